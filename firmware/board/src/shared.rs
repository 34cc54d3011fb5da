//! The statics the step (TIM3 interrupt) and the tasks share: ceiling-locked queues, the
//! handoff of built runs, atomics, and what the step has to say. Here, below both, so that
//! neither the step (`crate::step`) nor the tasks (`crate::can_io`, `crate::telemetry`,
//! `crate::app`) reach into each other's module for them.

use core::sync::atomic::{AtomicBool, AtomicU8, AtomicU32};

use embassy_stm32::can::Frame;
use hils_rig_core::can::Command;
use hils_rig_core::can_tx::QueuedFrame;
use hils_rig_core::hw::TelemetryEvent;
use hils_rig_core::rig::CommandError;
use hils_rig_core::rig::{Built, StartRequest};

use crate::ceiling::StepChannel;
use crate::handoff::Handoff;

/// Frames from the step to the CAN transmit task, with the tick they were made at.
pub static CAN_TX: StepChannel<QueuedFrame<Frame>, 32> = StepChannel::new();
/// `RIG_COMMAND` frames received, for the step.
pub static CAN_RX: StepChannel<Frame, 8> = StepChannel::new();
/// Local commands (user button, autostart), for the step.
pub static LOCAL_CMD: StepChannel<Command, 2> = StepChannel::new();
/// Runs the step requested, for the builder task (thread mode).
pub static START_REQUESTS: StepChannel<StartRequest, 1> = StepChannel::new();
/// The builder's word that it built a run in the rig's store (`crate::sim_store`), or why
/// not: a few bytes, the simulation itself is not moved.
pub static BUILT: Handoff<Built<()>, 1> = Handoff::new();
/// Telemetry events from the step to the logging task.
pub static TELEMETRY: StepChannel<TelemetryEvent, 16> = StepChannel::new();
/// What the step has to say, for a task to log (the step never logs).
pub static STEP_EVENTS: StepChannel<StepEvent, 8> = StepChannel::new();

/// Step ticks since the step started (0.1 ms, wrapping); written by the step only.
pub static STEP_TICKS: AtomicU32 = AtomicU32::new(0);
/// Bus state for the step: bit 0 error passive, bit 1 bus-off (now or seen); bits 8.. count.
pub static BUS_STATE: AtomicU32 = AtomicU32::new(0);
/// Rig state for the LED task.
pub static RIG_STATE: AtomicU8 = AtomicU8::new(0);
/// Frames dropped after they left the step's queue (stale, or cancelled in the controller).
pub static CAN_TX_DROPS: AtomicU32 = AtomicU32::new(0);
/// Telemetry events the RTT channel could not take.
pub static TELEMETRY_DROPS: AtomicU32 = AtomicU32::new(0);
/// Thread mode's heartbeat: the step tick at the bus task's last 10 ms poll. The step
/// feeds the watchdog only while it is fresh (`hils_rig_core::heartbeat`).
pub static THREAD_HEARTBEAT: AtomicU32 = AtomicU32::new(0);
/// Fresh ADC sequences the step took (wrapping; the ADC task watches it for progress).
pub static ADC_SEQUENCES: AtomicU32 = AtomicU32::new(0);
/// ADC ring restarts after a stall (the ADC task).
pub static ADC_RESTARTS: AtomicU32 = AtomicU32::new(0);
/// `RIG_COMMAND` frames lost: Rx FIFO 0 full (FDCAN RF0L) or the step's queue full.
pub static RX_LOST: AtomicU32 = AtomicU32::new(0);
/// The stack's high-water mark, bytes (the health task).
pub static STACK_PEAK: AtomicU32 = AtomicU32::new(0);

/// Something the step reports to the log.
#[derive(Clone, Copy, Debug, defmt::Format)]
pub enum StepEvent {
    CommandRejected(CommandError),
    LocalCommandRejected(CommandError),
    /// A requested run could not start (the build failed).
    StartFailed(CommandError),
    /// A build came back for a start request no longer pending (stopped, or superseded
    /// by a later `Start`): not installed; with the rig's count of such builds.
    StaleBuild {
        seq: u32,
        count: u32,
    },
}

/// Entries into bus-off seen by the FDCAN interrupt since power-up (wrapping).
pub static BUS_OFF_IRQS: AtomicU32 = AtomicU32::new(0);
/// The step's `ClearFaults` asks the bus supervision to clear its sticky bus-off.
pub static BUS_CLEAR: AtomicBool = AtomicBool::new(false);
