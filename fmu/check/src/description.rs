//! The model description of a packed FMU, read back with an XML reader (not the FMU's own
//! tables): what an importer knows of the FMU.

use std::io::Read;
use std::path::Path;

use anyhow::{Context, Result, anyhow, bail};
use quick_xml::Reader;
use quick_xml::events::Event;

/// One variable as the model description declares it.
#[derive(Clone, Debug, PartialEq)]
pub struct Var {
    pub name: String,
    pub vr: u32,
    /// The element: `Float64`, `UInt32`, `Boolean`, `String`, `Enumeration`.
    pub kind: String,
    pub causality: String,
}

/// What an importer reads from `modelDescription.xml`.
#[derive(Clone, Debug)]
pub struct Description {
    pub token: String,
    pub model_identifier: String,
    pub variables: Vec<Var>,
    /// The default experiment's communication step, s.
    pub step_size: f64,
}

impl Description {
    /// Parses the XML text.
    pub fn parse(xml: &str) -> Result<Self> {
        let mut reader = Reader::from_str(xml);
        let mut d = Description {
            token: String::new(),
            model_identifier: String::new(),
            variables: Vec::new(),
            step_size: f64::NAN,
        };
        let mut in_variables = false;
        loop {
            match reader.read_event()? {
                Event::Start(e) | Event::Empty(e) => {
                    let tag = e.name().as_ref().to_string();
                    let attr = |key: &str| -> Option<String> {
                        e.attributes()
                            .flatten()
                            .find(|a| a.key.as_ref() == key)
                            .and_then(|a| {
                                a.normalized_value(quick_xml::XmlVersion::Implicit1_0)
                                    .ok()
                                    .map(|v| v.into_owned())
                            })
                    };
                    match tag.as_str() {
                        "fmiModelDescription" => {
                            d.token = attr("instantiationToken").unwrap_or_default()
                        }
                        "CoSimulation" => {
                            d.model_identifier = attr("modelIdentifier").unwrap_or_default()
                        }
                        "DefaultExperiment" => {
                            d.step_size = attr("stepSize")
                                .and_then(|s| s.parse().ok())
                                .unwrap_or(f64::NAN)
                        }
                        "ModelVariables" => in_variables = true,
                        _ if in_variables && attr("valueReference").is_some() => {
                            d.variables.push(Var {
                                name: attr("name").unwrap_or_default(),
                                vr: attr("valueReference")
                                    .and_then(|v| v.parse().ok())
                                    .ok_or_else(|| anyhow!("variable {tag}: bad valueReference"))?,
                                kind: tag.clone(),
                                causality: attr("causality").unwrap_or_else(|| "local".into()),
                            })
                        }
                        _ => {}
                    }
                }
                Event::End(e) if e.name().as_ref() == "ModelVariables" => in_variables = false,
                Event::Eof => break,
                _ => {}
            }
        }
        if d.token.is_empty() || d.model_identifier.is_empty() || d.variables.is_empty() {
            bail!("not an FMI 3.0 Co-Simulation model description");
        }
        Ok(d)
    }

    /// Reads `modelDescription.xml` of an FMU archive.
    pub fn of_fmu(fmu: &Path) -> Result<Self> {
        let file =
            std::fs::File::open(fmu).with_context(|| format!("cannot open {}", fmu.display()))?;
        let mut zip = zip::ZipArchive::new(file)?;
        let mut xml = String::new();
        zip.by_name("modelDescription.xml")?
            .read_to_string(&mut xml)?;
        Self::parse(&xml)
    }

    /// The variable named `name`.
    pub fn var(&self, name: &str) -> Result<&Var> {
        self.variables
            .iter()
            .find(|v| v.name == name)
            .ok_or_else(|| anyhow!("the FMU has no variable {name}"))
    }

    /// The outputs of type `kind`, in description order.
    pub fn outputs(&self, kind: &str) -> Vec<&Var> {
        self.variables
            .iter()
            .filter(|v| v.causality == "output" && v.kind == kind)
            .collect()
    }
}
