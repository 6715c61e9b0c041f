//! `grains validate --part contact,stability`: the DEM contact law against its analytic
//! restitution, and stability maps: where each method fails as its knob grows.
//!
//! - **contact**: two equal grains of the column's material meet head-on; the rebound over the
//!   approach speed is the restitution the damping was derived from (linear spring–dashpot:
//!   e = exp(−πζ/√(1−ζ²)), Cundall & Strack's model as used by Yue 2018 §2). Checked to 2%.
//! - **DEM time step** (in process, the library the DEM participant runs): the column's settled
//!   packing (a = 0.5) collapsing for 20 ms with dt = f × the critical step 2/ω (√(1+ζ²) − ζ)
//!   of the lightest pair. Unstable: a non-finite grain, or the total energy (kinetic +
//!   gravity + contact springs) rising by more than 10% of m g H / 2 above its start (a
//!   dissipative system can only lose energy). `grains run` refuses f above
//!   [`SAFE_FRACTION`]; the report quotes that message.
//! - **MPM CFL number** (in process): the MPM column (a = 1) for 50 ms with dt = f × h/c,
//!   c = √(M/ρ) the P-wave speed. Unstable: the step fails (non-finite values, a point leaving
//!   the grid) or the kinetic energy exceeds m g H / 2, all the energy gravity can release.
//!   `grains run` refuses CFL numbers above [`MAX_CFL`].
//! - **Substeps k** (processes): the hybrid column a = 1 for 0.2 s, DEM step 5e-7 s, MPM step
//!   k × 5e-7 s, up to past the MPM's CFL limit (drawn), where `grains run` refuses.
//! - **MPM cell / grain diameter** (processes): the same hybrid column on cells of 1–4 grain
//!   diameters (Yue 2018 used 2 and saw trouble at 1).
//!
//! `--quick` runs the contact check and the two in-process maps (seconds); the process maps
//! run in a full validation.

use crate::chart::{Chart, Kind, Series, VLine};
use crate::report::Part;
use crate::validate::{L0_COLUMN, ValidateArgs, ensure_packing, load_with, sweep};
use grains_dem::contact::{ContactParams, Damping};
use grains_dem::pipeline::{DemPipeline, SAFE_FRACTION, critical_time_step};
use grains_dem::space::{D2, Space};
use grains_dem::state::{DemParams, DemState, Domain, Grains};
use grains_mpm::pipeline::MAX_CFL;
use std::fmt::Write as _;

/// Restitution coefficients checked and their tolerance.
const RESTITUTIONS: [f64; 3] = [0.1, 0.5, 0.9];
const RESTITUTION_TOLERANCE: f64 = 0.02;
/// A run is unstable when the energy rises by this share of m g H / 2.
const ENERGY_GAIN: f64 = 0.1;

/// Rebound over approach speed of a head-on impact of two grains with `p`, radius `r`.
fn impact(p: ContactParams, r: f64, density: f64) -> f64 {
    let mut st = DemState::<D2> {
        grains: Grains::default(),
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

pub fn validate_contact(args: &ValidateArgs) -> anyhow::Result<Part> {
    let scene = load_with(&args.scenes.join("silo_hybrid_2d.toml"), &[])?;
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
            friction: dem.friction,
            cohesion_normal: 0.0,
            cohesion_tangential: 0.0,
            damping_scale: 1.0,
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

/// One run of a stability map.
struct Probe {
    knob: f64,
    stable: bool,
    /// The measure the criterion reads (energy gain or kinetic energy over m g H / 2).
    measure: f64,
    /// What failed, or what `grains run` says of this setting ("" when it runs).
    message: String,
    /// Wall time of the run [s].
    wall: f64,
}

pub fn validate_stability(args: &ValidateArgs) -> anyhow::Result<Part> {
    let mut part = Part::default();
    let mut md = String::from("## Stability maps\n\n");
    let dem = dem_map(args)?;
    map_section(
        &mut md,
        "DEM time step",
        "dt / critical step",
        "the column's settled packing, a = 0.5, 20 ms, in process. Unstable: a non-finite grain or the total energy \
         (kinetic + gravity + contact springs) gaining more than 10% of m g H / 2",
        "max energy gain / (m g H / 2)",
        &dem,
    );
    let first = dem.iter().find(|p| !p.stable).map(|p| p.knob);
    part.check(
        "DEM stable at every step grains accepts",
        format!("energy criterion at dt ≤ {SAFE_FRACTION} × critical (the limit `grains run` enforces)"),
        match first {
            Some(f) => format!("first unstable at {f} × critical"),
            None => "stable at every step tried".into(),
        },
        format!("stable up to {SAFE_FRACTION}"),
        dem.iter().filter(|p| p.knob <= SAFE_FRACTION).all(|p| p.stable),
    );
    part.check(
        "DEM instability detected beyond the analytic limit",
        "velocity Verlet diverges above 2/ω (√(1+ζ²) − ζ)",
        match first {
            Some(f) => format!("first unstable at {f} × critical"),
            None => "stable at every step tried".into(),
        },
        "unstable at 2 × critical",
        dem.iter().filter(|p| p.knob >= 2.0).all(|p| !p.stable),
    );
    part.chart(
        &args.out,
        "stability_dem_dt",
        "DEM: energy gain against the time step",
        &map_chart(
            "DEM time step: stability of the column's packing",
            "dt / critical step 2/w (sqrt(1+z^2) - z)",
            "max energy gain / (m g H / 2)",
            &dem,
            vec![
                VLine {
                    x: 1.0,
                    label: "analytic limit".into(),
                },
                VLine {
                    x: SAFE_FRACTION,
                    label: "grains refuses above".into(),
                },
            ],
            ENERGY_GAIN,
        ),
    )?;
    let mpm = mpm_map(args)?;
    map_section(
        &mut md,
        "MPM CFL number",
        "dt / (h/c)",
        "`column_collapse_mpm_2d.toml`, a = 1, 50 ms, in process. Unstable: the step fails (non-finite value, a point off \
         the grid) or the kinetic energy exceeds m g H / 2",
        "max kinetic energy / (m g H / 2)",
        &mpm,
    );
    part.check(
        "MPM stable at every step grains accepts",
        format!("energy criterion at CFL ≤ {MAX_CFL} (the limit `grains run` enforces; explicit MPM's bound is CFL 1, c = √(M/ρ))"),
        match mpm.iter().find(|p| !p.stable) {
            Some(p) => format!("first unstable at CFL {}", p.knob),
            None => "stable at every CFL number tried".into(),
        },
        format!("stable up to {MAX_CFL}"),
        mpm.iter().filter(|p| p.knob <= MAX_CFL).all(|p| p.stable),
    );
    part.chart(
        &args.out,
        "stability_mpm_cfl",
        "MPM: kinetic energy against the CFL number",
        &map_chart(
            "MPM CFL number: stability of the column collapse",
            "CFL number dt c / h",
            "max kinetic energy / (m g H / 2)",
            &mpm,
            vec![
                VLine {
                    x: 1.0,
                    label: "CFL limit h/c".into(),
                },
                VLine {
                    x: MAX_CFL,
                    label: "grains refuses above".into(),
                },
            ],
            1.0,
        ),
    )?;
    if !args.quick || !args.sweep_k.is_empty() {
        hybrid_maps(args, &mut part, &mut md)?;
    }
    part.md = md;
    Ok(part)
}

fn map_section(md: &mut String, title: &str, knob: &str, how: &str, measure: &str, probes: &[Probe]) {
    let _ = writeln!(
        md,
        "### {title}\n\n{how}.\n\n| {knob} | {measure} | stable | wall s | message |\n|---:|---:|---|---:|---|"
    );
    for p in probes {
        let _ = writeln!(
            md,
            "| {} | {:.3e} | {} | {:.1} | {} |",
            p.knob,
            p.measure,
            if p.stable { "yes" } else { "**no**" },
            p.wall,
            p.message.replace('|', "/").replace('\n', " ")
        );
    }
    md.push('\n');
}

fn map_chart(title: &str, x: &str, y: &str, probes: &[Probe], vlines: Vec<VLine>, bound: f64) -> Chart {
    // A log axis: measures at or under zero (energy lost) are drawn at 1e-6.
    let pt = |p: &Probe| (p.knob, if p.measure.is_finite() { p.measure.max(1e-6) } else { 1e3 });
    let lo = probes.first().map_or(0.01, |p| p.knob);
    let hi = probes.last().map_or(1.0, |p| p.knob);
    Chart {
        title: title.into(),
        x_label: x.into(),
        y_label: y.into(),
        log_x: true,
        log_y: true,
        series: vec![
            Series::new(
                "stable (a loss drawn at 1e-6)",
                Kind::Points,
                probes.iter().filter(|p| p.stable).map(pt).collect(),
            ),
            Series::new(
                "unstable (non-finite drawn at 1e3)",
                Kind::Crosses,
                probes.iter().filter(|p| !p.stable).map(pt).collect(),
            ),
            Series::new("criterion", Kind::Dashed, vec![(lo, bound), (hi, bound)]),
        ],
        vlines,
        ..Chart::default()
    }
}

fn dem_map(args: &ValidateArgs) -> anyhow::Result<Vec<Probe>> {
    let a = 0.5;
    let packing = ensure_packing(args, 1.0, 1)?;
    let path = args.scenes.join("column_collapse_2d.toml");
    let base = vec![
        format!("body.0.max=[{L0_COLUMN},{}]", 0.0015 + a * L0_COLUMN),
        format!("body.0.packing={:?}", packing.display().to_string()),
    ];
    let scene = load_with(&path, &base)?;
    let state0 = grains_dem_service::setup::build_state::<D2>(&scene, &grains_service::zones::ZoneField::layered(&scene))?;
    let g = &state0.grains;
    let free = (0..g.len()).filter(|&i| !g.frozen[i]);
    let m_min = free.clone().map(|i| g.mass[i]).fold(f64::INFINITY, f64::min);
    let mass: f64 = free.map(|i| g.mass[i]).sum();
    let critical = critical_time_step(&state0.params.materials[0], m_min);
    let scale = mass * 9.81 * 0.5 * a * L0_COLUMN;
    let duration = 0.02;
    let mut probes = Vec::new();
    for f in [0.05, 0.1, 0.2, 0.4, 0.7, 1.0, 1.3, 2.0] {
        let dt = f * critical;
        eprintln!("validate: stability, DEM dt = {f} × critical ({dt:.2e} s)");
        let t0 = std::time::Instant::now();
        let mut st = state0.clone();
        let mut pipe = DemPipeline::<D2>::new(scene.threads as usize)?;
        let energy = |pipe: &DemPipeline<D2>, st: &DemState<D2>| {
            DemPipeline::kinetic_energy(st) + DemPipeline::potential_energy(st) + pipe.elastic_energy(st)
        };
        pipe.run(&mut st, dt, 1);
        let e0 = energy(&pipe, &st);
        let (mut gain, mut message) = (f64::NEG_INFINITY, String::new());
        let steps = (duration / dt).ceil() as usize;
        let chunk = 20;
        for done in (0..steps).step_by(chunk) {
            pipe.run(&mut st, dt, chunk.min(steps - done));
            if let Some(id) = DemPipeline::first_non_finite(&st) {
                gain = f64::NAN;
                message = format!("grain {id} not finite at t = {:.2e} s", st.time);
                break;
            }
            gain = gain.max((energy(&pipe, &st) - e0) / scale);
            if gain > 1e3 {
                break;
            }
        }
        let stable = gain.is_finite() && gain <= ENERGY_GAIN;
        if stable || message.is_empty() {
            // What a user asking for this step is told.
            let mut s = scene.clone();
            s.dt = dt * s.coupling.substeps as f64;
            if let Err(refusal) = grains_dem_service::setup::check_time_step(&s) {
                message = format!("grains run refuses: {refusal}");
            }
        }
        probes.push(Probe {
            knob: f,
            stable,
            measure: gain,
            message,
            wall: t0.elapsed().as_secs_f64(),
        });
    }
    Ok(probes)
}

fn mpm_map(args: &ValidateArgs) -> anyhow::Result<Vec<Probe>> {
    use grains_mpm::pipeline::{MpmPipeline, cfl_time_step};
    let a = 1.0;
    let path = args.scenes.join("column_collapse_mpm_2d.toml");
    let scene = load_with(&path, &[format!("body.0.max=[{L0_COLUMN},{}]", a * L0_COLUMN)])?;
    let zones = grains_service::zones::ZoneField::layered(&scene);
    let (pts0, params) = grains_mpm_service::setup::build::<grains_grid::D2>(&scene, &zones).map_err(anyhow::Error::msg)?;
    let mat = &scene.materials[0];
    let rho = mat.density * mat.mpm.as_ref().map_or(1.0, |m| m.packing);
    let h = scene.domain.cell_size;
    let limit = cfl_time_step(&params.model, rho, h, 2);
    let mass: f64 = pts0.mass.iter().sum();
    let scale = mass * 9.81 * 0.5 * a * L0_COLUMN;
    let duration = 0.05;
    let mut probes = Vec::new();
    for f in [0.1, 0.3, 0.5, 0.8, 0.9, 0.95, 1.0, 1.2, 1.5, 2.0, 3.0] {
        let dt = f * limit;
        eprintln!("validate: stability, MPM CFL {f} ({dt:.2e} s)");
        let t0 = std::time::Instant::now();
        let mut pts = pts0.clone();
        let mut pipe = MpmPipeline::new(scene.threads as usize).map_err(anyhow::Error::msg)?;
        let (mut ke_max, mut message) = (0.0f64, String::new());
        let steps = (duration / dt).ceil() as usize;
        for _ in 0..steps {
            if let Err(e) = pipe.step(&mut pts, &params, dt) {
                message = e.to_string();
                ke_max = f64::NAN;
                break;
            }
            let ke: f64 = pts.mass.iter().zip(&pts.v).map(|(m, v)| 0.5 * m * v.length_squared()).sum();
            ke_max = ke_max.max(ke / scale);
            if !ke_max.is_finite() || ke_max > 1e3 {
                break;
            }
        }
        let stable = ke_max.is_finite() && ke_max <= 1.0;
        let mut s = scene.clone();
        s.dt = dt;
        if let Err((field, refusal)) = grains_mpm_service::setup::check(&s) {
            let said = format!("grains run refuses ({field}): {refusal}");
            message = if message.is_empty() { said } else { format!("{message}; {said}") };
        }
        probes.push(Probe {
            knob: f,
            stable,
            measure: ke_max,
            message,
            wall: t0.elapsed().as_secs_f64(),
        });
    }
    Ok(probes)
}

/// The process maps of the hybrid: substeps k and the cell / grain ratio.
fn hybrid_maps(args: &ValidateArgs, part: &mut Part, md: &mut String) -> anyhow::Result<()> {
    let ks = if args.sweep_k.is_empty() {
        vec![2, 5, 10, 20, 40, 80, 160]
    } else {
        args.sweep_k.clone()
    };
    let packing = ensure_packing(args, 1.0, 1)?;
    let hybrid = load_with(&args.scenes.join("column_collapse_hybrid_2d.toml"), &args.hybrid_overrides)?;
    let mat = &hybrid.materials[0];
    let rho = mat.density * mat.mpm.as_ref().map_or(1.0, |m| m.packing);
    let model = grains_mpm_service::setup::model(mat, 2);
    let k_limit = grains_mpm::pipeline::cfl_time_step(&model, rho, hybrid.domain.cell_size, 2) / 5e-7;
    let k_allowed = MAX_CFL * k_limit;
    let rows = sweep(args, &packing, &ks, &[])?;
    let probes: Vec<Probe> = rows
        .iter()
        .map(|r| Probe {
            knob: r.k as f64,
            stable: r.stable,
            measure: r.energy_ratio,
            message: r.message.clone(),
            wall: r.wall,
        })
        .collect();
    map_section(
        md,
        "DEM substeps per MPM step (hybrid)",
        "k",
        &format!(
            "hybrid column a = 1, 0.2 s, DEM step 5e-7 s, MPM step k × 5e-7 s; the MPM's CFL limit is k = {k_limit:.0}, \
             `grains run` refuses k above {k_allowed:.0} (CFL {MAX_CFL}). \
             Unstable: the run fails (NaN, runaway energy, a body leaving the grid) or is refused, or its kinetic energy \
             exceeds m g H / 2 (Yue 2018 §3.7 saw trouble beyond about 10)"
        ),
        "max KE / (m g H / 2)",
        &probes,
    );
    part.check(
        "hybrid stable at the scene's substeps",
        "energy criterion at k = 10 (column_collapse_hybrid_2d.toml)",
        probes
            .iter()
            .find(|p| p.knob == 10.0)
            .map_or("not run".into(), |p| format!("max KE / (m g H/2) = {:.3}", p.measure)),
        "≤ 1",
        probes.iter().filter(|p| p.knob == 10.0).all(|p| p.stable),
    );
    part.chart(
        &args.out,
        "stability_substeps",
        "Hybrid: kinetic energy against the substeps",
        &map_chart(
            "Hybrid column: DEM substeps per MPM step",
            "substeps k",
            "max kinetic energy / (m g H / 2)",
            &probes,
            vec![
                VLine {
                    x: k_limit,
                    label: "MPM CFL limit".into(),
                },
                VLine {
                    x: k_allowed,
                    label: "grains refuses above".into(),
                },
            ],
            1.0,
        ),
    )?;
    let ratios = [1.0, 2.0, 3.0, 4.0];
    let d = 0.001;
    let mut cell_rows = Vec::new();
    for r in ratios {
        let cell = r * d;
        // The band and the discrete layer hold at least one cell each.
        let layer = (4e-3f64).max(2.0 * cell);
        let extra = vec![
            format!("domain.cell_size={cell}"),
            // The material stays two cells inside the domain's wall layers.
            format!("domain.min=[{},{}]", -3.0 * cell, -3.0 * cell),
            format!("coupling.discrete_layer={layer}"),
            format!("coupling.hybrid_band={layer}"),
        ];
        eprintln!("validate: stability, hybrid cell = {r} d");
        let row = sweep(args, &packing, &[10], &extra)?.remove(0);
        cell_rows.push(Probe {
            knob: r,
            stable: row.stable,
            measure: row.energy_ratio,
            message: row.message,
            wall: row.wall,
        });
    }
    map_section(
        md,
        "MPM cell width / grain diameter (hybrid)",
        "cell / d",
        "hybrid column a = 1, 0.2 s, k = 10, discrete layer and band max(4 mm, 2 cells). Same criterion as above. Yue 2018 \
         used 2 and saw trouble at 1 except where noted",
        "max KE / (m g H / 2)",
        &cell_rows,
    );
    part.chart(
        &args.out,
        "stability_cell",
        "Hybrid: kinetic energy against the cell / grain ratio",
        &map_chart(
            "Hybrid column: MPM cell width / grain diameter",
            "cell / d",
            "max kinetic energy / (m g H / 2)",
            &cell_rows,
            vec![VLine {
                x: 2.0,
                label: "Yue 2018: 2".into(),
            }],
            1.0,
        ),
    )?;
    Ok(())
}
