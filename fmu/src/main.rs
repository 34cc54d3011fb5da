//! `cargo fmu`: packs `target/fmu/hils_plant.fmu` from the shared library cargo built beside
//! this program (the same build: `cargo run --release -p hils-fmu`), the model description
//! and the parameter resource written from the code's tables.
#![allow(missing_docs)]

use std::io::{Read, Write};
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::Parser;
use hils_fmu::RESOURCE_FILE;
use hils_fmu::description::{MODEL_IDENTIFIER, model_description, parameter_file};
use zip::write::SimpleFileOptions;

/// Packs the plant as an FMI 3.0 Co-Simulation FMU.
#[derive(Parser, Debug)]
#[command(name = "cargo fmu")]
struct Args {
    /// Parameter file whose values become the FMU's defaults (start values and
    /// resources/parameters.toml); default: the built-in values (equal to
    /// spec/reference-parameters.toml).
    #[arg(long)]
    params: Option<PathBuf>,
    /// The FMU to write; default: target/fmu/hils_plant.fmu.
    #[arg(long)]
    out: Option<PathBuf>,
    /// An FMU of this version built on another platform: its binaries/ are added (its
    /// modelDescription.xml must be the same).
    #[arg(long)]
    merge: Vec<PathBuf>,
}

/// The FMI platform folder and library extension of this build.
fn platform() -> Result<(&'static str, &'static str)> {
    let arch = match std::env::consts::ARCH {
        "x86_64" => "x86_64",
        "aarch64" => "aarch64",
        "x86" => "x86",
        other => bail!("no FMI platform name for the architecture {other}"),
    };
    let (os, ext) = match std::env::consts::OS {
        "linux" => ("linux", "so"),
        "windows" => ("windows", "dll"),
        "macos" => ("darwin", "dylib"),
        other => bail!("no FMI platform name for the operating system {other}"),
    };
    Ok((Box::leak(format!("{arch}-{os}").into_boxed_str()), ext))
}

/// Builds the shared library (release, as this program) and returns its path: cargo's
/// own report of the artifact, so the target folder and platform name need no guess.
fn build_library() -> Result<PathBuf> {
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let output = std::process::Command::new(cargo)
        .args(["build", "--release", "-p", "hils-fmu", "--lib"])
        .arg("--message-format=json-render-diagnostics")
        .stderr(std::process::Stdio::inherit())
        .output()
        .context("cannot run cargo to build the FMU's library")?;
    if !output.status.success() {
        bail!("cargo build --release -p hils-fmu --lib failed");
    }
    for line in String::from_utf8_lossy(&output.stdout).lines() {
        let Ok(message) = serde_json::from_str::<serde_json::Value>(line) else {
            continue;
        };
        let is_cdylib = message["target"]["crate_types"]
            .as_array()
            .is_some_and(|t| t.iter().any(|t| t == "cdylib"));
        if message["reason"] == "compiler-artifact" && is_cdylib {
            let library = message["filenames"]
                .as_array()
                .into_iter()
                .flatten()
                .filter_map(|f| f.as_str())
                .find(|f| [".so", ".dll", ".dylib"].iter().any(|e| f.ends_with(e)));
            if let Some(library) = library {
                return Ok(PathBuf::from(library));
            }
        }
    }
    bail!("cargo built no shared library of hils-fmu")
}

fn main() -> Result<()> {
    let args = Args::parse();
    let (platform, ext) = platform()?;
    let lib = build_library()?;
    let (defaults, origin) = match &args.params {
        Some(p) => (
            hils_fmu::load_params(p).map_err(|e| anyhow::anyhow!(e.0))?,
            p.display().to_string(),
        ),
        None => (
            hils_sil::ParamFile::default(),
            "the built-in defaults (equal to spec/reference-parameters.toml)".to_string(),
        ),
    };
    let description = model_description(&defaults)?;
    let resource = parameter_file(&defaults, &origin);
    let out = match args.out {
        Some(o) => o,
        None => {
            // <target>/release/hils-fmu -> <target>/fmu/hils_plant.fmu
            let target = lib
                .parent()
                .and_then(Path::parent)
                .context("cannot find the target folder")?;
            target.join("fmu").join(format!("{MODEL_IDENTIFIER}.fmu"))
        }
    };
    let mut entries: Vec<(String, Vec<u8>)> = vec![
        (
            "modelDescription.xml".into(),
            description.clone().into_bytes(),
        ),
        (
            format!("binaries/{platform}/{MODEL_IDENTIFIER}.{ext}"),
            std::fs::read(&lib).with_context(|| format!("cannot read {}", lib.display()))?,
        ),
        (format!("resources/{RESOURCE_FILE}"), resource.into_bytes()),
    ];
    for other in &args.merge {
        merge_binaries(other, &description, &mut entries)?;
    }
    write_fmu(&out, &entries)?;
    let platforms: Vec<&str> = entries
        .iter()
        .filter_map(|(n, _)| n.strip_prefix("binaries/"))
        .collect();
    println!(
        "{}: FMI 3.0 Co-Simulation, {} variables, binaries {}",
        out.display(),
        hils_fmu::variables::VARIABLES.len(),
        platforms.join(", ")
    );
    Ok(())
}

/// Adds the `binaries/` of another FMU of the same model description.
fn merge_binaries(
    other: &Path,
    description: &str,
    entries: &mut Vec<(String, Vec<u8>)>,
) -> Result<()> {
    let file =
        std::fs::File::open(other).with_context(|| format!("cannot open {}", other.display()))?;
    let mut zip = zip::ZipArchive::new(file)
        .with_context(|| format!("{} is not an FMU (zip)", other.display()))?;
    let mut theirs = String::new();
    zip.by_name("modelDescription.xml")
        .with_context(|| format!("{} has no modelDescription.xml", other.display()))?
        .read_to_string(&mut theirs)?;
    if theirs != description {
        bail!(
            "{}: its modelDescription.xml differs from this build's (another version or other defaults): not merged",
            other.display()
        );
    }
    for i in 0..zip.len() {
        let mut entry = zip.by_index(i)?;
        let name = entry.name()?.to_string();
        if !name.starts_with("binaries/")
            || entry.is_dir()
            || entries.iter().any(|(n, _)| *n == name)
        {
            continue;
        }
        let mut bytes = Vec::new();
        entry.read_to_end(&mut bytes)?;
        entries.push((name, bytes));
    }
    Ok(())
}

/// Writes the archive beside its destination and renames it into place (no half-written
/// FMU).
fn write_fmu(out: &Path, entries: &[(String, Vec<u8>)]) -> Result<()> {
    if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    }
    let tmp = out.with_extension("fmu.part");
    let file =
        std::fs::File::create(&tmp).with_context(|| format!("cannot create {}", tmp.display()))?;
    let mut zip = zip::ZipWriter::new(file);
    let options = SimpleFileOptions::default().compression_method(zip::CompressionMethod::Deflated);
    for (name, bytes) in entries {
        zip.start_file(name.as_str(), options)?;
        zip.write_all(bytes)?;
    }
    zip.finish()?;
    std::fs::rename(&tmp, out).with_context(|| format!("cannot write {}", out.display()))?;
    Ok(())
}
