//! One FMU instance in safe Rust: the FMI 3.0 Co-Simulation state machine over the plant or
//! the closed loop of `hils-sil` (the same code `hils simulate` runs), its parameters (a
//! whole parameter file, [`ParamFile`]), its inputs and its results ([`RunRecord`], the
//! run log's record). Every refusal is a [`Fault`] with a message naming the variable, the
//! value and the rule; [`crate::abi`] logs it and returns `fmi3Error`. Nothing here
//! panics on any value or call order (the C API catches a panic all the same).

use std::collections::BTreeMap;
use std::path::Path;

use hils_brake_unit::BrakeDemand;
use hils_plant::keys::{KeyInfo, KeyValue, KeyVisitor, Keys};
use hils_plant::{BrakeInput, Flags, Real, WHEELSETS};
use hils_sil::record::run_log::V_REF_EST;
use hils_sil::{ClosedLoop, Cmd, KMH_PER_MPS, ParamFile, RunRecord};

use crate::variables::{self, Causality, Kind, Role, Variable};

/// An FMI status.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
#[repr(i32)]
pub enum Status {
    /// `fmi3OK`.
    Ok = 0,
    /// `fmi3Warning`.
    Warning = 1,
    /// `fmi3Discard`.
    Discard = 2,
    /// `fmi3Error`.
    Error = 3,
    /// `fmi3Fatal`.
    Fatal = 4,
}

/// A refused call: the message the FMU logs (status `fmi3Error`).
#[derive(Clone, Debug, PartialEq)]
pub struct Fault(pub String);

/// Shorthand for a refusal.
pub fn fault<T>(message: impl Into<String>) -> Result<T, Fault> {
    Err(Fault(message.into()))
}

/// What a call gives back: a status (OK or a warning) or a refusal.
pub type Outcome = Result<Status, Fault>;

/// The FMI 3.0 Co-Simulation states an instance is in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    /// After instantiation or reset: parameters and inputs may be set.
    Instantiated,
    /// Configuration Mode: structural parameters may be set.
    Configuration,
    /// Initialization Mode: parameters, inputs; outputs may be read.
    Initialization,
    /// Step Mode: inputs, steps, outputs.
    Step,
    /// After terminate: results may be read.
    Terminated,
}

impl Mode {
    /// The state's name as the FMI standard says it.
    pub fn name(self) -> &'static str {
        match self {
            Mode::Instantiated => "Instantiated",
            Mode::Configuration => "Configuration Mode",
            Mode::Initialization => "Initialization Mode",
            Mode::Step => "Step Mode",
            Mode::Terminated => "Terminated",
        }
    }
}

/// What drives the brakes (the structural parameter `brake_input`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Drive {
    /// `p_cyl1_pa..p_cyl4_pa` through Eq (1).
    CylinderPressure,
    /// `f_clamp1_n..f_clamp4_n`.
    ClampForce,
    /// The simulated brake unit answers `cmd` (the closed loop of `hils simulate`).
    BrakeUnit,
}

impl Drive {
    const ALL: [Drive; 3] = [Drive::CylinderPressure, Drive::ClampForce, Drive::BrakeUnit];
}

/// Everything an FMU state save (`fmi3GetFMUState`) keeps.
#[derive(Clone, Debug)]
pub struct Model {
    mode: Mode,
    /// The resource's parameter file (what reset returns to).
    defaults: ParamFile,
    file: ParamFile,
    /// Free-text keys' values, by key index.
    notes: BTreeMap<usize, String>,
    params_file: String,
    drive: Drive,
    p_cyl_pa: [f64; WHEELSETS],
    f_clamp_n: [f64; WHEELSETS],
    cmd: Cmd,
    service_deceleration_mps2: f64,
    sim: Option<ClosedLoop<f32>>,
    start_time_s: f64,
    stop_time_s: Option<f64>,
    steps: u64,
    /// The plant's flags over the last communication step, or-ed.
    flags: u32,
    /// The record of the present state (built on the first read after a step).
    record: Option<RunRecord>,
    /// Inputs already warned about as not read by `brake_input` ([`Model::unread_inputs`]).
    unread_warned: u32,
}

/// The plant's flags a step warns about (the plant handles them safely).
const WARN_FLAGS: u32 = Flags::INPUT_NOT_FINITE | Flags::INPUT_OUT_OF_RANGE | Flags::NUMERIC_FAULT;

/// How far (in plant steps) an importer's `currentCommunicationPoint` may lie from the
/// FMU's own time (start + steps x step) and still name it: an importer that sums its time
/// (`t += h`), or runs at a large start time, drifts from it by rounding (t += 1 ms over an
/// hour: 0.27 us; one ulp of 1e7 s: 1.9 ns), always far less than half a plant step.
pub const TIME_TOLERANCE_STEPS: f64 = 0.5;

/// How far (in plant steps) a `communicationStepSize` may lie from a whole number of plant
/// steps (a step computed as a difference of two large times carries their rounding).
pub const STEP_TOLERANCE_STEPS: f64 = 1e-4;

/// Most plant steps one `doStep` may take (a day at 10 kHz): a bound on the call's time.
pub const MAX_STEPS_PER_CALL: f64 = 864e6;

impl Model {
    /// A model with `defaults` as its parameters (the resource file's).
    pub fn new(defaults: ParamFile) -> Self {
        Self {
            mode: Mode::Instantiated,
            defaults,
            file: defaults,
            notes: BTreeMap::new(),
            params_file: String::new(),
            drive: Drive::CylinderPressure,
            p_cyl_pa: [0.0; WHEELSETS],
            f_clamp_n: [0.0; WHEELSETS],
            cmd: Cmd::Release,
            service_deceleration_mps2: 0.0,
            sim: None,
            start_time_s: 0.0,
            stop_time_s: None,
            steps: 0,
            flags: 0,
            record: None,
            unread_warned: 0,
        }
    }

    /// The state the instance is in.
    pub fn mode(&self) -> Mode {
        self.mode
    }

    /// The parameters in force.
    pub fn params(&self) -> &ParamFile {
        &self.file
    }

    /// Back to the state after instantiation (`fmi3Reset`).
    pub fn reset(&mut self) {
        *self = Self::new(self.defaults);
    }

    fn expect_mode(&self, call: &str, allowed: &[Mode]) -> Result<(), Fault> {
        if allowed.contains(&self.mode) {
            return Ok(());
        }
        let names: Vec<&str> = allowed.iter().map(|m| m.name()).collect();
        fault(format!(
            "{call} is not allowed in {} (only in {})",
            self.mode.name(),
            names.join(", ")
        ))
    }

    /// `fmi3EnterConfigurationMode`.
    pub fn enter_configuration_mode(&mut self) -> Outcome {
        self.expect_mode("fmi3EnterConfigurationMode", &[Mode::Instantiated])?;
        self.mode = Mode::Configuration;
        Ok(Status::Ok)
    }

    /// `fmi3ExitConfigurationMode`.
    pub fn exit_configuration_mode(&mut self) -> Outcome {
        self.expect_mode("fmi3ExitConfigurationMode", &[Mode::Configuration])?;
        self.mode = Mode::Instantiated;
        Ok(Status::Ok)
    }

    /// `fmi3EnterInitializationMode`.
    pub fn enter_initialization_mode(&mut self, start_s: f64, stop_s: Option<f64>) -> Outcome {
        self.expect_mode("fmi3EnterInitializationMode", &[Mode::Instantiated])?;
        if !start_s.is_finite() {
            return fault(format!("startTime = {start_s} s: must be finite"));
        }
        if let Some(stop) = stop_s
            && !(stop >= start_s)
        {
            return fault(format!(
                "stopTime = {stop} s: must not lie before startTime = {start_s} s"
            ));
        }
        self.start_time_s = start_s;
        self.stop_time_s = stop_s;
        self.mode = Mode::Initialization;
        Ok(Status::Ok)
    }

    /// `fmi3ExitInitializationMode`: builds the plant (or the closed loop) of the
    /// parameters; refused parameters leave the instance in Initialization Mode.
    pub fn exit_initialization_mode(&mut self) -> Outcome {
        self.expect_mode("fmi3ExitInitializationMode", &[Mode::Initialization])?;
        self.ensure_sim()?;
        self.mode = Mode::Step;
        Ok(Status::Ok)
    }

    /// `fmi3Terminate`.
    pub fn terminate(&mut self) -> Outcome {
        self.expect_mode("fmi3Terminate", &[Mode::Step])?;
        self.mode = Mode::Terminated;
        Ok(Status::Ok)
    }

    /// The plant step of the parameters, s.
    pub fn step_s(&self) -> f64 {
        self.file.scenario.paper_eb.step_s
    }

    /// The FMU's time, s.
    pub fn time_s(&self) -> f64 {
        self.start_time_s + self.steps as f64 * self.step_s()
    }

    fn ensure_sim(&mut self) -> Result<&mut ClosedLoop<f32>, Fault> {
        if self.sim.is_none() {
            self.file
                .validate()
                .map_err(|e| Fault(format!("the parameters are refused: {e}")))?;
            let sc = &self.file.scenario.paper_eb;
            // As `hils simulate` builds its loop (tools/src/scenario.rs, run_eb).
            let v0 = f32::of(sc.initial_speed_kmh / KMH_PER_MPS);
            let sim = ClosedLoop::from_file(&self.file, sc.rail, v0)
                .map_err(|e| Fault(format!("the parameters are refused: {e}")))?;
            self.sim = Some(sim);
            self.record = None;
        }
        match self.sim.as_mut() {
            Some(sim) => Ok(sim),
            None => fault("the model could not be built"),
        }
    }

    /// `fmi3DoStep` from `t_s` over `h_s`: a whole number of plant steps with the inputs
    /// held. A warning (with its message) when the plant flagged a brake input this step.
    pub fn do_step(&mut self, t_s: f64, h_s: f64) -> Result<(Status, Option<String>), Fault> {
        self.expect_mode("fmi3DoStep", &[Mode::Step])?;
        let dt = self.step_s();
        let n = steps_of(h_s, dt)?;
        let now = self.time_s();
        if !((t_s - now).abs() < TIME_TOLERANCE_STEPS * dt) {
            return fault(format!(
                "fmi3DoStep from currentCommunicationPoint = {t_s} s, but the FMU is at {} s (the end of its last step)",
                to_ns(now)
            ));
        }
        if let Some(stop) = self.stop_time_s
            && now + n as f64 * dt > stop + TIME_TOLERANCE_STEPS * dt
        {
            return fault(format!(
                "fmi3DoStep to {} s goes past stopTime = {stop} s",
                to_ns(now + n as f64 * dt)
            ));
        }
        let drive = self.drive;
        let (p_cyl, f_clamp) = (self.p_cyl_pa, self.f_clamp_n);
        let demand = self.demand();
        let sim = self.ensure_sim()?;
        let flags = match drive {
            Drive::CylinderPressure => step_plant(
                sim,
                n,
                &p_cyl.map(|p| BrakeInput::CylinderPressure(to_f32(p))),
            ),
            Drive::ClampForce => {
                step_plant(sim, n, &f_clamp.map(|f| BrakeInput::ClampForce(to_f32(f))))
            }
            Drive::BrakeUnit => {
                sim.set_demand(demand);
                let mut flags = 0;
                for _ in 0..n {
                    flags |= sim.step().0;
                }
                flags
            }
        };
        let new = flags & WARN_FLAGS & !self.flags;
        self.steps += n;
        self.flags = flags;
        self.record = None;
        let mut warnings = Vec::new();
        if new != 0 {
            warnings.push(flag_message(new, self.time_s()));
        }
        let unread = self.unread_inputs() & !self.unread_warned;
        if unread != 0 {
            self.unread_warned |= unread;
            warnings.push(self.unread_message(unread));
        }
        if warnings.is_empty() {
            return Ok((Status::Ok, None));
        }
        Ok((Status::Warning, Some(warnings.join("; "))))
    }

    /// The inputs that hold a value the model does not read with this `brake_input` (an
    /// importer that drives the clamp forces but left `brake_input` at its default would
    /// otherwise brake with nothing, silently). Bit `j`: `p_cyl{j+1}_pa`, bit `4 + j`:
    /// `f_clamp{j+1}_n`, bit 8: `cmd`, bit 9: `service_deceleration_mps2`.
    fn unread_inputs(&self) -> u32 {
        let mut bits = 0;
        for j in 0..WHEELSETS {
            if self.drive != Drive::CylinderPressure && self.p_cyl_pa[j] != 0.0 {
                bits |= 1 << j;
            }
            if self.drive != Drive::ClampForce && self.f_clamp_n[j] != 0.0 {
                bits |= 1 << (WHEELSETS + j);
            }
        }
        if self.drive != Drive::BrakeUnit {
            if self.cmd != Cmd::Release {
                bits |= 1 << (2 * WHEELSETS);
            }
            if self.service_deceleration_mps2 != 0.0 {
                bits |= 1 << (2 * WHEELSETS + 1);
            }
        }
        bits
    }

    /// The warning of the inputs of `bits` ([`Model::unread_inputs`]).
    fn unread_message(&self, bits: u32) -> String {
        let role = |bit: usize| match bit {
            b if b < WHEELSETS => Role::CylinderPressure(b),
            b if b < 2 * WHEELSETS => Role::ClampForce(b - WHEELSETS),
            b if b == 2 * WHEELSETS => Role::Command,
            _ => Role::ServiceDeceleration,
        };
        let names: Vec<&str> = (0..2 * WHEELSETS + 2)
            .filter(|&bit| bits & (1 << bit) != 0)
            .filter_map(|bit| variables::VARIABLES.iter().find(|v| v.role == role(bit)))
            .map(|v| v.name.as_str())
            .collect();
        let drive = Drive::ALL
            .iter()
            .position(|d| *d == self.drive)
            .unwrap_or(0);
        let (name, reads) = variables::BRAKE_INPUT.items[drive];
        format!(
            "{} set but not read: brake_input = {name} ({reads}); to drive the brakes by them, set brake_input before fmi3ExitInitializationMode",
            names.join(", ")
        )
    }

    fn demand(&self) -> BrakeDemand {
        match self.cmd {
            Cmd::Release => BrakeDemand::Release,
            Cmd::Emergency => BrakeDemand::Emergency,
            Cmd::Service => BrakeDemand::Service {
                deceleration_mps2: self.service_deceleration_mps2 as f32,
            },
        }
    }

    /// The record of the present state.
    fn record(&mut self) -> Result<RunRecord, Fault> {
        if let Some(r) = self.record {
            return Ok(r);
        }
        let cmd = self.cmd;
        let drive = self.drive;
        let mut r = RunRecord::of(self.ensure_sim()?, cmd);
        if drive != Drive::BrakeUnit {
            // Without the unit its outputs are not the model's: zero.
            r.v_ref_est_mps = 0.0;
        }
        self.record = Some(r);
        Ok(r)
    }

    fn check_readable(&self, v: &Variable) -> Result<(), Fault> {
        if v.causality == Causality::Output
            && matches!(self.mode, Mode::Instantiated | Mode::Configuration)
        {
            return fault(format!(
                "output {} cannot be read in {}: results exist from fmi3EnterInitializationMode on",
                v.name,
                self.mode.name()
            ));
        }
        Ok(())
    }

    fn check_settable(&self, v: &Variable) -> Result<(), Fault> {
        use Mode::*;
        let (ok, when) = match v.causality {
            Causality::Independent | Causality::Output => {
                return fault(format!(
                    "{} is an {} and cannot be set",
                    v.name,
                    v.causality.name()
                ));
            }
            Causality::StructuralParameter => (
                matches!(self.mode, Instantiated | Configuration | Initialization),
                "before fmi3ExitInitializationMode",
            ),
            Causality::Parameter => (
                matches!(self.mode, Instantiated | Initialization),
                "after instantiation or in Initialization Mode",
            ),
            Causality::Input => (
                matches!(self.mode, Instantiated | Initialization | Step),
                "until fmi3Terminate",
            ),
        };
        if ok {
            Ok(())
        } else {
            fault(format!(
                "{} ({}) cannot be set in {}: only {when}",
                v.name,
                v.causality.name(),
                self.mode.name()
            ))
        }
    }

    /// A changed parameter: the model is built again from it.
    fn parameters_changed(&mut self) {
        self.sim = None;
        self.record = None;
    }

    /// `fmi3GetFloat64` of one variable.
    pub fn get_f64(&mut self, v: &Variable) -> Result<f64, Fault> {
        self.check_readable(v)?;
        Ok(match v.role {
            Role::Time => self.time_s(),
            Role::CylinderPressure(j) => self.p_cyl_pa[j],
            Role::ClampForce(j) => self.f_clamp_n[j],
            Role::ServiceDeceleration => self.service_deceleration_mps2,
            Role::Key(i) => match key_value(&mut self.file, i, |_, v| match v {
                KeyValue::Real(x) => Some(*x),
                _ => None,
            }) {
                Some(Some(x)) => x,
                _ => return mismatch(v, "Float64"),
            },
            Role::Record(channel, j) if v.kind == Kind::Float64 => {
                let r = self.record()?;
                if channel == V_REF_EST && self.drive != Drive::BrakeUnit {
                    0.0
                } else {
                    r.value(channel, j).unwrap_or(0.0)
                }
            }
            _ => return mismatch(v, "Float64"),
        })
    }

    /// `fmi3SetFloat64` of one variable.
    pub fn set_f64(&mut self, v: &Variable, x: f64) -> Outcome {
        self.check_settable(v)?;
        let input = |what: &str| -> Result<f64, Fault> {
            if x.is_finite() {
                Ok(x)
            } else {
                fault(format!(
                    "input {} = {x} refused: {what} must be finite (the last valid value stays)",
                    v.name
                ))
            }
        };
        match v.role {
            Role::CylinderPressure(j) => self.p_cyl_pa[j] = input("a cylinder pressure")?,
            Role::ClampForce(j) => self.f_clamp_n[j] = input("a clamp force")?,
            Role::ServiceDeceleration => {
                let a = input("a deceleration")?;
                if a < 0.0 {
                    return fault(format!(
                        "input {} = {a} refused: a deceleration is not negative",
                        v.name
                    ));
                }
                self.service_deceleration_mps2 = a;
            }
            Role::Key(i) => {
                match key_value(&mut self.file, i, |info, value| match value {
                    KeyValue::Real(slot) => {
                        info.check(x).map_err(|e| Fault(e.to_string()))?;
                        *slot = x;
                        Ok(true)
                    }
                    _ => Ok(false),
                }) {
                    Some(Ok(true)) => self.parameters_changed(),
                    Some(Err(e)) => return Err(e),
                    _ => return mismatch(v, "Float64"),
                }
            }
            _ => return mismatch(v, "Float64"),
        }
        Ok(Status::Ok)
    }

    /// `fmi3GetUInt32` of one variable.
    pub fn get_u32(&mut self, v: &Variable) -> Result<u32, Fault> {
        self.check_readable(v)?;
        match v.role {
            Role::Flags => {
                if self.sim.is_none() {
                    self.ensure_sim()?;
                }
                Ok(self.flags)
            }
            Role::Key(i) => match key_value(&mut self.file, i, |_, v| match v {
                KeyValue::Count(n) => Some(*n),
                _ => None,
            }) {
                Some(Some(n)) => Ok(n),
                _ => mismatch(v, "UInt32"),
            },
            _ => mismatch(v, "UInt32"),
        }
    }

    /// `fmi3SetUInt32` of one variable.
    pub fn set_u32(&mut self, v: &Variable, n: u32) -> Outcome {
        self.check_settable(v)?;
        let Role::Key(i) = v.role else {
            return mismatch(v, "UInt32");
        };
        match key_value(&mut self.file, i, |info, value| match value {
            KeyValue::Count(slot) => {
                info.check(f64::from(n)).map_err(|e| Fault(e.to_string()))?;
                *slot = n;
                Ok(true)
            }
            _ => Ok(false),
        }) {
            Some(Ok(true)) => {
                self.parameters_changed();
                Ok(Status::Ok)
            }
            Some(Err(e)) => Err(e),
            _ => mismatch(v, "UInt32"),
        }
    }

    /// `fmi3GetBoolean` of one variable.
    pub fn get_bool(&mut self, v: &Variable) -> Result<bool, Fault> {
        self.check_readable(v)?;
        match v.role {
            Role::Record(_, j) if v.kind == Kind::Boolean => {
                let r = self.record()?;
                Ok(r.wsp.get(j).copied().unwrap_or(false))
            }
            Role::Key(i) => match key_value(&mut self.file, i, |_, v| match v {
                KeyValue::Flag(b) => Some(*b),
                _ => None,
            }) {
                Some(Some(b)) => Ok(b),
                _ => mismatch(v, "Boolean"),
            },
            _ => mismatch(v, "Boolean"),
        }
    }

    /// `fmi3SetBoolean` of one variable.
    pub fn set_bool(&mut self, v: &Variable, b: bool) -> Outcome {
        self.check_settable(v)?;
        let Role::Key(i) = v.role else {
            return mismatch(v, "Boolean");
        };
        match key_value(&mut self.file, i, |_, value| match value {
            KeyValue::Flag(slot) => {
                *slot = b;
                true
            }
            _ => false,
        }) {
            Some(true) => {
                self.parameters_changed();
                Ok(Status::Ok)
            }
            _ => mismatch(v, "Boolean"),
        }
    }

    /// `fmi3GetInt64` of one variable (enumerations).
    pub fn get_i64(&mut self, v: &Variable) -> Result<i64, Fault> {
        self.check_readable(v)?;
        match v.role {
            Role::BrakeInput => Ok(Drive::ALL
                .iter()
                .position(|d| *d == self.drive)
                .unwrap_or(0) as i64),
            Role::Command => Ok(i64::from(u8::from(self.cmd))),
            Role::Key(i) => match key_value(&mut self.file, i, |_, v| match v {
                KeyValue::Choice(c) => Some(c.index() as i64),
                _ => None,
            }) {
                Some(Some(x)) => Ok(x),
                _ => mismatch(v, "Enumeration"),
            },
            _ => mismatch(v, "Enumeration"),
        }
    }

    /// `fmi3SetInt64` of one variable (enumerations: the item's value).
    pub fn set_i64(&mut self, v: &Variable, x: i64) -> Outcome {
        self.check_settable(v)?;
        let Kind::Enumeration(t) = v.kind else {
            return mismatch(v, "Enumeration");
        };
        let index = usize::try_from(x).ok().filter(|&i| i < t.items.len());
        let Some(index) = index else {
            let items: Vec<String> = t
                .items
                .iter()
                .enumerate()
                .map(|(i, (n, _))| format!("{i} = {n}"))
                .collect();
            return fault(format!(
                "{} = {x} refused: not an item of {} ({})",
                v.name,
                t.name,
                items.join(", ")
            ));
        };
        match v.role {
            Role::BrakeInput => {
                self.drive = Drive::ALL[index];
                self.parameters_changed();
            }
            Role::Command => {
                self.cmd = Cmd::try_from(index as u8).unwrap_or(Cmd::Release);
                self.record = None;
            }
            Role::Key(i) => {
                match key_value(&mut self.file, i, |_, value| match value {
                    KeyValue::Choice(c) => c.select(index),
                    _ => false,
                }) {
                    Some(true) => self.parameters_changed(),
                    _ => return mismatch(v, "Enumeration"),
                }
            }
            _ => return mismatch(v, "Enumeration"),
        }
        Ok(Status::Ok)
    }

    /// `fmi3GetString` of one variable.
    pub fn get_string(&mut self, v: &Variable) -> Result<String, Fault> {
        self.check_readable(v)?;
        match v.role {
            Role::ParamsFile => Ok(self.params_file.clone()),
            Role::Key(i) if v.kind == Kind::String => {
                Ok(self.notes.get(&i).cloned().unwrap_or_default())
            }
            _ => mismatch(v, "String"),
        }
    }

    /// `fmi3SetString` of one variable: `params_file` loads the file (every key takes its
    /// value; an empty name: the resource's defaults).
    pub fn set_string(&mut self, v: &Variable, s: &str) -> Result<(Status, Option<String>), Fault> {
        self.check_settable(v)?;
        match v.role {
            Role::ParamsFile => {
                let (file, note) = if s.is_empty() {
                    (
                        self.defaults,
                        "the FMU's resources/parameters.toml".to_string(),
                    )
                } else {
                    let path = s.strip_prefix("file://").unwrap_or(s);
                    (
                        crate::load_params(Path::new(path))?,
                        format!("parameter file {path}"),
                    )
                };
                self.file = file;
                self.params_file = s.to_string();
                self.parameters_changed();
                Ok((Status::Ok, Some(format!("parameters loaded from {note}"))))
            }
            Role::Key(i) if v.kind == Kind::String => {
                self.notes.insert(i, s.to_string());
                Ok((Status::Ok, None))
            }
            _ => mismatch(v, "String"),
        }
    }
}

/// A time shown to the nanosecond (no binary noise such as 0.00030000000000000003), s.
fn to_ns(t_s: f64) -> f64 {
    (t_s * 1e9).round() / 1e9
}

/// The number of plant steps of a communication step `h_s` (a whole multiple of `dt`).
fn steps_of(h_s: f64, dt: f64) -> Result<u64, Fault> {
    let ratio = h_s / dt;
    let n = ratio.round();
    if !(h_s > 0.0) || !ratio.is_finite() {
        return fault(format!(
            "communicationStepSize = {h_s} s refused: must be positive and finite (a multiple of the plant step {dt} s)"
        ));
    }
    if n < 1.0 || (ratio - n).abs() > STEP_TOLERANCE_STEPS {
        let ns = |k: f64| to_ns(k * dt);
        let nearest = if ratio < 1.0 {
            format!("the smallest multiple is {} s", ns(1.0))
        } else {
            let below = ratio.floor();
            format!(
                "the nearest multiples are {} s and {} s",
                ns(below),
                ns(below + 1.0)
            )
        };
        return fault(format!(
            "communicationStepSize = {h_s} s refused: not a multiple of the plant's fixed step {dt} s (scenario.paper_eb.step); {nearest}"
        ));
    }
    if n > MAX_STEPS_PER_CALL {
        return fault(format!(
            "communicationStepSize = {h_s} s refused: more than {MAX_STEPS_PER_CALL} plant steps in one call"
        ));
    }
    Ok(n as u64)
}

/// A finite input in the plant's f32: saturated at f32's largest magnitude (a plain `as`
/// turns 1e300 into an infinity, which the plant would hold as a non-finite input instead
/// of clamping it to its physical range as any other too large value).
fn to_f32(x: f64) -> f32 {
    x.clamp(-f64::from(f32::MAX), f64::from(f32::MAX)) as f32
}

/// `n` plant steps with the brake inputs held; the flags or-ed.
fn step_plant(sim: &mut ClosedLoop<f32>, n: u64, inputs: &[BrakeInput<f32>; WHEELSETS]) -> u32 {
    let mut flags = 0;
    for _ in 0..n {
        flags |= sim.plant.step(inputs).0;
    }
    flags
}

/// The warning of newly raised plant flags.
fn flag_message(flags: u32, t_s: f64) -> String {
    let wheelsets = |group: u32| -> String {
        (0..WHEELSETS)
            .filter(|&j| flags & Flags::wheelset_bit(group, j) != 0)
            .map(|j| (j + 1).to_string())
            .collect::<Vec<_>>()
            .join(", ")
    };
    let mut parts = Vec::new();
    if flags & Flags::INPUT_OUT_OF_RANGE != 0 {
        parts.push(format!(
            "brake input out of the physical range on wheelset {}: clamped by the plant",
            wheelsets(Flags::INPUT_OUT_OF_RANGE)
        ));
    }
    if flags & Flags::INPUT_NOT_FINITE != 0 {
        parts.push(format!(
            "brake input not finite on wheelset {}: the last valid value held",
            wheelsets(Flags::INPUT_NOT_FINITE)
        ));
    }
    if flags & Flags::NUMERIC_FAULT != 0 {
        parts.push("numeric fault: the plant was put at rest (safe state)".to_string());
    }
    format!(
        "step to t = {} s: {} (plant_flags 0x{flags:04x})",
        to_ns(t_s),
        parts.join("; ")
    )
}

fn mismatch<T>(v: &Variable, asked: &str) -> Result<T, Fault> {
    let kind = match v.kind {
        Kind::Float64 => "Float64",
        Kind::UInt32 => "UInt32",
        Kind::Boolean => "Boolean",
        Kind::String => "String",
        Kind::Enumeration(_) => "Enumeration (Int64)",
    };
    fault(format!(
        "{} (value reference {}) is a {kind} variable, not {asked}",
        v.name, v.vr
    ))
}

/// Calls `f` with key `index` of `file` (in [`Keys`] order); `None` when there is no such
/// key.
fn key_value<R>(
    file: &mut ParamFile,
    index: usize,
    f: impl FnOnce(&KeyInfo, KeyValue<'_>) -> R,
) -> Option<R> {
    struct At<F, R> {
        index: usize,
        at: usize,
        f: Option<F>,
        out: Option<R>,
    }
    impl<F: FnOnce(&KeyInfo, KeyValue<'_>) -> R, R> KeyVisitor for At<F, R> {
        fn key(&mut self, info: &KeyInfo, value: KeyValue<'_>) {
            if self.at == self.index
                && let Some(f) = self.f.take()
            {
                self.out = Some(f(info, value));
            }
            self.at += 1;
        }
    }
    let mut at = At {
        index,
        at: 0,
        f: Some(f),
        out: None,
    };
    file.visit_keys(&mut at);
    at.out
}

/// The variable of a value reference, or the refusal naming it.
pub fn variable(vr: u32) -> Result<&'static Variable, Fault> {
    variables::by_vr(vr).map_or_else(
        || {
            fault(format!(
                "value reference {vr} is not a variable of this FMU"
            ))
        },
        Ok,
    )
}
