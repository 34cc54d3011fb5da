//! e^x in f32 arithmetic only, within 1 ulp, for the plant's hot path.
//!
//! Why not `libm::expf`: it is accurate but costs ~71 instructions per call on the
//! Cortex-M4F (special-case tests, a division in its rational approximation, a `scalbnf`
//! call), and the plant evaluates e^x 16 times per step (Eqs 2, 4-6 and 11 for four
//! wheelsets). This version costs about a third of that (measured by `hils target-cost`,
//! see docs/target.md) and keeps the accuracy: < 1 ulp over the whole f32 range (the
//! tests below check it against the f64 reference).
//!
//! Method (the classic one, as in FreeBSD's e_expf.c, with a polynomial instead of the
//! rational form): x = k ln2 + r with k = round(x / ln2) and |r| <= ~ln2/2 (Cody-Waite:
//! ln2 split in a 15-bit head, so k ln2_hi is exact, and a tail); e^r = 1 + r + r^2 q(r)
//! with the Taylor terms up to r^7/7! (truncation < 5.2e-9 relative, 0.05 ulp), the
//! rounding error of 1 + r carried along (Fast2Sum); then
//! e^x = 2^k e^r by adding k to the exponent bits. Only `+ - *` (correctly rounded in
//! IEEE 754, never fused) and integer operations, so the result is the same bit for bit
//! on every IEEE 754 machine: x86-64 and the Cortex-M4F FPU alike.

/// 1/ln 2 rounded to f32.
const INV_LN2: f32 = f32::from_bits(0x3fb8_aa3b);
/// ln 2 head: 15 significant bits, so k LN2_HI is exact for |k| < 2^9.
const LN2_HI: f32 = f32::from_bits(0x3f31_7200);
/// ln 2 - LN2_HI.
const LN2_LO: f32 = f32::from_bits(0x35bf_be8e);
/// 1.5 2^23: adding it to |v| < 2^22 rounds v to the nearest integer (in the last bits).
const ROUND: f32 = 12_582_912.0;
/// Taylor coefficients 1/n!, n = 2..7.
const C2: f32 = 0.5;
const C3: f32 = (1.0 / 6.0) as f32;
const C4: f32 = (1.0 / 24.0) as f32;
const C5: f32 = (1.0 / 120.0) as f32;
const C6: f32 = (1.0 / 720.0) as f32;
const C7: f32 = (1.0 / 5040.0) as f32;
/// exp(x) overflows for x >= this (88.72284).
const OVERFLOW: f32 = f32::from_bits(0x42b1_7218);
/// exp(x) rounds to 0 below this (-103.97208).
const UNDERFLOW: f32 = f32::from_bits(0xc2cf_f1b5);
/// Bits of 87.0: for |x| <= 87 the fast path's 2^k is a normal number.
const FAST_LIMIT_BITS: u32 = 0x42ae_0000;

/// e^x (< 1 ulp). NaN gives NaN, overflow +inf, underflow 0 or a subnormal.
#[inline(always)]
pub fn exp(x: f32) -> f32 {
    // |x| <= 87 (a NaN has larger bits than any number and takes the other path).
    if x.to_bits() & 0x7fff_ffff <= FAST_LIMIT_BITS {
        let (k, p) = reduce(x);
        // p in [0.70, 1.42], k in [-126, 126], and p >= 1 when k = -126: p 2^k is a
        // normal number whose exponent field is p's plus k.
        f32::from_bits(p.to_bits().wrapping_add((k as u32) << 23))
    } else {
        exp_outside(x)
    }
}

/// k and e^r for x = k ln2 + r, |r| <= ~ln2/2 (needs |x| < 2^21).
#[inline(always)]
fn reduce(x: f32) -> (i32, f32) {
    let t = x * INV_LN2 + ROUND;
    let k = t.to_bits() as i32 - ROUND.to_bits() as i32;
    let kf = t - ROUND;
    let r = (x - kf * LN2_HI) - kf * LN2_LO;
    let q = C2 + r * (C3 + r * (C4 + r * (C5 + r * (C6 + r * C7))));
    // 1 + r + r^2 q with the rounding error of 1 + r carried (Fast2Sum, |r| < 1), so the
    // sum is rounded about once: for r < 0 the result lies below 1, where one rounding
    // of 1 + (r + r^2 q) alone could cost a whole ulp.
    let hi = 1.0 + r;
    let lo = (1.0 - hi) + r;
    (k, hi + (lo + (r * r) * q))
}

/// 2^k for k in [-126, 127].
#[inline(always)]
fn pow2(k: i32) -> f32 {
    f32::from_bits(((k + 127) as u32) << 23)
}

/// |x| > 87, inf or NaN.
#[inline(never)]
#[cold]
fn exp_outside(x: f32) -> f32 {
    if x.is_nan() {
        return x + x;
    }
    if x >= OVERFLOW {
        return f32::INFINITY;
    }
    if x < UNDERFLOW {
        return 0.0;
    }
    // k in [-150, 128]: scale in two steps, the first exact, so p 2^k is rounded once.
    let (k, p) = reduce(x);
    let k1 = k / 2;
    p * pow2(k1) * pow2(k - k1)
}

#[cfg(test)]
mod tests {
    use super::exp;

    /// Error of `y` against the exact `reference`, in units of the last place of the f32
    /// nearest to the reference (the smallest subnormal for subnormal results).
    fn ulps(y: f32, reference: f64) -> f64 {
        let r32 = reference as f32;
        if r32 == 0.0 || !r32.is_finite() {
            return if y == r32 { 0.0 } else { f64::INFINITY };
        }
        let mag = f32::from_bits(r32.to_bits() & 0x7fff_ffff);
        let ulp = f32::from_bits(mag.to_bits() + 1) as f64 - mag as f64;
        (y as f64 - reference).abs() / ulp
    }

    /// Every 61st f32 between -104 and 89 (about 35 million arguments over all binades):
    /// the error stays below 1 ulp. The f64 libm result is the reference; its own error,
    /// < 1e-16 relative, is far below an f32 ulp.
    #[test]
    fn within_one_ulp_over_the_whole_range() {
        let mut worst = (0.0f64, 0.0f32);
        for sign in [0u32, 0x8000_0000] {
            let limit = if sign == 0 { 89.0f32 } else { 104.0 };
            let mut bits = 0u32;
            while f32::from_bits(bits) <= limit {
                let x = f32::from_bits(bits | sign);
                let e = ulps(exp(x), libm::exp(x as f64));
                if e > worst.0 {
                    worst = (e, x);
                }
                bits += 61;
            }
        }
        std::eprintln!(
            "expf on [-104, 89]: max error {:.3} ulp at x = {:e}",
            worst.0,
            worst.1
        );
        assert!(
            worst.0 < 1.0,
            "max error {} ulp at x = {:e}",
            worst.0,
            worst.1
        );
    }

    /// The plant's arguments ([-20, 4]: -B|w|, -m_v v_d, -m_T T_d, 0.8 ln v), every 23rd
    /// f32: below 1 ulp, and correctly rounded for the great majority.
    #[test]
    fn dense_in_the_plants_range() {
        let (mut n, mut exact, mut worst) = (0u64, 0u64, 0.0f64);
        let mut check = |x: f32| {
            let reference = libm::exp(x as f64);
            let y = exp(x);
            worst = f64::max(worst, ulps(y, reference));
            exact += (y == reference as f32) as u64;
            n += 1;
        };
        let mut bits = 0u32;
        while f32::from_bits(bits) <= 20.0 {
            let x = f32::from_bits(bits);
            check(-x);
            if x <= 4.0 {
                check(x);
            }
            bits += 23;
        }
        std::eprintln!(
            "expf on [-20, 4]: {n} arguments, max error {worst:.3} ulp, {:.2} % correctly rounded",
            100.0 * exact as f64 / n as f64
        );
        assert!(worst < 1.0, "max error {worst} ulp");
        assert!(
            exact as f64 > 0.9 * n as f64,
            "only {exact} of {n} correctly rounded"
        );
    }

    #[test]
    fn special_values() {
        assert_eq!(exp(0.0), 1.0);
        assert_eq!(exp(-0.0), 1.0);
        assert!(exp(f32::NAN).is_nan());
        assert_eq!(exp(f32::INFINITY), f32::INFINITY);
        assert_eq!(exp(f32::NEG_INFINITY), 0.0);
        assert_eq!(exp(89.0), f32::INFINITY);
        assert_eq!(exp(-104.0), 0.0);
        // Near overflow, subnormal results, and the edges of the fast path.
        for x in [
            88.72283f32,
            88.0,
            87.0,
            87.000_01,
            -87.0,
            -87.000_01,
            -100.0,
            -103.9,
        ] {
            let e = ulps(exp(x), libm::exp(x as f64));
            assert!(e < 1.0, "exp({x}) off by {e} ulp");
        }
    }

    /// Monotonic over consecutive floats where the reduction switches k (odd multiples of
    /// ln2/2) and at the edges of the fast path.
    #[test]
    fn monotonic_where_the_method_switches() {
        let ln2 = core::f32::consts::LN_2;
        for centre in [0.5 * ln2, 1.5 * ln2, -0.5 * ln2, -1.5 * ln2, 87.0, -87.0] {
            let mut x = f32::from_bits(centre.to_bits() - 500);
            let mut prev = exp(x);
            for _ in 0..1000 {
                x = f32::from_bits(x.to_bits() + 1);
                let y = exp(x);
                // The bits step away from zero: x grows for positive centres, falls else.
                let ordered = if centre > 0.0 { y >= prev } else { y <= prev };
                assert!(ordered, "exp not monotonic at {x:e}");
                prev = y;
            }
        }
    }
}
