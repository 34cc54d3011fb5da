//! SYSCLK against a clock that does not come from it: TIM16 (at SYSCLK, PSC 0) captures
//! every 8th edge of the LSE (crystal X2, 32.768 kHz) or, without it, of the LSI, selected
//! inside the chip by TIM16_TISEL (no pin). Every other clock check compares two clocks
//! derived from SYSCLK; a crystal X3 of the wrong frequency fails here.

use embassy_stm32::Peri;
use embassy_stm32::pac;
use embassy_stm32::pac::timer::vals::CcmrInputCcs;
use embassy_stm32::peripherals::TIM16;
use embassy_stm32::timer::low_level::Timer;
use embassy_time::{Duration, Instant, Timer as Delay};
use hils_rig_core::bringup::{PulseCapture, ReferenceClock, sysclk_from_reference, sysclk_matches};

use super::verdict;
use crate::step::CPU_HZ;

/// Captures per measurement (64 x 8 LSE periods = 15.6 ms).
const CAPTURES: u32 = 64;
/// LSE start-up allowed (datasheet: up to 2 s typical at the lowest drive).
const LSE_START: Duration = Duration::from_millis(2500);

/// Starts `clock`; `false` if it is not ready in time.
async fn start(clock: ReferenceClock) -> bool {
    let deadline = Instant::now() + LSE_START;
    let ready = || match clock {
        ReferenceClock::Lse => pac::RCC.bdcr().read().lserdy(),
        ReferenceClock::Lsi => pac::RCC.csr().read().lsirdy(),
    };
    match clock {
        ReferenceClock::Lse => {
            // Backup domain write access (PWR_CR1.DBP), then LSEON.
            pac::PWR.cr1().modify(|w| w.set_dbp(true));
            pac::RCC.bdcr().modify(|w| w.set_lseon(true));
        }
        ReferenceClock::Lsi => pac::RCC.csr().modify(|w| w.set_lsion(true)),
    }
    while !ready() {
        if Instant::now() > deadline {
            return false;
        }
        Delay::after_millis(10).await;
    }
    true
}

/// Captures of every 8th edge of `clock`, polled (no interrupt mask: the capture holds the
/// counter value; an overcapture flag means one was missed, and the run starts again).
fn capture(clock: ReferenceClock) -> Option<PulseCapture> {
    let t16 = pac::TIM16;
    t16.cr1().modify(|w| w.set_cen(false));
    t16.psc().write_value(0);
    t16.arr().write(|w| w.set_arr(0xFFFF));
    t16.tisel().write(|w| w.set_tisel(0, clock.tisel()));
    t16.ccmr_input(0).modify(|w| {
        w.set_ccs(0, CcmrInputCcs::TI4);
        w.set_icpsc(0, 3);
    });
    t16.ccer().modify(|w| w.set_cce(0, true));
    t16.egr().write(|w| w.set_ug(true));
    t16.sr().write(|w| w.0 = 0);
    t16.cr1().modify(|w| w.set_cen(true));
    // Three capture intervals of the slowest reference (LSI at 29.5 kHz), in cycles.
    let timeout = 3 * 8 * (CPU_HZ / 29_500);
    for _attempt in 0..3 {
        let mut c = PulseCapture::default();
        let mut missed = false;
        for _ in 0..=CAPTURES {
            let start = cortex_m::peripheral::DWT::cycle_count();
            while !t16.sr().read().ccif(0) {
                if cortex_m::peripheral::DWT::cycle_count().wrapping_sub(start) > timeout {
                    return None;
                }
            }
            // Reading CCR1 clears CC1IF.
            c.capture(t16.ccr(0).read().ccr() as u16);
            if t16.sr().read().ccof(0) {
                t16.sr().write(|w| w.0 = 0);
                missed = true;
                break;
            }
        }
        if !missed {
            t16.cr1().modify(|w| w.set_cen(false));
            return Some(c);
        }
    }
    None
}

/// SYSCLK measured against the LSE (if X2 starts) or the LSI, within the reference's
/// tolerance (`hils_rig_core::bringup::sysclk_matches`).
pub async fn sysclk_against_reference(tim16: Peri<'static, TIM16>) -> bool {
    let _clock_on = Timer::new(tim16);
    let reference = if start(ReferenceClock::Lse).await {
        ReferenceClock::Lse
    } else {
        let _ = start(ReferenceClock::Lsi).await;
        ReferenceClock::Lsi
    };
    let got = capture(reference);
    let (lo, hi) = reference.sysclk_range_hz();
    let (pass, measured) = match &got {
        Some(c) => (
            sysclk_matches(c, reference),
            sysclk_from_reference(c, reference),
        ),
        None => (false, 0.0),
    };
    defmt::println!(
        "{=str} sysclk: {=f32} MHz measured against the {=str} ({=f32} Hz nominal; passes {=f32}..{=f32} MHz){=str}",
        verdict(pass),
        (measured / 1e6) as f32,
        match reference {
            ReferenceClock::Lse => "LSE (crystal X2)",
            ReferenceClock::Lsi => "LSI (X2 did not start: +-7 % only)",
        },
        reference.nominal_hz() as f32,
        (lo / 1e6) as f32,
        (hi / 1e6) as f32,
        if got.is_none() { "; no captures" } else { "" }
    );
    pass
}
