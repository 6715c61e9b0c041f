//! Wire types: `#[repr(C)]`, fixed-size integers and floats only, little-endian, no implicit
//! padding (explicit `_pad` fields), so that a participant in C or Python can read them.
//! Sizes and offsets are pinned by `tests/layout.rs` and written in `protocol/README.md`.
//!
//! Every data service carries a slice of one element type as payload and a [`StepHeader`]
//! as iceoryx2 user header. Only [`Hello`] and [`Welcome`] (the admission handshake) have no
//! user header: their layout never changes, so that a participant of another protocol version
//! can still be told why it is refused.

#[cfg(feature = "zero-copy")]
use iceoryx2::prelude::ZeroCopySend;

macro_rules! wire_type {
    ($(#[$meta:meta])* $name:literal, pub struct $ty:ident { $($(#[$fmeta:meta])* pub $field:ident : $fty:ty,)* }) => {
        $(#[$meta])*
        #[derive(Clone, Copy, Debug, Default, PartialEq)]
        #[cfg_attr(feature = "zero-copy", derive(ZeroCopySend), type_name($name))]
        #[repr(C)]
        pub struct $ty { $($(#[$fmeta])* pub $field: $fty,)* }
    };
}

wire_type! {
    /// User header of every data service. 80 bytes.
    "grains.StepHeader.v1",
    pub struct StepHeader {
        /// [`crate::PROTOCOL_VERSION`] of the sender.
        pub protocol_version: u32,
        /// [`crate::Role`] code of the sender.
        pub sender: u32,
        /// Macro-step this message belongs to (the first step is 1; 0 for messages sent
        /// before the first step, such as a zone field at start).
        pub step: u64,
        /// Simulated time at the start of the step [s].
        pub time: f64,
        /// Macro-step length [s].
        pub dt: f64,
        /// [`crate::checksum`] of the payload bytes, or 0 when not computed.
        pub checksum: u64,
        /// Meaning per service (see `protocol/README.md`); 0 when unused.
        pub flags: u64,
        /// Run id, ASCII, zero-padded.
        pub run_id: [u8; 32],
    }
}

wire_type! {
    /// Admission request, participant → launcher on [`crate::names::HELLO`]. 64 bytes.
    "grains.Hello",
    pub struct Hello {
        /// [`crate::HELLO_MAGIC`].
        pub magic: u64,
        /// [`crate::scene::Scene::hash`] of the scene file the participant loaded.
        pub scene_hash: u64,
        pub protocol_version: u32,
        /// [`crate::Role`] code.
        pub role: u32,
        pub pid: u32,
        /// 0: admission request; 1 ([`HELLO_READY`]): every port connected, ready to start.
        pub flags: u32,
        pub run_id: [u8; 32],
    }
}

/// [`Hello::flags`] of a participant's second hello.
pub const HELLO_READY: u32 = 1;

wire_type! {
    /// Admission answer, launcher → participants on [`crate::names::WELCOME`]; a participant
    /// reads only the answer with its own `role` and `pid`. 64 bytes.
    "grains.Welcome",
    pub struct Welcome {
        pub magic: u64,
        /// The run's scene hash.
        pub scene_hash: u64,
        /// The run's protocol version.
        pub protocol_version: u32,
        pub role: u32,
        pub pid: u32,
        /// [`Verdict`] code.
        pub verdict: u32,
        pub run_id: [u8; 32],
    }
}

/// Launcher's answer to a [`Hello`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u32)]
pub enum Verdict {
    Accepted = 0,
    WrongProtocolVersion = 1,
    WrongScene = 2,
    RoleNotInRun = 3,
    RoleTaken = 4,
    /// Broadcast (role 0, pid 0) once every participant is ready: the run starts.
    Start = 100,
}

impl Verdict {
    pub fn from_code(code: u32) -> Option<Verdict> {
        use Verdict::*;
        [Accepted, WrongProtocolVersion, WrongScene, RoleNotInRun, RoleTaken, Start]
            .into_iter()
            .find(|v| *v as u32 == code)
    }
}

wire_type! {
    /// Time owner → solvers on [`crate::names::STEP_BEGIN`], one element. 8 bytes.
    /// Step, time and dt are in the header.
    "grains.StepBegin.v1",
    pub struct StepBegin {
        /// Bit set of `STEP_*` flags.
        pub flags: u32,
        /// DEM substeps per macro-step (Yue 2018 Alg. 2).
        pub substeps: u32,
    }
}

/// [`StepBegin::flags`]: the run is over; do not step, finish and exit 0.
pub const STEP_STOP: u32 = 1;
/// [`StepBegin::flags`]: write a checkpoint after this step (a `checkpoint` command), as on
/// the scene's own checkpoint steps.
pub const STEP_CHECKPOINT: u32 = 2;

wire_type! {
    /// One grid node of a sparse raster (DEM or MPM → coupler). 40 bytes.
    /// Nodes of one raster are sorted by strictly increasing `node`.
    "grains.RasterNode.v1",
    pub struct RasterNode {
        /// Linear index of the grid node.
        pub node: u64,
        /// Weighted mass on the node [kg] (2D: kg per metre of thickness).
        pub mass: f64,
        /// Weighted momentum on the node [kg m/s]; the third component is 0 in 2D.
        pub momentum: [f64; 3],
    }
}

wire_type! {
    /// One constrained node velocity (coupler → DEM and MPM). 32 bytes, sorted by `node`.
    "grains.NodeVelocity.v1",
    pub struct NodeVelocity {
        pub node: u64,
        /// [m/s]; the third component is 0 in 2D.
        pub velocity: [f64; 3],
    }
}

wire_type! {
    /// Zone of one grid cell (oracle → solvers). 24 bytes.
    "grains.ZoneCell.v1",
    pub struct ZoneCell {
        pub cell: u64,
        /// [`Zone`] code.
        pub zone: u32,
        pub _pad: u32,
        /// Signed distance to the discrete/continuum interface [m] (negative inside the
        /// discrete side).
        pub distance: f64,
    }
}

/// Model of a zone (Yue 2018 §4.1).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u32)]
pub enum Zone {
    Continuum = 0,
    Hybrid = 1,
    Discrete = 2,
}

impl Zone {
    /// The zone of a wire code (`ZoneCell::zone`).
    pub fn from_code(code: u32) -> Option<Zone> {
        [Zone::Continuum, Zone::Hybrid, Zone::Discrete]
            .into_iter()
            .find(|&z| z as u32 == code)
    }
}

wire_type! {
    /// A grain to create (oracle → DEM). 64 bytes.
    "grains.SpawnGrain.v1",
    pub struct SpawnGrain {
        pub id: u64,
        /// [m]
        pub radius: f64,
        /// [m]
        pub position: [f64; 3],
        /// [m/s]
        pub velocity: [f64; 3],
    }
}

wire_type! {
    /// A material point to create (oracle → MPM). 120 bytes.
    "grains.SpawnPoint.v1",
    pub struct SpawnPoint {
        pub id: u64,
        /// [m³] (2D: m² per metre of thickness)
        pub volume: f64,
        /// [kg]
        pub mass: f64,
        pub position: [f64; 3],
        pub velocity: [f64; 3],
        /// Cauchy stress [Pa], Voigt order xx, yy, zz, yz, xz, xy.
        pub stress: [f64; 6],
    }
}

wire_type! {
    /// A grain (DEM → oracle) or a material point (MPM → oracle) at an oracle epoch. 112 bytes.
    "grains.EpochItem.v3",
    pub struct EpochItem {
        pub id: u64,
        /// Grain radius [m]; 0 for a material point.
        pub radius: f64,
        /// Full (unweighted) mass [kg] (2D: per metre).
        pub mass: f64,
        /// The share of the mass the solver counts: 1, or 1 − w (grains) / w (points) in a
        /// hybrid cell.
        pub share: f64,
        /// Bit 0 ([`EPOCH_FIXED`]): a frozen grain, part of the scene's fixed boundary (never
        /// deleted or weighed; new grains must not overlap it).
        pub flags: u64,
        pub position: [f64; 3],
        pub velocity: [f64; 3],
        /// A point's accumulated plastic strain and its rate over the last step [1/s], the
        /// shear-band oracle's inputs (Chen 2021 Alg. 1); 0 for a grain and for a model
        /// without plasticity.
        pub plastic_strain: f64,
        pub plastic_rate: f64,
        /// A point's pressure [Pa], compression positive (the mean of the principal Cauchy
        /// stresses, negated); 0 for a grain. Kinematic training brings the grains it makes
        /// to the pressure of the points they replace.
        pub pressure: f64,
    }
}

wire_type! {
    /// A material point whose mass and volume the MPM multiplies by `factor` (oracle → MPM,
    /// at an epoch: the cell's mass stays what it was). 16 bytes.
    "grains.PointScale.v1",
    pub struct PointScale {
        pub id: u64,
        pub factor: f64,
    }
}

/// [`EpochItem::flags`]: a frozen grain.
pub const EPOCH_FIXED: u64 = 1;

wire_type! {
    /// The grains' homogenized stress on one grid node (DEM → oracle, Yue 2018 Alg. 11).
    /// 56 bytes.
    "grains.NodeStress.v1",
    pub struct NodeStress {
        pub node: u64,
        /// Cauchy stress [Pa], tension positive, Voigt order xx, yy, zz, yz, xz, xy.
        pub stress: [f64; 6],
    }
}

wire_type! {
    /// One participant's account of one macro-step (every participant → launcher). 104 bytes.
    "grains.Summary.v1",
    pub struct Summary {
        /// [`crate::Role`] code.
        pub role: u32,
        /// 0 = ok; otherwise a [`SummaryStatus`] code.
        pub status: u32,
        pub step: u64,
        /// Simulated time at the end of the step [s].
        pub time: f64,
        /// Grains (DEM), material points (MPM) or zone nodes (coupler).
        pub n_items: u64,
        /// Raster nodes sent (DEM, MPM) or received (coupler).
        pub n_nodes: u64,
        /// Total mass [kg].
        pub mass: f64,
        /// Total linear momentum [kg m/s].
        pub momentum: [f64; 3],
        /// Kinetic energy [J].
        pub kinetic_energy: f64,
        /// Checksum of what this participant sent this step (0 if none).
        pub checksum: u64,
        /// Wall time spent computing this step [ns] (a timing column: varies run to run).
        pub compute_ns: u64,
        /// Wall time spent waiting for peers this step [ns] (timing column).
        pub wait_ns: u64,
    }
}

/// [`Summary::status`] codes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u32)]
pub enum SummaryStatus {
    Ok = 0,
    /// The participant stops after this summary (a numerical failure, reported on stderr).
    Failed = 1,
}

wire_type! {
    /// A command to the time owner (launcher or bridge → time owner). 24 bytes.
    "grains.Control.v1",
    pub struct Control {
        /// Sender's sequence number, echoed in acknowledgements.
        pub seq: u64,
        /// [`Command`] code.
        pub command: u32,
        /// Parameter key of `Set` (0 otherwise).
        pub key: u32,
        /// Value of `Set`.
        pub value: f64,
    }
}

/// [`Control::command`] codes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u32)]
pub enum Command {
    Pause = 1,
    Resume = 2,
    Stop = 3,
    Snapshot = 4,
    Set = 5,
    /// Checkpoint after the next step (the time owner flags that step's begin).
    Checkpoint = 6,
}

impl Command {
    pub const ALL: [Command; 6] = [
        Command::Pause,
        Command::Resume,
        Command::Stop,
        Command::Snapshot,
        Command::Set,
        Command::Checkpoint,
    ];

    pub fn from_code(code: u32) -> Option<Command> {
        Command::ALL.into_iter().find(|c| *c as u32 == code)
    }

    /// Lower-case name, as remote clients spell it (`pause`, `set`, …).
    pub fn name(self) -> &'static str {
        match self {
            Command::Pause => "pause",
            Command::Resume => "resume",
            Command::Stop => "stop",
            Command::Snapshot => "snapshot",
            Command::Set => "set",
            Command::Checkpoint => "checkpoint",
        }
    }
}

wire_type! {
    /// What became of a [`Control`] (time owner → launcher and bridge on
    /// [`crate::names::ACK`]). 32 bytes.
    "grains.Ack.v1",
    pub struct Ack {
        /// [`Control::seq`] of the command.
        pub seq: u64,
        /// The last macro-step completed when the command took effect (or was refused).
        pub step: u64,
        /// [`Command`] code as received.
        pub command: u32,
        /// [`AckStatus`] code.
        pub status: u32,
        /// [`Control::key`] as received.
        pub key: u32,
        pub _pad: u32,
    }
}

/// A parameter a `set` command may change. On the wire ([`Control::key`]): gravity 1 + axis;
/// the translation velocity of scene wall `w` 16 + 4 w + axis (axis 0, 1, 2 = x, y, z).
/// Remote clients spell them `gravity.y`, `wall.2.velocity.x`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Param {
    Gravity { axis: usize },
    WallVelocity { wall: usize, axis: usize },
}

const AXES: [&str; 3] = ["x", "y", "z"];

impl Param {
    pub fn from_code(code: u32) -> Option<Param> {
        let code = code as usize;
        match code {
            1..=3 => Some(Param::Gravity { axis: code - 1 }),
            16.. if (code - 16) % 4 < 3 => Some(Param::WallVelocity {
                wall: (code - 16) / 4,
                axis: (code - 16) % 4,
            }),
            _ => None,
        }
    }

    pub fn code(self) -> u32 {
        (match self {
            Param::Gravity { axis } => 1 + axis,
            Param::WallVelocity { wall, axis } => 16 + 4 * wall + axis,
        }) as u32
    }

    pub fn name(self) -> String {
        match self {
            Param::Gravity { axis } => format!("gravity.{}", AXES[axis]),
            Param::WallVelocity { wall, axis } => format!("wall.{wall}.velocity.{}", AXES[axis]),
        }
    }

    /// The parameter a client names (`gravity.y`, `wall.0.velocity.x`).
    pub fn parse(name: &str) -> Option<Param> {
        let axis = |a: &str| AXES.iter().position(|x| *x == a);
        let parts: Vec<&str> = name.split('.').collect();
        match parts.as_slice() {
            ["gravity", a] => Some(Param::Gravity { axis: axis(a)? }),
            ["wall", w, "velocity", a] if w.bytes().all(|b| b.is_ascii_digit()) && w.len() <= 4 => Some(Param::WallVelocity {
                wall: w.parse().ok()?,
                axis: axis(a)?,
            }),
            _ => None,
        }
    }

    /// Allowed values (inclusive) and their unit.
    pub fn range(self) -> (f64, f64, &'static str) {
        match self {
            Param::Gravity { .. } => (-100.0, 100.0, "m/s²"),
            Param::WallVelocity { .. } => (-10.0, 10.0, "m/s"),
        }
    }

    /// The axis the parameter acts along.
    pub fn axis(self) -> usize {
        match self {
            Param::Gravity { axis } | Param::WallVelocity { axis, .. } => axis,
        }
    }
}

wire_type! {
    /// One grain or material point of a view for remote viewers (DEM or MPM → bridge on
    /// [`crate::names::DEM_VIEW`] / [`crate::names::MPM_VIEW`]). 72 bytes. The header's
    /// `flags` holds the solver's total count (the view is every k-th item).
    "grains.ViewPoint.v2",
    pub struct ViewPoint {
        pub id: u64,
        pub position: [f64; 3],
        pub velocity: [f64; 3],
        /// Radius of a grain; half the spacing of a material point [m].
        pub size: f64,
        /// Pressure −tr σ / d [Pa], positive in compression: a material point's, or a
        /// grain's Love–Weber mean stress over its volume; NaN where the solver does not say.
        pub pressure: f64,
    }
}

wire_type! {
    /// A rigid body's reach (DEM → MPM at the start of every step of a scene with rigid bodies
    /// and a continuum, Jiang 2020 §4): no part of the body is farther than `reach` from
    /// `center`. 40 bytes.
    "grains.BodyReach.v1",
    pub struct BodyReach {
        pub id: u64,
        /// [m]; the third component is 0 in 2D.
        pub center: [f64; 3],
        /// [m]
        pub reach: f64,
    }
}

wire_type! {
    /// A material point within a body's reach plus its contact radius (MPM → DEM, Jiang 2020
    /// §4: an "identified material point", a disk of radius `radius` to the body's contact
    /// law). 80 bytes, sorted by `index`.
    "grains.ContactPoint.v1",
    pub struct ContactPoint {
        /// The point's index in the sender's arrays this step: [`PointForce::index`] echoes it.
        pub index: u64,
        /// The point's id (stable over the run: the contact's history is kept by it).
        pub id: u64,
        /// [m]
        pub position: [f64; 3],
        /// [m/s]
        pub velocity: [f64; 3],
        /// [kg] (2D: per metre); the point's full mass.
        pub mass: f64,
        /// Contact radius r_p [m] (Jiang 2020 eq. 44–45).
        pub radius: f64,
    }
}

wire_type! {
    /// The bodies' contact force on one material point over the coming step (DEM → MPM,
    /// Jiang 2020 eq. 46–48); its reaction acts on the bodies. 32 bytes, sorted by `index`.
    "grains.PointForce.v1",
    pub struct PointForce {
        /// [`ContactPoint::index`] of the point.
        pub index: u64,
        /// [N] (2D: N per metre); the third component is 0 in 2D.
        pub force: [f64; 3],
    }
}

/// [`Ack::status`] codes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u32)]
pub enum AckStatus {
    /// Took effect after [`Ack::step`].
    Applied = 0,
    /// A command code this time owner does not know.
    UnknownCommand = 1,
    /// A known command this run's participants cannot carry out.
    Unsupported = 2,
    /// Too many commands at once (between two steps, or while paused): not applied, retry.
    Busy = 3,
}

impl AckStatus {
    pub fn from_code(code: u32) -> Option<AckStatus> {
        use AckStatus::*;
        [Applied, UnknownCommand, Unsupported, Busy].into_iter().find(|c| *c as u32 == code)
    }
}
