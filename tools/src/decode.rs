//! `hils decode` (being built; see its issue).

use anyhow::{Result, bail};
use clap::Args;

/// Arguments of `hils decode`.
#[derive(Args, Debug, Clone)]
pub struct DecodeArgs {}

pub fn main(_args: DecodeArgs) -> Result<()> {
    bail!("`hils decode` is not available yet")
}
