//! CAN transmit freshness: a frame that waited past its useful life is dropped and
//! counted, never sent late.
//!
//! The step queues frames with the tick they were made at ([`QueuedFrame`]); the board's
//! transmit task moves them into the controller's three-deep transmit FIFO. While the bus
//! is down (no acknowledge, error passive retrying, bus-off) frames pile up; without this
//! rule the recovery would burst out wheel speeds up to the queue's depth old (issue 11:
//! ~35 ms). Two places drop:
//!
//! * the software queue: [`is_stale`] before a frame goes to the controller;
//! * the controller's FIFO: [`TxSlots`] remembers which frame is in which buffer and asks for
//!   the cancellation (FDCAN_TXBCR) of any still pending past its life; a cancellation that
//!   finished without the frame having gone out (FDCAN_TXBCF set, FDCAN_TXBTO clear) counts
//!   as a drop, as embassy-stm32's own `abort` reads them (fd/peripheral.rs).
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

/// Frames leaving the controller's buffers, since the last call.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TxOutcome {
    pub sent: u32,
    pub dropped: u32,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Slot {
    id: u16,
    tick: u32,
    cancel_requested: bool,
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
    pub const fn new() -> Self {
        Self { slots: [None; N] }
    }

    /// A frame of `id` made at `tick` was written into buffer `slot`.
    pub fn on_write(&mut self, slot: usize, id: u16, tick: u32) {
        if let Some(s) = self.slots.get_mut(slot) {
            *s = Some(Slot {
                id,
                tick,
                cancel_requested: false,
            });
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

    /// Buffers to cancel now: pending (`pending` = FDCAN_TXBRP), past their life, not yet
    /// asked. Marks them asked; the caller writes the mask to FDCAN_TXBCR.
    pub fn stale_mask(&mut self, pending: u32, now_tick: u32) -> u32 {
        let mut m = 0;
        for (i, s) in self.slots.iter_mut().enumerate() {
            if let Some(s) = s
                && pending & (1 << i) != 0
                && !s.cancel_requested
                && is_stale(s.id, s.tick, now_tick)
            {
                s.cancel_requested = true;
                m |= 1 << i;
            }
        }
        m
    }

    /// Frees the buffers whose request ended: not pending any more (`pending` =
    /// FDCAN_TXBRP). Sent if FDCAN_TXBTO says the transmission occurred, else dropped (a
    /// cancellation, ours or the controller's).
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
    fn stale_pending_frames_are_cancelled_once_and_counted() {
        let mut s = TxSlots::<3>::new();
        s.on_write(0, ID_WHEEL_SPEED_12, 0);
        s.on_write(1, ID_STATUS, 0);
        assert_eq!(s.stale_mask(0b011, 10), 0);
        assert_eq!(s.stale_mask(0b011, 11), 0b001);
        assert_eq!(s.stale_mask(0b011, 12), 0, "asked once");
        // Buffer 0 cancelled (no transmission), buffer 1 went out.
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
