fn main() -> std::process::ExitCode {
    fdimc::cli::main_with(&[])
}
