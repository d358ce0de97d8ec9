//! `run`, `summarize`, `merge`, `check`, `report`, `train`: each finds the study's method in the registry
//! (by the deck's marker table or the results folder's kind) and lets the engine do the rest.

use std::path::{Path, PathBuf};

use crate::cli::{CliError, Placement, RareEventArgs, RunFolder, WorstCaseArgs};
use crate::engine::method::{self, Inputs, Method, Opt, Study};
use crate::engine::results::summary;
use crate::engine::results::thresholds::Calibration;
use crate::engine::run::runner::{self, FmuProcesses, Manifest, RunError, RunOptions, Shard};

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
    pub folder: RunFolder,
    /// Classifiers to evaluate instead of training them ([`Opt::Classifiers`]).
    pub classifiers: Option<&'a Path>,
    /// `--precision W` and the rates it watches.
    pub precision: Option<f64>,
    pub precision_rates: Vec<String>,
    /// `fdimc sensitivity`'s design and the thresholds its outcomes are read at.
    pub sensitivity: Option<SensitivityArgs>,
}

/// `fdimc sensitivity`: base samples and bootstrap resamples of its design, and another run's
/// `thresholds.csv` to read the outcomes at (default: the deck's thresholds).
pub struct SensitivityArgs {
    pub base_samples: u64,
    pub bootstrap: u64,
    pub thresholds: Option<PathBuf>,
}

/// Refuses `--threads 0` and sets `--seed`; the results folder (`sub` under the study's by default) and
/// the shard, and whether the scheduler gave it (`--shard auto`).
fn place(p: &Placement, study: &mut dyn Study, sub: Option<&str>) -> Result<(PathBuf, Shard, bool), CliError> {
    if p.threads == Some(0) {
        return Err(CliError::Invalid("--threads 0: give at least 1 (or leave it out for one per core)".into()));
    }
    let (shard, auto) = shard_of(p.shard.as_deref())?;
    if let Some(seed) = p.seed {
        *study.seed_and_trials().0 = seed;
    }
    Ok((results_folder(p.out.as_deref(), &study.header().name, sub, shard, auto), shard, auto))
}

/// `--shard`: `I/N`, or the scheduler's array task (`auto`); whether it was `auto`.
fn shard_of(text: Option<&str>) -> Result<(Shard, bool), CliError> {
    match text {
        Some(s) => {
            Shard::from_arg(s, |name| std::env::var(name).ok()).map_err(|e| CliError::Invalid(format!("--shard {e}")))
        }
        None => Ok((Shard::WHOLE, false)),
    }
}

/// The results folder of a run: `--out`, or `results/<study>[/<sub>]`; a shard's folder under it when
/// the shard is the default's or the scheduler's (array tasks that share one `--out` cannot collide).
fn results_folder(out: Option<&Path>, study: &str, sub: Option<&str>, shard: Shard, auto: bool) -> PathBuf {
    let whole = || {
        let base = PathBuf::from("results").join(study);
        sub.map_or(base.clone(), |s| base.join(s))
    };
    match out {
        Some(dir) if !auto => dir.to_path_buf(),
        given => {
            let base = given.map_or_else(whole, Path::to_path_buf);
            if shard == Shard::WHOLE { base } else { base.join(shard.folder()) }
        }
    }
}

/// The shared summary of the run in `dir`, with what `method` adds, or the indices of a sensitivity run;
/// printed unless `print` is false.
/// A run in which more than this share of the trial x detector units failed (an FMU that errors, a
/// design that fails for most models) exits 2 after writing its tables: its rates rest on the few that
/// flew, if any. Half is fdimc's choice.
const MOST_FAILED: f64 = 0.5;

/// Refuses a run whose units mostly failed, saying how many and the first failure's reason.
fn refuse_mostly_failed(dir: &Path, units: u64, failed: u64) -> Result<(), CliError> {
    if units == 0 || (failed as f64) <= MOST_FAILED * units as f64 {
        return Ok(());
    }
    let (manifest, path) = crate::engine::results::tables::complete_run(dir)?;
    let (_, first) = crate::engine::results::tables::failures(&path, manifest.rows as usize)?;
    Err(CliError::Invalid(format!(
        "{}: {failed} of {units} trial x detector units failed (not flown to the end), so its rates rest on the {} \
         that flew; the first failure: {}. The tables are written; see `failure` in trials.parquet",
        dir.display(),
        units - failed,
        first.as_deref().unwrap_or("(not recorded)")
    )))
}

fn summarize(method: &Method, dir: &Path, calibration: Option<&Calibration>, print: bool) -> Result<(), CliError> {
    if Manifest::read(dir)?.sensitivity.is_some() {
        let thresholds = match calibration {
            Some(Calibration::File(f)) => Some(f.as_path()),
            _ => None,
        };
        let indices = crate::engine::sensitivity::analyse(dir, thresholds)?;
        if print {
            crate::engine::sensitivity::print(&indices)?;
            println!("\n-> {}", dir.join("sensitivity.csv").display());
        }
        return Ok(());
    }
    let spec = method.summary;
    // The run's deck, where it is unchanged, checks the per-hour conversion by the residual's exact
    // law (read only when the summary asks).
    let manifest = Manifest::read(dir)?;
    let laws = std::cell::OnceCell::new();
    let law = |d: usize, statistics: &[String], thresholds: &[f64]| {
        let laws = laws.get_or_init(|| method.hour_laws_of_run(&manifest, statistics));
        Some(laws.get(d)?.as_ref()?(thresholds))
    };
    let s = summary::summarize(dir, &spec, calibration, Some(&law))?;
    if print {
        summary::print(&spec, &s);
    }
    refuse_mostly_failed(dir, s.units, s.failed_units)
}

/// The commands over the kinds of study this command line knows: fdimc's own and, through
/// [`crate::cli::main_with`], a caller's.
pub struct Kinds(pub &'static [&'static Method]);

impl Kinds {
    /// The deck's method and study, with `--classifiers` checked against what the method takes.
    pub fn load(&self, deck: &Path, classifiers: Option<&Path>) -> Result<(&'static Method, Box<dyn Study>), CliError> {
        let (method, study) = method::load(self.0, deck)?;
        if classifiers.is_some() {
            method::require(self.0, method, Opt::Classifiers)?;
        }
        Ok((method, study))
    }

    /// The method of the run in `dir`, from its manifest.
    fn method_of_run(&self, dir: &Path) -> Result<(&'static Method, Manifest), CliError> {
        let manifest = Manifest::read(dir)?;
        let method =
            method::find(self.0, &manifest.kind).map_err(|e| CliError::Invalid(format!("{}: {e}", dir.display())))?;
        Ok((method, manifest))
    }

    pub fn exec_run(&self, a: RunArgs) -> Result<PathBuf, CliError> {
        let f = &a.folder;
        let (method, mut study) = self.load(a.deck, a.classifiers)?;
        if let Some(n) = a.trials {
            if n == 0 || n > crate::engine::scenario::streams::MAX_TRIAL {
                return Err(CliError::Invalid(format!(
                    "--trials {n}: allowed 1 to {}",
                    crate::engine::scenario::streams::MAX_TRIAL
                )));
            }
            *study.seed_and_trials().1 = n;
        }
        if let Some(r) = f.profile_resolution {
            use crate::engine::results::schema::ProfileGrid;
            if !ProfileGrid::valid(r) {
                return Err(CliError::Invalid(format!("--profile-resolution {r}: allowed {}", ProfileGrid::ALLOWED)));
            }
            study.monte_carlo().profile = ProfileGrid::new(r);
        }
        if f.fmu_processes {
            method::require(self.0, method, Opt::FmuProcesses)?;
        }
        let sub = a.sensitivity.is_some().then_some("sensitivity");
        let (out_dir, shard, auto) = place(&f.place, study.as_mut(), sub)?;
        let design = match &a.sensitivity {
            Some(SensitivityArgs { base_samples, bootstrap, thresholds }) => {
                method::require(self.0, method, Opt::Sensitivity)?;
                if let Some(f) = thresholds {
                    // A bad file is refused before any trial is flown.
                    crate::engine::results::thresholds::read_thresholds(f)?;
                }
                let design = study.sensitivity_design(*base_samples, *bootstrap)?;
                if !f.quiet {
                    for part in &design.parts {
                        let names: Vec<&str> = part.factors.iter().map(|f| f.name.as_str()).collect();
                        println!(
                            "{} trials: {} factors ({}): {} trials",
                            if part.fault_free { "fault-free" } else { "faulty" },
                            names.len(),
                            names.join(", "),
                            base_samples * (names.len() as u64 + 2)
                        );
                    }
                }
                Some(design)
            }
            None => None,
        };
        if auto && !f.quiet {
            println!("shard {}/{} from the scheduler's array task -> {}", shard.index, shard.count, out_dir.display());
        }
        let opts = RunOptions {
            deck: a.deck.into(),
            out_dir: out_dir.clone(),
            threads: f.place.threads,
            shard,
            resume: f.resume,
            force: f.force,
            progress: !f.quiet,
            stop_after_chunks: f.stop_after,
            stop: match a.precision {
                Some(w) => {
                    let monitor = summary::PrecisionMonitor::new(&method.summary, w, &a.precision_rates)
                        .map_err(CliError::Invalid)?;
                    Some(runner::StopHandle(std::sync::Arc::new(std::sync::Mutex::new(monitor))))
                }
                None => None,
            },
            sensitivity: design,
            command_line: std::env::args().collect(),
            fmu_processes: match (f.fmu_processes, f.fmu_in_process) {
                (true, _) => FmuProcesses::Always,
                (false, true) => FmuProcesses::InProcess,
                (false, false) => FmuProcesses::Auto,
            },
            low_disk: f.low_disk,
        };
        let report = study.run(&opts, Inputs { classifiers: a.classifiers, quiet: f.quiet })?;
        let m = &report.manifest;
        if !f.quiet {
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
        if let (Some(p), false) = (&m.precision, f.quiet) {
            if p.met {
                println!(
                    "  precision {} reached at {} of at most {} trials: all {} watched rates ({}) have a 95 % half-width <= {}; the last to get there: {}",
                    p.half_width,
                    m.end_trial,
                    m.trials,
                    p.watched,
                    p.rates.join(", "),
                    p.half_width,
                    p.widest
                );
            } else {
                println!(
                    "  warning: the cap of {} trials came first: {} of {} watched rates are still wider than {}; the widest: {} (run again with a larger --trials)",
                    m.trials, p.wider, p.watched, p.half_width, p.widest
                );
            }
        }
        if !m.complete {
            println!(
                "  stopped after {} part file(s): continue with the same command and --resume",
                f.stop_after.unwrap_or(0)
            );
            return Ok(out_dir);
        }
        if shard == Shard::WHOLE {
            let calibration = a.sensitivity.and_then(|s| s.thresholds).map(Calibration::File);
            summarize(method, &out_dir, calibration.as_ref(), !f.quiet)?;
        } else if !f.quiet && m.sensitivity.is_some() {
            println!("  shard done: join the shards with `fdimc merge <shard dirs>... --out DIR` to get the indices");
        } else if !f.quiet {
            println!("  shard done: join the shards with `fdimc merge <shard dirs>... --out DIR` to get the summary");
        }
        Ok(out_dir)
    }

    pub fn exec_summarize(
        &self,
        dir: &Path,
        target_pfa: Option<f64>,
        target_pfa_per_hour: Option<f64>,
        confidence: Option<f64>,
        thresholds: Option<&Path>,
    ) -> Result<(), CliError> {
        let (method, manifest) = self.method_of_run(dir)?;
        if let (Some(_), Some(_)) = (target_pfa, target_pfa_per_hour) {
            return Err(CliError::Invalid("give --target-pfa (per trial) or --target-pfa-per-hour, not both".into()));
        }
        if let Some(c) = confidence
            && !(c > 0.0 && c < 1.0)
        {
            return Err(CliError::Invalid(format!("--confidence {c}: allowed 0 < c < 1 (e.g. 0.95)")));
        }
        let calibration = match (target_pfa, target_pfa_per_hour, thresholds, confidence) {
            (Some(_), _, Some(_), _) | (_, Some(_), Some(_), _) => {
                return Err(CliError::Invalid("give --target-pfa or --thresholds, not both".into()));
            }
            (_, _, Some(_), Some(_)) => {
                return Err(CliError::Invalid("--confidence calibrates; --thresholds applies another run's".into()));
            }
            (_, _, Some(f), None) => Some(Calibration::File(f.into())),
            (_, Some(h), None, _) if !(h > 0.0 && h < 1.0) => {
                return Err(CliError::Invalid(format!("--target-pfa-per-hour {h}: allowed 0 < p < 1")));
            }
            (_, Some(per_hour), None, c) => {
                let segment_s = manifest.trial_duration_s.ok_or_else(|| {
                    CliError::Invalid(format!(
                        "{}: the manifest does not give the trial's duration (a run of an older fdimc): use --target-pfa",
                        dir.display()
                    ))
                })?;
                let calibration = Calibration::PerHour { per_hour, segment_s, confidence: c.or(manifest.confidence) };
                println!("target {}", calibration.describe());
                Some(calibration)
            }
            (Some(p), None, None, _) if !(p > 0.0 && p < 1.0) => {
                return Err(CliError::Invalid(format!("--target-pfa {p}: allowed 0 < p < 1")));
            }
            // Target and confidence each from the command line where given, else from the deck.
            (Some(p), None, None, c) => Some(match c.or(manifest.confidence) {
                Some(confidence) => Calibration::Confident { pfa: p, confidence },
                None => Calibration::Target(p),
            }),
            (None, None, None, Some(confidence)) => {
                Some(Calibration::Confident { pfa: manifest.target_pfa, confidence })
            }
            (None, None, None, None) => None,
        };
        if matches!(
            calibration,
            Some(Calibration::Target(_) | Calibration::Confident { .. } | Calibration::PerHour { .. })
        ) && manifest.sensitivity.is_some()
        {
            return Err(CliError::Invalid(format!(
                "{}: a sensitivity run calibrates no thresholds: give another run's --thresholds, or none for the deck's",
                dir.display()
            )));
        }
        if calibration.is_some() {
            method::require(self.0, method, Opt::Thresholds)
                .map_err(|e| CliError::Invalid(format!("{}: {e}", dir.display())))?;
        }
        summarize(method, dir, calibration.as_ref(), true)
    }

    pub fn exec_merge(&self, dirs: &[PathBuf], out: &Path, force: bool) -> Result<(), CliError> {
        if dirs.is_empty() {
            return Err(CliError::Invalid("name the shard folders to merge".into()));
        }
        if dirs[0].join("rare_event.json").exists() {
            return Ok(crate::engine::rare_event::study::merge(dirs, out)?);
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
                || m.sensitivity != first.sensitivity
                || m.profile_resolution != first.profile_resolution
                || m.profiles_exact_at_deadlines != first.profiles_exact_at_deadlines
            {
                return Err(CliError::Invalid(format!(
                    "{}: from another run (deck, seed, trial count, shard count, profile resolution or the profiles' \
                     exact points at the window and the hazard, written by another fdimc, differ from {})",
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
        runner::concatenate(&inputs, &out.join("trials.parquet"), false)?;
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
        summarize(method::find(self.0, &merged.kind)?, out, None, true)
    }

    pub fn exec_check(
        &self,
        target: &Path,
        baseline: &Path,
        alpha: f64,
        threads: Option<usize>,
    ) -> Result<bool, CliError> {
        if !(alpha > 0.0 && alpha < 1.0) {
            return Err(CliError::Invalid(format!("--alpha {alpha}: allowed 0 < alpha < 1")));
        }
        let base = crate::engine::results::tables::read_summary(baseline)?;
        crate::engine::results::check::consistent(&base, baseline)?;
        let (current, scratch) = if target.is_dir() {
            (crate::engine::results::tables::read_summary(&target.join("summary.csv"))?, None)
        } else {
            let scratch = std::env::temp_dir().join(format!("fdimc-check-{}", std::process::id()));
            let _ = std::fs::remove_dir_all(&scratch);
            let args = RunArgs {
                deck: target,
                trials: None,
                folder: RunFolder {
                    place: Placement { threads, out: Some(scratch.clone()), ..Placement::default() },
                    resume: false,
                    force: true,
                    quiet: true,
                    stop_after: None,
                    fmu_processes: false,
                    fmu_in_process: false,
                    low_disk: false,
                    profile_resolution: None,
                },
                classifiers: None,
                precision: None,
                precision_rates: Vec::new(),
                sensitivity: None,
            };
            let dir = self.exec_run(args)?;
            (crate::engine::results::tables::read_summary(&dir.join("summary.csv"))?, Some(scratch))
        };
        let dir = scratch.clone().unwrap_or_else(|| target.to_path_buf());
        // A baseline copied from another calibration (`summarize --target-pfa P --confidence C`): a run
        // is calibrated at the baseline's too, so that the rates compare at one false-alarm rate. (A
        // calibration's own folder is not a run: compare refuses the mismatch and says why.)
        let current = match crate::engine::results::check::calibration(&base) {
            Some(wanted)
                if crate::engine::results::check::calibration(&current) != Some(wanted)
                    && dir.join("manifest.json").exists() =>
            {
                let calibration = match wanted {
                    (pfa, Some(confidence)) => Calibration::Confident { pfa, confidence },
                    (pfa, None) => Calibration::Target(pfa),
                };
                let (method, _) = self.method_of_run(&dir)?;
                let s = summary::summarize(&dir, &method.summary, Some(&calibration), None)?;
                println!(
                    "the baseline's thresholds are calibrated at {}: this run calibrated there too ({})",
                    crate::engine::results::check::describe(Some(wanted)),
                    if scratch.is_some() { "in a scratch folder".to_string() } else { s.out_dir.display().to_string() }
                );
                crate::engine::results::tables::read_summary(&s.out_dir.join("summary.csv"))?
            }
            _ => current,
        };
        let verdict = crate::engine::results::check::compare(&current, &base, alpha);
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
        for n in &verdict.notes {
            println!("warning: {n}");
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

    pub fn exec_report(&self, dir: &Path, trials: &[u64]) -> Result<(), CliError> {
        let (method, manifest) = self.method_of_run(dir)?;
        let report = method.write_report(dir, trials)?;
        // One line each (report.html has them whole, and `--verbose` prints them so).
        for w in crate::engine::results::summary::console_warnings(&report.warnings, &manifest.detectors) {
            println!("warning: {w}");
        }
        if let Some(page) = report.files.last() {
            println!("{} plots -> {}", report.files.len() - 1, page.display());
        }
        Ok(())
    }

    pub fn exec_train(&self, deck: &Path, out: Option<&Path>) -> Result<(), CliError> {
        let (method, study) = method::load(self.0, deck)?;
        method::require(self.0, method, Opt::Classifiers)?;
        Ok(study.train(out)?)
    }

    /// `fdimc new KIND FILE`: the kind's starter deck, its study named after the file; with `replay`, the
    /// accelerometer kind's deck that replays that log.
    pub fn exec_new(&self, kind: &str, file: &Path, force: bool, replay: Option<&Path>) -> Result<(), CliError> {
        let method = method::find(self.0, kind)?;
        let replay = match (replay, method.replay_starter) {
            (Some(_), None) => {
                let replaying: Vec<&str> =
                    self.0.iter().filter(|m| m.replay_starter.is_some()).map(|m| m.kind).collect();
                return Err(CliError::Invalid(format!(
                    "--replay: kind {kind} does not replay flight logs; {}",
                    match replaying.as_slice() {
                        [one] => format!("kind {one} does"),
                        many => format!("kinds {} do", many.join(", ")),
                    }
                )));
            }
            (Some(log), Some(write)) => Some((log, write)),
            (None, _) => None,
        };
        if file.exists() && !force {
            return Err(CliError::Invalid(format!(
                "{}: exists; name another file, or --force to replace it",
                file.display()
            )));
        }
        // The study's name is a folder name: the file's stem, other characters made '_'.
        let stem = file.file_stem().map(|s| s.to_string_lossy().to_string()).unwrap_or_default();
        let study: String =
            stem.chars().map(|c| if c.is_ascii_alphanumeric() || c == '_' || c == '-' { c } else { '_' }).collect();
        let study = if study.is_empty() { kind.to_string() } else { study };
        if let Some(parent) = file.parent().filter(|p| !p.as_os_str().is_empty()) {
            std::fs::create_dir_all(parent).map_err(|e| CliError::Invalid(format!("{}: {e}", parent.display())))?;
        }
        let text = match replay {
            None => method.starter_deck(&study),
            // Checked before anything is written: a log the deck could not replay is refused here.
            Some((log, write)) => write(&study, log, file).map_err(CliError::Invalid)?,
        };
        crate::engine::run::runner::write_atomically(file, text.as_bytes())?;
        println!(
            "wrote {}: a deck of kind {kind} ({}), study {study:?}\nnext: fdimc validate {0}, then fdimc run {0}",
            file.display(),
            method.title
        );
        Ok(())
    }

    pub fn exec_validate(&self, deck: &Path) -> Result<(), CliError> {
        Ok(method::load(self.0, deck)?.1.validate()?)
    }

    pub fn exec_design(&self, deck: &Path, json: bool) -> Result<(), CliError> {
        let (method, study) = method::load(self.0, deck)?;
        method::require(self.0, method, Opt::Design)?;
        Ok(study.design(json)?)
    }

    /// `fdimc rare-event`: checks the options (each estimator's own, the others refused), then runs.
    pub fn exec_rare_event(&self, a: RareEventArgs) -> Result<(), CliError> {
        use crate::engine::rare_event::study::{Estimator, FlightOptions, RareEventOptions};
        use crate::engine::scenario::streams::{MAX_BRANCH, MAX_REPLICA};
        let bad = |m: String| Err(CliError::Invalid(m));
        let estimator = if a.estimator == "splitting" { Estimator::Splitting } else { Estimator::Importance };
        let (own, other): (&[(&str, bool)], &[(&str, bool)]) = (
            &[("--trials", a.trials.is_some())],
            &[("--particles", a.particles.is_some()), ("--replicas", a.replicas.is_some())],
        );
        let refused = if estimator == Estimator::Splitting { own } else { other };
        if let Some((flag, _)) = refused.iter().find(|(_, given)| *given) {
            return bad(format!("{flag} does not apply to --estimator {}", estimator.name()));
        }
        let mut levels = a.levels.clone();
        if let Some(l) = levels.iter().find(|l| !(l.is_finite() && **l > 0.0)) {
            return bad(format!("--levels {l}: a level is a threshold scale, allowed > 0"));
        }
        levels.sort_by(f64::total_cmp);
        levels.dedup();
        let trials = a.trials.unwrap_or(20_000);
        // A trial's importance choices come from branch `trial` of a reserved replica's streams.
        if !(10..=MAX_BRANCH).contains(&trials) {
            return bad(format!("--trials {trials}: allowed 10 (a fifth is the pilot) to {MAX_BRANCH}"));
        }
        let particles = a.particles.unwrap_or(100);
        let replicas = a.replicas.unwrap_or(16);
        if !(2..=1_000_000).contains(&particles) {
            return bad(format!("--particles {particles}: allowed 2 to 1000000"));
        }
        if !(2..=MAX_REPLICA).contains(&replicas) {
            return bad(format!("--replicas {replicas}: allowed 2 (an interval needs two) to {MAX_REPLICA}"));
        }
        if a.miss_before_hazard {
            if estimator != Estimator::Splitting {
                return bad(
                    "--miss-before-hazard splits in time: add --estimator splitting (with --particles, --replicas)"
                        .into(),
                );
            }
            if a.flight_s.is_some() {
                return bad("--flight-s does not apply to --miss-before-hazard (its trials are the deck's)".into());
            }
        }
        if a.flight_trials.is_some() && estimator == Estimator::Splitting {
            return bad(
                "--flight-trials does not apply to --estimator splitting (its flights are its particles)".into()
            );
        }
        let flight_trials = a.flight_trials.unwrap_or(1_000);
        if !(10..=MAX_BRANCH).contains(&flight_trials) {
            return bad(format!("--flight-trials {flight_trials}: allowed 10 (a fifth is the pilot) to {MAX_BRANCH}"));
        }
        let (method, mut study) = self.load(&a.deck, None)?;
        method::require(self.0, method, Opt::RareEvent)?;
        let flight = match a.flight_s {
            None => None,
            Some(f) => Some(FlightOptions { seconds: check_flight_s(f, study.header())?, trials: flight_trials }),
        };
        let (out, shard, _) = place(&a.place, study.as_mut(), Some("rare_event"))?;
        if a.miss_before_hazard && shard != Shard::WHOLE {
            return bad("--miss-before-hazard runs on one machine: drop --shard".into());
        }
        if flight.is_some() && shard != Shard::WHOLE {
            return bad(
                "--flight-s runs on one machine: drop --shard (the flights' own estimate is not sharded)".into()
            );
        }
        let opts = RareEventOptions {
            deck: a.deck,
            shard,
            estimator,
            detector: a.detector,
            levels,
            trials,
            particles,
            replicas,
            out,
            quiet: a.quiet,
            flight,
            miss_before_hazard: a.miss_before_hazard,
        };
        runner::thread_pool(a.place.threads)?.install(|| study.rare_event(&opts))?;
        if !a.quiet && opts.miss_before_hazard {
            println!("wrote {}", opts.out.join(crate::engine::rare_event::study::MISS_FILE).display());
        } else if !a.quiet && shard == Shard::WHOLE {
            println!("wrote {}", opts.out.join("rare_event.csv").display());
            if flight.is_some() {
                println!("wrote {}", opts.out.join(crate::engine::rare_event::flights::PER_HOUR_FILE).display());
            }
        }
        Ok(())
    }

    /// `fdimc flight-thresholds`: checks the target, finds the kind's way (or says what to run
    /// instead), searches, prints each detector's statement and writes the files; `false` when a
    /// detector's thresholds were not confirmed.
    pub fn exec_flight_thresholds(&self, a: crate::cli::FlightThresholdsArgs) -> Result<bool, CliError> {
        use crate::engine::results::flight_thresholds::{self as found, Allocation, FlightTarget};
        let bad = |m: String| Err(CliError::Invalid(m));
        let (flag, p) = match (a.per_hour, a.per_flight) {
            (Some(p), _) => ("--per-hour", p),
            (_, Some(p)) => ("--per-flight", p),
            (None, None) => unreachable!("clap requires one"),
        };
        if !(p > 0.0 && p < 0.5) {
            return bad(format!("{flag} {p}: a false-alarm probability, allowed > 0 and < 0.5"));
        }
        if !(a.flight_s.is_finite() && a.flight_s > 0.0) {
            return bad(format!("--flight-s {}: a flight's length in seconds, allowed > 0", a.flight_s));
        }
        if a.threads == Some(0) {
            return bad("--threads 0: give at least 1 (or leave it out for one per core)".into());
        }
        let allocation = if a.allocation == "deck" { Allocation::Deck } else { Allocation::Equal };
        let target = match a.per_hour {
            Some(h) => FlightTarget::per_hour(h, a.flight_s, allocation, a.seed),
            None => FlightTarget::per_flight(p, a.flight_s, allocation, a.seed),
        };
        if !(target.per_flight < 0.5) {
            return bad(format!(
                "{flag} {p} over flights of {} s is {:.3} per flight: allowed below 0.5 (a shorter --flight-s)",
                a.flight_s, target.per_flight
            ));
        }
        let text = crate::engine::scenario::deck::read_deck(&a.deck)?;
        let kind = method::method_of(self.0, &text, &a.deck)?;
        let Some(search) = kind.flight_thresholds else {
            let instead = if kind.options.contains(&Opt::RareEvent) {
                format!(
                    "estimate per flight with fdimc rare-event {} --flight-s F --levels S1,S2,... and take the \
                     smallest level whose per_hour.csv upper bound is below the target",
                    a.deck.display()
                )
            } else {
                format!(
                    "the nearest is fdimc summarize RUN --target-pfa-per-hour P on a run of the deck (the tail fit \
                     and the conversion from trials to hours, neither confirmed over whole flights: {}'s role and \
                     statement say how far to trust them)",
                    crate::engine::results::summary::safety::SAFETY_FILE
                )
            };
            return bad(format!(
                "{}: a {} study ({}) has no exact false-alarm law to find thresholds on; {instead}",
                a.deck.display(),
                kind.kind,
                kind.title
            ));
        };
        let name = toml::from_str::<toml::Table>(&text)
            .ok()
            .and_then(|t| t.get("study")?.get("name")?.as_str().map(String::from))
            .unwrap_or_else(|| "study".into());
        let out = results_folder(a.out.as_deref(), &name, Some("flight_thresholds"), Shard::WHOLE, false);
        let searched =
            runner::thread_pool(a.threads)?.install(|| search(&text, &a.deck, a.detector.as_deref(), &target))?;
        for why in &searched.skipped {
            println!("skipped {why}");
        }
        let results = searched.found;
        for f in &results {
            println!("{}", f.statement(&target));
        }
        for file in found::write(&out, &results, &target)? {
            println!("wrote {file}");
        }
        Ok(results.iter().all(|f| f.confirmed))
    }

    /// `fdimc worst-case`: checks the sizes, then searches.
    pub fn exec_worst_case(&self, a: WorstCaseArgs) -> Result<(), CliError> {
        use crate::engine::worst_case::{Objective, SearchOptions, WorstCaseOptions};
        let bad = |m: String| Err(CliError::Invalid(m));
        let objective = Objective::parse(&a.objective).expect("clap checked the value");
        if !(10..=crate::engine::scenario::streams::MAX_TRIAL / 4).contains(&a.batch) {
            return bad(format!(
                "--batch {}: allowed 10 to {}",
                a.batch,
                crate::engine::scenario::streams::MAX_TRIAL / 4
            ));
        }
        if a.budget < 2 * a.batch {
            return bad(format!(
                "--budget {}: at least two candidates of --batch {} trials ({})",
                a.budget,
                a.batch,
                2 * a.batch
            ));
        }
        if !(10..=crate::engine::scenario::streams::MAX_TRIAL / 4).contains(&a.confirm) {
            return bad(format!(
                "--confirm {}: allowed 10 to {}",
                a.confirm,
                crate::engine::scenario::streams::MAX_TRIAL / 4
            ));
        }
        if let Some(file) = &a.write_deck
            && file.extension().is_none_or(|e| e != "toml")
        {
            return bad(format!("--write-deck {}: a deck is a .toml file", file.display()));
        }
        let (method, mut study) = self.load(&a.deck, None)?;
        method::require(self.0, method, Opt::WorstCase)?;
        let (out, shard, _) = place(&a.place, study.as_mut(), Some("worst_case"))?;
        if shard != Shard::WHOLE {
            return bad("--shard: a worst-case search runs on one machine (its candidates follow each other)".into());
        }
        let seed = study.header().seed;
        let opts = WorstCaseOptions {
            search: SearchOptions { objective, budget: a.budget, batch: a.batch, confirm: a.confirm, seed },
            detector: a.detector,
            out,
            write_deck: a.write_deck,
            deck: a.deck,
            quiet: a.quiet,
        };
        runner::thread_pool(a.place.threads)?.install(|| study.worst_case(&opts))?;
        if !a.quiet {
            println!("wrote {}", opts.out.join("worst_case.csv").display());
        }
        Ok(())
    }

    pub fn exec_simulate(
        &self,
        deck: &Path,
        trial: u64,
        detector: Option<&str>,
        out: &Path,
        classifiers: Option<&Path>,
    ) -> Result<(), CliError> {
        // Check the output name before simulating, so a typo costs nothing.
        crate::engine::run::output::TableFormat::from_path(out)?;
        if trial > crate::engine::scenario::streams::MAX_TRIAL {
            return Err(CliError::Invalid(format!(
                "--trial {trial}: allowed 0 to {}",
                crate::engine::scenario::streams::MAX_TRIAL
            )));
        }
        let (_, study) = self.load(deck, classifiers)?;
        Ok(study.simulate(trial, detector, out, Inputs { classifiers, quiet: false })?)
    }
}

/// The most samples a `--flight-s` flight may have: importance sampling's tilts keep every sample's
/// response to every output's draw (outputs^2 numbers per sample; 6 outputs: 288 MB at the limit).
pub const MAX_FLIGHT_SAMPLES: f64 = 1e6;

/// `--flight-s F`: a whole number (at least 2) of the deck's trials, at most [`MAX_FLIGHT_SAMPLES`].
fn check_flight_s(f: f64, header: &crate::engine::scenario::deck::StudyHeader) -> Result<f64, CliError> {
    let trial_s = header.steps as f64 * header.dt_s;
    let segments = f / trial_s;
    let whole = (segments - segments.round()).abs() < 1e-9 * segments.max(1.0);
    if !(f.is_finite() && whole && segments.round() >= 2.0) {
        return Err(CliError::Invalid(format!(
            "--flight-s {f}: a flight is a whole number (2 or more) of the deck's {trial_s} s trials ({}: study.duration_s), e.g. {}",
            header.path.display(),
            (3600.0 / trial_s).ceil().max(2.0) * trial_s
        )));
    }
    if f / header.dt_s > MAX_FLIGHT_SAMPLES {
        return Err(CliError::Invalid(format!(
            "--flight-s {f}: {} samples at dt {} s; allowed at most {MAX_FLIGHT_SAMPLES:.0} per flight",
            (f / header.dt_s).round(),
            header.dt_s
        )));
    }
    Ok(segments.round() * trial_s)
}
