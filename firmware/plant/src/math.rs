//! The one place that picks the math implementation of the plant, for every build.
//!
//! Every transcendental function the plant evaluates goes through this module, on the
//! host (tests, tools, f32 and f64) and on the Cortex-M4F alike. The plant never calls
//! `std`'s float methods: with `#![cfg_attr(not(test), no_std)]` a crate would silently
//! use the platform libm in its unit tests and a different implementation on the board,
//! and the host could no longer check the target bit for bit.
//!
//! * default (`expf+libm`): e^x from `math/expf.rs` (f32 only, < 1 ulp, less than half of
//!   libm's instructions on the Cortex-M4F), ln, atan and sqrt from the `libm` crate (a
//!   Rust port of FreeBSD msun; f32 functions compute in f32 only, so no soft-float
//!   double on the Cortex-M4F; results within 1 ulp). Chosen from the measured comparison
//!   in docs/target.md.
//! * feature `math-libm`: every f32 function from `libm` (the comparison's baseline).
//! * feature `math-micromath`: micromath's fast approximations for f32 (kept for the
//!   measured comparison; slower than the default on the Cortex-M4F and less accurate).
//!
//! f64 always uses libm: it is the reference.
//!
//! `+ - * /` and `sqrt` are IEEE 754 correctly rounded on both x86-64 (SSE) and the
//! Cortex-M4F FPU, and Rust never fuses a multiply and an add on its own, so with one
//! implementation of the functions below an f32 run is bit-identical on both.

mod atan;
mod expf;

pub use atan::ATAN_OVER_X_MAX_REL_ERROR;

#[cfg(all(feature = "math-libm", feature = "math-micromath"))]
compile_error!("the features math-libm and math-micromath exclude each other");

#[cfg(not(feature = "math-micromath"))]
mod f32_impl {
    #[inline(always)]
    /// e^x in f32 (paper Eqs (2), (11)).
    pub fn exp(x: f32) -> f32 {
        #[cfg(feature = "math-libm")]
        {
            libm::expf(x)
        }
        #[cfg(not(feature = "math-libm"))]
        {
            super::expf::exp(x)
        }
    }
    #[inline(always)]
    /// Natural logarithm in f32.
    pub fn ln(x: f32) -> f32 {
        libm::logf(x)
    }
    #[inline(always)]
    /// Arc tangent in f32, rad (paper Eq (9)).
    pub fn atan(x: f32) -> f32 {
        libm::atanf(x)
    }
    #[inline(always)]
    /// atan(x)/x in f32 (1 at 0): paper Eq (9)'s bracket without a division by the creepage.
    pub fn atan_over_x(x: f32) -> f32 {
        #[cfg(feature = "math-libm")]
        {
            super::quotient(x, libm::atanf(x))
        }
        #[cfg(not(feature = "math-libm"))]
        {
            super::atan::atan_over_x(x)
        }
    }
    #[inline(always)]
    /// Square root in f32.
    pub fn sqrt(x: f32) -> f32 {
        libm::sqrtf(x)
    }
}

#[cfg(feature = "math-micromath")]
mod f32_impl {
    use micromath::F32Ext;
    #[inline(always)]
    pub fn exp(x: f32) -> f32 {
        F32Ext::exp(x)
    }
    #[inline(always)]
    pub fn ln(x: f32) -> f32 {
        F32Ext::ln(x)
    }
    #[inline(always)]
    pub fn atan(x: f32) -> f32 {
        F32Ext::atan(x)
    }
    #[inline(always)]
    pub fn atan_over_x(x: f32) -> f32 {
        super::quotient(x, F32Ext::atan(x))
    }
    #[inline(always)]
    pub fn sqrt(x: f32) -> f32 {
        libm::sqrtf(x)
    }
}

/// Name of the math implementation compiled in (reported by tools and the target).
pub const IMPLEMENTATION: &str = if cfg!(feature = "math-micromath") {
    "micromath"
} else if cfg!(feature = "math-libm") {
    "libm"
} else {
    "expf+libm"
};

pub use f32_impl::{
    atan as atan_f32, atan_over_x as atan_over_x_f32, exp as exp_f32, ln as ln_f32,
    sqrt as sqrt_f32,
};

/// atan(x)/x from atan(x) (1 - x^2/3 for |x| < 1e-3, where the quotient loses digits):
/// the f64 reference and the f32 baselines.
#[inline(always)]
#[allow(dead_code)]
fn quotient<F>(x: F, atan_x: F) -> F
where
    F: Copy + PartialOrd + From<f32> + core::ops::Neg<Output = F>,
    F: core::ops::Mul<Output = F> + core::ops::Sub<Output = F> + core::ops::Div<Output = F>,
{
    // |x| < 1e-3 written with core's operators only (this module sits below `real`).
    let small = F::from(1.0e-3f32);
    if x < small && -x < small {
        F::from(1.0f32) - x * x / F::from(3.0f32)
    } else {
        atan_x / x
    }
}

#[inline(always)]
/// atan(x)/x in f64 (1 at 0): paper Eq (9)'s bracket without a division by the creepage.
pub fn atan_over_x_f64(x: f64) -> f64 {
    quotient(x, libm::atan(x))
}

#[inline(always)]
/// e^x in f64 (paper Eqs (2), (11)).
pub fn exp_f64(x: f64) -> f64 {
    libm::exp(x)
}
#[inline(always)]
/// Natural logarithm in f64.
pub fn ln_f64(x: f64) -> f64 {
    libm::log(x)
}
#[inline(always)]
/// Arc tangent in f64, rad (paper Eq (9)).
pub fn atan_f64(x: f64) -> f64 {
    libm::atan(x)
}
#[inline(always)]
/// Square root in f64.
pub fn sqrt_f64(x: f64) -> f64 {
    libm::sqrt(x)
}

/// Test support: the worst error seen over a sweep and the check of a stated bound.
#[cfg(test)]
pub(crate) struct Worst<T> {
    pub error: f64,
    pub at: Option<T>,
}

#[cfg(test)]
impl<T: core::fmt::Debug> Worst<T> {
    pub fn new() -> Self {
        Self {
            error: 0.0,
            at: None,
        }
    }
    /// Keeps `error` if it is the largest so far.
    pub fn see(&mut self, error: f64, at: T) {
        if error > self.error || self.at.is_none() {
            self.error = error;
            self.at = Some(at);
        }
    }
    /// Asserts the worst error within `bound` and above `tight` times it (a bound loose by
    /// orders of magnitude would hide a wrong method); prints it.
    pub fn check(&self, name: &str, bound: f64, tight: f64) {
        std::eprintln!(
            "{name}: worst relative error {:.3e} at {:?}",
            self.error,
            self.at
        );
        assert!(
            self.error <= bound,
            "{name}: {} at {:?}",
            self.error,
            self.at
        );
        assert!(
            self.error > tight * bound,
            "{name}: {} at {:?}",
            self.error,
            self.at
        );
    }
}
