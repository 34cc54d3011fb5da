//! Localisation along the signal chain (`spec/diagnosis.md`, `localisation`): each link
//! whose input and output are both logged is checked on its own, in noise units on
//! validation data, for the baseline and for the extended model.
//!
//! Links and what observes them:
//! - `pad-force`: cylinder pressure -> pad clamp force (Eq 1, actuator lag, sensor gains),
//!   per wheelset where `p_cyl` and `f_clamp` are both logged;
//! - `disc-pad-friction`: clamp force -> tangential brake force (mu_d, Eq 2), per wheelset
//!   where `f_brake` is logged (the replay evaluates Eq 2 at the measured disc temperature
//!   where logged);
//! - `disc-thermal`: brake power -> disc temperature (Eqs 3-6), per wheelset where `t_disc`
//!   is logged;
//! - `wheel-rail`: per wheelset, the wheel's speed relative to v_ref (creep, wheel radius,
//!   adhesion): the slip v_ref - r omega_j, measured against the model;
//! - `vehicle`: net force -> deceleration (v_ref, a_x, axle loads).
//!
//! A link is explained when the extended model's error there is within
//! [`LINK_EXPLAINED_RMS`] noise units. A link with per-wheelset channels has one entry per
//! wheelset when the wheelsets differ beyond noise (issue 27): their verdicts differ, or a
//! wheelset departs from the others' common measured-to-model scale by more than the link's
//! explained level ([`odd_wheelsets`]); the note then names the wheelset and the size of the
//! difference. An extension that makes a link's error worse than the baseline's by more than
//! [`SPOIL_MARGIN`] is not kept ([`spoiled`]).

use std::collections::BTreeMap;

use serde::Serialize;

use super::replay::{Channel, Prepared, Quantity, Replay};
use crate::figures::{round_dp, round_sig};
use hils_plant::WHEELSETS;

/// A link's validation RMS (noise units) up to which the model explains it.
pub const LINK_EXPLAINED_RMS: f64 = 2.5;
/// An extension spoils a link when its error there exceeds the baseline's by more than
/// this (noise units): it makes the link worse beyond the noise.
pub const SPOIL_MARGIN: f64 = 1.0;

/// A link of the signal chain.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Link {
    PadForce,
    DiscPadFriction,
    DiscThermal,
    WheelRail,
    Vehicle,
}

impl Link {
    /// The spec's name.
    pub fn name(self) -> &'static str {
        match self {
            Link::PadForce => "pad-force",
            Link::DiscPadFriction => "disc-pad-friction",
            Link::DiscThermal => "disc-thermal",
            Link::WheelRail => "wheel-rail",
            Link::Vehicle => "vehicle",
        }
    }

    fn what(self) -> &'static str {
        match self {
            Link::PadForce => "cylinder pressure -> pad clamp force (Eq 1, lag, sensor gains)",
            Link::DiscPadFriction => "clamp force -> brake force, mu_d (Eq 2)",
            Link::DiscThermal => "brake power -> disc temperature (Eqs 3-6)",
            Link::WheelRail => {
                "brake torque -> wheel speed relative to v_ref (creep, adhesion, radius)"
            }
            Link::Vehicle => "net force -> deceleration (mass, gradient, resistance, axle loads)",
        }
    }

    /// What differs on a wheelset, in words, for the notes.
    fn quantity(self) -> &'static str {
        match self {
            Link::PadForce => "the clamp force for its cylinder pressure",
            Link::DiscPadFriction => "mu_d",
            Link::DiscThermal => "the disc temperature rise",
            Link::WheelRail => "the wheel speed r omega",
            Link::Vehicle => "the vehicle's response",
        }
    }

    /// The channel of wheelset `j` that measures the link's output.
    fn channel(self, j: usize) -> Option<Quantity> {
        match self {
            Link::PadForce => Some(Quantity::PadFromPressure(j)),
            Link::DiscPadFriction => Some(Quantity::BrakeForce(j)),
            Link::DiscThermal => Some(Quantity::DiscTemp(j)),
            Link::WheelRail => Some(Quantity::WheelSpeed(j)),
            Link::Vehicle => None,
        }
    }
}

/// A link, and its wheelset (0-based) where it is checked per wheelset.
pub type LinkKey = (Link, Option<usize>);

/// Validation RMS per link and wheelset, noise units.
pub type Errors = BTreeMap<LinkKey, f64>;

/// One entry of the `localisation` list.
#[derive(Clone, Debug, Serialize)]
pub struct LinkCheck {
    pub link: String,
    /// 1-based wheelset for a per-wheelset entry.
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

    fn add(&mut self, other: Acc) {
        self.0 += other.0;
        self.1 += other.1;
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

/// The link (and wheelset) a channel observes (None: wheel speeds, which the slip uses).
fn link_of(q: Quantity) -> Option<LinkKey> {
    match q {
        Quantity::PadFromPressure(j) => Some((Link::PadForce, Some(j))),
        Quantity::BrakeForce(j) => Some((Link::DiscPadFriction, Some(j))),
        Quantity::DiscTemp(j) => Some((Link::DiscThermal, Some(j))),
        Quantity::VRef | Quantity::Accel | Quantity::AxleLoad(_) => Some((Link::Vehicle, None)),
        Quantity::WheelSpeed(_) => None,
    }
}

/// Validation error sums per link and wheelset of replays `reps` of `runs`.
fn accumulate(runs: &[Prepared], reps: &[Replay]) -> BTreeMap<LinkKey, Acc> {
    let mut out: BTreeMap<LinkKey, Acc> = BTreeMap::new();
    for (run, rep) in runs.iter().zip(reps) {
        for (i, c) in run.channels.iter().enumerate() {
            if let Some(key) = link_of(c.quantity) {
                channel_acc(run, c, &rep.predicted[i], out.entry(key).or_default());
            }
        }
        for j in 0..WHEELSETS {
            let mut a = Acc::default();
            slip_acc(run, rep, j, &mut a);
            if a.1 > 0 {
                out.entry((Link::WheelRail, Some(j))).or_default().add(a);
            }
        }
    }
    out
}

/// The validation error of every link (per wheelset where it has per-wheelset channels).
pub fn errors(runs: &[Prepared], reps: &[Replay]) -> Errors {
    accumulate(runs, reps)
        .into_iter()
        .filter(|(_, a)| a.1 > 0)
        .map(|(k, a)| (k, a.rms()))
        .collect()
}

/// The first link that `extended` makes worse than `baseline` by more than
/// [`SPOIL_MARGIN`], with both errors (issue 27: such an extension is not kept).
pub fn spoiled(baseline: &Errors, extended: &Errors) -> Option<(LinkKey, f64, f64)> {
    extended.iter().find_map(|(k, &e)| {
        let b = baseline.get(k).copied().unwrap_or(0.0);
        (e > b + SPOIL_MARGIN).then_some((*k, b, e))
    })
}

/// A link and wheelset in words (`disc-pad-friction of wheelset 3`).
pub fn key_name((link, j): LinkKey) -> String {
    match j {
        Some(j) => format!("{} of wheelset {}", link.name(), j + 1),
        None => link.name().to_string(),
    }
}

/// Weighted sums of one wheelset's channel of a link over all bins: measured m and model p
/// over their sigmas (for the least-squares scale m ~ s p), and the largest |m - p|.
#[derive(Clone, Copy, Default)]
struct ScaleSums {
    mp: f64,
    pp: f64,
    mm: f64,
    n: usize,
    /// Largest |m - p| (channel units) and its time, s.
    largest: (f64, f64),
}

impl ScaleSums {
    /// The least-squares scale of measured on model.
    fn scale(&self) -> f64 {
        if self.pp > 0.0 {
            self.mp / self.pp
        } else {
            1.0
        }
    }

    /// RMS of (m - s p) / sigma, noise units.
    fn rms_at(&self, s: f64) -> f64 {
        let ss = (self.mm - 2.0 * s * self.mp + s * s * self.pp).max(0.0);
        (ss / self.n.max(1) as f64).sqrt()
    }
}

/// [`ScaleSums`] per wheelset of `link` over replays `reps` (None where not logged).
fn scale_sums(runs: &[Prepared], reps: &[Replay], link: Link) -> [Option<ScaleSums>; WHEELSETS] {
    std::array::from_fn(|j| {
        let q = link.channel(j)?;
        let mut s: Option<ScaleSums> = None;
        for (run, rep) in runs.iter().zip(reps) {
            let Some(i) = run.channels.iter().position(|c| c.quantity == q) else {
                continue;
            };
            let (c, pred) = (&run.channels[i], &rep.predicted[i]);
            let acc = s.get_or_insert_with(ScaleSums::default);
            for k in 0..c.bins.len() {
                let (m, p) = (c.measured[k], pred[k]);
                if !(m.is_finite() && p.is_finite()) {
                    continue;
                }
                let w = 1.0 / (c.sigma[k] * c.sigma[k]);
                acc.mp += w * m * p;
                acc.pp += w * p * p;
                acc.mm += w * m * m;
                acc.n += 1;
                if (m - p).abs() > acc.largest.0.abs() {
                    acc.largest = (m - p, c.times[k]);
                }
            }
        }
        s
    })
}

/// Median of a few values.
fn median(mut x: Vec<f64>) -> f64 {
    x.sort_by(f64::total_cmp);
    let n = x.len();
    if n == 0 {
        f64::NAN
    } else if n % 2 == 1 {
        x[n / 2]
    } else {
        0.5 * (x[n / 2 - 1] + x[n / 2])
    }
}

/// Wheelsets (0-based) whose channel of `link` departs from the others: scaled by the
/// wheelsets' common (median) measured-to-model scale, its error exceeds
/// [`LINK_EXPLAINED_RMS`], while its own scale explains it (the difference is a level of that
/// wheelset). Empty when fewer than three wheelsets log the link, or more than two depart
/// (then the wheelsets have no common level).
pub fn odd_wheelsets(runs: &[Prepared], reps: &[Replay], link: Link) -> Vec<usize> {
    let sums = scale_sums(runs, reps, link);
    let logged: Vec<usize> = (0..WHEELSETS).filter(|&j| sums[j].is_some()).collect();
    if logged.len() < 3 {
        return Vec::new();
    }
    let common = median(
        logged
            .iter()
            .filter_map(|&j| sums[j].map(|s| s.scale()))
            .collect(),
    );
    let odd: Vec<usize> = logged
        .into_iter()
        .filter(|&j| {
            let s = sums[j].unwrap_or_default();
            let off = s.rms_at(common);
            off > LINK_EXPLAINED_RMS && s.rms_at(s.scale()) < 0.5 * off
        })
        .collect();
    if odd.len() > 2 { Vec::new() } else { odd }
}

/// A force, speed or temperature difference with its unit.
fn amount(x: f64, unit: &str) -> String {
    if unit == "N" && x.abs() >= 1000.0 {
        format!("{} kN", round_sig(x / 1000.0, 3))
    } else {
        format!("{} {unit}", round_sig(x, 3))
    }
}

/// The size of wheelset `j`'s difference on `link` against the other wheelsets (extended
/// model): its measured-to-model scale relative to theirs where a scale describes it (its
/// own scale explains most of its error), and its largest difference beside theirs.
fn size_note(runs: &[Prepared], reps: &[Replay], link: Link, j: usize) -> Option<String> {
    let sums = scale_sums(runs, reps, link);
    let own = sums[j]?;
    let others: Vec<ScaleSums> = (0..WHEELSETS)
        .filter(|&k| k != j)
        .filter_map(|k| sums[k])
        .collect();
    let unit = link.channel(j)?.unit();
    let (diff, at) = own.largest;
    let mut largest = format!(
        "largest difference from the model {} at {} s",
        amount(diff, unit),
        round_dp(at, 2)
    );
    if !others.is_empty() {
        let theirs = others.iter().map(|s| s.largest.0.abs()).fold(0.0, f64::max);
        largest += &format!(", the others' at most {}", amount(theirs, unit));
    }
    let common = median(others.iter().map(|s| s.scale()).collect());
    let is_level = own.rms_at(own.scale()) < 0.5 * own.rms_at(common);
    if others.is_empty() || !is_level {
        return Some(format!("wheelset {}: {largest}", j + 1));
    }
    let rel = own.scale() / common - 1.0;
    let pct = round_dp(rel.abs() * 100.0, 1);
    let dir = if rel >= 0.0 { "above" } else { "below" };
    Some(format!(
        "{} of wheelset {} is {pct} % {dir} the others' ({largest})",
        link.quantity(),
        j + 1
    ))
}

fn verdict(baseline: f64, explained: bool) -> &'static str {
    if baseline <= LINK_EXPLAINED_RMS {
        "the baseline explains it"
    } else if explained {
        "the effects found explain it"
    } else {
        "no listed effect explains it"
    }
}

/// The localisation list for runs replayed in the baseline and in the extended model.
pub fn localise(runs: &[Prepared], base: &[Replay], ext: &[Replay]) -> Vec<LinkCheck> {
    let (b, e) = (accumulate(runs, base), accumulate(runs, ext));
    let names = channel_names(runs);
    let mut out = Vec::new();
    for link in [
        Link::PadForce,
        Link::DiscPadFriction,
        Link::DiscThermal,
        Link::Vehicle,
        Link::WheelRail,
    ] {
        let keys: Vec<LinkKey> = b.keys().filter(|k| k.0 == link).copied().collect();
        if keys.is_empty() {
            continue;
        }
        let per_wheelset = link == Link::WheelRail
            || (keys.len() > 1 && wheelsets_differ(runs, base, ext, link, &b, &e, &keys));
        if per_wheelset {
            for &k in &keys {
                let entry = Entry::new(k, b[&k], e.get(&k).copied().unwrap_or_default());
                out.push(entry.check(&names, runs, ext));
            }
        } else {
            let (mut bs, mut es) = (Acc::default(), Acc::default());
            for k in &keys {
                bs.add(b[k]);
                es.add(e.get(k).copied().unwrap_or_default());
            }
            out.push(Entry::new((link, None), bs, es).check(&names, runs, ext));
        }
    }
    out
}

/// Whether the wheelsets of a link differ beyond noise: their verdicts differ (baseline or
/// extended), or some wheelset departs from the others ([`odd_wheelsets`]).
fn wheelsets_differ(
    runs: &[Prepared],
    base: &[Replay],
    ext: &[Replay],
    link: Link,
    b: &BTreeMap<LinkKey, Acc>,
    e: &BTreeMap<LinkKey, Acc>,
    keys: &[LinkKey],
) -> bool {
    let split = |m: &BTreeMap<LinkKey, Acc>| {
        let ok: Vec<bool> = keys
            .iter()
            .map(|k| m.get(k).copied().unwrap_or_default().rms() <= LINK_EXPLAINED_RMS)
            .collect();
        ok.iter().any(|x| *x) && ok.iter().any(|x| !*x)
    };
    split(b)
        || split(e)
        || !odd_wheelsets(runs, base, link).is_empty()
        || !odd_wheelsets(runs, ext, link).is_empty()
}

/// One entry being built: its key and error sums.
struct Entry {
    key: LinkKey,
    b: Acc,
    e: Acc,
}

impl Entry {
    fn new(key: LinkKey, b: Acc, e: Acc) -> Self {
        Entry { key, b, e }
    }

    fn check(
        &self,
        names: &BTreeMap<LinkKey, Vec<String>>,
        runs: &[Prepared],
        ext: &[Replay],
    ) -> LinkCheck {
        let (link, j) = self.key;
        let (be, ee) = (self.b.rms(), self.e.rms());
        let explained = ee <= LINK_EXPLAINED_RMS;
        let channels = match j {
            Some(j) if link == Link::WheelRail => vec!["v_ref".into(), format!("omega{}", j + 1)],
            _ => names
                .iter()
                .filter(|(k, _)| k.0 == link && (j.is_none() || k.1 == j))
                .flat_map(|(_, n)| n.clone())
                .collect(),
        };
        let mut note = format!("{}: {}", link.what(), verdict(be, explained));
        if let (Some(j), false) = (j, explained) {
            if let Some(size) = size_note(runs, ext, link, j) {
                note = format!("{note}: {size}");
            }
        }
        LinkCheck {
            link: link.name().to_string(),
            wheelset: j.map(|j| j + 1),
            channels,
            baseline_error: be,
            extended_error: ee,
            explained,
            note,
        }
    }
}

/// The compared channels' names per link and wheelset.
fn channel_names(runs: &[Prepared]) -> BTreeMap<LinkKey, Vec<String>> {
    let mut out: BTreeMap<LinkKey, Vec<String>> = BTreeMap::new();
    for run in runs {
        for c in &run.channels {
            if let Some(k) = link_of(c.quantity) {
                let n = c.quantity.label();
                let v = out.entry(k).or_default();
                if !v.contains(&n) {
                    v.push(n);
                }
            }
        }
    }
    out
}
