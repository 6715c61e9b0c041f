//! Zones of hybrid bodies: the field of zones on grid cells that the oracle publishes
//! ([`ZoneField`]) and the layered zones it computes from the scene (layered hybridization,
//! Yue 2018 §4.3): grains in a layer of `coupling.discrete_layer` under a body's free faces,
//! then a band of `coupling.hybrid_band` where grains and material points overlap and are
//! coupled, points only below. Zones are fixed to the material (every grain and point keeps the
//! zone it was created in) until the adaptive oracle moves them.
//!
//! Both solvers classify their material by the cell it lies in, so that grains and points agree
//! on every boundary.

use grains_grid::Grid;
use grains_protocol::scene::{Body, Model, OracleKind, Scene, Shape, WallShape};
use grains_protocol::wire::{Zone, ZoneCell};

/// Whether the face of a box body on `axis` (the low face when `low`) at coordinate `at` rests
/// on a plane or box wall, on a segment lying in it (a silo bottom, orifice included), or on
/// the domain's own wall layers (within one cell).
fn supported(scene: &Scene, axis: usize, low: bool, at: f64) -> bool {
    let h = scene.domain.cell_size;
    let near = |c: f64| (c - at).abs() <= h;
    let domain_face = if low { scene.domain.min[axis] } else { scene.domain.max[axis] };
    if (domain_face - at).abs() <= 3.0 * h {
        return true;
    }
    scene.walls.iter().any(|w| match w.shape {
        WallShape::Plane { point, normal } => {
            let inward = if low { normal[axis] } else { -normal[axis] };
            inward > 0.99 && near(point[axis])
        }
        WallShape::Box { min, max } => near(if low { min[axis] } else { max[axis] }),
        WallShape::Segment { from, to } => near(from[axis]) && near(to[axis]),
        WallShape::Drum { .. } => false,
    })
}

/// Depth of `x` below the free surface of `body` [m]: the distance to the nearest face not
/// resting on a wall (a box), or to the surface (a ball). Infinite when every face rests.
pub fn depth(scene: &Scene, body: &Body, x: [f64; 3]) -> f64 {
    match body.shape {
        Shape::Box { min, max } => {
            let mut d = f64::INFINITY;
            for k in 0..scene.dim() {
                if !supported(scene, k, true, min[k]) {
                    d = d.min(x[k] - min[k]);
                }
                if !supported(scene, k, false, max[k]) {
                    d = d.min(max[k] - x[k]);
                }
            }
            d
        }
        Shape::Ball { center, radius } => radius - (0..scene.dim()).map(|k| (x[k] - center[k]).powi(2)).sum::<f64>().sqrt(),
    }
}

/// Height of `x` over the faces of `body` that rest on a wall or the domain's edge (periodic
/// axes excepted) [m]; infinite for a ball or a box resting on nothing.
fn height(scene: &Scene, body: &Body, x: [f64; 3]) -> f64 {
    let Shape::Box { min, max } = body.shape else {
        return f64::INFINITY;
    };
    let mut d = f64::INFINITY;
    for k in (0..scene.dim()).filter(|&k| !scene.domain.periodic[k]) {
        if supported(scene, k, true, min[k]) {
            d = d.min(x[k] - min[k]);
        }
        if supported(scene, k, false, max[k]) {
            d = d.min(max[k] - x[k]);
        }
    }
    d
}

/// The depth that decides the layered zone of `x`: its depth under the free faces, or, with
/// `coupling.discrete_base`, its height over the resting faces shifted so that the base layer
/// reads as the discrete layer and the band over it as the band.
fn zone_depth(scene: &Scene, body: &Body, x: [f64; 3]) -> f64 {
    let d = depth(scene, body, x);
    let base = scene.coupling.discrete_base;
    if base > 0.0 {
        d.min(height(scene, body, x) - base + band(scene).0)
    } else {
        d
    }
}

/// The layered zone of material at `x` in a hybrid `body`.
pub fn layered_zone(scene: &Scene, body: &Body, x: [f64; 3]) -> Zone {
    zone_of_depth(scene, zone_depth(scene, body, x))
}

/// Depths [m] where the hybrid band begins and ends: `coupling.discrete_layer` and
/// `+ hybrid_band`, or a surface oracle's own band (`oracle.centre` ± `oracle.half_width`)
/// when the scene sets one, so that its run starts from the zones it keeps.
pub fn band(scene: &Scene) -> (f64, f64) {
    let c = &scene.coupling;
    let (mut centre, mut half) = (c.discrete_layer + 0.5 * c.hybrid_band, 0.5 * c.hybrid_band);
    if let Some(o) = scene.oracle.as_ref().filter(|o| o.kind.adaptive()) {
        centre = o.centre.unwrap_or(centre);
        half = o.half_width.unwrap_or(half);
    }
    (centre - half, centre + half)
}

fn zone_of_depth(scene: &Scene, d: f64) -> Zone {
    let (begin, end) = band(scene);
    if d < begin {
        Zone::Discrete
    } else if d < end {
        Zone::Hybrid
    } else {
        Zone::Continuum
    }
}

/// The zone of every listed cell of the scene's grid; material in a cell not listed is
/// discrete. Cells are numbered like nodes, on a grid of one node less per axis (cell
/// `(i, j, k)` spans nodes `(i, j, k)` to `(i+1, j+1, k+1)`).
#[derive(Clone, Debug, PartialEq)]
pub struct ZoneField {
    cells: Grid,
    /// Sorted by cell.
    zones: Vec<ZoneCell>,
}

impl ZoneField {
    /// The layered zones of the scene's hybrid bodies (what the oracle publishes at start):
    /// every cell that overlaps a hybrid body's bounding box, with the zone at its centre.
    /// Where bodies overlap, the most discrete zone wins.
    /// With `oracle.kind = "shear_band"` every cell of the grid is continuum instead (Chen 2021:
    /// the run starts as a continuum, grains come only where a band forms).
    pub fn layered(scene: &Scene) -> Self {
        let (grid, _) = crate::grid::scene_grid(scene);
        let cells = cell_grid(&grid, scene.dim());
        if scene.oracle.as_ref().is_some_and(|o| o.kind == OracleKind::ShearBand) {
            let zones = (0..cells.nodes.iter().product::<u64>())
                .map(|cell| ZoneCell {
                    cell,
                    zone: Zone::Continuum as u32,
                    _pad: 0,
                    distance: f64::INFINITY,
                })
                .collect();
            return ZoneField { cells, zones };
        }
        // Interface in the middle of the band: negative on the discrete side.
        let (begin, end) = band(scene);
        let interface = 0.5 * (begin + end);
        let mut by_cell = std::collections::BTreeMap::<u64, f64>::new();
        for body in scene.bodies.iter().filter(|b| b.model == Model::Hybrid) {
            let (lo, hi) = bounds(scene, body);
            let first = |k: usize| (((lo[k] - cells.origin[k]) / cells.h).floor() as i64).max(0);
            let last = |k: usize| (((hi[k] - cells.origin[k]) / cells.h).floor() as i64).min(cells.nodes[k] as i64 - 1);
            for k3 in first(2)..=last(2) {
                for j in first(1)..=last(1) {
                    for i in first(0)..=last(0) {
                        let ijk = [i, j, k3];
                        let Some(cell) = cells.index(ijk) else { continue };
                        let mut x = cells.position(ijk);
                        for xk in x.iter_mut().take(scene.dim()) {
                            *xk += 0.5 * cells.h;
                        }
                        let d = zone_depth(scene, body, x) - interface;
                        by_cell.entry(cell).and_modify(|e| *e = e.min(d)).or_insert(d);
                    }
                }
            }
        }
        let zones = by_cell
            .into_iter()
            .map(|(cell, distance)| ZoneCell {
                cell,
                zone: zone_of_depth(scene, distance + interface) as u32,
                _pad: 0,
                distance,
            })
            .collect();
        ZoneField { cells, zones }
    }

    /// A field received from the oracle (cells sorted by index, as the protocol requires).
    pub fn from_cells(scene: &Scene, zones: &[ZoneCell]) -> Result<Self, String> {
        let (grid, _) = crate::grid::scene_grid(scene);
        let cells = cell_grid(&grid, scene.dim());
        let n = cells.nodes.iter().product::<u64>();
        for (i, z) in zones.iter().enumerate() {
            if z.cell >= n {
                return Err(format!("zone cell {i}: cell index {} outside the grid's {n} cells", z.cell));
            }
            if i > 0 && zones[i - 1].cell >= z.cell {
                return Err(format!(
                    "zone cell {i}: cell indices must increase strictly ({} after {})",
                    z.cell,
                    zones[i - 1].cell
                ));
            }
            if Zone::from_code(z.zone).is_none() {
                return Err(format!("zone cell {i}: zone code {} is not 0, 1 or 2", z.zone));
            }
        }
        Ok(ZoneField {
            cells,
            zones: zones.to_vec(),
        })
    }

    /// The cells as the oracle sends them.
    pub fn cells(&self) -> &[ZoneCell] {
        &self.zones
    }

    /// The zone of material at `x`: the zone of its cell; discrete outside the listed cells.
    pub fn zone_at(&self, x: [f64; 3]) -> Zone {
        let ijk = [0, 1, 2].map(|k| ((x[k] - self.cells.origin[k]) / self.cells.h).floor() as i64);
        let ijk = [0, 1, 2].map(|k| if self.cells.nodes[k] == 1 { 0 } else { ijk[k] });
        let Some(cell) = self.cells.index(ijk) else {
            return Zone::Discrete;
        };
        match self.zones.binary_search_by_key(&cell, |z| z.cell) {
            Ok(i) => Zone::from_code(self.zones[i].zone).unwrap_or(Zone::Discrete),
            Err(_) => Zone::Discrete,
        }
    }

    /// The grid of the cells (one node less per used axis than the MPM grid).
    pub fn cell_grid(&self) -> &Grid {
        &self.cells
    }

    /// The zone of every cell, x fastest (discrete where not listed).
    pub fn dense(&self) -> Vec<Zone> {
        let mut out = vec![Zone::Discrete; self.cells.nodes.iter().product::<u64>() as usize];
        for z in &self.zones {
            out[z.cell as usize] = Zone::from_code(z.zone).unwrap_or(Zone::Discrete);
        }
        out
    }

    /// Number of listed cells in `zone`.
    pub fn count(&self, zone: Zone) -> usize {
        self.zones.iter().filter(|z| Zone::from_code(z.zone) == Some(zone)).count()
    }
}

/// The cells of a node grid, as a grid of their own (one node less per used axis).
fn cell_grid(grid: &Grid, dim: usize) -> Grid {
    let mut cells = *grid;
    for k in 0..dim {
        cells.nodes[k] = (grid.nodes[k] - 1).max(1);
    }
    cells
}

/// Bounding box of a body.
fn bounds(scene: &Scene, body: &Body) -> ([f64; 3], [f64; 3]) {
    match body.shape {
        Shape::Box { min, max } => (min, max),
        Shape::Ball { center, radius } => {
            let (mut lo, mut hi) = (center, center);
            for k in 0..scene.dim() {
                lo[k] -= radius;
                hi[k] += radius;
            }
            (lo, hi)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const SCENE: &str = r#"
schema = 1
[run]
dimension = 2
dt = 1e-5
steps = 1
[domain]
min = [-0.006, -0.006]
max = [0.1, 0.1]
cell_size = 0.002
[[material]]
name = "m"
density = 2500.0
[material.dem]
radius = 5e-4
stiffness_normal = 1e6
restitution = 0.5
friction = 0.5
[material.mpm]
young = 1e6
poisson = 0.3
friction_angle = 20.0
packing = 0.8
[[body]]
material = "m"
model = "hybrid"
shape = "box"
min = [0.0, 0.0015]
max = [0.04, 0.0815]
[[body]]
material = "m"
model = "hybrid"
shape = "ball"
center = [0.07, 0.05]
radius = 0.01
[[wall]]
kind = "plane"
point = [0.0, 0.0]
normal = [0.0, 1.0]
[[wall]]
kind = "plane"
point = [0.0, 0.0]
normal = [1.0, 0.0]
[coupling]
discrete_layer = 0.004
hybrid_band = 0.003
"#;

    fn scene() -> Scene {
        scene_of(SCENE)
    }

    fn scene_of(text: &str) -> Scene {
        // One file per call: the tests run in parallel threads of one process.
        static N: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
        let n = N.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let path = std::env::temp_dir().join(format!("grains-zones-{}-{n}.toml", std::process::id()));
        std::fs::write(&path, text).unwrap();
        let s = grains_protocol::scene::load(&path).unwrap();
        std::fs::remove_file(&path).unwrap();
        s
    }

    /// The column rests on the floor (0.0015 m above the plane, within a cell) and leans on the
    /// left wall: its depth is measured from the top and the right face only.
    #[test]
    fn depth_counts_free_faces_only() {
        let s = scene();
        let column = &s.bodies[0];
        // Near the floor and the left wall, far from the free faces.
        assert!((depth(&s, column, [0.001, 0.002, 0.0]) - 0.039).abs() < 1e-12);
        // 1 mm under the top.
        assert!((depth(&s, column, [0.01, 0.0805, 0.0]) - 0.001).abs() < 1e-12);
        assert_eq!(layered_zone(&s, column, [0.01, 0.0805, 0.0]), Zone::Discrete);
        // 5 mm from the right face: in the band (4 to 7 mm); 8 mm: continuum.
        assert_eq!(layered_zone(&s, column, [0.035, 0.04, 0.0]), Zone::Hybrid);
        assert_eq!(layered_zone(&s, column, [0.032, 0.04, 0.0]), Zone::Continuum);
        // A disk: depth from its circle.
        let disk = &s.bodies[1];
        assert!((depth(&s, disk, [0.07, 0.05, 0.0]) - 0.01).abs() < 1e-12);
        assert_eq!(layered_zone(&s, disk, [0.078, 0.05, 0.0]), Zone::Discrete);
        assert_eq!(layered_zone(&s, disk, [0.075, 0.05, 0.0]), Zone::Hybrid);
        assert_eq!(layered_zone(&s, disk, [0.071, 0.05, 0.0]), Zone::Continuum);
    }

    /// The oracle's field gives every cell of a hybrid body the layer at its centre, and
    /// material takes the zone of its cell; a field that went over the wire reads the same.
    #[test]
    fn layered_field_classifies_by_cell() {
        let s = scene();
        let f = ZoneField::layered(&s);
        // Cell 2 mm wide from -6 mm: the cell [30, 32] x [40, 42] mm of the column has its centre
        // 9 mm from the right face (continuum); [34, 36] 5 mm (hybrid); [38, 40] 1 mm (discrete).
        assert_eq!(f.zone_at([0.0301, 0.041, 0.0]), Zone::Continuum);
        assert_eq!(f.zone_at([0.0319, 0.041, 0.0]), Zone::Continuum);
        assert_eq!(f.zone_at([0.0341, 0.041, 0.0]), Zone::Hybrid);
        assert_eq!(f.zone_at([0.0399, 0.041, 0.0]), Zone::Discrete);
        // Outside every hybrid body: discrete.
        assert_eq!(f.zone_at([0.09, 0.09, 0.0]), Zone::Discrete);
        // The signed distance is negative on the discrete side (interface at 5.5 mm depth).
        let cell = |x: [f64; 3]| {
            f.cells()
                .iter()
                .find(|z| {
                    z.cell
                        == f.cells
                            .index([0, 1, 2].map(|k| if k == 2 { 0 } else { ((x[k] + 0.006) / 0.002).floor() as i64 }))
                            .unwrap()
                })
                .copied()
                .unwrap()
        };
        assert!((cell([0.0391, 0.041, 0.0]).distance - (0.001 - 0.0055)).abs() < 1e-12);
        assert!((cell([0.0301, 0.041, 0.0]).distance - (0.009 - 0.0055)).abs() < 1e-12);
        // Every layer is present and the round trip keeps the field.
        assert!(f.count(Zone::Discrete) > 0 && f.count(Zone::Hybrid) > 0 && f.count(Zone::Continuum) > 0);
        assert_eq!(ZoneField::from_cells(&s, f.cells()).unwrap(), f);
        let mut bad = f.cells().to_vec();
        bad.swap(0, 1);
        assert!(ZoneField::from_cells(&s, &bad).unwrap_err().contains("increase strictly"));
    }

    /// `coupling.discrete_base` keeps grains over the faces the column rests on (the floor and
    /// the left wall), with the band over them; the free faces keep their own layer.
    #[test]
    fn a_discrete_base_lines_the_resting_faces() {
        let s = scene_of(&SCENE.replace("hybrid_band = 0.003\n", "hybrid_band = 0.003\ndiscrete_base = 0.002\n"));
        assert_eq!(s.coupling.discrete_base, 0.002);
        let column = &s.bodies[0];
        let zone = |x: f64, y: f64| layered_zone(&s, column, [x, y, 0.0]);
        // 1 mm over the floor (at 1.5 mm), 4 mm over it (the band: 2 to 5 mm), 6 mm over it.
        assert_eq!(zone(0.02, 0.0025), Zone::Discrete);
        assert_eq!(zone(0.02, 0.0055), Zone::Hybrid);
        assert_eq!(zone(0.02, 0.0075), Zone::Continuum);
        // 1 mm from the left wall, at mid-height.
        assert_eq!(zone(0.001, 0.04), Zone::Discrete);
        // The free faces as without it.
        assert_eq!(zone(0.01, 0.0805), Zone::Discrete);
        assert_eq!(zone(0.035, 0.04), Zone::Hybrid);
        // The field, by the cells' centres: [2, 4] mm (1.5 mm over the floor) discrete, [4, 6]
        // hybrid, [6, 8] continuum.
        let f = ZoneField::layered(&s);
        assert_eq!(f.zone_at([0.0201, 0.0021, 0.0]), Zone::Discrete);
        assert_eq!(f.zone_at([0.0201, 0.0041, 0.0]), Zone::Hybrid);
        assert_eq!(f.zone_at([0.0201, 0.0061, 0.0]), Zone::Continuum);
        // The signed distance the field carries reads the base as the discrete layer: the
        // height over the floor, less the base, plus the discrete layer (4 mm), less the band's
        // middle (5.5 mm). The cell [4, 6] mm, centre 3.5 mm over the floor: on the band's
        // middle; [2, 4], centre 1.5 mm over it: 2 mm on the discrete side.
        let distance = |x: f64, y: f64| {
            let c = f
                .cells
                .index([((x + 0.006) / 0.002).floor() as i64, ((y + 0.006) / 0.002).floor() as i64, 0]);
            f.cells().iter().find(|z| Some(z.cell) == c).unwrap().distance
        };
        assert!(distance(0.0201, 0.0051).abs() < 1e-12, "{}", distance(0.0201, 0.0051));
        assert!((distance(0.0201, 0.0031) + 0.002).abs() < 1e-12, "{}", distance(0.0201, 0.0031));
        // A ball rests on nothing: unchanged.
        assert_eq!(layered_zone(&s, &s.bodies[1], [0.071, 0.05, 0.0]), Zone::Continuum);
    }

    /// Across a periodic axis a box has no resting face: a layer spanning the domain's width
    /// keeps its base over the floor only, where the same layer in a closed domain also lines
    /// the domain's side faces it touches.
    #[test]
    fn a_discrete_base_skips_periodic_axes() {
        let layer = SCENE
            .replace("hybrid_band = 0.003\n", "hybrid_band = 0.003\ndiscrete_base = 0.002\n")
            .replace(
                "min = [0.0, 0.0015]\nmax = [0.04, 0.0815]",
                "min = [-0.006, 0.0015]\nmax = [0.1, 0.0815]",
            )
            .replace("[[wall]]\nkind = \"plane\"\npoint = [0.0, 0.0]\nnormal = [1.0, 0.0]\n", "");
        let periodic = layer.replace("cell_size = 0.002\n", "cell_size = 0.002\nperiodic = [true, false]\n");
        assert_ne!(layer, periodic);
        let (closed, open) = (scene_of(&layer), scene_of(&periodic));
        assert!(open.domain.periodic[0] && closed.walls.len() == 1);
        // 1 mm from the domain's left edge at mid-height, and over the floor.
        let zone = |s: &Scene, x: f64, y: f64| layered_zone(s, &s.bodies[0], [x, y, 0.0]);
        assert_eq!(zone(&closed, -0.005, 0.04), Zone::Discrete);
        assert_eq!(zone(&open, -0.005, 0.04), Zone::Continuum);
        assert_eq!(zone(&open, -0.005, 0.0025), Zone::Discrete);
        assert_eq!(zone(&open, 0.05, 0.0075), Zone::Continuum);
    }
}
