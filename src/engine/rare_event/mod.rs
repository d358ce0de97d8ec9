//! Rare false alarms by simulation (`fdimc rare-event`): the estimators (importance sampling,
//! splitting) and the command around them.

pub mod estimators;
pub mod flights;
pub mod study;
