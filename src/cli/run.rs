use std::io::IsTerminal;
use std::path::{Path, PathBuf};

use crate::cli::CliError;
use crate::engine::deck::deck_kind;
use crate::engine::runner::{self, Manifest, RunError, RunOptions, Shard, StudyKind};
use crate::methods::accelerometer::AccelerometerTrials;
use crate::methods::accelerometer::study::AccelerometerStudy;
use crate::methods::accelerometer::summary::AccelerometerSummary;
use crate::methods::accelerometer::trial::TrainedClassifiers;
use crate::methods::air_data::AirDataTrials;
use crate::methods::air_data::study::AirDataStudy;
use crate::methods::air_data::summary::AirDataSummary;
use crate::methods::detection_filter::study::Study;
use crate::methods::detection_filter::summary::{Calibration, SummaryReport};
use crate::methods::surface_bank::SurfaceTrials;
use crate::methods::surface_bank::study::SurfaceStudy;
use crate::methods::surface_bank::summary::SurfaceSummary;
use crate::methods::thrust_loss::LaunchTrials;
use crate::methods::thrust_loss::study::LaunchStudy;
use crate::methods::thrust_loss::summary::LaunchSummary;

impl From<RunError> for CliError {
    fn from(e: RunError) -> Self {
        match e {
            RunError::Invalid(m) => CliError::Invalid(m),
            other => CliError::Internal(other.to_string()),
        }
    }
}

pub struct RunArgs<'a> {
    pub deck: &'a Path,
    pub trials: Option<u64>,
    pub seed: Option<u64>,
    pub threads: Option<usize>,
    pub out: Option<PathBuf>,
    pub shard: Option<&'a str>,
    pub resume: bool,
    pub force: bool,
    pub quiet: bool,
    pub stop_after: Option<u64>,
    /// Accelerometer decks: classifiers to evaluate instead of training them.
    pub classifiers: Option<&'a Path>,
}

/// A deck of either kind, with the command line's overrides applied.
enum Loaded {
    Lti(Study),
    Surfaces(SurfaceStudy),
    AirData(AirDataStudy),
    Launch(LaunchStudy),
    Accelerometer(AccelerometerStudy),
}

impl Loaded {
    fn load(a: &RunArgs) -> Result<Loaded, CliError> {
        let text = crate::engine::deck::read_deck(a.deck)?;
        let mut loaded = match deck_kind(&text) {
            StudyKind::SurfaceBank => Loaded::Surfaces(SurfaceStudy::from_toml(&text, a.deck)?),
            StudyKind::AirData => Loaded::AirData(AirDataStudy::from_toml(&text, a.deck)?),
            StudyKind::ThrustLoss => Loaded::Launch(LaunchStudy::from_toml(&text, a.deck)?),
            StudyKind::Accelerometer => Loaded::Accelerometer(AccelerometerStudy::from_toml(&text, a.deck)?),
            StudyKind::DetectionFilter => Loaded::Lti(Study::from_toml(&text, a.deck)?),
        };
        if let Some(n) = a.trials {
            if n == 0 || n > crate::engine::streams::MAX_TRIAL {
                return Err(CliError::Invalid(format!(
                    "--trials {n}: allowed 1 to {}",
                    crate::engine::streams::MAX_TRIAL
                )));
            }
            match &mut loaded {
                Loaded::Lti(s) => s.monte_carlo.trials = n,
                Loaded::Surfaces(s) => s.monte_carlo.trials = n,
                Loaded::AirData(s) => s.monte_carlo.trials = n,
                Loaded::Launch(s) => s.monte_carlo.trials = n,
                Loaded::Accelerometer(s) => s.trials = n,
            }
        }
        if let Some(seed) = a.seed {
            match &mut loaded {
                Loaded::Lti(s) => s.seed = seed,
                Loaded::Surfaces(s) => s.seed = seed,
                Loaded::AirData(s) => s.seed = seed,
                Loaded::Launch(s) => s.seed = seed,
                Loaded::Accelerometer(s) => s.seed = seed,
            }
        }
        Ok(loaded)
    }

    fn name(&self) -> &str {
        match self {
            Loaded::Lti(s) => &s.name,
            Loaded::Surfaces(s) => &s.name,
            Loaded::AirData(s) => &s.name,
            Loaded::Launch(s) => &s.name,
            Loaded::Accelerometer(s) => &s.name,
        }
    }
}

pub fn exec_run(a: RunArgs) -> Result<PathBuf, CliError> {
    let shard = match a.shard {
        Some(s) => Shard::parse(s).map_err(|e| CliError::Invalid(format!("--shard {e}")))?,
        None => Shard::WHOLE,
    };
    if a.threads == Some(0) {
        return Err(CliError::Invalid("--threads 0: give at least 1 (or leave it out for one per core)".into()));
    }
    let study = Loaded::load(&a)?;
    let out_dir = a.out.clone().unwrap_or_else(|| {
        let base = PathBuf::from("results").join(study.name());
        if shard == Shard::WHOLE { base } else { base.join(format!("shard-{}-of-{}", shard.index, shard.count)) }
    });
    let opts = RunOptions {
        deck: a.deck.into(),
        out_dir: out_dir.clone(),
        threads: a.threads,
        shard,
        resume: a.resume,
        force: a.force,
        progress: !a.quiet && std::io::stderr().is_terminal(),
        stop_after_chunks: a.stop_after,
        command_line: std::env::args().collect(),
    };
    let report = match &study {
        Loaded::Lti(study) => crate::methods::detection_filter::run_study(study, &opts)?,
        Loaded::Surfaces(study) => {
            let trials = SurfaceTrials::new(study);
            runner::run(&trials, trials.manifest(), &opts)?
        }
        Loaded::AirData(study) => {
            let trials = AirDataTrials::new(study);
            runner::run(&trials, trials.manifest(), &opts)?
        }
        Loaded::Launch(study) => {
            // Designs and loss tables are the deck's: one that cannot be designed is invalid input.
            let trials =
                LaunchTrials::new(study).map_err(|e| CliError::Invalid(format!("{}: {e}", study.path.display())))?;
            runner::run(&trials, trials.manifest(), &opts)?
        }
        Loaded::Accelerometer(study) => {
            // Classifiers from a file, from the folder being resumed, or trained now; written beside the
            // results once the run has started, so a refused run leaves the folder as it was.
            let beside = out_dir.join("classifiers.json");
            let (classifiers, write_beside) = match a.classifiers {
                Some(file) => (TrainedClassifiers::load(file)?, true),
                None if a.resume && beside.exists() => (TrainedClassifiers::load(&beside)?, false),
                None => {
                    if !a.quiet {
                        eprintln!(
                            "training the classifiers on {} trials per class (seed {})",
                            study.training.trials_per_class, study.training.seed
                        );
                    }
                    (
                        TrainedClassifiers::train(study)
                            .map_err(|e| CliError::Invalid(format!("{}: {e}", study.path.display())))?,
                        true,
                    )
                }
            };
            let trials = AccelerometerTrials::new(study, &classifiers);
            let report = runner::run(&trials, trials.manifest(), &opts)?;
            if write_beside {
                classifiers.save(&beside)?;
            }
            report
        }
    };
    let m = &report.manifest;
    if !a.quiet {
        let n = m.end_trial - m.first_trial;
        let rate = if report.seconds > 0.0 { report.trials_run as f64 / report.seconds } else { f64::NAN };
        println!(
            "{}: trials {}..{} of {} ({} run, {} resumed) x {} detector(s) in {:.1} s ({:.0} trials/s) -> {}",
            m.study,
            m.first_trial,
            m.end_trial,
            m.trials,
            report.trials_run,
            report.trials_resumed,
            m.detectors.len(),
            report.seconds,
            rate,
            out_dir.join("trials.parquet").display()
        );
        if n == 0 {
            println!("  (this shard holds no trials)");
        }
    }
    if !m.complete {
        println!(
            "  stopped after {} part file(s): continue with the same command and --resume",
            a.stop_after.unwrap_or(0)
        );
        return Ok(out_dir);
    }
    if shard == Shard::WHOLE {
        let summary = summarize(&out_dir, m, None)?;
        if !a.quiet {
            summary.print(&out_dir)?;
        }
    } else if !a.quiet {
        println!("  shard done: join the shards with `fdimc merge <shard dirs>... --out DIR` to get the summary");
    }
    Ok(out_dir)
}

/// The summaries of either kind of study.
enum Summary {
    Lti(SummaryReport),
    Surfaces(SurfaceSummary),
    AirData(AirDataSummary),
    Launch(LaunchSummary),
    Accelerometer(AccelerometerSummary),
}

impl Summary {
    fn print(&self, dir: &Path) -> Result<(), CliError> {
        match self {
            Summary::Lti(s) => print_summary(dir, s),
            Summary::Surfaces(s) => print_surface_summary(dir, s),
            Summary::AirData(s) => print_air_data_summary(dir, s),
            Summary::Launch(s) => print_launch_summary(dir, s),
            Summary::Accelerometer(s) => print_accelerometer_summary(dir, s),
        }
    }
}

/// Writes the summaries of the run in `dir`; `calibration` (LTI studies only) defaults to the deck's
/// target false-alarm probability.
fn summarize(dir: &Path, manifest: &Manifest, calibration: Option<Calibration>) -> Result<Summary, CliError> {
    Ok(match manifest.kind {
        StudyKind::DetectionFilter => Summary::Lti(crate::methods::detection_filter::summary::summarize(
            dir,
            &calibration.unwrap_or(Calibration::Target(manifest.target_pfa)),
        )?),
        StudyKind::SurfaceBank | StudyKind::AirData | StudyKind::Accelerometer if calibration.is_some() => {
            return Err(CliError::Invalid(format!(
                "{}: this study's detectors declare by model probabilities (the deck's 0.9 / 0.05): \
                 --target-pfa and --thresholds apply to detection-filter and thrust-loss studies",
                dir.display()
            )));
        }
        StudyKind::ThrustLoss => Summary::Launch(crate::methods::thrust_loss::summary::summarize(
            dir,
            match calibration {
                None => manifest.target_pfa,
                Some(Calibration::Target(p)) => p,
                Some(Calibration::File(_)) => {
                    return Err(CliError::Invalid(format!(
                        "{}: --thresholds reads a detection filter's thresholds.csv; use --target-pfa here",
                        dir.display()
                    )));
                }
            },
        )?),
        StudyKind::SurfaceBank => Summary::Surfaces(crate::methods::surface_bank::summary::summarize(dir)?),
        StudyKind::AirData => Summary::AirData(crate::methods::air_data::summary::summarize(dir)?),
        StudyKind::Accelerometer => Summary::Accelerometer(crate::methods::accelerometer::summary::summarize(dir)?),
    })
}

pub fn exec_summarize(dir: &Path, target_pfa: Option<f64>, thresholds: Option<&Path>) -> Result<(), CliError> {
    let manifest = Manifest::read(dir)?;
    let calibration = match (target_pfa, thresholds) {
        (Some(_), Some(_)) => return Err(CliError::Invalid("give --target-pfa or --thresholds, not both".into())),
        (_, Some(f)) => Some(Calibration::File(f.into())),
        (Some(p), None) if p > 0.0 && p < 1.0 => Some(Calibration::Target(p)),
        (Some(p), None) => return Err(CliError::Invalid(format!("--target-pfa {p}: allowed 0 < p < 1"))),
        (None, None) => None,
    };
    summarize(dir, &manifest, calibration)?.print(dir)
}

pub fn exec_merge(dirs: &[PathBuf], out: &Path, force: bool) -> Result<(), CliError> {
    if dirs.is_empty() {
        return Err(CliError::Invalid("name the shard folders to merge".into()));
    }
    let mut manifests = Vec::with_capacity(dirs.len());
    for d in dirs {
        let m = Manifest::read(d)?;
        if !m.complete || !d.join("trials.parquet").exists() {
            return Err(CliError::Invalid(format!(
                "{}: shard not complete: finish it with `fdimc run ... --resume`",
                d.display()
            )));
        }
        manifests.push((d.clone(), m));
    }
    manifests.sort_by_key(|(_, m)| m.shard.index);
    let first = &manifests[0].1;
    let count = first.shard.count;
    for (d, m) in &manifests {
        if m.deck_sha256 != first.deck_sha256
            || m.seed != first.seed
            || m.trials != first.trials
            || m.shard.count != count
        {
            return Err(CliError::Invalid(format!(
                "{}: from another run (deck, seed, trial count or shard count differ from {})",
                d.display(),
                manifests[0].0.display()
            )));
        }
    }
    let indices: Vec<u64> = manifests.iter().map(|(_, m)| m.shard.index).collect();
    if indices != (0..count).collect::<Vec<_>>() {
        return Err(CliError::Invalid(format!("need shards 0..{count} exactly once each, got {indices:?}")));
    }
    if out.join("manifest.json").exists() && !force {
        return Err(CliError::Invalid(format!(
            "{}: already holds a run; use --force to replace it, or another --out",
            out.display()
        )));
    }
    std::fs::create_dir_all(out).map_err(|e| CliError::Internal(format!("{}: {e}", out.display())))?;
    let inputs: Vec<PathBuf> =
        manifests.iter().filter(|(_, m)| m.rows > 0).map(|(d, _)| d.join("trials.parquet")).collect();
    runner::concatenate(&inputs, &out.join("trials.parquet"))?;
    let rows = manifests.iter().map(|(_, m)| m.rows).sum();
    let merged = Manifest {
        shard: Shard::WHOLE,
        first_trial: 0,
        end_trial: first.trials,
        rows,
        complete: true,
        command_line: std::env::args().collect(),
        ..first.clone()
    };
    merged.write(out)?;
    println!("merged {} shards: {} rows -> {}", manifests.len(), rows, out.join("trials.parquet").display());
    summarize(out, &merged, None)?.print(out)
}

pub fn exec_check(target: &Path, baseline: &Path, alpha: f64, threads: Option<usize>) -> Result<bool, CliError> {
    if !(alpha > 0.0 && alpha < 1.0) {
        return Err(CliError::Invalid(format!("--alpha {alpha}: allowed 0 < alpha < 1")));
    }
    let base = crate::engine::summary::read_summary(baseline)?;
    let (current, scratch) = if target.is_dir() {
        (crate::engine::summary::read_summary(&target.join("summary.csv"))?, None)
    } else {
        let scratch = std::env::temp_dir().join(format!("fdimc-check-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&scratch);
        let args = RunArgs {
            deck: target,
            trials: None,
            seed: None,
            threads,
            out: Some(scratch.clone()),
            shard: None,
            resume: false,
            force: true,
            quiet: true,
            stop_after: None,
            classifiers: None,
        };
        let dir = exec_run(args)?;
        (crate::engine::summary::read_summary(&dir.join("summary.csv"))?, Some(scratch))
    };
    let verdict = crate::engine::check::compare(&current, &base, alpha);
    if let Some(s) = scratch {
        let _ = std::fs::remove_dir_all(s);
    }
    let verdict = verdict?;
    for r in &verdict.regressions {
        println!("REGRESSION {r}");
    }
    for g in &verdict.only_in_baseline {
        println!("warning: group only in the baseline: {g}");
    }
    for g in &verdict.only_in_current {
        println!("warning: group not in the baseline: {g}");
    }
    println!(
        "{}: {} groups compared, {} tests at family-wise alpha {alpha}: {} regression(s)",
        baseline.display(),
        verdict.compared_groups,
        verdict.tests,
        verdict.regressions.len()
    );
    Ok(verdict.regressions.is_empty())
}

fn print_summary(dir: &Path, s: &SummaryReport) -> Result<(), CliError> {
    println!("  thresholds: {}", s.calibration_source);
    for t in &s.thresholds {
        let pfa =
            if t.calibration_trials > 0 { t.whole_false_alarms as f64 / t.calibration_trials as f64 } else { f64::NAN };
        println!(
            "    {}: [{}] (Pfa achieved {:.4} on {} calibration trials)",
            t.detector,
            t.whole.iter().map(|v| format!("{v:.4}")).collect::<Vec<_>>().join(", "),
            pfa,
            t.calibration_trials
        );
    }
    use polars::prelude::*;
    let internal = |e: PolarsError| CliError::Internal(e.to_string());
    let overall = s
        .summary
        .clone()
        .lazy()
        .filter(col("kind").neq(lit("none")))
        .group_by_stable([col("thresholds"), col("detector"), col("kind")])
        .agg([(col("trials") - col("design_failures")).sum().alias("n"), col("detected").sum().alias("detected")])
        .sort(["thresholds", "detector", "kind"], Default::default())
        .collect()
        .map_err(internal)?;
    println!("  detection probability over all sizes (see summary.csv for groups):");
    let text = |n: &str| overall.column(n).and_then(|c| c.str().cloned()).map_err(internal);
    let count = |n: &str| overall.column(n).and_then(|c| c.u64().cloned()).map_err(internal);
    let (set, det, kind, n, detected) =
        (text("thresholds")?, text("detector")?, text("kind")?, count("n")?, count("detected")?);
    for i in 0..overall.height() {
        let (n, k) = (n.get(i).unwrap_or(0), detected.get(i).unwrap_or(0));
        println!(
            "    {:<10} {:<12} {:<14} {:>6}/{:<6} = {:.3}",
            set.get(i).unwrap_or(""),
            det.get(i).unwrap_or(""),
            kind.get(i).unwrap_or(""),
            k,
            n,
            k as f64 / n.max(1) as f64
        );
    }
    for w in &s.warnings {
        println!("  warning: {w}");
    }
    let mut files = vec!["thresholds.csv", "summary.csv", "summary.parquet", "curves.csv", "min_detectable.csv"];
    if s.comparison.is_some() {
        files.push("comparison.csv");
    }
    println!("  wrote {} in {}", files.join(", "), dir.display());
    Ok(())
}

/// A summary table's columns as plain values for printing: a missing column or a null prints as NaN
/// (numbers), 0 (counts) or "" (text).
struct Table<'a>(&'a polars::prelude::DataFrame);

impl Table<'_> {
    fn f64s(&self, name: &str) -> Vec<f64> {
        use polars::prelude::*;
        let column = self.0.column(name).and_then(|c| c.cast(&DataType::Float64));
        let values = column.as_ref().ok().and_then(|c| c.f64().ok());
        (0..self.0.height()).map(|i| values.and_then(|v| v.get(i)).unwrap_or(f64::NAN)).collect()
    }

    fn u64s(&self, name: &str) -> Vec<u64> {
        use polars::prelude::*;
        let column = self.0.column(name).and_then(|c| c.cast(&DataType::UInt64));
        let values = column.as_ref().ok().and_then(|c| c.u64().ok());
        (0..self.0.height()).map(|i| values.and_then(|v| v.get(i)).unwrap_or(0)).collect()
    }

    fn strs(&self, name: &str) -> Vec<String> {
        let values = self.0.column(name).ok().and_then(|c| c.str().ok());
        (0..self.0.height()).map(|i| values.and_then(|v| v.get(i)).unwrap_or("").to_string()).collect()
    }

    /// `rate [lo, hi]` per row from the columns `name`, `name_lo`, `name_hi`; "-" where there is no rate.
    fn rates(&self, name: &str) -> Vec<String> {
        let (rate, lo, hi) = (self.f64s(name), self.f64s(&format!("{name}_lo")), self.f64s(&format!("{name}_hi")));
        (0..rate.len())
            .map(|i| if rate[i].is_nan() { "-".into() } else { format!("{:.3} [{:.3}, {:.3}]", rate[i], lo[i], hi[i]) })
            .collect()
    }

    /// `p50/p90 s` per row from two percentile columns.
    fn delays(&self, p50: &str, p90: &str) -> Vec<String> {
        let (a, b) = (self.f64s(p50), self.f64s(p90));
        a.iter().zip(&b).map(|(a, b)| format!("{a:.2}/{b:.2} s")).collect()
    }
}

/// The per-detector (variant) table of a surface study (`detectors.csv`), then warnings and the files written.
fn print_surface_summary(dir: &Path, s: &SurfaceSummary) -> Result<(), CliError> {
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

/// The per-detector table of an air-data study (`detectors.csv`), then warnings and the files written.
fn print_air_data_summary(dir: &Path, s: &AirDataSummary) -> Result<(), CliError> {
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

/// The thresholds and per-detector table of a launch study (`detectors.csv`).
fn print_launch_summary(dir: &Path, s: &LaunchSummary) -> Result<(), CliError> {
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

/// Warnings, then the files written.
fn print_footer(dir: &Path, warnings: &[String], files: &str) {
    for w in warnings {
        println!("  warning: {w}");
    }
    println!("  wrote {files} in {}", dir.display());
}

pub fn exec_report(dir: &Path, trials: &[u64]) -> Result<(), CliError> {
    let report = crate::methods::detection_filter::report::write_report(dir, trials)?;
    for w in &report.warnings {
        println!("warning: {w}");
    }
    if let Some(page) = report.files.last() {
        println!("{} plots -> {}", report.files.len() - 1, page.display());
    }
    Ok(())
}

/// `fdimc train`: trains an accelerometer deck's classifiers and writes them.
pub fn exec_train(deck: &Path, out: Option<PathBuf>) -> Result<(), CliError> {
    let study = AccelerometerStudy::load(deck)?;
    let out = out.unwrap_or_else(|| PathBuf::from("results").join(&study.name).join("classifiers.json"));
    if let Some(parent) = out.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent).map_err(|e| CliError::Internal(format!("{}: {e}", parent.display())))?;
    }
    let started = std::time::Instant::now();
    let trained =
        TrainedClassifiers::train(&study).map_err(|e| CliError::Invalid(format!("{}: {e}", deck.display())))?;
    trained.save(&out)?;
    println!(
        "{}: trained the SVM decision tree and the one-against-one SVM on {} trials per class (seed {}) in {:.1} s -> {}",
        study.name,
        study.training.trials_per_class,
        study.training.seed,
        started.elapsed().as_secs_f64(),
        out.display()
    );
    if let Some(tree) = trained.tree.tree() {
        for (k, m) in tree.merges.iter().enumerate() {
            let names = |c: &[crate::methods::accelerometer::ekf_svm::FaultClass]| {
                c.iter().map(|c| c.name()).collect::<Vec<_>>().join("+")
            };
            println!(
                "  merge {}: {} | {} (separability {:.3}, the least of the {} pairs)",
                k + 1,
                names(&m.positive),
                names(&m.negative),
                m.separability,
                m.candidates.len()
            );
        }
    }
    Ok(())
}

/// The confusion matrices and per-classifier table of an accelerometer study.
fn print_accelerometer_summary(dir: &Path, s: &AccelerometerSummary) -> Result<(), CliError> {
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
