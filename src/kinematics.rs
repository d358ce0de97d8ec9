//! Rigid-body conventions the flight methods share: gravity, its body components, and the NED-to-body
//! rotation.

use nalgebra::Matrix3;

/// Standard gravity (m/s^2).
pub const GRAVITY_MPS2: f64 = 9.80665;

/// The direction-cosine matrix from NED to body axes (yaw `psi`, pitch `theta`, roll `phi`, in that
/// order).
pub fn body_from_ned(roll_rad: f64, pitch_rad: f64, heading_rad: f64) -> Matrix3<f64> {
    let (sp, cp) = roll_rad.sin_cos();
    let (st, ct) = pitch_rad.sin_cos();
    let (ss, cs) = heading_rad.sin_cos();
    Matrix3::new(
        ct * cs,
        ct * ss,
        -st,
        sp * st * cs - cp * ss,
        sp * st * ss + cp * cs,
        sp * ct,
        cp * st * cs + sp * ss,
        cp * st * ss - sp * cs,
        cp * ct,
    )
}

/// Roll and pitch by their sines and cosines, computed once per sample for every filter or sigma point
/// that needs gravity's body components.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Attitude {
    pub sin_cos_roll: (f64, f64),
    pub sin_cos_pitch: (f64, f64),
}

impl Attitude {
    pub fn new(roll_rad: f64, pitch_rad: f64) -> Self {
        Attitude { sin_cos_roll: roll_rad.sin_cos(), sin_cos_pitch: pitch_rad.sin_cos() }
    }

    /// `g (sin theta, cos theta sin phi, cos theta cos phi)`: gravity `g` (or a weight `m g`) in body
    /// axes, the x component with its sign reversed (it enters the body x axis as `-g sin theta`).
    pub fn gravity_terms(&self, g: f64) -> [f64; 3] {
        let ((sphi, cphi), (sth, cth)) = (self.sin_cos_roll, self.sin_cos_pitch);
        [g * sth, g * cth * sphi, g * cth * cphi]
    }
}
