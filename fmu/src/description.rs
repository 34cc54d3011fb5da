//! `modelDescription.xml` (FMI 3.0, Co-Simulation) and `resources/parameters.toml`, both
//! written from the variable table ([`crate::variables::VARIABLES`]) and a parameter file's
//! values (the start values and the resource are the same file's).

use std::io;

use hils_plant::keys::{KeyInfo, KeyValue, KeyVisitor, Keys};
use hils_sil::ParamFile;
use quick_xml::Writer;
use quick_xml::events::{BytesDecl, Event};

use crate::units::{self, Unit};
use crate::variables::{Causality, EnumType, Kind, Role, VARIABLES, Variable};

/// The model identifier: the shared library's name in `binaries/<platform>/`.
pub const MODEL_IDENTIFIER: &str = "hils_plant";

/// The default communication step of the model description's experiment, s (1 kHz, the
/// run log's rate; any multiple of the plant step is accepted).
pub const DEFAULT_STEP_S: f64 = 1e-3;

/// Stop time of the default experiment, s (the paper's EB stops at 29.4 s).
pub const DEFAULT_STOP_S: f64 = 35.0;

/// The log categories (name, description): errors are always logged, the others when
/// debug logging is on.
pub const LOG_CATEGORIES: [(&str, &str); 3] = [
    (
        "logStatusError",
        "Calls refused: values out of range, calls out of order, bad step sizes",
    ),
    (
        "logStatusWarning",
        "The plant's flags: brake inputs clamped, a numeric fault",
    ),
    (
        "logEvents",
        "Mode changes, parameter files loaded, the model built",
    ),
];

/// The instantiation token: the crate version and a hash of the variable table (names,
/// value references, types), so a binary refuses a model description of another table.
pub fn instantiation_token() -> String {
    // FNV-1a, 64 bit.
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for v in VARIABLES.iter() {
        let text = format!("{}:{}:{:?}:{:?};", v.name, v.vr, v.kind, v.causality);
        for b in text.bytes() {
            h = (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3);
        }
    }
    format!("{{hils-plant-{}-{h:016x}}}", env!("CARGO_PKG_VERSION"))
}

/// A number as XML and TOML write it (shortest text that reads back to the same f64).
pub fn number(x: f64) -> String {
    format!("{x:?}")
}

/// The start values of the parameters (value references of keys) from a file.
fn key_starts(file: &ParamFile) -> Vec<String> {
    struct Starts(Vec<String>);
    impl KeyVisitor for Starts {
        fn key(&mut self, _: &KeyInfo, value: KeyValue<'_>) {
            self.0.push(match value {
                KeyValue::Real(x) => number(*x),
                KeyValue::Count(n) => n.to_string(),
                KeyValue::Flag(b) => b.to_string(),
                KeyValue::Choice(c) => c.index().to_string(),
                KeyValue::Note => String::new(),
            });
        }
    }
    let mut starts = Starts(Vec::new());
    let mut file = *file;
    file.visit_keys(&mut starts);
    starts.0
}

/// The model description of the FMU with `defaults` as the parameters' start values.
pub fn model_description(defaults: &ParamFile) -> io::Result<String> {
    let starts = key_starts(defaults);
    let mut w = Writer::new_with_indent(Vec::new(), b' ', 2);
    w.write_event(Event::Decl(BytesDecl::new("1.0", Some("UTF-8"), None)))?;
    let token = instantiation_token();
    w.create_element("fmiModelDescription")
        .with_attributes([
            ("fmiVersion", "3.0"),
            ("modelName", "hils_plant"),
            ("description", "Railway brake HILS plant (Lee & Kang 2015): 17-DOF railcar, Polach wheel-rail contact, disc-pad friction of Eq (2) and the disc heat balance; optionally in closed loop with the simulated brake unit (ECU, cylinders, WSP). The same f32 code as the real-time board and hils simulate."),
            ("version", env!("CARGO_PKG_VERSION")),
            ("license", env!("CARGO_PKG_LICENSE")),
            ("generationTool", concat!("hils-fmu ", env!("CARGO_PKG_VERSION"))),
            ("instantiationToken", token.as_str()),
            ("variableNamingConvention", "structured"),
        ])
        .write_inner_content(|w| {
            co_simulation(w, defaults)?;
            unit_definitions(w)?;
            type_definitions(w)?;
            log_categories(w)?;
            default_experiment(w, defaults)?;
            w.create_element("ModelVariables")
                .write_inner_content(|w| {
                    VARIABLES
                        .iter()
                        .try_for_each(|v| variable(w, v, &starts))
                })?;
            model_structure(w)
        })?;
    String::from_utf8(w.into_inner()).map_err(io::Error::other)
}

/// The Co-Simulation capabilities; the internal step is the defaults' plant step (a file
/// given to `cargo fmu --params` may set another than 0.1 ms).
fn co_simulation(w: &mut Writer<Vec<u8>>, defaults: &ParamFile) -> io::Result<()> {
    let step = number(defaults.scenario.paper_eb.step_s);
    w.create_element("CoSimulation")
        .with_attributes([
            ("modelIdentifier", MODEL_IDENTIFIER),
            ("canBeInstantiatedOnlyOncePerProcess", "false"),
            ("canGetAndSetFMUState", "true"),
            ("canSerializeFMUState", "false"),
            ("canHandleVariableCommunicationStepSize", "true"),
            ("fixedInternalStepSize", step.as_str()),
            ("hasEventMode", "false"),
        ])
        .write_empty()?;
    Ok(())
}

fn unit_definitions(w: &mut Writer<Vec<u8>>) -> io::Result<()> {
    let mut used: Vec<&Unit> = Vec::new();
    for v in VARIABLES.iter().filter(|v| !v.unit.is_empty()) {
        let unit = units::find(v.unit).ok_or_else(|| {
            io::Error::other(format!(
                "variable {}: unit `{}` is not in fmu/src/units.rs",
                v.name, v.unit
            ))
        })?;
        if !used.contains(&unit) {
            used.push(unit);
        }
    }
    w.create_element("UnitDefinitions")
        .write_inner_content(|w| {
            for u in used {
                let mut base: Vec<(&str, String)> = [
                    ("kg", u.kg),
                    ("m", u.m),
                    ("s", u.s),
                    ("K", u.k),
                    ("rad", u.rad),
                ]
                .into_iter()
                .filter(|(_, e)| *e != 0)
                .map(|(n, e)| (n, e.to_string()))
                .collect();
                if u.factor != 1.0 {
                    base.push(("factor", number(u.factor)));
                }
                if u.offset != 0.0 {
                    base.push(("offset", number(u.offset)));
                }
                w.create_element("Unit")
                    .with_attribute(("name", u.name))
                    .write_inner_content(|w| {
                        w.create_element("BaseUnit")
                            .with_attributes(base.iter().map(|(k, v)| (*k, v.as_str())))
                            .write_empty()?;
                        Ok(())
                    })?;
            }
            Ok(())
        })?;
    Ok(())
}

/// The declared type of a Float64 variable with a unit: one type per unit, named as the
/// unit (as the FMI Reference FMUs declare units through types); temperatures are rises
/// above ambient (`relativeQuantity`).
pub fn declared_type(v: &Variable) -> Option<&'static str> {
    (v.kind == Kind::Float64 && !v.unit.is_empty()).then_some(v.unit)
}

fn type_definitions(w: &mut Writer<Vec<u8>>) -> io::Result<()> {
    let mut enums: Vec<EnumType> = Vec::new();
    let mut floats: Vec<&str> = Vec::new();
    for v in VARIABLES.iter() {
        if let Kind::Enumeration(t) = v.kind
            && !enums.iter().any(|u| u.name == t.name)
        {
            enums.push(t);
        }
        if let Some(t) = declared_type(v)
            && !floats.contains(&t)
        {
            floats.push(t);
        }
    }
    w.create_element("TypeDefinitions")
        .write_inner_content(|w| {
            for unit in &floats {
                let mut t = w
                    .create_element("Float64Type")
                    .with_attributes([("name", *unit), ("unit", *unit)]);
                if *unit == "degC" {
                    t = t.with_attribute(("relativeQuantity", "true"));
                }
                t.write_empty()?;
            }
            for t in &enums {
                w.create_element("EnumerationType")
                    .with_attribute(("name", t.name))
                    .write_inner_content(|w| {
                        for (value, (name, description)) in t.items.iter().enumerate() {
                            let value = value.to_string();
                            let mut item = w
                                .create_element("Item")
                                .with_attributes([("name", *name), ("value", value.as_str())]);
                            if !description.is_empty() {
                                item = item.with_attribute(("description", *description));
                            }
                            item.write_empty()?;
                        }
                        Ok(())
                    })?;
            }
            Ok(())
        })?;
    Ok(())
}

fn log_categories(w: &mut Writer<Vec<u8>>) -> io::Result<()> {
    w.create_element("LogCategories").write_inner_content(|w| {
        for (name, description) in LOG_CATEGORIES {
            w.create_element("Category")
                .with_attributes([("name", name), ("description", description)])
                .write_empty()?;
        }
        Ok(())
    })?;
    Ok(())
}

fn default_experiment(w: &mut Writer<Vec<u8>>, defaults: &ParamFile) -> io::Result<()> {
    // A multiple of the file's plant step.
    let step = defaults.scenario.paper_eb.step_s;
    let step = (DEFAULT_STEP_S / step).round().max(1.0) * step;
    w.create_element("DefaultExperiment")
        .with_attributes([
            ("startTime", "0.0"),
            ("stopTime", number(DEFAULT_STOP_S).as_str()),
            ("stepSize", number(step).as_str()),
        ])
        .write_empty()?;
    Ok(())
}

/// The start value of a variable as text, if it has one.
fn start(v: &Variable, key_starts: &[String]) -> Option<String> {
    match (v.causality, v.role) {
        (Causality::Parameter, Role::Key(i)) => key_starts.get(i).cloned(),
        (Causality::Input | Causality::Parameter | Causality::StructuralParameter, _) => {
            Some(match v.kind {
                Kind::Float64 => "0.0".into(),
                Kind::Boolean => "false".into(),
                Kind::String => String::new(),
                Kind::UInt32 | Kind::Enumeration(_) => "0".into(),
            })
        }
        _ => None,
    }
}

fn variable(w: &mut Writer<Vec<u8>>, v: &Variable, key_starts: &[String]) -> io::Result<()> {
    let element = match v.kind {
        Kind::Float64 => "Float64",
        Kind::UInt32 => "UInt32",
        Kind::Boolean => "Boolean",
        Kind::String => "String",
        Kind::Enumeration(_) => "Enumeration",
    };
    let vr = v.vr.to_string();
    let mut attrs: Vec<(&str, String)> = vec![
        ("name", v.name.clone()),
        ("valueReference", vr),
        ("description", v.description.clone()),
        ("causality", v.causality.name().into()),
        ("variability", v.variability().into()),
    ];
    if let Kind::Enumeration(t) = v.kind {
        attrs.push(("declaredType", t.name.into()));
    }
    if let Some(t) = declared_type(v) {
        attrs.push(("declaredType", t.into()));
    }
    if let Some((min, max)) = v.range {
        let (min, max) = match v.kind {
            Kind::UInt32 => ((min as u32).to_string(), (max as u32).to_string()),
            _ => (number(min), number(max)),
        };
        attrs.push(("min", min));
        attrs.push(("max", max));
    }
    let start = start(v, key_starts);
    if matches!(
        v.causality,
        Causality::Parameter | Causality::StructuralParameter
    ) {
        attrs.push(("initial", "exact".into()));
    }
    let element = w
        .create_element(element)
        .with_attributes(attrs.iter().map(|(k, v)| (*k, v.as_str())));
    match (v.kind, start) {
        (Kind::String, Some(s)) => {
            element.write_inner_content(|w| {
                w.create_element("Start")
                    .with_attribute(("value", s.as_str()))
                    .write_empty()?;
                Ok(())
            })?;
        }
        (_, Some(s)) => {
            element
                .with_attribute(("start", s.as_str()))
                .write_empty()?;
        }
        (_, None) => {
            element.write_empty()?;
        }
    }
    Ok(())
}

fn model_structure(w: &mut Writer<Vec<u8>>) -> io::Result<()> {
    let outputs: Vec<String> = VARIABLES
        .iter()
        .filter(|v| v.causality == Causality::Output)
        .map(|v| v.vr.to_string())
        .collect();
    w.create_element("ModelStructure")
        .write_inner_content(|w| {
            // No direct feedthrough: an output changes only in a step (the inputs act over
            // the step), so an importer needs no algebraic loop solver.
            for vr in &outputs {
                w.create_element("Output")
                    .with_attributes([("valueReference", vr.as_str()), ("dependencies", "")])
                    .write_empty()?;
            }
            // At initialisation the outputs depend on the parameters (no dependencies given:
            // on every known).
            for vr in &outputs {
                w.create_element("InitialUnknown")
                    .with_attribute(("valueReference", vr.as_str()))
                    .write_empty()?;
            }
            Ok(())
        })?;
    Ok(())
}

/// `resources/parameters.toml`: every key of `file` with its value, meaning, unit and range,
/// section by section (the file the FMU loads its defaults from; `hils simulate --params`
/// reads it too).
pub fn parameter_file(file: &ParamFile, origin: &str) -> String {
    struct Toml {
        text: String,
        section: String,
    }
    impl KeyVisitor for Toml {
        fn key(&mut self, info: &KeyInfo, value: KeyValue<'_>) {
            let (section, key) = info.name.rsplit_once('.').unwrap_or(("", info.name));
            if section != self.section {
                self.text.push_str(&format!("\n[{section}]\n"));
                self.section = section.to_string();
            }
            let doc = info.doc.split_whitespace().collect::<Vec<_>>().join(" ");
            let mut note = format!("# {doc}");
            if info.min.is_finite() || info.max.is_finite() {
                let unit = if info.unit.is_empty() { "" } else { info.unit };
                note.push_str(&format!(
                    " Range [{}, {}] {unit}",
                    number(info.min),
                    number(info.max)
                ));
            }
            let value = match value {
                KeyValue::Real(x) => number(*x),
                KeyValue::Count(n) => n.to_string(),
                KeyValue::Flag(b) => b.to_string(),
                KeyValue::Choice(c) => {
                    let names = c.names();
                    format!("\"{}\"", names.get(c.index()).copied().unwrap_or(""))
                }
                KeyValue::Note => "\"\"".into(),
            };
            self.text
                .push_str(&format!("{}\n{key} = {value}\n", note.trim_end()));
        }
    }
    let mut toml = Toml {
        text: format!(
            "# The parameter file of the hils_plant FMU: its defaults (the model description's\n\
             # start values are these values). Written by `cargo fmu` from {origin};\n\
             # every key of spec/reference-parameters.toml and the project's extension keys.\n"
        ),
        section: String::new(),
    };
    let mut file = *file;
    file.visit_keys(&mut toml);
    toml.text
}
