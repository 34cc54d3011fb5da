//! `Real`: the float type the plant is generic over (f32 on the target, f32 and f64 on
//! the host), so that one copy of the physics runs in both precisions.

use core::fmt::Debug;
use core::ops::{Add, AddAssign, Div, Mul, MulAssign, Neg, Sub, SubAssign};

use crate::math;

/// A float the plant can compute in. Transcendentals go through [`crate::math`].
pub trait Real:
    Copy
    + Default
    + Debug
    + PartialOrd
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + AddAssign
    + SubAssign
    + MulAssign
    + 'static
{
    const ZERO: Self;
    const ONE: Self;
    /// Converts a parameter or constant (rounding to nearest).
    fn of(x: f64) -> Self;
    fn to_f64(self) -> f64;
    fn exp(self) -> Self;
    fn ln(self) -> Self;
    fn atan(self) -> Self;
    fn sqrt(self) -> Self;
    fn is_finite(self) -> bool;
    fn is_nan(self) -> bool;

    /// |x| (clears the sign bit).
    fn abs(self) -> Self;

    /// The smaller of two values; `other` if `self` is NaN.
    #[inline(always)]
    fn min(self, other: Self) -> Self {
        if self < other { self } else { other }
    }
    /// The larger of two values; `other` if `self` is NaN.
    #[inline(always)]
    fn max(self, other: Self) -> Self {
        if self > other { self } else { other }
    }
    /// `self` limited to `[lo, hi]`; NaN becomes `lo`.
    #[inline(always)]
    fn clamp_to(self, lo: Self, hi: Self) -> Self {
        if self > lo {
            if self < hi { self } else { hi }
        } else {
            lo
        }
    }
    /// x^y for x > 0 (0 for x <= 0), as exp(y ln x).
    #[inline(always)]
    fn powf_pos(self, y: Self) -> Self {
        if self > Self::ZERO {
            (y * self.ln()).exp()
        } else {
            Self::ZERO
        }
    }
}

impl Real for f32 {
    const ZERO: f32 = 0.0;
    const ONE: f32 = 1.0;
    #[inline(always)]
    fn of(x: f64) -> f32 {
        x as f32
    }
    #[inline(always)]
    fn to_f64(self) -> f64 {
        self as f64
    }
    #[inline(always)]
    fn exp(self) -> f32 {
        math::exp_f32(self)
    }
    #[inline(always)]
    fn ln(self) -> f32 {
        math::ln_f32(self)
    }
    #[inline(always)]
    fn atan(self) -> f32 {
        math::atan_f32(self)
    }
    #[inline(always)]
    fn sqrt(self) -> f32 {
        math::sqrt_f32(self)
    }
    #[inline(always)]
    fn is_finite(self) -> bool {
        (self.to_bits() & 0x7f80_0000) != 0x7f80_0000
    }
    #[inline(always)]
    fn is_nan(self) -> bool {
        f32::is_nan(self)
    }
    #[inline(always)]
    fn abs(self) -> f32 {
        f32::from_bits(self.to_bits() & 0x7fff_ffff)
    }
}

impl Real for f64 {
    const ZERO: f64 = 0.0;
    const ONE: f64 = 1.0;
    #[inline(always)]
    fn of(x: f64) -> f64 {
        x
    }
    #[inline(always)]
    fn to_f64(self) -> f64 {
        self
    }
    #[inline(always)]
    fn exp(self) -> f64 {
        math::exp_f64(self)
    }
    #[inline(always)]
    fn ln(self) -> f64 {
        math::ln_f64(self)
    }
    #[inline(always)]
    fn atan(self) -> f64 {
        math::atan_f64(self)
    }
    #[inline(always)]
    fn sqrt(self) -> f64 {
        math::sqrt_f64(self)
    }
    #[inline(always)]
    fn is_finite(self) -> bool {
        (self.to_bits() & 0x7ff0_0000_0000_0000) != 0x7ff0_0000_0000_0000
    }
    #[inline(always)]
    fn is_nan(self) -> bool {
        f64::is_nan(self)
    }
    #[inline(always)]
    fn abs(self) -> f64 {
        f64::from_bits(self.to_bits() & 0x7fff_ffff_ffff_ffff)
    }
}
