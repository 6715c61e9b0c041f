//! Kinematic training (Chen 2021 §4.1.1). Before a packing replaces a continuum region, it is
//! driven through that region's deformation history, so that when it is released it holds
//! the stress the continuum's history built (and the packing and fabric that go with it).
//!
//! Only the packing's boundary is driven: a shell of grains moves with the continuum's
//! velocity; the grains inside move as grains do. Driving every grain with the continuum's
//! motion over-constrains the packing: a continuum's simple shear is linear, a packing's is
//! not (the grains roll and rearrange), and the imposed motion gives the wrong stress (§4.1.1,
//! "early attempts").

use crate::pipeline::DemPipeline;
use crate::space::Space;
use crate::state::DemState;

/// The ids of the grains whose centres lie within `thickness` of the region's boundary,
/// `distance(x)` being the signed distance to it (negative inside). The grains outside the
/// region (distance > 0) are in the shell too: they are the boundary's outer side.
pub fn shell<S: Space>(state: &DemState<S>, distance: impl Fn(S::V) -> f64, thickness: f64) -> Vec<u64> {
    let g = &state.grains;
    (0..g.len()).filter(|&i| distance(g.x[i]) > -thickness).map(|i| g.id[i]).collect()
}

/// Trains `state` for `steps` steps of `dt`: the grains `shell` (ids) take no force and move
/// with `velocity(x, t)`, the continuum's velocity at their centre `t` seconds into the
/// training, without spin; the others are free. At the end the shell is released: each of its
/// grains is frozen again only if it was frozen before.
pub fn train<S: Space>(
    pipe: &mut DemPipeline<S>,
    state: &mut DemState<S>,
    shell: &[u64],
    velocity: impl Fn(S::V, f64) -> S::V,
    dt: f64,
    steps: usize,
) {
    let mut ids = shell.to_vec();
    ids.sort_unstable();
    let in_shell = |id: u64| ids.binary_search(&id).is_ok();
    // The grains frozen before the training, to restore at release.
    let mut frozen_before: Vec<u64> = {
        let g = &state.grains;
        (0..g.len()).filter(|&i| g.frozen[i]).map(|i| g.id[i]).collect()
    };
    frozen_before.sort_unstable();
    {
        let g = &mut state.grains;
        for i in 0..g.len() {
            if in_shell(g.id[i]) {
                g.frozen[i] = true;
            }
        }
    }
    for step in 0..steps {
        let t = step as f64 * dt;
        let g = &mut state.grains;
        // Storage order may change between steps (the pipeline sorts): find the shell by id.
        for i in 0..g.len() {
            if g.frozen[i] && in_shell(g.id[i]) {
                // Midpoint of the step in time: the shell's displacement over it is second order.
                g.v[i] = velocity(g.x[i], t + 0.5 * dt);
                g.omega[i] = S::Ang::default();
            }
        }
        pipe.step(state, dt);
    }
    let g = &mut state.grains;
    for i in 0..g.len() {
        if in_shell(g.id[i]) {
            g.frozen[i] = frozen_before.binary_search(&g.id[i]).is_ok();
        }
    }
}
