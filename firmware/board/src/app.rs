//! The rig application: peripherals configured in thread mode, the rig handed to the step,
//! the tasks spawned (among them the builder of each run's simulation, the ADC watch and the
//! health task), then the step clock started. The bring-up image runs it too, with CAN in
//! internal loopback, to time the application's own step in TIM3 (`bringup::step_time`).

use defmt::{info, unwrap};
use embassy_executor::Spawner;
use embassy_stm32::adc::{Adc, AdcChannel, AdcConfig, Exten, RingBufferedAdc, SampleTime};
use embassy_stm32::can::CanConfigurator;
use embassy_stm32::gpio::{Input, Level, Output, OutputType, Pull, Speed};
use embassy_stm32::interrupt::{self, InterruptExt};
use embassy_stm32::pac;
use embassy_stm32::peripherals::{ADC1, DMA1_CH1, PA0, PA1, PC0, PC1, TIM3};
use embassy_stm32::timer::low_level::Timer;
use embassy_stm32::timer::simple_pwm::PwmPin;
use embassy_stm32::triggers;
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_stm32::{Peri, Peripherals};
use embassy_time::{Duration, Instant, Ticker, Timer as Delay};
use hils_plant::FrictionModel;
use hils_rig_core::Code;
use hils_rig_core::adc_watch::{self, AdcAction, AdcConverter, AdcRing, AdcWatch};
use hils_rig_core::can::{Command, RigState};
use hils_rig_core::reset_loop::HEALTHY_RUN_TICKS;
use hils_rig_core::rig::{Rig, RigConfig};
use hils_rig_core::sensor::ADC_SEQUENCE_LEN;
use hils_rig_core::stack::StackWatch;

use crate::Irqs;
use crate::can_io::Join;
use crate::pulse::PulseOut;
use crate::shared::{
    ADC_RESTARTS, ADC_SEQUENCES, BUILT, LOCAL_CMD, RIG_STATE, STACK_PEAK, START_REQUESTS,
    STEP_TICKS,
};
use crate::sim_store::{BoardSim, lent_store};
use crate::step::{
    BoardIo, REAL_TIME, RealTime, WATCHDOG_TIMEOUT_US, Watchdog, configure_step_timer,
};

/// ADC ring buffer: four sequences.
const ADC_RING: usize = 4 * ADC_SEQUENCE_LEN;

/// Which image runs the application.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Image {
    /// The rig: CAN on the controller's bus, the button, `selftest-autostart`.
    Rig,
    /// The bring-up image's step check: CAN in internal loopback (off the bus), the
    /// self-test paper scenario started at once, no button.
    Bringup,
}

pub async fn run(spawner: Spawner, p: Peripherals, image: Image) {
    let rig_config = RigConfig::nucleo_g474re();
    let silent = rig_config.pulse_timer.silent();

    // Wheelsets 1-4: a timer and its channel-1 pin each (push-pull), silent until the
    // first step; the pin goes to the timer only once the timer drives it low (`PulseOut::new`).
    // Each timer and pin is its own type, hence a macro.
    macro_rules! pulse_out {
        ($timer:expr, $pin:expr) => {
            PulseOut::new(
                Timer::new($timer),
                || PwmPin::new($pin, OutputType::PushPull),
                &silent,
            )
        };
    }
    let ws1 = pulse_out!(p.TIM1, p.PA8);
    let ws2 = pulse_out!(p.TIM15, p.PB14);
    let ws3 = pulse_out!(p.TIM8, p.PC6);
    let ws4 = pulse_out!(p.TIM20, p.PB2);

    // The interface stage's output enable: an output, low (the step drives it from here);
    // kept configured for good (dropping it would return the pin to analog).
    core::mem::forget(Output::new(p.PC8, Level::Low, Speed::Low));

    let adc = start_adc(p.ADC1, p.DMA1_CH1, (p.PA0, p.PA1, p.PC1, p.PC0));

    let join = match image {
        Image::Rig => Join::Bus,
        Image::Bringup => Join::Loopback,
    };
    let (tx, props) =
        crate::can_io::start(CanConfigurator::new(p.FDCAN1, p.PA11, p.PA12, Irqs), join);

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
    spawner.spawn(unwrap!(crate::can_io::bus_task(props)));
    spawner.spawn(unwrap!(crate::telemetry::telemetry_task()));
    spawner.spawn(unwrap!(crate::telemetry::step_events_task()));
    spawner.spawn(unwrap!(sim_builder_task()));
    spawner.spawn(unwrap!(adc_watch_task()));
    spawner.spawn(unwrap!(health_task()));
    if image == Image::Rig {
        spawner.spawn(unwrap!(button_task(Input::new(p.PC13, Pull::Down))));
    }
    spawner.spawn(unwrap!(led_task(Output::new(
        p.PA5,
        Level::Low,
        Speed::Low
    ))));

    start_step_timer(p.TIM3);
    info!(
        "10 kHz step running, watchdog {=u32} us; outputs to the controller disarmed (RIG_COMMAND Arm); B1: self-test paper scenario (never drives them)",
        WATCHDOG_TIMEOUT_US
    );

    if image == Image::Bringup || cfg!(feature = "selftest-autostart") {
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

/// ADC1 as `adc_watch::stop` drives it (RM0440 ADC: ADSTP, ADSTART, DR, ISR), in thread
/// mode with the step running.
struct BoardAdc;

/// Reads of ADSTART before a stop counts as failed (ADSTP ends within a conversion, < 1 us;
/// thread mode, the step is not masked).
const ADC_STOP_READS: u32 = 10_000;

impl AdcConverter for BoardAdc {
    fn stop_conversions(&mut self) -> bool {
        let adc = pac::ADC1;
        if adc.cr().read().adstart() {
            adc.cr()
                .modify(|w| w.set_adstp(pac::adc::vals::Adstp::STOP));
        }
        (0..ADC_STOP_READS).any(|_| !adc.cr().read().adstart())
    }
    fn discard_pending_conversion(&mut self) {
        let adc = pac::ADC1;
        // Reading DR clears EOC and with it the DMA request of that conversion.
        let _ = adc.dr().read();
        // rc_w1: only the bits written 1 clear.
        adc.isr().write(|w| {
            w.set_eoc(true);
            w.set_eos(true);
        });
    }
    fn clear_overrun(&mut self) {
        pac::ADC1.isr().write(|w| w.set_ovr(true));
    }
}

/// The DMA ring as `adc_watch::realign` drives it (RM0440 DMA: CCR.EN, CNDTR, IFCR; ADC
/// ADSTART), under the step's ceiling: register writes only, no wait. The channel is idle
/// when EN is cleared (the ADC is stopped and its DR consumed by `adc_watch::stop`: no
/// request, no transfer in progress), so CNDTR takes the new count.
struct BoardAdcRing<'a>(&'a mut RingBufferedAdc<'static, ADC1>);

impl AdcRing for BoardAdcRing<'_> {
    fn rewind_dma(&mut self) {
        let ch = pac::DMA1.ch(0);
        ch.cr().modify(|w| w.set_en(false));
        ch.ndtr().write(|w| w.set_ndt(ADC_RING as u16));
        pac::DMA1.ifcr().write(|w| {
            w.set_gif(0, true);
            w.set_tcif(0, true);
            w.set_htif(0, true);
            w.set_teif(0, true);
        });
        ch.cr().modify(|w| w.set_en(true));
    }
    fn reset_reader(&mut self) {
        self.0.clear();
    }
    fn start_conversions(&mut self) {
        pac::ADC1.cr().modify(|w| w.set_adstart(true));
    }
}

/// Watches the ADC ring's progress every ms and restarts it, aligned, when it stalls
/// (`hils_rig_core::adc_watch`: no fresh sequence for 2 ms while the step runs, or an ADC
/// overrun); the stop runs in thread mode, the realignment is a few register writes under
/// the step's ceiling.
#[embassy_executor::task]
async fn adc_watch_task() {
    use core::sync::atomic::Ordering::Relaxed;
    let mut watch = AdcWatch::new();
    let mut ticker = Ticker::every(Duration::from_millis(1));
    loop {
        ticker.next().await;
        let overrun = pac::ADC1.isr().read().ovr();
        let now_ms = Instant::now().as_millis() as u32;
        let action = watch.poll(
            ADC_SEQUENCES.load(Relaxed),
            STEP_TICKS.load(Relaxed),
            overrun,
            now_ms,
        );
        if action == AdcAction::Restart {
            // The stop and its bounded wait run with the step unmasked; only the realignment
            // (a few register writes, no wait) masks it.
            let done = adc_watch::stop(&mut BoardAdc);
            if done.is_ok() {
                // SAFETY: thread mode; register writes only.
                unsafe {
                    REAL_TIME.with_step_masked(|rt| {
                        adc_watch::realign(&mut BoardAdcRing(&mut rt.io.adc))
                    })
                };
            }
            ADC_RESTARTS.store(watch.restarts, Relaxed);
            defmt::warn!(
                "ADC ring stalled (overrun {=bool}): restart {}, {=u32} so far",
                overrun,
                done,
                watch.restarts
            );
        }
    }
}

/// Every 100 ms: the stack's high-water mark from its paint (`RIG_HEALTH` `StackPeak`,
/// warned above 3/4 of the stack), and once the board has run 10 s, the count of fault
/// resets in a row starts again (`hils_rig_core::reset_loop`).
#[embassy_executor::task]
async fn health_task() {
    use core::sync::atomic::Ordering::Relaxed;
    let (bottom, top) = crate::fault::stack_span();
    let mut watch = StackWatch::new(((top - bottom) / 4) as usize);
    let mut warned = false;
    let mut healthy = false;
    let mut ticker = Ticker::every(Duration::from_millis(100));
    loop {
        ticker.next().await;
        // SAFETY: word reads inside the stack region (`stack.x`); a word another context is
        // writing reads as a scrubbed word, which it is.
        let peak =
            watch.scan(|i| unsafe { core::ptr::read_volatile((bottom as *const u32).add(i)) });
        STACK_PEAK.store(peak, Relaxed);
        if !warned && peak > watch.size_bytes() / 4 * 3 {
            warned = true;
            defmt::warn!("stack: {=u32} of {=u32} B used", peak, watch.size_bytes());
        }
        if !healthy && STEP_TICKS.load(Relaxed) >= HEALTHY_RUN_TICKS {
            healthy = true;
            crate::fault::ran_healthy();
        }
    }
}

/// B1 starts the self-test paper scenario; each press alternates the friction law. A
/// self-test run never drives the outputs a controller reads, and its start disarms the
/// rig (`hils_rig_core::arming`).
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
