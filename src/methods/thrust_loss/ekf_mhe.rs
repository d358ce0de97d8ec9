//! Method 001: launch-vehicle thrust-loss detection by an EKF residual on the pitch rate and a
//! moving-horizon generalised-least-squares (GLS) fault estimator, with the loss converted to a
//! percentage by a linear fit and the faulty engine named by the signs of the lateral-overload jumps
//! (Ye, Chen, Xiong, Beijing Institute of Aerospace Automatic Control; `docs/findings-seed001.md`).
//!
//! # Residual
//! An EKF ([`Stekf`]`<13, 12>`, no fading, Joseph-form update) on the 13-state model of
//! [`crate::methods::thrust_loss::vehicle`] (`[P, vx, vy, vz, wx, wy, wz, x, y, z, phi, psi, gamma]`), measuring
//! the 12 states other than the thrust (`H = [0 I]`). Its model ([`FilterModel`]): all four engines at
//! `P / 4`, the nominal mass schedule, the thrust's nominal altitude law, and the measured gimbal
//! positions as input; one RK4 step per sample. The transition Jacobian is
//! `I + A dt + (A dt)^2 / 2` with `A` the exact Jacobian of the continuous dynamics at `x(k|k)`, from one
//! evaluation on dual numbers, which also gives the first RK4 stage (exact to second order in `dt`). The
//! residual is the innovation of the pitch rate, `r(k) = wz_measured(k) - wz(k|k-1)` (rad/s).
//!
//! That filter has no state for a loss's moment (its model holds the four engines equal), so a loss
//! leaves a lasting step in the residual. The seed's residual recovers ("after the detection the jump
//! returns to normal"): [`EkfParams::moment_bias_sigma_rad_s2_per_sqrt_s`] adds an angular-acceleration
//! bias per body axis ([`AUGMENTED`] states, random walks), which follows the moment, so the jump
//! clears within a time set by the walk's rate (about 0.05 s at 0.1 rad/s^2/sqrt(s), 0.15 s at 0.01).
//!
//! # Moving-horizon GLS
//! The window `Y(k) = [r(k - N D), r(k - (N-1) D), ..., r(k)]'` (N + 1 samples at interval D). The
//! seed linearises `Y(f) = Y(0) + S f` with the sensitivity `S` obtained by finite difference with a
//! unit fault `e` of 1 % thrust loss, and with `e_w ~ N(0, V)`, `f ~ N(0, R)` estimates
//! `fhat = (S' V^-1 S + R^-1)^-1 S' V^-1 (Y - Y0)`, `V = I`, `R = F^2` ([`gls_fault_estimate`]). `f` and
//! `F` are counted in unit faults, so `fhat = 30` reads "thirty 1 % losses".
//!
//! Where the seed is silent, and how it is done here ([`DetectorParams::design`]):
//! - Time alignment. A fault's residual signature depends on the time since its onset, and an online
//!   estimator does not know the onset. Each window is read as "a fault began just before this
//!   window": `S_j` is the residual response `j D` samples after the first sample that feels a 1 %
//!   loss (the sample after the onset). So `fhat(k)` is a matched filter for a fault starting at
//!   sample `k - N D`.
//! - Finite difference, offline, on the nominal model. One noise-free nominal flight (truth, controller
//!   and this EKF) is flown; at each onset of a grid ([`CalibrationGrid`], default every 5 s) it is
//!   branched with a 1 % loss on the reference engine, and
//!   `S_j(t_c) = r_branch(k_c + 1 + j D) - r_nominal(k_c + 1 + j D)` (per unit fault). Online, `S` is
//!   interpolated linearly in the hypothesised onset time (clamped at the grid ends, counted).
//! - `Y0` is the nominal flight's residual at the window's samples (numerically zero when the filter's
//!   model is the truth's, but kept so that a design model that differs from the nominal truth is
//!   handled as the seed writes it).
//! - Engine sign. A loss on engines {1, 4} (`y1 > 0`) pitches the nose up, on {2, 3} down: the pitch-rate
//!   residual of one pair is the mirror image of the other's. `S` is computed for the reference engine
//!   (engine 1), so `fhat` is negative for engines 2 and 3; detection and the loss conversion use
//!   `|fhat|`.
//! - `V = v I` with `v` a parameter: the seed's `V = I` is `v = 1` with the residual in rad/s. The
//!   residual's own variance is about `8.7e-8 (rad/s)^2`, so with `V = I` the prior term `1/R`
//!   dominates `S'S` (`~2e-10` per unit fault squared) for every `R` up to `500^2`, and
//!   `fhat ~ R S'(Y - Y0)`: a correlation scaled by `R`. Setting `v` to the residual variance makes the
//!   estimate a proper MAP estimate, in which `R` trades prior and data as the seed describes.
//!
//! # What comes out of the seed's findings here
//! (measured; tests `window_length_and_fault_intensity_as_they_come_out_here`,
//! `fhat_peak_grows_linearly_with_the_loss`)
//! - With the plain filter the residual of a permanent loss is a step that ramps up over ~0.3 s and
//!   stays: `fhat` plateaus near its peak instead of recovering, for every `N`, and the peak-to-noise
//!   ratio grows with `N` (11.9, 19.8, 27.3 for 1, 5, 10).
//! - With the recovering filter (`the_recovering_residual_clears_and_shows_the_seeds_window_trade`) the
//!   jump clears, and the seed's "a smaller N loses amplitude" appears (peak-to-noise 0.59, 1.16, 1.17
//!   at 0.1 rad/s^2/sqrt(s)); its "a larger N recovers in fewer beats" does not; and a jump that clears
//!   carries a twentieth of the step's peak-to-noise.
//! - `R`: with `V = I` it only scales `fhat` (same peak-to-noise); with `V` the residual variance, the
//!   peak grows with `R` and saturates, with no second rise.
//! - The peak of `fhat` is linear in the loss (R^2 = 0.9995 over 10-60 %), as the seed reports.
//!
//! # Detection, loss, localisation
//! An alarm is `|fhat| >= threshold` ([`DetectorParams::threshold_fhat`]). From the first alarm on, the
//! running peak of `|fhat|` is converted to a loss percentage by the linear fit `loss = a + b fhat_peak`
//! ([`LossFit`], fitted from calibration runs by [`MheDesign::calibrate_loss_fit`], the seed's eq. 27; the
//! seed's table over onset time is `trial.rs`'s `LossTable`, one fit per onset). At the first alarm the
//! onset is located as the largest
//! step of the overloads within the last second, the jumps are
//! `mean(n over post samples after the onset) - mean(n over pre samples up to it)`
//! ([`LocalisationParams`]), and their signs name the engine ([`localise`]): `n_y` alike for {1, 4} and
//! for {2, 3}, `n_z` alike for {1, 2} and for {3, 4}, as the seed's table.
//!
//! Numerical trouble is counted ([`DetectorHealth`]), never a panic.
#![allow(non_snake_case)]

use std::collections::VecDeque;
use std::sync::Arc;

use nalgebra::{SMatrix, SVector};

use crate::dual::{Real, value_and_jacobian};
use crate::engine::scenario::noise::NoiseRng;
use crate::engine::scenario::streams::{Substream, noise_rng};
use crate::estimation::{DiscreteModel, Fading, FilterHealth, Stekf};
use crate::methods::thrust_loss::vehicle::{
    ENGINES, Gimbals, LaunchVehicleConfig, LaunchVehicleError, MEASURED, Measured, Measurement, STATES, SensorNoise,
    State, ThrustFault, Vehicle, VehicleParams, expected_jump_signs, filter_derivatives, idx, rk4, rk4_from,
};

/// The unit fault `f` is counted in: a 1 % thrust loss of one engine (the seed's `e`).
pub const UNIT_FAULT: f64 = 0.01;

/// Index of the pitch rate `wz` in the measurement vector.
pub const PITCH_RATE_MEASUREMENT: usize = idx::WZ - 1;

/// The filter's input at a sample: its time and the gimbal positions held over the coming step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FilterInput {
    pub t_s: f64,
    pub gimbals: Gimbals,
}

impl FilterInput {
    pub fn new(t_s: f64, gimbal_rad: [f64; ENGINES]) -> Self {
        FilterInput { t_s, gimbals: Gimbals::new(gimbal_rad) }
    }
}

/// The EKF's model of the vehicle (module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct FilterModel {
    pub params: VehicleParams,
    pub dt_s: f64,
}

impl DiscreteModel<STATES, MEASURED> for FilterModel {
    type Input = FilterInput;

    fn transition(&self, x: &State, u: &FilterInput) -> State {
        rk4(x, u.t_s, self.dt_s, |t_s, x| filter_derivatives(&self.params, x, t_s, &u.gimbals))
    }

    fn measurement(&self, x: &State) -> Measured {
        x.fixed_rows::<MEASURED>(1).into_owned()
    }

    fn transition_jacobian(&self, x: &State, u: &FilterInput) -> SMatrix<f64, STATES, STATES> {
        self.transition_with_jacobian(x, u).1
    }

    /// RK4 and `I + A dt + (A dt)^2 / 2` with `A = df/dx` exact: one evaluation on dual numbers gives `A`
    /// and the first RK4 stage.
    fn transition_with_jacobian(&self, x: &State, u: &FilterInput) -> (State, SMatrix<f64, STATES, STATES>) {
        let (k1, A) = value_and_jacobian(x, |x| filter_derivatives(&self.params, x, u.t_s, &u.gimbals));
        let next = rk4_from(x, k1, u.t_s, self.dt_s, |t_s, x| filter_derivatives(&self.params, x, t_s, &u.gimbals));
        (next, second_order_transition(&A, self.dt_s))
    }

    fn measured_states(&self) -> Option<[usize; MEASURED]> {
        Some(std::array::from_fn(|i| i + 1))
    }
}

/// States of the recovering filter: the vehicle's 13 and an angular-acceleration bias per body axis
/// (`[.., bx, by, bz]`, rad/s^2), random walks added to the body rates' derivatives.
pub const AUGMENTED: usize = STATES + 3;

/// The filter model with the angular-acceleration biases ([`AUGMENTED`]): a thrust loss's moment, which
/// the plain model cannot express (it holds the four engines equal), is followed by the biases, so the
/// pitch-rate innovation returns to zero once they have converged (the seed's recovering jump).
struct WithMomentStates<'a>(&'a FilterModel);

/// `Phi = I + A dt + (A dt)^2 / 2` from the continuous Jacobian `A`.
fn second_order_transition<const N: usize>(A: &SMatrix<f64, N, N>, dt_s: f64) -> SMatrix<f64, N, N> {
    let Adt = A * dt_s;
    SMatrix::identity() + Adt + Adt * Adt * 0.5
}

impl WithMomentStates<'_> {
    fn derivatives<T: Real>(&self, x: &SVector<T, AUGMENTED>, t_s: f64, gimbals: &Gimbals) -> SVector<T, AUGMENTED> {
        let vehicle: SVector<T, STATES> = x.fixed_rows::<STATES>(0).into_owned();
        let mut dx = SVector::<T, AUGMENTED>::zeros();
        dx.fixed_rows_mut::<STATES>(0).copy_from(&filter_derivatives(&self.0.params, &vehicle, t_s, gimbals));
        for axis in 0..3 {
            dx[idx::WX + axis] += x[STATES + axis];
        }
        dx
    }
}

impl DiscreteModel<AUGMENTED, MEASURED> for WithMomentStates<'_> {
    type Input = FilterInput;

    fn transition(&self, x: &SVector<f64, AUGMENTED>, u: &FilterInput) -> SVector<f64, AUGMENTED> {
        rk4(x, u.t_s, self.0.dt_s, |t_s, x| self.derivatives(x, t_s, &u.gimbals))
    }

    fn measurement(&self, x: &SVector<f64, AUGMENTED>) -> Measured {
        x.fixed_rows::<MEASURED>(1).into_owned()
    }

    fn transition_jacobian(&self, x: &SVector<f64, AUGMENTED>, u: &FilterInput) -> SMatrix<f64, AUGMENTED, AUGMENTED> {
        self.transition_with_jacobian(x, u).1
    }

    /// As [`FilterModel`]'s: one evaluation on dual numbers for `A` and the first RK4 stage.
    fn transition_with_jacobian(
        &self,
        x: &SVector<f64, AUGMENTED>,
        u: &FilterInput,
    ) -> (SVector<f64, AUGMENTED>, SMatrix<f64, AUGMENTED, AUGMENTED>) {
        let (k1, A) = value_and_jacobian(x, |x| self.derivatives(x, u.t_s, &u.gimbals));
        let next = rk4_from(x, k1, u.t_s, self.0.dt_s, |t_s, x| self.derivatives(x, t_s, &u.gimbals));
        (next, second_order_transition(&A, self.0.dt_s))
    }

    fn measured_states(&self) -> Option<[usize; MEASURED]> {
        Some(std::array::from_fn(|i| i + 1))
    }
}

/// The filter whose pitch-rate innovation is the residual: the plain 13-state EKF (a loss leaves a
/// lasting step) or the one with angular-acceleration biases (the step recovers).
#[derive(Debug, Clone)]
#[allow(clippy::large_enum_variant)] // one per detector and trial, stepped in place: no box in the hot loop
enum ResidualFilter {
    Plain(Stekf<STATES, MEASURED>),
    Recovering(Stekf<AUGMENTED, MEASURED>),
}

impl ResidualFilter {
    /// The pitch-rate innovation of one filter step (rad/s).
    fn pitch_rate_residual(&mut self, model: &FilterModel, m: &Measurement) -> f64 {
        let input = FilterInput::new(m.t_s, m.gimbal_rad);
        let gamma = match self {
            ResidualFilter::Plain(f) => f.step(model, &m.y, &input).gamma,
            ResidualFilter::Recovering(f) => f.step(&WithMomentStates(model), &m.y, &input).gamma,
        };
        gamma[PITCH_RATE_MEASUREMENT]
    }

    fn health(&self) -> FilterHealth {
        match self {
            ResidualFilter::Plain(f) => f.health(),
            ResidualFilter::Recovering(f) => f.health(),
        }
    }
}

/// EKF tuning: standard deviations per state (process noise as intensities per square-root second, so
/// that a step of `dt` adds `sigma^2 dt`), per measurement, and of the initial estimate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EkfParams {
    /// Defaults, state order: thrust 2e4 N/sqrt(s) (lets the filter follow a thrust change of a few
    /// percent within a second); velocities 0.05 m/s/sqrt(s) (the Coriolis acceleration the launch frame
    /// leaves out, `2 Omega v`, is ~0.05 m/s^2 at 350 m/s); body rates 1e-4 rad/s/sqrt(s) (the filter
    /// trusts its rotational model: 1e-5 rad/s per 0.01 s step, a thirtieth of the gyro noise, so that an
    /// unmodelled moment accumulates in the residual over ~0.3 s instead of being followed at once);
    /// positions 1e-3 m/sqrt(s) and attitude 1e-5 rad/sqrt(s) (integrals of the above).
    pub process_sigma_per_sqrt_s: [f64; STATES],
    /// The sensors' standard deviations ([`SensorNoise::measured_sigma`]).
    pub measurement_sigma: [f64; MEASURED],
    /// Initial estimate's standard deviations: thrust 1 % of the lift-off thrust (30 kN), the others
    /// the measurement's.
    pub initial_sigma: [f64; STATES],
    /// Joseph-form covariance update (the seed's eq. 11); on by default.
    pub joseph: bool,
    /// `None` (default): the plain 13-state filter, whose residual keeps a lasting step after a loss.
    /// `Some(sigma)`: the recovering filter ([`AUGMENTED`]) with angular-acceleration biases walking at
    /// `sigma` rad/s^2 per square-root second, initially zero with that standard deviation over 1 s.
    pub moment_bias_sigma_rad_s2_per_sqrt_s: Option<f64>,
}

impl EkfParams {
    /// The defaults (field docs) for sensors with noise `noise`.
    pub fn for_noise(noise: &SensorNoise) -> Self {
        let measurement_sigma = noise.measured_sigma();
        let mut initial_sigma = [0.0; STATES];
        initial_sigma[idx::THRUST] = 3.0e4;
        initial_sigma[1..].copy_from_slice(&measurement_sigma);
        let (v, w, r, a) = (0.05, 1e-4, 1e-3, 1e-5);
        EkfParams {
            process_sigma_per_sqrt_s: [2.0e4, v, v, v, w, w, w, r, r, r, a, a, a],
            measurement_sigma,
            initial_sigma,
            joseph: true,
            moment_bias_sigma_rad_s2_per_sqrt_s: None,
        }
    }

    fn filter(&self, x0: State, dt_s: f64) -> ResidualFilter {
        let R = SMatrix::from_diagonal(&SVector::from(self.measurement_sigma.map(|s| s * s)));
        let Some(bias_sigma) = self.moment_bias_sigma_rad_s2_per_sqrt_s else {
            let P0 = SMatrix::from_diagonal(&SVector::from(self.initial_sigma.map(|s| s * s)));
            let Q = SMatrix::from_diagonal(&SVector::from(self.process_sigma_per_sqrt_s.map(|s| s * s * dt_s)));
            let f = Stekf::new(x0, P0, Q, R, Fading::None);
            return ResidualFilter::Plain(if self.joseph { f.with_joseph_update() } else { f });
        };
        let augmented = |vehicle: &[f64; STATES], bias: f64| {
            SVector::<f64, AUGMENTED>::from_fn(|i, _| if i < STATES { vehicle[i] } else { bias })
        };
        let mut x = SVector::<f64, AUGMENTED>::zeros();
        x.fixed_rows_mut::<STATES>(0).copy_from(&x0);
        let P0 = SMatrix::from_diagonal(&augmented(&self.initial_sigma, bias_sigma).map(|s| s * s));
        let Q = SMatrix::from_diagonal(&augmented(&self.process_sigma_per_sqrt_s, bias_sigma).map(|s| s * s * dt_s));
        let f = Stekf::new(x, P0, Q, R, Fading::None);
        ResidualFilter::Recovering(if self.joseph { f.with_joseph_update() } else { f })
    }
}

impl Default for EkfParams {
    fn default() -> Self {
        Self::for_noise(&SensorNoise::default())
    }
}

/// The moving-horizon GLS estimator's parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MheParams {
    /// `N`: the window holds `N + 1` samples. Seed: 5 (of 1, 5, 10).
    pub window_n: usize,
    /// `D` in samples of the plant step. Seed: `D = 0.01 s`, one sample at the default step.
    pub interval_samples: usize,
    /// `F`, the expected fault intensity in unit faults; `R = F^2`. Seed: 20 (of 20-50).
    pub fault_intensity: f64,
    /// `v` in `V = v I`. Seed: 1 (`V = I`, residual in rad/s); module docs.
    pub window_variance: f64,
    /// The loss fraction of the finite difference: 0.01 (one [`UNIT_FAULT`]), the seed's; `S` is always
    /// per unit fault.
    pub unit_loss_fraction: f64,
    /// Engine the sensitivity is computed for: index 0, the seed's engine 1.
    pub reference_engine: usize,
}

impl MheParams {
    /// The seed's choices: N = 5, D = 1 sample, F = 20, V = I, 1 % unit fault, engine 1.
    pub fn seed() -> Self {
        MheParams {
            window_n: 5,
            interval_samples: 1,
            fault_intensity: 20.0,
            window_variance: 1.0,
            unit_loss_fraction: 0.01,
            reference_engine: 0,
        }
    }

    /// `R = F^2`.
    pub fn R(&self) -> f64 {
        self.fault_intensity * self.fault_intensity
    }

    /// Samples the window spans, first to last: `N D + 1`.
    pub fn span_samples(&self) -> usize {
        self.window_n * self.interval_samples + 1
    }
}

impl Default for MheParams {
    fn default() -> Self {
        Self::seed()
    }
}

/// Onset estimate and overload averaging for localisation.
///
/// At the first alarm the onset is located in the overloads themselves: among the samples of the last
/// `max_lookback_samples` before the alarm, the one after which the step
/// `(mean over the next post_samples) - (mean over the pre_samples up to it)` of `(n_y, n_z)` is largest
/// in norm. That step's signs name the engine. The overloads step at once at the onset (the fault
/// moment's angular acceleration at the IMU's lever arm: 9.7e-3 g in each for a 30 % loss, 11 times the
/// sensor noise), then settle by about a third as the gimbals take the moment; the residual, by
/// contrast, ramps up over ~0.3 s, so `fhat` dates the onset only to within a tenth of a second, and
/// a reference taken after the true onset can reverse the jump's sign.
///
/// Defaults: look back 100 samples (1 s; the default estimator alarms within 0.3 s of a 30 % loss),
/// 10 samples before and 3 after: with 8.5e-4 g sensor noise a step's noise is 5.6e-4 g, against the
/// 3.2e-3 g in each a 10 % loss produces.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalisationParams {
    pub max_lookback_samples: usize,
    pub pre_samples: usize,
    pub post_samples: usize,
}

impl Default for LocalisationParams {
    fn default() -> Self {
        LocalisationParams { max_lookback_samples: 100, pre_samples: 10, post_samples: 3 }
    }
}

/// Onsets (s) at which the sensitivity is computed: `first, first + spacing, ...` up to `last`.
/// Default 0 s to 130 s every 5 s (first-stage burnout is at 140 s).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CalibrationGrid {
    pub first_onset_s: f64,
    pub spacing_s: f64,
    pub last_onset_s: f64,
}

impl Default for CalibrationGrid {
    fn default() -> Self {
        CalibrationGrid { first_onset_s: 0.0, spacing_s: 5.0, last_onset_s: 130.0 }
    }
}

impl CalibrationGrid {
    fn onsets_s(&self) -> Vec<f64> {
        let count = ((self.last_onset_s - self.first_onset_s) / self.spacing_s + 1e-9).floor() as usize + 1;
        (0..count).map(|i| self.first_onset_s + i as f64 * self.spacing_s).collect()
    }
}

/// Everything the detector is built from.
#[derive(Debug, Clone, PartialEq)]
pub struct DetectorParams {
    pub ekf: EkfParams,
    pub mhe: MheParams,
    pub localisation: LocalisationParams,
    pub grid: CalibrationGrid,
    /// Alarm when `|fhat| >= threshold_fhat`. Default 1.3e-5 for the seed's N, F, V with the default
    /// vehicle and sensors: 1.5 times the largest `|fhat|` of twenty fault-free 60-s noisy flights
    /// (ChaCha8 seeds 0-19: 8.75e-6; the fault-free `fhat` has a standard deviation of about 2e-6). A
    /// noise-free loss at 20 s peaks at 5.9e-6 (10 %), 1.7e-5 (30 %), 2.7e-5 (50 %). On 160 noisy flights
    /// per size with onsets over 15-75 s, alarms within 1.5 s of the onset: 10 % 58/160, 15 % 127/160,
    /// 20 % and up 160/160. It scales with `R` and `1/v` and grows with `N`: recalibrate when they change
    /// (the runner calibrates thresholds from fault-free trials anyway).
    pub threshold_fhat: f64,
}

impl DetectorParams {
    /// The seed's estimator ([`MheParams::seed`]) with the default filter, localisation and grid.
    pub fn seed() -> Self {
        DetectorParams {
            ekf: EkfParams::default(),
            mhe: MheParams::seed(),
            localisation: LocalisationParams::default(),
            grid: CalibrationGrid::default(),
            threshold_fhat: 1.3e-5,
        }
    }
}

impl Default for DetectorParams {
    fn default() -> Self {
        Self::seed()
    }
}

/// Why a design could not be made; a value, never a panic.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DesignError {
    #[error("invalid {field}: {value} (allowed: {allowed})")]
    Invalid { field: &'static str, value: f64, allowed: &'static str },
    #[error("calibration flight failed: {0}")]
    Flight(#[from] LaunchVehicleError),
    #[error("loss fit: {0}")]
    Fit(#[from] FitError),
}

/// The designed detector: its parameters, the filter model, the sensitivity table and the nominal
/// residual. Build once per design model and share between trials.
#[derive(Debug, Clone, PartialEq)]
pub struct MheDesign {
    params: DetectorParams,
    model: FilterModel,
    x0: State,
    onsets_s: Vec<f64>,
    /// `S` per grid onset, `N + 1` entries each, per unit fault (rad/s).
    sensitivity: Vec<Vec<f64>>,
    /// The noise-free nominal flight's residual at every sample (rad/s).
    nominal_residual: Vec<f64>,
}

impl DetectorParams {
    fn validate(&self, config: &LaunchVehicleConfig) -> Result<(), DesignError> {
        let invalid = |field, value, allowed| Err(DesignError::Invalid { field, value, allowed });
        let m = &self.mhe;
        if m.window_n == 0 {
            return invalid("window_n", 0.0, ">= 1");
        }
        if m.interval_samples == 0 {
            return invalid("interval_samples", 0.0, ">= 1");
        }
        if !(m.fault_intensity.is_finite() && m.fault_intensity > 0.0) {
            return invalid("fault_intensity", m.fault_intensity, "> 0");
        }
        if !(m.window_variance.is_finite() && m.window_variance > 0.0) {
            return invalid("window_variance", m.window_variance, "> 0");
        }
        if !(m.unit_loss_fraction > 0.0 && m.unit_loss_fraction <= 1.0) {
            return invalid("unit_loss_fraction", m.unit_loss_fraction, "in (0, 1]");
        }
        if m.reference_engine >= ENGINES {
            return invalid("reference_engine", m.reference_engine as f64, "0, 1, 2 or 3");
        }
        let g = &self.grid;
        if !(g.spacing_s > 0.0 && g.first_onset_s >= 0.0 && g.last_onset_s >= g.first_onset_s) {
            return invalid("grid.spacing_s", g.spacing_s, "> 0 with 0 <= first_onset_s <= last_onset_s");
        }
        let l = &self.localisation;
        if l.post_samples == 0 || l.pre_samples == 0 {
            return invalid("localisation pre/post samples", 0.0, ">= 1 each");
        }
        if !(self.threshold_fhat.is_finite() && self.threshold_fhat > 0.0) {
            return invalid("threshold_fhat", self.threshold_fhat, "> 0");
        }
        if !(config.dt_s.is_finite() && config.dt_s > 0.0) {
            return invalid("dt_s", config.dt_s, "> 0");
        }
        Ok(())
    }

    /// Designs the detector for the vehicle `config` describes (its parameters are the filter's model):
    /// one noise-free nominal flight to the last grid onset plus a window, branched at every grid onset
    /// with a unit loss on the reference engine (module docs).
    pub fn design(&self, config: &LaunchVehicleConfig) -> Result<MheDesign, DesignError> {
        self.validate(config)?;
        let mut exact = config.clone();
        exact.noise = SensorNoise::none();
        let model = FilterModel { params: config.params.clone(), dt_s: config.dt_s };
        let x0 = config.params.liftoff_state();
        let onsets_s = self.grid.onsets_s();
        let span = self.mhe.span_samples();
        let onset_steps: Vec<usize> = onsets_s.iter().map(|t| (t / config.dt_s).round() as usize).collect();
        let last_step = onset_steps.last().copied().unwrap_or(0) + span + 1;

        let mut vehicle = Vehicle::new(&exact, None)?;
        let mut ekf = self.ekf.filter(x0, config.dt_s);
        let mut nominal_residual = Vec::with_capacity(last_step + 1);
        let mut branches = Vec::new();
        for k in 0..=last_step {
            if onset_steps.contains(&k) {
                let fault = ThrustFault {
                    engine: self.mhe.reference_engine,
                    loss_fraction: self.mhe.unit_loss_fraction,
                    onset_s: k as f64 * config.dt_s,
                };
                branches.push((vehicle.with_fault(fault)?, ekf.clone(), Vec::with_capacity(span + 1)));
            }
            let m = vehicle.step_exact()?;
            nominal_residual.push(ekf.pitch_rate_residual(&model, &m));
            for (branch_vehicle, branch_ekf, residuals) in branches.iter_mut() {
                if residuals.len() <= span {
                    let mb = branch_vehicle.step_exact()?;
                    residuals.push((mb.k, branch_ekf.pitch_rate_residual(&model, &mb)));
                }
            }
        }
        let step = self.mhe.interval_samples;
        let unit_faults = self.mhe.unit_loss_fraction / UNIT_FAULT;
        let sensitivity = branches
            .iter()
            .map(|(_, _, residuals)| {
                (0..=self.mhe.window_n)
                    .map(|j| {
                        let (k, r) = residuals[1 + j * step];
                        (r - nominal_residual[k]) / unit_faults
                    })
                    .collect()
            })
            .collect();
        Ok(MheDesign { params: self.clone(), model, x0, onsets_s, sensitivity, nominal_residual })
    }
}

impl MheDesign {
    pub fn params(&self) -> &DetectorParams {
        &self.params
    }

    /// Whether `other`'s filter computes this design's residual, sample for sample: the same filter
    /// tuning, model and initial state.
    pub fn same_residual(&self, other: &MheDesign) -> bool {
        self.params.ekf == other.params.ekf && self.model == other.model && self.x0 == other.x0
    }

    /// The grid onsets (s) and their sensitivities (per unit fault, rad/s).
    pub fn sensitivity_table(&self) -> (&[f64], &[Vec<f64>]) {
        (&self.onsets_s, &self.sensitivity)
    }

    /// The noise-free nominal flight's pitch-rate residual (rad/s), one per sample.
    pub fn nominal_residual(&self) -> &[f64] {
        &self.nominal_residual
    }

    /// `S` for a fault hypothesised at `onset_s`: linear interpolation in the grid; `true` when clamped
    /// at an end of the grid (a non-finite onset gets the first entry, flagged).
    pub fn sensitivity_at(&self, onset_s: f64) -> (Vec<f64>, bool) {
        let mut S = Vec::with_capacity(self.params.mhe.window_n + 1);
        let clamped = self.sensitivity_into(onset_s, &mut S);
        (S, clamped)
    }

    /// [`MheDesign::sensitivity_at`] into `S` (cleared first): the detector's per-sample form, with no
    /// allocation once `S` has grown to the window.
    pub fn sensitivity_into(&self, onset_s: f64, S: &mut Vec<f64>) -> bool {
        S.clear();
        let t = &self.onsets_s;
        let (first, last) = (t[0], t[t.len() - 1]);
        let (row, clamped) = if !onset_s.is_finite() {
            (0, true)
        } else if t.len() == 1 {
            (0, onset_s != first)
        } else if onset_s <= first {
            (0, onset_s < first)
        } else if onset_s >= last {
            (t.len() - 1, onset_s > last)
        } else {
            let i = t.partition_point(|&s| s <= onset_s) - 1;
            let w = (onset_s - t[i]) / (t[i + 1] - t[i]);
            S.extend(self.sensitivity[i].iter().zip(&self.sensitivity[i + 1]).map(|(a, b)| a + w * (b - a)));
            return false;
        };
        S.extend_from_slice(&self.sensitivity[row]);
        clamped
    }

    /// Calibrates the linear loss fit (the seed's eq. 27) from flights of `config` with a loss of each of
    /// `losses_percent` at `onset_s`, the peak of `|fhat|` taken over `horizon_s` after the onset;
    /// returns the fit and the `(loss %, peak |fhat|)` pairs. Noise-free (`noise: None`): one flight per
    /// loss on the reference engine. Noisy: `flights_per_loss` flights per loss with the deck's sensor
    /// noise, on engines 1, 2, 3, 4, 1, .. in turn, flight `j` of loss `i` drawing its noise from stream
    /// `first_stream + i * flights_per_loss + j` of `seed` (flown in parallel; the pairs keep that
    /// order, so the fit is the same for any thread count). A noisy peak is the noise-free one plus the
    /// largest noise excursion near it, so a noise-free fit reads noisy flights high; a noisy fit absorbs
    /// that. The fit holds for onsets near `onset_s` (`S` and so `fhat` grow by about 50 % from 20 s to
    /// 50 s as the inertia falls); `LossTable` (`trial.rs`) builds the seed's table over onset time from
    /// one fit per onset.
    pub fn calibrate_loss_fit(
        self: &Arc<Self>,
        config: &LaunchVehicleConfig,
        onset_s: f64,
        losses_percent: &[f64],
        horizon_s: f64,
        noise: Option<NoisyCalibration>,
    ) -> Result<(LossFit, Vec<(f64, f64)>), DesignError> {
        use rayon::prelude::*;
        let reference = self.params.mhe.reference_engine;
        let flights: Vec<(f64, usize, Option<u64>)> = match noise {
            None => losses_percent.iter().map(|&loss| (loss, reference, None)).collect(),
            Some(n) => (losses_percent.iter().enumerate())
                .flat_map(|(i, &loss)| {
                    (0..n.flights_per_loss).map(move |j| {
                        let stream = n.first_stream + (i * n.flights_per_loss + j) as u64;
                        (loss, (reference + j) % ENGINES, Some(stream))
                    })
                })
                .collect(),
        };
        let pairs = flights
            .par_iter()
            .map(|&(loss, engine, stream)| {
                let fault = ThrustFault { engine, loss_fraction: loss / 100.0, onset_s };
                let peak = match (stream, noise) {
                    (Some(stream), Some(n)) => {
                        let mut rng = noise_rng(n.seed, stream, Substream::SensorNoise);
                        self.peak_fhat_flown(config, Some(fault), onset_s, horizon_s, Some(&mut rng))?
                    }
                    _ => self.peak_fhat(config, Some(fault), onset_s, horizon_s)?,
                };
                Ok((loss, peak))
            })
            .collect::<Result<Vec<_>, DesignError>>()?;
        Ok((LossFit::fit(&pairs)?, pairs))
    }

    /// Largest `|fhat|` from `from_s` to `from_s + horizon_s` of a noise-free flight of `config` with
    /// `fault`.
    pub fn peak_fhat(
        self: &Arc<Self>,
        config: &LaunchVehicleConfig,
        fault: Option<ThrustFault>,
        from_s: f64,
        horizon_s: f64,
    ) -> Result<f64, DesignError> {
        self.peak_fhat_flown(config, fault, from_s, horizon_s, None::<&mut NoiseRng>)
    }

    /// [`MheDesign::peak_fhat`] with the sensor noise of `config` drawn from `rng` (noise-free when
    /// `None`).
    fn peak_fhat_flown<R: rand::Rng + ?Sized>(
        self: &Arc<Self>,
        config: &LaunchVehicleConfig,
        fault: Option<ThrustFault>,
        from_s: f64,
        horizon_s: f64,
        mut rng: Option<&mut R>,
    ) -> Result<f64, DesignError> {
        let mut flown = config.clone();
        if rng.is_none() {
            flown.noise = SensorNoise::none();
        }
        let mut vehicle = Vehicle::new(&flown, fault)?;
        let mut detector = EkfMhe::new(Arc::clone(self), None);
        let mut peak = 0.0f64;
        while vehicle.time_s() <= from_s + horizon_s + 1e-9 {
            let m = match rng.as_deref_mut() {
                Some(rng) => vehicle.step(rng)?,
                None => vehicle.step_exact()?,
            };
            let out = detector.step(&m);
            if m.t_s >= from_s - 1e-9 {
                peak = peak.max(out.fhat.abs());
            }
        }
        Ok(peak)
    }
}

/// Noisy flights for a loss fit ([`MheDesign::calibrate_loss_fit`]): how many per loss, and the seed
/// and first stream their sensor noise is drawn from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NoisyCalibration {
    pub flights_per_loss: usize,
    pub seed: u64,
    pub first_stream: u64,
}

/// The GLS estimate `fhat = (S' V^-1 S + R^-1)^-1 S' V^-1 (Y - Y0)` for `V = v I` and scalar `R`; `None`
/// when it is not finite.
pub fn gls_fault_estimate(S: &[f64], Y: &[f64], Y0: &[f64], v: f64, R: f64) -> Option<f64> {
    assert!(S.len() == Y.len() && Y.len() == Y0.len(), "window lengths differ");
    let (mut StS, mut StY) = (0.0, 0.0);
    for ((s, y), y0) in S.iter().zip(Y).zip(Y0) {
        StS += s * s;
        StY += s * (y - y0);
    }
    let fhat = (StY / v) / (StS / v + 1.0 / R);
    fhat.is_finite().then_some(fhat)
}

/// The linear fit `loss % = intercept + slope * fhat_peak` (the seed's eq. 27: loss as the dependent
/// variable, the peak of `|fhat|` as the independent one).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LossFit {
    pub intercept_percent: f64,
    pub slope_percent_per_fhat: f64,
    /// Coefficient of determination of the fit.
    pub r_squared: f64,
}

/// Why a loss fit could not be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FitError {
    #[error("{0} points; a line needs at least 2")]
    TooFewPoints(usize),
    #[error("all fhat peaks are equal: the loss cannot be a function of them")]
    NoSpread,
    #[error("a point is not finite")]
    NonFinite,
}

impl LossFit {
    /// Least squares through `(loss %, fhat peak)` pairs.
    pub fn fit(pairs: &[(f64, f64)]) -> Result<Self, FitError> {
        if pairs.len() < 2 {
            return Err(FitError::TooFewPoints(pairs.len()));
        }
        if pairs.iter().any(|(l, f)| !(l.is_finite() && f.is_finite())) {
            return Err(FitError::NonFinite);
        }
        let n = pairs.len() as f64;
        let mean_f = pairs.iter().map(|p| p.1).sum::<f64>() / n;
        let mean_l = pairs.iter().map(|p| p.0).sum::<f64>() / n;
        let sff: f64 = pairs.iter().map(|p| (p.1 - mean_f).powi(2)).sum();
        let sfl: f64 = pairs.iter().map(|p| (p.1 - mean_f) * (p.0 - mean_l)).sum();
        let sll: f64 = pairs.iter().map(|p| (p.0 - mean_l).powi(2)).sum();
        if sff <= f64::EPSILON * mean_f.abs().max(f64::MIN_POSITIVE).powi(2) * n {
            return Err(FitError::NoSpread);
        }
        let slope = sfl / sff;
        let r_squared = if sll > 0.0 { sfl * sfl / (sff * sll) } else { 1.0 };
        Ok(LossFit { intercept_percent: mean_l - slope * mean_f, slope_percent_per_fhat: slope, r_squared })
    }

    /// The loss (%) for a peak `|fhat|`.
    pub fn loss_percent(&self, fhat_peak: f64) -> f64 {
        self.intercept_percent + self.slope_percent_per_fhat * fhat_peak
    }
}

/// The engine (index) whose loss produces jumps of these signs (module docs of the plant); `None` when
/// either jump is exactly zero or not finite.
pub fn localise(jump_n_y_g: f64, jump_n_z_g: f64) -> Option<usize> {
    if !(jump_n_y_g.is_finite() && jump_n_z_g.is_finite()) || jump_n_y_g == 0.0 || jump_n_z_g == 0.0 {
        return None;
    }
    (0..ENGINES).find(|&i| expected_jump_signs(i) == (jump_n_y_g.signum(), jump_n_z_g.signum()))
}

/// The first alarm of a run and the engine it names.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Detection {
    pub k: usize,
    pub t_s: f64,
    /// The estimated onset: the sample after which the overloads step ([`LocalisationParams`]).
    pub onset_estimate_s: f64,
    pub jump_n_y_g: f64,
    pub jump_n_z_g: f64,
    /// Engine index (the seed's engine `index + 1`); `None` if a jump is zero or not finite.
    pub engine: Option<usize>,
}

/// What the detector reports at a sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MheStep {
    /// `wz_measured - wz(k|k-1)` (rad/s).
    pub residual_rad_s: f64,
    /// The GLS estimate (unit faults; negative for engines 2 and 3); 0 until the window is full or when
    /// the estimate is not finite.
    pub fhat: f64,
    pub window_full: bool,
    /// `|fhat| >= threshold` at this sample.
    pub alarm: bool,
    /// The first alarm so far, if any.
    pub detection: Option<Detection>,
    /// The loss (%) from the running peak of `|fhat|` since the first alarm (needs a [`LossFit`]).
    pub loss_percent: Option<f64>,
}

/// Numerical-health counters of a run (columns of the trial records).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct DetectorHealth {
    pub filter: FilterHealth,
    /// Samples whose hypothesised onset lay outside the sensitivity grid (the nearest end was used).
    pub sensitivity_clamped: u32,
    /// Samples past the end of the nominal residual (`Y0 = 0` was used).
    pub nominal_residual_missing: u32,
    /// Samples whose GLS estimate was not finite (reported as 0).
    pub gls_failed: u32,
}

/// One sample of the detector's memory.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Past {
    k: usize,
    residual: f64,
    n_y_g: f64,
    n_z_g: f64,
    fhat: f64,
}

/// Indices, in a history of `len` samples (at least `N D + 1`), of the window
/// `[x(k - N D), x(k - (N-1) D), ..., x(k)]` of the newest samples.
fn window_indices(len: usize, mhe: &MheParams) -> impl Iterator<Item = usize> + use<> {
    let (first, n, d) = (len - mhe.span_samples(), mhe.window_n, mhe.interval_samples);
    (0..=n).map(move |j| first + j * d)
}

/// The online detector of one trial.
#[derive(Debug, Clone)]
pub struct EkfMhe {
    design: Arc<MheDesign>,
    loss_fit: Option<LossFit>,
    ekf: ResidualFilter,
    /// The latest samples, oldest first: the window, the look-back and the pre-onset average.
    history: VecDeque<Past>,
    capacity: usize,
    detection: Option<Detection>,
    peak_abs_fhat: f64,
    health: DetectorHealth,
    /// Per-sample buffers of the window's `Y`, `Y0` and `S`, kept to spare an allocation each sample.
    window_y: Vec<f64>,
    window_y0: Vec<f64>,
    window_s: Vec<f64>,
}

impl EkfMhe {
    /// A detector at lift-off (filter at the lift-off state).
    pub fn new(design: Arc<MheDesign>, loss_fit: Option<LossFit>) -> Self {
        let ekf = design.params.ekf.filter(design.x0, design.model.dt_s);
        let p = &design.params;
        let capacity = p.mhe.span_samples().max(p.localisation.max_lookback_samples + 1) + p.localisation.pre_samples;
        EkfMhe {
            design,
            loss_fit,
            ekf,
            history: VecDeque::with_capacity(capacity),
            capacity,
            detection: None,
            peak_abs_fhat: 0.0,
            health: DetectorHealth::default(),
            window_y: Vec::new(),
            window_y0: Vec::new(),
            window_s: Vec::new(),
        }
    }

    pub fn health(&self) -> DetectorHealth {
        DetectorHealth { filter: self.ekf.health(), ..self.health }
    }

    /// One sample (the plant's step k, at the design's `dt`).
    pub fn step(&mut self, m: &Measurement) -> MheStep {
        let residual_rad_s = self.ekf.pitch_rate_residual(&self.design.model, m);
        self.step_residual(m, residual_rad_s)
    }

    /// [`EkfMhe::step`] with the residual of another detector whose design has the same filter
    /// ([`MheDesign::same_residual`]): one filter serves a sweep of windows and intensities. This
    /// detector's own filter is not stepped, so its health is the other's.
    pub fn step_residual(&mut self, m: &Measurement, residual_rad_s: f64) -> MheStep {
        let design = Arc::clone(&self.design);
        let p = &design.params;
        if self.history.len() == self.capacity {
            self.history.pop_front();
        }
        self.history.push_back(Past { k: m.k, residual: residual_rad_s, n_y_g: m.n_y_g, n_z_g: m.n_z_g, fhat: 0.0 });

        let window_full = self.history.len() >= p.mhe.span_samples();
        let mut fhat = 0.0;
        if window_full {
            self.window_y.clear();
            self.window_y0.clear();
            let mut oldest_k = None;
            for i in window_indices(self.history.len(), &p.mhe) {
                let k = self.history[i].k;
                oldest_k.get_or_insert(k);
                self.window_y.push(self.history[i].residual);
                self.window_y0.push(design.nominal_residual.get(k).copied().unwrap_or_else(|| {
                    self.health.nominal_residual_missing += 1;
                    0.0
                }));
            }
            // A fault cannot begin before lift-off: the first windows hypothesise an onset at sample 0.
            let onset_s = oldest_k.unwrap_or(0).saturating_sub(1) as f64 * design.model.dt_s;
            let clamped = design.sensitivity_into(onset_s, &mut self.window_s);
            self.health.sensitivity_clamped += u32::from(clamped);
            match gls_fault_estimate(&self.window_s, &self.window_y, &self.window_y0, p.mhe.window_variance, p.mhe.R())
            {
                Some(f) => fhat = f,
                None => self.health.gls_failed += 1,
            }
        }
        if let Some(last) = self.history.back_mut() {
            last.fhat = fhat;
        }
        let alarm = window_full && fhat.abs() >= p.threshold_fhat;
        if alarm && self.detection.is_none() {
            self.detection = Some(self.localise_now(m));
        }
        if self.detection.is_some() {
            self.peak_abs_fhat = self.peak_abs_fhat.max(fhat.abs());
        }
        let loss_percent = match (&self.detection, &self.loss_fit) {
            (Some(_), Some(fit)) => Some(fit.loss_percent(self.peak_abs_fhat)),
            _ => None,
        };
        MheStep { residual_rad_s, fhat, window_full, alarm, detection: self.detection, loss_percent }
    }

    /// Onset estimate and overload jumps at the first alarm ([`LocalisationParams`]): the largest
    /// overload step among the look-back's samples that have at least one sample before and after them
    /// (fewer are averaged near the ends); NaN jumps (no engine) when the history is too short.
    fn localise_now(&self, m: &Measurement) -> Detection {
        let l = &self.design.params.localisation;
        let newest = self.history.len() - 1;
        let mean = |range: std::ops::Range<usize>, pick: fn(&Past) -> f64| {
            let len = range.len() as f64;
            range.map(|i| pick(&self.history[i])).sum::<f64>() / len
        };
        let step_after = |i: usize| {
            let pre = i.saturating_sub(l.pre_samples - 1)..i + 1;
            let post = i + 1..(i + 1 + l.post_samples).min(newest + 1);
            (
                mean(post.clone(), |s| s.n_y_g) - mean(pre.clone(), |s| s.n_y_g),
                mean(post, |s| s.n_z_g) - mean(pre, |s| s.n_z_g),
            )
        };
        let candidates = newest.saturating_sub(l.max_lookback_samples)..newest;
        let best = candidates
            .map(|i| (i, step_after(i)))
            .filter(|(_, (y, z))| y.is_finite() && z.is_finite())
            .max_by(|a, b| (a.1.0.hypot(a.1.1)).total_cmp(&b.1.0.hypot(b.1.1)));
        let (onset, (jump_n_y_g, jump_n_z_g)) = best.unwrap_or((newest, (f64::NAN, f64::NAN)));
        Detection {
            k: m.k,
            t_s: m.t_s,
            onset_estimate_s: self.history[onset].k as f64 * self.design.model.dt_s,
            jump_n_y_g,
            jump_n_z_g,
            engine: localise(jump_n_y_g, jump_n_z_g),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{DMatrix, DVector};
    use rand::rngs::ChaCha8Rng;
    use rand::{RngExt, SeedableRng};
    use rand_distr::StandardNormal;
    use std::sync::OnceLock;

    fn seed_design() -> Arc<MheDesign> {
        static DESIGN: OnceLock<Arc<MheDesign>> = OnceLock::new();
        DESIGN.get_or_init(|| Arc::new(DetectorParams::seed().design(&LaunchVehicleConfig::default()).unwrap())).clone()
    }

    /// The loss fit of the seed design: noise-free losses of 10, 15, .. 60 % at 20 s, peaks over 3 s.
    fn seed_fit() -> &'static (LossFit, Vec<(f64, f64)>) {
        static FIT: OnceLock<(LossFit, Vec<(f64, f64)>)> = OnceLock::new();
        FIT.get_or_init(|| {
            let losses: Vec<f64> = (0..11).map(|i| 10.0 + 5.0 * i as f64).collect();
            seed_design().calibrate_loss_fit(&LaunchVehicleConfig::default(), 20.0, &losses, 3.0, None).unwrap()
        })
    }

    /// Flies a trial to `until_s` with sensor noise from ChaCha8 `seed` (noise-free when `None`).
    fn run(
        design: &Arc<MheDesign>,
        fault: Option<ThrustFault>,
        until_s: f64,
        seed: Option<u64>,
        fit: Option<LossFit>,
    ) -> Vec<(Measurement, MheStep)> {
        let mut config = LaunchVehicleConfig::default();
        if seed.is_none() {
            config.noise = SensorNoise::none();
        }
        let mut rng = ChaCha8Rng::seed_from_u64(seed.unwrap_or(0));
        let mut vehicle = Vehicle::new(&config, fault).unwrap();
        let mut detector = EkfMhe::new(Arc::clone(design), fit);
        let mut out = Vec::new();
        while vehicle.time_s() < until_s - 1e-9 {
            let m = if seed.is_some() { vehicle.step(&mut rng) } else { vehicle.step_exact() }.unwrap();
            out.push((m, detector.step(&m)));
        }
        assert_eq!(detector.health().filter, FilterHealth::default());
        assert_eq!(detector.health().gls_failed, 0);
        out
    }

    /// The filters' exact Jacobians (dual numbers) against central differences of the continuous
    /// dynamics at flown states (the pad, max-q, a gust, late in the burn, with a loss): equal to the
    /// differences' own error, 1e-6 of each column's scale; the first RK4 stage is the plain
    /// evaluation's to the bit, so the transition does not move.
    #[test]
    fn exact_jacobians_match_central_differences() {
        use crate::estimation::stekf::central_difference;
        let config = LaunchVehicleConfig::default();
        let model = FilterModel { params: config.params.clone(), dt_s: config.dt_s };
        let flown = run(
            &seed_design(),
            Some(ThrustFault { engine: 2, onset_s: 60.0, loss_fraction: 0.3 }),
            80.0,
            Some(3),
            None,
        );
        for t_s in [0.0, 40.5, 50.5, 62.0, 79.0] {
            let (m, _) = flown.iter().find(|(m, _)| m.t_s >= t_s).unwrap();
            let u = FilterInput::new(m.t_s, m.gimbal_rad);
            let (k1, exact) = value_and_jacobian(&m.truth, |x| filter_derivatives(&model.params, x, u.t_s, &u.gimbals));
            let numeric = central_difference(&m.truth, |x| filter_derivatives(&model.params, x, u.t_s, &u.gimbals));
            assert_eq!(k1, filter_derivatives(&model.params, &m.truth, u.t_s, &u.gimbals));
            // A central difference's own error: its truncation (relative, below 1e-6 of the column here)
            // and its rounding, about 1e-16 |f_r| / h_c with the step h_c = 1e-6 max(1, |x_c|); allowed
            // 100x that.
            for c in 0..STATES {
                let scale = exact.column(c).amax();
                for r in 0..STATES {
                    let rounding = 1e-8 * k1[r].abs().max(1.0) / m.truth[c].abs().max(1.0);
                    let error = (exact[(r, c)] - numeric[(r, c)]).abs();
                    assert!(error <= 1e-6 * scale + rounding, "t = {t_s} s, ({r}, {c}): {error:e} of {scale:e}");
                }
            }
            // Thrust lifts, and climbing raises the thrust: the thrust state is coupled both ways.
            assert!(exact[(idx::VY, idx::THRUST)] > 0.0 && exact[(idx::THRUST, idx::VY)] > 0.0);
            assert_eq!(model.transition_with_jacobian(&m.truth, &u).0, model.transition(&m.truth, &u));
            let augmented = WithMomentStates(&model);
            let x16 = SVector::<f64, AUGMENTED>::from_fn(|i, _| if i < STATES { m.truth[i] } else { 0.01 * i as f64 });
            let (_, exact16) = value_and_jacobian(&x16, |x| augmented.derivatives(x, u.t_s, &u.gimbals));
            let numeric16 = central_difference(&x16, |x| augmented.derivatives(x, u.t_s, &u.gimbals));
            assert!((exact16 - numeric16).amax() <= 1e-6 * exact16.amax().max(1.0), "t = {t_s} s, augmented");
            assert_eq!(exact16[(idx::WX, STATES)], 1.0);
            assert_eq!(augmented.transition_with_jacobian(&x16, &u).0, augmented.transition(&x16, &u));
        }
    }

    /// `(S' V^-1 S + R^-1)^-1 S' V^-1 (Y - Y0)` written out with general matrices.
    fn closed_form(S: &[f64], Y: &[f64], Y0: &[f64], V: &DMatrix<f64>, R: f64) -> f64 {
        let S = DMatrix::from_column_slice(S.len(), 1, S);
        let Vi = V.clone().try_inverse().unwrap();
        let A = S.transpose() * &Vi * &S + DMatrix::from_element(1, 1, 1.0 / R);
        let b = S.transpose() * &Vi * (DVector::from_column_slice(Y) - DVector::from_column_slice(Y0));
        (A.try_inverse().unwrap() * b)[(0, 0)]
    }

    /// The estimator on synthetic windows (random `S`, `Y`, `Y0` of the real scales, `V = v I`, the seed's
    /// `R` range) equals the closed form to 1e-12 relative (measured worst 5.2e-15), and the window takes
    /// the samples `k - (N - j) D`.
    #[test]
    fn gls_equals_the_closed_form_on_a_synthetic_window() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let mut normal = || rng.sample::<f64, _>(StandardNormal);
        let mut worst = 0.0f64;
        for case in 0..200 {
            let n = 2 + case % 10;
            let S: Vec<f64> = (0..n).map(|_| 1e-5 * normal()).collect();
            let Y: Vec<f64> = (0..n).map(|_| 1e-3 * normal()).collect();
            let Y0: Vec<f64> = (0..n).map(|_| 1e-4 * normal()).collect();
            let v = [1.0, 8.7e-8, 1e-10][case % 3];
            let R = [0.01f64, 1.0, 20.0, 500.0, 5000.0, 1e4][case % 6].powi(2);
            let ours = gls_fault_estimate(&S, &Y, &Y0, v, R).unwrap();
            let reference = closed_form(&S, &Y, &Y0, &(DMatrix::identity(n, n) * v), R);
            worst = worst.max((ours - reference).abs() / reference.abs());
        }
        assert!(worst < 1e-12, "{worst:e}");

        let mhe = MheParams { window_n: 3, interval_samples: 2, ..MheParams::seed() };
        let history: VecDeque<Past> =
            (0..20).map(|k| Past { k, residual: k as f64, n_y_g: 0.0, n_z_g: 0.0, fhat: 0.0 }).collect();
        let ks: Vec<usize> = window_indices(history.len(), &mhe).map(|i| history[i].k).collect();
        assert_eq!(ks, [13, 15, 17, 19]);
    }

    /// How much the data weigh against the prior in the seed's estimator (issue 21.2): `R S'S / v` for
    /// the window's `S` (per unit fault) at a 20 s onset. Measured `S'S` = 2.62e-10 (rad/s)^2, 8.59e-7
    /// (deg/s)^2; it grows with the onset (1e-10 at lift-off, 1.8e-9 at 130 s) as the inertia falls. So for
    /// the seed's F of 1 to 100 the prior dominates in either unit (`R S'S / v` at most 2.6e-6 in rad/s,
    /// 8.6e-3 in deg/s), and `fhat` is `R` times a correlation of the window with `S`: its shape cannot
    /// change with `R` there. The data weigh as much as the prior only from F = 1,100 in deg/s (62,000
    /// in rad/s).
    #[test]
    fn the_prior_dominates_in_rad_s_and_not_in_deg_s() {
        let design = seed_design();
        let (onsets, table) = design.sensitivity_table();
        let at = onsets.iter().position(|t| *t == 20.0).unwrap();
        let sts: f64 = table[at].iter().map(|s| s * s).sum();
        assert!((2.55e-10..2.7e-10).contains(&sts), "{sts:e}");
        let deg2 = (180.0 / std::f64::consts::PI).powi(2);
        let weight = |f: f64, v: f64| f * f * sts / v;
        assert!(weight(100.0, 1.0) < 3e-6 && weight(100.0, 1.0 / deg2) < 0.01);
        assert!(weight(1100.0, 1.0 / deg2) > 1.0 && weight(1000.0, 1.0 / deg2) < 1.0);
        let first_onset = table[0].iter().map(|s| s * s).sum::<f64>();
        let last_onset = table[table.len() - 1].iter().map(|s| s * s).sum::<f64>();
        assert!(first_onset < sts && sts < last_onset);
    }

    /// On a real noisy run with a 30 % loss, every `fhat` the detector reports from 0.5 s before to 1 s
    /// after the onset is the closed-form GLS of its own residual window, with `S` and `Y0` from the
    /// design, to 1e-12 relative (measured worst 2.1e-16).
    #[test]
    fn the_detector_fhat_is_the_closed_form_of_its_window() {
        let design = seed_design();
        let p = design.params().mhe;
        let fault = ThrustFault { engine: 0, loss_fraction: 0.3, onset_s: 25.0 };
        let trace = run(&design, Some(fault), 26.0, Some(3), None);
        let n = p.window_n + 1;
        let mut worst = 0.0f64;
        for k in 2450..trace.len() {
            let ks: Vec<usize> = (0..n).map(|j| k - p.window_n + j).collect();
            let Y: Vec<f64> = ks.iter().map(|&i| trace[i].1.residual_rad_s).collect();
            let Y0: Vec<f64> = ks.iter().map(|&i| design.nominal_residual()[i]).collect();
            let (S, clamped) = design.sensitivity_at((ks[0] - 1) as f64 * 0.01);
            assert!(!clamped);
            let reference = closed_form(&S, &Y, &Y0, &DMatrix::identity(n, n), p.R());
            worst = worst.max((trace[k].1.fhat - reference).abs() / reference.abs());
        }
        assert!(worst < 1e-12, "{worst:e}");
    }

    /// The noise-free filter model is the truth: the nominal residual is numerically zero (measured
    /// 1.7e-15 rad/s against a 1 % loss's 1.7e-6), and a unit loss's residual grows over the window.
    #[test]
    fn the_filter_model_reproduces_the_nominal_truth() {
        let design = seed_design();
        let worst = design.nominal_residual().iter().fold(0.0f64, |a, r| a.max(r.abs()));
        assert!(worst < 1e-12, "{worst:e}");
        let (onsets, S) = design.sensitivity_table();
        assert_eq!(onsets.len(), 27);
        for s in S {
            assert!(s.windows(2).all(|w| w[1] > w[0] && w[0] > 0.0), "{s:?}");
        }
    }

    /// The peak of `|fhat|` (noise-free, engine 1 at 20 s, peak over 3 s) is linear in the loss over
    /// 10-60 % in 5 % steps: R^2 > 0.99 (measured 0.99948; 5.87e-6 at 10 %, 3.23e-5 at 60 %, slightly
    /// concave: the slope falls from 5.7e-7 to 4.9e-7 per percent; fit `loss = -1.72 + 1.892e6 fhat`),
    /// and the fit gives every calibration loss back within 2 points (measured 0.62). A fault-free
    /// flight's `fhat` is numerically zero.
    #[test]
    fn fhat_peak_grows_linearly_with_the_loss() {
        let (fit, pairs) = seed_fit();
        assert!(fit.r_squared > 0.99, "{fit:?}");
        assert!(fit.slope_percent_per_fhat > 0.0);
        for (loss, peak) in pairs {
            assert!((fit.loss_percent(*peak) - loss).abs() < 2.0, "{loss}: {}", fit.loss_percent(*peak));
        }
        assert!(pairs.windows(2).all(|w| w[1].1 > w[0].1), "{pairs:?}");
        let design = seed_design();
        let none = design.peak_fhat(&LaunchVehicleConfig::default(), None, 20.0, 3.0).unwrap();
        assert!(none < 1e-15, "{none:e}");
        // Losses the fit never saw, between its points and on the other engines: within 1.5 points (measured
        // -0.41, -0.32, -1.05 on engine 2, -0.42).
        for (engine, loss) in [(0, 12.5), (2, 27.5), (1, 42.5), (3, 57.5)] {
            let fault = ThrustFault { engine, loss_fraction: loss / 100.0, onset_s: 20.0 };
            let peak = design.peak_fhat(&LaunchVehicleConfig::default(), Some(fault), 20.0, 3.0).unwrap();
            assert!(
                (fit.loss_percent(peak) - loss).abs() < 1.5,
                "{loss} % on engine {engine}: {}",
                fit.loss_percent(peak)
            );
        }
    }

    /// Each engine, on noisy flights (the seed's 30 % at 25 s, and 50 % at 50 s): no alarm before the
    /// onset; the alarm within 0.5 s (measured 0.21-0.27 s at 30 %, 0.08-0.10 s at 50 %); the onset
    /// located within 0.1 s (measured: on the onset sample in all eight); the engine named correctly
    /// (jumps measured 8.8e-3 to 1.0e-2 g at 30 %, 1.8e-2 to 2.1e-2 g at 50 %). Outside the tests, 160
    /// noisy flights per size with onsets spread over 15-75 s localised 160/160 at 20, 30 and 50 %.
    #[test]
    fn each_engine_is_localised_on_a_noisy_run() {
        let design = seed_design();
        for engine in 0..ENGINES {
            for (loss_fraction, onset_s) in [(0.3, 25.0), (0.5, 50.0)] {
                let fault = ThrustFault { engine, loss_fraction, onset_s };
                let trace = run(&design, Some(fault), onset_s + 1.0, Some(100 + engine as u64), None);
                let early = trace.iter().filter(|(m, _)| m.t_s < onset_s).any(|(_, s)| s.alarm);
                assert!(!early, "engine {engine}: alarm before the onset");
                let d = trace.last().unwrap().1.detection.expect("detected");
                assert!(d.t_s - onset_s < 0.5, "engine {engine} {loss_fraction}: {d:?}");
                assert!((d.onset_estimate_s - onset_s).abs() < 0.1, "engine {engine} {loss_fraction}: {d:?}");
                assert_eq!(d.engine, Some(engine), "{loss_fraction}: {d:?}");
            }
        }
    }

    /// Fresh fault-free noisy flights (ChaCha8 seeds 200-205, not those the threshold came from) raise no
    /// alarm in 60 s: the largest `|fhat|` is 0.66 of the threshold (measured).
    #[test]
    fn a_fault_free_noisy_flight_raises_no_alarm() {
        let design = seed_design();
        let mut worst = 0.0f64;
        for seed in 200..206 {
            let trace = run(&design, None, 60.0, Some(seed), None);
            assert!(trace.iter().all(|(_, s)| !s.alarm && s.detection.is_none()), "seed {seed}");
            worst = trace.iter().fold(worst, |a, (_, s)| a.max(s.fhat.abs()));
        }
        assert!(worst < design.params().threshold_fhat, "{worst:e}");
    }

    /// The fit from the noise-free calibration, applied to noisy flights with losses of 30, 40 and 50 % at
    /// 20 s on each engine, estimates the loss 2 s after the onset within 12 points, always too high
    /// (measured +3.95 to +9.29 points): the peak of a noisy `|fhat|` is the noise-free peak plus the
    /// largest noise excursion over the plateau (about 2.5 standard deviations of 2e-6, i.e. ~9 points at
    /// the fit's slope). A fit calibrated on noisy flights would absorb this bias.
    #[test]
    fn the_estimated_loss_follows_the_injected_one() {
        let design = seed_design();
        let (fit, _) = seed_fit();
        let (mut lowest, mut highest) = (f64::INFINITY, f64::NEG_INFINITY);
        for engine in 0..ENGINES {
            for loss in [30.0, 40.0, 50.0] {
                let fault = ThrustFault { engine, loss_fraction: loss / 100.0, onset_s: 20.0 };
                let trace = run(&design, Some(fault), 22.0, Some(300 + engine as u64), Some(*fit));
                let estimate = trace.last().unwrap().1.loss_percent.expect("detected");
                lowest = lowest.min(estimate - loss);
                highest = highest.max(estimate - loss);
            }
        }
        assert!(lowest > 0.0 && highest < 12.0, "{lowest} {highest}");
    }

    /// The same noisy flights read through a fit calibrated on noisy flights (the seed's 5 % steps, 4
    /// flights per loss with the default sensor noise, streams of seed 1): the bias is gone, the errors
    /// fall on both sides of zero and within 5 points (measured -1.8 to +3.0, mean +0.8; the noise-free
    /// fit reads the same flights +3.95 to +9.29 points high).
    #[test]
    fn a_fit_on_noisy_flights_reads_the_loss_without_the_bias() {
        let design = seed_design();
        let losses: Vec<f64> = (0..11).map(|i| 10.0 + 5.0 * i as f64).collect();
        let noise = NoisyCalibration { flights_per_loss: 4, seed: 1, first_stream: 0 };
        let (fit, pairs) =
            design.calibrate_loss_fit(&LaunchVehicleConfig::default(), 20.0, &losses, 3.0, Some(noise)).unwrap();
        assert_eq!(pairs.len(), 44);
        let (noise_free, _) = seed_fit();
        assert!(fit.loss_percent(2e-5) < noise_free.loss_percent(2e-5) - 3.0, "{fit:?} {noise_free:?}");
        let mut errors = Vec::new();
        for engine in 0..ENGINES {
            for loss in [30.0, 40.0, 50.0] {
                let fault = ThrustFault { engine, loss_fraction: loss / 100.0, onset_s: 20.0 };
                let trace = run(&design, Some(fault), 22.0, Some(300 + engine as u64), Some(fit));
                errors.push(trace.last().unwrap().1.loss_percent.expect("detected") - loss);
            }
        }
        let mean = errors.iter().sum::<f64>() / errors.len() as f64;
        assert!(errors.iter().all(|e| e.abs() < 5.0) && errors.iter().any(|e| *e < 0.0), "{errors:?}");
        assert!(mean.abs() < 2.0, "{mean}");
    }

    /// Runs the seed's N and R comparisons (50 % at 50 s, noise-free peak of `|fhat|`; fault-free `fhat`
    /// standard deviation over 5-60 s of one noisy flight) and returns (peak, fhat 5 s after the onset,
    /// noise standard deviation).
    fn compare(window_n: usize, fault_intensity: f64, window_variance: f64) -> (f64, f64, f64) {
        let (peak, late, sd, _) = compare_filters(window_n, fault_intensity, window_variance, None);
        (peak, late, sd)
    }

    /// [`compare`] with the filter's angular-acceleration biases at `moment_bias_sigma` (the plain filter
    /// when `None`); also returns the samples at which `|fhat|` is at least half its peak.
    fn compare_filters(
        window_n: usize,
        fault_intensity: f64,
        window_variance: f64,
        moment_bias_sigma: Option<f64>,
    ) -> (f64, f64, f64, usize) {
        let mut params = DetectorParams {
            mhe: MheParams { window_n, fault_intensity, window_variance, ..MheParams::seed() },
            ..DetectorParams::seed()
        };
        params.ekf.moment_bias_sigma_rad_s2_per_sqrt_s = moment_bias_sigma;
        let design = Arc::new(params.design(&LaunchVehicleConfig::default()).unwrap());
        let fault = ThrustFault { engine: 0, loss_fraction: 0.5, onset_s: 50.0 };
        let trace = run(&design, Some(fault), 55.0, None, None);
        let peak = trace.iter().filter(|(m, _)| m.t_s >= 50.0).fold(0.0f64, |a, (_, s)| a.max(s.fhat.abs()));
        let late = trace.last().unwrap().1.fhat;
        let quiet: Vec<f64> =
            run(&design, None, 60.0, Some(3), None).iter().filter(|(m, _)| m.t_s > 5.0).map(|(_, s)| s.fhat).collect();
        let sd = (quiet.iter().map(|f| f * f).sum::<f64>() / quiet.len() as f64).sqrt();
        let half = trace.iter().filter(|(m, s)| m.t_s >= 50.0 && s.fhat.abs() >= 0.5 * peak).count();
        (peak, late, sd, half)
    }

    /// The seed's N and R findings, as they come out on this model (measured numbers; the seed's do not
    /// reproduce, see the module docs):
    /// - N = 1, 5, 10 (D = 0.01 s, R = 20^2, V = I): peak-to-noise 11.9, 19.8, 27.3, i.e. a longer window
    ///   is better, not worse; and `fhat` does not "recover" for any N: 5 s after the onset it is still
    ///   0.89-0.90 of its peak, because the loss is permanent and the plain EKF has no state for its
    ///   moment, so the pitch-rate residual is a step (ramping over ~0.3 s), not a spike;
    /// - with `V = I` (residual in rad/s), `R` only scales `fhat`: `F = 50` gives exactly `(50/20)^2` the
    ///   peak of `F = 20`, with the same peak-to-noise; with `V` the residual variance (8.7e-8, a MAP
    ///   estimate), the peak grows with `R` and saturates (168 at 20^2, 241 at 50^2, 263 at 500^2 unit
    ///   faults for a 50-unit loss) while the peak-to-noise falls slightly (17.2, 15.7, 15.3); there is
    ///   no second rise.
    #[test]
    fn window_length_and_fault_intensity_as_they_come_out_here() {
        let (p1, l1, s1) = compare(1, 20.0, 1.0);
        let (p5, l5, s5) = compare(5, 20.0, 1.0);
        let (p10, l10, s10) = compare(10, 20.0, 1.0);
        assert!(p1 / s1 < p5 / s5 && p5 / s5 < p10 / s10, "{} {} {}", p1 / s1, p5 / s5, p10 / s10);
        for (late, peak) in [(l1, p1), (l5, p5), (l10, p10)] {
            assert!(late / peak > 0.8, "{late:e} {peak:e}");
        }
        let (p50, _, s50) = compare(5, 50.0, 1.0);
        assert!((p50 / p5 / 6.25 - 1.0).abs() < 1e-3, "{}", p50 / p5);
        assert!(((p50 / s50) / (p5 / s5) - 1.0).abs() < 0.02);
        let map = [20.0, 50.0, 500.0].map(|f| compare(5, f, 8.7e-8));
        assert!(map[0].0 < map[1].0 && map[1].0 < map[2].0, "{map:?}");
        assert!(map[2].0 / map[1].0 < 1.15, "{map:?}");
        assert!(map[2].0 / map[2].2 < map[0].0 / map[0].2, "{map:?}");
    }

    /// The recovering residual (issue 21.1) on the seed's N experiment (50 % at 50 s, noise-free, R = 20^2,
    /// V = I; noise from one fault-free noisy flight), with angular-acceleration biases walking at 0.1
    /// rad/s^2/sqrt(s) (this project's choice: the jump then clears within about 0.05 s, the seed's
    /// "controlled within about 10 ms" scale) and at 0.01 (clears within about 0.15 s). Measured:
    /// - the jump recovers: `fhat` 5 s after the onset is at most 1e-3 of its peak (0.9 with the plain filter);
    /// - the seed's "a smaller N loses amplitude" holds: at 0.1, peak-to-noise 0.59, 1.16, 1.17 for N = 1, 5,
    ///   10; its "a larger N recovers in fewer beats" does not: `|fhat|` stays above half its peak for
    ///   4, 5, 5 samples; at 0.01 N = 10 is best (1.60, 2.98, 4.73);
    /// - a jump that clears costs the detector most of its signal: peak-to-noise 1.16 against the plain
    ///   filter's 21.2 at N = 5;
    /// - the prior still dominates: the recovering `S` is smaller than the plain one's, so `R S'S / v`
    ///   is below 0.01 even at F = 100 in deg/s and `R` only scales `fhat`.
    #[test]
    fn the_recovering_residual_clears_and_shows_the_seeds_window_trade() {
        let fast = [1, 5, 10].map(|n| compare_filters(n, 20.0, 1.0, Some(0.1)));
        let slow = [1, 5, 10].map(|n| compare_filters(n, 20.0, 1.0, Some(0.01)));
        let plain = compare_filters(5, 20.0, 1.0, None);
        let ratio = |r: &(f64, f64, f64, usize)| r.0 / r.2;
        for r in fast.iter().chain(&slow) {
            assert!(r.1.abs() < 2e-3 * r.0, "{r:?}");
        }
        assert!(ratio(&fast[0]) < 0.6 * ratio(&fast[1]), "{fast:?}");
        assert!((ratio(&fast[2]) / ratio(&fast[1]) - 1.0).abs() < 0.05, "{fast:?}");
        assert!(fast.iter().all(|r| (3..=6).contains(&r.3)) && fast[2].3 >= fast[1].3, "{fast:?}");
        assert!(ratio(&slow[0]) < ratio(&slow[1]) && ratio(&slow[1]) < ratio(&slow[2]), "{slow:?}");
        assert!(ratio(&fast[1]) < 0.1 * ratio(&plain), "{plain:?}");

        let mut params = DetectorParams::seed();
        params.ekf.moment_bias_sigma_rad_s2_per_sqrt_s = Some(0.1);
        let design = params.design(&LaunchVehicleConfig::default()).unwrap();
        let (onsets, table) = design.sensitivity_table();
        let sts = |onset_s: f64| {
            let at = onsets.iter().position(|t| *t == onset_s).unwrap();
            table[at].iter().map(|s| s * s).sum::<f64>()
        };
        let deg2 = (180.0 / std::f64::consts::PI).powi(2);
        assert!((1.3e-11..1.42e-11).contains(&sts(20.0)) && (1.9e-11..2.07e-11).contains(&sts(50.0)));
        assert!(100.0f64.powi(2) * sts(50.0) * deg2 < 0.01, "{:e}", sts(50.0));
    }

    /// The seed's table: `n_y` alike for engines {1, 4} and {2, 3}, `n_z` for {1, 2} and {3, 4}.
    #[test]
    fn localise_follows_the_seed_table() {
        assert_eq!(localise(0.01, 0.02), Some(0));
        assert_eq!(localise(-0.01, 0.02), Some(1));
        assert_eq!(localise(-0.01, -0.02), Some(2));
        assert_eq!(localise(0.01, -0.02), Some(3));
        assert_eq!(localise(0.0, 0.02), None);
        assert_eq!(localise(f64::NAN, 0.02), None);
        let sign = |i: usize, f: fn(usize) -> f64| f(i);
        let ny = |i| expected_jump_signs(i).0;
        let nz = |i| expected_jump_signs(i).1;
        assert!(sign(1, ny) == sign(2, ny) && sign(0, ny) == sign(3, ny) && sign(0, ny) != sign(1, ny));
        assert!(sign(0, nz) == sign(1, nz) && sign(2, nz) == sign(3, nz) && sign(0, nz) != sign(2, nz));
    }

    /// Same RNG state, same outputs, bit for bit.
    #[test]
    fn same_rng_state_gives_bit_identical_outputs() {
        let design = seed_design();
        let fault = Some(ThrustFault { engine: 3, loss_fraction: 0.4, onset_s: 2.0 });
        let steps = |seed| run(&design, fault, 3.0, Some(seed), None).into_iter().map(|(_, s)| s).collect::<Vec<_>>();
        assert_eq!(steps(9), steps(9));
        assert_ne!(steps(9), steps(10));
    }

    #[test]
    fn loss_fit_recovers_an_exact_line_and_rejects_degenerate_input() {
        let pairs: Vec<(f64, f64)> = [1e-6, 2e-6, 5e-6].iter().map(|f| (3.0 + 2e6 * f, *f)).collect();
        let fit = LossFit::fit(&pairs).unwrap();
        assert!((fit.intercept_percent - 3.0).abs() < 1e-9 && (fit.slope_percent_per_fhat - 2e6).abs() < 1e-3);
        assert!((fit.r_squared - 1.0).abs() < 1e-12);
        assert_eq!(LossFit::fit(&pairs[..1]), Err(FitError::TooFewPoints(1)));
        assert_eq!(LossFit::fit(&[(10.0, 1e-6), (20.0, 1e-6)]), Err(FitError::NoSpread));
        assert_eq!(LossFit::fit(&[(10.0, f64::NAN), (20.0, 1e-6)]), Err(FitError::NonFinite));
    }

    #[test]
    fn invalid_parameters_are_design_errors() {
        let config = LaunchVehicleConfig::default();
        type Breaks = fn(&mut DetectorParams);
        let cases: [(Breaks, &str); 6] = [
            (|p| p.mhe.window_n = 0, "window_n"),
            (|p| p.mhe.fault_intensity = 0.0, "fault_intensity"),
            (|p| p.mhe.window_variance = f64::NAN, "window_variance"),
            (|p| p.mhe.reference_engine = 4, "reference_engine"),
            (|p| p.threshold_fhat = -1.0, "threshold_fhat"),
            (|p| p.localisation.pre_samples = 0, "localisation pre/post samples"),
        ];
        for (break_it, field) in cases {
            let mut p = DetectorParams::seed();
            break_it(&mut p);
            match p.design(&config) {
                Err(DesignError::Invalid { field: f, .. }) => assert_eq!(f, field),
                other => panic!("{field}: {:?}", other.map(|_| ())),
            }
        }
    }

    /// `S` is interpolated linearly between grid onsets and clamped (and flagged) outside.
    #[test]
    fn sensitivity_interpolates_between_grid_onsets() {
        let design = seed_design();
        let (onsets, table) = design.sensitivity_table();
        let (mid, clamped) = design.sensitivity_at(0.5 * (onsets[3] + onsets[4]));
        assert!(!clamped);
        for j in 0..mid.len() {
            assert!((mid[j] - 0.5 * (table[3][j] + table[4][j])).abs() < 1e-20);
        }
        assert_eq!(design.sensitivity_at(1000.0), (table[table.len() - 1].clone(), true));
        assert_eq!(design.sensitivity_at(onsets[0]), (table[0].clone(), false));
    }
}
