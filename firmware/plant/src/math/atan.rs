//! atan(x)/x in f32 arithmetic only, for Polach's Eq (9) (the bracket's atan(k_s eps)
//! divided by k_s eps, so that the adhesion force is a chord times the slip velocity).
//!
//! Why not `libm::atanf(x) / x`: the plant needs the quotient, not atan itself, and
//! Cephes' reduction (S. L. Moshier, Cephes Math Library, atanf.c) gives it with at most
//! one division per call instead of libm's reduction division plus the quotient's:
//!
//! * |x| <= tan(pi/8): atan(x)/x = 1 + z P(z), z = x^2 (no division at all: the slip of
//!   a rolling wheel, the common case);
//! * |x| <= tan(3pi/8): atan(x) = pi/4 + atan(y), y = (x - 1)/(x + 1);
//! * beyond: atan(x) = pi/2 + atan(y), y = -1/x, and atan(x)/x = -y atan(x).
//!
//! P is Cephes' degree-3 minimax polynomial of atanf (documented peak relative error of
//! atanf 1.9e-7 over +-10, IEEE single). The test below checks the quotient against the f64
//! reference over every binade the contact can reach: within [`ATAN_OVER_X_MAX_REL_ERROR`]
//! (4 roundings over Cephes' bound). Only `+ - * /` (IEEE 754, never fused): the same bits
//! on x86-64 and the Cortex-M4F.

/// Relative error bound of [`atan_over_x`] against atan(x)/x (checked by the tests).
pub const ATAN_OVER_X_MAX_REL_ERROR: f64 = 4.0e-7;

const TAN_PI_8: f32 = 0.414_213_57;
const TAN_3PI_8: f32 = 2.414_213_6;
const PI_4: f32 = core::f32::consts::FRAC_PI_4;
const PI_2: f32 = core::f32::consts::FRAC_PI_2;
/// Cephes atanf.c coefficients (atan(y) = y + y z P(z), z = y^2, |y| <= tan(pi/8)).
const P3: f32 = 8.053_744_5e-2;
const P2: f32 = -1.387_768_6e-1;
const P1: f32 = 1.997_771_1e-1;
const P0: f32 = -3.333_294_9e-1;

/// z P(z).
#[inline(always)]
fn zp(z: f32) -> f32 {
    (((P3 * z + P2) * z + P1) * z + P0) * z
}

/// atan(x)/x (even in x; 1 at x = 0; NaN for NaN; 0 for an infinite x).
#[inline(always)]
pub fn atan_over_x(x: f32) -> f32 {
    let a = f32::from_bits(x.to_bits() & 0x7fff_ffff);
    if a <= TAN_PI_8 {
        1.0 + zp(a * a)
    } else if a <= TAN_3PI_8 {
        let y = (a - 1.0) / (a + 1.0);
        (PI_4 + (y + y * zp(y * y))) / a
    } else {
        let y = -1.0 / a;
        -y * (PI_2 + (y + y * zp(y * y)))
    }
}

#[cfg(test)]
mod tests {
    use super::{ATAN_OVER_X_MAX_REL_ERROR, atan_over_x};
    use crate::math::Worst;

    fn reference(x: f32) -> f64 {
        let x = x as f64;
        if x == 0.0 { 1.0 } else { libm::atan(x) / x }
    }

    /// Every 17th f32 from 1e-9 to 1e9 (both signs; the contact's k_s eps runs from 0 to
    /// a few hundred): within the bound against the f64 reference, and the bound is not
    /// loose by orders of magnitude.
    #[test]
    fn within_the_bound_over_the_contacts_range() {
        let mut worst = Worst::new();
        let mut bits = 1.0e-9f32.to_bits();
        while f32::from_bits(bits) <= 1.0e9 {
            for x in [f32::from_bits(bits), -f32::from_bits(bits)] {
                let r = reference(x);
                worst.see((atan_over_x(x) as f64 - r).abs() / r, x);
            }
            bits += 17;
        }
        worst.check("atan(x)/x", ATAN_OVER_X_MAX_REL_ERROR, 0.05);
    }

    #[test]
    fn special_values() {
        assert_eq!(atan_over_x(0.0), 1.0);
        assert_eq!(atan_over_x(-0.0), 1.0);
        assert!(atan_over_x(f32::NAN).is_nan());
        assert_eq!(atan_over_x(f32::INFINITY), 0.0);
        assert_eq!(atan_over_x(f32::NEG_INFINITY), 0.0);
        // Continuous where the reduction switches (within the bound on both sides).
        for edge in [super::TAN_PI_8, super::TAN_3PI_8] {
            let below = atan_over_x(f32::from_bits(edge.to_bits() - 1));
            let above = atan_over_x(f32::from_bits(edge.to_bits() + 1));
            assert!(
                ((below - above) as f64).abs() / (below as f64) < 2.0 * ATAN_OVER_X_MAX_REL_ERROR
            );
        }
    }
}
