//! The air-data detectors' `trials.parquet` (method 002): one row per (trial, detector configuration),
//! the core columns of [`crate::engine::results::schema`] first, where `target` is the set of faulty sensors
//! (`airspeed_mps+alpha_rad` for a common-mode fault), `isolated` the detector's faulty set
//! `isolation_delay_s` after its detection (`none`: empty), `failure` why the flight could not be
//! flown, `diverged` a filter step with non-finite values, and sizes are as the deck gives them (sensor
//! sigmas, output units or a gain factor); then the detectors' own columns:
//!
//! | column | meaning |
//! |---|---|
//! | `faulty_sensors` | how many sensors the fault hits |
//! | `gust_std_mps`, `gust_bin` | turbulence intensity and its group label |
//! | `faulty_lanes` | how many redundant lanes of each faulty sensor the fault hits (0: fault-free); a group key |
//! | `bias_error_rms_sigma` | bias and drift faults: RMS error of the bias estimate over the fault's second half, in sigmas |
//! | `estimate_rms_sigma`, `raw_rms_sigma` | over the same period, RMS error of the blended air data and of the raw faulty sensors against the truth, pooled over the faulty sensors, in sigmas |
//! | `<channel>_estimate_rms`, `<channel>_raw_rms` | the same per channel, in its units (`airspeed_mps`, `alpha_deg`, `beta_deg`) |
//! | `covariance_repairs`, `singular_innovation_steps`, `non_finite_steps` | UKF health, both filters |
//! | `floor_steps`, `both_reinitialisations` | steps with the probability floor applied; steps re-initialising both models |
//! | `pre_max_held_s`, `fp_t_s_held_s`, `fp_v_held_s` | the detector's decision statistic `held_s` recorded ([`STATISTIC`], [`crate::methods::air_data::trial`]): how long its alarm condition held, largest before the onset (the whole fault-free flight) and its first-passage profile after it, so `summarize` calibrates the hold and draws the ROC |

use std::borrow::Cow;

use polars::prelude::*;

use super::flight::AIR_DATA_CHANNEL_NAMES;
use super::study::AirDataStudy;
use super::trial::AirDataTrialResult;
use crate::engine::results::schema::col::{self as schema_col, NO_FAULT};
use crate::engine::results::schema::{CoreColumns, Outcome, StatisticColumns};

/// Column names of this kind's own columns that its summary reads.
pub mod col {
    pub const GUST_BIN: &str = "gust_bin";
    pub const FAULTY_LANES: &str = "faulty_lanes";
    pub const BIAS_ERROR_RMS_SIGMA: &str = "bias_error_rms_sigma";
    pub const ESTIMATE_RMS_SIGMA: &str = "estimate_rms_sigma";
    pub const RAW_RMS_SIGMA: &str = "raw_rms_sigma";
    pub const COVARIANCE_REPAIRS: &str = "covariance_repairs";
}

/// The recorded statistic: how long the detector's alarm condition has held (s).
pub const STATISTIC: &str = "held_s";

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
    let mut core = CoreColumns::new(Vec::new(), rows, study.monte_carlo.common.detection_window_s);
    let mut statistics = StatisticColumns::new(&[STATISTIC.to_string()], rows);
    let mut t = Columns::default();
    for r in results {
        let s = &r.spec;
        let faulty = !s.fault.faults.is_empty();
        let target = sensor_set(&s.outputs);
        for (d, det) in study.detectors.iter().enumerate() {
            let o = r.outcome.as_ref().ok().map(|o| &o[d]);
            let isolated = o.and_then(|o| o.isolated.as_ref());
            let h = o.map(|o| o.health);
            core.push(Outcome {
                trial: s.trial,
                detector: &det.name,
                kind: s.fault.kind,
                target: faulty.then(|| Cow::Owned(target.clone())),
                size: Some(s.fault.size),
                size_unit: s.fault.size_unit,
                size_bin: Some(s.fault.size_bin),
                onset_s: faulty.then_some(s.fault.onset_s),
                fault_free: !faulty,
                failure: r.outcome.as_ref().err().cloned(),
                diverged: h.is_some_and(|h| h.no_fault.non_finite + h.fault.non_finite > 0),
                truth_diverged: false,
                false_alarm_s: o.and_then(|o| o.false_alarm_s),
                delay_s: o.and_then(|o| o.detection_s).filter(|_| faulty).map(|t| t - s.fault.onset_s),
                isolated: isolated.map(|i| Cow::Owned(sensor_set(i))),
                isolated_correctly: isolated.map(|i| *i == s.outputs),
                noise_scale: s.noise_scale,
                noise_bin: s.noise_bin,
                param_error_bin: 0.0,
                param_errors: &[],
            });
            statistics.push_recorded(0, o.map(|o| &o.statistic));
            t.faulty_sensors.push(s.outputs.len() as u32);
            t.gust.push(s.gust_std_mps);
            t.gust_bin.push(s.gust_bin);
            t.faulty_lanes.push(s.faulty_lanes as u32);
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
        Column::new(col::FAULTY_LANES.into(), t.faulty_lanes),
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
        Column::new(schema_col::SINGULAR_INNOVATION_STEPS.into(), t.singular),
        Column::new(schema_col::NON_FINITE_STEPS.into(), t.non_finite),
        Column::new("floor_steps".into(), t.floor),
        Column::new("both_reinitialisations".into(), t.both),
    ]);
    columns.extend(statistics.finish());
    DataFrame::new_infer_height(columns)
}

/// This kind's own columns while rows are added.
#[derive(Default)]
struct Columns {
    faulty_sensors: Vec<u32>,
    gust: Vec<f64>,
    gust_bin: Vec<f64>,
    faulty_lanes: Vec<u32>,
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::results::summary::hand_made::Summarized;
    use crate::engine::scenario::deck::FromDeck;
    use crate::fault::deck::TrialFaults;
    use crate::fault::{ChannelFault, FaultMode};
    use crate::methods::air_data::dual_ukf::DualUkfHealth;
    use crate::methods::air_data::scenario::AirDataTrialSpec;
    use crate::methods::air_data::trial::AirDataOutcome;

    /// Two detectors on three hand-made flights, a common-mode bias of 5 sigmas on airspeed and alpha at
    /// 30 s, or none. Trial 0: a isolates both after 0.5 s, b only airspeed after 1.0 s (and repaired a
    /// covariance); trial 1: a misses, b isolates both after 0.4 s; trial 2: fault-free, a false alarm by a.
    #[test]
    fn summary_of_hand_made_air_data_flights() {
        let mut study = AirDataStudy::bundled("ci_seed002.toml");
        study.detectors.truncate(1);
        study.detectors.push(study.detectors[0].clone());
        study.detectors[0].name = "a".into();
        study.detectors[1].name = "b".into();
        let fault = |channel| ChannelFault { channel, onset_s: 30.0, mode: FaultMode::Bias { bias: 5.0 } };
        let spec = |trial: u64, faulty: bool| AirDataTrialSpec {
            trial,
            fault: TrialFaults {
                faults: if faulty { vec![fault(0), fault(1)] } else { vec![] },
                actuators: Vec::new(),
                kind: if faulty { "bias" } else { NO_FAULT },
                size: if faulty { 5.0 } else { f64::NAN },
                size_bin: if faulty { 5.0 } else { f64::NAN },
                size_unit: if faulty {
                    crate::engine::results::schema::unit::SENSOR_SIGMA
                } else {
                    crate::engine::results::schema::unit::NONE
                },
                onset_s: 30.0,
            },
            outputs: if faulty { vec![0, 1] } else { vec![] },
            noise_scale: 1.0,
            noise_bin: 1.0,
            gust_std_mps: 0.0,
            gust_bin: 0.0,
            faulty_lanes: 1,
        };
        let out = |detection: Option<f64>, isolated: Option<Vec<usize>>, bias_err: Option<f64>, est: Option<f64>| {
            AirDataOutcome {
                false_alarm_s: None,
                detection_s: detection,
                isolated,
                bias_error_rms_sigma: bias_err,
                estimate_rms: [0.1; 3],
                raw_rms: [0.2; 3],
                estimate_rms_sigma: est,
                raw_rms_sigma: est.map(|_| 3.0),
                health: DualUkfHealth::default(),
                statistic: Default::default(),
            }
        };
        let mut repaired = out(Some(31.0), Some(vec![0]), Some(0.6), Some(1.5));
        repaired.health.fault.covariance_repairs = 2;
        let results = vec![
            AirDataTrialResult {
                spec: spec(0, true),
                outcome: Ok(vec![out(Some(30.5), Some(vec![0, 1]), Some(0.2), Some(0.5)), repaired]),
            },
            AirDataTrialResult {
                spec: spec(1, true),
                outcome: Ok(vec![
                    out(None, None, None, Some(2.8)),
                    out(Some(30.4), Some(vec![0, 1]), Some(0.4), Some(0.7)),
                ]),
            },
            AirDataTrialResult {
                spec: spec(2, false),
                outcome: Ok(vec![
                    AirDataOutcome { false_alarm_s: Some(12.0), ..out(None, None, None, None) },
                    out(None, None, None, None),
                ]),
            },
        ];
        let df = frame(&study, &results).unwrap();
        assert_eq!(df.height(), 6);
        let targets: Vec<Option<&str>> = df.column("target").unwrap().str().unwrap().iter().collect();
        assert_eq!(targets[0], Some("airspeed_mps+alpha_rad"), "a set of sensors is one target");
        let s = Summarized::of(df, &super::super::METHOD, 3, &["a", "b"]);
        let counts = |row| {
            ["trials", "false_alarms", "detected", "isolation_decided", "isolated_correctly", "repaired"]
                .map(|c| s.count(c, row).unwrap())
        };
        let (a, b) = (s.row("a", "bias"), s.row("b", "bias"));
        assert_eq!(counts(a), [2, 0, 1, 1, 1, 0]);
        assert_eq!(counts(b), [2, 0, 2, 2, 1, 1], "b named airspeed alone in trial 0: wrong set; it repaired once");
        assert_eq!(counts(s.row("a", "none"))[..2], [1, 1]);
        assert_eq!(counts(s.row("b", "none"))[..2], [1, 0]);
        assert_eq!((s.value("pd", a), s.value("isolation_accuracy", b)), (Some(0.5), Some(0.5)));
        s.assert_close("delay_p50_s", b, 0.7); // median of 1.0 and 0.4
        s.assert_close("bias_error_p50_sigma", a, 0.2); // a's one estimate
        s.assert_close("bias_error_p50_sigma", b, 0.5); // median of 0.6 and 0.4
        s.assert_close("estimate_rms_p50_sigma", a, 1.65); // of 0.5 and 2.8
        s.assert_close("raw_rms_p50_sigma", b, 3.0);
    }
}
