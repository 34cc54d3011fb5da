//! Wheel-rail adhesion: Polach's simplified contact model, paper Eqs (9)-(12).

use crate::params::{AdhesionSet, ContactParams, Rail};
use crate::real::Real;
use crate::tracked::TrackedExp;

/// Precomputed constants of the Polach model for one rail condition.
#[derive(Clone, Copy, Debug)]
pub struct Polach<F> {
    two_over_pi: F,
    k_a: F,
    k_s: F,
    /// mu_0 (1 - A): the part of the friction that decays with slip velocity (Eq 11).
    mu_decaying: F,
    /// mu_0 A = mu_inf (Eq 11).
    mu_inf: F,
    b_exp: F,
    creep_speed_floor: F,
    /// k_A and k_s times the stiffness (2/3) C pi a^2 b, N (Eq 10 reads
    /// eps = stiffness s / (Q mu)): k_A eps and k_s eps from s / (Q mu) (Eq 10 folded).
    k_a_stiffness: F,
    k_s_stiffness: F,
    /// (2/pi) `stiffness` k_A and k_s, N (Eq 9 times Eq 10, folded into the chord's terms).
    two_over_pi_stiffness_k_a: F,
    two_over_pi_stiffness_k_s: F,
}

/// The contact of one wheelset (two wheels lumped: Q is the axle load).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ContactForce<F> {
    /// Adhesion force F, N (positive: the rail decelerates the wheelset).
    pub force: F,
    /// Chord slope F / (v - r omega), N s/m, >= 0: the semi-implicit spin update treats
    /// F = chord * slip velocity implicitly, which is stable at any step and exact at a
    /// steady state.
    pub chord: F,
    /// Wheel-rail friction coefficient mu (Eq 11).
    pub mu: F,
    /// Creepage s (Eq 12, with the speed floor).
    pub creepage: F,
}

impl<F: Real> Polach<F> {
    /// Polach's contact with the `[contact]` geometry and the parameter set of `rail` (paper Eqs (9)-(12)).
    pub fn new(contact: &ContactParams, rail: Rail) -> Self {
        Self::with_set(contact, &contact.set(rail))
    }

    /// The model of one parameter set `set` on the contact geometry of `contact` (the
    /// track's low-adhesion sets, [`crate::track`]).
    #[inline(never)] // one copy for the four surfaces (board flash)
    pub fn with_set(contact: &ContactParams, set: &AdhesionSet) -> Self {
        let stiffness = 2.0 / 3.0
            * contact.shear_stiffness_c
            * core::f64::consts::PI
            * contact.semi_axis_a
            * contact.semi_axis_a
            * contact.semi_axis_b;
        Self {
            two_over_pi: F::of(2.0 / core::f64::consts::PI),
            k_a: F::of(set.k_a),
            k_s: F::of(set.k_s),
            mu_decaying: F::of(set.mu_0 * (1.0 - set.a_ratio)),
            mu_inf: F::of(set.mu_0 * set.a_ratio),
            b_exp: F::of(set.b_exp),
            creep_speed_floor: F::of(contact.creep_speed_floor),
            k_a_stiffness: F::of(set.k_a * stiffness),
            k_s_stiffness: F::of(set.k_s * stiffness),
            two_over_pi_stiffness_k_a: F::of(2.0 / core::f64::consts::PI * stiffness * set.k_a),
            two_over_pi_stiffness_k_s: F::of(2.0 / core::f64::consts::PI * stiffness * set.k_s),
        }
    }

    /// Eq (11): mu = mu_0 [(1 - A) e^(-B |w|) + A] for slip velocity w = v - r omega.
    #[inline(always)]
    pub fn friction(&self, slip_velocity: F) -> F {
        self.mu_decaying * (-self.b_exp * slip_velocity.abs()).exp() + self.mu_inf
    }

    /// Eqs (9)-(12) for slip velocity `u = v - r omega` (m/s), wheelset speed `v` (m/s)
    /// and axle load `q` (N). Returns the force, its chord slope F/u, mu and the creepage.
    ///
    /// F = (2 mu Q / pi) [k_A eps / (1 + (k_A eps)^2) + atan(k_s eps)]        (9)
    /// eps = (2/3) C pi a^2 b s / (Q mu)                                      (10)
    /// s = u / max(|v|, floor)                                                (12)
    /// Written as F = chord * u with chord = (2/pi)(K/V)[k_A/(1+(k_A eps)^2) + k_s atan(x)/x],
    /// x = k_s eps, which has no division by u and stays finite at u = 0 and Q -> 0.
    #[inline(always)]
    pub fn evaluate(&self, slip_velocity: F, speed: F, load: F) -> ContactForce<F> {
        self.evaluate_with_mu(slip_velocity, speed, load, self.friction(slip_velocity))
    }

    /// Eq (11) with e^(-B |w|) from a [`TrackedExp`] (the plant's step: w moves little
    /// from step to step; within [`crate::tracked::TRACK_MAX_REL_ERROR`] of [`Self::friction`]).
    #[inline(always)]
    pub fn friction_tracked(&self, slip_velocity: F, decay: &mut TrackedExp<F>) -> F {
        self.mu_decaying * decay.exp(-self.b_exp * slip_velocity.abs()) + self.mu_inf
    }

    /// [`Self::evaluate`] with the friction coefficient `mu` given (Eq 11, possibly scaled
    /// by the degraded-adhesion recovery of [`crate::track`]): Eqs (9), (10) and (12).
    #[inline(always)]
    pub fn evaluate_with_mu(&self, slip_velocity: F, speed: F, load: F, mu: F) -> ContactForce<F> {
        let v_floor = speed.abs().max(self.creep_speed_floor);
        let load_mu = load * mu;
        if !(load_mu > F::ZERO) {
            return ContactForce {
                force: F::ZERO,
                chord: F::ZERO,
                mu,
                creepage: slip_velocity / v_floor,
            };
        }
        // One division for Eqs (10) and (12): 1 / (V Q mu) gives 1/V, 1/(Q mu) and 1/Q.
        let inv_v_load_mu = F::ONE / (v_floor * load_mu);
        let inv_v_floor = load_mu * inv_v_load_mu;
        let creepage = slip_velocity * inv_v_floor;
        // k_A eps and k_s eps (Eq 10 with the stiffness folded into k_A and k_s).
        let slip_per_v_load_mu = slip_velocity * inv_v_load_mu;
        let x_a = self.k_a_stiffness * slip_per_v_load_mu;
        let x_s = self.k_s_stiffness * slip_per_v_load_mu;
        let adhesion_part = self.two_over_pi_stiffness_k_a / (F::ONE + x_a * x_a);
        let atan_over_x = x_s.atan_over_x();
        let chord = (adhesion_part + self.two_over_pi_stiffness_k_s * atan_over_x) * inv_v_floor;
        ContactForce {
            force: chord * slip_velocity,
            chord,
            mu,
            creepage,
        }
    }

    /// Adhesion coefficient F/Q (paper Eq 13) at creepage `s`, speed `v` (m/s) and axle
    /// load `q` (N) (the curve of Fig 11).
    pub fn adhesion_coefficient(&self, creepage: F, speed: F, load: F) -> F {
        let v_floor = speed.abs().max(self.creep_speed_floor);
        if !(load > F::ZERO) {
            return F::ZERO;
        }
        self.evaluate(creepage * v_floor, speed, load).force / load
    }

    /// Normalised force F/(Q mu) as a function of eps (the bracket of Eq 9 times 2/pi);
    /// tends to 1 as eps grows. Used by tests of the Polach identities.
    pub fn normalised_force(&self, eps: F) -> F {
        let x_a = self.k_a * eps;
        self.two_over_pi * (x_a / (F::ONE + x_a * x_a) + (self.k_s * eps).atan())
    }
}
