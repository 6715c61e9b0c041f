//! `grains validate --part stability`: stability maps, where each method fails as its knob
//! grows.
//!
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
//! `--quick` runs the two in-process maps (seconds); the process maps run in a full
//! validation.

use super::args::ValidateArgs;
use super::column::sweep;
use super::packings;
use super::runs::load_with;
use super::scenes::column::{BOTTOM, DEM, HYBRID, L0 as L0_COLUMN, MPM};
use crate::report::Part;
use crate::report::chart::{Chart, Kind, Series, VLine};
use grains_dem::pipeline::{DemPipeline, SAFE_FRACTION, critical_time_step};
use grains_dem::space::D2;
use grains_dem::state::DemState;
use grains_mpm::pipeline::MAX_CFL;
use std::fmt::Write as _;

/// A run is unstable when the energy rises by this share of m g H / 2.
const ENERGY_GAIN: f64 = 0.1;

/// The DEM map's criterion on [`dem_probe`]'s energy rise.
fn dem_stable(gain: f64) -> bool {
    gain.is_finite() && gain <= ENERGY_GAIN
}

/// The MPM map's criterion on [`mpm_probe`]'s kinetic energy over m g H / 2.
fn mpm_stable(ke: f64) -> bool {
    ke.is_finite() && ke <= 1.0
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

pub fn validate(args: &ValidateArgs) -> anyhow::Result<Part> {
    let mut part = Part::default();
    let mut md = String::from("## Stability maps\n\n");
    dem_section(args, &mut part, &mut md)?;
    mpm_section(args, &mut part, &mut md)?;
    if !args.quick || !args.sweep_k.is_empty() {
        hybrid_maps(args, &mut part, &mut md)?;
    }
    part.md = md;
    Ok(part)
}

/// The DEM step map, its two checks and its chart.
fn dem_section(args: &ValidateArgs, part: &mut Part, md: &mut String) -> anyhow::Result<()> {
    let dem = dem_map(args)?;
    map_section(
        md,
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
    Ok(())
}

/// The MPM CFL map, its check and its chart.
fn mpm_section(args: &ValidateArgs, part: &mut Part, md: &mut String) -> anyhow::Result<()> {
    let mpm = mpm_map(args)?;
    map_section(
        md,
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
    Ok(())
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
    let packing = packings::column(args, 1.0, 1)?;
    let path = args.scenes.join(DEM);
    let base = vec![
        format!("body.0.max=[{L0_COLUMN},{}]", BOTTOM + a * L0_COLUMN),
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
        tracing::info!("validate: stability, DEM dt = {f} × critical ({dt:.2e} s)");
        let t0 = std::time::Instant::now();
        let (gain, mut message) = dem_probe(&state0, scene.threads as usize, dt, duration, scale)?;
        let stable = dem_stable(gain);
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

/// The DEM map's probe: `state0` stepped at `dt` for `duration`; the largest rise of its total
/// energy (kinetic + gravity + contact springs) over `scale`, NaN with the reason if a grain
/// went non-finite. Stable ([`dem_stable`]): a rise of at most [`ENERGY_GAIN`] (the grains
/// can only lose energy).
fn dem_probe(state0: &DemState<D2>, threads: usize, dt: f64, duration: f64, scale: f64) -> anyhow::Result<(f64, String)> {
    let mut st = state0.clone();
    let mut pipe = DemPipeline::<D2>::new(threads)?;
    let energy = |pipe: &DemPipeline<D2>, st: &DemState<D2>| {
        DemPipeline::kinetic_energy(st) + DemPipeline::potential_energy(st) + pipe.elastic_energy(st)
    };
    pipe.run(&mut st, dt, 1);
    let e0 = energy(&pipe, &st);
    let mut gain = f64::NEG_INFINITY;
    let steps = (duration / dt).ceil() as usize;
    let chunk = 20;
    for done in (0..steps).step_by(chunk) {
        pipe.run(&mut st, dt, chunk.min(steps - done));
        if let Some(id) = DemPipeline::first_non_finite(&st) {
            return Ok((f64::NAN, format!("grain {id} not finite at t = {:.2e} s", st.time)));
        }
        gain = gain.max((energy(&pipe, &st) - e0) / scale);
        if gain > 1e3 {
            break;
        }
    }
    Ok((gain, String::new()))
}

fn mpm_map(args: &ValidateArgs) -> anyhow::Result<Vec<Probe>> {
    use grains_mpm::pipeline::cfl_time_step;
    let a = 1.0;
    let path = args.scenes.join(MPM);
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
        tracing::info!("validate: stability, MPM CFL {f} ({dt:.2e} s)");
        let t0 = std::time::Instant::now();
        let (ke_max, mut message) = mpm_probe(&pts0, &params, scene.threads as usize, dt, duration, scale)?;
        let stable = mpm_stable(ke_max);
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

/// The MPM map's probe: `pts0` stepped at `dt` for `duration`; the largest kinetic energy
/// over `scale`, NaN with the solver's reason if a step failed. Stable ([`mpm_stable`]): at
/// most 1 (with `scale` = m g H / 2, all the energy gravity can release).
fn mpm_probe(
    pts0: &grains_mpm::points::Points<grains_grid::D2>,
    params: &grains_mpm::pipeline::MpmParams<grains_grid::D2>,
    threads: usize,
    dt: f64,
    duration: f64,
    scale: f64,
) -> anyhow::Result<(f64, String)> {
    let mut pts = pts0.clone();
    let mut pipe = grains_mpm::pipeline::MpmPipeline::new(threads).map_err(anyhow::Error::msg)?;
    let mut ke_max = 0.0f64;
    let steps = (duration / dt).ceil() as usize;
    for _ in 0..steps {
        if let Err(e) = pipe.step(&mut pts, params, dt) {
            return Ok((f64::NAN, e.to_string()));
        }
        let ke: f64 = pts.mass.iter().zip(&pts.v).map(|(m, v)| 0.5 * m * v.length_squared()).sum();
        ke_max = ke_max.max(ke / scale);
        if !ke_max.is_finite() || ke_max > 1e3 {
            break;
        }
    }
    Ok((ke_max, String::new()))
}

/// The process maps of the hybrid: substeps k and the cell / grain ratio.
/// The substep map of the hybrid column (processes), then its cell map.
fn hybrid_maps(args: &ValidateArgs, part: &mut Part, md: &mut String) -> anyhow::Result<()> {
    let ks = if args.sweep_k.is_empty() {
        vec![2, 5, 10, 20, 40, 80, 160]
    } else {
        args.sweep_k.clone()
    };
    let packing = packings::column(args, 1.0, 1)?;
    let hybrid = load_with(&args.scenes.join(HYBRID), &args.hybrid_overrides)?;
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
    cell_map(args, part, md, &packing)
}

/// The hybrid column on cells of 1–4 grain diameters.
fn cell_map(args: &ValidateArgs, part: &mut Part, md: &mut String, packing: &std::path::Path) -> anyhow::Result<()> {
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
        tracing::info!("validate: stability, hybrid cell = {r} d");
        let row = sweep(args, packing, &[10], &extra)?.remove(0);
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::run::steps::{Limit, load};
    use grains_service::zones::ZoneField;

    /// `coupling.substeps = "auto"` never picks a step that the maps' probes call unstable:
    /// on a small hybrid block (tests/scenes/hybrid_small_2d.toml), with the MPM's limit
    /// setting the macro-step (the DEM at its own stable step), then with a continuum stiff
    /// enough that the MPM's limit falls below the DEM's (k = 1, the DEM step brought down to
    /// it), the DEM's grains and the MPM's points are each stable for 20 ms at the steps
    /// chosen, by the criteria of the maps. The same probes at the maps' first unstable
    /// settings (2 × the critical step, CFL 1.5) must fail, or they could not catch a bad choice.
    #[test]
    fn automatic_steps_stay_where_the_stability_maps_say_stable() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/scenes/hybrid_small_2d.toml");
        let (duration, height, g) = (0.02, 0.016, 9.81);
        for (stiff, limit) in [(false, Limit::Mpm), (true, Limit::Dem)] {
            let mut overrides = vec!["coupling.substeps=\"auto\"".to_string(), "run.dt=1e-3".to_string()];
            if stiff {
                overrides.push("material.0.mpm.young=2.5e9".to_string());
            }
            let (scene, _, chosen) = load(&path, &overrides).unwrap();
            let c = chosen.expect("an auto scene");
            assert_eq!(c.limit, limit, "{c}");
            let zones = ZoneField::layered(&scene);

            let state0 = grains_dem_service::setup::build_state::<D2>(&scene, &zones).unwrap();
            let grains = &state0.grains;
            let free = (0..grains.len()).filter(|&i| !grains.frozen[i]);
            let m_min = free.clone().map(|i| grains.mass[i]).fold(f64::INFINITY, f64::min);
            let scale = free.map(|i| grains.mass[i]).sum::<f64>() * g * 0.5 * height;
            let critical = critical_time_step(&state0.params.materials[0], m_min);
            let (gain, why) = dem_probe(&state0, 1, c.dem_dt, duration, scale).unwrap();
            assert!(dem_stable(gain), "{c}: the DEM's energy rose by {gain:.3e} of m g H / 2 {why}");
            let (gain, _) = dem_probe(&state0, 1, 2.0 * critical, duration, scale).unwrap();
            assert!(
                !dem_stable(gain),
                "the DEM probe at twice the critical step saw a rise of only {gain:.3e}"
            );

            let (pts0, params) = grains_mpm_service::setup::build::<grains_grid::D2>(&scene, &zones).unwrap();
            let scale = pts0.mass.iter().sum::<f64>() * g * 0.5 * height;
            let (ke, why) = mpm_probe(&pts0, &params, 1, c.dt, duration, scale).unwrap();
            assert!(mpm_stable(ke), "{c}: the MPM's kinetic energy reached {ke:.3e} of m g H / 2 {why}");
            let cfl_one = c.mpm_limit / MAX_CFL;
            let (ke, _) = mpm_probe(&pts0, &params, 1, 1.5 * cfl_one, duration, scale).unwrap();
            assert!(!mpm_stable(ke), "the MPM probe at CFL 1.5 saw a kinetic energy of only {ke:.3e}");
        }
    }
}
