//! A sand block collapsing in a unit box, timed: `cargo run --release -p grains-mpm --example
//! collapse -- <dim 2|3> <cells per axis> <fill> <threads> <steps> [bspline|gimp] [cs|dp]
//! [periodic 0|1]`. Prints µs per point-step and where the time goes (the profiling companion
//! of `grains bench mpm`; `gimp dp 1` is the chute's continuum: GIMP, Drucker–Prager, a
//! periodic x axis).

use grains_grid::{D2, D3, Grid, Kernel, Space};
use grains_mpm::boundary::Contact;
use grains_mpm::constitutive::hencky_critical_state::HenckyCriticalState;
use grains_mpm::constitutive::plasticity_drucker_prager::DruckerPragerYue;
use grains_mpm::matrix::MpmSpace;
use grains_mpm::pipeline::{Model, MpmParams, MpmPipeline, PhaseTimes, Transfer, cfl_time_step};
use grains_mpm::points::{Points, Region, seed};
use std::time::Instant;

struct Options {
    gimp: bool,
    drucker_prager: bool,
    periodic: bool,
}

fn run<S: MpmSpace + Space>(n: usize, fill: f64, threads: usize, steps: usize, o: &Options) {
    let h = 1.0 / n as f64;
    let cells = ((fill * (n - 6) as f64).round() as usize).max(1);
    let mut lo = [0.0; 3];
    let mut hi = [0.0; 3];
    for k in 0..S::DIM {
        let w = cells as f64 * h;
        lo[k] = if k == 1 { 3.0 * h } else { 0.5 - 0.5 * w };
        hi[k] = lo[k] + w;
    }
    let (young, nu, rho) = (3.537e5, 0.3, 2200.0);
    let shear = young / (2.0 * (1.0 + nu));
    let lambda = young * nu / ((1.0 + nu) * (1.0 - 2.0 * nu));
    let model = if o.drucker_prager {
        Model::Yue(DruckerPragerYue::new(young, nu, 30.0, S::DIM))
    } else {
        Model::CriticalState(HenckyCriticalState {
            bulk: lambda + 2.0 * shear / S::DIM as f64,
            shear,
            tan_friction_cs: 30f64.to_radians().tan(),
            packing_cs: 0.6,
            chi: 0.0,
            xi: 0.0,
            cohesion: 0.0,
        })
    };
    let mut pts = Points::<S>::default();
    let vol = (h / 2.0).powi(S::DIM as i32);
    for x in seed::<S>(Region::Box { min: lo, max: hi }, [0.0; 3], h, 2) {
        pts.push(x, rho * vol, vol, 0.6);
    }
    let mut g = [0.0; 3];
    g[1] = -9.81;
    let params = MpmParams {
        grid: Grid::covering([0.0; 3], [1.0; 3], h, S::DIM).with_periodic([o.periodic, false, false]),
        kernel: if o.gimp {
            Kernel::Gimp { half_width: h / 4.0 }
        } else {
            Kernel::Bspline2
        },
        model,
        gravity: S::from_array(g),
        transfer: Transfer::Flip(0.95),
        domain_walls: Some(Contact::Sticky),
        walls: Vec::new(),
        point_loads: grains_mpm::pipeline::PointLoads::Weights,
        ambient_pressure: 0.0,
    };
    let dt = 0.3 * cfl_time_step(&params.model, rho, h, S::DIM);
    let mut pipe = MpmPipeline::<S>::new(threads).unwrap();
    for _ in 0..10 {
        pipe.step(&mut pts, &params, dt).unwrap();
    }
    pipe.times = PhaseTimes::default();
    let t = Instant::now();
    for _ in 0..steps {
        pipe.step(&mut pts, &params, dt).unwrap();
    }
    let wall = t.elapsed().as_secs_f64();
    let per = |d: std::time::Duration| d.as_secs_f64() / (steps * pts.len()) as f64 * 1e6;
    let tm = pipe.times;
    println!(
        "{}D {} points, {} threads: {:.4} µs/pt-step (p2g {:.4}, grid {:.4}, g2p {:.4}, constitutive {:.4}); {} active nodes",
        S::DIM,
        pts.len(),
        threads,
        wall / (steps * pts.len()) as f64 * 1e6,
        per(tm.p2g),
        per(tm.grid),
        per(tm.g2p),
        per(tm.constitutive),
        pipe.map.len()
    );
}

fn main() {
    let a: Vec<String> = std::env::args().collect();
    let arg = |k: usize, d: &str| a.get(k).cloned().unwrap_or_else(|| d.to_string());
    let (dim, n, fill, threads, steps): (usize, usize, f64, usize, usize) = (
        arg(1, "2").parse().unwrap(),
        arg(2, "256").parse().unwrap(),
        arg(3, "0.6").parse().unwrap(),
        arg(4, "1").parse().unwrap(),
        arg(5, "100").parse().unwrap(),
    );
    let o = Options {
        gimp: arg(6, "bspline") == "gimp",
        drucker_prager: arg(7, "cs") == "dp",
        periodic: arg(8, "0") == "1",
    };
    if dim == 2 {
        run::<D2>(n, fill, threads, steps, &o)
    } else {
        run::<D3>(n, fill, threads, steps, &o)
    }
}
