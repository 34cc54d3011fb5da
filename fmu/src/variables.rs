//! The FMU's variables, built from the project's own tables: the parameter file's keys
//! ([`hils_plant::keys`]: name, doc, unit, range) and the run-log schema
//! ([`hils_sil::record::run_log`]: the channel names and units of `spec/measured-data.md`).
//! The model description ([`crate::description`]) and the C API ([`crate::abi`]) both read
//! [`VARIABLES`]; there is no second list.

use std::sync::LazyLock;

use hils_plant::WHEELSETS;
use hils_plant::keys::{KeyInfo, KeyValue, KeyVisitor, Keys};
use hils_sil::ParamFile;
use hils_sil::record::Channel;
use hils_sil::record::run_log::*;

use crate::units;

/// FMI 3.0 causality.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Causality {
    /// `time`.
    Independent,
    /// `brake_input`: fixed before initialisation, selects the inputs.
    StructuralParameter,
    /// A key of the parameter file, or `params_file`.
    Parameter,
    /// A brake input.
    Input,
    /// A result.
    Output,
}

impl Causality {
    /// The attribute value.
    pub fn name(self) -> &'static str {
        match self {
            Causality::Independent => "independent",
            Causality::StructuralParameter => "structuralParameter",
            Causality::Parameter => "parameter",
            Causality::Input => "input",
            Causality::Output => "output",
        }
    }
}

/// An FMI enumeration type: its name and items (values 0, 1, ...).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct EnumType {
    /// Type name in `TypeDefinitions`.
    pub name: &'static str,
    /// Item names and descriptions, in value order.
    pub items: &'static [(&'static str, &'static str)],
}

/// The FMI type of a variable.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Kind {
    /// `Float64` (every number of the model: the plant runs in f32, every f32 is an f64).
    Float64,
    /// `UInt32` (counts, the plant's flags).
    UInt32,
    /// `Boolean`.
    Boolean,
    /// `String`.
    String,
    /// `Enumeration` (get and set as Int64).
    Enumeration(EnumType),
}

/// What a variable stands for: where [`crate::instance`] reads or writes its value.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Role {
    /// The independent variable, s.
    Time,
    /// The structural parameter `brake_input`.
    BrakeInput,
    /// `params_file`: a parameter file loaded when set.
    ParamsFile,
    /// Key `index` of the parameter file, in [`Keys`] order.
    Key(usize),
    /// Cylinder pressure input of wheelset `j` (0-based), Pa.
    CylinderPressure(usize),
    /// Clamp force input of wheelset `j`, N.
    ClampForce(usize),
    /// The brake command of the closed loop.
    Command,
    /// The service brake deceleration of the closed loop, m/s^2.
    ServiceDeceleration,
    /// Run-record channel of wheelset `j` (ignored for a scalar channel).
    Record(Channel, usize),
    /// The plant's flags over the last communication step.
    Flags,
}

/// One variable of the model description.
#[derive(Clone, Debug, PartialEq)]
pub struct Variable {
    /// Name (structured naming: `vehicle.carbody_mass`, `omega1_radps`).
    pub name: String,
    /// Value reference.
    pub vr: u32,
    /// Causality.
    pub causality: Causality,
    /// FMI type.
    pub kind: Kind,
    /// Meaning, as one line.
    pub description: String,
    /// Unit symbol ([`units::UNITS`]), empty when none.
    pub unit: &'static str,
    /// Valid range (a parameter file key's), else none.
    pub range: Option<(f64, f64)>,
    /// What the value stands for.
    pub role: Role,
}

impl Variable {
    /// The FMI variability: `fixed` for parameters, `discrete` for non-float inputs and
    /// outputs, `continuous` for float ones and time.
    pub fn variability(&self) -> &'static str {
        match (self.causality, self.kind) {
            (Causality::Parameter | Causality::StructuralParameter, _) => "fixed",
            (_, Kind::Float64) => "continuous",
            _ => "discrete",
        }
    }
}

/// How the brakes are driven: the values of `brake_input`.
pub const BRAKE_INPUT: EnumType = EnumType {
    name: "BrakeInput",
    items: &[
        (
            "cylinder_pressure",
            "p_cyl1_pa..p_cyl4_pa drive the brakes through Eq (1)",
        ),
        (
            "clamp_force",
            "f_clamp1_n..f_clamp4_n (pad force per face) drive the brakes",
        ),
        (
            "brake_unit",
            "the closed loop: the simulated brake unit (ECU, cylinders, WSP) answers cmd",
        ),
    ],
};

/// The brake command of the run log's `cmd` column (`hils_sil::Cmd`, values as its codes).
pub const CMD: EnumType = EnumType {
    name: "Cmd",
    items: &[
        ("REL", "brakes released"),
        ("EB", "emergency brake (open-loop EB pressure)"),
        ("SB", "service brake at service_deceleration_mps2"),
    ],
};

/// A result: its run-record channel, its name stem when it differs from the channel's
/// (an input of the same channel has the run log's name), its FMI type and its meaning.
struct Output {
    channel: Channel,
    stem: Option<&'static str>,
    kind: Kind,
    doc: &'static str,
}

const fn output(channel: Channel, doc: &'static str) -> Output {
    Output {
        channel,
        stem: None,
        kind: Kind::Float64,
        doc,
    }
}

/// The results, in model-description order (a per-wheelset channel gives four).
const OUTPUTS: [Output; 14] = [
    output(V_REF, "True vehicle (carbody) speed."),
    output(X, "Distance run by the carbody."),
    output(A_X, "Carbody longitudinal acceleration."),
    output(
        OMEGA,
        "Wheelset angular speed, positive rolling forward (wheelset 1 leads).",
    ),
    output(Q, "Wheelset (axle) load: the rail normal force."),
    output(MU_D, "Disc-pad friction coefficient (Eq 2, or mu_d0)."),
    output(
        F_BRAKE,
        "Tangential friction force on the disc at the friction radius, summed over the faces (T_b / l_p, Eq 1).",
    ),
    output(T_DISC, "Disc temperature rise above ambient (Eqs 3-6)."),
    output(
        CREEPAGE,
        "Wheel-rail creepage (v - r omega) / max(|v|, floor) (Eq 12).",
    ),
    output(ADHESION, "Adhesion coefficient used, F / Q (Eq 13)."),
    Output {
        stem: Some("f_clamp_act"),
        ..output(
            F_CLAMP,
            "Pad normal force per friction face acting (the input after the plant's clamping, the actuator lag, and Eq 1 from a pressure).",
        )
    },
    Output {
        stem: Some("p_cyl_unit"),
        ..output(
            P_CYL,
            "Cylinder pressure the simulated brake unit sets (brake_input = brake_unit; 0 otherwise).",
        )
    },
    Output {
        kind: Kind::Boolean,
        ..output(
            WSP,
            "True while the wheelset's WSP valve vents (brake_input = brake_unit; false otherwise).",
        )
    },
    output(
        V_REF_EST,
        "The WSP's reference speed estimate (brake_input = brake_unit; 0 otherwise).",
    ),
];

/// Value references: blocks that stay put when keys are added to the parameter file.
const VR_INPUTS: u32 = 100;
const VR_OUTPUTS: u32 = 200;
const VR_KEYS: u32 = 1000;

/// Every variable, in model-description order (built once per process).
pub static VARIABLES: LazyLock<Vec<Variable>> = LazyLock::new(build);

/// The index in [`VARIABLES`] of each value reference (`u16::MAX`: none): one load per
/// lookup on the per-step path (`fmi3SetFloat64` of the inputs), where a binary search of
/// the table touched a cache line per probe.
static INDEX_OF_VR: LazyLock<Vec<u16>> = LazyLock::new(|| {
    let top = VARIABLES.iter().map(|v| v.vr).max().unwrap_or(0) as usize;
    let mut index = vec![u16::MAX; top + 1];
    for (i, v) in VARIABLES.iter().enumerate() {
        index[v.vr as usize] = u16::try_from(i).unwrap_or(u16::MAX);
    }
    index
});

/// The variable of value reference `vr`.
pub fn by_vr(vr: u32) -> Option<&'static Variable> {
    let i = *INDEX_OF_VR.get(usize::try_from(vr).ok()?)?;
    VARIABLES.get(usize::from(i))
}

/// The variable named `name`.
pub fn by_name(name: &str) -> Option<&'static Variable> {
    VARIABLES.iter().find(|v| v.name == name)
}

fn build() -> Vec<Variable> {
    let mut vars = vec![
        Variable {
            name: "time".into(),
            vr: 0,
            causality: Causality::Independent,
            kind: Kind::Float64,
            description: "Simulation time.".into(),
            unit: "s",
            range: None,
            role: Role::Time,
        },
        Variable {
            name: "brake_input".into(),
            vr: 1,
            causality: Causality::StructuralParameter,
            kind: Kind::Enumeration(BRAKE_INPUT),
            description: "What drives the brakes: the cylinder pressures (the default), the clamp forces, or the simulated brake unit (closed loop).".into(),
            unit: "",
            range: None,
            role: Role::BrakeInput,
        },
        Variable {
            name: "params_file".into(),
            vr: 2,
            causality: Causality::Parameter,
            kind: Kind::String,
            description: "A parameter file (TOML, as spec/reference-parameters.toml) loaded when set: every key takes the file's value (keys set later override it); empty: the FMU's resources/parameters.toml.".into(),
            unit: "",
            range: None,
            role: Role::ParamsFile,
        },
    ];
    inputs(&mut vars);
    outputs(&mut vars);
    keys(&mut vars);
    vars
}

fn inputs(vars: &mut Vec<Variable>) {
    let mut vr = VR_INPUTS;
    let mut push = |name: String, kind, description: String, unit, role| {
        vars.push(Variable {
            name,
            vr,
            causality: Causality::Input,
            kind,
            description,
            unit,
            range: None,
            role,
        });
        vr += 1;
    };
    for (channel, role, doc) in [
        (
            P_CYL,
            Role::CylinderPressure as fn(usize) -> Role,
            "Brake cylinder pressure (brake_input = cylinder_pressure).",
        ),
        (
            F_CLAMP,
            Role::ClampForce,
            "Pad normal force per friction face (brake_input = clamp_force).",
        ),
    ] {
        for j in 0..WHEELSETS {
            push(
                channel.name(j).to_string(),
                Kind::Float64,
                format!("Wheelset {}: {doc}", j + 1),
                unit_of(channel),
                role(j),
            );
        }
    }
    push(
        CMD_CHANNEL.name(0).to_string(),
        Kind::Enumeration(CMD),
        "Brake command of the simulated brake unit (brake_input = brake_unit).".into(),
        "",
        Role::Command,
    );
    push(
        "service_deceleration_mps2".into(),
        Kind::Float64,
        "Demanded deceleration of a service brake (cmd = SB; limited to the EB deceleration)."
            .into(),
        "m/s2",
        Role::ServiceDeceleration,
    );
}

/// The run log's `cmd` channel.
const CMD_CHANNEL: Channel = hils_sil::record::run_log::CMD;

fn outputs(vars: &mut Vec<Variable>) {
    let mut vr = VR_OUTPUTS;
    for o in &OUTPUTS {
        let channel = match o.stem {
            Some(stem) => Channel { stem, ..o.channel },
            None => o.channel,
        };
        for j in 0..o.channel.width() {
            let description = if o.channel.per_wheelset {
                format!("Wheelset {}: {}", j + 1, o.doc)
            } else {
                o.doc.to_string()
            };
            vars.push(Variable {
                name: channel.name(j).to_string(),
                vr,
                causality: Causality::Output,
                kind: o.kind,
                description,
                unit: unit_of(o.channel),
                range: None,
                role: Role::Record(o.channel, j),
            });
            vr += 1;
        }
    }
    vars.push(Variable {
        name: "plant_flags".into(),
        vr,
        causality: Causality::Output,
        kind: Kind::UInt32,
        description: "The plant's flags over the last communication step, or-ed (hils_plant::Flags: bits 0-3 brake input not finite, 4-7 out of range and clamped, 8 initial speed clamped, 9-12 wheelset unloaded, 13 numeric fault).".into(),
        unit: "",
        range: None,
        role: Role::Flags,
    });
}

/// The unit symbol of a channel (its run-log suffix).
fn unit_of(channel: Channel) -> &'static str {
    units::of_suffix(channel.unit).unwrap_or("")
}

/// The FMI kind of a key's value.
fn key_kind(info: &KeyInfo, value: &KeyValue<'_>) -> Kind {
    match value {
        KeyValue::Real(_) => Kind::Float64,
        KeyValue::Count(_) => Kind::UInt32,
        KeyValue::Flag(_) => Kind::Boolean,
        KeyValue::Note => Kind::String,
        KeyValue::Choice(c) => Kind::Enumeration(EnumType {
            name: info.name,
            items: choice_items(c.names()),
        }),
    }
}

/// Enumeration items of a choice's names (leaked once per process: the table is static).
fn choice_items(names: &'static [&'static str]) -> &'static [(&'static str, &'static str)] {
    Box::leak(
        names
            .iter()
            .map(|n| (*n, ""))
            .collect::<Vec<_>>()
            .into_boxed_slice(),
    )
}

fn keys(vars: &mut Vec<Variable>) {
    struct Collect<'a> {
        vars: &'a mut Vec<Variable>,
        index: usize,
    }
    impl KeyVisitor for Collect<'_> {
        fn key(&mut self, info: &KeyInfo, value: KeyValue<'_>) {
            let kind = key_kind(info, &value);
            let ranged = matches!(kind, Kind::Float64 | Kind::UInt32);
            self.vars.push(Variable {
                name: info.name.to_string(),
                vr: VR_KEYS + self.index as u32,
                causality: Causality::Parameter,
                kind,
                description: one_line(info.doc),
                unit: info.unit,
                range: ranged.then_some((info.min, info.max)),
                role: Role::Key(self.index),
            });
            self.index += 1;
        }
    }
    ParamFile::default().visit_keys(&mut Collect { vars, index: 0 });
}

/// A doc comment as one line.
fn one_line(doc: &str) -> String {
    doc.split_whitespace().collect::<Vec<_>>().join(" ")
}
