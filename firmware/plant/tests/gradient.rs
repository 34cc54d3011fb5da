//! Energy balance on a gradient: the work of gravity along the track (part of
//! `external_power`) plus the loss of kinetic and spring energy equals what the brakes,
//! the contacts and the dampers dissipate. On level track the gradient terms are zero, so
//! the paper scenario's balance does not exercise them.

use hils_plant::{BrakeInput, Params, Plant, Rail};

/// Brakes at a third of the caliper's limit for 3 s from 30 m/s on `permille`; returns the
/// energy lost (start - end + external work) and the dissipated energy, J, and the
/// external work.
fn balance(permille: f64) -> (f64, f64, f64) {
    let mut p = Params::default();
    p.track.gradient_permille = permille;
    let mut plant = Plant::<f64>::new(&p, Rail::Dry, 30.0).unwrap();
    let e0 = plant.energy();
    let dt = plant.dt();
    let input = [BrakeInput::ClampForce(8.0e3); 4];
    let (mut dissipated, mut external) = (0.0, 0.0);
    for _ in 0..30_000 {
        plant.step(&input);
        let o = plant.outputs();
        for w in &o.wheelsets {
            dissipated += (w.brake_power + w.contact_power) * dt;
        }
        dissipated += o.damper_power * dt;
        external += o.external_power * dt;
    }
    let e1 = plant.energy();
    let lost = (e0.kinetic + e0.potential) - (e1.kinetic + e1.potential) + external;
    (lost, dissipated, external)
}

#[test]
fn energy_balance_closes_uphill_and_downhill() {
    let (_, _, level_external) = balance(0.0);
    for permille in [-30.0, 30.0] {
        let (lost, dissipated, external) = balance(permille);
        // The gradient's work is a sizeable part of the balance (m g 0.03 x ~80 m).
        assert!(
            (external - level_external).abs() > 0.1 * dissipated,
            "{permille}: external {external:.0} J vs level {level_external:.0} J"
        );
        assert!(
            (lost - dissipated).abs() < 0.01 * dissipated,
            "{permille} permille: lost {lost:.0} J, dissipated {dissipated:.0} J"
        );
    }
}
