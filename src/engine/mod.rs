//! The engine: everything a study needs that does not depend on its method. It knows methods only
//! through the traits of [`method`] and [`runner::TrialSource`], never by name.

pub mod check;
pub mod deck;
pub mod flight_log;
pub mod intervals;
pub mod log_source;
pub mod method;
pub mod noise;
pub mod output;
pub mod paired;
pub mod progress;
pub mod quantiles;
pub mod rare;
pub mod rare_event;
pub mod rare_event_study;
pub mod report;
pub mod runner;
pub mod scenario;
pub mod schema;
pub mod sensitivity;
pub mod streams;
pub mod summary;
pub mod tables;
pub mod tail;
pub mod thresholds;
