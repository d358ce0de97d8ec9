//! What the shared summary ([`crate::engine::results::summary`]) reads of a kind's records beyond the
//! core columns: its own group keys, what its detectors isolate, its own aggregates. A kind's
//! [`crate::engine::method::Method`] carries one.

/// What the shared summary ([`crate::engine::results::summary`]) reads of a kind's records beyond the core columns.
#[derive(Debug, Clone, Copy)]
pub struct SummarySpec {
    /// Group keys after the shared ones: bins of the kind's own factors (numbers, e.g. `gust_bin`).
    pub extra_keys: &'static [&'static str],
    /// What `isolated` names.
    pub isolates: Isolates,
    /// The kind's own aggregates, per group and per detector, at the deck's thresholds.
    pub extras: &'static [Extra],
    /// The kind's own columns (delays, estimation errors) whose median paired difference, with its 95 %
    /// interval, `comparison.csv` reports (`median_<column>_b_minus_a`, `_lo`, `_hi`).
    pub paired_medians: &'static [&'static str],
    /// Columns of `detectors.csv` that `run` prints after the shared ones: (header, column).
    pub printed: &'static [(&'static str, &'static str)],
}

/// What a kind's detectors name when they isolate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Isolates {
    /// The faulty target (output, sensor set, engine, surface), once a fault is detected.
    Target,
    /// The fault's kind, for every unit (a classifier: its classes include the fault-free one).
    Kind,
}

/// An aggregate of a kind's own columns over the units of a group that were flown to the end.
#[derive(Debug, Clone, Copy)]
pub enum Extra {
    /// Units on which `column` is true, or a number > 0.
    Count { name: &'static str, column: &'static str },
    /// Units on which `column` has a value.
    Present { name: &'static str, column: &'static str },
    /// Units on which `column` names the unit's target.
    NamesTarget { name: &'static str, column: &'static str },
    /// `k / n` with its 95 % Wilson interval (`name_lo`, `name_hi`): `k` a count above, `n` a count
    /// above or a core count (`flown`, `isolation_decided`); null where `n` is 0, or for fault-free
    /// groups when `faulty_only`.
    Rate { name: &'static str, k: &'static str, n: &'static str, faulty_only: bool },
    /// The `p` quantile of `column` (of its magnitude with `abs`) over the units where it has a value.
    Quantile { name: &'static str, column: &'static str, p: f64, abs: bool },
}

impl Extra {
    pub fn name(&self) -> &'static str {
        match *self {
            Extra::Count { name, .. }
            | Extra::Present { name, .. }
            | Extra::NamesTarget { name, .. }
            | Extra::Rate { name, .. }
            | Extra::Quantile { name, .. } => name,
        }
    }

    /// The record column it reads, if any.
    pub fn column(&self) -> Option<&'static str> {
        match *self {
            Extra::Count { column, .. }
            | Extra::Present { column, .. }
            | Extra::NamesTarget { column, .. }
            | Extra::Quantile { column, .. } => Some(column),
            Extra::Rate { .. } => None,
        }
    }
}
