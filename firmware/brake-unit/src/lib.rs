//! # hils-brake-unit: a simulated brake unit for software-in-the-loop runs
//!
//! `no_std` and allocation-free, so the board can close the loop without the rig
//! (self-test mode). An EB command sets the cylinder pressure open-loop (load-weighing,
//! [`eb_pressure`]); the pressure reaches the cylinders after a pneumatic dead time with
//! first-order fill and vent lags; per-wheelset wheel slide protection ([`wsp`]) dumps,
//! holds, reapplies to a pressure memory and probes each cylinder in the style of EN 15595.
//! The unit owns its section of the parameter file, `[brake_unit]` ([`BrakeUnitParams`]);
//! the loop with the plant is `hils-sil`'s.
#![no_std]
#![forbid(unsafe_code)]

pub mod ep;
pub mod params;
pub mod unit;
pub mod wsp;

pub use unit::{
    BrakeDemand, BrakeUnit, BrakeUnitParams, MAX_PERIOD_S, UnitConfig, UnitError, UnitOutputs,
    demand_pressure, eb_pressure, service_pressure, service_step_deceleration,
};
pub use wsp::{Valve, WspTuning};
