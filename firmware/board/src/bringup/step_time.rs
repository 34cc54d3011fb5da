//! The step time of 1000 paper-scenario steps, timed with the cycle counter.

use cortex_m::peripheral::DWT;
use hils_plant::FrictionModel;
use hils_rig_core::can::{ClassicFrame, Command};
use hils_rig_core::hw::{RigIo, TelemetryEvent};
use hils_rig_core::pulse::PulseRegisters;
use hils_rig_core::rig::{Rig, RigConfig};
use hils_rig_core::sensor::ADC_SEQUENCE_LEN;
use hils_rig_core::timing::{StepTiming, cycles_to_us};
use static_cell::StaticCell;

use super::verdict;
use crate::step::{CPU_HZ, rig_step};

const STEPS: u32 = 1000;

/// The board as the step sees it, minus the hardware: live-zero ADC counts, queues that
/// always take.
struct BenchIo {
    tick: u32,
}

impl RigIo for BenchIo {
    type Frame = ClassicFrame;
    fn adc_sequence(&mut self) -> Option<[u16; ADC_SEQUENCE_LEN]> {
        self.tick = self.tick.wrapping_add(1);
        let t = self.tick as usize;
        Some(core::array::from_fn(|rank| {
            410 + ((t * 7 + rank * 13) % 5) as u16
        }))
    }
    fn set_pulse(&mut self, _: usize, _: &PulseRegisters) {}
    fn queue_frame(&mut self, _: ClassicFrame) -> bool {
        true
    }
    fn queue_telemetry(&mut self, _: &TelemetryEvent) -> bool {
        true
    }
}

static RIG: StaticCell<Rig> = StaticCell::new();

/// The self-test paper scenario (150 km/h, wet, EB) started in thread mode, then 1000
/// steps through the same function the step interrupt runs (`step::rig_step`, in CCM
/// SRAM), each timed with interrupts masked. Passes with no step reaching the 100 us period.
pub fn paper_steps() -> bool {
    let rig = RIG.init(Rig::new(RigConfig::nucleo_g474re()));
    let started = rig
        .command(Command::paper_self_test(FrictionModel::Variable))
        .and_then(|_| rig.build_pending())
        .is_ok();
    let mut io = BenchIo { tick: 0 };
    let mut timing = StepTiming::new(CPU_HZ, hils_rig_core::STEP_RATE_HZ);
    for _ in 0..STEPS {
        let (entry, exit) = cortex_m::interrupt::free(|_| {
            let entry = DWT::cycle_count();
            rig_step(rig, &mut io);
            (entry, DWT::cycle_count())
        });
        timing.record(entry, exit, false);
    }
    let max = timing.run_max_cycles;
    let mean = timing.run_mean_cycles();
    let pass = started && rig.run_steps() == STEPS && timing.overruns == 0;
    defmt::println!(
        "{=str} step: {=u32} paper-scenario steps, max {=f32} us ({=u32} cycles, {=u32} % of the 100 us period), mean {=f32} us; overruns {=u32}",
        verdict(pass),
        rig.run_steps(),
        cycles_to_us(max, CPU_HZ),
        max,
        100 * max / timing.period_cycles,
        cycles_to_us(mean, CPU_HZ),
        timing.overruns
    );
    pass
}
