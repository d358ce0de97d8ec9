//! FMUs (Functional Mock-up Units, FMI 2.0 and 3.0): a user's model or detector, as a building block any
//! kind can use where a model is needed.
//!
//! [`Fmu::open`] checks a `.fmu` file (a zip, its `modelDescription.xml`, a binary for this platform)
//! and loads it with the `fmi` crate (jondo2010/rust-fmi: the maintained Rust importer of FMI 2.0 and
//! 3.0, MIT/Apache-2.0); [`Description`] is what the description says, read by fdimc itself;
//! [`Instance`] steps one instance: co-simulation (FMI 2.0 and 3.0) through the FMU's own `doStep`,
//! model exchange (FMI 2.0) by fdimc's fixed-step [`integrator::Rk4`] with the FMU's time and state
//! events handled. Instances are not `Send`: each worker thread instantiates its own.

pub mod description;
pub mod identify;
pub mod instance;
pub mod integrator;
pub mod messages;
pub mod plant;
pub mod trim;

use std::io::Read;
use std::path::{Path, PathBuf};

use fmi::traits::FmiImport;
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

enum Import {
    V2(fmi::fmi2::import::Fmi2Import),
    V3(fmi::fmi3::import::Fmi3Import),
}

/// An opened FMU: its file, its SHA-256 (for the manifest), its description and the loaded archive
/// (unpacked into a temporary folder that lives as long as this value).
pub struct Fmu {
    pub path: PathBuf,
    pub sha256: String,
    pub description: Description,
    import: Import,
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
        messages::install();
        // Unpacked here (the binary and its resources live as long as the import), then handed to the
        // fmi crate with the description it needs to load the binary (Description::for_loader).
        let dir = tempfile::Builder::new()
            .prefix("fdimc-fmu")
            .tempdir()
            .map_err(|e| FmuError::Invalid(format!("{shown}: cannot make a folder to unpack it into: {e}")))?;
        zip.extract(dir.path()).map_err(|e| FmuError::Invalid(format!("{shown}: cannot unpack: {e}")))?;
        let loaded = |e: fmi::Error| FmuError::Invalid(format!("{shown}: the fmi crate cannot load this FMU: {e}"));
        let xml = description.for_loader();
        let import = match description.version {
            FmiVersion::V2 => Import::V2(FmiImport::new(dir, &xml).map_err(loaded)?),
            FmiVersion::V3 => Import::V3(FmiImport::new(dir, &xml).map_err(loaded)?),
        };
        Ok(Fmu { path: path.to_path_buf(), sha256, description, import })
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
        if interface == Interface::ModelExchange && d.version == FmiVersion::V3 {
            return Err(FmuError::Invalid(format!(
                "{shown}: FMI 3.0 model exchange is not supported (the fmi crate lacks its state and derivative \
                 calls fdimc needs); use the FMU's co-simulation interface or an FMI 2.0 export"
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
