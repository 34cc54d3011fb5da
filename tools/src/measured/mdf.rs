//! Stage 1 of reading for MDF4 files (`crate::mdf4`): the file's channels as the table
//! the CSV reader makes, so that both formats share every later check and stage.
//!
//! * Names and units: the file's channel names through the channel map (or the spec's own
//!   names), the units it stores (or the map's) converted to SI ([`super::map`]).
//! * Rates: channel groups record at their own rates. The master time grid is the time of
//!   the fastest group among those with used channels. A channel of a slower group is put
//!   on that grid at the grid time nearest each of its own samples (its value there
//!   interpolated between its own two samples around that time, so no timing shifts);
//!   the grid times between its samples stay empty: "not measured at this sample", as an
//!   empty CSV cell, counted in `missing` and said in the notes. A sample with no grid
//!   time within half a grid interval (outside the grid's times, in a gap) is left out.
//!   Nothing is invented beyond a channel's own samples and nothing is smoothed in; where
//!   a tool holds a value between samples (the replay's brake inputs), it says so itself.
//! * Every value is checked as a CSV cell is: finite or empty, within its column's limits,
//!   time strictly increasing; an error names the file, the channel (file name and spec
//!   column) and the sample.

use std::path::Path;

use super::limits::Limit;
use super::map::{ChannelMap, Resolved, resolve};
use super::table::{Cells, MeasuredError, Metadata, Table, TextColumn, file_error};
use super::units::{Quantity, to_si};
use crate::mdf4::blocks::ReadAt;
use crate::mdf4::data::{ChannelError, Chunk, ChunkError, Values};
use crate::mdf4::{Group, Mdf4};

/// A used channel: where it is in the file and which table column it fills.
struct Used {
    column: usize,
    group: usize,
    channel: usize,
}

/// An MDF4 file opened: its structure, its table (no rows yet), the used channels and
/// what reading it did that a user should know.
struct Opened<'a> {
    mdf: Mdf4<'a>,
    table: Table,
    used: Vec<Used>,
    notes: Vec<String>,
}

/// Opens an MDF4 file: its channels named and converted by `map` into a table's columns.
fn open<'a>(
    path: &Path,
    src: &'a dyn ReadAt,
    map: Option<&ChannelMap>,
) -> Result<Opened<'a>, MeasuredError> {
    let mdf = Mdf4::open(src).map_err(|e| file_error(path, e))?;
    let mut notes = Vec::new();
    let map = without_time(map, &mut notes);
    let (names, units, places) = channel_names(&mdf);
    let mut resolved = vec![Resolved {
        target: "t_s".into(),
        source: "t_s".into(),
        to_si: super::units::ToSi::IDENTITY,
        unit: String::new(),
    }];
    resolved.extend(resolve(map.as_ref(), path, &names, &units)?);
    let metadata = Metadata(mdf.metadata.clone());
    let table = Table::new(path, metadata, resolved, 0)?;
    let used: Vec<Used> = (1..table.header.len())
        .filter(|&i| !matches!(table.columns[i], Cells::Ignored))
        .map(|i| Used {
            column: i,
            group: places[i - 1].0,
            channel: places[i - 1].1,
        })
        .collect();
    check_unique(&mdf, &table, &used, &names)?;
    Ok(Opened {
        mdf,
        table,
        used,
        notes,
    })
}

/// Reads an MDF4 file into a table (columns named and converted by `map`).
pub(crate) fn read_table(
    path: &Path,
    src: &dyn ReadAt,
    map: Option<&ChannelMap>,
) -> Result<Table, MeasuredError> {
    let mut f = open(path, src, map)?;
    fill(&f.mdf, &mut f.table, &f.used, &mut f.notes)?;
    f.table.notes.extend(f.notes);
    Ok(f.table)
}

/// [`read_table`] in chunks of `chunk_rows` rows, as the CSV reader's
/// [`super::table::read_table_chunks`]: each full chunk is handed to `each` (the table
/// holding those rows only; rows in errors count from the group's first record), then
/// dropped; the table returned holds the last, partial chunk. When every used channel is
/// in one channel group (with its time master), that group's records are read chunk by
/// chunk: memory is bounded by the chunk, whatever the file's length. Used channels in
/// several groups (different rates) are put on one time grid, which needs every time of
/// the master: the file is read whole (one table returned, `each` not called), noted.
pub(crate) fn read_table_chunks(
    path: &Path,
    src: &dyn ReadAt,
    map: Option<&ChannelMap>,
    chunk_rows: usize,
    mut each: impl FnMut(&mut Table) -> Result<(), MeasuredError>,
) -> Result<Table, MeasuredError> {
    let Opened {
        mdf,
        mut table,
        used,
        mut notes,
    } = open(path, src, map)?;
    let groups = used_groups(&used);
    let &[g] = groups.as_slice() else {
        fill(&mdf, &mut table, &used, &mut notes)?;
        notes.push(format!(
            "the channels used are in {} channel groups (at their own rates): the file was \
             read whole to put them on one time grid, not in row chunks, so its memory grows \
             with its length (docs/mdf4.md)",
            groups.len()
        ));
        table.notes.extend(notes);
        return Ok(table);
    };
    table.notes.extend(notes);
    let mine: Vec<&Used> = used.iter().collect();
    let wanted: Vec<usize> = mine.iter().map(|u| u.channel).collect();
    table.labels[0] = format!("t_s (the time of {})", mdf.groups[g].label());
    let mut first = None;
    let last = mdf
        .read_group_chunks(g, &wanted, chunk_rows, |chunk| {
            take_chunk(&mdf, &mut table, &mine, g, chunk, &mut first)?;
            table.hand_on(Some(0), &mut each)
        })
        .map_err(|e| match e {
            ChunkError::File(e) => channel_err(&mdf, &table, &mine, g, e),
            ChunkError::Each(e) => e,
        })?;
    take_chunk(&mdf, &mut table, &mine, g, last, &mut first)?;
    Ok(table)
}

/// Puts a chunk of group `g`'s records (the `mine` channels) into the table, checking
/// every time and value (`first`: the group's first time, for the span check).
fn take_chunk(
    mdf: &Mdf4,
    table: &mut Table,
    mine: &[&Used],
    g: usize,
    (mut time_s, values): Chunk,
    first: &mut Option<f64>,
) -> Result<(), MeasuredError> {
    time_in_s(mdf, table, g, &mut time_s)?;
    put_time(table, &time_s, first)?;
    for (u, v) in mine.iter().zip(values) {
        store(table, u.column, v)?;
    }
    Ok(())
}

/// The channel groups of the used channels, in order, each once.
fn used_groups(used: &[Used]) -> Vec<usize> {
    let mut groups: Vec<usize> = used.iter().map(|u| u.group).collect();
    groups.sort_unstable();
    groups.dedup();
    groups
}

/// The map without a `t_s` entry (the time is the groups' master channels), noted.
fn without_time(map: Option<&ChannelMap>, notes: &mut Vec<String>) -> Option<ChannelMap> {
    let mut map = map.cloned()?;
    if let Some(src) = map.channels.remove("t_s") {
        notes.push(format!(
            "channel map: `t_s` from `{}` not used: in an MDF4 file the time is each channel \
             group's master channel",
            src.from
        ));
    }
    Some(map)
}

/// The names of the file's data channels (masters and VLSD groups left out; a name in
/// several groups once, at its first place), their units and places (group, channel).
fn channel_names(mdf: &Mdf4) -> (Vec<String>, Vec<String>, Vec<(usize, usize)>) {
    let (mut names, mut units, mut places) = (Vec::new(), Vec::new(), Vec::new());
    for (g, group) in mdf.groups.iter().enumerate() {
        if group.is_vlsd() {
            continue;
        }
        for (c, ch) in group.channels.iter().enumerate() {
            if ch.is_master() || names.contains(&ch.name) {
                continue;
            }
            names.push(ch.name.clone());
            units.push(ch.unit.clone());
            places.push((g, c));
        }
    }
    (names, units, places)
}

/// A used channel whose name is in several groups is ambiguous: an error naming them.
fn check_unique(
    mdf: &Mdf4,
    table: &Table,
    used: &[Used],
    names: &[String],
) -> Result<(), MeasuredError> {
    for u in used {
        let name = &names[u.column - 1];
        let groups: Vec<String> = mdf
            .groups
            .iter()
            .filter(|g| {
                !g.is_vlsd() && g.channels.iter().any(|c| !c.is_master() && c.name == *name)
            })
            .map(Group::label)
            .collect();
        if groups.len() > 1 {
            return Err(MeasuredError {
                column: table.labels[u.column].clone(),
                ..file_error(
                    &table.path,
                    format!(
                        "channel `{name}` is in {}: which one is meant?",
                        groups.join(" and ")
                    ),
                )
            });
        }
    }
    Ok(())
}

/// A group's times (s) and its used channels' values.
struct GroupData {
    group: usize,
    time_s: Vec<f64>,
    /// (table column, values) of the group's used channels.
    columns: Vec<(usize, Values)>,
}

/// Reads the used groups, picks the master grid, places every channel on it and checks
/// every value into the table.
fn fill(
    mdf: &Mdf4,
    table: &mut Table,
    used: &[Used],
    notes: &mut Vec<String>,
) -> Result<(), MeasuredError> {
    let groups = used_groups(used);
    let mut data = Vec::with_capacity(groups.len());
    for &g in &groups {
        data.push(read_group(mdf, table, used, g)?);
    }
    let Some(master) = (0..data.len()).max_by(|&a, &b| rate(&data[a]).total_cmp(&rate(&data[b])))
    else {
        return Err(file_error(
            &table.path,
            "no channel of the file is a spec column",
        ));
    };
    let grid = std::mem::take(&mut data[master].time_s);
    let grid_label = mdf.groups[data[master].group].label();
    table.labels[0] = format!("t_s (the time of {grid_label})");
    put_time(table, &grid, &mut None)?;
    for (i, d) in data.into_iter().enumerate() {
        let own_grid = i == master;
        for (col, values) in d.columns {
            let values = if own_grid {
                values
            } else {
                let (v, note) = place(&grid, &d.time_s, values, &table.labels[col]);
                notes.push(note);
                v
            };
            store(table, col, values)?;
        }
    }
    Ok(())
}

/// Puts the times of the table's rows (`grid`, s) in its time column, checking each
/// (`first`: the log's first time, for the span check).
fn put_time(table: &mut Table, grid: &[f64], first: &mut Option<f64>) -> Result<(), MeasuredError> {
    table.lines = vec![0; grid.len()];
    for (k, &t) in grid.iter().enumerate() {
        if let Cells::Numeric(v, limit) = &mut table.columns[0] {
            v.push(t);
            let limit = *limit;
            table.check_value(k, 0, t, limit)?;
        }
        table.check_time(k, 0, first)?;
    }
    Ok(())
}

/// Samples per second of a group (0 for fewer than two samples).
fn rate(d: &GroupData) -> f64 {
    match (d.time_s.first(), d.time_s.last()) {
        (Some(a), Some(b)) if b > a => (d.time_s.len() - 1) as f64 / (b - a),
        _ => 0.0,
    }
}

/// Reads group `g`: its time (checked, in s) and its used channels.
fn read_group(
    mdf: &Mdf4,
    table: &Table,
    used: &[Used],
    g: usize,
) -> Result<GroupData, MeasuredError> {
    let mine: Vec<&Used> = used.iter().filter(|u| u.group == g).collect();
    let wanted: Vec<usize> = mine.iter().map(|u| u.channel).collect();
    let (mut time_s, values) = mdf
        .read_group(g, &wanted)
        .map_err(|e| channel_err(mdf, table, &mine, g, e))?;
    time_in_s(mdf, table, g, &mut time_s)?;
    Ok(GroupData {
        group: g,
        time_s,
        columns: mine.iter().map(|u| u.column).zip(values).collect(),
    })
}

/// An error of the MDF4 reader about a channel of group `g` (one of `mine`), named as
/// the file and the map name it.
fn channel_err(
    mdf: &Mdf4,
    table: &Table,
    mine: &[&Used],
    g: usize,
    e: ChannelError,
) -> MeasuredError {
    let column = mine
        .iter()
        .find(|u| mdf.groups[g].channels[u.channel].name == e.channel)
        .map_or(e.channel.clone(), |u| table.labels[u.column].clone());
    MeasuredError {
        column,
        ..file_error(&table.path, e.message)
    }
}

/// Converts group `g`'s times (its records after the table's `rows_before`) to s and
/// checks that they increase (from the table's `time_before`, the chunk before).
fn time_in_s(mdf: &Mdf4, table: &Table, g: usize, time_s: &mut [f64]) -> Result<(), MeasuredError> {
    let group = &mdf.groups[g];
    if let Some(m) = group.time_master() {
        let unit = &group.channels[m].unit;
        if !unit.is_empty() && unit != "s" {
            let c = to_si(Quantity::Time, unit).map_err(|e| MeasuredError {
                column: group.channels[m].name.clone(),
                ..file_error(
                    &table.path,
                    format!("time master of {}: {e}", group.label()),
                )
            })?;
            time_s.iter_mut().for_each(|t| *t = c.apply(*t));
        }
    }
    let before = |k: usize| match k {
        0 => table.time_before,
        _ => Some(time_s[k - 1]),
    };
    let Some(k) = (0..time_s.len()).find(|&k| before(k).is_some_and(|b| !(time_s[k] > b))) else {
        return Ok(());
    };
    Err(MeasuredError {
        column: "t_s".into(),
        ..file_error(
            &table.path,
            format!(
                "{}: its time does not increase at record {} ({} after {})",
                group.label(),
                table.rows_before + k + 1,
                time_s[k],
                before(k).unwrap_or(f64::NAN)
            ),
        )
    })
}

/// Puts a channel sampled at `t` on `grid`: each own sample at the nearest grid time, its
/// value interpolated between its own samples to that time; other grid times empty. With
/// the note that says so (and how many samples had no grid time of their own).
fn place(grid: &[f64], t: &[f64], values: Values, label: &str) -> (Values, String) {
    let n = grid.len();
    let mut slot_of = Vec::with_capacity(t.len());
    let (mut shared, mut outside) = (0usize, 0usize);
    let mut last_slot = None;
    for &ti in t {
        let Some(k) = nearest_grid_time(grid, ti) else {
            outside += 1;
            slot_of.push(None);
            continue;
        };
        if last_slot == Some(k) {
            shared += 1;
            slot_of.push(None);
        } else {
            slot_of.push(Some(k));
            last_slot = Some(k);
        }
    }
    let out = match values {
        Values::Num(v) => {
            let mut out = vec![f64::NAN; n];
            for (i, slot) in slot_of.iter().enumerate() {
                if let Some(k) = *slot {
                    out[k] = interpolate_at(t, &v, i, grid[k]);
                }
            }
            Values::Num(out)
        }
        Values::Text(v) => {
            let mut texts = v.values.clone();
            let empty = texts.iter().position(|t| t.is_empty()).unwrap_or_else(|| {
                texts.push(String::new());
                texts.len() - 1
            });
            let mut codes = vec![empty as u32; n];
            for (i, slot) in slot_of.iter().enumerate() {
                if let Some(k) = *slot {
                    codes[k] = v.codes[i];
                }
            }
            Values::Text(TextColumn {
                values: texts,
                codes,
            })
        }
    };
    let own_hz = if t.len() > 1 {
        (t.len() - 1) as f64 / (t[t.len() - 1] - t[0])
    } else {
        0.0
    };
    let grid_hz = if n > 1 {
        (n - 1) as f64 / (grid[n - 1] - grid[0])
    } else {
        0.0
    };
    let mut note = format!(
        "{label}: {} samples at {} Hz put on the {} Hz master grid at the nearest grid times \
         (values interpolated between its own samples to those times); the grid times between \
         them are empty (not measured, not invented)",
        t.len(),
        crate::figures::round_sig(own_hz, 3),
        crate::figures::round_sig(grid_hz, 3)
    );
    if shared > 0 {
        note +=
            &format!("; {shared} samples share a grid time with an earlier one and are left out");
    }
    if outside > 0 {
        note += &format!(
            "; {outside} of them lie outside the master grid's times (before its start, after \
             its end or in a gap of it) and are left out"
        );
    }
    (out, note)
}

/// The grid time nearest `ti`, if within half the grid's local interval (the shorter of
/// the two around it): a sample before the grid's start, after its end or in a gap of it
/// has none (its value is not moved to a grid time it was not measured near).
fn nearest_grid_time(grid: &[f64], ti: f64) -> Option<usize> {
    let n = grid.len();
    let k = grid.partition_point(|&g| g < ti);
    let k = match (k.checked_sub(1), grid.get(k)) {
        (Some(a), Some(&b)) if ti - grid[a] <= b - ti => a,
        (Some(a), None) => a,
        _ => k.min(n.checked_sub(1)?),
    };
    let before = k.checked_sub(1).map(|a| grid[k] - grid[a]);
    let after = grid.get(k + 1).map(|b| b - grid[k]);
    let interval = match (before, after) {
        (Some(x), Some(y)) => x.min(y),
        (Some(x), None) | (None, Some(x)) => x,
        (None, None) => 0.0,
    };
    ((ti - grid[k]).abs() <= 0.5 * interval).then_some(k)
}

/// Channel value at `at` near own sample `i`: linear between the own samples around it.
fn interpolate_at(t: &[f64], v: &[f64], i: usize, at: f64) -> f64 {
    let (j0, j1) = if at >= t[i] {
        (i, (i + 1).min(t.len() - 1))
    } else {
        (i.saturating_sub(1), i)
    };
    // At its own time, or next to an invalid sample: its own value (shifted by at most
    // half a grid interval).
    if at == t[i] || j0 == j1 || t[j1] == t[j0] || v[j0].is_nan() || v[j1].is_nan() {
        return v[i];
    }
    v[j0] + (v[j1] - v[j0]) * (at - t[j0]) / (t[j1] - t[j0])
}

/// Converts a channel's values to SI, checks each into column `col` of the table.
fn store(table: &mut Table, col: usize, values: Values) -> Result<(), MeasuredError> {
    match (&table.columns[col], values) {
        (Cells::Numeric(_, limit), Values::Num(mut v)) => {
            let limit: Limit = *limit;
            let conv = table.to_si[col];
            // Converted in place (one copy of the column).
            for (r, x) in v.iter_mut().enumerate() {
                if !x.is_nan() {
                    *x = conv.apply(*x);
                    table.check_value(r, col, *x, limit)?;
                }
            }
            v.shrink_to_fit();
            table.columns[col] = Cells::Numeric(v, limit);
        }
        (Cells::Numeric(..), Values::Text(_)) => {
            return Err(MeasuredError {
                column: table.labels[col].clone(),
                ..file_error(
                    &table.path,
                    "the channel holds texts; this column needs numbers",
                )
            });
        }
        (Cells::Text(_), Values::Text(t)) => table.columns[col] = Cells::Text(t),
        (Cells::Text(_), values) => {
            let mut text = TextColumn::default();
            match values {
                Values::Text(_) => {}
                Values::Num(v) => v.iter().for_each(|x| {
                    text.push(&if x.is_nan() {
                        String::new()
                    } else {
                        format!("{x}")
                    })
                }),
            }
            table.columns[col] = Cells::Text(text);
        }
        (Cells::Ignored, _) => {}
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn placed(grid: &[f64], t: &[f64], v: &[f64]) -> (Vec<f64>, String) {
        match place(grid, t, Values::Num(v.to_vec()), "x") {
            (Values::Num(out), note) => (out, note),
            _ => unreachable!(),
        }
    }

    /// A slow channel that starts before and ends after the master grid: its samples
    /// outside the grid's times are left out (said in the note), never extrapolated to the
    /// grid's ends, and its own samples at grid times keep their values.
    #[test]
    fn samples_outside_the_grid_are_left_out_not_extrapolated() {
        let grid: Vec<f64> = (0..=1000).map(|k| 1.0 + k as f64 * 1e-3).collect();
        let t = [0.0, 0.5, 1.0, 1.5, 2.0, 2.5];
        let v = [0.0, 7.0, 10.0, 15.0, 20.0, 40.0];
        let (out, note) = placed(&grid, &t, &v);
        let filled: Vec<(usize, f64)> = out
            .iter()
            .enumerate()
            .filter(|(_, x)| !x.is_nan())
            .map(|(k, &x)| (k, x))
            .collect();
        assert_eq!(filled, vec![(0, 10.0), (500, 15.0), (1000, 20.0)]);
        assert!(note.contains("3 of them lie outside"), "{note}");
    }

    /// A master grid with a gap (the fast group paused): a slow sample in the gap has no
    /// grid time near it and is left out, not put at the gap's edge.
    #[test]
    fn samples_in_a_gap_of_the_grid_are_left_out() {
        let mut grid: Vec<f64> = (0..=100).map(|k| k as f64 * 1e-3).collect();
        grid.extend((0..=100).map(|k| 5.0 + k as f64 * 1e-3));
        let t = [0.05, 2.5, 5.05];
        let v = [1.0, 2.0, 3.0];
        let (out, _) = placed(&grid, &t, &v);
        let filled: Vec<f64> = out.iter().copied().filter(|x| !x.is_nan()).collect();
        assert_eq!(filled, vec![1.0, 3.0]);
    }
}
