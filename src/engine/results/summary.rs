//! The one summary of every kind of study, from `trials.parquet` without re-simulating, in memory that
//! does not grow with the trial count: the file is read a slice at a time, every table is a set of
//! counts (exact) and quantile sketches ([`crate::engine::stats::quantiles`]: exact to 4,096 values per group) that
//! the slices add to, and the paired comparison forgets each trial once the next begins.
//!
//! Threshold sets: `deck` (the alarms, delays and isolation the trial recorded at the deck's thresholds
//! or decision rule) and, for kinds that record a detection statistic, `calibrated` (the whole-detector
//! thresholds of [`crate::engine::results::thresholds`], evaluated from the recorded pre-onset maxima and first-passage
//! profiles; isolation needs the signals after the alarm, so it is the deck's only).
//!
//! Rates are over the units flown to the end (`failure` null): Pd is `detected / flown` in faulty
//! groups, Pfa `false_alarms / flown`, isolation accuracy `isolated_correctly / isolation_decided`;
//! each with its 95 % Wilson interval. Written to the results folder:
//!
//! | file | one row per | what |
//! |---|---|---|
//! | `summary.csv`, `summary.parquet` | thresholds x detector x kind x target x size bin x noise bin x parameter-error bin (x the kind's own bins) | the key columns, then `trials` (units), `failed`, `diverged`, `false_alarms`, `detected`, `missed`, `isolation_decided`, `isolated_correctly`, Pd, Pfa and isolation accuracy with intervals, delay p50/p90/p99, then the kind's own aggregates |
//! | `curves.csv` | thresholds x detector x kind x target x size bin | the same counts and rates (noise and parameter-error bins pooled): Pd against fault size |
//! | `min_detectable.csv` | thresholds x detector x kind x target | the smallest fault (by \|size\|, or \|factor - 1\| for gain) whose size bin has Pd >= 0.9, and whose Wilson lower bound is >= 0.9 |
//! | `detectors.csv` | thresholds x detector | over the faulty units: Pd, isolation, delays, the kind's aggregates; over every trial once (its first unit): flights, failures, false alarms, Pfa |
//! | `confusion.csv` | detector x truth x isolated | at the deck's thresholds: units, and their share of the truth's units (truth: the faulty target, or the kind for classifiers) |
//! | `comparison.csv` | thresholds x pair of detectors | [`crate::engine::stats::paired`] |
//! | `thresholds.csv` | detector x statistic (+ `all`) | kinds with a statistic: [`crate::engine::results::thresholds`] |

use std::collections::HashMap;
use std::path::Path;

use polars::prelude::*;

use crate::engine::results::schema::col;
use crate::engine::results::schema::unit;
use crate::engine::results::summary_spec::{Extra, Isolates, SummarySpec};
use crate::engine::results::tables::{
    Table, bool_col, column_names, complete_run, f64_col, numbers, slices, str_col, u64_col,
};
use crate::engine::results::thresholds::{
    Calibration, DECK, DetectorThresholds, RecordedStatistics, SLICE_ROWS, per_flight_hour, thresholds,
    write_thresholds,
};
use crate::engine::run::output::write_table;
use crate::engine::run::runner::{RunError, pol, write_parquet};
use crate::engine::stats::intervals::{Z95, wilson};
use crate::engine::stats::paired::{PairedUnits, UnitOutcome};
use crate::engine::stats::quantiles::Quantiles;

pub const CALIBRATED: &str = "calibrated";
/// Another run's thresholds (`summarize --thresholds`) on this run's trials.
pub const VALIDATION: &str = "validation";
/// Where `summarize --thresholds` writes, inside the run's folder: the run's own tables stay.
pub const VALIDATION_DIR: &str = "validation";
/// What `summarize` was asked and warned of, for the report (`summarize.json`).
pub const SETTINGS_FILE: &str = "summarize.json";

/// What `summarize` wrote, for printing.
#[derive(Debug)]
pub struct Summary {
    /// Kinds with a statistic: its names, the thresholds and where they came from.
    pub statistics: Vec<String>,
    pub thresholds: Option<(Vec<DetectorThresholds>, String)>,
    /// The rare-false-alarm fits ([`crate::engine::results::tails`]), per detector and threshold set.
    pub tails: Vec<crate::engine::results::tails::DetectorTail>,
    pub summary: DataFrame,
    pub detectors: DataFrame,
    pub confusion: DataFrame,
    pub warnings: Vec<String>,
    pub files: Vec<&'static str>,
    /// The folder the tables went to: the run's, or its `validation/`.
    pub out_dir: std::path::PathBuf,
    /// The threshold set beside `deck`: `calibrated` or `validation` (none for kinds without a statistic).
    pub set: Option<&'static str>,
}

/// `summarize.json`: the settings and warnings of the summary in a folder.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Settings {
    /// The threshold set beside `deck` (`calibrated`, `validation`), if any.
    pub thresholds: Option<String>,
    /// The false-alarm probability the thresholds are for.
    pub target_pfa: Option<f64>,
    /// Where the thresholds came from, as `thresholds.csv`'s `source` says.
    pub source: Option<String>,
    pub warnings: Vec<String>,
}

impl Settings {
    /// The settings `summarize` left in `dir`, if it left any.
    pub fn read(dir: &Path) -> Result<Option<Settings>, RunError> {
        let path = dir.join(SETTINGS_FILE);
        if !path.exists() {
            return Ok(None);
        }
        let text = std::fs::read_to_string(&path).map_err(crate::engine::run::runner::io(&path))?;
        serde_json::from_str(&text)
            .map(Some)
            .map_err(|e| RunError::Invalid(format!("{}: not a summarize.json of this fdimc ({e})", path.display())))
    }
}

/// Distinct strings of the key columns; keys hold their indices.
#[derive(Default)]
struct Names {
    ids: HashMap<String, u32>,
    names: Vec<String>,
}

const NO_NAME: u32 = u32::MAX;
const NO_NUMBER: u64 = u64::MAX;

impl Names {
    fn id(&mut self, s: Option<&str>) -> u32 {
        let Some(s) = s else { return NO_NAME };
        if let Some(&id) = self.ids.get(s) {
            return id;
        }
        self.names.push(s.to_string());
        self.ids.insert(s.to_string(), (self.names.len() - 1) as u32);
        (self.names.len() - 1) as u32
    }

    fn name(&self, id: u64) -> Option<&str> {
        (id != NO_NAME as u64).then(|| self.names[id as usize].as_str())
    }
}

fn number_key(v: Option<f64>) -> u64 {
    v.filter(|v| !v.is_nan()).map_or(NO_NUMBER, f64::to_bits)
}

fn number_of(key: u64) -> Option<f64> {
    (key != NO_NUMBER).then(|| f64::from_bits(key))
}

/// One unit's result at one threshold set.
struct Unit {
    flown: bool,
    faulty: bool,
    diverged: bool,
    false_alarm: bool,
    detected: bool,
    delay_s: Option<f64>,
    isolated: Option<u32>,
    correct: bool,
}

/// Counts and sketches of a set of units.
#[derive(Clone, Default)]
struct Counts {
    units: u64,
    failed: u64,
    diverged: u64,
    false_alarms: u64,
    detected: u64,
    decided: u64,
    correct: u64,
    faulty: bool,
    delay: Quantiles,
    /// Per [`Extra`]: the count of the counting ones.
    extra_counts: Vec<u64>,
    /// Per [`Extra`]: the values of the quantile ones.
    extra_values: Vec<Quantiles>,
}

impl Counts {
    fn new(extras: usize) -> Self {
        Counts { extra_counts: vec![0; extras], extra_values: vec![Quantiles::default(); extras], ..Default::default() }
    }

    /// Adds a unit; `extras` (per [`Extra`], see [`Extras::row`]) only at the deck's thresholds.
    fn add(&mut self, u: &Unit, extras: Option<&[f64]>, spec: &SummarySpec) {
        self.units += 1;
        self.faulty |= u.faulty;
        if !u.flown {
            self.failed += 1;
            return;
        }
        self.diverged += u.diverged as u64;
        self.false_alarms += u.false_alarm as u64;
        if u.faulty && u.detected {
            self.detected += 1;
            if let Some(d) = u.delay_s {
                self.delay.push(d);
            }
        }
        if u.isolated.is_some() {
            self.decided += 1;
            self.correct += u.correct as u64;
        }
        if let Some(values) = extras {
            for (k, (e, &v)) in spec.extras.iter().zip(values).enumerate() {
                match e {
                    Extra::Quantile { .. } => self.extra_values[k].push(v),
                    Extra::Rate { .. } => {}
                    _ => self.extra_counts[k] += (v > 0.0) as u64,
                }
            }
        }
    }

    fn merge(&mut self, o: &Counts) {
        self.units += o.units;
        self.failed += o.failed;
        self.diverged += o.diverged;
        self.false_alarms += o.false_alarms;
        self.detected += o.detected;
        self.decided += o.decided;
        self.correct += o.correct;
        self.faulty |= o.faulty;
        self.delay.merge(&o.delay);
        for (a, b) in self.extra_counts.iter_mut().zip(&o.extra_counts) {
            *a += b;
        }
        for (a, b) in self.extra_values.iter_mut().zip(&o.extra_values) {
            a.merge(b);
        }
    }

    fn flown(&self) -> u64 {
        self.units - self.failed
    }
}

/// The kind's own columns of one slice, as numbers per row and [`Extra`].
struct Extras {
    values: Vec<Vec<f64>>,
}

impl Extras {
    fn read(df: &DataFrame, spec: &SummarySpec, file: &Path) -> Result<Extras, RunError> {
        let target = str_col(df, col::TARGET, file)?;
        let values = spec
            .extras
            .iter()
            .map(|e| match *e {
                Extra::Rate { .. } => Ok(vec![f64::NAN; df.height()]),
                Extra::Present { column, .. } => {
                    let c = df.column(column).map_err(pol(file))?;
                    Ok((0..df.height()).map(|i| c.get(i).map_or(0.0, |v| (!v.is_null()) as u8 as f64)).collect())
                }
                Extra::NamesTarget { column, .. } => {
                    let c = str_col(df, column, file)?;
                    Ok((0..df.height())
                        .map(|i| (c.get(i).is_some() && c.get(i) == target.get(i)) as u8 as f64)
                        .collect())
                }
                Extra::Quantile { column, abs, .. } => {
                    let v = numbers(df, column, file)?;
                    Ok(if abs { v.into_iter().map(f64::abs).collect() } else { v })
                }
                Extra::Count { column, .. } => numbers(df, column, file),
            })
            .collect::<Result<_, RunError>>()?;
        Ok(Extras { values })
    }

    fn row(&self, i: usize, out: &mut Vec<f64>) {
        out.clear();
        out.extend(self.values.iter().map(|v| v[i]));
    }
}

/// Everything the slices add to.
struct Aggregates<'s> {
    spec: &'s SummarySpec,
    sets: Vec<&'static str>,
    detectors: Vec<String>,
    names: Names,
    groups: HashMap<Vec<u64>, Counts>,
    /// Per (set, detector): every unit, the faulty units, and every trial once (its first unit).
    per_detector: Vec<(Counts, Counts, Counts)>,
    /// (detector, truth, isolated) at the deck's thresholds.
    confusion: HashMap<(usize, u32, u32), u64>,
    pairs: Vec<PairedUnits>,
    /// The current trial and how many units each detector has had in it.
    trial: Option<u64>,
    units_seen: Vec<usize>,
}

impl<'s> Aggregates<'s> {
    fn new(spec: &'s SummarySpec, sets: Vec<&'static str>, detectors: &[String]) -> Self {
        let nd = detectors.len();
        let n_extras = spec.extras.len();
        let isolation_on_all = spec.isolates == Isolates::Kind;
        Aggregates {
            spec,
            pairs: sets.iter().map(|_| PairedUnits::new(detectors, spec.paired_medians, isolation_on_all)).collect(),
            per_detector: vec![(Counts::new(n_extras), Counts::new(n_extras), Counts::new(n_extras)); sets.len() * nd],
            sets,
            detectors: detectors.to_vec(),
            names: Names::default(),
            groups: HashMap::new(),
            confusion: HashMap::new(),
            trial: None,
            units_seen: vec![0; nd],
        }
    }

    /// Adds the rows of one slice; `calibrated`: the whole-detector thresholds per detector and the
    /// statistics' names, for kinds that record statistics.
    fn add_slice(
        &mut self,
        df: &DataFrame,
        file: &Path,
        calibrated: Option<(&[DetectorThresholds], &[String])>,
    ) -> Result<(), RunError> {
        let spec = self.spec;
        let trial = u64_col(df, col::TRIAL, file)?;
        let det = str_col(df, col::DETECTOR, file)?;
        let kind = str_col(df, col::KIND, file)?;
        let target = str_col(df, col::TARGET, file)?;
        let size_bin = f64_col(df, col::SIZE_BIN, file)?;
        let onset = f64_col(df, col::ONSET_S, file)?;
        let fault_free = bool_col(df, col::FAULT_FREE, file)?;
        let failure = str_col(df, col::FAILURE, file)?;
        let diverged = bool_col(df, col::DIVERGED, file)?;
        let false_alarm = bool_col(df, col::FALSE_ALARM, file)?;
        let detected = bool_col(df, col::DETECTED, file)?;
        let delay = f64_col(df, col::DELAY_S, file)?;
        let isolated = str_col(df, col::ISOLATED, file)?;
        let correct = bool_col(df, col::ISOLATED_CORRECTLY, file)?;
        let noise_bin = f64_col(df, col::NOISE_BIN, file)?;
        let perr_bin = f64_col(df, col::PARAM_ERROR_BIN, file)?;
        let extra_keys =
            spec.extra_keys.iter().map(|k| numbers(df, k, file)).collect::<Result<Vec<Vec<f64>>, RunError>>()?;
        let extras = Extras::read(df, spec, file)?;
        let paired_medians =
            spec.paired_medians.iter().map(|c| numbers(df, c, file)).collect::<Result<Vec<Vec<f64>>, RunError>>()?;
        let profiles = match calibrated {
            Some((_, statistics)) => Some(RecordedStatistics::read(df, statistics, file)?),
            None => None,
        };

        let mut key = Vec::with_capacity(7 + spec.extra_keys.len());
        let mut extra_row = Vec::with_capacity(spec.extras.len());
        for i in 0..df.height() {
            let name = det.get(i).unwrap_or_default();
            let d = self.detectors.iter().position(|n| n == name).ok_or_else(|| {
                RunError::Invalid(format!(
                    "{}: row of detector {name:?}, which the manifest does not list ({})",
                    file.display(),
                    self.detectors.join(", ")
                ))
            })?;
            let t = trial.get(i).unwrap_or(0);
            if self.trial != Some(t) {
                self.trial = Some(t);
                self.units_seen.iter_mut().for_each(|n| *n = 0);
            }
            let first_unit = self.units_seen[d] == 0;
            self.units_seen[d] += 1;
            let faulty = fault_free.get(i) != Some(true);
            let flown = failure.get(i).is_none();
            let kind_id = self.names.id(kind.get(i));
            let target_id = self.names.id(target.get(i));
            extras.row(i, &mut extra_row);
            for s in 0..self.sets.len() {
                let set = self.sets[s];
                let unit = if set == DECK {
                    let iso = isolated.get(i).map(|n| self.names.id(Some(n)));
                    Unit {
                        flown,
                        faulty,
                        diverged: diverged.get(i) == Some(true),
                        false_alarm: false_alarm.get(i) == Some(true),
                        detected: detected.get(i) == Some(true),
                        delay_s: delay.get(i),
                        isolated: iso,
                        correct: correct.get(i) == Some(true),
                    }
                } else {
                    let (thresholds, _) = calibrated.expect("a calibrated set has thresholds");
                    let profiles = profiles.as_ref().expect("a calibrated set has profiles");
                    let (fa, alarm) = profiles.alarms_at(i, &thresholds[d].whole, faulty);
                    Unit {
                        flown,
                        faulty,
                        diverged: diverged.get(i) == Some(true),
                        false_alarm: fa,
                        detected: alarm.is_some(),
                        delay_s: alarm.map(|a| a - onset.get(i).unwrap_or(f64::NAN)),
                        isolated: None,
                        correct: false,
                    }
                };
                let extras_here = (set == DECK).then_some(extra_row.as_slice());
                key.clear();
                key.extend([
                    s as u64,
                    d as u64,
                    kind_id as u64,
                    target_id as u64,
                    number_key(size_bin.get(i)),
                    number_key(noise_bin.get(i)),
                    number_key(perr_bin.get(i)),
                ]);
                key.extend(extra_keys.iter().map(|k| number_key(Some(k[i]))));
                match self.groups.get_mut(key.as_slice()) {
                    Some(g) => g.add(&unit, extras_here, spec),
                    None => {
                        let mut g = Counts::new(spec.extras.len());
                        g.add(&unit, extras_here, spec);
                        self.groups.insert(key.clone(), g);
                    }
                }
                let (units, faulty_units, trials) = &mut self.per_detector[s * self.detectors.len() + d];
                units.add(&unit, extras_here, spec);
                if faulty {
                    faulty_units.add(&unit, extras_here, spec);
                }
                if first_unit {
                    trials.add(&unit, None, spec);
                }
                let truth = match spec.isolates {
                    Isolates::Target if faulty => Some(target_id),
                    Isolates::Target => None,
                    Isolates::Kind => Some(kind_id),
                };
                if let (DECK, Some(truth), true) = (set, truth, flown) {
                    *self.confusion.entry((d, truth, unit.isolated.unwrap_or(NO_NAME))).or_insert(0) += 1;
                }
                let mut paired = vec![unit.delay_s];
                paired.extend(paired_medians.iter().map(|c| Some(c[i]).filter(|v| !v.is_nan())));
                self.pairs[s].push(
                    t,
                    d,
                    UnitOutcome {
                        flown,
                        faulty,
                        detected: faulty && unit.detected,
                        isolated: unit.correct && unit.isolated.is_some(),
                        false_alarm: unit.false_alarm,
                        paired,
                    },
                );
            }
        }
        Ok(())
    }
}

/// The key columns of a table, by position in a group key.
struct KeyColumns {
    names: Vec<String>,
    /// Per key position: text (an interned name) or a number.
    text: Vec<bool>,
}

/// A table of groups: the key columns, then the counts, rates, delays and (with `extras`) the kind's
/// aggregates, sorted by key (text ascending, numbers ascending, nulls last).
fn group_table(
    groups: &[(Vec<u64>, Counts)],
    keys: &KeyColumns,
    names: &Names,
    sets: &[&str],
    spec: &SummarySpec,
    extras: bool,
) -> PolarsResult<DataFrame> {
    let mut rows: Vec<&(Vec<u64>, Counts)> = groups.iter().collect();
    let text_of = |k: usize, v: u64| if k == 0 { Some(sets[v as usize]) } else { names.name(v) };
    rows.sort_by(|a, b| {
        for k in 0..keys.names.len() {
            let o = if keys.text[k] {
                match (text_of(k, a.0[k]), text_of(k, b.0[k])) {
                    (Some(x), Some(y)) => x.cmp(y),
                    (x, y) => x.is_none().cmp(&y.is_none()),
                }
            } else {
                match (number_of(a.0[k]), number_of(b.0[k])) {
                    (Some(x), Some(y)) => x.total_cmp(&y),
                    (x, y) => x.is_none().cmp(&y.is_none()),
                }
            };
            if o != std::cmp::Ordering::Equal {
                return o;
            }
        }
        std::cmp::Ordering::Equal
    });
    let mut columns = Vec::new();
    for (k, name) in keys.names.iter().enumerate() {
        if keys.text[k] {
            let v: Vec<Option<&str>> = rows.iter().map(|r| text_of(k, r.0[k])).collect();
            columns.push(Column::new(name.as_str().into(), v));
        } else {
            let v: Vec<Option<f64>> = rows.iter().map(|r| number_of(r.0[k])).collect();
            columns.push(Column::new(name.as_str().into(), v));
        }
    }
    let counts: Vec<&Counts> = rows.iter().map(|r| &r.1).collect();
    let deck = |r: &&(Vec<u64>, Counts)| sets[r.0[0] as usize] == DECK;
    let at_deck: Vec<bool> = rows.iter().map(deck).collect();
    columns.extend(count_columns(&counts, spec, extras.then_some(at_deck.as_slice())));
    DataFrame::new_infer_height(columns)
}

/// The shared counts, rates and delays of `counts`, then (with `at_deck`: per row, whether it is of the
/// deck's set; the others have no kind aggregates) the kind's aggregates.
fn count_columns(counts: &[&Counts], spec: &SummarySpec, at_deck: Option<&[bool]>) -> Vec<Column> {
    let u = |f: &dyn Fn(&Counts) -> u64| counts.iter().map(|c| f(c)).collect::<Vec<u64>>();
    let mut columns = vec![
        Column::new("trials".into(), u(&|c| c.units)),
        Column::new("failed".into(), u(&|c| c.failed)),
        Column::new("diverged".into(), u(&|c| c.diverged)),
        Column::new("false_alarms".into(), u(&|c| c.false_alarms)),
        Column::new("detected".into(), u(&|c| c.detected)),
        Column::new(
            "missed".into(),
            counts.iter().map(|c| c.faulty.then(|| c.flown() - c.detected)).collect::<Vec<Option<u64>>>(),
        ),
        Column::new("isolation_decided".into(), u(&|c| c.decided)),
        Column::new("isolated_correctly".into(), u(&|c| c.correct)),
    ];
    let pairs = |f: &dyn Fn(&Counts) -> (u64, u64, bool)| counts.iter().map(|c| f(c)).collect::<Vec<_>>();
    columns.extend(rate_columns("pd", &pairs(&|c| (c.detected, c.flown(), c.faulty))));
    columns.extend(rate_columns("pfa", &pairs(&|c| (c.false_alarms, c.flown(), true))));
    columns.extend(rate_columns("isolation_accuracy", &pairs(&|c| (c.correct, c.decided, true))));
    for (name, p) in [("delay_p50_s", 0.5), ("delay_p90_s", 0.9), ("delay_p99_s", 0.99)] {
        columns.push(Column::new(name.into(), counts.iter().map(|c| c.delay.quantile(p)).collect::<Vec<_>>()));
    }
    if let Some(at_deck) = at_deck {
        columns.extend(extra_columns(counts, spec, at_deck));
    }
    columns
}

/// The kind's aggregates of `counts`; rows not of the deck's set (`at_deck` false) have none.
fn extra_columns(counts: &[&Counts], spec: &SummarySpec, at_deck: &[bool]) -> Vec<Column> {
    let mut columns = Vec::new();
    for (k, e) in spec.extras.iter().enumerate() {
        match *e {
            Extra::Quantile { name, p, .. } => {
                let v: Vec<Option<f64>> =
                    counts.iter().zip(at_deck).map(|(c, &d)| c.extra_values[k].quantile(p).filter(|_| d)).collect();
                columns.push(Column::new(name.into(), v));
            }
            Extra::Rate { name, k: num, n: den, faulty_only } => {
                let count = |c: &Counts, which: &str| -> u64 {
                    match which {
                        "flown" => c.flown(),
                        "isolation_decided" => c.decided,
                        other => spec.extras.iter().position(|e| e.name() == other).map_or(0, |j| c.extra_counts[j]),
                    }
                };
                let v: Vec<(u64, u64, bool)> = counts
                    .iter()
                    .zip(at_deck)
                    .map(|(c, &d)| (count(c, num), if d { count(c, den) } else { 0 }, !faulty_only || c.faulty))
                    .collect();
                columns.extend(rate_columns(name, &v));
            }
            _ => {
                let v: Vec<Option<u64>> =
                    counts.iter().zip(at_deck).map(|(c, &d)| d.then_some(c.extra_counts[k])).collect();
                columns.push(Column::new(e.name().into(), v));
            }
        }
    }
    columns
}

/// `name`, `name_lo`, `name_hi`: `k / n` with its 95 % Wilson interval, null where `n = 0` or not kept.
fn rate_columns(name: &str, rates: &[(u64, u64, bool)]) -> [Column; 3] {
    let mut cols: [Vec<Option<f64>>; 3] = Default::default();
    for &(k, n, keep) in rates {
        let ok = keep && n > 0;
        let (lo, hi) = wilson(k, n, Z95);
        cols[0].push(ok.then(|| k as f64 / n as f64));
        cols[1].push(ok.then_some(lo));
        cols[2].push(ok.then_some(hi));
    }
    let [rate, lo, hi] = cols;
    [
        Column::new(name.into(), rate),
        Column::new(format!("{name}_lo").into(), lo),
        Column::new(format!("{name}_hi").into(), hi),
    ]
}

/// Reads the run in `dir`, writes the tables of the module docs and returns what `print` shows.
/// `calibration` applies to kinds that record statistics (default: the deck's target Pfa).
pub fn summarize(dir: &Path, spec: &SummarySpec, calibration: Option<&Calibration>) -> Result<Summary, RunError> {
    let (manifest, path) = complete_run(dir)?;
    let columns = column_names(&path)?;
    let statistics: Vec<String> =
        columns.iter().filter_map(|c| c.strip_prefix(col::PRE_MAX_PREFIX)).map(str::to_string).collect();
    let mut warnings = Vec::new();
    let thresholds = if statistics.is_empty() {
        None
    } else {
        let calibration = calibration.cloned().unwrap_or(Calibration::Target(manifest.target_pfa));
        Some(thresholds(&path, &manifest, &statistics, &calibration, &mut warnings)?)
    };
    let validating = matches!(calibration, Some(Calibration::File(_)));
    let set = thresholds.as_ref().map(|_| if validating { VALIDATION } else { CALIBRATED });
    let sets: Vec<&'static str> = [Some(DECK), set].into_iter().flatten().collect();
    let dir_out = if validating { dir.join(VALIDATION_DIR) } else { dir.to_path_buf() };
    std::fs::create_dir_all(&dir_out).map_err(crate::engine::run::runner::io(&dir_out))?;

    // Only the columns the tables read.
    let mut select: Vec<String> = [
        col::TRIAL,
        col::DETECTOR,
        col::KIND,
        col::TARGET,
        col::SIZE_BIN,
        col::ONSET_S,
        col::FAULT_FREE,
        col::FAILURE,
        col::DIVERGED,
        col::FALSE_ALARM,
        col::DETECTED,
        col::DELAY_S,
        col::ISOLATED,
        col::ISOLATED_CORRECTLY,
        col::NOISE_BIN,
        col::PARAM_ERROR_BIN,
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    let own = spec
        .extra_keys
        .iter()
        .copied()
        .chain(spec.extras.iter().filter_map(Extra::column))
        .chain(spec.paired_medians.iter().copied());
    for c in own {
        if !select.iter().any(|s| s == c) {
            select.push(c.to_string());
        }
    }
    if thresholds.is_some() {
        for s in &statistics {
            select.extend([col::pre_max(s), col::fp_t(s), col::fp_v(s)]);
        }
    }
    for c in &select {
        if !columns.contains(c) {
            return Err(RunError::Invalid(format!(
                "{}: has no column {c:?}: not a {} run of this fdimc (re-run the study)",
                path.display(),
                manifest.kind
            )));
        }
    }

    let mut agg = Aggregates::new(spec, sets.clone(), &manifest.detectors);
    let calibrated = thresholds.as_ref().map(|(t, _)| (t.as_slice(), statistics.as_slice()));
    for df in slices(&path, manifest.rows as usize, SLICE_ROWS, &select) {
        agg.add_slice(&df?, &path, calibrated)?;
    }

    let mut key_names: Vec<String> =
        ["thresholds", col::DETECTOR, col::KIND, col::TARGET, col::SIZE_BIN, col::NOISE_BIN, col::PARAM_ERROR_BIN]
            .iter()
            .map(|s| s.to_string())
            .collect();
    key_names.extend(spec.extra_keys.iter().map(|s| s.to_string()));
    let mut text = vec![true, true, true, true, false, false, false];
    text.extend(spec.extra_keys.iter().map(|_| false));
    let keys = KeyColumns { names: key_names, text };
    // The detector's name in tables: its index in the key becomes its interned name.
    let mut names = std::mem::take(&mut agg.names);
    let detector_ids: Vec<u32> = manifest.detectors.iter().map(|d| names.id(Some(d))).collect();
    let groups: Vec<(Vec<u64>, Counts)> = agg
        .groups
        .drain()
        .map(|(mut k, c)| {
            k[1] = detector_ids[k[1] as usize] as u64;
            (k, c)
        })
        .collect();
    let mut summary = group_table(&groups, &keys, &names, &sets, spec, true).map_err(pol(&path))?;

    let mut curves_map: HashMap<Vec<u64>, Counts> = HashMap::new();
    for (k, c) in &groups {
        curves_map.entry(k[..5].to_vec()).or_insert_with(|| Counts::new(spec.extras.len())).merge(c);
    }
    let curve_groups: Vec<(Vec<u64>, Counts)> = curves_map.into_iter().collect();
    let curve_keys = KeyColumns { names: keys.names[..5].to_vec(), text: keys.text[..5].to_vec() };
    let mut curves = group_table(&curve_groups, &curve_keys, &names, &sets, spec, false).map_err(pol(&path))?;
    let mut min_detectable = min_detectable(&curves, &manifest.fault_size_units).map_err(pol(&path))?;
    for df in [&mut summary, &mut curves, &mut min_detectable] {
        with_size_unit(df, &manifest.fault_size_units).map_err(pol(&path))?;
    }
    let bins = &manifest.fault_size_bins;
    for df in [&mut summary, &mut curves] {
        with_bin_edges(df, col::SIZE_BIN, bins).map_err(pol(&path))?;
    }
    for centre in ["min_size_pd90", "min_size_pd90_lower_bound"] {
        with_bin_edges(&mut min_detectable, centre, bins).map_err(pol(&path))?;
    }

    let mut detectors = detector_table(&agg, &sets, spec).map_err(pol(&path))?;
    let mut confusion = confusion_table(&agg, &names).map_err(pol(&path))?;

    let out = |f: &str| dir_out.join(f);
    let mut files = Vec::new();
    let mut tails = Vec::new();
    if let (Some((t, source)), Some(set)) = (&thresholds, set) {
        write_thresholds(&dir_out, t, &statistics, source)?;
        files.push("thresholds.csv");
        tails = crate::engine::results::tails::tails(&path, &manifest, &statistics, t, set)?;
        crate::engine::results::tails::write_tail_tables(&dir_out, &tails, &statistics)?;
        files.extend(["tail.csv", "tail_diagnostics.csv"]);
    }
    write_table(&mut summary, &out("summary.csv"))?;
    write_parquet(&mut summary, &out("summary.parquet"))?;
    write_table(&mut curves, &out("curves.csv"))?;
    write_table(&mut min_detectable, &out("min_detectable.csv"))?;
    write_table(&mut detectors, &out("detectors.csv"))?;
    write_table(&mut confusion, &out("confusion.csv"))?;
    files.extend(crate::engine::run::output::SUMMARY_TABLES);
    if manifest.detectors.len() > 1 {
        let mut all: Option<DataFrame> = None;
        for (set, pairs) in sets.iter().zip(std::mem::take(&mut agg.pairs)) {
            let mut df = pairs.finish().map_err(pol(&path))?;
            let height = df.height();
            df.insert_column(0, Column::new("thresholds".into(), vec![*set; height])).map_err(pol(&path))?;
            match &mut all {
                Some(a) => {
                    a.vstack_mut(&df).map_err(pol(&path))?;
                }
                None => all = Some(df),
            }
        }
        if let Some(mut c) = all {
            write_table(&mut c, &out("comparison.csv"))?;
            files.push("comparison.csv");
        }
    }

    // Failures and divergence, counted once per unit (every threshold set holds the same units).
    let (failed, diverged) = agg.per_detector[..manifest.detectors.len()]
        .iter()
        .fold((0, 0), |(f, d), (units, _, _)| (f + units.failed, d + units.diverged));
    if failed > 0 {
        warnings.push(format!("{failed} trial x detector units were not flown to the end (failure in trials.parquet)"));
    }
    if diverged > 0 {
        warnings.push(format!("{diverged} trial x detector units had a filter diverge (diverged in trials.parquet)"));
    }
    let settings = Settings {
        thresholds: set.map(str::to_string),
        target_pfa: thresholds.as_ref().and_then(|(t, _)| t.first().and_then(|t| t.target_pfa)),
        source: thresholds.as_ref().map(|(_, s)| s.clone()),
        warnings: warnings.clone(),
    };
    let json = serde_json::to_string_pretty(&settings).map_err(|e| RunError::Internal(e.to_string()))?;
    let settings_path = out(SETTINGS_FILE);
    crate::engine::run::runner::write_atomically(&settings_path, json.as_bytes())?;
    files.push(SETTINGS_FILE);
    Ok(Summary { statistics, thresholds, tails, summary, detectors, confusion, warnings, files, out_dir: dir_out, set })
}

/// `detectors.csv` (module docs), sets in order, detectors in the manifest's order.
fn detector_table(agg: &Aggregates, sets: &[&'static str], spec: &SummarySpec) -> PolarsResult<DataFrame> {
    let nd = agg.detectors.len();
    let (mut set_col, mut det_col) = (Vec::new(), Vec::new());
    let (mut faulty, mut trials, mut isolation, mut at_deck) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for (s, set) in sets.iter().enumerate() {
        for (d, name) in agg.detectors.iter().enumerate() {
            let (units, faulty_units, per_trial) = &agg.per_detector[s * nd + d];
            set_col.push(*set);
            det_col.push(name.as_str());
            let f = faulty_units.clone();
            isolation.push(match spec.isolates {
                Isolates::Target => (f.correct, f.decided),
                Isolates::Kind => (units.correct, units.decided),
            });
            faulty.push(f);
            trials.push(per_trial.clone());
            at_deck.push(*set == DECK);
        }
    }
    let f: Vec<&Counts> = faulty.iter().collect();
    let mut columns = vec![
        Column::new("thresholds".into(), set_col),
        Column::new(col::DETECTOR.into(), det_col),
        Column::new("faulty_units".into(), f.iter().map(|c| c.units).collect::<Vec<u64>>()),
        Column::new("detected".into(), f.iter().map(|c| c.detected).collect::<Vec<u64>>()),
    ];
    columns.extend(rate_columns("pd", &f.iter().map(|c| (c.detected, c.flown(), true)).collect::<Vec<_>>()));
    columns.push(Column::new("isolation_decided".into(), isolation.iter().map(|i| i.1).collect::<Vec<u64>>()));
    columns.push(Column::new("isolated_correctly".into(), isolation.iter().map(|i| i.0).collect::<Vec<u64>>()));
    columns
        .extend(rate_columns("isolation_accuracy", &isolation.iter().map(|&(k, n)| (k, n, true)).collect::<Vec<_>>()));
    for (name, p) in [("delay_p50_s", 0.5), ("delay_p90_s", 0.9), ("delay_p99_s", 0.99)] {
        columns.push(Column::new(name.into(), f.iter().map(|c| c.delay.quantile(p)).collect::<Vec<_>>()));
    }
    columns.extend(extra_columns(&f, spec, &at_deck));
    columns.extend([
        Column::new("flights".into(), trials.iter().map(|c| c.units).collect::<Vec<u64>>()),
        Column::new("flights_failed".into(), trials.iter().map(|c| c.failed).collect::<Vec<u64>>()),
        Column::new("flights_diverged".into(), trials.iter().map(|c| c.diverged).collect::<Vec<u64>>()),
        Column::new("flights_with_false_alarm".into(), trials.iter().map(|c| c.false_alarms).collect::<Vec<u64>>()),
    ]);
    columns.extend(rate_columns("pfa", &trials.iter().map(|c| (c.false_alarms, c.flown(), true)).collect::<Vec<_>>()));
    DataFrame::new_infer_height(columns)
}

/// `confusion.csv`: detector (manifest order) x truth x isolated (`none`: nothing named).
fn confusion_table(agg: &Aggregates, names: &Names) -> PolarsResult<DataFrame> {
    let mut rows: Vec<(usize, Option<&str>, Option<&str>, u64)> =
        agg.confusion.iter().map(|(&(d, t, i), &n)| (d, names.name(t as u64), names.name(i as u64), n)).collect();
    rows.sort_by(|a, b| (a.0, a.1, a.2.is_none(), a.2).cmp(&(b.0, b.1, b.2.is_none(), b.2)));
    let mut truth_total: HashMap<(usize, Option<&str>), u64> = HashMap::new();
    for r in &rows {
        *truth_total.entry((r.0, r.1)).or_insert(0) += r.3;
    }
    DataFrame::new_infer_height(vec![
        Column::new(col::DETECTOR.into(), rows.iter().map(|r| agg.detectors[r.0].as_str()).collect::<Vec<_>>()),
        Column::new("truth".into(), rows.iter().map(|r| r.1).collect::<Vec<_>>()),
        Column::new(col::ISOLATED.into(), rows.iter().map(|r| r.2.unwrap_or(col::NO_FAULT)).collect::<Vec<_>>()),
        Column::new("units".into(), rows.iter().map(|r| r.3).collect::<Vec<u64>>()),
        Column::new(
            "share_of_truth".into(),
            rows.iter().map(|r| r.3 as f64 / truth_total[&(r.0, r.1)] as f64).collect::<Vec<f64>>(),
        ),
    ])
}

/// Smallest fault (by magnitude: |size|, or |factor - 1| for gain) whose size bin has Pd >= 0.9 (point
/// estimate, and with the Wilson lower bound >= 0.9), per (thresholds, detector, kind, target). A gain
/// whose bins are already deviations (`units` says [`unit::GAIN_DEVIATION_BINS`]) is ordered by them.
fn min_detectable(curves: &DataFrame, units: &std::collections::BTreeMap<String, String>) -> PolarsResult<DataFrame> {
    let s = |n: &str| curves.column(n).and_then(|c| c.str().cloned());
    let (set, det, kind, target) = (s("thresholds")?, s(col::DETECTOR)?, s(col::KIND)?, s(col::TARGET)?);
    let size = curves.column(col::SIZE_BIN)?.f64()?.clone();
    let pd = curves.column("pd")?.f64()?.clone();
    let lo = curves.column("pd_lo")?.f64()?.clone();
    type Key = (String, String, String, String);
    // Per key: (magnitude, size) of the smallest qualifying bin, point estimate and lower bound.
    let mut rows: Vec<(Key, Option<(f64, f64)>, Option<(f64, f64)>)> = Vec::new();
    for i in 0..curves.height() {
        let (Some(k), Some(o), Some(sz)) = (kind.get(i), target.get(i), size.get(i)) else { continue };
        if pd.get(i).is_none() {
            continue; // fault-free, or nothing flown
        }
        let key: Key =
            (set.get(i).unwrap_or_default().into(), det.get(i).unwrap_or_default().into(), k.into(), o.into());
        let idx = match rows.iter().position(|r| r.0 == key) {
            Some(p) => p,
            None => {
                rows.push((key, None, None));
                rows.len() - 1
            }
        };
        let factor_bins = k == "gain" && units.get(k).is_none_or(|u| u != unit::GAIN_DEVIATION_BINS);
        let magnitude = if factor_bins { (sz - 1.0).abs() } else { sz.abs() };
        let better = |cur: Option<(f64, f64)>| cur.is_none_or(|(m, _)| magnitude < m);
        if pd.get(i).is_some_and(|p| p >= 0.9) && better(rows[idx].1) {
            rows[idx].1 = Some((magnitude, sz));
        }
        if lo.get(i).is_some_and(|p| p >= 0.9) && better(rows[idx].2) {
            rows[idx].2 = Some((magnitude, sz));
        }
    }
    let key = |f: fn(&Key) -> &String| rows.iter().map(|r| f(&r.0).clone()).collect::<Vec<_>>();
    DataFrame::new_infer_height(vec![
        Column::new("thresholds".into(), key(|k| &k.0)),
        Column::new(col::DETECTOR.into(), key(|k| &k.1)),
        Column::new(col::KIND.into(), key(|k| &k.2)),
        Column::new(col::TARGET.into(), key(|k| &k.3)),
        Column::new("min_size_pd90".into(), rows.iter().map(|r| r.1.map(|x| x.1)).collect::<Vec<_>>()),
        Column::new("min_size_pd90_lower_bound".into(), rows.iter().map(|r| r.2.map(|x| x.1)).collect::<Vec<_>>()),
    ])
}

/// Appends `size_unit`, the unit of each row's fault size (and `size_bin`, `min_size_pd90`), from the
/// manifest's units per fault kind: last, so that `check`'s key columns (those before `trials`) stay.
fn with_size_unit(df: &mut DataFrame, units: &std::collections::BTreeMap<String, String>) -> PolarsResult<()> {
    let kinds = df.column(col::KIND)?.str()?.clone();
    let unit: Vec<Option<&str>> = kinds.iter().map(|k| k.and_then(|k| units.get(k)).map(String::as_str)).collect();
    df.with_column(Column::new("size_unit".into(), unit))?;
    Ok(())
}

/// Appends `<centre>_lo` and `<centre>_hi`, the edges of the size bin whose centre is in column
/// `centre`, from the manifest's bins per fault kind: the bin with that centre (to rounding), or the
/// value itself where the size was listed or fixed (or the folder predates recorded bins). Last, as
/// [`with_size_unit`].
fn with_bin_edges(
    df: &mut DataFrame,
    centre: &str,
    bins: &crate::engine::scenario::deck::SizeBins,
) -> PolarsResult<()> {
    let kinds = df.column(col::KIND)?.str()?.clone();
    let centres = df.column(centre)?.f64()?.clone();
    let edges: Vec<Option<[f64; 2]>> = (kinds.iter().zip(centres.iter()))
        .map(|(kind, c)| {
            let c = c?;
            let of_kind = kind.and_then(|k| bins.get(k)).map(Vec::as_slice).unwrap_or_default();
            let near = |e: &&[f64; 2]| (0.5 * (e[0] + e[1]) - c).abs() <= 1e-9 * (e[1] - e[0]).abs().max(1e-300);
            Some(of_kind.iter().find(near).copied().unwrap_or([c, c]))
        })
        .collect();
    for (side, name) in [(0, "lo"), (1, "hi")] {
        let values: Vec<Option<f64>> = edges.iter().map(|e| e.map(|e| e[side])).collect();
        df.with_column(Column::new(format!("{centre}_{name}").into(), values))?;
    }
    Ok(())
}

/// What `run`, `summarize` and `merge` print: the thresholds (kinds with a statistic), per threshold set
/// and detector Pd, isolation, delay and Pfa with the kind's printed aggregates, a classifier's
/// confusion matrices, warnings and the files written.
pub fn print(spec: &SummarySpec, s: &Summary) {
    if let Some((thresholds, source)) = &s.thresholds {
        println!("  thresholds: {source}");
        for t in thresholds {
            let (lo, hi) = wilson(t.whole_false_alarms, t.calibration_units, Z95);
            let list = |v: &[f64]| {
                let named = s.statistics.iter().zip(v).map(|(n, v)| format!("{n} {}", significant(*v)));
                named.collect::<Vec<_>>().join(", ")
            };
            let (label, trials) = match s.set {
                Some(VALIDATION) => ("applied", "this run's trials"),
                _ => ("calibrated", "the calibration trials"),
            };
            let rate = t.whole_false_alarms as f64 / t.calibration_units.max(1) as f64;
            let per_hour = t.unit_duration_s.map_or(String::new(), |d| {
                let h = |p: f64| per_flight_hour(p, d);
                format!(
                    ", per flight hour {:.4} [{:.4}, {:.4}] (the hour's {d} s segments taken as independent)",
                    h(rate),
                    h(lo),
                    h(hi)
                )
            });
            println!(
                "    {}: {label} [{}] (deck [{}]); Pfa achieved {}/{} = {rate:.4} [{lo:.4}, {hi:.4}] on {trials}{per_hour}",
                t.detector,
                list(&t.whole),
                list(&t.deck),
                t.whole_false_alarms,
                t.calibration_units,
            );
        }
        crate::engine::results::tails::print_tails(&s.tails);
    }
    let t = Table(&s.detectors);
    let (sets, names, units, flights) =
        (t.strs("thresholds"), t.strs(col::DETECTOR), t.u64s("faulty_units"), t.u64s("flights"));
    let (pd, iso, pfa) = (t.rates("pd"), t.rates("isolation_accuracy"), t.rates("pfa"));
    let delay = t.delays("delay_p50_s", "delay_p90_s");
    let own: Vec<Vec<f64>> = spec.printed.iter().map(|(_, c)| t.f64s(c)).collect();
    println!("  per detector, paired over the same trials (summary.csv for groups, comparison.csv for the tests):");
    let mut header = format!(
        "    {:<10} {:<16} {:>7} {:<21} {:<21} {:>14} {:>7} {:<21}",
        "thresholds",
        "detector",
        "faulty",
        "Pd [95 % CI]",
        "isolated [95 % CI]",
        "delay p50/p90",
        "flights",
        "Pfa [95 % CI]"
    );
    for (h, _) in spec.printed {
        header.push_str(&format!(" {h:>12}"));
    }
    println!("{header}");
    for i in 0..names.len() {
        let mut line = format!(
            "    {:<10} {:<16} {:>7} {:<21} {:<21} {:>14} {:>7} {:<21}",
            sets[i], names[i], units[i], pd[i], iso[i], delay[i], flights[i], pfa[i]
        );
        for v in &own {
            line.push_str(&if v[i].is_nan() { format!(" {:>12}", "-") } else { format!(" {:>12.3}", v[i]) });
        }
        println!("{line}");
    }
    if spec.isolates == Isolates::Kind {
        let c = Table(&s.confusion);
        let (det, truth, isolated, n) =
            (c.strs(col::DETECTOR), c.strs("truth"), c.strs(col::ISOLATED), c.u64s("units"));
        let mut classes: Vec<&str> = truth.iter().map(String::as_str).collect();
        classes.sort_unstable();
        classes.dedup();
        let mut detectors: Vec<&String> = Vec::new();
        for d in &det {
            if !detectors.contains(&d) {
                detectors.push(d);
            }
        }
        for name in detectors {
            println!("  confusion ({name}): rows the true class, columns the class named: {}", classes.join(" / "));
            for class in &classes {
                let row: Vec<String> = classes
                    .iter()
                    .map(|p| {
                        let k = (0..det.len())
                            .find(|&i| det[i] == **name && truth[i] == *class && isolated[i] == *p)
                            .map_or(0, |i| n[i]);
                        format!("{k:>6}")
                    })
                    .collect();
                println!("    {class:<8} {}", row.join(" "));
            }
        }
    }
    for w in &s.warnings {
        println!("  warning: {w}");
    }
    println!("  wrote {} in {}", s.files.join(", "), s.out_dir.display());
}

/// A threshold with four significant digits, in scientific notation when it is very small or large.
fn significant(v: f64) -> String {
    if v != 0.0 && (v.abs() < 1e-3 || v.abs() >= 1e5) { format!("{v:.3e}") } else { format!("{v:.4}") }
}

/// Summaries of hand-made records for the kinds' tests: written, summarised and read back.
#[cfg(test)]
pub mod hand_made {
    use polars::prelude::*;

    use crate::engine::method::Method;
    use crate::engine::results::summary_spec::SummarySpec;
    use crate::engine::results::tables::read_summary;
    use crate::engine::run::runner::{Manifest, write_parquet};

    /// A results folder with `trials.parquet` from hand-made rows and the tables `summarize` wrote.
    pub struct Summarized {
        pub dir: tempfile::TempDir,
        pub summary: DataFrame,
    }

    /// The manifest of a hand-made run of `method`: `trials` trials flown by `detectors`.
    pub fn manifest(method: &Method, trials: u64, detectors: &[&str]) -> Manifest {
        Manifest {
            kind: method.kind.into(),
            trials,
            detectors: detectors.iter().map(|d| d.to_string()).collect(),
            ..Manifest::unstarted()
        }
    }

    impl Summarized {
        /// [`Summarized::new`] under [`manifest`], by `method`'s summary.
        pub fn of(records: DataFrame, method: &Method, trials: u64, detectors: &[&str]) -> Self {
            Summarized::new(records, manifest(method, trials, detectors), &method.summary)
        }

        /// Writes `records` under `manifest` (its rows and completeness set here), summarises them by
        /// `spec` and reads `summary.csv` back.
        pub fn new(mut records: DataFrame, manifest: Manifest, spec: &SummarySpec) -> Self {
            let dir = tempfile::tempdir().unwrap();
            write_parquet(&mut records, &dir.path().join("trials.parquet")).unwrap();
            Manifest { rows: records.height() as u64, complete: true, ..manifest }.write(dir.path()).unwrap();
            super::summarize(dir.path(), spec, None).unwrap();
            let summary = read_summary(&dir.path().join("summary.csv")).unwrap();
            Summarized { dir, summary }
        }

        pub fn table(&self, name: &str) -> DataFrame {
            read_summary(&self.dir.path().join(name)).unwrap()
        }

        fn text(&self, column: &str, i: usize) -> Option<String> {
            self.summary.column(column).unwrap().str().unwrap().get(i).map(String::from)
        }

        /// The row of `detector` and fault kind `kind` at the deck's thresholds (one per pair in these tests).
        pub fn row(&self, detector: &str, kind: &str) -> usize {
            let at = |i: usize, c: &str, v: &str| self.text(c, i).as_deref() == Some(v);
            (0..self.summary.height())
                .find(|&i| at(i, "thresholds", "deck") && at(i, "detector", detector) && at(i, "kind", kind))
                .unwrap_or_else(|| panic!("no row {detector}/{kind}: {}", self.summary))
        }

        pub fn count(&self, column: &str, row: usize) -> Option<u64> {
            self.summary.column(column).unwrap().cast(&DataType::UInt64).unwrap().u64().unwrap().get(row)
        }

        pub fn value(&self, column: &str, row: usize) -> Option<f64> {
            self.summary.column(column).unwrap().cast(&DataType::Float64).unwrap().f64().unwrap().get(row)
        }

        /// `column` at `row` is `want` to rounding (a median, an interpolated quantile).
        pub fn assert_close(&self, column: &str, row: usize, want: f64) {
            let got = self.value(column, row);
            assert!(got.is_some_and(|g| (g - want).abs() < 1e-12), "{column} row {row}: {got:?}, want {want}");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::scenario::deck::Factor;

    /// A gain's smallest detectable fault: by `|factor - 1|` where the bins are factors (0.9 is missed,
    /// 1.3 is nearer 1 than 0.6), by the bin itself where the bins are already deviations (the
    /// accelerometer's: every bin detected, the smallest wins).
    #[test]
    fn a_gains_smallest_detectable_bin_follows_what_its_bins_are() {
        let curves = |bins: [f64; 3], pd: [f64; 3]| {
            df!(
                "thresholds" => ["deck"; 3],
                col::DETECTOR => ["d"; 3],
                col::KIND => ["gain"; 3],
                col::TARGET => ["x"; 3],
                col::SIZE_BIN => bins,
                "pd" => pd,
                "pd_lo" => pd,
            )
            .unwrap()
        };
        let smallest = |df: &DataFrame, units: &std::collections::BTreeMap<String, String>| {
            let m = min_detectable(df, units).unwrap();
            m.column("min_size_pd90").unwrap().f64().unwrap().get(0)
        };
        let factors = curves([0.6, 0.9, 1.3], [1.0, 0.5, 1.0]);
        let none = Default::default();
        assert_eq!(smallest(&factors, &none), Some(1.3));
        let deviations = curves([0.0917, 0.175, 0.2583], [1.0, 1.0, 1.0]);
        let units = [("gain".to_string(), unit::GAIN_DEVIATION_BINS.to_string())].into();
        assert_eq!(smallest(&deviations, &units), Some(0.0917));
        assert_eq!(smallest(&deviations, &none), Some(0.2583), "read as factors, the largest is nearest 1");
    }

    /// Each centre gets the edges of its kind's bin: a range of 2-20 in 3 bins, a second population of
    /// the same kind in 0-1 in 2 bins, a listed size (its own bin), a kind without bins, a fault-free row.
    #[test]
    fn bin_centres_get_their_kinds_edges() {
        let mut bins = Default::default();
        Factor::Range { lo: 2.0, hi: 20.0, bins: 3 }.add_bins_to("bias", &mut bins);
        Factor::Range { lo: 0.0, hi: 1.0, bins: 2 }.add_bins_to("bias", &mut bins);
        Factor::Values(vec![4.0]).add_bins_to("drift", &mut bins);
        assert_eq!(bins["bias"], vec![[2.0, 8.0], [8.0, 14.0], [14.0, 20.0], [0.0, 0.5], [0.5, 1.0]]);
        assert!(!bins.contains_key("drift"), "a listed size has no bins");
        let mut df = df!(
            col::KIND => ["bias", "bias", "bias", "drift", "stuck", "none"],
            col::SIZE_BIN => [Some(11.0), Some(0.25), Some(17.0 + 1e-14), Some(4.0), Some(3.0), None],
        )
        .unwrap();
        with_bin_edges(&mut df, col::SIZE_BIN, &bins).unwrap();
        let edges = |name: &str| df.column(name).unwrap().f64().unwrap().iter().collect::<Vec<_>>();
        assert_eq!(edges("size_bin_lo"), [Some(8.0), Some(0.0), Some(14.0), Some(4.0), Some(3.0), None]);
        assert_eq!(edges("size_bin_hi"), [Some(14.0), Some(0.5), Some(20.0), Some(4.0), Some(3.0), None]);
    }
}

/// The rates a precision stop can watch (`fdimc run --precision`), as `summary.csv` names them.
pub const PRECISION_RATES: [&str; 3] = ["pd", "pfa", "isolation_accuracy"];

/// Where a run stands against a precision: every watched rate of every group of `summary.csv` at the
/// deck's thresholds, its 95 % Wilson half-width. Fed chunk by chunk in trial order, so where it is met
/// depends only on the deck and seed.
pub struct PrecisionMonitor {
    agg: Option<Aggregates<'static>>,
    spec: &'static SummarySpec,
    half_width: f64,
    rates: Vec<&'static str>,
}

/// The widest watched rate of a [`PrecisionMonitor`] and how many rates are still wider than asked.
#[derive(Debug, Clone, PartialEq)]
pub struct PrecisionStatus {
    /// The group (`detector seed, kind bias, target q_rad_s, size bin 3, ...`), the rate, `k`, `n` and
    /// its half-width.
    pub widest: Option<(String, &'static str, u64, u64, f64)>,
    pub wider: usize,
    pub rates: usize,
}

impl PrecisionStatus {
    pub fn met(&self) -> bool {
        self.wider == 0 && self.rates > 0
    }

    pub fn describe(&self) -> String {
        match &self.widest {
            Some((group, rate, k, n, h)) => format!("{rate} of {group}: {k}/{n}, half-width {h:.4}"),
            None => "no rate yet".into(),
        }
    }
}

impl PrecisionMonitor {
    /// Watches `rates` (names of [`PRECISION_RATES`]; all of them when empty) of a kind's groups for a
    /// 95 % half-width of at most `half_width`.
    pub fn new(spec: &'static SummarySpec, half_width: f64, rates: &[String]) -> Result<PrecisionMonitor, String> {
        if !(half_width > 0.0 && half_width < 0.5) {
            return Err(format!("--precision {half_width}: allowed 0 < W < 0.5 (a 95 % half-width)"));
        }
        let mut watched = Vec::new();
        for r in rates {
            let known = PRECISION_RATES.iter().find(|k| **k == r.as_str()).ok_or_else(|| {
                format!(
                    "--precision-rates: {r:?} is not a rate of summary.csv; allowed: {}",
                    PRECISION_RATES.join(", ")
                )
            })?;
            watched.push(*known);
        }
        if watched.is_empty() {
            watched = PRECISION_RATES.to_vec();
        }
        Ok(PrecisionMonitor { agg: None, spec, half_width, rates: watched })
    }

    pub fn status(&self) -> PrecisionStatus {
        let mut status = PrecisionStatus { widest: None, wider: 0, rates: 0 };
        let Some(agg) = &self.agg else { return status };
        for (key, c) in &agg.groups {
            for &rate in &self.rates {
                let (k, n) = match rate {
                    "pd" if c.faulty => (c.detected, c.flown()),
                    "pfa" => (c.false_alarms, c.flown()),
                    "isolation_accuracy" => (c.correct, c.decided),
                    _ => continue,
                };
                if n == 0 {
                    continue;
                }
                let (lo, hi) = wilson(k, n, Z95);
                let h = 0.5 * (hi - lo);
                status.rates += 1;
                status.wider += (h > self.half_width) as usize;
                if status.widest.as_ref().is_none_or(|w| h > w.4) {
                    status.widest = Some((group_name(agg, key), rate, k, n, h));
                }
            }
        }
        status
    }
}

impl crate::engine::run::runner::StopRule for PrecisionMonitor {
    fn start(&mut self, manifest: &crate::engine::run::runner::Manifest) -> Result<(), RunError> {
        self.agg = Some(Aggregates::new(self.spec, vec![DECK], &manifest.detectors));
        Ok(())
    }

    fn add(&mut self, chunk: &DataFrame, file: &Path) -> Result<(), RunError> {
        match &mut self.agg {
            Some(agg) => agg.add_slice(chunk, file, None),
            None => Err(RunError::Internal("precision monitor fed before the run started".into())),
        }
    }

    fn enough(&self) -> bool {
        self.status().met()
    }

    fn outcome(&self) -> crate::engine::run::runner::PrecisionOutcome {
        let status = self.status();
        crate::engine::run::runner::PrecisionOutcome {
            half_width: self.half_width,
            rates: self.rates.iter().map(|r| r.to_string()).collect(),
            met: status.met(),
            watched: status.rates,
            wider: status.wider,
            widest: status.describe(),
        }
    }
}

/// A group key as text: `detector seed, kind bias, target q_rad_s, size bin 3, noise bin 1, ...`.
fn group_name(agg: &Aggregates, key: &[u64]) -> String {
    let names = &agg.names;
    let mut parts = vec![format!("detector {}", agg.detectors[key[1] as usize])];
    parts.push(format!("kind {}", names.name(key[2]).unwrap_or("-")));
    parts.push(format!("target {}", names.name(key[3]).unwrap_or("-")));
    let labels =
        ["size bin", "noise bin", "parameter-error bin"].into_iter().chain(agg.spec.extra_keys.iter().copied());
    for (label, &v) in labels.zip(&key[4..]) {
        if let Some(x) = number_of(v) {
            parts.push(format!("{label} {}", significant(x)));
        }
    }
    parts.join(", ")
}
