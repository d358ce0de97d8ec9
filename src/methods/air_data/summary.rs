//! Statistics of air-data studies (method 002) from `trials.parquet`, without re-simulating. Written to
//! the results folder:
//! - `summary.csv`, `summary.parquet`: per (detector, kind, faulty sensors, size bin, noise bin, gust
//!   bin): trials, `failed`, detection probability and false-alarm rate (a declaration before the onset,
//!   anywhere when fault-free) with 95 % Wilson intervals, detection-delay percentiles, correct isolation
//!   among the detected (the detector's faulty set is exactly the faulty sensors) with its interval, the
//!   median bias-estimate error (bias and drift faults, in sensor sigmas), the median air-data error of
//!   the blended estimate against that of the raw faulty sensors (sigmas), and trials whose filters
//!   needed covariance repairs or went non-finite;
//! - `detectors.csv`: the same per detector over all faults, with the false-alarm rate over all flights
//!   (what `fdimc run` prints);
//! - `comparison.csv`: every pair of detectors on the same trials ([`crate::engine::paired`]).

use crate::engine::summary::{Table, print_footer};
use std::path::Path;

use polars::prelude::*;

use crate::engine::output::write_table;
use crate::engine::paired::{Outcome, PairedUnits};
use crate::engine::runner::{RunError, pol, write_parquet};
use crate::engine::schema::col as common;
use crate::engine::summary::{add_rate, f64_col, flown_and_faulty, read_run, str_col, u64_values};
use crate::methods::air_data::records::col;

/// What `summarize` wrote for an air-data study.
#[derive(Debug)]
pub struct AirDataSummary {
    pub summary: DataFrame,
    pub detectors: DataFrame,
    pub comparison: DataFrame,
    pub warnings: Vec<String>,
}

/// Reads `dir/trials.parquet` of a complete air-data run and writes the tables of the module docs.
pub fn summarize(dir: &Path) -> Result<AirDataSummary, RunError> {
    let (manifest, trials, path) = read_run(dir)?;
    let keys = [common::DETECTOR, common::KIND, col::SENSORS, common::SIZE_BIN, common::NOISE_BIN, col::GUST_BIN];
    let rows = flagged(&trials);
    let mut summary = aggregate(&rows, &keys).map_err(pol(&path))?;
    let mut detectors = per_detector(&rows).map_err(pol(&path))?;
    let mut comparison = compare(&trials, &manifest.detectors, &path)?;
    let out = |name: &str| dir.join(name);
    write_table(&mut summary, &out("summary.csv"))?;
    write_parquet(&mut summary, &out("summary.parquet"))?;
    write_table(&mut detectors, &out("detectors.csv"))?;
    write_table(&mut comparison, &out("comparison.csv"))?;
    let count = |name: &str| u64_values(&detectors, name).map(|v| v.iter().sum::<u64>());
    let mut warnings = Vec::new();
    let failed = count("failed").map_err(pol(&path))?;
    if failed > 0 {
        warnings.push(format!("{failed} trial x detector runs could not be flown (failure in trials.parquet)"));
    }
    let non_finite = count("non_finite").map_err(pol(&path))?;
    if non_finite > 0 {
        warnings.push(format!("{non_finite} trial x detector runs had non-finite filter values (non_finite_steps)"));
    }
    Ok(AirDataSummary { summary, detectors, comparison, warnings })
}

/// The records with the per-row indicators the aggregation counts.
fn flagged(trials: &DataFrame) -> LazyFrame {
    use polars::prelude::col as c;
    let flag = |e: Expr| e.fill_null(lit(false)).cast(DataType::UInt64);
    trials.clone().lazy().with_columns([
        flag(c(col::FAILURE).is_not_null()).alias("failed_flag"),
        flag(c(col::DETECTED)).alias("detected_flag"),
        flag(c(col::ISOLATED_CORRECTLY)).alias("isolated_flag"),
        flag(c(common::FALSE_ALARM_S).is_not_null()).alias("false_alarm_flag"),
        flag(c(col::COVARIANCE_REPAIRS).gt(lit(0))).alias("repaired_flag"),
        flag(c(col::NON_FINITE_STEPS).gt(lit(0))).alias("non_finite_flag"),
        c(common::KIND).neq(lit(common::NO_FAULT)).alias("faulty"),
    ])
}

/// Group counts, rates with Wilson intervals, percentiles over `keys`.
fn aggregate(rows: &LazyFrame, keys: &[&str]) -> PolarsResult<DataFrame> {
    use polars::prelude::col as c;
    let q = |name: &str, p: f64, alias: &str| c(name).quantile(lit(p), QuantileMethod::Linear).alias(alias);
    let mut df = rows
        .clone()
        .group_by(keys.iter().map(|k| c(*k)).collect::<Vec<_>>())
        .agg([
            len().cast(DataType::UInt64).alias("trials"),
            c("failed_flag").sum().alias("failed"),
            c("detected_flag").sum().alias("detected"),
            c("isolated_flag").sum().alias("isolated_correctly"),
            c("false_alarm_flag").sum().alias("false_alarms"),
            c("repaired_flag").sum().alias("repaired"),
            c("non_finite_flag").sum().alias("non_finite"),
            c("faulty").max().alias("faulty"),
            q(common::DELAY_S, 0.5, "delay_p50_s"),
            q(common::DELAY_S, 0.9, "delay_p90_s"),
            q(common::DELAY_S, 0.99, "delay_p99_s"),
            q(col::BIAS_ERROR_RMS_SIGMA, 0.5, "bias_error_p50_sigma"),
            q(col::ESTIMATE_RMS_SIGMA, 0.5, "estimate_rms_p50_sigma"),
            q(col::RAW_RMS_SIGMA, 0.5, "raw_rms_p50_sigma"),
        ])
        .sort(
            keys.iter().map(|k| k.to_string()).collect::<Vec<_>>(),
            SortMultipleOptions::default().with_nulls_last(true),
        )
        .collect()?;
    let (detected, isolated, fa) =
        (u64_values(&df, "detected")?, u64_values(&df, "isolated_correctly")?, u64_values(&df, "false_alarms")?);
    let (flown, faulty) = flown_and_faulty(&mut df)?;
    add_rate(&mut df, "pd", &detected, &flown, &|i| faulty[i])?;
    add_rate(&mut df, "pfa", &fa, &flown, &|_| true)?;
    add_rate(&mut df, "isolation_accuracy", &isolated, &detected, &|i| faulty[i])?;
    Ok(df)
}

/// One row per detector: the fault rates over its faulty trials, the false-alarm rate over all flights.
fn per_detector(rows: &LazyFrame) -> PolarsResult<DataFrame> {
    use polars::prelude::col as c;
    let faulty = aggregate(&rows.clone().filter(c("faulty")), &[common::DETECTOR])?;
    let all = aggregate(rows, &[common::DETECTOR])?;
    faulty
        .lazy()
        .select([
            c(common::DETECTOR),
            c("trials").alias("faulty_trials"),
            c("detected"),
            c("pd"),
            c("pd_lo"),
            c("pd_hi"),
            c("isolated_correctly"),
            c("isolation_accuracy"),
            c("isolation_accuracy_lo"),
            c("isolation_accuracy_hi"),
            c("delay_p50_s"),
            c("delay_p90_s"),
            c("bias_error_p50_sigma"),
            c("estimate_rms_p50_sigma"),
            c("raw_rms_p50_sigma"),
        ])
        .join(
            all.lazy().select([
                c(common::DETECTOR),
                c("trials").alias("flights"),
                c("failed"),
                c("false_alarms"),
                c("pfa"),
                c("pfa_lo"),
                c("pfa_hi"),
                c("repaired"),
                c("non_finite"),
            ]),
            [c(common::DETECTOR)],
            [c(common::DETECTOR)],
            JoinArgs::new(JoinType::Right),
        )
        .collect()
}

/// Every pair of detectors on the same trials.
fn compare(trials: &DataFrame, detectors: &[String], file: &Path) -> Result<DataFrame, RunError> {
    let trial = trials.column(common::TRIAL).and_then(|c| c.u64().cloned()).map_err(pol(file))?;
    let det = str_col(trials, common::DETECTOR, file)?;
    let kind = str_col(trials, common::KIND, file)?;
    let failure = str_col(trials, col::FAILURE, file)?;
    let bool_col = |n: &str| trials.column(n).and_then(|c| c.bool().cloned()).map_err(pol(file));
    let (detected, isolated) = (bool_col(col::DETECTED)?, bool_col(col::ISOLATED_CORRECTLY)?);
    let delay = f64_col(trials, common::DELAY_S, file)?;
    let false_alarm = f64_col(trials, common::FALSE_ALARM_S, file)?;
    let mut units = PairedUnits::new(detectors);
    for i in 0..trials.height() {
        let outcome = Outcome {
            flown: failure.get(i).is_none(),
            faulty: kind.get(i) != Some(common::NO_FAULT),
            detected: detected.get(i).unwrap_or(false),
            isolated: isolated.get(i).unwrap_or(false),
            delay_s: delay.get(i),
            clearing_s: None,
            false_alarm: false_alarm.get(i).is_some(),
            first_unit_of_trial: true,
        };
        units
            .insert(trial.get(i).unwrap_or(0), None, det.get(i).unwrap_or_default(), outcome)
            .map_err(|e| RunError::Invalid(format!("{}: {e}", file.display())))?;
    }
    units.compare(false).map_err(pol(file))
}

/// The per-detector table of an air-data study (`detectors.csv`), then warnings and the files written.
pub fn print(dir: &Path, s: &AirDataSummary) -> Result<(), RunError> {
    let t = Table(&s.detectors);
    let (names, faults, flights, repaired) =
        (t.strs("detector"), t.u64s("faulty_trials"), t.u64s("flights"), t.u64s("repaired"));
    let (pd, iso, pfa) = (t.rates("pd"), t.rates("isolation_accuracy"), t.rates("pfa"));
    let delay = t.delays("delay_p50_s", "delay_p90_s");
    let (bias, est, raw) =
        (t.f64s("bias_error_p50_sigma"), t.f64s("estimate_rms_p50_sigma"), t.f64s("raw_rms_p50_sigma"));
    println!("  per detector, paired over the same trials (see summary.csv for groups, comparison.csv for tests);");
    println!("  errors in sensor sigmas, medians; Pfa: declarations before the onset or in fault-free flights:");
    println!(
        "    {:<12} {:>6} {:<21} {:<21} {:>14} {:>9} {:>15} {:>7} {:<21} {:>8}",
        "detector",
        "faults",
        "Pd [95 % CI]",
        "isolated [95 % CI]",
        "delay p50/p90",
        "bias err",
        "air data / raw",
        "flights",
        "Pfa [95 % CI]",
        "repaired"
    );
    for i in 0..names.len() {
        println!(
            "    {:<12} {:>6} {:<21} {:<21} {:>14} {:>9.2} {:>15} {:>7} {:<21} {:>8}",
            names[i],
            faults[i],
            pd[i],
            iso[i],
            delay[i],
            bias[i],
            format!("{:.2} / {:.2}", est[i], raw[i]),
            flights[i],
            pfa[i],
            repaired[i]
        );
    }
    print_footer(dir, &s.warnings, "summary.csv, summary.parquet, detectors.csv, comparison.csv");
    Ok(())
}
