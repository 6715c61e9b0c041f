//! Zones of a hybrid body given by the scene (layered hybridization, Yue 2018 §4.3): grains in
//! a layer of `coupling.discrete_layer` under the body's free faces, then a band of
//! `coupling.hybrid_band` where grains and material points overlap and are coupled, points only
//! below. Zones are fixed to the material (every grain and point keeps the zone it was created
//! in), which is how the solvers of issue 5 use them until the oracle moves them.
//!
//! One function for both solvers, so that grains and points agree on every boundary.

use grains_protocol::scene::{Body, Scene, Shape, WallShape};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Layer {
    Discrete,
    Hybrid,
    Continuum,
}

/// Whether the face of a box body on `axis` (the low face when `low`) at coordinate `at` rests
/// on a plane or box wall, or on the domain's own wall layers (within one cell).
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
        WallShape::Drum { .. } | WallShape::Segment { .. } => false,
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

/// The zone of material at `x` in a hybrid `body`.
pub fn layer(scene: &Scene, body: &Body, x: [f64; 3]) -> Layer {
    let d = depth(scene, body, x);
    let c = &scene.coupling;
    if d < c.discrete_layer {
        Layer::Discrete
    } else if d < c.discrete_layer + c.hybrid_band {
        Layer::Hybrid
    } else {
        Layer::Continuum
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
        let path = std::env::temp_dir().join(format!("grains-zones-{}.toml", std::process::id()));
        std::fs::write(&path, SCENE).unwrap();
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
        assert_eq!(layer(&s, column, [0.01, 0.0805, 0.0]), Layer::Discrete);
        // 5 mm from the right face: in the band (4 to 7 mm); 8 mm: continuum.
        assert_eq!(layer(&s, column, [0.035, 0.04, 0.0]), Layer::Hybrid);
        assert_eq!(layer(&s, column, [0.032, 0.04, 0.0]), Layer::Continuum);
        // A disk: depth from its circle.
        let disk = &s.bodies[1];
        assert!((depth(&s, disk, [0.07, 0.05, 0.0]) - 0.01).abs() < 1e-12);
        assert_eq!(layer(&s, disk, [0.078, 0.05, 0.0]), Layer::Discrete);
        assert_eq!(layer(&s, disk, [0.075, 0.05, 0.0]), Layer::Hybrid);
        assert_eq!(layer(&s, disk, [0.071, 0.05, 0.0]), Layer::Continuum);
    }
}
