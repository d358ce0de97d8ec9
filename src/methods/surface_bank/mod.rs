//! Control-surface studies (method 004): banks of (strong-tracking) EKFs on a UAV.

pub mod actuator;
pub mod commands;
pub mod records;
pub mod scenario;
pub mod stmmae;
pub mod study;
pub mod trial;
pub mod uav;

use std::path::Path;

use crate::engine::deck::DeckError;
use crate::engine::method::{Extra, Inputs, Isolates, Method, Study, SummarySpec};
use crate::engine::runner::{Manifest, RunError, RunOptions, RunReport, TrialSource, run};
use crate::engine::streams::{Substream, noise_rng};
use crate::methods::surface_bank::scenario::SurfaceScenarioSampler;
use crate::methods::surface_bank::stmmae::BankParams;
use crate::methods::surface_bank::study::SurfaceStudy;
use crate::methods::surface_bank::uav::SURFACE_NAMES;
use trial::*;

/// `manifest.json`'s kind of these studies.
pub const KIND: &str = "surface_bank";

/// Method 004: the registry's entry.
pub struct SurfaceBanks;

impl Method for SurfaceBanks {
    fn kind(&self) -> &'static str {
        KIND
    }
    fn marker(&self) -> &'static str {
        "airframe"
    }
    fn title(&self) -> &'static str {
        "banks of (strong-tracking) EKFs on a UAV, control-surface faults (method 004)"
    }
    fn load(&self, text: &str, path: &Path) -> Result<Box<dyn Study>, DeckError> {
        Ok(Box::new(SurfaceStudy::from_toml(text, path)?))
    }
    fn summary(&self) -> SummarySpec {
        use records::col;
        SummarySpec {
            extra_keys: &[],
            isolates: Isolates::Target,
            extras: &[
                Extra::Present { name: "clear_decided", column: col::CLEARED },
                Extra::Count { name: "cleared", column: col::CLEARED },
                Extra::Rate { name: "clearing_rate", k: "cleared", n: "clear_decided", faulty_only: true },
                Extra::Count { name: "post_fault", column: col::POST_FAULT_DECLARATIONS },
                Extra::Rate { name: "post_fault_rate", k: "post_fault", n: "flown", faulty_only: true },
                Extra::Count { name: "asymmetric", column: col::ASYMMETRIC_STEPS },
                Extra::Count { name: "not_positive_definite", column: col::NOT_POSITIVE_DEFINITE_STEPS },
                Extra::Quantile { name: "isolation_delay_p50_s", column: col::ISOLATION_DELAY_S, p: 0.5, abs: false },
                Extra::Quantile { name: "clearing_p50_s", column: col::CLEARING_DELAY_S, p: 0.5, abs: false },
                Extra::Quantile { name: "clearing_p90_s", column: col::CLEARING_DELAY_S, p: 0.9, abs: false },
                Extra::Quantile {
                    name: "estimate_rms_p50_deg",
                    column: col::SURFACE_ESTIMATE_RMS_DEG,
                    p: 0.5,
                    abs: false,
                },
            ],
            paired_delays: &[col::CLEARING_DELAY_S],
            printed: &[("clear p50 s", "clearing_p50_s"), ("relapse", "post_fault_rate")],
        }
    }
}

impl Study for SurfaceStudy {
    fn name(&self) -> &str {
        &self.name
    }
    fn trials(&self) -> u64 {
        self.monte_carlo.trials
    }
    fn set_trials(&mut self, trials: u64) {
        self.monte_carlo.trials = trials;
    }
    fn set_seed(&mut self, seed: u64) {
        self.seed = seed;
    }
    fn validate(&self) -> Result<(), RunError> {
        commands::validate(self)
    }
    fn simulate(&self, trial: u64, detector: Option<&str>, out: &Path, _: Inputs) -> Result<(), RunError> {
        commands::simulate(self, trial, detector, out)
    }
    fn run(&self, opts: &RunOptions, _: Inputs) -> Result<RunReport, RunError> {
        let trials = SurfaceTrials::new(self);
        run(&trials, trials.manifest(), opts)
    }
}

/// The runner's view of a surface study: every bank of the deck on each trial's one flight.
pub struct SurfaceTrials<'a> {
    study: &'a SurfaceStudy,
    sampler: SurfaceScenarioSampler<'a>,
    banks: Vec<BankParams>,
}

impl<'a> SurfaceTrials<'a> {
    pub fn new(study: &'a SurfaceStudy) -> Self {
        let banks = study.banks.iter().map(|(_, p)| p.clone()).collect();
        SurfaceTrials { study, sampler: SurfaceScenarioSampler::new(study), banks }
    }

    /// The study's fields of `manifest.json`.
    pub fn manifest(&self) -> Manifest {
        let s = self.study;
        let units = [
            ("stuck", "deg (the stuck position)"),
            ("oscillation", "deg (the square wave's amplitude)"),
            ("loss_of_effectiveness", "fraction of the deflection still acting"),
        ];
        Manifest {
            kind: KIND.into(),
            study: s.name.clone(),
            seed: s.seed,
            trials: s.monte_carlo.trials,
            detectors: s.banks.iter().map(|(n, _)| n.clone()).collect(),
            outputs: SURFACE_NAMES.iter().map(|n| n.to_string()).collect(),
            fault_size_units: units.iter().map(|(k, u)| (k.to_string(), u.to_string())).collect(),
            ..Manifest::unstarted()
        }
    }

    /// Trial `trial`: its scenario from the scenario stream, its sensor noise from the sensor stream.
    pub fn run_trial(&self, trial: u64) -> SurfaceTrialResult {
        let spec = self.sampler.spec(trial);
        let setup = SurfaceTrial::new(&self.sampler, &spec);
        let mut rng = noise_rng(self.study.seed, trial, Substream::SensorNoise);
        let outcome = run_banks(self.study, &setup, &self.banks, &mut rng, |_, _| ());
        SurfaceTrialResult { spec, outcome }
    }
}

impl TrialSource for SurfaceTrials<'_> {
    type Result = SurfaceTrialResult;
    /// A flight costs 0.1-2 s, so 64 of them make a part file of seconds to a minute on 2 cores.
    fn chunk_trials(&self) -> u64 {
        64
    }
    fn group_trials(&self) -> u64 {
        1
    }
    fn simulate(&self, first: u64, end: u64) -> Vec<SurfaceTrialResult> {
        (first..end).map(|t| self.run_trial(t)).collect()
    }
    fn frame(&self, results: &[SurfaceTrialResult]) -> polars::prelude::PolarsResult<polars::prelude::DataFrame> {
        crate::methods::surface_bank::records::frame(self.study, results)
    }
}
