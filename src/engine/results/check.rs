//! Baseline comparison: is any group's detection probability or isolation accuracy lower, or
//! false-alarm rate higher, than the committed baseline's, beyond chance?
//!
//! Groups are matched on the key columns of the shared summary ([`crate::engine::results::summary`]): every column before
//! `trials` (thresholds, detector, kind, target, size, noise and parameter-error bins, and a kind's own
//! bins). Units that did not run to the end (`failed`) are left out of every rate.
//! Each rate is tested one-sided with a pooled two-proportion z-test (continuity-corrected) at level
//! `alpha / m`, m the number of tests (Bonferroni), so a study with hundreds of groups does not flag
//! regressions by chance. Groups in only one of the two summaries are reported, not failed.

use std::collections::HashMap;

use polars::prelude::*;

use crate::engine::results::thresholds::DECK;
use crate::engine::run::runner::RunError;
use crate::engine::stats::intervals::p_lower;

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
    /// What the comparison could not check (printed as warnings).
    pub notes: Vec<String>,
}

/// What a summary's calibrated rows (any threshold set but the deck's) were calibrated for: `Ok(None)`
/// without such rows; `Err(())` when the summary does not say (no `target_pfa` column: an older fdimc).
fn calibration_of(df: &DataFrame) -> Result<Option<(f64, Option<f64>)>, ()> {
    let Ok(sets) = df.column("thresholds").and_then(|c| c.str().cloned()) else { return Ok(None) };
    let calibrated: Vec<usize> = (0..df.height()).filter(|&i| sets.get(i).is_some_and(|s| s != DECK)).collect();
    let Some(&first) = calibrated.first() else { return Ok(None) };
    let number = |name: &str| df.column(name).ok().and_then(|c| c.cast(&DataType::Float64).ok());
    let target = number("target_pfa").ok_or(())?;
    let confidence = number("confidence");
    let value = |c: &Column| c.f64().ok().and_then(|c| c.get(first));
    Ok(value(&target).map(|t| (t, confidence.as_ref().and_then(value))))
}

/// What a summary's calibrated rows were calibrated for, (target Pfa, confidence), when it says.
pub fn calibration(df: &DataFrame) -> Option<(f64, Option<f64>)> {
    calibration_of(df).ok().flatten()
}

pub fn describe(c: Option<(f64, Option<f64>)>) -> String {
    match c {
        Some((p, Some(conf))) => format!("Pfa {p} with {conf} confidence"),
        Some((p, None)) => format!("Pfa {p}"),
        None => "no target".into(),
    }
}

/// Each row's group, named by its key columns (every column before `trials`): `detector=seed kind=bias ...`.
fn group_names(df: &DataFrame) -> PolarsResult<Vec<String>> {
    let names = df.get_column_names();
    let keys: Vec<&str> = names.iter().map(|n| n.as_str()).take_while(|n| *n != "trials").collect();
    if keys.len() == names.len() {
        polars_bail!(ColumnNotFound: "trials");
    }
    let key_cols: Vec<Column> =
        keys.iter().map(|k| df.column(k).and_then(|c| c.cast(&DataType::String))).collect::<PolarsResult<_>>()?;
    let key_cols: Vec<&StringChunked> = key_cols.iter().map(|c| c.str()).collect::<PolarsResult<_>>()?;
    Ok((0..df.height())
        .map(|i| {
            let key: Vec<String> =
                keys.iter().zip(&key_cols).map(|(name, c)| format!("{name}={}", c.get(i).unwrap_or("null"))).collect();
            key.join(" ")
        })
        .collect())
}

/// Refuses a baseline whose rates do not follow from its counts (a hand-edited `pd`, say): `check`
/// compares counts, so an edited rate would be silently ignored. Names the file, the row and its group.
pub fn consistent(df: &DataFrame, file: &std::path::Path) -> Result<(), RunError> {
    let bad = |e: PolarsError| RunError::Invalid(format!("{}: not an fdimc summary.csv ({e})", file.display()));
    let groups = group_names(df).map_err(bad)?;
    let u = |n: &str| -> PolarsResult<UInt64Chunked> { Ok(df.column(n)?.cast(&DataType::UInt64)?.u64()?.clone()) };
    let f = |n: &str| -> PolarsResult<Float64Chunked> { Ok(df.column(n)?.cast(&DataType::Float64)?.f64()?.clone()) };
    let (trials, failed) = (u("trials").map_err(bad)?, u("failed").map_err(bad)?);
    let checks = [
        ("pd", "detected", None),
        ("pfa", "false_alarms", None),
        ("isolation_accuracy", "isolated_correctly", Some("isolation_decided")),
    ];
    for (rate, count, of) in checks {
        let (r, k) = (f(rate).map_err(bad)?, u(count).map_err(bad)?);
        let n = of.map(&u).transpose().map_err(bad)?;
        for i in 0..df.height() {
            let flown = trials.get(i).unwrap_or(0).saturating_sub(failed.get(i).unwrap_or(0));
            let (k, n) = (k.get(i).unwrap_or(0), n.as_ref().map_or(flown, |n| n.get(i).unwrap_or(0)));
            let Some(given) = r.get(i).filter(|v| !v.is_nan()) else { continue };
            let from_counts = k as f64 / n as f64;
            if n == 0 || (given - from_counts).abs() > 1e-9 {
                let denominator = of.unwrap_or("(trials - failed)");
                return Err(RunError::Invalid(format!(
                    "{}: line {} ({}): {rate} = {given} but {count} / {denominator} = {k}/{n}: the rates must follow from the counts (check compares counts; renew the baseline from a run instead of editing it)",
                    file.display(),
                    i + 2,
                    groups[i]
                )));
            }
        }
    }
    Ok(())
}

/// Per group, its counts.
fn groups(df: &DataFrame) -> PolarsResult<HashMap<String, Counts>> {
    let names = group_names(df)?;
    let u = |n: &str| -> PolarsResult<UInt64Chunked> { Ok(df.column(n)?.cast(&DataType::UInt64)?.u64()?.clone()) };
    let (trials, failed, detected, fa) = (u("trials")?, u("failed")?, u("detected")?, u("false_alarms")?);
    let (decided, correct) = (u("isolation_decided")?, u("isolated_correctly")?);
    let pd = df.column("pd")?.cast(&DataType::Float64)?;
    let pd = pd.f64()?;
    let mut map = HashMap::with_capacity(df.height());
    for (i, name) in names.into_iter().enumerate() {
        map.insert(
            name,
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
    // Rates bought at different false-alarm rates do not compare: a looser calibration detects more.
    match (calibration_of(current), calibration_of(baseline)) {
        (Ok(c), Ok(b)) if c.is_some() && b.is_some() && c != b => {
            return Err(RunError::Invalid(format!(
                "the summary's calibrated thresholds are at {}, the baseline's at {}: rates bought at different false-alarm rates do not compare; summarize both at one target (`fdimc summarize DIR --target-pfa P [--confidence C]` writes DIR/calibrations/<target>/summary.csv)",
                describe(c),
                describe(b)
            )));
        }
        (Ok(Some(_)), Err(())) => verdict.notes.push(
            "the baseline does not say at what false-alarm rate its thresholds were calibrated (made by an older fdimc): compared as if at the summary's".into(),
        ),
        (Err(()), Ok(Some(_))) => verdict.notes.push(
            "the summary does not say at what false-alarm rate its thresholds were calibrated (made by an older fdimc): compared as if at the baseline's".into(),
        ),
        _ => {}
    }
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
        // Each rate as (successes, trials) where a drop is the regression; the false-alarm rate through
        // its complement, the quiet flights.
        let quiet = |x: Counts| (x.flown - x.false_alarms, x.flown);
        let tests = [
            (b.faulty, "detection probability", (b.detected, b.flown), (c.detected, c.flown), None),
            (b.decided > 0, "isolation accuracy", (b.correct, b.decided), (c.correct, c.decided), None),
            (
                true,
                "false-alarm rate",
                (b.false_alarms, b.flown),
                (c.false_alarms, c.flown),
                Some((quiet(b), quiet(c))),
            ),
        ];
        for (applies, what, baseline, current, complement) in tests {
            if applies {
                let ((bk, bn), (ck, cn)) = complement.unwrap_or((baseline, current));
                candidates.push((key.clone(), what, baseline, current, p_lower(ck, cn, bk, bn)));
            }
        }
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The one-sided test against SciPy's Yates-corrected chi-square of the 2 x 2 table
    /// (`scipy.stats.chi2_contingency(..., correction=True)`, z = sqrt(chi2), p = norm.sf(z)), an
    /// independent implementation of the same statistic.
    #[test]
    fn the_one_sided_test_matches_the_yates_corrected_chi_square() {
        for ((k1, n1, k0, n0), reference) in [
            ((80, 100, 90, 100), 0.03735296665606522),
            ((800, 1000, 900, 1000), 2.829973789935477e-10),
            ((45, 60, 55, 60), 0.013743168055755164),
            ((970, 1000, 990, 1000), 0.0012040202336439786),
            ((188, 200, 199, 200), 0.002403431559150862),
        ] {
            let p = p_lower(k1, n1, k0, n0);
            assert!((p - reference).abs() <= 1e-9 * reference, "{k1}/{n1} against {k0}/{n0}: {p}, SciPy {reference}");
        }
    }

    /// A summary of hand-made groups: (target, trials, detected, false alarms, isolation decided,
    /// isolated correctly, faulty).
    fn summary(rows: &[(&str, u64, u64, u64, u64, u64, bool)]) -> DataFrame {
        let c = |f: fn(&(&str, u64, u64, u64, u64, u64, bool)) -> u64| rows.iter().map(f).collect::<Vec<u64>>();
        df!(
            "thresholds" => vec!["deck"; rows.len()],
            "detector" => vec!["d"; rows.len()],
            "target" => rows.iter().map(|r| r.0).collect::<Vec<_>>(),
            "trials" => c(|r| r.1),
            "failed" => vec![0u64; rows.len()],
            "detected" => c(|r| r.2),
            "false_alarms" => c(|r| r.3),
            "isolation_decided" => c(|r| r.4),
            "isolated_correctly" => c(|r| r.5),
            "pd" => rows.iter().map(|r| r.6.then(|| r.2 as f64 / r.1 as f64)).collect::<Vec<_>>(),
            "pfa" => rows.iter().map(|r| r.3 as f64 / r.1 as f64).collect::<Vec<_>>(),
            "isolation_accuracy" => rows.iter().map(|r| (r.4 > 0).then(|| r.5 as f64 / r.4 as f64)).collect::<Vec<_>>(),
        )
        .unwrap()
    }

    /// A detection drop, an isolation drop and a false-alarm rise, each flagged where Bonferroni over
    /// the 10 tests lets it through: at alpha 0.01 (level 0.001) only the detection drop (p 2.8e-10),
    /// at 0.05 (level 0.005) also the isolation drop (p 1.2e-3) and the false-alarm rise (p 2.4e-3).
    #[test]
    fn drops_and_rises_are_flagged_at_the_bonferroni_level() {
        let baseline = summary(&[
            ("a", 1000, 900, 0, 900, 880, true),
            ("b", 1000, 950, 0, 1000, 990, true),
            ("c", 200, 0, 1, 0, 0, false),
            ("d", 500, 400, 2, 400, 390, true),
        ]);
        let current = summary(&[
            ("a", 1000, 800, 0, 900, 880, true),
            ("b", 1000, 950, 0, 1000, 970, true),
            ("c", 200, 0, 12, 0, 0, false),
            ("d", 500, 400, 2, 400, 390, true),
        ]);
        let flagged = |alpha: f64| {
            let v = compare(&current, &baseline, alpha).unwrap();
            assert_eq!((v.tests, v.compared_groups), (10, 4));
            v.regressions.iter().map(|r| format!("{} {}", r.group, r.what)).collect::<Vec<_>>()
        };
        assert_eq!(flagged(0.01), ["thresholds=deck detector=d target=a detection probability"]);
        assert_eq!(
            flagged(0.05),
            [
                "thresholds=deck detector=d target=a detection probability",
                "thresholds=deck detector=d target=b isolation accuracy",
                "thresholds=deck detector=d target=c false-alarm rate",
            ]
        );
        // The same tables the other way round: improvements are no regression.
        assert!(compare(&baseline, &current, 0.05).unwrap().regressions.is_empty());
    }

    #[test]
    fn a_baseline_whose_rate_disagrees_with_its_counts_is_refused() {
        let mut edited = summary(&[("a", 1000, 900, 0, 900, 880, true)]);
        edited.with_column(Column::new("pd".into(), [0.999])).unwrap();
        let e = consistent(&edited, std::path::Path::new("b.csv")).unwrap_err().to_string();
        assert_eq!(
            e,
            "b.csv: line 2 (thresholds=deck detector=d target=a): pd = 0.999 but detected / (trials - failed) = 900/1000: the rates must follow from the counts (check compares counts; renew the baseline from a run instead of editing it)"
        );
        assert!(consistent(&summary(&[("a", 1000, 900, 0, 900, 880, true)]), std::path::Path::new("b.csv")).is_ok());
    }

    /// The same counts, read as calibrated at `target` (with `confidence`), or saying nothing (`None`).
    fn calibrated(target: Option<f64>, confidence: Option<f64>) -> DataFrame {
        let mut df = summary(&[("a", 1000, 900, 0, 900, 880, true), ("c", 200, 0, 1, 0, 0, false)]);
        df.with_column(Column::new("thresholds".into(), vec!["calibrated"; 2])).unwrap();
        if let Some(t) = target {
            df.with_column(Column::new("target_pfa".into(), vec![Some(t); 2])).unwrap();
            df.with_column(Column::new("confidence".into(), vec![confidence; 2])).unwrap();
        }
        df
    }

    /// Rates calibrated at another false-alarm rate are refused, naming both; the same calibration
    /// compares; a baseline that does not say is compared with a warning.
    #[test]
    fn summaries_calibrated_differently_are_refused() {
        let at = |t, c| calibrated(Some(t), c);
        let err = compare(&at(0.05, None), &at(0.01, None), 0.05).unwrap_err().to_string();
        assert!(err.contains("at Pfa 0.05, the baseline's at Pfa 0.01"), "{err}");
        let err = compare(&at(0.01, Some(0.95)), &at(0.01, None), 0.05).unwrap_err().to_string();
        assert!(err.contains("Pfa 0.01 with 0.95 confidence, the baseline's at Pfa 0.01"), "{err}");
        let same = compare(&at(0.01, Some(0.95)), &at(0.01, Some(0.95)), 0.05).unwrap();
        assert_eq!((same.compared_groups, same.regressions.len(), same.notes.len()), (2, 0, 0));
        let unsaid = compare(&at(0.01, None), &calibrated(None, None), 0.05).unwrap();
        assert_eq!((unsaid.compared_groups, unsaid.notes.len()), (2, 1), "{:?}", unsaid.notes);
        let unsaid = compare(&calibrated(None, None), &at(0.01, None), 0.05).unwrap();
        assert!(unsaid.notes.iter().any(|n| n.starts_with("the summary does not say")), "{:?}", unsaid.notes);
        // The deck's thresholds carry no calibration: nothing to refuse.
        assert!(
            compare(&summary(&[("a", 10, 9, 0, 9, 9, true)]), &summary(&[("a", 10, 9, 0, 9, 9, true)]), 0.05).is_ok()
        );
    }
}
