//! `hils target-cost` (being built; see its issue).

use anyhow::{Result, bail};
use clap::Args;

/// Arguments of `hils target-cost`.
#[derive(Args, Debug, Clone)]
pub struct TargetCostArgs {}

pub fn main(_args: TargetCostArgs) -> Result<()> {
    bail!("`hils target-cost` is not available yet")
}
