//! Statistics of accelerometer studies (method 003) from `trials.parquet`, without re-simulating:
//! - `confusion.csv`: per classifier, true class x predicted class: counts, and the share of the true
//!   class's trials (its recall on the diagonal);
//! - `summary.csv`, `summary.parquet`: per (classifier, true class, axis, size bin, noise scale):
//!   trials, `failed`, correctly classified with the recall's 95 % Wilson interval, detected (the
//!   residual detector, faulty classes) with Pd's interval, false alarms with Pfa's interval, delay
//!   percentiles;
//! - `detectors.csv`: per classifier: accuracy and each class's recall with intervals, Pd, delay, Pfa;
//! - `comparison.csv`: the tree against the flat SVM on the same trials: trials classified correctly by
//!   one only, exact McNemar p-value.

use crate::engine::summary::{Table, print_footer};
use std::path::Path;

use polars::prelude::*;

use crate::engine::intervals::{Z95, mcnemar_exact, wilson};
use crate::engine::output::write_table;
use crate::engine::runner::{RunError, pol, write_parquet};
use crate::engine::schema::col as common;
use crate::engine::summary::{add_rate, flown_and_faulty, read_run, str_col, u64_values};
use crate::methods::accelerometer::ekf_svm::FaultClass;
use crate::methods::accelerometer::records::col;

/// What `summarize` wrote for an accelerometer study.
#[derive(Debug)]
pub struct AccelerometerSummary {
    pub confusion: DataFrame,
    pub summary: DataFrame,
    pub detectors: DataFrame,
    pub comparison: DataFrame,
    pub warnings: Vec<String>,
}

/// Reads `dir/trials.parquet` of a complete accelerometer run and writes the tables of the module docs.
pub fn summarize(dir: &Path) -> Result<AccelerometerSummary, RunError> {
    let (manifest, trials, path) = read_run(dir)?;
    let keys = [common::DETECTOR, common::KIND, col::AXIS, common::SIZE_BIN, common::NOISE_BIN];
    let mut summary = aggregate(&trials, &keys).map_err(pol(&path))?;
    let mut confusion = confusion(&trials, &manifest.detectors, &path)?;
    let mut detectors = per_detector(&trials, &manifest.detectors, &path)?;
    let mut comparison = compare(&trials, &manifest.detectors, &path)?;
    let out = |name: &str| dir.join(name);
    write_table(&mut confusion, &out("confusion.csv"))?;
    write_table(&mut summary, &out("summary.csv"))?;
    write_parquet(&mut summary, &out("summary.parquet"))?;
    write_table(&mut detectors, &out("detectors.csv"))?;
    write_table(&mut comparison, &out("comparison.csv"))?;
    let failed = u64_values(&summary, "failed").map_err(pol(&path))?.iter().sum::<u64>();
    let warnings = if failed > 0 {
        vec![format!("{failed} trial x classifier rows could not be simulated or classified (failure)")]
    } else {
        Vec::new()
    };
    Ok(AccelerometerSummary { confusion, summary, detectors, comparison, warnings })
}

/// Group counts and rates over `keys` (module docs).
fn aggregate(trials: &DataFrame, keys: &[&str]) -> PolarsResult<DataFrame> {
    use polars::prelude::col as c;
    let flag = |e: Expr| e.fill_null(lit(false)).cast(DataType::UInt64).sum();
    let q = |p: f64, alias: &str| c(common::DELAY_S).quantile(lit(p), QuantileMethod::Linear).alias(alias);
    let mut df = trials
        .clone()
        .lazy()
        .group_by(keys.iter().map(|k| c(*k)).collect::<Vec<_>>())
        .agg([
            len().cast(DataType::UInt64).alias("trials"),
            flag(c(col::FAILURE).is_not_null()).alias("failed"),
            flag(c(col::CORRECT)).alias("correct"),
            flag(c(common::ALARM_S).is_not_null()).alias("detected"),
            flag(c(common::FALSE_ALARM_S).is_not_null()).alias("false_alarms"),
            // The normal class is a class here, not a fault: a group is faulty when its kind is not normal.
            c(common::KIND).neq(lit(FaultClass::Normal.name())).max().alias("faulty"),
            q(0.5, "delay_p50_s"),
            q(0.9, "delay_p90_s"),
        ])
        .sort(
            keys.iter().map(|k| k.to_string()).collect::<Vec<_>>(),
            SortMultipleOptions::default().with_nulls_last(true),
        )
        .collect()?;
    let (correct, detected, fa) =
        (u64_values(&df, "correct")?, u64_values(&df, "detected")?, u64_values(&df, "false_alarms")?);
    let (flown, faulty) = flown_and_faulty(&mut df)?;
    add_rate(&mut df, "recall", &correct, &flown, &|_| true)?;
    add_rate(&mut df, "pd", &detected, &flown, &|i| faulty[i])?;
    add_rate(&mut df, "pfa", &fa, &flown, &|_| true)?;
    Ok(df)
}

/// Per classifier, every (true, predicted) pair of classes with its count and its share of the true class.
fn confusion(trials: &DataFrame, detectors: &[String], file: &Path) -> Result<DataFrame, RunError> {
    let det = str_col(trials, common::DETECTOR, file)?;
    let truth = str_col(trials, common::KIND, file)?;
    let predicted = str_col(trials, col::PREDICTED, file)?;
    let classes = FaultClass::ALL.map(FaultClass::name);
    let (mut d_col, mut t_col, mut p_col, mut count, mut share) = (vec![], vec![], vec![], vec![], vec![]);
    for d in detectors {
        let mut counts = [[0u64; 4]; 4];
        for i in 0..trials.height() {
            if det.get(i) != Some(d.as_str()) {
                continue;
            }
            let index = |v: Option<&str>| classes.iter().position(|c| Some(*c) == v);
            if let (Some(t), Some(p)) = (index(truth.get(i)), index(predicted.get(i))) {
                counts[t][p] += 1;
            }
        }
        for (t, row) in counts.iter().enumerate() {
            let total: u64 = row.iter().sum();
            for (p, &k) in row.iter().enumerate() {
                d_col.push(d.clone());
                t_col.push(classes[t]);
                p_col.push(classes[p]);
                count.push(k);
                share.push((total > 0).then(|| k as f64 / total as f64));
            }
        }
    }
    DataFrame::new_infer_height(vec![
        Column::new(common::DETECTOR.into(), d_col),
        Column::new("true_class".into(), t_col),
        Column::new("predicted_class".into(), p_col),
        Column::new("trials".into(), count),
        Column::new("share_of_true_class".into(), share),
    ])
    .map_err(pol(file))
}

/// Per classifier: accuracy and per-class recall with Wilson intervals, detection and false alarms.
fn per_detector(trials: &DataFrame, detectors: &[String], file: &Path) -> Result<DataFrame, RunError> {
    let by_class = aggregate(trials, &[common::DETECTOR, common::KIND]).map_err(pol(file))?;
    let all = aggregate(trials, &[common::DETECTOR]).map_err(pol(file))?;
    let faulty = trials
        .clone()
        .lazy()
        .filter(polars::prelude::col(common::KIND).neq(lit(FaultClass::Normal.name())))
        .collect()
        .map_err(pol(file))?;
    let detection = aggregate(&faulty, &[common::DETECTOR]).map_err(pol(file))?;
    let get = |df: &DataFrame, name: &str| -> Result<Vec<u64>, RunError> { u64_values(df, name).map_err(pol(file)) };
    let f64s = |df: &DataFrame, name: &str| -> Vec<f64> {
        df.column(name)
            .ok()
            .and_then(|c| c.f64().ok().cloned())
            .map_or(vec![], |c| (0..c.len()).map(|i| c.get(i).unwrap_or(f64::NAN)).collect())
    };
    let class_det = str_col(&by_class, common::DETECTOR, file)?.clone();
    let class_kind = str_col(&by_class, common::KIND, file)?.clone();
    let (class_correct, class_trials) = (get(&by_class, "correct")?, get(&by_class, "trials")?);
    // The aggregates are sorted by name; the manifest lists the detectors in deck order.
    let row_of = |df: &DataFrame, name: &str| -> Result<Option<usize>, RunError> {
        let names = str_col(df, common::DETECTOR, file)?;
        Ok((0..df.height()).find(|&i| names.get(i) == Some(name)))
    };
    let (all_correct, all_trials, all_fa) = (get(&all, "correct")?, get(&all, "trials")?, get(&all, "false_alarms")?);
    let (det_detected, det_trials) = (get(&detection, "detected")?, get(&detection, "trials")?);
    let (d50, d90) = (f64s(&detection, "delay_p50_s"), f64s(&detection, "delay_p90_s"));
    let (mut trials_col, mut correct_col) = (Vec::new(), Vec::new());
    let mut columns: Vec<(String, Vec<f64>)> = Vec::new();
    let mut push = |name: String, v: f64| match columns.iter_mut().find(|(n, _)| *n == name) {
        Some((_, c)) => c.push(v),
        None => columns.push((name, vec![v])),
    };
    for d in detectors {
        let a_row = row_of(&all, d)?;
        let d_row = row_of(&detection, d)?;
        let at = |v: &[u64], r: Option<usize>| r.and_then(|r| v.get(r).copied()).unwrap_or(0);
        let (n_all, k_all) = (at(&all_trials, a_row), at(&all_correct, a_row));
        trials_col.push(n_all);
        correct_col.push(k_all);
        let rate = |k: u64, n: u64| {
            let (lo, hi) = wilson(k, n, Z95);
            (if n > 0 { k as f64 / n as f64 } else { f64::NAN }, lo, hi)
        };
        let (a, lo, hi) = rate(k_all, n_all);
        push("accuracy".into(), a);
        push("accuracy_lo".into(), lo);
        push("accuracy_hi".into(), hi);
        for class in FaultClass::ALL {
            let row = (0..by_class.height())
                .find(|&r| class_det.get(r) == Some(d.as_str()) && class_kind.get(r) == Some(class.name()));
            let (k, n) = row.map_or((0, 0), |r| (class_correct[r], class_trials[r]));
            let (rc, lo, hi) = rate(k, n);
            push(format!("recall_{}", class.name()), rc);
            push(format!("recall_{}_lo", class.name()), lo);
            push(format!("recall_{}_hi", class.name()), hi);
        }
        let (pd, lo, hi) = rate(at(&det_detected, d_row), at(&det_trials, d_row));
        push("pd".into(), pd);
        push("pd_lo".into(), lo);
        push("pd_hi".into(), hi);
        let delay = |v: &[f64]| d_row.and_then(|r| v.get(r).copied()).unwrap_or(f64::NAN);
        push("delay_p50_s".into(), delay(&d50));
        push("delay_p90_s".into(), delay(&d90));
        let (pfa, lo, hi) = rate(at(&all_fa, a_row), n_all);
        push("pfa".into(), pfa);
        push("pfa_lo".into(), lo);
        push("pfa_hi".into(), hi);
    }
    let mut frame = vec![
        Column::new(common::DETECTOR.into(), detectors.to_vec()),
        Column::new("trials".into(), trials_col),
        Column::new("correct".into(), correct_col),
    ];
    frame.extend(columns.into_iter().map(|(n, v)| Column::new(n.into(), v)));
    DataFrame::new_infer_height(frame).map_err(pol(file))
}

/// The first classifier against every other on the same trials: discordant correct classifications.
fn compare(trials: &DataFrame, detectors: &[String], file: &Path) -> Result<DataFrame, RunError> {
    let det = str_col(trials, common::DETECTOR, file)?;
    let correct = trials.column(col::CORRECT).and_then(|c| c.bool().cloned()).map_err(pol(file))?;
    let trial = trials.column(common::TRIAL).and_then(|c| c.u64().cloned()).map_err(pol(file))?;
    let mut by_trial: std::collections::BTreeMap<u64, Vec<Option<bool>>> = Default::default();
    for i in 0..trials.height() {
        let d = detectors.iter().position(|n| Some(n.as_str()) == det.get(i)).unwrap_or(usize::MAX);
        if d < detectors.len() {
            by_trial.entry(trial.get(i).unwrap_or(0)).or_insert_with(|| vec![None; detectors.len()])[d] =
                correct.get(i);
        }
    }
    let (mut a, mut b, mut n, mut acc_a, mut acc_b, mut a_only, mut b_only, mut p) =
        (vec![], vec![], vec![], vec![], vec![], vec![], vec![], vec![]);
    for k in 1..detectors.len() {
        let (mut count, mut ca, mut cb, mut x, mut y) = (0u64, 0u64, 0u64, 0u64, 0u64);
        for row in by_trial.values() {
            if let (Some(u), Some(v)) = (row[0], row[k]) {
                count += 1;
                ca += u as u64;
                cb += v as u64;
                x += (u && !v) as u64;
                y += (v && !u) as u64;
            }
        }
        a.push(detectors[0].clone());
        b.push(detectors[k].clone());
        n.push(count);
        acc_a.push(ca as f64 / count.max(1) as f64);
        acc_b.push(cb as f64 / count.max(1) as f64);
        a_only.push(x);
        b_only.push(y);
        p.push(mcnemar_exact(x, y));
    }
    DataFrame::new_infer_height(vec![
        Column::new("detector_a".into(), a),
        Column::new("detector_b".into(), b),
        Column::new("trials".into(), n),
        Column::new("accuracy_a".into(), acc_a),
        Column::new("accuracy_b".into(), acc_b),
        Column::new("correct_by_a_only".into(), a_only),
        Column::new("correct_by_b_only".into(), b_only),
        Column::new("mcnemar_p_correct".into(), p),
    ])
    .map_err(pol(file))
}

/// The confusion matrices and per-classifier table of an accelerometer study.
pub fn print(dir: &Path, s: &AccelerometerSummary) -> Result<(), RunError> {
    let t = Table(&s.detectors);
    let (names, trials) = (t.strs("detector"), t.u64s("trials"));
    let (accuracy, pd, pfa) = (t.rates("accuracy"), t.rates("pd"), t.rates("pfa"));
    let delay = t.delays("delay_p50_s", "delay_p90_s");
    println!("  per classifier, on the same fresh trials (confusion.csv, summary.csv; comparison.csv for the test):");
    println!(
        "    {:<6} {:>6} {:<21} {:<21} {:<21} {:<21} {:<21}",
        "", "trials", "accuracy", "recall normal", "recall bias", "recall gain", "recall stuck"
    );
    for i in 0..names.len() {
        let recall: Vec<String> =
            ["normal", "bias", "gain", "stuck"].iter().map(|c| t.rates(&format!("recall_{c}"))[i].clone()).collect();
        println!(
            "    {:<6} {:>6} {:<21} {:<21} {:<21} {:<21} {:<21}",
            names[i], trials[i], accuracy[i], recall[0], recall[1], recall[2], recall[3]
        );
    }
    if let Some(i) = (0..names.len()).next() {
        println!("  residual detector (either classifier's rows): Pd {}, delay {}, Pfa {}", pd[i], delay[i], pfa[i]);
    }
    let c = Table(&s.confusion);
    let (det, truth, count) = (c.strs("detector"), c.strs("true_class"), c.u64s("trials"));
    for name in &names {
        println!("  confusion ({name}): rows true class, columns predicted normal / bias / gain / stuck");
        for class in ["normal", "bias", "gain", "stuck"] {
            let row: Vec<String> = (0..det.len())
                .filter(|&i| det[i] == *name && truth[i] == class)
                .map(|i| format!("{:>6}", count[i]))
                .collect();
            println!("    {class:<7} {}", row.join(" "));
        }
    }
    print_footer(dir, &s.warnings, "confusion.csv, summary.csv, summary.parquet, detectors.csv, comparison.csv");
    Ok(())
}
