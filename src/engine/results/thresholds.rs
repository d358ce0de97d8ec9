//! Thresholds on recorded statistics (kinds whose records carry `pre_max_<s>` and first-passage
//! profiles, [`crate::engine::results::schema`]), calibrated after the run without re-simulating.
//!
//! Per detector (`thresholds.csv`):
//! - per statistic: the smallest threshold that at most `floor(p n)` of the `n` calibration units'
//!   pre-onset maxima exceed (so each statistic alone has false-alarm probability <= p on calibration
//!   data);
//! - whole detector: those thresholds times one common factor, the smallest at which at most
//!   `floor(p n)` calibration units alarm on any statistic: the detector's false-alarm probability is p
//!   (each threshold raised, where the product rounds below it, to the largest value of the units the
//!   factor lets through: [`let_through`]; so exactly `floor(p n)` alarm unless units tie).
//!
//! Calibration units are the fault-free ones flown to the end (their whole duration); without any, the
//! pre-onset windows of all units. `--thresholds F` applies another run's thresholds instead, and the
//! rates achieved here validate them on fresh trials (a warning when the target Pfa they were
//! calibrated for lies outside the interval achieved here). Only the `floor(p n) + 1` largest values are kept
//! per statistic, so memory does not grow with the trial count.

use std::cmp::Reverse;
use std::collections::BinaryHeap;
use std::path::{Path, PathBuf};

use polars::prelude::*;

use crate::engine::results::schema::{col, is_late};
use crate::engine::results::tables::{
    bool_col, column_names, f64_col, list_col, numbers, read_summary, slices, str_col,
};
use crate::engine::run::output::{VALIDATION_DIR, write_table};
use crate::engine::run::runner::{Manifest, RunError, pol};
use crate::engine::stats::intervals::{Z95, wilson};

/// The threshold sets' names.
pub const DECK: &str = "deck";

/// Rows read at a time.
pub const SLICE_ROWS: usize = 16_384;

/// Where the calibrated thresholds come from.
#[derive(Debug, Clone, PartialEq)]
pub enum Calibration {
    /// Calibrated here at this false-alarm probability.
    Target(f64),
    /// Calibrated here at this false-alarm probability with this confidence that the true probability
    /// is at most it (order statistic, [`confident_allowed`]).
    Confident { pfa: f64, confidence: f64 },
    /// Read from another run's `thresholds.csv`.
    File(PathBuf),
    /// Calibrated here at this false-alarm probability per flight hour, as the user gave it, converted
    /// to one per unit of `segment_s` seconds by [`per_segment`] (the hour's units taken as
    /// independent); with a confidence, as [`Calibration::Confident`] at that probability.
    PerHour { per_hour: f64, segment_s: f64, confidence: Option<f64> },
}

impl Calibration {
    /// The calibration a run's deck asks for (`monte_carlo.target_pfa`, `monte_carlo.confidence`): the
    /// one its own tables are at.
    pub fn of_deck(manifest: &Manifest) -> Self {
        match manifest.confidence {
            Some(confidence) => Calibration::Confident { pfa: manifest.target_pfa, confidence },
            None => Calibration::Target(manifest.target_pfa),
        }
    }

    /// The folder (under the run's `calibrations/`) a calibration other than the deck's is written to:
    /// `pfa_<p>` or `pfa_<p>_confidence_<c>`, numbers in Rust's shortest form (`pfa_0.05`, `pfa_1e-5`).
    /// A per-hour target is named as given: `pfa_per_hour_<h>` (`pfa_per_hour_1e-7`).
    pub fn folder_name(&self) -> String {
        let with = |c: Option<f64>| c.map_or(String::new(), |c| format!("_confidence_{}", short(c)));
        match self {
            Calibration::Target(p) => format!("pfa_{}", short(*p)),
            Calibration::Confident { pfa, confidence } => format!("pfa_{}{}", short(*pfa), with(Some(*confidence))),
            Calibration::PerHour { per_hour, confidence, .. } => {
                format!("pfa_per_hour_{}{}", short(*per_hour), with(*confidence))
            }
            Calibration::File(_) => VALIDATION_DIR.to_string(),
        }
    }

    /// The confidence of the calibration, where it has one.
    pub fn confidence(&self) -> Option<f64> {
        match self {
            Calibration::Confident { confidence, .. } => Some(*confidence),
            Calibration::PerHour { confidence, .. } => *confidence,
            _ => None,
        }
    }

    /// The false-alarm probability per calibration unit it calibrates at (`None`: a file's).
    pub fn target_pfa(&self) -> Option<f64> {
        match self {
            Calibration::Target(p) | Calibration::Confident { pfa: p, .. } => Some(*p),
            Calibration::PerHour { per_hour, segment_s, .. } => Some(per_segment(*per_hour, *segment_s)),
            Calibration::File(_) => None,
        }
    }

    /// The target as the user gave it: `Pfa 0.01`, `Pfa 0.01 with 0.95 confidence`, `1e-7 per flight
    /// hour (Pfa 2.7778e-10 per 10 s trial, the hour's trials taken as independent)`.
    pub fn describe(&self) -> String {
        let with = |c: Option<f64>| c.map_or(String::new(), |c| format!(" with {c} confidence"));
        match self {
            Calibration::Target(p) => format!("Pfa {p}"),
            Calibration::Confident { pfa, confidence } => format!("Pfa {pfa}{}", with(Some(*confidence))),
            Calibration::PerHour { per_hour, segment_s, confidence } => format!(
                "{per_hour} per flight hour (Pfa {:.4e} per {segment_s} s trial, the hour's trials taken as \
                 independent){}",
                per_segment(*per_hour, *segment_s),
                with(*confidence)
            ),
            Calibration::File(f) => format!("the thresholds of {}", f.display()),
        }
    }
}

/// `x` in the shorter of Rust's plain and exponent forms (`0.05`, `1e-5`, `1.6666666666666667e-8`).
fn short(x: f64) -> String {
    let (plain, exp) = (format!("{x}"), format!("{x:e}"));
    if exp.len() < plain.len() { exp } else { plain }
}

/// Thresholds of one detector configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct DetectorThresholds {
    pub detector: String,
    pub deck: Vec<f64>,
    /// Per statistic, each at the target false-alarm probability alone.
    pub per_statistic: Vec<f64>,
    /// Whole-detector thresholds (`per_statistic * scale`, [`let_through`] applied).
    pub whole: Vec<f64>,
    /// The fault-free units the thresholds were calibrated on, or (`--thresholds`) validated on.
    pub calibration_units: u64,
    pub per_statistic_false_alarms: Vec<u64>,
    pub whole_false_alarms: u64,
    /// The false-alarm probability the thresholds were calibrated for (`None`: a thresholds file that
    /// does not say).
    pub target_pfa: Option<f64>,
    /// The confidence they were calibrated with (`None`: plain calibration, or a file that does not
    /// say).
    pub confidence: Option<f64>,
    /// How long each calibration unit flew (s): a whole trial when calibrated on fault-free trials;
    /// `None` on pre-onset windows (of differing lengths) or without a trial duration.
    pub unit_duration_s: Option<f64>,
    /// Calibrated (or validated) on the fault-free trials, not on pre-onset windows.
    pub on_fault_free_trials: bool,
}

/// A probability per segment of `segment_s` seconds as one per flight hour, the hour's segments taken as
/// independent: `1 - (1 - p)^(3600 / segment_s)`.
pub fn per_flight_hour(p: f64, segment_s: f64) -> f64 {
    -((-p).ln_1p() * (3600.0 / segment_s)).exp_m1()
}

/// A whole flight's false-alarm figure above this many times the hour's segments converted by
/// [`per_flight_hour`] (the extremal index, or `design`'s exact ratio): the converted figure is a lower
/// bound, not one to quote (a choice: the issue that asked for it, #81).
pub const UNDERCOUNT_FLAG: f64 = 1.5;

/// What converting a trial's false-alarm probability to one per flight hour misses, where a kind knows
/// its residual's exact law ([`crate::engine::method::Method::hour_laws`]; the conversion takes the
/// hour's trials as independent, each starting with the filter on the truth): the extremal index
/// against the conversion, `ln P(no alarm in an hour flown through) / ln P(no alarm in the hour's
/// trials converted)` as `fdimc rare-event --flight-s` measures it, each `P` by Sidak's bound over every
/// sample and output. Near 1 when the residual settles early in a trial; above it when a slow mode
/// keeps the residual below its settled spread for much of the trial, where the hour's samples are
/// nearly all settled: the conversion then under-counts about this many times (for rare alarms, the
/// ratio of the hour's exceedance sum to its trials'; clusters of alarms aside).
/// src/exact/false_alarms.rs brackets it by the exact law. With the model exact and white
/// Gaussian noise.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HourConversion {
    /// The extremal index against the conversion; NaN where a trial's bound is 0.
    pub ratio: f64,
    /// The residual's slowest mode as a time constant (s).
    pub slowest_time_constant_s: f64,
    /// Sidak's bound on a trial's false-alarm probability at the thresholds: the exact law's upper
    /// bound (tight where alarms are rare and do not cluster within a trial); NaN where not computed.
    pub trial_upper: f64,
}

/// A detector's [`HourConversion`] at any thresholds (one per statistic), its law computed once.
pub type HourLaw = Box<dyn Fn(&[f64]) -> HourConversion + Send + Sync>;

impl HourConversion {
    /// The converted figures are lower bounds, not figures to quote (above [`UNDERCOUNT_FLAG`]).
    pub fn undercounts(&self) -> bool {
        self.ratio > UNDERCOUNT_FLAG
    }
}

/// The probability per segment of `segment_s` seconds that gives `per_hour` per flight hour (the
/// inverse of [`per_flight_hour`]).
pub fn per_segment(per_hour: f64, segment_s: f64) -> f64 {
    -((-per_hour).ln_1p() * segment_s / 3600.0).exp_m1()
}

/// The recorded statistics of a slice of `trials.parquet` (per statistic, each row's pre-onset maximum
/// and first-passage profile), read back to place alarms at other thresholds than the deck's.
pub struct RecordedStatistics {
    /// `pre[j][i]`: statistic j's largest value before the onset in row i (NaN where not recorded).
    pub pre: Vec<Vec<f64>>,
    /// `fp_t[j][i]`, `fp_v[j][i]`: statistic j's first-passage profile in row i, times (s) and values.
    pub fp_t: Vec<Vec<Vec<f64>>>,
    pub fp_v: Vec<Vec<Vec<f64>>>,
    /// Each row's onset (s; NaN when fault-free), and the run's detection window (s; infinite: none).
    pub onset_s: Vec<f64>,
    pub detection_window_s: f64,
}

impl RecordedStatistics {
    /// The columns that hold `statistics`, to select when reading a slice ([`RecordedStatistics::read`]
    /// also reads `onset_s`, which callers select with them).
    pub fn columns(statistics: &[String]) -> impl Iterator<Item = String> + '_ {
        statistics.iter().flat_map(|s| [col::pre_max(s), col::fp_t(s), col::fp_v(s)])
    }

    /// `statistics`' columns and the onsets of `df` (read from `file`, for messages), for a run whose
    /// manifest gives `detection_window_s`.
    pub fn read(
        df: &DataFrame,
        statistics: &[String],
        detection_window_s: Option<f64>,
        file: &Path,
    ) -> Result<Self, RunError> {
        let onset_s = f64_col(df, col::ONSET_S, file)?.iter().map(|v| v.unwrap_or(f64::NAN)).collect();
        let mut r = RecordedStatistics {
            pre: Vec::new(),
            fp_t: Vec::new(),
            fp_v: Vec::new(),
            onset_s,
            detection_window_s: detection_window_s.unwrap_or(f64::INFINITY),
        };
        for s in statistics {
            r.pre.push(numbers(df, &col::pre_max(s), file)?);
            r.fp_t.push(list_col(df, &col::fp_t(s), file)?);
            r.fp_v.push(list_col(df, &col::fp_v(s), file)?);
        }
        Ok(r)
    }

    /// Row `i`'s alarms at whole-detector thresholds `whole`: whether it has a false alarm, and its first
    /// post-onset alarm (none for a fault-free row).
    pub fn alarms_at(&self, i: usize, whole: &[f64], faulty: bool) -> (bool, Option<f64>) {
        let false_alarm = (0..whole.len()).any(|j| self.pre[j][i] > whole[j]);
        (false_alarm, if faulty { self.first_alarm(i, whole) } else { None })
    }

    /// Row `i`'s first post-onset alarm at thresholds `thr` (of the first `thr.len()` statistics) within
    /// the detection window: for each statistic the first profile point above its threshold, then the
    /// earliest over statistics, if it came within the window of the onset.
    pub fn first_alarm(&self, i: usize, thr: &[f64]) -> Option<f64> {
        self.first_alarm_any_time(i, thr).filter(|&t| !self.late(i, t))
    }

    /// Row `i`'s first post-onset alarm at thresholds `thr`, when it came after the detection window: a
    /// late alarm (a miss).
    pub fn late_alarm(&self, i: usize, thr: &[f64]) -> Option<f64> {
        self.first_alarm_any_time(i, thr).filter(|&t| self.late(i, t))
    }

    /// Row `i`'s first post-onset alarm within the detection window ([`Self::first_alarm`]) at each of
    /// the threshold sets `sets`, into `first` (one per set), where the sets descend statistic by
    /// statistic (`sets[k][j] <= sets[k - 1][j]`, or NaN in every set: [`descending`]). A profile whose
    /// values do not decrease (a running maximum's, as recorded) is walked down once for all the sets,
    /// where each set would search it; any other is searched per set. The ROC asks this of its ~41
    /// points per row.
    pub fn first_alarms_descending(&self, i: usize, sets: &[Vec<f64>], first: &mut [Option<f64>]) {
        let first = &mut first[..sets.len()];
        first.fill(None);
        let mut earliest = |k: usize, t: f64| first[k] = Some(first[k].map_or(t, |f: f64| f.min(t)));
        for j in 0..sets.first().map_or(0, Vec::len) {
            let (t, v) = (&self.fp_t[j][i], &self.fp_v[j][i]);
            if v.windows(2).all(|w| w[0] <= w[1]) {
                // The values above a threshold are a suffix `p..`; a lower threshold only lengthens it.
                let mut p = v.len();
                for (k, thr) in sets.iter().enumerate() {
                    while p > 0 && v[p - 1] > thr[j] {
                        p -= 1;
                    }
                    if p < v.len() {
                        earliest(k, t[p]);
                    }
                }
            } else {
                for (k, thr) in sets.iter().enumerate() {
                    if let Some((t, _)) = t.iter().zip(v).find(|(_, v)| **v > thr[j]) {
                        earliest(k, *t);
                    }
                }
            }
        }
        for f in first.iter_mut() {
            *f = f.filter(|&t| !self.late(i, t));
        }
    }

    fn first_alarm_any_time(&self, i: usize, thr: &[f64]) -> Option<f64> {
        (0..thr.len())
            .filter_map(|j| {
                let (t, v) = (&self.fp_t[j][i], &self.fp_v[j][i]);
                t.iter().zip(v).find(|(_, v)| **v > thr[j]).map(|(t, _)| *t)
            })
            .reduce(f64::min)
    }

    /// An alarm at `t_s` in row `i` is later than the window ([`is_late`], as the records).
    fn late(&self, i: usize, t_s: f64) -> bool {
        is_late(t_s - self.onset_s[i], self.detection_window_s)
    }
}

/// Whether the threshold sets `sets` descend statistic by statistic, as
/// [`RecordedStatistics::first_alarms_descending`] needs: each `sets[k][j] <= sets[k - 1][j]`, or NaN
/// in every set.
pub fn descending(sets: &[Vec<f64>]) -> bool {
    sets.windows(2)
        .all(|w| w[0].len() == w[1].len() && w[0].iter().zip(&w[1]).all(|(a, b)| b <= a || (a.is_nan() && b.is_nan())))
}

/// A unit's largest ratio of its statistics (`value(j)`) to the thresholds `base` (NaN values and
/// thresholds ignored): the unit alarms at `base * scale` when this exceeds `scale`.
pub fn unit_ratio(value: impl Fn(usize) -> f64, base: &[f64]) -> f64 {
    (0..base.len()).map(|j| value(j) / base[j]).fold(0.0, f64::max)
}

/// Makes `scaled` (`base * scale`) let through a unit whose ratio to `base` ([`unit_ratio`]) is at most
/// `scale`: the product can round one ulp below the value whose ratio set the scale, and that unit would
/// alarm. Each threshold is raised to the unit's value; a NaN threshold (a statistic that calibrates
/// nothing) stays NaN. Units with a larger ratio still alarm: their value on some statistic is above
/// that of every unit let through.
pub fn let_through(scaled: &mut [f64], value: impl Fn(usize) -> f64, base: &[f64], scale: f64) {
    if unit_ratio(&value, base) <= scale {
        for (j, t) in scaled.iter_mut().enumerate() {
            if !t.is_nan() {
                *t = t.max(value(j));
            }
        }
    }
}

/// The order statistic such that at most `floor(p n)` of the values exceed it; `(threshold,
/// exceedances)`.
pub fn calibrate(values: &mut [f64], p: f64) -> (f64, u64) {
    let mut top = TopValues::new(allowed(values.len() as u64, p) + 1);
    values.iter().for_each(|&v| top.push(v));
    let thr = top.threshold();
    (thr, values.iter().filter(|&&v| v > thr).count() as u64)
}

/// How many of `n` values may exceed the threshold at false-alarm probability `p` (at least one value
/// stays at or below it).
fn allowed(n: u64, p: f64) -> usize {
    ((p * n as f64).floor() as u64).min(n.saturating_sub(1)) as usize
}

/// How many of `n` calibration values may exceed a threshold whose true false-alarm probability is at
/// most `p` with probability `confidence` (distribution-free, Wilks' order-statistic bound, as 95/95
/// tolerance limits are set in safety analysis): the threshold is the `(m + 1)`-th largest value, and
/// it lies at or above the true `p`-quantile unless fewer than `m + 1` of the `n` values reach it, which
/// has probability `P(Binomial(n, p) <= m)`; the largest `m` that keeps this at most `1 - confidence`.
/// `None` when even the largest value cannot (`n` below [`trials_needed`]).
pub fn confident_allowed(n: u64, p: f64, confidence: f64) -> Option<usize> {
    use statrs::distribution::{Binomial, DiscreteCDF};
    let binomial = Binomial::new(p, n).ok()?;
    (0..n).take_while(|&m| binomial.cdf(m) <= 1.0 - confidence).last().map(|m| m as usize)
}

/// The fewest calibration values for which the largest is a threshold of false-alarm probability at
/// most `p` with `confidence`: `ceil(ln(1 - confidence) / ln(1 - p))` (59 at 0.05 / 0.95, 299 at 0.01).
pub fn trials_needed(p: f64, confidence: f64) -> u64 {
    ((1.0 - confidence).ln() / (1.0 - p).ln()).ceil() as u64
}

/// The `k` largest values seen (ordered as `f64::total_cmp`, NaN above everything).
pub(crate) struct TopValues {
    k: usize,
    heap: BinaryHeap<Reverse<Total>>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct Total(f64);
impl Eq for Total {}
impl PartialOrd for Total {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Total {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.0.total_cmp(&other.0)
    }
}

impl TopValues {
    pub(crate) fn new(k: usize) -> Self {
        TopValues { k, heap: BinaryHeap::with_capacity(k + 1) }
    }

    pub(crate) fn push(&mut self, v: f64) {
        if self.heap.len() < self.k {
            self.heap.push(Reverse(Total(v)));
        } else if self.heap.peek().is_some_and(|Reverse(min)| Total(v) > *min) {
            self.heap.pop();
            self.heap.push(Reverse(Total(v)));
        }
    }

    /// The values kept, in no order.
    pub(crate) fn values(&self) -> Vec<f64> {
        self.heap.iter().map(|Reverse(t)| t.0).collect()
    }

    /// The k-th largest value (NaN without values).
    fn threshold(&self) -> f64 {
        self.heap.peek().map_or(f64::NAN, |Reverse(t)| t.0)
    }
}

/// The calibration columns of one slice: which rows calibrate which detector, and their pre-onset maxima.
pub(crate) struct CalibrationRows {
    /// Per row: the detector's index when the row is a calibration unit.
    pub detector: Vec<Option<usize>>,
    /// `pre[j][row]`, NaN where null.
    pub pre: Vec<Vec<f64>>,
    /// Rows that would calibrate but whose truth diverged (left out, as every failed row).
    pub truth_diverged: u64,
}

/// Reads the calibration rows of `path` slice by slice and hands each slice to `visit`; `fault_free_only`
/// is `None` on the first pass (every flown row, with its fault-free flag), then whether only the
/// fault-free rows calibrate.
pub(crate) fn for_each_slice(
    path: &Path,
    rows: u64,
    manifest: &Manifest,
    statistics: &[String],
    fault_free_only: bool,
    mut visit: impl FnMut(&CalibrationRows),
) -> Result<(), RunError> {
    let mut select = vec![col::DETECTOR.to_string(), col::FAULT_FREE.to_string(), col::FAILURE.to_string()];
    // Runs of an fdimc before the column have none.
    let has_truth_diverged = column_names(path)?.iter().any(|c| c == col::TRUTH_DIVERGED);
    if has_truth_diverged {
        select.push(col::TRUTH_DIVERGED.to_string());
    }
    select.extend(statistics.iter().map(|s| col::pre_max(s)));
    for df in slices(path, rows as usize, SLICE_ROWS, &select) {
        let df = df?;
        let (det, fault_free, failure) = (
            str_col(&df, col::DETECTOR, path)?,
            bool_col(&df, col::FAULT_FREE, path)?,
            str_col(&df, col::FAILURE, path)?,
        );
        let diverged = if has_truth_diverged { Some(bool_col(&df, col::TRUTH_DIVERGED, path)?) } else { None };
        let mut detector = Vec::with_capacity(df.height());
        let mut truth_diverged = 0;
        for i in 0..df.height() {
            let candidate = !fault_free_only || fault_free.get(i) == Some(true);
            let calibrates = failure.get(i).is_none() && candidate;
            truth_diverged += (candidate && diverged.is_some_and(|c| c.get(i) == Some(true))) as u64;
            let d = det.get(i).and_then(|name| manifest.detectors.iter().position(|n| n == name));
            detector.push(d.filter(|_| calibrates));
        }
        let pre = statistics
            .iter()
            .map(|s| {
                let c = df.column(&col::pre_max(s)).and_then(|c| c.f64().cloned()).map_err(pol(path))?;
                Ok(c.iter().map(|v| v.unwrap_or(f64::NAN)).collect())
            })
            .collect::<Result<Vec<Vec<f64>>, RunError>>()?;
        visit(&CalibrationRows { detector, pre, truth_diverged });
    }
    Ok(())
}

/// Calibrates (or reads) every detector's thresholds on the run in `path` (module docs); returns them
/// and where they came from, and adds warnings. A target past what the calibration units resolve (the
/// thresholds would be only the largest values seen) is refused when `asked` (a calibration other than
/// the deck's), and said in the source when it is the deck's own.
pub fn thresholds(
    path: &Path,
    manifest: &Manifest,
    statistics: &[String],
    calibration: &Calibration,
    asked: bool,
    warnings: &mut Vec<String>,
) -> Result<(Vec<DetectorThresholds>, String), RunError> {
    let nd = manifest.detectors.len();
    let ns = statistics.len();
    let rows = manifest.rows;

    // Pass 1: are there fault-free units, and how many calibration units has each detector?
    let fault_free_rows = {
        let mut any = false;
        for df in slices(path, rows as usize, SLICE_ROWS, &[col::FAULT_FREE.to_string()]) {
            if bool_col(&df?, col::FAULT_FREE, path)?.any() {
                any = true;
                break;
            }
        }
        any
    };
    let mut n = vec![0u64; nd];
    let mut truth_diverged = 0;
    for_each_slice(path, rows, manifest, &[], fault_free_rows, |s| {
        s.detector.iter().flatten().for_each(|&d| n[d] += 1);
        truth_diverged += s.truth_diverged;
    })?;
    if truth_diverged > 0 && !matches!(calibration, Calibration::File(_)) {
        warnings.push(format!(
            "{truth_diverged} calibration trial x detector units left out of the calibration: their truth diverged \
             (truth_diverged in trials.parquet)"
        ));
    }
    let file = match calibration {
        Calibration::File(f) => Some(read_thresholds(f)?),
        _ => None,
    };
    let target_pfa = calibration.target_pfa().or_else(|| file.as_ref().and_then(|f| f.target_pfa));
    let confidence = match &file {
        Some(f) => f.confidence,
        None => calibration.confidence(),
    };
    // Every calibration unit failed (a diverged or crashed truth): nothing to calibrate on, and the
    // thresholds (NaN) must not read as calibrated.
    let none_flown = !matches!(calibration, Calibration::File(_)) && n.iter().all(|&k| k == 0);
    if none_flown {
        warnings.push(
            "no calibration trial was flown to the end (each failed: see failure in trials.parquet): no thresholds \
             calibrated"
                .into(),
        );
    }
    let target = calibration.describe();
    let mut source = match calibration {
        _ if none_flown => "not calibrated: no calibration trial was flown to the end".to_string(),
        Calibration::File(f) => format!(
            "thresholds from {}{}, validated on this run's {}",
            f.display(),
            target_pfa.map_or(String::new(), |p| format!(" (calibrated at Pfa {p})")),
            if fault_free_rows { "fault-free trials" } else { "pre-onset windows" }
        ),
        _ if fault_free_rows && confidence.is_some() => format!(
            "calibrated at {target} (order statistic; with too few trials for it, the tail fit's bound) on the \
             fault-free trials"
        ),
        _ if fault_free_rows => format!("calibrated at {target} on the fault-free trials"),
        _ => {
            warnings.push(
                "no fault-free trials: thresholds calibrated on the pre-onset windows (shorter than a whole trial)"
                    .into(),
            );
            format!("calibrated at {target} on the pre-onset windows")
        }
    };
    // Detectors whose thresholds are only the largest values seen: the target is past what the units
    // resolve (per detector: why, and how many units would).
    let mut unresolved: Vec<(usize, u64)> = Vec::new();

    let (per, whole): (Vec<Vec<f64>>, Vec<Vec<f64>>) = match (calibration, target_pfa) {
        (Calibration::File(f), _) => match &file {
            Some(file) => file.for_run(f, &manifest.detectors, ns)?,
            None => return Err(RunError::Internal("a thresholds file that was not read".into())),
        },
        (_, None) => return Err(RunError::Internal("a calibration without a target".into())),
        (_, Some(p)) => {
            let p = &p;
            let mut k = Vec::with_capacity(nd);
            // Detectors whose order statistic cannot give the confidence: their common factor comes from
            // the tail fit's upper bound instead, where one can be made.
            let mut by_tail = vec![false; nd];
            for (d, name) in manifest.detectors.iter().enumerate() {
                if n[d] == 0 {
                    // NaN thresholds; the run's warning says it when no detector has a unit.
                    if !none_flown {
                        warnings.push(format!(
                            "detector {name}: not calibrated: none of its calibration units was flown to the end \
                             (see failure in trials.parquet); its thresholds are NaN"
                        ));
                    }
                    k.push(1);
                    continue;
                }
                let exceedances = match confidence {
                    None => {
                        if (n[d] as f64) * p < 1.0 {
                            let needs = (1.0 / p).ceil();
                            warnings.push(format!(
                                "detector {name}: {} calibration trials cannot resolve Pfa {p} (needs >= {needs}): thresholds are the largest values seen",
                                n[d],
                            ));
                            unresolved.push((d, needs as u64));
                        }
                        allowed(n[d], *p)
                    }
                    Some(c) => confident_allowed(n[d], *p, c).unwrap_or_else(|| {
                        by_tail[d] = crate::engine::stats::tail::exceedances_for(n[d]).is_some();
                        if !by_tail[d] {
                            unresolved.push((d, trials_needed(*p, c)));
                            warnings.push(format!(
                                "detector {name}: {} calibration trials cannot give Pfa {p} with {c} confidence (needs >= {} fault-free trials for the order statistic, {} for a tail fit): thresholds are the largest values seen, without that confidence",
                                n[d],
                                trials_needed(*p, c),
                                10 * crate::engine::stats::tail::MIN_EXCEEDANCES
                            ));
                        }
                        0
                    }),
                };
                k.push(exceedances + 1);
            }
            // Pass 2: per statistic, the largest values.
            let mut top: Vec<Vec<TopValues>> =
                k.iter().map(|&k| (0..ns).map(|_| TopValues::new(k)).collect()).collect();
            for_each_slice(path, rows, manifest, statistics, fault_free_rows, |s| {
                for (i, d) in s.detector.iter().enumerate() {
                    if let Some(d) = *d {
                        for j in 0..ns {
                            top[d][j].push(s.pre[j][i]);
                        }
                    }
                }
            })?;
            let per: Vec<Vec<f64>> = top.iter().map(|t| t.iter().map(TopValues::threshold).collect()).collect();
            // Pass 3: the common factor, on each unit's largest statistic-to-threshold ratio.
            let kept = |d: usize| match crate::engine::stats::tail::exceedances_for(n[d]) {
                Some(e) if by_tail[d] => 2 * e + 1,
                _ => k[d],
            };
            let mut scale: Vec<TopValues> = (0..nd).map(|d| TopValues::new(kept(d))).collect();
            for_each_slice(path, rows, manifest, statistics, fault_free_rows, |s| {
                for (i, d) in s.detector.iter().enumerate() {
                    if let Some(d) = *d {
                        scale[d].push(unit_ratio(|j| s.pre[j][i], &per[d]));
                    }
                }
            })?;
            let factor: Vec<f64> = (0..nd)
                .map(|d| {
                    let (Some(c), true) = (confidence, by_tail[d]) else { return scale[d].threshold() };
                    let values = scale[d].values();
                    let fit = crate::engine::stats::tail::exceedances_for(n[d]).and_then(|e| crate::engine::stats::tail::TailFit::fit(&values, n[d], e));
                    let bound = fit.as_ref().map_or(f64::INFINITY, |f| f.quantile_upper(*p, c));
                    let largest = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
                    let name = &manifest.detectors[d];
                    if bound.is_finite() {
                        warnings.push(format!(
                            "detector {name}: {} calibration trials cannot give Pfa {p} with {c} confidence by the order statistic (needs >= {} fault-free trials): thresholds at the tail fit's {c} upper bound over tail shapes >= 0, {bound:.4} x the per-statistic maxima (holds if the generalised Pareto law holds beyond the data; tail.csv)",
                            n[d],
                            trials_needed(*p, c)
                        ));
                        bound
                    } else {
                        unresolved.push((d, trials_needed(*p, c)));
                        warnings.push(format!(
                            "detector {name}: {} calibration trials cannot give Pfa {p} with {c} confidence (needs >= {} fault-free trials), and the tail fit bounds no threshold: thresholds are the largest values seen, without that confidence",
                            n[d],
                            trials_needed(*p, c)
                        ));
                        largest
                    }
                })
                .collect();
            let mut whole: Vec<Vec<f64>> =
                per.iter().zip(&factor).map(|(p, s)| p.iter().map(|t| t * s).collect()).collect();
            for_each_slice(path, rows, manifest, statistics, fault_free_rows, |s| {
                for (i, d) in s.detector.iter().enumerate() {
                    if let Some(d) = *d {
                        let_through(&mut whole[d], |j| s.pre[j][i], &per[d], factor[d]);
                    }
                }
            })?;
            (per, whole)
        }
    };

    if let Some(&(_, needs)) = unresolved.iter().max_by_key(|u| u.1) {
        let names: Vec<&str> = unresolved.iter().map(|u| manifest.detectors[u.0].as_str()).collect();
        let have = unresolved.iter().map(|u| n[u.0]).min().unwrap_or(0);
        let units = if fault_free_rows { "fault-free trials" } else { "pre-onset windows" };
        if asked {
            let dir = path.parent().unwrap_or(path);
            let all = if have > 0 && fault_free_rows {
                let trials = (needs as f64 * manifest.trials as f64 / have as f64).ceil();
                format!(", about {trials} trials in all at this run's share of fault-free ones")
            } else {
                String::new()
            };
            return Err(RunError::Invalid(format!(
                "{}: {target} is past what this run resolves: {have} {units} per detector ({}), where the order \
                 statistic needs >= {needs}; no calibration written. Fly more trials (fdimc run DECK --trials N{all}), \
                 read the generalised Pareto tail fit's thresholds for rare targets in tail.csv (an extrapolation \
                 below 1/trials: tail_diagnostics.csv says when not to trust it), or estimate the false-alarm rate \
                 of given thresholds with fdimc rare-event (importance sampling or splitting on a linear truth; \
                 --flight-s for a whole flight)",
                dir.display(),
                names.join(", ")
            )));
        }
        source = format!(
            "not calibrated at {target}: {have} {units} cannot resolve it (needs >= {needs}); the thresholds of {} \
             are the largest values seen",
            names.join(", ")
        );
    }

    // Pass 4: what each threshold set lets through on the calibration units.
    let mut per_fa = vec![vec![0u64; ns]; nd];
    let mut whole_fa = vec![0u64; nd];
    for_each_slice(path, rows, manifest, statistics, fault_free_rows, |s| {
        for (i, d) in s.detector.iter().enumerate() {
            if let Some(d) = *d {
                for j in 0..ns {
                    per_fa[d][j] += (s.pre[j][i] > per[d][j]) as u64;
                }
                whole_fa[d] += (0..ns).any(|j| s.pre[j][i] > whole[d][j]) as u64;
            }
        }
    })?;
    let thresholds = manifest
        .detectors
        .iter()
        .enumerate()
        .map(|(d, name)| DetectorThresholds {
            detector: name.clone(),
            deck: manifest.deck_thresholds.get(d).cloned().unwrap_or_default(),
            per_statistic: per[d].clone(),
            whole: whole[d].clone(),
            calibration_units: n[d],
            per_statistic_false_alarms: per_fa[d].clone(),
            whole_false_alarms: whole_fa[d],
            target_pfa,
            confidence,
            unit_duration_s: manifest.trial_duration_s.filter(|_| fault_free_rows),
            on_fault_free_trials: fault_free_rows,
        })
        .collect::<Vec<_>>();
    // Thresholds from elsewhere: does this run bear out the false-alarm probability they were made for?
    if let (Calibration::File(f), Some(p)) = (calibration, target_pfa) {
        for t in &thresholds {
            let (lo, hi) = wilson(t.whole_false_alarms, t.calibration_units, Z95);
            if !(lo <= p && p <= hi) {
                warnings.push(format!(
                    "detector {}: the thresholds of {} were calibrated for Pfa {p}, but here {}/{} trials alarm ({:.4} [{lo:.4}, {hi:.4}]): the target is outside the interval",
                    t.detector,
                    f.display(),
                    t.whole_false_alarms,
                    t.calibration_units,
                    t.whole_false_alarms as f64 / t.calibration_units.max(1) as f64
                ));
            }
        }
    }
    Ok((thresholds, source))
}

/// Writes `thresholds.csv`: per detector, one row per statistic and one (`all`) for the whole detector.
pub fn write_thresholds(
    dir: &Path,
    thresholds: &[DetectorThresholds],
    statistics: &[String],
    source: &str,
) -> Result<(), RunError> {
    let path = dir.join("thresholds.csv");
    let (mut detector, mut statistic, mut deck, mut per, mut whole) = (vec![], vec![], vec![], vec![], vec![]);
    let mut n = vec![];
    // Per statistic rows: that statistic alone over its own threshold; `all` rows: the whole detector.
    let (mut alone, mut alone_pfa, mut alone_lo, mut alone_hi) = (vec![], vec![], vec![], vec![]);
    let (mut whole_fa, mut whole_pfa, mut whole_lo, mut whole_hi) = (vec![], vec![], vec![], vec![]);
    let (mut target, mut confidence) = (vec![], vec![]);
    let rate = |k: u64, n: u64| {
        let (lo, hi) = wilson(k, n, Z95);
        (n > 0).then(|| (k as f64 / n as f64, lo, hi))
    };
    for t in thresholds {
        let rows = statistics.iter().enumerate().map(|(j, s)| {
            (
                s.clone(),
                t.deck.get(j).copied(),
                Some(t.per_statistic[j]),
                Some(t.whole[j]),
                Some(t.per_statistic_false_alarms[j]),
                None,
            )
        });
        let all = std::iter::once(("all".to_string(), None, None, None, None, Some(t.whole_false_alarms)));
        for (s, dk, p, w, k_alone, k_whole) in rows.chain(all) {
            detector.push(t.detector.clone());
            statistic.push(s);
            deck.push(dk);
            per.push(p);
            whole.push(w);
            n.push(t.calibration_units);
            let r = k_alone.and_then(|k| rate(k, t.calibration_units));
            alone.push(k_alone);
            alone_pfa.push(r.map(|r| r.0));
            alone_lo.push(r.map(|r| r.1));
            alone_hi.push(r.map(|r| r.2));
            let r = k_whole.and_then(|k| rate(k, t.calibration_units));
            whole_fa.push(k_whole);
            whole_pfa.push(r.map(|r| r.0));
            whole_lo.push(r.map(|r| r.1));
            whole_hi.push(r.map(|r| r.2));
            target.push(t.target_pfa);
            confidence.push(t.confidence);
        }
    }
    let height = detector.len();
    let mut df = DataFrame::new_infer_height(vec![
        Column::new(col::DETECTOR.into(), detector),
        Column::new("statistic".into(), statistic),
        Column::new("deck_threshold".into(), deck),
        Column::new("per_statistic_threshold".into(), per),
        Column::new("detector_threshold".into(), whole),
        Column::new("trials".into(), n),
        Column::new("statistic_false_alarms".into(), alone),
        Column::new("statistic_pfa".into(), alone_pfa),
        Column::new("statistic_pfa_lo".into(), alone_lo),
        Column::new("statistic_pfa_hi".into(), alone_hi),
        Column::new("detector_false_alarms".into(), whole_fa),
        Column::new("detector_pfa".into(), whole_pfa),
        Column::new("detector_pfa_lo".into(), whole_lo),
        Column::new("detector_pfa_hi".into(), whole_hi),
        Column::new("target_pfa".into(), target),
        Column::new("confidence".into(), confidence),
        Column::new("source".into(), vec![source; height]),
    ])
    .map_err(pol(&path))?;
    Ok(write_table(&mut df, &path)?)
}

/// A `thresholds.csv` as read back: per detector (per-statistic thresholds, whole-detector thresholds) in
/// order, and the false-alarm probability they were calibrated for (`None` in a file without one).
pub struct ThresholdsFile {
    pub detectors: Vec<(String, Vec<f64>, Vec<f64>)>,
    pub target_pfa: Option<f64>,
    /// The confidence they were calibrated with (`None`: plain, or a file without the column).
    pub confidence: Option<f64>,
}

impl ThresholdsFile {
    /// Per-statistic and whole-detector thresholds of each of a run's `detectors` (in its order), each
    /// with `statistics` entries; a detector missing or a count that differs is refused, naming `path`.
    pub fn for_run(
        &self,
        path: &Path,
        detectors: &[String],
        statistics: usize,
    ) -> Result<(Vec<Vec<f64>>, Vec<Vec<f64>>), RunError> {
        let mut per = Vec::with_capacity(detectors.len());
        let mut whole = Vec::with_capacity(detectors.len());
        for d in detectors {
            let (_, p, w) = self.detectors.iter().find(|(name, _, _)| name == d).cloned().ok_or_else(|| {
                RunError::Invalid(format!(
                    "{}: has no detector {d:?}: calibrate on a run of the same deck",
                    path.display()
                ))
            })?;
            if p.len() != statistics {
                return Err(RunError::Invalid(format!(
                    "{}: has {} statistics for {d:?}, this run {statistics}",
                    path.display(),
                    p.len()
                )));
            }
            per.push(p);
            whole.push(w);
        }
        Ok((per, whole))
    }
}

/// Reads `thresholds.csv` (see [`ThresholdsFile`]).
pub fn read_thresholds(path: &Path) -> Result<ThresholdsFile, RunError> {
    let df = read_summary(path)?;
    let bad = |what: &str| RunError::Invalid(format!("{}: not an fdimc thresholds.csv ({what})", path.display()));
    let det = df.column(col::DETECTOR).and_then(|c| c.str().cloned()).map_err(|_| bad("no detector column"))?;
    let stat = df.column("statistic").and_then(|c| c.str().cloned()).map_err(|_| bad("no statistic column"))?;
    let number = |name: &str| {
        df.column(name).and_then(|c| c.cast(&DataType::Float64)).map_err(|_| bad(&format!("no {name} column")))
    };
    let (per, whole) = (number("per_statistic_threshold")?, number("detector_threshold")?);
    let (per, whole) =
        (per.f64().map_err(|_| bad("per_statistic_threshold"))?, whole.f64().map_err(|_| bad("detector_threshold"))?);
    let target_pfa = (number("target_pfa").ok())
        .and_then(|c| c.f64().ok().and_then(|c| c.iter().flatten().next()))
        .filter(|p| *p > 0.0 && *p < 1.0);
    let confidence = (number("confidence").ok())
        .and_then(|c| c.f64().ok().and_then(|c| c.iter().flatten().next()))
        .filter(|c| *c > 0.0 && *c < 1.0);
    let mut result: Vec<(String, Vec<f64>, Vec<f64>)> = Vec::new();
    for i in 0..df.height() {
        if stat.get(i) == Some("all") {
            continue;
        }
        let d = det.get(i).ok_or_else(|| bad("empty detector"))?.to_string();
        let (p, w) =
            (per.get(i).ok_or_else(|| bad("empty threshold"))?, whole.get(i).ok_or_else(|| bad("empty threshold"))?);
        // 0 is a threshold: a held time's (any sample above the level alarms) where few units hold at all.
        if !(p.is_finite() && w.is_finite() && p >= 0.0 && w >= 0.0) {
            return Err(bad(&format!("row {}: thresholds must be finite and >= 0", i + 1)));
        }
        match result.iter_mut().find(|r| r.0 == d) {
            Some(r) => {
                r.1.push(p);
                r.2.push(w);
            }
            None => result.push((d, vec![p], vec![w])),
        }
    }
    Ok(ThresholdsFile { detectors: result, target_pfa, confidence })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A scale that is one unit's ratio lets that unit through even where the product rounds one ulp
    /// below its value (about one pair in 20 does); a unit above the scale still alarms; a NaN
    /// threshold stays NaN, and a NaN value is no ratio.
    #[test]
    fn a_scale_lets_through_the_unit_that_set_it() {
        let (a, b) = (1..10_000)
            .map(|i| (1.0 + i as f64 * 1e-4 * std::f64::consts::PI, 0.3 + i as f64 * 1e-3))
            .find(|&(a, b)| b * (a / b) < a)
            .unwrap();
        let (base, unit) = ([b, f64::NAN], [a, 1.0]);
        let scale = unit_ratio(|j| unit[j], &base);
        assert_eq!(scale, a / b);
        let mut thresholds = [b * scale, f64::NAN];
        assert!(a > thresholds[0], "the product alone would let the unit alarm");
        let_through(&mut thresholds, |j| unit[j], &base, scale);
        assert_eq!(thresholds[0], a);
        assert!(thresholds[1].is_nan());
        let above = a * (1.0 + 1e-12);
        assert!(unit_ratio(|j| [above, 1.0][j], &base) > scale && above > thresholds[0]);
        // A unit above the scale raises nothing.
        let before = thresholds;
        let_through(&mut thresholds, |j| [above, 1.0][j], &base, scale);
        assert_eq!(thresholds[0], before[0]);
    }

    /// Per flight hour from 60 s trials: 60 independent segments an hour, so 1 - (1 - p)^60 (1e-3 per
    /// trial is 0.0583 per hour (0.058264); 1e-9 per trial is 6e-8 per hour), and back.
    #[test]
    fn per_flight_hour_takes_the_hours_segments_as_independent() {
        assert!((per_flight_hour(1e-3, 60.0) - (1.0 - 0.999f64.powi(60))).abs() < 1e-15);
        assert!((per_flight_hour(1e-3, 60.0) - 0.058264).abs() < 1e-6);
        assert!((per_flight_hour(1e-9, 60.0) / 6e-8 - 1.0).abs() < 1e-6, "no cancellation at small p");
        for p in [1e-9, 1e-4, 0.01] {
            assert!((per_segment(per_flight_hour(p, 30.0), 30.0) / p - 1.0).abs() < 1e-9, "{p}");
        }
    }

    /// Wilks' numbers: 59 values give a 95/95 bound with the largest (58 do not), 299 at Pfa 0.01;
    /// 500 values at 0.01 allow one exceedance (P(Binomial(500, 0.01) <= 1) = 0.040, <= 2: 0.123).
    #[test]
    fn confident_calibration_follows_wilks() {
        assert_eq!((trials_needed(0.05, 0.95), trials_needed(0.01, 0.95)), (59, 299));
        assert_eq!(confident_allowed(59, 0.05, 0.95), Some(0));
        assert_eq!(confident_allowed(58, 0.05, 0.95), None);
        assert_eq!(confident_allowed(298, 0.01, 0.95), None);
        assert_eq!(confident_allowed(500, 0.01, 0.95), Some(1));
        assert_eq!(confident_allowed(869, 0.01, 0.95), Some(3), "the CI deck's fault-free trials");
    }

    /// Over 4000 fresh calibration sets of 500 exponential maxima (true Pfa of a threshold x: e^-x), the
    /// plain threshold (at most floor(p n) = 5 exceedances) lets through more than the target 0.01 in
    /// 62 % of them; the 95 %-confident one in at most 5 % (here 4 %: its order is the one whose
    /// miss probability is 0.040).
    #[test]
    fn confident_thresholds_exceed_the_target_in_at_most_5_percent_of_fresh_seeds() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, Exp1};
        let (p, n, sets) = (0.01, 500, 4000);
        let (mut plain_over, mut confident_over) = (0, 0);
        for seed in 0..sets {
            let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(seed);
            let mut values: Vec<f64> = (0..n).map(|_| Exp1.sample(&mut rng)).collect();
            let (plain, _) = calibrate(&mut values, p);
            let mut top = TopValues::new(confident_allowed(n as u64, p, 0.95).unwrap() + 1);
            values.iter().for_each(|&v| top.push(v));
            plain_over += ((-plain).exp() > p) as u32;
            confident_over += ((-top.threshold()).exp() > p) as u32;
        }
        let (plain, confident) = (plain_over as f64 / sets as f64, confident_over as f64 / sets as f64);
        // Measured 0.618 and 0.039 (the formulas: P(Binomial(500, 0.01) <= 5) = 0.616, <= 1: 0.040).
        assert!((0.59..=0.65).contains(&plain), "plain thresholds exceed the target in {plain} of the sets");
        assert!((0.03..=0.05).contains(&confident), "confident thresholds exceed it in {confident}");
    }

    #[test]
    fn calibration_allows_floor_p_n_exceedances() {
        let mut v: Vec<f64> = (1..=1000).map(f64::from).collect();
        assert_eq!(calibrate(&mut v, 0.01), (990.0, 10));
        let mut v: Vec<f64> = (1..=50).map(f64::from).collect();
        assert_eq!(calibrate(&mut v, 0.01), (50.0, 0), "too few trials: the maximum, no exceedance");
        let mut v = vec![3.0, 1.0, 2.0, 2.0];
        assert_eq!(calibrate(&mut v, 0.5), (2.0, 1), "ties never give more exceedances than allowed");
        let mut v = vec![f64::NAN, 1.0, 2.0];
        assert!(calibrate(&mut v, 0.2).0.is_nan(), "NaN orders above every number, as total_cmp does");
    }

    #[test]
    fn the_alarm_is_the_earliest_first_passage_over_any_threshold() {
        // One row, two statistics.
        let recorded = RecordedStatistics {
            pre: vec![vec![0.4], vec![0.1]],
            fp_t: vec![vec![vec![1.0, 2.0, 3.0]], vec![vec![1.5, 2.5]]],
            fp_v: vec![vec![vec![0.5, 1.5, 2.5]], vec![vec![0.2, 3.0]]],
            onset_s: vec![0.5],
            detection_window_s: f64::INFINITY,
        };
        assert_eq!(recorded.first_alarm(0, &[1.0, 1.0]), Some(2.0));
        assert_eq!(recorded.first_alarm(0, &[2.0, 1.0]), Some(2.5));
        assert_eq!(recorded.first_alarm(0, &[3.0, 3.0]), None);
        assert_eq!(recorded.first_alarm(0, &[2.0]), Some(3.0), "the first statistic alone");
        assert_eq!(recorded.alarms_at(0, &[0.3, 1.0], true), (true, Some(1.0)));
        assert_eq!(recorded.alarms_at(0, &[0.5, 1.0], false), (false, None), "a fault-free row has no detection");
        // A 2 s window from the onset at 0.5 s: the alarm at 2.5 s is still a detection, at 3 s late.
        let windowed = RecordedStatistics { detection_window_s: 2.0, ..recorded };
        assert_eq!((windowed.first_alarm(0, &[2.0, 1.0]), windowed.late_alarm(0, &[2.0, 1.0])), (Some(2.5), None));
        assert_eq!((windowed.first_alarm(0, &[2.0]), windowed.late_alarm(0, &[2.0])), (None, Some(3.0)));
        assert_eq!(windowed.alarms_at(0, &[2.0], true), (false, None), "late: a miss");
    }

    /// The walk down each profile for descending threshold sets gives, set by set, what
    /// `first_alarm` gives: on 2,000 random rows of three statistics (running maxima on a grid, ties,
    /// empty profiles, a profile that decreases, onsets whose window cuts the profile) at 41 sets
    /// scaled down from random thresholds, one statistic's NaN in every set.
    #[test]
    fn the_descending_walk_gives_each_sets_first_alarm() {
        let mut state = 0x9e37_79b9_7f4a_7c15_u64;
        let mut uniform = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let rows = 2000;
        let (mut fp_t, mut fp_v) = (vec![Vec::new(); 3], vec![Vec::new(); 3]);
        let mut onset_s = Vec::new();
        for i in 0..rows {
            let onset = 1.0 + uniform();
            onset_s.push(onset);
            for j in 0..3 {
                let n = (uniform() * 12.0) as usize;
                let (mut t, mut v) = (Vec::new(), Vec::new());
                let (mut time, mut value) = (onset, uniform() * 2.0 - 0.5);
                for _ in 0..n {
                    time += 0.01 + uniform();
                    // A grid of 0.25 makes ties; every 97th row of statistic 1 decreases once.
                    value += (uniform() * 8.0).floor() * 0.25;
                    t.push(time);
                    v.push(value);
                }
                if j == 1 && i % 97 == 0 && n > 2 {
                    v[1] = v[0] - 1.0;
                }
                fp_t[j].push(t);
                fp_v[j].push(v);
            }
        }
        let pre = vec![vec![0.0; rows]; 3];
        let recorded = RecordedStatistics { pre, fp_t, fp_v, onset_s, detection_window_s: 4.0 };
        let base = [5.0, 4.0, f64::NAN];
        let sets: Vec<Vec<f64>> =
            (0..41).map(|k| base.iter().map(|b| b * (2.0 - k as f64 * 0.049)).collect()).collect();
        assert!(descending(&sets));
        assert!(!descending(&[vec![1.0, 2.0], vec![1.5, 1.0]]) && !descending(&[vec![f64::NAN], vec![1.0]]));
        let mut first = vec![None; 41];
        let (mut alarms, mut decreasing) = (0, 0);
        for i in 0..rows {
            recorded.first_alarms_descending(i, &sets, &mut first);
            for (k, set) in sets.iter().enumerate() {
                assert_eq!(first[k], recorded.first_alarm(i, set), "row {i}, set {k}");
                alarms += first[k].is_some() as usize;
            }
            decreasing += recorded.fp_v[1][i].windows(2).any(|w| w[1] < w[0]) as usize;
        }
        // Of the 82,000 row-sets, many alarm and many do not.
        assert!(alarms > 16_000 && alarms < 66_000 && decreasing > 10, "{alarms} alarms, {decreasing} decreasing");
    }
}
