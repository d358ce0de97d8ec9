//! The engine: everything a study needs that does not depend on its method. It knows methods only
//! through the contract of [`method`] and [`run::runner::TrialSource`], never by name.
//!
//! Folders in the order data flows, each one job; a folder imports only those above it in this list
//! (checked by `tests/layers.rs`, the rule is written in `docs/architecture.md`):
//! 1. [`stats`]: intervals, quantiles, tail fits, paired tests: statistics that know nothing of studies;
//! 2. [`scenario`]: the decks' common sections, the sensitivity design, the random streams and the
//!    draws that make a trial's scenario;
//! 3. [`run`]: the runner (the only parallel code) with its manifest, shards, lock and progress, and
//!    the writing of tables;
//! 4. [`results`]: the outcome schema, reading records back, thresholds, the summary and its tail-fit
//!    tables, the regression check;
//! 5. [`rare_event`], [`sensitivity`], [`worst_case`], [`logs`]: the commands that read or feed results
//!    (rare false alarms by simulation, Sobol indices, the worst point of the uncertainty box, recorded
//!    flights);
//! 6. [`report`]: plots and the HTML page;
//! 7. [`method`]: the plug-in contract a kind of study implements, which ties one piece of every layer
//!    (its deck, its trials, its summary spec, its report) into one [`method::Method`].

pub mod logs;
pub mod method;
pub mod rare_event;
pub mod report;
pub mod results;
pub mod run;
pub mod scenario;
pub mod sensitivity;
pub mod stats;
pub mod worst_case;
