//! CAN transmit freshness: a frame that waited past its useful life is dropped and
//! counted, never sent late.
//!
//! The step queues frames with the tick they were made at ([`QueuedFrame`]); the board's
//! transmit task moves them into the controller's three-deep transmit FIFO. While the bus
//! is down (no acknowledge, error passive retrying, bus-off) frames pile up; without this
//! rule the recovery would burst out wheel speeds up to the queue's depth old (issue 11:
//! ~35 ms). Frames are dropped in the software queue: [`is_stale_behind`] before a frame
//! goes to the controller (past its life by the time the frames ahead of it in the FIFO
//! have gone out), and none is written while the controller is bus-off.
//!
//! Frames already in the controller are not cancelled: the transmit buffers run in FIFO
//! mode (so that no pending frame is aborted for a higher-priority one), and Bosch's M_CAN
//! user's manual (Tx FIFO; Tx buffer cancellation) says cancellation is not intended for
//! Tx FIFO operation. [`TxSlots`] still tracks which frame is in which buffer, and counts a
//! request that ended without a transmission (FDCAN_TXBTO clear) as a drop, as
//! embassy-stm32's own `abort` reads them (fd/peripheral.rs). So at most the three frames
//! in the controller when the bus goes down can go out late when it comes back.
//!
//! A frame's life is its period ([`max_age_ticks`]): by then the step has made a newer one
//! of the same id, which is the one the receiver wants.

use crate::STEP_RATE_HZ;
use crate::can::{ID_DIAG, ID_STATUS, ID_WHEEL_SPEED_12, ID_WHEEL_SPEED_34};

/// Step ticks per millisecond.
pub const TICKS_PER_MS: u32 = STEP_RATE_HZ / 1000;

/// A frame with the step tick it was made at.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct QueuedFrame<F> {
    /// The frame.
    pub frame: F,
    /// The step tick (0.1 ms, wrapping) the frame was queued at.
    pub tick: u32,
}

/// Useful life of a frame by identifier, step ticks: one period of the frame.
pub fn max_age_ticks(id: u16) -> u32 {
    match id {
        ID_WHEEL_SPEED_12 | ID_WHEEL_SPEED_34 => TICKS_PER_MS,
        ID_STATUS => 10 * TICKS_PER_MS,
        ID_DIAG => 100 * TICKS_PER_MS,
        _ => 100 * TICKS_PER_MS,
    }
}

/// Whether a frame of `id` queued at `queued_tick` is past its life at `now_tick`
/// (a wrapping tick counter).
pub fn is_stale(id: u16, queued_tick: u32, now_tick: u32) -> bool {
    now_tick.wrapping_sub(queued_tick) > max_age_ticks(id)
}

/// Bits on the bus of the longest classic frame (8 data bytes, standard id, worst-case bit
/// stuffing, end of frame and intermission): 135.
pub const MAX_FRAME_BITS: u32 = 135;

/// Step ticks one longest frame occupies a bus of `bitrate` bit/s, rounded up (3 at
/// 500 kbit/s).
pub fn frame_ticks(bitrate: u32) -> u32 {
    (MAX_FRAME_BITS * STEP_RATE_HZ).div_ceil(bitrate.max(1))
}

/// Whether a frame of `id` queued at `queued_tick` would be past its life when it gets
/// on the bus behind `frames_ahead` frames pending in the controller's FIFO (each
/// `frame_ticks` long): such a frame is dropped before it is written, since a frame in
/// the FIFO cannot be taken back.
pub fn is_stale_behind(
    id: u16,
    queued_tick: u32,
    now_tick: u32,
    frames_ahead: u32,
    frame_ticks: u32,
) -> bool {
    is_stale(
        id,
        queued_tick,
        now_tick.wrapping_add(frames_ahead.saturating_mul(frame_ticks)),
    )
}

/// Frames leaving the controller's buffers, since the last call.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TxOutcome {
    /// Frames that went out on the bus.
    pub sent: u32,
    /// Frames whose transmission request ended without a transmission (cancelled).
    pub dropped: u32,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Slot {
    id: u16,
    tick: u32,
}

/// What sits in each of the controller's `N` transmit buffers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TxSlots<const N: usize> {
    slots: [Option<Slot>; N],
}

impl<const N: usize> Default for TxSlots<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> TxSlots<N> {
    /// All slots empty.
    pub const fn new() -> Self {
        Self { slots: [None; N] }
    }

    /// A frame of `id` made at `tick` was written into buffer `slot`.
    pub fn on_write(&mut self, slot: usize, id: u16, tick: u32) {
        if let Some(s) = self.slots.get_mut(slot) {
            *s = Some(Slot { id, tick });
        }
    }

    /// Buffers still occupied by a tracked frame (bit per buffer).
    pub fn occupied(&self) -> u32 {
        let mut m = 0;
        for (i, s) in self.slots.iter().enumerate() {
            if s.is_some() {
                m |= 1 << i;
            }
        }
        m
    }

    /// Frees the buffers whose request ended: not pending any more (`pending` =
    /// FDCAN_TXBRP). Sent if FDCAN_TXBTO says the transmission occurred, else dropped (a
    /// request the controller ended without sending).
    pub fn retire(&mut self, pending: u32, tx_occurred: u32) -> TxOutcome {
        let mut out = TxOutcome::default();
        for (i, s) in self.slots.iter_mut().enumerate() {
            let bit = 1 << i;
            if s.is_some() && pending & bit == 0 {
                if tx_occurred & bit != 0 {
                    out.sent += 1;
                } else {
                    out.dropped += 1;
                }
                *s = None;
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn life_is_one_period_and_wraps() {
        assert!(!is_stale(ID_WHEEL_SPEED_12, 100, 110));
        assert!(is_stale(ID_WHEEL_SPEED_12, 100, 111));
        assert!(!is_stale(ID_STATUS, 100, 200));
        assert!(is_stale(ID_STATUS, 100, 201));
        assert!(!is_stale(ID_WHEEL_SPEED_12, u32::MAX - 4, 5));
        assert!(is_stale(ID_DIAG, u32::MAX - 500, 501));
    }

    #[test]
    fn ended_requests_are_counted_sent_or_dropped() {
        let mut s = TxSlots::<3>::new();
        s.on_write(0, ID_WHEEL_SPEED_12, 0);
        s.on_write(1, ID_STATUS, 0);
        assert_eq!(s.occupied(), 0b011);
        // Both still pending: nothing retired.
        assert_eq!(s.retire(0b011, 0), TxOutcome::default());
        // Buffer 0 ended without transmission, buffer 1 went out.
        assert_eq!(
            s.retire(0b000, 0b010),
            TxOutcome {
                sent: 1,
                dropped: 1
            }
        );
        assert_eq!(s.occupied(), 0);
        assert_eq!(s.retire(0, 0b111), TxOutcome::default());
    }
}
