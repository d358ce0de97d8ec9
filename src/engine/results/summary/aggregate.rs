//! Everything the slices of `trials.parquet` add to: interned key names, a unit's result, the counts and
//! quantile sketches of a group, the kind's own columns of a slice, and the aggregates of a whole run
//! (groups, per detector, confusion, paired units).

use std::collections::HashMap;
use std::path::Path;

use polars::prelude::*;

use crate::engine::results::schema::col;
use crate::engine::results::summary_spec::{Extra, Isolates, SummarySpec};
use crate::engine::results::tables::{bool_col, f64_col, numbers, str_col, u64_col};
use crate::engine::results::thresholds::{DECK, DetectorThresholds, RecordedStatistics};
use crate::engine::run::runner::{RunError, pol};
use crate::engine::stats::paired::{PairedUnits, UnitOutcome};
use crate::engine::stats::quantiles::Quantiles;

/// Distinct strings of the key columns; keys hold their indices.
#[derive(Default)]
pub(super) struct Names {
    pub(super) ids: HashMap<String, u32>,
    pub(super) names: Vec<String>,
}

pub(super) const NO_NAME: u32 = u32::MAX;
pub(super) const NO_NUMBER: u64 = u64::MAX;

impl Names {
    pub(super) fn id(&mut self, s: Option<&str>) -> u32 {
        let Some(s) = s else { return NO_NAME };
        if let Some(&id) = self.ids.get(s) {
            return id;
        }
        self.names.push(s.to_string());
        self.ids.insert(s.to_string(), (self.names.len() - 1) as u32);
        (self.names.len() - 1) as u32
    }

    pub(super) fn name(&self, id: u64) -> Option<&str> {
        (id != NO_NAME as u64).then(|| self.names[id as usize].as_str())
    }
}

pub(super) fn number_key(v: Option<f64>) -> u64 {
    v.filter(|v| !v.is_nan()).map_or(NO_NUMBER, f64::to_bits)
}

pub(super) fn number_of(key: u64) -> Option<f64> {
    (key != NO_NUMBER).then(|| f64::from_bits(key))
}

/// One unit's result at one threshold set.
pub(super) struct Unit {
    pub(super) flown: bool,
    pub(super) faulty: bool,
    pub(super) diverged: bool,
    /// The trial's truth diverged (the unit is not flown either).
    pub(super) truth_diverged: bool,
    pub(super) false_alarm: bool,
    pub(super) detected: bool,
    pub(super) delay_s: Option<f64>,
    /// The first alarm after the onset came after the detection window (then not detected).
    pub(super) late_alarm: bool,
    pub(super) isolated: Option<u32>,
    /// The deck's time to hazard of this unit's fault (`time_to_hazard_s`), if it gives one.
    pub(super) hazard_s: Option<f64>,
    /// Whether what was isolated is the truth; `None` when nothing was, or when the truth is not
    /// something the detector can name (an actuator fault for a detector that names sensors): such a
    /// unit is not an isolation decision.
    pub(super) correct: Option<bool>,
}

/// Counts and sketches of a set of units.
#[derive(Clone, Default)]
pub(super) struct Counts {
    pub(super) units: u64,
    pub(super) failed: u64,
    pub(super) diverged: u64,
    pub(super) truth_diverged: u64,
    pub(super) false_alarms: u64,
    pub(super) detected: u64,
    pub(super) late_alarms: u64,
    pub(super) decided: u64,
    pub(super) correct: u64,
    pub(super) faulty: bool,
    pub(super) delay: Quantiles,
    /// Faulty units that flew with a time to hazard, and those of them detected within it.
    pub(super) hazard_units: u64,
    pub(super) detected_in_time: u64,
    /// The units' time to hazard when they share one (NaN when they differ).
    pub(super) hazard_s: Option<f64>,
    /// Per [`Extra`]: the count of the counting ones.
    pub(super) extra_counts: Vec<u64>,
    /// Per [`Extra`]: the values of the quantile ones.
    pub(super) extra_values: Vec<Quantiles>,
}

impl Counts {
    pub(super) fn new(extras: usize) -> Self {
        Counts { extra_counts: vec![0; extras], extra_values: vec![Quantiles::default(); extras], ..Default::default() }
    }

    /// Adds a unit; `extras` (per [`Extra`], see [`Extras::row`]) only at the deck's thresholds.
    pub(super) fn add(&mut self, u: &Unit, extras: Option<&[f64]>, spec: &SummarySpec) {
        self.units += 1;
        self.faulty |= u.faulty;
        self.diverged += u.diverged as u64;
        // A diverged truth is a failed unit too: counted in both, in no rate.
        self.truth_diverged += u.truth_diverged as u64;
        if !u.flown {
            self.failed += 1;
            return;
        }
        self.false_alarms += u.false_alarm as u64;
        self.late_alarms += (u.faulty && u.late_alarm) as u64;
        if u.faulty && u.detected {
            self.detected += 1;
            if let Some(d) = u.delay_s {
                self.delay.push(d);
            }
        }
        if let (true, Some(t)) = (u.faulty, u.hazard_s) {
            self.hazard_units += 1;
            self.detected_in_time += (u.detected && u.delay_s.is_some_and(|d| d <= t)) as u64;
            self.hazard_s = Some(self.shared_hazard(t));
        }
        if let Some(correct) = u.correct {
            self.decided += 1;
            self.correct += correct as u64;
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

    pub(super) fn merge(&mut self, o: &Counts) {
        self.units += o.units;
        self.failed += o.failed;
        self.diverged += o.diverged;
        self.truth_diverged += o.truth_diverged;
        self.false_alarms += o.false_alarms;
        self.detected += o.detected;
        self.late_alarms += o.late_alarms;
        self.decided += o.decided;
        self.correct += o.correct;
        self.faulty |= o.faulty;
        self.delay.merge(&o.delay);
        self.hazard_units += o.hazard_units;
        self.detected_in_time += o.detected_in_time;
        if let Some(t) = o.hazard_s {
            self.hazard_s = Some(self.shared_hazard(t));
        }
        for (a, b) in self.extra_counts.iter_mut().zip(&o.extra_counts) {
            *a += b;
        }
        for (a, b) in self.extra_values.iter_mut().zip(&o.extra_values) {
            a.merge(b);
        }
    }

    pub(super) fn flown(&self) -> u64 {
        self.units - self.failed
    }

    /// The time to hazard of these units with one of `t` added: `t` if they share it, else NaN.
    fn shared_hazard(&self, t: f64) -> f64 {
        match self.hazard_s {
            Some(s) if s.to_bits() != t.to_bits() => f64::NAN,
            _ => t,
        }
    }
}

/// The kind's own columns of one slice, as numbers per row and [`Extra`].
pub(super) struct Extras {
    pub(super) values: Vec<Vec<f64>>,
}

impl Extras {
    pub(super) fn read(df: &DataFrame, spec: &SummarySpec, file: &Path) -> Result<Extras, RunError> {
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

    pub(super) fn row(&self, i: usize, out: &mut Vec<f64>) {
        out.clear();
        out.extend(self.values.iter().map(|v| v[i]));
    }
}

/// Everything the slices add to.
pub(super) struct Aggregates<'s> {
    pub(super) spec: &'s SummarySpec,
    pub(super) sets: Vec<&'static str>,
    pub(super) detectors: Vec<String>,
    pub(super) names: Names,
    pub(super) groups: HashMap<Vec<u64>, Counts>,
    /// Per (set, detector): every unit, the faulty units, and every trial once (its first unit).
    pub(super) per_detector: Vec<(Counts, Counts, Counts)>,
    /// (detector, truth, isolated) at the deck's thresholds.
    pub(super) confusion: HashMap<(usize, u32, u32), u64>,
    pub(super) pairs: Vec<PairedUnits>,
    /// The current trial and how many units each detector has had in it.
    pub(super) trial: Option<u64>,
    pub(super) units_seen: Vec<usize>,
    /// Each varied parameter error's bins, and per (set, detector, fault or none, parameter, its bin)
    /// the units: `parameter_errors.csv`, which derivative drives the misses.
    pub(super) parameters: Vec<ParameterBins>,
    pub(super) by_parameter: HashMap<Vec<u64>, Counts>,
    /// The deck's times to hazard (the manifest's `time_to_hazard_s`).
    pub(super) hazard_times: crate::engine::scenario::deck::HazardTimes,
}

/// How one parameter error's recorded values (`perr_<name>`) are binned for `parameter_errors.csv`:
/// each value its own bin where the deck lists a few values, else equal bins over the values' span.
#[derive(Debug, Clone)]
pub(super) struct ParameterBins {
    pub(super) name: String,
    pub(super) column: String,
    /// `None`: each value is its own bin; else (low, high, bins): equal bins over the range.
    pub(super) span: Option<(f64, f64, usize)>,
}

/// Equal bins of a parameter error drawn from a range whose manifest does not give the deck's (more
/// distinct values than [`LISTED_VALUES_MAX`]: a range).
pub(super) const PARAMETER_BINS: usize = 5;
pub(super) const LISTED_VALUES_MAX: usize = 12;

impl ParameterBins {
    fn label(&self, v: f64) -> f64 {
        match self.span {
            None => v,
            Some((lo, hi, bins)) => {
                let u = if hi > lo { (v - lo) / (hi - lo) } else { 0.0 };
                let bin = ((u * bins as f64) as usize).min(bins - 1);
                crate::engine::scenario::draws::bin_centre(lo, hi, bin, bins)
            }
        }
    }
}

impl<'s> Aggregates<'s> {
    pub(super) fn new(spec: &'s SummarySpec, sets: Vec<&'static str>, detectors: &[String]) -> Self {
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
            parameters: Vec::new(),
            by_parameter: HashMap::new(),
            hazard_times: Default::default(),
        }
    }

    /// Adds the rows of one slice; `calibrated`: the whole-detector thresholds per detector and the
    /// slice's recorded statistics, for kinds that record statistics.
    pub(super) fn add_slice(
        &mut self,
        df: &DataFrame,
        file: &Path,
        calibrated: Option<(&[DetectorThresholds], &RecordedStatistics)>,
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
        // Runs of an fdimc before the column have none (their diverged truths are in `diverged`).
        let truth_diverged = match df.column(col::TRUTH_DIVERGED) {
            Ok(_) => Some(bool_col(df, col::TRUTH_DIVERGED, file)?),
            Err(_) => None,
        };
        let false_alarm = bool_col(df, col::FALSE_ALARM, file)?;
        let detected = bool_col(df, col::DETECTED, file)?;
        let delay = f64_col(df, col::DELAY_S, file)?;
        let late = f64_col(df, col::LATE_ALARM_S, file)?;
        let isolated = str_col(df, col::ISOLATED, file)?;
        let correct = bool_col(df, col::ISOLATED_CORRECTLY, file)?;
        let noise_bin = f64_col(df, col::NOISE_BIN, file)?;
        let perr_bin = f64_col(df, col::PARAM_ERROR_BIN, file)?;
        let extra_keys =
            spec.extra_keys.iter().map(|k| numbers(df, k, file)).collect::<Result<Vec<Vec<f64>>, RunError>>()?;
        let extras = Extras::read(df, spec, file)?;
        let paired_medians =
            spec.paired_medians.iter().map(|c| numbers(df, c, file)).collect::<Result<Vec<Vec<f64>>, RunError>>()?;

        let parameter_values =
            (self.parameters.iter().map(|p| f64_col(df, &p.column, file))).collect::<Result<Vec<_>, RunError>>()?;
        let parameter_ids: Vec<u32> = self.parameters.iter().map(|p| self.names.id(Some(&p.name))).collect();
        let (fault_id, none_id) = (self.names.id(Some("all faults")), self.names.id(Some(col::NO_FAULT)));
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
            let hazard_s = match (faulty, self.hazard_times.is_empty()) {
                (true, false) => crate::engine::scenario::deck::time_to_hazard(
                    &self.hazard_times,
                    kind.get(i).unwrap_or_default(),
                    target.get(i).unwrap_or_default(),
                ),
                _ => None,
            };
            extras.row(i, &mut extra_row);
            for s in 0..self.sets.len() {
                let set = self.sets[s];
                let unit = if set == DECK {
                    let iso = isolated.get(i).map(|n| self.names.id(Some(n)));
                    Unit {
                        flown,
                        faulty,
                        diverged: diverged.get(i) == Some(true),
                        truth_diverged: truth_diverged.is_some_and(|c| c.get(i) == Some(true)),
                        false_alarm: false_alarm.get(i) == Some(true),
                        detected: detected.get(i) == Some(true),
                        delay_s: delay.get(i),
                        late_alarm: late.get(i).is_some(),
                        isolated: iso,
                        hazard_s,
                        correct: correct.get(i),
                    }
                } else {
                    let (thresholds, profiles) = calibrated.expect("a calibrated set has thresholds");
                    let (fa, alarm) = profiles.alarms_at(i, &thresholds[d].whole, faulty);
                    Unit {
                        flown,
                        faulty,
                        diverged: diverged.get(i) == Some(true),
                        truth_diverged: truth_diverged.is_some_and(|c| c.get(i) == Some(true)),
                        false_alarm: fa,
                        detected: alarm.is_some(),
                        delay_s: alarm.map(|a| a - onset.get(i).unwrap_or(f64::NAN)),
                        late_alarm: faulty && profiles.late_alarm(i, &thresholds[d].whole).is_some(),
                        isolated: None,
                        hazard_s,
                        correct: None,
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
                for (j, (p, values)) in self.parameters.iter().zip(&parameter_values).enumerate() {
                    let Some(v) = values.get(i) else { continue };
                    let k = vec![
                        s as u64,
                        d as u64,
                        (if faulty { fault_id } else { none_id }) as u64,
                        parameter_ids[j] as u64,
                        number_key(Some(p.label(v))),
                    ];
                    self.by_parameter.entry(k).or_insert_with(|| Counts::new(spec.extras.len())).add(&unit, None, spec);
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
                        isolated: unit.correct == Some(true),
                        false_alarm: unit.false_alarm,
                        paired,
                    },
                );
            }
        }
        Ok(())
    }
}
