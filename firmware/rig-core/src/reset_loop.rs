//! Fault resets in a row, counted across resets, and the hold after too many.
//!
//! Every fault ends in the safe state and a reset (`firmware/board/src/fault.rs`). A fault
//! that comes back at every start (a failed check at start-up, a wrong clock, a missing
//! part) would otherwise make a reset loop of ~20 Hz that rejoins the controller's bus and
//! moves the lines each time. The board keeps a [`ResetLoopRecord`] in RAM that a reset
//! does not clear (`.uninit`), and at each start takes the reset's cause
//! ([`ResetCause`]):
//!
//! * a fault reset (one of the board's fault handlers reset it, or the independent
//!   watchdog did) counts one more;
//! * a power-up, a brown-out, the reset button (NRST alone) or a debugger's reset (a
//!   software reset with no fault recorded) starts the count again at 0;
//! * after [`HOLD_AFTER_FAULT_RESETS`] fault resets in a row the board does not start: it
//!   holds the safe state (no CAN, no step, outputs silent, the LED's hold pattern) until
//!   it is power-cycled or reset by its button ([`Boot::Hold`]);
//! * once the board has run [`HEALTHY_RUN_TICKS`] steps after a start, the count is 0 again
//!   ([`ResetLoopRecord::ran_healthy`]): faults far apart are not a loop.
//!
//! The record is three words, the count protected by a magic word and its complement: RAM
//! that holds garbage after a power-up reads as a count of 0.

use crate::STEP_RATE_HZ;

/// Fault resets in a row after which the board holds the safe state instead of starting.
pub const HOLD_AFTER_FAULT_RESETS: u32 = 3;
/// Steps after a start after which the run counts as healthy (10 s).
pub const HEALTHY_RUN_TICKS: u32 = 10 * STEP_RATE_HZ;

const MAGIC: u32 = 0x5E5E_7C0D;

/// Why the board was reset, as the start-up code finds it (RCC_CSR flags, and whether a
/// fault handler recorded a fault before the reset).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ResetCause {
    /// Power-up, brown-out or option-byte load.
    PowerOn,
    /// The reset pin alone (the board's reset button).
    Pin,
    /// A software reset with no fault recorded (a debugger or probe reset).
    Debugger,
    /// A software reset by a fault handler (a fault was recorded).
    FaultHandler,
    /// The independent (or window) watchdog.
    Watchdog,
}

/// What the board does at this start.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Boot {
    /// Start normally; `fault_resets` in a row before this start.
    Start {
        /// Fault resets in a row before this start.
        fault_resets: u32,
    },
    /// Hold the safe state until power-cycled or reset by the button.
    Hold {
        /// Fault resets in a row before this start.
        fault_resets: u32,
    },
}

impl Boot {
    /// Fault resets in a row before this start.
    pub fn fault_resets(self) -> u32 {
        match self {
            Boot::Start { fault_resets } | Boot::Hold { fault_resets } => fault_resets,
        }
    }
}

/// The record kept across resets (`repr(C)`: three words in the board's `.uninit`).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ResetLoopRecord {
    magic: u32,
    count: u32,
    check: u32,
}

impl ResetLoopRecord {
    /// A record of `count` fault resets.
    pub const fn with_count(count: u32) -> Self {
        Self {
            magic: MAGIC,
            count,
            check: !count ^ MAGIC,
        }
    }

    /// Any three words (RAM after a power-up).
    pub const fn from_words(magic: u32, count: u32, check: u32) -> Self {
        Self {
            magic,
            count,
            check,
        }
    }

    /// Fault resets in a row recorded (0 unless the record is intact).
    pub fn count(&self) -> u32 {
        if self.magic == MAGIC && self.check == !self.count ^ MAGIC {
            self.count
        } else {
            0
        }
    }

    /// Takes this start's reset cause: updates the count and says whether to start.
    pub fn on_boot(&mut self, cause: ResetCause) -> Boot {
        let fault_resets = match cause {
            ResetCause::PowerOn | ResetCause::Pin | ResetCause::Debugger => 0,
            ResetCause::FaultHandler | ResetCause::Watchdog => self.count().saturating_add(1),
        };
        *self = Self::with_count(fault_resets);
        if fault_resets >= HOLD_AFTER_FAULT_RESETS {
            Boot::Hold { fault_resets }
        } else {
            Boot::Start { fault_resets }
        }
    }

    /// The board ran [`HEALTHY_RUN_TICKS`] after this start: the next fault starts a new count.
    pub fn ran_healthy(&mut self) {
        *self = Self::with_count(0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn three_fault_resets_in_a_row_hold_the_board() {
        let mut r = ResetLoopRecord::from_words(0xDEAD_BEEF, 7, 0);
        assert_eq!(r.count(), 0, "garbage after power-up");
        assert_eq!(
            r.on_boot(ResetCause::PowerOn),
            Boot::Start { fault_resets: 0 }
        );
        assert_eq!(
            r.on_boot(ResetCause::FaultHandler),
            Boot::Start { fault_resets: 1 }
        );
        assert_eq!(
            r.on_boot(ResetCause::Watchdog),
            Boot::Start { fault_resets: 2 }
        );
        assert_eq!(
            r.on_boot(ResetCause::FaultHandler),
            Boot::Hold { fault_resets: 3 }
        );
        // A watchdog or fault reset while holding cannot happen (the hold starts nothing);
        // if one did, it still holds.
        assert_eq!(r.on_boot(ResetCause::Watchdog).fault_resets(), 4);
        assert!(matches!(r.on_boot(ResetCause::Watchdog), Boot::Hold { .. }));
    }

    #[test]
    fn power_the_button_a_debugger_or_a_healthy_run_start_the_count_again() {
        for cause in [ResetCause::PowerOn, ResetCause::Pin, ResetCause::Debugger] {
            let mut r = ResetLoopRecord::with_count(5);
            assert_eq!(
                r.on_boot(cause),
                Boot::Start { fault_resets: 0 },
                "{cause:?}"
            );
        }
        let mut r = ResetLoopRecord::with_count(2);
        r.ran_healthy();
        assert_eq!(
            r.on_boot(ResetCause::FaultHandler),
            Boot::Start { fault_resets: 1 }
        );
    }

    #[test]
    fn a_damaged_record_reads_as_no_fault_resets() {
        let good = ResetLoopRecord::with_count(2);
        for flip in 0..96 {
            let mut w = [good.magic, good.count, good.check];
            w[flip / 32] ^= 1 << (flip % 32);
            let r = ResetLoopRecord::from_words(w[0], w[1], w[2]);
            assert_eq!(r.count(), 0, "bit {flip}");
        }
        assert_eq!(
            ResetLoopRecord::with_count(u32::MAX).count(),
            u32::MAX,
            "saturates, never wraps to 0"
        );
        let mut r = ResetLoopRecord::with_count(u32::MAX);
        assert_eq!(r.on_boot(ResetCause::Watchdog).fault_resets(), u32::MAX);
    }
}
