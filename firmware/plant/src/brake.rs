//! Brake caliper, paper Eq (1): T_b = mu_d (A_c P_c - K_r) r_c l_p N_d.

use crate::params::BrakeParams;
use crate::real::Real;

/// Precomputed caliper constants.
#[derive(Clone, Copy, Debug)]
pub struct Caliper<F> {
    piston_area: F,
    retaining_spring_force: F,
    lever_ratio: F,
    /// l_p N_d: friction radius times friction faces, m.
    radius_faces: F,
    friction_faces: F,
    /// Pad force at 1.5 x the supply pressure (Eq 1; at least 1 N): clamp-force inputs
    /// above it are clamped and flagged.
    pub clamp_force_limit: F,
    /// 1.5 x the supply pressure: pressure inputs above it are clamped and flagged.
    pub pressure_limit: F,
}

impl<F: Real> Caliper<F> {
    /// The caliper of one wheelset with the `[brake]` parameters (paper Eq (1)).
    pub fn new(p: &BrakeParams) -> Self {
        let pressure_limit = F::of(1.5 * p.supply_pressure);
        let mut caliper = Self {
            piston_area: F::of(p.piston_area),
            retaining_spring_force: F::of(p.retaining_spring_force),
            lever_ratio: F::of(p.lever_ratio),
            radius_faces: F::of(p.friction_radius * p.friction_faces as f64),
            friction_faces: F::of(p.friction_faces as f64),
            clamp_force_limit: F::ZERO,
            pressure_limit,
        };
        // The limit is the pad force of the pressure limit computed as the step computes
        // it (in F): every step of that computation rounds monotonically, so the pad force
        // of any pressure within [0, pressure_limit] is within [0, clamp_force_limit] with
        // no further clamp in the step.
        caliper.clamp_force_limit = caliper.clamp_force(pressure_limit).max(F::ONE);
        caliper
    }

    /// Pad normal force per friction face from cylinder pressure:
    /// f_clamp = max(0, A_c P_c - K_r) r_c (the bracket of Eq 1 times the lever ratio).
    #[inline(always)]
    pub fn clamp_force(&self, cylinder_pressure: F) -> F {
        (self.piston_area * cylinder_pressure - self.retaining_spring_force).max(F::ZERO)
            * self.lever_ratio
    }

    /// Eq (1): brake torque T_b = mu_d f_clamp l_p N_d, N m.
    #[inline(always)]
    pub fn torque(&self, mu_d: F, clamp_force: F) -> F {
        mu_d * clamp_force * self.radius_faces
    }

    /// Tangential friction force at the friction radius summed over faces, T_b / l_p, N.
    #[inline(always)]
    pub fn friction_force(&self, mu_d: F, clamp_force: F) -> F {
        mu_d * clamp_force * self.friction_faces
    }
}

/// Cylinder pressure that gives a pad clamp force (inverse of [`Caliper::clamp_force`]), Pa.
pub fn pressure_for_clamp_force(p: &BrakeParams, clamp_force: f64) -> f64 {
    (clamp_force / p.lever_ratio + p.retaining_spring_force) / p.piston_area
}
