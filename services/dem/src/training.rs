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

/// What [`release`] did: the packing's pressure before and after [Pa], and the shell's
/// dilation (linear strain).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Release {
    pub before: f64,
    pub after: f64,
    pub strain: f64,
}

/// The mean pressure of the grains `counted` (by id and centre) over `area`: Σ V p / area, with
/// p each grain's Love–Weber pressure ([`DemPipeline::grain_pressures`]), compression
/// positive; the continuum's measure of the same packing. 0 before the contacts are known.
pub fn pressure<S: Space>(pipe: &DemPipeline<S>, state: &DemState<S>, counted: impl Fn(u64, S::V) -> bool, area: f64) -> f64 {
    if !pipe.contacts_known() {
        return 0.0;
    }
    let g = &state.grains;
    let p = pipe.grain_pressures(state);
    (0..g.len())
        .filter(|&i| counted(g.id[i], g.x[i]))
        .map(|i| crate::state::Grains::<S>::mass_of(g.radius[i], 1.0) * p[i])
        .sum::<f64>()
        / area
}

/// Dilation of the shell per round of [`release`], the steps the packing relaxes after each
/// round, and the rounds it always takes (to settle against grains added frozen).
const RELEASE_STEP: f64 = 5e-4;
const RELEASE_SETTLE: usize = 100;
const RELEASE_MIN_ROUNDS: usize = 3;

/// Lets a trained packing settle against the grains around it and give up the pressure the
/// continuum does not carry. A shell driven with a continuum that dilates less than the grains
/// (an isochoric plastic flow; a dense packing's dilates) holds the packing at a volume it
/// would leave, and it ends far above the continuum's pressure: inserted so, it bursts. Each
/// round, every grain starts from rest; while the mean pressure of the grains `counted`
/// ([`pressure`] over `area`) exceeds `target`, the shell (`shell`, ids; held at rest) is
/// dilated about its centroid by [`RELEASE_STEP`] (at most `max_strain` in all); then the free
/// grains relax for [`RELEASE_SETTLE`] steps of `dt`. The rounds go on until the pressure is
/// down and at least [`RELEASE_MIN_ROUNDS`] have run. Only the volume changes: the shape the
/// training gave, and the fabric inside, stay. The walls stand still meanwhile. The grains
/// end with the velocities they had (the continuum's motion) and their frozen flags as
/// before.
#[allow(clippy::too_many_arguments)]
pub fn release<S: Space>(
    pipe: &mut DemPipeline<S>,
    state: &mut DemState<S>,
    shell: &[u64],
    counted: impl Fn(u64, S::V) -> bool + Copy,
    area: f64,
    target: f64,
    dt: f64,
    max_strain: f64,
) -> Release {
    let mut ids = shell.to_vec();
    ids.sort_unstable();
    let in_shell = |id: u64| ids.binary_search(&id).is_ok();
    if !pipe.contacts_known() {
        pipe.step(state, dt);
    }
    let before = pressure(pipe, state, counted, area);
    let mut out = Release {
        before,
        after: before,
        strain: 0.0,
    };
    // Velocities and frozen flags by id: the pipeline may reorder the grains.
    let saved: std::collections::HashMap<u64, (S::V, S::Ang, bool)> = {
        let g = &state.grains;
        (0..g.len()).map(|i| (g.id[i], (g.v[i], g.omega[i], g.frozen[i]))).collect()
    };
    let wall_motion: Vec<(S::V, f64)> = state.walls.iter().map(|w| (w.velocity, w.spin)).collect();
    for w in &mut state.walls {
        (w.velocity, w.spin) = (S::V::default(), 0.0);
    }
    let centre = {
        let g = &state.grains;
        let (mut sum, mut n) = (S::V::default(), 0.0);
        for i in (0..g.len()).filter(|&i| in_shell(g.id[i])) {
            sum += g.x[i];
            n += 1.0;
        }
        if n > 0.0 { sum * (1.0 / n) } else { sum }
    };
    let mut rounds = 0;
    while rounds < RELEASE_MIN_ROUNDS || (out.after > target && out.strain < max_strain) {
        let dilate = out.after > target && out.strain < max_strain && !ids.is_empty();
        let g = &mut state.grains;
        for i in 0..g.len() {
            g.v[i] = S::V::default();
            g.omega[i] = S::Ang::default();
            if in_shell(g.id[i]) {
                g.frozen[i] = true;
                if dilate {
                    g.x[i] = centre + (g.x[i] - centre) * (1.0 + RELEASE_STEP);
                }
            }
        }
        if dilate {
            out.strain = (1.0 + out.strain) * (1.0 + RELEASE_STEP) - 1.0;
        }
        for _ in 0..RELEASE_SETTLE {
            pipe.step(state, dt);
        }
        out.after = pressure(pipe, state, counted, area);
        rounds += 1;
        if !dilate && rounds >= RELEASE_MIN_ROUNDS {
            break;
        }
    }
    for (w, &(v, spin)) in state.walls.iter_mut().zip(&wall_motion) {
        (w.velocity, w.spin) = (v, spin);
    }
    let g = &mut state.grains;
    for i in 0..g.len() {
        if let Some(&(v, w, frozen)) = saved.get(&g.id[i]) {
            (g.v[i], g.omega[i], g.frozen[i]) = (v, w, frozen);
        }
    }
    out
}
