//! Nominal CAN bit timing from the controller's kernel clock, and the oscillator tolerance
//! it gives.
//!
//! A bit is `1 + tseg1 + tseg2` time quanta (tq) of `prescaler / f_kernel` each: the sync
//! segment, then `tseg1` = Prop_Seg + Phase_Seg1 up to the sample point, then `tseg2` =
//! Phase_Seg2. [`nominal_bit_timing`] takes the bit rate exactly (it refuses a kernel clock
//! that does not divide into it), puts the sample point as close to 87.5 % as the quanta
//! allow (CiA's recommendation for classic CAN; ties go to more quanta per bit, i.e. a
//! finer phase-error measurement), and makes the resynchronisation jump width (SJW) as
//! large as the phase segments allow (ISO 11898-1: SJW <= min(Phase_Seg1, Phase_Seg2)).
//!
//! The FDCAN controller merges Prop_Seg and Phase_Seg1 into one field (`NTSEG1`). For the
//! tolerance the split is taken as Phase_Seg1 = Phase_Seg2 (as large as it may be without
//! lengthening the resynchronisation), Prop_Seg = the rest: [`NominalBitTiming::prop_seg_ns`]
//! is then the round-trip delay (2 x (cable + transceiver + controller delays)) the bus may
//! have.
//!
//! **Oscillator tolerance** (ISO 11898-1 / Hartwich and Bassemir, "The Configuration of
//! the CAN Bit Timing", 6th iCC 1999), with all times in tq and `N` the bit time:
//!
//! * (1) `df <= min(Phase_Seg1, Phase_Seg2) / (2 x (13 N - Phase_Seg2))`: resynchronisation
//!   after a stuff error, the worst case of 13 bits without an edge;
//! * (2) `df <= SJW / (20 N)`: 10 bits between edges, both nodes off in opposite directions.
//!
//! `df` is the largest relative deviation each node's clock may have from nominal. The
//! NUCLEO's 24 MHz crystal needs well under 100 ppm; the HSI RC oscillator (+-1 %) needs
//! 10 000 ppm, which no bit timing gives. Register limits: FDCAN_NBTP (RM0440; stm32-metapac
//! `can_fdcan_v1::Nbtp`): NBRP 9 bits, NTSEG1 8 bits, NTSEG2 7 bits, NSJW 7 bits, each
//! holding the value minus one.

/// Sample point the timing aims at, per mille of the bit.
pub const SAMPLE_POINT_TARGET_PERMILLE: u32 = 875;

/// Fewest quanta per bit accepted (the CAN specification's lower bound of the bit time).
pub const MIN_TQ_PER_BIT: u32 = 8;

/// Field limits of the controller's nominal bit timing register.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BitTimingLimits {
    /// Largest bit-rate prescaler.
    pub prescaler_max: u32,
    /// Largest time segment 1 (propagation and phase 1), time quanta.
    pub tseg1_max: u32,
    /// Largest time segment 2 (phase 2), time quanta.
    pub tseg2_max: u32,
    /// Largest synchronisation jump width, time quanta.
    pub sjw_max: u32,
}

impl BitTimingLimits {
    /// STM32G4 FDCAN_NBTP: prescaler 1..512, tseg1 1..256, tseg2 1..128, SJW 1..128.
    /// (embassy-stm32 0.6 carries `seg1` in a `NonZeroU8`, so 255 is the largest it passes.)
    pub const FDCAN: Self = Self {
        prescaler_max: 512,
        tseg1_max: 255,
        tseg2_max: 128,
        sjw_max: 128,
    };
}

/// A nominal bit timing.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct NominalBitTiming {
    /// Controller kernel clock, Hz.
    pub kernel_hz: u32,
    /// Kernel clocks per time quantum.
    pub prescaler: u16,
    /// Prop_Seg + Phase_Seg1, tq.
    pub tseg1: u16,
    /// Phase_Seg2, tq.
    pub tseg2: u8,
    /// Resynchronisation jump width, tq.
    pub sjw: u8,
}

/// The oscillator tolerance of a bit timing, parts per million.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct OscillatorTolerance {
    /// Condition (1): resynchronisation after a stuff error.
    pub resync_ppm: u32,
    /// Condition (2): SJW over 10 bits.
    pub sjw_ppm: u32,
}

impl OscillatorTolerance {
    /// The tolerance: the smaller of the two conditions.
    pub fn ppm(&self) -> u32 {
        self.resync_ppm.min(self.sjw_ppm)
    }
}

/// Why no bit timing was found.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum BitTimingError {
    /// Bit rate zero or above an eighth of the kernel clock.
    BitrateOutOfRange,
    /// The kernel clock is not a whole multiple of the bit rate: the rate would not be exact.
    NotExact,
    /// No prescaler gives a bit of 8..(1 + tseg1_max + tseg2_max) quanta.
    NoQuanta,
}

impl NominalBitTiming {
    /// Quanta per bit.
    pub fn tq_per_bit(&self) -> u32 {
        1 + self.tseg1 as u32 + self.tseg2 as u32
    }

    /// The bit rate this timing gives, bit/s (rounded down).
    pub fn bitrate(&self) -> u32 {
        self.kernel_hz / (self.prescaler as u32 * self.tq_per_bit())
    }

    /// Sample point, per mille of the bit (rounded down).
    pub fn sample_point_permille(&self) -> u32 {
        1000 * (1 + self.tseg1 as u32) / self.tq_per_bit()
    }

    /// Phase_Seg1 with the split of the module doc: Phase_Seg2, or less if tseg1 is short
    /// (Prop_Seg keeps at least one quantum).
    pub fn phase_seg1(&self) -> u32 {
        (self.tseg2 as u32).min((self.tseg1 as u32).saturating_sub(1))
    }

    /// Prop_Seg, tq (tseg1 - Phase_Seg1).
    pub fn prop_seg(&self) -> u32 {
        self.tseg1 as u32 - self.phase_seg1()
    }

    /// One time quantum, ns.
    pub fn tq_ns(&self) -> f64 {
        1e9 * self.prescaler as f64 / self.kernel_hz as f64
    }

    /// Prop_Seg as a time, ns: the round-trip bus delay this timing absorbs.
    pub fn prop_seg_ns(&self) -> u32 {
        (self.prop_seg() as f64 * self.tq_ns()) as u32
    }

    /// Oscillator tolerance by conditions (1) and (2) of the module doc (rounded down).
    pub fn tolerance(&self) -> OscillatorTolerance {
        let n = self.tq_per_bit() as u64;
        let ps2 = self.tseg2 as u64;
        let ps_min = (self.phase_seg1() as u64).min(ps2);
        OscillatorTolerance {
            resync_ppm: (1_000_000 * ps_min / (2 * (13 * n - ps2))) as u32,
            sjw_ppm: (1_000_000 * self.sjw as u64 / (20 * n)) as u32,
        }
    }

    /// The FDCAN_NBTP register value (each field holds its value minus one): NSJW \[31:25\],
    /// NBRP \[24:16\], NTSEG1 \[15:8\], NTSEG2 \[6:0\].
    pub fn nbtp(&self) -> u32 {
        ((self.sjw as u32 - 1) << 25)
            | ((self.prescaler as u32 - 1) << 16)
            | ((self.tseg1 as u32 - 1) << 8)
            | (self.tseg2 as u32 - 1)
    }

    /// The timing an FDCAN_NBTP value holds (for reading the register back).
    pub fn from_nbtp(nbtp: u32, kernel_hz: u32) -> Self {
        Self {
            kernel_hz,
            prescaler: ((nbtp >> 16) & 0x1FF) as u16 + 1,
            tseg1: ((nbtp >> 8) & 0xFF) as u16 + 1,
            tseg2: (nbtp & 0x7F) as u8 + 1,
            sjw: ((nbtp >> 25) & 0x7F) as u8 + 1,
        }
    }
}

/// The bit timing for `bitrate` from a kernel clock of `kernel_hz` (see the module doc).
pub fn nominal_bit_timing(
    kernel_hz: u32,
    bitrate: u32,
    limits: BitTimingLimits,
) -> Result<NominalBitTiming, BitTimingError> {
    if bitrate == 0 || kernel_hz / bitrate < MIN_TQ_PER_BIT {
        return Err(BitTimingError::BitrateOutOfRange);
    }
    if kernel_hz % bitrate != 0 {
        return Err(BitTimingError::NotExact);
    }
    let clocks_per_bit = kernel_hz / bitrate;
    let max_tq = 1 + limits.tseg1_max + limits.tseg2_max;
    let mut best: Option<(u32, NominalBitTiming)> = None;
    for prescaler in 1..=limits.prescaler_max.min(clocks_per_bit) {
        if clocks_per_bit % prescaler != 0 {
            continue;
        }
        let n = clocks_per_bit / prescaler;
        if !(MIN_TQ_PER_BIT..=max_tq).contains(&n) {
            continue;
        }
        for timing in split_bit(kernel_hz, prescaler, n, limits) {
            let error = timing
                .sample_point_permille_exact()
                .abs_diff(SAMPLE_POINT_TARGET_PERMILLE * 1000);
            // Strictly better only: for equal errors the smaller prescaler (more quanta) wins.
            if best.is_none_or(|(e, _)| error < e) {
                best = Some((error, timing));
            }
        }
    }
    best.map(|(_, t)| t).ok_or(BitTimingError::NoQuanta)
}

impl NominalBitTiming {
    /// Sample point in millionths of the bit (for comparing candidates).
    fn sample_point_permille_exact(&self) -> u32 {
        1_000_000 * (1 + self.tseg1 as u32) / self.tq_per_bit()
    }
}

/// The (at most two) splits of an `n`-quanta bit with the sample point just below and just
/// above the target, each moved to the latest sample point the register allows if the
/// target lies beyond it; SJW as large as allowed.
fn split_bit(
    kernel_hz: u32,
    prescaler: u32,
    n: u32,
    limits: BitTimingLimits,
) -> impl Iterator<Item = NominalBitTiming> {
    // Quanta before the sample point (sync + tseg1), floor and ceiling of 87.5 % of n.
    let below = n * SAMPLE_POINT_TARGET_PERMILLE / 1000;
    let above = (n * SAMPLE_POINT_TARGET_PERMILLE).div_ceil(1000);
    [below, above].into_iter().filter_map(move |before_sp| {
        let tseg1 = before_sp.checked_sub(1)?.min(limits.tseg1_max);
        let tseg2 = n.checked_sub(1 + tseg1)?;
        let legal = tseg1 >= 1 && (1..=limits.tseg2_max).contains(&tseg2);
        legal.then(|| {
            let mut t = NominalBitTiming {
                kernel_hz,
                prescaler: prescaler as u16,
                tseg1: tseg1 as u16,
                tseg2: tseg2 as u8,
                sjw: 1,
            };
            t.sjw = t.phase_seg1().min(tseg2).min(limits.sjw_max).max(1) as u8;
            t
        })
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nbtp_round_trips() {
        let t = NominalBitTiming {
            kernel_hz: 24_000_000,
            prescaler: 512,
            tseg1: 255,
            tseg2: 128,
            sjw: 128,
        };
        assert_eq!(NominalBitTiming::from_nbtp(t.nbtp(), t.kernel_hz), t);
        assert_eq!(t.nbtp(), 0xFFFF_FE7F);
    }

    #[test]
    fn refuses_inexact_and_out_of_range_rates() {
        let l = BitTimingLimits::FDCAN;
        assert_eq!(
            nominal_bit_timing(24_000_000, 0, l),
            Err(BitTimingError::BitrateOutOfRange)
        );
        assert_eq!(
            nominal_bit_timing(24_000_000, 4_000_000, l),
            Err(BitTimingError::BitrateOutOfRange)
        );
        assert_eq!(
            nominal_bit_timing(24_000_000, 333_333, l),
            Err(BitTimingError::NotExact)
        );
        // 24 MHz / 1 kbit/s = 24 000 clocks: 75 x 320 quanta would need tseg1 = 279 > 255
        // for 87.5 %; 100 x 240 gets it exactly. 100 bit/s needs 240 000 clocks, more
        // than 512 x 384.
        assert_eq!(
            nominal_bit_timing(24_000_000, 1_000, l).map(|t| t.prescaler),
            Ok(100)
        );
        assert_eq!(
            nominal_bit_timing(24_000_000, 100, l),
            Err(BitTimingError::NoQuanta)
        );
    }
}
