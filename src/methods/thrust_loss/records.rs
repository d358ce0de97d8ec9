//! The launch detectors' `trials.parquet` (method 001): one row per (trial, detector configuration),
//! the core columns of [`crate::engine::results::schema`] first, where `kind` is `thrust_loss` (`none` when
//! fault-free), `target` the faulty engine (`engine_1` to `engine_4`), `size` the loss in % of one
//! engine's thrust, `failure` why the flight ended early, alarms at the deck's threshold, and `isolated`
//! the engine named from the overload jumps at the detection (`none`: no sign pattern); then the
//! recorded statistic `|fhat|` and the detectors' own columns:
//!
//! | column | meaning |
//! |---|---|
//! | `gust_scale`, `gust_bin` | factor on the deck's gusts and its group label |
//! | `alarm_s` | first alarm at or after the onset (deck threshold) |
//! | `onset_estimate_s`, `fhat_peak`, `loss_estimate_percent`, `loss_error_percent` | the detector's onset estimate, the peak `\|fhat\|` over the loss table's horizon after the alarm, the loss it means, minus the true loss |
//! | `fhat_above_threshold_s` | when detected: the time `\|fhat\|` spends at or above the deck's threshold in the detection window after the onset (the seed's "beats" the estimate shows the loss) |
//! | `singular_innovation_steps`, `asymmetric_steps`, `not_positive_definite_steps`, `non_finite_steps` | EKF health |
//! | `sensitivity_clamped`, `gls_failed` | samples outside the sensitivity grid; non-finite estimates |
//! | `pre_max_fhat`, `fp_t_s_fhat`, `fp_v_fhat` | the recorded statistic `\|fhat\|`: evaluate any threshold |

use std::borrow::Cow;

use polars::prelude::*;

use super::study::LaunchStudy;
use super::trial::LaunchTrialResult;
use crate::engine::results::schema::col::NO_FAULT;
use crate::engine::results::schema::{CoreColumns, FilterHealthColumns, Outcome, StatisticColumns};

/// Column names of this kind's own columns that its summary reads.
pub mod col {
    pub const GUST_BIN: &str = "gust_bin";
    pub const LOSS_ERROR_PERCENT: &str = "loss_error_percent";
    pub const ABOVE_THRESHOLD_S: &str = "fhat_above_threshold_s";
    /// Fault kind of a thrust loss.
    pub const THRUST_LOSS: &str = "thrust_loss";
    /// The recorded statistic: `|fhat|`.
    pub const FHAT: &str = "fhat";

    /// The engine's name in tables (index 0 is the seed's engine 1).
    pub fn engine_name(index: usize) -> String {
        format!("engine_{}", index + 1)
    }
}

/// The rows of `results` (trial order); see the module docs.
pub fn frame(study: &LaunchStudy, results: &[LaunchTrialResult]) -> PolarsResult<DataFrame> {
    let rows = results.len() * study.detectors.len();
    let mut core = CoreColumns::new(Vec::new(), rows, study.monte_carlo.common.detection_window_s);
    let mut statistics = StatisticColumns::new(&[col::FHAT.to_string()], rows);
    let mut t = Columns::default();
    for r in results {
        let s = &r.spec;
        let onset = s.fault.map(|f| f.onset_s);
        let target = s.fault.map(|f| col::engine_name(f.engine));
        for (d, det) in study.detectors.iter().enumerate() {
            let o = r.outcome.as_ref().ok().map(|o| &o[d]);
            let localised = o.and_then(|o| o.localised);
            let h = o.map(|o| o.health);
            core.push(Outcome {
                trial: s.trial,
                detector: &det.name,
                kind: if s.fault.is_some() { col::THRUST_LOSS } else { NO_FAULT },
                target: target.clone().map(Cow::Owned),
                size: s.fault.map(|_| s.loss_percent),
                size_unit: if s.fault.is_some() {
                    "percent of one engine's thrust"
                } else {
                    crate::engine::results::schema::unit::NONE
                },
                size_bin: s.fault.map(|_| s.loss_bin),
                onset_s: onset,
                fault_free: s.fault.is_none(),
                failure: r.outcome.as_ref().err().cloned(),
                diverged: h.is_some_and(|h| h.filter.non_finite > 0),
                truth_diverged: false,
                false_alarm_s: o.and_then(|o| o.false_alarm_s),
                delay_s: o.and_then(|o| o.alarm_s).zip(onset).map(|(a, t0)| a - t0),
                isolated: localised.map(|e| Cow::Owned(e.map_or(NO_FAULT.to_string(), col::engine_name))),
                isolated_correctly: localised.map(|e| e.is_some() && e == s.fault.map(|f| f.engine)),
                noise_scale: s.noise_scale,
                noise_bin: s.noise_bin,
                param_error_bin: 0.0,
                param_errors: &[],
            });
            match o {
                Some(o) => statistics.push(0, Some(o.pre_max_fhat), &o.profile_t_s, &o.profile_fhat),
                None => statistics.push(0, None, &[], &[]),
            }
            t.gust_scale.push(s.gust_scale);
            t.gust_bin.push(s.gust_bin);
            t.alarm_s.push(o.and_then(|o| o.alarm_s));
            t.onset_estimate.push(o.and_then(|o| o.onset_estimate_s));
            t.fhat_peak.push(o.and_then(|o| o.fhat_peak));
            let estimate = o.and_then(|o| o.loss_estimate_percent);
            t.loss_estimate.push(estimate);
            t.loss_error.push(estimate.filter(|_| s.fault.is_some()).map(|e| e - s.loss_percent));
            t.above_threshold.push(o.and_then(|o| o.above_threshold_s));
            t.health.push(h.map(|h| h.filter));
            t.clamped.push(h.map(|h| h.sensitivity_clamped));
            t.gls_failed.push(h.map(|h| h.gls_failed));
        }
    }
    let mut columns = core.finish();
    columns.extend([
        Column::new("gust_scale".into(), t.gust_scale),
        Column::new(col::GUST_BIN.into(), t.gust_bin),
        Column::new("alarm_s".into(), t.alarm_s),
        Column::new("onset_estimate_s".into(), t.onset_estimate),
        Column::new("fhat_peak".into(), t.fhat_peak),
        Column::new("loss_estimate_percent".into(), t.loss_estimate),
        Column::new(col::LOSS_ERROR_PERCENT.into(), t.loss_error),
        Column::new(col::ABOVE_THRESHOLD_S.into(), t.above_threshold),
    ]);
    columns.extend(t.health.finish());
    columns
        .extend([Column::new("sensitivity_clamped".into(), t.clamped), Column::new("gls_failed".into(), t.gls_failed)]);
    columns.extend(statistics.finish());
    DataFrame::new_infer_height(columns)
}

/// This kind's own columns while rows are added.
#[derive(Default)]
struct Columns {
    gust_scale: Vec<f64>,
    gust_bin: Vec<f64>,
    alarm_s: Vec<Option<f64>>,
    onset_estimate: Vec<Option<f64>>,
    fhat_peak: Vec<Option<f64>>,
    loss_estimate: Vec<Option<f64>>,
    loss_error: Vec<Option<f64>>,
    above_threshold: Vec<Option<f64>>,
    health: FilterHealthColumns,
    clamped: Vec<Option<u32>>,
    gls_failed: Vec<Option<u32>>,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::results::summary::hand_made::{Summarized, manifest};
    use crate::engine::run::runner::Manifest;
    use crate::engine::scenario::deck::FromDeck;
    use crate::engine::stats::intervals::{Z95, wilson};
    use crate::methods::thrust_loss::ekf_mhe::DetectorHealth;
    use crate::methods::thrust_loss::scenario::LaunchTrialSpec;
    use crate::methods::thrust_loss::trial::LaunchOutcome;
    use crate::methods::thrust_loss::vehicle::ThrustFault;

    /// Two detectors on five hand-made flights (engine 2 losing 40 % at 20 s, or none). Trial 0: a names
    /// engine 2 after 0.5 s (loss estimate 38 %), b names engine 4 after 1.0 s (45 %); trial 1: a misses, b
    /// names engine 2 after 0.8 s (41 %); trial 2: fault-free, a false alarm by a at 10 s; trial 3: the
    /// flight ended early; trial 4: a names engine 2 after 0.3 s (44 %), b alarms after 0.4 s but names no
    /// engine (39 %).
    #[test]
    fn summary_of_hand_made_launch_flights() {
        let mut study = LaunchStudy::bundled("ci_seed001.toml");
        study.detectors.truncate(1);
        study.detectors.push(study.detectors[0].clone());
        study.detectors[0].name = "a".into();
        study.detectors[1].name = "b".into();
        let fault = ThrustFault { engine: 1, loss_fraction: 0.4, onset_s: 20.0 };
        let spec = |trial: u64, faulty: bool| LaunchTrialSpec {
            trial,
            fault: faulty.then_some(fault),
            loss_percent: if faulty { 40.0 } else { f64::NAN },
            loss_bin: if faulty { 40.0 } else { f64::NAN },
            noise_scale: 1.0,
            noise_bin: 1.0,
            gust_scale: 1.0,
            gust_bin: 1.0,
        };
        let out = |alarm: Option<f64>, engine: Option<Option<usize>>, loss: Option<f64>, false_alarm: Option<f64>| {
            LaunchOutcome {
                pre_max_fhat: 0.1,
                profile_t_s: vec![],
                profile_fhat: vec![],
                false_alarm_s: false_alarm,
                alarm_s: alarm,
                localised: engine,
                onset_estimate_s: alarm.map(|a| a - 0.2),
                fhat_peak: loss.map(|l| l / 100.0),
                loss_estimate_percent: loss,
                above_threshold_s: alarm.map(|a| a - 19.0),
                health: DetectorHealth::default(),
            }
        };
        let results = vec![
            LaunchTrialResult {
                spec: spec(0, true),
                outcome: Ok(vec![
                    out(Some(20.5), Some(Some(1)), Some(38.0), None),
                    out(Some(21.0), Some(Some(3)), Some(45.0), None),
                ]),
            },
            LaunchTrialResult {
                spec: spec(1, true),
                outcome: Ok(vec![out(None, None, None, None), out(Some(20.8), Some(Some(1)), Some(41.0), None)]),
            },
            LaunchTrialResult {
                spec: spec(2, false),
                outcome: Ok(vec![out(None, None, None, Some(10.0)), out(None, None, None, None)]),
            },
            LaunchTrialResult { spec: spec(3, true), outcome: Err("the flight ended early".into()) },
            LaunchTrialResult {
                spec: spec(4, true),
                outcome: Ok(vec![
                    out(Some(20.3), Some(Some(1)), Some(44.0), None),
                    out(Some(20.4), Some(None), Some(39.0), None),
                ]),
            },
        ];
        let df = frame(&study, &results).unwrap();
        assert_eq!(df.height(), 10, "one row per flight and detector");
        let manifest =
            Manifest { deck_thresholds: vec![vec![0.5], vec![0.5]], ..manifest(&super::super::METHOD, 5, &["a", "b"]) };
        let s = Summarized::new(df, manifest, &super::super::METHOD.summary);
        let counts = |row| {
            ["trials", "failed", "detected", "isolation_decided", "isolated_correctly"]
                .map(|c| s.count(c, row).unwrap())
        };
        let (a, b) = (s.row("a", "thrust_loss"), s.row("b", "thrust_loss"));
        assert_eq!(counts(a), [4, 1, 2, 2, 2]);
        assert_eq!(counts(b), [4, 1, 3, 3, 1], "b's 'no engine' is a decision, and a wrong one");
        assert_eq!(
            (s.count("false_alarms", s.row("a", "none")), s.value("pfa", s.row("a", "none"))),
            (Some(1), Some(1.0))
        );
        assert_eq!(s.count("false_alarms", s.row("b", "none")), Some(0));
        assert_eq!((s.value("pd", a), s.value("pd", b)), (Some(2.0 / 3.0), Some(1.0)));
        let (lo, hi) = wilson(2, 3, Z95);
        assert_eq!((s.value("pd_lo", a), s.value("pd_hi", a)), (Some(lo), Some(hi)));
        assert_eq!(s.value("isolation_accuracy", b), Some(1.0 / 3.0));
        s.assert_close("delay_p50_s", a, 0.4); // median of 0.5 and 0.3
        s.assert_close("delay_p50_s", b, 0.8); // of 1.0, 0.8, 0.4
        // The kind's own aggregates: the loss estimates' errors, signed and absolute.
        s.assert_close("loss_error_p50_percent", a, 1.0); // median of -2 and +4
        s.assert_close("loss_abs_error_p50_percent", a, 3.0);
        s.assert_close("loss_error_p50_percent", b, 1.0); // of +5, +1, -1
        s.assert_close("loss_abs_error_p50_percent", b, 1.0); // of 5, 1, 1
        assert_eq!(s.value("loss_error_p50_percent", s.row("a", "none")), None, "no loss without a fault");
        // How long fhat stays above the threshold after the detection (alarm - 19 s here).
        s.assert_close("above_threshold_p50_s", a, 1.4); // median of 1.5 and 1.3
        s.assert_close("above_threshold_p50_s", b, 1.8); // of 2.0, 1.8, 1.4
    }
}
