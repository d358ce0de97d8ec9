//! `run --fmu-processes`: each worker thread's trials flown in a child process of its own (the hidden
//! `fdimc fmu-worker`), so that an FMU whose own code crashes the process (an abort, a segmentation
//! fault) fails only the trial it was flying. That trial is recorded as failed with how the process
//! died, a fresh child flies the rest, and the run goes on. A trial is a function of the deck, the
//! seed and its index, so a child computes what the thread would have: the records are the same.
//!
//! One line each way per request: the parent writes `first end`; the child answers one line per trial
//! as it finishes it (so a crash loses only the trial in flight): per detector `O` and its outcome, or
//! `E` and its failure message (hex UTF-8); every f64 as its bit pattern, so nothing is rounded.

use std::cell::RefCell;
use std::fmt::Write as _;
use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, ChildStdout, Command, Stdio};

use super::study::LtiStudy;
use super::trial::DetectorOutcome;
use super::trials::{Engine, TrialFailure, TrialResult};
use crate::engine::method::Study;
use crate::engine::run::runner::RunError;
use crate::engine::scenario::deck::FromDeck;

/// What a child needs to build the parent's study: the deck, and the run's seed and trial count. A
/// child rebuilds the study from the deck file: a study changed in code after loading (a library
/// caller's) is not what it flies.
#[derive(Debug, Clone, PartialEq)]
pub struct WorkerSpec {
    pub executable: PathBuf,
    pub deck: PathBuf,
    pub seed: u64,
    pub trials: u64,
    /// The profile grid's step (`run --profile-resolution` may change the deck's).
    pub profile_resolution: f64,
    /// SHA-256 of the deck file as the run read it; a child that reads another refuses to fly.
    pub deck_sha256: String,
    /// `fdimc sensitivity`: the design's base samples and bootstrap resamples, which the child's study
    /// takes too (its trials are the design's).
    pub design: Option<(u64, u64)>,
}

impl WorkerSpec {
    /// The spec of a run of `deck` (its SHA-256 read now).
    pub fn new(
        executable: PathBuf,
        deck: &Path,
        seed: u64,
        trials: u64,
        profile_resolution: f64,
        design: Option<(u64, u64)>,
    ) -> Result<Self, RunError> {
        let deck_sha256 = deck_sha256(deck)?;
        Ok(WorkerSpec { executable, deck: deck.to_path_buf(), seed, trials, profile_resolution, deck_sha256, design })
    }
}

fn deck_sha256(deck: &Path) -> Result<String, RunError> {
    use sha2::{Digest, Sha256};
    let bytes = std::fs::read(deck).map_err(|e| RunError::Invalid(format!("{}: {e}", deck.display())))?;
    Ok(Sha256::digest(&bytes).iter().map(|b| format!("{b:02x}")).collect())
}

struct Worker {
    spec: WorkerSpec,
    child: Child,
    stdin: ChildStdin,
    stdout: BufReader<ChildStdout>,
    /// The child's temporary folder (its `TMPDIR`), where it unpacks its FMUs: removed by the parent
    /// after the child is gone, since a child that is killed or crashes cannot remove it.
    _temporary: tempfile::TempDir,
}

impl Drop for Worker {
    /// A worker holds nothing unsaved: it is stopped and reaped (no zombie stays behind), then its
    /// temporary folder goes (the field's own drop, after this).
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// This thread's child for the study it was started for, or why no child can fly that study (then
/// every trial fails with it at once, instead of a process start per trial).
enum Slot {
    Empty,
    Running(Worker),
    Broken(WorkerSpec, String),
}

thread_local! {
    static WORKER: RefCell<Slot> = const { RefCell::new(Slot::Empty) };
}

/// What a child says once it has built its study, for the parent to check it flies the same one.
fn fingerprint(detectors: usize, seed: u64, trials: u64, deck_sha256: &str) -> String {
    format!("READY {detectors} {seed} {trials} {deck_sha256}")
}

impl WorkerSpec {
    /// Trials `first..end` flown by this thread's child; a trial whose child dies is failed with why.
    pub fn run_group(&self, engine: &Engine, first: u64, end: u64) -> Vec<TrialResult> {
        let mut out = Vec::with_capacity((end - first) as usize);
        while first + (out.len() as u64) < end {
            let next = first + out.len() as u64;
            if let Err(why) = self.fly(engine, next, end, &mut out) {
                let t = first + out.len() as u64;
                let failure = TrialFailure::Reported(why);
                out.push(TrialResult { spec: engine.spec(t), detectors: vec![Err(failure); engine.detectors()] });
            }
        }
        out
    }

    /// Asks the child for `next..end` and appends what it answers; `Err`: the child died (or could
    /// not start) before answering trial `next + answered`, and why.
    fn fly(&self, engine: &Engine, next: u64, end: u64, out: &mut Vec<TrialResult>) -> Result<(), String> {
        WORKER.with(|w| {
            let mut w = w.borrow_mut();
            match &*w {
                Slot::Running(worker) if worker.spec == *self => {}
                Slot::Broken(spec, why) if spec == self => return Err(why.clone()),
                _ => {
                    *w = Slot::Empty; // a child of another study is stopped
                    *w = match self.spawn(engine.detectors()) {
                        Ok(worker) => Slot::Running(worker),
                        Err(why) => {
                            let why = format!("no worker process can fly this study: {why}");
                            Slot::Broken(self.clone(), why.clone())
                        }
                    };
                    if let Slot::Broken(_, why) = &*w {
                        return Err(why.clone());
                    }
                }
            }
            let Slot::Running(worker) = &mut *w else { unreachable!("running above") };
            let asked = writeln!(worker.stdin, "{next} {end}").and_then(|()| worker.stdin.flush());
            for t in next..end {
                let mut line = Vec::new();
                let read = match asked {
                    Ok(()) => worker.stdout.read_until(b'\n', &mut line).map_err(|e| e.to_string()),
                    Err(ref e) => Err(e.to_string()),
                };
                // Only a whole line is an answer: a child that died mid-write left a truncated one.
                let answer = match read {
                    Ok(_) if line.ends_with(b"\n") => std::str::from_utf8(&line)
                        .ok()
                        .and_then(|l| decode_trial(l, engine.detectors()))
                        .ok_or_else(|| format!("the worker process answered trial {t} unreadably")),
                    Ok(_) | Err(_) => Err(died(worker, t)),
                };
                match answer {
                    Ok(detectors) => out.push(TrialResult { spec: engine.spec(t), detectors }),
                    Err(why) => {
                        *w = Slot::Empty; // stopped and reaped
                        return Err(why);
                    }
                }
            }
            Ok(())
        })
    }

    /// A started child that has built the study and said so with the parent's [`fingerprint`].
    fn spawn(&self, detectors: usize) -> Result<Worker, String> {
        let temporary = tempfile::Builder::new()
            .prefix("fdimc-worker")
            .tempdir()
            .map_err(|e| format!("cannot make a temporary folder for a worker process: {e}"))?;
        let mut command = Command::new(&self.executable);
        command
            .env("TMPDIR", temporary.path())
            .arg("fmu-worker")
            .arg(&self.deck)
            .args(["--seed", &self.seed.to_string(), "--trials", &self.trials.to_string()])
            .args(["--profile-resolution", &self.profile_resolution.to_string()])
            .args(self.design.iter().flat_map(|(base, bootstrap)| {
                [
                    "--design-base-samples".to_string(),
                    base.to_string(),
                    "--design-bootstrap".into(),
                    bootstrap.to_string(),
                ]
            }))
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit());
        #[cfg(unix)]
        {
            use std::os::unix::process::CommandExt;
            // A crashing FMU is expected here: no core file in the user's folder.
            // SAFETY: setrlimit is async-signal-safe and touches no memory of the parent.
            unsafe {
                command.pre_exec(|| {
                    let none = libc::rlimit { rlim_cur: 0, rlim_max: 0 };
                    libc::setrlimit(libc::RLIMIT_CORE, &none);
                    Ok(())
                });
            }
        }
        let mut child = command
            .spawn()
            .map_err(|e| format!("cannot start a worker process ({}): {e}", self.executable.display()))?;
        let stdin = child.stdin.take().expect("piped");
        let stdout = BufReader::new(child.stdout.take().expect("piped"));
        let mut worker = Worker { spec: self.clone(), child, stdin, stdout, _temporary: temporary };
        let mut ready = String::new();
        let _ = worker.stdout.read_line(&mut ready);
        let want = fingerprint(detectors, self.seed, self.trials, &self.deck_sha256);
        if ready.trim_end() != want {
            let status = match worker.child.try_wait() {
                Ok(Some(s)) => format!("it exited ({s}); its error is above"),
                _ => format!(
                    "it built another study ({:?}, not {want:?}): the deck changed since the run began?",
                    ready.trim_end()
                ),
            };
            return Err(format!("{}: {status}", self.deck.display()));
        }
        Ok(worker)
    }
}

/// How the child died while flying trial `t` (stopped first, should it still be alive).
fn died(worker: &mut Worker, t: u64) -> String {
    let _ = worker.child.kill();
    let status = worker.child.wait().map_or_else(|e| format!("status unknown: {e}"), |s| s.to_string());
    format!("the worker process died while flying trial {t} ({status}): an FMU crashed the process")
}

/// `fdimc fmu-worker DECK --seed S --trials N --profile-resolution R [--design-base-samples B
/// --design-bootstrap K]`: answers `first end` requests on stdin until it closes.
pub fn serve(
    deck: &Path,
    seed: u64,
    trials: u64,
    profile_resolution: f64,
    design: Option<(u64, u64)>,
) -> Result<(), RunError> {
    // First: whatever the FMUs print goes to a file of the worker's, not into the answers.
    let (mut stdout, mut printed) = protocol_channel()?;
    let mut study = LtiStudy::load(deck).map_err(|e| RunError::Invalid(e.to_string()))?;
    if let Some((base_samples, bootstrap)) = design {
        study.sensitivity_design(base_samples, bootstrap)?;
    }
    let (s, n) = study.seed_and_trials();
    (*s, *n) = (seed, trials);
    study.monte_carlo.common.profile = crate::engine::results::schema::ProfileGrid::new(profile_resolution);
    let engine = Engine::new(&study);
    printed.pass_on();
    writeln!(stdout, "{}", fingerprint(engine.detectors(), seed, trials, &deck_sha256(deck)?))
        .and_then(|()| stdout.flush())
        .map_err(|e| RunError::Internal(format!("fmu-worker: {e}")))?;
    let stdin = std::io::stdin();
    let io = |e: std::io::Error| RunError::Internal(format!("fmu-worker: {e}"));
    for request in stdin.lock().lines() {
        let request = request.map_err(io)?;
        let mut words = request.split_ascii_whitespace().map(str::parse::<u64>);
        let (Some(Ok(first)), Some(Ok(end)), None) = (words.next(), words.next(), words.next()) else {
            return Err(RunError::Internal(format!("fmu-worker: not a request: {request:?}")));
        };
        for t in first..end {
            let mut detectors = engine.run(t).detectors;
            printed.attach(&mut detectors);
            let line = encode_trial(&detectors);
            // One line per trial, flushed: what a crash loses is the trial in flight.
            stdout.write_all(line.as_bytes()).and_then(|()| stdout.flush()).map_err(io)?;
        }
    }
    Ok(())
}

/// What the FMUs print on the process's stdout (some exporters' runtimes print their errors there and
/// not through the FMI logger: OpenModelica's "division leads to inf or nan"), caught in a file per
/// trial: a trial an FMU failed gets its last lines in its failure; anything else goes on to stderr.
struct Printed {
    file: std::fs::File,
}

/// How much of what an FMU printed a failure keeps: its last lines, each at most this long.
const PRINTED_LINES: usize = 4;
const PRINTED_LINE_CHARS: usize = 400;

impl Printed {
    /// What was printed since the last call, the file emptied.
    fn take(&mut self) -> String {
        use std::io::{Read, Seek, SeekFrom};
        // SAFETY: fflush(NULL) flushes every C stdio stream; the FMU's buffered printf output lands
        // in the file before it is read.
        unsafe {
            libc::fflush(std::ptr::null_mut());
        }
        let mut text = String::new();
        let read = self.file.seek(SeekFrom::Start(0)).and_then(|_| {
            let mut bytes = Vec::new();
            self.file.read_to_end(&mut bytes)?;
            text = String::from_utf8_lossy(&bytes).into_owned();
            self.file.set_len(0)?;
            // stdout shares this file's offset: the next print starts at the beginning again.
            self.file.seek(SeekFrom::Start(0))
        });
        if let Err(e) = read {
            return format!("(what the FMU printed cannot be read: {e})");
        }
        text
    }

    /// Sends what was printed on to stderr (where a worker's other messages go).
    fn pass_on(&mut self) {
        let text = self.take();
        if !text.is_empty() {
            eprint!("{text}");
        }
    }

    /// A trial's FMU failures get the last lines the FMU printed during the trial; with none, what was
    /// printed goes on to stderr.
    fn attach(&mut self, detectors: &mut [Result<DetectorOutcome, TrialFailure>]) {
        let text = self.take();
        let failed = detectors.iter().any(|d| matches!(d, Err(TrialFailure::Fmu(_))));
        if !failed {
            if !text.is_empty() {
                eprint!("{text}");
            }
            return;
        }
        let lines: Vec<&str> = text.lines().map(str::trim).filter(|l| !l.is_empty()).collect();
        if lines.is_empty() {
            return;
        }
        let last: Vec<String> = lines[lines.len().saturating_sub(PRINTED_LINES)..]
            .iter()
            .map(|l| {
                if l.chars().count() > PRINTED_LINE_CHARS {
                    l.chars().take(PRINTED_LINE_CHARS).collect()
                } else {
                    l.to_string()
                }
            })
            .collect();
        for d in detectors.iter_mut() {
            if let Err(e @ TrialFailure::Fmu(_)) = d {
                let why = format!("{e}; the FMU printed: {}", last.join(" | "));
                *e = match e.diverged_at_s() {
                    Some(at_s) => TrialFailure::Diverged { at_s, why },
                    None => TrialFailure::Reported(why),
                };
            }
        }
    }
}

/// The pipe to the parent: the process's stdout as it started, with stdout itself then pointed at a
/// file of the worker's ([`Printed`]), so that what an FMU prints cannot mix with the answers.
fn protocol_channel() -> Result<(std::fs::File, Printed), RunError> {
    #[cfg(unix)]
    {
        use std::os::fd::{AsRawFd, FromRawFd};
        let internal = |e: String| RunError::Internal(format!("fmu-worker: {e}"));
        std::io::stdout().flush().map_err(|e| internal(e.to_string()))?;
        // In the worker's TMPDIR, which the parent removes.
        let file =
            tempfile::tempfile().map_err(|e| internal(format!("cannot make a file for what FMUs print: {e}")))?;
        // SAFETY: dup and dup2 on the standard descriptors, before any other thread exists; the
        // duplicate is owned by the File alone, and `file` outlives every print (it is held to the end).
        unsafe {
            let fd = libc::dup(1);
            if fd < 0 || libc::dup2(file.as_raw_fd(), 1) < 0 {
                return Err(internal("cannot set up its pipe".into()));
            }
            Ok((std::fs::File::from_raw_fd(fd), Printed { file }))
        }
    }
    #[cfg(not(unix))]
    {
        Err(RunError::Invalid("--fmu-processes: worker processes need a Unix system".into()))
    }
}

fn encode_trial(detectors: &[Result<DetectorOutcome, TrialFailure>]) -> String {
    let mut s = String::new();
    for d in detectors {
        match d {
            Ok(o) => {
                s.push_str("O ");
                encode_outcome(o, &mut s);
            }
            Err(e) => {
                match e.diverged_at_s() {
                    Some(at_s) => {
                        let _ = write!(s, "D {:x} ", at_s.to_bits());
                    }
                    None => s.push_str("E "),
                }
                let text = e.to_string();
                let hex: String = text.bytes().map(|b| format!("{b:02x}")).collect();
                s.push_str(if hex.is_empty() { "-" } else { &hex });
                s.push(' ');
            }
        }
    }
    s.push('\n');
    s
}

fn encode_outcome(o: &DetectorOutcome, s: &mut String) {
    let f = |s: &mut String, v: f64| {
        let _ = write!(s, "{:x} ", v.to_bits());
    };
    let vec = |s: &mut String, v: &[f64]| {
        let _ = write!(s, "{} ", v.len());
        v.iter().for_each(|&x| f(s, x));
    };
    let alarm = |s: &mut String, a: Option<(f64, usize)>| match a {
        Some((t, j)) => {
            f(s, t);
            let _ = write!(s, "{j} ");
        }
        None => s.push_str("- "),
    };
    let index = |s: &mut String, i: Option<usize>| match i {
        Some(j) => {
            let _ = write!(s, "{j} ");
        }
        None => s.push_str("- "),
    };
    vec(s, &o.pre_onset_max_abs_residual);
    let _ = write!(s, "{} ", o.profile_t_s.len());
    o.profile_t_s.iter().chain(&o.profile_value).for_each(|p| vec(s, p));
    alarm(s, o.false_alarm);
    alarm(s, o.detection);
    index(s, o.isolated_by_max);
    index(s, o.isolated_by_direction);
    match o.diverged_at_s {
        Some(t) => f(s, t),
        None => s.push_str("- "),
    }
}

/// The detectors' results of one trial line, or `None` if it is not one.
fn decode_trial(line: &str, detectors: usize) -> Option<Vec<Result<DetectorOutcome, TrialFailure>>> {
    let mut w = line.split_ascii_whitespace();
    let mut out = Vec::with_capacity(detectors);
    for _ in 0..detectors {
        match w.next()? {
            "O" => out.push(Ok(decode_outcome(&mut w)?)),
            kind @ ("E" | "D") => {
                let at_s = match kind {
                    "D" => Some(f64::from_bits(u64::from_str_radix(w.next()?, 16).ok()?)),
                    _ => None,
                };
                let hex = w.next()?;
                let bytes: Option<Vec<u8>> = if hex == "-" {
                    Some(Vec::new())
                } else {
                    (0..hex.len())
                        .step_by(2)
                        .map(|i| hex.get(i..i + 2).and_then(|b| u8::from_str_radix(b, 16).ok()))
                        .collect()
                };
                let why = String::from_utf8(bytes?).ok()?;
                out.push(Err(match at_s {
                    Some(at_s) => TrialFailure::Diverged { at_s, why },
                    None => TrialFailure::Reported(why),
                }));
            }
            _ => return None,
        }
    }
    w.next().is_none().then_some(out)
}

fn decode_outcome<'a>(w: &mut impl Iterator<Item = &'a str>) -> Option<DetectorOutcome> {
    let mut r = Tokens(w.peekable());
    let pre_onset_max_abs_residual = r.vec()?;
    let outputs = r.count()?;
    let profile_t_s = (0..outputs).map(|_| r.vec()).collect::<Option<Vec<_>>>()?;
    let profile_value = (0..outputs).map(|_| r.vec()).collect::<Option<Vec<_>>>()?;
    Some(DetectorOutcome {
        pre_onset_max_abs_residual,
        profile_t_s,
        profile_value,
        false_alarm: if r.none() { None } else { Some((r.f64()?, r.count()?)) },
        detection: if r.none() { None } else { Some((r.f64()?, r.count()?)) },
        isolated_by_max: if r.none() { None } else { Some(r.count()?) },
        isolated_by_direction: if r.none() { None } else { Some(r.count()?) },
        diverged_at_s: if r.none() { None } else { Some(r.f64()?) },
    })
}

/// The tokens of an outcome, read in [`encode_outcome`]'s order.
struct Tokens<I: Iterator>(std::iter::Peekable<I>);

impl<'a, I: Iterator<Item = &'a str>> Tokens<I> {
    fn f64(&mut self) -> Option<f64> {
        u64::from_str_radix(self.0.next()?, 16).ok().map(f64::from_bits)
    }

    fn count(&mut self) -> Option<usize> {
        self.0.next()?.parse().ok()
    }

    fn vec(&mut self) -> Option<Vec<f64>> {
        let n = self.count()?;
        (0..n).map(|_| self.f64()).collect()
    }

    /// Takes a `-` (nothing) if it is next.
    fn none(&mut self) -> bool {
        self.0.next_if_eq(&"-").is_some()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_outcome_and_a_failure_cross_the_pipe_unchanged() {
        let outcome = DetectorOutcome {
            pre_onset_max_abs_residual: vec![0.1, f64::NAN, -0.0],
            profile_t_s: vec![vec![5.0, 5.01], vec![], vec![7.5]],
            profile_value: vec![vec![1e-300, f64::INFINITY], vec![], vec![0.3]],
            false_alarm: Some((1.23, 2)),
            detection: None,
            isolated_by_max: Some(1),
            isolated_by_direction: None,
            diverged_at_s: Some(19.99),
        };
        let failure = TrialFailure::Reported("the FMU truth failed: x.fmu: ü at t = 1 s".into());
        let diverged = TrialFailure::Diverged { at_s: 21.86, why: "the FMU truth failed: diverged".into() };
        let line = encode_trial(&[Ok(outcome.clone()), Err(failure.clone()), Err(diverged.clone())]);
        let back = decode_trial(&line, 3).unwrap();
        // A diverged truth stays diverged across the pipe (the records' `diverged`), an error does not.
        assert_eq!(back[2], Err(diverged));
        assert_eq!(back[1].as_ref().unwrap_err().diverged_at_s(), None);
        let got = back[0].as_ref().unwrap();
        // Bit for bit, NaN and the sign of zero included.
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&got.pre_onset_max_abs_residual), bits(&outcome.pre_onset_max_abs_residual));
        assert_eq!((&got.profile_t_s, &got.profile_value), (&outcome.profile_t_s, &outcome.profile_value));
        assert_eq!((got.false_alarm, got.detection, got.diverged_at_s), (Some((1.23, 2)), None, Some(19.99)));
        assert_eq!((got.isolated_by_max, got.isolated_by_direction), (Some(1), None));
        assert_eq!(back[1].as_ref().unwrap_err().to_string(), failure.to_string());
        // A truncated line (a child that died mid-write) is not taken for an answer.
        assert!(decode_trial(&line[..line.len() / 2], 3).is_none());
        assert!(decode_trial(&line, 4).is_none());
    }
}
