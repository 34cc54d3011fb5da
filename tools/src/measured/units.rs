//! Units of measured channels: a unit text as a file stores it (MDF4's channel unit) or as
//! a channel map names it (`unit = "bar"`), converted to the SI unit of the spec's column
//! (`hils_sil::record::Channel::unit_symbol`) by the units library `uom` (its unit
//! abbreviations and names; its conversion factors). Only the spellings loggers use that
//! `uom` does not know are mapped onto its own ([`ALIASES`]); no factor is written here.
//!
//! A unit that is not a unit of the column's quantity (a pressure unit on a speed column)
//! or that no quantity knows is an error; its message says which quantity the unit is of,
//! when it is one.

use uom::si::f64::{
    Acceleration, AngularVelocity, Force, Length, Pressure, Ratio, TemperatureInterval, Time,
    Velocity,
};

/// The quantity of a spec column, named after its SI unit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Quantity {
    Time,
    Speed,
    AngularSpeed,
    Pressure,
    Force,
    /// A temperature difference (the spec's disc temperature is a rise above ambient).
    TemperatureRise,
    Length,
    Acceleration,
    /// A number without unit (a flag, a coefficient).
    Dimensionless,
}

impl Quantity {
    /// The quantity of a column whose SI unit is `symbol` (`Channel::unit_symbol`).
    pub fn of_symbol(symbol: &str) -> Quantity {
        match symbol {
            "s" | "us" => Quantity::Time,
            "m/s" => Quantity::Speed,
            "rad/s" => Quantity::AngularSpeed,
            "Pa" => Quantity::Pressure,
            "N" => Quantity::Force,
            "degC" => Quantity::TemperatureRise,
            "m" => Quantity::Length,
            "m/s^2" => Quantity::Acceleration,
            _ => Quantity::Dimensionless,
        }
    }

    /// For messages: "a speed", "a pressure".
    pub fn describe(self) -> &'static str {
        match self {
            Quantity::Time => "a time",
            Quantity::Speed => "a speed",
            Quantity::AngularSpeed => "an angular speed",
            Quantity::Pressure => "a pressure",
            Quantity::Force => "a force",
            Quantity::TemperatureRise => "a temperature",
            Quantity::Length => "a length",
            Quantity::Acceleration => "an acceleration",
            Quantity::Dimensionless => "a dimensionless number",
        }
    }

    const ALL: [Quantity; 9] = [
        Quantity::Time,
        Quantity::Speed,
        Quantity::AngularSpeed,
        Quantity::Pressure,
        Quantity::Force,
        Quantity::TemperatureRise,
        Quantity::Length,
        Quantity::Acceleration,
        Quantity::Dimensionless,
    ];
}

/// A linear conversion to SI: `si = raw * factor + offset`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ToSi {
    pub factor: f64,
    pub offset: f64,
}

impl ToSi {
    pub const IDENTITY: ToSi = ToSi {
        factor: 1.0,
        offset: 0.0,
    };

    pub fn apply(self, raw: f64) -> f64 {
        raw * self.factor + self.offset
    }

    pub fn is_identity(self) -> bool {
        self == Self::IDENTITY
    }
}

/// Spellings loggers use for units whose `uom` abbreviation differs (ASCII for `°`, `²`,
/// `µ`; the German `U/min`; `kph`): mapped onto `uom`'s abbreviation.
pub const ALIASES: [(&str, &str); 20] = [
    ("degC", "°C"),
    ("deg C", "°C"),
    ("°C", "°C"),
    ("C", "°C"),
    ("K", "K"),
    ("degF", "°F"),
    ("m/s^2", "m/s²"),
    ("m/s2", "m/s²"),
    ("m/(s^2)", "m/s²"),
    ("g", "g₀"),
    ("kph", "km/h"),
    ("kmh", "km/h"),
    ("km/hr", "km/h"),
    ("U/min", "rpm"),
    ("1/min", "rpm"),
    ("min^-1", "rpm"),
    ("r/min", "rpm"),
    ("us", "µs"),
    ("rad/sec", "rad/s"),
    ("Nm", "N · m"),
];

/// `uom`'s spelling of a unit text (trimmed; aliases resolved).
fn canonical(unit: &str) -> &str {
    let u = unit.trim();
    ALIASES.iter().find(|(a, _)| *a == u).map_or(u, |(_, c)| c)
}

/// The SI value of `x` of `unit` in `quantity`, by `uom` (None: not a unit of it).
fn parse_in(quantity: Quantity, x: f64, unit: &str) -> Option<f64> {
    let text = format!("{x} {unit}");
    match quantity {
        Quantity::Time => text.parse::<Time>().ok().map(|q| q.value),
        Quantity::Speed => text.parse::<Velocity>().ok().map(|q| q.value),
        Quantity::AngularSpeed => text.parse::<AngularVelocity>().ok().map(|q| q.value),
        Quantity::Pressure => text.parse::<Pressure>().ok().map(|q| q.value),
        Quantity::Force => text.parse::<Force>().ok().map(|q| q.value),
        Quantity::TemperatureRise => text.parse::<TemperatureInterval>().ok().map(|q| q.value),
        Quantity::Length => text.parse::<Length>().ok().map(|q| q.value),
        Quantity::Acceleration => text.parse::<Acceleration>().ok().map(|q| q.value),
        Quantity::Dimensionless => match unit {
            "" | "-" | "1" => Some(x),
            _ => text.parse::<Ratio>().ok().map(|q| q.value),
        },
    }
}

/// The conversion of `unit` to the SI unit of `quantity` (an empty unit on a dimensionless
/// quantity is the identity), or the error saying what the unit is.
pub fn to_si(quantity: Quantity, unit: &str) -> Result<ToSi, String> {
    let u = canonical(unit);
    if u.is_empty() && quantity != Quantity::Dimensionless {
        return Err(format!("no unit given; {} needs one", quantity.describe()));
    }
    let base = parse_in(quantity, 0.0, u);
    let one = parse_in(quantity, 1.0, u);
    match (base, one) {
        (Some(offset), Some(at_one)) if (at_one - offset).is_finite() && at_one != offset => {
            let factor = at_one - offset;
            // Round-off of uom's base conversion (0.0 -> -0.0, 1e-17): SI units stay exact.
            let offset = if offset.abs() < 1e-12 { 0.0 } else { offset };
            Ok(ToSi { factor, offset })
        }
        _ => {
            let other = Quantity::ALL
                .iter()
                .find(|&&q| q != quantity && parse_in(q, 1.0, u).is_some());
            // A flag or a text (valve, command) has no quantity: a logger's label for "no
            // unit" (`[-]`, `bool`, `state`) is none; a unit of a quantity is refused.
            if quantity == Quantity::Dimensionless && other.is_none() {
                return Ok(ToSi::IDENTITY);
            }
            Err(match other {
                Some(q) if !u.is_empty() => format!(
                    "unit `{unit}` is {} unit, not {} unit",
                    q.describe(),
                    quantity.describe()
                ),
                _ => format!(
                    "unit `{unit}` is not a unit of {} (known to the units library: e.g. {})",
                    quantity.describe(),
                    examples(quantity)
                ),
            })
        }
    }
}

/// A few units of `quantity`, for messages.
fn examples(quantity: Quantity) -> &'static str {
    match quantity {
        Quantity::Time => "s, ms, min",
        Quantity::Speed => "m/s, km/h, mi/h",
        Quantity::AngularSpeed => "rad/s, rpm, °/s",
        Quantity::Pressure => "Pa, kPa, bar, psi",
        Quantity::Force => "N, kN",
        Quantity::TemperatureRise => "degC, K",
        Quantity::Length => "m, km",
        Quantity::Acceleration => "m/s^2, g",
        Quantity::Dimensionless => "-, %",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Within 1e-7 relative: uom defines psi to 7 digits (6894.757 Pa).
    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() <= 1e-7 * b.abs().max(1.0)
    }

    /// Factors against independent definitions (SI brochure, ISO 80000).
    #[test]
    fn logger_units_convert_to_si() {
        let cases = [
            (Quantity::Speed, "km/h", 1.0 / 3.6),
            (Quantity::Speed, "kph", 1.0 / 3.6),
            (Quantity::Speed, "m/s", 1.0),
            (Quantity::AngularSpeed, "rpm", std::f64::consts::PI / 30.0),
            (Quantity::AngularSpeed, "U/min", std::f64::consts::PI / 30.0),
            (Quantity::AngularSpeed, "rad/s", 1.0),
            (Quantity::Pressure, "bar", 1e5),
            (Quantity::Pressure, "kPa", 1e3),
            (Quantity::Pressure, "MPa", 1e6),
            (Quantity::Pressure, "psi", 6894.757293168361),
            (Quantity::Force, "kN", 1e3),
            (Quantity::TemperatureRise, "degC", 1.0),
            (Quantity::TemperatureRise, "K", 1.0),
            (Quantity::Acceleration, "g", 9.80665),
            (Quantity::Acceleration, "m/s^2", 1.0),
            (Quantity::Time, "ms", 1e-3),
            (Quantity::Time, "s", 1.0),
            (Quantity::Dimensionless, "", 1.0),
            (Quantity::Dimensionless, "%", 0.01),
        ];
        for (q, unit, factor) in cases {
            let c = to_si(q, unit).unwrap_or_else(|e| panic!("{unit}: {e}"));
            assert!(close(c.factor, factor), "{unit}: {} vs {factor}", c.factor);
            assert_eq!(c.offset, 0.0, "{unit}");
        }
    }

    #[test]
    fn a_unit_of_another_quantity_is_named() {
        let e = to_si(Quantity::Speed, "bar").unwrap_err();
        assert!(e.contains("pressure unit"), "{e}");
        let e = to_si(Quantity::Pressure, "km/h").unwrap_err();
        assert!(e.contains("speed unit"), "{e}");
        let e = to_si(Quantity::Pressure, "furlongs").unwrap_err();
        assert!(e.contains("not a unit of a pressure"), "{e}");
        assert!(to_si(Quantity::Pressure, "").is_err());
    }
}
