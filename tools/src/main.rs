//! `hils`: host tools of the railway brake HILS. See README.md.

use clap::Parser;

fn main() -> anyhow::Result<()> {
    hils::cli::run(hils::cli::Cli::parse())
}
