//! The prescribed flight of method 002: a [`FlightProfile`] of smooth segments, its envelope check, and
//! the kinematic state (body velocity, rates, specific forces) it implies at any time (module docs of
//! [`super`]).

use nalgebra::Vector3;
use thiserror::Error;

use super::kinematics::*;
use crate::checks::{ValueError, finite};
use crate::kinematics::GRAVITY_MPS2;

/// Airspeed the profile must stay above, by the conservative envelope check (m/s): `beta = asin(v/V)`
/// needs `V > 0`; 1 m/s leaves room for rounding.
pub const MIN_AIRSPEED_MPS: f64 = 1.0;
/// Largest angle (rad) the envelope check lets roll, pitch, alpha and beta reach: 80 deg keeps the
/// Euler angles and `tan(phi)` of the coordinated turn away from their singularities at 90 deg.
pub const MAX_ANGLE_RAD: f64 = 80.0 * std::f64::consts::PI / 180.0;

/// Why a profile cannot be flown.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ProfileError {
    #[error(transparent)]
    Value(#[from] ValueError),
    #[error("profile segment {index} needs a finite start and amplitude and a positive duration: {segment:?}")]
    Segment { index: usize, segment: ProfileSegment },
    #[error(
        "the profile can take {field} to {extreme}: airspeed must stay above {MIN_AIRSPEED_MPS} m/s, angles \
             within {MAX_ANGLE_RAD} rad"
    )]
    Envelope { field: &'static str, extreme: f64 },
}

/// Which prescribed history a profile segment moves.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ProfileChannel {
    Airspeed,
    Alpha,
    Beta,
    Roll,
    Pitch,
}

/// The shape of a segment over its window `start_s <= t <= start_s + duration_s`, with `tau` the
/// fraction of the window elapsed; each is continuous with a continuous derivative.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SegmentShape {
    /// `(1 - cos(pi tau)) / 2`: a smooth step to `amplitude`, held afterwards.
    Ramp,
    /// `(1 - cos(2 pi tau)) / 2`: up to `amplitude` at mid-window and back.
    Pulse,
    /// `sin(2 pi tau) (1 - cos(2 pi tau)) / 2`, scaled so its peaks are `+- amplitude`: one lobe each way.
    Doublet,
}

/// Peak of `sin(x) (1 - cos(x)) / 2` (at `x = 2 pi / 3`): `3 sqrt(3) / 8`.
const DOUBLET_PEAK: f64 = 0.649_519_052_838_329;

impl SegmentShape {
    /// Value and derivative with respect to `tau` at `tau` (zero outside the window, one after a ramp).
    fn eval(self, tau: f64) -> (f64, f64) {
        use std::f64::consts::{PI, TAU};
        match self {
            SegmentShape::Ramp if tau <= 0.0 => (0.0, 0.0),
            SegmentShape::Ramp if tau >= 1.0 => (1.0, 0.0),
            SegmentShape::Ramp => (0.5 * (1.0 - (PI * tau).cos()), 0.5 * PI * (PI * tau).sin()),
            _ if !(0.0..=1.0).contains(&tau) => (0.0, 0.0),
            SegmentShape::Pulse => (0.5 * (1.0 - (TAU * tau).cos()), PI * (TAU * tau).sin()),
            SegmentShape::Doublet => {
                let (s, c) = (TAU * tau).sin_cos();
                (s * (1.0 - c) / 2.0 / DOUBLET_PEAK, TAU * (1.0 + c - 2.0 * c * c) / 2.0 / DOUBLET_PEAK)
            }
        }
    }
}

/// One manoeuvre element: `amplitude` (m/s on airspeed, rad on the angles) times `shape` on `channel`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProfileSegment {
    pub channel: ProfileChannel,
    pub shape: SegmentShape,
    pub start_s: f64,
    pub duration_s: f64,
    pub amplitude: f64,
}

/// Prescribed air-relative flight: initial values plus segments (module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct FlightProfile {
    pub airspeed_mps: f64,
    pub alpha_rad: f64,
    pub beta_rad: f64,
    pub roll_rad: f64,
    pub pitch_rad: f64,
    pub heading_rad: f64,
    pub segments: Vec<ProfileSegment>,
}

impl FlightProfile {
    /// Level flight at 70 m/s, alpha = pitch = 4 deg, and four manoeuvres in 60 s (chosen, not from the
    /// patent; they excite every axis, which is what makes sensor biases observable in the kinematics):
    /// - 5-13 s pull-up: pitch pulse +8 deg (8 s), alpha pulse +3 deg (5-11 s);
    /// - 16-34 s coordinated 30 deg turn: roll ramps to 30 deg (16-19 s) and back (31-34 s), alpha +1 deg
    ///   with it (load factor 1.15);
    /// - 37-45 s speed change: airspeed ramp +15 m/s, alpha -2 deg (same lift at the higher speed);
    /// - 48-54 s sideslip doublet: beta +-4 deg.
    pub fn seed() -> Self {
        use ProfileChannel::*;
        use SegmentShape::*;
        let deg = |d: f64| d.to_radians();
        let seg = |channel, shape, start_s, duration_s, amplitude| ProfileSegment {
            channel,
            shape,
            start_s,
            duration_s,
            amplitude,
        };
        FlightProfile {
            segments: vec![
                seg(Pitch, Pulse, 5.0, 8.0, deg(8.0)),
                seg(Alpha, Pulse, 5.0, 6.0, deg(3.0)),
                seg(Roll, Ramp, 16.0, 3.0, deg(30.0)),
                seg(Alpha, Ramp, 16.0, 3.0, deg(1.0)),
                seg(Roll, Ramp, 31.0, 3.0, deg(-30.0)),
                seg(Alpha, Ramp, 31.0, 3.0, deg(-1.0)),
                seg(Airspeed, Ramp, 37.0, 8.0, 15.0),
                seg(Alpha, Ramp, 37.0, 8.0, deg(-2.0)),
                seg(Beta, Doublet, 48.0, 6.0, deg(4.0)),
            ],
            ..Self::steady(70.0, deg(4.0), deg(4.0))
        }
    }

    /// Straight flight with no manoeuvre, wings level, no sideslip, heading north.
    pub fn steady(airspeed_mps: f64, alpha_rad: f64, pitch_rad: f64) -> Self {
        FlightProfile {
            airspeed_mps,
            alpha_rad,
            beta_rad: 0.0,
            roll_rad: 0.0,
            pitch_rad,
            heading_rad: 0.0,
            segments: Vec::new(),
        }
    }

    /// Every segment's amplitude times `factor` (0: steady flight; 2: manoeuvres twice as large).
    pub fn scaled(mut self, factor: f64) -> Self {
        for s in &mut self.segments {
            s.amplitude *= factor;
        }
        self
    }

    /// Value and time derivative of one prescribed history at `t_s`.
    fn channel(&self, channel: ProfileChannel, t_s: f64) -> (f64, f64) {
        let base = match channel {
            ProfileChannel::Airspeed => self.airspeed_mps,
            ProfileChannel::Alpha => self.alpha_rad,
            ProfileChannel::Beta => self.beta_rad,
            ProfileChannel::Roll => self.roll_rad,
            ProfileChannel::Pitch => self.pitch_rad,
        };
        self.segments.iter().filter(|s| s.channel == channel).fold((base, 0.0), |(value, rate), s| {
            let (shape, shape_rate) = s.shape.eval((t_s - s.start_s) / s.duration_s);
            (value + s.amplitude * shape, rate + s.amplitude * shape_rate / s.duration_s)
        })
    }

    /// Conservative envelope check: every channel's base plus the sum of its segments' peak magnitudes.
    pub(super) fn validate(&self) -> Result<(), ProfileError> {
        let base = [
            ("profile.airspeed_mps", self.airspeed_mps),
            ("profile.alpha_rad", self.alpha_rad),
            ("profile.beta_rad", self.beta_rad),
            ("profile.roll_rad", self.roll_rad),
            ("profile.pitch_rad", self.pitch_rad),
            ("profile.heading_rad", self.heading_rad),
        ];
        for (field, value) in base {
            finite(field, value)?;
        }
        for (index, s) in self.segments.iter().enumerate() {
            if !(s.start_s.is_finite() && s.amplitude.is_finite() && s.duration_s > 0.0 && s.duration_s.is_finite()) {
                return Err(ProfileError::Segment { index, segment: *s });
            }
        }
        let swing = |c: ProfileChannel| -> f64 {
            self.segments.iter().filter(|s| s.channel == c).map(|s| s.amplitude.abs()).sum()
        };
        let lowest_airspeed = self.airspeed_mps - swing(ProfileChannel::Airspeed);
        if lowest_airspeed < MIN_AIRSPEED_MPS {
            return Err(ProfileError::Envelope { field: "airspeed_mps", extreme: lowest_airspeed });
        }
        let angles = [
            ("alpha_rad", self.alpha_rad, ProfileChannel::Alpha),
            ("beta_rad", self.beta_rad, ProfileChannel::Beta),
            ("roll_rad", self.roll_rad, ProfileChannel::Roll),
            ("pitch_rad", self.pitch_rad, ProfileChannel::Pitch),
        ];
        for (field, base, channel) in angles {
            let extreme = base.abs() + swing(channel);
            if extreme > MAX_ANGLE_RAD {
                return Err(ProfileError::Envelope { field, extreme });
            }
        }
        Ok(())
    }
}

/// The noise-free kinematic state of a profile at one time (no turbulence).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KinematicState {
    pub air_data: AirData,
    /// `(u, v, w)` (m/s) and its time derivative (m/s^2).
    pub velocity_body_mps: Vector3<f64>,
    pub velocity_rate_body_mps2: Vector3<f64>,
    /// What a perfect inertial system measures.
    pub inertial: Inertial,
    /// Coordinated-turn heading rate `g tan(phi) / V` (rad/s).
    pub heading_rate_rad_s: f64,
}

/// The profile's kinematic state at `t_s` (module docs).
pub fn kinematic_state(profile: &FlightProfile, t_s: f64) -> KinematicState {
    let (V, V_rate) = profile.channel(ProfileChannel::Airspeed, t_s);
    let (a, a_rate) = profile.channel(ProfileChannel::Alpha, t_s);
    let (b, b_rate) = profile.channel(ProfileChannel::Beta, t_s);
    let (phi, phi_rate) = profile.channel(ProfileChannel::Roll, t_s);
    let (theta, theta_rate) = profile.channel(ProfileChannel::Pitch, t_s);
    let air_data = AirData { airspeed_mps: V, alpha_rad: a, beta_rad: b };
    let (sa, ca) = a.sin_cos();
    let (sb, cb) = b.sin_cos();
    let velocity = velocity_from_air_data(&air_data);
    let velocity_rate = Vector3::new(
        V_rate * ca * cb - V * sa * cb * a_rate - V * ca * sb * b_rate,
        V_rate * sb + V * cb * b_rate,
        V_rate * sa * cb + V * ca * cb * a_rate - V * sa * sb * b_rate,
    );
    let psi_rate = GRAVITY_MPS2 * phi.tan() / V;
    let (sphi, cphi) = phi.sin_cos();
    let (sth, cth) = theta.sin_cos();
    let p = phi_rate - psi_rate * sth;
    let q = theta_rate * cphi + psi_rate * cth * sphi;
    let r = -theta_rate * sphi + psi_rate * cth * cphi;
    let (u, v, w) = (velocity[0], velocity[1], velocity[2]);
    let g = GRAVITY_MPS2;
    let inertial = Inertial {
        p_rad_s: p,
        q_rad_s: q,
        r_rad_s: r,
        ax_mps2: velocity_rate[0] - r * v + q * w + g * sth,
        ay_mps2: velocity_rate[1] - p * w + r * u - g * cth * sphi,
        az_mps2: velocity_rate[2] - q * u + p * v - g * cth * cphi,
        roll_rad: phi,
        pitch_rad: theta,
    };
    KinematicState {
        air_data,
        velocity_body_mps: velocity,
        velocity_rate_body_mps2: velocity_rate,
        inertial,
        heading_rate_rad_s: psi_rate,
    }
}
