//! Chen 2021 §6.4 at this machine's size: a planar shear `--shear-large-times` times as tall as §6.1's,
//! run as the hybrid on coarse cells, and its cost against the DEM's. As Chen's Table 11,
//! the DEM at that size is not run to its end: its cost is its measured cost per step on the
//! tall specimen times the steps of the shear. The speed-up model of §6.4.1 is fitted to the
//! measured costs (a grain's, a cell's) and set against the measured speed-up.

use super::continuum::{ContinuumShear, continuum_run};
use super::hybrid::transfer_named;
use super::*;
use grains_dem::DemState;

/// DEM steps timed on the tall specimen a round (after as many to build the neighbour lists),
/// and the rounds.
const PROBE_STEPS: usize = 300;
const PROBE_ROUNDS: usize = 3;
/// The target for the largest planar shear that runs here (issue 22).
const TARGET: f64 = 10.0;

/// §6.1's DEM stretched to `times` its height: the same width, speed and step, its prepared
/// packing moved up so that its middle is the tall specimen's (where the continuum's weak row
/// seeds the band, and where the enrichment cuts its grains).
fn stretched(dem: &DemShear, times: usize) -> DemShear {
    let mut tall = dem.clone();
    tall.height = times as f64 * dem.height;
    let offset = 0.5 * (tall.height - dem.height);
    let g = &mut tall.initial.grains;
    for x in g.x.iter_mut() {
        let p = D2::to_array(*x);
        *x = D2::from_array([p[0], p[1] + offset, 0.0]);
    }
    let domain = &mut tall.initial.params.domain;
    (domain.min[1], domain.max[1]) = (-tall.height, 2.0 * tall.height);
    tall
}

/// `times` copies of the consolidated sample `initial` stacked (each `height` above the last,
/// their frozen floor and plate layers meeting at the seams), and a pipeline that has built
/// their lists ([`PROBE_STEPS`] steps).
fn stacked(initial: &DemState<D2>, height: f64, times: usize, dt: f64) -> anyhow::Result<(DemState<D2>, grains_dem::DemPipeline<D2>)> {
    let mut state = initial.clone();
    let g0 = &initial.grains;
    state.grains = Default::default();
    for j in 0..times {
        for i in 0..g0.len() {
            let p = D2::to_array(g0.x[i]);
            let y = p[1] + j as f64 * height;
            let k = state.grains.push(
                g0.id[i] + ((j as u64) << 40),
                D2::from_array([p[0], y, 0.0]),
                g0.radius[i],
                g0.mass[i],
                g0.material[i],
            );
            state.grains.frozen[k] = g0.frozen[i];
            state.grains.v[k] = g0.v[i];
        }
    }
    let domain = &mut state.params.domain;
    (domain.min[1], domain.max[1]) = (-height, (times + 2) as f64 * height);
    let mut pipe = grains_dem::DemPipeline::<D2>::new(2)?;
    pipe.run(&mut state, dt, PROBE_STEPS);
    Ok((state, pipe))
}

/// The wall seconds per DEM step of one copy of `initial` and of `times` copies stacked
/// ([`stacked`]), timed in turns ([`PROBE_ROUNDS`], the fastest of each kept: a shared
/// machine only adds time), one copy for `times` as many steps, so that both take as long.
fn dem_step_costs(initial: &DemState<D2>, height: f64, times: usize, dt: f64) -> anyhow::Result<[(usize, f64); 2]> {
    let mut probes = [stacked(initial, height, 1, dt)?, stacked(initial, height, times, dt)?];
    let mut best = [f64::INFINITY; 2];
    for _ in 0..PROBE_ROUNDS {
        for (k, (state, pipe)) in probes.iter_mut().enumerate() {
            let steps = if k == 0 { times * PROBE_STEPS } else { PROBE_STEPS };
            let t = std::time::Instant::now();
            pipe.run(state, dt, steps);
            best[k] = best[k].min(t.elapsed().as_secs_f64() / steps as f64);
        }
    }
    Ok([0, 1].map(|k| (probes[k].0.grains.len(), best[k])))
}

/// Chen's §6.4.1 speed-up: 1 / (T_D/T + (1 − T_D/T) r), r = C_C / (C_D N_D) the continuum's
/// cost of an element over its grains' in the DEM.
fn speedup(t_d_over_t: f64, r: f64) -> f64 {
    1.0 / (t_d_over_t + (1.0 - t_d_over_t) * r)
}

pub(super) fn large_planar_shear(
    args: &ValidateArgs,
    dem: &DemShear,
    model: &grains_mpm::constitutive::hencky_critical_state::HenckyCriticalState,
    grain_density: f64,
    part: &mut Part,
    md: &mut String,
) -> anyhow::Result<()> {
    // The specimen's height in §6.1's heights and its continuum's cells [D50]
    // (`--shear-large-times`, `--shear-large-cells`): Chen's large planar shear has 0.75-cm
    // cells in 1-mm grains (Table 11), 58 grains a cell (§6.4.1).
    let (times, cell_d) = (args.shear_large_times as usize, args.shear_large_cells);
    let d = dem.diameter;
    let tall = stretched(dem, times);
    // The DEM's cost at the tall size: §6.1's measured shear scaled by the cost per step of
    // the tall specimen over the small one's, probed in turns. (The probe alone reads a
    // packing at rest, whose cost per step is not the sheared run's: only its ratio is used.)
    let [(small_grains, small_step), (tall_grains, tall_step)] = dem_step_costs(&dem.initial, dem.height, times, dem.dt)?;
    let dem_wall = dem.shear_wall * tall_step / small_step;
    // The continuum alone on the tall specimen (its cost per cell), then the hybrid with each
    // transfer of `--shear-transfer`: the paper's (`pic`) gives the paper's method's cost, and
    // the target is the speed-up with the DEM's band.
    let continuum = continuum_run(&tall, model, grain_density, cell_d, None)?;
    let cell = continuum.cell / d;
    let cells = (tall.width / continuum.cell).round() * (tall.height / continuum.cell).ceil();
    let steps = dem.shear_steps as f64;
    // §6.4.1 fitted: C_D a grain's cost per DEM step (§6.1's shear), C_C a cell's per DEM step
    // (the continuum's wall over the DEM's steps for the same shear).
    let c_d = dem.shear_wall / steps / small_grains as f64;
    let c_c = continuum.wall / steps / cells;
    let n_d = tall_grains as f64 / cells;
    let r = c_c / (c_d * n_d);
    let mut rows = Vec::new();
    for name in &args.shear_transfers {
        let run = continuum_run(&tall, model, grain_density, cell_d, Some(transfer_named(name)?));
        match run.and_then(Large::of) {
            Ok(row) => rows.push((name.as_str(), row)),
            Err(e) => unfinished(
                part,
                md,
                &format!("§6.4: the large hybrid, `{name}`"),
                &format!("large planar shear ({name})"),
                &e,
            ),
        }
    }
    let Some((_, first)) = rows.first() else {
        anyhow::bail!("no large hybrid finished");
    };
    // The grains' zone is the enrichment's, the same for every transfer.
    let (lo, hi) = first.slab;
    let t_d_over_t = (hi - lo) / (tall.height / d);
    let predicted = speedup(t_d_over_t, r);
    let _ = writeln!(
        md,
        "### §6.4: a large planar shear, cost\n\n§6.1's specimen {times} times as tall ({:.0} × {:.0} D50), as Chen's large \
         planar shear (Table 11: 10,000 D50 tall, 0.75-cm cells, 116× faster than its DEM). The hybrid on {cell:.1}-D50 cells, \
         once per transfer (`pic` is the paper's), enriched from §6.1's seed-{} sample at the continuum's band in the \
         middle, trained and coupled as in §6.1. As Chen's Table 11, the DEM at this size ({tall_grains} grains) is not run to \
         its end: its cost is §6.1's shear ({:.0} s for {small_grains} grains, {} steps) times the ratio of the costs of a \
         step of {times} copies of the consolidated sample stacked and of one copy, probed in turns ({PROBE_ROUNDS} rounds of \
         {PROBE_STEPS} steps of the tall one and {times} times as many of one copy, the fastest round of each, after \
         {PROBE_STEPS} steps to build the lists): {:.2} ms against {:.3} ms, {:.2}× for {:.2}× the grains. (The probe \
         alone reads a packing at rest: {:.3} ms a step on one copy against {:.3} ms over the sheared run.) The DEM's band \
         on the same sample at §6.1's size: {:.1} D50 at {:.1} D50 of {:.0}.\n\n\
         | | grains | points | wall | speed-up | t_s (App. A) | band centre | peak τ/σ_yy (strain) | mean τ/σ_yy over the window |\n\
         |---|---:|---:|---:|---:|---:|---:|---:|---:|\n\
         | DEM, {times} × §6.1 | {tall_grains} | | {dem_wall:.0} s (scaled) | 1 | | | | |\n\
         | continuum, {cell:.1}-D50 cells | | {} | {:.0} s | | | | | |",
        tall.width / d,
        tall.height / d,
        dem.seed,
        dem.shear_wall,
        dem.shear_steps,
        1e3 * tall_step,
        1e3 * small_step,
        tall_step / small_step,
        tall_grains as f64 / small_grains as f64,
        1e3 * small_step,
        1e3 * dem.shear_wall / steps,
        dem.t_s,
        dem.centre,
        dem.height / d,
        continuum.points,
        continuum.wall,
    );
    for (name, l) in &rows {
        let _ = writeln!(
            md,
            "| hybrid, `{name}` | {} | {} | {:.0} s | **{:.1}×** | {:.1} D50 | {:.1} D50 | {:.3} ({:.2}) | {:.3} |",
            l.grains,
            l.hybrid.points,
            l.hybrid.wall,
            dem_wall / l.hybrid.wall,
            l.t_s,
            l.centre,
            l.peak.1,
            l.peak.0,
            l.residual
        );
    }
    let _ = writeln!(
        md,
        "\nThe hybrid's wall is its continuum up to the detection, the enrichment and the training, and the coupled run: {}. \
         The grains span {lo:.0}–{hi:.0} D50 of {:.0} (T_D / T = {t_d_over_t:.3}). §6.4.1's model with the costs measured here: \
         C_D = {c_d:.2e} s a grain and DEM step, C_C = {c_c:.2e} s a cell and DEM step, N_D = {n_d:.1} grains a cell, so r = \
         C_C / (C_D N_D) = {r:.3} (Chen: {:.4} for its planar shear) and the predicted speed-up 1 / (T_D/T + (1 − T_D/T) r) \
         = **{predicted:.1}×**. The model leaves out what a hybrid grain costs beyond a DEM grain (the hybrid's wall less the \
         continuum's, over its grains and steps, in DEM grains): {}. The model's limit as the specimen grows (T_D / T → 0) is \
         1 / r = {:.0}×; {}.\n",
        rows.iter()
            .map(|(name, l)| {
                let detection = l.hybrid.detection_wall.unwrap_or(f64::NAN);
                format!(
                    "`{name}` {detection:.0} + {:.0} + {:.0} s",
                    l.training_wall,
                    l.hybrid.wall - detection - l.training_wall
                )
            })
            .collect::<Vec<_>>()
            .join(", "),
        tall.height / d,
        4.87e-7 / (1.14e-6 * 58.0),
        rows.iter()
            .map(|(name, l)| format!("`{name}` {:.2}", (l.hybrid.wall - continuum.wall) / (l.grains as f64 * steps * c_d)))
            .collect::<Vec<_>>()
            .join(", "),
        1.0 / r,
        if r < 1.0 / TARGET {
            let ratio = (1.0 / TARGET - r) / (1.0 - r);
            format!(
                "by the model {TARGET:.0}× needs T_D / T ≤ {ratio:.3}, a specimen {:.0} D50 tall at this T_D",
                (hi - lo) / ratio
            )
        } else {
            format!("{TARGET:.0}× is out of reach at this cell size, at any height")
        },
    );
    for (name, l) in &rows {
        let measured = dem_wall / l.hybrid.wall;
        part.check(
            format!("large planar shear ({name}): the hybrid's speed-up over the DEM"),
            format!("Chen 2021 Table 11: 116× at 10,000 D50 tall; issue 22: ≥ {TARGET:.0}× on the largest planar shear that runs here"),
            format!(
                "{measured:.1}× ({:.0} D50 tall; §6.4.1's model with the measured costs: {predicted:.1}×)",
                tall.height / d
            ),
            format!("≥ {TARGET:.0}×"),
            measured >= TARGET,
        );
        part.check(
            format!("large planar shear ({name}): the band's thickness"),
            format!(
                "issue 22: t_s within 2 D50 of the DEM's; §6.1's DEM on the same sample: {:.1} D50",
                dem.t_s
            ),
            format!("{:.1} D50 at {:.1} D50 up, the grains from {lo:.0} to {hi:.0} D50", l.t_s, l.centre),
            "within 2 D50 of the DEM's, the band (centre ± t_s / 2) at least a cell inside the grains' faces",
            (l.t_s - dem.t_s).abs() <= 2.0 && l.centre - 0.5 * l.t_s > lo + 2.0 * cell && l.centre + 0.5 * l.t_s < hi - 2.0 * cell,
        );
        part.check(
            format!("large planar shear ({name}): §6.4.1's model predicts the measured speed-up"),
            "Chen 2021 §6.4.1, Fig. 27: the model's speed-up agrees with the measured one",
            format!("model {predicted:.1}×, measured {measured:.1}×"),
            "within 30%",
            (predicted / measured - 1.0).abs() <= 0.3,
        );
    }
    let model_curve: Vec<(f64, f64)> = (0..=40)
        .map(|k| {
            let t_over_t_d = 10f64.powf(k as f64 / 10.0);
            (t_over_t_d, speedup(1.0 / t_over_t_d, r))
        })
        .collect();
    let chart = Chart {
        title: "Planar shear: the hybrid's speed-up over the DEM against the specimen's height (Chen 2021 §6.4.1)".into(),
        x_label: "T / T_D (specimen height over the grains' zone)".into(),
        y_label: "speed-up".into(),
        log_x: true,
        log_y: true,
        series: vec![Series::new(format!("§6.4.1 model, r = {r:.3}"), Kind::Line, model_curve)]
            .into_iter()
            .chain(rows.iter().map(|(name, l)| {
                Series::new(
                    format!("measured, {name}"),
                    Kind::Points,
                    vec![(1.0 / t_d_over_t, dem_wall / l.hybrid.wall)],
                )
            }))
            .collect(),
        ..Chart::default()
    };
    part.chart(
        &args.out,
        "shear_large_speedup",
        "Planar shear: the speed-up model and the measured point",
        &chart,
    )?;
    Ok(())
}

/// One large hybrid's figures: its run, the enrichment's grains and zone [D50], the
/// training's wall, its band (App. A) and its softening.
struct Large {
    hybrid: ContinuumShear,
    grains: usize,
    slab: (f64, f64),
    training_wall: f64,
    t_s: f64,
    centre: f64,
    peak: (f64, f64),
    residual: f64,
}

impl Large {
    fn of(hybrid: ContinuumShear) -> anyhow::Result<Self> {
        let h = hybrid
            .hybrid
            .as_ref()
            .context("the large hybrid's oracle never fired: nothing enriched")?;
        let (t_s, centre) = match &h.band {
            Ok((m, _, _)) => (m.t_s, m.centre),
            Err(_) => (f64::NAN, f64::NAN),
        };
        let (peak, residual) = softening(&hybrid.curve);
        Ok(Large {
            grains: h.training.enrichment.grains,
            slab: h.training.slab,
            training_wall: h.training.wall,
            t_s,
            centre,
            peak,
            residual,
            hybrid,
        })
    }
}
