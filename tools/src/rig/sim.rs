//! `--interface sim`: the board's own logic (`hils_rig_core::rig::Rig`) stepping at 10 kHz in
//! this process behind an in-process bus, with a simulated brake controller under test.
//!
//! Per tick (0.1 ms of board time), in the order of the board's step interrupt
//! (`firmware/board/src/step.rs`): the frames the host sent are handed to
//! [`Rig::command_frame`] (and seen by the controller, as on a shared bus), the controller
//! under test steps, [`Rig::step`] runs with a mock [`RigIo`], and the step is timed.
//!
//! * **The rig hardware** ([`SimIo`]): four brake cylinder pressure transducers, the eight
//!   valve inputs (all wired, active low), the EB loop relay, the demand PWM and the two
//!   air-spring DACs. The ADC
//!   reads each cylinder pressure of the controller through the transducer's nominal
//!   characteristic (`SensorKind::PressureTransducer.default_calibration()`, inverted) with
//!   +-2 counts of deterministic noise (a real ADC never reads the same sum for long; the
//!   board's stuck-sensor check needs that). The board's channels are set to pressure
//!   transducers at power-up, as a rig fitted with them would be calibrated.
//! * **The controller under test** ([`SimController`]): the project's simulated brake unit
//!   (`hils_brake_unit::BrakeUnit`, the one `hils simulate` runs, WSP on) at the plant step,
//!   wired to the board as a real controller would be, every signal through the rig-core
//!   code the board runs:
//!   - wheel speeds from the four axle-speed pulse trains, as a WSP unit's speed sensor
//!     inputs read them ([`SpeedSensors`]): each train's mean frequency over the board's
//!     period dither (`hils_rig_core::pulse::PulseTimer::frequency_of` of the setting the
//!     board wrote; the board's channel code drives a counting timer model each tick) times
//!     the wheel circumference over the teeth (its configuration: the `Configure Teeth` and
//!     `Vehicle` frames it sees); a silent train is a wheel at rest;
//!   - its brake demand from the train lines the board drives: the emergency brake loop
//!     and the service demand PWM's registers, read through
//!     `hils_rig_core::demand::{DemandConfig::decode_pwm, ControllerDemand}` (open loop or
//!     no valid PWM = emergency brake);
//!   - its load (load weighing, at each start) from the two air-spring DAC codes, read
//!     through `hils_rig_core::load::LoadConfig::read_pa` as a transducer's signal: the
//!     bogie forces give the carbody mass its EB pressure is set for (the other `[vehicle]`
//!     values it takes from the `Vehicle` frames, as its configuration);
//!   - its WSP valve coils (vent: dump and hold coils; hold: the hold coil) on the board's
//!     valve inputs through `hils_rig_core::valves::ValveLevels::of_coils` (the interface
//!     stage), which the board samples and debounces.
//!
//!   It keeps the same I/O configuration as the board (the `Configure` frames it sees).
//!   At standstill (every train silent: the board idle, in its safe state, or a run
//!   finished) it keeps its brake as the lines demand; a jump from standstill to a running
//!   speed is the next run: it starts afresh (no WSP state, its cylinders empty) and weighs
//!   the car.
//! * **Step timing**: the host time of each [`Rig::step`] call, in cycles of the board's
//!   170 MHz clock, so the diagnostic frame shows real (host) figures. Unless paced
//!   (`--realtime`), board time is not wall time, so a step is capped just below the period
//!   (a host preemption is no overrun of the board); paced, an overrun is flagged as on the
//!   board.
//! * **Fault injection for tests and demos** ([`SimFaults`]): the board goes silent, the
//!   host's controller goes bus-off, or the status frame's alive counter freezes, at a
//!   given board time.
//!
//! Board time runs as fast as the host can step it, or paced to the wall clock with
//! `--realtime`.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use hils_brake_unit::{BrakeDemand, BrakeUnit, UnitConfig, Valve};
use hils_plant::params::STEP_S;
use hils_plant::{Params, WHEELSETS};
use hils_rig_core::can::{
    ClassicFrame, Command, CommandFrame, ConfigItem, StatusFrame, VehicleKey,
};
use hils_rig_core::controller_io::{DrivenOutputs, IoConfig};
use hils_rig_core::demand::ControllerDemand;
use hils_rig_core::hw::{RigIo, TelemetryEvent};
use hils_rig_core::pulse::{PulseChannel, PulseRegisters, PulseTimer};
use hils_rig_core::rig::{Rig, RigConfig};
use hils_rig_core::sensor::{ADC_MAX_COUNTS, ADC_SEQUENCE_LEN, OVERSAMPLING, SensorKind};
use hils_rig_core::timer_model::CountingTimer;
use hils_rig_core::valves::{ValveLevels, ValveWiring};
use hils_rig_core::{CHANNELS, STEP_RATE_HZ};

use super::transport::{ProbeEvent, Received, Transport, TransportError};

/// Board time of one tick, s.
pub const TICK_S: f64 = 1.0 / STEP_RATE_HZ as f64;

/// Faults the simulated bus can show, at board times (s).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SimFaults {
    /// The board goes silent (power or cable lost).
    pub board_lost_at_s: Option<f64>,
    /// The host's CAN controller goes bus-off.
    pub bus_off_at_s: Option<f64>,
    /// The status frame's alive counter stops counting (a hung sender task).
    pub status_alive_frozen_at_s: Option<f64>,
}

/// The four pulse trains and the controller's axle speed sensor inputs that read them.
///
/// Each train is the board's channel logic (`hils_rig_core::pulse::PulseChannel`: update
/// order, dithered periods) driving a counting model of its timer
/// (`hils_rig_core::timer_model::CountingTimer`), which runs for one tick of board time
/// before each step. The model checks the dither over whole runs
/// ([`SimBoard::pulse_dither_check`]).
///
/// The controller's inputs read each train's frequency as its mean over the dither: the
/// frequency of the setting the board wrote in its last step
/// (`PulseTimer::frequency_of`, fraction included; a silent train is a wheel at rest). The
/// pin's edges move by one timer count from one period to the next (at most 3e-5 of the
/// period below 2.6 kHz: 12 ns at 1388 Hz), below what a controller's speed input resolves
/// (a capture clock of 1-10 MHz), and
/// SIL's unit reads the plant's speeds as an ideal input too, without the period's delay
/// of a period-measuring input.
struct SpeedSensors {
    timer: PulseTimer,
    channels: [PulseChannel; WHEELSETS],
    timers: [CountingTimer; WHEELSETS],
    /// The settings the step wrote last.
    settings: [PulseRegisters; WHEELSETS],
    /// Exact mean period of the setting each timer's running period was loaded from, and
    /// of the one its next period loads, undivided counts (None: silent).
    running: [Option<f64>; WHEELSETS],
    dither: [DitherCheck; WHEELSETS],
}

/// Whole pulse periods of a train against the settings they were loaded from.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DitherCheck {
    /// Periods that ended at the prescaler of the one before (a prescaler change starts
    /// the dither's residue afresh in the new counts).
    pub periods: u64,
    /// Sum of (period - its setting's exact mean period), in prescaled counts.
    pub sum_error_counts: f64,
}

impl SpeedSensors {
    fn new(timer: PulseTimer) -> Self {
        Self {
            timer,
            channels: [PulseChannel::new(timer.silent()); WHEELSETS],
            timers: [CountingTimer::new(timer.silent()); WHEELSETS],
            settings: [timer.silent(); WHEELSETS],
            running: [None; WHEELSETS],
            dither: [DitherCheck::default(); WHEELSETS],
        }
    }

    /// Exact mean period of a setting, undivided counts (None: silent).
    fn mean_period(&self, r: &PulseRegisters) -> Option<f64> {
        let f = self.timer.frequency_of(r);
        (f > 0.0).then(|| self.timer.clock_hz as f64 / f)
    }

    /// One tick of board time: the timers count; a period that ended is checked against
    /// the setting it was loaded from.
    fn run_tick(&mut self) {
        let counts = self.timer.clock_hz as u64 / STEP_RATE_HZ as u64;
        for j in 0..WHEELSETS {
            let t = &mut self.timers[j];
            let psc_before = t.shadow().psc;
            let ended = t.run(counts);
            if ended == 0 {
                continue;
            }
            let (Some(p), Some(want)) = (t.last_period_counts(), self.running[j]) else {
                self.running[j] = self.mean_period(&self.settings[j]);
                continue;
            };
            let psc = t.shadow().psc;
            if ended == 1 && psc == psc_before {
                let d = &mut self.dither[j];
                d.periods += 1;
                d.sum_error_counts += (p as f64 - want) / (psc as f64 + 1.0);
            }
            self.running[j] = self.mean_period(&self.settings[j]);
        }
    }

    /// The step's setting for a wheelset's train.
    fn write(&mut self, wheelset: usize, r: &PulseRegisters) {
        if let (Some(c), Some(t), Some(s)) = (
            self.channels.get_mut(wheelset),
            self.timers.get_mut(wheelset),
            self.settings.get_mut(wheelset),
        ) {
            c.write(r, t);
            *s = *r;
        }
    }

    /// Wheel circumferential speeds, m/s, for `teeth` teeth on wheels of radius `r_m`.
    fn speeds_mps(&self, teeth: u16, r_m: f64) -> [f32; WHEELSETS] {
        self.settings.map(|r| {
            (self.timer.frequency_of(&r) * core::f64::consts::TAU * r_m / teeth.max(1) as f64)
                as f32
        })
    }
}

/// The rig's hardware as the board's step sees it.
struct SimIo {
    /// Cylinder pressures the transducers see, Pa.
    pressure_pa: [f32; CHANNELS],
    /// The valve inputs' port (the controller's coils through the interface stage).
    valve_levels: ValveLevels,
    /// What the board drives on the controller's lines.
    driven: DrivenOutputs,
    /// The axle speed pulse trains.
    pulses: SpeedSensors,
    noise: u32,
    frames: Vec<ClassicFrame>,
    telemetry: Vec<TelemetryEvent>,
}

impl SimIo {
    /// ADC counts of a pressure through the transducer's nominal characteristic.
    fn counts(p_pa: f32, noise: i32) -> u16 {
        let cal = SensorKind::PressureTransducer.default_calibration();
        let c = cal.offset_counts + p_pa / cal.gain + noise as f32;
        c.round().clamp(0.0, ADC_MAX_COUNTS as f32) as u16
    }

    /// The next -2..=2 of a deterministic noise sequence (a 32-bit LCG).
    fn next_noise(&mut self) -> i32 {
        self.noise = self
            .noise
            .wrapping_mul(1_664_525)
            .wrapping_add(1_013_904_223);
        ((self.noise >> 16) % 5) as i32 - 2
    }
}

impl RigIo for SimIo {
    type Frame = ClassicFrame;

    fn adc_sequence(&mut self) -> Option<[u16; ADC_SEQUENCE_LEN]> {
        let mut seq = [0u16; ADC_SEQUENCE_LEN];
        // Ranks: ch1..ch4, four times (`sensor::split_sequence`).
        for (rank, slot) in seq.iter_mut().enumerate() {
            let n = self.next_noise();
            *slot = Self::counts(self.pressure_pa[rank % CHANNELS], n);
        }
        debug_assert_eq!(ADC_SEQUENCE_LEN, CHANNELS * OVERSAMPLING);
        Some(seq)
    }

    fn set_pulse(&mut self, wheelset: usize, registers: &PulseRegisters) {
        self.pulses.write(wheelset, registers);
    }

    fn queue_frame(&mut self, frame: ClassicFrame) -> bool {
        self.frames.push(frame);
        true
    }

    fn queue_telemetry(&mut self, event: &TelemetryEvent) -> bool {
        self.telemetry.push(*event);
        true
    }

    fn valve_levels(&mut self) -> ValveLevels {
        self.valve_levels
    }

    fn set_controller_outputs(&mut self, outputs: &DrivenOutputs) {
        self.driven = *outputs;
    }
}

/// The brake controller under test: the simulated brake unit on the bus and the train lines.
pub struct SimController {
    params: Params,
    /// Its I/O configuration (the board's, from the `Configure` frames it sees).
    io: IoConfig,
    /// Teeth of its speed sensors' phonic wheels (the board's, from `Configure Teeth`).
    teeth: u16,
    unit: Option<BrakeUnit<f32>>,
    demand: BrakeDemand,
    pressure_pa: [f32; WHEELSETS],
    /// Every speed sensor read zero at the last step.
    was_stopped: bool,
    /// The carbody mass its load weighing found at the last start, kg (None: the air-spring
    /// signals were not valid; it took the configured vehicle's).
    weighed_carbody_kg: Option<f64>,
}

/// A wheel speed above this right after standstill is a new run, m/s (0.5 m/s within a
/// 0.1 ms step is 5000 m/s^2: no braking or traction does it).
const NEW_RUN_JUMP_MPS: f32 = 0.5;

/// What the controller drives: its cylinder pressures and its valve coils.
struct ControllerOut {
    pressure_pa: [f32; WHEELSETS],
    /// Dump and hold coils energised, per wheelset.
    dump: [bool; WHEELSETS],
    hold: [bool; WHEELSETS],
}

impl SimController {
    fn new(io: IoConfig, teeth: u16) -> Self {
        Self {
            params: Params::default(),
            io,
            teeth,
            unit: None,
            demand: BrakeDemand::Emergency,
            pressure_pa: [0.0; WHEELSETS],
            was_stopped: true,
            weighed_carbody_kg: None,
        }
    }

    /// A frame on the bus: the board's configuration and vehicle frames are its own
    /// configuration (a real unit is configured for its train).
    fn on_frame(&mut self, frame: &ClassicFrame) {
        let Ok(c) = CommandFrame::decode(frame) else {
            return;
        };
        match c.command {
            Command::Vehicle { key, value } => match key {
                VehicleKey::Default => self.params.vehicle = Params::default().vehicle,
                key => key.apply(&mut self.params.vehicle, value),
            },
            // The board refuses an inconsistent value; so does this copy.
            Command::Configure(ConfigItem::Io(item, v)) => {
                let _ = self.io.set(item, v);
            }
            Command::Configure(ConfigItem::Teeth(t)) => self.teeth = t.max(1),
            _ => {}
        }
    }

    /// The demand on the train lines the board drives (loop and PWM).
    fn read_demand(&self, lines: &DrivenOutputs) -> BrakeDemand {
        ControllerDemand {
            eb_loop_closed: lines.eb_loop_closed,
            service_mps2: self.io.demand.decode_pwm(&lines.pwm),
        }
        .brake(&self.io.demand)
    }

    /// Load weighing: the carbody mass the two air-spring signals carry (their bogie
    /// forces over g), kg; None when either signal is not valid.
    fn weigh(&self, lines: &DrivenOutputs) -> Option<f64> {
        let load = &self.io.load;
        let force: Option<f64> = lines
            .dac
            .iter()
            .map(|&code| load.read_pa(code).map(|p| load.force_n(p) as f64))
            .sum();
        force.map(|f| f / self.params.vehicle.g)
    }

    /// A unit for a new run: weighed, then built with the demand on the lines.
    fn start_unit(&mut self, lines: &DrivenOutputs) {
        self.weighed_carbody_kg = self.weigh(lines);
        let mut params = self.params;
        if let Some(m) = self.weighed_carbody_kg {
            params.vehicle.carbody_mass = m;
        }
        // The reference unit builds for any vehicle the board accepts (tested in brake-unit).
        self.unit = BrakeUnit::new(&params, &UnitConfig::new(STEP_S)).ok();
        if let Some(u) = &mut self.unit {
            u.set_demand(self.demand);
        }
    }

    /// One plant step of the controller, reading the lines the board drove last and its
    /// speed sensors.
    fn step(&mut self, lines: &DrivenOutputs, sensors: &SpeedSensors) -> ControllerOut {
        let demand = self.read_demand(lines);
        if demand != self.demand {
            self.demand = demand;
            if let Some(u) = &mut self.unit {
                u.set_demand(demand);
            }
        }
        let mut out = ControllerOut {
            pressure_pa: [0.0; WHEELSETS],
            dump: [false; WHEELSETS],
            hold: [false; WHEELSETS],
        };
        // A jump from standstill (every train silent: the board idle, in its safe state or
        // a run finished) to a running speed, which no braking or traction makes within a
        // step, is a new run on the rig: the unit starts afresh and weighs the car. At
        // standstill it keeps its brake as demanded.
        let speeds = sensors.speeds_mps(self.teeth, self.params.vehicle.wheel_radius);
        let stopped = speeds.iter().all(|&v| v <= 0.0);
        let new_run = self.was_stopped && speeds.iter().any(|&v| v > NEW_RUN_JUMP_MPS);
        self.was_stopped = stopped;
        if self.unit.is_none() && stopped {
            return out;
        }
        if self.unit.is_none() || new_run {
            self.start_unit(lines);
        }
        if let Some(u) = &mut self.unit {
            let o = u.step(&speeds);
            self.pressure_pa = o.cylinder_pressure_pa;
            for j in 0..WHEELSETS {
                out.dump[j] = o.valves[j] == Valve::Vent;
                out.hold[j] = o.valves[j] != Valve::Apply;
            }
        }
        out.pressure_pa = self.pressure_pa;
        out
    }
}

/// The simulated board on its in-process bus: a [`Transport`].
pub struct SimBoard {
    rig: Rig,
    io: SimIo,
    controller: SimController,
    tick: u64,
    to_board: VecDeque<ClassicFrame>,
    to_host: VecDeque<Received>,
    probe: Vec<ProbeEvent>,
    faults: SimFaults,
    realtime: Option<Instant>,
    /// Counter the frozen status frames keep.
    frozen_counter: Option<u8>,
}

impl SimBoard {
    pub fn new(faults: SimFaults, realtime: bool) -> Self {
        // The simulated rig has every valve input wired (active low).
        let mut config = RigConfig::nucleo_g474re();
        config.io.valves = ValveWiring::ALL;
        let mut rig = Rig::new(config);
        for s in &mut rig.sensors {
            s.set_kind(SensorKind::PressureTransducer);
        }
        Self {
            rig,
            io: SimIo {
                pressure_pa: [0.0; CHANNELS],
                valve_levels: ValveLevels::of_coils([false; 4], [false; 4], &config.io.valves),
                driven: DrivenOutputs::safe(&config.pulse_timer),
                pulses: SpeedSensors::new(config.pulse_timer),
                noise: 0x2545_F491,
                frames: Vec::new(),
                telemetry: Vec::new(),
            },
            controller: SimController::new(config.io, config.teeth),
            tick: 0,
            to_board: VecDeque::new(),
            to_host: VecDeque::new(),
            probe: Vec::new(),
            faults,
            realtime: realtime.then(Instant::now),
            frozen_counter: None,
        }
    }

    /// The board's logic (for tests that compare what the host saw with the board's state).
    pub fn rig(&self) -> &Rig {
        &self.rig
    }

    /// Each pulse train's whole periods against the settings they were loaded from, over
    /// the session so far: the board's dither keeps their sum within a count or so.
    pub fn pulse_dither_check(&self) -> [DitherCheck; WHEELSETS] {
        self.io.pulses.dither
    }

    /// The carbody mass the controller's load weighing found at its last start, kg.
    pub fn controller_weighed_carbody_kg(&self) -> Option<f64> {
        self.controller.weighed_carbody_kg
    }

    fn reached(&self, at: Option<f64>) -> bool {
        at.is_some_and(|t| self.now_s() >= t)
    }

    /// One tick of the board and the controller.
    fn tick(&mut self) {
        self.tick += 1;
        while let Some(f) = self.to_board.pop_front() {
            self.controller.on_frame(&f);
            // Rejections are in the status frame (`CommandResult`), as on the board.
            let _ = self.rig.command_frame(&f);
        }
        // The board's builder task (thread mode): a requested run is built and handed over
        // between two steps; a build error is in the status frame as on the board.
        let _ = self.rig.build_pending();
        self.io.pulses.run_tick();
        let out = self.controller.step(&self.io.driven, &self.io.pulses);
        self.io.pressure_pa = out.pressure_pa;
        let wiring = self.rig.config().io.valves;
        self.io.valve_levels = ValveLevels::of_coils(out.dump, out.hold, &wiring);
        let started = Instant::now();
        self.rig.step(&mut self.io);

        let cpu_hz = self.rig.config().cpu_hz as f64;
        let period = (cpu_hz / STEP_RATE_HZ as f64) as u64;
        let mut cycles = (started.elapsed().as_secs_f64() * cpu_hz).min(u32::MAX as f64) as u64;
        if self.realtime.is_none() {
            // Not paced: board time is not wall time, a host preemption is no overrun.
            cycles = cycles.min(period - 1);
        }
        let entry = (self.tick * period) as u32;
        self.rig
            .record_timing(entry, entry.wrapping_add(cycles as u32), cycles >= period);
        let t_s = self.now_s();
        let lost = self.reached(self.faults.board_lost_at_s);
        for f in std::mem::take(&mut self.io.frames) {
            self.controller.on_frame(&f);
            if !lost {
                let frame = self.freeze(f);
                self.to_host.push_back(Received { frame, t_s });
            }
        }
        for event in std::mem::take(&mut self.io.telemetry) {
            self.probe.push(ProbeEvent { t_s, event });
        }
        if let Some(start) = self.realtime {
            let ahead = t_s - start.elapsed().as_secs_f64();
            if ahead > 0.002 {
                std::thread::sleep(Duration::from_secs_f64(ahead));
            }
        }
    }

    /// A status frame with its alive counter frozen (from `status_alive_frozen_at_s`).
    fn freeze(&mut self, frame: ClassicFrame) -> ClassicFrame {
        if !self.reached(self.faults.status_alive_frozen_at_s) {
            return frame;
        }
        match StatusFrame::decode(&frame) {
            Ok(mut s) => {
                s.counter = *self.frozen_counter.get_or_insert(s.counter);
                s.encode().unwrap_or(frame)
            }
            Err(_) => frame,
        }
    }
}

impl Transport for SimBoard {
    fn send(&mut self, frame: &ClassicFrame) -> Result<(), TransportError> {
        if self.reached(self.faults.bus_off_at_s) {
            return Err(TransportError::BusOff);
        }
        self.to_board.push_back(*frame);
        Ok(())
    }

    fn receive(&mut self, timeout_s: f64) -> Result<Option<Received>, TransportError> {
        let deadline = self.now_s() + timeout_s;
        loop {
            if self.reached(self.faults.bus_off_at_s) {
                return Err(TransportError::BusOff);
            }
            if let Some(r) = self.to_host.pop_front() {
                return Ok(Some(r));
            }
            if self.now_s() >= deadline {
                return Ok(None);
            }
            self.tick();
        }
    }

    fn now_s(&self) -> f64 {
        self.tick as f64 * TICK_S
    }

    fn take_probe(&mut self) -> Vec<ProbeEvent> {
        std::mem::take(&mut self.probe)
    }

    fn describe(&self) -> String {
        "sim (in-process board, simulated brake unit as the controller under test)".into()
    }
}
