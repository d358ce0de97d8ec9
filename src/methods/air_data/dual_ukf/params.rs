//! The dual UKF's parameters, their seed values and checks, and why a detector cannot be built.

use thiserror::Error;

use super::models::{COMPONENTS, MODELS};
use crate::estimation::LikelihoodForm;
use crate::estimation::bank::DecisionLevels;
use crate::estimation::ukf::{UkfError, UnscentedParams};
use crate::methods::air_data::flight::SensorNoise;

/// The detector's parameters; [`DualUkfParams::seed`] documents the defaults.
#[derive(Debug, Clone, PartialEq)]
pub struct DualUkfParams {
    pub unscented: UnscentedParams,
    pub likelihood: LikelihoodForm,
    /// The sensor noise the filters assume: air data for `R`, inertial for `Q`.
    pub noise: SensorNoise,
    /// Velocity random walk for what the kinematics miss (m/s per sqrt(s)).
    pub velocity_random_walk_mps_per_sqrt_s: f64,
    /// Bias random walks: airspeed (m/s per sqrt(s)), alpha and beta (rad per sqrt(s)).
    pub bias_random_walk_per_sqrt_s: [f64; COMPONENTS],
    /// Standard deviation of an open (re-initialised) bias: m/s, rad, rad.
    pub initial_bias_std: [f64; COMPONENTS],
    /// Prior probability of the fault model.
    pub prior_fault_probability: f64,
    /// Floor, declaration (with its hold) and clearance of the fault model's probability.
    pub levels: DecisionLevels,
    /// Allowed false-alarm probability of one component's isolation test.
    pub false_alarm_probability: f64,
    /// Samples summed in the isolation statistic (1: the patent's per-sample test).
    pub isolation_window: usize,
    /// Not in the patent: a component stays in the faulty set while its bias estimate passes a Wald
    /// test (module docs, step 4); false: the faulty set is this step's isolation alone.
    pub keep_significant_biases: bool,
}

impl DualUkfParams {
    /// Defaults; the patent gives no number, so all are choices:
    /// - unscented `alpha = 1, beta = 2, kappa = 0` ([`UnscentedParams::seed`]); Gaussian likelihood
    ///   (the patent's "conditional probability density");
    /// - the assumed noise equals the generator's ([`SensorNoise::seed`]): a matched design;
    /// - velocity random walk 0.02 m/s/sqrt(s): a sixth of what the 0.1 deg/s gyro noise already puts in
    ///   at 70 m/s (0.12 m/s/sqrt(s) at 100 Hz), a margin for integration error and light turbulence;
    /// - bias random walks 0.01 m/s/sqrt(s) and 0.01 deg/sqrt(s): an estimated bias stays put over a
    ///   trial (0.08 m/s, 0.08 deg in a minute) yet can follow a slow change;
    /// - open bias 3 m/s, 2 deg, 2 deg: the size of the faults the studies look for. A larger value
    ///   costs the fault model `0.5 ln(1 + sigma_b^2 / S)` per component and step in fault-free flight
    ///   and so slows the detection of small faults; a smaller one fits large faults less well;
    /// - prior fault probability 0.01, floor 0.001 (seed 004's), declare 0.9 held 0.1 s, clear 0.05
    ///   (seed 004's decision numbers);
    /// - `P_fa` = 0.001 per component and sample (threshold 10.83), per-sample test (the patent's form);
    /// - the faulty set is the isolation of each step (the patent's rule; no Wald test).
    pub fn seed() -> Self {
        DualUkfParams {
            unscented: UnscentedParams::seed(),
            likelihood: LikelihoodForm::Gaussian,
            noise: SensorNoise::seed(),
            velocity_random_walk_mps_per_sqrt_s: 0.02,
            bias_random_walk_per_sqrt_s: [0.01, 0.01f64.to_radians(), 0.01f64.to_radians()],
            initial_bias_std: [3.0, 2f64.to_radians(), 2f64.to_radians()],
            prior_fault_probability: 0.01,
            levels: DecisionLevels::seed(),
            false_alarm_probability: 0.001,
            isolation_window: 1,
            keep_significant_biases: false,
        }
    }

    /// Checks every field (the constructors of the building blocks panic on invalid numbers).
    pub fn validate(&self) -> Result<(), DualUkfError> {
        let bad = |field: &'static str, value: f64, requirement: &'static str| {
            Err(DualUkfError::InvalidParameter { field, value, requirement })
        };
        let n = &self.noise;
        for (field, value) in [
            ("noise.airspeed_std_mps", n.airspeed_std_mps),
            ("noise.alpha_std_rad", n.alpha_std_rad),
            ("noise.beta_std_rad", n.beta_std_rad),
            ("bias_random_walk_per_sqrt_s[0]", self.bias_random_walk_per_sqrt_s[0]),
            ("bias_random_walk_per_sqrt_s[1]", self.bias_random_walk_per_sqrt_s[1]),
            ("bias_random_walk_per_sqrt_s[2]", self.bias_random_walk_per_sqrt_s[2]),
            ("initial_bias_std[0]", self.initial_bias_std[0]),
            ("initial_bias_std[1]", self.initial_bias_std[1]),
            ("initial_bias_std[2]", self.initial_bias_std[2]),
        ] {
            if !(value > 0.0 && value.is_finite()) {
                return bad(field, value, "positive and finite");
            }
        }
        for (field, value) in [
            ("noise.gyro_std_rad_s", n.gyro_std_rad_s),
            ("noise.accelerometer_std_mps2", n.accelerometer_std_mps2),
            ("noise.attitude_std_rad", n.attitude_std_rad),
            ("velocity_random_walk_mps_per_sqrt_s", self.velocity_random_walk_mps_per_sqrt_s),
        ] {
            if !(value >= 0.0 && value.is_finite()) {
                return bad(field, value, "non-negative and finite");
            }
        }
        if let Err((field, value, requirement)) = self.levels.check(MODELS) {
            return bad(field, value, requirement);
        }
        let (prior, floor) = (self.prior_fault_probability, self.levels.probability_floor);
        if !(prior >= floor && 1.0 - prior >= floor) {
            return bad("prior_fault_probability", prior, "in [floor, 1 - floor]");
        }
        let pfa = self.false_alarm_probability;
        if !(pfa > 0.0 && pfa < 1.0) {
            return bad("false_alarm_probability", pfa, "in (0, 1)");
        }
        if !(1..=MAX_ISOLATION_WINDOW).contains(&self.isolation_window) {
            return bad("isolation_window", self.isolation_window as f64, "from 1 to 10000 samples");
        }
        self.unscented.weights(6)?;
        Ok(())
    }
}

/// Longest isolation window, samples: 100 s at the seed's 100 Hz, a thousand times the longest studied (10);
/// the detector holds a threshold and a history row per sample of it (a mistyped huge window hung the
/// deck's validation building them).
pub const MAX_ISOLATION_WINDOW: usize = 10_000;

impl Default for DualUkfParams {
    fn default() -> Self {
        Self::seed()
    }
}

/// Why a detector cannot be built.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum DualUkfError {
    #[error("{field} = {value}: must be {requirement}")]
    InvalidParameter { field: &'static str, value: f64, requirement: &'static str },
    #[error("sample period dt_s = {0} must be positive and finite")]
    SamplePeriod(f64),
    #[error(transparent)]
    Unscented(#[from] UkfError),
}
