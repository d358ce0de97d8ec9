//! `fdimc report DIR`: plots (SVG) and one self-contained HTML page next to a run's tables.
//!
//! - `pd_size_<detector>_<kind>.svg`: detection probability against fault size per faulty output, with
//!   95 % Wilson bands, the minimum size detected with Pd >= 0.9 marked (calibrated thresholds);
//! - `roc.svg`: Pd against Pfa as the whole-detector thresholds are scaled from 0.2x to 5x, per detector,
//!   the calibrated threshold (1x) marked;
//! - `delay_<detector>.svg`: detection-delay distributions per fault kind (calibrated thresholds);
//! - `confusion_<detector>.svg`: isolation confusion matrix (faulty output x isolated output, deck
//!   thresholds, signature-direction rule);
//! - `trace_trial<N>.svg`: residuals of chosen trials with thresholds, onset and alarm times;
//! - `report.html`: provenance, warnings, thresholds, and every plot.
//!
//! Text is rendered with the bundled DejaVu Sans (`assets/fonts`), so output is the same on any machine.

mod plots;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use polars::prelude::*;

use crate::engine::deck::FromDeck;
use crate::engine::runner::{Manifest, RunError, io, write_atomically};
use crate::engine::schema::col;
use crate::engine::tables::{f64_col, list_col, read_slice, read_summary, str_col};
use crate::engine::thresholds::{alarm_time, read_thresholds};

/// What a report contains, for the CLI and tests.
#[derive(Debug, Default)]
pub struct Report {
    pub files: Vec<PathBuf>,
    pub warnings: Vec<String>,
}

/// Per-detector data gathered from `trials.parquet` for the plots.
#[derive(Default)]
struct DetectorData {
    /// max_j pre_max_j / thr_j on fault-free (calibration) trials.
    z_fault_free: Vec<f64>,
    /// max_j post-onset max_j / thr_j on faulty designed trials.
    z_faulty: Vec<f64>,
    /// Calibrated-threshold delays per fault kind.
    delays: BTreeMap<String, Vec<f64>>,
    /// Isolation counts: (faulty output, isolated output or "none") -> trials (deck thresholds).
    confusion: BTreeMap<(String, String), u64>,
}

/// Writes the report of the run in `dir`; `trials` are traced (re-simulated from the deck).
pub fn write_report(dir: &Path, trials: &[u64]) -> Result<Report, RunError> {
    let manifest = Manifest::read(dir)?;
    for f in ["summary.parquet", "thresholds.csv", "curves.csv", "min_detectable.csv"] {
        if !dir.join(f).exists() {
            return Err(RunError::Invalid(format!(
                "{}: missing {f}: run `fdimc summarize {}` first",
                dir.display(),
                dir.display()
            )));
        }
    }
    let out = dir.join("report");
    std::fs::create_dir_all(&out).map_err(io(&out))?;
    plots::register_font();
    let mut report = Report::default();
    let thresholds = read_thresholds(&dir.join("thresholds.csv"))?;
    let data = gather(dir, &manifest, &thresholds)?;

    // Pd against size.
    let curves = read_csv(&dir.join("curves.csv"))?;
    let min_det = read_csv(&dir.join("min_detectable.csv"))?;
    for d in &manifest.detectors {
        for kind in kinds_with_sizes(&curves, d)? {
            let file = out.join(format!("pd_size_{d}_{kind}.svg"));
            let unit = manifest.fault_size_units.get(&kind).cloned().unwrap_or_else(|| "deck units".into());
            plots::pd_against_size(&file, &curves, &min_det, d, &kind, &unit).map_err(internal(&file))?;
            report.files.push(file);
        }
    }
    // ROC.
    let file = out.join("roc.svg");
    let roc: Vec<(String, Vec<f64>, Vec<f64>)> = manifest
        .detectors
        .iter()
        .map(|d| (d.clone(), data[d].z_fault_free.clone(), data[d].z_faulty.clone()))
        .collect();
    if roc.iter().any(|(_, ff, f)| !ff.is_empty() && !f.is_empty()) {
        plots::roc(&file, &roc).map_err(internal(&file))?;
        report.files.push(file);
    } else {
        report.warnings.push("no ROC: it needs both fault-free and faulty trials".into());
    }
    for d in &manifest.detectors {
        let dd = &data[d];
        if dd.delays.values().any(|v| !v.is_empty()) {
            let file = out.join(format!("delay_{d}.svg"));
            plots::delays(&file, d, &dd.delays).map_err(internal(&file))?;
            report.files.push(file);
        }
        if !dd.confusion.is_empty() {
            let file = out.join(format!("confusion_{d}.svg"));
            plots::confusion(&file, d, &manifest.outputs, &dd.confusion).map_err(internal(&file))?;
            report.files.push(file);
        }
    }
    // Traces of chosen trials, re-simulated from the deck (only if it is the deck of this run).
    if !trials.is_empty() {
        let deck = PathBuf::from(&manifest.deck);
        let same = crate::engine::runner::deck_sha256(&deck).map(|h| h == manifest.deck_sha256).unwrap_or(false);
        if !same {
            return Err(RunError::Invalid(format!(
                "--trials: {} is missing or changed since this run (SHA-256 differs): traces need the run's deck",
                deck.display()
            )));
        }
        let mut study = crate::methods::detection_filter::study::LtiStudy::load(&deck)
            .map_err(|e| RunError::Invalid(e.to_string()))?;
        study.header.seed = manifest.seed;
        study.monte_carlo.common.trials = manifest.trials;
        let engine = crate::methods::detection_filter::trials::Engine::new(&study);
        let calibrated = &thresholds.iter().find(|t| t.0 == study.detectors[0].name).map(|t| t.2.clone());
        for &trial in trials {
            if trial >= manifest.trials {
                return Err(RunError::Invalid(format!(
                    "--trials: trial {trial} is not in this run (0..{})",
                    manifest.trials
                )));
            }
            let mut trace = crate::engine::output::Trace::default();
            let (spec, outcome) = engine
                .simulate(trial, 0, &mut trace)
                .map_err(|e| RunError::Invalid(format!("trial {trial}: design failed: {e}")))?;
            let file = out.join(format!("trace_trial{trial}.svg"));
            plots::trace(&file, &study, &spec, &outcome, &trace, calibrated.as_deref()).map_err(internal(&file))?;
            report.files.push(file);
        }
    }

    // Warnings from the summary.
    let summary = crate::engine::runner::read_parquet(&dir.join("summary.parquet"))?;
    report.warnings.extend(health_warnings(&summary));
    for d in &manifest.detectors {
        let n = data[d].z_fault_free.len();
        if (n as f64) * manifest.target_pfa < 1.0 {
            report.warnings.push(format!(
                "detector {d}: {n} fault-free trials cannot resolve the target Pfa {} (needs {})",
                manifest.target_pfa,
                (1.0 / manifest.target_pfa).ceil()
            ));
        }
    }

    let html = out.join("report.html");
    let page = html_page(dir, &manifest, &report)?;
    write_atomically(&html, page.as_bytes())?;
    report.files.push(html);
    Ok(report)
}

fn internal(file: &Path) -> impl FnOnce(String) -> RunError + '_ {
    move |e| RunError::Internal(format!("{}: {e}", file.display()))
}

fn read_csv(path: &Path) -> Result<DataFrame, RunError> {
    read_summary(path)
}

/// Failed designs and diverged filters, counted once per (trial, detector) from the summary's `deck`
/// rows (every threshold set holds the same trials).
fn health_warnings(summary: &DataFrame) -> Vec<String> {
    let deck_sum = |name: &str| -> u64 {
        let (Ok(set), Ok(values)) = (summary.column("thresholds"), summary.column(name)) else { return 0 };
        let (Ok(set), Ok(values)) = (set.str(), values.u64()) else { return 0 };
        (0..summary.height()).filter(|&i| set.get(i) == Some("deck")).filter_map(|i| values.get(i)).sum()
    };
    let mut warnings = Vec::new();
    let failures = deck_sum("failed");
    if failures > 0 {
        warnings.push(format!("{failures} trial x detector designs failed (failure in trials.parquet)"));
    }
    let diverged = deck_sum("diverged");
    if diverged > 0 {
        warnings.push(format!("{diverged} trial x detector runs diverged (diverged_at_s in trials.parquet)"));
    }
    warnings
}

/// Fault kinds of detector `d` with at least two size bins in the calibrated curves.
fn kinds_with_sizes(curves: &DataFrame, d: &str) -> Result<Vec<String>, RunError> {
    let f = curves
        .clone()
        .lazy()
        .filter(
            polars::prelude::col("thresholds")
                .eq(lit("calibrated"))
                .and(polars::prelude::col(col::DETECTOR).eq(lit(d))),
        )
        .group_by_stable([polars::prelude::col(col::KIND)])
        .agg([polars::prelude::col(col::SIZE_BIN).n_unique().alias("n")])
        .filter(polars::prelude::col("n").gt_eq(lit(2)))
        .collect()
        .map_err(|e| RunError::Internal(e.to_string()))?;
    let k = f.column(col::KIND).and_then(|c| c.str().cloned()).map_err(|e| RunError::Internal(e.to_string()))?;
    Ok((0..k.len()).filter_map(|i| k.get(i).map(str::to_string)).collect())
}

fn gather(
    dir: &Path,
    m: &Manifest,
    thresholds: &[(String, Vec<f64>, Vec<f64>)],
) -> Result<BTreeMap<String, DetectorData>, RunError> {
    let path = dir.join("trials.parquet");
    let mut data: BTreeMap<String, DetectorData> =
        m.detectors.iter().map(|d| (d.clone(), DetectorData::default())).collect();
    let whole: BTreeMap<&str, &Vec<f64>> = thresholds.iter().map(|t| (t.0.as_str(), &t.2)).collect();
    let step = 8_192usize;
    let mut offset = 0usize;
    while offset < m.rows as usize {
        let df = read_slice(&path, offset, step, None)?;
        offset += step;
        let det = str_col(&df, col::DETECTOR, &path)?;
        let kind = str_col(&df, col::KIND, &path)?;
        let output = str_col(&df, col::TARGET, &path)?;
        let failure = str_col(&df, col::FAILURE, &path)?;
        let onset = f64_col(&df, col::ONSET_S, &path)?;
        let iso = str_col(&df, col::ISOLATED, &path)?;
        let pre: Vec<&Float64Chunked> =
            m.outputs.iter().map(|o| f64_col(&df, &col::pre_max(o), &path)).collect::<Result<_, _>>()?;
        let fp_t: Vec<Vec<Vec<f64>>> =
            m.outputs.iter().map(|o| list_col(&df, &col::fp_t(o), &path)).collect::<Result<_, _>>()?;
        let fp_v: Vec<Vec<Vec<f64>>> =
            m.outputs.iter().map(|o| list_col(&df, &col::fp_v(o), &path)).collect::<Result<_, _>>()?;
        for i in 0..df.height() {
            let (Some(d), Some(k)) = (det.get(i), kind.get(i)) else { continue };
            if failure.get(i).is_some() {
                continue;
            }
            let (Some(th), Some(dd)) = (whole.get(d), data.get_mut(d)) else { continue };
            if k == col::NO_FAULT {
                let z = (0..m.outputs.len()).map(|j| pre[j].get(i).unwrap_or(f64::NAN) / th[j]).fold(0.0, f64::max);
                dd.z_fault_free.push(z);
                continue;
            }
            let z = (0..m.outputs.len()).map(|j| fp_v[j][i].last().copied().unwrap_or(0.0) / th[j]).fold(0.0, f64::max);
            dd.z_faulty.push(z);
            let t: Vec<&[f64]> = fp_t.iter().map(|c| c[i].as_slice()).collect();
            let v: Vec<&[f64]> = fp_v.iter().map(|c| c[i].as_slice()).collect();
            let t_alarm = alarm_time(&t, &v, th);
            if let (Some(t), Some(t0)) = (t_alarm, onset.get(i)) {
                dd.delays.entry(k.to_string()).or_default().push(t - t0);
            }
            let truth = output.get(i).unwrap_or("").to_string();
            let named = iso.get(i).unwrap_or(col::NO_FAULT).to_string();
            *dd.confusion.entry((truth, named)).or_default() += 1;
        }
    }
    Ok(data)
}

fn escape(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;")
}

fn html_page(dir: &Path, m: &Manifest, r: &Report) -> Result<String, RunError> {
    let thresholds = std::fs::read_to_string(dir.join("thresholds.csv"))
        .map_err(|e| RunError::Io { file: dir.join("thresholds.csv"), source: e })?;
    let mut table = String::from("<table>\n");
    for (i, line) in thresholds.lines().enumerate() {
        let cell = if i == 0 { "th" } else { "td" };
        table.push_str("<tr>");
        for v in line.split(',') {
            let v = v.parse::<f64>().map(|x| format!("{x:.5}")).unwrap_or_else(|_| v.to_string());
            table.push_str(&format!("<{cell}>{}</{cell}>", escape(&v)));
        }
        table.push_str("</tr>\n");
    }
    table.push_str("</table>\n");
    let mut figures = String::new();
    for f in r.files.iter().filter(|f| f.extension().is_some_and(|e| e == "svg")) {
        let name = f.file_name().unwrap_or_default().to_string_lossy();
        figures.push_str(&format!(
            "<figure><img src=\"{0}\" alt=\"{0}\"><figcaption>{0}</figcaption></figure>\n",
            escape(&name)
        ));
    }
    let warnings = if r.warnings.is_empty() {
        "<p>None.</p>".to_string()
    } else {
        format!("<ul>{}</ul>", r.warnings.iter().map(|w| format!("<li>{}</li>", escape(w))).collect::<String>())
    };
    Ok(format!(
        r#"<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>fdimc report: {study}</title>
<style>body{{font-family:sans-serif;max-width:1100px;margin:2em auto;padding:0 1em}}
table{{border-collapse:collapse;font-size:85%}}td,th{{border:1px solid #ccc;padding:2px 6px;text-align:right}}
figure{{display:inline-block;margin:0.5em}}img{{max-width:100%}}code{{background:#f4f4f4}}</style></head>
<body>
<h1>fdimc report: {study}</h1>
<h2>Provenance</h2>
<table>
<tr><th>deck</th><td><code>{deck}</code></td></tr>
<tr><th>deck SHA-256</th><td><code>{sha}</code></td></tr>
<tr><th>seed</th><td>{seed}</td></tr>
<tr><th>trials</th><td>{trials}</td></tr>
<tr><th>detectors</th><td>{detectors}</td></tr>
<tr><th>target Pfa</th><td>{pfa}</td></tr>
<tr><th>fdimc</th><td>{version}</td></tr>
<tr><th>command</th><td><code>{cmd}</code></td></tr>
</table>
<h2>Warnings</h2>
{warnings}
<h2>Thresholds</h2>
<p>Per output at the target false-alarm probability, and for the whole detector; achieved rates with 95 % Wilson intervals. Tables: <code>summary.csv</code>, <code>curves.csv</code>, <code>min_detectable.csv</code> in the results folder.</p>
{table}
<h2>Plots</h2>
{figures}
</body></html>
"#,
        study = escape(&m.study),
        deck = escape(&m.deck),
        sha = m.deck_sha256,
        seed = m.seed,
        trials = m.trials,
        detectors = escape(&m.detectors.join(", ")),
        pfa = m.target_pfa,
        version = escape(&m.fdimc_version),
        cmd = escape(&m.command_line.join(" ")),
    ))
}
