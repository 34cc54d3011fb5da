//! Wheel slide protection (WSP) in the style of EN 15595.
//!
//! # Logic (per wheelset, evaluated every control cycle, 1 ms by default)
//!
//! **Reference speed.** The unit sees only wheel speeds v_j = r omega_j (as from axle speed
//! sensors). The vehicle reference speed v_ref follows the fastest wheel, but may fall no
//! faster than [`WspTuning::ref_max_decel_mps2`] (a wheel that slides cannot drag it down)
//! and rises at once when a wheel runs faster (a recovered wheel shows the true speed).
//!
//! **Slide detection.** For each wheel:
//! * speed deficit dv = v_ref - v_j, threshold dv_th = max(`deficit_min_mps`,
//!   `deficit_ratio` v_ref);
//! * wheel deceleration relative to the reference, a_rel = dv_j/dt - dv_ref/dt, from a
//!   first-order filtered derivative.
//! A wheel slides when dv > dv_th, or when dv > dv_th / 2 and it decelerates faster than
//! the reference by more than `decel_threshold_mps2` (early detection of a runaway).
//!
//! **Valve states** (one dump valve per wheelset):
//! * `Apply`: the cylinder follows the brake demand. Slide detected -> `Vent`.
//! * `Vent`: the cylinder vents. When the wheel speeds up clearly (its own acceleration
//!   a_j > `recover_accel_mps2`, i.e. the vented torque is well below the adhesion torque) and
//!   is no longer locked -> `Hold`.
//! * `Hold`: the cylinder pressure is held while the wheel spins back up to the vehicle
//!   speed. Runaway again or locked -> `Vent`. Once the wheel has stopped speeding up
//!   (a_j < `caught_up_accel_mps2`): dv below `reapply_ratio` dv_th -> `Apply`; dv still above
//!   dv_th -> `Vent` (the held pressure is too high to recover). Held longer than
//!   `hold_max_s` -> `Apply`.
//! The recovery thresholds use the wheel's own acceleration, not the deficit to the
//! reference: when every wheel slides the reference is itself too low, and only a wheel
//! that has spun back up to the rail speed can correct it.
//!
//! A recovered wheel runs at the true vehicle speed and lifts the reference to it, so
//! the reference is re-anchored after every WSP cycle even when all wheels slide at once.
//!
//! **Bounds.** A wheel is *locked* while v_j < `lock_ratio` v_ref. A locked wheel always
//! vents (no hold), so lock ends as soon as the vented pressure lets the adhesion spin it
//! up: with the reference brake unit (dead time 50 ms, vent lag 150 ms) a lock lasts well
//! under 0.4 s (the tests measure it). Continuous WSP action (vent and hold together: the
//! brake not applied) is limited to `vent_max_s` (EN 15595's WSP timer): after it the valve
//! returns to `Apply` and the channel may not act for `hold_max_s`, so that a faulty WSP
//! cannot release a brake indefinitely, not even by cycling vent and hold. Below
//! `min_speed_mps` the WSP is inhibited (`Apply`).

use hils_plant::Real;

/// Valve state of one wheelset's WSP dump valve (2 bits: 0 apply, 1 hold, 2 vent; `u8`
/// conversions derived, an undefined code reads as `Apply`).
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, Default, num_enum::IntoPrimitive, num_enum::FromPrimitive,
)]
#[repr(u8)]
pub enum Valve {
    /// The cylinder follows the demand (fill and exhaust through the relay valve).
    #[default]
    Apply,
    /// The cylinder pressure is held.
    Hold,
    /// The dump valve vents the cylinder.
    Vent,
}

impl Valve {
    /// The valve of the low 2 bits of `bits` (3 reads as `Apply`).
    pub fn from_bits(bits: u8) -> Valve {
        Valve::from(bits & 3)
    }
}

/// Thresholds of the WSP (SI units).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WspTuning {
    /// Smallest speed-deficit threshold, m/s.
    pub deficit_min_mps: f64,
    /// Speed-deficit threshold as a share of the reference speed.
    pub deficit_ratio: f64,
    /// Reapply when the deficit falls below this share of the threshold.
    pub reapply_ratio: f64,
    /// Wheel deceleration beyond the reference that counts as a runaway, m/s^2.
    pub decel_threshold_mps2: f64,
    /// Wheel acceleration that ends venting, m/s^2.
    pub recover_accel_mps2: f64,
    /// Wheel acceleration below which a held wheel has caught up, m/s^2.
    pub caught_up_accel_mps2: f64,
    /// A wheel below this share of the reference speed is locked.
    pub lock_ratio: f64,
    /// Longest continuous WSP action (vent and hold), s (EN 15595 WSP timer).
    pub vent_max_s: f64,
    /// Longest hold, s.
    pub hold_max_s: f64,
    /// WSP inhibited below this reference speed, m/s.
    pub min_speed_mps: f64,
    /// Largest fall rate of the reference speed, m/s^2.
    pub ref_max_decel_mps2: f64,
    /// Time constant of the wheel-deceleration filter, s.
    pub accel_filter_s: f64,
}

impl Default for WspTuning {
    fn default() -> Self {
        Self {
            deficit_min_mps: 0.8,
            deficit_ratio: 0.06,
            reapply_ratio: 0.5,
            decel_threshold_mps2: 2.5,
            recover_accel_mps2: 1.5,
            caught_up_accel_mps2: 0.0,
            lock_ratio: 0.5,
            vent_max_s: 3.0,
            hold_max_s: 1.0,
            min_speed_mps: 1.4,
            ref_max_decel_mps2: 2.0,
            accel_filter_s: 0.01,
        }
    }
}

impl WspTuning {
    /// Checks every value against its physical range (NaN and inf are out of range); the
    /// error names the value by its key, `wsp.` and the field's name without its unit
    /// (`wsp.vent_max` for [`WspTuning::vent_max_s`]).
    pub fn validate(&self) -> Result<(), hils_plant::ParamError> {
        use hils_plant::params::check;
        check("wsp.deficit_min", self.deficit_min_mps, 0.0, 10.0)?;
        check("wsp.deficit_ratio", self.deficit_ratio, 0.0, 1.0)?;
        check("wsp.reapply_ratio", self.reapply_ratio, 0.0, 1.0)?;
        check("wsp.decel_threshold", self.decel_threshold_mps2, 0.0, 50.0)?;
        check("wsp.recover_accel", self.recover_accel_mps2, -50.0, 50.0)?;
        check(
            "wsp.caught_up_accel",
            self.caught_up_accel_mps2,
            -50.0,
            50.0,
        )?;
        check("wsp.lock_ratio", self.lock_ratio, 0.0, 1.0)?;
        check("wsp.vent_max", self.vent_max_s, 0.0, 60.0)?;
        check("wsp.hold_max", self.hold_max_s, 0.0, 60.0)?;
        check("wsp.min_speed", self.min_speed_mps, 0.0, 20.0)?;
        check("wsp.ref_max_decel", self.ref_max_decel_mps2, 0.0, 50.0)?;
        check("wsp.accel_filter", self.accel_filter_s, 0.0, 10.0)
    }
}

/// Precomputed tuning in the unit's float type, for a control period `dt`.
#[derive(Clone, Copy, Debug)]
pub struct WspConstants<F> {
    /// [`WspTuning::deficit_min_mps`], m/s.
    pub deficit_min_mps: F,
    /// [`WspTuning::deficit_ratio`] (share of the reference speed).
    pub deficit_ratio: F,
    /// [`WspTuning::reapply_ratio`] (share of the deficit threshold).
    pub reapply_ratio: F,
    /// [`WspTuning::decel_threshold_mps2`], m/s^2.
    pub decel_threshold_mps2: F,
    /// [`WspTuning::recover_accel_mps2`], m/s^2.
    pub recover_accel_mps2: F,
    /// [`WspTuning::caught_up_accel_mps2`], m/s^2.
    pub caught_up_accel_mps2: F,
    /// [`WspTuning::lock_ratio`] (share of the reference speed).
    pub lock_ratio: F,
    /// [`WspTuning::vent_max_s`] in control periods (rounded).
    pub vent_max_cycles: u32,
    /// [`WspTuning::hold_max_s`] in control periods (rounded).
    pub hold_max_cycles: u32,
    /// [`WspTuning::min_speed_mps`], m/s.
    pub min_speed_mps: F,
    /// Largest fall of the reference speed in one control period, m/s
    /// ([`WspTuning::ref_max_decel_mps2`] x dt).
    pub ref_fall_per_cycle_mps: F,
    /// 1 / dt, 1/s (the control period's rate).
    pub inv_dt: F,
    /// Filter gain dt / (tau + dt).
    pub accel_gain: F,
}

impl<F: Real> WspConstants<F> {
    /// The tuning `t` in the float type `F` for the control period `dt` (s).
    pub fn new(t: &WspTuning, dt: f64) -> Self {
        let cycles = |s: f64| (s / dt + 0.5) as u32;
        Self {
            deficit_min_mps: F::of(t.deficit_min_mps),
            deficit_ratio: F::of(t.deficit_ratio),
            reapply_ratio: F::of(t.reapply_ratio),
            decel_threshold_mps2: F::of(t.decel_threshold_mps2),
            recover_accel_mps2: F::of(t.recover_accel_mps2),
            caught_up_accel_mps2: F::of(t.caught_up_accel_mps2),
            lock_ratio: F::of(t.lock_ratio),
            vent_max_cycles: cycles(t.vent_max_s),
            hold_max_cycles: cycles(t.hold_max_s),
            min_speed_mps: F::of(t.min_speed_mps),
            ref_fall_per_cycle_mps: F::of(t.ref_max_decel_mps2 * dt),
            inv_dt: F::of(1.0 / dt),
            accel_gain: F::of(dt / (t.accel_filter_s + dt)),
        }
    }
}

/// Reference speed estimate from the wheel speeds; `accel` is the filtered rate of its
/// falls (rises re-anchor it and are left out, so `accel <= 0` under braking).
#[derive(Clone, Copy, Debug, Default)]
pub struct ReferenceSpeed<F> {
    /// Estimated vehicle (reference) speed, m/s.
    pub speed: F,
    /// Filtered rate of change, m/s^2.
    pub accel: F,
    initialised: bool,
}

impl<F: Real> ReferenceSpeed<F> {
    /// One control period: the fastest wheel speed (m/s), limited to a fall of
    /// `ref_fall_per_cycle_mps`, and the filtered rate of the fall.
    pub fn update(&mut self, k: &WspConstants<F>, wheel_speeds: &[F; 4]) {
        let fastest = wheel_speeds.iter().fold(F::ZERO, |m, &v| m.max(v));
        if !self.initialised {
            self.speed = fastest;
            self.initialised = true;
            return;
        }
        let previous = self.speed;
        let floor = previous - k.ref_fall_per_cycle_mps;
        self.speed = fastest.max(floor).max(F::ZERO);
        // Only the fall of the reference is a vehicle deceleration. A rise re-anchors the
        // estimate to a wheel that has spun back up to the rail speed (issue 13: when
        // wheelset 4 recovered, the rise drove the filtered derivative to ~+4 m/s^2 and
        // the runaway test fired on a normally braking wheelset 2); it is not fed to the
        // derivative filter.
        let raw = (self.speed - previous).min(F::ZERO) * k.inv_dt;
        self.accel += (raw - self.accel) * k.accel_gain;
    }
}

/// One wheelset's WSP channel.
#[derive(Clone, Copy, Debug, Default)]
pub struct WspChannel<F> {
    /// The dump valve command of this wheelset.
    pub valve: Valve,
    /// Filtered wheel acceleration, m/s^2.
    pub accel: F,
    last_speed: F,
    initialised: bool,
    /// Cycles spent in the current valve state.
    cycles_in_state: u32,
    /// Cycles of continuous WSP action (vent or hold: the brake not applied), for the WSP
    /// timer; 0 while the valve applies.
    released_cycles: u32,
    /// Cycles left during which the channel may not vent (after the vent timer expired).
    inhibit_cycles: u32,
}

impl<F: Real> WspChannel<F> {
    /// One control cycle: updates the valve from wheel speed `v` and the reference.
    pub fn update(&mut self, k: &WspConstants<F>, v: F, reference: &ReferenceSpeed<F>) -> Valve {
        if !self.initialised {
            self.last_speed = v;
            self.initialised = true;
        }
        let raw = (v - self.last_speed) * k.inv_dt;
        self.last_speed = v;
        self.accel += (raw - self.accel) * k.accel_gain;

        let v_ref = reference.speed;
        let deficit = v_ref - v;
        let threshold = k.deficit_min_mps.max(k.deficit_ratio * v_ref);
        let half = F::of(0.5) * threshold;
        let rel_accel = self.accel - reference.accel;
        let runaway = deficit > half && rel_accel < -k.decel_threshold_mps2;
        let slide = deficit > threshold || runaway;
        let locked = v < k.lock_ratio * v_ref;

        let next = if !(v_ref > k.min_speed_mps) || self.inhibit_cycles > 0 {
            self.inhibit_cycles = self.inhibit_cycles.saturating_sub(1);
            Valve::Apply
        } else if self.valve != Valve::Apply && self.released_cycles >= k.vent_max_cycles {
            // WSP timer: vent and hold together have kept the brake off for `vent_max_s`
            // (a Vent -> Hold -> Vent cycle does not restart it). Give the brake back and do
            // not act again for `hold_max_s`, so a slide that never clears cannot keep the
            // brake off.
            self.inhibit_cycles = k.hold_max_cycles;
            Valve::Apply
        } else {
            match self.valve {
                Valve::Apply => {
                    if slide {
                        Valve::Vent
                    } else {
                        Valve::Apply
                    }
                }
                Valve::Vent => {
                    if self.accel > k.recover_accel_mps2 && !locked {
                        Valve::Hold
                    } else {
                        Valve::Vent
                    }
                }
                Valve::Hold => {
                    if runaway || locked {
                        Valve::Vent
                    } else if self.cycles_in_state >= k.hold_max_cycles {
                        Valve::Apply
                    } else if self.accel < k.caught_up_accel_mps2 {
                        if deficit < k.reapply_ratio * threshold {
                            Valve::Apply
                        } else if deficit > threshold {
                            Valve::Vent
                        } else {
                            Valve::Hold
                        }
                    } else {
                        Valve::Hold
                    }
                }
            }
        };
        self.released_cycles = if next == Valve::Apply {
            0
        } else {
            self.released_cycles.saturating_add(1)
        };
        if next == self.valve {
            self.cycles_in_state = self.cycles_in_state.saturating_add(1);
        } else {
            self.cycles_in_state = 0;
            self.valve = next;
        }
        next
    }
}
