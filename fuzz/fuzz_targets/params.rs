//! The parameter loader on arbitrary text: no panic; a file it accepts builds the closed
//! loop (plant and brake unit), and a short EB keeps every output finite.
#![no_main]

use hils_brake_unit::BrakeDemand;
use hils_plant::Rail;
use hils_sil::ClosedLoop;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let Ok(file) = hils::params_file::parse_params(text, "fuzz.toml") else {
        return;
    };
    let v0 = (file.scenario.paper_eb.initial_speed_kmh / 3.6) as f32;
    let mut sim = ClosedLoop::<f32>::from_file(&file, Rail::Wet, v0)
        .expect("a file the loader accepts builds the loop");
    sim.set_demand(BrakeDemand::Emergency);
    for _ in 0..50 {
        sim.step();
        let o = sim.outputs();
        assert!(o.vehicle_speed.is_finite() && o.distance.is_finite());
        for w in &o.wheelsets {
            assert!(w.values().iter().all(|x| x.is_finite()), "{w:?}");
        }
    }
});
