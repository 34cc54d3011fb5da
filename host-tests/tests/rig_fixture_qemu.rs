//! Regenerates the telemetry fixture of `hils decode` from the current sources (the
//! thumbv7em build of firmware/rig-fixture, run in QEMU netduinoplus2) and checks that the
//! fresh defmt frames decode to the host's telemetry bit for bit, like the committed ones.
//!
//! Needs the thumbv7em-none-eabihf target, qemu-system-arm and llvm-objcopy, so its test is
//! ignored unless asked for (CI: `cargo test -p host-tests --test rig_fixture_qemu --
//! --ignored`). To refresh the committed fixture: `bash firmware/rig-fixture/make-fixture.sh`.

use std::path::PathBuf;
use std::process::Command;

use hils::decode::rig_core::hw::TelemetryEvent;
use hils::decode::rig_core::script;
use hils::decode::{defmt_to_text, parse_runs};

#[test]
#[ignore = "needs qemu-system-arm and the thumbv7em target: run with -- --ignored (CI: .ci/run)"]
fn fresh_target_build_in_qemu_decodes_to_the_host_telemetry() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let out = std::env::temp_dir().join(format!("hils-rig-fixture-{}", std::process::id()));
    let status = Command::new("bash")
        .arg(root.join("firmware/rig-fixture/make-fixture.sh"))
        .arg(&out)
        .current_dir(&root)
        .status()
        .expect("run make-fixture.sh");
    assert!(status.success(), "make-fixture.sh failed");
    let elf = std::fs::read(out.join("rig-fixture.elf")).unwrap();
    let raw = std::fs::read(out.join("telemetry.defmt")).unwrap();
    let text = defmt_to_text(&elf, &raw).unwrap();
    assert_eq!(text.malformed_frames, 0);
    assert!(
        text.lines.last().unwrap().starts_with("fixture done"),
        "{:?}",
        text.lines.last()
    );
    let runs = parse_runs(text.lines.iter().map(String::as_str)).unwrap();
    assert_eq!(runs.len(), 1);
    let mut host = Vec::new();
    script::run(|e| {
        if let TelemetryEvent::Record(r) = e {
            host.push(*r)
        }
    });
    assert_eq!(runs[0].records.len(), host.len());
    for (t, h) in runs[0].records.iter().zip(&host) {
        // Record equality with NaN-free values compares every field exactly.
        assert_eq!(format!("{t:?}"), format!("{h:?}"), "step {}", h.step);
        assert_eq!(t.v_ref.to_bits(), h.v_ref.to_bits());
        assert_eq!(t.omega.map(f32::to_bits), h.omega.map(f32::to_bits));
        assert_eq!(t.mu_d.map(f32::to_bits), h.mu_d.map(f32::to_bits));
    }
    std::fs::remove_dir_all(&out).ok();
}
