//! The application's own step, timed by the application: the rig application starts as on
//! the rig (the step in TIM3 at P1 from CCM SRAM, the ADC ring, FDCAN in internal loopback,
//! the CAN, logging and builder tasks, the time driver), the self-test paper scenario runs,
//! and after 3 s the rig's own step timing is read (the DWT figures `RIG_DIAG` reports).

use embassy_executor::Spawner;
use embassy_stm32::Peripherals;
use embassy_time::Timer;
use hils_rig_core::can::RigState;
use hils_rig_core::timing::cycles_to_us;

use super::verdict;
use crate::app::{self, Image};
use crate::step::{CPU_HZ, REAL_TIME};

/// How long the paper scenario runs before the figures are read, s.
const RUN_S: u64 = 3;

/// Passes when the run is stepping, no step reached the 100 us period (no overrun, no
/// missed tick) over the 3 s.
pub async fn application_step(spawner: Spawner, p: Peripherals) -> bool {
    app::run(spawner, p, Image::Bringup).await;
    Timer::after_secs(RUN_S).await;
    // SAFETY: thread mode; a few loads under the step's ceiling.
    let figures = unsafe {
        REAL_TIME.with_step_masked(|rt| {
            let t = rt.rig.timing();
            (
                t.run_max_cycles,
                t.run_mean_cycles(),
                t.overruns,
                t.missed_ticks,
                t.period_cycles,
                rt.rig.run_steps(),
                rt.rig.state(),
            )
        })
    };
    let Some((max, mean, overruns, missed, period, steps, state)) = figures else {
        defmt::println!("FAIL step: the application's step never ran");
        return false;
    };
    let pass = state == RigState::Running
        && steps >= (RUN_S as u32 - 1) * hils_rig_core::STEP_RATE_HZ
        && overruns == 0
        && missed == 0
        && max < period;
    defmt::println!(
        "{=str} step: the application's step in TIM3 (paper scenario, {=u32} steps): max {=f32} us ({=u32} cycles, {=u32} % of the 100 us period), mean {=f32} us; overruns {=u32}, missed ticks {=u32}",
        verdict(pass),
        steps,
        cycles_to_us(max, CPU_HZ),
        max,
        100 * max / period.max(1),
        cycles_to_us(mean, CPU_HZ),
        overruns,
        missed
    );
    pass
}
