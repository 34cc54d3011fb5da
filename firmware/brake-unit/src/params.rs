//! `[brake_unit]` of the parameter file: the simulated ECU / BOU / WSP's own section
//! (the unit and its EP valve read it; neither owns the other's types).

use hils_plant::keys::{KeyInfo, KeyValue, KeyVisitor, Keys, check_keys};
use hils_plant::params::ParamError;
#[cfg(feature = "serde")]
use serde::Deserialize;

/// `[brake_unit]` of the parameter file: the simulated ECU / BOU / WSP. Field names carry
/// their units; the file's keys are the reference file's (`eb_deceleration`, ...).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(Deserialize), serde(deny_unknown_fields))]
pub struct BrakeUnitParams {
    /// EB deceleration the open-loop pressure is set for, m/s^2 (paper: 5 km/h/s).
    #[cfg_attr(feature = "serde", serde(rename = "eb_deceleration"))]
    pub eb_deceleration_mps2: f64,
    /// Cylinder pressure first-order lag on fill, s.
    #[cfg_attr(feature = "serde", serde(rename = "fill_time_constant"))]
    pub fill_time_constant_s: f64,
    /// Lag when a WSP valve vents, s.
    #[cfg_attr(feature = "serde", serde(rename = "vent_time_constant"))]
    pub vent_time_constant_s: f64,
    /// Pneumatic transport delay, s.
    #[cfg_attr(feature = "serde", serde(rename = "dead_time"))]
    pub dead_time_s: f64,
    /// Whether the ECU sets the pressure through the EP valve with PI control
    /// ([`crate::ep`]); off: the demand acts directly (the unit before issue 13).
    #[cfg_attr(feature = "serde", serde(default = "defaults::ep_valve"))]
    pub ep_valve: bool,
    /// EP valve PI proportional gain.
    #[cfg_attr(feature = "serde", serde(default = "defaults::ep_kp"))]
    pub ep_kp: f64,
    /// EP valve PI integral gain, 1/s.
    #[cfg_attr(feature = "serde", serde(default = "defaults::ep_ki_per_s"))]
    pub ep_ki_per_s: f64,
    /// EP valve hysteresis (play width), Pa.
    #[cfg_attr(feature = "serde", serde(default = "defaults::ep_hysteresis_pa"))]
    pub ep_hysteresis_pa: f64,
    /// Whether the ECU compensates the EP valve's hysteresis.
    #[cfg_attr(feature = "serde", serde(default = "defaults::ep_valve"))]
    pub ep_hysteresis_compensation: bool,
    /// Pilot pressure lag of the EP valve, s.
    #[cfg_attr(feature = "serde", serde(default = "defaults::ep_time_constant_s"))]
    pub ep_time_constant_s: f64,
    /// WSP probe after a slide: the longest fill of one pulse, s (each pulse raises the brake
    /// force by the WSP's `probe_step_share`, [`crate::wsp`]).
    #[cfg_attr(feature = "serde", serde(default = "defaults::reapply_pulse_fill_s"))]
    pub reapply_pulse_fill_s: f64,
    /// WSP probe after a slide: the hold before each pulse's fill, s (longer than the dead
    /// time and the wheel's settling, so that the wheel shows each step's effect).
    #[cfg_attr(feature = "serde", serde(default = "defaults::reapply_pulse_hold_s"))]
    pub reapply_pulse_hold_s: f64,
    /// Deceleration of the highest service brake step, m/s^2.
    #[cfg_attr(feature = "serde", serde(default = "defaults::full_service_mps2"))]
    pub full_service_deceleration_mps2: f64,
    /// Number of service brake steps.
    #[cfg_attr(feature = "serde", serde(default = "defaults::service_steps"))]
    pub service_steps: u8,
}

/// Defaults of the `[brake_unit]` keys added by issue 13 (the reference file predates
/// them). Assumed values: a proportional EP valve of ~15 kPa hysteresis and 30 ms pilot
/// lag; WSP probe pulses of at most 50 ms fill after 100 ms holds (issue 25; 30 / 50 ms
/// before); 7 service steps up to 1.0 m/s^2.
mod defaults {
    pub fn ep_valve() -> bool {
        true
    }
    pub fn ep_kp() -> f64 {
        0.5
    }
    pub fn ep_ki_per_s() -> f64 {
        20.0
    }
    pub fn ep_hysteresis_pa() -> f64 {
        15e3
    }
    pub fn ep_time_constant_s() -> f64 {
        0.03
    }
    pub fn reapply_pulse_fill_s() -> f64 {
        0.05
    }
    pub fn reapply_pulse_hold_s() -> f64 {
        0.1
    }
    pub fn full_service_mps2() -> f64 {
        1.0
    }
    pub fn service_steps() -> u8 {
        7
    }
}

impl Default for BrakeUnitParams {
    fn default() -> Self {
        Self {
            eb_deceleration_mps2: 1.3889,
            fill_time_constant_s: 0.5,
            vent_time_constant_s: 0.15,
            dead_time_s: 0.05,
            ep_valve: defaults::ep_valve(),
            ep_kp: defaults::ep_kp(),
            ep_ki_per_s: defaults::ep_ki_per_s(),
            ep_hysteresis_pa: defaults::ep_hysteresis_pa(),
            ep_hysteresis_compensation: defaults::ep_valve(),
            ep_time_constant_s: defaults::ep_time_constant_s(),
            reapply_pulse_fill_s: defaults::reapply_pulse_fill_s(),
            reapply_pulse_hold_s: defaults::reapply_pulse_hold_s(),
            full_service_deceleration_mps2: defaults::full_service_mps2(),
            service_steps: defaults::service_steps(),
        }
    }
}

impl BrakeUnitParams {
    /// Checks every value against its range (NaN and inf are out of range); the error names
    /// the file's key. The ranges are those of the key table ([`Keys`]).
    pub fn validate(&self) -> Result<(), ParamError> {
        check_keys(self)
    }
}

/// One key of `[brake_unit]`: its file name, doc, unit and range.
const fn key(
    name: &'static str,
    doc: &'static str,
    unit: &'static str,
    min: f64,
    max: f64,
) -> KeyInfo {
    KeyInfo {
        name,
        doc,
        unit,
        min,
        max,
    }
}

/// The key table of `[brake_unit]`, in file order: names as in the file, ranges checked by
/// [`BrakeUnitParams::validate`].
impl Keys for BrakeUnitParams {
    fn visit_keys<V: KeyVisitor>(&mut self, v: &mut V) {
        use KeyValue::{Flag, Real};
        #[rustfmt::skip]
        let reals: [(KeyInfo, &mut f64); 4] = [
            (key("brake_unit.eb_deceleration", "EB deceleration the open-loop (load-weighing) pressure is set for (paper: 5 km/h/s), m/s^2.", "m/s2", 0.01, 10.0), &mut self.eb_deceleration_mps2),
            (key("brake_unit.fill_time_constant", "Cylinder pressure first-order lag on fill, s.", "s", 1e-3, 100.0), &mut self.fill_time_constant_s),
            (key("brake_unit.vent_time_constant", "Cylinder pressure lag when a WSP valve vents, s.", "s", 1e-3, 100.0), &mut self.vent_time_constant_s),
            (key("brake_unit.dead_time", "Pneumatic transport delay, s.", "s", 0.0, 1.0), &mut self.dead_time_s),
        ];
        for (info, value) in reals {
            v.key(&info, Real(value));
        }
        v.key(&KeyInfo::unranged("brake_unit.ep_valve", "Whether the ECU sets the pressure through the EP valve with PI control (off: the demand acts directly)."), Flag(&mut self.ep_valve));
        #[rustfmt::skip]
        let ep: [(KeyInfo, &mut f64); 3] = [
            (key("brake_unit.ep_kp", "EP valve PI proportional gain.", "", 0.0, 10.0), &mut self.ep_kp),
            (key("brake_unit.ep_ki_per_s", "EP valve PI integral gain, 1/s.", "1/s", 0.0, 1000.0), &mut self.ep_ki_per_s),
            (key("brake_unit.ep_hysteresis_pa", "EP valve hysteresis (play width), Pa.", "Pa", 0.0, 1e5), &mut self.ep_hysteresis_pa),
        ];
        for (info, value) in ep {
            v.key(&info, Real(value));
        }
        v.key(
            &KeyInfo::unranged(
                "brake_unit.ep_hysteresis_compensation",
                "Whether the ECU compensates the EP valve's hysteresis.",
            ),
            Flag(&mut self.ep_hysteresis_compensation),
        );
        #[rustfmt::skip]
        let rest: [(KeyInfo, &mut f64); 4] = [
            (key("brake_unit.ep_time_constant_s", "Pilot pressure lag of the EP valve, s.", "s", 1e-3, 1.0), &mut self.ep_time_constant_s),
            (key("brake_unit.reapply_pulse_fill_s", "WSP reapply in pulses: fill time of a pulse, s (0: one continuous refill).", "s", 0.0, 1.0), &mut self.reapply_pulse_fill_s),
            (key("brake_unit.reapply_pulse_hold_s", "WSP reapply in pulses: hold between pulses, s.", "s", 0.0, 1.0), &mut self.reapply_pulse_hold_s),
            (key("brake_unit.full_service_deceleration_mps2", "Deceleration of the highest service brake step, m/s^2.", "m/s2", 0.01, 10.0), &mut self.full_service_deceleration_mps2),
        ];
        for (info, value) in rest {
            v.key(&info, Real(value));
        }
        let mut steps = u32::from(self.service_steps);
        v.key(
            &key(
                "brake_unit.service_steps",
                "Number of service brake steps.",
                "",
                1.0,
                20.0,
            ),
            KeyValue::Count(&mut steps),
        );
        self.service_steps = u8::try_from(steps).unwrap_or(u8::MAX);
    }
}
