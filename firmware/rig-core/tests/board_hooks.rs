//! The hooks the board shell uses besides `RigIo`: drops counted downstream of the step's
//! queues reach the fault flags and are cleared like the others.

use hils_rig_core::can::Command;
use hils_rig_core::rig::{Faults, Rig, RigConfig};

#[test]
fn downstream_drops_set_sticky_flags_until_cleared() {
    let mut rig = Rig::new(RigConfig::nucleo_g474re());
    assert!(
        !rig.faults()
            .intersects(Faults::TELEMETRY_DROPPED | Faults::CAN_TX_DROPPED)
    );
    rig.note_downstream_drops(true, false);
    assert!(rig.faults().intersects(Faults::TELEMETRY_DROPPED));
    assert!(!rig.faults().intersects(Faults::CAN_TX_DROPPED));
    rig.note_downstream_drops(false, true);
    assert!(rig.faults().intersects(Faults::CAN_TX_DROPPED));
    rig.note_downstream_drops(false, false);
    assert!(
        rig.faults()
            .intersects(Faults::TELEMETRY_DROPPED | Faults::CAN_TX_DROPPED),
        "sticky"
    );
    rig.command(Command::ClearFaults).unwrap();
    assert!(!rig.faults().intersects(Faults::TELEMETRY_DROPPED));
    assert!(!rig.faults().intersects(Faults::CAN_TX_DROPPED));
}
