//! Command line: clap definitions, one `exec` per subcommand, the exit codes ([`exit`]).
//!
//! [`main_with`] is the whole program over fdimc's own kinds of study and a caller's: a crate that adds
//! a kind of its own calls it from its `main` (`examples/custom_method.rs`).

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{CommandFactory, FromArgMatches, Parser, Subcommand};

use crate::engine::method::Method;
use crate::engine::run::output::OutputError;
use crate::engine::scenario::deck::DeckError;

mod fmu;
mod log;
mod run;
pub mod verify;

#[derive(Debug, Parser)]
#[command(
    name = "fdimc",
    version,
    about = "Monte Carlo robustness studies of fault detection and isolation in flight control",
    long_about = "Monte Carlo robustness studies of fault detection and isolation (FDI) in flight control.\n\n\
A study deck (TOML, see studies/) names a plant, sensor noise, faults and a detector. Start with\n\
`fdimc validate DECK` to see what the deck resolves to, `fdimc design DECK` for the detector's gains and\n\
closed-loop eigenvalues, and `fdimc simulate DECK --trial 0 --out trace.csv` for one trial's residuals."
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
    /// run, summarize, merge, report: print the details behind the answer too (the calibration, the tail fits,
    /// the per-detector table, the safety sentences, every warning whole); otherwise the answer, a line
    /// per warning naming the file that explains it, and what to look at next.
    #[arg(long, global = true)]
    pub verbose: bool,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Write a starter deck of a kind of study (commented; it validates and runs as written). With
    /// --replay LOG (kind accelerometer), a deck that replays that PX4 log instead of simulating.
    #[command(after_help = "Example: fdimc new air_data my_air_data.toml && fdimc run my_air_data.toml\n\
Replay: fdimc new accelerometer my_replay.toml --replay studies/logs/sample_appended_multiple.ulg && fdimc run my_replay.toml")]
    New {
        /// The kind of study (one of the registry's, listed by --help).
        #[arg(index = 1)]
        kind: String,
        /// The deck to write; its name (without .toml) names the study and its results folder.
        #[arg(index = 2)]
        file: PathBuf,
        /// Replace an existing file.
        #[arg(long)]
        force: bool,
        /// A PX4 ULog file (.ulg) to replay (kind accelerometer): the deck's `[log]` names it, its first
        /// half trains, its second half is evaluated.
        #[arg(long, value_name = "LOG")]
        replay: Option<PathBuf>,
    },
    /// Parse and validate a deck, design its detector, and print the resolved study.
    Validate {
        /// Study deck (TOML).
        deck: PathBuf,
    },
    /// Design the detector: gains, closed-loop eigenvalues, eigenvector conditioning, plant ranks.
    Design {
        /// Study deck (TOML).
        deck: PathBuf,
        /// Print JSON (for scripts) instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Simulate one trial and write its per-sample trace (time, inputs, measurements, estimates,
    /// residuals, alarms).
    Simulate {
        /// Study deck (TOML).
        deck: PathBuf,
        /// Trial index: selects the trial's random streams (same index, same noise).
        #[arg(long, default_value_t = 0)]
        trial: u64,
        /// Detector configuration to trace (default: the deck's first).
        #[arg(long)]
        detector: Option<String>,
        /// Trace file; the format follows the extension: .csv or .parquet.
        #[arg(long)]
        out: PathBuf,
        /// Accelerometer decks: classifiers written by `fdimc train` (default: trained now).
        #[arg(long, value_name = "FILE")]
        classifiers: Option<PathBuf>,
    },
    /// Train an accelerometer deck's classifiers (the SVM decision tree and the flat one-against-one
    /// SVM) on the deck's training trials and save them; `run --classifiers FILE` evaluates them.
    Train {
        /// Accelerometer study deck (TOML, with `[imu]`).
        deck: PathBuf,
        /// Classifiers file (default: `results/<study>/classifiers.json`).
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Run the Monte Carlo study: trials in parallel, records to DIR/trials.parquet, then thresholds
    /// and summaries (thresholds.csv, summary.csv/.parquet, curves.csv, min_detectable.csv).
    #[command(after_help = "Shards: run `--shard I/N` for I = 0..N-1 (e.g. as a SLURM array), then `fdimc merge`.\n\
The same deck and seed give identical records for any --threads, shard split or --resume.\n\
Precision: `--precision 0.01 --precision-rates pd,pfa --trials 1000000` runs until every Pd and Pfa of summary.csv is within \
+/-0.01 (95 %), at most 10^6 trials.")]
    Run {
        /// Study deck (TOML).
        deck: PathBuf,
        /// Number of trials (default: the deck's monte_carlo.trials).
        #[arg(long)]
        trials: Option<u64>,
        #[command(flatten)]
        folder: RunFolder,
        /// Accelerometer decks: evaluate the classifiers in FILE (written by `fdimc train`) instead of
        /// training them first.
        #[arg(long, value_name = "FILE")]
        classifiers: Option<PathBuf>,
        /// Stop at the first chunk boundary where every rate of summary.csv's groups (deck thresholds)
        /// has a 95 % Wilson half-width of at most W (e.g. 0.01); --trials (or the deck's) is then a
        /// cap. Where it stops depends only on the deck and seed; --resume with a smaller W goes on.
        #[arg(long, value_name = "W")]
        precision: Option<f64>,
        /// The rates --precision watches (default all): pd, pfa, isolation_accuracy.
        #[arg(long, value_name = "R,...", value_delimiter = ',', requires = "precision")]
        precision_rates: Vec<String>,
    },
    /// Recompute thresholds and summaries from DIR/trials.parquet, without simulating; every kind
    /// records a detection statistic (for detectors that declare on a held probability, how long it
    /// held: the threshold is the hold), so every run also gets roc.csv (Pd against Pfa as the
    /// thresholds scale) and tail.csv:
    /// false-alarm rates and thresholds below 1/trials (1e-5 to 1e-9 per flight hour) from a
    /// generalised Pareto fit, with 95 % intervals and when not to trust it. A calibration other than
    /// the deck's (--target-pfa, --target-pfa-per-hour, --confidence) is written to
    /// a folder of its own under DIR/calibrations/ (pfa_0.05, pfa_0.01_confidence_0.95,
    /// pfa_per_hour_1e-5, ...), --thresholds to DIR/validation/: the run's own tables stay. A target the
    /// fault-free trials cannot resolve is refused (exit 2), nothing written.
    Summarize {
        /// Results folder of a complete run.
        dir: PathBuf,
        /// Target false-alarm probability per trial (default: the deck's monte_carlo.target_pfa).
        #[arg(long)]
        target_pfa: Option<f64>,
        /// Calibrate conservatively (default: the deck's monte_carlo.confidence, if it sets one):
        /// thresholds whose true false-alarm probability is at most the target with this confidence (e.g. 0.95: Wilks' order statistic; says how many fault-free trials it
        /// needs when there are too few).
        #[arg(long)]
        confidence: Option<f64>,
        /// Target false-alarm probability per flight hour instead of per trial: converted from the
        /// trial's duration, the hour's trials taken as independent segments (e.g. 1e-5).
        #[arg(long, value_name = "P")]
        target_pfa_per_hour: Option<f64>,
        /// Evaluate with the thresholds of another run (its thresholds.csv) instead of calibrating:
        /// validates a calibration on fresh trials.
        #[arg(long, value_name = "THRESHOLDS_CSV")]
        thresholds: Option<PathBuf>,
    },
    /// Estimate false-alarm probabilities far below 1 / trials (1e-5 .. 1e-20 per trial) by simulation, unbiased:
    /// importance sampling on the sensor noise (default; statistics without memory) or adaptive
    /// multilevel splitting (statistics with memory: a CUSUM, a windowed test). Writes rare_event.csv.
    #[command(after_help = "Example: fdimc rare-event studies/seed000_rare_false_alarms.toml --levels 1,1.2,1.4\n\
Every trial is fault-free (the deck's faults are removed; its noise scale and parameter errors stay). A level is a \
threshold scale: the detector alarms when a statistic exceeds its deck threshold times the level. The same deck, \
seed and options give the same numbers for any --threads.")]
    RareEvent(RareEventArgs),
    /// Thresholds for a false-alarm target per flight hour (or per flight) over whole flights of a
    /// stated length, found on the residual's exact law and confirmed by fresh draws of another
    /// estimate: their per-flight (and per-hour) figure with its one-sided 95 % upper bound, which must
    /// lie below the target. Writes DIR/flight_thresholds.csv and, for the confirmed detectors,
    /// DIR/thresholds.csv (`summarize RUN --thresholds` reads it); exit 1 when a detector's could not
    /// be confirmed (nothing written as its calibration). Detection-filter decks with a linear truth;
    /// other kinds are told what to run instead.
    #[command(
        after_help = "Example: fdimc flight-thresholds studies/seed000_lateral_slow_mode.toml --per-hour 1e-7 --flight-s 3600
An hour is 3600 / F flights of F seconds, each begun with the filter on the truth, independent. With --allocation \
equal each output gets the same share of the target; with deck the deck's thresholds are scaled together. \
The search aims at 0.9 of the target (room for the confirmation's interval). Then: \
fdimc summarize RUN --thresholds DIR/thresholds.csv reads detection at the thresholds found."
    )]
    FlightThresholds(FlightThresholdsArgs),
    /// The worst point of the deck's uncertainty box: the parameter errors, noise scale, fault size and
    /// onset (each within the deck's range or list) where a detector misses most, alarms falsely most,
    /// detects latest or isolates worst, by CMA-ES against random points of the same budget, both
    /// confirmed on fresh trials. Writes DIR/worst_case.csv.
    #[command(after_help = "Example: fdimc worst-case studies/seed000_worst_case.toml --objective pd --detector fast
Each candidate point is judged on the same batch of trials (the same noise, fault kinds and outputs), so candidates differ only in the point; the best of each search is judged again on --confirm fresh trials, beside the deck as drawn. The same deck, seed and options give the same point for any --threads. --write-deck FILE writes the deck at the found point, for fdimc simulate, run and report --trials.")]
    WorstCase(WorstCaseArgs),
    /// Which uncertainty drives the misses and false alarms: Sobol indices (first and total order, with
    /// 95 % bootstrap intervals) of Pd, isolation, delay and Pfa per detector to every factor the deck's
    /// trials draw, the noise realisation among them. Writes DIR/sensitivity.csv and .parquet.
    #[command(after_help = "Example: fdimc run studies/seed000_robustness.toml, then\n  \
fdimc sensitivity studies/seed000_robustness.toml --base-samples 4096 --thresholds results/seed000_robustness/thresholds.csv\n\
The trials are the rows of a Saltelli design: matrices A and B of --base-samples rows each and, per factor i, A with \
column i from B, for faulty and for fault-free trials: base-samples x (factors + 2) trials per part. \
It prints the factors before it runs. Shards, --resume and `fdimc merge` work as for `run`; \
`fdimc report DIR` draws the indices.")]
    Sensitivity {
        /// Study deck (TOML).
        deck: PathBuf,
        /// Rows of each of the matrices A and B; the interval half-widths shrink as 1/sqrt(N).
        #[arg(long, default_value_t = 512)]
        base_samples: u64,
        /// Bootstrap resamples of the base rows for the 95 % intervals.
        #[arg(long, default_value_t = 500)]
        bootstrap: u64,
        #[command(flatten)]
        folder: RunFolder,
        /// Read the outcomes at the whole-detector thresholds of another run's thresholds.csv (e.g. the
        /// deck's own run, calibrated at its target Pfa) instead of the deck's; leaves out isolation,
        /// which is recorded at the deck's thresholds only.
        #[arg(long, value_name = "THRESHOLDS_CSV")]
        thresholds: Option<PathBuf>,
    },
    /// (Internal) `run --fmu-processes`' worker: flies a detection-filter deck's trials as its parent
    /// asks on stdin, answering on stdout.
    #[command(hide = true)]
    FmuWorker {
        deck: PathBuf,
        #[arg(long)]
        seed: u64,
        #[arg(long)]
        trials: u64,
        #[arg(long)]
        profile_resolution: f64,
        /// `fdimc sensitivity`'s design: its base samples and bootstrap resamples.
        #[arg(long, requires = "design_bootstrap")]
        design_base_samples: Option<u64>,
        #[arg(long, requires = "design_base_samples")]
        design_bootstrap: Option<u64>,
    },
    /// Join the results folders of all shards of one run into one, then summarize.
    Merge {
        /// Shard results folders (any order).
        #[arg(required = true)]
        dirs: Vec<PathBuf>,
        /// Merged results folder.
        #[arg(long)]
        out: PathBuf,
        /// Replace an existing run in --out.
        #[arg(long)]
        force: bool,
    },
    /// Plots (SVG) and a one-page HTML summary of a run, in DIR/report/.
    Report {
        /// Results folder of a complete run.
        dir: PathBuf,
        /// Trials whose residual traces to plot (re-simulated from the run's deck), e.g. 3,17.
        #[arg(long, value_delimiter = ',')]
        trials: Vec<u64>,
    },
    /// What a flight log (PX4 ULog) holds: every topic instance with its samples, span (seconds from
    /// the log's first sample; its boot time is printed once), mean rate, largest gap and timestamps that
    /// repeat or go back (bad_times); with --topic, the mean and spread of each of its number fields and
    /// its noise's law (the excess kurtosis and the Student-t of it, for a deck's noise.sensor_law);
    /// with --plot, chosen fields over time as an SVG, a replay deck's train_s and evaluate_s shaded.
    #[command(after_help = "Examples: fdimc log studies/logs/sample_log_small.ulg --topic sensor_combined\n  \
fdimc log studies/logs/sample_appended_multiple.ulg --plot imu.svg --signals gyro_rad[2],accelerometer_m_s2[2] --deck studies/replay_px4.toml\n\
Times are seconds from the first sample, as a deck's [log] evaluate_s and train_s are (those count from the replayed topic's first sample).")]
    Log {
        /// The log file (.ulg).
        file: PathBuf,
        /// A topic whose fields to summarise or plot (default for --plot: the deck's, else sensor_combined).
        #[arg(long)]
        topic: Option<String>,
        /// The topic's instance (multi_id; 0 for the first or only one).
        #[arg(long, default_value_t = 0)]
        instance: u8,
        /// Draw --signals over time (s from the topic's first sample) into this SVG file.
        #[arg(long, value_name = "OUT.svg")]
        plot: Option<PathBuf>,
        /// The topic's fields to draw, e.g. `gyro_rad[0],gyro_rad[2]`.
        #[arg(long, value_name = "FIELD,...", value_delimiter = ',', requires = "plot")]
        signals: Vec<String>,
        /// A replay deck of this log: its `[log]` topic, and its train_s and evaluate_s shaded on the plot.
        #[arg(long, value_name = "DECK", requires = "plot")]
        deck: Option<PathBuf>,
    },
    /// What an FMU (FMI 2.0 or 3.0) offers a deck: its interfaces and whether they run here, its
    /// capabilities (get/set state, directional derivatives, instances per process), inputs, outputs,
    /// continuous states (in state order, with their derivatives) and parameters with types and array
    /// sizes, start values, units and declared ranges, and the default experiment.
    #[command(
        after_help = "Example: fdimc fmu target/fmus/aircraft.fmu   (cargo run --release --example build_fmus builds the test FMUs)"
    )]
    Fmu {
        /// The FMU file (.fmu).
        file: PathBuf,
        /// List the model's local variables too (internal values a trim or an initial state may be
        /// read from).
        #[arg(long)]
        locals: bool,
    },
    /// Run known-answer cases on this build and machine (closed forms and the exact laws the tests use,
    /// each against a run's 95 % interval) and write verification.csv and verification.html with the
    /// build's version and commit, the CPU and the lane path's vector form; exit 1 when a case fails.
    /// For a safety case's tool qualification (docs/verification.md); a few seconds (--full: minutes).
    #[command(after_help = "Example: fdimc verify --out results/verify && open results/verify/verification.html")]
    Verify {
        /// Results folder (default: results/verify).
        #[arg(long, default_value = "results/verify")]
        out: PathBuf,
        /// The full form: each run case over 20 seeds (its 95 % intervals' coverage), the second
        /// implementation at 20,000 trials and on the robustness deck (parameter errors, the CUSUM and
        /// Kalman chi-square baselines); 1.5 to 3 minutes on 2 cores.
        #[arg(long)]
        full: bool,
        /// Seeds each run case's coverage is counted over, at least 8 (default: none; 20 with --full).
        #[arg(long)]
        seeds: Option<u64>,
        /// Python with NumPy, SciPy and polars, for the second implementation (default: $FDIMC_PYTHON,
        /// else python3); without them that case is not run, and verify says so.
        #[arg(long)]
        python: Option<PathBuf>,
    },
    /// Statistical regression check against a baseline summary; exit 1 on regression.
    #[command(after_help = "Make a baseline: cp results/<study>/summary.csv results/baselines/<study>.csv")]
    Check {
        /// A deck (run now, in a scratch folder) or the results folder of a run.
        target: PathBuf,
        /// Baseline summary (summary.csv or summary.parquet of an earlier run).
        #[arg(long)]
        baseline: PathBuf,
        /// Family-wise significance level (Bonferroni over all groups and rates).
        #[arg(long, default_value_t = 0.01)]
        alpha: f64,
        /// Worker threads when running a deck.
        #[arg(long)]
        threads: Option<usize>,
    },
}

/// The options of `rare-event`.
#[derive(Debug, clap::Args)]
pub struct RareEventArgs {
    /// Study deck (TOML).
    pub deck: PathBuf,
    /// The detector to study (default: every one of the deck).
    #[arg(long)]
    pub detector: Option<String>,
    /// importance (sensor-noise importance sampling) or splitting (adaptive multilevel splitting).
    #[arg(long, default_value = "importance", value_parser = ["importance", "splitting"])]
    pub estimator: String,
    /// Threshold scales to estimate at (the deck's thresholds times each), e.g. 1,1.2,1.4.
    #[arg(long, value_name = "S,...", value_delimiter = ',', default_value = "1")]
    pub levels: Vec<f64>,
    /// Importance sampling: trials, the first fifth a pilot that tunes the mixture [default: 20000].
    #[arg(long)]
    pub trials: Option<u64>,
    /// Splitting: particles per replica [default: 100].
    #[arg(long)]
    pub particles: Option<usize>,
    /// Splitting: independent replicas, whose spread gives the interval [default: 16].
    #[arg(long)]
    pub replicas: Option<u64>,
    /// Also fly fault-free flights of F seconds (a whole number of the deck's trials, e.g. 3600),
    /// estimate their false-alarm probability the same way, and compare it with the conversion from
    /// the deck's trials (per_hour.csv: both, and the extremal index linking them).
    #[arg(long, value_name = "F")]
    pub flight_s: Option<f64>,
    /// Instead of false alarms: the probability that a faulty trial's fault is not detected within its
    /// time to hazard (the deck's [monte_carlo.time_to_hazard_s]), by splitting in time (with
    /// --estimator splitting; --particles, --replicas); writes miss_before_hazard.csv.
    #[arg(long)]
    pub miss_before_hazard: bool,
    /// With --flight-s and importance sampling: the flights [default: 1000].
    #[arg(long, value_name = "N", requires = "flight_s")]
    pub flight_trials: Option<u64>,
    #[command(flatten)]
    pub place: Placement,
    /// No progress or pilot lines.
    #[arg(long)]
    pub quiet: bool,
}

/// The options of `flight-thresholds`.
#[derive(Debug, clap::Args)]
pub struct FlightThresholdsArgs {
    /// Study deck (TOML).
    pub deck: PathBuf,
    /// The target: the probability of at least one false alarm in a flight hour (e.g. 1e-7).
    #[arg(long, value_name = "P", required_unless_present = "per_flight", conflicts_with = "per_flight")]
    pub per_hour: Option<f64>,
    /// The target per flight instead (at least one false alarm in a flight of --flight-s).
    #[arg(long, value_name = "P")]
    pub per_flight: Option<f64>,
    /// The flights' length in seconds: each begins with the filter on the truth.
    #[arg(long, value_name = "F", default_value_t = 3600.0)]
    pub flight_s: f64,
    /// How the target is shared among a detector's outputs: equal (each the same share) or deck (the
    /// deck's thresholds scaled together).
    #[arg(long, default_value = "equal", value_parser = ["equal", "deck"])]
    pub allocation: String,
    /// The detector (default: every one of the deck).
    #[arg(long)]
    pub detector: Option<String>,
    /// Seed of the confirmation's draws (default: the deck's study.seed).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Results folder (default: `results/<study name>/flight_thresholds`).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Worker threads (default: one per core).
    #[arg(long)]
    pub threads: Option<usize>,
}

#[derive(Debug, clap::Args)]
pub struct WorstCaseArgs {
    /// Study deck (TOML).
    pub deck: PathBuf,
    /// What to make worst: pd (missed faults), pfa (false alarms), delay_p90 (the 90th percentile of the
    /// detection delay) or isolation (wrong isolations).
    #[arg(long, value_parser = ["pd", "pfa", "delay_p90", "isolation"])]
    pub objective: String,
    /// The detector judged (default: the deck's first).
    #[arg(long)]
    pub detector: Option<String>,
    /// Trials each search spends (CMA-ES's candidates, and the random search's, times --batch).
    #[arg(long, default_value_t = 4000)]
    pub budget: u64,
    /// Trials per candidate (the same trials for every candidate).
    #[arg(long, default_value_t = 100)]
    pub batch: u64,
    /// Fresh trials on which the found points and the deck as drawn are judged again.
    #[arg(long, default_value_t = 2000)]
    pub confirm: u64,
    /// Also write the deck at the found point to FILE.
    #[arg(long, value_name = "FILE")]
    pub write_deck: Option<PathBuf>,
    /// Seed, threads and results folder (under it worst_case/); a search is not sharded.
    #[command(flatten)]
    pub place: Placement,
    /// Print nothing.
    #[arg(long)]
    pub quiet: bool,
}

/// Seed, threads, results folder and shard: where `run`, `sensitivity` and `rare-event` fly their trials.
#[derive(Debug, Default, clap::Args)]
pub struct Placement {
    /// Study seed (default: the deck's study.seed); another seed gives fresh trials.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Worker threads (default: one per core).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Results folder (default: `results/<study name>`, and under it sensitivity/, rare_event/ or
    /// worst_case/ for those commands; a shard's in shard-I-of-N under it).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Run only shard I of N (0-based) of the trial chunks (rare-event splitting: of the replicas), e.g.
    /// 0/4, then `fdimc merge` the N folders; `auto` (or auto/N): the scheduler's array task
    /// (SLURM_ARRAY_TASK_ID, a Kubernetes JOB_COMPLETION_INDEX), its folder shard-I-of-N under --out.
    #[arg(long, value_name = "I/N|auto")]
    pub shard: Option<String>,
}

/// Where and how `run` and `sensitivity` fly their trials.
#[derive(Debug, clap::Args)]
pub struct RunFolder {
    #[command(flatten)]
    pub place: Placement,
    /// Continue an interrupted run in the same folder (same deck, seed, trials or design, and shard).
    #[arg(long)]
    pub resume: bool,
    /// Replace an existing run in the results folder.
    #[arg(long, conflicts_with = "resume")]
    pub force: bool,
    /// No progress bar or report.
    #[arg(long)]
    pub quiet: bool,
    /// Stop after writing N part files (4096 trials each for detection filters, 64 for surface banks), as
    /// if interrupted; continue later with --resume.
    #[arg(long, value_name = "N")]
    pub stop_after: Option<u64>,
    /// Insist on worker processes (the default for a deck with FMUs): each thread's trials fly in a
    /// process of its own, so an FMU that crashes its process or is not thread-safe fails only the
    /// trial it was flying, recorded with how the process died, and the run goes on. A deck without
    /// FMUs is refused. The records are the same either way.
    #[arg(long, conflicts_with = "fmu_in_process")]
    pub fmu_processes: bool,
    /// Fly a deck's FMUs in this process, on the run's threads (no worker processes): saves a process
    /// start per thread and a pipe round trip per trial, but an FMU that crashes, or whose runtime is
    /// not thread-safe, takes the whole run down. For FMUs known to be safe.
    #[arg(long)]
    pub fmu_in_process: bool,
    /// Hold the records on disk once: the part files are appended to trials.parquet only after the
    /// last one, each removed once appended (by default rows are appended as they come and the parts
    /// kept until the end, twice the records' size). Costs copying every part's bytes at the end (the
    /// same trials.parquet, byte for byte; the robustness deck 6.4 s against 6.1 s); for runs whose
    /// records near the free disk (10^7 trials: docs/performance.md).
    #[arg(long)]
    pub low_disk: bool,
    /// The recorded first-passage profiles' value grid, a relative step (default: the deck's
    /// monte_carlo.profile_resolution, else 0.05): alarm times replayed at other thresholds are those of
    /// the grid level above the threshold. 0 keeps every rise at its exact value (full profiles); 1, a
    /// point per doubling, is the lean setting for 10^7 trials (docs/outputs.md gives the sizes).
    #[arg(long, value_name = "STEP", allow_negative_numbers = true)]
    pub profile_resolution: Option<f64>,
}

/// An error the CLI reports, with its exit code.
#[derive(Debug)]
pub enum CliError {
    /// Bad deck, arguments or input files: exit 2.
    Invalid(String),
    /// I/O or internal failure: exit 3.
    Internal(String),
}

impl From<DeckError> for CliError {
    fn from(e: DeckError) -> Self {
        CliError::Invalid(e.to_string())
    }
}

impl From<OutputError> for CliError {
    fn from(e: OutputError) -> Self {
        match e {
            OutputError::UnknownFormat { .. } => CliError::Invalid(e.to_string()),
            OutputError::Io { .. } | OutputError::Polars { .. } => CliError::Internal(e.to_string()),
        }
    }
}

/// The exit codes of every command, in one place (`fdimc --help` lists them, as does docs/commands.md).
pub mod exit {
    /// The command did what was asked.
    pub const OK: u8 = 0;
    /// `check` found a regression against the baseline.
    pub const REGRESSION: u8 = 1;
    /// `flight-thresholds` could not confirm a detector's thresholds.
    pub const NOT_CONFIRMED: u8 = 1;
    /// `verify`: a known-answer case failed.
    pub const CASE_FAILED: u8 = 1;
    /// Invalid input: a deck, an argument or an input file; the message names the file and the field.
    pub const INVALID_INPUT: u8 = 2;
    /// An I/O or internal error.
    pub const INTERNAL: u8 = 3;

    /// The codes as `--help` prints them.
    pub fn help() -> String {
        format!(
            "Exit codes: {OK} ok, {REGRESSION} regression found (check), thresholds not confirmed (flight-thresholds) or a case failed (verify), {INVALID_INPUT} invalid input (deck, \
             arguments, files), {INTERNAL} I/O or internal error."
        )
    }
}

/// fdimc's command line over its own kinds of study and `extra` ones: what `fdimc` itself runs (with
/// none), and what a crate that adds a kind of its own calls from its `main`, e.g.
/// `fdimc::cli::main_with(&[&MY_METHOD])`. Every command then finds the caller's kind as it finds
/// fdimc's own: by the table that marks a deck, or the kind a results folder's manifest names.
///
/// # Panics
/// When a kind or marker table of `extra` is already taken (a programming error of the caller).
pub fn main_with(extra: &[&'static Method]) -> ExitCode {
    // A reader that stops early (`fdimc design deck | head`) ends fdimc quietly, as it does any Unix
    // tool, instead of a panic on the broken pipe. Results are written by rename, so nothing is left
    // half-written.
    #[cfg(unix)]
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    let kinds = registry_with(extra);
    let cli = command(kinds).try_get_matches().and_then(|m| Cli::from_arg_matches(&m)).unwrap_or_else(|e| e.exit());
    run(cli, kinds)
}

/// fdimc's own kinds followed by `extra`, for the life of the process.
pub fn registry_with(extra: &[&'static Method]) -> &'static [&'static Method] {
    let all: Vec<&'static Method> = crate::methods::REGISTRY.iter().chain(extra).copied().collect();
    for (i, m) in all.iter().enumerate() {
        for o in &all[..i] {
            assert!(m.kind != o.kind, "two kinds of study are named {:?}", m.kind);
            assert!(m.marker != o.marker, "kinds {:?} and {:?} are both marked by [{}]", o.kind, m.kind, m.marker);
        }
    }
    Box::leak(all.into_boxed_slice())
}

/// The clap command over `kinds`: `new` takes their names, and `--help` ends with the exit codes.
pub fn command(kinds: &[&'static Method]) -> clap::Command {
    let names: Vec<&'static str> = kinds.iter().map(|m| m.kind).collect();
    Cli::command().after_help(exit::help()).mut_subcommand("new", |c| {
        c.mut_arg("kind", |a| a.value_parser(clap::builder::PossibleValuesParser::new(names)))
    })
}

/// Runs one parsed command over `kinds` and returns its exit code ([`exit`]).
pub fn run(cli: Cli, kinds: &'static [&'static Method]) -> ExitCode {
    let commands = run::Kinds(kinds);
    crate::engine::results::summary::set_verbose(cli.verbose);
    let result = match cli.command {
        Command::New { kind, file, force, replay } => commands.exec_new(&kind, &file, force, replay.as_deref()),
        Command::Validate { deck } => commands.exec_validate(&deck),
        Command::Design { deck, json } => commands.exec_design(&deck, json),
        Command::Simulate { deck, trial, detector, out, classifiers } => {
            commands.exec_simulate(&deck, trial, detector.as_deref(), &out, classifiers.as_deref())
        }
        Command::Train { deck, out } => commands.exec_train(&deck, out.as_deref()),
        Command::Run { deck, trials, folder, classifiers, precision, precision_rates } => commands
            .exec_run(run::RunArgs {
                precision,
                precision_rates,
                deck: &deck,
                trials,
                folder,
                classifiers: classifiers.as_deref(),
                sensitivity: None,
            })
            .map(|_| ()),
        Command::RareEvent(args) => commands.exec_rare_event(args),
        Command::WorstCase(args) => commands.exec_worst_case(args),
        Command::FlightThresholds(args) => match commands.exec_flight_thresholds(args) {
            Ok(true) => Ok(()),
            Ok(false) => return ExitCode::from(exit::NOT_CONFIRMED),
            Err(e) => Err(e),
        },
        Command::Sensitivity { deck, base_samples, bootstrap, folder, thresholds } => {
            if !(2..=crate::engine::scenario::streams::MAX_TRIAL / 64).contains(&base_samples) {
                Err(CliError::Invalid(format!(
                    "--base-samples {base_samples}: allowed 2 to {}",
                    crate::engine::scenario::streams::MAX_TRIAL / 64
                )))
            } else if !(10..=100_000).contains(&bootstrap) {
                Err(CliError::Invalid(format!("--bootstrap {bootstrap}: allowed 10 to 100000")))
            } else {
                commands
                    .exec_run(run::RunArgs {
                        precision: None,
                        precision_rates: Vec::new(),
                        deck: &deck,
                        trials: None,
                        folder,
                        classifiers: None,
                        sensitivity: Some(run::SensitivityArgs { base_samples, bootstrap, thresholds }),
                    })
                    .map(|_| ())
            }
        }
        Command::Summarize { dir, target_pfa, confidence, target_pfa_per_hour, thresholds } => {
            commands.exec_summarize(&dir, target_pfa, target_pfa_per_hour, confidence, thresholds.as_deref())
        }
        Command::Merge { dirs, out, force } => commands.exec_merge(&dirs, &out, force),
        Command::FmuWorker { deck, seed, trials, profile_resolution, design_base_samples, design_bootstrap } => {
            let design = design_base_samples.zip(design_bootstrap);
            crate::methods::detection_filter::workers::serve(&deck, seed, trials, profile_resolution, design)
                .map_err(CliError::from)
        }
        Command::Report { dir, trials } => commands.exec_report(&dir, &trials),
        Command::Log { file, topic, instance, plot, signals, deck } => log::exec_log(&log::LogArgs {
            file: &file,
            topic: topic.as_deref(),
            instance,
            plot: plot.as_deref(),
            signals: &signals,
            deck: deck.as_deref(),
        }),
        Command::Fmu { file, locals } => fmu::exec_fmu(&file, locals),
        Command::Verify { out, full, seeds, python } => match verify::exec_verify(
            &out,
            &verify::VerifyOptions {
                seeds: seeds.unwrap_or(if full { 20 } else { 0 }),
                second_trials: if full { 20_000 } else { 3_000 },
                second_with_parameter_errors: full,
                python: python
                    .or_else(|| std::env::var_os("FDIMC_PYTHON").map(PathBuf::from))
                    .unwrap_or_else(|| PathBuf::from("python3")),
            },
        ) {
            Ok(true) => Ok(()),
            Ok(false) => return ExitCode::from(exit::CASE_FAILED),
            Err(e) => Err(e),
        },
        Command::Check { target, baseline, alpha, threads } => {
            match commands.exec_check(&target, &baseline, alpha, threads) {
                Ok(true) => Ok(()),
                Ok(false) => return ExitCode::from(exit::REGRESSION),
                Err(e) => Err(e),
            }
        }
    };
    match result {
        Ok(()) => ExitCode::from(exit::OK),
        Err(CliError::Invalid(msg)) => {
            eprintln!("error: {msg}");
            ExitCode::from(exit::INVALID_INPUT)
        }
        Err(CliError::Internal(msg)) => {
            eprintln!("error: {msg}");
            ExitCode::from(exit::INTERNAL)
        }
    }
}
