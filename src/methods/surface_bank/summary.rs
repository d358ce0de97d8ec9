//! Statistics of control-surface studies (method 004) from `trials.parquet`, without re-simulating.
//!
//! Every bank of a deck flies the same trials, so their comparison is paired. Written to the results
//! folder:
//! - `summary.csv`, `summary.parquet`: per (detector, kind, surface, size bin, noise bin, parameter-error
//!   bin), over the fault windows of the group (a Monte Carlo fault population gives one per faulty
//!   trial): windows (`trials`), flights that stopped early (`failed`), detection probability (a surface
//!   declared in the window) and the false-alarm rate (trials with a declaration while no fault was
//!   active) with 95 % Wilson intervals; correct isolation among the detected windows (the first
//!   declaration names the faulty surface) with its interval; detection, isolation and clearing delay
//!   percentiles; the clearing rate after the window ends; the rate of post-fault declarations (a
//!   surface declared after the fault ended, while the airframe recovers) with its interval; the median
//!   surface-estimate error; trials whose covariances lost symmetry, positive definiteness or
//!   finiteness. The false-alarm rate counts declarations before any fault (the whole flight when
//!   fault-free), as the detection-filter summaries do;
//! - `detectors.csv`: the same per detector over all faults (window rates over the faulty windows,
//!   trial rates once per trial), the table `fdimc run` prints;
//! - `comparison.csv`: every pair of detectors on the same windows and trials: discordant detections,
//!   correct isolations and false alarms with exact McNemar p-values, and the median paired difference
//!   of detection and clearing delays (b - a, over the windows both detected or cleared).
//!
//! Rates are over the flights that reached the end: a trial that left the envelope counts in `failed`.

use crate::engine::summary::{Table, print_footer};
use std::path::Path;

use polars::prelude::*;

use crate::engine::intervals::{Z95, wilson};
use crate::engine::output::write_table;
use crate::engine::paired::{Outcome, PairedUnits};
use crate::engine::runner::{RunError, pol, write_parquet};
use crate::engine::schema::col as common;
use crate::engine::summary::{add_rate, f64_col, flown_and_faulty, read_run, str_col, u64_values};
use crate::methods::surface_bank::records::col;

/// What `summarize` wrote for a surface study.
#[derive(Debug)]
pub struct SurfaceSummary {
    pub summary: DataFrame,
    /// Per detector (bank), over all faults: `detectors.csv`.
    pub detectors: DataFrame,
    pub comparison: DataFrame,
    pub warnings: Vec<String>,
}

/// Reads `dir/trials.parquet` of a complete surface run and writes the tables of the module docs.
pub fn summarize(dir: &Path) -> Result<SurfaceSummary, RunError> {
    let (manifest, trials, trials_path) = read_run(dir)?;
    let keys =
        [common::DETECTOR, common::KIND, col::SURFACE, common::SIZE_BIN, common::NOISE_BIN, common::PARAM_ERROR_BIN];
    let mut summary = aggregate(&windows(&trials), &keys).map_err(pol(&trials_path))?;
    let mut detectors = per_detector(&trials).map_err(pol(&trials_path))?;
    let mut comparison = compare(&trials, &manifest.detectors, &trials_path)?;
    let out = |name: &str| dir.join(name);
    write_table(&mut summary, &out("summary.csv"))?;
    write_parquet(&mut summary, &out("summary.parquet"))?;
    write_table(&mut detectors, &out("detectors.csv"))?;
    write_table(&mut comparison, &out("comparison.csv"))?;
    let warnings = warnings(&trials).map_err(pol(&trials_path))?;
    Ok(SurfaceSummary { summary, detectors, comparison, warnings })
}

/// The records with the per-row indicators the aggregation counts.
fn windows(trials: &DataFrame) -> LazyFrame {
    use polars::prelude::col as c;
    let flag = |e: Expr| e.fill_null(lit(false)).cast(DataType::UInt64);
    trials.clone().lazy().with_columns([
        flag(c(col::FAILURE).is_not_null()).alias("failed_flag"),
        flag(c(col::DETECTED)).alias("detected_flag"),
        flag(c(col::ISOLATED_CORRECTLY)).alias("isolated_flag"),
        flag(c(col::CLEARED)).alias("cleared_flag"),
        flag(c(col::CLEARED).is_not_null()).alias("clear_decided_flag"),
        flag(c(col::FALSE_ALARMS).gt(lit(0))).alias("false_alarm_flag"),
        flag(c(col::POST_FAULT_DECLARATIONS).gt(lit(0))).alias("post_fault_flag"),
        flag(c(col::ASYMMETRIC_STEPS).gt(lit(0))).alias("asymmetric_flag"),
        flag(c(col::NOT_POSITIVE_DEFINITE_STEPS).gt(lit(0))).alias("not_pd_flag"),
        flag(c(col::NON_FINITE_STEPS).gt(lit(0))).alias("non_finite_flag"),
        c(common::KIND).neq(lit(common::NO_FAULT)).alias("faulty"),
    ])
}

/// Group counts, rates with Wilson intervals, delay percentiles over `keys`.
fn aggregate(rows: &LazyFrame, keys: &[&str]) -> PolarsResult<DataFrame> {
    use polars::prelude::col as c;
    let sum = |flag: &str, name: &str| c(flag).sum().alias(name);
    let q = |name: &str, p: f64, alias: &str| c(name).quantile(lit(p), QuantileMethod::Linear).alias(alias);
    let mut df = rows
        .clone()
        .group_by(keys.iter().map(|k| c(*k)).collect::<Vec<_>>())
        .agg([
            len().cast(DataType::UInt64).alias("trials"),
            sum("failed_flag", "failed"),
            sum("detected_flag", "detected"),
            sum("isolated_flag", "isolated_correctly"),
            sum("clear_decided_flag", "clear_decided"),
            sum("cleared_flag", "cleared"),
            sum("false_alarm_flag", "false_alarms"),
            sum("post_fault_flag", "post_fault"),
            sum("asymmetric_flag", "asymmetric"),
            sum("not_pd_flag", "not_positive_definite"),
            sum("non_finite_flag", "non_finite"),
            c("faulty").first().alias("faulty"),
            q(col::DETECTION_DELAY_S, 0.5, "delay_p50_s"),
            q(col::DETECTION_DELAY_S, 0.9, "delay_p90_s"),
            q(col::DETECTION_DELAY_S, 0.99, "delay_p99_s"),
            q(col::ISOLATION_DELAY_S, 0.5, "isolation_delay_p50_s"),
            q(col::CLEARING_DELAY_S, 0.5, "clearing_p50_s"),
            q(col::CLEARING_DELAY_S, 0.9, "clearing_p90_s"),
            q(col::SURFACE_ESTIMATE_RMS_DEG, 0.5, "estimate_rms_p50_deg"),
        ])
        .sort(
            keys.iter().map(|k| k.to_string()).collect::<Vec<_>>(),
            SortMultipleOptions::default().with_nulls_last(true),
        )
        .collect()?;
    add_rates(&mut df)?;
    Ok(df)
}

/// Adds `pd`, `pfa`, `isolation_accuracy`, `clearing_rate`, `post_fault_rate` with 95 % Wilson
/// intervals to counts.
fn add_rates(df: &mut DataFrame) -> PolarsResult<()> {
    let (detected, isolated) = (u64_values(df, "detected")?, u64_values(df, "isolated_correctly")?);
    let (clear_decided, cleared) = (u64_values(df, "clear_decided")?, u64_values(df, "cleared")?);
    let (fa, post_fault) = (u64_values(df, "false_alarms")?, u64_values(df, "post_fault")?);
    let (flown, faulty) = flown_and_faulty(df)?;
    add_rate(df, "pd", &detected, &flown, &|i| faulty[i])?;
    add_rate(df, "pfa", &fa, &flown, &|_| true)?;
    add_rate(df, "isolation_accuracy", &isolated, &detected, &|i| faulty[i])?;
    add_rate(df, "clearing_rate", &cleared, &clear_decided, &|i| faulty[i])?;
    add_rate(df, "post_fault_rate", &post_fault, &flown, &|i| faulty[i])?;
    Ok(())
}

/// Per detector: window rates over the faulty windows, trial rates (false alarms, health) once per
/// trial, joined into one row per detector in deck order.
fn per_detector(trials: &DataFrame) -> PolarsResult<DataFrame> {
    use polars::prelude::col as c;
    let rows = windows(trials);
    let faulty = aggregate(&rows.clone().filter(c("faulty")), &[common::DETECTOR])?;
    let once = rows
        .unique_stable(Some(cols([common::TRIAL, common::DETECTOR])), UniqueKeepStrategy::First)
        .group_by_stable([c(common::DETECTOR)])
        .agg([
            len().cast(DataType::UInt64).alias("flights"),
            c("failed_flag").sum().alias("flights_failed"),
            c("false_alarm_flag").sum().alias("flights_with_false_alarm"),
            c("asymmetric_flag").sum().alias("flights_asymmetric"),
            c("not_pd_flag").sum().alias("flights_not_positive_definite"),
            c("non_finite_flag").sum().alias("flights_non_finite"),
        ])
        .collect()?;
    let mut out = faulty
        .lazy()
        .select([
            c(common::DETECTOR),
            c("trials").alias("fault_windows"),
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
            c("isolation_delay_p50_s"),
            c("cleared"),
            c("clearing_rate"),
            c("clearing_p50_s"),
            c("clearing_p90_s"),
            c("post_fault"),
            c("post_fault_rate"),
            c("post_fault_rate_lo"),
            c("post_fault_rate_hi"),
            c("estimate_rms_p50_deg"),
        ])
        .join(once.lazy(), [c(common::DETECTOR)], [c(common::DETECTOR)], JoinArgs::new(JoinType::Right))
        .collect()?;
    let flights = out.column("flights")?.u64()?.clone();
    let failed = out.column("flights_failed")?.u64()?.clone();
    let fa = out.column("flights_with_false_alarm")?.u64()?.clone();
    let mut pfa: [Vec<f64>; 3] = Default::default();
    for i in 0..out.height() {
        let n = flights.get(i).unwrap_or(0) - failed.get(i).unwrap_or(0);
        let k = fa.get(i).unwrap_or(0);
        let (lo, hi) = wilson(k, n, Z95);
        pfa[0].push(if n > 0 { k as f64 / n as f64 } else { f64::NAN });
        pfa[1].push(lo);
        pfa[2].push(hi);
    }
    let [p, lo, hi] = pfa;
    out.with_column(Column::new("pfa".into(), p))?;
    out.with_column(Column::new("pfa_lo".into(), lo))?;
    out.with_column(Column::new("pfa_hi".into(), hi))?;
    Ok(out)
}

/// Every pair of detectors on the same (trial, window) ([`PairedUnits`]).
fn compare(trials: &DataFrame, detectors: &[String], file: &Path) -> Result<DataFrame, RunError> {
    let trial = trials.column(common::TRIAL).and_then(|c| c.u64().cloned()).map_err(pol(file))?;
    let window = trials.column(col::WINDOW).and_then(|c| c.u32().cloned()).map_err(pol(file))?;
    let det = str_col(trials, common::DETECTOR, file)?;
    let kind = str_col(trials, common::KIND, file)?;
    let failure = str_col(trials, col::FAILURE, file)?;
    let bool_col = |n: &str| trials.column(n).and_then(|c| c.bool().cloned()).map_err(pol(file));
    let (detected, isolated) = (bool_col(col::DETECTED)?, bool_col(col::ISOLATED_CORRECTLY)?);
    let delay = f64_col(trials, col::DETECTION_DELAY_S, file)?;
    let clearing = f64_col(trials, col::CLEARING_DELAY_S, file)?;
    let fa = trials.column(col::FALSE_ALARMS).and_then(|c| c.u32().cloned()).map_err(pol(file))?;
    let mut units = PairedUnits::new(detectors);
    for i in 0..trials.height() {
        let w = window.get(i);
        let outcome = Outcome {
            flown: failure.get(i).is_none(),
            faulty: kind.get(i) != Some(common::NO_FAULT),
            detected: detected.get(i).unwrap_or(false),
            isolated: isolated.get(i).unwrap_or(false),
            delay_s: delay.get(i),
            clearing_s: clearing.get(i),
            false_alarm: fa.get(i).unwrap_or(0) > 0,
            first_unit_of_trial: w.is_none_or(|w| w == 0),
        };
        units
            .insert(trial.get(i).unwrap_or(0), w, det.get(i).unwrap_or_default(), outcome)
            .map_err(|e| RunError::Invalid(format!("{}: {e}", file.display())))?;
    }
    units.compare(true).map_err(pol(file))
}

/// Flights that stopped early, and covariance trouble, counted once per (trial, detector).
fn warnings(trials: &DataFrame) -> PolarsResult<Vec<String>> {
    use polars::prelude::col as c;
    let once = windows(trials)
        .unique_stable(Some(cols([common::TRIAL, common::DETECTOR])), UniqueKeepStrategy::First)
        .select([c("failed_flag").sum(), c("non_finite_flag").sum()])
        .collect()?;
    let get = |n: &str| once.column(n).and_then(|c| c.u64().map(|v| v.get(0).unwrap_or(0)));
    let mut warnings = Vec::new();
    let failed = get("failed_flag")?;
    if failed > 0 {
        warnings.push(format!("{failed} trial x detector flights stopped early (failure in trials.parquet)"));
    }
    let non_finite = get("non_finite_flag")?;
    if non_finite > 0 {
        warnings.push(format!("{non_finite} trial x detector runs had non-finite covariances (non_finite_steps)"));
    }
    Ok(warnings)
}

/// The per-detector (variant) table of a surface study (`detectors.csv`), then warnings and the files written.
pub fn print(dir: &Path, s: &SurfaceSummary) -> Result<(), RunError> {
    let t = Table(&s.detectors);
    let (names, windows, flights) = (t.strs("detector"), t.u64s("fault_windows"), t.u64s("flights"));
    let (pd, iso, pfa) = (t.rates("pd"), t.rates("isolation_accuracy"), t.rates("pfa"));
    let (delay, clear, relapse) =
        (t.delays("delay_p50_s", "delay_p90_s"), t.f64s("clearing_p50_s"), t.f64s("post_fault_rate"));
    let (asym, not_pd, non_finite) =
        (t.u64s("flights_asymmetric"), t.u64s("flights_not_positive_definite"), t.u64s("flights_non_finite"));
    println!("  per variant, paired over the same trials (see summary.csv for groups, comparison.csv for tests);");
    println!("  relapse: share of faults after which a surface is declared again; Pfa: alarms before any fault:");
    println!(
        "    {:<16} {:>7} {:<21} {:<21} {:>14} {:>10} {:>8} {:>7} {:<21} {:>16}",
        "variant",
        "faults",
        "Pd [95 % CI]",
        "isolated [95 % CI]",
        "delay p50/p90",
        "clear p50",
        "relapse",
        "flights",
        "Pfa [95 % CI]",
        "asym/notPD/NaN"
    );
    for i in 0..names.len() {
        println!(
            "    {:<16} {:>7} {:<21} {:<21} {:>14} {:>8.2} s {:>8.3} {:>7} {:<21} {:>7}/{}/{}",
            names[i],
            windows[i],
            pd[i],
            iso[i],
            delay[i],
            clear[i],
            relapse[i],
            flights[i],
            pfa[i],
            asym[i],
            not_pd[i],
            non_finite[i]
        );
    }
    print_footer(dir, &s.warnings, "summary.csv, summary.parquet, detectors.csv, comparison.csv");
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::estimation::FilterHealth;
    use crate::methods::surface_bank::actuator::{ActuatorFault, ActuatorFaultKind};
    use crate::methods::surface_bank::scenario::{ScenarioFault, SurfaceTrialSpec};
    use crate::methods::surface_bank::study::SurfaceStudy;
    use crate::methods::surface_bank::trial::{BankOutcome, SurfaceTrialResult, UavSimError, WindowOutcome};

    /// Two banks on five hand-made trials (a left aileron stuck at -15 deg from 5 s to 15 s, or none):
    /// trial 0: a isolates (0.5 s), b declares the rudder first (1.0 s); trial 1: a misses, b isolates
    /// (0.8 s); trial 2: fault-free, a false alarm by a; trial 3: the flight left the envelope; trial 4:
    /// both isolate (0.4 s, 0.6 s), and b declares twice more after the fault ended.
    fn hand_made() -> (SurfaceStudy, DataFrame) {
        let deck =
            std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/studies/seed004_surfaces.toml")).unwrap();
        let mut study = SurfaceStudy::from_toml(&deck, Path::new("seed004_surfaces.toml")).unwrap();
        study.banks.truncate(2);
        study.banks[0].0 = "a".into();
        study.banks[1].0 = "b".into();
        let fault = ActuatorFault {
            surface: 0,
            kind: ActuatorFaultKind::Stuck { position_rad: (-15f64).to_radians() },
            onset_s: 5.0,
            end_s: Some(15.0),
        };
        let spec = |trial: u64, faulty: bool| SurfaceTrialSpec {
            trial,
            faults: if faulty { vec![ScenarioFault { fault, size: -15.0, size_bin: -15.0 }] } else { vec![] },
            noise_scale: 1.0,
            noise_bin: 1.0,
            parameter_errors: vec![],
            parameter_error_bin: 0.0,
        };
        let window = |detect: Option<f64>, first: Option<usize>, clear: Option<f64>| WindowOutcome {
            surface: 0,
            onset_s: 5.0,
            end_s: 15.0,
            detection_delay_s: detect,
            isolation_delay_s: if first == Some(0) { detect } else { None },
            first_declared: first,
            clearing_delay_s: clear,
            surface_estimate_rms_rad: 0.01,
        };
        let bank = |w: Option<WindowOutcome>, false_alarms: u32| BankOutcome {
            windows: w.into_iter().collect(),
            false_alarms,
            first_false_alarm_s: (false_alarms > 0).then_some(2.0),
            post_fault_declarations: 0,
            health: FilterHealth::default(),
            floor_steps: 0,
        };
        let results = vec![
            SurfaceTrialResult {
                spec: spec(0, true),
                outcome: Ok(vec![
                    bank(Some(window(Some(0.5), Some(0), Some(0.2))), 0),
                    bank(Some(window(Some(1.0), Some(4), None)), 0),
                ]),
            },
            SurfaceTrialResult {
                spec: spec(1, true),
                outcome: Ok(vec![
                    bank(Some(window(None, None, None)), 0),
                    bank(Some(window(Some(0.8), Some(0), Some(4.0))), 0),
                ]),
            },
            SurfaceTrialResult { spec: spec(2, false), outcome: Ok(vec![bank(None, 1), bank(None, 0)]) },
            SurfaceTrialResult {
                spec: spec(3, true),
                outcome: Err(UavSimError::Envelope { t_s: 9.0, what: "altitude below 0".into() }),
            },
            SurfaceTrialResult {
                spec: spec(4, true),
                outcome: Ok(vec![
                    bank(Some(window(Some(0.4), Some(0), Some(0.3))), 0),
                    BankOutcome { post_fault_declarations: 2, ..bank(Some(window(Some(0.6), Some(0), Some(0.5))), 0) },
                ]),
            },
        ];
        let df = crate::methods::surface_bank::records::frame(&study, &results).unwrap();
        (study, df)
    }

    #[test]
    fn summary_counts_rates_and_paired_differences_of_hand_made_trials() {
        let (_, df) = hand_made();
        assert_eq!(df.height(), 10, "one row per trial and bank");
        let keys = [common::DETECTOR, common::KIND, col::SURFACE, common::SIZE_BIN];
        let summary = aggregate(&windows(&df), &keys).unwrap();
        let u = |n: &str| -> Vec<u64> {
            let c = summary.column(n).unwrap().cast(&DataType::UInt64).unwrap();
            c.u64().unwrap().into_no_null_iter().collect()
        };
        let f = |n: &str| -> Vec<Option<f64>> {
            let c = summary.column(n).unwrap().f64().unwrap().clone();
            (0..c.len()).map(|i| c.get(i)).collect()
        };
        // Rows: (a, none), (a, stuck), (b, none), (b, stuck): sorted by detector, then kind.
        let kinds = summary.column(common::KIND).unwrap().str().unwrap().clone();
        let kinds: Vec<_> = (0..kinds.len()).map(|i| kinds.get(i).unwrap().to_string()).collect();
        assert_eq!(kinds, ["none", "stuck", "none", "stuck"]);
        assert_eq!(u("trials"), [1, 4, 1, 4]);
        assert_eq!(u("failed"), [0, 1, 0, 1]);
        assert_eq!(u("detected"), [0, 2, 0, 3]);
        assert_eq!(u("isolated_correctly"), [0, 2, 0, 2]);
        assert_eq!(u("false_alarms"), [1, 0, 0, 0]);
        assert_eq!(u("post_fault"), [0, 0, 0, 1]);
        assert_eq!(f("post_fault_rate")[3], Some(1.0 / 3.0));
        assert_eq!(f("post_fault_rate")[2], None, "no fault, nothing after one");
        assert_eq!(f("pd")[1], Some(2.0 / 3.0));
        assert_eq!(f("pd")[3], Some(1.0));
        assert_eq!(f("pd")[0], None, "no detection probability without a fault");
        assert_eq!(f("isolation_accuracy")[3], Some(2.0 / 3.0));
        assert_eq!(f("pfa")[0], Some(1.0));
        assert_eq!(f("delay_p50_s")[1], Some(0.45));
        assert_eq!(f("clearing_rate")[3], Some(1.0), "b cleared both faults it isolated");
        let (lo, hi) = wilson(2, 3, Z95);
        assert_eq!((f("pd_lo")[1], f("pd_hi")[1]), (Some(lo), Some(hi)));

        let c = compare(&df, &["a".into(), "b".into()], Path::new("t")).unwrap();
        let cu = |n: &str| c.column(n).unwrap().u64().unwrap().get(0).unwrap();
        assert_eq!(c.height(), 1);
        assert_eq!(cu("fault_windows"), 3, "trials 0, 1, 4: trial 3 did not fly to the end");
        assert_eq!((cu("detected_by_a_only"), cu("detected_by_b_only")), (0, 1));
        assert_eq!((cu("isolated_by_a_only"), cu("isolated_by_b_only")), (1, 1));
        assert_eq!((cu("flights"), cu("false_alarm_a_only"), cu("false_alarm_b_only")), (4, 1, 0));
        assert_eq!(cu("delay_pairs"), 2);
        let diff = c.column("median_delay_b_minus_a_s").unwrap().f64().unwrap().get(0).unwrap();
        assert!((diff - 0.35).abs() < 1e-12, "median of 1.0 - 0.5 and 0.6 - 0.4: {diff}");
        let p = c.column("mcnemar_p_detection").unwrap().f64().unwrap().get(0).unwrap();
        assert_eq!(p, 1.0);

        let v = per_detector(&df).unwrap();
        let vu = |n: &str| -> Vec<u64> { v.column(n).unwrap().u64().unwrap().into_no_null_iter().collect() };
        assert_eq!(vu("flights"), [5, 5]);
        assert_eq!(vu("flights_failed"), [1, 1]);
        assert_eq!(vu("flights_with_false_alarm"), [1, 0]);
        assert_eq!(vu("detected"), [2, 3]);
        let pfa: Vec<f64> = v.column("pfa").unwrap().f64().unwrap().into_no_null_iter().collect();
        assert_eq!(pfa, [0.25, 0.0]);
    }
}
