//! # hils-rig-core: the board-independent logic of the rig interface board
//!
//! The rig interface board (NUCLEO-G474RE, `firmware/board`) runs the plant of the HILS at
//! 10 kHz against a real brake controller: it reads the brake inputs (caliper load cells or
//! cylinder pressure transducers), steps `hils_plant::Plant<f32>`, and sends the wheel speeds
//! back by CAN and as axle-speed-sensor pulse trains. Everything here is `no_std`,
//! allocation-free and panic-free on any input, and is tested on the host; the board binary
//! is a thin HAL shell that moves bytes between these types and the peripherals.
//!
//! Modules, one concern each:
//! * [`can`]: the CAN frame codec over [`embedded_can::Frame`] (wheel speeds, status,
//!   diagnostics out; commands in), described by `hils.dbc` beside this crate.
//! * [`sensor`]: ADC oversampling, offset/gain calibration, scaling to clamp force or
//!   cylinder pressure, and plausibility (open, short, out of range, stuck).
//! * [`pulse`]: pulse-train timer settings, f = teeth omega / 2 pi.
//! * [`timing`]: step accounting from the DWT cycle counter (max, mean, overruns, missed ticks).
//! * [`bus`]: CAN bus state supervision (error passive, bus-off, recovery).
//! * [`telemetry`]: the decimated telemetry record, its defmt line and its parser.
//! * [`rig`]: the real-time step and the run state machine (commands, faults, safe state).
//! * [`hw`]: the hardware-interface traits the board implements.
//! * [`script`]: a scripted self-test run shared by the QEMU telemetry fixture and its host check.
#![no_std]
#![forbid(unsafe_code)]

#[cfg(test)]
extern crate std;

pub mod bus;
pub mod can;
pub mod hw;
pub mod pulse;
pub mod rig;
pub mod script;
pub mod sensor;
pub mod telemetry;
pub mod timing;

pub use hils_plant::WHEELSETS;

/// Number of analog brake-input channels (one per wheelset).
pub const CHANNELS: usize = 4;

/// Plant step rate of the real-time loop, Hz (0.1 ms step, paper text).
pub const STEP_RATE_HZ: u32 = 10_000;

/// km/h per m/s.
pub const KMH_PER_MPS: f32 = 3.6;
