//! Disc-pad friction coefficient, paper Eq (2).

use crate::params::{FrictionModel, FrictionParams};
use crate::real::Real;
use crate::tracked::TrackedExp;

/// Precomputed Eq (2): mu_d = c mu_d0 (n_v e^(-m_v v_d) + 1)(n_T e^(-m_T T_d) + 1),
/// or mu_d0 alone with [`FrictionModel::Constant`]; times the pressure extension
/// (1 + k_p f_clamp / 10 kN), which is 1 in the reference model.
#[derive(Clone, Copy, Debug)]
pub struct DiscPadFriction<F> {
    variable: bool,
    /// c mu_d0 (variable model) or mu_d0 (constant).
    c_mu_d0: F,
    /// c mu_d0 n_T (variable model): the temperature bracket with c mu_d0 folded in.
    c_mu_d0_n_t: F,
    n_v: F,
    m_v: F,
    n_t: F,
    m_t: F,
    /// k_p / 10 kN, 1/N.
    k_p_per_n: F,
}

impl<F: Real> DiscPadFriction<F> {
    /// The disc-pad friction law of `[friction]` (paper Eq (2), Table 1).
    pub fn new(p: &FrictionParams) -> Self {
        let variable = p.model == FrictionModel::Variable;
        Self {
            variable,
            c_mu_d0: F::of(if variable {
                p.correction_c * p.mu_d0
            } else {
                p.mu_d0
            }),
            c_mu_d0_n_t: F::of(p.correction_c * p.mu_d0 * p.n_t),
            n_v: F::of(if variable { p.n_v } else { 0.0 }),
            m_v: F::of(if variable { p.m_v } else { 0.0 }),
            n_t: F::of(p.n_t),
            m_t: F::of(p.m_t),
            k_p_per_n: F::of(p.k_p / 1.0e4),
        }
    }

    /// mu_d at friction speed `v_d` (m/s, at the friction radius), disc temperature rise
    /// `t_d` (degC) and pad clamp force `f_clamp` (N per face).
    #[inline(always)]
    pub fn mu_d(&self, v_d: F, t_d: F, f_clamp: F) -> F {
        self.mu_d_with(v_d, self.temperature_factor(t_d), f_clamp)
    }

    /// The temperature bracket of Eq (2), n_T e^(-m_T T_d) + 1 (1 with the constant model).
    /// The disc temperature changes over seconds, so the plant refreshes this factor less
    /// often than every step.
    #[inline(always)]
    pub fn temperature_factor(&self, t_d: F) -> F {
        if self.variable {
            self.n_t * (-self.m_t * t_d).exp() + F::ONE
        } else {
            F::ONE
        }
    }

    /// c mu_d0 times [`Self::temperature_factor`] with e^(-m_T T_d) from a [`TrackedExp`]
    /// (the plant's refresh in turn: the disc temperature moves little between refreshes;
    /// within [`crate::tracked::TRACK_MAX_REL_ERROR`] of the exact factor), mu_d0 with the
    /// constant model; for [`Self::scaled_brackets_tracked`].
    #[inline(always)]
    pub fn scaled_temperature_factor_tracked(&self, t_d: F, decay: &mut TrackedExp<F>) -> F {
        if self.variable {
            self.c_mu_d0_n_t * decay.exp(-self.m_t * t_d) + self.c_mu_d0
        } else {
            self.c_mu_d0
        }
    }

    /// The tracker of the temperature factor's e^(-m_T T_d), anchored at `t_d` (degC).
    pub fn temperature_decay_at(&self, t_d: F) -> TrackedExp<F> {
        TrackedExp::at(-self.m_t * t_d)
    }

    /// The tracker of the speed factor's e^(-m_v v_d), anchored at friction speed `v_d`.
    pub fn speed_decay_at(&self, v_d: F) -> TrackedExp<F> {
        TrackedExp::at(-self.m_v * v_d.abs())
    }

    /// mu_d at friction speed `v_d` with a precomputed [`Self::temperature_factor`].
    #[inline(always)]
    pub fn mu_d_with(&self, v_d: F, temperature_factor: F, f_clamp: F) -> F {
        // One formula for both models: the constant model has n_v = m_v = 0 and
        // c mu_d0 = mu_d0, so the speed factor is exactly 1 and (temperature factor 1)
        // the base exactly mu_d0.
        let speed_factor = self.n_v * (-self.m_v * v_d.abs()).exp() + F::ONE;
        let base = self.c_mu_d0 * speed_factor * temperature_factor;
        base * (F::ONE + self.k_p_per_n * f_clamp)
    }

    /// -m_v l_p, s: the exponent of Eq (2)'s speed factor per rad/s of wheel spin (friction
    /// radius `friction_radius_m` folded in; 0 with the constant model).
    pub fn speed_exponent_per_spin(p: &FrictionParams, friction_radius_m: f64) -> F {
        let variable = p.model == FrictionModel::Variable;
        F::of(if variable {
            -p.m_v * friction_radius_m
        } else {
            0.0
        })
    }

    /// Eq (2)'s two brackets times c mu_d0,
    /// c mu_d0 (n_v e^(-m_v v_d) + 1) (n_T e^(-m_T T_d) + 1)
    /// (mu_d0 with the constant model), from the temperature bracket times c mu_d0
    /// ([`Self::scaled_temperature_factor_tracked`]) and the speed bracket's exponent
    /// -m_v |v_d| ([`Self::speed_exponent_per_spin`] times |omega|), e^x from a
    /// [`TrackedExp`]. Both brackets follow quantities that change over seconds in braking
    /// (and over tenths of a second in a slide), so the plant refreshes this factor in
    /// turn; [`Self::mu_d_of_brackets`] gives mu_d from it every step.
    #[inline(always)]
    pub fn scaled_brackets_tracked(
        &self,
        speed_exponent: F,
        scaled_temperature_factor: F,
        decay: &mut TrackedExp<F>,
    ) -> F {
        let speed_factor = self.n_v * decay.exp(speed_exponent) + F::ONE;
        speed_factor * scaled_temperature_factor
    }

    /// mu_d of Eq (2) from its brackets times c mu_d0 ([`Self::scaled_brackets_tracked`])
    /// and the pad clamp force `f_clamp` (N per face): times the pressure extension
    /// (1 + k_p f_clamp / 10 kN).
    #[inline(always)]
    pub fn mu_d_of_brackets(&self, scaled_brackets: F, f_clamp: F) -> F {
        scaled_brackets * (F::ONE + self.k_p_per_n * f_clamp)
    }
}
