//! Whether thread mode is alive, for the watchdog.
//!
//! The step runs in an interrupt, so a step that feeds the independent watchdog on every
//! tick keeps a board alive whose thread mode is dead (a task stuck in a loop, the
//! executor starved, a deadlock): CAN transmit, bus supervision and logging would stop
//! while the pulse trains go on. So a thread-mode task (the bus task, every 10 ms) stamps
//! a heartbeat with the step tick, and the step feeds the watchdog only while that beat is
//! at most [`HEARTBEAT_MAX_AGE_TICKS`] old: a dead thread mode resets the board within
//! that age plus the watchdog's timeout.

use crate::STEP_RATE_HZ;

/// Oldest heartbeat that still counts, step ticks: 50 ms (five of the bus task's 10 ms
/// periods).
pub const HEARTBEAT_MAX_AGE_TICKS: u32 = 50 * STEP_RATE_HZ / 1000;

/// Whether a heartbeat stamped at step tick `beat_tick` is fresh at `now_tick` (wrapping
/// tick counter; a beat is never stamped after `now_tick`).
pub fn thread_alive(now_tick: u32, beat_tick: u32) -> bool {
    now_tick.wrapping_sub(beat_tick) <= HEARTBEAT_MAX_AGE_TICKS
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A model of the board: the bus task beats every 100 ticks until thread mode dies;
    /// the step feeds the watchdog (10 ms = 100 ticks) while the beat is fresh. The board
    /// must keep running while thread mode lives and reset within 50 ms + 10 ms of its
    /// last beat, across the tick counter's wrap.
    #[test]
    fn a_dead_thread_mode_resets_the_board_in_bounded_time() {
        const WATCHDOG_TICKS: u32 = 100;
        for start in [0u32, 12_345, u32::MAX - 2_000] {
            for dies_after in [0u32, 1_000, 5_050] {
                let mut beat = start;
                let mut last_feed = start;
                let mut reset_at = None;
                for k in 0..20_000u32 {
                    let now = start.wrapping_add(k);
                    if k <= dies_after && k % 100 == 0 {
                        beat = now;
                    }
                    if thread_alive(now, beat) {
                        last_feed = now;
                    }
                    if now.wrapping_sub(last_feed) > WATCHDOG_TICKS {
                        reset_at = Some(k);
                        break;
                    }
                }
                let last_beat = dies_after - dies_after % 100;
                let k = reset_at.expect("a dead thread mode must reset the board");
                assert!(k > dies_after, "no reset while thread mode lives");
                assert!(
                    k <= last_beat + HEARTBEAT_MAX_AGE_TICKS + WATCHDOG_TICKS + 1,
                    "reset at {k}, last beat {last_beat}"
                );
            }
        }
    }

    #[test]
    fn fresh_within_50_ms_and_across_the_wrap() {
        assert!(thread_alive(1000, 1000));
        assert!(thread_alive(1500, 1000));
        assert!(!thread_alive(1501, 1000));
        assert!(thread_alive(10, u32::MAX - 100));
        assert!(!thread_alive(500, u32::MAX - 100));
    }
}
