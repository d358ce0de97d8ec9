//! Launch-vehicle thrust-loss studies (method 001): EKF residual and moving-horizon least squares.

pub mod commands;
pub mod ekf_mhe;
pub mod records;
pub mod scenario;
pub mod study;
pub mod trial;
pub mod vehicle;

use crate::engine::method::Method;
use crate::engine::report::{OwnPlot, TracePanel};
use crate::engine::results::summary_spec::{Extra, Isolates, SummarySpec};
use crate::engine::run::runner::{Manifest, RunError, TrialSource};
use crate::engine::scenario::deck::FromDeck;
use crate::engine::scenario::streams::{Substream, noise_rng};
use crate::methods::thrust_loss::ekf_mhe::MheStep;
use crate::methods::thrust_loss::scenario::LaunchScenarioSampler;
use crate::methods::thrust_loss::study::LaunchStudy;
use crate::methods::thrust_loss::vehicle::Measurement;
use std::sync::Arc;
use trial::*;

/// `manifest.json`'s kind of these studies.
pub const KIND: &str = "thrust_loss";

/// Method 001: the registry's entry.
pub static METHOD: Method = Method {
    kind: KIND,
    marker: "vehicle",
    title: "EKF residual and moving-horizon least squares on a launch vehicle, thrust loss (method 001)",
    options: study::OPTIONS,
    load: |text, path| Ok(Box::new(LaunchStudy::from_toml(text, path)?)),
    summary: SummarySpec {
        extra_keys: &[records::col::GUST_BIN],
        isolates: Isolates::Target,
        extras: &[
            Extra::Quantile {
                name: "loss_error_p50_percent",
                column: records::col::LOSS_ERROR_PERCENT,
                p: 0.5,
                abs: false,
            },
            Extra::Quantile {
                name: "loss_abs_error_p50_percent",
                column: records::col::LOSS_ERROR_PERCENT,
                p: 0.5,
                abs: true,
            },
            Extra::Quantile {
                name: "above_threshold_p50_s",
                column: records::col::ABOVE_THRESHOLD_S,
                p: 0.5,
                abs: false,
            },
        ],
        paired_medians: &[],
        printed: &[("loss err %", "loss_abs_error_p50_percent")],
    },
    report: None,
    trace_panels: &[
        TracePanel { title: "pitch rate wz (rad/s)", columns: &["wz_*"] },
        TracePanel { title: "thrust (N)", columns: &["thrust_true_n"] },
        TracePanel { title: "EKF residual (rad/s)", columns: &["*_residual_rad_s"] },
        TracePanel { title: "estimated fault fhat", columns: &["*_fhat"] },
        TracePanel { title: "|fhat| / deck threshold (alarm at 1)", columns: &["*_fhat_over_threshold"] },
        TracePanel { title: "alarm", columns: &["*_alarm"] },
    ],
    own_plots: &[OwnPlot::Scatter {
        file: "loss_error",
        title: "Loss-estimate error against the true loss (detected trials)",
        x: "size",
        y: records::col::LOSS_ERROR_PERCENT,
        diagonal: false,
    }],
    starter: ("studies/ci_seed001.toml", include_str!("../../../studies/ci_seed001.toml")),
    replay_starter: None,
    hour_laws: None,
    flight_thresholds: None,
};

// Designs and loss tables are the deck's: one that cannot be designed is invalid input.
crate::plain_study!(LaunchStudy, monte_carlo.common, |s| LaunchTrials::new(s)
    .map_err(|e| RunError::Invalid(format!("{}: {e}", s.header.path.display()))),
    sensitivity: |s| scenario::sensitivity_parts(s));

/// The runner's view of a launch study: designs built once, every trial flown once.
pub struct LaunchTrials<'a> {
    study: &'a LaunchStudy,
    sampler: LaunchScenarioSampler<'a>,
    detectors: Vec<DesignedDetector>,
}

impl<'a> LaunchTrials<'a> {
    /// Designs every detector on the study's vehicle (no gusts, no noise) and calibrates its loss
    /// table; an error names the detector.
    pub fn new(study: &'a LaunchStudy) -> Result<Self, String> {
        let detectors = study
            .detectors
            .iter()
            .map(|d| {
                let design = Arc::new(d.params.design(&study.config).map_err(|e| format!("detector {}: {e}", d.name))?);
                let table = LossTable::calibrate(&design, &study.config, &d.loss_table)
                    .map_err(|e| format!("detector {}: loss table: {e}", d.name))?;
                Ok(DesignedDetector { name: d.name.clone(), design, table })
            })
            .collect::<Result<Vec<_>, String>>()?;
        Ok(LaunchTrials { study, sampler: LaunchScenarioSampler::new(study), detectors })
    }

    /// Trial `trial`, handing each sample and the detectors' steps to `on_sample`.
    pub fn run_trial_with(&self, trial: u64, on_sample: impl FnMut(&Measurement, &[MheStep])) -> LaunchTrialResult {
        let spec = self.sampler.spec(trial);
        let config = self.sampler.config(&spec);
        let mut rng = noise_rng(self.study.header.seed, self.sampler.noise_trial(trial), Substream::SensorNoise);
        let (duration_s, window_s) = (self.study.header.duration_s, self.study.monte_carlo.common.detection_window_s);
        let profile = self.study.monte_carlo.common.profile;
        let outcome =
            run_detectors(&config, &spec, duration_s, window_s, &self.detectors, profile, &mut rng, on_sample);
        LaunchTrialResult { spec, outcome }
    }
}

impl TrialSource for LaunchTrials<'_> {
    type Result = LaunchTrialResult;
    fn trial(&self, trial: u64) -> LaunchTrialResult {
        self.run_trial_with(trial, |_, _| ())
    }
    fn manifest(&self) -> Manifest {
        let s = self.study;
        Manifest {
            // A 90 s flight costs about 0.12 s per detector (measured on the bundled deck): 128 make a part
            // file of seconds.
            chunk_trials: 128,
            outputs: (1..=4).map(|e| format!("engine_{e}")).collect(),
            deck_thresholds: s.detectors.iter().map(|d| vec![d.params.threshold_fhat]).collect(),
            fault_size_units: [("thrust_loss".to_string(), "percent of one engine's thrust".to_string())].into(),
            fault_size_bins: (s.monte_carlo.loss_percent.iter())
                .map(|f| ("thrust_loss".to_string(), f.bin_edges()))
                .filter(|(_, e)| !e.is_empty())
                .collect(),
            ..Manifest::of(KIND, &s.header, &s.monte_carlo.common, s.detectors.iter().map(|d| d.name.as_str()))
        }
    }
    fn frame(&self, results: &[LaunchTrialResult]) -> polars::prelude::PolarsResult<polars::prelude::DataFrame> {
        records::frame(self.study, results)
    }
}
