//! The plant on the emulated Cortex-M4F: QEMU `-machine mps2-an386 -cpu cortex-m4`.
//!
//! Runs [`hils_sil::EbScenario`] (the paper's EB, wet rail, 150 km/h) in f32 for both
//! disc-pad friction models and prints over semihosting, one line each:
//!
//! * `H key=value ...`: the header: math implementation, the SysTick calibration;
//! * `K n=N instructions=I`: calibration points (a loop of exactly N instructions, measured);
//! * `F fn=NAME n= sum= max=`: instructions per call of the plant's math functions;
//! * `B friction=F`: a run starts;
//! * `R ...`: a [`hils_sil::TraceRow`] every 10 ms (f32 bit patterns, hex);
//! * `C friction=F part=P n= sum= max= max_step= p50= p99=`: instructions per step of a part
//!   (see [`hils_sil::trace::PARTS`]);
//! * `E friction=F steps= stop_step= rows=`: the run ended;
//! * `D part=step track=low_dry_low n= sum= max= max_step= p50= p99=`: instructions per plant
//!   step with the degraded-adhesion model on ([`hils_plant::track`]), variable friction, on
//!   the low -> dry -> low track of `programmes/wsp-low-adhesion.toml` (the first
//!   [`DEGRADED_STEPS`] steps of the EB: both zone changes under every wheelset);
//! * `G part=rig_step n= sum= max= max_tick= rejected=`: instructions per tick of the rig's
//!   step (`Rig::step` with the tick's command, mock board) over the cost sequence
//!   ([`hils_rig_core::script::CostRun`]);
//! * `X message`: an error (then the program exits with failure).
//!
//! # Counting instructions
//!
//! Under `-icount shift=0` QEMU advances its virtual clock by 2^0 = 1 ns per executed
//! instruction, and the mps2-an386 core clock is 25 MHz, so SysTick (processor clock source)
//! counts down one tick every 40 instructions; the program measures that ratio itself at
//! start (`H ... instructions_per_tick=`; the `H` line also names the math and the
//! optimisation level the image is built at, `opt_level=`). A measurement starts right after a tick edge
//! (spinning on the counter) and ends by counting spin iterations (4 instructions each) up
//! to the next edge, which resolves a duration to a few instructions instead of 40; the
//! constant overhead of the measurement is calibrated and removed, and the `K` lines check
//! the result against loops of known length.

#![cfg_attr(target_os = "none", no_std, no_main)]
// A binary: nothing public to document.
#![allow(missing_docs)]

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!(
        "hils-qemu runs on the emulated Cortex-M4F only: build it with `cargo qemu` \
         (thumbv7em-none-eabihf) and run it with `hils target-cost`"
    );
    std::process::exit(2);
}

#[cfg(target_os = "none")]
mod emulator {
    use core::arch::asm;
    use core::fmt::Write;
    use core::hint::black_box;

    use cortex_m::peripheral::syst::SystClkSource;
    use cortex_m_rt::{ExceptionFrame, entry, exception};
    use cortex_m_semihosting::{debug, hio};
    use hils_plant::friction::DiscPadFriction;
    use hils_plant::thermal::DiscThermal;
    use hils_plant::track::ContactSets;
    use hils_plant::tracked::{TrackedExp, TrackedPow};
    use hils_plant::{BrakeInput, FrictionModel, Surface, Track, WHEELSETS, Zone};
    use hils_sil::trace::{LINE_LEN, PARTS, RECORD_EVERY};
    use hils_sil::{EbScenario, ParamFile, TraceRow};

    /// SysTick current value register.
    const SYST_CVR: u32 = 0xE000_E018;
    /// SysTick counts 24 bits.
    const SYST_MASK: u32 = 0x00FF_FFFF;
    /// Instructions per iteration of the counting spin loop in [`edge_counting`].
    const SPIN_INSTRUCTIONS: u32 = 4;
    /// Steps of the degraded-adhesion run (20 s: past both zone bounds at 120 m and 220 m).
    const DEGRADED_STEPS: u32 = 200_000;
    /// Histogram bin width, instructions.
    const BIN: u32 = 8;
    const BINS: usize = 1024;

    /// Spins until the SysTick counter changes; returns the new value (taken within one
    /// 3-instruction iteration of the tick edge).
    #[inline(always)]
    fn edge() -> u32 {
        let now: u32;
        // SAFETY: reads the SysTick current value register, which is always mapped.
        unsafe {
            asm!(
                "ldr {first}, [{cvr}]",
                "2:",
                "ldr {now}, [{cvr}]",
                "cmp {now}, {first}",
                "beq 2b",
                cvr = in(reg) SYST_CVR,
                first = out(reg) _,
                now = out(reg) now,
                options(nostack),
            );
        }
        now
    }

    /// As [`edge`], also returning the number of spin iterations (4 instructions each).
    #[inline(always)]
    fn edge_counting() -> (u32, u32) {
        let now: u32;
        let spins: u32;
        // SAFETY: as in `edge`.
        unsafe {
            asm!(
                "ldr {first}, [{cvr}]",
                "movs {spins}, #0",
                "2:",
                "ldr {now}, [{cvr}]",
                "adds {spins}, {spins}, #1",
                "cmp {now}, {first}",
                "beq 2b",
                cvr = in(reg) SYST_CVR,
                first = out(reg) _,
                spins = out(reg) spins,
                now = out(reg) now,
                options(nostack),
            );
        }
        (now, spins)
    }

    /// `N` `nop`s (the timer's dithering).
    #[inline(always)]
    fn nops<const N: usize>() {
        // SAFETY: no operands but the count, no effects.
        unsafe { asm!(".rept {n}", "nop", ".endr", n = const N, options(nomem, nostack)) }
    }

    /// A loop of exactly `2 n` instructions (`subs`, `bne`), n >= 1.
    #[inline(always)]
    fn known_loop(n: u32) {
        // SAFETY: register-only loop.
        unsafe {
            asm!(
                "2:",
                "subs {n}, {n}, #1",
                "bne 2b",
                n = inout(reg) n => _,
                options(nomem, nostack),
            );
        }
    }

    /// Instructions of a piece of code from SysTick.
    struct Timer {
        instructions_per_tick: u32,
        /// Instructions the measurement itself adds (an empty measurement).
        overhead: u32,
    }

    impl Timer {
        /// Raw instructions between the start edge and the end of `f` (overhead included).
        #[inline(always)]
        fn raw<R>(&self, f: impl FnOnce() -> R) -> (R, u32) {
            let start = edge();
            let r = f();
            let (end, spins) = edge_counting();
            let ticks = start.wrapping_sub(end) & SYST_MASK;
            let raw = (ticks * self.instructions_per_tick).wrapping_sub(spins * SPIN_INSTRUCTIONS);
            (r, raw)
        }

        /// Instructions of `f` (the measurement's own overhead removed).
        #[inline(always)]
        fn measure<R>(&self, f: impl FnOnce() -> R) -> (R, u32) {
            let (r, raw) = self.raw(f);
            (r, raw.saturating_sub(self.overhead))
        }
    }

    /// Distribution of a part's instructions per step.
    struct Stat {
        n: u32,
        sum: u64,
        max: u32,
        max_step: u32,
        hist: [u32; BINS],
    }

    impl Stat {
        const fn new() -> Self {
            Self {
                n: 0,
                sum: 0,
                max: 0,
                max_step: 0,
                hist: [0; BINS],
            }
        }

        fn add(&mut self, x: u32, step: u32) {
            self.n += 1;
            self.sum += x as u64;
            if x > self.max {
                self.max = x;
                self.max_step = step;
            }
            self.hist[((x / BIN) as usize).min(BINS - 1)] += 1;
        }

        /// Upper edge of the bin holding the q-quantile (q in per mille).
        fn quantile(&self, per_mille: u32) -> u32 {
            let target = (self.n as u64 * per_mille as u64).div_ceil(1000);
            let mut seen = 0u64;
            for (b, &c) in self.hist.iter().enumerate() {
                seen += c as u64;
                if seen >= target {
                    return (b as u32 + 1) * BIN;
                }
            }
            self.max
        }
    }

    /// A line being formatted for the host.
    struct Line {
        buf: [u8; 512],
        len: usize,
    }

    impl Line {
        fn new() -> Self {
            Self {
                buf: [0; 512],
                len: 0,
            }
        }
    }

    impl Write for Line {
        fn write_str(&mut self, s: &str) -> core::fmt::Result {
            let b = s.as_bytes();
            let end = self.len + b.len();
            if end > self.buf.len() {
                return Err(core::fmt::Error);
            }
            self.buf[self.len..end].copy_from_slice(b);
            self.len = end;
            Ok(())
        }
    }

    struct Host {
        out: hio::HostStream,
    }

    impl Host {
        fn send(&mut self, bytes: &[u8]) {
            if self.out.write_all(bytes).is_err() {
                fail_exit();
            }
        }

        fn line(&mut self, args: core::fmt::Arguments) {
            let mut l = Line::new();
            if l.write_fmt(args).is_err() || l.write_str("\n").is_err() {
                self.send(b"X line too long\n");
                fail_exit();
            }
            self.send(&l.buf[..l.len]);
        }

        fn row(&mut self, row: &TraceRow) {
            let mut buf = [0u8; LINE_LEN];
            row.encode(&mut buf);
            self.send(&buf);
        }
    }

    fn fail_exit() -> ! {
        debug::exit(debug::EXIT_FAILURE);
        loop {
            cortex_m::asm::bkpt();
        }
    }

    /// The SysTick ratio and the timer's overhead; prints `H` and `K` lines.
    fn calibrate(host: &mut Host) -> Timer {
        // Instructions per tick from a 2 000 000-instruction loop (the measurement's own few
        // instructions are far below one tick).
        let n = 1_000_000;
        let start = edge();
        known_loop(n);
        let (end, _) = edge_counting();
        let ticks = (start.wrapping_sub(end) & SYST_MASK).max(1);
        let mut timer = Timer {
            instructions_per_tick: (2 * n + ticks / 2) / ticks,
            overhead: 0,
        };
        // Overhead: the mean of empty measurements, each is off by up to one spin iteration
        // depending on where the end edge falls. The emulator is deterministic, so the same
        // empty measurement always falls at the same phase: the measurements are dithered
        // over the phases of the spin by 0-3 `nop`s (their count subtracted), and the mean
        // centres the error to within about one instruction (the compiler may place a
        // store in one variant's window).
        let reps = 16;
        let dithered = |nops: i64, raw: u32| i64::from(raw) - nops;
        let total: i64 = (0..reps)
            .map(|_| {
                dithered(0, timer.raw(|| ()).1)
                    + dithered(1, timer.raw(nops::<1>).1)
                    + dithered(2, timer.raw(nops::<2>).1)
                    + dithered(3, timer.raw(nops::<3>).1)
            })
            .sum();
        let overhead = u32::try_from((total + 2 * reps) / (4 * reps)).unwrap_or(0);
        timer.overhead = overhead;
        host.line(format_args!(
            "H hils-qemu math={} opt_level={} instructions_per_tick={} ticks_for_2000000={} overhead={} spin={}",
            hils_plant::math::IMPLEMENTATION,
            env!("HILS_QEMU_OPT_LEVEL"),
            timer.instructions_per_tick,
            ticks,
            overhead,
            SPIN_INSTRUCTIONS
        ));
        // Check points: loops of exactly 2 n instructions.
        for n in [1u32, 2, 3, 5, 8, 13, 21, 50, 100, 377, 1000, 1500] {
            let ((), got) = timer.measure(|| known_loop(n));
            host.line(format_args!("K n={} instructions={}", 2 * n, got));
        }
        timer
    }

    /// Measures four calls of a sub-model (one per wheelset) with per-wheelset arguments;
    /// `baseline` is the same harness around a trivial function, subtracted.
    #[inline(always)]
    fn four(timer: &Timer, args: &[[f32; 3]; WHEELSETS], f: impl Fn([f32; 3]) -> f32) -> u32 {
        timer
            .measure(|| {
                let mut acc = 0.0f32;
                for a in args {
                    acc += f(black_box(*a));
                }
                black_box(acc);
            })
            .1
    }

    /// As [`four`] for a sub-model that updates a per-wheelset tracker.
    #[inline(always)]
    fn four_tracked(
        timer: &Timer,
        args: &[[f32; 3]; WHEELSETS],
        trackers: &mut [TrackedExp<f32>; WHEELSETS],
        f: impl Fn([f32; 3], &mut TrackedExp<f32>) -> f32,
    ) -> u32 {
        timer
            .measure(|| {
                let mut acc = 0.0f32;
                for (a, t) in args.iter().zip(trackers.iter_mut()) {
                    acc += f(black_box(*a), t);
                }
                black_box(acc);
            })
            .1
    }

    /// As [`four`] for a single call.
    fn one(timer: &Timer, args: &[[f32; 3]; 1], f: impl Fn([f32; 3]) -> f32) -> u32 {
        timer
            .measure(|| {
                black_box(f(black_box(args[0])));
            })
            .1
    }

    fn trivial(a: [f32; 3]) -> f32 {
        a[0] + a[1] + a[2]
    }

    /// Instructions per call of the plant's transcendental functions (whatever
    /// implementation `hils_plant::math` compiled in) over the argument ranges of the
    /// scenario; prints `F fn=NAME n= sum= max= lo= hi=` lines (the math comparison).
    type MathFn<'a> = &'a dyn Fn(f32) -> f32;

    fn function_costs(host: &mut Host, timer: &Timer) {
        use hils_plant::math::{atan_f32, exp_f32, ln_f32};
        // One call inside the harness, minus the harness around an identity function.
        let one = |x: f32, f: &dyn Fn(f32) -> f32| {
            timer
                .measure(|| {
                    black_box(f(black_box(x)));
                })
                .1
        };
        let base = (0..16).map(|i| one(i as f32, &|x| x)).min().unwrap_or(0);
        let ranges: [(&str, f32, f32, MathFn); 3] = [
            // exp: -B|w|, -m_v v_d, -m_T T_d, 0.8 ln v: arguments in [-20, 3].
            ("exp", -20.0, 3.0, &|x| exp_f32(x)),
            // ln: wheel speeds 0.01..45 m/s.
            ("ln", 0.01, 45.0, &|x| ln_f32(x)),
            // atan: k_s eps over the creep range, 1e-3..50.
            ("atan", 1.0e-3, 50.0, &|x| atan_f32(x)),
        ];
        for (name, lo, hi, f) in ranges {
            let n = 1000u32;
            let (mut sum, mut max) = (0u64, 0u32);
            for i in 0..n {
                let x = lo + (hi - lo) * (i as f32 + 0.5) / n as f32;
                let c = one(x, f).saturating_sub(base);
                sum += c as u64;
                max = max.max(c);
            }
            host.line(format_args!(
                "F fn={name} n={n} sum={sum} max={max} lo={lo} hi={hi}"
            ));
        }
    }

    fn friction_name(f: FrictionModel) -> &'static str {
        match f {
            FrictionModel::Variable => "variable",
            FrictionModel::Constant => "constant",
        }
    }

    /// The plant's sub-models timed on their own with each step's values: contact
    /// (Polach Eqs 9-12), disc-pad friction (Eq 2) and disc heat (Eqs 3-6), for the four
    /// wheelsets, with the step's trackers replayed and the harness baselines subtracted.
    struct SubModels {
        fr: DiscPadFriction<f32>,
        th: DiscThermal<f32>,
        polach: hils_plant::contact::Polach<f32>,
        wheel_radius: f32,
        /// Eq (2)'s speed exponent per rad/s of spin, -m_v l_p.
        speed_exponent_per_spin: f32,
        /// Harness cost of four and of one trivial call.
        baseline: u32,
        baseline_one: u32,
        /// The step's trackers of e^(-B|w|), e^(-m_v v_d) and e^(-m_T T_d), replayed from
        /// the same arguments (the measurements follow the step's anchors).
        rail_decay: [TrackedExp<f32>; WHEELSETS],
        speed_decay: [TrackedExp<f32>; WHEELSETS],
        temperature_decay: [TrackedExp<f32>; WHEELSETS],
        /// The step's trackers of v_w^0.8 (Eq 5), replayed likewise.
        speed_power: [TrackedPow<f32>; WHEELSETS],
    }

    impl SubModels {
        fn new(timer: &Timer, file: &ParamFile, sc: &EbScenario<f32>) -> Self {
            let params = &file.plant;
            let fr = DiscPadFriction::<f32>::new(&params.friction);
            let th = DiscThermal::<f32>::new(&params.thermal);
            let friction_radius = params.brake.friction_radius as f32;
            let zero = [[0.5f32, 20.0, 1.0e5]; WHEELSETS];
            let baseline = (0..8)
                .map(|_| four(timer, &zero, trivial))
                .min()
                .unwrap_or(0);
            let baseline_one = (0..8)
                .map(|_| one(timer, &[zero[0]], trivial))
                .min()
                .unwrap_or(0);
            let v_d0 = sc.sim.outputs().wheelsets[0].omega * friction_radius;
            Self {
                speed_decay: [fr.speed_decay_at(v_d0); WHEELSETS],
                temperature_decay: [fr.temperature_decay_at(0.0); WHEELSETS],
                speed_power: [th.speed_power_at(sc.sim.outputs().wheelsets[0].speed); WHEELSETS],
                fr,
                th,
                polach: *sc.sim.plant.polach(),
                wheel_radius: params.vehicle.wheel_radius as f32,
                speed_exponent_per_spin: DiscPadFriction::<f32>::speed_exponent_per_spin(
                    &params.friction,
                    params.brake.friction_radius,
                ),
                baseline,
                baseline_one,
                rail_decay: [TrackedExp::<f32>::default(); WHEELSETS],
            }
        }

        /// Instructions of contact, friction and thermal in the step from `prev` to `cur`.
        fn costs(
            &mut self,
            timer: &Timer,
            prev: &hils_plant::Outputs<f32>,
            cur: &hils_plant::Outputs<f32>,
        ) -> [u32; 3] {
            let (fr, th, polach) = (&self.fr, &self.th, &self.polach);
            let r = self.wheel_radius;
            let (baseline, baseline_one) = (self.baseline, self.baseline_one);
            let w = |o: &hils_plant::Outputs<f32>, j: usize| o.wheelsets[j];
            let contact_args = [0, 1, 2, 3].map(|j| {
                [
                    w(prev, j).slip_velocity,
                    w(prev, j).speed,
                    w(cur, j).axle_load,
                ]
            });
            // Friction and heat as the step computes them: Eq (2) from its brackets and
            // Eq (5) with the loss coefficient, one of which the step refreshes for one
            // wheelset (`slow`) in an 8-step turn, plus that refresh.
            let turn = prev.steps % (2 * WHEELSETS as u32);
            let slow = (turn % WHEELSETS as u32) as usize;
            let friction_args = [0, 1, 2, 3].map(|j| {
                [
                    // mu_d_of_brackets has no data-dependent path: any bracket value.
                    w(cur, j).mu_d,
                    w(cur, j).clamp_force,
                    0.0,
                ]
            });
            let brackets_args = [
                self.speed_exponent_per_spin * w(prev, slow).omega.abs(),
                w(prev, slow).disc_temp,
            ];
            let thermal_args = [0, 1, 2, 3].map(|j| {
                [
                    w(cur, j).brake_power,
                    w(prev, j).disc_temp,
                    0.0, // any loss coefficient: rate_with has no data-dependent path
                ]
            });
            let refresh_args = [[w(prev, slow).disc_temp, r * w(prev, slow).omega, 0.0]; 1];
            let contact = four_tracked(timer, &contact_args, &mut self.rail_decay, |a, d| {
                let mu = polach.friction_tracked(a[0], d);
                let c = polach.evaluate_with_mu(a[0], a[1], a[2], mu);
                c.chord + c.mu + c.creepage
            })
            .saturating_sub(baseline);
            let refresh_friction = turn < WHEELSETS as u32;
            let refresh = if refresh_friction {
                let speed_decay = &mut self.speed_decay[slow];
                let temperature_decay = &mut self.temperature_decay[slow];
                timer
                    .measure(|| {
                        let [x, t_d] = black_box(brackets_args);
                        let t = fr.scaled_temperature_factor_tracked(t_d, temperature_decay);
                        black_box(fr.scaled_brackets_tracked(x, t, speed_decay));
                    })
                    .1
            } else {
                baseline_one
            };
            let friction = (four(timer, &friction_args, |a| fr.mu_d_of_brackets(a[0], a[1]))
                + refresh)
                .saturating_sub(baseline + baseline_one);
            let thermal = (four(timer, &thermal_args, |a| th.rate_with(a[0], a[1], a[2]))
                + if refresh_friction {
                    baseline_one
                } else {
                    let power = &mut self.speed_power[slow];
                    timer
                        .measure(|| {
                            let a = black_box(refresh_args[0]);
                            black_box(th.loss_coefficient_tracked(a[1], power));
                        })
                        .1
                })
            .saturating_sub(baseline + baseline_one);
            [contact, friction, thermal]
        }
    }

    /// The paper scenario under `friction` on the target: its trace rows (`R`), the cost of
    /// each part of every step ([`PARTS`], `C` lines) and the end (`E`).
    fn run(host: &mut Host, timer: &Timer, friction: FrictionModel) {
        let name = friction_name(friction);
        let mut file = ParamFile::default();
        file.plant.friction.model = friction;
        let Ok(mut sc) = EbScenario::<f32>::new(&file, RECORD_EVERY) else {
            host.line(format_args!(
                "X friction={name}: cannot build the closed loop"
            ));
            fail_exit();
        };
        let mut models = SubModels::new(timer, &file, &sc);
        host.line(format_args!(
            "B friction={name} harness_baseline={}",
            models.baseline
        ));
        host.row(&TraceRow::of(&sc.sim));
        let mut stats = [const { Stat::new() }; PARTS.len()];
        let mut rows = 1u32;
        loop {
            let prev = sc.sim.outputs();
            let mut replay = sc.sim.plant.clone();
            let mut loop_cost = 0;
            let adv = sc.advance(|sim| {
                loop_cost = timer
                    .measure(|| {
                        sim.step();
                    })
                    .1;
            });
            let step = sc.steps();
            let step_cost = replay_cost(host, timer, &sc, &mut replay);
            let [contact, friction, thermal] = models.costs(timer, &prev, &sc.sim.outputs());
            let suspension = step_cost.saturating_sub(contact + friction + thermal);
            let unit = loop_cost.saturating_sub(step_cost);
            for (k, x) in [
                step_cost, loop_cost, contact, friction, thermal, suspension, unit,
            ]
            .into_iter()
            .enumerate()
            {
                stats[k].add(x, step);
            }
            if adv.record {
                host.row(&TraceRow::of(&sc.sim));
                rows += 1;
            }
            if adv.done {
                break;
            }
        }
        report(host, name, &stats, &sc, rows);
    }

    /// The `C` line of each part and the `E` line of a run.
    fn report(host: &mut Host, name: &str, stats: &[Stat], sc: &EbScenario<f32>, rows: u32) {
        for (k, s) in stats.iter().enumerate() {
            host.line(format_args!(
                "C friction={name} part={} n={} sum={} max={} max_step={} p50={} p99={}",
                PARTS[k],
                s.n,
                s.sum,
                s.max,
                s.max_step,
                s.quantile(500),
                s.quantile(990)
            ));
        }
        match sc.stop_step() {
            Some(s) => host.line(format_args!(
                "E friction={name} steps={} stop_step={s} rows={rows}",
                sc.steps()
            )),
            None => host.line(format_args!(
                "E friction={name} steps={} stop_step=none rows={rows}",
                sc.steps()
            )),
        }
    }

    /// Instructions of the plant step alone, on `replay` (a copy of the plant before the step
    /// the loop just took) with the brake unit's outputs of that step; the replay must give
    /// the loop's outputs exactly.
    fn replay_cost(
        host: &mut Host,
        timer: &Timer,
        sc: &EbScenario<f32>,
        replay: &mut hils_plant::Plant<f32>,
    ) -> u32 {
        let inputs = sc
            .sim
            .unit_outputs()
            .cylinder_pressure_pa
            .map(BrakeInput::CylinderPressure);
        let ((), cost) = timer.measure(|| {
            replay.step(black_box(&inputs));
        });
        if replay.outputs() != sc.sim.outputs() {
            host.line(format_args!(
                "X the replayed plant step {} differs",
                sc.steps()
            ));
            fail_exit();
        }
        cost
    }

    /// Instructions per plant step with degraded adhesion on, on the low -> dry -> low track
    /// (`programmes/wsp-low-adhesion.toml`'s `low_dry_low`), variable friction: the `D` line.
    fn degraded_cost(host: &mut Host, timer: &Timer) {
        let mut file = ParamFile::default();
        file.plant.friction.model = FrictionModel::Variable;
        file.degraded_adhesion.enabled = true;
        let zones = [Zone {
            start_m: 120.0,
            end_m: 220.0,
            surface: Surface::Dry,
        }];
        let Ok(track) = Track::new(Surface::Low, &zones) else {
            host.line(format_args!("X degraded: bad track"));
            fail_exit();
        };
        let Ok(mut sc) = EbScenario::<f32>::new(&file, RECORD_EVERY) else {
            host.line(format_args!("X degraded: cannot build the closed loop"));
            fail_exit();
        };
        if sc
            .sim
            .set_track(&file, track, &ContactSets::default())
            .is_err()
        {
            host.line(format_args!("X degraded: cannot set the track"));
            fail_exit();
        }
        let mut stat = Stat::new();
        loop {
            let mut replay = sc.sim.plant.clone();
            let adv = sc.advance(|sim| {
                sim.step();
            });
            let cost = replay_cost(host, timer, &sc, &mut replay);
            stat.add(cost, sc.steps());
            if adv.done || sc.steps() >= DEGRADED_STEPS {
                break;
            }
        }
        host.line(format_args!(
            "D part=step track=low_dry_low n={} sum={} max={} max_step={} p50={} p99={}",
            stat.n,
            stat.sum,
            stat.max,
            stat.max_step,
            stat.quantile(500),
            stat.quantile(990)
        ));
    }

    /// Instructions of each tick of the rig's cost sequence: the command and the step, as
    /// the board's step interrupt runs them; the build of a requested run happens between
    /// ticks (thread mode on the board) and is not counted.
    fn rig_cost(host: &mut Host, timer: &Timer) {
        let mut run = hils_rig_core::script::CostRun::new();
        let (mut n, mut sum, mut max, mut max_tick) = (0u32, 0u64, 0u32, 0u32);
        loop {
            let (more, cost) = timer.measure(|| run.tick());
            if !more {
                break;
            }
            run.between_ticks();
            if cost > max {
                (max, max_tick) = (cost, n);
            }
            sum += cost as u64;
            n += 1;
        }
        host.line(format_args!(
            "G part=rig_step n={n} sum={sum} max={max} max_tick={max_tick} rejected={}",
            run.rejected()
        ));
    }

    #[entry]
    fn main() -> ! {
        let Some(mut p) = cortex_m::Peripherals::take() else {
            fail_exit()
        };
        // The FPU: cortex-m-rt's reset handler grants CP10/CP11 full access for
        // -eabihf targets before `main`; set it again (idempotent) and check, since every
        // f32 operation of the plant would fault without it.
        // SAFETY: CPACR write enabling the FPU coprocessors, no other effect.
        unsafe {
            p.SCB.cpacr.modify(|v| v | (0b1111 << 20));
        }
        cortex_m::asm::dsb();
        cortex_m::asm::isb();
        let Ok(out) = hio::hstdout() else { fail_exit() };
        let mut host = Host { out };
        if p.SCB.cpacr.read() & (0b1111 << 20) != (0b1111 << 20) {
            host.send(b"X the FPU (CPACR CP10/CP11) could not be enabled\n");
            fail_exit();
        }
        // SysTick free-running from the processor clock, no interrupt.
        p.SYST.disable_interrupt();
        p.SYST.set_clock_source(SystClkSource::Core);
        p.SYST.set_reload(SYST_MASK);
        p.SYST.clear_current();
        p.SYST.enable_counter();

        let timer = calibrate(&mut host);
        function_costs(&mut host, &timer);
        for friction in [FrictionModel::Variable, FrictionModel::Constant] {
            run(&mut host, &timer, friction);
        }
        degraded_cost(&mut host, &timer);
        rig_cost(&mut host, &timer);
        debug::exit(debug::EXIT_SUCCESS);
        loop {
            cortex_m::asm::bkpt();
        }
    }

    #[exception]
    unsafe fn HardFault(frame: &ExceptionFrame) -> ! {
        if let Ok(mut out) = hio::hstdout() {
            let mut l = Line::new();
            let _ = writeln!(l, "X hard fault at pc {:#010x}", frame.pc());
            let _ = out.write_all(&l.buf[..l.len]);
        }
        fail_exit()
    }

    #[panic_handler]
    fn panic(info: &core::panic::PanicInfo) -> ! {
        if let Ok(mut out) = hio::hstdout() {
            let mut l = Line::new();
            let _ = writeln!(l, "X panic: {}", info.message());
            let _ = out.write_all(&l.buf[..l.len]);
        }
        fail_exit()
    }
}
