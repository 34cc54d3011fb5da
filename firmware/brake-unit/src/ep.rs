//! The ECU's electro-pneumatic (EP) valve: "The ECU controls an electro-pneumatic (EP)
//! valve that generates the required pressure using a PI (proportional-plus-integral)
//! control and a hysteresis-compensating algorithm" (paper, text of Fig 6).
//!
//! Per control cycle (1 ms), with the pilot pressure p_ep measured:
//!
//!   e = p_t - p_ep,   I += k_i dt e (limited to +-supply),
//!   u = p_t + k_p e + I + c,   c = +h/2 while the pressure must rise, -h/2 while it must fall
//!
//! (feedforward, PI, hysteresis compensation). The valve has a play of width h (its
//! output y moves only once u leaves [y - h/2, y + h/2]: magnetic and friction hysteresis of
//! a proportional solenoid), and the pilot pressure follows y with the lag
//! `ep_time_constant`. Without the compensation the integral has to wind through h/2 on
//! every reversal; with it the valve output lands on the target at once. The pilot pressure
//! then drives the relay valve (BOU) and the cylinders after the dead time.

use hils_plant::Real;

/// Precomputed EP constants in the unit's float type.
#[derive(Clone, Copy, Debug)]
pub struct EpConstants<F> {
    kp: F,
    ki_dt: F,
    half_h: F,
    compensate: F,
    /// Pilot lag factor per control cycle 1 - exp(-dt / tau).
    gain: F,
    supply: F,
    /// Error band inside which the direction of motion is kept, Pa.
    band: F,
}

impl<F: Real> EpConstants<F> {
    /// Constants for a control cycle `dt_s`.
    pub fn new(p: &crate::params::BrakeUnitParams, dt_s: f64, supply_pa: f64) -> Self {
        Self {
            kp: F::of(p.ep_kp),
            ki_dt: F::of(p.ep_ki_per_s * dt_s),
            half_h: F::of(0.5 * p.ep_hysteresis_pa),
            compensate: if p.ep_hysteresis_compensation {
                F::ONE
            } else {
                F::ZERO
            },
            gain: F::of(1.0 - hils_plant::math::exp_f64(-dt_s / p.ep_time_constant_s)),
            supply: F::of(supply_pa),
            band: F::of(0.01 * p.ep_hysteresis_pa + 1.0),
        }
    }
}

/// The EP valve and its PI controller.
#[derive(Clone, Copy, Debug, Default)]
pub struct EpValve<F> {
    integral: F,
    /// Valve output behind the play, Pa.
    output: F,
    /// Pilot pressure, Pa.
    pilot: F,
    /// Rounding carry of the pilot lag (compensated, as the cylinder's).
    carry: F,
    last_target: F,
    rising: bool,
}

impl<F: Real> EpValve<F> {
    /// The pilot pressure, Pa.
    pub fn pilot(&self) -> F {
        self.pilot
    }

    /// One control cycle toward the target pressure `target` (Pa); returns the pilot
    /// pressure.
    pub fn update(&mut self, k: &EpConstants<F>, target: F) -> F {
        let error = target - self.pilot;
        if target > self.last_target || error > k.band {
            self.rising = true;
        } else if target < self.last_target || error < -k.band {
            self.rising = false;
        }
        self.last_target = target;
        self.integral = (self.integral + k.ki_dt * error).clamp_to(-k.supply, k.supply);
        let direction = if self.rising { F::ONE } else { -F::ONE };
        let u = target + k.kp * error + self.integral + direction * k.half_h * k.compensate;
        if u > self.output + k.half_h {
            self.output = u - k.half_h;
        } else if u < self.output - k.half_h {
            self.output = u + k.half_h;
        }
        let y = self.output.clamp_to(F::ZERO, k.supply);
        approach(&mut self.pilot, &mut self.carry, y, k.gain);
        self.pilot
    }
}

/// First-order lag `value += (target - value) gain` with the rounding error carried into
/// the next update (compensated summation): the plain update stalls in f32 where the
/// increment falls below half an ulp of the value (78 Pa short of 355 kPa at gain 2e-4).
#[inline]
pub(crate) fn approach<F: Real>(value: &mut F, carry: &mut F, target: F, gain: F) {
    let step = (target - *value) * gain - *carry;
    let next = *value + step;
    *carry = (next - *value) - step;
    *value = next;
}
