//! `hils diagnose` (being built; see its issue).

use anyhow::{Result, bail};
use clap::Args;

/// Arguments of `hils diagnose`.
#[derive(Args, Debug, Clone)]
pub struct DiagnoseArgs {}

pub fn main(_args: DiagnoseArgs) -> Result<()> {
    bail!("`hils diagnose` is not available yet")
}
