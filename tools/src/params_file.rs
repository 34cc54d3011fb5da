//! Loading a parameter file (`reference-parameters.toml` or a variant of it): the whole
//! file ([`hils_sil::ParamFile`]: the plant's sections, `[brake_unit]`, `[scenario]`).

use std::path::Path;

use anyhow::{Context, Result, anyhow};
use hils_sil::ParamFile;

/// Parses a parameter file's text. Unknown sections or keys, wrong types and values
/// outside their physical range are errors that name the key.
pub fn parse_params(text: &str, origin: &str) -> Result<ParamFile> {
    let file: ParamFile =
        toml::from_str(text).map_err(|e| anyhow!("{origin}: invalid parameter file: {e}"))?;
    file.validate().map_err(|e| anyhow!("{origin}: {e}"))?;
    Ok(file)
}

/// Loads and checks a parameter file.
pub fn load_params(path: &Path) -> Result<ParamFile> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read parameter file {}", path.display()))?;
    parse_params(&text, &path.display().to_string())
}

/// The parameters of `--params FILE`, or the built-in defaults (equal to the reference file).
pub fn params_or_default(path: Option<&Path>) -> Result<ParamFile> {
    match path {
        Some(p) => load_params(p),
        None => Ok(ParamFile::default()),
    }
}
