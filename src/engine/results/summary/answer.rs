//! The answer at a glance: per detector, at the thresholds in use, where those came from, the
//! false-alarm probability on fault-free flights, Pd over all faults and per fault kind, the delays
//! and the smallest detectable fault per target. Written as `answer.csv`, printed last by `run`,
//! `summarize` and `merge`, and the first table of the report.

use std::collections::BTreeMap;

use polars::prelude::*;

use crate::engine::results::schema::col;
use crate::engine::results::tables::Table;
use crate::engine::results::text::{proportion, significant};
use crate::engine::results::thresholds::DECK;
use crate::engine::stats::intervals::{Z95, wilson};

pub const ANSWER_FILE: &str = "answer.csv";

/// The threshold set the answer reads: another run's thresholds when validating, else the calibrated
/// ones, else the deck's.
pub fn set_in_use(detectors: &DataFrame) -> String {
    let sets = Table(detectors).strs("thresholds");
    ["validation", "calibrated"].into_iter().find(|s| sets.iter().any(|x| x == s)).unwrap_or(DECK).to_string()
}

/// Per detector of `set`: its thresholds by statistic (`thresholds`: detector, values; `source`: where
/// they came from), read with `summary`, `detectors` and `min_detectable` (the tables `summarize`
/// wrote) into the rows of `answer.csv`.
pub fn answer(
    set: &str,
    thresholds: &[(String, String)],
    source: &str,
    summary: &DataFrame,
    detectors: &DataFrame,
    min_detectable: &DataFrame,
) -> PolarsResult<DataFrame> {
    let d = Table(detectors);
    let (d_sets, d_names) = (d.strs("thresholds"), d.strs(col::DETECTOR));
    let (faulty, detected) = (d.u64s("faulty_units"), d.u64s("detected"));
    let (pd, pd_lo, pd_hi) = (d.f64s("pd"), d.f64s("pd_lo"), d.f64s("pd_hi"));
    let (p50, p90) = (d.f64s("delay_p50_s"), d.f64s("delay_p90_s"));

    // Fault-free flights and per-kind detections, summed over the summary's groups.
    let s = Table(summary);
    let (s_sets, s_names, kinds) = (s.strs("thresholds"), s.strs(col::DETECTOR), s.strs(col::KIND));
    let (trials, failed, alarms, hits) =
        (s.u64s("trials"), s.u64s("failed"), s.u64s("false_alarms"), s.u64s("detected"));
    let faulty_row = s.f64s("pd");
    let mut quiet: BTreeMap<&str, (u64, u64)> = BTreeMap::new();
    let mut by_kind: BTreeMap<&str, BTreeMap<&str, (u64, u64)>> = BTreeMap::new();
    // Per detector and kind with a time to hazard: (missed before it, units, the time when one); the
    // columns are NaN throughout without one.
    let (hazard_units, missed_in_time, hazard_s) =
        (s.f64s("hazard_units"), s.f64s("missed_before_hazard"), s.f64s("time_to_hazard_s"));
    let mut by_hazard: BTreeMap<&str, BTreeMap<&str, (u64, u64, Option<f64>)>> = BTreeMap::new();
    for i in 0..summary.height() {
        if s_sets[i] != set {
            continue;
        }
        let flown = trials[i] - failed[i];
        // A group without faulty units (pd blank) is fault-free, whatever the kind calls it (`none`,
        // a classifier's `normal`).
        if faulty_row[i].is_nan() {
            let e = quiet.entry(s_names[i].as_str()).or_default();
            *e = (e.0 + alarms[i], e.1 + flown);
        } else {
            let e = by_kind.entry(s_names[i].as_str()).or_default().entry(kinds[i].as_str()).or_default();
            *e = (e.0 + hits[i], e.1 + flown);
            if !hazard_units[i].is_nan() {
                let h = by_hazard.entry(s_names[i].as_str()).or_default().entry(kinds[i].as_str()).or_insert((
                    0,
                    0,
                    Some(hazard_s[i]),
                ));
                h.0 += missed_in_time[i] as u64;
                h.1 += hazard_units[i] as u64;
                // One time for the kind when all its rows share it (a target's own otherwise).
                h.2 = h.2.filter(|t| t.to_bits() == hazard_s[i].to_bits());
            }
        }
    }

    // The smallest size with Pd >= 0.9, per detector and kind, over the targets.
    let m = Table(min_detectable);
    let (m_sets, m_names, m_kinds, m_targets, m_units) =
        (m.strs("thresholds"), m.strs(col::DETECTOR), m.strs(col::KIND), m.strs(col::TARGET), m.strs("size_unit"));
    let smallest = m.f64s("min_size_pd90");
    let mut sizes: BTreeMap<&str, BTreeMap<&str, (Vec<(String, f64)>, String)>> = BTreeMap::new();
    for i in 0..min_detectable.height() {
        if m_sets[i] != set {
            continue;
        }
        let e = sizes.entry(m_names[i].as_str()).or_default().entry(m_kinds[i].as_str()).or_default();
        e.0.push((m_targets[i].clone(), smallest[i]));
        e.1 = m_units[i].clone();
    }

    let mut rows = Rows::default();
    for i in (0..detectors.height()).filter(|&i| d_sets[i] == set) {
        let name = d_names[i].as_str();
        let (false_alarms, flights) = quiet.get(name).copied().unwrap_or_default();
        let (lo, hi) = if flights > 0 { wilson(false_alarms, flights, Z95) } else { (f64::NAN, f64::NAN) };
        let pfa = if flights > 0 { false_alarms as f64 / flights as f64 } else { f64::NAN };
        let per_kind: Vec<String> = by_kind
            .get(name)
            .into_iter()
            .flatten()
            .map(|(kind, &(k, n))| format!("{kind} {}", proportion(k, n)))
            .collect();
        let detectable: Vec<String> = sizes
            .get(name)
            .into_iter()
            .flatten()
            .map(|(kind, (targets, unit))| format!("{kind}: {} ({unit})", per_target(targets)))
            .collect();
        rows.set.push(set.to_string());
        rows.detector.push(name.to_string());
        rows.source.push(source.to_string());
        rows.values.push(thresholds.iter().find(|(d, _)| d == name).map(|(_, v)| v.clone()));
        rows.flights.push(flights);
        rows.false_alarms.push(false_alarms);
        rows.pfa.push([pfa, lo, hi]);
        rows.faulty.push(faulty[i]);
        rows.detected.push(detected[i]);
        rows.pd.push([pd[i], pd_lo[i], pd_hi[i]]);
        rows.per_kind.push(Some(per_kind.join("; ")).filter(|s| !s.is_empty()));
        rows.delays.push([p50[i], p90[i]]);
        rows.detectable.push(Some(detectable.join("; ")).filter(|s| !s.is_empty()));
        let missed: Vec<String> = by_hazard
            .get(name)
            .into_iter()
            .flatten()
            .map(|(kind, &(k, n, t))| {
                let within = t
                    .filter(|t| !t.is_nan())
                    .map_or("its target's time".to_string(), |t| format!("{} s", significant(t)));
                format!("{kind} within {within} {}", proportion(k, n))
            })
            .collect();
        rows.missed_before_hazard.push(Some(missed.join("; ")).filter(|s| !s.is_empty()));
    }
    rows.frame()
}

/// `q_rad_s 7, v_m_s 11, h_m none`, or `15 on every target` when they agree.
fn per_target(targets: &[(String, f64)]) -> String {
    let text = |v: f64| if v.is_nan() { "none".to_string() } else { significant(v) };
    if targets.len() > 1 && targets.iter().all(|(_, v)| v.to_bits() == targets[0].1.to_bits()) {
        return format!("{} on every target", text(targets[0].1));
    }
    targets.iter().map(|(t, v)| format!("{t} {}", text(*v))).collect::<Vec<_>>().join(", ")
}

#[derive(Default)]
struct Rows {
    set: Vec<String>,
    detector: Vec<String>,
    source: Vec<String>,
    values: Vec<Option<String>>,
    flights: Vec<u64>,
    false_alarms: Vec<u64>,
    pfa: Vec<[f64; 3]>,
    faulty: Vec<u64>,
    detected: Vec<u64>,
    pd: Vec<[f64; 3]>,
    per_kind: Vec<Option<String>>,
    delays: Vec<[f64; 2]>,
    detectable: Vec<Option<String>>,
    missed_before_hazard: Vec<Option<String>>,
}

impl Rows {
    fn frame(self) -> PolarsResult<DataFrame> {
        let nan = |v: f64| (!v.is_nan()).then_some(v);
        let at = |v: &[[f64; 3]], k: usize| v.iter().map(|x| nan(x[k])).collect::<Vec<_>>();
        DataFrame::new_infer_height(vec![
            Column::new("thresholds".into(), self.set),
            Column::new(col::DETECTOR.into(), self.detector),
            Column::new("threshold_source".into(), self.source),
            Column::new("threshold_values".into(), self.values),
            Column::new("fault_free_flights".into(), self.flights),
            Column::new("fault_free_false_alarms".into(), self.false_alarms),
            Column::new("pfa_fault_free".into(), at(&self.pfa, 0)),
            Column::new("pfa_fault_free_lo".into(), at(&self.pfa, 1)),
            Column::new("pfa_fault_free_hi".into(), at(&self.pfa, 2)),
            Column::new("faulty_units".into(), self.faulty),
            Column::new("detected".into(), self.detected),
            Column::new("pd".into(), at(&self.pd, 0)),
            Column::new("pd_lo".into(), at(&self.pd, 1)),
            Column::new("pd_hi".into(), at(&self.pd, 2)),
            Column::new("pd_by_fault".into(), self.per_kind),
            Column::new("delay_p50_s".into(), self.delays.iter().map(|x| nan(x[0])).collect::<Vec<_>>()),
            Column::new("delay_p90_s".into(), self.delays.iter().map(|x| nan(x[1])).collect::<Vec<_>>()),
            Column::new("min_size_pd90".into(), self.detectable),
            Column::new("p_miss_before_hazard".into(), self.missed_before_hazard),
        ])
    }
}

/// The answer's lines on the console: a line per detector, then its Pd per fault kind and its
/// probability of missing the hazard, each on a line of its own; with `details` (`--verbose`) also
/// the smallest detectable faults and the thresholds, which otherwise the header names once.
pub fn print(answer: &DataFrame, details: bool) {
    let t = Table(answer);
    if answer.height() == 0 {
        return;
    }
    let (names, sources, values) = (t.strs(col::DETECTOR), t.strs("threshold_source"), t.strs("threshold_values"));
    let (flights, faulty) = (t.u64s("fault_free_flights"), t.u64s("faulty_units"));
    let (pfa, pd) = (t.rates("pfa_fault_free"), t.rates("pd"));
    let delay = t.delays("delay_p50_s", "delay_p90_s");
    let (per_kind, detectable) = (t.strs("pd_by_fault"), t.strs("min_size_pd90"));
    let hazard = t.strs("p_miss_before_hazard");
    let set = t.strs("thresholds");
    let source =
        if !details && sources.iter().all(|x| *x == sources[0]) { format!("{}; ", sources[0]) } else { String::new() };
    println!("  answer, at the {} thresholds ({source}answer.csv; 95 % Wilson intervals):", set[0]);
    let width = names.iter().map(String::len).max().unwrap_or(0);
    for i in 0..names.len() {
        let quiet = if flights[i] > 0 {
            format!("{} on {} fault-free flights", pfa[i], flights[i])
        } else {
            "- (no fault-free flights)".into()
        };
        let caught = if faulty[i] > 0 { format!("{} on {} faulty", pd[i], faulty[i]) } else { "- (no faults)".into() };
        println!("    {:<width$}  Pfa {quiet}; Pd {caught}; delay p50/p90 {}", names[i], delay[i]);
        let pad = " ".repeat(width);
        if !per_kind[i].is_empty() {
            println!("    {pad}  Pd by fault: {}", per_kind[i]);
        }
        if details && !detectable[i].is_empty() {
            println!("    {pad}  smallest with Pd >= 0.9: {}", detectable[i]);
        }
        if !hazard[i].is_empty() {
            println!("    {pad}  P(not detected before the hazard): {}", hazard[i]);
        }
        if !details {
            continue;
        }
        println!(
            "    {pad}  thresholds: {}{}",
            sources[i],
            if values[i].is_empty() { String::new() } else { format!(": {}", values[i]) }
        );
    }
}
