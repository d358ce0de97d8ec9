//! ROC curves (`roc.csv`): per detector, Pd against Pfa as its whole-detector thresholds are scaled
//! together, read from the recorded statistics without re-simulating.
//!
//! The points are the scales at which the calibration units' alarms step: for `n` units whose largest
//! statistic-to-threshold ratios are `r(1) >= r(2) >= ...`, the scale `r(k + 1)` lets exactly `k` of them
//! alarm (ties aside; each point's thresholds let through the units its scale does, as the calibration's
//! own, [`let_through`]). About forty `k` are taken, spaced evenly in `log k` from 0 to `n - 1`, plus the
//! scale 1 (the calibrated thresholds themselves, `calibrated = true`). At each point the alarms are
//! counted as everywhere else: a unit alarms when a statistic's pre-onset maximum exceeds its scaled
//! threshold, and a faulty unit is detected at the first post-onset profile point above one
//! ([`RecordedStatistics::alarms_at`]); so the calibrated point repeats `thresholds.csv`'s false alarms
//! and the `calibrated` set's Pd exactly.
//!
//! A threshold of 0 cannot be scaled (a held time, [`crate::estimation::bank::held_s`], calibrates to 0
//! when fewer units than the calibration lets through hold at all): a detector of one statistic whose
//! calibrated threshold is 0 is scaled from its deck threshold instead (from 1 if that is 0 too), and
//! its calibrated point is the scale 0.
//!
//! A point's Pfa is read on the units that set the calibrated thresholds (`pfa_read_on`
//! `calibration trials`: in-sample, so a point is about as optimistic as the calibration itself), or,
//! for thresholds of another run (`summarize --thresholds`), on this run's units (`fresh trials`).

use std::path::Path;

use polars::prelude::*;

use crate::engine::results::schema::col;
use crate::engine::results::tables::{bool_col, f64_col, str_col};
use crate::engine::results::thresholds::{
    DetectorThresholds, RecordedStatistics, descending, for_each_slice, let_through, unit_ratio,
};
use crate::engine::run::output::write_table;
use crate::engine::run::runner::{Manifest, RunError, pol};
use crate::engine::stats::intervals::{Z95, wilson};
use crate::engine::stats::quantiles::Quantiles;

/// Points per detector besides the calibrated one (at most; fewer with few calibration units).
pub const ROC_POINTS: usize = 40;

/// One operating point of one detector.
#[derive(Debug, Clone)]
pub struct RocPoint {
    pub detector: String,
    /// The factor on the detector's whole-detector thresholds (1: the calibrated thresholds).
    pub scale: f64,
    pub calibrated: bool,
    pub calibration_units: u64,
    pub false_alarms: u64,
    pub faulty_units: u64,
    pub detected: u64,
    delays_s: Quantiles,
}

impl RocPoint {
    pub fn pfa(&self) -> f64 {
        self.false_alarms as f64 / self.calibration_units.max(1) as f64
    }

    pub fn pd(&self) -> f64 {
        self.detected as f64 / self.faulty_units.max(1) as f64
    }

    /// The median delay from the onset of the detected units (s).
    pub fn delay_p50_s(&self) -> Option<f64> {
        self.delays_s.median()
    }
}

/// The scales of the module docs from one detector's calibration ratios (any order), descending, with
/// `calibrated` (the calibrated thresholds' scale) among them.
fn scales(mut ratios: Vec<f64>, calibrated: f64) -> Vec<f64> {
    ratios.retain(|r| !r.is_nan());
    ratios.sort_by(|a, b| b.total_cmp(a));
    let n = ratios.len();
    let mut s: Vec<f64> = Vec::with_capacity(ROC_POINTS + 1);
    if n > 0 {
        let top = (n - 1) as f64;
        for i in 0..ROC_POINTS {
            // k = 0, then log-spaced to n - 1.
            let k =
                if i == 0 { 0 } else { ((top + 1.0).powf(i as f64 / (ROC_POINTS - 1) as f64) - 1.0).round() as usize };
            s.push(ratios[k.min(n - 1)]);
        }
    }
    s.push(calibrated);
    s.sort_by(|a, b| b.total_cmp(a));
    s.dedup();
    s
}

/// The ROC points of every detector of a run at its thresholds, counted slice by slice: made from the
/// calibration columns (passes 1 and 1b of the module docs, the pre-onset maxima only), then fed the
/// slices the summary reads anyway ([`Roc::add_slice`]), so the first-passage profiles are decoded once
/// for both.
pub struct Roc {
    detectors: Vec<String>,
    /// Per detector: its whole-detector thresholds' length is the statistics' count (else no points).
    scored: Vec<bool>,
    on_fault_free: bool,
    points: Vec<Vec<RocPoint>>,
    /// `scaled[d][k]`: detector d's thresholds at point k.
    scaled: Vec<Vec<Vec<f64>>>,
    /// Per detector: its points' thresholds descend ([`descending`]), so a row's first alarms at every
    /// point come from one walk down each profile.
    descending: Vec<bool>,
    /// A row's first alarm at each point (scratch).
    first: Vec<Option<f64>>,
}

impl Roc {
    /// The points of every detector of the run in `path` at `thresholds` (their whole-detector
    /// thresholds scaled), over `statistics`; their counts are empty until the slices are added.
    pub fn new(
        path: &Path,
        manifest: &Manifest,
        statistics: &[String],
        thresholds: &[DetectorThresholds],
    ) -> Result<Self, RunError> {
        let nd = manifest.detectors.len();
        let ns = statistics.len();
        let whole: Vec<&[f64]> = (0..nd)
            .map(|d| {
                (thresholds.iter().find(|t| t.detector == manifest.detectors[d]))
                    .map_or(&[][..], |t| t.whole.as_slice())
            })
            .collect();
        // What the points scale, and the scale of the calibrated thresholds (module docs).
        let (base, calibrated_scale): (Vec<Vec<f64>>, Vec<f64>) = (0..nd)
            .map(|d| match whole[d] {
                [t] if *t == 0.0 => {
                    let deck = manifest.deck_thresholds.get(d).and_then(|t| t.first()).copied().unwrap_or(0.0);
                    (vec![if deck > 0.0 { deck } else { 1.0 }], 0.0)
                }
                w => (w.to_vec(), 1.0),
            })
            .unzip();
        let on_fault_free = thresholds.first().is_some_and(|t| t.on_fault_free_trials);

        // Each calibration unit of a detector with thresholds, with its pre-onset maxima: the calibration's
        // own reader, so the ROC calibrates on the same units.
        let for_each_calibration_unit = |visit: &mut dyn FnMut(usize, &dyn Fn(usize) -> f64)| {
            for_each_slice(path, manifest.rows, manifest, statistics, on_fault_free, |rows| {
                for (i, d) in rows.detector.iter().enumerate() {
                    if let Some(d) = *d
                        && whole[d].len() == ns
                    {
                        visit(d, &|j| rows.pre[j][i]);
                    }
                }
            })
        };
        // Pass 1: each calibration unit's largest ratio to its detector's thresholds.
        let mut ratios: Vec<Vec<f64>> = vec![Vec::new(); nd];
        for_each_calibration_unit(&mut |d, value| ratios[d].push(unit_ratio(value, &base[d])))?;
        let points: Vec<Vec<RocPoint>> = (0..nd)
            .map(|d| {
                scales(std::mem::take(&mut ratios[d]), calibrated_scale[d])
                    .into_iter()
                    .map(|scale| RocPoint {
                        detector: manifest.detectors[d].clone(),
                        scale,
                        calibrated: scale == calibrated_scale[d],
                        calibration_units: 0,
                        false_alarms: 0,
                        faulty_units: 0,
                        detected: 0,
                        delays_s: Quantiles::default(),
                    })
                    .collect()
            })
            .collect();
        let mut scaled: Vec<Vec<Vec<f64>>> = (0..nd)
            .map(|d| points[d].iter().map(|p| base[d].iter().map(|t| t * p.scale).collect()).collect())
            .collect();
        // Pass 1b: as the calibration itself, each point's thresholds let through the units its scale does.
        for_each_calibration_unit(&mut |d, value| {
            for (thr, p) in scaled[d].iter_mut().zip(&points[d]) {
                let_through(thr, value, &base[d], p.scale);
            }
        })?;
        let scored = whole.iter().map(|w| w.len() == ns).collect();
        let descending = scaled.iter().map(|s| descending(s)).collect();
        let first = vec![None; points.iter().map(Vec::len).max().unwrap_or(0)];
        Ok(Roc { detectors: manifest.detectors.clone(), scored, on_fault_free, points, scaled, descending, first })
    }

    /// The columns [`Self::add_slice`] reads besides the statistics' ([`RecordedStatistics::columns`]).
    pub const COLUMNS: [&str; 4] = [col::DETECTOR, col::FAULT_FREE, col::FAILURE, col::ONSET_S];

    /// Pass 2: at each point, the alarms of the calibration units and the detections of the faulty ones
    /// in the slice `df` (read from `path`) whose statistics are `recorded`.
    pub fn add_slice(&mut self, df: &DataFrame, recorded: &RecordedStatistics, path: &Path) -> Result<(), RunError> {
        let (det, fault_free, failure, onset) = (
            str_col(df, col::DETECTOR, path)?,
            bool_col(df, col::FAULT_FREE, path)?,
            str_col(df, col::FAILURE, path)?,
            f64_col(df, col::ONSET_S, path)?,
        );
        // Which rows calibrate: flown, and fault-free where there are fault-free trials (as thresholds.rs).
        let on_fault_free = self.on_fault_free;
        let calibrates =
            |fault_free: Option<bool>, failed: bool| !failed && (!on_fault_free || fault_free == Some(true));
        for i in 0..df.height() {
            let Some(d) = det.get(i).and_then(|n| self.detectors.iter().position(|x| x == n)) else { continue };
            if !self.scored[d] {
                continue;
            }
            let failed = failure.get(i).is_some();
            // By `fault_free`, as the summary: a classifier's fault-free class has a name (`normal`).
            let faulty = !failed && fault_free.get(i) != Some(true);
            let calibration = calibrates(fault_free.get(i), failed);
            let walked = faulty && self.descending[d];
            if walked {
                recorded.first_alarms_descending(i, &self.scaled[d], &mut self.first);
            }
            for (k, (p, thr)) in self.points[d].iter_mut().zip(&self.scaled[d]).enumerate() {
                let (false_alarm, first) = if walked {
                    (recorded.alarms_at(i, thr, false).0, self.first[k])
                } else {
                    recorded.alarms_at(i, thr, faulty)
                };
                if calibration {
                    p.calibration_units += 1;
                    p.false_alarms += false_alarm as u64;
                }
                if faulty {
                    p.faulty_units += 1;
                    if let Some(t) = first {
                        p.detected += 1;
                        p.delays_s.push(t - onset.get(i).unwrap_or(f64::NAN));
                    }
                }
            }
        }
        Ok(())
    }

    /// Every detector's points, in the run's detector order, scales descending.
    pub fn points(self) -> Vec<RocPoint> {
        self.points.into_iter().flatten().collect()
    }
}

/// Writes `roc.csv`: one row per detector and point, scales descending (Pfa ascending); `fresh` says the
/// thresholds came from another run, so each Pfa is read on other trials than those that set them.
pub fn write_roc(
    dir: &Path,
    points: &[RocPoint],
    target_pfa: Option<f64>,
    confidence: Option<f64>,
    fresh: bool,
) -> Result<(), RunError> {
    let path = dir.join("roc.csv");
    let interval = |k: u64, n: u64| (n > 0).then(|| wilson(k, n, Z95));
    let pfa_ci: Vec<Option<(f64, f64)>> =
        points.iter().map(|p| interval(p.false_alarms, p.calibration_units)).collect();
    let pd_ci: Vec<Option<(f64, f64)>> = points.iter().map(|p| interval(p.detected, p.faulty_units)).collect();
    let height = points.len();
    let read_on = if fresh { "fresh trials" } else { "calibration trials" };
    let mut df = DataFrame::new_infer_height(vec![
        Column::new(col::DETECTOR.into(), points.iter().map(|p| p.detector.as_str()).collect::<Vec<_>>()),
        Column::new("scale".into(), points.iter().map(|p| p.scale).collect::<Vec<_>>()),
        Column::new("calibrated".into(), points.iter().map(|p| p.calibrated).collect::<Vec<_>>()),
        Column::new("trials".into(), points.iter().map(|p| p.calibration_units).collect::<Vec<_>>()),
        Column::new("false_alarms".into(), points.iter().map(|p| p.false_alarms).collect::<Vec<_>>()),
        Column::new(
            "pfa".into(),
            points.iter().map(|p| (p.calibration_units > 0).then(|| p.pfa())).collect::<Vec<_>>(),
        ),
        Column::new("pfa_lo".into(), pfa_ci.iter().map(|c| c.map(|c| c.0)).collect::<Vec<_>>()),
        Column::new("pfa_hi".into(), pfa_ci.iter().map(|c| c.map(|c| c.1)).collect::<Vec<_>>()),
        Column::new("faulty".into(), points.iter().map(|p| p.faulty_units).collect::<Vec<_>>()),
        Column::new("detected".into(), points.iter().map(|p| p.detected).collect::<Vec<_>>()),
        Column::new("pd".into(), points.iter().map(|p| (p.faulty_units > 0).then(|| p.pd())).collect::<Vec<_>>()),
        Column::new("pd_lo".into(), pd_ci.iter().map(|c| c.map(|c| c.0)).collect::<Vec<_>>()),
        Column::new("pd_hi".into(), pd_ci.iter().map(|c| c.map(|c| c.1)).collect::<Vec<_>>()),
        Column::new("delay_p50_s".into(), points.iter().map(RocPoint::delay_p50_s).collect::<Vec<_>>()),
        Column::new("delay_p90_s".into(), points.iter().map(|p| p.delays_s.quantile(0.9)).collect::<Vec<_>>()),
        Column::new("pfa_read_on".into(), vec![read_on; height]),
        Column::new("target_pfa".into(), vec![target_pfa; height]),
        Column::new("confidence".into(), vec![confidence; height]),
    ])
    .map_err(pol(&path))?;
    Ok(write_table(&mut df, &path)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Scales are order statistics of the ratios, descending, with 1 among them; the first lets none
    /// through, and k = n - 1 is reached.
    #[test]
    fn scales_step_through_the_calibration_ratios() {
        let ratios: Vec<f64> = (1..=1000).map(|i| i as f64 / 500.0).collect();
        let s = scales(ratios.clone(), 1.0);
        assert_eq!(s[0], 2.0, "the largest ratio: no unit above it");
        assert_eq!(*s.last().unwrap(), 0.002, "k = n - 1: all but the smallest alarm");
        assert!(s.contains(&1.0) && s.windows(2).all(|w| w[0] > w[1]), "{s:?}");
        assert!(s.len() > 30 && s.len() <= ROC_POINTS + 1, "{}", s.len());
        for &x in &s {
            let k = ratios.iter().filter(|&&r| r > x).count();
            assert_eq!(k, 1000 - (x * 500.0).round() as usize, "{x}");
        }
        assert_eq!(scales(Vec::new(), 1.0), vec![1.0]);
        assert_eq!(*scales(ratios, 0.0).last().unwrap(), 0.0, "a calibrated threshold of 0: the scale 0");
    }
}
