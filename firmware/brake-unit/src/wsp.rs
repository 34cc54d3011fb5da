//! Wheel slide protection (WSP) with pressure memory, in the style of EN 15595.
//!
//! A modern WSP does not cycle a sliding wheel between locked and rolling: it takes a little
//! air out of the cylinder, holds, puts most of it back at once and then feels its way up
//! again, so that the wheel runs near the creep of peak adhesion, where the adhesion curve
//! is flat (on the project's low rail the force at twice the peak creep is still 95 % of
//! the peak, at a slip of 1 m/s 95-100 %). The logic below is that of the published
//! descriptions of rule-based WSP and ABS control cycles; the values are the project's
//! (assumed, chosen once on the WSP bench's programmes, `docs/wsp.md`), because no
//! manufacturer publishes its own.
//!
//! # Sources
//!
//! * Detection on speed deficit, deceleration and slip against a reference speed, with
//!   thresholds "from engineers' experience and field tests", and a model-based
//!   estimate of the adhesion force besides: "A 4-Phase Combined Adhesion Threshold
//!   Algorithm for Wheel Slide Protection Systems in Rail Vehicles", Actuators 13 (2024) 47
//!   (Tongji University). Refill and dump valves driven by an ECU from tachometer speeds:
//!   Pugi et al., "HIL testing of wheel slide protection systems", Railway Engineering
//!   Science 31 (2023); the Trenitalia WSP that Allotta, Conti, Meli, Ridolfi model, IEEE
//!   Trans. Control Syst. Technol. 23 (2015) 186-196.
//! * The control cycle (reduce, hold while the wheel re-accelerates, reapply fast, then
//!   raise in stages until the wheel decelerates again; the staged rise much slower than
//!   the first application): the ABS cycle of the Bosch Automotive Handbook ("typical
//!   control cycles").
//! * Cycling the pressure about the pressure of the critical slip: EP 0 392 686 (antilock
//!   control); a reduction sized from the brake force just before it: US 5 673 981. The
//!   "pressure memory" of railway WSP is the same idea: the pressure at which the wheel last
//!   slid says where the adhesion limit is.
//!
//! # Logic (per wheelset, every control cycle of 1 ms)
//!
//! **Observer.** The unit knows each wheelset's cylinder pressure p (its transducer) and
//! wheel acceleration a_w (filtered, `accel_filter_s`). The wheel's spin balance,
//! I_w dw/dt = F r - T_b, with Eq (1)'s T_b = k_T (p - p_s) (k_T = mu_d0 A_c r_c l_p N_d,
//! p_s = K_r / A_c the pressure at which the pads start to clamp), gives the adhesion force
//! the wheel carries as a brake force equivalent, p_a = (p - p_s) + c_I a_w with
//! c_I = I_w / (r k_T) ([`Pneumatics::inertia_pa_per_mps2`], 27.4 kPa per m/s^2 for the
//! reference vehicle). While the wheel rolls, p_a follows the brake force; past the peak of
//! the adhesion curve it stops following it. The rail forces of all four decelerate the
//! vehicle: a_v = k_T sum(p_a) / (r M) ([`vehicle_deceleration`]; mu_d0 is the unit's
//! nominal pad friction, so a_v is low by the pads' excess friction, ~10 %).
//!
//! **Reference speed.** v_ref follows the fastest wheel, rises at once when a wheel runs
//! faster (a recovered wheel shows the true speed: it re-anchors the reference even when
//! every axle has slid) and falls no faster than `ref_decel_gain` a_v +
//! `ref_margin_decel_mps2` (nor than
//! `ref_max_decel_mps2`): a group of wheels sliding together cannot drag it down.
//!
//! **Slide.** Speed deficit dv = v_ref - v_w against dv_th = max(`deficit_min_mps`,
//! `deficit_ratio` v_ref), and the deceleration against the reference's,
//! a_rel = a_w - dv_ref/dt. A wheel slides when
//! * dv > dv_th; or
//! * dv > dv_th / 2 and a_rel < -`decel_threshold_mps2` (a runaway seen early); or
//! * a_w < -(a_v + `overbrake_decel_mps2`) and dv > `overbrake_deficit_ratio` dv_th (it
//!   decelerates faster than the rail forces decelerate the vehicle: its brake torque
//!   exceeds its adhesion, whatever the reference). The speed loss keeps the swing of the
//!   creep on a patch of better adhesion (the stiff side of its curve) from counting.
//!
//! A wheel below `lock_ratio` v_ref is locked.
//!
//! **Phases** (each valve command acts on the cylinder one pneumatic dead time later,
//! `[brake_unit] dead_time`; "brake force share" is the share of p - p_s, so that a share
//! means the same torque share at any pressure):
//! 1. *Apply*: the cylinder follows the demand (relay valve).
//! 2. *Dump*: on a slide the wheel's pressure memory is set, p_m = p_s + max(p_a) + c_I a_v
//!    (the pressure that holds the wheel at the highest adhesion it carried in this rise,
//!    while it follows the vehicle; at most p), and the cylinder vents for the time the vent
//!    lag takes to `dump_share` of p_m's brake force: t = tau_v ln(p / p_target). Then Hold.
//!    A locked wheel vents on.
//! 3. *Hold*: the pressure is held as soon as the dump ends. A wheel that has not begun to
//!    spin up (a_w > `turn_accel_mps2`) once the dump has had time to act (the dead time
//!    and `dump_settle_s`) gets another dump step, to `dump_share` of its present brake
//!    force. Spun up, then recovered (dv below `reapply_ratio` dv_th and a_w back below
//!    `caught_up_accel_mps2`), or held for `hold_max_s`: Reapply.
//! 4. *Reapply*: one timed fill, t = tau_f ln((p_d - p) / (p_d - p_t)), to
//!    p_t = `memory_share` of p_m's brake force; then Probe.
//! 5. *Probe*: a slow pulsed rise that feels for more adhesion: holds of
//!    `[brake_unit] reapply_pulse_hold_s`, each followed by a timed fill that raises the
//!    brake force by `probe_step_share` (at most `reapply_pulse_fill_s` of fill). Back at
//!    95 % of the demand: Apply. A sudden rise of adhesion (a patch of better grip):
//!    p_a above `risen_share` of the remembered peak, or the wheel spinning up faster than
//!    `sudden_grip_accel_mps2` under a rising brake force: Apply at once, the cylinder
//!    fills to the full demand. A probe that reaches `cap_share` of p_m's brake force
//!    without such a rise has passed the peak the memory knows: it counts as a slide. A
//!    slide in Reapply or Probe: Dump, with a new memory.
//!
//! **Bounds** (EN 15595). Continuous WSP action (vent and hold together: the brake not
//! applied) is limited to `vent_max_s` (the WSP timer): after it the valve returns to Apply
//! and the channel may not act for `timer_inhibit_s`, so that a faulty WSP cannot release a
//! brake indefinitely, not even by cycling vent and hold. Below `min_speed_mps` the WSP is
//! inhibited (Apply). A locked wheel always vents (no hold).

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

/// The WSP's phase of one wheelset (module doc, "Phases").
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Phase {
    /// The cylinder follows the demand.
    #[default]
    Apply,
    /// A timed vent step.
    Dump,
    /// Pressure held while the wheel turns and recovers.
    Hold,
    /// One timed fill to the pressure memory's share.
    Reapply,
    /// Pulsed slow rise.
    Probe,
}

/// Thresholds and times of the WSP (SI units). One tuning serves every speed, load,
/// demand and surface (issue 25); every value is the project's assumption, chosen on the
/// WSP bench (`docs/wsp.md`, with the figures of the values next to them).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WspTuning {
    /// Smallest speed-deficit threshold, m/s (0.8).
    pub deficit_min_mps: f64,
    /// Speed-deficit threshold as a share of the reference speed (0.06).
    pub deficit_ratio: f64,
    /// Recovered when the deficit falls below this share of the threshold (0.5).
    pub reapply_ratio: f64,
    /// Wheel deceleration beyond the reference's that counts as a runaway, m/s^2 (2.5).
    pub decel_threshold_mps2: f64,
    /// A wheel decelerating faster than the vehicle by more than this slides, m/s^2 (1.0).
    pub overbrake_decel_mps2: f64,
    /// ... once it has lost this share of the deficit threshold against the reference
    /// (0.2; also the least loss at which a probe's cap counts).
    pub overbrake_deficit_ratio: f64,
    /// A held wheel has turned once its own acceleration exceeds this, m/s^2 (0).
    pub turn_accel_mps2: f64,
    /// A turned wheel has caught up once its own acceleration falls below this, m/s^2 (0).
    pub caught_up_accel_mps2: f64,
    /// Brake force share of the pressure memory a slide's dump vents to; a further dump
    /// step vents to this share of the present brake force (0.8).
    pub dump_share: f64,
    /// Time a dump step is given to act on the wheel after its vent and the dead time, s
    /// (0.02).
    pub dump_settle_s: f64,
    /// Brake force share of the pressure memory the fast reapply fills to (0.9).
    pub memory_share: f64,
    /// Each probe pulse raises the brake force by this share of itself (0.015).
    pub probe_step_share: f64,
    /// A probe goes no higher than this share of the memory's brake force without a rise
    /// of the adhesion (1.2).
    pub cap_share: f64,
    /// The adhesion has risen when the wheel carries this share of the remembered peak
    /// (1.1) ...
    pub risen_share: f64,
    /// ... or spins up faster than this while the brake force rises, m/s^2 (2.0).
    pub sudden_grip_accel_mps2: f64,
    /// A wheel below this share of the reference speed is locked (0.5).
    pub lock_ratio: f64,
    /// Longest continuous WSP action (vent and hold), s (EN 15595 WSP timer; 3.0).
    pub vent_max_s: f64,
    /// Longest hold, s (2.0).
    pub hold_max_s: f64,
    /// Time the channel may not act after the WSP timer, s (1.0).
    pub timer_inhibit_s: f64,
    /// WSP inhibited below this reference speed, m/s (1.4).
    pub min_speed_mps: f64,
    /// Largest fall rate of the reference speed, m/s^2 (2.0).
    pub ref_max_decel_mps2: f64,
    /// The reference falls no faster than this times the vehicle's deceleration (from the
    /// adhesion the wheelsets carry; the pads' friction above mu_d0 makes that low by up to
    /// ~25 %) ... (1.3)
    pub ref_decel_gain: f64,
    /// ... plus this, m/s^2 (0.1).
    pub ref_margin_decel_mps2: f64,
    /// Time constant of the wheel-deceleration filter, s (0.01).
    pub accel_filter_s: f64,
}

impl Default for WspTuning {
    fn default() -> Self {
        Self {
            deficit_min_mps: 0.8,
            deficit_ratio: 0.06,
            reapply_ratio: 0.5,
            decel_threshold_mps2: 2.5,
            overbrake_decel_mps2: 1.0,
            overbrake_deficit_ratio: 0.2,
            turn_accel_mps2: 0.0,
            caught_up_accel_mps2: 0.0,
            dump_share: 0.8,
            dump_settle_s: 0.02,
            memory_share: 0.9,
            probe_step_share: 0.015,
            cap_share: 1.2,
            risen_share: 1.1,
            sudden_grip_accel_mps2: 2.0,
            lock_ratio: 0.5,
            vent_max_s: 3.0,
            hold_max_s: 2.0,
            timer_inhibit_s: 1.0,
            min_speed_mps: 1.4,
            ref_max_decel_mps2: 2.0,
            ref_decel_gain: 1.3,
            ref_margin_decel_mps2: 0.1,
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
        let accel = 50.0;
        for (key, value, min, max) in [
            ("wsp.deficit_min", self.deficit_min_mps, 0.0, 10.0),
            ("wsp.deficit_ratio", self.deficit_ratio, 0.0, 1.0),
            ("wsp.reapply_ratio", self.reapply_ratio, 0.0, 1.0),
            ("wsp.decel_threshold", self.decel_threshold_mps2, 0.0, accel),
            ("wsp.overbrake_decel", self.overbrake_decel_mps2, 0.0, accel),
            (
                "wsp.overbrake_deficit_ratio",
                self.overbrake_deficit_ratio,
                0.0,
                1.0,
            ),
            ("wsp.turn_accel", self.turn_accel_mps2, -accel, accel),
            (
                "wsp.caught_up_accel",
                self.caught_up_accel_mps2,
                -accel,
                accel,
            ),
            ("wsp.dump_share", self.dump_share, 0.0, 0.99),
            ("wsp.dump_settle", self.dump_settle_s, 0.0, 1.0),
            ("wsp.memory_share", self.memory_share, 0.0, 1.0),
            ("wsp.probe_step_share", self.probe_step_share, 1e-3, 1.0),
            ("wsp.cap_share", self.cap_share, 1.0, 10.0),
            ("wsp.risen_share", self.risen_share, 1.0, 10.0),
            (
                "wsp.sudden_grip_accel",
                self.sudden_grip_accel_mps2,
                0.0,
                accel,
            ),
            ("wsp.lock_ratio", self.lock_ratio, 0.0, 1.0),
            ("wsp.vent_max", self.vent_max_s, 0.0, 60.0),
            ("wsp.hold_max", self.hold_max_s, 0.0, 60.0),
            ("wsp.timer_inhibit", self.timer_inhibit_s, 0.0, 60.0),
            ("wsp.min_speed", self.min_speed_mps, 0.0, 20.0),
            ("wsp.ref_max_decel", self.ref_max_decel_mps2, 0.0, accel),
            ("wsp.ref_decel_gain", self.ref_decel_gain, 1.0, 10.0),
            (
                "wsp.ref_margin_decel",
                self.ref_margin_decel_mps2,
                0.0,
                accel,
            ),
            ("wsp.accel_filter", self.accel_filter_s, 0.0, 10.0),
        ] {
            check(key, value, min, max)?;
        }
        Ok(())
    }
}

/// What the WSP knows of the pneumatics it drives and of the vehicle (from `[brake_unit]`,
/// `[brake]`, `[friction]` and `[vehicle]`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pneumatics {
    /// Dead time from a valve command to the cylinder, s.
    pub dead_time_s: f64,
    /// Fill lag of the cylinder toward the demand, s.
    pub fill_time_constant_s: f64,
    /// Lag of a vent, s.
    pub vent_time_constant_s: f64,
    /// Cylinder pressure at which the pads start to clamp, K_r / A_c, Pa.
    pub spring_pressure_pa: f64,
    /// Longest fill of one probe pulse, s.
    pub pulse_fill_s: f64,
    /// Hold before each probe pulse's fill, s.
    pub pulse_hold_s: f64,
    /// Cylinder pressure whose brake torque (Eq 1 with mu_d0) spins the wheelset at 1 m/s^2
    /// at the rim: I_w / (r mu_d0 A_c r_c l_p N_d), Pa s^2/m.
    pub inertia_pa_per_mps2: f64,
    /// Vehicle deceleration per pascal of adhesion observer summed over the wheelsets:
    /// mu_d0 A_c r_c l_p N_d / (r M), M the moving mass (load-weighed), m/s^2/Pa.
    pub vehicle_decel_per_pa: f64,
}

impl Default for Pneumatics {
    /// The reference unit's (`[brake_unit]` and the plant's defaults).
    fn default() -> Self {
        Self::of(
            &crate::params::BrakeUnitParams::default(),
            &hils_plant::Params::default(),
        )
    }
}

impl Pneumatics {
    /// The pneumatics of a `[brake_unit]` section on the vehicle and caliper of `p`.
    pub fn of(u: &crate::params::BrakeUnitParams, p: &hils_plant::Params) -> Self {
        let b = &p.brake;
        let torque_per_pa = p.friction.mu_d0
            * b.piston_area
            * b.lever_ratio
            * b.friction_radius
            * b.friction_faces as f64;
        Self {
            dead_time_s: u.dead_time_s,
            fill_time_constant_s: u.fill_time_constant_s,
            vent_time_constant_s: u.vent_time_constant_s,
            spring_pressure_pa: b.retaining_spring_force / b.piston_area,
            pulse_fill_s: u.reapply_pulse_fill_s,
            pulse_hold_s: u.reapply_pulse_hold_s,
            inertia_pa_per_mps2: p.vehicle.wheelset_spin_inertia
                / (p.vehicle.wheel_radius * torque_per_pa),
            vehicle_decel_per_pa: torque_per_pa / (p.vehicle.wheel_radius * p.total_mass()),
        }
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
    /// [`WspTuning::overbrake_decel_mps2`], m/s^2.
    pub overbrake_decel_mps2: F,
    /// [`WspTuning::overbrake_deficit_ratio`].
    pub overbrake_deficit_ratio: F,
    /// [`WspTuning::turn_accel_mps2`], m/s^2.
    pub turn_accel_mps2: F,
    /// [`WspTuning::caught_up_accel_mps2`], m/s^2.
    pub caught_up_accel_mps2: F,
    /// [`WspTuning::dump_share`].
    pub dump_share: F,
    /// [`WspTuning::memory_share`].
    pub memory_share: F,
    /// [`WspTuning::probe_step_share`].
    pub probe_step_share: F,
    /// [`WspTuning::cap_share`].
    pub cap_share: F,
    /// [`WspTuning::risen_share`].
    pub risen_share: F,
    /// [`WspTuning::sudden_grip_accel_mps2`], m/s^2.
    pub sudden_grip_accel_mps2: F,
    /// [`WspTuning::lock_ratio`] (share of the reference speed).
    pub lock_ratio: F,
    /// [`WspTuning::vent_max_s`] in control periods (rounded).
    pub vent_max_cycles: u32,
    /// [`WspTuning::hold_max_s`] in control periods (rounded).
    pub hold_max_cycles: u32,
    /// [`WspTuning::timer_inhibit_s`] in control periods (rounded).
    pub timer_inhibit_cycles: u32,
    /// Dead time plus [`WspTuning::dump_settle_s`] in control periods: how long after its
    /// vent a dump step is judged.
    pub settle_cycles: u32,
    /// Longest fill of a probe pulse in control periods.
    pub pulse_fill_cycles: u32,
    /// Hold of a probe pulse in control periods.
    pub pulse_hold_cycles: u32,
    /// [`WspTuning::min_speed_mps`], m/s.
    pub min_speed_mps: F,
    /// Largest fall of the reference speed in one control period, m/s
    /// ([`WspTuning::ref_max_decel_mps2`] x dt).
    pub ref_fall_per_cycle_mps: F,
    /// [`WspTuning::ref_margin_decel_mps2`] x dt, m/s.
    pub ref_margin_per_cycle_mps: F,
    /// [`WspTuning::ref_decel_gain`] x dt, s.
    pub ref_gain_dt: F,
    /// 1 / dt, 1/s (the control period's rate).
    pub inv_dt: F,
    /// Filter gain dt / (tau + dt).
    pub accel_gain: F,
    /// [`Pneumatics::spring_pressure_pa`], Pa.
    pub spring_pa: F,
    /// [`Pneumatics::inertia_pa_per_mps2`], Pa s^2/m.
    pub inertia_pa_per_mps2: F,
    /// [`Pneumatics::vehicle_decel_per_pa`], m/s^2/Pa.
    pub vehicle_decel_per_pa: F,
    /// Fill lag in control periods (tau_f / dt).
    pub fill_tau_cycles: F,
    /// Vent lag in control periods (tau_v / dt).
    pub vent_tau_cycles: F,
}

impl<F: Real> WspConstants<F> {
    /// The tuning `t` with the pneumatics `p` in the float type `F` for the control period
    /// `dt` (s).
    pub fn new(t: &WspTuning, p: &Pneumatics, dt: f64) -> Self {
        let cycles = |s: f64| (s / dt + 0.5) as u32;
        Self {
            deficit_min_mps: F::of(t.deficit_min_mps),
            deficit_ratio: F::of(t.deficit_ratio),
            reapply_ratio: F::of(t.reapply_ratio),
            decel_threshold_mps2: F::of(t.decel_threshold_mps2),
            overbrake_decel_mps2: F::of(t.overbrake_decel_mps2),
            overbrake_deficit_ratio: F::of(t.overbrake_deficit_ratio),
            turn_accel_mps2: F::of(t.turn_accel_mps2),
            caught_up_accel_mps2: F::of(t.caught_up_accel_mps2),
            dump_share: F::of(t.dump_share),
            memory_share: F::of(t.memory_share),
            probe_step_share: F::of(t.probe_step_share),
            cap_share: F::of(t.cap_share),
            risen_share: F::of(t.risen_share),
            sudden_grip_accel_mps2: F::of(t.sudden_grip_accel_mps2),
            lock_ratio: F::of(t.lock_ratio),
            vent_max_cycles: cycles(t.vent_max_s),
            hold_max_cycles: cycles(t.hold_max_s),
            timer_inhibit_cycles: cycles(t.timer_inhibit_s),
            settle_cycles: cycles(p.dead_time_s + t.dump_settle_s),
            pulse_fill_cycles: cycles(p.pulse_fill_s).max(1),
            pulse_hold_cycles: cycles(p.pulse_hold_s),
            min_speed_mps: F::of(t.min_speed_mps),
            ref_fall_per_cycle_mps: F::of(t.ref_max_decel_mps2 * dt),
            ref_margin_per_cycle_mps: F::of(t.ref_margin_decel_mps2 * dt),
            ref_gain_dt: F::of(t.ref_decel_gain * dt),
            inv_dt: F::of(1.0 / dt),
            accel_gain: F::of(dt / (t.accel_filter_s + dt)),
            spring_pa: F::of(p.spring_pressure_pa),
            inertia_pa_per_mps2: F::of(p.inertia_pa_per_mps2),
            vehicle_decel_per_pa: F::of(p.vehicle_decel_per_pa),
            fill_tau_cycles: F::of(p.fill_time_constant_s / dt),
            vent_tau_cycles: F::of(p.vent_time_constant_s / dt),
        }
    }

    /// The pressure of brake force share `share` of pressure `p` (Pa): p_s + share (p - p_s).
    fn share_of(&self, p: F, share: F) -> F {
        self.spring_pa + share * (p - self.spring_pa).max(F::ZERO)
    }
}

/// The vehicle's deceleration from the adhesion the wheelsets carry: the sum of their
/// observers p_a (Pa, at least 0) times [`WspConstants::vehicle_decel_per_pa`] (the rail
/// forces on the moving mass), m/s^2.
pub fn vehicle_deceleration<F: Real>(k: &WspConstants<F>, channels: &[WspChannel<F>; 4]) -> F {
    let sum = channels
        .iter()
        .fold(F::ZERO, |s, c| s + c.adhesion_pa.max(F::ZERO));
    sum * k.vehicle_decel_per_pa
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
    /// One control period: the fastest wheel speed (m/s), its fall limited to the
    /// vehicle's deceleration `vehicle_decel` (m/s^2, [`vehicle_deceleration`]) plus
    /// `ref_margin_decel_mps2` (times `ref_decel_gain`) and to `ref_max_decel_mps2`; and the
    /// filtered rate of the
    /// fall. When every wheel slides, the reference follows the vehicle, not the wheels.
    pub fn update(&mut self, k: &WspConstants<F>, wheel_speeds: &[F; 4], vehicle_decel: F) {
        let fastest = wheel_speeds.iter().fold(F::ZERO, |m, &v| m.max(v));
        if !self.initialised {
            self.speed = fastest;
            self.initialised = true;
            return;
        }
        let previous = self.speed;
        let fall = (vehicle_decel.max(F::ZERO) * k.ref_gain_dt + k.ref_margin_per_cycle_mps)
            .min(k.ref_fall_per_cycle_mps);
        self.speed = fastest.max(previous - fall).max(F::ZERO);
        // Only the fall of the reference is a vehicle deceleration. A rise re-anchors the
        // estimate to a wheel that has spun back up to the rail speed (issue 13: when
        // wheelset 4 recovered, the rise drove the filtered derivative to ~+4 m/s^2 and
        // the runaway test fired on a normally braking wheelset 2); it is not fed to the
        // derivative filter.
        let raw = (self.speed - previous).min(F::ZERO) * k.inv_dt;
        self.accel += (raw - self.accel) * k.accel_gain;
    }
}

/// A probe ends at this share of the demand pressure (the relay fills the rest).
const BACK_AT_DEMAND: f64 = 0.95;

/// What the channel reads in one control cycle besides the reference.
#[derive(Clone, Copy, Debug)]
pub struct ChannelInputs<F> {
    /// Wheel circumferential speed r omega, m/s.
    pub wheel_speed_mps: F,
    /// The channel's cylinder pressure (the unit's transducer), Pa.
    pub cylinder_pressure_pa: F,
    /// The demand pressure the relay valve is given now (it acts with the valve commands
    /// of this cycle), Pa.
    pub demand_pressure_pa: F,
    /// The vehicle's deceleration from the adhesion all wheelsets carry
    /// ([`vehicle_deceleration`]), m/s^2.
    pub vehicle_decel_mps2: F,
}

/// One wheelset's WSP channel.
#[derive(Clone, Copy, Debug, Default)]
pub struct WspChannel<F> {
    /// The dump valve command of this wheelset.
    pub valve: Valve,
    /// The phase of the control cycle (module doc).
    pub phase: Phase,
    /// Filtered wheel acceleration a_w, m/s^2.
    pub accel: F,
    /// Pressure memory p_m: the cylinder pressure that holds the wheel at the peak of the
    /// adhesion of the last slide (0: none yet), Pa.
    pub memory_pa: F,
    /// The adhesion the wheel carries as a brake force equivalent (the observer p_a of the
    /// module doc), Pa.
    pub adhesion_pa: F,
    /// Highest `adhesion_pa` of the current rise of the brake force, Pa.
    rise_max_pa: F,
    /// `rise_max_pa` at the last slide: the peak adhesion remembered, Pa.
    peak_pa: F,
    last_speed: F,
    initialised: bool,
    /// Whether the wheel has spun up since the last dump step.
    spun_up: bool,
    /// Cycles spent in the current phase.
    cycles_in_phase: u32,
    /// Cycles of the phase's timed valve action (vent of a dump, fill of a reapply or of a
    /// probe pulse).
    action_cycles: u32,
    /// Cycles into the current probe pulse.
    pulse_cycle: u32,
    /// Cycles of continuous WSP action (vent or hold: the brake not applied), for the WSP
    /// timer; 0 while the valve applies.
    released_cycles: u32,
    /// Cycles left during which the channel may not act (after the WSP timer expired).
    inhibit_cycles: u32,
}

/// Slide signals of one cycle.
#[derive(Clone, Copy, Debug)]
struct Signals {
    slide: bool,
    /// It has lost `overbrake_deficit_ratio` of the deficit threshold against the reference.
    creeping: bool,
    locked: bool,
    /// Back near the reference and no longer spinning up.
    caught_up: bool,
    /// The wheel's own acceleration is above `turn_accel_mps2`.
    spinning_up: bool,
}

impl<F: Real> WspChannel<F> {
    /// First part of a control cycle, for every channel before any [`Self::update`]: the
    /// wheel's filtered acceleration a_w from its speed `v` (m/s) and the adhesion observer
    /// p_a = (p - p_s) + c_I a_w from its cylinder pressure `p` (Pa).
    pub fn observe(&mut self, k: &WspConstants<F>, v: F, p: F) {
        if !self.initialised {
            self.last_speed = v;
            self.initialised = true;
        }
        let raw = (v - self.last_speed) * k.inv_dt;
        self.last_speed = v;
        self.accel += (raw - self.accel) * k.accel_gain;
        self.adhesion_pa = (p - k.spring_pa) + k.inertia_pa_per_mps2 * self.accel;
    }

    /// Second part of a control cycle: the valve command from the wheel speed, the cylinder
    /// and demand pressures, the vehicle's deceleration and the reference.
    pub fn update(
        &mut self,
        k: &WspConstants<F>,
        inputs: &ChannelInputs<F>,
        reference: &ReferenceSpeed<F>,
    ) -> Valve {
        let signals = self.signals(k, inputs, reference);
        let (phase, valve) = if !(reference.speed > k.min_speed_mps) || self.inhibit_cycles > 0 {
            self.inhibit_cycles = self.inhibit_cycles.saturating_sub(1);
            (Phase::Apply, Valve::Apply)
        } else if self.valve != Valve::Apply && self.released_cycles >= k.vent_max_cycles {
            // WSP timer: vent and hold together have kept the brake off for `vent_max_s`
            // (a Vent -> Hold -> Vent cycle does not restart it). Give the brake back and do
            // not act again for `timer_inhibit_s`, so a slide that never clears cannot keep the
            // brake off.
            self.inhibit_cycles = k.timer_inhibit_cycles;
            (Phase::Apply, Valve::Apply)
        } else {
            self.next(k, &signals, inputs)
        };
        self.released_cycles = if valve == Valve::Apply {
            0
        } else {
            self.released_cycles.saturating_add(1)
        };
        if phase == self.phase {
            self.cycles_in_phase = self.cycles_in_phase.saturating_add(1);
        } else {
            self.cycles_in_phase = 0;
            self.phase = phase;
        }
        self.valve = valve;
        valve
    }

    /// The slide signals against the reference and the vehicle's deceleration.
    fn signals(
        &self,
        k: &WspConstants<F>,
        inputs: &ChannelInputs<F>,
        reference: &ReferenceSpeed<F>,
    ) -> Signals {
        let v = inputs.wheel_speed_mps;
        let v_ref = reference.speed;
        let deficit = v_ref - v;
        let threshold = k.deficit_min_mps.max(k.deficit_ratio * v_ref);
        let rel_accel = self.accel - reference.accel;
        let runaway = deficit > F::of(0.5) * threshold && rel_accel < -k.decel_threshold_mps2;
        let creeping = deficit > k.overbrake_deficit_ratio * threshold;
        let overbraked =
            self.accel < -(inputs.vehicle_decel_mps2 + k.overbrake_decel_mps2) && creeping;
        Signals {
            slide: deficit > threshold || runaway || overbraked,
            creeping,
            locked: v < k.lock_ratio * v_ref,
            caught_up: deficit < k.reapply_ratio * threshold && self.accel < k.caught_up_accel_mps2,
            spinning_up: self.accel > k.turn_accel_mps2,
        }
    }

    /// The phase and valve command of this cycle (WSP active).
    fn next(
        &mut self,
        k: &WspConstants<F>,
        s: &Signals,
        inputs: &ChannelInputs<F>,
    ) -> (Phase, Valve) {
        let p = inputs.cylinder_pressure_pa;
        let p_d = inputs.demand_pressure_pa;
        let n = self.cycles_in_phase;
        if matches!(self.phase, Phase::Apply | Phase::Reapply | Phase::Probe) {
            // (Not while the wheel spins up suddenly: that transient is no adhesion it
            // carries for long.)
            if self.accel < k.sudden_grip_accel_mps2 {
                self.rise_max_pa = self.rise_max_pa.max(self.adhesion_pa);
            }
            // A probe at `cap_share` of the memory without a rise of the adhesion, its wheel
            // creeping, has passed the peak the memory knows.
            let capped = self.phase == Phase::Probe
                && s.creeping
                && p >= k.share_of(self.memory_pa, k.cap_share)
                && !self.risen(k);
            if s.slide || capped {
                self.remember(k, p, inputs.vehicle_decel_mps2);
                return self.dump(k, p, self.memory_pa);
            }
        }
        match self.phase {
            Phase::Apply => (Phase::Apply, Valve::Apply),
            Phase::Dump => {
                if n < self.action_cycles || s.locked {
                    (Phase::Dump, Valve::Vent)
                } else {
                    (Phase::Hold, Valve::Hold)
                }
            }
            Phase::Hold => {
                self.spun_up |= s.spinning_up;
                if s.locked || (n >= k.settle_cycles && !self.spun_up) {
                    self.dump(k, p, p)
                } else if (self.spun_up && s.caught_up) || n >= k.hold_max_cycles {
                    self.reapply(k, p, p_d)
                } else {
                    (Phase::Hold, Valve::Hold)
                }
            }
            Phase::Reapply => {
                if n < self.action_cycles {
                    (Phase::Reapply, Valve::Apply)
                } else {
                    self.pulse_cycle = 1;
                    (Phase::Probe, Valve::Hold)
                }
            }
            Phase::Probe => {
                if p >= F::of(BACK_AT_DEMAND) * p_d || self.risen(k) {
                    (Phase::Apply, Valve::Apply)
                } else {
                    self.probe_pulse(k, p, p_d)
                }
            }
        }
    }

    /// One cycle of the probe's pulses: a hold of `pulse_hold_s`, then a timed fill that
    /// raises the brake force by `probe_step_share` of itself (at most `pulse_fill_s`).
    fn probe_pulse(&mut self, k: &WspConstants<F>, p: F, p_d: F) -> (Phase, Valve) {
        let c = self.pulse_cycle;
        self.pulse_cycle += 1;
        if c < k.pulse_hold_cycles {
            return (Phase::Probe, Valve::Hold);
        }
        if c == k.pulse_hold_cycles {
            let target = k.share_of(p, F::ONE + k.probe_step_share);
            self.action_cycles = if p_d > target {
                fill_cycles(k, p, p_d, target).min(k.pulse_fill_cycles)
            } else {
                k.pulse_fill_cycles
            };
        }
        if c >= k.pulse_hold_cycles + self.action_cycles {
            self.pulse_cycle = 1;
            return (Phase::Probe, Valve::Hold);
        }
        (Phase::Probe, Valve::Apply)
    }

    /// Whether the adhesion has risen since the last slide (a patch of better grip): the
    /// wheel carries `risen_share` of the remembered peak, or spins up faster than
    /// `sudden_grip_accel_mps2` while the brake force rises.
    fn risen(&self, k: &WspConstants<F>) -> bool {
        (self.peak_pa > F::ZERO && self.adhesion_pa > k.risen_share * self.peak_pa)
            || self.accel > k.sudden_grip_accel_mps2
    }

    /// Remembers the slide of this rise: the peak adhesion it carried and the pressure
    /// that holds the wheel there while it follows the vehicle's deceleration (the inertia
    /// term c_I a_v added), at most the pressure `p` now.
    fn remember(&mut self, k: &WspConstants<F>, p: F, vehicle_decel: F) {
        self.peak_pa = self.rise_max_pa;
        let hold = k.spring_pa + self.rise_max_pa + k.inertia_pa_per_mps2 * vehicle_decel;
        self.memory_pa = hold.min(p);
    }

    /// A dump step from pressure `p` to `dump_share` of the brake force of `from` (at
    /// most `p`): a vent of the time the vent lag takes, tau_v ln(p / p_target).
    fn dump(&mut self, k: &WspConstants<F>, p: F, from: F) -> (Phase, Valve) {
        let target = k.share_of(from.min(p), k.dump_share);
        self.spun_up = false;
        self.action_cycles = if p > target && target > F::ZERO {
            cycles_of(k.vent_tau_cycles * (p / target).ln())
        } else {
            1
        };
        (Phase::Dump, Valve::Vent)
    }

    /// The fast reapply from pressure `p` toward `memory_share` of the memory's brake force
    /// (at most the demand `p_d`): one fill of the time the fill lag takes.
    fn reapply(&mut self, k: &WspConstants<F>, p: F, p_d: F) -> (Phase, Valve) {
        self.rise_max_pa = self.adhesion_pa;
        self.pulse_cycle = 1;
        let target = k.share_of(self.memory_pa, k.memory_share);
        if target >= F::of(BACK_AT_DEMAND) * p_d {
            return (Phase::Apply, Valve::Apply);
        }
        if p >= target {
            return (Phase::Probe, Valve::Hold);
        }
        self.action_cycles = fill_cycles(k, p, p_d, target);
        (Phase::Reapply, Valve::Apply)
    }
}

/// Control cycles the fill lag takes from `p` to `target` toward the demand `p_d`
/// (`target < p_d`): tau_f ln((p_d - p) / (p_d - target)).
fn fill_cycles<F: Real>(k: &WspConstants<F>, p: F, p_d: F, target: F) -> u32 {
    cycles_of(k.fill_tau_cycles * ((p_d - p) / (p_d - target)).ln())
}

/// A duration in control cycles (rounded half up, at least 1; NaN gives 1, huge values the
/// largest count). In the float type itself: no soft double on the Cortex-M4F.
fn cycles_of<F: Real>(x: F) -> u32 {
    x.round_u32().max(1)
}
