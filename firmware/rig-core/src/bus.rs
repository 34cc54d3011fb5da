//! CAN bus supervision: error-passive and bus-off are detected, recovered from and reported.
//!
//! The board polls the controller's protocol status (FDCAN `PSR`: bus-off and
//! error-passive bits; `ECR`: error counters) every 10 ms and feeds it to
//! [`BusMonitor::poll`]. Recovery from bus-off is the CAN standard's: the controller leaves
//! bus-off after 128 x 11 recessive bits (2.8 ms at 500 kbit/s once the bus is idle); the
//! board starts it at once (FDCAN automatic bus-off recovery: `CCCR.INIT` cleared in the
//! interrupt). If the controller is still bus-off after [`BusMonitor::RESTART_AFTER_MS`]
//! (nobody acknowledges, e.g. the cable is off), the monitor asks the board to restart the
//! controller ([`BusAction::Restart`]) and keeps asking at that interval. Error passive
//! needs no action: the controller goes on sending and returns to error active by itself.
//!
//! Reported: the mode now (fault flags [`crate::rig::Faults::CAN_ERROR_PASSIVE`],
//! [`crate::rig::Faults::CAN_BUS_OFF`]), a sticky "bus-off seen" flag until faults are
//! cleared, and the count of bus-off events (in `RIG_DIAG`).

/// Error state of the controller.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum BusMode {
    #[default]
    ErrorActive,
    /// An error counter is above 127.
    ErrorPassive,
    /// TEC above 255: not on the bus.
    BusOff,
}

/// A poll of the controller.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct BusStatus {
    pub mode: BusMode,
    pub tx_errors: u8,
    pub rx_errors: u8,
}

/// A change the monitor saw (for the log).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum BusEvent {
    EnteredErrorPassive,
    WentBusOff,
    /// Back to error active (from passive or bus-off), with the bus-off time if it was off, ms.
    Recovered {
        bus_off_ms: u32,
    },
}

/// What the board must do.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum BusAction {
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
}

impl BusMonitor {
    /// Bus-off this long (ms) -> restart the controller.
    pub const RESTART_AFTER_MS: u32 = 1000;

    pub fn new() -> Self {
        Self::default()
    }

    pub fn mode(&self) -> BusMode {
        self.mode
    }

    /// Takes a poll at `now_ms` (a wrapping millisecond clock).
    pub fn poll(&mut self, status: BusStatus, now_ms: u32) -> (Option<BusEvent>, BusAction) {
        let before = self.mode;
        self.mode = status.mode;
        let mut event = None;
        match (before, status.mode) {
            (BusMode::BusOff, BusMode::BusOff) => {}
            (_, BusMode::BusOff) => {
                self.bus_off_count = self.bus_off_count.saturating_add(1);
                self.bus_off_seen = true;
                self.bus_off_since_ms = Some(now_ms);
                self.last_restart_ms = now_ms;
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
            && now_ms.wrapping_sub(self.last_restart_ms) >= Self::RESTART_AFTER_MS
        {
            self.last_restart_ms = now_ms;
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
    fn restart_when_bus_off_persists_and_again_each_second() {
        let mut m = BusMonitor::new();
        m.poll(st(BusMode::BusOff), 5000);
        let mut restarts = 0;
        for t in (5010..8100).step_by(10) {
            if m.poll(st(BusMode::BusOff), t).1 == BusAction::Restart {
                restarts += 1;
            }
        }
        // At 6000, 7000 and 8000 ms.
        assert_eq!(restarts, 3);
        assert_eq!(m.bus_off_count, 1);
        // The millisecond clock may wrap.
        let mut m = BusMonitor::new();
        m.poll(st(BusMode::BusOff), u32::MAX - 100);
        assert_eq!(m.poll(st(BusMode::BusOff), 898).1, BusAction::None);
        assert_eq!(m.poll(st(BusMode::BusOff), 899).1, BusAction::Restart);
    }
}
