//! Stage 7: the text report of the figures.

use std::fmt::Write;

use super::compare::column_names;
use super::{FrictionCost, TargetCost};

fn opt(x: Option<f64>, digits: usize) -> String {
    x.map_or("-".to_string(), |v| format!("{v:.digits$}"))
}

/// The parts of a step as the report lists them, with their labels.
const PART_LABELS: [(&str, &str); 7] = [
    ("step", "full plant step (Plant::step)"),
    ("contact", "  contact, 4 wheelsets (Eqs 9-12)"),
    ("friction", "  friction, 4 wheelsets (Eq 2)"),
    ("thermal", "  thermal, 4 wheelsets (Eqs 3-6)"),
    ("suspension", "  suspension, bodies, spin (the rest)"),
    ("loop", "closed loop (brake unit + plant)"),
    ("unit", "  brake unit + wiring"),
];

/// The text report.
pub fn report(c: &TargetCost) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "Plant on the emulated Cortex-M4F: {}", c.machine);
    let _ = writeln!(
        s,
        "  math: {}; 1 SysTick tick = {} instructions; timer checked against known loops \
         within {} instructions",
        c.math, c.instructions_per_systick_tick, c.calibration_max_error
    );
    if let Some(o) = &c.opt_level {
        let _ = writeln!(s, "  {}", o.text());
    }
    costs(&mut s, c);
    cycles(&mut s, c);
    let _ = writeln!(s, "Math functions (instructions per call):");
    for f in &c.functions {
        let _ = writeln!(
            s,
            "  {:<6} mean {:5.1} max {:4} ({} arguments)",
            f.name, f.mean, f.max, f.calls
        );
    }
    bit_identity(&mut s, c);
    fidelity(&mut s, c);
    let _ = writeln!(s, "  (emulator wall time {:.1} s)", c.emulator_wall_s);
    s
}

/// Instructions per step, per part and friction model, against the targets.
fn costs(s: &mut String, c: &TargetCost) {
    let _ = writeln!(
        s,
        "Instructions per step, paper EB (150 km/h, wet), every step of the run:"
    );
    let _ = writeln!(
        s,
        "  {:<38} {:>27} {:>27}",
        "", "variable friction", "constant friction"
    );
    for (part, label) in PART_LABELS {
        let cell = |f: &FrictionCost| {
            f.parts.get(part).map_or("-".to_string(), |p| {
                format!("mean {:6.0} max {:5} p99 {:5}", p.mean, p.max, p.p99)
            })
        };
        let _ = writeln!(
            s,
            "  {:<38} {:>27} {:>27}",
            label,
            c.frictions.first().map(cell).unwrap_or_default(),
            c.frictions.get(1).map(cell).unwrap_or_default()
        );
    }
    let met = |ok: bool| if ok { "met" } else { "NOT MET" };
    let _ = writeln!(
        s,
        "  targets: mean <= {} ({:.0}: {}), max <= {} ({}: {})",
        c.target_mean,
        c.instructions_mean,
        met(c.instructions_mean <= c.target_mean),
        c.target_max,
        c.instructions_max,
        met(c.instructions_max <= c.target_max)
    );
    match &c.degraded {
        Some(d) => {
            let _ = writeln!(
                s,
                "  degraded adhesion on, track {} (variable friction, first {} steps of the EB): \
                 mean {:.0} max {} p99 {}; {:+.1} % over the paper EB's mean (target <= +{:.0} %: {})",
                d.track,
                d.steps,
                d.instructions_mean,
                d.instructions_max,
                d.instructions_p99,
                d.increase_percent,
                d.target_increase_percent,
                met(d.within_target)
            );
        }
        None => {
            let _ = writeln!(
                s,
                "  degraded adhesion on: not measured by this emulator binary"
            );
        }
    }
}

/// Estimated cycles per step (CCM SRAM and flash) with the model stated.
fn cycles(s: &mut String, c: &TargetCost) {
    let Some(e) = &c.cycles else {
        let _ = writeln!(
            s,
            "Cycles per step: not estimated ({})",
            c.cycles_error.as_deref().unwrap_or("no profile")
        );
        return;
    };
    let _ = writeln!(
        s,
        "Cycles per step, estimated (executed mix of the first {} step calls, {:.0} \
         instructions each, times the run's mean):",
        e.steps_profiled, e.profile_instructions_per_step
    );
    let _ = writeln!(
        s,
        "  CCM SRAM (zero wait): CPI {:.2}, {:.0} cycles = {:.1} us at 170 MHz ({:.0} % of 100 us)",
        e.cpi_ccm, e.cycles_per_step_ccm, e.us_per_step_ccm, e.us_per_step_ccm
    );
    let _ = writeln!(
        s,
        "  flash, no cache hits: CPI {:.2}, {:.0} cycles = {:.1} us",
        e.cpi_flash, e.cycles_per_step_flash, e.us_per_step_flash
    );
    let _ = writeln!(s, "  model: {}", e.model);
    for (class, i, cyc) in &e.classes {
        let _ = writeln!(s, "    {class:<22} {i:6.0} instructions {cyc:6.0} cycles");
    }
}

/// Host f32 against the emulated target, per friction model.
fn bit_identity(s: &mut String, c: &TargetCost) {
    let _ = writeln!(s, "Host f32 vs emulated target, bit for bit:");
    for f in &c.frictions {
        let cmp = &f.comparison;
        let verdict = if cmp.identical {
            format!(
                "IDENTICAL: {} rows x {} values ({} values; {} also equal to hils simulate's samples)",
                cmp.rows_target,
                column_names().len(),
                cmp.values_compared,
                f.simulate_values_checked
            )
        } else {
            format!(
                "DIFFERENT: {} of {} values, rows {} (target) vs {} (host); first: {:?}",
                cmp.values_different,
                cmp.values_compared,
                cmp.rows_target,
                cmp.rows_host,
                cmp.first_mismatch
            )
        };
        let _ = writeln!(s, "  {:<9} {verdict}", f.friction);
    }
}

/// The f32 run against the f64 reference, per friction model.
fn fidelity(s: &mut String, c: &TargetCost) {
    let _ = writeln!(
        s,
        "Fidelity of the f32 run ({}) against the f64 reference (libm):",
        c.math
    );
    for f in &c.fidelity {
        let _ = writeln!(
            s,
            "  {:<9} stop {} s vs {} s, distance {} m vs {} m ({} %); slides {:?} vs {:?}, \
             onsets differ by <= {} ms; mu_d max |diff| {:.2e}, rms {:.2e}",
            f.friction,
            opt(f.f32.stop_time_s, 4),
            opt(f.f64.stop_time_s, 4),
            opt(f.f32.stopping_distance_m, 2),
            opt(f.f64.stopping_distance_m, 2),
            opt(f.stopping_distance_error_pct, 4),
            f.f32.slides,
            f.f64.slides,
            opt(f.slide_onset_max_diff_ms, 1),
            f.mu_d_max_abs_diff,
            f.mu_d_rms_diff
        );
    }
}
