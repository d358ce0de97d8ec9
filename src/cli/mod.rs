//! Command line: clap definitions, one `exec` per subcommand, exit codes.
//!
//! Exit codes: 0 ok, 1 regression found, 2 invalid input (deck, arguments, files),
//! 3 I/O or internal error.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};

use crate::design::DesignError;
use crate::output::OutputError;
use crate::study::DeckError;

mod design;
mod simulate;
mod validate;

#[derive(Debug, Parser)]
#[command(
    name = "fdimc",
    version,
    about = "Monte Carlo robustness studies of fault detection and isolation in flight control",
    long_about = "Monte Carlo robustness studies of fault detection and isolation (FDI) in flight control.\n\n\
A study deck (TOML, see studies/) names a plant, sensor noise, faults and a detector. Start with\n\
`fdimc validate DECK` to see what the deck resolves to, `fdimc design DECK` for the detector's gains and\n\
closed-loop eigenvalues, and `fdimc simulate DECK --trial 0 --out trace.csv` for one trial's residuals.\n\n\
Exit codes: 0 ok, 1 regression found, 2 invalid input (deck, arguments, files), 3 I/O or internal error."
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Parse and validate a deck, design its detector, and print the resolved study.
    Validate {
        /// Study deck (TOML).
        deck: PathBuf,
    },
    /// Design the detector: gains, closed-loop eigenvalues, eigenvector conditioning, plant ranks.
    Design {
        /// Study deck (TOML).
        deck: PathBuf,
        /// Print JSON (for scripts) instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Simulate one trial and write its per-sample trace (time, inputs, measurements, estimates,
    /// residuals, alarms).
    Simulate {
        /// Study deck (TOML).
        deck: PathBuf,
        /// Trial index: selects the trial's random streams (same index, same noise).
        #[arg(long, default_value_t = 0)]
        trial: u64,
        /// Detector configuration to trace (default: the deck's first).
        #[arg(long)]
        detector: Option<String>,
        /// Trace file; the format follows the extension: .csv or .parquet.
        #[arg(long)]
        out: PathBuf,
    },
}

/// An error the CLI reports, with its exit code.
#[derive(Debug)]
pub enum CliError {
    /// Bad deck, arguments or input files: exit 2.
    Invalid(String),
    /// I/O or internal failure: exit 3.
    Internal(String),
}

impl From<DeckError> for CliError {
    fn from(e: DeckError) -> Self {
        CliError::Invalid(e.to_string())
    }
}

impl From<OutputError> for CliError {
    fn from(e: OutputError) -> Self {
        match e {
            OutputError::UnknownFormat { .. } => CliError::Invalid(e.to_string()),
            OutputError::Io { .. } | OutputError::Polars { .. } => CliError::Internal(e.to_string()),
        }
    }
}

/// A deck whose detector cannot be designed is invalid input.
fn design_error(deck: &std::path::Path, what: &str, e: DesignError) -> CliError {
    CliError::Invalid(format!("{}: detector: {what}: {e}", deck.display()))
}

pub fn run(cli: Cli) -> ExitCode {
    let result = match cli.command {
        Command::Validate { deck } => validate::exec(&deck),
        Command::Design { deck, json } => design::exec(&deck, json),
        Command::Simulate { deck, trial, detector, out } => simulate::exec(&deck, trial, detector.as_deref(), &out),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(CliError::Invalid(msg)) => {
            eprintln!("error: {msg}");
            ExitCode::from(2)
        }
        Err(CliError::Internal(msg)) => {
            eprintln!("error: {msg}");
            ExitCode::from(3)
        }
    }
}
