//! The summary's tables from the aggregates: groups (`summary`, `curves`), `detectors.csv`,
//! `confusion.csv`, `min_detectable.csv`, and the size bins' units and edges.

use std::collections::HashMap;

use polars::prelude::*;

use crate::engine::results::schema::col;
use crate::engine::results::schema::unit;
use crate::engine::results::summary_spec::{Extra, Isolates, SummarySpec};
use crate::engine::results::text;
use crate::engine::results::thresholds::DECK;
use crate::engine::stats::intervals::{Z95, wilson};

use super::aggregate::{Aggregates, Counts, Names, number_of};

/// The key columns of a table, by position in a group key.
pub(super) struct KeyColumns {
    pub(super) names: Vec<String>,
    /// Per key position: text (an interned name) or a number.
    pub(super) text: Vec<bool>,
}

/// A table of groups: the key columns, then the counts, rates, delays and (with `extras`) the kind's
/// aggregates, sorted by key (text ascending, numbers ascending, nulls last).
pub(super) fn group_table(
    groups: &[(Vec<u64>, Counts)],
    keys: &KeyColumns,
    names: &Names,
    sets: &[&str],
    spec: &SummarySpec,
    extras: bool,
) -> PolarsResult<DataFrame> {
    let mut rows: Vec<&(Vec<u64>, Counts)> = groups.iter().collect();
    let text_of = |k: usize, v: u64| if k == 0 { Some(sets[v as usize]) } else { names.name(v) };
    rows.sort_by(|a, b| {
        for k in 0..keys.names.len() {
            let o = if keys.text[k] {
                match (text_of(k, a.0[k]), text_of(k, b.0[k])) {
                    (Some(x), Some(y)) => x.cmp(y),
                    (x, y) => x.is_none().cmp(&y.is_none()),
                }
            } else {
                match (number_of(a.0[k]), number_of(b.0[k])) {
                    (Some(x), Some(y)) => x.total_cmp(&y),
                    (x, y) => x.is_none().cmp(&y.is_none()),
                }
            };
            if o != std::cmp::Ordering::Equal {
                return o;
            }
        }
        std::cmp::Ordering::Equal
    });
    let mut columns = Vec::new();
    for (k, name) in keys.names.iter().enumerate() {
        if keys.text[k] {
            let v: Vec<Option<&str>> = rows.iter().map(|r| text_of(k, r.0[k])).collect();
            columns.push(Column::new(name.as_str().into(), v));
        } else {
            let v: Vec<Option<f64>> = rows.iter().map(|r| number_of(r.0[k])).collect();
            columns.push(Column::new(name.as_str().into(), v));
        }
    }
    let counts: Vec<&Counts> = rows.iter().map(|r| &r.1).collect();
    let deck = |r: &&(Vec<u64>, Counts)| sets[r.0[0] as usize] == DECK;
    let at_deck: Vec<bool> = rows.iter().map(deck).collect();
    columns.extend(count_columns(&counts, spec, extras.then_some(at_deck.as_slice())));
    DataFrame::new_infer_height(columns)
}

/// The shared counts, rates and delays of `counts`, then (with `at_deck`: per row, whether it is of the
/// deck's set; the others have no kind aggregates) the kind's aggregates.
pub(super) fn count_columns(counts: &[&Counts], spec: &SummarySpec, at_deck: Option<&[bool]>) -> Vec<Column> {
    let u = |f: &dyn Fn(&Counts) -> u64| counts.iter().map(|c| f(c)).collect::<Vec<u64>>();
    let mut columns = vec![
        Column::new("trials".into(), u(&|c| c.units)),
        Column::new("failed".into(), u(&|c| c.failed)),
        Column::new("diverged".into(), u(&|c| c.diverged)),
        Column::new("truth_diverged".into(), u(&|c| c.truth_diverged)),
        Column::new("false_alarms".into(), u(&|c| c.false_alarms)),
        Column::new("detected".into(), u(&|c| c.detected)),
        Column::new(
            "missed".into(),
            counts.iter().map(|c| c.faulty.then(|| c.flown() - c.detected)).collect::<Vec<Option<u64>>>(),
        ),
        Column::new("late_alarms".into(), u(&|c| c.late_alarms)),
        Column::new("isolation_decided".into(), u(&|c| c.decided)),
        Column::new("isolated_correctly".into(), u(&|c| c.correct)),
    ];
    let pairs = |f: &dyn Fn(&Counts) -> (u64, u64, bool)| counts.iter().map(|c| f(c)).collect::<Vec<_>>();
    columns.extend(rate_columns("pd", &pairs(&|c| (c.detected, c.flown(), c.faulty))));
    columns.extend(rate_columns("pfa", &pairs(&|c| (c.false_alarms, c.flown(), true))));
    columns.extend(rate_columns("isolation_accuracy", &pairs(&|c| (c.correct, c.decided, true))));
    for (name, p) in [("delay_p50_s", 0.5), ("delay_p90_s", 0.9), ("delay_p99_s", 0.99)] {
        columns.push(Column::new(name.into(), counts.iter().map(|c| c.delay.quantile(p)).collect::<Vec<_>>()));
    }
    columns.extend(hazard_columns(counts));
    if let Some(at_deck) = at_deck {
        columns.extend(extra_columns(counts, spec, at_deck));
    }
    columns
}

/// A deck with times to hazard: P(a fault is not detected within its time to hazard), over the faulty
/// units that have one (`time_to_hazard_s` blank where the row's units differ in it); none without.
fn hazard_columns(counts: &[&Counts]) -> Vec<Column> {
    if !counts.iter().any(|c| c.hazard_units > 0) {
        return Vec::new();
    }
    let some = |c: &Counts| c.hazard_units > 0;
    let missed: Vec<_> =
        counts.iter().map(|c| (c.hazard_units - c.detected_in_time, c.hazard_units, some(c))).collect();
    let mut columns = vec![
        Column::new(
            "time_to_hazard_s".into(),
            counts.iter().map(|c| c.hazard_s.filter(|t| some(c) && !t.is_nan())).collect::<Vec<_>>(),
        ),
        Column::new(
            "hazard_units".into(),
            counts.iter().map(|c| some(c).then_some(c.hazard_units)).collect::<Vec<_>>(),
        ),
        Column::new(
            "missed_before_hazard".into(),
            counts.iter().map(|c| some(c).then(|| c.hazard_units - c.detected_in_time)).collect::<Vec<_>>(),
        ),
    ];
    columns.extend(rate_columns("p_miss_before_hazard", &missed));
    columns
}

/// The kind's aggregates of `counts`; rows not of the deck's set (`at_deck` false) have none.
pub(super) fn extra_columns(counts: &[&Counts], spec: &SummarySpec, at_deck: &[bool]) -> Vec<Column> {
    let mut columns = Vec::new();
    for (k, e) in spec.extras.iter().enumerate() {
        match *e {
            Extra::Quantile { name, p, .. } => {
                let v: Vec<Option<f64>> =
                    counts.iter().zip(at_deck).map(|(c, &d)| c.extra_values[k].quantile(p).filter(|_| d)).collect();
                columns.push(Column::new(name.into(), v));
            }
            Extra::Rate { name, k: num, n: den, faulty_only } => {
                let count = |c: &Counts, which: &str| -> u64 {
                    match which {
                        "flown" => c.flown(),
                        "isolation_decided" => c.decided,
                        other => spec.extras.iter().position(|e| e.name() == other).map_or(0, |j| c.extra_counts[j]),
                    }
                };
                let v: Vec<(u64, u64, bool)> = counts
                    .iter()
                    .zip(at_deck)
                    .map(|(c, &d)| (count(c, num), if d { count(c, den) } else { 0 }, !faulty_only || c.faulty))
                    .collect();
                columns.extend(rate_columns(name, &v));
            }
            _ => {
                let v: Vec<Option<u64>> =
                    counts.iter().zip(at_deck).map(|(c, &d)| d.then_some(c.extra_counts[k])).collect();
                columns.push(Column::new(e.name().into(), v));
            }
        }
    }
    columns
}

/// `name`, `name_lo`, `name_hi`: `k / n` with its 95 % Wilson interval, null where `n = 0` or not kept.
pub(super) fn rate_columns(name: &str, rates: &[(u64, u64, bool)]) -> [Column; 3] {
    let mut cols: [Vec<Option<f64>>; 3] = Default::default();
    for &(k, n, keep) in rates {
        let ok = keep && n > 0;
        let (lo, hi) = wilson(k, n, Z95);
        cols[0].push(ok.then(|| k as f64 / n as f64));
        cols[1].push(ok.then_some(lo));
        cols[2].push(ok.then_some(hi));
    }
    let [rate, lo, hi] = cols;
    [
        Column::new(name.into(), rate),
        Column::new(format!("{name}_lo").into(), lo),
        Column::new(format!("{name}_hi").into(), hi),
    ]
}

/// `detectors.csv` (module docs), sets in order, detectors in the manifest's order.
pub(super) fn detector_table(agg: &Aggregates, sets: &[&'static str], spec: &SummarySpec) -> PolarsResult<DataFrame> {
    let nd = agg.detectors.len();
    let (mut set_col, mut det_col) = (Vec::new(), Vec::new());
    let (mut faulty, mut trials, mut isolation, mut at_deck) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for (s, set) in sets.iter().enumerate() {
        for (d, name) in agg.detectors.iter().enumerate() {
            let (units, faulty_units, per_trial) = &agg.per_detector[s * nd + d];
            set_col.push(*set);
            det_col.push(name.as_str());
            let f = faulty_units.clone();
            isolation.push(match spec.isolates {
                Isolates::Target => (f.correct, f.decided),
                Isolates::Kind => (units.correct, units.decided),
            });
            faulty.push(f);
            trials.push(per_trial.clone());
            at_deck.push(*set == DECK);
        }
    }
    let f: Vec<&Counts> = faulty.iter().collect();
    let mut columns = vec![
        Column::new("thresholds".into(), set_col),
        Column::new(col::DETECTOR.into(), det_col),
        Column::new("faulty_units".into(), f.iter().map(|c| c.units).collect::<Vec<u64>>()),
        Column::new("detected".into(), f.iter().map(|c| c.detected).collect::<Vec<u64>>()),
        Column::new("late_alarms".into(), f.iter().map(|c| c.late_alarms).collect::<Vec<u64>>()),
    ];
    columns.extend(rate_columns("pd", &f.iter().map(|c| (c.detected, c.flown(), true)).collect::<Vec<_>>()));
    columns.push(Column::new("isolation_decided".into(), isolation.iter().map(|i| i.1).collect::<Vec<u64>>()));
    columns.push(Column::new("isolated_correctly".into(), isolation.iter().map(|i| i.0).collect::<Vec<u64>>()));
    columns
        .extend(rate_columns("isolation_accuracy", &isolation.iter().map(|&(k, n)| (k, n, true)).collect::<Vec<_>>()));
    for (name, p) in [("delay_p50_s", 0.5), ("delay_p90_s", 0.9), ("delay_p99_s", 0.99)] {
        columns.push(Column::new(name.into(), f.iter().map(|c| c.delay.quantile(p)).collect::<Vec<_>>()));
    }
    columns.extend(hazard_columns(&f));
    columns.extend(extra_columns(&f, spec, &at_deck));
    columns.extend([
        Column::new("flights".into(), trials.iter().map(|c| c.units).collect::<Vec<u64>>()),
        Column::new("flights_failed".into(), trials.iter().map(|c| c.failed).collect::<Vec<u64>>()),
        Column::new("flights_diverged".into(), trials.iter().map(|c| c.diverged).collect::<Vec<u64>>()),
        Column::new("flights_truth_diverged".into(), trials.iter().map(|c| c.truth_diverged).collect::<Vec<u64>>()),
        Column::new("flights_with_false_alarm".into(), trials.iter().map(|c| c.false_alarms).collect::<Vec<u64>>()),
    ]);
    columns.extend(rate_columns("pfa", &trials.iter().map(|c| (c.false_alarms, c.flown(), true)).collect::<Vec<_>>()));
    DataFrame::new_infer_height(columns)
}

/// `confusion.csv`: detector (manifest order) x truth x isolated (`none`: nothing named).
pub(super) fn confusion_table(agg: &Aggregates, names: &Names) -> PolarsResult<DataFrame> {
    let mut rows: Vec<(usize, Option<&str>, Option<&str>, u64)> =
        agg.confusion.iter().map(|(&(d, t, i), &n)| (d, names.name(t as u64), names.name(i as u64), n)).collect();
    rows.sort_by(|a, b| (a.0, a.1, a.2.is_none(), a.2).cmp(&(b.0, b.1, b.2.is_none(), b.2)));
    let mut truth_total: HashMap<(usize, Option<&str>), u64> = HashMap::new();
    for r in &rows {
        *truth_total.entry((r.0, r.1)).or_insert(0) += r.3;
    }
    DataFrame::new_infer_height(vec![
        Column::new(col::DETECTOR.into(), rows.iter().map(|r| agg.detectors[r.0].as_str()).collect::<Vec<_>>()),
        Column::new("truth".into(), rows.iter().map(|r| r.1).collect::<Vec<_>>()),
        Column::new(col::ISOLATED.into(), rows.iter().map(|r| r.2.unwrap_or(col::NO_FAULT)).collect::<Vec<_>>()),
        Column::new("units".into(), rows.iter().map(|r| r.3).collect::<Vec<u64>>()),
        Column::new(
            "share_of_truth".into(),
            rows.iter().map(|r| r.3 as f64 / truth_total[&(r.0, r.1)] as f64).collect::<Vec<f64>>(),
        ),
    ])
}

/// Smallest fault (by magnitude: |size|, or |factor - 1| for gain) whose size bin has Pd >= 0.9 (point
/// estimate, and with the Wilson lower bound >= 0.9), per (thresholds, detector, kind, target). A gain
/// whose bins are already deviations (`units` says [`unit::GAIN_DEVIATION_BINS`]) is ordered by them.
pub(super) fn min_detectable(
    curves: &DataFrame,
    units: &std::collections::BTreeMap<String, String>,
) -> PolarsResult<DataFrame> {
    let s = |n: &str| curves.column(n).and_then(|c| c.str().cloned());
    let (set, det, kind, target) = (s("thresholds")?, s(col::DETECTOR)?, s(col::KIND)?, s(col::TARGET)?);
    let size = curves.column(col::SIZE_BIN)?.f64()?.clone();
    let pd = curves.column("pd")?.f64()?.clone();
    let lo = curves.column("pd_lo")?.f64()?.clone();
    type Key = (String, String, String, String);
    // Per key: (magnitude, size) of the smallest qualifying bin, point estimate and lower bound; and
    // the largest size flown with its Pd, to say why a key has none.
    struct Row {
        key: Key,
        pd90: Option<(f64, f64)>,
        lower_bound: Option<(f64, f64)>,
        largest: Option<(f64, f64, f64)>,
    }
    let mut rows: Vec<Row> = Vec::new();
    for i in 0..curves.height() {
        let (Some(k), Some(o), Some(sz)) = (kind.get(i), target.get(i), size.get(i)) else { continue };
        let Some(p) = pd.get(i) else {
            continue; // fault-free, or nothing flown
        };
        let key: Key =
            (set.get(i).unwrap_or_default().into(), det.get(i).unwrap_or_default().into(), k.into(), o.into());
        let idx = match rows.iter().position(|r| r.key == key) {
            Some(p) => p,
            None => {
                rows.push(Row { key, pd90: None, lower_bound: None, largest: None });
                rows.len() - 1
            }
        };
        let factor_bins = k == "gain" && units.get(k).is_none_or(|u| u != unit::GAIN_DEVIATION_BINS);
        let magnitude = if factor_bins { (sz - 1.0).abs() } else { sz.abs() };
        let better = |cur: Option<(f64, f64)>| cur.is_none_or(|(m, _)| magnitude < m);
        let row = &mut rows[idx];
        if p >= 0.9 && better(row.pd90) {
            row.pd90 = Some((magnitude, sz));
        }
        if lo.get(i).is_some_and(|p| p >= 0.9) && better(row.lower_bound) {
            row.lower_bound = Some((magnitude, sz));
        }
        if row.largest.is_none_or(|(m, _, _)| magnitude > m) {
            row.largest = Some((magnitude, sz, p));
        }
    }
    // A blank says why: no bin reached Pd 0.9 (or its lower bound), up to the largest size flown.
    let note = |r: &Row| -> Option<String> {
        let (_, size, p) = r.largest?;
        let at = format!("the largest size flown, {}, has Pd {}", text::significant(size), text::rate(p));
        match (r.pd90, r.lower_bound) {
            (None, _) => Some(format!("no size bin reaches Pd 0.9: {at}")),
            (Some(_), None) => Some(format!("no size bin's Pd lower 95 % bound reaches 0.9: {at}")),
            _ => None,
        }
    };
    let key = |f: fn(&Key) -> &String| rows.iter().map(|r| f(&r.key).clone()).collect::<Vec<_>>();
    DataFrame::new_infer_height(vec![
        Column::new("thresholds".into(), key(|k| &k.0)),
        Column::new(col::DETECTOR.into(), key(|k| &k.1)),
        Column::new(col::KIND.into(), key(|k| &k.2)),
        Column::new(col::TARGET.into(), key(|k| &k.3)),
        Column::new("min_size_pd90".into(), rows.iter().map(|r| r.pd90.map(|x| x.1)).collect::<Vec<_>>()),
        Column::new(
            "min_size_pd90_lower_bound".into(),
            rows.iter().map(|r| r.lower_bound.map(|x| x.1)).collect::<Vec<_>>(),
        ),
        Column::new("min_size_note".into(), rows.iter().map(note).collect::<Vec<_>>()),
    ])
}

/// Appends `size_unit`, the unit of each row's fault size (and `size_bin`, `min_size_pd90`), from the
/// manifest's units per fault kind: last, so that `check`'s key columns (those before `trials`) stay.
pub(super) fn with_size_unit(
    df: &mut DataFrame,
    units: &std::collections::BTreeMap<String, String>,
) -> PolarsResult<()> {
    let kinds = df.column(col::KIND)?.str()?.clone();
    let unit: Vec<Option<&str>> = kinds.iter().map(|k| k.and_then(|k| units.get(k)).map(String::as_str)).collect();
    df.with_column(Column::new("size_unit".into(), unit))?;
    Ok(())
}

/// Appends `target_pfa` and `confidence`: what the thresholds of each row's set were calibrated for
/// (null on the deck's rows, whose thresholds the deck gives; `confidence` null for a plain
/// calibration), so a table read on its own says at what false-alarm rate its rates were bought.
/// Last, as [`with_size_unit`].
pub(super) fn with_calibration(
    df: &mut DataFrame,
    target_pfa: Option<f64>,
    confidence: Option<f64>,
) -> PolarsResult<()> {
    let sets = df.column("thresholds")?.str()?.clone();
    let of = |v: Option<f64>| -> Vec<Option<f64>> { sets.iter().map(|s| v.filter(|_| s != Some(DECK))).collect() };
    df.with_column(Column::new("target_pfa".into(), of(target_pfa)))?;
    df.with_column(Column::new("confidence".into(), of(confidence)))?;
    Ok(())
}

/// Appends `<centre>_lo` and `<centre>_hi`, the edges of the size bin whose centre is in column
/// `centre`, from the manifest's bins per fault kind: the bin with that centre (to rounding), or the
/// value itself where the size was listed or fixed (or the folder predates recorded bins). Last, as
/// [`with_size_unit`].
pub(super) fn with_bin_edges(
    df: &mut DataFrame,
    centre: &str,
    bins: &crate::engine::scenario::deck::SizeBins,
) -> PolarsResult<()> {
    let kinds = df.column(col::KIND)?.str()?.clone();
    let centres = df.column(centre)?.f64()?.clone();
    let edges: Vec<Option<[f64; 2]>> = (kinds.iter().zip(centres.iter()))
        .map(|(kind, c)| {
            let c = c?;
            let of_kind = kind.and_then(|k| bins.get(k)).map(Vec::as_slice).unwrap_or_default();
            let near = |e: &&[f64; 2]| (0.5 * (e[0] + e[1]) - c).abs() <= 1e-9 * (e[1] - e[0]).abs().max(1e-300);
            Some(of_kind.iter().find(near).copied().unwrap_or([c, c]))
        })
        .collect();
    for (side, name) in [(0, "lo"), (1, "hi")] {
        let values: Vec<Option<f64>> = edges.iter().map(|e| e.map(|e| e[side])).collect();
        df.with_column(Column::new(format!("{centre}_{name}").into(), values))?;
    }
    Ok(())
}
