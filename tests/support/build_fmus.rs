//! Builds the test FMUs of `fmus/` (C sources, see fmus/README.md) into real `.fmu` archives, the way
//! an exporting tool does: compile the model with the FMI functions into a shared library, then zip it
//! with its modelDescription.xml. Used by the tests and by `cargo run --example build_fmus`.
//! Linux x86_64 (the binary folders below); needs a C compiler (`cc`, or `$CC`).

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::Command;

/// One FMU to build: the model folder under `fmus/`, its description file, the archive's name, FMI major version.
pub const FMUS: &[(&str, &str, &str, u8)] = &[
    ("aircraft", "FMI2.xml", "aircraft", 2),
    ("aircraft", "FMI2_cs.xml", "aircraft_cs", 2),
    ("aircraft", "FMI3.xml", "aircraft_fmi3", 3),
    ("pitch_controller", "FMI2.xml", "pitch_controller", 2),
    ("ewma_detector", "FMI2.xml", "ewma_detector", 2),
    ("aircraft_actuated", "FMI2.xml", "aircraft_actuated", 2),
];

/// Builds every FMU of [`FMUS`] from the sources under `root/fmus` into `out/<name>.fmu`.
pub fn build_all(root: &Path, out: &Path) -> Result<Vec<PathBuf>, String> {
    std::fs::create_dir_all(out).map_err(|e| format!("{}: {e}", out.display()))?;
    FMUS.iter().map(|&(model, xml, name, version)| build(root, out, model, xml, name, version)).collect()
}

fn build(root: &Path, out: &Path, model: &str, xml: &str, name: &str, version: u8) -> Result<PathBuf, String> {
    let src = root.join("fmus");
    let folder = if version == 2 { "linux64" } else { "x86_64-linux" };
    // Per process and per call: test binaries, and tests in one binary's threads, may build into the
    // same folder at once (two threads sharing a stage removed each other's library); the final rename
    // is atomic.
    static CALLS: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let call = CALLS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let unique = format!("{}.{call}", std::process::id());
    let stage = out.join(format!(".{name}.build.{unique}"));
    std::fs::create_dir_all(&stage).map_err(|e| format!("{}: {e}", stage.display()))?;
    let lib = stage.join(format!("{model}.so"));
    let cc = std::env::var("CC").unwrap_or_else(|_| "cc".into());
    // -O2 and nothing that changes floating point (no -march, no -ffast-math): the tests compare the
    // FMU's arithmetic with the same equations in Rust to the bit.
    let status = Command::new(&cc)
        .args(["-shared", "-fPIC", "-O2", "-ffp-contract=off", "-DDISABLE_PREFIX"])
        .arg(format!("-DFMI_VERSION={version}"))
        .arg("-I")
        .arg(src.join("include"))
        .arg("-I")
        .arg(src.join(model))
        .arg(src.join(model).join("model.c"))
        .arg(src.join("src").join(format!("fmi{version}Functions.c")))
        .arg(src.join("src").join("cosimulation.c"))
        .arg("-o")
        .arg(&lib)
        .arg("-lm")
        .status()
        .map_err(|e| format!("cannot run the C compiler {cc:?}: {e}"))?;
    if !status.success() {
        return Err(format!("{cc} failed to compile fmus/{model} (FMI {version})"));
    }
    let fmu = out.join(format!("{name}.fmu"));
    let tmp = out.join(format!(".{name}.fmu.tmp.{unique}"));
    let mut zip = zip::ZipWriter::new(std::fs::File::create(&tmp).map_err(|e| format!("{}: {e}", tmp.display()))?);
    let options = zip::write::SimpleFileOptions::default();
    let mut add = |path: String, bytes: Vec<u8>| -> Result<(), String> {
        zip.start_file(path, options).map_err(|e| e.to_string())?;
        zip.write_all(&bytes).map_err(|e| e.to_string())
    };
    add("modelDescription.xml".into(), std::fs::read(src.join(model).join(xml)).map_err(|e| format!("{xml}: {e}"))?)?;
    add(format!("binaries/{folder}/{model}.so"), std::fs::read(&lib).map_err(|e| e.to_string())?)?;
    zip.finish().map_err(|e| e.to_string())?;
    std::fs::rename(&tmp, &fmu).map_err(|e| e.to_string())?;
    std::fs::remove_dir_all(&stage).map_err(|e| e.to_string())?;
    Ok(fmu)
}
