//! Plots (issue 24 item 17): no key (legend) over data, and key swatches drawn as their
//! series are. Checked on the SVG files the commands write (simulate's Figs 8A-11,
//! fit-friction's Fig 2, wsp-test's per-run plots): the key is the box with a black border;
//! data are the 2 px lines and the 2 px points.

mod common;

use std::path::Path;

use common::*;

/// The value of attribute `name` in an SVG element's text.
fn attr(element: &str, name: &str) -> Option<String> {
    let start = element.find(&format!(" {name}=\""))? + name.len() + 3;
    let end = start + element[start..].find('"')?;
    Some(element[start..end].to_string())
}

fn num(element: &str, name: &str) -> f64 {
    attr(element, name)
        .and_then(|v| v.parse().ok())
        .unwrap_or(f64::NAN)
}

/// The SVG's elements of one kind (`<polyline ...`), as text.
fn elements<'a>(svg: &'a str, kind: &str) -> Vec<&'a str> {
    svg.match_indices(&format!("<{kind} "))
        .map(|(i, _)| &svg[i..i + svg[i..].find('>').unwrap()])
        .collect()
}

/// What a plot's key box holds: (data points inside, swatch pieces, label rows).
fn key_check(svg: &str) -> (usize, usize, usize) {
    let key = elements(svg, "rect")
        .into_iter()
        .find(|r| {
            attr(r, "fill").as_deref() == Some("none")
                && attr(r, "stroke").as_deref() == Some("#000000")
        })
        .expect("a key box");
    let (x0, y0) = (num(key, "x"), num(key, "y"));
    let (x1, y1) = (x0 + num(key, "width"), y0 + num(key, "height"));
    let inside = |x: f64, y: f64| x >= x0 && x <= x1 && y >= y0 && y <= y1;
    let (mut data_inside, mut swatches) = (0, 0);
    for line in elements(svg, "polyline") {
        if attr(line, "stroke-width").as_deref() != Some("2") {
            continue;
        }
        let pts: Vec<(f64, f64)> = attr(line, "points")
            .unwrap_or_default()
            .split_whitespace()
            .filter_map(|p| {
                let (x, y) = p.split_once(',')?;
                Some((x.parse().ok()?, y.parse().ok()?))
            })
            .collect();
        if !pts.is_empty() && pts.iter().all(|&(x, y)| inside(x, y)) && pts.len() <= 2 {
            swatches += 1;
        } else {
            data_inside += pts.iter().filter(|&&(x, y)| inside(x, y)).count();
        }
    }
    for c in elements(svg, "circle") {
        let at = inside(num(c, "cx"), num(c, "cy"));
        match attr(c, "r").as_deref() {
            Some("2") if at => data_inside += 1,
            Some("3") if at => swatches += 1,
            _ => {}
        }
    }
    let rows = elements(svg, "text")
        .into_iter()
        .filter(|t| inside(num(t, "x"), num(t, "y")))
        .count();
    (data_inside, swatches, rows)
}

/// The key covered data in Figs 8B, 9 and 10 (and others), and its swatches were solid
/// lines for dashed and dotted series. Now the key sits where the data is not (or outside
/// the axes) in every plot, and a dotted series' swatch is dotted.
#[test]
fn no_key_covers_data_and_swatches_are_drawn_as_their_lines() {
    let dir = temp_dir("plots");
    hils_ok(&dir, args!["simulate", "--out", "sim"]);
    std::fs::write(dir.join("ft.csv"), friction_test_text(2400)).unwrap();
    hils_ok(&dir, args!["fit-friction", "ft.csv", "--report", "fit"]);
    let programme = "[tracks.ldl]\nbase = \"low\"\n[[tracks.ldl.zone]]\nstart_m = 60.0\nend_m = 120.0\nsurface = \"dry\"\n"
        .to_string()
        + &run_table("change-eb-60", 60.0, "emergency", "ldl");
    std::fs::write(dir.join("p.toml"), programme).unwrap();
    hils_ok(
        &dir,
        args!["wsp-test", "--programme", "p.toml", "--report", "wsp"],
    );
    let mut checked = 0;
    for sub in ["sim", "fit", "wsp"] {
        for f in files_in(&dir.join(sub))
            .iter()
            .filter(|f| f.ends_with(".svg"))
        {
            let svg = std::fs::read_to_string(dir.join(sub).join(f)).unwrap();
            let (data, swatches, rows) = key_check(&svg);
            assert_eq!(data, 0, "{sub}/{f}: {data} data points under the key");
            assert!(
                rows > 0 && swatches >= rows,
                "{sub}/{f}: {swatches} swatches, {rows} rows"
            );
            checked += 1;
        }
    }
    assert_eq!(checked, 5 + 2 + 3);
    // Fig 9: a solid and a dotted series: the dotted swatch is five dots, not one line.
    let svg = std::fs::read_to_string(dir.join("sim/fig9_mu_d.svg")).unwrap();
    let (_, swatches, rows) = key_check(&svg);
    assert_eq!(rows, 2);
    assert!(
        swatches >= 1 + 4,
        "{swatches} swatch pieces for a solid and a dotted line"
    );
    let _ = Path::new(".");
    std::fs::remove_dir_all(&dir).unwrap();
}
