//! The Monte Carlo runner: the only parallel code in fdimc.
//!
//! Trials are processed in chunks of consecutive indices ([`Manifest::chunk_trials`]). A chunk runs in parallel on
//! rayon, its results are collected in trial order and written as one complete Parquet part file
//! (`parts/part-<first trial>.parquet`, temporary name then rename), so memory stays at a few chunks
//! whatever the trial count, and a killed run loses at most the chunks in flight. A writer thread
//! encodes each chunk while the next one simulates and appends its rows in trial order to
//! `trials.parquet` (renamed into place when the last chunk is in, the parts then removed); with
//! `--low-disk` the parts are appended only at the end, each removed once appended, so the disk holds
//! the records once.
//! `--resume` reads back the parts already on disk instead of simulating them.
//! Each trial's numbers depend only on (deck, seed, trial index), so any thread count, shard split or
//! resume gives identical rows.
//!
//! The runner knows nothing of plants or detectors: a study hands it a [`TrialSource`] (simulate trials
//! `first..end`, turn results into rows) and the study fields of its [`Manifest`]. The LTI studies of
//! method 000 (`methods::detection_filter::run_study`), and the studies of methods 001, 002 and 004 share it.

use std::fs::File;
use std::path::{Path, PathBuf};
use std::time::Instant;

use polars::prelude::*;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::engine::run::output::temporary_sibling;
use crate::engine::run::progress::Progress;
use crate::engine::run::row_groups::{RowGroupError, RowGroupWriter};
use crate::engine::scenario::deck::{MonteCarlo, StudyHeader};

/// What the runner needs of a study.
pub trait TrialSource: Sync {
    type Result: Send;
    /// Consecutive trials one worker simulates together (the SIMD lane width for LTI studies; 1: each
    /// trial on its own).
    fn group_trials(&self) -> u64 {
        1
    }
    /// Trial `trial` on its own.
    fn trial(&self, trial: u64) -> Self::Result;
    /// The results of trials `first..end` (at most [`TrialSource::group_trials`]), in trial order.
    fn simulate(&self, first: u64, end: u64) -> Vec<Self::Result> {
        (first..end).map(|t| self.trial(t)).collect()
    }
    /// The study's own fields of `manifest.json` (see [`Manifest::of`]); the run fills in the rest.
    fn manifest(&self) -> Manifest;
    /// The trials.parquet rows of `results` (trial order); `&[]` gives the empty table with its schema.
    fn frame(&self, results: &[Self::Result]) -> PolarsResult<DataFrame>;
}

/// One trial's scenario and its detectors' outcome, or why the trial could not be flown (a simulation
/// that stopped); what most kinds' [`TrialSource::Result`] is.
#[derive(Debug, Clone, PartialEq)]
pub struct TrialResult<Spec, Outcome, Error = String> {
    pub spec: Spec,
    pub outcome: Result<Outcome, Error>,
}

/// Trials per part file of LTI studies (a few seconds of work); a source may choose its own.
pub const CHUNK_TRIALS: u64 = 4096;

/// Errors of a run; `Invalid` ones are the user's to fix (exit 2), the rest are I/O or internal (exit 3).
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    #[error("{0}")]
    Invalid(String),
    #[error("{file}: {source}")]
    Io { file: PathBuf, source: std::io::Error },
    #[error("{file}: {source}")]
    Polars { file: PathBuf, source: PolarsError },
    #[error("{0}")]
    Internal(String),
}

pub(crate) fn io(file: &Path) -> impl FnOnce(std::io::Error) -> RunError + '_ {
    move |source| RunError::Io { file: file.into(), source }
}

/// The worker pool of a command: `threads` workers, or one per core.
pub fn thread_pool(threads: Option<usize>) -> Result<rayon::ThreadPool, RunError> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads.unwrap_or(0))
        .build()
        .map_err(|e| RunError::Internal(format!("thread pool: {e}")))
}

pub(crate) fn pol(file: &Path) -> impl FnOnce(PolarsError) -> RunError + '_ {
    move |source| RunError::Polars { file: file.into(), source }
}

impl From<RowGroupError> for RunError {
    fn from(e: RowGroupError) -> Self {
        match e {
            RowGroupError::Io { file, source } => RunError::Io { file, source },
            RowGroupError::Invalid(why) => RunError::Invalid(why),
            RowGroupError::Internal(why) => RunError::Internal(why),
        }
    }
}

impl From<crate::engine::scenario::deck::DeckError> for RunError {
    fn from(e: crate::engine::scenario::deck::DeckError) -> Self {
        RunError::Invalid(e.to_string())
    }
}

impl From<crate::engine::run::output::OutputError> for RunError {
    fn from(e: crate::engine::run::output::OutputError) -> Self {
        use crate::engine::run::output::OutputError;
        match e {
            OutputError::UnknownFormat { .. } => RunError::Invalid(e.to_string()),
            OutputError::Io { file, source } => RunError::Io { file, source },
            OutputError::Polars { file, source } => RunError::Polars { file, source },
        }
    }
}

/// Part `index` of `count` of a study's trials.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Shard {
    pub index: u64,
    pub count: u64,
}

impl Shard {
    pub const WHOLE: Shard = Shard { index: 0, count: 1 };

    /// Parses `I/N` (0 <= I < N).
    pub fn parse(text: &str) -> Result<Shard, String> {
        let (i, n) = text.split_once('/').ok_or_else(|| format!("{text:?}: expected I/N, e.g. 0/4"))?;
        let index: u64 = i.trim().parse().map_err(|_| format!("{text:?}: I must be a whole number"))?;
        let count: u64 = n.trim().parse().map_err(|_| format!("{text:?}: N must be a whole number"))?;
        if count == 0 || index >= count {
            return Err(format!("{text:?}: needs 0 <= I < N (shards are numbered from 0)"));
        }
        Ok(Shard { index, count })
    }

    /// `--shard`'s text: `I/N`, or `auto` (or `auto/N`) for the array task the scheduler runs this
    /// process as, read by `env` ([`Shard::from_scheduler`]). The flag says whether it was `auto`.
    pub fn from_arg(text: &str, env: impl Fn(&str) -> Option<String>) -> Result<(Shard, bool), String> {
        match text.trim().strip_prefix("auto") {
            Some("") => Ok((Shard::from_scheduler(None, env)?, true)),
            Some(rest) => {
                let n = rest.strip_prefix('/').and_then(|n| n.trim().parse::<u64>().ok()).filter(|&n| n > 0);
                let n = n.ok_or_else(|| format!("{text:?}: expected auto or auto/N (N the task count, >= 1)"))?;
                Ok((Shard::from_scheduler(Some(n), env)?, true))
            }
            None => Ok((Shard::parse(text)?, false)),
        }
    }

    /// The shard of the scheduler's array task: SLURM's `SLURM_ARRAY_TASK_ID` among
    /// `SLURM_ARRAY_TASK_MIN..=MAX` (or `0..SLURM_ARRAY_TASK_COUNT`), or a Kubernetes indexed job's
    /// `JOB_COMPLETION_INDEX` among `count` (`auto/N`) or `FDIMC_SHARD_COUNT` completions. Refuses an
    /// environment that names no task, names both, or disagrees with itself or with `count`.
    pub fn from_scheduler(count: Option<u64>, env: impl Fn(&str) -> Option<String>) -> Result<Shard, String> {
        let number = |name: &str| -> Result<Option<u64>, String> {
            match env(name) {
                None => Ok(None),
                Some(v) => v.trim().parse::<u64>().map(Some).map_err(|_| format!("{name}={v:?}: not a whole number")),
            }
        };
        let (slurm_id, k8s_index) = (number("SLURM_ARRAY_TASK_ID")?, number("JOB_COMPLETION_INDEX")?);
        let shard = match (slurm_id, k8s_index) {
            (None, None) => {
                return Err("auto: no array task in the environment (SLURM_ARRAY_TASK_ID, or a Kubernetes indexed \
                            job's JOB_COMPLETION_INDEX): run it as an array task, or give --shard I/N"
                    .into());
            }
            (Some(_), Some(_)) => {
                return Err("auto: both SLURM_ARRAY_TASK_ID and JOB_COMPLETION_INDEX are set: give --shard I/N".into());
            }
            (Some(id), None) => {
                let (min, max, n) = (
                    number("SLURM_ARRAY_TASK_MIN")?,
                    number("SLURM_ARRAY_TASK_MAX")?,
                    number("SLURM_ARRAY_TASK_COUNT")?,
                );
                let min = min.unwrap_or(0);
                let span = max.map(|max| max.saturating_sub(min) + 1);
                let tasks = match (span, n) {
                    (Some(s), Some(n)) if s != n => {
                        return Err(format!(
                            "auto: SLURM_ARRAY_TASK_MIN..MAX holds {s} tasks but SLURM_ARRAY_TASK_COUNT is {n}: \
                             a stepped or sparse --array; give the array as a range like 0-3"
                        ));
                    }
                    (Some(t), _) | (None, Some(t)) => t,
                    (None, None) => {
                        return Err("auto: SLURM_ARRAY_TASK_ID is set but neither SLURM_ARRAY_TASK_COUNT nor \
                                    SLURM_ARRAY_TASK_MAX"
                            .into());
                    }
                };
                if id < min || id - min >= tasks {
                    return Err(format!(
                        "auto: SLURM_ARRAY_TASK_ID {id} is outside the array's {min}..{}",
                        min + tasks
                    ));
                }
                Shard { index: id - min, count: tasks }
            }
            (None, Some(index)) => {
                let tasks = match (count, number("FDIMC_SHARD_COUNT")?) {
                    (Some(c), Some(e)) if c != e => {
                        return Err(format!("auto/{c}: FDIMC_SHARD_COUNT says {e}"));
                    }
                    (Some(c), _) | (None, Some(c)) => c,
                    (None, None) => {
                        return Err("auto: JOB_COMPLETION_INDEX is set but not the completions: give --shard auto/N \
                                    or set FDIMC_SHARD_COUNT"
                            .into());
                    }
                };
                if index >= tasks {
                    return Err(format!("auto: JOB_COMPLETION_INDEX {index} is outside 0..{tasks}"));
                }
                Shard { index, count: tasks }
            }
        };
        // Each arm above refused an index outside 0..count, so count is at least 1 here.
        match count {
            Some(c) if c != shard.count => Err(format!("auto/{c}: the scheduler's array has {} tasks", shard.count)),
            _ => Ok(shard),
        }
    }

    /// A shard's own results folder under a run's: `shard-I-of-N`.
    pub fn folder(&self) -> String {
        format!("shard-{}-of-{}", self.index, self.count)
    }

    /// The half-open trial range of this shard among `trials`.
    pub fn range(&self, trials: u64) -> (u64, u64) {
        let at = |k: u64| ((k as u128 * trials as u128) / self.count as u128) as u64;
        (at(self.index), at(self.index + 1))
    }
}

/// Provenance of a results folder, and what `--resume` and `merge` check.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    pub fdimc_version: String,
    /// The kind of study ([`crate::engine::method::Method::kind`]): which method summarizes and reports it.
    pub kind: String,
    pub study: String,
    pub deck: String,
    pub deck_sha256: String,
    pub seed: u64,
    /// Trials of the whole study (all shards).
    pub trials: u64,
    pub shard: Shard,
    /// Trial range written here: `[first_trial, end_trial)`.
    pub first_trial: u64,
    pub end_trial: u64,
    /// Trials per part file: what a killed run can lose, so a few seconds to a minute of work.
    pub chunk_trials: u64,
    pub detectors: Vec<String>,
    /// The faulty components a study can name: output names (sensors) or surface names.
    pub outputs: Vec<String>,
    /// Per detector, the deck's thresholds (detection filters; empty for banks).
    pub deck_thresholds: Vec<Vec<f64>>,
    /// Calibration target of detection filters; 0 for banks, which declare by model probability.
    pub target_pfa: f64,
    /// The confidence the deck calibrates with (`monte_carlo.confidence`; `None`: plain calibration).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub confidence: Option<f64>,
    /// A trial's duration (s), for false-alarm rates per flight hour (`None` in runs written before).
    #[serde(default)]
    pub trial_duration_s: Option<f64>,
    /// `monte_carlo.detection_window_s`: an alarm later than this after the onset is a late alarm, not a
    /// detection (`None`: to the end of the trial).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub detection_window_s: Option<f64>,
    /// The relative step of the first-passage profiles' value grid (`monte_carlo.profile_resolution`;
    /// 0: every rise; `None`: a run written before the grid, whose points rose by 2 % each).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub profile_resolution: Option<f64>,
    /// The profiles keep the running maximum exactly at the end of the detection window and at the
    /// time to hazard ([`crate::engine::results::schema::ExactDelays`]), so detections and misses before
    /// the hazard replay exactly at any thresholds (`false`: a kind or an fdimc that does not).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub profiles_exact_at_deadlines: bool,
    /// Unit of each fault kind's size bins (for plot axes).
    #[serde(default)]
    pub fault_size_units: std::collections::BTreeMap<String, String>,
    /// Each fault kind's size bins as `[low, high)` edges where the deck draws sizes from a range (a
    /// listed or fixed size is its own bin); the summary tables give each bin centre its edges.
    #[serde(default)]
    pub fault_size_bins: crate::engine::scenario::deck::SizeBins,
    /// Each parameter error drawn from a range: its bins as `[low, high)` edges, by its name (the
    /// deck's `bins`; `parameter_errors.csv` groups by them).
    #[serde(default, skip_serializing_if = "std::collections::BTreeMap::is_empty")]
    pub parameter_error_bins: crate::engine::scenario::deck::SizeBins,
    /// The sensor noise's law in words, where the kind says (`safety.csv`'s assumptions): a detection
    /// filter's `noise.sensor_law`, a replay's recorded noise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sensor_noise: Option<String>,
    /// The deck's `time_to_hazard_s` (per fault kind, per target or `""` for all): the summary's
    /// `p_miss_before_hazard`.
    #[serde(default, skip_serializing_if = "std::collections::BTreeMap::is_empty")]
    pub time_to_hazard_s: crate::engine::scenario::deck::HazardTimes,
    pub command_line: Vec<String>,
    pub complete: bool,
    pub rows: u64,
    /// A run asked to stop at a precision (`run --precision`): what it was asked and where it stopped.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub precision: Option<PrecisionOutcome>,
    /// A sensitivity study (`fdimc sensitivity`): its design, whose rows the trials are.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sensitivity: Option<crate::engine::scenario::design::Design>,
    /// The model files the study flies besides its deck (an FMU truth): file name and SHA-256. A resume
    /// with another file is refused, as with another deck.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub models: Vec<ModelFile>,
}

/// A model file a study flies, for provenance.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelFile {
    pub file: String,
    pub sha256: String,
}

/// What `run --precision` asked and where the run stopped.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PrecisionOutcome {
    /// The largest 95 % Wilson half-width allowed.
    pub half_width: f64,
    /// The rates watched (`summary.csv` names).
    pub rates: Vec<String>,
    /// Whether every watched rate got there (else the trial cap stopped the run).
    pub met: bool,
    /// Watched rates, and those still wider than asked.
    pub watched: usize,
    pub wider: usize,
    /// The widest watched rate at the stop: the group that set it.
    pub widest: String,
}

/// A JSON record a run leaves in its folder: `folder` names the folder it marks (for a file that cannot
/// be read), `record` what it holds (for one that does not parse).
pub fn read_record<T: serde::de::DeserializeOwned>(path: &Path, folder: &str, record: &str) -> Result<T, RunError> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| RunError::Invalid(format!("{}: cannot read ({e}): not {folder}?", path.display())))?;
    serde_json::from_str(&text).map_err(|e| RunError::Invalid(format!("{}: not a valid {record}: {e}", path.display())))
}

impl Manifest {
    pub fn read(dir: &Path) -> Result<Manifest, RunError> {
        read_record(&dir.join("manifest.json"), "an fdimc results folder", "fdimc manifest")
    }

    pub fn write(&self, dir: &Path) -> Result<(), RunError> {
        let path = dir.join("manifest.json");
        let text = serde_json::to_string_pretty(self).map_err(|e| RunError::Internal(e.to_string()))?;
        write_atomically(&path, text.as_bytes())
    }

    /// Whether two manifests describe the same study run (deck, seed, trial count, chunking).
    fn same_study(&self, other: &Manifest) -> bool {
        self.deck_sha256 == other.deck_sha256
            && self.seed == other.seed
            && self.trials == other.trials
            && self.chunk_trials == other.chunk_trials
            && self.sensitivity == other.sensitivity
            && self.models == other.models
            && self.profile_resolution == other.profile_resolution
            && self.profiles_exact_at_deadlines == other.profiles_exact_at_deadlines
    }
}

/// The one writer of a results folder: an advisory lock on `DIR/.fdimc-lock`, held while a run writes.
/// It is the kernel's (`flock`, through std's `File::try_lock`): released when the process ends however
/// it ends, so a killed run leaves no lock behind, only the file, whose text names its last holder.
pub struct FolderLock {
    _file: File,
}

/// The lock file of a results folder.
pub const LOCK_FILE: &str = ".fdimc-lock";

impl FolderLock {
    /// Takes the lock of `dir` (created if missing), or refuses (exit 2) naming the process that holds it.
    pub fn take(dir: &Path, command_line: &[String]) -> Result<FolderLock, RunError> {
        use std::io::{Seek, Write};
        std::fs::create_dir_all(dir).map_err(io(dir))?;
        let path = dir.join(LOCK_FILE);
        let mut file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(&path)
            .map_err(io(&path))?;
        match file.try_lock() {
            Ok(()) => {}
            Err(std::fs::TryLockError::WouldBlock) => {
                let holder = std::fs::read_to_string(&path).unwrap_or_default();
                return Err(RunError::Invalid(format!(
                    "{}: another fdimc is writing this folder ({}): let it finish (then --resume if it was \
                     interrupted), or use another --out",
                    dir.display(),
                    describe_holder(holder.trim())
                )));
            }
            Err(std::fs::TryLockError::Error(e)) => return Err(RunError::Io { file: path, source: e }),
        }
        let since = unix_time_s();
        let host = std::fs::read_to_string("/proc/sys/kernel/hostname").unwrap_or_default();
        let holder = format!(
            "pid={} host={} since_unix_s={since} command={}\n",
            std::process::id(),
            host.trim(),
            command_line.join(" ")
        );
        // What the file says is for the message above; the lock is the kernel's whatever it says.
        let _ = file.set_len(0).and_then(|_| file.rewind()).and_then(|_| file.write_all(holder.as_bytes()));
        Ok(FolderLock { _file: file })
    }
}

/// Seconds since the Unix epoch (0 on a clock set before it).
fn unix_time_s() -> u64 {
    std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_secs())
}

/// `pid 123 on host n1, started 42 s ago: fdimc run ...` from a lock file's text.
fn describe_holder(text: &str) -> String {
    let field = |name: &str| {
        text.split_whitespace().find_map(|w| w.strip_prefix(&format!("{name}="))).unwrap_or("?").to_string()
    };
    let now = unix_time_s();
    let ago = field("since_unix_s").parse::<u64>().map_or("?".into(), |t| now.saturating_sub(t).to_string());
    let command = text.split_once("command=").map_or("", |c| c.1);
    format!("pid {} on host {}, started {ago} s ago: {command}", field("pid"), field("host"))
}

/// Writes `bytes` to `path` through a temporary file and a rename.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> Result<(), RunError> {
    let tmp = temporary_sibling(path);
    std::fs::write(&tmp, bytes).map_err(io(path))?;
    std::fs::rename(&tmp, path).map_err(io(path))
}

/// SHA-256 of the deck's bytes, hex.
pub fn deck_sha256(deck: &Path) -> Result<String, RunError> {
    use sha2::{Digest, Sha256};
    let bytes = std::fs::read(deck).map_err(io(deck))?;
    Ok(Sha256::digest(&bytes).iter().map(|b| format!("{b:02x}")).collect())
}

/// What `fdimc run` was asked.
#[derive(Debug, Clone)]
pub struct RunOptions {
    pub deck: PathBuf,
    pub out_dir: PathBuf,
    pub threads: Option<usize>,
    pub shard: Shard,
    pub resume: bool,
    /// Replace an existing results folder.
    pub force: bool,
    /// Progress on stderr (a bar on a terminal, a plain line every few seconds elsewhere).
    pub progress: bool,
    /// Stop after writing this many part files, as if interrupted (time-boxed or preemptible jobs).
    pub stop_after_chunks: Option<u64>,
    /// Stop at the first chunk boundary where this rule says the trials so far are enough (`run
    /// --precision`); the trial count is then a cap.
    pub stop: Option<StopHandle>,
    /// The design of a sensitivity study, recorded in the manifest (the study draws its trials from it).
    pub sensitivity: Option<crate::engine::scenario::design::Design>,
    pub command_line: Vec<String>,
    /// Append the parts to trials.parquet only after the last chunk, removing each once appended: the
    /// records on disk once rather than twice, for a longer run (`run --low-disk`).
    pub low_disk: bool,
    /// Where a deck's FMUs fly: in worker processes, one per thread, so that an FMU that crashes its
    /// process (or is not thread-safe) fails only the trial it was flying, or in this process.
    pub fmu_processes: FmuProcesses,
}

/// Where the trials of a deck with FMUs fly (`fdimc run`'s default, `--fmu-processes`,
/// `--fmu-in-process`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FmuProcesses {
    /// In worker processes when the deck runs FMUs and the run allows them (not a sensitivity design:
    /// then in this process, with a note); the command-line default. The workers are this executable
    /// (`fdimc fmu-worker`): a library caller's own program cannot be one, so it asks for `InProcess`.
    Auto,
    /// In worker processes, or refused: a deck without FMUs or a sensitivity design is an error.
    Always,
    /// In this process, on the run's threads: an FMU that crashes takes the run down with it.
    InProcess,
}

/// What decides, chunk by chunk in trial order, that a run has enough trials (the summary's
/// precision monitor). Fed only in trial order, so where it stops depends only on the deck and seed.
pub trait StopRule: Send {
    /// Before the first chunk: the run's manifest (its detectors).
    fn start(&mut self, manifest: &Manifest) -> Result<(), RunError>;
    /// A chunk's rows, after they are appended to `trials.parquet`.
    fn add(&mut self, chunk: &DataFrame, file: &Path) -> Result<(), RunError>;
    fn enough(&self) -> bool;
    /// What `manifest.json` records of the stop.
    fn outcome(&self) -> PrecisionOutcome;
}

/// A [`StopRule`] shared by the options and the writer thread.
#[derive(Clone)]
pub struct StopHandle(pub std::sync::Arc<std::sync::Mutex<dyn StopRule>>);

impl std::fmt::Debug for StopHandle {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("StopHandle")
    }
}

impl StopHandle {
    fn lock(&self) -> Result<std::sync::MutexGuard<'_, dyn StopRule + 'static>, RunError> {
        self.0.lock().map_err(|_| RunError::Internal("the stop rule panicked".into()))
    }
}

/// What a finished run reports.
#[derive(Debug, Clone)]
pub struct RunReport {
    pub manifest: Manifest,
    pub trials_run: u64,
    pub trials_resumed: u64,
    pub seconds: f64,
}

fn part_path(dir: &Path, first_trial: u64) -> PathBuf {
    dir.join("parts").join(format!("part-{first_trial:020}.parquet"))
}

impl Manifest {
    /// A study's fields (kind, name, seed, detector names, and from its `[monte_carlo]` the trial count
    /// and target Pfa) over [`Manifest::unstarted`]; a kind sets its outputs, thresholds and units on top.
    pub fn of<'a>(
        kind: &str,
        header: &StudyHeader,
        monte_carlo: &MonteCarlo,
        detectors: impl IntoIterator<Item = &'a str>,
    ) -> Manifest {
        Manifest {
            kind: kind.into(),
            study: header.name.clone(),
            seed: header.seed,
            trials: monte_carlo.trials,
            target_pfa: monte_carlo.target_pfa,
            confidence: monte_carlo.confidence,
            detection_window_s: monte_carlo.detection_window_s.is_finite().then_some(monte_carlo.detection_window_s),
            profile_resolution: Some(monte_carlo.profile.step()),
            detectors: detectors.into_iter().map(String::from).collect(),
            trial_duration_s: Some(header.duration_s),
            time_to_hazard_s: monte_carlo.time_to_hazard_s.clone(),
            ..Manifest::unstarted()
        }
    }

    /// Every field a run fills in itself at its defaults; a study sets its own fields on top.
    pub fn unstarted() -> Manifest {
        Manifest {
            fdimc_version: env!("CARGO_PKG_VERSION").into(),
            kind: String::new(),
            study: String::new(),
            deck: String::new(),
            deck_sha256: String::new(),
            seed: 0,
            trials: 0,
            shard: Shard::WHOLE,
            first_trial: 0,
            end_trial: 0,
            chunk_trials: CHUNK_TRIALS,
            detectors: Vec::new(),
            outputs: Vec::new(),
            deck_thresholds: Vec::new(),
            target_pfa: 0.0,
            confidence: None,
            trial_duration_s: None,
            detection_window_s: None,
            profile_resolution: None,
            profiles_exact_at_deadlines: false,
            fault_size_units: Default::default(),
            fault_size_bins: Default::default(),
            parameter_error_bins: Default::default(),
            time_to_hazard_s: Default::default(),
            sensor_noise: None,
            command_line: Vec::new(),
            complete: false,
            rows: 0,
            precision: None,
            sensitivity: None,
            models: Vec::new(),
        }
    }
}

/// Runs the trials of `opts.shard` of the source's trials into `opts.out_dir` (see the module
/// docs). The source's manifest carries the study's own fields (kind, name, seed, trials, detectors,
/// outputs, thresholds, units); the run fills in the deck, its hash, the shard and the progress.
pub fn run<S: TrialSource>(source: &S, opts: &RunOptions) -> Result<RunReport, RunError> {
    let study_manifest = source.manifest();
    let started = Instant::now();
    let trials = study_manifest.trials;
    let (first, end) = opts.shard.range(trials);
    let manifest = Manifest {
        fdimc_version: env!("CARGO_PKG_VERSION").into(),
        deck: opts.deck.display().to_string(),
        deck_sha256: deck_sha256(&opts.deck)?,
        shard: opts.shard,
        first_trial: first,
        end_trial: end,
        command_line: opts.command_line.clone(),
        complete: false,
        rows: 0,
        sensitivity: opts.sensitivity.clone(),
        ..study_manifest
    };

    if let Some(stop) = &opts.stop {
        if opts.shard != Shard::WHOLE {
            return Err(RunError::Invalid(
                "--precision stops where the trials before, in order, are precise enough: run it unsharded (it uses \
                 every core), or shard a fixed --trials"
                    .into(),
            ));
        }
        stop.lock()?.start(&manifest)?;
    }
    let dir = &opts.out_dir;
    let _writer = FolderLock::take(dir, &opts.command_line)?;
    crate::engine::run::output::remove_stale_temporaries(&dir.join("trials.parquet"));
    let existing = dir.join("manifest.json").exists();
    if existing && opts.resume {
        let old = Manifest::read(dir)?;
        if !old.same_study(&manifest) || old.shard != manifest.shard {
            return Err(RunError::Invalid(format!(
                "{}: holds a run of another deck, seed, trial count, shard or profile resolution, or one whose profiles \
                 lack the exact points at the window and the hazard (an older fdimc) (deck {}, seed {}, {} trials, shard {}/{}); \
                 --resume continues only the same run: use another --out",
                dir.display(),
                old.deck,
                old.seed,
                old.trials,
                old.shard.index,
                old.shard.count
            )));
        }
        // A run stopped at a precision keeps its parts, so --resume can take it further.
        let stopped_early = old.end_trial < end;
        if old.complete && dir.join("trials.parquet").exists() && !(opts.stop.is_some() && stopped_early) {
            let resumed = old.end_trial - old.first_trial;
            return Ok(RunReport { manifest: old, trials_run: 0, trials_resumed: resumed, seconds: 0.0 });
        }
        if old.complete && !part_path(dir, first).exists() {
            return Err(RunError::Invalid(format!(
                "{}: the part files of the run stopped at trial {} are gone: run again with --force",
                dir.display(),
                old.end_trial
            )));
        }
    } else if existing && !opts.force {
        return Err(RunError::Invalid(format!(
            "{}: already holds a run; use --resume to continue it, --force to replace it, or another --out",
            dir.display()
        )));
    } else if existing {
        // What the old run's summaries wrote would describe trials that are gone.
        let summaries = ["trials.parquet", "thresholds.csv", "comparison.csv", "summarize.json"];
        for name in summaries.into_iter().chain(crate::engine::run::output::SUMMARY_TABLES) {
            let _ = std::fs::remove_file(dir.join(name));
        }
        use crate::engine::run::output::{CALIBRATIONS_DIR, VALIDATION_DIR};
        for sub in ["parts", VALIDATION_DIR, CALIBRATIONS_DIR, "report"] {
            let _ = std::fs::remove_dir_all(dir.join(sub));
        }
    }
    std::fs::create_dir_all(dir.join("parts")).map_err(io(dir))?;
    manifest.write(dir)?;

    let pool = thread_pool(opts.threads)?;
    let bar = Progress::new(&manifest.study, end - first, opts.progress);

    // Simulation and output overlap: a writer thread encodes chunk k (its part file, then its rows
    // appended to trials.parquet) while the pool simulates chunk k + 1. The channel holds one chunk,
    // so memory stays at about three chunks.
    let (mut resumed, mut run_count, mut chunks_written) = (0, 0, 0);
    let (tx, rx) = std::sync::mpsc::sync_channel::<Chunk<S::Result>>(1);
    let precise = std::sync::atomic::AtomicBool::new(false);
    let outcome = std::thread::scope(|scope| -> Result<Option<Written>, RunError> {
        let (stop, precise) = (opts.stop.as_ref(), &precise);
        let writer = scope.spawn(move || write_chunks(source, dir, rx, stop, precise, opts.low_disk));
        let mut chunk_start = first;
        let mut stopped_early = false;
        while chunk_start < end && !precise.load(std::sync::atomic::Ordering::SeqCst) {
            let chunk_end = (chunk_start + manifest.chunk_trials).min(end);
            let path = part_path(dir, chunk_start);
            let chunk = if path.exists() && opts.resume {
                resumed += chunk_end - chunk_start;
                Chunk::Resumed { path, end: chunk_end }
            } else {
                let group = source.group_trials();
                let results: Vec<S::Result> = pool.install(|| {
                    (chunk_start..chunk_end)
                        .step_by(group as usize)
                        .collect::<Vec<u64>>()
                        .into_par_iter()
                        .flat_map_iter(|first| {
                            let r = source.simulate(first, (first + group).min(chunk_end));
                            bar.inc(r.len() as u64);
                            r
                        })
                        .collect()
                });
                run_count += chunk_end - chunk_start;
                chunks_written += 1;
                Chunk::Fresh { path, results, end: chunk_end }
            };
            if tx.send(chunk).is_err() {
                break; // The writer failed; its error is reported below.
            }
            chunk_start = chunk_end;
            if opts.stop_after_chunks.is_some_and(|n| chunks_written >= n) && chunk_start < end {
                stopped_early = true;
                break;
            }
        }
        if !stopped_early && first < end {
            let _ = tx.send(Chunk::Complete);
        }
        drop(tx);
        writer.join().map_err(|_| RunError::Internal("the trials writer panicked".into()))?
    });
    bar.finish();
    let written = outcome?;
    let end_trial = written.as_ref().and_then(|w| w.stopped_at).unwrap_or(end);
    let rows = match written {
        Some(w) => w.rows,
        None if first < end => {
            return Ok(RunReport {
                manifest,
                trials_run: run_count,
                trials_resumed: resumed,
                seconds: started.elapsed().as_secs_f64(),
            });
        }
        None => {
            // A shard with no trials (more shards than trials) still leaves a readable, empty table.
            let path = dir.join("trials.parquet");
            let mut empty = source.frame(&[]).map_err(pol(&path))?;
            write_parquet(&mut empty, &path)?;
            std::fs::remove_dir_all(dir.join("parts")).map_err(io(dir))?;
            0
        }
    };
    let precision = match &opts.stop {
        Some(stop) => Some(stop.lock()?.outcome()),
        None => None,
    };
    let manifest = Manifest { complete: true, rows, end_trial, precision, ..manifest };
    manifest.write(dir)?;
    // A chunk simulated while the writer found the run precise enough is dropped unwritten.
    let kept = end_trial - first;
    let trials_resumed = resumed.min(kept);
    let trials_run = run_count.min(kept - trials_resumed);
    Ok(RunReport { manifest, trials_run, trials_resumed, seconds: started.elapsed().as_secs_f64() })
}

/// What the writer thread receives, in trial order.
enum Chunk<R> {
    /// Simulated now: write its part file; `end`: the trial after its last.
    Fresh { path: PathBuf, results: Vec<R>, end: u64 },
    /// On disk from an interrupted run.
    Resumed { path: PathBuf, end: u64 },
    /// Every chunk was sent: assemble trials.parquet.
    Complete,
}

/// The writer thread: a part file per chunk (for `--resume`) while the pool simulates the next, and
/// the rows in trial order in trials.parquet (under a temporary name until complete, then renamed, and
/// the parts removed). Each chunk is encoded once, into its part; trials.parquet takes the part's row
/// groups byte for byte ([`RowGroupWriter`]). By default each part is appended as it comes, so the run
/// ends when its last chunk is written, and the disk holds the records twice until then. With
/// `low_disk`, the parts are appended only after the last chunk, each removed once appended: the disk
/// holds the records once plus one part; a run killed while assembling has lost the parts already
/// appended, and `--resume` simulates them again (the same rows).
/// Returns the rows of trials.parquet, or `None` if the run stopped before its last chunk. With a
/// `stop` rule, each chunk's rows are measured in trial order, and the file is finished at the first
/// chunk that makes the run precise enough (`precise` tells the simulating side; the parts stay, so a
/// tighter precision can resume).
fn write_chunks<S: TrialSource>(
    source: &S,
    dir: &Path,
    chunks: std::sync::mpsc::Receiver<Chunk<S::Result>>,
    stop: Option<&StopHandle>,
    precise: &std::sync::atomic::AtomicBool,
    low_disk: bool,
) -> Result<Option<Written>, RunError> {
    let out = dir.join("trials.parquet");
    let mut writer = if low_disk { None } else { Some(RowGroupWriter::create(&out)?) };
    let result = (|| {
        let mut parts = Vec::new();
        // The rows so far in trials.parquet, renamed into place; `remove_parts`: the run is complete.
        let finish =
            |writer: &mut Option<RowGroupWriter>, parts: &[PathBuf], remove_parts: bool| -> Result<u64, RunError> {
                match writer.take() {
                    Some(w) => Ok(w.finish()?),
                    None => concatenate(parts, &out, remove_parts && low_disk),
                }
            };
        for chunk in chunks {
            let (df, path, chunk_end) = match chunk {
                Chunk::Fresh { path, results, end } => {
                    let mut df = source.frame(&results).map_err(pol(&path))?;
                    let bytes = encode_parquet(&mut df, &path)?;
                    write_atomically(&path, &bytes)?;
                    if let Some(w) = &mut writer {
                        w.append(&bytes, &path)?;
                    }
                    (stop.is_some().then_some(df), path, end)
                }
                Chunk::Resumed { path, end } => {
                    if let Some(w) = &mut writer {
                        w.append_file(&path)?;
                    }
                    (stop.map(|_| read_parquet(&path)).transpose()?, path, end)
                }
                Chunk::Complete => {
                    let rows = finish(&mut writer, &parts, true)?;
                    std::fs::remove_dir_all(dir.join("parts")).map_err(io(dir))?;
                    return Ok(Some(Written { rows, stopped_at: None }));
                }
            };
            parts.push(path.clone());
            if let (Some(stop), Some(df)) = (stop, &df) {
                let mut rule = stop.lock()?;
                rule.add(df, &path)?;
                if rule.enough() {
                    precise.store(true, std::sync::atomic::Ordering::SeqCst);
                    let rows = finish(&mut writer, &parts, false)?;
                    return Ok(Some(Written { rows, stopped_at: Some(chunk_end) }));
                }
            }
        }
        Ok(None)
    })();
    if let Some(w) = writer {
        w.abandon();
    }
    result
}

/// What the writer finished: its rows, and the trial it stopped before when a precision stopped it.
struct Written {
    rows: u64,
    stopped_at: Option<u64>,
}

/// Writes a complete Parquet file atomically.
pub fn write_parquet(df: &mut DataFrame, path: &Path) -> Result<(), RunError> {
    write_atomically(path, &encode_parquet(df, path)?)
}

/// `df` as a Parquet file (zstd, with column statistics: polars' defaults), in memory.
fn encode_parquet(df: &mut DataFrame, path: &Path) -> Result<Vec<u8>, RunError> {
    let mut bytes = Vec::new();
    ParquetWriter::new(&mut bytes).finish(df).map_err(pol(path))?;
    Ok(bytes)
}

/// Reads a Parquet file, naming it in errors (a corrupt file is the user's input: exit 2).
pub fn read_parquet(path: &Path) -> Result<DataFrame, RunError> {
    let file = File::open(path).map_err(io(path))?;
    ParquetReader::new(file).finish().map_err(|e| {
        RunError::Invalid(format!("{}: not a readable Parquet file ({e}); re-run or remove it", path.display()))
    })
}

/// Concatenates Parquet files (same schema) in order into `out`, their row groups copied as they are
/// ([`RowGroupWriter`]), one input in memory at a time; with `remove_inputs`, each input is removed
/// once its rows are written, so the disk never holds both. Returns the rows written.
pub fn concatenate(inputs: &[PathBuf], out: &Path, remove_inputs: bool) -> Result<u64, RunError> {
    if inputs.is_empty() {
        return Err(RunError::Internal("nothing to concatenate".into()));
    }
    let mut writer = RowGroupWriter::create(out)?;
    let appended = inputs.iter().try_for_each(|path| {
        writer.append_file(path)?;
        if remove_inputs {
            std::fs::remove_file(path).map_err(io(path))?;
        }
        Ok(())
    });
    match appended {
        Ok(()) => Ok(writer.finish()?),
        // Whatever failed, the unfinished file goes.
        Err(e) => {
            writer.abandon();
            Err(e)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shards_cover_the_trials_exactly_once() {
        for trials in [1u64, 7, 4096, 10_001] {
            for count in 1..6 {
                let mut next = 0;
                for index in 0..count {
                    let (a, b) = Shard { index, count }.range(trials);
                    assert_eq!(a, next);
                    next = b;
                }
                assert_eq!(next, trials);
            }
        }
        assert!(Shard::parse("3/2").is_err());
        assert!(Shard::parse("1/0").is_err());
        assert!(Shard::parse("x").is_err());
        assert_eq!(Shard::parse("1/4"), Ok(Shard { index: 1, count: 4 }));
    }

    /// `--shard auto` from each scheduler's variables; every inconsistent environment refused.
    #[test]
    fn the_scheduler_names_the_shard() {
        let env = |vars: &[(&str, &str)]| {
            let vars: Vec<(String, String)> = vars.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect();
            move |name: &str| vars.iter().find(|(k, _)| k == name).map(|(_, v)| v.clone())
        };
        let slurm = |id: &str, count: &str| {
            env(&[("SLURM_ARRAY_TASK_ID", id), ("SLURM_ARRAY_TASK_COUNT", count), ("SLURM_ARRAY_TASK_MIN", "0")])
        };
        assert_eq!(Shard::from_arg("auto", slurm("2", "4")), Ok((Shard { index: 2, count: 4 }, true)));
        assert_eq!(Shard::from_arg("auto/4", slurm("3", "4")), Ok((Shard { index: 3, count: 4 }, true)));
        assert_eq!(Shard::from_arg("1/4", slurm("3", "4")), Ok((Shard { index: 1, count: 4 }, false)));
        // --array=1-4: tasks 1..4 are shards 0..3.
        let one_based =
            env(&[("SLURM_ARRAY_TASK_ID", "4"), ("SLURM_ARRAY_TASK_MIN", "1"), ("SLURM_ARRAY_TASK_MAX", "4")]);
        assert_eq!(Shard::from_scheduler(None, one_based), Ok(Shard { index: 3, count: 4 }));
        let k8s = env(&[("JOB_COMPLETION_INDEX", "5")]);
        assert_eq!(Shard::from_arg("auto/8", &k8s), Ok((Shard { index: 5, count: 8 }, true)));
        let k8s_env = env(&[("JOB_COMPLETION_INDEX", "0"), ("FDIMC_SHARD_COUNT", "2")]);
        assert_eq!(Shard::from_scheduler(None, k8s_env), Ok(Shard { index: 0, count: 2 }));
        for (arg, vars, want) in [
            ("auto", vec![], "no array task in the environment"),
            ("auto", vec![("SLURM_ARRAY_TASK_ID", "1"), ("JOB_COMPLETION_INDEX", "1")], "both"),
            ("auto", vec![("SLURM_ARRAY_TASK_ID", "x")], "not a whole number"),
            ("auto", vec![("SLURM_ARRAY_TASK_ID", "1")], "neither SLURM_ARRAY_TASK_COUNT"),
            ("auto", vec![("SLURM_ARRAY_TASK_ID", "4"), ("SLURM_ARRAY_TASK_COUNT", "4")], "outside the array's 0..4"),
            (
                "auto",
                vec![
                    ("SLURM_ARRAY_TASK_ID", "4"),
                    ("SLURM_ARRAY_TASK_MIN", "0"),
                    ("SLURM_ARRAY_TASK_MAX", "12"),
                    ("SLURM_ARRAY_TASK_COUNT", "4"),
                ],
                "a stepped or sparse --array",
            ),
            ("auto/3", vec![("SLURM_ARRAY_TASK_ID", "1"), ("SLURM_ARRAY_TASK_COUNT", "4")], "has 4 tasks"),
            ("auto", vec![("JOB_COMPLETION_INDEX", "1")], "give --shard auto/N"),
            ("auto/2", vec![("JOB_COMPLETION_INDEX", "2")], "outside 0..2"),
            ("auto/2", vec![("JOB_COMPLETION_INDEX", "1"), ("FDIMC_SHARD_COUNT", "3")], "FDIMC_SHARD_COUNT says 3"),
            ("auto/0", vec![("JOB_COMPLETION_INDEX", "0")], "expected auto or auto/N"),
        ] {
            let e = Shard::from_arg(arg, env(&vars)).unwrap_err();
            assert!(e.contains(want), "{arg} {vars:?}: {e}");
        }
    }
}
