//! The air-data detectors' `trials.parquet` (method 002): one row per (trial, detector configuration),
//! the core columns of [`crate::engine::schema`] first, where `target` is the set of faulty sensors
//! (`airspeed_mps+alpha_rad` for a common-mode fault), `isolated` the detector's faulty set
//! `isolation_delay_s` after its detection (`none`: empty), `failure` why the flight could not be
//! flown, `diverged` a filter step with non-finite values, and sizes are as the deck gives them (sensor
//! sigmas, output units or a gain factor); then the detectors' own columns:
//!
//! | column | meaning |
//! |---|---|
//! | `faulty_sensors` | how many sensors the fault hits |
//! | `gust_std_mps`, `gust_bin` | turbulence intensity and its group label |
//! | `bias_error_rms_sigma` | bias and drift faults: RMS error of the bias estimate over the fault's second half, in sigmas |
//! | `estimate_rms_sigma`, `raw_rms_sigma` | over the same period, RMS error of the blended air data and of the raw faulty sensors against the truth, pooled over the faulty sensors, in sigmas |
//! | `<channel>_estimate_rms`, `<channel>_raw_rms` | the same per channel, in its units (`airspeed_mps`, `alpha_deg`, `beta_deg`) |
//! | `covariance_repairs`, `singular_innovation_steps`, `non_finite_steps` | UKF health, both filters |
//! | `floor_steps`, `both_reinitialisations` | steps with the probability floor applied; steps re-initialising both models |

use std::borrow::Cow;

use polars::prelude::*;

use super::flight::AIR_DATA_CHANNEL_NAMES;
use super::study::AirDataStudy;
use super::trial::AirDataTrialResult;
use crate::engine::schema::col::NO_FAULT;
use crate::engine::schema::{CoreColumns, Outcome};

/// Column names of this kind's own columns that its summary reads.
pub mod col {
    pub const GUST_BIN: &str = "gust_bin";
    pub const BIAS_ERROR_RMS_SIGMA: &str = "bias_error_rms_sigma";
    pub const ESTIMATE_RMS_SIGMA: &str = "estimate_rms_sigma";
    pub const RAW_RMS_SIGMA: &str = "raw_rms_sigma";
    pub const COVARIANCE_REPAIRS: &str = "covariance_repairs";
}

/// Per-channel error columns: name and the factor from the channel's SI unit (m/s, rad) to the column's.
const CHANNEL_COLUMNS: [(&str, f64); 3] =
    [("airspeed_mps", 1.0), ("alpha_deg", 180.0 / std::f64::consts::PI), ("beta_deg", 180.0 / std::f64::consts::PI)];

/// A set of sensors as a column value: names joined by `+` (`none` when empty).
pub fn sensor_set(channels: &[usize]) -> String {
    if channels.is_empty() {
        return NO_FAULT.to_string();
    }
    channels.iter().map(|&j| AIR_DATA_CHANNEL_NAMES[j]).collect::<Vec<_>>().join("+")
}

/// The rows of `results` (trial order); see the module docs.
pub fn frame(study: &AirDataStudy, results: &[AirDataTrialResult]) -> PolarsResult<DataFrame> {
    let rows = results.len() * study.detectors.len();
    let mut core = CoreColumns::new(Vec::new(), rows);
    let mut t = Columns::default();
    for r in results {
        let s = &r.spec;
        let faulty = !s.faults.is_empty();
        let target = sensor_set(&s.outputs);
        for (d, det) in study.detectors.iter().enumerate() {
            let o = r.outcome.as_ref().ok().map(|o| &o[d]);
            let isolated = o.and_then(|o| o.isolated.as_ref());
            let h = o.map(|o| o.health);
            core.push(Outcome {
                trial: s.trial,
                detector: &det.name,
                kind: s.kind,
                target: faulty.then(|| Cow::Owned(target.clone())),
                size: Some(s.size),
                size_unit: s.size_unit,
                size_bin: Some(s.size_bin),
                onset_s: faulty.then_some(s.onset_s),
                fault_free: !faulty,
                failure: r.outcome.as_ref().err().cloned(),
                diverged: h.is_some_and(|h| h.no_fault.non_finite + h.fault.non_finite > 0),
                false_alarm_s: o.and_then(|o| o.false_alarm_s),
                delay_s: o.and_then(|o| o.detection_s).filter(|_| faulty).map(|t| t - s.onset_s),
                isolated: isolated.map(|i| Cow::Owned(sensor_set(i))),
                isolated_correctly: isolated.map(|i| *i == s.outputs),
                noise_scale: s.noise_scale,
                noise_bin: s.noise_bin,
                param_error_bin: 0.0,
                param_errors: &[],
            });
            t.faulty_sensors.push(s.outputs.len() as u32);
            t.gust.push(s.gust_std_mps);
            t.gust_bin.push(s.gust_bin);
            t.bias_error.push(o.and_then(|o| o.bias_error_rms_sigma));
            t.estimate_sigma.push(o.and_then(|o| o.estimate_rms_sigma));
            t.raw_sigma.push(o.and_then(|o| o.raw_rms_sigma));
            for (j, (_, factor)) in CHANNEL_COLUMNS.iter().enumerate() {
                t.estimate[j].push(o.map(|o| o.estimate_rms[j] * factor));
                t.raw[j].push(o.map(|o| o.raw_rms[j] * factor));
            }
            t.repairs.push(h.map(|h| h.no_fault.covariance_repairs + h.fault.covariance_repairs));
            t.singular.push(h.map(|h| h.no_fault.singular_innovation + h.fault.singular_innovation));
            t.non_finite.push(h.map(|h| h.no_fault.non_finite + h.fault.non_finite));
            t.floor.push(h.map(|h| h.probability_floor_steps));
            t.both.push(h.map(|h| h.both_models_reinitialisations));
        }
    }
    let mut columns = core.finish();
    columns.extend([
        Column::new("faulty_sensors".into(), t.faulty_sensors),
        Column::new("gust_std_mps".into(), t.gust),
        Column::new(col::GUST_BIN.into(), t.gust_bin),
        Column::new(col::BIAS_ERROR_RMS_SIGMA.into(), t.bias_error),
        Column::new(col::ESTIMATE_RMS_SIGMA.into(), t.estimate_sigma),
        Column::new(col::RAW_RMS_SIGMA.into(), t.raw_sigma),
    ]);
    for (j, (name, _)) in CHANNEL_COLUMNS.iter().enumerate() {
        columns.push(Column::new(format!("{name}_estimate_rms").into(), std::mem::take(&mut t.estimate[j])));
        columns.push(Column::new(format!("{name}_raw_rms").into(), std::mem::take(&mut t.raw[j])));
    }
    columns.extend([
        Column::new(col::COVARIANCE_REPAIRS.into(), t.repairs),
        Column::new("singular_innovation_steps".into(), t.singular),
        Column::new("non_finite_steps".into(), t.non_finite),
        Column::new("floor_steps".into(), t.floor),
        Column::new("both_reinitialisations".into(), t.both),
    ]);
    DataFrame::new_infer_height(columns)
}

/// This kind's own columns while rows are added.
#[derive(Default)]
struct Columns {
    faulty_sensors: Vec<u32>,
    gust: Vec<f64>,
    gust_bin: Vec<f64>,
    bias_error: Vec<Option<f64>>,
    estimate_sigma: Vec<Option<f64>>,
    raw_sigma: Vec<Option<f64>>,
    estimate: [Vec<Option<f64>>; 3],
    raw: [Vec<Option<f64>>; 3],
    repairs: Vec<Option<u32>>,
    singular: Vec<Option<u32>>,
    non_finite: Vec<Option<u32>>,
    floor: Vec<Option<u32>>,
    both: Vec<Option<u32>>,
}
