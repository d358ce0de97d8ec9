//! The longitudinal aircraft of [`super::longitudinal`] with a second-order elevator actuator, a
//! first-order engine lag and first-order alpha / q / theta sensor lags: 11 continuous states, the
//! equations of the test FMU `fmus/aircraft_actuated` written once more in Rust (the benchmark of FMU
//! vs native cost per step wants a model of at least 10 states). Generic over [`Real`]; in `f64` the
//! arithmetic is the C model's operation by operation, so the two agree to the bit.
//!
//! The airframe is driven by the actuator position (state 5) and the engine state (state 7), not by
//! the commands: `longitudinal::derivatives(airframe, x[0..5], [x[5], x[7], effectiveness])`.

use crate::dual::Real;

/// States, in the FMU's order (also the order of its `<Derivatives>`).
pub const STATES: [&str; 11] = [
    "V_m_s",
    "alpha_rad",
    "q_rad_s",
    "theta_rad",
    "h_m",
    "elevator_rad",
    "elevator_rate_rad_s",
    "throttle_state",
    "alpha_meas_rad",
    "q_meas_rad_s",
    "theta_meas_rad",
];
/// Inputs, in the FMU's order; `elevator_effectiveness` is the fault input (1 healthy), multiplying
/// the actuator position as in `fmus/aircraft`.
pub const INPUTS: [&str; 3] = ["elevator_cmd_rad", "throttle_cmd", "elevator_effectiveness"];

/// The airframe's parameters and those of the actuator, engine and sensors, with the FMU's defaults.
#[derive(Debug, Clone, PartialEq)]
pub struct ActuatedParams {
    pub airframe: super::longitudinal::LongitudinalParams,
    /// Elevator actuator natural frequency (rad/s).
    pub wa_rad_s: f64,
    /// Elevator actuator damping ratio.
    pub za: f64,
    /// Engine lag time constant (s).
    pub tau_engine_s: f64,
    /// Time constant of the alpha, q and theta sensor lags (s).
    pub tau_sensor_s: f64,
}

impl Default for ActuatedParams {
    fn default() -> Self {
        ActuatedParams {
            airframe: super::longitudinal::LongitudinalParams::default(),
            wa_rad_s: 40.0,
            za: 0.7,
            tau_engine_s: 0.5,
            tau_sensor_s: 0.02,
        }
    }
}

/// `dx/dt` at state `x` ([`STATES`]) and inputs `u` ([`INPUTS`]).
///
/// The C model's order (fmus/aircraft_actuated/model.c `computeDerivatives`), reproduced here:
/// - airframe: [`super::longitudinal::derivatives`] with elevator = `x[5]`, throttle = `x[7]`;
/// - actuator: `wa2 = wa * wa`, `err = cmd - elevator`, `spring = wa2 * err`, `c1 = 2.0 * za`,
///   `c2 = c1 * wa`, `damping = c2 * rate`, `d(rate) = spring - damping`, `d(elevator) = rate`;
/// - engine: `d(throttle_state) = (throttle_cmd - throttle_state) / tau_engine`;
/// - sensors: `d(x_meas) = (x - x_meas) / tau_sensor` for x = alpha, q, theta.
///
/// `a * b == b * a` exactly, so factors may be swapped; the grouping may not.
pub fn derivatives<R: Real>(p: &ActuatedParams, x: &[R; 11], u: &[R; 3]) -> [R; 11] {
    let [elevator_cmd, throttle_cmd, effectiveness] = *u;
    let (elevator, rate, throttle) = (x[5], x[6], x[7]);
    let airframe_state = [x[0], x[1], x[2], x[3], x[4]];
    let [dv, dalpha, dq, dtheta, dh] =
        super::longitudinal::derivatives(&p.airframe, &airframe_state, &[elevator, throttle, effectiveness]);
    let wa2 = p.wa_rad_s * p.wa_rad_s;
    let spring = (elevator_cmd - elevator) * wa2;
    let c2 = 2.0 * p.za * p.wa_rad_s;
    let damping = rate * c2;
    [
        dv,
        dalpha,
        dq,
        dtheta,
        dh,
        rate,
        spring - damping,
        (throttle_cmd - throttle) / p.tau_engine_s,
        (x[1] - x[8]) / p.tau_sensor_s,
        (x[2] - x[9]) / p.tau_sensor_s,
        (x[3] - x[10]) / p.tau_sensor_s,
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dual::Dual;

    // The aircraft's trim at V = 53.6 m/s, level flight (fmus/README.md).
    const ALPHA: f64 = 0.0443566119725;
    const ELEVATOR: f64 = 0.0211591440454;
    const THROTTLE: f64 = 0.459166130340;
    const TRIM: [f64; 11] = [53.6, ALPHA, 0.0, ALPHA, 1000.0, ELEVATOR, 0.0, THROTTLE, ALPHA, 0.0, ALPHA];

    #[test]
    fn the_trim_with_settled_actuator_engine_and_sensors_is_an_equilibrium() {
        let p = ActuatedParams::default();
        let d = derivatives(&p, &TRIM, &[ELEVATOR, THROTTLE, 1.0]);
        for (i, v) in d.iter().enumerate() {
            assert!(v.abs() < 1e-9, "state {}: {v}", STATES[i]);
        }
    }

    #[test]
    fn an_elevator_command_step_accelerates_the_actuator_only() {
        let p = ActuatedParams::default();
        let d = derivatives(&p, &TRIM, &[ELEVATOR + 0.01, THROTTLE, 1.0]);
        // wa^2 * 0.01 = 40 * 40 * 0.01; the airframe sees the actuator position, which has not moved.
        assert!((d[6] - 16.0).abs() < 1e-12, "d(elevator_rate)/dt = {}", d[6]);
        for (i, v) in d.iter().enumerate().filter(|&(i, _)| i != 6) {
            assert!(v.abs() < 1e-9, "state {}: {v}", STATES[i]);
        }
    }

    #[test]
    fn the_lags_follow_their_own_states_and_commands() {
        let p = ActuatedParams::default();
        let mut x = TRIM;
        x[6] = 0.1; // actuator rate
        x[8] = ALPHA - 0.01; // alpha sensor lags 0.01 rad behind
        x[9] = -0.02; // q sensor
        x[10] = ALPHA + 0.03; // theta sensor
        let d = derivatives(&p, &x, &[ELEVATOR, THROTTLE + 0.1, 1.0]);
        let close = |a: f64, b: f64| (a - b).abs() < 1e-12;
        assert!(close(d[5], 0.1), "d(elevator)/dt = rate: {}", d[5]);
        assert!(close(d[6], -2.0 * 0.7 * 40.0 * 0.1), "rate damping: {}", d[6]);
        assert!(close(d[7], 0.1 / 0.5), "engine lag: {}", d[7]);
        assert!((d[8] - 0.01 / 0.02).abs() < 1e-9, "alpha sensor: {}", d[8]);
        assert!(close(d[9], 0.02 / 0.02), "q sensor: {}", d[9]);
        assert!((d[10] + 0.03 / 0.02).abs() < 1e-9, "theta sensor: {}", d[10]);
        // The airframe is unaffected by the sensors and by the commands.
        let d0 = derivatives(&p, &TRIM, &[ELEVATOR, THROTTLE, 1.0]);
        assert_eq!(d[..5], d0[..5]);
    }

    #[test]
    fn dual_numbers_give_the_actuator_engine_and_sensor_jacobian_and_the_f64_values() {
        let p = ActuatedParams::default();
        let xd: [Dual<11>; 11] = std::array::from_fn(|i| Dual::input(TRIM[i], i));
        let ud = [Dual::<11>::cst(ELEVATOR), Dual::cst(THROTTLE), Dual::cst(1.0)];
        let d = derivatives(&p, &xd, &ud);
        let f = derivatives(&p, &TRIM, &[ELEVATOR, THROTTLE, 1.0]);
        for ((dual, value), name) in d.iter().zip(f).zip(STATES) {
            assert_eq!(dual.v.to_bits(), value.to_bits(), "value of d{name}");
        }
        let close = |a: f64, b: f64| (a - b).abs() < 1e-9 * b.abs().max(1.0);
        assert!(close(d[5].d[6], 1.0));
        assert!(close(d[6].d[5], -1600.0) && close(d[6].d[6], -56.0));
        assert!(close(d[7].d[7], -2.0));
        for (row, x) in [(8, 1), (9, 2), (10, 3)] {
            assert!(close(d[row].d[x], 50.0) && close(d[row].d[row], -50.0), "sensor row {row}");
        }
        // The airframe depends on the actuator position and the engine state, not on the sensors.
        assert!(d[2].d[5] < 0.0, "positive elevator is nose down");
        assert!(d[0].d[7] > 0.0, "throttle accelerates");
        for (row, name) in d[..5].iter().zip(STATES) {
            assert!((6..11).filter(|&c| c != 7).all(|c| row.d[c] == 0.0), "d{name} on the rate or the sensors");
        }
    }
}
