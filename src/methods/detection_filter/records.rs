//! The detection filters' `trials.parquet`: one row per (trial, detector configuration), the core
//! columns of [`crate::engine::schema`] first, where
//!
//! - `target` is the faulty output, `isolated` the output whose bias signature the mean residual after
//!   the alarm is most parallel to (the paper's "direction of the residual vector");
//! - `size` and `size_bin` are in the unit the deck gives (`size_sigma`: multiples of the sensor sigma);
//! - `failure` is the design error for the trial's model, `diverged` a residual that became non-finite;
//! - alarms and isolation are at the deck's thresholds;
//!
//! then the filters' own columns:
//!
//! | column | meaning |
//! |---|---|
//! | `diverged_at_s` | time a residual became non-finite (null: never) |
//! | `false_alarm_output` | the output of the first pre-onset alarm |
//! | `alarm_s`, `alarm_output` | first post-onset alarm and its output |
//! | `isolated_by_max` | the output whose threshold-scaled mean residual is largest |
//! | `pre_max_<out>`, `fp_t_s_<out>`, `fp_v_<out>` | per output, the recorded statistic \|residual\| |

use std::borrow::Cow;

use polars::prelude::*;

use super::filter::Isolation;
use super::study::LtiStudy;
use super::trials::TrialResult;
use crate::engine::schema::{CoreColumns, Outcome, StatisticColumns};

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
            core: CoreColumns::new(perr, capacity),
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
            let truth = name(spec.output);
            let isolated = match d.params.isolation {
                Isolation::LargestNormalised => o.and_then(|o| name(o.isolated_by_max)),
                Isolation::Signature => o.and_then(|o| name(o.isolated_by_direction)),
            };
            self.core.push(Outcome {
                trial: spec.trial,
                detector: &d.name,
                kind: spec.kind,
                target: truth.map(Cow::Borrowed),
                size: Some(spec.size),
                size_unit: spec.size_unit,
                size_bin: Some(spec.size_bin),
                onset_s: Some(spec.onset_s),
                fault_free: spec.faults.is_empty(),
                failure: outcome.as_ref().err().map(ToString::to_string),
                diverged: o.is_some_and(|o| o.diverged_at_s.is_some()),
                false_alarm_s: o.and_then(|o| o.false_alarm.map(|a| a.0)),
                delay_s: o.and_then(|o| o.detection.map(|a| a.0 - spec.onset_s)),
                isolated: isolated.map(Cow::Borrowed),
                isolated_correctly: isolated.map(|i| Some(i) == truth),
                noise_scale: spec.noise_scale,
                noise_bin: spec.noise_bin,
                param_error_bin: spec.parameter_error_bin,
                param_errors: &spec.parameter_errors,
            });
            self.diverged_at_s.push(o.and_then(|o| o.diverged_at_s));
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
