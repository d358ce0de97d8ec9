//! Airframes more than one method flies: blocks, not a method's property.
//!
//! - [`aerosonde`]: the Aerosonde UAV's 6-DoF model with actuators and autopilot, the truth of the
//!   control-surface study (seed 004) and of the air-data study's high-fidelity truth (seed 002).
//! - [`longitudinal`]: a nonlinear longitudinal light airplane, the equations of the test FMU
//!   `fmus/aircraft` in Rust (the FMU studies compare against it).
//! - [`actuated`]: the same airplane with elevator actuator, engine lag and sensor lags (11 states),
//!   the equations of the test FMU `fmus/aircraft_actuated` (the FMU cost benchmark flies both).

pub mod actuated;
pub mod aerosonde;
pub mod longitudinal;
