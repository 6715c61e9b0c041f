//! Verlet neighbour lists built from cell lists, with a skin.
//!
//! Grain pairs closer than r_i + r_j + skin, and grain–wall pairs closer than r + skin, are
//! listed; the list stays valid until some grain (or wall) has moved more than skin/2 since
//! the build. Pairs are listed once (i < j) in grain order, so the list, and everything
//! computed over it, is the same whatever the thread count. Contact history is carried from
//! one list to the next by the pair's grain ids, so it survives any reordering of the arrays.

use crate::contact::ContactState;
use crate::space::{Space, Vector};
use crate::state::{DemState, Grains, WallShape};
use rayon::prelude::*;

/// Contact histories keyed for lookup across a rebuild.
type History<K, V> = Vec<(K, ContactState<V>)>;

/// One listed grain pair and what the last force evaluation left for it.
#[derive(Clone, Copy, Debug, Default, serde::Serialize, serde::Deserialize)]
#[serde(bound = "")]
pub struct PairSlot<S: Space> {
    pub i: u32,
    pub j: u32,
    pub state: ContactState<S::V>,
}

/// One listed grain–wall pair.
#[derive(Clone, Copy, Debug, Default, serde::Serialize, serde::Deserialize)]
#[serde(bound = "")]
pub struct WallSlot<S: Space> {
    pub grain: u32,
    pub wall: u32,
    pub state: ContactState<S::V>,
    pub force: S::V,
    pub couple: S::Ang,
    pub active: bool,
}

#[derive(Clone, Debug, Default, serde::Serialize, serde::Deserialize)]
#[serde(bound = "")]
pub struct NeighborList<S: Space> {
    pub pairs: Vec<PairSlot<S>>,
    pub walls: Vec<WallSlot<S>>,
    /// For grain i, its wall pairs are `walls[wall_offsets[i]..wall_offsets[i+1]]`.
    pub wall_offsets: Vec<u32>,
    x_built: Vec<S::V>,
    /// Grain ids at the last build: the indices stored in the list refer to them.
    ids_built: Vec<u64>,
    wall_anchor_built: Vec<S::V>,
    skin: f64,
    pub builds: u64,
}

/// Separation x_i − x_j with periodic axes wrapped (minimum image).
#[inline]
pub fn separation<S: Space>(xi: S::V, xj: S::V, period: S::V, half: S::V) -> S::V {
    (xi - xj).min_image(period, half)
}

/// The periodic lengths and half lengths (0 on open axes), for [`separation`]. On an open
/// axis the half length is +∞, so that no separation is ever wrapped there.
pub fn periods<S: Space>(state: &DemState<S>) -> (S::V, S::V) {
    let d = &state.params.domain;
    let mut p = [0.0; 3];
    let mut half = [f64::INFINITY; 3];
    for k in 0..S::DIM {
        if d.periodic[k] {
            p[k] = d.length(k);
            half[k] = 0.5 * p[k];
        }
    }
    (S::from_array(p), S::from_array(half))
}

/// Reference point of a wall that moves with it (for the rebuild criterion).
fn wall_anchor<S: Space>(shape: &WallShape<S>) -> S::V {
    match *shape {
        WallShape::Plane { point, .. } => point,
        WallShape::Drum { center, .. } => center,
        WallShape::Segment { a, .. } => a,
    }
}

/// Distance from a grain centre to a wall's surface, positive on the grains' side.
#[inline]
pub fn wall_gap<S: Space>(shape: &WallShape<S>, x: S::V) -> f64 {
    wall_geometry(shape, x, S::V::default(), 0.0).0
}

/// Gap from a grain centre at `x` to the wall surface (positive on the grains' side), the
/// unit normal from the wall to the grain, and the wall's surface velocity at the contact,
/// for a wall translating at `velocity` (and a drum spinning at `spin` about z).
#[inline]
pub fn wall_geometry<S: Space>(shape: &WallShape<S>, x: S::V, velocity: S::V, spin: f64) -> (f64, S::V, S::V) {
    match *shape {
        WallShape::Plane { point, normal } => ((x - point).dot(normal), normal, velocity),
        WallShape::Drum { center, radius } => {
            let mut d = S::to_array(x - center);
            d[2] = 0.0;
            let len = (d[0] * d[0] + d[1] * d[1]).sqrt().max(1e-300);
            let n = S::from_array([-d[0] / len, -d[1] / len, 0.0]);
            let arm = [d[0] / len * radius, d[1] / len * radius];
            (radius - len, n, velocity + S::from_array([-spin * arm[1], spin * arm[0], 0.0]))
        }
        WallShape::Segment { a, b } => {
            let ab = b - a;
            let t = ((x - a).dot(ab) / ab.length_squared().max(1e-300)).clamp(0.0, 1.0);
            let d = x - (a + ab * t);
            let len = d.length().max(1e-300);
            (len, d * (1.0 / len), velocity)
        }
    }
}

/// Grain order along cells (x fastest, then y, then z) of width `cell`: neighbours in space
/// become neighbours in memory. Ties keep index order, so the order is deterministic.
pub fn spatial_order<S: Space>(state: &DemState<S>, cell: f64) -> Vec<u32> {
    let g = &state.grains;
    let mut lo = [f64::MAX; 3];
    let mut hi = [f64::MIN; 3];
    for &x in &g.x {
        let a = S::to_array(x);
        for k in 0..3 {
            lo[k] = lo[k].min(a[k]);
            hi[k] = hi[k].max(a[k]);
        }
    }
    let dims: Vec<u64> = (0..3)
        .map(|k| if k < S::DIM { ((hi[k] - lo[k]) / cell) as u64 + 1 } else { 1 })
        .collect();
    let key = |x: S::V| {
        let a = S::to_array(x);
        let c: Vec<u64> = (0..3)
            .map(|k| if k < S::DIM { ((a[k] - lo[k]) / cell) as u64 } else { 0 })
            .collect();
        (c[2] * dims[1] + c[1]) * dims[0] + c[0]
    };
    let mut order: Vec<u32> = (0..g.len() as u32).collect();
    let keys: Vec<u64> = g.x.iter().map(|&x| key(x)).collect();
    order.sort_by_key(|&i| (keys[i as usize], i));
    order
}

impl<S: Space> NeighborList<S> {
    /// Positions at the last build (empty before the first).
    pub fn positions_at_build(&self) -> &[S::V] {
        &self.x_built
    }

    /// Whether the list must be rebuilt, given the largest squared grain displacement since
    /// the last build: a grain or a wall moved more than skin/2, or the grains or walls changed.
    pub fn needs_rebuild(&self, state: &DemState<S>, moved2: f64) -> bool {
        let limit = (0.5 * self.skin).powi(2);
        self.x_built.len() != state.grains.len()
            || self.wall_anchor_built.len() != state.walls.len()
            || self.skin != state.params.skin
            || moved2 > limit
            || state
                .walls
                .iter()
                .zip(&self.wall_anchor_built)
                .any(|(w, &a)| (wall_anchor(&w.shape) - a).length_squared() > limit)
    }

    /// Whether the list must be rebuilt before the next force evaluation.
    pub fn stale(&self, state: &DemState<S>) -> bool {
        let g = &state.grains;
        if self.x_built.len() != g.len() || self.wall_anchor_built.len() != state.walls.len() || self.skin != state.params.skin {
            return true;
        }
        let (period, half) = periods(state);
        let limit = (0.5 * self.skin).powi(2);
        let grain_moved =
            g.x.par_iter()
                .zip(&self.x_built)
                .with_min_len(4096)
                .any(|(&x, &x0)| separation::<S>(x, x0, period, half).length_squared() > limit);
        grain_moved
            || state
                .walls
                .iter()
                .zip(&self.wall_anchor_built)
                .any(|(w, &a)| (wall_anchor(&w.shape) - a).length_squared() > limit)
    }

    /// Rebuilds the list for the current positions, carrying contact history over by ids.
    pub fn build(&mut self, state: &DemState<S>) {
        let g = &state.grains;
        let r_max = g.radius.iter().copied().fold(0.0, f64::max);
        let grid = CellGrid::new(state, (2.0 * r_max + state.params.skin).max(1e-12));
        let cells: Vec<[usize; 3]> = g.x.par_iter().with_min_len(4096).map(|&x| grid.cell_of::<S>(x)).collect();
        let (start, sorted) = grid.sort_by_cell(&cells);
        let listed = list_pairs(state, &grid, &cells, &start, &sorted);
        self.pairs = self.pairs_with_history(g, &listed);
        (self.walls, self.wall_offsets) = self.list_walls(state);
        self.record_build(state);
    }

    /// The listed pairs with the history the previous list holds for them (looked up by the
    /// pair's grain ids; the spring turned over when their order flipped).
    fn pairs_with_history(&self, g: &Grains<S>, listed: &[(u32, u32)]) -> Vec<PairSlot<S>> {
        // Old pairs that hold something, keyed by (id, id).
        let mut old: History<(u64, u64), S::V> = self
            .pairs
            .iter()
            .filter(|p| p.state != ContactState::default())
            .filter_map(|p| {
                let (a, b) = (*self.ids_built.get(p.i as usize)?, *self.ids_built.get(p.j as usize)?);
                Some(if a < b {
                    ((a, b), p.state)
                } else {
                    (
                        (b, a),
                        ContactState {
                            spring: -p.state.spring,
                            bonded: p.state.bonded,
                        },
                    )
                })
            })
            .collect();
        old.par_sort_unstable_by_key(|e| e.0);
        let lookup = |a: u64, b: u64| -> ContactState<S::V> {
            let (key, flip) = if a < b { ((a, b), false) } else { ((b, a), true) };
            match old.binary_search_by_key(&key, |e| e.0) {
                Ok(k) if flip => ContactState {
                    spring: -old[k].1.spring,
                    bonded: old[k].1.bonded,
                },
                Ok(k) => old[k].1,
                Err(_) => ContactState::default(),
            }
        };
        listed
            .par_iter()
            .with_min_len(4096)
            .map(|&(i, j)| PairSlot {
                i,
                j,
                state: lookup(g.id[i as usize], g.id[j as usize]),
            })
            .collect()
    }

    /// Grain–wall pairs closer than r + skin, by grain then wall index, with the history the
    /// previous list holds for them (by grain id and wall index); and each grain's offsets.
    fn list_walls(&self, state: &DemState<S>) -> (Vec<WallSlot<S>>, Vec<u32>) {
        let g = &state.grains;
        let n = g.len();
        let skin = state.params.skin;
        let mut old_walls: History<(u64, u32), S::V> = self
            .walls
            .iter()
            .filter(|w| w.state != ContactState::default())
            .filter_map(|w| Some(((*self.ids_built.get(w.grain as usize)?, w.wall), w.state)))
            .collect();
        old_walls.sort_unstable_by_key(|e| e.0);
        let mut walls = Vec::new();
        let mut wall_offsets = vec![0u32; n + 1];
        for i in 0..n {
            for (k, w) in state.walls.iter().enumerate() {
                if wall_gap(&w.shape, g.x[i]) < g.radius[i] + skin {
                    let st = old_walls
                        .binary_search_by_key(&(g.id[i], k as u32), |e| e.0)
                        .map_or_else(|_| ContactState::default(), |p| old_walls[p].1);
                    walls.push(WallSlot {
                        grain: i as u32,
                        wall: k as u32,
                        state: st,
                        ..WallSlot::default()
                    });
                }
            }
            wall_offsets[i + 1] = walls.len() as u32;
        }
        (walls, wall_offsets)
    }

    /// What the rebuild criteria and the next history carry compare with.
    fn record_build(&mut self, state: &DemState<S>) {
        let g = &state.grains;
        self.x_built = g.x.clone();
        self.wall_anchor_built = state.walls.iter().map(|w| wall_anchor(&w.shape)).collect();
        self.skin = state.params.skin;
        self.ids_built = g.id.clone();
        self.builds += 1;
    }
}

/// The cell grid of a build, cells at least `cell` wide: periodic axes span the domain (and
/// wrap, given at least 3 cells), open axes span the grains' bounding box.
struct CellGrid {
    lo: [f64; 3],
    dims: [usize; 3],
    wrap: [bool; 3],
    cell_len: [f64; 3],
}

impl CellGrid {
    fn new<S: Space>(state: &DemState<S>, cell: f64) -> Self {
        let g = &state.grains;
        let n = g.len();
        let domain = &state.params.domain;
        let mut lo = [0.0; 3];
        let mut dims = [1usize; 3];
        let mut wrap = [false; 3];
        for k in 0..S::DIM {
            if domain.periodic[k] {
                lo[k] = domain.min[k];
                let cells = (domain.length(k) / cell).floor() as usize;
                // Fewer than 3 cells would list a pair twice through the wrap: one cell then.
                if cells >= 3 {
                    dims[k] = cells;
                    wrap[k] = true;
                }
            } else {
                let (mn, mx) = g.x.iter().fold((f64::MAX, f64::MIN), |(a, b), &x| {
                    let c = S::component(x, k);
                    (a.min(c), b.max(c))
                });
                lo[k] = if n > 0 { mn } else { 0.0 };
                dims[k] = if n > 0 { ((mx - mn) / cell).floor() as usize + 1 } else { 1 };
            }
        }
        let cell_len = [
            if wrap[0] { domain.length(0) / dims[0] as f64 } else { cell },
            if wrap[1] { domain.length(1) / dims[1] as f64 } else { cell },
            if wrap[2] { domain.length(2) / dims[2] as f64 } else { cell },
        ];
        CellGrid { lo, dims, wrap, cell_len }
    }

    /// The cell of a position: wrapped on periodic axes, clamped onto the grid on open ones.
    #[inline]
    fn cell_of<S: Space>(&self, x: S::V) -> [usize; 3] {
        let a = S::to_array(x);
        let mut c = [0usize; 3];
        for k in 0..S::DIM {
            let mut t = (a[k] - self.lo[k]) / self.cell_len[k];
            if self.wrap[k] {
                t = t.rem_euclid(self.dims[k] as f64);
            }
            c[k] = (t.floor().max(0.0) as usize).min(self.dims[k] - 1);
        }
        c
    }

    #[inline]
    fn linear(&self, c: [usize; 3]) -> usize {
        (c[2] * self.dims[1] + c[1]) * self.dims[0] + c[0]
    }

    /// The cell at offset `d` from cell `c`: wrapped on periodic axes, `None` off the grid.
    #[inline]
    fn offset(&self, c: [usize; 3], d: [isize; 3]) -> Option<[usize; 3]> {
        let mut nc = [0usize; 3];
        let mut ok = true;
        for k in 0..3 {
            let t = c[k] as isize + d[k];
            if self.wrap[k] {
                nc[k] = t.rem_euclid(self.dims[k] as isize) as usize;
            } else if t < 0 || t >= self.dims[k] as isize {
                ok = false;
            } else {
                nc[k] = t as usize;
            }
        }
        ok.then_some(nc)
    }

    /// Counting sort of the grains (their `cells`) by cell: the grains of the cell with linear
    /// index `l` are `sorted[start[l]..start[l + 1]]`, in index order.
    fn sort_by_cell(&self, cells: &[[usize; 3]]) -> (Vec<u32>, Vec<u32>) {
        let n_cells = self.dims[0] * self.dims[1] * self.dims[2];
        let mut start = vec![0u32; n_cells + 1];
        for c in cells {
            start[self.linear(*c) + 1] += 1;
        }
        for k in 0..n_cells {
            start[k + 1] += start[k];
        }
        let mut fill = start.clone();
        let mut sorted = vec![0u32; cells.len()];
        for (i, c) in cells.iter().enumerate() {
            let l = self.linear(*c);
            sorted[fill[l] as usize] = i as u32;
            fill[l] += 1;
        }
        (start, sorted)
    }
}

/// Offsets to the 3^d cells around a cell, itself included (x fastest).
fn stencil<S: Space>() -> Vec<[isize; 3]> {
    let r = |k: usize| if k < S::DIM { -1isize..=1 } else { 0..=0 };
    let mut s = Vec::new();
    for dz in r(2) {
        for dy in r(1) {
            for dx in r(0) {
                s.push([dx, dy, dz]);
            }
        }
    }
    s
}

/// Grain pairs (i < j) closer than r_i + r_j + skin, two frozen grains excepted, searched in the
/// stencil of each grain's cell (`cells`, sorted by [`CellGrid::sort_by_cell`]); per chunk of
/// grains in parallel, concatenated in grain order, each grain's partners in index order.
fn list_pairs<S: Space>(state: &DemState<S>, grid: &CellGrid, cells: &[[usize; 3]], start: &[u32], sorted: &[u32]) -> Vec<(u32, u32)> {
    let g = &state.grains;
    let n = g.len();
    let skin = state.params.skin;
    let (period, half) = periods(state);
    let stencil = stencil::<S>();
    const CHUNK: usize = 1024;
    let chunks: Vec<Vec<(u32, u32)>> = (0..n.div_ceil(CHUNK))
        .into_par_iter()
        .map(|chunk| {
            let mut out = Vec::new();
            #[allow(clippy::needless_range_loop)] // i is also the pair's first index
            for i in chunk * CHUNK..((chunk + 1) * CHUNK).min(n) {
                let c = cells[i];
                let (xi, ri) = (g.x[i], g.radius[i]);
                let mut found: Vec<u32> = Vec::new();
                for d in &stencil {
                    let Some(nc) = grid.offset(c, *d) else { continue };
                    let l = grid.linear(nc);
                    for &j in &sorted[start[l] as usize..start[l + 1] as usize] {
                        if (j as usize) <= i || (g.frozen[i] && g.frozen[j as usize]) {
                            continue;
                        }
                        let cut = ri + g.radius[j as usize] + skin;
                        if separation::<S>(xi, g.x[j as usize], period, half).length_squared() < cut * cut {
                            found.push(j);
                        }
                    }
                }
                found.sort_unstable();
                out.extend(found.into_iter().map(|j| (i as u32, j)));
            }
            out
        })
        .collect();
    chunks.into_iter().flatten().collect()
}
