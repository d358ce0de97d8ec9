//! Nonlinear 6-DoF model of the Aerosonde small UAV with five independent control surfaces, its
//! actuators, a PID autopilot, and the reduced `[p, q, r, alpha, beta]` model a bank of (strong-tracking)
//! EKFs uses for control-surface fault detection (method 004, after Ducard & Geering, JGCD 31(1), 2008).
//!
//! # Source
//! R. W. Beard and T. W. McLain, *Small Unmanned Aircraft: Theory and Practice*, Princeton University
//! Press, 2012 (first edition). Parameters: Appendix E, the Aerosonde UAV table (mass 13.5 kg,
//! propeller `S_prop = 0.2027`, `C_prop = 1`, `k_motor = 80`; the later online revision with 11 kg and a
//! motor/propeller map is *not* used). Equations: chapter 3 (rigid-body equations with the Gamma
//! inertia terms) and chapter 4 (forces and moments).
//!
//! Lift and drag are the book's nonlinear blended model (section 4.2):
//! - `C_L(alpha) = (1 - sigma) (C_L_0 + C_L_alpha alpha) + sigma 2 sign(alpha) sin^2(alpha) cos(alpha)`,
//! - `sigma(alpha) = (1 + e^{-M(alpha - alpha0)} + e^{M(alpha + alpha0)})
//!   / ((1 + e^{-M(alpha - alpha0)}) (1 + e^{M(alpha + alpha0)}))`,
//! - `C_D(alpha) = C_D_p + (C_L_0 + C_L_alpha alpha)^2 / (pi e AR)`, `AR = b^2 / S` (parabolic polar),
//!
//! rotated into body axes (`C_X = -C_D cos(alpha) + C_L sin(alpha)`, `C_Z = -C_D sin(alpha) - C_L cos(alpha)`,
//! and likewise for the `q` and `delta_e` derivatives). The linear-drag coefficients `C_D_0`, `C_D_alpha`
//! and `epsilon` of the table are kept as fields for reference but do not enter this model. Pitching,
//! rolling and yawing moments and the side force are the book's linear ones. Thrust is the book's
//! `F_prop = 1/2 rho S_prop C_prop ((k_motor delta_t)^2 - Va^2)` along body x, propeller torque
//! `-k_T_P (k_Omega delta_t)^2` (zero in the table).
//!
//! # State, frames, wind
//! `x = [pn, pe, pd, u, v, w, phi, theta, psi, p, q, r]`: NED position (m), body-axis ground velocity
//! (m/s), 3-2-1 Euler angles (rad), body rates (rad/s). Altitude is `-pd`. A steady wind (NED, m/s, the
//! velocity of the air mass) enters through the air-relative velocity `[u, v, w] - R^T w_ned`, from which
//! `Va = |.|`, `alpha = atan2(w_r, u_r)`, `beta = asin(v_r / Va)`. Gravity is 9.81 m/s^2
//! ([`AerosondeParams::gravity_mps2`]).
//!
//! # Five surfaces and their sign conventions
//! Surface order: [`SURFACE_NAMES`] = left aileron, right aileron, left elevator, right elevator, rudder
//! (rad). Each surface is positive by the right-hand rule about its hinge axis (Beard & McLain section 4.1):
//! ailerons and elevators positive *trailing edge down*, rudder positive *trailing edge left*. The book's
//! effective deflections are formed as
//! - aileron `delta_a = (delta_a_left - delta_a_right) / 2` (the book's definition): positive `delta_a`
//!   rolls right (`C_l_delta_a = 0.08 > 0`, positive `p` is right wing down). A +5 deg step of the left
//!   aileron alone therefore rolls right, of the right aileron alone rolls left by the same amount; each
//!   half carries half of `C_l_delta_a`, `C_n_delta_a` and `C_Y_delta_a`;
//! - elevator `delta_e = (delta_e_left + delta_e_right) / 2` in lift, drag and pitching moment: positive
//!   `delta_e` pitches nose down (`C_m_delta_e = -0.5`);
//! - elevator difference `delta_e_diff = (delta_e_left - delta_e_right) / 2` adds a rolling moment
//!   `C_l_delta_e_diff delta_e_diff`, so that a left- and a right-elevator fault are distinguishable (with
//!   only the mean deflection they would be indistinguishable to any observer). Estimate from the tail
//!   geometry: the elevator pitching moment is the tail lift times the tail arm `l_t`, so one tail half
//!   deflected by `delta` produces a tail lift `1/2 rho Va^2 S c |C_m_delta_e| (delta / 2) / l_t` acting at
//!   the half-tail's spanwise centroid `y_t`, i.e. `C_l_delta_e_diff = |C_m_delta_e| (c / b) (y_t / l_t)`.
//!   With `l_t = 1.0 m` and a horizontal tail of span 0.46 m (tail volume `S_t l_t / (S c) ~ 0.5`, tail
//!   aspect ratio ~4), `y_t = 0.46 / 4 = 0.115 m`, giving `C_l_delta_e_diff = 0.5 * 0.18994 / 2.8956 *
//!   0.115 = 0.00377` (about 1/21 of `C_l_delta_a`). Sign: an upward tail lift on the left half rolls
//!   right, so a positive (trailing-edge-down) left elevator rolls right, like the left aileron;
//! - aileron common deflection `delta_a_sym = (delta_a_left + delta_a_right) / 2`: the book's ailerons
//!   only ever move antisymmetrically, so it has no term for it, but with independent halves a left
//!   aileron at -8 deg and a right aileron at +8 deg would otherwise be the same airframe to any
//!   observer. Each half is a plain flap on its wing: lift `C_L_delta_a_sym delta_a_sym` with
//!   `C_L_delta_a_sym = C_l_delta_a / (y_a / b) = 0.08 / 0.35 = 0.229` (the lift that, at the aileron's
//!   spanwise centroid `y_a = 0.35 b`, gives the book's rolling derivative), and a nose-down pitching
//!   moment `C_m_delta_a_sym = -0.25 C_L_delta_a_sym = -0.057` (a trailing-edge flap's lift acts about
//!   a quarter chord behind the CG); the drag change is neglected;
//! - rudder `delta_r` as the book: positive `delta_r` yaws nose left (`C_n_delta_r = -0.032 < 0`).
//!
//! The table's `C_L_delta_e = -0.36` and `C_Y_delta_r = -0.17` have signs that disagree with the
//! trailing-edge-down / trailing-edge-left conventions implied by `C_m_delta_e < 0`, `C_l_delta_r > 0` and
//! `C_n_delta_r < 0`; they are kept as published, as is `C_n_delta_a = +0.06` (proverse yaw).
//!
//! # Reduced model (filter state `[p, q, r, alpha, beta]`)
//! [`reduced_derivatives`] takes airspeed, roll and pitch as known inputs and assumes zero wind. It
//! rebuilds `u = Va cos(alpha) cos(beta)`, `v = Va sin(beta)`, `w = Va sin(alpha) cos(beta)`, evaluates the
//! same forces and moments (gravity through `phi`, `theta`), and returns `pdot, qdot, rdot` (the full
//! model's equations), `alpha_dot = (u wdot - w udot) / (u^2 + w^2)` and `beta_dot = (Va vdot - v Va_dot)
//! / (Va^2 cos(beta))` with `Va_dot = (u udot + v vdot + w wdot) / Va` computed from the same force
//! balance. At an instant with exact `Va`, `phi`, `theta` and no wind these are exact; the approximation
//! when it is integrated is that `Va`, `phi`, `theta` are held over a filter step (they are not filter
//! states: `dVa/dt` is used only inside `beta_dot`, never integrated).
//!
//! # Actuators and autopilot
//! [`Actuators`]: each surface follows its command through a first-order lag (default 0.05 s, discretised
//! exactly for commands held over a step) and is limited to +/-25 deg. [`Autopilot`]: successive loop
//! closure (Beard & McLain ch. 6), see [`AutopilotGains`] for the loops, gains and how they were chosen.
#![allow(non_snake_case)]

use crate::dual::Real;
use crate::kinematics::{Attitude, body_from_ned};
use nalgebra::{Matrix3, SVector, Vector3};

/// Airspeeds (m/s, inclusive) inside the flight envelope the models are valid for; a flight outside it stops with its reason.
pub const ENVELOPE_AIRSPEED_MPS: std::ops::RangeInclusive<f64> = 5.0..=80.0;
/// Largest |angle of attack| (deg) inside the envelope.
pub const ENVELOPE_MAX_ALPHA_DEG: f64 = 45.0;

/// Number of independent control surfaces.
pub const SURFACES: usize = 5;
/// Surface order in every `[f64; 5]` of this module.
pub const SURFACE_NAMES: [&str; 5] = ["aileron_left", "aileron_right", "elevator_left", "elevator_right", "rudder"];
/// `[pn, pe, pd (m), u, v, w (m/s), phi, theta, psi (rad), p, q, r (rad/s)]`.
pub type State = SVector<f64, 12>;
/// `[p, q, r (rad/s), alpha, beta (rad)]`: the reduced model's state.
pub type ReducedState = SVector<f64, 5>;

/// Aerosonde airframe (Beard & McLain 2012, Appendix E) plus the split-elevator rolling derivative.
/// Aerodynamic coefficients are dimensionless, per rad for angle derivatives; rate derivatives use the
/// book's normalisation (`b p / (2 Va)`, `c q / (2 Va)`, `b r / (2 Va)`).
#[derive(Debug, Clone, PartialEq)]
pub struct AerosondeParams {
    pub mass_kg: f64,
    pub Jx_kgm2: f64,
    pub Jy_kgm2: f64,
    pub Jz_kgm2: f64,
    pub Jxz_kgm2: f64,
    /// Wing area S (m^2).
    pub S_wing_m2: f64,
    /// Wing span b (m).
    pub b_m: f64,
    /// Mean aerodynamic chord c (m).
    pub c_m: f64,
    pub rho_kgpm3: f64,
    pub gravity_mps2: f64,
    /// Oswald efficiency factor e.
    pub e_oswald: f64,
    /// Propeller disc area S_prop (m^2).
    pub S_prop_m2: f64,
    pub C_prop: f64,
    /// Motor constant: `k_motor delta_t` is the propeller slipstream speed (m/s).
    pub k_motor_mps: f64,
    /// Propeller torque constant k_T_P (N m s^2 / rad^2).
    pub k_T_P: f64,
    /// Propeller speed constant k_Omega (rad/s at full throttle).
    pub k_Omega_radps: f64,
    /// Sigmoid blending rate M (1/rad).
    pub M_blend: f64,
    /// Stall angle alpha0 of the sigmoid (rad).
    pub alpha0_rad: f64,
    /// Table value; not used by this model.
    pub epsilon: f64,
    pub C_L_0: f64,
    pub C_L_alpha: f64,
    pub C_L_q: f64,
    pub C_L_delta_e: f64,
    /// Linear drag model only; not used (the blended model uses `C_D_p`).
    pub C_D_0: f64,
    /// Linear drag model only; not used (the blended model uses `C_D_p`).
    pub C_D_alpha: f64,
    /// Parasitic drag of the parabolic drag polar.
    pub C_D_p: f64,
    pub C_D_q: f64,
    pub C_D_delta_e: f64,
    pub C_m_0: f64,
    pub C_m_alpha: f64,
    pub C_m_q: f64,
    pub C_m_delta_e: f64,
    pub C_Y_0: f64,
    pub C_Y_beta: f64,
    pub C_Y_p: f64,
    pub C_Y_r: f64,
    pub C_Y_delta_a: f64,
    pub C_Y_delta_r: f64,
    /// Rolling moment coefficients (the book's `C_ell_*`).
    pub C_l_0: f64,
    pub C_l_beta: f64,
    pub C_l_p: f64,
    pub C_l_r: f64,
    pub C_l_delta_a: f64,
    pub C_l_delta_r: f64,
    /// Rolling moment per rad of `(delta_e_left - delta_e_right) / 2` (not in the book; see module docs).
    pub C_l_delta_e_diff: f64,
    /// Lift and pitching moment per rad of the ailerons' common deflection `(delta_a_left +
    /// delta_a_right) / 2` (not in the book; see module docs).
    pub C_L_delta_a_sym: f64,
    pub C_m_delta_a_sym: f64,
    pub C_n_0: f64,
    pub C_n_beta: f64,
    pub C_n_p: f64,
    pub C_n_r: f64,
    pub C_n_delta_a: f64,
    pub C_n_delta_r: f64,
}

/// Spanwise centroid of an aileron as a fraction of the span, assumed for
/// [`AerosondeParams::C_L_delta_a_sym`].
pub const AILERON_CENTROID_SPAN_FRACTION: f64 = 0.35;

/// Horizontal-tail arm (m) behind the CG assumed for [`AerosondeParams::C_l_delta_e_diff`].
pub const TAIL_ARM_M: f64 = 1.0;
/// Spanwise centroid (m) of one horizontal-tail half assumed for [`AerosondeParams::C_l_delta_e_diff`].
pub const TAIL_HALF_CENTROID_M: f64 = 0.115;

impl Default for AerosondeParams {
    fn default() -> Self {
        let (b_m, c_m, C_m_delta_e, C_l_delta_a) = (2.8956, 0.18994, -0.5, 0.08);
        Self {
            mass_kg: 13.5,
            Jx_kgm2: 0.8244,
            Jy_kgm2: 1.135,
            Jz_kgm2: 1.759,
            Jxz_kgm2: 0.1204,
            S_wing_m2: 0.55,
            b_m,
            c_m,
            rho_kgpm3: 1.2682,
            gravity_mps2: 9.81,
            e_oswald: 0.9,
            S_prop_m2: 0.2027,
            C_prop: 1.0,
            k_motor_mps: 80.0,
            k_T_P: 0.0,
            k_Omega_radps: 0.0,
            M_blend: 50.0,
            alpha0_rad: 0.4712,
            epsilon: 0.1592,
            C_L_0: 0.28,
            C_L_alpha: 3.45,
            C_L_q: 0.0,
            C_L_delta_e: -0.36,
            C_D_0: 0.03,
            C_D_alpha: 0.30,
            C_D_p: 0.0437,
            C_D_q: 0.0,
            C_D_delta_e: 0.0,
            C_m_0: -0.02338,
            C_m_alpha: -0.38,
            C_m_q: -3.6,
            C_m_delta_e,
            C_Y_0: 0.0,
            C_Y_beta: -0.98,
            C_Y_p: 0.0,
            C_Y_r: 0.0,
            C_Y_delta_a: 0.0,
            C_Y_delta_r: -0.17,
            C_l_0: 0.0,
            C_l_beta: -0.12,
            C_l_p: -0.26,
            C_l_r: 0.14,
            C_l_delta_a,
            C_l_delta_r: 0.105,
            C_l_delta_e_diff: C_m_delta_e.abs() * (c_m / b_m) * (TAIL_HALF_CENTROID_M / TAIL_ARM_M),
            C_L_delta_a_sym: C_l_delta_a / AILERON_CENTROID_SPAN_FRACTION,
            C_m_delta_a_sym: -0.25 * C_l_delta_a / AILERON_CENTROID_SPAN_FRACTION,
            C_n_0: 0.0,
            C_n_beta: 0.25,
            C_n_p: 0.022,
            C_n_r: -0.35,
            C_n_delta_a: 0.06,
            C_n_delta_r: -0.032,
        }
    }
}

/// Coefficient names accepted by [`AerosondeParams::scaled`]: every coefficient that enters the model.
pub const SCALABLE_COEFFICIENTS: [&str; 33] = [
    "C_L_0",
    "C_L_alpha",
    "C_L_q",
    "C_L_delta_e",
    "C_D_p",
    "C_D_q",
    "C_D_delta_e",
    "C_m_0",
    "C_m_alpha",
    "C_m_q",
    "C_m_delta_e",
    "C_Y_0",
    "C_Y_beta",
    "C_Y_p",
    "C_Y_r",
    "C_Y_delta_a",
    "C_Y_delta_r",
    "C_l_0",
    "C_l_beta",
    "C_l_p",
    "C_l_r",
    "C_l_delta_a",
    "C_l_delta_r",
    "C_l_delta_e_diff",
    "C_L_delta_a_sym",
    "C_m_delta_a_sym",
    "C_n_0",
    "C_n_beta",
    "C_n_p",
    "C_n_r",
    "C_n_delta_a",
    "C_n_delta_r",
    "C_prop",
];

/// Terms of the split-surface model derived from a book coefficient (module docs): `(parent, derived)`.
/// [`AerosondeParams::scaled`] scales them with their parent.
pub const DERIVED_COEFFICIENTS: [(&str, &str); 3] =
    [("C_l_delta_a", "C_L_delta_a_sym"), ("C_l_delta_a", "C_m_delta_a_sym"), ("C_m_delta_e", "C_l_delta_e_diff")];

impl AerosondeParams {
    fn coefficient_mut(&mut self, name: &str) -> Option<&mut f64> {
        Some(match name {
            "C_L_0" => &mut self.C_L_0,
            "C_L_alpha" => &mut self.C_L_alpha,
            "C_L_q" => &mut self.C_L_q,
            "C_L_delta_e" => &mut self.C_L_delta_e,
            "C_D_p" => &mut self.C_D_p,
            "C_D_q" => &mut self.C_D_q,
            "C_D_delta_e" => &mut self.C_D_delta_e,
            "C_m_0" => &mut self.C_m_0,
            "C_m_alpha" => &mut self.C_m_alpha,
            "C_m_q" => &mut self.C_m_q,
            "C_m_delta_e" => &mut self.C_m_delta_e,
            "C_Y_0" => &mut self.C_Y_0,
            "C_Y_beta" => &mut self.C_Y_beta,
            "C_Y_p" => &mut self.C_Y_p,
            "C_Y_r" => &mut self.C_Y_r,
            "C_Y_delta_a" => &mut self.C_Y_delta_a,
            "C_Y_delta_r" => &mut self.C_Y_delta_r,
            "C_l_0" => &mut self.C_l_0,
            "C_l_beta" => &mut self.C_l_beta,
            "C_l_p" => &mut self.C_l_p,
            "C_l_r" => &mut self.C_l_r,
            "C_l_delta_a" => &mut self.C_l_delta_a,
            "C_l_delta_r" => &mut self.C_l_delta_r,
            "C_l_delta_e_diff" => &mut self.C_l_delta_e_diff,
            "C_L_delta_a_sym" => &mut self.C_L_delta_a_sym,
            "C_m_delta_a_sym" => &mut self.C_m_delta_a_sym,
            "C_n_0" => &mut self.C_n_0,
            "C_n_beta" => &mut self.C_n_beta,
            "C_n_p" => &mut self.C_n_p,
            "C_n_r" => &mut self.C_n_r,
            "C_n_delta_a" => &mut self.C_n_delta_a,
            "C_n_delta_r" => &mut self.C_n_delta_r,
            "C_prop" => &mut self.C_prop,
            _ => return None,
        })
    }

    /// The same airframe with aerodynamic derivatives scaled: used for model-parameter errors. `name` is a field
    /// name like "C_m_delta_e" (one of [`SCALABLE_COEFFICIENTS`]); returns Err(String listing allowed names) for an
    /// unknown name or a non-finite factor. Scaling a book coefficient scales the terms derived from it
    /// ([`DERIVED_COEFFICIENTS`]) too, so a model 20 % off on `C_l_delta_a` is 20 % off on the aileron halves'
    /// common lift and pitch as well; naming a derived term scales that term alone.
    pub fn scaled(&self, name: &str, factor: f64) -> Result<Self, String> {
        if !factor.is_finite() {
            return Err(format!("scale factor for {name} must be finite, got {factor}"));
        }
        let mut out = self.clone();
        let Some(c) = out.coefficient_mut(name) else {
            return Err(format!(
                "unknown aerodynamic coefficient {name:?}; allowed: {}",
                SCALABLE_COEFFICIENTS.join(", ")
            ));
        };
        *c *= factor;
        for (parent, derived) in DERIVED_COEFFICIENTS {
            if parent == name {
                // C_l_delta_e_diff is built from |C_m_delta_e|; the aileron terms from C_l_delta_a itself.
                let by = if derived == "C_l_delta_e_diff" { factor.abs() } else { factor };
                *out.coefficient_mut(derived).expect("derived names are scalable") *= by;
            }
        }
        Ok(out)
    }

    /// The book's inertia combinations Gamma_1..Gamma_8 (chapter 3), index 0..7. A model evaluated
    /// many times on one airframe computes them once and passes them on (8 divisions).
    pub fn gammas(&self) -> [f64; 8] {
        let (jx, jy, jz, jxz) = (self.Jx_kgm2, self.Jy_kgm2, self.Jz_kgm2, self.Jxz_kgm2);
        let g = jx * jz - jxz * jxz;
        [
            jxz * (jx - jy + jz) / g,
            (jz * (jz - jy) + jxz * jxz) / g,
            jz / g,
            jxz / g,
            (jz - jx) / jy,
            jxz / jy,
            ((jx - jy) * jx + jxz * jxz) / g,
            jx / g,
        ]
    }
}

/// The book's effective deflections formed from the five surfaces (rad); see the module docs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EffectiveDeflections<T = f64> {
    /// `(left - right) / 2` of the ailerons.
    pub aileron_rad: T,
    /// `(left + right) / 2` of the ailerons.
    pub aileron_sym_rad: T,
    /// `(left + right) / 2` of the elevators.
    pub elevator_rad: T,
    /// `(left - right) / 2` of the elevators.
    pub elevator_diff_rad: T,
    pub rudder_rad: T,
}

/// Mixes the five surfaces into the book's `delta_a`, `delta_e`, the elevator difference and `delta_r`.
pub fn effective_deflections<T: Real>(surfaces_rad: &[T; 5]) -> EffectiveDeflections<T> {
    let s = surfaces_rad;
    EffectiveDeflections {
        aileron_rad: (s[0] - s[1]) * 0.5,
        aileron_sym_rad: (s[0] + s[1]) * 0.5,
        elevator_rad: (s[2] + s[3]) * 0.5,
        elevator_diff_rad: (s[2] - s[3]) * 0.5,
        rudder_rad: s[4],
    }
}

/// Aerodynamic and propulsive forces (N) and moments (N m) in body axes, gravity excluded:
/// `[fx, fy, fz, l, m, n]`.
#[allow(clippy::too_many_arguments)] // the model's inputs as the book names them; the Jacobian duals some
fn aero_propulsion<T: Real>(
    p: &AerosondeParams,
    va: f64,
    alpha: T,
    alpha_sin_cos: (T, T),
    beta: T,
    rates: [T; 3],
    surfaces_rad: &[T; 5],
    throttle: f64,
) -> [T; 6] {
    let d = effective_deflections(surfaces_rad);
    let [pr, qr, rr] = rates;
    let qbar = 0.5 * p.rho_kgpm3 * va * va;
    // Nondimensional rates; at zero airspeed the dynamic pressure is zero anyway.
    let (p_hat, q_hat, r_hat) = if va > 1e-9 {
        (pr * p.b_m / (2.0 * va), qr * p.c_m / (2.0 * va), rr * p.b_m / (2.0 * va))
    } else {
        (T::cst(0.0), T::cst(0.0), T::cst(0.0))
    };
    let em = ((alpha - p.alpha0_rad) * -p.M_blend).exp();
    let ep = ((alpha + p.alpha0_rad) * p.M_blend).exp();
    let sigma = (T::cst(1.0) + em + ep) / ((T::cst(1.0) + em) * (T::cst(1.0) + ep));
    let (sa, ca) = alpha_sin_cos;
    let cl_lin = T::cst(p.C_L_0) + alpha * p.C_L_alpha;
    let c_l = (T::cst(1.0) - sigma) * cl_lin + sigma * 2.0 * alpha.re().signum() * sa * sa * ca;
    let aspect_ratio = p.b_m * p.b_m / p.S_wing_m2;
    let c_d = T::cst(p.C_D_p) + cl_lin * cl_lin / (std::f64::consts::PI * p.e_oswald * aspect_ratio);
    let cx = -c_d * ca + c_l * sa;
    let cx_q = ca * -p.C_D_q + sa * p.C_L_q;
    let cx_de = ca * -p.C_D_delta_e + sa * p.C_L_delta_e;
    let cx_as = sa * p.C_L_delta_a_sym;
    let cz = -c_d * sa - c_l * ca;
    let cz_q = sa * -p.C_D_q - ca * p.C_L_q;
    let cz_de = sa * -p.C_D_delta_e - ca * p.C_L_delta_e;
    let cz_as = ca * -p.C_L_delta_a_sym;
    let qs = qbar * p.S_wing_m2;
    let slip = p.k_motor_mps * throttle;
    let thrust = 0.5 * p.rho_kgpm3 * p.S_prop_m2 * p.C_prop * (slip * slip - va * va);
    let fx = (cx + cx_q * q_hat + cx_de * d.elevator_rad + cx_as * d.aileron_sym_rad) * qs + thrust;
    // The lateral-directional coefficients share their form: `C_0 + C_beta beta + C_p p^ + C_r r^ +
    // C_da delta_a + C_dr delta_r` (summed in this order).
    let lateral = |c: [f64; 6]| {
        T::cst(c[0]) + beta * c[1] + p_hat * c[2] + r_hat * c[3] + d.aileron_rad * c[4] + d.rudder_rad * c[5]
    };
    let fy = lateral([p.C_Y_0, p.C_Y_beta, p.C_Y_p, p.C_Y_r, p.C_Y_delta_a, p.C_Y_delta_r]) * qs;
    let fz = (cz + cz_q * q_hat + cz_de * d.elevator_rad + cz_as * d.aileron_sym_rad) * qs;
    let omega = p.k_Omega_radps * throttle;
    let l = (lateral([p.C_l_0, p.C_l_beta, p.C_l_p, p.C_l_r, p.C_l_delta_a, p.C_l_delta_r])
        + d.elevator_diff_rad * p.C_l_delta_e_diff)
        * (qs * p.b_m)
        - p.k_T_P * omega * omega;
    let m = (T::cst(p.C_m_0)
        + alpha * p.C_m_alpha
        + q_hat * p.C_m_q
        + d.elevator_rad * p.C_m_delta_e
        + d.aileron_sym_rad * p.C_m_delta_a_sym)
        * (qs * p.c_m);
    let n = lateral([p.C_n_0, p.C_n_beta, p.C_n_p, p.C_n_r, p.C_n_delta_a, p.C_n_delta_r]) * (qs * p.b_m);
    [fx, fy, fz, l, m, n]
}

/// The weight (N) of `p`'s aircraft in body axes at `attitude`: `m g [-sin(theta), cos(theta) sin(phi),
/// cos(theta) cos(phi)]`.
fn weight_in_body(p: &AerosondeParams, attitude: &Attitude) -> [f64; 3] {
    let [x, y, z] = attitude.gravity_terms(p.mass_kg * p.gravity_mps2);
    [-x, y, z]
}

/// Body accelerations `[udot, vdot, wdot, pdot, qdot, rdot]` from velocities, the weight in body axes,
/// rates, and the air data the forces depend on (`alpha` with its sine and cosine, which every caller
/// has already): the shared kernel of the full and the reduced model.
#[allow(clippy::too_many_arguments)]
fn body_accelerations<T: Real>(
    p: &AerosondeParams,
    g: &[f64; 8],
    uvw: [T; 3],
    attitude: &Attitude,
    rates: [T; 3],
    air: (f64, T, (T, T), T),
    surfaces_rad: &[T; 5],
    throttle: f64,
) -> [T; 6] {
    let (va, alpha, alpha_sin_cos, beta) = air;
    let [fx, fy, fz, l, m, n] = aero_propulsion(p, va, alpha, alpha_sin_cos, beta, rates, surfaces_rad, throttle);
    let [u, v, w] = uvw;
    let [pr, qr, rr] = rates;
    let weight_body_n = weight_in_body(p, attitude);
    let fx = fx + weight_body_n[0];
    let fy = fy + weight_body_n[1];
    let fz = fz + weight_body_n[2];
    [
        rr * v - qr * w + fx / p.mass_kg,
        pr * w - rr * u + fy / p.mass_kg,
        qr * u - pr * v + fz / p.mass_kg,
        pr * g[0] * qr - qr * g[1] * rr + l * g[2] + n * g[3],
        pr * g[4] * rr - (pr * pr - rr * rr) * g[5] + m / p.Jy_kgm2,
        pr * g[6] * qr - qr * g[0] * rr + l * g[3] + n * g[7],
    ]
}

/// Airspeed (m/s), angle of attack and sideslip (rad) relative to the air mass.
pub fn air_data(x: &State, wind_ned_mps: &Vector3<f64>) -> (f64, f64, f64) {
    air_data_rotated(x, &body_from_ned(x[6], x[7], x[8]).transpose(), wind_ned_mps)
}

/// [`air_data`] with the state's body-to-NED rotation already at hand.
fn air_data_rotated(x: &State, body_to_ned: &Matrix3<f64>, wind_ned_mps: &Vector3<f64>) -> (f64, f64, f64) {
    let wind_body = body_to_ned.transpose() * wind_ned_mps;
    let (ur, vr, wr) = (x[3] - wind_body[0], x[4] - wind_body[1], x[5] - wind_body[2]);
    let va = (ur * ur + vr * vr + wr * wr).sqrt();
    let alpha = wr.atan2(ur);
    let beta = if va > 0.0 { (vr / va).clamp(-1.0, 1.0).asin() } else { 0.0 };
    (va, alpha, beta)
}

/// Specific force (m/s^2, body axes): what ideal accelerometers at the CG measure, the aerodynamic and
/// propulsive force over the mass (gravity excluded), with the wind the air data see.
pub fn specific_force(
    p: &AerosondeParams,
    x: &State,
    surfaces_rad: &[f64; 5],
    throttle: f64,
    wind_ned_mps: &Vector3<f64>,
) -> Vector3<f64> {
    let (va, alpha, beta) = air_data(x, wind_ned_mps);
    let f = aero_propulsion(p, va, alpha, alpha.sin_cos(), beta, [x[9], x[10], x[11]], surfaces_rad, throttle);
    Vector3::new(f[0], f[1], f[2]) / p.mass_kg
}

/// dx/dt of the 12-state rigid body, surfaces in rad (five), throttle in `[0, 1]`, steady wind in NED m/s.
pub fn derivatives(
    p: &AerosondeParams,
    x: &State,
    surfaces_rad: &[f64; 5],
    throttle: f64,
    wind_ned_mps: &Vector3<f64>,
) -> State {
    let (phi, theta, psi) = (x[6], x[7], x[8]);
    let uvw = [x[3], x[4], x[5]];
    let rates = [x[9], x[10], x[11]];
    let rotation = body_from_ned(phi, theta, psi).transpose();
    let pos_dot = rotation * Vector3::new(uvw[0], uvw[1], uvw[2]);
    let (va, alpha, beta) = air_data_rotated(x, &rotation, wind_ned_mps);
    let air = (va, alpha, alpha.sin_cos(), beta);
    let attitude = Attitude::new(phi, theta);
    let acc = body_accelerations(p, &p.gammas(), uvw, &attitude, rates, air, surfaces_rad, throttle);
    let [pr, qr, rr] = rates;
    let (sf, cf) = attitude.sin_cos_roll;
    let (tt, ct) = (theta.tan(), theta.cos());
    State::from_column_slice(&[
        pos_dot[0],
        pos_dot[1],
        pos_dot[2],
        acc[0],
        acc[1],
        acc[2],
        pr + (qr * sf + rr * cf) * tt,
        qr * cf - rr * sf,
        (qr * sf + rr * cf) / ct,
        acc[3],
        acc[4],
        acc[5],
    ])
}

/// One RK4 step of dt_s with inputs held.
pub fn step_rk4(
    p: &AerosondeParams,
    x: &State,
    surfaces_rad: &[f64; 5],
    throttle: f64,
    wind_ned_mps: &Vector3<f64>,
    dt_s: f64,
) -> State {
    let f = |y: &State| derivatives(p, y, surfaces_rad, throttle, wind_ned_mps);
    let k1 = f(x);
    let k2 = f(&(x + k1 * (0.5 * dt_s)));
    let k3 = f(&(x + k2 * (0.5 * dt_s)));
    let k4 = f(&(x + k3 * dt_s));
    x + (k1 + k2 * 2.0 + k3 * 2.0 + k4) * (dt_s / 6.0)
}

/// Wings-level trim state at airspeed `va`, altitude `h`, `theta = alpha` (flight-path angle zero), `psi = 0`.
fn level_state(va: f64, altitude_m: f64, alpha: f64) -> State {
    let mut x = State::zeros();
    x[2] = -altitude_m;
    x[3] = va * alpha.cos();
    x[5] = va * alpha.sin();
    x[7] = alpha;
    x
}

/// Straight and level trim at airspeed va_mps and altitude altitude_m (Newton on alpha, delta_e, throttle;
/// ailerons/rudder zero): returns the state, surfaces and throttle; Err if it does not converge or throttle
/// leaves `[0, 1]`.
///
/// Newton iterates on `z = [alpha, delta_e, delta_t]` to zero `[udot, wdot, qdot]` (central-difference
/// Jacobian); both elevators take `delta_e`, `theta = alpha`, wings level, no wind, `psi = 0`. The lateral
/// equations balance by symmetry (`C_Y_0 = C_l_0 = C_n_0 = 0`, no propeller torque); the full derivative is
/// checked at the end, so a parameter set that would need lateral trim is rejected. Also rejected: an
/// angle of attack beyond the sigmoid's stall angle `alpha0`.
pub fn trim(p: &AerosondeParams, va_mps: f64, altitude_m: f64) -> Result<(State, [f64; 5], f64), String> {
    if !(va_mps.is_finite() && va_mps > 0.0 && altitude_m.is_finite()) {
        return Err(format!("trim needs a positive finite airspeed and a finite altitude, got {va_mps}, {altitude_m}"));
    }
    let zero_wind = Vector3::zeros();
    let build = |z: &Vector3<f64>| (level_state(va_mps, altitude_m, z[0]), [0.0, 0.0, z[1], z[1], 0.0], z[2]);
    let residual = |z: &Vector3<f64>| {
        let (x, s, t) = build(z);
        let d = derivatives(p, &x, &s, t, &zero_wind);
        Vector3::new(d[3], d[5], d[10])
    };
    let mut z = Vector3::new(0.05, 0.0, 0.5);
    let mut converged = false;
    for _ in 0..100 {
        let f = residual(&z);
        if !f.iter().all(|v| v.is_finite()) {
            return Err(format!("trim diverged at Va = {va_mps} m/s (non-finite residual)"));
        }
        if f.amax() < 1e-12 {
            converged = true;
            break;
        }
        let mut jac = Matrix3::zeros();
        for j in 0..3 {
            let h = 1e-7;
            let mut zp = z;
            let mut zm = z;
            zp[j] += h;
            zm[j] -= h;
            jac.set_column(j, &((residual(&zp) - residual(&zm)) / (2.0 * h)));
        }
        let Some(dz) = jac.lu().solve(&(-f)) else {
            return Err(format!("trim Jacobian singular at Va = {va_mps} m/s"));
        };
        z += dz;
        if dz.amax() < 1e-15 {
            converged = residual(&z).amax() < 1e-10;
            break;
        }
    }
    if !converged {
        return Err(format!("trim did not converge at Va = {va_mps} m/s (residual {:e})", residual(&z).amax()));
    }
    let (x, s, t) = build(&z);
    if !(0.0..=1.0).contains(&t) {
        return Err(format!("trim throttle {t:.4} outside [0, 1] at Va = {va_mps} m/s"));
    }
    if z[0].abs() > p.alpha0_rad {
        return Err(format!("trim angle of attack {:.4} rad beyond stall at Va = {va_mps} m/s", z[0]));
    }
    let d = derivatives(p, &x, &s, t, &zero_wind);
    let worst = [3, 4, 5, 9, 10, 11].iter().map(|&i| d[i].abs()).fold(0.0, f64::max);
    if worst > 1e-9 {
        return Err(format!("no symmetric trim at Va = {va_mps} m/s: residual acceleration {worst:e}"));
    }
    Ok((x, s, t))
}

/// Known inputs of the reduced model (treated as exogenous by the filter). The attitude's sines and
/// cosines are computed once per sample, for every filter of every bank.
#[derive(Debug, Clone, Copy)]
pub struct ReducedInputs {
    pub va_mps: f64,
    pub attitude: Attitude,
    pub throttle: f64,
}

impl ReducedInputs {
    pub fn new(va_mps: f64, phi_rad: f64, theta_rad: f64, throttle: f64) -> Self {
        ReducedInputs { va_mps, attitude: Attitude::new(phi_rad, theta_rad), throttle }
    }
}

/// The reduced model an estimator of `[p, q, r, alpha, beta]` uses (Ducard & Geering's filter state): the
/// time derivative of `x5` given airspeed, roll and pitch (known inputs), the surfaces and throttle, with
/// zero wind; see the module docs for the exact assumptions. With exact `Va`, `phi`, `theta` and no wind
/// the rows equal the full model's `pdot, qdot, rdot` and the true `alpha_dot`, `beta_dot`.
pub fn reduced_derivatives(
    p: &AerosondeParams,
    x5: &ReducedState,
    inputs: &ReducedInputs,
    surfaces_rad: &[f64; 5],
) -> ReducedState {
    let x = [x5[0], x5[1], x5[2], x5[3], x5[4]];
    ReducedState::from(reduced_derivatives_of(p, &x, inputs, surfaces_rad))
}

/// [`reduced_derivatives`] in any [`Real`]: on [`crate::dual::Dual`] numbers it gives the derivatives
/// and their exact Jacobian in one evaluation.
pub fn reduced_derivatives_of<T: Real>(
    p: &AerosondeParams,
    x5: &[T; 5],
    inputs: &ReducedInputs,
    surfaces_rad: &[T; 5],
) -> [T; 5] {
    reduced_derivatives_at(p, &p.gammas(), x5, inputs, surfaces_rad).0
}

/// The values inside one evaluation of the reduced model that its rate and surface columns of the
/// Jacobian need ([`reduced_rate_and_surface_columns`]).
#[derive(Debug, Clone, Copy)]
pub struct ReducedPoint {
    pub sin_cos_alpha: (f64, f64),
    /// Body velocities `[u, v, w]` (m/s).
    pub uvw: [f64; 3],
    /// `u^2 + w^2`.
    pub uw2: f64,
}

/// [`reduced_derivatives_of`] with the point it was evaluated at; `gammas` are `p.gammas()`.
pub fn reduced_derivatives_at<T: Real>(
    p: &AerosondeParams,
    gammas: &[f64; 8],
    x5: &[T; 5],
    inputs: &ReducedInputs,
    surfaces_rad: &[T; 5],
) -> ([T; 5], ReducedPoint) {
    let (alpha, beta) = (x5[3], x5[4]);
    let va = inputs.va_mps;
    let (sa, ca) = alpha.sin_cos();
    let (sb, cb) = beta.sin_cos();
    let (u, v, w) = (ca * va * cb, sb * va, sa * va * cb);
    let rates = [x5[0], x5[1], x5[2]];
    let acc = body_accelerations(
        p,
        gammas,
        [u, v, w],
        &inputs.attitude,
        rates,
        (va, alpha, (sa, ca), beta),
        surfaces_rad,
        inputs.throttle,
    );
    let (udot, vdot, wdot) = (acc[0], acc[1], acc[2]);
    let uw2 = u * u + w * w;
    let alpha_dot = (u * wdot - w * udot) / uw2;
    let va_dot = (u * udot + v * vdot + w * wdot) / va;
    let beta_dot = (vdot * va - v * va_dot) / (uw2.sqrt() * va);
    let point = ReducedPoint { sin_cos_alpha: (sa.re(), ca.re()), uvw: [u.re(), v.re(), w.re()], uw2: uw2.re() };
    ([acc[3], acc[4], acc[5], alpha_dot, beta_dot], point)
}

/// `d f / d p`, `d f / d q`, `d f / d r` and `d f / d s` of the reduced model (`f = [pdot, qdot, rdot,
/// alpha_dot, beta_dot]`, `s` the position of `surface`; zero without one) at `point`, written out
/// (`g`: `p.gammas()`).
///
/// The model is linear in the nondimensional rates and the deflections, and `u, v, w` do not depend
/// on either, so these columns are short sums of the coefficients (the Coriolis and gyroscopic terms
/// add the rates themselves); only alpha and beta need the chain through the aerodynamics, which dual
/// numbers give. Each entry is formed as dual numbers over all six inputs form it (the same products
/// in the same order, a quotient as a product with the reciprocal; the terms they add in exact zeros
/// left out), so the columns are theirs to the bit for finite values (tested in `stmmae`).
pub fn reduced_rate_and_surface_columns(
    p: &AerosondeParams,
    g: &[f64; 8],
    x5: &[f64; 5],
    inputs: &ReducedInputs,
    point: &ReducedPoint,
    surface: Option<usize>,
) -> [[f64; 5]; 4] {
    let va = inputs.va_mps;
    let qs = 0.5 * p.rho_kgpm3 * va * va * p.S_wing_m2;
    let (kb, kc) = if va > 1e-9 { (p.b_m / (2.0 * va), p.c_m / (2.0 * va)) } else { (0.0, 0.0) };
    let (sa, ca) = point.sin_cos_alpha;
    let cx_q = ca * -p.C_D_q + sa * p.C_L_q;
    let cz_q = sa * -p.C_D_q - ca * p.C_L_q;
    let (qsb, qsc) = (qs * p.b_m, qs * p.c_m);
    // Forces and moments per unit rate: [dfx, dfy, dfz, dl, dm, dn].
    let per_p = [0.0, p.C_Y_p * kb * qs, 0.0, p.C_l_p * kb * qsb, 0.0, p.C_n_p * kb * qsb];
    let per_q = [cx_q * kc * qs, 0.0, cz_q * kc * qs, 0.0, p.C_m_q * kc * qsc, 0.0];
    let per_r = [0.0, p.C_Y_r * kb * qs, 0.0, p.C_l_r * kb * qsb, 0.0, p.C_n_r * kb * qsb];
    let per_s = match surface {
        None => [0.0; 6],
        Some(i) => {
            let mut unit = [0.0; 5];
            unit[i] = 1.0;
            let d = effective_deflections(&unit);
            let cx_de = ca * -p.C_D_delta_e + sa * p.C_L_delta_e;
            let cz_de = sa * -p.C_D_delta_e - ca * p.C_L_delta_e;
            let (cx_as, cz_as) = (sa * p.C_L_delta_a_sym, ca * -p.C_L_delta_a_sym);
            [
                (cx_de * d.elevator_rad + cx_as * d.aileron_sym_rad) * qs,
                (p.C_Y_delta_a * d.aileron_rad + p.C_Y_delta_r * d.rudder_rad) * qs,
                (cz_de * d.elevator_rad + cz_as * d.aileron_sym_rad) * qs,
                (p.C_l_delta_a * d.aileron_rad
                    + p.C_l_delta_r * d.rudder_rad
                    + p.C_l_delta_e_diff * d.elevator_diff_rad)
                    * qsb,
                (p.C_m_delta_e * d.elevator_rad + p.C_m_delta_a_sym * d.aileron_sym_rad) * qsc,
                (p.C_n_delta_a * d.aileron_rad + p.C_n_delta_r * d.rudder_rad) * qsb,
            ]
        }
    };
    let [u, v, w] = point.uvw;
    let [pr, qr, rr] = [x5[0], x5[1], x5[2]];
    // The Coriolis (velocities) and gyroscopic (rates) terms' derivatives, [udot, vdot, wdot, pdot,
    // qdot, rdot] per rate; none per surface.
    let kinematic = [
        [0.0, w, -v, g[0] * qr, g[4] * rr - 2.0 * pr * g[5], g[6] * qr],
        [-w, 0.0, u, pr * g[0] - g[1] * rr, 0.0, pr * g[6] - g[0] * rr],
        [v, -u, 0.0, -qr * g[1], pr * g[4] + 2.0 * rr * g[5], -qr * g[0]],
        [0.0; 6],
    ];
    let column = |aero: &[f64; 6], kin: &[f64; 6]| {
        let udot = kin[0] + aero[0] / p.mass_kg;
        let vdot = kin[1] + aero[1] / p.mass_kg;
        let wdot = kin[2] + aero[2] / p.mass_kg;
        let pdot = kin[3] + aero[3] * g[2] + aero[5] * g[3];
        let qdot = kin[4] + aero[4] / p.Jy_kgm2;
        let rdot = kin[5] + aero[3] * g[3] + aero[5] * g[7];
        // A dual quotient by a dual without these inputs' derivatives multiplies by the reciprocal.
        let alpha_dot = (u * wdot - w * udot) * (1.0 / point.uw2);
        let va_dot = (u * udot + v * vdot + w * wdot) / va;
        let beta_dot = (vdot * va - v * va_dot) * (1.0 / (point.uw2.sqrt() * va));
        [pdot, qdot, rdot, alpha_dot, beta_dot]
    };
    [
        column(&per_p, &kinematic[0]),
        column(&per_q, &kinematic[1]),
        column(&per_r, &kinematic[2]),
        column(&per_s, &kinematic[3]),
    ]
}

/// Surface actuators: each position follows its command through a first-order lag with position limits.
///
/// `x(k+1) = x(k) + (1 - exp(-dt/tau)) (sat(c) - x(k))`, exact for a command held over the step (the command is
/// saturated to +/-`max_deflection_rad` first, so positions never leave the limits). Defaults: `tau = 0.05 s`
/// (a bandwidth of 20 rad/s, typical of small-UAV servos and well above the 7-8 rad/s roll and pitch loops),
/// limits +/-25 deg. `tau = 0` gives positions equal to the saturated commands.
#[derive(Debug, Clone)]
pub struct Actuators {
    pub time_constant_s: f64,
    pub max_deflection_rad: f64,
    positions: [f64; 5],
}

impl Actuators {
    pub const DEFAULT_TIME_CONSTANT_S: f64 = 0.05;
    pub const DEFAULT_MAX_DEFLECTION_RAD: f64 = 25.0 * std::f64::consts::PI / 180.0;

    /// Default lag and limits, starting at `initial_rad` (saturated).
    pub fn new(initial_rad: [f64; 5]) -> Self {
        Self::with_limits(initial_rad, Self::DEFAULT_TIME_CONSTANT_S, Self::DEFAULT_MAX_DEFLECTION_RAD)
    }

    pub fn with_limits(initial_rad: [f64; 5], time_constant_s: f64, max_deflection_rad: f64) -> Self {
        let positions = initial_rad.map(|v| v.clamp(-max_deflection_rad, max_deflection_rad));
        Self { time_constant_s, max_deflection_rad, positions }
    }

    /// Current surface positions (rad), order [`SURFACE_NAMES`].
    pub fn positions(&self) -> [f64; 5] {
        self.positions
    }

    /// Advances the positions by `dt_s` with the commands held; returns the new positions.
    pub fn step(&mut self, commands_rad: &[f64; 5], dt_s: f64) -> [f64; 5] {
        let gain = if self.time_constant_s > 0.0 { 1.0 - (-dt_s / self.time_constant_s).exp() } else { 1.0 };
        for (x, c) in self.positions.iter_mut().zip(commands_rad) {
            let target = c.clamp(-self.max_deflection_rad, self.max_deflection_rad);
            *x += gain * (target - *x);
        }
        self.positions
    }
}

/// Gains and limits of the successive-loop-closure autopilot (Beard & McLain ch. 6).
///
/// Loops (all errors are command minus measurement, angles in rad):
/// - roll -> ailerons: `delta_a = kp_roll e_phi + ki_roll int(e_phi) - kd_roll p`, applied antisymmetrically
///   (left = trim + delta_a, right = trim - delta_a), limited to +/-`max_deflection_rad`;
/// - altitude -> pitch command: `theta_c = theta_ff + kp_altitude e_h + ki_altitude int(e_h) - kd_altitude hdot`,
///   limited to +/-`max_pitch_cmd_rad`, where `theta_ff` is the pitch at engagement (bumpless transfer; the
///   trim pitch when engaged at trim) and `hdot` the climb rate;
/// - pitch -> both elevators: `delta_e = delta_e_trim - kp_pitch (theta_c - theta) + kd_pitch q` (negative
///   signs because positive elevator pitches nose down), limited to +/-`max_deflection_rad`;
/// - airspeed -> throttle: `delta_t = delta_t_trim + kp_airspeed e_V + ki_airspeed int(e_V)`, limited to [0, 1];
/// - sideslip -> rudder: `delta_r = delta_r_trim - kp_sideslip beta - ki_sideslip int(beta)` (positive rudder
///   yaws nose left, which raises beta; the book's side-force-only design has the opposite sign and
///   destabilises this airframe). The Dutch roll is well damped open loop, so no yaw damper is used.
///
/// Anti-windup: an integrator is frozen on a step where integrating would push a saturated output further
/// into its limit, and the roll and altitude integrators run only inside a band around the setpoint
/// (`roll_integrator_band_rad`, `altitude_integrator_band_m`), so a large step is flown on the PD terms
/// and the integrator only removes the residual offset.
///
/// How the defaults were chosen, at the 25 m/s, 100 m trim (alpha 4.72 deg, delta_e -6.26 deg, delta_t 0.334):
/// the book's transfer-function coefficients are `a_phi1 = 11.58`, `a_phi2 = 65.04`, `a_theta1 = 0.499`,
/// `a_theta2 = 13.86`, `a_theta3 = -18.24`, `a_V1 = 0.547`, `a_V2 = 40.65`. Pitch: `kp_pitch = 25 deg
/// elevator / 10 deg error = 2.5`, giving `omega_theta = sqrt(a_theta2 + kp |a_theta3|) = 7.7 rad/s`, and
/// `kd_pitch = (2 zeta omega - a_theta1) / |a_theta3| = 0.6` (zeta = 0.75). Roll: `kp_roll = 0.8` (omega =
/// 7.2 rad/s), `kd_roll = 0.12` (zeta = 1.35: the book's zeta = 0.9 value 0.02 left a 15 % overshoot from
/// the roll/sideslip coupling), `ki_roll = 0.3` inside 0.1 rad. Airspeed: `omega_V = 0.9 rad/s`, `ki_airspeed
/// = omega^2 / a_V2 = 0.02`, `kp_airspeed = 0.04` (zeta = 1.2). Altitude: the book's PI from `K_theta_DC`
/// overshot by 25 % (integrator windup during the climb), so a climb-rate term `kd_altitude = 0.06` rad per
/// m/s and an integrator band of 1 m were added, and `kp_altitude = 0.04` rad/m, `ki_altitude = 0.01` tuned by
/// simulation of the nonlinear model with actuators (100 Hz): a 5 m step overshoots by about 5 % and is within
/// 0.05 m after 20 s; a 2 m/s airspeed step is within 0.01 m/s after 10 s with under 1 % overshoot; a 20 deg
/// roll command is within 0.3 deg after 5 s with under 1 % overshoot. Sideslip: `kp_sideslip = 1.0`,
/// `ki_sideslip = 0.5`, chosen by simulation (steady sideslip in a 20 deg bank goes to zero).
#[derive(Debug, Clone, PartialEq)]
pub struct AutopilotGains {
    /// rad aileron per rad roll error.
    pub kp_roll: f64,
    /// rad aileron per rad s of integrated roll error.
    pub ki_roll: f64,
    /// rad aileron per rad/s roll rate.
    pub kd_roll: f64,
    /// The roll integrator runs only when |roll error| is below this (rad).
    pub roll_integrator_band_rad: f64,
    /// Roll commands are limited to +/- this (rad).
    pub max_roll_cmd_rad: f64,
    /// rad elevator per rad pitch error.
    pub kp_pitch: f64,
    /// rad elevator per rad/s pitch rate.
    pub kd_pitch: f64,
    /// rad pitch command per m altitude error.
    pub kp_altitude: f64,
    /// rad pitch command per m s of integrated altitude error.
    pub ki_altitude: f64,
    /// rad pitch command per m/s climb rate.
    pub kd_altitude: f64,
    /// The altitude integrator runs only when |altitude error| is below this (m).
    pub altitude_integrator_band_m: f64,
    /// Pitch commands are limited to +/- this (rad, absolute pitch).
    pub max_pitch_cmd_rad: f64,
    /// throttle per m/s airspeed error.
    pub kp_airspeed: f64,
    /// throttle per m of integrated airspeed error.
    pub ki_airspeed: f64,
    /// rad rudder per rad sideslip.
    pub kp_sideslip: f64,
    /// rad rudder per rad s of integrated sideslip.
    pub ki_sideslip: f64,
    /// Surface commands are limited to +/- this (rad).
    pub max_deflection_rad: f64,
}

impl Default for AutopilotGains {
    fn default() -> Self {
        let deg = std::f64::consts::PI / 180.0;
        Self {
            kp_roll: 0.8,
            ki_roll: 0.3,
            kd_roll: 0.12,
            roll_integrator_band_rad: 0.1,
            max_roll_cmd_rad: 45.0 * deg,
            kp_pitch: 2.5,
            kd_pitch: 0.6,
            kp_altitude: 0.04,
            ki_altitude: 0.01,
            kd_altitude: 0.06,
            altitude_integrator_band_m: 1.0,
            max_pitch_cmd_rad: 15.0 * deg,
            kp_airspeed: 0.04,
            ki_airspeed: 0.02,
            kp_sideslip: 1.0,
            ki_sideslip: 0.5,
            max_deflection_rad: 25.0 * deg,
        }
    }
}

/// Autopilot setpoints.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Setpoints {
    pub va_mps: f64,
    pub altitude_m: f64,
    pub roll_rad: f64,
}

/// PID autopilot holding airspeed, altitude and roll angle, with sideslip held at zero (see [`AutopilotGains`]).
#[derive(Debug, Clone)]
pub struct Autopilot {
    pub gains: AutopilotGains,
    trim_surfaces: [f64; 5],
    trim_throttle: f64,
    /// Pitch feedforward, latched on the first command (bumpless engagement).
    pitch_ff_rad: Option<f64>,
    int_roll: f64,
    int_altitude: f64,
    int_airspeed: f64,
    int_sideslip: f64,
}

/// PI(D) step with conditional-integration anti-windup: `base + kp e + ki int`, limited to `[lo, hi]`; the
/// integrator advances only when `|e| < band` and the advance would not push a saturated output further out.
#[allow(clippy::too_many_arguments)]
fn pi_step(integral: &mut f64, e: f64, dt_s: f64, kp: f64, ki: f64, base: f64, band: f64, lo: f64, hi: f64) -> f64 {
    let candidate = if e.abs() < band { *integral + e * dt_s } else { *integral };
    let u = base + kp * e + ki * candidate;
    let winding_up = (u > hi && ki * (candidate - *integral) > 0.0) || (u < lo && ki * (candidate - *integral) < 0.0);
    if !winding_up {
        *integral = candidate;
    }
    (base + kp * e + ki * *integral).clamp(lo, hi)
}

impl Autopilot {
    pub fn new(gains: AutopilotGains, trim_surfaces: [f64; 5], trim_throttle: f64) -> Self {
        Self {
            gains,
            trim_surfaces,
            trim_throttle,
            pitch_ff_rad: None,
            int_roll: 0.0,
            int_altitude: 0.0,
            int_airspeed: 0.0,
            int_sideslip: 0.0,
        }
    }

    /// Commands from measured/known quantities (pass the true state; noise is added elsewhere). Returns surfaces
    /// (rad) and throttle. Uses from `x`: altitude `-pd`, `u, v, w` (climb rate), `phi`, `theta`, `p`, `q`.
    pub fn command(
        &mut self,
        x: &State,
        va_mps: f64,
        alpha_rad: f64,
        beta_rad: f64,
        sp: &Setpoints,
        dt_s: f64,
    ) -> ([f64; 5], f64) {
        let _ = alpha_rad; // part of the measurement set; these loops do not use it
        let g = &self.gains;
        let (phi, theta) = (x[6], x[7]);
        let (pr, qr) = (x[9], x[10]);
        let (sf, cf) = phi.sin_cos();
        let (st, ct) = theta.sin_cos();
        let climb_rate = x[3] * st - x[4] * sf * ct - x[5] * cf * ct;
        let theta_ff = *self.pitch_ff_rad.get_or_insert(theta);
        let dmax = g.max_deflection_rad;

        // Altitude -> pitch command -> both elevators.
        let e_h = sp.altitude_m - (-x[2]);
        let theta_c = pi_step(
            &mut self.int_altitude,
            e_h,
            dt_s,
            g.kp_altitude,
            g.ki_altitude,
            theta_ff - g.kd_altitude * climb_rate,
            g.altitude_integrator_band_m,
            -g.max_pitch_cmd_rad,
            g.max_pitch_cmd_rad,
        );
        let d_elevator = -g.kp_pitch * (theta_c - theta) + g.kd_pitch * qr;

        // Roll -> antisymmetric ailerons.
        let phi_c = sp.roll_rad.clamp(-g.max_roll_cmd_rad, g.max_roll_cmd_rad);
        let d_aileron = pi_step(
            &mut self.int_roll,
            phi_c - phi,
            dt_s,
            g.kp_roll,
            g.ki_roll,
            -g.kd_roll * pr,
            g.roll_integrator_band_rad,
            -dmax,
            dmax,
        );

        // Sideslip -> rudder.
        let d_rudder = pi_step(
            &mut self.int_sideslip,
            -beta_rad,
            dt_s,
            g.kp_sideslip,
            g.ki_sideslip,
            0.0,
            f64::INFINITY,
            -dmax,
            dmax,
        );

        // Airspeed -> throttle.
        let throttle = pi_step(
            &mut self.int_airspeed,
            sp.va_mps - va_mps,
            dt_s,
            g.kp_airspeed,
            g.ki_airspeed,
            self.trim_throttle,
            f64::INFINITY,
            0.0,
            1.0,
        );

        let t = &self.trim_surfaces;
        let surfaces = [t[0] + d_aileron, t[1] - d_aileron, t[2] + d_elevator, t[3] + d_elevator, t[4] + d_rudder]
            .map(|v| v.clamp(-dmax, dmax));
        (surfaces, throttle)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const DEG: f64 = std::f64::consts::PI / 180.0;

    fn no_wind() -> Vector3<f64> {
        Vector3::zeros()
    }

    /// Angular accelerations `[pdot, qdot, rdot]` and `[udot, wdot]` at `x`.
    fn accel(p: &AerosondeParams, x: &State, s: &[f64; 5], t: f64) -> ([f64; 3], [f64; 2]) {
        let d = derivatives(p, x, s, t, &no_wind());
        ([d[9], d[10], d[11]], [d[3], d[5]])
    }

    struct Run {
        t: Vec<f64>,
        altitude: Vec<f64>,
        va: Vec<f64>,
        roll: Vec<f64>,
        beta: Vec<f64>,
    }

    /// Closed loop at 100 Hz from the 25 m/s, 100 m trim (optionally perturbed) with setpoints `sp(t)`.
    fn closed_loop(duration_s: f64, perturb: impl Fn(&mut State), sp: impl Fn(f64) -> Setpoints) -> Run {
        let p = AerosondeParams::default();
        let (mut x, s0, t0) = trim(&p, 25.0, 100.0).unwrap();
        perturb(&mut x);
        let dt = 0.01;
        let mut act = Actuators::new(s0);
        let mut ap = Autopilot::new(AutopilotGains::default(), s0, t0);
        let mut run = Run { t: vec![], altitude: vec![], va: vec![], roll: vec![], beta: vec![] };
        let steps = (duration_s / dt).round() as usize;
        for k in 0..steps {
            let t = k as f64 * dt;
            let (va, alpha, beta) = air_data(&x, &no_wind());
            let (cmd, throttle) = ap.command(&x, va, alpha, beta, &sp(t), dt);
            let pos = act.step(&cmd, dt);
            x = step_rk4(&p, &x, &pos, throttle, &no_wind(), dt);
            let (va, _, beta) = air_data(&x, &no_wind());
            run.t.push(t + dt);
            run.altitude.push(-x[2]);
            run.va.push(va);
            run.roll.push(x[6]);
            run.beta.push(beta);
        }
        run
    }

    fn at(run: &Run, series: &[f64], t: f64) -> f64 {
        let k = run.t.iter().position(|&s| s >= t - 1e-9).unwrap();
        series[k]
    }

    fn level(va: f64, h: f64, roll: f64) -> Setpoints {
        Setpoints { va_mps: va, altitude_m: h, roll_rad: roll }
    }

    #[test]
    fn trim_is_an_equilibrium_with_the_expected_values() {
        let p = AerosondeParams::default();
        // Values cross-checked with an independent Python transcription of the same equations.
        for (va, alpha, de, dt) in [(25.0, 0.082321, -0.109324, 0.333523), (35.0, 0.003490, -0.049413, 0.463821)] {
            let (x, s, t) = trim(&p, va, 100.0).unwrap();
            let d = derivatives(&p, &x, &s, t, &no_wind());
            for i in [3, 4, 5, 9, 10, 11] {
                assert!(d[i].abs() < 1e-8, "Va {va}: derivative {i} = {}", d[i]);
            }
            assert!(d[2].abs() < 1e-12, "pd_dot {}", d[2]);
            assert!((d[0] - va).abs() < 1e-9);
            assert!((x[7] - alpha).abs() < 2e-6, "alpha {}", x[7]);
            assert!((s[2] - de).abs() < 2e-6 && s[2] == s[3], "elevator {:?}", s);
            assert!((t - dt).abs() < 2e-6, "throttle {t}");
            assert_eq!([s[0], s[1], s[4]], [0.0; 3]);
            let (va_x, alpha_x, beta_x) = air_data(&x, &no_wind());
            assert!((va_x - va).abs() < 1e-12 && (alpha_x - x[7]).abs() < 1e-12 && beta_x == 0.0);
        }
        // 80 m/s needs more than full throttle: (80 delta_t)^2 - Va^2 < 0 at delta_t = 1.
        let err = trim(&p, 80.0, 100.0).unwrap_err();
        assert!(err.contains("throttle") || err.contains("converge"), "{err}");
    }

    #[test]
    fn air_data_subtracts_the_wind() {
        // Flying north at 25 m/s ground speed into a 5 m/s wind from the north: 30 m/s airspeed; a
        // crosswind from the west (air moving east) gives negative sideslip.
        let mut x = State::zeros();
        x[3] = 25.0;
        let (va, alpha, beta) = air_data(&x, &Vector3::new(-5.0, 0.0, 0.0));
        assert!((va - 30.0).abs() < 1e-12 && alpha.abs() < 1e-15 && beta.abs() < 1e-15);
        let (va, _, beta) = air_data(&x, &Vector3::new(0.0, 5.0, 0.0));
        assert!((va - 650f64.sqrt()).abs() < 1e-12);
        assert!((beta - (-5.0 / 650f64.sqrt()).asin()).abs() < 1e-12);
    }

    #[test]
    fn open_loop_from_trim_stays_put_and_closed_loop_holds_a_perturbation() {
        let p = AerosondeParams::default();
        let (x0, s, t) = trim(&p, 25.0, 100.0).unwrap();
        let run = |x0: State| {
            let mut x = x0;
            let mut worst = (0.0f64, 0.0f64, 0.0f64);
            for _ in 0..1000 {
                x = step_rk4(&p, &x, &s, t, &no_wind(), 0.01);
                let (va, _, _) = air_data(&x, &no_wind());
                worst = (worst.0.max((-x[2] - 100.0).abs()), worst.1.max((va - 25.0).abs()), worst.2.max(x[6].abs()));
            }
            (x, worst)
        };
        let (x, worst) = run(x0);
        assert!(worst.0 < 1e-8 && worst.1 < 1e-8 && worst.2 < 1e-8, "{worst:?}");
        assert!((x[0] - 250.0).abs() < 1e-6, "north {}", x[0]);
        // Open loop with a 0.05 rad/s pitch and roll rate kick: stable short period, small drift.
        let mut xp = x0;
        xp[9] = 0.05;
        xp[10] = 0.05;
        let (_, worst) = run(xp);
        assert!(worst.0 < 1.0 && worst.1 < 0.5 && worst.2 < 1.0 * DEG, "{worst:?}");
        assert!(worst.0 > 0.1, "the kick should disturb the altitude: {worst:?}");
        // Closed loop with 0.05 rad/s on all rates: within 0.5 m and 0.2 m/s over 60 s, back at the setpoint.
        let r = closed_loop(
            60.0,
            |x| {
                x[9] = 0.05;
                x[10] = 0.05;
                x[11] = 0.05
            },
            |_| level(25.0, 100.0, 0.0),
        );
        let dh = r.altitude.iter().map(|h| (h - 100.0).abs()).fold(0.0, f64::max);
        let dv = r.va.iter().map(|v| (v - 25.0).abs()).fold(0.0, f64::max);
        assert!(dh < 0.5 && dv < 0.2, "dh {dh} dv {dv}");
        assert!((r.altitude.last().unwrap() - 100.0).abs() < 1e-3 && r.roll.last().unwrap().abs() < 1e-4);
    }

    #[test]
    fn autopilot_altitude_step() {
        let r = closed_loop(40.0, |_| {}, |_| level(25.0, 105.0, 0.0));
        let peak = r.altitude.iter().cloned().fold(f64::MIN, f64::max);
        let overshoot = (peak - 105.0) / 5.0;
        assert!(overshoot < 0.5, "overshoot {overshoot}");
        assert!(overshoot < 0.10, "should be nearly non-oscillatory: overshoot {overshoot}");
        let e20 = (at(&r, &r.altitude, 20.0) - 105.0).abs();
        assert!(e20 < 0.1, "error after 20 s {e20}");
        let late = r.altitude.iter().zip(&r.t).filter(|(_, t)| **t >= 20.0).map(|(h, _)| (h - 105.0).abs());
        assert!(late.fold(0.0, f64::max) < 0.1);
        assert!(r.va.iter().all(|v| (v - 25.0).abs() < 0.5));
    }

    #[test]
    fn autopilot_airspeed_step() {
        let r = closed_loop(40.0, |_| {}, |_| level(27.0, 100.0, 0.0));
        let e20 = (at(&r, &r.va, 20.0) - 27.0).abs();
        assert!(e20 < 0.02, "error after 20 s {e20}");
        let peak = r.va.iter().cloned().fold(f64::MIN, f64::max);
        assert!(peak < 27.0 + 0.1 * 2.0, "overshoot {}", peak - 27.0);
        assert!(r.altitude.iter().all(|h| (h - 100.0).abs() < 1.0));
    }

    #[test]
    fn autopilot_roll_command() {
        let r = closed_loop(30.0, |_| {}, |_| level(25.0, 100.0, 20.0 * DEG));
        let e5 = (at(&r, &r.roll, 5.0) - 20.0 * DEG).abs();
        assert!(e5 < 0.5 * DEG, "error after 5 s {} deg", e5 / DEG);
        let peak = r.roll.iter().cloned().fold(f64::MIN, f64::max);
        assert!(peak < 21.0 * DEG, "peak {} deg", peak / DEG);
        // The turn is coordinated and held: sideslip back near zero, altitude within 1 m.
        assert!(r.beta.last().unwrap().abs() < 0.1 * DEG, "beta {}", r.beta.last().unwrap() / DEG);
        assert!(r.altitude.iter().all(|h| (h - 100.0).abs() < 1.0));
        assert!((r.roll.last().unwrap() - 20.0 * DEG).abs() < 0.1 * DEG);
    }

    #[test]
    fn each_surface_has_its_documented_sign_and_is_distinguishable() {
        let p = AerosondeParams::default();
        let (x, s0, t) = trim(&p, 25.0, 100.0).unwrap();
        let (a0, f0) = accel(&p, &x, &s0, t);
        let delta = |i: usize| {
            let mut s = s0;
            s[i] += 5.0 * DEG;
            let (a, f) = accel(&p, &x, &s, t);
            ([a[0] - a0[0], a[1] - a0[1], a[2] - a0[2]], [f[0] - f0[0], f[1] - f0[1]])
        };
        let (al, _) = delta(0);
        let (ar, _) = delta(1);
        assert!(al[0] > 1.0, "left aileron rolls right: pdot {}", al[0]);
        assert!((al[0] + ar[0]).abs() < 1e-12 && (al[2] + ar[2]).abs() < 1e-12, "{al:?} {ar:?}");
        // Each half is also a flap on its wing: both pitch nose down alike, so a left aileron at +5 deg
        // and a right one at -5 deg roll the same but pitch oppositely (distinguishable).
        assert!(al[1] < -0.05 && (al[1] - ar[1]).abs() < 1e-12, "aileron pitch {} {}", al[1], ar[1]);
        let (el, fl) = delta(2);
        let (er, fr) = delta(3);
        assert!(el[1] < -0.5, "positive elevator pitches nose down: qdot {}", el[1]);
        assert!((el[1] - er[1]).abs() < 1e-12 && (fl[0] - fr[0]).abs() < 1e-12 && (fl[1] - fr[1]).abs() < 1e-12);
        assert!(el[0] > 0.05, "left elevator rolls right: pdot {}", el[0]);
        assert!((el[0] + er[0]).abs() < 1e-12);
        assert!(el[0] < 0.1 * al[0], "the elevator roll effect is small next to the aileron's");
        let (ru, _) = delta(4);
        assert!(ru[2] < -0.1, "positive rudder yaws nose left: rdot {}", ru[2]);
        // Mixing.
        let d = effective_deflections(&[0.1, 0.3, 0.2, -0.4, 0.05]);
        let got = [d.aileron_rad, d.aileron_sym_rad, d.elevator_rad, d.elevator_diff_rad, d.rudder_rad];
        for (g, w) in got.iter().zip([-0.1, 0.2, -0.1, 0.3, 0.05]) {
            assert!((g - w).abs() < 1e-15, "{got:?}");
        }
    }

    #[test]
    fn reduced_model_matches_the_full_model() {
        let p = AerosondeParams::default();
        let x = State::from_column_slice(&[10.0, -5.0, -120.0, 24.0, 2.0, 3.0, 0.3, 0.15, 0.7, 0.2, -0.1, 0.15]);
        let s = [0.05, -0.02, -0.08, -0.12, 0.03];
        let throttle = 0.5;
        let (va, alpha, beta) = air_data(&x, &no_wind());
        let x5 = ReducedState::new(x[9], x[10], x[11], alpha, beta);
        let inputs = ReducedInputs::new(va, x[6], x[7], throttle);
        let r = reduced_derivatives(&p, &x5, &inputs, &s);
        let d = derivatives(&p, &x, &s, throttle, &no_wind());
        for i in 0..3 {
            assert!((r[i] - d[9 + i]).abs() < 1e-10, "row {i}: {} vs {}", r[i], d[9 + i]);
            assert!(d[9 + i].abs() > 1e-3, "the state should be non-trivial");
        }
        let h = 1e-4;
        let xp = step_rk4(&p, &x, &s, throttle, &no_wind(), h);
        let xm = step_rk4(&p, &x, &s, throttle, &no_wind(), -h);
        let (_, ap, bp) = air_data(&xp, &no_wind());
        let (_, am, bm) = air_data(&xm, &no_wind());
        let (alpha_dot, beta_dot) = ((ap - am) / (2.0 * h), (bp - bm) / (2.0 * h));
        assert!(alpha_dot.abs() > 1e-2 && beta_dot.abs() > 1e-2, "{alpha_dot} {beta_dot}");
        assert!(((r[3] - alpha_dot) / alpha_dot).abs() < 1e-5, "alpha_dot {} vs {alpha_dot}", r[3]);
        assert!(((r[4] - beta_dot) / beta_dot).abs() < 1e-5, "beta_dot {} vs {beta_dot}", r[4]);
    }

    #[test]
    fn scaled_scales_the_named_derivative() {
        let p = AerosondeParams::default();
        let (x, s0, t) = trim(&p, 25.0, 100.0).unwrap();
        let mut s = s0;
        s[2] += 2.0 * DEG;
        s[3] += 2.0 * DEG;
        let dq = |p: &AerosondeParams| accel(p, &x, &s, t).0[1] - accel(p, &x, &s0, t).0[1];
        let q = p.scaled("C_m_delta_e", 1.3).unwrap();
        assert!((q.C_m_delta_e - 1.3 * p.C_m_delta_e).abs() < 1e-15);
        assert!(((dq(&q) / dq(&p)) - 1.3).abs() < 1e-10, "{} {}", dq(&q), dq(&p));
        assert_eq!(
            AerosondeParams { C_m_delta_e: p.C_m_delta_e, C_l_delta_e_diff: p.C_l_delta_e_diff, ..q.clone() },
            p
        );
        for name in SCALABLE_COEFFICIENTS {
            assert!(p.scaled(name, 2.0).is_ok(), "{name}");
        }
        let err = p.scaled("C_m_delta_x", 1.1).unwrap_err();
        assert!(
            err.contains("C_m_delta_x") && err.contains("C_m_delta_e") && err.contains("C_l_delta_e_diff"),
            "{err}"
        );
        assert!(p.scaled("C_m_delta_e", f64::NAN).is_err());
    }

    /// A model error on a book coefficient keeps the split surfaces' derived terms what the module docs
    /// derive them from (the scaled parent), for either sign of the factor; a derived term named alone
    /// moves alone.
    #[test]
    fn scaling_a_parent_scales_its_derived_terms() {
        let p = AerosondeParams::default();
        for factor in [1.2, 0.8, -1.3] {
            let q = p.scaled("C_l_delta_a", factor).unwrap();
            assert!((q.C_l_delta_a - 0.08 * factor).abs() < 1e-15);
            assert!((q.C_L_delta_a_sym - q.C_l_delta_a / AILERON_CENTROID_SPAN_FRACTION).abs() < 1e-15);
            assert!((q.C_m_delta_a_sym + 0.25 * q.C_l_delta_a / AILERON_CENTROID_SPAN_FRACTION).abs() < 1e-15);
            assert_eq!(q.C_l_delta_e_diff, p.C_l_delta_e_diff);
            let r = p.scaled("C_m_delta_e", factor).unwrap();
            let from_tail = r.C_m_delta_e.abs() * (r.c_m / r.b_m) * (TAIL_HALF_CENTROID_M / TAIL_ARM_M);
            assert!((r.C_l_delta_e_diff - from_tail).abs() < 1e-15, "{factor}: {} vs {from_tail}", r.C_l_delta_e_diff);
            assert!((r.C_l_delta_e_diff - 0.5 * 0.18994 / 2.8956 * 0.115).abs() > 1e-4, "moved with its parent");
            assert_eq!((r.C_L_delta_a_sym, r.C_m_delta_a_sym), (p.C_L_delta_a_sym, p.C_m_delta_a_sym));
        }
        let alone = p.scaled("C_L_delta_a_sym", 2.0).unwrap();
        assert_eq!(AerosondeParams { C_L_delta_a_sym: p.C_L_delta_a_sym, ..alone.clone() }, p);
        assert!((alone.C_L_delta_a_sym - 2.0 * p.C_L_delta_a_sym).abs() < 1e-15);
    }

    #[test]
    fn actuators_lag_and_saturate() {
        let mut a = Actuators::new([0.0; 5]);
        let cmd = [0.1, -0.1, 1.0, -1.0, 0.0];
        let pos = a.step(&cmd, 0.05);
        let k = 1.0 - (-1.0f64).exp();
        assert!((pos[0] - 0.1 * k).abs() < 1e-15 && (pos[1] + 0.1 * k).abs() < 1e-15);
        for _ in 0..200 {
            a.step(&cmd, 0.01);
        }
        let pos = a.positions();
        assert!((pos[2] - Actuators::DEFAULT_MAX_DEFLECTION_RAD).abs() < 1e-9);
        assert!((pos[3] + Actuators::DEFAULT_MAX_DEFLECTION_RAD).abs() < 1e-9);
        assert!(pos.iter().all(|v| v.abs() <= Actuators::DEFAULT_MAX_DEFLECTION_RAD));
    }
}
