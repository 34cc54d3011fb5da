//! `hils-fmu-check rust-fmi FMU`: the packed FMU through rust-fmi's importer (the `fmi`
//! crate: its own model-description parser, loader and bindings): the paper's EB in closed
//! loop at 1 ms and the plant driven by the run's pressures at 0.1 ms equal `hils
//! simulate`'s run bit for bit at every communication point.
//!
//! rust-fmi 0.8's model-description parser departs from the FMI 3.0 schema in two places:
//! it reads `BaseUnit`'s exponents `K` and `A` as `k` and `a` (and refuses the standard's
//! names: "UnknownField BaseUnit K"), and it has no `Enumeration` variables (it skips them).
//! So rust-fmi imports a copy of the FMU whose `modelDescription.xml` names the exponents its
//! way (binary and resources unchanged), and the value references of the enumerations
//! `brake_input` and `cmd` come from the model description read directly.

use std::path::Path;

use anyhow::{Result, anyhow, bail};
use fmi::fmi3::import::Fmi3Import;
use fmi::fmi3::instance::InstanceCS;
use fmi::fmi3::{CoSimulation, Common, Fmi3Model, GetSet};
use fmi::traits::FmiImport;
use hils_fmu_check::{UNIT_OUTPUTS, columns, first_difference, paper_run};
use hils_sil::ParamFile;

/// Prints the FMU's messages (rust-fmi hands them to the `log` crate).
struct Printer;

impl log::Log for Printer {
    fn enabled(&self, m: &log::Metadata) -> bool {
        m.level() <= log::Level::Warn
    }
    fn log(&self, r: &log::Record) {
        if self.enabled(r.metadata()) {
            eprintln!("rust-fmi: [{}] {}", r.level(), r.args());
        }
    }
    fn flush(&self) {}
}

/// Name, value reference and kind of the outputs and inputs rust-fmi read.
struct Vars {
    by_name: Vec<(String, u32, String)>,
}

impl Vars {
    fn of(import: &Fmi3Import) -> Self {
        let md = import.model_description();
        let by_name = md
            .model_variables
            .iter_abstract()
            .map(|v| {
                (
                    v.name().to_string(),
                    v.value_reference(),
                    format!("{:?}/{:?}", v.data_type(), v.causality()),
                )
            })
            .collect();
        Vars { by_name }
    }

    fn vr(&self, name: &str) -> Result<u32> {
        self.by_name
            .iter()
            .find(|(n, _, _)| n == name)
            .map(|v| v.1)
            .ok_or_else(|| anyhow!("rust-fmi found no variable {name}"))
    }

    /// The Float64 outputs (name, vr).
    fn float_outputs(&self) -> Vec<(String, u32)> {
        self.by_name
            .iter()
            .filter(|(_, _, k)| k == "FmiFloat64/Output")
            .map(|(n, v, _)| (n.clone(), *v))
            .collect()
    }
}

fn status<T, E: std::fmt::Debug>(call: &str, r: Result<T, E>) -> Result<T> {
    r.map_err(|e| anyhow!("{call}: {e:?}"))
}

fn instantiate(import: &Fmi3Import, name: &str) -> Result<InstanceCS> {
    status(
        "instantiate_cs",
        import.instantiate_cs(name, false, true, false, false, &[]),
    )
}

fn initialize(inst: &mut InstanceCS) -> Result<()> {
    status(
        "enter_initialization_mode",
        inst.enter_initialization_mode(None, 0.0, None),
    )?;
    status("exit_initialization_mode", inst.exit_initialization_mode())?;
    Ok(())
}

fn step(inst: &mut InstanceCS, t: f64, h: f64) -> Result<()> {
    let (mut a, mut b, mut c, mut last) = (false, false, false, 0.0);
    status(
        "do_step",
        inst.do_step(t, h, true, &mut a, &mut b, &mut c, &mut last),
    )?;
    Ok(())
}

/// A copy of the FMU with `BaseUnit`'s `K` and `A` written as rust-fmi 0.8 reads them.
fn patched_copy(path: &Path, dir: &Path) -> Result<std::path::PathBuf> {
    let mut zip = zip::ZipArchive::new(std::fs::File::open(path)?)?;
    let copy = dir.join("hils_plant.fmu");
    let mut out = zip::ZipWriter::new(std::fs::File::create(&copy)?);
    for i in 0..zip.len() {
        let mut entry = zip.by_index(i)?;
        let name = entry.name()?.to_string();
        let mut bytes = Vec::new();
        std::io::Read::read_to_end(&mut entry, &mut bytes)?;
        if name == "modelDescription.xml" {
            let xml = String::from_utf8(bytes)?;
            bytes = xml
                .replace(" K=\"", " k=\"")
                .replace(" A=\"", " a=\"")
                .into_bytes();
        }
        out.start_file(name.as_str(), zip::write::SimpleFileOptions::default())?;
        std::io::Write::write_all(&mut out, &bytes)?;
    }
    out.finish()?;
    Ok(copy)
}

pub fn check(path: &Path) -> Result<()> {
    let _ = log::set_logger(&Printer).map(|()| log::set_max_level(log::LevelFilter::Warn));
    let dir = tempfile::tempdir()?;
    let copy = patched_copy(path, dir.path())?;
    let import: Fmi3Import = status("import", fmi::import::from_path(&copy))?;
    let vars = Vars::of(&import);
    let direct = hils_fmu_check::description::Description::of_fmu(path)?;
    let outputs = vars.float_outputs();
    let (names, vrs): (Vec<String>, Vec<u32>) = outputs.into_iter().unzip();
    let cols = columns(&names)?;
    if names.len() < 30 {
        bail!("rust-fmi read only {} Float64 outputs", names.len());
    }
    let run = paper_run(&ParamFile::default())?;
    let mut values = vec![0.0; vrs.len()];

    // The closed loop at 1 ms.
    let mut inst = instantiate(&import, "rust-fmi-loop")?;
    // rust-fmi 0.8 skips Enumeration variables: their references from the XML.
    let enumeration =
        |name: &str| -> Result<u32> { vars.vr(name).or_else(|_| Ok(direct.var(name)?.vr)) };
    status(
        "set brake_input",
        inst.set_int64(&[enumeration("brake_input")?], &[2]),
    )?;
    status("set cmd", inst.set_int64(&[enumeration("cmd")?], &[1]))?;
    initialize(&mut inst)?;
    let every = 10;
    let mut t = 0.0;
    let mut points = 0;
    for (k, s) in run.samples.iter().enumerate().step_by(every).skip(1) {
        step(&mut inst, t, 1e-3)?;
        t += 1e-3;
        status("get_float64", inst.get_float64(&vrs, &mut values))?;
        if let Some(d) = first_difference(s, &names, &cols, &values, &[], k) {
            bail!("rust-fmi, closed loop: {d}");
        }
        points += 1;
    }
    println!(
        "rust-fmi importer: closed loop at 1 ms, {points} communication points x {} Float64 outputs bit-identical to hils simulate",
        names.len()
    );

    // The plant driven by the run's pressures at the plant step.
    let mut inst = instantiate(&import, "rust-fmi-plant")?;
    let inputs: Vec<u32> = (1..=4)
        .map(|j| vars.vr(&format!("p_cyl{j}_pa")))
        .collect::<Result<_>>()?;
    initialize(&mut inst)?;
    let mut t = 0.0;
    for (k, s) in run.samples.iter().enumerate().skip(1) {
        status("set_float64", inst.set_float64(&inputs, &s.p_cyl_pa))?;
        step(&mut inst, t, run.dt)?;
        t += run.dt;
        status("get_float64", inst.get_float64(&vrs, &mut values))?;
        if let Some(d) = first_difference(s, &names, &cols, &values, &UNIT_OUTPUTS, k) {
            bail!("rust-fmi, plant: {d}");
        }
    }
    println!(
        "rust-fmi importer: plant driven by the run's p_cyl1..4_pa at {} s, {} communication points bit-identical",
        run.dt,
        run.samples.len() - 1
    );
    Ok(())
}
