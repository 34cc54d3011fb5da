//! MDF4 conversions (CC blocks): raw value -> physical value. Read: identity (0), linear
//! (1), rational (2), value to value with (4) and without (5) interpolation, value range
//! to value (6), value to text (7), value range to text (8). The others (algebraic
//! formulas, text to value, bitfields) are named in an error when a channel that is used
//! has one.

use super::blocks::{Block, Blocks};

/// A conversion of a channel's raw values.
#[derive(Clone, Debug, PartialEq)]
pub enum Conversion {
    Identity,
    /// phys = offset + factor * raw.
    Linear {
        offset: f64,
        factor: f64,
    },
    /// phys = (p1 x^2 + p2 x + p3) / (p4 x^2 + p5 x + p6).
    Rational([f64; 6]),
    /// Pairs (raw, phys), raw increasing; `interpolate`: linear between keys, else the
    /// value of the nearest key.
    Table {
        keys: Vec<f64>,
        values: Vec<f64>,
        interpolate: bool,
    },
    /// Ranges [lo, hi] (integers) or [lo, hi) (floats) -> value, with a default.
    Ranges {
        ranges: Vec<(f64, f64, f64)>,
        default: f64,
    },
    /// Raw value (or range) -> text, with a default text.
    Texts {
        keys: Vec<(f64, f64)>,
        texts: Vec<String>,
        default: String,
    },
    /// A conversion not read (its CC type, for the message).
    Unsupported(u8),
}

/// A physical value: a number or a text.
#[derive(Clone, Debug, PartialEq)]
pub enum Phys {
    Num(f64),
    Text(String),
}

impl Conversion {
    /// Whether the conversion gives texts.
    pub fn is_text(&self) -> bool {
        matches!(self, Conversion::Texts { .. })
    }

    /// The physical value of an integer raw value `x` (NaN stays NaN).
    pub fn apply(&self, x: f64) -> Phys {
        self.apply_raw(x, false)
    }

    /// The physical value of raw value `x`; `float_raw`: the channel stores floats, whose
    /// ranges (range to value 6, range to text 8) exclude their upper bound, lower <= x <
    /// upper, where an integer's include it (ASAM MDF 4.1, CC_R2V and CC_R2T; asammdf reads
    /// them so). NaN stays NaN.
    pub fn apply_raw(&self, x: f64, float_raw: bool) -> Phys {
        let within = |lo: f64, hi: f64| x >= lo && (x < hi || (!float_raw && x == hi));
        Phys::Num(match self {
            Conversion::Identity | Conversion::Unsupported(_) => x,
            Conversion::Linear { offset, factor } => offset + factor * x,
            Conversion::Rational(p) => {
                (p[0] * x * x + p[1] * x + p[2]) / (p[3] * x * x + p[4] * x + p[5])
            }
            Conversion::Table {
                keys,
                values,
                interpolate,
            } => table(keys, values, *interpolate, x),
            Conversion::Ranges { .. } if x.is_nan() => x,
            Conversion::Ranges { ranges, default } => ranges
                .iter()
                .find(|(lo, hi, _)| within(*lo, *hi))
                .map_or(*default, |r| r.2),
            Conversion::Texts {
                keys,
                texts,
                default,
            } => {
                let t = keys
                    .iter()
                    .position(|&(lo, hi)| within(lo, hi) || (lo == hi && x == lo))
                    .map_or(default.as_str(), |i| texts[i].as_str());
                return Phys::Text(t.to_string());
            }
        })
    }
}

/// An MDF4 conversion type (`cc_type`) for messages.
pub fn type_name(cc_type: u8) -> &'static str {
    match cc_type {
        3 => "an algebraic formula",
        9 => "a text-to-value table",
        10 => "a text-to-text table",
        11 => "a bit-field text table",
        _ => "a conversion of an unknown type",
    }
}

/// A value-to-value table (keys increasing, as the format requires).
fn table(keys: &[f64], values: &[f64], interpolate: bool, x: f64) -> f64 {
    if keys.is_empty() || x.is_nan() {
        return f64::NAN;
    }
    let i = keys.partition_point(|&k| k < x);
    if i == 0 {
        return values[0];
    }
    if i >= keys.len() {
        return values[keys.len() - 1];
    }
    let (k0, k1) = (keys[i - 1], keys[i]);
    if interpolate {
        if k1 == k0 {
            return values[i];
        }
        values[i - 1] + (values[i] - values[i - 1]) * (x - k0) / (k1 - k0)
    } else if x - k0 <= k1 - x {
        // Nearest key; on a tie, the lower (as the format says).
        values[i - 1]
    } else {
        values[i]
    }
}

/// Reads the CC block at `addr` (identity for link 0), with the unit it carries (its
/// `cc_md_unit`, used when the channel has none).
pub fn read(blocks: &Blocks, addr: u64) -> Result<(Conversion, String), String> {
    if addr == 0 {
        return Ok((Conversion::Identity, String::new()));
    }
    let b = blocks.block(addr, &[b"CC"])?;
    b.need(24)?;
    let unit = blocks.plain_text(b.link(1))?;
    let cc_type = b.data[0];
    let ref_count = b.uint(2 + 2, 2) as usize;
    let val_count = b.uint(6, 2) as usize;
    b.need(24 + 8 * val_count)?;
    let vals: Vec<f64> = (0..val_count).map(|i| b.f64(24 + 8 * i)).collect();
    let refs: Vec<u64> = (0..ref_count).map(|i| b.link(4 + i)).collect();
    let need = |n: usize| -> Result<(), String> {
        if val_count < n {
            return Err(format!(
                "conversion at {addr:#x} (type {cc_type}): {val_count} values, needs {n}"
            ));
        }
        Ok(())
    };
    let conv = match cc_type {
        0 => Conversion::Identity,
        1 => {
            need(2)?;
            Conversion::Linear {
                offset: vals[0],
                factor: vals[1],
            }
        }
        2 => {
            need(6)?;
            Conversion::Rational([vals[0], vals[1], vals[2], vals[3], vals[4], vals[5]])
        }
        4 | 5 => {
            let n = val_count / 2;
            Conversion::Table {
                keys: (0..n).map(|i| vals[2 * i]).collect(),
                values: (0..n).map(|i| vals[2 * i + 1]).collect(),
                interpolate: cc_type == 4,
            }
        }
        6 => {
            let n = val_count / 3;
            Conversion::Ranges {
                ranges: (0..n)
                    .map(|i| (vals[3 * i], vals[3 * i + 1], vals[3 * i + 2]))
                    .collect(),
                default: vals.get(3 * n).copied().unwrap_or(f64::NAN),
            }
        }
        7 | 8 => texts(blocks, &b, cc_type, &vals, &refs)?,
        other => Conversion::Unsupported(other),
    };
    Ok((conv, unit))
}

/// A value-to-text (7) or range-to-text (8) conversion; its references are TX blocks
/// (a reference to a further conversion is read as its name, not applied).
fn texts(
    blocks: &Blocks,
    b: &Block,
    cc_type: u8,
    vals: &[f64],
    refs: &[u64],
) -> Result<Conversion, String> {
    let n = if cc_type == 7 {
        vals.len()
    } else {
        vals.len() / 2
    };
    let text_of = |addr: u64| -> Result<String, String> {
        if addr == 0 {
            return Ok(String::new());
        }
        let h = blocks.header(addr, &[b"TX", b"MD", b"CC"])?;
        if &h.id == b"CC" {
            return Err(format!(
                "conversion at {:#x}: a value-to-text table that refers to a further conversion (not read)",
                b.addr
            ));
        }
        blocks.plain_text(addr)
    };
    let mut texts = Vec::with_capacity(n);
    for i in 0..n {
        texts.push(text_of(refs.get(i).copied().unwrap_or(0))?);
    }
    let default = text_of(refs.get(n).copied().unwrap_or(0))?;
    let keys = (0..n)
        .map(|i| {
            if cc_type == 7 {
                (vals[i], vals[i])
            } else {
                (vals[2 * i], vals[2 * i + 1])
            }
        })
        .collect();
    Ok(Conversion::Texts {
        keys,
        texts,
        default,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tables_interpolate_or_take_the_nearest_key() {
        let keys = vec![0.0, 10.0, 20.0];
        let values = vec![0.0, 100.0, 400.0];
        let tabi = Conversion::Table {
            keys: keys.clone(),
            values: values.clone(),
            interpolate: true,
        };
        let tab = Conversion::Table {
            keys,
            values,
            interpolate: false,
        };
        assert_eq!(tabi.apply(5.0), Phys::Num(50.0));
        assert_eq!(tabi.apply(15.0), Phys::Num(250.0));
        assert_eq!(tabi.apply(-3.0), Phys::Num(0.0));
        assert_eq!(tabi.apply(30.0), Phys::Num(400.0));
        assert_eq!(tab.apply(4.0), Phys::Num(0.0));
        assert_eq!(tab.apply(5.0), Phys::Num(0.0));
        assert_eq!(tab.apply(6.0), Phys::Num(100.0));
        assert_eq!(tab.apply(19.0), Phys::Num(400.0));
    }

    #[test]
    fn linear_rational_and_texts() {
        let lin = Conversion::Linear {
            offset: 1.0,
            factor: 0.5,
        };
        assert_eq!(lin.apply(4.0), Phys::Num(3.0));
        let rat = Conversion::Rational([0.0, 2.0, 1.0, 0.0, 0.0, 2.0]);
        assert_eq!(rat.apply(3.0), Phys::Num(3.5));
        let t = Conversion::Texts {
            keys: vec![(0.0, 0.0), (1.0, 1.0)],
            texts: vec!["REL".into(), "EB".into()],
            default: "?".into(),
        };
        assert_eq!(t.apply(1.0), Phys::Text("EB".into()));
        assert_eq!(t.apply(7.0), Phys::Text("?".into()));
    }

    /// ASAM MDF 4.1 (CC_R2V, CC_R2T): an integer's range includes its upper bound, a
    /// float's excludes it, so adjacent float ranges [0, 10), [10, 20) do not overlap.
    #[test]
    fn float_ranges_exclude_their_upper_bound() {
        let r = Conversion::Ranges {
            ranges: vec![(0.0, 10.0, 1.0), (10.0, 20.0, 2.0)],
            default: -1.0,
        };
        assert_eq!(r.apply_raw(10.0, false), Phys::Num(1.0));
        assert_eq!(r.apply_raw(10.0, true), Phys::Num(2.0));
        assert_eq!(r.apply_raw(20.0, false), Phys::Num(2.0));
        assert_eq!(r.apply_raw(20.0, true), Phys::Num(-1.0));
        assert_eq!(r.apply_raw(19.999, true), Phys::Num(2.0));
        let t = Conversion::Texts {
            keys: vec![(0.0, 0.5), (0.5, 1.0), (3.0, 3.0)],
            texts: vec!["low".into(), "high".into(), "three".into()],
            default: "?".into(),
        };
        assert_eq!(t.apply_raw(0.5, true), Phys::Text("high".into()));
        assert_eq!(t.apply_raw(0.5, false), Phys::Text("low".into()));
        assert_eq!(t.apply_raw(1.0, true), Phys::Text("?".into()));
        // A single value (lower = upper) still matches itself in a float channel.
        assert_eq!(t.apply_raw(3.0, true), Phys::Text("three".into()));
    }
}
