//! The bring-up self-test (`cargo board-run --features bringup`): what a bare NUCLEO-G474RE
//! can check alone, one check a function, each printing one `PASS`/`FAIL` line over defmt,
//! then a summary. The pass/fail rules are `hils_rig_core::bringup` (host-tested); docs/rig.md
//! "First flash" lists the expected output. The rig application does not start in this image.
//!
//! Wiring: one jumper wire from D7 (PA8, pulse train 1, TIM1_CH1) to D12 (PA6, TIM16_CH1)
//! for the pulse check. Nothing else (no transceiver: FDCAN runs in internal loopback).

mod adc;
mod clock;
mod fdcan;
mod pulse;
mod step_time;
mod tim3;

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

pub async fn run(p: Peripherals) {
    defmt::println!("bringup: start (jumper D7-D12 for the pulse check)");
    let mut t = Tally::default();
    t.note(clock::clock_tree());
    t.note(clock::ccm_code());
    t.note(tim3::step_timer_period(p.TIM3));
    t.note(fdcan::loopback(p.FDCAN1, p.PA11, p.PA12).await);
    t.note(adc::vrefint_and_temperature(p.ADC1).await);
    t.note(pulse::pulse_through_jumper(p.TIM1, p.PA8, p.TIM16, p.PA6).await);
    t.note(step_time::paper_steps());
    defmt::println!("bringup: {=u32} PASS, {=u32} FAIL", t.pass, t.fail);
}

/// The `PASS`/`FAIL` word of a line.
fn verdict(pass: bool) -> &'static str {
    if pass { "PASS" } else { "FAIL" }
}
