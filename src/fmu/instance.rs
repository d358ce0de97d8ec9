//! One instance of an FMU, stepped at the communication step a study gives it.
//!
//! Co-simulation: the FMU's `doStep` (FMI 2.0 and 3.0). Model exchange (FMI 2.0 and 3.0): fdimc
//! integrates the FMU's derivatives with [`Rk4`] over the step, inputs held: a time event
//! (`nextEventTime`) ends a sub-step exactly at the event; a state event (an event indicator changing
//! sign) is located within the sub-step by bisection (as CVode's root finding, where FMI's `fmusim` and
//! FMPy's fixed-step solver take the sub-step's end); a step event (`enterEventMode` from
//! `completedIntegratorStep`) is handled at the end of its sub-step; each with the event iteration
//! (`newDiscreteStates` / `updateDiscreteStates` until no update is needed) and the states re-read when
//! the FMU re-initialised them. An event iteration that does not settle, or an FMU asking to terminate, fails the trial: fdimc
//! never steps on past an event it did not handle.
//!
//! A call that returns Discard, Error or Fatal fails with the call, the model time and what the FMU
//! logged ([`Inbox`]). After Fatal the FMI standard allows no further call into any instance of that
//! FMU: the instance is not freed, and the library refuses new instances (the loaded library's
//! `poisoned` flag).

use std::ffi::{CString, c_int};
use std::sync::Arc;

use super::ffi::{self, Fmi2CallbackFunctions, Fmi2EventInfo, Functions};
use super::integrator::Rk4;
use super::messages::Inbox;
use super::{Fmu, FmuError, Interface, Loaded};

/// Event iterations at one time instant before the FMU is judged not to settle (a chattering model).
const MAX_EVENT_ITERATIONS: usize = 100;

/// A state event is located to this fraction of the sub-step (or of 1 s, the larger): 2^-40 of it,
/// CVode's root finding's order of accuracy, in at most 40 bisections.
const EVENT_BISECTIONS: u32 = 40;

/// Model exchange: the continuous states, the integrator and the event bookkeeping.
struct Continuous {
    x: Vec<f64>,
    /// The states at the sub-step's start, which a state event's search integrates from again.
    x_start: Vec<f64>,
    z: Vec<f64>,
    z_new: Vec<f64>,
    next_event_s: Option<f64>,
    rk4: Rk4,
    /// RK4 steps per `step` (between time events, the step split evenly).
    substeps: u32,
}

/// One FMU instance. Set parameters after [`Fmu::instantiate`] or [`reset`](Instance::reset), then
/// [`initialise`](Instance::initialise), then per step: inputs, [`step`](Instance::step), outputs.
pub struct Instance {
    /// The FMU's instance pointer (`fmi2Component`, `fmi3Instance`).
    handle: *mut std::ffi::c_void,
    library: Arc<Loaded>,
    /// Where the FMU's logger puts what it says; its address is the instance's environment.
    inbox: Box<Inbox>,
    /// FMI 2.0 keeps a pointer to its callbacks for the instance's life.
    _callbacks: Option<Box<Fmi2CallbackFunctions>>,
    label: String,
    time_s: f64,
    continuous: Option<Continuous>,
}

impl Drop for Instance {
    fn drop(&mut self) {
        // After Fatal nothing may be called, not even the free.
        if self.library.is_poisoned() {
            return;
        }
        // SAFETY: the handle is this instance's, freed once, with the library still loaded.
        match &self.library.library.functions {
            Functions::V2(f) => {
                if let Some(free) = f.fmi2FreeInstance {
                    unsafe { free(self.handle) }
                }
            }
            Functions::V3(f) => {
                if let Some(free) = f.fmi3FreeInstance {
                    unsafe { free(self.handle) }
                }
            }
        }
    }
}

/// A failed FMI call: its name and the status it returned (`None`: the library lacks the function).
struct CallError(&'static str, Option<c_int>);

type Call<T = ()> = Result<T, CallError>;

/// Calls an FMI function of the table `$f` (its status checked), or fails when the library lacks it.
macro_rules! call {
    ($f:expr, $name:ident ( $($arg:expr),* $(,)? )) => {
        match $f.$name {
            // SAFETY: the standard's signature (ffi.rs); the arguments are valid for the call.
            Some(function) => check(stringify!($name), unsafe { function($($arg),*) }),
            None => Err(CallError(stringify!($name), None)),
        }
    };
}

/// FMI 2.0 and 3.0 number OK (0) and Warning (1) alike: both let the computation go on.
fn check(name: &'static str, status: c_int) -> Call {
    if status == ffi::FMI2_OK || status == ffi::FMI2_WARNING { Ok(()) } else { Err(CallError(name, Some(status))) }
}

fn status_word(status: c_int) -> &'static str {
    match status {
        ffi::FMI2_DISCARD => "Discard",
        ffi::FMI2_ERROR => "Error",
        ffi::FMI2_FATAL => "Fatal",
        ffi::FMI2_PENDING => "Pending",
        _ => "an unknown status",
    }
}

impl Instance {
    pub(super) fn new(fmu: &Fmu, interface: Interface, name: &str) -> Result<Self, FmuError> {
        let shown = fmu.path.display();
        let library = fmu.library(interface)?;
        if library.is_poisoned() {
            return Err(FmuError::Failed(format!(
                "{}: the FMU returned Fatal earlier in this process: the FMI standard allows no further call into it",
                fmu.file_name()
            )));
        }
        let d = &fmu.description;
        let c = |s: &str, what: &str| {
            CString::new(s).map_err(|_| FmuError::Invalid(format!("{shown}: the {what} holds a NUL character")))
        };
        let instance_name = c(name, "instance name")?;
        let token = c(&d.instantiation_token, "instantiation token (guid)")?;
        let resources = fmu.unpacked.path().join("resources");
        // The FMU logs its errors when told to: status categories on where it declares them.
        let status_categories: Vec<CString> = d
            .log_categories
            .iter()
            .filter(|c| c.starts_with("logStatus") && !c.ends_with("Pending"))
            .filter_map(|c| CString::new(c.as_str()).ok())
            .collect();
        let logging_on = !status_categories.is_empty();
        let category_ptrs: Vec<*const std::ffi::c_char> = status_categories.iter().map(|c| c.as_ptr()).collect();
        let inbox = Box::new(Inbox::default());
        let refused = |why: String| {
            let said = inbox.take().map(|m| format!(" (the FMU said: {m})")).unwrap_or_default();
            FmuError::Invalid(format!("{shown}: cannot instantiate its {} interface: {why}{said}", interface.name()))
        };
        let mut callbacks = None;
        let handle = match &library.library.functions {
            Functions::V2(f) => {
                let cb = Box::new(Fmi2CallbackFunctions {
                    logger: Some(ffi::fdimc_fmi2_logger as ffi::Fmi2Logger),
                    allocate_memory: Some(libc::calloc),
                    free_memory: Some(libc::free),
                    step_finished: None,
                    component_environment: inbox.environment(),
                });
                let uri = c(&ffi::file_uri(&resources), "resource path")?;
                let kind = match interface {
                    Interface::ModelExchange => ffi::FMI2_MODEL_EXCHANGE,
                    Interface::CoSimulation => ffi::FMI2_CO_SIMULATION,
                };
                let instantiate =
                    f.fmi2Instantiate.ok_or_else(|| refused("its library has no fmi2Instantiate".into()))?;
                // SAFETY: valid strings and callbacks, which outlive the instance (kept in it).
                let h = unsafe {
                    instantiate(
                        instance_name.as_ptr(),
                        kind,
                        token.as_ptr(),
                        uri.as_ptr(),
                        &*cb,
                        0,
                        logging_on as c_int,
                    )
                };
                callbacks = Some(cb);
                if !h.is_null() && logging_on {
                    let _ = call!(f, fmi2SetDebugLogging(h, 1, category_ptrs.len(), category_ptrs.as_ptr()));
                }
                h
            }
            Functions::V3(f) => {
                let mut path = resources.to_string_lossy().into_owned();
                path.push(std::path::MAIN_SEPARATOR);
                let path = c(&path, "resource path")?;
                let env = inbox.environment();
                let log = Some(super::messages::fdimc_fmu_log as ffi::Fmi3LogMessage);
                // SAFETY: valid strings; the environment (the inbox) outlives the instance.
                let h = unsafe {
                    match interface {
                        Interface::ModelExchange => {
                            let instantiate = f
                                .fmi3InstantiateModelExchange
                                .ok_or_else(|| refused("its library has no fmi3InstantiateModelExchange".into()))?;
                            instantiate(
                                instance_name.as_ptr(),
                                token.as_ptr(),
                                path.as_ptr(),
                                false,
                                logging_on,
                                env,
                                log,
                            )
                        }
                        Interface::CoSimulation => {
                            let instantiate = f
                                .fmi3InstantiateCoSimulation
                                .ok_or_else(|| refused("its library has no fmi3InstantiateCoSimulation".into()))?;
                            instantiate(
                                instance_name.as_ptr(),
                                token.as_ptr(),
                                path.as_ptr(),
                                false,
                                logging_on,
                                false,
                                false,
                                std::ptr::null(),
                                0,
                                env,
                                log,
                                std::ptr::null(),
                            )
                        }
                    }
                };
                if !h.is_null() && logging_on {
                    let _ = call!(f, fmi3SetDebugLogging(h, true, category_ptrs.len(), category_ptrs.as_ptr()));
                }
                h
            }
        };
        if handle.is_null() {
            return Err(refused("the FMU returned no instance".into()));
        }
        let continuous = (interface == Interface::ModelExchange).then(|| {
            let (n, nz) = (d.n_states, d.n_event_indicators);
            Continuous {
                x: vec![0.0; n],
                x_start: vec![0.0; n],
                z: vec![0.0; nz],
                z_new: vec![0.0; nz],
                next_event_s: None,
                rk4: Rk4::new(n),
                substeps: 1,
            }
        });
        Ok(Instance { handle, library, inbox, _callbacks: callbacks, label: fmu.file_name(), time_s: 0.0, continuous })
    }

    /// A failed call as a trial's failure: the call, the time and what the FMU logged. A Fatal
    /// status poisons the library (no further call into it).
    fn failed(&self, e: CallError, time_s: f64) -> FmuError {
        let CallError(name, status) = e;
        let Some(status) = status else {
            return FmuError::Failed(format!(
                "{}: the FMU's library has no {name}, which fdimc needs here",
                self.label
            ));
        };
        if status == ffi::FMI2_FATAL {
            self.library.poison();
        }
        let said = self.inbox.take().map(|m| format!(": the FMU said {m}")).unwrap_or_default();
        FmuError::Failed(format!("{}: {name} returned {} at t = {time_s} s{said}", self.label, status_word(status)))
    }

    /// Model exchange: RK4 steps per [`step`](Self::step) (at least 1; co-simulation ignores it).
    pub fn set_substeps(&mut self, substeps: u32) {
        if let Some(c) = self.continuous.as_mut() {
            c.substeps = substeps.max(1);
        }
    }

    /// The model time the instance has reached (s).
    pub fn time_s(&self) -> f64 {
        self.time_s
    }

    /// Sets real variables by value reference.
    pub fn set_real(&mut self, vrs: &[u32], values: &[f64]) -> Result<(), FmuError> {
        assert_eq!(vrs.len(), values.len(), "one value per value reference");
        let h = self.handle;
        let r = match &self.library.library.functions {
            Functions::V2(f) => call!(f, fmi2SetReal(h, vrs.as_ptr(), vrs.len(), values.as_ptr())),
            Functions::V3(f) => call!(f, fmi3SetFloat64(h, vrs.as_ptr(), vrs.len(), values.as_ptr(), values.len())),
        };
        r.map_err(|e| self.failed(e, self.time_s))
    }

    /// Reads real variables by value reference into `out`.
    pub fn get_real(&mut self, vrs: &[u32], out: &mut [f64]) -> Result<(), FmuError> {
        assert_eq!(vrs.len(), out.len(), "one value per value reference");
        let h = self.handle;
        let r = match &self.library.library.functions {
            Functions::V2(f) => call!(f, fmi2GetReal(h, vrs.as_ptr(), vrs.len(), out.as_mut_ptr())),
            Functions::V3(f) => call!(f, fmi3GetFloat64(h, vrs.as_ptr(), vrs.len(), out.as_mut_ptr(), out.len())),
        };
        r.map_err(|e| self.failed(e, self.time_s))
    }

    /// Reads integer variables by value reference into `out`.
    pub fn get_integer(&mut self, vrs: &[u32], out: &mut [i32]) -> Result<(), FmuError> {
        assert_eq!(vrs.len(), out.len(), "one value per value reference");
        let h = self.handle;
        let r = match &self.library.library.functions {
            Functions::V2(f) => call!(f, fmi2GetInteger(h, vrs.as_ptr(), vrs.len(), out.as_mut_ptr())),
            Functions::V3(f) => call!(f, fmi3GetInt32(h, vrs.as_ptr(), vrs.len(), out.as_mut_ptr(), out.len())),
        };
        r.map_err(|e| self.failed(e, self.time_s))
    }

    /// Initialisation at `start_s` (parameters and start values set before it take effect); model
    /// exchange then settles the initial event iteration and reads the states.
    pub fn initialise(&mut self, start_s: f64, stop_s: f64) -> Result<(), FmuError> {
        self.inbox.clear();
        self.time_s = start_s;
        let h = self.handle;
        let r = match &self.library.library.functions {
            Functions::V2(f) => call!(f, fmi2SetupExperiment(h, 0, 0.0, start_s, 1, stop_s))
                .and_then(|()| call!(f, fmi2EnterInitializationMode(h)))
                .and_then(|()| call!(f, fmi2ExitInitializationMode(h))),
            Functions::V3(f) => call!(f, fmi3EnterInitializationMode(h, false, 0.0, start_s, true, stop_s))
                .and_then(|()| call!(f, fmi3ExitInitializationMode(h))),
        };
        r.map_err(|e| self.failed(e, start_s))?;
        if let Some(mut c) = self.continuous.take() {
            let r = self.settle_initial(&mut c, start_s);
            self.continuous = Some(c);
            r?;
        }
        Ok(())
    }

    fn settle_initial(&mut self, c: &mut Continuous, start_s: f64) -> Result<(), FmuError> {
        c.next_event_s = self.event_iteration(start_s)?;
        self.enter_continuous_time_mode().map_err(|e| self.failed(e, start_s))?;
        self.get_states(&mut c.x).map_err(|e| self.failed(e, start_s))?;
        if !c.z.is_empty() {
            self.get_event_indicators(&mut c.z).map_err(|e| self.failed(e, start_s))?;
        }
        Ok(())
    }

    /// Advances the model from `t_s` (the time it has reached, as the caller counts it: `k dt`, so no
    /// rounding accumulates) by `dt_s`, inputs held (model exchange: RK4 with events).
    pub fn step(&mut self, t_s: f64, dt_s: f64) -> Result<(), FmuError> {
        let h = self.handle;
        match self.continuous.take() {
            Some(mut c) => {
                let r = self.step_model_exchange(&mut c, t_s, dt_s);
                self.continuous = Some(c);
                r?;
            }
            None => match &self.library.library.functions {
                Functions::V2(f) => call!(f, fmi2DoStep(h, t_s, dt_s, 1)).map_err(|e| self.failed(e, t_s))?,
                Functions::V3(f) => {
                    let (mut event, mut terminate, mut early, mut last) = (false, false, false, t_s);
                    call!(f, fmi3DoStep(h, t_s, dt_s, true, &mut event, &mut terminate, &mut early, &mut last))
                        .map_err(|e| self.failed(e, t_s))?;
                    if terminate {
                        return Err(FmuError::Failed(format!(
                            "{}: the FMU asked to terminate at t = {last} s",
                            self.label
                        )));
                    }
                }
            },
        }
        self.time_s = t_s + dt_s;
        Ok(())
    }

    /// Model exchange: the state derivatives at `(t_s, x)`, inputs as set (for linearisation).
    pub fn derivatives(&mut self, t_s: f64, x: &[f64], dx: &mut [f64]) -> Result<(), FmuError> {
        if self.continuous.is_none() {
            return Err(FmuError::Invalid(format!(
                "{}: state derivatives need the model-exchange interface",
                self.label
            )));
        }
        let mut time_unset = f64::NAN;
        self.rhs(t_s, x, dx, &mut time_unset)
    }

    /// Model exchange: real variables `vrs` at `(t_s, x)`, inputs as set (for linearisation).
    pub fn reals_at(&mut self, t_s: f64, x: &[f64], vrs: &[u32], out: &mut [f64]) -> Result<(), FmuError> {
        if self.continuous.is_none() {
            return Err(FmuError::Invalid(format!(
                "{}: setting states needs the model-exchange interface",
                self.label
            )));
        }
        self.set_time(t_s).map_err(|e| self.failed(e, t_s))?;
        self.set_states(x).map_err(|e| self.failed(e, t_s))?;
        self.get_real(vrs, out)
    }

    /// The partial derivative of variable `unknown` (a state derivative or an output) with respect to
    /// `known` (a state or an input), from the FMU (`GetDirectionalDerivative`, seed 1).
    pub fn partial_derivative(&mut self, unknown: u32, known: u32) -> Result<f64, FmuError> {
        let (h, mut d) = (self.handle, [0.0]);
        let (u, k) = ([unknown], [known]);
        let r = match &self.library.library.functions {
            Functions::V2(f) => {
                call!(f, fmi2GetDirectionalDerivative(h, u.as_ptr(), 1, k.as_ptr(), 1, [1.0].as_ptr(), d.as_mut_ptr()))
            }
            Functions::V3(f) => call!(
                f,
                fmi3GetDirectionalDerivative(h, u.as_ptr(), 1, k.as_ptr(), 1, [1.0].as_ptr(), 1, d.as_mut_ptr(), 1)
            ),
        };
        r.map_err(|e| self.failed(e, self.time_s))?;
        Ok(d[0])
    }

    /// Model exchange: the current continuous states.
    pub fn states(&self) -> Option<&[f64]> {
        self.continuous.as_ref().map(|c| c.x.as_slice())
    }

    /// Back to the state right after instantiation (FMI `reset`): parameters may be set again.
    pub fn reset(&mut self) -> Result<(), FmuError> {
        self.inbox.clear();
        let h = self.handle;
        let r = match &self.library.library.functions {
            Functions::V2(f) => call!(f, fmi2Reset(h)),
            Functions::V3(f) => call!(f, fmi3Reset(h)),
        };
        self.time_s = 0.0;
        r.map_err(|e| self.failed(e, 0.0))
    }

    // The model-exchange calls, one per FMI function both versions have.

    fn set_time(&self, t_s: f64) -> Call {
        let h = self.handle;
        match &self.library.library.functions {
            Functions::V2(f) => call!(f, fmi2SetTime(h, t_s)),
            Functions::V3(f) => call!(f, fmi3SetTime(h, t_s)),
        }
    }

    // A model without continuous states (a feedthrough, a lookup) has nothing to get or set: the
    // Reference-FMUs' FMI 3.0 Feedthrough answers such a call with an error.
    fn set_states(&self, x: &[f64]) -> Call {
        if x.is_empty() {
            return Ok(());
        }
        let h = self.handle;
        match &self.library.library.functions {
            Functions::V2(f) => call!(f, fmi2SetContinuousStates(h, x.as_ptr(), x.len())),
            Functions::V3(f) => call!(f, fmi3SetContinuousStates(h, x.as_ptr(), x.len())),
        }
    }

    fn get_states(&self, x: &mut [f64]) -> Call {
        if x.is_empty() {
            return Ok(());
        }
        let h = self.handle;
        match &self.library.library.functions {
            Functions::V2(f) => call!(f, fmi2GetContinuousStates(h, x.as_mut_ptr(), x.len())),
            Functions::V3(f) => call!(f, fmi3GetContinuousStates(h, x.as_mut_ptr(), x.len())),
        }
    }

    fn get_derivatives(&self, dx: &mut [f64]) -> Call {
        if dx.is_empty() {
            return Ok(());
        }
        let h = self.handle;
        match &self.library.library.functions {
            Functions::V2(f) => call!(f, fmi2GetDerivatives(h, dx.as_mut_ptr(), dx.len())),
            Functions::V3(f) => call!(f, fmi3GetContinuousStateDerivatives(h, dx.as_mut_ptr(), dx.len())),
        }
    }

    fn get_event_indicators(&self, z: &mut [f64]) -> Call {
        let h = self.handle;
        match &self.library.library.functions {
            Functions::V2(f) => call!(f, fmi2GetEventIndicators(h, z.as_mut_ptr(), z.len())),
            Functions::V3(f) => call!(f, fmi3GetEventIndicators(h, z.as_mut_ptr(), z.len())),
        }
    }

    fn enter_event_mode(&self) -> Call {
        let h = self.handle;
        match &self.library.library.functions {
            Functions::V2(f) => call!(f, fmi2EnterEventMode(h)),
            Functions::V3(f) => call!(f, fmi3EnterEventMode(h)),
        }
    }

    fn enter_continuous_time_mode(&self) -> Call {
        let h = self.handle;
        match &self.library.library.functions {
            Functions::V2(f) => call!(f, fmi2EnterContinuousTimeMode(h)),
            Functions::V3(f) => call!(f, fmi3EnterContinuousTimeMode(h)),
        }
    }

    /// `completedIntegratorStep`: (enter event mode, terminate).
    fn completed_integrator_step(&self) -> Call<(bool, bool)> {
        let h = self.handle;
        match &self.library.library.functions {
            Functions::V2(f) => {
                let (mut event, mut terminate) = (0, 0);
                call!(f, fmi2CompletedIntegratorStep(h, 1, &mut event, &mut terminate))?;
                Ok((event != 0, terminate != 0))
            }
            Functions::V3(f) => {
                let (mut event, mut terminate) = (false, false);
                call!(f, fmi3CompletedIntegratorStep(h, true, &mut event, &mut terminate))?;
                Ok((event, terminate))
            }
        }
    }

    /// One `newDiscreteStates` / `updateDiscreteStates`: (needs another, terminate, next time event).
    fn update_discrete_states(&self) -> Call<(bool, bool, Option<f64>)> {
        let h = self.handle;
        match &self.library.library.functions {
            Functions::V2(f) => {
                let mut info = Fmi2EventInfo::default();
                call!(f, fmi2NewDiscreteStates(h, &mut info))?;
                let next = (info.next_event_time_defined != 0).then_some(info.next_event_time);
                Ok((info.new_discrete_states_needed != 0, info.terminate_simulation != 0, next))
            }
            Functions::V3(f) => {
                let (mut again, mut terminate, mut nominals, mut values, mut defined, mut next) =
                    (false, false, false, false, false, 0.0);
                call!(
                    f,
                    fmi3UpdateDiscreteStates(
                        h,
                        &mut again,
                        &mut terminate,
                        &mut nominals,
                        &mut values,
                        &mut defined,
                        &mut next
                    )
                )?;
                Ok((again, terminate, defined.then_some(next)))
            }
        }
    }

    /// `dx = f(t, x)` through the FMU: set time (unless `t_set`, the time last set, is it already) and
    /// states, get the derivatives.
    fn rhs(&self, t_s: f64, x: &[f64], dx: &mut [f64], t_set: &mut f64) -> Result<(), FmuError> {
        if *t_set != t_s {
            self.set_time(t_s).map_err(|e| self.failed(e, t_s))?;
            *t_set = t_s;
        }
        self.set_states(x).map_err(|e| self.failed(e, t_s))?;
        self.get_derivatives(dx).map_err(|e| self.failed(e, t_s))
    }

    /// The event iteration at one instant (the instance is in event or initialisation-exit mode): the
    /// next time event, if the FMU has one.
    fn event_iteration(&self, t_s: f64) -> Result<Option<f64>, FmuError> {
        for _ in 0..MAX_EVENT_ITERATIONS {
            let (again, terminate, next) = self.update_discrete_states().map_err(|e| self.failed(e, t_s))?;
            if terminate {
                return Err(FmuError::Failed(format!("{}: the FMU asked to terminate at t = {t_s} s", self.label)));
            }
            if !again {
                return Ok(next);
            }
        }
        Err(FmuError::Failed(format!(
            "{}: the event iteration at t = {t_s} s did not settle in {MAX_EVENT_ITERATIONS} iterations",
            self.label
        )))
    }

    fn step_model_exchange(&self, c: &mut Continuous, t0: f64, dt_s: f64) -> Result<(), FmuError> {
        let end = t0 + dt_s;
        let mut t = t0;
        // RK4's two middle stages share a time, and its last is the step's end: each is set once.
        let mut t_set = f64::NAN;
        // Sub-steps: the whole step in `substeps` equal parts, a part cut at a time event inside it.
        let part = dt_s / c.substeps as f64;
        let mut k = 0u32;
        while t < end {
            let time_event = c.next_event_s.filter(|&te| te <= end && te > t);
            k += 1;
            // The parts' ends are counted from t0 (no rounding accumulates); the last is `end` itself.
            let grid = if k >= c.substeps { end } else { t0 + part * k as f64 };
            let mut to = match time_event {
                Some(te) if te < grid => {
                    k -= 1; // the part resumes after the event
                    te
                }
                Some(te) if te == grid => te,
                _ => grid,
            };
            let mut hits_event = time_event == Some(to);
            // The whole step is `dt_s` itself: `(t0 + dt) - t0` is not `dt` in floating point.
            let h = if to == end && t == t0 { dt_s } else { to - t };
            c.x_start.copy_from_slice(&c.x);
            // One RK4 step of `tau` from the sub-step's start, the FMU left at its end with the event
            // indicators read there: whether one changed sign.
            let mut try_step = |c: &mut Continuous, tau: f64, at: f64| -> Result<bool, FmuError> {
                c.x.copy_from_slice(&c.x_start);
                c.rk4.step(&mut c.x, t, tau, |ts, x, dx| self.rhs(ts, x, dx, &mut t_set))?;
                if t_set != at {
                    self.set_time(at).map_err(|e| self.failed(e, at))?;
                    t_set = at;
                }
                self.set_states(&c.x).map_err(|e| self.failed(e, at))?;
                if c.z.is_empty() {
                    return Ok(false);
                }
                self.get_event_indicators(&mut c.z_new).map_err(|e| self.failed(e, at))?;
                Ok(c.z.iter().zip(&c.z_new).any(|(a, b)| (*a > 0.0) != (*b > 0.0)))
            };
            let mut state_event = try_step(c, h, to)?;
            if state_event {
                // Located by bisection on the step's length, as CVode's root finding would (at the
                // sub-step's end, a bouncing ball loses up to a sub-step of fall per bounce and never
                // comes to rest). The FMU takes the step to the first time past the sign change; the
                // part resumes from there.
                let (mut lo, mut hi) = (0.0, h);
                let tolerance = h.max(1.0) * 0.5f64.powi(EVENT_BISECTIONS as i32);
                while hi - lo > tolerance {
                    let mid = 0.5 * (lo + hi);
                    if try_step(c, mid, t + mid)? {
                        hi = mid;
                    } else {
                        lo = mid;
                    }
                }
                // Late in a long flight `t + hi` may round to `t`: then the sub-step's end it is, as
                // before, so that time always moves on.
                if hi < h && t + hi > t {
                    if to == grid {
                        k -= 1; // the part resumes after the event (a time event's cut did so already)
                    }
                    to = t + hi;
                    hits_event = false;
                    state_event = try_step(c, hi, to)?;
                }
            }
            let (step_event, terminate) = self.completed_integrator_step().map_err(|e| self.failed(e, to))?;
            if terminate {
                return Err(FmuError::Failed(format!("{}: the FMU asked to terminate at t = {to} s", self.label)));
            }
            if hits_event || state_event || step_event {
                self.enter_event_mode().map_err(|e| self.failed(e, to))?;
                c.next_event_s = self.event_iteration(to)?;
                self.enter_continuous_time_mode().map_err(|e| self.failed(e, to))?;
                // The states may have been re-initialised; the indicators are the new instant's.
                self.get_states(&mut c.x).map_err(|e| self.failed(e, to))?;
                if !c.z.is_empty() {
                    self.get_event_indicators(&mut c.z_new).map_err(|e| self.failed(e, to))?;
                }
            }
            std::mem::swap(&mut c.z, &mut c.z_new);
            t = to;
        }
        Ok(())
    }
}
