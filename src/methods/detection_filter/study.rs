//! Detection-filter decks (method 000): the `[plant]` deck validated into a [`LtiStudy`] that cannot be invalid.

use std::path::Path;

use nalgebra::{DMatrix, DVector};

use super::deck::{ControllerSection, Deck, TruthSection};
use super::filter::{DetectionFilterParams, DetectorDeck};
use super::{cusum, filter, fmu_detector, kalman_chi2};
use serde::Deserialize;

use crate::engine::method::Opt;
use crate::engine::scenario::deck::{
    DeckError, FromDeck, ModelTarget, MonteCarlo, MonteCarloRules, MonteCarloSection, StudyHeader, Validator,
    parse_deck,
};
use crate::fault::ChannelFault;
use crate::fault::deck::{FaultKindSpec, FaultSide};
use crate::fmu::plant::{FmuPlant, Linearisation, PlantMapping};
use crate::lti::LtiPlant;

/// The options this kind takes beyond the common ones (its `Method::options`): said here, where its deck
/// rules read them (`monte_carlo.target_pfa` with [`Opt::Thresholds`]).
pub const OPTIONS: &[Opt] =
    &[Opt::Thresholds, Opt::Design, Opt::RareEvent, Opt::Sensitivity, Opt::FmuProcesses, Opt::WorstCase];

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

/// The detector kinds of LTI decks: the deck's `kind`, what it is, and its reader (in its own file).
const KINDS: &[(&str, &str, fn(&DetectorDeck) -> Result<DetectionFilterParams, DeckError>)] = &[
    ("detection_filter", "method 000, alarm on |residual|", filter::read),
    ("cusum", "the same filter, a CUSUM on |residual|", cusum::read),
    ("kalman_chi2", "a steady-state Kalman filter's windowed chi-square test", kalman_chi2::read),
    ("fmu", "a detector FMU: its statistic on the measured signals", fmu_detector::read),
];

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
    /// Each output's sensor-noise law (`noise.sensor_law`); its standard deviation is `sensor_sigma`.
    pub sensor_law: Vec<crate::engine::scenario::noise::SensorLaw>,
    pub process_sigma_per_step: DVector<f64>,
    /// Detector configurations; every one runs on the same trials (same faults, same noise).
    pub detectors: Vec<DetectorConfig>,
    /// Sensor faults of the deck's fixed scenario (`[[faults]]`); used when `monte_carlo.faults` is
    /// empty.
    pub faults: Vec<ChannelFault>,
    /// Actuator faults of the deck's fixed scenario (channels: [`LtiStudy::failing_inputs`]).
    pub actuator_faults: Vec<ChannelFault>,
    /// The inputs an actuator fault may hit: the plant's inputs (the command the detectors see is
    /// what the controller sends; the plant gets the faulty value), then the FMU truth's own fault
    /// inputs (`[truth] fault_inputs`).
    pub failing_inputs: Vec<String>,
    pub monte_carlo: LtiMonteCarlo,
    /// `[truth]`: an FMU flies instead of `plant`, which is then the linear model in deviations from the
    /// FMU's trim.
    pub truth: Option<FmuPlant>,
    /// `[truth] linearise = true`: the FMU's linearisation `plant` was made from.
    pub linearisation: Option<Linearisation>,
    /// `[truth.trim]`: the trim solved on the FMU.
    pub trim: Option<SolvedTrim>,
    /// `[controller] fmu`: a controller FMU closes the loop instead of `output_feedback`.
    pub controller_fmu: Option<ControllerFmu>,
}

/// A trim solved on the FMU (`[truth.trim]`): the free inputs and parameters, the variables made zero.
#[derive(Debug, Clone)]
pub struct SolvedTrim {
    pub free: Vec<String>,
    pub zero: Vec<String>,
    pub trim: crate::fmu::trim::Trim,
}

/// A controller FMU and where its signals come from and go: its inputs are the measured outputs
/// `measured` (plant output indices) then the commands `commands` (the excitation on those plant
/// inputs), in that order; its outputs drive the plant inputs `drives`.
#[derive(Debug, Clone)]
pub struct ControllerFmu {
    pub fmu: FmuPlant,
    pub measured: Vec<usize>,
    pub commands: Vec<usize>,
    pub drives: Vec<usize>,
    /// Subtracted from the controller's outputs: the plant's inputs are deviations from its trim.
    pub plant_input_trim: Vec<f64>,
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

/// What a parameter error perturbs: matrix entries of the linear plant or design model, or parameters of
/// the FMU truth (value reference and nominal value: the deck's `[truth] parameters` value, else the
/// FMU's start value), scaled together.
#[derive(Debug, Clone, PartialEq)]
pub enum Perturbs {
    Matrix(MatrixEntries),
    FmuParameters(Vec<(u32, f64)>),
}

pub type ParameterError = crate::engine::scenario::deck::ParameterError<Perturbs>;

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

impl LtiStudy {
    /// Whether any state has process noise: without it a trial draws no process normals at all.
    pub fn has_process_noise(&self) -> bool {
        self.process_sigma_per_step.iter().any(|&v| v > 0.0)
    }

    /// Whether any trial can have an actuator fault.
    pub fn has_actuator_faults(&self) -> bool {
        !self.actuator_faults.is_empty() || self.monte_carlo.faults.iter().any(|f| !f.inputs.is_empty())
    }

    /// What doubts the FMU truth's model: its linearisation's warnings, a start that is not an
    /// equilibrium, an integrator step too long for its fastest mode (`validate`, `design` and `run`
    /// print them).
    pub fn truth_warnings(&self) -> Vec<String> {
        let mut out: Vec<String> = self.linearisation.iter().flat_map(|l| l.warnings.iter().cloned()).collect();
        let Some(t) = &self.truth else { return out };
        if let Some(a) = &t.at_start {
            out.extend(a.not_an_equilibrium());
            let h = self.header.dt_s / t.substeps as f64;
            if a.fastest_mode_per_s * h > 2.0 * crate::fmu::plant::MODE_STEP {
                out.push(format!(
                    "the integrator step {h} s is long for the FMU's fastest mode at the trim, {:.4} rad/s (|lambda| h = \
                     {:.3}; RK4 loses accuracy above {} and diverges near 2.8): remove truth.integrator_step_s to let \
                     fdimc choose",
                    a.fastest_mode_per_s,
                    a.fastest_mode_per_s * h,
                    crate::fmu::plant::MODE_STEP
                ));
            }
        }
        out
    }

    /// Every FMU the study runs: its truth, its controller, its detectors'.
    pub fn fmus(&self) -> Vec<&FmuPlant> {
        let detectors = self.detectors.iter().filter_map(|d| d.params.decision.as_ref().and_then(|t| t.fmu()));
        self.truth.iter().chain(self.controller_fmu.iter().map(|c| &c.fmu)).chain(detectors).collect()
    }
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
    // None: an autonomous plant (the commonest FMU: a model with no inputs), flown on its own dynamics.
    chk.names_if_any("plant.inputs", &p.inputs)?;
    chk.names("plant.outputs", &p.outputs)?;
    let (n, nu, ny) = (p.states.len(), p.inputs.len(), p.outputs.len());
    let dims = format!("{n} states, {nu} inputs, {ny} outputs");
    let truth = match &deck.truth {
        Some(t) => Some(fmu_truth(chk, t, &p.inputs, &p.outputs, &header)?),
        None => None,
    };
    let (truth, trim) = match truth {
        Some((plant, trim)) => (Some(plant), trim),
        None => (None, None),
    };
    if let Some(t) = deck.truth.as_ref().filter(|t| t.linearise || t.identify) {
        if t.linearise && t.identify {
            return Err(chk.err("truth.identify", "give linearise (model exchange) or identify, not both"));
        }
        let how = if t.identify { "identify" } else { "linearise" };
        for (field, given) in [("plant.a", &p.a), ("plant.b", &p.b), ("plant.c", &p.c), ("plant.d", &p.d)] {
            if given.is_some() {
                return Err(chk.err(field, format!("[truth] {how} = true gives the matrices: remove it")));
            }
        }
    }
    let linearisation = match (&deck.truth, &truth) {
        (Some(t), Some(fmu)) if t.identify => {
            let found = crate::fmu::identify::identify(fmu, n, header.dt_s, &p.outputs)
                .map_err(|e| chk.err("truth.identify", e.to_string()))?;
            Some(found.linearisation)
        }
        (Some(t), Some(fmu)) if t.linearise => {
            let lin = fmu.linearise().map_err(|e| chk.err("truth.linearise", e.to_string()))?;
            if lin.x_trim.len() != n {
                return Err(chk.err(
                    "plant.states",
                    format!(
                        "{n} names for the FMU's {} continuous states: one name per state, in its order",
                        lin.x_trim.len()
                    ),
                ));
            }
            Some(lin)
        }
        _ => None,
    };
    let given = |field: &str, m: &Option<Vec<Vec<f64>>>, rows, cols, shape: &str| match m {
        Some(m) => chk.matrix(field, m, rows, cols, &format!("{shape}, {dims}")),
        None => Err(chk.err(field, "required (or, with an FMU truth, [truth] linearise = true or identify = true)")),
    };
    let (a, b, c, d) = match &linearisation {
        Some(l) => (l.a.clone(), l.b.clone(), l.c.clone(), l.d.clone()),
        None => (
            given("plant.a", &p.a, n, n, "n x n")?,
            match (&p.b, nu) {
                // An autonomous plant has no input matrix to give.
                (None, 0) => DMatrix::zeros(n, 0),
                _ => given("plant.b", &p.b, n, nu, "n x inputs")?,
            },
            given("plant.c", &p.c, ny, n, "outputs x n")?,
            match &p.d {
                Some(d) => chk.matrix("plant.d", d, ny, nu, &format!("outputs x inputs, {dims}"))?,
                None => DMatrix::zeros(ny, nu),
            },
        ),
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

    let (output_feedback, controller_fmu) = match &deck.controller {
        Some(cs) => match (&cs.output_feedback, &cs.fmu) {
            (Some(g), None) => {
                for (field, empty) in [
                    ("controller.measured", cs.measured.is_empty()),
                    ("controller.commands", cs.commands.is_empty()),
                    ("controller.drives", cs.drives.is_empty()),
                    ("controller.parameters", cs.parameters.is_empty()),
                ] {
                    if !empty {
                        return Err(chk.err(field, "only with a controller FMU (controller.fmu): remove it"));
                    }
                }
                (chk.matrix("controller.output_feedback", g, nu, ny, &format!("inputs x outputs, {dims}"))?, None)
            }
            (None, Some(file)) => {
                (DMatrix::zeros(nu, ny), Some(controller_fmu(chk, cs, file, &plant, truth.as_ref(), &header)?))
            }
            _ => {
                return Err(chk
                    .err("controller", "give output_feedback (a gain matrix) or fmu (a controller FMU), one of them"));
            }
        },
        None => (DMatrix::zeros(nu, ny), None),
    };
    if output_feedback.amax() > 0.0 && plant.D.amax() > 0.0 {
        return Err(chk.err(
            "controller.output_feedback",
            "output feedback with a non-zero plant.d is an algebraic loop (u depends on y, y on u): use d = 0 or no controller",
        ));
    }
    // A linear truth measures y = C x + D r before the loop closes: with a controller FMU u is not r.
    if controller_fmu.is_some() && truth.is_none() && plant.D.amax() > 0.0 {
        return Err(chk.err(
            "controller.fmu",
            "a controller FMU on a linear truth with a non-zero plant.d is an algebraic loop (u depends on y, y on u): use d = 0",
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
            other => return Err(chk.not_allowed(field("shape"), other, &[("square", ""), ("sine", ""), ("step", "")])),
        };
        excitations.push(Excitation { input, shape, amplitude, start_s });
    }

    let sensor_sigma =
        chk.vector("noise.sensor_sigma", &deck.noise.sensor_sigma, ny, "one per output, output units")?;
    let sensor_law = sensor_laws(chk, deck.noise.sensor_law.as_ref(), ny)?;
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

    chk.detector_names("detector", deck.detector.iter().map(|d| d.name.as_str()))?;
    let mut detectors = Vec::with_capacity(deck.detector.len());
    for (i, d) in deck.detector.iter().enumerate() {
        if d.kind != "fmu"
            && let Some((field, _)) = fmu_detector::own_fields(d).into_iter().find(|(_, given)| *given)
        {
            return Err(chk.err(format!("detector[{i}].{field}"), "applies to kind = \"fmu\" only (a detector FMU)"));
        }
        let deck = DetectorDeck {
            chk,
            i,
            d,
            plant: &plant,
            sensor_sigma: &sensor_sigma,
            truth: truth.as_ref(),
            header: &header,
        };
        let params = match KINDS.iter().find(|k| k.0 == d.kind) {
            Some((_, _, read)) => read(&deck)?,
            None => {
                let allowed: Vec<String> = KINDS.iter().map(|(k, what, _)| format!("{k:?} ({what})")).collect();
                return Err(
                    chk.err(format!("detector[{i}].kind"), format!("{:?}: allowed {}", d.kind, allowed.join(", ")))
                );
            }
        };
        detectors.push(DetectorConfig { name: d.name.clone(), params });
    }

    let failing_inputs: Vec<String> =
        p.inputs.iter().chain(deck.truth.iter().flat_map(|t| &t.fault_inputs)).cloned().collect();
    let input_list = if truth.is_some() { "plant.inputs or truth.fault_inputs" } else { "plant.inputs" };
    let (mut faults, mut actuator_faults) = (Vec::new(), Vec::new());
    for (i, f) in deck.faults.iter().enumerate() {
        match chk.fault(i, f, (&p.outputs, "plant.outputs"), (&failing_inputs, input_list), duration_s)? {
            (FaultSide::Sensor, fault) => faults.push(fault),
            (FaultSide::Actuator, fault) => actuator_faults.push(fault),
        }
    }
    if truth.is_some() && process_sigma_per_step.amax() > 0.0 {
        return Err(chk.err(
            "noise.process_sigma_per_step",
            "not with an FMU truth ([truth]): its states are the FMU's own; remove it",
        ));
    }
    let monte_carlo =
        monte_carlo(chk, deck.monte_carlo, &plant, truth.as_ref(), duration_s, (&failing_inputs, input_list))?;
    let fixed = !faults.is_empty() || !actuator_faults.is_empty();
    chk.one_fault_source("[[faults]]", "[[monte_carlo.fault]]", !monte_carlo.faults.is_empty() && fixed)?;
    // A linear truth measures y = C x + D r: the faulty input would have to feed through too.
    let actuated = !actuator_faults.is_empty() || monte_carlo.faults.iter().any(|f| !f.inputs.is_empty());
    if actuated && truth.is_none() && plant.D.amax() > 0.0 {
        return Err(chk.err(
            "plant.d",
            "actuator faults on a linear truth need d = 0 (the measurement would feed the faulty input through)",
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
        sensor_law,
        process_sigma_per_step,
        detectors,
        faults,
        actuator_faults,
        failing_inputs,
        monte_carlo,
        truth,
        linearisation,
        trim,
        controller_fmu,
    })
}

/// `[truth]`: the FMU opened and its variables mapped to `[plant]`'s inputs and outputs.
fn fmu_truth(
    chk: &Validator,
    t: &TruthSection,
    inputs: &[String],
    outputs: &[String],
    header: &StudyHeader,
) -> Result<(FmuPlant, Option<SolvedTrim>), DeckError> {
    let interface = crate::fmu::Interface::from_name(&t.interface).ok_or_else(|| {
        chk.not_allowed("truth.interface", &t.interface, &[("model_exchange", ""), ("co_simulation", "")])
    })?;
    for (field, names, model, list) in
        [("truth.inputs", &t.inputs, inputs, "plant.inputs"), ("truth.outputs", &t.outputs, outputs, "plant.outputs")]
    {
        if names.len() != model.len() {
            return Err(chk.err(
                field,
                format!(
                    "{} names for {} {list}: one FMU variable per entry of {list}, in its order",
                    names.len(),
                    model.len()
                ),
            ));
        }
    }
    for (k, v) in t.trim_inputs.iter().enumerate() {
        chk.finite(&format!("truth.trim_inputs[{k}]"), *v)?;
    }
    for (name, v) in &t.parameters {
        chk.finite(&format!("truth.parameters.{name}"), *v)?;
    }
    let mut parameters: Vec<(String, f64)> = t.parameters.iter().map(|(k, v)| (k.clone(), *v)).collect();
    let mut trim_inputs = t.trim_inputs.clone();
    if trim_inputs.len() != t.inputs.len() {
        return Err(chk.err(
            "truth.trim_inputs",
            format!(
                "{} values for {} inputs: one per input (a solved trim starts from them)",
                trim_inputs.len(),
                t.inputs.len()
            ),
        ));
    }
    let trim = match &t.trim {
        Some(ts) => Some(solve_trim(chk, t, ts, interface, &mut parameters, &mut trim_inputs, header)?),
        None => None,
    };
    let fields = |list: &str, len: usize| (0..len).map(|k| format!("truth.{list}[{k}]")).collect::<Vec<_>>();
    let mapping = PlantMapping {
        interface,
        inputs: &t.inputs,
        input_fields: &fields("inputs", t.inputs.len()),
        outputs: &t.outputs,
        output_fields: &fields("outputs", t.outputs.len()),
        parameters: &parameters,
        fault_inputs: &t.fault_inputs,
        input_trim: &trim_inputs,
        stop_s: header.duration_s,
        dt_s: header.dt_s,
    };
    let mut plant = chk.fmu("truth", &t.fmu, &mapping)?;
    if let Some(h) = t.integrator_step_s {
        let h = chk.positive("truth.integrator_step_s", h)?;
        if interface != crate::fmu::Interface::ModelExchange {
            return Err(chk.err(
                "truth.integrator_step_s",
                "only with interface = \"model_exchange\" (a co-simulation FMU steps itself)",
            ));
        }
        if h > header.dt_s {
            return Err(chk.err(
                "truth.integrator_step_s",
                format!("{h} s is longer than the study's dt_s ({} s): at most dt_s", header.dt_s),
            ));
        }
        plant.set_integrator_step(h, header.dt_s);
    }
    if t.integrator_step_s.is_none()
        && plant.substeps > crate::fmu::plant::MAX_AUTO_SUBSTEPS
        && let Some(a) = &plant.at_start
    {
        return Err(chk.err(
            "truth.integrator_step_s",
            format!(
                "the FMU's fastest mode at the trim is {:.4e} rad/s: RK4 would need {} steps per study step of {} s \
                 (more than the {} fdimc takes by itself: a stiff model, or a linearisation across a discontinuity). \
                 Set truth.integrator_step_s (stable below about {:.3e} s for that mode), or fly the FMU's co-simulation \
                 interface",
                a.fastest_mode_per_s,
                plant.substeps,
                header.dt_s,
                crate::fmu::plant::MAX_AUTO_SUBSTEPS,
                2.8 / a.fastest_mode_per_s
            ),
        ));
    }
    if let Some(a) = plant.at_start.as_mut() {
        a.transient_intended = t.transient_start;
    }
    if let Some(f) = t.stray_factor {
        if f.is_nan() || f <= 0.0 {
            return Err(chk.err(
                "truth.stray_factor",
                format!("must be a number > 0 (inf: never compare the truth with [plant]), got {f}"),
            ));
        }
        plant.stray_factor = f;
    }
    Ok((plant, trim))
}

/// `[truth.trim]`: solves the trim on the FMU and writes the solved values into the trial's
/// `parameters` and `trim_inputs`.
fn solve_trim(
    chk: &Validator,
    t: &TruthSection,
    ts: &super::deck::TrimSection,
    interface: crate::fmu::Interface,
    parameters: &mut Vec<(String, f64)>,
    trim_inputs: &mut [f64],
    header: &StudyHeader,
) -> Result<SolvedTrim, DeckError> {
    use crate::fmu::{Causality, ValueType};
    let tolerance = match ts.tolerance {
        Some(v) => chk.positive("truth.trim.tolerance", v)?,
        None => 1e-10,
    };
    if ts.free.is_empty() || ts.free.len() != ts.zero.len() {
        return Err(chk.err(
            "truth.trim.zero",
            format!(
                "{} variables for {} free values: as many variables made zero as inputs and parameters left free, at least one",
                ts.zero.len(),
                ts.free.len()
            ),
        ));
    }
    let path = chk.file.parent().unwrap_or(Path::new(".")).join(&t.fmu);
    let fmu = crate::fmu::Fmu::open(&path).map_err(|e| chk.err("truth.fmu", e.to_string()))?;
    let d = &fmu.description;
    let real = |field: String, name: &str, causality: &[Causality]| -> Result<u32, DeckError> {
        match d.variable(name) {
            Some(v)
                if v.value_type == ValueType::Real && causality.contains(&v.causality) && v.dimensions.is_empty() =>
            {
                Ok(v.value_reference)
            }
            _ => Err(chk.err(
                field,
                format!(
                    "{} has no such scalar Real variable {name:?}; allowed: {}",
                    fmu.file_name(),
                    d.names_of(causality).join(", ")
                ),
            )),
        }
    };
    // Fixed: every parameter and every trim input that is not free.
    let mut fixed = Vec::new();
    for (name, v) in parameters.iter() {
        if !ts.free.contains(name) {
            fixed.push((real(format!("truth.parameters.{name}"), name, &[Causality::Parameter])?, *v));
        }
    }
    for (k, (name, v)) in t.inputs.iter().zip(trim_inputs.iter()).enumerate() {
        if !ts.free.contains(name) {
            fixed.push((real(format!("truth.inputs[{k}]"), name, &[Causality::Input])?, *v));
        }
    }
    // Free: a mapped input starts at its trim_inputs value, a parameter at its deck or start value.
    let mut free = Vec::new();
    for (k, name) in ts.free.iter().enumerate() {
        let field = format!("truth.trim.free[{k}]");
        // An input is free only if the deck maps it (it has a trim value); otherwise it is a parameter.
        let causality: &[Causality] =
            if t.inputs.contains(name) { &[Causality::Input] } else { &[Causality::Parameter] };
        let vr = real(field.clone(), name, causality)?;
        let guess = match t.inputs.iter().position(|n| n == name) {
            Some(j) => trim_inputs[j],
            None => match parameters.iter().find(|(n, _)| n == name) {
                Some((_, v)) => *v,
                None => d.variable(name).and_then(|v| v.start_f64()).ok_or_else(|| {
                    chk.err(&field, format!("{name:?} has no start value: give one in [truth] parameters"))
                })?,
            },
        };
        free.push((vr, guess));
    }
    let zero = ts
        .zero
        .iter()
        .enumerate()
        .map(|(k, name)| {
            real(format!("truth.trim.zero[{k}]"), name, &[Causality::Local, Causality::Output, Causality::Parameter])
        })
        .collect::<Result<Vec<_>, _>>()?;
    let problem = crate::fmu::trim::TrimProblem {
        interface,
        fixed: &fixed,
        free: &free,
        zero: &zero,
        stop_s: header.duration_s,
        tolerance,
    };
    let solved = crate::fmu::trim::solve(&fmu, &problem).map_err(|e| chk.err("truth.trim", e.to_string()))?;
    for (name, &v) in ts.free.iter().zip(&solved.values) {
        match t.inputs.iter().position(|n| n == name) {
            Some(j) => trim_inputs[j] = v,
            None => match parameters.iter_mut().find(|(n, _)| n == name) {
                Some(p) => p.1 = v,
                None => parameters.push((name.clone(), v)),
            },
        }
    }
    Ok(SolvedTrim { free: ts.free.clone(), zero: ts.zero.clone(), trim: solved })
}

/// `[controller] fmu`: a co-simulation FMU closing the loop on absolute values (trims added back).
fn controller_fmu(
    chk: &Validator,
    cs: &ControllerSection,
    file: &str,
    plant: &LtiPlant,
    truth: Option<&FmuPlant>,
    header: &StudyHeader,
) -> Result<ControllerFmu, DeckError> {
    let output_trim = |j: usize| truth.map_or(0.0, |t| t.output_trim[j]);
    let input_trim = |j: usize| truth.map_or(0.0, |t| t.input_trim[j]);
    let (mut inputs, mut trims, mut measured, mut commands) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let (mut input_fields, mut output_fields) = (Vec::new(), Vec::new());
    for (input, output) in &cs.measured {
        let j = chk.index_of(&format!("controller.measured.{input}"), output, &plant.output_names, "plant.outputs")?;
        input_fields.push(format!("controller.measured.{input}"));
        inputs.push(input.clone());
        trims.push(output_trim(j));
        measured.push(j);
    }
    for (input, plant_input) in &cs.commands {
        let j =
            chk.index_of(&format!("controller.commands.{input}"), plant_input, &plant.input_names, "plant.inputs")?;
        input_fields.push(format!("controller.commands.{input}"));
        inputs.push(input.clone());
        trims.push(0.0);
        commands.push(j);
    }
    let (mut outputs, mut drives) = (Vec::new(), Vec::new());
    for (output, plant_input) in &cs.drives {
        let j =
            chk.index_of(&format!("controller.drives.{output}"), plant_input, &plant.input_names, "plant.inputs")?;
        if drives.contains(&j) {
            return Err(chk.err(format!("controller.drives.{output}"), format!("{plant_input:?} is driven twice")));
        }
        output_fields.push(format!("controller.drives.{output}"));
        outputs.push(output.clone());
        drives.push(j);
    }
    if drives.is_empty() {
        return Err(chk.err("controller.drives", "map at least one controller output to a plant input"));
    }
    let parameters: Vec<(String, f64)> = cs.parameters.iter().map(|(k, v)| (k.clone(), *v)).collect();
    let mapping = PlantMapping {
        interface: crate::fmu::Interface::CoSimulation,
        inputs: &inputs,
        input_fields: &input_fields,
        outputs: &outputs,
        output_fields: &output_fields,
        parameters: &parameters,
        fault_inputs: &[],
        input_trim: &trims,
        stop_s: header.duration_s,
        dt_s: header.dt_s,
    };
    let mut fmu = chk.fmu("controller", file, &mapping)?;
    // The controller's outputs are the plant's absolute inputs, not deviations from its own trim.
    fmu.output_trim.iter_mut().for_each(|v| *v = 0.0);
    let plant_input_trim = (0..plant.n_inputs()).map(input_trim).collect();
    Ok(ControllerFmu { fmu, measured, commands, drives, plant_input_trim })
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
    matrix: Option<String>,
    entries: Option<Vec<(String, String)>>,
    fmu_parameters: Option<Vec<String>>,
}

/// `noise.sensor_law`'s `{ log = "FILE.ulg", field = "...", topic = "sensor_combined", instance = 0 }`:
/// the empirical law of a recorded channel's residual noise, the log relative to the deck's folder.
fn recorded_law(
    chk: &Validator,
    field: &str,
    t: &toml::map::Map<String, toml::Value>,
) -> Result<crate::engine::scenario::noise::SensorLaw, DeckError> {
    use crate::engine::logs::flight_log::{PX4_IMU_TOPIC, TopicRequest, read_ulog};
    use crate::engine::scenario::noise::{EmpiricalLaw, SensorLaw};
    if let Some(key) = t.keys().find(|k| !["log", "field", "topic", "instance"].contains(&k.as_str())) {
        return Err(chk.err(format!("{field}.{key}"), "unknown key; allowed log, field, topic, instance"));
    }
    let text = |key: &str| match t.get(key) {
        Some(toml::Value::String(s)) => Ok(Some(s.clone())),
        None => Ok(None),
        Some(other) => Err(chk.err(format!("{field}.{key}"), format!("expected text, got {}", other.type_str()))),
    };
    let log =
        text("log")?.ok_or_else(|| chk.err(format!("{field}.log"), "missing: the ULog file (relative to the deck)"))?;
    let signal = text("field")?
        .ok_or_else(|| chk.err(format!("{field}.field"), "missing: the topic's field, e.g. \"gyro_rad[1]\""))?;
    let topic = text("topic")?.unwrap_or_else(|| PX4_IMU_TOPIC.to_string());
    let instance = match t.get("instance") {
        None => 0,
        Some(toml::Value::Integer(i)) if (0..=255).contains(i) => *i as u8,
        Some(other) => return Err(chk.err(format!("{field}.instance"), format!("allowed 0 to 255, got {other}"))),
    };
    let path = chk.file.parent().unwrap_or(Path::new(".")).join(&log);
    // Every gap bridged: the law reads the residuals about each sample's neighbours, not the timing.
    let request =
        TopicRequest { topic: topic.clone(), instance, fields: vec![signal.clone()], max_gap_s: f64::INFINITY };
    let series = read_ulog(&path, &request).map_err(|e| chk.err(format!("{field}.log"), e.to_string()))?;
    let source = format!("{log}: {topic} {signal}");
    EmpiricalLaw::from_samples(&source, &series.values[0])
        .map(|law| SensorLaw::Empirical(std::sync::Arc::new(law)))
        .map_err(|e| chk.err(field, e))
}

/// `noise.sensor_law`: one law for every output, or a list of one per output.
fn sensor_laws(
    chk: &Validator,
    given: Option<&toml::Value>,
    outputs: usize,
) -> Result<Vec<crate::engine::scenario::noise::SensorLaw>, DeckError> {
    use crate::engine::scenario::noise::SensorLaw;
    let parse = |field: &str, v: &toml::Value| match v {
        toml::Value::String(s) => SensorLaw::parse(s).map_err(|e| chk.err(field, e)),
        toml::Value::Table(t) => recorded_law(chk, field, t),
        other => {
            Err(chk.err(field, format!("got {}; {}", other.type_str(), crate::engine::scenario::noise::ALLOWED_LAWS)))
        }
    };
    match given {
        None => Ok(vec![SensorLaw::Gaussian; outputs]),
        Some(toml::Value::Array(list)) if list.len() == outputs => {
            (list.iter().enumerate()).map(|(j, v)| parse(&format!("noise.sensor_law[{j}]"), v)).collect()
        }
        Some(toml::Value::Array(list)) => Err(chk.err(
            "noise.sensor_law",
            format!("one law for every output, or a list of {outputs} (one per output), got {}", list.len()),
        )),
        Some(v) => Ok(vec![parse("noise.sensor_law", v)?; outputs]),
    }
}

fn monte_carlo(
    chk: &Validator,
    mc: Option<MonteCarloSection>,
    plant: &LtiPlant,
    truth: Option<&FmuPlant>,
    duration_s: f64,
    failing_inputs: (&[String], &str),
) -> Result<LtiMonteCarlo, DeckError> {
    let rules = MonteCarloRules {
        parameter_errors: Some(true),
        time_to_hazard: true,
        ..MonteCarloRules::sampled("detection-filter decks", duration_s, OPTIONS.contains(&Opt::Thresholds))
    };
    let (common, own, parameter_errors) = chk.monte_carlo(mc, &rules, |prefix, table| {
        let field = |name: &str| format!("{prefix}.{name}");
        let pe: MatrixEntriesSection =
            toml::Value::Table(table).try_into().map_err(|e| chk.err(prefix, e.to_string().trim_end().to_string()))?;
        if let Some(names) = &pe.fmu_parameters {
            let Some(fmu) = truth else {
                return Err(
                    chk.err(field("fmu_parameters"), "only with an FMU truth ([truth]); use matrix and entries")
                );
            };
            if pe.matrix.is_some() || pe.entries.is_some() {
                return Err(chk.err(field("fmu_parameters"), "names FMU parameters: remove matrix and entries"));
            }
            if names.is_empty() {
                return Err(chk.err(field("fmu_parameters"), "name at least one parameter of the FMU"));
            }
            let d = &fmu.fmu.description;
            let mut perturbed = Vec::with_capacity(names.len());
            for (k, name) in names.iter().enumerate() {
                let f = field(&format!("fmu_parameters[{k}]"));
                let parameters = d.names_of(&[crate::fmu::Causality::Parameter]);
                let v =
                    d.variable(name).filter(|v| v.causality == crate::fmu::Causality::Parameter).ok_or_else(|| {
                        chk.err(
                            &f,
                            format!(
                                "{} has no parameter {name:?}; its parameters: {}",
                                fmu.fmu.file_name(),
                                parameters.join(", ")
                            ),
                        )
                    })?;
                let set = fmu.parameters.iter().find(|(vr, _)| *vr == v.value_reference).map(|p| p.1);
                let nominal = set.or(v.start_f64()).ok_or_else(|| {
                    chk.err(&f, format!("{name:?} has no start value: give it in [truth] parameters"))
                })?;
                perturbed.push((v.value_reference, nominal));
            }
            return Ok(Perturbs::FmuParameters(perturbed));
        }
        let (Some(matrix), Some(pe_entries)) = (&pe.matrix, &pe.entries) else {
            return Err(chk.err(prefix, "name the matrix and its entries (or, with an FMU truth, fmu_parameters)"));
        };
        let matrices = [
            ("a", (false, &plant.state_names, "plant.states"), ""),
            ("b", (true, &plant.input_names, "plant.inputs"), ""),
        ];
        let (matrix_b, col_names, col_list) = chk.choice(&field("matrix"), matrix, &matrices)?;
        if pe_entries.is_empty() {
            return Err(chk.err(field("entries"), "list at least one [row, column] pair of names"));
        }
        let mut entries = Vec::with_capacity(pe_entries.len());
        for (k, (row, col)) in pe_entries.iter().enumerate() {
            let f = field(&format!("entries[{k}]"));
            let r = chk.index_of(&f, row, &plant.state_names, "plant.states (rows)")?;
            let c = chk.index_of(&f, col, col_names, col_list)?;
            entries.push((r, c));
        }
        Ok(Perturbs::Matrix(MatrixEntries { matrix_b, entries }))
    })?;
    for (k, pe) in parameter_errors.iter().enumerate() {
        let field = format!("monte_carlo.parameter_error[{k}]");
        match (&pe.what, pe.model, truth.is_some()) {
            (Perturbs::Matrix(_), ModelTarget::Plant, true) => {
                return Err(chk.err(
                    field,
                    "the truth is an FMU: a plant parameter error names fmu_parameters (the matrices are the design model's)",
                ));
            }
            (Perturbs::FmuParameters(_), ModelTarget::Design, _) => {
                return Err(chk.err(field, "fmu_parameters perturb the truth: model = \"plant\""));
            }
            _ => {}
        }
    }
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
    let faults = chk.fault_kind_specs(&own.fault, failing_inputs)?;
    // What each population may hit, as its records name it: a sensor fault one of the outputs flown,
    // an actuator fault one of its failing inputs.
    let mut flown: Vec<(String, Vec<String>)> = Vec::new();
    for f in &faults {
        let hit: Vec<String> = if f.inputs.is_empty() {
            outputs.iter().map(|&o| plant.output_names[o].clone()).collect()
        } else {
            f.inputs.iter().map(|&i| failing_inputs.0[i].clone()).collect()
        };
        match flown.iter_mut().find(|(k, _)| k == f.record_kind()) {
            Some((_, targets)) => targets.extend(hit.into_iter().filter(|t| !targets.contains(t)).collect::<Vec<_>>()),
            None => flown.push((f.record_kind().to_string(), hit)),
        }
    }
    chk.hazard_times(&common.time_to_hazard_s, &flown)?;
    Ok(LtiMonteCarlo { common, outputs, faults, parameter_errors })
}
