//! The trial-record table of air-data studies (`trials.parquet` of method 002): one row per (trial,
//! detector configuration).
//!
//! | column | meaning |
//! |---|---|
//! | `trial`, `detector` | trial index (its random streams), detector configuration |
//! | `kind`, `sensors`, `faulty_sensors` | fault kind (`none` when fault-free), the faulty sensors joined by `+`, how many |
//! | `size`, `size_bin` | fault size as the deck gives it (sensor sigmas, output units, or a gain factor); its group label |
//! | `onset_s` | fault onset |
//! | `noise_scale`, `noise_bin`, `gust_std_mps`, `gust_bin` | factor on every sensor sigma, turbulence intensity, and their group labels |
//! | `failure` | why the trial could not be flown (null: flown) |
//! | `false_alarm_s` | first declaration before the onset (anywhere when fault-free) |
//! | `detected`, `delay_s` | a declaration at or after the onset; its delay |
//! | `isolated`, `isolated_correctly` | the detector's faulty set after `isolation_delay_s` (`none`: empty), whether it is exactly the faulty sensors |
//! | `bias_error_rms_sigma` | bias and drift faults: RMS error of the bias estimate over the fault's second half, in sigmas |
//! | `estimate_rms_sigma`, `raw_rms_sigma` | over the same period, RMS error of the blended air data and of the raw faulty sensors against the truth, pooled over the faulty sensors, in sigmas |
//! | `<channel>_estimate_rms`, `<channel>_raw_rms` | the same per channel, in its units (`airspeed_mps`, `alpha_deg`, `beta_deg`) |
//! | `covariance_repairs`, `singular_innovation_steps`, `non_finite_steps` | UKF health, both filters |
//! | `floor_steps`, `both_reinitialisations` | steps with the probability floor applied; steps re-initialising both models |

use polars::prelude::*;

use crate::engine::schema::col as common;
use crate::methods::air_data::flight::AIR_DATA_CHANNEL_NAMES;
use crate::methods::air_data::study::AirDataStudy;
use crate::methods::air_data::trial::AirDataTrialResult;

/// Column names of this table beyond those it shares with the LTI records.
pub mod col {
    pub const SENSORS: &str = "sensors";
    pub const FAULTY_SENSORS: &str = "faulty_sensors";
    pub const GUST_STD_MPS: &str = "gust_std_mps";
    pub const GUST_BIN: &str = "gust_bin";
    pub const FAILURE: &str = "failure";
    pub const DETECTED: &str = "detected";
    pub const ISOLATED: &str = "isolated";
    pub const ISOLATED_CORRECTLY: &str = "isolated_correctly";
    pub const BIAS_ERROR_RMS_SIGMA: &str = "bias_error_rms_sigma";
    pub const ESTIMATE_RMS_SIGMA: &str = "estimate_rms_sigma";
    pub const RAW_RMS_SIGMA: &str = "raw_rms_sigma";
    pub const COVARIANCE_REPAIRS: &str = "covariance_repairs";
    pub const SINGULAR_INNOVATION_STEPS: &str = "singular_innovation_steps";
    pub const NON_FINITE_STEPS: &str = "non_finite_steps";
    pub const FLOOR_STEPS: &str = "floor_steps";
    pub const BOTH_REINITIALISATIONS: &str = "both_reinitialisations";
}

/// Per-channel error columns: name and the factor from the channel's SI unit (m/s, rad) to the column's.
const CHANNEL_COLUMNS: [(&str, f64); 3] =
    [("airspeed_mps", 1.0), ("alpha_deg", 180.0 / std::f64::consts::PI), ("beta_deg", 180.0 / std::f64::consts::PI)];

/// A set of sensors as a column value: names joined by `+` (`none` when empty).
pub fn sensor_set(channels: &[usize]) -> String {
    if channels.is_empty() {
        return common::NO_FAULT.to_string();
    }
    channels.iter().map(|&j| AIR_DATA_CHANNEL_NAMES[j]).collect::<Vec<_>>().join("+")
}

/// The rows of `results` (trial order); see the module docs.
pub fn frame(study: &AirDataStudy, results: &[AirDataTrialResult]) -> PolarsResult<DataFrame> {
    let rows = results.len() * study.detectors.len();
    let mut t = Columns::with_capacity(rows);
    for r in results {
        let s = &r.spec;
        for (d, det) in study.detectors.iter().enumerate() {
            let o = r.outcome.as_ref().ok().map(|o| &o[d]);
            let faulty = !s.faults.is_empty();
            t.trial.push(s.trial);
            t.detector.push(det.name.clone());
            t.kind.push(s.kind);
            t.sensors.push(faulty.then(|| sensor_set(&s.outputs)));
            t.faulty_sensors.push(s.outputs.len() as u32);
            t.size.push(s.size.is_finite().then_some(s.size));
            t.size_bin.push(s.size_bin.is_finite().then_some(s.size_bin));
            t.onset_s.push(faulty.then_some(s.onset_s));
            t.noise_scale.push(s.noise_scale);
            t.noise_bin.push(s.noise_bin);
            t.gust.push(s.gust_std_mps);
            t.gust_bin.push(s.gust_bin);
            t.failure.push(r.outcome.as_ref().err().cloned());
            t.false_alarm_s.push(o.and_then(|o| o.false_alarm_s));
            t.detected.push(o.map(|o| faulty && o.detection_s.is_some()));
            t.delay_s.push(o.and_then(|o| o.detection_s).map(|d| d - s.onset_s));
            t.isolated.push(o.and_then(|o| o.isolated.as_deref().map(sensor_set)));
            t.isolated_correctly.push(o.and_then(|o| o.isolated.as_ref().map(|i| *i == s.outputs)));
            t.bias_error.push(o.and_then(|o| o.bias_error_rms_sigma));
            t.estimate_sigma.push(o.and_then(|o| o.estimate_rms_sigma));
            t.raw_sigma.push(o.and_then(|o| o.raw_rms_sigma));
            for (j, (_, factor)) in CHANNEL_COLUMNS.iter().enumerate() {
                t.estimate[j].push(o.map(|o| o.estimate_rms[j] * factor));
                t.raw[j].push(o.map(|o| o.raw_rms[j] * factor));
            }
            let h = o.map(|o| o.health);
            t.repairs.push(h.map(|h| h.no_fault.covariance_repairs + h.fault.covariance_repairs));
            t.singular.push(h.map(|h| h.no_fault.singular_innovation + h.fault.singular_innovation));
            t.non_finite.push(h.map(|h| h.no_fault.non_finite + h.fault.non_finite));
            t.floor.push(h.map(|h| h.probability_floor_steps));
            t.both.push(h.map(|h| h.both_models_reinitialisations));
        }
    }
    let mut columns = vec![
        Column::new(common::TRIAL.into(), t.trial),
        Column::new(common::DETECTOR.into(), t.detector),
        Column::new(common::KIND.into(), t.kind),
        Column::new(col::SENSORS.into(), t.sensors),
        Column::new(col::FAULTY_SENSORS.into(), t.faulty_sensors),
        Column::new(common::SIZE.into(), t.size),
        Column::new(common::SIZE_BIN.into(), t.size_bin),
        Column::new(common::ONSET_S.into(), t.onset_s),
        Column::new(common::NOISE_SCALE.into(), t.noise_scale),
        Column::new(common::NOISE_BIN.into(), t.noise_bin),
        Column::new(col::GUST_STD_MPS.into(), t.gust),
        Column::new(col::GUST_BIN.into(), t.gust_bin),
        Column::new(col::FAILURE.into(), t.failure),
        Column::new(common::FALSE_ALARM_S.into(), t.false_alarm_s),
        Column::new(col::DETECTED.into(), t.detected),
        Column::new(common::DELAY_S.into(), t.delay_s),
        Column::new(col::ISOLATED.into(), t.isolated),
        Column::new(col::ISOLATED_CORRECTLY.into(), t.isolated_correctly),
        Column::new(col::BIAS_ERROR_RMS_SIGMA.into(), t.bias_error),
        Column::new(col::ESTIMATE_RMS_SIGMA.into(), t.estimate_sigma),
        Column::new(col::RAW_RMS_SIGMA.into(), t.raw_sigma),
    ];
    for (j, (name, _)) in CHANNEL_COLUMNS.iter().enumerate() {
        columns.push(Column::new(format!("{name}_estimate_rms").into(), std::mem::take(&mut t.estimate[j])));
        columns.push(Column::new(format!("{name}_raw_rms").into(), std::mem::take(&mut t.raw[j])));
    }
    columns.extend([
        Column::new(col::COVARIANCE_REPAIRS.into(), t.repairs),
        Column::new(col::SINGULAR_INNOVATION_STEPS.into(), t.singular),
        Column::new(col::NON_FINITE_STEPS.into(), t.non_finite),
        Column::new(col::FLOOR_STEPS.into(), t.floor),
        Column::new(col::BOTH_REINITIALISATIONS.into(), t.both),
    ]);
    DataFrame::new_infer_height(columns)
}

/// The table's columns while rows are added.
#[derive(Default)]
struct Columns {
    trial: Vec<u64>,
    detector: Vec<String>,
    kind: Vec<&'static str>,
    sensors: Vec<Option<String>>,
    faulty_sensors: Vec<u32>,
    size: Vec<Option<f64>>,
    size_bin: Vec<Option<f64>>,
    onset_s: Vec<Option<f64>>,
    noise_scale: Vec<f64>,
    noise_bin: Vec<f64>,
    gust: Vec<f64>,
    gust_bin: Vec<f64>,
    failure: Vec<Option<String>>,
    false_alarm_s: Vec<Option<f64>>,
    detected: Vec<Option<bool>>,
    delay_s: Vec<Option<f64>>,
    isolated: Vec<Option<String>>,
    isolated_correctly: Vec<Option<bool>>,
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

impl Columns {
    fn with_capacity(rows: usize) -> Self {
        let mut c = Columns::default();
        c.trial.reserve(rows);
        c.detector.reserve(rows);
        c
    }
}
