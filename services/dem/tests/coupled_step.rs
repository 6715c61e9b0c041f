//! The DEM half of a coupled step (Yue 2018 Alg. 2, 4–6, [`grains_dem::coupled`]) against the
//! DEM step alone and against what the coupler gives it, without a coupler: the constrained
//! velocities are made up by each test.

use glam::DVec2;
use grains_dem::contact::{ContactParams, Damping};
use grains_dem::coupled::{CoupledStep, CouplingParams, GrainTransfer};
use grains_dem::packing::lattice_in_box;
use grains_dem::pipeline::DemPipeline;
use grains_dem::space::{D2, Space};
use grains_dem::state::{DemParams, DemState, Domain, Grains, Wall};
use grains_grid::rng::{Rng, radius};
use grains_grid::{Grid, Kernel};

const RADIUS: f64 = 5e-4;
const DENSITY: f64 = 2530.0;
/// The box of the grains and the domain [m].
const SIZE: [f64; 3] = [0.02, 0.03, 0.0];
/// A macro-step of 100 DEM steps of 5e-7 s (≈ 150 per contact).
const DT: f64 = 5e-5;
const SUBSTEPS: usize = 100;
const CELL: f64 = 0.002;

/// A few hundred disks (Chen 2021 Table 1 contact law) on a jittered lattice in a walled box,
/// under gravity, with small random velocities: they collide and settle.
fn bed() -> DemState<D2> {
    let p = ContactParams {
        stiffness_normal: 1772093.8,
        stiffness_tangential: 886046.9,
        damping: Damping::Viscous(7.0),
        friction: 0.5,
        cohesion_normal: 0.0,
        cohesion_tangential: 0.0,
        damping_scale: 1.0,
    };
    let mut st = DemState {
        grains: Grains::default(),
        walls: Vec::new(),
        bodies: Vec::new(),
        params: DemParams {
            materials: vec![p],
            gravity: DVec2::new(0.0, -9.81),
            domain: Domain {
                min: [0.0; 3],
                max: SIZE,
                periodic: [false; 3],
            },
            skin: 0.2 * RADIUS,
        },
        time: 0.0,
    };
    for k in 0..2 {
        let mut n = [0.0; 3];
        n[k] = 1.0;
        st.walls.push(Wall::plane(DVec2::ZERO, D2::from_array(n), 0.5));
        n[k] = -1.0;
        st.walls.push(Wall::plane(D2::from_array(SIZE), D2::from_array(n), 0.5));
    }
    let mut rng = Rng::new(5);
    let r_max = RADIUS + 2.0 * 4e-5;
    let sites = lattice_in_box::<D2>([0.0; 3], [0.02, 0.02, 0.0], 2.04 * r_max, 1.01 * r_max, 0.01 * RADIUS, &mut rng);
    for (id, x) in sites.into_iter().enumerate() {
        let r = radius(&mut rng, RADIUS, 4e-5);
        let i = st.grains.push(id as u64, x, r, Grains::<D2>::mass_of(r, DENSITY), 0);
        st.grains.v[i] = DVec2::new(0.02 * rng.normal(), 0.02 * rng.normal());
    }
    assert!(st.grains.len() > 200, "{} grains", st.grains.len());
    st
}

/// The stage on a grid over the box with a margin of two cells: a quadratic B-spline reaches
/// nodes up to 1.5 cells from a grain, so a grain at a wall has weight beyond it (on the
/// scene's grid, which ends at the domain, those nodes would be dropped).
fn stage(transfer: GrainTransfer, kernel: Kernel) -> CoupledStep<D2> {
    let margin = 2.0 * CELL;
    CoupledStep::new(CouplingParams {
        grid: Grid::covering([-margin, -margin, 0.0], [SIZE[0] + margin, SIZE[1] + margin, 0.0], CELL, 2),
        kernel,
        transfer,
        quasi_static: 1e-3,
        gravity: 9.81,
        fluid: None,
    })
}

/// The scene's default kernel: GIMP with two points per cell and axis.
const GIMP: Kernel = Kernel::Gimp { half_width: 0.25 * CELL };

/// Σ (1 − w) m v of the grains.
fn weighted_momentum(g: &Grains<D2>) -> DVec2 {
    (0..g.len()).fold(DVec2::ZERO, |a, i| a + g.v[i] * (g.mass[i] * g.scale[i]))
}

/// Without hybrid grains a coupled step is the step alone, bit for bit, with either transfer:
/// nothing is rasterized and every grain keeps its substepped state.
#[test]
fn without_hybrid_grains_the_coupled_step_is_the_step_alone() {
    for transfer in [GrainTransfer::Flip, GrainTransfer::Pic, GrainTransfer::Points(0.95)] {
        let (mut alone, mut coupled) = (bed(), bed());
        let (mut pipe_alone, mut pipe_coupled) = (DemPipeline::<D2>::new(1).unwrap(), DemPipeline::<D2>::new(1).unwrap());
        let mut step = stage(transfer, GIMP);
        for _ in 0..10 {
            pipe_alone.run(&mut alone, DT / SUBSTEPS as f64, SUBSTEPS);
            assert!(step.predict(&mut coupled, &mut pipe_coupled, DT, SUBSTEPS).is_empty());
            step.finish(&mut coupled, &mut pipe_coupled, [], DT);
        }
        assert_eq!(alone.grains, coupled.grains, "{transfer:?}");
        assert_eq!(alone.time, coupled.time);
    }
}

/// With every grain hybrid (scale 1 − w = 0.5) and no MPM to share nodes with, the grains take
/// the velocities of their own raster (Alg. 5): the weighted momentum of the raster is the
/// grains' weighted momentum after the substeps, and after the transfer back it is unchanged
/// (Σ_g m_g Σ_i w_gi v_i = Σ_i m_i v_i: the weights are a partition of unity), to round-off;
/// with either transfer and kernel.
#[test]
fn hybrid_grains_round_trip_through_their_raster_keeping_momentum() {
    for transfer in [GrainTransfer::Flip, GrainTransfer::Pic, GrainTransfer::Points(0.95)] {
        for kernel in [GIMP, Kernel::Bspline2] {
            let mut st = bed();
            st.grains.scale.iter_mut().for_each(|s| *s = 0.5);
            let mut pipe = DemPipeline::<D2>::new(1).unwrap();
            let mut step = stage(transfer, kernel);
            let n = step.predict(&mut st, &mut pipe, DT, SUBSTEPS).len();
            assert!(n > 0);
            let raster_m: f64 = step.raster().iter().map(|r| r.mass).sum();
            let raster_p = (0..n).fold(DVec2::ZERO, |a, k| a + step.uncoupled_momentum(k));
            let g = &st.grains;
            let before = weighted_momentum(g);
            let grains_m: f64 = (0..g.len()).map(|i| g.mass[i] * g.scale[i]).sum();
            assert!((raster_m - grains_m).abs() < 1e-12 * grains_m, "{transfer:?}, {kernel:?}");
            assert!(
                (raster_p - before).length() < 1e-12 * grains_m,
                "{transfer:?}, {kernel:?}: {raster_p:?} vs {before:?}"
            );
            step.finish(&mut st, &mut pipe, [], DT);
            let after = weighted_momentum(&st.grains);
            assert!(
                (after - before).length() < 1e-12 * grains_m,
                "{transfer:?}, {kernel:?}: {after:?} vs {before:?}"
            );
        }
    }
}

/// One free grain in empty space (no gravity, no walls, no contacts).
fn lone_grain(scale: f64, v0: DVec2) -> DemState<D2> {
    let mut st = bed();
    st.grains = Grains::default();
    st.walls.clear();
    st.params.gravity = DVec2::ZERO;
    let i = st
        .grains
        .push(7, DVec2::new(0.0093, 0.0151), RADIUS, Grains::<D2>::mass_of(RADIUS, DENSITY), 0);
    st.grains.scale[i] = scale;
    st.grains.v[i] = v0;
    st
}

fn close(a: DVec2, b: DVec2, tolerance: f64) -> bool {
    (a - b).length() <= tolerance * b.length().max(1e-300)
}

/// With "flip" the coupling's acceleration of a step pushes the next step's substeps, and the
/// raster the coupler gets leaves that push out. A lone hybrid grain (scale 0.75) at v0, every
/// node of its raster constrained to u: it takes u (Alg. 5), and each node keeps the
/// acceleration (u − v0)/dt. Next step the substeps push it with that acceleration on its
/// scaled mass: velocity Verlet integrates a constant force exactly, so it reaches
/// u + (u − v0), while every node's uncoupled velocity (the raster without the carried
/// impulse) is u, what it would have without coupling. Where the coupler then leaves the
/// nodes alone the push is taken back: the grain ends at u again.
#[test]
fn flip_carries_the_coupling_push_through_the_substeps_and_out_of_the_raster() {
    let (v0, u) = (DVec2::new(0.01, 0.0), DVec2::new(0.02, -0.01));
    let mut st = lone_grain(0.75, v0);
    let mut pipe = DemPipeline::<D2>::new(1).unwrap();
    let mut step = stage(GrainTransfer::Flip, Kernel::Bspline2);
    let nodes: Vec<u64> = step.predict(&mut st, &mut pipe, DT, SUBSTEPS).iter().map(|r| r.node).collect();
    assert!(nodes.len() >= 9);
    assert_eq!(st.grains.external[0], DVec2::ZERO, "no push in the first step");
    step.finish(&mut st, &mut pipe, nodes.iter().map(|&n| (n, u)), DT);
    assert!(close(st.grains.v[0], u, 1e-12), "{:?} vs {u:?}", st.grains.v[0]);

    let raster = step.predict(&mut st, &mut pipe, DT, SUBSTEPS).to_vec();
    let push = (u - v0) * (1.0 / DT);
    let g = &st.grains;
    assert!(close(g.external[0], push * (g.mass[0] * 0.75), 1e-12), "push {:?}", g.external[0]);
    assert!(close(g.v[0], u + (u - v0), 1e-12), "pushed: {:?}", g.v[0]);
    for (k, r) in raster.iter().enumerate() {
        assert!(close(r.momentum * (1.0 / r.mass), u + (u - v0), 1e-12), "node {}", r.node);
        assert!(close(step.uncoupled_momentum(k) * (1.0 / r.mass), u, 1e-12), "node {}", r.node);
    }
    step.finish(&mut st, &mut pipe, [], DT);
    assert!(close(st.grains.v[0], u, 1e-12), "taken back: {:?} vs {u:?}", st.grains.v[0]);
}

/// With "pic" (Alg. 5–6 as written) a hybrid grain moves from the position it had at the
/// start of the step, not from where its substeps took it: given a uniform node velocity u it
/// takes u, the field's spin (none), and ends at x_saved + u dt.
#[test]
fn pic_advects_from_the_saved_position() {
    let (v0, u) = (DVec2::new(0.3, 0.1), DVec2::new(-0.02, 0.05));
    let mut st = lone_grain(0.5, v0);
    st.grains.omega[0] = 40.0;
    let x0 = st.grains.x[0];
    let mut pipe = DemPipeline::<D2>::new(1).unwrap();
    let mut step = stage(GrainTransfer::Pic, GIMP);
    let nodes: Vec<u64> = step.predict(&mut st, &mut pipe, DT, SUBSTEPS).iter().map(|r| r.node).collect();
    assert!(close(st.grains.x[0], x0 + v0 * DT, 1e-12), "the substeps move it with v0");
    step.finish(&mut st, &mut pipe, nodes.iter().map(|&n| (n, u)), DT);
    let g = &st.grains;
    assert!(close(g.v[0], u, 1e-12), "{:?} vs {u:?}", g.v[0]);
    assert!(g.omega[0].abs() < 1e-9, "spin {}", g.omega[0]);
    assert!(close(g.x[0], x0 + u * DT, 1e-14), "{:?} vs {:?}", g.x[0], x0 + u * DT);
}

/// With "points" (Yue 2018 §3.7: "in the same manner as MPM points") a lone hybrid grain at
/// v0, its raster's nodes constrained to u, takes β (v0 + (u − v0)) + (1 − β) u = u whatever
/// β when the field is its own; with the nodes it shares moved by a uniform u against its
/// own raster velocity v0 it keeps the blend of its own velocity plus the change (FLIP) and
/// u (PIC), moves with that from its saved position (Alg. 6), and keeps its spin.
#[test]
fn points_blend_the_grain_s_own_velocity_and_the_grid_s_as_the_mpm_points_do() {
    let (v0, u, beta) = (DVec2::new(0.3, 0.1), DVec2::new(-0.02, 0.05), 0.9);
    let mut st = lone_grain(0.5, v0);
    st.grains.omega[0] = 40.0;
    let x0 = st.grains.x[0];
    let mut pipe = DemPipeline::<D2>::new(1).unwrap();
    let mut step = stage(GrainTransfer::Points(beta), GIMP);
    let nodes: Vec<u64> = step.predict(&mut st, &mut pipe, DT, SUBSTEPS).iter().map(|r| r.node).collect();
    step.finish(&mut st, &mut pipe, nodes.iter().map(|&n| (n, u)), DT);
    let g = &st.grains;
    // Alone on its nodes its raster velocity is v0, so FLIP gives v0 + (u − v0) = u, as PIC.
    assert!(close(g.v[0], u, 1e-12), "{:?} vs {u:?}", g.v[0]);
    assert_eq!(g.omega[0], 40.0, "its spin is its own");
    assert!(close(g.x[0], x0 + u * DT, 1e-14), "{:?} vs {:?}", g.x[0], x0 + u * DT);
    // Two grains on the same nodes at other velocities, every node's velocity moved by u:
    // β = 1 (FLIP) gives each its own velocity + u, β = 0 (PIC) the interpolated node
    // velocity, which differs from both, and β the blend of the two.
    let after = |beta: f64| {
        let mut st = lone_grain(0.5, v0);
        let j = st.grains.push(
            8,
            st.grains.x[0] + DVec2::new(1e-4, 0.0),
            RADIUS,
            Grains::<D2>::mass_of(RADIUS, DENSITY),
            0,
        );
        st.grains.scale[j] = 0.5;
        st.grains.v[j] = -v0;
        let mut pipe = DemPipeline::<D2>::new(1).unwrap();
        let mut step = stage(GrainTransfer::Points(beta), GIMP);
        let moved: Vec<(u64, DVec2)> = step
            .predict(&mut st, &mut pipe, DT, SUBSTEPS)
            .iter()
            .map(|r| (r.node, r.momentum * (1.0 / r.mass) + u))
            .collect();
        let before = [st.grains.v[0], st.grains.v[j]];
        step.finish(&mut st, &mut pipe, moved, DT);
        (before, [st.grains.v[0], st.grains.v[j]])
    };
    let (before, flip) = after(1.0);
    let (_, pic) = after(0.0);
    let (_, blend) = after(beta);
    for k in 0..2 {
        assert!(
            close(flip[k], before[k] + u, 1e-12),
            "FLIP {k}: {:?} vs {:?}",
            flip[k],
            before[k] + u
        );
        assert!(
            (pic[k] - flip[k]).length() > 1e-3 * v0.length(),
            "PIC {k} equals FLIP: {:?}",
            pic[k]
        );
        assert!(close(blend[k], flip[k] * beta + pic[k] * (1.0 - beta), 1e-12), "blend {k}");
    }
}

/// The substeps of a coupled step keep every grain at its storage index (the stage addresses
/// grains by index between its halves) even when a re-sort falls due: a bed shaken fast
/// enough to rebuild its neighbour list dozens of times keeps its order through
/// `run_in_order`, and the re-sort then happens at `settle`.
#[test]
fn the_substeps_keep_the_grain_order_and_a_due_sort_waits_for_settle() {
    let mut st = bed();
    for v in st.grains.v.iter_mut() {
        *v *= 20.0;
    }
    let mut pipe = DemPipeline::<D2>::new(1).unwrap();
    pipe.settle(&mut st);
    let ids = st.grains.id.clone();
    let builds = pipe.neighbors.builds;
    pipe.run_in_order(&mut st, 5e-7, 4000);
    assert!(
        pipe.neighbors.builds >= builds + 20,
        "{} builds: no sort fell due",
        pipe.neighbors.builds - builds
    );
    assert_eq!(st.grains.id, ids, "the order changed during run_in_order");
    pipe.settle(&mut st);
    assert_ne!(st.grains.id, ids, "the due sort did not happen at settle");
}

/// After grains are moved outside of a step, `moved` (forces again at the new positions, the
/// neighbour list kept unless stale) gives the step `invalidate` (everything rebuilt) gives,
/// up to the order of float sums: within 1e-12 of the motion, grain by grain.
#[test]
fn moved_steps_like_invalidate() {
    // Two identical histories (one thread: bit for bit), then the same push of every third grain.
    let (mut a, mut b) = (bed(), bed());
    let (mut pipe, mut pipe_b) = (DemPipeline::<D2>::new(1).unwrap(), DemPipeline::<D2>::new(1).unwrap());
    for (st, p) in [(&mut a, &mut pipe), (&mut b, &mut pipe_b)] {
        p.run(st, 5e-7, 200);
        for i in (0..st.grains.len()).step_by(3) {
            st.grains.x[i] += DVec2::new(1e-6, -2e-6);
            st.grains.v[i] += DVec2::new(0.01, 0.0);
        }
    }
    assert_eq!(a, b);
    pipe.moved();
    pipe.run(&mut a, 5e-7, 1);
    pipe_b.invalidate();
    pipe_b.run(&mut b, 5e-7, 1);
    let mut n = 0;
    for i in 0..a.grains.len() {
        let j = b.grains.index_of(a.grains.id[i]).unwrap();
        let (dx, dv) = ((a.grains.x[i] - b.grains.x[j]).length(), (a.grains.v[i] - b.grains.v[j]).length());
        assert!(dx < 1e-15 && dv < 1e-12 * 0.02, "grain {}: dx {dx:e}, dv {dv:e}", a.grains.id[i]);
        n += 1;
    }
    assert!(n > 200);
}
