//! Method 004: control-surface fault detection and isolation by a bank of (strong-tracking) EKFs and
//! Bayesian model probabilities (Ma, Ni, Xie, Dong: improved strong-tracking multiple-model adaptive
//! estimation, after Ducard & Geering's EMMAE, JGCD 31(1), 2008). `docs/findings-seed004.md`.
//!
//! # The bank
//! Six filters on the reduced model of [`crate::vehicles::aerosonde`]: state `x = [p, q, r, alpha, beta]`
//! (rad/s, rad), measured directly (`H = [I 0]`), propagated by Euler steps
//! `x(k+1) = x(k) + dt f(x(k), Va, phi, theta, throttle, surfaces)` with the measured airspeed, roll and
//! pitch as known inputs and the autopilot's commanded deflections as the surfaces:
//! - filter 0, no fault: every surface at its command;
//! - filter i = 1..5, surface i-1 faulty: the state is augmented with that surface's position
//!   `delta`, which replaces its command in `f` and follows a random walk `delta(k+1) = delta(k) + w`.
//!
//! Filter noise as the seed: `R_W = 0.002 I5` on `x` (read as per second, see [`BankParams::seed`]),
//! `R_V = diag(0.1 I3, 0.02 I2)`. The surface random walk's intensity is not in the seed: with none,
//! a plain EKF's surface variance collapses and it cannot follow a surface that moves.
//!
//! The filters step as [`crate::estimation::Stekf`] in one of three covariance forms (plain EKF, the
//! original multiple-fading-factor STF, the improved symmetric one); their innovations feed the Bayes
//! recursion of [`crate::estimation::ModelProbabilities`] with the Gaussian or the Euclidean-norm
//! likelihood and the floor 0.001; [`crate::estimation::bank::DeclareClear`] turns probabilities into
//! declarations (0.9, held) and clearances (0.05, optionally held). The seed's four variants are combinations:
//!
//! | variant | covariance | likelihood |
//! |---|---|---|
//! | EMMAE (Ducard & Geering) | `ekf` | `gaussian` |
//! | EKF + fast probability | `ekf` | `euclidean_norm` |
//! | STMMAE | `strong_tracking` | `euclidean_norm` |
//! | improved STMMAE | `symmetric_strong_tracking` | `euclidean_norm` |
//!
//! STMMAE's likelihood is not stated in the seed (its table compares detection times of "STMMAE" next
//! to the fast-probability rows); the Euclidean-norm form is used so that STMMAE and the improved STMMAE
//! differ only in the covariance form.
#![allow(non_snake_case)]

use nalgebra::{SMatrix, SVector};

use crate::dual::{Dual, Real};
use crate::estimation::bank::{Decision, DecisionLevels, DeclareClear, held_s};
use crate::estimation::stekf::{FadingParams, FilterHealth, Innovation};
use crate::estimation::{DiscreteModel, Fading, FloorRule, LikelihoodForm, ModelProbabilities, Stekf};
use crate::vehicles::aerosonde::{
    AerosondeParams, ReducedInputs, SURFACES, reduced_derivatives, reduced_derivatives_at,
    reduced_rate_and_surface_columns,
};

/// Models in the bank: no fault, then one per surface.
pub const MODELS: usize = SURFACES + 1;

/// How each filter's predicted covariance is formed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CovarianceForm {
    Ekf,
    StrongTracking,
    SymmetricStrongTracking,
}

/// The bank's parameters; [`BankParams::seed`] gives the seed's numbers.
#[derive(Debug, Clone, PartialEq)]
pub struct BankParams {
    pub covariance: CovarianceForm,
    pub likelihood: LikelihoodForm,
    /// Diagonal of `R_W` on `[p, q, r, alpha, beta]`, per second: `Q = R_W dt` per step.
    pub process_variance_per_s: [f64; 5],
    /// Random-walk intensity of the augmented surface position (rad^2/s): `dt` times it per step.
    pub surface_process_variance_rad2_per_s: f64,
    /// Diagonal of `R_V` on the five measurements.
    pub measurement_variance: [f64; 5],
    /// Initial variance of the surface-position state (rad^2).
    pub initial_surface_variance_rad2: f64,
    /// Strong tracking: forgetting `rho`, weakening `beta`, prior weights `a` on the five states and
    /// `a_surface` on the surface position.
    pub rho: f64,
    pub beta: f64,
    pub a: [f64; 5],
    pub a_surface: f64,
    /// Floor, declaration (with its hold) and clearance of the models' probabilities.
    pub levels: DecisionLevels,
    /// The declared model's probability must stay below `clear_probability` this long before the
    /// declaration clears (0: the first sample below).
    pub clear_hold_s: f64,
    /// Which probabilities the floor raises: all below it at every step, or only those at 0 (the seed's words).
    pub floor_rule: FloorRule,
}

impl BankParams {
    /// The seed's numbers, and documented choices where it is silent:
    /// - `R_W = 0.002 I5` is read as a continuous-time intensity (per second; 2e-5 per 0.01 s step).
    ///   Read per step, it lets each filter's rates follow the measurements so closely that the
    ///   models' different dynamics hardly show in their innovations;
    /// - surface random walk 0.01 rad^2/s (0.1 rad per square-root second, so a filter can follow a
    ///   30 deg surface jump in about a second), initial surface variance (10 deg)^2;
    /// - `beta = 1`, `a_j = 1`, declaration held 0.1 s, clearance not held;
    /// - the floor raises every probability below it at every step (README: "The floor").
    pub fn seed(covariance: CovarianceForm, likelihood: LikelihoodForm) -> Self {
        BankParams {
            covariance,
            likelihood,
            process_variance_per_s: [0.002; 5],
            surface_process_variance_rad2_per_s: 0.01,
            measurement_variance: [0.1, 0.1, 0.1, 0.02, 0.02],
            initial_surface_variance_rad2: 10f64.to_radians().powi(2),
            rho: 0.95,
            beta: 1.0,
            a: [1.0; 5],
            a_surface: 1.0,
            levels: DecisionLevels::seed(),
            clear_hold_s: 0.0,
            floor_rule: FloorRule::EveryStep,
        }
    }

    /// Whether banks with `self` and `other` run the same six filters: the same covariance form and
    /// tuning (the fading factors' parameters only matter with strong tracking). Their likelihoods,
    /// floors and decision rules may differ.
    pub fn same_filters(&self, other: &BankParams) -> bool {
        let fading = |p: &BankParams| (p.rho, p.beta, p.a, p.a_surface);
        self.covariance == other.covariance
            && self.same_noise(other)
            && (self.covariance == CovarianceForm::Ekf || fading(self) == fading(other))
    }

    /// Whether a bank with `self` is strong tracking and its filters, while their fading factors are
    /// 1, step as those of an EKF bank with `ekf` ([`BankFilters::step_beside`]): the same noise
    /// tuning, which is all that sets the EKFs.
    pub fn tracks_beside(&self, ekf: &BankParams) -> bool {
        self.covariance != CovarianceForm::Ekf && ekf.covariance == CovarianceForm::Ekf && self.same_noise(ekf)
    }

    /// The same process, measurement and initial variances.
    fn same_noise(&self, other: &BankParams) -> bool {
        self.process_variance_per_s == other.process_variance_per_s
            && self.surface_process_variance_rad2_per_s == other.surface_process_variance_rad2_per_s
            && self.measurement_variance == other.measurement_variance
            && self.initial_surface_variance_rad2 == other.initial_surface_variance_rad2
    }

    fn fading<const N: usize>(&self) -> Fading<N> {
        let a = SVector::<f64, N>::from_fn(|j, _| if j < 5 { self.a[j] } else { self.a_surface });
        let params = FadingParams { rho: self.rho, beta: self.beta, a };
        match self.covariance {
            CovarianceForm::Ekf => Fading::None,
            CovarianceForm::StrongTracking => Fading::Original(params),
            CovarianceForm::SymmetricStrongTracking => Fading::Symmetric(params),
        }
    }
}

/// What the filters know at a step besides the measurement: the measured airspeed, roll, pitch, the
/// throttle and the commanded deflections.
#[derive(Debug, Clone, Copy)]
pub struct BankInput {
    pub inputs: ReducedInputs,
    pub commanded_rad: [f64; SURFACES],
}

/// Filter 0's model: every surface at its command.
struct NoFault<'a> {
    airframe: &'a AerosondeParams,
    /// `airframe.gammas()`, computed once per bank.
    gammas: &'a [f64; 8],
    dt_s: f64,
}

impl DiscreteModel<5, 5> for NoFault<'_> {
    type Input = BankInput;
    fn transition(&self, x: &SVector<f64, 5>, u: &BankInput) -> SVector<f64, 5> {
        x + self.dt_s * reduced_derivatives(self.airframe, x, &u.inputs, &u.commanded_rad)
    }
    fn transition_jacobian(&self, x: &SVector<f64, 5>, u: &BankInput) -> SMatrix<f64, 5, 5> {
        self.transition_with_jacobian(x, u).1
    }
    /// `f` and `I + dt df/dx`, exact ([`reduced_with_jacobian`]).
    fn transition_with_jacobian(&self, x: &SVector<f64, 5>, u: &BankInput) -> (SVector<f64, 5>, SMatrix<f64, 5, 5>) {
        let x5 = [x[0], x[1], x[2], x[3], x[4]];
        let (f, J) = reduced_with_jacobian(self.airframe, self.gammas, &x5, &u.inputs, &u.commanded_rad, None);
        (x + self.dt_s * SVector::from(f), SMatrix::identity() + self.dt_s * SMatrix::from_fn(|r, c| J[c][r]))
    }
    fn measurement(&self, x: &SVector<f64, 5>) -> SVector<f64, 5> {
        *x
    }
    fn measured_states(&self) -> Option<[usize; 5]> {
        Some([0, 1, 2, 3, 4])
    }
}

/// The reduced model's derivatives `f` at `x5` and their Jacobian's columns `[d/dp, d/dq, d/dr,
/// d/dalpha, d/dbeta, d/ds]` (`s`: `surface`'s position; zero without one), exact: alpha and beta by
/// dual numbers over those two (the only inputs the model is not linear in), the others written out
/// ([`reduced_rate_and_surface_columns`]). The values are the `f64` evaluation's and the columns those
/// of dual numbers over all six inputs, to the bit (tested), at about half the cost.
fn reduced_with_jacobian(
    airframe: &AerosondeParams,
    gammas: &[f64; 8],
    x5: &[f64; 5],
    inputs: &ReducedInputs,
    surfaces_rad: &[f64; SURFACES],
    surface: Option<usize>,
) -> ([f64; 5], [[f64; 5]; 6]) {
    let duals =
        [Dual::cst(x5[0]), Dual::cst(x5[1]), Dual::cst(x5[2]), Dual::<2>::input(x5[3], 0), Dual::input(x5[4], 1)];
    let (f, point) = reduced_derivatives_at(airframe, gammas, &duals, inputs, &surfaces_rad.map(Dual::cst));
    let [p, q, r, s] = reduced_rate_and_surface_columns(airframe, gammas, x5, inputs, &point, surface);
    let (alpha, beta) = (f.map(|e| e.d[0]), f.map(|e| e.d[1]));
    (f.map(|e| e.v), [p, q, r, alpha, beta, s])
}

/// Filter i's model: surface i at the augmented state's position.
struct SurfaceFault<'a> {
    airframe: &'a AerosondeParams,
    gammas: &'a [f64; 8],
    dt_s: f64,
    surface: usize,
}

impl DiscreteModel<6, 5> for SurfaceFault<'_> {
    type Input = BankInput;
    fn transition(&self, x: &SVector<f64, 6>, u: &BankInput) -> SVector<f64, 6> {
        let mut surfaces = u.commanded_rad;
        surfaces[self.surface] = x[5];
        let x5 = x.fixed_rows::<5>(0).into_owned();
        let next = x5 + self.dt_s * reduced_derivatives(self.airframe, &x5, &u.inputs, &surfaces);
        SVector::<f64, 6>::from_fn(|j, _| if j < 5 { next[j] } else { x[5] })
    }
    fn transition_jacobian(&self, x: &SVector<f64, 6>, u: &BankInput) -> SMatrix<f64, 6, 6> {
        self.transition_with_jacobian(x, u).1
    }
    /// `f` and `[I + dt df/dx5, dt df/ds; 0, 1]` (`s`: the surface's position), exact
    /// ([`reduced_with_jacobian`]).
    fn transition_with_jacobian(&self, x: &SVector<f64, 6>, u: &BankInput) -> (SVector<f64, 6>, SMatrix<f64, 6, 6>) {
        let mut surfaces = u.commanded_rad;
        surfaces[self.surface] = x[5];
        let x5 = [x[0], x[1], x[2], x[3], x[4]];
        let (f, J) = reduced_with_jacobian(self.airframe, self.gammas, &x5, &u.inputs, &surfaces, Some(self.surface));
        let next = SVector::from_fn(|r, _| if r < 5 { x[r] + self.dt_s * f[r] } else { x[5] });
        let jacobian = SMatrix::from_fn(|r, c| f64::from(r == c) + if r < 5 { self.dt_s * J[c][r] } else { 0.0 });
        (next, jacobian)
    }
    fn measurement(&self, x: &SVector<f64, 6>) -> SVector<f64, 5> {
        x.fixed_rows::<5>(0).into_owned()
    }
    fn measured_states(&self) -> Option<[usize; 5]> {
        Some([0, 1, 2, 3, 4])
    }
}

/// One step's output of the bank.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BankStep {
    /// Model probabilities after this step (index 0: no fault, i: surface i-1).
    pub probabilities: [f64; MODELS],
    /// Filter i's estimate of surface i-1's position (rad), after this step's update.
    pub surface_estimates_rad: [f64; SURFACES],
    /// The probability-weighted estimate of `[p, q, r, alpha, beta]`.
    pub blended: SVector<f64, 5>,
    /// A declaration or clearance made at this step.
    pub decision: Option<Decision>,
    /// The decision statistic: how long (s) a surface model's probability has stayed above
    /// `declare_probability` ([`DeclareClear::held_samples`]), and that surface (0-based).
    pub held_s: f64,
    pub held_surface: Option<usize>,
}

/// The six filters of a bank: they depend on the bank's covariance form and tuning, not on its
/// likelihood or decision rule, so banks that differ only there can share one set
/// ([`BankParams::same_filters`]) and get the same numbers.
#[derive(Debug, Clone)]
pub struct BankFilters {
    airframe: AerosondeParams,
    /// `airframe.gammas()`, which the six filters' model evaluations would each recompute.
    gammas: [f64; 8],
    dt_s: f64,
    no_fault: Stekf<5, 5>,
    surfaces: [Stekf<6, 5>; SURFACES],
    /// Per filter (0: no fault, i: surface i-1), whether it has taken an EKF's step at every step so
    /// far ([`BankFilters::step_beside`]).
    beside: [bool; MODELS],
}

impl BankFilters {
    /// The filters of a bank with `params` on the design airframe `airframe` (the detector's model,
    /// which may differ from the truth), started at the first measurement `y0` with the surfaces at
    /// `initial_surfaces_rad` (their trim).
    pub fn new(
        params: &BankParams,
        airframe: AerosondeParams,
        dt_s: f64,
        y0: &SVector<f64, 5>,
        initial_surfaces_rad: &[f64; SURFACES],
    ) -> Self {
        let Q5 = SMatrix::<f64, 5, 5>::from_diagonal(&SVector::from(params.process_variance_per_s)) * dt_s;
        let R = SMatrix::<f64, 5, 5>::from_diagonal(&SVector::from(params.measurement_variance));
        let P5 = R;
        let no_fault = Stekf::new(*y0, P5, Q5, R, params.fading());
        let surfaces = std::array::from_fn(|i| {
            let x0 = SVector::<f64, 6>::from_fn(|j, _| if j < 5 { y0[j] } else { initial_surfaces_rad[i] });
            let mut P0 = SMatrix::<f64, 6, 6>::zeros();
            P0.fixed_view_mut::<5, 5>(0, 0).copy_from(&P5);
            P0[(5, 5)] = params.initial_surface_variance_rad2;
            let mut Q = SMatrix::<f64, 6, 6>::zeros();
            Q.fixed_view_mut::<5, 5>(0, 0).copy_from(&Q5);
            Q[(5, 5)] = params.surface_process_variance_rad2_per_s * dt_s;
            Stekf::new(x0, P0, Q, R, params.fading())
        });
        BankFilters { gammas: airframe.gammas(), airframe, dt_s, no_fault, surfaces, beside: [true; MODELS] }
    }

    /// Every filter updates with `y` and predicts with `input`; the banks read the step through
    /// [`Self::innovation`] and [`Self::estimates`].
    pub fn step(&mut self, y: &SVector<f64, 5>, input: &BankInput) {
        let (airframe, gammas, dt_s) = (&self.airframe, &self.gammas, self.dt_s);
        self.no_fault.step(&NoFault { airframe, gammas, dt_s }, y, input);
        for (surface, filter) in self.surfaces.iter_mut().enumerate() {
            filter.step(&SurfaceFault { airframe, gammas, dt_s, surface }, y, input);
        }
        self.beside = [false; MODELS];
    }

    /// [`BankFilters::step`] beside `ekf`, the filters of an EKF bank with this bank's noise tuning
    /// ([`BankParams::tracks_beside`]) on the same airframe, started with these and already stepped on
    /// `y` and `input`, and only on those: each filter that has taken the EKF's step at every step so
    /// far takes it again if its fading factors are all 1, where its step is the EKF's to the bit
    /// ([`Stekf::step_beside`]); the others step themselves. Before a fault the seed deck's strong
    /// tracking hardly ever fades, so its two strong-tracking banks cost little more than their
    /// fading factors until the onset.
    pub fn step_beside(&mut self, ekf: &BankFilters, y: &SVector<f64, 5>, input: &BankInput) {
        /// `filter`'s step beside `ekf` while it has taken the EKF's every step (`*beside`), its own after.
        fn one<const N: usize, D: DiscreteModel<N, 5, Input = BankInput>>(
            filter: &mut Stekf<N, 5>,
            ekf: &Stekf<N, 5>,
            beside: &mut bool,
            model: &D,
            y: &SVector<f64, 5>,
            input: &BankInput,
        ) {
            if *beside {
                *beside = filter.step_beside(ekf, model, y, input);
            } else {
                filter.step(model, y, input);
            }
        }
        let (airframe, gammas, dt_s) = (&self.airframe, &self.gammas, self.dt_s);
        one(&mut self.no_fault, &ekf.no_fault, &mut self.beside[0], &NoFault { airframe, gammas, dt_s }, y, input);
        for (surface, filter) in self.surfaces.iter_mut().enumerate() {
            let model = SurfaceFault { airframe, gammas, dt_s, surface };
            one(filter, &ekf.surfaces[surface], &mut self.beside[surface + 1], &model, y, input);
        }
    }

    /// How many of the six filters took an EKF's step at the last [`BankFilters::step_beside`] (for tests).
    #[cfg(test)]
    fn steps_taken_beside(&self) -> usize {
        self.beside.iter().filter(|&&b| b).count()
    }

    /// Filter `model`'s innovation at the last step (0: no fault, i: surface i-1).
    pub fn innovation(&self, model: usize) -> &Innovation<5> {
        match model {
            0 => self.no_fault.innovation(),
            i => self.surfaces[i - 1].innovation(),
        }
    }

    /// Each filter's estimate of `[p, q, r, alpha, beta]` after the last step's update.
    pub fn estimates(&self) -> [SVector<f64, 5>; MODELS] {
        std::array::from_fn(|i| match i {
            0 => *self.no_fault.estimate(),
            i => self.surfaces[i - 1].estimate().fixed_rows::<5>(0).into_owned(),
        })
    }

    /// Filter i's estimate of surface i-1's position (rad).
    pub fn surface_estimates_rad(&self) -> [f64; SURFACES] {
        std::array::from_fn(|i| self.surfaces[i].estimate()[5])
    }

    /// The six filters' health counters, summed.
    pub fn health(&self) -> FilterHealth {
        self.surfaces.iter().map(Stekf::health).fold(self.no_fault.health(), |a, b| FilterHealth {
            singular_innovation: a.singular_innovation + b.singular_innovation,
            asymmetric: a.asymmetric + b.asymmetric,
            not_positive_definite: a.not_positive_definite + b.not_positive_definite,
            non_finite: a.non_finite + b.non_finite,
        })
    }
}

/// A bank's probabilities and decision rule, on the innovations of its six filters ([`BankFilters`],
/// which banks with the same filters share); see the module docs.
#[derive(Debug, Clone)]
pub struct SurfaceBank {
    dt_s: f64,
    likelihood: LikelihoodForm,
    probabilities: ModelProbabilities<MODELS>,
    rule: DeclareClear,
}

impl SurfaceBank {
    /// A bank with equal prior probabilities.
    pub fn new(params: &BankParams, dt_s: f64) -> Self {
        SurfaceBank {
            dt_s,
            likelihood: params.likelihood,
            probabilities: ModelProbabilities::new([1.0 / MODELS as f64; MODELS], params.levels.probability_floor)
                .with_floor_rule(params.floor_rule),
            rule: params.levels.rule(params.clear_hold_s, dt_s),
        }
    }

    /// One sample: the probabilities and the decision rule on one step of the filters.
    pub fn step(&mut self, filters: &BankFilters) -> BankStep {
        let log_likelihood: [f64; MODELS] =
            std::array::from_fn(|i| self.likelihood.log_likelihood(filters.innovation(i)));
        self.probabilities.update(&log_likelihood);
        let probabilities = *self.probabilities.probabilities();
        let decision = self.rule.observe(&probabilities);
        let (held, model) = self.rule.held_samples();
        BankStep {
            held_s: held_s(held, self.dt_s),
            held_surface: model.map(|i| i - 1),
            probabilities,
            surface_estimates_rad: filters.surface_estimates_rad(),
            blended: self.probabilities.blend(&filters.estimates()),
            decision,
        }
    }

    /// The surface currently declared faulty (0-based), if any.
    pub fn declared_surface(&self) -> Option<usize> {
        self.rule.declared().map(|i| i - 1)
    }

    /// Steps on which the probability floor was applied.
    pub fn floor_steps(&self) -> u32 {
        self.probabilities.floor_steps
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::estimation::stekf::central_difference;
    use crate::vehicles::aerosonde::{air_data, reduced_derivatives_of, trim};

    /// States `[p, q, r, alpha, beta, surface]` around the trim and far from it (rates up to 1 rad/s,
    /// alpha and beta to +-0.3 rad, a surface at 20 deg), and the inputs at state k (airspeed 18 to 30 m/s).
    const STATES: [[f64; 6]; 4] = [
        [0.0, 0.0, 0.0, 0.05, 0.0, 0.0],
        [0.3, -0.2, 0.1, 0.12, -0.05, 0.1],
        [-1.0, 0.8, -0.6, -0.3, 0.3, -0.35],
        [0.5, 0.5, 0.5, 0.3, -0.3, 0.35],
    ];
    const COMMANDED_RAD: [f64; SURFACES] = [0.05, -0.05, -0.1, -0.08, 0.02];

    fn inputs_at(k: usize) -> ReducedInputs {
        ReducedInputs::new(18.0 + 4.0 * k as f64, 0.2, -0.1, 0.6)
    }

    /// The filters' exact Jacobians against central differences of their transitions at [`STATES`]:
    /// equal to the differences' own error, about 1e-8 relative to the entry scale.
    #[test]
    fn exact_jacobians_match_central_differences() {
        let airframe = AerosondeParams::default();
        let dt_s = 0.01;
        for (k, x) in STATES.iter().enumerate() {
            let u = BankInput { inputs: inputs_at(k), commanded_rad: COMMANDED_RAD };
            let x5 = SVector::<f64, 5>::from_fn(|i, _| x[i]);
            let model = NoFault { airframe: &airframe, gammas: &airframe.gammas(), dt_s };
            let (exact, numeric) =
                (model.transition_jacobian(&x5, &u), central_difference(&x5, |x| model.transition(x, &u)));
            assert!((exact - numeric).amax() < 1e-8 * exact.amax(), "state {k}: {exact} vs {numeric}");
            // The dual evaluation's values are the plain one's to the bit: the records do not move.
            assert_eq!(model.transition_with_jacobian(&x5, &u).0, model.transition(&x5, &u));
            for surface in 0..SURFACES {
                let x6 = SVector::<f64, 6>::from_fn(|i, _| x[i]);
                let model = SurfaceFault { airframe: &airframe, gammas: &airframe.gammas(), dt_s, surface };
                let (exact, numeric) =
                    (model.transition_jacobian(&x6, &u), central_difference(&x6, |x| model.transition(x, &u)));
                assert!(
                    (exact - numeric).amax() < 1e-8 * exact.amax(),
                    "state {k}, surface {surface}: {exact} vs {numeric}"
                );
                assert_eq!(model.transition_with_jacobian(&x6, &u).0, model.transition(&x6, &u));
                // The surface's own column is not zero: the position moves the rates.
                assert!(exact.column(5).rows(0, 3).amax() > 1e-6, "surface {surface}: {exact}");
            }
        }
    }
    use rand::SeedableRng;
    use rand::rngs::ChaCha8Rng;
    use rand_distr::{Distribution, Normal};

    /// The Jacobian's columns against dual numbers over all six inputs (how they were formed before),
    /// to the bit, values included, at [`STATES`], for the no-fault model and each surface: the records
    /// do not move.
    #[test]
    fn written_out_columns_are_the_all_dual_jacobians() {
        use crate::dual::value_and_jacobian;
        let airframe = AerosondeParams::default();
        for (k, x) in STATES.iter().enumerate() {
            let (inputs, commanded) = (inputs_at(k), COMMANDED_RAD);
            for surface in [None, Some(0), Some(1), Some(2), Some(3), Some(4)] {
                let mut surfaces = commanded;
                if let Some(i) = surface {
                    surfaces[i] = x[5];
                }
                let x6 = SVector::<f64, 6>::from_fn(|i, _| x[i]);
                let (f_all, J_all) = value_and_jacobian(&x6, |d| {
                    let mut s = commanded.map(Dual::cst);
                    if let Some(i) = surface {
                        s[i] = d[5];
                    }
                    SVector::from(reduced_derivatives_of(&airframe, &[d[0], d[1], d[2], d[3], d[4]], &inputs, &s))
                });
                let x5 = [x[0], x[1], x[2], x[3], x[4]];
                let (f, J) = reduced_with_jacobian(&airframe, &airframe.gammas(), &x5, &inputs, &surfaces, surface);
                let what = format!("state {k}, surface {surface:?}");
                assert_eq!(SVector::from(f), f_all, "{what}");
                for (c, column) in J.iter().enumerate() {
                    assert_eq!(SVector::from(*column), J_all.column(c), "{what}, column {c}");
                }
                // Without a surface, its column is zero; with one, the surface moves the rates.
                assert_eq!(J[5] == [0.0; 5], surface.is_none(), "{what}");
            }
        }
    }

    /// The flight of these tests: the filters' own reduced model (Euler, 100 Hz) at the 25 m/s trim,
    /// with the seed's sensor noise (seed 7) and one surface moved off its command from an onset on.
    struct TrimFlight {
        airframe: AerosondeParams,
        trim_surfaces: [f64; SURFACES],
        input: BankInput,
        truth: SVector<f64, 5>,
        rng: ChaCha8Rng,
    }

    impl TrimFlight {
        const DT_S: f64 = 0.01;

        fn new() -> Self {
            let airframe = AerosondeParams::default();
            let (x, trim_surfaces, throttle) = trim(&airframe, 25.0, 100.0).unwrap();
            let (va, alpha, beta) = air_data(&x, &nalgebra::Vector3::zeros());
            let inputs = ReducedInputs::new(va, 0.0, x[7], throttle);
            let truth = SVector::<f64, 5>::new(0.0, 0.0, 0.0, alpha, beta);
            let input = BankInput { inputs, commanded_rad: trim_surfaces };
            TrimFlight { airframe, trim_surfaces, input, truth, rng: ChaCha8Rng::seed_from_u64(7) }
        }

        fn measure(&mut self) -> SVector<f64, 5> {
            let variance = [0.0076, 0.0076, 0.0076, 0.0012, 0.0012];
            SVector::<f64, 5>::from_fn(|j, _| {
                self.truth[j] + Normal::new(0.0, f64::sqrt(variance[j])).unwrap().sample(&mut self.rng)
            })
        }

        fn filters(&mut self, params: &BankParams, y0: &SVector<f64, 5>) -> BankFilters {
            BankFilters::new(params, self.airframe.clone(), Self::DT_S, y0, &self.trim_surfaces)
        }

        /// One step of the truth from `t`, `surface` moved by `offset_rad` once `t >= onset_s`.
        fn advance(&mut self, t: f64, surface: usize, offset_rad: f64, onset_s: f64) {
            let mut actual = self.trim_surfaces;
            if t >= onset_s {
                actual[surface] += offset_rad;
            }
            self.truth += Self::DT_S * reduced_derivatives(&self.airframe, &self.truth, &self.input.inputs, &actual);
        }
    }

    /// The decisions of a bank with `params` on a [`TrimFlight`] with `surface` moved by `offset_rad`
    /// from `onset_s` on while its command stays at trim, with the step at which each was made.
    fn isolate(
        params: &BankParams,
        surface: usize,
        offset_rad: f64,
        onset_s: f64,
        seconds: f64,
    ) -> Vec<(f64, Decision)> {
        let mut flight = TrimFlight::new();
        let y0 = flight.measure();
        let mut filters = flight.filters(params, &y0);
        let mut bank = SurfaceBank::new(params, TrimFlight::DT_S);
        let mut decisions = Vec::new();
        for k in 0..(seconds / TrimFlight::DT_S) as usize {
            let t = k as f64 * TrimFlight::DT_S;
            filters.step(&flight.measure(), &flight.input);
            let step = bank.step(&filters);
            if let Some(d) = step.decision {
                decisions.push((t, d));
            }
            flight.advance(t, surface, offset_rad, onset_s);
        }
        decisions
    }

    #[test]
    fn each_surface_is_isolated_by_every_variant() {
        // Surface moved 8 deg off its command at 1 s. Measured here (seed 7): EMMAE declares after
        // 1.62, 1.62, 4.13, 3.48, 0.25 s; the Euclidean-norm variants after 1.87, 1.87, 2.92, 2.58, 0.19 s
        // (before the fault the fading factors stay 1, the seed's R_V being 13x the gyros' true noise
        // variance; after it some rise: strong_tracking_beside_an_ekf_is_strong_tracking_alone).
        for (covariance, likelihood) in [
            (CovarianceForm::Ekf, LikelihoodForm::Gaussian),
            (CovarianceForm::Ekf, LikelihoodForm::EuclideanNorm),
            (CovarianceForm::StrongTracking, LikelihoodForm::EuclideanNorm),
            (CovarianceForm::SymmetricStrongTracking, LikelihoodForm::EuclideanNorm),
        ] {
            let params = BankParams::seed(covariance, likelihood);
            for surface in 0..SURFACES {
                let decisions = isolate(&params, surface, (-8f64).to_radians(), 1.0, 8.0);
                let what = format!("{covariance:?} {likelihood:?} surface {surface}: {decisions:?}");
                let &(t, first) = decisions.first().unwrap_or_else(|| panic!("{what}"));
                assert_eq!(first, Decision::Declared(surface + 1), "{what}");
                assert!((1.0..6.0).contains(&t), "{what}");
                assert_eq!(decisions.len(), 1, "no clearance or switch while the fault persists: {what}");
            }
        }
    }

    /// A [`TrimFlight`] with `surface` moved by `offset_rad` from `onset_s` on: an EKF bank's filters
    /// with `ekf`, a strong-tracking bank's with `tracking` stepped beside them, and the same stepped
    /// alone. Every step, the filters beside give the filters alone to the bit (innovations, estimates,
    /// health); returns how many of the six took the EKF's step at each step.
    fn beside_and_alone(
        ekf: &BankParams,
        tracking: &BankParams,
        surface: usize,
        offset_rad: f64,
        onset_s: f64,
        seconds: f64,
    ) -> Vec<usize> {
        assert!(tracking.tracks_beside(ekf));
        let mut flight = TrimFlight::new();
        let y0 = flight.measure();
        let (mut by_ekf, mut beside, mut alone) =
            (flight.filters(ekf, &y0), flight.filters(tracking, &y0), flight.filters(tracking, &y0));
        let mut taken = Vec::new();
        for k in 0..(seconds / TrimFlight::DT_S) as usize {
            let t = k as f64 * TrimFlight::DT_S;
            let (y, input) = (flight.measure(), &flight.input);
            by_ekf.step(&y, input);
            beside.step_beside(&by_ekf, &y, input);
            alone.step(&y, input);
            for m in 0..MODELS {
                assert_eq!(format!("{:?}", beside.innovation(m)), format!("{:?}", alone.innovation(m)), "{t} s");
            }
            assert_eq!(format!("{:?}", beside.estimates()), format!("{:?}", alone.estimates()), "{t} s");
            let bits = |f: &BankFilters| f.surface_estimates_rad().map(f64::to_bits);
            assert_eq!(bits(&beside), bits(&alone), "{t} s");
            assert_eq!(beside.health(), alone.health());
            taken.push(beside.steps_taken_beside());
            flight.advance(t, surface, offset_rad, onset_s);
        }
        taken
    }

    /// Strong-tracking filters beside an EKF bank's are the strong-tracking filters alone, to the bit,
    /// on the seed's tuning with an 8 deg elevator fault from 1 s, both while they take the EKF's steps
    /// and after their fading factors first leave 1 (measured, either form: all six take the EKF's
    /// step until 1.31 s, three still do at the end, 4 s).
    #[test]
    fn strong_tracking_beside_an_ekf_is_strong_tracking_alone() {
        for form in [CovarianceForm::StrongTracking, CovarianceForm::SymmetricStrongTracking] {
            let ekf = BankParams::seed(CovarianceForm::Ekf, LikelihoodForm::Gaussian);
            let tracking = BankParams::seed(form, LikelihoodForm::EuclideanNorm);
            let taken = beside_and_alone(&ekf, &tracking, 1, (-8f64).to_radians(), 1.0, 4.0);
            let all_until = taken.iter().position(|&n| n < MODELS);
            assert_eq!((all_until, taken[taken.len() - 1]), (Some(131), 3), "{form:?}");
        }
    }
}
