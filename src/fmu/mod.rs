//! FMUs (Functional Mock-up Units, FMI 2.0 and 3.0): a user's model or detector, as a building block any
//! kind can use where a model is needed.
//!
//! [`Fmu::open`] checks a `.fmu` file (a zip, its `modelDescription.xml`, a binary for this platform)
//! and unpacks it; its library is loaded through fdimc's own declarations of the FMI C interface
//! ([`ffi`]) when an interface is first instantiated; [`Description`] is what the description says;
//! [`Instance`] steps one instance: co-simulation through the FMU's own `doStep`, model exchange by
//! fdimc's fixed-step [`integrator::Rk4`] with the FMU's time and state events handled (FMI 2.0 and
//! 3.0 alike). Instances are not `Send`: each worker thread instantiates its own.

pub mod description;
pub mod ffi;
pub mod identify;
pub mod instance;
pub mod integrator;
pub mod messages;
pub mod plant;
pub mod trim;

use std::collections::HashMap;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

use sha2::{Digest, Sha256};

pub use description::{Causality, Description, FmiVersion, Interface, ValueType, Variable};
pub use instance::Instance;

/// Why an FMU cannot be used or a call into it failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FmuError {
    /// The file or what it declares cannot be used (a deck's error: exit 2). The text names the file.
    #[error("{0}")]
    Invalid(String),
    /// A call into the FMU failed (a trial's failure): which call, at what time, what the FMU said.
    #[error("{0}")]
    Failed(String),
}

/// The platform folder of an FMU's binaries on this machine, per FMI version.
pub fn platform_folder(version: FmiVersion) -> Option<&'static str> {
    match (version, std::env::consts::OS, std::env::consts::ARCH) {
        (FmiVersion::V2, "linux", "x86_64") => Some("linux64"),
        (FmiVersion::V2, "linux", "x86") => Some("linux32"),
        (FmiVersion::V2, "macos", _) => Some("darwin64"),
        (FmiVersion::V2, "windows", "x86_64") => Some("win64"),
        (FmiVersion::V3, "linux", "x86_64") => Some("x86_64-linux"),
        (FmiVersion::V3, "linux", "aarch64") => Some("aarch64-linux"),
        (FmiVersion::V3, "macos", "x86_64") => Some("x86_64-darwin"),
        (FmiVersion::V3, "macos", "aarch64") => Some("aarch64-darwin"),
        (FmiVersion::V3, "windows", "x86_64") => Some("x86_64-windows"),
        _ => None,
    }
}

/// An FMU library, loaded once per FMU and model identifier and shared by its instances.
pub(crate) struct Loaded {
    library: ffi::Library,
    /// An instance returned Fatal: the FMI standard allows no further call into any of them.
    poisoned: AtomicBool,
}

impl Loaded {
    fn is_poisoned(&self) -> bool {
        self.poisoned.load(Ordering::Relaxed)
    }
    fn poison(&self) {
        self.poisoned.store(true, Ordering::Relaxed);
    }
}

/// An opened FMU: its file, its SHA-256 (for the manifest), its description and the archive unpacked
/// into a temporary folder that lives as long as this value.
pub struct Fmu {
    pub path: PathBuf,
    pub sha256: String,
    pub description: Description,
    unpacked: tempfile::TempDir,
    /// Libraries by model identifier, loaded at their interface's first instance.
    libraries: Mutex<HashMap<String, Arc<Loaded>>>,
}

impl std::fmt::Debug for Fmu {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Fmu").field("path", &self.path).field("sha256", &self.sha256).finish_non_exhaustive()
    }
}

impl Fmu {
    /// Opens and checks `path`; every refusal names the file and says what is wrong.
    pub fn open(path: &Path) -> Result<Fmu, FmuError> {
        let shown = path.display();
        let bytes = std::fs::read(path).map_err(|e| FmuError::Invalid(format!("{shown}: cannot read the FMU: {e}")))?;
        let sha256 = Sha256::digest(&bytes).iter().map(|b| format!("{b:02x}")).collect();
        let mut zip = zip::ZipArchive::new(std::io::Cursor::new(&bytes[..]))
            .map_err(|e| FmuError::Invalid(format!("{shown}: not an FMU: an FMU is a zip archive ({e})")))?;
        let mut xml = String::new();
        zip.by_name("modelDescription.xml")
            .map_err(|_| {
                FmuError::Invalid(format!("{shown}: not an FMU: no modelDescription.xml at the archive's root"))
            })?
            .read_to_string(&mut xml)
            .map_err(|e| FmuError::Invalid(format!("{shown}: modelDescription.xml cannot be read: {e}")))?;
        let description = Description::parse(&xml).map_err(|e| FmuError::Invalid(format!("{shown}: {e}")))?;
        if description.model_exchange.is_none() && description.co_simulation.is_none() {
            return Err(FmuError::Invalid(format!(
                "{shown}: the FMU offers neither model exchange nor co-simulation (fdimc runs those two)"
            )));
        }
        let folder = platform_folder(description.version).ok_or_else(|| {
            FmuError::Invalid(format!(
                "{shown}: fdimc does not know FMI {}'s binary folder for {}/{}",
                description.version.label(),
                std::env::consts::OS,
                std::env::consts::ARCH
            ))
        })?;
        for info in description.model_exchange.iter().chain(&description.co_simulation) {
            let lib = format!("binaries/{folder}/{}{}", info.model_identifier, std::env::consts::DLL_SUFFIX);
            if zip.by_name(&lib).is_err() {
                let binaries: Vec<&str> = zip.file_names().filter(|n| n.starts_with("binaries/")).collect();
                let has = if binaries.is_empty() {
                    "it has no binaries (a source-only FMU must be compiled first, e.g. `fmpy compile`)".to_string()
                } else {
                    format!("it has {}", binaries.join(", "))
                };
                return Err(FmuError::Invalid(format!("{shown}: no binary for this platform: expected {lib}; {has}")));
            }
        }
        // Unpacked here: the binary and its resources live as long as this value.
        let unpacked = tempfile::Builder::new()
            .prefix("fdimc-fmu")
            .tempdir()
            .map_err(|e| FmuError::Invalid(format!("{shown}: cannot make a folder to unpack it into: {e}")))?;
        zip.extract(unpacked.path()).map_err(|e| FmuError::Invalid(format!("{shown}: cannot unpack: {e}")))?;
        Ok(Fmu { path: path.to_path_buf(), sha256, description, unpacked, libraries: Mutex::default() })
    }

    /// The library of `interface`, loaded at first use (a library that does not load, for a missing
    /// dependency say, is the deck's error and names what the loader said).
    fn library(&self, interface: Interface) -> Result<Arc<Loaded>, FmuError> {
        let d = &self.description;
        let info = d.interface(interface).ok_or_else(|| {
            FmuError::Invalid(format!("{}: the FMU has no {} interface", self.path.display(), interface.name()))
        })?;
        let mut libraries = self.libraries.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(loaded) = libraries.get(&info.model_identifier) {
            return Ok(Arc::clone(loaded));
        }
        let folder = platform_folder(d.version).expect("Fmu::open checked the platform");
        let file = self.unpacked.path().join("binaries").join(folder).join(format!(
            "{}{}",
            info.model_identifier,
            std::env::consts::DLL_SUFFIX
        ));
        let version = match d.version {
            FmiVersion::V2 => 2,
            FmiVersion::V3 => 3,
        };
        let library = ffi::Library::load(&file, version).map_err(|e| {
            // PythonFMU's exports leave the CPython API to the host: a host that is not Python must
            // load libpython first, as their README says.
            let hint = match e.to_string().contains("undefined symbol: _Py")
                || e.to_string().contains("undefined symbol: Py")
            {
                true => {
                    " (it calls into Python, as PythonFMU's exports do: run fdimc with that Python's shared \
                         library loaded first, LD_PRELOAD=/path/to/libpython3.X.so.1.0)"
                }
                false => "",
            };
            FmuError::Invalid(format!(
                "{}: its library for this platform does not load: {e}{hint}",
                self.path.display()
            ))
        })?;
        let loaded = Arc::new(Loaded { library, poisoned: AtomicBool::new(false) });
        libraries.insert(info.model_identifier.clone(), Arc::clone(&loaded));
        Ok(loaded)
    }

    /// The file's name (the manifest's record of it).
    pub fn file_name(&self) -> String {
        self.path.file_name().map_or_else(|| self.path.display().to_string(), |n| n.to_string_lossy().into_owned())
    }

    /// Whether fdimc can run `interface` of this FMU, and if not, why (a deck's error).
    pub fn supports(&self, interface: Interface) -> Result<(), FmuError> {
        let d = &self.description;
        let shown = self.path.display();
        let info = d.interface(interface).ok_or_else(|| {
            let offers: Vec<&str> = [Interface::ModelExchange, Interface::CoSimulation]
                .into_iter()
                .filter(|i| d.interface(*i).is_some())
                .map(Interface::name)
                .collect();
            FmuError::Invalid(format!(
                "{shown}: the FMU has no {} interface; it offers {}",
                interface.name(),
                offers.join(", ")
            ))
        })?;
        if info.needs_execution_tool {
            return Err(FmuError::Invalid(format!(
                "{shown}: the FMU needs its exporting tool to run (needsExecutionTool); fdimc runs self-contained FMUs"
            )));
        }
        Ok(())
    }

    /// A new instance of `interface` (the caller checked [`supports`](Self::supports)).
    pub fn instantiate(&self, interface: Interface, name: &str) -> Result<Instance, FmuError> {
        self.supports(interface)?;
        Instance::new(self, interface, name)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_missing_file_and_a_file_that_is_not_a_zip_are_refused_by_name() {
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("nope.fmu");
        let e = Fmu::open(&missing).unwrap_err().to_string();
        assert!(e.contains("nope.fmu: cannot read the FMU"), "{e}");
        let text = dir.path().join("text.fmu");
        std::fs::write(&text, "not a zip").unwrap();
        let e = Fmu::open(&text).unwrap_err().to_string();
        assert!(e.contains("text.fmu: not an FMU: an FMU is a zip archive"), "{e}");
    }
}
