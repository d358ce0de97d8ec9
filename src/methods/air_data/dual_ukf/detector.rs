//! The dual UKF detector of method 002: both filters stepped, the model probabilities, the
//! declaration, the chi-square isolation and the selective re-initialisation (module docs of
//! [`super`], steps 1-5).
#![allow(non_snake_case)]

use nalgebra::{SMatrix, SVector, Vector3};

use super::chi_square::*;
use super::models::*;
use super::params::*;
use crate::estimation::bank::{Decision, DeclareClear, held_s};
use crate::estimation::stekf::central_difference;
use crate::estimation::ukf::{Ukf, UkfHealth};
use crate::estimation::{Innovation, ModelProbabilities};
use crate::methods::air_data::flight::{
    AirData, Inertial, InertialInterval, air_data_from_velocity, velocity_derivative_input_jacobian,
    velocity_from_air_data,
};

/// How the fault model's bias component was re-initialised at the last step (module docs, step 4).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BiasMode {
    /// 0 with the initial variance: "a fault may be here".
    Open,
    /// Kept: the sensor is isolated as faulty and its bias is being estimated.
    Estimated,
    /// 0 with one step of random-walk variance: the sensor is trusted.
    Healthy,
}

/// One step's outputs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DualUkfStep {
    /// `[no fault, fault]` after this step's Bayes update; they sum to 1.
    pub probabilities: [f64; MODELS],
    /// A fault is declared (after this step's decision).
    pub fault_declared: bool,
    /// Declared or cleared at this step.
    pub decision: Option<Decision>,
    /// The decision statistic: how long (s) the fault model's probability has stayed above
    /// `declare_probability` ([`DeclareClear::held_samples`]); the fault is declared when it exceeds
    /// the threshold the declaration hold sets ([`crate::estimation::bank::held_threshold_s`]) with no
    /// declaration standing.
    pub held_s: f64,
    /// Both models were re-initialised at this step (a fault is present: declared, or the fault model's
    /// probability above `declare_probability`); otherwise only the fault model.
    pub both_reinitialised: bool,
    /// Isolation statistic per component (airspeed, alpha, beta): the window sum of `gamma_j^2 / S_jj`
    /// of the no-fault filter; NaN where that filter's update was skipped.
    pub chi_square: [f64; COMPONENTS],
    /// The threshold it was compared with (chi-square with as many degrees of freedom as samples summed).
    pub chi_square_threshold: f64,
    /// `chi_square > chi_square_threshold`: the patent's isolation of the faulty source.
    pub isolated: [bool; COMPONENTS],
    /// How each bias was re-initialised (step 4 of the module docs); `Estimated` = in the faulty set.
    pub bias_modes: [BiasMode; COMPONENTS],
    /// Probability-weighted air data.
    pub air_data: AirData,
    /// Probability-weighted bias estimate `p_1 b` (m/s, rad, rad).
    pub bias: [f64; COMPONENTS],
    /// The fault model's own bias estimate after this step's update, before re-initialisation.
    pub fault_model_bias: [f64; COMPONENTS],
}

/// Numerical-health and bookkeeping counters over a run.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct DualUkfHealth {
    pub no_fault: UkfHealth,
    pub fault: UkfHealth,
    /// Steps on which the probability floor was applied.
    pub probability_floor_steps: u32,
    /// Steps on which neither model had a usable likelihood (probabilities kept).
    pub probability_skipped_steps: u32,
    /// Steps on which only the fault model was re-initialised (no fault present).
    pub fault_model_reinitialisations: u32,
    /// Steps on which both models were re-initialised (a fault present).
    pub both_models_reinitialisations: u32,
}

/// The dual-model detector; see the module docs.
#[derive(Debug, Clone)]
pub struct DualUkf {
    params: DualUkfParams,
    dt_s: f64,
    no_fault: Ukf<3, 3>,
    fault: Ukf<6, 3>,
    probabilities: ModelProbabilities<MODELS>,
    rule: DeclareClear,
    /// `thresholds[c - 1]`: chi-square(c) quantile at `1 - P_fa`.
    thresholds: Vec<f64>,
    /// Last `isolation_window` per-sample statistics, a ring.
    history: Vec<[f64; COMPONENTS]>,
    history_next: usize,
    history_filled: usize,
    bias_modes: [BiasMode; COMPONENTS],
    /// The previous inertial sample; `None` before the first step.
    previous_inertial: Option<Inertial>,
    fault_model_reinitialisations: u32,
    both_models_reinitialisations: u32,
}

impl DualUkf {
    /// A detector sampling every `dt_s`; it initialises itself from the first air-data sample it steps.
    pub fn new(params: &DualUkfParams, dt_s: f64) -> Result<Self, DualUkfError> {
        params.validate()?;
        if !(dt_s > 0.0 && dt_s.is_finite()) {
            return Err(DualUkfError::SamplePeriod(dt_s));
        }
        let thresholds: Vec<f64> = (1..=params.isolation_window)
            .map(|c| chi_square_threshold(c as u32, params.false_alarm_probability))
            .collect();
        let R = SMatrix::<f64, 3, 3>::from_diagonal(&Vector3::from(params.noise.air_data_std().map(|s| s * s)));
        let no_fault = Ukf::new(Vector3::zeros(), SMatrix::identity(), SMatrix::zeros(), R, &params.unscented)?;
        let fault = Ukf::new(SVector::zeros(), SMatrix::identity(), SMatrix::zeros(), R, &params.unscented)?;
        let prior = params.prior_fault_probability;
        Ok(DualUkf {
            dt_s,
            no_fault,
            fault,
            probabilities: ModelProbabilities::new([1.0 - prior, prior], params.levels.probability_floor),
            // Cleared at the first sample below the lower level: the patent names no clearing hold.
            rule: params.levels.rule(0.0, dt_s),
            history: vec![[0.0; COMPONENTS]; params.isolation_window],
            thresholds,
            history_next: 0,
            history_filled: 0,
            bias_modes: [BiasMode::Open; COMPONENTS],
            previous_inertial: None,
            fault_model_reinitialisations: 0,
            both_models_reinitialisations: 0,
            params: params.clone(),
        })
    }

    pub fn params(&self) -> &DualUkfParams {
        &self.params
    }

    /// The per-sample isolation threshold, chi-square(1) at `1 - P_fa`.
    pub fn isolation_threshold(&self) -> f64 {
        self.thresholds[0]
    }

    /// The threshold of the full isolation window, chi-square(n) at `1 - P_fa`.
    pub fn window_threshold(&self) -> f64 {
        self.thresholds[self.thresholds.len() - 1]
    }

    /// The no-fault filter (after the last step's re-initialisation).
    pub fn no_fault_filter(&self) -> &Ukf<3, 3> {
        &self.no_fault
    }

    /// The fault filter (after the last step's re-initialisation).
    pub fn fault_filter(&self) -> &Ukf<6, 3> {
        &self.fault
    }

    pub fn fault_declared(&self) -> bool {
        self.rule.declared().is_some()
    }

    pub fn health(&self) -> DualUkfHealth {
        DualUkfHealth {
            no_fault: self.no_fault.health(),
            fault: self.fault.health(),
            probability_floor_steps: self.probabilities.floor_steps,
            probability_skipped_steps: self.probabilities.skipped_steps,
            fault_model_reinitialisations: self.fault_model_reinitialisations,
            both_models_reinitialisations: self.both_models_reinitialisations,
        }
    }

    /// One sample: the inertial data `inertial` and the air data `air` taken at the same time.
    pub fn step(&mut self, inertial: &Inertial, air: &AirData) -> DualUkfStep {
        let innovation = self.filter(inertial, air);
        self.decide(air, innovation.as_ref())
    }

    /// Whether `other`'s filters step as this detector's do: their parameters differ at most in the
    /// isolation settings (`false_alarm_probability`, `isolation_window`, `keep_significant_biases`),
    /// which enter only [`DualUkf::decide`].
    pub fn filters_like(&self, other: &DualUkf) -> bool {
        let filtering = |p: &DualUkfParams| DualUkfParams {
            false_alarm_probability: 0.0,
            isolation_window: 1,
            keep_significant_biases: false,
            ..p.clone()
        };
        self.dt_s == other.dt_s && filtering(&self.params) == filtering(&other.params)
    }

    /// Whether `other`'s [`DualUkf::filter`] would now give this detector's to the bit, for two detectors
    /// whose filters are [`DualUkf::filters_like`] (the caller checks that once, not at every sample):
    /// their states, covariances, model probabilities, health counters and last inertial sample have the
    /// same bits. The seed deck's three detectors are so until their first step with a fault present
    /// and, when their isolations agree there, after it.
    pub fn same_filters(&self, other: &DualUkf) -> bool {
        fn same_ukf<const N: usize, const M: usize>(a: &Ukf<N, M>, b: &Ukf<N, M>) -> bool {
            same_bits(a.state().as_slice(), b.state().as_slice())
                && same_bits(a.covariance().as_slice(), b.covariance().as_slice())
                && a.health() == b.health()
        }
        let (p, q) = (&self.probabilities, &other.probabilities);
        same_ukf(&self.no_fault, &other.no_fault)
            && same_ukf(&self.fault, &other.fault)
            && same_bits(p.probabilities(), q.probabilities())
            && (p.floor_steps, p.skipped_steps) == (q.floor_steps, q.skipped_steps)
            && match (&self.previous_inertial, &other.previous_inertial) {
                (None, None) => true,
                (Some(a), Some(b)) => same_bits(&a.to_array(), &b.to_array()),
                _ => false,
            }
    }

    /// The first part of [`DualUkf::step`], which the isolation settings do not enter: both filters'
    /// prediction and update and the model probabilities (at the first sample, the initialisation).
    /// Returns the no-fault innovation for [`DualUkf::decide`]; none at the first sample.
    pub fn filter(&mut self, inertial: &Inertial, air: &AirData) -> Option<Innovation<3>> {
        let Some(previous) = self.previous_inertial.replace(*inertial) else {
            self.initialise(air);
            return None;
        };
        self.predict(&InertialInterval::new(previous, *inertial));
        let y = air.to_vector();
        let nf_model = NoFaultModel { dt_s: self.dt_s };
        let f_model = FaultModel { dt_s: self.dt_s };
        let nf_innovation = self.no_fault.update(&nf_model, &y);
        let f_innovation = self.fault.update(&f_model, &y);
        let likelihood = self.params.likelihood;
        self.probabilities
            .update(&[likelihood.log_likelihood(&nf_innovation), likelihood.log_likelihood(&f_innovation)]);
        Some(nf_innovation)
    }

    /// Takes `leader`'s filters and model probabilities after its [`DualUkf::filter`] in place of this
    /// detector's own [`DualUkf::filter`]: the same numbers when the two had
    /// [`DualUkf::same_filters`] before it.
    pub fn follow(&mut self, leader: &DualUkf) {
        self.no_fault.clone_from(&leader.no_fault);
        self.fault.clone_from(&leader.fault);
        self.probabilities.clone_from(&leader.probabilities);
        self.previous_inertial = leader.previous_inertial;
    }

    /// The second part of [`DualUkf::step`]: the declaration, the isolation, the re-initialisation and
    /// the outputs, from the no-fault `innovation` that [`DualUkf::filter`] returned.
    pub fn decide(&mut self, air: &AirData, innovation: Option<&Innovation<3>>) -> DualUkfStep {
        let Some(nf_innovation) = innovation else {
            return DualUkfStep {
                probabilities: *self.probabilities.probabilities(),
                fault_declared: false,
                decision: None,
                held_s: 0.0,
                both_reinitialised: false,
                chi_square: [0.0; COMPONENTS],
                chi_square_threshold: self.thresholds[0],
                isolated: [false; COMPONENTS],
                bias_modes: self.bias_modes,
                air_data: *air,
                bias: [0.0; COMPONENTS],
                fault_model_bias: [0.0; COMPONENTS],
            };
        };
        let probabilities = *self.probabilities.probabilities();
        let decision = self.rule.observe(&probabilities);
        let fault_declared = self.fault_declared();

        let (chi_square, chi_square_threshold) = self.isolation_statistic(nf_innovation);
        let isolated = chi_square.map(|t| t > chi_square_threshold);
        let fault_model_bias = self.bias_estimate();
        // The patent judges the fault from the model probabilities at each step; the hold of the
        // declaration is for the alarm only (module docs, step 4).
        let fault_present = fault_declared || probabilities[1] > self.params.levels.declare_probability;
        if fault_present {
            self.reinitialise_both(&isolated);
        } else {
            self.reinitialise_fault_model();
        }

        let p = probabilities;
        let velocity = self.no_fault.state() * p[0] + self.fault.state().fixed_rows::<3>(0) * p[1];
        let bias = self.bias_estimate().map(|b| p[1] * b);
        DualUkfStep {
            probabilities,
            fault_declared,
            decision,
            held_s: held_s(self.rule.held_samples().0, self.dt_s),
            both_reinitialised: fault_present,
            chi_square,
            chi_square_threshold,
            isolated,
            bias_modes: self.bias_modes,
            air_data: air_data_from_velocity(&velocity),
            bias,
            fault_model_bias,
        }
    }

    /// First sample: both filters start at the measured air data (module docs), every bias open. Only
    /// the filters: the bias modes start open and the re-initialisation counters at zero.
    fn initialise(&mut self, air: &AirData) {
        let y = air.to_vector();
        let x0 = velocity_from_air_data(air);
        let J = central_difference(&y, |a| velocity_from_air_data(&AirData::from_array([a[0], a[1], a[2]])));
        let P0 = J * self.no_fault.measurement_noise() * J.transpose();
        self.no_fault.reinitialise(x0, P0);
        let (x, P) = self.fault_model_start();
        self.fault.reinitialise(x, P);
    }

    /// Window sum of `gamma_j^2 / S_jj` and the threshold for the samples it holds.
    fn isolation_statistic(&mut self, innovation: &Innovation<3>) -> ([f64; COMPONENTS], f64) {
        let per_sample: [f64; COMPONENTS] = std::array::from_fn(|j| {
            let s = innovation.S[(j, j)];
            if innovation.S_inverse.is_some() && s > 0.0 { innovation.gamma[j].powi(2) / s } else { f64::NAN }
        });
        let n = self.history.len();
        self.history[self.history_next] = per_sample;
        self.history_next = (self.history_next + 1) % n;
        self.history_filled = (self.history_filled + 1).min(n);
        // Oldest first, so the sum does not depend on where the ring starts.
        let oldest = (self.history_next + n - self.history_filled) % n;
        let mut sum = [0.0; COMPONENTS];
        for i in 0..self.history_filled {
            let sample = &self.history[(oldest + i) % n];
            for j in 0..COMPONENTS {
                sum[j] += sample[j];
            }
        }
        (sum, self.thresholds[self.history_filled - 1])
    }

    /// The fault model's current bias states.
    fn bias_estimate(&self) -> [f64; COMPONENTS] {
        let x = self.fault.state();
        [x[3], x[4], x[5]]
    }

    /// No fault declared: the fault model restarts from the no-fault model with every bias open.
    fn reinitialise_fault_model(&mut self) {
        let (x, P) = self.fault_model_start();
        self.fault.reinitialise(x, P);
        self.bias_modes = [BiasMode::Open; COMPONENTS];
        self.fault_model_reinitialisations += 1;
    }

    /// The fault model's start from the no-fault model: its velocity `(x, P)`, every bias 0 with its
    /// initial variance.
    fn fault_model_start(&self) -> (SVector<f64, 6>, SMatrix<f64, 6, 6>) {
        let mut x = SVector::<f64, 6>::zeros();
        x.fixed_rows_mut::<3>(0).copy_from(self.no_fault.state());
        let mut P = SMatrix::<f64, 6, 6>::zeros();
        P.fixed_view_mut::<3, 3>(0, 0).copy_from(self.no_fault.covariance());
        for j in 0..COMPONENTS {
            P[(3 + j, 3 + j)] = self.params.initial_bias_std[j].powi(2);
        }
        (x, P)
    }

    /// Fault declared: the fault model's biases selectively (faulty set), then the no-fault model from
    /// the fault model's velocity (module docs, step 4).
    fn reinitialise_both(&mut self, isolated: &[bool; COMPONENTS]) {
        let wald_threshold = self.thresholds[0];
        let (mut x, mut P) = (*self.fault.state(), *self.fault.covariance());
        let faulty: [bool; COMPONENTS] = std::array::from_fn(|j| {
            let significant = x[3 + j].powi(2) / P[(3 + j, 3 + j)] > wald_threshold;
            isolated[j]
                || (self.params.keep_significant_biases && self.bias_modes[j] == BiasMode::Estimated && significant)
        });
        let any_faulty = faulty.contains(&true);
        let modes: [BiasMode; COMPONENTS] = std::array::from_fn(|j| match (faulty[j], self.bias_modes[j]) {
            (true, BiasMode::Healthy) => BiasMode::Open,
            (true, _) => BiasMode::Estimated,
            (false, _) if any_faulty => BiasMode::Healthy,
            (false, _) => BiasMode::Open,
        });
        for (j, mode) in modes.iter().enumerate() {
            let variance = match mode {
                BiasMode::Estimated => continue,
                BiasMode::Open => self.params.initial_bias_std[j].powi(2),
                BiasMode::Healthy => self.params.bias_random_walk_per_sqrt_s[j].powi(2) * self.dt_s,
            };
            let i = 3 + j;
            x[i] = 0.0;
            P.row_mut(i).fill(0.0);
            P.column_mut(i).fill(0.0);
            P[(i, i)] = variance;
        }
        self.fault.reinitialise(x, P);
        self.bias_modes = modes;
        self.no_fault.reinitialise(x.fixed_rows::<3>(0).into_owned(), P.fixed_view::<3, 3>(0, 0).into_owned());
        self.both_models_reinitialisations += 1;
    }

    /// Both filters' time update over `interval` with this step's `Q` (module docs).
    fn predict(&mut self, interval: &InertialInterval) {
        let (a, b) = (interval.start.to_array(), interval.end.to_array());
        let mean = Inertial::from_array(std::array::from_fn(|i| 0.5 * (a[i] + b[i])));
        let Q_nf = self.velocity_process_noise(self.no_fault.state(), &mean);
        self.no_fault.set_process_noise(Q_nf);
        self.no_fault.predict(&NoFaultModel { dt_s: self.dt_s }, interval);

        let velocity = self.fault.state().fixed_rows::<3>(0).into_owned();
        let mut Q_f = SMatrix::<f64, 6, 6>::zeros();
        Q_f.fixed_view_mut::<3, 3>(0, 0).copy_from(&self.velocity_process_noise(&velocity, &mean));
        for j in 0..COMPONENTS {
            Q_f[(3 + j, 3 + j)] = self.params.bias_random_walk_per_sqrt_s[j].powi(2) * self.dt_s;
        }
        self.fault.set_process_noise(Q_f);
        self.fault.predict(&FaultModel { dt_s: self.dt_s }, interval);
    }

    /// `dt^2 G diag(sigma_inertial^2) G' + dt q_v I` at `velocity`.
    pub(super) fn velocity_process_noise(&self, velocity: &Vector3<f64>, inertial: &Inertial) -> SMatrix<f64, 3, 3> {
        let G = velocity_derivative_input_jacobian(velocity, inertial);
        let Sigma =
            SMatrix::<f64, 8, 8>::from_diagonal(&SVector::from(self.params.noise.inertial_std().map(|s| s * s)));
        let q_v = self.params.velocity_random_walk_mps_per_sqrt_s.powi(2);
        G * Sigma * G.transpose() * (self.dt_s * self.dt_s) + SMatrix::<f64, 3, 3>::identity() * (q_v * self.dt_s)
    }
}
