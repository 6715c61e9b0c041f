//! `grains validate --part contact`: the DEM contact law against its analytic restitution.
//! Two equal grains of the silo's material meet head-on; the rebound over the approach speed
//! is the restitution the damping was derived from (linear spring–dashpot:
//! e = exp(−πζ/√(1−ζ²)), Cundall & Strack's model as used by Yue 2018 §2). Checked to 2%.

use super::args::ValidateArgs;
use super::runs::load_with;
use super::scenes::silo::SCENE;
use crate::report::Part;
use grains_dem::contact::{ContactParams, Damping};
use grains_dem::pipeline::DemPipeline;
use grains_dem::space::{D2, Space};
use grains_dem::state::{DemParams, DemState, Domain, Grains};
use std::fmt::Write as _;

/// Restitution coefficients checked and their tolerance.
const RESTITUTIONS: [f64; 3] = [0.1, 0.5, 0.9];
const RESTITUTION_TOLERANCE: f64 = 0.02;

/// Rebound over approach speed of a head-on impact of two grains with `p`, radius `r`.
fn impact(p: ContactParams, r: f64, density: f64) -> f64 {
    let mut st = DemState::<D2> {
        grains: Grains::default(),
        bodies: Vec::new(),
        walls: Vec::new(),
        params: DemParams {
            materials: vec![p],
            gravity: D2::from_array([0.0; 3]),
            domain: Domain {
                min: [-1.0; 3],
                max: [1.0; 3],
                periodic: [false; 3],
            },
            skin: 0.1 * r,
        },
        time: 0.0,
    };
    let m = Grains::<D2>::mass_of(r, density);
    let v0 = 0.1;
    let a = st.grains.push(0, D2::from_array([-1.05 * r, 0.0, 0.0]), r, m, 0);
    let b = st.grains.push(1, D2::from_array([1.05 * r, 0.0, 0.0]), r, m, 0);
    st.grains.v[a] = D2::from_array([v0, 0.0, 0.0]);
    st.grains.v[b] = D2::from_array([-v0, 0.0, 0.0]);
    let contact = std::f64::consts::PI / (p.stiffness_normal / (0.5 * m)).sqrt();
    let dt = contact / 200.0;
    let steps = (3.0 * contact / dt) as usize + (0.1 * r / v0 / dt) as usize;
    let mut pipe = DemPipeline::<D2>::new(1).expect("one thread");
    pipe.run(&mut st, dt, steps);
    let (a, b) = (st.grains.index_of(0).unwrap(), st.grains.index_of(1).unwrap());
    D2::component(st.grains.v[b] - st.grains.v[a], 0) / (2.0 * v0)
}

pub fn validate(args: &ValidateArgs) -> anyhow::Result<Part> {
    let scene = load_with(&args.scenes.join(SCENE), &[])?;
    let mat = &scene.materials[0];
    let dem = mat.dem.as_ref().expect("the silo's material has DEM parameters");
    let mut part = Part::default();
    let mut md = String::from("## DEM contact: restitution of a head-on impact\n\n");
    let _ = writeln!(
        md,
        "Two grains of `silo_hybrid_2d.toml`'s material (radius {} m, k_n = {:.3e} N/m, density {} kg/m³) meet head-on \
         at ±0.1 m/s, 200 steps per contact time; measured: rebound over approach speed. Reference: the restitution the \
         damping was derived from (linear spring–dashpot, e = exp(−πζ/√(1−ζ²))).\n\n| set e | measured | error |\n|---:|---:|---:|",
        dem.radius, dem.stiffness_normal, mat.density
    );
    for e in RESTITUTIONS {
        let p = ContactParams {
            stiffness_normal: dem.stiffness_normal,
            stiffness_tangential: dem.stiffness_tangential,
            damping: Damping::Restitution(e),
            // GRAINS_FAULT: the fault-injection test breaks this check on purpose.
            damping_scale: grains_service::fault::restitution_damping_scale(),
            friction: dem.friction,
            cohesion_normal: 0.0,
            cohesion_tangential: 0.0,
        };
        let got = impact(p, dem.radius, mat.density);
        let err = got / e - 1.0;
        let _ = writeln!(md, "| {e} | {got:.4} | {:+.2}% |", 100.0 * err);
        part.check(
            format!("DEM restitution e = {e}"),
            "analytic: the set e (linear spring–dashpot)",
            format!("{got:.4} ({:+.2}%)", 100.0 * err),
            format!("±{:.0}%", 100.0 * RESTITUTION_TOLERANCE),
            err.abs() <= RESTITUTION_TOLERANCE,
        );
    }
    part.md = md;
    Ok(part)
}
