//! Variance-based global sensitivity (Sobol indices) of a study's outcomes to its sampled factors:
//! `fdimc sensitivity DECK`.
//!
//! **Design** ([`crate::engine::scenario::design`]; Saltelli's pick-freeze scheme). For each part of the study, faulty trials and fault-free
//! trials, two independent matrices `A` and `B` of `base_samples` rows draw every sampled factor of the
//! deck (one uniform per factor and row, from the row's own scenario stream, so rows are independent
//! and the bootstrap over rows is valid); `A_B^i` is `A` with factor `i`'s column from `B`. The trials
//! are the rows of `A`, `B`, `A_B^1`, .., `A_B^k` in that order, part after part: `base_samples (k + 2)`
//! trials per part. A listed factor (fault kind, output, listed noise scales or parameter errors) is
//! drawn uniformly from its list instead of cycling on the grid.
//!
//! **The noise realisation is a factor of its own** (`noise_realisation`): the sensor and process
//! noise of a row come from the random streams of its `A` row (of its `B` row in `B` and in `A_B^noise`),
//! so its index is the share of the outcome's variance that no deck factor explains, by itself
//! (`S1`) and with its interactions (`ST`).
//!
//! **Outcomes**, per detector, from the core columns of `trials.parquet`: on faulty trials `pd`
//! (detected), `isolation` (isolated correctly; a miss counts as wrong) and `delay_s` (the detection
//! delay, a miss counted as the time left in the flight after the onset, so every row has a value); on
//! fault-free trials `pfa` (any alarm). A base row whose trials any detector failed to fly (a design
//! failure) is left out of that detector's indices, with all its `A_B^i` rows. At the deck's
//! thresholds by default; with another run's `thresholds.csv` (kinds that record their statistics) at
//! those, from the recorded pre-onset maxima and first-passage profiles, without `isolation` (the
//! direction at an alarm is recorded at the deck's thresholds only).
//!
//! **Estimators**, with `f` the outcome and `V` the variance of `f(A)` and `f(B)` together:
//! - first order (Saltelli et al. 2010): `S1_i = mean(f(B) (f(A_B^i) - f(A))) / V`;
//! - total order (Jansen 1999): `ST_i = mean((f(A) - f(A_B^i))^2) / (2 V)`.
//!
//! For binary outcomes Jansen's `ST_i` is the probability that changing factor `i` alone flips the
//! outcome, over `2 V`: never negative, and the estimator of smallest variance among the usual ones
//! (Saltelli et al. 2010, table 2). Saltelli's `S1_i` takes `f(B)` as the weight, which subtracts no
//! squared mean and stays unbiased for small indices, where the older `f(A) f(A_B^i) - f0^2` forms
//! lose the index in the rounding of two large terms. Intervals: the 2.5 and 97.5 percentiles of the
//! indices recomputed on `bootstrap` resamples of the base rows (with replacement).

use std::path::Path;

use polars::prelude::*;
use rand::RngExt;
use rand::SeedableRng;
use rand::rngs::ChaCha8Rng;

use crate::engine::results::schema::col;
use crate::engine::results::tables::{
    bool_col, column_names, complete_run, f64_col, numbers, slices, str_col, u64_col,
};
use crate::engine::results::thresholds::{RecordedStatistics, SLICE_ROWS, read_thresholds};
use crate::engine::run::output::write_table;
use crate::engine::run::runner::{Manifest, RunError, pol};
use crate::engine::scenario::design::Part;

/// First- and total-order indices of each factor, from the outcome on `A`, `B` and each `A_B^i` over
/// the base rows `rows` (repeats allowed: a bootstrap resample). `None` when the outcome does not vary.
pub fn indices(fa: &[f64], fb: &[f64], fab: &[Vec<f64>], rows: &[usize]) -> Option<(Vec<f64>, Vec<f64>)> {
    let n = rows.len() as f64;
    let mean = rows.iter().map(|&j| fa[j] + fb[j]).sum::<f64>() / (2.0 * n);
    let variance = rows.iter().map(|&j| (fa[j] - mean).powi(2) + (fb[j] - mean).powi(2)).sum::<f64>() / (2.0 * n);
    if variance <= 0.0 {
        return None;
    }
    let s1 = fab.iter().map(|f| rows.iter().map(|&j| fb[j] * (f[j] - fa[j])).sum::<f64>() / n / variance).collect();
    let st =
        fab.iter().map(|f| rows.iter().map(|&j| (fa[j] - f[j]).powi(2)).sum::<f64>() / (2.0 * n) / variance).collect();
    Some((s1, st))
}

/// The indices with 95 % bootstrap percentile intervals, per factor.
#[derive(Debug, Clone, PartialEq)]
pub struct Estimate {
    pub s1: f64,
    pub s1_interval: (f64, f64),
    pub st: f64,
    pub st_interval: (f64, f64),
}

/// Confidence of the intervals of `sensitivity.csv`.
pub const LEVEL: f64 = 0.95;

/// [`indices`] on every base row, with percentile intervals at confidence `level` from `bootstrap`
/// resamples of the rows drawn from `rng`, and how many of the resamples gave indices (one on which
/// the outcome does not vary has none, and the intervals are then over the others); `None` when the
/// outcome does not vary over the rows.
pub fn estimate(
    fa: &[f64],
    fb: &[f64],
    fab: &[Vec<f64>],
    bootstrap: u64,
    level: f64,
    rng: &mut ChaCha8Rng,
) -> Option<(Vec<Estimate>, u64)> {
    let n = fa.len();
    let all: Vec<usize> = (0..n).collect();
    let (s1, st) = indices(fa, fb, fab, &all)?;
    let k = fab.len();
    let (mut s1_boot, mut st_boot) = (vec![Vec::new(); k], vec![Vec::new(); k]);
    let mut rows = vec![0; n];
    let mut resamples = 0;
    for _ in 0..bootstrap {
        rows.iter_mut().for_each(|j| *j = rng.random_range(0..n));
        if let Some((s, t)) = indices(fa, fb, fab, &rows) {
            resamples += 1;
            for i in 0..k {
                s1_boot[i].push(s[i]);
                st_boot[i].push(t[i]);
            }
        }
    }
    let interval = |v: &mut Vec<f64>, at: f64| -> (f64, f64) {
        v.sort_by(f64::total_cmp);
        let tail = (1.0 - level) / 2.0;
        (percentile(v, tail).unwrap_or(at), percentile(v, 1.0 - tail).unwrap_or(at))
    };
    let estimates = (0..k)
        .map(|i| Estimate {
            s1: s1[i],
            s1_interval: interval(&mut s1_boot[i], s1[i]),
            st: st[i],
            st_interval: interval(&mut st_boot[i], st[i]),
        })
        .collect();
    Some((estimates, resamples))
}

/// The `p` quantile of sorted values, linear between order statistics.
fn percentile(sorted: &[f64], p: f64) -> Option<f64> {
    let last = sorted.len().checked_sub(1)?;
    let at = p * last as f64;
    let (lo, frac) = (at.floor() as usize, at - at.floor());
    Some(sorted[lo] + frac * (sorted[(lo + 1).min(last)] - sorted[lo]))
}

/// The outcomes of each part, in `sensitivity.csv`'s order.
fn outcomes(part: &Part) -> &'static [&'static str] {
    if part.fault_free { &["pfa"] } else { &["pd", "isolation", "delay_s"] }
}

/// Computes the indices of the complete sensitivity run in `dir` and writes `sensitivity.csv` and
/// `sensitivity.parquet`; returns the table.
/// `thresholds`: another run's `thresholds.csv`, whose whole-detector thresholds replace the deck's.
pub fn analyse(dir: &Path, thresholds: Option<&Path>) -> Result<DataFrame, RunError> {
    let (manifest, path) = complete_run(dir)?;
    let design = manifest.sensitivity.clone().ok_or_else(|| {
        RunError::Invalid(format!("{}: not a sensitivity run (made by `fdimc sensitivity`)", dir.display()))
    })?;
    let per_detector = read_rows(&manifest, &path, thresholds)?;
    let source = thresholds.map_or("deck".to_string(), |file| format!("from {}", file.display()));
    let mut table = Table::default();
    let n = design.base_samples as usize;
    let mut first = 0usize;
    for (p, part) in design.parts.iter().enumerate() {
        let k = part.factors.len();
        for (d, detector) in manifest.detectors.iter().enumerate() {
            let rows = &per_detector[d];
            // Base rows whose every trial was flown.
            let flown: Vec<usize> =
                (0..n).filter(|&j| (0..k + 2).all(|b| rows.failure[first + b * n + j].is_none())).collect();
            for (o, outcome) in outcomes(part).iter().enumerate() {
                if thresholds.is_some() && *outcome == "isolation" {
                    continue;
                }
                let value = |t: usize| rows.outcome(outcome, t, manifest.trial_duration_s);
                let pick = |block: usize| -> Vec<f64> { flown.iter().map(|&j| value(first + block * n + j)).collect() };
                let (fa, fb) = (pick(0), pick(1));
                let fab: Vec<Vec<f64>> = (0..k).map(|i| pick(2 + i)).collect();
                // The resamples of each (part, detector, outcome) from a stream of their own.
                let mut rng = ChaCha8Rng::seed_from_u64(manifest.seed ^ BOOTSTRAP_KEY);
                rng.set_stream(((p * 64 + d) * 8 + o) as u64);
                let all: Vec<f64> = fa.iter().chain(&fb).copied().collect();
                let mean = all.iter().sum::<f64>() / all.len().max(1) as f64;
                let variance = all.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / all.len().max(1) as f64;
                let note = too_few(outcome, &all);
                let estimates =
                    if note.is_some() { None } else { estimate(&fa, &fb, &fab, design.bootstrap, LEVEL, &mut rng) };
                let sum_s1 = estimates.as_ref().map(|(e, _)| e.iter().map(|e| e.s1).sum::<f64>());
                for (i, f) in part.factors.iter().enumerate() {
                    let e = estimates.as_ref().map(|(e, _)| &e[i]);
                    table.push(Row {
                        outcome,
                        part: part.name(),
                        detector,
                        factor: &f.name,
                        estimate: e,
                        sum_s1,
                        resamples: estimates.as_ref().map(|(_, r)| *r),
                        base_samples: flown.len() as u64,
                        trials: (flown.len() * (k + 2)) as u64,
                        mean,
                        variance,
                        note: note.clone(),
                        thresholds: &source,
                    });
                }
            }
        }
        first += n * (k + 2);
    }
    let mut df = table.frame().map_err(pol(dir))?;
    write_table(&mut df, &dir.join("sensitivity.csv"))?;
    write_table(&mut df, &dir.join("sensitivity.parquet"))?;
    Ok(df)
}

/// Rows of the rarer value a binary outcome needs among the `A` and `B` rows before its indices mean
/// anything: with fewer, most bootstrap resamples hold one or two events and the intervals are noise.
pub const MIN_RARER_ROWS: usize = 10;

/// Why an outcome gets no indices: it does not vary, or (binary outcomes) its rarer value is too rare.
fn too_few(outcome: &str, values: &[f64]) -> Option<String> {
    if values.is_empty() {
        return Some("no base row was flown by every trial of its design".into());
    }
    if values.iter().all(|v| *v == values[0]) {
        return Some(format!("the outcome is {} on every row: no variance to share", values[0]));
    }
    if outcome == "delay_s" {
        return None;
    }
    let ones = values.iter().filter(|v| **v == 1.0).count();
    let rarer = ones.min(values.len() - ones);
    (rarer < MIN_RARER_ROWS).then(|| {
        format!(
            "{rarer} of the {} A and B rows hold the rarer value: too few for indices (needs {MIN_RARER_ROWS}; raise --base-samples)",
            values.len()
        )
    })
}

/// The key of the bootstrap streams ("sensitiv" in ASCII), apart from every trial's.
const BOOTSTRAP_KEY: u64 = 0x7365_6e73_6974_6976;

/// Each detector's rows of the complete run in `path`, read 16,384 rows at a time (only the columns the
/// outcomes need), so memory holds the outcomes, not the records. `thresholds`: another run's
/// `thresholds.csv`, whose whole-detector thresholds replace the deck's (the alarms are re-read from the
/// recorded statistics, as `fdimc summarize --thresholds` does).
fn read_rows(manifest: &Manifest, path: &Path, thresholds: Option<&Path>) -> Result<Vec<DetectorRows>, RunError> {
    let trials = manifest.trials as usize;
    if manifest.rows != manifest.trials * manifest.detectors.len() as u64 {
        return Err(RunError::Invalid(format!(
            "{}: {} rows for {} trials x {} detectors: sensitivity needs one row per trial and detector",
            path.display(),
            manifest.rows,
            trials,
            manifest.detectors.len()
        )));
    }
    let mut columns: Vec<String> = [
        col::TRIAL,
        col::DETECTOR,
        col::FAILURE,
        col::DETECTED,
        col::FALSE_ALARM,
        col::ISOLATED_CORRECTLY,
        col::DELAY_S,
        col::ONSET_S,
        col::FAULT_FREE,
    ]
    .map(String::from)
    .to_vec();
    let whole = match thresholds {
        None => None,
        Some(file) => {
            let statistics: Vec<String> = column_names(path)?
                .iter()
                .filter_map(|c| c.strip_prefix(col::PRE_MAX_PREFIX))
                .map(str::to_string)
                .collect();
            if statistics.is_empty() {
                return Err(RunError::Invalid(format!(
                    "--thresholds {}: the {} run in {} records no detection statistic to apply thresholds to",
                    file.display(),
                    manifest.kind,
                    path.display()
                )));
            }
            let (_, whole) = read_thresholds(file)?.for_run(file, &manifest.detectors, statistics.len())?;
            for s in &statistics {
                columns.extend([col::pre_max(s), col::fp_t(s), col::fp_v(s)]);
            }
            Some((statistics, whole))
        }
    };
    let mut out: Vec<DetectorRows> = manifest
        .detectors
        .iter()
        .map(|_| DetectorRows {
            failure: vec![None; trials],
            detected: vec![false; trials],
            false_alarm: vec![false; trials],
            isolated_correctly: vec![false; trials],
            delay_s: vec![None; trials],
            onset_s: vec![None; trials],
        })
        .collect();
    for records in slices(path, manifest.rows as usize, SLICE_ROWS, &columns) {
        let records = records?;
        add_rows(&records, manifest, path, &mut out)?;
        if let Some((statistics, whole)) = &whole {
            at_thresholds(&records, manifest, path, statistics, whole, &mut out)?;
        }
    }
    Ok(out)
}

/// Replaces the alarms of `records`' rows by those at each detector's whole-detector thresholds `whole`,
/// from the recorded `statistics`.
fn at_thresholds(
    records: &DataFrame,
    manifest: &Manifest,
    path: &Path,
    statistics: &[String],
    whole: &[Vec<f64>],
    rows: &mut [DetectorRows],
) -> Result<(), RunError> {
    let (trial, detector) = (u64_col(records, col::TRIAL, path)?, str_col(records, col::DETECTOR, path)?);
    let fault_free = bool_col(records, col::FAULT_FREE, path)?;
    let recorded = RecordedStatistics::read(records, statistics, manifest.detection_window_s, path)?;
    for r in 0..records.height() {
        let (t, name) = (trial.get(r).unwrap_or(0) as usize, detector.get(r).unwrap_or(""));
        let d = manifest.detectors.iter().position(|n| n == name).unwrap_or(0);
        let out = &mut rows[d];
        let (false_alarm, alarm) = recorded.alarms_at(r, &whole[d], fault_free.get(r) != Some(true));
        out.false_alarm[t] = false_alarm;
        out.detected[t] = alarm.is_some();
        out.delay_s[t] = alarm.map(|a| a - out.onset_s[t].unwrap_or(f64::NAN));
    }
    Ok(())
}

/// One detector's rows of a sensitivity run, by trial: what the outcomes read.
struct DetectorRows {
    failure: Vec<Option<String>>,
    detected: Vec<bool>,
    false_alarm: Vec<bool>,
    isolated_correctly: Vec<bool>,
    delay_s: Vec<Option<f64>>,
    onset_s: Vec<Option<f64>>,
}

impl DetectorRows {
    fn outcome(&self, outcome: &str, t: usize, duration_s: Option<f64>) -> f64 {
        match outcome {
            "pfa" => f64::from(self.false_alarm[t]),
            "pd" => f64::from(self.detected[t]),
            "isolation" => f64::from(self.isolated_correctly[t]),
            // A miss is censored at the end of the flight.
            _ => match (self.delay_s[t], self.detected[t]) {
                (Some(d), true) => d,
                _ => duration_s.unwrap_or(f64::NAN) - self.onset_s[t].unwrap_or(0.0),
            },
        }
    }
}

/// Adds `records`' rows to each detector's rows, indexed by trial; refuses a row outside the design.
fn add_rows(records: &DataFrame, manifest: &Manifest, path: &Path, out: &mut [DetectorRows]) -> Result<(), RunError> {
    let trials = manifest.trials as usize;
    let (trial, detector) = (u64_col(records, col::TRIAL, path)?, str_col(records, col::DETECTOR, path)?);
    let failure = str_col(records, col::FAILURE, path)?;
    let (detected, false_alarm) = (bool_col(records, col::DETECTED, path)?, bool_col(records, col::FALSE_ALARM, path)?);
    let isolated = bool_col(records, col::ISOLATED_CORRECTLY, path)?;
    let (delay, onset) = (f64_col(records, col::DELAY_S, path)?, f64_col(records, col::ONSET_S, path)?);
    for r in 0..records.height() {
        let (t, name) = (trial.get(r).unwrap_or(u64::MAX) as usize, detector.get(r).unwrap_or(""));
        let Some(d) = manifest.detectors.iter().position(|n| n == name).filter(|_| t < trials) else {
            return Err(RunError::Invalid(format!(
                "{}: row (trial {t}, detector {name:?}) is not in the run's design",
                path.display()
            )));
        };
        let rows = &mut out[d];
        rows.failure[t] = failure.get(r).map(String::from);
        rows.detected[t] = detected.get(r).unwrap_or(false);
        rows.false_alarm[t] = false_alarm.get(r).unwrap_or(false);
        rows.isolated_correctly[t] = isolated.get(r).unwrap_or(false);
        rows.delay_s[t] = delay.get(r);
        rows.onset_s[t] = onset.get(r);
    }
    Ok(())
}

struct Row<'a> {
    outcome: &'a str,
    part: &'a str,
    detector: &'a str,
    factor: &'a str,
    estimate: Option<&'a Estimate>,
    sum_s1: Option<f64>,
    resamples: Option<u64>,
    base_samples: u64,
    trials: u64,
    mean: f64,
    variance: f64,
    note: Option<String>,
    thresholds: &'a str,
}

/// `sensitivity.csv`'s columns while rows are added.
#[derive(Default)]
struct Table {
    outcome: Vec<String>,
    part: Vec<String>,
    detector: Vec<String>,
    factor: Vec<String>,
    s1: Vec<Option<f64>>,
    s1_lo: Vec<Option<f64>>,
    s1_hi: Vec<Option<f64>>,
    st: Vec<Option<f64>>,
    st_lo: Vec<Option<f64>>,
    st_hi: Vec<Option<f64>>,
    sum_s1: Vec<Option<f64>>,
    bootstrap_resamples: Vec<Option<u64>>,
    base_samples: Vec<u64>,
    trials: Vec<u64>,
    outcome_mean: Vec<f64>,
    outcome_variance: Vec<f64>,
    note: Vec<Option<String>>,
    thresholds: Vec<String>,
}

impl Table {
    fn push(&mut self, r: Row) {
        self.outcome.push(r.outcome.into());
        self.part.push(r.part.into());
        self.detector.push(r.detector.into());
        self.factor.push(r.factor.into());
        let e = r.estimate;
        self.s1.push(e.map(|e| e.s1));
        self.s1_lo.push(e.map(|e| e.s1_interval.0));
        self.s1_hi.push(e.map(|e| e.s1_interval.1));
        self.st.push(e.map(|e| e.st));
        self.st_lo.push(e.map(|e| e.st_interval.0));
        self.st_hi.push(e.map(|e| e.st_interval.1));
        self.sum_s1.push(r.sum_s1);
        self.bootstrap_resamples.push(r.resamples);
        self.base_samples.push(r.base_samples);
        self.trials.push(r.trials);
        self.outcome_mean.push(r.mean);
        self.outcome_variance.push(r.variance);
        self.note.push(r.note);
        self.thresholds.push(r.thresholds.into());
    }

    fn frame(self) -> PolarsResult<DataFrame> {
        DataFrame::new_infer_height(vec![
            Column::new("outcome".into(), self.outcome),
            Column::new("detector".into(), self.detector),
            Column::new("factor".into(), self.factor),
            Column::new("s1".into(), self.s1),
            Column::new("s1_lo".into(), self.s1_lo),
            Column::new("s1_hi".into(), self.s1_hi),
            Column::new("st".into(), self.st),
            Column::new("st_lo".into(), self.st_lo),
            Column::new("st_hi".into(), self.st_hi),
            Column::new("sum_s1".into(), self.sum_s1),
            Column::new("bootstrap_resamples".into(), self.bootstrap_resamples),
            Column::new("part".into(), self.part),
            Column::new("base_samples".into(), self.base_samples),
            Column::new("trials".into(), self.trials),
            Column::new("outcome_mean".into(), self.outcome_mean),
            Column::new("outcome_variance".into(), self.outcome_variance),
            Column::new("thresholds".into(), self.thresholds),
            Column::new("note".into(), self.note),
        ])
    }
}

/// One outcome and detector's rows of `sensitivity.csv`, as read back.
pub struct IndexBlock {
    pub outcome: String,
    pub detector: String,
    pub mean: f64,
    pub base_samples: u64,
    pub sum_s1: f64,
    /// Each factor's indices, in the table's order; `Err(why)`: the outcome got none.
    pub factors: Result<Vec<(String, Estimate)>, String>,
}

/// The blocks of `sensitivity.csv` (`df`, read from `file`), in the table's order.
pub fn index_blocks(df: &DataFrame, file: &Path) -> Result<Vec<IndexBlock>, RunError> {
    let (outcome, detector, factor) =
        (str_col(df, "outcome", file)?, str_col(df, "detector", file)?, str_col(df, "factor", file)?);
    // As numbers whatever their type: read back from the CSV, a column of whole numbers or of nulls only
    // comes as integers or strings. Null: NaN.
    let num = |name: &str| numbers(df, name, file);
    let (s1, s1_lo, s1_hi, st, st_lo, st_hi) =
        (num("s1")?, num("s1_lo")?, num("s1_hi")?, num("st")?, num("st_lo")?, num("st_hi")?);
    let (sum_s1, mean, base) = (num("sum_s1")?, num("outcome_mean")?, num("base_samples")?);
    let note = str_col(df, "note", file)?;
    let mut out = Vec::new();
    let mut r = 0;
    while r < df.height() {
        let key = (outcome.get(r), detector.get(r));
        let end = (r..df.height()).find(|&i| (outcome.get(i), detector.get(i)) != key).unwrap_or(df.height());
        let factors = match s1[r].is_nan() {
            true => Err(note.get(r).unwrap_or("the outcome does not vary").to_string()),
            false => Ok((r..end)
                .map(|i| {
                    let estimate = Estimate {
                        s1: s1[i],
                        s1_interval: (s1_lo[i], s1_hi[i]),
                        st: st[i],
                        st_interval: (st_lo[i], st_hi[i]),
                    };
                    (factor.get(i).unwrap_or("").to_string(), estimate)
                })
                .collect()),
        };
        out.push(IndexBlock {
            outcome: key.0.unwrap_or("").to_string(),
            detector: key.1.unwrap_or("").to_string(),
            mean: mean[r],
            base_samples: base[r] as u64,
            sum_s1: sum_s1[r],
            factors,
        });
        r = end;
    }
    Ok(out)
}

/// Prints the indices, one block per outcome and detector, factors by total index.
pub fn print(df: &DataFrame) -> Result<(), RunError> {
    for b in index_blocks(df, Path::new("sensitivity.csv"))? {
        println!("\n{} of detector {} (mean {:.4}, {} base rows):", b.outcome, b.detector, b.mean, b.base_samples);
        let mut factors = match b.factors {
            Ok(f) => f,
            Err(why) => {
                println!("  no indices: {why}");
                continue;
            }
        };
        println!("  {:<24} {:>22} {:>22}", "factor", "S1 [95 %]", "ST [95 %]");
        factors.sort_by(|a, b| b.1.st.total_cmp(&a.1.st));
        let show = |v: f64, (lo, hi): (f64, f64)| format!("{v:.3} [{lo:.3}, {hi:.3}]");
        for (name, e) in factors {
            println!("  {:<24} {:>22} {:>22}", name, show(e.s1, e.s1_interval), show(e.st, e.st_interval));
        }
        let sum = b.sum_s1;
        println!("  sum of S1 {sum:.3}: interactions hold about {:.3} of the variance", 1.0 - sum);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::scenario::design::{Design, DesignFactor, Slot};
    use std::f64::consts::PI;

    /// Ishigami's function (a = 7, b = 0.1) of three factors uniform on [-pi, pi].
    fn ishigami(x: &[f64]) -> f64 {
        x[0].sin() + 7.0 * x[1].sin().powi(2) + 0.1 * x[2].powi(4) * x[0].sin()
    }

    /// The three factors of a design on dimensions 0, 1, 2 and no noise realisation.
    fn three_factor_design(base_samples: u64) -> Design {
        let factors = (0..3).map(|d| DesignFactor { name: format!("x{}", d + 1), slot: Slot::Dim(d) }).collect();
        Design { base_samples, bootstrap: 1000, parts: vec![Part { fault_free: false, factors }] }
    }

    /// `f` on every trial of the design seeded `seed` (its unit draws mapped to [-pi, pi]), then the
    /// estimates. The six intervals of a design are a family: each at `1 - 0.05 / 6` (Bonferroni), so
    /// that all six hold the truth with at least 95 % probability, as one 95 % interval does.
    fn estimate_on_design(design: &Design, seed: u64, f: impl Fn(&[f64]) -> f64) -> Vec<Estimate> {
        let n = design.base_samples as usize;
        let y: Vec<f64> = (0..design.trials())
            .map(|t| {
                let units = design.draws(seed, t, 3).dim_units;
                f(&units.iter().map(|u| -PI + 2.0 * PI * u).collect::<Vec<_>>())
            })
            .collect();
        let block = |b: usize| y[b * n..(b + 1) * n].to_vec();
        let fab: Vec<Vec<f64>> = (0..3).map(|i| block(2 + i)).collect();
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let (estimates, resamples) =
            estimate(&block(0), &block(1), &fab, design.bootstrap, 1.0 - 0.05 / 6.0, &mut rng).unwrap();
        assert_eq!(resamples, design.bootstrap, "a continuous outcome varies on every resample");
        estimates
    }

    /// A resample on which the outcome does not vary gives no indices, and the count says how many
    /// did: with one event among four base rows, exactly the resamples that drew its row (replayed
    /// here from the same stream; about 1 - (3/4)^4 = 68 % of them).
    #[test]
    fn resamples_without_variance_are_counted_out() {
        let (fa, fb, fab) = (vec![1.0, 0.0, 0.0, 0.0], vec![0.0; 4], vec![vec![0.0; 4]]);
        let (_, resamples) = estimate(&fa, &fb, &fab, 1000, LEVEL, &mut ChaCha8Rng::seed_from_u64(5)).unwrap();
        let mut replay = ChaCha8Rng::seed_from_u64(5);
        let with_the_event = (0..1000)
            .filter(|_| (0..4).map(|_| replay.random_range(0..4usize)).fold(false, |seen, j| seen | (j == 0)))
            .count();
        assert_eq!(resamples, with_the_event as u64);
        assert!((640..730).contains(&resamples), "{resamples}");
    }

    /// On four independent designs (seeds 1-4) of 8192 base rows, the family of six intervals holds the
    /// true indices on at least three (each family fails with probability at most 0.05, so this test
    /// fails by chance with probability below 0.015), and every interval is narrower than 0.1.
    fn assert_recovered(f: impl Fn(&[f64]) -> f64, s1: [f64; 3], st: [f64; 3], what: &str) {
        let design = three_factor_design(8192);
        let mut missed = Vec::new();
        for seed in 1..=4 {
            let estimates = estimate_on_design(&design, seed, &f);
            for (i, e) in estimates.iter().enumerate() {
                for (name, truth, (lo, hi), value) in
                    [("S1", s1[i], e.s1_interval, e.s1), ("ST", st[i], e.st_interval, e.st)]
                {
                    assert!(hi - lo < 0.1, "{what}, seed {seed}: {name} of x{} has the interval [{lo}, {hi}]", i + 1);
                    if !(lo <= truth && truth <= hi) {
                        missed.push((seed, format!("{name} of x{} = {truth} outside [{lo}, {hi}] ({value})", i + 1)));
                    }
                }
            }
        }
        let families_missed = (1..=4).filter(|s| missed.iter().any(|m| m.0 == *s)).count();
        assert!(families_missed <= 1, "{what}: {missed:?}");
    }

    /// Issue 49, item 4: the estimators against SALib 1.6.0's (`SALib.analyze.sobol.first_order` and
    /// `total_order`, the forms `sobol.analyze` calls), which share no code with fdimc, on the same design: 64 base rows of Ishigami's
    /// function whose A and B are additive recurrences `x = -pi + 2 pi frac((j + 1) alpha)`
    /// (`scripts/reference/sobol_salib.py` prints the numbers). To rounding: a wrong weight (`f(A)`
    /// for `f(B)`), a sample variance or a missing factor 2 is off in the second digit. (`sobol.analyze`
    /// itself first standardises the outputs, which moves S1's weight `f(B)` by their mean: another
    /// estimate of the same index, 0.2346 for x1 here.)
    #[test]
    fn sobol_estimators_match_salib() {
        let alpha_a = [2f64.sqrt() - 1.0, 3f64.sqrt() - 1.0, 5f64.sqrt() - 2.0];
        let alpha_b = [7f64.sqrt() - 2.0, 11f64.sqrt() - 3.0, 13f64.sqrt() - 3.0];
        let point = |j: usize, alphas: &[f64; 3]| -> Vec<f64> {
            alphas.iter().map(|a| -PI + 2.0 * PI * (((j + 1) as f64 * a) % 1.0)).collect()
        };
        let (mut fa, mut fb, mut fab) = (Vec::new(), Vec::new(), vec![Vec::new(); 3]);
        for j in 0..64 {
            let (a, b) = (point(j, &alpha_a), point(j, &alpha_b));
            fa.push(ishigami(&a));
            fb.push(ishigami(&b));
            for (i, f) in fab.iter_mut().enumerate() {
                let mut ab = a.clone();
                ab[i] = b[i];
                f.push(ishigami(&ab));
            }
        }
        let (s1, st) = indices(&fa, &fb, &fab, &(0..64).collect::<Vec<_>>()).unwrap();
        let salib_s1 = [2.284078592384746e-01, 5.016564859899527e-01, -1.114933922108651e-01];
        let salib_st = [2.707918334559673e-01, 4.222865927187757e-01, 2.167577061776181e-01];
        for i in 0..3 {
            assert!((s1[i] - salib_s1[i]).abs() < 1e-12, "S1 of x{}: {} vs SALib {}", i + 1, s1[i], salib_s1[i]);
            assert!((st[i] - salib_st[i]).abs() < 1e-12, "ST of x{}: {} vs SALib {}", i + 1, st[i], salib_st[i]);
        }
    }

    /// The analytic indices of Ishigami's function, a = 7, b = 0.1 (Saltelli et al. 2008, p. 179):
    /// S1 = 0.314, 0.442, 0; ST = 0.558, 0.442, 0.244.
    #[test]
    fn ishigami_indices_are_recovered_within_their_intervals() {
        let (a, b) = (7.0f64, 0.1f64);
        let pi4 = PI.powi(4);
        let v1 = 0.5 * (1.0 + b * pi4 / 5.0).powi(2);
        let v2 = a * a / 8.0;
        let v13 = b * b * PI.powi(8) * (1.0 / 18.0 - 1.0 / 50.0);
        let v = v1 + v2 + v13;
        let (s1, st) = ([v1 / v, v2 / v, 0.0], [(v1 + v13) / v, v2 / v, v13 / v]);
        assert!((s1[0] - 0.314).abs() < 5e-4 && (st[2] - 0.244).abs() < 5e-4, "{s1:?} {st:?}");
        assert_recovered(ishigami, s1, st, "Ishigami");
    }

    /// The thresholded (binary) Ishigami function `1[f(x) > 3.5]`, its indices by numerical integration
    /// on a 240-point midpoint grid per factor: S1_i = Var(P(Y | x_i)) / V, ST_i = E(p (1 - p)) / V with
    /// p = P(Y | all factors but x_i), V = P(Y) (1 - P(Y)).
    #[test]
    fn thresholded_ishigami_indices_are_recovered_within_their_intervals() {
        const G: usize = 240;
        let grid: Vec<f64> = (0..G).map(|i| -PI + 2.0 * PI * (i as f64 + 0.5) / G as f64).collect();
        let mut y = vec![false; G * G * G];
        for (i, x1) in grid.iter().enumerate() {
            for (j, x2) in grid.iter().enumerate() {
                for (k, x3) in grid.iter().enumerate() {
                    y[(i * G + j) * G + k] = ishigami(&[*x1, *x2, *x3]) > 3.5;
                }
            }
        }
        let at = |axis: usize, u: usize, v: usize, w: usize| -> bool {
            // (u = the factor's own index, v, w the other two in order)
            let idx = match axis {
                0 => [u, v, w],
                1 => [v, u, w],
                _ => [v, w, u],
            };
            y[(idx[0] * G + idx[1]) * G + idx[2]]
        };
        let p = y.iter().filter(|&&b| b).count() as f64 / y.len() as f64;
        let variance = p * (1.0 - p);
        let (mut s1, mut st) = ([0.0; 3], [0.0; 3]);
        for axis in 0..3 {
            let conditional: Vec<f64> = (0..G)
                .map(|u| (0..G * G).filter(|vw| at(axis, u, vw / G, vw % G)).count() as f64 / (G * G) as f64)
                .collect();
            s1[axis] = conditional.iter().map(|c| (c - p).powi(2)).sum::<f64>() / G as f64 / variance;
            st[axis] = (0..G * G)
                .map(|vw| {
                    let q = (0..G).filter(|&u| at(axis, u, vw / G, vw % G)).count() as f64 / G as f64;
                    q * (1.0 - q)
                })
                .sum::<f64>()
                / (G * G) as f64
                / variance;
        }
        assert_recovered(|x| f64::from(u8::from(ishigami(x) > 3.5)), s1, st, "thresholded Ishigami");
        // What the test is about: x3 matters only with x1, and more than its first-order index says.
        assert!(st[2] > s1[2] + 0.05, "{s1:?} {st:?}");
    }
}
