//! # hils-fmu: the plant as an FMI 3.0 Co-Simulation FMU
//!
//! The same `hils-plant` (and, with `brake_input = brake_unit`, the closed loop of
//! `hils-sil` with the simulated brake unit) behind the FMI 3.0 C API, so Simulink, dSPACE
//! VEOS/SCALEXIO, OpenModelica or Python (FMPy) run the vehicle model of the board and of
//! `hils simulate`, bit for bit. `cargo fmu` builds `target/fmu/hils_plant.fmu`
//! (`src/main.rs`); `docs/fmu.md` is the user's guide.
//!
//! * [`variables`]: the variables, from the parameter file's key table and the run-log
//!   schema (no list of its own);
//! * [`description`]: `modelDescription.xml` and `resources/parameters.toml` from them;
//! * [`instance`]: one instance's state machine, parameters, inputs, steps and results, in
//!   safe Rust;
//! * [`abi`]: the C functions of `fmi3Functions.h` over it (pointers checked, panics
//!   caught, every refusal logged);
//! * [`units`]: the unit definitions.

pub mod abi;
pub mod description;
pub mod instance;
pub mod units;
pub mod variables;

use std::path::Path;

use hils_sil::ParamFile;

use crate::instance::Fault;

/// The parameter file in the FMU's `resources/` folder (its defaults).
pub const RESOURCE_FILE: &str = "parameters.toml";

/// Parses a parameter file's text as `hils` does (`tools/src/params_file.rs`): unknown
/// sections or keys, wrong types and values outside their range are errors naming the key.
pub fn parse_params(text: &str, origin: &str) -> Result<ParamFile, Fault> {
    let file: ParamFile = toml::from_str(text)
        .map_err(|e| Fault(format!("{origin}: invalid parameter file: {e}")))?;
    file.validate()
        .map_err(|e| Fault(format!("{origin}: {e}")))?;
    Ok(file)
}

/// Loads and checks a parameter file.
pub fn load_params(path: &Path) -> Result<ParamFile, Fault> {
    let text = std::fs::read_to_string(path).map_err(|e| {
        Fault(format!(
            "cannot read parameter file {}: {e}",
            path.display()
        ))
    })?;
    parse_params(&text, &path.display().to_string())
}
