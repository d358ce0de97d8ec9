//! The detection rule on the residual and the trials: one trial's filter output, and the training and
//! evaluation examples drawn from the trial design.

use nalgebra::{Vector3, Vector4};
use rand::Rng;
use thiserror::Error;

use crate::methods::accelerometer::attitude::{
    AttitudeEkf, AttitudeEkfParams, AttitudeHealth, as_vector, tilt_error_rad,
};
use crate::methods::accelerometer::imu::{AccelFaultRanges, ImuScenario, ImuScenarioError, ImuScenarioParams};

use super::features::*;

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
    pub(super) params: DetectionParams,
    pub(super) ring: Vec<Vector3<f64>>,
    pub(super) next: usize,
    pub(super) filled: usize,
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
    /// With `filter_knows_noise`: the scale is not the trial's true one but estimated from a first pass
    /// of the nominal filter, as the RMS of its residual components over `[from, to)` s (before any
    /// fault) against the nominal residual sigma (see [`Self::simulate_tuned`]); `None`: the true one.
    pub noise_estimate_s: Option<[f64; 2]>,
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
            noise_estimate_s: None,
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

    pub(super) fn example_from(
        &self,
        trace: &ResidualTrace,
        start: usize,
        class: FaultClass,
    ) -> Result<Example, ClassifierError> {
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

    /// Simulates `scenario` with the filter tuned as the design says, and returns the residuals and the
    /// noise scale the filter and the detector were tuned to: 1 (nominal), the scenario's own, or its
    /// estimate ([`Self::noise_estimate_s`]): the trial is flown once with the nominal filter on a copy
    /// of `rng` (`fork` makes it), the estimate read off its residuals before any fault, then flown
    /// again, on the same noise, with the filter tuned to it (what a flight computer could do on its
    /// first seconds).
    pub fn simulate_tuned<R: Rng>(
        &self,
        scenario: ImuScenarioParams,
        detection: &DetectionParams,
        rng: &mut R,
        fork: impl FnOnce(&R) -> R,
    ) -> Result<(ResidualTrace, f64), TrialError> {
        let scale = match (self.filter_knows_noise, self.noise_estimate_s) {
            (false, _) => 1.0,
            (true, None) => scenario.noise_scale,
            (true, Some([from_s, to_s])) => {
                let first = simulate_trial(scenario.clone(), &self.ekf, &mut fork(rng))?;
                let k = |t_s: f64| ((t_s / first.dt_s).round() as usize).min(first.samples.len());
                let window = &first.samples[k(from_s)..k(to_s)];
                let square_sum: f64 = window.iter().flat_map(|s| s.residual).map(|e| e * e).sum();
                let rms = (square_sum / (3 * window.len().max(1)) as f64).sqrt();
                rms / detection.residual_std
            }
        };
        let ekf = if self.filter_knows_noise { self.ekf_for(scale) } else { self.ekf };
        Ok((simulate_trial(scenario, &ekf, rng)?, scale))
    }

    /// [`Self::draw_trial`], [`simulate_trial`] and [`Self::example`] with one RNG, in that order.
    pub fn draw_example<R: Rng + ?Sized>(&self, class: FaultClass, rng: &mut R) -> Result<Example, TrialError> {
        let (scenario, onset_s) = self.draw_trial(class, rng);
        let trace = simulate_trial(scenario, &self.ekf_for(self.scenario.noise_scale), rng)?;
        Ok(self.example(&trace, onset_s, class)?)
    }
}
