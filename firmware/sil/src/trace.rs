//! The emulated target's trace: what the emulator binary (`firmware/qemu`) streams every
//! [`RECORD_EVERY`] steps of the paper scenario and the host compares bit for bit
//! ([`TraceRow`], its text line [`TraceRow::encode`] / [`TraceRow::decode`]), and the names
//! of the cost lines the binary prints ([`PARTS`]).

use hils_brake_unit::UnitOutputs;
use hils_plant::{Outputs, WHEELSETS};

use crate::closed_loop::ClosedLoop;
use crate::record::{Channel, run_log};

/// Record every this many plant steps: 10 ms at the 0.1 ms step.
pub const RECORD_EVERY: u32 = 100;

/// The scalar values of a [`TraceRow`], in order: channels of the run-record schema
/// ([`crate::record`]): the run log's, and the trace's own (the plant's and the unit's
/// internals no run log has, named by the same rule: the plant's names as stem and unit).
pub const SCALAR_COLUMNS: [Channel; 7] = [
    run_log::T,
    run_log::V_REF,
    run_log::X,
    run_log::A_X,
    Channel::scalar("carbody_pitch", "_rad"),
    run_log::V_REF_EST,
    Channel::scalar("demand_pressure", "_pa"),
];

/// The per-wheelset values of a [`TraceRow`], in order: the plant's wheelset outputs (the
/// order of [`hils_plant::WheelsetOutput::values`] and its `NAMES`), then the unit's cylinder
/// pressure; the run log's channels where it has the value, else the plant's name.
pub const WHEELSET_COLUMNS: [Channel; 16] = [
    run_log::OMEGA,
    Channel::wheelset("speed", "_mps"),
    Channel::wheelset("slip_velocity", "_mps"),
    run_log::CREEPAGE,
    run_log::Q,
    Channel::wheelset("adhesion_force", "_n"),
    run_log::ADHESION,
    Channel::wheelset("rail_mu", ""),
    run_log::MU_D,
    run_log::F_CLAMP,
    Channel::wheelset("brake_torque", "_nm"),
    run_log::F_BRAKE,
    run_log::T_DISC,
    Channel::wheelset("brake_power", "_w"),
    Channel::wheelset("contact_power", "_w"),
    run_log::P_CYL,
];

/// Every value of a [`TraceRow`] as (channel, wheelset 0-based; 0 for a scalar), in the
/// order of [`TraceRow::values`].
pub fn columns() -> impl Iterator<Item = (Channel, usize)> {
    let scalars = SCALAR_COLUMNS.into_iter().map(|c| (c, 0));
    let per = (0..WHEELSETS).flat_map(|j| WHEELSET_COLUMNS.into_iter().map(move |c| (c, j)));
    scalars.chain(per)
}

/// Number of f32 values in a [`TraceRow`].
pub const VALUES: usize = SCALAR_COLUMNS.len() + WHEELSETS * WHEELSET_COLUMNS.len();

/// Number of 32-bit words of an encoded row: step, flags, valves, then the values.
pub const WORDS: usize = 3 + VALUES;

/// Length of an encoded row: `R`, then per word a space and 8 hex digits, then `\n`.
pub const LINE_LEN: usize = 1 + 9 * WORDS + 1;

/// One recorded step of the closed loop; every float kept as its f32 bit pattern.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TraceRow {
    /// Plant steps since the start.
    pub step: u32,
    /// The plant's flags of the step (`hils_plant::Flags`).
    pub flags: u32,
    /// The WSP valve commands, 2 bits per wheelset (0 apply, 1 hold, 2 vent), wheelset 1
    /// in the lowest bits.
    pub valves: u32,
    /// [`SCALAR_COLUMNS`], then [`WHEELSET_COLUMNS`] of wheelset 1, 2, 3, 4.
    pub values: [u32; VALUES],
}

impl TraceRow {
    /// The row of the loop's current state.
    pub fn of(sim: &ClosedLoop<f32>) -> Self {
        Self::from_outputs(sim.plant.time(), &sim.outputs(), sim.unit_outputs())
    }

    /// The row of a plant time (s), the plant's outputs and the unit's outputs.
    pub fn from_outputs(time: f32, o: &Outputs<f32>, u: &UnitOutputs<f32>) -> Self {
        let mut values = [0u32; VALUES];
        let scalars = [
            time,
            o.vehicle_speed,
            o.distance,
            o.carbody_accel,
            o.carbody_pitch,
            u.reference_speed_mps,
            u.demand_pressure_pa,
        ];
        let mut k = 0;
        for x in scalars {
            values[k] = x.to_bits();
            k += 1;
        }
        let mut valves = 0u32;
        for j in 0..WHEELSETS {
            let w = &o.wheelsets[j];
            let per = w.values().into_iter().chain([u.cylinder_pressure_pa[j]]);
            for x in per {
                values[k] = x.to_bits();
                k += 1;
            }
            valves |= (u8::from(u.valves[j]) as u32) << (2 * j);
        }
        Self {
            step: o.steps,
            flags: o.flags.0,
            valves,
            values,
        }
    }

    /// Value `k` as f32.
    pub fn value(&self, k: usize) -> f32 {
        f32::from_bits(self.values[k])
    }

    /// Whether wheelset `j`'s WSP valve vents.
    pub fn venting(&self, j: usize) -> bool {
        (self.valves >> (2 * j)) & 3 == 2
    }

    /// Writes the text line (`R`, [`WORDS`] words of 8 hex digits, `\n`) into `buf`.
    pub fn encode(&self, buf: &mut [u8; LINE_LEN]) {
        const HEX: &[u8; 16] = b"0123456789abcdef";
        buf[0] = b'R';
        let mut at = 1;
        let mut put = |word: u32| {
            buf[at] = b' ';
            for d in 0..8 {
                buf[at + 1 + d] = HEX[((word >> (28 - 4 * d)) & 0xf) as usize];
            }
            at += 9;
        };
        put(self.step);
        put(self.flags);
        put(self.valves);
        for v in self.values {
            put(v);
        }
        buf[LINE_LEN - 1] = b'\n';
    }

    /// Parses a line written by [`TraceRow::encode`] (without or with its `\n`). `None` if it
    /// is not exactly such a line.
    pub fn decode(line: &str) -> Option<Self> {
        let rest = line.strip_suffix('\n').unwrap_or(line).strip_prefix('R')?;
        let mut words = [0u32; WORDS];
        let mut n = 0;
        for field in rest.split(' ').skip(1) {
            if n == WORDS || field.len() != 8 {
                return None;
            }
            words[n] = u32::from_str_radix(field, 16).ok()?;
            n += 1;
        }
        if n != WORDS || !rest.starts_with(' ') {
            return None;
        }
        let mut values = [0u32; VALUES];
        values.copy_from_slice(&words[3..]);
        Some(Self {
            step: words[0],
            flags: words[1],
            valves: words[2],
            values,
        })
    }
}

/// The timed parts of a step, as the binary names them in its `C` (cost) lines.
///
/// * `step`: `Plant::step` (the full plant step: 4 wheelsets, 17 DOF, contact, friction,
///   heat), timed on an exact replay of each step of the loop;
/// * `loop`: `ClosedLoop::step` (brake unit + plant), the step that makes the trajectory;
/// * `contact`, `friction`, `thermal`: the plant's sub-models (Polach Eqs 9-12, Eq 2,
///   Eqs 3-6) for the four wheelsets, called separately with the step's values;
/// * `suspension`: the rest of the plant step (suspension forces, the 17-DOF bodies, the
///   semi-implicit spin/brake update, integration, input checks): `step` minus the three
///   sub-models, per step;
/// * `unit`: the brake unit and the loop's wiring: `loop` minus `step`, per step.
pub const PARTS: [&str; 7] = [
    "step",
    "loop",
    "contact",
    "friction",
    "thermal",
    "suspension",
    "unit",
];
