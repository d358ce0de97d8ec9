//! IMU scenarios for method 003 (`docs/findings-seed003.md`: accelerometer fault monitoring from
//! attitude-EKF residuals): a vehicle turning through prescribed attitude manoeuvres, a three-axis gyro
//! and a three-axis accelerometer with white noise and small constant biases, and accelerometer faults
//! (bias, gain, stuck; any axis) through [`crate::fault::ActiveFaults`].
//!
//! # Frames and truth
//! NED navigation axes, body axes x forward, y right, z down. The attitude is the quaternion
//! `q = (q0, q1, q2, q3)` (scalar first) of the rotation from body to NED axes, built from Euler angles
//! roll `phi`, pitch `theta`, yaw `psi` in the aerospace order (yaw, then pitch, then roll); its
//! transpose rotation is `C_bn` ([`crate::kinematics::body_from_ned`]). The manoeuvre
//! ([`AttitudeManoeuvre`]) prescribes each Euler angle as `mean + amplitude sin(2 pi t / period + phase)`,
//! so attitude and rates are analytic: `p = phi' - psi' sin(theta)`,
//! `q = theta' cos(phi) + psi' cos(theta) sin(phi)`, `r = -theta' sin(phi) + psi' cos(theta) cos(phi)`.
//!
//! The vehicle's own (translational) acceleration is zero: it rotates about its centre of mass, as on a
//! rate table. That is the seed's validity condition (`a_n << g`) made exact, so the accelerometer reads
//! `f = C_bn (a_n - g_n) = -g C_bn e_3` and its direction is the gravity direction the EKF measures.
//! What a real manoeuvre's acceleration does to the classifier is a question for a study, not modelled
//! here.
//!
//! # Sensors
//! - gyro: `w_m = w + b_g + sigma_g n` (rad/s);
//! - accelerometer: `a_m = f + b_a + sigma_a n` (m/s^2), then the faults replace channel
//!   [`ACCEL_X`], [`ACCEL_Y`] or [`ACCEL_Z`] by `beta a_m + alpha` (seed's unified form) with
//!   - bias: `beta = 1`, `alpha != 0` ([`crate::fault::FaultMode::Bias`], m/s^2);
//!   - gain: `beta != 1`, `alpha = 0` ([`crate::fault::FaultMode::Gain`]);
//!   - stuck: a constant output ([`crate::fault::FaultMode::Stuck`]; by default the reading held at the
//!     onset sample, noise included, so the output freezes without a jump).
//!
//! The biases `b_g`, `b_a` are constant per trial and are plain parameters
//! ([`ImuScenarioParams::gyro_bias_rad_s`], [`ImuScenarioParams::accel_bias_mps2`]);
//! [`ImuScenarioParams::draw_sensor_biases`] draws them from [`ImuNoise`].
//!
//! # Random draws (fixed order: the same RNG state gives bit-identical samples)
//! - [`ImuScenarioParams::draw_sensor_biases`]: 6 standard normals: gyro x, y, z, accelerometer x, y, z.
//! - [`AccelFaultRanges::draw`]: 4 uniforms in `[0, 1)` (`rng.random::<f64>()`, one `u64` each): axis,
//!   size, sign, onset, for every kind and for the fault-free class too (then only the onset is used:
//!   it is the nominal time a classification window starts), so trials of different classes drawn from
//!   one RNG state share axis and onset (common random numbers).
//! - [`ImuScenario::next_sample`]: [`DRAWS_PER_SAMPLE`] = 6 standard normals per sample, always in this
//!   order and whatever the noise settings: gyro x, y, z noise, accelerometer x, y, z noise.
//!
//! The numbers of [`ImuNoise::seed`], [`AttitudeManoeuvre::seed`] and [`AccelFaultRanges::seed`] are
//! chosen (typical of a MEMS IMU on a small UAV); the patent gives none.
#![allow(non_snake_case)]

use nalgebra::{UnitQuaternion, Vector3};
use rand::{Rng, RngExt};
use rand_distr::{Distribution, StandardNormal};
use thiserror::Error;

use crate::checks::{ValueError, finite, non_negative, positive, sensor_faults};
use crate::fault::{ActiveFaults, ChannelFault, FaultMode};
use crate::kinematics::{GRAVITY_MPS2, body_from_ned};

/// Accelerometer channel indices (the `channel` of a [`ChannelFault`]).
pub const ACCEL_X: usize = 0;
pub const ACCEL_Y: usize = 1;
pub const ACCEL_Z: usize = 2;
pub const ACCEL_CHANNEL_NAMES: [&str; 3] = ["ax_mps2", "ay_mps2", "az_mps2"];

/// Standard normals drawn per sample (module docs).
pub const DRAWS_PER_SAMPLE: usize = 6;

/// Largest `|mean| + |amplitude|` of the pitch history (rad): 80 deg keeps the Euler rates away from
/// their singularity at 90 deg.
pub const MAX_PITCH_RAD: f64 = 80.0 * std::f64::consts::PI / 180.0;

/// One Euler angle's history: `mean_rad + amplitude_rad sin(2 pi t / period_s + phase_rad)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EulerSinusoid {
    pub mean_rad: f64,
    pub amplitude_rad: f64,
    pub period_s: f64,
    pub phase_rad: f64,
}

impl EulerSinusoid {
    /// A constant angle.
    pub fn constant(angle_rad: f64) -> Self {
        EulerSinusoid { mean_rad: angle_rad, amplitude_rad: 0.0, period_s: 1.0, phase_rad: 0.0 }
    }

    /// Value (rad) and rate (rad/s) at `t_s`.
    pub fn eval(&self, t_s: f64) -> (f64, f64) {
        let w = std::f64::consts::TAU / self.period_s;
        let (s, c) = (w * t_s + self.phase_rad).sin_cos();
        (self.mean_rad + self.amplitude_rad * s, self.amplitude_rad * w * c)
    }
}

/// Prescribed attitude (module docs): roll, pitch and yaw histories, and an optional translational
/// acceleration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AttitudeManoeuvre {
    pub roll: EulerSinusoid,
    pub pitch: EulerSinusoid,
    pub yaw: EulerSinusoid,
    /// Amplitude of the vehicle's acceleration in NED axes (m/s^2; 0: none, the seed's motion): north
    /// `A sin(2 pi t / 7 s)`, east `A sin(2 pi t / 11 s)`, down `A / 2 sin(2 pi t / 13 s)` (periods
    /// incommensurate with the attitude's, a choice). The accelerometers feel it; the attitude EKF takes
    /// the specific force for gravity alone, so it reaches the residual.
    pub translation_mps2: f64,
}

impl AttitudeManoeuvre {
    /// Roll +-30 deg over 8 s, pitch +-20 deg over 5 s, yaw +-45 deg over 12 s, all phases 0 (peak
    /// rates 24, 25 and 24 deg/s). The roll and pitch periods are incommensurate over a trial, so the
    /// gravity direction in body axes keeps moving through every axis: a gain fault (proportional to
    /// the axis' share of gravity) and a stuck one (frozen while that share changes) then look different
    /// from a bias within a window of 1-2 s, and the x and y axes, horizontal in level flight, carry up
    /// to 0.34 and 0.5 g. Yaw does not change the gravity direction; it exercises the quaternion.
    pub fn seed() -> Self {
        let deg = |d: f64| d.to_radians();
        let sine = |amplitude_deg: f64, period_s: f64| EulerSinusoid {
            mean_rad: 0.0,
            amplitude_rad: deg(amplitude_deg),
            period_s,
            phase_rad: 0.0,
        };
        AttitudeManoeuvre {
            roll: sine(30.0, 8.0),
            pitch: sine(20.0, 5.0),
            yaw: sine(45.0, 12.0),
            translation_mps2: 0.0,
        }
    }

    /// The translational acceleration in NED axes at `t_s` (m/s^2; see [`Self::translation_mps2`]).
    pub fn acceleration_ned_mps2(&self, t_s: f64) -> Vector3<f64> {
        let wave = |period_s: f64| (std::f64::consts::TAU * t_s / period_s).sin();
        self.translation_mps2 * Vector3::new(wave(7.0), wave(11.0), 0.5 * wave(13.0))
    }

    /// A constant attitude.
    pub fn still(roll_rad: f64, pitch_rad: f64, yaw_rad: f64) -> Self {
        AttitudeManoeuvre {
            roll: EulerSinusoid::constant(roll_rad),
            pitch: EulerSinusoid::constant(pitch_rad),
            yaw: EulerSinusoid::constant(yaw_rad),
            translation_mps2: 0.0,
        }
    }

    /// Every amplitude times `factor` (0: a constant attitude at the means).
    pub fn scaled(mut self, factor: f64) -> Self {
        for s in [&mut self.roll, &mut self.pitch, &mut self.yaw] {
            s.amplitude_rad *= factor;
        }
        self
    }

    /// The same manoeuvre with the phases `[roll, pitch, yaw]` (rad).
    pub fn with_phases(mut self, phases_rad: [f64; 3]) -> Self {
        self.roll.phase_rad = phases_rad[0];
        self.pitch.phase_rad = phases_rad[1];
        self.yaw.phase_rad = phases_rad[2];
        self
    }

    /// Euler angles `[roll, pitch, yaw]` (rad) and their rates (rad/s) at `t_s`.
    pub fn euler(&self, t_s: f64) -> ([f64; 3], [f64; 3]) {
        let (phi, phi_rate) = self.roll.eval(t_s);
        let (theta, theta_rate) = self.pitch.eval(t_s);
        let (psi, psi_rate) = self.yaw.eval(t_s);
        ([phi, theta, psi], [phi_rate, theta_rate, psi_rate])
    }

    fn validate(&self) -> Result<(), ImuScenarioError> {
        for (name, s) in [("roll", self.roll), ("pitch", self.pitch), ("yaw", self.yaw)] {
            let ok = s.mean_rad.is_finite()
                && s.amplitude_rad.is_finite()
                && s.phase_rad.is_finite()
                && s.period_s.is_finite()
                && s.period_s > 0.0;
            if !ok {
                return Err(ImuScenarioError::Manoeuvre { angle: name, sinusoid: s });
            }
        }
        let extreme = self.pitch.mean_rad.abs() + self.pitch.amplitude_rad.abs();
        if extreme > MAX_PITCH_RAD {
            return Err(ImuScenarioError::PitchEnvelope { extreme_rad: extreme });
        }
        Ok(())
    }
}

/// The true motion at one time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImuTruth {
    /// Rotation from body to NED axes (the `q` the attitude EKF estimates).
    pub attitude: UnitQuaternion<f64>,
    /// `[roll, pitch, yaw]` (rad).
    pub euler_rad: [f64; 3],
    /// Body rates `(p, q, r)` (rad/s).
    pub rate_rad_s: Vector3<f64>,
    /// Specific force in body axes (m/s^2): `C_bn (a - g e_3)`, `a` the translational acceleration.
    pub specific_force_mps2: Vector3<f64>,
}

/// The truth of `manoeuvre` at `t_s` (module docs).
pub fn imu_truth(manoeuvre: &AttitudeManoeuvre, t_s: f64) -> ImuTruth {
    let ([phi, theta, psi], [phi_rate, theta_rate, psi_rate]) = manoeuvre.euler(t_s);
    let (sphi, cphi) = phi.sin_cos();
    let (sth, cth) = theta.sin_cos();
    let rate_rad_s = Vector3::new(
        phi_rate - psi_rate * sth,
        theta_rate * cphi + psi_rate * cth * sphi,
        -theta_rate * sphi + psi_rate * cth * cphi,
    );
    let C_bn = body_from_ned(phi, theta, psi);
    let mut specific_force_mps2 = -GRAVITY_MPS2 * C_bn.column(2);
    if manoeuvre.translation_mps2 != 0.0 {
        // Added only when there is one, so the seed's motion keeps its exact numbers.
        specific_force_mps2 += C_bn * manoeuvre.acceleration_ned_mps2(t_s);
    }
    ImuTruth {
        attitude: UnitQuaternion::from_euler_angles(phi, theta, psi),
        euler_rad: [phi, theta, psi],
        rate_rad_s,
        specific_force_mps2,
    }
}

/// Standard deviations of the sensor errors (chosen, typical MEMS values; the patent gives none).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImuNoise {
    /// White noise per gyro sample (rad/s).
    pub gyro_noise_std_rad_s: f64,
    /// Spread of the constant gyro bias over trials (rad/s).
    pub gyro_bias_std_rad_s: f64,
    /// White noise per accelerometer sample (m/s^2).
    pub accel_noise_std_mps2: f64,
    /// Spread of the constant accelerometer bias over trials (m/s^2).
    pub accel_bias_std_mps2: f64,
}

impl ImuNoise {
    /// Gyro 0.1 deg/s per sample with a 0.02 deg/s bias (a MEMS gyro after its power-up bias
    /// calibration: in-run stability is 0.001-0.01 deg/s, a calibration leaves some 0.01-0.05 deg/s);
    /// accelerometer 0.02 m/s^2 per sample (about 200 ug/sqrt(Hz) at 100 Hz) with a 0.01 m/s^2 (1 mg)
    /// bias. The healthy bias stays below the smallest fault of [`AccelFaultRanges::seed`] (0.05 m/s^2)
    /// by five standard deviations.
    pub fn seed() -> Self {
        ImuNoise {
            gyro_noise_std_rad_s: 0.1f64.to_radians(),
            gyro_bias_std_rad_s: 0.02f64.to_radians(),
            accel_noise_std_mps2: 0.02,
            accel_bias_std_mps2: 0.01,
        }
    }
}

impl Default for ImuNoise {
    fn default() -> Self {
        Self::seed()
    }
}

/// Everything that defines one trial, as plain numbers.
#[derive(Debug, Clone, PartialEq)]
pub struct ImuScenarioParams {
    /// Sample period (s).
    pub dt_s: f64,
    /// Samples at `t = k dt_s`, `k = 0 .. round(duration_s / dt_s)`, end excluded.
    pub duration_s: f64,
    pub manoeuvre: AttitudeManoeuvre,
    pub noise: ImuNoise,
    /// Multiplies the white-noise standard deviations (0 = noise-free); biases are given separately.
    pub noise_scale: f64,
    /// Constant gyro bias of this trial (rad/s).
    pub gyro_bias_rad_s: [f64; 3],
    /// Constant accelerometer bias of this trial (m/s^2).
    pub accel_bias_mps2: [f64; 3],
    /// Accelerometer faults; `channel` is [`ACCEL_X`], [`ACCEL_Y`] or [`ACCEL_Z`], sizes in m/s^2.
    pub faults: Vec<ChannelFault>,
}

impl ImuScenarioParams {
    /// 100 Hz (a typical attitude-loop rate), 20 s, the seed manoeuvre, seed noise, zero biases (draw
    /// them with [`Self::draw_sensor_biases`]), no fault.
    pub fn seed() -> Self {
        ImuScenarioParams {
            dt_s: 0.01,
            duration_s: 20.0,
            manoeuvre: AttitudeManoeuvre::seed(),
            noise: ImuNoise::seed(),
            noise_scale: 1.0,
            gyro_bias_rad_s: [0.0; 3],
            accel_bias_mps2: [0.0; 3],
            faults: Vec::new(),
        }
    }

    /// Sets the biases to 6 standard normals (gyro x, y, z, then accelerometer x, y, z) times
    /// [`ImuNoise::gyro_bias_std_rad_s`] and [`ImuNoise::accel_bias_std_mps2`].
    pub fn draw_sensor_biases<R: Rng + ?Sized>(&mut self, rng: &mut R) {
        let mut draw = || -> f64 { StandardNormal.sample(&mut *rng) };
        let (g, a) = (self.noise.gyro_bias_std_rad_s, self.noise.accel_bias_std_mps2);
        self.gyro_bias_rad_s = std::array::from_fn(|_| g * draw());
        self.accel_bias_mps2 = std::array::from_fn(|_| a * draw());
    }
}

/// The three fault kinds of the seed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum AccelFaultKind {
    Bias,
    Gain,
    Stuck,
}

/// Where fault sizes and onsets are drawn from (uniformly).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AccelFaultRanges {
    /// `|alpha|` range of a bias (m/s^2); the sign is drawn.
    pub bias_mps2: [f64; 2],
    /// `|beta - 1|` range of a gain; the sign of `beta - 1` is drawn.
    pub gain_deviation: [f64; 2],
    /// Onset range (s).
    pub onset_s: [f64; 2],
}

impl AccelFaultRanges {
    /// Bias 0.05-0.5 m/s^2 (5-50 mg: from five healthy-bias standard deviations up to a gross fault),
    /// gain 5-30 % either way (a scale-factor failure; a few hundred ppm is healthy), onset 4-14 s of
    /// the seed's 20 s trial (the filter has converged by 4 s; 6 s of data remain after the latest).
    pub fn seed() -> Self {
        AccelFaultRanges { bias_mps2: [0.05, 0.5], gain_deviation: [0.05, 0.3], onset_s: [4.0, 14.0] }
    }

    /// Draws a fault of `kind` (or only an onset for `None`, the fault-free class): 4 uniforms in the
    /// order axis, size, sign, onset, whatever the kind (module docs). A stuck fault holds the reading
    /// at its onset. Returns the fault (if any) and the onset.
    pub fn draw<R: Rng + ?Sized>(&self, kind: Option<AccelFaultKind>, rng: &mut R) -> (Option<ChannelFault>, f64) {
        let u: [f64; 4] = std::array::from_fn(|_| rng.random::<f64>());
        let channel = ((u[0] * 3.0) as usize).min(ACCEL_Z);
        let sign = if u[2] < 0.5 { -1.0 } else { 1.0 };
        let within = |r: [f64; 2], v: f64| r[0] + (r[1] - r[0]) * v;
        let onset_s = within(self.onset_s, u[3]);
        let mode = match kind {
            None => return (None, onset_s),
            Some(AccelFaultKind::Bias) => FaultMode::Bias { bias: sign * within(self.bias_mps2, u[1]) },
            Some(AccelFaultKind::Gain) => FaultMode::Gain { factor: 1.0 + sign * within(self.gain_deviation, u[1]) },
            Some(AccelFaultKind::Stuck) => FaultMode::Stuck { value: None },
        };
        (Some(ChannelFault { channel, onset_s, mode }), onset_s)
    }
}

impl Default for AccelFaultRanges {
    fn default() -> Self {
        Self::seed()
    }
}

/// Why a scenario cannot be built.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ImuScenarioError {
    #[error(transparent)]
    Value(#[from] ValueError),
    #[error("the {angle} history needs finite numbers and a positive period: {sinusoid:?}")]
    Manoeuvre { angle: &'static str, sinusoid: EulerSinusoid },
    #[error("the manoeuvre can take pitch to {extreme_rad} rad; the limit is {MAX_PITCH_RAD} rad")]
    PitchEnvelope { extreme_rad: f64 },
}

/// One sample of a trial.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImuSample {
    pub t_s: f64,
    /// Measured body rates (rad/s): truth + bias + noise.
    pub gyro_rad_s: Vector3<f64>,
    /// Measured specific force (m/s^2): truth + bias + noise, then faulted.
    pub accel_mps2: Vector3<f64>,
    /// The same reading had the accelerometer been healthy (what the faults were applied to).
    pub healthy_accel_mps2: Vector3<f64>,
    pub truth: ImuTruth,
}

/// A scenario being stepped; see the module docs.
#[derive(Debug, Clone)]
pub struct ImuScenario {
    params: ImuScenarioParams,
    faults: ActiveFaults,
    samples: usize,
    k: usize,
}

impl ImuScenario {
    /// Validates `params` (finite positive step and duration, non-negative noise, finite biases, the
    /// manoeuvre's pitch envelope, fault channels and onsets).
    pub fn new(params: ImuScenarioParams) -> Result<Self, ImuScenarioError> {
        positive("dt_s", params.dt_s)?;
        positive("duration_s", params.duration_s)?;
        non_negative("noise_scale", params.noise_scale)?;
        let n = params.noise;
        for (field, value) in [
            ("noise.gyro_noise_std_rad_s", n.gyro_noise_std_rad_s),
            ("noise.gyro_bias_std_rad_s", n.gyro_bias_std_rad_s),
            ("noise.accel_noise_std_mps2", n.accel_noise_std_mps2),
            ("noise.accel_bias_std_mps2", n.accel_bias_std_mps2),
        ] {
            non_negative(field, value)?;
        }
        for value in params.gyro_bias_rad_s {
            finite("gyro_bias_rad_s", value)?;
        }
        for value in params.accel_bias_mps2 {
            finite("accel_bias_mps2", value)?;
        }
        params.manoeuvre.validate()?;
        sensor_faults(&params.faults, ACCEL_Z + 1, "accelerometer channels are 0 (x), 1 (y), 2 (z)")?;
        let samples = (params.duration_s / params.dt_s).round().max(1.0) as usize;
        Ok(ImuScenario { faults: ActiveFaults::new(params.faults.clone()), params, samples, k: 0 })
    }

    pub fn params(&self) -> &ImuScenarioParams {
        &self.params
    }

    /// Samples in the trial.
    pub fn samples(&self) -> usize {
        self.samples
    }

    /// Earliest fault onset (`None` when fault-free).
    pub fn first_onset_s(&self) -> Option<f64> {
        self.faults.first_onset_s()
    }

    /// The next sample, drawing exactly [`DRAWS_PER_SAMPLE`] standard normals from `rng` in the order of
    /// the module docs; `None` (and no draw) after the last.
    pub fn next_sample<R: Rng + ?Sized>(&mut self, rng: &mut R) -> Option<ImuSample> {
        if self.k >= self.samples {
            return None;
        }
        let p = &self.params;
        let t_s = self.k as f64 * p.dt_s;
        let truth = imu_truth(&p.manoeuvre, t_s);
        let mut draw = || -> f64 { StandardNormal.sample(&mut *rng) };
        let (sg, sa) = (p.noise_scale * p.noise.gyro_noise_std_rad_s, p.noise_scale * p.noise.accel_noise_std_mps2);
        let gyro: [f64; 3] = std::array::from_fn(|i| truth.rate_rad_s[i] + p.gyro_bias_rad_s[i] + sg * draw());
        let healthy: [f64; 3] =
            std::array::from_fn(|i| truth.specific_force_mps2[i] + p.accel_bias_mps2[i] + sa * draw());
        let mut accel = healthy;
        self.faults.apply(t_s, &mut accel);
        self.k += 1;
        Some(ImuSample {
            t_s,
            gyro_rad_s: Vector3::from(gyro),
            accel_mps2: Vector3::from(accel),
            healthy_accel_mps2: Vector3::from(healthy),
            truth,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand::rngs::ChaCha8Rng;

    fn run(params: ImuScenarioParams, seed: u64) -> Vec<ImuSample> {
        let mut s = ImuScenario::new(params).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        std::iter::from_fn(|| s.next_sample(&mut rng)).collect()
    }

    /// A translational acceleration reaches the specific force as `C_bn (a - g e_3)`: level, it adds
    /// `a` itself (north 2 m/s^2 at a quarter of its 7 s period, east 2 sin(2 pi 1.75 / 11), down
    /// sin(2 pi 1.75 / 13)); in any attitude the specific force's length is that of `a - g e_3`; and
    /// without one the seed's numbers are unchanged to the bit.
    #[test]
    fn a_translational_acceleration_reaches_the_specific_force() {
        let level = AttitudeManoeuvre { translation_mps2: 2.0, ..AttitudeManoeuvre::still(0.0, 0.0, 0.0) };
        let f = imu_truth(&level, 1.75).specific_force_mps2;
        let tau = std::f64::consts::TAU;
        let want = [2.0, 2.0 * (tau * 1.75 / 11.0).sin(), (tau * 1.75 / 13.0).sin() - GRAVITY_MPS2];
        for i in 0..3 {
            assert!((f[i] - want[i]).abs() < 1e-12, "{i}: {} vs {}", f[i], want[i]);
        }
        let turning = AttitudeManoeuvre { translation_mps2: 3.0, ..AttitudeManoeuvre::seed() };
        for t in [0.4, 2.2, 6.1, 13.7] {
            let a = turning.acceleration_ned_mps2(t) - Vector3::new(0.0, 0.0, GRAVITY_MPS2);
            let f = imu_truth(&turning, t).specific_force_mps2;
            assert!((f.norm() - a.norm()).abs() < 1e-12, "t = {t}");
        }
        let seed = AttitudeManoeuvre::seed();
        let plain = -GRAVITY_MPS2 * body_from_ned(0.3, -0.2, 0.9).column(2);
        let still = AttitudeManoeuvre::still(0.3, -0.2, 0.9);
        assert_eq!(imu_truth(&still, 5.0).specific_force_mps2, plain);
        assert_eq!(seed.translation_mps2, 0.0);
    }

    /// The body rates are the rates of the attitude: `q(t + h) ~ q(t) exp(w h / 2)` by central
    /// differences of the analytic quaternion (the body-axes rate is `2 q^-1 q'`), to 1e-7 rad/s at
    /// times across the seed manoeuvre; the specific force is `-g` times the third column of `C_bn`,
    /// which is the NED down axis seen from the body (`q^-1 e_3 q`).
    #[test]
    fn rates_and_specific_force_follow_the_attitude() {
        let m = AttitudeManoeuvre::seed();
        let h = 1e-5;
        for t in [0.0, 1.3, 2.9, 4.4, 7.7, 11.0, 15.5, 19.9] {
            let truth = imu_truth(&m, t);
            let (before, after) = (imu_truth(&m, t - h).attitude, imu_truth(&m, t + h).attitude);
            let q_dot = (after.quaternion() - before.quaternion()) / (2.0 * h);
            let w = (truth.attitude.quaternion().conjugate() * q_dot) * 2.0;
            assert!(w.scalar().abs() < 1e-7);
            assert!((w.vector() - truth.rate_rad_s).amax() < 1e-7, "t = {t}: {} vs {}", w.vector(), truth.rate_rad_s);
            let down_in_body = truth.attitude.inverse_transform_vector(&Vector3::z());
            assert!((truth.specific_force_mps2 + GRAVITY_MPS2 * down_in_body).amax() < 1e-12);
        }
        // Level: the accelerometer reads -g on z; pitched nose-up by 30 deg: +g/2 on x.
        let level = imu_truth(&AttitudeManoeuvre::still(0.0, 0.0, 1.0), 0.0).specific_force_mps2;
        assert!((level - Vector3::new(0.0, 0.0, -GRAVITY_MPS2)).amax() < 1e-12);
        let pitched = imu_truth(&AttitudeManoeuvre::still(0.0, 30f64.to_radians(), 0.0), 0.0).specific_force_mps2;
        assert!((pitched[0] - GRAVITY_MPS2 / 2.0).abs() < 1e-12);
    }

    /// Exactly six normals a sample in the documented order: a trial equals one rebuilt by hand from
    /// the same RNG state; noise-free samples equal the truth plus the biases.
    #[test]
    fn draws_follow_the_documented_order() {
        let mut params = ImuScenarioParams::seed();
        params.draw_sensor_biases(&mut ChaCha8Rng::seed_from_u64(3));
        let samples = run(params.clone(), 9);
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        for s in samples.iter().take(50) {
            let n: [f64; 6] = std::array::from_fn(|_| StandardNormal.sample(&mut rng));
            for i in 0..3 {
                let gyro = s.truth.rate_rad_s[i] + params.gyro_bias_rad_s[i] + params.noise.gyro_noise_std_rad_s * n[i];
                let accel = s.truth.specific_force_mps2[i]
                    + params.accel_bias_mps2[i]
                    + params.noise.accel_noise_std_mps2 * n[3 + i];
                assert_eq!((s.gyro_rad_s[i], s.accel_mps2[i]), (gyro, accel));
            }
        }
        assert_eq!(samples, run(params.clone(), 9), "same RNG state, same samples");
        let quiet = run(ImuScenarioParams { noise_scale: 0.0, ..params.clone() }, 9);
        for s in &quiet {
            assert_eq!(s.gyro_rad_s, s.truth.rate_rad_s + Vector3::from(params.gyro_bias_rad_s));
        }
        assert_eq!(samples.len(), 2000);
    }

    /// A fault changes exactly its channel from its onset by the seed's `beta a + alpha`; everything
    /// else (other channels, gyro, truth, the healthy reading) is bit-identical to the fault-free run.
    #[test]
    fn faults_change_only_their_channel_from_the_onset() {
        let healthy = run(ImuScenarioParams::seed(), 4);
        let cases = [
            (ACCEL_X, FaultMode::Bias { bias: 0.2 }),
            (ACCEL_Y, FaultMode::Gain { factor: 1.2 }),
            (ACCEL_Z, FaultMode::Stuck { value: None }),
        ];
        for (channel, mode) in cases {
            let fault = ChannelFault { channel, onset_s: 7.005, mode };
            let faulty = run(ImuScenarioParams { faults: vec![fault], ..ImuScenarioParams::seed() }, 4);
            let held = faulty.iter().find(|s| s.t_s >= 7.005).unwrap().healthy_accel_mps2[channel];
            for (h, f) in healthy.iter().zip(&faulty) {
                assert_eq!(
                    (h.gyro_rad_s, h.healthy_accel_mps2, h.truth),
                    (f.gyro_rad_s, f.healthy_accel_mps2, f.truth)
                );
                for i in 0..3 {
                    let y = h.accel_mps2[i];
                    let want = match mode {
                        _ if i != channel || f.t_s < 7.005 => y,
                        FaultMode::Bias { bias } => y + bias,
                        FaultMode::Gain { factor } => factor * y,
                        _ => held,
                    };
                    assert_eq!(f.accel_mps2[i], want, "{mode:?}, t = {}, axis {i}", f.t_s);
                }
            }
        }
    }

    /// Fault draws: 4 uniforms whatever the kind (so kinds drawn from one RNG state share axis and
    /// onset), sizes and onsets within their ranges, every axis and both signs reached.
    #[test]
    fn fault_draws_share_axis_and_onset_and_stay_in_range() {
        let ranges = AccelFaultRanges::seed();
        let mut axes = [0usize; 3];
        let (mut positive, mut negative) = (0, 0);
        for seed in 0..300 {
            let draw = |kind| {
                let mut rng = ChaCha8Rng::seed_from_u64(seed);
                let out = ranges.draw(kind, &mut rng);
                (out, rng.random::<u64>())
            };
            let ((none, onset), next) = draw(None);
            assert!(none.is_none() && (4.0..14.0).contains(&onset));
            for kind in [AccelFaultKind::Bias, AccelFaultKind::Gain, AccelFaultKind::Stuck] {
                let ((fault, onset_k), next_k) = draw(Some(kind));
                let fault = fault.unwrap();
                assert_eq!((onset_k, next_k, fault.onset_s), (onset, next, onset));
                match fault.mode {
                    FaultMode::Bias { bias } => {
                        assert!((0.05..0.5).contains(&bias.abs()));
                        if bias > 0.0 {
                            positive += 1
                        } else {
                            negative += 1
                        }
                        axes[fault.channel] += 1;
                    }
                    FaultMode::Gain { factor } => assert!((0.05..0.3).contains(&(factor - 1.0).abs())),
                    FaultMode::Stuck { value } => assert_eq!(value, None),
                    other => panic!("unexpected {other:?}"),
                }
            }
        }
        assert!(axes.iter().all(|&n| n > 70), "{axes:?}");
        assert!(positive > 120 && negative > 120, "{positive} {negative}");
    }

    #[test]
    fn invalid_parameters_are_errors() {
        let bad = |f: fn(&mut ImuScenarioParams)| {
            let mut p = ImuScenarioParams::seed();
            f(&mut p);
            ImuScenario::new(p).unwrap_err()
        };
        assert!(matches!(
            bad(|p| p.dt_s = 0.0),
            ImuScenarioError::Value(ValueError::NotPositive { field: "dt_s", .. })
        ));
        assert!(matches!(
            bad(|p| p.noise.accel_noise_std_mps2 = -1.0),
            ImuScenarioError::Value(ValueError::Negative { .. })
        ));
        assert!(matches!(
            bad(|p| p.gyro_bias_rad_s[1] = f64::NAN),
            ImuScenarioError::Value(ValueError::NotFinite { .. })
        ));
        assert!(matches!(bad(|p| p.manoeuvre.pitch.amplitude_rad = 1.5), ImuScenarioError::PitchEnvelope { .. }));
        assert!(matches!(bad(|p| p.manoeuvre.roll.period_s = 0.0), ImuScenarioError::Manoeuvre { angle: "roll", .. }));
        let fault = ChannelFault { channel: 3, onset_s: 1.0, mode: FaultMode::Bias { bias: 1.0 } };
        assert!(matches!(
            bad_with(fault),
            ImuScenarioError::Value(ValueError::FaultChannel { index: 0, channel: 3, .. })
        ));
        let fault = ChannelFault { channel: 0, onset_s: f64::INFINITY, mode: FaultMode::Bias { bias: 1.0 } };
        assert!(matches!(bad_with(fault), ImuScenarioError::Value(ValueError::FaultOnset { index: 0, .. })));
    }

    fn bad_with(fault: ChannelFault) -> ImuScenarioError {
        ImuScenario::new(ImuScenarioParams { faults: vec![fault], ..ImuScenarioParams::seed() }).unwrap_err()
    }
}
