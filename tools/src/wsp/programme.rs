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
//!
//! Every value is checked when the programme is read, before any run, and an error names
//! the file, the table and the key ([`Programme::load`], [`Programme::runs`]): each
//! criterion within its range ([`Criteria::validate`]); zone bounds finite, ordered, within
//! [`ZONE_RANGE_M`]; contact sets and vehicle values within the parameter file's ranges;
//! run names plain file names (they name the report's files:
//! [`crate::outputs::safe_file_name`]) and unique; speeds in (5, 400] km/h; a service
//! deceleration above 0 and at most the emergency brake's, a service step within the
//! parameter file's steps; tracks and vehicles that exist.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{Context, Result, anyhow, bail};
use hils_brake_unit::BrakeDemand;
use hils_plant::params::{ParamError, check};
use hils_plant::track::ContactSets;
use hils_plant::{Surface, Track, Zone};
use hils_sil::ParamFile;
use serde::Deserialize;

use crate::outputs::safe_file_name;

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
    /// Checks every criterion and bench constant against its range (NaN and inf fail); the
    /// error names the key.
    pub fn validate(&self) -> Result<(), ParamError> {
        let c = self;
        check("max_distance_ratio", c.max_distance_ratio, 1.0, 10.0)?;
        check("max_lock_s", c.max_lock_s, 0.0, 60.0)?;
        check(
            "max_wsp_timer_actions",
            c.max_wsp_timer_actions as f64,
            0.0,
            1000.0,
        )?;
        check("max_air_consumption_l", c.max_air_consumption_l, 0.0, 1e5)?;
        check("lock_speed_ratio", c.lock_speed_ratio, 0.01, 0.99)?;
        check("cylinder_stroke_m", c.cylinder_stroke_m, 1e-3, 0.5)?;
        check("pipe_volume_l", c.pipe_volume_l, 0.0, 100.0)?;
        check("min_speed_mps", c.min_speed_mps, 0.0, 30.0)
    }

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

/// Zone bounds a track may have, m from the leading wheelset at the brake command (the
/// trailing wheelsets start 16.5 m behind it).
pub const ZONE_RANGE_M: (f64, f64) = (-1000.0, 1.0e6);

impl TrackSpec {
    /// The track (zones checked: finite, in [`ZONE_RANGE_M`], ordered, disjoint) and its
    /// contact sets checked.
    pub fn track(&self) -> Result<Track> {
        for (i, z) in self.zone.iter().enumerate() {
            for (key, x) in [("start_m", z.start_m), ("end_m", z.end_m)] {
                check(key, x, ZONE_RANGE_M.0, ZONE_RANGE_M.1)
                    .map_err(|e| anyhow!("zone {}: {e}", i + 1))?;
            }
        }
        self.sets.validate().map_err(|e| anyhow!("{e}"))?;
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
    /// The file it was read from (for messages).
    #[serde(skip)]
    pub path: std::path::PathBuf,
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

/// Parses a demand: `emergency`, `service:<m/s^2>` or `step:<service brake step>` (the
/// form only: [`check_demand`] checks its value against a parameter file).
pub fn parse_demand(text: &str) -> Result<BrakeDemand> {
    let text = text.trim();
    if text == "emergency" {
        return Ok(BrakeDemand::Emergency);
    }
    if let Some(step) = text.strip_prefix("step:") {
        let step = step
            .trim()
            .parse::<u8>()
            .ok()
            .filter(|s| *s >= 1)
            .ok_or_else(|| anyhow!("`{text}`: a service step is `step:<1..255>`"))?;
        return Ok(BrakeDemand::ServiceStep { step });
    }
    let decel = text
        .strip_prefix("service:")
        .and_then(|d| d.trim().parse::<f32>().ok())
        .filter(|d| d.is_finite() && *d > 0.0)
        .ok_or_else(|| {
            anyhow!("`{text}`: a demand is `emergency`, `service:<m/s^2 > 0>` or `step:<n>`")
        })?;
    Ok(BrakeDemand::Service {
        deceleration_mps2: decel,
    })
}

/// Checks a demand's value against the brake unit of `file`: a service deceleration at
/// most the emergency brake's, a step within the service steps.
pub fn check_demand(demand: BrakeDemand, file: &ParamFile) -> Result<()> {
    let u = &file.brake_unit;
    match demand {
        BrakeDemand::Service { deceleration_mps2 } => {
            let d = deceleration_mps2 as f64;
            if d > u.eb_deceleration_mps2 {
                bail!(
                    "service deceleration {d} m/s^2 is above the emergency brake's {} m/s^2 \
                     (brake_unit.eb_deceleration_mps2): at most that",
                    u.eb_deceleration_mps2
                );
            }
        }
        BrakeDemand::ServiceStep { step } if step > u.service_steps => bail!(
            "service step {step} of {} (brake_unit.service_steps): a step is 1-{}",
            u.service_steps,
            u.service_steps
        ),
        _ => {}
    }
    Ok(())
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
            other => bail!("[vehicles.{name}] unknown key `{other}`"),
        };
        *slot = value;
    }
    file.validate()
        .map_err(|e| anyhow!("[vehicles.{name}] {e}"))
}

impl Programme {
    /// Reads and checks a programme (every value that does not depend on the parameter
    /// file: criteria, tracks, run names); errors name the file, the table and the key.
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read programme {}", path.display()))?;
        Self::parse(path, &text)
    }

    /// Parses and checks a programme's text ([`Programme::load`]; `path` names it).
    pub fn parse(path: &Path, text: &str) -> Result<Self> {
        let at = path.display();
        let mut p: Programme =
            toml::from_str(text).map_err(|e| anyhow!("{at}: invalid programme: {e}"))?;
        p.path = path.to_path_buf();
        p.criteria
            .validate()
            .map_err(|e| anyhow!("{at}: [criteria] {e}"))?;
        p.criteria = p.criteria.for_file(&ParamFile::default());
        for (name, spec) in &p.tracks {
            spec.track()
                .map_err(|e| anyhow!("{at}: [tracks.{name}] {e}"))?;
        }
        if p.run.is_empty() {
            bail!("{at}: the programme has no [[run]]");
        }
        let mut names = std::collections::BTreeSet::new();
        for (i, r) in p.run.iter().enumerate() {
            let run = format!("{at}: [[run]] {} `{}`", i + 1, r.name);
            safe_file_name(&r.name).map_err(|why| {
                anyhow!("{run}: `name` {why} (a run's name names its report files and log)")
            })?;
            if !names.insert(r.name.as_str()) {
                bail!("{run}: `name` appears twice");
            }
        }
        Ok(p)
    }

    /// The runs on the parameter file `base`, checked (tracks and vehicles known, speeds
    /// and demands in range, vehicle values within the parameter file's ranges); errors
    /// name the file, the run and the key.
    pub fn runs(&self, base: &ParamFile) -> Result<Vec<Run>> {
        self.run
            .iter()
            .enumerate()
            .map(|(i, r)| {
                self.run_of(r, base).map_err(|e| {
                    anyhow!(
                        "{}: [[run]] {} `{}`: {e:#}",
                        self.path.display(),
                        i + 1,
                        r.name
                    )
                })
            })
            .collect()
    }

    /// One run, checked ([`Programme::runs`]).
    fn run_of(&self, r: &RunSpec, base: &ParamFile) -> Result<Run> {
        let spec = self
            .tracks
            .get(&r.track)
            .ok_or_else(|| anyhow!("`track` = \"{}\": no [tracks.{}]", r.track, r.track))?;
        let track = spec
            .track()
            .map_err(|e| anyhow!("[tracks.{}] {e}", r.track))?;
        if !(r.speed_kmh > 5.0 && r.speed_kmh <= 400.0) {
            bail!("`speed_kmh` = {}: not in (5, 400] km/h", r.speed_kmh);
        }
        let mut file = *base;
        if let Some(v) = &r.vehicle {
            let keys = self
                .vehicles
                .get(v)
                .ok_or_else(|| anyhow!("`vehicle` = \"{v}\": no [vehicles.{v}]"))?;
            apply_vehicle(&mut file, v, keys)?;
        }
        let demand = parse_demand(&r.demand)
            .and_then(|d| check_demand(d, &file).map(|()| d))
            .map_err(|e| anyhow!("`demand` = \"{}\": {e:#}", r.demand))?;
        Ok(Run {
            name: r.name.clone(),
            speed_mps: r.speed_kmh / hils_sil::KMH_PER_MPS,
            demand,
            track,
            sets: spec.sets,
            file,
        })
    }
}
