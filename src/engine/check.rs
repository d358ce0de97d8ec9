//! Baseline comparison: is any group's detection rate (or classification recall) lower, or false-alarm
//! rate higher, than the committed baseline's, beyond chance?
//!
//! Groups are matched on the key columns the summaries have: (thresholds, detector, kind, output,
//! size_bin, noise_bin, param_error_bin) for detection filters, (detector, kind, surface, size_bin,
//! noise_bin, param_error_bin) for surface banks, (detector, kind, sensors, size_bin, noise_bin,
//! gust_bin) for air-data detectors, (thresholds, detector, kind, engine, size_bin, noise_bin, gust_bin)
//! for thrust-loss detectors. Flights that did not run to the end (design failures,
//! or `failed` surface flights) are left out of both rates.
//! Each rate is tested one-sided with a pooled two-proportion z-test (continuity-corrected) at level
//! `alpha / m`, m the number of tests (Bonferroni), so a study with hundreds of groups does not flag
//! regressions by chance. Groups in only one of the two summaries are reported, not failed.

use std::collections::HashMap;

use polars::prelude::*;

use crate::engine::intervals::p_lower;
use crate::engine::runner::RunError;
use crate::engine::schema::col;

const KEYS: [&str; 12] = [
    "thresholds",
    col::DETECTOR,
    col::KIND,
    col::OUTPUT,
    "surface",
    "sensors",
    "engine",
    "axis",
    col::SIZE_BIN,
    col::NOISE_BIN,
    col::PARAM_ERROR_BIN,
    "gust_bin",
];

/// Per summary kind, the column counting the groups' trials that did not run to the end.
const FAILURE_COLUMNS: [&str; 2] = ["design_failures", "failed"];

/// One group's counts.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Counts {
    designed: u64,
    detected: u64,
    false_alarms: u64,
    /// Trials classified correctly (classification studies).
    correct: Option<u64>,
    faulty: bool,
}

/// A rate that dropped (or a false-alarm rate that rose) beyond chance.
#[derive(Debug, Clone, PartialEq)]
pub struct Regression {
    pub group: String,
    pub what: &'static str,
    pub baseline: (u64, u64),
    pub current: (u64, u64),
    pub p_value: f64,
}

impl std::fmt::Display for Regression {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let rate = |(k, n): (u64, u64)| if n == 0 { f64::NAN } else { k as f64 / n as f64 };
        write!(
            f,
            "{}: {} {:.4} ({}/{}) -> {:.4} ({}/{}), p = {:.2e}",
            self.group,
            self.what,
            rate(self.baseline),
            self.baseline.0,
            self.baseline.1,
            rate(self.current),
            self.current.0,
            self.current.1,
            self.p_value
        )
    }
}

#[derive(Debug, Default)]
pub struct Verdict {
    pub regressions: Vec<Regression>,
    pub compared_groups: usize,
    pub tests: usize,
    pub only_in_baseline: Vec<String>,
    pub only_in_current: Vec<String>,
}

fn groups(df: &DataFrame) -> PolarsResult<HashMap<String, Counts>> {
    let keys: Vec<&str> = KEYS.iter().copied().filter(|k| df.column(k).is_ok()).collect();
    let failure_column = FAILURE_COLUMNS.iter().find(|k| df.column(k).is_ok()).copied().unwrap_or(FAILURE_COLUMNS[0]);
    let df = df
        .clone()
        .lazy()
        .with_columns(keys.iter().map(|k| polars::prelude::col(*k).cast(DataType::String)).collect::<Vec<_>>())
        .collect()?;
    let key_cols: Vec<StringChunked> =
        keys.iter().map(|k| df.column(k).and_then(|c| c.str().cloned())).collect::<PolarsResult<_>>()?;
    let kind_cols = df.column(col::KIND)?.str()?.clone();
    let u = |n: &str| -> PolarsResult<UInt64Chunked> { Ok(df.column(n)?.cast(&DataType::UInt64)?.u64()?.clone()) };
    let (trials, failures, detected, fa) = (u("trials")?, u(failure_column)?, u("detected")?, u("false_alarms")?);
    // Classification studies also count the trials classified correctly.
    let correct = df.column("correct").is_ok().then(|| u("correct")).transpose()?;
    let normal = "normal";
    let mut map = HashMap::with_capacity(df.height());
    for i in 0..df.height() {
        let key: Vec<&str> = key_cols.iter().map(|c| c.get(i).unwrap_or("")).collect();
        let kind = kind_cols.get(i).unwrap_or("");
        map.insert(
            key.join(" | "),
            Counts {
                designed: trials.get(i).unwrap_or(0) - failures.get(i).unwrap_or(0),
                detected: detected.get(i).unwrap_or(0),
                false_alarms: fa.get(i).unwrap_or(0),
                correct: correct.as_ref().map(|c| c.get(i).unwrap_or(0)),
                faulty: kind != col::NO_FAULT && kind != normal,
            },
        );
    }
    Ok(map)
}

/// Compares `current` against `baseline` summaries at family-wise level `alpha`.
pub fn compare(current: &DataFrame, baseline: &DataFrame, alpha: f64) -> Result<Verdict, RunError> {
    let bad = |e: PolarsError| {
        RunError::Invalid(format!("summary without the expected columns ({e}): use an fdimc summary.csv"))
    };
    let cur = groups(current).map_err(bad)?;
    let base = groups(baseline).map_err(bad)?;
    let mut verdict = Verdict::default();
    let mut keys: Vec<&String> = base.keys().collect();
    keys.sort();
    let mut candidates = Vec::new();
    for key in keys {
        let b = base[key];
        let Some(&c) = cur.get(key) else {
            verdict.only_in_baseline.push(key.clone());
            continue;
        };
        verdict.compared_groups += 1;
        if let (Some(bc), Some(cc)) = (b.correct, c.correct) {
            candidates.push((
                key.clone(),
                "classification recall",
                (bc, b.designed),
                (cc, c.designed),
                p_lower(cc, c.designed, bc, b.designed),
            ));
        }
        if b.faulty {
            candidates.push((
                key.clone(),
                "detection probability",
                (b.detected, b.designed),
                (c.detected, c.designed),
                p_lower(c.detected, c.designed, b.detected, b.designed),
            ));
        }
        let quiet = |x: Counts| (x.designed - x.false_alarms, x.designed);
        let (bq, cq) = (quiet(b), quiet(c));
        candidates.push((
            key.clone(),
            "false-alarm rate",
            (b.false_alarms, b.designed),
            (c.false_alarms, c.designed),
            p_lower(cq.0, cq.1, bq.0, bq.1),
        ));
    }
    let mut only_current: Vec<String> = cur.keys().filter(|k| !base.contains_key(*k)).cloned().collect();
    only_current.sort();
    verdict.only_in_current = only_current;
    verdict.tests = candidates.len();
    let level = alpha / candidates.len().max(1) as f64;
    for (group, what, baseline, current, p_value) in candidates {
        if p_value < level {
            verdict.regressions.push(Regression { group, what, baseline, current, p_value });
        }
    }
    Ok(verdict)
}
