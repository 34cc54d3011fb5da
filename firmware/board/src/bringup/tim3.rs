//! The step timer's period against the cycle counter.

use cortex_m::peripheral::DWT;
use embassy_stm32::Peri;
use embassy_stm32::peripherals::TIM3;
use embassy_stm32::timer::low_level::Timer;
use hils_rig_core::STEP_RATE_HZ;
use hils_rig_core::bringup::period_matches;

use super::verdict;
use crate::step::{CPU_HZ, configure_step_timer};

/// Periods measured, in chunks of [`CHUNK`] (10 ms with interrupts masked each: embassy's
/// 16-bit time driver must be served every 32.8 ms).
const CHUNKS: u32 = 10;
const CHUNK: u32 = 100;

/// TIM3 configured as in the application (PSC 0, ARR 16 999, CCR4 8500) runs 1000 periods
/// of 17 000 cycles: 10 kHz. Each chunk of 100 periods is polled with interrupts masked
/// (10 ms), between chunks the interrupts run.
pub fn step_timer_period(tim3: Peri<'static, TIM3>) -> bool {
    let t = Timer::new(tim3);
    configure_step_timer(&t);
    let regs = embassy_stm32::pac::TIM3;
    regs.sr().modify(|w| w.set_uif(false));
    t.start();
    let mut cycles = 0u64;
    for _ in 0..CHUNKS {
        cycles += cortex_m::interrupt::free(|_| {
            let wait = || {
                while !regs.sr().read().uif() {}
                regs.sr().modify(|w| w.set_uif(false));
                DWT::cycle_count()
            };
            let first = wait();
            let mut last = first;
            for _ in 0..CHUNK {
                last = wait();
            }
            last.wrapping_sub(first) as u64
        });
    }
    t.stop();
    let periods = CHUNKS * CHUNK;
    let arr = regs.arr().read().arr();
    let ccr4 = regs.ccr(3).read().ccr();
    let pass = period_matches(cycles, periods, CPU_HZ, STEP_RATE_HZ, 10);
    defmt::println!(
        "{=str} tim3: {=u32} periods in {=u64} cycles = {=f32} Hz (PSC {=u16}, ARR {=u32}, CCR4 {=u32})",
        verdict(pass),
        periods,
        cycles,
        CPU_HZ as f32 * periods as f32 / cycles as f32,
        regs.psc().read(),
        arr as u32,
        ccr4 as u32
    );
    pass
}
