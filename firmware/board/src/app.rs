//! The rig application: peripherals configured in thread mode, the rig handed to the step,
//! the tasks spawned (among them the builder of each run's simulation), then the step clock
//! started.

use defmt::{info, unwrap};
use embassy_executor::Spawner;
use embassy_stm32::adc::{Adc, AdcChannel, AdcConfig, Exten, RingBufferedAdc, SampleTime};
use embassy_stm32::can::CanConfigurator;
use embassy_stm32::gpio::{Input, Level, Output, OutputType, Pull, Speed};
use embassy_stm32::interrupt::{self, InterruptExt};
use embassy_stm32::peripherals::{ADC1, DMA1_CH1, PA0, PA1, PC0, PC1, TIM3};
use embassy_stm32::timer::low_level::Timer;
use embassy_stm32::timer::simple_pwm::PwmPin;
use embassy_stm32::triggers;
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_stm32::{Peri, Peripherals};
use embassy_time::Timer as Delay;
use hils_plant::FrictionModel;
use hils_rig_core::Code;
use hils_rig_core::can::{Command, RigState};
use hils_rig_core::rig::{Rig, RigConfig};
use hils_rig_core::sensor::ADC_SEQUENCE_LEN;

use crate::Irqs;
use crate::pulse::PulseOut;
use crate::shared::{BUILT, LOCAL_CMD, RIG_STATE, START_REQUESTS};
use crate::sim_store::{BoardSim, lent_store};
use crate::step::{
    BoardIo, REAL_TIME, RealTime, WATCHDOG_TIMEOUT_US, Watchdog, configure_step_timer,
};

/// ADC ring buffer: four sequences.
const ADC_RING: usize = 4 * ADC_SEQUENCE_LEN;

pub async fn run(spawner: Spawner, p: Peripherals) {
    let rig_config = RigConfig::nucleo_g474re();
    let silent = rig_config.pulse_timer.silent();

    // Wheelsets 1-4: a timer and its channel-1 pin each (push-pull), silent until the
    // first step (each timer and pin is its own type, hence a macro).
    macro_rules! pulse_out {
        ($timer:expr, $pin:expr) => {
            PulseOut::new(
                Timer::new($timer),
                PwmPin::new($pin, OutputType::PushPull),
                &silent,
            )
        };
    }
    let ws1 = pulse_out!(p.TIM1, p.PA8);
    let ws2 = pulse_out!(p.TIM4, p.PB6);
    let ws3 = pulse_out!(p.TIM8, p.PC6);
    let ws4 = pulse_out!(p.TIM20, p.PB2);

    let adc = start_adc(p.ADC1, p.DMA1_CH1, (p.PA0, p.PA1, p.PC1, p.PC0));

    let (tx, rx, props) =
        crate::can_io::start(CanConfigurator::new(p.FDCAN1, p.PA11, p.PA12, Irqs));

    // The rig is built here, in thread mode, and handed to the step.
    let watchdog = Watchdog::new(IndependentWatchdog::new(p.IWDG, WATCHDOG_TIMEOUT_US));
    unwrap!(
        REAL_TIME
            .publish_with(|| RealTime {
                // SAFETY: the one handle on the store, for the step's rig.
                rig: Rig::with_store(rig_config, unsafe { BoardSim::new() }),
                io: BoardIo {
                    adc,
                    adc_buf: [0; ADC_SEQUENCE_LEN],
                    ws1,
                    ws2,
                    ws3,
                    ws4,
                    tick: 0,
                },
                watchdog,
                seen_drops: (0, 0),
            })
            .ok()
    );

    spawner.spawn(unwrap!(crate::can_io::can_tx_task(tx)));
    spawner.spawn(unwrap!(crate::can_io::can_rx_task(rx)));
    spawner.spawn(unwrap!(crate::can_io::bus_task(props)));
    spawner.spawn(unwrap!(crate::telemetry::telemetry_task()));
    spawner.spawn(unwrap!(crate::telemetry::step_events_task()));
    spawner.spawn(unwrap!(sim_builder_task()));
    spawner.spawn(unwrap!(adc_restart_task()));
    spawner.spawn(unwrap!(button_task(Input::new(p.PC13, Pull::Down))));
    spawner.spawn(unwrap!(led_task(Output::new(
        p.PA5,
        Level::Low,
        Speed::Low
    ))));

    start_step_timer(p.TIM3);
    info!(
        "10 kHz step running, watchdog {=u32} us; press B1 for the self-test paper scenario",
        WATCHDOG_TIMEOUT_US
    );

    if cfg!(feature = "selftest-autostart") {
        LOCAL_CMD
            .send(Command::paper_self_test(FrictionModel::Variable))
            .await;
    }
}

/// ADC1: 16 ranks (each brake input in four) triggered by TIM3_CC4, into a circular DMA
/// ring; started (the conversions begin with the step timer).
fn start_adc(
    adc1: Peri<'static, ADC1>,
    dma: Peri<'static, DMA1_CH1>,
    pins: (
        Peri<'static, PA0>,
        Peri<'static, PA1>,
        Peri<'static, PC1>,
        Peri<'static, PC0>,
    ),
) -> RingBufferedAdc<'static, ADC1> {
    let adc = Adc::new(adc1, AdcConfig::default());
    let t = SampleTime::CYCLES24_5;
    // Each input appears in four ranks. SAFETY: the copies of a pin only put it in analog
    // mode and name its channel; nothing else uses these pins.
    let (ch1, ch2, ch3, ch4) = pins;
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
    let mut ring = adc.into_ring_buffered(
        dma,
        dma_buf,
        Irqs,
        sequence.into_iter(),
        triggers::TIM3_CC4,
        Exten::RISING_EDGE,
    );
    ring.start();
    ring
}

/// TIM3: 10 kHz update interrupt (the step), CH4 at mid-period (the ADC trigger); runs
/// for good from here.
fn start_step_timer(tim3: Peri<'static, TIM3>) {
    let step_timer = Timer::new(tim3);
    configure_step_timer(&step_timer);
    step_timer.enable_update_interrupt(true);
    // SAFETY: the handler touches only REAL_TIME (published by `run` before this call), the
    // queues and atomics.
    unsafe { interrupt::TIM3.enable() };
    step_timer.start();
    // The step timer runs for good: keep its clock on (Timer's drop would disable it).
    core::mem::forget(step_timer);
}

/// Builds the simulation of each run the step requests, in thread mode (~35 000
/// instructions and a large stack frame that must not run in the step), in place in the
/// rig's store the step lent with the request, and tells the step (`BUILT`, a few bytes),
/// which starts the run at its next tick if the request is still the pending one.
#[embassy_executor::task]
async fn sim_builder_task() {
    loop {
        let request = START_REQUESTS.receive().await;
        // SAFETY: the rig lent the store with this request and touches it again only
        // after `BUILT` is published below; the reference ends with this statement.
        let built = request.build_into(unsafe { lent_store() });
        // The slot is busy only while the step has not yet taken the last word (< 0.1 ms).
        while BUILT.publish_with(|| built.clone()).is_err() {
            Delay::after_micros(100).await;
        }
    }
}

/// Restarts the ADC ring when the step found its DMA stopped (the step only reports it
/// as stale ticks: embassy's restart is set-up work that does not belong in the step).
#[embassy_executor::task]
async fn adc_restart_task() {
    let mut restarts = 0u32;
    loop {
        Delay::after_millis(1).await;
        if crate::shared::ADC_STOPPED.swap(false, core::sync::atomic::Ordering::Relaxed) {
            // SAFETY: thread mode; `start` is a few register writes.
            let done = unsafe { REAL_TIME.with_step_masked(|rt| rt.io.adc.start()) };
            if done.is_some() {
                restarts += 1;
                defmt::warn!("ADC ring stopped: restarted ({=u32} so far)", restarts);
            }
        }
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
        match RigState::from_raw(RIG_STATE.load(core::sync::atomic::Ordering::Relaxed)) {
            Some(RigState::Running) => led.set_high(),
            Some(RigState::Fault) => {
                on = !on;
                led.set_level(if on { Level::High } else { Level::Low });
            }
            _ => led.set_low(),
        }
    }
}
