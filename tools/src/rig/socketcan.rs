//! SocketCAN transport: placeholder until step 5.

use anyhow::{Result, bail};

use super::transport::Transport;

pub fn open(interface: &str) -> Result<Box<dyn Transport>> {
    bail!("{interface}: SocketCAN transport not built yet")
}
