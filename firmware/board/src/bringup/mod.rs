//! The bring-up self-test (`cargo board-run --features bringup`): what a bare NUCLEO-G474RE
//! can check alone, one check a function, each printing one `PASS`/`FAIL` line over defmt,
//! then a summary. The pass/fail rules are `hils_rig_core::bringup` (host-tested); docs/rig.md
//! "First flash" lists the expected output. The checks measure what the application runs:
//! SYSCLK against an independent clock (LSE, else LSI), the pulse timer and its break, and
//! last the application itself (`crate::app`, CAN in internal loopback, the self-test paper
//! scenario) with its own step in TIM3 under its real interrupt load. No check masks
//! interrupts for longer than embassy's 16-bit time driver allows (32.8 ms).
//!
//! Wiring: one jumper wire from D7 (PA8, pulse train 1, TIM1_CH1) to D12 (PA6, TIM16_CH1)
//! for the pulse check. Nothing else (no transceiver: FDCAN runs in internal loopback).

mod adc;
mod clock;
mod fdcan;
mod pulse;
mod reference;
mod step_time;
mod tim3;

use embassy_executor::Spawner;
use embassy_stm32::Peripherals;

/// Counts the checks.
#[derive(Default)]
struct Tally {
    pass: u32,
    fail: u32,
}

impl Tally {
    fn note(&mut self, pass: bool) {
        if pass {
            self.pass += 1;
        } else {
            self.fail += 1;
        }
    }
}

pub async fn run(spawner: Spawner, p: Peripherals) {
    defmt::println!("bringup: start (jumper D7-D12 for the pulse check)");
    let mut t = Tally::default();
    t.note(clock::clock_tree());
    t.note(clock::ccm_code());
    // SAFETY (each clone below): the check's drivers are dropped before the application
    // takes the same peripheral from `p`; nothing runs concurrently with a check.
    t.note(reference::sysclk_against_reference(unsafe { p.TIM16.clone_unchecked() }).await);
    t.note(tim3::step_timer_period(unsafe { p.TIM3.clone_unchecked() }));
    t.note(
        fdcan::loopback(
            unsafe { p.FDCAN1.clone_unchecked() },
            unsafe { p.PA11.clone_unchecked() },
            unsafe { p.PA12.clone_unchecked() },
        )
        .await,
    );
    t.note(adc::vrefint_and_temperature(unsafe { p.ADC1.clone_unchecked() }).await);
    t.note(
        pulse::pulse_through_jumper(
            unsafe { p.TIM1.clone_unchecked() },
            unsafe { p.PA8.clone_unchecked() },
            unsafe { p.TIM16.clone_unchecked() },
            unsafe { p.PA6.clone_unchecked() },
        )
        .await,
    );
    t.note(step_time::application_step(spawner, p).await);
    defmt::println!("bringup: {=u32} PASS, {=u32} FAIL", t.pass, t.fail);
}

/// The `PASS`/`FAIL` word of a line.
fn verdict(pass: bool) -> &'static str {
    if pass { "PASS" } else { "FAIL" }
}
