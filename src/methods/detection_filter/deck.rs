//! The study deck as written in TOML. Parsing only: every check lives in `validate`, which turns a
//! `Deck` into a `Study` that cannot be invalid. Unknown fields are errors, so a typo never silently
//! falls back to a default.

use serde::Deserialize;

use crate::engine::scenario::deck::StudySection;
use crate::fault::deck::FaultSection;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Deck {
    pub study: StudySection,
    pub plant: PlantSection,
    pub design_model: Option<DesignModelSection>,
    pub controller: Option<ControllerSection>,
    #[serde(default)]
    pub excitation: Vec<ExcitationSection>,
    pub noise: NoiseSection,
    pub detector: Vec<DetectorSection>,
    #[serde(default)]
    pub faults: Vec<FaultSection>,
    pub monte_carlo: Option<crate::engine::scenario::deck::MonteCarloSection>,
}

/// Matrices are lists of rows.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlantSection {
    pub states: Vec<String>,
    pub inputs: Vec<String>,
    pub outputs: Vec<String>,
    pub a: Vec<Vec<f64>>,
    pub b: Vec<Vec<f64>>,
    pub c: Vec<Vec<f64>>,
    pub d: Option<Vec<Vec<f64>>>,
    pub initial_state: Option<Vec<f64>>,
}

/// The model the detector is designed on and runs, when it differs from the true plant.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DesignModelSection {
    pub a: Option<Vec<Vec<f64>>>,
    pub b: Option<Vec<Vec<f64>>>,
}

/// `u = u_excitation - G y_measured`: the loop that keeps an open-loop-unstable airframe flying.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ControllerSection {
    pub output_feedback: Vec<Vec<f64>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExcitationSection {
    pub input: String,
    pub shape: String,
    pub amplitude: f64,
    pub period_s: Option<f64>,
    #[serde(default)]
    pub start_s: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NoiseSection {
    pub sensor_sigma: Vec<f64>,
    pub process_sigma_per_step: Option<Vec<f64>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DetectorSection {
    pub name: String,
    pub kind: String,
    pub eigenvalues_per_s: Option<Vec<f64>>,
    pub fault_directions: Option<Vec<Vec<f64>>>,
    pub thresholds: Option<Vec<f64>>,
    /// `kind = "kalman_chi2"`: samples summed, false-alarm probability per window, and the process
    /// noise per step and state the filter is designed for.
    pub window: Option<usize>,
    pub false_alarm_probability: Option<f64>,
    pub design_process_sigma_per_step: Option<Vec<f64>>,
    /// `kind = "cusum"`: the allowance per sample and output.
    pub drift: Option<Vec<f64>>,
    pub isolation_delay_s: Option<f64>,
    pub isolation_window_s: Option<f64>,
}
