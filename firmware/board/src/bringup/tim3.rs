//! The step timer's period against the cycle counter.

use cortex_m::peripheral::DWT;
use embassy_stm32::Peri;
use embassy_stm32::peripherals::TIM3;
use embassy_stm32::timer::low_level::Timer;
use hils_rig_core::STEP_RATE_HZ;
use hils_rig_core::bringup::period_matches;

use super::verdict;
use crate::step::{CPU_HZ, configure_step_timer};

const PERIODS: u32 = 1000;

/// TIM3 configured as in the application (PSC 0, ARR 16 999, CCR4 8500) runs 1000 periods
/// of 17 000 cycles: 10 kHz. Polled with interrupts masked (100 ms).
pub fn step_timer_period(tim3: Peri<'static, TIM3>) -> bool {
    let t = Timer::new(tim3);
    configure_step_timer(&t);
    let regs = embassy_stm32::pac::TIM3;
    regs.sr().modify(|w| w.set_uif(false));
    t.start();
    let cycles = cortex_m::interrupt::free(|_| {
        let wait = || {
            while !regs.sr().read().uif() {}
            regs.sr().modify(|w| w.set_uif(false));
            DWT::cycle_count()
        };
        let first = wait();
        let mut last = first;
        for _ in 0..PERIODS {
            last = wait();
        }
        last.wrapping_sub(first) as u64
    });
    t.stop();
    let arr = regs.arr().read().arr();
    let ccr4 = regs.ccr(3).read().ccr();
    let pass = period_matches(cycles, PERIODS, CPU_HZ, STEP_RATE_HZ, 10);
    defmt::println!(
        "{=str} tim3: {=u32} periods in {=u64} cycles = {=f32} Hz (PSC {=u16}, ARR {=u32}, CCR4 {=u32})",
        verdict(pass),
        PERIODS,
        cycles,
        CPU_HZ as f32 * PERIODS as f32 / cycles as f32,
        regs.psc().read(),
        arr as u32,
        ccr4 as u32
    );
    pass
}
