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
