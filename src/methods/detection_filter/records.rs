//! The trial-record table (`trials.parquet`): one row per (trial, detector configuration).
//!
//! | column | meaning |
//! |---|---|
//! | `trial` | trial index (its random streams) |
//! | `detector` | detector configuration name |
//! | `kind`, `output` | fault kind (`none` when fault-free) and faulty output |
//! | `size`, `size_bin` | fault size in the output's units (a factor for gain); its group label in the deck's unit |
//! | `onset_s` | fault onset |
//! | `noise_scale`, `noise_bin` | multiplier of every sensor sigma, and its group label |
//! | `perr_<name>`, `param_error_bin` | parameter errors (relative or absolute, as the deck gives them), and the largest \|group label\| |
//! | `design_error` | why the design failed for this trial's model (null: designed) |
//! | `diverged_at_s` | time a residual became non-finite (null: never) |
//! | `false_alarm_s`, `false_alarm_output` | first pre-onset alarm at the deck's thresholds |
//! | `alarm_s`, `alarm_output`, `delay_s` | first post-onset alarm at the deck's thresholds |
//! | `isolated_by_max`, `isolated_by_direction` | isolation at the deck's thresholds |
//! | `pre_max_<out>` | largest |residual| before onset (whole trial when fault-free) |
//! | `fp_t_s_<out>`, `fp_v_<out>` | post-onset first-passage profile of |residual| (lists) |

use polars::prelude::*;

use crate::methods::detection_filter::study::LtiStudy;
use crate::methods::detection_filter::trials::TrialResult;

use crate::engine::schema::col;

/// Accumulates trial results column by column.
pub struct RecordBuilder<'a> {
    study: &'a LtiStudy,
    trial: Vec<u64>,
    detector: Vec<&'a str>,
    kind: Vec<&'static str>,
    output: Vec<Option<&'a str>>,
    size: Vec<Option<f64>>,
    size_bin: Vec<Option<f64>>,
    onset_s: Vec<Option<f64>>,
    noise_scale: Vec<f64>,
    noise_bin: Vec<f64>,
    perr: Vec<Vec<f64>>,
    param_error_bin: Vec<f64>,
    design_error: Vec<Option<String>>,
    diverged_at_s: Vec<Option<f64>>,
    false_alarm_s: Vec<Option<f64>>,
    false_alarm_output: Vec<Option<&'a str>>,
    alarm_s: Vec<Option<f64>>,
    alarm_output: Vec<Option<&'a str>>,
    delay_s: Vec<Option<f64>>,
    isolated_by_max: Vec<Option<&'a str>>,
    isolated_by_direction: Vec<Option<&'a str>>,
    pre_max: Vec<Vec<Option<f64>>>,
    fp_t: Vec<ListPrimitiveChunkedBuilder<Float64Type>>,
    fp_v: Vec<ListPrimitiveChunkedBuilder<Float64Type>>,
}

fn finite(v: f64) -> Option<f64> {
    v.is_finite().then_some(v)
}

impl<'a> RecordBuilder<'a> {
    pub fn new(study: &'a LtiStudy, capacity: usize) -> Self {
        let outputs = &study.plant.output_names;
        let list = |name: String| {
            ListPrimitiveChunkedBuilder::<Float64Type>::new(name.into(), capacity, capacity * 4, DataType::Float64)
        };
        RecordBuilder {
            study,
            trial: Vec::with_capacity(capacity),
            detector: Vec::with_capacity(capacity),
            kind: Vec::with_capacity(capacity),
            output: Vec::with_capacity(capacity),
            size: Vec::with_capacity(capacity),
            size_bin: Vec::with_capacity(capacity),
            onset_s: Vec::with_capacity(capacity),
            noise_scale: Vec::with_capacity(capacity),
            noise_bin: Vec::with_capacity(capacity),
            perr: vec![Vec::with_capacity(capacity); study.monte_carlo.parameter_errors.len()],
            param_error_bin: Vec::with_capacity(capacity),
            design_error: Vec::with_capacity(capacity),
            diverged_at_s: Vec::with_capacity(capacity),
            false_alarm_s: Vec::with_capacity(capacity),
            false_alarm_output: Vec::with_capacity(capacity),
            alarm_s: Vec::with_capacity(capacity),
            alarm_output: Vec::with_capacity(capacity),
            delay_s: Vec::with_capacity(capacity),
            isolated_by_max: Vec::with_capacity(capacity),
            isolated_by_direction: Vec::with_capacity(capacity),
            pre_max: vec![Vec::with_capacity(capacity); outputs.len()],
            fp_t: outputs.iter().map(|o| list(col::fp_t(o))).collect(),
            fp_v: outputs.iter().map(|o| list(col::fp_v(o))).collect(),
        }
    }

    /// Appends one row per detector configuration of `result`.
    pub fn push(&mut self, result: &TrialResult) {
        let s = self.study;
        let names = &s.plant.output_names;
        let name = |j: Option<usize>| j.map(|j| names[j].as_str());
        let spec = &result.spec;
        for (d, outcome) in s.detectors.iter().zip(&result.detectors) {
            self.trial.push(spec.trial);
            self.detector.push(&d.name);
            self.kind.push(spec.kind);
            self.output.push(name(spec.output));
            self.size.push(finite(spec.size));
            self.size_bin.push(finite(spec.size_bin));
            self.onset_s.push(finite(spec.onset_s));
            self.noise_scale.push(spec.noise_scale);
            self.noise_bin.push(spec.noise_bin);
            for (col, v) in self.perr.iter_mut().zip(&spec.parameter_errors) {
                col.push(*v);
            }
            self.param_error_bin.push(spec.parameter_error_bin);
            match outcome {
                Err(e) => {
                    self.design_error.push(Some(e.to_string()));
                    self.diverged_at_s.push(None);
                    self.false_alarm_s.push(None);
                    self.false_alarm_output.push(None);
                    self.alarm_s.push(None);
                    self.alarm_output.push(None);
                    self.delay_s.push(None);
                    self.isolated_by_max.push(None);
                    self.isolated_by_direction.push(None);
                    for j in 0..names.len() {
                        self.pre_max[j].push(None);
                        self.fp_t[j].append_slice(&[]);
                        self.fp_v[j].append_slice(&[]);
                    }
                }
                Ok(o) => {
                    self.design_error.push(None);
                    self.diverged_at_s.push(o.diverged_at_s);
                    self.false_alarm_s.push(o.false_alarm.map(|a| a.0));
                    self.false_alarm_output.push(name(o.false_alarm.map(|a| a.1)));
                    self.alarm_s.push(o.detection.map(|a| a.0));
                    self.alarm_output.push(name(o.detection.map(|a| a.1)));
                    self.delay_s.push(o.detection.map(|a| a.0 - spec.onset_s));
                    self.isolated_by_max.push(name(o.isolated_by_max));
                    self.isolated_by_direction.push(name(o.isolated_by_direction));
                    for j in 0..names.len() {
                        self.pre_max[j].push(Some(o.pre_onset_max_abs_residual[j]));
                        self.fp_t[j].append_slice(&o.profile_t_s[j]);
                        self.fp_v[j].append_slice(&o.profile_value[j]);
                    }
                }
            }
        }
    }

    /// The rows so far as a data frame (the builder is consumed).
    pub fn finish(self) -> PolarsResult<DataFrame> {
        let s = self.study;
        let mut columns = vec![
            Column::new(col::TRIAL.into(), self.trial),
            Column::new(col::DETECTOR.into(), self.detector),
            Column::new(col::KIND.into(), self.kind),
            Column::new(col::OUTPUT.into(), self.output),
            Column::new(col::SIZE.into(), self.size),
            Column::new(col::SIZE_BIN.into(), self.size_bin),
            Column::new(col::ONSET_S.into(), self.onset_s),
            Column::new(col::NOISE_SCALE.into(), self.noise_scale),
            Column::new(col::NOISE_BIN.into(), self.noise_bin),
        ];
        for (pe, v) in s.monte_carlo.parameter_errors.iter().zip(self.perr) {
            columns.push(Column::new(col::perr(&pe.name).into(), v));
        }
        columns.extend([
            Column::new(col::PARAM_ERROR_BIN.into(), self.param_error_bin),
            Column::new(col::DESIGN_ERROR.into(), self.design_error),
            Column::new(col::DIVERGED_AT_S.into(), self.diverged_at_s),
            Column::new(col::FALSE_ALARM_S.into(), self.false_alarm_s),
            Column::new(col::FALSE_ALARM_OUTPUT.into(), self.false_alarm_output),
            Column::new(col::ALARM_S.into(), self.alarm_s),
            Column::new(col::ALARM_OUTPUT.into(), self.alarm_output),
            Column::new(col::DELAY_S.into(), self.delay_s),
            Column::new(col::ISOLATED_BY_MAX.into(), self.isolated_by_max),
            Column::new(col::ISOLATED_BY_DIRECTION.into(), self.isolated_by_direction),
        ]);
        for (o, v) in s.plant.output_names.iter().zip(self.pre_max) {
            columns.push(Column::new(col::pre_max(o).into(), v));
        }
        for (mut t, mut v) in self.fp_t.into_iter().zip(self.fp_v) {
            columns.push(t.finish().into_series().into_column());
            columns.push(v.finish().into_series().into_column());
        }
        DataFrame::new_infer_height(columns)
    }
}
