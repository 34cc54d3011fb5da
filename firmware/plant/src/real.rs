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
    /// 0.
    const ZERO: Self;
    /// 1.
    const ONE: Self;
    /// Converts a parameter or constant (rounding to nearest).
    fn of(x: f64) -> Self;
    /// The value as f64 (exact: every f32 is an f64).
    fn to_f64(self) -> f64;
    /// e^self (paper Eqs (2), (11)).
    fn exp(self) -> Self;
    /// Natural logarithm.
    fn ln(self) -> Self;
    /// Arc tangent, rad (paper Eq (9)).
    fn atan(self) -> Self;
    /// atan(x)/x (1 at 0), Eq (9)'s bracket without a division by the creepage.
    fn atan_over_x(self) -> Self;
    /// Square root.
    fn sqrt(self) -> Self;
    /// Neither NaN nor infinite.
    fn is_finite(self) -> bool;
    /// Not a number.
    fn is_nan(self) -> bool;
    /// Whether `0 <= self <= hi` (for a finite `hi >= 0`) by one integer compare of the
    /// bit patterns, which order as the values for non-negative floats; false for NaN,
    /// infinities above `hi`, negative values and -0 (the callers then take their detailed
    /// path, which treats these).
    fn within_zero_and(self, hi: Self) -> bool;

    /// |x| (clears the sign bit).
    fn abs(self) -> Self;

    /// Rounded half up to a whole number, as u32: `trunc(self + 0.5)` without the
    /// addition's rounding (the same for an f32 value computed in f32 or f64), by the FPU's
    /// conversion (no f64 on the Cortex-M4F). NaN and values below 0.5 give 0, values
    /// from `u32::MAX` on give `u32::MAX`.
    fn round_u32(self) -> u32;

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

/// `Real` for a float type: its math functions and its exponent and sign masks.
macro_rules! impl_real {
    ($t:ty, [$($name:ident = $f:path),*], $exp_mask:expr, $abs_mask:expr) => {
        impl Real for $t {
            const ZERO: $t = 0.0;
            const ONE: $t = 1.0;
            #[inline(always)]
            fn of(x: f64) -> $t {
                x as $t
            }
            #[inline(always)]
            fn to_f64(self) -> f64 {
                self as f64
            }
            $(
                #[inline(always)]
                fn $name(self) -> $t {
                    $f(self)
                }
            )*
            #[inline(always)]
            fn is_finite(self) -> bool {
                (self.to_bits() & $exp_mask) != $exp_mask
            }
            #[inline(always)]
            fn within_zero_and(self, hi: $t) -> bool {
                self.to_bits() <= hi.to_bits()
            }
            #[inline(always)]
            fn is_nan(self) -> bool {
                <$t>::is_nan(self)
            }
            #[inline]
            fn round_u32(self) -> u32 {
                // Truncates, saturates, NaN -> 0; `self - whole` is exact below 2^32.
                let whole = self as u32;
                if self - whole as $t >= 0.5 {
                    whole.saturating_add(1)
                } else {
                    whole
                }
            }
            #[inline(always)]
            fn abs(self) -> $t {
                <$t>::from_bits(self.to_bits() & $abs_mask)
            }
        }
    };
}

impl_real! { f32, [exp = math::exp_f32, ln = math::ln_f32, atan = math::atan_f32, atan_over_x = math::atan_over_x_f32, sqrt = math::sqrt_f32], 0x7f80_0000, 0x7fff_ffff }
impl_real! { f64, [exp = math::exp_f64, ln = math::ln_f64, atan = math::atan_f64, atan_over_x = math::atan_over_x_f64, sqrt = math::sqrt_f64], 0x7ff0_0000_0000_0000, 0x7fff_ffff_ffff_ffff }

#[cfg(test)]
mod tests {
    use super::*;

    /// `round_u32` against `trunc(x + 0.5)` in f64 (exact for every f32 and saturating, NaN
    /// to 0), over f32 bit patterns of every sign and exponent and the edges of the
    /// rounding: just below halves, odd integers above 2^23 where `x + 0.5` in f32 would
    /// round to even, the top of the u32 range.
    #[test]
    fn round_u32_is_round_half_up_of_the_exact_value() {
        let edges = [
            0.5f32.next_down(),
            0.5,
            1.5f32.next_down(),
            1.5,
            8_388_609.0,
            16_777_215.0,
            4_294_967_040.0,
            4_294_967_296.0,
            -0.25,
            -0.0,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
        ];
        let strided = (0..u32::MAX).step_by(7_919).map(f32::from_bits);
        for x in edges.into_iter().chain(strided) {
            assert_eq!(x.round_u32(), (x as f64 + 0.5) as u32, "f32 {x:e}");
            let y = x as f64 * 1.000_000_1;
            assert_eq!(y.round_u32(), (y + 0.5) as u32, "f64 {y:e}");
        }
    }
}
