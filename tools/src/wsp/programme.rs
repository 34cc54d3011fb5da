//! The WSP test programme (TOML): criteria, tracks, vehicle variants and runs.
//!
//! ```toml
//! [criteria]                  # pass criteria and bench constants (all optional)
//! max_distance_ratio = 1.35
//! [tracks.low]                # a track: base surface, zones, optional [tracks.X.sets]
//! base = "low"
//! [[tracks.change.zone]]
//! start_m = 150.0
//! end_m = 250.0
//! surface = "dry"
//! [vehicles.tare]             # a vehicle variant: plant values that differ
//! carbody_mass = 26000.0
//! [[run]]
//! name = "low-160"
//! speed_kmh = 160.0
//! demand = "emergency"        # or "service:<deceleration m/s^2>", "step:<service step>"
//! track = "low"               # a [tracks.X] name
//! vehicle = "tare"            # optional; the parameter file's vehicle when absent
//! ```

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{Context, Result, anyhow, bail};
use hils_brake_unit::BrakeDemand;
use hils_plant::track::ContactSets;
use hils_plant::{Surface, Track, Zone};
use hils_sil::ParamFile;
use serde::Deserialize;

/// Pass criteria and bench constants.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct Criteria {
    /// Largest stopping distance over the distance the adhesion allows.
    pub max_distance_ratio: f64,
    /// Longest a wheelset may stay locked, s.
    pub max_lock_s: f64,
    /// WSP timer actions allowed per run.
    pub max_wsp_timer_actions: u32,
    /// Largest free air the WSP may vent in a run, litres (default: the usable air of an
    /// assumed 150 l brake reservoir between the 500 kPa supply and the laden EB cylinder
    /// pressure, docs/wsp.md).
    pub max_air_consumption_l: f64,
    /// A wheelset is locked while its speed is below this share of the vehicle speed.
    pub lock_speed_ratio: f64,
    /// Piston stroke of a brake cylinder (with its clearance), m (assumed).
    pub cylinder_stroke_m: f64,
    /// Pipe volume from the dump valve to the cylinders of one wheelset, litres (assumed).
    pub pipe_volume_l: f64,
    /// Evaluation stops below this vehicle speed (WSP inhibited), m/s.
    pub min_speed_mps: f64,
    /// Volume one dump valve vents, litres: n_cyl A_c stroke + pipe, n_cyl = one caliper
    /// cylinder per two friction faces of `[brake]` ([`Criteria::for_file`]).
    #[serde(skip)]
    pub channel_volume_l: f64,
    /// The WSP timer of the unit under test, s: the simulated unit's `vent_max_s`
    /// ([`Criteria::for_file`]); a continuous WSP action this long counts as a timer action.
    #[serde(skip)]
    pub wsp_timer_s: f64,
}

impl Default for Criteria {
    fn default() -> Self {
        Self {
            max_distance_ratio: 1.35,
            max_lock_s: 1.0,
            max_wsp_timer_actions: 0,
            max_air_consumption_l: 214.1,
            lock_speed_ratio: 0.2,
            cylinder_stroke_m: 0.05,
            pipe_volume_l: 0.5,
            min_speed_mps: 1.4,
            channel_volume_l: 0.0,
            wsp_timer_s: 0.0,
        }
        .for_file(&ParamFile::default())
    }
}

impl Criteria {
    /// The bench constants that follow from the parameter file: the vented volume of a
    /// channel from `[brake]` and the WSP timer of the unit.
    pub fn for_file(mut self, file: &ParamFile) -> Self {
        let b = &file.plant.brake;
        let cylinders = (b.friction_faces as f64 / 2.0).ceil().max(1.0);
        self.channel_volume_l =
            cylinders * b.piston_area * self.cylinder_stroke_m * 1000.0 + self.pipe_volume_l;
        self.wsp_timer_s = file.unit_config().wsp.vent_max_s;
        self
    }
}

/// A track as the programme (or a track file) writes it.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrackSpec {
    /// Surface outside the zones.
    pub base: Surface,
    /// Zones in order.
    #[serde(default)]
    pub zone: Vec<Zone>,
    /// Low and very low contact sets (default: the documented ones).
    #[serde(default)]
    pub sets: ContactSets,
}

impl TrackSpec {
    pub fn track(&self) -> Result<Track> {
        Track::new(self.base, &self.zone).map_err(|e| anyhow!("{e}"))
    }
}

/// A run of the programme.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunSpec {
    pub name: String,
    pub speed_kmh: f64,
    pub demand: String,
    pub track: String,
    #[serde(default)]
    pub vehicle: Option<String>,
}

/// The programme file.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Programme {
    #[serde(default)]
    pub criteria: Criteria,
    #[serde(default)]
    pub tracks: BTreeMap<String, TrackSpec>,
    /// Vehicle variants: `[vehicle]` keys of the parameter file that differ.
    #[serde(default)]
    pub vehicles: BTreeMap<String, BTreeMap<String, f64>>,
    pub run: Vec<RunSpec>,
}

/// A run ready to simulate or to judge.
#[derive(Clone, Debug)]
pub struct Run {
    pub name: String,
    pub speed_mps: f64,
    pub demand: BrakeDemand,
    pub track: Track,
    pub sets: ContactSets,
    pub file: ParamFile,
}

/// Parses a demand: `emergency`, `service:<m/s^2>` or `step:<service brake step>`.
pub fn parse_demand(text: &str) -> Result<BrakeDemand> {
    if text == "emergency" {
        return Ok(BrakeDemand::Emergency);
    }
    if let Some(step) = text.strip_prefix("step:") {
        let step = step
            .trim()
            .parse::<u8>()
            .ok()
            .filter(|s| *s >= 1)
            .ok_or_else(|| anyhow!("demand `{text}`: `step:<1..>`"))?;
        return Ok(BrakeDemand::ServiceStep { step });
    }
    let decel = text
        .strip_prefix("service:")
        .and_then(|d| d.trim().parse::<f32>().ok())
        .filter(|d| d.is_finite() && *d > 0.0)
        .ok_or_else(|| {
            anyhow!("demand `{text}`: `emergency`, `service:<m/s^2 > 0>` or `step:<n>`")
        })?;
    Ok(BrakeDemand::Service {
        deceleration_mps2: decel,
    })
}

/// The demand as the programme writes it: `emergency`, `service:<m/s^2>`, `step:<n>`
/// (what [`parse_demand`] reads; `release` for no brake).
pub fn demand_text(demand: BrakeDemand) -> String {
    match demand {
        BrakeDemand::Emergency => "emergency".into(),
        BrakeDemand::Service { deceleration_mps2 } => format!("service:{deceleration_mps2}"),
        BrakeDemand::ServiceStep { step } => format!("step:{step}"),
        BrakeDemand::Release => "release".into(),
    }
}

/// A track in one line: the base surface, then each zone, `low; dry from 120 to 220 m`
/// (a uniform track is its surface's name). A run log's `# track:` metadata (written by
/// `hils rig`) says its track so, and `hils wsp-test --log` compares it with the run's.
pub fn track_layout(track: &Track) -> String {
    let mut s = track.base().name().to_string();
    for z in track.zones() {
        s += &format!("; {} from {} to {} m", z.surface.name(), z.start_m, z.end_m);
    }
    s
}

fn apply_vehicle(file: &mut ParamFile, name: &str, keys: &BTreeMap<String, f64>) -> Result<()> {
    let v = &mut file.plant.vehicle;
    for (key, &value) in keys {
        let slot = match key.as_str() {
            "carbody_mass" => &mut v.carbody_mass,
            "carbody_pitch_inertia" => &mut v.carbody_pitch_inertia,
            "bogie_mass" => &mut v.bogie_mass,
            "wheelset_mass" => &mut v.wheelset_mass,
            "wheel_radius" => &mut v.wheel_radius,
            other => bail!("vehicle `{name}`: unknown key `{other}`"),
        };
        *slot = value;
    }
    file.validate()
        .map_err(|e| anyhow!("vehicle `{name}`: {e}"))
}

impl Programme {
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read programme {}", path.display()))?;
        let mut p: Programme = toml::from_str(&text)
            .map_err(|e| anyhow!("{}: invalid programme: {e}", path.display()))?;
        p.criteria = p.criteria.for_file(&ParamFile::default());
        if p.run.is_empty() {
            bail!("{}: the programme has no [[run]]", path.display());
        }
        Ok(p)
    }

    /// The runs on the parameter file `base`, checked (names unique, tracks and vehicles
    /// known, speeds in range).
    pub fn runs(&self, base: &ParamFile) -> Result<Vec<Run>> {
        let mut names = std::collections::BTreeSet::new();
        self.run
            .iter()
            .map(|r| {
                if !names.insert(r.name.as_str()) {
                    bail!("run `{}` appears twice", r.name);
                }
                let spec = self
                    .tracks
                    .get(&r.track)
                    .ok_or_else(|| anyhow!("run `{}`: no track `{}`", r.name, r.track))?;
                let track = spec
                    .track()
                    .map_err(|e| anyhow!("track `{}`: {e}", r.track))?;
                spec.sets
                    .validate()
                    .map_err(|e| anyhow!("track `{}`: {e}", r.track))?;
                if !(r.speed_kmh > 5.0 && r.speed_kmh <= 400.0) {
                    bail!(
                        "run `{}`: speed_kmh {} not in (5, 400]",
                        r.name,
                        r.speed_kmh
                    );
                }
                let mut file = *base;
                if let Some(v) = &r.vehicle {
                    let keys = self
                        .vehicles
                        .get(v)
                        .ok_or_else(|| anyhow!("run `{}`: no vehicle `{v}`", r.name))?;
                    apply_vehicle(&mut file, v, keys)?;
                }
                Ok(Run {
                    name: r.name.clone(),
                    speed_mps: r.speed_kmh / hils_sil::KMH_PER_MPS,
                    demand: parse_demand(&r.demand).with_context(|| format!("run `{}`", r.name))?,
                    track,
                    sets: spec.sets,
                    file,
                })
            })
            .collect()
    }
}
