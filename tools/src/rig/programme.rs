//! `hils rig run --programme FILE`: placeholder until step 6.

use anyhow::{Result, bail};
use clap::Args;
use std::path::PathBuf;

#[derive(Args, Debug, Clone)]
pub struct RunArgs {
    #[arg(long)]
    pub programme: PathBuf,
    #[arg(long)]
    pub json: Option<PathBuf>,
    #[arg(long)]
    pub report: Option<PathBuf>,
}

pub fn main(_: &super::RigArgs, _: &RunArgs) -> Result<()> {
    bail!("not built yet")
}
