//! # hils: host tools of the railway brake HILS
//!
//! Software-in-the-loop runs of the plant with the simulated brake unit
//! ([`scenario`], [`simulate`]), the run-log CSV format ([`runlog`]), plots ([`plots`]),
//! the host benchmark ([`bench`]), measured data ([`measured`]), friction fits
//! ([`fit_friction`]), the diagnosis ([`diagnose`]), the target cost ([`target_cost`]) and the telemetry decoder ([`decode`]).
// A host tool: `missing_docs` is for the no_std crates (the workspace lint).
#![allow(missing_docs)]

pub mod bench;
pub mod cli;
pub mod decode;
pub mod diagnose;
pub mod figures;
pub mod fit_friction;
pub mod flags;
pub mod mdf4;
pub mod measured;
pub mod outputs;
pub mod params_file;
pub mod plots;
pub mod rig;
pub mod runlog;
pub mod scenario;
pub mod simulate;
pub mod target_cost;
pub mod wsp;
