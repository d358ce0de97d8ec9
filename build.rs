//! Compiles `src/fmu/logger.c`, FMI 2.0's C-variadic logger callback (stable Rust cannot define one):
//! the only C in fdimc's build, and all a fresh machine needs beyond Rust is a C compiler.

fn main() {
    println!("cargo::rerun-if-changed=src/fmu/logger.c");
    cc::Build::new().file("src/fmu/logger.c").warnings(true).extra_warnings(true).compile("fdimc_fmu_logger");
}
