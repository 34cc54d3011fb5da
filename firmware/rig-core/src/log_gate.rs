//! Counting the telemetry the RTT channel could not take.
//!
//! The board logs with defmt-rtt in non-blocking, drop-on-contention mode (features
//! `disable-blocking-mode` and `drop-on-contention`): a frame that does not fit the free
//! space of the up-channel ring is dropped whole by defmt-rtt (`Channel::stage_bytes`), so
//! the stream never stalls the board and is never corrupted, but defmt-rtt does not say
//! that it dropped. The logging task therefore reads the ring's cursors (the RTT control
//! block, whose layout is SEGGER's and which the probe reads too) around each record:
//!
//! * before: [`LogGate::admit`] refuses a record when the free space is below the largest
//!   record frame seen so far (and a reserve), and counts it;
//! * after: [`LogGate::landed`] counts the record as dropped if the write cursor did not
//!   move (a contention or a frame larger than the space).
//!
//! Only the logging task writes records; the count is exact as long as interrupts do not
//! log (on this board only the fault handlers do, and they end in a reset).

/// Free bytes of an RTT ring of `size` bytes with host `read` and target `write` cursors
/// (one byte always stays empty, as in SEGGER's and defmt-rtt's ring).
pub fn ring_free_bytes(size: u32, read: u32, write: u32) -> u32 {
    if size == 0 {
        return 0;
    }
    let used = write.wrapping_sub(read).wrapping_add(size) % size;
    size - 1 - used
}

/// Bytes a write moved the cursor of a ring of `size` bytes.
pub fn ring_advance(size: u32, before: u32, after: u32) -> u32 {
    if size == 0 {
        return 0;
    }
    after.wrapping_sub(before).wrapping_add(size) % size
}

/// Counts records logged and dropped.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LogGate {
    reserve_bytes: u32,
    max_frame_bytes: u32,
    /// Records that reached the ring.
    pub logged: u32,
    /// Records dropped (no room, or the frame did not land).
    pub dropped: u32,
}

impl LogGate {
    /// A gate that wants at least `reserve_bytes` free before a record (an upper bound of a
    /// record's encoded frame until one has been measured).
    pub const fn new(reserve_bytes: u32) -> Self {
        Self {
            reserve_bytes,
            max_frame_bytes: 0,
            logged: 0,
            dropped: 0,
        }
    }

    /// Space a record needs: the reserve or the largest record frame seen, whichever is more.
    pub fn needed_bytes(&self) -> u32 {
        self.reserve_bytes.max(self.max_frame_bytes)
    }

    /// Largest record frame measured, bytes.
    pub fn max_frame_bytes(&self) -> u32 {
        self.max_frame_bytes
    }

    /// Whether to write a record with `free` bytes in the ring; a refusal is counted.
    pub fn admit(&mut self, free: u32) -> bool {
        let ok = free >= self.needed_bytes();
        if !ok {
            self.dropped = self.dropped.wrapping_add(1);
        }
        ok
    }

    /// After writing a record: the write cursor went from `before` to `after` in a ring of
    /// `size` bytes.
    pub fn landed(&mut self, size: u32, before: u32, after: u32) {
        let n = ring_advance(size, before, after);
        if n == 0 {
            self.dropped = self.dropped.wrapping_add(1);
        } else {
            self.logged = self.logged.wrapping_add(1);
            self.max_frame_bytes = self.max_frame_bytes.max(n);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn free_space_matches_a_byte_model() {
        let size = 16u32;
        for read in 0..size {
            for write in 0..size {
                // Bytes the host has still to read: from `read` up to `write`.
                let mut n = 0;
                let mut r = read;
                while r != write {
                    r = (r + 1) % size;
                    n += 1;
                }
                assert_eq!(ring_free_bytes(size, read, write), size - 1 - n);
            }
        }
    }

    #[test]
    fn gate_counts_refusals_and_frames_that_did_not_land() {
        let mut g = LogGate::new(200);
        assert!(!g.admit(199));
        assert!(g.admit(200));
        g.landed(1024, 1000, 170); // wrapped: 194 bytes
        assert_eq!((g.logged, g.dropped, g.max_frame_bytes()), (1, 1, 194));
        g.landed(1024, 170, 170);
        assert_eq!(g.dropped, 2);
        let mut g = LogGate::new(100);
        g.landed(1024, 0, 300);
        assert_eq!(g.needed_bytes(), 300);
        assert!(!g.admit(299));
    }
}
