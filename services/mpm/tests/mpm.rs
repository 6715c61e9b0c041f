//! MPM transfers and the elastic step against exact and analytic answers (issue 4).

use glam::DVec2;
use grains_grid::{D2, Grid, Kernel};
use grains_mpm::constitutive::plasticity_drucker_prager::DruckerPragerYue;
use grains_mpm::matrix::MpmSpace;
use grains_mpm::pipeline::{Model, MpmParams, MpmPipeline, Transfer, cfl_time_step};
use grains_mpm::points::{Points, totals as point_totals};

fn block(lo: [f64; 2], hi: [f64; 2], h: f64, ppc: usize, density: f64) -> Points<D2> {
    let mut pts = Points::<D2>::default();
    let d = h / ppc as f64;
    let nx = ((hi[0] - lo[0]) / d).round() as usize;
    let ny = ((hi[1] - lo[1]) / d).round() as usize;
    for j in 0..ny {
        for i in 0..nx {
            pts.push(
                DVec2::new(lo[0] + (i as f64 + 0.5) * d, lo[1] + (j as f64 + 0.5) * d),
                density * d * d,
                d * d,
                0.8,
            );
        }
    }
    pts
}

fn params(grid: Grid, h: f64, ppc: usize, material: DruckerPragerYue) -> MpmParams<D2> {
    MpmParams {
        grid,
        kernel: Kernel::Gimp {
            half_width: 0.5 * h / ppc as f64,
        },
        model: Model::Elastic(material),
        gravity: DVec2::ZERO,
        transfer: Transfer::Flip(1.0),
        domain_walls: None,
        walls: Vec::new(),
        point_loads: grains_mpm::pipeline::PointLoads::Weights,
        ambient_pressure: 0.0,
    }
}

fn pipeline<S: MpmSpace>() -> MpmPipeline<S> {
    MpmPipeline::new(1).unwrap()
}

/// Frequency of the first axial mode of a bar, from the zero crossings of the mean x
/// velocity of its left end (points with x below `left_edge`): v_end = v0 cos(ωt) crosses zero
/// at T/4, 3T/4, 5T/4, …, so crossings 1 and 3 are one period apart.
fn axial_frequency<S: MpmSpace>(pts: &mut Points<S>, p: &MpmParams<S>, left_edge: f64, dt: f64, steps: usize) -> f64 {
    // By id: the pipeline reorders the points.
    let left: Vec<u64> = (0..pts.len())
        .filter(|&k| S::component(pts.x[k], 0) < left_edge)
        .map(|k| pts.id[k])
        .collect();
    let end_velocity = |pts: &Points<S>| {
        let ends = (0..pts.len()).filter(|&k| left.binary_search(&pts.id[k]).is_ok());
        ends.map(|k| S::component(pts.v[k], 0)).sum::<f64>() / left.len() as f64
    };
    let mut pipe = pipeline::<S>();
    let mut crossings = Vec::new();
    let mut last = end_velocity(pts);
    for s in 1..=steps {
        pipe.step(pts, p, dt).unwrap();
        let now = end_velocity(pts);
        if (now > 0.0) != (last > 0.0) {
            // Linear interpolation of the crossing time.
            crossings.push((s as f64 - now / (now - last)) * dt);
        }
        last = now;
    }
    assert!(crossings.len() >= 4, "{crossings:?}");
    1.0 / (crossings[3] - crossings[1])
}

/// P2G conserves mass and momentum to round-off (the weights are a partition of unity).
#[test]
fn particle_to_grid_conserves_mass_and_momentum() {
    let h = 0.1;
    let grid = Grid::covering([0.0; 3], [2.0, 2.0, 0.0], h, 2);
    let mut pts = block([0.5, 0.5], [1.5, 1.2], h, 2, 1000.0);
    for k in 0..pts.len() {
        let t = k as f64 * 0.618;
        pts.v[k] = DVec2::new(t.sin(), (1.7 * t).cos());
        pts.x[k] += DVec2::new(0.013 * (3.1 * t).sin(), 0.011 * (2.3 * t).cos());
    }
    let mut pipe = pipeline::<D2>();
    let p = params(grid, h, 2, DruckerPragerYue::new(1e5, 0.3, 30.0, 2));
    pipe.phase1(&pts, &p, 1e-4).unwrap();
    let (m_grid, p_grid) = pipe.grid_totals();
    let m_pts: f64 = pts.mass.iter().sum();
    let (_, p_pts) = point_totals(&pts);
    assert!((m_grid - m_pts).abs() < 1e-12 * m_pts, "{m_grid} vs {m_pts}");
    assert!((p_grid - p_pts).length() < 1e-12 * m_pts, "{p_grid} vs {p_pts}");
}

/// A free block translating at constant velocity stays a rigid translation: unstrained,
/// every point keeps its velocity and moves by v t (G2P of a uniform field is exact).
#[test]
fn rigid_translation_is_preserved() {
    let h = 0.05;
    let grid = Grid::covering([0.0; 3], [2.0, 1.0, 0.0], h, 2);
    let mut pts = block([0.3, 0.3], [0.7, 0.6], h, 2, 1000.0);
    let v0 = DVec2::new(0.8, -0.3);
    pts.v.iter_mut().for_each(|v| *v = v0);
    let x0 = pts.x.clone();
    let mut pipe = pipeline::<D2>();
    let p = params(grid, h, 2, DruckerPragerYue::new(1e5, 0.3, 30.0, 2));
    let (dt, n) = (1e-3, 200);
    for _ in 0..n {
        pipe.step(&mut pts, &p, dt).unwrap();
    }
    for k in 0..pts.len() {
        let start = x0[pts.id[k] as usize];
        assert!((pts.v[k] - v0).length() < 1e-10, "point {k}: {:?}", pts.v[k]);
        assert!((pts.x[k] - (start + v0 * (n as f64 * dt))).length() < 1e-9, "point {k} drifted");
    }
}

/// First axial mode of a free–free elastic bar: f = c / (2L) with c = √(E/ρ) (ν = 0, so the
/// model's uniaxial modulus κ + μ is E; a classic result of 1D elastodynamics). Measured from
/// the sign changes of the end's velocity.
#[test]
fn elastic_bar_vibrates_at_c_over_2l() {
    let (len, young, density) = (1.0, 1e4, 1.0);
    let h = len / 64.0;
    let grid = Grid::covering([0.0; 3], [1.5, 0.25, 0.0], h, 2);
    let (x0, y0) = (0.25, 0.1);
    let mut pts = block([x0, y0], [x0 + len, y0 + 2.0 * h], h, 2, density);
    let v0 = 0.01;
    for k in 0..pts.len() {
        pts.v[k] = DVec2::new(v0 * (std::f64::consts::PI * (pts.x[k].x - x0) / len).cos(), 0.0);
    }
    let material = DruckerPragerYue::new(young, 0.0, 30.0, 2);
    let p = params(grid, h, 2, material);
    let c = (young / density).sqrt();
    let dt = 0.2 * cfl_time_step(&p.model, density, h, 2);
    let f = axial_frequency(&mut pts, &p, x0 + 0.5 * h, dt, (2.2 * 2.0 * len / c / dt) as usize);
    let expected = c / (2.0 * len);
    assert!(
        (f - expected).abs() / expected < 0.02,
        "f = {f} Hz, expected c/(2L) = {expected} Hz"
    );
}

/// Along a periodic axis a ring of material has no ends: a standing wave of one period's
/// length vibrates at f = c / L (c = √(E/ρ), as above), twice the free bar's c / (2L) for
/// the same length. Needs the grid to join across the boundary: with open ends the same
/// strip would ring at c / (2L).
#[test]
fn a_periodic_strip_rings_at_c_over_l() {
    let (len, young, density) = (1.0, 1e4, 1.0);
    let h = len / 64.0;
    let grid = Grid::covering([0.0; 3], [len, 0.25, 0.0], h, 2).with_periodic([true, false, false]);
    let y0 = 0.1;
    let mut pts = block([0.0, y0], [len, y0 + 2.0 * h], h, 2, density);
    let v0 = 0.01;
    for k in 0..pts.len() {
        pts.v[k] = DVec2::new(v0 * (2.0 * std::f64::consts::PI * pts.x[k].x / len).cos(), 0.0);
    }
    let p = params(grid, h, 2, DruckerPragerYue::new(young, 0.0, 30.0, 2));
    let c = (young / density).sqrt();
    let dt = 0.2 * cfl_time_step(&p.model, density, h, 2);
    // Points near x = 0 move as v0 cos(ωt) (the wave's antinode).
    let f = axial_frequency(&mut pts, &p, 0.5 * h, dt, (2.2 * 2.0 * len / c / dt) as usize);
    let expected = c / len;
    assert!((f - expected).abs() / expected < 0.02, "f = {f} Hz, expected c/L = {expected} Hz");
}

/// A block translating across a periodic boundary stays a rigid translation, on two threads
/// (each scattering its own share of the points): every point moves by v t modulo the
/// period and keeps v; the grid's mass and momentum are the points' to round-off.
#[test]
fn a_block_crossing_a_periodic_boundary_translates_rigidly() {
    let h = 0.01;
    let grid = Grid::covering([0.0; 3], [1.0, 1.0, 0.0], h, 2).with_periodic([true, false, false]);
    // 9,000 points: enough for the pipeline to split them between its threads.
    let mut pts = block([0.5, 0.2], [0.95, 0.7], h, 2, 1000.0);
    assert!(pts.len() >= 8192);
    let v0 = DVec2::new(1.0, 0.1);
    pts.v.iter_mut().for_each(|v| *v = v0);
    let x0 = pts.x.clone();
    let mut pipe = MpmPipeline::<D2>::new(2).unwrap();
    // Soft enough that dt is a tenth of the elastic limit h / c.
    let p = params(grid, h, 2, DruckerPragerYue::new(1e3, 0.3, 30.0, 2));
    // 0.3 s: the block's front crosses x = 1 after 0.05 s, its back after 0.5 s; half of it
    // ends on the far side.
    let (dt, n) = (1e-3, 300);
    for _ in 0..n {
        pipe.phase1(&pts, &p, dt).unwrap();
        let (m_grid, p_grid) = pipe.grid_totals();
        let m: f64 = pts.mass.iter().sum();
        assert!((m_grid - m).abs() < 1e-12 * m && (p_grid - v0 * m).length() < 1e-10 * m);
        pipe.phase2(&mut pts, &p, dt).unwrap();
    }
    let mut wrapped = 0;
    for k in 0..pts.len() {
        let mut x = x0[pts.id[k] as usize] + v0 * (n as f64 * dt);
        if x.x >= 1.0 {
            x.x -= 1.0;
            wrapped += 1;
        }
        assert!((pts.v[k] - v0).length() < 1e-10, "point {k}: {:?}", pts.v[k]);
        assert!((pts.x[k] - x).length() < 1e-9, "point {k} at {:?}, expected {x:?}", pts.x[k]);
    }
    assert!(wrapped > pts.len() / 3, "{wrapped} of {} crossed", pts.len());
}

/// A free elastic block spinning rigidly keeps its angular momentum within 1% over 1,000
/// steps with APIC (which conserves it by construction, Jiang et al. 2015). Measured on the
/// grid after each step's P2G, Σ x_i × p_i, which counts the points' affine part too.
#[test]
fn rigid_rotation_keeps_angular_momentum_with_apic() {
    let h = 0.05;
    let grid = Grid::covering([0.0; 3], [2.0, 2.0, 0.0], h, 2);
    let mut pts = block([0.8, 0.8], [1.2, 1.2], h, 2, 1000.0);
    let center = DVec2::new(1.0, 1.0);
    let omega = 1.0;
    for k in 0..pts.len() {
        let r = pts.x[k] - center;
        pts.v[k] = DVec2::new(-omega * r.y, omega * r.x);
        // The rigid rotation's velocity gradient.
        pts.affine[k] = glam::DMat2::from_cols(DVec2::new(0.0, omega), DVec2::new(-omega, 0.0));
    }
    let material = DruckerPragerYue::new(1e6, 0.3, 30.0, 2);
    let mut p = params(grid, h, 2, material);
    p.transfer = Transfer::Apic;
    let dt = 0.3 * cfl_time_step(&p.model, 1000.0, h, 2);
    let mut pipe = pipeline::<D2>();
    let grid_angular = |pipe: &mut MpmPipeline<D2>| -> f64 {
        let mut l = 0.0;
        pipe.for_each_node_mut(|ijk, m, v| {
            let x = grid.position(ijk);
            l += m * (x[0] * v.y - x[1] * v.x);
        });
        l
    };
    pipe.step(&mut pts, &p, dt).unwrap();
    let l0 = grid_angular(&mut pipe);
    for _ in 0..999 {
        pipe.step(&mut pts, &p, dt).unwrap();
    }
    let l1 = grid_angular(&mut pipe);
    let first = pts.id.iter().position(|&i| i == 0).unwrap();
    let moved = (pts.x[first] - center).angle_to(DVec2::new(0.8, 0.8) - center).abs();
    assert!(moved > 0.1, "the block must have turned");
    assert!((l1 - l0).abs() < 0.01 * l0.abs(), "angular momentum {l1} vs {l0}");
}

/// The same free–free bar in 3D (a square rod): f = c / (2L).
#[test]
fn elastic_bar_vibrates_at_c_over_2l_in_3d() {
    use glam::DVec3;
    use grains_grid::D3;
    let (len, young, density) = (1.0, 1e4, 1.0);
    let h = len / 32.0;
    let grid = Grid::covering([0.0; 3], [1.5, 0.25, 0.25], h, 3);
    let (x0, y0) = (0.25, 0.1);
    let mut pts = Points::<D3>::default();
    let d = h / 2.0;
    for k in 0..4 {
        for j in 0..4 {
            for i in 0..64 {
                pts.push(
                    DVec3::new(x0 + (i as f64 + 0.5) * d, y0 + (j as f64 + 0.5) * d, y0 + (k as f64 + 0.5) * d),
                    density * d * d * d,
                    d * d * d,
                    0.6,
                );
            }
        }
    }
    let v0 = 0.01;
    for k in 0..pts.len() {
        pts.v[k] = DVec3::new(v0 * (std::f64::consts::PI * (pts.x[k].x - x0) / len).cos(), 0.0, 0.0);
    }
    let material = DruckerPragerYue::new(young, 0.0, 30.0, 3);
    let p = MpmParams::<D3> {
        grid,
        kernel: Kernel::Gimp { half_width: 0.25 * h },
        model: Model::Elastic(material),
        gravity: DVec3::ZERO,
        transfer: Transfer::Flip(1.0),
        domain_walls: None,
        walls: Vec::new(),
        point_loads: grains_mpm::pipeline::PointLoads::Weights,
        ambient_pressure: 0.0,
    };
    // ν = 0 in 3D: κ = E/3, μ = E/2; the uniaxial stress modulus of a free rod is E.
    let c = (young / density).sqrt();
    let dt = 0.2 * cfl_time_step(&p.model, density, h, 3);
    let f = axial_frequency(&mut pts, &p, x0 + 0.5 * h, dt, (2.2 * 2.0 * len / c / dt) as usize);
    let expected = c / (2.0 * len);
    assert!(
        (f - expected).abs() / expected < 0.02,
        "3D: f = {f} Hz, expected c/(2L) = {expected} Hz"
    );
}

fn sand_params_2d(grid: Grid, h: f64, model: Model) -> MpmParams<D2> {
    use grains_mpm::boundary::{Contact, Geometry, Wall};
    MpmParams {
        grid,
        kernel: Kernel::Gimp { half_width: 0.25 * h },
        model,
        gravity: DVec2::new(0.0, -9.81),
        transfer: Transfer::Flip(0.98),
        domain_walls: Some(Contact::Slip),
        walls: vec![Wall {
            geometry: Geometry::Plane {
                point: DVec2::ZERO,
                normal: DVec2::Y,
            },
            contact: Contact::Friction(0.5),
            velocity: DVec2::ZERO,
            shift: DVec2::ZERO,
            id: 0,
        }],
        point_loads: grains_mpm::pipeline::PointLoads::Weights,
        ambient_pressure: 0.0,
    }
}

/// Slope of a pile's flank: the highest point in every column of width `w`, fitted by least
/// squares over the columns whose top lies between 20% and 80% of the pile's height (the
/// crest and the one-point-thick toe left out).
fn flank_slope(pts: &Points<D2>, w: f64) -> f64 {
    let x_max = pts.x.iter().map(|x| x.x).fold(0.0, f64::max);
    let n = (x_max / w).ceil() as usize + 1;
    let mut top = vec![f64::NEG_INFINITY; n];
    for x in &pts.x {
        let c = ((x.x.max(0.0) / w) as usize).min(n - 1);
        top[c] = top[c].max(x.y);
    }
    let height = top.iter().cloned().fold(0.0, f64::max);
    let flank: Vec<(f64, f64)> = top
        .iter()
        .enumerate()
        .filter(|(_, t)| **t > 0.2 * height && **t < 0.8 * height)
        .map(|(c, t)| ((c as f64 + 0.5) * w, *t))
        .collect();
    assert!(flank.len() >= 5, "too few flank columns: {flank:?}");
    let n = flank.len() as f64;
    let (mx, my) = (
        flank.iter().map(|p| p.0).sum::<f64>() / n,
        flank.iter().map(|p| p.1).sum::<f64>() / n,
    );
    let sxy: f64 = flank.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    let sxx: f64 = flank.iter().map(|p| (p.0 - mx).powi(2)).sum();
    (sxy / sxx).abs()
}

/// A block of Drucker–Prager sand (Yue 2018 model, friction angle 30°) released on a rough
/// floor slumps and comes to rest with a flank no steeper than the friction angle: with
/// α from the plane Mohr–Coulomb match, a slope steeper than φ cannot carry gravity (the
/// infinite-slope stability of a cohesionless Coulomb material, tan β ≤ tan φ).
#[test]
fn drucker_prager_block_comes_to_rest_no_steeper_than_its_friction_angle() {
    let (h, density, phi) = (0.01, 1600.0, 30.0);
    let grid = Grid::covering([-0.03, -0.03, 0.0], [0.8, 0.35, 0.0], h, 2);
    let mut pts = block([0.0, 0.0], [0.2, 0.2], h, 2, density);
    let material = DruckerPragerYue::new(1e6, 0.3, phi, 2);
    let p = sand_params_2d(grid, h, Model::Yue(material));
    let dt = 0.3 * cfl_time_step(&p.model, density, h, 2);
    let mut pipe = pipeline::<D2>();
    let steps = (1.5 / dt) as usize;
    let mass: f64 = pts.mass.iter().sum();
    for _ in 0..steps {
        pipe.step(&mut pts, &p, dt).unwrap();
    }
    let (ke, _) = point_totals(&pts);
    // At rest: kinetic energy below 1e-6 of the potential energy released m g H.
    assert!(ke < 1e-6 * mass * 9.81 * 0.2, "still moving: {ke} J");
    let runout = pts.x.iter().map(|x| x.x).fold(0.0, f64::max);
    assert!(runout > 0.25, "the block must have slumped (front at {runout} m)");
    let slope = flank_slope(&pts, 2.0 * h);
    let limit = phi.to_radians().tan();
    eprintln!(
        "pile flank {:.1}° (friction angle {phi}°), front at {runout:.3} m",
        slope.atan().to_degrees()
    );
    assert!(
        slope <= limit,
        "flank slope {slope:.3} (= {:.1}°) above tan φ = {limit:.3}",
        slope.atan().to_degrees()
    );
}

/// An infinite slope (Yue 2018 §5's periodic chute as a continuum): a layer of the Drucker–
/// Prager model on a sticky floor, inclined at θ beyond its friction angle φ, accelerates as a
/// whole at a = g (sin θ − cos θ sin φ). Equilibrium of the layer above depth z gives
/// τ_xy / σ_yy = (g sin θ − a) / (g cos θ) at every depth, and in 2D the model yields when
/// the Mohr circle's radius reaches p sin φ; in steady simple shear the (deviatoric,
/// coaxial) flow keeps σ_xx = σ_yy, so τ_xy = p sin φ with p = σ_yy. The continuum's chute is
/// a Coulomb block with friction sin φ: it never reaches the steady flow a grain chute does.
#[test]
fn a_continuum_layer_on_an_incline_slides_as_a_coulomb_block() {
    use grains_mpm::boundary::{Contact, Geometry, Wall};
    let (h, density, phi, theta) = (0.004, 2075.0, 13.24f64, 22.0f64);
    let grid = Grid::covering([0.0, -3.0 * h, 0.0], [0.2, 0.08, 0.0], h, 2).with_periodic([true, false, false]);
    let mut pts = block([0.0, 0.0], [0.2, 0.048], h, 2, density);
    let g = 9.81;
    let (st, ct) = (theta.to_radians().sin(), theta.to_radians().cos());
    let p = MpmParams {
        grid,
        kernel: Kernel::Gimp { half_width: 0.25 * h },
        model: Model::Yue(DruckerPragerYue::new(2.8e5, 0.3, phi, 2)),
        gravity: DVec2::new(g * st, -g * ct),
        transfer: Transfer::Flip(1.0),
        domain_walls: Some(Contact::Slip),
        walls: vec![Wall {
            geometry: Geometry::Plane {
                point: DVec2::ZERO,
                normal: DVec2::Y,
            },
            contact: Contact::Sticky,
            velocity: DVec2::ZERO,
            shift: DVec2::ZERO,
            id: 0,
        }],
        point_loads: grains_mpm::pipeline::PointLoads::Weights,
        ambient_pressure: 0.0,
    };
    let dt = 0.3 * cfl_time_step(&p.model, density, h, 2);
    let mut pipe = pipeline::<D2>();
    // The upper half of the layer, by id (the pipeline reorders the points): the floor holds
    // the material within a cell of it, which does not slide.
    let upper: Vec<u64> = (0..pts.len()).filter(|&k| pts.x[k].y > 0.024).map(|k| pts.id[k]).collect();
    let mean_vx = |pts: &Points<D2>| {
        let v = (0..pts.len())
            .filter(|&k| upper.binary_search(&pts.id[k]).is_ok())
            .map(|k| pts.v[k].x);
        v.sum::<f64>() / upper.len() as f64
    };
    // The mean velocity from 0.1 s (the elastic start over) to 0.3 s.
    let (mut first, mut t) = (None, 0.0);
    while t < 0.3 {
        pipe.step(&mut pts, &p, dt).unwrap();
        t += dt;
        if first.is_none() && t >= 0.1 {
            first = Some((t, mean_vx(&pts)));
        }
    }
    let (t1, v1) = first.unwrap();
    let a = (mean_vx(&pts) - v1) / (t - t1);
    let expected = g * (st - ct * phi.to_radians().sin());
    eprintln!(
        "a = {a:.4} m/s², g (sin θ − cos θ sin φ) = {expected:.4}, with tan φ {:.4}",
        g * (st - ct * phi.to_radians().tan())
    );
    // 1.5%: friction tan φ (Mohr–Coulomb's tangent plane) would be 3.6% slower.
    assert!((a - expected).abs() < 0.015 * expected, "a = {a} m/s², expected {expected}");
}

/// Material pulled apart carries no pressure: under extension the Yue model flows freely
/// (det b^e projected to 1) and the critical-state model returns to its stress-free apex
/// (cohesionless). A block given a uniform expansion velocity field, no gravity.
#[test]
fn extension_leaves_zero_pressure() {
    use grains_mpm::constitutive::hencky_critical_state::HenckyCriticalState;
    let (h, density) = (0.05, 1000.0);
    let grid = Grid::covering([0.0; 3], [2.0, 2.0, 0.0], h, 2);
    let yue = Model::Yue(DruckerPragerYue::new(1e5, 0.3, 30.0, 2));
    let elastic = DruckerPragerYue::new(1e5, 0.3, 0.0, 2);
    let chen = Model::CriticalState(HenckyCriticalState {
        bulk: elastic.bulk,
        shear: elastic.shear,
        tan_friction_cs: 30f64.to_radians().tan(),
        packing_cs: 0.8,
        chi: 7.0,
        xi: 0.01,
        cohesion: 0.0,
    });
    for model in [yue, chen] {
        let mut pts = block([0.7, 0.7], [1.3, 1.3], h, 2, density);
        let center = DVec2::new(1.0, 1.0);
        for k in 0..pts.len() {
            pts.v[k] = (pts.x[k] - center) * 0.5;
        }
        let mut p = params(grid, h, 2, elastic);
        p.model = model;
        let dt = 0.3 * cfl_time_step(&p.model, density, h, 2);
        let mut pipe = pipeline::<D2>();
        for _ in 0..200 {
            pipe.step(&mut pts, &p, dt).unwrap();
        }
        let spread = pts.x.iter().map(|x| (*x - center).length()).fold(0.0, f64::max);
        assert!(spread > 0.45, "{model:?}: the block must have expanded ({spread})");
        for k in 0..pts.len() {
            let pressure = Model::pressure(&pts.tau[k], pts.jacobian[k]);
            assert!(pressure.abs() < 1e-9 * elastic.bulk, "{model:?}: point {k} pressure {pressure} Pa");
        }
    }
}

/// The coupling point: phase 2 starts from the grid velocities as the coupler left them. With
/// PIC (β = 0) every point takes the interpolated grid velocity, so a uniform overwrite u
/// reaches every point exactly (the weights sum to one), and the points move by u dt.
#[test]
fn phase_two_starts_from_overwritten_grid_velocities() {
    let h = 0.05;
    let grid = Grid::covering([0.0; 3], [2.0, 2.0, 0.0], h, 2);
    let mut pts = block([0.5, 0.5], [1.0, 0.9], h, 2, 1000.0);
    for k in 0..pts.len() {
        pts.v[k] = DVec2::new(0.3 * (k as f64).sin(), -0.2);
    }
    let mut p = params(grid, h, 2, DruckerPragerYue::new(1e5, 0.3, 30.0, 2));
    p.transfer = Transfer::Flip(0.0);
    let mut pipe = pipeline::<D2>();
    let (dt, u) = (1e-4, DVec2::new(0.7, 0.25));
    let x0 = pts.x.clone();
    pipe.phase1(&pts, &p, dt).unwrap();
    let mut nodes = 0;
    pipe.for_each_node_mut(|_, _, v| {
        *v = u;
        nodes += 1;
    });
    assert!(nodes > 0);
    pipe.phase2(&mut pts, &p, dt).unwrap();
    for k in 0..pts.len() {
        assert!((pts.v[k] - u).length() < 1e-12, "point {k}: {:?}", pts.v[k]);
        assert!((pts.x[k] - x0[pts.id[k] as usize] - u * dt).length() < 1e-12);
    }
}

/// The hybrid hook: a point's weight w scales the mass it puts on the grid (and its stress):
/// with w = 0.5 on every point the grid carries half the mass and half the momentum.
#[test]
fn hybrid_weight_scales_the_mass_on_the_grid() {
    let h = 0.1;
    let grid = Grid::covering([0.0; 3], [2.0, 2.0, 0.0], h, 2);
    let mut pts = block([0.5, 0.5], [1.5, 1.2], h, 2, 1000.0);
    pts.v.iter_mut().for_each(|v| *v = DVec2::new(1.0, 2.0));
    pts.weight.iter_mut().for_each(|w| *w = 0.5);
    let mut pipe = pipeline::<D2>();
    let p = params(grid, h, 2, DruckerPragerYue::new(1e5, 0.3, 30.0, 2));
    pipe.phase1(&pts, &p, 1e-4).unwrap();
    let (m_grid, p_grid) = pipe.grid_totals();
    let m_pts: f64 = pts.mass.iter().sum();
    assert!((m_grid - 0.5 * m_pts).abs() < 1e-12 * m_pts, "{m_grid} vs {m_pts} / 2");
    assert!((p_grid - DVec2::new(0.5, 1.0) * m_pts).length() < 1e-12 * m_pts);
}

/// The other way to confine a box of points (those in `range`), kept to compare: every point
/// within one point spacing `d` of a face carries the dead load −p A n (A = d^(d−1), n the outward
/// normal of the face), fixed in direction (small rotations of the faces assumed).
fn confine<S: MpmSpace>(
    pts: &mut grains_mpm::points::Points<S>,
    range: std::ops::Range<usize>,
    min: [f64; 3],
    max: [f64; 3],
    spacing: f64,
    pressure: f64,
) {
    let area = spacing.powi(S::DIM as i32 - 1);
    for p in range {
        let x = S::to_array(pts.x[p]);
        let mut f = [0.0; 3];
        for k in 0..S::DIM {
            if x[k] - min[k] < spacing {
                f[k] += pressure * area;
            }
            if max[k] - x[k] < spacing {
                f[k] -= pressure * area;
            }
        }
        if f != [0.0; 3] {
            pts.loads.push((p, S::from_array(f)));
        }
    }
}

/// A confining fluid at p around a free elastic block from rest at no stress (no gravity, PIC
/// damping the ringing: the scene's `confining_pressure`, `MpmParams::ambient_pressure`)
/// compresses it isotropically: at rest its interior pressure is p (force balance of a
/// uniformly loaded body), within 0.5% (measured 0.06% under), and so is the face's outer
/// cell as a whole: the mean σxx of its two columns of points, within 2% (measured 1.2%
/// under). The columns share it unevenly, 1.16 p on the outer and 0.81 p on the inner: a
/// stress mode of the points within a cell that the nodes, which see only what the cell's
/// points add up to (nearly: GIMP's weights differ a little), do not resist; the transient
/// from no stress leaves it there. That is the outer ring's 10% over p printed beside (the
/// ring is the outer column); a block started at −p I keeps p on every point
/// (`an_ambient_pressure_holds_a_block_at_its_stress`). The same block with the pressure as
/// point loads on the outer ring ([`confine`], the scene's way until 2026-12-05), printed:
/// interior 1.2% over, ring 17% under, the outer cell 26% under.
#[test]
fn a_confining_pressure_is_carried_by_the_interior() {
    let (h, density, pressure) = (0.02, 1000.0, 2e4);
    let grid = Grid::covering([0.0; 3], [1.0, 1.0, 0.0], h, 2);
    let (lo, hi) = ([0.3, 0.3], [0.7, 0.7]);
    let center = DVec2::new(0.5, 0.5);
    let mut results = Vec::new();
    for fluid in [true, false] {
        let mut pts = block(lo, hi, h, 2, density);
        let n = pts.len();
        let mut p = params(grid, h, 2, DruckerPragerYue::new(2e6, 0.3, 30.0, 2));
        if fluid {
            p.ambient_pressure = pressure;
        } else {
            confine(&mut pts, 0..n, [lo[0], lo[1], 0.0], [hi[0], hi[1], 0.0], 0.5 * h, pressure);
            assert_eq!(pts.loads.len(), 4 * 40 - 4, "the outer ring of 40 × 40 points");
        }
        p.transfer = Transfer::Flip(0.0);
        let dt = 0.3 * cfl_time_step(&p.model, density, h, 2);
        let mut pipe = pipeline::<D2>();
        for _ in 0..4000 {
            pipe.step(&mut pts, &p, dt).unwrap();
        }
        // At rest: kinetic energy below 1e-6 of the stored elastic energy p² A / (2κ).
        let (ke, _) = point_totals(&pts);
        let elastic = pressure * pressure * 0.16 / (2.0 * DruckerPragerYue::new(2e6, 0.3, 30.0, 2).bulk);
        assert!(ke < 1e-6 * elastic, "not at rest: {ke} J");
        let mean_of = |keep: &dyn Fn(f64) -> bool| {
            let ps: Vec<f64> = (0..pts.len())
                .filter(|&k| keep((pts.x[k] - center).abs().max_element()))
                .map(|k| Model::pressure(&pts.tau[k], pts.jacobian[k]))
                .collect();
            ps.iter().sum::<f64>() / ps.len() as f64
        };
        let (inner, ring) = (mean_of(&|r| r < 0.1), mean_of(&|r| r > 0.19));
        // The right face's outer cell (x 0.68–0.70): its two columns of points, the corners
        // left out, σxx each and their mean.
        let column = |x: f64| {
            let ids: Vec<usize> = (0..pts.len())
                .filter(|&k| (pts.x[k].x - x).abs() < 0.004 && (pts.x[k].y - center.y).abs() < 0.15)
                .collect();
            ids.iter().map(|&k| -pts.tau[k].x_axis.x / pts.jacobian[k]).sum::<f64>() / ids.len() as f64
        };
        let (outer, next) = (column(0.695), column(0.685));
        eprintln!(
            "{}: interior pressure {inner:.1} Pa, outer ring {ring:.1} Pa under a confining {pressure} Pa; the right face's outer cell: σxx {outer:.1} (outer column), {next:.1} (inner), mean {:.1} Pa",
            if fluid { "fluid" } else { "point loads" },
            0.5 * (outer + next)
        );
        results.push((inner, 0.5 * (outer + next)));
    }
    let (inner, face) = results[0];
    assert!(
        (inner - pressure).abs() < 0.005 * pressure,
        "interior pressure {inner} Pa vs {pressure} Pa"
    );
    assert!(
        (face - pressure).abs() < 0.02 * pressure,
        "the outer cell's σxx {face} Pa vs {pressure} Pa"
    );
}

/// A block at the stress −p I of a confining fluid, in a frictional material at rest, stays
/// there with `ambient_pressure` = p: every point keeps p to round-off and nothing moves (the
/// fluid's nodal forces cancel the stress's node by node), also with the points' volume 10%
/// under their reference one (the fluid's Kirchhoff stress is J p I). Without the fluid the
/// same block springs out from its faces, which the test checks too. (With the pressure as
/// point loads on the outer ring, `confine`, the ring's points lose their stress: printed.)
#[test]
fn an_ambient_pressure_holds_a_block_at_its_stress() {
    use grains_mpm::constitutive::hencky_critical_state::HenckyCriticalState;
    use grains_mpm::matrix::Matrix;
    let (h, density, pressure) = (0.02, 1000.0, 2e4);
    let grid = Grid::covering([0.0; 3], [1.0, 1.0, 0.0], h, 2);
    let (lo, hi) = ([0.3, 0.3], [0.7, 0.7]);
    // Chen's Hencky model at its critical state (no dilatancy): Kirchhoff −p I from
    // b^e = exp(−p / K) I in 2D, with J = 1.
    let material = HenckyCriticalState {
        bulk: 1.7e6,
        shear: 7.7e5,
        tan_friction_cs: 30f64.to_radians().tan(),
        packing_cs: 0.8,
        chi: 0.0,
        xi: 0.0,
        cohesion: 0.0,
    };
    // `jacobian`: the points' J (their volume over the reference one); the fluid's Kirchhoff
    // stress is J p I, so a block at Cauchy −p I with J ≠ 1 is still in equilibrium.
    let run = |ambient: f64, loads: bool, jacobian: f64| {
        let mut pts = block(lo, hi, h, 2, density);
        pts.jacobian.iter_mut().for_each(|j| *j = jacobian);
        let mut p = params(grid, h, 2, DruckerPragerYue::new(2e6, 0.3, 30.0, 2));
        p.model = Model::CriticalState(material);
        p.ambient_pressure = ambient;
        let identity = <D2 as MpmSpace>::M::identity();
        for k in 0..pts.len() {
            pts.b_e[k] = identity * (-pressure * jacobian / material.bulk).exp();
            pts.tau[k] = p.model.kirchhoff(&pts.b_e[k]);
        }
        if loads {
            let n = pts.len();
            confine(&mut pts, 0..n, [lo[0], lo[1], 0.0], [hi[0], hi[1], 0.0], 0.5 * h, pressure);
        }
        let dt = 0.3 * cfl_time_step(&p.model, density, h, 2);
        let mut pipe = pipeline::<D2>();
        for _ in 0..500 {
            pipe.step(&mut pts, &p, dt).unwrap();
        }
        let speed = pts.v.iter().map(|v| v.length()).fold(0.0, f64::max);
        let worst = (0..pts.len())
            .map(|k| (Model::pressure(&pts.tau[k], pts.jacobian[k]) - pressure).abs())
            .fold(0.0, f64::max);
        eprintln!(
            "ambient {ambient} Pa, point loads {loads}: fastest point {speed:.3e} m/s, worst pressure off by {:.3e}",
            worst / pressure
        );
        (speed, worst / pressure)
    };
    let (speed, error) = run(pressure, false, 1.0);
    assert!(
        speed < 1e-12 && error < 1e-9,
        "with the fluid: {speed} m/s, pressure off by {error}"
    );
    // Compressed by 10% in area: the fluid's term must carry J (without it the block moves).
    let (speed, error) = run(pressure, false, 0.9);
    assert!(
        speed < 1e-12 && error < 1e-9,
        "with the fluid, J = 0.9: {speed} m/s, pressure off by {error}"
    );
    let (speed, error) = run(0.0, false, 1.0);
    assert!(speed > 1e-3 && error > 0.1, "without it: {speed} m/s, pressure off by {error}");
    // The point loads, for the record (not asserted: a better `confine` may close the gap).
    run(0.0, true, 1.0);
}

/// Memory follows the material: a small block in a 20 m × 20 m domain of 1 cm cells (4 million
/// nodes) stores under 0.1% of the domain's nodes.
#[test]
fn the_grid_stores_only_blocks_near_material() {
    let h = 0.01;
    let grid = Grid::covering([0.0; 3], [20.0, 20.0, 0.0], h, 2);
    let pts = block([10.0, 10.0], [10.2, 10.2], h, 2, 1000.0);
    let mut pipe = pipeline::<D2>();
    let p = params(grid, h, 2, DruckerPragerYue::new(1e5, 0.3, 30.0, 2));
    pipe.phase1(&pts, &p, 1e-4).unwrap();
    let domain_nodes = (grid.nodes[0] * grid.nodes[1]) as usize;
    assert!(
        pipe.map.len() < domain_nodes / 1000,
        "{} of {domain_nodes} nodes stored",
        pipe.map.len()
    );
    // 20 × 20 cells of material touch at most 7 × 7 blocks of 4 × 4 nodes.
    assert!(pipe.map.len() <= 49 * 16, "{}", pipe.map.len());
}

/// A step that goes wrong stops with the phase named: a NaN velocity poisons the grid in
/// phase 1; a point pushed to the grid's edge is caught before its stencil leaves the grid.
#[test]
fn broken_states_stop_naming_the_phase() {
    use grains_mpm::pipeline::{Phase, StepError};
    let h = 0.05;
    let grid = Grid::covering([0.0; 3], [2.0, 2.0, 0.0], h, 2);
    let p = params(grid, h, 2, DruckerPragerYue::new(1e5, 0.3, 30.0, 2));
    let mut pts = block([0.5, 0.5], [0.7, 0.7], h, 2, 1000.0);
    pts.v[3] = DVec2::new(f64::NAN, 0.0);
    let err = pipeline::<D2>().step(&mut pts, &p, 1e-4).unwrap_err();
    assert!(
        matches!(
            err,
            StepError::NotFinite {
                phase: Phase::GridUpdate,
                ..
            }
        ),
        "{err}"
    );
    assert!(err.to_string().contains("phase 1"), "{err}");
    let mut pts = block([0.5, 0.5], [0.7, 0.7], h, 2, 1000.0);
    pts.x[0] = DVec2::new(0.02, 0.6);
    let err = pipeline::<D2>().step(&mut pts, &p, 1e-4).unwrap_err();
    assert!(matches!(err, StepError::LeftDomain { .. }), "{err}");
}

/// A point load for one step (the contact coupling's): spread with the point's weights it
/// reaches every point sharing one of its nodes; put on the nearest node instead (Jiang 2020
/// §5.4's MPM-GRID) only the points within that node's support move. Both add F dt to the
/// momentum exactly (FLIP, no walls, no gravity), and so does the load on the point's face
/// (`PointLoads::Face`).
#[test]
fn a_point_load_acts_through_the_weights_or_on_the_nearest_node() {
    use grains_mpm::pipeline::PointLoads;
    let h = 0.05;
    let lp = 0.25 * h;
    let f = DVec2::new(3.0, -1.0);
    let dt = 1e-4;
    let mut moved = Vec::new();
    for mode in [PointLoads::Weights, PointLoads::Nearest, PointLoads::Face] {
        let grid = Grid::covering([0.0; 3], [1.0, 1.0, 0.0], h, 2);
        let mut pts = block([0.3, 0.3], [0.7, 0.7], h, 2, 1000.0);
        // A point near the middle: x = 0.5125, y = 0.4875 (a quarter cell off the node (0.5, 0.5)).
        let p = (0..pts.len())
            .min_by(|&a, &b| {
                (pts.x[a] - DVec2::splat(0.5))
                    .length()
                    .total_cmp(&(pts.x[b] - DVec2::splat(0.5)).length())
            })
            .unwrap();
        let node = (pts.x[p] / h).round() * h;
        pts.loads.push((p, f));
        let mut params = params(grid, h, 2, DruckerPragerYue::new(1e5, 0.3, 30.0, 2));
        params.point_loads = mode;
        let p0: DVec2 = pts.v.iter().zip(&pts.mass).map(|(v, m)| *v * *m).sum();
        pipeline::<D2>().step(&mut pts, &params, dt).unwrap();
        let p1: DVec2 = pts.v.iter().zip(&pts.mass).map(|(v, m)| *v * *m).sum();
        assert!(
            (p1 - p0 - f * dt).length() < 1e-12 * (f * dt).length(),
            "{mode:?}: momentum {:?}",
            p1 - p0
        );
        // Points outside the nearest node's support (|x − x_j| ≥ h + l_p along an axis).
        let outside: Vec<bool> = (0..pts.len())
            .map(|k| {
                let d = (pts.x[k] - node).abs();
                d.x >= h + lp || d.y >= h + lp
            })
            .collect();
        let moved_outside = (0..pts.len()).filter(|&k| outside[k] && pts.v[k] != DVec2::ZERO).count();
        moved.push(moved_outside);
    }
    assert!(
        moved[0] > 0,
        "spread with its weights, the load reaches beyond the nearest node's support"
    );
    assert_eq!(moved[1], 0, "on the nearest node, the load moves only the points of its support");
}
