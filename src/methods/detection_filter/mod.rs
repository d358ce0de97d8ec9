//! Detection-filter studies (method 000): eigenstructure-assigned detection filters on an LTI plant.

pub mod commands;
pub mod cusum;
pub mod decision;
pub mod deck;
pub mod false_alarms;
pub mod filter;
pub mod flight_thresholds;
pub mod fmu_detector;
pub mod kalman_chi2;
pub mod kernel;
pub mod lanes;
pub mod normals;
pub mod rare_event;
pub mod records;
pub mod report;
pub mod scenario;
pub mod study;
pub mod trial;
pub mod trials;
pub mod workers;
pub mod worst_case;

use polars::prelude::*;

use std::path::Path;

use crate::engine::method::{Inputs, Method, Study};
use crate::engine::results::summary_spec::{Extra, Isolates, SummarySpec};
use crate::engine::run::runner::{
    FmuProcesses, Manifest, ModelFile, RunError, RunOptions, RunReport, TrialSource, run,
};
use crate::engine::scenario::deck::FromDeck;
use crate::engine::scenario::design::Design;
use kernel::LANES;
use records::RecordBuilder;
use study::LtiStudy;

/// `manifest.json`'s kind of these studies.
pub const KIND: &str = "detection_filter";

/// Method 000: the registry's entry.
pub static METHOD: Method = Method {
    kind: KIND,
    marker: "plant",
    title: "eigenstructure-assigned detection filters on an LTI plant, sensor faults (method 000)",
    options: study::OPTIONS,
    load: |text, path| Ok(Box::new(LtiStudy::from_toml(text, path)?)),
    summary: SummarySpec {
        extra_keys: &[],
        isolates: Isolates::Target,
        // Isolation by the largest threshold-scaled residual, beside the signature rule's `isolated`.
        extras: &[
            Extra::NamesTarget { name: "isolated_by_max_correctly", column: "isolated_by_max" },
            Extra::Rate {
                name: "isolation_by_max_accuracy",
                k: "isolated_by_max_correctly",
                n: "isolation_decided",
                faulty_only: false,
            },
        ],
        paired_medians: &[],
        printed: &[],
    },
    report: Some(report::report_part),
    trace_panels: &[],
    own_plots: &[],
    starter: ("studies/starter_detection_filter.toml", include_str!("../../../studies/starter_detection_filter.toml")),
    replay_starter: None,
    hour_laws: Some(false_alarms::hour_laws),
    flight_thresholds: Some(flight_thresholds::for_deck),
};

impl Study for LtiStudy {
    crate::study_accessors!(monte_carlo.common);
    fn validate(&self) -> Result<(), RunError> {
        commands::validate(self)
    }
    fn design(&self, json: bool) -> Result<(), RunError> {
        commands::design(self, json)
    }
    fn simulate(&self, trial: u64, detector: Option<&str>, out: &Path, _: Inputs) -> Result<(), RunError> {
        commands::simulate(self, trial, detector, out)
    }
    fn run(&self, opts: &RunOptions, _: Inputs) -> Result<RunReport, RunError> {
        run_study(self, opts)
    }
    fn worst_case(&self, opts: &crate::engine::worst_case::WorstCaseOptions) -> Result<(), RunError> {
        worst_case::run(self, opts)
    }
    fn rare_event(&self, opts: &crate::engine::rare_event::study::RareEventOptions) -> Result<(), RunError> {
        if !self.fmus().is_empty() {
            return Err(RunError::Invalid(format!(
                "{}: rare-event runs on a linear truth and loop; this deck flies an FMU: use run with the tail fit",
                self.header.path.display()
            )));
        }
        if self.sensor_law.iter().any(|l| *l != crate::engine::scenario::noise::SensorLaw::Gaussian) {
            return Err(RunError::Invalid(format!(
                "{}: noise.sensor_law: importance sampling and splitting here tilt Gaussian sensor noise; this deck's is heavy-tailed: use run with the tail fit",
                self.header.path.display()
            )));
        }
        rare_event::run(self, opts)
    }
    fn sensitivity_design(&mut self, base_samples: u64, bootstrap: u64) -> Result<Design, RunError> {
        let parts = scenario::ScenarioSampler::sensitivity_parts(self);
        Ok(self.monte_carlo.common.use_design(base_samples, bootstrap, parts))
    }
}
use trials::{Engine, TrialResult};

/// Runs an LTI study (method 000) through [`run`]; a detector that cannot be designed on the nominal
/// model is the deck's error (with parameter errors, per-trial design failures are rows instead).
pub fn run_study(study: &LtiStudy, opts: &RunOptions) -> Result<RunReport, RunError> {
    let engine = Engine::new(study);
    for (d, f) in study.detectors.iter().zip(engine.nominal_filters()) {
        match f {
            Err(e) if study.monte_carlo.parameter_errors.is_empty() => {
                return Err(RunError::Invalid(format!("{}: detector {}: {e}", opts.deck.display(), d.name)));
            }
            Ok(filter) if opts.progress => {
                if let Some(w) = filter.discrete.conditioning_warning() {
                    eprintln!("warning: {}: detector {:?}: {w}", opts.deck.display(), d.name);
                }
            }
            _ => {}
        }
    }
    if opts.progress {
        for w in study.truth_warnings() {
            eprintln!("warning: {}: {w}", opts.deck.display());
        }
    }
    let workers = match opts.fmu_processes {
        FmuProcesses::InProcess => None,
        // Worker processes need Unix (their pipes and descriptors): elsewhere the default is in process.
        FmuProcesses::Auto if study.fmus().is_empty() || !cfg!(unix) => None,
        FmuProcesses::Always if study.fmus().is_empty() => {
            return Err(RunError::Invalid(format!(
                "--fmu-processes: {} runs no FMU (it isolates FMU crashes in worker processes)",
                opts.deck.display()
            )));
        }
        FmuProcesses::Auto | FmuProcesses::Always => Some(workers::WorkerSpec::new(
            std::env::current_exe()
                .map_err(|e| RunError::Internal(format!("worker processes: where is this program? {e}")))?,
            &opts.deck,
            study.header.seed,
            study.monte_carlo.common.trials,
            study.monte_carlo.common.profile.step(),
            opts.sensitivity.as_ref().map(|d| (d.base_samples, d.bootstrap)),
        )?),
    };
    // An FMU whose instances may not share a process's threads (only one allowed, or a runtime that is
    // not thread-safe) gets one worker thread in process; in worker processes each has its own.
    let alone = study
        .fmus()
        .into_iter()
        .find_map(|p| p.fmu.description.one_thread_per_process(p.interface).map(|why| (p.fmu.file_name(), why)));
    let one_thread;
    let opts = match alone {
        Some((file, why)) if opts.threads != Some(1) && workers.is_none() => {
            if opts.progress {
                eprintln!("note: {file}: {why}: the run in process uses one thread (worker processes need not)");
            }
            one_thread = RunOptions { threads: Some(1), ..opts.clone() };
            &one_thread
        }
        _ => opts,
    };
    run(&LtiTrials { study, engine, workers }, opts)
}

/// Method 000's trials: 8 at a time in SIMD lanes (when every test is built in).
struct LtiTrials<'a> {
    study: &'a LtiStudy,
    engine: Engine<'a>,
    /// `run --fmu-processes`: the trials are flown in worker processes.
    workers: Option<workers::WorkerSpec>,
}

impl TrialSource for LtiTrials<'_> {
    type Result = TrialResult;
    fn group_trials(&self) -> u64 {
        LANES as u64
    }
    fn trial(&self, trial: u64) -> TrialResult {
        self.engine.run(trial)
    }
    fn manifest(&self) -> Manifest {
        let study = self.study;
        Manifest {
            outputs: study.plant.output_names.clone(),
            deck_thresholds: study.detectors.iter().map(|d| d.params.thresholds.iter().copied().collect()).collect(),
            fault_size_units: fault_size_units(study),
            fault_size_bins: crate::fault::deck::FaultKindSpec::size_bins(&study.monte_carlo.faults),
            parameter_error_bins: crate::engine::scenario::deck::ParameterError::bins(
                &study.monte_carlo.parameter_errors,
            ),
            sensor_noise: Some(noise_in_words(study)),
            profiles_exact_at_deadlines: true,
            models: (study.fmus().into_iter())
                .map(|t| ModelFile { file: t.fmu.file_name(), sha256: t.fmu.sha256.clone() })
                .collect(),
            ..Manifest::of(
                KIND,
                &study.header,
                &study.monte_carlo.common,
                study.detectors.iter().map(|d| d.name.as_str()),
            )
        }
    }
    fn simulate(&self, first: u64, end: u64) -> Vec<TrialResult> {
        match &self.workers {
            Some(w) => w.run_group(&self.engine, first, end),
            None => self.engine.run_group(first, end),
        }
    }
    fn frame(&self, results: &[TrialResult]) -> PolarsResult<DataFrame> {
        let mut builder = RecordBuilder::new(self.study, results.len() * self.study.detectors.len());
        for r in results {
            builder.push(r);
        }
        builder.finish()
    }
}

/// The unit of each fault kind's size, as the deck gives it.
fn fault_size_units(study: &LtiStudy) -> std::collections::BTreeMap<String, String> {
    use crate::fault::deck::fixed_size_unit;
    let mut units = std::collections::BTreeMap::new();
    for f in &study.monte_carlo.faults {
        units.insert(f.record_kind().to_string(), f.size_unit().to_string());
    }
    for f in &study.faults {
        units.entry(f.mode.name().to_string()).or_insert_with(|| fixed_size_unit(&f.mode, false).to_string());
    }
    for f in &study.actuator_faults {
        units.entry(f.mode.actuator_name().to_string()).or_insert_with(|| fixed_size_unit(&f.mode, true).to_string());
    }
    units
}

/// The sensor noise's law in words for the manifest (`safety.csv`'s assumptions).
fn noise_in_words(study: &LtiStudy) -> String {
    use crate::engine::scenario::noise::SensorLaw;
    if study.sensor_law.iter().all(|l| *l == SensorLaw::Gaussian) {
        return "Gaussian, white, of the deck's sensor_sigma".into();
    }
    let each: Vec<String> = (study.plant.output_names.iter().zip(&study.sensor_law))
        .map(|(name, law)| format!("{name} {}", law.describe()))
        .collect();
    format!("white, of the deck's sensor_sigma, by output: {}", each.join(", "))
}
