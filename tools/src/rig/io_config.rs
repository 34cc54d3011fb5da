//! The rig's controller I/O configuration file (`hils rig configure io FILE`, `hils rig run
//! --io FILE`): which valve inputs are wired, the demand PWM and the air-spring transducer
//! signals, in the units a rig builder reads off the controller's documentation. Every key
//! is optional (the board's default); the file becomes the `Configure` frames of
//! `hils_rig_core::controller_io::IoItem`, checked here with the board's own rules
//! (`IoConfig::set`) before anything is sent.
//!
//! ```toml
//! [valves]                  # wheelsets 1-4 whose coil is wired to the board
//! dump = [1, 2, 3, 4]
//! hold = [1, 2, 3, 4]
//! active_high = false       # the optocoupler pulls the input low while the coil is energised
//! [demand]
//! pwm_frequency_hz = 500
//! duty_release_percent = 10.0
//! duty_full_percent = 90.0
//! full_scale_mps2 = 1.5     # deceleration at the full-scale duty
//! service_steps = 7         # the controller's steps: step n = n / steps of full service
//! full_service_mps2 = 1.0
//! frame = false             # also send RIG_BRAKE_DEMAND
//! [load]
//! zero_v = 0.5              # at the controller, at 0 bar
//! full_v = 4.5              # at the full scale
//! full_scale_bar = 10.0
//! stage_gain = 2.0          # DAC pin -> controller
//! air_spring_area_m2 = 0.34 # per bogie (its springs together)
//! ```

use std::path::Path;

use anyhow::{Context, Result, anyhow, bail};
use hils_rig_core::can::{Command, ConfigItem};
use hils_rig_core::controller_io::{IoConfig, IoItem};
use serde::Deserialize;

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct File {
    #[serde(default)]
    valves: Valves,
    #[serde(default)]
    demand: Demand,
    #[serde(default)]
    load: Load,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct Valves {
    dump: Option<Vec<u8>>,
    hold: Option<Vec<u8>>,
    active_high: Option<bool>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct Demand {
    pwm_frequency_hz: Option<f64>,
    duty_release_percent: Option<f64>,
    duty_full_percent: Option<f64>,
    full_scale_mps2: Option<f64>,
    service_steps: Option<f64>,
    full_service_mps2: Option<f64>,
    frame: Option<bool>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct Load {
    zero_v: Option<f64>,
    full_v: Option<f64>,
    full_scale_bar: Option<f64>,
    stage_gain: Option<f64>,
    air_spring_area_m2: Option<f64>,
}

/// Which rule an I/O configuration in range breaks, with its values (`IoConfig::check`).
fn inconsistency(c: &IoConfig) -> String {
    let (d, l) = (&c.demand, &c.load);
    let reach_mv = hils_rig_core::load::DAC_VREF_MV as f64 * l.stage_gain_permille as f64 / 1e3;
    if d.duty_release_permille >= d.duty_full_permille {
        format!(
            "the release duty ({} %) must be below the full-scale duty ({} %)",
            d.duty_release_permille as f64 / 10.0,
            d.duty_full_permille as f64 / 10.0
        )
    } else if l.zero_mv >= l.full_mv {
        format!(
            "the signal at 0 bar ({} V) must be below the signal at the full scale ({} V)",
            l.zero_mv as f64 / 1e3,
            l.full_mv as f64 / 1e3
        )
    } else if l.full_mv as f64 > reach_mv {
        format!(
            "the signal at the full scale ({} V) is beyond the stage's reach (3.3 V x gain {} = {} V)",
            l.full_mv as f64 / 1e3,
            l.stage_gain_permille as f64 / 1e3,
            reach_mv / 1e3
        )
    } else {
        "inconsistent with the other values".to_string()
    }
}

/// The wheelset bits of a list of wheelsets 1-4.
/// A wheelset listed twice is refused (a typo such as `[1, 1, 3, 4]` for `[1, 2, 3, 4]`
/// would leave one input silently unwired).
pub fn wheelset_bits(key: &str, list: &[u8]) -> Result<u8> {
    list.iter().try_fold(0u8, |bits, &w| {
        if !(1..=4).contains(&w) {
            bail!("`{key}`: wheelset {w}; the board has wheelsets 1-4")
        }
        if bits & 1 << (w - 1) != 0 {
            bail!("`{key}`: wheelset {w} is listed twice")
        }
        Ok(bits | 1 << (w - 1))
    })
}

/// Reads a configuration file into the board's configuration, every value checked.
pub fn load(path: &Path) -> Result<IoConfig> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    parse(&text).with_context(|| format!("{}", path.display()))
}

/// A configuration from the file's text.
pub fn parse(text: &str) -> Result<IoConfig> {
    let f: File = toml::from_str(text).map_err(|e| anyhow!("{e}"))?;
    let mut c = IoConfig::DEFAULT;
    let mut wiring = c.valves;
    if let Some(d) = &f.valves.dump {
        wiring.dump = wheelset_bits("valves.dump", d)?;
    }
    if let Some(h) = &f.valves.hold {
        wiring.hold = wheelset_bits("valves.hold", h)?;
    }
    wiring.active_high = f.valves.active_high.unwrap_or(wiring.active_high);
    c.valves = wiring;
    let (d, l) = (&f.demand, &f.load);
    // (key, item, value in the file's unit, the item's units per file unit)
    let values = [
        (
            "demand.pwm_frequency_hz",
            IoItem::PwmFrequency,
            d.pwm_frequency_hz,
            1.0,
        ),
        (
            "demand.duty_release_percent",
            IoItem::DutyRelease,
            d.duty_release_percent,
            10.0,
        ),
        (
            "demand.duty_full_percent",
            IoItem::DutyFull,
            d.duty_full_percent,
            10.0,
        ),
        (
            "demand.full_scale_mps2",
            IoItem::DemandFullScale,
            d.full_scale_mps2,
            1000.0,
        ),
        (
            "demand.service_steps",
            IoItem::ServiceSteps,
            d.service_steps,
            1.0,
        ),
        (
            "demand.full_service_mps2",
            IoItem::FullService,
            d.full_service_mps2,
            1000.0,
        ),
        ("load.zero_v", IoItem::LoadZero, l.zero_v, 1000.0),
        ("load.full_v", IoItem::LoadFull, l.full_v, 1000.0),
        (
            "load.full_scale_bar",
            IoItem::LoadFullScale,
            l.full_scale_bar,
            1000.0,
        ),
        (
            "load.stage_gain",
            IoItem::LoadStageGain,
            l.stage_gain,
            1000.0,
        ),
        (
            "load.air_spring_area_m2",
            IoItem::AirSpringArea,
            l.air_spring_area_m2,
            1e4,
        ),
    ];
    for (key, item, value, scale) in values {
        let Some(value) = value else { continue };
        let (lo, hi) = item.range();
        let raw = (value * scale).round();
        if !(raw >= lo as f64 && raw <= hi as f64) {
            bail!(
                "`{key}` = {value}: the board takes {} to {}",
                lo as f64 / scale,
                hi as f64 / scale
            );
        }
        // The board would run the rounded value: a value off its grid is refused, not
        // rounded (0.5 Hz is not 1 Hz; 7.5 service steps are not 8).
        if (value * scale - raw).abs() > 1e-6 * raw.abs().max(1.0) {
            bail!(
                "`{key}` = {value}: the board takes steps of {} (the nearest is {})",
                1.0 / scale,
                raw / scale
            );
        }
        c.assign(item, raw as u16);
    }
    c.demand.frame = d.frame.unwrap_or(false);
    c.check()
        .map_err(|e| anyhow!("`{}`: {}", key_of(e.0), inconsistency(&c)))?;
    Ok(c)
}

/// The file key of an item.
fn key_of(item: IoItem) -> &'static str {
    match item {
        IoItem::ValveWiring => "valves",
        IoItem::PwmFrequency => "demand.pwm_frequency_hz",
        IoItem::DutyRelease => "demand.duty_release_percent",
        IoItem::DutyFull => "demand.duty_full_percent",
        IoItem::DemandFullScale => "demand.full_scale_mps2",
        IoItem::ServiceSteps => "demand.service_steps",
        IoItem::FullService => "demand.full_service_mps2",
        IoItem::LoadZero => "load.zero_v",
        IoItem::LoadFull => "load.full_v",
        IoItem::LoadFullScale => "load.full_scale_bar",
        IoItem::LoadStageGain => "load.stage_gain",
        IoItem::AirSpringArea => "load.air_spring_area_m2",
        IoItem::DemandFrame => "demand.frame",
    }
}

/// The `Configure` commands that set the board to `c`, in an order the board accepts.
pub fn commands(c: &IoConfig) -> Vec<Command> {
    c.items()
        .into_iter()
        .map(|(item, v)| Command::Configure(ConfigItem::Io(item, v)))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_file_becomes_the_board_configuration_and_bad_values_name_their_key() {
        let c = parse(
            "[valves]\ndump = [1, 2]\nhold = [3]\n[demand]\nduty_release_percent = 20\n\
             duty_full_percent = 80\nframe = true\n[load]\nzero_v = 1.0\nfull_v = 5.0\n\
             stage_gain = 2.5\n",
        )
        .unwrap();
        assert_eq!((c.valves.dump, c.valves.hold), (0b0011, 0b0100));
        assert_eq!(
            (c.demand.duty_release_permille, c.demand.duty_full_permille),
            (200, 800)
        );
        assert!(c.demand.frame);
        assert_eq!((c.load.zero_mv, c.load.full_mv), (1000, 5000));
        assert_eq!(parse("").unwrap(), IoConfig::DEFAULT);
        let err = |t: &str| format!("{:#}", parse(t).unwrap_err());
        assert!(err("[valves]\ndump = [5]\n").contains("valves.dump"));
        assert!(err("[demand]\npwm_frequency_hz = 0\n").contains("demand.pwm_frequency_hz"));
        assert!(
            err("[demand]\nduty_release_percent = 95\n").contains("duty"),
            "{}",
            err("[demand]\nduty_release_percent = 95\n")
        );
        assert!(err("[load]\nfull_v = 9.0\n").contains("load"));
        // The controller's full service above the PWM's full scale: its top steps would
        // all read as the full scale.
        let e = err("[demand]\nfull_scale_mps2 = 0.5\nfull_service_mps2 = 1.0\n");
        assert!(e.contains("demand.full_service_mps2"), "{e}");
        assert!(err("[load]\nvolts = 1\n").contains("volts"));
        // Off the item's grid: refused, not rounded; a wheelset twice: refused.
        for (text, key) in [
            (
                "[demand]\npwm_frequency_hz = 0.5\n",
                "demand.pwm_frequency_hz",
            ),
            ("[demand]\nservice_steps = 7.5\n", "demand.service_steps"),
            (
                "[demand]\nduty_release_percent = 10.05\n",
                "demand.duty_release_percent",
            ),
            ("[valves]\ndump = [1, 1, 3, 4]\n", "valves.dump"),
        ] {
            assert!(err(text).contains(key), "{text}: {}", err(text));
        }
        assert_eq!(
            parse("[demand]\nduty_release_percent = 10.1\nfull_scale_mps2 = 1.234\n")
                .unwrap()
                .demand
                .duty_release_permille,
            101
        );
    }
}
