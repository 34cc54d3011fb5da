//! The `--json FILE` and `--report DIR` outputs that several subcommands share: one flag
//! definition and one way of writing them (pretty JSON with a final newline; each written file
//! named on standard output).

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::Args;
use serde::Serialize;

/// `--json FILE` and `--report DIR` of a subcommand (its help says what each holds).
#[derive(Args, Debug, Clone, Default)]
pub struct Outputs {
    /// Write the results as JSON to this file (the subcommand's format: see its docs).
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Write a report (report.md with SVG plots) into this directory.
    #[arg(long)]
    pub report: Option<PathBuf>,
}

impl Outputs {
    /// Writes `value` to the `--json` file, if one was given.
    pub fn write_json(&self, value: &impl Serialize) -> Result<()> {
        if let Some(path) = &self.json {
            write_json_file(path, value)?;
            println!("wrote {}", path.display());
        }
        Ok(())
    }

    /// Calls `write` with the `--report` directory, if one was given, and names the files it
    /// wrote.
    pub fn write_report(&self, write: impl FnOnce(&Path) -> Result<Vec<PathBuf>>) -> Result<()> {
        if let Some(dir) = &self.report {
            for f in write(dir)? {
                println!("wrote {}", f.display());
            }
        }
        Ok(())
    }
}

/// Writes `value` as pretty JSON with a final newline.
pub fn write_json_file(path: &Path, value: &impl Serialize) -> Result<()> {
    std::fs::write(path, serde_json::to_string_pretty(value)? + "\n")
        .with_context(|| format!("cannot write {}", path.display()))
}
