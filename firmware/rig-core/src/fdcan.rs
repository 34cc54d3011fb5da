//! Register sequences of the FDCAN controller (RM0440 "FDCAN"; Bosch M_CAN user's manual)
//! that decide what goes on the controller's bus, written over [`FdcanRegisters`] so that
//! the host tests run them against a model of the controller.
//!
//! * [`restart_after_bus_off`]: leave bus-off without the frames queued before it. The
//!   M_CAN sets `CCCR.INIT` on bus-off; clearing INIT alone keeps `TXBRP` and the frames
//!   queued before the outage go out after recovery with old speeds and alive counters.
//!   Setting `CCCR.CCE` (allowed only while INIT is set) resets HPMS, RXF0S, RXF1S, TXFQS,
//!   TXBRP, TXBTO, TXBCF and TXEFS (M_CAN manual, CCCR); `TxSlots::retire` then counts each
//!   flushed frame as dropped (TXBRP and TXBTO clear). Clearing INIT clears CCE with it.
//!   Bosch M_CAN erratum 10 (the Tx handler stops when CCE is set during a Tx scan) needs
//!   a scan in progress: the board writes no TXBAR while bus-off, so none runs.
//! * [`join_bus`]: the controller is started in internal loopback (RM0440 FDCAN test modes:
//!   `CCCR.TEST`, `CCCR.MON`, `TEST.LBCK`; FDCAN_TX held recessive, FDCAN_RX not used), so
//!   the bit timing (`NBTP`) is checked before the node acknowledges or sends anything; only
//!   then is it switched to normal operation. A mismatch leaves it off the bus.
//! * [`rx_element`]: a received classic frame from an Rx FIFO element (RM0440 "Rx FIFO
//!   element"), for the board's own Rx FIFO 0 drain at interrupt priority.

/// `FDCAN_CCCR` bits (RM0440; stm32-metapac `can::regs::Cccr`).
pub mod cccr {
    /// Initialization: the protocol controller is off the bus.
    pub const INIT: u32 = 1 << 0;
    /// Configuration change enable (only while INIT; cleared with INIT).
    pub const CCE: u32 = 1 << 1;
    /// Bus monitoring mode (FDCAN_TX recessive).
    pub const MON: u32 = 1 << 5;
    /// Test mode enable (FDCAN_TEST writable).
    pub const TEST: u32 = 1 << 7;
}

/// `FDCAN_TEST.LBCK`: loop back mode (writable while `CCCR.TEST` is set).
pub const TEST_LBCK: u32 = 1 << 4;

/// How many reads a written INIT may take to show (the M_CAN synchronises INIT between its
/// clock domains: a few kernel clock cycles; far more than enough).
pub const INIT_SYNC_READS: u32 = 10_000;

/// The FDCAN registers the sequences use.
pub trait FdcanRegisters {
    /// `FDCAN_CCCR`.
    fn cccr(&self) -> u32;
    /// Writes `FDCAN_CCCR`.
    fn set_cccr(&mut self, value: u32);
    /// `FDCAN_TEST`.
    fn test(&self) -> u32;
    /// Writes `FDCAN_TEST`.
    fn set_test(&mut self, value: u32);
    /// `FDCAN_NBTP`.
    fn nbtp(&self) -> u32;
}

/// Why the controller could not be (re)started.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FdcanError {
    /// INIT did not read back as set within [`INIT_SYNC_READS`].
    InitTimeout,
    /// `NBTP` holds `found`, not the computed timing: the node stays off the bus.
    NbtpMismatch {
        /// The register's value.
        found: u32,
        /// The computed value.
        expected: u32,
    },
    /// The controller is still in a test or monitoring mode after the switch.
    StillInTestMode {
        /// `FDCAN_CCCR` read back.
        cccr: u32,
    },
}

/// Sets INIT (if not set) and waits until it reads back set; then CCE.
fn enter_configuration(r: &mut impl FdcanRegisters) -> Result<u32, FdcanError> {
    let c = r.cccr() | cccr::INIT;
    r.set_cccr(c);
    if !(0..INIT_SYNC_READS).any(|_| r.cccr() & cccr::INIT != 0) {
        return Err(FdcanError::InitTimeout);
    }
    let c = r.cccr() | cccr::INIT | cccr::CCE;
    r.set_cccr(c);
    Ok(c)
}

/// Restarts the controller after bus-off with its transmit FIFO empty: INIT (already set
/// by the bus-off), CCE (flushes TXBRP/TXFQS), then INIT clear, which starts the bus-off
/// recovery sequence (129 x 11 recessive bits) and clears CCE.
pub fn restart_after_bus_off(r: &mut impl FdcanRegisters) -> Result<(), FdcanError> {
    let c = enter_configuration(r)?;
    r.set_cccr(c & !(cccr::INIT | cccr::CCE));
    Ok(())
}

/// Takes a controller running in internal loopback (off the bus) to normal operation, only
/// if `NBTP` holds `expected_nbtp`; otherwise it stays in loopback and off the bus.
pub fn join_bus(r: &mut impl FdcanRegisters, expected_nbtp: u32) -> Result<(), FdcanError> {
    let found = r.nbtp();
    if found != expected_nbtp {
        return Err(FdcanError::NbtpMismatch {
            found,
            expected: expected_nbtp,
        });
    }
    let c = enter_configuration(r)?;
    // LBCK first (FDCAN_TEST is writable only while CCCR.TEST is set), then TEST and MON.
    let t = r.test() & !TEST_LBCK;
    r.set_test(t);
    r.set_cccr(c & !(cccr::TEST | cccr::MON));
    let c = r.cccr();
    if c & (cccr::TEST | cccr::MON) != 0 || r.test() & TEST_LBCK != 0 {
        return Err(FdcanError::StillInTestMode { cccr: c });
    }
    r.set_cccr(c & !(cccr::INIT | cccr::CCE));
    Ok(())
}

/// Byte offset of Rx FIFO 0 in an FDCAN instance's message RAM (RM0440 "FDCAN message
/// RAM": the G4's fixed layout, 28 standard filters of 1 word and 8 extended of 2 words
/// before it; embassy-stm32 0.6 `message_ram::RegisterBlock` agrees).
pub const RX_FIFO0_OFFSET_BYTES: usize = 28 * 4 + 8 * 8;
/// Bytes of one Rx FIFO element: two header words and 64 data bytes.
pub const RX_ELEMENT_BYTES: usize = 2 * 4 + 64;
/// Elements in an Rx FIFO.
pub const RX_FIFO_ELEMENTS: usize = 3;

/// A classic data frame with a standard identifier, from an Rx FIFO element.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RxElement {
    /// Standard identifier.
    pub id: u16,
    /// Data length, bytes (0-8).
    pub len: u8,
    /// Data bytes; the first `len` are the frame's.
    pub data: [u8; 8],
}

/// Decodes an Rx FIFO element's first four words (RM0440 Rx FIFO element: R0 ESI 31, XTD
/// 30, RTR 29, ID 28:0 with a standard identifier in 28:18; R1 ANMF 31, FIDX 30:24, FDF
/// 21, BRS 20, DLC 19:16, RXTS 15:0; then the data bytes, little endian). `None` for an
/// extended identifier, a remote frame, an FD frame or a DLC above 8: not a `RIG_COMMAND`.
pub fn rx_element(r0: u32, r1: u32, data: [u32; 2]) -> Option<RxElement> {
    let extended = r0 & (1 << 30) != 0;
    let remote = r0 & (1 << 29) != 0;
    let fd = r1 & (1 << 21) != 0;
    let dlc = ((r1 >> 16) & 0xF) as u8;
    if extended || remote || fd || dlc > 8 {
        return None;
    }
    let mut bytes = [0u8; 8];
    bytes[..4].copy_from_slice(&data[0].to_le_bytes());
    bytes[4..].copy_from_slice(&data[1].to_le_bytes());
    Some(RxElement {
        id: ((r0 >> 18) & 0x7FF) as u16,
        len: dlc,
        data: bytes,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::vec::Vec;

    /// The M_CAN as RM0440 and the M_CAN manual describe the bits used here: CCE only
    /// while INIT (cleared with INIT), CCE set resets the transmit FIFO status; TEST and MON
    /// writable only under INIT and CCE; FDCAN_TEST writable only with CCCR.TEST, and reset
    /// when TEST clears. Frames pending in the FIFO go out whenever the node is on the bus.
    #[derive(Default)]
    struct MCan {
        cccr: u32,
        test: u32,
        nbtp: u32,
        /// Transmit requests pending (TXBRP): alive counters of the queued frames.
        pending: Vec<u8>,
        sent: Vec<u8>,
        /// INIT reads 0 for this many reads after it was set (clock domain crossing).
        init_lag: u32,
        lag_left: core::cell::Cell<u32>,
        /// Whether the node was ever on the bus.
        was_on_bus: bool,
    }

    impl MCan {
        fn on_bus(&self) -> bool {
            self.cccr & (cccr::INIT | cccr::MON) == 0
        }
        fn bus_time(&mut self) {
            if self.on_bus() {
                self.was_on_bus = true;
                self.sent.append(&mut self.pending);
            }
        }
    }

    impl FdcanRegisters for MCan {
        fn cccr(&self) -> u32 {
            if self.lag_left.get() > 0 {
                self.lag_left.set(self.lag_left.get() - 1);
                return self.cccr & !cccr::INIT;
            }
            self.cccr
        }
        fn set_cccr(&mut self, v: u32) {
            let old = self.cccr;
            let protected = old & cccr::INIT != 0 && old & cccr::CCE != 0;
            let mut new = old;
            for bit in [cccr::TEST, cccr::MON] {
                if protected {
                    new = (new & !bit) | (v & bit);
                }
            }
            new = (new & !cccr::INIT) | (v & cccr::INIT);
            if old & cccr::INIT == 0 && new & cccr::INIT != 0 {
                self.lag_left.set(self.init_lag);
            }
            if new & cccr::INIT == 0 {
                new &= !cccr::CCE;
            } else if old & cccr::INIT != 0 {
                new = (new & !cccr::CCE) | (v & cccr::CCE);
                if old & cccr::CCE == 0 && new & cccr::CCE != 0 {
                    self.pending.clear();
                }
            }
            if new & cccr::TEST == 0 {
                self.test = 0;
            }
            self.cccr = new;
            self.bus_time();
        }
        fn test(&self) -> u32 {
            self.test
        }
        fn set_test(&mut self, v: u32) {
            if self.cccr & cccr::TEST != 0 {
                self.test = v;
            }
        }
        fn nbtp(&self) -> u32 {
            self.nbtp
        }
    }

    /// A node on the bus with frames 3, 4, 5 queued when the bus goes off.
    fn bus_off_with_three_queued() -> MCan {
        let mut m = MCan::default();
        m.pending = std::vec![3, 4, 5];
        // Bus-off: the hardware sets INIT; the frames stay pending.
        m.cccr |= cccr::INIT;
        m
    }

    #[test]
    fn a_restart_after_bus_off_sends_none_of_the_frames_queued_before() {
        let mut m = bus_off_with_three_queued();
        m.init_lag = 3;
        restart_after_bus_off(&mut m).unwrap();
        assert!(m.on_bus(), "back on the bus");
        assert_eq!(m.cccr & (cccr::INIT | cccr::CCE), 0);
        // A fresh frame after the restart goes out; none of the old ones.
        m.pending.push(6);
        m.bus_time();
        assert_eq!(m.sent, [6]);
        // Negative control, the old restart (INIT cleared alone): the old frames go out.
        let mut m = bus_off_with_three_queued();
        m.set_cccr(m.cccr & !cccr::INIT);
        assert_eq!(m.sent, [3, 4, 5]);
    }

    /// Internal loopback as embassy's `start(InternalLoopbackMode)` leaves it.
    fn in_loopback(nbtp: u32) -> MCan {
        MCan {
            cccr: cccr::TEST | cccr::MON,
            test: TEST_LBCK,
            nbtp,
            ..Default::default()
        }
    }

    #[test]
    fn the_node_joins_the_bus_only_with_the_computed_timing() {
        let mut m = in_loopback(0x0A00_2805);
        assert_eq!(
            join_bus(&mut m, 0x0A00_2806),
            Err(FdcanError::NbtpMismatch {
                found: 0x0A00_2805,
                expected: 0x0A00_2806
            })
        );
        assert!(!m.was_on_bus, "a wrong timing never reaches the bus");
        assert_eq!((m.cccr, m.test), (cccr::TEST | cccr::MON, TEST_LBCK));
        let mut m = in_loopback(0x0A00_2805);
        m.init_lag = 5;
        join_bus(&mut m, 0x0A00_2805).unwrap();
        assert!(m.on_bus());
        assert_eq!((m.cccr, m.test), (0, 0));
        // Negative control: TEST and MON cannot be cleared outside INIT/CCE, so a plain write
        // leaves the node in loopback.
        let mut m = in_loopback(0x0A00_2805);
        m.set_cccr(0);
        assert!(!m.on_bus());
    }

    #[test]
    fn an_init_that_never_shows_stops_the_sequence() {
        let mut m = in_loopback(7);
        m.init_lag = INIT_SYNC_READS + 1;
        assert_eq!(join_bus(&mut m, 7), Err(FdcanError::InitTimeout));
        assert!(!m.was_on_bus);
    }

    #[test]
    fn rx_elements_decode_standard_classic_frames_only() {
        // RIG_COMMAND 0x200, DLC 8, bytes 1..=8, filter index 0, timestamp 0x1234.
        let r0 = 0x200 << 18;
        let r1 = (8 << 16) | 0x1234;
        let e = rx_element(r0, r1, [0x0403_0201, 0x0807_0605]).unwrap();
        assert_eq!(
            e,
            RxElement {
                id: 0x200,
                len: 8,
                data: [1, 2, 3, 4, 5, 6, 7, 8]
            }
        );
        assert_eq!(rx_element(0x7FF << 18, 3 << 16, [0, 0]).unwrap().id, 0x7FF);
        for (r0, r1) in [
            (r0 | 1 << 30, r1),     // extended identifier
            (r0 | 1 << 29, r1),     // remote frame
            (r0, r1 | 1 << 21),     // FD frame
            (r0, (9 << 16) | 0x12), // DLC 9 (12 bytes: FD only)
        ] {
            assert_eq!(rx_element(r0, r1, [0, 0]), None);
        }
    }
}
