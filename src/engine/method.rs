//! How the engine and the command line know a study method: a [`Method`] (one per folder in
//! `src/methods/`, listed once in `methods::REGISTRY`) reads the decks of its kind into a [`Study`],
//! which can be validated, simulated trial by trial and run through the engine's runner.
//!
//! The engine never names a method: commands find one by the table that marks a deck ([`load`]) or by
//! the `kind` a results folder's manifest records ([`find`]), in the registry the caller hands in.

use std::path::Path;

use crate::engine::report::{KindReport, OwnPlot, Report, ReportContext, ReportPart, TracePanel};
use crate::engine::results::summary_spec::SummarySpec;
use crate::engine::run::runner::{Manifest, RunError, RunOptions, RunReport};
use crate::engine::scenario::deck::{DeckError, StudyHeader, read_deck};

/// A kind of study: how its decks read, what it adds to the shared summary, which options it takes.
/// Each method folder defines one as a `static`, listed in `methods::REGISTRY`.
pub struct Method {
    /// `manifest.json`'s `kind` and the folder under `src/methods/`.
    pub kind: &'static str,
    /// The top-level table that marks a deck of this kind (`plant` for `[plant]`).
    pub marker: &'static str,
    /// What the kind studies, in a few words with the seed method's number, for lists and messages.
    pub title: &'static str,
    /// The options beyond the common ones that this kind takes.
    pub options: &'static [Opt],
    /// Parses and validates a deck of this kind; every rejection names the file and the field.
    pub load: fn(&str, &Path) -> Result<Box<dyn Study>, DeckError>,
    /// What the shared summary adds for this kind ([`crate::engine::results::summary`]).
    pub summary: SummarySpec,
    /// What the kind adds to the shared report (`fdimc report`, [`crate::engine::report`]): its own plots and
    /// sections; one that draws `trace_trial<N>.svg` itself replaces the generic traces.
    pub report: Option<fn(&ReportContext) -> Result<ReportPart, RunError>>,
    /// The panels of `fdimc report --trials N`: the columns of `simulate`'s trace each one draws.
    pub trace_panels: &'static [TracePanel],
    /// Plots of the kind's own `trials.parquet` columns in its report.
    pub own_plots: &'static [OwnPlot],
    /// `fdimc new <kind> FILE`: a commented deck of this kind that validates and runs as written (the
    /// kind's CI deck, `include_str!`), and the bundled file it is.
    pub starter: (&'static str, &'static str),
    /// `fdimc new <kind> FILE --replay LOG`: for kinds that replay flight logs, the starter deck of study
    /// `study` (first argument) replaying LOG, to be written to FILE; or why LOG cannot be replayed so.
    pub replay_starter: Option<fn(&str, &Path, &Path) -> Result<String, String>>,
    /// Where the kind knows its residual's exact law: per detector of a deck (its text and path), how
    /// far converting a trial's false-alarm probability to one per flight hour under-counts at any
    /// thresholds (one per statistic, named as given), `None` for a detector whose law it does not
    /// know. `summarize` checks the conversion with it ([`Method::hour_laws_of_run`]); it must not run
    /// a user's code (an FMU) in this process.
    pub hour_laws: Option<HourLaws>,
    /// `fdimc flight-thresholds`: where the kind can find thresholds for a false-alarm target over
    /// whole flights, per detector of a deck (its text and path; the named detector, or every one it can
    /// search, the others skipped with why).
    /// `None`: it cannot, and the command says what to run instead.
    pub flight_thresholds: Option<FlightThresholds>,
}

/// See [`Method::hour_laws`].
pub type HourLaws = fn(&str, &Path, &[String]) -> Vec<Option<crate::engine::results::thresholds::HourLaw>>;

/// See [`Method::flight_thresholds`].
pub type FlightThresholds = fn(
    &str,
    &Path,
    Option<&str>,
    &crate::engine::results::flight_thresholds::FlightTarget,
) -> Result<crate::engine::results::flight_thresholds::FlightSearch, RunError>;

impl Method {
    /// [`Method::hour_laws`] of the deck a run in a folder read (`manifest`), when the kind has them and
    /// the deck is where the run read it and unchanged (its SHA-256 the run's); else none.
    pub fn hour_laws_of_run(
        &self,
        manifest: &Manifest,
        statistics: &[String],
    ) -> Vec<Option<crate::engine::results::thresholds::HourLaw>> {
        let Some(laws) = self.hour_laws else { return Vec::new() };
        let deck = Path::new(&manifest.deck);
        let same = crate::engine::run::runner::deck_sha256(deck).is_ok_and(|h| h == manifest.deck_sha256);
        match read_deck(deck) {
            Ok(text) if same => laws(&text, deck, statistics),
            _ => Vec::new(),
        }
    }

    /// The kind records a detection statistic whose thresholds `summarize` calibrates after the run
    /// ([`Opt::Thresholds`]); its decks then take `monte_carlo.target_pfa`.
    pub fn calibrates(&self) -> bool {
        self.options.contains(&Opt::Thresholds)
    }

    /// `fdimc report DIR`: the shared report of the run in `dir` with what this kind adds, `trials`
    /// re-flown by the kind's `simulate` from the deck the run used.
    pub fn write_report(&self, dir: &Path, trials: &[u64]) -> Result<Report, RunError> {
        let kind = KindReport {
            kind: self.kind,
            calibrates: self.calibrates(),
            trains_classifiers: self.options.contains(&Opt::Classifiers),
            part: self.report,
            trace_panels: self.trace_panels,
            own_plots: self.own_plots,
        };
        // The deck is read once, at the first trial to re-fly.
        let mut study: Option<Box<dyn Study>> = None;
        let mut refly = |deck: &Path, manifest: &Manifest, trial: u64, table: &Path, classifiers: Option<&Path>| {
            if study.is_none() {
                let text = read_deck(deck).map_err(|e| RunError::Invalid(e.to_string()))?;
                let mut s = (self.load)(&text, deck).map_err(|e| RunError::Invalid(e.to_string()))?;
                let (seed, n) = s.seed_and_trials();
                (*seed, *n) = (manifest.seed, manifest.trials);
                study = Some(s);
            }
            let study = study.as_ref().expect("loaded above");
            study.simulate(trial, None, table, Inputs { classifiers, quiet: true })
        };
        crate::engine::report::write_report(dir, trials, &kind, &mut refly)
    }

    /// `fdimc new`: the starter deck with its study named `study` (results go to `results/<study>/`),
    /// under a header that says where it came from instead of the bundled deck's own.
    pub fn starter_deck(&self, study: &str) -> String {
        let (source, text) = self.starter;
        // The bundled deck's opening comment (to its first blank line) speaks of its own role (CI); the
        // comments of its tables stay.
        let body = match text.split_once("\n\n") {
            Some((opening, rest)) if opening.lines().all(|l| l.starts_with('#')) => rest,
            _ => text,
        };
        let mut out = format!(
            "# A deck of kind {kind} ({title}), written by `fdimc new {kind}` from {source}.\n\
             # `fdimc validate` shows what it resolves to, `fdimc run` writes results/{study}/; every table\n\
             # and field of every kind: docs/deck.md in fdimc's repository.\n\n",
            kind = self.kind,
            title = self.title,
        );
        let mut in_study = false;
        let mut named = false;
        for line in body.lines() {
            if line.trim_start().starts_with('[') {
                in_study = line.trim() == "[study]";
            }
            if in_study && !named && line.trim_start().starts_with("name") && line.contains('=') {
                out.push_str(&format!("name = \"{study}\"\n"));
                named = true;
                continue;
            }
            out.push_str(line);
            out.push('\n');
        }
        out
    }
}

/// Options that only some kinds take; a kind that does not list one refuses it (exit 2).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Opt {
    /// `summarize --target-pfa` and `--thresholds`: the kind records a detection statistic whose
    /// threshold can be calibrated after the run.
    Thresholds,
    /// `run`, `simulate --classifiers FILE` and `fdimc train`: the kind trains classifiers first.
    Classifiers,
    /// `fdimc design`: the kind has a gain design to show.
    Design,
    /// `fdimc rare-event`: the kind's fault-free trials run as rare-event paths.
    RareEvent,
    /// `fdimc sensitivity`: the kind's trials can be drawn from a sensitivity design.
    Sensitivity,
    /// `run --fmu-processes`: the kind can fly its trials in worker processes (its decks run FMUs).
    FmuProcesses,
    /// `fdimc worst-case`: the kind's trials can take a point of the deck's uncertainty box.
    WorstCase,
}

impl Opt {
    /// The option as the command line spells it.
    pub fn flag(self) -> &'static str {
        match self {
            Opt::Thresholds => "--target-pfa / --thresholds",
            Opt::Classifiers => "--classifiers / fdimc train",
            Opt::Design => "fdimc design",
            Opt::RareEvent => "fdimc rare-event",
            Opt::Sensitivity => "fdimc sensitivity",
            Opt::FmuProcesses => "--fmu-processes",
            Opt::WorstCase => "fdimc worst-case",
        }
    }
}

/// What a command hands a study beyond the deck.
#[derive(Debug, Clone, Copy, Default)]
pub struct Inputs<'a> {
    /// Classifiers written by `fdimc train` ([`Opt::Classifiers`]).
    pub classifiers: Option<&'a Path>,
    pub quiet: bool,
}

/// A deck its method has validated.
pub trait Study: Sync {
    /// The deck's `[study]` fields.
    fn header(&self) -> &StudyHeader;
    /// What `run --seed S` and `--trials N` change: the seed and the trial count.
    fn seed_and_trials(&mut self) -> (&mut u64, &mut u64);
    /// The shared `[monte_carlo]` fields (`run --profile-resolution` changes the profile grid).
    fn monte_carlo(&mut self) -> &mut crate::engine::scenario::deck::MonteCarlo;
    /// `fdimc validate`: prints the resolved study.
    fn validate(&self) -> Result<(), RunError>;
    /// `fdimc simulate`: writes one trial's per-sample trace to `out` and prints what happened in it.
    fn simulate(&self, trial: u64, detector: Option<&str>, out: &Path, inputs: Inputs) -> Result<(), RunError>;
    /// `fdimc run`: the trials through [`crate::engine::run::runner::run`].
    fn run(&self, opts: &RunOptions, inputs: Inputs) -> Result<RunReport, RunError>;
    /// `fdimc design` ([`Opt::Design`]): prints the detectors' gains.
    fn design(&self, _json: bool) -> Result<(), RunError> {
        Err(RunError::Internal("this kind lists no design".into()))
    }
    /// `fdimc rare-event` ([`Opt::RareEvent`]): estimates, writes and prints rare false alarms.
    fn rare_event(&self, _opts: &crate::engine::rare_event::study::RareEventOptions) -> Result<(), RunError> {
        Err(RunError::Internal("this kind lists no rare-event paths".into()))
    }
    /// `fdimc worst-case` ([`Opt::WorstCase`]): searches, writes and prints the worst point.
    fn worst_case(&self, _opts: &crate::engine::worst_case::WorstCaseOptions) -> Result<(), RunError> {
        Err(RunError::Internal("this kind lists no worst-case search".into()))
    }
    /// `fdimc sensitivity` ([`Opt::Sensitivity`]): makes the study's trials the rows of a Saltelli design
    /// of `base_samples` rows per matrix over the factors its trials draw, and returns the design.
    fn sensitivity_design(
        &mut self,
        _base_samples: u64,
        _bootstrap: u64,
    ) -> Result<crate::engine::scenario::design::Design, RunError> {
        Err(RunError::Internal("this kind lists no sensitivity design".into()))
    }
    /// `fdimc train` ([`Opt::Classifiers`]): trains what the study evaluates and writes it to `out`.
    fn train(&self, _out: Option<&Path>) -> Result<(), RunError> {
        Err(RunError::Internal("this kind lists nothing to train".into()))
    }
}

/// `simulate --detector NAME`: the index of `wanted` among the deck's detector `names` (`None` when no
/// name is given: every detector flies), or an error listing the names.
pub fn select_detector(header: &StudyHeader, names: &[&str], wanted: Option<&str>) -> Result<Option<usize>, RunError> {
    let Some(name) = wanted else { return Ok(None) };
    names.iter().position(|n| *n == name).map(Some).ok_or_else(|| {
        RunError::Invalid(format!("--detector {name:?}: {} has detectors {}", header.path.display(), names.join(", ")))
    })
}

/// `simulate --detector NAME`: keeps only detector `wanted` of `detectors` (named by `name`), or all of
/// them when no name is given; an error lists the names.
pub fn keep_detector<D>(
    header: &StudyHeader,
    detectors: &mut Vec<D>,
    name: impl Fn(&D) -> &str,
    wanted: Option<&str>,
) -> Result<(), RunError> {
    let names: Vec<&str> = detectors.iter().map(name).collect();
    if let Some(i) = select_detector(header, &names, wanted)? {
        detectors.swap(0, i);
        detectors.truncate(1);
    }
    Ok(())
}

/// The method of `kind` (a results folder's), or an error listing the kinds there are.
pub fn find<'r>(registry: &'r [&'r Method], kind: &str) -> Result<&'r Method, RunError> {
    registry.iter().copied().find(|m| m.kind == kind).ok_or_else(|| {
        RunError::Invalid(format!("unknown kind of study {kind:?}; this fdimc knows {}", kinds(registry)))
    })
}

/// Reads the deck at `path`, finds its method by the table that marks it, and validates it.
pub fn load<'r>(registry: &'r [&'r Method], path: &Path) -> Result<(&'r Method, Box<dyn Study>), DeckError> {
    let text = read_deck(path)?;
    let method = method_of(registry, &text, path)?;
    Ok((method, (method.load)(&text, path)?))
}

/// The method whose marker table the deck text has: exactly one must match.
pub fn method_of<'r>(registry: &'r [&'r Method], text: &str, path: &Path) -> Result<&'r Method, DeckError> {
    let table: toml::Table = toml::from_str(text)
        .map_err(|e| DeckError::Parse { file: path.into(), message: e.to_string().trim_end().to_string() })?;
    let matching: Vec<&Method> = registry.iter().copied().filter(|m| table.contains_key(m.marker)).collect();
    match matching.as_slice() {
        [one] => Ok(*one),
        [] => Err(DeckError::Invalid {
            file: path.into(),
            field: "(top level)".into(),
            message: format!("no kind of study matches: a deck has one of the tables {}", kinds(registry)),
        }),
        several => Err(DeckError::Invalid {
            file: path.into(),
            field: "(top level)".into(),
            message: format!(
                "the tables {} mark different kinds of study: keep one",
                several.iter().map(|m| format!("[{}]", m.marker)).collect::<Vec<_>>().join(", ")
            ),
        }),
    }
}

/// Refuses an option `method` does not list, naming the kinds that take it.
pub fn require(registry: &[&Method], method: &Method, opt: Opt) -> Result<(), RunError> {
    if method.options.contains(&opt) {
        return Ok(());
    }
    let takers: Vec<&str> = registry.iter().filter(|m| m.options.contains(&opt)).map(|m| m.kind).collect();
    Err(RunError::Invalid(format!(
        "{} applies to {} studies, not to this {} study ({})",
        opt.flag(),
        takers.join(", "),
        method.kind,
        method.title
    )))
}

/// `[plant] (detection_filter: ...), [vehicle] (...)`.
fn kinds(registry: &[&Method]) -> String {
    registry.iter().map(|m| format!("[{}] ({}: {})", m.marker, m.kind, m.title)).collect::<Vec<_>>().join(", ")
}

/// The [`Study`] accessors of a study type with a `header` field and its shared `[monte_carlo]` fields
/// at the given path (`monte_carlo.common`).
#[macro_export]
macro_rules! study_accessors {
    ($($mc:ident).+) => {
        fn header(&self) -> &$crate::engine::scenario::deck::StudyHeader {
            &self.header
        }
        fn seed_and_trials(&mut self) -> (&mut u64, &mut u64) {
            (&mut self.header.seed, &mut self.$($mc).+.trials)
        }
        fn monte_carlo(&mut self) -> &mut $crate::engine::scenario::deck::MonteCarlo {
            &mut self.$($mc).+
        }
    };
}

/// `impl Study` for a kind whose folder has `commands::{validate, simulate}` and whose trials are a
/// [`crate::engine::run::runner::TrialSource`] made from the study by `|study| source` (a `Result`: an error is the
/// deck's, exit 2), its shared `[monte_carlo]` fields at the path given (`monte_carlo.common`); with
/// `sensitivity: |study| parts`, the kind's sensitivity design ([`Opt::Sensitivity`]) over the parts its
/// scenario names. Kinds
/// with more to do (a gain design, trained classifiers) write the impl out.
#[macro_export]
macro_rules! plain_study {
    ($study:ty, $($mc:ident).+, |$s:ident| $source:expr) => {
        $crate::plain_study!(@impl $study, [$($mc).+], |$s| $source, {});
    };
    ($study:ty, $($mc:ident).+, |$s:ident| $source:expr, sensitivity: |$p:ident| $parts:expr) => {
        $crate::plain_study!(@impl $study, [$($mc).+], |$s| $source, {
            fn sensitivity_design(
                &mut self,
                base_samples: u64,
                bootstrap: u64,
            ) -> Result<$crate::engine::scenario::design::Design, $crate::engine::run::runner::RunError> {
                let $p = &*self;
                let parts = $parts;
                Ok(self.$($mc).+.use_design(base_samples, bootstrap, parts))
            }
        });
    };
    (@impl $study:ty, [$($mc:ident).+], |$s:ident| $source:expr, { $($extra:tt)* }) => {
        impl $crate::engine::method::Study for $study {
            $crate::study_accessors!($($mc).+);
            fn validate(&self) -> Result<(), $crate::engine::run::runner::RunError> {
                commands::validate(self)
            }
            fn simulate(
                &self,
                trial: u64,
                detector: Option<&str>,
                out: &std::path::Path,
                _: $crate::engine::method::Inputs,
            ) -> Result<(), $crate::engine::run::runner::RunError> {
                commands::simulate(self, trial, detector, out)
            }
            fn run(
                &self,
                opts: &$crate::engine::run::runner::RunOptions,
                _: $crate::engine::method::Inputs,
            ) -> Result<$crate::engine::run::runner::RunReport, $crate::engine::run::runner::RunError> {
                let $s = self;
                $crate::engine::run::runner::run(&$source?, opts)
            }
            $($extra)*
        }
    };
}
