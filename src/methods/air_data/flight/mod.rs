//! Air-data / inertial flight scenarios for method 002 (`docs/findings-seed002.md`): a kinematic flight
//! with manoeuvres, the inertial measurements `p, q, r, ax, ay, az, roll, pitch` and the air-data
//! measurements `V, alpha, beta` with white noise, optional turbulence, and sensor faults on the air
//! data (any mode of [`crate::fault`], on one, two or all three sensors at once).
//!
//! # Kinematics (the patent's, the same the detector's filters use)
//! Body axes, air-relative velocity `(u, v, w)`, body rates `(p, q, r)`, specific force `(ax, ay, az)`
//! (what accelerometers measure), roll `phi`, pitch `theta`, `g` = [`GRAVITY_MPS2`](crate::kinematics::GRAVITY_MPS2):
//! ```text
//! u' = r v - q w - g sin(theta) + ax
//! v' = p w - r u + g cos(theta) sin(phi) + ay
//! w' = q u - p v + g cos(theta) cos(phi) + az
//! V = |(u, v, w)|,  alpha = atan2(w, u),  beta = asin(v / V)
//! ```
//! ([`velocity_derivative`], [`air_data_from_velocity`]).
//!
//! # How a flight is made
//! A [`FlightProfile`] prescribes smooth time histories of airspeed, angle of attack, sideslip, roll and
//! pitch: constant values plus segments (a raised-cosine ramp to a new level, a raised-cosine pulse, a
//! smooth doublet), each with an analytic time derivative. Heading follows the coordinated-turn rate
//! `psi' = g tan(phi) / V`. From these:
//! - `(u, v, w) = V (cos a cos b, sin b, sin a cos b)` and its derivative by the chain rule;
//! - body rates from the Euler-angle rates: `p = phi' - psi' sin(theta)`,
//!   `q = theta' cos(phi) + psi' cos(theta) sin(phi)`, `r = -theta' sin(phi) + psi' cos(theta) cos(phi)`;
//! - specific forces from the kinematics inverted: `ax = u' - r v + q w + g sin(theta)`,
//!   `ay = v' - p w + r u - g cos(theta) sin(phi)`, `az = w' - q u + p v - g cos(theta) cos(phi)`.
//!
//! So noise-free measurements satisfy the filters' model exactly in continuous time; a discrete
//! one-step prediction differs from the truth by integration error only: third order in the step with
//! Heun's method on the inertial data of both ends ([`propagate_velocity`], what the detector uses),
//! second order with Euler and the first sample held (both tested).
//!
//! # Wind
//! - A *steady* wind `W` (NED) is not a model error: the aircraft's inertial velocity is the
//!   air-relative one plus `W`, the wind's derivative is zero, and the kinematics of the air-relative
//!   velocity are unchanged. The profile prescribes the air-relative motion, so a steady wind changes
//!   no measurement (tested); it only shows in the truth's ground velocity.
//! - *Turbulence* is: a first-order Gauss-Markov gust `g` per NED axis,
//!   `g(k+1) = e^(-dt/tau) g(k) + sigma sqrt(1 - e^(-2 dt/tau)) n(k)`, starting at zero (exact
//!   discretisation of `g' = -g/tau + white`, stationary standard deviation `sigma`). The aircraft keeps
//!   its inertial path (the inertial measurements do not see the gust) and the air data see
//!   `(u, v, w) - C_bn(phi, theta, psi) g`: the filters' kinematics do not explain that change.
//!
//! # Noise, faults, random draws
//! White Gaussian noise on every measurement ([`SensorNoise`], times `noise_scale`), then the air-data
//! faults through [`crate::fault::ActiveFaults`] (channel [`AIRSPEED`], [`ALPHA`], [`BETA`]; sizes in m/s
//! and rad). Per sample, exactly 14 standard normals are drawn from the caller's RNG, always in this
//! order and whatever the noise and gust settings (so scenarios differing only in those use the same
//! random numbers): `p, q, r, ax, ay, az, roll, pitch` noise, `V, alpha, beta` noise, then the gust
//! innovations `N, E, D` that carry the gust to the next sample. The same RNG state gives bit-identical
//! samples.
//!
//! The numbers of [`SensorNoise::seed`], [`FlightProfile::seed`] and [`WindParams::seed`] are chosen
//! (typical of a light transport aircraft with a tactical-grade IMU and a calibrated air-data system);
//! the patent gives none.
#![allow(non_snake_case)]

mod kinematics;
mod profile;
mod scenario;

pub use kinematics::*;
pub use profile::*;
pub use scenario::*;

#[cfg(test)]
mod tests {
    use super::scenario::inertial_of;
    use super::*;
    use nalgebra::Vector3;

    use crate::checks::ValueError;
    use crate::fault::ChannelFault;
    use crate::fault::FaultMode;
    use crate::kinematics::GRAVITY_MPS2;
    use crate::methods::air_data::airframe::{AerosondeFlight, AirframeSample};
    use nalgebra::SVector;
    use rand::rngs::ChaCha8Rng;
    use rand::{RngExt, SeedableRng};

    fn scenario(params: ScenarioParams) -> AirDataScenario {
        AirDataScenario::new(params).unwrap()
    }

    fn run(params: ScenarioParams, seed: u64) -> Vec<AirDataSample> {
        let mut s = scenario(params);
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        std::iter::from_fn(|| s.next_sample(&mut rng)).collect()
    }

    fn noise_free(dt_s: f64) -> ScenarioParams {
        ScenarioParams { dt_s, noise_scale: 0.0, ..ScenarioParams::seed() }
    }

    /// Largest one-step error of the predictions `x + dt f(x, u(k))` (Euler) and
    /// [`propagate_velocity`] (Heun) against the next noise-free sample over the seed profile.
    fn worst_prediction_errors(dt_s: f64) -> (f64, f64) {
        let samples = run(noise_free(dt_s), 1);
        samples.windows(2).fold((0.0f64, 0.0f64), |(euler, heun), w| {
            let x = velocity_from_air_data(&w[0].air_data);
            let next = velocity_from_air_data(&w[1].air_data);
            let by_euler = x + dt_s * velocity_derivative(&x, &w[0].inertial);
            let by_heun = propagate_velocity(&x, &InertialInterval::new(w[0].inertial, w[1].inertial), dt_s);
            (euler.max((by_euler - next).amax()), heun.max((by_heun - next).amax()))
        })
    }

    /// Noise-free measurements obey the kinematics: in continuous time exactly (the profile's velocity
    /// rate equals `f(x, u)` to 1e-12 at every sample), and a one-step prediction misses the next
    /// sample by integration error only. Measured worst errors at 50, 100, 200 Hz: Euler 2.74e-3,
    /// 6.84e-4, 1.71e-4 m/s (ratios 4.0: second order); Heun 1.76e-5, 2.20e-6, 2.74e-7 m/s (ratios 8:
    /// third order). No model mismatch would survive such ratios.
    #[test]
    fn noise_free_measurements_satisfy_the_kinematics() {
        for sample in run(noise_free(0.01), 1) {
            let state = kinematic_state(&FlightProfile::seed(), sample.t_s);
            let x = velocity_from_air_data(&sample.air_data);
            assert!((x - state.velocity_body_mps).amax() < 1e-12);
            let rate = velocity_derivative(&x, &sample.inertial);
            assert!((rate - state.velocity_rate_body_mps2).amax() < 1e-12, "t = {}", sample.t_s);
            assert_eq!(sample.inertial, sample.truth.inertial);
        }
        let (e50, e100, e200) =
            (worst_prediction_errors(0.02), worst_prediction_errors(0.01), worst_prediction_errors(0.005));
        assert!(e100.0 < 1e-3 && e100.1 < 5e-6, "{e100:?}");
        for ratio in [e50.0 / e100.0, e100.0 / e200.0] {
            assert!((3.6..4.4).contains(&ratio), "euler {ratio}");
        }
        for ratio in [e50.1 / e100.1, e100.1 / e200.1] {
            assert!((6.5..9.5).contains(&ratio), "heun {ratio}");
        }
    }

    /// The analytic rates of the profile agree with central differences of the profile itself: the
    /// velocity rate (chain rule) to 1e-6 m/s^2 and the body rates with `-dC_bn/dt C_bn'` (the skew
    /// matrix of `(p, q, r)`) to 1e-7 rad/s, at times inside every manoeuvre.
    #[test]
    fn analytic_rates_match_finite_differences_of_the_profile() {
        let profile = FlightProfile::seed();
        let h = 1e-5;
        for t in [2.0, 6.3, 9.1, 17.2, 25.0, 32.5, 40.0, 49.1, 52.7] {
            let state = kinematic_state(&profile, t);
            let (before, after) = (kinematic_state(&profile, t - h), kinematic_state(&profile, t + h));
            let rate = (after.velocity_body_mps - before.velocity_body_mps) / (2.0 * h);
            assert!(
                (rate - state.velocity_rate_body_mps2).amax() < 1e-6,
                "t = {t}: {rate} vs {}",
                state.velocity_rate_body_mps2
            );
            let psi_rate = state.heading_rate_rad_s;
            let C = |s: &KinematicState, psi: f64| body_from_ned(s.inertial.roll_rad, s.inertial.pitch_rad, psi);
            let C_dot = (C(&after, h * psi_rate) - C(&before, -h * psi_rate)) / (2.0 * h);
            let skew = -C_dot * C(&state, 0.0).transpose();
            let pqr = Vector3::new(skew[(2, 1)], skew[(0, 2)], skew[(1, 0)]);
            let want = Vector3::new(state.inertial.p_rad_s, state.inertial.q_rad_s, state.inertial.r_rad_s);
            assert!((pqr - want).amax() < 1e-7, "t = {t}: {pqr} vs {want}");
        }
        // Steady level flight: no rates, the specific force is minus gravity in body axes.
        let level = kinematic_state(&FlightProfile::steady(60.0, 0.05, 0.05), 3.0).inertial;
        assert_eq!((level.p_rad_s, level.q_rad_s, level.r_rad_s), (0.0, 0.0, 0.0));
        assert!((level.ax_mps2 - GRAVITY_MPS2 * 0.05f64.sin()).abs() < 1e-12);
        assert!((level.az_mps2 + GRAVITY_MPS2 * 0.05f64.cos()).abs() < 1e-12);
    }

    /// The input Jacobian is the derivative of the kinematics (central differences, 1e-6).
    #[test]
    fn input_jacobian_matches_central_differences() {
        let x = Vector3::new(68.0, 2.0, 5.0);
        let m = Inertial::from_array([0.1, -0.05, 0.2, 0.3, -0.2, -9.5, 0.3, 0.1]);
        let G = velocity_derivative_input_jacobian(&x, &m);
        let numeric = crate::estimation::stekf::central_difference(&SVector::<f64, 8>::from(m.to_array()), |u| {
            velocity_derivative(&x, &Inertial::from_array(std::array::from_fn(|i| u[i])))
        });
        assert!((G - numeric).amax() < 1e-6, "{G} vs {numeric}");
    }

    /// Faults touch only their sensors, from their onset: alpha biased by exactly 2 deg from 10 s,
    /// beta held at its 20 s reading, airspeed times 1.1 from 30 s; the inertial data and the truth are
    /// bit-identical to the fault-free run and every channel is identical before its onset. The
    /// common-mode case (all three at 15 s) likewise.
    #[test]
    fn faults_change_exactly_the_intended_sensors() {
        let bias = 2f64.to_radians();
        let fault = |channel, onset_s, mode| ChannelFault { channel, onset_s, mode };
        let cases = [
            [
                fault(ALPHA, 10.0, FaultMode::Bias { bias }),
                fault(BETA, 20.0, FaultMode::Stuck { value: None }),
                fault(AIRSPEED, 30.0, FaultMode::Gain { factor: 1.1 }),
            ],
            [
                fault(ALPHA, 15.0, FaultMode::Bias { bias }),
                fault(BETA, 15.0, FaultMode::Stuck { value: None }),
                fault(AIRSPEED, 15.0, FaultMode::Gain { factor: 1.1 }),
            ],
        ];
        let healthy = run(ScenarioParams::seed(), 5);
        for faults in cases {
            let onset = faults.map(|f| (f.channel, f.onset_s));
            let onset_of = |c: usize| onset.iter().find(|(ch, _)| *ch == c).unwrap().1;
            let faulty = run(ScenarioParams { faults: faults.to_vec(), ..ScenarioParams::seed() }, 5);
            let held = faulty.iter().find(|s| s.t_s >= onset_of(BETA)).unwrap().air_data.beta_rad;
            for (h, f) in healthy.iter().zip(&faulty) {
                assert_eq!((h.inertial, h.truth), (f.inertial, f.truth));
                let t = h.t_s;
                let want_alpha = if t >= onset_of(ALPHA) { h.air_data.alpha_rad + bias } else { h.air_data.alpha_rad };
                let want_beta = if t >= onset_of(BETA) { held } else { h.air_data.beta_rad };
                let want_v =
                    if t >= onset_of(AIRSPEED) { 1.1 * h.air_data.airspeed_mps } else { h.air_data.airspeed_mps };
                assert_eq!(f.air_data.alpha_rad, want_alpha, "t = {t}");
                assert_eq!(f.air_data.beta_rad, want_beta, "t = {t}");
                assert_eq!(f.air_data.airspeed_mps, want_v, "t = {t}");
            }
            assert_ne!(held, healthy.iter().find(|s| s.t_s >= onset_of(BETA) + 1.0).unwrap().air_data.beta_rad);
        }
    }

    /// The same RNG state gives bit-identical samples; every sample draws exactly 14 normals whatever
    /// the noise scale and gust (the RNGs are in the same state afterwards), and a noise scale of 2
    /// doubles every noise sample exactly.
    #[test]
    fn draws_are_fixed_and_reproducible() {
        assert_eq!(run(ScenarioParams::seed(), 9), run(ScenarioParams::seed(), 9));
        let other = ScenarioParams {
            noise_scale: 2.0,
            wind: WindParams { gust_std_mps: 1.5, ..WindParams::seed() },
            ..ScenarioParams::seed()
        };
        let (mut a, mut b) = (scenario(ScenarioParams::seed()), scenario(other));
        let (mut ra, mut rb) = (ChaCha8Rng::seed_from_u64(2), ChaCha8Rng::seed_from_u64(2));
        for _ in 0..500 {
            let (sa, sb) = (a.next_sample(&mut ra).unwrap(), b.next_sample(&mut rb).unwrap());
            let (ia, ib, t) = (sa.inertial.to_array(), sb.inertial.to_array(), sa.truth.inertial.to_array());
            for i in 0..8 {
                assert!(((ib[i] - t[i]) - 2.0 * (ia[i] - t[i])).abs() < 1e-12);
            }
            let (aa, ab) = (sa.air_data.to_array(), sb.air_data.to_array());
            let (ta, tb) = (sa.truth.air_data.to_array(), sb.truth.air_data.to_array());
            for j in 0..3 {
                assert!(((ab[j] - tb[j]) - 2.0 * (aa[j] - ta[j])).abs() < 1e-12);
            }
        }
        assert_eq!(ra.random::<u64>(), rb.random::<u64>());
        let mut short = scenario(ScenarioParams { duration_s: 0.05, ..ScenarioParams::seed() });
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        assert_eq!(std::iter::from_fn(|| short.next_sample(&mut rng)).count(), 5);
        assert_eq!(short.produced(), short.samples());
    }

    /// A steady wind changes no measurement (bit-identical samples; only the ground velocity moves by the
    /// wind); a gust changes the air data only, never the inertial data.
    #[test]
    fn steady_wind_is_invisible_and_a_gust_moves_only_the_air_data() {
        let calm = run(ScenarioParams::seed(), 4);
        let windy = run(
            ScenarioParams {
                wind: WindParams { steady_ned_mps: [12.0, -5.0, 0.5], ..WindParams::seed() },
                ..ScenarioParams::seed()
            },
            4,
        );
        for (c, w) in calm.iter().zip(&windy) {
            assert_eq!((c.inertial, c.air_data, c.truth.air_data), (w.inertial, w.air_data, w.truth.air_data));
            let shift = w.truth.ground_velocity_ned_mps - c.truth.ground_velocity_ned_mps;
            assert!((shift - Vector3::new(12.0, -5.0, 0.5)).amax() < 1e-12);
        }
        let gusty = run(
            ScenarioParams { wind: WindParams { gust_std_mps: 1.0, ..WindParams::seed() }, ..ScenarioParams::seed() },
            4,
        );
        let mut largest_change = 0.0f64;
        for (c, g) in calm.iter().zip(&gusty) {
            assert_eq!(c.inertial, g.inertial);
            largest_change = largest_change.max((c.air_data.airspeed_mps - g.air_data.airspeed_mps).abs());
        }
        assert!(largest_change > 0.5, "{largest_change}");
    }

    /// Over 200 s at 100 Hz the measurement errors have the stated standard deviations (within 3%; the
    /// standard error is 0.5%) and a 0.2 s gust has its stated 1 m/s (within 10%). Measured ratios:
    /// 0.991-1.006 for the sensors, 0.985-1.023 for the gust axes.
    #[test]
    fn noise_and_gust_have_the_stated_sizes() {
        let params = ScenarioParams {
            duration_s: 200.0,
            wind: WindParams { gust_std_mps: 1.0, gust_time_constant_s: 0.2, ..WindParams::seed() },
            ..ScenarioParams::seed()
        };
        let noise = params.noise;
        let samples = run(params, 8);
        let n = samples.len() as f64;
        let rms = |f: &dyn Fn(&AirDataSample) -> f64| (samples.iter().map(|s| f(s).powi(2)).sum::<f64>() / n).sqrt();
        for (i, name) in INERTIAL_CHANNEL_NAMES.iter().enumerate() {
            let got = rms(&|s| s.inertial.to_array()[i] - s.truth.inertial.to_array()[i]);
            let ratio = got / noise.inertial_std()[i];
            assert!((ratio - 1.0).abs() < 0.03, "{name}: {ratio}");
        }
        for (j, name) in AIR_DATA_CHANNEL_NAMES.iter().enumerate() {
            let got = rms(&|s| s.air_data.to_array()[j] - s.truth.air_data.to_array()[j]);
            let ratio = got / noise.air_data_std()[j];
            assert!((ratio - 1.0).abs() < 0.03, "{name}: {ratio}");
        }
        for axis in 0..3 {
            let ratio = rms(&|s| s.truth.gust_ned_mps[axis]);
            assert!((ratio - 1.0).abs() < 0.1, "gust axis {axis}: {ratio}");
        }
    }

    /// The sensor errors, noise-free: the air data are the truth through a first-order lag (the step
    /// response of a lag at one sample), scale factor and mounting offset; the inertial data rotated by
    /// the IMU's misalignment. With noise, the coloured air-data noise keeps the white noise's size and
    /// has the Gauss-Markov autocorrelation `exp(-dt / tau)` at one sample.
    #[test]
    fn sensor_errors_are_lag_scale_offset_rotation_and_coloured_noise() {
        let errors = SensorErrors {
            airspeed_lag_s: 0.1,
            flow_angle_lag_s: 0.05,
            airspeed_scale_factor: 0.02,
            flow_angle_scale_factor: 0.05,
            alpha_misalignment_rad: 0.3f64.to_radians(),
            beta_misalignment_rad: 0.2f64.to_radians(),
            imu_misalignment_rad: 0.1f64.to_radians(),
            noise_correlation_s: 0.0,
        };
        let ideal = run(noise_free(0.01), 1);
        let imperfect = run(ScenarioParams { sensor_errors: errors, ..noise_free(0.01) }, 1);
        let (mut lagged, a) = (ideal[0].truth.air_data.to_array(), [(-0.1f64).exp(), (-0.2f64).exp(), (-0.2f64).exp()]);
        for (i, e) in ideal.iter().zip(&imperfect) {
            let truth = i.truth.air_data.to_array();
            if i.t_s > 0.0 {
                lagged = std::array::from_fn(|j| a[j] * lagged[j] + (1.0 - a[j]) * truth[j]);
            }
            let want = [
                lagged[0] * 1.02,
                lagged[1] * 1.05 + errors.alpha_misalignment_rad,
                lagged[2] * 1.05 + errors.beta_misalignment_rad,
            ];
            let got = e.air_data.to_array();
            assert!((0..3).all(|j| (got[j] - want[j]).abs() < 1e-12), "{} {got:?} {want:?}", i.t_s);
            let (x, y) = (i.inertial.to_array(), e.inertial.to_array());
            let rates = Vector3::new(x[0], x[1], x[2]);
            let rotated = rates + Vector3::repeat(errors.imu_misalignment_rad).cross(&rates);
            assert!((Vector3::new(y[0], y[1], y[2]) - rotated).amax() < 1e-15);
            assert!((y[6] - x[6] - errors.imu_misalignment_rad).abs() < 1e-15);
        }
        // Through the 30 deg bank the lagged airspeed trails the truth.
        assert!(
            imperfect.iter().any(|s| (s.air_data.airspeed_mps / 1.02 - s.truth.air_data.airspeed_mps).abs() > 0.01)
        );

        let coloured = ScenarioParams {
            duration_s: 200.0,
            sensor_errors: SensorErrors { noise_correlation_s: 0.5, ..SensorErrors::default() },
            ..ScenarioParams::seed()
        };
        let sigma = coloured.noise.airspeed_std_mps;
        let samples = run(coloured, 8);
        let e: Vec<f64> =
            samples.iter().map(|s| (s.air_data.airspeed_mps - s.truth.air_data.airspeed_mps) / sigma).collect();
        let n = e.len() as f64;
        let variance = e.iter().map(|v| v * v).sum::<f64>() / n;
        let lag1 = e.windows(2).map(|w| w[0] * w[1]).sum::<f64>() / (n - 1.0) / variance;
        // 200 s is 400 correlation times: the variance is known to about 7 %.
        assert!((variance - 1.0).abs() < 0.2, "{variance}");
        assert!((lag1 - (-0.02f64).exp()).abs() < 0.005, "{lag1}");
    }

    /// Three lanes: lane 0 draws exactly what a single-lane scenario draws (same samples, same gusts),
    /// the others their own noise after the gust; a fault hits the first `faulty_lanes` lanes only.
    #[test]
    fn lanes_share_the_truth_and_the_fault_hits_the_first_ones() {
        let fault = ChannelFault { channel: ALPHA, onset_s: 1.0, mode: FaultMode::Bias { bias: 0.05 } };
        let one = run(ScenarioParams { faults: vec![fault], ..ScenarioParams::seed() }, 5);
        for faulty_lanes in [1, 3] {
            let three =
                run(ScenarioParams { faults: vec![fault], lanes: 3, faulty_lanes, ..ScenarioParams::seed() }, 5);
            assert_eq!((one[0].air_data, one[0].inertial), (three[0].air_data, three[0].inertial));
            assert_eq!(one[0].truth, three[0].truth);
            for s in &three[200..] {
                let alpha = s.lanes.map(|l| l.alpha_rad - s.truth.air_data.alpha_rad);
                for (lane, error) in alpha.iter().enumerate() {
                    let faulty = lane < faulty_lanes;
                    assert_eq!(error.abs() > 0.03, faulty, "lane {lane} of {faulty_lanes}: {error}");
                }
                assert_ne!(s.lanes[1].airspeed_mps, s.lanes[2].airspeed_mps, "independent noise");
            }
        }
    }

    /// The Aerosonde's 60 s manoeuvres in calm air at 100 Hz.
    fn fly_aerosonde(scale: f64) -> Vec<AirframeSample> {
        let mut flight = AerosondeFlight::new(scale, 0.01).unwrap();
        (0..6000).map(|k| flight.sample_and_step(k as f64 * 0.01, &Vector3::zeros()).unwrap()).collect()
    }

    /// The manoeuvres happen (bank, speed, sideslip), and in calm air a rigid body obeys the patent's
    /// kinematics: the filters' one-step prediction (Heun on the inertial samples) misses the next
    /// air-relative velocity only between samples. Measured: bank 29.9 deg, 30.0 m/s, sideslip 2.5 deg
    /// (the autopilot's sideslip loop does not reach the 4 deg commanded in 2 s); one-step error 3e-5 m/s
    /// in steady flight, 2.8e-3 at most through the manoeuvres, and 0.053 m/s once: at the speed step
    /// the throttle jumps within a sample (5 m/s^2 more thrust) and the prediction averages the jump.
    #[test]
    fn the_airframe_flies_the_manoeuvres_and_obeys_the_kinematics() {
        let samples = fly_aerosonde(1.0);
        let max_by = |f: &dyn Fn(&AirframeSample) -> f64| samples.iter().map(f).fold(f64::NEG_INFINITY, f64::max);
        assert!((29.0..31.0).contains(&max_by(&|s| s.roll_rad.to_degrees())));
        assert!((29.9..30.5).contains(&max_by(&|s| air_data_from_velocity(&s.velocity_air_body_mps).airspeed_mps)));
        assert!(
            (2.0..4.0).contains(&max_by(&|s| air_data_from_velocity(&s.velocity_air_body_mps).beta_rad.to_degrees()))
        );
        let mut errors: Vec<f64> = samples
            .windows(2)
            .map(|w| {
                let predicted = propagate_velocity(
                    &w[0].velocity_air_body_mps,
                    &InertialInterval::new(inertial_of(&w[0]), inertial_of(&w[1])),
                    0.01,
                );
                (predicted - w[1].velocity_air_body_mps).amax()
            })
            .collect();
        assert!(errors[..700].iter().all(|e| *e < 1e-4), "steady flight before the climb");
        let (at, worst) = errors.iter().enumerate().fold((0, 0.0), |m, (k, e)| if *e > m.1 { (k, *e) } else { m });
        assert_eq!(at, 3599, "the sample before the speed step at 36 s");
        assert!((0.04..0.06).contains(&worst), "{worst}");
        errors[at] = 0.0;
        assert!(errors.iter().all(|e| *e < 3e-3));
    }

    #[test]
    fn invalid_scenarios_are_errors_naming_the_field() {
        let with = |edit: &dyn Fn(&mut ScenarioParams)| {
            let mut p = ScenarioParams::seed();
            edit(&mut p);
            AirDataScenario::new(p).unwrap_err()
        };
        assert_eq!(
            with(&|p| p.dt_s = 0.0),
            ScenarioError::Value(ValueError::NotPositive { field: "dt_s", value: 0.0 })
        );
        assert!(matches!(
            with(&|p| p.noise.alpha_std_rad = f64::NAN),
            ScenarioError::Value(ValueError::NotFinite { field: "noise.alpha_std_rad", .. })
        ));
        assert!(matches!(
            with(&|p| p.noise_scale = -1.0),
            ScenarioError::Value(ValueError::Negative { field: "noise_scale", .. })
        ));
        let bad_fault = ChannelFault { channel: 3, onset_s: 1.0, mode: FaultMode::TotalFailure };
        assert!(matches!(
            with(&|p| p.faults = vec![bad_fault]),
            ScenarioError::Value(ValueError::FaultChannel { index: 0, channel: 3, .. })
        ));
        assert!(matches!(
            with(&|p| p.profile.airspeed_mps = 14.0),
            ScenarioError::Profile(ProfileError::Envelope { field: "airspeed_mps", .. })
        ));
        assert!(matches!(
            with(&|p| p.profile.roll_rad = 1.2),
            ScenarioError::Profile(ProfileError::Envelope { field: "roll_rad", .. })
        ));
        assert!(matches!(
            with(&|p| p.profile.segments[2].duration_s = 0.0),
            ScenarioError::Profile(ProfileError::Segment { index: 2, .. })
        ));
        let err = with(&|p| p.wind.gust_time_constant_s = 0.0).to_string();
        assert!(err.contains("wind.gust_time_constant_s"), "{err}");
    }
}
