//! The classes, a residual sample, the features of a window of them, and what can go wrong making
//! features or a classifier (the saved classifier's format tag among it).

use std::path::PathBuf;

use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::methods::accelerometer::attitude::AttitudeStep;
use crate::methods::accelerometer::imu::AccelFaultKind;

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

    /// Index in [`Self::ALL`] (rows and columns of a [`super::ConfusionMatrix`]).
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
    /// shift with a time constant of about 1.2 s at [`crate::methods::accelerometer::attitude::AttitudeEkfParams::seed`] (measured: the mean
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

/// Tag of the saved JSON.
pub const CLASSIFIER_FORMAT: &str = "fdimc-ekf-svm/1";

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
pub(super) fn regression(x: &[f64], y: &[f64], floor: f64) -> (f64, f64) {
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
