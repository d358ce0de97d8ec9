//! Paired comparison of detector configurations that ran on the same trials (common random numbers),
//! streamed: the rows of one trial are consecutive, so a trial's units are compared when the next trial
//! begins and nothing is kept of it afterwards.
//!
//! For every pair of detectors, over the units both flew to the end: discordant detections and correct
//! isolations (among the faulty units; among all units for classifiers, which name a class for every
//! unit) and discordant false alarms (once per trial, on its first unit), each with an exact McNemar
//! p-value, and the median paired difference `b - a`, with its 95 % sign-test interval, of the
//! detection delay and of any other per-unit value a kind names (a delay, an estimation error), over
//! the units both have a value for.

use polars::prelude::*;

use crate::engine::stats::intervals::mcnemar_exact;
use crate::engine::stats::quantiles::Quantiles;

/// One detector's result on one unit.
#[derive(Debug, Clone, PartialEq)]
pub struct UnitOutcome {
    /// Flown to the end (failed units are left out of every count).
    pub flown: bool,
    pub faulty: bool,
    pub detected: bool,
    pub isolated: bool,
    pub false_alarm: bool,
    /// The detection delay, then the kind's own paired columns ([`PairedUnits::new`]'s `paired`).
    pub paired: Vec<Option<f64>>,
}

/// Counts of one pair of detectors.
#[derive(Debug, Clone, Default)]
struct PairCounts {
    units: u64,
    flights: u64,
    /// detection, isolation, false alarm: [a only, b only]
    discordant: [[u64; 2]; 3],
    /// detected, isolated: [a, b]
    positive: [[u64; 2]; 2],
    /// Per paired value (the detection delay first): the differences b - a where both have one.
    differences: Vec<Quantiles>,
}

/// Units per (trial, detector) as they stream past, and the pairs' counts so far.
pub struct PairedUnits {
    detectors: Vec<String>,
    paired_names: Vec<String>,
    /// Classifiers: isolation is compared on every unit, not only on the faulty ones.
    isolation_on_all_units: bool,
    trial: Option<u64>,
    current: Vec<Vec<UnitOutcome>>,
    pairs: Vec<PairCounts>,
}

impl PairedUnits {
    /// `paired`: the kind's own columns compared after the detection delay (for column names).
    pub fn new(detectors: &[String], paired: &[&str], isolation_on_all_units: bool) -> Self {
        let n = detectors.len();
        let pair = PairCounts { differences: vec![Quantiles::default(); 1 + paired.len()], ..Default::default() };
        PairedUnits {
            detectors: detectors.to_vec(),
            paired_names: paired.iter().map(|s| s.to_string()).collect(),
            isolation_on_all_units,
            trial: None,
            current: vec![Vec::new(); n],
            pairs: vec![pair; n * n.saturating_sub(1) / 2],
        }
    }

    /// The next unit of `detector` (index in the manifest's order) in trial `trial`; rows must come
    /// in trial order.
    pub fn push(&mut self, trial: u64, detector: usize, outcome: UnitOutcome) {
        if self.trial != Some(trial) {
            self.flush();
            self.trial = Some(trial);
        }
        self.current[detector].push(outcome);
    }

    /// Compares the units of the trial held, and forgets them.
    fn flush(&mut self) {
        let n = self.detectors.len();
        let mut p = 0;
        for a in 0..n {
            for b in a + 1..n {
                let c = &mut self.pairs[p];
                p += 1;
                for (k, (x, y)) in self.current[a].iter().zip(&self.current[b]).enumerate() {
                    if !(x.flown && y.flown) {
                        continue;
                    }
                    if x.faulty {
                        c.units += 1;
                        c.discordant[0][0] += (x.detected && !y.detected) as u64;
                        c.discordant[0][1] += (y.detected && !x.detected) as u64;
                        c.positive[0][0] += x.detected as u64;
                        c.positive[0][1] += y.detected as u64;
                        for (q, (u, v)) in c.differences.iter_mut().zip(x.paired.iter().zip(&y.paired)) {
                            if let (Some(u), Some(v)) = (u, v) {
                                q.push(v - u);
                            }
                        }
                    }
                    if x.faulty || self.isolation_on_all_units {
                        c.discordant[1][0] += (x.isolated && !y.isolated) as u64;
                        c.discordant[1][1] += (y.isolated && !x.isolated) as u64;
                        c.positive[1][0] += x.isolated as u64;
                        c.positive[1][1] += y.isolated as u64;
                    }
                    if k == 0 {
                        c.flights += 1;
                        c.discordant[2][0] += (x.false_alarm && !y.false_alarm) as u64;
                        c.discordant[2][1] += (y.false_alarm && !x.false_alarm) as u64;
                    }
                }
            }
        }
        self.current.iter_mut().for_each(Vec::clear);
    }

    /// One row per pair of detectors (module docs).
    pub fn finish(mut self) -> PolarsResult<DataFrame> {
        self.flush();
        let n = self.detectors.len();
        let mut names: [Vec<String>; 2] = Default::default();
        let mut counts: Vec<Vec<u64>> = vec![Vec::new(); 10];
        let mut rates: Vec<Vec<Option<f64>>> = vec![Vec::new(); 4];
        let mut p_values: Vec<Vec<f64>> = vec![Vec::new(); 3];
        // Per paired column: the median difference and its 95 % interval.
        let mut medians: Vec<[Vec<Option<f64>>; 3]> = vec![Default::default(); 1 + self.paired_names.len()];
        let mut pairs = self.pairs.iter();
        for a in 0..n {
            for b in a + 1..n {
                let c = pairs.next().expect("one count per pair");
                names[0].push(self.detectors[a].clone());
                names[1].push(self.detectors[b].clone());
                let isolation_units = if self.isolation_on_all_units { c.flights } else { c.units };
                let share = |k: u64, n: u64| (n > 0).then(|| k as f64 / n as f64);
                rates[0].push(share(c.positive[0][0], c.units));
                rates[1].push(share(c.positive[0][1], c.units));
                rates[2].push(share(c.positive[1][0], isolation_units));
                rates[3].push(share(c.positive[1][1], isolation_units));
                for (k, v) in [
                    c.units,
                    c.discordant[0][0],
                    c.discordant[0][1],
                    c.discordant[1][0],
                    c.discordant[1][1],
                    c.differences[0].count(),
                    c.flights,
                    c.discordant[2][0],
                    c.discordant[2][1],
                    isolation_units,
                ]
                .into_iter()
                .enumerate()
                {
                    counts[k].push(v);
                }
                for (k, d) in c.discordant.iter().enumerate() {
                    p_values[k].push(mcnemar_exact(d[0], d[1]));
                }
                for (m, q) in medians.iter_mut().zip(&c.differences) {
                    let interval = q.median_interval(crate::engine::stats::intervals::Z95);
                    m[0].push(q.median());
                    m[1].push(interval.map(|i| i.0));
                    m[2].push(interval.map(|i| i.1));
                }
            }
        }
        let [a, b] = names;
        let mut columns = vec![
            Column::new("detector_a".into(), a),
            Column::new("detector_b".into(), b),
            Column::new("faulty_units".into(), std::mem::take(&mut counts[0])),
            Column::new("pd_a".into(), std::mem::take(&mut rates[0])),
            Column::new("pd_b".into(), std::mem::take(&mut rates[1])),
            Column::new("detected_by_a_only".into(), std::mem::take(&mut counts[1])),
            Column::new("detected_by_b_only".into(), std::mem::take(&mut counts[2])),
            Column::new("mcnemar_p_detection".into(), std::mem::take(&mut p_values[0])),
            Column::new("isolation_units".into(), std::mem::take(&mut counts[9])),
            Column::new("isolated_a".into(), std::mem::take(&mut rates[2])),
            Column::new("isolated_b".into(), std::mem::take(&mut rates[3])),
            Column::new("isolated_by_a_only".into(), std::mem::take(&mut counts[3])),
            Column::new("isolated_by_b_only".into(), std::mem::take(&mut counts[4])),
            Column::new("mcnemar_p_isolation".into(), std::mem::take(&mut p_values[1])),
            Column::new("delay_pairs".into(), std::mem::take(&mut counts[5])),
        ];
        let names = std::iter::once("median_delay_b_minus_a_s".to_string())
            .chain(self.paired_names.iter().map(|name| format!("median_{name}_b_minus_a")));
        for (name, m) in names.zip(medians.iter_mut()) {
            for (suffix, values) in ["", "_lo", "_hi"].iter().zip(m.iter_mut()) {
                columns.push(Column::new(format!("{name}{suffix}").into(), std::mem::take(values)));
            }
        }
        columns.extend([
            Column::new("flights".into(), std::mem::take(&mut counts[6])),
            Column::new("false_alarm_a_only".into(), std::mem::take(&mut counts[7])),
            Column::new("false_alarm_b_only".into(), std::mem::take(&mut counts[8])),
            Column::new("mcnemar_p_false_alarm".into(), std::mem::take(&mut p_values[2])),
        ]);
        DataFrame::new_infer_height(columns)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit(
        flown: bool,
        faulty: bool,
        detected: bool,
        isolated: bool,
        false_alarm: bool,
        delay: Option<f64>,
    ) -> UnitOutcome {
        UnitOutcome { flown, faulty, detected, isolated, false_alarm, paired: vec![delay] }
    }

    /// Three detectors on four trials by hand: trial 0 (faulty) a detects at 0.5 s and isolates, b
    /// detects at 1.0 s without isolating, c misses; trial 1 (fault-free) b alarms; trial 2 a's flight
    /// failed; trial 3 (faulty) all detect, a at 0.2 s, b at 0.6 s.
    #[test]
    fn pairs_count_discordant_units_on_what_both_flew() {
        let names: Vec<String> = ["a", "b", "c"].map(String::from).to_vec();
        let mut p = PairedUnits::new(&names, &[], false);
        p.push(0, 0, unit(true, true, true, true, false, Some(0.5)));
        p.push(0, 1, unit(true, true, true, false, false, Some(1.0)));
        p.push(0, 2, unit(true, true, false, false, false, None));
        for d in 0..3 {
            p.push(1, d, unit(true, false, false, false, d == 1, None));
        }
        p.push(2, 0, unit(false, true, false, false, false, None));
        p.push(2, 1, unit(true, true, true, true, false, Some(0.1)));
        p.push(2, 2, unit(true, true, true, true, false, Some(0.1)));
        p.push(3, 0, unit(true, true, true, true, false, Some(0.2)));
        p.push(3, 1, unit(true, true, true, true, false, Some(0.6)));
        p.push(3, 2, unit(true, true, true, false, false, Some(0.3)));
        let df = p.finish().unwrap();
        assert_eq!(df.height(), 3, "a-b, a-c, b-c");
        let u = |name: &str| -> Vec<u64> { df.column(name).unwrap().u64().unwrap().into_no_null_iter().collect() };
        assert_eq!(u("faulty_units"), [2, 2, 3], "trial 2 counts only for b-c");
        assert_eq!(u("detected_by_a_only"), [0, 1, 1]);
        assert_eq!(u("detected_by_b_only"), [0, 0, 0]);
        assert_eq!(u("isolated_by_a_only"), [1, 2, 1]);
        assert_eq!(u("isolated_by_b_only"), [0, 0, 0]);
        assert_eq!(u("flights"), [3, 3, 4]);
        assert_eq!(u("false_alarm_b_only"), [1, 0, 0]);
        assert_eq!(u("false_alarm_a_only"), [0, 0, 1]);
        let median: Vec<Option<f64>> = df.column("median_delay_b_minus_a_s").unwrap().f64().unwrap().iter().collect();
        // a-b: 1.0 - 0.5 and 0.6 - 0.2; a-c: 0.3 - 0.2 only; b-c: 0.1 - 0.1 and 0.3 - 0.6.
        let close = |x: Option<f64>, y: f64| (x.unwrap() - y).abs() < 1e-12;
        assert!(close(median[0], 0.45) && close(median[1], 0.1) && close(median[2], -0.15), "{median:?}");
        let p_det: Vec<f64> = df.column("mcnemar_p_detection").unwrap().f64().unwrap().into_no_null_iter().collect();
        assert_eq!(p_det[1], 1.0, "one discordant pair is no evidence");
    }
}
