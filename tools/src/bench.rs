//! `hils bench`: host steps per second of the full plant.

use anyhow::Result;
use clap::Args;

#[derive(Args, Debug, Clone)]
pub struct BenchArgs {
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
}

pub fn main(_args: BenchArgs) -> Result<()> {
    anyhow::bail!("not yet")
}
