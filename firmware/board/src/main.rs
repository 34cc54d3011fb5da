//! Rig interface board firmware (NUCLEO-G474RE, STM32G474RE at 170 MHz).
//!
//! A thin HAL shell over `hils-rig-core`: all logic (frame codec, sensor scaling and
//! plausibility, pulse timing, telemetry, commands, the run state machine and the safe
//! state) lives there and is tested on the host. This file wires the peripherals:
//!
//! * **TIM3**: the 10 kHz step clock. Its update interrupt (priority 0, the highest) runs
//!   [`hils_rig_core::rig::Rig::step`]; channel 4 (PWM mode 2, CCR4 = half the period)
//!   triggers the ADC at mid-period, so every step uses samples taken 50 us before it, at
//!   a fixed phase.
//! * **ADC1 + DMA1_CH1**: regular sequence of 16 ranks (PA0 PA1 PC1 PC0, four times),
//!   hardware-triggered by TIM3_CC4, circular DMA; the step takes the latest complete
//!   sequence (`read_latest`); none -> the ADC is stale (flagged, safe state in rig mode).
//! * **TIM1/TIM4/TIM8/TIM20 channel 1** (PA8, PB6, PC6, PB2): the four pulse trains, PWM
//!   mode 1 with ARR and CCR preload; PSC/ARR/CCR written at the end of every step.
//! * **FDCAN1** (PA11 RX, PA12 TX, classic CAN 500 kbit/s): frames queued by the step are
//!   sent by a task; received frames are queued for the step; a task polls the bus state
//!   every 10 ms (error passive, bus-off, automatic recovery, restart when stuck).
//! * **DWT cycle counter**: the step is timed from interrupt entry to the end of the
//!   output writes; TIM3's update flag set again at exit = overrun.
//! * **B1 (PC13)**: starts the self-test paper scenario (press again: the other friction law).
//! * **LD2 (PA5)**: on while a run is stepped, blinking after a fault.
//! * **defmt over RTT**: telemetry lines (`tlm1 ...`) logged by a low-priority task.
#![no_std]
#![no_main]

use core::cell::RefCell;
use core::sync::atomic::{AtomicU8, AtomicU32, Ordering};

use cortex_m::peripheral::DWT;
use cortex_m_rt::interrupt;
use defmt::{info, unwrap, warn};
use embassy_executor::Spawner;
use embassy_stm32::adc::{Adc, AdcChannel, AdcConfig, Exten, RingBufferedAdc, SampleTime};
use embassy_stm32::can::{self, CanConfigurator, CanRx, CanTx, Frame, OperatingMode, Properties};
use embassy_stm32::gpio::{Input, Level, Output, OutputType, Pull, Speed};
use embassy_stm32::interrupt::{self, InterruptExt, Priority};
use embassy_stm32::peripherals::{ADC1, DMA1_CH1, FDCAN1, TIM1, TIM4, TIM8, TIM20};
use embassy_stm32::timer::low_level::{OutputCompareMode, Timer};
use embassy_stm32::timer::simple_pwm::PwmPin;
use embassy_stm32::timer::{Ch1, Channel as TimChannel, GeneralInstance4Channel};
use embassy_stm32::{Config, bind_interrupts, dma, pac, triggers};
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::channel::Channel;
use embassy_time::{Duration, Ticker, Timer as Delay};
use hils_plant::FrictionModel;
use hils_rig_core::bus::{BusAction, BusMode, BusMonitor, BusStatus};
use hils_rig_core::can::{Command, ID_COMMAND, RigState};
use hils_rig_core::hw::{RigIo, TelemetryEvent};
use hils_rig_core::pulse::PulseRegisters;
use hils_rig_core::rig::{Rig, RigConfig};
use hils_rig_core::sensor::ADC_SEQUENCE_LEN;
use static_cell::StaticCell;
use {defmt_rtt as _, panic_probe as _};

bind_interrupts!(struct Irqs {
    FDCAN1_IT0 => can::IT0InterruptHandler<FDCAN1>;
    FDCAN1_IT1 => can::IT1InterruptHandler<FDCAN1>;
    DMA1_CHANNEL1 => dma::InterruptHandler<DMA1_CH1>;
});

/// CPU and timer clock, Hz.
const CPU_HZ: u32 = 170_000_000;
/// Step period in timer counts (10 kHz at 170 MHz).
const STEP_COUNTS: u16 = (CPU_HZ / hils_rig_core::STEP_RATE_HZ) as u16;
/// ADC ring buffer: four sequences.
const ADC_RING: usize = 4 * ADC_SEQUENCE_LEN;

/// Frames from the step to the CAN transmit task.
static CAN_TX: Channel<CriticalSectionRawMutex, Frame, 32> = Channel::new();
/// Frames received, for the step.
static CAN_RX: Channel<CriticalSectionRawMutex, Frame, 8> = Channel::new();
/// Local commands (user button, autostart), for the step.
static LOCAL_CMD: Channel<CriticalSectionRawMutex, Command, 2> = Channel::new();
/// Telemetry events from the step to the logging task.
static TELEMETRY: Channel<CriticalSectionRawMutex, TelemetryEvent, 16> = Channel::new();
/// Bus state for the step: bit 0 error passive, bit 1 bus-off (now or seen); bits 8.. count.
static BUS_STATE: AtomicU32 = AtomicU32::new(0);
/// Rig state for the LED task.
static RIG_STATE: AtomicU8 = AtomicU8::new(0);

/// One pulse output: a timer driving channel 1.
struct PulseOut<T: GeneralInstance4Channel> {
    timer: Timer<'static, T>,
    _pin: PwmPin<'static, T, Ch1>,
}

impl<T: GeneralInstance4Channel> PulseOut<T> {
    fn new(
        timer: Timer<'static, T>,
        pin: PwmPin<'static, T, Ch1>,
        silent: &PulseRegisters,
    ) -> Self {
        timer.set_output_compare_mode(TimChannel::Ch1, OutputCompareMode::PwmMode1);
        timer.set_output_compare_preload(TimChannel::Ch1, true);
        timer.set_autoreload_preload(true);
        let out = Self { timer, _pin: pin };
        out.write(silent);
        out.timer.generate_update_event();
        out.timer.enable_channel(TimChannel::Ch1, true);
        out.timer.enable_outputs();
        out.timer.start();
        out
    }

    /// Writes PSC, ARR and CCR1; all preloaded: they take effect at the next update event.
    #[inline(always)]
    fn write(&self, r: &PulseRegisters) {
        let regs = self.timer.regs_core();
        regs.psc().write_value(r.psc);
        regs.arr().write(|w| w.set_arr(r.arr as u16));
        self.timer
            .regs_gp16()
            .ccr(0)
            .write(|w| w.set_ccr(r.ccr as u16));
    }
}

/// The peripherals the step uses.
struct BoardIo {
    adc: RingBufferedAdc<'static, ADC1>,
    adc_buf: [u16; ADC_SEQUENCE_LEN],
    ws1: PulseOut<TIM1>,
    ws2: PulseOut<TIM4>,
    ws3: PulseOut<TIM8>,
    ws4: PulseOut<TIM20>,
}

impl RigIo for BoardIo {
    type Frame = Frame;

    fn adc_sequence(&mut self) -> Option<[u16; ADC_SEQUENCE_LEN]> {
        let n = self.adc.read_latest(&mut self.adc_buf);
        (n == ADC_SEQUENCE_LEN).then_some(self.adc_buf)
    }

    fn set_pulse(&mut self, wheelset: usize, r: &PulseRegisters) {
        match wheelset {
            0 => self.ws1.write(r),
            1 => self.ws2.write(r),
            2 => self.ws3.write(r),
            _ => self.ws4.write(r),
        }
    }

    fn queue_frame(&mut self, frame: Frame) -> bool {
        CAN_TX.try_send(frame).is_ok()
    }

    fn queue_telemetry(&mut self, event: &TelemetryEvent) -> bool {
        TELEMETRY.try_send(*event).is_ok()
    }
}

struct RealTime {
    rig: Rig,
    io: BoardIo,
}

/// Storage of the rig and its peripherals (zero-initialised: in .bss, not in flash).
static REAL_TIME_CELL: StaticCell<RealTime> = StaticCell::new();
/// The rig and its peripherals, owned by the step interrupt after start-up.
static REAL_TIME: Mutex<CriticalSectionRawMutex, RefCell<Option<&'static mut RealTime>>> =
    Mutex::new(RefCell::new(None));

/// The 10 kHz step: highest priority, never waits.
#[interrupt]
fn TIM3() {
    let entry = DWT::cycle_count();
    pac::TIM3.sr().modify(|w| w.set_uif(false));
    REAL_TIME.lock(|rt| {
        let mut rt = rt.borrow_mut();
        let Some(rt) = rt.as_mut() else { return };
        while let Ok(frame) = CAN_RX.try_receive() {
            if let Err(e) = rt.rig.command_frame(&frame) {
                warn!("command rejected: {}", e);
            }
        }
        while let Ok(c) = LOCAL_CMD.try_receive() {
            if let Err(e) = rt.rig.command(c) {
                warn!("local command rejected: {}", e);
            }
        }
        let bus = BUS_STATE.load(Ordering::Relaxed);
        rt.rig.set_bus(bus & 1 != 0, bus & 2 != 0, bus >> 8);
        rt.rig.step(&mut rt.io);
        RIG_STATE.store(rt.rig.state() as u8, Ordering::Relaxed);
        let exit = DWT::cycle_count();
        let tick_pending = pac::TIM3.sr().read().uif();
        rt.rig.record_timing(entry, exit, tick_pending);
    });
}

#[embassy_executor::main]
async fn main(spawner: Spawner) {
    let mut config = Config::default();
    {
        use embassy_stm32::rcc::*;
        // HSI16 / 4 x 85 / 2 = 170 MHz; timers, FDCAN (PCLK1) and ADC (SYSCLK / 4) from it.
        config.rcc.hsi = true;
        config.rcc.pll = Some(Pll {
            source: PllSource::HSI,
            prediv: PllPreDiv::DIV4,
            mul: PllMul::MUL85,
            divp: None,
            divq: None,
            divr: Some(PllRDiv::DIV2),
        });
        config.rcc.sys = Sysclk::PLL1_R;
        config.rcc.boost = true;
        config.rcc.mux.fdcansel = mux::Fdcansel::PCLK1;
        config.rcc.mux.adc12sel = mux::Adcsel::SYS;
    }
    let p = embassy_stm32::init(config);
    info!("rig interface board: STM32G474RE at {} Hz", CPU_HZ);

    // DWT cycle counter for step timing.
    let mut cp = unwrap!(cortex_m::Peripherals::take());
    cp.DCB.enable_trace();
    cp.DWT.enable_cycle_counter();

    let rig_config = RigConfig::nucleo_g474re();
    let silent = rig_config.pulse_timer.silent();

    // Pulse trains.
    let ws1 = PulseOut::new(
        Timer::new(p.TIM1),
        PwmPin::new(p.PA8, OutputType::PushPull),
        &silent,
    );
    let ws2 = PulseOut::new(
        Timer::new(p.TIM4),
        PwmPin::new(p.PB6, OutputType::PushPull),
        &silent,
    );
    let ws3 = PulseOut::new(
        Timer::new(p.TIM8),
        PwmPin::new(p.PC6, OutputType::PushPull),
        &silent,
    );
    let ws4 = PulseOut::new(
        Timer::new(p.TIM20),
        PwmPin::new(p.PB2, OutputType::PushPull),
        &silent,
    );

    // ADC1: 16 ranks triggered by TIM3_CC4, circular DMA.
    let adc = Adc::new(p.ADC1, AdcConfig::default());
    let t = SampleTime::CYCLES24_5;
    // Each input appears in four ranks. SAFETY: the copies of a pin only put it in analog
    // mode and name its channel; nothing else uses these pins.
    let (ch1, ch2, ch3, ch4) = (p.PA0, p.PA1, p.PC1, p.PC0);
    let sequence: [_; ADC_SEQUENCE_LEN] = core::array::from_fn(|rank| unsafe {
        let ch = match rank % 4 {
            0 => ch1.clone_unchecked().degrade_adc(),
            1 => ch2.clone_unchecked().degrade_adc(),
            2 => ch3.clone_unchecked().degrade_adc(),
            _ => ch4.clone_unchecked().degrade_adc(),
        };
        (ch, t)
    });
    let dma_buf = unwrap!(cortex_m::singleton!(: [u16; ADC_RING] = [0; ADC_RING]));
    let mut adc = adc.into_ring_buffered(
        p.DMA1_CH1,
        dma_buf,
        Irqs,
        sequence.into_iter(),
        triggers::TIM3_CC4,
        Exten::RISING_EDGE,
    );
    adc.start();

    // FDCAN1, classic CAN at 500 kbit/s, automatic bus-off recovery.
    let mut can_cfg = CanConfigurator::new(p.FDCAN1, p.PA11, p.PA12, Irqs);
    can_cfg.set_bitrate(500_000);
    can_cfg.set_config(can_cfg.config().set_automatic_bus_off_recovery(true));
    let can = can_cfg.start(OperatingMode::NormalOperationMode);
    let (tx, rx, props) = can.split();

    // Lower priority than the step for everything else.
    for irq in [
        interrupt::FDCAN1_IT0,
        interrupt::FDCAN1_IT1,
        interrupt::DMA1_CHANNEL1,
        interrupt::TIM2,
    ] {
        irq.set_priority(Priority::P3);
    }

    let real_time = REAL_TIME_CELL.init(RealTime {
        rig: Rig::new(rig_config),
        io: BoardIo {
            adc,
            adc_buf: [0; ADC_SEQUENCE_LEN],
            ws1,
            ws2,
            ws3,
            ws4,
        },
    });
    REAL_TIME.lock(|rt| {
        rt.replace(Some(real_time));
    });

    spawner.spawn(unwrap!(can_tx_task(tx)));
    spawner.spawn(unwrap!(can_rx_task(rx)));
    spawner.spawn(unwrap!(bus_task(props)));
    spawner.spawn(unwrap!(telemetry_task()));
    spawner.spawn(unwrap!(button_task(Input::new(p.PC13, Pull::Down))));
    spawner.spawn(unwrap!(led_task(Output::new(
        p.PA5,
        Level::Low,
        Speed::Low
    ))));

    // TIM3: 10 kHz update interrupt (the step), CH4 at mid-period (the ADC trigger).
    let step_timer = Timer::new(p.TIM3);
    step_timer.regs_core().psc().write_value(0);
    step_timer.set_max_compare_value(STEP_COUNTS - 1);
    step_timer.set_output_compare_mode(TimChannel::Ch4, OutputCompareMode::PwmMode2);
    step_timer.set_compare_value(TimChannel::Ch4, STEP_COUNTS / 2);
    step_timer.enable_channel(TimChannel::Ch4, true);
    step_timer.enable_update_interrupt(true);
    interrupt::TIM3.set_priority(Priority::P0);
    // SAFETY: the handler only touches REAL_TIME (initialised above) and the queues.
    unsafe { interrupt::TIM3.enable() };
    step_timer.start();
    core::mem::forget(step_timer);
    info!("10 kHz step running; press B1 for the self-test paper scenario");

    if cfg!(feature = "selftest-autostart") {
        LOCAL_CMD
            .send(Command::paper_self_test(FrictionModel::Variable))
            .await;
    }
}

/// Sends the frames the step queued. While the bus is off, writes wait and the queue fills:
/// the step then counts dropped frames (flag CAN_TX_DROPPED).
#[embassy_executor::task]
async fn can_tx_task(mut tx: CanTx<'static>) {
    loop {
        let frame = CAN_TX.receive().await;
        tx.write(&frame).await;
    }
}

/// Hands received `RIG_COMMAND` frames to the step (decoded and checked there).
#[embassy_executor::task]
async fn can_rx_task(mut rx: CanRx<'static>) {
    loop {
        match rx.read().await {
            Ok(envelope) => {
                let (frame, _) = envelope.parts();
                // Frames of other nodes on the bus are not for the board.
                let for_us = matches!(frame.id(), embedded_can::Id::Standard(id) if id.as_raw() == ID_COMMAND);
                if for_us && CAN_RX.try_send(frame).is_err() {
                    warn!("command queue full: frame dropped");
                }
            }
            Err(e) => warn!("CAN receive error: {}", e),
        }
    }
}

/// Polls the bus state every 10 ms: error passive, bus-off, recovery, restart.
#[embassy_executor::task]
async fn bus_task(props: Properties) {
    let mut monitor = BusMonitor::new();
    let mut ticker = Ticker::every(Duration::from_millis(10));
    loop {
        ticker.next().await;
        let mode = match props.bus_error_mode() {
            can::enums::BusErrorMode::ErrorActive => BusMode::ErrorActive,
            can::enums::BusErrorMode::ErrorPassive => BusMode::ErrorPassive,
            can::enums::BusErrorMode::BusOff => BusMode::BusOff,
        };
        let status = BusStatus {
            mode,
            tx_errors: props.tx_error_count(),
            rx_errors: props.rx_error_count(),
        };
        let now_ms = embassy_time::Instant::now().as_millis() as u32;
        let (event, action) = monitor.poll(status, now_ms);
        if let Some(e) = event {
            warn!(
                "CAN bus: {} (TEC {}, REC {})",
                e, status.tx_errors, status.rx_errors
            );
        }
        if action == BusAction::Restart {
            warn!(
                "CAN bus-off for over {} ms: restarting the controller",
                BusMonitor::RESTART_AFTER_MS
            );
            // Leaving INIT starts the bus-off recovery sequence again.
            pac::FDCAN1.cccr().modify(|w| w.set_init(false));
        }
        let bits = (mode == BusMode::ErrorPassive) as u32
            | ((monitor.bus_off_seen as u32) << 1)
            | (monitor.bus_off_count.min(0x00FF_FFFF) << 8);
        BUS_STATE.store(bits, Ordering::Relaxed);
    }
}

/// Logs the telemetry the step queued (defmt over RTT).
#[embassy_executor::task]
async fn telemetry_task() {
    loop {
        TELEMETRY.receive().await.log();
    }
}

/// B1 starts the self-test paper scenario; each press alternates the friction law.
#[embassy_executor::task]
async fn button_task(button: Input<'static>) {
    let mut variable = true;
    let mut was_pressed = false;
    loop {
        Delay::after_millis(20).await;
        let pressed = button.is_high();
        if pressed && !was_pressed {
            let friction = if variable {
                FrictionModel::Variable
            } else {
                FrictionModel::Constant
            };
            info!(
                "B1: self-test paper scenario, {} friction",
                if variable { "variable" } else { "constant" }
            );
            LOCAL_CMD.send(Command::paper_self_test(friction)).await;
            variable = !variable;
        }
        was_pressed = pressed;
    }
}

/// LD2: on while running, blinking in fault, off otherwise.
#[embassy_executor::task]
async fn led_task(mut led: Output<'static>) {
    let mut on = false;
    loop {
        Delay::after_millis(250).await;
        match RigState::from_raw(RIG_STATE.load(Ordering::Relaxed)) {
            Some(RigState::Running) => led.set_high(),
            Some(RigState::Fault) => {
                on = !on;
                led.set_level(if on { Level::High } else { Level::Low });
            }
            _ => led.set_low(),
        }
    }
}
