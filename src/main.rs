use clap::Parser;

fn main() -> std::process::ExitCode {
    // A reader that stops early (`fdimc design deck | head`) ends fdimc quietly, as it does any Unix
    // tool, instead of a panic on the broken pipe. Results are written by rename, so nothing is left
    // half-written.
    #[cfg(unix)]
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    fdimc::cli::run(fdimc::cli::Cli::parse())
}
