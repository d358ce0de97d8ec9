use clap::Parser;

fn main() -> std::process::ExitCode {
    fdimc::cli::run(fdimc::cli::Cli::parse())
}
