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
    pub truth: Option<TruthSection>,
    pub controller: Option<ControllerSection>,
    #[serde(default)]
    pub excitation: Vec<ExcitationSection>,
    pub noise: NoiseSection,
    pub detector: Vec<DetectorSection>,
    #[serde(default)]
    pub faults: Vec<FaultSection>,
    pub monte_carlo: Option<crate::engine::scenario::deck::MonteCarloSection>,
}

impl Deck {
    /// The deck flies an FMU (truth, controller or detector): loading it runs the FMU in this process,
    /// and its residual's law is not the linear model's.
    pub fn flies_fmu(&self) -> bool {
        self.truth.is_some()
            || self.controller.as_ref().is_some_and(|c| c.fmu.is_some())
            || self.detector.iter().any(|d| d.fmu.is_some())
    }
}

/// Matrices are lists of rows.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlantSection {
    pub states: Vec<String>,
    pub inputs: Vec<String>,
    pub outputs: Vec<String>,
    /// Required unless `[truth] linearise = true` gives them.
    pub a: Option<Vec<Vec<f64>>>,
    pub b: Option<Vec<Vec<f64>>>,
    pub c: Option<Vec<Vec<f64>>>,
    pub d: Option<Vec<Vec<f64>>>,
    pub initial_state: Option<Vec<f64>>,
}

/// An FMU as the true plant: `[plant]` is then the linear model in deviations from the FMU's trim (the
/// detectors' design model and the loop's coordinates).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TruthSection {
    /// The FMU file, relative to the deck's folder.
    pub fmu: String,
    /// `model_exchange` or `co_simulation`.
    pub interface: String,
    /// The FMU input each `[plant]` input drives.
    pub inputs: Vec<String>,
    /// The FMU output each `[plant]` output reads.
    pub outputs: Vec<String>,
    /// The FMU inputs' values at the trim; the plant's inputs are deviations from them.
    pub trim_inputs: Vec<f64>,
    /// FMU parameters set before initialisation in every trial (the trim's initial state among them).
    #[serde(default)]
    pub parameters: std::collections::BTreeMap<String, f64>,
    /// `[plant]`'s a, b, c, d from the FMU's linearisation at the trim (model exchange) instead of the deck.
    #[serde(default)]
    pub linearise: bool,
    /// `[plant]`'s a, b, c, d identified from the FMU's pulse responses about the trim (any interface;
    /// what a co-simulation-only FMU has), as many states as `[plant] states` names.
    #[serde(default)]
    pub identify: bool,
    /// FMU inputs the model implements faults with (e.g. a loss of effectiveness), which actuator
    /// faults may target (`input = "..."`); healthy: their start values.
    #[serde(default)]
    pub fault_inputs: Vec<String>,
    /// `[truth.trim]`: the trim solved on the FMU instead of given.
    pub trim: Option<TrimSection>,
    /// Model exchange: fdimc's RK4 step (s), at most `dt_s` (rounded down to `dt_s / k`). By default
    /// `|lambda| h <= 0.1` for the fastest mode of the linearisation at the trim.
    pub integrator_step_s: Option<f64>,
    /// The FMU is meant to start off an equilibrium (no warning from `validate` and `run`).
    #[serde(default)]
    pub transient_start: bool,
    /// A trial's truth diverged when an output strays from `[plant]`'s prediction for the same inputs by
    /// more than this many times (the prediction's largest magnitude so far + the output's scale); by
    /// default [`crate::fmu::plant::STRAY_FACTOR`], `inf` never.
    pub stray_factor: Option<f64>,
}

/// The FMU inputs and parameters the engine adjusts (from their deck values) until the variables
/// `zero` are zero after initialisation.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrimSection {
    pub free: Vec<String>,
    pub zero: Vec<String>,
    pub tolerance: Option<f64>,
}

/// The model the detector is designed on and runs, when it differs from the true plant.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DesignModelSection {
    pub a: Option<Vec<Vec<f64>>>,
    pub b: Option<Vec<Vec<f64>>>,
}

/// The loop: `u = u_excitation - G y_measured` (`output_feedback`), or a controller FMU (`fmu`).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ControllerSection {
    pub output_feedback: Option<Vec<Vec<f64>>>,
    /// A co-simulation FMU, relative to the deck's folder; it sees the measured outputs and drives the
    /// inputs as absolute values (plus their trims), and sees the commands as deviations.
    pub fmu: Option<String>,
    /// Controller input = measured plant output (`{ controller_input = "plant_output" }`).
    #[serde(default)]
    pub measured: std::collections::BTreeMap<String, String>,
    /// Controller input = the excitation on a plant input, the command (`{ controller_input = "plant_input" }`).
    #[serde(default)]
    pub commands: std::collections::BTreeMap<String, String>,
    /// Plant input = controller output (`{ controller_output = "plant_input" }`); an input no output
    /// drives gets its excitation.
    #[serde(default)]
    pub drives: std::collections::BTreeMap<String, String>,
    /// Controller parameters set before initialisation.
    #[serde(default)]
    pub parameters: std::collections::BTreeMap<String, f64>,
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
    /// `"gaussian"` (default) or `"student_t(N)"`, for every output or one per output.
    pub sensor_law: Option<toml::Value>,
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
    /// `kind = "fmu"`: the detector's co-simulation FMU (relative to the deck's folder), what it sees
    /// (`{ fmu_input = "plant_output" }`, `{ fmu_input = "plant_input" }`), its statistic output, its
    /// isolated-channel output and the outputs its channels 1, 2, ... name, and its parameters.
    pub fmu: Option<String>,
    #[serde(default)]
    pub measured: std::collections::BTreeMap<String, String>,
    #[serde(default)]
    pub applied: std::collections::BTreeMap<String, String>,
    pub statistic: Option<String>,
    pub isolated_channel: Option<String>,
    pub channels: Option<Vec<String>>,
    #[serde(default)]
    pub parameters: std::collections::BTreeMap<String, f64>,
    pub isolation_delay_s: Option<f64>,
    pub isolation_window_s: Option<f64>,
}
