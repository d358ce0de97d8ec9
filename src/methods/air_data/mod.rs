//! Air-data studies (method 002): the dual-model UKF detector of air-data sensor faults.

pub mod airframe;
pub mod commands;
pub mod dual_ukf;
pub mod flight;
pub mod records;
pub mod scenario;
pub mod study;
pub mod trial;
pub mod voting;

use crate::engine::method::Method;
use crate::engine::report::{OwnPlot, TracePanel};
use crate::engine::results::summary_spec::{Extra, Isolates, SummarySpec};
use crate::engine::run::runner::{Manifest, RunError, TrialSource};
use crate::engine::scenario::deck::FromDeck;
use crate::engine::scenario::streams::{Substream, noise_rng};
use crate::methods::air_data::flight::{AIR_DATA_CHANNEL_NAMES, AirDataSample};
use crate::methods::air_data::scenario::AirDataScenarioSampler;
use crate::methods::air_data::study::AirDataStudy;
use trial::*;

/// `manifest.json`'s kind of these studies.
pub const KIND: &str = "air_data";

/// Method 002: the registry's entry.
pub static METHOD: Method = Method {
    kind: KIND,
    marker: "flight",
    title: "dual-model UKF on air-data sensors, chi-square isolation (method 002)",
    options: study::OPTIONS,
    load: |text, path| Ok(Box::new(AirDataStudy::from_toml(text, path)?)),
    summary: SummarySpec {
        extra_keys: &[records::col::GUST_BIN, records::col::FAULTY_LANES],
        isolates: Isolates::Target,
        extras: &[
            Extra::Count { name: "repaired", column: records::col::COVARIANCE_REPAIRS },
            Extra::Quantile {
                name: "bias_error_p50_sigma",
                column: records::col::BIAS_ERROR_RMS_SIGMA,
                p: 0.5,
                abs: false,
            },
            Extra::Quantile {
                name: "estimate_rms_p50_sigma",
                column: records::col::ESTIMATE_RMS_SIGMA,
                p: 0.5,
                abs: false,
            },
            Extra::Quantile { name: "raw_rms_p50_sigma", column: records::col::RAW_RMS_SIGMA, p: 0.5, abs: false },
        ],
        paired_medians: &[],
        printed: &[
            ("bias err σ", "bias_error_p50_sigma"),
            ("air data σ", "estimate_rms_p50_sigma"),
            ("raw σ", "raw_rms_p50_sigma"),
        ],
    },
    report: None,
    trace_panels: &[
        TracePanel { title: "airspeed (m/s)", columns: &["airspeed_mps_*", "*_airspeed_mps_estimate"] },
        TracePanel { title: "angle of attack (rad)", columns: &["alpha_rad_*", "*_alpha_rad_estimate"] },
        TracePanel { title: "sideslip (rad)", columns: &["beta_rad_*", "*_beta_rad_estimate"] },
        TracePanel {
            title: "isolation statistics (chi-square; voting: lane miscompare, sigmas)",
            columns: &["*_test_statistic"],
        },
        TracePanel { title: "P(fault)", columns: &["*_p_fault"] },
    ],
    own_plots: &[OwnPlot::Scatter {
        file: "air_data_error",
        title: "Air-data error after the onset: blended estimate against the raw sensors (sensor sigmas)",
        x: "raw_rms_sigma",
        y: "estimate_rms_sigma",
        diagonal: true,
    }],
    starter: ("studies/ci_seed002.toml", include_str!("../../../studies/ci_seed002.toml")),
    replay_starter: None,
    hour_laws: None,
    flight_thresholds: None,
};

crate::plain_study!(AirDataStudy, monte_carlo.common, |s| Ok::<_, RunError>(AirDataTrials::new(s)),
    sensitivity: |s| scenario::sensitivity_parts(s));

/// The runner's view of an air-data study.
pub struct AirDataTrials<'a> {
    study: &'a AirDataStudy,
    sampler: AirDataScenarioSampler<'a>,
}

impl<'a> AirDataTrials<'a> {
    pub fn new(study: &'a AirDataStudy) -> Self {
        AirDataTrials { study, sampler: AirDataScenarioSampler::new(study) }
    }

    /// Trial `trial`: its scenario from the scenario stream, its sensor noise and gusts from the sensor
    /// stream; every detector on the same samples.
    pub fn run_trial(&self, trial: u64) -> AirDataTrialResult {
        self.run_trial_with(trial, |_, _| ())
    }

    /// [`AirDataTrials::run_trial`] handing each sample and the detectors' steps to `on_sample`.
    pub fn run_trial_with(
        &self,
        trial: u64,
        on_sample: impl FnMut(&AirDataSample, &[DetectorStep]),
    ) -> AirDataTrialResult {
        let spec = self.sampler.spec(trial);
        let mut rng = noise_rng(self.study.header.seed, self.sampler.noise_trial(trial), Substream::SensorNoise);
        let outcome = run_detectors(
            self.sampler.scenario(&spec),
            &spec,
            &self.study.detectors,
            self.study.monte_carlo.common.profile,
            &mut rng,
            on_sample,
        );
        AirDataTrialResult { spec, outcome }
    }
}

impl TrialSource for AirDataTrials<'_> {
    type Result = AirDataTrialResult;
    fn trial(&self, trial: u64) -> AirDataTrialResult {
        self.run_trial(trial)
    }
    fn manifest(&self) -> Manifest {
        let s = self.study;
        let units = s.monte_carlo.faults.iter().map(|f| (f.kind.name().to_string(), f.size_unit().to_string()));
        Manifest {
            // A 60 s flight with two detectors costs about 30 ms: 256 make a part file of a few seconds.
            chunk_trials: 256,
            outputs: AIR_DATA_CHANNEL_NAMES.iter().map(|n| n.to_string()).collect(),
            fault_size_units: units.collect(),
            fault_size_bins: crate::fault::deck::FaultKindSpec::size_bins(&s.monte_carlo.faults),
            deck_thresholds: s.detectors.iter().map(|d| vec![d.alarm_threshold_s(s.header.dt_s)]).collect(),
            ..Manifest::of(KIND, &s.header, &s.monte_carlo.common, s.detectors.iter().map(|d| d.name.as_str()))
        }
    }
    fn frame(&self, results: &[AirDataTrialResult]) -> polars::prelude::PolarsResult<polars::prelude::DataFrame> {
        records::frame(self.study, results)
    }
}
