//! One instance of an FMU, stepped at the communication step a study gives it.
//!
//! Co-simulation: the FMU's `doStep` (FMI 2.0 and 3.0). Model exchange (FMI 2.0): fdimc integrates the
//! FMU's derivatives with [`Rk4`] over the step, inputs held, as FMI's reference simulator `fmusim` and
//! FMPy's fixed-step solver do with their Euler step: a time event (`nextEventTime`) ends a sub-step
//! exactly at the event; a state event (an event indicator changing sign) and a step event
//! (`enterEventMode` from `completedIntegratorStep`) are handled at the end of the sub-step in which they
//! happen, with the event iteration (`newDiscreteStates` until no update is needed) and the states
//! re-read when the FMU re-initialised them. An event iteration that does not settle, or an FMU asking to
//! terminate, fails the trial: fdimc never steps on past an event it did not handle.

use fmi::fmi2::instance::{CoSimulation as _, Common as _, InstanceCS, InstanceME, ModelExchange as _};
use fmi::fmi3::{CoSimulation as _, Fmi3Model as _, GetSet as _};
use fmi::traits::{FmiInstance, FmiModelExchange};

use super::integrator::Rk4;
use super::{FmiVersion, Fmu, FmuError, Import, Interface, messages};

/// Event iterations at one time instant before the FMU is judged not to settle (a chattering model).
const MAX_EVENT_ITERATIONS: usize = 100;

/// Boxed: the crate's instances are kilobytes of function pointers each.
enum Inner {
    Cs2(Box<InstanceCS>),
    Me2(Box<InstanceME>),
    Cs3(Box<fmi::fmi3::instance::InstanceCS>),
}

/// Model exchange: the continuous states, the integrator and the event bookkeeping.
struct Continuous {
    x: Vec<f64>,
    z: Vec<f64>,
    z_new: Vec<f64>,
    next_event_s: Option<f64>,
    rk4: Rk4,
}

/// One FMU instance. Set parameters after [`Fmu::instantiate`] or [`reset`](Instance::reset), then
/// [`initialise`](Instance::initialise), then per step: inputs, [`step`](Instance::step), outputs.
pub struct Instance {
    inner: Inner,
    label: String,
    time_s: f64,
    continuous: Option<Continuous>,
}

/// An FMI call's failure as a trial's failure: the call, the time and the FMU's own message.
fn failed(label: &str, call: &str, time_s: f64, status: impl std::fmt::Debug) -> FmuError {
    let said = messages::take_last().map(|m| format!(": {m}")).unwrap_or_default();
    FmuError::Failed(format!("{label}: {call} returned {status:?} at t = {time_s} s{said}"))
}

impl Instance {
    pub(super) fn new(fmu: &Fmu, interface: Interface, name: &str) -> Result<Self, FmuError> {
        let label = fmu.file_name();
        let refused = |e: fmi::Error| FmuError::Invalid(format!("{}: cannot instantiate: {e}", fmu.path.display()));
        messages::clear();
        let inner = match (&fmu.import, interface) {
            (Import::V2(imp), Interface::CoSimulation) => {
                Inner::Cs2(Box::new(imp.instantiate_cs(name, false, false).map_err(refused)?))
            }
            (Import::V2(imp), Interface::ModelExchange) => {
                Inner::Me2(Box::new(imp.instantiate_me(name, false, false).map_err(refused)?))
            }
            (Import::V3(imp), Interface::CoSimulation) => {
                Inner::Cs3(Box::new(imp.instantiate_cs(name, false, false, false, false, &[]).map_err(refused)?))
            }
            (Import::V3(_), Interface::ModelExchange) => unreachable!("Fmu::supports refuses FMI 3.0 model exchange"),
        };
        let continuous = matches!(inner, Inner::Me2(_)).then(|| {
            let (n, nz) = (fmu.description.n_states, fmu.description.n_event_indicators);
            Continuous { x: vec![0.0; n], z: vec![0.0; nz], z_new: vec![0.0; nz], next_event_s: None, rk4: Rk4::new(n) }
        });
        debug_assert!(fmu.description.version == FmiVersion::V2 || continuous.is_none());
        Ok(Instance { inner, label, time_s: 0.0, continuous })
    }

    /// The model time the instance has reached (s).
    pub fn time_s(&self) -> f64 {
        self.time_s
    }

    /// Sets real variables by value reference.
    pub fn set_real(&mut self, vrs: &[u32], values: &[f64]) -> Result<(), FmuError> {
        let r = match &mut self.inner {
            Inner::Cs2(i) => i.set_real(vrs, values).map(drop).map_err(|e| format!("{e:?}")),
            Inner::Me2(i) => i.set_real(vrs, values).map(drop).map_err(|e| format!("{e:?}")),
            Inner::Cs3(i) => i.set_float64(vrs, values).map(drop).map_err(|e| format!("{e:?}")),
        };
        r.map_err(|s| failed(&self.label, "set real", self.time_s, s))
    }

    /// Reads real variables by value reference into `out`.
    pub fn get_real(&mut self, vrs: &[u32], out: &mut [f64]) -> Result<(), FmuError> {
        let r = match &mut self.inner {
            Inner::Cs2(i) => i.get_real(vrs, out).map(drop).map_err(|e| format!("{e:?}")),
            Inner::Me2(i) => i.get_real(vrs, out).map(drop).map_err(|e| format!("{e:?}")),
            Inner::Cs3(i) => i.get_float64(vrs, out).map(drop).map_err(|e| format!("{e:?}")),
        };
        r.map_err(|s| failed(&self.label, "get real", self.time_s, s))
    }

    /// Reads integer variables by value reference into `out`.
    pub fn get_integer(&mut self, vrs: &[u32], out: &mut [i32]) -> Result<(), FmuError> {
        let r = match &mut self.inner {
            Inner::Cs2(i) => i.get_integer(vrs, out).map(drop).map_err(|e| format!("{e:?}")),
            Inner::Me2(i) => i.get_integer(vrs, out).map(drop).map_err(|e| format!("{e:?}")),
            Inner::Cs3(i) => i.get_int32(vrs, out).map(drop).map_err(|e| format!("{e:?}")),
        };
        r.map_err(|s| failed(&self.label, "get integer", self.time_s, s))
    }

    /// Initialisation at `start_s` (parameters and start values set before it take effect); model
    /// exchange then settles the initial event iteration and reads the states.
    pub fn initialise(&mut self, start_s: f64, stop_s: f64) -> Result<(), FmuError> {
        messages::clear();
        self.time_s = start_s;
        let label = self.label.clone();
        let fail = |call: &str, s: String| failed(&label, call, start_s, s);
        let stop = Some(stop_s);
        match &mut self.inner {
            Inner::Cs2(i) => {
                FmiInstance::enter_initialization_mode(&mut **i, None, start_s, stop)
                    .map_err(|e| fail("enter initialisation", format!("{e:?}")))?;
                FmiInstance::exit_initialization_mode(&mut **i)
                    .map_err(|e| fail("exit initialisation", format!("{e:?}")))?;
            }
            Inner::Cs3(i) => {
                FmiInstance::enter_initialization_mode(&mut **i, None, start_s, stop)
                    .map_err(|e| fail("enter initialisation", format!("{e:?}")))?;
                FmiInstance::exit_initialization_mode(&mut **i)
                    .map_err(|e| fail("exit initialisation", format!("{e:?}")))?;
            }
            Inner::Me2(i) => {
                FmiInstance::enter_initialization_mode(&mut **i, None, start_s, stop)
                    .map_err(|e| fail("enter initialisation", format!("{e:?}")))?;
                FmiInstance::exit_initialization_mode(&mut **i)
                    .map_err(|e| fail("exit initialisation", format!("{e:?}")))?;
                let c = self.continuous.as_mut().expect("model exchange keeps its states");
                c.next_event_s = event_iteration(i, &label, start_s)?;
                FmiModelExchange::enter_continuous_time_mode(&mut **i)
                    .map_err(|e| fail("enter continuous-time mode", format!("{e:?}")))?;
                FmiModelExchange::get_continuous_states(&mut **i, &mut c.x)
                    .map_err(|e| fail("get states", format!("{e:?}")))?;
                if !c.z.is_empty() {
                    FmiModelExchange::get_event_indicators(&mut **i, &mut c.z)
                        .map_err(|e| fail("get event indicators", format!("{e:?}")))?;
                }
            }
        }
        Ok(())
    }

    /// Advances the model from `t_s` (the time it has reached, as the caller counts it: `k dt`, so no
    /// rounding accumulates) by `dt_s`, inputs held (model exchange: RK4 with events).
    pub fn step(&mut self, t_s: f64, dt_s: f64) -> Result<(), FmuError> {
        let t = t_s;
        let label = self.label.as_str();
        match &mut self.inner {
            Inner::Cs2(i) => {
                i.do_step(t, dt_s, true).map_err(|e| failed(label, "doStep", t, e))?;
            }
            Inner::Cs3(i) => {
                let (mut event, mut terminate, mut early, mut last) = (false, false, false, t);
                i.do_step(t, dt_s, true, &mut event, &mut terminate, &mut early, &mut last)
                    .map_err(|e| failed(label, "doStep", t, e))?;
                if terminate {
                    return Err(FmuError::Failed(format!("{label}: the FMU asked to terminate at t = {last} s")));
                }
            }
            Inner::Me2(i) => {
                let c = self.continuous.as_mut().expect("model exchange keeps its states");
                step_model_exchange(i, c, label, t, dt_s)?;
            }
        }
        self.time_s = t + dt_s;
        Ok(())
    }

    /// Model exchange: the state derivatives at `(t_s, x)`, inputs as set (for linearisation).
    pub fn derivatives(&mut self, t_s: f64, x: &[f64], dx: &mut [f64]) -> Result<(), FmuError> {
        let label = self.label.clone();
        let Inner::Me2(i) = &mut self.inner else {
            return Err(FmuError::Invalid(format!("{label}: state derivatives need the model-exchange interface")));
        };
        let mut time_unset = f64::NAN;
        rhs(i, &label, t_s, x, dx, &mut time_unset)
    }

    /// FMI 2.0: the partial derivative of variable `unknown` (a state derivative or an output) with
    /// respect to `known` (a state or an input), from the FMU (`fmi2GetDirectionalDerivative`, seed 1).
    pub fn partial_derivative(&mut self, unknown: u32, known: u32) -> Result<f64, FmuError> {
        let mut d = [0.0];
        let r = match &mut self.inner {
            Inner::Cs2(i) => i.get_directional_derivative(&[unknown], &[known], &[1.0], &mut d),
            Inner::Me2(i) => i.get_directional_derivative(&[unknown], &[known], &[1.0], &mut d),
            Inner::Cs3(_) => {
                return Err(FmuError::Invalid(format!(
                    "{}: directional derivatives are read from FMI 2.0 FMUs",
                    self.label
                )));
            }
        };
        r.map_err(|e| failed(&self.label, "get directional derivative", self.time_s, format!("{e:?}")))?;
        Ok(d[0])
    }

    /// Model exchange: the current continuous states.
    pub fn states(&self) -> Option<&[f64]> {
        self.continuous.as_ref().map(|c| c.x.as_slice())
    }

    /// Back to the state right after instantiation (FMI `reset`): parameters may be set again.
    pub fn reset(&mut self) -> Result<(), FmuError> {
        messages::clear();
        let r = match &mut self.inner {
            Inner::Cs2(i) => FmiInstance::reset(&mut **i).map(drop).map_err(|e| format!("{e:?}")),
            Inner::Me2(i) => FmiInstance::reset(&mut **i).map(drop).map_err(|e| format!("{e:?}")),
            Inner::Cs3(i) => FmiInstance::reset(&mut **i).map(drop).map_err(|e| format!("{e:?}")),
        };
        self.time_s = 0.0;
        r.map_err(|s| failed(&self.label, "reset", self.time_s, s))
    }
}

/// `dx = f(t, x)` through the FMU: set time (unless `t_set`, the time last set, is it already) and
/// states, get the derivatives.
fn rhs(i: &mut InstanceME, label: &str, t_s: f64, x: &[f64], dx: &mut [f64], t_set: &mut f64) -> Result<(), FmuError> {
    if *t_set != t_s {
        FmiModelExchange::set_time(i, t_s).map_err(|e| failed(label, "setTime", t_s, e))?;
        *t_set = t_s;
    }
    FmiModelExchange::set_continuous_states(i, x).map_err(|e| failed(label, "setContinuousStates", t_s, e))?;
    i.get_derivatives(dx).map_err(|e| failed(label, "getDerivatives", t_s, e))?;
    Ok(())
}

/// The event iteration at one instant (the instance is in event or initialisation-exit mode): the next
/// time event, if the FMU has one.
fn event_iteration(i: &mut InstanceME, label: &str, t_s: f64) -> Result<Option<f64>, FmuError> {
    for _ in 0..MAX_EVENT_ITERATIONS {
        let mut flags = fmi::EventFlags::default();
        i.new_discrete_states(&mut flags).map_err(|e| failed(label, "newDiscreteStates", t_s, e))?;
        if flags.terminate_simulation {
            return Err(FmuError::Failed(format!("{label}: the FMU asked to terminate at t = {t_s} s")));
        }
        if !flags.discrete_states_need_update {
            return Ok(flags.next_event_time);
        }
    }
    Err(FmuError::Failed(format!(
        "{label}: the event iteration at t = {t_s} s did not settle in {MAX_EVENT_ITERATIONS} iterations"
    )))
}

fn step_model_exchange(
    i: &mut InstanceME,
    c: &mut Continuous,
    label: &str,
    t0: f64,
    dt_s: f64,
) -> Result<(), FmuError> {
    let end = t0 + dt_s;
    let mut t = t0;
    // RK4's two middle stages share a time, and its last is the step's end: each is set once.
    let mut t_set = f64::NAN;
    // Sub-steps: the whole step, or up to a time event inside it and then the rest.
    while t < end {
        let time_event = c.next_event_s.filter(|&te| te <= end && te > t);
        let to = time_event.unwrap_or(end);
        // The whole step is `dt_s` itself: `(t0 + dt) - t0` is not `dt` in floating point.
        let h = if to == end && t == t0 { dt_s } else { to - t };
        c.rk4.step(&mut c.x, t, h, |ts, x, dx| rhs(i, label, ts, x, dx, &mut t_set))?;
        if t_set != to {
            FmiModelExchange::set_time(i, to).map_err(|e| failed(label, "setTime", to, e))?;
            t_set = to;
        }
        FmiModelExchange::set_continuous_states(i, &c.x).map_err(|e| failed(label, "setContinuousStates", to, e))?;
        let (mut step_event, mut terminate) = (false, false);
        FmiModelExchange::completed_integrator_step(i, true, &mut step_event, &mut terminate)
            .map_err(|e| failed(label, "completedIntegratorStep", to, e))?;
        if terminate {
            return Err(FmuError::Failed(format!("{label}: the FMU asked to terminate at t = {to} s")));
        }
        let mut state_event = false;
        if !c.z.is_empty() {
            FmiModelExchange::get_event_indicators(i, &mut c.z_new)
                .map_err(|e| failed(label, "getEventIndicators", to, e))?;
            state_event = c.z.iter().zip(&c.z_new).any(|(a, b)| (*a > 0.0) != (*b > 0.0));
        }
        if time_event.is_some() || state_event || step_event {
            FmiModelExchange::enter_event_mode(i).map_err(|e| failed(label, "enterEventMode", to, e))?;
            c.next_event_s = event_iteration(i, label, to)?;
            FmiModelExchange::enter_continuous_time_mode(i)
                .map_err(|e| failed(label, "enterContinuousTimeMode", to, e))?;
            // The states may have been re-initialised; the indicators are the new instant's.
            FmiModelExchange::get_continuous_states(i, &mut c.x)
                .map_err(|e| failed(label, "getContinuousStates", to, e))?;
            if !c.z.is_empty() {
                FmiModelExchange::get_event_indicators(i, &mut c.z_new)
                    .map_err(|e| failed(label, "getEventIndicators", to, e))?;
            }
        }
        std::mem::swap(&mut c.z, &mut c.z_new);
        t = to;
    }
    Ok(())
}
