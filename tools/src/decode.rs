//! `hils decode`: the rig board's defmt telemetry log -> a run-log CSV in the format of
//! `spec/measured-data.md` (section 1), ready for `hils diagnose`.
//!
//! Input, either:
//! * a **raw defmt capture** (the bytes of the board's RTT channel, e.g. from
//!   `probe-rs attach --rtt-raw`-style tools or the QEMU fixture) together with the firmware
//!   ELF (`--elf`), decoded with the ELF's defmt table (`defmt-decoder`); or
//! * a **text log** as `probe-rs run` / `defmt-print` print it (one message per line,
//!   timestamps, levels and location lines around it are skipped).
//!
//! The board logs `tlm1-start ...` when a run starts, `tlm1 ...` records every `divider`
//! steps and `tlm1-end ...` when it ends (layout and parser: `hils_rig_core::telemetry`).
//! Each run becomes one CSV. Nothing is dropped silently: malformed defmt frames, corrupt
//! records (their CRC-32 does not match their values: a damaged capture that still decodes;
//! left out of the CSV), missing records (gaps in the records' sequence numbers: the
//! board's log queue or the RTT buffer overflowed, or a record was corrupt) and a missing
//! end line are counted, printed, and written into the metadata; any other malformed
//! telemetry line is an error naming its line. So the CSV holds only records whose values
//! are the board's.

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, anyhow, bail};
use clap::Args;
pub use hils_rig_core as rig_core;
use hils_rig_core::Code;
use hils_rig_core::can::RigState;
use hils_rig_core::telemetry::{Line, ParseError, RunHeader, TelemetryRecord, parse_line};
use hils_rig_core::valves::ValveStates;
use hils_sil::Cmd;
use hils_sil::record::Channel;
use hils_sil::record::run_log::{self, *};

use crate::outputs::OutFile;
use crate::runlog;

/// Arguments of `hils decode`.
#[derive(Args, Debug, Clone)]
pub struct DecodeArgs {
    /// The captured log: raw defmt bytes (with --elf) or text (probe-rs / defmt-print output).
    pub input: PathBuf,
    /// Firmware ELF whose defmt table decodes a raw capture (target/thumbv7em-none-eabihf/firmware/board).
    #[arg(long)]
    pub elf: Option<PathBuf>,
    /// Output file: CSV, or MDF4 when its name ends in `.mf4` (`-`: standard output, one
    /// run); with several runs in the log, `-N` is added before the extension unless --run
    /// picks one.
    #[arg(short, long)]
    pub out: PathBuf,
    /// Decode only this run of the log (1 = the first).
    #[arg(long, value_parser = crate::flags::run_index)]
    pub run: Option<usize>,
}

/// Text lines of a log, with what could not be decoded.
#[derive(Clone, Debug, Default)]
pub struct LogText {
    pub lines: Vec<String>,
    /// defmt frames that did not decode (skipped; their records show up as missing).
    pub malformed_frames: usize,
}

/// Decodes a raw defmt capture with the table of the firmware ELF into message lines.
pub fn defmt_to_text(elf: &[u8], raw: &[u8]) -> Result<LogText> {
    let table = defmt_decoder::Table::parse(elf)
        .map_err(|e| anyhow!("cannot read the defmt table of the ELF: {e}"))?
        .ok_or_else(|| {
            anyhow!("the ELF has no defmt table (.defmt section): not a defmt firmware")
        })?;
    let mut decoder = table.new_stream_decoder();
    decoder.received(raw);
    let mut out = LogText::default();
    loop {
        match decoder.decode() {
            Ok(frame) => out.lines.push(frame.display_message().to_string()),
            Err(defmt_decoder::DecodeError::UnexpectedEof) => break,
            Err(defmt_decoder::DecodeError::Malformed) => {
                out.malformed_frames += 1;
                // rzcobs: the decoder has skipped the bad frame; raw encoding cannot resync.
                if table.encoding() == defmt_decoder::Encoding::Raw {
                    bail!(
                        "malformed defmt frame in a raw-encoded capture after {} messages: cannot resynchronise",
                        out.lines.len()
                    );
                }
            }
        }
    }
    Ok(out)
}

/// One run of a telemetry log.
#[derive(Clone, Debug)]
pub struct Run {
    pub header: RunHeader,
    /// 1-based line of the header.
    pub line: usize,
    pub records: Vec<TelemetryRecord>,
    /// The end line (step, state) if the log has it.
    pub end: Option<(u32, u8)>,
    /// Records missing: gaps in the sequence numbers (corrupt ones included).
    pub missing_records: u64,
    /// Records that failed their CRC-32 (left out).
    pub corrupt_records: u64,
}

/// Finds the runs in the text lines of a log. A malformed telemetry line, a record before
/// any run header, or steps that go backwards are errors naming the line.
pub fn parse_runs<'a>(lines: impl IntoIterator<Item = &'a str>) -> Result<Vec<Run>> {
    let mut runs: Vec<Run> = Vec::new();
    for (i, text) in lines.into_iter().enumerate() {
        let n = i + 1;
        let line = match parse_line(text) {
            Err(ParseError::Crc { .. }) => {
                let run = runs.last_mut().ok_or_else(|| {
                    anyhow!("line {n}: corrupt telemetry record before any run header")
                })?;
                run.corrupt_records += 1;
                continue;
            }
            other => other.map_err(|e| anyhow!("line {n}: bad telemetry line: {e}"))?,
        };
        match line {
            None => {}
            Some(Line::Header(header)) => {
                if header.divider == 0 || header.step_ns == 0 {
                    bail!("line {n}: run header with a zero divider or step");
                }
                // The speed goes into the CSV's metadata: finite and plausible (fuzz finding).
                let v0 = header.initial_speed_kmh;
                if !(0.0..=500.0).contains(&v0) {
                    bail!("line {n}: run header with initial speed {v0} km/h (not in [0, 500])");
                }
                runs.push(Run {
                    header,
                    line: n,
                    records: Vec::new(),
                    end: None,
                    missing_records: 0,
                    corrupt_records: 0,
                });
            }
            Some(Line::Record(r)) => {
                let run = runs.last_mut().ok_or_else(|| {
                    anyhow!("line {n}: telemetry record before any run header (`tlm1-start`): the capture began during a run; start the capture before the run")
                })?;
                if run.end.is_some() {
                    bail!("line {n}: telemetry record after the run's end line");
                }
                if let Some(last) = run.records.last() {
                    if r.step <= last.step {
                        bail!(
                            "line {n}: step {} does not increase (previous record: step {})",
                            r.step,
                            last.step
                        );
                    }
                    if r.seq <= last.seq {
                        bail!(
                            "line {n}: record number {} does not increase (previous: {})",
                            r.seq,
                            last.seq
                        );
                    }
                    run.missing_records += (r.seq - last.seq - 1) as u64;
                } else {
                    // Records lost before the first one that arrived.
                    run.missing_records += r.seq as u64;
                }
                run.records.push(r);
            }
            Some(Line::End { step, state }) => {
                let run = runs
                    .last_mut()
                    .ok_or_else(|| anyhow!("line {n}: run end line before any run header"))?;
                run.end = Some((step, state));
            }
        }
    }
    Ok(runs)
}

/// The `cmd` cell of a telemetry command code (empty for none).
fn cmd_text(code: u8) -> &'static str {
    Cmd::try_from(code).map_or("", Cmd::text)
}

/// The `t_s` cell: the exact time of a step in ns as seconds with 9 decimals, so distinct
/// steps never share a time (six decimals did when a record interval was under 1 us).
pub fn time_text(ns: u64) -> String {
    format!("{}.{:09}", ns / 1_000_000_000, ns % 1_000_000_000)
}

/// The `state` cell of a run-state code.
fn state_text(code: u8) -> &'static str {
    match RigState::from_raw(code) {
        Some(RigState::Idle) => "idle",
        Some(RigState::Running) => "running",
        Some(RigState::Finished) => "finished",
        Some(RigState::Stopped) => "stopped",
        Some(RigState::Fault) => "fault",
        Some(RigState::Starting) => "starting",
        None => "unknown",
    }
}

/// A float cell: the f32's shortest exact text, empty for NaN (not measured).
fn cell(x: f32) -> String {
    if x.is_nan() {
        String::new()
    } else {
        format!("{x}")
    }
}

impl Run {
    /// Time of a record, s.
    pub fn time_s(&self, r: &TelemetryRecord) -> f64 {
        r.step as f64 * self.header.step_ns as f64 * 1e-9
    }

    fn self_test(&self) -> bool {
        self.header.mode == 1
    }

    /// Whether the log has cylinder pressures / clamp forces.
    fn has_pressure(&self) -> bool {
        self.self_test() || self.header.pressure_channels & 0x0F != 0
    }
    fn has_clamp(&self) -> bool {
        self.self_test() || self.header.pressure_channels & 0x0F != 0x0F
    }
    /// Whether any record knows a dump (`hold`: a hold) valve's state: a valve input wired
    /// (rig mode) or the simulated unit's valves (self-test).
    fn has_valves(&self, hold: bool) -> bool {
        self.records.iter().any(|r| {
            let v = ValveStates::of_bits(r.valves);
            (if hold { v.hold_known } else { v.dump_known }) != 0
        })
    }

    /// The logged channels, in the schema's order: the controller outputs the board drove
    /// (EB loop, service demand, air springs) in rig mode only (self-test drives none).
    pub fn channels(&self) -> Vec<Channel> {
        let logged = |c: Channel| match c {
            P_CYL => self.has_pressure(),
            F_CLAMP => self.has_clamp(),
            WSP => self.has_valves(false),
            HOLD => self.has_valves(true),
            EB_LOOP | SERVICE_DEMAND | AIR_SPRING1 | AIR_SPRING2 => !self.self_test(),
            CREEPAGE | ADHESION | X | V_REF_EST => false,
            _ => true,
        };
        run_log::ALL.into_iter().filter(|&c| logged(c)).collect()
    }

    /// Column names of the CSV, in order.
    pub fn columns(&self) -> Vec<String> {
        runlog::column_names(&self.channels())
    }

    /// `# key: value` metadata of the CSV.
    pub fn metadata(&self, source: &str) -> Vec<(&'static str, String)> {
        let h = &self.header;
        let mut m = vec![
            (
                "source",
                format!("rig interface board, hils decode of {source}"),
            ),
            (
                "mode",
                if self.self_test() {
                    "self-test (simulated brake unit)"
                } else {
                    "rig (measured brake inputs)"
                }
                .to_string(),
            ),
            ("rail", if h.rail == 1 { "dry" } else { "wet" }.to_string()),
            (
                "friction",
                if h.friction == 1 {
                    "constant"
                } else {
                    "variable"
                }
                .to_string(),
            ),
            ("initial_speed_kmh", format!("{}", h.initial_speed_kmh)),
        ];
        if let Some(r) = self.records.iter().find(|r| r.cmd == 1) {
            m.push(("eb_command_s", format!("{}", self.time_s(r))));
        }
        let rate = 1e9 / (h.step_ns as f64 * h.divider as f64);
        m.push(("sample_rate_hz", format!("{rate}")));
        m.push(("plant_step_s", format!("{}", h.step_ns as f64 * 1e-9)));
        m.push(("cpu_hz", h.cpu_hz.to_string()));
        m.push(("teeth", h.teeth.to_string()));
        m.push(("records", self.records.len().to_string()));
        m.push(("missing_records", self.missing_records.to_string()));
        m.push(("corrupt_records", self.corrupt_records.to_string()));
        m.push((
            "end",
            match self.end {
                Some((step, state)) => format!("{} at step {step}", state_text(state)),
                None => "none (the log ends during the run)".to_string(),
            },
        ));
        if let Some(last) = self.records.last() {
            let max = self
                .records
                .iter()
                .map(|r| r.step_max_cycles)
                .max()
                .unwrap_or(0);
            m.push((
                "step_max_us",
                format!("{:.2}", max as f64 * 1e6 / h.cpu_hz.max(1) as f64),
            ));
            m.push(("overruns", last.overruns.to_string()));
            m.push(("missed_ticks", last.missed_ticks.to_string()));
        }
        m.push((
            "notes",
            "p_cyl/f_clamp empty = not measured on that channel; wsp = dump valve coil, hold = hold valve coil (rig: the valve inputs, empty where not wired; self-test: the simulated unit's valves); eb_loop_closed, service_demand_mps2, air_spring1/2_pa = what the board drove on the controller's lines (rig mode; air springs empty while silent); faults = hils_rig_core::rig::Faults bits; sensor_faults = 4 bits per channel; step times from the DWT cycle counter; surface = zone under the wheelset (board telemetry); mu_avail = available adhesion of that surface at v_ref (default vehicle and contact sets, as the board's plant; hils wsp-test's table)".to_string(),
        ));
        m
    }

    /// The cell of channel `c`, wheelset `j`, of a record.
    fn cell(&self, r: &TelemetryRecord, c: Channel, j: usize) -> String {
        let us = |cycles: u32| {
            format!(
                "{:.3}",
                cycles as f64 * 1e6 / self.header.cpu_hz.max(1) as f64
            )
        };
        match c {
            T => time_text(r.step as u64 * self.header.step_ns as u64),
            V_REF => cell(r.v_ref),
            OMEGA => cell(r.omega[j]),
            P_CYL => cell(r.p_cyl[j]),
            F_CLAMP => cell(r.f_clamp[j]),
            F_BRAKE => cell(r.f_brake[j]),
            T_DISC => cell(r.t_disc[j]),
            Q => cell(r.q[j]),
            WSP | HOLD => {
                let v = ValveStates::of_bits(r.valves);
                let state = if c == WSP { v.dump(j) } else { v.hold(j) };
                state.map_or(String::new(), |on| (on as u8).to_string())
            }
            EB_LOOP => (r.driven & 1).to_string(),
            SERVICE_DEMAND => cell(r.service_demand),
            AIR_SPRING1 => cell(r.air_spring[0]),
            AIR_SPRING2 => cell(r.air_spring[1]),
            A_X => cell(r.a_x),
            CMD => cmd_text(r.cmd).to_string(),
            MU_D => cell(r.mu_d[j]),
            STATE => state_text(r.state).to_string(),
            FAULTS => format!("0x{:08x}", r.faults),
            SENSOR_FAULTS => format!("0x{:04x}", r.sensor_faults),
            STEP_MAX => us(r.step_max_cycles),
            STEP_MEAN => us(r.step_mean_cycles),
            OVERRUNS => r.overruns.to_string(),
            MISSED_TICKS => r.missed_ticks.to_string(),
            SURFACE => r.surface(j).name().to_string(),
            MU_AVAIL => format!(
                "{:.4}",
                crate::rig::track::board_adhesion().at(r.surface(j), r.v_ref as f64)
            ),
            _ => String::new(),
        }
    }

    /// Every value the CSV will hold within its column's plausible range (the reader's
    /// table, `measured::limits`) and the run's span within `MAX_SPAN_S`: a corrupt
    /// record is an error naming its step and column, never a file the reader refuses.
    fn check_plausible(&self, channels: &[Channel]) -> Result<()> {
        for r in &self.records {
            for &c in channels {
                for j in 0..c.width() {
                    let name = c.name(j).to_string();
                    let Some(range) = crate::measured::plausible_range(&name) else {
                        continue;
                    };
                    let text = self.cell(r, c, j);
                    match text.parse::<f64>() {
                        Ok(x) if !range.contains(&x) => bail!(
                            "run of line {}, record of step {}: `{name}` = {x} is outside the \
                             plausible range [{}, {}] (a corrupt record?)",
                            self.line,
                            r.step,
                            range.start(),
                            range.end()
                        ),
                        _ => {}
                    }
                }
            }
        }
        if let (Some(a), Some(b)) = (self.records.first(), self.records.last()) {
            let span = self.time_s(b) - self.time_s(a);
            if span > crate::measured::MAX_SPAN_S {
                bail!(
                    "run of line {}: the records span {span} s (steps {} to {}); at most {} s",
                    self.line,
                    a.step,
                    b.step,
                    crate::measured::MAX_SPAN_S
                );
            }
        }
        Ok(())
    }

    /// Writes the run as a run-log CSV (an error, before anything is written, when a
    /// value is implausible).
    pub fn write_csv<W: Write>(&self, out: W, source: &str) -> Result<()> {
        self.write_as(runlog::Format::Csv, out, source)
    }

    /// Writes the run as a run log in `format` (CSV or MDF4; the same columns).
    pub fn write_as<W: Write>(&self, format: runlog::Format, out: W, source: &str) -> Result<()> {
        let channels = self.channels();
        self.check_plausible(&channels)?;
        let rows = self.records.iter().map(|r| {
            channels
                .iter()
                .flat_map(|&c| (0..c.width()).map(move |j| self.cell(r, c, j)))
                .collect()
        });
        runlog::write_table_as(format, out, &self.metadata(source), &self.columns(), rows)
    }
}

/// Reads a log file: raw defmt with an ELF, else text.
pub fn read_log(input: &Path, elf: Option<&Path>) -> Result<LogText> {
    let bytes = std::fs::read(input).with_context(|| format!("cannot read {}", input.display()))?;
    match elf {
        Some(elf_path) => {
            let elf = std::fs::read(elf_path)
                .with_context(|| format!("cannot read the ELF {}", elf_path.display()))?;
            defmt_to_text(&elf, &bytes).with_context(|| format!("{}", input.display()))
        }
        None => {
            let text = String::from_utf8(bytes).map_err(|_| {
                anyhow!(
                    "{} is not text: a raw defmt capture needs --elf FIRMWARE",
                    input.display()
                )
            })?;
            Ok(LogText {
                lines: text.lines().map(str::to_string).collect(),
                ..Default::default()
            })
        }
    }
}

pub fn main(args: DecodeArgs) -> Result<()> {
    let mut inputs = vec![("log", args.input.as_path())];
    inputs.extend(args.elf.as_deref().map(|e| ("--elf", e)));
    let out = OutFile::check(&args.out, "-o")?.not_over("-o", &inputs)?;
    let log = read_log(&args.input, args.elf.as_deref())?;
    if log.malformed_frames > 0 {
        eprintln!(
            "warning: {} malformed defmt frames skipped",
            log.malformed_frames
        );
    }
    let runs = parse_runs(log.lines.iter().map(String::as_str))
        .with_context(|| format!("{}", args.input.display()))?;
    if runs.is_empty() {
        bail!(
            "{}: no run in the log (no `tlm1-start` line among {} lines)",
            args.input.display(),
            log.lines.len()
        );
    }
    let chosen: Vec<(usize, &Run)> = match args.run {
        Some(k) => {
            let run = runs
                .get(k.wrapping_sub(1))
                .ok_or_else(|| anyhow!("--run {k}: the log has {} run(s)", runs.len()))?;
            vec![(k, run)]
        }
        None => runs.iter().enumerate().map(|(i, r)| (i + 1, r)).collect(),
    };
    let outputs = run_outputs(&out, &args.out, &chosen)?;
    let source = args.input.display().to_string();
    for ((k, run), out) in chosen.iter().zip(&outputs) {
        if run.records.is_empty() {
            bail!("run {k} (line {}): no telemetry records", run.line);
        }
        // Written whole once it is complete (atomically): a run refused half-way leaves no
        // file.
        let mut csv = Vec::new();
        // The format by the name's extension (`-`, standard output: CSV).
        let format = runlog::Format::of_path(&args.out);
        run.write_as(format, &mut csv, &source)
            .with_context(|| format!("{}", args.input.display()))?;
        out.write(csv)?;
        let last = run.records.last().map(|r| run.time_s(r)).unwrap_or(0.0);
        crate::say!(
            "run {k}: {} records, 0 to {last:.3} s, {} missing, {} corrupt, end: {} -> {}",
            run.records.len(),
            run.missing_records,
            run.corrupt_records,
            run.end.map(|(_, s)| state_text(s)).unwrap_or("none"),
            out.describe()
        );
        if run.corrupt_records > 0 {
            eprintln!(
                "warning: run {k}: {} records corrupt (CRC-32 mismatch: the capture was damaged) and left out; see `corrupt_records`",
                run.corrupt_records
            );
        }
        if run.missing_records > 0 {
            eprintln!(
                "warning: run {k}: {} records missing (the board's log queue or the RTT buffer overflowed; see `missing_records`)",
                run.missing_records
            );
        }
    }
    Ok(())
}

/// The output of each chosen run, checked before any is written: `-o` itself for one run;
/// for several, `-N` before the extension of `-o` (standard output takes one run only).
fn run_outputs(out: &OutFile, path: &Path, chosen: &[(usize, &Run)]) -> Result<Vec<OutFile>> {
    if chosen.len() == 1 {
        return Ok(vec![out.clone()]);
    }
    if *out == OutFile::Stdout {
        bail!(
            "-o -: the log holds {} runs and standard output takes one: pick it with --run N",
            chosen.len()
        );
    }
    let stem = path.file_stem().and_then(|s| s.to_str()).unwrap_or("run");
    let ext = path.extension().and_then(|s| s.to_str()).unwrap_or("csv");
    chosen
        .iter()
        .map(|(k, _)| OutFile::check(&path.with_file_name(format!("{stem}-{k}.{ext}")), "-o"))
        .collect()
}
