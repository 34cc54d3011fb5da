//! Localisation along the signal chain (`spec/diagnosis.md`, `localisation`): each link
//! whose input and output are both logged is checked on its own, in noise units on
//! validation data, for the baseline and for the extended model.
//!
//! Links and what observes them:
//! - `pad-force`: cylinder pressure -> pad clamp force (Eq 1, actuator lag, sensor gains),
//!   where `p_cyl` and `f_clamp` are both logged;
//! - `disc-pad-friction`: clamp force -> tangential brake force (mu_d, Eq 2) where `f_brake`
//!   is logged (the replay evaluates Eq 2 at the measured disc temperature where logged);
//! - `disc-thermal`: brake power -> disc temperature (Eqs 3-6) where `t_disc` is logged;
//! - `wheel-rail`: per wheelset, the wheel's speed relative to v_ref (creep, wheel radius,
//!   adhesion): the slip v_ref - r omega_j, measured against the model;
//! - `vehicle`: net force -> deceleration (v_ref, a_x, axle loads).
//!
//! A link is explained when the extended model's error there is within
//! [`LINK_EXPLAINED_RMS`] noise units.

use serde::Serialize;

use super::replay::{Channel, Prepared, Quantity, Replay};
use hils_plant::WHEELSETS;

/// A link's validation RMS (noise units) up to which the model explains it.
pub const LINK_EXPLAINED_RMS: f64 = 2.5;

/// One entry of the `localisation` list.
#[derive(Clone, Debug, Serialize)]
pub struct LinkCheck {
    pub link: String,
    /// 1-based wheelset for a per-wheelset link.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub wheelset: Option<usize>,
    pub channels: Vec<String>,
    pub baseline_error: f64,
    pub extended_error: f64,
    pub explained: bool,
    pub note: String,
}

/// Sum of squared normalised validation residuals and their count.
#[derive(Clone, Copy, Default)]
struct Acc(f64, usize);

impl Acc {
    fn rms(self) -> f64 {
        if self.1 == 0 {
            0.0
        } else {
            (self.0 / self.1 as f64).sqrt()
        }
    }
}

fn channel_acc(run: &Prepared, c: &Channel, pred: &[f64], acc: &mut Acc) {
    for (k, &b) in c.bins.iter().enumerate() {
        if run.validation[b] && pred[k].is_finite() {
            acc.0 += ((pred[k] - c.measured[k]) / c.sigma[k]).powi(2);
            acc.1 += 1;
        }
    }
}

/// Slip error of wheelset `j`: (v - r omega_j) of the model against the measurement, over
/// the combined sigma of both channels, on validation bins where both are measured.
fn slip_acc(run: &Prepared, rep: &Replay, j: usize, acc: &mut Acc) {
    let find = |q: Quantity| run.channels.iter().position(|c| c.quantity == q);
    let (Some(iv), Some(iw)) = (find(Quantity::VRef), find(Quantity::WheelSpeed(j))) else {
        return;
    };
    let (cv, cw) = (&run.channels[iv], &run.channels[iw]);
    let (pv, pw) = (&rep.predicted[iv], &rep.predicted[iw]);
    let mut kv = 0;
    for (kw, &b) in cw.bins.iter().enumerate() {
        while kv < cv.bins.len() && cv.bins[kv] < b {
            kv += 1;
        }
        if kv >= cv.bins.len() || cv.bins[kv] != b || !run.validation[b] {
            continue;
        }
        let model = pv[kv] - pw[kw];
        let measured = cv.measured[kv] - cw.measured[kw];
        let sigma = (cv.sigma[kv].powi(2) + cw.sigma[kw].powi(2)).sqrt();
        if model.is_finite() && measured.is_finite() {
            acc.0 += ((model - measured) / sigma).powi(2);
            acc.1 += 1;
        }
    }
}

/// Which link a channel observes (None: wheel speeds, which the slip check uses).
fn link_of(q: Quantity) -> Option<&'static str> {
    match q {
        Quantity::PadFromPressure(_) => Some("pad-force"),
        Quantity::BrakeForce(_) => Some("disc-pad-friction"),
        Quantity::DiscTemp(_) => Some("disc-thermal"),
        Quantity::VRef | Quantity::Accel | Quantity::AxleLoad(_) => Some("vehicle"),
        Quantity::WheelSpeed(_) => None,
    }
}

const LINKS: [&str; 4] = ["pad-force", "disc-pad-friction", "disc-thermal", "vehicle"];

fn note_for(link: &str, explained: bool, baseline: f64) -> String {
    let what = match link {
        "pad-force" => "cylinder pressure -> pad clamp force (Eq 1, lag, sensor gains)",
        "disc-pad-friction" => "clamp force -> brake force, mu_d (Eq 2)",
        "disc-thermal" => "brake power -> disc temperature (Eqs 3-6)",
        "wheel-rail" => "brake torque -> wheel speed relative to v_ref (creep, adhesion, radius)",
        _ => "net force -> deceleration (mass, gradient, resistance, axle loads)",
    };
    let verdict = if baseline <= LINK_EXPLAINED_RMS {
        "the baseline explains it"
    } else if explained {
        "the effects found explain it"
    } else {
        "no listed effect explains it"
    };
    format!("{what}: {verdict}")
}

/// The localisation list for runs replayed in the baseline and in the extended model.
pub fn localise(runs: &[Prepared], base: &[Replay], ext: &[Replay]) -> Vec<LinkCheck> {
    let mut out = Vec::new();
    let entry = |link: &str, ws: Option<usize>, ch: Vec<String>, b: Acc, e: Acc| {
        let (be, ee) = (b.rms(), e.rms());
        let explained = ee <= LINK_EXPLAINED_RMS;
        LinkCheck {
            link: link.to_string(),
            wheelset: ws,
            channels: ch,
            baseline_error: be,
            extended_error: ee,
            explained,
            note: note_for(link, explained, be),
        }
    };
    for link in LINKS {
        let (mut b, mut e) = (Acc::default(), Acc::default());
        let mut names: Vec<String> = Vec::new();
        for ((run, rb), re) in runs.iter().zip(base).zip(ext) {
            for (i, c) in run.channels.iter().enumerate() {
                if link_of(c.quantity) != Some(link) {
                    continue;
                }
                channel_acc(run, c, &rb.predicted[i], &mut b);
                channel_acc(run, c, &re.predicted[i], &mut e);
                let n = c.quantity.label();
                if !names.contains(&n) {
                    names.push(n);
                }
            }
        }
        if b.1 > 0 {
            out.push(entry(link, None, names, b, e));
        }
    }
    for j in 0..WHEELSETS {
        let (mut b, mut e) = (Acc::default(), Acc::default());
        for ((run, rb), re) in runs.iter().zip(base).zip(ext) {
            slip_acc(run, rb, j, &mut b);
            slip_acc(run, re, j, &mut e);
        }
        if b.1 > 0 {
            let ch = vec!["v_ref".to_string(), format!("omega{}", j + 1)];
            out.push(entry("wheel-rail", Some(j + 1), ch, b, e));
        }
    }
    out
}
