//! The hardware interface of the real-time step (Tock/Hubris style: the logic sees traits,
//! the board implements them over its HAL, the host tests over mocks).
//!
//! Everything here is called from the step interrupt and must return at once: no waiting,
//! no allocation. Queues that feed lower-priority tasks (CAN transmission, defmt logging)
//! report "full" instead of blocking; the step counts what it had to drop.

use crate::controller_io::DrivenOutputs;
use crate::pulse::PulseRegisters;
use crate::sensor::ADC_SEQUENCE_LEN;
use crate::telemetry::{RunHeader, TelemetryRecord};
use crate::valves::ValveLevels;

/// What the step hands to the logging task.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TelemetryEvent {
    /// A run started: its `tlm1-start` header.
    Header(RunHeader),
    /// One telemetry record (`tlm1` line).
    Record(TelemetryRecord),
    /// The run ended at `step` in state `state` (a `RigState` code): the `tlm1-end` line.
    End {
        /// Plant steps of the run.
        step: u32,
        /// Final state (a `RigState` code).
        state: u8,
    },
}

impl TelemetryEvent {
    /// The record of a `Record` event.
    pub fn record(&self) -> Option<TelemetryRecord> {
        match self {
            TelemetryEvent::Record(r) => Some(*r),
            _ => None,
        }
    }

    /// Logs the event with defmt (in the logging task, not in the step).
    #[cfg(feature = "defmt")]
    pub fn log(&self) {
        match self {
            TelemetryEvent::Header(h) => h.log(),
            TelemetryEvent::Record(r) => r.log(),
            TelemetryEvent::End { step, state } => {
                defmt::println!("tlm1-end {=u32} {=u8}", *step, *state)
            }
        }
    }
}

/// The peripherals the step uses.
pub trait RigIo {
    /// The HAL's CAN frame type.
    type Frame: embedded_can::Frame;

    /// The ADC sequence converted since the last step (16 ranks: ch1..ch4 four times),
    /// or `None` if no new complete sequence arrived (trigger or DMA fault).
    fn adc_sequence(&mut self) -> Option<[u16; ADC_SEQUENCE_LEN]>;

    /// Sets the pulse output of a wheelset (0-3); takes effect at the next timer period.
    /// Called every step; the board writes it through [`crate::pulse::PulseChannel`], which
    /// dithers the period by the setting's `arr_frac`.
    fn set_pulse(&mut self, wheelset: usize, registers: &PulseRegisters);

    /// Queues a frame for transmission; `false` if the queue is full (the frame is lost).
    fn queue_frame(&mut self, frame: Self::Frame) -> bool;

    /// Queues a telemetry event for the logging task; `false` if the queue is full.
    fn queue_telemetry(&mut self, event: &TelemetryEvent) -> bool;

    /// The valve inputs' port as it reads now ([`crate::valves`]: GPIOC_IDR on the board).
    /// Default (an IO with no valve inputs): every pin high, no coil energised through the
    /// active-low stage.
    fn valve_levels(&mut self) -> ValveLevels {
        ValveLevels(u16::MAX)
    }

    /// Drives the EB loop relay, the service demand PWM and the air-spring DACs
    /// ([`crate::controller_io`]). Default (an IO without those lines): nothing.
    fn set_controller_outputs(&mut self, outputs: &DrivenOutputs) {
        let _ = outputs;
    }
}
