//! The detection filters' `trials.parquet`: one row per (trial, detector configuration), the core
//! columns of [`crate::engine::results::schema`] first, where
//!
//! - `target` is the faulty output, `isolated` the output whose bias signature the mean residual after
//!   the alarm is most parallel to (the paper's "direction of the residual vector");
//! - `size` and `size_bin` are in the unit the deck gives (`size_sigma`: multiples of the sensor sigma);
//! - `failure` is the design error for the trial's model or the FMU's, `diverged` a residual that became
//!   non-finite, `truth_diverged` an FMU truth that diverged (then `failure` too);
//! - alarms and isolation are at the deck's thresholds;
//!
//! then the filters' own columns:
//!
//! | column | meaning |
//! |---|---|
//! | `diverged_at_s` | time a residual became non-finite or the FMU truth diverged (null: never) |
//! | `false_alarm_output` | the output of the first pre-onset alarm |
//! | `alarm_s`, `alarm_output` | first post-onset alarm and its output |
//! | `isolated_by_max` | the output whose threshold-scaled mean residual is largest |
//! | `pre_max_<out>`, `fp_t_s_<out>`, `fp_v_<out>` | per output, the recorded statistic \|residual\| |

use std::borrow::Cow;

use polars::prelude::*;

use super::filter::Isolation;
use super::study::LtiStudy;
use super::trials::TrialResult;
use crate::engine::results::schema::{CoreColumns, Outcome, StatisticColumns};

/// Accumulates trial results column by column.
pub struct RecordBuilder<'a> {
    study: &'a LtiStudy,
    core: CoreColumns<'a>,
    diverged_at_s: Vec<Option<f64>>,
    false_alarm_output: Vec<Option<&'a str>>,
    alarm_s: Vec<Option<f64>>,
    alarm_output: Vec<Option<&'a str>>,
    isolated_by_max: Vec<Option<&'a str>>,
    statistics: StatisticColumns,
}

impl<'a> RecordBuilder<'a> {
    pub fn new(study: &'a LtiStudy, capacity: usize) -> Self {
        let perr = study.monte_carlo.parameter_errors.iter().map(|p| p.name.clone());
        RecordBuilder {
            study,
            core: CoreColumns::new(perr, capacity, study.monte_carlo.common.detection_window_s),
            diverged_at_s: Vec::with_capacity(capacity),
            false_alarm_output: Vec::with_capacity(capacity),
            alarm_s: Vec::with_capacity(capacity),
            alarm_output: Vec::with_capacity(capacity),
            isolated_by_max: Vec::with_capacity(capacity),
            statistics: StatisticColumns::new(&study.plant.output_names, capacity),
        }
    }

    /// Appends one row per detector configuration of `result`.
    pub fn push(&mut self, result: &'a TrialResult) {
        let s = self.study;
        let names = &s.plant.output_names;
        let name = |j: Option<usize>| j.map(|j| names[j].as_str());
        let spec = &result.spec;
        for (d, outcome) in s.detectors.iter().zip(&result.detectors) {
            let o = outcome.as_ref().ok();
            // A filter's residual (the unit counts) or the truth itself (a failure).
            let (diverged_at_s, truth_diverged) = match outcome {
                Ok(o) => (o.diverged_at_s, false),
                Err(e) => (e.diverged_at_s(), e.diverged_at_s().is_some()),
            };
            let truth = spec.target_name(s);
            // A detector names outputs: an actuator fault's input is nothing it could name.
            let nameable = !spec.fault.faults.is_empty();
            let isolated = match d.params.isolation {
                Isolation::LargestNormalised | Isolation::Named => o.and_then(|o| name(o.isolated_by_max)),
                Isolation::Signature => o.and_then(|o| name(o.isolated_by_direction)),
            };
            self.core.push(Outcome {
                trial: spec.trial,
                detector: &d.name,
                kind: spec.fault.kind,
                target: truth.map(Cow::Borrowed),
                size: Some(spec.fault.size),
                size_unit: spec.fault.size_unit,
                size_bin: Some(spec.fault.size_bin),
                onset_s: Some(spec.fault.onset_s),
                fault_free: spec.fault.is_fault_free(),
                failure: outcome.as_ref().err().map(ToString::to_string),
                diverged: diverged_at_s.is_some() && !truth_diverged,
                truth_diverged,
                false_alarm_s: o.and_then(|o| o.false_alarm.map(|a| a.0)),
                delay_s: o.and_then(|o| o.detection.map(|a| a.0 - spec.fault.onset_s)),
                isolated: isolated.map(Cow::Borrowed),
                isolated_correctly: isolated.filter(|_| nameable).map(|i| Some(i) == truth),
                noise_scale: spec.noise_scale,
                noise_bin: spec.noise_bin,
                param_error_bin: spec.parameter_error_bin,
                param_errors: &spec.parameter_errors,
            });
            self.diverged_at_s.push(diverged_at_s);
            self.false_alarm_output.push(o.and_then(|o| name(o.false_alarm.map(|a| a.1))));
            self.alarm_s.push(o.and_then(|o| o.detection.map(|a| a.0)));
            self.alarm_output.push(o.and_then(|o| name(o.detection.map(|a| a.1))));
            self.isolated_by_max.push(o.and_then(|o| name(o.isolated_by_max)));
            for j in 0..names.len() {
                match o {
                    Some(o) => self.statistics.push(
                        j,
                        Some(o.pre_onset_max_abs_residual[j]),
                        &o.profile_t_s[j],
                        &o.profile_value[j],
                    ),
                    None => self.statistics.push(j, None, &[], &[]),
                }
            }
        }
    }

    /// The rows so far as a data frame (the builder is consumed).
    pub fn finish(self) -> PolarsResult<DataFrame> {
        let mut columns = self.core.finish();
        columns.extend([
            Column::new("diverged_at_s".into(), self.diverged_at_s),
            Column::new("false_alarm_output".into(), self.false_alarm_output),
            Column::new("alarm_s".into(), self.alarm_s),
            Column::new("alarm_output".into(), self.alarm_output),
            Column::new("isolated_by_max".into(), self.isolated_by_max),
        ]);
        columns.extend(self.statistics.finish());
        DataFrame::new_infer_height(columns)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::design::DesignError;
    use crate::engine::results::summary::hand_made::{Summarized, manifest};
    use crate::engine::run::runner::Manifest;
    use crate::engine::scenario::deck::FromDeck;
    use crate::fault::deck::TrialFaults;
    use crate::fault::{ChannelFault, FaultMode};
    use crate::methods::detection_filter::scenario::TrialSpec;
    use crate::methods::detection_filter::trial::DetectorOutcome;

    /// The CI deck's two detectors ("seed", "fast") on four hand-made trials, a q_rad_s bias of 3 sigmas
    /// at 5 s or none. Trial 0: seed alarms after 0.2 s and isolates q both ways; fast after 0.1 s, its
    /// signature names alpha, its largest residual q. Trial 1: seed misses; fast after 0.3 s, signature q,
    /// largest residual theta. Trial 2: fault-free, a false alarm of seed. Trial 3: seed's design failed
    /// for this trial; fast after 0.4 s, q both ways.
    #[test]
    fn summary_of_hand_made_lti_trials() {
        let study = LtiStudy::bundled("ci_seed000.toml");
        let names: Vec<&str> = study.detectors.iter().map(|d| d.name.as_str()).collect();
        assert_eq!(names, ["seed", "fast"]);
        let q = 2;
        let spec = |trial: u64, faulty: bool| TrialSpec {
            trial,
            noise_trial: trial,
            fault: TrialFaults {
                faults: if faulty {
                    vec![ChannelFault { channel: q, onset_s: 5.0, mode: FaultMode::Bias { bias: 0.015 } }]
                } else {
                    vec![]
                },
                actuators: Vec::new(),
                kind: if faulty { "bias" } else { "none" },
                size: if faulty { 3.0 } else { f64::NAN },
                size_bin: if faulty { 3.0 } else { f64::NAN },
                size_unit: crate::engine::results::schema::unit::SENSOR_SIGMA,
                onset_s: 5.0,
            },
            noise_scale: 1.0,
            noise_bin: 1.0,
            parameter_errors: vec![],
            parameter_error_bin: 0.0,
        };
        let out =
            |detection: Option<f64>, by_direction: Option<usize>, by_max: Option<usize>, false_alarm: Option<f64>| {
                Ok(DetectorOutcome {
                    pre_onset_max_abs_residual: vec![0.0; 6],
                    profile_t_s: vec![vec![]; 6],
                    profile_value: vec![vec![]; 6],
                    false_alarm: false_alarm.map(|t| (t, 0)),
                    detection: detection.map(|t| (t, q)),
                    isolated_by_max: by_max,
                    isolated_by_direction: by_direction,
                    diverged_at_s: None,
                })
            };
        let results = [
            TrialResult {
                spec: spec(0, true),
                detectors: vec![out(Some(5.2), Some(q), Some(q), None), out(Some(5.1), Some(1), Some(q), None)],
            },
            TrialResult {
                spec: spec(1, true),
                detectors: vec![out(None, None, None, None), out(Some(5.3), Some(q), Some(3), None)],
            },
            TrialResult {
                spec: spec(2, false),
                detectors: vec![out(None, None, None, Some(2.0)), out(None, None, None, None)],
            },
            TrialResult {
                spec: spec(3, true),
                detectors: vec![
                    Err(DesignError::RepeatedEigenvalues { first: -1.0, second: -1.0 }.into()),
                    out(Some(5.4), Some(q), Some(q), None),
                ],
            },
        ];
        let mut builder = RecordBuilder::new(&study, 8);
        for r in &results {
            builder.push(r);
        }
        let df = builder.finish().unwrap();
        assert_eq!(df.height(), 8);
        let manifest = Manifest {
            outputs: study.plant.output_names.clone(),
            deck_thresholds: study.detectors.iter().map(|d| d.params.thresholds.iter().copied().collect()).collect(),
            ..manifest(&super::super::METHOD, 4, &names)
        };
        let s = Summarized::new(df, manifest, &super::super::METHOD.summary);
        let (seed, fast) = (s.row("seed", "bias"), s.row("fast", "bias"));
        let counts = |i| {
            ["trials", "failed", "detected", "isolation_decided", "isolated_correctly", "isolated_by_max_correctly"]
                .map(|n| s.count(n, i).unwrap())
        };
        assert_eq!(counts(seed), [3, 1, 1, 1, 1, 1], "trial 3's failed design is a failed unit");
        assert_eq!(counts(fast), [3, 0, 3, 3, 2, 2]);
        assert_eq!(s.value("pd", seed), Some(0.5));
        assert_eq!(s.value("isolation_by_max_accuracy", fast), Some(2.0 / 3.0));
        s.assert_close("delay_p50_s", fast, 0.3);
        let none = s.row("seed", "none");
        assert_eq!((s.count("false_alarms", none), s.value("pfa", none)), (Some(1), Some(1.0)));
        assert_eq!(s.count("false_alarms", s.row("fast", "none")), Some(0));
    }
}
