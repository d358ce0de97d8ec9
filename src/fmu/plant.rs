//! An FMU as a study's plant: its inputs and outputs mapped to a linear model's, in deviations from a
//! trim, with parameters set before initialisation; one instance per worker thread, reset between
//! trials. What any kind needs to fly an FMU where it would fly a model of its own.

use std::cell::RefCell;
use std::path::Path;
use std::sync::{Arc, Weak};

use super::{Causality, Fmu, FmuError, Instance, Interface, ValueType};

/// A mapped FMU plant: what every trial starts from.
#[derive(Debug, Clone)]
pub struct FmuPlant {
    pub fmu: Arc<Fmu>,
    pub interface: Interface,
    /// Value references of the FMU inputs the model's inputs drive (model order).
    pub input_vrs: Vec<u32>,
    /// Value references of the FMU outputs the model's outputs read (model order).
    pub output_vrs: Vec<u32>,
    /// Parameters set before initialisation in every trial (value reference, value).
    pub parameters: Vec<(u32, f64)>,
    /// The FMU's own fault inputs (a fault the model implements, e.g. a loss of effectiveness): value
    /// reference and healthy value (its start value), which a trial's actuator faults change.
    pub fault_inputs: Vec<(u32, f64)>,
    /// The FMU's input values the model's inputs are deviations from.
    pub input_trim: Vec<f64>,
    /// The outputs at the trim (the nominal FMU, initialised with the trim inputs): the model's outputs
    /// are deviations from these.
    pub output_trim: Vec<f64>,
    /// The end of a trial (s), passed to the FMU at initialisation.
    pub stop_s: f64,
}

/// What names the plant maps, as a deck gives them; `field` prefixes name the deck fields in errors.
pub struct PlantMapping<'a> {
    pub interface: Interface,
    pub inputs: &'a [String],
    /// The deck field that names each input, for errors (e.g. `truth.inputs[0]`).
    pub input_fields: &'a [String],
    pub outputs: &'a [String],
    /// The deck field that names each output, for errors.
    pub output_fields: &'a [String],
    pub parameters: &'a [(String, f64)],
    /// FMU inputs the model implements faults with, left at their start values unless a fault acts.
    pub fault_inputs: &'a [String],
    pub input_trim: &'a [f64],
    pub stop_s: f64,
    /// The study's step: a co-simulation FMU that cannot vary its communication step must have it as
    /// its default step.
    pub dt_s: f64,
}

/// Why a mapping is refused: the deck field and the message (the caller adds the deck's file).
pub type MappingError = (String, String);

impl FmuPlant {
    /// Opens `path` (an error names the file) and maps it (an error names the deck field `prefix.*`).
    pub fn open(path: &Path, prefix: &str, m: &PlantMapping) -> Result<Result<FmuPlant, MappingError>, FmuError> {
        let fmu = Fmu::open(path)?;
        fmu.supports(m.interface)?;
        let d = &fmu.description;
        if let (Interface::CoSimulation, Some(info)) = (m.interface, d.co_simulation.as_ref())
            && !info.variable_step
            && d.default_experiment.step_size_s.is_none_or(|h| (h - m.dt_s).abs() > 1e-12 * h.abs().max(m.dt_s))
        {
            return Err(FmuError::Invalid(format!(
                "{}: the FMU steps only at a fixed communication step ({} s, its default experiment) and the study's dt_s is {} s",
                path.display(),
                d.default_experiment.step_size_s.map_or_else(|| "not given".to_string(), |h| h.to_string()),
                m.dt_s
            )));
        }
        Ok(Self::map(Arc::new(fmu), prefix, m))
    }

    fn map(fmu: Arc<Fmu>, prefix: &str, m: &PlantMapping) -> Result<FmuPlant, MappingError> {
        let d = &fmu.description;
        let lookup = |field: String, name: &str, causality: &[Causality], what: &str| -> Result<u32, MappingError> {
            match d.variable(name) {
                Some(v) if causality.contains(&v.causality) && v.value_type == ValueType::Real => Ok(v.value_reference),
                Some(v) => Err((
                    field,
                    format!(
                        "{name:?} of {} has causality {} and type {:?}; {what} must be one of: {}",
                        fmu.file_name(),
                        v.causality.label(),
                        v.value_type,
                        d.names_of(causality).join(", ")
                    ),
                )),
                None => Err((
                    field,
                    format!(
                        "{} has no variable {name:?}; {what} must be one of: {}",
                        fmu.file_name(),
                        d.names_of(causality).join(", ")
                    ),
                )),
            }
        };
        let input_vrs = m
            .inputs
            .iter()
            .enumerate()
            .map(|(k, n)| lookup(m.input_fields[k].clone(), n, &[Causality::Input], "an input"))
            .collect::<Result<Vec<_>, _>>()?;
        // Outputs: what a sensor measures; a state (local) is as good as an output where the FMU exposes it.
        let output_vrs = m
            .outputs
            .iter()
            .enumerate()
            .map(|(k, n)| lookup(m.output_fields[k].clone(), n, &[Causality::Output, Causality::Local], "an output"))
            .collect::<Result<Vec<_>, _>>()?;
        let mut fault_inputs = Vec::with_capacity(m.fault_inputs.len());
        for (k, name) in m.fault_inputs.iter().enumerate() {
            let field = format!("{prefix}.fault_inputs[{k}]");
            if m.inputs.contains(name) {
                return Err((
                    field,
                    format!("{name:?} is mapped to a model input ({prefix}.inputs): a fault input is not"),
                ));
            }
            let vr = lookup(field.clone(), name, &[Causality::Input], "a fault input")?;
            let healthy = d.variable(name).and_then(|v| v.start_f64()).ok_or_else(|| {
                (field, format!("{name:?} has no start value: its healthy value must be the FMU's start value"))
            })?;
            fault_inputs.push((vr, healthy));
        }
        let mut parameters = Vec::with_capacity(m.parameters.len());
        for (name, value) in m.parameters {
            let field = format!("{prefix}.parameters.{name}");
            let vr = lookup(field.clone(), name, &[Causality::Parameter], "a parameter")?;
            if let Some(why) = d.variable(name).and_then(|v| v.out_of_range(*value)) {
                return Err((field, why));
            }
            parameters.push((vr, *value));
        }
        if m.input_trim.len() != input_vrs.len() {
            return Err((
                format!("{prefix}.trim_inputs"),
                format!("{} values for {} inputs: one per input", m.input_trim.len(), input_vrs.len()),
            ));
        }
        for (k, (&u, name)) in m.input_trim.iter().zip(m.inputs).enumerate() {
            if let Some(why) = d.variable(name).and_then(|v| v.out_of_range(u)) {
                let field =
                    if prefix == "truth" { format!("truth.trim_inputs[{k}]") } else { m.input_fields[k].clone() };
                return Err((field, format!("{name}: {why}")));
            }
        }
        let mut plant = FmuPlant {
            fmu,
            interface: m.interface,
            input_vrs,
            output_vrs,
            parameters,
            fault_inputs,
            input_trim: m.input_trim.to_vec(),
            output_trim: Vec::new(),
            stop_s: m.stop_s,
        };
        // The outputs at the trim, read while `output_trim` is still empty (so nothing is subtracted).
        let trim = plant.start(&[]).and_then(|mut t| {
            let mut y = vec![0.0; t.plant.output_vrs.len()];
            t.outputs(&mut y)?;
            Ok(y)
        });
        // This thread's instance is not kept: an FMU allowed one instance per process gets it back on
        // the worker thread.
        release(&plant.fmu);
        match trim {
            Ok(y) => plant.output_trim = y,
            Err(e) => return Err((prefix.to_string(), format!("the FMU fails at its trim: {e}"))),
        }
        Ok(plant)
    }

    /// A trial's flight: this thread's instance (instantiated once, reset between trials), the deck's
    /// parameters then `errors` (value reference, value) set, the trim inputs applied, initialised.
    pub fn start(&self, errors: &[(u32, f64)]) -> Result<Flight<'_>, FmuError> {
        let instance = self.ready(errors)?;
        Ok(Flight {
            plant: PlantRef::Borrowed(self),
            instance: Some(instance),
            inputs: vec![0.0; self.input_vrs.len()],
        })
    }

    /// [`start`](Self::start) for a flight that owns its plant (a detector's test state, which outlives
    /// no borrow).
    pub fn start_shared(self: &Arc<Self>, errors: &[(u32, f64)]) -> Result<Flight<'static>, FmuError> {
        let instance = self.ready(errors)?;
        Ok(Flight {
            plant: PlantRef::Shared(Arc::clone(self)),
            instance: Some(instance),
            inputs: vec![0.0; self.input_vrs.len()],
        })
    }

    fn ready(&self, errors: &[(u32, f64)]) -> Result<Instance, FmuError> {
        let mut instance = take_instance(&self.fmu, self.interface)?;
        for &(vr, v) in self.parameters.iter().chain(errors) {
            instance.set_real(&[vr], &[v])?;
        }
        instance.set_real(&self.input_vrs, &self.input_trim)?;
        for &(vr, healthy) in &self.fault_inputs {
            instance.set_real(&[vr], &[healthy])?;
        }
        instance.initialise(0.0, self.stop_s)?;
        Ok(instance)
    }
}

/// The plant a flight flies: borrowed for a trial's truth, shared for a state that must own it.
enum PlantRef<'p> {
    Borrowed(&'p FmuPlant),
    Shared(Arc<FmuPlant>),
}

impl std::ops::Deref for PlantRef<'_> {
    type Target = FmuPlant;
    fn deref(&self) -> &FmuPlant {
        match self {
            PlantRef::Borrowed(p) => p,
            PlantRef::Shared(p) => p,
        }
    }
}

/// One trial on an FMU plant. Its instance returns to the thread's pool when the flight ends well; an
/// instance that failed is dropped (freed), and the next trial instantiates a fresh one.
pub struct Flight<'p> {
    plant: PlantRef<'p>,
    instance: Option<Instance>,
    inputs: Vec<f64>,
}

impl Flight<'_> {
    /// The model's outputs: the FMU's mapped outputs minus their trim.
    pub fn outputs(&mut self, y: &mut [f64]) -> Result<(), FmuError> {
        let vrs = &self.plant.output_vrs;
        let instance = live(&mut self.instance)?;
        let r = instance.get_real(vrs, y);
        self.fail_on(r)?;
        for (v, t) in y.iter_mut().zip(&self.plant.output_trim) {
            *v -= t;
        }
        Ok(())
    }

    /// Applies the model's inputs `u` (deviations: the FMU gets trim + u) and steps from `t_s` by `dt_s`.
    pub fn step(&mut self, t_s: f64, dt_s: f64, u: &[f64]) -> Result<(), FmuError> {
        self.set_inputs(u)?;
        self.advance(t_s, dt_s)
    }

    /// Sets the model's inputs `u` (deviations: the FMU gets trim + u), for outputs that feed through.
    pub fn set_inputs(&mut self, u: &[f64]) -> Result<(), FmuError> {
        for ((x, trim), du) in self.inputs.iter_mut().zip(&self.plant.input_trim).zip(u) {
            *x = trim + du;
        }
        let (vrs, inputs) = (&self.plant.input_vrs, &self.inputs);
        let instance = live(&mut self.instance)?;
        let r = instance.set_real(vrs, inputs);
        self.fail_on(r)
    }

    /// Sets the FMU's own fault inputs (absolute values, in [`FmuPlant::fault_inputs`] order).
    pub fn set_fault_inputs(&mut self, values: &[f64]) -> Result<(), FmuError> {
        let instance = live(&mut self.instance)?;
        let r =
            (self.plant.fault_inputs.iter().zip(values)).try_for_each(|(&(vr, _), v)| instance.set_real(&[vr], &[*v]));
        self.fail_on(r)
    }

    /// Real variables `vrs` beyond the mapped outputs, as they are now.
    pub fn reals(&mut self, vrs: &[u32], out: &mut [f64]) -> Result<(), FmuError> {
        let instance = live(&mut self.instance)?;
        let r = instance.get_real(vrs, out);
        self.fail_on(r)
    }

    /// Integer variables `vrs` (an isolated channel), as they are now.
    pub fn integers(&mut self, vrs: &[u32], out: &mut [i32]) -> Result<(), FmuError> {
        let instance = live(&mut self.instance)?;
        let r = instance.get_integer(vrs, out);
        self.fail_on(r)
    }

    /// Steps from `t_s` by `dt_s` with the inputs as set.
    pub fn advance(&mut self, t_s: f64, dt_s: f64) -> Result<(), FmuError> {
        let instance = live(&mut self.instance)?;
        let r = instance.step(t_s, dt_s);
        self.fail_on(r)
    }

    fn fail_on(&mut self, r: Result<(), FmuError>) -> Result<(), FmuError> {
        if r.is_err() {
            self.instance = None;
        }
        r
    }
}

/// The flight's instance, unless a failed call dropped it.
fn live(instance: &mut Option<Instance>) -> Result<&mut Instance, FmuError> {
    instance.as_mut().ok_or_else(|| FmuError::Failed("the FMU instance failed earlier".into()))
}

impl Drop for Flight<'_> {
    fn drop(&mut self) {
        if let Some(instance) = self.instance.take() {
            give_back(&self.plant.fmu, self.plant.interface, instance);
        }
    }
}

type Pool = Vec<(Weak<Fmu>, Interface, Instance)>;

thread_local! {
    /// Instances this thread made, by FMU and interface. An entry whose FMU is gone is stale: a new FMU
    /// may live at the same address, so entries are matched by a live `Weak`, not by address.
    static POOL: RefCell<Pool> = const { RefCell::new(Vec::new()) };
}

/// This thread's idle instance of `fmu`, reset, or a new one.
fn take_instance(fmu: &Arc<Fmu>, interface: Interface) -> Result<Instance, FmuError> {
    let pooled = POOL.with(|p| {
        let mut p = p.borrow_mut();
        p.retain(|(w, _, _)| w.strong_count() > 0);
        p.iter()
            .position(|(w, i, _)| *i == interface && w.upgrade().is_some_and(|f| Arc::ptr_eq(&f, fmu)))
            .map(|at| p.swap_remove(at).2)
    });
    match pooled {
        Some(mut instance) => match instance.reset() {
            Ok(()) => Ok(instance),
            // An FMU that cannot reset gets a fresh instance instead.
            Err(_) => fmu.instantiate(interface, "fdimc"),
        },
        None => fmu.instantiate(interface, "fdimc"),
    }
}

fn give_back(fmu: &Arc<Fmu>, interface: Interface, instance: Instance) {
    POOL.with(|p| p.borrow_mut().push((Arc::downgrade(fmu), interface, instance)));
}

/// A plant's linear model about its trim, from the FMU: `dx = A dx + B du`, `dy = C dx + D du`.
#[derive(Debug, Clone, PartialEq)]
pub struct Linearisation {
    pub a: nalgebra::DMatrix<f64>,
    pub b: nalgebra::DMatrix<f64>,
    pub c: nalgebra::DMatrix<f64>,
    pub d: nalgebra::DMatrix<f64>,
    /// The FMU's continuous states at the trim.
    pub x_trim: Vec<f64>,
    /// `max |dx/dt|` at the trim, per state: zero at an equilibrium, what a non-equilibrium trim leaves.
    pub derivative_at_trim: Vec<f64>,
    /// How it was obtained, in words (for `fdimc design`).
    pub method: String,
}

/// The central-difference step of a variable at `v`: `RELATIVE_STEP * max(|v|, 1)`. Truncation error
/// O(h^2) and rounding O(eps / h) are both near 1e-10 relative for smooth models at this step.
pub(super) const RELATIVE_STEP: f64 = 1e-6;

/// Where a linearisation's Jacobian comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Jacobian {
    /// The FMU's own directional derivatives (`fmi2GetDirectionalDerivative`), one entry at a time.
    Directional,
    /// Central differences of its state derivatives and outputs.
    CentralDifferences,
}

impl FmuPlant {
    /// The linearisation at the trim (the deck's parameters and trim inputs) on the FMU's
    /// model-exchange interface: from its directional derivatives where it provides them (and declares
    /// its states), else by central differences. An FMU without model exchange cannot be linearised.
    pub fn linearise(&self) -> Result<Linearisation, FmuError> {
        let d = &self.fmu.description;
        let directional = d.model_exchange.as_ref().is_some_and(|me| me.provides_directional_derivatives)
            && d.state_derivative_vrs.len() == d.n_states;
        self.linearise_by(if directional { Jacobian::Directional } else { Jacobian::CentralDifferences })
    }

    /// [`linearise`](Self::linearise) with the Jacobian from `how`: derivatives and mapped outputs with
    /// respect to the states and the mapped inputs.
    pub fn linearise_by(&self, how: Jacobian) -> Result<Linearisation, FmuError> {
        let fmu = &self.fmu;
        if fmu.supports(Interface::ModelExchange).is_err() {
            return Err(FmuError::Invalid(format!(
                "{}: linearisation needs the FMU's model-exchange interface (FMI 2.0); give [plant] a, b, c instead",
                fmu.path.display()
            )));
        }
        let mut i = fmu.instantiate(Interface::ModelExchange, "fdimc-linearise")?;
        for &(vr, v) in &self.parameters {
            i.set_real(&[vr], &[v])?;
        }
        i.set_real(&self.input_vrs, &self.input_trim)?;
        i.initialise(0.0, self.stop_s)?;
        let x0 = i.states().expect("a model-exchange instance has states").to_vec();
        let (n, nu, ny) = (x0.len(), self.input_vrs.len(), self.output_vrs.len());
        let u0 = self.input_trim.clone();
        // f(x, u) and y(x, u): derivatives and outputs with the states and inputs set.
        let mut eval = |x: &[f64], u: &[f64]| -> Result<(Vec<f64>, Vec<f64>), FmuError> {
            i.set_real(&self.input_vrs, u)?;
            let mut dx = vec![0.0; n];
            i.derivatives(0.0, x, &mut dx)?;
            let mut y = vec![0.0; ny];
            i.get_real(&self.output_vrs, &mut y)?;
            Ok((dx, y))
        };
        let (f0, _) = eval(&x0, &u0)?;
        let mut jacobian = nalgebra::DMatrix::zeros(n + ny, n + nu);
        let method = match how {
            Jacobian::CentralDifferences => {
                // Column k of [A B; C D]: variable k of z = [x; u] perturbed by +/- h, the others at the trim.
                let z0: Vec<f64> = x0.iter().chain(&u0).copied().collect();
                for k in 0..n + nu {
                    let h = RELATIVE_STEP * z0[k].abs().max(1.0);
                    let (mut zp, mut zm) = (z0.clone(), z0.clone());
                    zp[k] += h;
                    zm[k] -= h;
                    let ((fp, yp), (fm, ym)) = (eval(&zp[..n], &zp[n..])?, eval(&zm[..n], &zm[n..])?);
                    let span = zp[k] - zm[k];
                    for (r, (p, m)) in fp.iter().chain(&yp).zip(fm.iter().chain(&ym)).enumerate() {
                        jacobian[(r, k)] = (p - m) / span;
                    }
                }
                format!(
                    "central differences on {}'s model exchange at the trim (step {RELATIVE_STEP:e} x max(|value|, 1) \
                     per state and input)",
                    fmu.file_name()
                )
            }
            Jacobian::Directional => {
                let states = &fmu.description.state_derivative_vrs;
                if states.len() != n {
                    return Err(FmuError::Invalid(format!(
                        "{}: directional derivatives need the states and their derivatives declared in <Derivatives>",
                        fmu.path.display()
                    )));
                }
                // The instance is at the trim (the last evaluation): x0, u0.
                let rows: Vec<u32> = states.iter().map(|s| s.1).chain(self.output_vrs.iter().copied()).collect();
                let columns: Vec<u32> = states.iter().map(|s| s.0).chain(self.input_vrs.iter().copied()).collect();
                for (r, &unknown) in rows.iter().enumerate() {
                    for (c, &known) in columns.iter().enumerate() {
                        jacobian[(r, c)] = i.partial_derivative(unknown, known)?;
                    }
                }
                format!("{}'s directional derivatives at the trim (fmi2GetDirectionalDerivative)", fmu.file_name())
            }
        };
        let (a, b) = (jacobian.view((0, 0), (n, n)).into_owned(), jacobian.view((0, n), (n, nu)).into_owned());
        let (c, d) = (jacobian.view((n, 0), (ny, n)).into_owned(), jacobian.view((n, n), (ny, nu)).into_owned());
        Ok(Linearisation { a, b, c, d, x_trim: x0, derivative_at_trim: f0, method })
    }
}

/// Frees this thread's pooled instances of `fmu`.
pub fn release(fmu: &Arc<Fmu>) {
    POOL.with(|p| p.borrow_mut().retain(|(w, _, _)| w.upgrade().is_some_and(|f| !Arc::ptr_eq(&f, fmu))));
}
