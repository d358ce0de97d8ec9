//! Study decks: parse (`deck`), then validate into a [`Study`] that cannot be invalid.
//!
//! Every rejection names the file, the field (as a TOML path) and what is allowed.

use std::path::{Path, PathBuf};

use nalgebra::{DMatrix, DVector};

use serde::Deserialize;

/// A deck that could not be read or is not a valid study.
#[derive(Debug, thiserror::Error)]
pub enum DeckError {
    #[error("{file}: cannot read: {source}")]
    Read { file: PathBuf, source: std::io::Error },
    #[error("{file}: {message}")]
    Parse { file: PathBuf, message: String },
    #[error("{file}: {field}: {message}")]
    Invalid { file: PathBuf, field: String, message: String },
}

/// A study factor.
#[derive(Debug, Clone, PartialEq)]
pub enum Factor {
    Fixed(f64),
    /// Continuous on `[lo, hi]`, drawn by the sampler; grouped into `bins` equal bins.
    Range {
        lo: f64,
        hi: f64,
        bins: usize,
    },
    /// Listed values, crossed with the other listed factors (a full grid, cycled over the trials).
    Values(Vec<f64>),
}

/// How continuous factors are drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sampler {
    Random,
    LatinHypercube,
    Sobol,
}

/// Sensor fault kinds of a Monte Carlo population (sizes are drawn per trial).

/// Which model a parameter error perturbs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ModelTarget {
    /// The true plant (the detector's model is then wrong the other way).
    Plant,
    /// The design model: the detector's gains are recomputed per trial for it.
    Design,
}

/// One uncertain physical coefficient: the listed entries of `A` or `B` scaled by `1 + value`

/// A deck file's text; a missing or unreadable file names itself.
pub(crate) fn read_deck(path: &Path) -> Result<String, DeckError> {
    std::fs::read_to_string(path).map_err(|source| DeckError::Read { file: path.into(), source })
}

/// A deck's text parsed into its serde type; TOML errors (unknown fields among them) name the file.
pub(crate) fn parse_deck<T: serde::de::DeserializeOwned>(text: &str, path: &Path) -> Result<T, DeckError> {
    toml::from_str(text)
        .map_err(|e| DeckError::Parse { file: path.into(), message: e.to_string().trim_end().to_string() })
}

/// `[study]`, the same in every deck.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StudySection {
    pub name: String,
    pub seed: u64,
    pub duration_s: f64,
    pub dt_s: f64,
}

/// A factor: a fixed number, `{ range = [lo, hi], bins = k }` (continuous, drawn by the sampler, grouped
/// into k equal bins) or `{ values = [..] }` (listed, crossed with the other listed factors).
/// Kept as a raw TOML value and read by `validate`, which can then name the field in every message.
pub type FactorSpec = toml::Value;

/// Checks deck values and names the file and field in every rejection; shared by every kind of deck.
pub(crate) struct Validator<'a> {
    pub(crate) file: &'a Path,
}

impl Validator<'_> {
    pub(crate) fn err(&self, field: impl Into<String>, message: impl Into<String>) -> DeckError {
        DeckError::Invalid { file: self.file.into(), field: field.into(), message: message.into() }
    }

    pub(crate) fn finite(&self, field: &str, v: f64) -> Result<f64, DeckError> {
        if v.is_finite() { Ok(v) } else { Err(self.err(field, format!("must be a finite number, got {v}"))) }
    }

    pub(crate) fn positive(&self, field: &str, v: f64) -> Result<f64, DeckError> {
        if v.is_finite() && v > 0.0 {
            Ok(v)
        } else {
            Err(self.err(field, format!("must be a finite number > 0, got {v}")))
        }
    }

    pub(crate) fn vector(&self, field: &str, v: &[f64], len: usize, what: &str) -> Result<DVector<f64>, DeckError> {
        if v.len() != len {
            return Err(self.err(field, format!("expected {len} numbers ({what}), got {}", v.len())));
        }
        for (i, &x) in v.iter().enumerate() {
            self.finite(&format!("{field}[{i}]"), x)?;
        }
        Ok(DVector::from_column_slice(v))
    }

    pub(crate) fn matrix(
        &self,
        field: &str,
        rows: &[Vec<f64>],
        nrows: usize,
        ncols: usize,
        what: &str,
    ) -> Result<DMatrix<f64>, DeckError> {
        if rows.len() != nrows {
            return Err(
                self.err(field, format!("expected {nrows} rows of {ncols} numbers ({what}), got {} rows", rows.len()))
            );
        }
        for (i, row) in rows.iter().enumerate() {
            if row.len() != ncols {
                return Err(
                    self.err(format!("{field}[{i}]"), format!("expected {ncols} numbers ({what}), got {}", row.len()))
                );
            }
            for (j, &x) in row.iter().enumerate() {
                self.finite(&format!("{field}[{i}][{j}]"), x)?;
            }
        }
        Ok(DMatrix::from_fn(nrows, ncols, |i, j| rows[i][j]))
    }

    pub(crate) fn names(&self, field: &str, names: &[String]) -> Result<(), DeckError> {
        if names.is_empty() {
            return Err(self.err(field, "must name at least one"));
        }
        for (i, n) in names.iter().enumerate() {
            if n.is_empty() || !n.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
                return Err(self.err(
                    format!("{field}[{i}]"),
                    format!(
                        "{n:?}: names are column names: use letters, digits and '_' (with the unit, e.g. \"q_rad_s\")"
                    ),
                ));
            }
            if names[..i].contains(n) {
                return Err(self.err(format!("{field}[{i}]"), format!("{n:?} appears twice")));
            }
        }
        Ok(())
    }

    pub(crate) fn index_of(&self, field: &str, name: &str, names: &[String], list: &str) -> Result<usize, DeckError> {
        names
            .iter()
            .position(|n| n == name)
            .ok_or_else(|| self.err(field, format!("{name:?} is not one of {list}: {}", names.join(", "))))
    }

    /// `[study]`: a name fit for a folder, a positive duration and step; returns (duration, step, samples).
    pub(crate) fn study_section(&self, s: &StudySection) -> Result<(f64, f64, usize), DeckError> {
        if s.name.is_empty() || !s.name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-') {
            return Err(self.err(
                "study.name",
                format!("{:?}: use letters, digits, '_' and '-' (it names the results folder)", s.name),
            ));
        }
        let duration_s = self.positive("study.duration_s", s.duration_s)?;
        let dt_s = self.positive("study.dt_s", s.dt_s)?;
        let steps_f = (duration_s / dt_s).round();
        if steps_f < 1.0 || steps_f > 1e8 {
            return Err(self.err("study.dt_s", format!("duration_s / dt_s = {steps_f} samples; allowed 1 to 1e8")));
        }
        Ok((duration_s, dt_s, steps_f as usize))
    }

    /// Reads a factor (see [`Factor`]); `None` gives `default`.
    pub(crate) fn factor(&self, field: &str, spec: Option<&FactorSpec>, default: Factor) -> Result<Factor, DeckError> {
        use toml::Value;
        let allowed = "allowed: a number, { range = [lo, hi], bins = k } or { values = [v1, v2, ...] }";
        let number = |field: &str, v: &Value| -> Result<f64, DeckError> {
            match v {
                Value::Float(x) => self.finite(field, *x),
                Value::Integer(x) => Ok(*x as f64),
                other => Err(self.err(field, format!("expected a number, got {}", other.type_str()))),
            }
        };
        let Some(spec) = spec else { return Ok(default) };
        match spec {
            Value::Table(t) => {
                for key in t.keys() {
                    if !["range", "bins", "values"].contains(&key.as_str()) {
                        return Err(self.err(format!("{field}.{key}"), format!("unknown key; {allowed}")));
                    }
                }
                match (t.get("range"), t.get("values")) {
                    (Some(Value::Array(r)), None) if r.len() == 2 => {
                        let lo = number(&format!("{field}.range[0]"), &r[0])?;
                        let hi = number(&format!("{field}.range[1]"), &r[1])?;
                        if !(lo < hi) {
                            return Err(self.err(format!("{field}.range"), format!("needs lo < hi, got [{lo}, {hi}]")));
                        }
                        let bins = match t.get("bins") {
                            None => 1,
                            Some(Value::Integer(b)) if (1..=1000).contains(b) => *b as usize,
                            Some(other) => {
                                return Err(self.err(
                                    format!("{field}.bins"),
                                    format!("expected a whole number from 1 to 1000, got {other}"),
                                ));
                            }
                        };
                        Ok(Factor::Range { lo, hi, bins })
                    }
                    (None, Some(Value::Array(v))) if !v.is_empty() => {
                        if t.contains_key("bins") {
                            return Err(self.err(
                                format!("{field}.bins"),
                                "only used with range: listed values are their own groups",
                            ));
                        }
                        let values = v
                            .iter()
                            .enumerate()
                            .map(|(k, x)| number(&format!("{field}.values[{k}]"), x))
                            .collect::<Result<Vec<_>, _>>()?;
                        Ok(Factor::Values(values))
                    }
                    _ => Err(self.err(field, allowed)),
                }
            }
            v @ (Value::Float(_) | Value::Integer(_)) => Ok(Factor::Fixed(number(field, v)?)),
            other => Err(self.err(field, format!("got {}; {allowed}", other.type_str()))),
        }
    }

    /// Checks every value a factor can take with `ok`, which describes what is allowed.
    pub(crate) fn factor_within(
        &self,
        field: &str,
        factor: &Factor,
        ok: impl Fn(f64) -> bool,
        allowed: &str,
    ) -> Result<(), DeckError> {
        let values: Vec<f64> = match factor {
            Factor::Fixed(v) => vec![*v],
            Factor::Range { lo, hi, .. } => vec![*lo, *hi],
            Factor::Values(v) => v.clone(),
        };
        match values.into_iter().find(|&v| !ok(v)) {
            Some(bad) => Err(self.err(field, format!("{bad} is out of range; allowed {allowed}"))),
            None => Ok(()),
        }
    }

    /// A trial count: 1 to [`crate::engine::streams::MAX_TRIAL`].
    pub(crate) fn trials(&self, field: &str, n: u64) -> Result<u64, DeckError> {
        if n == 0 || n > crate::engine::streams::MAX_TRIAL {
            return Err(self.err(field, format!("allowed 1 to {}, got {n}", crate::engine::streams::MAX_TRIAL)));
        }
        Ok(n)
    }

    /// A fraction in [0, 1].
    pub(crate) fn fraction(&self, field: &str, v: f64) -> Result<f64, DeckError> {
        if !(0.0..=1.0).contains(&v) {
            return Err(self.err(field, format!("allowed 0 to 1, got {v}")));
        }
        Ok(v)
    }

    /// The sampler of continuous factors (default random).
    pub(crate) fn sampler(&self, field: &str, name: Option<&str>) -> Result<Sampler, DeckError> {
        match name {
            None | Some("random") => Ok(Sampler::Random),
            Some("lhs") => Ok(Sampler::LatinHypercube),
            Some("sobol") => Ok(Sampler::Sobol),
            Some(other) => Err(self.err(field, format!("{other:?}: allowed \"random\", \"lhs\", \"sobol\""))),
        }
    }

    /// A name that becomes a column (`perr_<name>`): letters, digits and '_', not among `earlier`.
    pub(crate) fn column_name<'n>(
        &self,
        field: &str,
        name: &str,
        mut earlier: impl Iterator<Item = &'n str>,
    ) -> Result<(), DeckError> {
        if name.is_empty() || !name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
            return Err(self.err(field, format!("{name:?}: letters, digits and '_' (it names a column)")));
        }
        if earlier.any(|o| o == name) {
            return Err(self.err(field, format!("{name:?} appears twice")));
        }
        Ok(())
    }

    /// Which model a parameter error perturbs.
    pub(crate) fn model_target(&self, field: &str, name: &str) -> Result<ModelTarget, DeckError> {
        match name {
            "plant" => Ok(ModelTarget::Plant),
            "design" => Ok(ModelTarget::Design),
            other => Err(self
                .err(field, format!("{other:?}: allowed \"plant\" (the truth) or \"design\" (the detector's model)"))),
        }
    }
}
