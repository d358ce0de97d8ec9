//! The trial-record table of control-surface studies (`trials.parquet` of method 004): one row per
//! (trial, bank, fault window); a fault-free trial has one row per bank with kind `none`. Trial-level
//! columns (false alarms, health counters) belong to the trial and bank, and repeat on each of its
//! window rows (a Monte Carlo fault population gives one window per faulty trial).
//!
//! | column | meaning |
//! |---|---|
//! | `trial`, `detector` | trial index (its random streams), bank name |
//! | `kind`, `surface` | fault kind (`stuck`, `oscillation`, `loss_of_effectiveness`; `none`) and faulty surface |
//! | `size`, `size_bin` | stuck position or square-wave amplitude (deg), or effectiveness (fraction); its group label |
//! | `onset_s`, `end_s`, `window` | the fault window and its index in the trial (onset order) |
//! | `noise_scale`, `noise_bin` | factor on every sensor standard deviation, and its group label |
//! | `perr_<name>`, `param_error_bin` | relative coefficient errors, and the largest \|group label\| |
//! | `failure` | why the flight stopped early (no trim, left the envelope); null: flown to the end |
//! | `detected`, `detection_delay_s` | a surface was declared in the window; from the onset to the first declaration |
//! | `isolated`, `isolated_correctly`, `isolation_delay_s` | the first surface declared in the window (`none`), whether it is the faulty one; from the onset to the first declaration of the faulty surface |
//! | `cleared`, `clearing_delay_s` | the faulty surface, once declared, was cleared after the window ended; from the end to the clearance |
//! | `surface_estimate_rms_deg` | RMS error of the faulty surface's position estimate over the window's second half |
//! | `false_alarms`, `first_false_alarm_s` | declarations while no fault was active and none had ended (trial and bank) |
//! | `post_fault_declarations` | declarations while no fault was active after one had ended (relapses during the recovery) |
//! | `singular_innovation_steps`, `asymmetric_steps`, `not_positive_definite_steps`, `non_finite_steps` | covariance health, filter-steps summed over the bank's six filters |
//! | `floor_steps` | steps on which the probability floor was applied |

use polars::prelude::*;

use crate::engine::schema::col::{self as common, perr};
use crate::methods::surface_bank::study::SurfaceStudy;
use crate::methods::surface_bank::trial::{BankOutcome, SurfaceTrialResult};
use crate::methods::surface_bank::uav::SURFACE_NAMES;

/// Column names of this table beyond those it shares with the LTI records.
pub mod col {
    pub const SURFACE: &str = "surface";
    pub const END_S: &str = "end_s";
    pub const WINDOW: &str = "window";
    pub const FAILURE: &str = "failure";
    pub const DETECTED: &str = "detected";
    pub const DETECTION_DELAY_S: &str = "detection_delay_s";
    pub const ISOLATED: &str = "isolated";
    pub const ISOLATED_CORRECTLY: &str = "isolated_correctly";
    pub const ISOLATION_DELAY_S: &str = "isolation_delay_s";
    pub const CLEARED: &str = "cleared";
    pub const CLEARING_DELAY_S: &str = "clearing_delay_s";
    pub const SURFACE_ESTIMATE_RMS_DEG: &str = "surface_estimate_rms_deg";
    pub const FALSE_ALARMS: &str = "false_alarms";
    pub const FIRST_FALSE_ALARM_S: &str = "first_false_alarm_s";
    pub const POST_FAULT_DECLARATIONS: &str = "post_fault_declarations";
    pub const SINGULAR_INNOVATION_STEPS: &str = "singular_innovation_steps";
    pub const ASYMMETRIC_STEPS: &str = "asymmetric_steps";
    pub const NOT_POSITIVE_DEFINITE_STEPS: &str = "not_positive_definite_steps";
    pub const NON_FINITE_STEPS: &str = "non_finite_steps";
    pub const FLOOR_STEPS: &str = "floor_steps";
}

/// The rows of `results` (trial order); see the module docs.
pub fn frame(study: &SurfaceStudy, results: &[SurfaceTrialResult]) -> PolarsResult<DataFrame> {
    let mut t = Columns::default();
    let n_perr = study.monte_carlo.parameter_errors.len();
    let mut perrs: Vec<Vec<f64>> = vec![Vec::new(); n_perr];
    for r in results {
        let spec = &r.spec;
        for (b, (bank, _)) in study.banks.iter().enumerate() {
            let outcome: Option<&BankOutcome> = r.outcome.as_ref().ok().map(|o| &o[b]);
            // One row per window; a fault-free trial gets one row without a window.
            let windows = spec.faults.len().max(1);
            for w in 0..windows {
                let fault = spec.faults.get(w);
                let scored = outcome.and_then(|o| o.windows.get(w));
                t.trial.push(spec.trial);
                t.detector.push(bank.clone());
                t.kind.push(fault.map_or(common::NO_FAULT, |f| f.fault.kind.name()));
                t.surface.push(fault.map(|f| SURFACE_NAMES[f.fault.surface]));
                t.size.push(fault.map(|f| f.size));
                t.size_bin.push(fault.map(|f| f.size_bin));
                t.onset_s.push(fault.map(|f| f.fault.onset_s));
                t.end_s.push(fault.map(|f| f.fault.end_s.unwrap_or(study.duration_s)));
                t.window.push(fault.map(|_| w as u32));
                t.noise_scale.push(spec.noise_scale);
                t.noise_bin.push(spec.noise_bin);
                for (k, v) in spec.parameter_errors.iter().enumerate() {
                    perrs[k].push(*v);
                }
                t.param_error_bin.push(spec.parameter_error_bin);
                t.failure.push(r.outcome.as_ref().err().map(|e| e.to_string()));
                t.detected.push(scored.map(|s| s.detection_delay_s.is_some()));
                t.detection_delay_s.push(scored.and_then(|s| s.detection_delay_s));
                t.isolated.push(scored.map(|s| s.first_declared.map_or(common::NO_FAULT, |j| SURFACE_NAMES[j])));
                t.isolated_correctly.push(scored.map(|s| s.isolated_correctly()));
                t.isolation_delay_s.push(scored.and_then(|s| s.isolation_delay_s));
                t.cleared.push(scored.and_then(|s| s.isolation_delay_s.map(|_| s.clearing_delay_s.is_some())));
                t.clearing_delay_s.push(scored.and_then(|s| s.clearing_delay_s));
                t.estimate_rms_deg
                    .push(scored.map(|s| s.surface_estimate_rms_rad.to_degrees()).filter(|v: &f64| v.is_finite()));
                t.false_alarms.push(outcome.map(|o| o.false_alarms));
                t.first_false_alarm_s.push(outcome.and_then(|o| o.first_false_alarm_s));
                t.post_fault.push(outcome.map(|o| o.post_fault_declarations));
                let h = outcome.map(|o| o.health);
                t.singular.push(h.map(|h| h.singular_innovation));
                t.asymmetric.push(h.map(|h| h.asymmetric));
                t.not_pd.push(h.map(|h| h.not_positive_definite));
                t.non_finite.push(h.map(|h| h.non_finite));
                t.floor.push(outcome.map(|o| o.floor_steps));
            }
        }
    }
    let mut columns = vec![
        Column::new(common::TRIAL.into(), t.trial),
        Column::new(common::DETECTOR.into(), t.detector),
        Column::new(common::KIND.into(), t.kind),
        Column::new(col::SURFACE.into(), t.surface),
        Column::new(common::SIZE.into(), t.size),
        Column::new(common::SIZE_BIN.into(), t.size_bin),
        Column::new(common::ONSET_S.into(), t.onset_s),
        Column::new(col::END_S.into(), t.end_s),
        Column::new(col::WINDOW.into(), t.window),
        Column::new(common::NOISE_SCALE.into(), t.noise_scale),
        Column::new(common::NOISE_BIN.into(), t.noise_bin),
    ];
    for (pe, v) in study.monte_carlo.parameter_errors.iter().zip(perrs) {
        columns.push(Column::new(perr(&pe.name).into(), v));
    }
    columns.extend([
        Column::new(common::PARAM_ERROR_BIN.into(), t.param_error_bin),
        Column::new(col::FAILURE.into(), t.failure),
        Column::new(col::DETECTED.into(), t.detected),
        Column::new(col::DETECTION_DELAY_S.into(), t.detection_delay_s),
        Column::new(col::ISOLATED.into(), t.isolated),
        Column::new(col::ISOLATED_CORRECTLY.into(), t.isolated_correctly),
        Column::new(col::ISOLATION_DELAY_S.into(), t.isolation_delay_s),
        Column::new(col::CLEARED.into(), t.cleared),
        Column::new(col::CLEARING_DELAY_S.into(), t.clearing_delay_s),
        Column::new(col::SURFACE_ESTIMATE_RMS_DEG.into(), t.estimate_rms_deg),
        Column::new(col::FALSE_ALARMS.into(), t.false_alarms),
        Column::new(col::FIRST_FALSE_ALARM_S.into(), t.first_false_alarm_s),
        Column::new(col::POST_FAULT_DECLARATIONS.into(), t.post_fault),
        Column::new(col::SINGULAR_INNOVATION_STEPS.into(), t.singular),
        Column::new(col::ASYMMETRIC_STEPS.into(), t.asymmetric),
        Column::new(col::NOT_POSITIVE_DEFINITE_STEPS.into(), t.not_pd),
        Column::new(col::NON_FINITE_STEPS.into(), t.non_finite),
        Column::new(col::FLOOR_STEPS.into(), t.floor),
    ]);
    DataFrame::new_infer_height(columns)
}

/// The table's columns while rows are added.
#[derive(Default)]
struct Columns {
    trial: Vec<u64>,
    detector: Vec<String>,
    kind: Vec<&'static str>,
    surface: Vec<Option<&'static str>>,
    size: Vec<Option<f64>>,
    size_bin: Vec<Option<f64>>,
    onset_s: Vec<Option<f64>>,
    end_s: Vec<Option<f64>>,
    window: Vec<Option<u32>>,
    noise_scale: Vec<f64>,
    noise_bin: Vec<f64>,
    param_error_bin: Vec<f64>,
    failure: Vec<Option<String>>,
    detected: Vec<Option<bool>>,
    detection_delay_s: Vec<Option<f64>>,
    isolated: Vec<Option<&'static str>>,
    isolated_correctly: Vec<Option<bool>>,
    isolation_delay_s: Vec<Option<f64>>,
    cleared: Vec<Option<bool>>,
    clearing_delay_s: Vec<Option<f64>>,
    estimate_rms_deg: Vec<Option<f64>>,
    false_alarms: Vec<Option<u32>>,
    first_false_alarm_s: Vec<Option<f64>>,
    post_fault: Vec<Option<u32>>,
    singular: Vec<Option<u32>>,
    asymmetric: Vec<Option<u32>>,
    not_pd: Vec<Option<u32>>,
    non_finite: Vec<Option<u32>>,
    floor: Vec<Option<u32>>,
}
