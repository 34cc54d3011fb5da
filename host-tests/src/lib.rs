//! Shared helpers of the host integration tests (`tests/`).
// Test support, not an interface: no docs required.
#![allow(missing_docs)]

use std::path::PathBuf;

/// The shared, read-only project material (`../shared` beside the checkout), or
/// `$HILS_SHARED_DIR`.
pub fn shared_dir() -> PathBuf {
    if let Some(dir) = std::env::var_os("HILS_SHARED_DIR") {
        return PathBuf::from(dir);
    }
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared")
}

/// `spec/reference-parameters.toml` of the shared material.
pub fn reference_parameters_path() -> PathBuf {
    shared_dir().join("spec/reference-parameters.toml")
}

pub mod generator;
