//! Logging the telemetry the step queued, counting what the RTT channel could not take.
//!
//! defmt-rtt runs non-blocking and drop-on-contention (Cargo.toml): a frame that does not
//! fit the ring is dropped whole, silently. The count comes from the ring's cursors in the
//! RTT control block, whose layout is SEGGER's (the probe parses the same block; defmt-rtt
//! 1.3 lib.rs `Header`/`channel.rs` `Channel`, both `repr(C)`), around each record:
//! `hils_rig_core::log_gate`. Drops are counted in either channel mode (probe-rs sets
//! blocking when it attaches unless told otherwise; a host may leave it non-blocking): with
//! no host reading, the ring fills and every later record is counted as lost (it is).

use core::ptr::addr_of;
use core::sync::atomic::{AtomicU32, Ordering};

use hils_rig_core::log_gate::{LogGate, ring_free_bytes};

use crate::shared::{STEP_EVENTS, TELEMETRY, TELEMETRY_DROPS};

/// Room a record needs before it has been measured: a `tlm1` record is 160 bytes before
/// rzCOBS framing (index, 64-bit timestamp, 41 values), at most ~185 after.
const RECORD_RESERVE_BYTES: u32 = 256;

#[repr(C)]
struct RttUpChannel {
    name: *const u8,
    buffer: *mut u8,
    size: u32,
    write: AtomicU32,
    read: AtomicU32,
    flags: AtomicU32,
}

#[repr(C)]
struct RttControlBlock {
    id: [u8; 16],
    max_up_channels: u32,
    max_down_channels: u32,
    up: RttUpChannel,
}

unsafe extern "C" {
    /// defmt-rtt's control block (`#[no_mangle] static _SEGGER_RTT`).
    static _SEGGER_RTT: RttControlBlock;
}

fn up_channel() -> &'static RttUpChannel {
    // SAFETY: the symbol is defmt-rtt's control block with this layout; only its atomics
    // and the constant size are read.
    unsafe { &(*addr_of!(_SEGGER_RTT)).up }
}

/// Logs the step's reports (rejected commands).
#[embassy_executor::task]
pub async fn step_events_task() {
    loop {
        let e = STEP_EVENTS.receive().await;
        defmt::warn!("step: {}", e);
    }
}

/// Logs the telemetry events, gated and counted.
#[embassy_executor::task]
pub async fn telemetry_task() {
    let mut gate = LogGate::new(RECORD_RESERVE_BYTES);
    loop {
        let event = TELEMETRY.receive().await;
        let ch = up_channel();
        // In either RTT mode: in blocking mode a full ring would stall this task (and the
        // logger's lock), in non-blocking mode defmt-rtt would cut the frame short. Both
        // are avoided by writing only what fits, and every event left out is counted.
        let free = ring_free_bytes(
            ch.size,
            ch.read.load(Ordering::Acquire),
            ch.write.load(Ordering::Acquire),
        );
        if gate.admit(free) {
            let before = ch.write.load(Ordering::Acquire);
            event.log();
            gate.landed(ch.size, before, ch.write.load(Ordering::Acquire));
        }
        TELEMETRY_DROPS.store(gate.dropped, Ordering::Relaxed);
    }
}
