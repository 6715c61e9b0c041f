//! Rigid spheropolygons (Jiang 2020 §3) against rigid-body mechanics, through the DEM's own
//! step: impacts against the impulse of a restitution e (Newton's law along the normal), a
//! body at rest on a floor against statics, sliding against Coulomb's law.

mod common;

use common::{law, state};
use glam::DVec2;
use grains_dem::bodies::{Body, Motion};
use grains_dem::pipeline::DemPipeline;
use grains_dem::space::D2;
use grains_dem::state::{DemState, Grains, Wall};

const DENSITY: f64 = 2500.0;
const KN: f64 = 1e7;

/// A square of side `s` centred at `c` (counter-clockwise).
fn square(c: DVec2, s: f64) -> Vec<DVec2> {
    let h = 0.5 * s;
    vec![
        c + DVec2::new(-h, -h),
        c + DVec2::new(h, -h),
        c + DVec2::new(h, h),
        c + DVec2::new(-h, h),
    ]
}

/// A square of side `s` standing on a corner (a diamond), centred at `c`.
fn diamond(c: DVec2, s: f64) -> Vec<DVec2> {
    let h = s / 2f64.sqrt();
    vec![
        c + DVec2::new(h, 0.0),
        c + DVec2::new(0.0, h),
        c + DVec2::new(-h, 0.0),
        c + DVec2::new(0.0, -h),
    ]
}

/// A fixed slab 100 × 10 mm under y = 0, swept by `a`.
fn slab(id: u64, a: f64) -> Body {
    let corners = [
        DVec2::new(-0.05, -0.01),
        DVec2::new(0.05, -0.01),
        DVec2::new(0.05, 0.0),
        DVec2::new(-0.05, 0.0),
    ];
    Body::new(id, &corners, a, DENSITY, 0, Motion::Fixed)
}

fn run(st: &mut DemState<D2>, dt: f64, seconds: f64) {
    let mut p = DemPipeline::<D2>::new(1).unwrap();
    p.run(st, dt, (seconds / dt).round() as usize);
}

fn assert_close(actual: f64, expected: f64, tol: f64, what: &str) {
    assert!(
        (actual - expected).abs() <= tol,
        "{what}: {actual} vs {expected} (tolerance {tol:e})"
    );
}

/// A diamond's corner hits a square's face at v: head-on when the corner is on the square's
/// centre line, off it by `offset` otherwise. Frictionless, restitution `e`. Returns (body A
/// after, body B after, the contact's arm on B, m_A, m_B, I_B).
fn impact(e: f64, offset: f64) -> (Body, Body, DVec2) {
    let (s, a, v) = (0.02, 0.001, 1.0);
    let hit = Body::new(0, &diamond(DVec2::new(-0.03, offset), s), a, DENSITY, 0, Motion::Free);
    let mut target = Body::new(1, &square(DVec2::ZERO, s), a, DENSITY, 0, Motion::Free);
    target.motion = Motion::Free;
    let mut hit = hit;
    hit.v = DVec2::new(v, 0.0);
    let arm = DVec2::new(-0.5 * s - a, offset);
    let mut st = state(law(KN, e, 0.0), DVec2::ZERO, vec![hit, target], Vec::new());
    run(&mut st, 1e-6, 0.03);
    (st.bodies[0].clone(), st.bodies[1].clone(), arm)
}

/// Head-on (the corner on the line of the centres): the rebound is Newton's, v_A' = (m_A −
/// e m_B) v / (m_A + m_B), v_B' = (1 + e) m_A v / (m_A + m_B), and nothing turns.
#[test]
fn a_head_on_impact_rebounds_with_the_restitution_of_the_law() {
    for e in [0.2, 0.5, 0.9] {
        let (a, b, _) = impact(e, 0.0);
        let (ma, mb) = (a.mass, b.mass);
        let before = 1.0;
        assert_close(a.v.x, (ma - e * mb) * before / (ma + mb), 2e-3, "A's velocity");
        assert_close(b.v.x, (1.0 + e) * ma * before / (ma + mb), 2e-3, "B's velocity");
        assert!(a.omega.abs() < 1e-9 && b.omega.abs() < 1e-9, "spins {} {}", a.omega, b.omega);
        assert!(a.v.y.abs() < 1e-9 && b.v.y.abs() < 1e-9);
    }
}

/// Off the centre line by 6 mm (the square's half side is 10 mm): the normal impulse of a
/// rigid-body impact with restitution e, J = (1 + e) v / (1/m_A + 1/m_B + (r_B × N)²/I_B) (the
/// corner's arm on A is along N), turns B by ω_B = (r_B × J)/I_B; momentum and angular
/// momentum are kept.
#[test]
fn an_off_centre_impact_turns_the_body_by_the_impulse_s_torque() {
    let (e, offset) = (0.5, 0.006);
    let (a, b, arm) = impact(e, offset);
    let (ma, mb, ib) = (a.mass, b.mass, b.inertia);
    // r_B × N with N = −x (from B to A): r_x · 0 − r_y · (−1).
    let cross = arm.y;
    let j = (1.0 + e) * 1.0 / (1.0 / ma + 1.0 / mb + cross * cross / ib);
    assert_close(a.v.x, 1.0 - j / ma, 3e-3, "A's velocity");
    assert_close(b.v.x, j / mb, 3e-3, "B's velocity");
    // The impulse on B is +x at r_B = (−s/2 − a, offset): ω_B = (r_B × (J x̂)) / I_B = −offset J / I_B.
    let expected = -offset * j / ib;
    assert_close(b.omega, expected, 0.01 * expected.abs(), "B's spin");
    // A is hit on its centre line; only B's turning during the contact (about 0.01 rad at
    // this stiffness) tilts the normal off it: A's angular impulse is a small share of B's.
    eprintln!(
        "A: v {} ω {}; B: v {} ω {} (expected {expected}); J {j}",
        a.v, a.omega, b.v, b.omega
    );
    assert!(
        (a.inertia * a.omega).abs() < 0.02 * (ib * b.omega).abs(),
        "A's angular impulse {} against B's {}",
        a.inertia * a.omega,
        ib * b.omega
    );
    // Momentum, and angular momentum about the origin (both bodies).
    assert_close(ma * a.v.x + mb * b.v.x, ma, 1e-9 * ma, "momentum");
    let l = |b: &Body| b.inertia * b.omega + b.mass * (b.x.x * b.v.y - b.x.y * b.v.x);
    assert_close(l(&a) + l(&b), -ma * offset, 1e-9 * ma * offset, "angular momentum");
}

/// A square on a floor, at rest after settling: the floor carries its weight (statics), to
/// 0.1%, whether the floor is a plane wall, a fixed body, a segment wall or the bottom of a
/// large drum.
#[test]
fn a_square_at_rest_on_a_floor_weighs_its_weight() {
    let g = DVec2::new(0.0, -9.81);
    let (s, a) = (0.01, 0.0005);
    for floor in ["plane", "body", "segment", "drum"] {
        let sq = Body::new(0, &square(DVec2::new(0.0, 0.5 * s + a + 1e-4), s), a, DENSITY, 0, Motion::Free);
        let weight = sq.mass * 9.81;
        let (bodies, walls) = match floor {
            "plane" => (vec![sq], vec![Wall::plane(DVec2::ZERO, DVec2::Y, 0.5)]),
            "body" => (vec![sq, slab(1, 0.0)], Vec::new()),
            "segment" => (vec![sq], vec![Wall::segment(DVec2::new(-0.05, 0.0), DVec2::new(0.05, 0.0), 0.5)]),
            // A drum of 1 m: its bottom is flat to 12 µm across the square.
            _ => (vec![sq], vec![Wall::drum(DVec2::new(0.0, 1.0), 1.0, 0.5)]),
        };
        let mut st = state(law(KN, 0.3, 0.5), g, bodies, walls);
        run(&mut st, 2e-6, 0.2);
        let b = &st.bodies[0];
        assert_close(
            b.force.y,
            weight,
            1e-3 * weight,
            &format!("{floor}: the floor's force on the square"),
        );
        assert!(b.force.x.abs() < 1e-6 * weight, "{floor}: no sideways force: {}", b.force.x);
        assert!(b.v.length() < 1e-6 && b.omega.abs() < 1e-4, "{floor}: at rest: {} {}", b.v, b.omega);
        if floor == "body" {
            assert_close(st.bodies[1].force.y, -weight, 1e-3 * weight, "the square's force on the floor");
        }
    }
}

/// The square on a floor tilted by gravity at θ: with tan θ > μ it slides and the friction is
/// μ times the normal force (Coulomb's slip); with tan θ < μ it sticks and the friction
/// carries the weight's slope component, m g sin θ < μ N.
#[test]
fn friction_holds_below_the_slip_limit_and_is_mu_n_at_it() {
    let mu = 0.4;
    let (s, a) = (0.01, 0.0005);
    for theta in [15f64.to_radians(), 30f64.to_radians()] {
        let g = DVec2::new(9.81 * theta.sin(), -9.81 * theta.cos());
        let sq = Body::new(0, &square(DVec2::new(0.0, 0.5 * s + a), s), a, DENSITY, 0, Motion::Free);
        let m = sq.mass;
        let mut st = state(law(KN, 0.3, mu), g, vec![sq], vec![Wall::plane(DVec2::ZERO, DVec2::Y, mu)]);
        run(&mut st, 2e-6, 0.1);
        let b = &st.bodies[0];
        let normal = m * 9.81 * theta.cos();
        assert_close(b.force.y, normal, 1e-3 * normal, "normal force");
        if theta.tan() > mu {
            assert_close(-b.force.x, mu * b.force.y, 1e-3 * normal, "sliding friction = mu N");
            let accel = 9.81 * (theta.sin() - mu * theta.cos());
            assert_close(b.v.x, accel * 0.1, 0.01 * accel * 0.1, "slides at g (sin θ − μ cos θ)");
        } else {
            assert_close(-b.force.x, m * 9.81 * theta.sin(), 1e-3 * normal, "sticking friction = m g sin θ");
            assert!(b.v.length() < 1e-5, "sticks: {}", b.v);
        }
    }
}

/// A grain dropped on a fixed body comes to rest on it with its weight carried (the grain
/// meets the body as a one-vertex body of its radius), and the body records the load.
#[test]
fn a_grain_rests_on_a_fixed_body() {
    let g = DVec2::new(0.0, -9.81);
    let mut st = state(law(KN, 0.3, 0.5), g, vec![slab(0, 0.0005)], Vec::new());
    let r = 0.001;
    let m = Grains::<D2>::mass_of(r, DENSITY);
    st.grains.push(7, DVec2::new(0.003, 0.0005 + r + 2e-4), r, m, 0);
    run(&mut st, 1e-6, 0.1);
    let weight = m * 9.81;
    assert_close(
        st.grains.x[0].y,
        0.0005 + r - weight / KN,
        1e-7,
        "resting height (overlap m g / k_n)",
    );
    assert!(st.grains.v[0].length() < 1e-6);
    assert_close(st.bodies[0].force.y, -weight, 1e-3 * weight, "load on the body");
}

/// A disk body (one vertex swept by r) hits a fixed slab at 45° with friction μ = 0.1: it
/// slides through the whole impact (μ (1 + e) v_n (1 + m r²/I) < v_t), so the friction's
/// impulse is μ times the normal one, and rigid-body impact gives v_n' = e v_n,
/// v_t' = v_t − μ (1 + e) v_n and the spin ω' = μ (1 + e) v_n m r / I, turning the disk to
/// roll the way it moves (clockwise moving +x: ω < 0). Elastic (e = 1), so that the normal
/// force never pulls: with e < 1 the grains' un-clamped dashpot pulls at the end of a
/// contact and the Coulomb cap takes |f_n| (at e = 0.5, 6.7% more friction impulse than
/// μ J_n).
#[test]
fn an_oblique_impact_with_friction_spins_the_body_by_the_friction_impulse() {
    let (r, e, mu) = (0.005, 1.0, 0.1);
    let mut disk = Body::new(0, &[DVec2::new(0.0, r + 1e-4)], r, DENSITY, 0, Motion::Free);
    disk.v = DVec2::new(1.0, -1.0);
    let mut st = state(law(KN, e, mu), DVec2::ZERO, vec![disk, slab(1, 1e-4)], Vec::new());
    run(&mut st, 1e-7, 0.002);
    let b = &st.bodies[0];
    let (m, inertia) = (b.mass, b.inertia);
    assert_close(inertia, 0.5 * m * r * r, 1e-12 * inertia, "a disk's moment of inertia");
    // The slab is swept by 0.1 mm: the contact is at r from the disk's centre either way.
    let jn = 1.0 + e;
    assert_close(b.v.y, e * 1.0, 2e-3, "normal rebound");
    assert_close(b.v.x, 1.0 - mu * jn, 2e-3, "tangential velocity after the friction impulse");
    // The force acts at the middle of the overlap (eq. 41), r − ξ/2 from the centre: ξ
    // reaches v_n √(m / k_n) = 0.14 mm here, so the arm is up to 1.4% short of r.
    let spin = -mu * jn * m * r / inertia;
    assert_close(b.omega, spin, 0.02 * spin.abs(), "spin from the friction's torque");
}

/// An L of foot `w` × `t` and upright `t` × `h`, its outer corner at `at` (counter-clockwise;
/// the reflex corner at `at` + (t, t)).
fn ell(at: DVec2, w: f64, t: f64, h: f64) -> Vec<DVec2> {
    [(0.0, 0.0), (w, 0.0), (w, t), (t, t), (t, h), (0.0, h)]
        .iter()
        .map(|&(x, y)| at + DVec2::new(x, y))
        .collect()
}

/// A fixed block 40 × 10 mm with a V notch cut in its top: faces at `beta` to the
/// horizontal, 20 mm across, the apex (reflex) on x = 0.
fn notched(beta: f64) -> Body {
    let depth = 0.01 * beta.tan();
    let v = [
        (-0.02, -0.01),
        (0.02, -0.01),
        (0.02, 0.0),
        (0.01, 0.0),
        (0.0, -depth),
        (-0.01, 0.0),
        (-0.02, 0.0),
    ];
    let v: Vec<DVec2> = v.iter().map(|&(x, y)| DVec2::new(x, y)).collect();
    Body::new(9, &v, 5e-4, DENSITY, 0, Motion::Fixed)
}

/// A non-convex body (an L, its centre of mass off its outline's middle, its reflex corner
/// never touching the floor) at rest on a floor: the floor carries its weight to 0.1%, on a
/// plane wall and on a fixed body.
#[test]
fn an_l_at_rest_on_a_floor_weighs_its_weight() {
    let g = DVec2::new(0.0, -9.81);
    let a = 0.0005;
    for floor in ["plane", "body"] {
        let l = Body::new(
            0,
            &ell(DVec2::new(-0.01, a + 1e-4), 0.02, 0.005, 0.015),
            a,
            DENSITY,
            0,
            Motion::Free,
        );
        let weight = l.mass * 9.81;
        let (bodies, walls) = match floor {
            "plane" => (vec![l], vec![Wall::plane(DVec2::ZERO, DVec2::Y, 0.5)]),
            _ => (vec![l, slab(1, 0.0)], Vec::new()),
        };
        let mut st = state(law(KN, 0.3, 0.5), g, bodies, walls);
        run(&mut st, 2e-6, 0.2);
        let b = &st.bodies[0];
        eprintln!("{floor}: the floor carries {} N of the L's {weight} N", b.force.y);
        assert_close(b.force.y, weight, 1e-3 * weight, &format!("{floor}: the floor's force on the L"));
        assert!(b.v.length() < 1e-6 && b.omega.abs() < 1e-4, "{floor}: at rest: {} {}", b.v, b.omega);
    }
}

/// A disk in a frictionless V notch (faces at β = 30° to the horizontal, the apex a reflex
/// vertex) rests on both faces at once, as a grain and as a one-vertex body: each face
/// pushes with N = m g / (2 cos β) along its normal, so its overlap is ξ = N / k_n and its
/// centre sits (r + a − ξ) / cos β above the apex, on the notch's axis. Touching one face
/// only it would slide down that face past the apex; counting a face twice would halve ξ.
#[test]
fn a_disk_in_a_notch_rests_on_both_faces() {
    let beta = 30f64.to_radians();
    let g = DVec2::new(0.0, -9.81);
    let (r, a) = (0.002, 5e-4);
    let apex = DVec2::new(0.0, -0.01 * beta.tan());
    for kind in ["grain", "body"] {
        let start = apex + DVec2::new(0.0, (r + a) / beta.cos() + 2e-4);
        let (mut st, m) = if kind == "grain" {
            let mut st = state(law(KN, 0.3, 0.0), g, vec![notched(beta)], Vec::new());
            let m = Grains::<D2>::mass_of(r, DENSITY);
            st.grains.push(7, start, r, m, 0);
            (st, m)
        } else {
            // A disk body of radius r + a in all (its sphero-radius), on the notch's a.
            let disk = Body::new(0, &[start], r, DENSITY, 0, Motion::Free);
            let m = disk.mass;
            (state(law(KN, 0.3, 0.0), g, vec![disk, notched(beta)], Vec::new()), m)
        };
        run(&mut st, 1e-6, 0.1);
        let (x, v) = if kind == "grain" {
            (st.grains.x[0], st.grains.v[0])
        } else {
            (st.bodies[0].x, st.bodies[0].v)
        };
        let xi = m * 9.81 / (2.0 * beta.cos() * KN);
        let height = (r + a - xi) / beta.cos();
        eprintln!(
            "{kind}: {:.6} mm above the apex, expected {:.6} (ξ = {:.3e} m); x = {:.2e} m",
            (x.y - apex.y) * 1e3,
            height * 1e3,
            xi,
            x.x
        );
        assert!(v.length() < 1e-6, "{kind}: at rest: {v}");
        assert!(x.x.abs() < 1e-9, "{kind}: on the axis: {}", x.x);
        assert_close(
            x.y - apex.y,
            height,
            0.02 * xi / beta.cos(),
            &format!("{kind}: height above the apex"),
        );
        let notch = st.bodies.iter().find(|b| b.id == 9).unwrap();
        assert_close(
            notch.force.y,
            -m * 9.81,
            1e-3 * m * 9.81,
            &format!("{kind}: the load on the notched block"),
        );
    }
}

/// A disk body hits the inner face of a free L's upright (the face beside its reflex
/// corner), frictionless, e = 0.5, 4 mm above the L's centre of mass: the normal impulse of
/// a rigid-body impact J = (1 + e) v / (1/m_A + 1/m_B + (r_B × N)² / I_B), with the L's mass,
/// centre and moment of inertia from its non-convex swept shape, turns it by (r_B × J) / I_B.
#[test]
fn a_hit_on_an_l_s_inner_face_turns_it_by_the_impulse_s_torque() {
    let (e, a, r) = (0.5, 5e-4, 0.002);
    let shape = ell(DVec2::new(-0.0025, -0.01), 0.02, 0.005, 0.03);
    let target = Body::new(1, &shape, a, DENSITY, 0, Motion::Free);
    // The inner face is x = 0.0025 (swept out by a), from y = −0.005 to 0.02; the contact's
    // arm on B from its centre of mass.
    let y = target.x.y + 0.004;
    let arm = DVec2::new(0.0025 + a, y) - target.x;
    let mut hit = Body::new(0, &[DVec2::new(0.012, y)], r, DENSITY, 0, Motion::Free);
    hit.v = DVec2::new(-1.0, 0.0);
    let mut st = state(law(KN, e, 0.0), DVec2::ZERO, vec![hit, target], Vec::new());
    run(&mut st, 1e-7, 0.008);
    let (a_after, b) = (&st.bodies[0], &st.bodies[1]);
    let (ma, mb, ib) = (a_after.mass, b.mass, b.inertia);
    // N = −x (from A into B): r_B × N = r_x · 0 − r_y · (−1) = r_y.
    let cross = arm.y;
    let j = (1.0 + e) * 1.0 / (1.0 / ma + 1.0 / mb + cross * cross / ib);
    assert_close(a_after.v.x, -1.0 + j / ma, 3e-3, "A's velocity");
    assert_close(b.v.x, -j / mb, 3e-3, "B's velocity");
    // The impulse on B is −x at r_B: ω_B = (r_B × (−J x̂)) / I_B = r_y J / I_B.
    let expected = arm.y * j / ib;
    eprintln!(
        "A {} m/s (expected {}), B {} m/s (expected {}), B's spin {} rad/s (expected {expected})",
        a_after.v.x,
        -1.0 + j / ma,
        b.v.x,
        -j / mb,
        b.omega
    );
    assert_close(b.omega, expected, 0.01 * expected.abs(), "B's spin");
}
