//! Rigid-body conventions the flight methods share: gravity and the NED-to-body rotation.

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
