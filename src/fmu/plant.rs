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
    /// Per mapped output, the absolute values beyond which a trial's truth has diverged or left its
    /// physical range (see [`FmuPlant::beyond`]).
    pub output_limits: Vec<(f64, f64)>,
    /// Per mapped output, its scale: the largest of its declared `nominal`, its declared range's
    /// bounds, its value at the trim and 1.
    pub output_scale: Vec<f64>,
    /// How far the outputs may stray from the linear plant's prediction (see [`FmuPlant::strays`]), in
    /// multiples of that prediction's largest magnitude so far plus the output's scale.
    pub stray_factor: f64,
    /// Model exchange: RK4 steps per study step (1 for co-simulation). By default enough that every
    /// mode of the linearisation at the trim has `|lambda| h <= MODE_STEP`; a deck may set the step.
    pub substeps: u32,
    /// Model exchange: what the start looks like (the linearisation at the trim, by central
    /// differences), for the integrator's step and the checks of `fdimc validate`.
    pub at_start: Option<AtStart>,
}

/// The model-exchange FMU at its start (the trim): how fast its fastest mode is and whether it is an
/// equilibrium.
#[derive(Debug, Clone, PartialEq)]
pub struct AtStart {
    /// The largest `|lambda|` of the linearisation's A (1/s).
    pub fastest_mode_per_s: f64,
    /// The continuous states and their derivatives at the start, by name (the FMU's state order).
    pub state_names: Vec<String>,
    pub states: Vec<f64>,
    pub derivatives: Vec<f64>,
    /// The deck says the start is meant not to be an equilibrium (`[truth] transient_start = true`).
    pub transient_intended: bool,
}

impl AtStart {
    /// Why the start is not an equilibrium, if it is not and the deck did not say so: the derivatives
    /// above `EQUILIBRIUM_TOLERANCE x max(|x|, 1)`, by name.
    pub fn not_an_equilibrium(&self) -> Option<String> {
        if self.transient_intended {
            return None;
        }
        let off: Vec<String> = (self.state_names.iter().zip(&self.states).zip(&self.derivatives))
            .filter(|((_, x), dx)| dx.abs() > EQUILIBRIUM_TOLERANCE * x.abs().max(1.0))
            .map(|((n, _), dx)| format!("d {n}/dt = {dx:.4e}"))
            .collect();
        (!off.is_empty()).then(|| {
            format!(
                "the FMU does not start at an equilibrium: {} (the trial starts in a transient the detectors see \
                 as a fault; set the trim (trim_inputs, parameters, [truth.trim]) or, if it is meant, [truth] \
                 transient_start = true)",
                off.join(", ")
            )
        })
    }
}

/// A state derivative at the start above this, relative to `max(|x|, 1)` per second, is not an
/// equilibrium (a choice: far above a solved trim's residual, 1e-10, far below a transient).
pub const EQUILIBRIUM_TOLERANCE: f64 = 1e-6;

/// RK4's step against the fastest mode: `|lambda| h` at most this (a choice: RK4's local error per
/// step on that mode is then about `(|lambda| h)^5 / 120`, 1e-7 relative; FMPy's CVode agrees to 1e-5
/// over a trial of a 100 rad/s mode, tested).
pub const MODE_STEP: f64 = 0.1;

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
        // The variables a deck may name: fdimc's inputs and sensors are real numbers.
        let allowed = |causality: &[Causality]| -> String {
            let names: Vec<&str> = (d.variables.iter())
                .filter(|v| {
                    causality.contains(&v.causality) && v.value_type == ValueType::Real && v.dimensions.is_empty()
                })
                .map(|v| v.name.as_str())
                .collect();
            match names.is_empty() {
                true => "a real variable, and this FMU has none of that causality".to_string(),
                false => format!("one of: {}", names.join(", ")),
            }
        };
        let lookup = |field: String, name: &str, causality: &[Causality], what: &str| -> Result<u32, MappingError> {
            match d.variable(name) {
                // An FMI 3.0 array would take one value where it needs all its elements.
                Some(v) if !v.dimensions.is_empty() => Err((
                    field,
                    format!(
                        "{name:?} of {} is an array ({}): fdimc exchanges scalar variables only, so a deck cannot \
                         map it (an FMU that exposes its elements as scalars can be); {what} must be {}",
                        fmu.file_name(),
                        v.type_label(),
                        allowed(causality)
                    ),
                )),
                Some(v) if causality.contains(&v.causality) && v.value_type == ValueType::Real => Ok(v.value_reference),
                Some(v) if v.value_type == ValueType::Real => Err((
                    field,
                    format!(
                        "{name:?} of {} has causality {} and type Real; {what} must be {}",
                        fmu.file_name(),
                        v.causality.label(),
                        allowed(causality)
                    ),
                )),
                Some(v) => Err((
                    field,
                    format!(
                        "{name:?} of {} has type {}: fdimc reads real variables only (Real, Float64, Float32), no \
                         integer, boolean or string as a signal; {what} must be {}",
                        fmu.file_name(),
                        v.type_name,
                        allowed(causality)
                    ),
                )),
                None => Err((
                    field,
                    format!("{} has no variable {name:?}; {what} must be {}", fmu.file_name(), allowed(causality)),
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
        // A continuous state's start value is set as a parameter is (its initial value).
        let state = |name: &str| {
            d.variable(name).filter(|v| {
                v.value_type == ValueType::Real && d.state_derivative_vrs.iter().any(|s| s.0 == v.value_reference)
            })
        };
        for (name, value) in m.parameters {
            let field = format!("{prefix}.parameters.{name}");
            let vr = match state(name) {
                Some(v) => v.value_reference,
                None => lookup(field.clone(), name, &[Causality::Parameter], "a parameter").map_err(|(f, why)| {
                    let states: Vec<&str> =
                        (d.state_derivative_vrs.iter()).filter_map(|s| d.real(s.0)).map(|v| v.name.as_str()).collect();
                    if states.is_empty() {
                        (f, why)
                    } else {
                        (f, format!("{why}; or a continuous state: {}", states.join(", ")))
                    }
                })?,
            };
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
            substeps: 1,
            at_start: None,
            output_limits: Vec::new(),
            output_scale: Vec::new(),
            stray_factor: STRAY_FACTOR,
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
        let described = &plant.fmu.description;
        (plant.output_limits, plant.output_scale) = (m.outputs.iter().zip(&plant.output_trim))
            .map(|(name, &trim)| {
                let v = described.variable(name).expect("mapped above");
                (output_limits(v, trim), output_scale(v, trim))
            })
            .unzip();
        if m.interface == Interface::ModelExchange && plant.fmu.description.n_states > 0 {
            let l = plant
                .linearise_by(Jacobian::CentralDifferences)
                .map_err(|e| (prefix.to_string(), format!("the FMU fails at its trim: {e}")))?;
            let fastest = l.a.clone().complex_eigenvalues().iter().map(|v| v.norm()).fold(0.0, f64::max);
            let d = &plant.fmu.description;
            let state_names = if d.state_derivative_vrs.len() == l.x_trim.len() {
                d.state_names()
            } else {
                (0..l.x_trim.len()).map(|k| format!("state {k}")).collect()
            };
            plant.substeps = substeps_for(fastest, m.dt_s);
            plant.at_start = Some(AtStart {
                fastest_mode_per_s: fastest,
                state_names,
                states: l.x_trim,
                derivatives: l.derivative_at_trim,
                transient_intended: false,
            });
        }
        Ok(plant)
    }

    /// Model exchange: the RK4 step the deck asks (`h_s`), as a whole number of steps per study step.
    pub fn set_integrator_step(&mut self, h_s: f64, dt_s: f64) {
        self.substeps = steps_of_at_most(dt_s, h_s);
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
        instance.set_substeps(self.substeps);
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
    /// The plant flown.
    pub fn plant(&self) -> &FmuPlant {
        &self.plant
    }

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
    /// What doubts it: the model description's declared dependencies contradicted, an identification
    /// that cannot see a fast mode (printed by `validate`, `design` and `run`).
    pub warnings: Vec<String>,
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
    ///
    /// The FMU's directional derivatives are held against central differences: an exporter may return
    /// wrong ones (the Modelica Reference-FMUs' VanDerPol gives 0 for an output that is a state, d x0 /
    /// d x0), so where any entry of `[A B; C D]` differs by more than 1e-5 of its row's largest, the
    /// central differences are used and a warning names the entries.
    pub fn linearise(&self) -> Result<Linearisation, FmuError> {
        let d = &self.fmu.description;
        let directional = d.model_exchange.as_ref().is_some_and(|me| me.provides_directional_derivatives)
            && d.state_derivative_vrs.len() == d.n_states;
        if !directional {
            return self.linearise_by(Jacobian::CentralDifferences);
        }
        let mut own = self.linearise_by(Jacobian::Directional)?;
        let differences = match self.linearise_by(Jacobian::CentralDifferences) {
            Ok(l) => l,
            Err(e) => {
                own.warnings.push(format!(
                    "{}'s directional derivatives are not checked: central differences at the trim failed ({e})",
                    self.fmu.file_name()
                ));
                return Ok(own);
            }
        };
        let stack = |l: &Linearisation| {
            let (n, nu, ny) = (l.a.nrows(), l.b.ncols(), l.c.nrows());
            let mut j = nalgebra::DMatrix::zeros(n + ny, n + nu);
            j.view_mut((0, 0), (n, n)).copy_from(&l.a);
            j.view_mut((0, n), (n, nu)).copy_from(&l.b);
            j.view_mut((n, 0), (ny, n)).copy_from(&l.c);
            j.view_mut((n, n), (ny, nu)).copy_from(&l.d);
            j
        };
        let (by_fmu, by_differences) = (stack(&own), stack(&differences));
        let name = |vr: u32| d.real_name(vr);
        let rows: Vec<String> = (d.state_derivative_vrs.iter().map(|s| name(s.1)))
            .chain(self.output_vrs.iter().map(|&vr| name(vr)))
            .collect();
        let columns: Vec<String> = (d.state_derivative_vrs.iter().map(|s| name(s.0)))
            .chain(self.input_vrs.iter().map(|&vr| name(vr)))
            .collect();
        let mut differ = Vec::new();
        for r in 0..by_fmu.nrows() {
            let scale = by_fmu.row(r).amax().max(by_differences.row(r).amax());
            for c in 0..by_fmu.ncols() {
                let (ours, theirs) = (by_differences[(r, c)], by_fmu[(r, c)]);
                if (ours - theirs).abs() > 1e-5 * scale || !theirs.is_finite() {
                    differ.push(format!(
                        "d {} / d {}: the FMU's {theirs:.6e}, central differences {ours:.6e}",
                        rows[r], columns[c]
                    ));
                }
            }
        }
        if differ.is_empty() {
            return Ok(own);
        }
        let shown = differ.len().min(4);
        let more = if differ.len() > shown { format!("; and {} more", differ.len() - shown) } else { String::new() };
        let mut used = differences;
        used.warnings.push(format!(
            "{}'s directional derivatives disagree with central differences at the trim ({}{more}): fdimc uses the \
             central differences",
            self.fmu.file_name(),
            differ[..shown].join("; ")
        ));
        used.method = format!("{} (the FMU's directional derivatives disagree with them)", used.method);
        Ok(used)
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
        // f(x, u) and y(x, u). Outputs first, then the states set again and the derivatives: an
        // exporter may compute only the derivatives in GetDerivatives and mark its outputs current
        // (OpenModelica 1.19 and 1.21 then return the previous point's outputs), while setting the
        // states makes every exporter's cached values stale.
        let mut eval = |x: &[f64], u: &[f64]| -> Result<(Vec<f64>, Vec<f64>), FmuError> {
            i.set_real(&self.input_vrs, u)?;
            let mut y = vec![0.0; ny];
            i.reals_at(0.0, x, &self.output_vrs, &mut y)?;
            let mut dx = vec![0.0; n];
            i.derivatives(0.0, x, &mut dx)?;
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
        let warnings = self.undeclared(&jacobian);
        Ok(Linearisation { a, b, c, d, x_trim: x0, derivative_at_trim: f0, method, warnings })
    }

    /// The Jacobian `[A B; C D]` held against `<ModelStructure>`'s declared dependencies: an output's
    /// entry that is exactly zero where the description declares a dependency, or any entry clearly
    /// nonzero where it declares none, names both variables. Either says the FMU or its linearisation is not what it
    /// seems (a stale cached output gives exact zeros).
    fn undeclared(&self, jacobian: &nalgebra::DMatrix<f64>) -> Vec<String> {
        let d = &self.fmu.description;
        if d.state_derivative_vrs.len() != jacobian.ncols() - self.input_vrs.len() {
            return Vec::new();
        }
        let name = |vr: u32| d.real_name(vr);
        let rows: Vec<u32> =
            d.state_derivative_vrs.iter().map(|s| s.1).chain(self.output_vrs.iter().copied()).collect();
        let columns: Vec<u32> =
            d.state_derivative_vrs.iter().map(|s| s.0).chain(self.input_vrs.iter().copied()).collect();
        let mut warnings = Vec::new();
        for (r, unknown) in rows.iter().enumerate() {
            let Some(declared) = d.dependencies.get(unknown) else { continue };
            // An output that is a state is a known, not an unknown: exporters (the Reference-FMUs)
            // declare it with no dependencies.
            if r >= d.state_derivative_vrs.len() && d.state_derivative_vrs.iter().any(|s| s.0 == *unknown) {
                continue;
            }
            // Clearly nonzero: above rounding of a central difference relative to the row's largest entry.
            let scale = jacobian.row(r).amax();
            for (c, known) in columns.iter().enumerate() {
                let v = jacobian[(r, c)];
                let listed = declared.contains(known);
                // An output's exactly-zero declared dependency (a state derivative's may vanish at a
                // trim: d v'/d k = -x/m at x = 0).
                if listed && v == 0.0 && r >= d.state_derivative_vrs.len() {
                    warnings.push(format!(
                        "the linearisation's d {} / d {} is exactly 0, but the FMU declares that {} depends on {} \
                         (an FMU returning stale values, or a dependency at this trim only)",
                        name(*unknown),
                        name(*known),
                        name(*unknown),
                        name(*known)
                    ));
                } else if !listed && v.abs() > 1e-6 * scale.max(f64::MIN_POSITIVE) && v.abs() > 1e-12 {
                    warnings.push(format!(
                        "the linearisation's d {} / d {} is {v:.4e}, but the FMU declares that {} does not depend on {}",
                        name(*unknown),
                        name(*known),
                        name(*unknown),
                        name(*known)
                    ));
                }
            }
        }
        warnings
    }
}

/// How far an output may go before its trial is not data: `DIVERGED_FACTOR` times its scale (the
/// largest of its declared `nominal`, its declared range's bounds, its value at the trim and 1) from
/// the trim, and never beyond its declared `min`/`max` by more than `RANGE_MARGIN` of that scale. A
/// choice: a growth of a million over any scale the model declares is no flight, and 1 % past a
/// declared bound is no rounding.
pub const DIVERGED_FACTOR: f64 = 1e6;
pub const RANGE_MARGIN: f64 = 0.01;

/// How far an output may stray from what the deck's linear plant predicts for the same inputs before
/// its trial is not data, by default: this many times the prediction's largest magnitude so far plus
/// the output's scale (a choice: a nonlinear model that is the linear one's truth differs from it by a
/// fraction of the motion, not by a hundred times the motion and the output's scale; `[truth]
/// stray_factor` sets another, `inf` none).
pub const STRAY_FACTOR: f64 = 100.0;

fn output_scale(v: &super::Variable, trim: f64) -> f64 {
    [v.nominal, v.min, v.max, Some(trim), Some(1.0)]
        .into_iter()
        .flatten()
        .filter(|x| x.is_finite())
        .fold(0.0f64, |m, x| m.max(x.abs()))
}

fn output_limits(v: &super::Variable, trim: f64) -> (f64, f64) {
    let scale = output_scale(v, trim);
    let (mut lo, mut hi) = (trim - DIVERGED_FACTOR * scale, trim + DIVERGED_FACTOR * scale);
    if let Some(min) = v.min.filter(|x| x.is_finite()) {
        lo = lo.max(min - RANGE_MARGIN * scale);
    }
    if let Some(max) = v.max.filter(|x| x.is_finite()) {
        hi = hi.min(max + RANGE_MARGIN * scale);
    }
    (lo, hi)
}

impl FmuPlant {
    /// Why the outputs `y_dev` (deviations from the trim, as a flight reads them) are not a
    /// trajectory to take as data, if they are not: a non-finite value, or one beyond
    /// [`output_limits`](Self::output_limits).
    pub fn beyond(&self, y_dev: &[f64]) -> Option<String> {
        for (k, ((v, trim), (lo, hi))) in y_dev.iter().zip(&self.output_trim).zip(&self.output_limits).enumerate() {
            let y = v + trim;
            if !y.is_finite() || y < *lo || y > *hi {
                let name = self.fmu.description.real_name(self.output_vrs[k]);
                let declared =
                    self.fmu.description.real(self.output_vrs[k]).is_some_and(|v| v.min.is_some() || v.max.is_some());
                return Some(format!(
                    "{name} = {y:e}, outside [{lo:e}, {hi:e}] ({DIVERGED_FACTOR:e} times its scale from the trim{})",
                    if declared {
                        format!(", and its declared range with a {RANGE_MARGIN} margin")
                    } else {
                        String::new()
                    }
                ));
            }
        }
        None
    }

    /// Why the outputs `y_dev` are no trajectory next to what the deck's linear plant predicts for the
    /// same inputs, if they are not: an output `j` with `|y_dev_j - y_lin_j| > stray_factor (peak_j +
    /// scale_j)`, `peak_j` the largest `|y_lin_j|` so far (all deviations from the trim).
    pub fn strays(&self, y_dev: &[f64], y_lin: &[f64], peak_lin: &[f64]) -> Option<String> {
        for (k, ((y, lin), (peak, scale))) in
            y_dev.iter().zip(y_lin).zip(peak_lin.iter().zip(&self.output_scale)).enumerate()
        {
            let allowed = self.stray_factor * (peak + scale);
            if (y - lin).abs() > allowed {
                let name = self.fmu.description.real_name(self.output_vrs[k]);
                return Some(format!(
                    "{name} = {:e} ({y:e} from the trim), where the deck's linear plant predicts {lin:e} for the \
                     same inputs: more than {} x ({peak:e}, the prediction's largest magnitude so far, + {scale:e}, \
                     the output's scale) apart ([truth] stray_factor)",
                    y + self.output_trim[k],
                    self.stray_factor
                ));
            }
        }
        None
    }
}

/// RK4 steps per study step `dt_s` that keep `|lambda| h <= MODE_STEP` for a mode of `fastest_per_s`.
pub fn substeps_for(fastest_per_s: f64, dt_s: f64) -> u32 {
    steps_of_at_most(dt_s, MODE_STEP / fastest_per_s)
}

/// The fewest equal steps of `dt_s` each at most `h_s` long (1 for an infinite or NaN `h_s`); the
/// factor keeps a quotient that is a whole number up to rounding from taking one step more.
fn steps_of_at_most(dt_s: f64, h_s: f64) -> u32 {
    let k = (dt_s / h_s * (1.0 - 1e-12)).ceil();
    if k.is_finite() { k.clamp(1.0, 1e6) as u32 } else { 1 }
}

/// RK4 steps per study step fdimc chooses by itself, at most: more means a mode so fast (a stiff model,
/// or a linearisation across a discontinuity) that an explicit integrator would crawl; the deck is
/// refused unless it sets `truth.integrator_step_s` (a choice: 1,000 is 10 us at a 100 Hz study).
pub const MAX_AUTO_SUBSTEPS: u32 = 1000;

/// Frees this thread's pooled instances of `fmu`.
pub fn release(fmu: &Arc<Fmu>) {
    POOL.with(|p| p.borrow_mut().retain(|(w, _, _)| w.upgrade().is_some_and(|f| !Arc::ptr_eq(&f, fmu))));
}
