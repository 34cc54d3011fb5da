//! Interrupt priorities, and the critical section of the data the step shares with the
//! rest: a priority ceiling (BASEPRI), not a global interrupt mask.
//!
//! | priority | what |
//! |---|---|
//! | P0 | nothing: kept free, so that nothing can delay a future input above the step |
//! | P1 | TIM3 update: the 10 kHz step ([`STEP_PRIORITY`]) |
//! | P3 | embassy's interrupts: TIM2 (time driver), FDCAN1 IT0/IT1, DMA1 (ADC ring) |
//! | thread | the embassy executor: CAN transmit/receive, bus supervision, telemetry logging, button, LED |
//!
//! The step reaches the other contexts only through the queues of [`StepChannel`]. Their
//! lock raises BASEPRI to the step's priority (RTIC's stack resource policy): while a task
//! copies a frame or a telemetry record in or out, the step may wait at most that copy
//! (~1 us); interrupts above the ceiling are never masked. Inside the step the lock changes
//! nothing (BASEPRI_MAX never lowers the mask, and nothing else runs at P1).
//!
//! Invariant that makes [`StepCeiling`] sound: no code running above the ceiling (P0)
//! uses these queues. embassy's own drivers keep their short `critical_section` (PRIMASK)
//! blocks; the step uses none of them.

use embassy_stm32::interrupt::{self, InterruptExt, Priority};
use embassy_sync::blocking_mutex::raw::RawMutex;
use embassy_sync::channel::Channel;

/// The step's priority: the ceiling of everything it shares.
pub const STEP_PRIORITY: Priority = Priority::P1;
/// Everything embassy runs in interrupts.
pub const BACKGROUND_PRIORITY: Priority = Priority::P3;

/// A raw mutex that masks the step and everything below it, nothing above.
pub struct StepCeiling(());

// SAFETY: while `lock` runs its closure, BASEPRI masks every interrupt at or below the
// step's priority, and thread mode cannot preempt; the only contexts that use these
// mutexes are thread mode, P3 interrupts and the step (module invariant), so no other
// user can run until the closure returns.
unsafe impl RawMutex for StepCeiling {
    const INIT: Self = StepCeiling(());

    #[unsafe(link_section = ".ccm_text.step_ceiling")]
    fn lock<R>(&self, f: impl FnOnce() -> R) -> R {
        let before = cortex_m::register::basepri::read();
        // BASEPRI_MAX only raises the mask (cortex-m register::basepri_max).
        cortex_m::register::basepri_max::write(STEP_PRIORITY as u8);
        let r = f();
        // SAFETY: restores the mask this context had; the closure did not lower it.
        unsafe { cortex_m::register::basepri::write(before) };
        r
    }
}

/// A queue between the step and the tasks.
pub type StepChannel<T, const N: usize> = Channel<StepCeiling, T, N>;

/// Sets the priorities of every interrupt embassy enables (they come up at P0, above the
/// step) and of the step. Call right after `embassy_stm32::init`, before any driver.
pub fn set_interrupt_priorities() {
    for irq in [
        interrupt::TIM2,
        interrupt::FDCAN1_IT0,
        interrupt::FDCAN1_IT1,
        interrupt::DMA1_CHANNEL1,
    ] {
        irq.set_priority(BACKGROUND_PRIORITY);
    }
    interrupt::TIM3.set_priority(STEP_PRIORITY);
}
