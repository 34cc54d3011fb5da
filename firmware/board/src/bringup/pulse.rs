//! A pulse train measured through one jumper wire: D7 (PA8, TIM1_CH1, wheelset 1's pulse
//! output) to D12 (PA6, TIM16_CH1 input capture, AF1); then the timer's break: a software
//! break (EGR.BG, the path a lockup or a clock failure takes in hardware) must clear MOE and
//! hold the pin low with no further edge.
//!
//! PA8 is a controller-facing output, and the bring-up image is never armed: it drives PA8
//! only after finding the jumper with the chip's weak pulls alone (D7 pulled up, then down,
//! D12 following each time: `hils_rig_core::bringup::jumper_found`), i.e. on a bare board.
//! A rig's pull-down on the line or an interface stage fails that probe, and PA8 stays
//! low. After the check PA8 is a GPIO output driven low again, as `__pre_init` left it.

use cortex_m::peripheral::DWT;
use embassy_stm32::Peri;
use embassy_stm32::gpio::{AfType, Flex, OutputType, Pull, Speed};
use embassy_stm32::pac;
use embassy_stm32::pac::timer::vals::CcmrInputCcs;
use embassy_stm32::peripherals::{PA6, PA8, TIM1, TIM16};
use embassy_stm32::timer::low_level::Timer;
use embassy_stm32::timer::simple_pwm::PwmPin;
use hils_plant::Params;
use hils_rig_core::bringup::{
    JUMPER_PROBES, PULSE_CAPTURE_HZ, PULSE_TEST_SPEED_KMH, PulseCapture, jumper_found,
    pulse_test_registers,
};
use hils_rig_core::pulse::PulseTimer;
use hils_rig_core::rig::RigConfig;

use super::verdict;
use crate::pulse::{PULSE_PINS, PulseOut, drive_low};
use crate::step::CPU_HZ;

/// The capture timer's prescaler: 170 MHz / 4 = 42.5 MHz (`PULSE_CAPTURE_HZ`), so a
/// period of the test frequency (30 620 counts) fits the 16-bit counter.
const CAPTURE_PSC: u16 = (CPU_HZ / PULSE_CAPTURE_HZ - 1) as u16;
const PERIODS: u32 = 200;

/// Waits for a rising-edge capture; `None` after `timeout_cycles`.
fn next_capture(timeout_cycles: u32) -> Option<u16> {
    let t16 = pac::TIM16;
    let start = DWT::cycle_count();
    while !t16.sr().read().ccif(0) {
        if DWT::cycle_count().wrapping_sub(start) > timeout_cycles {
            return None;
        }
    }
    // Reading CCR1 clears CC1IF.
    Some(t16.ccr(0).read().ccr() as u16)
}

/// Probes the jumper D7-D12 with PA8's weak pulls only (module doc); PA8 is left a GPIO
/// output driven low.
fn jumper_probe(pa8: Peri<'static, PA8>, pa6: Peri<'static, PA6>) -> bool {
    let mut d7 = Flex::new(pa8);
    let mut d12 = Flex::new(pa6);
    d12.set_as_input(Pull::None);
    let probes: [(bool, bool); JUMPER_PROBES] = core::array::from_fn(|k| {
        let up = k % 2 == 0;
        d7.set_as_input(if up { Pull::Up } else { Pull::Down });
        // 100 us: a weak pull (~40 kohm) charges the jumpered line in a few us.
        cortex_m::asm::delay(CPU_HZ / 10_000);
        (up, d12.is_high())
    });
    // Low again before the driver is forgotten (a dropped Flex would leave PA8 analog).
    d7.set_low();
    d7.set_as_output(Speed::Low);
    core::mem::forget(d7);
    jumper_found(&probes)
}

/// Wheelset 1's pulse output set for 150 km/h on the reference wheel (90 teeth, ~1388 Hz)
/// by the rig's own pulse code, measured over 200 periods by TIM16's input capture; only
/// with the jumper found (module doc).
pub async fn pulse_through_jumper(
    tim1: Peri<'static, TIM1>,
    pa8: Peri<'static, PA8>,
    tim16: Peri<'static, TIM16>,
    pa6: Peri<'static, PA6>,
) -> bool {
    // SAFETY: the probe's drivers are forgotten or dropped before the pins are used again.
    if !jumper_probe(unsafe { pa8.clone_unchecked() }, unsafe {
        pa6.clone_unchecked()
    }) {
        defmt::println!(
            "FAIL pulse: no jumper D7 (PA8) -> D12 (PA6) found with weak pulls alone (not fitted, or a pull-down or interface stage on D7): PA8, wheelset 1's output, not driven; the break check not run"
        );
        return false;
    }
    let config = RigConfig::nucleo_g474re();
    let timer: PulseTimer = config.pulse_timer;
    let mut out = PulseOut::new(
        Timer::new(tim1),
        || PwmPin::new(pa8, OutputType::PushPull),
        &timer.silent(),
    );
    let radius = Params::default().vehicle.wheel_radius as f32;
    let regs = pulse_test_registers(&timer, config.teeth, radius);
    out.write(&regs);
    let expected_hz = timer.frequency_of(&regs);

    let capture = Timer::new(tim16);
    let mut pin = Flex::new(pa6);
    pin.set_as_af_unchecked(1, AfType::input(Pull::None));
    let t16 = pac::TIM16;
    t16.psc().write_value(CAPTURE_PSC);
    t16.arr().write(|w| w.set_arr(0xFFFF));
    t16.egr().write(|w| w.set_ug(true));
    t16.ccmr_input(0)
        .modify(|w| w.set_ccs(0, CcmrInputCcs::TI4));
    t16.ccer().modify(|w| w.set_cce(0, true));
    t16.sr().write(|w| w.0 = 0);
    capture.start();

    // Two periods of the test frequency, with margin.
    let timeout = (3.0 * CPU_HZ as f64 / expected_hz) as u32;
    let mut c = PulseCapture::default();
    let mut edges = true;
    for _ in 0..=PERIODS {
        match next_capture(timeout) {
            Some(v) => c.capture(v),
            None => {
                edges = false;
                break;
            }
        }
    }
    // The break: MOE cleared by hardware, the output at its idle level (low), no edge.
    let tim = out.regs();
    tim.egr().write(|w| w.set_bg(0, true));
    t16.sr().write(|w| w.0 = 0);
    let quiet = next_capture(timeout).is_none();
    let low = pac::GPIOA.idr().read().0 & (1 << 8) == 0;
    let broke = !tim.bdtr().read().moe() && quiet && low;
    capture.stop();
    out.write(&timer.silent());
    // PA8 back to a GPIO output driven low (the timer drives it low now: no edge), then the
    // driver forgotten: dropping it would leave the pin analog, undriven.
    let (port, pin) = PULSE_PINS[0];
    drive_low(port, pin);
    core::mem::forget(out);
    let pass = edges && c.matches(PULSE_CAPTURE_HZ, expected_hz, 100);
    defmt::println!(
        "{=str} break: software break on TIM1: MOE cleared {=bool}, no edge after it {=bool}, PA8 low {=bool} (the path of a lockup, SYSCFG_CFGR2.CLL {=bool})",
        verdict(broke),
        !tim.bdtr().read().moe(),
        quiet,
        low,
        pac::SYSCFG.cfgr2().read().cll()
    );
    defmt::println!(
        "{=str} pulse: D7 (PA8) -> D12 (PA6): {=f32} Hz measured over {=u32} periods (min {=u32}, max {=u32} counts at {=u32} Hz), {=f32} Hz set for {=f32} km/h (PSC {=u16}, ARR {=u32}){=str}",
        verdict(pass),
        c.frequency_hz(PULSE_CAPTURE_HZ) as f32,
        c.periods,
        c.min_counts,
        c.max_counts,
        PULSE_CAPTURE_HZ,
        expected_hz as f32,
        PULSE_TEST_SPEED_KMH,
        regs.psc,
        regs.arr,
        if edges {
            ""
        } else {
            "; no edges: fit the jumper D7-D12"
        }
    );
    pass && broke
}
