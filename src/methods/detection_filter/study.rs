//! Detection-filter decks (method 000): the `[plant]` deck validated into a [`LtiStudy`] that cannot be invalid.

use std::path::Path;

use nalgebra::{DMatrix, DVector};

use super::decision::Decision;
use super::deck::Deck;
use serde::Deserialize;

use crate::engine::deck::{
    DeckError, FromDeck, MonteCarlo, MonteCarloRules, MonteCarloSection, StudyHeader, Validator, parse_deck,
};
use crate::fault::SensorFault;
use crate::fault::deck::FaultKindSpec;
use crate::lti::LtiPlant;

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
    /// Alarm when output j's statistic ([`Decision`]) exceeds `thresholds[j]`.
    pub thresholds: DVector<f64>,
    /// The test the residual meets: `|residual|` for `kind = "detection_filter"`, a CUSUM for `"cusum"`.
    pub decision: Decision,
    /// `kind = "kalman_chi2"`: the gain is the steady-state Kalman filter's, not an eigenstructure.
    pub kalman: Option<KalmanParams>,
    /// Isolation looks at the mean residual over `[alarm + delay, alarm + delay + window]`, after the
    /// filter's transient (the slowest eigenvalue's time constant sets a sensible delay).
    pub isolation_delay_s: f64,
    pub isolation_window_s: f64,
}

/// The noise a `kind = "kalman_chi2"` filter is designed for (covariances per step).
#[derive(Debug, Clone)]
pub struct KalmanParams {
    pub process_covariance: DMatrix<f64>,
    pub sensor_covariance: DMatrix<f64>,
}

/// A validated study: every dimension agrees, every number is finite and in range.
#[derive(Debug, Clone)]
pub struct LtiStudy {
    pub header: StudyHeader,
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
    pub monte_carlo: LtiMonteCarlo,
}

/// A named detector configuration.
#[derive(Debug, Clone)]
pub struct DetectorConfig {
    pub name: String,
    pub params: DetectionFilterParams,
}

/// What a parameter error perturbs: entries of `A` (or `B`), scaled by `1 + value` (relative) or shifted
/// by `value` (absolute, in the entry's units).
#[derive(Debug, Clone, PartialEq)]
pub struct MatrixEntries {
    pub matrix_b: bool,
    pub entries: Vec<(usize, usize)>,
}

pub type ParameterError = crate::engine::deck::ParameterError<MatrixEntries>;

/// The Monte Carlo part of a study.
#[derive(Debug, Clone, PartialEq)]
pub struct LtiMonteCarlo {
    pub common: MonteCarlo,
    /// Outputs a sampled fault may hit.
    pub outputs: Vec<usize>,
    /// Sampled fault population; empty: every faulty trial has the deck's fixed `[[faults]]`.
    pub faults: Vec<FaultKindSpec>,
    pub parameter_errors: Vec<ParameterError>,
}

impl FromDeck for LtiStudy {
    fn from_toml(text: &str, path: &Path) -> Result<LtiStudy, DeckError> {
        let deck: Deck = parse_deck(text, path)?;
        study(&Validator { file: path }, deck)
    }
}

fn study(chk: &Validator, deck: Deck) -> Result<LtiStudy, DeckError> {
    let s = &deck.study;
    let header = chk.study_section(s)?;
    let (duration_s, _dt_s) = (header.duration_s, header.dt_s);

    let p = &deck.plant;
    chk.names("plant.states", &p.states)?;
    chk.names("plant.inputs", &p.inputs)?;
    chk.names("plant.outputs", &p.outputs)?;
    let (n, nu, ny) = (p.states.len(), p.inputs.len(), p.outputs.len());
    let dims = format!("{n} states, {nu} inputs, {ny} outputs");
    let a = chk.matrix("plant.a", &p.a, n, n, &format!("n x n, {dims}"))?;
    let b = chk.matrix("plant.b", &p.b, n, nu, &format!("n x inputs, {dims}"))?;
    let c = chk.matrix("plant.c", &p.c, ny, n, &format!("outputs x n, {dims}"))?;
    let d = match &p.d {
        Some(d) => chk.matrix("plant.d", d, ny, nu, &format!("outputs x inputs, {dims}"))?,
        None => DMatrix::zeros(ny, nu),
    };
    let initial_state = match &p.initial_state {
        Some(x0) => chk.vector("plant.initial_state", x0, n, "one per state")?,
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
            design_plant.A = chk.matrix("design_model.a", a, n, n, &format!("n x n, {dims}"))?;
        }
        if let Some(b) = &dm.b {
            design_plant.B = chk.matrix("design_model.b", b, n, nu, &format!("n x inputs, {dims}"))?;
        }
    }

    let output_feedback = match &deck.controller {
        Some(cs) => {
            chk.matrix("controller.output_feedback", &cs.output_feedback, nu, ny, &format!("inputs x outputs, {dims}"))?
        }
        None => DMatrix::zeros(nu, ny),
    };
    if output_feedback.amax() > 0.0 && plant.D.amax() > 0.0 {
        return Err(chk.err(
            "controller.output_feedback",
            "output feedback with a non-zero plant.d is an algebraic loop (u depends on y, y on u): use d = 0 or no controller",
        ));
    }

    let mut excitations = Vec::with_capacity(deck.excitation.len());
    for (i, e) in deck.excitation.iter().enumerate() {
        let field = |f: &str| format!("excitation[{i}].{f}");
        let input = chk.index_of(&field("input"), &e.input, &p.inputs, "plant.inputs")?;
        let amplitude = chk.finite(&field("amplitude"), e.amplitude)?;
        let start_s = chk.finite(&field("start_s"), e.start_s)?;
        let period = |v: Option<f64>| -> Result<f64, DeckError> {
            match v {
                Some(v) => chk.positive(&field("period_s"), v),
                None => Err(chk.err(field("period_s"), format!("required for shape {:?}", e.shape))),
            }
        };
        let shape = match e.shape.as_str() {
            "square" => Shape::Square { period_s: period(e.period_s)? },
            "sine" => Shape::Sine { period_s: period(e.period_s)? },
            "step" => {
                if e.period_s.is_some() {
                    return Err(chk.err(field("period_s"), "not used by shape \"step\": remove it"));
                }
                Shape::Step
            }
            other => {
                return Err(chk.err(field("shape"), format!("{other:?}: allowed \"square\", \"sine\", \"step\"")));
            }
        };
        excitations.push(Excitation { input, shape, amplitude, start_s });
    }

    let sensor_sigma =
        chk.vector("noise.sensor_sigma", &deck.noise.sensor_sigma, ny, "one per output, output units")?;
    let process_sigma_per_step = match &deck.noise.process_sigma_per_step {
        Some(v) => chk.vector("noise.process_sigma_per_step", v, n, "one per state, state units")?,
        None => DVector::zeros(n),
    };
    for (i, &s) in sensor_sigma.iter().chain(process_sigma_per_step.iter()).enumerate() {
        if s < 0.0 {
            let field = if i < ny {
                format!("noise.sensor_sigma[{i}]")
            } else {
                format!("noise.process_sigma_per_step[{}]", i - ny)
            };
            return Err(chk.err(field, format!("a standard deviation must be >= 0, got {s}")));
        }
    }

    if deck.detector.is_empty() {
        return Err(chk.err("detector", "at least one [[detector]] is required"));
    }
    let mut detectors = Vec::with_capacity(deck.detector.len());
    for (i, d) in deck.detector.iter().enumerate() {
        let field = format!("detector[{i}].name");
        if d.name.is_empty() || !d.name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-') {
            return Err(chk.err(field, format!("{:?}: use letters, digits, '_' and '-'", d.name)));
        }
        if deck.detector[..i].iter().any(|o| o.name == d.name) {
            return Err(chk.err(field, format!("{:?} appears twice", d.name)));
        }
        let params = if d.kind == "kalman_chi2" {
            kalman_detector(chk, i, d, &plant, &sensor_sigma)?
        } else {
            detector(chk, i, d, &plant)?
        };
        detectors.push(DetectorConfig { name: d.name.clone(), params });
    }

    let mut faults = Vec::with_capacity(deck.faults.len());
    for (i, f) in deck.faults.iter().enumerate() {
        faults.push(chk.fault(i, f, &p.outputs)?);
    }
    let monte_carlo = monte_carlo(chk, deck.monte_carlo, &plant, duration_s)?;
    if !monte_carlo.faults.is_empty() && !faults.is_empty() {
        return Err(chk.err(
            "faults",
            "give either a fixed scenario ([[faults]]) or a sampled population ([[monte_carlo.fault]]), not both",
        ));
    }

    Ok(LtiStudy {
        header,
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
    chk: &Validator,
    i: usize,
    d: &super::deck::DetectorSection,
    plant: &LtiPlant,
) -> Result<DetectionFilterParams, DeckError> {
    let f = |name: &str| format!("detector[{i}].{name}");
    let (n, ny) = (plant.n_states(), plant.n_outputs());
    refuse(
        chk,
        i,
        &[
            ("window", d.window.is_some()),
            ("false_alarm_probability", d.false_alarm_probability.is_some()),
            ("design_process_sigma_per_step", d.design_process_sigma_per_step.is_some()),
        ],
        "applies to kind = \"kalman_chi2\" only",
    )?;
    let eigenvalues = d.eigenvalues_per_s.as_ref().ok_or_else(|| {
        chk.err(f("eigenvalues_per_s"), format!("required for kind = {:?}: the filter's eigenvalues (1/s)", d.kind))
    })?;
    let given_thresholds = d.thresholds.as_ref().ok_or_else(|| {
        chk.err(f("thresholds"), format!("required for kind = {:?}: {ny} numbers, one per output", d.kind))
    })?;
    let decision = match (d.kind.as_str(), &d.drift) {
        ("detection_filter", None) => Decision::Absolute,
        ("detection_filter", Some(_)) => {
            return Err(chk.err(f("drift"), "applies to kind = \"cusum\" only (a CUSUM's allowance per sample)"));
        }
        ("cusum", Some(drift)) => {
            let drift = chk.vector(&f("drift"), drift, ny, "one per output, output units per sample")?;
            for (k, &v) in drift.iter().enumerate() {
                if v < 0.0 {
                    return Err(chk.err(f(&format!("drift[{k}]")), format!("must be >= 0, got {v}")));
                }
            }
            Decision::Cusum { drift: drift.iter().copied().collect() }
        }
        ("cusum", None) => {
            return Err(chk.err(
                f("drift"),
                format!("required for kind = \"cusum\": {ny} numbers, the residual each output may carry per sample without counting as evidence"),
            ));
        }
        (other, _) => {
            return Err(chk.err(
                f("kind"),
                format!("{other:?}: allowed \"detection_filter\" (method 000, alarm on |residual|), \"cusum\" (the same filter, a CUSUM on |residual|) or \"kalman_chi2\" (a steady-state Kalman filter's windowed chi-square test)"),
            ));
        }
    };
    let r = eigenvalues.len();
    if r == 0 || r > n {
        return Err(chk
            .err(f("eigenvalues_per_s"), format!("expected 1 to {n} eigenvalues (one per fault direction), got {r}")));
    }
    for (k, &l) in eigenvalues.iter().enumerate() {
        let field = f(&format!("eigenvalues_per_s[{k}]"));
        if !(l.is_finite() && l < 0.0) {
            return Err(chk.err(
                field,
                format!("must be a finite negative number (a stable continuous-time eigenvalue, 1/s), got {l}"),
            ));
        }
    }
    let fault_directions = match &d.fault_directions {
        // Listed as r vectors f_i of length n: the columns of F.
        Some(dirs) => chk
            .matrix(&f("fault_directions"), dirs, r, n, &format!("one direction of {n} numbers per eigenvalue"))?
            .transpose(),
        None if r == n => DMatrix::identity(n, n),
        None => {
            return Err(chk.err(
                f("fault_directions"),
                format!("required when there are fewer eigenvalues ({r}) than states ({n})"),
            ));
        }
    };
    let thresholds = chk.vector(&f("thresholds"), given_thresholds, ny, "one per output, output units")?;
    for (k, &t) in thresholds.iter().enumerate() {
        if t <= 0.0 {
            return Err(chk.err(f(&format!("thresholds[{k}]")), format!("must be > 0, got {t}")));
        }
    }
    let slowest_time_constant_s = 1.0 / eigenvalues.iter().fold(f64::INFINITY, |m, l| m.min(-l));
    let isolation_delay_s = match d.isolation_delay_s {
        Some(v) if v.is_finite() && v >= 0.0 => v,
        Some(v) => return Err(chk.err(f("isolation_delay_s"), format!("must be a finite number >= 0, got {v}"))),
        None => 3.0 * slowest_time_constant_s,
    };
    let isolation_window_s = match d.isolation_window_s {
        Some(v) => chk.positive(&f("isolation_window_s"), v)?,
        None => slowest_time_constant_s,
    };
    Ok(DetectionFilterParams {
        eigenvalues_per_s: eigenvalues.clone(),
        fault_directions,
        thresholds,
        decision,
        kalman: None,
        isolation_delay_s,
        isolation_window_s,
    })
}

/// Refuses, with `why`, the first of detector `i`'s `fields` that is given.
fn refuse(chk: &Validator, i: usize, fields: &[(&str, bool)], why: &str) -> Result<(), DeckError> {
    match fields.iter().find(|(_, given)| *given) {
        Some((field, _)) => Err(chk.err(format!("detector[{i}].{field}"), why)),
        None => Ok(()),
    }
}

/// `kind = "kalman_chi2"`: the textbook innovation test. A steady-state Kalman filter designed from the
/// deck's sensor noise and the detector's design process noise; alarm when the normalised innovation
/// squared summed over `window` samples exceeds the chi-square(window x outputs) quantile at
/// `false_alarm_probability` per window; isolation by the largest normalised innovation.
fn kalman_detector(
    chk: &Validator,
    i: usize,
    d: &super::deck::DetectorSection,
    plant: &LtiPlant,
    sensor_sigma: &DVector<f64>,
) -> Result<DetectionFilterParams, DeckError> {
    use statrs::distribution::{ChiSquared, ContinuousCDF};
    let f = |name: &str| format!("detector[{i}].{name}");
    let (n, ny) = (plant.n_states(), plant.n_outputs());
    refuse(
        chk,
        i,
        &[
            ("eigenvalues_per_s", d.eigenvalues_per_s.is_some()),
            ("fault_directions", d.fault_directions.is_some()),
            ("thresholds", d.thresholds.is_some()),
            ("drift", d.drift.is_some()),
        ],
        "does not apply to kind = \"kalman_chi2\" (its gain is the Kalman filter's, its threshold the chi-square quantile)",
    )?;
    let window = match d.window {
        Some(w) if (1..=10_000).contains(&w) => w,
        Some(w) => return Err(chk.err(f("window"), format!("allowed 1 to 10000 samples, got {w}"))),
        None => return Err(chk.err(f("window"), "required for kind = \"kalman_chi2\": the samples summed")),
    };
    let pfa = match d.false_alarm_probability {
        Some(p) if p > 0.0 && p < 1.0 => p,
        Some(p) => {
            return Err(chk.err(f("false_alarm_probability"), format!("allowed 0 < p < 1 (per window), got {p}")));
        }
        None => {
            return Err(chk.err(
                f("false_alarm_probability"),
                "required for kind = \"kalman_chi2\": the chi-square test's false-alarm probability per window",
            ));
        }
    };
    let q = d.design_process_sigma_per_step.as_ref().ok_or_else(|| {
        chk.err(
            f("design_process_sigma_per_step"),
            format!(
                "required for kind = \"kalman_chi2\": {n} numbers >= 0, the process noise per step the filter assumes"
            ),
        )
    })?;
    let q = chk.vector(&f("design_process_sigma_per_step"), q, n, "one per state, state units per step")?;
    if let Some(k) = q.iter().position(|v| *v < 0.0) {
        return Err(chk.err(f(&format!("design_process_sigma_per_step[{k}]")), format!("must be >= 0, got {}", q[k])));
    }
    let dof = (window * ny) as f64;
    let quantile = ChiSquared::new(dof).map(|c| c.inverse_cdf(1.0 - pfa)).unwrap_or(f64::NAN);
    if !(quantile.is_finite() && quantile > 0.0) {
        return Err(chk.err(f("false_alarm_probability"), format!("{pfa}: no chi-square({dof}) quantile")));
    }
    let isolation_delay_s = match d.isolation_delay_s {
        Some(v) if v.is_finite() && v >= 0.0 => v,
        Some(v) => return Err(chk.err(f("isolation_delay_s"), format!("must be a finite number >= 0, got {v}"))),
        None => 0.0,
    };
    let isolation_window_s = match d.isolation_window_s {
        Some(v) => chk.positive(&f("isolation_window_s"), v)?,
        None => 1.0,
    };
    Ok(DetectionFilterParams {
        eigenvalues_per_s: Vec::new(),
        fault_directions: DMatrix::zeros(n, 0),
        thresholds: DVector::from_element(ny, quantile),
        decision: Decision::Nis { window, s_inv: DMatrix::zeros(0, 0) },
        kalman: Some(KalmanParams {
            process_covariance: DMatrix::from_diagonal(&q.map(|s| s * s)),
            sensor_covariance: DMatrix::from_diagonal(&sensor_sigma.map(|s| s * s)),
        }),
        isolation_delay_s,
        isolation_window_s,
    })
}

/// `[monte_carlo]`'s own fields in detection-filter decks.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct MonteCarloOwn {
    outputs: Option<Vec<String>>,
    #[serde(default)]
    fault: Vec<crate::fault::deck::FaultKindSection>,
}

/// What a parameter error perturbs, as decks write it.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct MatrixEntriesSection {
    matrix: String,
    entries: Vec<(String, String)>,
}

fn monte_carlo(
    chk: &Validator,
    mc: Option<MonteCarloSection>,
    plant: &LtiPlant,
    duration_s: f64,
) -> Result<LtiMonteCarlo, DeckError> {
    let rules = MonteCarloRules {
        target_pfa: true,
        parameter_errors: Some(true),
        ..MonteCarloRules::sampled("detection-filter decks", duration_s)
    };
    let (common, own, parameter_errors) = chk.monte_carlo(mc, &rules, |prefix, table| {
        let field = |name: &str| format!("{prefix}.{name}");
        let pe: MatrixEntriesSection =
            toml::Value::Table(table).try_into().map_err(|e| chk.err(prefix, e.to_string().trim_end().to_string()))?;
        let (matrix_b, col_names, col_list) = match pe.matrix.as_str() {
            "a" => (false, &plant.state_names, "plant.states"),
            "b" => (true, &plant.input_names, "plant.inputs"),
            other => return Err(chk.err(field("matrix"), format!("{other:?}: allowed \"a\" or \"b\""))),
        };
        if pe.entries.is_empty() {
            return Err(chk.err(field("entries"), "list at least one [row, column] pair of names"));
        }
        let mut entries = Vec::with_capacity(pe.entries.len());
        for (k, (row, col)) in pe.entries.iter().enumerate() {
            let f = field(&format!("entries[{k}]"));
            let r = chk.index_of(&f, row, &plant.state_names, "plant.states (rows)")?;
            let c = chk.index_of(&f, col, col_names, col_list)?;
            entries.push((r, c));
        }
        Ok(MatrixEntries { matrix_b, entries })
    })?;
    let own: MonteCarloOwn = own.unwrap_or(MonteCarloOwn { outputs: None, fault: Vec::new() });
    let outputs = match &own.outputs {
        None => (0..plant.n_outputs()).collect(),
        Some(names) if names.is_empty() => return Err(chk.err("monte_carlo.outputs", "name at least one output")),
        Some(names) => names
            .iter()
            .enumerate()
            .map(|(k, n)| chk.index_of(&format!("monte_carlo.outputs[{k}]"), n, &plant.output_names, "plant.outputs"))
            .collect::<Result<Vec<_>, _>>()?,
    };
    let faults = own
        .fault
        .iter()
        .enumerate()
        .map(|(i, f)| chk.fault_kind_spec(&format!("monte_carlo.fault[{i}]"), f))
        .collect::<Result<Vec<_>, _>>()?;
    Ok(LtiMonteCarlo { common, outputs, faults, parameter_errors })
}
