//! The outcome schema: every kind's `trials.parquet` starts with the same core columns, the same name
//! and type for the same meaning, then the method's own columns. The summaries, `check`, `merge` and
//! the paired comparison read the core columns only (and the statistics, where a kind records one).
//!
//! One row per trial x detector x unit: a unit is what a detector is scored on within a trial, the
//! trial itself for most kinds, or one fault window of a trial with several (method 004). The rows of
//! one trial are consecutive, detectors in deck order, each detector's units in order.
//!
//! | column | type | meaning |
//! |---|---|---|
//! | `trial` | u64 | trial index (its random streams) |
//! | `detector` | str | detector configuration |
//! | `kind` | str | fault kind (`none` when fault-free; a classifier's classes for method 003, `normal` among them) |
//! | `target` | str | the faulty component: output, sensor set (`+`-joined), engine, axis, surface; null when fault-free |
//! | `size`, `size_bin` | f64 | fault size and its group label, both in `size_unit` (null for kinds without a size) |
//! | `size_unit` | str | the unit the deck gives the size in (`multiples of the sensor sigma`, `deg`, `gain factor`, ...) |
//! | `onset_s` | f64 | fault onset (null when fault-free) |
//! | `fault_free` | bool | the trial has no fault (its alarms are false alarms) |
//! | `failure` | str | why the unit was not flown to the end (design failure, left the envelope, ...); null: flown. Failed units are left out of every rate |
//! | `diverged` | bool | a filter of the detector became non-finite (the unit still counts) |
//! | `truth_diverged` | bool | the trial's truth is no trajectory: an FMU truth's outputs became non-finite, left their declared range, passed 10^6 x their scale or strayed from the deck's linear plant by more than its stated multiple (the unit is `failed` too, in no rate and no calibration) |
//! | `false_alarm`, `false_alarm_s` | bool, f64 | an alarm before the onset (anywhere when fault-free), and the first one's time |
//! | `detected`, `delay_s` | bool, f64 | the fault detected at or after its onset, within `monte_carlo.detection_window_s` of it, and the delay from the onset |
//! | `late_alarm_s` | f64 | the first alarm after the onset when it came later than the detection window: then a miss (`detected` false, nothing isolated), its delay here; null otherwise |
//! | `isolated`, `isolated_correctly` | str, bool | what the detector named (a target, or a class for classifiers; null: nothing named), and whether it is the truth |
//! | `noise_scale`, `noise_bin` | f64 | factor on every sensor's noise, and its group label |
//! | `param_error_bin` | f64 | largest \|group label\| of the trial's parameter errors (0 without any) |
//! | `perr_<name>` | f64 | each parameter error of the deck, as the deck gives it (relative or absolute) |
//!
//! Every kind records a detection statistic per unit, and adds, per statistic `s`,
//! `pre_max_<s>` (its largest value before the onset, the whole trial when fault-free) and the lists
//! `fp_t_s_<s>`, `fp_v_<s>` (the first-passage profile after the onset: times and values at which its
//! running maximum rises), so any threshold can be evaluated later without re-simulating.

use std::borrow::Cow;

use polars::prelude::*;

use crate::estimation::stekf::FilterHealth;

/// The tables `fdimc rare-event` writes into a run's `rare_event/` folder, which the run's safety summary
/// reads back.
pub mod rare_event_files {
    /// The false-alarm estimates and their record.
    pub const TABLE: &str = "rare_event.csv";
    pub const RECORD: &str = "rare_event.json";
    /// `--flight-s`: flights against the segment conversion.
    pub const PER_HOUR: &str = "per_hour.csv";
    /// `--miss-before-hazard`: the table and its record.
    pub const MISS: &str = "miss_before_hazard.csv";
    pub const MISS_RECORD: &str = "miss_before_hazard.json";
}

/// Column names of the core schema and of recorded statistics.
pub mod col {
    pub const TRIAL: &str = "trial";
    pub const DETECTOR: &str = "detector";
    pub const KIND: &str = "kind";
    pub const TARGET: &str = "target";
    pub const SIZE: &str = "size";
    pub const SIZE_UNIT: &str = "size_unit";
    pub const SIZE_BIN: &str = "size_bin";
    pub const ONSET_S: &str = "onset_s";
    pub const FAULT_FREE: &str = "fault_free";
    pub const FAILURE: &str = "failure";
    pub const DIVERGED: &str = "diverged";
    pub const TRUTH_DIVERGED: &str = "truth_diverged";
    pub const FALSE_ALARM: &str = "false_alarm";
    pub const FALSE_ALARM_S: &str = "false_alarm_s";
    pub const DETECTED: &str = "detected";
    pub const DELAY_S: &str = "delay_s";
    pub const LATE_ALARM_S: &str = "late_alarm_s";
    pub const ISOLATED: &str = "isolated";
    pub const ISOLATED_CORRECTLY: &str = "isolated_correctly";
    pub const NOISE_SCALE: &str = "noise_scale";
    pub const NOISE_BIN: &str = "noise_bin";
    pub const PARAM_ERROR_BIN: &str = "param_error_bin";
    /// Fault kind of fault-free trials.
    pub const NO_FAULT: &str = "none";
    /// Prefix of the parameter-error columns.
    pub const PERR_PREFIX: &str = "perr_";
    /// Prefix of a recorded statistic's pre-onset maximum.
    pub const PRE_MAX_PREFIX: &str = "pre_max_";
    /// A Kalman-type filter's health counters ([`super::FilterHealthColumns`]), filter-steps.
    pub const SINGULAR_INNOVATION_STEPS: &str = "singular_innovation_steps";
    pub const ASYMMETRIC_STEPS: &str = "asymmetric_steps";
    pub const NOT_POSITIVE_DEFINITE_STEPS: &str = "not_positive_definite_steps";
    pub const NON_FINITE_STEPS: &str = "non_finite_steps";

    pub fn perr(name: &str) -> String {
        format!("{PERR_PREFIX}{name}")
    }
    pub fn pre_max(statistic: &str) -> String {
        format!("{PRE_MAX_PREFIX}{statistic}")
    }
    pub fn fp_t(statistic: &str) -> String {
        format!("fp_t_s_{statistic}")
    }
    pub fn fp_v(statistic: &str) -> String {
        format!("fp_v_{statistic}")
    }
}

/// One row's core values; `false_alarm` and `detected` follow from their times.
#[derive(Debug, Clone, PartialEq)]
pub struct Outcome<'a> {
    pub trial: u64,
    pub detector: &'a str,
    pub kind: &'a str,
    pub target: Option<Cow<'a, str>>,
    pub size: Option<f64>,
    pub size_unit: &'a str,
    pub size_bin: Option<f64>,
    pub onset_s: Option<f64>,
    pub fault_free: bool,
    pub failure: Option<String>,
    pub diverged: bool,
    /// The trial's truth diverged or left its physical range (then `failure` says how).
    pub truth_diverged: bool,
    pub false_alarm_s: Option<f64>,
    pub delay_s: Option<f64>,
    pub isolated: Option<Cow<'a, str>>,
    pub isolated_correctly: Option<bool>,
    pub noise_scale: f64,
    pub noise_bin: f64,
    pub param_error_bin: f64,
    /// One per `perr_<name>` column, in the builder's order.
    pub param_errors: &'a [f64],
}

/// The core columns while rows are added; a method's frame builder puts its own columns after them.
pub struct CoreColumns<'a> {
    detection_window_s: f64,
    perr_names: Vec<String>,
    trial: Vec<u64>,
    detector: Vec<&'a str>,
    kind: Vec<&'a str>,
    target: Vec<Option<Cow<'a, str>>>,
    size: Vec<Option<f64>>,
    size_unit: Vec<&'a str>,
    size_bin: Vec<Option<f64>>,
    onset_s: Vec<Option<f64>>,
    fault_free: Vec<bool>,
    failure: Vec<Option<String>>,
    diverged: Vec<bool>,
    truth_diverged: Vec<bool>,
    false_alarm: Vec<bool>,
    false_alarm_s: Vec<Option<f64>>,
    detected: Vec<bool>,
    delay_s: Vec<Option<f64>>,
    late_alarm_s: Vec<Option<f64>>,
    isolated: Vec<Option<Cow<'a, str>>>,
    isolated_correctly: Vec<Option<bool>>,
    noise_scale: Vec<f64>,
    noise_bin: Vec<f64>,
    param_error_bin: Vec<f64>,
    perr: Vec<Vec<f64>>,
}

impl<'a> CoreColumns<'a> {
    /// A builder for about `rows` rows whose parameter errors are named `perr_names` (deck order), an
    /// alarm later than `detection_window_s` after the onset (`monte_carlo.detection_window_s`) being a
    /// late alarm, not a detection.
    pub fn new(perr_names: impl IntoIterator<Item = String>, rows: usize, detection_window_s: f64) -> Self {
        let perr_names: Vec<String> = perr_names.into_iter().collect();
        CoreColumns {
            detection_window_s,
            late_alarm_s: Vec::with_capacity(rows),
            perr: perr_names.iter().map(|_| Vec::with_capacity(rows)).collect(),
            perr_names,
            trial: Vec::with_capacity(rows),
            detector: Vec::with_capacity(rows),
            kind: Vec::with_capacity(rows),
            target: Vec::with_capacity(rows),
            size: Vec::with_capacity(rows),
            size_unit: Vec::with_capacity(rows),
            size_bin: Vec::with_capacity(rows),
            onset_s: Vec::with_capacity(rows),
            fault_free: Vec::with_capacity(rows),
            failure: Vec::with_capacity(rows),
            diverged: Vec::with_capacity(rows),
            truth_diverged: Vec::with_capacity(rows),
            false_alarm: Vec::with_capacity(rows),
            false_alarm_s: Vec::with_capacity(rows),
            detected: Vec::with_capacity(rows),
            delay_s: Vec::with_capacity(rows),
            isolated: Vec::with_capacity(rows),
            isolated_correctly: Vec::with_capacity(rows),
            noise_scale: Vec::with_capacity(rows),
            noise_bin: Vec::with_capacity(rows),
            param_error_bin: Vec::with_capacity(rows),
        }
    }

    /// Adds one row. Panics if `o.param_errors` does not have one value per parameter-error column
    /// (a programmer's error).
    #[track_caller]
    pub fn push(&mut self, o: Outcome<'a>) {
        assert_eq!(o.param_errors.len(), self.perr.len(), "one value per parameter-error column");
        self.trial.push(o.trial);
        self.detector.push(o.detector);
        self.kind.push(o.kind);
        self.target.push(o.target);
        self.size.push(o.size.filter(|v| v.is_finite()));
        self.size_unit.push(o.size_unit);
        self.size_bin.push(o.size_bin.filter(|v| v.is_finite()));
        self.onset_s.push(o.onset_s.filter(|v| v.is_finite()));
        self.fault_free.push(o.fault_free);
        self.failure.push(o.failure);
        self.diverged.push(o.diverged);
        self.truth_diverged.push(o.truth_diverged);
        self.false_alarm.push(o.false_alarm_s.is_some());
        self.false_alarm_s.push(o.false_alarm_s);
        let late = o.delay_s.filter(|&d| is_late(d, self.detection_window_s));
        let delay_s = o.delay_s.filter(|_| late.is_none());
        self.detected.push(delay_s.is_some());
        self.delay_s.push(delay_s);
        self.late_alarm_s.push(late);
        self.isolated.push(if late.is_some() { None } else { o.isolated });
        self.isolated_correctly.push(if late.is_some() { None } else { o.isolated_correctly });
        self.noise_scale.push(o.noise_scale);
        self.noise_bin.push(o.noise_bin);
        self.param_error_bin.push(o.param_error_bin);
        for (column, v) in self.perr.iter_mut().zip(o.param_errors) {
            column.push(*v);
        }
    }

    /// Rows added so far.
    pub fn len(&self) -> usize {
        self.trial.len()
    }

    pub fn is_empty(&self) -> bool {
        self.trial.is_empty()
    }

    /// The core columns in schema order.
    pub fn finish(self) -> Vec<Column> {
        let text = |name: &str, v: &[Option<Cow<'a, str>>]| {
            Column::new(name.into(), v.iter().map(|s| s.as_deref()).collect::<Vec<Option<&str>>>())
        };
        let mut columns = vec![
            Column::new(col::TRIAL.into(), self.trial),
            Column::new(col::DETECTOR.into(), self.detector),
            Column::new(col::KIND.into(), self.kind),
            text(col::TARGET, &self.target),
            Column::new(col::SIZE.into(), self.size),
            Column::new(col::SIZE_UNIT.into(), self.size_unit),
            Column::new(col::SIZE_BIN.into(), self.size_bin),
            Column::new(col::ONSET_S.into(), self.onset_s),
            Column::new(col::FAULT_FREE.into(), self.fault_free),
            Column::new(col::FAILURE.into(), self.failure),
            Column::new(col::DIVERGED.into(), self.diverged),
            Column::new(col::TRUTH_DIVERGED.into(), self.truth_diverged),
            Column::new(col::FALSE_ALARM.into(), self.false_alarm),
            Column::new(col::FALSE_ALARM_S.into(), self.false_alarm_s),
            Column::new(col::DETECTED.into(), self.detected),
            Column::new(col::DELAY_S.into(), self.delay_s),
            Column::new(col::LATE_ALARM_S.into(), self.late_alarm_s),
            text(col::ISOLATED, &self.isolated),
            Column::new(col::ISOLATED_CORRECTLY.into(), self.isolated_correctly),
            Column::new(col::NOISE_SCALE.into(), self.noise_scale),
            Column::new(col::NOISE_BIN.into(), self.noise_bin),
            Column::new(col::PARAM_ERROR_BIN.into(), self.param_error_bin),
        ];
        for (name, v) in self.perr_names.iter().zip(self.perr) {
            columns.push(Column::new(col::perr(name).into(), v));
        }
        columns
    }
}

/// An alarm `delay_s` after the onset is late (a miss, `late_alarm_s`) with a detection window of
/// `detection_window_s`: the one rule of the records ([`CoreColumns::push`]) and of the replay
/// ([`crate::engine::results::thresholds::RecordedStatistics::first_alarm`]).
pub fn is_late(delay_s: f64, detection_window_s: f64) -> bool {
    delay_s > detection_window_s
}

pub use crate::engine::scenario::profile_grid::{DEFAULT_PROFILE_RESOLUTION, NO_LEVEL, ProfileGrid};

/// A statistic's first-passage profile after the onset while a unit is flown: a point `(t, value)`
/// each time its running maximum rises past a level of the [`ProfileGrid`], and the final maximum to
/// close it ([`FirstPassage::close`]), so "alarm or not" is exact at every threshold and the alarm time
/// is that of the first sample at which the statistic was past the grid level above the threshold (at
/// most one step above it). The points go to the caller's vectors (a unit's outcome holds them).
#[derive(Debug, Clone, Copy)]
pub struct FirstPassage {
    grid: ProfileGrid,
    running_max: f64,
    running_max_t: f64,
    next_kept: f64,
    next_level: i32,
    exact: ExactDelays,
}

impl FirstPassage {
    pub fn new(grid: ProfileGrid) -> Self {
        FirstPassage {
            grid,
            running_max: 0.0,
            running_max_t: f64::NAN,
            next_kept: f64::NEG_INFINITY,
            next_level: NO_LEVEL,
            exact: ExactDelays::NONE,
        }
    }

    /// A profile that also keeps the running maximum exactly at `exact`'s delays after the onset.
    pub fn with_exact_delays(grid: ProfileGrid, exact: ExactDelays) -> Self {
        FirstPassage { exact, ..FirstPassage::new(grid) }
    }

    /// The statistic's value `a` at `t` (s), after the onset.
    pub fn observe(&mut self, t: f64, a: f64, profile_t_s: &mut Vec<f64>, profile_value: &mut Vec<f64>) {
        if self.exact.passed(t) {
            keep_exact(self.running_max_t, self.running_max, profile_t_s, profile_value);
        }
        if a > self.running_max || self.running_max_t.is_nan() {
            self.running_max = a;
            self.running_max_t = t;
            if let Some(v) = self.grid.keep(&mut self.next_kept, &mut self.next_level, a) {
                profile_t_s.push(t);
                profile_value.push(v);
            }
        }
    }

    /// Closes the profile with the final maximum, where the last point kept is not it.
    pub fn close(&self, profile_t_s: &mut Vec<f64>, profile_value: &mut Vec<f64>) {
        close_profile(self.running_max_t, self.running_max, profile_t_s, profile_value);
    }
}

/// The delays after a unit's onset (s) at which its profiles keep the running maximum exactly, so that
/// "alarmed within this delay" replays exactly at every threshold whatever the grid: the detection
/// window (a detection, [`is_late`]) and the fault's time to hazard (a miss before the hazard). A
/// delay passes at the first sample with `t - onset > delay`, the replay's own rule; the profile then
/// keeps the maximum so far ([`keep_exact`]), reached at or before the delay.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExactDelays {
    onset_s: f64,
    /// Ascending; +inf where none.
    delays_s: [f64; 2],
    next: usize,
}

impl ExactDelays {
    /// No exact points (the grid's only).
    pub const NONE: ExactDelays = ExactDelays { onset_s: 0.0, delays_s: [f64::INFINITY; 2], next: 2 };

    /// The delays `delays_s` after `onset_s` (non-finite or negative ones: none).
    pub fn new(onset_s: f64, delays_s: [f64; 2]) -> Self {
        let mut d = delays_s.map(|d| if d.is_finite() && d >= 0.0 && onset_s.is_finite() { d } else { f64::INFINITY });
        d.sort_by(f64::total_cmp);
        ExactDelays { onset_s, delays_s: d, next: d.iter().position(|d| d.is_finite()).map_or(2, |_| 0) }
    }

    /// Whether the sample at `t_s` is the first past a delay (then past every delay it passed).
    #[inline]
    pub fn passed(&mut self, t_s: f64) -> bool {
        if self.next < 2 && t_s - self.onset_s > self.delays_s[self.next] {
            while self.next < 2 && t_s - self.onset_s > self.delays_s[self.next] {
                self.next += 1;
            }
            true
        } else {
            false
        }
    }

    /// The absolute time (s) a sample must pass for [`ExactDelays::passed`] to be worth asking: a
    /// little before the next delay (the subtraction there may round either way), +inf after the last.
    pub fn next_check_s(&self) -> f64 {
        match self.delays_s.get(self.next) {
            Some(d) if d.is_finite() => {
                let at = self.onset_s + d;
                at - 1e-9 * (1.0 + at.abs())
            }
            _ => f64::INFINITY,
        }
    }
}

/// Adds the running maximum `max`, reached at `max_t` (NaN: no value after the onset yet), to a profile
/// as an exact point where its last point is below it: at the same time as the last point, that
/// point's value becomes exact. The grid's later points stay above it (it is below the next bar).
#[cold]
pub fn keep_exact(max_t: f64, max: f64, profile_t_s: &mut Vec<f64>, profile_value: &mut Vec<f64>) {
    if max_t.is_nan() || profile_value.last().is_some_and(|&v| v >= max) {
        return;
    }
    match (profile_t_s.last(), profile_value.last_mut()) {
        (Some(&t), Some(v)) if t == max_t => *v = max,
        _ => {
            profile_t_s.push(max_t);
            profile_value.push(max);
        }
    }
}

/// Ends a profile with its final maximum `max` reached at `max_t` (NaN: no value after the onset),
/// unless its last point is that maximum already.
pub fn close_profile(max_t: f64, max: f64, profile_t_s: &mut Vec<f64>, profile_value: &mut Vec<f64>) {
    if !max_t.is_nan() && profile_value.last() != Some(&max) {
        profile_t_s.push(max_t);
        profile_value.push(max);
    }
}

/// One statistic of one unit as recorded: its largest value before the onset (0 when none) and its
/// first-passage profile after it ([`FirstPassage`]); a row's `pre_max_<s>`, `fp_t_s_<s>`, `fp_v_<s>`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct RecordedStatistic {
    pub pre_max: f64,
    pub profile_t_s: Vec<f64>,
    pub profile_value: Vec<f64>,
}

/// A [`RecordedStatistic`] while its unit is flown: values before the onset, then after it.
#[derive(Debug, Clone)]
pub struct StatisticRecorder {
    recorded: RecordedStatistic,
    first_passage: FirstPassage,
}

impl StatisticRecorder {
    /// A recorder whose profile keeps the points of `grid`.
    pub fn new(grid: ProfileGrid) -> Self {
        StatisticRecorder { recorded: RecordedStatistic::default(), first_passage: FirstPassage::new(grid) }
    }

    /// A value before the onset (NaN: none).
    pub fn before_onset(&mut self, value: f64) {
        if value > self.recorded.pre_max {
            self.recorded.pre_max = value;
        }
    }

    /// The value at `t_s`, at or after the onset (NaN: none).
    pub fn after_onset(&mut self, t_s: f64, value: f64) {
        if !value.is_nan() {
            let r = &mut self.recorded;
            self.first_passage.observe(t_s, value, &mut r.profile_t_s, &mut r.profile_value);
        }
    }

    /// The statistic as recorded, its profile closed.
    pub fn finish(mut self) -> RecordedStatistic {
        let r = &mut self.recorded;
        self.first_passage.close(&mut r.profile_t_s, &mut r.profile_value);
        self.recorded
    }
}

/// Recorded statistics (pre-onset maxima and first-passage profiles), one per name, while rows are
/// added; a kind that records them puts these columns after its core columns.
pub struct StatisticColumns {
    names: Vec<String>,
    pre_max: Vec<Vec<Option<f64>>>,
    fp_t: Vec<ListPrimitiveChunkedBuilder<Float64Type>>,
    fp_v: Vec<ListPrimitiveChunkedBuilder<Float64Type>>,
}

impl StatisticColumns {
    pub fn new(names: &[String], rows: usize) -> Self {
        let list = |name: String| {
            ListPrimitiveChunkedBuilder::<Float64Type>::new(name.into(), rows, rows * 4, DataType::Float64)
        };
        StatisticColumns {
            names: names.to_vec(),
            pre_max: names.iter().map(|_| Vec::with_capacity(rows)).collect(),
            fp_t: names.iter().map(|n| list(col::fp_t(n))).collect(),
            fp_v: names.iter().map(|n| list(col::fp_v(n))).collect(),
        }
    }

    /// Statistic `j` of the next row as recorded (none: the unit was not flown).
    pub fn push_recorded(&mut self, j: usize, recorded: Option<&RecordedStatistic>) {
        match recorded {
            Some(r) => self.push(j, Some(r.pre_max), &r.profile_t_s, &r.profile_value),
            None => self.push(j, None, &[], &[]),
        }
    }

    /// Statistic `j` of the next row: its pre-onset maximum and first-passage profile (times, values).
    pub fn push(&mut self, j: usize, pre_max: Option<f64>, profile_t_s: &[f64], profile_value: &[f64]) {
        self.pre_max[j].push(pre_max);
        self.fp_t[j].append_slice(profile_t_s);
        self.fp_v[j].append_slice(profile_value);
    }

    /// `pre_max_<s>` for every statistic, then `fp_t_s_<s>`, `fp_v_<s>` for each.
    pub fn finish(self) -> Vec<Column> {
        let mut columns: Vec<Column> =
            self.names.iter().zip(self.pre_max).map(|(n, v)| Column::new(col::pre_max(n).into(), v)).collect();
        for (mut t, mut v) in self.fp_t.into_iter().zip(self.fp_v) {
            columns.push(t.finish().into_series().into_column());
            columns.push(v.finish().into_series().into_column());
        }
        columns
    }
}

/// A Kalman-type filter's health counters ([`FilterHealth`]) while rows are added, for kinds whose
/// detectors are such filters (null where the unit was not flown): `singular_innovation_steps`,
/// `asymmetric_steps`, `not_positive_definite_steps`, `non_finite_steps`, in this order.
#[derive(Default)]
pub struct FilterHealthColumns {
    singular: Vec<Option<u32>>,
    asymmetric: Vec<Option<u32>>,
    not_positive_definite: Vec<Option<u32>>,
    non_finite: Vec<Option<u32>>,
}

impl FilterHealthColumns {
    pub fn push(&mut self, health: Option<FilterHealth>) {
        self.singular.push(health.map(|h| h.singular_innovation));
        self.asymmetric.push(health.map(|h| h.asymmetric));
        self.not_positive_definite.push(health.map(|h| h.not_positive_definite));
        self.non_finite.push(health.map(|h| h.non_finite));
    }

    pub fn finish(self) -> [Column; 4] {
        [
            Column::new(col::SINGULAR_INNOVATION_STEPS.into(), self.singular),
            Column::new(col::ASYMMETRIC_STEPS.into(), self.asymmetric),
            Column::new(col::NOT_POSITIVE_DEFINITE_STEPS.into(), self.not_positive_definite),
            Column::new(col::NON_FINITE_STEPS.into(), self.non_finite),
        ]
    }
}

/// Units of fault sizes (the `size_unit` column), as records and summaries name them.
pub mod unit {
    pub const SENSOR_SIGMA: &str = "multiples of the sensor sigma";
    /// A drift's size: its rate.
    pub const SENSOR_SIGMA_PER_S: &str = "multiples of the sensor sigma per second";
    pub const GAIN_FACTOR: &str = "gain factor";
    pub const OUTPUT_UNITS: &str = "output units";
    pub const OUTPUT_UNITS_PER_S: &str = "output units per second";
    /// An actuator fault's size: the input's units (a deviation from the trim for a mapped FMU input).
    pub const INPUT_UNITS: &str = "input units";
    /// A gain whose size bins are deviations `|factor - 1|` of either sign, not factors.
    pub const GAIN_DEVIATION_BINS: &str = "factor (bin: |factor - 1|)";
    /// A fault without a size (stuck at the held reading, total failure), or no fault.
    pub const NONE: &str = "none";
}

#[cfg(test)]
mod tests {
    use super::*;

    fn profile(step: f64, series: &[(f64, f64)]) -> (Vec<f64>, Vec<f64>) {
        let mut recorder = StatisticRecorder::new(ProfileGrid::new(step));
        series.iter().for_each(|&(t, a)| recorder.after_onset(t, a));
        let r = recorder.finish();
        (r.profile_t_s, r.profile_value)
    }

    const SERIES: [(f64, f64); 10] = [
        (0.0, 0.3),
        (1.0, 0.2),
        (2.0, 0.45),
        (3.0, 0.6),
        (4.0, 1.7),
        (5.0, 1.9),
        (6.0, 2.0),
        (7.0, 9.0),
        (8.0, 3.0),
        (9.0, 9.5),
    ];

    /// Step 1 (levels at the powers of 2, exact in binary): the first value exact, then the level at or
    /// below each maximum that passes the next level (0.6 -> 0.5, 1.7 -> 1, 9 -> 8; 2.0 does not pass 2),
    /// then the final maximum.
    #[test]
    fn a_profile_keeps_the_grid_levels_the_maximum_passes() {
        assert_eq!(profile(1.0, &SERIES), (vec![0.0, 3.0, 4.0, 7.0, 9.0], vec![0.3, 0.5, 1.0, 8.0, 9.5]));
        // Step 0: every rise of the running maximum, at its value.
        assert_eq!(
            profile(0.0, &SERIES),
            (vec![0.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 9.0], vec![0.3, 0.45, 0.6, 1.7, 1.9, 2.0, 9.0, 9.5])
        );
        // A first value of 0: the next point is the first positive maximum's level, then the maximum.
        assert_eq!(profile(1.0, &[(0.0, 0.0), (1.0, 0.0), (2.0, 0.3)]), (vec![0.0, 2.0, 2.0], vec![0.0, 0.25, 0.3]));
        assert_eq!(profile(1.0, &[]), (vec![], vec![]));
    }

    /// Step 0.05 on a wandering, rising statistic: the levels are powers of 1.05; at every threshold the
    /// replayed alarm (the first point above it) is exactly whether the statistic passed it, never
    /// earlier than the statistic's first sample above it, and later only while the running maximum
    /// was still below the grid level above the threshold (at most 5 % above it).
    #[test]
    fn a_replayed_alarm_is_within_one_grid_step_of_the_threshold() {
        let series: Vec<(f64, f64)> =
            (0..2000).map(|k| (k as f64 * 0.01, 0.5 + 0.4 * (k as f64 * 0.37).sin() + 0.002 * k as f64)).collect();
        let (t, v) = profile(0.05, &series);
        assert!(v.windows(2).all(|w| w[1] > w[0]) && t.windows(2).all(|w| w[1] >= w[0]));
        let max = series.iter().map(|p| p.1).fold(f64::MIN, f64::max);
        assert_eq!(*v.last().unwrap(), max);
        for (i, &level) in v.iter().enumerate().skip(1).take(v.len() - 2) {
            let l = level.ln() / 1.05f64.ln();
            assert!((l - l.round()).abs() < 1e-9, "point {i}: {level} is a power of 1.05");
        }
        for thr in [0.2, 0.5, 0.9, 1.0, 1.3, 2.0, 4.0, 4.5, max - 1e-9, max] {
            let exact = series.iter().find(|p| p.1 > thr).map(|p| p.0);
            let replayed = t.iter().zip(&v).find(|(_, v)| **v > thr).map(|(t, _)| *t);
            assert_eq!(exact.is_some(), replayed.is_some(), "threshold {thr}");
            if let (Some(e), Some(r)) = (exact, replayed) {
                let before = series.iter().filter(|p| p.0 < r).map(|p| p.1).fold(f64::MIN, f64::max);
                assert!(r >= e && (r == e || before <= thr * 1.05 * (1.0 + 1e-12)), "threshold {thr}: {e} {r}");
            }
        }
        // Fewer points than rises: 2,000 samples, a maximum rising from 0.5 to about 4.9.
        assert!(v.len() < 60, "{} points", v.len());
    }

    /// With exact delays of 3.33 s and 7.5 s after an onset at 0.02 s, on the 5 % grid: at every
    /// threshold, "alarmed within the delay" read from the profile (the replay's rule: the first point
    /// above the threshold, no later than the delay) is exactly the statistic's, where the grid alone
    /// misses some (a point up to a grid step late); the profile still rises and ends at the maximum.
    #[test]
    fn a_profile_is_exact_at_its_delays_whatever_the_grid() {
        let onset = 0.02;
        let series: Vec<(f64, f64)> = (2..2000)
            .map(|k| {
                (k as f64 * 0.01, 0.5 + 0.4 * (k as f64 * 0.37).sin() + 0.002 * k as f64 + 0.05 * (k as f64).cos())
            })
            .collect();
        let delays = [7.5, 3.33];
        let record = |exact: ExactDelays| {
            let mut fp = FirstPassage::with_exact_delays(ProfileGrid::new(0.05), exact);
            let (mut t, mut v) = (Vec::new(), Vec::new());
            series.iter().for_each(|&(ts, a)| fp.observe(ts, a, &mut t, &mut v));
            fp.close(&mut t, &mut v);
            (t, v)
        };
        let (t, v) = record(ExactDelays::new(onset, delays));
        let (t_grid, v_grid) = record(ExactDelays::NONE);
        assert!(v.windows(2).all(|w| w[1] >= w[0]) && t.windows(2).all(|w| w[1] >= w[0]));
        assert_eq!(v.last(), v_grid.last());
        let within = |t: &[f64], v: &[f64], thr: f64, delay: f64| {
            t.iter().zip(v).find(|(_, v)| **v > thr).is_some_and(|(t, _)| t - onset <= delay)
        };
        let (mut checked, mut grid_wrong) = (0, 0);
        for delay in delays {
            let max = series.iter().filter(|p| p.0 - onset <= delay).map(|p| p.1).fold(f64::MIN, f64::max);
            for k in 0..400 {
                let thr = 0.3 + k as f64 * 0.01;
                let exact = max > thr;
                assert_eq!(within(&t, &v, thr, delay), exact, "delay {delay}, threshold {thr}");
                grid_wrong += (within(&t_grid, &v_grid, thr, delay) != exact) as usize;
                checked += 1;
            }
            // Just below the maximum within the delay: the exact point itself.
            assert!(within(&t, &v, max - 1e-12, delay) && !within(&t, &v, max, delay));
        }
        assert_eq!(checked, 800);
        assert!(grid_wrong > 0, "the grid alone misses some (else this test shows nothing)");
        // No delay (onset not finite, or negative or infinite delays): the grid's profile.
        for none in [ExactDelays::new(f64::NAN, delays), ExactDelays::new(onset, [-1.0, f64::INFINITY])] {
            assert_eq!(record(none), (t_grid.clone(), v_grid.clone()));
        }
    }

    /// With a 2 s window: a delay of 1 s is a detection, 3 s a late alarm (a miss, nothing isolated),
    /// none neither; 2 s exactly is still within.
    #[test]
    fn an_alarm_after_the_detection_window_is_a_late_alarm_and_a_miss() {
        let mut core = CoreColumns::new(Vec::new(), 4, 2.0);
        for (trial, delay) in [(0, Some(1.0)), (1, Some(3.0)), (2, None), (3, Some(2.0))] {
            core.push(Outcome {
                trial,
                detector: "d",
                kind: "bias",
                target: Some(Cow::Borrowed("x")),
                size: Some(1.0),
                size_unit: unit::NONE,
                size_bin: Some(1.0),
                onset_s: Some(5.0),
                fault_free: false,
                failure: None,
                diverged: false,
                truth_diverged: false,
                false_alarm_s: None,
                delay_s: delay,
                isolated: delay.map(|_| Cow::Borrowed("x")),
                isolated_correctly: delay.map(|_| true),
                noise_scale: 1.0,
                noise_bin: 1.0,
                param_error_bin: 0.0,
                param_errors: &[],
            });
        }
        let df = DataFrame::new_infer_height(core.finish()).unwrap();
        let f = |c: &str| df.column(c).unwrap().f64().unwrap().iter().collect::<Vec<_>>();
        let detected: Vec<_> = df.column(col::DETECTED).unwrap().bool().unwrap().iter().collect();
        let isolated: Vec<_> = df.column(col::ISOLATED).unwrap().str().unwrap().iter().collect();
        assert_eq!(detected, [Some(true), Some(false), Some(false), Some(true)]);
        assert_eq!(f(col::DELAY_S), [Some(1.0), None, None, Some(2.0)]);
        assert_eq!(f(col::LATE_ALARM_S), [None, Some(3.0), None, None]);
        assert_eq!(isolated, [Some("x"), None, None, Some("x")]);
    }
}
