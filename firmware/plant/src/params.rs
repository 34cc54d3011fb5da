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
    #[default]
    Wet,
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

macro_rules! section {
    ($(#[$m:meta])* $name:ident { $($(#[$fm:meta])* $field:ident : $ty:ty = $val:expr),* $(,)? }) => {
        $(#[$m])*
        #[derive(Clone, Copy, Debug, PartialEq)]
        #[cfg_attr(feature = "serde", derive(Deserialize), serde(deny_unknown_fields))]
        pub struct $name { $($(#[$fm])* pub $field: $ty),* }
        impl Default for $name {
            fn default() -> Self { Self { $($field: $val),* } }
        }
    };
}

section!(
    /// `[vehicle]`: one car, 1 carbody, 2 bogies, 4 wheelsets (paper Table 3).
    VehicleParams {
        g: f64 = 9.81,
        carbody_mass: f64 = 35000.0,
        carbody_pitch_inertia: f64 = 1.2e6,
        carbody_cog_height: f64 = 1.2,
        bogie_mass: f64 = 2500.0,
        bogie_pitch_inertia: f64 = 950.0,
        bogie_cog_height: f64 = 0.62,
        wheelset_mass: f64 = 850.0,
        wheelset_spin_inertia: f64 = 280.0,
        wheel_radius: f64 = 0.43,
        bogie_base: f64 = 14.0,
        wheel_base: f64 = 2.5,
    }
);

section!(
    /// `[suspension]`: per element values and counts of parallel elements (2-D model).
    SuspensionParams {
        secondary_vertical_stiffness: f64 = 700e3,
        secondary_vertical_count: u32 = 2,
        secondary_vertical_damping: f64 = 30e3,
        secondary_longitudinal_stiffness: f64 = 200e3,
        secondary_longitudinal_count: u32 = 2,
        traction_link_stiffness: f64 = 13000e3,
        secondary_longitudinal_damping: f64 = 40e3,
        secondary_longitudinal_height: f64 = 0.75,
        primary_vertical_stiffness: f64 = 2000e3,
        primary_vertical_count: u32 = 2,
        primary_vertical_damping: f64 = 15e3,
        primary_longitudinal_stiffness: f64 = 18000e3,
        primary_longitudinal_count: u32 = 2,
        primary_longitudinal_damping: f64 = 5e3,
        primary_longitudinal_height: f64 = 0.43,
    }
);

section!(
    /// One Polach parameter set (paper Eqs 9-12, Table 2).
    AdhesionSet {
        k_a: f64 = 0.30,
        k_s: f64 = 0.10,
        mu_0: f64 = 0.21,
        a_ratio: f64 = 0.40,
        b_exp: f64 = 0.20,
    }
);

impl AdhesionSet {
    /// Polach's dry-rail values of the reference file (`[contact.dry]`).
    pub const DRY: AdhesionSet = AdhesionSet {
        k_a: 1.00,
        k_s: 0.40,
        mu_0: 0.55,
        a_ratio: 0.40,
        b_exp: 0.60,
    };
}

section!(
    /// `[contact]`: the wet set (paper Table 2), contact geometry, and `[contact.dry]`.
    ContactParams {
        k_a: f64 = 0.30,
        k_s: f64 = 0.10,
        mu_0: f64 = 0.21,
        a_ratio: f64 = 0.40,
        b_exp: f64 = 0.20,
        semi_axis_a: f64 = 6.0e-3,
        semi_axis_b: f64 = 4.5e-3,
        shear_stiffness_c: f64 = 4.3e13,
        creep_speed_floor: f64 = 0.1,
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
    BrakeParams {
        piston_area: f64 = 0.0227,
        retaining_spring_force: f64 = 1000.0,
        lever_ratio: f64 = 2.5,
        friction_radius: f64 = 0.275,
        friction_faces: u32 = 4,
        supply_pressure: f64 = 500e3,
        /// Extension (not in the reference file): first-order lag of the pad force behind
        /// the cylinder pressure, s (0 = none). The diagnosis effect `actuator-lag`, `tau_s`.
        #[cfg_attr(feature = "serde", serde(default))]
        actuator_lag_s: f64 = 0.0,
    }
);

section!(
    /// `[friction]`: paper Eq (2) and Table 1.
    FrictionParams {
        model: FrictionModel = FrictionModel::Variable,
        mu_d0: f64 = 0.38,
        n_v: f64 = 0.184,
        m_v: f64 = 0.1,
        n_t: f64 = 0.105,
        m_t: f64 = 0.014,
        correction_c: f64 = 0.98,
        /// Extension (not in the reference file): relative change of mu_d per 10 kN of pad
        /// clamp force, mu_d *= 1 + k_p f_clamp / 10 kN (0 = none). Effect `friction-pressure`.
        #[cfg_attr(feature = "serde", serde(default))]
        k_p: f64 = 0.0,
    }
);

section!(
    /// `[thermal]`: paper Eqs (3)-(6), lumped disc energy balance per wheelset.
    ThermalParams {
        heat_partition: f64 = 0.9,
        disc_mass: f64 = 80.0,
        specific_heat: f64 = 460.0,
        alpha: f64 = 50.0,
        beta: f64 = 10.0,
        ambient_rise: f64 = 0.0,
    }
);

section!(
    /// `[track]`.
    TrackParams {
        gradient_permille: f64 = 0.0,
    }
);

section!(
    /// `[resistance]`: Davis running resistance F = a + b v + c v^2 (the paper has none).
    ResistanceParams {
        davis_a_n: f64 = 0.0,
        davis_b_n_per_mps: f64 = 0.0,
        davis_c_n_per_mps2: f64 = 0.0,
    }
);

section!(
    /// The plant's sections of the parameter file (the vehicle, its contact, brakes and
    /// discs, the track). The brake unit and the scenario own their own sections
    /// (`hils_brake_unit::BrakeUnitParams`, `hils_sil::ScenarioParams`); the whole file is
    /// `hils_sil::ParamFile`.
    Params {
        vehicle: VehicleParams = VehicleParams::default(),
        suspension: SuspensionParams = SuspensionParams::default(),
        contact: ContactParams = ContactParams::default(),
        brake: BrakeParams = BrakeParams::default(),
        friction: FrictionParams = FrictionParams::default(),
        thermal: ThermalParams = ThermalParams::default(),
        track: TrackParams = TrackParams::default(),
        resistance: ResistanceParams = ResistanceParams::default(),
    }
);

/// The plant's fixed step on the real-time board and in the paper's scenario, s (10 kHz,
/// paper text: 0.1 ms sampling of the vehicle model).
pub const STEP_S: f64 = 1.0e-4;

/// A parameter outside its physical range: names the key, the value and the range.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ParamError {
    /// `section.key` as in the parameter file.
    pub key: &'static str,
    pub value: f64,
    pub min: f64,
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
/// (`section.key` as in the parameter file). Every section's validation uses it.
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

fn check_count(key: &'static str, value: u32) -> Result<(), ParamError> {
    check(key, value as f64, 1.0, 16.0)
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
        let v = &self.vehicle;
        check("vehicle.g", v.g, 0.1, 100.0)?;
        check("vehicle.carbody_mass", v.carbody_mass, 1e3, 1e6)?;
        check(
            "vehicle.carbody_pitch_inertia",
            v.carbody_pitch_inertia,
            1e3,
            1e9,
        )?;
        check(
            "vehicle.carbody_cog_height",
            v.carbody_cog_height,
            0.0,
            10.0,
        )?;
        check("vehicle.bogie_mass", v.bogie_mass, 100.0, 1e5)?;
        check(
            "vehicle.bogie_pitch_inertia",
            v.bogie_pitch_inertia,
            10.0,
            1e6,
        )?;
        check("vehicle.bogie_cog_height", v.bogie_cog_height, 0.0, 10.0)?;
        check("vehicle.wheelset_mass", v.wheelset_mass, 50.0, 1e4)?;
        check(
            "vehicle.wheelset_spin_inertia",
            v.wheelset_spin_inertia,
            1.0,
            1e4,
        )?;
        check("vehicle.wheel_radius", v.wheel_radius, 0.05, 2.0)?;
        check("vehicle.bogie_base", v.bogie_base, 0.5, 100.0)?;
        check("vehicle.wheel_base", v.wheel_base, 0.1, 20.0)?;

        let s = &self.suspension;
        check(
            "suspension.secondary_vertical_stiffness",
            s.secondary_vertical_stiffness,
            1e3,
            1e9,
        )?;
        check_count(
            "suspension.secondary_vertical_count",
            s.secondary_vertical_count,
        )?;
        check(
            "suspension.secondary_vertical_damping",
            s.secondary_vertical_damping,
            0.0,
            1e7,
        )?;
        check(
            "suspension.secondary_longitudinal_stiffness",
            s.secondary_longitudinal_stiffness,
            1e3,
            1e9,
        )?;
        check_count(
            "suspension.secondary_longitudinal_count",
            s.secondary_longitudinal_count,
        )?;
        check(
            "suspension.traction_link_stiffness",
            s.traction_link_stiffness,
            0.0,
            1e9,
        )?;
        check(
            "suspension.secondary_longitudinal_damping",
            s.secondary_longitudinal_damping,
            0.0,
            1e8,
        )?;
        check(
            "suspension.secondary_longitudinal_height",
            s.secondary_longitudinal_height,
            0.0,
            10.0,
        )?;
        check(
            "suspension.primary_vertical_stiffness",
            s.primary_vertical_stiffness,
            1e3,
            1e9,
        )?;
        check_count(
            "suspension.primary_vertical_count",
            s.primary_vertical_count,
        )?;
        check(
            "suspension.primary_vertical_damping",
            s.primary_vertical_damping,
            0.0,
            1e7,
        )?;
        check(
            "suspension.primary_longitudinal_stiffness",
            s.primary_longitudinal_stiffness,
            1e3,
            1e9,
        )?;
        check_count(
            "suspension.primary_longitudinal_count",
            s.primary_longitudinal_count,
        )?;
        check(
            "suspension.primary_longitudinal_damping",
            s.primary_longitudinal_damping,
            0.0,
            1e8,
        )?;
        check(
            "suspension.primary_longitudinal_height",
            s.primary_longitudinal_height,
            0.0,
            10.0,
        )?;

        let c = &self.contact;
        for (rail, name) in [(Rail::Wet, "contact"), (Rail::Dry, "contact.dry")] {
            let set = c.set(rail);
            let key = |k: &'static str, w: &'static str| if name == "contact" { k } else { w };
            check(key("contact.k_a", "contact.dry.k_a"), set.k_a, 1e-3, 100.0)?;
            check(key("contact.k_s", "contact.dry.k_s"), set.k_s, 1e-3, 100.0)?;
            check(key("contact.mu_0", "contact.dry.mu_0"), set.mu_0, 1e-3, 2.0)?;
            check(
                key("contact.a_ratio", "contact.dry.a_ratio"),
                set.a_ratio,
                0.0,
                1.0,
            )?;
            check(
                key("contact.b_exp", "contact.dry.b_exp"),
                set.b_exp,
                0.0,
                100.0,
            )?;
        }
        check("contact.semi_axis_a", c.semi_axis_a, 1e-5, 0.1)?;
        check("contact.semi_axis_b", c.semi_axis_b, 1e-5, 0.1)?;
        check("contact.shear_stiffness_c", c.shear_stiffness_c, 1e9, 1e17)?;
        check("contact.creep_speed_floor", c.creep_speed_floor, 1e-3, 10.0)?;

        let b = &self.brake;
        check("brake.piston_area", b.piston_area, 1e-5, 1.0)?;
        check(
            "brake.retaining_spring_force",
            b.retaining_spring_force,
            0.0,
            1e5,
        )?;
        check("brake.lever_ratio", b.lever_ratio, 0.01, 100.0)?;
        check("brake.friction_radius", b.friction_radius, 0.01, 2.0)?;
        check("brake.friction_faces", b.friction_faces as f64, 1.0, 16.0)?;
        check("brake.supply_pressure", b.supply_pressure, 1e3, 2e6)?;
        check("brake.actuator_lag_s", b.actuator_lag_s, 0.0, 10.0)?;

        let f = &self.friction;
        check("friction.mu_d0", f.mu_d0, 1e-3, 2.0)?;
        check("friction.n_v", f.n_v, 0.0, 10.0)?;
        check("friction.m_v", f.m_v, 0.0, 10.0)?;
        check("friction.n_t", f.n_t, 0.0, 10.0)?;
        check("friction.m_t", f.m_t, 0.0, 10.0)?;
        check("friction.correction_c", f.correction_c, 0.01, 10.0)?;
        check("friction.k_p", f.k_p, -0.9, 10.0)?;

        let t = &self.thermal;
        check("thermal.heat_partition", t.heat_partition, 0.0, 1.0)?;
        check("thermal.disc_mass", t.disc_mass, 1.0, 1e4)?;
        check("thermal.specific_heat", t.specific_heat, 10.0, 1e5)?;
        check("thermal.alpha", t.alpha, 0.0, 1e6)?;
        check("thermal.beta", t.beta, 0.0, 1e6)?;
        check("thermal.ambient_rise", t.ambient_rise, -100.0, 1000.0)?;

        check(
            "track.gradient_permille",
            self.track.gradient_permille,
            -100.0,
            100.0,
        )?;

        let r = &self.resistance;
        check("resistance.davis_a_n", r.davis_a_n, 0.0, 1e6)?;
        check(
            "resistance.davis_b_n_per_mps",
            r.davis_b_n_per_mps,
            0.0,
            1e6,
        )?;
        check(
            "resistance.davis_c_n_per_mps2",
            r.davis_c_n_per_mps2,
            0.0,
            1e5,
        )?;

        // Geometry: the wheelsets of a bogie must fit between the bogie centres.
        check("vehicle.wheel_base", v.wheel_base, 0.1, v.bogie_base)?;
        Ok(())
    }
}
