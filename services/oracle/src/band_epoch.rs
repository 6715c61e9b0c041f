//! One enrichment into a shear band (Chen 2021 §4): the cells that the band's zones
//! ([`crate::shear_band::zones`]) make discrete or hybrid take grains cut from a prepared
//! packing, the points of the discrete cells go, and the mass and the momentum of the whole
//! stay what they were.
//!
//! It differs from the surface oracle's epoch ([`crate::epoch`]) where Chen differs from Yue:
//! the zones come from the band, not from the packing; a cell may go from continuum to
//! discrete at once (the grains arrive in the same epoch); a cell never goes back (the band
//! does not heal); and the new grains are a packing prepared beforehand (Chen §6.4: a
//! periodic packing, so a band of any length needs no pour), not grown in place. They arrive
//! at the packing's own state; kinematic training (`grains_dem::training`) then takes them
//! through the continuum's deformation.

use crate::epoch::{
    Inputs, NewGrain, Plan, cell_corner, cell_masses, cell_of, conserve_mass, grain_volume, interpolate, momentum_on_nodes,
};
use crate::{Zone, dims};
use grains_grid::Space;
use std::collections::{BTreeMap, BTreeSet, HashMap};

/// A prepared packing: grains (centre, radius) in the box of size `period` from `min`,
/// periodic along every axis whose period is > 0, so that copies of it side by side neither
/// overlap nor leave a gap. Along an axis of period 0 it is not repeated.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Packing {
    pub min: [f64; 3],
    pub period: [f64; 3],
    pub grains: Vec<([f64; 3], f64)>,
}

impl Packing {
    /// The grains of the packing and of its copies whose centres lie in [`lo`, `hi`].
    pub fn tile(&self, dim: usize, lo: [f64; 3], hi: [f64; 3]) -> Vec<([f64; 3], f64)> {
        let copies = |k: usize| {
            if k < dim && self.period[k] > 0.0 {
                let first = ((lo[k] - self.min[k]) / self.period[k]).floor() as i64;
                let last = ((hi[k] - self.min[k]) / self.period[k]).floor() as i64;
                first..=last
            } else {
                0..=0
            }
        };
        let mut out = Vec::new();
        for iz in copies(2) {
            for iy in copies(1) {
                for ix in copies(0) {
                    let shift = [ix, iy, iz].map(|i| i as f64);
                    for &(x, r) in &self.grains {
                        let y: [f64; 3] = std::array::from_fn(|k| x[k] + shift[k] * self.period[k]);
                        if (0..dim).all(|k| y[k] >= lo[k] && y[k] <= hi[k]) {
                            out.push((y, r));
                        }
                    }
                }
            }
        }
        out
    }
}

/// The zone that holds more grains: continuum < hybrid < discrete.
fn rank(z: Zone) -> u8 {
    match z {
        Zone::Continuum => 0,
        Zone::Hybrid => 1,
        Zone::Discrete => 2,
    }
}

/// Kinematic training of the grains for the cells that need them ([`enrich`]).
pub type Train<'a> = &'a mut dyn FnMut(&BTreeSet<usize>) -> Vec<NewGrain>;

/// One enrichment (Chen 2021 §4) to the zones `band`: every cell takes the more discrete of
/// its previous zone and the band's. Cells that are discrete or hybrid and hold few grains
/// (under half their points' mass), and cells that turn more discrete, get the grains of
/// `packing` whose centres lie in them, clear of the walls by their radius and of every grain
/// already there (one that overlaps those is moved out to touch them); they move with the
/// points' velocity interpolated with the MPM's kernel. The points of discrete cells are
/// deleted. The points that remain take the mass the grains do not carry (the surface
/// epoch's rule, [`conserve_mass`]), and every new grain takes the same small velocity
/// change that makes the total momentum what it was: the interpolated velocities of grains
/// that are heavier or lighter than the points they replace, and the mass moved a cell or
/// two, would otherwise change it. Returns the plan (no new points; `distance` empty: the
/// zones come from the band) and that velocity change. `weight` is the points' share w in a
/// hybrid cell (the grains' 1 − w), `grain_density` the new grains' [kg/m³]. New grains' ids
/// count up from `next_grain_id`.
///
/// With `train`, the new grains are what it returns for the cells that need them (kinematic
/// training, §4.1.1: the packing taken through the continuum's history), kept where their
/// centres lie in those cells, clear of the walls and of the grains there. They too take the
/// points' velocity: the trained velocities (the grains' own, rattling about the continuum's)
/// moved the total momentum by 2.2 cm/s of the new grains' mass on the plate indentation,
/// which the correction then put on every new grain, and the plate's force fell for 10 ms
/// after the enrichment (docs/validation.md).
pub fn enrich<S: Space>(
    input: &Inputs<'_>,
    band: &[Zone],
    packing: &Packing,
    (weight, grain_density): (f64, f64),
    next_grain_id: u64,
    train: Option<Train<'_>>,
) -> (Plan, [f64; 3]) {
    let (cells, dim) = (input.cells, S::DIM);
    let count: usize = dims(cells, dim).iter().product();
    assert_eq!(band.len(), count, "one band zone per cell");
    assert_eq!(input.previous.len(), count, "one previous zone per cell");
    let zones: Vec<Zone> = input
        .previous
        .iter()
        .zip(band)
        .map(|(&a, &b)| if rank(b) > rank(a) { b } else { a })
        .collect();
    let (grain_mass, point_mass) = cell_masses(input, dim);
    // A cell that turns more discrete is filled where its grains leave room (it may hold a
    // band's grains already: its points go, and the room they held would be a void).
    let need: BTreeSet<usize> = (0..count)
        .filter(|&c| {
            zones[c] != Zone::Continuum && point_mass[c] > 0.0 && (grain_mass[c] < 0.5 * point_mass[c] || zones[c] != input.previous[c])
        })
        .collect();
    let zone_at = |x: [f64; 3]| cell_of(cells, dim, x).map_or(Zone::Discrete, |c| zones[c]);
    let mut plan = Plan {
        delete_grains: input
            .grains
            .iter()
            .filter(|g| !g.fixed && zone_at(g.x) == Zone::Continuum)
            .map(|g| g.id)
            .collect(),
        delete_points: input
            .points
            .iter()
            .filter(|p| zone_at(p.x) == Zone::Discrete)
            .map(|p| p.id)
            .collect(),
        zones,
        ..Plan::default()
    };
    plan.new_grains = match train {
        // A trained grain may touch a wall as the training left it (a plate pressing on it);
        // one cut from the packing as it is must clear the walls.
        // Trained grains have settled against the grains there: they touch them, pressed as
        // the continuum is (a contact's overlap is ~1e-3 of a radius at 1 kPa here).
        Some(train) if !need.is_empty() => cut(input, dim, &need, train(&need), (0.5, TRAINED_OVERLAP)),
        Some(_) => Vec::new(),
        None => cut(input, dim, &need, packing_grains(dim, &need, input.cells, packing), (1.0, 0.0)),
    };
    let node_mp = momentum_on_nodes::<S>(input.nodes, input.kernel, input.points.iter().map(|p| (p.x, p.mass, p.v)));
    let none = BTreeMap::new();
    for (i, g) in plan.new_grains.iter_mut().enumerate() {
        g.id = next_grain_id + i as u64;
        g.v = interpolate::<S>(input.nodes, input.kernel, g.x, &node_mp, &none).0;
    }
    conserve_mass(input, dim, weight, grain_density, &mut plan);
    let shift = keep_momentum(input, dim, (weight, grain_density), &mut plan);
    (plan, shift)
}

/// The packing's grains (velocity zero) over the bounding box of the cells `need`.
fn packing_grains(dim: usize, need: &BTreeSet<usize>, cells: &grains_grid::Grid, packing: &Packing) -> Vec<NewGrain> {
    if need.is_empty() {
        return Vec::new();
    }
    let (lo, hi) = bounding_box(cells, dim, need);
    packing
        .tile(dim, lo, hi)
        .into_iter()
        .map(|(x, radius)| NewGrain {
            id: 0,
            x,
            radius,
            v: [0.0; 3],
        })
        .collect()
}

/// Where the material a training must supply started (Chen 2021 §4.1.1: the prepared packing
/// is the material at the start, so the grains for the cells `need` are cut where that
/// material was): the cells of the start positions of the points now in `need` (`moved`: each
/// point's position now and at the start), and a ring of one cell around them (its grains are
/// driven with the continuum's motion, the inner ones move freely). Returns (start, ring).
pub fn training_cells(
    cells: &grains_grid::Grid,
    dim: usize,
    need: &BTreeSet<usize>,
    moved: impl IntoIterator<Item = ([f64; 3], [f64; 3])>,
) -> (BTreeSet<usize>, BTreeSet<usize>) {
    let start: BTreeSet<usize> = moved
        .into_iter()
        .filter(|(now, _)| cell_of(cells, dim, *now).is_some_and(|c| need.contains(&c)))
        .filter_map(|(_, then)| cell_of(cells, dim, then))
        .collect();
    let n = dims(cells, dim);
    let mut ring = BTreeSet::new();
    for &c in &start {
        let ijk = [c % n[0], (c / n[0]) % n[1], c / (n[0] * n[1])];
        let span = |k: usize| if k < dim { -1i64..=1 } else { 0..=0 };
        for dz in span(2) {
            for dy in span(1) {
                for dx in span(0) {
                    let m = [ijk[0] as i64 + dx, ijk[1] as i64 + dy, ijk[2] as i64 + dz];
                    if (0..3).all(|k| m[k] >= 0 && (m[k] as usize) < n[k]) {
                        let d = crate::linear(n, m.map(|v| v as usize));
                        if !start.contains(&d) {
                            ring.insert(d);
                        }
                    }
                }
            }
        }
    }
    (start, ring)
}

/// The box around the cells `set`.
pub fn bounding_box(cells: &grains_grid::Grid, dim: usize, set: &BTreeSet<usize>) -> ([f64; 3], [f64; 3]) {
    let n = dims(cells, dim);
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for &c in set {
        let corner = cell_corner(cells, n, c);
        for k in 0..3 {
            lo[k] = lo[k].min(corner[k]);
            hi[k] = hi[k].max(if k < dim { corner[k] + cells.h } else { corner[k] });
        }
    }
    (lo, hi)
}

/// Of `candidates`, the grains whose centres lie in the cells `need`, `clear` × their radius
/// from the walls, overlapping no grain of `input` by more than `allow` × the smaller radius;
/// one that does is moved out to touch them, if it then still fits.
fn cut(input: &Inputs<'_>, dim: usize, need: &BTreeSet<usize>, candidates: Vec<NewGrain>, (clear, allow): (f64, f64)) -> Vec<NewGrain> {
    let cells = input.cells;
    if need.is_empty() {
        return Vec::new();
    }
    let (lo, hi) = bounding_box(cells, dim, need);
    // The grains already there, hashed by cells of the largest diameter.
    let r_max = candidates
        .iter()
        .map(|g| g.radius)
        .chain(input.grains.iter().map(|g| g.radius))
        .fold(0.0, f64::max);
    let size = 2.0 * r_max;
    let key = |x: [f64; 3]| -> [i64; 3] { std::array::from_fn(|k| if k < dim { (x[k] / size).floor() as i64 } else { 0 }) };
    let mut there: HashMap<[i64; 3], Vec<([f64; 3], f64)>> = HashMap::new();
    for g in input.grains {
        if (0..dim).all(|k| g.x[k] >= lo[k] - size && g.x[k] <= hi[k] + size) {
            there.entry(key(g.x)).or_default().push((g.x, g.radius));
        }
    }
    // The deepest overlap of a disk (x, r) with the grains in `there`: (their centre, radius).
    let deepest = |there: &HashMap<[i64; 3], Vec<([f64; 3], f64)>>, x: [f64; 3], r: f64| {
        let c = key(x);
        let span = |k: usize| if k < dim { -1..=1 } else { 0..=0 };
        let mut worst: Option<(f64, [f64; 3], f64)> = None;
        for dz in span(2) {
            for dy in span(1) {
                for dx in span(0) {
                    for &(y, s) in there.get(&[c[0] + dx, c[1] + dy, c[2] + dz]).into_iter().flatten() {
                        let overlap = r + s - (0..dim).map(|k| (x[k] - y[k]).powi(2)).sum::<f64>().sqrt();
                        if overlap > allow * r.min(s) && worst.is_none_or(|w| overlap > w.0) {
                            worst = Some((overlap, y, s));
                        }
                    }
                }
            }
        }
        worst.map(|w| (w.1, w.2))
    };
    let fits = |x: [f64; 3], r: f64| cell_of(cells, dim, x).is_some_and(|c| need.contains(&c)) && (input.clearance)(x) >= clear * r;
    let (mut kept, mut refused) = (Vec::new(), Vec::new());
    for g in candidates.into_iter().filter(|g| fits(g.x, g.radius)) {
        if deepest(&there, g.x, g.radius).is_none() {
            kept.push(g);
        } else {
            refused.push(g);
        }
    }
    // A candidate that overlaps the grains already there is moved out of them, to touch the
    // one it overlaps most, a few times over; kept if it then fits and overlaps nothing. Two
    // packings meeting leave a seam of voids half a grain wide otherwise, and the old grains
    // settle into it (the plate indentation lost its contact for 0.26 mm of travel).
    for g in &kept {
        there.entry(key(g.x)).or_default().push((g.x, g.radius));
    }
    for mut g in refused {
        for _ in 0..PUSH_TRIES {
            let Some((y, s)) = deepest(&there, g.x, g.radius) else { break };
            let d: [f64; 3] = std::array::from_fn(|k| if k < dim { g.x[k] - y[k] } else { 0.0 });
            let length = d.iter().map(|c| c * c).sum::<f64>().sqrt();
            if length == 0.0 {
                break;
            }
            let reach = (g.radius + s) * (1.0 + 1e-9);
            g.x = std::array::from_fn(|k| if k < dim { y[k] + d[k] / length * reach } else { g.x[k] });
        }
        if fits(g.x, g.radius) && deepest(&there, g.x, g.radius).is_none() {
            there.entry(key(g.x)).or_default().push((g.x, g.radius));
            kept.push(g);
        }
    }
    kept
}

/// The overlap with a grain already there that a trained grain may keep, as a fraction of the
/// smaller radius.
pub const TRAINED_OVERLAP: f64 = 0.01;

/// How many times [`cut`] moves a candidate out of the grain it overlaps most.
const PUSH_TRIES: usize = 4;

/// The velocity change of every new grain that keeps the total momentum, as the solvers
/// weigh it (grains 1 − w, points w in hybrid cells), what it was before `plan`; applied to
/// `plan.new_grains` and returned (zero when there are none).
fn keep_momentum(input: &Inputs<'_>, dim: usize, (weight, grain_density): (f64, f64), plan: &mut Plan) -> [f64; 3] {
    let zones = &plan.zones;
    let at = |x: [f64; 3]| cell_of(input.cells, dim, x).map_or(Zone::Discrete, |c| zones[c]);
    let grain_share = |x| if at(x) == Zone::Hybrid { 1.0 - weight } else { 1.0 };
    let point_share = |x| if at(x) == Zone::Hybrid { weight } else { 1.0 };
    let gone_g: BTreeSet<u64> = plan.delete_grains.iter().copied().collect();
    let gone_p: BTreeSet<u64> = plan.delete_points.iter().copied().collect();
    let factor: BTreeMap<u64, f64> = plan.scale_points.iter().copied().collect();
    let mut missing = [0.0; 3];
    let mut add = |m: f64, v: [f64; 3]| (0..3).for_each(|k| missing[k] += m * v[k]);
    for g in input.grains.iter().filter(|g| !g.fixed) {
        add(g.share * g.mass, g.v);
        if !gone_g.contains(&g.id) {
            add(-grain_share(g.x) * g.mass, g.v);
        }
    }
    for p in input.points {
        add(p.share * p.mass, p.v);
        if !gone_p.contains(&p.id) {
            add(-point_share(p.x) * p.mass * factor.get(&p.id).copied().unwrap_or(1.0), p.v);
        }
    }
    let mut new_mass = 0.0;
    for g in &plan.new_grains {
        let m = grain_share(g.x) * grain_density * grain_volume(dim, g.radius);
        add(-m, g.v);
        new_mass += m;
    }
    if new_mass <= 0.0 {
        return [0.0; 3];
    }
    let shift = missing.map(|p| p / new_mass);
    for g in plan.new_grains.iter_mut() {
        (0..3).for_each(|k| g.v[k] += shift[k]);
    }
    shift
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::epoch::tests::{H, R, apply, block_of_points, grids, settings, totals};
    use crate::epoch::{Grain, Point};
    use crate::shear_band::zones;
    use grains_grid::{D2, Grid, Kernel};

    /// The training's cells follow the material back to where it started: points moved by
    /// one and a half cells in x and half a cell down (their start positions, three per cell
    /// and axis) now in a block of 3 × 2 cells started in the 4 × 3 cells that block spans
    /// shifted back; the ring is the 8 neighbours of those and no cell of them; points not
    /// in the block are not followed. In 3D the same with a block of one cell: the ring is
    /// its 26 neighbours.
    #[test]
    fn the_training_starts_where_the_material_was() {
        let h = 1.0;
        let cells = Grid {
            origin: [0.0; 3],
            h,
            nodes: [12, 10, 1],
            period: [0, 0, 0],
        };
        let index = |i: usize, j: usize| j * 12 + i;
        let need: BTreeSet<usize> = [(6, 5), (7, 5), (8, 5), (6, 6), (7, 6), (8, 6)].map(|(i, j)| index(i, j)).into();
        let shift = [1.5 * h, -0.5 * h, 0.0];
        let moved: Vec<([f64; 3], [f64; 3])> = (0..36)
            .flat_map(|a| (0..30).map(move |b| [(a as f64 + 0.5) * h / 3.0, (b as f64 + 0.5) * h / 3.0, 0.0]))
            .map(|now| (now, [now[0] - shift[0], now[1] - shift[1], 0.0]))
            .collect();
        let (start, ring) = training_cells(&cells, 2, &need, moved);
        // x from [6, 9) back 1.5 → [4.5, 7.5): cells 4..=7; y from [5, 7) up 0.5 → [5.5, 7.5): 5..=7.
        let want: BTreeSet<usize> = (4..=7).flat_map(|i| (5..=7).map(move |j| index(i, j))).collect();
        assert_eq!(start, want);
        let around: BTreeSet<usize> = (3..=8)
            .flat_map(|i| (4..=8).map(move |j| index(i, j)))
            .filter(|c| !want.contains(c))
            .collect();
        assert_eq!(ring, around);

        let cells = Grid { nodes: [5, 5, 5], ..cells };
        let need: BTreeSet<usize> = [2 * 25 + 2 * 5 + 2].into();
        let (start, ring) = training_cells(&cells, 3, &need, [([2.5, 2.5, 2.5], [1.5, 2.5, 2.5])]);
        assert_eq!(start, [2 * 25 + 2 * 5 + 1].into());
        assert_eq!(ring.len(), 26);
        assert!(!ring.contains(&(2 * 25 + 2 * 5 + 1)));
    }

    /// Shear rate of the continuum [1/s] about y = 16 mm, and its uniform vertical velocity.
    const RATE: f64 = 10.0;
    const VY: f64 = 0.05;

    fn velocity(x: [f64; 3]) -> [f64; 3] {
        [RATE * (x[1] - 0.016), VY, 0.0]
    }

    /// A triangular lattice of radius-R disks, spacing 2.2 R (packing fraction 0.75, under the
    /// continuum's 0.82: the grains carry less mass than the points they replace), rows
    /// `a √3 / 2` apart, the odd ones shifted by a / 2: periodic over 10 × 12 sites, its box off
    /// the grid's lines.
    fn lattice() -> (Packing, f64, f64) {
        let (a, (nx, ny)) = (2.2 * R, (10, 12));
        let dy = a * 3f64.sqrt() / 2.0;
        let min = [0.37e-3, 0.91e-3, 0.0];
        let site = |i: i64, j: i64| {
            [
                min[0] + (i as f64 + 0.5 * (j.rem_euclid(2)) as f64) * a,
                min[1] + j as f64 * dy,
                0.0,
            ]
        };
        let grains = (0..ny).flat_map(|j| (0..nx).map(move |i| (site(i, j), R))).collect();
        let packing = Packing {
            min,
            period: [nx as f64 * a, ny as f64 * dy, 0.0],
            grains,
        };
        (packing, a, dy)
    }

    fn flagged_rows(cells: &Grid, rows: &[usize]) -> Vec<bool> {
        let nx = cells.nodes[0] as usize;
        (0..nx * cells.nodes[1] as usize).map(|c| rows.contains(&(c / nx))).collect()
    }

    static NO_STRESS: BTreeMap<u64, [[f64; 3]; 3]> = BTreeMap::new();

    fn inputs<'a>(nodes: &'a Grid, cells: &'a Grid, previous: &'a [Zone], grains: &'a [Grain], points: &'a [Point]) -> Inputs<'a> {
        Inputs {
            nodes,
            kernel: Kernel::Gimp { half_width: 0.25 * H },
            cells,
            previous,
            solid: &[],
            clearance: &|_| f64::INFINITY,
            grains,
            points,
            stress: &NO_STRESS,
        }
    }

    fn assert_no_overlaps(grains: &[Grain]) {
        for (i, a) in grains.iter().enumerate() {
            for b in &grains[i + 1..] {
                let d = ((a.x[0] - b.x[0]).powi(2) + (a.x[1] - b.x[1]).powi(2)).sqrt();
                assert!(
                    d >= a.radius + b.radius - 1e-12,
                    "grains {} and {} overlap by {}",
                    a.id,
                    b.id,
                    a.radius + b.radius - d
                );
            }
        }
    }

    fn assert_kept(before: (f64, [f64; 3]), after: (f64, [f64; 3]), speed: f64) {
        assert!((after.0 - before.0).abs() < 1e-12 * before.0, "mass {} -> {}", before.0, after.0);
        for k in 0..3 {
            let change = (after.1[k] - before.1[k]).abs();
            assert!(change < 1e-12 * before.0 * speed, "momentum {:?} -> {:?}", before.1, after.1);
        }
    }

    /// A continuum 48 × 32 mm (points 1 mm apart) sheared about y = 16 mm (v_x = γ̇ (y − 16
    /// mm), v_y uniform), its band flagged along the cell row 16–18 mm, φ0 = 5 mm, overlap one
    /// cell: the rows within 3.5 mm of it turn discrete and those 3.5–5.5 mm away hybrid.
    /// - Epoch 1: every such cell takes exactly the lattice's sites in it (counted from the
    ///   lattice's formula, not from the tiling: copies neither dropped nor doubled), none
    ///   overlapping; no point is left in a discrete cell; the mass and the momentum are the
    ///   same to round-off; the grains move with the continuum's linear velocity, to the
    ///   momentum's velocity change, which is under γ̇ d (the grains' centre of mass lies within
    ///   a grain of the points').
    /// - Epoch 2: the band widens by a row after the grains moved 0.3 spacing sideways (those off the
    ///   grid dropped): the new grains keep clear of the old ones, and mass and momentum are kept again.
    #[test]
    fn enrichment_into_a_band_keeps_mass_and_momentum_to_round_off() {
        let (nodes, cells) = grids();
        let count = (cells.nodes[0] * cells.nodes[1]) as usize;
        let s = settings();
        let speed = RATE * 0.016;
        let mut points = block_of_points(48, 32, velocity);
        let mut grains: Vec<Grain> = Vec::new();
        let (packing, a, dy) = lattice();
        let band = zones(&cells, 2, &flagged_rows(&cells, &[8]), 0.0045, H);
        let previous = vec![Zone::Continuum; count];
        let before = totals(&cells, &previous, &grains, &points, true);
        let (plan, shift) = enrich::<D2>(
            &inputs(&nodes, &cells, &previous, &grains, &points),
            &band,
            &packing,
            (s.weight, s.grain_density),
            100,
            None,
        );
        assert_eq!(plan.zones, band);
        let row_zone = |row: usize| band[row * cells.nodes[0] as usize];
        let rows: Vec<Zone> = (0..16).map(row_zone).collect();
        use Zone::{Continuum as C, Discrete as D, Hybrid as Y};
        assert_eq!(rows, [C, C, C, C, C, C, Y, D, D, D, Y, C, C, C, C, C], "zones by row");
        // The lattice's sites (i, j) in the cells that turned, from its formula.
        let (lo, hi) = (6.0 * H, 11.0 * H);
        let mut expected = 0;
        for j in -50..50i64 {
            let y = packing.min[1] + j as f64 * dy;
            for i in -50..100i64 {
                let x = packing.min[0] + (i as f64 + 0.5 * j.rem_euclid(2) as f64) * a;
                if (lo..hi).contains(&y) && (0.0..0.048).contains(&x) {
                    expected += 1;
                }
            }
        }
        assert_eq!(plan.new_grains.len(), expected, "new grains against the lattice's sites");
        assert!(plan.unplaced.abs() < 1e-15 * before.0, "unplaced mass {}", plan.unplaced);
        let norm = (shift[0].powi(2) + shift[1].powi(2)).sqrt();
        eprintln!(
            "epoch 1: {} grains, {} points deleted, velocity change {:.3e} m/s",
            expected,
            plan.delete_points.len(),
            norm
        );
        // The grains' centre of mass is not the points' (a lattice row is 0.95 mm): under a
        // grain diameter of it, the change is under the continuum's velocity across one grain.
        assert!(
            norm > 0.0 && norm < RATE * 2.0 * R,
            "velocity change {shift:?} against γ̇ d = {}",
            RATE * 2.0 * R
        );
        for g in &plan.new_grains {
            let want = velocity(g.x);
            let off = ((g.v[0] - want[0]).powi(2) + (g.v[1] - want[1]).powi(2)).sqrt();
            assert!(off < norm + 1e-9, "grain at {:?}: {:?} against {want:?}", g.x, g.v);
        }
        apply(&cells, &plan, &mut grains, &mut points);
        assert_no_overlaps(&grains);
        assert_kept(before, totals(&cells, &plan.zones, &grains, &points, true), speed);

        grains.iter_mut().for_each(|g| g.x[0] += 0.3 * a);
        grains.retain(|g| g.x[0] < 0.048);
        let previous = plan.zones.clone();
        let before = totals(&cells, &previous, &grains, &points, true);
        let band = zones(&cells, 2, &flagged_rows(&cells, &[8, 9]), 0.0045, H);
        let (two, _) = enrich::<D2>(
            &inputs(&nodes, &cells, &previous, &grains, &points),
            &band,
            &packing,
            (s.weight, s.grain_density),
            10_000,
            None,
        );
        assert!(!two.new_grains.is_empty());
        for g in &two.new_grains {
            let c = cell_of(&cells, 2, g.x).unwrap();
            assert_ne!(two.zones[c], Zone::Continuum, "a new grain in a continuum cell");
        }
        apply(&cells, &two, &mut grains, &mut points);
        assert_no_overlaps(&grains);
        assert_kept(before, totals(&cells, &two.zones, &grains, &points, true), speed);
    }
}
