//! Detection-filter decks (method 000): the `[plant]` deck validated into a [`LtiStudy`] that cannot be invalid.

use std::path::{Path, PathBuf};

use nalgebra::{DMatrix, DVector};

use super::deck::Deck;
use crate::engine::deck::{DeckError, Factor, ModelTarget, Sampler, Validator, parse_deck, read_deck};
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
    /// Alarm when `|residual_j| > thresholds[j]` (output units).
    pub thresholds: DVector<f64>,
    /// Isolation looks at the mean residual over `[alarm + delay, alarm + delay + window]`, after the
    /// filter's transient (the slowest eigenvalue's time constant sets a sensible delay).
    pub isolation_delay_s: f64,
    pub isolation_window_s: f64,
}

/// A validated study: every dimension agrees, every number is finite and in range.
#[derive(Debug, Clone)]
pub struct LtiStudy {
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

impl LtiStudy {
    /// Reads, parses and validates a deck file.
    pub fn load(path: &Path) -> Result<LtiStudy, DeckError> {
        let text = read_deck(path)?;
        LtiStudy::from_toml(&text, path)
    }

    /// Parses and validates deck text; `path` names it in messages.
    pub fn from_toml(text: &str, path: &Path) -> Result<LtiStudy, DeckError> {
        let deck: Deck = parse_deck(text, path)?;
        study(&Validator { file: path }, deck)
    }
}

fn study(chk: &Validator, deck: Deck) -> Result<LtiStudy, DeckError> {
    let s = &deck.study;
    let (duration_s, dt_s, steps) = chk.study_section(s)?;

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
        detectors.push(DetectorConfig { name: d.name.clone(), params: detector(chk, i, d, &plant)? });
    }

    let mut faults = Vec::with_capacity(deck.faults.len());
    for (i, f) in deck.faults.iter().enumerate() {
        faults.push(chk.fault(i, f, &p.outputs)?);
    }
    let monte_carlo = monte_carlo(chk, deck.monte_carlo.as_ref(), &plant, duration_s)?;
    if !monte_carlo.faults.is_empty() && !faults.is_empty() {
        return Err(chk.err(
            "faults",
            "give either a fixed scenario ([[faults]]) or a sampled population ([[monte_carlo.fault]]), not both",
        ));
    }

    Ok(LtiStudy {
        source: chk.file.into(),
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
    chk: &Validator,
    i: usize,
    d: &super::deck::DetectorSection,
    plant: &LtiPlant,
) -> Result<DetectionFilterParams, DeckError> {
    let f = |name: &str| format!("detector[{i}].{name}");
    if d.kind != "detection_filter" {
        return Err(chk.err(f("kind"), format!("{:?}: allowed \"detection_filter\" (method 000)", d.kind)));
    }
    let (n, ny) = (plant.n_states(), plant.n_outputs());
    let r = d.eigenvalues_per_s.len();
    if r == 0 || r > n {
        return Err(chk
            .err(f("eigenvalues_per_s"), format!("expected 1 to {n} eigenvalues (one per fault direction), got {r}")));
    }
    for (k, &l) in d.eigenvalues_per_s.iter().enumerate() {
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
    let thresholds = chk.vector(&f("thresholds"), &d.thresholds, ny, "one per output, output units")?;
    for (k, &t) in thresholds.iter().enumerate() {
        if t <= 0.0 {
            return Err(chk.err(f(&format!("thresholds[{k}]")), format!("must be > 0, got {t}")));
        }
    }
    let slowest_time_constant_s = 1.0 / d.eigenvalues_per_s.iter().fold(f64::INFINITY, |m, l| m.min(-l));
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
        eigenvalues_per_s: d.eigenvalues_per_s.clone(),
        fault_directions,
        thresholds,
        isolation_delay_s,
        isolation_window_s,
    })
}

fn monte_carlo(
    chk: &Validator,
    mc: Option<&super::deck::MonteCarloSection>,
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
    chk.trials("monte_carlo.trials", mc.trials)?;
    let fraction = chk.fraction("monte_carlo.fault_free_fraction", mc.fault_free_fraction)?;
    let sampler = chk.sampler("monte_carlo.sampler", mc.sampler.as_deref())?;
    let target_pfa = mc.target_pfa.unwrap_or(0.01);
    if !(target_pfa > 0.0 && target_pfa < 1.0) {
        return Err(chk.err("monte_carlo.target_pfa", format!("allowed 0 < p < 1, got {target_pfa}")));
    }
    let outputs = match &mc.outputs {
        None => (0..plant.n_outputs()).collect(),
        Some(names) if names.is_empty() => return Err(chk.err("monte_carlo.outputs", "name at least one output")),
        Some(names) => names
            .iter()
            .enumerate()
            .map(|(k, n)| chk.index_of(&format!("monte_carlo.outputs[{k}]"), n, &plant.output_names, "plant.outputs"))
            .collect::<Result<Vec<_>, _>>()?,
    };
    let onset_s = chk.factor("monte_carlo.onset_s", mc.onset_s.as_ref(), Factor::Fixed(duration_s / 3.0))?;
    chk.factor_within(
        "monte_carlo.onset_s",
        &onset_s,
        |v| v >= 0.0 && v < duration_s,
        &format!("0 <= onset_s < duration_s = {duration_s}"),
    )?;
    let noise_scale = chk.factor("monte_carlo.noise_scale", mc.noise_scale.as_ref(), Factor::Fixed(1.0))?;
    chk.factor_within("monte_carlo.noise_scale", &noise_scale, |v| v >= 0.0, ">= 0")?;

    let faults = mc
        .fault
        .iter()
        .enumerate()
        .map(|(i, f)| chk.fault_kind_spec(&format!("monte_carlo.fault[{i}]"), f))
        .collect::<Result<Vec<_>, _>>()?;

    let mut parameter_errors = Vec::with_capacity(mc.parameter_error.len());
    for (i, pe) in mc.parameter_error.iter().enumerate() {
        let field = |name: &str| format!("monte_carlo.parameter_error[{i}].{name}");
        chk.column_name(&field("name"), &pe.name, mc.parameter_error[..i].iter().map(|o| o.name.as_str()))?;
        let model = chk.model_target(&field("model"), &pe.model)?;
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
        let (absolute, value) = match (&pe.relative, &pe.absolute) {
            (Some(r), None) => {
                let v = chk.factor(&field("relative"), Some(r), Factor::Fixed(0.0))?;
                chk.factor_within(&field("relative"), &v, |x| x > -1.0 && x < 10.0, "-1 < relative < 10")?;
                (false, v)
            }
            (None, Some(a)) => (true, chk.factor(&field("absolute"), Some(a), Factor::Fixed(0.0))?),
            _ => {
                return Err(chk.err(
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
