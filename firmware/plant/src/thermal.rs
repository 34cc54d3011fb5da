//! Lumped disc heat balance per wheelset, paper Eqs (3)-(6).

use crate::params::ThermalParams;
use crate::real::Real;
use crate::tracked::{PowLaw, TrackedPow};

/// The exponent of the wheel speed in the convective loss of Eq (5).
const CONVECTION_EXPONENT: f64 = 0.8;

/// Precomputed constants of Eqs (3)-(6).
#[derive(Clone, Copy, Debug)]
pub struct DiscThermal<F> {
    heat_partition: F,
    inv_heat_capacity: F,
    alpha: F,
    beta: F,
    /// v_w^0.8 of Eq (5).
    speed_power: PowLaw<F>,
}

impl<F: Real> DiscThermal<F> {
    /// The disc heat balance of `[thermal]` (paper Eqs (3)-(6)).
    pub fn new(p: &ThermalParams) -> Self {
        Self {
            heat_partition: F::of(p.heat_partition),
            inv_heat_capacity: F::of(1.0 / (p.specific_heat * p.disc_mass)),
            alpha: F::of(p.alpha),
            beta: F::of(p.beta),
            speed_power: PowLaw::new(CONVECTION_EXPONENT),
        }
    }

    /// dT_d/dt, K/s, from brake power `t_b omega_d` (W), disc temperature rise `t_d` (degC)
    /// and wheel circumferential speed `v_w = r omega` (m/s):
    /// E_br = sigma_d T_b omega_d                                   (4)
    /// Q_cond + Q_conv = alpha T_d + beta T_d v_w^0.8               (5)
    /// dT_d/dt = (E_br - Q_cond - Q_conv) / (c_p m_disc)            (3), (6)
    #[inline(always)]
    pub fn rate(&self, brake_power: F, t_d: F, wheel_speed: F) -> F {
        self.rate_with(brake_power, t_d, self.loss_coefficient(wheel_speed))
    }

    /// The loss coefficient of Eq (5), alpha + beta v_w^0.8, W/K. It follows the wheel
    /// speed, which changes over seconds, so the plant refreshes it less often than every
    /// step.
    #[inline(always)]
    pub fn loss_coefficient(&self, wheel_speed: F) -> F {
        self.alpha + self.beta * wheel_speed.abs().powf_pos(self.speed_power.exponent())
    }

    /// [`Self::loss_coefficient`] with v_w^0.8 from a [`TrackedPow`] (the plant's refresh in
    /// turn; within [`crate::tracked::TRACK_POW_MAX_REL_ERROR`] of the exact power).
    #[inline(always)]
    pub fn loss_coefficient_tracked(&self, wheel_speed: F, power: &mut TrackedPow<F>) -> F {
        self.alpha + self.beta * power.pow(wheel_speed.abs(), &self.speed_power)
    }

    /// The tracker of v_w^0.8 of Eq (5), anchored at wheel speed `wheel_speed` (m/s).
    pub fn speed_power_at(&self, wheel_speed: F) -> TrackedPow<F> {
        TrackedPow::at(wheel_speed.abs(), &self.speed_power)
    }

    /// dT_d/dt with a precomputed [`Self::loss_coefficient`].
    #[inline(always)]
    pub fn rate_with(&self, brake_power: F, t_d: F, loss_coefficient: F) -> F {
        self.net_heat_flow(brake_power, t_d, loss_coefficient) * self.inv_heat_capacity
    }

    /// E_br - Q_cond - Q_conv of Eq (3), W, with a precomputed [`Self::loss_coefficient`]
    /// (the plant multiplies it by dt / (c_p m_disc), folded: [`Self::step_gain`]).
    #[inline(always)]
    pub fn net_heat_flow(&self, brake_power: F, t_d: F, loss_coefficient: F) -> F {
        self.heat_partition * brake_power - loss_coefficient * t_d
    }

    /// dt / (c_p m_disc), K/(W step): the temperature rise over a step `dt_s` per watt.
    pub fn step_gain(p: &ThermalParams, dt_s: f64) -> F {
        F::of(dt_s / (p.specific_heat * p.disc_mass))
    }
}
