//! Friction points gathered as the files are read, in bounded memory (issue 24 item 9):
//! up to [`EXACT_POINTS`] points are kept and fitted as they are; beyond, every point goes
//! into a cell of a grid over (friction speed, disc temperature), which keeps its count,
//! its mean speed, temperature and mu, and the sum of squares of mu about its mean. The
//! fit then takes each cell's mean point weighted by its count ([`super::fit_cells`]):
//! within a cell Eq (2) is linear to far below the noise (the cells start at 1/512 of the
//! first points' ranges; points spread evenly over them fill [`MAX_CELLS`] at 1/128, where
//! Eq (2)'s curvature moves a cell's mean mu by under 1e-5 with the reference parameters),
//! so this is the least-squares fit of all the points, and the
//! intervals and the rms use every point's residual (the within-cell sums of squares
//! added). When the cells exceed [`MAX_CELLS`] (data far outside the first points'
//! ranges) the grid coarsens by 2 in both directions, merging cells exactly. A sample of
//! [`PLOT_POINTS`] points (reservoir sampling, seeded: the same file gives the same
//! sample) is kept for the report's plots.

use std::collections::HashMap;

/// Points fitted as they are, at most; beyond, the points are gathered in cells.
pub const EXACT_POINTS: usize = 200_000;
/// Most cells kept: beyond, the grid coarsens.
pub const MAX_CELLS: usize = 65_536;
/// Points kept for the report's plots.
pub const PLOT_POINTS: usize = 20_000;
/// Cells per axis over the first points' ranges.
const CELLS_PER_RANGE: f64 = 512.0;

/// One cell: count, sums of speed and temperature, mean mu and the sum of squares of mu
/// about it (Welford; merged exactly by Chan's formula).
#[derive(Clone, Copy, Debug, Default)]
pub struct Cell {
    pub n: f64,
    pub sum_v: f64,
    pub sum_t: f64,
    pub mean_mu: f64,
    pub m2: f64,
}

impl Cell {
    fn add(&mut self, v: f64, t: f64, mu: f64) {
        self.n += 1.0;
        self.sum_v += v;
        self.sum_t += t;
        let d = mu - self.mean_mu;
        self.mean_mu += d / self.n;
        self.m2 += d * (mu - self.mean_mu);
    }

    fn merge(&mut self, o: &Cell) {
        let n = self.n + o.n;
        let d = o.mean_mu - self.mean_mu;
        self.mean_mu += d * o.n / n;
        self.m2 += o.m2 + d * d * self.n * o.n / n;
        self.sum_v += o.sum_v;
        self.sum_t += o.sum_t;
        self.n = n;
    }
}

/// The grid of cells.
#[derive(Clone, Debug)]
pub struct Cells {
    /// Cell widths: friction speed, m/s, and disc temperature, degC.
    pub width: (f64, f64),
    pub map: HashMap<(i64, i64), Cell>,
}

impl Cells {
    fn key(&self, v: f64, t: f64) -> (i64, i64) {
        (
            (v / self.width.0).floor() as i64,
            (t / self.width.1).floor() as i64,
        )
    }

    fn add(&mut self, v: f64, t: f64, mu: f64) {
        let k = self.key(v, t);
        self.map.entry(k).or_default().add(v, t, mu);
        if self.map.len() > MAX_CELLS {
            self.coarsen();
        }
    }

    /// Doubles the widths, merging each 2 x 2 block of cells.
    fn coarsen(&mut self) {
        self.width = (2.0 * self.width.0, 2.0 * self.width.1);
        let old = std::mem::take(&mut self.map);
        for ((i, j), c) in old {
            self.map
                .entry((i.div_euclid(2), j.div_euclid(2)))
                .or_default()
                .merge(&c);
        }
    }

    /// Each cell's mean speed, temperature and mu, its count and the within-cell sum of
    /// squares of mu over all cells.
    pub fn means(&self) -> (Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>, f64) {
        let mut cells: Vec<&Cell> = self.map.values().collect();
        // A fixed order (the map's is not): the same file gives the same fit.
        cells.sort_by(|a, b| {
            (a.sum_v / a.n, a.sum_t / a.n)
                .partial_cmp(&(b.sum_v / b.n, b.sum_t / b.n))
                .unwrap_or(std::cmp::Ordering::Equal)
        });
        let v = cells.iter().map(|c| c.sum_v / c.n).collect();
        let t = cells.iter().map(|c| c.sum_t / c.n).collect();
        let mu = cells.iter().map(|c| c.mean_mu).collect();
        let n = cells.iter().map(|c| c.n).collect();
        let ss = cells.iter().map(|c| c.m2).sum();
        (v, t, mu, n, ss)
    }
}

/// The points of the files so far (module doc).
#[derive(Clone, Debug)]
pub struct Gathered {
    /// The points (speed m/s, temperature degC, mu) while they are at most
    /// [`EXACT_POINTS`].
    pub exact: Vec<[f64; 3]>,
    /// The cells once there are more.
    pub cells: Option<Cells>,
    /// Points gathered.
    pub n: usize,
    /// An even sample for the plots.
    pub sample: Vec<[f64; 3]>,
    rng: u64,
}

impl Default for Gathered {
    fn default() -> Self {
        Self {
            exact: Vec::new(),
            cells: None,
            n: 0,
            sample: Vec::new(),
            rng: 0x9E37_79B9_7F4A_7C15,
        }
    }
}

impl Gathered {
    /// Takes a point.
    pub fn add(&mut self, v: f64, t: f64, mu: f64) {
        self.n += 1;
        self.keep_sample([v, t, mu]);
        match &mut self.cells {
            Some(cells) => cells.add(v, t, mu),
            None => {
                self.exact.push([v, t, mu]);
                if self.exact.len() > EXACT_POINTS {
                    self.to_cells();
                }
            }
        }
    }

    /// Reservoir sampling (Algorithm R) with a fixed-seed xorshift generator.
    fn keep_sample(&mut self, p: [f64; 3]) {
        if self.sample.len() < PLOT_POINTS {
            self.sample.push(p);
            return;
        }
        self.rng ^= self.rng << 13;
        self.rng ^= self.rng >> 7;
        self.rng ^= self.rng << 17;
        let k = (self.rng % self.n as u64) as usize;
        if k < PLOT_POINTS {
            self.sample[k] = p;
        }
    }

    /// Moves the exact points into cells of 1/512 of their ranges.
    fn to_cells(&mut self) {
        let span = |i: usize| {
            let (lo, hi) = self
                .exact
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
                    (lo.min(p[i]), hi.max(p[i]))
                });
            hi - lo
        };
        let width = (
            (span(0) / CELLS_PER_RANGE).max(1e-4),
            (span(1) / CELLS_PER_RANGE).max(1e-3),
        );
        let mut cells = Cells {
            width,
            map: HashMap::new(),
        };
        for p in std::mem::take(&mut self.exact) {
            cells.add(p[0], p[1], p[2]);
        }
        self.cells = Some(cells);
    }

    /// The points for the plots: all of them while they are exact, else the sample.
    pub fn plot_points(&self) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let pts = if self.cells.is_none() {
            &self.exact
        } else {
            &self.sample
        };
        (
            pts.iter().map(|p| p[0]).collect(),
            pts.iter().map(|p| p[1]).collect(),
            pts.iter().map(|p| p[2]).collect(),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cells_keep_counts_means_and_sums_of_squares_exactly() {
        let pts: Vec<[f64; 3]> = (0..5000)
            .map(|i| {
                let x = i as f64;
                [
                    (x * 0.37) % 30.0,
                    (x * 1.7) % 250.0,
                    0.4 + 0.01 * (x * 0.91).sin(),
                ]
            })
            .collect();
        let mut cells = Cells {
            width: (0.5, 5.0),
            map: HashMap::new(),
        };
        for p in &pts {
            cells.add(p[0], p[1], p[2]);
        }
        let mut coarse = cells.clone();
        coarse.coarsen();
        coarse.coarsen();
        let n: f64 = coarse.map.values().map(|c| c.n).sum();
        assert_eq!(n, 5000.0);
        // Total sum of squares about the grand mean = within + between, either grid.
        let mean = pts.iter().map(|p| p[2]).sum::<f64>() / 5000.0;
        let total: f64 = pts.iter().map(|p| (p[2] - mean).powi(2)).sum();
        for grid in [&cells, &coarse] {
            let (_, _, mu, n, within) = grid.means();
            let between: f64 = mu.iter().zip(&n).map(|(m, n)| n * (m - mean).powi(2)).sum();
            assert!(
                (within + between - total).abs() < 1e-9 * total,
                "{within} {between} {total}"
            );
        }
    }

    #[test]
    fn memory_is_bounded_whatever_the_points() {
        let mut g = Gathered::default();
        for i in 0..(EXACT_POINTS + 300_000) {
            let x = i as f64;
            // Far beyond the first points' ranges after them: the grid coarsens.
            let scale = if i > EXACT_POINTS { 1000.0 } else { 1.0 };
            g.add((x * 0.37) % 30.0 * scale, (x * 1.7) % 250.0 * scale, 0.4);
        }
        let cells = g.cells.as_ref().unwrap();
        assert!(cells.map.len() <= MAX_CELLS);
        assert!(g.exact.is_empty() && g.sample.len() == PLOT_POINTS);
        let n: f64 = cells.map.values().map(|c| c.n).sum();
        assert_eq!(n as usize, g.n);
    }
}
