//! The participant loop of a solver (DEM or MPM), the same for every solver behind the
//! [`Solver`] trait, and the time-owner helpers (control commands) that a solver running
//! alone shares with the coupler.

use crate::session::Session;
use crate::zones::ZoneField;
use anyhow::bail;
use grains_protocol::names;
use grains_protocol::wire::{
    Ack, AckStatus, BodyReach, Command, ContactPoint, Control, EpochItem, NodeStress, NodeVelocity, Param, PointForce, PointScale,
    RasterNode, STEP_CHECKPOINT, STEP_STOP, SpawnGrain, SpawnPoint, StepBegin, StepHeader, Summary, ViewPoint, ZoneCell,
};
use grains_protocol::{Role, checksum::checksum_bytes, scene::Scene};
use grains_transport::{Publisher, Subscriber, Transport, as_bytes};
use std::time::{Duration, Instant};

/// The macro-step a solver is asked to take.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepWindow {
    pub step: u64,
    /// Simulated time at the start of the step [s].
    pub time: f64,
    pub dt: f64,
    /// DEM substeps per macro-step: the time owner's (the coupler's `StepBegin`, or the
    /// scene's `coupling.substeps` for a DEM that runs alone), the DEM's one source of them.
    pub substeps: u32,
    /// A `checkpoint` command asked for a checkpoint after this step.
    pub checkpoint: bool,
}

impl StepWindow {
    /// Macro-step `step` (from 1) of a scene.
    pub fn of(scene: &Scene, step: u64) -> Self {
        StepWindow {
            step,
            time: (step - 1) as f64 * scene.dt,
            dt: scene.dt,
            substeps: scene.coupling.substeps,
            checkpoint: false,
        }
    }
}

/// What a solver reports after each step (the physics half of [`Summary`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SolverReport {
    pub n_items: u64,
    pub n_nodes: u64,
    pub mass: f64,
    pub momentum: [f64; 3],
    pub kinetic_energy: f64,
    /// Checksum of the raster sent, when checksums are on.
    pub checksum: u64,
}

/// A solver as the participant loop drives it (Yue 2018 Alg. 1, one macro-step):
/// [`Solver::predict`] up to the coupling point, [`Solver::write_raster`] into the loaned
/// message, then [`Solver::finish`] with the coupler's velocities. Without a coupler in the
/// run, [`Solver::step_alone`] takes the whole step.
pub trait Solver {
    /// Advances to the coupling point and returns the number of raster nodes to send.
    fn predict(&mut self, window: &StepWindow) -> anyhow::Result<usize>;
    /// Writes the raster (sorted by node) in place into the message.
    fn write_raster(&mut self, window: &StepWindow, out: &mut [RasterNode]);
    /// Takes the constrained node velocities and completes the step.
    fn finish(&mut self, window: &StepWindow, velocities: &[NodeVelocity]) -> anyhow::Result<()>;
    /// A whole step when the solver is the only one in the run.
    fn step_alone(&mut self, window: &StepWindow) -> anyhow::Result<()>;
    /// State after the last step.
    fn report(&self) -> SolverReport;
    /// Whether [`Solver::view`] can say everything now (false: the view waits for the next
    /// step; the DEM's after an epoch's exchange, whose contacts are not known yet).
    fn view_ready(&self) -> bool {
        true
    }
    /// A view for remote viewers: at most `max` items (every k-th) into `out`; returns the
    /// total count.
    fn view(&self, max: usize, out: &mut Vec<ViewPoint>) -> u64 {
        let _ = (max, out);
        0
    }
    /// At an oracle epoch: every grain or point, as the oracle sees it.
    fn epoch_items(&mut self, out: &mut Vec<EpochItem>) {
        let _ = out;
    }
    /// At an oracle epoch (DEM): the grains' homogenized stress per grid node.
    fn epoch_stress(&mut self, out: &mut Vec<NodeStress>) {
        let _ = out;
    }
    /// The oracle's decisions of an epoch after step `step`: delete, create, then weigh
    /// every item by the zone of its cell.
    fn apply_epoch(&mut self, step: u64, changes: &EpochChanges<'_>) -> anyhow::Result<()> {
        let _ = (step, changes);
        bail!("this solver does not take oracle epochs")
    }
    /// Its whole state after a step, for a checkpoint ([`crate::checkpoint`]): what
    /// [`Solver::restore`] needs to go on bit for bit.
    fn save(&self) -> anyhow::Result<Vec<u8>> {
        bail!("this solver cannot write checkpoints")
    }
    /// Takes back the state of [`Solver::save`], in a solver just built from the scene.
    fn restore(&mut self, bytes: &[u8]) -> anyhow::Result<()> {
        let _ = bytes;
        bail!("this solver cannot resume from checkpoints")
    }
    /// Contact coupling (DEM, Jiang 2020 §4), at the start of a step: every rigid body's
    /// reach.
    fn body_reach(&self, out: &mut Vec<BodyReach>) {
        let _ = out;
    }
    /// Contact coupling (MPM): the points within `reach` of a body plus their contact radius.
    fn contact_points(&mut self, reach: &[BodyReach], out: &mut Vec<ContactPoint>) {
        let _ = (reach, out);
    }
    /// Contact coupling (DEM): the bodies' force on each of `points` over the step of
    /// `window` into `out`; their reactions act on the bodies through the step.
    fn contact_forces(&mut self, window: &StepWindow, points: &[ContactPoint], out: &mut Vec<PointForce>) -> anyhow::Result<()> {
        let _ = (window, points, out);
        bail!("this solver has no rigid bodies to meet a continuum")
    }
    /// Contact coupling (MPM): the bodies' forces on its points, loads for the coming step.
    fn take_contact_forces(&mut self, forces: &[PointForce]) -> anyhow::Result<()> {
        let _ = forces;
        bail!("this solver has no material points to take contact forces")
    }
    /// A `snapshot` or `set` command, between steps (after step `done`); why not, if it
    /// cannot be carried out.
    fn command(&mut self, done: u64, c: &Control) -> Result<(), String> {
        let _ = (done, c);
        Err("this solver takes no commands".into())
    }
}

/// What an oracle epoch asks of a solver (its own lists only: the DEM gets no points).
pub struct EpochChanges<'a> {
    pub zones: &'a ZoneField,
    /// Ids of this solver's items to delete.
    pub delete: &'a [u64],
    pub spawn_grains: &'a [SpawnGrain],
    pub spawn_points: &'a [SpawnPoint],
    /// Points whose mass and volume change (before the new ones are added).
    pub scale_points: &'a [PointScale],
}

/// A solver's ports for oracle epochs.
struct EpochPorts<T: Transport> {
    items: T::Publisher<EpochItem, StepHeader>,
    stress: Option<T::Publisher<NodeStress, StepHeader>>,
    delete: T::Subscriber<u64, StepHeader>,
    spawn_grains: Option<T::Subscriber<SpawnGrain, StepHeader>>,
    spawn_points: Option<T::Subscriber<SpawnPoint, StepHeader>>,
    scale_points: Option<T::Subscriber<PointScale, StepHeader>>,
    items_buf: Vec<EpochItem>,
    stress_buf: Vec<NodeStress>,
}

impl<T: Transport> EpochPorts<T> {
    fn open(session: &Session<'_, T>) -> anyhow::Result<Self> {
        let dem = session.role == Role::Dem;
        Ok(EpochPorts {
            items: session.publisher(if dem { &names::DEM_EPOCH } else { &names::MPM_EPOCH }, 1024)?,
            stress: if dem {
                Some(session.publisher(&names::DEM_STRESS, 1024)?)
            } else {
                None
            },
            delete: session.subscriber(if dem { &names::DELETE_GRAINS } else { &names::DELETE_POINTS })?,
            spawn_grains: if dem {
                Some(session.subscriber(&names::SPAWN_GRAINS)?)
            } else {
                None
            },
            spawn_points: if dem {
                None
            } else {
                Some(session.subscriber(&names::SPAWN_POINTS)?)
            },
            scale_points: if dem {
                None
            } else {
                Some(session.subscriber(&names::SCALE_POINTS)?)
            },
            items_buf: Vec::new(),
            stress_buf: Vec::new(),
        })
    }

    fn connected(&mut self) -> bool {
        self.items.subscriber_count() >= 1
            && self.stress.as_mut().is_none_or(|p| p.subscriber_count() >= 1)
            && self.delete.publisher_count() >= 1
            && self.spawn_grains.as_mut().is_none_or(|s| s.publisher_count() >= 1)
            && self.spawn_points.as_mut().is_none_or(|s| s.publisher_count() >= 1)
            && self.scale_points.as_mut().is_none_or(|s| s.publisher_count() >= 1)
    }

    /// Sends the solver's items (and stress) of step `window.step` to the oracle, waits for
    /// its decisions and applies them.
    fn exchange<S: Solver>(
        &mut self,
        session: &Session<'_, T>,
        scene: &Scene,
        zones_sub: &mut T::Subscriber<ZoneCell, StepHeader>,
        window: &StepWindow,
        solver: &mut S,
    ) -> anyhow::Result<()> {
        let header = session.header(window.step, window.time, window.dt);
        self.items_buf.clear();
        solver.epoch_items(&mut self.items_buf);
        let items = &self.items_buf;
        self.items.publish(items.len(), |h, out| {
            *h = header;
            out.copy_from_slice(items);
        })?;
        if let Some(p) = &mut self.stress {
            self.stress_buf.clear();
            solver.epoch_stress(&mut self.stress_buf);
            let stress = &self.stress_buf;
            p.publish(stress.len(), |h, out| {
                *h = header;
                out.copy_from_slice(stress);
            })?;
        }
        let step = window.step;
        let zones = session.recv(zones_sub, "the oracle's zones", |h, cells| -> anyhow::Result<ZoneField> {
            session.check_message(&names::ZONES, h, step, cells)?;
            ZoneField::from_cells(scene, cells).map_err(|e| anyhow::anyhow!("{}: {e}", names::ZONES.name))
        })??;
        let delete_spec = if session.role == Role::Dem {
            names::DELETE_GRAINS
        } else {
            names::DELETE_POINTS
        };
        let delete = session.recv(&mut self.delete, "the oracle's delete list", |h, ids| -> anyhow::Result<Vec<u64>> {
            session.check_message(&delete_spec, h, step, ids)?;
            Ok(ids.to_vec())
        })??;
        let spawn_grains = match &mut self.spawn_grains {
            Some(sub) => session.recv(sub, "the oracle's new grains", |h, g| -> anyhow::Result<Vec<SpawnGrain>> {
                session.check_message(&names::SPAWN_GRAINS, h, step, g)?;
                Ok(g.to_vec())
            })??,
            None => Vec::new(),
        };
        let spawn_points = match &mut self.spawn_points {
            Some(sub) => session.recv(sub, "the oracle's new points", |h, p| -> anyhow::Result<Vec<SpawnPoint>> {
                session.check_message(&names::SPAWN_POINTS, h, step, p)?;
                Ok(p.to_vec())
            })??,
            None => Vec::new(),
        };
        let scale_points = match &mut self.scale_points {
            Some(sub) => session.recv(sub, "the oracle's point scales", |h, p| -> anyhow::Result<Vec<PointScale>> {
                session.check_message(&names::SCALE_POINTS, h, step, p)?;
                Ok(p.to_vec())
            })??,
            None => Vec::new(),
        };
        solver.apply_epoch(
            step,
            &EpochChanges {
                zones: &zones,
                delete: &delete,
                spawn_grains: &spawn_grains,
                spawn_points: &spawn_points,
                scale_points: &scale_points,
            },
        )
    }
}

/// The ports of the contact coupling of rigid bodies and a continuum (Jiang 2020 §4), one
/// side each: the DEM owns the bodies and their contacts; each step it sends the bodies' reach,
/// the MPM answers with its points in reach, the DEM with the force on each of them.
enum ContactPorts<T: Transport> {
    Dem {
        reach: T::Publisher<BodyReach, StepHeader>,
        points: T::Subscriber<ContactPoint, StepHeader>,
        forces: T::Publisher<PointForce, StepHeader>,
        reach_buf: Vec<BodyReach>,
        forces_buf: Vec<PointForce>,
    },
    Mpm {
        reach: T::Subscriber<BodyReach, StepHeader>,
        points: T::Publisher<ContactPoint, StepHeader>,
        forces: T::Subscriber<PointForce, StepHeader>,
        points_buf: Vec<ContactPoint>,
    },
}

impl<T: Transport> ContactPorts<T> {
    fn open(session: &Session<'_, T>) -> anyhow::Result<Self> {
        Ok(if session.role == Role::Dem {
            ContactPorts::Dem {
                reach: session.publisher(&names::BODY_REACH, 16)?,
                points: session.subscriber(&names::CONTACT_POINTS)?,
                forces: session.publisher(&names::POINT_FORCES, 1024)?,
                reach_buf: Vec::new(),
                forces_buf: Vec::new(),
            }
        } else {
            ContactPorts::Mpm {
                reach: session.subscriber(&names::BODY_REACH)?,
                points: session.publisher(&names::CONTACT_POINTS, 1024)?,
                forces: session.subscriber(&names::POINT_FORCES)?,
                points_buf: Vec::new(),
            }
        })
    }

    fn connected(&mut self) -> bool {
        match self {
            ContactPorts::Dem { reach, points, forces, .. } => {
                reach.subscriber_count() >= 1 && points.publisher_count() >= 1 && forces.subscriber_count() >= 1
            }
            ContactPorts::Mpm { reach, points, forces, .. } => {
                reach.publisher_count() >= 1 && points.subscriber_count() >= 1 && forces.publisher_count() >= 1
            }
        }
    }

    /// The exchange at the start of `window`'s step, before the solver predicts; returns the
    /// time spent waiting for the other solver.
    fn exchange<S: Solver>(
        &mut self,
        session: &Session<'_, T>,
        window: &StepWindow,
        solver: &mut S,
        checksums: bool,
    ) -> anyhow::Result<Duration> {
        let header = session.header(window.step, window.time, window.dt);
        let step = window.step;
        // Time in `recv` minus the time the solver took inside it.
        let mut waited = Duration::ZERO;
        let mut timed_recv = |recv: &mut dyn FnMut(&mut Duration) -> anyhow::Result<()>| -> anyhow::Result<()> {
            let (t, mut inside) = (Instant::now(), Duration::ZERO);
            recv(&mut inside)?;
            waited += t.elapsed().saturating_sub(inside);
            Ok(())
        };
        match self {
            ContactPorts::Dem {
                reach,
                points,
                forces,
                reach_buf,
                forces_buf,
            } => {
                reach_buf.clear();
                solver.body_reach(reach_buf);
                publish_slice(reach, header, reach_buf, checksums)?;
                forces_buf.clear();
                timed_recv(&mut |inside| {
                    session.recv(points, "the material points near the bodies", |h, p| -> anyhow::Result<()> {
                        let t = Instant::now();
                        session.check_message(&names::CONTACT_POINTS, h, step, p)?;
                        solver.contact_forces(window, p, forces_buf)?;
                        *inside = t.elapsed();
                        Ok(())
                    })?
                })?;
                publish_slice(forces, header, forces_buf, checksums)?;
            }
            ContactPorts::Mpm {
                reach,
                points,
                forces,
                points_buf,
            } => {
                points_buf.clear();
                timed_recv(&mut |inside| {
                    session.recv(reach, "the rigid bodies' reach", |h, r| -> anyhow::Result<()> {
                        let t = Instant::now();
                        session.check_message(&names::BODY_REACH, h, step, r)?;
                        solver.contact_points(r, points_buf);
                        *inside = t.elapsed();
                        Ok(())
                    })?
                })?;
                publish_slice(points, header, points_buf, checksums)?;
                timed_recv(&mut |inside| {
                    session.recv(forces, "the contact forces on the points", |h, f| -> anyhow::Result<()> {
                        let t = Instant::now();
                        session.check_message(&names::POINT_FORCES, h, step, f)?;
                        solver.take_contact_forces(f)?;
                        *inside = t.elapsed();
                        Ok(())
                    })?
                })?;
            }
        }
        Ok(waited)
    }
}

/// Publishes `items` with `header` (and their checksum).
pub fn publish_slice<E: grains_transport::Pod + grains_transport::ZeroCopy>(
    publisher: &mut impl Publisher<E, StepHeader>,
    header: StepHeader,
    items: &[E],
    checksums: bool,
) -> anyhow::Result<()> {
    publisher.publish(items.len(), |h, out| {
        out.copy_from_slice(items);
        *h = header;
        if checksums {
            h.checksum = checksum_bytes(as_bytes(out));
        }
    })?;
    Ok(())
}

/// Views for remote viewers: at most this often, and at most this many items.
pub const VIEW_PERIOD: Duration = Duration::from_millis(200);
pub const VIEW_MAX: usize = 5000;

/// A solver's view publisher: a few times a second, only while someone (the bridge) listens;
/// the service overwrites an unread view, so a slow reader never holds the solver up.
pub struct Viewer<T: Transport> {
    publisher: T::Publisher<ViewPoint, StepHeader>,
    last: Option<Instant>,
    buf: Vec<ViewPoint>,
}

impl<T: Transport> Viewer<T> {
    pub fn open(session: &Session<'_, T>) -> anyhow::Result<Option<Self>> {
        let spec = match session.role {
            Role::Dem => names::DEM_VIEW,
            Role::Mpm => names::MPM_VIEW,
            _ => return Ok(None),
        };
        Ok(Some(Viewer {
            publisher: session.publisher(&spec, 1)?,
            last: None,
            buf: Vec::new(),
        }))
    }

    /// Publishes a view of `solver` after `window` if one is due and someone listens.
    pub fn offer<S: Solver>(&mut self, session: &Session<'_, T>, window: &StepWindow, solver: &S) -> anyhow::Result<()> {
        if self.last.is_some_and(|t| t.elapsed() < VIEW_PERIOD) || !solver.view_ready() {
            return Ok(());
        }
        self.last = Some(Instant::now());
        if self.publisher.subscriber_count() == 0 {
            return Ok(());
        }
        self.buf.clear();
        let total = solver.view(VIEW_MAX, &mut self.buf);
        let mut header = session.header(window.step, window.time + window.dt, window.dt);
        header.flags = total;
        let buf = &self.buf;
        self.publisher.publish(buf.len(), |h, out| {
            *h = header;
            out.copy_from_slice(buf);
        })?;
        Ok(())
    }
}

/// A vector (gravity, a wall's velocity) after a `set` of `param`'s axis to `value` in a
/// `dim`-dimensional run (for [`Solver::command`]); refused for an axis the run does not have.
pub fn set_component(mut v: [f64; 3], dim: usize, param: Param, value: f64) -> Result<[f64; 3], String> {
    if param.axis() >= dim {
        return Err(format!("{} in a {dim}D run", param.name()));
    }
    v[param.axis()] = value;
    Ok(v)
}

/// Every k-th of `n` items so that at most `max` remain (for [`Solver::view`]).
pub fn view_stride(n: usize, max: usize) -> usize {
    n.div_ceil(max.max(1)).max(1)
}

/// Participant options that do not come from the scene.
#[derive(Clone, Debug)]
pub struct ParticipantOptions {
    pub run_id: String,
    pub stop: crate::signals::StopFlag,
    pub connect_timeout: Option<Duration>,
    pub protocol_version: u32,
    /// Compute and verify payload checksums.
    pub checksums: bool,
    /// The run's output directory (frames go under it), if outputs are wanted.
    pub out_dir: Option<std::path::PathBuf>,
    /// The checkpoint to resume from (`grains resume`), if any.
    pub resume: Option<crate::checkpoint::Resume>,
}

impl ParticipantOptions {
    /// The step after which this participant starts (0, or the checkpoint's).
    pub fn start_after(&self) -> u64 {
        self.resume.as_ref().map_or(0, |r| r.step)
    }

    /// Writes this participant's checkpoint after `window`'s step if one is due there or
    /// was asked for (before its summary of the step: the launcher counts a checkpoint
    /// complete once it has every summary).
    pub fn checkpoint(
        &self,
        scene: &Scene,
        role: Role,
        window: &StepWindow,
        payload: impl FnOnce() -> anyhow::Result<Vec<u8>>,
    ) -> anyhow::Result<()> {
        let step = window.step;
        if !crate::checkpoint::due(scene, step) && !window.checkpoint {
            return Ok(());
        }
        let Some(dir) = &self.out_dir else {
            bail!("a checkpoint is due after step {step}, but this participant has no output directory (--out-dir) to write it in");
        };
        let t = Instant::now();
        let bytes = payload()?;
        crate::checkpoint::write(dir, role, scene.hash, step, &bytes)?;
        tracing::debug!(
            "checkpoint after step {step}: {} bytes in {:.1} ms",
            bytes.len(),
            t.elapsed().as_secs_f64() * 1e3
        );
        Ok(())
    }
}

/// Runs one solver participant to the end of the run.
///
/// `make` builds the solver from the zone field: the oracle's when the run has an oracle
/// (received before the start, so that setup does not count as step time), else the layered
/// zones of the scene (empty without hybrid bodies).
pub fn run<T: Transport, S: Solver>(
    transport: &T,
    role: Role,
    scene: &Scene,
    opts: &ParticipantOptions,
    make: impl FnOnce(&ZoneField) -> anyhow::Result<S>,
) -> anyhow::Result<()> {
    let mut session = join(transport, role, scene, opts)?;
    let resume = |solver: &mut S| match &opts.resume {
        Some(r) => solver.restore(&crate::checkpoint::read(r, role, scene.hash)?),
        None => Ok(()),
    };
    if scene.time_owner() == role {
        let mut solver = make(&ZoneField::layered(scene))?;
        resume(&mut solver)?;
        return run_alone(&mut session, scene, opts, &mut solver);
    }
    let mut ports = CoupledPorts::<T>::open(&session, scene)?;
    session.wait_until(
        "the coupler, the oracle (if any), the other solver's contact ports (rigid bodies and a continuum) and the launcher",
        |_| ports.connected(),
    )?;
    let zones = ports.initial_zones(&session, scene)?;
    let mut solver = make(&zones)?;
    resume(&mut solver)?;
    session.ready()?;
    loop {
        let wait_start = Instant::now();
        let Some(window) = next_step(&session, &mut ports.step_sub)? else {
            return Ok(());
        };
        // Only once the step is in hand: after the last one the coupler may be exiting.
        session.watch_peers()?;
        crate::telemetry::set_step(Some(window.step));
        let wait = wait_start.elapsed();
        ports.step(&session, scene, opts, &window, &mut solver, wait)?;
    }
}

/// The ports of a solver that the coupler drives. (Fields in the reverse of the order they
/// are opened in: they close in the order they did as the loop's locals, the step begins last.)
struct CoupledPorts<T: Transport> {
    /// Rigid bodies against a continuum, when the scene has both.
    contact: Option<ContactPorts<T>>,
    /// Oracle epochs, when the run's oracle is adaptive.
    epochs: Option<EpochPorts<T>>,
    /// The oracle's zones, when the run has an oracle.
    zones_sub: Option<T::Subscriber<ZoneCell, StepHeader>>,
    viewer: Option<Viewer<T>>,
    command_sub: T::Subscriber<Control, StepHeader>,
    summary_pub: T::Publisher<Summary, StepHeader>,
    raster_pub: T::Publisher<RasterNode, StepHeader>,
    vel_sub: T::Subscriber<NodeVelocity, StepHeader>,
    step_sub: T::Subscriber<StepBegin, StepHeader>,
}

impl<T: Transport> CoupledPorts<T> {
    fn open(session: &Session<'_, T>, scene: &Scene) -> anyhow::Result<Self> {
        let raster_spec = if session.role == Role::Dem {
            names::DEM_RASTER
        } else {
            names::MPM_RASTER
        };
        let step_sub = session.subscriber::<StepBegin, StepHeader>(&names::STEP_BEGIN)?;
        let vel_sub = session.subscriber::<NodeVelocity, StepHeader>(&names::VELOCITIES)?;
        let raster_pub = session.publisher::<RasterNode, StepHeader>(&raster_spec, 1024)?;
        let summary_pub = session.publisher::<Summary, StepHeader>(&names::SUMMARY, 1)?;
        let command_sub = session.subscriber::<Control, StepHeader>(&names::COMMAND)?;
        let viewer = Viewer::open(session)?;
        let zones_sub = match scene.participants().contains(&Role::Oracle) {
            true => Some(session.subscriber::<ZoneCell, StepHeader>(&names::ZONES)?),
            false => None,
        };
        let adaptive = scene.oracle.as_ref().is_some_and(|o| o.kind.adaptive()) && zones_sub.is_some();
        let epochs = if adaptive { Some(EpochPorts::<T>::open(session)?) } else { None };
        let contact = if scene.contact_coupling() {
            Some(ContactPorts::<T>::open(session)?)
        } else {
            None
        };
        Ok(CoupledPorts {
            contact,
            epochs,
            zones_sub,
            viewer,
            command_sub,
            summary_pub,
            raster_pub,
            vel_sub,
            step_sub,
        })
    }

    /// The coupler, the oracle (if any) and the launcher are connected.
    fn connected(&mut self) -> bool {
        self.step_sub.publisher_count() >= 1
            && self.command_sub.publisher_count() >= 1
            && self.vel_sub.publisher_count() >= 1
            && self.raster_pub.subscriber_count() >= 1
            && self.summary_pub.subscriber_count() >= 1
            && self.zones_sub.as_ref().is_none_or(|z| z.publisher_count() >= 1)
            && self.epochs.as_mut().is_none_or(EpochPorts::connected)
            && self.contact.as_mut().is_none_or(ContactPorts::connected)
    }

    /// The zone field to build the solver from: the oracle's (step 0) when the run has one,
    /// else the layered zones of the scene.
    fn initial_zones(&mut self, session: &Session<'_, T>, scene: &Scene) -> anyhow::Result<ZoneField> {
        Ok(match &mut self.zones_sub {
            Some(sub) => session.recv(sub, "the zone field", |h, cells| -> anyhow::Result<ZoneField> {
                session.check_message(&names::ZONES, h, 0, cells)?;
                ZoneField::from_cells(scene, cells).map_err(|e| anyhow::anyhow!("{}: {e}", names::ZONES.name))
            })??,
            None => ZoneField::layered(scene),
        })
    }

    /// One macro-step of `window` (Yue 2018 Alg. 1), once its step begin is in (after
    /// `wait`): the commands the time owner accepted, predict and send the raster, finish with
    /// the coupler's velocities, the oracle's epoch if one is due; then the summary and a view.
    fn step<S: Solver>(
        &mut self,
        session: &Session<'_, T>,
        scene: &Scene,
        opts: &ParticipantOptions,
        window: &StepWindow,
        solver: &mut S,
        mut wait: Duration,
    ) -> anyhow::Result<()> {
        let compute_start = Instant::now();
        self.apply_commands(window, solver)?;
        let mut contact_wait = Duration::ZERO;
        if let Some(c) = &mut self.contact {
            contact_wait = c.exchange(session, window, solver, opts.checksums)?;
        }
        let sent_checksum = self.send_raster(session, window, solver, opts.checksums)?;
        let mut compute = compute_start.elapsed() - contact_wait;
        wait += contact_wait;

        let wait_start = Instant::now();
        let finish_time = self.finish(session, window, solver)?;
        wait += wait_start.elapsed() - finish_time;
        compute += finish_time;
        if let (Some(e), Some(z)) = (&mut self.epochs, &mut self.zones_sub)
            && scene.epoch_after(window.step)
        {
            // Counted as compute: the oracle's planning is part of the step's work.
            let t = Instant::now();
            e.exchange(session, scene, z, window, solver)?;
            compute += t.elapsed();
        }

        opts.checkpoint(scene, session.role, window, || solver.save())?;
        let mut report = solver.report();
        report.checksum = sent_checksum;
        publish_summary(session, &mut self.summary_pub, window, &report, compute, wait)?;
        if let Some(v) = &mut self.viewer {
            v.offer(session, window, &*solver)?;
        }
        Ok(())
    }

    /// Commands the time owner accepted after the previous step (sent before this begin).
    fn apply_commands<S: Solver>(&mut self, window: &StepWindow, solver: &mut S) -> anyhow::Result<()> {
        while let Some(Some(c)) = self.command_sub.receive(Duration::ZERO, |_, c| c.first().copied())? {
            if let Err(why) = solver.command(window.step - 1, &c) {
                tracing::warn!("command {} not carried out: {why}", c.command);
            }
        }
        Ok(())
    }

    /// Advances the solver to the coupling point and sends its raster; returns the raster's
    /// checksum (0 without checksums).
    fn send_raster<S: Solver>(
        &mut self,
        session: &Session<'_, T>,
        window: &StepWindow,
        solver: &mut S,
        checksums: bool,
    ) -> anyhow::Result<u64> {
        let n = solver.predict(window)?;
        let header = session.header(window.step, window.time, window.dt);
        let mut sent_checksum = 0;
        self.raster_pub.publish(n, |hdr, out| {
            solver.write_raster(window, out);
            *hdr = header;
            if checksums {
                hdr.checksum = checksum_bytes(as_bytes(out));
                sent_checksum = hdr.checksum;
            }
        })?;
        Ok(sent_checksum)
    }

    /// Waits for the coupler's velocities and completes the step with them; returns the time
    /// the solver took.
    fn finish<S: Solver>(&mut self, session: &Session<'_, T>, window: &StepWindow, solver: &mut S) -> anyhow::Result<Duration> {
        let mut finish_time = Duration::ZERO;
        session.recv(&mut self.vel_sub, "the constrained velocities", |h, v| -> anyhow::Result<()> {
            session.check_message(&names::VELOCITIES, h, window.step, v)?;
            let t = Instant::now();
            solver.finish(window, v)?;
            finish_time = t.elapsed();
            Ok(())
        })??;
        Ok(finish_time)
    }
}

/// Joins the run of `scene` as `role` (admission by the launcher).
pub fn join<'t, T: Transport>(transport: &'t T, role: Role, scene: &Scene, opts: &ParticipantOptions) -> anyhow::Result<Session<'t, T>> {
    if scene.coupling.auto.is_some() {
        bail!(
            "{}: coupling.substeps = \"auto\" is resolved by `grains run`, which writes the chosen steps into the run's copy \
             of the scene (<run dir>/scene.toml): a participant reads that copy",
            scene.path.display()
        );
    }
    Session::join(
        transport,
        role,
        &opts.run_id,
        scene.hash,
        opts.stop.clone(),
        opts.connect_timeout,
        opts.protocol_version,
    )
}

/// Waits for the time owner's next step begin (checked); `None` when it says stop.
pub fn next_step<T: Transport>(
    session: &Session<'_, T>,
    step_sub: &mut T::Subscriber<StepBegin, StepHeader>,
) -> anyhow::Result<Option<StepWindow>> {
    let (h, b) = session.recv(step_sub, "the next step", |h, b| -> anyhow::Result<(StepHeader, StepBegin)> {
        session.check_message(&names::STEP_BEGIN, h, h.step, b)?;
        let begin = b.first().copied().ok_or_else(|| {
            anyhow::anyhow!(
                "{}: step {}: an empty message (one StepBegin expected)",
                names::STEP_BEGIN.name,
                h.step
            )
        })?;
        Ok((*h, begin))
    })??;
    Ok((b.flags & STEP_STOP == 0).then_some(StepWindow {
        step: h.step,
        time: h.time,
        dt: h.dt,
        substeps: b.substeps,
        checkpoint: b.flags & STEP_CHECKPOINT != 0,
    }))
}

/// A solver that owns time: it steps by itself and obeys control commands between steps.
fn run_alone<T: Transport, S: Solver>(
    session: &mut Session<'_, T>,
    scene: &Scene,
    opts: &ParticipantOptions,
    solver: &mut S,
) -> anyhow::Result<()> {
    let mut clock = RunClock::open(session)?;
    let mut summary_pub = session.publisher::<Summary, StepHeader>(&names::SUMMARY, 1)?;
    session.wait_until("the launcher", |_| clock.connected() && summary_pub.subscriber_count() >= 1)?;
    session.ready()?;
    let mut viewer = Viewer::open(session)?;
    for step in opts.start_after() + 1..=scene.steps {
        let mut checkpoint = false;
        let go_on = clock.obey(session, step - 1, |c| {
            if Command::from_code(c.command) == Some(Command::Checkpoint) {
                checkpoint = opts.out_dir.is_some();
                return if checkpoint { AckStatus::Applied } else { AckStatus::Unsupported };
            }
            match solver.command(step - 1, c) {
                Ok(()) => AckStatus::Applied,
                Err(why) => {
                    tracing::warn!("command {} refused: {why}", c.command);
                    AckStatus::Unsupported
                }
            }
        })?;
        if !go_on {
            break;
        }
        session.watch_peers()?;
        crate::telemetry::set_step(Some(step));
        let window = StepWindow {
            checkpoint,
            ..StepWindow::of(scene, step)
        };
        let t = Instant::now();
        solver.step_alone(&window)?;
        let compute = t.elapsed();
        opts.checkpoint(scene, session.role, &window, || solver.save())?;
        publish_summary(session, &mut summary_pub, &window, &solver.report(), compute, Duration::ZERO)?;
        if let Some(v) = &mut viewer {
            v.offer(session, &window, &*solver)?;
        }
    }
    Ok(())
}

/// Sends this participant's summary of one step.
pub fn publish_summary<T: Transport>(
    session: &Session<'_, T>,
    summary_pub: &mut T::Publisher<Summary, StepHeader>,
    window: &StepWindow,
    r: &SolverReport,
    compute: Duration,
    wait: Duration,
) -> anyhow::Result<()> {
    let summary = Summary {
        role: session.role as u32,
        status: 0,
        step: window.step,
        time: window.time + window.dt,
        n_items: r.n_items,
        n_nodes: r.n_nodes,
        mass: r.mass,
        momentum: r.momentum,
        kinetic_energy: r.kinetic_energy,
        checksum: r.checksum,
        compute_ns: compute.as_nanos() as u64,
        wait_ns: wait.as_nanos() as u64,
    };
    let header = session.header(window.step, window.time, window.dt);
    summary_pub.publish(1, |h, out| {
        *h = header;
        out[0] = summary;
    })?;
    Ok(())
}

/// How long the time owner keeps its ports after acknowledging a stop.
const ACK_LINGER: Duration = Duration::from_millis(300);

/// The time owner's side of the control service: commands in, acknowledgements out, and
/// the pause state.
pub struct RunClock<T: Transport> {
    control: T::Subscriber<Control, StepHeader>,
    ack: T::Publisher<Ack, StepHeader>,
    paused: bool,
}

impl<T: Transport> RunClock<T> {
    pub fn open(session: &Session<'_, T>) -> anyhow::Result<Self> {
        Ok(RunClock {
            control: session.subscriber(&names::CONTROL)?,
            ack: session.publisher(&names::ACK, 1)?,
            paused: false,
        })
    }

    /// The launcher is connected (its control publisher and acknowledgement subscriber).
    pub fn connected(&mut self) -> bool {
        self.control.publisher_count() >= 1 && self.ack.subscriber_count() >= 1
    }

    /// Applies pending control commands after macro-step `done`, acknowledging each
    /// (`snapshot`, `set` and `checkpoint` through `apply`); while paused, blocks on the control service
    /// (with liveness checks). Returns `false` when the run must stop before the next step.
    pub fn obey(&mut self, session: &Session<'_, T>, done: u64, mut apply: impl FnMut(&Control) -> AckStatus) -> anyhow::Result<bool> {
        loop {
            let timeout = if self.paused { crate::session::POLL } else { Duration::ZERO };
            match self.control.receive(timeout, |_, c| c.first().copied())? {
                Some(Some(c)) => {
                    let status = match Command::from_code(c.command) {
                        Some(Command::Stop | Command::Pause | Command::Resume) => AckStatus::Applied,
                        Some(Command::Snapshot | Command::Set | Command::Checkpoint) => apply(&c),
                        None => AckStatus::UnknownCommand,
                    };
                    let header = session.header(done, 0.0, 0.0);
                    self.ack.publish(1, |h, out| {
                        *h = header;
                        out[0] = Ack {
                            seq: c.seq,
                            step: done,
                            command: c.command,
                            status: status as u32,
                            key: c.key,
                            _pad: 0,
                        };
                    })?;
                    match Command::from_code(c.command) {
                        Some(Command::Stop) => {
                            // iceoryx2 drops a message still queued when its publisher goes
                            // away: stay until the launcher and the bridge (which poll every
                            // 50 and 20 ms) have taken this acknowledgement.
                            std::thread::sleep(ACK_LINGER);
                            return Ok(false);
                        }
                        Some(Command::Pause) => self.paused = true,
                        Some(Command::Resume) => self.paused = false,
                        _ => {}
                    }
                }
                Some(None) => {}
                None if self.paused => session.check_alive("a resume command")?,
                None => return Ok(true),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use grains_transport::inproc::InProc;

    /// Issue 20: a step begin whose header carries the checksum of its payload (as the spec
    /// allows every sender to) is accepted, one with a wrong checksum is refused. The solvers
    /// used to check the checksum against an empty payload, so only a 0 got through.
    #[test]
    fn a_step_begin_with_its_checksum_is_accepted_and_a_wrong_one_refused() {
        let bus = InProc::new();
        let session = Session::unadmitted(&bus, Role::Dem, "test-run").unwrap();
        let mut step_pub = bus.publisher::<StepBegin, StepHeader>(&names::STEP_BEGIN, 1).unwrap();
        let mut step_sub = session.subscriber::<StepBegin, StepHeader>(&names::STEP_BEGIN).unwrap();
        let begin = StepBegin { flags: 0, substeps: 7 };
        let mut send = |step: u64, checksum: Option<u64>| {
            let header = session.header(step, 0.5, 1e-3);
            step_pub
                .publish(1, |h, out| {
                    out[0] = begin;
                    *h = header;
                    h.sender = Role::Coupler as u32;
                    h.checksum = checksum.unwrap_or_else(|| checksum_bytes(as_bytes(out)));
                })
                .unwrap();
        };
        send(3, None);
        let window = next_step(&session, &mut step_sub).unwrap().expect("a step, not a stop");
        assert_eq!((window.step, window.substeps), (3, 7));
        assert_ne!(checksum_bytes(as_bytes(&[begin])), 0, "the test must send a non-zero checksum");
        send(4, Some(0x1234));
        let err = next_step(&session, &mut step_sub).unwrap_err().to_string();
        assert!(err.contains("checksum"), "{err}");
    }
}
