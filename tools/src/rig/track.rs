//! Tracks and vehicle variants sent to the board (issue 13 item 5): the `RIG_COMMAND`
//! frames `TrackZone` (one per zone), `Track` commit, and `Vehicle`, then a `Start` with
//! `StartTrack` = 1 (`hils rig start --track FILE`, `hils rig run --programme`).
//!
//! What the frames carry, checked here before anything is sent (nothing is approximated):
//! zone bounds on a 0.1 m grid within 0-104 857.5 m; up to 16 zones (the plant's
//! `MAX_ZONES`); the documented low / very-low contact sets (the board has no others);
//! the `[vehicle]` keys of [`VehicleKey`] as IEEE f32 (a value f32 does not hold exactly to
//! 1e-6 is refused); the rest of the parameter file at its defaults (the board's plant runs
//! the default parameter file), degraded adhesion off.

use std::path::Path;

use anyhow::{Context, Result, anyhow, bail};
use hils_plant::params::VehicleParams;
use hils_plant::track::{ContactSets, MAX_ZONES};
use hils_plant::{Params, Track};
use hils_rig_core::can::{
    Command, TrackCommand, VehicleKey, ZONE_MAX_M, ZONE_RESOLUTION_M, ZoneFrame,
};
use hils_rig_core::rig::KeptSetup;
use hils_sil::ParamFile;

use crate::wsp::metrics::AvailableAdhesion;
use crate::wsp::programme::TrackSpec;

/// Reads a track file: the `[tracks.NAME]` table of a programme at the top level
/// (`base = "low"`, `[[zone]]` with `start_m`, `end_m`, `surface`; optional `[sets]`).
pub fn load_track_file(path: &Path) -> Result<(Track, ContactSets)> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read track file {}", path.display()))?;
    let spec: TrackSpec =
        toml::from_str(&text).with_context(|| format!("{}: invalid track file", path.display()))?;
    let track = spec.track().with_context(|| path.display().to_string())?;
    // ParamError (no_std) is a leaf with Display only: its text is the whole cause.
    spec.sets
        .validate()
        .map_err(|e| anyhow!("{}: {e}", path.display()))?;
    Ok((track, spec.sets))
}

/// The frames that put `track` on the board (a clear, the zones, then the commit), or why
/// it cannot go. The clear first: zones left from an earlier, unfinished load are not
/// committed with this track's.
pub fn track_commands(track: &Track, sets: &ContactSets) -> Result<Vec<Command>> {
    if *sets != ContactSets::default() {
        bail!("the track's own low/very-low contact sets: the board has the documented ones only");
    }
    if track.zones().len() > MAX_ZONES {
        bail!("a track on the board holds at most {MAX_ZONES} zones");
    }
    let mut out = Vec::with_capacity(track.zones().len() + 2);
    out.push(Command::Track(TrackCommand::Clear));
    for (i, z) in track.zones().iter().enumerate() {
        let zone = ZoneFrame::of(z).ok_or_else(|| {
            anyhow!(
                "zone {}: bounds {}-{} m not on the TrackZone frame's {ZONE_RESOLUTION_M} m grid within 0-{ZONE_MAX_M} m",
                i + 1,
                z.start_m,
                z.end_m
            )
        })?;
        out.push(Command::TrackZone {
            index: i as u8,
            zone,
        });
    }
    out.push(Command::Track(TrackCommand::Commit {
        base: track.base(),
        zones: track.zones().len() as u8,
    }));
    Ok(out)
}

/// `start` with the setup digest of what `setup` (the frames sent before it, from a
/// `Track` clear and a `Vehicle` default on) leaves on a board that received them all:
/// the frames replayed through rig-core's own [`KeptSetup`], the board's rules. A lost frame makes the board's digest differ: the start is
/// rejected instead of running an earlier setup.
pub fn with_setup_digest(setup: &[Command], mut start: Command) -> Result<Command> {
    let mut kept = KeptSetup::default();
    for c in setup {
        kept.apply(c).map_err(|e| {
            anyhow!(
                "the {} frame would be refused by the board ({})",
                super::commands::command_name(c),
                refusal(e)
            )
        })?;
    }
    if let Command::Start(start) = &mut start {
        if start.track && kept.track().is_none() {
            bail!("a start on a track, but no track commit is sent before it");
        }
        start.setup_digest = kept.digest(start.track);
    }
    Ok(start)
}

/// Why the board's kept setup refuses a frame, in words.
fn refusal(e: hils_rig_core::rig::CommandError) -> String {
    use hils_rig_core::rig::CommandError;
    match e {
        CommandError::Track(t) => t.to_string(),
        CommandError::TrackIncomplete { index } => {
            format!("zone {} not received before the commit", index + 1)
        }
        CommandError::NoTrack => "no track kept".into(),
        _ => "a setup frame out of place".into(),
    }
}

/// The frames that set the board's vehicle to `vehicle` (the default vehicle, then each
/// key that differs), or why it cannot be carried.
pub fn vehicle_commands(vehicle: &VehicleParams) -> Result<Vec<Command>> {
    let default = VehicleParams::default();
    let mut out = vec![Command::Vehicle {
        key: VehicleKey::Default,
        value: 0.0,
    }];
    let mut carried = default;
    for key in VehicleKey::VALUES {
        let value = key.value(vehicle);
        if value != key.value(&default) {
            let v32 = value as f32;
            if ((v32 as f64) - value).abs() > 1e-6 * value.abs() {
                bail!(
                    "vehicle {} = {value}: not carried exactly as f32",
                    key.name()
                );
            }
            out.push(Command::Vehicle { key, value: v32 });
        }
        key.apply(&mut carried, value as f32);
    }
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-6 * b.abs();
    let same = [
        (carried.g, vehicle.g),
        (carried.carbody_cog_height, vehicle.carbody_cog_height),
        (carried.bogie_pitch_inertia, vehicle.bogie_pitch_inertia),
        (carried.bogie_cog_height, vehicle.bogie_cog_height),
        (carried.wheelset_spin_inertia, vehicle.wheelset_spin_inertia),
        (carried.bogie_base, vehicle.bogie_base),
        (carried.wheel_base, vehicle.wheel_base),
    ]
    .iter()
    .all(|&(a, b)| close(a, b));
    if !same {
        bail!("a [vehicle] key the Vehicle frame does not carry differs from the default");
    }
    Ok(out)
}

/// Whether the board can run on `file`'s parameters: everything but `[vehicle]` (sent by
/// [`vehicle_commands`]) and the friction model (in the start frame) at the defaults.
pub fn check_params(file: &ParamFile) -> Result<()> {
    if file.degraded_adhesion.enabled {
        bail!("degraded adhesion is on: the board's plant runs it off (no frame carries it)");
    }
    let mut plant = file.plant;
    plant.vehicle = Params::default().vehicle;
    plant.friction.model = Params::default().friction.model;
    if plant != Params::default() {
        bail!("the parameter file differs from the default one the board runs");
    }
    Ok(())
}

/// The available adhesion of the board's plant (default parameters and contact sets,
/// degraded adhesion off): what `hils decode` and `hils rig record` write as `mu_avail*`
/// from the logged surface and vehicle speed; the table `hils wsp-test` judges with
/// ([`AvailableAdhesion`]), computed once.
pub fn board_adhesion() -> &'static AvailableAdhesion {
    static TABLE: std::sync::OnceLock<AvailableAdhesion> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| AvailableAdhesion::new(&Params::default(), &ContactSets::default()))
}
