//! `kind = "fmu"`: a detector built elsewhere (Simulink, Modelica, C) and exported as a co-simulation
//! FMU, run beside fdimc's own detectors on the same trials. Each sample it sees the measured outputs
//! (noisy, possibly faulty) and, if mapped, the inputs applied to the plant, both as absolute values
//! (the FMU truth's trims added back); it is stepped by `dt` and gives its decision statistic and,
//! optionally, the channel it isolates (1 = the first of the deck's `channels`, 0 = none).
//!
//! fdimc runs no filter for it: its "residual" is the measured output as it is (a filter with no model
//! and no gain), and its test is the FMU. The statistic is recorded under every output, as the Kalman
//! chi-square test's is, so thresholds calibrate at a false-alarm rate and the ROC draws as for any
//! detector. Isolation is the FMU's: the channel it names at the end of the isolation window.

use std::sync::Arc;

use nalgebra::{DMatrix, DVector};

use super::decision::{Decision, ResidualTest, TestState};
use super::filter::{DetectionFilter, DetectionFilterParams, DetectorDeck, Gain, GainDesign, Isolation};
use crate::design::{Assignment, DesignError, eigen_report};
use crate::engine::scenario::deck::DeckError;
use crate::fmu::plant::{Flight, FmuPlant, PlantMapping};
use crate::fmu::{Causality, Interface, ValueType};
use crate::lti::{DiscreteLti, LtiPlant};

/// A detector FMU mapped onto a study's signals.
#[derive(Debug)]
pub struct FmuTest {
    /// Inputs: the measured outputs `measured`, then the applied inputs `applied`; output: the
    /// statistic.
    plant: Arc<FmuPlant>,
    measured: Vec<usize>,
    applied: Vec<usize>,
    channel: Channel,
    /// Channel `k` (1-based) names output `channels[k - 1]`.
    channels: Vec<usize>,
    statistic_name: String,
}

/// How the isolated channel is read, if the deck maps one.
#[derive(Debug, Clone, Copy)]
enum Channel {
    None,
    /// A Real output with this value reference (rounded to the nearest channel).
    Real(u32),
    /// An Integer output with this value reference.
    Integer(u32),
}

impl ResidualTest for FmuTest {
    fn describe(&self) -> String {
        format!(
            "the output {:?} of the detector FMU {} (co-simulation, sha256 {})",
            self.statistic_name,
            self.plant.fmu.file_name(),
            &self.plant.fmu.sha256[..16]
        )
    }

    fn start(&self, outputs: usize, dt_s: f64) -> Box<dyn TestState> {
        let (flight, failure) = match self.plant.start_shared(&[]) {
            Ok(f) => (Some(f), None),
            Err(e) => (None, Some(e.to_string())),
        };
        Box::new(FmuTestState {
            flight,
            failure,
            measured: self.measured.clone(),
            applied: self.applied.clone(),
            channel: self.channel,
            channels: self.channels.clone(),
            k: 0,
            dt_s,
            u: Vec::new(),
            inputs: vec![0.0; self.plant.input_vrs.len()],
            read: vec![0.0; self.plant.output_vrs.len()],
            named: None,
            outputs,
            label: self.plant.fmu.file_name(),
        })
    }

    fn kind(&self) -> &'static str {
        "fmu"
    }

    fn isolates(&self) -> bool {
        true
    }

    fn fmu(&self) -> Option<&FmuPlant> {
        Some(&self.plant)
    }
}

/// One trial of a detector FMU: its instance (this thread's, reset), and what it named last.
struct FmuTestState {
    flight: Option<Flight<'static>>,
    failure: Option<String>,
    measured: Vec<usize>,
    applied: Vec<usize>,
    channel: Channel,
    channels: Vec<usize>,
    /// Samples stepped so far: the FMU's time is `k dt`, as the trial's.
    k: u64,
    dt_s: f64,
    u: Vec<f64>,
    inputs: Vec<f64>,
    read: Vec<f64>,
    named: Option<usize>,
    outputs: usize,
    /// The FMU's file name, for a failure's message.
    label: String,
}

impl FmuTestState {
    /// Sets this sample's inputs, steps the FMU and reads its statistic and channel.
    fn advance(&mut self, y: &[f64]) -> Result<f64, crate::fmu::FmuError> {
        let flight = self.flight.as_mut().expect("advanced only while flying");
        let nm = self.measured.len();
        for (k, &j) in self.measured.iter().enumerate() {
            self.inputs[k] = y[j];
        }
        for (k, &j) in self.applied.iter().enumerate() {
            self.inputs[nm + k] = self.u.get(j).copied().unwrap_or(0.0);
        }
        flight.set_inputs(&self.inputs)?;
        flight.advance(self.k as f64 * self.dt_s, self.dt_s)?;
        self.k += 1;
        flight.outputs(&mut self.read)?;
        // A statistic that is not a number would never alarm: the trial fails instead of looking quiet.
        if !self.read[0].is_finite() {
            return Err(crate::fmu::FmuError::Failed(format!(
                "{}: its statistic is {} after the step to t = {} s",
                self.label,
                self.read[0],
                self.k as f64 * self.dt_s
            )));
        }
        let index = match self.channel {
            Channel::None => None,
            Channel::Real(vr) => {
                let mut c = [0.0];
                flight.reals(&[vr], &mut c)?;
                Some(c[0].round() as i64)
            }
            Channel::Integer(vr) => {
                let mut c = [0];
                flight.integers(&[vr], &mut c)?;
                Some(i64::from(c[0]))
            }
        };
        // Channel 0 (or one past the list) names no output.
        self.named = index
            .and_then(|c| usize::try_from(c).ok())
            .and_then(|c| c.checked_sub(1))
            .and_then(|c| self.channels.get(c).copied());
        Ok(self.read[0])
    }
}

impl TestState for FmuTestState {
    fn inputs(&mut self, u: &[f64]) {
        self.u.clear();
        self.u.extend_from_slice(u);
    }

    fn step(&mut self, residual: &[f64], statistic: &mut [f64]) {
        debug_assert_eq!(residual.len(), self.outputs);
        let value = if self.flight.is_some() {
            match self.advance(residual) {
                Ok(v) => v,
                Err(e) => {
                    self.flight = None;
                    self.failure = Some(e.to_string());
                    0.0
                }
            }
        } else {
            0.0
        };
        statistic.fill(value);
    }

    fn isolated(&self) -> Option<usize> {
        self.named
    }

    fn failure(&mut self) -> Option<String> {
        self.failure.take()
    }
}

/// No filter: the residual is the measured output, `gamma = y` (a model and a gain of zeros).
#[derive(Debug)]
struct PassThrough;

impl GainDesign for PassThrough {
    fn design(
        &self,
        params: &DetectionFilterParams,
        design: &LtiPlant,
        dt_s: f64,
    ) -> Result<DetectionFilter, DesignError> {
        let (n, nu, ny) = (design.n_states(), design.n_inputs(), design.n_outputs());
        let model = DiscreteLti {
            Ad: DMatrix::zeros(n, n),
            Bd: DMatrix::zeros(n, nu),
            C: DMatrix::zeros(ny, n),
            D: DMatrix::zeros(ny, nu),
            dt_s,
        };
        let (closed_loop_eigenvalues, eigenvector_condition) = eigen_report(&model.Ad)?;
        let discrete = Assignment {
            K: DMatrix::zeros(n, ny),
            closed_loop_eigenvalues,
            eigenvector_condition,
            relative_residual: f64::NAN,
        };
        let decision = params.decision.clone().expect("an FMU detector has its test");
        DetectionFilter::new(model, None, discrete, params, decision, DVector::from_element(ny, 1.0))
    }

    fn describe(&self) -> String {
        "no filter: the measured outputs go to the FMU as they are".into()
    }

    fn kind(&self) -> &'static str {
        "fmu"
    }
}

/// The deck fields only a detector FMU takes, and whether detector `d` gives each.
pub(crate) fn own_fields(d: &super::deck::DetectorSection) -> [(&'static str, bool); 7] {
    [
        ("fmu", d.fmu.is_some()),
        ("measured", !d.measured.is_empty()),
        ("applied", !d.applied.is_empty()),
        ("statistic", d.statistic.is_some()),
        ("isolated_channel", d.isolated_channel.is_some()),
        ("channels", d.channels.is_some()),
        ("parameters", !d.parameters.is_empty()),
    ]
}

/// Reads detector `i` of `kind = "fmu"`: `fmu`, `measured` and `applied` (what it sees), `statistic`
/// and `thresholds` (one number), optionally `isolated_channel` with `channels`, `parameters`, and
/// the isolation timing; no eigenvalues, directions, drift or chi-square fields.
pub(crate) fn read(r: &DetectorDeck) -> Result<DetectionFilterParams, DeckError> {
    let DetectorDeck { chk, i, d, plant, truth, header, .. } = *r;
    let f = |name: &str| format!("detector[{i}].{name}");
    r.refuse(
        &[
            ("eigenvalues_per_s", d.eigenvalues_per_s.is_some()),
            ("fault_directions", d.fault_directions.is_some()),
            ("drift", d.drift.is_some()),
            ("window", d.window.is_some()),
            ("false_alarm_probability", d.false_alarm_probability.is_some()),
            ("design_process_sigma_per_step", d.design_process_sigma_per_step.is_some()),
        ],
        "does not apply to kind = \"fmu\" (the FMU is the detector)",
    )?;
    let file =
        d.fmu.as_ref().ok_or_else(|| chk.err(f("fmu"), "required for kind = \"fmu\": the detector's .fmu file"))?;
    let statistic = d
        .statistic
        .as_ref()
        .ok_or_else(|| chk.err(f("statistic"), "required for kind = \"fmu\": the FMU output it alarms on"))?;
    let threshold = match d.thresholds.as_deref() {
        Some([t]) if t.is_finite() && *t > 0.0 => *t,
        Some([t]) => return Err(chk.err(f("thresholds[0]"), format!("must be a finite number > 0, got {t}"))),
        Some(v) => {
            return Err(chk.err(
                f("thresholds"),
                format!("one number for kind = \"fmu\" (its statistic's threshold), got {}", v.len()),
            ));
        }
        None => {
            return Err(chk.err(f("thresholds"), "required for kind = \"fmu\": one number, the statistic's threshold"));
        }
    };
    if d.measured.is_empty() && d.applied.is_empty() {
        return Err(chk.err(f("measured"), "map at least one FMU input: { fmu_input = \"plant_output\" }"));
    }
    let output_trim = |j: usize| truth.map_or(0.0, |t| t.output_trim[j]);
    let input_trim = |j: usize| truth.map_or(0.0, |t| t.input_trim[j]);
    let (mut inputs, mut trims, mut measured, mut applied) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut input_fields = Vec::new();
    for (input, output) in &d.measured {
        let j = chk.index_of(&f(&format!("measured.{input}")), output, &plant.output_names, "plant.outputs")?;
        input_fields.push(f(&format!("measured.{input}")));
        inputs.push(input.clone());
        trims.push(output_trim(j));
        measured.push(j);
    }
    for (input, plant_input) in &d.applied {
        let j = chk.index_of(&f(&format!("applied.{input}")), plant_input, &plant.input_names, "plant.inputs")?;
        input_fields.push(f(&format!("applied.{input}")));
        inputs.push(input.clone());
        trims.push(input_trim(j));
        applied.push(j);
    }
    let channels = match (&d.isolated_channel, &d.channels) {
        (Some(_), Some(names)) => names
            .iter()
            .enumerate()
            .map(|(k, name)| chk.index_of(&f(&format!("channels[{k}]")), name, &plant.output_names, "plant.outputs"))
            .collect::<Result<Vec<_>, _>>()?,
        (Some(_), None) => {
            return Err(
                chk.err(f("channels"), "required with isolated_channel: the outputs its channels 1, 2, ... name")
            );
        }
        (None, Some(_)) => return Err(chk.err(f("channels"), "only with isolated_channel: remove it")),
        (None, None) => Vec::new(),
    };
    let parameters: Vec<(String, f64)> = d.parameters.iter().map(|(k, v)| (k.clone(), *v)).collect();
    for (name, v) in &parameters {
        chk.finite(&f(&format!("parameters.{name}")), *v)?;
    }
    let mapping = PlantMapping {
        interface: Interface::CoSimulation,
        fault_inputs: &[],
        inputs: &inputs,
        input_fields: &input_fields,
        outputs: std::slice::from_ref(statistic),
        output_fields: &[f("statistic")],
        parameters: &parameters,
        input_trim: &trims,
        stop_s: header.duration_s,
        dt_s: header.dt_s,
    };
    let mut fmu = chk.fmu(&format!("detector[{i}]"), file, &mapping)?;
    // Its statistic is read as it is, not as a deviation from its value at the start.
    fmu.output_trim.iter_mut().for_each(|v| *v = 0.0);
    let described = &fmu.fmu;
    let channel = match &d.isolated_channel {
        None => Channel::None,
        Some(name) => match described.description.variable(name) {
            Some(v) if v.causality == Causality::Output && v.value_type == ValueType::Real => {
                Channel::Real(v.value_reference)
            }
            Some(v) if v.causality == Causality::Output && v.value_type == ValueType::Integer => {
                Channel::Integer(v.value_reference)
            }
            _ => {
                return Err(chk.err(
                    f("isolated_channel"),
                    format!(
                        "{} has no Real or Integer output {name:?}; its outputs: {}",
                        described.file_name(),
                        described.description.names_of(&[Causality::Output]).join(", ")
                    ),
                ));
            }
        },
    };
    let test =
        FmuTest { plant: Arc::new(fmu), measured, applied, channel, channels, statistic_name: statistic.clone() };
    // Our choice, not a paper's: the channel the FMU names 1 s after the alarm.
    let (isolation_delay_s, isolation_window_s) = r.isolation_timing(0.0, 1.0)?;
    Ok(DetectionFilterParams {
        gain: Gain::Own(Arc::new(PassThrough)),
        thresholds: DVector::from_element(plant.n_outputs(), threshold),
        decision: Some(Decision::new(test)),
        isolation: Isolation::Named,
        isolation_delay_s,
        isolation_window_s,
    })
}
