//! Stage 1: build the emulator binary (`cargo qemu` with the host's math).

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use anyhow::{Context, Result, bail};

/// The workspace root (the emulator crate is `firmware/qemu` below it).
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// Cargo features of the emulator that select the math implementation this program was
/// built with, so that host and target compute with the same functions.
pub fn emulator_features() -> &'static [&'static str] {
    match hils_plant::math::IMPLEMENTATION {
        "micromath" => &["--features", "math-micromath"],
        "libm" => &["--features", "math-libm"],
        _ => &[],
    }
}

/// Builds the emulator binary (profile `firmware`, as the board image; thumbv7em-none-eabihf, the host's math) with
/// cargo and returns the ELF's path (as cargo reports it).
pub fn build_elf() -> Result<PathBuf> {
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let output = Command::new(&cargo)
        .current_dir(workspace_root())
        .args([
            "build",
            "--profile",
            "firmware",
            "-p",
            "hils-qemu",
            "--target",
            "thumbv7em-none-eabihf",
        ])
        .args(emulator_features())
        .args(["--message-format", "json-render-diagnostics"])
        .stderr(Stdio::inherit())
        .output()
        .with_context(|| format!("cannot run {}", Path::new(&cargo).display()))?;
    if !output.status.success() {
        bail!(
            "building the emulator binary failed ({}); it needs the thumbv7em-none-eabihf \
             target: `rustup target add thumbv7em-none-eabihf`",
            output.status
        );
    }
    let stdout = String::from_utf8_lossy(&output.stdout);
    for line in stdout.lines() {
        let Ok(msg) = serde_json::from_str::<serde_json::Value>(line) else {
            continue;
        };
        if msg["reason"] == "compiler-artifact"
            && msg["target"]["name"] == "hils-qemu"
            && let Some(exe) = msg["executable"].as_str()
        {
            return Ok(PathBuf::from(exe));
        }
    }
    bail!("cargo built no hils-qemu executable")
}
