//! The arming gate: the one place that decides whether the outputs a real brake controller
//! reads are live.
//!
//! **Controller-facing outputs** are every signal the controller under test takes as an
//! input from the rig: the four axle-speed pulse trains, the wheel speeds in
//! `RIG_WHEEL_SPEED_12`/`_34`, and every controller output the controller I/O adds (the
//! emergency-brake loop, the PWM service demand, the DAC air-spring pressure). They are
//! live only when [`ArmingGate::outputs_live`] says so; otherwise each holds its safe value
//! (pulse trains silent, wheel speeds "not available", the controller I/O's own safe
//! values). `RIG_STATUS`, `RIG_DIAG` and `RIG_HEALTH` are for the operator and are always
//! sent: a controller must not use them as a speed source.
//!
//! **The rule.** Outputs are live only while the gate is armed *and* a rig-mode run is
//! `Running` or `Finished` (at rest after the run: speeds 0.00 km/h) *and* that run was
//! started armed with the gate armed ever since ([`ArmingGate::run_started`]). So arming
//! makes nothing live by itself: an `Arm` in `Finished` (after a `Disarm`), or a start
//! whose build failed and left the rig in the `Finished` of the run before, keeps every
//! output safe until a new rig-mode run starts. A self-test run (the
//! board's own simulated brake unit closes the loop, started by a `Start` in self-test
//! mode, the user button or `selftest-autostart`) never drives them, armed or not.
//!
//! **Arming** happens only by the explicit `Arm` command ([`ArmingGate::arm`]), refused
//! while a run is starting or running, in `Fault`, or with a latched fault. Nothing else
//! arms: not a start, not the button, not a reset.
//!
//! **Disarming** ([`ArmingGate::disarm`], with the reason kept for `RIG_HEALTH`):
//! * every reset: the gate lives in zeroed RAM (`.bss`, in the rig), never in memory that
//!   survives a reset, and [`ArmingGate::new`] is disarmed ([`Disarm::Reset`]);
//! * every fault: a run going to `Fault`, a latched sensor fault, a board fault
//!   ([`Disarm::Fault`]);
//! * every safe state by command: `Stop` ([`Disarm::Stop`]);
//! * a self-test start: the controller is not in that loop ([`Disarm::SelfTest`]);
//! * the `Disarm` command ([`Disarm::Command`]).
//!
//! Re-arming after any of these takes a new `Arm` command.

use num_enum::{IntoPrimitive, TryFromPrimitive};

use crate::can::{RigMode, RigState};

/// Why the gate is disarmed (3 bits, `DisarmCause` in `RIG_HEALTH`; codes in declaration order).
#[derive(Clone, Copy, Debug, PartialEq, Eq, IntoPrimitive, TryFromPrimitive)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum Disarm {
    /// Power-up or any other reset: the gate is never kept across a reset.
    Reset = 0,
    /// The `Disarm` command.
    Command,
    /// A fault: a run went to `Fault`, a sensor fault latched, or the board found a fault.
    Fault,
    /// The safe state by command (`Stop`).
    Stop,
    /// A self-test run was started (the board's simulated brake unit closes that loop).
    SelfTest,
}

/// Why an `Arm` command was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ArmRefused {
    /// A run is starting or running: arm before the start, not during a run.
    Busy(RigState),
    /// The rig is in `Fault` or a fault is latched: clear the faults first.
    Faulted,
}

/// The arming gate of the controller-facing outputs (module doc).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ArmingGate {
    /// `None` while armed; else why not.
    disarmed: Option<Disarm>,
    /// The current run is a rig-mode run started armed, and the gate stayed armed since.
    run_armed: bool,
}

impl Default for ArmingGate {
    fn default() -> Self {
        Self::new()
    }
}

impl ArmingGate {
    /// The gate at power-up and after every reset: disarmed ([`Disarm::Reset`]).
    pub const fn new() -> Self {
        Self {
            disarmed: Some(Disarm::Reset),
            run_armed: false,
        }
    }

    /// The `Arm` command: arms unless a run is starting or running (`Busy`), or the rig is
    /// in `Fault` or has a latched fault (`Faulted`). Arming an armed gate is accepted.
    pub fn arm(&mut self, state: RigState, fault_latched: bool) -> Result<(), ArmRefused> {
        match state {
            RigState::Starting | RigState::Running => Err(ArmRefused::Busy(state)),
            RigState::Fault => Err(ArmRefused::Faulted),
            _ if fault_latched => Err(ArmRefused::Faulted),
            _ => {
                self.disarmed = None;
                Ok(())
            }
        }
    }

    /// Disarms (keeps the first reason while disarmed: a `Stop` after a fault still reads
    /// `Fault`).
    pub fn disarm(&mut self, why: Disarm) {
        if self.disarmed.is_none() {
            self.disarmed = Some(why);
        }
        self.run_armed = false;
    }

    /// A run begins (installed, `Running`): its outputs may go live only if it is a
    /// rig-mode run and the gate is armed now.
    pub fn run_started(&mut self, mode: RigMode) {
        self.run_armed = self.is_armed() && mode == RigMode::Rig;
    }

    /// A new start was requested: the run before no longer drives anything, whatever
    /// becomes of the request (a failed build goes back to the state before).
    pub fn run_left(&mut self) {
        self.run_armed = false;
    }

    /// Whether the gate is armed.
    pub fn is_armed(&self) -> bool {
        self.disarmed.is_none()
    }

    /// Why the gate is disarmed (`None` while armed).
    pub fn disarmed_by(&self) -> Option<Disarm> {
        self.disarmed
    }

    /// Whether the controller-facing outputs are live now: armed, and a rig-mode run started
    /// armed is `Running` or `Finished`. Everything a controller reads follows this one
    /// answer.
    pub fn outputs_live(&self, state: RigState, mode: RigMode) -> bool {
        self.is_armed()
            && self.run_armed
            && mode == RigMode::Rig
            && matches!(state, RigState::Running | RigState::Finished)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const STATES: [RigState; 6] = [
        RigState::Idle,
        RigState::Running,
        RigState::Finished,
        RigState::Stopped,
        RigState::Fault,
        RigState::Starting,
    ];

    #[test]
    fn disarmed_at_power_up_and_nothing_is_live() {
        let g = ArmingGate::new();
        assert_eq!(g, ArmingGate::default());
        assert_eq!(g.disarmed_by(), Some(Disarm::Reset));
        for s in STATES {
            for m in [RigMode::Rig, RigMode::SelfTest] {
                assert!(!g.outputs_live(s, m), "{s:?} {m:?}");
            }
        }
    }

    #[test]
    fn live_only_armed_in_a_rig_mode_run() {
        let mut g = ArmingGate::new();
        assert_eq!(g.arm(RigState::Idle, false), Ok(()));
        // Armed, but no run started armed: nothing is live, in any state.
        for s in STATES {
            assert!(!g.outputs_live(s, RigMode::Rig), "{s:?}");
        }
        g.run_started(RigMode::Rig);
        for s in STATES {
            let want = matches!(s, RigState::Running | RigState::Finished);
            assert_eq!(g.outputs_live(s, RigMode::Rig), want, "{s:?}");
            // A self-test run never drives the controller, armed or not.
            assert!(!g.outputs_live(s, RigMode::SelfTest), "{s:?}");
        }
    }

    #[test]
    fn arming_is_refused_during_a_run_and_with_faults() {
        let mut g = ArmingGate::new();
        for s in [RigState::Starting, RigState::Running] {
            assert_eq!(g.arm(s, false), Err(ArmRefused::Busy(s)));
        }
        assert_eq!(g.arm(RigState::Fault, false), Err(ArmRefused::Faulted));
        assert_eq!(g.arm(RigState::Stopped, true), Err(ArmRefused::Faulted));
        assert!(!g.is_armed());
        for s in [RigState::Idle, RigState::Finished, RigState::Stopped] {
            let mut g = ArmingGate::new();
            assert_eq!(g.arm(s, false), Ok(()), "{s:?}");
            assert!(g.is_armed());
        }
    }

    #[test]
    fn every_disarm_needs_a_new_arm_and_keeps_its_first_reason() {
        for why in [
            Disarm::Command,
            Disarm::Fault,
            Disarm::Stop,
            Disarm::SelfTest,
            Disarm::Reset,
        ] {
            let mut g = ArmingGate::new();
            g.arm(RigState::Idle, false).unwrap();
            g.disarm(why);
            assert_eq!(g.disarmed_by(), Some(why));
            assert!(!g.outputs_live(RigState::Running, RigMode::Rig));
            // A later disarm does not hide the first reason.
            g.disarm(Disarm::Command);
            assert_eq!(g.disarmed_by(), Some(why));
            g.arm(RigState::Stopped, false).unwrap();
            // Arming again makes nothing live until a run starts armed.
            assert!(!g.outputs_live(RigState::Finished, RigMode::Rig));
            g.run_started(RigMode::Rig);
            assert!(g.outputs_live(RigState::Running, RigMode::Rig));
        }
    }

    #[test]
    fn arming_after_a_run_or_a_new_request_makes_nothing_live() {
        let mut g = ArmingGate::new();
        g.arm(RigState::Idle, false).unwrap();
        g.run_started(RigMode::Rig);
        assert!(g.outputs_live(RigState::Finished, RigMode::Rig));
        // Disarmed and armed again at rest after the run: safe.
        g.disarm(Disarm::Command);
        g.arm(RigState::Finished, false).unwrap();
        assert!(!g.outputs_live(RigState::Finished, RigMode::Rig));
        // A new request leaves the run before, even if its build fails.
        g.run_started(RigMode::Rig);
        g.run_left();
        assert!(!g.outputs_live(RigState::Finished, RigMode::Rig));
        // A self-test run started armed never drives them.
        g.run_started(RigMode::SelfTest);
        assert!(!g.outputs_live(RigState::Running, RigMode::SelfTest));
        assert!(!g.outputs_live(RigState::Running, RigMode::Rig));
    }

    #[test]
    fn disarm_codes_are_the_frame_codes() {
        for (code, why) in [
            (0u8, Disarm::Reset),
            (1, Disarm::Command),
            (2, Disarm::Fault),
            (3, Disarm::Stop),
            (4, Disarm::SelfTest),
        ] {
            assert_eq!(u8::from(why), code);
            assert_eq!(Disarm::try_from(code), Ok(why));
        }
        assert!(Disarm::try_from(5u8).is_err());
    }
}
