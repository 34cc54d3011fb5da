//! Bad use through the C API: every refusal is `fmi3Error` with a logged message that names
//! the variable, value or rule (logged whatever the debug-logging setting), nothing
//! crashes, and the instance stays usable; the plant's own handling of bad inputs (clamp
//! and flag) stays as it is and is reported as a warning.

mod common;

use std::ffi::c_void;

use common::{ERROR, Fmu, OK, WARNING, resources, var};
use hils_fmu::abi::*;
use hils_sil::ParamFile;

fn fmu(tag: &str) -> Fmu {
    Fmu::new(&resources(tag, &ParamFile::default()))
}

/// The call was refused and logged a message containing every `needle`.
fn refused(f: &Fmu, status: i32, needles: &[&str]) {
    let last = f.last();
    assert_eq!(status, ERROR, "expected fmi3Error, got {status} ({last})");
    for n in needles {
        assert!(last.contains(n), "message `{last}` lacks `{n}`");
    }
    let (s, category, _) = f.messages().last().cloned().unwrap();
    assert_eq!((s, category.as_str()), (ERROR, "logStatusError"));
}

#[test]
fn parameters_out_of_their_range_are_refused_naming_the_key_and_range() {
    let f = fmu("range");
    refused(
        &f,
        f.set_f64("vehicle.carbody_mass", 5e6),
        &["vehicle.carbody_mass", "5000000", "[1000, 1000000]"],
    );
    refused(
        &f,
        f.set_f64("contact.dry.mu_0", f64::NAN),
        &["contact.dry.mu_0", "NaN"],
    );
    refused(
        &f,
        f.set_f64("brake_unit.dead_time", 2.0),
        &["brake_unit.dead_time", "[0, 1]"],
    );
    refused(
        &f,
        f.set_u32("brake.friction_faces", 0),
        &["brake.friction_faces"],
    );
    refused(
        &f,
        f.set_i64("friction.model", 7),
        &["friction.model", "0 = variable, 1 = constant"],
    );
    // The refused values were not taken: the reference vehicle still builds and runs.
    assert_eq!(f.get_f64("vehicle.carbody_mass"), 35000.0);
    // The ranges are the project's: every key's min/max is what validate() refuses outside.
    f.init();
    assert_eq!(f.step(0.0, 1e-3), OK);
}

#[test]
fn a_parameter_set_that_validate_refuses_as_a_whole_is_refused_at_initialisation() {
    let f = fmu("cross");
    // Each key in range, the combination not: the wheelsets of a bogie wider than the bogies.
    assert_eq!(f.set_f64("vehicle.bogie_base", 2.0), OK);
    assert_eq!(f.set_f64("vehicle.wheel_base", 3.0), OK);
    assert_eq!(f.enter_init(), OK);
    refused(&f, f.exit_init(), &["vehicle.wheel_base", "refused"]);
    // Still in Initialization Mode: a valid value lets it go on.
    assert_eq!(f.set_f64("vehicle.wheel_base", 2.5), OK);
    assert_eq!(f.set_f64("vehicle.bogie_base", 14.0), OK);
    assert_eq!(f.exit_init(), OK, "{}", f.last());
}

#[test]
fn a_nan_input_is_refused_and_the_last_valid_value_stays() {
    let f = fmu("nan");
    f.init();
    assert_eq!(f.set_f64("p_cyl3_pa", 2e5), OK);
    refused(
        &f,
        f.set_f64("p_cyl3_pa", f64::NAN),
        &["p_cyl3_pa", "NaN", "last valid value"],
    );
    refused(
        &f,
        f.set_f64("f_clamp1_n", f64::INFINITY),
        &["f_clamp1_n", "inf"],
    );
    assert_eq!(f.get_f64("p_cyl3_pa"), 2e5);
    assert_eq!(f.step(0.0, 1e-3), OK);
    assert!(
        f.get_f64("f_clamp_act3_n") > 0.0,
        "the last valid pressure brakes"
    );
}

#[test]
fn an_input_beyond_the_physical_range_is_clamped_by_the_plant_with_a_warning() {
    let f = fmu("clamp");
    f.init();
    // 10 MPa: far above 1.5 x the 500 kPa supply; the plant clamps and flags it.
    assert_eq!(f.set_f64("p_cyl2_pa", 1e7), OK);
    assert_eq!(f.step(0.0, 1e-3), WARNING);
    let (status, category, message) = f.messages().last().cloned().unwrap();
    assert_eq!((status, category.as_str()), (WARNING, "logStatusWarning"));
    assert!(
        message.contains("wheelset 2") && message.contains("clamped"),
        "{message}"
    );
    assert_ne!(
        f.get_u32("plant_flags") & hils_plant::Flags::INPUT_OUT_OF_RANGE,
        0
    );
    // The clamp force is the one of 1.5 x the supply pressure through Eq (1).
    let b = ParamFile::default().plant.brake;
    let limit = ((b.piston_area * 1.5 * b.supply_pressure - b.retaining_spring_force)
        * b.lever_ratio) as f32;
    assert_eq!(f.get_f64("f_clamp_act2_n") as f32, limit);
    // Told once, not at every step while it lasts.
    assert_eq!(f.step(1e-3, 1e-3), OK);
    // A finite value beyond f32's range (the plant's type) is clamped the same way, not
    // turned into an infinity the plant would hold as "not finite"; a clamp force too.
    let g = fmu("clamp-huge");
    assert_eq!(g.set_i64("brake_input", 1), OK);
    g.init();
    assert_eq!(g.step(0.0, 1e-2), OK);
    for (k, x) in [1e300, -1e300, 3.5e38].into_iter().enumerate() {
        assert_eq!(g.set_f64("f_clamp3_n", x), OK);
        let status = g.step(1e-2 + k as f64 * 1e-3, 1e-3);
        let flags = g.get_u32("plant_flags");
        assert_eq!(
            flags & hils_plant::Flags::INPUT_NOT_FINITE,
            0,
            "{x:e}: {}",
            g.last()
        );
        assert_ne!(flags & hils_plant::Flags::INPUT_OUT_OF_RANGE, 0, "{x:e}");
        if k == 0 {
            assert_eq!(status, WARNING);
            // The time as people read it (110 steps of 0.1 ms, not 0.011000000000000001).
            assert!(
                g.last().contains("clamped") && g.last().contains("step to t = 0.011 s"),
                "{}",
                g.last()
            );
        }
    }
    assert_eq!(g.set_f64("f_clamp3_n", 1e9), OK);
    let t = 1.3e-2;
    assert_eq!(g.step(t, 1e-3), OK);
    let clamped_1e9 = g.get_f64("f_clamp_act3_n");
    assert_eq!(g.set_f64("f_clamp3_n", 1e300), OK);
    assert_eq!(g.step(t + 1e-3, 1e-3), OK);
    assert_eq!(g.get_f64("f_clamp_act3_n"), clamped_1e9);
}

#[test]
fn a_step_size_not_a_multiple_of_the_plant_step_is_refused_with_the_nearest_multiples() {
    let f = fmu("step");
    f.init();
    refused(
        &f,
        f.step(0.0, 2.5e-4),
        &[
            "0.00025",
            "not a multiple",
            "0.0001",
            "0.0002 s and 0.0003 s",
        ],
    );
    refused(&f, f.step(0.0, 0.0), &["positive"]);
    refused(&f, f.step(0.0, -1e-3), &["positive"]);
    refused(&f, f.step(0.0, f64::NAN), &["positive"]);
    refused(&f, f.step(0.5, 1e-3), &["0.5", "the FMU is at 0 s"]);
    // Multiples of 0.1 ms are taken, however the importer summed its time.
    let mut t = 0.0;
    for h in [1e-4, 3e-4, 1e-3, 0.1, 7e-4] {
        assert_eq!(f.step(t, h), OK, "{h}: {}", f.last());
        t += h;
    }
    assert!((f.get_f64("time") - t).abs() < 1e-12);
}

/// Importers' clocks carry rounding: one that sums its time (`t += h`) or runs at a large
/// start time names the FMU's time only to within a few ulps, and its step sizes (differences
/// of two such times) are multiples of 0.1 ms only to within them. Followed, not refused;
/// a time or step that is really another is still refused.
#[test]
fn an_importers_rounded_clock_is_followed_and_a_wrong_time_still_refused() {
    let f = fmu("clock");
    let start = |f: &Fmu, t0: f64| {
        assert_eq!(
            unsafe { fmi3EnterInitializationMode(f.ptr, 0, 0.0, t0, 0, 0.0) },
            OK,
            "{}",
            f.last()
        );
        assert_eq!(f.exit_init(), OK, "{}", f.last());
    };
    // Step sizes as FMPy computes them at a start time of 1e7 s (one ulp: 1.9 ns).
    let t0 = 1e7;
    start(&f, t0);
    for k in 0..100 {
        let (t, next) = (t0 + k as f64 * 1e-3, t0 + (k + 1) as f64 * 1e-3);
        assert_eq!(f.step(t, next - t), OK, "step {k}: {}", f.last());
    }
    assert_eq!(f.get_f64("time"), t0 + 1000.0 * 1e-4);
    // A time summed with `t += h` (at 1e4 s it is 0.4 ns off after 2000 steps).
    assert_eq!(unsafe { fmi3Reset(f.ptr) }, OK);
    let t0 = 1e4;
    start(&f, t0);
    let mut t = t0;
    for k in 0..2000 {
        assert_eq!(f.step(t, 1e-3), OK, "step {k} at {t} s: {}", f.last());
        t += 1e-3;
    }
    assert!((t - f.get_f64("time")).abs() > 1e-10, "the sum drifted");
    // Half a plant step off is another time; 20 ns off a multiple is another step.
    let now = f.get_f64("time");
    refused(&f, f.step(now + 0.6e-4, 1e-3), &["the FMU is at"]);
    refused(&f, f.step(now - 0.6e-4, 1e-3), &["the FMU is at"]);
    refused(&f, f.step(now, 1e-3 + 2e-8), &["not a multiple"]);
    refused(
        &f,
        f.step(now, 0.5e-4),
        &["the smallest multiple is 0.0001 s"],
    );
    assert_eq!(f.step(now, 1e-3), OK, "{}", f.last());
}

/// An input the chosen `brake_input` does not read (clamp forces with the default
/// `cylinder_pressure`, a brake command without the brake unit) would brake with nothing,
/// silently: the step warns, once per input, naming it and what is read.
#[test]
fn an_input_that_brake_input_does_not_read_is_warned_once() {
    let f = fmu("unread");
    // Every input at its start value (0, REL): nothing to warn about.
    f.init();
    assert_eq!(f.step(0.0, 1e-3), OK, "{}", f.last());
    assert_eq!(f.set_f64("f_clamp2_n", 5000.0), OK);
    assert_eq!(f.step(1e-3, 1e-3), WARNING);
    let last = f.last();
    for needle in ["f_clamp2_n", "not read", "brake_input = cylinder_pressure"] {
        assert!(last.contains(needle), "`{last}` lacks `{needle}`");
    }
    assert_eq!(f.step(2e-3, 1e-3), OK, "warned once: {}", f.last());
    assert_eq!(
        f.get_f64("f_clamp_act2_n"),
        0.0,
        "the plant read no clamp force"
    );
    assert_eq!(f.set_i64("cmd", 1), OK);
    assert_eq!(f.step(3e-3, 1e-3), WARNING);
    assert!(f.last().contains("cmd set but not read"), "{}", f.last());
    // In the closed loop the pressures are the unit's: a pressure set is not read.
    let g = fmu("unread-loop");
    assert_eq!(g.set_i64("brake_input", 2), OK);
    assert_eq!(g.set_i64("cmd", 1), OK);
    g.init();
    assert_eq!(g.step(0.0, 1e-3), OK, "{}", g.last());
    assert_eq!(g.set_f64("p_cyl1_pa", 3e5), OK);
    assert_eq!(g.step(1e-3, 1e-3), WARNING);
    assert!(
        g.last()
            .contains("p_cyl1_pa set but not read: brake_input = brake_unit"),
        "{}",
        g.last()
    );
}

#[test]
fn calls_out_of_the_state_machines_order_are_refused() {
    let f = fmu("order");
    refused(&f, f.step(0.0, 1e-3), &["fmi3DoStep", "Instantiated"]);
    refused(
        &f,
        f.exit_init(),
        &["fmi3ExitInitializationMode", "Instantiated"],
    );
    let vr = var("v_ref_mps").vr;
    let mut x = 0.0;
    let s = unsafe { fmi3GetFloat64(f.ptr, &vr, 1, &mut x, 1) };
    refused(&f, s, &["v_ref_mps", "Instantiated"]);
    refused(&f, f.set_f64("time", 1.0), &["time", "cannot be set"]);
    refused(
        &f,
        f.set_f64("v_ref_mps", 1.0),
        &["v_ref_mps", "cannot be set"],
    );
    refused(&f, unsafe { fmi3Terminate(f.ptr) }, &["fmi3Terminate"]);
    f.init();
    refused(
        &f,
        f.enter_init(),
        &["fmi3EnterInitializationMode", "Step Mode"],
    );
    refused(
        &f,
        f.set_f64("brake.supply_pressure", 4e5),
        &["brake.supply_pressure", "Step Mode"],
    );
    refused(
        &f,
        f.set_i64("brake_input", 1),
        &["brake_input", "Step Mode"],
    );
    assert_eq!(unsafe { fmi3Terminate(f.ptr) }, OK);
    refused(&f, f.step(0.0, 1e-3), &["fmi3DoStep", "Terminated"]);
    // Reset: back to the start, usable again.
    assert_eq!(unsafe { fmi3Reset(f.ptr) }, OK);
    f.init();
    assert_eq!(f.step(0.0, 1e-3), OK);
}

#[test]
fn wrong_types_counts_and_pointers_are_refused_not_crashed() {
    let f = fmu("pointers");
    let vr = var("vehicle.carbody_mass").vr;
    let mut n = 0u32;
    refused(
        &f,
        unsafe { fmi3GetUInt32(f.ptr, &vr, 1, &mut n, 1) },
        &["vehicle.carbody_mass", "Float64"],
    );
    refused(
        &f,
        unsafe { fmi3GetFloat64(f.ptr, std::ptr::null(), 2, std::ptr::null_mut(), 2) },
        &["NULL"],
    );
    let mut x = [0.0; 2];
    refused(
        &f,
        unsafe { fmi3GetFloat64(f.ptr, &vr, 1, x.as_mut_ptr(), 2) },
        &["nValues = 2"],
    );
    let bad_vr = 999_999;
    refused(
        &f,
        unsafe { fmi3SetFloat64(f.ptr, &bad_vr, 1, &1.0, 1) },
        &["999999", "not a variable"],
    );
    let mut y = 0f32;
    refused(
        &f,
        unsafe { fmi3GetFloat32(f.ptr, &vr, 1, &mut y, 1) },
        &["no Float32"],
    );
    refused(&f, unsafe { fmi3EnterEventMode(f.ptr) }, &["not supported"]);
    // Any byte is a Boolean (C's bool from a careless importer).
    let flag = var("brake_unit.ep_valve").vr;
    assert_eq!(unsafe { fmi3SetBoolean(f.ptr, &flag, 1, &42u8, 1) }, OK);
    // NULL and foreign instances: an error status, no crash.
    assert_eq!(
        unsafe {
            fmi3DoStep(
                std::ptr::null_mut(),
                0.0,
                1e-3,
                0,
                std::ptr::null_mut(),
                std::ptr::null_mut(),
                std::ptr::null_mut(),
                std::ptr::null_mut(),
            )
        },
        ERROR
    );
    let mut junk = [0u64; 64];
    assert_eq!(
        unsafe { fmi3Terminate(junk.as_mut_ptr() as *mut c_void) },
        ERROR
    );
    unsafe { fmi3FreeInstance(std::ptr::null_mut()) };
}

/// `fmi3FreeInstance` frees only an instance alive: a second free of the same pointer, NULL,
/// or a foreign pointer (even one whose first word is an instance's magic) is nothing; the
/// other instances go on.
#[test]
fn free_instance_twice_null_or_foreign_frees_nothing() {
    let a = fmu("free-a");
    let b = fmu("free-b");
    b.init();
    unsafe { fmi3FreeInstance(a.ptr) };
    unsafe { fmi3FreeInstance(a.ptr) };
    unsafe { fmi3FreeInstance(std::ptr::null_mut()) };
    let mut foreign = vec![0u64; 4096];
    foreign[0] = u64::from_be_bytes(*b"hilsfmu3");
    unsafe { fmi3FreeInstance(foreign.as_mut_ptr() as *mut c_void) };
    assert_eq!(b.step(0.0, 1e-3), OK, "{}", b.last());
    assert!(b.get_f64("v_ref_mps") > 41.0);
    // `a`'s Drop frees it a third time: nothing.
}

#[test]
fn instantiation_refuses_a_wrong_token_and_a_bad_parameter_resource_with_a_message() {
    let f = Fmu::with(
        Some(&resources("token", &ParamFile::default())),
        "{another-build}",
        false,
    );
    assert!(f.ptr.is_null());
    assert!(
        f.last().contains("instantiationToken") && f.last().contains("another-build"),
        "{}",
        f.last()
    );

    let dir = resources("bad-resource", &ParamFile::default());
    std::fs::write(dir.join(hils_fmu::RESOURCE_FILE), "[vehicle]\ng = 1e9\n").unwrap();
    let f = Fmu::with(
        Some(&dir),
        &hils_fmu::description::instantiation_token(),
        false,
    );
    assert!(f.ptr.is_null());
    assert!(f.last().contains("parameters.toml"), "{}", f.last());

    // Model Exchange is not offered: NULL with a message.
    let log: common::Log = Default::default();
    let p = unsafe {
        fmi3InstantiateModelExchange(
            std::ptr::null(),
            std::ptr::null(),
            std::ptr::null(),
            0,
            0,
            &log as *const _ as *mut c_void,
            None,
        )
    };
    assert!(p.is_null());
}

#[test]
fn a_missing_or_bad_params_file_is_refused_naming_the_file_and_key() {
    let f = fmu("params-file");
    refused(
        &f,
        f.set_string("params_file", "/nonexistent/p.toml"),
        &["/nonexistent/p.toml", "cannot read"],
    );
    let bad = std::env::temp_dir().join(format!("hils-fmu-bad-{}.toml", std::process::id()));
    let text = hils_fmu::description::parameter_file(&ParamFile::default(), "a test")
        .replace("wheel_radius = 0.43", "wheel_radius = 7.0");
    std::fs::write(&bad, text).unwrap();
    refused(
        &f,
        f.set_string("params_file", &bad.display().to_string()),
        &["vehicle.wheel_radius", "7"],
    );
    std::fs::remove_file(bad).ok();
}
