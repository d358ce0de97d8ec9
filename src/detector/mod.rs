//! Fault detectors. Each steps one sample at a time; `sim` owns time, fault injection and alarms.

pub mod detection_filter;
pub mod dual_ukf;
pub mod ekf_mhe;
pub mod ekf_svm;
pub mod stmmae;

pub use detection_filter::DetectionFilter;
