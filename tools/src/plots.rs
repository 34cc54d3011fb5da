//! Line and scatter charts as SVG (plotters), shared by every command that draws.
//!
//! # The key (legend)
//!
//! Every chart draws its key through one mechanism ([`Chart::draw`]), so that no key covers
//! data (issue 24 item 17):
//!
//! * Its size follows from its entries (one row per series, then the [`Chart::shade_key`]
//!   rows).
//! * It goes where the data is not: candidate places inside the plot (the four corners, the
//!   middles of the edges, then a grid over the plot) are tried in that order, and the first
//!   whose box (with a margin) holds no point of any series and is crossed by no line
//!   segment is taken ([`free_place`]). When every place inside is taken by data, the key
//!   goes outside the axes, right of the plot, which narrows to make room.
//! * Its swatches are drawn as the series are: solid, dashed (10 on, 6 off) and dotted
//!   (3 on, 4 off) lines, points as points, shading as a shaded square.

use std::path::Path;

use anyhow::{Result, anyhow};
use plotters::coord::Shift;
use plotters::prelude::*;

/// How a series is drawn.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Style {
    Solid,
    Dashed,
    Dotted,
    Points,
}

/// One named series of (x, y) points.
#[derive(Clone, Debug)]
pub struct Series {
    pub name: String,
    pub points: Vec<(f64, f64)>,
    pub style: Style,
    /// Index into the palette.
    pub color: usize,
}

impl Series {
    pub fn new(
        name: impl Into<String>,
        points: Vec<(f64, f64)>,
        style: Style,
        color: usize,
    ) -> Self {
        Self {
            name: name.into(),
            points,
            style,
            color,
        }
    }
}

/// A chart: title, axis labels and series.
#[derive(Clone, Debug, Default)]
pub struct Chart {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub series: Vec<Series>,
    /// Fixed axis ranges (None: from the data).
    pub x_range: Option<(f64, f64)>,
    pub y_range: Option<(f64, f64)>,
    /// Shaded x intervals (from, to, palette index), drawn under the series.
    pub shades: Vec<(f64, f64, usize)>,
    /// Key rows for the shading: (label, palette index), after the series' rows.
    pub shade_key: Vec<(String, usize)>,
}

pub const PALETTE: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(23, 190, 207),
    RGBColor(127, 127, 127),
    RGBColor(0, 0, 0),
];

/// The opacity of shading (under the series, and in its key swatch).
const SHADE_OPACITY: f64 = 0.15;
/// Canvas size, px.
const SIZE: (u32, u32) = (900, 560);
/// Key text size, px, row height, swatch length and padding, px.
const KEY_FONT_PX: u32 = 14;
const KEY_ROW_PX: i32 = 20;
const KEY_SWATCH_PX: i32 = 30;
const KEY_PAD_PX: i32 = 8;
/// Clearance kept between the key and any data, px.
const KEY_CLEARANCE_PX: i32 = 6;
/// Points drawn per series at most (larger series are thinned evenly).
const MAX_POINTS: usize = 4000;
/// Radius of a data point and of a key swatch's point, px.
const POINT_PX: i32 = 2;
const SWATCH_POINT_PX: i32 = 3;

fn range_of(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values.filter(|v| v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    if hi - lo < 1e-12 {
        let pad = lo.abs().max(1.0) * 0.05;
        return (lo - pad, hi + pad);
    }
    let pad = 0.04 * (hi - lo);
    (lo - pad, hi + pad)
}

/// Keeps at most `max` points of a series (evenly), so large runs give small files.
pub fn thin(points: &[(f64, f64)], max: usize) -> Vec<(f64, f64)> {
    if points.len() <= max || max < 2 {
        return points.to_vec();
    }
    let stride = points.len().div_ceil(max);
    let mut v: Vec<(f64, f64)> = points.iter().step_by(stride).copied().collect();
    if let Some(last) = points.last() {
        if v.last() != Some(last) {
            v.push(*last);
        }
    }
    v
}

/// A box in pixels: left, top, right, bottom.
pub type PxBox = (i32, i32, i32, i32);

/// What the data occupies on the canvas: each series' points in pixels, joined by lines
/// unless drawn as points.
pub struct Occupied {
    pub series: Vec<(Vec<(i32, i32)>, bool)>,
}

impl Occupied {
    /// Whether any point lies in `b` or any line segment crosses it.
    pub fn hits(&self, b: PxBox) -> bool {
        let inside = |&(x, y): &(i32, i32)| x >= b.0 && x <= b.2 && y >= b.1 && y <= b.3;
        self.series.iter().any(|(pts, joined)| {
            pts.iter().any(inside)
                || (*joined && pts.windows(2).any(|w| segment_crosses(w[0], w[1], b)))
        })
    }
}

/// Whether the segment a-b crosses the box `b` (Liang-Barsky clipping).
fn segment_crosses(a: (i32, i32), c: (i32, i32), b: PxBox) -> bool {
    let (x0, y0) = (a.0 as f64, a.1 as f64);
    let (dx, dy) = ((c.0 - a.0) as f64, (c.1 - a.1) as f64);
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for (p, q) in [
        (-dx, x0 - b.0 as f64),
        (dx, b.2 as f64 - x0),
        (-dy, y0 - b.1 as f64),
        (dy, b.3 as f64 - y0),
    ] {
        if p == 0.0 {
            if q < 0.0 {
                return false;
            }
        } else {
            let r = q / p;
            if p < 0.0 {
                t0 = t0.max(r);
            } else {
                t1 = t1.min(r);
            }
            if t0 > t1 {
                return false;
            }
        }
    }
    true
}

/// The first place (top-left corner) for a key of `size` inside `plot` whose box, grown by
/// the clearance, meets no data: the corners (upper right, upper left, lower right, lower
/// left), the middles of the edges, then a grid over the plot (module doc).
pub fn free_place(occupied: &Occupied, plot: PxBox, size: (i32, i32)) -> Option<(i32, i32)> {
    let inset = 10;
    let (w, h) = size;
    let (l, t, r, b) = (
        plot.0 + inset,
        plot.1 + inset,
        plot.2 - inset - w,
        plot.3 - inset - h,
    );
    if r < l || b < t {
        return None;
    }
    let (cx, cy) = ((l + r) / 2, (t + b) / 2);
    let mut places = vec![
        (r, t),
        (l, t),
        (r, b),
        (l, b),
        (cx, t),
        (cx, b),
        (r, cy),
        (l, cy),
    ];
    let step = 16;
    for y in (t..=b).step_by(step) {
        for x in (l..=r).rev().step_by(step) {
            places.push((x, y));
        }
    }
    let c = KEY_CLEARANCE_PX;
    places
        .into_iter()
        .find(|&(x, y)| !occupied.hits((x - c, y - c, x + w + c, y + h + c)))
}

/// One row of the key: its label and how its swatch is drawn.
enum Swatch {
    Line(Style, RGBColor),
    Shade(RGBColor),
}

/// Error of drawing on a backend.
type DrawResult<DB> =
    std::result::Result<(), DrawingAreaErrorKind<<DB as DrawingBackend>::ErrorType>>;

impl Chart {
    pub fn new(title: &str, x_label: &str, y_label: &str) -> Self {
        Self {
            title: title.into(),
            x_label: x_label.into(),
            y_label: y_label.into(),
            ..Self::default()
        }
    }

    pub fn with(mut self, s: Series) -> Self {
        self.series.push(s);
        self
    }

    /// The chart as SVG text.
    pub fn svg(&self) -> Result<String> {
        let mut text = String::new();
        {
            let root = SVGBackend::with_string(&mut text, SIZE).into_drawing_area();
            self.draw(&root)
                .map_err(|e| anyhow!("cannot draw `{}`: {e}", self.title))?;
            root.present()
                .map_err(|e| anyhow!("cannot draw `{}`: {e}", self.title))?;
        }
        Ok(text)
    }

    /// Draws the chart to an SVG file (written atomically, `crate::outputs`).
    pub fn save_svg(&self, path: &Path) -> Result<()> {
        crate::outputs::write_file(path, self.svg()?)
    }

    /// The axis ranges: fixed, or from the data.
    fn ranges(&self) -> ((f64, f64), (f64, f64)) {
        let all = |f: fn(&(f64, f64)) -> f64| {
            range_of(self.series.iter().flat_map(move |s| s.points.iter().map(f)))
        };
        (
            self.x_range.unwrap_or_else(|| all(|p| p.0)),
            self.y_range.unwrap_or_else(|| all(|p| p.1)),
        )
    }

    /// The key's rows.
    fn key_rows(&self) -> Vec<(&str, Swatch)> {
        let color = |c: usize| PALETTE[c % PALETTE.len()];
        self.series
            .iter()
            .map(|s| (s.name.as_str(), Swatch::Line(s.style, color(s.color))))
            .chain(
                self.shade_key
                    .iter()
                    .map(|(l, c)| (l.as_str(), Swatch::Shade(color(*c)))),
            )
            .collect()
    }

    /// The key's size, px (a conservative estimate of the text width).
    fn key_size(&self) -> (i32, i32) {
        let rows = self.key_rows();
        let chars = rows
            .iter()
            .map(|(l, _)| l.chars().count())
            .max()
            .unwrap_or(0);
        // plotters draws text at 1/1.24 of its size; 0.6 em per character is generous for
        // a sans-serif face.
        let em = KEY_FONT_PX as f64 / 1.24;
        let text_px = (0.6 * em * chars as f64).ceil() as i32;
        (
            2 * KEY_PAD_PX + KEY_SWATCH_PX + 8 + text_px,
            2 * KEY_PAD_PX + KEY_ROW_PX * rows.len() as i32,
        )
    }

    /// Builds the axes (and draws the caption) on `area`.
    fn axes<'a, DB: DrawingBackend>(
        &self,
        area: &'a DrawingArea<DB, Shift>,
    ) -> std::result::Result<
        ChartContext<
            'a,
            DB,
            Cartesian2d<
                plotters::coord::types::RangedCoordf64,
                plotters::coord::types::RangedCoordf64,
            >,
        >,
        DrawingAreaErrorKind<DB::ErrorType>,
    > {
        let (x, y) = self.ranges();
        ChartBuilder::on(area)
            .caption(&self.title, ("sans-serif", 22))
            .margin(14)
            .x_label_area_size(44)
            .y_label_area_size(70)
            .build_cartesian_2d(x.0..x.1, y.0..y.1)
    }

    /// Where the data lies on a canvas whose chart is laid out as on `area`, and the plot's
    /// pixel box.
    fn occupied(&self) -> Result<(Occupied, PxBox)> {
        let mut scratch = String::new();
        let root = SVGBackend::with_string(&mut scratch, SIZE).into_drawing_area();
        let chart = self.axes(&root).map_err(|e| anyhow!("{e}"))?;
        let (xs, ys) = chart.plotting_area().get_pixel_range();
        let series = self
            .series
            .iter()
            .map(|s| {
                let pts = thin(&s.points, MAX_POINTS)
                    .into_iter()
                    .filter(|p| p.0.is_finite() && p.1.is_finite())
                    .map(|p| chart.backend_coord(&p))
                    .collect();
                (pts, s.style != Style::Points)
            })
            .collect();
        Ok((Occupied { series }, (xs.start, ys.start, xs.end, ys.end)))
    }

    /// Draws the chart: axes, shading, series, then the key where the data is not (module
    /// doc), or outside the axes.
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult<DB> {
        root.fill(&WHITE)?;
        let size = self.key_size();
        let inside = match self.occupied() {
            Ok((occupied, plot)) => free_place(&occupied, plot, size),
            Err(_) => None,
        };
        match inside {
            Some(at) => {
                self.draw_plot(root)?;
                self.draw_key(root, at, size)
            }
            None => {
                let (plot, side) = root.split_horizontally(SIZE.0 as i32 - size.0 - 2 * KEY_PAD_PX);
                self.draw_plot(&plot)?;
                // Level with the top of the plot (below the caption).
                self.draw_key(&side, (0, 50), size)
            }
        }
    }

    /// Axes, shading and series on `area`.
    fn draw_plot<DB: DrawingBackend>(&self, area: &DrawingArea<DB, Shift>) -> DrawResult<DB> {
        let (x, y) = self.ranges();
        let mut chart = self.axes(area)?;
        chart
            .configure_mesh()
            .x_desc(self.x_label.as_str())
            .y_desc(self.y_label.as_str())
            .light_line_style(RGBColor(235, 235, 235))
            .draw()?;
        for &(from, to, c) in &self.shades {
            let color = PALETTE[c % PALETTE.len()].mix(SHADE_OPACITY);
            chart.draw_series(std::iter::once(Rectangle::new(
                [(from.max(x.0), y.0), (to.min(x.1), y.1)],
                color.filled(),
            )))?;
        }
        for s in &self.series {
            let color = PALETTE[s.color % PALETTE.len()];
            let pts = thin(&s.points, MAX_POINTS);
            match s.style {
                Style::Solid => {
                    chart.draw_series(LineSeries::new(pts, color.stroke_width(2)))?;
                }
                Style::Dashed => {
                    chart.draw_series(DashedLineSeries::new(pts, 10, 6, color.stroke_width(2)))?;
                }
                Style::Dotted => {
                    chart.draw_series(DashedLineSeries::new(pts, 3, 4, color.stroke_width(2)))?;
                }
                Style::Points => {
                    chart.draw_series(
                        pts.into_iter()
                            .map(|p| Circle::new(p, POINT_PX as u32, color.filled())),
                    )?;
                }
            }
        }
        Ok(())
    }

    /// The key at `at` (top-left, px of `area`): a box, then per row its swatch (drawn as the
    /// series is) and its label.
    fn draw_key<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
        at: (i32, i32),
        size: (i32, i32),
    ) -> DrawResult<DB> {
        let (x0, y0) = at;
        let corner = (x0 + size.0, y0 + size.1);
        area.draw(&Rectangle::new([at, corner], WHITE.mix(0.9).filled()))?;
        area.draw(&Rectangle::new([at, corner], BLACK.stroke_width(1)))?;
        let font = ("sans-serif", KEY_FONT_PX).into_font().color(&BLACK);
        for (i, (label, swatch)) in self.key_rows().into_iter().enumerate() {
            let y = y0 + KEY_PAD_PX + KEY_ROW_PX * i as i32 + KEY_ROW_PX / 2;
            let x = x0 + KEY_PAD_PX;
            draw_swatch(area, &swatch, x, y)?;
            area.draw(&Text::new(
                label.to_string(),
                (x + KEY_SWATCH_PX + 8, y - KEY_FONT_PX as i32 / 2 - 1),
                font.clone(),
            ))?;
        }
        Ok(())
    }
}

/// A key swatch from (x, y) over [`KEY_SWATCH_PX`], drawn as its series is.
fn draw_swatch<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    swatch: &Swatch,
    x: i32,
    y: i32,
) -> DrawResult<DB> {
    let dashes = |on: i32, off: i32| -> Vec<(i32, i32)> {
        (0..)
            .map(|k| k * (on + off))
            .take_while(|&a| a < KEY_SWATCH_PX)
            .map(|a| (a, (a + on).min(KEY_SWATCH_PX)))
            .collect()
    };
    match *swatch {
        Swatch::Line(style, color) => {
            let line = color.stroke_width(2);
            let parts = match style {
                Style::Solid => vec![(0, KEY_SWATCH_PX)],
                Style::Dashed => dashes(10, 6),
                Style::Dotted => dashes(3, 4),
                Style::Points => {
                    for k in [5, 15, 25] {
                        area.draw(&Circle::new(
                            (x + k, y),
                            SWATCH_POINT_PX as u32,
                            color.filled(),
                        ))?;
                    }
                    return Ok(());
                }
            };
            for (a, b) in parts {
                area.draw(&PathElement::new(vec![(x + a, y), (x + b, y)], line))?;
            }
        }
        Swatch::Shade(color) => {
            area.draw(&Rectangle::new(
                [(x + 4, y - 7), (x + KEY_SWATCH_PX - 4, y + 7)],
                color.mix(SHADE_OPACITY).filled(),
            ))?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn segments_crossing_a_box() {
        let b = (10, 10, 20, 20);
        assert!(segment_crosses((0, 15), (30, 15), b), "through");
        assert!(segment_crosses((0, 0), (30, 30), b), "diagonal");
        assert!(!segment_crosses((0, 0), (30, 0), b), "above");
        assert!(!segment_crosses((0, 30), (9, 21), b), "beside");
        assert!(segment_crosses((15, 15), (15, 15), b), "a point inside");
    }

    #[test]
    fn the_key_goes_where_the_data_is_not() {
        let plot = (0, 0, 400, 300);
        // A line along the top: the key goes to a lower corner.
        let top = Occupied {
            series: vec![(vec![(0, 20), (400, 20)], true)],
        };
        let (_, y) = free_place(&top, plot, (100, 60)).unwrap();
        assert!(y > 40, "{y}");
        // Lines along the top and the bottom: a middle band is free.
        let bands = Occupied {
            series: vec![
                (vec![(0, 20), (400, 20)], true),
                (vec![(0, 280), (400, 280)], true),
            ],
        };
        let (_, y) = free_place(&bands, plot, (100, 60)).unwrap();
        assert!(y > 26 && y + 60 < 274, "{y}");
        // A grid of points everywhere: no free place (the key goes outside the axes).
        let full = Occupied {
            series: vec![(
                (0..=40)
                    .flat_map(|i| (0..=30).map(move |j| (i * 10, j * 10)))
                    .collect(),
                false,
            )],
        };
        assert_eq!(free_place(&full, plot, (100, 60)), None);
    }
}
