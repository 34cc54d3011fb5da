//! Reading measured data: run logs and brake-dynamometer friction tests, in the formats of
//! `spec/measured-data.md`, one module per stage and format: [`table`] (CSV cells,
//! metadata, errors, checks), [`run_log`] (section 1) and [`friction_test`] (section 2).
//! Column names come from the one schema, `hils_sil::record`.
//!
//! Both kinds are CSV files with `# key: value` metadata lines before one header row. Units
//! are part of every column name, columns come in any order, unknown columns are kept (by
//! name) and ignored.
//!
//! # Error behaviour (the spec's "Bad input")
//!
//! * A missing required column, a non-numeric cell in a numeric column, a time that does not
//!   increase, a NaN/inf cell, or a physically impossible value (negative pressure, force,
//!   speed or load beyond noise) is an error that names the file, the line, the data row and
//!   the column ([`MeasuredError`]).
//! * An empty cell means "not measured at this sample": it is kept as missing (`NaN` in the
//!   channel), never invented; every column's count of missing cells is in
//!   [`RunLog::missing`], and every tool that skips or repairs something says how many and
//!   why ([`RunLog::notes`], [`FrictionTest::notes`]).
//! * Small negative readings within the noise band (see [`negative_tolerance`]) are kept as
//!   measured (a zero-centred sensor reads slightly negative at rest).

pub mod friction_test;
pub mod run_log;
pub mod table;

use std::path::Path;

pub use friction_test::{FrictionTest, RELEASED_SHARE};
pub use run_log::{PerWheelset, RunLog};
pub use table::{MeasuredError, Metadata, negative_tolerance, noise_sigma};

use hils_sil::record::{friction_test as ft, run_log as rl};
use table::{file_error, parse_table};

/// Either kind of measured file.
#[derive(Clone, Debug)]
pub enum Measured {
    Run(RunLog),
    Friction(FrictionTest),
}

/// Reads a measured file of either kind (decided by its columns: `v_friction_mps` makes a
/// friction test, `v_ref_mps` a run log).
pub fn read(path: &Path) -> Result<Measured, MeasuredError> {
    let text =
        std::fs::read_to_string(path).map_err(|e| file_error(path, format!("cannot read: {e}")))?;
    parse(path, &text)
}

/// Parses the text of a measured file of either kind (`path` names it in messages).
pub fn parse(path: &Path, text: &str) -> Result<Measured, MeasuredError> {
    let table = parse_table(path, text)?;
    if table.has(ft::V_FRICTION.name(0)) {
        friction_test::from_table(table).map(Measured::Friction)
    } else if table.has(rl::V_REF.name(0)) || table.has(rl::OMEGA.name(0)) {
        run_log::from_table(table).map(Measured::Run)
    } else {
        Err(table.err(
            table.header_line,
            0,
            "",
            "neither a run log (needs `t_s`, `v_ref_mps`, `omega1_radps`..) nor a friction test \
             (needs `v_friction_mps`, `t_disc_c`, `mu` or `f_clamp_n` + `f_friction_n`)",
        ))
    }
}

impl Measured {
    /// The file as the kind the caller wants (`pick`), or the error naming what it is.
    fn expect<T>(
        self,
        path: &Path,
        pick: fn(Measured) -> Option<T>,
        otherwise: &str,
    ) -> Result<T, MeasuredError> {
        pick(self).ok_or_else(|| file_error(path, otherwise))
    }

    fn run(self) -> Option<RunLog> {
        match self {
            Measured::Run(r) => Some(r),
            Measured::Friction(_) => None,
        }
    }

    fn friction(self) -> Option<FrictionTest> {
        match self {
            Measured::Friction(f) => Some(f),
            Measured::Run(_) => None,
        }
    }
}

/// The message for a friction test read as a run log, and the other way round.
const NOT_A_RUN_LOG: &str = "is a friction test (has `v_friction_mps`), not a run log";
const NOT_A_FRICTION_TEST: &str = "is a run log, not a friction test (needs `v_friction_mps`)";

/// Reads a run log (an error if the file is a friction test).
pub fn read_run_log(path: &Path) -> Result<RunLog, MeasuredError> {
    read(path)?.expect(path, Measured::run, NOT_A_RUN_LOG)
}

/// Parses a run log's text.
pub fn parse_run_log(path: &Path, text: &str) -> Result<RunLog, MeasuredError> {
    parse(path, text)?.expect(path, Measured::run, NOT_A_RUN_LOG)
}

/// Reads a friction test (an error if the file is a run log).
pub fn read_friction_test(path: &Path) -> Result<FrictionTest, MeasuredError> {
    read(path)?.expect(path, Measured::friction, NOT_A_FRICTION_TEST)
}

/// Parses a friction test's text.
pub fn parse_friction_test(path: &Path, text: &str) -> Result<FrictionTest, MeasuredError> {
    parse(path, text)?.expect(path, Measured::friction, NOT_A_FRICTION_TEST)
}

#[cfg(test)]
mod tests {
    use super::*;
    use hils_plant::Rail;
    fn p() -> &'static Path {
        Path::new("x.csv")
    }

    const GOOD: &str = "# source: test\n# rail: dry\n# initial_speed_kmh: 120\n\
t_s,v_ref_mps,omega1_radps,omega2_radps,omega3_radps,omega4_radps,p_cyl1_pa,p_cyl2_pa,p_cyl3_pa,p_cyl4_pa,extra\n\
0.0,33.3,77.5,77.5,77.5,77.5,0,0,0,0,a\n\
0.01,33.2,77.2,77.2,77.2,77.2,1000,1000,,1000,b\n";

    #[test]
    fn reads_metadata_columns_and_empty_cells() {
        let r = parse_run_log(p(), GOOD).unwrap();
        assert_eq!(r.len(), 2);
        assert_eq!(r.rail, Some(Rail::Dry));
        assert_eq!(r.metadata.get("source"), Some("test"));
        assert_eq!(r.unknown_columns, vec!["extra".to_string()]);
        assert!(r.p_cyl_pa[2].as_ref().unwrap()[1].is_nan());
        assert_eq!(r.missing.get("p_cyl3_pa"), Some(&1));
        assert_eq!(r.notes.len(), 1);
    }

    #[test]
    fn errors_name_line_row_and_column() {
        let bad = GOOD.replace("1000,1000,,1000", "1000,abc,,1000");
        let e = parse_run_log(p(), &bad).unwrap_err();
        assert_eq!((e.line, e.row, e.column.as_str()), (6, 2, "p_cyl2_pa"));
        let bad = GOOD.replace("0.01,33.2", "0.0,33.2");
        let e = parse_run_log(p(), &bad).unwrap_err();
        assert_eq!((e.row, e.column.as_str()), (2, "t_s"));
        let bad = GOOD.replace("1000,1000,,1000", "1000,-90000,,1000");
        let e = parse_run_log(p(), &bad).unwrap_err();
        assert_eq!(e.column, "p_cyl2_pa");
        let bad = GOOD.replace("33.2,77.2", "NaN,77.2");
        let e = parse_run_log(p(), &bad).unwrap_err();
        assert_eq!(e.column, "v_ref_mps");
        let bad = GOOD.replace(",omega4_radps", ",omega9_radps");
        let e = parse_run_log(p(), &bad).unwrap_err();
        assert_eq!(e.column, "omega4_radps");
        assert!(e.to_string().contains("x.csv"));
    }

    #[test]
    fn friction_test_from_forces_skips_released_rows_with_count() {
        let text = "t_s,v_friction_mps,t_disc_c,f_clamp_n,f_friction_n\n0,20,0,0,0\n0.1,19.9,1,10000,4000\n0.2,19.8,2,10000,\n";
        let f = parse_friction_test(p(), text).unwrap();
        assert_eq!(f.mu, vec![0.4]);
        assert_eq!(f.skipped, 2);
        assert_eq!(f.notes.len(), 2);
    }
}
