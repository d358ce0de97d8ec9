//! Compiles `src/fmu/logger.c`, FMI 2.0's C-variadic logger callback (stable Rust cannot define one):
//! the only C in fdimc's build, and all a fresh machine needs beyond Rust is a C compiler. Also records
//! the git commit `fdimc verify` reports.

fn main() {
    println!("cargo::rerun-if-changed=src/fmu/logger.c");
    // The commit `fdimc verify` names: git's HEAD where the build has one, else "unknown" (a source
    // archive). Read again when HEAD moves; changes not committed are not told apart.
    println!("cargo::rerun-if-changed=.git/HEAD");
    println!("cargo::rerun-if-changed=.git/refs/heads");
    let commit = std::process::Command::new("git")
        .args(["rev-parse", "--short=12", "HEAD"])
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
        .unwrap_or_else(|| "unknown".to_string());
    println!("cargo::rustc-env=FDIMC_COMMIT={commit}");
    cc::Build::new().file("src/fmu/logger.c").warnings(true).extra_warnings(true).compile("fdimc_fmu_logger");
}
