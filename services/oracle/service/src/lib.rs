//! The grains-oracle participant: decides which grid cells are discrete, hybrid or continuum
//! and tells the solvers over `grains/oracle/zones`.
//!
//! At start it sends the layered zones of the scene (Yue 2018 §4.3,
//! [`grains_service::zones::ZoneField::layered`]), with header step 0, before the solvers
//! build their grains and points. With `oracle.kind = "fixed"` (the default) that is all: the
//! zones stay with the material. With `"surface"` it holds an epoch after every
//! `oracle.every` steps (Yue 2018 Alg. 7–9, [`grains_oracle::epoch::plan`]): it takes every
//! grain (`grains/dem/epoch`), the grains' stress per node (`grains/dem/stress`) and every
//! point (`grains/mpm/epoch`) of that step, and answers with the new zones and, per solver,
//! the items to delete and to create. Its summary of an epoch step carries the total mass and
//! momentum before the epoch (the solvers' summaries of the same step, those after it) and
//! the epoch's time as its compute time; on other steps mass and momentum are 0. With
//! `"shear_band"` every cell starts continuum and the epochs look for a shear band in the
//! points' plastic strain instead ([`band`], Chen 2021 Alg. 1 and §4).

pub mod band;

use anyhow::bail;
use grains_grid::{D2, D3};
use grains_oracle::band_epoch;
use grains_oracle::epoch::{self, Grain, Point, Settings};
use grains_protocol::Role;
use grains_protocol::names;
use grains_protocol::scene::{Dimension, Model, OracleKind, Scene};
use grains_protocol::wire::{EpochItem, NodeStress, PointScale, SpawnGrain, SpawnPoint, StepBegin, StepHeader, Summary, Zone, ZoneCell};
use grains_service::session::Session;
use grains_service::solver::{ParticipantOptions, SolverReport, StepWindow, join, next_step, publish_slice, publish_summary};
use grains_service::zones::ZoneField;
use grains_transport::{Publisher, Subscriber, Transport};
use std::collections::BTreeMap;
use std::time::{Duration, Instant};

/// Checks what the oracle needs of a scene: the kinds of oracle this build has, and for
/// `"surface"` a hybrid body whose material has grains and a continuum (new grains take its
/// radii, new points its density).
pub fn check_scene(scene: &Scene) -> Result<(), grains_protocol::scene::SceneError> {
    let err = |field: &str, message: String| grains_protocol::scene::SceneError {
        path: scene.path.clone(),
        line_col: None,
        field: Some(field.into()),
        message,
    };
    match scene.oracle.as_ref().map(|o| o.kind) {
        None | Some(OracleKind::Fixed) => Ok(()),
        Some(kind @ (OracleKind::Surface | OracleKind::Layered | OracleKind::ShearBand)) => {
            let name = kind.name();
            if settings(scene).is_none() {
                return Err(err(
                    "oracle.kind",
                    format!("\"{name}\" needs a body with model = \"hybrid\" whose material has both [material.dem] and [material.mpm]"),
                ));
            }
            if kind == OracleKind::Layered && scene.gravity.iter().all(|g| *g == 0.0) {
                return Err(err(
                    "oracle.kind",
                    "\"layered\" measures depth against gravity: the scene has none".into(),
                ));
            }
            // Its zones cover every cell, so every body's material is converted: a "dem" or
            // "mpm" body would be turned hybrid too. Frozen grains are the boundary: kept.
            match scene
                .bodies
                .iter()
                .position(|b| b.model != Model::Hybrid && !(b.model == Model::Dem && b.frozen))
            {
                Some(k) => Err(err(
                    &format!("body.{k}.model"),
                    format!(
                        "with oracle.kind = \"{name}\" every body is \"hybrid\" (the zones move over all material), except frozen \"dem\" bodies"
                    ),
                )),
                None => Ok(()),
            }
        }
    }
}

/// The epoch settings of a surface oracle: the band at `oracle.centre` ± `oracle.half_width`
/// inside the isocontour (by default where the layered zones put it: centre
/// `discrete_layer + hybrid_band / 2`, half-width `hybrid_band / 2`), new grains and points of
/// the first hybrid body's material.
pub fn settings(scene: &Scene) -> Option<Settings> {
    let body = scene.bodies.iter().find(|b| b.model == Model::Hybrid)?;
    let material = &scene.materials[body.material];
    let (dem, mpm) = (material.dem.as_ref()?, material.mpm.as_ref()?);
    let c = &scene.coupling;
    let o = scene.oracle.as_ref();
    // Up is against the largest component of gravity.
    let g = scene.gravity;
    let axis = (0..3).max_by(|&a, &b| g[a].abs().total_cmp(&g[b].abs())).unwrap_or(1);
    Some(Settings {
        critical_packing: o.map_or(0.5, |o| o.critical_packing),
        layered: o.filter(|o| o.kind == OracleKind::Layered).map(|_| (axis, -g[axis].signum())),
        centre: o.and_then(|o| o.centre).unwrap_or(c.discrete_layer + 0.5 * c.hybrid_band),
        half_width: o.and_then(|o| o.half_width).unwrap_or(0.5 * c.hybrid_band),
        radius_mean: dem.radius,
        radius_std: dem.radius_std,
        points_per_axis: scene.mpm.points_per_axis,
        bulk_density: material.density * mpm.packing,
        attempts: 30,
        weight: c.weight,
        grain_density: material.density,
        max_inertial: o.map_or(0.0, |o| o.max_inertial),
        gravity: g,
    })
}

pub fn run<T: Transport>(transport: &T, scene: &Scene, opts: &ParticipantOptions) -> anyhow::Result<()> {
    if scene.synthetic.is_some() {
        bail!("synthetic scenes have no oracle: list dem, mpm and coupler as their participants");
    }
    check_scene(scene)?;
    let t = Instant::now();
    let field = ZoneField::layered(scene);
    let field_time = t.elapsed();
    let mut session = join(transport, Role::Oracle, scene, opts)?;
    let cells = field.cells();
    let mut zones_pub = session.publisher::<ZoneCell, StepHeader>(&names::ZONES, cells.len().max(1))?;
    let mut step_sub = session.subscriber::<StepBegin, StepHeader>(&names::STEP_BEGIN)?;
    let mut summary_pub = session.publisher::<Summary, StepHeader>(&names::SUMMARY, 1)?;
    let mut epochs = match scene.oracle.as_ref().map(|o| o.kind) {
        Some(kind) if kind.adaptive() => Some(Epochs::<T>::open(&session, scene)?),
        _ => None,
    };
    session.wait_until("the DEM, the MPM, the coupler and the launcher", |_| {
        zones_pub.subscriber_count() >= 2
            && step_sub.publisher_count() >= 1
            && summary_pub.subscriber_count() >= 1
            && epochs.as_mut().is_none_or(Epochs::connected)
    })?;
    // Both solvers are subscribed: they build their grains and points from this field before
    // they declare themselves ready.
    let header = session.header(0, 0.0, scene.dt);
    publish_slice(&mut zones_pub, header, cells, opts.checksums)?;
    session.ready()?;

    let mut report = SolverReport {
        n_items: cells.len() as u64,
        n_nodes: field.count(Zone::Hybrid) as u64,
        ..SolverReport::default()
    };
    if let (Some(r), Some(e)) = (&opts.resume, &mut epochs) {
        e.state
            .restore(&grains_service::checkpoint::read(r, Role::Oracle, scene.hash)?, &mut report)?;
    }
    let mut compute = field_time;
    loop {
        let wait_start = Instant::now();
        let Some(window) = next_step(&session, &mut step_sub)? else {
            return Ok(());
        };
        // Only once the step is in hand: after the last one the coupler may be exiting.
        session.watch_peers()?;
        grains_service::telemetry::set_step(Some(window.step));
        let mut wait = wait_start.elapsed();
        report.mass = 0.0;
        report.momentum = [0.0; 3];
        if let Some(e) = &mut epochs
            && scene.epoch_after(window.step)
        {
            let (w, c) = e.epoch(&session, scene, &window, &mut zones_pub, &mut report, opts.checksums)?;
            wait += w;
            compute += c;
        }
        // Fixed zones carry nothing from one step to the next.
        opts.checkpoint(scene, Role::Oracle, &window, || match &epochs {
            Some(e) => e.state.save(&report),
            None => Ok(Vec::new()),
        })?;
        publish_summary(&session, &mut summary_pub, &window, &report, compute, wait)?;
        compute = Duration::ZERO;
    }
}

/// What one epoch sends: the zones (non-discrete cells) and each solver's lists, and the
/// total mass and momentum before it (for the summary).
#[derive(Clone, Debug, Default)]
pub struct EpochMessages {
    pub zones: Vec<ZoneCell>,
    pub delete_grains: Vec<u64>,
    pub delete_points: Vec<u64>,
    pub spawn_grains: Vec<SpawnGrain>,
    pub spawn_points: Vec<SpawnPoint>,
    pub scale_points: Vec<PointScale>,
    pub mass_before: f64,
    pub momentum_before: [f64; 3],
    /// Hybrid cells after the epoch.
    pub hybrid_cells: u64,
}

/// The surface oracle between epochs: plain data, so that a test can drive epochs without a
/// transport.
pub struct OracleState {
    pub settings: Settings,
    /// The zone of every cell.
    pub zones: Vec<Zone>,
    /// The grid of the zone cells.
    cells: grains_grid::Grid,
    next_ids: (u64, u64),
    rng: grains_grid::rng::Rng,
    /// `shear_band`: the band's detection (None: the surface or layered oracle).
    pub band: Option<band::BandState>,
}

impl OracleState {
    /// At the start of a run: the scene's layered zones.
    pub fn new(scene: &Scene) -> anyhow::Result<Self> {
        check_scene(scene)?;
        let field = ZoneField::layered(scene);
        Ok(OracleState {
            settings: settings(scene).ok_or_else(|| anyhow::anyhow!("the scene has no surface oracle"))?,
            zones: field.dense(),
            cells: *field.cell_grid(),
            next_ids: (0, 0),
            rng: grains_grid::rng::Rng::new(scene.seed ^ 0x6f72_6163_6c65),
            band: match scene.oracle.as_ref().map(|o| o.kind) {
                Some(OracleKind::ShearBand) => Some(band::BandState::new(scene)?),
                _ => None,
            },
        })
    }

    /// What a checkpoint holds of the oracle: the zones, the next ids, the generator, and
    /// the counts its summary reports between epochs.
    pub fn save(&self, report: &SolverReport) -> anyhow::Result<Vec<u8>> {
        let zones: Vec<u32> = self.zones.iter().map(|z| *z as u32).collect();
        let band = self.band.as_ref().map(band::BandState::save);
        grains_service::checkpoint::encode(&(zones, self.next_ids, &self.rng, report.n_items, report.n_nodes, band))
    }

    /// Takes back the state of [`OracleState::save`] (and the summary's counts).
    pub fn restore(&mut self, bytes: &[u8], report: &mut SolverReport) -> anyhow::Result<()> {
        type Saved = (Vec<u32>, (u64, u64), grains_grid::rng::Rng, u64, u64, Option<band::Saved>);
        let (zones, next_ids, rng, n_items, n_nodes, saved_band): Saved = grains_service::checkpoint::decode(bytes)?;
        match (&mut self.band, saved_band) {
            (Some(b), Some(saved)) => b.restore(saved),
            (None, None) => {}
            _ => anyhow::bail!("the checkpoint's oracle is not of this scene's kind"),
        }
        if zones.len() != self.zones.len() {
            anyhow::bail!("the checkpoint has {} zone cells, this scene {}", zones.len(), self.zones.len());
        }
        self.zones = zones
            .into_iter()
            .map(|z| Zone::from_code(z).ok_or_else(|| anyhow::anyhow!("zone code {z} in the checkpoint")))
            .collect::<anyhow::Result<_>>()?;
        (self.next_ids, self.rng) = (next_ids, rng);
        (report.n_items, report.n_nodes) = (n_items, n_nodes);
        Ok(())
    }

    /// One epoch at `time` over the DEM's grains and stress and the MPM's points.
    pub fn epoch(&mut self, scene: &Scene, time: f64, grains: &[EpochItem], stress: &[NodeStress], points: &[EpochItem]) -> EpochMessages {
        let (mass, momentum) = totals(grains, points);
        let stress: BTreeMap<u64, [[f64; 3]; 3]> = stress.iter().map(|n| (n.node, from_voigt(n.stress))).collect();
        let grains_in: Vec<Grain> = grains.iter().map(oracle_grain).collect();
        let points_in: Vec<Point> = points.iter().map(oracle_point).collect();
        // New ids above every id either solver has used.
        let max_id = |items: &[EpochItem]| items.iter().map(|i| i.id + 1).max().unwrap_or(0);
        self.next_ids = (self.next_ids.0.max(max_id(grains)), self.next_ids.1.max(max_id(points)));
        let (nodes, kernel) = grains_service::grid::scene_grid(scene);
        let cells = self.cells;
        let band_zones = match &mut self.band {
            Some(b) => match b.detect(&cells, scene.dim(), time, points, grains) {
                Some(zones) => Some(zones),
                // No band (yet) and all continuum: nothing to convert.
                None if self.zones.iter().all(|&z| z == Zone::Continuum) => {
                    let plan = epoch::Plan {
                        zones: self.zones.clone(),
                        ..epoch::Plan::default()
                    };
                    return messages(&plan, 0.0, mass, momentum);
                }
                // No new band, but the solvers weigh their items by the cell they are in
                // after every epoch: the zones stay and the enrichment's rules keep the mass
                // of the grains and points that moved across a zone's edge since the last.
                None => Some(vec![Zone::Continuum; self.zones.len()]),
            },
            None => None,
        };
        let solid = solid_cells(scene, &cells, time, self.settings.centre + self.settings.half_width);
        let clearance = |x: [f64; 3]| wall_clearance(scene, x, time);
        let input = epoch::Inputs {
            nodes: &nodes,
            kernel,
            cells: &cells,
            previous: &self.zones,
            solid: &solid,
            clearance: &clearance,
            grains: &grains_in,
            points: &points_in,
            stress: &stress,
        };
        let plan = match (&self.band, band_zones) {
            (Some(b), Some(zones)) => {
                let s = (self.settings.weight, self.settings.grain_density);
                // Grains are cut only where the band turns cells discrete or hybrid (the zone
                // codes rank them: continuum 0 < hybrid 1 < discrete 2): a band that has not
                // grown, or cells the grains have left since, get none (and no training).
                let grown = zones.iter().zip(&self.zones).any(|(&z, &was)| z as u32 > was as u32);
                let cut = (points, time, grown);
                let (plan, shift) = match scene.dimension {
                    Dimension::Two => enrich_band::<D2>(b, scene, &input, &zones, s, self.next_ids.0, cut),
                    Dimension::Three => enrich_band::<D3>(b, scene, &input, &zones, s, self.next_ids.0, cut),
                };
                if !plan.new_grains.is_empty() {
                    self.band.as_mut().expect("a band state").enrichments += 1;
                    tracing::info!(
                        "shear band at t = {time:.5} s: {} new grains, {} points deleted, the new grains' velocity shifted by {:.2e} m/s to keep the momentum",
                        plan.new_grains.len(),
                        plan.delete_points.len(),
                        shift.iter().map(|c| c * c).sum::<f64>().sqrt()
                    );
                }
                plan
            }
            _ => match scene.dimension {
                Dimension::Two => epoch::plan::<D2>(&input, &self.settings, self.next_ids, &mut self.rng),
                Dimension::Three => epoch::plan::<D3>(&input, &self.settings, self.next_ids, &mut self.rng),
            },
        };
        if scene.dim() == 2 && tracing::enabled!(tracing::Level::DEBUG) {
            tracing::debug!("zones of the epoch:\n{}", zone_map(&cells, &plan, &solid, time));
        }
        self.next_ids.0 += plan.new_grains.len() as u64;
        self.next_ids.1 += plan.new_points.len() as u64;
        let out = messages(&plan, self.settings.centre, mass, momentum);
        self.zones = plan.zones;
        out
    }
}

/// One shear-band enrichment ([`band_epoch::enrich`]) to the zones `band`, with kinematic
/// training when the scene has it on ([`band::BandState::train`]; the MPM's `points` and the
/// epoch's `time`); no grains are cut unless the band has `grown`.
fn enrich_band<S: grains_grid::Space>(
    b: &band::BandState,
    scene: &Scene,
    input: &epoch::Inputs<'_>,
    band: &[Zone],
    shares: (f64, f64),
    next_grain_id: u64,
    (points, time, grown): (&[EpochItem], f64, bool),
) -> (epoch::Plan, [f64; 3]) {
    let mut train = |need: &std::collections::BTreeSet<usize>| {
        b.train::<S>(scene, input.cells, need, points, input.grains, time)
            .unwrap_or_else(|e| {
                tracing::error!("kinematic training failed, no grains cut this epoch: {e:#}");
                Vec::new()
            })
    };
    let mut none = |_: &std::collections::BTreeSet<usize>| Vec::new();
    // None: the packing's grains as they are (no training).
    let cut: Option<band_epoch::Train<'_>> = match (grown, b.training) {
        (false, _) => Some(&mut none),
        (true, true) => Some(&mut train),
        (true, false) => None,
    };
    band_epoch::enrich::<S>(input, band, &b.packing, shares, next_grain_id, cut)
}

/// Total mass and momentum of the items as the solvers weigh them (their share).
fn totals(grains: &[EpochItem], points: &[EpochItem]) -> (f64, [f64; 3]) {
    let (mut mass, mut momentum) = (0.0, [0.0; 3]);
    for it in grains.iter().chain(points) {
        mass += it.share * it.mass;
        (0..3).for_each(|k| momentum[k] += it.share * it.mass * it.velocity[k]);
    }
    (mass, momentum)
}

/// A grain of the DEM's epoch message as the oracle sees it.
fn oracle_grain(g: &EpochItem) -> Grain {
    Grain {
        id: g.id,
        x: g.position,
        radius: g.radius,
        mass: g.mass,
        share: g.share,
        v: g.velocity,
        fixed: g.flags & grains_protocol::wire::EPOCH_FIXED != 0,
    }
}

/// A point of the MPM's epoch message as the oracle sees it.
fn oracle_point(p: &EpochItem) -> Point {
    Point {
        id: p.id,
        x: p.position,
        mass: p.mass,
        share: p.share,
        v: p.velocity,
    }
}

/// What the solvers are sent of `plan`: the non-discrete cells with their distance from the
/// band's centre `centre`, and each solver's lists; `mass` and `momentum` before the epoch.
fn messages(plan: &epoch::Plan, centre: f64, mass: f64, momentum: [f64; 3]) -> EpochMessages {
    let zones = plan
        .zones
        .iter()
        .enumerate()
        .filter(|(_, z)| **z != Zone::Discrete)
        .map(|(c, &z)| ZoneCell {
            cell: c as u64,
            zone: z as u32,
            _pad: 0,
            // The band's zones carry no distance to a surface.
            distance: plan.distance.get(c).map_or(f64::INFINITY, |d| d - centre),
        })
        .collect();
    EpochMessages {
        zones,
        delete_grains: plan.delete_grains.clone(),
        delete_points: plan.delete_points.clone(),
        spawn_grains: plan
            .new_grains
            .iter()
            .map(|g| SpawnGrain {
                id: g.id,
                radius: g.radius,
                position: g.x,
                velocity: g.v,
            })
            .collect(),
        spawn_points: plan
            .new_points
            .iter()
            .map(|p| SpawnPoint {
                id: p.id,
                volume: p.volume,
                mass: p.mass,
                position: p.x,
                velocity: p.v,
                stress: to_voigt(&p.stress),
            })
            .collect(),
        scale_points: plan.scale_points.iter().map(|&(id, factor)| PointScale { id, factor }).collect(),
        mass_before: mass,
        momentum_before: momentum,
        hybrid_cells: plan.zones.iter().filter(|z| **z == Zone::Hybrid).count() as u64,
    }
}

/// The surface oracle's ports.
struct Epochs<T: Transport> {
    grains_sub: T::Subscriber<EpochItem, StepHeader>,
    stress_sub: T::Subscriber<NodeStress, StepHeader>,
    points_sub: T::Subscriber<EpochItem, StepHeader>,
    spawn_grains: T::Publisher<SpawnGrain, StepHeader>,
    spawn_points: T::Publisher<SpawnPoint, StepHeader>,
    delete_grains: T::Publisher<u64, StepHeader>,
    delete_points: T::Publisher<u64, StepHeader>,
    scale_points: T::Publisher<PointScale, StepHeader>,
    state: OracleState,
}

impl<T: Transport> Epochs<T> {
    fn open(session: &Session<'_, T>, scene: &Scene) -> anyhow::Result<Self> {
        Ok(Epochs {
            grains_sub: session.subscriber(&names::DEM_EPOCH)?,
            stress_sub: session.subscriber(&names::DEM_STRESS)?,
            points_sub: session.subscriber(&names::MPM_EPOCH)?,
            spawn_grains: session.publisher(&names::SPAWN_GRAINS, 256)?,
            spawn_points: session.publisher(&names::SPAWN_POINTS, 256)?,
            delete_grains: session.publisher(&names::DELETE_GRAINS, 256)?,
            delete_points: session.publisher(&names::DELETE_POINTS, 256)?,
            scale_points: session.publisher(&names::SCALE_POINTS, 256)?,
            state: OracleState::new(scene)?,
        })
    }

    fn connected(&mut self) -> bool {
        self.grains_sub.publisher_count() >= 1
            && self.stress_sub.publisher_count() >= 1
            && self.points_sub.publisher_count() >= 1
            && self.spawn_grains.subscriber_count() >= 1
            && self.spawn_points.subscriber_count() >= 1
            && self.delete_grains.subscriber_count() >= 1
            && self.delete_points.subscriber_count() >= 1
            && self.scale_points.subscriber_count() >= 1
    }

    /// One epoch after `window.step`: (wait, compute) times.
    fn epoch(
        &mut self,
        session: &Session<'_, T>,
        scene: &Scene,
        window: &StepWindow,
        zones_pub: &mut T::Publisher<ZoneCell, StepHeader>,
        report: &mut SolverReport,
        checksums: bool,
    ) -> anyhow::Result<(Duration, Duration)> {
        let step = window.step;
        let wait_start = Instant::now();
        let grains = session.recv(
            &mut self.grains_sub,
            "the DEM's grains",
            |h, items| -> anyhow::Result<Vec<EpochItem>> {
                session.check_message(&names::DEM_EPOCH, h, step, items)?;
                Ok(items.to_vec())
            },
        )??;
        let stress = session.recv(
            &mut self.stress_sub,
            "the DEM's stress",
            |h, s| -> anyhow::Result<Vec<NodeStress>> {
                session.check_message(&names::DEM_STRESS, h, step, s)?;
                Ok(s.to_vec())
            },
        )??;
        let points = session.recv(
            &mut self.points_sub,
            "the MPM's points",
            |h, items| -> anyhow::Result<Vec<EpochItem>> {
                session.check_message(&names::MPM_EPOCH, h, step, items)?;
                Ok(items.to_vec())
            },
        )??;
        let wait = wait_start.elapsed();
        let t = Instant::now();
        let m = self.state.epoch(scene, window.time + window.dt, &grains, &stress, &points);
        let header = session.header(step, window.time, window.dt);
        publish_slice(zones_pub, header, &m.zones, checksums)?;
        // The five lists carry no checksum (§3.10).
        publish_slice(&mut self.delete_grains, header, &m.delete_grains, false)?;
        publish_slice(&mut self.delete_points, header, &m.delete_points, false)?;
        publish_slice(&mut self.spawn_grains, header, &m.spawn_grains, false)?;
        publish_slice(&mut self.spawn_points, header, &m.spawn_points, false)?;
        publish_slice(&mut self.scale_points, header, &m.scale_points, false)?;
        report.mass = m.mass_before;
        report.momentum = m.momentum_before;
        report.n_items = m.zones.len() as u64;
        report.n_nodes = m.hybrid_cells;
        Ok((wait, t.elapsed()))
    }
}

/// The zones of a 2D epoch as text (logged at debug level, `RUST_LOG=grains_oracle_service=debug`, for debugging scenes): a row of
/// letters per cell row, top first, D/H/C (lower case behind a wall), and what changes.
fn zone_map(cells: &grains_grid::Grid, plan: &epoch::Plan, solid: &[bool], time: f64) -> String {
    let n0 = cells.nodes[0] as usize;
    let mut out = format!("grains-oracle: epoch at t = {time:.6} s, unplaced mass {:.3e} kg\n", plan.unplaced);
    for j in (0..cells.nodes[1] as usize).rev() {
        let row: String = (j * n0..(j + 1) * n0)
            .map(|c| {
                let z = match plan.zones[c] {
                    Zone::Discrete => 'D',
                    Zone::Hybrid => 'H',
                    Zone::Continuum => 'C',
                };
                if solid[c] { z.to_ascii_lowercase() } else { z }
            })
            .collect();
        out.push_str(&row);
        out.push('\n');
    }
    out.push_str(&format!(
        "new grains {}, new points {}, deleted grains {}, deleted points {}, scaled points {}\n",
        plan.new_grains.len(),
        plan.new_points.len(),
        plan.delete_grains.len(),
        plan.delete_points.len(),
        plan.scale_points.len()
    ));
    out
}

/// Distance from `x` to the nearest wall at `time` (walls translate at their scene velocity),
/// negative behind one (behind a 2D segment: on its right, see the MPM's segment).
pub fn wall_clearance(scene: &Scene, x: [f64; 3], time: f64) -> f64 {
    let dim = scene.dim();
    let dot = |a: [f64; 3], b: [f64; 3]| (0..dim).map(|k| a[k] * b[k]).sum::<f64>();
    scene
        .walls
        .iter()
        .map(|w| {
            let at = |p: [f64; 3]| -> [f64; 3] { std::array::from_fn(|k| p[k] + w.velocity[k] * time) };
            match w.shape {
                grains_protocol::scene::WallShape::Plane { point, normal } => {
                    let p = at(point);
                    dot(std::array::from_fn(|k| x[k] - p[k]), normal)
                }
                grains_protocol::scene::WallShape::Box { min, max } => {
                    let (lo, hi) = (at(min), at(max));
                    (0..dim).map(|k| (x[k] - lo[k]).min(hi[k] - x[k])).fold(f64::INFINITY, f64::min)
                }
                grains_protocol::scene::WallShape::Drum { center, radius } => {
                    let c = at(center);
                    radius - (0..2).map(|k| (x[k] - c[k]).powi(2)).sum::<f64>().sqrt()
                }
                grains_protocol::scene::WallShape::Segment { from, to } => {
                    let (a, b) = (at(from), at(to));
                    let ab: [f64; 3] = std::array::from_fn(|k| b[k] - a[k]);
                    let ax: [f64; 3] = std::array::from_fn(|k| x[k] - a[k]);
                    let along = dot(ax, ab) / dot(ab, ab).max(f64::MIN_POSITIVE);
                    let t = along.clamp(0.0, 1.0);
                    let distance = (0..dim).map(|k| (ax[k] - t * ab[k]).powi(2)).sum::<f64>().sqrt();
                    // Behind a 2D segment (its right, across from the continuum's side) is
                    // behind a wall: no new grains there (they would land in a silo's bin).
                    let ahead = ax[0] * -ab[1] + ax[1] * ab[0];
                    if dim == 2 && (0.0..=1.0).contains(&along) && ahead < 0.0 {
                        -distance
                    } else {
                        distance
                    }
                }
            }
        })
        .fold(f64::INFINITY, f64::min)
}

/// The cells whose centre lies behind a wall at `time` (walls translate at their scene
/// velocity): behind a plane, outside a box or a drum, or up to `behind` plus a cell behind a
/// segment (its back, the side opposite the continuum's: see the MPM's segment). The space
/// behind a segment is open (a silo's bin), but it must not read as a free surface for the
/// material resting on the segment: `behind` is the depth of the oracle's band, so that only
/// the orifice, past the segment's end, is one.
pub fn solid_cells(scene: &Scene, cells: &grains_grid::Grid, time: f64, behind: f64) -> Vec<bool> {
    let dim = scene.dim();
    let n = [0, 1, 2].map(|k| if k < dim { cells.nodes[k] as usize } else { 1 });
    let mut out = vec![false; n.iter().product()];
    for (c, solid) in out.iter_mut().enumerate() {
        let ijk = [c % n[0], (c / n[0]) % n[1], c / (n[0] * n[1])];
        let x: [f64; 3] = std::array::from_fn(|k| {
            if k < dim {
                cells.origin[k] + (ijk[k] as f64 + 0.5) * cells.h
            } else {
                0.0
            }
        });
        *solid = scene.walls.iter().any(|w| {
            let at = |p: [f64; 3]| -> [f64; 3] { std::array::from_fn(|k| p[k] + w.velocity[k] * time) };
            match w.shape {
                grains_protocol::scene::WallShape::Plane { point, normal } => {
                    let p = at(point);
                    (0..dim).map(|k| (x[k] - p[k]) * normal[k]).sum::<f64>() < 0.0
                }
                grains_protocol::scene::WallShape::Box { min, max } => {
                    let (lo, hi) = (at(min), at(max));
                    (0..dim).any(|k| x[k] < lo[k] || x[k] > hi[k])
                }
                grains_protocol::scene::WallShape::Drum { center, radius } => {
                    let c = at(center);
                    (0..2).map(|k| (x[k] - c[k]).powi(2)).sum::<f64>() > radius * radius
                }
                grains_protocol::scene::WallShape::Segment { from, to } => {
                    // A cell centred on an end is half in the opening: open.
                    let f = grains_grid::space::segment_frame(at(from), at(to), x);
                    dim == 2 && f.between_ends(false) && f.ahead < 0.0 && f.ahead >= -(behind + cells.h)
                }
            }
        });
    }
    out
}

/// Voigt order xx, yy, zz, yz, xz, xy (the protocol's).
pub fn to_voigt(s: &[[f64; 3]; 3]) -> [f64; 6] {
    [s[0][0], s[1][1], s[2][2], s[1][2], s[0][2], s[0][1]]
}

pub fn from_voigt(v: [f64; 6]) -> [[f64; 3]; 3] {
    [[v[0], v[5], v[4]], [v[5], v[1], v[3]], [v[4], v[3], v[2]]]
}
