//! # hils-sil: the plant in a closed loop, and what every run shares
//!
//! `no_std` and allocation-free, below the rig board, the emulated target and the host
//! tools (`plant` -> `brake-unit` -> `sil` -> `rig-core` / `qemu` / `hils`), so that each of
//! these exists once:
//!
//! * [`closed_loop`]: the plant with the simulated brake unit (`hils simulate`, the emulated
//!   target, the board's self-test mode);
//! * [`scenario`]: the paper's emergency brake and the stop rule every run ends by;
//! * [`record`]: the run record and the run-log schema (column names, units, order) that
//!   every writer and the reader use;
//! * [`trace`]: the emulated target's trace rows (f32 bit patterns) and cost-line names;
//! * [`params`]: the whole parameter file, one section per crate that uses it.
#![no_std]
#![forbid(unsafe_code)]

pub mod closed_loop;
pub mod params;
pub mod record;
pub mod scenario;
pub mod trace;

pub use closed_loop::{ClosedLoop, LoopError};
pub use params::{PaperEbScenario, ParamFile, ScenarioParams};
pub use record::{Cmd, RunRecord};
pub use scenario::{EbScenario, StopRule};
pub use trace::TraceRow;

/// km/h per m/s (the one conversion factor; the board uses it as f32).
pub const KMH_PER_MPS: f64 = 3.6;
