//! Recorded flights: the ULog reader and the log as a scenario source any method can replay.

pub mod flight_log;
pub mod log_source;
