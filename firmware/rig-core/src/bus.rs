//! CAN bus supervision: error-passive and bus-off are detected, recovered from and reported.
//!
//! **Counting.** The FDCAN interrupt (`IR.BO`, bus-off status changed) counts every entry
//! into bus-off as it happens; the board passes that total to [`BusMonitor::note_irq_bus_offs`],
//! so an episode shorter than the 10 ms poll is counted too. The board also polls the
//! protocol status (FDCAN `PSR`: bus-off and error-passive bits; `ECR`: error counters)
//! every 10 ms and feeds it to [`BusMonitor::poll`] for the mode, the log and the recovery.
//!
//! **Recovery with backoff.** Automatic recovery is off: the controller stays bus-off
//! (`CCCR.INIT` set by the hardware) until the monitor asks for a restart
//! ([`BusAction::Restart`]: the board clears `CCCR.INIT`, after which the controller waits
//! 128 x 11 recessive bits, 2.8 ms at 500 kbit/s, before it joins the bus again). The first
//! restart comes [`BusMonitor::BACKOFF_FIRST_MS`] after the bus-off, each further one of the
//! same episode after twice the delay before, up to [`BusMonitor::RESTART_AFTER_MS`]: a
//! controller that keeps going bus-off (wrong bit rate, short) disturbs the bus less and
//! less often. Error passive needs no action: the controller goes on sending and returns to
//! error active by itself.
//!
//! Reported: the mode now (fault flags [`crate::rig::Faults::CAN_ERROR_PASSIVE`],
//! [`crate::rig::Faults::CAN_BUS_OFF`]), a sticky "bus-off seen" flag until faults are
//! cleared ([`BusMonitor::clear`], refused while bus-off), and the count of bus-off events
//! (in `RIG_DIAG`).

/// Error state of the controller.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum BusMode {
    #[default]
    /// Both error counters at most 127: on the bus normally.
    ErrorActive,
    /// An error counter is above 127.
    ErrorPassive,
    /// TEC above 255: not on the bus.
    BusOff,
}

/// A poll of the controller.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct BusStatus {
    /// Error state.
    pub mode: BusMode,
    /// Transmit error counter (TEC).
    pub tx_errors: u8,
    /// Receive error counter (REC).
    pub rx_errors: u8,
}

/// A change the monitor saw (for the log).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum BusEvent {
    /// An error counter went above 127.
    EnteredErrorPassive,
    /// The controller left the bus (TEC above 255).
    WentBusOff,
    /// Back to error active (from passive or bus-off), with the bus-off time if it was off, ms.
    Recovered {
        /// Time spent bus-off, ms (0 if it was only error passive).
        bus_off_ms: u32,
    },
}

/// What the board must do.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum BusAction {
    /// Nothing to do.
    None,
    /// Re-initialise and restart the controller (it stayed bus-off too long).
    Restart,
}

/// Supervises the bus state.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BusMonitor {
    mode: BusMode,
    bus_off_since_ms: Option<u32>,
    last_restart_ms: u32,
    /// Bus-off events since power-up.
    pub bus_off_count: u32,
    /// Error-passive episodes since power-up.
    pub passive_count: u32,
    /// Restarts requested since power-up.
    pub restarts: u32,
    /// A bus-off happened since faults were last cleared.
    pub bus_off_seen: bool,
    /// Restarts asked for in the present bus-off episode (sets the backoff).
    attempts: u32,
    /// Bus-off entries the interrupt counted since power-up.
    irq_total_count: u32,
    /// Bus-off entries the polls saw since power-up.
    poll_count: u32,
    /// The interrupt's bus-off count at the last [`BusMonitor::note_irq_bus_offs`].
    irq_seen: u32,
}

impl BusMonitor {
    /// Longest delay between restarts of one bus-off episode, ms.
    pub const RESTART_AFTER_MS: u32 = 1000;
    /// Delay of the first restart after a bus-off, ms (one poll).
    pub const BACKOFF_FIRST_MS: u32 = 10;

    /// A monitor of a controller that is error active, no fault seen.
    pub fn new() -> Self {
        Self::default()
    }

    /// The error state of the last poll.
    pub fn mode(&self) -> BusMode {
        self.mode
    }

    /// Takes the interrupt's running count of bus-off entries (wrapping): episodes the
    /// polls missed are counted and set "bus-off seen".
    pub fn note_irq_bus_offs(&mut self, irq_total: u32) {
        let new = irq_total.wrapping_sub(self.irq_seen);
        self.irq_seen = irq_total;
        if new > 0 {
            self.bus_off_seen = true;
            // The polls count the entries they see; the interrupt sees all of them.
            self.irq_total_count = self.irq_total_count.saturating_add(new);
            self.bus_off_count = self.poll_count.max(self.irq_total_count);
        }
    }

    /// Delay before the next restart of this episode, ms.
    pub fn backoff_ms(&self) -> u32 {
        Self::BACKOFF_FIRST_MS
            .checked_shl(self.attempts)
            .unwrap_or(u32::MAX)
            .min(Self::RESTART_AFTER_MS)
    }

    /// Takes a poll at `now_ms` (a wrapping millisecond clock).
    pub fn poll(&mut self, status: BusStatus, now_ms: u32) -> (Option<BusEvent>, BusAction) {
        let before = self.mode;
        self.mode = status.mode;
        let mut event = None;
        match (before, status.mode) {
            (BusMode::BusOff, BusMode::BusOff) => {}
            (_, BusMode::BusOff) => {
                self.poll_count = self.poll_count.saturating_add(1);
                self.bus_off_count = self.poll_count.max(self.irq_total_count);
                self.bus_off_seen = true;
                self.bus_off_since_ms = Some(now_ms);
                self.last_restart_ms = now_ms;
                self.attempts = 0;
                event = Some(BusEvent::WentBusOff);
            }
            (BusMode::ErrorActive, BusMode::ErrorPassive) => {
                self.passive_count = self.passive_count.saturating_add(1);
                event = Some(BusEvent::EnteredErrorPassive);
            }
            (BusMode::BusOff, m) => {
                let since = self.bus_off_since_ms.take().unwrap_or(now_ms);
                if m == BusMode::ErrorPassive {
                    self.passive_count = self.passive_count.saturating_add(1);
                }
                event = Some(BusEvent::Recovered {
                    bus_off_ms: now_ms.wrapping_sub(since),
                });
            }
            (BusMode::ErrorPassive, BusMode::ErrorActive) => {
                event = Some(BusEvent::Recovered { bus_off_ms: 0 });
            }
            _ => {}
        }
        let mut action = BusAction::None;
        if status.mode == BusMode::BusOff
            && now_ms.wrapping_sub(self.last_restart_ms) >= self.backoff_ms()
        {
            self.last_restart_ms = now_ms;
            self.attempts = self.attempts.saturating_add(1);
            self.restarts = self.restarts.saturating_add(1);
            action = BusAction::Restart;
        }
        (event, action)
    }

    /// Clears the sticky "bus-off seen" (by the clear-faults command) unless bus-off now.
    pub fn clear(&mut self) {
        if self.mode != BusMode::BusOff {
            self.bus_off_seen = false;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn st(mode: BusMode) -> BusStatus {
        BusStatus {
            mode,
            tx_errors: 0,
            rx_errors: 0,
        }
    }

    #[test]
    fn passive_and_back() {
        let mut m = BusMonitor::new();
        assert_eq!(m.poll(st(BusMode::ErrorActive), 0), (None, BusAction::None));
        assert_eq!(
            m.poll(st(BusMode::ErrorPassive), 10).0,
            Some(BusEvent::EnteredErrorPassive)
        );
        assert_eq!(m.poll(st(BusMode::ErrorPassive), 20).0, None);
        assert_eq!(
            m.poll(st(BusMode::ErrorActive), 30).0,
            Some(BusEvent::Recovered { bus_off_ms: 0 })
        );
        assert_eq!(
            (m.passive_count, m.bus_off_count, m.bus_off_seen),
            (1, 0, false)
        );
    }

    #[test]
    fn bus_off_recovers_and_is_reported_until_cleared() {
        let mut m = BusMonitor::new();
        m.poll(st(BusMode::ErrorPassive), 0);
        assert_eq!(
            m.poll(st(BusMode::BusOff), 10).0,
            Some(BusEvent::WentBusOff)
        );
        m.clear();
        assert!(m.bus_off_seen, "cannot clear while bus-off");
        assert_eq!(
            m.poll(st(BusMode::ErrorActive), 40).0,
            Some(BusEvent::Recovered { bus_off_ms: 30 })
        );
        assert_eq!(m.bus_off_count, 1);
        assert!(m.bus_off_seen);
        m.clear();
        assert!(!m.bus_off_seen);
    }

    #[test]
    fn restarts_back_off_from_10_ms_to_each_second() {
        let mut m = BusMonitor::new();
        m.poll(st(BusMode::BusOff), 5000);
        let mut at = std::vec::Vec::new();
        for t in (5010..8300).step_by(10) {
            if m.poll(st(BusMode::BusOff), t).1 == BusAction::Restart {
                at.push(t);
            }
        }
        // Delays 10, 20, 40, ... 640 ms, then 1000 ms (independent list).
        assert_eq!(at, [5010, 5030, 5070, 5150, 5310, 5630, 6270, 7270, 8270]);
        assert_eq!(m.bus_off_count, 1);
        // A new episode starts the backoff again.
        m.poll(st(BusMode::ErrorActive), 8280);
        m.poll(st(BusMode::BusOff), 8290);
        assert_eq!(m.poll(st(BusMode::BusOff), 8300).1, BusAction::Restart);
        assert_eq!(m.bus_off_count, 2);
        // The millisecond clock may wrap.
        let mut m = BusMonitor::new();
        m.poll(st(BusMode::BusOff), u32::MAX - 5);
        assert_eq!(m.poll(st(BusMode::BusOff), 3).1, BusAction::None);
        assert_eq!(m.poll(st(BusMode::BusOff), 4).1, BusAction::Restart);
    }

    #[test]
    fn a_bus_off_shorter_than_the_poll_is_counted_from_the_interrupt() {
        let mut m = BusMonitor::new();
        m.poll(st(BusMode::ErrorActive), 0);
        // Two episodes of 3 ms between polls: the polls never see bus-off.
        m.note_irq_bus_offs(2);
        m.poll(st(BusMode::ErrorActive), 10);
        assert_eq!((m.bus_off_count, m.bus_off_seen), (2, true));
        // One seen by both the interrupt and the poll is counted once.
        m.note_irq_bus_offs(3);
        m.poll(st(BusMode::BusOff), 20);
        assert_eq!(m.bus_off_count, 3);
        m.poll(st(BusMode::ErrorActive), 30);
        m.clear();
        assert!(!m.bus_off_seen);
        // The interrupt's counter wraps.
        let mut m = BusMonitor::new();
        m.note_irq_bus_offs(u32::MAX);
        m.note_irq_bus_offs(1);
        assert_eq!(m.bus_off_count, u32::MAX);
    }
}
