//! The shear-band oracle (Chen 2021 §3, Alg. 1), as plain functions over cell values of a
//! uniform grid (cell-centred, x fastest, as [`crate::packing_fraction`] numbers them):
//!
//! - [`cell_average`]: a point quantity (plastic strain rate, recent plastic strain) as the
//!   mass-weighted mean of the points in each cell;
//! - [`indicator`]: the regularised Laplacian of the plastic strain rate, H = |∇²ė| / ė_max,
//!   with ė_max the largest rate in the cell's neighbourhood (§3.1);
//! - [`flag`]: Alg. 1 lines 2–6, the cells on a band's boundary: H above
//!   min(c0 / D50², c0 / ΔX²) (§3.1.1) where the recent plastic strain exceeds c1 (§3.2);
//! - [`window`]: τ = c / γ̇_max, the rate-independent windows τ_l and τ_g (§3.2);
//! - [`RecentStrain`]: each point's plastic strain over the last τ_l, followed by point id;
//! - [`Persistence`]: Alg. 1 line 7, a band once the flagged set has stayed the same for τ_g;
//! - [`zones`]: §4, the enrichment zones from the band: discrete within φ0 of its flagged
//!   boundary, hybrid over the overlap t_h about φ0, continuum beyond.

use crate::{Zone, dims, distance_to_level, linear, zone_of_distance};
use grains_grid::Grid;
use std::collections::VecDeque;

/// The oracle's dimensionless coefficients (Chen 2021 Tables 4, 6 and 9).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Coefficients {
    /// c0: the Laplacian threshold is min(c0 / D50², c0 / ΔX²).
    pub c0: f64,
    /// c1: the recent plastic strain a cell must exceed to be a candidate.
    pub c1: f64,
    /// c_l: τ_l = c_l / γ̇_max, the window of the recent plastic strain.
    pub cl: f64,
    /// c_g: τ_g = c_g / γ̇_max, how long the flagged set must stay the same.
    pub cg: f64,
}

impl Coefficients {
    /// Table 4 (planar shear).
    pub const PLANAR_SHEAR: Self = Self {
        c0: 1.0e-6,
        c1: 1.0e-4,
        cl: 8.0e-4,
        cg: 1.2e-3,
    };
    /// Tables 6 and 9 (biaxial compression, plate indentation).
    pub const BIAXIAL: Self = Self {
        c0: 1.0e-6,
        c1: 8.0e-3,
        cl: 2.0e-2,
        cg: 9.6e-3,
    };
}

/// Mass-weighted mean of `value` over the points in each cell (0 in a cell with none). Points
/// are (position, mass, value); those outside the grid are left out.
pub fn cell_average(cells: &Grid, dim: usize, points: impl IntoIterator<Item = ([f64; 3], f64, f64)>) -> Vec<f64> {
    let n = dims(cells, dim);
    let mut sum = vec![0.0; n.iter().product()];
    let mut mass = vec![0.0; sum.len()];
    for (x, m, v) in points {
        let mut ijk = [0usize; 3];
        let mut inside = true;
        for k in 0..dim {
            let t = ((x[k] - cells.origin[k]) / cells.h).floor();
            inside &= t >= 0.0 && t < n[k] as f64;
            ijk[k] = t.max(0.0) as usize;
        }
        if inside {
            let i = linear(n, ijk);
            sum[i] += m * v;
            mass[i] += m;
        }
    }
    sum.iter().zip(&mass).map(|(&s, &m)| if m > 0.0 { s / m } else { 0.0 }).collect()
}

/// The neighbour of cell `ijk` one step along axis `k`: across a periodic axis it wraps; at an
/// open face it is the cell itself (a mirror: no flux through the grid's edge, so a field
/// that reaches the edge is not a band boundary there).
fn neighbour(cells: &Grid, n: [usize; 3], ijk: [usize; 3], k: usize, step: i64) -> usize {
    let j = ijk[k] as i64 + step;
    let mut nb = ijk;
    nb[k] = if cells.period[k] > 0 {
        j.rem_euclid(n[k] as i64) as usize
    } else if j < 0 || j >= n[k] as i64 {
        ijk[k]
    } else {
        j as usize
    };
    linear(n, nb)
}

/// The regularised indicator H of every cell (§3.1): |∇²ė| / ė_max, where ∇² is the
/// (2 dim + 1)-point Laplacian of the plastic strain rate norm `rate` and ė_max the largest
/// rate over the cell and the cells around it (3^dim); 0 where that largest rate is 0.
/// Units 1/m²: it is compared with c0 / length².
pub fn indicator(cells: &Grid, dim: usize, rate: &[f64]) -> Vec<f64> {
    let n = dims(cells, dim);
    assert_eq!(rate.len(), n.iter().product::<usize>(), "one rate per cell");
    let h2 = cells.h * cells.h;
    (0..rate.len())
        .map(|i| {
            let ijk = [i % n[0], (i / n[0]) % n[1], i / (n[0] * n[1])];
            let mut lap = 0.0;
            for k in 0..dim {
                lap += rate[neighbour(cells, n, ijk, k, -1)] + rate[neighbour(cells, n, ijk, k, 1)] - 2.0 * rate[i];
            }
            lap /= h2;
            // The 3^dim block around the cell, one axis at a time.
            let mut block = vec![i];
            for k in 0..dim {
                block = block
                    .iter()
                    .flat_map(|&c| {
                        let cijk = [c % n[0], (c / n[0]) % n[1], c / (n[0] * n[1])];
                        [c, neighbour(cells, n, cijk, k, -1), neighbour(cells, n, cijk, k, 1)]
                    })
                    .collect();
            }
            let max = block.iter().map(|&c| rate[c]).fold(0.0, f64::max);
            if max > 0.0 { (lap / max).abs() } else { 0.0 }
        })
        .collect()
}

/// Alg. 1 lines 2–6: the cells on a band's boundary. A cell is flagged where its neighbourhood
/// yields (ė_max > 0), its recent plastic strain `recent` exceeds c1, and H exceeds
/// min(c0 / D50², c0 / ΔX²): on a coarse grid the sharp edge of the band is smeared over a
/// cell, so the cell's own length sets the lower threshold (§3.1.1, App. D).
pub fn flag(cells: &Grid, dim: usize, rate: &[f64], recent: &[f64], d50: f64, c: &Coefficients) -> Vec<bool> {
    let threshold = (c.c0 / (d50 * d50)).min(c.c0 / (cells.h * cells.h));
    indicator(cells, dim, rate)
        .iter()
        .zip(recent)
        .map(|(&h, &r)| h > 0.0 && r > c.c1 && h > threshold)
        .collect()
}

/// τ = c / γ̇_max [s]: the oracle's windows scale with the fastest shear of the whole body, so
/// a slow and a fast band are found at the same strain (§3.2, App. E). Infinite at rest.
pub fn window(c: f64, max_shear_rate: f64) -> f64 {
    if max_shear_rate > 0.0 { c / max_shear_rate } else { f64::INFINITY }
}

/// The accumulated plastic strain of the points at past times, to give each point its plastic
/// strain over the last τ_l (§3.2). Points are followed by id (Lagrangian: a point that has
/// moved across cells keeps its history; a point that is new since a record has none, and
/// counts from its first record).
#[derive(Clone, Debug, Default, serde::Serialize, serde::Deserialize)]
pub struct RecentStrain {
    /// (time, (id, accumulated plastic strain) sorted by id), oldest first.
    records: VecDeque<(f64, Vec<(u64, f64)>)>,
}

impl RecentStrain {
    /// Most records kept: past that, every other old one is dropped, so the history spans
    /// the whole run at a coarser spacing rather than forgetting its start.
    pub const MAX_RECORDS: usize = 64;

    /// Records the points' accumulated plastic strain at time `t` (ids and strains in step).
    pub fn record(&mut self, t: f64, ids: &[u64], strain: &[f64]) {
        let mut r: Vec<(u64, f64)> = ids.iter().copied().zip(strain.iter().copied()).collect();
        r.sort_unstable_by_key(|&(id, _)| id);
        self.records.push_back((t, r));
        if self.records.len() > Self::MAX_RECORDS {
            // Keep the newest half as is; thin the older half.
            let old = self.records.len() / 2;
            let mut k = 0;
            self.records.retain(|_| {
                k += 1;
                k > old || k % 2 == 1
            });
        }
    }

    /// Each point's plastic strain since the newest record at or before `t − tau` (or since
    /// the oldest record, if none is that old; 0 for a point no record has).
    pub fn recent(&self, t: f64, tau: f64, ids: &[u64], strain: &[f64]) -> Vec<f64> {
        let base = self
            .records
            .iter()
            .rev()
            .find(|(tr, _)| *tr <= t - tau)
            .or_else(|| self.records.front());
        ids.iter()
            .zip(strain)
            .map(|(id, &s)| {
                let Some((_, r)) = base else { return 0.0 };
                match r.binary_search_by_key(id, |&(i, _)| i) {
                    Ok(k) => s - r[k].1,
                    Err(_) => 0.0,
                }
            })
            .collect()
    }
}

/// Alg. 1 line 7: the flagged set is a band once it is non-empty and has not changed (no cell
/// added or removed) for τ_g.
#[derive(Clone, Debug, Default, serde::Serialize, serde::Deserialize)]
pub struct Persistence {
    flagged: Vec<bool>,
    since: f64,
}

impl Persistence {
    /// Takes the set flagged at time `t`; true when it is a band.
    pub fn update(&mut self, t: f64, flagged: Vec<bool>, tau_g: f64) -> bool {
        if flagged != self.flagged {
            self.flagged = flagged;
            self.since = t;
        }
        self.flagged.iter().any(|&f| f) && t - self.since >= tau_g
    }

    /// The cells of the current set.
    pub fn flagged(&self) -> &[bool] {
        &self.flagged
    }
}

/// Chen 2021 §4 (Fig. 6 c–e): the zone of every cell from the band's flagged cells (its
/// boundary, as [`flag`] gives it). A cell whose centre lies within φ0 − t_h / 2 of the nearest
/// flagged cell centre is discrete, within t_h / 2 of φ0 hybrid (the overlap the coupling
/// needs), continuum beyond; a flagged cell is at distance 0. With nothing flagged every cell
/// stays continuum. The distance is [`distance_to_level`]'s (first order in the cell width,
/// exact for a straight band) and does not wrap across a periodic axis.
pub fn zones(cells: &Grid, dim: usize, flagged: &[bool], phi0: f64, overlap: f64) -> Vec<Zone> {
    if !flagged.iter().any(|&f| f) {
        return vec![Zone::Continuum; flagged.len()];
    }
    let field: Vec<f64> = flagged.iter().map(|&f| if f { 1.0 } else { 0.0 }).collect();
    let signed = distance_to_level(cells, dim, &field, 0.5);
    signed
        .iter()
        .zip(flagged)
        .map(|(&d, &f)| {
            // Outside the flagged set d < 0 is the distance to the contour, which runs half a
            // cell from the flagged centres.
            let from_centre = if f { 0.0 } else { -d + 0.5 * cells.h };
            if from_centre.is_finite() {
                zone_of_distance(from_centre, phi0, 0.5 * overlap)
            } else {
                Zone::Continuum
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(nx: u64, ny: u64, h: f64) -> Grid {
        Grid {
            origin: [0.0; 3],
            h,
            nodes: [nx, ny, 1],
            period: [0; 3],
        }
    }

    /// A continuum band as a local continuum makes it (App. C): a plastic strain rate that is
    /// `peak` in a band of `width` about y = `y0` and falls off over one cell on each side
    /// (the rate is the band's mean over each cell), 0 elsewhere.
    fn band_rate(g: &Grid, y0: f64, width: f64) -> Vec<f64> {
        let n = dims(g, 2);
        (0..n[0] * n[1])
            .map(|i| {
                let (lo, hi) = ((i / n[0]) as f64 * g.h, (i / n[0] + 1) as f64 * g.h);
                let overlap = hi.min(y0 + width / 2.0) - lo.max(y0 - width / 2.0);
                // Round-off at an edge that falls on a cell face is no plastic rate.
                if overlap > 1e-9 * g.h { overlap / g.h } else { 0.0 }
            })
            .collect()
    }

    fn rows(g: &Grid, flagged: &[bool]) -> Vec<usize> {
        let nx = g.nodes[0] as usize;
        let mut r: Vec<usize> = flagged.iter().enumerate().filter(|(_, f)| **f).map(|(i, _)| i / nx).collect();
        r.dedup();
        r.sort_unstable();
        r.dedup();
        r
    }

    /// Each point counts in the cell it lies in, by its mass; empty cells and points outside
    /// the grid count nothing.
    #[test]
    fn a_cell_holds_the_mass_weighted_mean_of_its_points() {
        let g = grid(2, 2, 1.0);
        let pts = [
            ([0.5, 0.5, 0.0], 1.0, 2.0),
            ([0.9, 0.1, 0.0], 3.0, 6.0),
            ([1.5, 1.5, 0.0], 2.0, -1.0),
            ([2.5, 0.5, 0.0], 5.0, 9.0),
        ];
        assert_eq!(cell_average(&g, 2, pts), vec![5.0, 0.0, 0.0, -1.0]);
    }

    /// A band 6 D50 wide across a 10-D50 grid: the cells flagged are the rows at the band's two
    /// edges and no other, all along the band; a uniform rate (the whole body flowing, as
    /// the under-consolidated shear of Fig. 5) flags nothing.
    #[test]
    fn the_oracle_flags_the_edges_of_a_band_and_not_a_uniform_flow() {
        let d50 = 1e-3;
        let h = 2e-3;
        let g = grid(20, 40, h);
        let c = Coefficients {
            c0: 0.5,
            ..Coefficients::PLANAR_SHEAR
        };
        // Band 12 mm wide about y = 40 mm: rows 17-22 plastic, 14-16 and 23-25 not.
        let rate = band_rate(&g, 0.040, 0.012);
        let recent = vec![1.0; rate.len()];
        let f = flag(&g, 2, &rate, &recent, d50, &c);
        assert_eq!(rows(&g, &f), vec![16, 17, 22, 23], "rows flagged");
        assert!(f.chunks(20).all(|row| row.iter().all(|&x| x == row[0])), "each flagged row whole");
        let uniform = vec![3.0; rate.len()];
        assert!(!flag(&g, 2, &uniform, &recent, d50, &c).iter().any(|&x| x), "uniform flow");
        // Without recent plastic strain (a band that has stopped, or not yet strained c1) the
        // same rate flags nothing.
        let still = vec![0.5 * c.c1; rate.len()];
        assert!(!flag(&g, 2, &rate, &still, d50, &c).iter().any(|&x| x), "no recent strain");
    }

    /// App. D: a local continuum's band is one element thick on any grid, so H peaks near
    /// 1 / ΔX² and a coarse grid never reaches a threshold set by the grain alone. The same
    /// band on a fine (ΔX = 2 D50) and a coarse (ΔX = 10 D50) grid: with min(c0/D50², c0/ΔX²)
    /// both detect it; with c0/D50² alone only the fine one does.
    #[test]
    fn both_thresholds_detect_on_a_coarse_and_a_fine_grid() {
        let d50 = 1e-3;
        // H peaks at 2 / ΔX² (the band's own row): 5e5 on the fine grid, 2e4 on the coarse;
        // c0 / D50² = 4e5 lies between.
        let c = Coefficients {
            c0: 0.4,
            ..Coefficients::PLANAR_SHEAR
        };
        for (h, grain_alone_detects) in [(2e-3, true), (1e-2, false)] {
            let g = grid(10, 40, h);
            let y0 = 20.5 * h; // one element thick, as the continuum makes it
            let rate = band_rate(&g, y0, h);
            let recent = vec![1.0; rate.len()];
            let f = flag(&g, 2, &rate, &recent, d50, &c);
            assert_eq!(rows(&g, &f), vec![19, 20, 21], "ΔX = {h}: the band's row and its two neighbours");
            let hmax = indicator(&g, 2, &rate).into_iter().fold(0.0, f64::max);
            assert_eq!(hmax > c.c0 / (d50 * d50), grain_alone_detects, "ΔX = {h}: H max {hmax}");
        }
    }

    /// A periodic axis has no edge: a band crossing it is found on both sides of the seam and
    /// the wrap adds no flag; an open edge is a mirror, so a flow up to it is not a band there.
    #[test]
    fn a_periodic_axis_wraps_and_an_open_edge_mirrors() {
        let c = Coefficients {
            c0: 0.5,
            ..Coefficients::PLANAR_SHEAR
        };
        let mut g = grid(40, 10, 1e-3);
        // Plastic in the first 6 columns, as a band running along y.
        let rate: Vec<f64> = (0..400).map(|i| if i % 40 < 6 { 1.0 } else { 0.0 }).collect();
        let recent = vec![1.0; 400];
        let cols = |f: &[bool]| {
            let mut c: Vec<usize> = f.iter().enumerate().filter(|(_, x)| **x).map(|(i, _)| i % 40).collect();
            c.sort_unstable();
            c.dedup();
            c
        };
        assert_eq!(cols(&flag(&g, 2, &rate, &recent, 1e-3, &c)), vec![5, 6], "open: one edge");
        g.period = [40, 0, 0];
        assert_eq!(cols(&flag(&g, 2, &rate, &recent, 1e-3, &c)), vec![0, 5, 6, 39], "periodic: both");
    }

    #[test]
    fn recent_strain_counts_from_the_record_a_window_ago() {
        let mut h = RecentStrain::default();
        h.record(0.0, &[7, 3], &[0.0, 0.0]);
        h.record(1.0, &[3, 7], &[0.1, 0.5]);
        h.record(2.0, &[3, 7, 9], &[0.3, 0.6, 0.2]);
        // At t = 2.5 with τ = 1: since the record at 1.0. Point 9 is new since then.
        let r = h.recent(2.5, 1.0, &[7, 3, 9], &[0.8, 0.4, 0.25]);
        assert_eq!(r.len(), 3);
        assert!((r[0] - 0.3).abs() < 1e-12 && (r[1] - 0.3).abs() < 1e-12 && r[2] == 0.0, "{r:?}");
        // A window longer than the history: since the oldest record.
        let r = h.recent(2.5, 10.0, &[7], &[0.8]);
        assert!((r[0] - 0.8).abs() < 1e-12);
        // Thinning keeps the first record and the newest ones.
        for k in 3..200 {
            h.record(k as f64, &[3], &[k as f64]);
        }
        assert!(h.records.len() <= RecentStrain::MAX_RECORDS);
        assert_eq!(h.records.front().map(|r| r.0), Some(0.0));
        assert_eq!(h.records.back().map(|r| r.0), Some(199.0));
        let r = h.recent(199.0, 0.5, &[3], &[199.0]);
        assert!((r[0] - 1.0).abs() < 1e-12, "{r:?}");
    }

    /// §4: the two flagged edges of a band six cells wide (rows 17 and 22 of 40, h = 1 mm);
    /// φ0 = 5.2 mm, t_h = 1 mm. Analytic: a row |Δ| rows from the nearer edge is discrete for
    /// |Δ| h < 4.7 mm, hybrid up to 5.7 mm, continuum beyond (the band's inside, at most 2 rows
    /// from an edge, discrete). No bound falls on a row, so a half-cell error in the distance
    /// shows. Nothing flagged: all continuum.
    #[test]
    fn zones_reach_phi0_from_the_band_s_boundary_with_the_overlap_about_it() {
        let h = 1e-3;
        let g = grid(12, 40, h);
        let flagged: Vec<bool> = (0..12 * 40).map(|i| matches!(i / 12, 17 | 22)).collect();
        let z = zones(&g, 2, &flagged, 5.2 * h, h);
        for (i, zone) in z.iter().enumerate() {
            let row = (i / 12) as i64;
            let away = (row - 17).abs().min((row - 22).abs()) as f64;
            let expected = if away < 4.7 {
                Zone::Discrete
            } else if away <= 5.7 {
                Zone::Hybrid
            } else {
                Zone::Continuum
            };
            assert_eq!(*zone, expected, "row {row}, {away} rows from the band's edge");
        }
        assert!(
            zones(&g, 2, &vec![false; 12 * 40], 5.0 * h, h)
                .iter()
                .all(|z| *z == Zone::Continuum)
        );
    }

    #[test]
    fn a_band_is_a_flagged_set_that_stays_for_tau_g() {
        let mut p = Persistence::default();
        let a = vec![false, true, true];
        let b = vec![true, true, false];
        assert!(!p.update(0.0, vec![false; 3], 0.1), "nothing flagged");
        assert!(!p.update(0.1, a.clone(), 0.1));
        assert!(!p.update(0.15, a.clone(), 0.1));
        assert!(!p.update(0.18, b.clone(), 0.1), "changed: the clock restarts");
        assert!(!p.update(0.25, b.clone(), 0.1));
        assert!(p.update(0.3, b.clone(), 0.1));
        assert!(!p.update(0.5, vec![false; 3], 0.1), "an empty set is no band");
        assert_eq!(window(1.2e-3, 0.0), f64::INFINITY);
        assert!((window(1.2e-3, 0.6) - 2e-3).abs() < 1e-15);
    }
}
