//! The grains-oracle participant: decides which grid cells are discrete, hybrid or continuum
//! and tells the solvers over `grains/oracle/zones`.
//!
//! In this build the zones are layered from the scene (Yue 2018 §4.3,
//! [`grains_service::zones::ZoneField::layered`]) and fixed to the material: the oracle sends
//! the field once, before the first step (header step 0), then follows the steps so that it
//! ends with the run and accounts for itself in `metrics.csv` (items: cells of the field,
//! nodes: hybrid cells). The adaptive oracle replaces how the field is computed and sends
//! changes every `oracle.every` steps.

use anyhow::bail;
use grains_protocol::names;
use grains_protocol::scene::{OracleKind, Scene};
use grains_protocol::wire::{StepBegin, StepHeader, Summary, ZoneCell};
use grains_protocol::{Role, checksum::checksum_bytes};
use grains_service::solver::{ParticipantOptions, SolverReport, join, next_step, publish_summary};
use grains_service::zones::{Layer, ZoneField};
use grains_transport::{Publisher, Subscriber, Transport, as_bytes};
use std::time::{Duration, Instant};

/// Checks what the oracle needs of a scene: the kinds of oracle this build has.
pub fn check_scene(scene: &Scene) -> Result<(), grains_protocol::scene::SceneError> {
    match scene.oracle.as_ref().map(|o| o.kind) {
        None | Some(OracleKind::Fixed) => Ok(()),
        Some(kind) => {
            let kind = if kind == OracleKind::Layered { "layered" } else { "surface" };
            Err(grains_protocol::scene::SceneError {
                path: scene.path.clone(),
                line_col: None,
                field: Some("oracle.kind".into()),
                message: format!(
                    "\"{kind}\" zones (moving with the flow) are not in this build; allowed: \"fixed\" (layered from the scene at start, kept by the material)"
                ),
            })
        }
    }
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
    session.wait_until("the DEM, the MPM, the coupler and the launcher", |_| {
        zones_pub.subscriber_count() >= 2 && step_sub.publisher_count() >= 1 && summary_pub.subscriber_count() >= 1
    })?;
    // Both solvers are subscribed: they build their grains and points from this field before
    // they declare themselves ready.
    let header = session.header(0, 0.0, scene.dt);
    zones_pub.publish(cells.len(), |h, out| {
        out.copy_from_slice(cells);
        *h = header;
        if opts.checksums {
            h.checksum = checksum_bytes(as_bytes(out));
        }
    })?;
    session.ready()?;

    let report = SolverReport {
        n_items: cells.len() as u64,
        n_nodes: field.count(Layer::Hybrid) as u64,
        ..SolverReport::default()
    };
    let mut compute = field_time;
    loop {
        let wait_start = Instant::now();
        let Some(window) = next_step(&session, &mut step_sub)? else {
            return Ok(());
        };
        publish_summary(&session, &mut summary_pub, &window, &report, compute, wait_start.elapsed())?;
        compute = Duration::ZERO;
    }
}
