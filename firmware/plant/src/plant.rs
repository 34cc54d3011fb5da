//! The 17-DOF vehicle of the paper (Fig 3) with contact, brakes and disc heat, stepped at a
//! fixed step (0.1 ms by default).
//!
//! # Model
//!
//! Carbody and two bogies move in the longitudinal-vertical plane (x, z, pitch each);
//! four wheelsets stay on a straight rail and move longitudinally and spin (x, omega):
//! 3 + 2 x 3 + 4 x 2 = 17 DOF. Wheelset 1 leads (front of bogie 1), the train runs
//! toward +x. Pitch is positive nose-up. Each axle load Q is the wheelset weight plus the
//! force of its primary vertical springs and dampers (the wheelset has no vertical DOF).
//! The caliper sits on the bogie frame: the brake torque T_b that decelerates a wheelset
//! pitches its bogie by -T_b (nose down). Longitudinal elements act at the heights of the
//! parameter file, so longitudinal forces pitch the bodies (the axle-load transfer of
//! Fig 8B).
//!
//! Wheelset spin and translation, paper Eqs (7)-(8):
//!   I_w d(omega)/dt = F r - T_b,   m_w dv/dt = F_xps - F.
//!
//! # Numerics (hazards handled, each with a test)
//!
//! * **f32 cancellation.** Absolute positions reach 600 m while deflections are
//!   millimetres. Only the carbody speed and travelled distance are absolute (summed with
//!   Kahan compensation, so a 1.4e-4 m/s increment on 41 m/s loses nothing); bogies are
//!   integrated relative to the carbody, wheelsets relative to their bogie, and each
//!   wheelset's spin as its slip velocity `u = v - r omega`, a small number.
//! * **Stiff spin equation.** The contact's time constant is ~6 ms at 150 km/h and falls
//!   as 1/v (15 us at the creep floor): an explicit update at 0.1 ms chatters and diverges
//!   below ~1 m/s. The slip velocity is updated semi-implicitly with F = chord * u at the
//!   new u (chord = F/u of the current step, always >= 0): unconditionally stable, exact
//!   at steady state.
//! * **Stopping.** The brake is a friction clutch: it opposes the spin with at most T_b and
//!   holds the wheel at omega = 0 when that suffices, solved exactly in the same linear
//!   update, so a wheel never spins backwards and the vehicle stops cleanly. Creepage uses
//!   max(|v|, floor).
//! * **Slow factors.** Eq (2)'s speed and temperature brackets and the loss coefficient of
//!   Eq (5) (alpha + beta v_w^0.8) follow the friction speed, the disc temperature and the
//!   wheel speed, which change over seconds in braking (over tenths of a second in a
//!   slide); each step refreshes, for one wheelset in turn, either Eq (2)'s product of
//!   brackets or Eq (5)'s loss coefficient (each every 8 steps, 0.8 ms at 10 kHz). mu_d
//!   thus lags the spin speed by at most 7 steps: its relative error is at most
//!   n_v m_v l_p |d omega/dt| 7 dt (3.5e-4 at a slide's 100 rad/s^2 at 10 kHz; 10 times
//!   that at the diagnosis replay's 1 ms step), checked in `tests/friction_refresh.rs`.
//!   This takes every transcendental function of Eqs (2) and (5) out of the per-wheelset
//!   work of the 10 kHz step; v_w^0.8 is tracked by [`TrackedPow`] (a binomial series
//!   about an exact anchor while v_w stays within 1/64 of it; within 8e-7 relative).
//! * **Tracked exponentials.** e^(-B |w|) (Eq 11), e^(-m_v v_d) and e^(-m_T T_d) (Eq 2)
//!   move little from step to step (or refresh to refresh): [`TrackedExp`] serves them
//!   from an exact anchor with a degree-3 polynomial (within 4.2e-7 relative, tested
//!   against the exact function) and evaluates e^x again only when the argument leaves a
//!   window of 1/64.
//! * **Bad input.** Brake inputs are clamped to [0, 1.5 x the physical maximum] and
//!   flagged; a NaN/inf input holds the last valid value and is flagged. A non-finite state
//!   (never seen with validated parameters) puts the plant in a safe state: at rest, flagged.

use crate::brake::Caliper;
use crate::contact::{ContactForce, Polach};
use crate::friction::DiscPadFriction;
use crate::params::{ParamError, Params, Rail};
use crate::real::Real;
use crate::thermal::DiscThermal;
use crate::track::{DegradedAdhesionParams, Surface, Track, TrackAdhesion};
use crate::tracked::{TrackedExp, TrackedPow};

pub use crate::params::WHEELSETS;

/// The measured or simulated brake input of one wheelset.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum BrakeInput<F> {
    /// Brake cylinder pressure, Pa (pad force through Eq 1).
    CylinderPressure(F),
    /// Pad normal force per friction face, N (a caliper load cell).
    ClampForce(F),
}

impl<F: Real> Default for BrakeInput<F> {
    fn default() -> Self {
        BrakeInput::ClampForce(F::ZERO)
    }
}

/// Status flags of a step (bit set), see the constants.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Flags(pub u32);

impl Flags {
    /// Bits 0-3: wheelset 1-4 brake input NaN/inf; the last valid value was used.
    pub const INPUT_NOT_FINITE: u32 = 0x000f;
    /// Bits 4-7: wheelset 1-4 brake input out of range; clamped.
    pub const INPUT_OUT_OF_RANGE: u32 = 0x00f0;
    /// Initial speed out of range or not finite; clamped.
    pub const INITIAL_SPEED_CLAMPED: u32 = 0x0100;
    /// Bits 9-12: wheelset 1-4 unloaded (Q <= 0): no adhesion.
    pub const WHEEL_UNLOADED: u32 = 0x1e00;
    /// The state became non-finite; the plant was put at rest (safe state).
    pub const NUMERIC_FAULT: u32 = 0x2000;

    /// Whether any bit of `mask` (one of the constants above) is set.
    pub fn contains(self, mask: u32) -> bool {
        self.0 & mask != 0
    }
    /// Per-wheelset bit of a 4-bit group (`wheelset` 0-based).
    pub fn wheelset_bit(group: u32, wheelset: usize) -> u32 {
        (group & group.wrapping_neg()) << wheelset
    }
}

/// Outputs of one wheelset after a step.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct WheelsetOutput<F> {
    /// Spin speed omega, rad/s (positive rolling forward).
    pub omega: F,
    /// Longitudinal speed of the wheelset, m/s.
    pub speed: F,
    /// Slip velocity v - r omega, m/s.
    pub slip_velocity: F,
    /// Creepage s (Eq 12 with the floor).
    pub creepage: F,
    /// Axle load Q (rail normal force), N.
    pub axle_load: F,
    /// Adhesion force F, N.
    pub adhesion_force: F,
    /// Adhesion coefficient F/Q (Eq 13).
    pub adhesion: F,
    /// Wheel-rail friction coefficient mu (Eq 11).
    pub rail_mu: F,
    /// Disc-pad friction coefficient mu_d (Eq 2).
    pub mu_d: F,
    /// Pad normal force per face acting this step, N.
    pub clamp_force: F,
    /// Brake torque applied this step (clutch: <= the kinetic torque of Eq 1), N m.
    pub brake_torque: F,
    /// Kinetic tangential friction force at the friction radius over all faces,
    /// mu_d f N_d (Eq 1's force; T_b / l_p while the disc slips, more than that while
    /// the clutch holds the wheel), N.
    pub brake_force: F,
    /// Disc temperature rise T_d, degC (Eq 6).
    pub disc_temp: F,
    /// Brake power T_b omega (mean over the step), W.
    pub brake_power: F,
    /// Power dissipated in the wheel-rail contact F (v - r omega), W.
    pub contact_power: F,
}

impl<F: Copy> WheelsetOutput<F> {
    /// Names of [`Self::values`], in order (units in the names).
    pub const NAMES: [&'static str; 15] = [
        "omega_radps",
        "speed_mps",
        "slip_velocity_mps",
        "creepage",
        "axle_load_n",
        "adhesion_force_n",
        "adhesion",
        "rail_mu",
        "mu_d",
        "clamp_force_n",
        "brake_torque_nm",
        "brake_force_n",
        "disc_temp_c",
        "brake_power_w",
        "contact_power_w",
    ];

    /// Every value, in the order of [`Self::NAMES`] (for checks and trace formats).
    pub fn values(&self) -> [F; 15] {
        [
            self.omega,
            self.speed,
            self.slip_velocity,
            self.creepage,
            self.axle_load,
            self.adhesion_force,
            self.adhesion,
            self.rail_mu,
            self.mu_d,
            self.clamp_force,
            self.brake_torque,
            self.brake_force,
            self.disc_temp,
            self.brake_power,
            self.contact_power,
        ]
    }
}

/// Outputs of a step.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Outputs<F> {
    /// Steps taken since start.
    pub steps: u32,
    /// Carbody (vehicle) speed, m/s.
    pub vehicle_speed: F,
    /// Distance travelled by the carbody, m.
    pub distance: F,
    /// Carbody longitudinal acceleration, m/s^2.
    pub carbody_accel: F,
    /// Carbody pitch, rad (positive nose up).
    pub carbody_pitch: F,
    /// Per wheelset, 1-4 (wheelset 1 leads).
    pub wheelsets: [WheelsetOutput<F>; WHEELSETS],
    /// Power dissipated in all suspension dampers, W.
    pub damper_power: F,
    /// Power of running resistance and gradient on all bodies (negative = taken out), W.
    pub external_power: F,
    /// Flags of this step.
    pub flags: Flags,
}

/// Energies of the vehicle, J (for the energy balance test).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Energy {
    /// Translational and rotational kinetic energy of all bodies.
    pub kinetic: f64,
    /// Spring energy about the static equilibrium (gravity included).
    pub potential: f64,
}

/// Constants derived from the parameters once.
#[derive(Clone, Copy, Debug)]
struct Constants<F> {
    dt: F,
    g_along: F,
    /// dt g_along: the gradient's velocity increment over a step, m/s.
    dt_g_along: F,
    /// Gradient force on the carbody, one bogie and one wheelset, m g_along, N.
    grade_force_c: F,
    grade_force_b: F,
    grade_force_w: F,
    m_c: F,
    inv_m_c: F,
    inv_i_c: F,
    /// dt/m and dt/I of the carbody and a bogie (vertical and pitch updates).
    dt_inv_m_c: F,
    dt_inv_i_c: F,
    dt_inv_m_b: F,
    dt_inv_i_b: F,
    m_b: F,
    inv_i_b: F,
    m_w: F,
    i_w: F,
    r: F,
    inv_r: F,
    /// dt (1/m_w + r^2/I_w): the spin update's compliance over one step.
    dt_spin_compliance: F,
    /// dt/m_w, dt/I_w, dt r/I_w (folded for the spin update).
    dt_inv_m_w: F,
    dt_inv_i_w: F,
    dt_r_inv_i_w: F,
    /// Bogie centres relative to the carbody COG (bogie 1 front): +L/2, -L/2.
    x_bogie: [F; 2],
    /// Wheelsets relative to the bogie centre: leading +b/2, trailing -b/2.
    x_axle: [F; 2],
    /// Heights of longitudinal elements relative to body COGs.
    pz_carbody_sl: F,
    pz_bogie_sl: F,
    pz_bogie_pl: F,
    /// Suspension stiffnesses (N/m) and dampings (N s/m), negated: the forces
    /// -(k e + c e') = (-k) e + (-c) e' take no negation in the step (exact: IEEE
    /// negation and round-to-nearest are symmetric).
    neg_k_sv: F,
    neg_c_sv: F,
    neg_k_sl: F,
    neg_c_sl: F,
    neg_k_pv: F,
    neg_c_pv: F,
    neg_k_pl: F,
    neg_c_pl: F,
    /// Static axle load m_w g + primary preload, N.
    q_static: F,
    davis_a: F,
    davis_b: F,
    davis_c: F,
    /// 1 / the speed band over which the running resistance fades in, s/m.
    inv_resistance_speed_band: F,
    actuator_lag_rate: F,
    /// Whether the actuator lag acts (rate below 1).
    actuator_lag: bool,
    /// Lowest brake inputs taken as noise around zero: -2 % of the limits, Pa and N.
    pressure_low: F,
    clamp_force_low: F,
    speed_limit: F,
    polach: Polach<F>,
    friction: DiscPadFriction<F>,
    caliper: Caliper<F>,
    thermal: DiscThermal<F>,
    friction_radius: F,
    /// -m_v l_p: Eq (2)'s speed exponent per rad/s of wheel spin, s.
    speed_exponent_per_spin: F,
    /// dt / (c_p m_disc): disc temperature rise per step per watt (Eqs 3, 6).
    dt_inv_disc_heat_capacity: F,
}

/// The integrated state.
#[derive(Clone, Copy, Debug, Default)]
struct State<F: Real> {
    /// Carbody speed and its Kahan compensation.
    v_c: F,
    v_c_comp: F,
    x_c: F,
    x_c_comp: F,
    z_c: F,
    vz_c: F,
    pitch_c: F,
    pitch_rate_c: F,
    /// Bogie x and speed relative to the carbody (about the nominal position).
    dx_b: [F; 2],
    dv_b: [F; 2],
    z_b: [F; 2],
    vz_b: [F; 2],
    pitch_b: [F; 2],
    pitch_rate_b: [F; 2],
    /// The wheelsets' state, one record each (laid out for the step's wheelset loop).
    w: [WheelsetState<F>; WHEELSETS],
}

/// What a step leaves of one wheelset besides its state: the values of
/// [`WheelsetOutput`] that the state does not hold (the rest, and the derived ones, are
/// computed on demand by [`Plant::outputs`], so the 10 kHz step stores 9 values per
/// wheelset instead of 15), and the step's own values of the wheelset, written and read
/// in place (no copy on the stack).
#[derive(Clone, Copy, Debug, Default)]
struct WheelsetRecord<F> {
    /// Spin speed, rad/s: at the start of the step within it, after the step outside.
    omega: F,
    /// Wheelset speed, m/s: at the start of the step within it, after the step outside.
    speed: F,
    creepage: F,
    axle_load: F,
    adhesion_force: F,
    rail_mu: F,
    brake_torque: F,
    brake_power: F,
    contact_power: F,
    /// Primary vertical force deviation on the bogie and longitudinal force, N (the
    /// step's, for the bodies' equations).
    f_pv: F,
    f_pl: F,
    /// Wheelset velocity increment over the step (dt times its acceleration), m/s.
    dv_w: F,
}

/// The state of one wheelset.
#[derive(Clone, Copy, Debug, Default)]
struct WheelsetState<F: Real> {
    /// Wheelset x and speed relative to its bogie.
    dx: F,
    dv: F,
    /// Slip velocity v_w - r omega.
    slip: F,
    disc_temp: F,
    /// Pad force acting, N per face: the actuator-lag extension's state with the lag on,
    /// else the last valid brake input itself.
    pad_force: F,
    /// Eq (2)'s speed and temperature brackets times c mu_d0 (refreshed in turn, every 8
    /// steps, at that step's spin speed and disc temperature); mu_d is this times the
    /// pressure extension.
    friction_brackets: F,
    /// Eq (5) loss coefficient alpha + beta v_w^0.8, W/K (refreshed in turn).
    heat_loss: F,
    /// e^(-B |w|) of Eq (11), tracked from an exact anchor.
    rail_decay: TrackedExp<F>,
    /// e^(-m_v v_d) of Eq (2), tracked from an exact anchor.
    speed_decay: TrackedExp<F>,
    /// e^(-m_T T_d) of Eq (2), tracked from an exact anchor.
    temperature_decay: TrackedExp<F>,
    /// v_w^0.8 of Eq (5), tracked from an exact anchor.
    speed_power: TrackedPow<F>,
    /// Last valid brake input (clamp force, N) with the actuator lag on (without it the
    /// pad force is that value).
    last_clamp: F,
}

// 16 values: a 64-byte stride, one shift per wheelset address on the Cortex-M4F (instead
// of a multiply-add pair) in the step's wheelset loop.
const _: () = assert!(core::mem::size_of::<WheelsetState<f32>>() == 64);

/// The plant: vehicle, contact, brakes, disc heat. `F` = f32 on the target.
#[derive(Clone, Debug)]
pub struct Plant<F: Real> {
    k: Constants<F>,
    s: State<F>,
    /// Steps taken since start.
    steps: u32,
    /// Flags of the last step.
    flags: Flags,
    /// What the last step left of each wheelset besides its state.
    record: [WheelsetRecord<F>; WHEELSETS],
    /// Carbody acceleration and damper power of the last step.
    carbody_accel: F,
    damper_power: F,
    /// Running resistance (N) and mean carbody speed (m/s) of the last step: the
    /// external power of [`Outputs`] is computed from them on demand.
    resistance: F,
    carbody_mid_speed: F,
    sticky: Flags,
    initial_speed: F,
    /// Adhesion along the track ([`crate::track`]): one surface everywhere unless set.
    track: TrackAdhesion<F>,
    /// Track position of each wheelset relative to the carbody distance, m.
    track_offset: [F; WHEELSETS],
}

/// The wheelset loop's schedule, chosen here once for every build. On the Cortex-M4F (the
/// board and the emulator: `arm` without an OS) one wheelset at a time, kept a loop (not
/// unrolled): one wheelset's values fit its registers. Elsewhere (a host CPU) the four
/// contacts (Eqs 9-12) are evaluated side by side before the loop, which is unrolled.
/// Both compute the same values bit for bit: wheelset j's contact reads only wheelset j's
/// state and the track, and the loop body for j writes only wheelset j's (`hils
/// target-cost` and host-tests' `target_qemu` compare host and target bit for bit).
const ONE_WHEELSET_AT_A_TIME: bool = cfg!(all(target_arch = "arm", target_os = "none"));

/// The wheelset loop's trip count: hidden from the optimiser one wheelset at a time (no
/// unrolling), a constant otherwise (unrolled).
#[inline(always)]
fn wheelset_loop_count() -> usize {
    if ONE_WHEELSET_AT_A_TIME {
        core::hint::black_box(WHEELSETS)
    } else {
        WHEELSETS
    }
}

#[inline(always)]
fn kahan_add<F: Real>(sum: &mut F, comp: &mut F, x: F) {
    let y = x - *comp;
    let t = *sum + y;
    *comp = (t - *sum) - y;
    *sum = t;
}

impl<F: Real> Plant<F> {
    /// A plant at rest in static equilibrium, rolling at `initial_speed` (m/s), with the
    /// real-time step [`crate::params::STEP_S`] (10 kHz). Refuses invalid parameters;
    /// clamps (and flags) an initial speed outside [0, 140] m/s.
    pub fn new(params: &Params, rail: Rail, initial_speed: F) -> Result<Self, ParamError> {
        Self::with_step(params, rail, initial_speed, crate::params::STEP_S)
    }

    /// As [`Plant::new`] with another fixed step `dt` (s).
    pub fn with_step(
        params: &Params,
        rail: Rail,
        initial_speed: F,
        dt: f64,
    ) -> Result<Self, ParamError> {
        params.validate()?;
        let k = Self::constants(params, rail, dt)?;
        let surface = match rail {
            Rail::Wet => Surface::Wet,
            Rail::Dry => Surface::Dry,
        };
        let track = TrackAdhesion::new(
            &params.contact,
            &Default::default(),
            Track::uniform(surface),
            &DegradedAdhesionParams::default(),
            dt,
        )?;
        let lead = k.x_bogie[0] + k.x_axle[0];
        let mut plant = Plant {
            k,
            s: State::default(),
            steps: 0,
            flags: Flags::default(),
            record: Default::default(),
            carbody_accel: F::ZERO,
            damper_power: F::ZERO,
            resistance: F::ZERO,
            carbody_mid_speed: F::ZERO,
            sticky: Flags::default(),
            initial_speed: F::ZERO,
            track,
            track_offset: core::array::from_fn(|j| k.x_bogie[j / 2] + k.x_axle[j % 2] - lead),
        };
        let mut flags = 0;
        let v0 = if initial_speed.is_finite() && initial_speed >= F::ZERO {
            initial_speed
        } else {
            flags |= Flags::INITIAL_SPEED_CLAMPED;
            F::ZERO
        };
        let v0 = if v0 > k.speed_limit {
            flags |= Flags::INITIAL_SPEED_CLAMPED;
            k.speed_limit
        } else {
            v0
        };
        plant.initial_speed = v0;
        plant.reset_state([F::of(params.thermal.ambient_rise); WHEELSETS]);
        plant.sticky = Flags(flags);
        plant.flags = Flags(flags);
        Ok(plant)
    }

    fn constants(p: &Params, rail: Rail, dt: f64) -> Result<Constants<F>, ParamError> {
        if !(dt >= 1e-6 && dt <= 1e-2) {
            return Err(ParamError {
                key: "step",
                value: dt,
                min: 1e-6,
                max: 1e-2,
            });
        }
        let v = &p.vehicle;
        let s = &p.suspension;
        let k_sv = s.secondary_vertical_stiffness * s.secondary_vertical_count as f64;
        let c_sv = s.secondary_vertical_damping * s.secondary_vertical_count as f64;
        let k_sl = s.secondary_longitudinal_stiffness * s.secondary_longitudinal_count as f64
            + s.traction_link_stiffness;
        let c_sl = s.secondary_longitudinal_damping;
        let k_pv = s.primary_vertical_stiffness * s.primary_vertical_count as f64;
        let c_pv = s.primary_vertical_damping * s.primary_vertical_count as f64;
        let k_pl = s.primary_longitudinal_stiffness * s.primary_longitudinal_count as f64;
        let c_pl = s.primary_longitudinal_damping * s.primary_longitudinal_count as f64;

        // Explicit (symplectic Euler) suspension update: refuse parameter sets whose
        // fastest mode the step cannot resolve (bound: sum of stiffnesses on a body over
        // its mass or inertia, Gershgorin).
        let half_base = 0.5 * v.bogie_base;
        let half_wb = 0.5 * v.wheel_base;
        let h_sl_b = s.secondary_longitudinal_height - v.bogie_cog_height;
        let h_pl_b = s.primary_longitudinal_height - v.bogie_cog_height;
        let h_sl_c = s.secondary_longitudinal_height - v.carbody_cog_height;
        let modes = [
            (
                (2.0 * k_sl + 2.0 * k_sv) / v.carbody_mass,
                (2.0 * c_sl + 2.0 * c_sv) / v.carbody_mass,
            ),
            (
                (2.0 * k_sv * half_base * half_base + 2.0 * k_sl * h_sl_c * h_sl_c)
                    / v.carbody_pitch_inertia,
                (2.0 * c_sv * half_base * half_base + 2.0 * c_sl * h_sl_c * h_sl_c)
                    / v.carbody_pitch_inertia,
            ),
            (
                (k_sl + 2.0 * k_pl + k_sv + 2.0 * k_pv) / v.bogie_mass,
                (c_sl + 2.0 * c_pl + c_sv + 2.0 * c_pv) / v.bogie_mass,
            ),
            (
                (2.0 * k_pv * half_wb * half_wb
                    + k_sl * h_sl_b * h_sl_b
                    + 2.0 * k_pl * h_pl_b * h_pl_b)
                    / v.bogie_pitch_inertia,
                (2.0 * c_pv * half_wb * half_wb
                    + c_sl * h_sl_b * h_sl_b
                    + 2.0 * c_pl * h_pl_b * h_pl_b)
                    / v.bogie_pitch_inertia,
            ),
            (k_pl / v.wheelset_mass, c_pl / v.wheelset_mass),
        ];
        for (stiff, damp) in modes {
            // Needs omega dt well inside the stability limit 2 and damping rate dt < 1.
            let omega_dt = libm::sqrt(stiff) * dt;
            if !(omega_dt <= 1.0) || !(damp * dt <= 0.5) {
                return Err(ParamError {
                    key: "step",
                    value: dt,
                    min: 1e-6,
                    max: dt / omega_dt.max(2.0 * damp * dt),
                });
            }
        }

        let p_sv = 0.5 * v.carbody_mass * v.g;
        let p_pv = 0.5 * (p_sv + v.bogie_mass * v.g);
        let grad = p.track.gradient_permille / 1000.0;
        let r = v.wheel_radius;
        let lag = p.brake.actuator_lag_s;
        let g_along = v.g * grad / libm::sqrt(1.0 + grad * grad);
        let caliper = Caliper::new(&p.brake);
        Ok(Constants {
            dt: F::of(dt),
            g_along: F::of(g_along),
            dt_g_along: F::of(dt * g_along),
            grade_force_c: F::of(g_along * v.carbody_mass),
            grade_force_b: F::of(g_along * v.bogie_mass),
            grade_force_w: F::of(g_along * v.wheelset_mass),
            m_c: F::of(v.carbody_mass),
            inv_m_c: F::of(1.0 / v.carbody_mass),
            inv_i_c: F::of(1.0 / v.carbody_pitch_inertia),
            dt_inv_m_c: F::of(dt / v.carbody_mass),
            dt_inv_i_c: F::of(dt / v.carbody_pitch_inertia),
            dt_inv_m_b: F::of(dt / v.bogie_mass),
            dt_inv_i_b: F::of(dt / v.bogie_pitch_inertia),
            m_b: F::of(v.bogie_mass),
            inv_i_b: F::of(1.0 / v.bogie_pitch_inertia),
            m_w: F::of(v.wheelset_mass),
            i_w: F::of(v.wheelset_spin_inertia),
            r: F::of(r),
            inv_r: F::of(1.0 / r),
            dt_spin_compliance: F::of(
                dt * (1.0 / v.wheelset_mass + r * r / v.wheelset_spin_inertia),
            ),
            dt_inv_m_w: F::of(dt / v.wheelset_mass),
            dt_inv_i_w: F::of(dt / v.wheelset_spin_inertia),
            dt_r_inv_i_w: F::of(dt * r / v.wheelset_spin_inertia),
            x_bogie: [F::of(half_base), F::of(-half_base)],
            x_axle: [F::of(half_wb), F::of(-half_wb)],
            pz_carbody_sl: F::of(h_sl_c),
            pz_bogie_sl: F::of(h_sl_b),
            pz_bogie_pl: F::of(h_pl_b),
            neg_k_sv: -F::of(k_sv),
            neg_c_sv: -F::of(c_sv),
            neg_k_sl: -F::of(k_sl),
            neg_c_sl: -F::of(c_sl),
            neg_k_pv: -F::of(k_pv),
            neg_c_pv: -F::of(c_pv),
            neg_k_pl: -F::of(k_pl),
            neg_c_pl: -F::of(c_pl),
            q_static: F::of(p_pv + v.wheelset_mass * v.g),
            davis_a: F::of(p.resistance.davis_a_n),
            davis_b: F::of(p.resistance.davis_b_n_per_mps),
            davis_c: F::of(p.resistance.davis_c_n_per_mps2),
            inv_resistance_speed_band: F::of(1.0 / 0.01),
            actuator_lag_rate: F::of(if lag > 0.0 { (dt / lag).min(1.0) } else { 1.0 }),
            actuator_lag: lag > 0.0 && dt / lag < 1.0,
            pressure_low: -F::of(0.02) * caliper.pressure_limit,
            clamp_force_low: -F::of(0.02) * caliper.clamp_force_limit,
            speed_limit: F::of(140.0),
            polach: Polach::new(&p.contact, rail),
            friction: DiscPadFriction::new(&p.friction),
            caliper,
            thermal: DiscThermal::new(&p.thermal),
            friction_radius: F::of(p.brake.friction_radius),
            speed_exponent_per_spin: DiscPadFriction::speed_exponent_per_spin(
                &p.friction,
                p.brake.friction_radius,
            ),
            dt_inv_disc_heat_capacity: DiscThermal::step_gain(&p.thermal, dt),
        })
    }

    /// Back to static equilibrium at the initial speed (discs at `disc_temp`).
    fn reset_state(&mut self, disc_temps: [F; WHEELSETS]) {
        let v0 = self.initial_speed;
        self.s = State::default();
        self.s.v_c = v0;
        // Outputs of the last step that the state does not hold: none before a step.
        self.damper_power = F::ZERO;
        self.resistance = F::ZERO;
        self.carbody_mid_speed = v0;
        for (w, &disc_temp) in self.s.w.iter_mut().zip(disc_temps.iter()) {
            w.disc_temp = disc_temp;
            w.temperature_decay = self.k.friction.temperature_decay_at(disc_temp);
            w.heat_loss = self.k.thermal.loss_coefficient(v0);
            w.speed_power = self.k.thermal.speed_power_at(v0);
            w.speed_decay = self
                .k
                .friction
                .speed_decay_at(v0 * self.k.inv_r * self.k.friction_radius);
            Self::refresh_friction_brackets(&self.k, w, v0 * self.k.inv_r);
        }
        self.steps = 0;
        self.carbody_accel = F::ZERO;
        for w in self.record.iter_mut() {
            *w = WheelsetRecord {
                omega: v0 * self.k.inv_r,
                speed: v0,
                axle_load: self.k.q_static,
                rail_mu: self.k.polach.friction(F::ZERO),
                ..WheelsetRecord::default()
            };
        }
    }

    /// Wheel circumferential speeds r omega, m/s (what axle speed sensors measure).
    pub fn wheel_speeds(&self) -> [F; WHEELSETS] {
        let r = self.k.r;
        self.record.map(|w| w.omega * r)
    }

    /// Wheelset spin speeds omega, rad/s (positive rolling forward), of the last step.
    pub fn spin_speeds(&self) -> [F; WHEELSETS] {
        self.record.map(|w| w.omega)
    }

    /// Carbody (vehicle) speed, m/s.
    pub fn vehicle_speed(&self) -> F {
        self.s.v_c
    }

    /// Carbody longitudinal acceleration of the last step, m/s^2.
    pub fn carbody_accel(&self) -> F {
        self.carbody_accel
    }

    /// Steps taken since start.
    pub fn steps(&self) -> u32 {
        self.steps
    }

    /// Wheel radius, m.
    pub fn wheel_radius(&self) -> F {
        self.k.r
    }

    /// Power of running resistance and gradient on all bodies over the last step
    /// (negative = taken out), W, for the energy balance. Gradient forces m g_along of
    /// each body folded at construction; bogies and wheelsets summed first (one product
    /// per body kind); speeds: the carbody's mean over the step, the bogies' relative
    /// speeds after it added to it, the wheelsets' after it.
    fn external_power(&self) -> F {
        if self.steps == 0 {
            // Before the first step: no step, no work done.
            return F::ZERO;
        }
        let k = &self.k;
        let v_mid = self.carbody_mid_speed;
        let bogie_speeds = (v_mid + self.s.dv_b[0]) + (v_mid + self.s.dv_b[1]);
        let wo = &self.record;
        let wheelset_speeds = (wo[0].speed + wo[1].speed) + (wo[2].speed + wo[3].speed);
        -(self.resistance + k.grade_force_c) * v_mid
            - k.grade_force_b * bogie_speeds
            - k.grade_force_w * wheelset_speeds
    }

    /// Outputs of the last step (or of the initial state), built on demand: the step
    /// keeps only what its state does not hold (one record per wheelset), and the values
    /// here come from that record and the state. Board code that needs a few values every
    /// step uses [`Self::spin_speeds`], [`Self::wheel_speeds`], [`Self::vehicle_speed`] and
    /// [`Self::carbody_accel`] instead.
    pub fn outputs(&self) -> Outputs<F> {
        let s = &self.s;
        Outputs {
            steps: self.steps,
            vehicle_speed: s.v_c,
            distance: s.x_c,
            carbody_accel: self.carbody_accel,
            carbody_pitch: s.pitch_c,
            wheelsets: core::array::from_fn(|j| {
                let r = &self.record[j];
                let w = &s.w[j];
                // Eq (2) as the step computed it: the state's brackets and pad force.
                let mu_d = self
                    .k
                    .friction
                    .mu_d_of_brackets(w.friction_brackets, w.pad_force);
                WheelsetOutput {
                    omega: r.omega,
                    speed: r.speed,
                    slip_velocity: w.slip,
                    creepage: r.creepage,
                    axle_load: r.axle_load,
                    adhesion_force: r.adhesion_force,
                    adhesion: Self::adhesion_coefficient(r.adhesion_force, r.axle_load),
                    rail_mu: r.rail_mu,
                    mu_d,
                    clamp_force: w.pad_force,
                    brake_torque: r.brake_torque,
                    brake_force: self.k.caliper.friction_force(mu_d, w.pad_force),
                    disc_temp: w.disc_temp,
                    brake_power: r.brake_power,
                    contact_power: r.contact_power,
                }
            }),
            damper_power: self.damper_power,
            external_power: self.external_power(),
            flags: self.flags,
        }
    }

    /// The adhesion coefficient F/Q of Eq (13) from the adhesion force `force_n` and the
    /// axle load `load_n` (N): 0 when the wheelset is unloaded (no contact force then).
    fn adhesion_coefficient(force_n: F, load_n: F) -> F {
        if load_n > F::ZERO {
            force_n / load_n
        } else {
            F::ZERO
        }
    }

    /// Flags of every step so far, or-ed.
    pub fn sticky_flags(&self) -> Flags {
        self.sticky
    }

    /// The fixed step, s.
    pub fn dt(&self) -> F {
        self.k.dt
    }

    /// Time since start, s.
    pub fn time(&self) -> F {
        F::of(self.steps as f64) * self.k.dt
    }

    /// Static axle load (all four equal), N.
    pub fn static_axle_load(&self) -> F {
        self.k.q_static
    }

    /// Vertical force of each bogie's secondary (air) suspension on the carbody, N, bogie 1
    /// (wheelsets 1, 2) first: the static preload, half the carbody's weight, plus the
    /// deviation of the springs and dampers in the state (the step's secondary vertical
    /// force), so the pitch load transfer in braking shows. What a car's air-spring
    /// pressure transducers weigh (the rig's load-weighing signal, `hils_rig_core::load`).
    pub fn air_spring_forces(&self) -> [F; 2] {
        let (k, s) = (&self.k, &self.s);
        // q_static = g (m_c / 4 + m_b / 2 + m_w): the weight g the plant was built with.
        let quarter = F::of(0.25);
        let g = k.q_static / (quarter * k.m_c + F::of(0.5) * k.m_b + k.m_w);
        let preload = F::of(0.5) * k.m_c * g;
        core::array::from_fn(|i| {
            let e = s.z_c + k.x_bogie[i] * s.pitch_c - s.z_b[i];
            let e_rate = s.vz_c + k.x_bogie[i] * s.pitch_rate_c - s.vz_b[i];
            preload + k.neg_c_sv * e_rate + k.neg_k_sv * e
        })
    }

    /// Eq (2)'s brackets of wheelset `w` (times c mu_d0) at spin speed `omega` (rad/s;
    /// friction speed v_d = l_p |omega|) and its disc temperature, from its trackers: the
    /// refresh in turn of the step, and the state's start.
    #[inline(always)]
    fn refresh_friction_brackets(k: &Constants<F>, w: &mut WheelsetState<F>, omega: F) {
        let temperature_factor = k
            .friction
            .scaled_temperature_factor_tracked(w.disc_temp, &mut w.temperature_decay);
        w.friction_brackets = k.friction.scaled_brackets_tracked(
            k.speed_exponent_per_spin * omega.abs(),
            temperature_factor,
            &mut w.speed_decay,
        );
    }

    /// Sanitises one brake input to a pad clamp force (N per face), flagging bad values;
    /// a non-finite input gives the wheelset's last valid value (`w`'s last clamp force
    /// with the actuator lag on, else its pad force, which is that value).
    #[inline(always)]
    fn clamp_force_input(
        k: &Constants<F>,
        w: &WheelsetState<F>,
        j: usize,
        input: BrakeInput<F>,
        flags: &mut u32,
    ) -> F {
        let cal = &k.caliper;
        // The usual case, a reading within [0, limit], by one integer compare (one per
        // input kind); the detailed checks only when it fails.
        match input {
            // Within [0, clamp_force_limit] by the limit's construction (Caliper::new).
            BrakeInput::CylinderPressure(p) if p.within_zero_and(cal.pressure_limit) => {
                cal.clamp_force(p)
            }
            BrakeInput::ClampForce(f) if f.within_zero_and(cal.clamp_force_limit) => f,
            _ => {
                let (value, limit, low) = match input {
                    BrakeInput::CylinderPressure(p) => (p, cal.pressure_limit, k.pressure_low),
                    BrakeInput::ClampForce(f) => (f, cal.clamp_force_limit, k.clamp_force_low),
                };
                if !value.is_finite() {
                    *flags |= Flags::wheelset_bit(Flags::INPUT_NOT_FINITE, j);
                    return if k.actuator_lag {
                        w.last_clamp
                    } else {
                        w.pad_force
                    };
                }
                // Below zero by more than 2 % of the range, or above the limit: out of
                // range. Small negative readings are sensor noise around zero and clamp
                // silently to 0.
                if value > limit || value < low {
                    *flags |= Flags::wheelset_bit(Flags::INPUT_OUT_OF_RANGE, j);
                }
                let value = value.clamp_to(F::ZERO, limit);
                match input {
                    BrakeInput::CylinderPressure(_) => cal.clamp_force(value),
                    BrakeInput::ClampForce(_) => value,
                }
            }
        }
    }

    /// The pad force acting on wheelset `j` (N per face): its input through the optional
    /// actuator lag.
    #[inline(always)]
    fn pad_force(
        k: &Constants<F>,
        w: &mut WheelsetState<F>,
        j: usize,
        input: BrakeInput<F>,
        flags: &mut u32,
    ) -> F {
        let target = Self::clamp_force_input(k, w, j, input, flags);
        // First-order lag, written from the target so that rate 1 (no lag) gives the
        // target exactly, and kept between the old value and the target: rounding may
        // not overshoot the (clamped) target. Without lag (rate 1): the target, skipped
        // (the pad force is then the last valid input itself).
        if k.actuator_lag {
            w.last_clamp = target;
            let pad = &mut w.pad_force;
            let lagged = target - (target - *pad) * (F::ONE - k.actuator_lag_rate);
            *pad = lagged.clamp_to(pad.min(target), pad.max(target));
        } else {
            w.pad_force = target;
        }
        w.pad_force
    }

    /// The wheel-rail contact of a wheelset at the step's start (its state `w`, record
    /// `record`, the track's contact model `polach` under it and recovery factor
    /// `mu_factor`): Eq (11)'s mu (times the factor) and Eqs (9), (10), (12).
    #[inline(always)]
    fn wheelset_contact(
        (polach, mu_factor): (&Polach<F>, F),
        w: &mut WheelsetState<F>,
        record: &WheelsetRecord<F>,
    ) -> ContactForce<F> {
        let mu = polach.friction_tracked(w.slip, &mut w.rail_decay) * mu_factor;
        polach.evaluate_with_mu(w.slip, record.speed, record.axle_load, mu)
    }

    /// Advances the plant by one fixed step with the brake inputs of the four wheelsets;
    /// returns the step's flags ([`Self::outputs`] gives the values).
    ///
    /// Longer than the project's ~80 lines on purpose: it is the 10 kHz hot path, laid out
    /// for the Cortex-M4F's registers (live ranges, spills), and every change to it is
    /// measured per instruction by `hils target-cost`; its sections are marked `// ----`.
    pub fn step(&mut self, inputs: &[BrakeInput<F>; WHEELSETS]) -> Flags {
        let mut flags = 0u32;
        let half = F::of(0.5);
        let k = &self.k;
        let dt = k.dt;
        let s = &mut self.s;

        // ---- Pad forces (inputs; optional actuator lag) and kinematics ----
        // This step's values of each wheelset, one record each (every field set here or
        // before it is read).
        let v_c = s.v_c;
        let v_b = [v_c + s.dv_b[0], v_c + s.dv_b[1]];
        let r = &mut self.record;
        for j in 0..WHEELSETS {
            // The pad force acting is the state's `pad_force` from here on.
            Self::pad_force(k, &mut s.w[j], j, inputs[j], &mut flags);
            let v_w = v_b[j / 2] + s.w[j].dv;
            r[j].speed = v_w;
            r[j].omega = (v_w - s.w[j].slip) * k.inv_r;
        }

        // ---- Primary suspension (deviation from the static preloads) ----
        let mut damper_power = F::ZERO;
        // Primary vertical (force deviation on the bogie, upward) and longitudinal (force on
        // the wheelset), wheelset j in bogie j/2.
        for j in 0..WHEELSETS {
            let i = j / 2;
            let xa = k.x_axle[j % 2];
            let e = s.z_b[i] + xa * s.pitch_b[i];
            let e_rate = s.vz_b[i] + xa * s.pitch_rate_b[i];
            // Damping forces -c e' once, for the force and the damper power c e'^2.
            let damping_v = k.neg_c_pv * e_rate;
            r[j].f_pv = damping_v + k.neg_k_pv * e;
            r[j].axle_load = k.q_static + r[j].f_pv;
            if !(r[j].axle_load > F::ZERO) {
                flags |= Flags::wheelset_bit(Flags::WHEEL_UNLOADED, j);
            }
            let d = s.w[j].dx + k.pz_bogie_pl * s.pitch_b[i];
            let d_rate = s.w[j].dv + k.pz_bogie_pl * s.pitch_rate_b[i];
            let damping_l = k.neg_c_pl * d_rate;
            r[j].f_pl = damping_l + k.neg_k_pl * d;
            damper_power -= damping_v * e_rate;
            damper_power -= damping_l * d_rate;
        }

        // ---- Slow factors, in turn: of wheelset `slow`, either Eq (2)'s brackets or
        // Eq (5)'s loss coefficient (each every 8 steps) ----
        let turn = self.steps % (2 * WHEELSETS as u32);
        let slow = (turn % WHEELSETS as u32) as usize;
        let w = &mut s.w[slow];
        if turn < WHEELSETS as u32 {
            Self::refresh_friction_brackets(k, w, r[slow].omega);
        } else {
            w.heat_loss = k
                .thermal
                .loss_coefficient_tracked(k.r * r[slow].omega, &mut w.speed_power);
        }
        // Zones and degraded adhesion along the track (crate::track): one wheelset per
        // step, in turn; nothing to do on a uniform track with degraded adhesion off.
        let track = &mut self.track;
        if track.active() {
            track.step(
                slow,
                s.x_c + self.track_offset[slow],
                r[slow].speed,
                r[slow].contact_power,
                F::of(WHEELSETS as f64) * dt,
            );
        }

        // ---- Wheelsets: contact (Eqs 9-12), friction (Eq 2), brake (Eq 1), spin (Eqs 7-8)
        // On the Cortex-M4F kept a loop (not unrolled four times: one wheelset's values fit
        // its registers); a host CPU runs the four unrolled faster. The same operations in
        // the same order either way (host/target bit identity).
        // The contacts side by side first, or one wheelset at a time in the loop
        // ([`ONE_WHEELSET_AT_A_TIME`]: the same values either way).
        let mut host_contacts = [ContactForce::<F>::default(); WHEELSETS];
        if !ONE_WHEELSET_AT_A_TIME {
            for (j, contact) in host_contacts.iter_mut().enumerate() {
                *contact = Self::wheelset_contact(track.contact(j), &mut s.w[j], &r[j]);
            }
        }
        for j in 0..wheelset_loop_count() {
            let j = j & (WHEELSETS - 1);
            let ws = &mut s.w[j];
            let w = &mut r[j];
            let (v_w, omega, clamp) = (w.speed, w.omega, ws.pad_force);
            let contact = if ONE_WHEELSET_AT_A_TIME {
                Self::wheelset_contact(track.contact(j), ws, w)
            } else {
                host_contacts[j]
            };
            // Eq (2) from its brackets, refreshed in turn (above).
            let mu_d = k.friction.mu_d_of_brackets(ws.friction_brackets, clamp);
            let torque_kinetic = k.caliper.torque(mu_d, clamp);

            // Semi-implicit spin/slip update with the brake as a clutch. Unknowns at the
            // new step: u', omega', F' = chord u'. With D = 1 + dt chord (1/m + r^2/I):
            //   u'(T) = (u + dt a + dt r T / I) / D,  a = explicit wheelset acceleration
            //   omega'(T) = omega0 - g T,  g = (dt/I)(1 + dt chord/m)/D > 0
            // The brake torque T opposes the spin up to the kinetic torque and holds the
            // wheel (omega' = 0) when that suffices.
            let chord = contact.chord;
            // dt times the explicit acceleration (dt folded into 1/m_w and g_along).
            let dv_explicit = w.f_pl * k.dt_inv_m_w - k.dt_g_along;
            let d = F::ONE + chord * k.dt_spin_compliance;
            let inv_d = F::ONE / d;
            let u0 = (ws.slip + dv_explicit) * inv_d;
            let omega0 = omega + chord * u0 * k.dt_r_inv_i_w;
            let g = k.dt_inv_i_w * (F::ONE + chord * k.dt_inv_m_w) * inv_d;
            let limit = g * torque_kinetic;
            let (torque, omega_new) = if omega0 > limit {
                (torque_kinetic, omega0 - limit)
            } else if omega0 < -limit {
                (-torque_kinetic, omega0 + limit)
            } else {
                (omega0 / g, F::ZERO)
            };
            let u_new = u0 + torque * k.dt_r_inv_i_w * inv_d;
            let force = chord * u_new;
            w.dv_w = dv_explicit - force * k.dt_inv_m_w;

            // The pad force and the disc temperature are the state's; the outputs
            // derive the rest (Plant::outputs).
            w.omega = omega_new;
            w.speed = v_w + w.dv_w;
            w.creepage = contact.creepage;
            w.adhesion_force = force;
            w.rail_mu = contact.mu;
            w.brake_torque = torque;
            w.brake_power = torque * half * (omega + omega_new);
            w.contact_power = force * half * (ws.slip + u_new);
            ws.slip = u_new;

            // Disc heat balance, Eqs (3)-(6) (explicit: time constant of minutes).
            let heat_flow = k
                .thermal
                .net_heat_flow(w.brake_power, ws.disc_temp, ws.heat_loss);
            ws.disc_temp += heat_flow * k.dt_inv_disc_heat_capacity;
        }

        // ---- Secondary suspension (deviation from the static preloads), after the
        // wheelsets: its forces need not live across their loop ----
        // Secondary vertical, bogie i: extension e = z_c + X_i theta_c - z_b;
        // force deviation on the carbody, upward.
        let mut f_sv = [F::ZERO; 2];
        let mut f_sl = [F::ZERO; 2];
        for i in 0..2 {
            let e = s.z_c + k.x_bogie[i] * s.pitch_c - s.z_b[i];
            let e_rate = s.vz_c + k.x_bogie[i] * s.pitch_rate_c - s.vz_b[i];
            let damping_v = k.neg_c_sv * e_rate;
            f_sv[i] = damping_v + k.neg_k_sv * e;
            // Secondary longitudinal (springs + traction link), bogie relative to carbody at
            // the element height; force on the bogie.
            let d = s.dx_b[i] - k.pz_bogie_sl * s.pitch_b[i] + k.pz_carbody_sl * s.pitch_c;
            let d_rate =
                s.dv_b[i] - k.pz_bogie_sl * s.pitch_rate_b[i] + k.pz_carbody_sl * s.pitch_rate_c;
            let damping_l = k.neg_c_sl * d_rate;
            f_sl[i] = damping_l + k.neg_k_sl * d;
            damper_power -= damping_v * e_rate;
            damper_power -= damping_l * d_rate;
        }
        // ---- Bodies ----
        // Running resistance on the carbody (Davis), faded in over +-1 cm/s so that the
        // vehicle never creeps backwards at rest.
        let speed_fade = (v_c * k.inv_resistance_speed_band).clamp_to(-F::ONE, F::ONE);
        let v_abs = v_c.abs();
        let resistance = (k.davis_a + k.davis_b * v_abs + k.davis_c * v_abs * v_abs) * speed_fade;
        let a_c = (-(f_sl[0] + f_sl[1]) - resistance) * k.inv_m_c - k.g_along;

        // ---- Integrate (symplectic Euler: velocities, then positions), body by body:
        // each body's velocity increments over the step (dt/m, dt/I and dt g_along
        // folded) go into its state at once (short live ranges, no spills) ----
        let dv_c = a_c * dt;
        kahan_add(&mut s.v_c, &mut s.v_c_comp, dv_c);
        let v_c_new = s.v_c;
        kahan_add(&mut s.x_c, &mut s.x_c_comp, v_c_new * dt);
        s.vz_c += (f_sv[0] + f_sv[1]) * k.dt_inv_m_c;
        s.z_c += s.vz_c * dt;
        let mut moment_c = F::ZERO;
        for i in 0..2 {
            // Vertical deviation at X_i; longitudinal force on the carbody (-f_sl) at pz.
            moment_c += k.x_bogie[i] * f_sv[i] + k.pz_carbody_sl * f_sl[i];
        }
        s.pitch_rate_c += moment_c * k.dt_inv_i_c;
        s.pitch_c += s.pitch_rate_c * dt;
        for i in 0..2 {
            let (j0, j1) = (2 * i, 2 * i + 1);
            let dv_b = (f_sl[i] - r[j0].f_pl - r[j1].f_pl) * k.dt_inv_m_b - k.dt_g_along;
            s.dv_b[i] += dv_b - dv_c;
            s.dx_b[i] += s.dv_b[i] * dt;
            s.vz_b[i] += (r[j0].f_pv + r[j1].f_pv - f_sv[i]) * k.dt_inv_m_b;
            s.z_b[i] += s.vz_b[i] * dt;
            // Moments: primary vertical at +-b/2, primary longitudinal (-f_pl on the bogie)
            // at pz_pl, secondary longitudinal at pz_sl, brake reactions -T_b.
            let m = k.x_axle[0] * r[j0].f_pv
                + k.x_axle[1] * r[j1].f_pv
                + k.pz_bogie_pl * (r[j0].f_pl + r[j1].f_pl)
                - k.pz_bogie_sl * f_sl[i]
                - r[j0].brake_torque
                - r[j1].brake_torque;
            s.pitch_rate_b[i] += m * k.dt_inv_i_b;
            s.pitch_b[i] += s.pitch_rate_b[i] * dt;
            for j in [j0, j1] {
                s.w[j].dv += r[j].dv_w - dv_b;
                s.w[j].dx += s.w[j].dv * dt;
            }
        }

        // External power (resistance and gradient) for the energy balance: from these
        // two on demand (Self::external_power).
        self.carbody_mid_speed = half * (v_c + v_c_new);
        self.resistance = resistance;

        // ---- Safe state on a non-finite state (never expected with valid parameters) ----
        // One test on a sum: a NaN or an infinity anywhere makes the sum NaN or infinite
        // (and a sum of finite values overflows only far beyond any physical state).
        let mut sum = s.v_c + s.pitch_c + s.pitch_b[0] + s.pitch_b[1];
        for j in 0..WHEELSETS {
            sum += s.w[j].slip + s.w[j].disc_temp;
        }
        let finite = sum.is_finite();
        self.steps = self.steps.wrapping_add(1);
        self.carbody_accel = a_c;
        self.damper_power = damper_power;
        if !finite {
            flags |= Flags::NUMERIC_FAULT;
            self.enter_safe_state();
        }
        self.flags = Flags(flags);
        self.sticky.0 |= flags;
        self.flags
    }

    /// Safe state after a numeric fault: vehicle at rest, brakes' effect nil, discs kept
    /// if finite. Outputs show standstill, so a brake controller sees a stopped train.
    fn enter_safe_state(&mut self) {
        // Discs keep a finite temperature (0 when it is not finite); Eq (2)'s factors
        // follow it.
        let temps = self.s.w.map(|w| {
            if w.disc_temp.is_finite() {
                w.disc_temp
            } else {
                F::ZERO
            }
        });
        let steps = self.steps;
        self.initial_speed = F::ZERO;
        self.reset_state(temps);
        self.steps = steps;
    }

    /// Kinetic and spring energy (host-side check of the energy balance).
    pub fn energy(&self) -> Energy {
        let s = &self.s;
        let k = &self.k;
        let f = |x: F| x.to_f64();
        let v_c = f(s.v_c);
        let mut kinetic = 0.5 * f(k.m_c) * (v_c * v_c + f(s.vz_c) * f(s.vz_c))
            + 0.5 * f(s.pitch_rate_c) * f(s.pitch_rate_c) / f(k.inv_i_c);
        let mut potential = 0.0;
        for i in 0..2 {
            let v_b = v_c + f(s.dv_b[i]);
            kinetic += 0.5 * f(k.m_b) * (v_b * v_b + f(s.vz_b[i]) * f(s.vz_b[i]))
                + 0.5 * f(s.pitch_rate_b[i]) * f(s.pitch_rate_b[i]) / f(k.inv_i_b);
            let e = f(s.z_c) + f(k.x_bogie[i]) * f(s.pitch_c) - f(s.z_b[i]);
            let d = f(s.dx_b[i]) - f(k.pz_bogie_sl) * f(s.pitch_b[i])
                + f(k.pz_carbody_sl) * f(s.pitch_c);
            potential += 0.5 * -f(k.neg_k_sv) * e * e + 0.5 * -f(k.neg_k_sl) * d * d;
        }
        for j in 0..WHEELSETS {
            let i = j / 2;
            let v_w = v_c + f(s.dv_b[i]) + f(s.w[j].dv);
            let omega = (v_w - f(s.w[j].slip)) / f(k.r);
            kinetic += 0.5 * f(k.m_w) * v_w * v_w + 0.5 * f(k.i_w) * omega * omega;
            let xa = f(k.x_axle[j % 2]);
            let e = f(s.z_b[i]) + xa * f(s.pitch_b[i]);
            let d = f(s.w[j].dx) + f(k.pz_bogie_pl) * f(s.pitch_b[i]);
            potential += 0.5 * -f(k.neg_k_pv) * e * e + 0.5 * -f(k.neg_k_pl) * d * d;
        }
        Energy { kinetic, potential }
    }

    /// Sets the adhesion along the track (zones, contact sets, degraded adhesion).
    pub fn set_track(&mut self, track: TrackAdhesion<F>) {
        self.track = track;
        for j in 0..WHEELSETS {
            let x = self.s.x_c + self.track_offset[j];
            self.track
                .step(j, x, self.record[j].speed, F::ZERO, F::ZERO);
        }
    }

    /// The adhesion along the track and the surface under each wheelset.
    pub fn track(&self) -> &TrackAdhesion<F> {
        &self.track
    }

    /// The Polach model in use (for adhesion curves, Fig 11).
    pub fn polach(&self) -> &Polach<F> {
        &self.k.polach
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The numeric-fault safe state (module doc, "Bad input"): a non-finite state puts the
    /// plant at rest, flagged, with every output finite, the step count kept and each
    /// disc's finite temperature kept (Eq 2's factors following it).
    #[test]
    fn non_finite_state_enters_the_documented_safe_state() {
        let params = Params::default();
        let mut plant = Plant::<f32>::new(&params, Rail::Dry, 30.0).unwrap();
        let eb = [BrakeInput::ClampForce(20_000.0); WHEELSETS];
        for _ in 0..500 {
            plant.step(&eb);
        }
        assert!(!plant.sticky_flags().contains(Flags::NUMERIC_FAULT));
        let hot = plant.s.w[0].disc_temp;
        assert!(hot > 0.0);
        // An infinite disc temperature on wheelset 2 (the other discs stay finite).
        plant.s.w[1].disc_temp = f32::INFINITY;
        let flags = plant.step(&eb);
        assert!(flags.contains(Flags::NUMERIC_FAULT));
        let o = plant.outputs();
        assert_eq!(o.steps, 501);
        assert_eq!(o.vehicle_speed, 0.0);
        assert_eq!(o.damper_power, 0.0);
        assert_eq!(o.external_power, 0.0);
        let kept = o.wheelsets[0].disc_temp;
        // One more step of braking heat on it (0.05 s of braking before: under 1 % more).
        assert!(kept >= hot && kept <= 1.01 * hot, "{kept} vs {hot}");
        assert_eq!(o.wheelsets[1].disc_temp, 0.0);
        let friction = DiscPadFriction::<f32>::new(&params.friction);
        // Eq (2) at rest and the kept temperature (the plant's brackets are refreshed from
        // exact anchors there: within a few roundings).
        let exact = friction.mu_d(0.0, kept, 0.0);
        let mu_d = o.wheelsets[0].mu_d;
        assert!(
            (mu_d - exact).abs() <= 4.0 * f32::EPSILON * exact,
            "{mu_d} vs {exact}"
        );
        for w in o.wheelsets {
            assert_eq!(w.omega, 0.0);
            assert!(w.values().iter().all(|x| x.is_finite()), "{w:?}");
        }
        // It stays at rest and finite under the same brake inputs.
        for _ in 0..100 {
            let flags = plant.step(&eb);
            assert!(!flags.contains(Flags::NUMERIC_FAULT));
        }
        let o = plant.outputs();
        assert_eq!(o.vehicle_speed, 0.0);
        assert!(o.wheelsets.iter().all(|w| w.omega == 0.0 && w.speed == 0.0));
        assert!(plant.sticky_flags().contains(Flags::NUMERIC_FAULT));
    }

    /// Before the first step no work has been done: external and damper power are zero,
    /// on a gradient too.
    #[test]
    fn no_power_before_the_first_step() {
        let mut params = Params::default();
        params.track.gradient_permille = 10.0;
        let plant = Plant::<f32>::new(&params, Rail::Dry, 30.0).unwrap();
        let o = plant.outputs();
        assert_eq!((o.external_power, o.damper_power, o.steps), (0.0, 0.0, 0));
    }
}
