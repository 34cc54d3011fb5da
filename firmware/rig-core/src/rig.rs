//! The real-time step of the rig interface board and its run state machine.
//!
//! [`Rig::step`] runs once per 0.1 ms tick, in the highest-priority interrupt:
//!
//! 1. read this tick's ADC sequence (converted at a fixed phase of the previous period)
//!    and update the four [`SensorChannel`]s;
//! 2. while running, step the plant: in [`RigMode::Rig`] with the measured brake inputs
//!    (load cell -> `BrakeInput::ClampForce`, pressure -> `BrakeInput::CylinderPressure`),
//!    in [`RigMode::SelfTest`] closed with the simulated brake unit
//!    (`hils_sil::ClosedLoop<f32>`);
//! 3. write the outputs: four pulse trains, and on schedule the CAN frames (wheel speeds,
//!    two frames of two wheelsets, every 10 ticks = 1 ms, status every 100 = 10 ms, diagnostics every 1000 = 100 ms:
//!    [`WHEEL_SPEED_SCHEDULE`], [`STATUS_SCHEDULE`], [`DIAG_SCHEDULE`]);
//! 4. every `divider` plant steps, a telemetry record.
//!
//! The board times each call with the DWT cycle counter and reports it with
//! [`Rig::record_timing`]; overruns and missed ticks are counted and flagged.
//!
//! # Safe state
//!
//! Outside a run, and in the states `Stopped` and `Fault`, the outputs are in the safe
//! state: every pulse train silent (pin low) and every wheel speed "not available"
//! (raw 0xFFFF) in `RIG_WHEEL_SPEED_12`/`_34`; the status frame keeps coming with the state and
//! the fault flags. A brake controller sees a lost speed signal, the condition its own
//! sensor supervision is built for, rather than a plausible but false speed. After a run
//! ends at standstill (`Finished`), the speeds are sent as 0.00 km/h and the trains are
//! silent (the wheels are at rest).
//!
//! A run goes to `Fault` (and so to the safe state), and the plant is no longer stepped,
//! when during a run:
//! * in rig mode, a sensor channel latches a fault (open, short, out of range, stuck, ADC
//!   invalid: see [`crate::sensor`]);
//! * in rig mode, no fresh ADC sequence arrives for [`ADC_STALE_TICKS`] ticks (1 ms);
//! * the plant reports a numeric fault (non-finite state; it has put itself at rest).
//!
//! In self-test mode the sensors close no loop: their faults are reported, nothing stops.
//! Overruns, missed ticks, dropped frames or telemetry, CAN error passive and bus-off are
//! flagged and counted but do not stop a run (the rig operator decides from the flags).
//! `ClearFaults` clears latched faults whose cause is gone and takes `Fault` to `Stopped`.
//!
//! # Arming
//!
//! The outputs a real controller reads (pulse trains, wheel speeds, the controller I/O) are
//! live only when the arming gate says so ([`crate::arming`], [`Rig::controller_outputs_live`]):
//! armed by the `Arm` command, in a rig-mode run started armed (arming alone makes nothing
//! live). A rig-mode `Start` is refused while the rig
//! is not armed ([`CommandError::NotArmed`]); `Stop`, `Fault`, a latched fault, a self-test
//! start, `Disarm` and every reset disarm it. A self-test run (the button, `selftest-autostart`,
//! a self-test `Start`) never drives these outputs: its speeds are in the telemetry and the
//! status frame only.

use embedded_can::Frame;
use hils_brake_unit::BrakeDemand;
use hils_plant::track::{ContactSets, MAX_ZONES, TrackError};
use hils_plant::{
    BrakeInput, DegradedAdhesionParams, Flags, FrictionModel, Outputs, Params, Plant, Rail, STEP_S,
    Surface, TrackAdhesion,
};
use hils_sil::scenario::at_standstill;
use hils_sil::{ClosedLoop, LoopError};

use crate::Code;
use crate::arming::{ArmRefused, ArmingGate, Disarm};
use crate::can::{
    BrakeCommand, BrakeDemandFrame, Calibration, Command, CommandFrame, CommandResult, ConfigItem,
    DecodeError, DiagFrame, HealthFrame, RigMode, RigState, StartCommand, StatusFrame,
    TrackCommand, WHEEL_SPEED_MAX_KMH, WheelSpeedFrame, ZoneFrame, friction_code, rail_code,
    surface_code,
};
use crate::controller_io::{DrivenOutputs, IoConfig, IoConfigError, IoItem};
use crate::digest::setup_digest;
use crate::hw::{RigIo, TelemetryEvent};
use crate::pulse::{PulseRegisters, PulseTimer, wheel_frequency_hz};
use crate::sensor::{CalibrationError, SensorChannel, SensorFault, SensorKind, split_sequence};
use crate::setup::{TrackFrames, VehicleValues};
use crate::telemetry::{RunHeader, TelemetryRecord};
use crate::timing::{StepTiming, cycles_to_us};
use crate::valves::{ValveInputs, ValveStates};
use crate::{CHANNELS, KMH_PER_MPS, STEP_RATE_HZ, WHEELSETS};

/// A frame schedule in ticks: sent when `tick % period == phase`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Schedule {
    /// Period, ticks.
    pub period: u32,
    /// Phase within the period, ticks (spreads the frames over the ticks).
    pub phase: u32,
}

impl Schedule {
    /// Whether a frame is due at `tick`.
    pub fn due(self, tick: u32) -> bool {
        tick % self.period == self.phase
    }
}

/// `RIG_WHEEL_SPEED_12` and `RIG_WHEEL_SPEED_34` every 10 ticks (1 ms).
pub const WHEEL_SPEED_SCHEDULE: Schedule = Schedule {
    period: 10,
    phase: 0,
};
/// `RIG_STATUS` every 100 ticks (10 ms), 5 ticks after a wheel-speed frame.
pub const STATUS_SCHEDULE: Schedule = Schedule {
    period: 100,
    phase: 5,
};
/// `RIG_DIAG` every 1000 ticks (100 ms).
pub const DIAG_SCHEDULE: Schedule = Schedule {
    period: 1000,
    phase: 50,
};
/// `RIG_HEALTH` every 1000 ticks (100 ms), half a period after `RIG_DIAG`.
pub const HEALTH_SCHEDULE: Schedule = Schedule {
    period: 1000,
    phase: 550,
};
/// `RIG_BRAKE_DEMAND` (when configured) every 100 ticks (10 ms), and in the tick the demand
/// changes.
pub const DEMAND_SCHEDULE: Schedule = Schedule {
    period: 100,
    phase: 2,
};
/// Ticks without a fresh ADC sequence after which a rig-mode run faults (1 ms).
pub const ADC_STALE_TICKS: u32 = 10;

/// Step times since the last `RIG_DIAG` frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct DiagWindow {
    max_cycles: u32,
    sum_cycles: u64,
    steps: u32,
}

bitflags::bitflags! {
    /// Fault flags (bit set). The low 16 bits go into `RIG_STATUS`; all 32 into telemetry.
    /// `intersects(mask)`: whether any bit of `mask` is set.
    #[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
    pub struct Faults: u32 {
        /// Bits 0-3: sensor channel 1-4 has a latched fault.
        const SENSOR = 0x000F;
        /// A step overran its period (sticky until cleared).
        const OVERRUN = 0x0010;
        /// The CAN controller is error passive now.
        const CAN_ERROR_PASSIVE = 0x0020;
        /// The CAN controller is or was bus-off since faults were cleared.
        const CAN_BUS_OFF = 0x0040;
        /// A plant brake input was clamped or not finite (plant flags).
        const PLANT_INPUT = 0x0080;
        /// The plant's state became non-finite; it put itself at rest.
        const PLANT_NUMERIC = 0x0100;
        /// A wheel speed was above the frame's 655.34 km/h and was sent saturated.
        const SPEED_SATURATED = 0x0200;
        /// A command was rejected (sticky until cleared; the last result is in the status frame).
        const COMMAND_REJECTED = 0x0400;
        /// A telemetry event was dropped (logging queue full).
        const TELEMETRY_DROPPED = 0x0800;
        /// A fault injection is active on some channel.
        const FAULT_INJECTED = 0x1000;
        /// No fresh ADC sequence for at least one tick (sticky); latches the run in rig mode
        /// after 10 ticks.
        const ADC_STALE = 0x2000;
        /// A CAN frame was dropped (transmit queue full).
        const CAN_TX_DROPPED = 0x4000;
        /// Ticks were lost (sticky): the simulated time lags the wall clock.
        const MISSED_TICKS = 0x8000;
        /// Bits 16-19 (telemetry only): sensor channel 1-4 has a pending (not yet latched) condition.
        const SENSOR_PENDING = 0x000F_0000;
    }
}

/// The board's own health as its tasks measured it, for `RIG_HEALTH`
/// ([`Rig::set_board_health`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct BoardHealth {
    /// Stack high-water mark since power-up, bytes.
    pub stack_peak_bytes: u32,
    /// The stack's size, bytes.
    pub stack_size_bytes: u32,
    /// Command frames lost in reception since power-up: a lower bound (FDCAN RF0L is a
    /// flag; losses before the interrupt clears it count once).
    pub rx_lost: u32,
    /// ADC ring restarts since power-up.
    pub adc_restarts: u32,
    /// Consecutive fault resets before this start.
    pub fault_resets: u32,
}

/// Configuration of the rig.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RigConfig {
    /// CPU (DWT) clock, Hz.
    pub cpu_hz: u32,
    /// Pulse timers' counter clock, Hz.
    pub pulse_timer: PulseTimer,
    /// Teeth of the simulated speed-sensor wheel.
    pub teeth: u16,
    /// Telemetry every this many plant steps.
    pub telemetry_divider: u16,
    /// The controller I/O: valve inputs wired, demand and load signals.
    pub io: IoConfig,
}

impl RigConfig {
    /// NUCLEO-G474RE at 170 MHz, 16-bit pulse timers (the demand PWM's too) at 170 MHz, 90
    /// teeth, 100 Hz telemetry, no valve input wired, the default demand and load signals.
    pub const fn nucleo_g474re() -> Self {
        Self {
            cpu_hz: 170_000_000,
            pulse_timer: PulseTimer::timer16(170_000_000),
            teeth: 90,
            telemetry_divider: 100,
            io: IoConfig::DEFAULT,
        }
    }
}

/// Why a command was not carried out.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CommandError {
    /// The frame did not decode.
    Frame(DecodeError),
    /// Same alive counter as the last command: a repeated frame, ignored.
    Repeated,
    /// Not allowed in this state (e.g. calibration during a run).
    NotNow(RigState),
    /// Initial speed above what the wheel-speed frame carries (655.34 km/h) or negative.
    SpeedOutOfRange,
    /// A rig-mode start with latched sensor faults (clear them first).
    SensorFaults,
    /// The plant or brake unit refused the parameters.
    Build(LoopError),
    /// A `Start` on the kept track, but no track is kept (commit one first).
    NoTrack,
    /// A track commit whose zone `index` (0-based) was not received since the last commit
    /// or clear.
    TrackIncomplete {
        /// The first missing zone index.
        index: u8,
    },
    /// A track zone or commit refused: zone index or count above 16, a zone empty, out of
    /// order or overlapping ([`TrackError`]).
    Track(TrackError),
    /// A build came back for a start request that is no longer pending (stopped, or
    /// superseded by a later `Start`): not installed, counted ([`Rig::stale_builds`]).
    StaleBuild {
        /// [`StartRequest::seq`] of the request it was built for.
        seq: u32,
    },
    /// The calibration command was refused.
    Calibration(CalibrationError),
    /// A controller I/O configuration value that would make the configuration
    /// inconsistent ([`IoConfig::set`]).
    IoConfig(IoConfigError),
    /// A `Start` whose `StartDigest` differs from the digest of the track and vehicle the
    /// board keeps ([`crate::digest::setup_digest`]): a `Track` or `Vehicle` frame the
    /// sender sent did not arrive. Nothing changes; the sender resends the setup.
    SetupMismatch {
        /// The digest of the board's setup.
        kept: u16,
    },
    /// A rig-mode `Start` while the rig is not armed for a controller (send `Arm` first).
    NotArmed,
    /// The `Arm` command was refused.
    Arm(ArmRefused),
}

/// The simulation of a run.
#[derive(Clone, Debug)]
#[allow(clippy::large_enum_variant)]
enum Sim {
    None,
    Rig(Plant<f32>),
    SelfTest(ClosedLoop<f32>),
}

/// The parameters of a requested run: checked by the step (the `Start` command), built
/// outside it ([`StartRequest::build`], thread mode on the board).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StartRequest {
    /// Which `Start` this is (counts the rig's start requests, wrapping): the build comes
    /// back with it ([`Built::seq`]) and is installed only under the same request.
    pub seq: u32,
    /// Self-test or rig mode.
    pub mode: RigMode,
    /// Rail condition.
    pub rail: Rail,
    /// Disc-pad friction law.
    pub friction: FrictionModel,
    /// The simulated brake unit gets the EB command at t = 0.
    pub emergency: bool,
    /// Initial speed, km/h.
    pub initial_speed_kmh: f32,
    /// The run's track (`None`: `rail` everywhere), copied from the rig's kept track.
    pub track: Option<TrackFrames>,
    /// The run's vehicle: the default one with the values set by `Vehicle` commands.
    pub vehicle: VehicleValues,
}

/// The simulation of a run, built by [`StartRequest::build`] outside the step.
#[derive(Clone, Debug)]
pub struct Simulation(Sim);

impl Simulation {
    /// No run.
    pub const fn none() -> Self {
        Self(Sim::None)
    }
}

/// The simulation in `store`, or none while it is lent (a function of the fields, so that
/// the rig's other fields stay free to borrow).
fn sim_in<S: SimStore>(store: &S, lent: bool) -> Option<&Sim> {
    (!lent).then(|| &store.sim().0)
}

/// Where the rig keeps the simulation of its run: in the rig itself ([`Simulation`], for
/// hosts: [`Rig::install`] moves a build in), or in storage outside it that the builder
/// fills in place while the rig has lent it (the board: no 6 KiB move in the step,
/// [`Rig::install_in_place`]). The rig touches its store only while it has not lent it:
/// from [`Rig::take_start_request`] until the build for that request comes back
/// (`install`/`install_in_place`/`retry_start_request`), the builder owns it.
pub trait SimStore {
    /// The simulation in the store (the rig calls this only while it has not lent it).
    fn sim(&self) -> &Simulation;
    /// As [`SimStore::sim`], to step or replace it.
    fn sim_mut(&mut self) -> &mut Simulation;
}

impl SimStore for Simulation {
    fn sim(&self) -> &Simulation {
        self
    }
    fn sim_mut(&mut self) -> &mut Simulation {
        self
    }
}

/// What the builder hands back for a request: the request's sequence number and the
/// simulation, `T = Simulation` (or `()` when it was built in the rig's store), or why it
/// could not be built.
#[derive(Clone, Debug)]
pub struct Built<T = Simulation> {
    /// [`StartRequest::seq`] of the request this was built for.
    pub seq: u32,
    /// The simulation (or `()`: built in the rig's store), or why the build failed.
    pub result: Result<T, CommandError>,
}

impl StartRequest {
    /// Builds the run's simulation (plant, and in self-test mode the simulated brake unit):
    /// ~35 000 instructions of mostly soft-float f64 and a large stack frame, so never in
    /// the step (issue 11).
    pub fn build(&self) -> Built {
        Built {
            seq: self.seq,
            result: self.build_simulation(),
        }
    }

    /// Builds the run's simulation into `store` (the board's builder, in thread mode, into
    /// the store the rig lent it) and says how it went, for [`Rig::install_in_place`].
    pub fn build_into(&self, store: &mut Simulation) -> Built<()> {
        let result = match self.build_simulation() {
            Ok(sim) => {
                *store = sim;
                Ok(())
            }
            Err(e) => {
                *store = Simulation::none();
                Err(e)
            }
        };
        Built {
            seq: self.seq,
            result,
        }
    }

    /// The simulation of this request (plant, and in self-test mode the brake unit).
    pub fn build_simulation(&self) -> Result<Simulation, CommandError> {
        let mut params = Params::default();
        params.friction.model = self.friction;
        params.vehicle = self.vehicle.vehicle();
        let v0 = self.initial_speed_kmh / KMH_PER_MPS;
        let params_error = |e| CommandError::Build(LoopError::Params(e));
        let adhesion = match self.track {
            Some(frames) => Some(
                TrackAdhesion::<f32>::new(
                    &params.contact,
                    &ContactSets::default(),
                    frames.track().map_err(CommandError::Track)?,
                    &DegradedAdhesionParams::default(),
                    STEP_S,
                )
                .map_err(params_error)?,
            ),
            None => None,
        };
        let sim = match self.mode {
            RigMode::Rig => {
                let mut plant = Plant::new(&params, self.rail, v0).map_err(params_error)?;
                if let Some(a) = adhesion {
                    plant.set_track(a);
                }
                Sim::Rig(plant)
            }
            RigMode::SelfTest => {
                let mut c = ClosedLoop::new(&params, self.rail, v0).map_err(CommandError::Build)?;
                if let Some(a) = adhesion {
                    c.plant.set_track(a);
                }
                c.set_demand(if self.emergency {
                    BrakeDemand::Emergency
                } else {
                    BrakeDemand::Release
                });
                Sim::SelfTest(c)
            }
        };
        Ok(Simulation(sim))
    }
}

/// The rig: sensors, simulation, outputs, telemetry and state. `S`: where it keeps the
/// simulation ([`SimStore`]).
pub struct Rig<S: SimStore = Simulation> {
    config: RigConfig,
    /// The four brake-input channels (ADC, calibration, plausibility).
    pub sensors: [SensorChannel; CHANNELS],
    sim: S,
    /// The store is lent to the builder (a request was handed out, no build came back).
    sim_lent: bool,
    state: RigState,
    mode: RigMode,
    rail: Rail,
    friction: FrictionModel,
    initial_speed_kmh: f32,
    brake: Option<BrakeCommand>,
    timing: StepTiming,
    /// Ticks since power-up (schedules the frames).
    tick: u32,
    /// Plant steps of the run.
    run_steps: u32,
    sticky: Faults,
    bus_flags: Faults,
    /// Bus-off events since power-up (saturates at 255; `RIG_DIAG` carries up to 15).
    pub bus_off_count: u8,
    last_command_counter: Option<u8>,
    last_result: CommandResult,
    stale_ticks: u32,
    /// `ClearFaults` asked the bus supervision to clear its sticky bus-off (board).
    bus_clear_requested: bool,
    /// Alive counters: wheel speeds, status, health, brake demand.
    counters: [u8; 4],
    diag_window: DiagWindow,
    /// The valve inputs (debounced each tick).
    valves: ValveInputs,
    /// The controller outputs as last driven.
    driven: DrivenOutputs,
    /// The service-demand PWM's prescaler and period for the configuration in force
    /// (`DemandConfig::pwm_period`: set at construction and by `Configure`, not per tick).
    pwm_period: PulseRegisters,
    wheel_speed_kmh: [Option<f32>; WHEELSETS],
    pulses: [PulseRegisters; WHEELSETS],
    /// Sensor channels with a condition present but not latched (this tick).
    pending: [bool; CHANNELS],
    /// A run started: header and t = 0 record due at the next tick.
    start_events: bool,
    /// A run ended: final record and end line due.
    end_event: bool,
    /// Plant step of the last telemetry record of the run (no record twice for a step).
    last_record_step: Option<u32>,
    /// Sequence number of the run's next telemetry record (sent or dropped).
    record_seq: u32,
    /// The run requested, while `Starting`.
    start_request: Option<StartRequest>,
    /// The request has not been handed to the builder yet.
    start_request_new: bool,
    /// The state before `Starting` (back to it if the build fails).
    state_before_start: RigState,
    /// Sequence number of the last start request.
    start_seq: u32,
    /// Builds that came back for a request no longer pending (not installed).
    stale_builds: u32,
    /// The track and vehicle kept for the following runs.
    setup: KeptSetup,
    /// Whether the outputs a controller reads are live ([`crate::arming`]).
    arming: ArmingGate,
    /// The board's own health (`RIG_HEALTH`).
    health: BoardHealth,
}

/// What the board keeps for the following runs from `TrackZone`, `Track` and `Vehicle`
/// commands: the zones received since the last commit or clear, the committed track and the
/// vehicle values. The rig holds one; the host replays the frames it sent through one to
/// stamp a `Start` with the digest the board will compute ([`KeptSetup::digest`]).
#[derive(Clone, Copy, Debug, Default)]
pub struct KeptSetup {
    /// Track zones received since the last commit or clear, and which (bit i: zone i).
    zones: [ZoneFrame; MAX_ZONES],
    zones_received: u16,
    /// The track committed (`Start` with `track` runs on it).
    track: Option<TrackFrames>,
    /// The vehicle of the following runs.
    vehicle: VehicleValues,
}

impl KeptSetup {
    /// The track kept by the last commit (None: cleared or never committed).
    pub fn track(&self) -> Option<&TrackFrames> {
        self.track.as_ref()
    }

    /// The vehicle values of the following runs.
    pub fn vehicle(&self) -> &VehicleValues {
        &self.vehicle
    }

    /// The setup digest of a run on the kept vehicle, on the kept track when `track`.
    pub fn digest(&self, track: bool) -> u16 {
        setup_digest(self.track.as_ref().filter(|_| track), &self.vehicle)
    }

    /// Carries out a `TrackZone`, `Track` or `Vehicle` command (others change nothing).
    pub fn apply(&mut self, command: &Command) -> Result<(), CommandError> {
        match *command {
            Command::TrackZone { index, zone } => self.track_zone(index, zone),
            Command::Track(t) => self.track_command(t),
            Command::Vehicle { key, value } => {
                self.vehicle.set(key, value);
                Ok(())
            }
            _ => Ok(()),
        }
    }

    /// `TrackZone`: keeps zone `index` for the next commit.
    fn track_zone(&mut self, index: u8, zone: ZoneFrame) -> Result<(), CommandError> {
        let slot = self
            .zones
            .get_mut(index as usize)
            .ok_or(CommandError::Track(TrackError::TooManyZones))?;
        *slot = zone;
        self.zones_received |= 1 << index;
        Ok(())
    }

    /// `Track`: commit checks the zones received (all of 0..n, ordered, disjoint, not
    /// empty) and keeps the track; clear forgets it. A refused commit keeps the last track;
    /// every commit, refused or not, forgets the zones received, so a later commit cannot
    /// pick up a refused attempt's zones.
    fn track_command(&mut self, command: TrackCommand) -> Result<(), CommandError> {
        let received = core::mem::take(&mut self.zones_received);
        let TrackCommand::Commit { base, zones } = command else {
            self.track = None;
            return Ok(());
        };
        let n = zones as usize;
        if n > MAX_ZONES {
            return Err(CommandError::Track(TrackError::TooManyZones));
        }
        if let Some(index) = (0..n).find(|&i| received & (1 << i) == 0) {
            return Err(CommandError::TrackIncomplete { index: index as u8 });
        }
        let track = TrackFrames::new(base, &self.zones[..n]).map_err(CommandError::Track)?;
        self.track = Some(track);
        Ok(())
    }
}

impl Rig<Simulation> {
    /// A rig that keeps the simulation in itself.
    pub fn new(config: RigConfig) -> Self {
        Self::with_store(config, Simulation::none())
    }

    /// Installs a built simulation (a move) and starts the run, if it was built for the
    /// pending request: [`Rig::install_in_place`] after moving it into the rig.
    pub fn install(&mut self, built: Built) -> Result<(), CommandError> {
        let result = match built.result {
            Ok(sim) if self.sim_lent => {
                *self.sim.sim_mut() = sim;
                Ok(())
            }
            Ok(_) => Ok(()),
            Err(e) => Err(e),
        };
        self.install_in_place(Built {
            seq: built.seq,
            result,
        })
    }

    /// Builds a requested run here and installs it: for hosts (tests, the scripted run,
    /// the QEMU cost measurement), where the build does not count against a step. The
    /// board builds in thread mode instead. `Ok` when nothing was requested.
    pub fn build_pending(&mut self) -> Result<(), CommandError> {
        match self.take_start_request() {
            Some(req) => self.install(req.build()),
            None => Ok(()),
        }
    }
}

impl<S: SimStore> Rig<S> {
    /// A rig that keeps the simulation in `store`, empty (`Simulation::none()`) at first.
    pub fn with_store(config: RigConfig, store: S) -> Self {
        let silent = config.pulse_timer.silent();
        Self {
            config,
            sensors: [SensorChannel::new(SensorKind::LoadCell); CHANNELS],
            sim: store,
            sim_lent: false,
            state: RigState::Idle,
            mode: RigMode::Rig,
            rail: Rail::Wet,
            friction: FrictionModel::Variable,
            initial_speed_kmh: 0.0,
            brake: None,
            timing: StepTiming::new(config.cpu_hz, STEP_RATE_HZ),
            tick: 0,
            run_steps: 0,
            sticky: Faults::empty(),
            bus_flags: Faults::empty(),
            bus_off_count: 0,
            last_command_counter: None,
            last_result: CommandResult::None,
            stale_ticks: 0,
            bus_clear_requested: false,
            counters: [0; 4],
            diag_window: DiagWindow::default(),
            valves: ValveInputs::new(config.io.valves),
            driven: DrivenOutputs::safe(&config.pulse_timer),
            pwm_period: config.io.demand.pwm_period(&config.pulse_timer),
            wheel_speed_kmh: [None; WHEELSETS],
            pulses: [silent; WHEELSETS],
            pending: [false; CHANNELS],
            start_events: false,
            end_event: false,
            last_record_step: None,
            record_seq: 0,
            start_request: None,
            start_request_new: false,
            state_before_start: RigState::Idle,
            start_seq: 0,
            stale_builds: 0,
            setup: KeptSetup::default(),
            arming: ArmingGate::new(),
            health: BoardHealth::default(),
        }
    }

    /// The track kept by the last commit (None: cleared or never committed).
    pub fn track(&self) -> Option<&TrackFrames> {
        self.setup.track()
    }

    /// The vehicle values of the following runs.
    pub fn vehicle(&self) -> &VehicleValues {
        self.setup.vehicle()
    }

    /// The setup digest of a run on the kept vehicle, on the kept track when `track`.
    pub fn kept_setup_digest(&self, track: bool) -> u16 {
        self.setup.digest(track)
    }

    /// `command` with, if it is a `Start`, the digest of the kept setup: for starts made
    /// on the board (user button), which run on whatever the board keeps.
    pub fn on_kept_setup(&self, mut command: Command) -> Command {
        if let Command::Start(start) = &mut command {
            start.setup_digest = self.kept_setup_digest(start.track);
        }
        command
    }

    /// `Vehicle`: one value of the following runs' vehicle (checked when a run is built;
    /// only while no run is active).
    fn vehicle_command(&mut self, command: &Command) -> Result<(), CommandError> {
        if self.busy() {
            return Err(CommandError::NotNow(self.state));
        }
        self.setup.apply(command)
    }

    /// State of the rig.
    pub fn state(&self) -> RigState {
        self.state
    }

    /// The arming gate of the outputs a controller reads.
    pub fn arming(&self) -> &ArmingGate {
        &self.arming
    }

    /// Whether the outputs a controller reads are live now (armed, in a rig-mode run:
    /// [`ArmingGate::outputs_live`]). Every controller-facing output follows this answer
    /// and holds its safe value otherwise.
    pub fn controller_outputs_live(&self) -> bool {
        self.arming.outputs_live(self.state, self.mode)
    }

    /// Whether a sensor channel has a latched fault.
    fn sensor_fault_latched(&self) -> bool {
        self.sensors.iter().any(|s| s.fault().is_some())
    }

    /// The simulation, unless the store is lent to the builder.
    fn sim(&self) -> Option<&Sim> {
        sim_in(&self.sim, self.sim_lent)
    }

    fn sim_mut(&mut self) -> Option<&mut Sim> {
        (!self.sim_lent).then(|| &mut self.sim.sim_mut().0)
    }
    /// Mode of the current (or last) run.
    pub fn mode(&self) -> RigMode {
        self.mode
    }
    /// The board configuration.
    pub fn config(&self) -> &RigConfig {
        &self.config
    }
    /// Step timing of the current (or last) run.
    pub fn timing(&self) -> &StepTiming {
        &self.timing
    }
    /// Plant steps of the current (or last) run.
    pub fn run_steps(&self) -> u32 {
        self.run_steps
    }
    /// Wheel speeds as last sent (None = not available), km/h.
    pub fn wheel_speeds_kmh(&self) -> [Option<f32>; WHEELSETS] {
        self.wheel_speed_kmh
    }
    /// Pulse registers as last written.
    pub fn pulses(&self) -> [PulseRegisters; WHEELSETS] {
        self.pulses
    }

    /// The plant outputs of the run (None without a run), built on demand
    /// ([`hils_plant::Plant::outputs`]; the tick uses the plant's cheap accessors).
    pub fn outputs(&self) -> Option<Outputs<f32>> {
        self.plant().map(|p| p.outputs())
    }

    /// The plant of the run (None without a run).
    fn plant(&self) -> Option<&Plant<f32>> {
        match self.sim()? {
            Sim::None => None,
            Sim::Rig(p) => Some(p),
            Sim::SelfTest(c) => Some(&c.plant),
        }
    }

    /// The surface under each wheelset (None without a run).
    pub fn surfaces(&self) -> Option<[Surface; WHEELSETS]> {
        match self.sim()? {
            Sim::None => None,
            Sim::Rig(p) => Some(p.track().surfaces()),
            Sim::SelfTest(c) => Some(c.plant.track().surfaces()),
        }
    }

    /// Fault flags now.
    pub fn faults(&self) -> Faults {
        let mut f = self.sticky | self.bus_flags;
        for (j, s) in self.sensors.iter().enumerate() {
            if s.fault().is_some() {
                f |= Faults::from_bits_retain(1 << j);
            }
            if s.injected().is_some() {
                f |= Faults::FAULT_INJECTED;
            }
        }
        f
    }

    /// Bus state from the CAN task (error passive now; bus-off now or seen; bus-off count).
    pub fn set_bus(&mut self, error_passive: bool, bus_off: bool, bus_off_count: u32) {
        self.bus_flags = Faults::empty();
        self.bus_flags.set(Faults::CAN_ERROR_PASSIVE, error_passive);
        self.bus_flags.set(Faults::CAN_BUS_OFF, bus_off);
        self.bus_off_count = bus_off_count.min(255) as u8;
    }

    /// The board's own health as its tasks measured it (stack, receive losses, ADC
    /// restarts, fault resets), sent in `RIG_HEALTH`.
    pub fn set_board_health(&mut self, health: BoardHealth) {
        self.health = health;
    }

    /// Whether `ClearFaults` asked since the last call that the bus supervision clear its
    /// sticky bus-off (the board then calls `BusMonitor::clear`, which refuses while the
    /// controller is bus-off, and passes the result back through [`Rig::set_bus`]).
    pub fn take_bus_clear(&mut self) -> bool {
        core::mem::take(&mut self.bus_clear_requested)
    }

    /// Drops the board counted downstream of the step's queues: telemetry the RTT channel
    /// could not take (`log_gate`), CAN frames dropped stale or cancelled in the controller
    /// (`can_tx`). Sets the sticky flags, as a full queue does.
    pub fn note_downstream_drops(&mut self, telemetry: bool, can: bool) {
        if telemetry {
            self.sticky |= Faults::TELEMETRY_DROPPED;
        }
        if can {
            self.sticky |= Faults::CAN_TX_DROPPED;
        }
    }

    /// Records the timing of the last step (DWT cycles at entry and exit of the step
    /// interrupt; whether the next tick was already pending at exit).
    pub fn record_timing(&mut self, entry: u32, exit: u32, tick_pending: bool) {
        let v = self.timing.record(entry, exit, tick_pending);
        if v.overrun {
            self.sticky |= Faults::OVERRUN;
        }
        if v.missed_ticks > 0 {
            self.sticky |= Faults::MISSED_TICKS;
        }
        let d = &mut self.diag_window;
        d.max_cycles = d.max_cycles.max(v.duration_cycles);
        d.sum_cycles += v.duration_cycles as u64;
        d.steps += 1;
    }

    /// Decodes and carries out a received command frame; the result goes into the status
    /// frame (and `COMMAND_REJECTED` when rejected).
    pub fn command_frame<F: Frame>(&mut self, frame: &F) -> Result<Command, CommandError> {
        let r = match CommandFrame::decode(frame) {
            Ok(cf) => {
                if self.last_command_counter == Some(cf.counter) {
                    Err(CommandError::Repeated)
                } else {
                    self.last_command_counter = Some(cf.counter);
                    self.command(cf.command).map(|_| cf.command)
                }
            }
            Err(e) => Err(CommandError::Frame(e)),
        };
        self.note_result(r.is_ok());
        r
    }

    fn note_result(&mut self, ok: bool) {
        if ok {
            self.last_result = CommandResult::Accepted;
        } else {
            self.last_result = CommandResult::Rejected;
            self.sticky |= Faults::COMMAND_REJECTED;
        }
    }

    fn running(&self) -> bool {
        self.state == RigState::Running
    }

    /// A run is requested or running: no new start, calibration or configuration.
    fn busy(&self) -> bool {
        matches!(self.state, RigState::Running | RigState::Starting)
    }

    /// The `Start` command: checks it and requests the run (`Starting`); the simulation is
    /// built outside the step ([`Rig::take_start_request`], [`StartRequest::build`]) and
    /// the run begins when it is installed ([`Rig::install`]).
    fn start(&mut self, start: StartCommand) -> Result<(), CommandError> {
        let StartCommand {
            mode,
            track,
            initial_speed_kmh,
            ..
        } = start;
        // In this order (the host names a rejection by the same order): busy, speed,
        // sensor faults, arming, track, setup digest.
        if self.busy() {
            return Err(CommandError::NotNow(self.state));
        }
        if !(0.0..=WHEEL_SPEED_MAX_KMH).contains(&initial_speed_kmh) {
            return Err(CommandError::SpeedOutOfRange);
        }
        if mode == RigMode::Rig && self.sensor_fault_latched() {
            return Err(CommandError::SensorFaults);
        }
        if mode == RigMode::Rig && !self.arming.is_armed() {
            return Err(CommandError::NotArmed);
        }
        if track && self.setup.track().is_none() {
            return Err(CommandError::NoTrack);
        }
        // After the busy check: the CRC runs only on an idle board's step.
        let kept = self.kept_setup_digest(track);
        if start.setup_digest != kept {
            return Err(CommandError::SetupMismatch { kept });
        }
        if mode == RigMode::SelfTest {
            // The board's own brake unit closes this loop: the controller is not in it.
            self.arming.disarm(Disarm::SelfTest);
        }
        // The run before drives nothing from here, whatever becomes of this request.
        self.arming.run_left();
        // The old run's simulation is no longer shown (plain data: nothing to drop).
        if let Some(sim) = self.sim_mut() {
            *sim = Sim::None;
        }
        self.start_seq = self.start_seq.wrapping_add(1);
        self.start_request = Some(StartRequest {
            seq: self.start_seq,
            mode,
            rail: start.rail,
            friction: start.friction,
            emergency: start.emergency,
            initial_speed_kmh,
            track: self.setup.track().filter(|_| track).copied(),
            vehicle: *self.setup.vehicle(),
        });
        self.start_request_new = true;
        self.state_before_start = self.state;
        self.state = RigState::Starting;
        Ok(())
    }

    /// The run requested since the last call, for the builder (once per request); from
    /// now until its build comes back the builder owns the rig's [`SimStore`]. None while
    /// the store is still lent for an earlier request (its build, stale, comes back
    /// first), or while the last run's final record is still due.
    pub fn take_start_request(&mut self) -> Option<StartRequest> {
        if self.sim_lent || self.end_event || !self.start_request_new {
            return None;
        }
        self.start_request_new = false;
        self.sim_lent = self.start_request.is_some();
        self.start_request
    }

    /// A request [`Rig::take_start_request`] gave out that the board could not pass to the
    /// builder (still busy with an earlier one): offered again at the next call, if it is
    /// still the pending request.
    pub fn retry_start_request(&mut self, req: &StartRequest) {
        // The builder never got it: the store is the rig's again.
        self.sim_lent = false;
        if self.start_request.is_some_and(|r| r.seq == req.seq) {
            self.start_request_new = true;
        }
    }

    /// Builds that came back for a request no longer pending (stopped, or superseded by a
    /// later `Start`), each refused by [`Rig::install`] with [`CommandError::StaleBuild`].
    pub fn stale_builds(&self) -> u32 {
        self.stale_builds
    }

    /// The builder is done with the store (the step, at the tick the build comes back):
    /// starts the run with the simulation it built there, if it was built for the pending
    /// request (same [`StartRequest::seq`]); a failed build goes back to the state before
    /// the request, with the command rejected. A build for any other request (stopped
    /// meanwhile, or an earlier `Start` superseded by a later one) is not installed:
    /// counted in [`Rig::stale_builds`] and refused with `StaleBuild`. Only the enum tag
    /// is written here: no construction and no move in the step.
    pub fn install_in_place(&mut self, built: Built<()>) -> Result<(), CommandError> {
        if !self.sim_lent {
            // Nothing was lent: not a build of ours.
            self.stale_builds = self.stale_builds.wrapping_add(1);
            return Err(CommandError::StaleBuild { seq: built.seq });
        }
        self.sim_lent = false;
        let Some(req) = self
            .start_request
            .filter(|r| self.state == RigState::Starting && r.seq == built.seq)
        else {
            self.sim.sim_mut().0 = Sim::None;
            self.stale_builds = self.stale_builds.wrapping_add(1);
            return Err(CommandError::StaleBuild { seq: built.seq });
        };
        self.start_request = None;
        self.start_request_new = false;
        if let Err(e) = built.result {
            self.sim.sim_mut().0 = Sim::None;
            self.state = self.state_before_start;
            self.note_result(false);
            return Err(e);
        }
        self.mode = req.mode;
        self.rail = req.rail;
        self.friction = req.friction;
        self.initial_speed_kmh = req.initial_speed_kmh;
        // Rig mode: the demand in force (the board drives it on the train lines) stays.
        self.brake = match (req.mode, req.emergency) {
            (RigMode::SelfTest, true) => Some(BrakeCommand::Emergency),
            (RigMode::SelfTest, false) => Some(BrakeCommand::Release),
            (RigMode::Rig, _) => self.brake,
        };
        self.state = RigState::Running;
        self.arming.run_started(req.mode);
        self.run_steps = 0;
        self.timing.reset();
        self.diag_window = DiagWindow::default();
        self.stale_ticks = 0;
        self.start_events = true;
        self.last_record_step = None;
        self.record_seq = 0;
        Ok(())
    }

    /// Carries out a command (also from the board's user button). Out of line: the board
    /// runs it from flash, on the tick of a command only (firmware/board/ccm.x).
    #[inline(never)]
    pub fn command(&mut self, command: Command) -> Result<(), CommandError> {
        match command {
            Command::Start(start) => self.start(start),
            Command::Stop => match self.state {
                RigState::Running => {
                    self.end_run(RigState::Stopped);
                    Ok(())
                }
                // Cancelled before it ran: no run events; a late simulation is discarded.
                RigState::Starting => {
                    self.start_request = None;
                    self.start_request_new = false;
                    self.state = RigState::Stopped;
                    self.arming.disarm(Disarm::Stop);
                    Ok(())
                }
                s => Err(CommandError::NotNow(s)),
            },
            Command::Brake(b) => {
                if let Some(Sim::SelfTest(c)) = self.sim_mut() {
                    c.set_demand(b);
                }
                // In rig mode the board drives the command on the train lines (EB loop,
                // service PWM: `update_outputs`, this tick) and logs it as `cmd`.
                self.brake = Some(b);
                Ok(())
            }
            Command::InjectFault { channel, fault } => {
                let ch = self
                    .sensors
                    .get_mut(channel as usize)
                    .ok_or(CommandError::Frame(DecodeError::BadValue("Channel")))?;
                ch.inject(fault);
                Ok(())
            }
            Command::Calibrate { channel, action } => {
                if self.busy() {
                    return Err(CommandError::NotNow(self.state));
                }
                let ch = self
                    .sensors
                    .get_mut(channel as usize)
                    .ok_or(CommandError::Frame(DecodeError::BadValue("Channel")))?;
                match action {
                    Calibration::Tare => ch.tare(),
                    Calibration::SetGain(g) => ch.set_gain(g),
                    Calibration::SetOffset(o) => ch.set_offset(o),
                    Calibration::SetKind(k) => {
                        ch.set_kind(k);
                        Ok(())
                    }
                }
                .map_err(CommandError::Calibration)
            }
            Command::ClearFaults => {
                let mut all_clear = true;
                for s in &mut self.sensors {
                    all_clear &= s.clear_fault();
                }
                // A flag whose cause is present stays: ADC still stale, bus still off (the
                // board's monitor clears "bus-off seen" only if it is back on the bus).
                let stale = self.stale_ticks > 0;
                self.sticky = if stale {
                    Faults::ADC_STALE
                } else {
                    Faults::empty()
                };
                self.bus_clear_requested = true;
                if self.state == RigState::Fault && all_clear && !stale {
                    self.state = RigState::Stopped;
                }
                Ok(())
            }
            Command::Configure(item) => {
                if self.busy() {
                    return Err(CommandError::NotNow(self.state));
                }
                match item {
                    ConfigItem::TelemetryDivider(d) => self.config.telemetry_divider = d.max(1),
                    ConfigItem::Teeth(t) => self.config.teeth = t.max(1),
                    ConfigItem::Io(item, v) => {
                        self.config
                            .io
                            .set(item, v)
                            .map_err(CommandError::IoConfig)?;
                        self.pwm_period =
                            self.config.io.demand.pwm_period(&self.config.pulse_timer);
                        if item == IoItem::ValveWiring {
                            self.valves.set_wiring(self.config.io.valves);
                        }
                    }
                }
                Ok(())
            }
            Command::TrackZone { .. } | Command::Track(_) => self.setup.apply(&command),
            Command::Vehicle { .. } => self.vehicle_command(&command),
            Command::Arm => self
                .arming
                .arm(self.state, self.sensor_fault_latched())
                .map_err(CommandError::Arm),
            Command::Disarm => {
                self.arming.disarm(Disarm::Command);
                Ok(())
            }
        }
    }

    /// Ends the run in `state`; `Fault` and `Stopped` disarm (safe state).
    fn end_run(&mut self, state: RigState) {
        self.state = state;
        self.end_event = true;
        match state {
            RigState::Fault => self.arming.disarm(Disarm::Fault),
            RigState::Stopped => self.arming.disarm(Disarm::Stop),
            _ => {}
        }
    }

    /// One tick of the real-time loop.
    pub fn step<IO: RigIo>(&mut self, io: &mut IO) {
        self.tick = self.tick.wrapping_add(1);

        // 0. Valve inputs, sampled at the start of every tick.
        self.valves.update(io.valve_levels());

        // 1. Sensors.
        // Without a fresh sequence the channels are not updated (a stalled DMA is one
        // ADC_STALE fault, not four "stuck" sensors) and hold their last plausible values.
        match io.adc_sequence() {
            Some(seq) => {
                self.stale_ticks = 0;
                let split = split_sequence(&seq);
                for (j, s) in self.sensors.iter_mut().enumerate() {
                    self.pending[j] = s.update(split[j]).pending;
                }
            }
            None => {
                self.stale_ticks = self.stale_ticks.saturating_add(1);
                self.sticky |= Faults::ADC_STALE;
            }
        }
        let readings: [f32; CHANNELS] = core::array::from_fn(|j| self.sensors[j].value());

        // 2. Start-of-run telemetry (header and the t = 0 record).
        if core::mem::take(&mut self.start_events) {
            let h = self.header();
            self.emit(io, &TelemetryEvent::Header(h));
            self.emit_record(io);
        }

        // 3. Simulation.
        if self.running() {
            let rig_fault = self.mode == RigMode::Rig
                && (self.sensors.iter().any(|s| s.fault().is_some())
                    || self.stale_ticks >= ADC_STALE_TICKS);
            if rig_fault {
                self.end_run(RigState::Fault);
            } else {
                let flags = self.step_sim(&readings);
                self.run_steps = self.run_steps.wrapping_add(1);
                if flags.contains(Flags::INPUT_NOT_FINITE | Flags::INPUT_OUT_OF_RANGE) {
                    self.sticky |= Faults::PLANT_INPUT;
                }
                if flags.contains(Flags::NUMERIC_FAULT) {
                    self.sticky |= Faults::PLANT_NUMERIC;
                    self.end_run(RigState::Fault);
                } else if self
                    .plant()
                    .is_some_and(|p| at_standstill(p.vehicle_speed()))
                {
                    self.end_run(RigState::Finished);
                }
                let divider = self.config.telemetry_divider.max(1) as u32;
                if self.running() && self.run_steps % divider == 0 {
                    self.emit_record(io);
                }
            }
        }
        if core::mem::take(&mut self.end_event) {
            self.emit_record(io);
            let ev = TelemetryEvent::End {
                step: self.run_steps,
                state: self.state as u8,
            };
            self.emit(io, &ev);
        }

        // 4. Outputs: pulse trains every tick, frames on schedule.
        self.update_outputs(io);
    }

    fn step_sim(&mut self, readings: &[f32; CHANNELS]) -> Flags {
        if self.sim_lent {
            return Flags(0);
        }
        match &mut self.sim.sim_mut().0 {
            Sim::None => Flags(0),
            Sim::Rig(plant) => {
                let mut inputs = [BrakeInput::ClampForce(0.0f32); WHEELSETS];
                for j in 0..WHEELSETS {
                    inputs[j] = match self.sensors[j].kind {
                        SensorKind::LoadCell => BrakeInput::ClampForce(readings[j]),
                        SensorKind::PressureTransducer => BrakeInput::CylinderPressure(readings[j]),
                    };
                }
                plant.step(&inputs)
            }
            Sim::SelfTest(c) => c.step(),
        }
    }

    fn header(&self) -> RunHeader {
        let mut pressure_channels = 0u8;
        for (j, s) in self.sensors.iter().enumerate() {
            if s.kind == SensorKind::PressureTransducer {
                pressure_channels |= 1 << j;
            }
        }
        RunHeader {
            mode: self.mode as u8,
            rail: rail_code(self.rail),
            friction: friction_code(self.friction),
            initial_speed_kmh: self.initial_speed_kmh,
            step_ns: 1_000_000_000 / STEP_RATE_HZ,
            divider: self.config.telemetry_divider as u32,
            cpu_hz: self.config.cpu_hz,
            teeth: self.config.teeth,
            pressure_channels,
        }
    }

    fn emit<IO: RigIo>(&mut self, io: &mut IO, ev: &TelemetryEvent) {
        if !io.queue_telemetry(ev) {
            self.sticky |= Faults::TELEMETRY_DROPPED;
        }
    }

    fn emit_record<IO: RigIo>(&mut self, io: &mut IO) {
        if self.last_record_step == Some(self.run_steps) {
            return;
        }
        if let Some(r) = self.record() {
            self.last_record_step = Some(r.step);
            // Counted whether or not the queue takes it: a dropped record is a gap.
            self.record_seq = self.record_seq.wrapping_add(1);
            self.emit(io, &TelemetryEvent::Record(r));
        }
    }

    /// The telemetry record of now (None without a run); takes the timing window.
    pub fn record(&mut self) -> Option<TelemetryRecord> {
        let window = self.timing.take_window();
        let faults = self.faults().bits() | self.pending_bits();
        let mut sensor_faults = 0u16;
        for (j, s) in self.sensors.iter().enumerate() {
            sensor_faults |= (SensorFault::code(s.fault()) as u16) << (4 * j);
        }
        let (o, unit, plant_surfaces) = match self.sim()? {
            Sim::None => return None,
            Sim::Rig(p) => (p.outputs(), None, p.track().surfaces()),
            Sim::SelfTest(c) => (
                c.outputs(),
                Some(c.unit_outputs()),
                c.plant.track().surfaces(),
            ),
        };
        let mut surfaces = 0u8;
        for (j, s) in plant_surfaces.iter().enumerate() {
            surfaces |= surface_code(*s) << (2 * j);
        }
        let w = |f: &dyn Fn(usize) -> f32| -> [f32; 4] { [f(0), f(1), f(2), f(3)] };
        let (p_cyl, f_clamp, valves) = match unit {
            Some(u) => {
                let holding = u.valves.map(|v| v == hils_brake_unit::Valve::Hold);
                (
                    u.cylinder_pressure_pa,
                    w(&|j| o.wheelsets[j].clamp_force),
                    ValveStates::of_unit(u.venting, holding),
                )
            }
            None => {
                let measured = |kind: SensorKind| {
                    w(&|j| {
                        if self.sensors[j].kind == kind {
                            self.sensors[j].value()
                        } else {
                            f32::NAN
                        }
                    })
                };
                (
                    measured(SensorKind::PressureTransducer),
                    measured(SensorKind::LoadCell),
                    self.valves.states(),
                )
            }
        };
        Some(TelemetryRecord {
            step: self.run_steps,
            state: self.state as u8,
            mode: self.mode as u8,
            cmd: self
                .brake
                .map(|b| u8::from(hils_sil::Cmd::of(b)))
                .unwrap_or(0xFF),
            driven: self.driven.bits(),
            valves: valves.bits(),
            v_ref: o.vehicle_speed,
            omega: w(&|j| o.wheelsets[j].omega),
            p_cyl,
            f_clamp,
            f_brake: w(&|j| o.wheelsets[j].brake_force),
            t_disc: w(&|j| o.wheelsets[j].disc_temp),
            q: w(&|j| o.wheelsets[j].axle_load),
            mu_d: w(&|j| o.wheelsets[j].mu_d),
            a_x: o.carbody_accel,
            service_demand: self.driven.service_mps2,
            air_spring: self.driven.air_spring_pa,
            step_max_cycles: window.max_cycles,
            step_mean_cycles: window.mean_cycles,
            overruns: self.timing.overruns,
            missed_ticks: self.timing.missed_ticks,
            faults,
            sensor_faults,
            surfaces,
            seq: self.record_seq,
        })
    }

    fn pending_bits(&self) -> u32 {
        let mut f = 0;
        for j in 0..CHANNELS {
            if self.pending[j] {
                f |= 1 << (16 + j);
            }
        }
        f
    }

    fn update_outputs<IO: RigIo>(&mut self, io: &mut IO) {
        // Every fault disarms (a latched sensor fault also outside a run).
        if self.sensor_fault_latched() {
            self.arming.disarm(Disarm::Fault);
        }
        // The run's plant (status frame), and the plant the controller-facing outputs show:
        // only while the arming gate says they are live.
        let live = matches!(self.state, RigState::Running | RigState::Finished);
        let plant = match (sim_in(&self.sim, self.sim_lent), live) {
            (Some(Sim::Rig(p)), true) => Some(p),
            (Some(Sim::SelfTest(c)), true) => Some(&c.plant),
            _ => None,
        };
        let (v, a) = plant
            .map(|p| (p.vehicle_speed(), p.carbody_accel()))
            .unwrap_or((0.0, 0.0));
        let o = plant.filter(|_| self.arming.outputs_live(self.state, self.mode));
        // Wheel circumferential speeds r omega (m/s) for CAN, spin speeds omega (rad/s)
        // for the pulse trains.
        let speeds = o.map(|p| p.wheel_speeds()).unwrap_or([0.0; WHEELSETS]);
        // At rest after the run (`Finished`): trains silent, speeds 0.00 km/h (the plant's
        // residual creep and carbody swing-back are not wheel rotation to report).
        let at_rest = self.state == RigState::Finished;
        let spins = o.map(|p| p.spin_speeds());
        for j in 0..WHEELSETS {
            let regs = match spins {
                Some(spins) if !at_rest => self
                    .config
                    .pulse_timer
                    .registers(wheel_frequency_hz(spins[j], self.config.teeth)),
                _ => self.config.pulse_timer.silent(),
            };
            self.pulses[j] = regs;
            io.set_pulse(j, &regs);
            self.wheel_speed_kmh[j] = o.map(|_| {
                if at_rest {
                    0.0
                } else {
                    speeds[j] * KMH_PER_MPS
                }
            });
        }

        self.drive_controller(io);

        if WHEEL_SPEED_SCHEDULE.due(self.tick) {
            let mut saturated = false;
            for s in self.wheel_speed_kmh {
                saturated |= WheelSpeedFrame::raw_speed(s).1;
            }
            if saturated {
                self.sticky |= Faults::SPEED_SATURATED;
            }
            let valves = self.valves.states();
            for frame in WheelSpeedFrame::cycle(self.wheel_speed_kmh, valves, self.counters[0]) {
                self.send(io, frame.encode());
            }
            self.counters[0] = (self.counters[0] + 1) & 0x0F;
        }
        if STATUS_SCHEDULE.due(self.tick) {
            let frame = StatusFrame {
                vehicle_speed_kmh: if live { v * KMH_PER_MPS } else { 0.0 },
                deceleration_mps2: if live { -a } else { 0.0 },
                state: self.state,
                mode: self.mode,
                command_result: self.last_result,
                faults: self.faults().bits() as u16,
                counter: self.counters[1],
            };
            self.counters[1] = (self.counters[1] + 1) & 0x0F;
            self.send(io, frame.encode());
        }
        if DIAG_SCHEDULE.due(self.tick) {
            let w = core::mem::take(&mut self.diag_window);
            let (max, n) = (w.max_cycles, w.steps);
            let mean = if n > 0 {
                crate::pulse::div_u64(w.sum_cycles, n as u64) as u32
            } else {
                0
            };
            let frame = DiagFrame {
                step_max_us: cycles_to_us(max, self.config.cpu_hz),
                step_mean_us: cycles_to_us(mean, self.config.cpu_hz),
                overruns: self.timing.overruns.min(u16::MAX as u32) as u16,
                sensor_faults: core::array::from_fn(|j| self.sensors[j].fault()),
                bus_off_count: self.bus_off_count.min(15),
            };
            self.send(io, frame.encode());
        }
        if HEALTH_SCHEDULE.due(self.tick) {
            let h = self.health;
            let frame = HealthFrame {
                stack_peak_bytes: h.stack_peak_bytes,
                stack_size_bytes: h.stack_size_bytes,
                rx_lost: h.rx_lost.min(255) as u8,
                adc_restarts: h.adc_restarts.min(255) as u8,
                disarmed: self.arming.disarmed_by(),
                fault_resets: h.fault_resets.min(15) as u8,
                counter: self.counters[2],
            };
            self.counters[2] = (self.counters[2] + 1) & 0x0F;
            self.send(io, frame.encode());
        }
    }

    /// The controller's demand and load lines ([`crate::controller_io`]): while the arming
    /// gate says the controller-facing outputs are live (armed, a rig-mode run running or
    /// finished: [`Rig::controller_outputs_live`]) the brake command in force (release when
    /// none was given) and the plant's air-spring forces; else, in the same tick, the safe
    /// outputs. The demand frame, when configured, on its schedule and in the tick the
    /// demand changes.
    fn drive_controller<IO: RigIo>(&mut self, io: &mut IO) {
        let timer = self.config.pulse_timer;
        let plant = if self.controller_outputs_live() {
            self.plant()
        } else {
            None
        };
        let driven = match plant {
            Some(p) => self.config.io.driven_in(
                self.pwm_period,
                self.brake.unwrap_or(BrakeCommand::Release),
                p.air_spring_forces(),
            ),
            None => DrivenOutputs::safe(&timer),
        };
        let changed = (driven.eb_loop_closed, driven.service_mps2)
            != (self.driven.eb_loop_closed, self.driven.service_mps2);
        self.driven = driven;
        io.set_controller_outputs(&driven);
        if self.config.io.demand.frame && (changed || DEMAND_SCHEDULE.due(self.tick)) {
            let frame = BrakeDemandFrame {
                eb_loop_closed: driven.eb_loop_closed,
                service_mps2: driven.service_mps2,
                counter: self.counters[3],
            };
            self.counters[3] = (self.counters[3] + 1) & 0x0F;
            self.send(io, frame.encode());
        }
    }

    /// The valve inputs as the step last sampled them (debounced; wired ones known).
    pub fn valve_states(&self) -> ValveStates {
        self.valves.states()
    }

    /// The controller outputs as last driven.
    pub fn driven(&self) -> DrivenOutputs {
        self.driven
    }

    fn send<IO: RigIo>(&mut self, io: &mut IO, frame: Option<IO::Frame>) {
        match frame {
            Some(f) => {
                if !io.queue_frame(f) {
                    self.sticky |= Faults::CAN_TX_DROPPED;
                }
            }
            None => self.sticky |= Faults::CAN_TX_DROPPED,
        }
    }
}
