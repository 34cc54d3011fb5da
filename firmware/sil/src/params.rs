//! The whole parameter file (`spec/reference-parameters.toml` and its variants), one section
//! per crate that uses it: the plant's sections ([`hils_plant::Params`]), `[brake_unit]`
//! ([`hils_brake_unit::BrakeUnitParams`]) and `[scenario.paper_eb]` ([`PaperEbScenario`],
//! owned here). [`ParamFile::default`] equals the reference file (a test loads the file and
//! compares). With the `serde` feature the file deserializes section by section; an
//! unknown section or key, a missing section or a wrong type is an error that names it.

use hils_brake_unit::{BrakeUnitParams, UnitConfig};
use hils_plant::DegradedAdhesionParams;
use hils_plant::keys::{KeyInfo, KeyValue, KeyVisitor, Keys, Unranged, check_keys};
use hils_plant::params::{ParamError, Params, Rail, STEP_S};
#[cfg(feature = "serde")]
use serde::Deserialize;

/// A free-text description in a parameter file (kept for people, ignored by the model).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct Description;

#[cfg(feature = "serde")]
impl<'de> Deserialize<'de> for Description {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl serde::de::Visitor<'_> for V {
            type Value = Description;
            fn expecting(&self, f: &mut core::fmt::Formatter) -> core::fmt::Result {
                f.write_str("a text")
            }
            fn visit_str<E: serde::de::Error>(self, _: &str) -> Result<Description, E> {
                Ok(Description)
            }
        }
        d.deserialize_str(V)
    }
}

/// `[scenario.paper_eb]`: the paper's HILS scenario.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(Deserialize), serde(deny_unknown_fields))]
pub struct PaperEbScenario {
    /// Speed at the EB command, km/h.
    pub initial_speed_kmh: f64,
    /// Rail condition.
    pub rail: Rail,
    /// The track, in words.
    pub track: Description,
    /// Plant step, s (file key `step`).
    #[cfg_attr(feature = "serde", serde(rename = "step"))]
    pub step_s: f64,
}

impl Default for PaperEbScenario {
    fn default() -> Self {
        Self {
            initial_speed_kmh: 150.0,
            rail: Rail::Wet,
            track: Description,
            step_s: STEP_S,
        }
    }
}

/// `[scenario]`.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
#[cfg_attr(feature = "serde", derive(Deserialize), serde(deny_unknown_fields))]
pub struct ScenarioParams {
    /// `[scenario.paper_eb]`.
    pub paper_eb: PaperEbScenario,
}

impl ScenarioParams {
    /// Checks every value against the range of its key ([`Keys`]); the error names the
    /// file's key.
    pub fn validate(&self) -> Result<(), ParamError> {
        check_keys(self)
    }
}

/// The key table of `[scenario.paper_eb]`, in file order.
impl Keys for ScenarioParams {
    fn visit_keys<V: KeyVisitor>(&mut self, v: &mut V) {
        let p = &mut self.paper_eb;
        v.key(
            &KeyInfo {
                name: "scenario.paper_eb.initial_speed_kmh",
                doc: "Speed at the EB command, km/h.",
                unit: "km/h",
                min: 0.0,
                max: 500.0,
            },
            KeyValue::Real(&mut p.initial_speed_kmh),
        );
        let rail = KeyInfo::unranged("scenario.paper_eb.rail", "Rail condition: wet or dry.");
        p.rail.visit_as(&rail, v);
        let track = KeyInfo::unranged("scenario.paper_eb.track", "The track, in words.");
        v.key(&track, KeyValue::Note);
        v.key(
            &KeyInfo {
                name: "scenario.paper_eb.step",
                doc: "Plant step, s (10 kHz: 0.1 ms, paper text).",
                unit: "s",
                min: 1e-6,
                max: 1e-2,
            },
            KeyValue::Real(&mut p.step_s),
        );
    }
}

/// The whole parameter file.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct ParamFile {
    /// The plant's sections (`[vehicle]` ... `[resistance]`).
    pub plant: Params,
    /// `[brake_unit]`.
    pub brake_unit: BrakeUnitParams,
    /// `[scenario]`.
    pub scenario: ScenarioParams,
    /// `[degraded_adhesion]` (optional; off when absent): recovery of contaminated rails,
    /// [`hils_plant::track`].
    pub degraded_adhesion: DegradedAdhesionParams,
}

impl ParamFile {
    /// Checks every section (NaN and inf are out of range); the error names the key.
    pub fn validate(&self) -> Result<(), ParamError> {
        self.plant.validate()?;
        self.brake_unit.validate()?;
        self.degraded_adhesion.validate()?;
        let v = &self.plant.vehicle;
        self.degraded_adhesion
            .validate_span(v.bogie_base + v.wheel_base)?;
        self.scenario.validate()
    }

    /// The brake unit of the file at the paper scenario's step.
    pub fn unit_config(&self) -> UnitConfig {
        UnitConfig::with_params(self.scenario.paper_eb.step_s, self.brake_unit)
    }
}

/// Every key of the file, in file order: the plant's sections, `[brake_unit]`,
/// `[scenario.paper_eb]`, `[degraded_adhesion]`.
impl Keys for ParamFile {
    fn visit_keys<V: KeyVisitor>(&mut self, visitor: &mut V) {
        self.plant.visit_keys(visitor);
        self.brake_unit.visit_keys(visitor);
        self.scenario.visit_keys(visitor);
        self.degraded_adhesion.visit_keys(visitor);
    }
}

#[cfg(feature = "serde")]
mod de {
    use serde::de::{Error, MapAccess, Visitor};
    use serde::{Deserialize, Deserializer};

    use super::ParamFile;
    use hils_plant::Params;

    const PLANT: usize = Params::SECTIONS.len();

    /// Every section of the file: the plant's, then `brake_unit`, `scenario` and the
    /// optional `degraded_adhesion` (the last).
    const SECTIONS: [&str; PLANT + 3] = {
        let mut s = [""; PLANT + 3];
        let mut k = 0;
        while k < PLANT {
            s[k] = Params::SECTIONS[k];
            k += 1;
        }
        s[PLANT] = "brake_unit";
        s[PLANT + 1] = "scenario";
        s[PLANT + 2] = "degraded_adhesion";
        s
    };
    /// Sections a file may leave out.
    const OPTIONAL: usize = PLANT + 2;

    /// A section name, as its index in [`SECTIONS`].
    struct Section(usize);

    impl<'de> Deserialize<'de> for Section {
        fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
            struct V;
            impl Visitor<'_> for V {
                type Value = Section;
                fn expecting(&self, f: &mut core::fmt::Formatter) -> core::fmt::Result {
                    f.write_str("a section of the parameter file")
                }
                fn visit_str<E: Error>(self, v: &str) -> Result<Section, E> {
                    SECTIONS
                        .iter()
                        .position(|s| *s == v)
                        .map(Section)
                        .ok_or_else(|| E::unknown_field(v, &SECTIONS))
                }
            }
            d.deserialize_identifier(V)
        }
    }

    struct FileVisitor;

    impl<'de> Visitor<'de> for FileVisitor {
        type Value = ParamFile;
        fn expecting(&self, f: &mut core::fmt::Formatter) -> core::fmt::Result {
            f.write_str("a parameter file")
        }
        fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<ParamFile, A::Error> {
            let mut file = ParamFile::default();
            let mut seen = [false; SECTIONS.len()];
            while let Some(Section(k)) = map.next_key()? {
                if seen[k] {
                    return Err(A::Error::duplicate_field(SECTIONS[k]));
                }
                seen[k] = true;
                match k {
                    k if k < PLANT => file.plant.read_section(k, &mut map)?,
                    k if k == PLANT => file.brake_unit = map.next_value()?,
                    k if k == PLANT + 1 => file.scenario = map.next_value()?,
                    _ => file.degraded_adhesion = map.next_value()?,
                }
            }
            match seen[..OPTIONAL].iter().position(|s| !s) {
                Some(k) => Err(A::Error::missing_field(SECTIONS[k])),
                None => Ok(file),
            }
        }
    }

    impl<'de> Deserialize<'de> for ParamFile {
        fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
            d.deserialize_struct("ParamFile", &SECTIONS, FileVisitor)
        }
    }
}
