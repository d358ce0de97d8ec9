//! The banks' `trials.parquet` (method 004): one row per (trial, bank, fault window); a fault-free
//! trial has one row per bank. The core columns of [`crate::engine::results::schema`] come first, where `target`
//! is the faulty surface, `size` the stuck position or square-wave amplitude (deg) or the effectiveness
//! (fraction), `failure` why the flight stopped early (no trim, left the envelope), `diverged` a
//! covariance that became non-finite, `delay_s` from the onset to the first declaration in the window,
//! `isolated` the first surface declared in it, and `false_alarm_s` the first declaration while no
//! fault was active and none had ended (trial and bank: it repeats on each window row). Then the banks'
//! own columns:
//!
//! | column | meaning |
//! |---|---|
//! | `end_s`, `window` | the fault window's end and its index in the trial (onset order) |
//! | `isolation_delay_s` | from the onset to the first declaration of the faulty surface |
//! | `cleared`, `clearing_delay_s` | the faulty surface, once declared, was cleared after the window ended; from the end to the clearance |
//! | `recovered`, `recovery_delay_s` | the seed's clearing event: the fault detected, the no-fault model's probability came back to 0.9 after the window ended; from the end to that step |
//! | `surface_estimate_rms_deg` | RMS error of the faulty surface's position estimate over the window's second half |
//! | `surface_estimate_rms_window_deg`, `surface_estimate_rms_first_s_deg` | the same over the whole window, and over its first second |
//! | `false_alarms` | how many such declarations |
//! | `post_fault_declarations` | declarations while no fault was active after one had ended (relapses during the recovery) |
//! | `singular_innovation_steps`, `asymmetric_steps`, `not_positive_definite_steps`, `non_finite_steps` | covariance health, filter-steps summed over the bank's six filters |
//! | `floor_steps` | steps on which the probability floor was applied |
//! | `pre_max_held_s`, `fp_t_s_held_s`, `fp_v_held_s` | the bank's decision statistic `held_s` recorded ([`STATISTIC`], [`crate::methods::surface_bank::trial`]): how long a surface model's probability has stayed above the declare level, largest while no fault was active and none had ended (it repeats on each window row), and its first-passage profile over the window, so `summarize` calibrates the hold and draws the ROC |

use std::borrow::Cow;

use polars::prelude::*;

use super::study::SurfaceStudy;
use super::trial::{BankOutcome, SurfaceTrialResult, WindowOutcome};
use crate::engine::results::schema::col::NO_FAULT;
use crate::engine::results::schema::{CoreColumns, FilterHealthColumns, Outcome, StatisticColumns};
use crate::vehicles::aerosonde::SURFACE_NAMES;

/// Column names of this kind's own columns that its summary reads.
pub mod col {
    pub const ISOLATION_DELAY_S: &str = "isolation_delay_s";
    pub const CLEARED: &str = "cleared";
    pub const CLEARING_DELAY_S: &str = "clearing_delay_s";
    pub const RECOVERED: &str = "recovered";
    pub const RECOVERY_DELAY_S: &str = "recovery_delay_s";
    pub const SURFACE_ESTIMATE_RMS_DEG: &str = "surface_estimate_rms_deg";
    pub const SURFACE_ESTIMATE_RMS_WINDOW_DEG: &str = "surface_estimate_rms_window_deg";
    pub const SURFACE_ESTIMATE_RMS_FIRST_S_DEG: &str = "surface_estimate_rms_first_s_deg";
    pub const POST_FAULT_DECLARATIONS: &str = "post_fault_declarations";
}

/// The recorded statistic: how long a surface model's probability has stayed above the declare level (s).
pub const STATISTIC: &str = "held_s";

/// The rows of `results` (trial order); see the module docs.
pub fn frame(study: &SurfaceStudy, results: &[SurfaceTrialResult]) -> PolarsResult<DataFrame> {
    let perr = study.monte_carlo.parameter_errors.iter().map(|p| p.name.clone());
    let mut core =
        CoreColumns::new(perr, results.len() * study.banks.len(), study.monte_carlo.common.detection_window_s);
    let mut t = Columns::default();
    let mut statistics = StatisticColumns::new(&[STATISTIC.to_string()], results.len() * study.banks.len());
    for r in results {
        let spec = &r.spec;
        for (b, (bank, _)) in study.banks.iter().enumerate() {
            let outcome: Option<&BankOutcome> = r.outcome.as_ref().ok().map(|o| &o[b]);
            // One row per window; a fault-free trial gets one row without a window.
            let windows = spec.faults.len().max(1);
            for w in 0..windows {
                let fault = spec.faults.get(w);
                let scored = outcome.and_then(|o| o.windows.get(w));
                let isolated = scored.and_then(|s| s.first_declared);
                core.push(Outcome {
                    trial: spec.trial,
                    detector: bank,
                    kind: fault.map_or(NO_FAULT, |f| f.fault.kind.name()),
                    target: fault.map(|f| Cow::Borrowed(SURFACE_NAMES[f.fault.surface])),
                    size: fault.map(|f| f.size),
                    size_unit: fault.map_or(crate::engine::results::schema::unit::NONE, |f| f.fault.kind.size_unit()),
                    size_bin: fault.map(|f| f.size_bin),
                    onset_s: fault.map(|f| f.fault.onset_s),
                    fault_free: spec.faults.is_empty(),
                    failure: r.outcome.as_ref().err().map(|e| e.to_string()),
                    diverged: outcome.is_some_and(|o| o.health.non_finite > 0),
                    truth_diverged: false,
                    false_alarm_s: outcome.and_then(|o| o.first_false_alarm_s),
                    delay_s: scored.and_then(|s| s.detection_delay_s),
                    isolated: isolated.map(|j| Cow::Borrowed(SURFACE_NAMES[j])),
                    isolated_correctly: scored.filter(|_| isolated.is_some()).map(|s| s.isolated_correctly()),
                    noise_scale: spec.noise_scale,
                    noise_bin: spec.noise_bin,
                    param_error_bin: spec.parameter_error_bin,
                    param_errors: &spec.parameter_errors,
                });
                statistics.push_recorded(0, outcome.and_then(|o| o.statistics.get(w)));
                t.end_s.push(fault.map(|f| f.fault.end_s.unwrap_or(study.header.duration_s)));
                t.window.push(fault.map(|_| w as u32));
                t.isolation_delay_s.push(scored.and_then(|s| s.isolation_delay_s));
                t.cleared.push(scored.and_then(|s| s.isolation_delay_s.map(|_| s.clearing_delay_s.is_some())));
                t.clearing_delay_s.push(scored.and_then(|s| s.clearing_delay_s));
                t.recovered.push(scored.and_then(|s| s.detection_delay_s.map(|_| s.recovery_delay_s.is_some())));
                t.recovery_delay_s.push(scored.and_then(|s| s.recovery_delay_s));
                let degrees = |rms_rad: fn(&WindowOutcome) -> f64| {
                    scored.map(|s| rms_rad(s).to_degrees()).filter(|v: &f64| v.is_finite())
                };
                t.estimate_rms_deg.push(degrees(|s| s.surface_estimate_rms_rad));
                t.estimate_rms_window_deg.push(degrees(|s| s.surface_estimate_rms_window_rad));
                t.estimate_rms_first_s_deg.push(degrees(|s| s.surface_estimate_rms_first_s_rad));
                t.false_alarms.push(outcome.map(|o| o.false_alarms));
                t.post_fault.push(outcome.map(|o| o.post_fault_declarations));
                t.health.push(outcome.map(|o| o.health));
                t.floor.push(outcome.map(|o| o.floor_steps));
            }
        }
    }
    let mut columns = core.finish();
    columns.extend([
        Column::new("end_s".into(), t.end_s),
        Column::new("window".into(), t.window),
        Column::new(col::ISOLATION_DELAY_S.into(), t.isolation_delay_s),
        Column::new(col::CLEARED.into(), t.cleared),
        Column::new(col::CLEARING_DELAY_S.into(), t.clearing_delay_s),
        Column::new(col::RECOVERED.into(), t.recovered),
        Column::new(col::RECOVERY_DELAY_S.into(), t.recovery_delay_s),
        Column::new(col::SURFACE_ESTIMATE_RMS_DEG.into(), t.estimate_rms_deg),
        Column::new(col::SURFACE_ESTIMATE_RMS_WINDOW_DEG.into(), t.estimate_rms_window_deg),
        Column::new(col::SURFACE_ESTIMATE_RMS_FIRST_S_DEG.into(), t.estimate_rms_first_s_deg),
        Column::new("false_alarms".into(), t.false_alarms),
        Column::new(col::POST_FAULT_DECLARATIONS.into(), t.post_fault),
    ]);
    columns.extend(t.health.finish());
    columns.push(Column::new("floor_steps".into(), t.floor));
    columns.extend(statistics.finish());
    DataFrame::new_infer_height(columns)
}

/// This kind's own columns while rows are added.
#[derive(Default)]
struct Columns {
    end_s: Vec<Option<f64>>,
    window: Vec<Option<u32>>,
    isolation_delay_s: Vec<Option<f64>>,
    cleared: Vec<Option<bool>>,
    clearing_delay_s: Vec<Option<f64>>,
    recovered: Vec<Option<bool>>,
    recovery_delay_s: Vec<Option<f64>>,
    estimate_rms_deg: Vec<Option<f64>>,
    estimate_rms_window_deg: Vec<Option<f64>>,
    estimate_rms_first_s_deg: Vec<Option<f64>>,
    false_alarms: Vec<Option<u32>>,
    post_fault: Vec<Option<u32>>,
    health: FilterHealthColumns,
    floor: Vec<Option<u32>>,
}

#[cfg(test)]
mod tests {

    use polars::prelude::*;

    use super::*;
    use crate::engine::results::summary::hand_made::Summarized;
    use crate::engine::scenario::deck::FromDeck;
    use crate::engine::stats::intervals::{Z95, wilson};
    use crate::estimation::FilterHealth;
    use crate::methods::surface_bank::actuator::{ActuatorFault, ActuatorFaultKind};
    use crate::methods::surface_bank::scenario::{ScenarioFault, SurfaceTrialSpec};
    use crate::methods::surface_bank::study::SurfaceStudy;
    use crate::methods::surface_bank::trial::{BankOutcome, SurfaceTrialResult, UavSimError, WindowOutcome};

    /// Two banks on five hand-made trials (a left aileron stuck at -15 deg from 5 s to 15 s, or none):
    /// trial 0: a isolates (0.5 s), b declares the rudder first (1.0 s); trial 1: a misses, b isolates
    /// (0.8 s); trial 2: fault-free, a false alarm by a; trial 3: the flight left the envelope; trial 4:
    /// both isolate (0.4 s, 0.6 s), and b declares twice more after the fault ended.
    fn hand_made() -> (SurfaceStudy, DataFrame) {
        let mut study = SurfaceStudy::bundled("seed004_surfaces.toml");
        study.banks.truncate(2);
        study.banks[0].0 = "a".into();
        study.banks[1].0 = "b".into();
        let fault = ActuatorFault {
            surface: 0,
            kind: ActuatorFaultKind::Stuck { position_rad: (-15f64).to_radians() },
            onset_s: 5.0,
            end_s: Some(15.0),
        };
        let spec = |trial: u64, faulty: bool| SurfaceTrialSpec {
            trial,
            faults: if faulty { vec![ScenarioFault { fault, size: -15.0, size_bin: -15.0 }] } else { vec![] },
            noise_scale: 1.0,
            noise_bin: 1.0,
            parameter_errors: vec![],
            parameter_error_bin: 0.0,
        };
        let window = |detect: Option<f64>, first: Option<usize>, clear: Option<f64>| WindowOutcome {
            surface: 0,
            onset_s: 5.0,
            end_s: 15.0,
            detection_delay_s: detect,
            isolation_delay_s: if first == Some(0) { detect } else { None },
            first_declared: first,
            clearing_delay_s: clear,
            // The no-fault model comes back 1 s after the declaration clears (none without a clearance).
            recovery_delay_s: clear.map(|c| c + 1.0),
            surface_estimate_rms_rad: 0.01,
            surface_estimate_rms_window_rad: 0.02,
            surface_estimate_rms_first_s_rad: 0.05,
        };
        let bank = |w: Option<WindowOutcome>, false_alarms: u32| BankOutcome {
            windows: w.into_iter().collect(),
            statistics: Vec::new(),
            false_alarms,
            first_false_alarm_s: (false_alarms > 0).then_some(2.0),
            post_fault_declarations: 0,
            health: FilterHealth::default(),
            floor_steps: 0,
        };
        let results = vec![
            SurfaceTrialResult {
                spec: spec(0, true),
                outcome: Ok(vec![
                    bank(Some(window(Some(0.5), Some(0), Some(0.2))), 0),
                    bank(Some(window(Some(1.0), Some(4), None)), 0),
                ]),
            },
            SurfaceTrialResult {
                spec: spec(1, true),
                outcome: Ok(vec![
                    bank(Some(window(None, None, None)), 0),
                    bank(Some(window(Some(0.8), Some(0), Some(4.0))), 0),
                ]),
            },
            SurfaceTrialResult { spec: spec(2, false), outcome: Ok(vec![bank(None, 1), bank(None, 0)]) },
            SurfaceTrialResult {
                spec: spec(3, true),
                outcome: Err(UavSimError::Envelope { t_s: 9.0, what: "altitude below 0".into() }),
            },
            SurfaceTrialResult {
                spec: spec(4, true),
                outcome: Ok(vec![
                    bank(Some(window(Some(0.4), Some(0), Some(0.3))), 0),
                    BankOutcome { post_fault_declarations: 2, ..bank(Some(window(Some(0.6), Some(0), Some(0.5))), 0) },
                ]),
            },
        ];
        let df = frame(&study, &results).unwrap();
        (study, df)
    }

    /// The shared summary of the hand-made trials, read back from the tables it writes.
    #[test]
    fn summary_counts_rates_and_paired_differences_of_hand_made_trials() {
        let (_, df) = hand_made();
        assert_eq!(df.height(), 10, "one row per trial and bank");
        let degrees = |n: &str| df.column(n).unwrap().f64().unwrap().get(0).unwrap();
        for (name, rad) in [
            ("surface_estimate_rms_deg", 0.01f64),
            ("surface_estimate_rms_window_deg", 0.02),
            ("surface_estimate_rms_first_s_deg", 0.05),
        ] {
            assert!((degrees(name) - rad.to_degrees()).abs() < 1e-12, "{name}");
        }
        let summarized = Summarized::of(df, &super::super::METHOD, 5, &["a", "b"]);
        let table = |name: &str| summarized.deck_table(name);

        let summary = table("summary.csv");
        let u = |n: &str| -> Vec<u64> {
            let c = summary.column(n).unwrap().cast(&DataType::UInt64).unwrap();
            c.u64().unwrap().into_no_null_iter().collect()
        };
        let f = |n: &str| -> Vec<Option<f64>> {
            let c = summary.column(n).unwrap().cast(&DataType::Float64).unwrap();
            c.f64().unwrap().iter().collect()
        };
        // Rows: (a, none), (a, stuck), (b, none), (b, stuck): sorted by detector, then kind.
        let kinds = summary.column("kind").unwrap().str().unwrap().clone();
        let kinds: Vec<_> = (0..kinds.len()).map(|i| kinds.get(i).unwrap().to_string()).collect();
        assert_eq!(kinds, ["none", "stuck", "none", "stuck"]);
        assert_eq!(u("trials"), [1, 4, 1, 4]);
        assert_eq!(u("failed"), [0, 1, 0, 1]);
        assert_eq!(u("detected"), [0, 2, 0, 3]);
        assert_eq!(u("isolated_correctly"), [0, 2, 0, 2]);
        assert_eq!(u("false_alarms"), [1, 0, 0, 0]);
        assert_eq!(u("post_fault"), [0, 0, 0, 1]);
        assert_eq!(f("post_fault_rate")[3], Some(1.0 / 3.0));
        assert_eq!(f("post_fault_rate")[2], None, "no fault, nothing after one");
        assert_eq!(f("pd")[1], Some(2.0 / 3.0));
        assert_eq!(f("pd")[3], Some(1.0));
        assert_eq!(f("pd")[0], None, "no detection probability without a fault");
        assert_eq!(f("isolation_accuracy")[3], Some(2.0 / 3.0));
        assert_eq!(f("pfa")[0], Some(1.0));
        assert_eq!(f("delay_p50_s")[1], Some(0.45));
        assert_eq!(f("clearing_rate")[3], Some(1.0), "b cleared both faults it isolated");
        assert_eq!(u("recovery_decided"), [0, 2, 0, 3], "detected windows");
        assert_eq!(f("recovery_rate")[3], Some(2.0 / 3.0), "b detected three, recovered after two");
        assert_eq!(f("recovery_p50_s")[1], Some(1.25), "a: 1.2 and 1.3 s");
        let (lo, hi) = wilson(2, 3, Z95);
        assert_eq!((f("pd_lo")[1], f("pd_hi")[1]), (Some(lo), Some(hi)));

        let c = table("comparison.csv");
        let cu = |n: &str| c.column(n).unwrap().cast(&DataType::UInt64).unwrap().u64().unwrap().get(0).unwrap();
        assert_eq!(c.height(), 1);
        assert_eq!(cu("faulty_units"), 3, "trials 0, 1, 4: trial 3 did not fly to the end");
        assert_eq!((cu("detected_by_a_only"), cu("detected_by_b_only")), (0, 1));
        assert_eq!((cu("isolated_by_a_only"), cu("isolated_by_b_only")), (1, 1));
        assert_eq!((cu("flights"), cu("false_alarm_a_only"), cu("false_alarm_b_only")), (4, 1, 0));
        assert_eq!(cu("delay_pairs"), 2);
        let diff = c.column("median_delay_b_minus_a_s").unwrap().f64().unwrap().get(0).unwrap();
        assert!((diff - 0.35).abs() < 1e-12, "median of 1.0 - 0.5 and 0.6 - 0.4: {diff}");
        // With two pairs the sign-test interval is their range.
        let bound = |n: &str| c.column(n).unwrap().f64().unwrap().get(0).unwrap();
        let (lo, hi) = (bound("median_delay_b_minus_a_s_lo"), bound("median_delay_b_minus_a_s_hi"));
        assert!((lo - 0.2).abs() < 1e-12 && (hi - 0.5).abs() < 1e-12, "[{lo}, {hi}]");
        assert_eq!(bound("median_surface_estimate_rms_deg_b_minus_a"), 0.0, "the same estimate error in every window");
        let clearing = c.column("median_clearing_delay_s_b_minus_a").unwrap().f64().unwrap().get(0).unwrap();
        assert!((clearing - 0.2).abs() < 1e-12, "only trial 4 has both clearing delays: 0.5 - 0.3: {clearing}");
        let recovery = bound("median_recovery_delay_s_b_minus_a");
        assert!((recovery - 0.2).abs() < 1e-12, "only trial 4 has both recoveries: 1.5 - 1.3: {recovery}");
        let p = c.column("mcnemar_p_detection").unwrap().f64().unwrap().get(0).unwrap();
        assert_eq!(p, 1.0);

        let v = table("detectors.csv");
        let vu = |n: &str| -> Vec<u64> {
            v.column(n).unwrap().cast(&DataType::UInt64).unwrap().u64().unwrap().into_no_null_iter().collect()
        };
        assert_eq!(vu("flights"), [5, 5]);
        assert_eq!(vu("flights_failed"), [1, 1]);
        assert_eq!(vu("flights_with_false_alarm"), [1, 0]);
        assert_eq!(vu("detected"), [2, 3]);
        let pfa: Vec<f64> = v.column("pfa").unwrap().f64().unwrap().into_no_null_iter().collect();
        assert_eq!(pfa, [0.25, 0.0]);

        let confusion = table("confusion.csv");
        let cc = |n: &str| -> Vec<String> {
            let c = confusion.column(n).unwrap().str().unwrap().clone();
            (0..c.len()).map(|i| c.get(i).unwrap().to_string()).collect()
        };
        // a: aileron_left named twice, once nothing; b: twice, the rudder once.
        assert_eq!(cc("detector"), ["a", "a", "b", "b"]);
        assert_eq!(cc("isolated"), ["aileron_left", "none", "aileron_left", "rudder"]);
    }
}
