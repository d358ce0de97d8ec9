//! Statistics of launch-vehicle studies (method 001) from `trials.parquet`, without re-simulating.
//!
//! Thresholds (`thresholds.csv`, per detector): the deck's `threshold_fhat`, and one calibrated to the
//! deck's target false-alarm probability: the smallest that at most `floor(p n)` of the `n` calibration
//! trials' largest `|fhat|` exceed ([`crate::engine::summary::calibrate`]; calibration trials are the fault-free flights,
//! or the pre-onset windows when there are none). `fhat` scales with `R` and `1 / v` and grows with `N`,
//! so configurations are compared at calibrated thresholds, at equal false-alarm probability.
//!
//! Every trial is evaluated at both sets, like the detection filters' summaries: `deck` online (with the
//! engine's localisation and the loss estimate, which need the signals at the alarm), `calibrated` from
//! the recorded pre-onset maximum and first-passage profile. Written:
//! - `summary.csv`, `summary.parquet`: per (thresholds, detector, kind, engine, loss bin, noise bin, gust
//!   bin): trials, `failed`, detection probability and false-alarm rate with 95 % Wilson intervals,
//!   delay percentiles, correct localisation among the detected with its interval, the median loss
//!   estimate error and its median absolute value (deck);
//! - `detectors.csv`: the same per (thresholds, detector) over all faults, the false-alarm rate over all
//!   flights;
//! - `comparison.csv`: every pair of detectors on the same trials, per threshold set ([`crate::engine::paired`]).

use crate::engine::summary::{Table, print_footer};
use std::path::Path;

use polars::prelude::*;

use crate::engine::intervals::{Z95, wilson};
use crate::engine::output::write_table;
use crate::engine::paired::{Outcome, PairedUnits};
use crate::engine::runner::{Manifest, RunError, pol, write_parquet};
use crate::engine::schema::col as common;
use crate::engine::summary::{add_rate, calibrate, f64_col, flown_and_faulty, list_col, read_run, str_col, u64_values};
use crate::methods::thrust_loss::records::col;

/// Thresholds of one detector.
#[derive(Debug, Clone, PartialEq)]
pub struct LaunchThresholds {
    pub detector: String,
    pub deck: f64,
    pub calibrated: f64,
    pub calibration_trials: u64,
    pub false_alarms: u64,
}

/// What `summarize` wrote for a launch study.
#[derive(Debug)]
pub struct LaunchSummary {
    pub thresholds: Vec<LaunchThresholds>,
    pub summary: DataFrame,
    pub detectors: DataFrame,
    pub comparison: DataFrame,
    pub warnings: Vec<String>,
}

/// Reads `dir/trials.parquet` of a complete launch run and writes the tables of the module docs, the
/// thresholds calibrated to `target_pfa`.
pub fn summarize(dir: &Path, target_pfa: f64) -> Result<LaunchSummary, RunError> {
    let (manifest, trials, path) = read_run(dir)?;
    let manifest = Manifest { target_pfa, ..manifest };
    let thresholds = calibrate_thresholds(&trials, &manifest, &path)?;
    let evaluated = evaluate(&trials, &thresholds, &path)?;
    let keys =
        ["thresholds", common::DETECTOR, common::KIND, col::ENGINE, common::SIZE_BIN, common::NOISE_BIN, col::GUST_BIN];
    let mut summary = aggregate(&evaluated.clone().lazy(), &keys).map_err(pol(&path))?;
    let mut detectors = per_detector(&evaluated).map_err(pol(&path))?;
    let mut comparison = compare(&evaluated, &manifest.detectors, &path)?;
    let mut threshold_table = threshold_frame(&thresholds, manifest.target_pfa).map_err(pol(&path))?;
    let out = |name: &str| dir.join(name);
    write_table(&mut threshold_table, &out("thresholds.csv"))?;
    write_table(&mut summary, &out("summary.csv"))?;
    write_parquet(&mut summary, &out("summary.parquet"))?;
    write_table(&mut detectors, &out("detectors.csv"))?;
    write_table(&mut comparison, &out("comparison.csv"))?;
    let failed = u64_values(&detectors, "failed").map_err(pol(&path))?.iter().sum::<u64>() / 2;
    let mut warnings = Vec::new();
    if failed > 0 {
        warnings.push(format!("{failed} trial x detector flights ended early (failure in trials.parquet)"));
    }
    for t in &thresholds {
        if (t.calibration_trials as f64) * manifest.target_pfa < 1.0 {
            warnings.push(format!(
                "detector {}: {} calibration trials are too few for a false-alarm probability of {} (need {})",
                t.detector,
                t.calibration_trials,
                manifest.target_pfa,
                (1.0 / manifest.target_pfa).ceil()
            ));
        }
    }
    Ok(LaunchSummary { thresholds, summary, detectors, comparison, warnings })
}

/// The deck's and the calibrated threshold of each detector (module docs).
fn calibrate_thresholds(trials: &DataFrame, m: &Manifest, file: &Path) -> Result<Vec<LaunchThresholds>, RunError> {
    let det = str_col(trials, common::DETECTOR, file)?;
    let kind = str_col(trials, common::KIND, file)?;
    let failure = str_col(trials, col::FAILURE, file)?;
    let pre = f64_col(trials, col::PRE_MAX_FHAT, file)?;
    let any_fault_free = (0..trials.height()).any(|i| kind.get(i) == Some(common::NO_FAULT));
    let mut out = Vec::with_capacity(m.detectors.len());
    for (d, name) in m.detectors.iter().enumerate() {
        let mut values: Vec<f64> = (0..trials.height())
            .filter(|&i| det.get(i) == Some(name.as_str()) && failure.get(i).is_none())
            .filter(|&i| !any_fault_free || kind.get(i) == Some(common::NO_FAULT))
            .filter_map(|i| pre.get(i))
            .collect();
        let n = values.len() as u64;
        let (calibrated, false_alarms) = calibrate(&mut values, m.target_pfa);
        let deck = m.deck_thresholds.get(d).and_then(|t| t.first()).copied().unwrap_or(f64::NAN);
        out.push(LaunchThresholds { detector: name.clone(), deck, calibrated, calibration_trials: n, false_alarms });
    }
    Ok(out)
}

fn threshold_frame(thresholds: &[LaunchThresholds], target_pfa: f64) -> PolarsResult<DataFrame> {
    let (lo, hi): (Vec<f64>, Vec<f64>) =
        thresholds.iter().map(|t| wilson(t.false_alarms, t.calibration_trials, Z95)).unzip();
    DataFrame::new_infer_height(vec![
        Column::new(common::DETECTOR.into(), thresholds.iter().map(|t| t.detector.clone()).collect::<Vec<_>>()),
        Column::new("deck_threshold_fhat".into(), thresholds.iter().map(|t| t.deck).collect::<Vec<_>>()),
        Column::new("calibrated_threshold_fhat".into(), thresholds.iter().map(|t| t.calibrated).collect::<Vec<_>>()),
        Column::new("target_pfa".into(), vec![target_pfa; thresholds.len()]),
        Column::new("calibration_trials".into(), thresholds.iter().map(|t| t.calibration_trials).collect::<Vec<_>>()),
        Column::new("false_alarms".into(), thresholds.iter().map(|t| t.false_alarms).collect::<Vec<_>>()),
        Column::new(
            "pfa_achieved".into(),
            thresholds.iter().map(|t| t.false_alarms as f64 / t.calibration_trials.max(1) as f64).collect::<Vec<_>>(),
        ),
        Column::new("pfa_lo".into(), lo),
        Column::new("pfa_hi".into(), hi),
    ])
}

/// One row per (trial, detector, threshold set) with what the aggregation counts.
fn evaluate(trials: &DataFrame, thresholds: &[LaunchThresholds], file: &Path) -> Result<DataFrame, RunError> {
    let n = trials.height();
    let det = str_col(trials, common::DETECTOR, file)?;
    let failure = str_col(trials, col::FAILURE, file)?;
    let kind = str_col(trials, common::KIND, file)?;
    let onset = f64_col(trials, common::ONSET_S, file)?;
    let pre = f64_col(trials, col::PRE_MAX_FHAT, file)?;
    let (fp_t, fp_v) = (list_col(trials, col::FP_T_S, file)?, list_col(trials, col::FP_V, file)?);
    let (false_alarm, delay) = (f64_col(trials, common::FALSE_ALARM_S, file)?, f64_col(trials, common::DELAY_S, file)?);
    let localised = trials.column(col::LOCALISED_CORRECTLY).and_then(|c| c.bool().cloned()).map_err(pol(file))?;
    let loss_error = f64_col(trials, col::LOSS_ERROR_PERCENT, file)?;
    let mut set: Vec<&str> = Vec::with_capacity(2 * n);
    let mut index: Vec<u32> = Vec::with_capacity(2 * n);
    let (mut fa, mut detected, mut delays, mut loc, mut err) = (vec![], vec![], vec![], vec![], vec![]);
    for (s, name) in ["deck", "calibrated"].into_iter().enumerate() {
        for i in 0..n {
            let d = det.get(i).unwrap_or_default();
            let t = thresholds
                .iter()
                .find(|t| t.detector == d)
                .ok_or_else(|| RunError::Invalid(format!("{}: unknown detector {d:?}", file.display())))?;
            let flown = failure.get(i).is_none();
            let faulty = kind.get(i) != Some(common::NO_FAULT);
            let (f, dl) = if s == 0 {
                (false_alarm.get(i).is_some(), delay.get(i))
            } else {
                let thr = t.calibrated;
                let first = fp_t[i].iter().zip(&fp_v[i]).find(|(_, v)| **v > thr).map(|(t, _)| *t);
                (pre.get(i).is_some_and(|v| v > thr), first.zip(onset.get(i)).map(|(a, t0)| a - t0))
            };
            set.push(name);
            index.push(i as u32);
            fa.push(flown && f);
            detected.push(flown && faulty && dl.is_some());
            delays.push(dl.filter(|_| flown && faulty));
            loc.push((s == 0).then(|| localised.get(i)).flatten());
            err.push(if s == 0 { loss_error.get(i) } else { None });
        }
    }
    let base = trials.select([
        common::TRIAL,
        common::DETECTOR,
        common::KIND,
        col::ENGINE,
        common::SIZE_BIN,
        common::NOISE_BIN,
        col::GUST_BIN,
        col::FAILURE,
    ]);
    let base = base.map_err(pol(file))?;
    let take = IdxCa::from_vec("idx".into(), index.iter().map(|&i| i as IdxSize).collect());
    let mut df = base.take(&take).map_err(pol(file))?;
    for c in [
        Column::new("thresholds".into(), set),
        Column::new("false_alarm".into(), fa),
        Column::new("detected".into(), detected),
        Column::new(common::DELAY_S.into(), delays),
        Column::new(col::LOCALISED_CORRECTLY.into(), loc),
        Column::new("loss_abs_error_percent".into(), err.iter().map(|e| e.map(f64::abs)).collect::<Vec<_>>()),
        Column::new(col::LOSS_ERROR_PERCENT.into(), err),
    ] {
        df.with_column(c).map_err(pol(file))?;
    }
    Ok(df)
}

/// Group counts, rates with Wilson intervals, delay and loss-error percentiles over `keys`.
fn aggregate(rows: &LazyFrame, keys: &[&str]) -> PolarsResult<DataFrame> {
    use polars::prelude::col as c;
    let flag = |name: &str| c(name).fill_null(lit(false)).cast(DataType::UInt64);
    let q = |e: Expr, p: f64, alias: &str| e.quantile(lit(p), QuantileMethod::Linear).alias(alias);
    let mut df = rows
        .clone()
        .with_column(c(common::KIND).neq(lit(common::NO_FAULT)).alias("faulty"))
        .group_by(keys.iter().map(|k| c(*k)).collect::<Vec<_>>())
        .agg([
            len().cast(DataType::UInt64).alias("trials"),
            c(col::FAILURE).is_not_null().cast(DataType::UInt64).sum().alias("failed"),
            flag("detected").sum().alias("detected"),
            flag("false_alarm").sum().alias("false_alarms"),
            flag(col::LOCALISED_CORRECTLY).sum().alias("localised_correctly"),
            c(col::LOCALISED_CORRECTLY).is_not_null().cast(DataType::UInt64).sum().alias("localisation_decided"),
            c("faulty").max().alias("faulty"),
            q(c(common::DELAY_S), 0.5, "delay_p50_s"),
            q(c(common::DELAY_S), 0.9, "delay_p90_s"),
            q(c(common::DELAY_S), 0.99, "delay_p99_s"),
            q(c(col::LOSS_ERROR_PERCENT), 0.5, "loss_error_p50_percent"),
            q(c("loss_abs_error_percent"), 0.5, "loss_abs_error_p50_percent"),
        ])
        .sort(
            keys.iter().map(|k| k.to_string()).collect::<Vec<_>>(),
            SortMultipleOptions::default().with_nulls_last(true),
        )
        .collect()?;
    let (detected, fa) = (u64_values(&df, "detected")?, u64_values(&df, "false_alarms")?);
    let (loc, decided) = (u64_values(&df, "localised_correctly")?, u64_values(&df, "localisation_decided")?);
    let (flown, faulty) = flown_and_faulty(&mut df)?;
    add_rate(&mut df, "pd", &detected, &flown, &|i| faulty[i])?;
    add_rate(&mut df, "pfa", &fa, &flown, &|_| true)?;
    add_rate(&mut df, "localisation_accuracy", &loc, &decided, &|i| faulty[i])?;
    Ok(df)
}

/// Per (thresholds, detector): the fault rates over the faulty trials, the false-alarm rate over all.
fn per_detector(evaluated: &DataFrame) -> PolarsResult<DataFrame> {
    use polars::prelude::col as c;
    let keys = ["thresholds", common::DETECTOR];
    let rows = evaluated.clone().lazy();
    let faulty = aggregate(&rows.clone().filter(c(common::KIND).neq(lit(common::NO_FAULT))), &keys)?;
    let all = aggregate(&rows, &keys)?;
    faulty
        .lazy()
        .select([
            c("thresholds"),
            c(common::DETECTOR),
            c("trials").alias("faulty_trials"),
            c("detected"),
            c("pd"),
            c("pd_lo"),
            c("pd_hi"),
            c("delay_p50_s"),
            c("delay_p90_s"),
            c("localised_correctly"),
            c("localisation_accuracy"),
            c("localisation_accuracy_lo"),
            c("localisation_accuracy_hi"),
            c("loss_error_p50_percent"),
            c("loss_abs_error_p50_percent"),
        ])
        .join(
            all.lazy().select([
                c("thresholds"),
                c(common::DETECTOR),
                c("trials").alias("flights"),
                c("failed"),
                c("false_alarms"),
                c("pfa"),
                c("pfa_lo"),
                c("pfa_hi"),
            ]),
            [c("thresholds"), c(common::DETECTOR)],
            [c("thresholds"), c(common::DETECTOR)],
            JoinArgs::new(JoinType::Right),
        )
        .collect()
}

/// Every pair of detectors on the same trials, per threshold set.
fn compare(evaluated: &DataFrame, detectors: &[String], file: &Path) -> Result<DataFrame, RunError> {
    let set = str_col(evaluated, "thresholds", file)?;
    let trial = evaluated.column(common::TRIAL).and_then(|c| c.u64().cloned()).map_err(pol(file))?;
    let det = str_col(evaluated, common::DETECTOR, file)?;
    let kind = str_col(evaluated, common::KIND, file)?;
    let failure = str_col(evaluated, col::FAILURE, file)?;
    let flag = |n: &str| evaluated.column(n).and_then(|c| c.bool().cloned()).map_err(pol(file));
    let (fa, detected, localised) = (flag("false_alarm")?, flag("detected")?, flag(col::LOCALISED_CORRECTLY)?);
    let delay = f64_col(evaluated, common::DELAY_S, file)?;
    let mut frames = Vec::new();
    for name in ["deck", "calibrated"] {
        let mut units = PairedUnits::new(detectors);
        for i in (0..evaluated.height()).filter(|&i| set.get(i) == Some(name)) {
            let outcome = Outcome {
                flown: failure.get(i).is_none(),
                faulty: kind.get(i) != Some(common::NO_FAULT),
                detected: detected.get(i).unwrap_or(false),
                isolated: localised.get(i).unwrap_or(false),
                delay_s: delay.get(i),
                clearing_s: None,
                false_alarm: fa.get(i).unwrap_or(false),
                first_unit_of_trial: true,
            };
            units
                .insert(trial.get(i).unwrap_or(0), None, det.get(i).unwrap_or_default(), outcome)
                .map_err(|e| RunError::Invalid(format!("{}: {e}", file.display())))?;
        }
        let mut df = units.compare(false).map_err(pol(file))?;
        let height = df.height();
        df.insert_column(0, Column::new("thresholds".into(), vec![name; height])).map_err(pol(file))?;
        frames.push(df);
    }
    let mut all = frames.remove(0);
    all.vstack_mut(&frames[0]).map_err(pol(file))?;
    Ok(all)
}

/// The thresholds and per-detector table of a launch study (`detectors.csv`).
pub fn print(dir: &Path, s: &LaunchSummary) -> Result<(), RunError> {
    println!("  thresholds on |fhat|: the deck's, and calibrated on the fault-free flights:");
    for t in &s.thresholds {
        println!(
            "    {:<12} deck {:.4e}, calibrated {:.4e} (Pfa achieved {:.4} on {} calibration flights)",
            t.detector,
            t.deck,
            t.calibrated,
            t.false_alarms as f64 / t.calibration_trials.max(1) as f64,
            t.calibration_trials
        );
    }
    let t = Table(&s.detectors);
    let (sets, names, faults, flights) =
        (t.strs("thresholds"), t.strs("detector"), t.u64s("faulty_trials"), t.u64s("flights"));
    let (pd, engine, pfa) = (t.rates("pd"), t.rates("localisation_accuracy"), t.rates("pfa"));
    let (delay, loss) = (t.delays("delay_p50_s", "delay_p90_s"), t.f64s("loss_abs_error_p50_percent"));
    println!("  per detector, paired over the same trials (see summary.csv for groups, comparison.csv for tests);");
    println!("  engine and loss (median |error|) at the deck's threshold only; Pfa: alarms before the onset:");
    println!(
        "    {:<10} {:<12} {:>6} {:<21} {:>14} {:<21} {:>8} {:>7} {:<21}",
        "thresholds",
        "detector",
        "faults",
        "Pd [95 % CI]",
        "delay p50/p90",
        "engine [95 % CI]",
        "loss err",
        "flights",
        "Pfa [95 % CI]"
    );
    for i in 0..names.len() {
        let loss_text = if loss[i].is_nan() { "-".to_string() } else { format!("{:.1} %", loss[i]) };
        println!(
            "    {:<10} {:<12} {:>6} {:<21} {:>14} {:<21} {:>8} {:>7} {:<21}",
            sets[i], names[i], faults[i], pd[i], delay[i], engine[i], loss_text, flights[i], pfa[i]
        );
    }
    print_footer(dir, &s.warnings, "thresholds.csv, summary.csv, summary.parquet, detectors.csv, comparison.csv");
    Ok(())
}
