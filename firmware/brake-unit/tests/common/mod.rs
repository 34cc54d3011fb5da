//! Set-up shared by the brake unit's tests.

use hils_brake_unit::{BrakeDemand, BrakeUnit, UnitConfig};
use hils_plant::{Params, Real, STEP_S};

/// The unit's control step in these tests, s (the plant's 10 kHz step).
pub const DT: f64 = STEP_S;

/// A brake unit with the reference parameters at the 10 kHz step.
pub fn reference_unit<F: Real>() -> BrakeUnit<F> {
    BrakeUnit::<F>::new(&Params::default(), &UnitConfig::new(DT)).unwrap()
}

/// [`reference_unit`] with the emergency brake demanded.
#[allow(dead_code)] // not every test file brakes at once
pub fn emergency_unit<F: Real>() -> BrakeUnit<F> {
    let mut unit = reference_unit();
    unit.set_demand(BrakeDemand::Emergency);
    unit
}
