//! The keys of the parameter file as a table that tools outside the model read: each key's
//! name in the file, its meaning, its unit and its valid range, next to its value.
//!
//! Every section declares its keys once (the plant's in `params.rs`'s `section!` tables,
//! `[brake_unit]`, `[scenario]` and `[degraded_adhesion]` where those sections live); the
//! same declaration gives the range check of `validate()` and, through
//! [`KeyVisitor`], the list an FMU's model description, a generated parameter file or a
//! tool's help is made from. No second copy of the key list or its ranges exists.

/// What a key of the parameter file is, besides its value.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct KeyInfo {
    /// `section.key` as in the file (`vehicle.carbody_mass`).
    pub name: &'static str,
    /// Meaning, unit in words, source: the key's doc comment, one line per source line.
    pub doc: &'static str,
    /// Unit symbol in Modelica's notation (`kg`, `N/m`, `m/s2`, `kg.m2`, `degC`), empty
    /// for a dimensionless number, a count, a flag or a choice.
    pub unit: &'static str,
    /// Lowest valid value (`-inf` for a key without a range).
    pub min: f64,
    /// Highest valid value (`inf` for a key without a range).
    pub max: f64,
}

impl KeyInfo {
    /// A key without a range (a flag, a choice, a note).
    pub const fn unranged(name: &'static str, doc: &'static str) -> Self {
        Self {
            name,
            doc,
            unit: "",
            min: f64::NEG_INFINITY,
            max: f64::INFINITY,
        }
    }

    /// Checks `value` against the key's range; the error names the key
    /// ([`crate::params::check`], the one range check).
    pub fn check(&self, value: f64) -> Result<(), crate::ParamError> {
        crate::params::check(self.name, value, self.min, self.max)
    }
}

/// A key whose value is one of a few names (`friction.model`, `scenario.paper_eb.rail`).
pub trait Choice {
    /// The names a file may give, in index order.
    fn names(&self) -> &'static [&'static str];
    /// The index of the present value in [`Choice::names`].
    fn index(&self) -> usize;
    /// Sets the value of index `index`; false (nothing changed) for an index out of range.
    fn select(&mut self, index: usize) -> bool;
}

/// The value of a key, as a visitor may read or change it.
pub enum KeyValue<'a> {
    /// A number in the key's unit.
    Real(&'a mut f64),
    /// A whole number (a count of parallel elements, faces, steps).
    Count(&'a mut u32),
    /// On or off.
    Flag(&'a mut bool),
    /// One of a few names.
    Choice(&'a mut dyn Choice),
    /// Free text for people; the model keeps no value (`scenario.paper_eb.track`).
    Note,
}

/// Visits every key of a section or file, in file order, with its value.
pub trait KeyVisitor {
    /// One key and its value.
    fn key(&mut self, info: &KeyInfo, value: KeyValue<'_>);
}

/// A section (or a whole file) whose keys a [`KeyVisitor`] can walk.
pub trait Keys {
    /// Calls `visitor` once per key, in file order.
    fn visit_keys<V: KeyVisitor>(&mut self, visitor: &mut V);
}

/// A field of a section table without a range: a choice or a nested section.
pub trait Unranged {
    /// Visits the field as the key `info` (a nested section ignores `info`: its keys name
    /// themselves).
    fn visit_as<V: KeyVisitor>(&mut self, info: &KeyInfo, visitor: &mut V);
}

/// A key value with a range (a number or a count).
pub trait Ranged {
    /// The value for the visitor.
    fn key_value(&mut self) -> KeyValue<'_>;
}

impl Ranged for f64 {
    fn key_value(&mut self) -> KeyValue<'_> {
        KeyValue::Real(self)
    }
}

impl Ranged for u32 {
    fn key_value(&mut self) -> KeyValue<'_> {
        KeyValue::Count(self)
    }
}

/// Checks every ranged key of a section against its range: the first failure, naming the
/// key (the `validate()` of sections whose table is written with [`KeyVisitor`]).
pub fn check_keys<S: Keys>(section: &S) -> Result<(), crate::ParamError>
where
    S: Copy,
{
    struct Check(Result<(), crate::ParamError>);
    impl KeyVisitor for Check {
        fn key(&mut self, info: &KeyInfo, value: KeyValue<'_>) {
            let v = match value {
                KeyValue::Real(v) => *v,
                KeyValue::Count(n) => f64::from(*n),
                _ => return,
            };
            if self.0.is_ok() {
                self.0 = info.check(v);
            }
        }
    }
    let mut copy = *section;
    let mut check = Check(Ok(()));
    copy.visit_keys(&mut check);
    check.0
}

/// Implements [`Choice`] for a fieldless enum from its variants and file names, in index
/// order.
#[macro_export]
macro_rules! choice {
    ($ty:ty { $($variant:ident = $name:literal),+ $(,)? }) => {
        impl $crate::keys::Choice for $ty {
            fn names(&self) -> &'static [&'static str] {
                &[$($name),+]
            }
            fn index(&self) -> usize {
                let all = [$(<$ty>::$variant),+];
                all.iter().position(|v| v == self).unwrap_or(0)
            }
            fn select(&mut self, index: usize) -> bool {
                let all = [$(<$ty>::$variant),+];
                match all.get(index) {
                    Some(v) => {
                        *self = *v;
                        true
                    }
                    None => false,
                }
            }
        }
        impl $crate::keys::Unranged for $ty {
            fn visit_as<V: $crate::keys::KeyVisitor>(
                &mut self,
                info: &$crate::keys::KeyInfo,
                visitor: &mut V,
            ) {
                visitor.key(info, $crate::keys::KeyValue::Choice(self));
            }
        }
    };
}
