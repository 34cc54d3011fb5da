//! Channel maps (`--map FILE`): which channel of a user's file is which column of the spec,
//! in which unit, and the spec's metadata a file carries elsewhere. TOML:
//!
//! ```toml
//! wheel_radius_m = 0.43            # optional: wheel speeds logged as km/h (r omega)
//! [channels.omega1_radps]
//! from = "WheelSpeed_Axle1"        # the file's channel (MDF4) or column (CSV)
//! unit = "rpm"                     # optional: when the file stores none, or to override it
//! [channels.p_cyl1_pa]
//! from = "BC_Pressure_1"
//! [metadata]
//! rail = "wet"
//! initial_speed_kmh = 120
//! ```
//!
//! The same map reads an MDF4 recording and a CSV export of it. A file's column that the
//! map does not name keeps its name (a spec column by name, or an unknown column).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use hils_sil::record::{Channel, friction_test as ft, run_log as rl};
use serde::Deserialize;

use super::table::{MeasuredError, file_error};
use super::units::{Quantity, ToSi, to_si};

/// One spec column's source.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Source {
    /// The file's channel or column name.
    pub from: String,
    /// Its unit (overrides what the file stores).
    pub unit: Option<String>,
}

/// A channel map as read from its TOML file.
#[derive(Clone, Debug, Default, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ChannelMap {
    #[serde(skip)]
    pub path: PathBuf,
    /// Wheel radius, m: converts wheel speeds logged as speeds (km/h) to rad/s.
    pub wheel_radius_m: Option<f64>,
    #[serde(default)]
    pub channels: BTreeMap<String, Source>,
    #[serde(default)]
    pub metadata: BTreeMap<String, toml::Value>,
}

/// Every spec column a map may name (run log and friction test).
fn spec_channel(name: &str) -> Option<Channel> {
    Channel::find(&rl::ALL, name)
        .or_else(|| {
            Channel::find(
                &[
                    ft::V_FRICTION,
                    ft::T_DISC,
                    ft::MU,
                    ft::F_CLAMP,
                    ft::F_FRICTION,
                ],
                name,
            )
        })
        .map(|(c, _)| c)
}

impl ChannelMap {
    /// Reads and checks a map file: every table names a spec column, every source is a
    /// name, the wheel radius is plausible, the metadata values are texts or numbers.
    pub fn load(path: &Path) -> Result<ChannelMap, MeasuredError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| file_error(path, format!("cannot read the channel map: {e}")))?;
        Self::parse(path, &text)
    }

    /// Parses a map's text (`path` names it in messages).
    pub fn parse(path: &Path, text: &str) -> Result<ChannelMap, MeasuredError> {
        let mut map: ChannelMap = toml::from_str(text)
            .map_err(|e| file_error(path, format!("channel map: {}", e.message())))?;
        map.path = path.to_path_buf();
        let err = |key: &str, m: String| MeasuredError {
            column: key.to_string(),
            ..file_error(path, format!("channel map: {m}"))
        };
        for (key, src) in &map.channels {
            if spec_channel(key).is_none() {
                return Err(err(
                    key,
                    format!(
                        "`[channels.{key}]` is not a column of spec/measured-data.md \
                         (e.g. omega1_radps, p_cyl1_pa, v_ref_mps)"
                    ),
                ));
            }
            if src.from.trim().is_empty() {
                return Err(err(key, format!("`[channels.{key}]`: `from` is empty")));
            }
        }
        if let Some(r) = map.wheel_radius_m {
            if !(r > 0.05 && r < 2.0) {
                return Err(err(
                    "wheel_radius_m",
                    format!("wheel_radius_m = {r}: not a wheel radius in metres (0.05 to 2)"),
                ));
            }
        }
        for (k, v) in &map.metadata {
            if !matches!(
                v,
                toml::Value::String(_) | toml::Value::Integer(_) | toml::Value::Float(_)
            ) {
                return Err(err(
                    k,
                    format!("`[metadata] {k}` must be a text or a number"),
                ));
            }
        }
        Ok(map)
    }

    /// The map's metadata as `key: value` texts.
    pub fn metadata_pairs(&self) -> Vec<(String, String)> {
        self.metadata
            .iter()
            .map(|(k, v)| {
                let text = match v {
                    toml::Value::String(s) => s.clone(),
                    other => other.to_string(),
                };
                (k.clone(), text)
            })
            .collect()
    }

    /// The spec column a file's channel `name` is mapped to (None: not named by the map).
    pub fn target_of(&self, name: &str) -> Vec<&str> {
        self.channels
            .iter()
            .filter(|(_, s)| s.from == name)
            .map(|(k, _)| k.as_str())
            .collect()
    }
}

/// How a file's column is read: the spec column it fills (or its own name when the map
/// does not name it), the file's name (for messages), and the conversion to SI.
#[derive(Clone, Debug, PartialEq)]
pub struct Resolved {
    /// The spec column (or the file's name, for a column the map does not name).
    pub target: String,
    /// The file's name.
    pub source: String,
    pub to_si: ToSi,
    /// The unit converted from (empty: the spec's own).
    pub unit: String,
}

impl Resolved {
    /// The column for messages: `BC_Pressure_1 (p_cyl1_pa)`, or the spec name alone.
    pub fn label(&self) -> String {
        if self.source == self.target {
            self.target.clone()
        } else {
            format!("{} ({})", self.source, self.target)
        }
    }
}

/// At most this many of a file's names listed in a message.
const LIST_NAMES: usize = 40;

/// `a, b, c` (the first [`LIST_NAMES`], then how many more).
pub fn list_names(names: &[String]) -> String {
    let mut s = names
        .iter()
        .take(LIST_NAMES)
        .map(|n| format!("`{n}`"))
        .collect::<Vec<_>>()
        .join(", ");
    if names.len() > LIST_NAMES {
        s += &format!(" and {} more", names.len() - LIST_NAMES);
    }
    s
}

/// The targets of a file's `names` (with `units` the file stores, "" = none; CSV: all
/// empty) under `map`: each mapped source renamed to its spec column, every spec column's
/// unit converted to SI. Errors: a map source absent from the file, a name twice, a unit
/// that is not of its column's quantity, a mapped column whose unit nobody gives.
pub fn resolve(
    map: Option<&ChannelMap>,
    file: &Path,
    names: &[String],
    units: &[String],
) -> Result<Vec<Resolved>, MeasuredError> {
    if let Some(map) = map {
        for (key, src) in &map.channels {
            if !names.iter().any(|n| *n == src.from) {
                return Err(MeasuredError {
                    column: src.from.clone(),
                    ..file_error(
                        file,
                        format!(
                            "the channel map ({}) takes `{key}` from `{}`, which the file does \
                             not have; its channels: {}",
                            map.path.display(),
                            src.from,
                            list_names(names)
                        ),
                    )
                });
            }
        }
    }
    let mut out: Vec<Resolved> = Vec::with_capacity(names.len());
    for (i, name) in names.iter().enumerate() {
        let stored = units.get(i).map_or("", |u| u.trim());
        let r = resolve_one(map, file, name, stored)?;
        if let Some(prev) = out.iter().find(|p| p.target == r.target) {
            return Err(MeasuredError {
                column: r.target.clone(),
                ..file_error(
                    file,
                    format!(
                        "`{}` comes from two of the file's columns: `{}` and `{}` (name one in \
                         the channel map, or rename)",
                        r.target, prev.source, r.source
                    ),
                )
            });
        }
        out.push(r);
    }
    Ok(out)
}

fn resolve_one(
    map: Option<&ChannelMap>,
    file: &Path,
    name: &str,
    stored: &str,
) -> Result<Resolved, MeasuredError> {
    let targets = map.map_or(Vec::new(), |m| m.target_of(name));
    let (target, map_unit) = match targets.as_slice() {
        [] => (name.to_string(), None),
        [t] => (t.to_string(), map.and_then(|m| m.channels[*t].unit.clone())),
        many => {
            return Err(MeasuredError {
                column: name.to_string(),
                ..file_error(
                    file,
                    format!(
                        "the channel map takes {} from `{name}`: one each",
                        many.join(", ")
                    ),
                )
            });
        }
    };
    let mapped = !targets.is_empty();
    let unit = map_unit.unwrap_or_else(|| stored.to_string());
    let plain = |to_si| Resolved {
        target: target.clone(),
        source: name.to_string(),
        to_si,
        unit: String::new(),
    };
    let Some(channel) = spec_channel(&target) else {
        return Ok(plain(ToSi::IDENTITY));
    };
    let quantity = Quantity::of_symbol(channel.unit_symbol());
    if unit.is_empty() {
        if mapped && quantity != Quantity::Dimensionless {
            return Err(MeasuredError {
                column: name.to_string(),
                ..file_error(
                    file,
                    format!(
                        "`{name}` (mapped to `{target}`): the file stores no unit for it; give \
                         `unit = \"...\"` in the channel map (`{target}` is {} in {})",
                        quantity.describe(),
                        channel.unit_symbol()
                    ),
                )
            });
        }
        // A spec name without stored unit: the name's own unit.
        return Ok(plain(ToSi::IDENTITY));
    }
    let conv = convert(map, quantity, &unit).map_err(|m| MeasuredError {
        column: name.to_string(),
        ..file_error(file, format!("`{name}` (as `{target}`): {m}"))
    })?;
    Ok(Resolved {
        unit: if conv.is_identity() {
            String::new()
        } else {
            unit
        },
        ..plain(conv)
    })
}

/// The conversion of `unit` for `quantity`; a speed unit on an angular speed through the
/// map's wheel radius.
fn convert(map: Option<&ChannelMap>, quantity: Quantity, unit: &str) -> Result<ToSi, String> {
    match to_si(quantity, unit) {
        Ok(c) => Ok(c),
        Err(e) if quantity == Quantity::AngularSpeed => match to_si(Quantity::Speed, unit) {
            Ok(v) => match map.and_then(|m| m.wheel_radius_m) {
                Some(r) => Ok(ToSi {
                    factor: v.factor / r,
                    offset: v.offset / r,
                }),
                None => Err(format!(
                    "unit `{unit}` is a speed (the wheel's circumferential speed): give \
                     `wheel_radius_m` in the channel map to turn it into rad/s"
                )),
            },
            Err(_) => Err(e),
        },
        Err(e) => Err(e),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MAP: &str = r#"
wheel_radius_m = 0.43
[channels.omega1_radps]
from = "WheelSpeed_Axle1"
unit = "km/h"
[channels.p_cyl1_pa]
from = "BC_Pressure_1"
[metadata]
rail = "wet"
initial_speed_kmh = 120
"#;

    fn names(v: &[&str]) -> Vec<String> {
        v.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn maps_names_and_units() {
        let map = ChannelMap::parse(Path::new("m.toml"), MAP).unwrap();
        let r = resolve(
            Some(&map),
            Path::new("f.mf4"),
            &names(&["WheelSpeed_Axle1", "BC_Pressure_1", "v_ref_mps", "Other"]),
            &names(&["", "bar", "km/h", "V"]),
        )
        .unwrap();
        assert_eq!(r[0].target, "omega1_radps");
        assert!((r[0].to_si.apply(3.6 * 0.43) - 1.0).abs() < 1e-12);
        assert_eq!(
            (r[1].target.as_str(), r[1].to_si.factor),
            ("p_cyl1_pa", 1e5)
        );
        assert!((r[2].to_si.apply(36.0) - 10.0).abs() < 1e-12);
        assert_eq!(r[3].target, "Other");
        assert_eq!(
            map.metadata_pairs(),
            vec![
                ("initial_speed_kmh".into(), "120".into()),
                ("rail".into(), "wet".into())
            ]
        );
    }

    /// Flags and texts (valves, command) carry no quantity: a logger's label for "no unit"
    /// (`[-]`, `bool`, `state`) is read as none; a unit of a quantity (bar) is refused.
    #[test]
    fn flags_and_texts_take_unit_labels_but_not_units_of_a_quantity() {
        let r = resolve(
            None,
            Path::new("f.mf4"),
            &names(&["wsp1", "wsp2", "cmd", "wsp3"]),
            &names(&["bool", "[-]", "state", "%"]),
        )
        .unwrap();
        assert!(r[..3].iter().all(|x| x.to_si.is_identity()));
        assert_eq!(r[3].to_si.factor, 0.01);
        let e = resolve(
            None,
            Path::new("f.mf4"),
            &names(&["wsp1"]),
            &names(&["bar"]),
        )
        .unwrap_err();
        assert!(e.message.contains("pressure unit"), "{e}");
    }

    #[test]
    fn bad_maps_and_units_name_the_channel() {
        let map = ChannelMap::parse(Path::new("m.toml"), MAP).unwrap();
        let e = resolve(
            Some(&map),
            Path::new("f.mf4"),
            &names(&["BC_Pressure_1"]),
            &[],
        )
        .unwrap_err();
        assert_eq!(e.column, "WheelSpeed_Axle1");
        assert!(e.to_string().contains("f.mf4"), "{e}");
        let e = resolve(
            Some(&map),
            Path::new("f.mf4"),
            &names(&["WheelSpeed_Axle1", "BC_Pressure_1"]),
            &names(&["", ""]),
        )
        .unwrap_err();
        assert_eq!(e.column, "BC_Pressure_1");
        assert!(e.message.contains("no unit"), "{e}");
        let e = resolve(
            None,
            Path::new("f.mf4"),
            &names(&["v_ref_mps"]),
            &names(&["bar"]),
        )
        .unwrap_err();
        assert!(e.message.contains("pressure unit"), "{e}");
        let e = ChannelMap::parse(
            Path::new("m.toml"),
            "[channels.omega9_radps]\nfrom = \"x\"\n",
        )
        .unwrap_err();
        assert_eq!(e.column, "omega9_radps");
        let e = ChannelMap::parse(
            Path::new("m.toml"),
            "[channels.omega1_radps]\nform = \"x\"\n",
        )
        .unwrap_err();
        assert!(e.to_string().contains("m.toml"), "{e}");
    }
}
