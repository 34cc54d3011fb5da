//! The load-weighing signal the board gives the controller: the air-spring pressure of each
//! bogie, as the pressure transducers the controller expects would show it, on a DAC output.
//!
//! The plant's secondary (air) suspension carries the carbody on the two bogies
//! ([`hils_plant::Plant::air_spring_forces`]: the static half of the carbody's weight plus the
//! spring and damper deviation, so the pitch load transfer in braking moves it). The
//! air-spring pressure is that force over the bogie's effective air-spring area
//! ([`LoadConfig::area_cm2`], the two springs of a bogie together; default 0.34 m^2: 5.0 bar
//! for the 35 t reference carbody, 3.7 bar tare). The transducer characteristic is linear
//! with a live zero: [`LoadConfig::zero_mv`] at 0 Pa, [`LoadConfig::full_mv`] at
//! [`LoadConfig::full_scale_hpa`] (default 0.5-4.5 V for 0-10 bar). The DAC (12 bit,
//! reference VREF+ = VDDA = 3.3 V on the NUCLEO) gives at most 3.3 V: an external
//! non-inverting stage of gain [`LoadConfig::stage_gain_permille`] (default 2.0) brings it
//! to the controller's range (docs/rig.md, "Controller I/O"). Silent (safe state, not armed,
//! every fault): code 0, 0 V at the controller, below the live zero, which a controller reads
//! as a transducer fault.

use crate::WHEELSETS;

/// DAC reference, mV (VREF+ tied to VDDA = 3.3 V on the NUCLEO-G474RE).
pub const DAC_VREF_MV: f32 = 3300.0;
/// Largest 12-bit DAC code.
pub const DAC_MAX_CODE: u16 = 4095;
/// Bogies (one air-spring signal each): bogie 1 carries wheelsets 1 and 2.
pub const BOGIES: usize = WHEELSETS / 2;

/// The transducer characteristic and the stage between the DAC and the controller.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LoadConfig {
    /// Signal at 0 Pa at the controller, mV.
    pub zero_mv: u16,
    /// Signal at the full scale at the controller, mV.
    pub full_mv: u16,
    /// Full-scale pressure, hPa (10 000 = 10 bar).
    pub full_scale_hpa: u16,
    /// Gain of the stage from the DAC pin to the controller, per mille (2000 = x2).
    pub stage_gain_permille: u16,
    /// Effective air-spring area of one bogie (its springs together), cm^2.
    pub area_cm2: u16,
}

impl LoadConfig {
    /// 0.5-4.5 V for 0-10 bar behind a x2 stage, 0.34 m^2 per bogie.
    pub const DEFAULT: Self = Self {
        zero_mv: 500,
        full_mv: 4500,
        full_scale_hpa: 10_000,
        stage_gain_permille: 2000,
        area_cm2: 3400,
    };

    fn area_m2(&self) -> f32 {
        self.area_cm2 as f32 * 1e-4
    }

    fn full_scale_pa(&self) -> f32 {
        self.full_scale_hpa as f32 * 100.0
    }

    fn gain(&self) -> f32 {
        self.stage_gain_permille as f32 * 1e-3
    }

    /// Air-spring pressure of a bogie carrying `force_n` (N), Pa (gauge).
    pub fn pressure_pa(&self, force_n: f32) -> f32 {
        force_n / self.area_m2()
    }

    /// The bogie force an air-spring pressure (Pa) means, N: what a controller's load
    /// weighing computes.
    pub fn force_n(&self, pressure_pa: f32) -> f32 {
        pressure_pa * self.area_m2()
    }

    /// The DAC code that shows `pressure_pa` at the controller, limited to the transducer's
    /// range (0 .. full scale) and the DAC's; NaN gives the zero-pressure signal.
    pub fn dac_code(&self, pressure_pa: f32) -> u16 {
        let share = (pressure_pa / self.full_scale_pa()).clamp(0.0, 1.0);
        let share = if share.is_nan() { 0.0 } else { share };
        let mv = self.zero_mv as f32 + (self.full_mv as f32 - self.zero_mv as f32) * share;
        let code = mv / self.gain() / DAC_VREF_MV * DAC_MAX_CODE as f32 + 0.5;
        (code as u32).min(DAC_MAX_CODE as u32) as u16
    }

    /// The signal at the controller of a DAC code, mV.
    pub fn signal_mv(&self, code: u16) -> f32 {
        code.min(DAC_MAX_CODE) as f32 * DAC_VREF_MV / DAC_MAX_CODE as f32 * self.gain()
    }

    /// The pressure a controller reads from the signal of a DAC code, Pa; `None` below the
    /// live zero by more than 2 % of the span or above the full scale by as much (a
    /// transducer fault to the controller: the silent output reads so).
    pub fn read_pa(&self, code: u16) -> Option<f32> {
        let (zero, full) = (self.zero_mv as f32, self.full_mv as f32);
        let share = (self.signal_mv(code) - zero) / (full - zero);
        (-0.02..=1.02)
            .contains(&share)
            .then(|| share.max(0.0) * self.full_scale_pa())
    }

    /// Whether the transducer's range fits the stage (full scale within the DAC's reach).
    pub fn fits(&self) -> bool {
        self.zero_mv < self.full_mv
            && self.full_mv as f32 <= DAC_VREF_MV * self.gain()
            && self.area_cm2 > 0
            && self.full_scale_hpa > 0
    }
}

impl Default for LoadConfig {
    fn default() -> Self {
        Self::DEFAULT
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_reference_carbody_shows_5_bar_and_reads_back_within_a_code() {
        let c = LoadConfig::DEFAULT;
        assert!(c.fits());
        // Half the 35 t carbody's weight per bogie on 0.34 m^2.
        let force = 0.5 * 35_000.0 * 9.81;
        let p = c.pressure_pa(force);
        assert!((p - 5.05e5).abs() < 1e3, "{p} Pa");
        let code = c.dac_code(p);
        // An independent evaluation: 0.5 V + 4 V x 5.05 bar / 10 bar at the controller,
        // halved by the stage, over 3.3 V / 4095.
        let expect = ((0.5 + 4.0 * p as f64 / 1e6) / 2.0 / 3.3 * 4095.0).round() as u16;
        assert_eq!(code, expect);
        let back = c.read_pa(code).unwrap();
        // One code: 3.3 V / 4095 x 2 = 1.6 mV = 403 Pa.
        assert!((back - p).abs() <= 403.0, "{back} vs {p}");
        assert!((c.force_n(back) - force).abs() / force < 1e-3);
        // Live zero: 0 Pa is 0.5 V, not 0 V; 0 V (the silent output) is no reading.
        assert!((c.signal_mv(c.dac_code(0.0)) - 500.0).abs() < 1.0);
        assert_eq!(c.read_pa(0), None);
        assert_eq!(c.dac_code(f32::NAN), c.dac_code(0.0));
        // Above the full scale: held at 4.5 V.
        assert_eq!(c.dac_code(2e6), c.dac_code(1e6));
    }

    #[test]
    fn a_range_beyond_the_stage_does_not_fit() {
        let mut c = LoadConfig::DEFAULT;
        c.stage_gain_permille = 1000;
        assert!(!c.fits(), "4.5 V from a 3.3 V DAC without gain");
        c.stage_gain_permille = 2000;
        c.zero_mv = 4600;
        assert!(!c.fits());
    }

    proptest::proptest! {
        #[test]
        fn any_pressure_reads_back_within_a_code(p in 0.0f32..1e6) {
            let c = LoadConfig::DEFAULT;
            let back = c.read_pa(c.dac_code(p)).unwrap();
            proptest::prop_assert!((back - p).abs() <= 403.0);
        }
    }
}
