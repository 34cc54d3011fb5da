//! The 10 kHz step: TIM3's update interrupt at [`crate::ceiling::STEP_PRIORITY`], running
//! from CCM SRAM, owning the rig and its peripherals (handed over once from `main`), talking
//! to the tasks only through ceiling-locked queues and atomics, feeding the watchdog.

use core::sync::atomic::Ordering;

use crate::sim_store::BoardSim;
use cortex_m::peripheral::DWT;
use cortex_m_rt::interrupt;
use embassy_stm32::adc::RingBufferedAdc;
use embassy_stm32::can::Frame;
use embassy_stm32::interrupt::{self};
use embassy_stm32::pac;
use embassy_stm32::peripherals::{ADC1, IWDG, TIM1, TIM8, TIM15, TIM20};
use embassy_stm32::wdg::IndependentWatchdog;
use hils_rig_core::can_tx::QueuedFrame;
use hils_rig_core::heartbeat::thread_alive;
use hils_rig_core::hw::{RigIo, TelemetryEvent};
use hils_rig_core::pulse::PulseRegisters;
use hils_rig_core::rig::CommandError;
use hils_rig_core::rig::{BoardHealth, Rig, SimStore};
use hils_rig_core::sensor::ADC_SEQUENCE_LEN;

use crate::handoff::Handoff;
use crate::pulse::PulseOut;
use crate::shared::{
    ADC_RESTARTS, ADC_SEQUENCES, BUS_CLEAR, BUS_STATE, CAN_RX, CAN_TX, CAN_TX_DROPS, LOCAL_CMD,
    RIG_STATE, RX_LOST, STACK_PEAK, STEP_EVENTS, STEP_TICKS, StepEvent, TELEMETRY, TELEMETRY_DROPS,
    THREAD_HEARTBEAT,
};
use crate::shared::{BUILT, START_REQUESTS};

/// CPU and timer clock, Hz.
pub const CPU_HZ: u32 = crate::clock::SYSCLK_HZ;
/// Step period in timer counts (10 kHz at 170 MHz).
pub const STEP_COUNTS: u16 = (CPU_HZ / hils_rig_core::STEP_RATE_HZ) as u16;
/// Watchdog timeout, us: 100 steps. LSI 32 kHz nominal, /4, reload 79 (embassy wdg).
pub const WATCHDOG_TIMEOUT_US: u32 = 10_000;

/// The peripherals the step uses.
pub struct BoardIo {
    pub adc: RingBufferedAdc<'static, ADC1>,
    pub adc_buf: [u16; ADC_SEQUENCE_LEN],
    pub ws1: PulseOut<TIM1>,
    pub ws2: PulseOut<TIM15>,
    pub ws3: PulseOut<TIM8>,
    pub ws4: PulseOut<TIM20>,
    /// The tick of the step in progress (stamps the queued frames).
    pub tick: u32,
}

impl RigIo for BoardIo {
    type Frame = Frame;

    #[unsafe(link_section = ".ccm_text.board_io")]
    fn adc_sequence(&mut self) -> Option<[u16; ADC_SEQUENCE_LEN]> {
        // embassy's `read_latest` restarts a stopped ring (DMA and ADC set-up) itself: not
        // in the step. A stopped ring (DMA1 channel 1 CCR.EN clear: only a DMA transfer
        // error, whose interrupt then panics into the safe state) is a stale tick. The
        // stall that keeps EN set (an ADC overrun) shows as no fresh sequence: the ADC
        // task watches ADC_SEQUENCES and restarts the ring (`hils_rig_core::adc_watch`).
        if !pac::DMA1.ch(0).cr().read().en() {
            return None;
        }
        let n = self.adc.read_latest(&mut self.adc_buf);
        if n != ADC_SEQUENCE_LEN {
            return None;
        }
        ADC_SEQUENCES.store(
            ADC_SEQUENCES.load(Ordering::Relaxed).wrapping_add(1),
            Ordering::Relaxed,
        );
        Some(self.adc_buf)
    }

    #[unsafe(link_section = ".ccm_text.board_io")]
    fn set_pulse(&mut self, wheelset: usize, r: &PulseRegisters) {
        match wheelset {
            0 => self.ws1.write(r),
            1 => self.ws2.write(r),
            2 => self.ws3.write(r),
            _ => self.ws4.write(r),
        }
    }

    #[unsafe(link_section = ".ccm_text.board_io")]
    fn queue_frame(&mut self, frame: Frame) -> bool {
        CAN_TX
            .try_send(QueuedFrame {
                frame,
                tick: self.tick,
            })
            .is_ok()
    }

    #[unsafe(link_section = ".ccm_text.board_io")]
    fn queue_telemetry(&mut self, event: &TelemetryEvent) -> bool {
        TELEMETRY.try_send(*event).is_ok()
    }
}

/// The independent watchdog, started by the first step and fed by every step while thread
/// mode's heartbeat is fresh.
pub struct Watchdog {
    iwdg: IndependentWatchdog<'static, IWDG>,
    started: bool,
}

impl Watchdog {
    pub fn new(iwdg: IndependentWatchdog<'static, IWDG>) -> Self {
        Self {
            iwdg,
            started: false,
        }
    }

    #[inline(always)]
    fn feed(&mut self) {
        if !self.started {
            self.iwdg.unleash();
            self.started = true;
        }
        self.iwdg.pet();
    }
}

/// The step's rig: its simulation in the static store the builder fills in place.
pub type StepRig = Rig<BoardSim>;

/// Everything the step owns.
pub struct RealTime {
    pub rig: StepRig,
    pub io: BoardIo,
    pub watchdog: Watchdog,
    /// Drop counters as last passed to the rig.
    pub seen_drops: (u32, u32),
}

/// The step's state, built in `main` and handed over once.
pub static REAL_TIME: Handoff<RealTime, 1> = Handoff::new();

/// The rig's step (a function of its own: `size.sh` checks its frame and placement).
#[unsafe(link_section = ".ccm_text.rig_step")]
#[inline(never)]
pub fn rig_step<S: SimStore, IO: RigIo>(rig: &mut Rig<S>, io: &mut IO) {
    rig.step(io);
}

#[interrupt]
fn TIM3() {
    step_tick();
}

/// One tick: commands, bus state, drops, the step, timing, watchdog.
#[unsafe(link_section = ".ccm_text.step_tick")]
#[inline(never)]
fn step_tick() {
    let entry = DWT::cycle_count();
    // TIMx_SR bits are rc_w0: a read-modify-write would also clear a flag set between the
    // read and the write (e.g. CC4IF). Write ones everywhere but UIF (as ST's HAL
    // `__HAL_TIM_CLEAR_FLAG` does: SR = ~flag).
    let mut clear_uif = pac::timer::regs::SrGp16(u32::MAX);
    clear_uif.set_uif(false);
    pac::TIM3.sr().write_value(clear_uif);
    let tick = STEP_TICKS.load(Ordering::Relaxed).wrapping_add(1);
    STEP_TICKS.store(tick, Ordering::Relaxed);
    // SAFETY: this is the step interrupt, the only caller; the reference ends with the call.
    let Some(rt) = (unsafe { REAL_TIME.step_value() }) else {
        return;
    };
    take_commands(&mut rt.rig);
    hand_over_runs(&mut rt.rig);
    if rt.rig.take_bus_clear() {
        BUS_CLEAR.store(true, Ordering::Relaxed);
    }
    let bus = BUS_STATE.load(Ordering::Relaxed);
    rt.rig.set_bus(bus & 1 != 0, bus & 2 != 0, bus >> 8);
    let drops = (
        TELEMETRY_DROPS.load(Ordering::Relaxed),
        CAN_TX_DROPS.load(Ordering::Relaxed),
    );
    rt.rig
        .note_downstream_drops(drops.0 != rt.seen_drops.0, drops.1 != rt.seen_drops.1);
    rt.seen_drops = drops;
    rt.rig.set_board_health(BoardHealth {
        stack_peak_bytes: STACK_PEAK.load(Ordering::Relaxed),
        stack_size_bytes: crate::fault::stack_bytes(),
        rx_lost: RX_LOST.load(Ordering::Relaxed),
        adc_restarts: ADC_RESTARTS.load(Ordering::Relaxed),
        fault_resets: crate::fault::FAULT_RESETS.load(Ordering::Relaxed),
    });
    rt.io.tick = tick;
    rig_step(&mut rt.rig, &mut rt.io);
    // The interface stage's output enable follows the arming gate, as every output does.
    crate::pulse::set_output_enable(rt.rig.controller_outputs_live());
    RIG_STATE.store(rt.rig.state() as u8, Ordering::Relaxed);
    let exit = DWT::cycle_count();
    let tick_pending = pac::TIM3.sr().read().uif();
    rt.rig.record_timing(entry, exit, tick_pending);
    if thread_alive(tick, THREAD_HEARTBEAT.load(Ordering::Relaxed)) {
        rt.watchdog.feed();
    }
}

/// Passes a start request to the builder (lending it the rig's simulation store) and
/// starts the run the builder built there, if it was built for the pending request: no
/// simulation is moved in the step.
#[inline(always)]
fn hand_over_runs(rig: &mut StepRig) {
    if let Some(req) = rig.take_start_request()
        && START_REQUESTS.try_send(req).is_err()
    {
        // Not expected (the rig lends its store for one request at a time): offer it
        // again next tick.
        rig.retry_start_request(&req);
    }
    // SAFETY: this is the step interrupt, the only caller.
    if let Some(built) = unsafe { BUILT.step_take() } {
        let failed = built.result.is_err();
        match rig.install_in_place(built) {
            Err(CommandError::StaleBuild { seq }) => {
                let count = rig.stale_builds();
                let _ = STEP_EVENTS.try_send(StepEvent::StaleBuild { seq, count });
            }
            Err(e) if failed => {
                let _ = STEP_EVENTS.try_send(StepEvent::StartFailed(e));
            }
            _ => {}
        }
    }
}

#[inline(always)]
fn take_commands(rig: &mut StepRig) {
    while let Ok(frame) = CAN_RX.try_receive() {
        if let Err(e) = rig.command_frame(&frame) {
            let _ = STEP_EVENTS.try_send(StepEvent::CommandRejected(e));
        }
    }
    while let Ok(c) = LOCAL_CMD.try_receive() {
        // A start made on the board (user button) runs on what the board keeps.
        if let Err(e) = rig.command(rig.on_kept_setup(c)) {
            let _ = STEP_EVENTS.try_send(StepEvent::LocalCommandRejected(e));
        }
    }
}

/// TIM3 as the step clock: 170 MHz / 17 000 = 10 kHz; channel 4 in PWM mode 2 with
/// CCR4 = half the period gives the ADC trigger (TIM3_CC4) at mid-period.
pub fn configure_step_timer(
    t: &embassy_stm32::timer::low_level::Timer<'_, embassy_stm32::peripherals::TIM3>,
) {
    use embassy_stm32::timer::Channel as TimChannel;
    use embassy_stm32::timer::low_level::OutputCompareMode;
    t.regs_core().psc().write_value(0);
    t.set_max_compare_value(STEP_COUNTS - 1);
    t.set_output_compare_mode(TimChannel::Ch4, OutputCompareMode::PwmMode2);
    t.set_compare_value(TimChannel::Ch4, STEP_COUNTS / 2);
    t.enable_channel(TimChannel::Ch4, true);
}
