//! `grains run`: one run from scene file to outputs.
//!
//! The launcher owns the run (STYLE §2.2 invariant 5): it creates the run id and the
//! iceoryx2 domain, opens the admission, summary and control services before any participant
//! exists, starts only the participants the scene needs ([`participants`]), admits them
//! ([`admission`]: protocol version, scene, role), releases them all at once, writes one
//! metrics row per macro-step from their summaries, supervises them ([`supervisor`]: a
//! participant that dies is named within a second and the others are stopped), and cleans up
//! every file of the run at the end ([`outputs`], [`crate::metrics`]).

mod admission;
pub mod bridge;
pub mod outputs;
pub mod participants;
mod progress;
pub mod resume;
pub mod steps;
mod supervisor;

use anyhow::{Context, bail};
use bridge::Bridge;
use grains_bridge::config::BridgeArgs;
use grains_protocol::Role;
use grains_protocol::scene::Scene;
use grains_service::signals::StopFlag;
use grains_transport::{inproc::InProc, ipc};
use outputs::{write_atomic, write_summary};
use participants::{Participants, Processes, Threads};
use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime};
use supervisor::Supervisor;

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum TransportKind {
    /// Separate processes exchanging over iceoryx2 shared memory.
    Ipc,
    /// Threads of the launcher's process (same participants, same protocol).
    Inproc,
    /// Separate processes exchanging over zenoh (TCP) through the launcher: a participant
    /// may run on another host (`--external ROLE`, joined with `--zenoh ENDPOINT`).
    Zenoh,
}

#[derive(Clone, Debug)]
pub struct RunOptions {
    pub scene_path: PathBuf,
    pub transport: TransportKind,
    /// Participants the launcher does not start: it waits for them to attach.
    pub external: Vec<Role>,
    /// Outputs go to `<out_root>/<scene name>/<run id>/`.
    pub out_root: PathBuf,
    /// Live progress on stderr.
    pub progress: bool,
    /// `--set key=value` overrides of the scene (applied before validation).
    pub overrides: Vec<String>,
    /// Say on stderr what the run is (id, output directory, participants) and how it ended.
    pub announce: bool,
    /// Start the zenoh bridge with these flags.
    pub bridge: Option<BridgeArgs>,
    /// With `--transport zenoh`: the endpoint the launcher's zenoh router listens on
    /// (default a free loopback port); participants connect to it.
    pub zenoh_listen: Option<String>,
    /// Continue the run in this directory from its last complete checkpoint (`grains resume`):
    /// its own copy of the scene is the scene; `scene_path` and `overrides` are not read.
    pub resume: Option<PathBuf>,
}

impl RunOptions {
    /// A run started from code (validate, benches): iceoryx2 processes, no bridge, nothing
    /// said on stderr.
    pub fn quiet(scene_path: PathBuf, out_root: PathBuf, overrides: Vec<String>) -> Self {
        RunOptions {
            scene_path,
            transport: TransportKind::Ipc,
            external: Vec::new(),
            out_root,
            progress: false,
            overrides,
            announce: false,
            bridge: None,
            zenoh_listen: None,
            resume: None,
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Status {
    Completed,
    Failed,
    Interrupted,
    /// Ended early by a `stop` control command (from the bridge).
    Stopped,
}

impl Status {
    pub fn exit_code(self) -> u8 {
        match self {
            Status::Completed | Status::Stopped => 0,
            Status::Failed => 1,
            Status::Interrupted => 130,
        }
    }
    pub fn as_str(self) -> &'static str {
        match self {
            Status::Completed => "completed",
            Status::Failed => "failed",
            Status::Interrupted => "interrupted",
            Status::Stopped => "stopped",
        }
    }
}

#[derive(Clone, Debug)]
pub struct RunOutcome {
    pub run_id: String,
    pub dir: PathBuf,
    pub status: Status,
    pub message: String,
    pub steps_done: u64,
    /// Wall time from the release of the participants to the last metrics row.
    pub stepping: Duration,
}

/// Bad input to `grains run` (exit code 2), apart from scene errors.
#[derive(Debug)]
pub struct BadInput(pub String);

/// What the solvers need of a physics scene, checked before anything starts: the participants
/// this build can run, then each solver's own checks (time steps against their limits).
pub fn check_physics(scene: &Scene) -> anyhow::Result<()> {
    let roles = scene.participants();
    match roles.as_slice() {
        [Role::Dem] => grains_dem_service::check_scene(scene)?,
        [Role::Mpm] => grains_mpm_service::check_scene(scene)?,
        [Role::Dem, Role::Mpm, Role::Coupler, Role::Oracle] => {
            grains_dem_service::check_scene(scene)?;
            grains_mpm_service::check_scene(scene)?;
            grains_oracle_service::check_scene(scene)?;
        }
        // Rigid bodies and a continuum, in contact.
        [Role::Dem, Role::Mpm, Role::Coupler] => {
            grains_dem_service::check_scene(scene)?;
            grains_mpm_service::check_scene(scene)?;
        }
        _ => {
            let list: Vec<_> = roles.iter().map(|r| r.name()).collect();
            bail!(BadInput(format!(
                "{}: this scene needs {}; this build runs DEM-only, MPM-only, hybrid and rigid-body–continuum scenes",
                scene.path.display(),
                list.join(", ")
            )));
        }
    }
    Ok(())
}

/// What a scene sets that its run will not use: an `[oracle]` table where no oracle starts
/// (a run with no grains or no continuum; kept valid, since a hybrid scene run as a DEM or a
/// continuum by `--set body.N.model=...` keeps its table).
pub fn unused(scene: &Scene) -> Option<String> {
    let oracle = scene.participants().contains(&Role::Oracle);
    (scene.oracle.is_some() && !oracle).then(|| {
        format!(
            "{}: [oracle] is not used: this scene starts no oracle (it runs where grains meet a continuum: a hybrid body, or DEM and MPM bodies together)",
            scene.path.display()
        )
    })
}

/// Hybrid bodies whose grains stand on the setup's lattice (no `packing` file) at a packing
/// fraction other than their continuum's: per volume the discrete part then weighs less than
/// the points it is coupled to (the lattice keeps the largest grains apart: about 0.65 for
/// 1-mm grains of σ 0.04 mm, against a continuum's 0.82).
pub fn lattice_density(scene: &Scene) -> Vec<String> {
    // A shear-band hybrid starts as a continuum: its grains come from the oracle's packing.
    if scene
        .oracle
        .as_ref()
        .is_some_and(|o| o.kind == grains_protocol::scene::OracleKind::ShearBand)
    {
        return Vec::new();
    }
    scene
        .bodies
        .iter()
        .enumerate()
        .filter(|(_, b)| b.model == grains_protocol::scene::Model::Hybrid && b.packing.is_none())
        .filter_map(|(k, b)| {
            let m = &scene.materials[b.material];
            let (dem, mpm) = (m.dem.as_ref()?, m.mpm.as_ref()?);
            let lattice = grains_dem_service::setup::lattice_packing(dem, scene.dim());
            ((lattice / mpm.packing - 1.0).abs() > 0.05).then(|| {
                format!(
                    "{}: body.{k}: its grains are built on a lattice at packing {lattice:.3} and its continuum is at {}: per volume \
                     the discrete part is {:.0}% {} than the points it is coupled to (`grains pack` a bed and name it in \
                     body.{k}.packing for grains as dense as the continuum)",
                    scene.path.display(),
                    mpm.packing,
                    100.0 * (1.0 - lattice / mpm.packing).abs(),
                    if lattice < mpm.packing { "lighter" } else { "heavier" }
                )
            })
        })
        .collect()
}

/// `grains check`: validates a scene file and the solvers' checks of it, and says what a
/// run would start.
pub fn check(path: &Path) -> anyhow::Result<()> {
    let (s, text, chosen) = steps::load(path, &[])?;
    if let Some(c) = chosen {
        println!("{}: {c}", path.display());
    }
    if s.synthetic.is_none() {
        check_physics(&s)?;
    }
    if let Some(note) = unused(&s) {
        println!("{note}");
    }
    for note in lattice_density(&s) {
        println!("{note}");
    }
    let roles: Vec<_> = s.participants().iter().map(|r| r.binary()).collect();
    println!(
        "{}: ok: scene {:?}, {}D, {} steps of {} s; starts {}",
        path.display(),
        s.name,
        s.dim(),
        s.steps,
        s.dt,
        roles.join(", ")
    );
    // Rigid bodies: what the shape gives (a typo in a vertex shows as a mass far off).
    for (k, r) in s.rigids.iter().enumerate() {
        use grains_dem::space::{D2, Space};
        let vertices: Vec<_> = r.vertices.iter().map(|&[x, y]| D2::from_array([x, y, 0.0])).collect();
        let props = grains_dem::bodies::mass_properties(&vertices, r.radius);
        let rho = s.materials[r.material].density;
        println!(
            "{}: rigid.{k}: {}, {} vertices swept by {} m: mass {:.4e} kg/m, moment of inertia {:.4e} kg m, centre of mass ({:.6}, {:.6}) m",
            path.display(),
            format!("{:?}", r.motion).to_lowercase(),
            r.vertices.len(),
            r.radius,
            rho * props.area,
            rho * props.second_moment,
            props.centroid.x,
            props.centroid.y
        );
    }
    if let Some((limit, k, m)) = grains_dem_service::setup::contact_step(&s) {
        println!(
            "{}: rigid bodies meet the material points by contact (r_p = {:.4e} m): macro-step {} s of at most {limit:.3e} s \
             (Jiang 2020 eq. 51, k_n = {k:.4e} N/m, the lighter side of a contact {m:.4e} kg)",
            path.display(),
            s.contact_radius(),
            s.dt
        );
    }
    if let Some(n) = crate::cost::counts(&s, &text)? {
        let (hybrid, dem) = crate::cost::predict(&crate::cost::MEASURED, &n);
        println!(
            "{}: predicted wall time on this kind of machine: hybrid {hybrid:.0} s ({} grains, {} points at the start, k = {}), \
             pure DEM {dem:.0} s ({} grains, same DEM step): {}",
            path.display(),
            n.hybrid_grains,
            n.points,
            n.substeps,
            n.all_grains,
            if hybrid < dem {
                format!("run it as hybrid ({:.1}x)", dem / hybrid)
            } else {
                format!("the pure DEM is cheaper ({:.1}x)", hybrid / dem)
            }
        );
        // The model counts the zones the run starts with; an adaptive oracle turns flowing
        // material discrete (the shipped column: 1,001 grains to 2,005 in 20 ms).
        if let Some(o) = s.oracle.as_ref().filter(|o| o.kind.adaptive()) {
            println!(
                "{}: the prediction counts the starting zones only: the {} oracle (every {} steps{}) moves them as the \
                 material flows, and where it turns the flow discrete the hybrid costs up to the pure DEM's, plus its MPM",
                path.display(),
                o.kind.name(),
                o.every,
                if o.max_inertial > 0.0 {
                    format!(", discrete above I = {:e}", o.max_inertial)
                } else {
                    String::new()
                }
            );
        }
    }
    Ok(())
}

impl std::fmt::Display for BadInput {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for BadInput {}

/// A new run id: UTC date and time plus 16 random bits, e.g. `20261122-013502-9f3a`.
pub fn new_run_id() -> String {
    let now = SystemTime::now().duration_since(SystemTime::UNIX_EPOCH).unwrap_or_default();
    let noise = (now.subsec_nanos() as u64 ^ ((std::process::id() as u64) << 20)).wrapping_mul(0x9e37_79b9_7f4a_7c15) >> 48;
    format!("{}-{noise:04x}", crate::clock::Utc::from_unix(now.as_secs()).compact())
}

/// Runs a scene to the end (or to a failure or Ctrl-C) and writes its outputs; or, with
/// [`RunOptions::resume`], continues a run from its last complete checkpoint.
pub fn run(opts: &RunOptions) -> anyhow::Result<RunOutcome> {
    let (scene, text, resume, held) = match &opts.resume {
        None => {
            let (scene, text, chosen) = steps::load(&opts.scene_path, &opts.overrides)?;
            if let Some(c) = chosen
                && opts.announce
            {
                tracing::info!("{c}");
            }
            (scene, text, None, None)
        }
        Some(dir) => {
            let (scene, text, _) = steps::load(&dir.join("scene.toml"), &[])?;
            let lock = resume::lock(dir)?;
            let resume = resume::prepare(dir, &scene)?;
            grains_service::checkpoint::share(&lock).with_context(|| format!("{}: run.lock", dir.display()))?;
            (scene, text, Some(resume), Some(lock))
        }
    };
    let roles = scene.participants();
    if scene.synthetic.is_none() {
        check_physics(&scene)?;
    }
    if let Some(note) = unused(&scene) {
        tracing::warn!("{note}");
    }
    for note in lattice_density(&scene) {
        tracing::warn!("{note}");
    }
    for e in &opts.external {
        if !roles.contains(e) {
            let list: Vec<_> = roles.iter().map(|r| r.name()).collect();
            bail!(BadInput(format!(
                "--external {e}: the scene has no {e} participant (it runs: {})",
                list.join(", ")
            )));
        }
    }
    if opts.transport == TransportKind::Inproc && !opts.external.is_empty() {
        bail!(BadInput(
            "--external needs --transport ipc or zenoh: an external participant is another process".into()
        ));
    }
    if opts.transport != TransportKind::Zenoh && opts.zenoh_listen.is_some() {
        bail!(BadInput("--zenoh-listen needs --transport zenoh".into()));
    }
    let zenoh_endpoint = match opts.transport {
        TransportKind::Zenoh => Some(match &opts.zenoh_listen {
            Some(e) => e.clone(),
            None => free_loopback_endpoint()?,
        }),
        _ => None,
    };
    let bridge_args = bridge_args(opts, &scene);
    let bridge_cfg = match &bridge_args {
        Some(args) => Some(args.resolve().map_err(|e| BadInput(format!("{e:#}")))?),
        None => None,
    };
    // A launcher killed outright (SIGKILL) leaves its run's files in /dev/shm.
    for (dead, files) in ipc::remove_dead_runs() {
        if opts.announce {
            tracing::info!("removed {} files left by run {dead}, whose processes are all gone", files.len());
        }
    }
    // A resumed run has a run id of its own (its transport is new), in the old directory.
    let run_id = new_run_id();
    let dir = match &resume {
        Some(r) => r.run_dir.clone(),
        None => opts.out_root.join(&scene.name).join(&run_id),
    };
    let scene_copy = dir.join("scene.toml");
    if resume.is_none() {
        std::fs::create_dir_all(&dir).with_context(|| format!("creating the output directory {}", dir.display()))?;
        // The exact scene of the run (overrides applied, file paths made absolute) sits beside
        // its outputs; every participant reads this copy.
        write_atomic(&scene_copy, text.as_bytes()).with_context(|| format!("writing {}", scene_copy.display()))?;
    }
    // Held to the end: a `grains resume` of this directory meanwhile is refused.
    let _lock = match held {
        Some(l) => l,
        None => grains_service::checkpoint::hold(&dir, false)
            .with_context(|| format!("{}: run.lock", dir.display()))?
            .with_context(|| format!("{}: run.lock is held exclusively by another grains", dir.display()))?,
    };
    let scene_path = std::fs::canonicalize(&scene_copy).with_context(|| format!("resolving {}", scene_copy.display()))?;

    let started = SystemTime::now();
    let ctx = RunCtx {
        scene: &scene,
        scene_path: &scene_path,
        roles: &roles,
        run_id: &run_id,
        dir: &dir,
        opts,
        resume: resume.as_ref(),
        zenoh: zenoh_endpoint.as_deref(),
    };
    let resume_dir = resume.as_ref().map(|r| r.checkpoint.as_path());
    // The participants as processes (iceoryx2 or zenoh), `extra` arguments to each.
    let spawn = |extra: &[String]| -> anyhow::Result<Box<dyn Participants>> {
        let external_timeout = if opts.external.is_empty() { 60.0 } else { 0.0 };
        let spawned: Vec<Role> = roles.iter().copied().filter(|r| !opts.external.contains(r)).collect();
        let p = Processes::spawn(&spawned, &scene_path, &run_id, &dir, external_timeout, resume_dir, extra)?;
        Ok(Box::new(p))
    };
    let (report, participants) = match opts.transport {
        TransportKind::Ipc => {
            let transport = ipc::Iceoryx2::join(&run_id, Role::Launcher.binary(), StopFlag::with_signals().as_cancel())?;
            let bridge = || match &bridge_args {
                Some(args) => Bridge::spawn_process(args, &scene, &scene_path, &run_id, &dir, &[]).map(Some),
                None => Ok(None),
            };
            let result = Supervisor::start(&transport, &ctx, bridge, || spawn(&[])).and_then(Supervisor::run);
            drop(transport);
            ipc::remove_run_files(&run_id);
            result?
        }
        TransportKind::Zenoh => {
            let listen = zenoh_endpoint.as_deref().expect("set for zenoh");
            let transport = grains_transport::zenoh::Zenoh::router(&run_id, Role::Launcher.binary(), listen)?;
            let connect = ["--zenoh".to_string(), local_connect(listen)];
            let bridge = || match &bridge_args {
                Some(args) => Bridge::spawn_process(args, &scene, &scene_path, &run_id, &dir, &connect).map(Some),
                None => Ok(None),
            };
            Supervisor::start(&transport, &ctx, bridge, || spawn(&connect))?.run()?
        }
        TransportKind::Inproc => {
            let bus = InProc::new();
            let bridge = || match &bridge_cfg {
                Some(cfg) => Bridge::spawn_thread(cfg, &bus, &scene, &run_id, &dir).map(Some),
                None => Ok(None),
            };
            Supervisor::start(&bus, &ctx, bridge, || {
                Ok(Box::new(Threads::spawn(&roles, &scene, &run_id, &dir, &bus, resume_dir)?) as Box<dyn Participants>)
            })?
            .run()?
        }
    };
    write_summary(&ctx, &report, participants, started)?;
    Ok(report)
}

/// `tcp/127.0.0.1:<a port that was free a moment ago>`.
fn free_loopback_endpoint() -> anyhow::Result<String> {
    let l = std::net::TcpListener::bind("127.0.0.1:0").context("finding a free port for the zenoh router")?;
    Ok(format!("tcp/127.0.0.1:{}", l.local_addr()?.port()))
}

/// Where a participant on the launcher's own host connects to a router listening on
/// `listen`: the same endpoint, but loopback for an unspecified address.
fn local_connect(listen: &str) -> String {
    listen.replace("/0.0.0.0:", "/127.0.0.1:").replace("/[::]:", "/[::1]:")
}

/// The bridge's flags: asked for on the command line, or by the scene's `[bridge]` table. The
/// scene's settings file is the base; flags on the command line override it.
fn bridge_args(opts: &RunOptions, scene: &Scene) -> Option<BridgeArgs> {
    match (&opts.bridge, &scene.bridge) {
        (Some(args), b) => Some(BridgeArgs {
            config: args.config.clone().or_else(|| b.as_ref().and_then(|b| b.settings.clone())),
            ..args.clone()
        }),
        (None, Some(b)) => Some(BridgeArgs {
            config: b.settings.clone(),
            ..BridgeArgs::default()
        }),
        (None, None) => None,
    }
}

/// What every part of the launcher needs to know of the run.
struct RunCtx<'a> {
    scene: &'a Scene,
    scene_path: &'a Path,
    roles: &'a [Role],
    run_id: &'a str,
    dir: &'a Path,
    opts: &'a RunOptions,
    /// What a resumed run continues from.
    resume: Option<&'a resume::Resumed>,
    /// The zenoh router's endpoint (`--transport zenoh`).
    zenoh: Option<&'a str>,
}

#[cfg(test)]
mod tests {
    /// A hybrid scene's `[oracle]` is used; the same scene run as a DEM keeps the table
    /// (valid) but starts no oracle, and `unused` says so.
    #[test]
    fn an_oracle_table_without_an_oracle_is_reported() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/column_collapse_hybrid_2d.toml");
        let (hybrid, ..) = super::steps::load(&path, &[]).unwrap();
        assert!(hybrid.oracle.is_some());
        assert_eq!(super::unused(&hybrid), None);
        let (dem, ..) = super::steps::load(&path, &["body.0.model=\"dem\"".into()]).unwrap();
        let note = super::unused(&dem).expect("a note");
        assert!(note.contains("[oracle] is not used"), "{note}");
    }

    /// The quickstart's hybrid column builds its grains on the lattice (packing 0.652) beside
    /// a continuum at 0.82, and is told so; the plate's hybrid starts as a continuum and takes
    /// its grains from a poured bed (the shear-band oracle's packing), and is not.
    #[test]
    fn a_hybrid_body_on_a_looser_lattice_than_its_continuum_is_reported() {
        let scenes = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
        let (quick, ..) = super::steps::load(&scenes.join("quickstart_hybrid_2d.toml"), &[]).unwrap();
        let notes = super::lattice_density(&quick);
        assert_eq!(notes.len(), 1, "{notes:?}");
        assert!(
            notes[0].contains("body.0") && notes[0].contains("packing 0.652") && notes[0].contains("20% lighter"),
            "{}",
            notes[0]
        );
        let (plate, ..) = super::steps::load(&scenes.join("plate_indentation_hybrid_2d.toml"), &[]).unwrap();
        assert!(super::lattice_density(&plate).is_empty());
    }
}
