//! The study methods, one folder each.

pub mod accelerometer;
pub mod air_data;
pub mod detection_filter;
pub mod surface_bank;
pub mod thrust_loss;
