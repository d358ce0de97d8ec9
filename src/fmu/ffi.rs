//! The FMI 2.0 and 3.0 C interfaces, declared here from the standard's headers (`fmus/include/`,
//! BSD-2-Clause, Modelica Association Project "FMI") and loaded from an FMU's library with `libloading`.
//!
//! Written by hand rather than generated at build time: bindgen needs libclang on the user's machine,
//! and the dozens of functions fdimc calls are fixed by the standard. Every function is looked up when
//! the library is loaded; one the library lacks is an error when it is called (an FMU need not export
//! what its description does not offer, such as directional derivatives).
//!
//! A library is loaded once per FMU and interface and never unloaded (`RTLD_NODELETE`): exporters'
//! runtimes register thread-key destructors and exit handlers that must outlive every instance, and a
//! run opens few FMUs.

use std::ffi::{c_char, c_int, c_uint, c_void};
use std::path::Path;

pub type Fmi2Status = c_int;
pub const FMI2_OK: Fmi2Status = 0;
pub const FMI2_WARNING: Fmi2Status = 1;
pub const FMI2_DISCARD: Fmi2Status = 2;
pub const FMI2_ERROR: Fmi2Status = 3;
pub const FMI2_FATAL: Fmi2Status = 4;
pub const FMI2_PENDING: Fmi2Status = 5;

/// `fmi2Type`: what `fmi2Instantiate` makes.
pub const FMI2_MODEL_EXCHANGE: c_int = 0;
pub const FMI2_CO_SIMULATION: c_int = 1;

pub type Fmi2Component = *mut c_void;
pub type Fmi2Boolean = c_int;
pub type Fmi2ValueReference = c_uint;

/// `fmi2CallbackLogger`: C-variadic, so its implementation is C (`src/fmu/logger.c`), which formats
/// the message and hands it to [`super::messages`].
pub type Fmi2Logger = unsafe extern "C" fn(*mut c_void, *const c_char, Fmi2Status, *const c_char, *const c_char, ...);

#[repr(C)]
pub struct Fmi2CallbackFunctions {
    pub logger: Option<Fmi2Logger>,
    pub allocate_memory: Option<unsafe extern "C" fn(usize, usize) -> *mut c_void>,
    pub free_memory: Option<unsafe extern "C" fn(*mut c_void)>,
    pub step_finished: Option<unsafe extern "C" fn(*mut c_void, Fmi2Status)>,
    pub component_environment: *mut c_void,
}

#[repr(C)]
#[derive(Debug, Clone, Copy, Default)]
pub struct Fmi2EventInfo {
    pub new_discrete_states_needed: Fmi2Boolean,
    pub terminate_simulation: Fmi2Boolean,
    pub nominals_of_continuous_states_changed: Fmi2Boolean,
    pub values_of_continuous_states_changed: Fmi2Boolean,
    pub next_event_time_defined: Fmi2Boolean,
    pub next_event_time: f64,
}

pub type Fmi3Status = c_int;
pub const FMI3_OK: Fmi3Status = 0;
pub const FMI3_WARNING: Fmi3Status = 1;
pub const FMI3_DISCARD: Fmi3Status = 2;
pub const FMI3_ERROR: Fmi3Status = 3;
pub const FMI3_FATAL: Fmi3Status = 4;

pub type Fmi3Instance = *mut c_void;
pub type Fmi3LogMessage = unsafe extern "C" fn(*mut c_void, Fmi3Status, *const c_char, *const c_char);

unsafe extern "C" {
    /// `src/fmu/logger.c`: formats an FMI 2.0 message and passes it on to `fdimc_fmu_log`.
    pub fn fdimc_fmi2_logger(
        environment: *mut c_void,
        instance_name: *const c_char,
        status: Fmi2Status,
        category: *const c_char,
        message: *const c_char,
        ...
    );
}

/// Declares a table of C functions, each looked up by its own name; a missing one is `None`.
macro_rules! functions {
    ($table:ident { $($name:ident : fn($($arg:ty),*) $(-> $ret:ty)?;)* }) => {
        #[allow(non_snake_case)]
        pub struct $table {
            $(pub $name: Option<unsafe extern "C" fn($($arg),*) $(-> $ret)?>,)*
        }
        impl $table {
            /// # Safety
            /// `lib` must be an FMU library of this FMI version: each symbol found is taken to have the
            /// standard's signature.
            unsafe fn load(lib: &libloading::Library) -> Self {
                $table {
                    $($name: unsafe {
                        lib.get::<unsafe extern "C" fn($($arg),*) $(-> $ret)?>(
                            concat!(stringify!($name), "\0").as_bytes(),
                        )
                        .ok()
                        .map(|s| *s)
                    },)*
                }
            }
        }
    };
}

type Vr = *const c_uint;

functions!(Fmi2Functions {
    fmi2Instantiate: fn(*const c_char, c_int, *const c_char, *const c_char, *const Fmi2CallbackFunctions, Fmi2Boolean, Fmi2Boolean) -> Fmi2Component;
    fmi2FreeInstance: fn(Fmi2Component);
    fmi2SetDebugLogging: fn(Fmi2Component, Fmi2Boolean, usize, *const *const c_char) -> Fmi2Status;
    fmi2SetupExperiment: fn(Fmi2Component, Fmi2Boolean, f64, f64, Fmi2Boolean, f64) -> Fmi2Status;
    fmi2EnterInitializationMode: fn(Fmi2Component) -> Fmi2Status;
    fmi2ExitInitializationMode: fn(Fmi2Component) -> Fmi2Status;
    fmi2Reset: fn(Fmi2Component) -> Fmi2Status;
    fmi2GetReal: fn(Fmi2Component, Vr, usize, *mut f64) -> Fmi2Status;
    fmi2GetInteger: fn(Fmi2Component, Vr, usize, *mut c_int) -> Fmi2Status;
    fmi2GetBoolean: fn(Fmi2Component, Vr, usize, *mut Fmi2Boolean) -> Fmi2Status;
    fmi2SetReal: fn(Fmi2Component, Vr, usize, *const f64) -> Fmi2Status;
    fmi2GetDirectionalDerivative: fn(Fmi2Component, Vr, usize, Vr, usize, *const f64, *mut f64) -> Fmi2Status;
    fmi2EnterEventMode: fn(Fmi2Component) -> Fmi2Status;
    fmi2NewDiscreteStates: fn(Fmi2Component, *mut Fmi2EventInfo) -> Fmi2Status;
    fmi2EnterContinuousTimeMode: fn(Fmi2Component) -> Fmi2Status;
    fmi2CompletedIntegratorStep: fn(Fmi2Component, Fmi2Boolean, *mut Fmi2Boolean, *mut Fmi2Boolean) -> Fmi2Status;
    fmi2SetTime: fn(Fmi2Component, f64) -> Fmi2Status;
    fmi2SetContinuousStates: fn(Fmi2Component, *const f64, usize) -> Fmi2Status;
    fmi2GetDerivatives: fn(Fmi2Component, *mut f64, usize) -> Fmi2Status;
    fmi2GetEventIndicators: fn(Fmi2Component, *mut f64, usize) -> Fmi2Status;
    fmi2GetContinuousStates: fn(Fmi2Component, *mut f64, usize) -> Fmi2Status;
    fmi2DoStep: fn(Fmi2Component, f64, f64, Fmi2Boolean) -> Fmi2Status;
});

functions!(Fmi3Functions {
    fmi3InstantiateModelExchange: fn(*const c_char, *const c_char, *const c_char, bool, bool, *mut c_void, Option<Fmi3LogMessage>) -> Fmi3Instance;
    fmi3InstantiateCoSimulation: fn(*const c_char, *const c_char, *const c_char, bool, bool, bool, bool, Vr, usize, *mut c_void, Option<Fmi3LogMessage>, *const c_void) -> Fmi3Instance;
    fmi3FreeInstance: fn(Fmi3Instance);
    fmi3SetDebugLogging: fn(Fmi3Instance, bool, usize, *const *const c_char) -> Fmi3Status;
    fmi3EnterInitializationMode: fn(Fmi3Instance, bool, f64, f64, bool, f64) -> Fmi3Status;
    fmi3ExitInitializationMode: fn(Fmi3Instance) -> Fmi3Status;
    fmi3Reset: fn(Fmi3Instance) -> Fmi3Status;
    fmi3GetFloat64: fn(Fmi3Instance, Vr, usize, *mut f64, usize) -> Fmi3Status;
    fmi3GetInt32: fn(Fmi3Instance, Vr, usize, *mut i32, usize) -> Fmi3Status;
    fmi3SetFloat64: fn(Fmi3Instance, Vr, usize, *const f64, usize) -> Fmi3Status;
    fmi3GetDirectionalDerivative: fn(Fmi3Instance, Vr, usize, Vr, usize, *const f64, usize, *mut f64, usize) -> Fmi3Status;
    fmi3EnterEventMode: fn(Fmi3Instance) -> Fmi3Status;
    fmi3UpdateDiscreteStates: fn(Fmi3Instance, *mut bool, *mut bool, *mut bool, *mut bool, *mut bool, *mut f64) -> Fmi3Status;
    fmi3EnterContinuousTimeMode: fn(Fmi3Instance) -> Fmi3Status;
    fmi3CompletedIntegratorStep: fn(Fmi3Instance, bool, *mut bool, *mut bool) -> Fmi3Status;
    fmi3SetTime: fn(Fmi3Instance, f64) -> Fmi3Status;
    fmi3SetContinuousStates: fn(Fmi3Instance, *const f64, usize) -> Fmi3Status;
    fmi3GetContinuousStateDerivatives: fn(Fmi3Instance, *mut f64, usize) -> Fmi3Status;
    fmi3GetEventIndicators: fn(Fmi3Instance, *mut f64, usize) -> Fmi3Status;
    fmi3GetContinuousStates: fn(Fmi3Instance, *mut f64, usize) -> Fmi3Status;
    fmi3DoStep: fn(Fmi3Instance, f64, f64, bool, *mut bool, *mut bool, *mut bool, *mut f64) -> Fmi3Status;
});

/// One FMU library, loaded, with its functions.
pub enum Functions {
    V2(Fmi2Functions),
    V3(Fmi3Functions),
}

pub struct Library {
    pub functions: Functions,
    /// Kept so the functions stay valid (the library is never unloaded anyway: see the module's note).
    _library: libloading::Library,
}

impl Library {
    /// Loads the library at `path` for FMI `version` (2 or 3); the error is the loader's own message
    /// (a missing dependency of the library names it).
    pub fn load(path: &Path, version: u8) -> Result<Library, String> {
        let library = open(path)?;
        // SAFETY: the library is an FMU's, of the version its description declares.
        let functions = unsafe {
            match version {
                2 => Functions::V2(Fmi2Functions::load(&library)),
                _ => Functions::V3(Fmi3Functions::load(&library)),
            }
        };
        Ok(Library { functions, _library: library })
    }
}

#[cfg(unix)]
fn open(path: &Path) -> Result<libloading::Library, String> {
    use libloading::os::unix::Library as Unix;
    // RTLD_LOCAL: two FMUs with the same symbols do not see each other's; RTLD_NODELETE: never unloaded.
    let flags = libc::RTLD_NOW | libc::RTLD_LOCAL | libc::RTLD_NODELETE;
    // SAFETY: loading runs the library's initialisers: an FMU's own code, trusted as any FMU is.
    unsafe { Unix::open(Some(path), flags) }.map(Into::into).map_err(|e| e.to_string())
}

#[cfg(not(unix))]
fn open(path: &Path) -> Result<libloading::Library, String> {
    // SAFETY: as above.
    unsafe { libloading::Library::new(path) }.map_err(|e| e.to_string())
}

/// A `file:` URI for a folder (FMI 2.0's `fmuResourceLocation`), with a trailing slash and every byte
/// outside the unreserved set percent-encoded.
pub fn file_uri(folder: &Path) -> String {
    let mut uri = String::from("file://");
    let text = folder.to_string_lossy();
    if !text.starts_with('/') {
        uri.push('/');
    }
    for b in text.replace('\\', "/").bytes() {
        if b.is_ascii_alphanumeric() || b"-._~/:".contains(&b) {
            uri.push(b as char);
        } else {
            uri.push_str(&format!("%{b:02X}"));
        }
    }
    if !uri.ends_with('/') {
        uri.push('/');
    }
    uri
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn resource_uris_are_percent_encoded_with_a_trailing_slash() {
        assert_eq!(file_uri(Path::new("/tmp/a b/resources")), "file:///tmp/a%20b/resources/");
        assert_eq!(file_uri(Path::new("/tmp/x_1.y/")), "file:///tmp/x_1.y/");
        assert_eq!(file_uri(Path::new("/t/%é")), "file:///t/%25%C3%A9/");
    }
}
