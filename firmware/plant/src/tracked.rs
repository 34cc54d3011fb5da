//! e^x of an argument that moves little from step to step, tracked from an exact anchor.
//!
//! The plant evaluates e^x twice per wheelset and step for arguments that change slowly
//! in almost every step: -B |w| of Polach's friction (Eq 11) and -m_v v_d of the disc-pad
//! speed factor (Eq 2). [`TrackedExp`] keeps an anchor (x_a, e^x_a) computed with the exact
//! function and returns, for |x - x_a| <= [`TRACK_WINDOW`], e^x_a times the Taylor
//! polynomial of e^d to degree 3 (d = x - x_a); further away it evaluates e^x exactly and
//! moves the anchor there. The value never drifts: it is always one polynomial step from
//! an exact value, never a product of many steps.
//!
//! Error bound (checked by the tests against the f64 reference): the truncation error of
//! the degree-3 Taylor polynomial is at most |d|^4 e^|d| / 24 <= 2.5e-9 relative for
//! |d| <= 1/64 (0.04 f32 ulp); the polynomial and the product add at most 4 roundings and
//! the anchor's < 1 ulp, so the result is within [`TRACK_MAX_REL_ERROR`] (4.2e-7, about
//! 3.5 ulp) of e^x. NaN and inf take the exact path (their distance is not <= the window).

use crate::real::Real;

/// Largest |x - x_a| served by the polynomial (1/64).
pub const TRACK_WINDOW: f64 = 1.0 / 64.0;
/// Relative error bound of [`TrackedExp::exp`] against e^x (truncation plus roundings).
pub const TRACK_MAX_REL_ERROR: f64 = 4.2e-7;

/// An exact anchor (x_a, e^x_a) of e^x; see the module documentation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrackedExp<F> {
    x_anchor: F,
    exp_anchor: F,
}

impl<F: Real> Default for TrackedExp<F> {
    fn default() -> Self {
        Self {
            x_anchor: F::ZERO,
            exp_anchor: F::ONE,
        }
    }
}

impl<F: Real> TrackedExp<F> {
    /// A tracker anchored (exactly) at `x`.
    pub fn at(x: F) -> Self {
        Self {
            x_anchor: x,
            exp_anchor: x.exp(),
        }
    }

    /// e^x within [`TRACK_MAX_REL_ERROR`]: the degree-3 Taylor polynomial about the anchor
    /// when |x - x_a| <= [`TRACK_WINDOW`], else the exact e^x (which becomes the anchor).
    #[inline(always)]
    pub fn exp(&mut self, x: F) -> F {
        let d = x - self.x_anchor;
        if d.abs() <= F::of(TRACK_WINDOW) {
            let p = F::of(1.0 / 2.0) + d * F::of(1.0 / 6.0);
            self.exp_anchor + self.exp_anchor * (d * (F::ONE + d * p))
        } else {
            *self = Self::at(x);
            self.exp_anchor
        }
    }
}

/// Largest |x/x_a - 1| served by [`TrackedPow`]'s series (1/64).
pub const TRACK_POW_WINDOW: f64 = 1.0 / 64.0;
/// Relative error bound of [`TrackedPow::pow`] against x^y (the exact anchor's own error,
/// that of [`Real::powf_pos`] in f32, plus the series' truncation and roundings).
pub const TRACK_POW_MAX_REL_ERROR: f64 = 8.0e-7;

/// The power law x^y (x > 0) that a [`TrackedPow`] follows: y and the coefficients of
/// the binomial series of (1 + d)^y, folded once.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PowLaw<F> {
    y: F,
    /// y, y(y-1)/2, y(y-1)(y-2)/6.
    coefficients: [F; 3],
}

impl<F: Real> PowLaw<F> {
    /// x^`y`.
    pub fn new(y: f64) -> Self {
        let c2 = y * (y - 1.0) / 2.0;
        Self {
            y: F::of(y),
            coefficients: [F::of(y), F::of(c2), F::of(c2 * (y - 2.0) / 3.0)],
        }
    }

    /// The exponent y.
    pub fn exponent(&self) -> F {
        self.y
    }
}

/// x^y of an argument that moves little between calls, tracked from an exact anchor
/// (1/x_a, x_a^y): for |d| <= [`TRACK_POW_WINDOW`], d = x/x_a - 1, x_a^y times the
/// binomial series of (1 + d)^y to degree 3 (truncation at most |C(y,4)| |d|^4 / (1 - |d|),
/// 1.1e-9 for y = 0.8); further away (or x <= 0, NaN, no anchor yet) the exact
/// [`Real::powf_pos`], which becomes the anchor. The disc's heat loss (Eq 5, v_w^0.8)
/// follows the wheel speed, which changes over seconds.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TrackedPow<F> {
    /// 1/x_a; 0 when there is no anchor (x <= 0): every x is then outside the window.
    x_anchor_inv: F,
    pow_anchor: F,
}

impl<F: Real> TrackedPow<F> {
    /// A tracker of `law` anchored (exactly) at `x`.
    pub fn at(x: F, law: &PowLaw<F>) -> Self {
        if x > F::ZERO {
            Self {
                x_anchor_inv: F::ONE / x,
                pow_anchor: x.powf_pos(law.y),
            }
        } else {
            Self::default()
        }
    }

    /// x^y within [`TRACK_POW_MAX_REL_ERROR`] (0 for x <= 0 and NaN): the series about the
    /// anchor when |x/x_a - 1| <= [`TRACK_POW_WINDOW`], else the exact value (the new
    /// anchor).
    #[inline(always)]
    pub fn pow(&mut self, x: F, law: &PowLaw<F>) -> F {
        let d = x * self.x_anchor_inv - F::ONE;
        if d.abs() <= F::of(TRACK_POW_WINDOW) {
            let [c1, c2, c3] = law.coefficients;
            self.pow_anchor + self.pow_anchor * (d * (c1 + d * (c2 + d * c3)))
        } else {
            *self = Self::at(x, law);
            self.pow_anchor
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{
        PowLaw, TRACK_MAX_REL_ERROR, TRACK_POW_MAX_REL_ERROR, TRACK_POW_WINDOW, TRACK_WINDOW,
        TrackedExp, TrackedPow,
    };
    use crate::math::Worst;

    fn rel_error(got: f32, x: f32) -> f64 {
        let exact = libm::exp(x as f64);
        (got as f64 - exact).abs() / exact
    }

    /// Every anchor over the plant's arguments ([-20, 0.5]: -B|w|, -m_v v_d) and every f32
    /// step of the window around it (both signs), against the f64 exp: within the bound.
    #[test]
    fn within_the_bound_over_the_window() {
        let mut worst = Worst::new();
        let mut anchor = -20.0f32;
        while anchor <= 0.5 {
            let t = TrackedExp::<f32>::at(anchor);
            for i in -500..=500 {
                let x = anchor + (i as f32 / 512.0) * TRACK_WINDOW as f32;
                let mut tt = t;
                let y = tt.exp(x);
                assert_eq!(tt, t, "x = {x} moved the anchor {anchor}");
                worst.see(rel_error(y, x), (anchor, x));
            }
            anchor += 0.0137;
        }
        worst.check("tracked exp", TRACK_MAX_REL_ERROR, 0.1);
    }

    /// A slow ramp (as a decelerating wheel) and jumps (as a slide onset): every value
    /// within the bound, the anchor moves only when the window is left.
    #[test]
    fn follows_ramps_and_jumps_without_drift() {
        let mut t = TrackedExp::<f32>::default();
        let mut refreshes = 0;
        let mut x = 0.0f32;
        for step in 0..200_000 {
            x = if step % 50_000 == 25_000 {
                x - 3.0
            } else {
                x - 2.0e-5
            };
            let before = t;
            let y = t.exp(x);
            if t != before {
                refreshes += 1;
            }
            assert!(rel_error(y, x) <= TRACK_MAX_REL_ERROR, "step {step} x {x}");
        }
        // 4 units of ramp in windows of 1/64, plus the jumps.
        assert!((200..=300).contains(&refreshes), "{refreshes}");
    }

    /// Not a number or an infinity never passes as close to the anchor.
    #[test]
    fn nan_and_inf_take_the_exact_path() {
        let mut t = TrackedExp::<f32>::at(-1.0);
        assert!(t.exp(f32::NAN).is_nan());
        assert_eq!(t.exp(-1.0), crate::math::exp_f32(-1.0));
        assert_eq!(t.exp(f32::NEG_INFINITY), 0.0);
        let y = t.exp(-2.0);
        assert!(rel_error(y, -2.0) < 1.2e-7);
    }

    /// Every anchor over the wheel speeds of the heat loss ([0.01, 140] m/s) and every f32
    /// step of the window about it, against the f64 x^0.8: within the bound; the anchor
    /// stays put inside the window.
    #[test]
    fn tracked_pow_within_the_bound_over_the_window() {
        let mut worst = Worst::new();
        let law = PowLaw::new(0.8);
        let mut anchor = 0.01f32;
        while anchor <= 140.0 {
            let t = TrackedPow::<f32>::at(anchor, &law);
            for i in -500..=500 {
                let x = anchor * (1.0 + (i as f32 / 512.0) * TRACK_POW_WINDOW as f32);
                let mut tt = t;
                let y = tt.pow(x, &law);
                assert_eq!(tt, t, "x = {x} moved the anchor {anchor}");
                let exact = libm::pow(x as f64, 0.8);
                worst.see((y as f64 - exact).abs() / exact, (anchor, x));
            }
            anchor *= 1.0137;
        }
        worst.check("tracked pow", TRACK_POW_MAX_REL_ERROR, 0.1);
    }

    /// From no anchor, a decelerating wheel down to rest and a jump (a slide onset):
    /// within the bound, 0 at and below 0, re-anchored only when the window is left.
    #[test]
    fn tracked_pow_follows_a_stop_and_jumps() {
        let law = PowLaw::new(0.8);
        let mut t = TrackedPow::<f32>::default();
        let mut refreshes = 0;
        let mut x = 40.0f32;
        while x > 1.0 {
            x = if (20.0..20.01).contains(&x) {
                10.0
            } else {
                x - 1.0e-3
            };
            let before = t;
            let y = t.pow(x, &law);
            refreshes += (t != before) as u32;
            let exact = libm::pow(x as f64, 0.8);
            assert!(
                (y as f64 - exact).abs() / exact <= TRACK_POW_MAX_REL_ERROR,
                "x {x}"
            );
        }
        // ln(40) / ln(1 + 1/64) ~ 238 windows, plus the jump.
        assert!((150..=300).contains(&refreshes), "{refreshes}");
        assert_eq!(t.pow(0.0, &law), 0.0);
        assert_eq!(t.pow(-1.0, &law), 0.0);
        // As Real::powf_pos: not a number gives 0 (and anchors there).
        assert_eq!(t.pow(f32::NAN, &law), 0.0);
        let y = t.pow(2.0, &law);
        assert!((y as f64 - libm::pow(2.0, 0.8)).abs() < 1e-6);
    }
}
