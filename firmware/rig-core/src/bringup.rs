//! The pass/fail rules of the board's bring-up self-test (`cargo board-run --features
//! bringup`): what a bare NUCLEO-G474RE can check alone. The board reads the registers and
//! counters; the arithmetic and the limits are here, tested on the host.
//!
//! Sources: RM0440 (flash wait states, Table "Number of wait states according to CPU clock
//! (HCLK) frequency", range 1 boost: <= 34/68/102/136/170 MHz for 0..4 WS, the same table as
//! ST's `stm32g4xx_ll_utils.c`), ST's `stm32g4xx_ll_adc.h` (factory calibration: VREFINT_CAL
//! at 0x1FFF_75AA and TS_CAL1/TS_CAL2 at 0x1FFF_75A8/0x1FFF_75CA, taken at VREF+ = 3.0 V and
//! 30/130 degC; `__LL_ADC_CALC_VREFANALOG_VOLTAGE` and `__LL_ADC_CALC_TEMPERATURE`).

/// The NUCLEO-G474RE's crystal X3, Hz.
pub const HSE_HZ: u32 = 24_000_000;
/// The system clock the board runs at, Hz.
pub const SYSCLK_HZ: u32 = 170_000_000;

/// VREF+ at which the factory calibration values were taken, mV.
pub const CAL_VREF_MV: u32 = 3000;
/// Temperatures of TS_CAL1 and TS_CAL2, degC.
pub const TS_CAL1_DEGC: f32 = 30.0;
/// Temperature of TS_CAL2, degC.
pub const TS_CAL2_DEGC: f32 = 130.0;

/// The NUCLEO's 3.3 V supply +-5 % (what VDDA from VREFINT must show), mV.
pub const VDDA_RANGE_MV: (u32, u32) = (3135, 3465);
/// A die temperature believable on a bench, degC.
pub const DIE_TEMPERATURE_RANGE_DEGC: (f32, f32) = (5.0, 70.0);

/// Flash wait states RM0440 asks for at `hclk_hz` (range 1; `boost` = R1MODE cleared).
pub fn flash_wait_states(hclk_hz: u32, boost: bool) -> u8 {
    let step = if boost { 34_000_000 } else { 30_000_000 };
    let ws = hclk_hz.saturating_sub(1) / step;
    ws.min(4) as u8
}

/// The PLL's R output, Hz: `src / M x N / R`.
pub fn pll_r_hz(src_hz: u32, m: u32, n: u32, r: u32) -> u32 {
    if m == 0 || r == 0 {
        return 0;
    }
    ((src_hz as u64 / m as u64) * n as u64 / r as u64) as u32
}

/// The clock tree as read back from RCC, PWR and FLASH.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ClockReadback {
    /// RCC_CR.HSERDY.
    pub hse_ready: bool,
    /// RCC_CR.PLLRDY.
    pub pll_ready: bool,
    /// RCC_CFGR.SWS = PLL.
    pub sysclk_is_pll: bool,
    /// RCC_PLLCFGR.PLLSRC = HSE.
    pub pll_from_hse: bool,
    /// Dividers and multiplier as values (M 1..16, N 8..127, R 2/4/6/8).
    pub pll_m: u32,
    /// PLL multiplier N (8..127).
    pub pll_n: u32,
    /// PLL divider R of the system clock (2, 4, 6 or 8).
    pub pll_r: u32,
    /// AHB prescaler as a divider.
    pub ahb_div: u32,
    /// FLASH_ACR.LATENCY.
    pub flash_ws: u8,
    /// PWR_CR5.R1MODE cleared.
    pub boost: bool,
}

/// What is wrong with the clock tree (the first finding).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ClockFault {
    /// The external crystal (HSE) did not become ready.
    HseNotReady,
    /// The PLL did not lock.
    PllNotReady,
    /// The system clock is not switched to the PLL.
    SysclkNotPll,
    /// The PLL does not run from the HSE.
    PllNotFromHse,
    /// SYSCLK from the PLL settings, Hz.
    WrongFrequency(u32),
    /// Wait states set, wait states needed.
    FlashLatency(u8, u8),
    /// 170 MHz needs range 1 boost mode.
    NoBoost,
}

impl ClockReadback {
    /// SYSCLK from the PLL settings, Hz.
    pub fn sysclk_hz(&self) -> u32 {
        pll_r_hz(HSE_HZ, self.pll_m, self.pll_n, self.pll_r)
    }

    /// HCLK, Hz.
    pub fn hclk_hz(&self) -> u32 {
        self.sysclk_hz() / self.ahb_div.max(1)
    }

    /// The board's clock tree: HSE 24 MHz -> PLL -> 170 MHz, boost, 4 wait states.
    pub fn check(&self) -> Result<u32, ClockFault> {
        if !self.hse_ready {
            return Err(ClockFault::HseNotReady);
        }
        if !self.pll_ready {
            return Err(ClockFault::PllNotReady);
        }
        if !self.sysclk_is_pll {
            return Err(ClockFault::SysclkNotPll);
        }
        if !self.pll_from_hse {
            return Err(ClockFault::PllNotFromHse);
        }
        let f = self.sysclk_hz();
        if f != SYSCLK_HZ || self.ahb_div != 1 {
            return Err(ClockFault::WrongFrequency(f));
        }
        if !self.boost {
            return Err(ClockFault::NoBoost);
        }
        let need = flash_wait_states(self.hclk_hz(), self.boost);
        if self.flash_ws != need {
            return Err(ClockFault::FlashLatency(self.flash_ws, need));
        }
        Ok(f)
    }
}

/// A timer period measured with the cycle counter: `cycles` over `periods` periods.
/// Passes within `tolerance_ppm` of `expected_hz` at `cpu_hz`.
pub fn period_matches(
    cycles: u64,
    periods: u32,
    cpu_hz: u32,
    expected_hz: u32,
    tolerance_ppm: u32,
) -> bool {
    if periods == 0 || cycles == 0 || expected_hz == 0 {
        return false;
    }
    let expected = cpu_hz as f64 / expected_hz as f64 * periods as f64;
    ((cycles as f64 - expected) / expected).abs() * 1e6 <= tolerance_ppm as f64
}

/// The factory calibration values of the ADC (system memory).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AdcFactoryCal {
    /// VREFINT_CAL: internal reference reading at [`CAL_VREF_MV`], ADC counts.
    pub vrefint_cal: u16,
    /// TS_CAL1: temperature sensor reading at [`TS_CAL1_DEGC`], ADC counts.
    pub ts_cal1: u16,
    /// TS_CAL2: temperature sensor reading at [`TS_CAL2_DEGC`], ADC counts.
    pub ts_cal2: u16,
}

impl AdcFactoryCal {
    /// Plausible values: VREFINT (1.182..1.232 V in the datasheet, read at 3.0 V: ~1614..1682
    /// counts, wider here) and a rising temperature line.
    pub fn plausible(&self) -> bool {
        (1500..=1800).contains(&self.vrefint_cal) && self.ts_cal2 > self.ts_cal1 && self.ts_cal1 > 0
    }
}

/// VDDA from a VREFINT conversion (12 bit), mV: 3000 x VREFINT_CAL / VREFINT_DATA.
pub fn vdda_mv(cal: &AdcFactoryCal, vrefint_data: u16) -> u32 {
    if vrefint_data == 0 {
        return 0;
    }
    CAL_VREF_MV * cal.vrefint_cal as u32 / vrefint_data as u32
}

/// Die temperature from a temperature-sensor conversion (12 bit) at `vdda_mv`, degC: the
/// conversion is scaled to the calibration's 3.0 V, then placed on the line through
/// (TS_CAL1, 30 degC) and (TS_CAL2, 130 degC).
pub fn die_temperature_c(cal: &AdcFactoryCal, ts_data: u16, vdda_mv: u32) -> f32 {
    let span = cal.ts_cal2 as f32 - cal.ts_cal1 as f32;
    if span <= 0.0 {
        return f32::NAN;
    }
    let at_cal_vref = ts_data as f32 * vdda_mv as f32 / CAL_VREF_MV as f32;
    (at_cal_vref - cal.ts_cal1 as f32) * (TS_CAL2_DEGC - TS_CAL1_DEGC) / span + TS_CAL1_DEGC
}

/// Probes of the pulse check's jumper: D7 (PA8) left undriven with the chip's weak pull-up,
/// then pull-down, alternately; D12 (PA6) read each time.
pub const JUMPER_PROBES: usize = 6;

/// Whether the jumper D7-D12 is fitted and nothing else is on D7, from the probes
/// `(d7_pulled_up, d12_high)`: D12 followed every weak pull of D7, up and down. A rig's
/// pull-down on the pulse line (docs/rig.md, "Lines in reset") or an interface stage
/// overrides the weak pull-up, and an open D12 does not follow both ways: then PA8, wheelset
/// 1's output to a controller, is never driven by the bring-up image.
pub fn jumper_found(probes: &[(bool, bool)]) -> bool {
    probes.iter().any(|p| p.0)
        && probes.iter().any(|p| !p.0)
        && probes.iter().all(|&(up, high)| up == high)
}

/// Speed the pulse check sets on wheelset 1's output, km/h.
pub const PULSE_TEST_SPEED_KMH: f32 = 150.0;
/// The capture timer's clock: 170 MHz / 4, so one period of the test frequency fits its
/// 16-bit counter.
pub const PULSE_CAPTURE_HZ: u32 = SYSCLK_HZ / 4;

/// The pulse registers the check writes: [`PULSE_TEST_SPEED_KMH`] on a wheel of
/// `wheel_radius_m`, through the rig's own pulse code (`teeth` teeth). The check writes
/// them once, without the step's per-period dither, so they carry no fraction: every
/// period is ARR + 1 counts and `PulseTimer::frequency_of` is the frequency on the pin.
pub fn pulse_test_registers(
    timer: &crate::pulse::PulseTimer,
    teeth: u16,
    wheel_radius_m: f32,
) -> crate::pulse::PulseRegisters {
    let omega = PULSE_TEST_SPEED_KMH / crate::KMH_PER_MPS / wheel_radius_m;
    crate::pulse::PulseRegisters {
        arr_frac: 0,
        ..timer.registers(crate::pulse::wheel_frequency_hz(omega, teeth))
    }
}

/// A pulse train measured by input capture: the counts between successive rising edges.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct PulseCapture {
    /// Periods captured.
    pub periods: u32,
    /// Sum of the periods, timer counts.
    pub total_counts: u64,
    /// Shortest period, timer counts.
    pub min_counts: u32,
    /// Longest period, timer counts.
    pub max_counts: u32,
    last: Option<u16>,
}

impl PulseCapture {
    /// Adds a captured counter value (a free-running 16-bit counter; one period must be
    /// shorter than its wrap).
    pub fn capture(&mut self, value: u16) {
        if let Some(last) = self.last {
            let d = value.wrapping_sub(last) as u32;
            if self.periods == 0 {
                self.min_counts = d;
                self.max_counts = d;
            }
            self.min_counts = self.min_counts.min(d);
            self.max_counts = self.max_counts.max(d);
            self.total_counts += d as u64;
            self.periods += 1;
        }
        self.last = Some(value);
    }

    /// Mean frequency at a capture clock of `clock_hz`, Hz.
    pub fn frequency_hz(&self, clock_hz: u32) -> f64 {
        if self.total_counts == 0 {
            return 0.0;
        }
        clock_hz as f64 * self.periods as f64 / self.total_counts as f64
    }

    /// Passes when every period is within 1 % of the expected one (no edge missed or extra)
    /// and the mean frequency within `tolerance_ppm`.
    pub fn matches(&self, clock_hz: u32, expected_hz: f64, tolerance_ppm: u32) -> bool {
        if self.periods == 0 || expected_hz <= 0.0 {
            return false;
        }
        let expected_counts = clock_hz as f64 / expected_hz;
        let each_ok = [self.min_counts, self.max_counts]
            .iter()
            .all(|&c| ((c as f64 - expected_counts) / expected_counts).abs() <= 0.01);
        let f = self.frequency_hz(clock_hz);
        each_ok && ((f - expected_hz) / expected_hz).abs() * 1e6 <= tolerance_ppm as f64
    }
}

/// An independent clock the bring-up measures SYSCLK against (TIM16 input capture of its TI1
/// selected by TIM16_TISEL: 1 LSI, 2 LSE; RM0440 TIM16 and ST's `TIM_TIM16_TI1_LSI/LSE`).
/// Every check before compares two clocks derived from SYSCLK: a crystal of the wrong
/// frequency passed them all.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ReferenceClock {
    /// The 32.768 kHz crystal X2 (LSE): tens of ppm.
    Lse,
    /// The internal 32 kHz RC (LSI): 29.5..34 kHz over the G474's range (datasheet).
    Lsi,
}

impl ReferenceClock {
    /// The TIM16_TISEL.TI1SEL code of this clock.
    pub fn tisel(self) -> u8 {
        match self {
            ReferenceClock::Lsi => 1,
            ReferenceClock::Lse => 2,
        }
    }

    /// Nominal frequency, Hz.
    pub fn nominal_hz(self) -> f64 {
        match self {
            ReferenceClock::Lse => 32_768.0,
            ReferenceClock::Lsi => 32_000.0,
        }
    }

    /// The range of SYSCLK estimates that passes, Hz: LSE +-500 ppm (both crystals' tolerance
    /// and ageing, with margin); LSI the frequencies its 29.5..34 kHz spread allows.
    pub fn sysclk_range_hz(self) -> (f64, f64) {
        let f = SYSCLK_HZ as f64;
        match self {
            ReferenceClock::Lse => (f * (1.0 - 500e-6), f * (1.0 + 500e-6)),
            ReferenceClock::Lsi => (f * 29_500.0 / 32_000.0, f * 34_000.0 / 32_000.0),
        }
    }
}

/// Reference edges per capture (TIM16 input prescaler /8): an LSE period of 5188 counts at
/// 170 MHz becomes 41 504, still within the 16-bit counter.
pub const REFERENCE_EDGES_PER_CAPTURE: u32 = 8;

/// SYSCLK as the reference clock measures it, Hz: the timer counts SYSCLK (PSC 0) between
/// captures of every [`REFERENCE_EDGES_PER_CAPTURE`]-th reference edge.
pub fn sysclk_from_reference(capture: &PulseCapture, reference: ReferenceClock) -> f64 {
    if capture.periods == 0 {
        return 0.0;
    }
    let counts_per_edge =
        capture.total_counts as f64 / capture.periods as f64 / REFERENCE_EDGES_PER_CAPTURE as f64;
    counts_per_edge * reference.nominal_hz()
}

/// Whether SYSCLK measured against `reference` is 170 MHz within its tolerance, with every
/// capture interval within 1 % of the mean (no capture missed).
pub fn sysclk_matches(capture: &PulseCapture, reference: ReferenceClock) -> bool {
    let f = sysclk_from_reference(capture, reference);
    let (lo, hi) = reference.sysclk_range_hz();
    let mean = capture.total_counts as f64 / capture.periods.max(1) as f64;
    let steady = [capture.min_counts, capture.max_counts]
        .iter()
        .all(|&c| ((c as f64 - mean) / mean).abs() <= 0.01);
    capture.periods > 0 && steady && (lo..=hi).contains(&f)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_jumper_is_found_only_when_d12_follows_both_pulls() {
        let probes = |d12: &dyn Fn(bool, usize) -> bool| -> [(bool, bool); JUMPER_PROBES] {
            core::array::from_fn(|k| (k % 2 == 0, d12(k % 2 == 0, k)))
        };
        // Fitted, nothing else on the line.
        assert!(jumper_found(&probes(&|up, _| up)));
        // A rig's pull-down (or a stage input) holds D7 low: never high.
        assert!(!jumper_found(&probes(&|_, _| false)));
        // A pull-up elsewhere, or D12 open and reading high: never low.
        assert!(!jumper_found(&probes(&|_, _| true)));
        // An open D12 that happens to follow once, then not.
        assert!(!jumper_found(&probes(&|up, k| if k < 2 {
            up
        } else {
            k % 3 == 0
        })));
        // Only one direction probed decides nothing.
        assert!(!jumper_found(&[(true, true)]));
        assert!(!jumper_found(&[]));
    }

    #[test]
    fn wait_states_follow_the_rm0440_table() {
        // Range 1 boost: 0 WS <= 34 MHz ... 4 WS <= 170 MHz; normal: steps of 30 MHz.
        let boost = [
            (34_000_000, 0),
            (34_000_001, 1),
            (68_000_000, 1),
            (102_000_000, 2),
            (136_000_000, 3),
            (136_000_001, 4),
            (170_000_000, 4),
        ];
        let normal = [
            (30_000_000, 0),
            (60_000_000, 1),
            (90_000_000, 2),
            (120_000_000, 3),
            (150_000_000, 4),
        ];
        let rows = boost
            .iter()
            .map(|r| (r, true))
            .chain(normal.iter().map(|r| (r, false)));
        for (&(f, ws), boost) in rows {
            assert_eq!(flash_wait_states(f, boost), ws, "{f} Hz, boost {boost}");
        }
    }

    fn board() -> ClockReadback {
        ClockReadback {
            hse_ready: true,
            pll_ready: true,
            sysclk_is_pll: true,
            pll_from_hse: true,
            pll_m: 6,
            pll_n: 85,
            pll_r: 2,
            ahb_div: 1,
            flash_ws: 4,
            boost: true,
        }
    }

    #[test]
    fn the_board_clock_tree_passes_and_each_fault_is_named() {
        assert_eq!(board().check(), Ok(170_000_000));
        assert_eq!(
            ClockReadback {
                hse_ready: false,
                ..board()
            }
            .check(),
            Err(ClockFault::HseNotReady)
        );
        assert_eq!(
            ClockReadback {
                pll_from_hse: false,
                ..board()
            }
            .check(),
            Err(ClockFault::PllNotFromHse)
        );
        assert_eq!(
            ClockReadback {
                pll_m: 4,
                ..board()
            }
            .check(),
            Err(ClockFault::WrongFrequency(255_000_000))
        );
        assert_eq!(
            ClockReadback {
                flash_ws: 3,
                ..board()
            }
            .check(),
            Err(ClockFault::FlashLatency(3, 4))
        );
        assert_eq!(
            ClockReadback {
                boost: false,
                ..board()
            }
            .check(),
            Err(ClockFault::NoBoost)
        );
    }

    #[test]
    fn adc_formulas_match_st_ll_macros() {
        // __LL_ADC_CALC_VREFANALOG_VOLTAGE: 3000 * CAL / DATA (integer).
        let cal = AdcFactoryCal {
            vrefint_cal: 1656,
            ts_cal1: 1040,
            ts_cal2: 1380,
        };
        assert!(cal.plausible());
        assert_eq!(vdda_mv(&cal, 1505), 3300);
        // __LL_ADC_CALC_TEMPERATURE (integer): ((DATA*VDDA/3000 - CAL1) * 100) / (CAL2 - CAL1) + 30.
        for data in [900u16, 1000, 1100, 1200] {
            let ll = ((data as i32 * 3300 / 3000 - 1040) * 100) / (1380 - 1040) + 30;
            let t = die_temperature_c(&cal, data, 3300);
            assert!((t - ll as f32).abs() < 1.0, "{data}: {t} vs {ll}");
        }
        assert!(
            !AdcFactoryCal {
                vrefint_cal: 0xFFFF,
                ..cal
            }
            .plausible()
        );
    }

    #[test]
    fn pulse_capture_counts_wrapping_periods_and_finds_a_missed_edge() {
        let mut c = PulseCapture::default();
        let mut v: u16 = 60_000;
        for _ in 0..=100 {
            c.capture(v);
            v = v.wrapping_add(30_600);
        }
        assert_eq!(c.periods, 100);
        assert!(c.matches(42_500_000, 42_500_000.0 / 30_600.0, 10));
        assert!(!c.matches(42_500_000, 1000.0, 10));
        // One edge lost: one period twice as long.
        c.capture(v.wrapping_add(30_600));
        assert!(!c.matches(42_500_000, 42_500_000.0 / 30_600.0, 20_000));
    }

    #[test]
    fn period_check() {
        assert!(period_matches(17_000 * 1000, 1000, 170_000_000, 10_000, 1));
        assert!(!period_matches(
            17_001 * 1000,
            1000,
            170_000_000,
            10_000,
            10
        ));
        assert!(!period_matches(0, 0, 170_000_000, 10_000, 10));
    }

    /// Captures of every 8th edge of a reference at `ref_hz` by a timer at `sysclk_hz`.
    fn reference_capture(sysclk_hz: f64, ref_hz: f64, n: u32) -> PulseCapture {
        let mut c = PulseCapture::default();
        for k in 0..=n {
            let t = k as f64 * REFERENCE_EDGES_PER_CAPTURE as f64 / ref_hz;
            c.capture((t * sysclk_hz).round() as u64 as u16);
        }
        c
    }

    #[test]
    fn a_wrong_crystal_fails_against_the_lse_and_a_far_one_against_the_lsi() {
        let lse = ReferenceClock::Lse;
        let right = reference_capture(170e6, 32_768.0, 64);
        assert!(sysclk_matches(&right, lse));
        assert!((sysclk_from_reference(&right, lse) - 170e6).abs() < 170.0);
        // A 25 MHz crystal where 24 MHz is assumed: SYSCLK 177.08 MHz, +4.2 %.
        let wrong = reference_capture(170e6 * 25.0 / 24.0, 32_768.0, 64);
        assert!(!sysclk_matches(&wrong, lse));
        // The LSI spreads +-7 %: it passes a 4 % error, but not an 8 MHz crystal (x 1/3).
        let lsi = ReferenceClock::Lsi;
        assert!(sysclk_matches(&reference_capture(170e6, 31_000.0, 64), lsi));
        assert!(sysclk_matches(
            &reference_capture(170e6 * 25.0 / 24.0, 32_000.0, 64),
            lsi
        ));
        assert!(!sysclk_matches(
            &reference_capture(170e6 / 3.0, 32_000.0, 64),
            lsi
        ));
        assert!(!sysclk_matches(&PulseCapture::default(), lse));
        assert_eq!((lse.tisel(), lsi.tisel()), (2, 1));
        // 8 LSE periods at 170 MHz fit the 16-bit counter.
        assert!(REFERENCE_EDGES_PER_CAPTURE as f64 * 170e6 / 32_768.0 < 65_536.0);
    }
}
