//! The trial-record table of launch-vehicle studies (`trials.parquet` of method 001): one row per
//! (trial, detector configuration).
//!
//! | column | meaning |
//! |---|---|
//! | `trial`, `detector` | trial index (its random streams), detector configuration |
//! | `kind`, `engine` | `thrust_loss` (or `none` when fault-free) and the faulty engine, `engine_1` to `engine_4` |
//! | `size`, `size_bin` | the loss (% of one engine's thrust) and its group label |
//! | `onset_s` | fault onset |
//! | `noise_scale`, `noise_bin`, `gust_scale`, `gust_bin` | factors on the sensor sigmas and the deck's gusts, and their group labels |
//! | `failure` | why the flight ended early (null: flown to the end) |
//! | `pre_max_fhat` | largest `\|fhat\|` before the onset (the whole flight when fault-free) |
//! | `fp_t_s_fhat`, `fp_v_fhat` | first-passage profile of `\|fhat\|` after the onset (lists): evaluate any threshold |
//! | `false_alarm_s`, `alarm_s`, `delay_s` | at the deck's threshold: first alarm before the onset; first at or after it, and its delay |
//! | `localised`, `localised_correctly` | the engine named from the overload jumps at the detection (`none`: no sign pattern), whether it is the faulty one |
//! | `onset_estimate_s`, `fhat_peak`, `loss_estimate_percent`, `loss_error_percent` | the detector's onset estimate, the peak `\|fhat\|` over the loss table's horizon after the alarm, the loss it means, minus the true loss |
//! | `singular_innovation_steps`, `asymmetric_steps`, `not_positive_definite_steps`, `non_finite_steps` | EKF health |
//! | `sensitivity_clamped`, `gls_failed` | samples outside the sensitivity grid; non-finite estimates |

use polars::prelude::*;

use crate::engine::schema::col as common;
use crate::methods::thrust_loss::study::LaunchStudy;
use crate::methods::thrust_loss::trial::LaunchTrialResult;

/// Column names of this table beyond those it shares with the LTI records.
pub mod col {
    pub const ENGINE: &str = "engine";
    pub const GUST_SCALE: &str = "gust_scale";
    pub const GUST_BIN: &str = "gust_bin";
    pub const FAILURE: &str = "failure";
    pub const PRE_MAX_FHAT: &str = "pre_max_fhat";
    pub const FP_T_S: &str = "fp_t_s_fhat";
    pub const FP_V: &str = "fp_v_fhat";
    pub const LOCALISED: &str = "localised";
    pub const LOCALISED_CORRECTLY: &str = "localised_correctly";
    pub const ONSET_ESTIMATE_S: &str = "onset_estimate_s";
    pub const FHAT_PEAK: &str = "fhat_peak";
    pub const LOSS_ESTIMATE_PERCENT: &str = "loss_estimate_percent";
    pub const LOSS_ERROR_PERCENT: &str = "loss_error_percent";
    /// Fault kind of a thrust loss.
    pub const THRUST_LOSS: &str = "thrust_loss";

    /// The engine's name in tables (index 0 is the seed's engine 1).
    pub fn engine_name(index: usize) -> String {
        format!("engine_{}", index + 1)
    }
}

/// The rows of `results` (trial order); see the module docs.
pub fn frame(study: &LaunchStudy, results: &[LaunchTrialResult]) -> PolarsResult<DataFrame> {
    let rows = results.len() * study.detectors.len();
    let list =
        |name: &str| ListPrimitiveChunkedBuilder::<Float64Type>::new(name.into(), rows, rows * 4, DataType::Float64);
    let (mut fp_t, mut fp_v) = (list(col::FP_T_S), list(col::FP_V));
    let mut t = Columns::default();
    for r in results {
        let s = &r.spec;
        for (d, det) in study.detectors.iter().enumerate() {
            let o = r.outcome.as_ref().ok().map(|o| &o[d]);
            let onset = s.fault.map(|f| f.onset_s);
            t.trial.push(s.trial);
            t.detector.push(det.name.clone());
            t.kind.push(if s.fault.is_some() { col::THRUST_LOSS } else { common::NO_FAULT });
            t.engine.push(s.fault.map(|f| col::engine_name(f.engine)));
            t.size.push(s.fault.map(|_| s.loss_percent));
            t.size_bin.push(s.fault.map(|_| s.loss_bin));
            t.onset_s.push(onset);
            t.noise_scale.push(s.noise_scale);
            t.noise_bin.push(s.noise_bin);
            t.gust_scale.push(s.gust_scale);
            t.gust_bin.push(s.gust_bin);
            t.failure.push(r.outcome.as_ref().err().cloned());
            t.pre_max.push(o.map(|o| o.pre_max_fhat));
            match o {
                Some(o) => {
                    fp_t.append_slice(&o.profile_t_s);
                    fp_v.append_slice(&o.profile_fhat);
                }
                None => {
                    fp_t.append_slice(&[]);
                    fp_v.append_slice(&[]);
                }
            }
            t.false_alarm_s.push(o.and_then(|o| o.false_alarm_s));
            t.alarm_s.push(o.and_then(|o| o.alarm_s));
            t.delay_s.push(o.and_then(|o| o.alarm_s).zip(onset).map(|(a, t0)| a - t0));
            let localised = o.and_then(|o| o.localised);
            t.localised.push(localised.map(|e| e.map_or(common::NO_FAULT.to_string(), col::engine_name)));
            t.localised_correctly.push(localised.map(|e| e.is_some() && e == s.fault.map(|f| f.engine)));
            t.onset_estimate.push(o.and_then(|o| o.onset_estimate_s));
            t.fhat_peak.push(o.and_then(|o| o.fhat_peak));
            let estimate = o.and_then(|o| o.loss_estimate_percent);
            t.loss_estimate.push(estimate);
            t.loss_error.push(estimate.filter(|_| s.fault.is_some()).map(|e| e - s.loss_percent));
            let h = o.map(|o| o.health);
            t.singular.push(h.map(|h| h.filter.singular_innovation));
            t.asymmetric.push(h.map(|h| h.filter.asymmetric));
            t.not_pd.push(h.map(|h| h.filter.not_positive_definite));
            t.non_finite.push(h.map(|h| h.filter.non_finite));
            t.clamped.push(h.map(|h| h.sensitivity_clamped));
            t.gls_failed.push(h.map(|h| h.gls_failed));
        }
    }
    DataFrame::new_infer_height(vec![
        Column::new(common::TRIAL.into(), t.trial),
        Column::new(common::DETECTOR.into(), t.detector),
        Column::new(common::KIND.into(), t.kind),
        Column::new(col::ENGINE.into(), t.engine),
        Column::new(common::SIZE.into(), t.size),
        Column::new(common::SIZE_BIN.into(), t.size_bin),
        Column::new(common::ONSET_S.into(), t.onset_s),
        Column::new(common::NOISE_SCALE.into(), t.noise_scale),
        Column::new(common::NOISE_BIN.into(), t.noise_bin),
        Column::new(col::GUST_SCALE.into(), t.gust_scale),
        Column::new(col::GUST_BIN.into(), t.gust_bin),
        Column::new(col::FAILURE.into(), t.failure),
        Column::new(col::PRE_MAX_FHAT.into(), t.pre_max),
        fp_t.finish().into_series().into_column(),
        fp_v.finish().into_series().into_column(),
        Column::new(common::FALSE_ALARM_S.into(), t.false_alarm_s),
        Column::new(common::ALARM_S.into(), t.alarm_s),
        Column::new(common::DELAY_S.into(), t.delay_s),
        Column::new(col::LOCALISED.into(), t.localised),
        Column::new(col::LOCALISED_CORRECTLY.into(), t.localised_correctly),
        Column::new(col::ONSET_ESTIMATE_S.into(), t.onset_estimate),
        Column::new(col::FHAT_PEAK.into(), t.fhat_peak),
        Column::new(col::LOSS_ESTIMATE_PERCENT.into(), t.loss_estimate),
        Column::new(col::LOSS_ERROR_PERCENT.into(), t.loss_error),
        Column::new("singular_innovation_steps".into(), t.singular),
        Column::new("asymmetric_steps".into(), t.asymmetric),
        Column::new("not_positive_definite_steps".into(), t.not_pd),
        Column::new("non_finite_steps".into(), t.non_finite),
        Column::new("sensitivity_clamped".into(), t.clamped),
        Column::new("gls_failed".into(), t.gls_failed),
    ])
}

/// The table's columns while rows are added.
#[derive(Default)]
struct Columns {
    trial: Vec<u64>,
    detector: Vec<String>,
    kind: Vec<&'static str>,
    engine: Vec<Option<String>>,
    size: Vec<Option<f64>>,
    size_bin: Vec<Option<f64>>,
    onset_s: Vec<Option<f64>>,
    noise_scale: Vec<f64>,
    noise_bin: Vec<f64>,
    gust_scale: Vec<f64>,
    gust_bin: Vec<f64>,
    failure: Vec<Option<String>>,
    pre_max: Vec<Option<f64>>,
    false_alarm_s: Vec<Option<f64>>,
    alarm_s: Vec<Option<f64>>,
    delay_s: Vec<Option<f64>>,
    localised: Vec<Option<String>>,
    localised_correctly: Vec<Option<bool>>,
    onset_estimate: Vec<Option<f64>>,
    fhat_peak: Vec<Option<f64>>,
    loss_estimate: Vec<Option<f64>>,
    loss_error: Vec<Option<f64>>,
    singular: Vec<Option<u32>>,
    asymmetric: Vec<Option<u32>>,
    not_pd: Vec<Option<u32>>,
    non_finite: Vec<Option<u32>>,
    clamped: Vec<Option<u32>>,
    gls_failed: Vec<Option<u32>>,
}
