//! The paper scenario's driver on its own.

use hils_plant::FrictionModel;
use hils_sil::EbScenario;
use hils_sil::trace::RECORD_EVERY;

/// A scenario whose step function does not advance the plant ends at once instead of
/// recording the same state forever (the driver counts the plant's steps).
#[test]
fn driver_stops_when_the_plant_does_not_advance() {
    let mut sc = EbScenario::<f32>::paper(FrictionModel::Variable, RECORD_EVERY).expect("scenario");
    let adv = sc.advance(|_| {});
    assert!(adv.done && !adv.record);
    assert_eq!(sc.steps(), 0);
}
