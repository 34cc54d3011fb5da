//! The plausible range of every measured column: ONE table, read by the reader (each value
//! is checked against its column's absolute limits as it is read) and printed into the
//! spec's companion doc `docs/measured-data-limits.md` (a test keeps the doc equal to
//! [`markdown`]).
//!
//! The limits are absolute physical bounds, never relative to other values in the file (an
//! outlier cannot widen them). The small negative lower bounds are the noise band of a
//! zero-centred sensor at rest: readings down to them are kept as measured; below them, or
//! above the upper bound, a value is an error naming file, line, row and column.

use hils_sil::record::Channel;
use hils_sil::record::{friction_test as ft, run_log as rl};

/// Longest span of a log's time column, s: a braking run or a dynamometer test lasts
/// minutes; a longer span is a unit error (milliseconds logged as seconds) and would ask
/// a replay for unbounded memory.
pub const MAX_SPAN_S: f64 = 3600.0;

/// The plausible range of one channel's columns (every wheelset alike).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Limit {
    pub channel: Channel,
    /// Lowest plausible value (in the column's unit).
    pub min: f64,
    /// Highest plausible value.
    pub max: f64,
    /// Why these bounds (for the doc).
    pub basis: &'static str,
}

impl Limit {
    /// Whether `x` (finite) lies within the range.
    pub fn contains(&self, x: f64) -> bool {
        x >= self.min && x <= self.max
    }
}

const fn limit(channel: Channel, min: f64, max: f64, basis: &'static str) -> Limit {
    Limit {
        channel,
        min,
        max,
        basis,
    }
}

/// The run-log columns (spec section 1).
pub const RUN_LOG: [Limit; 11] = [
    limit(
        rl::T,
        -MAX_SPAN_S,
        86_400.0,
        "within a day; span at most 3600 s",
    ),
    limit(
        rl::V_REF,
        -1.0,
        140.0,
        "0 to 500 km/h; -1 m/s noise at rest",
    ),
    limit(
        rl::OMEGA,
        -3.0,
        450.0,
        "500 km/h on a 0.31 m wheel; noise at rest",
    ),
    limit(
        rl::P_CYL,
        -20e3,
        2e6,
        "brake cylinders work below 1 MPa; -20 kPa noise",
    ),
    limit(
        rl::F_CLAMP,
        -5e3,
        2e5,
        "pad force of a disc brake; -5 kN load-cell noise",
    ),
    limit(
        rl::F_BRAKE,
        -2e5,
        2e5,
        "tangential brake force, either sign",
    ),
    limit(
        rl::T_DISC,
        -60.0,
        1200.0,
        "disc temperature, ambient to red heat",
    ),
    limit(rl::Q, -5e3, 5e5, "axle load up to 50 t; -5 kN noise"),
    limit(rl::WSP, 0.0, 1.0, "valve flag, 0 or 1"),
    limit(rl::HOLD, 0.0, 1.0, "valve flag, 0 or 1"),
    limit(rl::A_X, -30.0, 30.0, "about 3 g"),
];

/// The friction-test columns (spec section 2).
pub const FRICTION_TEST: [Limit; 6] = [
    limit(
        ft::T,
        -MAX_SPAN_S,
        86_400.0,
        "within a day; span at most 3600 s",
    ),
    limit(
        ft::V_FRICTION,
        -1.0,
        140.0,
        "0 to 500 km/h; -1 m/s noise at rest",
    ),
    limit(
        ft::T_DISC,
        -60.0,
        1200.0,
        "disc temperature, ambient to red heat",
    ),
    limit(ft::MU, 0.0, 2.0, "friction coefficient"),
    limit(ft::F_CLAMP, -5e3, 2e5, "pad force; -5 kN load-cell noise"),
    limit(
        ft::F_FRICTION,
        -5e3,
        4e5,
        "friction force, at most 2 x the clamp force",
    ),
];

/// The limit of a column among `table` (by its exact name).
pub fn find(table: &[Limit], column: &str) -> Option<Limit> {
    let channels: Vec<Channel> = table.iter().map(|l| l.channel).collect();
    let (c, _) = Channel::find(&channels, column)?;
    table.iter().find(|l| l.channel == c).copied()
}

/// The plausible range of a run-log or friction-test column by name (run log first).
pub fn plausible_range(column: &str) -> Option<std::ops::RangeInclusive<f64>> {
    find(&RUN_LOG, column)
        .or_else(|| find(&FRICTION_TEST, column))
        .map(|l| l.min..=l.max)
}

/// The doc's table (the text between the markers of `docs/measured-data-limits.md`).
pub fn markdown() -> String {
    let mut s = String::new();
    for (title, table) in [
        ("Run log (section 1)", &RUN_LOG[..]),
        ("Friction test (section 2)", &FRICTION_TEST[..]),
    ] {
        s += &format!("\n### {title}\n\n| column | min | max | basis |\n|---|---|---|---|\n");
        for l in table {
            let name = l.channel.name(0).to_string();
            let name = if l.channel.per_wheelset {
                name.replacen('1', "N", 1)
            } else {
                name
            };
            s += &format!("| `{name}` | {} | {} | {} |\n", l.min, l.max, l.basis);
        }
    }
    s
}
