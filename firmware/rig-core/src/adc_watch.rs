//! The ADC ring's stall: found by the lack of fresh sequences, not by the DMA's enable bit,
//! and the restart that brings the ring back aligned.
//!
//! The brake inputs come from ADC1 (16 ranks per TIM3 trigger) through a circular DMA ring
//! whose reader assumes rank 1 of every sequence at a buffer index that is a multiple of 16
//! (embassy's `read_latest` alignment). The stall that can happen is an ADC overrun
//! (RM0440 "ADC overrun (OVR, OVRMOD)"; embassy leaves OVRMOD = 0): a conversion the DMA did
//! not serve in time sets OVR, the ADC stops making DMA requests until OVR is cleared, and
//! the DMA channel stays enabled. So the step sees no fresh sequence (`ADC_STALE`; a rig
//! run faults after 1 ms) while DMA1 CH1 CCR.EN stays set. (A DMA transfer error, the only
//! thing that clears EN, makes embassy's DMA interrupt panic: the safe state and a reset.)
//!
//! **Detection** ([`AdcWatch::poll`], thread mode, every ms): the step counts the fresh
//! sequences it took; no new one for [`STALL_TICKS`] step ticks while the step runs, or
//! ADC1_ISR.OVR set, is a stall. **Recovery** in two parts. [`stop`], in thread mode with
//! the step running (it sees no fresh sequence meanwhile, as during the stall): stop the
//! conversions (ADSTP, a bounded wait for ADSTART = 0), consume the conversion pending in
//! ADC_DR (read it: EOC and its DMA request clear; else the re-enabled DMA would serve that
//! old request first and put its rank at index 0, shifting every channel by one), clear
//! OVR. Then [`realign`], with the step masked and no wait in it: rewind the DMA to the
//! start of its buffer, reset the ring's reader, start the conversions (rank 1 at the next
//! trigger): the ring is aligned again. Restarts back off from [`BACKOFF_FIRST_MS`] to [`BACKOFF_MAX_MS`] while the stall
//! lasts; each is counted (`RIG_HEALTH` `AdcRestarts`). When sequences come again the step
//! clears `ADC_STALE`'s cause and `ClearFaults` takes a faulted run to `Stopped`.

/// Step ticks without a fresh sequence that make a stall (2 ms: the step takes one each tick).
pub const STALL_TICKS: u32 = 20;
/// Delay before a second restart of the same stall, ms; doubled each time.
pub const BACKOFF_FIRST_MS: u32 = 10;
/// Longest delay between restarts of one stall, ms.
pub const BACKOFF_MAX_MS: u32 = 1000;

/// What the ADC task must do.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum AdcAction {
    /// Nothing.
    None,
    /// Restart the ring ([`stop`] then [`realign`], with the step masked).
    Restart,
}

/// Watches the ring's progress (module doc).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct AdcWatch {
    sequences_seen: u32,
    tick_of_progress: u32,
    /// No restart before this time (ms), while the stall lasts.
    quiet_until_ms: Option<u32>,
    backoff_ms: u32,
    /// Restarts since power-up.
    pub restarts: u32,
}

impl AdcWatch {
    /// A watch that has seen nothing yet.
    pub const fn new() -> Self {
        Self {
            sequences_seen: 0,
            tick_of_progress: 0,
            quiet_until_ms: None,
            backoff_ms: BACKOFF_FIRST_MS,
            restarts: 0,
        }
    }

    /// Takes the step's count of fresh sequences and its tick (both wrapping), the ADC's
    /// overrun flag and the time (ms, wrapping).
    pub fn poll(&mut self, sequences: u32, tick: u32, overrun: bool, now_ms: u32) -> AdcAction {
        if sequences != self.sequences_seen {
            self.sequences_seen = sequences;
            self.tick_of_progress = tick;
            if !overrun {
                self.quiet_until_ms = None;
                self.backoff_ms = BACKOFF_FIRST_MS;
                return AdcAction::None;
            }
        }
        let stalled = overrun || tick.wrapping_sub(self.tick_of_progress) >= STALL_TICKS;
        let quiet = self
            .quiet_until_ms
            .is_some_and(|t| (now_ms.wrapping_sub(t) as i32) < 0);
        if !stalled || quiet {
            return AdcAction::None;
        }
        self.restarts = self.restarts.saturating_add(1);
        self.quiet_until_ms = Some(now_ms.wrapping_add(self.backoff_ms));
        self.backoff_ms = (self.backoff_ms * 2).min(BACKOFF_MAX_MS);
        self.tick_of_progress = tick;
        AdcAction::Restart
    }
}

/// The ADC as [`stop`] drives it (thread mode, the step running).
pub trait AdcConverter {
    /// ADSTP, then waits (bounded) until ADSTART reads 0; `false` if it did not stop.
    fn stop_conversions(&mut self) -> bool;
    /// Reads ADC_DR (the value is discarded) and clears EOC/EOS: no DMA request is left
    /// pending for a conversion made before the stop.
    fn discard_pending_conversion(&mut self);
    /// Clears ADC_ISR.OVR (write 1): the ADC makes DMA requests again.
    fn clear_overrun(&mut self);
}

/// The DMA ring as [`realign`] drives it (the step masked: register writes only, no wait).
pub trait AdcRing {
    /// Disables the DMA channel, reloads its count with the buffer's length and enables it:
    /// the next sample lands at index 0.
    fn rewind_dma(&mut self);
    /// Resets the ring's reader to the DMA's position (embassy `RingBufferedAdc::clear`).
    fn reset_reader(&mut self);
    /// ADSTART: the next trigger converts the sequence from rank 1.
    fn start_conversions(&mut self);
}

/// Why a restart did not happen.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct AdcWouldNotStop;

/// The first part of a restart (module doc), in thread mode: stop, consume the pending
/// conversion, clear the overrun. Nothing the step owns is touched.
pub fn stop(a: &mut impl AdcConverter) -> Result<(), AdcWouldNotStop> {
    if !a.stop_conversions() {
        return Err(AdcWouldNotStop);
    }
    a.discard_pending_conversion();
    a.clear_overrun();
    Ok(())
}

/// The second part, with the step masked (register writes only): rewind the DMA, reset the
/// reader, start. Only after [`stop`] succeeded.
pub fn realign(r: &mut impl AdcRing) {
    r.rewind_dma();
    r.reset_reader();
    r.start_conversions();
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sensor::ADC_SEQUENCE_LEN;

    const RING: usize = 4 * ADC_SEQUENCE_LEN;

    /// ADC1 with OVRMOD = 0 and a circular DMA ring (RM0440: an unserved request sets OVR;
    /// while OVR is set conversions go on, their data is discarded and no DMA request is
    /// made, DR keeping the unread conversion and its request; ADSTP resets the sequence to
    /// rank 1; an enabled DMA channel serves a pending request at once). Each sample is
    /// tagged with its rank.
    struct Model {
        running: bool,
        ovr: bool,
        /// The rank of the conversion in DR whose DMA request is not served yet.
        dr_pending: Option<u8>,
        buf: [Option<u8>; RING],
        dma_pos: usize,
        /// The DMA misses the request of this rank once (bus busy): an overrun.
        miss_rank: Option<u8>,
        reader_at: usize,
        stops_ok: bool,
    }

    impl Model {
        fn new() -> Self {
            Self {
                running: true,
                ovr: false,
                dr_pending: None,
                buf: [None; RING],
                dma_pos: 0,
                miss_rank: None,
                reader_at: 0,
                stops_ok: true,
            }
        }
        /// One TIM3 trigger: the 16 ranks. Returns whether a whole sequence reached the ring.
        fn trigger(&mut self) -> bool {
            if !self.running {
                return false;
            }
            let mut moved = 0;
            for rank in 0..ADC_SEQUENCE_LEN as u8 {
                if self.ovr {
                    continue;
                }
                if self.miss_rank.take_if(|r| *r == rank).is_some() {
                    // Unserved: the next end of conversion finds DR unread.
                    self.dr_pending = Some(rank);
                    self.ovr = true;
                    continue;
                }
                self.buf[self.dma_pos] = Some(rank);
                self.dma_pos = (self.dma_pos + 1) % RING;
                moved += 1;
            }
            moved == ADC_SEQUENCE_LEN
        }
        /// Whether every sample's rank matches its index (what the reader assumes).
        fn aligned_since(&self, from: usize) -> bool {
            (from..self.dma_pos).all(|i| self.buf[i] == Some((i % ADC_SEQUENCE_LEN) as u8))
        }
    }

    impl AdcConverter for Model {
        fn stop_conversions(&mut self) -> bool {
            self.running = !self.stops_ok;
            self.stops_ok
        }
        fn discard_pending_conversion(&mut self) {
            self.dr_pending = None;
        }
        fn clear_overrun(&mut self) {
            self.ovr = false;
        }
    }

    impl AdcRing for Model {
        fn rewind_dma(&mut self) {
            self.dma_pos = 0;
            self.buf = [None; RING];
            // Enabled again: a request still pending is served at once.
            if let Some(rank) = self.dr_pending.take() {
                self.buf[0] = Some(rank);
                self.dma_pos = 1;
            }
        }
        fn reset_reader(&mut self) {
            self.reader_at = self.dma_pos;
        }
        fn start_conversions(&mut self) {
            self.running = true;
        }
    }

    /// Both parts of a restart, as the board runs them.
    fn restart(m: &mut Model) -> Result<(), AdcWouldNotStop> {
        stop(m)?;
        realign(m);
        Ok(())
    }

    /// Runs the step (a trigger per tick) and the watch (every 10 ticks = 1 ms) for `ticks`;
    /// returns the ticks with a fresh sequence and whether a restart was asked.
    fn run(m: &mut Model, w: &mut AdcWatch, tick: &mut u32, seqs: &mut u32, ticks: u32) -> bool {
        let mut restarted = false;
        for _ in 0..ticks {
            *tick += 1;
            if m.trigger() {
                *seqs += 1;
            }
            if *tick % 10 == 0 && w.poll(*seqs, *tick, m.ovr, *tick / 10) == AdcAction::Restart {
                restart(m).unwrap();
                restarted = true;
            }
        }
        restarted
    }

    #[test]
    fn an_overrun_is_found_within_2_ms_and_the_ring_restarts_aligned() {
        let (mut m, mut w, mut tick, mut seqs) = (Model::new(), AdcWatch::new(), 0, 0);
        assert!(
            !run(&mut m, &mut w, &mut tick, &mut seqs, 1000),
            "no restart while fine"
        );
        assert!(m.aligned_since(0));
        m.miss_rank = Some(7);
        let before = seqs;
        // The overrun flag is seen at the next poll, at most 1 ms later.
        assert!(run(&mut m, &mut w, &mut tick, &mut seqs, 10));
        assert_eq!(w.restarts, 1);
        assert!(run(&mut m, &mut w, &mut tick, &mut seqs, 500) == false);
        assert!(seqs > before + 480, "sequences again: {}", seqs - before);
        assert!(m.aligned_since(0), "rank 1 at a multiple of 16 again");
    }

    #[test]
    fn a_silent_stall_is_found_from_progress_alone() {
        // Conversions stop with OVR clear (a lost trigger): found after 20 ticks.
        let (mut m, mut w, mut tick, mut seqs) = (Model::new(), AdcWatch::new(), 0, 0);
        run(&mut m, &mut w, &mut tick, &mut seqs, 100);
        m.running = false;
        let mut when = None;
        for k in 1..=40 {
            tick += 1;
            assert!(!m.trigger());
            if tick % 10 == 0 && w.poll(seqs, tick, false, tick / 10) == AdcAction::Restart {
                when = Some(k);
                break;
            }
        }
        assert_eq!(when, Some(20));
    }

    #[test]
    fn a_restart_without_the_rewind_would_misalign_the_ring() {
        // Negative control: stop, clear, start (what a plain `start()` does): rank 1 lands
        // where the DMA stopped, at index 7 of a sequence.
        let mut m = Model::new();
        for _ in 0..3 {
            m.trigger();
        }
        m.miss_rank = Some(7);
        m.trigger();
        let at = m.dma_pos;
        m.stop_conversions();
        m.clear_overrun();
        m.start_conversions();
        m.trigger();
        // Rank 1 of the new sequence sits at index 55, not at a multiple of 16.
        assert_eq!((at, m.buf[at]), (55, Some(0)));
        assert_ne!(at % ADC_SEQUENCE_LEN, 0);
    }

    #[test]
    fn a_conversion_left_pending_in_dr_would_shift_every_channel() {
        // Negative control: the same restart without consuming DR: the re-enabled DMA
        // serves the old request first: the missed rank lands at index 0 and every rank
        // of the next sequence one place late.
        let mut m = Model::new();
        m.trigger();
        m.miss_rank = Some(7);
        m.trigger();
        assert!(m.stop_conversions());
        m.clear_overrun();
        realign(&mut m);
        m.trigger();
        assert_eq!(m.buf[0], Some(7));
        assert_eq!(m.buf[1], Some(0));
        assert!(!m.aligned_since(0));
        // With `stop` (DR consumed) the ring is aligned.
        let mut m = Model::new();
        m.trigger();
        m.miss_rank = Some(7);
        m.trigger();
        restart(&mut m).unwrap();
        m.trigger();
        assert!(m.dma_pos == ADC_SEQUENCE_LEN && m.aligned_since(0));
    }

    #[test]
    fn restarts_back_off_while_the_stall_lasts_and_a_stuck_adc_is_reported() {
        let mut w = AdcWatch::new();
        let mut at = std::vec::Vec::new();
        for ms in 0..3000u32 {
            if w.poll(0, ms * 10, false, ms) == AdcAction::Restart {
                at.push(ms);
            }
        }
        // The first after 2 ms, then 10, 20, 40, ... ms apart, at most every second.
        assert_eq!(at, [2, 12, 32, 72, 152, 312, 632, 1272, 2272]);
        assert_eq!(w.restarts as usize, at.len());
        let mut m = Model::new();
        m.stops_ok = false;
        assert_eq!(restart(&mut m), Err(AdcWouldNotStop));
    }
}
