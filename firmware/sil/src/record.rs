//! The run record and the run-log schema: one list of column names, units and order
//! (`spec/measured-data.md`, section 1, plus the simulation's and the rig's extra columns)
//! that every writer (`hils simulate`, `hils decode`, the diagnosis generator) and the
//! reader (`hils::measured`) name their columns through.
//!
//! A column is a [`Channel`]: a name stem, a unit suffix, and whether there is one per
//! wheelset (`omega1_radps` .. `omega4_radps`). The friction-test format (section 2) is
//! [`friction_test`].

use core::fmt;

use hils_brake_unit::BrakeDemand;
use hils_plant::{Real, WHEELSETS};

use crate::closed_loop::ClosedLoop;

/// One quantity of a log: `stem` + wheelset number (if per wheelset) + `unit`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Channel {
    /// Name stem (`omega`, `v_ref`).
    pub stem: &'static str,
    /// Unit suffix with its underscore (`_radps`), empty for a dimensionless quantity.
    pub unit: &'static str,
    /// One column per wheelset (the number goes between stem and unit).
    pub per_wheelset: bool,
}

impl Channel {
    /// A channel with one column (`t_s`).
    pub const fn scalar(stem: &'static str, unit: &'static str) -> Self {
        Self {
            stem,
            unit,
            per_wheelset: false,
        }
    }

    /// A channel with a column per wheelset (`omega1_radps`).
    pub const fn wheelset(stem: &'static str, unit: &'static str) -> Self {
        Self {
            stem,
            unit,
            per_wheelset: true,
        }
    }

    /// The column name of wheelset `j` (0-based; ignored for a scalar channel).
    pub fn name(self, j: usize) -> ColumnName {
        ColumnName { channel: self, j }
    }

    /// Number of columns: 4 per wheelset, else 1.
    pub fn width(self) -> usize {
        if self.per_wheelset { WHEELSETS } else { 1 }
    }

    /// The SI unit of the channel's values as a symbol (`rad/s` for `_radps`, `degC` for
    /// `_c`, empty for a dimensionless quantity or a text): what a file that stores units
    /// (MDF4) writes beside the column, and what a stored unit converts to.
    pub fn unit_symbol(self) -> &'static str {
        match self.unit {
            "_s" => "s",
            "_mps" => "m/s",
            "_radps" => "rad/s",
            "_pa" => "Pa",
            "_n" => "N",
            "_c" => "degC",
            "_m" => "m",
            "_mps2" => "m/s^2",
            "_us" => "us",
            _ => "",
        }
    }

    /// The channel and wheelset (0-based) of a column name, among `channels`.
    pub fn find(channels: &[Channel], name: &str) -> Option<(Channel, usize)> {
        channels.iter().find_map(|c| {
            let rest = name.strip_prefix(c.stem)?.strip_suffix(c.unit)?;
            if !c.per_wheelset {
                return rest.is_empty().then_some((*c, 0));
            }
            let j = match rest.as_bytes() {
                [d @ b'1'..=b'4'] => (d - b'1') as usize,
                _ => return None,
            };
            Some((*c, j))
        })
    }
}

/// A column name ([`Channel::name`]); `Display` writes it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ColumnName {
    channel: Channel,
    j: usize,
}

impl fmt::Display for ColumnName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let c = self.channel;
        if c.per_wheelset {
            write!(f, "{}{}{}", c.stem, self.j + 1, c.unit)
        } else {
            write!(f, "{}{}", c.stem, c.unit)
        }
    }
}

/// Run-log channels (`spec/measured-data.md` section 1 and the project's extras).
pub mod run_log {
    use super::Channel;

    /// Time since the start of the log, s (required).
    pub const T: Channel = Channel::scalar("t", "_s");
    /// Vehicle reference speed, m/s (required).
    pub const V_REF: Channel = Channel::scalar("v_ref", "_mps");
    /// Wheelset angular speed, rad/s (required).
    pub const OMEGA: Channel = Channel::wheelset("omega", "_radps");
    /// Brake cylinder pressure, Pa.
    pub const P_CYL: Channel = Channel::wheelset("p_cyl", "_pa");
    /// Pad clamp force per friction face, N.
    pub const F_CLAMP: Channel = Channel::wheelset("f_clamp", "_n");
    /// Disc friction force at the friction radius, N.
    pub const F_BRAKE: Channel = Channel::wheelset("f_brake", "_n");
    /// Disc temperature rise, degC.
    pub const T_DISC: Channel = Channel::wheelset("t_disc", "_c");
    /// Axle load, N.
    pub const Q: Channel = Channel::wheelset("q", "_n");
    /// WSP valve venting, 0/1 (the dump valve's coil energised).
    pub const WSP: Channel = Channel::wheelset("wsp", "");
    /// WSP hold valve coil energised, 0/1 (holding: hold without `wsp`; rig logs and
    /// `hils decode`, an extra column).
    pub const HOLD: Channel = Channel::wheelset("hold", "");
    /// The emergency brake loop the rig drove: 1 closed (no EB), 0 open (EB) (rig logs).
    pub const EB_LOOP: Channel = Channel::scalar("eb_loop_closed", "");
    /// The service brake deceleration the rig drove on the demand PWM, m/s^2 (rig logs).
    pub const SERVICE_DEMAND: Channel = Channel::scalar("service_demand", "_mps2");
    /// The air-spring pressure of bogie 1 the rig drove on its DAC, Pa (rig logs; empty
    /// while the output is silent).
    pub const AIR_SPRING1: Channel = Channel::scalar("air_spring1", "_pa");
    /// The air-spring pressure of bogie 2 the rig drove on its DAC, Pa.
    pub const AIR_SPRING2: Channel = Channel::scalar("air_spring2", "_pa");
    /// Carbody longitudinal acceleration, m/s^2.
    pub const A_X: Channel = Channel::scalar("a_x", "_mps2");
    /// Brake command in force ([`super::Cmd::text`]).
    pub const CMD: Channel = Channel::scalar("cmd", "");
    /// Disc-pad friction coefficient (Eq 2).
    pub const MU_D: Channel = Channel::wheelset("mu_d", "");
    /// Wheel-rail creepage.
    pub const CREEPAGE: Channel = Channel::wheelset("creepage", "");
    /// Adhesion coefficient used, F / Q.
    pub const ADHESION: Channel = Channel::wheelset("adhesion", "");
    /// Distance run, m.
    pub const X: Channel = Channel::scalar("x", "_m");
    /// The brake unit's reference-speed estimate, m/s.
    pub const V_REF_EST: Channel = Channel::scalar("v_ref_est", "_mps");
    /// Rig run state (`hils decode`).
    pub const STATE: Channel = Channel::scalar("state", "");
    /// Rig fault flags, hex (`hils decode`).
    pub const FAULTS: Channel = Channel::scalar("faults", "");
    /// Sensor fault codes, 4 bits per channel, hex (`hils decode`).
    pub const SENSOR_FAULTS: Channel = Channel::scalar("sensor_faults", "");
    /// Longest step since the last record, us (`hils decode`).
    pub const STEP_MAX: Channel = Channel::scalar("step_max", "_us");
    /// Mean step since the last record, us (`hils decode`).
    pub const STEP_MEAN: Channel = Channel::scalar("step_mean", "_us");
    /// Overruns since the run started (`hils decode`).
    pub const OVERRUNS: Channel = Channel::scalar("overruns", "");
    /// Missed ticks since the run started (`hils decode`).
    pub const MISSED_TICKS: Channel = Channel::scalar("missed_ticks", "");
    /// The surface (zone) under the wheelset: `dry`, `wet`, `low`, `very_low` (rig
    /// telemetry; an extra column, which the spec allows).
    pub const SURFACE: Channel = Channel::wheelset("surface", "");
    /// The available adhesion under the wheelset (peak of F/Q over creepage of its surface
    /// at the vehicle speed; rig logs, an extra column).
    pub const MU_AVAIL: Channel = Channel::wheelset("mu_avail", "");

    /// The spec's channels, in order: the required ones, then the optional ones.
    pub const SPEC: [Channel; 11] = [
        T, V_REF, OMEGA, P_CYL, F_CLAMP, F_BRAKE, T_DISC, Q, WSP, A_X, CMD,
    ];

    /// Every channel, in the order writers put them: the spec's, the simulation's extras,
    /// the rig's extras. A writer leaves out what it does not log and keeps the order.
    pub const ALL: [Channel; 30] = [
        T,
        V_REF,
        OMEGA,
        P_CYL,
        F_CLAMP,
        F_BRAKE,
        T_DISC,
        Q,
        WSP,
        HOLD,
        A_X,
        CMD,
        MU_D,
        CREEPAGE,
        ADHESION,
        X,
        V_REF_EST,
        STATE,
        FAULTS,
        SENSOR_FAULTS,
        STEP_MAX,
        STEP_MEAN,
        OVERRUNS,
        MISSED_TICKS,
        SURFACE,
        MU_AVAIL,
        EB_LOOP,
        SERVICE_DEMAND,
        AIR_SPRING1,
        AIR_SPRING2,
    ];
}

/// Friction-test channels (`spec/measured-data.md` section 2).
pub mod friction_test {
    use super::Channel;

    /// Time, s (optional: a time series): the run log's `t_s`.
    pub const T: Channel = super::run_log::T;
    /// Friction speed, m/s.
    pub const V_FRICTION: Channel = Channel::scalar("v_friction", "_mps");
    /// Disc temperature rise, degC.
    pub const T_DISC: Channel = Channel::scalar("t_disc", "_c");
    /// Friction coefficient.
    pub const MU: Channel = Channel::scalar("mu", "");
    /// Clamp force, N.
    pub const F_CLAMP: Channel = Channel::scalar("f_clamp", "_n");
    /// Friction force, N.
    pub const F_FRICTION: Channel = Channel::scalar("f_friction", "_n");
}

/// The brake command of a run log's `cmd` column (and of the rig's telemetry `cmd` code:
/// 0-2 in declaration order).
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, Default, num_enum::IntoPrimitive, num_enum::TryFromPrimitive,
)]
#[repr(u8)]
pub enum Cmd {
    /// Brakes released (`REL`).
    #[default]
    Release,
    /// Emergency brake (`EB`).
    Emergency,
    /// Service brake (`SB`).
    Service,
}

impl Cmd {
    /// The command of a brake demand.
    pub fn of(demand: BrakeDemand) -> Cmd {
        match demand {
            BrakeDemand::Release => Cmd::Release,
            BrakeDemand::Emergency => Cmd::Emergency,
            BrakeDemand::Service { .. } | BrakeDemand::ServiceStep { .. } => Cmd::Service,
        }
    }

    /// The cell text: `REL`, `EB`, `SB`.
    pub fn text(self) -> &'static str {
        match self {
            Cmd::Release => "REL",
            Cmd::Emergency => "EB",
            Cmd::Service => "SB",
        }
    }
}

/// One sample of a closed-loop run in SI units (f64 whatever the plant's precision): a row
/// of the simulation's run log, named as its columns.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RunRecord {
    /// Time since the start, s.
    pub t_s: f64,
    /// Carbody (true vehicle) speed, m/s.
    pub v_ref_mps: f64,
    /// Distance run, m.
    pub x_m: f64,
    /// Carbody acceleration, m/s^2.
    pub a_x_mps2: f64,
    /// Brake command in force.
    pub cmd: Cmd,
    /// Wheelset angular speeds, rad/s.
    pub omega_radps: [f64; WHEELSETS],
    /// Cylinder pressures, Pa.
    pub p_cyl_pa: [f64; WHEELSETS],
    /// Pad clamp forces per face, N.
    pub f_clamp_n: [f64; WHEELSETS],
    /// Disc friction forces, N.
    pub f_brake_n: [f64; WHEELSETS],
    /// Disc temperature rises, degC.
    pub t_disc_c: [f64; WHEELSETS],
    /// Axle loads, N.
    pub q_n: [f64; WHEELSETS],
    /// WSP venting.
    pub wsp: [bool; WHEELSETS],
    /// Disc-pad friction coefficients.
    pub mu_d: [f64; WHEELSETS],
    /// Creepages.
    pub creepage: [f64; WHEELSETS],
    /// Adhesion coefficients used.
    pub adhesion: [f64; WHEELSETS],
    /// The brake unit's reference-speed estimate, m/s.
    pub v_ref_est_mps: f64,
}

impl RunRecord {
    /// The record of a loop's present state under brake command `cmd`.
    pub fn of<F: Real>(sim: &ClosedLoop<F>, cmd: Cmd) -> Self {
        let o = sim.outputs();
        let u = sim.unit_outputs();
        let w = |g: &dyn Fn(usize) -> F| core::array::from_fn(|j| g(j).to_f64());
        Self {
            t_s: sim.plant.time().to_f64(),
            v_ref_mps: o.vehicle_speed.to_f64(),
            x_m: o.distance.to_f64(),
            a_x_mps2: o.carbody_accel.to_f64(),
            cmd,
            omega_radps: w(&|j| o.wheelsets[j].omega),
            p_cyl_pa: w(&|j| u.cylinder_pressure_pa[j]),
            f_clamp_n: w(&|j| o.wheelsets[j].clamp_force),
            f_brake_n: w(&|j| o.wheelsets[j].brake_force),
            t_disc_c: w(&|j| o.wheelsets[j].disc_temp),
            q_n: w(&|j| o.wheelsets[j].axle_load),
            wsp: u.venting,
            mu_d: w(&|j| o.wheelsets[j].mu_d),
            creepage: w(&|j| o.wheelsets[j].creepage),
            adhesion: w(&|j| o.wheelsets[j].adhesion),
            v_ref_est_mps: u.reference_speed_mps.to_f64(),
        }
    }

    /// The value of column `channel` of wheelset `j` (0-based; ignored for a scalar
    /// channel): `None` for a channel the record does not hold (`cmd`, as text in its
    /// column, and the rig's and the trace's own channels).
    pub fn value(&self, channel: Channel, j: usize) -> Option<f64> {
        use run_log::*;
        let w = |a: &[f64; WHEELSETS]| a.get(j).copied();
        match channel {
            T => Some(self.t_s),
            V_REF => Some(self.v_ref_mps),
            X => Some(self.x_m),
            A_X => Some(self.a_x_mps2),
            V_REF_EST => Some(self.v_ref_est_mps),
            OMEGA => w(&self.omega_radps),
            P_CYL => w(&self.p_cyl_pa),
            F_CLAMP => w(&self.f_clamp_n),
            F_BRAKE => w(&self.f_brake_n),
            T_DISC => w(&self.t_disc_c),
            Q => w(&self.q_n),
            MU_D => w(&self.mu_d),
            CREEPAGE => w(&self.creepage),
            ADHESION => w(&self.adhesion),
            WSP => self.wsp.get(j).map(|&v| v as u8 as f64),
            _ => None,
        }
    }

    /// The mean disc-pad friction coefficient over the wheelsets.
    pub fn mean_mu_d(&self) -> f64 {
        self.mu_d.iter().sum::<f64>() / WHEELSETS as f64
    }
}
