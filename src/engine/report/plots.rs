//! The plots of a report, drawn with plotters into SVG files. Errors are returned as text.

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Once;

use plotters::prelude::*;
use polars::prelude::*;

use crate::engine::results::schema::col;
use crate::engine::sensitivity::Estimate;

pub const FONT: &str = "sans-serif";

/// Registers the bundled font once per process (plotters' ab_glyph backend needs the bytes).
pub fn register_font() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        let bytes: &'static [u8] = include_bytes!("../../../assets/fonts/DejaVuSans.ttf");
        // Only fails for a corrupt font file, which is bundled: a programmer error.
        plotters::style::register_font(FONT, FontStyle::Normal, bytes).map_err(|_| ()).expect("bundled font");
    });
}

pub fn e<E: std::fmt::Debug>(err: E) -> String {
    format!("{err:?}")
}

/// The legend box every plot uses: its series' labels at `position`, in `size`-point text.
pub fn legend<'a, DB: DrawingBackend + 'a, CT: CoordTranslate>(
    chart: &mut ChartContext<'a, DB, CT>,
    position: SeriesLabelPosition,
    size: u32,
) -> Result<(), String> {
    chart
        .configure_series_labels()
        .position(position)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font((FONT, size))
        .draw()
        .map_err(e)
}

pub fn color(i: usize) -> RGBColor {
    // Okabe-Ito: distinguishable, also for colour-blind readers.
    const C: [(u8, u8, u8); 8] = [
        (0, 114, 178),
        (213, 94, 0),
        (0, 158, 115),
        (204, 121, 167),
        (230, 159, 0),
        (86, 180, 233),
        (240, 228, 66),
        (0, 0, 0),
    ];
    let (r, g, b) = C[i % C.len()];
    RGBColor(r, g, b)
}

fn strs(df: &DataFrame, name: &str) -> Result<StringChunked, String> {
    df.column(name).and_then(|c| c.cast(&DataType::String)).and_then(|c| c.str().cloned()).map_err(e)
}

fn floats(df: &DataFrame, name: &str) -> Result<Float64Chunked, String> {
    df.column(name).and_then(|c| c.cast(&DataType::Float64)).and_then(|c| c.f64().cloned()).map_err(e)
}

/// A white 900 x 560 SVG canvas, the size of every single-chart plot.
fn canvas(file: &Path) -> Result<DrawingArea<SVGBackend<'_>, plotters::coord::Shift>, String> {
    let root = SVGBackend::new(file, (900, 560)).into_drawing_area();
    root.fill(&WHITE).map_err(e)?;
    Ok(root)
}

/// A chart on `root` with the report's caption font, margin and room for the axis labels.
fn builder<'a, 'b, DB: DrawingBackend>(
    root: &'a DrawingArea<DB, plotters::coord::Shift>,
    caption: impl AsRef<str>,
    font_size: u32,
) -> ChartBuilder<'a, 'b, DB> {
    let mut b = ChartBuilder::on(root);
    b.caption(caption, (FONT, font_size)).margin(12).x_label_area_size(45).y_label_area_size(60);
    b
}

/// Pd against size for one detector and kind: one line per faulty output, Wilson band, min size marked.
pub fn pd_against_size(
    file: &Path,
    curves: &DataFrame,
    min_det: &DataFrame,
    set_name: &str,
    detector: &str,
    kind: &str,
    unit: &str,
) -> Result<(), String> {
    let (set, det, k, out) = (
        strs(curves, "thresholds")?,
        strs(curves, col::DETECTOR)?,
        strs(curves, col::KIND)?,
        strs(curves, col::TARGET)?,
    );
    let (size, pd, lo, hi) =
        (floats(curves, col::SIZE_BIN)?, floats(curves, "pd")?, floats(curves, "pd_lo")?, floats(curves, "pd_hi")?);
    let mut series: BTreeMap<String, Vec<(f64, f64, f64, f64)>> = BTreeMap::new();
    for i in 0..curves.height() {
        if set.get(i) != Some(set_name) || det.get(i) != Some(detector) || k.get(i) != Some(kind) {
            continue;
        }
        if let (Some(o), Some(s), Some(p), Some(l), Some(h)) =
            (out.get(i), size.get(i), pd.get(i), lo.get(i), hi.get(i))
        {
            series.entry(o.to_string()).or_default().push((s, p, l, h));
        }
    }
    let (ms, md, mk, mo, mv) = (
        strs(min_det, "thresholds")?,
        strs(min_det, col::DETECTOR)?,
        strs(min_det, col::KIND)?,
        strs(min_det, col::TARGET)?,
        floats(min_det, "min_size_pd90")?,
    );
    let min_size = |o: &str| {
        (0..min_det.height())
            .find(|&i| {
                ms.get(i) == Some(set_name)
                    && md.get(i) == Some(detector)
                    && mk.get(i) == Some(kind)
                    && mo.get(i) == Some(o)
            })
            .and_then(|i| mv.get(i))
    };
    let xs = series.values().flatten().map(|p| p.0);
    let (x0, x1) = xs.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| (a.min(x), b.max(x)));
    let pad = ((x1 - x0) * 0.05).max(1e-9);

    let root = canvas(file)?;
    let mut chart = builder(
        &root,
        format!(
            "Detection probability vs fault size: {detector}, {kind} ({set_name} thresholds; triangles: Pd >= 0.9)"
        ),
        18,
    )
    .build_cartesian_2d((x0 - pad)..(x1 + pad), 0f64..1.05)
    .map_err(e)?;
    chart
        .configure_mesh()
        .x_desc(format!("fault size ({unit})"))
        .y_desc("detection probability Pd")
        .label_style((FONT, 14))
        .draw()
        .map_err(e)?;
    chart
        .draw_series(LineSeries::new([(x0 - pad, 0.9), (x1 + pad, 0.9)], BLACK.mix(0.4)))
        .map_err(e)?
        .label("Pd = 0.9")
        .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], BLACK.mix(0.4)));
    for (i, (name, pts)) in series.iter().enumerate() {
        let c = color(i);
        let mut band: Vec<(f64, f64)> = pts.iter().map(|p| (p.0, p.3)).collect();
        band.extend(pts.iter().rev().map(|p| (p.0, p.2)));
        chart.draw_series(std::iter::once(Polygon::new(band, c.mix(0.15)))).map_err(e)?;
        let min = min_size(name);
        let label = match min {
            Some(m) => format!("{name} (Pd >= 0.9 from {m:.3})"),
            None => format!("{name} (Pd < 0.9 at every size)"),
        };
        chart
            .draw_series(LineSeries::new(pts.iter().map(|p| (p.0, p.1)), c.stroke_width(2)))
            .map_err(e)?
            .label(label)
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], c.stroke_width(2)));
        chart.draw_series(pts.iter().map(|p| Circle::new((p.0, p.1), 3, c.filled()))).map_err(e)?;
        if let Some(m) = min {
            chart.draw_series(std::iter::once(TriangleMarker::new((m, 0.9), 8, c.filled()))).map_err(e)?;
        }
    }
    legend(&mut chart, SeriesLabelPosition::LowerRight, 14)?;
    root.present().map_err(e)
}

/// One detector's ROC as `roc.csv` gives it: its points `(Pfa, Pd)` and the calibrated one, and the
/// fewest calibration trials a point's Pfa was read on.
pub struct RocCurve {
    pub detector: String,
    pub points: Vec<(f64, f64)>,
    pub calibrated: Option<(f64, f64)>,
    pub trials: u64,
}

/// ROC: Pd against Pfa as the whole-detector thresholds are scaled (`roc.csv`); the calibrated point marked.
pub fn roc(file: &Path, detectors: &[RocCurve]) -> Result<(), String> {
    let n_min = detectors.iter().map(|d| d.trials).filter(|&n| n > 0).min().unwrap_or(1) as f64;
    let floor = (0.5 / n_min).min(1e-2);
    let root = canvas(file)?;
    let mut chart = builder(&root, "ROC: the thresholds of every statistic scaled together", 20)
        .build_cartesian_2d((floor..1.0).log_scale(), 0f64..1.05)
        .map_err(e)?;
    chart
        .configure_mesh()
        .x_desc(format!("false-alarm probability Pfa per trial (log; 0 drawn at {floor:.1e})"))
        .y_desc("detection probability Pd")
        .label_style((FONT, 14))
        .draw()
        .map_err(e)?;
    for (i, curve) in detectors.iter().enumerate() {
        if curve.points.is_empty() {
            continue;
        }
        let (name, c) = (&curve.detector, color(i));
        let pts: Vec<(f64, f64)> = curve.points.iter().map(|&(pfa, pd)| (pfa.max(floor), pd)).collect();
        chart
            .draw_series(LineSeries::new(pts, c.stroke_width(2)))
            .map_err(e)?
            .label(name.as_str())
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], c.stroke_width(2)));
        let Some((pfa, pd)) = curve.calibrated else { continue };
        let chosen = (pfa.max(floor), pd);
        chart.draw_series(std::iter::once(Circle::new(chosen, 6, c.filled()))).map_err(e)?;
        chart
            .draw_series(std::iter::once(Text::new(
                format!("{name} calibrated: Pfa {:.4}, Pd {:.3}", chosen.0, chosen.1),
                (chosen.0 * 1.15, chosen.1 - 0.04 - 0.05 * i as f64),
                (FONT, 13).into_font().color(&c),
            )))
            .map_err(e)?;
    }
    legend(&mut chart, SeriesLabelPosition::LowerRight, 14)?;
    root.present().map_err(e)
}

/// Detection-delay distributions per fault kind, as frequency polygons over 40 bins.
pub fn delays(file: &Path, detector: &str, set_name: &str, delays: &BTreeMap<String, Vec<f64>>) -> Result<(), String> {
    let caption =
        format!("Detection delay by fault kind: {detector} ({set_name} thresholds; last bin holds the top 1 %)");
    frequencies(file, &caption, "delay after onset (s)", "detected", delays)
}

/// Distributions of a value per series, as frequency polygons over 40 bins from 0 (or the smallest
/// value, if negative) to the 99th percentile; the last bin holds the top 1 %.
pub fn frequencies(
    file: &Path,
    caption: &str,
    x_label: &str,
    counted: &str,
    series: &BTreeMap<String, Vec<f64>>,
) -> Result<(), String> {
    let mut all: Vec<f64> = series.values().flatten().copied().filter(|d| d.is_finite()).collect();
    all.sort_by(f64::total_cmp);
    let bottom = all.first().copied().unwrap_or(0.0).min(0.0);
    let top = all
        .get(((all.len() as f64 * 0.99) as usize).min(all.len().saturating_sub(1)))
        .copied()
        .unwrap_or(1.0)
        .max(bottom + 0.05);
    let bins = 40;
    let width = (top - bottom) / bins as f64;
    let hist: Vec<(String, Vec<(f64, f64)>)> = series
        .iter()
        .map(|(k, v)| {
            let mut counts = vec![0u64; bins];
            for &d in v.iter().filter(|d| d.is_finite()) {
                counts[(((d - bottom) / width) as usize).min(bins - 1)] += 1;
            }
            let n = v.len().max(1) as f64;
            let pts = counts.iter().enumerate().map(|(b, c)| (bottom + (b as f64 + 0.5) * width, *c as f64 / n));
            (k.clone(), pts.collect())
        })
        .collect();
    let ymax = hist.iter().flat_map(|h| h.1.iter().map(|p| p.1)).fold(0.0, f64::max).max(1e-3) * 1.1;
    let root = canvas(file)?;
    let mut chart = builder(&root, caption, 18).build_cartesian_2d(bottom..top, 0f64..ymax).map_err(e)?;
    chart
        .configure_mesh()
        .x_desc(x_label)
        .y_desc(format!("fraction of {counted} trials per bin"))
        .label_style((FONT, 14))
        .draw()
        .map_err(e)?;
    for (i, (name, pts)) in hist.iter().enumerate() {
        let c = color(i);
        let n = series[name].len();
        chart
            .draw_series(LineSeries::new(pts.iter().copied(), c.stroke_width(2)))
            .map_err(e)?
            .label(format!("{name} ({n} {counted})"))
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], c.stroke_width(2)));
    }
    legend(&mut chart, SeriesLabelPosition::UpperRight, 14)?;
    root.present().map_err(e)
}

/// `y` against `x`, one colour per series (detector), with the line y = 0 or y = x for reference.
pub fn scatter(
    file: &Path,
    caption: &str,
    (x_label, y_label): (&str, &str),
    diagonal: bool,
    series: &BTreeMap<String, Vec<(f64, f64)>>,
) -> Result<(), String> {
    let pts = series.values().flatten();
    let (mut x0, mut x1, mut y0, mut y1) = (f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY);
    for (x, y) in pts {
        (x0, x1, y0, y1) = (x0.min(*x), x1.max(*x), y0.min(*y), y1.max(*y));
    }
    if !x0.is_finite() {
        (x0, x1, y0, y1) = (0.0, 1.0, 0.0, 1.0);
    }
    if diagonal {
        (x0, y0) = (x0.min(y0).min(0.0), x0.min(y0).min(0.0));
        (x1, y1) = (x1.max(y1), x1.max(y1));
    } else {
        (y0, y1) = (y0.min(0.0), y1.max(0.0));
    }
    let (px, py) = (((x1 - x0) * 0.05).max(1e-9), ((y1 - y0) * 0.05).max(1e-9));
    let root = canvas(file)?;
    let mut chart =
        builder(&root, caption, 17).build_cartesian_2d((x0 - px)..(x1 + px), (y0 - py)..(y1 + py)).map_err(e)?;
    chart.configure_mesh().x_desc(x_label).y_desc(y_label).label_style((FONT, 14)).draw().map_err(e)?;
    let reference = if diagonal { [(x0, x0), (x1, x1)] } else { [(x0 - px, 0.0), (x1 + px, 0.0)] };
    chart
        .draw_series(LineSeries::new(reference, BLACK.mix(0.5)))
        .map_err(e)?
        .label(if diagonal { "y = x" } else { "y = 0" })
        .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], BLACK.mix(0.5)));
    for (i, (name, pts)) in series.iter().enumerate() {
        let c = color(i);
        chart
            .draw_series(pts.iter().map(|p| Circle::new(*p, 2, c.mix(0.6).filled())))
            .map_err(e)?
            .label(format!("{name} ({} trials)", pts.len()))
            .legend(move |(x, y)| Circle::new((x + 10, y), 4, c.filled()));
    }
    legend(&mut chart, SeriesLabelPosition::UpperLeft, 14)?;
    root.present().map_err(e)
}

/// Isolation (or classification) confusion matrix: rows = true target, columns = the one named (or
/// none), in the order of `order` (the manifest's outputs), then any other names.
pub fn confusion(
    file: &Path,
    detector: &str,
    order: &[String],
    counts: &BTreeMap<(String, String), u64>,
) -> Result<(), String> {
    let mut names: Vec<String> = order.to_vec();
    for (t, n) in counts.keys() {
        for x in [t, n] {
            if x != col::NO_FAULT && !names.contains(x) {
                names.push(x.clone());
            }
        }
    }
    let rows: Vec<&String> = names.iter().filter(|o| counts.keys().any(|k| &k.0 == *o)).collect();
    // Every listed target is a column when the targets are what `order` lists (a never-named output
    // is worth seeing as an empty column); otherwise only the names that occur.
    let listed = counts.keys().all(|k| order.contains(&k.0));
    let mut cols: Vec<String> = names
        .iter()
        .filter(|o| (listed && order.contains(o)) || counts.keys().any(|k| &k.1 == *o || &k.0 == *o))
        .cloned()
        .collect();
    cols.push(col::NO_FAULT.into());
    let (nr, nc) = (rows.len().max(1) as i32, cols.len() as i32);
    let figure = SVGBackend::new(file, (1160, 140 + 70 * nr as u32)).into_drawing_area();
    figure.fill(&WHITE).map_err(e)?;
    let (root, key) = figure.split_horizontally(960);
    // Legend: what the colours and shades mean.
    let (green, orange) = (RGBColor(0, 158, 115), RGBColor(213, 94, 0));
    for (k, (fill, text)) in [
        (green.mix(1.0), "correct isolation"),
        (orange.mix(1.0), "another target, or none"),
        (orange.mix(0.1), "shade: share of the row"),
    ]
    .into_iter()
    .enumerate()
    {
        let y = 60 + 28 * k as i32;
        key.draw(&Rectangle::new([(8, y), (26, y + 18)], ShapeStyle::from(fill).filled())).map_err(e)?;
        key.draw(&Text::new(text, (34, y + 3), (FONT, 13))).map_err(e)?;
    }
    let mut chart = ChartBuilder::on(&root)
        .caption(format!("Isolation confusion: {detector} (deck thresholds; rows: true target)"), (FONT, 18))
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(110)
        .build_cartesian_2d((0..nc - 1).into_segmented(), (0..nr - 1).into_segmented())
        .map_err(e)?;
    let centre = |v: &SegmentValue<i32>| match v {
        SegmentValue::CenterOf(i) => Some(*i as usize),
        _ => None,
    };
    chart
        .configure_mesh()
        .disable_mesh()
        .x_labels(nc as usize)
        .y_labels(nr as usize)
        .x_label_formatter(&|v| centre(v).and_then(|i| cols.get(i).cloned()).unwrap_or_default())
        .y_label_formatter(&|v| centre(v).and_then(|i| rows.get(i)).map(|s| s.to_string()).unwrap_or_default())
        .x_desc("isolated (named) target")
        .y_desc("true target")
        .label_style((FONT, 13))
        .draw()
        .map_err(e)?;
    for (r, truth) in rows.iter().enumerate() {
        let total: u64 = cols.iter().map(|c| counts.get(&((*truth).clone(), c.clone())).copied().unwrap_or(0)).sum();
        let r = r as i32;
        for (c, named) in cols.iter().enumerate() {
            let n = counts.get(&((*truth).clone(), named.clone())).copied().unwrap_or(0);
            let frac = if total > 0 { n as f64 / total as f64 } else { 0.0 };
            let fill = if *truth == named { green } else { orange };
            let c = c as i32;
            let cell = [
                (SegmentValue::Exact(c), SegmentValue::Exact(r)),
                (SegmentValue::Exact(c + 1), SegmentValue::Exact(r + 1)),
            ];
            chart.draw_series(std::iter::once(Rectangle::new(cell, fill.mix(0.1 + 0.9 * frac).filled()))).map_err(e)?;
            let label = Text::new(format!("{n}"), (SegmentValue::CenterOf(c), SegmentValue::CenterOf(r)), (FONT, 14));
            chart.draw_series(std::iter::once(label)).map_err(e)?;
        }
    }
    figure.present().map_err(e)
}

/// Whether [`false_alarms`] has something to draw against: more than one noise bin or parameter-error
/// bin (with one of each, a single point, the table says it).
pub fn false_alarms_vary(points: &[(f64, f64, f64, f64, f64, u64)]) -> bool {
    distinct(points.iter().map(|p| p.0)) > 1 || distinct(points.iter().map(|p| p.1)) > 1
}

fn distinct(values: impl Iterator<Item = f64>) -> usize {
    let mut v: Vec<f64> = values.collect();
    v.sort_by(f64::total_cmp);
    v.dedup();
    v.len()
}

/// False-alarm probability per trial against the noise scale, one series per parameter-error bin, with
/// 95 % Wilson intervals as bars; against the parameter-error bin, one series per noise scale, when
/// the noise has one scale only (a single column of points otherwise). `points`: (noise bin,
/// parameter-error bin, rate, lo, hi, trials).
pub fn false_alarms(
    file: &Path,
    detector: &str,
    set_name: &str,
    points: &[(f64, f64, f64, f64, f64, u64)],
) -> Result<(), String> {
    let by_error = distinct(points.iter().map(|p| p.0)) < 2;
    let points: Vec<_> =
        if by_error { points.iter().map(|p| (p.1, p.0, p.2, p.3, p.4, p.5)).collect() } else { points.to_vec() };
    let (x_desc, series) = if by_error {
        ("parameter error (bin: the largest |error| of the trial's parameters)", "noise scale")
    } else {
        ("noise scale (bin)", "parameter error bin")
    };
    let (x0, x1) = points.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| (a.min(p.0), b.max(p.0)));
    let pad = ((x1 - x0) * 0.08).max(0.05);
    let top = points.iter().map(|p| p.4).fold(0.0, f64::max).max(0.01) * 1.1;
    let root = canvas(file)?;
    let mut chart = builder(
        &root,
        format!("False alarms by noise and parameter-error bin: {detector} ({set_name} thresholds)"),
        18,
    )
    .build_cartesian_2d((x0 - pad)..(x1 + pad), 0f64..top)
    .map_err(e)?;
    chart
        .configure_mesh()
        .x_desc(x_desc)
        .y_desc("false-alarm probability per fault-free trial")
        .label_style((FONT, 14))
        .draw()
        .map_err(e)?;
    let mut bins: Vec<f64> = points.iter().map(|p| p.1).collect();
    bins.sort_by(f64::total_cmp);
    bins.dedup();
    for (i, b) in bins.iter().enumerate() {
        let c = color(i);
        // Bins side by side, so that overlapping intervals stay readable.
        let shift = (i as f64 - (bins.len() as f64 - 1.0) / 2.0) * pad * 0.25;
        let mut pts: Vec<_> = points.iter().filter(|p| p.1 == *b).map(|p| (p.0 + shift, p.2, p.3, p.4)).collect();
        pts.sort_by(|a, b| a.0.total_cmp(&b.0));
        chart
            .draw_series(LineSeries::new(pts.iter().map(|p| (p.0, p.1)), c.stroke_width(2)))
            .map_err(e)?
            .label(format!("{series} {b}"))
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], c.stroke_width(2)));
        chart
            .draw_series(pts.iter().map(|p| PathElement::new([(p.0, p.2), (p.0, p.3)], c.stroke_width(2))))
            .map_err(e)?;
        chart.draw_series(pts.iter().map(|p| Circle::new((p.0, p.1), 4, c.filled()))).map_err(e)?;
    }
    legend(&mut chart, SeriesLabelPosition::UpperLeft, 14)?;
    root.present().map_err(e)
}

/// One trial's trace as `simulate` writes it: one panel per (title, columns), against `t_s`; the
/// fault onset drawn where there is one.
pub fn trace_panels(
    file: &Path,
    title: &str,
    t_s: &[f64],
    panels: &[(String, Vec<(String, Vec<f64>)>)],
    onset_s: Option<f64>,
) -> Result<(), String> {
    let (t0, t1) = (t_s.first().copied().unwrap_or(0.0), t_s.last().copied().unwrap_or(1.0).max(1e-9));
    let root = SVGBackend::new(file, (1100, 80 + 240 * panels.len() as u32)).into_drawing_area();
    root.fill(&WHITE).map_err(e)?;
    let root = root.titled(title, (FONT, 20)).map_err(e)?;
    let areas = root.split_evenly((panels.len().max(1), 1));
    for ((name, series), area) in panels.iter().zip(&areas) {
        let finite = series.iter().flat_map(|s| s.1.iter().copied()).filter(|v| v.is_finite());
        let (lo, hi) = finite.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| (a.min(v), b.max(v)));
        let (lo, hi) = if lo.is_finite() { (lo, hi) } else { (0.0, 1.0) };
        let pad = ((hi - lo) * 0.08).max(1e-9);
        let mut chart = ChartBuilder::on(area)
            .margin(8)
            .x_label_area_size(35)
            .y_label_area_size(75)
            .build_cartesian_2d(t0..t1, (lo - pad)..(hi + pad))
            .map_err(e)?;
        chart.configure_mesh().x_desc("t (s)").y_desc(name.as_str()).label_style((FONT, 12)).draw().map_err(e)?;
        for (i, (column, v)) in series.iter().enumerate() {
            let c = color(i);
            let pts = t_s.iter().copied().zip(v.iter().copied()).filter(|p| p.1.is_finite());
            chart
                .draw_series(LineSeries::new(pts, c))
                .map_err(e)?
                .label(column.as_str())
                .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], c));
        }
        if let Some(t) = onset_s.filter(|t| t.is_finite()) {
            chart
                .draw_series(LineSeries::new([(t, lo - pad), (t, hi + pad)], BLACK.stroke_width(2)))
                .map_err(e)?
                .label("fault onset")
                .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], BLACK.stroke_width(2)));
        }
        legend(&mut chart, SeriesLabelPosition::UpperLeft, 11)?;
    }
    root.present().map_err(e)
}

/// The fitted tail of one detector's fault-free maxima (`tail.csv`, `tail_diagnostics.csv`).
pub struct TailPlot<'a> {
    pub detector: &'a str,
    /// Each fault-free unit's largest statistic over its calibrated threshold.
    pub values: &'a [f64],
    /// The chosen fit: threshold, scale, shape, and the probability of exceeding the threshold.
    pub fit: Option<(f64, f64, f64, f64)>,
    /// Per target: per-trial probability and the thresholds' factor with its interval.
    pub targets: &'a [(f64, f64, f64, f64)],
}

/// Exceedance probability against the factor on the calibrated thresholds (log scale): the observed
/// fraction of fault-free units above each value, the generalised Pareto fit beyond its threshold, and
/// the factor each target needs with its 95 % interval.
pub fn tail(file: &Path, p: &TailPlot) -> Result<(), String> {
    let mut sorted: Vec<f64> = p.values.iter().copied().filter(|v| v.is_finite()).collect();
    sorted.sort_by(|a, b| b.total_cmp(a));
    let n = p.values.len().max(1) as f64;
    let floor = p.targets.iter().map(|t| t.0).fold(0.5 / n, f64::min) / 3.0;
    let finite_hi = p.targets.iter().map(|t| if t.3.is_finite() { t.3 } else { t.1 }).fold(f64::NAN, f64::max);
    let x_max = sorted.first().copied().unwrap_or(1.0).max(finite_hi).max(1.0) * 1.1;
    let x_min = sorted.get(sorted.len() / 2).copied().filter(|v| *v > 0.0).unwrap_or(0.1).min(1.0) * 0.9;
    let root = canvas(file)?;
    let caption = format!("Fault-free tail: {} (calibrated thresholds scaled)", p.detector);
    let mut chart = builder(&root, caption, 20)
        .build_cartesian_2d((x_min..x_max).log_scale(), (floor..1.0).log_scale())
        .map_err(e)?;
    chart
        .configure_mesh()
        .x_desc("factor on the calibrated thresholds (largest statistic / threshold; log)")
        .x_label_formatter(&|v| format!("{v:.2}"))
        .y_desc("false-alarm probability per trial (log)")
        .y_label_formatter(&|v| format!("{v:.0e}"))
        .label_style((FONT, 14))
        .draw()
        .map_err(e)?;
    let observed: Vec<(f64, f64)> = drawn_ranks(sorted.len())
        .into_iter()
        .map(|i| (sorted[i], (i + 1) as f64 / n))
        .filter(|(x, _)| *x >= x_min)
        .collect();
    chart
        .draw_series(observed.iter().map(|&pt| Circle::new(pt, 2, color(0).filled())))
        .map_err(e)?
        .label("observed fraction above")
        .legend(|(x, y)| Circle::new((x + 10, y), 3, color(0).filled()));
    if let Some((u, sigma, xi, zeta)) = p.fit {
        let curve: Vec<(f64, f64)> = (0..=300)
            .map(|i| u * (x_max / u).powf(i as f64 / 300.0))
            .map(|x| (x, zeta * crate::engine::stats::tail::gpd_survival(x - u, sigma, xi)))
            .filter(|(_, q)| *q >= floor)
            .collect();
        let c = color(1);
        chart
            .draw_series(LineSeries::new(curve, c.stroke_width(2)))
            .map_err(e)?
            .label(format!("generalised Pareto fit (shape {xi:.3}) above {u:.3}"))
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], c.stroke_width(2)));
    }
    let c = color(2);
    for (i, &(q, s, lo, hi)) in p.targets.iter().enumerate() {
        let hi = if hi.is_finite() { hi } else { x_max };
        let bar =
            chart.draw_series(std::iter::once(PathElement::new([(lo, q), (hi, q)], c.stroke_width(3)))).map_err(e)?;
        if i == 0 {
            bar.label("threshold for a target, 95 % interval")
                .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], c.stroke_width(3)));
        }
        chart.draw_series(std::iter::once(Circle::new((s, q), 5, c.filled()))).map_err(e)?;
    }
    legend(&mut chart, SeriesLabelPosition::UpperRight, 14)?;
    root.present().map_err(e)
}

/// The ranks (0 the largest) of `len` sorted values a log-log survival plot draws: every one of the
/// first 1,000, then ranks 0.5 % apart, which a log axis cannot tell from all of them (at 10^7 trials
/// every rank made plots of 100 MB).
fn drawn_ranks(len: usize) -> Vec<usize> {
    let mut ranks = Vec::new();
    let mut r = 0;
    while r < len {
        ranks.push(r);
        r = if r < 1000 { r + 1 } else { (r as f64 * 1.005).ceil() as usize };
    }
    if ranks.last().is_some_and(|&l| l + 1 != len) {
        ranks.push(len - 1);
    }
    ranks
}

/// One outcome's Sobol indices for one detector (`sensitivity.csv`): per factor, the first-order index
/// (upper bar) and the total index (lower bar) with their 95 % bootstrap intervals as whiskers.
pub struct SensitivityBars<'a> {
    pub outcome: &'a str,
    pub detector: &'a str,
    /// (factor, its indices), drawn bottom to top.
    pub factors: Vec<(String, Estimate)>,
}

pub fn sensitivity_bars(file: &Path, p: &SensitivityBars) -> Result<(), String> {
    let k = p.factors.len().max(1) as i32;
    let lowest = p.factors.iter().map(|(_, f)| f.s1_interval.0.min(f.st_interval.0)).fold(0.0f64, f64::min);
    let highest = p.factors.iter().map(|(_, f)| f.s1_interval.1.max(f.st_interval.1)).fold(1.0f64, f64::max);
    let figure = SVGBackend::new(file, (900, 130 + 64 * k as u32)).into_drawing_area();
    figure.fill(&WHITE).map_err(e)?;
    let caption = format!("Sobol indices of {} for detector {} (95 % bootstrap intervals)", p.outcome, p.detector);
    let mut chart = ChartBuilder::on(&figure)
        .caption(caption, (FONT, 18))
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(150)
        .build_cartesian_2d(lowest - 0.02..highest + 0.02, (0..k - 1).into_segmented())
        .map_err(e)?;
    let names: Vec<String> = p.factors.iter().map(|f| f.0.clone()).collect();
    let centre = |v: &SegmentValue<i32>| match v {
        SegmentValue::CenterOf(i) => Some(*i as usize),
        _ => None,
    };
    chart
        .configure_mesh()
        .disable_y_mesh()
        .y_labels(k as usize)
        .y_label_formatter(&|v| centre(v).and_then(|i| names.get(i).cloned()).unwrap_or_default())
        .x_desc("share of the outcome's variance")
        .x_label_formatter(&|x| format!("{:.1}", if x.abs() < 1e-9 { 0.0 } else { *x }))
        .label_style((FONT, 13))
        .draw()
        .map_err(e)?;
    let segment_px = chart.plotting_area().dim_in_pixel().1 / k as u32;
    let at = |frac: f64| (frac * segment_px as f64).round() as u32;
    let (s1_colour, st_colour) = (color(0), color(1));
    for (i, (_, f)) in p.factors.iter().enumerate() {
        let (top, bottom) = (|| SegmentValue::Exact(i as i32), || SegmentValue::Exact(i as i32 + 1));
        // Segment i is drawn from its top (Exact(i)) down: S1 in the upper half, ST in the lower.
        for (value, (lo, hi), colour, upper) in
            [(f.s1, f.s1_interval, s1_colour, true), (f.st, f.st_interval, st_colour, false)]
        {
            let (t, b) = if upper { (at(0.12), at(0.52)) } else { (at(0.52), at(0.12)) };
            let mut bar = Rectangle::new([(0.0, top()), (value, bottom())], colour.mix(0.8).filled());
            bar.set_margin(t, b, 0, 0);
            let (wt, wb) = if upper { (at(0.31), at(0.69) - 2) } else { (at(0.69) - 2, at(0.31)) };
            let mut whisker = Rectangle::new([(lo, top()), (hi, bottom())], BLACK.filled());
            whisker.set_margin(wt, wb, 0, 0);
            chart.draw_series([bar, whisker]).map_err(e)?;
        }
    }
    chart
        .draw_series(std::iter::empty::<Circle<(f64, SegmentValue<i32>), i32>>())
        .map_err(e)?
        .label("S1: first order (the factor alone)")
        .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 16, y + 5)], s1_colour.filled()));
    chart
        .draw_series(std::iter::empty::<Circle<(f64, SegmentValue<i32>), i32>>())
        .map_err(e)?
        .label("ST: total (with its interactions)")
        .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 16, y + 5)], st_colour.filled()));
    legend(&mut chart, SeriesLabelPosition::LowerRight, 13)?;
    figure.present().map_err(e)
}

#[cfg(test)]
mod tests {
    use super::drawn_ranks;

    #[test]
    fn the_tail_plot_draws_every_top_rank_and_log_spaced_ones_below() {
        assert_eq!(drawn_ranks(0), Vec::<usize>::new());
        assert_eq!(drawn_ranks(5), vec![0, 1, 2, 3, 4]);
        // 8 million fault-free units (a 10^7-trial run): the first 1,000 ranks, then about
        // ln(8000) / ln(1.005) = 1,800 more, the last rank (the smallest value) among them.
        let ranks = drawn_ranks(8_000_000);
        assert_eq!(&ranks[..1001], &(0..1001).collect::<Vec<_>>()[..]);
        assert_eq!(*ranks.last().unwrap(), 7_999_999);
        assert!((2_700..2_900).contains(&ranks.len()), "{}", ranks.len());
        // Neighbours beyond the first 1,000 are at most 0.5 % (plus one rank) apart.
        assert!(ranks.windows(2).all(|w| w[1] > w[0] && (w[1] as f64) <= w[0] as f64 * 1.005 + 1.0));
    }
}
