//! Method 003: accelerometer fault detection and classification from attitude-EKF residuals with a
//! bottom-up SVM decision tree (`docs/findings-seed003.md`; the patent "一种飞机飞行控制系统的加速度计故障
//! 监测方法", steps 4-5, paragraphs 0146-0148). The residual comes from
//! [`crate::methods::accelerometer::attitude::AttitudeEkf`]; the trials from [`crate::methods::accelerometer::imu`].
//!
//! # Pipeline
//! 1. Residuals `e(k) = z(k) - g(q(k|k-1))` and the expected gravity direction `g(q(k|k-1))` of each
//!    sample ([`ResidualSample`]; [`simulate_trial`] runs scenario and filter together).
//! 2. Detection ([`ResidualDetector`]): `T(k) = n |mean of the last n residuals|^2 / sigma_z^2`, with
//!    `sigma_z = sigma_a / g0` the residual noise per component. For white residuals it is chi-square
//!    with about 2 degrees of freedom (normalisation leaves the component along gravity almost
//!    noise-free). The alarm is the first `T >= threshold`; the threshold of [`DetectionParams::seed`]
//!    is set from fault-free trials (see there), and a study calibrates its own from its fault-free
//!    trials (the project's threshold workflow: record `T`'s running maximum, choose afterwards).
//! 3. Features of a window of `n` residual samples ([`features`], [`FEATURE_NAMES`]).
//! 4. Classification into normal / bias / gain / stuck ([`FaultClass`]) by the seed's SVM decision tree
//!    ([`SvmTree`]) or, for comparison, a flat one-against-one SVM ([`OneVsOne`]), both in a
//!    [`Classifier`] that also holds the feature standardisation and settings, saved as JSON.
//!
//! # Features (per accelerometer axis j = x, y, z; 12 in all, dimensionless)
//! With `e_j(i)` the residual and `g_j(i)` the expected gravity direction at the window's samples,
//! `t_i = i dt`:
//! - `mean_j`: the mean of `e_j`. Any fault shifts it (residual expectation of the seed: zero when
//!   healthy, non-zero under a fault). A bias shifts it by `alpha / |a| (1 - z_j^2)` at once.
//! - `slope_j`: least-squares slope of `e_j` against `t` (1/s). A bias's shift is largest at the onset
//!   and decays as the filter absorbs it into the attitude (slope against the mean); a stuck output's
//!   grows from zero as the attitude moves away from where it froze (slope with the mean); a gain's
//!   follows the axis' share of gravity.
//! - `noise_j`: RMS of `e_j` about that line. A stuck output has no noise left (its residual is the
//!   smooth `gamma/|a| - g_j`), a gain scales the noise by `beta`, a bias leaves it.
//! - `sensitivity_j = cov(e_j, g_j) / (var(g_j) + floor^2)`: the regression of the residual on the
//!   gravity share. About -1 for a stuck axis (`e_j ~ const - g_j`), about `(beta - 1)(1 - 3 g_j^2)`
//!   for a gain (`e_j ~ (beta - 1) g_j (1 - g_j^2)`), near 0 for a bias and when healthy. The floor
//!   (0.02 by default: 1.1 deg of gravity swing) keeps it near 0 when the attitude barely moves and
//!   nothing can be told.
//!
//! # Scaling (fitted on the training set, saved with the model: [`Standardizer`])
//! Per feature, `u = asinh((x - m_0) / s_0)` with `m_0`, `s_0` the mean and standard deviation over the
//! normal class, then `(u - mean(u)) / std(u)` over all training examples. Fault sizes span a decade and
//! the features grow with the size, so plain standardisation lets the large faults set the scale and
//! crowds the small ones against the healthy cluster; in units of the healthy spread and compressed
//! logarithmically beyond it, a feature says how abnormal it is and the classifier reads the signature's
//! shape more than its size (measured on 300 trials per class: validation accuracy 0.82 with plain
//! standardisation, 0.93 with this, same SVM settings).
//!
//! # Which window (what a runner passes)
//! The classifier must see windows aligned as in training. [`TrialDesign`] makes training examples
//! from the window of `window_len` samples starting `window_delay_s` after the onset (for a fault-free
//! trial, after its drawn nominal onset, which the fault is not applied at), so a study that evaluates
//! on fresh trials passes the same window: `trace.samples[start..start + window_len]` with
//! `start = ceil((onset_s + window_delay_s) / dt_s)` ([`window_start`]). A runner that classifies after
//! its detector instead (onset unknown) trains and evaluates with the window starting at the alarm.
//!
//! # Separability and the bottom-up tree (patent paragraph 0147)
//! The patent names the inter-class separability `s_ij` but its formula is an image lost from the text;
//! this is the measure of the SVM-decision-tree literature it follows (separability measure
//! `s_ij = d_ij / (sigma_i + sigma_j)`, e.g. Tang, Wang, Chen, "A new binary tree multi-class SVM
//! algorithm", Computer Engineering and Applications 2005), computed in the standardised feature space:
//! ```text
//! c_i = mean of class i,   sigma_i = 1/(n_i - 1) sum_x |x - c_i|   (class spread),
//! d_ij = |c_i - c_j|,      s_ij = d_ij / (sigma_i + sigma_j)
//! ```
//! Training ([`Classifier::train`] with [`Scheme::Tree`]): start with one group per class; compute `s`
//! for every pair of groups (a merged group is one class: its samples pooled); train a binary SVM on the
//! least separable pair (positive: the group listed first); merge the pair; repeat until one group, the
//! root. Classification runs top-down: each internal node's SVM sends the sample to its positive or
//! negative subtree until a leaf. The merges, with every candidate pair's separability, are kept
//! ([`SvmTree::merges`]).
//!
//! # SVMs
//! Binary C-SVMs of `linfa-svm` (SMO solver), linear or Gaussian kernel `exp(-gamma |x - x'|^2)`;
//! [`SvmParams::seed`] gives the defaults and why. A trained `linfa_svm::Svm` is serde-serialisable
//! (its support vectors, weights, offset and kernel), so the whole [`Classifier`] is saved as JSON.
#![allow(non_snake_case)]

use std::path::{Path, PathBuf};

use linfa::prelude::*;
use linfa_svm::Svm;
use nalgebra::{Vector3, Vector4};
use ndarray::{Array1, Array2, ArrayView1};
use rand::Rng;
use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::methods::accelerometer::attitude::{
    AttitudeEkf, AttitudeEkfParams, AttitudeHealth, AttitudeStep, as_vector, tilt_error_rad,
};
use crate::methods::accelerometer::imu::{
    AccelFaultKind, AccelFaultRanges, ImuScenario, ImuScenarioError, ImuScenarioParams,
};

/// The four classes of the seed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FaultClass {
    Normal,
    Bias,
    Gain,
    Stuck,
}

/// Number of classes.
pub const CLASS_COUNT: usize = 4;

impl FaultClass {
    pub const ALL: [FaultClass; CLASS_COUNT] =
        [FaultClass::Normal, FaultClass::Bias, FaultClass::Gain, FaultClass::Stuck];

    /// Index in [`Self::ALL`] (rows and columns of a [`ConfusionMatrix`]).
    pub fn index(self) -> usize {
        self as usize
    }

    pub fn name(self) -> &'static str {
        match self {
            FaultClass::Normal => "normal",
            FaultClass::Bias => "bias",
            FaultClass::Gain => "gain",
            FaultClass::Stuck => "stuck",
        }
    }

    /// The fault kind of a faulty class (`None` for normal).
    pub fn fault_kind(self) -> Option<AccelFaultKind> {
        match self {
            FaultClass::Normal => None,
            FaultClass::Bias => Some(AccelFaultKind::Bias),
            FaultClass::Gain => Some(AccelFaultKind::Gain),
            FaultClass::Stuck => Some(AccelFaultKind::Stuck),
        }
    }
}

/// One residual sample as the features read it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ResidualSample {
    /// `e = z - g(q(k|k-1))`.
    pub residual: [f64; 3],
    /// `g(q(k|k-1))`.
    pub predicted: [f64; 3],
}

impl From<&AttitudeStep> for ResidualSample {
    fn from(step: &AttitudeStep) -> Self {
        ResidualSample { residual: step.residual.into(), predicted: step.predicted.into() }
    }
}

/// Features per axis and in all.
pub const FEATURES_PER_AXIS: usize = 4;
pub const FEATURE_COUNT: usize = 3 * FEATURES_PER_AXIS;
/// Names, in the order of [`features`]' output (module docs).
pub const FEATURE_NAMES: [&str; FEATURE_COUNT] = [
    "mean_x",
    "slope_x_per_s",
    "noise_x",
    "sensitivity_x",
    "mean_y",
    "slope_y_per_s",
    "noise_y",
    "sensitivity_y",
    "mean_z",
    "slope_z_per_s",
    "noise_z",
    "sensitivity_z",
];

/// A feature vector.
pub type Features = [f64; FEATURE_COUNT];

/// How features are computed (saved with a classifier).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FeatureParams {
    /// Sample period (s).
    pub dt_s: f64,
    /// Samples in a window.
    pub window_len: usize,
    /// Floor of the gravity-share swing in `sensitivity_j` (module docs).
    pub sensitivity_floor: f64,
    /// `noise_j` over the same RMS of the window before (each trial's own pre-fault level) rather than
    /// in absolute units, so that noisier sensors do not read as a fault's signature.
    #[serde(default)]
    pub relative_noise: bool,
}

impl FeatureParams {
    /// 100 Hz, a 1 s window (100 samples), floor 0.02. One second: the filter absorbs a persistent
    /// shift with a time constant of about 1.2 s at [`AttitudeEkfParams::seed`] (measured: the mean
    /// residual shift of a bias over the first second is 68 % of the formula's, 49 % over two), and the
    /// seed manoeuvre turns the gravity direction by up to some 30 deg in a second (roll and pitch rates
    /// peak at 24-25 deg/s), enough for the slope and sensitivity features.
    pub fn seed() -> Self {
        FeatureParams { dt_s: 0.01, window_len: 100, sensitivity_floor: 0.02, relative_noise: false }
    }
}

impl Default for FeatureParams {
    fn default() -> Self {
        Self::seed()
    }
}

/// Why features or a classifier could not be made.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ClassifierError {
    #[error("a feature window needs {expected} samples, got {got}")]
    WindowLength { expected: usize, got: usize },
    #[error("the window ends at sample {end}, the trial has {samples}")]
    TrialTooShort { end: usize, samples: usize },
    #[error("the trial is sampled every {trace_dt_s} s, the features expect {features_dt_s} s")]
    SamplePeriod { trace_dt_s: f64, features_dt_s: f64 },
    #[error("sample {index} of the window is not finite (an unusable accelerometer sample)")]
    NonFiniteSample { index: usize },
    #[error("training example {index} has a non-finite feature")]
    NonFiniteExample { index: usize },
    #[error("feature vector has {got} entries, the classifier expects {expected}")]
    FeatureCount { expected: usize, got: usize },
    #[error("feature vector has a non-finite entry")]
    NonFiniteFeature,
    #[error("class {class:?} has {count} training examples; at least 2 are needed")]
    TooFewExamples { class: FaultClass, count: usize },
    #[error("invalid SVM parameters: {0}")]
    Params(String),
    #[error("SVM training ({what}) failed: {message}")]
    Svm { what: String, message: String },
    #[error("{path}: {message}")]
    Io { path: PathBuf, message: String },
    #[error("classifier JSON: {0}")]
    Json(String),
    #[error("classifier format {found:?} is not {CLASSIFIER_FORMAT:?}")]
    Format { found: String },
}

/// Least-squares fit `y ~ a + b x` of paired samples: `(b, RMS of the fit's residual)`, with `b` the
/// covariance over `var(x) + floor^2`.
fn regression(x: &[f64], y: &[f64], floor: f64) -> (f64, f64) {
    let n = x.len() as f64;
    let (mx, my) = (x.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
    let (mut sxx, mut sxy) = (0.0, 0.0);
    for (a, b) in x.iter().zip(y) {
        sxx += (a - mx) * (a - mx);
        sxy += (a - mx) * (b - my);
    }
    // No swing at all (and no floor): nothing to regress on, the slope says nothing.
    let denominator = sxx + n * floor * floor;
    let slope = if denominator > 0.0 { sxy / denominator } else { 0.0 };
    let rms = (y.iter().zip(x).map(|(b, a)| (b - my - slope * (a - mx)).powi(2)).sum::<f64>() / n).sqrt();
    (slope, rms)
}

/// The 12 features of a window of exactly `params.window_len` samples (module docs).
pub fn features(window: &[ResidualSample], params: &FeatureParams) -> Result<Features, ClassifierError> {
    if window.len() != params.window_len || window.len() < 3 {
        return Err(ClassifierError::WindowLength { expected: params.window_len.max(3), got: window.len() });
    }
    if let Some(index) = window.iter().position(|s| !(s.residual.iter().chain(&s.predicted).all(|v| v.is_finite()))) {
        return Err(ClassifierError::NonFiniteSample { index });
    }
    let n = window.len() as f64;
    let t: Vec<f64> = (0..window.len()).map(|i| i as f64 * params.dt_s).collect();
    let mut out = [0.0; FEATURE_COUNT];
    for axis in 0..3 {
        let e: Vec<f64> = window.iter().map(|s| s.residual[axis]).collect();
        let g: Vec<f64> = window.iter().map(|s| s.predicted[axis]).collect();
        let (slope, noise) = regression(&t, &e, 0.0);
        let (sensitivity, _) = regression(&g, &e, params.sensitivity_floor);
        let f = &mut out[axis * FEATURES_PER_AXIS..(axis + 1) * FEATURES_PER_AXIS];
        f.copy_from_slice(&[e.iter().sum::<f64>() / n, slope, noise, sensitivity]);
    }
    Ok(out)
}

/// [`features`] of `window`, with `noise_j` over the RMS about its own line of `reference` (the samples
/// before the window) when `params.relative_noise`.
pub fn features_with_reference(
    window: &[ResidualSample],
    reference: &[ResidualSample],
    params: &FeatureParams,
) -> Result<Features, ClassifierError> {
    let mut out = features(window, params)?;
    if params.relative_noise {
        if reference.len() < 3 {
            return Err(ClassifierError::WindowLength { expected: 3, got: reference.len() });
        }
        let t: Vec<f64> = (0..reference.len()).map(|i| i as f64 * params.dt_s).collect();
        for axis in 0..3 {
            let e: Vec<f64> = reference.iter().map(|s| s.residual[axis]).collect();
            let (_, level) = regression(&t, &e, 0.0);
            // A reference with no noise at all (a stuck sensor before the window) leaves the value as it is.
            if level > 0.0 {
                out[axis * FEATURES_PER_AXIS + 2] /= level;
            }
        }
    }
    Ok(out)
}

/// First sample index of the classification window: `ceil((onset_s + delay_s) / dt_s)`, the first
/// sample at or after that time (module docs).
pub fn window_start(onset_s: f64, delay_s: f64, dt_s: f64) -> usize {
    // The small tolerance keeps a time that is a whole number of steps from rounding up a sample.
    ((onset_s + delay_s) / dt_s - 1e-9).ceil().max(0.0) as usize
}

// ---------------------------------------------------------------------------------------------------
// Detection

/// The detection rule (module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DetectionParams {
    /// Samples averaged (`n`).
    pub window: usize,
    /// `sigma_z` of the statistic: the residual noise per component (`sigma_a / g0`).
    pub residual_std: f64,
    /// Alarm when `T >= threshold`.
    pub threshold: f64,
}

impl DetectionParams {
    /// `n` = 20 samples (0.2 s at 100 Hz: a 0.05 m/s^2 bias, 2.5 sigma_z on a horizontal axis, gives a
    /// non-central chi-square mean near 125 before the filter absorbs it), `sigma_z` of
    /// [`AttitudeEkfParams::seed`], threshold 60. The threshold is measured, not from chi-square tables:
    /// the filter's tilt error (unmodelled gyro and accelerometer biases) gives healthy residuals a slowly
    /// varying mean, and a trial tests 1700 overlapping windows. Over 400 fault-free trials of
    /// [`TrialDesign::seed`] the largest `T` after 3 s (convergence) had median 24.6, 99th percentile 48.6
    /// and maximum 51.9, so 60 keeps per-trial false alarms well below 1 %; with it, 199 of 200 biases,
    /// 200 of 200 gains and 200 of 200 stuck faults of the seed ranges were detected, median delays
    /// 0.03, 0.01 and 0.12 s (90th percentiles 0.12, 0.05, 0.54 s).
    pub fn seed() -> Self {
        DetectionParams { window: 20, residual_std: AttitudeEkfParams::seed().residual_noise_std(), threshold: 60.0 }
    }
}

impl Default for DetectionParams {
    fn default() -> Self {
        Self::seed()
    }
}

/// `T(k) = n |mean of the last n residuals|^2 / sigma_z^2`, one sample at a time.
#[derive(Debug, Clone)]
pub struct ResidualDetector {
    params: DetectionParams,
    ring: Vec<Vector3<f64>>,
    next: usize,
    filled: usize,
}

impl ResidualDetector {
    /// Panics if `params.window` is 0 (a programmer error: the deck validator rejects it).
    #[track_caller]
    pub fn new(params: DetectionParams) -> Self {
        assert!(params.window > 0, "detection window must be positive");
        ResidualDetector { ring: vec![Vector3::zeros(); params.window], params, next: 0, filled: 0 }
    }

    /// Takes one residual; returns `T` once `n` residuals are in (NaN while a non-finite residual is in
    /// the window: no decision).
    pub fn push(&mut self, residual: &Vector3<f64>) -> Option<f64> {
        self.ring[self.next] = *residual;
        self.next = (self.next + 1) % self.ring.len();
        self.filled = (self.filled + 1).min(self.ring.len());
        if self.filled < self.ring.len() {
            return None;
        }
        // Summed afresh each time (n is small): no drift of a running sum over a long trial.
        let n = self.ring.len() as f64;
        let mean = self.ring.iter().sum::<Vector3<f64>>() / n;
        Some(n * mean.norm_squared() / self.params.residual_std.powi(2))
    }

    /// Whether `T` raises an alarm.
    pub fn alarms(&self, statistic: f64) -> bool {
        statistic >= self.params.threshold
    }
}

/// The statistic of every sample of a residual sequence (NaN before the window fills).
pub fn detection_statistics(samples: &[ResidualSample], params: &DetectionParams) -> Vec<f64> {
    let mut detector = ResidualDetector::new(*params);
    samples.iter().map(|s| detector.push(&Vector3::from(s.residual)).unwrap_or(f64::NAN)).collect()
}

/// First index at or after `from` whose statistic reaches `threshold` (NaN never does).
pub fn first_alarm(statistics: &[f64], threshold: f64, from: usize) -> Option<usize> {
    statistics.iter().enumerate().skip(from).find(|(_, t)| **t >= threshold).map(|(k, _)| k)
}

// ---------------------------------------------------------------------------------------------------
// Trials and examples

/// One trial's filter output.
#[derive(Debug, Clone, PartialEq)]
pub struct ResidualTrace {
    pub dt_s: f64,
    pub samples: Vec<ResidualSample>,
    /// Angle between true and estimated gravity directions per sample (rad).
    pub tilt_error_rad: Vec<f64>,
    pub health: AttitudeHealth,
}

/// Why a trial could not be simulated.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum TrialError {
    #[error(transparent)]
    Scenario(#[from] ImuScenarioError),
    #[error(transparent)]
    Filter(#[from] crate::methods::accelerometer::attitude::AttitudeError),
    #[error(transparent)]
    Classifier(#[from] ClassifierError),
}

/// Runs `scenario` (drawing its noise from `rng`, [`ImuScenario::next_sample`]) through the filter,
/// which starts aligned on the first accelerometer sample with heading 0.
pub fn simulate_trial<R: Rng + ?Sized>(
    scenario: ImuScenarioParams,
    ekf: &AttitudeEkfParams,
    rng: &mut R,
) -> Result<ResidualTrace, TrialError> {
    let dt_s = scenario.dt_s;
    let mut scenario = ImuScenario::new(scenario)?;
    let n = scenario.samples();
    let samples = std::iter::from_fn(|| scenario.next_sample(rng))
        .map(|s| (s.gyro_rad_s, s.accel_mps2, Some(as_vector(&s.truth.attitude))));
    filter_trial(dt_s, n, samples, ekf)
}

/// The attitude EKF over one trial's (gyro, accelerometer, true attitude if known) samples, aligned on
/// the first accelerometer sample; simulated and replayed trials alike (`expected_samples` sizes the
/// outputs once). Without a true attitude the tilt error is NaN.
pub fn filter_trial(
    dt_s: f64,
    expected_samples: usize,
    samples: impl Iterator<Item = (Vector3<f64>, Vector3<f64>, Option<Vector4<f64>>)>,
    ekf: &AttitudeEkfParams,
) -> Result<ResidualTrace, TrialError> {
    let mut filter: Option<AttitudeEkf> = None;
    let (mut residuals, mut tilt) = (Vec::with_capacity(expected_samples), Vec::with_capacity(expected_samples));
    for (gyro, accel, truth) in samples {
        let f = match &mut filter {
            Some(f) => f,
            None => filter.insert(AttitudeEkf::aligned(*ekf, &accel, 0.0)?),
        };
        let step = f.step(&gyro, &accel);
        residuals.push(ResidualSample::from(&step));
        tilt.push(truth.map_or(f64::NAN, |q| tilt_error_rad(&q, f.attitude())));
    }
    let health = filter.map(|f| f.health()).unwrap_or_default();
    Ok(ResidualTrace { dt_s, samples: residuals, tilt_error_rad: tilt, health })
}

/// A labelled feature vector.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Example {
    pub features: Features,
    pub class: FaultClass,
}

/// How a study makes one labelled trial (module docs, "Which window").
#[derive(Debug, Clone, PartialEq)]
pub struct TrialDesign {
    /// The fault-free scenario (manoeuvre, noise, duration); biases and the fault are drawn.
    pub scenario: ImuScenarioParams,
    pub ranges: AccelFaultRanges,
    pub ekf: AttitudeEkfParams,
    pub features: FeatureParams,
    /// The classification window starts this long after the onset (s).
    pub window_delay_s: f64,
    /// The filter's `Q` and `R` (and the detector's `sigma_z`) follow the trial's noise scale, as the
    /// patent sets them from the actual sensor noise; false: nominal whatever the noise.
    pub filter_knows_noise: bool,
}

impl TrialDesign {
    /// The seed scenario, fault ranges, filter and features; the window starts at the onset (the first
    /// faulty sample: the largest share of a bias before the filter absorbs it).
    pub fn seed() -> Self {
        TrialDesign {
            scenario: ImuScenarioParams::seed(),
            ranges: AccelFaultRanges::seed(),
            ekf: AttitudeEkfParams::seed(),
            features: FeatureParams::seed(),
            window_delay_s: 0.0,
            filter_knows_noise: false,
        }
    }

    /// Draws one trial of `class`: the fault ([`AccelFaultRanges::draw`], 4 uniforms), then the sensor
    /// biases ([`ImuScenarioParams::draw_sensor_biases`], 6 normals). Returns the scenario and the
    /// (nominal, for normal) onset.
    pub fn draw_trial<R: Rng + ?Sized>(&self, class: FaultClass, rng: &mut R) -> (ImuScenarioParams, f64) {
        let (fault, onset_s) = self.ranges.draw(class.fault_kind(), rng);
        let mut scenario = self.scenario.clone();
        scenario.faults = fault.into_iter().collect();
        scenario.draw_sensor_biases(rng);
        (scenario, onset_s)
    }

    /// The example of a simulated trial: the features of its window after the onset.
    pub fn example(&self, trace: &ResidualTrace, onset_s: f64, class: FaultClass) -> Result<Example, ClassifierError> {
        self.example_from(trace, window_start(onset_s, self.window_delay_s, trace.dt_s), class)
    }

    /// The example of the window starting at sample `start`; a window that would run past the trial's
    /// end is moved back to end with it (an alarm near the end is classified on its last samples).
    pub fn example_at(
        &self,
        trace: &ResidualTrace,
        start: usize,
        class: FaultClass,
    ) -> Result<Example, ClassifierError> {
        let start = start.min(trace.samples.len().saturating_sub(self.features.window_len));
        self.example_from(trace, start, class)
    }

    fn example_from(&self, trace: &ResidualTrace, start: usize, class: FaultClass) -> Result<Example, ClassifierError> {
        if (trace.dt_s - self.features.dt_s).abs() > 1e-9 * self.features.dt_s {
            return Err(ClassifierError::SamplePeriod { trace_dt_s: trace.dt_s, features_dt_s: self.features.dt_s });
        }
        let end = start + self.features.window_len;
        let window = trace
            .samples
            .get(start..end)
            .ok_or(ClassifierError::TrialTooShort { end, samples: trace.samples.len() })?;
        let reference = &trace.samples[start.saturating_sub(self.features.window_len)..start];
        Ok(Example { features: features_with_reference(window, reference, &self.features)?, class })
    }

    /// The filter of a trial at `noise_scale`: nominal, or scaled with the noise when the filter knows it.
    pub fn ekf_for(&self, noise_scale: f64) -> AttitudeEkfParams {
        if !self.filter_knows_noise {
            return self.ekf;
        }
        AttitudeEkfParams {
            gyro_noise_std_rad_s: self.ekf.gyro_noise_std_rad_s * noise_scale,
            accel_noise_std_mps2: self.ekf.accel_noise_std_mps2 * noise_scale,
            ..self.ekf
        }
    }

    /// The detector of a trial at `noise_scale`: its `sigma_z` follows the filter's `R`.
    pub fn detection_for(&self, detection: &DetectionParams, noise_scale: f64) -> DetectionParams {
        if !self.filter_knows_noise {
            return *detection;
        }
        DetectionParams { residual_std: detection.residual_std * noise_scale, ..*detection }
    }

    /// [`Self::draw_trial`], [`simulate_trial`] and [`Self::example`] with one RNG, in that order.
    pub fn draw_example<R: Rng + ?Sized>(&self, class: FaultClass, rng: &mut R) -> Result<Example, TrialError> {
        let (scenario, onset_s) = self.draw_trial(class, rng);
        let trace = simulate_trial(scenario, &self.ekf_for(self.scenario.noise_scale), rng)?;
        Ok(self.example(&trace, onset_s, class)?)
    }
}

// ---------------------------------------------------------------------------------------------------
// SVMs

/// Kernel of the binary SVMs.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum SvmKernel {
    Linear,
    /// `exp(-gamma |x - x'|^2)` on standardised features.
    Gaussian {
        gamma: f64,
    },
}

/// Settings of every binary SVM.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SvmParams {
    pub kernel: SvmKernel,
    /// Box constraint `C` (both classes).
    pub c: f64,
    /// SMO stopping tolerance.
    pub tolerance: f64,
    /// Weigh each side of a binary SVM by the inverse of its size (`C n / (2 n_side)`), so a merged
    /// group of three classes does not outvote the one class against it; false: `C` on both sides.
    #[serde(default)]
    pub balanced: bool,
}

impl SvmParams {
    /// Gaussian kernel with `gamma = 1 / 12` (libsvm's `1 / features` on standardised data), `C = 10`,
    /// tolerance 1e-3 (libsvm's). Chosen on a validation set (training RNG seed 1, validation seed 2, 150
    /// and 300 trials per class of [`TrialDesign::seed`]; the tests use other seeds): over `gamma` in
    /// 1/24-1/3 and `C` in 10-100 the tree's validation accuracy stayed within 0.88-0.93, this pair at
    /// the top (0.90 with 150 per class, 0.93 with 300) without the training accuracy reaching 1 (the
    /// larger pairs fit the training set exactly and lose on fresh trials). A linear kernel reached
    /// 0.63: the classes are not convex (each is a fault on one of three axes, of either sign).
    pub fn seed() -> Self {
        SvmParams {
            kernel: SvmKernel::Gaussian { gamma: 1.0 / FEATURE_COUNT as f64 },
            c: 10.0,
            tolerance: 1e-3,
            balanced: false,
        }
    }

    fn validate(&self) -> Result<(), ClassifierError> {
        let positive = |name: &str, v: f64| {
            if v.is_finite() && v > 0.0 { Ok(()) } else { Err(ClassifierError::Params(format!("{name} = {v}"))) }
        };
        positive("c", self.c)?;
        positive("tolerance", self.tolerance)?;
        if let SvmKernel::Gaussian { gamma } = self.kernel {
            positive("gamma", gamma)?;
        }
        Ok(())
    }
}

impl Default for SvmParams {
    fn default() -> Self {
        Self::seed()
    }
}

/// A trained binary SVM: `decision(x) >= 0` is the positive side.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BinarySvm {
    // Boxed: the model is some 200 bytes and lives in enum variants beside small ones.
    svm: Box<Svm<f64, bool>>,
}

impl BinarySvm {
    /// Trains on standardised `positive` and `negative` rows.
    fn train(
        positive: &[&[f64]],
        negative: &[&[f64]],
        params: &SvmParams,
        what: String,
    ) -> Result<Self, ClassifierError> {
        let rows = positive.len() + negative.len();
        let dim = positive.first().or(negative.first()).map_or(0, |r| r.len());
        let mut records = Array2::<f64>::zeros((rows, dim));
        for (i, row) in positive.iter().chain(negative).enumerate() {
            records.row_mut(i).assign(&ArrayView1::from(*row));
        }
        let targets = Array1::from_iter((0..rows).map(|i| i < positive.len()));
        let dataset = Dataset::new(records, targets);
        let (c_positive, c_negative) = if params.balanced {
            let half = 0.5 * rows as f64;
            (params.c * half / positive.len() as f64, params.c * half / negative.len() as f64)
        } else {
            (params.c, params.c)
        };
        let builder = Svm::<f64, bool>::params().pos_neg_weights(c_positive, c_negative).eps(params.tolerance);
        let builder = match params.kernel {
            SvmKernel::Linear => builder.linear_kernel(),
            SvmKernel::Gaussian { gamma } => builder.gaussian_kernel(1.0 / gamma),
        };
        let svm = builder.fit(&dataset).map_err(|e| ClassifierError::Svm { what, message: e.to_string() })?;
        Ok(BinarySvm { svm: Box::new(svm) })
    }

    /// The decision value `sum_i alpha_i K(x_i, x) - rho` of a standardised sample.
    pub fn decision(&self, x: &[f64]) -> f64 {
        self.svm.weighted_sum(&ArrayView1::from(x)) - self.svm.rho
    }

    /// Support vectors with a non-zero weight.
    pub fn support_vectors(&self) -> usize {
        self.svm.nsupport()
    }
}

/// The feature transform fitted on the training set (module docs, "Scaling"): first
/// `u = asinh((x - healthy_mean) / healthy_std)` per feature, then `(u - mean) / std` (a constant
/// feature keeps `std = 1`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Standardizer {
    /// Mean and standard deviation of each feature over the normal class (over all examples when the
    /// training set has no normal example).
    pub healthy_mean: Vec<f64>,
    pub healthy_std: Vec<f64>,
    /// Mean and standard deviation of `u` over all training examples.
    pub mean: Vec<f64>,
    pub std: Vec<f64>,
}

fn mean_std(rows: &[&[f64]], j: usize) -> (f64, f64) {
    let n = rows.len() as f64;
    let mean = rows.iter().map(|r| r[j]).sum::<f64>() / n;
    let var = rows.iter().map(|r| (r[j] - mean).powi(2)).sum::<f64>() / (n - 1.0).max(1.0);
    (mean, if var > 0.0 { var.sqrt() } else { 1.0 })
}

impl Standardizer {
    fn fit(rows: &[&[f64]], healthy: &[&[f64]]) -> Self {
        let dim = rows[0].len();
        let healthy = if healthy.len() >= 2 { healthy } else { rows };
        let (healthy_mean, healthy_std): (Vec<f64>, Vec<f64>) = (0..dim).map(|j| mean_std(healthy, j)).unzip();
        let mut s = Standardizer { healthy_mean, healthy_std, mean: vec![0.0; dim], std: vec![1.0; dim] };
        let compressed: Vec<Vec<f64>> = rows.iter().map(|r| s.compress(r)).collect();
        let compressed: Vec<&[f64]> = compressed.iter().map(|r| &r[..]).collect();
        (s.mean, s.std) = (0..dim).map(|j| mean_std(&compressed, j)).unzip();
        s
    }

    fn compress(&self, x: &[f64]) -> Vec<f64> {
        x.iter().zip(&self.healthy_mean).zip(&self.healthy_std).map(|((v, m), s)| ((v - m) / s).asinh()).collect()
    }

    pub fn apply(&self, x: &[f64]) -> Vec<f64> {
        let u = self.compress(x);
        u.iter().zip(&self.mean).zip(&self.std).map(|((v, m), s)| (v - m) / s).collect()
    }
}

/// The separability `s = d / (sigma_a + sigma_b)` of two sample sets (module docs): `d` the distance of
/// their means, `sigma` the mean distance of a set's samples from its mean with `n - 1` in the
/// denominator. `+inf` for distinct means with no spread, 0 for equal means.
pub fn separability(a: &[&[f64]], b: &[&[f64]]) -> f64 {
    let centre = |set: &[&[f64]]| -> Vec<f64> {
        let n = set.len() as f64;
        (0..set[0].len()).map(|j| set.iter().map(|r| r[j]).sum::<f64>() / n).collect()
    };
    let distance = |x: &[f64], y: &[f64]| x.iter().zip(y).map(|(p, q)| (p - q).powi(2)).sum::<f64>().sqrt();
    let spread =
        |set: &[&[f64]], c: &[f64]| set.iter().map(|r| distance(r, c)).sum::<f64>() / (set.len() as f64 - 1.0).max(1.0);
    let (ca, cb) = (centre(a), centre(b));
    let d = distance(&ca, &cb);
    let sigma = spread(a, &ca) + spread(b, &cb);
    if d == 0.0 {
        0.0
    } else if sigma == 0.0 {
        f64::INFINITY
    } else {
        d / sigma
    }
}

/// A node of the decision tree.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "node", rename_all = "snake_case")]
pub enum TreeNode {
    Leaf {
        class: FaultClass,
    },
    Split {
        svm: BinarySvm,
        /// Separability of the two groups when they were merged.
        separability: f64,
        /// Taken when `decision >= 0`.
        positive: Box<TreeNode>,
        negative: Box<TreeNode>,
    },
}

impl TreeNode {
    /// The classes below this node, sorted.
    pub fn classes(&self) -> Vec<FaultClass> {
        match self {
            TreeNode::Leaf { class } => vec![*class],
            TreeNode::Split { positive, negative, .. } => {
                let mut c = positive.classes();
                c.extend(negative.classes());
                c.sort();
                c
            }
        }
    }

    fn classify(&self, x: &[f64]) -> FaultClass {
        match self {
            TreeNode::Leaf { class } => *class,
            TreeNode::Split { svm, positive, negative, .. } => {
                if svm.decision(x) >= 0.0 {
                    positive.classify(x)
                } else {
                    negative.classify(x)
                }
            }
        }
    }
}

/// The separability of one candidate pair of groups at one merge.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PairSeparability {
    pub first: Vec<FaultClass>,
    pub second: Vec<FaultClass>,
    pub separability: f64,
}

/// One bottom-up step: the pair merged (the least separable) and every candidate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Merge {
    /// Positive side of the SVM trained here.
    pub positive: Vec<FaultClass>,
    pub negative: Vec<FaultClass>,
    pub separability: f64,
    pub candidates: Vec<PairSeparability>,
}

/// The seed's bottom-up SVM decision tree (module docs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SvmTree {
    pub root: TreeNode,
    /// In training order: the first is the least separable pair of single classes.
    pub merges: Vec<Merge>,
}

/// Standardised training rows of each class present, in class order.
type ClassRows<'a> = Vec<(FaultClass, Vec<&'a [f64]>)>;

/// A group of classes during the bottom-up build: its classes, their pooled rows, its subtree.
type Group<'a> = (Vec<FaultClass>, Vec<&'a [f64]>, TreeNode);

impl SvmTree {
    /// Bottom-up training on standardised rows grouped by class (module docs), merging the least
    /// separable pair first (the patent's order) or, for comparison, the most separable. Ties in
    /// separability go to the pair met first (groups in class order, merged groups where their first
    /// member was).
    fn train(rows: &ClassRows, params: &SvmParams, least_first: bool) -> Result<Self, ClassifierError> {
        let mut groups: Vec<Group> =
            rows.iter().map(|(c, r)| (vec![*c], r.clone(), TreeNode::Leaf { class: *c })).collect();
        let mut merges = Vec::new();
        while groups.len() > 1 {
            let mut candidates = Vec::new();
            let mut best = (0, 1, if least_first { f64::INFINITY } else { f64::NEG_INFINITY });
            for i in 0..groups.len() {
                for j in i + 1..groups.len() {
                    let s = separability(&groups[i].1, &groups[j].1);
                    candidates.push(PairSeparability {
                        first: groups[i].0.clone(),
                        second: groups[j].0.clone(),
                        separability: s,
                    });
                    if (least_first && s < best.2) || (!least_first && s > best.2) {
                        best = (i, j, s);
                    }
                }
            }
            let (i, j, s) = best;
            let (negative_classes, negative_rows, negative_node) = groups.remove(j);
            let (positive_classes, positive_rows, positive_node) = groups.remove(i);
            let what = format!("tree node {positive_classes:?} vs {negative_classes:?}");
            let svm = BinarySvm::train(&positive_rows, &negative_rows, params, what)?;
            merges.push(Merge {
                positive: positive_classes.clone(),
                negative: negative_classes.clone(),
                separability: s,
                candidates,
            });
            let node = TreeNode::Split {
                svm,
                separability: s,
                positive: Box::new(positive_node),
                negative: Box::new(negative_node),
            };
            let mut classes = positive_classes;
            classes.extend(negative_classes);
            let mut pooled = positive_rows;
            pooled.extend(negative_rows);
            groups.insert(i, (classes, pooled, node));
        }
        let root = groups.pop().map(|g| g.2).expect("at least one class");
        Ok(SvmTree { root, merges })
    }

    pub fn classify(&self, x: &[f64]) -> FaultClass {
        self.root.classify(x)
    }
}

/// Flat one-against-one SVM: one binary SVM per pair of classes, majority vote; a tie goes to the class
/// with the larger sum of the decision values in its favour, then to the lower class index.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OneVsOne {
    /// `(positive, negative, svm)` for every pair, in class order.
    pub machines: Vec<(FaultClass, FaultClass, BinarySvm)>,
}

impl OneVsOne {
    fn train(rows: &ClassRows, params: &SvmParams) -> Result<Self, ClassifierError> {
        let mut machines = Vec::new();
        for (i, (a, ra)) in rows.iter().enumerate() {
            for (b, rb) in &rows[i + 1..] {
                machines.push((*a, *b, BinarySvm::train(ra, rb, params, format!("{a:?} vs {b:?}"))?));
            }
        }
        Ok(OneVsOne { machines })
    }

    pub fn classify(&self, x: &[f64]) -> FaultClass {
        let mut votes = [0u32; CLASS_COUNT];
        let mut margin = [0.0f64; CLASS_COUNT];
        for (a, b, svm) in &self.machines {
            let d = svm.decision(x);
            let (winner, m) = if d >= 0.0 { (*a, d) } else { (*b, -d) };
            votes[winner.index()] += 1;
            margin[winner.index()] += m;
        }
        let best = (0..CLASS_COUNT)
            .max_by(|&i, &j| votes[i].cmp(&votes[j]).then(margin[i].total_cmp(&margin[j])).then(j.cmp(&i)))
            .unwrap_or(0);
        FaultClass::ALL[best]
    }
}

/// Which multi-class scheme.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum ClassifierModel {
    Tree(SvmTree),
    OneVsOne(OneVsOne),
}

/// Tag of the saved JSON.
pub const CLASSIFIER_FORMAT: &str = "fdimc-ekf-svm/1";

/// A trained classifier: feature settings, standardisation and the SVMs; saved and loaded as JSON.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Classifier {
    pub format: String,
    pub feature_names: Vec<String>,
    pub features: FeatureParams,
    pub svm: SvmParams,
    pub standardizer: Standardizer,
    pub model: ClassifierModel,
}

/// Which scheme to train.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Scheme {
    /// The seed's bottom-up decision tree (least separable pair merged first).
    Tree,
    /// The same tree built in the opposite order, the most separable pair first (comparison).
    TreeMostSeparableFirst,
    /// Flat one-against-one (comparison).
    OneVsOne,
}

/// Which window a classifier is trained on and classifies.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ClassifierWindow {
    /// The window after the true onset, for every trial detected or not: an oracle.
    Onset,
    /// The window from the residual detector's alarm, as the patent classifies online; no alarm, no
    /// classification (the trial is called normal).
    Alarm,
}

/// What a classifier is trained on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TrainingData {
    /// Simulated trials of the deck's scenario (the training seed).
    #[default]
    Simulation,
    /// Faults injected into the replayed log's training part (`log.train_s`), kept apart in time from
    /// the evaluated part.
    Log,
}

impl TrainingData {
    pub fn name(self) -> &'static str {
        match self {
            TrainingData::Simulation => "simulation",
            TrainingData::Log => "log",
        }
    }
}

impl Scheme {
    /// The deck's spelling.
    pub fn name(self) -> &'static str {
        match self {
            Scheme::Tree => "tree",
            Scheme::TreeMostSeparableFirst => "tree_most_separable_first",
            Scheme::OneVsOne => "flat",
        }
    }
}

impl ClassifierWindow {
    pub fn name(self) -> &'static str {
        match self {
            ClassifierWindow::Onset => "onset",
            ClassifierWindow::Alarm => "alarm",
        }
    }
}

/// One classifier of a study: its name (the detector column), scheme, window and class weighting.
#[derive(Debug, Clone, PartialEq)]
pub struct ClassifierSpec {
    pub name: String,
    pub scheme: Scheme,
    pub window: ClassifierWindow,
    pub balanced: bool,
    pub trained_on: TrainingData,
}

impl ClassifierSpec {
    /// The classifiers of a deck without `[[classifier]]`: the tree and the flat SVM on the onset window.
    pub fn defaults() -> Vec<ClassifierSpec> {
        [("tree", Scheme::Tree), ("flat", Scheme::OneVsOne)]
            .map(|(name, scheme)| ClassifierSpec {
                name: name.into(),
                scheme,
                window: ClassifierWindow::Onset,
                balanced: false,
                trained_on: TrainingData::Simulation,
            })
            .into()
    }
}

impl Classifier {
    /// Trains `scheme` on `examples` (every class needs at least 2; classes absent from the examples are
    /// left out of the model), standardising with their mean and standard deviation.
    pub fn train(
        scheme: Scheme,
        examples: &[Example],
        features: FeatureParams,
        svm: SvmParams,
    ) -> Result<Self, ClassifierError> {
        svm.validate()?;
        if let Some(index) = examples.iter().position(|e| !e.features.iter().all(|v| v.is_finite())) {
            return Err(ClassifierError::NonFiniteExample { index });
        }
        let raw: Vec<&[f64]> = examples.iter().map(|e| &e.features[..]).collect();
        if raw.is_empty() {
            return Err(ClassifierError::TooFewExamples { class: FaultClass::Normal, count: 0 });
        }
        let healthy: Vec<&[f64]> =
            examples.iter().filter(|e| e.class == FaultClass::Normal).map(|e| &e.features[..]).collect();
        let standardizer = Standardizer::fit(&raw, &healthy);
        let scaled: Vec<Vec<f64>> = raw.iter().map(|x| standardizer.apply(x)).collect();
        let mut rows: ClassRows = Vec::new();
        for class in FaultClass::ALL {
            let r: Vec<&[f64]> =
                examples.iter().zip(&scaled).filter(|(e, _)| e.class == class).map(|(_, x)| &x[..]).collect();
            match r.len() {
                0 => {}
                1 => return Err(ClassifierError::TooFewExamples { class, count: 1 }),
                _ => rows.push((class, r)),
            }
        }
        if rows.len() < 2 {
            let class = rows.first().map_or(FaultClass::Normal, |r| r.0);
            return Err(ClassifierError::TooFewExamples { class, count: 0 });
        }
        let model = match scheme {
            Scheme::Tree => ClassifierModel::Tree(SvmTree::train(&rows, &svm, true)?),
            Scheme::TreeMostSeparableFirst => ClassifierModel::Tree(SvmTree::train(&rows, &svm, false)?),
            Scheme::OneVsOne => ClassifierModel::OneVsOne(OneVsOne::train(&rows, &svm)?),
        };
        Ok(Classifier {
            format: CLASSIFIER_FORMAT.to_string(),
            feature_names: FEATURE_NAMES.iter().map(|s| s.to_string()).collect(),
            features,
            svm,
            standardizer,
            model,
        })
    }

    /// The class of a (raw, unstandardised) feature vector.
    pub fn classify(&self, features: &[f64]) -> Result<FaultClass, ClassifierError> {
        if features.len() != self.standardizer.mean.len() {
            return Err(ClassifierError::FeatureCount { expected: self.standardizer.mean.len(), got: features.len() });
        }
        if !features.iter().all(|v| v.is_finite()) {
            return Err(ClassifierError::NonFiniteFeature);
        }
        let x = self.standardizer.apply(features);
        Ok(match &self.model {
            ClassifierModel::Tree(tree) => tree.classify(&x),
            ClassifierModel::OneVsOne(flat) => flat.classify(&x),
        })
    }

    /// The class of a residual window (features with the saved settings).
    pub fn classify_window(&self, window: &[ResidualSample]) -> Result<FaultClass, ClassifierError> {
        self.classify(&features(window, &self.features)?)
    }

    /// The decision tree, if this is one.
    pub fn tree(&self) -> Option<&SvmTree> {
        match &self.model {
            ClassifierModel::Tree(t) => Some(t),
            ClassifierModel::OneVsOne(_) => None,
        }
    }

    pub fn to_json(&self) -> Result<String, ClassifierError> {
        serde_json::to_string(self).map_err(|e| ClassifierError::Json(e.to_string()))
    }

    pub fn from_json(text: &str) -> Result<Self, ClassifierError> {
        let c: Classifier = serde_json::from_str(text).map_err(|e| ClassifierError::Json(e.to_string()))?;
        if c.format != CLASSIFIER_FORMAT {
            return Err(ClassifierError::Format { found: c.format });
        }
        Ok(c)
    }

    /// Writes the JSON to a temporary name beside `path`, then renames it into place.
    pub fn save(&self, path: &Path) -> Result<(), ClassifierError> {
        let io = |e: std::io::Error| ClassifierError::Io { path: path.to_path_buf(), message: e.to_string() };
        let mut temporary = path.as_os_str().to_owned();
        temporary.push(".tmp");
        std::fs::write(&temporary, self.to_json()?).map_err(io)?;
        std::fs::rename(&temporary, path).map_err(io)
    }

    pub fn load(path: &Path) -> Result<Self, ClassifierError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| ClassifierError::Io { path: path.to_path_buf(), message: e.to_string() })?;
        Self::from_json(&text)
    }
}

/// Counts `[true class][predicted class]`, indexed by [`FaultClass::index`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ConfusionMatrix {
    pub counts: [[u32; CLASS_COUNT]; CLASS_COUNT],
}

impl ConfusionMatrix {
    /// The classifier's confusion matrix on `examples`; examples it cannot classify (non-finite
    /// features) are returned as a count instead.
    pub fn of(classifier: &Classifier, examples: &[Example]) -> (Self, usize) {
        let mut m = ConfusionMatrix::default();
        let mut failed = 0;
        for e in examples {
            match classifier.classify(&e.features) {
                Ok(c) => m.counts[e.class.index()][c.index()] += 1,
                Err(_) => failed += 1,
            }
        }
        (m, failed)
    }

    /// Correct over total (NaN when empty).
    pub fn accuracy(&self) -> f64 {
        let total: u32 = self.counts.iter().flatten().sum();
        let correct: u32 = (0..CLASS_COUNT).map(|i| self.counts[i][i]).sum();
        correct as f64 / total as f64
    }

    /// Recall of each class (NaN for a class with no example).
    pub fn recall(&self) -> [f64; CLASS_COUNT] {
        std::array::from_fn(|i| self.counts[i][i] as f64 / self.counts[i].iter().sum::<u32>() as f64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand::rngs::ChaCha8Rng;
    use std::sync::OnceLock;

    /// `per_class` trials of every class of [`TrialDesign::seed`], classes interleaved, from one RNG.
    fn examples(per_class: usize, seed: u64) -> Vec<Example> {
        let design = TrialDesign::seed();
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        (0..per_class)
            .flat_map(|_| FaultClass::ALL)
            .map(|class| design.draw_example(class, &mut rng).unwrap())
            .collect()
    }

    /// Training set (RNG seed 11) and test set (seed 12), 150 trials per class each; neither seed was
    /// used to choose the SVM settings.
    fn data() -> &'static (Vec<Example>, Vec<Example>) {
        static DATA: OnceLock<(Vec<Example>, Vec<Example>)> = OnceLock::new();
        DATA.get_or_init(|| (examples(150, 11), examples(150, 12)))
    }

    fn trained(scheme: Scheme) -> Classifier {
        Classifier::train(scheme, &data().0, FeatureParams::seed(), SvmParams::seed()).unwrap()
    }

    #[test]
    fn features_follow_their_definitions() {
        let params = FeatureParams { dt_s: 0.1, window_len: 50, sensitivity_floor: 0.0, relative_noise: false };
        // x: a line 0.01 + 0.2 t; y: -0.5 times the gravity share plus 0.3; z: alternating +-0.01.
        let window: Vec<ResidualSample> = (0..50)
            .map(|i| {
                let t = i as f64 * 0.1;
                let g = [0.0, (0.7 * t).sin() * 0.4, -0.9];
                let e = [0.01 + 0.2 * t, 0.3 - 0.5 * g[1], if i % 2 == 0 { 0.01 } else { -0.01 }];
                ResidualSample { residual: e, predicted: g }
            })
            .collect();
        let f = features(&window, &params).unwrap();
        let t_mean = 0.1 * 49.0 / 2.0;
        assert!((f[0] - (0.01 + 0.2 * t_mean)).abs() < 1e-12);
        assert!((f[1] - 0.2).abs() < 1e-12 && f[2] < 1e-12, "a line: slope 0.2, no noise");
        assert_eq!(f[3], 0.0, "no swing of the gravity share: sensitivity 0");
        assert!((f[7] + 0.5).abs() < 1e-12, "sensitivity is the regression on the gravity share");
        assert!(f[8].abs() < 1e-12 && (f[10] - 0.01).abs() < 1e-4);
        // The floor pulls the sensitivity towards 0 when the swing is small against it.
        let floored = features(&window, &FeatureParams { sensitivity_floor: 1.0, ..params }).unwrap();
        assert!(floored[7] > -0.1 && floored[7] < 0.0);
        assert_eq!(features(&window[..49], &params), Err(ClassifierError::WindowLength { expected: 50, got: 49 }));
        let mut bad = window.clone();
        bad[7].residual[1] = f64::NAN;
        assert_eq!(features(&bad, &params), Err(ClassifierError::NonFiniteSample { index: 7 }));
        // Relative noise: z's 0.01 over the same alternation of 0.04 before the window is 0.25; x's
        // reference is a line (no noise), which leaves x's value; without the option nothing changes.
        let reference: Vec<ResidualSample> = (0..20)
            .map(|i| ResidualSample {
                residual: [0.1 * i as f64, 0.0, if i % 2 == 0 { 0.04 } else { -0.04 }],
                predicted: [0.0; 3],
            })
            .collect();
        let relative = FeatureParams { relative_noise: true, ..params };
        let r = features_with_reference(&window, &reference, &relative).unwrap();
        assert!((r[10] - 0.25).abs() < 0.01, "{}", r[10]);
        assert_eq!((r[2], r[0], r[1]), (f[2], f[0], f[1]));
        assert_eq!(features_with_reference(&window, &reference, &params).unwrap(), f);
        assert!(features_with_reference(&window, &reference[..2], &relative).is_err());
        assert_eq!(window_start(8.0, 0.0, 0.01), 800);
        assert_eq!(window_start(8.001, 0.5, 0.01), 851);
    }

    /// `s = d / (sigma_a + sigma_b)` on hand-computed sets: centres (0, 0) and (3, 4) (d = 5), spreads
    /// (1 + 1) / 1 = 2 and (2 + 2 + 2) / 2 = 3, so s = 1.
    #[test]
    fn separability_matches_its_formula() {
        let a: Vec<&[f64]> = vec![&[1.0, 0.0], &[-1.0, 0.0]];
        let b: Vec<&[f64]> = vec![&[5.0, 4.0], &[1.0, 4.0], &[3.0, 4.0]];
        // b's centre is (3, 4); distances 2, 2, 0 -> spread 4 / 2 = 2.
        assert!((separability(&a, &b) - 5.0 / (2.0 + 2.0)).abs() < 1e-15);
        assert_eq!(separability(&a, &a), 0.0);
        let point: Vec<&[f64]> = vec![&[7.0, 0.0], &[7.0, 0.0]];
        let other: Vec<&[f64]> = vec![&[0.0, 0.0], &[0.0, 0.0]];
        assert_eq!(separability(&point, &other), f64::INFINITY);
    }

    /// The separability formula written out again, on owned rows.
    fn separability_written_out(a: &[Vec<f64>], b: &[Vec<f64>]) -> f64 {
        let stats = |rows: &[Vec<f64>]| {
            let n = rows.len() as f64;
            let c: Vec<f64> = (0..rows[0].len()).map(|j| rows.iter().map(|r| r[j]).sum::<f64>() / n).collect();
            let dist = |r: &Vec<f64>| r.iter().zip(&c).map(|(a, b)| (a - b) * (a - b)).sum::<f64>().sqrt();
            let spread = rows.iter().map(dist).sum::<f64>() / (n - 1.0);
            (c, spread)
        };
        let ((ca, sa), (cb, sb)) = (stats(a), stats(b));
        ca.iter().zip(&cb).map(|(a, b)| (a - b) * (a - b)).sum::<f64>().sqrt() / (sa + sb)
    }

    /// Independent re-computation of a separability the tree should have used: the scaled rows of the
    /// examples of two groups of classes.
    fn recomputed(classifier: &Classifier, examples: &[Example], first: &[FaultClass], second: &[FaultClass]) -> f64 {
        let rows = |set: &[FaultClass]| -> Vec<Vec<f64>> {
            examples
                .iter()
                .filter(|e| set.contains(&e.class))
                .map(|e| classifier.standardizer.apply(&e.features))
                .collect()
        };
        separability_written_out(&rows(first), &rows(second))
    }

    /// Checks that `tree` is a full binary tree over the four classes (3 splits, 4 leaves, each class
    /// once) and that each merge took the least separable of the candidate pairs, with separabilities
    /// that agree with an independent computation to 1e-9.
    fn check_tree(classifier: &Classifier, examples: &[Example]) {
        let tree = classifier.tree().unwrap();
        fn count(node: &TreeNode) -> (usize, usize) {
            match node {
                TreeNode::Leaf { .. } => (0, 1),
                TreeNode::Split { positive, negative, .. } => {
                    let (a, b) = (count(positive), count(negative));
                    (a.0 + b.0 + 1, a.1 + b.1)
                }
            }
        }
        assert_eq!(count(&tree.root), (3, 4));
        assert_eq!(tree.root.classes(), FaultClass::ALL.to_vec());
        assert_eq!(tree.merges.len(), 3);
        assert_eq!(tree.merges.iter().map(|m| m.candidates.len()).collect::<Vec<_>>(), [6, 3, 1]);
        for merge in &tree.merges {
            for c in &merge.candidates {
                let s = recomputed(classifier, examples, &c.first, &c.second);
                assert!((s - c.separability).abs() < 1e-9 * s.max(1.0), "{c:?} vs {s}");
            }
            let least = merge.candidates.iter().map(|c| c.separability).fold(f64::INFINITY, f64::min);
            assert_eq!(merge.separability, least);
            let chosen = merge.candidates.iter().find(|c| c.separability == least).unwrap();
            assert_eq!((&chosen.first, &chosen.second), (&merge.positive, &merge.negative));
        }
        // The root splits what the last merge joined.
        let last = tree.merges.last().unwrap();
        let TreeNode::Split { positive, negative, .. } = &tree.root else { panic!("root is a leaf") };
        assert_eq!((positive.classes(), negative.classes()), (sorted(&last.positive), sorted(&last.negative)));
    }

    fn sorted(c: &[FaultClass]) -> Vec<FaultClass> {
        let mut c = c.to_vec();
        c.sort();
        c
    }

    /// The tree-building step on four synthetic clusters (already standardised rows) whose
    /// separabilities are known in advance: unit spread in 12 dimensions (a mean distance from the centre
    /// near sqrt(12)), centres on the first axis at bias 0, gain 3, stuck 8, normal 20. The tree must
    /// join bias and gain first, then stuck, and put normal alone under the root; each merge's
    /// separabilities match an independent computation and it takes the least separable pair; the cluster
    /// centres are classified top-down to their own class.
    #[test]
    fn tree_merges_follow_the_separabilities_on_synthetic_clusters() {
        use FaultClass::*;
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let centre = |c: FaultClass| match c {
            Normal => 20.0,
            Bias => 0.0,
            Gain => 3.0,
            Stuck => 8.0,
        };
        let owned: Vec<(FaultClass, Vec<Vec<f64>>)> = FaultClass::ALL
            .into_iter()
            .map(|class| {
                let rows = (0..60)
                    .map(|_| {
                        (0..FEATURE_COUNT)
                            .map(|j| {
                                let n: f64 = rand_distr::Distribution::sample(&rand_distr::StandardNormal, &mut rng);
                                if j == 0 { centre(class) + n } else { n }
                            })
                            .collect()
                    })
                    .collect();
                (class, rows)
            })
            .collect();
        let rows: ClassRows = owned.iter().map(|(c, r)| (*c, r.iter().map(|x| &x[..]).collect())).collect();
        let tree = SvmTree::train(&rows, &SvmParams::seed(), true).unwrap();
        let merges = &tree.merges;
        assert_eq!((sorted(&merges[0].positive), sorted(&merges[0].negative)), (vec![Bias], vec![Gain]));
        assert_eq!((sorted(&merges[1].positive), sorted(&merges[1].negative)), (vec![Bias, Gain], vec![Stuck]));
        assert_eq!((sorted(&merges[2].positive), sorted(&merges[2].negative)), (vec![Normal], vec![Bias, Gain, Stuck]));
        for merge in merges {
            for c in &merge.candidates {
                let pick = |set: &[FaultClass]| -> Vec<Vec<f64>> {
                    owned.iter().filter(|(k, _)| set.contains(k)).flat_map(|(_, r)| r.clone()).collect()
                };
                let s = separability_written_out(&pick(&c.first), &pick(&c.second));
                assert!((s - c.separability).abs() < 1e-12, "{c:?} vs {s}");
            }
            let least = merge.candidates.iter().map(|c| c.separability).fold(f64::INFINITY, f64::min);
            assert_eq!(merge.separability, least);
        }
        // Top-down classification of the cluster centres.
        let classifies_the_centres = |tree: &SvmTree| {
            for class in FaultClass::ALL {
                let mut x = vec![0.0; FEATURE_COUNT];
                x[0] = centre(class);
                assert_eq!(tree.classify(&x), class);
            }
        };
        classifies_the_centres(&tree);
        // The opposite order merges the farthest pair first (normal at 20 with bias at 0), each merge the
        // most separable candidate; it still classifies the centres.
        let reversed = SvmTree::train(&rows, &SvmParams::seed(), false).unwrap();
        let first = &reversed.merges[0];
        assert_eq!((sorted(&first.positive), sorted(&first.negative)), (vec![Normal], vec![Bias]));
        for merge in &reversed.merges {
            let most = merge.candidates.iter().map(|c| c.separability).fold(f64::NEG_INFINITY, f64::max);
            assert_eq!(merge.separability, most);
        }
        classifies_the_centres(&reversed);
    }

    /// Balanced weights at a node of one class against three: on overlapping clusters (centres 0 and 1.5,
    /// unit spread) with 40 examples against 360, equal `C` gives the boundary to the large side and the
    /// small class's examples are voted away; weighted by the inverse of each side's size they are kept.
    /// Measured: 2 of the 40 on their own side with equal `C`, 35 balanced.
    #[test]
    fn balanced_weights_keep_the_small_side_of_a_merged_node() {
        let mut rng = ChaCha8Rng::seed_from_u64(8);
        let mut draw = |centre: f64, n: usize| -> Vec<Vec<f64>> {
            (0..n)
                .map(|_| {
                    (0..2)
                        .map(|j| {
                            let e: f64 = rand_distr::Distribution::sample(&rand_distr::StandardNormal, &mut rng);
                            if j == 0 { centre + e } else { e }
                        })
                        .collect()
                })
                .collect()
        };
        let (small, large) = (draw(0.0, 40), draw(1.5, 360));
        let (small, large): (Vec<&[f64]>, Vec<&[f64]>) =
            (small.iter().map(|x| &x[..]).collect(), large.iter().map(|x| &x[..]).collect());
        let recall = |balanced: bool| {
            let params = SvmParams { balanced, ..SvmParams::seed() };
            let svm = BinarySvm::train(&small, &large, &params, "test".into()).unwrap();
            small.iter().filter(|x| svm.decision(x) >= 0.0).count()
        };
        let (equal, balanced) = (recall(false), recall(true));
        assert!(equal < 10 && balanced > 30, "small-side examples kept: equal C {equal}, balanced {balanced} of 40");
    }

    /// On residual features (150 trials per class, RNG seed 11) the tree merges the least separable
    /// pair first and follows the separabilities up to the root. Measured: normal/bias 0.071 is the least
    /// separable pair (a small bias on an axis near vertical hardly moves the gravity direction; the
    /// other pairs 0.20-0.61), then {normal, bias} + gain at 0.249, a near tie with gain/stuck at 0.250
    /// (with the validation seed the latter won: the shape past the first merge is fragile on these
    /// classes), and the root splits {normal, bias, gain} from stuck at 0.392.
    #[test]
    fn tree_on_residual_features_follows_the_separabilities() {
        let classifier = trained(Scheme::Tree);
        check_tree(&classifier, &data().0);
        for m in &classifier.tree().unwrap().merges {
            eprintln!(
                "merged {:?} with {:?} at s = {:.3}; candidates {:?}",
                m.positive, m.negative, m.separability, m.candidates
            );
        }
        let first = &classifier.tree().unwrap().merges[0];
        assert_eq!(
            sorted(&[first.positive.clone(), first.negative.clone()].concat()),
            [FaultClass::Normal, FaultClass::Bias]
        );
    }

    /// Train on one RNG seed, test on fresh trials of another (150 per class each). Floors: accuracy
    /// 0.85 for both, recall normal 0.95, bias 0.80, gain 0.60, stuck 0.85. Measured: tree accuracy
    /// 0.898 (recall 0.993, 0.920, 0.733, 0.947), flat one-against-one 0.902 (0.993, 0.920, 0.740,
    /// 0.953). Most errors are small gains taken for biases (32 of 150: within a second the gravity
    /// share of the axis barely changes, so a gain looks like a constant shift).
    #[test]
    fn tree_and_flat_classify_fresh_trials_above_the_floor() {
        for scheme in [Scheme::Tree, Scheme::OneVsOne] {
            let classifier = trained(scheme);
            let (matrix, failed) = ConfusionMatrix::of(&classifier, &data().1);
            assert_eq!(failed, 0);
            let recall = matrix.recall();
            eprintln!("{scheme:?}: accuracy {:.3}, recall {recall:?}, {:?}", matrix.accuracy(), matrix.counts);
            assert!(matrix.accuracy() > 0.85, "{scheme:?}: {matrix:?}");
            for (class, floor) in FaultClass::ALL.into_iter().zip([0.95, 0.80, 0.60, 0.85]) {
                assert!(recall[class.index()] > floor, "{scheme:?} {class:?}: {recall:?}");
            }
        }
    }

    /// JSON round trip (string and file) gives a classifier that classifies every test example as
    /// before, with decision values equal to 1e-12 (serde_json's float parsing may differ from the
    /// written value in the last bit).
    #[test]
    fn saved_and_loaded_classifiers_classify_identically() {
        let dir = tempfile::tempdir().unwrap();
        for scheme in [Scheme::Tree, Scheme::OneVsOne] {
            let classifier = trained(scheme);
            let path = dir.path().join(format!("{scheme:?}.json"));
            classifier.save(&path).unwrap();
            let loaded = Classifier::load(&path).unwrap();
            let from_string = Classifier::from_json(&classifier.to_json().unwrap()).unwrap();
            for other in [&loaded, &from_string] {
                assert_eq!(other.features, classifier.features);
                for e in &data().1 {
                    assert_eq!(other.classify(&e.features), classifier.classify(&e.features));
                }
                let x = classifier.standardizer.apply(&data().1[0].features);
                let decisions = |c: &Classifier| -> Vec<f64> {
                    match &c.model {
                        ClassifierModel::Tree(t) => {
                            t.merges.iter().map(|_| 0.0).chain(node_decisions(&t.root, &x)).collect()
                        }
                        ClassifierModel::OneVsOne(f) => f.machines.iter().map(|m| m.2.decision(&x)).collect(),
                    }
                };
                for (a, b) in decisions(&classifier).iter().zip(decisions(other)) {
                    assert!((a - b).abs() <= 1e-12 * a.abs().max(1.0), "{a} vs {b}");
                }
            }
        }
        let missing = dir.path().join("missing.json");
        assert!(matches!(Classifier::load(&missing), Err(ClassifierError::Io { .. })));
        let wrong = trained(Scheme::Tree).to_json().unwrap().replace(CLASSIFIER_FORMAT, "other/9");
        assert!(matches!(Classifier::from_json(&wrong), Err(ClassifierError::Format { .. })));
        assert!(matches!(Classifier::from_json("{"), Err(ClassifierError::Json(_))));
    }

    fn node_decisions(node: &TreeNode, x: &[f64]) -> Vec<f64> {
        match node {
            TreeNode::Leaf { .. } => Vec::new(),
            TreeNode::Split { svm, positive, negative, .. } => {
                let mut d = vec![svm.decision(x)];
                d.extend(node_decisions(positive, x));
                d.extend(node_decisions(negative, x));
                d
            }
        }
    }

    /// The default threshold (60) raises no alarm after 3 s in 200 fresh fault-free trials (RNG seed 21;
    /// measured largest `T` 49.5) nor before the onset of faulty ones, and detects within 2 s of the
    /// onset at least 95 of 100 biases and every gain and stuck fault (100 trials per kind, seed 22).
    /// Measured: biases 98 (median delay 0.03 s, 90th percentile 0.16 s; the two missed are small and
    /// on an axis near vertical), gains 100 (0.01 s, 0.04 s), stuck 100 (0.12 s, 0.59 s).
    #[test]
    fn detection_threshold_bounds_fault_free_trials() {
        let design = TrialDesign::seed();
        let params = DetectionParams::seed();
        let mut rng = ChaCha8Rng::seed_from_u64(21);
        let mut largest = 0.0f64;
        for _ in 0..200 {
            let (scenario, _) = design.draw_trial(FaultClass::Normal, &mut rng);
            let trace = simulate_trial(scenario, &design.ekf, &mut rng).unwrap();
            let statistics = detection_statistics(&trace.samples, &params);
            largest = largest.max(statistics[300..].iter().cloned().fold(0.0, f64::max));
        }
        assert!(largest < params.threshold, "largest fault-free statistic {largest}");
        let mut rng = ChaCha8Rng::seed_from_u64(22);
        for class in [FaultClass::Bias, FaultClass::Gain, FaultClass::Stuck] {
            let mut delays = Vec::new();
            for _ in 0..100 {
                let (scenario, onset_s) = design.draw_trial(class, &mut rng);
                let trace = simulate_trial(scenario, &design.ekf, &mut rng).unwrap();
                let statistics = detection_statistics(&trace.samples, &params);
                let k0 = window_start(onset_s, 0.0, trace.dt_s);
                assert_eq!(
                    first_alarm(&statistics, params.threshold, 300),
                    first_alarm(&statistics, params.threshold, k0)
                );
                let alarm = first_alarm(&statistics, params.threshold, k0);
                delays.push(alarm.map_or(f64::INFINITY, |k| (k - k0) as f64 * trace.dt_s));
            }
            delays.sort_by(f64::total_cmp);
            let within_2_s = delays.iter().filter(|d| **d < 2.0).count();
            eprintln!(
                "{class:?}: {within_2_s} of 100 within 2 s, delay median {} s, 90 % {} s (healthy max T {largest})",
                delays[50], delays[90]
            );
            // A bias on an axis near vertical hardly moves the gravity direction: some go unseen.
            let floor = if class == FaultClass::Bias { 95 } else { 100 };
            assert!(within_2_s >= floor, "{class:?}: {delays:?}");
        }
    }

    /// The detector's statistic is `n |mean|^2 / sigma^2` of the last `n` residuals, none before the
    /// window fills, NaN while a non-finite residual is in it.
    #[test]
    fn detector_statistic_is_the_windowed_mean_norm() {
        let params = DetectionParams { window: 4, residual_std: 0.5, threshold: 3.0 };
        let mut d = ResidualDetector::new(params);
        let r = |x: f64| Vector3::new(x, 0.0, 0.0);
        assert_eq!([d.push(&r(1.0)), d.push(&r(1.0)), d.push(&r(1.0))], [None, None, None]);
        assert_eq!(d.push(&r(1.0)), Some(4.0 * 1.0 / 0.25));
        assert_eq!(d.push(&r(-1.0)), Some(4.0 * 0.25 / 0.25));
        assert!(d.alarms(4.0) && !d.alarms(1.0));
        assert!(d.push(&r(f64::NAN)).unwrap().is_nan());
        assert_eq!(first_alarm(&[f64::NAN, 1.0, 5.0, 2.0, 7.0], 3.0, 0), Some(2));
        assert_eq!(first_alarm(&[f64::NAN, 1.0, 5.0, 2.0, 7.0], 3.0, 3), Some(4));
    }

    #[test]
    fn classifier_misuse_is_an_error_value() {
        let (train, test) = data();
        let classifier = trained(Scheme::OneVsOne);
        assert_eq!(classifier.classify(&[0.0; 3]), Err(ClassifierError::FeatureCount { expected: 12, got: 3 }));
        let mut x = test[0].features;
        x[4] = f64::INFINITY;
        assert_eq!(classifier.classify(&x), Err(ClassifierError::NonFiniteFeature));
        let one_stuck: Vec<Example> = train
            .iter()
            .filter(|e| e.class != FaultClass::Stuck)
            .cloned()
            .chain(train.iter().find(|e| e.class == FaultClass::Stuck).cloned())
            .collect();
        assert_eq!(
            Classifier::train(Scheme::Tree, &one_stuck, FeatureParams::seed(), SvmParams::seed()),
            Err(ClassifierError::TooFewExamples { class: FaultClass::Stuck, count: 1 })
        );
        let bad = SvmParams { c: 0.0, ..SvmParams::seed() };
        assert!(matches!(
            Classifier::train(Scheme::Tree, train, FeatureParams::seed(), bad),
            Err(ClassifierError::Params(_))
        ));
        let mut with_nan = train.clone();
        with_nan[3].features[0] = f64::NAN;
        assert_eq!(
            Classifier::train(Scheme::Tree, &with_nan, FeatureParams::seed(), SvmParams::seed()),
            Err(ClassifierError::NonFiniteExample { index: 3 })
        );
        let design = TrialDesign::seed();
        let short = ImuScenarioParams { duration_s: 5.0, ..ImuScenarioParams::seed() };
        let trace = simulate_trial(short, &design.ekf, &mut ChaCha8Rng::seed_from_u64(1)).unwrap();
        assert_eq!(
            design.example(&trace, 4.95, FaultClass::Normal),
            Err(ClassifierError::TrialTooShort { end: 595, samples: 500 })
        );
        let coarse = ResidualTrace { dt_s: 0.02, ..trace.clone() };
        assert!(matches!(design.example(&coarse, 1.0, FaultClass::Normal), Err(ClassifierError::SamplePeriod { .. })));
        // Three classes train a two-split tree without the missing one.
        let three: Vec<Example> = train.iter().filter(|e| e.class != FaultClass::Gain).cloned().collect();
        let c = Classifier::train(Scheme::Tree, &three, FeatureParams::seed(), SvmParams::seed()).unwrap();
        assert_eq!(c.tree().unwrap().merges.len(), 2);
        assert!(!c.tree().unwrap().root.classes().contains(&FaultClass::Gain));
    }
}
