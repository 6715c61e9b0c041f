//! Every service name of a run, one function each (the only place they are spelled).
//!
//! Runs are isolated by the iceoryx2 domain prefix `grains_<run-id>_` (see
//! [`domain_prefix`]), not by the names, so the names are the same in every run. Each data
//! service is paired with an event service of the same name: the publisher notifies after
//! every send, the subscribers block on it.

/// iceoryx2 `config.global.prefix` of a run: every shared-memory segment, socket and node file
/// of the run starts with it, which is how a run is cleaned up and how two runs never meet.
pub fn domain_prefix(run_id: &str) -> String {
    format!("grains_{run_id}_")
}

/// Participant → launcher: who I am, which protocol I speak. Version-independent layout.
pub const HELLO: ServiceSpec = ServiceSpec {
    name: "grains/run/hello",
    max_publishers: 8,
    max_subscribers: 1,
    buffer: 8,
    overflow: false,
};
/// Launcher → participants: accepted or refused, and why. Version-independent layout.
pub const WELCOME: ServiceSpec = ServiceSpec {
    name: "grains/run/welcome",
    max_publishers: 1,
    max_subscribers: 8,
    buffer: 8,
    overflow: false,
};
/// Launcher (later the bridge) → time owner: pause, resume, stop, snapshot, set.
pub const CONTROL: ServiceSpec = ServiceSpec {
    name: "grains/run/control",
    max_publishers: 2,
    max_subscribers: 1,
    buffer: 16,
    overflow: false,
};
/// Time owner → launcher and bridge: what became of each control command.
pub const ACK: ServiceSpec = ServiceSpec {
    name: "grains/run/ack",
    max_publishers: 1,
    max_subscribers: 2,
    buffer: 16,
    overflow: false,
};
/// Every participant → launcher (and the bridge): one summary per macro-step.
pub const SUMMARY: ServiceSpec = ServiceSpec {
    name: "grains/run/summary",
    max_publishers: 6,
    max_subscribers: 2,
    buffer: 64,
    overflow: false,
};
/// The shortest turn of a loop that reads [`SUMMARY`] (the launcher's, the bridge's): woken
/// by every summary, each took a tenth of a core from a run of 2,000 steps a second (`grains
/// bench bridge`); in turns of 2 ms they drain what came meanwhile, and the 64 summaries a
/// queue holds keep up with 32,000 steps a second (the fastest handshake measured: 13,000
/// over iceoryx2) before a participant would wait.
pub const SUMMARY_READ_TURN: std::time::Duration = std::time::Duration::from_millis(2);
/// Time owner → solvers: begin macro-step n (or stop).
pub const STEP_BEGIN: ServiceSpec = ServiceSpec {
    name: "grains/step/begin",
    max_publishers: 1,
    max_subscribers: 3,
    buffer: 2,
    overflow: false,
};
/// Time owner → solvers of a coupled run: `snapshot` and `set` commands, applied before the
/// step whose begin follows them.
pub const COMMAND: ServiceSpec = ServiceSpec {
    name: "grains/step/command",
    max_publishers: 1,
    max_subscribers: 3,
    buffer: 16,
    overflow: false,
};
/// DEM → bridge: a decimated view of the grains, a few times a second, latest only.
pub const DEM_VIEW: ServiceSpec = ServiceSpec {
    name: "grains/dem/view",
    max_publishers: 1,
    max_subscribers: 1,
    buffer: 1,
    overflow: true,
};
/// MPM → bridge: a decimated view of the material points, a few times a second, latest only.
pub const MPM_VIEW: ServiceSpec = ServiceSpec {
    name: "grains/mpm/view",
    max_publishers: 1,
    max_subscribers: 1,
    buffer: 1,
    overflow: true,
};
/// DEM → coupler: predicted momentum and mass on grid nodes.
pub const DEM_RASTER: ServiceSpec = ServiceSpec {
    name: "grains/dem/raster",
    max_publishers: 1,
    max_subscribers: 1,
    buffer: 2,
    overflow: false,
};
/// MPM → coupler: phase-1 momentum and mass on grid nodes.
pub const MPM_RASTER: ServiceSpec = ServiceSpec {
    name: "grains/mpm/raster",
    max_publishers: 1,
    max_subscribers: 1,
    buffer: 2,
    overflow: false,
};
/// Coupler → DEM and MPM: constrained node velocities.
pub const VELOCITIES: ServiceSpec = ServiceSpec {
    name: "grains/coupler/velocities",
    max_publishers: 1,
    max_subscribers: 2,
    buffer: 2,
    overflow: false,
};
/// Oracle → solvers: the zone of every grid cell that is not discrete (at start and at
/// every epoch).
pub const ZONES: ServiceSpec = ServiceSpec {
    name: "grains/oracle/zones",
    max_publishers: 1,
    max_subscribers: 2,
    buffer: 2,
    overflow: false,
};
/// Oracle → DEM: grains to create.
pub const SPAWN_GRAINS: ServiceSpec = ServiceSpec {
    name: "grains/oracle/spawn_grains",
    max_publishers: 1,
    max_subscribers: 1,
    buffer: 2,
    overflow: false,
};
/// Oracle → MPM: material points to create.
pub const SPAWN_POINTS: ServiceSpec = ServiceSpec {
    name: "grains/oracle/spawn_points",
    max_publishers: 1,
    max_subscribers: 1,
    buffer: 2,
    overflow: false,
};
/// Oracle → DEM: ids of grains to delete.
pub const DELETE_GRAINS: ServiceSpec = ServiceSpec {
    name: "grains/oracle/delete_grains",
    max_publishers: 1,
    max_subscribers: 1,
    buffer: 2,
    overflow: false,
};
/// Oracle → MPM: ids of material points to delete.
pub const DELETE_POINTS: ServiceSpec = ServiceSpec {
    name: "grains/oracle/delete_points",
    max_publishers: 1,
    max_subscribers: 1,
    buffer: 2,
    overflow: false,
};
/// Oracle → MPM: material points whose mass and volume change by a factor.
pub const SCALE_POINTS: ServiceSpec = ServiceSpec {
    name: "grains/oracle/scale_points",
    max_publishers: 1,
    max_subscribers: 1,
    buffer: 2,
    overflow: false,
};
/// DEM → oracle: every grain, at an oracle epoch (after the step).
pub const DEM_EPOCH: ServiceSpec = ServiceSpec {
    name: "grains/dem/epoch",
    max_publishers: 1,
    max_subscribers: 1,
    buffer: 2,
    overflow: false,
};
/// DEM → oracle: the grains' homogenized stress per grid node, at an oracle epoch.
pub const DEM_STRESS: ServiceSpec = ServiceSpec {
    name: "grains/dem/stress",
    max_publishers: 1,
    max_subscribers: 1,
    buffer: 2,
    overflow: false,
};
/// MPM → oracle: every material point, at an oracle epoch.
pub const MPM_EPOCH: ServiceSpec = ServiceSpec {
    name: "grains/mpm/epoch",
    max_publishers: 1,
    max_subscribers: 1,
    buffer: 2,
    overflow: false,
};
/// DEM → MPM: the rigid bodies' reach at the start of each step (scenes with rigid bodies
/// and a continuum).
pub const BODY_REACH: ServiceSpec = ServiceSpec {
    name: "grains/dem/body_reach",
    max_publishers: 1,
    max_subscribers: 1,
    buffer: 2,
    overflow: false,
};
/// MPM → DEM: the material points within the bodies' reach.
pub const CONTACT_POINTS: ServiceSpec = ServiceSpec {
    name: "grains/mpm/contact_points",
    max_publishers: 1,
    max_subscribers: 1,
    buffer: 2,
    overflow: false,
};
/// DEM → MPM: the bodies' contact force on each of those points for the step.
pub const POINT_FORCES: ServiceSpec = ServiceSpec {
    name: "grains/dem/point_forces",
    max_publishers: 1,
    max_subscribers: 1,
    buffer: 2,
    overflow: false,
};

/// A service and its quality of service. Every participant opens a service with exactly
/// these limits (iceoryx2 refuses an opener whose limits exceed the creator's).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ServiceSpec {
    pub name: &'static str,
    pub max_publishers: usize,
    pub max_subscribers: usize,
    /// Messages a subscriber may have queued per publisher before the publisher waits.
    pub buffer: usize,
    /// Instead of waiting, the publisher overwrites the oldest queued message (views for
    /// remote viewers: a slow reader must never hold up a solver).
    pub overflow: bool,
}

/// Every service of a run, for the spec and for cleanup.
pub const ALL: [ServiceSpec; 24] = [
    HELLO,
    WELCOME,
    CONTROL,
    ACK,
    COMMAND,
    DEM_VIEW,
    MPM_VIEW,
    SUMMARY,
    STEP_BEGIN,
    DEM_RASTER,
    MPM_RASTER,
    VELOCITIES,
    ZONES,
    SPAWN_GRAINS,
    SPAWN_POINTS,
    DELETE_GRAINS,
    DELETE_POINTS,
    SCALE_POINTS,
    DEM_EPOCH,
    DEM_STRESS,
    MPM_EPOCH,
    BODY_REACH,
    CONTACT_POINTS,
    POINT_FORCES,
];

/// Node name of a participant in the iceoryx2 node list (`grains-dem`, …): what a survivor
/// reports when it finds a dead node.
pub fn node_name(role: crate::Role) -> &'static str {
    role.binary()
}
