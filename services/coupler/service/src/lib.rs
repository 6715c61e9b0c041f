//! The grains-coupler participant: the time owner of a coupled run.
//!
//! Each macro-step: obey control commands → publish step begin → receive the DEM and the
//! MPM raster (checked: run, step, version, checksum, order) → constrain the shared nodes in
//! place into the loaned velocity message (`grains_coupler::constrain`) → publish → summary.
//! After the last step (or a stop command) it publishes a step begin with the stop flag.

use anyhow::bail;
use grains_protocol::names;
use grains_protocol::wire::{
    AckStatus, Command, Control, NodeVelocity, Param, RasterNode, STEP_CHECKPOINT, STEP_STOP, StepBegin, StepHeader, Summary,
};
use grains_protocol::{Role, checksum::checksum_bytes, scene::Scene};
use grains_service::session::Session;
use grains_service::solver::{ParticipantOptions, RunClock, SolverReport, StepWindow, join, publish_summary, set_component};
use grains_transport::{Publisher, Subscriber, Transport, as_bytes};
use std::time::{Duration, Instant};

/// Runs the coupler to the end of the run: the macro-steps above, then the stop.
pub fn run<T: Transport>(transport: &T, scene: &Scene, opts: &ParticipantOptions) -> anyhow::Result<()> {
    let mut session = join(transport, Role::Coupler, scene, opts)?;
    let mut ports = Ports::<T>::open(&session)?;
    // The solvers, and the oracle when the run has one, follow the steps.
    let step_subscribers = 2 + usize::from(scene.participants().contains(&Role::Oracle));
    session.wait_until("the DEM, the MPM, the oracle and the launcher", |_| {
        ports.connected(step_subscribers)
    })?;
    session.ready()?;

    // The coupler carries nothing from one step to the next: its checkpoint is empty, and a
    // resumed run just starts after the checkpoint's step.
    let mut last = opts.start_after();
    for step in last + 1..=scene.steps {
        session.watch_peers()?;
        grains_service::telemetry::set_step(Some(step));
        if !ports.obey(&session, scene, opts, step)? {
            break;
        }
        let window = StepWindow {
            checkpoint: std::mem::take(&mut ports.checkpoint_next),
            ..StepWindow::of(scene, step)
        };
        let header = session.header(step, window.time, window.dt);
        ports.begin_step(header, &window, opts.checksums)?;
        let wait_start = Instant::now();
        let (report, compute) = ports.couple(&session, step, header, opts.checksums)?;
        let wait = wait_start.elapsed() - compute;
        opts.checkpoint(scene, Role::Coupler, &window, || Ok(Vec::new()))?;
        publish_summary(&session, &mut ports.summary_pub, &window, &report, compute, wait)?;
        last = step;
    }
    ports.stop(&session, scene, last)
}

/// The coupler's ports. (Fields in the reverse of the order they are opened in: they close
/// in the order they did as the loop's locals, the control service last.)
struct Ports<T: Transport> {
    summary_pub: T::Publisher<Summary, StepHeader>,
    vel_pub: T::Publisher<NodeVelocity, StepHeader>,
    step_pub: T::Publisher<StepBegin, StepHeader>,
    mpm_sub: T::Subscriber<RasterNode, StepHeader>,
    dem_sub: T::Subscriber<RasterNode, StepHeader>,
    /// Commands forwarded to the solvers.
    command_pub: T::Publisher<Control, StepHeader>,
    clock: RunClock<T>,
    /// A `checkpoint` command was accepted: the next step begin says so.
    checkpoint_next: bool,
}

impl<T: Transport> Ports<T> {
    fn open(session: &Session<'_, T>) -> anyhow::Result<Self> {
        let clock = RunClock::open(session)?;
        let command_pub = session.publisher::<Control, StepHeader>(&names::COMMAND, 1)?;
        let dem_sub = session.subscriber::<RasterNode, StepHeader>(&names::DEM_RASTER)?;
        let mpm_sub = session.subscriber::<RasterNode, StepHeader>(&names::MPM_RASTER)?;
        let step_pub = session.publisher::<StepBegin, StepHeader>(&names::STEP_BEGIN, 1)?;
        let vel_pub = session.publisher::<NodeVelocity, StepHeader>(&names::VELOCITIES, 1024)?;
        let summary_pub = session.publisher::<Summary, StepHeader>(&names::SUMMARY, 1)?;
        Ok(Ports {
            summary_pub,
            vel_pub,
            step_pub,
            mpm_sub,
            dem_sub,
            command_pub,
            clock,
            checkpoint_next: false,
        })
    }

    /// The launcher, both solvers and `step_subscribers` followers of the steps are connected.
    fn connected(&mut self, step_subscribers: usize) -> bool {
        self.clock.connected()
            && self.dem_sub.publisher_count() >= 1
            && self.mpm_sub.publisher_count() >= 1
            && self.step_pub.subscriber_count() >= step_subscribers
            && self.command_pub.subscriber_count() >= 2
            && self.vel_pub.subscriber_count() >= 2
            && self.summary_pub.subscriber_count() >= 1
    }

    /// The control commands before `step`, acknowledged at step − 1. Snapshot and set act on
    /// the solvers' state: checked here ([`accepts`]), carried out by both solvers before the
    /// next step. Returns `false` when the run must stop.
    fn obey(&mut self, session: &Session<'_, T>, scene: &Scene, opts: &ParticipantOptions, step: u64) -> anyhow::Result<bool> {
        let command_pub = &mut self.command_pub;
        let checkpoint_next = &mut self.checkpoint_next;
        let mut forward = Ok(());
        // The solvers read forwarded commands only at the next step begin: never more than
        // the service holds, or the coupler would wait for them while they wait for it.
        let mut forwarded = 0;
        let go_on = self.clock.obey(session, step - 1, |c| {
            // Every participant checkpoints after the next step: its begin carries the flag.
            if Command::from_code(c.command) == Some(Command::Checkpoint) {
                *checkpoint_next = opts.out_dir.is_some();
                return if *checkpoint_next {
                    AckStatus::Applied
                } else {
                    AckStatus::Unsupported
                };
            }
            if !accepts(scene, c) {
                return AckStatus::Unsupported;
            }
            if forwarded == names::COMMAND.buffer {
                return AckStatus::Busy;
            }
            forwarded += 1;
            let header = session.header(step - 1, 0.0, 0.0);
            let sent = command_pub.publish(1, |h, out| {
                *h = header;
                out[0] = *c;
            });
            if let Err(e) = sent {
                forward = Err(e);
            }
            AckStatus::Applied
        })?;
        forward?;
        Ok(go_on)
    }

    /// The step begin of `window`, with its DEM substeps.
    fn begin_step(&mut self, header: StepHeader, window: &StepWindow, checksums: bool) -> anyhow::Result<()> {
        self.step_pub.publish(1, |h, out| {
            *h = header;
            out[0] = StepBegin {
                flags: if window.checkpoint { STEP_CHECKPOINT } else { 0 },
                substeps: window.substeps,
            };
            if checksums {
                h.checksum = checksum_bytes(as_bytes(out));
            }
        })?;
        Ok(())
    }

    /// Receives the DEM and the MPM raster of `step` (checked: run, step, version, checksum,
    /// order), constrains the shared nodes in place into the loaned velocity message
    /// ([`grains_coupler::constrain`]) and publishes it. Returns the step's report and the
    /// time the solve took.
    fn couple(
        &mut self,
        session: &Session<'_, T>,
        step: u64,
        header: StepHeader,
        checksums: bool,
    ) -> anyhow::Result<(SolverReport, Duration)> {
        let (mpm_sub, vel_pub) = (&mut self.mpm_sub, &mut self.vel_pub);
        let mut compute = Duration::ZERO;
        let mut report = SolverReport::default();
        session.recv(&mut self.dem_sub, "the DEM raster", |dh, dem| -> anyhow::Result<()> {
            session.recv(mpm_sub, "the MPM raster", |mh, mpm| -> anyhow::Result<()> {
                let t = Instant::now();
                session.check_message(&names::DEM_RASTER, dh, step, dem)?;
                session.check_message(&names::MPM_RASTER, mh, step, mpm)?;
                for (raster, spec) in [(dem, &names::DEM_RASTER), (mpm, &names::MPM_RASTER)] {
                    if let Some((at, node)) = grains_coupler::first_unsorted(raster) {
                        bail!(
                            "{}: step {step}: node indices must increase strictly; element {at} is node {node}",
                            spec.name
                        );
                    }
                }
                let n = grains_coupler::count_shared(dem, mpm);
                vel_pub.publish(n, |h, out| {
                    let r = grains_coupler::constrain(dem, mpm, out);
                    *h = header;
                    if checksums {
                        h.checksum = checksum_bytes(as_bytes(out));
                    }
                    report = SolverReport {
                        n_items: r.shared_nodes,
                        n_nodes: (dem.len() + mpm.len()) as u64,
                        mass: r.mass,
                        momentum: r.momentum_after,
                        kinetic_energy: r.kinetic_energy_after,
                        checksum: h.checksum,
                    };
                })?;
                compute = t.elapsed();
                Ok(())
            })?
        })??;
        Ok((report, compute))
    }

    /// After the last step taken (`last`) or a stop command: the step begin with the stop flag.
    fn stop(&mut self, session: &Session<'_, T>, scene: &Scene, last: u64) -> anyhow::Result<()> {
        let header = session.header(last + 1, last as f64 * scene.dt, scene.dt);
        self.step_pub.publish(1, |h, out| {
            *h = header;
            out[0] = StepBegin {
                flags: STEP_STOP,
                substeps: 0,
            };
        })?;
        Ok(())
    }
}

/// Whether both solvers of this run can carry out a `snapshot` or `set` command (both have
/// every scene wall).
fn accepts(scene: &Scene, c: &Control) -> bool {
    match Command::from_code(c.command) {
        Some(Command::Snapshot) => true,
        Some(Command::Set) => Param::from_code(c.key).is_some_and(|p| {
            let (lo, hi, _) = p.range();
            let exists = match p {
                Param::Gravity { .. } => true,
                Param::WallVelocity { wall, .. } => wall < scene.walls.len(),
            };
            (lo..=hi).contains(&c.value) && exists && set_component([0.0; 3], scene.dim(), p, c.value).is_ok()
        }),
        _ => false,
    }
}
