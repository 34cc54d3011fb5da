//! `hils-fmu-check`: the packed FMU checked and measured from outside (scripts/fmu-check.sh,
//! scripts/fmu-bench.sh).
//!
//! * `direct FMU`: a direct Rust import (dlopen): the paper's EB in closed loop (1 ms) and
//!   the plant driven by the run's pressures (0.1 ms) equal `hils simulate` bit for bit at
//!   every communication point; two instances with different parameter files side by side;
//!   bad use refused with logged messages.
//! * `rust-fmi FMU` (feature `rust-fmi`): the same paper checks through rust-fmi's importer.
//! * `reference DIR`: the paper run's inputs and outputs at every plant step, for FMPy
//!   (`reference.json` + `reference.f32`).
//! * `bench FMU`: plant steps per second through the FMU (one step per call and 100) and of
//!   the plant itself, on the paper's inputs.

mod bench;
mod checks;
#[cfg(feature = "rust-fmi")]
mod rust_fmi;

use std::path::PathBuf;

use anyhow::Result;
use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "hils-fmu-check",
    about = "Checks and measures the packed FMU from outside"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Direct Rust import (dlopen): bit identity, two instances, bad use.
    Direct { fmu: PathBuf },
    /// rust-fmi's importer (build with --features rust-fmi): bit identity.
    RustFmi { fmu: PathBuf },
    /// Writes the paper run's inputs and outputs at every plant step for FMPy.
    Reference { dir: PathBuf },
    /// Plant steps per second through the FMU and of the plant alone.
    Bench {
        fmu: PathBuf,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
        /// Repetitions (the best is reported).
        #[arg(long, default_value_t = 3)]
        repeat: usize,
    },
}

fn main() -> Result<()> {
    match Cli::parse().command {
        Command::Direct { fmu } => checks::direct(&fmu),
        Command::RustFmi { fmu } => rust_fmi(&fmu),
        Command::Reference { dir } => checks::reference(&dir),
        Command::Bench { fmu, json, repeat } => bench::run(&fmu, json, repeat),
    }
}

#[cfg(feature = "rust-fmi")]
fn rust_fmi(fmu: &std::path::Path) -> Result<()> {
    rust_fmi::check(fmu)
}

#[cfg(not(feature = "rust-fmi"))]
fn rust_fmi(_: &std::path::Path) -> Result<()> {
    anyhow::bail!(
        "built without rust-fmi's importer: cargo run --release -p hils-fmu-check --features rust-fmi -- rust-fmi FMU (needs libclang: apt-get install libclang-dev)"
    )
}
