//! The offline design of method 001's estimator: its parameters, the sensitivity table `S` flown on the
//! nominal model at each onset of the grid, the nominal residual `Y0`, and the linear loss fit that
//! turns a peak of `fhat` into a percentage (module docs of [`super`]).
#![allow(non_snake_case)]

use super::residual::*;
use crate::methods::thrust_loss::vehicle::{
    ENGINES, LaunchVehicleConfig, LaunchVehicleError, SensorNoise, State, ThrustFault, Vehicle,
};

/// The unit fault `f` is counted in: a 1 % thrust loss of one engine (the seed's `e`).
pub const UNIT_FAULT: f64 = 0.01;

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
    pub(super) params: DetectorParams,
    pub(super) model: FilterModel,
    pub(super) x0: State,
    pub(super) onsets_s: Vec<f64>,
    /// `S` per grid onset, `N + 1` entries each, per unit fault (rad/s).
    pub(super) sensitivity: Vec<Vec<f64>>,
    /// The noise-free nominal flight's residual at every sample (rad/s).
    pub(super) nominal_residual: Vec<f64>,
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
