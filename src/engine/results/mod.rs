//! What a run's records say: the outcome schema, reading `trials.parquet` back, thresholds calibrated
//! after the run, the summary tables with their tail fits, and the regression check against a baseline.

pub mod check;
pub mod flight_thresholds;
pub mod roc;
pub mod schema;
pub mod summary;
pub mod summary_spec;
pub mod tables;
pub mod tails;
pub mod text;
pub mod thresholds;
