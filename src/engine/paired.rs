//! Paired comparison of detector configurations that ran on the same trials (common random numbers):
//! for every pair, on the units both flew to the end (a fault window, or a trial), discordant
//! detections, correct isolations and false alarms with exact McNemar p-values, and the median paired
//! difference of detection (and clearing) delays, `b - a`, over the units both detected (cleared).

use std::collections::BTreeMap;

use polars::prelude::*;

use crate::engine::intervals::mcnemar_exact;

/// One detector's result on one unit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Outcome {
    /// Flown to the end (failed flights are left out of every count).
    pub flown: bool,
    pub faulty: bool,
    pub detected: bool,
    pub isolated: bool,
    pub delay_s: Option<f64>,
    pub clearing_s: Option<f64>,
    pub false_alarm: bool,
    /// The unit that carries the trial's false alarms (a trial with several fault windows counts once).
    pub first_unit_of_trial: bool,
}

/// Outcomes per (trial, unit within the trial) and detector.
pub struct PairedUnits {
    detectors: Vec<String>,
    units: BTreeMap<(u64, Option<u32>), Vec<Option<Outcome>>>,
}

impl PairedUnits {
    pub fn new(detectors: &[String]) -> Self {
        PairedUnits { detectors: detectors.to_vec(), units: BTreeMap::new() }
    }

    /// Records `detector`'s outcome on unit `unit` of trial `trial`; an unknown detector is an error.
    pub fn insert(&mut self, trial: u64, unit: Option<u32>, detector: &str, outcome: Outcome) -> Result<(), String> {
        let d = self.detectors.iter().position(|n| n == detector).ok_or_else(|| {
            format!("unknown detector {detector:?} (the manifest names {})", self.detectors.join(", "))
        })?;
        let n = self.detectors.len();
        self.units.entry((trial, unit)).or_insert_with(|| vec![None; n])[d] = Some(outcome);
        Ok(())
    }

    /// One row per pair of detectors (module docs); the clearing columns only `with_clearing`.
    pub fn compare(&self, with_clearing: bool) -> PolarsResult<DataFrame> {
        let mut c = Comparison::default();
        let n_det = self.detectors.len();
        for a in 0..n_det {
            for b in a + 1..n_det {
                let (mut windows, mut flights) = (0u64, 0u64);
                let mut disc = [[0u64; 2]; 3]; // detection, isolation, false alarm: [a only, b only]
                let mut rate = [[0u64; 2]; 2]; // detected, isolated: [a, b]
                let (mut delay_diff, mut clear_diff) = (Vec::new(), Vec::new());
                for row in self.units.values() {
                    let (Some(x), Some(y)) = (row[a], row[b]) else { continue };
                    if !(x.flown && y.flown) {
                        continue;
                    }
                    if x.faulty {
                        windows += 1;
                        for (k, (u, v)) in [(x.detected, y.detected), (x.isolated, y.isolated)].into_iter().enumerate()
                        {
                            disc[k][0] += (u && !v) as u64;
                            disc[k][1] += (v && !u) as u64;
                            rate[k][0] += u as u64;
                            rate[k][1] += v as u64;
                        }
                        if let (Some(u), Some(v)) = (x.delay_s, y.delay_s) {
                            delay_diff.push(v - u);
                        }
                        if let (Some(u), Some(v)) = (x.clearing_s, y.clearing_s) {
                            clear_diff.push(v - u);
                        }
                    }
                    if x.first_unit_of_trial {
                        flights += 1;
                        disc[2][0] += (x.false_alarm && !y.false_alarm) as u64;
                        disc[2][1] += (y.false_alarm && !x.false_alarm) as u64;
                    }
                }
                let share = |k: u64| if windows > 0 { k as f64 / windows as f64 } else { f64::NAN };
                c.a.push(self.detectors[a].clone());
                c.b.push(self.detectors[b].clone());
                c.windows.push(windows);
                c.pd_a.push(share(rate[0][0]));
                c.pd_b.push(share(rate[0][1]));
                c.det_a_only.push(disc[0][0]);
                c.det_b_only.push(disc[0][1]);
                c.p_det.push(mcnemar_exact(disc[0][0], disc[0][1]));
                c.iso_a.push(share(rate[1][0]));
                c.iso_b.push(share(rate[1][1]));
                c.iso_a_only.push(disc[1][0]);
                c.iso_b_only.push(disc[1][1]);
                c.p_iso.push(mcnemar_exact(disc[1][0], disc[1][1]));
                c.delay_pairs.push(delay_diff.len() as u64);
                c.delay_diff.push(median(&mut delay_diff));
                c.clear_pairs.push(clear_diff.len() as u64);
                c.clear_diff.push(median(&mut clear_diff));
                c.flights.push(flights);
                c.fa_a_only.push(disc[2][0]);
                c.fa_b_only.push(disc[2][1]);
                c.p_fa.push(mcnemar_exact(disc[2][0], disc[2][1]));
            }
        }
        c.into_frame(with_clearing)
    }
}

/// The median (mean of the two middle values for an even count); `None` when empty.
pub fn median(v: &mut [f64]) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let m = v.len() / 2;
    Some(if v.len() % 2 == 1 { v[m] } else { 0.5 * (v[m - 1] + v[m]) })
}

#[derive(Default)]
struct Comparison {
    a: Vec<String>,
    b: Vec<String>,
    windows: Vec<u64>,
    pd_a: Vec<f64>,
    pd_b: Vec<f64>,
    det_a_only: Vec<u64>,
    det_b_only: Vec<u64>,
    p_det: Vec<f64>,
    iso_a: Vec<f64>,
    iso_b: Vec<f64>,
    iso_a_only: Vec<u64>,
    iso_b_only: Vec<u64>,
    p_iso: Vec<f64>,
    delay_pairs: Vec<u64>,
    delay_diff: Vec<Option<f64>>,
    clear_pairs: Vec<u64>,
    clear_diff: Vec<Option<f64>>,
    flights: Vec<u64>,
    fa_a_only: Vec<u64>,
    fa_b_only: Vec<u64>,
    p_fa: Vec<f64>,
}

impl Comparison {
    fn into_frame(self, with_clearing: bool) -> PolarsResult<DataFrame> {
        let mut columns = vec![
            Column::new("detector_a".into(), self.a),
            Column::new("detector_b".into(), self.b),
            Column::new("fault_windows".into(), self.windows),
            Column::new("pd_a".into(), self.pd_a),
            Column::new("pd_b".into(), self.pd_b),
            Column::new("detected_by_a_only".into(), self.det_a_only),
            Column::new("detected_by_b_only".into(), self.det_b_only),
            Column::new("mcnemar_p_detection".into(), self.p_det),
            Column::new("isolated_a".into(), self.iso_a),
            Column::new("isolated_b".into(), self.iso_b),
            Column::new("isolated_by_a_only".into(), self.iso_a_only),
            Column::new("isolated_by_b_only".into(), self.iso_b_only),
            Column::new("mcnemar_p_isolation".into(), self.p_iso),
            Column::new("delay_pairs".into(), self.delay_pairs),
            Column::new("median_delay_b_minus_a_s".into(), self.delay_diff),
        ];
        if with_clearing {
            columns.push(Column::new("clearing_pairs".into(), self.clear_pairs));
            columns.push(Column::new("median_clearing_b_minus_a_s".into(), self.clear_diff));
        }
        columns.extend([
            Column::new("flights".into(), self.flights),
            Column::new("false_alarm_a_only".into(), self.fa_a_only),
            Column::new("false_alarm_b_only".into(), self.fa_b_only),
            Column::new("mcnemar_p_false_alarm".into(), self.p_fa),
        ]);
        DataFrame::new_infer_height(columns)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn median_of_odd_and_even_counts() {
        assert_eq!(median(&mut []), None);
        assert_eq!(median(&mut [3.0, 1.0, 2.0]), Some(2.0));
        assert_eq!(median(&mut [4.0, 1.0, 3.0, 2.0]), Some(2.5));
    }
}
