//! Control-surface studies (method 004): banks of (strong-tracking) EKFs on a UAV.

pub mod actuator;
pub mod commands;
pub mod records;
pub mod scenario;
pub mod stmmae;
pub mod study;
pub mod trial;

use crate::engine::method::Method;
use crate::engine::report::{OwnPlot, TracePanel};
use crate::engine::results::summary_spec::{Extra, Isolates, SummarySpec};
use crate::engine::run::runner::{Manifest, RunError, TrialSource};
use crate::engine::scenario::deck::FromDeck;
use crate::engine::scenario::streams::{Substream, noise_rng};
use crate::methods::surface_bank::scenario::SurfaceScenarioSampler;
use crate::methods::surface_bank::stmmae::BankParams;
use crate::methods::surface_bank::study::SurfaceStudy;
use crate::vehicles::aerosonde::SURFACE_NAMES;
use trial::*;

/// `manifest.json`'s kind of these studies.
pub const KIND: &str = "surface_bank";

/// Method 004: the registry's entry.
pub static METHOD: Method = Method {
    kind: KIND,
    marker: "airframe",
    title: "banks of (strong-tracking) EKFs on a UAV, control-surface faults (method 004)",
    options: study::OPTIONS,
    load: |text, path| Ok(Box::new(SurfaceStudy::from_toml(text, path)?)),
    summary: SummarySpec {
        extra_keys: &[],
        isolates: Isolates::Target,
        extras: &[
            Extra::Present { name: "clear_decided", column: records::col::CLEARED },
            Extra::Count { name: "cleared", column: records::col::CLEARED },
            Extra::Rate { name: "clearing_rate", k: "cleared", n: "clear_decided", faulty_only: true },
            Extra::Present { name: "recovery_decided", column: records::col::RECOVERED },
            Extra::Count { name: "recovered", column: records::col::RECOVERED },
            Extra::Rate { name: "recovery_rate", k: "recovered", n: "recovery_decided", faulty_only: true },
            Extra::Count { name: "post_fault", column: records::col::POST_FAULT_DECLARATIONS },
            Extra::Rate { name: "post_fault_rate", k: "post_fault", n: "flown", faulty_only: true },
            Extra::Count { name: "asymmetric", column: crate::engine::results::schema::col::ASYMMETRIC_STEPS },
            Extra::Count {
                name: "not_positive_definite",
                column: crate::engine::results::schema::col::NOT_POSITIVE_DEFINITE_STEPS,
            },
            Extra::Quantile {
                name: "isolation_delay_p50_s",
                column: records::col::ISOLATION_DELAY_S,
                p: 0.5,
                abs: false,
            },
            Extra::Quantile { name: "clearing_p50_s", column: records::col::CLEARING_DELAY_S, p: 0.5, abs: false },
            Extra::Quantile { name: "clearing_p90_s", column: records::col::CLEARING_DELAY_S, p: 0.9, abs: false },
            Extra::Quantile { name: "recovery_p50_s", column: records::col::RECOVERY_DELAY_S, p: 0.5, abs: false },
            Extra::Quantile { name: "recovery_p90_s", column: records::col::RECOVERY_DELAY_S, p: 0.9, abs: false },
            Extra::Quantile {
                name: "estimate_rms_p50_deg",
                column: records::col::SURFACE_ESTIMATE_RMS_DEG,
                p: 0.5,
                abs: false,
            },
            Extra::Quantile {
                name: "estimate_rms_window_p50_deg",
                column: records::col::SURFACE_ESTIMATE_RMS_WINDOW_DEG,
                p: 0.5,
                abs: false,
            },
            Extra::Quantile {
                name: "estimate_rms_first_s_p50_deg",
                column: records::col::SURFACE_ESTIMATE_RMS_FIRST_S_DEG,
                p: 0.5,
                abs: false,
            },
        ],
        paired_medians: &[
            records::col::CLEARING_DELAY_S,
            records::col::RECOVERY_DELAY_S,
            records::col::SURFACE_ESTIMATE_RMS_DEG,
            records::col::SURFACE_ESTIMATE_RMS_WINDOW_DEG,
            records::col::SURFACE_ESTIMATE_RMS_FIRST_S_DEG,
        ],
        printed: &[
            ("clear p50 s", "clearing_p50_s"),
            ("recover p50 s", "recovery_p50_s"),
            ("relapse", "post_fault_rate"),
        ],
    },
    report: None,
    trace_panels: &[
        TracePanel { title: "surface positions (rad)", columns: &["*_position_rad"] },
        TracePanel { title: "banks' surface estimates (rad)", columns: &["*_estimate_rad"] },
        TracePanel { title: "model probabilities", columns: &["*_p_*"] },
        TracePanel { title: "body rates (rad/s)", columns: &["p_rad_s_*", "q_rad_s_*", "r_rad_s_*"] },
    ],
    own_plots: &[
        OwnPlot::Histogram {
            file: "clearing_delay",
            title: "Clearing delay after the fault ends",
            column: "clearing_delay_s",
        },
        OwnPlot::Histogram {
            file: "post_fault_declarations",
            title: "Declarations after the fault cleared, per trial",
            column: "post_fault_declarations",
        },
    ],
    starter: ("studies/ci_seed004.toml", include_str!("../../../studies/ci_seed004.toml")),
    replay_starter: None,
    hour_laws: None,
    flight_thresholds: None,
};

crate::plain_study!(SurfaceStudy, monte_carlo.common, |s| Ok::<_, RunError>(SurfaceTrials::new(s)));

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

    /// Trial `trial`: its scenario from the scenario stream, its sensor noise from the sensor stream.
    pub fn run_trial(&self, trial: u64) -> SurfaceTrialResult {
        let spec = self.sampler.spec(trial);
        let setup = SurfaceTrial::new(&self.sampler, &spec);
        let mut rng = noise_rng(self.study.header.seed, trial, Substream::SensorNoise);
        let outcome = run_banks(self.study, &setup, &self.banks, &mut rng, |_, _| ());
        SurfaceTrialResult { spec, outcome }
    }
}

impl TrialSource for SurfaceTrials<'_> {
    type Result = SurfaceTrialResult;
    fn trial(&self, trial: u64) -> SurfaceTrialResult {
        self.run_trial(trial)
    }
    fn manifest(&self) -> Manifest {
        let s = self.study;
        let units = [
            ("stuck", "deg (the stuck position)"),
            ("oscillation", "deg (the square wave's amplitude)"),
            ("loss_of_effectiveness", "fraction of the deflection still acting"),
        ];
        let mut bins = Default::default();
        for f in &s.monte_carlo.faults {
            f.size().add_bins_to(f.name(), &mut bins);
        }
        Manifest {
            fault_size_bins: bins,
            parameter_error_bins: crate::engine::scenario::deck::ParameterError::bins(&s.monte_carlo.parameter_errors),
            // A flight costs 0.1-2 s, so 64 of them make a part file of seconds to a minute on 2 cores.
            chunk_trials: 64,
            outputs: SURFACE_NAMES.iter().map(|n| n.to_string()).collect(),
            fault_size_units: units.iter().map(|(k, u)| (k.to_string(), u.to_string())).collect(),
            deck_thresholds: s.banks.iter().map(|(_, p)| vec![p.levels.alarm_threshold_s(s.header.dt_s)]).collect(),
            ..Manifest::of(KIND, &s.header, &s.monte_carlo.common, s.banks.iter().map(|(n, _)| n.as_str()))
        }
    }
    fn frame(&self, results: &[SurfaceTrialResult]) -> polars::prelude::PolarsResult<polars::prelude::DataFrame> {
        records::frame(self.study, results)
    }
}
