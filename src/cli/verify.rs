//! `fdimc verify` (issue 86, item 2): known-answer cases run by this build on this machine, for an
//! analyst to attach to a safety case. Each case runs `fdimc run` (this executable, as a user runs it) on
//! a deck whose answer is known from outside fdimc's estimators (a closed form, or an exact law of
//! `fdimc::exact`, the module the tests use), and checks that the run's 95 % interval holds it; the
//! exact laws themselves are checked against the reference scripts' printed numbers. It writes
//! `verification.csv` and `verification.html` with the build's version and commit, the CPU and the
//! vector forms the lane path runs here.

use std::path::{Path, PathBuf};

use polars::prelude::{Column, DataFrame};

use super::CliError;
use crate::engine::results::tables::{Table, read_summary};
use crate::engine::scenario::deck::FromDeck;
use crate::exact::cusum::CusumWindow;
use crate::exact::false_alarms::two_sided;
use crate::exact::fewest_covered;
use crate::exact::slow_mode::slow_mode_window;
use crate::methods::detection_filter::kernel::Vectors;
use crate::methods::detection_filter::study::LtiStudy;
use crate::methods::detection_filter::trials::lane_path_against_one_trial;

/// A white N(0, 1) residual (closed form): `tests/data/white_residual.toml`.
const WHITE_RESIDUAL: &str = include_str!("../../tests/data/white_residual.toml");

/// The white-residual deck with a slow mode (`fdimc::exact::slow_mode`'s law): the plant a = -1 /s
/// with process noise 0.141067 per step (the state error's stationary sd 1), the filter's eigenvalue the
/// plant's own (gain 0), at `threshold`, with the fault-free share and the faults' `size_sigma` given.
pub fn slow_mode_deck(threshold: f64, fault_free_fraction: &str, size_sigma: &str) -> String {
    edited(&[
        ("a = [[-1000.0]]", "a = [[-1.0]]".to_string()),
        ("eigenvalues_per_s = [-1000.0]", "eigenvalues_per_s = [-1.0]".to_string()),
        ("sensor_sigma = [1.0]", "sensor_sigma = [1.0]\nprocess_sigma_per_step = [0.141067]".to_string()),
        ("thresholds = [3.5]", format!("thresholds = [{threshold:?}]")),
        ("fault_free_fraction = 0.5", format!("fault_free_fraction = {fault_free_fraction}")),
        ("size_sigma = 1.0", format!("size_sigma = {size_sigma}")),
    ])
}

/// The white-residual deck with a CUSUM of drift 1 at `threshold`, a tenth of the trials fault-free
/// and a bias of `bias` sigma (`fdimc::exact::cusum`'s law).
pub fn cusum_deck(threshold: &str, bias: &str) -> String {
    edited(&[
        ("kind = \"detection_filter\"", "kind = \"cusum\"\ndrift = [1.0]".to_string()),
        ("thresholds = [3.5]", format!("thresholds = [{threshold}]")),
        ("fault_free_fraction = 0.5", "fault_free_fraction = 0.1".to_string()),
        ("size_sigma = 1.0", format!("size_sigma = {bias}")),
    ])
}

/// The exact law of the run cases' CUSUM (`cusum_deck("4.0", "1.0")` with its hazard window): drift 1,
/// threshold 4, a bias of 1 sigma, 100 samples before the onset and 20 to the hazard.
fn cusum_window() -> CusumWindow {
    CusumWindow { drift: 1.0, threshold: 4.0, bias: 1.0, before: 100, window: 20 }
}

/// The white-residual deck with each `(from, to)` replaced; every `from` must be there.
fn edited(edits: &[(&str, String)]) -> String {
    edits.iter().fold(WHITE_RESIDUAL.to_string(), |text, (from, to)| {
        assert!(text.contains(from), "the white-residual deck lost {from:?}");
        text.replace(from, to)
    })
}

/// The time to hazard the miss cases give their bias faults: the onset's sample and the 19 after it.
const HAZARD: &str = "\n[monte_carlo.time_to_hazard_s]\nbias = 0.195\n";

/// How a case passes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Rule {
    /// The measured value's interval holds the expected value.
    Holds,
    /// The measured value is at least the expected one (a count of seeds covered).
    AtLeast,
}

impl Rule {
    fn name(self) -> &'static str {
        match self {
            Rule::Holds => "the interval holds the expected value",
            Rule::AtLeast => "measured at least the expected",
        }
    }
}

/// One known-answer case and what this build measured.
#[derive(Debug, Clone)]
pub struct Case {
    pub name: &'static str,
    pub checks: String,
    pub expected_from: String,
    pub expected: f64,
    pub measured: f64,
    /// The measured value's 95 % interval (for a computation, its tolerance about the expected; for a
    /// count, the count).
    pub lo: f64,
    pub hi: f64,
    pub rule: Rule,
}

impl Case {
    pub fn pass(&self) -> bool {
        match self.rule {
            Rule::Holds => self.lo <= self.expected && self.expected <= self.hi,
            Rule::AtLeast => self.measured >= self.expected,
        }
    }
}

/// What `fdimc verify` runs beyond the quick form's cases.
#[derive(Debug, Clone)]
pub struct VerifyOptions {
    /// Seeds each run case is repeated over for its intervals' coverage (0: once, at the deck's seed).
    pub seeds: u64,
    /// The second implementation's trials on the CI deck.
    pub second_trials: u64,
    /// The second implementation on the robustness deck too (parameter errors, the CUSUM and Kalman
    /// chi-square baselines), at 3,000 trials.
    pub second_with_parameter_errors: bool,
    /// Python with NumPy, SciPy and polars for the second implementation.
    pub python: PathBuf,
}

/// The fewest seeds a coverage count is made over: below it [`fewest_covered`] allows nearly anything.
pub const FEWEST_SEEDS: u64 = 8;

/// The figure `column` (with `_lo`, `_hi`) at the deck's thresholds of the run in `dir`.
fn at_deck_thresholds(dir: &Path, column: &str) -> Result<[f64; 3], CliError> {
    let path = dir.join("detectors.csv");
    let df = read_summary(&path).map_err(|e| CliError::Internal(format!("{}: {e}", path.display())))?;
    let t = Table(&df);
    let row = (t.strs("thresholds").iter().position(|s| s == "deck"))
        .ok_or_else(|| CliError::Internal(format!("{}: no row at the deck's thresholds", path.display())))?;
    Ok([column.to_string(), format!("{column}_lo"), format!("{column}_hi")].map(|c| t.f64s(&c)[row]))
}

/// Runs this executable with `args`, as a user would.
fn fdimc(args: &[&str]) -> Result<(), CliError> {
    let exe = std::env::current_exe().map_err(|e| CliError::Internal(format!("this executable: {e}")))?;
    // Its answer is in the files read back; what it prints would bury verify's own lines.
    let status = (std::process::Command::new(exe).args(args).stdout(std::process::Stdio::null()).status())
        .map_err(|e| CliError::Internal(format!("fdimc {}: {e}", args.join(" "))))?;
    if !status.success() {
        return Err(CliError::Internal(format!("fdimc {} failed ({status})", args.join(" "))));
    }
    Ok(())
}

/// Writes `deck_text` to `out/decks/NAME.toml` and runs it with `extra` options into `out/runs/RUN`.
fn run_deck(out: &Path, name: &str, deck_text: &str, run: &str, extra: &[&str]) -> Result<PathBuf, CliError> {
    let io = |e: std::io::Error| CliError::Internal(format!("{}: {e}", out.display()));
    let decks = out.join("decks");
    std::fs::create_dir_all(&decks).map_err(io)?;
    let deck = decks.join(format!("{name}.toml"));
    std::fs::write(&deck, deck_text).map_err(io)?;
    let dir = out.join("runs").join(run);
    let (deck_s, dir_s) = (deck.to_string_lossy(), dir.to_string_lossy());
    fdimc(&[&["run", &deck_s, "--quiet", "--force", "--out", &dir_s][..], extra].concat())?;
    Ok(dir)
}

/// A run's records (`trials.parquet`).
fn records(dir: &Path) -> Result<DataFrame, CliError> {
    let path = dir.join("trials.parquet");
    read_summary(&path).map_err(|e| CliError::Internal(format!("{}: {e}", path.display())))
}

/// The white residual's records of `every_core` (its run on every core) against its runs on one thread
/// and in two shards merged: 1 when all three are identical, else 0.
fn records_identical(out: &Path, every_core: &Path) -> Result<f64, CliError> {
    let one = run_deck(out, "white_residual", WHITE_RESIDUAL, "threads_1", &["--threads", "1"])?;
    let first_half = run_deck(out, "white_residual", WHITE_RESIDUAL, "shard_0_of_2", &["--shard", "0/2"])?;
    let second_half = run_deck(out, "white_residual", WHITE_RESIDUAL, "shard_1_of_2", &["--shard", "1/2"])?;
    let merged = out.join("runs").join("merged");
    let parts = [first_half, second_half].map(|p| p.to_string_lossy().to_string());
    fdimc(&["merge", &parts[0], &parts[1], "--force", "--out", &merged.to_string_lossy()])?;
    let first = records(&one)?;
    let same = first.equals_missing(&records(every_core)?) && first.equals_missing(&records(&merged)?);
    Ok(if same { 1.0 } else { 0.0 })
}

/// The bundled decks the lane path is checked on: a fixed design, the bench's and one with per-trial
/// designs (model errors), with their trials drawn as in a run.
const LANE_DECKS: [(&str, &str); 3] = [
    ("studies/ci_seed000.toml", include_str!("../../studies/ci_seed000.toml")),
    ("studies/bench_seed000.toml", include_str!("../../studies/bench_seed000.toml")),
    ("studies/seed000_robustness.toml", include_str!("../../studies/seed000_robustness.toml")),
];

/// The lane path against the one-trial path: 40 trials of each of [`LANE_DECKS`] in every vector form
/// this CPU runs; the outcomes compared and the first difference (`None`: none).
fn lane_paths() -> Result<(u64, Option<String>), CliError> {
    let mut compared = 0;
    for (path, text) in LANE_DECKS {
        let study = LtiStudy::from_toml(text, Path::new(path)).map_err(|e| CliError::Internal(e.to_string()))?;
        for &form in Vectors::available() {
            let (n, differs) = lane_path_against_one_trial(&study, 40, form);
            compared += n;
            if let Some(d) = differs {
                return Ok((compared, Some(format!("{path}, {form:?}: {d}"))));
            }
        }
    }
    Ok((compared, None))
}

/// A case that runs `fdimc run` on a deck whose answer is known.
struct RunCase {
    name: &'static str,
    /// Its coverage over seeds' name.
    coverage: &'static str,
    checks: &'static str,
    expected_from: &'static str,
    deck: String,
    /// `detectors.csv`'s figure at the deck's thresholds.
    column: &'static str,
    expected: f64,
}

/// The run cases: the white residual's Pfa, the miss before the hazard of a slow mode and of a CUSUM.
fn run_cases() -> [RunCase; 3] {
    // A white N(0, 1) residual at threshold 3.5: half the flights fault-free over 200 samples, the
    // faulty half over the 100 before the onset.
    let sample = two_sided(3.5);
    let pfa = 0.5 * -(200.0 * (-sample).ln_1p()).exp_m1() + 0.5 * -(100.0 * (-sample).ln_1p()).exp_m1();
    [
        RunCase {
            name: "white_residual_pfa",
            coverage: "white_residual_pfa_coverage",
            checks: "detectors.csv's Pfa at the deck's threshold, 4,000 trials of a white N(0, 1) residual",
            expected_from: "closed form: 0.5 (1 - (1 - 2 Q(3.5))^200) + 0.5 (1 - (1 - 2 Q(3.5))^100)",
            deck: WHITE_RESIDUAL.to_string(),
            column: "pfa",
            expected: pfa,
        },
        RunCase {
            name: "slow_mode_miss_before_hazard",
            coverage: "slow_mode_miss_before_hazard_coverage",
            checks: "detectors.csv's miss before the hazard where the residual has a 1 s mode (b = 2, 20 samples)",
            expected_from: "exact law (fdimc::exact::slow_mode, the state error's density on a grid)",
            deck: slow_mode_deck(4.0, "0.1", "2.0") + HAZARD,
            column: "p_miss_before_hazard",
            expected: slow_mode_window().miss(2.0, 401),
        },
        RunCase {
            name: "cusum_miss_before_hazard",
            coverage: "cusum_miss_before_hazard_coverage",
            checks: "detectors.csv's miss before the hazard of a CUSUM (drift 1, threshold 4, b = 1, 20 samples)",
            expected_from: "exact law (fdimc::exact::cusum, Brook and Evans' chain)",
            deck: cusum_deck("4.0", "1.0") + HAZARD,
            column: "p_miss_before_hazard",
            expected: cusum_window().miss(0.04, 30.0),
        },
    ]
}

/// The white residual at 10,000 trials (three part files) run through, and stopped after its first part
/// file then resumed (`--stop-after 1`, then `--resume`): 1 when the records are identical, else 0 (and
/// 0 when the stopped run had not stopped: the resume would check nothing).
fn records_identical_after_resume(out: &Path) -> Result<f64, CliError> {
    let trials = ["--trials", "10000"];
    let through = run_deck(out, "white_residual", WHITE_RESIDUAL, "through_10000", &trials)?;
    let stopped = run_deck(
        out,
        "white_residual",
        WHITE_RESIDUAL,
        "resumed_10000",
        &[&trials[..], &["--stop-after", "1"]].concat(),
    )?;
    let before = stopped.join("trials.parquet").exists().then(|| records(&stopped)).transpose()?;
    if before.is_some_and(|r| r.height() >= 10_000) {
        return Ok(0.0);
    }
    let (deck, dir) = (out.join("decks").join("white_residual.toml"), stopped.to_string_lossy().to_string());
    fdimc(&[&["run", &deck.to_string_lossy(), "--quiet", "--resume", "--out", &dir][..], &trials].concat())?;
    Ok(if records(&through)?.equals_missing(&records(&stopped)?) { 1.0 } else { 0.0 })
}

/// The quick form's cases, each run here.
fn quick_cases(out: &Path) -> Result<Vec<Case>, CliError> {
    let mut cases = Vec::new();
    // The exact laws against the reference scripts' numbers (computed here, on this machine).
    let grid = slow_mode_window().miss(2.0, 801);
    cases.push(Case {
        name: "exact_slow_mode_law",
        checks: "the slow-mode residual's miss (b = 2, threshold 4, 20 samples) on this machine".into(),
        expected_from: "scripts/reference/slow_mode_miss_numpy.py (NumPy, SciPy): 0.531727682059".into(),
        expected: 0.531727682059,
        measured: grid,
        lo: grid - 1e-10,
        hi: grid + 1e-10,
        rule: Rule::Holds,
    });
    // The script's range (h + 8), extrapolated from bins of 0.01 and 0.02.
    let (scripts_range, _) = cusum_window().extrapolated(0.01, 8.0);
    cases.push(Case {
        name: "exact_cusum_chain",
        checks: "Brook and Evans' chain of a CUSUM (drift 1, threshold 4, b = 1, 100 + 20 samples) on this machine"
            .into(),
        expected_from: "scripts/reference/cusum_miss_numpy.py (NumPy, another binning): 0.3107492003".into(),
        expected: 0.3107492003,
        measured: scripts_range,
        lo: scripts_range - 2e-9,
        hi: scripts_range + 2e-9,
        rule: Rule::Holds,
    });
    let runs = run_cases();
    for r in &runs {
        let dir = run_deck(out, r.name, &r.deck, r.name, &[])?;
        let [measured, lo, hi] = at_deck_thresholds(&dir, r.column)?;
        cases.push(Case {
            name: r.name,
            checks: r.checks.into(),
            expected_from: r.expected_from.into(),
            expected: r.expected,
            measured,
            lo,
            hi,
            rule: Rule::Holds,
        });
    }
    let white = out.join("runs").join(runs[0].name);
    let identical = records_identical(out, &white)?;
    cases.push(Case {
        name: "records_identical_across_threads_and_shards",
        checks:
            "the white residual's trials.parquet on every core, on 1 thread, and in 2 shards merged: 1 when identical"
                .into(),
        expected_from: "fdimc's rule: the same deck and seed give the same records for any thread count or shard"
            .into(),
        expected: 1.0,
        measured: identical,
        lo: identical,
        hi: identical,
        rule: Rule::Holds,
    });
    let resumed = records_identical_after_resume(out)?;
    cases.push(Case {
        name: "records_identical_after_a_resume",
        checks: "the white residual's trials.parquet at 10,000 trials (three part files) run through, and stopped \
                 after its first part file (--stop-after 1) then resumed (--resume): 1 when identical"
            .into(),
        expected_from: "fdimc's rule: the same deck and seed give the same records after any resume".into(),
        expected: 1.0,
        measured: resumed,
        lo: resumed,
        hi: resumed,
        rule: Rule::Holds,
    });
    let (compared, differs) = lane_paths()?;
    let (forms, differing) = (Vectors::available(), if differs.is_some() { 1.0 } else { 0.0 });
    cases.push(Case {
        name: "lane_path_equals_one_trial_path",
        checks: match &differs {
            None => format!(
                "the outcomes of 40 trials of {} in the vector forms {forms:?}, each trial's run on the lane path \
                 against its run alone ({compared} compared): the number that differ",
                LANE_DECKS.map(|d| d.0).join(", ")
            ),
            Some(d) => format!("the lane path against the one-trial path: they differ at {d}"),
        },
        expected_from: "fdimc's rule: the lane path is only a faster way to the one-trial path's records".into(),
        expected: 0.0,
        measured: differing,
        lo: differing,
        hi: differing,
        rule: Rule::Holds,
    });
    Ok(cases)
}

/// Each run case over seeds `1..=seeds`: how many of their 95 % intervals hold the expected value, at
/// least [`fewest_covered`] to pass.
fn coverage_cases(out: &Path, seeds: u64) -> Result<Vec<Case>, CliError> {
    let fewest = fewest_covered(seeds);
    let mut cases = Vec::new();
    for r in run_cases() {
        let mut covered = 0;
        for seed in 1..=seeds {
            let seed = seed.to_string();
            let dir = run_deck(out, r.name, &r.deck, &format!("{}_seed{seed}", r.name), &["--seed", &seed])?;
            let [_, lo, hi] = at_deck_thresholds(&dir, r.column)?;
            covered += (lo <= r.expected && r.expected <= hi) as u64;
        }
        cases.push(Case {
            name: r.coverage,
            checks: format!(
                "{} over seeds 1 to {seeds}: the seeds whose 95 % interval holds {:.6e}",
                r.name, r.expected
            ),
            expected_from: format!(
                "{}; of {seeds} seeds at least {fewest} (95 % intervals cover fewer with probability under \
                 0.005: fdimc::exact::fewest_covered)",
                r.expected_from
            ),
            expected: fewest as f64,
            measured: covered as f64,
            lo: covered as f64,
            hi: covered as f64,
            rule: Rule::AtLeast,
        });
    }
    Ok(cases)
}

/// The second implementation's scripts (`scripts/reference/`), carried by the binary so that verify
/// runs them where fdimc runs.
const SECOND_IMPLEMENTATION: &str = include_str!("../../scripts/reference/second_implementation.py");
const COMPARE_SECOND_IMPLEMENTATION: &str = include_str!("../../scripts/reference/compare_second_implementation.py");
/// A deck the second implementation is compared on: its case's name, the deck (path, text), and the
/// tests the comparison makes on it at 3,000 trials and more (fewer means it compared less).
struct SecondDeck {
    case: &'static str,
    deck: (&'static str, &'static str),
    /// Its table of tests in verify's folder.
    table: &'static str,
    min_tests: u64,
}

/// The CI deck: the detection filter and its fault kinds.
const SECOND_CI: SecondDeck = SecondDeck {
    case: "second_implementation_agrees",
    deck: LANE_DECKS[0],
    table: "second_implementation.csv",
    min_tests: 44,
};
/// The robustness deck: parameter errors, the CUSUM and the Kalman chi-square baselines (`--full`).
const SECOND_ROBUSTNESS: SecondDeck = SecondDeck {
    case: "second_implementation_agrees_under_parameter_errors",
    deck: LANE_DECKS[2],
    table: "second_implementation_seed000_robustness.csv",
    min_tests: 552,
};

/// Whether `python` has NumPy, SciPy and polars, which the second implementation needs.
fn has_second_implementation(python: &Path) -> bool {
    std::process::Command::new(python)
        .args(["-c", "import numpy, scipy, polars, tomllib"])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

/// The second implementation (NumPy, SciPy) of `second`'s deck against this build's run of it, with
/// `python` (which has what it needs: [`has_second_implementation`]).
fn second_implementation(out: &Path, python: &Path, second: &SecondDeck, trials: u64) -> Result<Case, CliError> {
    let io = |e: std::io::Error| CliError::Internal(format!("{}: {e}", out.display()));
    let scripts = out.join("reference");
    std::fs::create_dir_all(&scripts).map_err(io)?;
    std::fs::write(scripts.join("second_implementation.py"), SECOND_IMPLEMENTATION).map_err(io)?;
    let compare = scripts.join("compare_second_implementation.py");
    std::fs::write(&compare, COMPARE_SECOND_IMPLEMENTATION).map_err(io)?;
    let decks = out.join("decks");
    std::fs::create_dir_all(&decks).map_err(io)?;
    let (deck_path, deck_text) = second.deck;
    let stem = Path::new(deck_path).file_stem().and_then(|s| s.to_str()).unwrap_or("deck");
    let deck = decks.join(format!("{stem}.toml"));
    std::fs::write(&deck, deck_text).map_err(io)?;
    let table = out.join(second.table);
    let exe = std::env::current_exe().map_err(|e| CliError::Internal(format!("this executable: {e}")))?;
    let done = std::process::Command::new(python)
        .arg(&compare)
        .arg(&deck)
        .args(["--trials", &trials.to_string(), "--min-tests", &second.min_tests.to_string()])
        .arg("--fdimc")
        .arg(&exe)
        .arg("--out")
        .arg(&table)
        .output()
        .map_err(|e| CliError::Internal(format!("{}: {e}", python.display())))?;
    // 0: all agree, 1: some rejected (read from the table); anything else did not compare.
    if !matches!(done.status.code(), Some(0 | 1)) {
        return Err(CliError::Internal(format!(
            "the second implementation did not compare ({}):\n{}",
            done.status,
            String::from_utf8_lossy(&done.stderr)
        )));
    }
    let df = read_summary(&table).map_err(|e| CliError::Internal(format!("{}: {e}", table.display())))?;
    let verdicts = Table(&df).strs("verdict");
    let tested = verdicts.iter().filter(|v| *v == "agree" || *v == "REJECT").count();
    let rejected = verdicts.iter().filter(|v| *v == "REJECT").count() as f64;
    Ok(Case {
        name: second.case,
        checks: format!(
            "{deck_path} at {trials} trials, fdimc against a NumPy/SciPy simulation written from the deck and \
             the docs alone: {tested} tests of the Pfa, Pd and delays per fault kind, output and size and the \
             fault-free statistic's law (Fisher, Mann-Whitney, KS; Holm at family-wise 0.01), the number \
             rejected ({})",
            second.table
        ),
        expected_from: "scripts/reference/second_implementation.py (its own draws, fault injection and alarm rule)"
            .into(),
        expected: 0.0,
        measured: rejected,
        lo: rejected,
        hi: rejected,
        rule: Rule::Holds,
    })
}

/// Where and what ran: fdimc's version and commit, the CPU, the vector forms the lane path uses here.
fn build_and_machine() -> Vec<(&'static str, String)> {
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|t| {
            t.lines()
                .find(|l| l.starts_with("model name"))
                .map(|l| l.split(':').nth(1).unwrap_or("").trim().to_string())
        })
        .unwrap_or_else(|| std::env::consts::ARCH.to_string());
    let forms = match Vectors::detect() {
        Vectors::Avx512 => "AVX-512 (and AVX2, scalar)",
        Vectors::Avx2 => "AVX2 (and scalar; no AVX-512 here)",
        Vectors::Scalar => "scalar only",
    };
    vec![
        ("fdimc", env!("CARGO_PKG_VERSION").to_string()),
        ("commit", env!("FDIMC_COMMIT").to_string()),
        ("cpu", cpu),
        ("cores", std::thread::available_parallelism().map_or(1, |n| n.get()).to_string()),
        ("lane path's vector form", forms.to_string()),
    ]
}

/// `fdimc verify --out DIR`: the cases, `verification.csv` and `verification.html`; whether all passed.
pub fn exec_verify(out: &Path, options: &VerifyOptions) -> Result<bool, CliError> {
    if options.seeds != 0 && options.seeds < FEWEST_SEEDS {
        return Err(CliError::Invalid(format!(
            "--seeds {}: at least {FEWEST_SEEDS} (fewer say nothing of a 95 % interval's coverage)",
            options.seeds
        )));
    }
    std::fs::create_dir_all(out).map_err(|e| CliError::Invalid(format!("--out {}: {e}", out.display())))?;
    let mut cases = quick_cases(out)?;
    if options.seeds > 0 {
        cases.extend(coverage_cases(out, options.seeds)?);
    }
    let mut about = build_and_machine();
    if has_second_implementation(&options.python) {
        cases.push(second_implementation(out, &options.python, &SECOND_CI, options.second_trials)?);
        if options.second_with_parameter_errors {
            cases.push(second_implementation(out, &options.python, &SECOND_ROBUSTNESS, 3_000)?);
        }
    } else {
        about.push((
            "second implementation",
            format!(
                "not run: {} lacks NumPy, SciPy or polars (give one that has them with --python)",
                options.python.display()
            ),
        ));
    }
    let mut df = DataFrame::new_infer_height(vec![
        Column::new("case".into(), cases.iter().map(|c| c.name).collect::<Vec<_>>()),
        Column::new("checks".into(), cases.iter().map(|c| c.checks.clone()).collect::<Vec<_>>()),
        Column::new("expected_from".into(), cases.iter().map(|c| c.expected_from.clone()).collect::<Vec<_>>()),
        Column::new("expected".into(), cases.iter().map(|c| c.expected).collect::<Vec<_>>()),
        Column::new("measured".into(), cases.iter().map(|c| c.measured).collect::<Vec<_>>()),
        Column::new("measured_lo".into(), cases.iter().map(|c| c.lo).collect::<Vec<_>>()),
        Column::new("measured_hi".into(), cases.iter().map(|c| c.hi).collect::<Vec<_>>()),
        Column::new("rule".into(), cases.iter().map(|c| c.rule.name()).collect::<Vec<_>>()),
        Column::new("pass".into(), cases.iter().map(Case::pass).collect::<Vec<_>>()),
        Column::new("fdimc".into(), vec![about[0].1.clone(); cases.len()]),
        Column::new("commit".into(), vec![about[1].1.clone(); cases.len()]),
        Column::new("cpu".into(), vec![about[2].1.clone(); cases.len()]),
        Column::new("vector_form".into(), vec![about[4].1.clone(); cases.len()]),
    ])
    .map_err(|e| CliError::Internal(e.to_string()))?;
    crate::engine::run::output::write_table(&mut df, &out.join("verification.csv"))?;
    let page = page(&cases, &about);
    crate::engine::run::runner::write_atomically(&out.join("verification.html"), page.as_bytes())
        .map_err(|e| CliError::Internal(e.to_string()))?;
    let failed = cases.iter().filter(|c| !c.pass()).count();
    for c in &cases {
        let verdict = if c.pass() { "pass" } else { "FAIL" };
        match c.rule {
            Rule::Holds => println!(
                "{verdict} {:<38} expected {:.6e}, measured {:.6e} [{:.6e}, {:.6e}]",
                c.name, c.expected, c.measured, c.lo, c.hi
            ),
            Rule::AtLeast => {
                println!("{verdict} {:<38} at least {} expected, measured {}", c.name, c.expected, c.measured)
            }
        }
    }
    if let Some((_, note)) = about.iter().find(|(k, _)| *k == "second implementation") {
        println!("the second implementation was {note}");
    }
    println!(
        "{} of {} cases passed on {} ({}); verification.csv and verification.html in {}",
        cases.len() - failed,
        cases.len(),
        about[2].1,
        about[4].1,
        out.display()
    );
    Ok(failed == 0)
}

/// The page: what ran where, then each case.
fn page(cases: &[Case], about: &[(&str, String)]) -> String {
    let escape = |s: &str| s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;");
    let mut html = String::from(
        "<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>fdimc verify</title>\n<style>body{font-family:sans-serif;max-width:70em;margin:2em auto}td,th{border:1px solid #ccc;padding:.3em;text-align:left}table{border-collapse:collapse}.fail{color:#b00;font-weight:bold}</style></head><body>\n<h1>fdimc verify: known-answer cases</h1>\n<p>Each case runs this build of fdimc on a deck whose answer comes from outside its estimators, and passes when the run's 95 % interval holds that answer (a computation: when it meets the reference to the tolerance shown; a count over seeds: when at least as many intervals hold it as 95 % ones would but for a chance under 0.005). It shows that this build, on this machine, gives these figures; it does not show that a user's model, deck or noise is right, nor anything of the kinds these cases do not run.</p>\n<table>\n",
    );
    for (k, v) in about {
        html.push_str(&format!("<tr><th>{}</th><td>{}</td></tr>\n", escape(k), escape(v)));
    }
    html.push_str("</table>\n<h2>Cases</h2>\n<table><tr><th>case</th><th>checks</th><th>expected, from</th><th>expected</th><th>measured [95 %]</th><th>result</th></tr>\n");
    for c in cases {
        let result = if c.pass() { "pass".to_string() } else { "<span class=\"fail\">FAIL</span>".to_string() };
        let (expected, measured) = match c.rule {
            Rule::Holds => (format!("{:.6e}", c.expected), format!("{:.6e} [{:.6e}, {:.6e}]", c.measured, c.lo, c.hi)),
            Rule::AtLeast => (format!("at least {}", c.expected), format!("{}", c.measured)),
        };
        html.push_str(&format!(
            "<tr><td>{}</td><td>{}</td><td>{}</td><td>{expected}</td><td>{measured}</td><td>{result}</td></tr>\n",
            c.name,
            escape(&c.checks),
            escape(&c.expected_from),
        ));
    }
    html.push_str("</table>\n</body></html>\n");
    html
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A case passes exactly when its interval holds the expected value, and the page says FAIL for one
    /// that does not.
    #[test]
    fn a_case_fails_when_its_interval_misses_the_answer() {
        let case = |lo: f64, hi: f64| Case {
            name: "c",
            checks: "x".into(),
            expected_from: "y".into(),
            expected: 0.5,
            measured: 0.45,
            lo,
            hi,
            rule: Rule::Holds,
        };
        assert!(case(0.4, 0.5).pass() && case(0.5, 0.6).pass());
        assert!(!case(0.4, 0.49).pass() && !case(0.51, 0.6).pass());
        // A coverage count passes at or above the fewest allowed.
        let count = |measured: f64| Case { measured, expected: 16.0, rule: Rule::AtLeast, ..case(0.0, 0.0) };
        assert!(count(16.0).pass() && count(20.0).pass() && !count(15.0).pass());
        let page = page(&[case(0.4, 0.49)], &[("commit", "abc".into())]);
        assert!(page.contains("FAIL") && page.contains("<td>abc</td>"), "{page}");
    }
}
