//! Stage 3: parse what the emulator printed (`H`, `K`, `F`, `B`, `R`, `C`, `E`, `D`, `G`, `X` lines;
//! see `firmware/qemu/src/main.rs`).

use anyhow::{Result, anyhow, bail};
use hils_sil::TraceRow;
use serde::Serialize;

/// Distribution of one part's instructions per step over a run.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct PartCost {
    /// Steps measured.
    pub n: u64,
    pub mean: f64,
    pub max: u32,
    /// Step (1-based) at which the maximum occurred.
    pub max_step: u32,
    /// Median and 99th percentile (upper edge of an 8-instruction bin).
    pub p50: u32,
    pub p99: u32,
}

/// One friction model's run on the emulator.
#[derive(Clone, Debug, Default)]
pub struct TargetRun {
    pub friction: String,
    pub rows: Vec<TraceRow>,
    /// Costs in the order of [`hils_sil::trace::PARTS`].
    pub parts: Vec<(String, PartCost)>,
    pub steps: u32,
    pub stop_step: Option<u32>,
    /// The instructions of the harness around a sub-model call (subtracted).
    pub harness_baseline: u32,
}

impl TargetRun {
    /// The cost of part `name`.
    pub fn part(&self, name: &str) -> Option<&PartCost> {
        self.parts.iter().find(|(n, _)| n == name).map(|(_, c)| c)
    }
}

/// A calibration check: a loop of exactly `expected` instructions, as measured.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct CalibrationPoint {
    pub expected: u32,
    pub measured: u32,
}

/// Instructions per call of a math function over an argument range.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FunctionCost {
    pub name: String,
    pub calls: u64,
    pub mean: f64,
    pub max: u32,
}

/// Instructions per tick of the rig's step over its cost sequence (a `G` line).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct RigStepCost {
    /// Ticks measured.
    pub ticks: u32,
    pub mean: f64,
    pub max: u32,
    /// Tick (0-based) at which the maximum occurred.
    pub max_tick: u32,
    /// Commands of the sequence the rig refused (0 expected).
    pub rejected_commands: u32,
}

/// Everything the emulator printed, parsed.
#[derive(Clone, Debug, Default)]
pub struct EmulatorOutput {
    pub math: String,
    /// The optimisation level the image was built at (`opt_level=` of the `H` line; `None`
    /// from an image built before it printed one).
    pub opt_level: Option<String>,
    pub instructions_per_tick: u32,
    pub timer_overhead: u32,
    pub calibration: Vec<CalibrationPoint>,
    pub functions: Vec<FunctionCost>,
    pub runs: Vec<TargetRun>,
    /// The rig's step over its cost sequence.
    pub rig: Option<RigStepCost>,
    /// The plant step with degraded adhesion on, on a non-uniform track (a `D` line): the
    /// track's name and the cost.
    pub degraded: Option<(String, PartCost)>,
}

impl EmulatorOutput {
    pub fn run(&self, friction: &str) -> Option<&TargetRun> {
        self.runs.iter().find(|r| r.friction == friction)
    }
}

fn kv<'a>(line: &'a str, key: &str) -> Result<&'a str> {
    line.split(' ')
        .find_map(|f| f.strip_prefix(key).and_then(|r| r.strip_prefix('=')))
        .ok_or_else(|| anyhow!("emulator line lacks `{key}=`: {line}"))
}

fn num<T: std::str::FromStr>(line: &str, key: &str) -> Result<T> {
    let v = kv(line, key)?;
    v.parse()
        .map_err(|_| anyhow!("emulator line: `{key}={v}` is not a number: {line}"))
}

/// Parses the emulator's output (see `firmware/qemu/src/main.rs` for the line kinds).
/// An `X` line (an error the target reported), a malformed line, a run without its end
/// line or a trajectory row outside a run is an error.
pub fn parse_output(text: &str) -> Result<EmulatorOutput> {
    let mut p = Parser::default();
    for (i, line) in text.lines().enumerate() {
        p.line(i + 1, line)?;
    }
    p.finish()
}

/// The state of [`parse_output`] between lines.
#[derive(Default)]
struct Parser {
    out: EmulatorOutput,
    current: Option<TargetRun>,
    header: bool,
}

impl Parser {
    fn line(&mut self, n: usize, line: &str) -> Result<()> {
        let at = || format!("emulator output line {n}");
        match line.split(' ').next().unwrap_or("") {
            "H" => {
                self.out.math = kv(line, "math")?.to_string();
                self.out.opt_level = kv(line, "opt_level").ok().map(str::to_string);
                self.out.instructions_per_tick = num(line, "instructions_per_tick")?;
                self.out.timer_overhead = num(line, "overhead")?;
                self.header = true;
            }
            "K" => self.out.calibration.push(CalibrationPoint {
                expected: num(line, "n")?,
                measured: num(line, "instructions")?,
            }),
            "F" => self.out.functions.push(function_cost(line)?),
            "B" => {
                if self.current.is_some() {
                    bail!("{}: a run starts before the previous one ended", at());
                }
                self.current = Some(TargetRun {
                    friction: kv(line, "friction")?.to_string(),
                    harness_baseline: num(line, "harness_baseline")?,
                    ..TargetRun::default()
                });
            }
            "R" => {
                let run = self.run(&at, "a row")?;
                let row = TraceRow::decode(line)
                    .ok_or_else(|| anyhow!("{}: malformed trajectory row", at()))?;
                run.rows.push(row);
            }
            "C" => {
                let cost = part_cost(line)?;
                self.run(&at, "costs")?.parts.push(cost);
            }
            "E" => self.end_run(line, &at)?,
            "G" => self.out.rig = Some(rig_step_cost(line)?),
            "D" => {
                let (_, cost) = part_cost(line)?;
                self.out.degraded = Some((kv(line, "track")?.to_string(), cost));
            }
            "X" => bail!(
                "the emulated target reported an error: {}",
                &line[1..].trim()
            ),
            "" => {}
            _ => bail!("{}: unexpected line: {line}", at()),
        }
        Ok(())
    }

    /// The run in progress, or the error for `what` outside a run.
    fn run(&mut self, at: &dyn Fn() -> String, what: &str) -> Result<&mut TargetRun> {
        self.current
            .as_mut()
            .ok_or_else(|| anyhow!("{}: {what} outside a run", at()))
    }

    fn end_run(&mut self, line: &str, at: &dyn Fn() -> String) -> Result<()> {
        let mut run = self
            .current
            .take()
            .ok_or_else(|| anyhow!("{}: a run ends that never started", at()))?;
        run.steps = num(line, "steps")?;
        run.stop_step = match kv(line, "stop_step")? {
            "none" => None,
            s => Some(s.parse().map_err(|_| anyhow!("{}: bad stop_step", at()))?),
        };
        let rows: usize = num(line, "rows")?;
        if rows != run.rows.len() {
            bail!(
                "{}: the target sent {rows} rows but {} arrived intact",
                at(),
                run.rows.len()
            );
        }
        self.out.runs.push(run);
        Ok(())
    }

    fn finish(self) -> Result<EmulatorOutput> {
        if let Some(run) = self.current {
            bail!(
                "the emulator's {} friction run did not end (output cut short?)",
                run.friction
            );
        }
        if !self.header {
            bail!("the emulator printed no header line (not the hils-qemu binary?)");
        }
        Ok(self.out)
    }
}

/// A `G` line.
fn rig_step_cost(line: &str) -> Result<RigStepCost> {
    let ticks: u32 = num(line, "n")?;
    let sum: u64 = num(line, "sum")?;
    if ticks == 0 {
        bail!("emulator line: the rig's cost sequence measured no tick: {line}");
    }
    Ok(RigStepCost {
        ticks,
        mean: sum as f64 / ticks as f64,
        max: num(line, "max")?,
        max_tick: num(line, "max_tick")?,
        rejected_commands: num(line, "rejected")?,
    })
}

/// An `F` line.
fn function_cost(line: &str) -> Result<FunctionCost> {
    let calls: u64 = num(line, "n")?;
    let sum: u64 = num(line, "sum")?;
    Ok(FunctionCost {
        name: kv(line, "fn")?.to_string(),
        calls,
        mean: sum as f64 / calls.max(1) as f64,
        max: num(line, "max")?,
    })
}

/// A `C` line: a part's name and cost.
fn part_cost(line: &str) -> Result<(String, PartCost)> {
    let n: u64 = num(line, "n")?;
    let sum: u64 = num(line, "sum")?;
    Ok((
        kv(line, "part")?.to_string(),
        PartCost {
            n,
            mean: sum as f64 / n.max(1) as f64,
            max: num(line, "max")?,
            max_step: num(line, "max_step")?,
            p50: num(line, "p50")?,
            p99: num(line, "p99")?,
        },
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::target_cost::compare::{column_names, compare};
    use hils_sil::trace::{LINE_LEN, VALUES};
    fn row(step: u32) -> TraceRow {
        let mut values = [0u32; VALUES];
        for (k, v) in values.iter_mut().enumerate() {
            *v = (k as f32 * 0.5 + step as f32).to_bits();
        }
        TraceRow {
            step,
            flags: 0,
            valves: 0b10_00_01_00,
            values,
        }
    }

    fn encoded(r: &TraceRow) -> String {
        let mut buf = [0u8; LINE_LEN];
        r.encode(&mut buf);
        String::from_utf8(buf.to_vec()).expect("ascii")
    }

    fn sample_output(rows: &[TraceRow]) -> String {
        let mut s = String::from(
            "H hils-qemu math=M opt_level=2 instructions_per_tick=40 ticks_for_2000000=50001 overhead=0 spin=4\n\
             K n=2000 instructions=2004\nF fn=exp n=10 sum=320 max=32 lo=-20 hi=3\n\
             B friction=variable harness_baseline=32\n",
        );
        for r in rows {
            s += &encoded(r);
        }
        s += "C friction=variable part=step n=4 sum=10000 max=2600 max_step=3 p50=2504 p99=2600\n";
        s += &format!(
            "E friction=variable steps=400 stop_step=300 rows={}\n",
            rows.len()
        );
        s
    }

    #[test]
    fn parses_what_the_emulator_prints() {
        let rows = [row(0), row(100), row(200)];
        let out = parse_output(&sample_output(&rows)).expect("parses");
        assert_eq!(out.math, "M");
        assert_eq!(out.instructions_per_tick, 40);
        assert_eq!(out.opt_level.as_deref(), Some("2"));
        assert_eq!(
            out.calibration,
            vec![CalibrationPoint {
                expected: 2000,
                measured: 2004
            }]
        );
        assert_eq!(out.functions[0].mean, 32.0);
        let run = out.run("variable").expect("run");
        assert_eq!(run.rows, rows);
        assert_eq!(run.stop_step, Some(300));
        let step = run.part("step").expect("step");
        assert_eq!((step.mean, step.max, step.max_step), (2500.0, 2600, 3));
    }

    #[test]
    fn rejects_cut_or_corrupt_output() {
        let rows = [row(0), row(100)];
        let good = sample_output(&rows);
        // Cut short: no end line.
        let cut = &good[..good.find("C friction").expect("cost line")];
        assert!(
            parse_output(cut)
                .unwrap_err()
                .to_string()
                .contains("did not end")
        );
        // A corrupted row.
        let bad = good.replacen(" 00000064 ", " 0000z064 ", 1);
        assert!(
            parse_output(&bad)
                .unwrap_err()
                .to_string()
                .contains("malformed")
        );
        // A row lost: the count in the end line no longer matches.
        let lost = good.replacen(&encoded(&rows[1]), "", 1);
        assert!(
            parse_output(&lost)
                .unwrap_err()
                .to_string()
                .contains("arrived intact")
        );
        // The target's own error report.
        let err =
            parse_output("H hils-qemu math=M instructions_per_tick=40 overhead=0\nX panic: boom\n");
        assert!(err.unwrap_err().to_string().contains("boom"));
    }

    #[test]
    fn comparison_finds_a_single_flipped_bit() {
        let host = vec![row(0), row(100), row(200)];
        assert!(compare("variable", &host, &host).identical);
        let mut target = host.clone();
        target[2].values[20] ^= 1;
        let c = compare("variable", &target, &host);
        assert!(!c.identical);
        assert_eq!(c.values_different, 1);
        let m = c.first_mismatch.expect("mismatch");
        assert_eq!((m.row, m.step), (2, 200));
        assert_eq!(m.column, column_names()[3 + 20]);
        // A missing row is a difference too.
        assert!(!compare("variable", &host[..2], &host).identical);
    }
}
