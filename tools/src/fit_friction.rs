//! `hils fit-friction` (being built; see its issue).

use anyhow::{Result, bail};
use clap::Args;

/// Arguments of `hils fit-friction`.
#[derive(Args, Debug, Clone)]
pub struct FitFrictionArgs {}

pub fn main(_args: FitFrictionArgs) -> Result<()> {
    bail!("`hils fit-friction` is not available yet")
}
