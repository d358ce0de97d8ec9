//! The precision stopping rule of `fdimc run --precision`: the runner feeds it each chunk in trial
//! order and stops once every watched rate's interval is narrow enough.

use std::path::Path;

use polars::prelude::*;

use crate::engine::results::summary_spec::SummarySpec;
use crate::engine::results::thresholds::DECK;
use crate::engine::run::runner::RunError;
use crate::engine::stats::intervals::{Z95, wilson};

use super::aggregate::{Aggregates, number_of};
use crate::engine::results::text::significant;

/// The rates a precision stop can watch (`fdimc run --precision`), as `summary.csv` names them.
pub const PRECISION_RATES: [&str; 3] = ["pd", "pfa", "isolation_accuracy"];

/// Where a run stands against a precision: every watched rate of every group of `summary.csv` at the
/// deck's thresholds, its 95 % Wilson half-width. Fed chunk by chunk in trial order, so where it is met
/// depends only on the deck and seed.
pub struct PrecisionMonitor {
    pub(super) agg: Option<Aggregates<'static>>,
    pub(super) spec: &'static SummarySpec,
    pub(super) half_width: f64,
    pub(super) rates: Vec<&'static str>,
}

/// The widest watched rate of a [`PrecisionMonitor`] and how many rates are still wider than asked.
#[derive(Debug, Clone, PartialEq)]
pub struct PrecisionStatus {
    /// The group (`detector seed, kind bias, target q_rad_s, size bin 3, ...`), the rate, `k`, `n` and
    /// its half-width.
    pub widest: Option<(String, &'static str, u64, u64, f64)>,
    pub wider: usize,
    pub rates: usize,
}

impl PrecisionStatus {
    pub fn met(&self) -> bool {
        self.wider == 0 && self.rates > 0
    }

    pub fn describe(&self) -> String {
        match &self.widest {
            Some((group, rate, k, n, h)) => format!("{rate} of {group}: {k}/{n}, half-width {h:.4}"),
            None => "no rate yet".into(),
        }
    }
}

impl PrecisionMonitor {
    /// Watches `rates` (names of [`PRECISION_RATES`]; all of them when empty) of a kind's groups for a
    /// 95 % half-width of at most `half_width`.
    pub fn new(spec: &'static SummarySpec, half_width: f64, rates: &[String]) -> Result<PrecisionMonitor, String> {
        if !(half_width > 0.0 && half_width < 0.5) {
            return Err(format!("--precision {half_width}: allowed 0 < W < 0.5 (a 95 % half-width)"));
        }
        let mut watched = Vec::new();
        for r in rates {
            let known = PRECISION_RATES.iter().find(|k| **k == r.as_str()).ok_or_else(|| {
                format!(
                    "--precision-rates: {r:?} is not a rate of summary.csv; allowed: {}",
                    PRECISION_RATES.join(", ")
                )
            })?;
            watched.push(*known);
        }
        if watched.is_empty() {
            watched = PRECISION_RATES.to_vec();
        }
        Ok(PrecisionMonitor { agg: None, spec, half_width, rates: watched })
    }

    pub fn status(&self) -> PrecisionStatus {
        let mut status = PrecisionStatus { widest: None, wider: 0, rates: 0 };
        let Some(agg) = &self.agg else { return status };
        for (key, c) in &agg.groups {
            for &rate in &self.rates {
                let (k, n) = match rate {
                    "pd" if c.faulty => (c.detected, c.flown()),
                    "pfa" => (c.false_alarms, c.flown()),
                    "isolation_accuracy" => (c.correct, c.decided),
                    _ => continue,
                };
                if n == 0 {
                    continue;
                }
                let (lo, hi) = wilson(k, n, Z95);
                let h = 0.5 * (hi - lo);
                status.rates += 1;
                status.wider += (h > self.half_width) as usize;
                if status.widest.as_ref().is_none_or(|w| h > w.4) {
                    status.widest = Some((group_name(agg, key), rate, k, n, h));
                }
            }
        }
        status
    }
}

impl crate::engine::run::runner::StopRule for PrecisionMonitor {
    fn start(&mut self, manifest: &crate::engine::run::runner::Manifest) -> Result<(), RunError> {
        self.agg = Some(Aggregates::new(self.spec, vec![DECK], &manifest.detectors));
        Ok(())
    }

    fn add(&mut self, chunk: &DataFrame, file: &Path) -> Result<(), RunError> {
        match &mut self.agg {
            Some(agg) => agg.add_slice(chunk, file, None),
            None => Err(RunError::Internal("precision monitor fed before the run started".into())),
        }
    }

    fn enough(&self) -> bool {
        self.status().met()
    }

    fn outcome(&self) -> crate::engine::run::runner::PrecisionOutcome {
        let status = self.status();
        crate::engine::run::runner::PrecisionOutcome {
            half_width: self.half_width,
            rates: self.rates.iter().map(|r| r.to_string()).collect(),
            met: status.met(),
            watched: status.rates,
            wider: status.wider,
            widest: status.describe(),
        }
    }
}

/// A group key as text: `detector seed, kind bias, target q_rad_s, size bin 3, noise bin 1, ...`.
pub(super) fn group_name(agg: &Aggregates, key: &[u64]) -> String {
    let names = &agg.names;
    let mut parts = vec![format!("detector {}", agg.detectors[key[1] as usize])];
    parts.push(format!("kind {}", names.name(key[2]).unwrap_or("-")));
    parts.push(format!("target {}", names.name(key[3]).unwrap_or("-")));
    let labels =
        ["size bin", "noise bin", "parameter-error bin"].into_iter().chain(agg.spec.extra_keys.iter().copied());
    for (label, &v) in labels.zip(&key[4..]) {
        if let Some(x) = number_of(v) {
            parts.push(format!("{label} {}", significant(x)));
        }
    }
    parts.join(", ")
}
