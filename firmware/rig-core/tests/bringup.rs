//! The bring-up self-test's fixed settings, checked against the hardware they run on:
//! the pulse check's frequency must be measurable by a 16-bit capture counter, and the
//! figures docs/rig.md lists as expected output are the ones the code produces.

use hils_plant::Params;
use hils_rig_core::bringup::{PULSE_CAPTURE_HZ, PulseCapture, pulse_test_registers};
use hils_rig_core::rig::RigConfig;

#[test]
fn the_pulse_check_fits_a_16_bit_capture_and_matches_the_docs() {
    let config = RigConfig::nucleo_g474re();
    let radius = Params::default().vehicle.wheel_radius as f32;
    let regs = pulse_test_registers(&config.pulse_timer, config.teeth, radius);
    let f = config.pulse_timer.frequency_of(&regs);
    // 150 km/h on the 0.43 m reference wheel, 90 teeth: 96.9 rad/s, 1388 Hz; the period
    // (122 478 counts at 170 MHz) needs prescaler 2 on the 16-bit pulse timer.
    let exact = 90.0 * (150.0 / 3.6 / 0.43) / std::f64::consts::TAU;
    assert!((f - exact).abs() / exact < 1e-4, "{f} Hz vs {exact} Hz");
    assert_eq!(
        (regs.psc, regs.arr),
        (1, 61_239),
        "docs/rig.md expected output"
    );
    let counts = PULSE_CAPTURE_HZ as f64 / f;
    assert!(
        counts < 65_536.0 * 0.99,
        "{counts} counts overflow the capture"
    );
    assert!(counts > 1000.0, "{counts} counts: too coarse");
    // The capture of that train passes; one of twice the frequency does not.
    let mut c = PulseCapture::default();
    let mut v = 0u16;
    let step = counts.round() as u16;
    for _ in 0..=200 {
        c.capture(v);
        v = v.wrapping_add(step);
    }
    assert!(c.matches(PULSE_CAPTURE_HZ, f, 100));
    assert!(!c.matches(PULSE_CAPTURE_HZ, 2.0 * f, 100));
}
