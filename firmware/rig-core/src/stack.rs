//! The stack: its high-water mark from the paint, and whether a HardFault was an overflow.
//!
//! The board puts its one stack (thread mode, the executor, the builder's large frame, every
//! interrupt and fault handler) at the bottom of SRAM, below the statics
//! (`firmware/board/stack.x`), so that it grows down towards the end of RAM, not into the
//! rig's state; below SRAM an MPU region forbids every access. An overflow is therefore a
//! MemManage fault (escalated to HardFault), whose handler moves to its own stack, finds
//! the overflow ([`is_overflow`]), puts the outputs in the safe state and resets.
//!
//! cortex-m-rt paints the stack with [`PAINT`] before `main` (feature `paint-stack`); a
//! thread-mode task finds the lowest scrubbed word ([`StackWatch`]) and reports the
//! high-water mark in `RIG_HEALTH` (`StackPeak` of `StackSize`).

/// cortex-m-rt's paint (`STACK_PAINT_VALUE`).
pub const PAINT: u32 = 0xCCCC_CCCC;

/// Bytes of a full exception frame with the FPU's registers (26 words + alignment).
pub const FP_FRAME_BYTES: u32 = 0x6C;

/// The high-water mark of a painted stack, kept between scans: the mark only grows, so each
/// scan reads only the words still painted.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StackWatch {
    /// Words of the stack.
    words: usize,
    /// Words from the bottom still painted at the last scan.
    untouched: usize,
}

impl StackWatch {
    /// A stack of `words` words, not scanned yet.
    pub const fn new(words: usize) -> Self {
        Self {
            words,
            untouched: words,
        }
    }

    /// Scans the still-painted words from the bottom (`read(i)`: word `i`, 0 = lowest
    /// address) up to the first scrubbed one; returns the high-water mark, bytes.
    pub fn scan(&mut self, read: impl Fn(usize) -> u32) -> u32 {
        self.untouched = (0..self.untouched)
            .find(|&i| read(i) != PAINT)
            .unwrap_or(self.untouched);
        self.peak_bytes()
    }

    /// The high-water mark of the last scan, bytes.
    pub fn peak_bytes(&self) -> u32 {
        ((self.words - self.untouched) * 4) as u32
    }

    /// The stack's size, bytes.
    pub fn size_bytes(&self) -> u32 {
        (self.words * 4) as u32
    }
}

/// SCB CFSR bits of a fault during exception entry stacking (ARMv7-M: MMFSR.MSTKERR,
/// BFSR.STKERR).
pub const CFSR_STACKING_ERROR: u32 = (1 << 4) | (1 << 12);
/// SCB CFSR MMFSR.MMARVALID: MMFAR holds the faulting address.
pub const CFSR_MMARVALID: u32 = 1 << 7;

/// Whether a HardFault was a stack overflow: the stack pointer the exception was taken with
/// (`sp`, what the handler finds in MSP) at or below `stack_bottom` plus one exception frame,
/// a stacking error, or a MemManage fault address below the stack's bottom.
pub fn is_overflow(sp: u32, stack_bottom: u32, cfsr: u32, mmfar: u32) -> bool {
    sp < stack_bottom.saturating_add(FP_FRAME_BYTES)
        || cfsr & CFSR_STACKING_ERROR != 0
        || (cfsr & CFSR_MMARVALID != 0 && mmfar < stack_bottom)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_high_water_mark_is_the_lowest_scrubbed_word() {
        // 1024 words; the stack grows down from the top: words 1024-200.. used.
        let mut mem = [PAINT; 1024];
        for w in &mut mem[824..] {
            *w = 0x1234_5678;
        }
        let mut watch = StackWatch::new(mem.len());
        assert_eq!(watch.size_bytes(), 4096);
        assert_eq!(watch.scan(|i| mem[i]), 200 * 4);
        // A deeper call scrubs lower words, even with a painted-looking word among them
        // (a local equal to the paint): the mark follows the lowest scrubbed word.
        mem[500] = 0;
        mem[600] = PAINT;
        assert_eq!(watch.scan(|i| mem[i]), 524 * 4);
        // The stack unwinds and the paint is not restored: the mark stays.
        assert_eq!(watch.scan(|i| mem[i]), 524 * 4);
        // Scans read only the words still painted.
        let reads = std::cell::Cell::new(0);
        watch.scan(|i| {
            reads.set(reads.get() + 1);
            mem[i]
        });
        assert_eq!(reads.get(), 500);
        // Untouched and fully used stacks.
        assert_eq!(StackWatch::new(16).scan(|_| PAINT), 0);
        assert_eq!(StackWatch::new(16).scan(|_| 0), 64);
    }

    #[test]
    fn an_overflow_is_told_from_other_hard_faults() {
        let bottom = 0x2000_0000;
        // The exception frame could not be pushed: SP below the bottom, or a stacking error.
        assert!(is_overflow(bottom - 0x20, bottom, 0, 0));
        assert!(is_overflow(bottom + 0x10, bottom, 0, 0));
        assert!(is_overflow(bottom + 0x400, bottom, 1 << 4, 0));
        assert!(is_overflow(bottom + 0x400, bottom, 1 << 12, 0));
        // A push below the bottom caught by the MPU region (MemManage, address valid).
        assert!(is_overflow(
            bottom + 0x400,
            bottom,
            (1 << 7) | (1 << 1),
            bottom - 4
        ));
        // Other faults with plenty of stack: a bad pointer above, a precise bus fault.
        assert!(!is_overflow(
            bottom + 0x400,
            bottom,
            (1 << 7) | (1 << 1),
            0x2001_0000
        ));
        assert!(!is_overflow(bottom + 0x400, bottom, 1 << 9, 0));
        assert!(!is_overflow(bottom + 0x7F00, bottom, 0, 0));
    }
}
