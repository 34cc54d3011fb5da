//! Stage 1: build the emulator binary (`cargo qemu` with the host's math).

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use anyhow::{Context, Result, anyhow, bail};

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

/// The optimisation level of the board image, as cargo's `OPT_LEVEL` spells it ("2", "s"):
/// `[profile.firmware.package.board] opt-level` of the workspace's Cargo.toml, else the
/// firmware profile's, else the release profile's (which it inherits).
pub fn board_opt_level() -> Result<String> {
    let path = workspace_root().join("Cargo.toml");
    let text = std::fs::read_to_string(&path)
        .with_context(|| format!("cannot read {}", path.display()))?;
    let doc: toml::Table =
        toml::from_str(&text).with_context(|| format!("cannot parse {}", path.display()))?;
    let profile = |name: &str| doc.get("profile").and_then(|p| p.get(name));
    let firmware = profile("firmware");
    let level = firmware
        .and_then(|r| r.get("package"))
        .and_then(|p| p.get("board"))
        .and_then(|b| b.get("opt-level"))
        .or_else(|| firmware.and_then(|r| r.get("opt-level")))
        .or_else(|| profile("release").and_then(|r| r.get("opt-level")))
        .ok_or_else(|| anyhow!("{}: no opt-level for the board image", path.display()))?;
    Ok(match level {
        toml::Value::String(s) => s.clone(),
        other => other.to_string(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The emulator image that `hils target-cost` measures is built at the board image's
    /// level (Cargo.toml sets both; the figures would not be the board's otherwise).
    #[test]
    fn the_emulator_is_built_at_the_board_images_opt_level() {
        let text = std::fs::read_to_string(workspace_root().join("Cargo.toml")).unwrap();
        let doc: toml::Table = toml::from_str(&text).unwrap();
        let emulator = &doc["profile"]["firmware"]["package"]["hils-qemu"]["opt-level"];
        let emulator = match emulator {
            toml::Value::String(s) => s.clone(),
            other => other.to_string(),
        };
        assert_eq!(emulator, board_opt_level().unwrap());
    }
}
