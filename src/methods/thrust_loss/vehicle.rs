//! Rigid-body launch vehicle with four gimballed engines, its attitude controller, thrust-loss faults and
//! sensors: the plant of method 001 (`docs/findings-seed001.md`: EKF residual + moving-horizon least
//! squares for thrust loss). The seed's own equations of motion were figures and are lost; this is the
//! textbook 6-DoF rigid body in a flat, non-rotating launch frame, with every number documented on
//! [`VehicleParams`], [`ControllerGains`], [`PitchProgram`] and [`SensorNoise`].
//!
//! # Frames and sign conventions
//! - Launch frame `O-xyz` (treated as inertial, as the seed does: the Earth's rotation, Coriolis and
//!   transport terms are left out of the truth too, the filter's process noise stands for them):
//!   origin at the pad, `x` horizontal down-range, `y` up along the local vertical, `z = x cross y`.
//!   Gravity is `-g0 (R_e / (R_e + y))^2` along `y`.
//! - Body frame `x1 y1 z1`, origin at the centre of mass: `x1` along the axis towards the nose; on the
//!   pad (`x1` vertical) `y1` points along `-x` and `z1` along `z`.
//! - Euler angles, rotation order pitch-yaw-roll (3-2-1, the Chinese launch-vehicle convention of the
//!   seed): pitch `phi` about `z`, yaw `psi` about the new `y`, roll `gamma` about `x1`;
//!   `v_body = Rx(gamma) Ry(psi) Rz(phi) v_launch`. On the pad `phi = 90 deg`; the pitch program lowers
//!   `phi` to tilt the nose down-range. Kinematics: `phi' = (wy sin gamma + wz cos gamma) / cos psi`,
//!   `psi' = wy cos gamma - wz sin gamma`, `gamma' = wx + tan psi (wy sin gamma + wz cos gamma)`.
//! - Body rates `wx, wy, wz` are roll, yaw and pitch rate (the pitch rate `wz` is the seed's residual
//!   channel). Velocities `vx, vy, vz` and positions `x, y, z` are launch-frame components.
//!
//! # State
//! The seed's 13 states, in its order ([`idx`], [`STATE_NAMES`]):
//! `[P, vx, vy, vz, wx, wy, wz, x, y, z, phi, psi, gamma]`, `P` the total thrust (N). In the truth `P` is
//! algebraic (the sum of the four engines' thrusts at the current altitude and fault state, written back
//! after every step); in the filter's model it is a state ([`filter_derivatives`]).
//!
//! # Engines, gimbals and thrust-loss faults
//! Four engines in the four quadrants of the body `y1-z1` plane, numbered like the quadrants: engine
//! `i` (index `i - 1`) sits at angle `theta_i = 45, 135, 225, 315 deg` from `+y1` towards `+z1`, at
//! radius `r_e`, a distance `l` behind the centre of mass: engine 1 at `(+y1, +z1)`, 2 at `(-y1, +z1)`,
//! 3 at `(-y1, -z1)`, 4 at `(+y1, -z1)`. This numbering reproduces the seed's observation: a loss on
//! engines {1, 4} (`y1 > 0`) pitches the nose up (`wz' > 0`) and its lateral overload `n_y` jumps
//! positive, on {2, 3} negative; a loss on {1, 2} (`z1 > 0`) moves `n_z` positive, on {3, 4} negative
//! (see [`expected_jump_signs`]).
//! Each engine swings on a single-axis tangential gimbal (the arrangement of the four-engine first stages
//! of the Long March 2/3 family): deflection `delta_i` tilts its thrust from `x1` towards the tangent
//! `t_i = (0, -sin theta_i, cos theta_i)`. An engine's thrust is `(1 - f_i) (P_vac - A_e p(y))` (vacuum
//! thrust less the back-pressure on the nozzle exit), `f_i` its thrust-loss fraction: the seed's fault
//! `P_f = (1 - f) P`, active from its onset ([`ThrustFault`]). Its propellant flow is
//! `(1 - f_i) P_vac / c_vac` (a loss of flow at constant exhaust velocity), so the truth's mass follows
//! the faults while the filter's mass is the nominal schedule.
//!
//! # Aerodynamics and atmosphere
//! Simple and documented, enough to give the attitude loop its (small) aerodynamic instability: axial
//! force `-1/2 rho S C_A |v| v_x1`, normal forces `-1/2 rho S C_N_alpha |v| (v_y1, v_z1)` (the linear
//! normal-force slope times `sin alpha`, written so that it is smooth at zero speed) acting at the centre
//! of pressure ahead of the centre of mass, `v` relative to the air; no Mach dependence, no aerodynamic
//! damping. The truth may fly through discrete gusts ([`Gust`]); the filter's model has no wind.
//! Exponential atmosphere for density and pressure.
//!
//! # Attitude control
//! [`Controller`]: PD on the measured attitude errors from the [`PitchProgram`] (the navigation output is
//! the measurement), `delta_phi = -(a0 (phi - phi_pr) + a1 (wz - phi_pr'))`, likewise yaw and roll about
//! zero, allocated to the four gimbals so that pitch, yaw and roll moments are `P l delta_phi`,
//! `P l delta_psi`, `P r_e delta_gamma`; servos are first-order lags with a deflection limit. A thrust
//! loss on one engine puts a step moment `r_e sin/cos(45 deg) f P_engine` on pitch and on yaw: for 50 %
//! at 25 s the rate deviation stops growing after 0.6 s (2.5e-3 rad/s) and is gone by 2.5 s, where the
//! attitude settles at the static offset a PD loop needs to hold the moment (0.19 deg). The seed's "the
//! controller holds the fault within about 10 ms" is not plausible for the rigid-body loop of a 200-t
//! vehicle (closed-loop natural frequency 1.6-1.9 rad/s here, typical of launch vehicles): 10 ms is one
//! sample, the time the pitch-rate residual needs to *show* the fault, not to recover from it.
//!
//! # One step ([`Vehicle::step`])
//! At `t_k = k dt`: (1) draw the 14 sensor noises, in this order: the 12 measured states in state
//! order (`vx .. gamma`), then `n_y`, `n_z`; (2) form the measurement of `x(k)` and the overloads (the
//! specific force at the IMU from the forces acting just before `t_k`); (3) the controller commands the
//! gimbals from the measurement; (4) the servos move, and their positions are held over `[t_k, t_k+1)`;
//! (5) one RK4 step with the engines' fault state at `t_k`. The [`Measurement`] of step k carries `y(k)`,
//! the overloads and the gimbal positions over the coming step (measured by the servos' feedback
//! potentiometers, taken as exact): the filter's `(y(k), u(k))`. The same RNG state gives bit-identical
//! samples.
//!
//! Numerical failure is a value: a step that starts from a non-finite state, after propellant exhaustion
//! or with an attitude error past [`LaunchVehicleConfig::max_attitude_error_rad`] returns a
//! [`LaunchVehicleError`] instead of a sample, and the trial ends there.
#![allow(non_snake_case)]

use nalgebra::{Matrix3, SVector, Vector3};

use crate::dual::Real;
use rand::RngExt;
use rand_distr::StandardNormal;

/// Number of engines.
pub const ENGINES: usize = 4;
/// Number of states.
pub const STATES: usize = 13;
/// Number of measured states (all but the thrust).
pub const MEASURED: usize = 12;
/// `[P, vx, vy, vz, wx, wy, wz, x, y, z, phi, psi, gamma]`.
pub type State = SVector<f64, STATES>;
/// The measured states `[vx, vy, vz, wx, wy, wz, x, y, z, phi, psi, gamma]`.
pub type Measured = SVector<f64, MEASURED>;

/// State names with units, in state order.
pub const STATE_NAMES: [&str; STATES] = [
    "thrust_n",
    "vx_mps",
    "vy_mps",
    "vz_mps",
    "wx_rad_s",
    "wy_rad_s",
    "wz_rad_s",
    "x_m",
    "y_m",
    "z_m",
    "pitch_rad",
    "yaw_rad",
    "roll_rad",
];

/// Indices into [`State`]; a measured state `i >= 1` is at `i - 1` in [`Measured`].
pub mod idx {
    pub const THRUST: usize = 0;
    pub const VX: usize = 1;
    pub const VY: usize = 2;
    pub const VZ: usize = 3;
    pub const WX: usize = 4;
    pub const WY: usize = 5;
    pub const WZ: usize = 6;
    pub const X: usize = 7;
    pub const Y: usize = 8;
    pub const Z: usize = 9;
    pub const PHI: usize = 10;
    pub const PSI: usize = 11;
    pub const GAMMA: usize = 12;
}

/// Angular position of engine `i` (index) in the `y1-z1` plane, from `+y1` towards `+z1` (module docs).
pub const ENGINE_ANGLES_DEG: [f64; ENGINES] = [45.0, 135.0, 225.0, 315.0];

/// Signs of the jumps `(n_y, n_z)` that a thrust loss on engine `index` produces (module docs): the sign
/// of the engine's `y1` and `z1` coordinates.
pub fn expected_jump_signs(index: usize) -> (f64, f64) {
    let (s, c) = engine_angle_sin_cos()[index];
    (c.signum(), s.signum())
}

/// Vehicle parameters: a two-stage vehicle of the Long March 2C class during first-stage flight.
/// Sources and rationale per field; the default is [`VehicleParams::medium_launcher`].
#[derive(Debug, Clone, PartialEq)]
pub struct VehicleParams {
    /// Lift-off mass: 233 t, the commonly quoted lift-off mass of the two-stage Long March 2C.
    pub liftoff_mass_kg: f64,
    /// First-stage propellant: 162 t (Long March 2C class); burnout after about 140 s at nominal flow.
    pub first_stage_propellant_kg: f64,
    /// Pitch/yaw radius of gyration about the centre of mass: a uniform cylinder of the vehicle's
    /// length 43 m and radius 1.675 m, `sqrt(L^2 / 12 + r^2 / 4) = 12.44 m`, held constant as propellant
    /// drains (inertia `m k^2` then falls with the mass).
    pub pitch_radius_of_gyration_m: f64,
    /// Roll radius of gyration: a solid cylinder of radius 1.675 m, `r / sqrt(2) = 1.18 m`.
    pub roll_radius_of_gyration_m: f64,
    /// Vacuum thrust of one engine: 816 kN, a YF-20B-class engine (four make the 2962 kN sea-level
    /// YF-21B first-stage assembly with the exit area below).
    pub vacuum_thrust_per_engine_n: f64,
    /// Nozzle exit area of one engine: 0.75 m^2, which makes the sea-level thrust
    /// `816 kN - 0.75 m^2 * 101.325 kPa = 740 kN` (2962 kN for four, thrust-to-weight 1.30 at lift-off).
    pub nozzle_exit_area_m2: f64,
    /// Vacuum effective exhaust velocity: 2834 m/s (specific impulse 289 s, storable UDMH/N2O4 engine);
    /// flow 288 kg/s per engine.
    pub vacuum_exhaust_velocity_mps: f64,
    /// Radius of the engines' gimbal points from the axis: 1.05 m (four ~1 m nozzles inside a 3.35 m
    /// diameter stage).
    pub engine_radius_m: f64,
    /// Distance from the centre of mass back to the gimbal plane: 15 m (the centre of mass of a 43 m
    /// vehicle whose mass is dominated by the 25-m first stage, about 35 % of the length up), constant.
    pub gimbal_arm_m: f64,
    /// IMU (overload sensors) ahead of the centre of mass: 18 m (instrument bay on top of the second
    /// stage, about 33 m above the gimbal plane).
    pub imu_ahead_of_cg_m: f64,
    /// Aerodynamic reference area: the 3.35 m diameter cross-section, 8.81 m^2.
    pub reference_area_m2: f64,
    /// Axial-force coefficient: 0.4, an average over the first-stage Mach range of slender launchers
    /// (about 0.3 subsonic, 0.7 at the transonic peak, 0.4 supersonic).
    pub axial_force_coefficient: f64,
    /// Normal-force slope: 2.5 per rad (slender-body theory gives 2 for the nose; body and small fins
    /// add some).
    pub normal_force_slope_per_rad: f64,
    /// Centre of pressure ahead of the centre of mass: 3 m (statically unstable, as launchers with small
    /// fins are).
    pub centre_of_pressure_ahead_of_cg_m: f64,
    pub sea_level_density_kgpm3: f64,
    /// Density scale height: 8.2 km, the exponential fit to the US Standard Atmosphere 1976 at 15 km
    /// (within 13 % up to 16 km, where maximum dynamic pressure lies; 20 % high at 20 km).
    pub density_scale_height_m: f64,
    pub sea_level_pressure_pa: f64,
    /// Pressure scale height: 7.0 km, the same fit for pressure (within 9 % over 0-20 km).
    pub pressure_scale_height_m: f64,
    /// Standard gravity 9.80665 m/s^2.
    pub gravity_mps2: f64,
    /// Mean Earth radius 6371 km (gravity falls with altitude).
    pub earth_radius_m: f64,
}

impl Default for VehicleParams {
    fn default() -> Self {
        Self::medium_launcher()
    }
}

impl VehicleParams {
    /// The documented medium launcher (field docs).
    pub fn medium_launcher() -> Self {
        VehicleParams {
            liftoff_mass_kg: 233.0e3,
            first_stage_propellant_kg: 162.0e3,
            pitch_radius_of_gyration_m: (43.0f64.powi(2) / 12.0 + 1.675f64.powi(2) / 4.0).sqrt(),
            roll_radius_of_gyration_m: 1.675 / 2f64.sqrt(),
            vacuum_thrust_per_engine_n: 816.0e3,
            nozzle_exit_area_m2: 0.75,
            vacuum_exhaust_velocity_mps: 2834.0,
            engine_radius_m: 1.05,
            gimbal_arm_m: 15.0,
            imu_ahead_of_cg_m: 18.0,
            reference_area_m2: std::f64::consts::PI * 1.675f64.powi(2),
            axial_force_coefficient: 0.4,
            normal_force_slope_per_rad: 2.5,
            centre_of_pressure_ahead_of_cg_m: 3.0,
            sea_level_density_kgpm3: 1.225,
            density_scale_height_m: 8200.0,
            sea_level_pressure_pa: 101_325.0,
            pressure_scale_height_m: 7000.0,
            gravity_mps2: 9.80665,
            earth_radius_m: 6.371e6,
        }
    }

    /// Ambient pressure (Pa) at altitude `y_m`.
    pub fn pressure_pa<T: Real>(&self, y_m: T) -> T {
        (-y_m / self.pressure_scale_height_m).exp() * self.sea_level_pressure_pa
    }

    /// Air density (kg/m^3) at altitude `y_m`.
    pub fn density_kgpm3<T: Real>(&self, y_m: T) -> T {
        (-y_m / self.density_scale_height_m).exp() * self.sea_level_density_kgpm3
    }

    /// Thrust (N) of one healthy engine at altitude `y_m`.
    pub fn engine_thrust_n(&self, y_m: f64) -> f64 {
        self.vacuum_thrust_per_engine_n - self.nozzle_exit_area_m2 * self.pressure_pa(y_m)
    }

    /// Rate of change (N/s) of one engine's thrust when climbing at `vy_mps` through altitude `y_m`:
    /// `-A_e dp/dt = A_e p / H_p vy`.
    pub fn engine_thrust_rate_n_s<T: Real>(&self, y_m: T, vy_mps: T) -> T {
        self.pressure_pa(y_m) * self.nozzle_exit_area_m2 / self.pressure_scale_height_m * vy_mps
    }

    /// Propellant flow (kg/s) of one healthy engine.
    pub fn engine_flow_kg_s(&self) -> f64 {
        self.vacuum_thrust_per_engine_n / self.vacuum_exhaust_velocity_mps
    }

    /// Nominal mass (kg) at time `t_s` (all engines healthy): the filter's mass schedule.
    pub fn nominal_mass_kg(&self, t_s: f64) -> f64 {
        self.liftoff_mass_kg - ENGINES as f64 * self.engine_flow_kg_s() * t_s
    }

    /// Mass (kg) at which the first stage's propellant is gone.
    pub fn burnout_mass_kg(&self) -> f64 {
        self.liftoff_mass_kg - self.first_stage_propellant_kg
    }

    /// Inertia diagonal `[Ix, Iy, Iz]` (kg m^2) at mass `mass_kg`.
    pub fn inertia_kgm2(&self, mass_kg: f64) -> Vector3<f64> {
        let (kx, k) = (self.roll_radius_of_gyration_m, self.pitch_radius_of_gyration_m);
        Vector3::new(mass_kg * kx * kx, mass_kg * k * k, mass_kg * k * k)
    }

    /// The state on the pad at lift-off: at rest, vertical, full sea-level thrust.
    pub fn liftoff_state(&self) -> State {
        let mut x = State::zeros();
        x[idx::THRUST] = ENGINES as f64 * self.engine_thrust_n(0.0);
        x[idx::PHI] = std::f64::consts::FRAC_PI_2;
        x
    }
}

/// `Rx(gamma) Ry(psi) Rz(phi)`: launch-frame components to body components.
pub fn launch_to_body<T: Real>(phi: T, psi: T, gamma: T) -> Matrix3<T> {
    launch_to_body_of(phi.sin_cos(), psi.sin_cos(), gamma.sin_cos())
}

/// [`launch_to_body`] from the angles' `(sin, cos)`. The entries are the products `Rx Ry` and then
/// `(Rx Ry) Rz` written out without their terms in exact zeros and ones: the same roundings in the same
/// order as the 3x3 products (only a zero's sign could differ), for a fifth of the work on dual numbers.
pub fn launch_to_body_of<T: Real>((sf, cf): (T, T), (sp, cp): (T, T), (sg, cg): (T, T)) -> Matrix3<T> {
    // Rx Ry = [cp 0 -sp; sg sp, cg, sg cp; cg sp, -sg, cg cp].
    let (sg_sp, cg_sp) = (sg * sp, cg * sp);
    Matrix3::new(
        cp * cf,
        cp * sf,
        -sp,
        sg_sp * cf + cg * -sf,
        sg_sp * sf + cg * cf,
        sg * cp,
        cg_sp * cf + -sg * -sf,
        cg_sp * sf + -sg * cf,
        cg * cp,
    )
}

/// The gimbal deflections over a step (rad, tangential, module docs) by their sines and cosines, which
/// every model evaluation of the step (RK4 stages, the filter's Jacobian) would otherwise compute again.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gimbals {
    sin_cos: [(f64, f64); ENGINES],
}

impl Gimbals {
    pub fn new(rad: [f64; ENGINES]) -> Self {
        Gimbals { sin_cos: rad.map(f64::sin_cos) }
    }
}

/// `(sin, cos)` of each engine's angle [`ENGINE_ANGLES_DEG`], computed once.
fn engine_angle_sin_cos() -> &'static [(f64, f64); ENGINES] {
    static SIN_COS: std::sync::LazyLock<[(f64, f64); ENGINES]> =
        std::sync::LazyLock::new(|| ENGINE_ANGLES_DEG.map(|a| a.to_radians().sin_cos()));
    &SIN_COS
}

/// What the rigid body feels at one instant besides its state. The thrusts are in the model's number
/// type: the filter's model derives them from its thrust state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Loads<T = f64> {
    pub mass_kg: f64,
    /// Thrust of each engine (N).
    pub thrust_n: [T; ENGINES],
    /// Gimbal deflection of each engine.
    pub gimbals: Gimbals,
    /// Velocity of the air, launch frame (m/s): the truth's gusts; zero in the filter's model.
    pub wind_mps: Vector3<f64>,
}

/// Horizontal axis of a gust, in the launch frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GustAxis {
    /// `x`, along the trajectory's plane: it changes the angle of attack in pitch.
    DownRange,
    /// `z`, across it: it changes the sideslip (yaw).
    CrossRange,
}

impl GustAxis {
    /// The deck's spelling.
    pub fn name(self) -> &'static str {
        match self {
            GustAxis::DownRange => "down_range",
            GustAxis::CrossRange => "cross_range",
        }
    }
}

/// A discrete "1 - cosine" gust in the truth (the filter knows no wind): the air moves at
/// `amplitude (1 - cos(2 pi (t - start) / duration)) / 2` along `axis` over `[start, start + duration)`.
/// The aerodynamic moment it brings moves the pitch-rate residual with no engine at fault: the seed's
/// "unrelated jumps" a thrust-loss detector must not alarm on.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gust {
    pub axis: GustAxis,
    pub amplitude_mps: f64,
    pub start_s: f64,
    pub duration_s: f64,
}

impl Gust {
    /// The air's velocity, launch frame (m/s), at `t_s`.
    pub fn wind_mps(&self, t_s: f64) -> Vector3<f64> {
        let phase = (t_s - self.start_s) / self.duration_s;
        if !(0.0..1.0).contains(&phase) {
            return Vector3::zeros();
        }
        let speed = 0.5 * self.amplitude_mps * (1.0 - (std::f64::consts::TAU * phase).cos());
        match self.axis {
            GustAxis::DownRange => Vector3::new(speed, 0.0, 0.0),
            GustAxis::CrossRange => Vector3::new(0.0, 0.0, speed),
        }
    }
}

/// Rates of the 12 rigid-body states (entry [`idx::THRUST`] left 0), the specific force at the centre of
/// mass (body axes, m/s^2) and the angular acceleration (rad/s^2).
pub fn rigid_body_derivatives<T: Real>(
    p: &VehicleParams,
    x: &SVector<T, STATES>,
    loads: &Loads<T>,
) -> (SVector<T, STATES>, Vector3<T>, Vector3<T>) {
    let (sp, cp) = x[idx::PSI].sin_cos();
    let (sg, cg) = x[idx::GAMMA].sin_cos();
    let C = launch_to_body_of(x[idx::PHI].sin_cos(), (sp, cp), (sg, cg));
    let v = Vector3::new(x[idx::VX], x[idx::VY], x[idx::VZ]);
    let w = Vector3::new(x[idx::WX], x[idx::WY], x[idx::WZ]);
    // The aerodynamics see the velocity relative to the air.
    let v_body = C * (v - loads.wind_mps.map(T::cst));

    let mut force = Vector3::<T>::zeros();
    let mut moment = Vector3::<T>::zeros();
    for ((&(s, c), thrust_n), &(sd, cd)) in
        engine_angle_sin_cos().iter().zip(&loads.thrust_n).zip(&loads.gimbals.sin_cos)
    {
        let f = Vector3::new(cd, -sd * s, sd * c).map(|e| *thrust_n * e);
        let r = Vector3::new(-p.gimbal_arm_m, p.engine_radius_m * c, p.engine_radius_m * s).map(T::cst);
        force += f;
        moment += r.cross(&f);
    }
    // Aerodynamic forces with the speed factored so that they are smooth through zero speed.
    let speed = v_body.dot(&v_body).sqrt();
    let half_rho_s_v = p.density_kgpm3(x[idx::Y]) * 0.5 * p.reference_area_m2 * speed;
    let aero = Vector3::new(
        v_body.x * p.axial_force_coefficient,
        v_body.y * p.normal_force_slope_per_rad,
        v_body.z * p.normal_force_slope_per_rad,
    )
    .map(|e| e * -half_rho_s_v);
    force += aero;
    moment += Vector3::new(p.centre_of_pressure_ahead_of_cg_m, 0.0, 0.0).map(T::cst).cross(&aero);

    let I = p.inertia_kgm2(loads.mass_kg).map(T::cst);
    let w_dot = (moment - w.cross(&I.component_mul(&w))).component_div(&I);
    let specific_force = force.map(|f| f / loads.mass_kg);
    let radius_ratio = T::cst(p.earth_radius_m) / (x[idx::Y] + p.earth_radius_m);
    let gravity = Vector3::new(T::zero(), radius_ratio * -p.gravity_mps2 * radius_ratio, T::zero());
    let v_dot = C.transpose() * specific_force + gravity;

    let pitch_yaw = w.y * sg + w.z * cg;
    let mut dx = SVector::<T, STATES>::zeros();
    dx.fixed_rows_mut::<3>(idx::VX).copy_from(&v_dot);
    dx.fixed_rows_mut::<3>(idx::WX).copy_from(&w_dot);
    dx.fixed_rows_mut::<3>(idx::X).copy_from(&v);
    dx[idx::PHI] = pitch_yaw / cp;
    dx[idx::PSI] = w.y * cg - w.z * sg;
    dx[idx::GAMMA] = w.x + sp / cp * pitch_yaw;
    (dx, specific_force, w_dot)
}

/// The filter's model: every engine at `P / 4` of the thrust state, the nominal mass at `t_s`, and the
/// thrust state's own rate from the nominal altitude law (`4 A_e p / H_p vy`). Generic so that one
/// evaluation on [`crate::dual::Dual`] numbers gives the filter its exact Jacobian.
pub fn filter_derivatives<T: Real>(
    p: &VehicleParams,
    x: &SVector<T, STATES>,
    t_s: f64,
    gimbals: &Gimbals,
) -> SVector<T, STATES> {
    let loads = Loads {
        mass_kg: p.nominal_mass_kg(t_s),
        thrust_n: [x[idx::THRUST] / ENGINES as f64; ENGINES],
        gimbals: *gimbals,
        wind_mps: Vector3::zeros(),
    };
    let (mut dx, _, _) = rigid_body_derivatives(p, x, &loads);
    dx[idx::THRUST] = p.engine_thrust_rate_n_s(x[idx::Y], x[idx::VY]) * ENGINES as f64;
    dx
}

/// One classical Runge-Kutta step of `x' = f(t, x)` from `t_s` over `dt_s`.
pub fn rk4<const N: usize>(
    x: &SVector<f64, N>,
    t_s: f64,
    dt_s: f64,
    f: impl Fn(f64, &SVector<f64, N>) -> SVector<f64, N>,
) -> SVector<f64, N> {
    rk4_from(x, f(t_s, x), t_s, dt_s, f)
}

/// [`rk4`] with its first stage `k1 = f(t_s, x)` already evaluated.
pub fn rk4_from<const N: usize>(
    x: &SVector<f64, N>,
    k1: SVector<f64, N>,
    t_s: f64,
    dt_s: f64,
    f: impl Fn(f64, &SVector<f64, N>) -> SVector<f64, N>,
) -> SVector<f64, N> {
    let k2 = f(t_s + dt_s / 2.0, &(x + k1 * (dt_s / 2.0)));
    let k3 = f(t_s + dt_s / 2.0, &(x + k2 * (dt_s / 2.0)));
    let k4 = f(t_s + dt_s, &(x + k3 * dt_s));
    x + (k1 + k2 * 2.0 + k3 * 2.0 + k4) * (dt_s / 6.0)
}

/// Pitch program: the commanded pitch angle, piecewise linear in time through `(t_s, phi_deg)` points.
/// Default: vertical rise for 10 s, a 1.5 deg pitch-over kick from 10 to 20 s, then a zero-lift gravity
/// turn (pitch = flight-path angle) computed with this vehicle's point-mass model (thrust with altitude,
/// mass flow, axial drag, gravity) and tabulated every 10 s to first-stage burnout, rounded to 0.1 deg.
/// Flown by the controller it keeps the angle of attack below 0.1 deg; maximum dynamic pressure is
/// about 29 kPa near 70 s (checked by a test).
#[derive(Debug, Clone, PartialEq)]
pub struct PitchProgram {
    pub points_s_deg: Vec<(f64, f64)>,
}

impl Default for PitchProgram {
    fn default() -> Self {
        PitchProgram {
            points_s_deg: vec![
                (0.0, 90.0),
                (10.0, 90.0),
                (20.0, 88.6),
                (30.0, 85.9),
                (40.0, 82.0),
                (50.0, 77.3),
                (60.0, 72.2),
                (70.0, 67.2),
                (80.0, 62.4),
                (90.0, 58.0),
                (100.0, 54.1),
                (110.0, 50.7),
                (120.0, 47.7),
                (130.0, 45.2),
                (140.0, 43.0),
            ],
        }
    }
}

impl PitchProgram {
    /// Commanded pitch angle (rad) and its rate (rad/s) at `t_s`; held constant outside the table.
    pub fn at(&self, t_s: f64) -> (f64, f64) {
        let pts = &self.points_s_deg;
        let (Some(first), Some(last)) = (pts.first(), pts.last()) else {
            return (std::f64::consts::FRAC_PI_2, 0.0);
        };
        match pts.iter().position(|(t, _)| *t > t_s) {
            Some(0) => (first.1.to_radians(), 0.0),
            None => (last.1.to_radians(), 0.0),
            Some(i) => {
                let ((t0, p0), (t1, p1)) = (pts[i - 1], pts[i]);
                let rate = (p1 - p0) / (t1 - t0);
                ((p0 + rate * (t_s - t0)).to_radians(), rate.to_radians())
            }
        }
    }
}

/// Attitude controller gains and servos. Pitch and yaw: `a0 = 2` (rad of equivalent deflection per rad
/// of error) and `a1 = 1.6 s`: with the control effectiveness `P l / I = 1.23 s^-2` at lift-off (1.8 at
/// 60 s) the loop's natural frequency is 1.57 rad/s at damping 0.63 (1.9 rad/s, 0.77 at 60 s), far
/// above the aerodynamic instability (`C_N_alpha q S x_cp / I < 0.1 s^-2`). Roll: `a0 = 0.5`,
/// `a1 = 0.3 s` with `P r_e / I_x = 9.5 s^-2`: 2.2 rad/s at damping 0.65. Servos: first-order lag
/// 0.02 s (an 8 Hz electro-hydraulic actuator), limit 10 deg per engine (the YF-20 family's gimbal range).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ControllerGains {
    pub pitch_yaw_a0: f64,
    pub pitch_yaw_a1_s: f64,
    pub roll_a0: f64,
    pub roll_a1_s: f64,
    pub servo_time_constant_s: f64,
    pub gimbal_limit_rad: f64,
}

impl Default for ControllerGains {
    fn default() -> Self {
        ControllerGains {
            pitch_yaw_a0: 2.0,
            pitch_yaw_a1_s: 1.6,
            roll_a0: 0.5,
            roll_a1_s: 0.3,
            servo_time_constant_s: 0.02,
            gimbal_limit_rad: 10f64.to_radians(),
        }
    }
}

/// The PD attitude controller, its allocation to the four gimbals, and the servos (module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct Controller {
    gains: ControllerGains,
    positions_rad: [f64; ENGINES],
}

impl Controller {
    pub fn new(gains: ControllerGains) -> Self {
        Controller { gains, positions_rad: [0.0; ENGINES] }
    }

    /// Equivalent pitch, yaw and roll deflections `(delta_phi, delta_psi, delta_gamma)` (rad) for the
    /// measured state `y` at `t_s`.
    pub fn equivalent_deflections(&self, y: &Measured, program: &PitchProgram, t_s: f64) -> (f64, f64, f64) {
        let g = &self.gains;
        let m = |i: usize| y[i - 1];
        let (phi_pr, phi_pr_rate) = program.at(t_s);
        let d_phi = -(g.pitch_yaw_a0 * (m(idx::PHI) - phi_pr) + g.pitch_yaw_a1_s * (m(idx::WZ) - phi_pr_rate));
        let d_psi = -(g.pitch_yaw_a0 * m(idx::PSI) + g.pitch_yaw_a1_s * m(idx::WY));
        let d_gamma = -(g.roll_a0 * m(idx::GAMMA) + g.roll_a1_s * m(idx::WX));
        (d_phi, d_psi, d_gamma)
    }

    /// Commands from the measurement, then one servo step of `dt_s`; returns the positions held over the
    /// coming step. Allocation `delta_i = delta_gamma + 2 (sin theta_i delta_phi + cos theta_i delta_psi)`
    /// makes the moments `P l delta_phi` (pitch), `P l delta_psi` (yaw), `P r_e delta_gamma` (roll) for
    /// small deflections and equal thrusts.
    pub fn step(&mut self, y: &Measured, program: &PitchProgram, t_s: f64, dt_s: f64) -> [f64; ENGINES] {
        let (d_phi, d_psi, d_gamma) = self.equivalent_deflections(y, program, t_s);
        let blend = 1.0 - (-dt_s / self.gains.servo_time_constant_s).exp();
        let limit = self.gains.gimbal_limit_rad;
        for (pos, &(s, c)) in self.positions_rad.iter_mut().zip(engine_angle_sin_cos()) {
            let command = (d_gamma + 2.0 * (s * d_phi + c * d_psi)).clamp(-limit, limit);
            *pos = (*pos + blend * (command - *pos)).clamp(-limit, limit);
        }
        self.positions_rad
    }

    pub fn positions_rad(&self) -> [f64; ENGINES] {
        self.positions_rad
    }
}

/// Sensor noise standard deviations (white, per 100-Hz sample). Rates: 2.9e-4 rad/s, a fibre-optic gyro
/// with angle random walk 0.1 deg/sqrt(h) sampled at 100 Hz (`0.1 / 60 * sqrt(100)` deg/s). Attitude:
/// 5e-5 rad (navigation attitude output jitter). Velocity 0.01 m/s and position 0.1 m (navigation output
/// quantisation). Overloads: 8.5e-4 g, an accelerometer with velocity random walk 0.05 m/s/sqrt(h) at
/// 100 Hz. The filter's measurement covariance is built from the same numbers unless told otherwise.
/// `rate_bias_stability_rad_s`: the standard deviation of each gyro's constant bias, drawn per flight
/// (0 by default: no bias; the filter never models it).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorNoise {
    pub velocity_mps: f64,
    pub rate_rad_s: f64,
    pub position_m: f64,
    pub attitude_rad: f64,
    pub overload_g: f64,
    pub rate_bias_stability_rad_s: f64,
}

impl Default for SensorNoise {
    fn default() -> Self {
        SensorNoise {
            velocity_mps: 0.01,
            rate_rad_s: 0.1f64.to_radians() / 60.0 * 100f64.sqrt(),
            position_m: 0.1,
            attitude_rad: 5e-5,
            overload_g: 0.05 / 60.0 * 100f64.sqrt() / 9.80665,
            rate_bias_stability_rad_s: 0.0,
        }
    }
}

impl SensorNoise {
    /// No noise at all (calibration runs).
    pub fn none() -> Self {
        SensorNoise {
            velocity_mps: 0.0,
            rate_rad_s: 0.0,
            position_m: 0.0,
            attitude_rad: 0.0,
            overload_g: 0.0,
            rate_bias_stability_rad_s: 0.0,
        }
    }

    /// Every standard deviation times `factor`.
    pub fn scaled(&self, factor: f64) -> Self {
        SensorNoise {
            velocity_mps: self.velocity_mps * factor,
            rate_rad_s: self.rate_rad_s * factor,
            position_m: self.position_m * factor,
            attitude_rad: self.attitude_rad * factor,
            overload_g: self.overload_g * factor,
            rate_bias_stability_rad_s: self.rate_bias_stability_rad_s * factor,
        }
    }

    /// Standard deviations of the 12 measured states, in [`Measured`] order.
    pub fn measured_sigma(&self) -> [f64; MEASURED] {
        let (v, w, r, a) = (self.velocity_mps, self.rate_rad_s, self.position_m, self.attitude_rad);
        [v, v, v, w, w, w, r, r, r, a, a, a]
    }
}

/// A thrust loss `P_f = (1 - f) P` on one engine from `onset_s` on.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ThrustFault {
    /// Engine index 0..4 (the seed's engine `index + 1`, module docs).
    pub engine: usize,
    /// `f` in [0, 1].
    pub loss_fraction: f64,
    pub onset_s: f64,
}

/// Everything a trial flies besides the fault.
#[derive(Debug, Clone, PartialEq)]
pub struct LaunchVehicleConfig {
    pub params: VehicleParams,
    pub gains: ControllerGains,
    pub program: PitchProgram,
    pub noise: SensorNoise,
    /// Sample and integration step: 0.01 s, the seed's `D` (RK4; the fastest dynamics, the servo lag of
    /// 0.02 s, is integrated exactly by the servo's discrete update).
    pub dt_s: f64,
    /// An attitude error (any axis) past this ends the trial as a loss of control: 30 deg.
    pub max_attitude_error_rad: f64,
    /// Gusts the truth flies through (none by default; the detector's design never sees them).
    pub gusts: Vec<Gust>,
    /// This flight's constant gyro biases on the body rates (rad/s), drawn with
    /// [`SensorNoise::rate_bias_stability_rad_s`]; zero by default.
    pub rate_bias_rad_s: [f64; 3],
}

impl LaunchVehicleConfig {
    /// The air's velocity at `t_s`: every gust summed.
    pub fn wind_mps(&self, t_s: f64) -> Vector3<f64> {
        self.gusts.iter().map(|g| g.wind_mps(t_s)).sum()
    }
}

impl Default for LaunchVehicleConfig {
    fn default() -> Self {
        LaunchVehicleConfig {
            params: VehicleParams::default(),
            gains: ControllerGains::default(),
            program: PitchProgram::default(),
            noise: SensorNoise::default(),
            dt_s: 0.01,
            max_attitude_error_rad: 30f64.to_radians(),
            gusts: Vec::new(),
            rate_bias_rad_s: [0.0; 3],
        }
    }
}

/// Why a vehicle or a trial could not be flown; a value, never a panic.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LaunchVehicleError {
    #[error("invalid {field}: {value} (allowed: {allowed})")]
    Invalid { field: &'static str, value: f64, allowed: &'static str },
    #[error("non-finite state at t = {t_s:.3} s")]
    NonFinite { t_s: f64 },
    #[error("first-stage propellant exhausted at t = {t_s:.3} s")]
    Burnout { t_s: f64 },
    #[error("loss of control at t = {t_s:.3} s: attitude error {error_deg:.1} deg")]
    LossOfControl { t_s: f64, error_deg: f64 },
}

/// One sample as the detector sees it, plus the truth for scoring.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Measurement {
    pub k: usize,
    pub t_s: f64,
    /// Measured `[vx .. gamma]`.
    pub y: Measured,
    /// Measured lateral overloads (specific force along `y1`, `z1` at the IMU, in g).
    pub n_y_g: f64,
    pub n_z_g: f64,
    /// Gimbal positions held over `[t, t + dt)` (the filter's input).
    pub gimbal_rad: [f64; ENGINES],
    pub truth: State,
    pub truth_n_y_g: f64,
    pub truth_n_z_g: f64,
    pub mass_kg: f64,
}

/// The truth simulation of one trial (module docs).
#[derive(Debug, Clone)]
pub struct Vehicle {
    config: LaunchVehicleConfig,
    fault: Option<ThrustFault>,
    /// First step at which the fault acts (`ceil(onset / dt)`, so onsets between samples act from the
    /// next one).
    fault_step: usize,
    k: usize,
    x: State,
    mass_kg: f64,
    controller: Controller,
    /// Loads acting over the last step (the accelerometers' specific force at `t_k`).
    last_loads: Loads,
}

impl Vehicle {
    /// A vehicle on the pad; `fault` is validated (engine 0..4, `f` in [0, 1], finite onset >= 0).
    pub fn new(config: &LaunchVehicleConfig, fault: Option<ThrustFault>) -> Result<Self, LaunchVehicleError> {
        if !(config.dt_s.is_finite() && config.dt_s > 0.0) {
            return Err(LaunchVehicleError::Invalid { field: "dt_s", value: config.dt_s, allowed: "> 0" });
        }
        let mut fault_step = usize::MAX;
        if let Some(f) = fault {
            if f.engine >= ENGINES {
                let value = f.engine as f64;
                return Err(LaunchVehicleError::Invalid { field: "engine", value, allowed: "0, 1, 2 or 3" });
            }
            if !(0.0..=1.0).contains(&f.loss_fraction) {
                let value = f.loss_fraction;
                return Err(LaunchVehicleError::Invalid { field: "loss_fraction", value, allowed: "0 to 1" });
            }
            if !(f.onset_s.is_finite() && f.onset_s >= 0.0) {
                return Err(LaunchVehicleError::Invalid { field: "onset_s", value: f.onset_s, allowed: ">= 0" });
            }
            // The small tolerance keeps an onset that is a whole number of steps on that step.
            fault_step = (f.onset_s / config.dt_s - 1e-9).ceil() as usize;
        }
        let p = &config.params;
        let x = p.liftoff_state();
        let last_loads = Loads {
            mass_kg: p.liftoff_mass_kg,
            thrust_n: [p.engine_thrust_n(0.0); ENGINES],
            gimbals: Gimbals::new([0.0; ENGINES]),
            wind_mps: Vector3::zeros(),
        };
        Ok(Vehicle {
            config: config.clone(),
            fault,
            fault_step,
            k: 0,
            x,
            mass_kg: p.liftoff_mass_kg,
            controller: Controller::new(config.gains),
            last_loads,
        })
    }

    pub fn config(&self) -> &LaunchVehicleConfig {
        &self.config
    }

    pub fn fault(&self) -> Option<ThrustFault> {
        self.fault
    }

    /// Replaces the fault (calibration branches a nominal flight with it); same rules as [`Vehicle::new`].
    pub fn with_fault(&self, fault: ThrustFault) -> Result<Self, LaunchVehicleError> {
        let fresh = Vehicle::new(&self.config, Some(fault))?;
        Ok(Vehicle { fault: fresh.fault, fault_step: fresh.fault_step, ..self.clone() })
    }

    /// The index of the next step.
    pub fn step_index(&self) -> usize {
        self.k
    }

    pub fn time_s(&self) -> f64 {
        self.k as f64 * self.config.dt_s
    }

    /// The true state `x(k)` of the next step.
    pub fn state(&self) -> &State {
        &self.x
    }

    /// Thrust-loss fraction of each engine during step `k`.
    fn losses_at(&self, k: usize) -> [f64; ENGINES] {
        let mut f = [0.0; ENGINES];
        if let Some(fault) = self.fault
            && k >= self.fault_step
        {
            f[fault.engine] = fault.loss_fraction;
        }
        f
    }

    /// True lateral overloads `(n_y, n_z)` (g) at the IMU for the current state under `loads`.
    fn overloads(&self, loads: &Loads) -> (f64, f64) {
        let p = &self.config.params;
        let (_, specific_force, w_dot) = rigid_body_derivatives(p, &self.x, loads);
        let w = Vector3::new(self.x[idx::WX], self.x[idx::WY], self.x[idx::WZ]);
        let r = Vector3::new(p.imu_ahead_of_cg_m, 0.0, 0.0);
        let f = specific_force + w_dot.cross(&r) + w.cross(&w.cross(&r));
        (f.y / p.gravity_mps2, f.z / p.gravity_mps2)
    }

    /// One sample with sensor noise drawn from `rng`: 14 standard normals in the documented order.
    pub fn step<R: rand::Rng + ?Sized>(&mut self, rng: &mut R) -> Result<Measurement, LaunchVehicleError> {
        let mut unit = [0.0; MEASURED + 2];
        for u in unit.iter_mut() {
            *u = rng.sample::<f64, _>(StandardNormal);
        }
        self.step_with(&unit)
    }

    /// One sample without sensor noise (calibration).
    pub fn step_exact(&mut self) -> Result<Measurement, LaunchVehicleError> {
        self.step_with(&[0.0; MEASURED + 2])
    }

    /// One sample with the given unit normals (the module docs' step).
    fn step_with(&mut self, unit: &[f64; MEASURED + 2]) -> Result<Measurement, LaunchVehicleError> {
        let cfg = &self.config;
        let (p, dt_s) = (&cfg.params, cfg.dt_s);
        let (k, t_s) = (self.k, self.time_s());
        if !self.x.iter().all(|v| v.is_finite()) {
            return Err(LaunchVehicleError::NonFinite { t_s });
        }
        if self.mass_kg <= p.burnout_mass_kg() {
            return Err(LaunchVehicleError::Burnout { t_s });
        }
        let (phi_pr, _) = cfg.program.at(t_s);
        let error = (self.x[idx::PHI] - phi_pr).abs().max(self.x[idx::PSI].abs()).max(self.x[idx::GAMMA].abs());
        if error > cfg.max_attitude_error_rad {
            return Err(LaunchVehicleError::LossOfControl { t_s, error_deg: error.to_degrees() });
        }
        let sigma = cfg.noise.measured_sigma();
        let truth = self.x;
        let mut y = Measured::from_fn(|i, _| truth[i + 1] + sigma[i] * unit[i]);
        if cfg.rate_bias_rad_s != [0.0; 3] {
            for (axis, bias) in cfg.rate_bias_rad_s.iter().enumerate() {
                y[idx::WX - 1 + axis] += bias; // measured index = state index - 1 (no thrust)
            }
        }
        let (truth_n_y_g, truth_n_z_g) = self.overloads(&self.last_loads);
        let n_y_g = truth_n_y_g + cfg.noise.overload_g * unit[MEASURED];
        let n_z_g = truth_n_z_g + cfg.noise.overload_g * unit[MEASURED + 1];

        let gimbal_rad = self.controller.step(&y, &cfg.program, t_s, dt_s);
        let losses = self.losses_at(k);
        let flow_kg_s: f64 = losses.iter().map(|f| (1.0 - f) * p.engine_flow_kg_s()).sum();
        let mass0 = self.mass_kg;
        let gimbals = Gimbals::new(gimbal_rad);
        let derivatives = |tau_s: f64, x: &State| {
            let engine = p.engine_thrust_n(x[idx::Y]);
            let loads = Loads {
                mass_kg: mass0 - flow_kg_s * (tau_s - t_s),
                thrust_n: losses.map(|f| (1.0 - f) * engine),
                gimbals,
                wind_mps: cfg.wind_mps(tau_s),
            };
            let (mut dx, _, _) = rigid_body_derivatives(p, x, &loads);
            let healthy: f64 = losses.iter().map(|f| 1.0 - f).sum();
            dx[idx::THRUST] = healthy * p.engine_thrust_rate_n_s(x[idx::Y], x[idx::VY]);
            dx
        };
        let mut x = truth;
        x[idx::THRUST] = losses.iter().map(|f| (1.0 - f) * p.engine_thrust_n(truth[idx::Y])).sum();
        let measurement =
            Measurement { k, t_s, y, n_y_g, n_z_g, gimbal_rad, truth: x, truth_n_y_g, truth_n_z_g, mass_kg: mass0 };

        let mut next = rk4(&x, t_s, dt_s, derivatives);
        self.mass_kg = mass0 - flow_kg_s * dt_s;
        let next_losses = self.losses_at(k + 1);
        next[idx::THRUST] = next_losses.iter().map(|f| (1.0 - f) * p.engine_thrust_n(next[idx::Y])).sum();
        self.last_loads = Loads {
            mass_kg: self.mass_kg,
            thrust_n: losses.map(|f| (1.0 - f) * p.engine_thrust_n(next[idx::Y])),
            gimbals,
            wind_mps: cfg.wind_mps(t_s + dt_s),
        };
        self.x = next;
        self.k += 1;
        Ok(measurement)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand::rngs::ChaCha8Rng;

    /// The rotation written out is the product `Rx(gamma) Ry(psi) Rz(phi)` to the bit, on `f64` and on
    /// dual numbers (values and derivatives), at angles of every quadrant.
    #[test]
    fn launch_to_body_is_the_product_of_the_three_rotations() {
        fn product<T: Real>(phi: T, psi: T, gamma: T) -> Matrix3<T> {
            let ((sf, cf), (sp, cp), (sg, cg)) = (phi.sin_cos(), psi.sin_cos(), gamma.sin_cos());
            let (o, l) = (T::zero(), T::one());
            let Rz = Matrix3::new(cf, sf, o, -sf, cf, o, o, o, l);
            let Ry = Matrix3::new(cp, o, -sp, o, l, o, sp, o, cp);
            let Rx = Matrix3::new(l, o, o, o, cg, sg, o, -sg, cg);
            Rx * Ry * Rz
        }
        // 1.5707: just short of pi/2, where the launch-to-body rotation is near its singular pitch.
        #[allow(clippy::approx_constant)]
        for (phi, psi, gamma) in [(1.5707, 0.01, -0.02), (0.3, -2.5, 2.9), (-1.1, 0.7, -3.0), (2.2, 1.9, 0.4)] {
            assert_eq!(launch_to_body(phi, psi, gamma), product(phi, psi, gamma));
            let d = |v: f64, i: usize| crate::dual::Dual::<3>::input(v, i);
            let (ours, theirs) =
                (launch_to_body(d(phi, 0), d(psi, 1), d(gamma, 2)), product(d(phi, 0), d(psi, 1), d(gamma, 2)));
            for (a, b) in ours.iter().zip(theirs.iter()) {
                assert_eq!(a.v, b.v);
                // Equal, up to the sign of an exact zero (which the product's terms in 0 can flip).
                assert!(a.d.iter().zip(&b.d).all(|(x, y)| x == y), "{a:?} {b:?}");
            }
        }
    }

    fn exact_config() -> LaunchVehicleConfig {
        LaunchVehicleConfig { noise: SensorNoise::none(), ..LaunchVehicleConfig::default() }
    }

    /// Flies `vehicle` without noise until `until_s`, handing every sample to `each`.
    fn fly(vehicle: &mut Vehicle, until_s: f64, mut each: impl FnMut(&Measurement)) {
        while vehicle.time_s() < until_s - 1e-9 {
            each(&vehicle.step_exact().expect("the nominal flight stays in the envelope"));
        }
    }

    /// Angle of attack (rad) of a state: the angle between the body axis and the velocity in the
    /// pitch plane.
    fn alpha_rad(x: &State) -> f64 {
        let v =
            launch_to_body(x[idx::PHI], x[idx::PSI], x[idx::GAMMA]) * Vector3::new(x[idx::VX], x[idx::VY], x[idx::VZ]);
        (-v.y).atan2(v.x)
    }

    /// Lift-off thrust-to-weight 1.296 (2962 kN / 233 t); at 60 s (measured) 8.02 km altitude, 337 m/s,
    /// 163.9 t; above 50 m/s the angle of attack stays below 0.5 deg (measured 0.28 deg, during the
    /// pitch-over kick) and the dynamic pressure peaks at 28.8 kPa at 71 s: a plausible first-stage
    /// ascent.
    #[test]
    fn thrust_to_weight_and_ascent_are_plausible() {
        let p = VehicleParams::default();
        let thrust_to_weight = p.liftoff_state()[idx::THRUST] / (p.liftoff_mass_kg * p.gravity_mps2);
        assert!((thrust_to_weight - 1.296).abs() < 1e-3, "{thrust_to_weight}");
        assert!((p.engine_thrust_n(0.0) - 740.0e3).abs() < 1e3);
        assert!(((p.first_stage_propellant_kg / (4.0 * p.engine_flow_kg_s())) - 140.7).abs() < 0.1);

        let mut vehicle = Vehicle::new(&exact_config(), None).unwrap();
        let (mut max_alpha, mut max_q, mut at_60) = (0.0f64, (0.0f64, 0.0), None);
        fly(&mut vehicle, 130.0, |m| {
            let x = &m.truth;
            let speed = Vector3::new(x[idx::VX], x[idx::VY], x[idx::VZ]).norm();
            let q = 0.5 * p.density_kgpm3(x[idx::Y]) * speed * speed;
            if q > max_q.0 {
                max_q = (q, m.t_s);
            }
            // The angle of attack is meaningless at the pad's near-zero speed.
            if speed > 50.0 {
                max_alpha = max_alpha.max(alpha_rad(x).abs());
            }
            if m.k == 6000 {
                at_60 = Some((x[idx::Y], speed, m.mass_kg));
            }
        });
        let (altitude_m, speed_mps, mass_kg) = at_60.unwrap();
        assert!((7000.0..9000.0).contains(&altitude_m), "{altitude_m}");
        assert!((300.0..380.0).contains(&speed_mps), "{speed_mps}");
        assert!((mass_kg - 163.9e3).abs() < 100.0, "{mass_kg}");
        assert!(max_alpha.to_degrees() < 0.5, "{}", max_alpha.to_degrees());
        assert!((25.0e3..33.0e3).contains(&max_q.0) && (60.0..80.0).contains(&max_q.1), "{max_q:?}");
    }

    /// A 50 % loss of any one engine at 20 s: the attitude error stays below 0.3 deg (measured 0.21 deg,
    /// mostly the yaw offset a PD loop needs to hold the engine's moment), the body rates are back on the
    /// fault-free flight's within 5 s (measured deviation over 25-30 s: 6.6e-5 rad/s, against 2.6e-3 in
    /// the first 5 s) and stay bounded to 60 s (measured 1.2e-3 rad/s: each break of the pitch program's
    /// rate, at 30, 40 and 50 s, now couples into yaw and roll through the unequal thrusts).
    #[test]
    fn controller_recovers_from_a_50_percent_loss_on_each_engine() {
        let mut nominal = Vec::new();
        fly(&mut Vehicle::new(&exact_config(), None).unwrap(), 60.0, |m| nominal.push(m.truth));
        for engine in 0..ENGINES {
            let fault = ThrustFault { engine, loss_fraction: 0.5, onset_s: 20.0 };
            let config = exact_config();
            let mut vehicle = Vehicle::new(&config, Some(fault)).unwrap();
            let (mut max_error, mut settled, mut later) = (0.0f64, 0.0f64, 0.0f64);
            fly(&mut vehicle, 60.0, |m| {
                let x = &m.truth;
                let (phi_pr, _) = config.program.at(m.t_s);
                let error = (x[idx::PHI] - phi_pr).abs().max(x[idx::PSI].abs()).max(x[idx::GAMMA].abs());
                max_error = max_error.max(error);
                let deviation = (x.fixed_rows::<3>(idx::WX) - nominal[m.k].fixed_rows::<3>(idx::WX)).amax();
                if (25.0..30.0).contains(&m.t_s) {
                    settled = settled.max(deviation);
                } else if m.t_s >= 30.0 {
                    later = later.max(deviation);
                }
            });
            assert!(max_error.to_degrees() < 0.3, "engine {engine}: {} deg", max_error.to_degrees());
            assert!(settled < 2e-4, "engine {engine}: {settled} rad/s");
            assert!(later < 3e-3, "engine {engine}: {later} rad/s");
        }
    }

    /// A loss on engine i moves the overloads at once with the signs of the engine's `y1`, `z1`
    /// coordinates (the seed's table: `n_y` alike for {1, 4} and {2, 3}, `n_z` for {1, 2} and {3, 4}), and
    /// pitches {1, 4} up and {2, 3} down. Measured for 30 % at 25 s: both jumps 9.7e-3 g in size one sample
    /// after the onset; nothing moves at the onset sample itself.
    #[test]
    fn a_loss_moves_the_overloads_with_the_seed_signs() {
        assert_eq!(
            (0..ENGINES).map(expected_jump_signs).collect::<Vec<_>>(),
            vec![(1.0, 1.0), (-1.0, 1.0), (-1.0, -1.0), (1.0, -1.0)]
        );
        let onset_k = 2500;
        let mut nominal = Vec::new();
        fly(&mut Vehicle::new(&exact_config(), None).unwrap(), 25.05, |m| nominal.push(*m));
        for engine in 0..ENGINES {
            let fault = ThrustFault { engine, loss_fraction: 0.3, onset_s: 25.0 };
            let mut faulty = Vec::new();
            fly(&mut Vehicle::new(&exact_config(), Some(fault)).unwrap(), 25.05, |m| faulty.push(*m));
            let (at, after) = (onset_k, onset_k + 1);
            assert_eq!(faulty[at].n_y_g, nominal[at].n_y_g);
            assert_eq!(faulty[at].y, nominal[at].y);
            let jump = (faulty[after].n_y_g - nominal[after].n_y_g, faulty[after].n_z_g - nominal[after].n_z_g);
            let (sy, sz) = expected_jump_signs(engine);
            assert!(jump.0 * sy > 5e-3 && jump.1 * sz > 5e-3, "engine {engine}: {jump:?}");
            let pitch_up = faulty[after + 2].truth[idx::WZ] - nominal[after + 2].truth[idx::WZ];
            assert_eq!(pitch_up.signum(), sy, "engine {engine}: {pitch_up}");
        }
    }

    /// The same RNG state gives bit-identical samples; another state does not.
    #[test]
    fn same_rng_state_gives_bit_identical_samples() {
        let config = LaunchVehicleConfig::default();
        let fault = Some(ThrustFault { engine: 2, loss_fraction: 0.4, onset_s: 1.0 });
        let run = |seed: u64| {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let mut vehicle = Vehicle::new(&config, fault).unwrap();
            (0..300).map(|_| vehicle.step(&mut rng).unwrap()).collect::<Vec<_>>()
        };
        assert_eq!(run(5), run(5));
        assert_ne!(run(5), run(6));
    }

    #[test]
    fn invalid_faults_are_errors_not_panics() {
        let config = LaunchVehicleConfig::default();
        for (engine, loss_fraction, onset_s, field) in [
            (4, 0.5, 1.0, "engine"),
            (0, 1.5, 1.0, "loss_fraction"),
            (0, -0.1, 1.0, "loss_fraction"),
            (0, 0.5, f64::NAN, "onset_s"),
            (0, 0.5, -1.0, "onset_s"),
        ] {
            match Vehicle::new(&config, Some(ThrustFault { engine, loss_fraction, onset_s })) {
                Err(LaunchVehicleError::Invalid { field: f, .. }) => assert_eq!(f, field),
                other => panic!("{engine} {loss_fraction} {onset_s}: {other:?}"),
            }
        }
    }

    /// The flight ends as a value when the first-stage propellant is gone (162 t at 1152 kg/s: 140.7 s).
    #[test]
    fn burnout_ends_the_flight_as_a_value() {
        let mut vehicle = Vehicle::new(&exact_config(), None).unwrap();
        let end = loop {
            if let Err(e) = vehicle.step_exact() {
                break e;
            }
        };
        match end {
            LaunchVehicleError::Burnout { t_s } => assert!((t_s - 140.7).abs() < 0.05, "{t_s}"),
            other => panic!("{other}"),
        }
    }

    #[test]
    fn pitch_program_interpolates_and_holds_its_ends() {
        let program = PitchProgram::default();
        let (phi, rate) = program.at(15.0);
        assert!((phi.to_degrees() - 89.3).abs() < 1e-9 && (rate.to_degrees() + 0.14).abs() < 1e-9);
        assert_eq!(program.at(5.0), (90f64.to_radians(), 0.0));
        assert_eq!(program.at(200.0), (43f64.to_radians(), 0.0));
        assert_eq!(PitchProgram { points_s_deg: vec![] }.at(3.0), (std::f64::consts::FRAC_PI_2, 0.0));
    }
}
