//! Set-up shared by the brake unit's tests.

use hils_brake_unit::{BrakeDemand, BrakeUnit, UnitConfig};
use hils_plant::{Params, Real, STEP_S};

/// The unit's control step in these tests, s (the plant's 10 kHz step).
pub const DT: f64 = STEP_S;

/// A brake unit with the reference parameters at the 10 kHz step.
#[allow(dead_code)] // not every test file uses it
pub fn reference_unit<F: Real>() -> BrakeUnit<F> {
    BrakeUnit::<F>::new(&Params::default(), &UnitConfig::new(DT)).unwrap()
}

/// [`reference_unit`] without the EP valve: the demand acts directly on the relay valve
/// and cylinder (their lags alone, without the EP valve's PI loop and pilot lag).
#[allow(dead_code)] // not every test file isolates the cylinder
pub fn relay_only_unit<F: Real>() -> BrakeUnit<F> {
    let mut config = UnitConfig::new(DT);
    config.params.ep_valve = false;
    BrakeUnit::<F>::new(&Params::default(), &config).unwrap()
}

/// [`reference_unit`] with the emergency brake demanded.
#[allow(dead_code)] // not every test file brakes at once
pub fn emergency_unit<F: Real>() -> BrakeUnit<F> {
    let mut unit = reference_unit();
    unit.set_demand(BrakeDemand::Emergency);
    unit
}
