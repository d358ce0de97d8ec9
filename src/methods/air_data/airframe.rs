//! A truth the air-data filters do not share (issue 20.6): the Aerosonde 6-DoF airframe of method 004
//! ([`crate::vehicles::aerosonde`]: aerodynamics, propulsion, actuators with lag and limits, the
//! PID autopilot) flying manoeuvres like the seed profile's, in the wind the air data see (steady plus
//! turbulence, which here moves the airframe too). The filters keep the patent's kinematics, which a rigid
//! body obeys exactly only in steady wind; what they miss is the turbulence's effect on the motion, the
//! autopilot's and the airframe's own dynamics between samples, and (in `flight/scenario.rs`) the sensors' lag,
//! scale factor, misalignment and coloured noise.
//!
//! The manoeuvres (choices, scaled by the deck's `manoeuvre_scale`), from trim at 25 m/s and 100 m: a
//! climb of 15 m from 8 s to 18 s and back; a 30 deg bank from 22 s to 32 s; +5 m/s from 36 s; a
//! sideslip doublet of +/-4 deg from 46 s to 50 s (through the autopilot's sideslip loop). The seed
//! profile's are a pull-up, a 30 deg turn, +15 m/s and a +/-4 deg doublet at 70 m/s, which is beyond this
//! airframe.

use nalgebra::Vector3;

use crate::vehicles::aerosonde::{
    Actuators, AerosondeParams, Autopilot, AutopilotGains, Setpoints, State, air_data, specific_force, step_rk4, trim,
};
use crate::vehicles::aerosonde::{ENVELOPE_AIRSPEED_MPS, ENVELOPE_MAX_ALPHA_DEG};

/// Trim airspeed (m/s) and altitude (m) of the flight.
pub const TRIM_AIRSPEED_MPS: f64 = 25.0;
pub const TRIM_ALTITUDE_M: f64 = 100.0;

/// What the airframe gives the sensors at one sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AirframeSample {
    /// Air-relative body velocity (m/s): the truth of the air data.
    pub velocity_air_body_mps: Vector3<f64>,
    /// Body rates `p, q, r` (rad/s) and the specific force at the CG (m/s^2): what perfect gyros and
    /// accelerometers measure.
    pub rates_rad_s: Vector3<f64>,
    pub specific_force_mps2: Vector3<f64>,
    pub roll_rad: f64,
    pub pitch_rad: f64,
    pub heading_rad: f64,
    /// Inertial velocity, NED (m/s).
    pub ground_velocity_ned_mps: Vector3<f64>,
}

/// The Aerosonde flying the manoeuvres; see the module docs.
#[derive(Debug, Clone)]
pub struct AerosondeFlight {
    params: AerosondeParams,
    x: State,
    actuators: Actuators,
    autopilot: Autopilot,
    manoeuvre_scale: f64,
    dt_s: f64,
}

impl AerosondeFlight {
    /// Trimmed, wings level, at [`TRIM_AIRSPEED_MPS`] and [`TRIM_ALTITUDE_M`].
    pub fn new(manoeuvre_scale: f64, dt_s: f64) -> Result<Self, String> {
        let params = AerosondeParams::default();
        let (x, surfaces, throttle) = trim(&params, TRIM_AIRSPEED_MPS, TRIM_ALTITUDE_M)?;
        Ok(AerosondeFlight {
            params,
            x,
            actuators: Actuators::new(surfaces),
            autopilot: Autopilot::new(AutopilotGains::default(), surfaces, throttle),
            manoeuvre_scale,
            dt_s,
        })
    }

    /// The autopilot's setpoints and the commanded sideslip (rad) at `t_s`.
    fn setpoints(&self, t_s: f64) -> (Setpoints, f64) {
        let k = self.manoeuvre_scale;
        let within = |a: f64, b: f64| (a..b).contains(&t_s);
        let setpoints = Setpoints {
            va_mps: TRIM_AIRSPEED_MPS + if t_s >= 36.0 { 5.0 * k } else { 0.0 },
            altitude_m: TRIM_ALTITUDE_M + if within(8.0, 18.0) { 15.0 * k } else { 0.0 },
            roll_rad: if within(22.0, 32.0) { 30f64.to_radians() * k } else { 0.0 },
        };
        let sideslip_rad = 4f64.to_radians()
            * k
            * if within(46.0, 48.0) {
                1.0
            } else if within(48.0, 50.0) {
                -1.0
            } else {
                0.0
            };
        (setpoints, sideslip_rad)
    }

    /// The sample at `t_s` in the wind `wind_ned_mps` (steady plus gust, held over the step), then one
    /// step of the airframe; Err when the step leaves the envelope of method 004's trials.
    pub fn sample_and_step(&mut self, t_s: f64, wind_ned_mps: &Vector3<f64>) -> Result<AirframeSample, String> {
        let x = self.x;
        let (va, alpha, beta) = air_data(&x, wind_ned_mps);
        let (setpoints, sideslip_rad) = self.setpoints(t_s);
        let (commands, throttle) = self.autopilot.command(&x, va, alpha, beta - sideslip_rad, &setpoints, self.dt_s);
        let positions = self.actuators.step(&commands, self.dt_s);
        let f = specific_force(&self.params, &x, &positions, throttle, wind_ned_mps);
        let (phi, theta, psi) = (x[6], x[7], x[8]);
        let body_from_ned = crate::kinematics::body_from_ned(phi, theta, psi);
        let velocity_body = Vector3::new(x[3], x[4], x[5]);
        let sample = AirframeSample {
            velocity_air_body_mps: velocity_body - body_from_ned * wind_ned_mps,
            rates_rad_s: Vector3::new(x[9], x[10], x[11]),
            specific_force_mps2: f,
            roll_rad: phi,
            pitch_rad: theta,
            heading_rad: psi,
            ground_velocity_ned_mps: body_from_ned.transpose() * velocity_body,
        };
        self.x = step_rk4(&self.params, &x, &positions, throttle, wind_ned_mps, self.dt_s);
        let (va, alpha, _) = air_data(&self.x, wind_ned_mps);
        let end_s = t_s + self.dt_s;
        if !self.x.iter().all(|v| v.is_finite()) {
            return Err(format!("the airframe's state is not finite at t = {end_s:.2} s"));
        }
        if !ENVELOPE_AIRSPEED_MPS.contains(&va) || alpha.abs() > ENVELOPE_MAX_ALPHA_DEG.to_radians() {
            return Err(format!(
                "the airframe left the envelope at t = {end_s:.2} s: airspeed {va:.1} m/s, alpha {:.1} deg",
                alpha.to_degrees()
            ));
        }
        Ok(sample)
    }
}
