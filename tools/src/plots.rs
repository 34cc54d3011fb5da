//! Line and scatter charts as SVG (plotters), shared by every command that draws.

use std::path::Path;

use anyhow::{Result, anyhow};
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
    /// Legend in the lower right corner instead of the upper right.
    pub legend_lower_right: bool,
    /// Shaded x intervals (from, to, palette index), drawn under the series.
    pub shades: Vec<(f64, f64, usize)>,
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
            let root = SVGBackend::with_string(&mut text, (900, 560)).into_drawing_area();
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

    fn draw<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, plotters::coord::Shift>,
    ) -> std::result::Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
        root.fill(&WHITE)?;
        let x = self.x_range.unwrap_or_else(|| {
            range_of(
                self.series
                    .iter()
                    .flat_map(|s| s.points.iter().map(|p| p.0)),
            )
        });
        let y = self.y_range.unwrap_or_else(|| {
            range_of(
                self.series
                    .iter()
                    .flat_map(|s| s.points.iter().map(|p| p.1)),
            )
        });
        let mut chart = ChartBuilder::on(root)
            .caption(&self.title, ("sans-serif", 22))
            .margin(14)
            .x_label_area_size(44)
            .y_label_area_size(70)
            .build_cartesian_2d(x.0..x.1, y.0..y.1)?;
        chart
            .configure_mesh()
            .x_desc(self.x_label.as_str())
            .y_desc(self.y_label.as_str())
            .light_line_style(RGBColor(235, 235, 235))
            .draw()?;
        for &(from, to, c) in &self.shades {
            let color = PALETTE[c % PALETTE.len()].mix(0.15);
            chart.draw_series(std::iter::once(Rectangle::new(
                [(from.max(x.0), y.0), (to.min(x.1), y.1)],
                color.filled(),
            )))?;
        }
        for s in &self.series {
            let color = PALETTE[s.color % PALETTE.len()];
            let pts = thin(&s.points, 4000);
            let anno = match s.style {
                Style::Solid => chart.draw_series(LineSeries::new(pts, color.stroke_width(2)))?,
                Style::Dashed => {
                    chart.draw_series(DashedLineSeries::new(pts, 10, 6, color.stroke_width(2)))?
                }
                Style::Dotted => {
                    chart.draw_series(DashedLineSeries::new(pts, 3, 4, color.stroke_width(2)))?
                }
                Style::Points => {
                    chart.draw_series(pts.into_iter().map(|p| Circle::new(p, 2, color.filled())))?
                }
            };
            anno.label(s.name.as_str()).legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2))
            });
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .position(if self.legend_lower_right {
                SeriesLabelPosition::LowerRight
            } else {
                SeriesLabelPosition::UpperRight
            })
            .draw()?;
        Ok(())
    }
}
