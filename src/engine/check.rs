//! Baseline comparison: is any group's detection probability or isolation accuracy lower, or
//! false-alarm rate higher, than the committed baseline's, beyond chance?
//!
//! Groups are matched on the key columns of the shared summary ([`super::summary`]): every column before
//! `trials` (thresholds, detector, kind, target, size, noise and parameter-error bins, and a kind's own
//! bins). Units that did not run to the end (`failed`) are left out of every rate.
//! Each rate is tested one-sided with a pooled two-proportion z-test (continuity-corrected) at level
//! `alpha / m`, m the number of tests (Bonferroni), so a study with hundreds of groups does not flag
//! regressions by chance. Groups in only one of the two summaries are reported, not failed.

use std::collections::HashMap;

use polars::prelude::*;

use crate::engine::intervals::p_lower;
use crate::engine::runner::RunError;

/// One group's counts.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Counts {
    flown: u64,
    detected: u64,
    false_alarms: u64,
    decided: u64,
    correct: u64,
    /// A group with a fault (its `pd` has a value).
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

/// Per group (its key columns: every column before `trials`, joined), its counts.
fn groups(df: &DataFrame) -> PolarsResult<HashMap<String, Counts>> {
    let names = df.get_column_names();
    let keys: Vec<&str> = names.iter().map(|n| n.as_str()).take_while(|n| *n != "trials").collect();
    if keys.len() == names.len() {
        polars_bail!(ColumnNotFound: "trials");
    }
    let key_cols: Vec<Column> =
        keys.iter().map(|k| df.column(k).and_then(|c| c.cast(&DataType::String))).collect::<PolarsResult<_>>()?;
    let key_cols: Vec<&StringChunked> = key_cols.iter().map(|c| c.str()).collect::<PolarsResult<_>>()?;
    let u = |n: &str| -> PolarsResult<UInt64Chunked> { Ok(df.column(n)?.cast(&DataType::UInt64)?.u64()?.clone()) };
    let (trials, failed, detected, fa) = (u("trials")?, u("failed")?, u("detected")?, u("false_alarms")?);
    let (decided, correct) = (u("isolation_decided")?, u("isolated_correctly")?);
    let pd = df.column("pd")?.cast(&DataType::Float64)?;
    let pd = pd.f64()?;
    let mut map = HashMap::with_capacity(df.height());
    for i in 0..df.height() {
        let key: Vec<String> =
            keys.iter().zip(&key_cols).map(|(name, c)| format!("{name}={}", c.get(i).unwrap_or("null"))).collect();
        map.insert(
            key.join(" "),
            Counts {
                flown: trials.get(i).unwrap_or(0) - failed.get(i).unwrap_or(0),
                detected: detected.get(i).unwrap_or(0),
                false_alarms: fa.get(i).unwrap_or(0),
                decided: decided.get(i).unwrap_or(0),
                correct: correct.get(i).unwrap_or(0),
                faulty: pd.get(i).is_some(),
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
        if b.faulty {
            candidates.push((
                key.clone(),
                "detection probability",
                (b.detected, b.flown),
                (c.detected, c.flown),
                p_lower(c.detected, c.flown, b.detected, b.flown),
            ));
        }
        if b.decided > 0 {
            candidates.push((
                key.clone(),
                "isolation accuracy",
                (b.correct, b.decided),
                (c.correct, c.decided),
                p_lower(c.correct, c.decided, b.correct, b.decided),
            ));
        }
        let quiet = |x: Counts| (x.flown - x.false_alarms, x.flown);
        let (bq, cq) = (quiet(b), quiet(c));
        candidates.push((
            key.clone(),
            "false-alarm rate",
            (b.false_alarms, b.flown),
            (c.false_alarms, c.flown),
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
