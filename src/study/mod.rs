//! Study decks: parse (`deck`), then validate into a [`Study`] that cannot be invalid.
//!
//! Every rejection names the file, the field (as a TOML path) and what is allowed.

pub mod accelerometer;
pub mod air_data;
pub mod deck;
pub mod launch;
pub mod surfaces;

use std::path::{Path, PathBuf};

use nalgebra::{DMatrix, DVector};

use serde::{Deserialize, Serialize};

use crate::fault::{FaultMode, SensorFault};
use crate::plant::LtiPlant;
use deck::Deck;

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

/// The shape of an excitation signal on one input.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Shape {
    /// `+amplitude` for the first half of each period, `-amplitude` for the second.
    Square {
        period_s: f64,
    },
    Sine {
        period_s: f64,
    },
    /// `amplitude` from `start_s` on.
    Step,
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Excitation {
    pub input: usize,
    pub shape: Shape,
    pub amplitude: f64,
    pub start_s: f64,
}

impl Excitation {
    /// The signal's value at `t_s` (zero before `start_s`).
    pub fn value(&self, t_s: f64) -> f64 {
        let tau = t_s - self.start_s;
        if tau < 0.0 {
            return 0.0;
        }
        match self.shape {
            Shape::Square { period_s } => {
                if (tau / period_s).fract() < 0.5 {
                    self.amplitude
                } else {
                    -self.amplitude
                }
            }
            Shape::Sine { period_s } => self.amplitude * (std::f64::consts::TAU * tau / period_s).sin(),
            Shape::Step => self.amplitude,
        }
    }
}

/// Detection-filter parameters (method 000).
#[derive(Debug, Clone)]
pub struct DetectionFilterParams {
    /// Continuous-time eigenvalues assigned to the fault directions (1/s), distinct and negative.
    pub eigenvalues_per_s: Vec<f64>,
    /// Fault directions `F` (n x r), one column per eigenvalue.
    pub fault_directions: DMatrix<f64>,
    /// Alarm when `|residual_j| > thresholds[j]` (output units).
    pub thresholds: DVector<f64>,
    /// Isolation looks at the mean residual over `[alarm + delay, alarm + delay + window]`, after the
    /// filter's transient (the slowest eigenvalue's time constant sets a sensible delay).
    pub isolation_delay_s: f64,
    pub isolation_window_s: f64,
}

/// A validated study: every dimension agrees, every number is finite and in range.
#[derive(Debug, Clone)]
pub struct Study {
    pub source: PathBuf,
    pub name: String,
    pub seed: u64,
    pub duration_s: f64,
    pub dt_s: f64,
    /// Number of samples, `round(duration_s / dt_s)`; sample k is at `k * dt_s`.
    pub steps: usize,
    /// The true plant the trial simulates.
    pub plant: LtiPlant,
    /// The model the detector is designed on (equal to `plant` unless the deck says otherwise).
    pub design_plant: LtiPlant,
    pub initial_state: DVector<f64>,
    /// Output feedback `G` (inputs x outputs): `u = u_excitation - G y_measured`.
    pub output_feedback: DMatrix<f64>,
    pub excitations: Vec<Excitation>,
    pub sensor_sigma: DVector<f64>,
    pub process_sigma_per_step: DVector<f64>,
    /// Detector configurations; every one runs on the same trials (same faults, same noise).
    pub detectors: Vec<DetectorConfig>,
    /// Faults of the deck's fixed scenario (`[[faults]]`); used when `monte_carlo.faults` is empty.
    pub faults: Vec<SensorFault>,
    pub monte_carlo: MonteCarlo,
}

/// A named detector configuration.
#[derive(Debug, Clone)]
pub struct DetectorConfig {
    pub name: String,
    pub params: DetectionFilterParams,
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
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FaultKind {
    /// Held at the reading at onset.
    Stuck,
    Gain,
    Bias,
    TotalFailure,
    Drift,
    Oscillation {
        frequency_hz: f64,
    },
}

impl FaultKind {
    pub fn name(&self) -> &'static str {
        match self {
            FaultKind::Stuck => "stuck",
            FaultKind::Gain => "gain",
            FaultKind::Bias => "bias",
            FaultKind::TotalFailure => "total_failure",
            FaultKind::Drift => "drift",
            FaultKind::Oscillation { .. } => "oscillation",
        }
    }

    /// The fault with a given size (output units, or a factor for gain).
    pub fn mode(&self, size: f64) -> FaultMode {
        match *self {
            FaultKind::Stuck => FaultMode::Stuck { value: None },
            FaultKind::Gain => FaultMode::Gain { factor: size },
            FaultKind::Bias => FaultMode::Bias { bias: size },
            FaultKind::TotalFailure => FaultMode::TotalFailure,
            FaultKind::Drift => FaultMode::Drift { rate_per_s: size },
            FaultKind::Oscillation { frequency_hz } => FaultMode::Oscillation { amplitude: size, frequency_hz },
        }
    }
}

/// How a fault kind's size is given.
#[derive(Debug, Clone, PartialEq)]
pub enum SizeSpec {
    /// The kind has no size (stuck at the held value, total failure).
    None,
    /// In the faulty output's units (a factor for gain).
    Output(Factor),
    /// In multiples of the faulty output's nominal sensor sigma (so one spec fits every output).
    SensorSigma(Factor),
}

#[derive(Debug, Clone, PartialEq)]
pub struct FaultKindSpec {
    pub kind: FaultKind,
    pub size: SizeSpec,
}

/// Which model a parameter error perturbs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ModelTarget {
    /// The true plant (the detector's model is then wrong the other way).
    Plant,
    /// The design model: the detector's gains are recomputed per trial for it.
    Design,
}

/// One uncertain physical coefficient: the listed entries of `A` or `B` scaled by `1 + value`
/// (relative) or shifted by `value` (absolute, in the entry's units).
#[derive(Debug, Clone, PartialEq)]
pub struct ParameterError {
    pub name: String,
    pub model: ModelTarget,
    pub matrix_b: bool,
    pub entries: Vec<(usize, usize)>,
    pub absolute: bool,
    pub value: Factor,
}

/// The Monte Carlo part of a study.
#[derive(Debug, Clone, PartialEq)]
pub struct MonteCarlo {
    pub trials: u64,
    /// Probability that a trial has no fault (used to calibrate thresholds).
    pub fault_free_fraction: f64,
    pub sampler: Sampler,
    /// Target false-alarm probability per trial for threshold calibration.
    pub target_pfa: f64,
    /// Outputs a sampled fault may hit.
    pub outputs: Vec<usize>,
    pub onset_s: Factor,
    /// Multiplies every sensor sigma.
    pub noise_scale: Factor,
    /// Sampled fault population; empty: every faulty trial has the deck's fixed `[[faults]]`.
    pub faults: Vec<FaultKindSpec>,
    pub parameter_errors: Vec<ParameterError>,
}

/// A deck file's text; a missing or unreadable file names itself.
pub(crate) fn read_deck(path: &Path) -> Result<String, DeckError> {
    std::fs::read_to_string(path).map_err(|source| DeckError::Read { file: path.into(), source })
}

/// A deck's text parsed into its serde type; TOML errors (unknown fields among them) name the file.
pub(crate) fn parse_deck<T: serde::de::DeserializeOwned>(text: &str, path: &Path) -> Result<T, DeckError> {
    toml::from_str(text)
        .map_err(|e| DeckError::Parse { file: path.into(), message: e.to_string().trim_end().to_string() })
}

/// Which kind of study a deck describes and a results folder holds: the commands dispatch on it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StudyKind {
    /// Method 000: an LTI plant and detection filters (`[plant]` decks).
    #[default]
    DetectionFilter,
    /// Method 004: the UAV with control-surface faults and banks of filters (`[airframe]` decks).
    SurfaceBank,
    /// Method 002: air-data sensor faults and the dual-model UKF (`[flight]` decks).
    AirData,
    /// Method 001: launch-vehicle thrust loss, EKF residual and moving-horizon GLS (`[vehicle]` decks).
    ThrustLoss,
    /// Method 003: accelerometer faults, attitude-EKF residuals and SVM classifiers (`[imu]` decks).
    Accelerometer,
}

impl StudyKind {
    /// The top-level table that marks a deck of this kind.
    pub fn deck_table(self) -> &'static str {
        match self {
            StudyKind::DetectionFilter => "plant",
            StudyKind::SurfaceBank => "airframe",
            StudyKind::AirData => "flight",
            StudyKind::ThrustLoss => "vehicle",
            StudyKind::Accelerometer => "imu",
        }
    }

    /// The kind in words, with its article: "a control-surface" (deck, study).
    pub fn adjective(self) -> &'static str {
        match self {
            StudyKind::DetectionFilter => "a detection-filter",
            StudyKind::SurfaceBank => "a control-surface",
            StudyKind::AirData => "an air-data",
            StudyKind::ThrustLoss => "a launch-vehicle",
            StudyKind::Accelerometer => "an accelerometer",
        }
    }

    /// The seed method a kind studies.
    pub fn method(self) -> &'static str {
        match self {
            StudyKind::DetectionFilter => "000",
            StudyKind::ThrustLoss => "001",
            StudyKind::AirData => "002",
            StudyKind::Accelerometer => "003",
            StudyKind::SurfaceBank => "004",
        }
    }
}

/// Which kind of deck a TOML text is, by the table that marks it (`[airframe]`, `[flight]`,
/// `[vehicle]`, `[imu]`); anything else, unparsable text included, is read as a detection-filter deck, whose
/// parser then names the file, the line and the field.
pub fn deck_kind(text: &str) -> StudyKind {
    let Ok(table) = text.parse::<toml::Table>() else { return StudyKind::DetectionFilter };
    [StudyKind::SurfaceBank, StudyKind::AirData, StudyKind::ThrustLoss, StudyKind::Accelerometer]
        .into_iter()
        .find(|k| table.contains_key(k.deck_table()))
        .unwrap_or(StudyKind::DetectionFilter)
}

impl Study {
    /// Reads, parses and validates a deck file.
    pub fn load(path: &Path) -> Result<Study, DeckError> {
        let text = read_deck(path)?;
        Study::from_toml(&text, path)
    }

    /// Parses and validates deck text; `path` names it in messages.
    pub fn from_toml(text: &str, path: &Path) -> Result<Study, DeckError> {
        let kind = deck_kind(text);
        if kind != StudyKind::DetectionFilter {
            return Err(DeckError::Invalid {
                file: path.into(),
                field: kind.deck_table().into(),
                message: format!(
                    "this is {} deck (method {}); this command reads detection-filter ([plant]) decks only",
                    kind.adjective(),
                    kind.method()
                ),
            });
        }
        let deck: Deck = parse_deck(text, path)?;
        Validator { file: path }.study(deck)
    }
}

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

    fn vector(&self, field: &str, v: &[f64], len: usize, what: &str) -> Result<DVector<f64>, DeckError> {
        if v.len() != len {
            return Err(self.err(field, format!("expected {len} numbers ({what}), got {}", v.len())));
        }
        for (i, &x) in v.iter().enumerate() {
            self.finite(&format!("{field}[{i}]"), x)?;
        }
        Ok(DVector::from_column_slice(v))
    }

    fn matrix(
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

    fn names(&self, field: &str, names: &[String]) -> Result<(), DeckError> {
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
    pub(crate) fn study_section(&self, s: &deck::StudySection) -> Result<(f64, f64, usize), DeckError> {
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

    fn study(&self, deck: Deck) -> Result<Study, DeckError> {
        let s = &deck.study;
        let (duration_s, dt_s, steps) = self.study_section(s)?;

        let p = &deck.plant;
        self.names("plant.states", &p.states)?;
        self.names("plant.inputs", &p.inputs)?;
        self.names("plant.outputs", &p.outputs)?;
        let (n, nu, ny) = (p.states.len(), p.inputs.len(), p.outputs.len());
        let dims = format!("{n} states, {nu} inputs, {ny} outputs");
        let a = self.matrix("plant.a", &p.a, n, n, &format!("n x n, {dims}"))?;
        let b = self.matrix("plant.b", &p.b, n, nu, &format!("n x inputs, {dims}"))?;
        let c = self.matrix("plant.c", &p.c, ny, n, &format!("outputs x n, {dims}"))?;
        let d = match &p.d {
            Some(d) => self.matrix("plant.d", d, ny, nu, &format!("outputs x inputs, {dims}"))?,
            None => DMatrix::zeros(ny, nu),
        };
        let initial_state = match &p.initial_state {
            Some(x0) => self.vector("plant.initial_state", x0, n, "one per state")?,
            None => DVector::zeros(n),
        };
        let plant = LtiPlant {
            state_names: p.states.clone(),
            input_names: p.inputs.clone(),
            output_names: p.outputs.clone(),
            A: a,
            B: b,
            C: c,
            D: d,
        };
        let mut design_plant = plant.clone();
        if let Some(dm) = &deck.design_model {
            if let Some(a) = &dm.a {
                design_plant.A = self.matrix("design_model.a", a, n, n, &format!("n x n, {dims}"))?;
            }
            if let Some(b) = &dm.b {
                design_plant.B = self.matrix("design_model.b", b, n, nu, &format!("n x inputs, {dims}"))?;
            }
        }

        let output_feedback = match &deck.controller {
            Some(cs) => self.matrix(
                "controller.output_feedback",
                &cs.output_feedback,
                nu,
                ny,
                &format!("inputs x outputs, {dims}"),
            )?,
            None => DMatrix::zeros(nu, ny),
        };
        if output_feedback.amax() > 0.0 && plant.D.amax() > 0.0 {
            return Err(self.err(
                "controller.output_feedback",
                "output feedback with a non-zero plant.d is an algebraic loop (u depends on y, y on u): use d = 0 or no controller",
            ));
        }

        let mut excitations = Vec::with_capacity(deck.excitation.len());
        for (i, e) in deck.excitation.iter().enumerate() {
            let field = |f: &str| format!("excitation[{i}].{f}");
            let input = self.index_of(&field("input"), &e.input, &p.inputs, "plant.inputs")?;
            let amplitude = self.finite(&field("amplitude"), e.amplitude)?;
            let start_s = self.finite(&field("start_s"), e.start_s)?;
            let period = |v: Option<f64>| -> Result<f64, DeckError> {
                match v {
                    Some(v) => self.positive(&field("period_s"), v),
                    None => Err(self.err(field("period_s"), format!("required for shape {:?}", e.shape))),
                }
            };
            let shape = match e.shape.as_str() {
                "square" => Shape::Square { period_s: period(e.period_s)? },
                "sine" => Shape::Sine { period_s: period(e.period_s)? },
                "step" => {
                    if e.period_s.is_some() {
                        return Err(self.err(field("period_s"), "not used by shape \"step\": remove it"));
                    }
                    Shape::Step
                }
                other => {
                    return Err(self.err(field("shape"), format!("{other:?}: allowed \"square\", \"sine\", \"step\"")));
                }
            };
            excitations.push(Excitation { input, shape, amplitude, start_s });
        }

        let sensor_sigma =
            self.vector("noise.sensor_sigma", &deck.noise.sensor_sigma, ny, "one per output, output units")?;
        let process_sigma_per_step = match &deck.noise.process_sigma_per_step {
            Some(v) => self.vector("noise.process_sigma_per_step", v, n, "one per state, state units")?,
            None => DVector::zeros(n),
        };
        for (i, &s) in sensor_sigma.iter().chain(process_sigma_per_step.iter()).enumerate() {
            if s < 0.0 {
                let field = if i < ny {
                    format!("noise.sensor_sigma[{i}]")
                } else {
                    format!("noise.process_sigma_per_step[{}]", i - ny)
                };
                return Err(self.err(field, format!("a standard deviation must be >= 0, got {s}")));
            }
        }

        if deck.detector.is_empty() {
            return Err(self.err("detector", "at least one [[detector]] is required"));
        }
        let mut detectors = Vec::with_capacity(deck.detector.len());
        for (i, d) in deck.detector.iter().enumerate() {
            let field = format!("detector[{i}].name");
            if d.name.is_empty() || !d.name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-') {
                return Err(self.err(field, format!("{:?}: use letters, digits, '_' and '-'", d.name)));
            }
            if deck.detector[..i].iter().any(|o| o.name == d.name) {
                return Err(self.err(field, format!("{:?} appears twice", d.name)));
            }
            detectors.push(DetectorConfig { name: d.name.clone(), params: self.detector(i, d, &plant)? });
        }

        let mut faults = Vec::with_capacity(deck.faults.len());
        for (i, f) in deck.faults.iter().enumerate() {
            faults.push(self.fault(i, f, &p.outputs)?);
        }
        let monte_carlo = self.monte_carlo(deck.monte_carlo.as_ref(), &plant, duration_s)?;
        if !monte_carlo.faults.is_empty() && !faults.is_empty() {
            return Err(self.err(
                "faults",
                "give either a fixed scenario ([[faults]]) or a sampled population ([[monte_carlo.fault]]), not both",
            ));
        }

        Ok(Study {
            source: self.file.into(),
            name: s.name.clone(),
            seed: s.seed,
            duration_s,
            dt_s,
            steps,
            plant,
            design_plant,
            initial_state,
            output_feedback,
            excitations,
            sensor_sigma,
            process_sigma_per_step,
            detectors,
            faults,
            monte_carlo,
        })
    }

    fn detector(
        &self,
        i: usize,
        d: &deck::DetectorSection,
        plant: &LtiPlant,
    ) -> Result<DetectionFilterParams, DeckError> {
        let f = |name: &str| format!("detector[{i}].{name}");
        if d.kind != "detection_filter" {
            return Err(self.err(f("kind"), format!("{:?}: allowed \"detection_filter\" (method 000)", d.kind)));
        }
        let (n, ny) = (plant.n_states(), plant.n_outputs());
        let r = d.eigenvalues_per_s.len();
        if r == 0 || r > n {
            return Err(self.err(
                f("eigenvalues_per_s"),
                format!("expected 1 to {n} eigenvalues (one per fault direction), got {r}"),
            ));
        }
        for (k, &l) in d.eigenvalues_per_s.iter().enumerate() {
            let field = f(&format!("eigenvalues_per_s[{k}]"));
            if !(l.is_finite() && l < 0.0) {
                return Err(self.err(
                    field,
                    format!("must be a finite negative number (a stable continuous-time eigenvalue, 1/s), got {l}"),
                ));
            }
        }
        let fault_directions = match &d.fault_directions {
            // Listed as r vectors f_i of length n: the columns of F.
            Some(dirs) => self
                .matrix(&f("fault_directions"), dirs, r, n, &format!("one direction of {n} numbers per eigenvalue"))?
                .transpose(),
            None if r == n => DMatrix::identity(n, n),
            None => {
                return Err(self.err(
                    f("fault_directions"),
                    format!("required when there are fewer eigenvalues ({r}) than states ({n})"),
                ));
            }
        };
        let thresholds = self.vector(&f("thresholds"), &d.thresholds, ny, "one per output, output units")?;
        for (k, &t) in thresholds.iter().enumerate() {
            if t <= 0.0 {
                return Err(self.err(f(&format!("thresholds[{k}]")), format!("must be > 0, got {t}")));
            }
        }
        let slowest_time_constant_s = 1.0 / d.eigenvalues_per_s.iter().fold(f64::INFINITY, |m, l| m.min(-l));
        let isolation_delay_s = match d.isolation_delay_s {
            Some(v) if v.is_finite() && v >= 0.0 => v,
            Some(v) => return Err(self.err(f("isolation_delay_s"), format!("must be a finite number >= 0, got {v}"))),
            None => 3.0 * slowest_time_constant_s,
        };
        let isolation_window_s = match d.isolation_window_s {
            Some(v) => self.positive(&f("isolation_window_s"), v)?,
            None => slowest_time_constant_s,
        };
        Ok(DetectionFilterParams {
            eigenvalues_per_s: d.eigenvalues_per_s.clone(),
            fault_directions,
            thresholds,
            isolation_delay_s,
            isolation_window_s,
        })
    }

    /// Reads a factor (see [`Factor`]); `None` gives `default`.
    pub(crate) fn factor(
        &self,
        field: &str,
        spec: Option<&deck::FactorSpec>,
        default: Factor,
    ) -> Result<Factor, DeckError> {
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

    /// A trial count: 1 to [`crate::sampling::MAX_TRIAL`].
    pub(crate) fn trials(&self, field: &str, n: u64) -> Result<u64, DeckError> {
        if n == 0 || n > crate::sampling::MAX_TRIAL {
            return Err(self.err(field, format!("allowed 1 to {}, got {n}", crate::sampling::MAX_TRIAL)));
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

    /// One `[[monte_carlo.fault]]` population (the same syntax in every deck with sensor faults).
    pub(crate) fn fault_kind_spec(&self, prefix: &str, f: &deck::FaultKindSection) -> Result<FaultKindSpec, DeckError> {
        let field = |name: &str| format!("{prefix}.{name}");
        if f.frequency_hz.is_some() && f.kind != "oscillation" {
            return Err(self.err(field("frequency_hz"), format!("only used by kind \"oscillation\", not {:?}", f.kind)));
        }
        let kind = match f.kind.as_str() {
            "stuck" => FaultKind::Stuck,
            "gain" => FaultKind::Gain,
            "bias" => FaultKind::Bias,
            "total_failure" => FaultKind::TotalFailure,
            "drift" => FaultKind::Drift,
            "oscillation" => match f.frequency_hz {
                Some(v) => FaultKind::Oscillation { frequency_hz: self.positive(&field("frequency_hz"), v)? },
                None => return Err(self.err(field("frequency_hz"), "required for kind \"oscillation\"")),
            },
            other => {
                return Err(self.err(field("kind"), format!("{other:?}: allowed \"stuck\" (held at onset), \"gain\", \"bias\", \"total_failure\", \"drift\", \"oscillation\"")));
            }
        };
        let sized = !matches!(kind, FaultKind::Stuck | FaultKind::TotalFailure);
        let size =
            match (sized, &f.size, &f.size_sigma) {
                (false, None, None) => SizeSpec::None,
                (false, _, _) => {
                    return Err(
                        self.err(field("size"), format!("kind {:?} has no size: remove size and size_sigma", f.kind))
                    );
                }
                (true, Some(_), Some(_)) => {
                    return Err(self.err(field("size_sigma"), "give size or size_sigma, not both"));
                }
                (true, None, None) => return Err(self.err(
                    field("size"),
                    format!(
                        "kind {:?} needs size (output units) or size_sigma (multiples of the output's sensor sigma)",
                        f.kind
                    ),
                )),
                (true, Some(v), None) => SizeSpec::Output(self.factor(&field("size"), Some(v), Factor::Fixed(0.0))?),
                (true, None, Some(v)) => {
                    if kind == FaultKind::Gain {
                        return Err(self.err(field("size_sigma"), "a gain is a factor: use size"));
                    }
                    SizeSpec::SensorSigma(self.factor(&field("size_sigma"), Some(v), Factor::Fixed(0.0))?)
                }
            };
        if kind == FaultKind::Gain {
            if let SizeSpec::Output(factor) = &size {
                self.factor_within(&field("size"), factor, |v| v != 1.0, "gain factors != 1")?;
            }
        }
        Ok(FaultKindSpec { kind, size })
    }

    fn monte_carlo(
        &self,
        mc: Option<&deck::MonteCarloSection>,
        plant: &LtiPlant,
        duration_s: f64,
    ) -> Result<MonteCarlo, DeckError> {
        let Some(mc) = mc else {
            return Ok(MonteCarlo {
                trials: 1000,
                fault_free_fraction: 0.0,
                sampler: Sampler::Random,
                target_pfa: 0.01,
                outputs: (0..plant.n_outputs()).collect(),
                onset_s: Factor::Fixed(0.0),
                noise_scale: Factor::Fixed(1.0),
                faults: Vec::new(),
                parameter_errors: Vec::new(),
            });
        };
        self.trials("monte_carlo.trials", mc.trials)?;
        let fraction = self.fraction("monte_carlo.fault_free_fraction", mc.fault_free_fraction)?;
        let sampler = self.sampler("monte_carlo.sampler", mc.sampler.as_deref())?;
        let target_pfa = mc.target_pfa.unwrap_or(0.01);
        if !(target_pfa > 0.0 && target_pfa < 1.0) {
            return Err(self.err("monte_carlo.target_pfa", format!("allowed 0 < p < 1, got {target_pfa}")));
        }
        let outputs = match &mc.outputs {
            None => (0..plant.n_outputs()).collect(),
            Some(names) if names.is_empty() => return Err(self.err("monte_carlo.outputs", "name at least one output")),
            Some(names) => names
                .iter()
                .enumerate()
                .map(|(k, n)| {
                    self.index_of(&format!("monte_carlo.outputs[{k}]"), n, &plant.output_names, "plant.outputs")
                })
                .collect::<Result<Vec<_>, _>>()?,
        };
        let onset_s = self.factor("monte_carlo.onset_s", mc.onset_s.as_ref(), Factor::Fixed(duration_s / 3.0))?;
        self.factor_within(
            "monte_carlo.onset_s",
            &onset_s,
            |v| v >= 0.0 && v < duration_s,
            &format!("0 <= onset_s < duration_s = {duration_s}"),
        )?;
        let noise_scale = self.factor("monte_carlo.noise_scale", mc.noise_scale.as_ref(), Factor::Fixed(1.0))?;
        self.factor_within("monte_carlo.noise_scale", &noise_scale, |v| v >= 0.0, ">= 0")?;

        let faults = mc
            .fault
            .iter()
            .enumerate()
            .map(|(i, f)| self.fault_kind_spec(&format!("monte_carlo.fault[{i}]"), f))
            .collect::<Result<Vec<_>, _>>()?;

        let mut parameter_errors = Vec::with_capacity(mc.parameter_error.len());
        for (i, pe) in mc.parameter_error.iter().enumerate() {
            let field = |name: &str| format!("monte_carlo.parameter_error[{i}].{name}");
            self.column_name(&field("name"), &pe.name, mc.parameter_error[..i].iter().map(|o| o.name.as_str()))?;
            let model = self.model_target(&field("model"), &pe.model)?;
            let (matrix_b, col_names, col_list) = match pe.matrix.as_str() {
                "a" => (false, &plant.state_names, "plant.states"),
                "b" => (true, &plant.input_names, "plant.inputs"),
                other => return Err(self.err(field("matrix"), format!("{other:?}: allowed \"a\" or \"b\""))),
            };
            if pe.entries.is_empty() {
                return Err(self.err(field("entries"), "list at least one [row, column] pair of names"));
            }
            let mut entries = Vec::with_capacity(pe.entries.len());
            for (k, (row, col)) in pe.entries.iter().enumerate() {
                let f = field(&format!("entries[{k}]"));
                let r = self.index_of(&f, row, &plant.state_names, "plant.states (rows)")?;
                let c = self.index_of(&f, col, col_names, col_list)?;
                entries.push((r, c));
            }
            let (absolute, value) = match (&pe.relative, &pe.absolute) {
                (Some(r), None) => {
                    let v = self.factor(&field("relative"), Some(r), Factor::Fixed(0.0))?;
                    self.factor_within(&field("relative"), &v, |x| x > -1.0 && x < 10.0, "-1 < relative < 10")?;
                    (false, v)
                }
                (None, Some(a)) => (true, self.factor(&field("absolute"), Some(a), Factor::Fixed(0.0))?),
                _ => {
                    return Err(self.err(
                        field("relative"),
                        "give relative (a fraction: -0.1 = -10 %) or absolute (in the entries' units), one of them",
                    ));
                }
            };
            parameter_errors.push(ParameterError { name: pe.name.clone(), model, matrix_b, entries, absolute, value });
        }

        Ok(MonteCarlo {
            trials: mc.trials,
            fault_free_fraction: fraction,
            sampler,
            target_pfa,
            outputs,
            onset_s,
            noise_scale,
            faults,
            parameter_errors,
        })
    }

    pub(crate) fn fault(&self, i: usize, f: &deck::FaultSection, outputs: &[String]) -> Result<SensorFault, DeckError> {
        let field = |name: &str| format!("faults[{i}].{name}");
        let channel = self.index_of(&field("output"), &f.output, outputs, "plant.outputs")?;
        let onset_s = self.finite(&field("onset_s"), f.onset_s)?;
        if onset_s < 0.0 {
            return Err(self.err(field("onset_s"), format!("must be >= 0, got {onset_s}")));
        }
        let size = match f.size {
            Some(v) => Some(self.finite(&field("size"), v)?),
            None => None,
        };
        let need_size = || size.ok_or_else(|| self.err(field("size"), format!("required for kind {:?}", f.kind)));
        if f.frequency_hz.is_some() && f.kind != "oscillation" {
            return Err(self.err(field("frequency_hz"), format!("only used by kind \"oscillation\", not {:?}", f.kind)));
        }
        let mode = match f.kind.as_str() {
            "stuck" => FaultMode::Stuck { value: size },
            "gain" => {
                let factor = need_size()?;
                if factor == 1.0 {
                    return Err(self.err(field("size"), "a gain fault needs a factor != 1"));
                }
                FaultMode::Gain { factor }
            }
            "bias" => {
                let bias = need_size()?;
                if bias == 0.0 {
                    return Err(self.err(field("size"), "a bias fault needs a bias != 0"));
                }
                FaultMode::Bias { bias }
            }
            "total_failure" => {
                if size.is_some() {
                    return Err(
                        self.err(field("size"), "not used by kind \"total_failure\" (the output is 0): remove it")
                    );
                }
                FaultMode::TotalFailure
            }
            "drift" => FaultMode::Drift { rate_per_s: need_size()? },
            "oscillation" => {
                let frequency_hz = match f.frequency_hz {
                    Some(v) => self.positive(&field("frequency_hz"), v)?,
                    None => return Err(self.err(field("frequency_hz"), "required for kind \"oscillation\"")),
                };
                FaultMode::Oscillation { amplitude: need_size()?, frequency_hz }
            }
            other => {
                return Err(self.err(
                    field("kind"),
                    format!("{other:?}: allowed \"stuck\", \"gain\", \"bias\", \"total_failure\", \"drift\", \"oscillation\""),
                ));
            }
        };
        Ok(SensorFault { channel, onset_s, mode })
    }
}
