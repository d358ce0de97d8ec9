//! Study decks: parse (`deck`), then validate into a kind's study type, which cannot be invalid.
//!
//! Every rejection names the file, the field (as a TOML path) and what is allowed.

use std::path::{Path, PathBuf};

use nalgebra::{DMatrix, DVector};

use serde::Deserialize;

use crate::engine::scenario::design::{Design, Part};

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

/// Size bins of fault kinds as `[low, high)` edges ([`Factor::bin_edges`]), for the manifest and the
/// summary tables.
pub type SizeBins = std::collections::BTreeMap<String, Vec<[f64; 2]>>;

impl Factor {
    /// Whether trials draw it (a range, or more than one listed value): a factor of a sensitivity design.
    pub fn is_sampled(&self) -> bool {
        match self {
            Factor::Fixed(_) => false,
            Factor::Range { lo, hi, .. } => hi > lo,
            Factor::Values(v) => v.len() > 1,
        }
    }

    /// The `[low, high)` edges of each of a range's bins (a listed or fixed value is its own bin: none).
    pub fn bin_edges(&self) -> Vec<[f64; 2]> {
        match self {
            Factor::Range { lo, hi, bins } => {
                let edge = |b: usize| lo + b as f64 * (hi - lo) / *bins as f64;
                (0..*bins).map(|b| [edge(b), if b + 1 == *bins { *hi } else { edge(b + 1) }]).collect()
            }
            Factor::Fixed(_) | Factor::Values(_) => Vec::new(),
        }
    }

    /// Adds this factor's bins to fault kind `kind`'s in `bins`.
    pub fn add_bins_to(&self, kind: &str, bins: &mut SizeBins) {
        let edges = self.bin_edges();
        if !edges.is_empty() {
            bins.entry(kind.to_string()).or_default().extend(edges);
        }
    }
}

/// As `validate` prints it: `3`, `2 to 6 in 4 bins`, `one of [0.5, 1, 2]`.
impl std::fmt::Display for Factor {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Factor::Fixed(v) => write!(f, "{v}"),
            Factor::Range { lo, hi, bins: 1 } => write!(f, "{lo} to {hi}"),
            Factor::Range { lo, hi, bins } => write!(f, "{lo} to {hi} in {bins} bins"),
            Factor::Values(v) => {
                let v: Vec<String> = v.iter().map(|x| format!("{x}")).collect();
                write!(f, "one of [{}]", v.join(", "))
            }
        }
    }
}

/// How continuous factors are drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sampler {
    Random,
    LatinHypercube,
    Sobol,
}

/// The deck's spelling.
impl std::fmt::Display for Sampler {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Sampler::Random => "random",
            Sampler::LatinHypercube => "lhs",
            Sampler::Sobol => "sobol",
        })
    }
}

/// Which model a parameter error perturbs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ModelTarget {
    /// The true plant (the detector's model is then wrong the other way).
    Plant,
    /// The design model: the detector's gains are recomputed per trial for it.
    Design,
}

/// The deck's spelling.
impl std::fmt::Display for ModelTarget {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            ModelTarget::Plant => "plant",
            ModelTarget::Design => "design",
        })
    }
}

/// A deck file's text; a missing or unreadable file names itself.
pub fn read_deck(path: &Path) -> Result<String, DeckError> {
    std::fs::read_to_string(path).map_err(|source| DeckError::Read { file: path.into(), source })
}

/// The first steps of every kind's reader: parses deck text into `D` (see [`parse_deck`]) and validates
/// its `[study]` table (`study` finds it); the validator names `path` in every later rejection.
pub fn open_deck<'a, D: serde::de::DeserializeOwned>(
    text: &str,
    path: &'a Path,
    study: impl FnOnce(&D) -> &StudySection,
) -> Result<(D, Validator<'a>, StudyHeader), DeckError> {
    let deck: D = parse_deck(text, path)?;
    let v = Validator { file: path };
    let header = v.study_section(study(&deck))?;
    Ok((deck, v, header))
}

/// A deck's text parsed into its serde type; TOML errors (unknown fields among them) name the file. A
/// table missing from the deck is named as such (TOML reports it at line 1 of the whole document).
pub fn parse_deck<T: serde::de::DeserializeOwned>(text: &str, path: &Path) -> Result<T, DeckError> {
    toml::from_str(text).map_err(|e| {
        let missing = e.message().strip_prefix("missing field `").and_then(|m| m.strip_suffix('`'));
        // The document's own span: empty or one character at its start (a table's spans its text).
        let whole_document = e.span().is_none_or(|s| s.start == 0 && (s.end <= 1 || s.end >= text.trim_end().len()));
        match missing {
            Some(table) if whole_document => DeckError::Invalid {
                file: path.into(),
                field: format!("[{table}]"),
                message: format!(
                    "the deck has no [{table}] table; a deck of this kind needs one (docs/deck.md lists \
                     every kind's tables and fields; `fdimc new <kind> FILE` writes a deck to start from)"
                ),
            },
            _ => DeckError::Parse { file: path.into(), message: e.to_string().trim_end().to_string() },
        }
    })
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

/// A study's `[study]` fields, validated; every kind's study holds one.
#[derive(Debug, Clone, PartialEq)]
pub struct StudyHeader {
    /// The deck file (for messages and the manifest).
    pub path: PathBuf,
    /// Names the results folder.
    pub name: String,
    pub seed: u64,
    pub duration_s: f64,
    pub dt_s: f64,
    /// `round(duration_s / dt_s)` samples; sample k is at `k dt_s`.
    pub steps: usize,
}

impl StudyHeader {
    /// The first lines of `validate`: the deck is valid, and the study's name, seed and time grid.
    pub fn print_valid(&self) {
        println!("{}: valid", self.path.display());
        println!(
            "study       {} (seed {}, {} s at dt {} s = {} samples)",
            self.name, self.seed, self.duration_s, self.dt_s, self.steps
        );
    }
}

/// Copies each field a deck table gives (`Some`) over the default of the same name in `$params`:
/// `take_given!(params, deck_table, [field_a, field_b])`.
#[macro_export]
macro_rules! take_given {
    ($params:expr, $given:expr, [$($field:ident),+ $(,)?]) => {
        $(
            if let Some(x) = $given.$field {
                $params.$field = x;
            }
        )+
    };
}

/// A study type read from deck text; `load` reads the file first.
pub trait FromDeck: Sized {
    /// Parses and validates deck text; `path` names it in messages.
    fn from_toml(text: &str, path: &Path) -> Result<Self, DeckError>;

    /// Reads, parses and validates a deck file.
    fn load(path: &Path) -> Result<Self, DeckError> {
        Self::from_toml(&read_deck(path)?, path)
    }

    /// A bundled deck (`studies/<file>`), for tests.
    #[cfg(test)]
    fn bundled(file: &str) -> Self {
        Self::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("studies").join(file)).unwrap()
    }
}

/// Checks deck values and names the file and field in every rejection; shared by every kind of deck.
pub struct Validator<'a> {
    pub file: &'a Path,
}

impl Validator<'_> {
    /// A deck's FMU (`file` relative to the deck's folder), opened and mapped as `mapping` says;
    /// errors name `prefix`'s fields (`truth.fmu`, the mapping's own fields).
    pub fn fmu(
        &self,
        prefix: &str,
        file: &str,
        mapping: &crate::fmu::plant::PlantMapping,
    ) -> Result<crate::fmu::plant::FmuPlant, DeckError> {
        let path = self.file.parent().unwrap_or(Path::new(".")).join(file);
        match crate::fmu::plant::FmuPlant::open(&path, prefix, mapping) {
            Err(e) => Err(self.err(format!("{prefix}.fmu"), e.to_string())),
            Ok(Err((field, message))) => Err(self.err(field, message)),
            Ok(Ok(plant)) => Ok(plant),
        }
    }

    pub fn err(&self, field: impl Into<String>, message: impl Into<String>) -> DeckError {
        DeckError::Invalid { file: self.file.into(), field: field.into(), message: message.into() }
    }

    pub fn finite(&self, field: &str, v: f64) -> Result<f64, DeckError> {
        if v.is_finite() { Ok(v) } else { Err(self.err(field, format!("must be a finite number, got {v}"))) }
    }

    pub fn positive(&self, field: &str, v: f64) -> Result<f64, DeckError> {
        if v.is_finite() && v > 0.0 {
            Ok(v)
        } else {
            Err(self.err(field, format!("must be a finite number > 0, got {v}")))
        }
    }

    /// A first-passage profile's grid step (`None`: the default); `fdimc run --profile-resolution` too.
    pub fn profile_grid(
        &self,
        field: &str,
        step: Option<f64>,
    ) -> Result<crate::engine::scenario::profile_grid::ProfileGrid, DeckError> {
        use crate::engine::scenario::profile_grid::ProfileGrid;
        match step {
            None => Ok(ProfileGrid::default()),
            Some(r) if ProfileGrid::valid(r) => Ok(ProfileGrid::new(r)),
            Some(r) => Err(self.err(field, format!("allowed {}, got {r}", ProfileGrid::ALLOWED))),
        }
    }

    pub fn non_negative(&self, field: &str, v: f64) -> Result<f64, DeckError> {
        if v.is_finite() && v >= 0.0 {
            Ok(v)
        } else {
            Err(self.err(field, format!("must be a finite number >= 0, got {v}")))
        }
    }

    /// A finite number >= `min`; `what` says in the message what the number is.
    pub fn at_least(&self, field: &str, v: f64, min: f64, what: &str) -> Result<f64, DeckError> {
        if v.is_finite() && v >= min {
            Ok(v)
        } else {
            Err(self.err(field, format!("must be >= {min} ({what}), got {v}")))
        }
    }

    pub fn vector(&self, field: &str, v: &[f64], len: usize, what: &str) -> Result<DVector<f64>, DeckError> {
        if v.len() != len {
            return Err(self.err(field, format!("expected {len} numbers ({what}), got {}", v.len())));
        }
        for (i, &x) in v.iter().enumerate() {
            self.finite(&format!("{field}[{i}]"), x)?;
        }
        Ok(DVector::from_column_slice(v))
    }

    pub fn matrix(
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

    pub fn names(&self, field: &str, names: &[String]) -> Result<(), DeckError> {
        if names.is_empty() {
            return Err(self.err(field, "must name at least one"));
        }
        self.names_if_any(field, names)
    }

    /// As [`Validator::names`], where none is allowed (an autonomous plant's inputs).
    pub fn names_if_any(&self, field: &str, names: &[String]) -> Result<(), DeckError> {
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

    /// The names of a deck's `[[table]]` of detectors (or banks): at least one, each names record rows and
    /// files, so letters, digits, '_' and '-', and none twice.
    pub fn detector_names<'n>(
        &self,
        table: &str,
        names: impl ExactSizeIterator<Item = &'n str>,
    ) -> Result<(), DeckError> {
        if names.len() == 0 {
            return Err(self.err(table, format!("at least one [[{table}]] is required")));
        }
        let mut seen: Vec<&str> = Vec::new();
        for (i, n) in names.enumerate() {
            let field = format!("{table}[{i}].name");
            if n.is_empty() || !n.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-') {
                return Err(self.err(field, format!("{n:?}: use letters, digits, '_' and '-'")));
            }
            if seen.contains(&n) {
                return Err(self.err(field, format!("{n:?} appears twice")));
            }
            seen.push(n);
        }
        Ok(())
    }

    /// A deck gives faults one way: a fixed scenario (`fixed`, e.g. `[[faults]]`) or a sampled population
    /// (`sampled`), not both (the population would silently replace the scenario).
    pub fn one_fault_source(&self, fixed: &str, sampled: &str, both: bool) -> Result<(), DeckError> {
        if both {
            let table = fixed.trim_matches(['[', ']']);
            return Err(self.err(
                table,
                format!("give either a fixed scenario ({fixed}) or a sampled population ({sampled}), not both"),
            ));
        }
        Ok(())
    }

    pub fn index_of(&self, field: &str, name: &str, names: &[String], list: &str) -> Result<usize, DeckError> {
        names.iter().position(|n| n == name).ok_or_else(|| match names.is_empty() {
            true => self.err(field, format!("{name:?}: {list} is empty, so nothing can name one of it")),
            false => self.err(field, format!("{name:?} is not one of {list}: {}", names.join(", "))),
        })
    }

    /// `[study]`: a name fit for a folder, a positive duration and step.
    pub fn study_section(&self, s: &StudySection) -> Result<StudyHeader, DeckError> {
        if s.name.is_empty() || !s.name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-') {
            return Err(self.err(
                "study.name",
                format!("{:?}: use letters, digits, '_' and '-' (it names the results folder)", s.name),
            ));
        }
        let duration_s = self.positive("study.duration_s", s.duration_s)?;
        let dt_s = self.positive("study.dt_s", s.dt_s)?;
        let steps_f = (duration_s / dt_s).round();
        if !(1.0..=1e8).contains(&steps_f) {
            return Err(self.err("study.dt_s", format!("duration_s / dt_s = {steps_f} samples; allowed 1 to 1e8")));
        }
        Ok(StudyHeader {
            path: self.file.into(),
            name: s.name.clone(),
            seed: s.seed,
            duration_s,
            dt_s,
            steps: steps_f as usize,
        })
    }

    /// Reads a factor (see [`Factor`]); `None` gives `default`.
    pub fn factor(&self, field: &str, spec: Option<&FactorSpec>, default: Factor) -> Result<Factor, DeckError> {
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
    pub fn factor_within(
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

    /// A trial count: 1 to [`crate::engine::scenario::streams::MAX_TRIAL`].
    pub fn trials(&self, field: &str, n: u64) -> Result<u64, DeckError> {
        if n == 0 || n > crate::engine::scenario::streams::MAX_TRIAL {
            return Err(
                self.err(field, format!("allowed 1 to {}, got {n}", crate::engine::scenario::streams::MAX_TRIAL))
            );
        }
        Ok(n)
    }

    /// A fraction in [0, 1].
    pub fn fraction(&self, field: &str, v: f64) -> Result<f64, DeckError> {
        if !(0.0..=1.0).contains(&v) {
            return Err(self.err(field, format!("allowed 0 to 1, got {v}")));
        }
        Ok(v)
    }

    /// One of a field's named values: `choices` pairs each name a deck may write with its value and what
    /// it means for the message ("" for nothing), which lists them all in this order.
    pub fn choice<T: Clone>(&self, field: &str, name: &str, choices: &[(&str, T, &str)]) -> Result<T, DeckError> {
        match choices.iter().find(|(n, ..)| *n == name) {
            Some((_, value, _)) => Ok(value.clone()),
            None => {
                Err(self.not_allowed(field, name, &choices.iter().map(|(n, _, what)| (*n, *what)).collect::<Vec<_>>()))
            }
        }
    }

    /// The error for a name that is none of `allowed` (each a name and what it means, "" for nothing):
    /// the one message of every field that takes a name, for those whose names [`Validator::choice`]
    /// cannot map (each reads other fields of its own).
    pub fn not_allowed(&self, field: impl Into<String>, name: &str, allowed: &[(&str, &str)]) -> DeckError {
        let allowed: Vec<String> = allowed
            .iter()
            .map(|(n, what)| if what.is_empty() { format!("{n:?}") } else { format!("{n:?} ({what})") })
            .collect();
        self.err(field, format!("{name:?}: allowed {}", allowed.join(", ")))
    }

    /// The sampler of continuous factors (default random).
    pub fn sampler(&self, field: &str, name: Option<&str>) -> Result<Sampler, DeckError> {
        let choices = [
            ("random", Sampler::Random, "default"),
            ("lhs", Sampler::LatinHypercube, ""),
            ("sobol", Sampler::Sobol, ""),
        ];
        self.choice(field, name.unwrap_or("random"), &choices)
    }

    /// A name that becomes a column (`perr_<name>`): letters, digits and '_', not among `earlier`.
    pub fn column_name<'n>(
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
    pub fn model_target(&self, field: &str, name: &str) -> Result<ModelTarget, DeckError> {
        self.choice(
            field,
            name,
            &[("plant", ModelTarget::Plant, "the truth"), ("design", ModelTarget::Design, "the detector's model")],
        )
    }
}

/// `[monte_carlo]` as a deck writes it: the fields every kind shares, and the rest for the kind's own
/// section type (which refuses unknown fields).
#[derive(Debug, Deserialize)]
pub struct MonteCarloSection {
    pub trials: u64,
    pub fault_free_fraction: Option<f64>,
    pub sampler: Option<String>,
    pub target_pfa: Option<f64>,
    pub confidence: Option<f64>,
    pub onset_s: Option<FactorSpec>,
    pub noise_scale: Option<FactorSpec>,
    pub detection_window_s: Option<f64>,
    pub profile_resolution: Option<f64>,
    #[serde(default)]
    pub parameter_error: Vec<toml::Table>,
    /// Per fault kind, a number (s) or a table of targets to numbers ([`HazardTimes`]).
    pub time_to_hazard_s: Option<toml::Table>,
    #[serde(flatten)]
    pub rest: toml::Table,
}

/// `[monte_carlo.time_to_hazard_s]`: per record kind (`bias`, `actuator_stuck`), per target (`""`: every
/// target of the kind) the time from the onset after which an undetected fault is hazardous (s). The
/// summary's `hazard.csv` gives P(not detected within it).
pub type HazardTimes = std::collections::BTreeMap<String, std::collections::BTreeMap<String, f64>>;

/// The time to hazard of a fault of `kind` on `target` in `times`, if the deck gives one.
pub fn time_to_hazard(times: &HazardTimes, kind: &str, target: &str) -> Option<f64> {
    let of_kind = times.get(kind)?;
    of_kind.get(target).or_else(|| of_kind.get("")).copied()
}

/// A point of the deck's uncertainty box that every trial takes (`fdimc worst-case`): per dimension
/// the unit draw to use instead of the sampler's (`None`: drawn as usual), a listed factor picked
/// from its list by it; and whether trials are fault-free (`None`: drawn as usual). The fault kind and
/// component (the grid) and the noise stay each trial's own, so points are compared on the same
/// trials.
#[derive(Debug, Clone, PartialEq)]
pub struct SearchPoint {
    pub units: Vec<Option<f64>>,
    pub fault_free: Option<bool>,
}

/// The shared fields of `[monte_carlo]`, validated.
#[derive(Debug, Clone, PartialEq)]
pub struct MonteCarlo {
    pub trials: u64,
    /// Probability that a trial has no fault (its alarms calibrate thresholds).
    pub fault_free_fraction: f64,
    pub sampler: Sampler,
    /// Target false-alarm probability per trial of threshold calibration (kinds with a statistic).
    pub target_pfa: f64,
    /// Calibrate conservatively: thresholds whose true false-alarm probability is at most
    /// `target_pfa` with this confidence (`None`: at the target on the calibration trials).
    pub confidence: Option<f64>,
    pub onset_s: Factor,
    /// Multiplies every sensor's noise standard deviation.
    pub noise_scale: Factor,
    /// An alarm is a detection only this long after the onset (s); a later one is a miss and a late
    /// alarm ([`crate::engine::results::schema::col::LATE_ALARM_S`]). Infinite: to the end of the trial.
    pub detection_window_s: f64,
    /// The value grid of the recorded first-passage profiles (`profile_resolution`, its relative step):
    /// the resolution at which alarm times can be replayed at other thresholds.
    pub profile: crate::engine::scenario::profile_grid::ProfileGrid,
    /// `time_to_hazard_s`, checked against the deck's faults by the kind ([`Validator::hazard_times`]).
    pub time_to_hazard_s: HazardTimes,
    /// Set by `fdimc sensitivity`, never by a deck: the trials are the rows of this design.
    pub design: Option<std::sync::Arc<Design>>,
    /// Set by `fdimc worst-case`, never by a deck: every trial takes this point's factors.
    pub search_point: Option<std::sync::Arc<SearchPoint>>,
}

impl MonteCarlo {
    /// Makes the trials the rows of a sensitivity design of `base_samples` rows per matrix over `parts`
    /// (`fdimc sensitivity`), and returns the design (for the manifest).
    pub fn use_design(&mut self, base_samples: u64, bootstrap: u64, parts: Vec<Part>) -> Design {
        let design = Design { base_samples, bootstrap, parts };
        self.trials = design.trials();
        self.design = Some(std::sync::Arc::new(design.clone()));
        design
    }
}

/// A `[[monte_carlo.parameter_error]]`: what every kind shares (a name for its `perr_<name>` column, the
/// model it perturbs, a relative or absolute error) and what it perturbs, which the kind reads (`P`).
#[derive(Debug, Clone, PartialEq)]
pub struct ParameterError<P> {
    pub name: String,
    pub model: ModelTarget,
    /// An offset in the quantity's units; otherwise a relative error, the quantity scaled by `1 + value`.
    pub absolute: bool,
    pub value: Factor,
    pub what: P,
}

impl<P> ParameterError<P> {
    /// The manifest's `parameter_error_bins` of `errors`: each drawn from a range, its deck's bins.
    pub fn bins(errors: &[ParameterError<P>]) -> SizeBins {
        let mut bins = SizeBins::new();
        for e in errors {
            e.value.add_bins_to(&e.name, &mut bins);
        }
        bins
    }
}

/// Which of the shared `[monte_carlo]` fields a kind takes (the others are refused by name).
#[derive(Debug, Clone, Copy)]
pub struct MonteCarloRules<'a> {
    /// The kind's decks, in words, for refusals ("accelerometer decks").
    pub decks: &'a str,
    pub duration_s: f64,
    /// Fault-free trials (a classifier's normal class replaces them).
    pub fault_free_fraction: bool,
    pub sampler: bool,
    /// Threshold calibration: the kind's [`crate::engine::method::Method::calibrates`], the one place
    /// that says it.
    pub target_pfa: bool,
    pub onset_s: bool,
    /// `noise_scale` may be a range (otherwise a number or listed values).
    pub noise_ranges: bool,
    /// Absolute parameter errors (otherwise relative only); `None`: no parameter errors.
    pub parameter_errors: Option<bool>,
    /// The kind's default `detection_window_s` (infinite: to the end of the trial).
    pub detection_window_s: f64,
    /// `time_to_hazard_s`: the kind checks its keys against the faults it flies
    /// ([`Validator::hazard_times`]).
    pub time_to_hazard: bool,
}

impl<'a> MonteCarloRules<'a> {
    /// A kind that samples fault-free trials, onsets and noise ranges with any sampler, calibrates its
    /// thresholds if `calibrates` says so, and has no parameter errors; a kind changes what differs.
    pub fn sampled(decks: &'a str, duration_s: f64, calibrates: bool) -> Self {
        MonteCarloRules {
            decks,
            duration_s,
            fault_free_fraction: true,
            sampler: true,
            target_pfa: calibrates,
            onset_s: true,
            noise_ranges: true,
            parameter_errors: None,
            detection_window_s: f64::INFINITY,
            time_to_hazard: false,
        }
    }
}

impl Validator<'_> {
    /// Checks `time_to_hazard_s` against the faults the deck flies: `flown` lists each record kind with
    /// the targets it may hit; a key of another kind, or a target its kind does not hit, is refused.
    pub fn hazard_times(&self, times: &HazardTimes, flown: &[(String, Vec<String>)]) -> Result<(), DeckError> {
        for (kind, targets) in times {
            let field = format!("monte_carlo.time_to_hazard_s.{kind}");
            let Some((_, hit)) = flown.iter().find(|(k, _)| k == kind) else {
                let kinds: Vec<&str> = flown.iter().map(|(k, _)| k.as_str()).collect();
                return Err(
                    self.err(field, format!("no {kind} faults in this deck; its fault kinds: {}", kinds.join(", ")))
                );
            };
            for target in targets.keys().filter(|t| !t.is_empty()) {
                if !hit.contains(target) {
                    return Err(self.err(
                        format!("{field}.{target}"),
                        format!("{kind} faults of this deck hit {}, not {target}", hit.join(", ")),
                    ));
                }
            }
        }
        Ok(())
    }

    /// Validates the shared fields of `[monte_carlo]` (defaults without the section: 1000 trials, no
    /// fault-free ones, random sampling, target Pfa 0.01, onset at a third of the trial, nominal noise),
    /// then hands the kind its own fields (`None` without the section) and each parameter error's own
    /// fields (`what`, given the error's TOML path and its table without the shared keys).
    pub fn monte_carlo<T: serde::de::DeserializeOwned, P>(
        &self,
        section: Option<MonteCarloSection>,
        rules: &MonteCarloRules,
        mut what: impl FnMut(&str, toml::Table) -> Result<P, DeckError>,
    ) -> Result<(MonteCarlo, Option<T>, Vec<ParameterError<P>>), DeckError> {
        let duration_s = rules.duration_s;
        let Some(mc) = section else {
            let defaults = MonteCarlo {
                trials: 1000,
                fault_free_fraction: 0.0,
                sampler: Sampler::Random,
                target_pfa: if rules.target_pfa { 0.01 } else { 0.0 },
                confidence: None,
                onset_s: Factor::Fixed(duration_s / 3.0),
                noise_scale: Factor::Fixed(1.0),
                detection_window_s: rules.detection_window_s,
                profile: Default::default(),
                time_to_hazard_s: HazardTimes::new(),
                design: None,
                search_point: None,
            };
            return Ok((defaults, None, Vec::new()));
        };
        let refuse = |field: &str, given: bool, taken: bool| -> Result<(), DeckError> {
            if given && !taken {
                return Err(self.err(format!("monte_carlo.{field}"), format!("not used by {}: remove it", rules.decks)));
            }
            Ok(())
        };
        refuse("fault_free_fraction", mc.fault_free_fraction.is_some(), rules.fault_free_fraction)?;
        refuse("sampler", mc.sampler.is_some(), rules.sampler)?;
        refuse("target_pfa", mc.target_pfa.is_some(), rules.target_pfa)?;
        refuse("confidence", mc.confidence.is_some(), rules.target_pfa)?;
        refuse("onset_s", mc.onset_s.is_some(), rules.onset_s)?;
        refuse("parameter_error", !mc.parameter_error.is_empty(), rules.parameter_errors.is_some())?;
        refuse("time_to_hazard_s", mc.time_to_hazard_s.is_some(), rules.time_to_hazard)?;
        let mut time_to_hazard_s = HazardTimes::new();
        for (kind, value) in mc.time_to_hazard_s.iter().flatten() {
            let field = format!("monte_carlo.time_to_hazard_s.{kind}");
            let times = time_to_hazard_s.entry(kind.clone()).or_default();
            match value {
                toml::Value::Table(targets) if !targets.is_empty() => {
                    for (target, t) in targets {
                        let field = format!("{field}.{target}");
                        let t = t
                            .as_float()
                            .or(t.as_integer().map(|i| i as f64))
                            .ok_or_else(|| self.err(&field, format!("a time in seconds, got {}", t.type_str())))?;
                        times.insert(target.clone(), self.positive(&field, t)?);
                    }
                }
                v => {
                    let t = v.as_float().or(v.as_integer().map(|i| i as f64)).ok_or_else(|| {
                        self.err(
                            &field,
                            format!("a time in seconds, or a table of targets to times (s), got {}", v.type_str()),
                        )
                    })?;
                    times.insert(String::new(), self.positive(&field, t)?);
                }
            }
        }

        let trials = self.trials("monte_carlo.trials", mc.trials)?;
        let fault_free_fraction =
            self.fraction("monte_carlo.fault_free_fraction", mc.fault_free_fraction.unwrap_or(0.0))?;
        let sampler = self.sampler("monte_carlo.sampler", mc.sampler.as_deref())?;
        // 0: the kind calibrates no threshold (as manifest.json says it).
        let target_pfa = if rules.target_pfa { mc.target_pfa.unwrap_or(0.01) } else { 0.0 };
        if rules.target_pfa && !(target_pfa > 0.0 && target_pfa < 1.0) {
            return Err(self.err("monte_carlo.target_pfa", format!("allowed 0 < p < 1, got {target_pfa}")));
        }
        if let Some(c) = mc.confidence
            && !(c > 0.0 && c < 1.0)
        {
            return Err(self.err("monte_carlo.confidence", format!("allowed 0 < c < 1 (e.g. 0.95), got {c}")));
        }
        let onset_s = self.factor("monte_carlo.onset_s", mc.onset_s.as_ref(), Factor::Fixed(duration_s / 3.0))?;
        self.factor_within(
            "monte_carlo.onset_s",
            &onset_s,
            |t| t >= 0.0 && t < duration_s,
            &format!("0 <= onset_s < duration_s = {duration_s}"),
        )?;
        let noise_scale = self.factor("monte_carlo.noise_scale", mc.noise_scale.as_ref(), Factor::Fixed(1.0))?;
        if !rules.noise_ranges && matches!(noise_scale, Factor::Range { .. }) {
            return Err(self.err(
                "monte_carlo.noise_scale",
                format!("a number or {{ values = [...] }} for {} (their trials are a grid)", rules.decks),
            ));
        }
        self.factor_within("monte_carlo.noise_scale", &noise_scale, |x| x >= 0.0, ">= 0")?;
        let detection_window_s = match mc.detection_window_s {
            Some(w) => self.positive("monte_carlo.detection_window_s", w)?,
            None => rules.detection_window_s,
        };
        let profile = self.profile_grid("monte_carlo.profile_resolution", mc.profile_resolution)?;

        let own = T::deserialize(toml::Value::Table(mc.rest))
            .map_err(|e| self.err("monte_carlo", e.to_string().trim_end().to_string()))?;

        let mut parameter_errors: Vec<ParameterError<P>> = Vec::with_capacity(mc.parameter_error.len());
        for (i, mut table) in mc.parameter_error.into_iter().enumerate() {
            let prefix = format!("monte_carlo.parameter_error[{i}]");
            let field = |name: &str| format!("{prefix}.{name}");
            let text = |table: &mut toml::Table, name: &str| -> Result<String, DeckError> {
                match table.remove(name) {
                    Some(toml::Value::String(s)) => Ok(s),
                    Some(other) => Err(self.err(field(name), format!("expected text, got {}", other.type_str()))),
                    None => Err(self.err(field(name), "required")),
                }
            };
            let name = text(&mut table, "name")?;
            self.column_name(&field("name"), &name, parameter_errors.iter().map(|p| p.name.as_str()))?;
            let model = self.model_target(&field("model"), &text(&mut table, "model")?)?;
            let (relative, absolute) = (table.remove("relative"), table.remove("absolute"));
            let (absolute, value) = match (relative, absolute) {
                (Some(r), None) => {
                    let v = self.factor(&field("relative"), Some(&r), Factor::Fixed(0.0))?;
                    self.factor_within(&field("relative"), &v, |x| x > -1.0 && x < 10.0, "-1 < relative < 10")?;
                    (false, v)
                }
                (None, Some(a)) if rules.parameter_errors == Some(true) => {
                    (true, self.factor(&field("absolute"), Some(&a), Factor::Fixed(0.0))?)
                }
                (None, Some(_)) => {
                    return Err(self.err(field("absolute"), format!("{} take relative errors only", rules.decks)));
                }
                _ => {
                    let allowed = if rules.parameter_errors == Some(true) {
                        "give relative (a fraction: -0.1 = -10 %) or absolute (in the entries' units), one of them"
                    } else {
                        "give relative (a fraction: -0.1 = -10 %)"
                    };
                    return Err(self.err(field("relative"), allowed));
                }
            };
            let what = what(&prefix, table)?;
            parameter_errors.push(ParameterError { name, model, absolute, value, what });
        }
        Ok((
            MonteCarlo {
                trials,
                fault_free_fraction,
                sampler,
                target_pfa,
                confidence: mc.confidence,
                onset_s,
                noise_scale,
                detection_window_s,
                profile,
                time_to_hazard_s,
                design: None,
                search_point: None,
            },
            Some(own),
            parameter_errors,
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A missing table is named; a missing field of a table that starts the file keeps TOML's message.
    #[test]
    fn a_missing_table_is_named_and_a_missing_field_is_not_taken_for_one() {
        #[derive(Debug, Deserialize)]
        #[allow(dead_code)]
        struct Two {
            study: StudySection,
            noise: toml::Table,
        }
        let path = Path::new("d.toml");
        let text = "# a deck\n[study]\nname = \"x\"\nseed = 1\nduration_s = 1.0\ndt_s = 0.1\n";
        let e = parse_deck::<Two>(text, path).unwrap_err().to_string();
        assert!(e.starts_with("d.toml: [noise]: the deck has no [noise] table; a deck of this kind needs one"), "{e}");
        let text = "[study]\nname = \"x\"\nduration_s = 1.0\ndt_s = 0.1\n[noise]\n";
        let e = parse_deck::<Two>(text, path).unwrap_err().to_string();
        assert!(e.contains("TOML parse error") && e.contains("missing field `seed`"), "{e}");
    }
}
