//! The plant in a closed loop with the simulated brake unit: what `hils simulate`, the
//! emulated target and the board's self-test mode run (one copy of the wiring).

use hils_brake_unit::{BrakeDemand, BrakeUnit, UnitConfig, UnitError, UnitOutputs, Valve};
use hils_plant::params::{ParamError, Params, Rail, STEP_S};
use hils_plant::track::ContactSets;
use hils_plant::{BrakeInput, Flags, Outputs, Plant, Real, Track, TrackAdhesion, WHEELSETS};

use crate::params::ParamFile;

/// Why a closed loop cannot be built; keeps the cause.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum LoopError {
    /// The plant refused its parameters.
    Params(ParamError),
    /// The brake unit refused its configuration.
    Unit(UnitError),
}

impl core::fmt::Display for LoopError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            LoopError::Params(e) => e.fmt(f),
            LoopError::Unit(e) => e.fmt(f),
        }
    }
}

/// Plant + brake unit. The unit reads the wheel speeds of the last step (as axle speed
/// sensors would) and its cylinder pressures drive the plant's brakes through Eq (1).
#[derive(Clone, Debug)]
pub struct ClosedLoop<F: Real> {
    /// The plant.
    pub plant: Plant<F>,
    /// The simulated brake unit.
    pub unit: BrakeUnit<F>,
    unit_out: UnitOutputs<F>,
}

impl<F: Real> ClosedLoop<F> {
    /// A loop of the reference brake unit at the real-time step ([`STEP_S`]), at the
    /// initial speed (m/s).
    pub fn new(params: &Params, rail: Rail, initial_speed: F) -> Result<Self, LoopError> {
        Self::with_config(params, rail, initial_speed, &UnitConfig::new(STEP_S))
    }

    /// A loop of a whole parameter file: its plant, its `[brake_unit]` and its scenario's
    /// step.
    pub fn from_file(file: &ParamFile, rail: Rail, initial_speed: F) -> Result<Self, LoopError> {
        Self::with_config(&file.plant, rail, initial_speed, &file.unit_config())
    }

    /// A loop of a plant and a brake unit configuration (its step is the plant's). Never
    /// inlined: the board builds a run from code in CCM SRAM, and construction must stay a
    /// cold call to flash (firmware/board/ccm.x, size.sh allows `with_config`).
    #[inline(never)]
    pub fn with_config(
        params: &Params,
        rail: Rail,
        initial_speed: F,
        config: &UnitConfig,
    ) -> Result<Self, LoopError> {
        let plant = Plant::with_step(params, rail, initial_speed, config.step_s)
            .map_err(LoopError::Params)?;
        let unit = BrakeUnit::new(params, config).map_err(LoopError::Unit)?;
        let unit_out = UnitOutputs {
            cylinder_pressure_pa: [F::ZERO; WHEELSETS],
            valves: [Valve::Apply; WHEELSETS],
            venting: [false; WHEELSETS],
            reference_speed_mps: plant.vehicle_speed(),
            demand_pressure_pa: F::ZERO,
        };
        Ok(Self {
            plant,
            unit,
            unit_out,
        })
    }

    /// Puts the loop on a track of adhesion zones with the file's `[contact]` and
    /// `[degraded_adhesion]` ([`hils_plant::track`]).
    pub fn set_track(
        &mut self,
        file: &ParamFile,
        track: Track,
        sets: &ContactSets,
    ) -> Result<(), ParamError> {
        let step_s = file.scenario.paper_eb.step_s;
        let v = &file.plant.vehicle;
        file.degraded_adhesion
            .validate_span(v.bogie_base + v.wheel_base)?;
        let adhesion = TrackAdhesion::new(
            &file.plant.contact,
            sets,
            track,
            &file.degraded_adhesion,
            step_s,
        )?;
        self.plant.set_track(adhesion);
        Ok(())
    }

    /// Sets the brake unit's demand.
    pub fn set_demand(&mut self, demand: BrakeDemand) {
        self.unit.set_demand(demand);
    }

    /// One fixed step of unit and plant; returns the plant's flags of the step
    /// ([`Self::outputs`] gives the values).
    pub fn step(&mut self) -> Flags {
        let speeds = self.plant.wheel_speeds();
        self.unit_out = self.unit.step(&speeds);
        let inputs = self
            .unit_out
            .cylinder_pressure_pa
            .map(BrakeInput::CylinderPressure);
        self.plant.step(&inputs)
    }

    /// The plant's outputs after the last step (built on demand, [`Plant::outputs`]).
    pub fn outputs(&self) -> Outputs<F> {
        self.plant.outputs()
    }

    /// The brake unit's outputs of the last step.
    pub fn unit_outputs(&self) -> &UnitOutputs<F> {
        &self.unit_out
    }
}
