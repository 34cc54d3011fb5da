//! The units of the model description: each unit symbol the parameter file's key table
//! ([`hils_plant::keys::KeyInfo::unit`]) or the run-log schema (a channel's unit suffix) uses,
//! with its SI base-unit exponents (FMI 3.0 `UnitDefinitions`, `BaseUnit`). A symbol not in
//! the table is an error of the model description's build (`tests/model_description.rs`
//! builds it from every key and signal), so a key added with a new unit cannot ship without
//! its definition.

/// One unit: its symbol (Modelica's notation) and SI base-unit exponents.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Unit {
    /// Symbol as variables name it (`N.s/m`).
    pub name: &'static str,
    /// Exponents of kg, m, s, K, rad.
    pub kg: i8,
    /// Exponent of m.
    pub m: i8,
    /// Exponent of s.
    pub s: i8,
    /// Exponent of K.
    pub k: i8,
    /// Exponent of rad.
    pub rad: i8,
    /// value in SI = factor x value + offset.
    pub factor: f64,
    /// Offset to SI (degC: 273.15; a temperature rise is marked `relativeQuantity`).
    pub offset: f64,
}

const fn unit(name: &'static str, kg: i8, m: i8, s: i8, k: i8, rad: i8) -> Unit {
    Unit {
        name,
        kg,
        m,
        s,
        k,
        rad,
        factor: 1.0,
        offset: 0.0,
    }
}

/// Every unit the model description uses, SI coherent unless a factor or offset says
/// otherwise.
pub const UNITS: [Unit; 24] = [
    unit("s", 0, 0, 1, 0, 0),
    unit("1/s", 0, 0, -1, 0, 0),
    unit("m", 0, 1, 0, 0, 0),
    unit("m2", 0, 2, 0, 0, 0),
    unit("m/s", 0, 1, -1, 0, 0),
    unit("s/m", 0, -1, 1, 0, 0),
    unit("m/s2", 0, 1, -2, 0, 0),
    Unit {
        factor: 1.0 / 3.6,
        ..unit("km/h", 0, 1, -1, 0, 0)
    },
    unit("rad/s", 0, 0, -1, 0, 1),
    unit("kg", 1, 0, 0, 0, 0),
    unit("kg.m2", 1, 2, 0, 0, 0),
    unit("N", 1, 1, -2, 0, 0),
    unit("N/m", 1, 0, -2, 0, 0),
    unit("N/m3", 1, -2, -2, 0, 0),
    unit("N.s/m", 1, 0, -1, 0, 0),
    unit("N.s2/m2", 1, -1, 0, 0, 0),
    unit("Pa", 1, -1, -2, 0, 0),
    unit("J/m", 1, 1, -2, 0, 0),
    unit("J/(kg.K)", 0, 2, -2, -1, 0),
    unit("W/K", 1, 2, -3, -1, 0),
    unit("1/K", 0, 0, 0, -1, 0),
    Unit {
        offset: 273.15,
        ..unit("degC", 0, 0, 0, 1, 0)
    },
    Unit {
        factor: 1e-3,
        ..unit("1/1000", 0, 0, 0, 0, 0)
    },
    unit("rad", 0, 0, 0, 0, 1),
];

/// The unit of a symbol, if the table has it.
pub fn find(name: &str) -> Option<&'static Unit> {
    UNITS.iter().find(|u| u.name == name)
}

/// The unit symbol of a run-log channel's unit suffix (`_radps` -> `rad/s`); `None` for a
/// suffix without a unit here. The suffixes are those of `hils_sil::record::run_log`.
pub fn of_suffix(suffix: &str) -> Option<&'static str> {
    Some(match suffix {
        "" => "",
        "_s" => "s",
        "_m" => "m",
        "_mps" => "m/s",
        "_mps2" => "m/s2",
        "_radps" => "rad/s",
        "_pa" => "Pa",
        "_n" => "N",
        "_c" => "degC",
        _ => return None,
    })
}
