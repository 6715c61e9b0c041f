//! The hybrid biaxial compression (Chen 2021 §6.2, Fig. 16–18 middle): the continuum until the
//! oracle fires, then the cells within φ0 of the band enriched with a DEM sample as it stood
//! before the shortening, its grains taken where that material started and trained through
//! the continuum's motion up to the detection (§4.1.1), and the two models coupled on the
//! shared nodes every step. The fluid's
//! pressure holds both models' free faces; the platen presses the points (by contact) and the
//! grains (the DEM's wall) alike. In process, as the planar shear's hybrid ([`super::super::hybrid`]).

use super::super::continuum::Detection;
use super::super::hybrid::Parts;
use super::*;
use grains_grid::Grid;
use grains_oracle::{Zone, band_epoch, epoch};
use std::collections::BTreeSet;

/// Ids of the training's ring (not kept).
const RING: u64 = 1 << 40;

/// The mass and velocity of each node of a grid (dense, x fastest).
type Nodes = Vec<(f64, [f64; 2])>;

/// The continuum's nodal velocities over the shortening, for the training: every record's
/// time and nodes of `grid`.
pub(super) struct NodeHistory {
    pub grid: Grid,
    pub records: Vec<(f64, Nodes)>,
}

impl NodeHistory {
    /// Records the grid's velocities after the MPM's phase 1, `t` into the shortening.
    pub fn record(&mut self, t: f64, pipe: &mut grains_mpm::pipeline::MpmPipeline<D2>) {
        let count = (self.grid.nodes[0] * self.grid.nodes[1]) as usize;
        let mut nodes = vec![(0.0, [0.0; 2]); count];
        let grid = self.grid;
        pipe.for_each_node_mut(|ijk, mass, v| {
            if let Some(n) = grid.index(ijk) {
                nodes[n as usize] = (mass, [v.x, v.y]);
            }
        });
        self.records.push((t, nodes));
    }

    /// The continuum's velocity at `x`, `t` into the shortening: the first record at or after
    /// `t` (they are a few steps apart),
    /// bilinear between the four nodes around `x` that carry mass (zero where none does).
    pub fn velocity(&self, x: [f64; 2], t: f64) -> [f64; 2] {
        let k = self.records.partition_point(|r| r.0 < t).min(self.records.len() - 1);
        let nodes = &self.records[k].1;
        let g = &self.grid;
        let f = [0, 1].map(|a| (x[a] - g.origin[a]) / g.h);
        let base = f.map(|v| v.floor());
        let (mut sum, mut weight) = ([0.0; 2], 0.0);
        for (di, dj) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
            let (i, j) = (base[0] as i64 + di, base[1] as i64 + dj);
            if i < 0 || j < 0 || i >= g.nodes[0] as i64 || j >= g.nodes[1] as i64 {
                continue;
            }
            let (mass, v) = nodes[(j * g.nodes[0] as i64 + i) as usize];
            if mass <= 0.0 {
                continue;
            }
            let w = (1.0 - (f[0] - i as f64).abs()) * (1.0 - (f[1] - j as f64).abs());
            sum = [sum[0] + w * v[0], sum[1] + w * v[1]];
            weight += w;
        }
        if weight > 0.0 {
            [sum[0] / weight, sum[1] / weight]
        } else {
            [0.0; 2]
        }
    }
}

/// What the enrichment and the training at the detection did.
pub(super) struct BandGrains {
    /// Grains cut, points deleted, the enrichment's changes of the total mass (relative) and
    /// momentum (over the total mass × the platen's speed).
    pub grains: usize,
    pub deleted: usize,
    pub mass: f64,
    pub momentum: f64,
    /// The trained packing's mean stress [σxx, σyy] (compression positive, Love–Weber over the
    /// region's grains and the ring, their area over the sample's packing) against the continuum's points in the same
    /// cells, and the packing as cut (untrained).
    pub trained: [f64; 2],
    pub untrained: [f64; 2],
    pub continuum: [f64; 2],
    /// Each new grain's position in the sample before the shortening, by id (App. A's box).
    pub start: HashMap<u64, [f64; 2]>,
    pub wall: f64,
}

/// Enriches the continuum `at` its detection, the cells within `phi0` [m] of the flagged ones,
/// with `sample`'s grains (the DEM specimen before its shortening: a packing of the same box,
/// not repeated), trained from the start of the shortening to `duration` with `history`
/// (Chen §4.1.1, as the runtime's band training): the cells the material now in the cells that
/// need grains started in (`origin`: the points' positions at the start of the shortening, by
/// id) take the sample's grains, which move freely, and a ring of the sample's grains in the
/// cells around those moves with the continuum's velocity there, in `fluid` at the free faces;
/// grains under `glue` stay glued; the top wall comes down by the platen's `travel` at a steady
/// speed. The trained grains whose centres end in the cells that need them are the new grains
/// (`band_epoch::enrich`'s cut: they take the continuum's velocity there). Returns the plan,
/// the DEM state (the sample's walls: the bottom, and the top where the points' platen is)
/// with its pipeline, and what it did. `stress`: each of `at`'s points' [τxx, τyy] and volume.
#[allow(clippy::too_many_arguments)]
pub(super) fn enrich_and_train(
    sample: &DemState<D2>,
    at: &Detection,
    origin: &HashMap<u64, [f64; 2]>,
    stress: &[([f64; 2], f64)],
    history: &NodeHistory,
    (duration, fluid): (f64, &grains_dem::fluid::Fluid),
    (dem_dt, glue, speed, travel, phi0): (f64, f64, f64, f64, f64),
) -> anyhow::Result<(Parts, BandGrains)> {
    use grains_dem::training;
    let t0 = std::time::Instant::now();
    let g0 = &sample.grains;
    let sample_ids: Vec<usize> = (0..g0.len()).filter(|&i| g0.id[i] < super::MEMBRANE).collect();
    let first = *sample_ids.first().context("an empty DEM sample")?;
    let material = g0.material[first];
    let density = g0.mass[first] / (std::f64::consts::PI * g0.radius[first].powi(2));
    let packing = band_epoch::Packing {
        min: [0.0; 3],
        period: [0.0; 3],
        grains: sample_ids.iter().map(|&i| (D2::to_array(g0.x[i]), g0.radius[i])).collect(),
    };
    let faces = sample_ids
        .iter()
        .fold([f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY], |f, &i| {
            let (x, r) = (g0.x[i], g0.radius[i]);
            [f[0].min(x.x - r), f[1].max(x.x + r), f[2].max(x.y + r)]
        });
    let sample_area: f64 = sample_ids.iter().map(|&i| std::f64::consts::PI * g0.radius[i].powi(2)).sum();
    // What the training did: the trained grains (not the ring) with their places in the
    // sample, and the packing's stress as cut and as trained.
    let mut trained_grains: Vec<([f64; 2], [f64; 2])> = Vec::new();
    let (mut untrained, mut trained) = ([0.0; 2], [0.0; 2]);
    // The packing as cut and as trained each in a pipeline of its own.
    let mut pipes = (grains_dem::DemPipeline::<D2>::new(2)?, grains_dem::DemPipeline::<D2>::new(2)?);
    let mut train = |need: &BTreeSet<usize>| -> Vec<grains_oracle::epoch::NewGrain> {
        // The cells the material now in `need` started in, and a ring of one cell around them.
        let moved = at.points.iter().filter_map(|p| origin.get(&p.id).map(|x| (p.x, [x[0], x[1], 0.0])));
        let (start, ring) = band_epoch::training_cells(&at.cells, 2, need, moved);
        // The trained packing starts as the sample did, at rest. The ring moves with the
        // continuum and is dropped after: driving the region's own outer grains instead
        // packed them into each other along its faces (two driven grains do not push each
        // other apart: the continuum's 2% of shortening along a face is 20 µm of overlap
        // between 1-mm neighbours) and they burst out at 1–2 m/s when released. The
        // specimen's free faces take the fluid's pressure, its load at the start (the faces
        // move by a few percent of a D50 meanwhile); the top wall comes down with the platen.
        let mut state = sample.clone();
        state.grains = Default::default();
        let mut shell = Vec::new();
        for &i in &sample_ids {
            let x = D2::to_array(g0.x[i]);
            let Some(c) = epoch::cell_of(&at.cells, 2, x) else { continue };
            let id = if start.contains(&c) {
                g0.id[i]
            } else if ring.contains(&c) {
                let id = RING + shell.len() as u64;
                shell.push(id);
                id
            } else {
                continue;
            };
            let k = state.grains.push(id, g0.x[i], g0.radius[i], g0.mass[i], material);
            state.grains.frozen[k] = x[1] < glue;
        }
        state.grains.external = grains_dem::fluid::forces(&state.grains, fluid).0;
        let area = {
            let g = &state.grains;
            let grains: f64 = (0..g.len()).map(|i| std::f64::consts::PI * g.radius[i].powi(2)).sum();
            grains * (faces[1] - faces[0]) * faces[2] / sample_area
        };
        let love_weber = |pipe: &grains_dem::DemPipeline<D2>, st: &DemState<D2>| {
            let s = crate::calibrate::shear::love_weber(pipe, st, area);
            [s[0], s[1]]
        };
        let mut cut = state.clone();
        training::train(&mut pipes.0, &mut cut, &shell, |_, _| D2::from_array([0.0; 3]), dem_dt, 1);
        untrained = love_weber(&pipes.0, &cut);
        let pipe = &mut pipes.1;
        let steps = (duration / dem_dt).round() as usize;
        state.walls[1].velocity = D2::from_array([0.0, -travel / (steps as f64 * dem_dt), 0.0]);
        training::train(
            pipe,
            &mut state,
            &shell,
            |x, t| {
                let v = history.velocity([x.x, x.y], t);
                D2::from_array([v[0], v[1], 0.0])
            },
            dem_dt,
            steps,
        );
        trained = love_weber(pipe, &state);
        let g = &state.grains;
        let places: HashMap<u64, [f64; 2]> = sample_ids.iter().map(|&i| (g0.id[i], [g0.x[i].x, g0.x[i].y])).collect();
        let inside = (0..g.len()).filter(|&i| g.id[i] < RING);
        trained_grains = inside.clone().map(|i| ([g.x[i].x, g.x[i].y], places[&g.id[i]])).collect();
        inside
            .map(|i| grains_oracle::epoch::NewGrain {
                id: 0,
                x: D2::to_array(g.x[i]),
                radius: g.radius[i],
                v: D2::to_array(g.v[i]),
            })
            .collect()
    };
    let super::super::training::Cut {
        plan, new, before, after, ..
    } = super::super::training::cut_band(at, &packing, phi0, density, Some(&mut train));
    anyhow::ensure!(!new.is_empty(), "the enrichment cut no grains");
    // Each new grain's place in the sample: the trained grain it is (the cut keeps a grain's
    // place, or moves it by less than a diameter out of a grain already there).
    let start: HashMap<u64, [f64; 2]> = new
        .iter()
        .map(|g| {
            let nearest = trained_grains
                .iter()
                .min_by(|a, b| {
                    let d = |p: &[f64; 2]| (p[0] - g.x[0]).powi(2) + (p[1] - g.x[1]).powi(2);
                    d(&a.0).total_cmp(&d(&b.0))
                })
                .map_or([g.x[0], g.x[1]], |t| t.1);
            (g.id, nearest)
        })
        .collect();
    let mut state = sample.clone();
    state.grains = Default::default();
    for g in &new {
        let i = state.grains.push(g.id, D2::from_array(g.x), g.radius, g.mass, material);
        if g.x[1] < glue {
            state.grains.frozen[i] = true;
        } else {
            state.grains.v[i] = D2::from_array(g.v);
        }
    }
    let pipe = grains_dem::DemPipeline::<D2>::new(2)?;
    // The continuum's stress in the same cells (compression positive, volume-weighted).
    let in_region = |x: [f64; 3]| epoch::cell_of(&at.cells, 2, x).is_some_and(|c| plan.zones[c] != Zone::Continuum);
    let continuum = {
        let (mut s, mut v) = ([0.0; 2], 0.0f64);
        for (p, &(tau, vol)) in at.points.iter().zip(stress) {
            if in_region(p.x) {
                s = [s[0] - tau[0] * vol, s[1] - tau[1] * vol];
                v += vol;
            }
        }
        [s[0] / v.max(f64::MIN_POSITIVE), s[1] / v.max(f64::MIN_POSITIVE)]
    };
    let scale = before.0 * speed;
    let grains = BandGrains {
        grains: new.len(),
        deleted: plan.delete_points.len(),
        mass: (after.0 - before.0).abs() / before.0,
        momentum: (0..2).map(|k| (after.1[k] - before.1[k]).abs()).fold(0.0, f64::max) / scale,
        trained,
        untrained,
        continuum,
        start,
        wall: t0.elapsed().as_secs_f64(),
    };
    Ok(((plan, state, pipe), grains))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A linear velocity field on the nodes comes back exactly between them (bilinear
    /// interpolation is exact for it), nodes without mass are left out rather than read as at
    /// rest, and the first record at or after the time asked is the one read.
    #[test]
    fn the_history_interpolates_the_nodes_that_carry_mass() {
        let grid = Grid {
            origin: [-0.01, -0.01, 0.0],
            h: 0.005,
            nodes: [6, 5, 1],
            period: [0, 0, 0],
        };
        let field = |x: f64, y: f64| [0.3 * x - 2.0 * y + 0.01, 1.5 * x + 0.02];
        let at = |i: u64, j: u64| [grid.origin[0] + i as f64 * grid.h, grid.origin[1] + j as f64 * grid.h];
        let record = |scale: f64, empty: Option<(u64, u64)>| -> Nodes {
            (0..grid.nodes[1])
                .flat_map(|j| (0..grid.nodes[0]).map(move |i| (i, j)))
                .map(|(i, j)| {
                    let p = at(i, j);
                    let v = field(p[0], p[1]);
                    if empty == Some((i, j)) {
                        (0.0, [0.0; 2])
                    } else {
                        (1.0, [scale * v[0], scale * v[1]])
                    }
                })
                .collect()
        };
        let history = NodeHistory {
            grid,
            records: vec![(0.0, record(0.0, None)), (1.0, record(1.0, Some((2, 2))))],
        };
        for x in [[0.0062, 0.0081], [-0.0073, 0.0088], [0.013, -0.004]] {
            let v = history.velocity(x, 0.9);
            let want = field(x[0], x[1]);
            for k in 0..2 {
                assert!((v[k] - want[k]).abs() < 1e-12, "{x:?}: {v:?} against {want:?}");
            }
            assert_eq!(history.velocity(x, 0.0), [0.0; 2], "the earlier record is at rest");
        }
        // Beside the empty node (2, 2) at (0, 0): the three others' weights, renormalised; a
        // linear field is then off by what the missing node's weight carried, but never read
        // as the empty node's zero.
        let x = [0.001, 0.001];
        let v = history.velocity(x, 1.0);
        let (w, mut want) = ([(0.8 * 0.2, at(3, 2)), (0.2 * 0.8, at(2, 3)), (0.2 * 0.2, at(3, 3))], [0.0; 2]);
        let total: f64 = w.iter().map(|(w, _)| w).sum();
        for (wk, p) in w {
            let f = field(p[0], p[1]);
            want = [want[0] + wk * f[0] / total, want[1] + wk * f[1] / total];
        }
        assert!(
            (v[0] - want[0]).abs() < 1e-12 && (v[1] - want[1]).abs() < 1e-12,
            "{v:?} against {want:?}"
        );
    }
}
