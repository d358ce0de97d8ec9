//! A flown air-data scenario: the truth from the profile or the Aerosonde airframe, sensor noise, wind
//! and turbulence, sensor errors and faults, sampled into the measurements the detectors read (module
//! docs of [`super`]).

use nalgebra::Vector3;
use rand::Rng;
use rand_distr::{Distribution, StandardNormal};
use thiserror::Error;

use super::kinematics::*;
use super::profile::*;
use crate::checks::{ValueError, finite, non_negative, positive, sensor_faults};
use crate::fault::{ActiveFaults, ChannelFault};
pub use crate::kinematics::body_from_ned;
use crate::methods::air_data::airframe::{AerosondeFlight, AirframeSample};

/// Standard normals drawn per sample (module docs).
pub const DRAWS_PER_SAMPLE: usize = 14;

/// Standard deviations of the white measurement noise (chosen, typical values; the patent gives none).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorNoise {
    pub gyro_std_rad_s: f64,
    pub accelerometer_std_mps2: f64,
    pub attitude_std_rad: f64,
    pub airspeed_std_mps: f64,
    pub alpha_std_rad: f64,
    pub beta_std_rad: f64,
}

impl SensorNoise {
    /// Gyro 0.1 deg/s, accelerometer 0.02 m/s^2, roll/pitch 0.1 deg (a tactical-grade IMU/AHRS sampled at
    /// 50-100 Hz), airspeed 0.5 m/s, alpha and beta 0.2 deg (vanes or a five-hole probe).
    pub fn seed() -> Self {
        SensorNoise {
            gyro_std_rad_s: 0.1f64.to_radians(),
            accelerometer_std_mps2: 0.02,
            attitude_std_rad: 0.1f64.to_radians(),
            airspeed_std_mps: 0.5,
            alpha_std_rad: 0.2f64.to_radians(),
            beta_std_rad: 0.2f64.to_radians(),
        }
    }

    /// Per inertial channel, order of [`INERTIAL_CHANNEL_NAMES`].
    pub fn inertial_std(&self) -> [f64; 8] {
        let (g, a, t) = (self.gyro_std_rad_s, self.accelerometer_std_mps2, self.attitude_std_rad);
        [g, g, g, a, a, a, t, t]
    }

    /// Per air-data channel, order of [`AIR_DATA_CHANNEL_NAMES`].
    pub fn air_data_std(&self) -> [f64; 3] {
        [self.airspeed_std_mps, self.alpha_std_rad, self.beta_std_rad]
    }
}

impl Default for SensorNoise {
    fn default() -> Self {
        Self::seed()
    }
}

/// Wind (module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WindParams {
    /// Steady wind, NED (m/s): changes no measurement, only the truth's ground velocity.
    pub steady_ned_mps: [f64; 3],
    /// Stationary standard deviation of the Gauss-Markov gust, per NED axis (m/s); 0 = calm air.
    pub gust_std_mps: f64,
    /// Correlation time of the gust (s).
    pub gust_time_constant_s: f64,
}

impl WindParams {
    /// Calm air. The gust time constant, used once a gust size is set, is the Dryden scale length
    /// 533 m (MIL-F-8785C, above 2000 ft) over the seed profile's 70 m/s: 7.6 s. Light turbulence is
    /// about 1 m/s.
    pub fn seed() -> Self {
        WindParams { steady_ned_mps: [0.0; 3], gust_std_mps: 0.0, gust_time_constant_s: 533.0 / 70.0 }
    }
}

impl Default for WindParams {
    fn default() -> Self {
        Self::seed()
    }
}

/// What flies the trial.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Airframe {
    /// The profile's kinematics: the filters' own model (the best case).
    #[default]
    Kinematic,
    /// The Aerosonde 6-DoF of method 004 flying its manoeuvres ([`crate::methods::air_data::airframe`]),
    /// scaled by the factor.
    Aerosonde { manoeuvre_scale: f64 },
}

/// Sensor imperfections the filters do not model (all zero: ideal sensors, the best case). Every air-data
/// lane has the same (one part number, one installation); each has its own noise.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SensorErrors {
    /// First-order lag of the airspeed (pneumatic) and of the flow angles (vanes), s.
    pub airspeed_lag_s: f64,
    pub flow_angle_lag_s: f64,
    /// Relative scale-factor errors: airspeed, and alpha and beta (local flow against free stream).
    pub airspeed_scale_factor: f64,
    pub flow_angle_scale_factor: f64,
    /// Mounting offsets of the alpha and beta vanes (rad).
    pub alpha_misalignment_rad: f64,
    pub beta_misalignment_rad: f64,
    /// Small rotation of the inertial unit about each body axis (rad): rates and specific forces
    /// rotated, roll and pitch offset by it.
    pub imu_misalignment_rad: f64,
    /// Correlation time of the air-data noise (s): first-order Gauss-Markov with the white noise's
    /// variance; 0: white.
    pub noise_correlation_s: f64,
}

/// Most air-data lanes a scenario simulates (a triplex system).
pub const MAX_LANES: usize = 3;

/// Everything that defines a scenario, as plain numbers.
#[derive(Debug, Clone, PartialEq)]
pub struct ScenarioParams {
    /// Sample period (s).
    pub dt_s: f64,
    /// Samples are taken at `t = k dt_s` for `k = 0 .. round(duration_s / dt_s)`, end excluded.
    pub duration_s: f64,
    pub profile: FlightProfile,
    pub noise: SensorNoise,
    /// Multiplies every noise standard deviation (0 = noise-free measurements).
    pub noise_scale: f64,
    pub wind: WindParams,
    /// Air-data faults; `channel` is [`AIRSPEED`], [`ALPHA`] or [`BETA`].
    pub faults: Vec<ChannelFault>,
    pub airframe: Airframe,
    pub sensor_errors: SensorErrors,
    /// Redundant air-data sensors per quantity (1 to [`MAX_LANES`]); lane 0 is the one a single-string
    /// detector reads.
    pub lanes: usize,
    /// How many lanes the faults hit, from lane 0 (1: a single sensor; all lanes: common mode).
    pub faulty_lanes: usize,
}

impl ScenarioParams {
    /// 100 Hz, 60 s, the seed profile, seed noise, calm air, no fault.
    pub fn seed() -> Self {
        ScenarioParams {
            dt_s: 0.01,
            duration_s: 60.0,
            profile: FlightProfile::seed(),
            noise: SensorNoise::seed(),
            noise_scale: 1.0,
            wind: WindParams::seed(),
            faults: Vec::new(),
            airframe: Airframe::Kinematic,
            sensor_errors: SensorErrors::default(),
            lanes: 1,
            faulty_lanes: 1,
        }
    }
}

/// Why a scenario cannot be built.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ScenarioError {
    #[error(transparent)]
    Value(#[from] ValueError),
    #[error(transparent)]
    Profile(#[from] ProfileError),
    #[error("{lanes} lane(s) with {faulty} faulty: allowed 1 to {MAX_LANES} lanes, 1 to that many faulty")]
    Lanes { lanes: usize, faulty: usize },
    #[error("the airframe: {0}")]
    Airframe(String),
}

/// What the generator knows at a sample besides the measurements.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FlightTruth {
    /// True air data (turbulence included: what a perfect air-data system measures).
    pub air_data: AirData,
    /// True air-relative body velocity `(u, v, w)` (m/s).
    pub velocity_body_mps: Vector3<f64>,
    /// What a perfect inertial system measures.
    pub inertial: Inertial,
    pub heading_rad: f64,
    pub gust_ned_mps: Vector3<f64>,
    /// Inertial velocity, NED (m/s): the profile's motion plus the steady wind.
    pub ground_velocity_ned_mps: Vector3<f64>,
}

/// One sample of a trial.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AirDataSample {
    pub t_s: f64,
    /// Measured (noisy) inertial data.
    pub inertial: Inertial,
    /// Measured air data of lane 0: noisy, then faulted.
    pub air_data: AirData,
    /// Every lane's (lane 0 is `air_data`; lanes beyond the scenario's count repeat lane 0).
    pub lanes: [AirData; MAX_LANES],
    pub truth: FlightTruth,
}

/// A scenario being stepped; see the module docs.
#[derive(Debug, Clone)]
pub struct AirDataScenario {
    params: ScenarioParams,
    /// The faults' run-time state, one per faulty lane.
    faults: Vec<ActiveFaults>,
    samples: usize,
    k: usize,
    heading_rad: f64,
    previous_heading_rate_rad_s: f64,
    gust_ned_mps: Vector3<f64>,
    airframe: Option<AerosondeFlight>,
    /// The lagged air data (after the first sample), and each channel's lag over one sample,
    /// `exp(-dt / lag)` (0 without a lag).
    lagged: Option<[f64; 3]>,
    lag_decay: [f64; 3],
    /// The coloured noise's correlation over one sample, `exp(-dt / tau)` (0 when white).
    noise_decay: f64,
    /// Each lane's coloured-noise state, in sigmas.
    coloured: [[f64; 3]; MAX_LANES],
    failure: Option<String>,
}

impl AirDataScenario {
    /// Validates `params` (finite, positive step and duration, non-negative noise, the profile's
    /// envelope, fault channels).
    pub fn new(params: ScenarioParams) -> Result<Self, ScenarioError> {
        positive("dt_s", params.dt_s)?;
        positive("duration_s", params.duration_s)?;
        non_negative("noise_scale", params.noise_scale)?;
        let n = params.noise;
        for (field, value) in [
            ("noise.gyro_std_rad_s", n.gyro_std_rad_s),
            ("noise.accelerometer_std_mps2", n.accelerometer_std_mps2),
            ("noise.attitude_std_rad", n.attitude_std_rad),
            ("noise.airspeed_std_mps", n.airspeed_std_mps),
            ("noise.alpha_std_rad", n.alpha_std_rad),
            ("noise.beta_std_rad", n.beta_std_rad),
            ("wind.gust_std_mps", params.wind.gust_std_mps),
        ] {
            non_negative(field, value)?;
        }
        positive("wind.gust_time_constant_s", params.wind.gust_time_constant_s)?;
        for (field, value) in ["wind.steady_ned_mps[0]", "wind.steady_ned_mps[1]", "wind.steady_ned_mps[2]"]
            .into_iter()
            .zip(params.wind.steady_ned_mps)
        {
            finite(field, value)?;
        }
        params.profile.validate()?;
        sensor_faults(&params.faults, BETA + 1, "air-data channels are 0 (airspeed), 1 (alpha), 2 (beta)")?;
        if !(1..=MAX_LANES).contains(&params.lanes) || !(1..=params.lanes).contains(&params.faulty_lanes) {
            return Err(ScenarioError::Lanes { lanes: params.lanes, faulty: params.faulty_lanes });
        }
        let e = &params.sensor_errors;
        for (field, value) in [
            ("sensor_errors.airspeed_lag_s", e.airspeed_lag_s),
            ("sensor_errors.flow_angle_lag_s", e.flow_angle_lag_s),
            ("sensor_errors.noise_correlation_s", e.noise_correlation_s),
        ] {
            non_negative(field, value)?;
        }
        for (field, value) in [
            ("sensor_errors.airspeed_scale_factor", e.airspeed_scale_factor),
            ("sensor_errors.flow_angle_scale_factor", e.flow_angle_scale_factor),
            ("sensor_errors.alpha_misalignment_rad", e.alpha_misalignment_rad),
            ("sensor_errors.beta_misalignment_rad", e.beta_misalignment_rad),
            ("sensor_errors.imu_misalignment_rad", e.imu_misalignment_rad),
        ] {
            finite(field, value)?;
        }
        let airframe = match params.airframe {
            Airframe::Kinematic => None,
            Airframe::Aerosonde { manoeuvre_scale } => {
                finite("manoeuvre_scale", manoeuvre_scale)?;
                Some(AerosondeFlight::new(manoeuvre_scale, params.dt_s).map_err(ScenarioError::Airframe)?)
            }
        };
        let samples = (params.duration_s / params.dt_s).round().max(1.0) as usize;
        let heading_rad = params.profile.heading_rad;
        let previous_heading_rate_rad_s = kinematic_state(&params.profile, 0.0).heading_rate_rad_s;
        let per_sample = |tau: f64| if tau > 0.0 { (-params.dt_s / tau).exp() } else { 0.0 };
        let lag_decay = [e.airspeed_lag_s, e.flow_angle_lag_s, e.flow_angle_lag_s].map(per_sample);
        let noise_decay = per_sample(e.noise_correlation_s);
        Ok(AirDataScenario {
            faults: vec![ActiveFaults::new(params.faults.clone()); params.faulty_lanes],
            params,
            samples,
            k: 0,
            heading_rad,
            previous_heading_rate_rad_s,
            gust_ned_mps: Vector3::zeros(),
            airframe,
            lagged: None,
            lag_decay,
            noise_decay,
            coloured: [[0.0; 3]; MAX_LANES],
            failure: None,
        })
    }

    pub fn params(&self) -> &ScenarioParams {
        &self.params
    }

    /// Samples in the trial.
    pub fn samples(&self) -> usize {
        self.samples
    }

    /// Samples already produced.
    pub fn produced(&self) -> usize {
        self.k
    }

    /// Why the flight stopped before its end (the airframe left the envelope), if it did.
    pub fn failure(&self) -> Option<&str> {
        self.failure.as_deref()
    }

    /// The next sample, drawing [`DRAWS_PER_SAMPLE`] standard normals from `rng` in the order of the
    /// module docs, then 3 per extra lane; `None` (and no draw) after the last, or once the airframe
    /// has left the envelope ([`AirDataScenario::failure`]).
    pub fn next_sample<R: Rng + ?Sized>(&mut self, rng: &mut R) -> Option<AirDataSample> {
        if self.k >= self.samples || self.failure.is_some() {
            return None;
        }
        let p = &self.params;
        let t_s = self.k as f64 * p.dt_s;
        let steady = Vector3::from(p.wind.steady_ned_mps);
        let truth = match &mut self.airframe {
            None => {
                let state = kinematic_state(&p.profile, t_s);
                // Heading by the trapezoidal rule on the analytic rate; it only orients the gust and the
                // ground velocity.
                if self.k > 0 {
                    self.heading_rad += 0.5 * p.dt_s * (self.previous_heading_rate_rad_s + state.heading_rate_rad_s);
                }
                self.previous_heading_rate_rad_s = state.heading_rate_rad_s;
                let (phi, theta) = (state.inertial.roll_rad, state.inertial.pitch_rad);
                let C_bn = body_from_ned(phi, theta, self.heading_rad);
                let velocity = state.velocity_body_mps - C_bn * self.gust_ned_mps;
                FlightTruth {
                    air_data: air_data_from_velocity(&velocity),
                    velocity_body_mps: velocity,
                    inertial: state.inertial,
                    heading_rad: self.heading_rad,
                    gust_ned_mps: self.gust_ned_mps,
                    ground_velocity_ned_mps: C_bn.transpose() * state.velocity_body_mps + steady,
                }
            }
            Some(airframe) => match airframe.sample_and_step(t_s, &(steady + self.gust_ned_mps)) {
                Ok(a) => FlightTruth {
                    air_data: air_data_from_velocity(&a.velocity_air_body_mps),
                    velocity_body_mps: a.velocity_air_body_mps,
                    inertial: inertial_of(&a),
                    heading_rad: a.heading_rad,
                    gust_ned_mps: self.gust_ned_mps,
                    ground_velocity_ned_mps: a.ground_velocity_ned_mps,
                },
                Err(e) => {
                    self.failure = Some(e);
                    return None;
                }
            },
        };

        let e = p.sensor_errors;
        let mut draw = || -> f64 { StandardNormal.sample(&mut *rng) };
        let scale = p.noise_scale;
        let inertial_std = p.noise.inertial_std();
        let clean = misaligned(&truth.inertial, e.imu_misalignment_rad).to_array();
        let inertial = Inertial::from_array(std::array::from_fn(|i| clean[i] + scale * inertial_std[i] * draw()));
        let sensed = sensed_air_data(&e, &self.lag_decay, &mut self.lagged, &truth.air_data);
        let air_std = p.noise.air_data_std();
        let decay = self.noise_decay;
        let first = self.k == 0;
        let coloured = &mut self.coloured;
        let mut lane_noise = |lane: usize, white: f64, j: usize| -> f64 {
            if e.noise_correlation_s == 0.0 {
                return white;
            }
            let c = &mut coloured[lane][j];
            *c = if first { white } else { decay * *c + (1.0 - decay * decay).sqrt() * white };
            *c
        };
        let mut lanes = [[0.0; 3]; MAX_LANES];
        lanes[0] = std::array::from_fn(|j| sensed[j] + scale * air_std[j] * lane_noise(0, draw(), j));
        let gust_noise = Vector3::new(draw(), draw(), draw());
        for lane in 1..p.lanes {
            lanes[lane] = std::array::from_fn(|j| sensed[j] + scale * air_std[j] * lane_noise(lane, draw(), j));
        }
        for (lane, faults) in self.faults.iter_mut().enumerate() {
            faults.apply(t_s, &mut lanes[lane]);
        }
        for lane in p.lanes..MAX_LANES {
            lanes[lane] = lanes[0];
        }

        let decay = (-p.dt_s / p.wind.gust_time_constant_s).exp();
        self.gust_ned_mps =
            self.gust_ned_mps * decay + gust_noise * (p.wind.gust_std_mps * (1.0 - decay * decay).sqrt());
        self.k += 1;
        let lanes = lanes.map(AirData::from_array);
        Some(AirDataSample { t_s, inertial, air_data: lanes[0], lanes, truth })
    }
}

/// The true air data through the sensors' lag (`decay` per sample; `lagged`: the lag's state, `None`
/// before the first sample), scale factor and misalignment (before noise).
fn sensed_air_data(e: &SensorErrors, decay: &[f64; 3], lagged: &mut Option<[f64; 3]>, truth: &AirData) -> [f64; 3] {
    let truth = truth.to_array();
    let now = match *lagged {
        None => truth,
        // Without a lag the decay is 0 and the truth passes exactly.
        Some(previous) => std::array::from_fn(|j| decay[j] * previous[j] + (1.0 - decay[j]) * truth[j]),
    };
    *lagged = Some(now);
    let scale = [e.airspeed_scale_factor, e.flow_angle_scale_factor, e.flow_angle_scale_factor];
    let offset = [0.0, e.alpha_misalignment_rad, e.beta_misalignment_rad];
    std::array::from_fn(|j| {
        if scale[j] == 0.0 && offset[j] == 0.0 { now[j] } else { now[j] * (1.0 + scale[j]) + offset[j] }
    })
}

/// What perfect inertial sensors read on the airframe.
pub(super) fn inertial_of(a: &AirframeSample) -> Inertial {
    let (w, f) = (a.rates_rad_s, a.specific_force_mps2);
    Inertial::from_array([w[0], w[1], w[2], f[0], f[1], f[2], a.roll_rad, a.pitch_rad])
}

/// What an inertial unit rotated by `angle_rad` about each body axis measures: rates and specific
/// forces through the small rotation `I + [e]x`, `e = (angle, angle, angle)`, roll and pitch offset by it.
fn misaligned(ideal: &Inertial, angle_rad: f64) -> Inertial {
    if angle_rad == 0.0 {
        return *ideal;
    }
    let e = Vector3::repeat(angle_rad);
    let rotate = |v: Vector3<f64>| v + e.cross(&v);
    let a = ideal.to_array();
    let rates = rotate(Vector3::new(a[0], a[1], a[2]));
    let forces = rotate(Vector3::new(a[3], a[4], a[5]));
    Inertial::from_array([
        rates[0],
        rates[1],
        rates[2],
        forces[0],
        forces[1],
        forces[2],
        a[6] + angle_rad,
        a[7] + angle_rad,
    ])
}
