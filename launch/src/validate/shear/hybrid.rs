//! The hybrid planar shear (Chen 2021 §6.1, Fig. 11 middle): the continuum until the oracle
//! fires, then the band's region enriched with trained grains ([`super::training`]) and the two
//! models coupled on the shared nodes every step (Yue 2018 Alg. 2–6, as Chen §4.2 uses them).
//! In process: the MPM's pipeline, the DEM's coupled stage and the coupler's function, one
//! after the other, as the run's participants do over shared memory.

use super::continuum::ContinuumShear;
use super::training::WEIGHT;
use super::*;
use grains_dem::coupled::{CoupledStep, CouplingParams, GrainTransfer};
use grains_grid::Grid;
use grains_mpm::pipeline::{MpmParams, MpmPipeline};
use grains_mpm::points::Points;
use grains_oracle::Zone;
use grains_protocol::wire::{NodeVelocity, RasterNode};
use std::collections::{HashMap, HashSet};

/// The hybrid's continuum cells [D50]: the coarse grid of the continuum's two (App. D: both
/// detect), the cheaper one.
pub(super) const HYBRID_CELL_D: f64 = 4.0;

/// A transfer named as `--shear-transfer` takes it: `pic`, `flip` (ours, its spin never
/// locked: the shear is quasi-static throughout) or `points:B`, B in [0, 1].
pub(super) fn transfer_named(name: &str) -> anyhow::Result<GrainTransfer> {
    match name {
        "pic" => Ok(GrainTransfer::Pic),
        "flip" => Ok(GrainTransfer::Flip),
        _ => match name.strip_prefix("points:").map(str::parse::<f64>) {
            Some(Ok(b)) if (0.0..=1.0).contains(&b) => Ok(GrainTransfer::Points(b)),
            _ => anyhow::bail!("--shear-transfer {name:?}: must be pic, flip or points:B with B in [0, 1] (e.g. points:0.95)"),
        },
    }
}

/// What the coupled step starts from: the enrichment's plan, the trained grains and their
/// pipeline.
pub(super) type Parts = (grains_oracle::epoch::Plan, grains_dem::DemState<D2>, grains_dem::DemPipeline<D2>);

/// The zone of the cell at `x` (off the grid: continuum).
fn zone_at(cells: &Grid, zones: &[Zone], x: [f64; 3]) -> Zone {
    grains_oracle::epoch::cell_of(cells, 2, x).map_or(Zone::Continuum, |c| zones[c])
}

/// The DEM half of the hybrid planar shear and what it measures.
pub(super) struct Coupled {
    state: grains_dem::DemState<D2>,
    pipe: grains_dem::DemPipeline<D2>,
    step: CoupledStep<D2>,
    zones: Vec<Zone>,
    cells: Grid,
    /// DEM substeps per MPM step.
    pub(super) substeps: usize,
    /// The period along x (the planar shear's), or none (the biaxial's).
    width: Option<f64>,
    /// The grains' positions when the strain window opens, by id (x unwrapped from there).
    reference: Option<HashMap<u64, [f64; 2]>>,
    /// Σ over the steps of the coupler's report: shared nodes, and the largest momentum error
    /// of a step over its momentum (it should be round-off: Alg. 3 conserves it).
    pub(super) shared: u64,
    pub(super) momentum_error: f64,
    /// The hybrid's mass (grains × their scale, points × their weight) after the enrichment,
    /// and the largest change of it over the coupled run, relative.
    mass: f64,
    pub(super) mass_change: f64,
    /// Coupled steps so far.
    pub(super) steps: u64,
}

impl Coupled {
    /// Takes the enriched band (the plan, the trained grains and their pipeline): the plan's deletions and mass factors applied to the MPM's
    /// points, each point weighed by its cell's zone (w in a hybrid cell), each grain likewise
    /// (1 − w); the DEM's substeps for the MPM's step `dt` at the DEM's own step `dem_dt`; the
    /// grains in a confining `fluid` or none (the points take theirs from `params`).
    pub(super) fn new(
        (plan, state, pipe): Parts,
        pts: &mut Points<D2>,
        params: &MpmParams<D2>,
        (cells, transfer, fluid): (Grid, GrainTransfer, Option<grains_dem::fluid::Fluid>),
        dt: f64,
        dem_dt: f64,
        width: Option<f64>,
    ) -> Self {
        let gone: HashSet<u64> = plan.delete_points.iter().copied().collect();
        let keep: Vec<u32> = (0..pts.len()).filter(|&k| !gone.contains(&pts.id[k])).map(|k| k as u32).collect();
        pts.retain_indices(&keep);
        let factor: HashMap<u64, f64> = plan.scale_points.iter().copied().collect();
        for k in 0..pts.len() {
            if let Some(f) = factor.get(&pts.id[k]) {
                pts.mass[k] *= f;
                pts.volume[k] *= f;
            }
        }
        let mut coupled = Coupled {
            state,
            pipe,
            step: CoupledStep::new(CouplingParams {
                grid: params.grid,
                kernel: params.kernel,
                transfer,
                quasi_static: 0.0,
                gravity: 0.0,
                fluid,
            }),
            zones: plan.zones,
            cells,
            substeps: (dt / dem_dt).ceil().max(1.0) as usize,
            width,
            reference: None,
            shared: 0,
            momentum_error: 0.0,
            mass: 0.0,
            mass_change: 0.0,
            steps: 0,
        };
        // Each point and grain keeps the share of its cell at the enrichment: w for a point,
        // 1 − w for a grain in a hybrid cell, 1 elsewhere. The runtime reweighs both only at an
        // oracle epoch, with the conversions. Reweighing the grains every step by the cell they
        // are in changed the mass by 1.6e-3 and 2.3e-3 of it (a grain crossing into a hybrid
        // cell halves, its springs with it, while the points there keep theirs;
        // docs/validation.md).
        for k in 0..pts.len() {
            let hybrid = coupled.zone(D2::to_array(pts.x[k])) == Zone::Hybrid;
            pts.weight[k] = if hybrid { WEIGHT } else { 1.0 };
        }
        let g = &mut coupled.state.grains;
        for i in 0..g.len() {
            let hybrid = zone_at(&coupled.cells, &coupled.zones, D2::to_array(g.x[i])) == Zone::Hybrid;
            g.scale[i] = if hybrid { 1.0 - WEIGHT } else { 1.0 };
        }
        coupled.mass = coupled.mass_now(pts);
        coupled
    }

    /// The mass the two models carry together: grains × scale, points × weight.
    fn mass_now(&self, pts: &Points<D2>) -> f64 {
        let g = &self.state.grains;
        let grains: f64 = (0..g.len()).map(|i| g.mass[i] * g.scale[i]).sum();
        grains + (0..pts.len()).map(|k| pts.mass[k] * pts.weight[k]).sum::<f64>()
    }

    /// After a step: the largest change of the mass so far.
    pub(super) fn track_mass(&mut self, pts: &Points<D2>) {
        let change = (self.mass_now(pts) / self.mass - 1.0).abs();
        self.mass_change = self.mass_change.max(change);
    }

    pub(super) fn zone(&self, x: [f64; 3]) -> Zone {
        zone_at(&self.cells, &self.zones, x)
    }

    /// Between the MPM's phase 1 and phase 2 of a step `dt`: the DEM's substeps and raster, the
    /// coupler's velocities on the shared nodes, and those velocities on the MPM's nodes.
    /// Returns them for [`Coupled::finish`].
    pub(super) fn couple(&mut self, mpm: &mut MpmPipeline<D2>, params: &MpmParams<D2>, dt: f64) -> anyhow::Result<Vec<NodeVelocity>> {
        let grid = params.grid;
        let mut mpm_raster = Vec::new();
        mpm.for_each_node_mut(|ijk, mass, v| {
            if let Some(node) = grid.index(ijk) {
                mpm_raster.push(RasterNode {
                    node,
                    mass,
                    momentum: D2::to_array(*v * mass),
                });
            }
        });
        mpm_raster.sort_unstable_by_key(|r| r.node);
        self.step.predict(&mut self.state, &mut self.pipe, dt, self.substeps);
        let dem_raster: Vec<RasterNode> = (0..self.step.raster().len())
            .map(|k| {
                let r = &self.step.raster()[k];
                RasterNode {
                    node: r.node,
                    mass: r.mass,
                    momentum: D2::to_array(self.step.uncoupled_momentum(k)),
                }
            })
            .collect();
        let mut out = vec![NodeVelocity::default(); grains_coupler::count_shared(&dem_raster, &mpm_raster)];
        let report = grains_coupler::constrain(&dem_raster, &mpm_raster, &mut out);
        self.shared += report.shared_nodes;
        self.steps += 1;
        let p = |v: [f64; 3]| v[0].hypot(v[1]);
        let change = p([0, 1, 2].map(|k| report.momentum_after[k] - report.momentum_before[k]));
        if p(report.momentum_before) > 0.0 {
            self.momentum_error = self.momentum_error.max(change / p(report.momentum_before));
        }
        for nv in &out {
            let v = mpm
                .node_velocity_mut(grid.ijk(nv.node))
                .with_context(|| format!("the coupler constrained node {} where the MPM has no material", nv.node))?;
            *v = D2::from_array(nv.velocity);
        }
        Ok(out)
    }

    /// After the MPM's phase 2: the grains take the constrained velocities back (Alg. 5–6).
    pub(super) fn finish(&mut self, constrained: &[NodeVelocity], dt: f64) -> anyhow::Result<()> {
        let given = constrained.iter().map(|nv| (nv.node, D2::from_array(nv.velocity)));
        self.step.finish(&mut self.state, &mut self.pipe, given, dt);
        if let Some(id) = grains_dem::pipeline::DemPipeline::first_non_finite(&self.state) {
            anyhow::bail!("grain {id} is not finite: the hybrid planar shear blew up");
        }
        Ok(())
    }

    /// The grains' positions now, by id, x unwrapped against the window's start (if periodic).
    pub(super) fn positions(&self) -> HashMap<u64, [f64; 2]> {
        match self.width {
            Some(width) => positions_of(&self.state, width, |_| true, self.reference.as_ref()),
            None => positions_of(&self.state, f64::INFINITY, |_| true, None),
        }
    }

    /// The DEM's state (its walls, for a moving platen).
    pub(super) fn dem_mut(&mut self) -> &mut grains_dem::DemState<D2> {
        &mut self.state
    }

    /// The DEM's state.
    pub(super) fn dem(&self) -> &grains_dem::DemState<D2> {
        &self.state
    }

    /// Marks the strain window's start.
    pub(super) fn open_window(&mut self) {
        if self.reference.is_none() {
            self.reference = Some(self.positions());
        }
    }

    /// The band over the strain window (App. A, as the DEM's) in the grains that were in
    /// discrete or hybrid cells when it opened, their number, and the number of grains in
    /// continuum cells at the end (strays: uncoupled, which an oracle epoch would delete),
    /// below and above the region's middle.
    pub(super) fn band(&self, d: f64, height: f64) -> anyhow::Result<(Measured, usize, [usize; 2])> {
        let from = self.reference.as_ref().context("the hybrid shear reached the window's start")?;
        let width = self.width.context("the planar shear's band is measured in a periodic cell")?;
        let inside = |p: &[f64; 2]| self.zone([p[0].rem_euclid(width), p[1], 0.0]) != Zone::Continuum;
        let from: HashMap<u64, [f64; 2]> = from.iter().filter(|(_, p)| inside(p)).map(|(&id, &p)| (id, p)).collect();
        let now = self.positions();
        let middle = from.values().map(|p| p[1]).sum::<f64>() / from.len().max(1) as f64;
        let strays = [false, true].map(|up| now.values().filter(|p| !inside(p) && (p[1] > middle) == up).count());
        Ok((band_of(&from, &now, d, width, height)?, from.len(), strays))
    }
}

/// A τ/σ_yy curve: (strain, value).
type Curve = Vec<(f64, f64)>;

/// The hybrid planar shears' table, checks and the band's picture: one run per transfer of
/// `--shear-transfer` and DEM sample, on cells of [`HYBRID_CELL_D`] D50. Returns each finished run's τ/σ_yy
/// curve, labelled.
pub(super) fn hybrid_report(
    args: &ValidateArgs,
    dems: &[DemShear],
    runs: Vec<(&str, &DemShear, anyhow::Result<ContinuumShear>)>,
    part: &mut Part,
    md: &mut String,
) -> anyhow::Result<Vec<(String, Curve)>> {
    let seeds = dems.iter().map(|d| d.seed.to_string()).collect::<Vec<_>>().join(", ");
    let _ = writeln!(
        md,
        "### §6.1: planar shear, hybrid\n\nThe continuum on {HYBRID_CELL_D}-D50 cells until the oracle fires; then its band enriched and \
         trained as above, once with the grains of each DEM sample (seeds {seeds}; each hybrid is compared with the DEM run on \
         its sample), and coupled from there to the end: each MPM step the DEM's substeps, the hybrid cells' grains (mass and \
         springs × 1 − w) and points (× w) rasterized on the MPM's nodes, the coupler's common velocity on the nodes both have (Yue 2018 Alg. 3, Chen §5), the \
         points' phase 2 and the grains' transfer back: Alg. 5–6 as written (`\"pic\"`: a hybrid grain takes the grid's velocity \
         and spin) and ours (`\"flip\"`: it keeps its own and adds the coupling's change), or as `--shear-transfer` names them \
         (`points:B`: Yue 2018 §3.7's blend, FLIP share B, from the saved position, spin from the contacts). The zones stay as the enrichment made \
         them, and each grain and point keeps the share its cell gave it then (as the runtime between two oracle epochs). The band is measured as the DEM's (App. A, same window) in the grains that were in discrete or hybrid cells when \
         the window opened; grains that end in continuum cells (strays, which an oracle epoch would convert) are \
         counted. The stress is the points' mean (equilibrium makes σ_xy the same at every height).\n\n\
         | | grains (measured) | strays (below / above) | DEM substeps | t_s (App. A) | band centre | slab profile at half peak | peak τ/σ_yy (strain) | mean τ/σ_yy over the window | shared nodes a step | coupler's momentum error | mass change | wall |\n\
         |---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
    );
    let mut profiles = Vec::new();
    for dem in dems {
        let _ = writeln!(
            md,
            "| DEM, seed {} | {GRAINS} | | | {:.1} D50 | {:.1} D50 | {:.0} D50 | {:.3} ({:.2}) | {:.3} | | | | {:.0} s |",
            dem.seed, dem.t_s, dem.centre, dem.fwhm, dem.peak.1, dem.peak.0, dem.residual, dem.wall
        );
        profiles.push(Series::new(
            format!("DEM, seed {}", dem.seed),
            Kind::LinePoints,
            dem.profile.clone(),
        ));
    }
    let mut curves = Vec::new();
    let mut regions = Vec::new();
    for (transfer, dem, run) in runs {
        let name = format!("{transfer}, seed {}", dem.seed);
        let run = match run.and_then(|r| r.hybrid.is_some().then_some(r).context("the oracle never fired: nothing enriched")) {
            Ok(r) => r,
            Err(e) => {
                let what = format!("planar shear (hybrid, {name})");
                super::unfinished_row(part, md, (&format!("hybrid, `{name}`"), 11), &what, &e);
                continue;
            }
        };
        let Some(h) = run.hybrid.as_ref() else { continue };
        let (peak, residual) = softening(&run.curve);
        let slab = h.training.slab;
        if !regions.iter().any(|&(seed, _)| seed == dem.seed) {
            regions.push((dem.seed, slab));
        }
        let (t_s, centre, fwhm, grains, strays) = match &h.band {
            Ok((m, grains, strays)) => (
                m.t_s,
                m.centre,
                m.fwhm,
                grains.to_string(),
                format!("{} / {}", strays[0], strays[1]),
            ),
            Err(e) => (f64::NAN, f64::NAN, f64::NAN, format!("no band: {e:#}"), String::new()),
        };
        let _ = writeln!(
            md,
            "| hybrid, `{name}` | {grains} | {strays} | {} | {t_s:.1} D50 | {centre:.1} D50 | {fwhm:.0} D50 | {:.3} ({:.2}) | {residual:.3} | {:.0} | {:.1e} | {:.1e} | {:.0} s |",
            h.substeps,
            peak.1,
            peak.0,
            h.shared as f64 / h.steps.max(1) as f64,
            h.momentum_error,
            h.mass_change,
            run.wall,
        );
        part.check(
            format!("planar shear (hybrid, {name}): the band's thickness"),
            format!(
                "Chen 2021 Fig. 11: the hybrid's band is the DEM's (22 D50 both); here the DEM's on the same sample, {:.1} D50",
                dem.t_s
            ),
            format!("{t_s:.1} D50 at {centre:.1} D50 up"),
            "within 2 D50 of the DEM's (issue 22)",
            (t_s - dem.t_s).abs() <= 2.0,
        );
        part.check(
            format!("planar shear (hybrid, {name}): the band forms within the grains, not at their edge"),
            "Chen 2021 §4, Fig. 11: the enrichment holds the band; its discrete zone runs to a cell from the region's faces",
            format!(
                "centre {centre:.1} D50, t_s {t_s:.1} D50; grains from {:.0} to {:.0} D50",
                slab.0, slab.1
            ),
            "the band (centre ± t_s / 2) at least a cell inside the discrete zone's faces",
            centre - 0.5 * t_s > slab.0 + 2.0 * HYBRID_CELL_D && centre + 0.5 * t_s < slab.1 - 2.0 * HYBRID_CELL_D,
        );
        part.check(
            format!("planar shear (hybrid, {name}): the coupler keeps momentum"),
            "Yue 2018 Alg. 3: one velocity per shared node from the summed momenta",
            format!("largest error of a step {:.1e} of its momentum", h.momentum_error),
            "round-off (1e-9)",
            h.momentum_error < 1e-9,
        );
        part.check(
            format!("planar shear (hybrid, {name}): the two models keep their mass"),
            "the coupling exchanges momentum, not mass: the two models together keep what the enrichment gave them",
            format!("largest change {:.1e} of the mass (grains × 1 − w, points × w)", h.mass_change),
            "round-off (1e-12)",
            h.mass_change < 1e-12,
        );
        if let Ok((m, _, _)) = &h.band {
            profiles.push(Series::new(format!("hybrid, {name} (grains)"), Kind::LinePoints, m.profile.clone()));
        }
        curves.push((format!("hybrid, {name}"), run.curve));
    }
    let _ = writeln!(md);
    for (seed, (lo, hi)) in regions {
        let _ = writeln!(
            md,
            "The enrichment region on seed {seed}'s sample: {lo:.0}–{hi:.0} D50 (discrete from {:.0} to {:.0}).",
            lo + HYBRID_CELL_D,
            hi - HYBRID_CELL_D
        );
    }
    let _ = writeln!(
        md,
        "\nThe hybrid's wall time includes its continuum up to the detection and the training.\n"
    );
    let chart = Chart {
        title: format!(
            "Planar shear: incremental strain {}-{} across the specimen, DEM and hybrid",
            WINDOW.0, WINDOW.1
        ),
        x_label: "mean deviatoric strain of a slab (grains: best fit)".into(),
        y_label: "height [D50]".into(),
        series: profiles,
        ..Chart::default()
    };
    part.chart(
        &args.out,
        "shear_planar_profiles_hybrid",
        "Planar shear: the DEM's band and the hybrid's",
        &chart,
    )?;
    Ok(curves)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `--shear-transfer`'s names, and a clear refusal of anything else.
    #[test]
    fn transfers_are_named_as_the_option_takes_them() {
        assert_eq!(transfer_named("pic").unwrap(), GrainTransfer::Pic);
        assert_eq!(transfer_named("flip").unwrap(), GrainTransfer::Flip);
        assert_eq!(transfer_named("points:0.95").unwrap(), GrainTransfer::Points(0.95));
        for bad in ["points", "points:1.5", "points:x", "apic"] {
            let e = transfer_named(bad).unwrap_err().to_string();
            assert!(e.contains(bad) && e.contains("points:B"), "{e}");
        }
    }
}
