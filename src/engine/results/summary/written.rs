//! What `summarize` wrote, for printing, and the settings it leaves in a folder (`summarize.json`);
//! the names of the threshold sets beside the deck's.

use std::path::Path;

use polars::prelude::*;

use crate::engine::results::thresholds::DetectorThresholds;
use crate::engine::run::runner::RunError;

pub const CALIBRATED: &str = "calibrated";
/// Another run's thresholds (`summarize --thresholds`) on this run's trials.
pub const VALIDATION: &str = "validation";
pub use crate::engine::run::output::{CALIBRATIONS_DIR, VALIDATION_DIR};
/// What `summarize` was asked and warned of, for the report (`summarize.json`).
pub const SETTINGS_FILE: &str = "summarize.json";

/// What `summarize` wrote, for printing.
#[derive(Debug)]
pub struct Summary {
    /// Kinds with a statistic: its names, the thresholds and where they came from.
    pub statistics: Vec<String>,
    pub thresholds: Option<(Vec<DetectorThresholds>, String)>,
    /// The rare-false-alarm fits ([`crate::engine::results::tails`]), per detector and threshold set.
    pub tails: Vec<crate::engine::results::tails::DetectorTail>,
    pub summary: DataFrame,
    pub detectors: DataFrame,
    pub confusion: DataFrame,
    /// `answer.csv`: the answer at a glance ([`super::answer`]).
    pub answer: DataFrame,
    /// `safety.csv` ([`super::safety`]).
    pub safety: DataFrame,
    pub warnings: Vec<String>,
    pub files: Vec<&'static str>,
    /// The folder the tables went to: the run's, or its `validation/`.
    pub out_dir: std::path::PathBuf,
    /// The threshold set beside `deck`: `calibrated` or `validation` (none for kinds without a statistic).
    pub set: Option<&'static str>,
    /// Trial x detector units in the run, and those not flown to the end (`failure` set).
    pub units: u64,
    pub failed_units: u64,
}

/// `summarize.json`: the settings and warnings of the summary in a folder.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Settings {
    /// The threshold set beside `deck` (`calibrated`, `validation`), if any.
    pub thresholds: Option<String>,
    /// The false-alarm probability the thresholds are for.
    pub target_pfa: Option<f64>,
    /// The confidence they were calibrated with, if any.
    #[serde(default)]
    pub confidence: Option<f64>,
    /// Where the thresholds came from, as `thresholds.csv`'s `source` says.
    pub source: Option<String>,
    pub warnings: Vec<String>,
}

impl Settings {
    /// The settings `summarize` left in `dir`, if it left any.
    pub fn read(dir: &Path) -> Result<Option<Settings>, RunError> {
        let path = dir.join(SETTINGS_FILE);
        if !path.exists() {
            return Ok(None);
        }
        let text = std::fs::read_to_string(&path).map_err(crate::engine::run::runner::io(&path))?;
        serde_json::from_str(&text)
            .map(Some)
            .map_err(|e| RunError::Invalid(format!("{}: not a summarize.json of this fdimc ({e})", path.display())))
    }
}
