//! The simulated brake unit: brake demand (ECU), pneumatic delay and cylinder lags (BOU),
//! and the WSP valves of the four wheelsets.

use hils_plant::params::{ParamError, Params};
use hils_plant::{Real, WHEELSETS};

use crate::ep::{EpConstants, EpValve};
pub use crate::params::BrakeUnitParams;
use crate::wsp::{
    ChannelInputs, Pneumatics, ReferenceSpeed, Valve, WspChannel, WspConstants, WspTuning,
};

/// Brake demand given to the unit (also the rig's brake command, `hils_rig_core::can`).
#[derive(Clone, Copy, Debug, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum BrakeDemand {
    /// Brakes released.
    #[default]
    Release,
    /// Emergency brake: the open-loop EB pressure.
    Emergency,
    /// Service brake for a deceleration, pressure in proportion to EB's.
    Service {
        /// Demanded deceleration, m/s^2 (limited to the EB deceleration).
        deceleration_mps2: f32,
    },
    /// Service brake step `step` of `service_steps`: `step / service_steps` of the full
    /// service deceleration (0: release; above the last: the last).
    ServiceStep {
        /// The step, 1-based.
        step: u8,
    },
}

/// Longest plant step or control cycle the unit accepts, s.
pub const MAX_PERIOD_S: f64 = 1.0;

/// Capacity of the dead-time delay line, in control cycles.
pub const DELAY_CAPACITY: usize = 1024;

/// Configuration of the unit: its `[brake_unit]` parameters, the plant step and a WSP tuning.
#[derive(Clone, Copy, Debug)]
pub struct UnitConfig {
    /// Plant step, s.
    pub step_s: f64,
    /// Control cycle of the ECU/WSP, s (rounded to whole plant steps).
    pub control_period_s: f64,
    /// The `[brake_unit]` section of the parameter file.
    pub params: BrakeUnitParams,
    /// WSP thresholds and times.
    pub wsp: WspTuning,
    /// Whether the WSP acts (off: valves always apply).
    pub wsp_enabled: bool,
}

impl UnitConfig {
    /// The reference unit (default `[brake_unit]`, 1 ms control cycle, WSP on) at plant
    /// step `step_s`.
    pub fn new(step_s: f64) -> Self {
        Self::with_params(step_s, BrakeUnitParams::default())
    }

    /// The unit of a parameter file's `[brake_unit]` section at plant step `step_s`.
    pub fn with_params(step_s: f64, params: BrakeUnitParams) -> Self {
        Self {
            step_s,
            control_period_s: 1.0e-3,
            params,
            wsp: WspTuning::default(),
            wsp_enabled: true,
        }
    }
}

/// Why a unit cannot be built.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum UnitError {
    /// A `[brake_unit]` value outside its range.
    Params(ParamError),
    /// The dead time needs more control cycles than the delay line holds.
    DeadTimeTooLong {
        /// The dead time asked for, s.
        dead_time_s: f64,
        /// The longest the delay line holds at this control cycle, s.
        max_s: f64,
    },
    /// The control period or plant step is not in (0, [`MAX_PERIOD_S`]].
    BadPeriod,
}

impl core::fmt::Display for UnitError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            UnitError::Params(e) => e.fmt(f),
            UnitError::DeadTimeTooLong { dead_time_s, max_s } => write!(
                f,
                "brake_unit.dead_time = {dead_time_s} s exceeds the delay line ({max_s} s)"
            ),
            UnitError::BadPeriod => {
                f.write_str("control period and plant step must be in (0, 1] s")
            }
        }
    }
}

/// Open-loop (load-weighing) EB cylinder pressure, Pa: the pressure at which the four
/// wheelsets' brake torques with the constant mu_d0 decelerate the vehicle, rotating
/// inertia included, at `eb_deceleration_mps2` (`[brake_unit]`) on a level track, through
/// Eq (1): sum T_b = M_eff a r, T_b = mu_d0 (A_c P_c - K_r) r_c l_p N_d.
/// Limited to the supply pressure.
pub fn eb_pressure(p: &Params, eb_deceleration_mps2: f64) -> f64 {
    let torque_per_wheelset =
        p.effective_mass() * eb_deceleration_mps2 * p.vehicle.wheel_radius / 4.0;
    let b = &p.brake;
    let clamp =
        torque_per_wheelset / (p.friction.mu_d0 * b.friction_radius * b.friction_faces as f64);
    hils_plant::brake::pressure_for_clamp_force(b, clamp).min(b.supply_pressure)
}

/// Most service brake steps.
pub const MAX_SERVICE_STEPS: usize = 20;

/// Cylinder pressure of a service brake for deceleration `decel_mps2` (m/s^2), Pa: the
/// brake force (pad clamp force, Eq 1) in proportion to EB's, so that the deceleration is
/// in proportion too; the pressure is the clamp force's ([`hils_plant::brake::
/// pressure_for_clamp_force`]: the retaining spring's K_r / A_c plus the rest in
/// proportion). 0 for no deceleration; limited to EB and the supply. (Before issue 25 the
/// pressure itself was in proportion to EB's: with the spring's 44 kPa left out, a 0.6 m/s^2
/// service brake gave 0.49 m/s^2.)
pub fn service_pressure(params: &Params, u: &BrakeUnitParams, decel_mps2: f64) -> f64 {
    if !(decel_mps2 > 0.0) {
        return 0.0;
    }
    let eb = eb_pressure(params, u.eb_deceleration_mps2);
    let spring = params.brake.retaining_spring_force / params.brake.piston_area;
    let share = (decel_mps2 / u.eb_deceleration_mps2).min(1.0);
    (spring + (eb - spring).max(0.0) * share).min(eb)
}

/// Deceleration of service step `step` (0: none; above the last: the last), m/s^2:
/// step / steps of the full service deceleration, limited to EB's.
pub fn service_step_deceleration(u: &BrakeUnitParams, step: u8) -> f64 {
    let steps = u.service_steps.clamp(1, MAX_SERVICE_STEPS as u8);
    (u.full_service_deceleration_mps2 * step.min(steps) as f64 / steps as f64)
        .min(u.eb_deceleration_mps2)
}

/// Cylinder pressure a demand asks for, Pa (f64: the bench's reference uses the same
/// mapping as the unit). A service deceleration that is not finite reads as 0.
pub fn demand_pressure(params: &Params, u: &BrakeUnitParams, demand: BrakeDemand) -> f64 {
    match demand {
        BrakeDemand::Release => 0.0,
        BrakeDemand::Emergency => eb_pressure(params, u.eb_deceleration_mps2),
        BrakeDemand::Service { deceleration_mps2 } => {
            let d = deceleration_mps2 as f64;
            service_pressure(params, u, if d.is_finite() { d } else { 0.0 })
        }
        BrakeDemand::ServiceStep { step } => {
            service_pressure(params, u, service_step_deceleration(u, step))
        }
    }
}

/// Demand pressure of each service step n (n = 0..=MAX_SERVICE_STEPS).
fn service_step_pressures<F: Real>(
    params: &Params,
    u: &BrakeUnitParams,
) -> [F; MAX_SERVICE_STEPS + 1] {
    core::array::from_fn(|n| {
        F::of(demand_pressure(
            params,
            u,
            BrakeDemand::ServiceStep { step: n as u8 },
        ))
    })
}

/// One wheelset's cylinder: pressure state with fill and vent lags.
#[derive(Clone, Copy, Debug, Default)]
struct Cylinder<F> {
    pressure: F,
    /// Rounding error of the last lag update, carried into the next (compensated
    /// summation): a plain `p += (target - p) * gain` stalls in f32 where the increment
    /// falls below half an ulp of p (78 Pa short of 355 kPa at gain 2e-4).
    carry: F,
}

impl<F: Real> Cylinder<F> {
    /// First-order lag toward `target`: p += (target - p) gain, compensated.
    #[inline]
    fn approach(&mut self, target: F, gain: F) {
        crate::ep::approach(&mut self.pressure, &mut self.carry, target, gain);
    }
}

/// The brake unit.
#[derive(Clone, Debug)]
pub struct BrakeUnit<F: Real> {
    steps_per_cycle: u32,
    cycle_s: f64,
    step_in_cycle: u32,
    /// Fill and vent factors 1 - exp(-dt/tau) per plant step.
    fill_gain: F,
    vent_gain: F,
    eb_pressure: F,
    eb_deceleration: F,
    wsp_enabled: bool,
    wsp_k: WspConstants<F>,
    ep_k: Option<EpConstants<F>>,
    ep: EpValve<F>,
    /// Demand pressure of each service step (index 0: release; the last repeats).
    service_step_pressure: [F; MAX_SERVICE_STEPS + 1],
    service_steps: u8,
    /// Cylinder pressure at which the pads start to clamp, K_r / A_c, Pa.
    spring_pressure: F,
    reference: ReferenceSpeed<F>,
    channels: [WspChannel<F>; WHEELSETS],
    cylinders: [Cylinder<F>; WHEELSETS],
    /// Dead time as a delay line of (demand pressure, packed valve states) per control
    /// cycle; `delay` cycles long.
    delay_pressure: [F; DELAY_CAPACITY],
    delay_valves: [u8; DELAY_CAPACITY],
    delay: usize,
    head: usize,
    /// Demand and valves after the dead time (acting on the cylinders).
    acting_pressure: F,
    acting_valves: [Valve; WHEELSETS],
    demand: BrakeDemand,
    cycles: u32,
    /// Control cycle of each wheelset's first vent command (None: never vented).
    first_vent_cycle: [Option<u32>; WHEELSETS],
}

/// What the unit shows after a step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UnitOutputs<F> {
    /// Brake cylinder pressure of each wheelset, Pa (the input of paper Eq (1)).
    pub cylinder_pressure_pa: [F; WHEELSETS],
    /// Valve commands of the WSP. The valve acts at once; the cylinder feels it after
    /// the pneumatic dead time.
    pub valves: [Valve; WHEELSETS],
    /// True while a wheelset's WSP valve vents (the `wsp1..4` column of a run log).
    pub venting: [bool; WHEELSETS],
    /// The WSP's reference (vehicle) speed estimate, m/s.
    pub reference_speed_mps: F,
    /// Cylinder pressure the brake demand asks for (before the WSP), Pa.
    pub demand_pressure_pa: F,
}

impl<F: Real> BrakeUnit<F> {
    /// Builds the unit (construction: kept out of line, so it stays in flash and out of
    /// the board's CCM step code, which inlines only the step).
    #[inline(never)]
    pub fn new(params: &Params, config: &UnitConfig) -> Result<Self, UnitError> {
        let dt = config.step_s;
        // Plant step and control cycle: positive, finite and at most 1 s (NaN fails too).
        let period_ok = |s: f64| s > 0.0 && s <= MAX_PERIOD_S;
        if !(period_ok(dt) && period_ok(config.control_period_s)) {
            return Err(UnitError::BadPeriod);
        }
        // Every value the unit is built from: the plant's (supply pressure, caliper, mass
        // of the EB pressure), `[brake_unit]` and the WSP tuning.
        params.validate().map_err(UnitError::Params)?;
        let u = &config.params;
        u.validate().map_err(UnitError::Params)?;
        config.wsp.validate().map_err(UnitError::Params)?;
        let steps_per_cycle = ((config.control_period_s / dt) + 0.5).max(1.0) as u32;
        let cycle = steps_per_cycle as f64 * dt;
        let delay = (u.dead_time_s / cycle + 0.5) as usize;
        if delay >= DELAY_CAPACITY {
            return Err(UnitError::DeadTimeTooLong {
                dead_time_s: u.dead_time_s,
                max_s: (DELAY_CAPACITY - 1) as f64 * cycle,
            });
        }
        Ok(Self {
            steps_per_cycle,
            cycle_s: cycle,
            step_in_cycle: 0,
            fill_gain: F::of(1.0 - hils_plant::math::exp_f64(-dt / u.fill_time_constant_s)),
            vent_gain: F::of(1.0 - hils_plant::math::exp_f64(-dt / u.vent_time_constant_s)),
            eb_pressure: F::of(eb_pressure(params, u.eb_deceleration_mps2)),
            eb_deceleration: F::of(u.eb_deceleration_mps2),
            wsp_enabled: config.wsp_enabled,
            wsp_k: WspConstants::new(&config.wsp, &Pneumatics::of(u, params), cycle),
            ep_k: u
                .ep_valve
                .then(|| EpConstants::new(u, cycle, params.brake.supply_pressure)),
            ep: EpValve::default(),
            service_step_pressure: service_step_pressures(params, u),
            service_steps: u.service_steps.clamp(1, MAX_SERVICE_STEPS as u8),
            spring_pressure: F::of(params.brake.retaining_spring_force / params.brake.piston_area),
            reference: ReferenceSpeed::default(),
            channels: [WspChannel::default(); WHEELSETS],
            cylinders: [Cylinder::default(); WHEELSETS],
            delay_pressure: [F::ZERO; DELAY_CAPACITY],
            delay_valves: [0; DELAY_CAPACITY],
            delay,
            head: 0,
            acting_pressure: F::ZERO,
            acting_valves: [Valve::Apply; WHEELSETS],
            demand: BrakeDemand::Release,
            cycles: 0,
            first_vent_cycle: [None; WHEELSETS],
        })
    }

    /// Sets the brake demand (takes effect at the next control cycle, then after the dead time).
    pub fn set_demand(&mut self, demand: BrakeDemand) {
        self.demand = demand;
    }

    /// The open-loop EB pressure, Pa.
    pub fn eb_pressure(&self) -> F {
        self.eb_pressure
    }

    /// The valve states acting on the cylinders now: the commands of one dead time ago
    /// (what the cylinder pressures follow; [`UnitOutputs::valves`] are the commands).
    pub fn acting_valves(&self) -> [Valve; WHEELSETS] {
        self.acting_valves
    }

    /// The WSP channels (phase, pressure memory, adhesion observer of each wheelset).
    pub fn channels(&self) -> &[WspChannel<F>; WHEELSETS] {
        &self.channels
    }

    /// Time of each wheelset's first WSP vent command since the unit started, s.
    pub fn first_vent_time(&self) -> [Option<f64>; WHEELSETS] {
        let period = self.cycle_s;
        self.first_vent_cycle.map(|c| c.map(|c| c as f64 * period))
    }

    fn demand_pressure(&self) -> F {
        match self.demand {
            BrakeDemand::Release => F::ZERO,
            BrakeDemand::Emergency => self.eb_pressure,
            BrakeDemand::Service {
                deceleration_mps2: decel,
            } => {
                let d = F::of(decel as f64);
                if !(d > F::ZERO) {
                    return F::ZERO;
                }
                // The brake force in proportion to EB's ([`service_pressure`]).
                let share = d.min(self.eb_deceleration) / self.eb_deceleration;
                (self.spring_pressure + (self.eb_pressure - self.spring_pressure) * share)
                    .min(self.eb_pressure)
            }
            BrakeDemand::ServiceStep { step } => {
                self.service_step_pressure[step.min(self.service_steps) as usize]
            }
        }
    }

    /// One control cycle: reference speed, demand (EP valve), WSP, delay line.
    fn control(&mut self, wheel_speeds: &[F; WHEELSETS]) {
        // The ECU's EP valve makes the pilot pressure (PI + hysteresis compensation).
        let demand = match &self.ep_k {
            Some(k) => self.ep.update(k, self.demand_pressure()),
            None => self.demand_pressure(),
        };
        for j in 0..WHEELSETS {
            let p = self.cylinders[j].pressure;
            self.channels[j].observe(&self.wsp_k, wheel_speeds[j], p);
        }
        let vehicle_decel = crate::wsp::vehicle_deceleration(&self.wsp_k, &self.channels);
        self.reference
            .update(&self.wsp_k, wheel_speeds, vehicle_decel);
        let mut packed = 0u8;
        for j in 0..WHEELSETS {
            let valve = if self.wsp_enabled {
                let inputs = ChannelInputs {
                    wheel_speed_mps: wheel_speeds[j],
                    cylinder_pressure_pa: self.cylinders[j].pressure,
                    demand_pressure_pa: demand,
                    vehicle_decel_mps2: vehicle_decel,
                };
                self.channels[j].update(&self.wsp_k, &inputs, &self.reference)
            } else {
                Valve::Apply
            };
            if valve == Valve::Vent && self.first_vent_cycle[j].is_none() {
                self.first_vent_cycle[j] = Some(self.cycles);
            }
            packed |= (valve as u8) << (2 * j);
        }
        // Delay line: write now, read what was written `delay` cycles ago.
        self.delay_pressure[self.head] = demand;
        self.delay_valves[self.head] = packed;
        let tail = (self.head + DELAY_CAPACITY - self.delay) % DELAY_CAPACITY;
        self.acting_pressure = self.delay_pressure[tail];
        let acting = self.delay_valves[tail];
        for j in 0..WHEELSETS {
            self.acting_valves[j] = Valve::from_bits(acting >> (2 * j));
        }
        self.head = (self.head + 1) % DELAY_CAPACITY;
        self.cycles = self.cycles.wrapping_add(1);
    }

    /// Advances by one plant step given the wheel circumferential speeds r omega (m/s) the
    /// axle speed sensors show. Returns the cylinder pressures for the plant.
    pub fn step(&mut self, wheel_speeds: &[F; WHEELSETS]) -> UnitOutputs<F> {
        if self.step_in_cycle == 0 {
            let sane = wheel_speeds.map(|v| if v.is_finite() { v } else { F::ZERO });
            self.control(&sane);
        }
        self.step_in_cycle += 1;
        if self.step_in_cycle >= self.steps_per_cycle {
            self.step_in_cycle = 0;
        }
        let mut out = UnitOutputs {
            cylinder_pressure_pa: [F::ZERO; WHEELSETS],
            valves: [Valve::Apply; WHEELSETS],
            venting: [false; WHEELSETS],
            reference_speed_mps: self.reference.speed,
            demand_pressure_pa: self.acting_pressure,
        };
        for j in 0..WHEELSETS {
            let c = &mut self.cylinders[j];
            match self.acting_valves[j] {
                // BOU relay: fill toward the demand with the fill lag, exhaust toward a
                // lower demand with the vent lag. The WSP modulates by holding and venting
                // (its pulsed reapply is a sequence of Apply and Hold commands).
                Valve::Apply => {
                    let gain = if self.acting_pressure > c.pressure {
                        self.fill_gain
                    } else {
                        self.vent_gain
                    };
                    c.approach(self.acting_pressure, gain);
                }
                Valve::Hold => {}
                Valve::Vent => c.approach(F::ZERO, self.vent_gain),
            }
            out.cylinder_pressure_pa[j] = c.pressure;
            out.valves[j] = self.channels[j].valve;
            out.venting[j] = self.channels[j].valve == Valve::Vent;
        }
        out
    }
}
