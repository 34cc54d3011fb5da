//! Parameters of the plant: the vehicle, contact, brake, friction, thermal, track and
//! resistance sections of the parameter file.
//!
//! The structs mirror `spec/reference-parameters.toml` section by section and key by key;
//! [`Params::default`] equals those sections of the file (a host test loads the file and
//! compares). The other sections belong to the crates that use them (`[brake_unit]`:
//! `hils-brake-unit`; `[scenario.paper_eb]`: `hils-sil`, which also owns the whole file). With
//! the `serde` feature every section derives `Deserialize` and rejects unknown keys, so a
//! misspelt key in a parameter file is an error, not a silently ignored value.
//!
//! A few keys are extensions that the reference file does not have (they default to
//! "effect absent"): `friction.k_p` (pad friction vs clamp force), `brake.actuator_lag_s`
//! (pad force lags the cylinder pressure). The diagnosis fits them as effects.

use crate::keys::{KeyInfo, KeyVisitor, Keys, Ranged, Unranged};
#[cfg(feature = "serde")]
use serde::Deserialize;

/// Wheel-rail condition: selects the Polach parameter set (`[contact]` or `[contact.dry]`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(
    feature = "serde",
    derive(Deserialize),
    serde(rename_all = "lowercase")
)]
pub enum Rail {
    /// Wet rail: the `[contact]` set (paper Table 2, the paper's scenario).
    #[default]
    Wet,
    /// Dry rail: the `[contact.dry]` set.
    Dry,
}

/// Disc-pad friction law.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(
    feature = "serde",
    derive(Deserialize),
    serde(rename_all = "lowercase")
)]
pub enum FrictionModel {
    /// Paper Eq (2): mu_d = c mu_d0 (n_v e^(-m_v v_d) + 1)(n_T e^(-m_T T_d) + 1).
    #[default]
    Variable,
    /// mu_d = mu_d0, the conventional assumption the paper questions.
    Constant,
}

crate::choice!(Rail { Wet = "wet", Dry = "dry" });
crate::choice!(FrictionModel {
    Variable = "variable",
    Constant = "constant"
});

/// One table per section: each key's type, valid range `[min, max, "unit"]` (where it has
/// one; the unit in Modelica's notation, empty when dimensionless) and default, written
/// once. It makes the struct (with serde's `deny_unknown_fields`), its `DEFAULT` and
/// `Default` (equal to `spec/reference-parameters.toml`) and, for a section of the file
/// (`Name "section" { .. }`), `check_ranges`, whose error names the file's key
/// `section.key`, and the key table ([`Keys`]: name, doc, unit, range, value) that tools
/// outside the model read.
macro_rules! section {
    ($(#[$m:meta])* $name:ident $key:literal {
        $($(#[doc = $doc:literal])* $(#[cfg_attr $fm:tt])* $field:ident : $ty:ty
            $([$min:expr, $max:expr, $unit:literal])? = $val:expr),* $(,)?
    }) => {
        section!($(#[$m])* $name { $($(#[doc = $doc])* $(#[cfg_attr $fm])* $field: $ty = $val),* });
        impl $name {
            /// Checks each key of this section against its valid range (NaN and inf are out
            /// of range); the error names the first key that fails.
            pub fn check_ranges(&self) -> Result<(), ParamError> {
                $($(check(concat!($key, ".", stringify!($field)), f64::from(self.$field), $min, $max)?;)?)*
                Ok(())
            }
        }
        impl Keys for $name {
            fn visit_keys<V: KeyVisitor>(&mut self, visitor: &mut V) {
                $(visit_field!(self, visitor, $key, $field, concat!($($doc, "\n"),*)
                    $(, [$min, $max, $unit])?);)*
            }
        }
    };
    ($(#[$m:meta])* $name:ident {
        $($(#[doc = $doc:literal])* $(#[cfg_attr $fm:tt])* $field:ident : $ty:ty = $val:expr),* $(,)?
    }) => {
        $(#[$m])*
        #[derive(Clone, Copy, Debug, PartialEq)]
        #[cfg_attr(feature = "serde", derive(Deserialize), serde(deny_unknown_fields))]
        pub struct $name { $($(#[doc = $doc])* $(#[cfg_attr $fm])* pub $field: $ty),* }
        impl Default for $name {
            fn default() -> Self { Self::DEFAULT }
        }
        impl $name {
            /// The reference file's values.
            pub const DEFAULT: Self = Self { $($field: $val),* };
        }
    };
}

/// One field of a section's key table: a ranged key (a number or a count) or an unranged
/// one (a choice, or a nested section whose keys name themselves).
macro_rules! visit_field {
    ($self:ident, $v:ident, $key:literal, $field:ident, $doc:expr, [$min:expr, $max:expr, $unit:literal]) => {
        $v.key(
            &KeyInfo {
                name: concat!($key, ".", stringify!($field)),
                doc: $doc,
                unit: $unit,
                min: $min as f64,
                max: $max as f64,
            },
            Ranged::key_value(&mut $self.$field),
        )
    };
    ($self:ident, $v:ident, $key:literal, $field:ident, $doc:expr) => {
        Unranged::visit_as(
            &mut $self.$field,
            &KeyInfo::unranged(concat!($key, ".", stringify!($field)), $doc),
            $v,
        )
    };
}

section!(
    /// `[vehicle]`: one car, 1 carbody, 2 bogies, 4 wheelsets (paper Table 3).
    VehicleParams "vehicle" {
        /// Gravitational acceleration g, m/s^2.
        g: f64 [0.1, 100.0, "m/s2"] = 9.81,
        /// Carbody mass, kg (paper Table 3).
        carbody_mass: f64 [1e3, 1e6, "kg"] = 35000.0,
        /// Carbody pitch inertia, kg m^2 (paper Table 3).
        carbody_pitch_inertia: f64 [1e3, 1e9, "kg.m2"] = 1.2e6,
        /// Carbody centre of gravity above the top of rail, m (paper Table 3).
        carbody_cog_height: f64 [0.0, 10.0, "m"] = 1.2,
        /// Mass of one bogie frame, kg (paper Table 3).
        bogie_mass: f64 [100.0, 1e5, "kg"] = 2500.0,
        /// Pitch inertia of one bogie frame, kg m^2 (paper Table 3).
        bogie_pitch_inertia: f64 [10.0, 1e6, "kg.m2"] = 950.0,
        /// Bogie centre of gravity above the top of rail, m (paper Table 3).
        bogie_cog_height: f64 [0.0, 10.0, "m"] = 0.62,
        /// Mass of one wheelset, kg (paper Table 3).
        wheelset_mass: f64 [50.0, 1e4, "kg"] = 850.0,
        /// Wheelset spin inertia about its axle, kg m^2 (paper Table 3, Eq (7)).
        wheelset_spin_inertia: f64 [1.0, 1e4, "kg.m2"] = 280.0,
        /// Wheel rolling radius r, m (paper text: diameter 0.86 m; Eqs (7), (12)).
        wheel_radius: f64 [0.05, 2.0, "m"] = 0.43,
        /// Distance between the bogie centres, m (paper Table 3: +-7 m).
        bogie_base: f64 [0.5, 100.0, "m"] = 14.0,
        /// Distance between the wheelsets of a bogie, m (paper Table 3: +-1.25 m).
        wheel_base: f64 [0.1, 20.0, "m"] = 2.5,
    }
);

section!(
    /// `[suspension]`: per element values and counts of parallel elements (2-D model).
    SuspensionParams "suspension" {
        /// Secondary (air spring) vertical stiffness per spring, N/m (paper Table 3).
        secondary_vertical_stiffness: f64 [1e3, 1e9, "N/m"] = 700e3,
        /// Secondary vertical springs acting in parallel per bogie.
        secondary_vertical_count: u32 [1.0, 16.0, ""] = 2,
        /// Secondary vertical damping per side, N s/m.
        secondary_vertical_damping: f64 [0.0, 1e7, "N.s/m"] = 30e3,
        /// Secondary longitudinal stiffness per spring, N/m (paper Table 3).
        secondary_longitudinal_stiffness: f64 [1e3, 1e9, "N/m"] = 200e3,
        /// Secondary longitudinal springs acting in parallel per bogie.
        secondary_longitudinal_count: u32 [1.0, 16.0, ""] = 2,
        /// Traction link stiffness, one per bogie, N/m (paper Table 3).
        traction_link_stiffness: f64 [0.0, 1e9, "N/m"] = 13000e3,
        /// Secondary longitudinal damping per bogie, N s/m.
        secondary_longitudinal_damping: f64 [0.0, 1e8, "N.s/m"] = 40e3,
        /// Height above rail at which the secondary longitudinal forces act, m.
        secondary_longitudinal_height: f64 [0.0, 10.0, "m"] = 0.75,
        /// Primary vertical stiffness per axle box spring, N/m (paper Table 3).
        primary_vertical_stiffness: f64 [1e3, 1e9, "N/m"] = 2000e3,
        /// Primary vertical springs acting in parallel per wheelset.
        primary_vertical_count: u32 [1.0, 16.0, ""] = 2,
        /// Primary vertical damping per axle box, N s/m.
        primary_vertical_damping: f64 [0.0, 1e7, "N.s/m"] = 15e3,
        /// Primary longitudinal stiffness per axle box guide, N/m (paper Table 3).
        primary_longitudinal_stiffness: f64 [1e3, 1e9, "N/m"] = 18000e3,
        /// Primary longitudinal guides acting in parallel per wheelset.
        primary_longitudinal_count: u32 [1.0, 16.0, ""] = 2,
        /// Primary longitudinal damping per axle box, N s/m.
        primary_longitudinal_damping: f64 [0.0, 1e8, "N.s/m"] = 5e3,
        /// Height above rail at which the axle-box guidance acts, m.
        primary_longitudinal_height: f64 [0.0, 10.0, "m"] = 0.43,
    }
);

section!(
    /// One Polach parameter set (paper Eqs 9-12, Table 2): here `[contact.dry]`, Polach's
    /// dry-rail values.
    AdhesionSet "contact.dry" {
        /// k_A, reduction of the initial slope of the adhesion curve in the adhesion area
        /// (paper Eq (9)).
        k_a: f64 [1e-3, 100.0, ""] = 1.00,
        /// k_S, reduction factor in the slip area (paper Eq (9)).
        k_s: f64 [1e-3, 100.0, ""] = 0.40,
        /// mu_0, maximum friction coefficient at zero slip velocity (paper Eq (11)).
        mu_0: f64 [1e-3, 2.0, ""] = 0.55,
        /// A = mu_inf / mu_0, friction at infinite over zero slip velocity (paper Eq (11)).
        a_ratio: f64 [0.0, 1.0, ""] = 0.40,
        /// B, exponential friction decrease with slip velocity, s/m (paper Eq (11)).
        b_exp: f64 [0.0, 100.0, "s/m"] = 0.60,
    }
);

impl AdhesionSet {
    /// Polach's dry-rail values of the reference file (`[contact.dry]`).
    pub const DRY: AdhesionSet = AdhesionSet::DEFAULT;
}

/// `[contact.dry]` inside `[contact]`: its keys name themselves (`contact.dry.k_a`).
impl Unranged for AdhesionSet {
    fn visit_as<V: KeyVisitor>(&mut self, _: &KeyInfo, visitor: &mut V) {
        self.visit_keys(visitor);
    }
}

section!(
    /// `[contact]`: the wet set (paper Table 2), contact geometry, and `[contact.dry]`.
    ContactParams "contact" {
        /// Wet-rail k_A (paper Table 2, Eq (9)).
        k_a: f64 [1e-3, 100.0, ""] = 0.30,
        /// Wet-rail k_S (paper Table 2, Eq (9)).
        k_s: f64 [1e-3, 100.0, ""] = 0.10,
        /// Wet-rail mu_0 (paper Table 2, Eq (11)).
        mu_0: f64 [1e-3, 2.0, ""] = 0.21,
        /// Wet-rail A = mu_inf / mu_0 (paper Table 2, Eq (11)).
        a_ratio: f64 [0.0, 1.0, ""] = 0.40,
        /// Wet-rail B, s/m (paper Table 2, Eq (11)).
        b_exp: f64 [0.0, 100.0, "s/m"] = 0.20,
        /// Contact ellipse half-axis a (longitudinal), m (paper Eq (10)).
        semi_axis_a: f64 [1e-5, 0.1, "m"] = 6.0e-3,
        /// Contact ellipse half-axis b (lateral), m (paper Eq (10)).
        semi_axis_b: f64 [1e-5, 0.1, "m"] = 4.5e-3,
        /// C, tangential contact stiffness per unit area, N/m^3 (paper Eq (10)).
        shear_stiffness_c: f64 [1e9, 1e17, "N/m3"] = 4.3e13,
        /// Speed floor of the creepage s = (v - r w) / max(|v|, floor), m/s (paper Eq (12)).
        creep_speed_floor: f64 [1e-3, 10.0, "m/s"] = 0.1,
        /// `[contact.dry]`: the dry-rail set.
        dry: AdhesionSet = AdhesionSet::DRY,
    }
);

impl ContactParams {
    /// The Polach set for a rail condition.
    pub fn set(&self, rail: Rail) -> AdhesionSet {
        match rail {
            Rail::Wet => AdhesionSet {
                k_a: self.k_a,
                k_s: self.k_s,
                mu_0: self.mu_0,
                a_ratio: self.a_ratio,
                b_exp: self.b_exp,
            },
            Rail::Dry => self.dry,
        }
    }
    /// Mutable access to the set of a rail condition's five values, in the order
    /// `k_a, k_s, mu_0, a_ratio, b_exp` (used by fits).
    pub fn set_mut(&mut self, rail: Rail) -> [&mut f64; 5] {
        match rail {
            Rail::Wet => [
                &mut self.k_a,
                &mut self.k_s,
                &mut self.mu_0,
                &mut self.a_ratio,
                &mut self.b_exp,
            ],
            Rail::Dry => {
                let d = &mut self.dry;
                [
                    &mut d.k_a,
                    &mut d.k_s,
                    &mut d.mu_0,
                    &mut d.a_ratio,
                    &mut d.b_exp,
                ]
            }
        }
    }
}

section!(
    /// `[brake]`: paper Eq (1), T_b = mu_d (A_c P_c - K_r) r_c l_p N_d.
    BrakeParams "brake" {
        /// A_c, brake cylinder piston area, m^2 (paper Eq (1)).
        piston_area: f64 [1e-5, 1.0, "m2"] = 0.0227,
        /// K_r, retaining spring force of the cylinder, N (paper Eq (1)).
        retaining_spring_force: f64 [0.0, 1e5, "N"] = 1000.0,
        /// r_c, lever (rigging) ratio from piston to pad (paper Eq (1)).
        lever_ratio: f64 [0.01, 100.0, ""] = 2.5,
        /// l_p, effective friction radius of the disc, m (paper Eq (1); v_d = omega l_p).
        friction_radius: f64 [0.01, 2.0, "m"] = 0.275,
        /// N_d, friction faces per wheelset (paper Eq (1)).
        friction_faces: u32 [1.0, 16.0, ""] = 4,
        /// Highest cylinder pressure the brake unit can reach, Pa.
        supply_pressure: f64 [1e3, 2e6, "Pa"] = 500e3,
        /// Extension (not in the reference file): first-order lag of the pad force behind
        /// the cylinder pressure, s (0 = none). The diagnosis effect `actuator-lag`, `tau_s`.
        #[cfg_attr(feature = "serde", serde(default))]
        actuator_lag_s: f64 [0.0, 10.0, "s"] = 0.0,
    }
);

section!(
    /// `[friction]`: paper Eq (2) and Table 1.
    FrictionParams "friction" {
        /// Which disc-pad friction law applies.
        model: FrictionModel = FrictionModel::Variable,
        /// mu_d0, nominal disc-pad friction coefficient (paper Table 1, Eq (2)).
        mu_d0: f64 [1e-3, 2.0, ""] = 0.38,
        /// n_v, amplitude of the speed term (paper Table 1, Eq (2)).
        n_v: f64 [0.0, 10.0, ""] = 0.184,
        /// m_v, decay of the speed term, s/m (paper Table 1, Eq (2)).
        m_v: f64 [0.0, 10.0, "s/m"] = 0.1,
        /// n_T, amplitude of the temperature term (paper Table 1, Eq (2)).
        n_t: f64 [0.0, 10.0, ""] = 0.105,
        /// m_T, decay of the temperature term, 1/degC (paper Table 1, Eq (2)).
        m_t: f64 [0.0, 10.0, "1/K"] = 0.014,
        /// c, the correction constant applied as a factor to Eq (2) (paper text).
        correction_c: f64 [0.01, 10.0, ""] = 0.98,
        /// Extension (not in the reference file): relative change of mu_d per 10 kN of pad
        /// clamp force, mu_d *= 1 + k_p f_clamp / 10 kN (0 = none). Effect `friction-pressure`.
        #[cfg_attr(feature = "serde", serde(default))]
        k_p: f64 [-0.9, 10.0, ""] = 0.0,
    }
);

section!(
    /// `[thermal]`: paper Eqs (3)-(6), lumped disc energy balance per wheelset.
    ThermalParams "thermal" {
        /// sigma_d, share of the braking power that heats the disc (paper Eq (4)).
        heat_partition: f64 [0.0, 1.0, ""] = 0.9,
        /// m_disc, effective heated disc mass per wheelset, kg (paper Eq (6)).
        disc_mass: f64 [1.0, 1e4, "kg"] = 80.0,
        /// c_p, specific heat of the disc, J/(kg K) (paper Eq (6)).
        specific_heat: f64 [10.0, 1e5, "J/(kg.K)"] = 460.0,
        /// alpha, conduction to the axle, W/K (paper Eq (5)).
        alpha: f64 [0.0, 1e6, "W/K"] = 50.0,
        /// beta, convection, W/(K (m/s)^0.8), with the wheel speed v_w = r omega (paper Eq (5)).
        beta: f64 [0.0, 1e6, ""] = 10.0,
        /// Initial disc temperature rise T_d above ambient, degC (paper Eq (6)).
        ambient_rise: f64 [-100.0, 1000.0, "degC"] = 0.0,
    }
);

section!(
    /// `[track]`.
    TrackParams "track" {
        /// Gradient, per mille (positive = uphill).
        gradient_permille: f64 [-100.0, 100.0, "1/1000"] = 0.0,
    }
);

section!(
    /// `[resistance]`: Davis running resistance F = a + b v + c v^2 (the paper has none).
    ResistanceParams "resistance" {
        /// Davis constant term a, N.
        davis_a_n: f64 [0.0, 1e6, "N"] = 0.0,
        /// Davis linear term b, N per m/s.
        davis_b_n_per_mps: f64 [0.0, 1e6, "N.s/m"] = 0.0,
        /// Davis quadratic term c, N per (m/s)^2.
        davis_c_n_per_mps2: f64 [0.0, 1e5, "N.s2/m2"] = 0.0,
    }
);

section!(
    /// The plant's sections of the parameter file (the vehicle, its contact, brakes and
    /// discs, the track). The brake unit and the scenario own their own sections
    /// (`hils_brake_unit::BrakeUnitParams`, `hils_sil::ScenarioParams`); the whole file is
    /// `hils_sil::ParamFile`.
    Params {
        /// `[vehicle]`.
        vehicle: VehicleParams = VehicleParams::DEFAULT,
        /// `[suspension]`.
        suspension: SuspensionParams = SuspensionParams::DEFAULT,
        /// `[contact]` with `[contact.dry]`.
        contact: ContactParams = ContactParams::DEFAULT,
        /// `[brake]`.
        brake: BrakeParams = BrakeParams::DEFAULT,
        /// `[friction]`.
        friction: FrictionParams = FrictionParams::DEFAULT,
        /// `[thermal]`.
        thermal: ThermalParams = ThermalParams::DEFAULT,
        /// `[track]`.
        track: TrackParams = TrackParams::DEFAULT,
        /// `[resistance]`.
        resistance: ResistanceParams = ResistanceParams::DEFAULT,
    }
);

/// The plant's fixed step on the real-time board and in the paper's scenario, s (10 kHz,
/// paper text: 0.1 ms sampling of the vehicle model).
pub const STEP_S: f64 = 1.0e-4;

/// Number of wheelsets of the vehicle (Fig 3: two bogies of two).
pub const WHEELSETS: usize = 4;

/// A parameter outside its physical range: names the key, the value and the range.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ParamError {
    /// `section.key` as in the parameter file.
    pub key: &'static str,
    /// The value found, in the key's unit.
    pub value: f64,
    /// Lowest valid value.
    pub min: f64,
    /// Highest valid value.
    pub max: f64,
}

impl core::fmt::Display for ParamError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "parameter `{}` = {} is outside its valid range [{}, {}]",
            self.key, self.value, self.min, self.max
        )
    }
}

/// Checks that `value` lies in `[min, max]` (NaN fails); the error names `key`
/// (`section.key` as in the parameter file). Every section's validation uses it; one copy,
/// not inlined at each key (two soft-float compares a key on the board: its flash budget).
#[inline(never)]
pub fn check(key: &'static str, value: f64, min: f64, max: f64) -> Result<(), ParamError> {
    // `!(a && b)` also rejects NaN.
    if value >= min && value <= max {
        Ok(())
    } else {
        Err(ParamError {
            key,
            value,
            min,
            max,
        })
    }
}

#[cfg(feature = "serde")]
impl Params {
    /// The plant's section names in a parameter file, in file order.
    pub const SECTIONS: [&'static str; 8] = [
        "vehicle",
        "suspension",
        "contact",
        "brake",
        "friction",
        "thermal",
        "track",
        "resistance",
    ];

    /// Reads the plant section `SECTIONS[index]` from the next value of a parameter file's
    /// map (the whole file's deserializer, `hils_sil::ParamFile`, hands each plant section
    /// here). An index outside `SECTIONS` reads nothing.
    pub fn read_section<'de, A: serde::de::MapAccess<'de>>(
        &mut self,
        index: usize,
        map: &mut A,
    ) -> Result<(), A::Error> {
        match index {
            0 => self.vehicle = map.next_value()?,
            1 => self.suspension = map.next_value()?,
            2 => self.contact = map.next_value()?,
            3 => self.brake = map.next_value()?,
            4 => self.friction = map.next_value()?,
            5 => self.thermal = map.next_value()?,
            6 => self.track = map.next_value()?,
            7 => self.resistance = map.next_value()?,
            _ => {}
        }
        Ok(())
    }
}

impl Keys for Params {
    /// The plant's sections' keys, in file order.
    fn visit_keys<V: KeyVisitor>(&mut self, visitor: &mut V) {
        self.vehicle.visit_keys(visitor);
        self.suspension.visit_keys(visitor);
        self.contact.visit_keys(visitor);
        self.brake.visit_keys(visitor);
        self.friction.visit_keys(visitor);
        self.thermal.visit_keys(visitor);
        self.track.visit_keys(visitor);
        self.resistance.visit_keys(visitor);
    }
}

impl Params {
    /// Total mass of the car (carbody, 2 bogies, 4 wheelsets), kg.
    pub fn total_mass(&self) -> f64 {
        let v = &self.vehicle;
        v.carbody_mass + 2.0 * v.bogie_mass + 4.0 * v.wheelset_mass
    }

    /// Translational mass plus the wheelsets' spin inertia reduced to the rail, kg.
    pub fn effective_mass(&self) -> f64 {
        let v = &self.vehicle;
        self.total_mass() + 4.0 * v.wheelset_spin_inertia / (v.wheel_radius * v.wheel_radius)
    }

    /// Checks every value against its physical range (NaN and inf are out of range).
    /// The plant refuses parameters that fail, so a step never meets them.
    pub fn validate(&self) -> Result<(), ParamError> {
        self.vehicle.check_ranges()?;
        self.suspension.check_ranges()?;
        self.contact.check_ranges()?;
        self.contact.dry.check_ranges()?;
        self.brake.check_ranges()?;
        self.friction.check_ranges()?;
        self.thermal.check_ranges()?;
        self.track.check_ranges()?;
        self.resistance.check_ranges()?;
        let v = &self.vehicle;
        // Geometry: the wheelsets of a bogie must fit between the bogie centres.
        check("vehicle.wheel_base", v.wheel_base, 0.1, v.bogie_base)?;
        Ok(())
    }
}
