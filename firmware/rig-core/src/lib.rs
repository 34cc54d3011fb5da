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
//! * [`adc_watch`]: the ADC ring's stall (no progress, overrun) and its aligned restart.
//! * [`arming`]: the arming gate: whether the outputs a real controller reads are live.
//! * [`can`]: the CAN frame codec over [`embedded_can::Frame`] (wheel speeds, status,
//!   diagnostics out; commands in), described by `hils.dbc` beside this crate.
//! * [`sensor`]: ADC oversampling, offset/gain calibration, scaling to clamp force or
//!   cylinder pressure, and plausibility (open, short, out of range, stuck).
//! * [`pulse`]: pulse-train timer settings, f = teeth omega / 2 pi, dithered periods.
//! * [`timer_model`]: a counting model of a pulse timer (host tests, the simulated rig).
//! * [`timing`]: step accounting from the DWT cycle counter (max, mean, overruns, missed ticks).
//! * [`bus`]: CAN bus state supervision (error passive, bus-off, recovery).
//! * [`can_timing`]: nominal CAN bit timing from the kernel clock and its oscillator tolerance.
//! * [`fdcan`]: FDCAN register sequences: bus-off restart with the TX FIFO flushed, NBTP
//!   checked before joining the bus, Rx FIFO elements.
//! * [`can_tx`]: transmit freshness (stale frames dropped and counted, not sent late).
//! * [`log_gate`]: counting the telemetry the RTT channel could not take.
//! * [`reset_loop`]: fault resets in a row, kept across resets, and the hold after three.
//! * [`stack`]: the painted stack's high-water mark and telling an overflow HardFault.
//! * [`handoff`]: the slot protocol that hands a value built in thread mode to the step.
//! * [`heartbeat`]: whether thread mode is alive (the watchdog is fed only then).
//! * [`bringup`]: pass/fail rules of the board's bring-up self-test.
//! * [`telemetry`]: the decimated telemetry record, its defmt line and its parser.
//! * [`setup`]: the track and vehicle a run is set up with, as the board keeps them.
//! * [`digest`]: the CRC-16 setup digest a `Start` carries.
//! * [`valves`]: the controller's WSP dump and hold valve inputs, debounced.
//! * [`demand`]: the brake demand to the controller: emergency brake loop, service PWM.
//! * [`load`]: the air-spring pressure (load-weighing) signals on the DACs.
//! * [`controller_io`]: the controller I/O's configuration and what the step drives.
//! * [`rig`]: the real-time step and the run state machine (commands, faults, safe state).
//! * [`hw`]: the hardware-interface traits the board implements.
//! * [`script`]: a scripted self-test run shared by the QEMU telemetry fixture and its host check.
#![no_std]
#![forbid(unsafe_code)]

#[cfg(test)]
extern crate std;

pub mod adc_watch;
pub mod arming;
pub mod bringup;
pub mod bus;
pub mod can;
pub mod can_timing;
pub mod can_tx;
pub mod controller_io;
pub mod demand;
pub mod digest;
pub mod fdcan;
pub mod handoff;
pub mod heartbeat;
pub mod hw;
pub mod load;
pub mod log_gate;
pub mod pulse;
pub mod reset_loop;
pub mod rig;
pub mod script;
pub mod sensor;
pub mod setup;
pub mod stack;
pub mod telemetry;
pub mod timer_model;
pub mod timing;
pub mod valves;

pub use hils_plant::WHEELSETS;

/// The codes of the enums sent in frames and telemetry (`RigState`, `RigMode`,
/// `CommandResult`, `SensorFault`, `InjectedFault`): their `u8` conversions are derived
/// (`num_enum`); this adds the two forms the wire uses, for every such enum at once.
pub trait Code: Sized + Into<u8> + TryFrom<u8> {
    /// The value of a raw code; `None` for an undefined one.
    fn from_raw(raw: u8) -> Option<Self> {
        Self::try_from(raw).ok()
    }

    /// The code of an optional value, 0 = none.
    fn code(value: Option<Self>) -> u8 {
        value.map_or(0, Into::into)
    }

    /// Inverse of [`Code::code`]: `Some(None)` for 0, `Some(Some(v))` for a defined code,
    /// `None` for an undefined one.
    fn from_code(code: u8) -> Option<Option<Self>> {
        if code == 0 {
            Some(None)
        } else {
            Self::from_raw(code).map(Some)
        }
    }
}

impl<T: Into<u8> + TryFrom<u8>> Code for T {}

/// Number of analog brake-input channels (one per wheelset).
pub const CHANNELS: usize = 4;

/// Plant step rate of the real-time loop, Hz (0.1 ms step, paper text).
pub const STEP_RATE_HZ: u32 = 10_000;

/// km/h per m/s as f32 (the one factor, [`hils_sil::KMH_PER_MPS`]).
pub const KMH_PER_MPS: f32 = hils_sil::KMH_PER_MPS as f32;
