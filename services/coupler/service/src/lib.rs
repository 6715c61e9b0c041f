//! The grains-coupler participant: the time owner of a coupled run.
//!
//! Each macro-step: obey control commands → publish step begin → receive the DEM and the
//! MPM raster (checked: run, step, version, checksum, order) → constrain the shared nodes in
//! place into the loaned velocity message (`grains_coupler::constrain`) → publish → summary.
//! After the last step (or a stop command) it publishes a step begin with the stop flag.

use anyhow::bail;
use grains_protocol::names;
use grains_protocol::wire::{AckStatus, Command, Control, NodeVelocity, Param, RasterNode, STEP_STOP, StepBegin, StepHeader, Summary};
use grains_protocol::{Role, checksum::checksum_bytes, scene::Scene};
use grains_service::solver::{ParticipantOptions, RunClock, SolverReport, StepWindow, join, publish_summary, set_component};
use grains_transport::{Publisher, Subscriber, Transport, as_bytes};
use std::time::Instant;

pub fn run<T: Transport>(transport: &T, scene: &Scene, opts: &ParticipantOptions) -> anyhow::Result<()> {
    let mut session = join(transport, Role::Coupler, scene, opts)?;
    let mut clock = RunClock::open(&session)?;
    let mut command_pub = session.publisher::<Control, StepHeader>(&names::COMMAND, 1)?;
    let mut dem_sub = session.subscriber::<RasterNode, StepHeader>(&names::DEM_RASTER)?;
    let mut mpm_sub = session.subscriber::<RasterNode, StepHeader>(&names::MPM_RASTER)?;
    let mut step_pub = session.publisher::<StepBegin, StepHeader>(&names::STEP_BEGIN, 1)?;
    let mut vel_pub = session.publisher::<NodeVelocity, StepHeader>(&names::VELOCITIES, 1024)?;
    let mut summary_pub = session.publisher::<Summary, StepHeader>(&names::SUMMARY, 1)?;
    // The solvers, and the oracle when the run has one, follow the steps.
    let step_subscribers = 2 + usize::from(scene.participants().contains(&Role::Oracle));
    session.wait_until("the DEM, the MPM, the oracle and the launcher", |_| {
        clock.connected()
            && dem_sub.publisher_count() >= 1
            && mpm_sub.publisher_count() >= 1
            && step_pub.subscriber_count() >= step_subscribers
            && command_pub.subscriber_count() >= 2
            && vel_pub.subscriber_count() >= 2
            && summary_pub.subscriber_count() >= 1
    })?;
    session.ready()?;

    let mut last = 0;
    for step in 1..=scene.steps {
        grains_service::telemetry::set_step(Some(step));
        // Snapshot and set act on the solvers' state: checked here, carried out by both
        // solvers before the next step.
        let mut forward = Ok(());
        // The solvers read forwarded commands only at the next step begin: never more than
        // the service holds, or the coupler would wait for them while they wait for it.
        let mut forwarded = 0;
        let go_on = clock.obey(&session, step - 1, |c| {
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
        if !go_on {
            break;
        }
        let window = StepWindow::of(scene, step);
        let header = session.header(step, window.time, window.dt);
        step_pub.publish(1, |h, out| {
            *h = header;
            out[0] = StepBegin {
                flags: 0,
                substeps: window.substeps,
            };
            if opts.checksums {
                h.checksum = checksum_bytes(as_bytes(out));
            }
        })?;

        let wait_start = Instant::now();
        let mut compute = std::time::Duration::ZERO;
        let mut report = SolverReport::default();
        session.recv(&mut dem_sub, "the DEM raster", |dh, dem| -> anyhow::Result<()> {
            session.recv(&mut mpm_sub, "the MPM raster", |mh, mpm| -> anyhow::Result<()> {
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
                    if opts.checksums {
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
        let wait = wait_start.elapsed() - compute;
        publish_summary(&session, &mut summary_pub, &window, &report, compute, wait)?;
        last = step;
    }
    let header = session.header(last + 1, last as f64 * scene.dt, scene.dt);
    step_pub.publish(1, |h, out| {
        *h = header;
        out[0] = StepBegin {
            flags: STEP_STOP,
            substeps: 0,
        };
    })?;
    Ok(())
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
