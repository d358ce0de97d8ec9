//! A nonlinear longitudinal rigid aircraft (Navion-like light airplane): the equations of the test FMU
//! `fmus/aircraft` written once more in Rust, generic over [`Real`] so dual numbers give its exact
//! Jacobian. In `f64` the arithmetic is the C model's operation by operation (fmus/README.md), so the
//! native model and the FMU stepped by the same integrator agree to the bit.
//!
//! Lift and pitching moment are cubic in the angle of attack (`CLa3`, `Cma3`): the nonlinearity a
//! linear design model leaves out.

use crate::dual::Real;

/// States, in the FMU's order.
pub const STATES: [&str; 5] = ["V_m_s", "alpha_rad", "q_rad_s", "theta_rad", "h_m"];
/// Inputs, in the FMU's order; `elevator_effectiveness` is the model's own fault input (1 healthy).
pub const INPUTS: [&str; 3] = ["elevator_rad", "throttle", "elevator_effectiveness"];

/// Airframe and aerodynamic parameters, with the FMU's names and default values.
#[derive(Debug, Clone, PartialEq)]
pub struct LongitudinalParams {
    pub m_kg: f64,
    pub s_m2: f64,
    pub cbar_m: f64,
    pub iyy_kg_m2: f64,
    pub rho_kg_m3: f64,
    pub g_m_s2: f64,
    pub cl0: f64,
    pub cla: f64,
    pub cla3: f64,
    pub clq: f64,
    pub clde: f64,
    pub cd0: f64,
    pub k_induced: f64,
    pub cm0: f64,
    pub cma: f64,
    pub cma3: f64,
    pub cmq: f64,
    pub cmde: f64,
    pub t_max_n: f64,
}

impl Default for LongitudinalParams {
    fn default() -> Self {
        LongitudinalParams {
            m_kg: 1247.0,
            s_m2: 17.09,
            cbar_m: 1.74,
            iyy_kg_m2: 4067.5,
            rho_kg_m3: 1.225,
            g_m_s2: 9.80665,
            cl0: 0.2,
            cla: 4.44,
            cla3: 6.0,
            clq: 3.8,
            clde: 0.355,
            cd0: 0.05,
            k_induced: 0.0675,
            cm0: 0.05,
            cma: -0.683,
            cma3: -2.0,
            cmq: -9.96,
            cmde: -0.923,
            t_max_n: 4000.0,
        }
    }
}

/// `dx/dt` at state `x` ([`STATES`]) and inputs `u` ([`INPUTS`]).
pub fn derivatives<R: Real>(p: &LongitudinalParams, x: &[R; 5], u: &[R; 3]) -> [R; 5] {
    let [v, alpha, q, theta, _h] = *x;
    let [elevator, throttle, effectiveness] = *u;
    // Each line is the C model's expression with its operations in the same order (a * b == b * a
    // exactly, so the factors may be swapped; the grouping may not).
    let qbar = v * (0.5 * p.rho_kg_m3) * v;
    let qhat = q * p.cbar_m / (v * 2.0);
    let de = effectiveness * elevator;
    let cl = R::cst(p.cl0) + alpha * p.cla - alpha_cubed(alpha, p.cla3) + qhat * p.clq + de * p.clde;
    let cd = R::cst(p.cd0) + cl * p.k_induced * cl;
    let cm = R::cst(p.cm0) + alpha * p.cma + alpha_cubed(alpha, p.cma3) + qhat * p.cmq + de * p.cmde;
    let lift_n = qbar * p.s_m2 * cl;
    let drag_n = qbar * p.s_m2 * cd;
    let moment_nm = qbar * p.s_m2 * p.cbar_m * cm;
    let thrust_n = throttle * p.t_max_n;
    let gamma = theta - alpha;
    let (sin_a, cos_a) = alpha.sin_cos();
    let (sin_g, cos_g) = gamma.sin_cos();
    [
        (thrust_n * cos_a - drag_n) / p.m_kg - sin_g * p.g_m_s2,
        q - (thrust_n * sin_a + lift_n) / (v * p.m_kg) + cos_g * p.g_m_s2 / v,
        moment_nm / p.iyy_kg_m2,
        q,
        v * sin_g,
    ]
}

/// `c alpha^3` in the C model's order, `((c alpha) alpha) alpha`.
fn alpha_cubed<R: Real>(alpha: R, c: f64) -> R {
    alpha * c * alpha * alpha
}

/// The outputs beyond the states: flight-path angle (rad) and load factor from lift (g).
pub fn gamma_and_nz<R: Real>(p: &LongitudinalParams, x: &[R; 5], u: &[R; 3]) -> (R, R) {
    let [v, alpha, q, theta, _] = *x;
    let qbar = v * (0.5 * p.rho_kg_m3) * v;
    let qhat = q * p.cbar_m / (v * 2.0);
    let de = u[2] * u[0];
    let cl = R::cst(p.cl0) + alpha * p.cla - alpha_cubed(alpha, p.cla3) + qhat * p.clq + de * p.clde;
    (theta - alpha, qbar * p.s_m2 * cl / (p.m_kg * p.g_m_s2))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_helpers_trim_is_an_equilibrium_and_a_nudge_is_not() {
        // The trim fmus/README.md reports (solved by Newton in Python): V = 53.6 m/s, theta = alpha.
        let p = LongitudinalParams::default();
        let (alpha, elevator, throttle) = (0.0443566119725, 0.0211591440454, 0.459166130340);
        let d = derivatives(&p, &[53.6, alpha, 0.0, alpha, 1000.0], &[elevator, throttle, 1.0]);
        for (i, v) in d.iter().enumerate() {
            assert!(v.abs() < 1e-9, "state {}: {v}", STATES[i]);
        }
        let d = derivatives(&p, &[53.6, alpha, 0.0, alpha, 1000.0], &[elevator + 0.01, throttle, 1.0]);
        // Positive elevator is nose down: a pitching-moment derivative of -0.923 per rad.
        let expected_dq = 0.5 * 1.225 * 53.6 * 53.6 * 17.09 * 1.74 * -0.923 * 0.01 / 4067.5;
        assert!((d[2] - expected_dq).abs() < 1e-12, "{} vs {expected_dq}", d[2]);
    }
}
