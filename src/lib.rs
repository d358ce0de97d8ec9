//! fdimc: Monte Carlo robustness studies of fault detection and isolation (FDI) in flight control.
//!
//! [`engine`] owns what every study shares (decks' common sections, scenario sampling, the parallel
//! runner, records, summaries, checks, reports); [`methods`] holds one folder per study method;
//! [`design`], [`estimation`], [`fault`], [`kinematics`], [`lti`] and [`linalg`] are building blocks the methods share.
//! The CLI in [`cli`] is a thin layer over these.

pub mod checks;
pub mod cli;
pub mod design;
pub mod dual;
pub mod engine;
pub mod estimation;
pub mod exact;
pub mod fault;
pub mod fmu;
pub mod kinematics;
pub mod linalg;
pub mod lti;
pub mod methods;
pub mod vehicles;
