//! The residual generator of method 001: the pitch-rate EKF on the 13-state model, plain or with the
//! moment-bias states that let a loss's jump clear (module docs of [`super`]).
#![allow(non_snake_case)]

use nalgebra::{SMatrix, SVector};

use crate::dual::{Real, value_and_jacobian};
use crate::estimation::{DiscreteModel, Fading, FilterHealth, Stekf};
use crate::methods::thrust_loss::vehicle::{
    ENGINES, Gimbals, MEASURED, Measured, Measurement, STATES, SensorNoise, State, VehicleParams, filter_derivatives,
    idx, rk4, rk4_from,
};

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
pub(super) struct WithMomentStates<'a>(pub(super) &'a FilterModel);

/// `Phi = I + A dt + (A dt)^2 / 2` from the continuous Jacobian `A`.
fn second_order_transition<const N: usize>(A: &SMatrix<f64, N, N>, dt_s: f64) -> SMatrix<f64, N, N> {
    let Adt = A * dt_s;
    SMatrix::identity() + Adt + Adt * Adt * 0.5
}

impl WithMomentStates<'_> {
    pub(super) fn derivatives<T: Real>(
        &self,
        x: &SVector<T, AUGMENTED>,
        t_s: f64,
        gimbals: &Gimbals,
    ) -> SVector<T, AUGMENTED> {
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
pub(super) enum ResidualFilter {
    Plain(Stekf<STATES, MEASURED>),
    Recovering(Stekf<AUGMENTED, MEASURED>),
}

impl ResidualFilter {
    /// The pitch-rate innovation of one filter step (rad/s).
    pub(super) fn pitch_rate_residual(&mut self, model: &FilterModel, m: &Measurement) -> f64 {
        let input = FilterInput::new(m.t_s, m.gimbal_rad);
        let gamma = match self {
            ResidualFilter::Plain(f) => f.step(model, &m.y, &input).gamma,
            ResidualFilter::Recovering(f) => f.step(&WithMomentStates(model), &m.y, &input).gamma,
        };
        gamma[PITCH_RATE_MEASUREMENT]
    }

    pub(super) fn health(&self) -> FilterHealth {
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

    pub(super) fn filter(&self, x0: State, dt_s: f64) -> ResidualFilter {
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
