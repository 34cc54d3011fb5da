//! The plant in a closed loop with the simulated brake unit: what `hils simulate`, the
//! emulated target and the board's self-test mode run (one copy of the wiring).

use hils_plant::params::{ParamError, Params, Rail};
use hils_plant::{BrakeInput, Outputs, Plant, Real, WHEELSETS};

use crate::unit::{BrakeDemand, BrakeUnit, UnitConfig, UnitError, UnitOutputs};

/// Why a closed loop cannot be built.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LoopError {
    Params(ParamError),
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
    pub plant: Plant<F>,
    pub unit: BrakeUnit<F>,
    unit_out: UnitOutputs<F>,
}

impl<F: Real> ClosedLoop<F> {
    /// A loop at the initial speed (m/s) with the step of the parameters.
    pub fn new(params: &Params, rail: Rail, initial_speed: F) -> Result<Self, LoopError> {
        let dt = params.scenario.paper_eb.step;
        Self::with_config(params, rail, initial_speed, &UnitConfig::new(dt))
    }

    pub fn with_config(
        params: &Params,
        rail: Rail,
        initial_speed: F,
        config: &UnitConfig,
    ) -> Result<Self, LoopError> {
        let plant =
            Plant::with_step(params, rail, initial_speed, config.dt).map_err(LoopError::Params)?;
        let unit = BrakeUnit::new(params, config).map_err(LoopError::Unit)?;
        let unit_out = UnitOutputs {
            cylinder_pressure: [F::ZERO; WHEELSETS],
            valves: [crate::Valve::Apply; WHEELSETS],
            venting: [false; WHEELSETS],
            reference_speed: plant.outputs().vehicle_speed,
            demand_pressure: F::ZERO,
        };
        Ok(Self {
            plant,
            unit,
            unit_out,
        })
    }

    pub fn set_demand(&mut self, demand: BrakeDemand) {
        self.unit.set_demand(demand);
    }

    /// One fixed step of unit and plant.
    pub fn step(&mut self) -> &Outputs<F> {
        let speeds = self.plant.wheel_speeds();
        self.unit_out = self.unit.step(&speeds);
        let inputs = self
            .unit_out
            .cylinder_pressure
            .map(BrakeInput::CylinderPressure);
        self.plant.step(&inputs)
    }

    pub fn outputs(&self) -> &Outputs<F> {
        self.plant.outputs()
    }

    pub fn unit_outputs(&self) -> &UnitOutputs<F> {
        &self.unit_out
    }
}
