//! fdimc: Monte Carlo robustness studies of fault detection and isolation (FDI) in flight control.
//!
//! Data flow (one direction): a TOML deck is parsed and validated into a [`study::Study`]; a detector
//! is designed from it ([`study::DetectionFilterParams::design`]); [`sim`] runs a trial (plant, noise,
//! faults, loop, detector, alarms) and returns a compact outcome or a per-sample trace; [`output`]
//! writes tables. The CLI in [`cli`] is a thin layer over these.

pub mod cli;
pub mod design;
pub mod detector;
pub mod estimation;
pub mod fault;
pub mod linalg;
pub mod output;
pub mod plant;
pub mod regress;
pub mod report;
pub mod runner;
pub mod sampling;
pub mod sim;
pub mod stats;
pub mod study;
