//! Builds the test FMUs from their C sources in `fmus/` into `studies/fmus/` (or the folder given):
//! the nonlinear aircraft (FMI 2.0 model exchange + co-simulation, FMI 2.0 co-simulation only, FMI 3.0),
//! the pitch controller and the EWMA detector. The bundled FMU decks fly these.
//!
//! ```sh
//! cargo run --release --example build_fmus            # -> studies/fmus/*.fmu
//! cargo run --release --example build_fmus -- DIR
//! ```

#[path = "../tests/support/build_fmus.rs"]
mod build_fmus;

fn main() -> std::process::ExitCode {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let out = std::env::args().nth(1).map_or_else(|| root.join("studies").join("fmus"), Into::into);
    match build_fmus::build_all(root, &out) {
        Ok(files) => {
            for f in files {
                println!("{}", f.display());
            }
            std::process::ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("error: {e}");
            std::process::ExitCode::from(2)
        }
    }
}
