//! Scene schema v1: TOML in, a validated [`Scene`] out.
//!
//! Two levels (ripgrep's low-level/high-level args): [`raw`] mirrors the file with serde
//! (`deny_unknown_fields`, spans kept for every value that has a range), [`load`] checks
//! types, ranges and cross-references and derives what the run needs (its participants, its
//! time owner). Every error names the file, the line and column, the field and what is
//! allowed; see [`SceneError`]. The format is documented field by field in `scenes/README.md`.

use crate::Role;
use serde::Deserialize;
use std::ops::Range;
use std::path::{Path, PathBuf};
use toml::Spanned;

/// The only schema version this build reads.
pub const SCHEMA_VERSION: u32 = 1;

/// A scene file that cannot be used, with where and why.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneError {
    pub path: PathBuf,
    /// 1-based line and column, when the problem has a place in the file.
    pub line_col: Option<(usize, usize)>,
    /// Dotted field path (`domain.cell_size`), when known.
    pub field: Option<String>,
    /// What is wrong and what is allowed.
    pub message: String,
}

impl std::fmt::Display for SceneError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}", self.path.display())?;
        if let Some((line, col)) = self.line_col {
            write!(f, ":{line}:{col}")?;
        }
        if let Some(field) = &self.field {
            write!(f, ": field `{field}`")?;
        }
        write!(f, ": {}", self.message)
    }
}

impl std::error::Error for SceneError {}

/// Spatial dimension of a scene.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Dimension {
    Two = 2,
    Three = 3,
}

/// How a body of material is modelled at the start.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Model {
    Dem,
    Mpm,
    Hybrid,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Domain {
    /// Lower corner [m]; the third component is 0 in 2D.
    pub min: [f64; 3],
    /// Upper corner [m].
    pub max: [f64; 3],
    /// Background grid cell width [m] (MPM grid, rasters, oracle).
    pub cell_size: f64,
    /// Axes along which the domain wraps around.
    pub periodic: [bool; 3],
}

/// How grain contacts dissipate energy.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum DemDamping {
    /// Restitution coefficient e of a head-on impact, in [0, 1] (0: critically damped).
    Restitution(f64),
    /// Constant damping coefficient γ_n = γ_t [N s/m] (Chen 2021 Table 1).
    Viscous(f64),
}

/// Grain parameters (Yue 2018 §3.2, Chen 2021 §2.1 and Table 1).
#[derive(Clone, Debug, PartialEq)]
pub struct DemMaterial {
    /// Mean grain radius [m].
    pub radius: f64,
    /// Standard deviation of the radius [m] (normal distribution, clamped to ±2σ).
    pub radius_std: f64,
    /// Normal stiffness k_n [N/m].
    pub stiffness_normal: f64,
    /// Tangential stiffness k_t [N/m].
    pub stiffness_tangential: f64,
    /// Normal and tangential damping.
    pub damping: DemDamping,
    /// Coulomb friction coefficient μ.
    pub friction: f64,
    /// Normal cohesion e_n [N/m] (Chen 2021).
    pub cohesion_normal: f64,
    /// Tangential cohesion e_t [N/m].
    pub cohesion_tangential: f64,
}

/// The continuum's constitutive model.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum MpmModel {
    /// Yue 2018 §3.3: b^e elasticity, Drucker–Prager, volume-preserving return, free flow.
    DruckerPrager,
    /// Chen 2021 §2.2: Hencky elasticity, cohesive Drucker–Prager with critical-state
    /// softening: tan φ = tan φ_cs + χ (Φ − Φ_cs), dΦ/dt = −ξ Φ (Φ − Φ_cs) ‖ε̇^p‖.
    CriticalState {
        /// Critical packing fraction Φ_cs.
        packing_critical: f64,
        /// χ of eq. 7.
        chi: f64,
        /// ξ of eq. 8.
        xi: f64,
    },
}

/// Continuum parameters (Yue 2018 §3.3–3.4, Chen 2021 §2.2).
#[derive(Clone, Debug, PartialEq)]
pub struct MpmMaterial {
    pub model: MpmModel,
    /// Young's modulus [Pa].
    pub young: f64,
    /// Poisson's ratio, in [0, 0.5).
    pub poisson: f64,
    /// Friction angle [degrees] (the critical-state one, φ_cs, with `critical_state`).
    pub friction_angle: f64,
    /// Cohesion [Pa] (`critical_state` only).
    pub cohesion: f64,
    /// Initial packing fraction Φ0: the continuum's density is Φ0 × the material density.
    pub packing: f64,
}

/// How the MPM discretizes (the `[mpm]` table).
#[derive(Clone, Debug, PartialEq)]
pub struct MpmSettings {
    /// Points per cell along each axis (2 → 4 per cell in 2D, 8 in 3D).
    pub points_per_axis: u32,
    /// Shape functions: GIMP (Yue 2018) or quadratic B-splines.
    pub kernel: MpmKernel,
    /// Grid-to-point transfer: PIC/FLIP with this FLIP share β, or APIC when `None`.
    pub flip: Option<f64>,
    /// Condition on the three outer node layers of the domain faces.
    pub domain_walls: MpmDomainWalls,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MpmKernel {
    Gimp,
    Bspline,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MpmDomainWalls {
    Slip,
    Sticky,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    pub name: String,
    /// Density of the grain material [kg/m³].
    pub density: f64,
    pub dem: Option<DemMaterial>,
    pub mpm: Option<MpmMaterial>,
}

#[derive(Clone, Debug, PartialEq)]
pub enum Shape {
    Box {
        min: [f64; 3],
        max: [f64; 3],
    },
    /// A disk in 2D, a sphere in 3D.
    Ball {
        center: [f64; 3],
        radius: f64,
    },
}

#[derive(Clone, Debug, PartialEq)]
pub struct Body {
    /// Index into [`Scene::materials`].
    pub material: usize,
    pub model: Model,
    pub shape: Shape,
    /// A packing (LAMMPS data file, e.g. written by `grains pack`) whose grains inside the
    /// shape make up the body, instead of a fresh lattice. Relative to the scene file.
    pub packing: Option<PathBuf>,
    /// Grains that never move but push (a rough base of glued grains). DEM bodies only.
    pub frozen: bool,
    /// Confining pressure on the faces of a box of material points [Pa] (biaxial and triaxial
    /// tests). MPM box bodies only.
    pub confining_pressure: f64,
    /// Initial velocity of the body's grains and points [m/s].
    pub velocity: [f64; 3],
}

#[derive(Clone, Debug, PartialEq)]
pub enum WallShape {
    /// Half-space boundary through `point` with inward `normal` (unit).
    Plane { point: [f64; 3], normal: [f64; 3] },
    /// Material kept inside the box.
    Box { min: [f64; 3], max: [f64; 3] },
    /// Material kept inside a circle (2D) or a cylinder along z (3D).
    Drum { center: [f64; 3], radius: f64 },
    /// A line segment material cannot cross (silo bottoms, hoppers; a thin rod in 3D).
    Segment { from: [f64; 3], to: [f64; 3] },
}

#[derive(Clone, Debug, PartialEq)]
pub struct Wall {
    pub shape: WallShape,
    /// Coulomb friction between material and wall.
    pub friction: f64,
    /// Scripted translation velocity [m/s].
    pub velocity: [f64; 3],
    /// Scripted angular velocity of a drum about its axis [rad/s], counter-clockwise positive.
    pub spin: f64,
    /// Material sticks (MPM): no slip at all, whatever the friction.
    pub sticky: bool,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Coupling {
    /// DEM substeps per macro-step k (Yue 2018 Alg. 2).
    pub substeps: u32,
    /// MPM share w of the mass in the hybrid zone (DEM takes 1 − w).
    pub weight: f64,
    /// Layered zones of a hybrid body (Yue 2018 §4.3), fixed to the material: grains only
    /// within this depth [m] of the body's free faces (those not on a wall or the domain's edge)...
    pub discrete_layer: f64,
    /// ... then a band of this thickness [m] where grains and points overlap and are coupled;
    /// points only below it.
    pub hybrid_band: f64,
    /// How a hybrid grain takes the constrained velocities back.
    pub grain_transfer: GrainTransfer,
    /// With `"flip"`: the inertial number γ̇ √(d / |g|) of the material around a band grain
    /// (γ̇ its shear rate, d the grain's diameter) below which the grain turns with the
    /// material; above it the grain keeps its own spin and rolls. GDR MiDi (2004) put the
    /// quasi-static regime of dense flows at I < 1e-3; √(d / |g|) takes the pressure under one
    /// grain layer, so deeper in the band the true inertial number is smaller and grains start
    /// rolling at a smaller one (early rather than late). 0 never turns
    /// the grains (Yue 2018 couples translation only); without gravity they always roll.
    pub quasi_static: f64,
}

/// How a hybrid grain takes the coupler's node velocities back (Yue 2018 Alg. 5–6).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GrainTransfer {
    /// Alg. 5–6 as written: the grain's velocity becomes the interpolated node velocity (spin:
    /// half the curl) and it moves from its saved position with it. The band's grains move
    /// affinely with the grid: they stay put at rest, but cannot rearrange, and the band holds
    /// faces a granular material would not.
    Pic,
    /// The default. The grain keeps its substepped velocity and position and adds the
    /// coupling's change of the node velocities interpolated to it (times dt / 2 for the
    /// position); where the material is quasi-static (`quasi_static`) its spin is the
    /// material's, elsewhere its own. The substeps carry the last step's coupling force of the
    /// nodes around each grain, so the coupling acts with the contacts rather than as a kick
    /// after them: a resting band stays at rest and a flowing band rolls
    /// (`docs/validate/column_collapse.md`).
    Flip,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OracleKind {
    /// Zones given by the scene, never changed.
    Fixed,
    /// Zones from the depth below the top surface of the grains' packing fraction, column by
    /// column against gravity, every `every` steps (Yue 2018 §4.3: discrete only at the
    /// visible top; walls, floors and cavities stay continuum).
    Layered,
    /// Zones from the distance to the packing-fraction isocontour (Yue 2018 §4).
    Surface,
}

impl OracleKind {
    /// Whether the oracle moves the zones every `every` steps.
    pub fn adaptive(self) -> bool {
        matches!(self, OracleKind::Layered | OracleKind::Surface)
    }
}

#[derive(Clone, Debug, PartialEq)]
pub struct Oracle {
    pub kind: OracleKind,
    /// Macro-steps between oracle epochs.
    pub every: u64,
    /// `surface`: the packing fraction Φρ of the isocontour the zones are measured from.
    pub critical_packing: f64,
    /// `surface`: φ0, the distance inside the isocontour of the hybrid band's centre [m]
    /// (default `coupling.discrete_layer + hybrid_band / 2`, where the layered zones put it;
    /// very large: all discrete; very negative: all continuum).
    pub centre: Option<f64>,
    /// `surface`: r_h, the band's half-width [m] (default `coupling.hybrid_band / 2`).
    pub half_width: Option<f64>,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Output {
    /// Macro-steps between VTU frames; 0 writes none.
    pub frames_every: u64,
}

/// `[bridge]`: open every run of this scene to remote clients (as `grains run --bridge`).
#[derive(Clone, Debug, PartialEq)]
pub struct SceneBridge {
    /// The bridge settings file (listen, steering, rate, access control), if any.
    pub settings: Option<PathBuf>,
}

/// A test scene whose solvers publish synthetic rasters instead of physics (issue 2): it
/// proves the runtime with real payloads and real checks. Never part of a physics scene.
#[derive(Clone, Debug, PartialEq)]
pub struct Synthetic {
    pub participants: Vec<Role>,
    /// Nodes in the DEM raster before variation.
    pub dem_nodes: u64,
    /// Nodes in the MPM raster before variation.
    pub mpm_nodes: u64,
    /// Share of the smaller raster's nodes that both rasters contain, in [0, 1].
    pub overlap: f64,
    /// Raster lengths shrink by up to this share, differently every step, in [0, 0.9].
    pub vary: f64,
    /// Compute and verify payload checksums.
    pub checksum: bool,
    /// How node values are made: hashed (every bit depends on seed, step and node; the
    /// default) or plain (cheap arithmetic, for benchmarks that time the exchange itself).
    pub content: SyntheticContent,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SyntheticContent {
    Hashed,
    Plain,
}

/// A validated scene.
#[derive(Clone, Debug, PartialEq)]
pub struct Scene {
    pub path: PathBuf,
    /// Hash of the file bytes: every participant of a run must have loaded the same scene.
    pub hash: u64,
    pub name: String,
    pub dimension: Dimension,
    /// Macro-step [s].
    pub dt: f64,
    pub steps: u64,
    pub seed: u64,
    /// Worker threads per solver process.
    pub threads: u32,
    pub domain: Domain,
    /// [m/s²]; the third component is 0 in 2D.
    pub gravity: [f64; 3],
    pub materials: Vec<Material>,
    pub bodies: Vec<Body>,
    pub walls: Vec<Wall>,
    pub coupling: Coupling,
    pub mpm: MpmSettings,
    pub oracle: Option<Oracle>,
    pub output: Output,
    /// Start the zenoh bridge with every run (`[bridge] enabled = true`).
    pub bridge: Option<SceneBridge>,
    pub synthetic: Option<Synthetic>,
}

impl Scene {
    /// The participants this scene needs, in start order; nothing it does not need
    /// (a DEM-only scene starts no MPM, no coupler, no oracle).
    pub fn participants(&self) -> Vec<Role> {
        if let Some(s) = &self.synthetic {
            return s.participants.clone();
        }
        let has = |m: Model| self.bodies.iter().any(|b| b.model == m);
        let dem = has(Model::Dem) || has(Model::Hybrid);
        let mpm = has(Model::Mpm) || has(Model::Hybrid);
        let mut out = Vec::new();
        if dem {
            out.push(Role::Dem);
        }
        if mpm {
            out.push(Role::Mpm);
        }
        if dem && mpm {
            out.push(Role::Coupler);
        }
        // The oracle publishes the zone field of every coupled run, fixed or adaptive.
        if dem && mpm {
            out.push(Role::Oracle);
        }
        out
    }

    /// The participant that owns time: the coupler when there is one, else the only solver.
    pub fn time_owner(&self) -> Role {
        let parts = self.participants();
        if parts.contains(&Role::Coupler) { Role::Coupler } else { parts[0] }
    }

    /// Number of components that matter in vectors (2 or 3).
    pub fn dim(&self) -> usize {
        self.dimension as usize
    }

    /// Whether the adaptive oracle holds an epoch after macro-step `step` (every
    /// `oracle.every` steps of a run with a surface oracle and an oracle participant).
    pub fn epoch_after(&self, step: u64) -> bool {
        self.oracle
            .as_ref()
            .is_some_and(|o| o.kind.adaptive() && step.is_multiple_of(o.every))
            && self.participants().contains(&Role::Oracle)
    }
}

/// FNV-1a of the file bytes.
pub fn hash_bytes(bytes: &[u8]) -> u64 {
    bytes
        .iter()
        .fold(0xcbf2_9ce4_8422_2325u64, |h, &b| (h ^ b as u64).wrapping_mul(0x100_0000_01b3))
}

/// Reads and validates a scene file.
pub fn load(path: &Path) -> Result<Scene, SceneError> {
    let plain = |message: String| SceneError {
        path: path.to_path_buf(),
        line_col: None,
        field: None,
        message,
    };
    let bytes = std::fs::read(path).map_err(|e| plain(format!("cannot read the scene file: {e}")))?;
    let text = match std::str::from_utf8(&bytes) {
        Ok(t) => t,
        Err(e) => {
            return Err(plain(format!(
                "not a text file: invalid UTF-8 at byte {} (a scene is a TOML text file)",
                e.valid_up_to()
            )));
        }
    };
    from_str(text, path, hash_bytes(&bytes))
}

/// Reads a scene file, applies `--set key=value` overrides (dotted keys, list entries by
/// index: `body.0.max=[0.1, 0.2]`, values in TOML syntax) and validates the result. Returns the
/// scene and the effective text, which is what a run hands to its participants.
pub fn load_with_overrides(path: &Path, overrides: &[String]) -> Result<(Scene, String), SceneError> {
    let scene = load(path)?; // the file itself must be sound before it is edited
    let text = std::fs::read_to_string(path).map_err(|e| SceneError {
        path: path.into(),
        line_col: None,
        field: None,
        message: format!("cannot read the scene file: {e}"),
    })?;
    if overrides.is_empty() {
        return Ok((scene, text));
    }
    let err = |field: &str, message: String| SceneError {
        path: path.into(),
        line_col: None,
        field: Some(field.into()),
        message,
    };
    let mut doc = toml::Value::Table(text.parse::<toml::Table>().map_err(|e| err("", e.message().to_string()))?);
    for o in overrides {
        let Some((key, value)) = o.split_once('=') else {
            return Err(err(o, format!("--set {o:?}: expected key=value, e.g. coupling.substeps=20")));
        };
        let key = key.trim();
        let value = format!("v = {}", value.trim())
            .parse::<toml::Table>()
            .map_err(|e| err(key, format!("--set {o:?}: the value is not TOML: {}", e.message())))?
            .remove("v")
            .expect("parsed above");
        let parts: Vec<&str> = key.split('.').collect();
        set_path(&mut doc, &parts, value).map_err(|m| err(key, format!("--set {o:?}: {m}")))?;
    }
    let text = toml::to_string(&doc).map_err(|e| err("", format!("cannot write the overridden scene: {e}")))?;
    let scene = from_str(&text, path, hash_bytes(text.as_bytes())).map_err(|mut e| {
        e.message = format!("{} (after --set {})", e.message, overrides.join(" --set "));
        e.line_col = None;
        e
    })?;
    Ok((scene, text))
}

fn set_path(node: &mut toml::Value, parts: &[&str], value: toml::Value) -> Result<(), String> {
    let Some((first, rest)) = parts.split_first() else {
        return Err("empty key".into());
    };
    let child = match node {
        toml::Value::Table(t) => {
            if rest.is_empty() {
                t.insert(first.to_string(), value);
                return Ok(());
            }
            t.entry(first.to_string()).or_insert_with(|| toml::Value::Table(toml::Table::new()))
        }
        toml::Value::Array(a) => {
            let n = a.len();
            let idx: usize = first
                .parse()
                .map_err(|_| format!("`{first}` must be an index into a list of {n} entries"))?;
            let child = a
                .get_mut(idx)
                .ok_or_else(|| format!("index {idx} is out of range: the list has {n} entries"))?;
            if rest.is_empty() {
                *child = value;
                return Ok(());
            }
            child
        }
        _ => return Err(format!("`{first}` is inside a value, not a table or list")),
    };
    set_path(child, rest, value)
}

/// Validates scene text; `path` is only used in messages.
pub fn from_str(text: &str, path: &Path, hash: u64) -> Result<Scene, SceneError> {
    let ctx = Ctx { text, path };
    if text.trim().is_empty() {
        return Err(ctx.err(
            None,
            None,
            format!("the file is empty; a scene needs at least `schema = {SCHEMA_VERSION}`, [run] and [domain] (see scenes/README.md)"),
        ));
    }
    let raw: raw::RawScene = toml::from_str(text).map_err(|e| ctx.toml_error(&e))?;
    validate(&ctx, raw, hash)
}

struct Ctx<'a> {
    text: &'a str,
    path: &'a Path,
}

impl Ctx<'_> {
    fn line_col(&self, offset: usize) -> (usize, usize) {
        let before = &self.text[..offset.min(self.text.len())];
        let line = before.matches('\n').count() + 1;
        let col = before.len() - before.rfind('\n').map_or(0, |i| i + 1) + 1;
        (line, col)
    }

    fn err(&self, span: Option<Range<usize>>, field: Option<&str>, message: String) -> SceneError {
        SceneError {
            path: self.path.to_path_buf(),
            line_col: span.map(|s| self.line_col(s.start)),
            field: field.map(str::to_string),
            message,
        }
    }

    /// A serde/TOML error: keep its message, add the key written on the offending line.
    fn toml_error(&self, e: &toml::de::Error) -> SceneError {
        let span = e.span();
        let field = span.clone().and_then(|s| self.key_on_line_of(s.start));
        let message = e.message().trim().replace('\n', " ");
        SceneError {
            path: self.path.to_path_buf(),
            line_col: span.map(|s| self.line_col(s.start)),
            field,
            message,
        }
    }

    /// The dotted key written on the line of `offset`, prefixed by the table it sits in.
    fn key_on_line_of(&self, offset: usize) -> Option<String> {
        let start = self.text[..offset.min(self.text.len())].rfind('\n').map_or(0, |i| i + 1);
        let line = self.text[start..].lines().next()?;
        let (key, _) = line.split_once('=')?;
        let key = key.trim();
        let ok = !key.is_empty() && key.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '.' || c == '-');
        if !ok {
            return None;
        }
        let table = self.text[..start]
            .lines()
            .rev()
            .map(str::trim)
            .find(|l| l.starts_with('['))
            .map(|l| l.trim_matches(|c| c == '[' || c == ']').trim().to_string());
        Some(match table {
            Some(t) => format!("{t}.{key}"),
            None => key.to_string(),
        })
    }
}

fn vec3(ctx: &Ctx, dim: usize, v: &Spanned<Vec<f64>>, field: &str) -> Result<[f64; 3], SceneError> {
    if v.get_ref().len() != dim {
        return Err(ctx.err(
            Some(v.span()),
            Some(field),
            format!("expected {dim} components for a {dim}D scene, got {}", v.get_ref().len()),
        ));
    }
    if let Some(x) = v.get_ref().iter().find(|x| !x.is_finite()) {
        return Err(ctx.err(Some(v.span()), Some(field), format!("components must be finite, got {x}")));
    }
    let mut out = [0.0; 3];
    out[..dim].copy_from_slice(v.get_ref());
    Ok(out)
}

/// Checks `lo < x < hi` (open or closed ends as given) and finiteness.
fn in_range(ctx: &Ctx, v: &Spanned<f64>, field: &str, lo: Bound, hi: Bound) -> Result<f64, SceneError> {
    let x = *v.get_ref();
    let ok = x.is_finite() && lo.below(x) && hi.above(x);
    if ok {
        Ok(x)
    } else {
        Err(ctx.err(
            Some(v.span()),
            Some(field),
            format!("must be {}{}, got {x}", lo.describe_lo(), hi.describe_hi()),
        ))
    }
}

#[derive(Clone, Copy)]
enum Bound {
    Open(f64),
    Closed(f64),
    None,
}

impl Bound {
    fn below(self, x: f64) -> bool {
        match self {
            Bound::Open(b) => x > b,
            Bound::Closed(b) => x >= b,
            Bound::None => true,
        }
    }
    fn above(self, x: f64) -> bool {
        match self {
            Bound::Open(b) => x < b,
            Bound::Closed(b) => x <= b,
            Bound::None => true,
        }
    }
    fn describe_lo(self) -> String {
        match self {
            Bound::Open(b) => format!("> {b}"),
            Bound::Closed(b) => format!(">= {b}"),
            Bound::None => "finite".into(),
        }
    }
    fn describe_hi(self) -> String {
        match self {
            Bound::Open(b) => format!(" and < {b}"),
            Bound::Closed(b) => format!(" and <= {b}"),
            Bound::None => String::new(),
        }
    }
}

use Bound::{Closed, Open};

fn positive(ctx: &Ctx, v: &Spanned<f64>, field: &str) -> Result<f64, SceneError> {
    in_range(ctx, v, field, Open(0.0), Bound::None)
}

fn non_negative(ctx: &Ctx, v: &Option<Spanned<f64>>, field: &str) -> Result<f64, SceneError> {
    v.as_ref().map_or(Ok(0.0), |v| in_range(ctx, v, field, Closed(0.0), Bound::None))
}

fn mpm_settings(ctx: &Ctx, raw: Option<&raw::RawMpm>) -> Result<MpmSettings, SceneError> {
    let mut out = MpmSettings {
        points_per_axis: 2,
        kernel: MpmKernel::Gimp,
        flip: Some(0.98),
        domain_walls: MpmDomainWalls::Slip,
    };
    let Some(m) = raw else { return Ok(out) };
    if let Some(n) = &m.points_per_axis {
        if !(1..=4).contains(n.get_ref()) {
            return Err(ctx.err(
                Some(n.span()),
                Some("mpm.points_per_axis"),
                format!("must be 1 to 4, got {}", n.get_ref()),
            ));
        }
        out.points_per_axis = *n.get_ref();
    }
    if let Some(k) = &m.kernel {
        out.kernel = match k.get_ref().as_str() {
            "gimp" => MpmKernel::Gimp,
            "bspline" => MpmKernel::Bspline,
            other => {
                return Err(ctx.err(
                    Some(k.span()),
                    Some("mpm.kernel"),
                    format!("must be \"gimp\" or \"bspline\", got {other:?}"),
                ));
            }
        };
    }
    let beta = match &m.flip {
        Some(b) => in_range(ctx, b, "mpm.flip", Closed(0.0), Closed(1.0))?,
        None => 0.98,
    };
    out.flip = match m.transfer.as_ref().map(|t| (t, t.get_ref().as_str())) {
        None | Some((_, "flip")) => Some(beta),
        Some((t, "apic")) => {
            if let Some(b) = &m.flip {
                return Err(ctx.err(
                    Some(b.span()),
                    Some("mpm.flip"),
                    "is the FLIP share of transfer = \"flip\"; APIC has none".into(),
                ));
            }
            let _ = t;
            None
        }
        Some((t, other)) => {
            return Err(ctx.err(
                Some(t.span()),
                Some("mpm.transfer"),
                format!("must be \"flip\" or \"apic\", got {other:?}"),
            ));
        }
    };
    if let Some(w) = &m.domain_walls {
        out.domain_walls = match w.get_ref().as_str() {
            "slip" => MpmDomainWalls::Slip,
            "sticky" => MpmDomainWalls::Sticky,
            other => {
                return Err(ctx.err(
                    Some(w.span()),
                    Some("mpm.domain_walls"),
                    format!("must be \"slip\" or \"sticky\", got {other:?}"),
                ));
            }
        };
    }
    Ok(out)
}

fn validate(ctx: &Ctx, raw: raw::RawScene, hash: u64) -> Result<Scene, SceneError> {
    if *raw.schema.get_ref() != SCHEMA_VERSION {
        return Err(ctx.err(
            Some(raw.schema.span()),
            Some("schema"),
            format!(
                "this build reads scene schema {SCHEMA_VERSION}, the file says {}",
                raw.schema.get_ref()
            ),
        ));
    }
    let run = &raw.run;
    let dimension = match *run.dimension.get_ref() {
        2 => Dimension::Two,
        3 => Dimension::Three,
        d => {
            return Err(ctx.err(
                Some(run.dimension.span()),
                Some("run.dimension"),
                format!("must be 2 or 3, got {d}"),
            ));
        }
    };
    let dim = dimension as usize;
    let dt = positive(ctx, &run.dt, "run.dt")?;
    let steps = match (&run.steps, &run.duration) {
        (Some(s), None) if *s.get_ref() >= 1 => *s.get_ref(),
        (Some(s), None) => return Err(ctx.err(Some(s.span()), Some("run.steps"), "must be >= 1, got 0".into())),
        (None, Some(d)) => {
            let d = positive(ctx, d, "run.duration")?;
            (d / dt).round().max(1.0) as u64
        }
        (Some(s), Some(_)) => {
            return Err(ctx.err(
                Some(s.span()),
                Some("run.steps"),
                "give either `run.steps` or `run.duration`, not both".into(),
            ));
        }
        (None, None) => {
            return Err(ctx.err(
                Some(run.dt.span()),
                Some("run"),
                "missing `steps` or `duration`: one of them sets the length of the run".into(),
            ));
        }
    };
    let threads = match &run.threads {
        None => 1,
        Some(t) if (1..=256).contains(t.get_ref()) => *t.get_ref(),
        Some(t) => {
            return Err(ctx.err(
                Some(t.span()),
                Some("run.threads"),
                format!("must be between 1 and 256, got {}", t.get_ref()),
            ));
        }
    };

    let d = &raw.domain;
    let min = vec3(ctx, dim, &d.min, "domain.min")?;
    let max = vec3(ctx, dim, &d.max, "domain.max")?;
    if (0..dim).any(|k| max[k] <= min[k]) {
        return Err(ctx.err(
            Some(d.max.span()),
            Some("domain.max"),
            format!(
                "must be greater than `domain.min` in every component ({:?} vs {:?})",
                &max[..dim],
                &min[..dim]
            ),
        ));
    }
    let cell_size = positive(ctx, &d.cell_size, "domain.cell_size")?;
    let mut periodic = [false; 3];
    if let Some(p) = &d.periodic {
        if p.get_ref().len() != dim {
            return Err(ctx.err(
                Some(p.span()),
                Some("domain.periodic"),
                format!("expected {dim} booleans, got {}", p.get_ref().len()),
            ));
        }
        periodic[..dim].copy_from_slice(p.get_ref());
    }
    let domain = Domain {
        min,
        max,
        cell_size,
        periodic,
    };
    let gravity = match &raw.gravity {
        Some(g) => vec3(ctx, dim, g, "gravity")?,
        None => [0.0; 3],
    };

    let mut materials = Vec::new();
    for (i, m) in raw.material.iter().enumerate() {
        let f = |name: &str| format!("material[{i}].{name}");
        let name = m.name.get_ref().clone();
        if materials.iter().any(|x: &Material| x.name == name) {
            return Err(ctx.err(Some(m.name.span()), Some(&f("name")), format!("material `{name}` is defined twice")));
        }
        let dem = match &m.dem {
            None => None,
            Some(g) => {
                let f = |name: &str| format!("material[{i}].dem.{name}");
                let stiffness_normal = positive(ctx, &g.stiffness_normal, &f("stiffness_normal"))?;
                Some(DemMaterial {
                    radius: positive(ctx, &g.radius, &f("radius"))?,
                    radius_std: non_negative(ctx, &g.radius_std, &f("radius_std"))?,
                    stiffness_normal,
                    stiffness_tangential: match &g.stiffness_tangential {
                        Some(k) => positive(ctx, k, &f("stiffness_tangential"))?,
                        None => stiffness_normal * 2.0 / 7.0,
                    },
                    damping: match (&g.restitution, &g.damping) {
                        (Some(e), None) => DemDamping::Restitution(in_range(ctx, e, &f("restitution"), Closed(0.0), Closed(1.0))?),
                        (None, Some(gm)) => DemDamping::Viscous(in_range(ctx, gm, &f("damping"), Closed(0.0), Bound::None)?),
                        (Some(e), Some(_)) => {
                            return Err(ctx.err(
                                Some(e.span()),
                                Some(&f("restitution")),
                                "give either `restitution` or `damping` [N s/m], not both".into(),
                            ));
                        }
                        (None, None) => {
                            return Err(ctx.err(
                                Some(g.radius.span()),
                                Some(&f("restitution")),
                                "missing: give `restitution` (0 <= e <= 1) or `damping` [N s/m]".into(),
                            ));
                        }
                    },
                    friction: in_range(ctx, &g.friction, &f("friction"), Closed(0.0), Bound::None)?,
                    cohesion_normal: non_negative(ctx, &g.cohesion_normal, &f("cohesion_normal"))?,
                    cohesion_tangential: non_negative(ctx, &g.cohesion_tangential, &f("cohesion_tangential"))?,
                })
            }
        };
        let mpm = match &m.mpm {
            None => None,
            Some(c) => {
                let f = |name: &str| format!("material[{i}].mpm.{name}");
                let model = match c.model.as_ref().map(|m| m.get_ref().as_str()) {
                    None | Some("drucker_prager") => {
                        for (name, v) in [("packing_critical", &c.packing_critical), ("chi", &c.chi), ("xi", &c.xi)] {
                            if let Some(v) = v {
                                return Err(ctx.err(
                                    Some(v.span()),
                                    Some(&f(name)),
                                    "belongs to model = \"critical_state\" (Chen 2021), not \"drucker_prager\"".into(),
                                ));
                            }
                        }
                        if let Some(coh) = &c.cohesion
                            && *coh.get_ref() != 0.0
                        {
                            return Err(ctx.err(
                                Some(coh.span()),
                                Some(&f("cohesion")),
                                "model = \"drucker_prager\" (Yue 2018) is cohesionless; use model = \"critical_state\" for cohesion".into(),
                            ));
                        }
                        MpmModel::DruckerPrager
                    }
                    Some("critical_state") => MpmModel::CriticalState {
                        packing_critical: match &c.packing_critical {
                            Some(v) => in_range(ctx, v, &f("packing_critical"), Open(0.0), Open(1.0))?,
                            None => {
                                return Err(ctx.err(
                                    c.model.as_ref().map(|m| m.span()),
                                    Some(&f("packing_critical")),
                                    "model = \"critical_state\" needs the critical packing fraction `packing_critical` (Chen 2021 Table 2: 0.815)".into(),
                                ));
                            }
                        },
                        chi: match &c.chi {
                            Some(v) => in_range(ctx, v, &f("chi"), Closed(0.0), Bound::None)?,
                            None => 7.0,
                        },
                        xi: match &c.xi {
                            Some(v) => in_range(ctx, v, &f("xi"), Closed(0.0), Bound::None)?,
                            None => 0.01,
                        },
                    },
                    Some(other) => {
                        return Err(ctx.err(
                            c.model.as_ref().map(|m| m.span()),
                            Some(&f("model")),
                            format!("must be \"drucker_prager\" (Yue 2018) or \"critical_state\" (Chen 2021), got {other:?}"),
                        ));
                    }
                };
                Some(MpmMaterial {
                    model,
                    young: positive(ctx, &c.young, &f("young"))?,
                    poisson: in_range(ctx, &c.poisson, &f("poisson"), Closed(0.0), Open(0.5))?,
                    friction_angle: in_range(ctx, &c.friction_angle, &f("friction_angle"), Closed(0.0), Open(90.0))?,
                    cohesion: non_negative(ctx, &c.cohesion, &f("cohesion"))?,
                    packing: in_range(ctx, &c.packing, &f("packing"), Open(0.0), Closed(1.0))?,
                })
            }
        };
        materials.push(Material {
            name,
            density: positive(ctx, &m.density, &f("density"))?,
            dem,
            mpm,
        });
    }

    let mut bodies = Vec::new();
    for (i, b) in raw.body.iter().enumerate() {
        let f = |name: &str| format!("body[{i}].{name}");
        let Some(material) = materials.iter().position(|m| &m.name == b.material.get_ref()) else {
            let known: Vec<_> = materials.iter().map(|m| format!("`{}`", m.name)).collect();
            return Err(ctx.err(
                Some(b.material.span()),
                Some(&f("material")),
                format!(
                    "no material named `{}`; defined: {}",
                    b.material.get_ref(),
                    if known.is_empty() { "none".into() } else { known.join(", ") }
                ),
            ));
        };
        let model = match b.model.get_ref().as_str() {
            "dem" => Model::Dem,
            "mpm" => Model::Mpm,
            "hybrid" => Model::Hybrid,
            other => {
                return Err(ctx.err(
                    Some(b.model.span()),
                    Some(&f("model")),
                    format!("must be one of \"dem\", \"mpm\", \"hybrid\", got {other:?}"),
                ));
            }
        };
        let mat = &materials[material];
        let needs_dem = matches!(model, Model::Dem | Model::Hybrid);
        let needs_mpm = matches!(model, Model::Mpm | Model::Hybrid);
        if (needs_dem && mat.dem.is_none()) || (needs_mpm && mat.mpm.is_none()) {
            return Err(ctx.err(
                Some(b.model.span()),
                Some(&f("model")),
                format!(
                    "model {:?} needs material `{}` to have {}",
                    b.model.get_ref(),
                    mat.name,
                    if needs_dem && mat.dem.is_none() {
                        "a [material.dem] table"
                    } else {
                        "a [material.mpm] table"
                    }
                ),
            ));
        }
        let shape = shape(ctx, dim, &b.shape, &b.min, &b.max, &b.center, &b.radius, &f)?;
        let packing = match &b.packing {
            None => None,
            Some(p) if model == Model::Mpm => {
                return Err(ctx.err(
                    Some(p.span()),
                    Some(&f("packing")),
                    "a packing file makes grains: only a model = \"dem\" or \"hybrid\" body can have one".into(),
                ));
            }
            Some(p) => {
                let base = ctx.path.parent().unwrap_or(Path::new("."));
                let path = base.join(p.get_ref());
                if !path.is_file() {
                    return Err(ctx.err(
                        Some(p.span()),
                        Some(&f("packing")),
                        format!("no packing file at {} (paths are relative to the scene file)", path.display()),
                    ));
                }
                Some(path)
            }
        };
        if let Some(fz) = &b.frozen
            && *fz.get_ref()
            && model != Model::Dem
        {
            return Err(ctx.err(
                Some(fz.span()),
                Some(&f("frozen")),
                "only a model = \"dem\" body can be frozen".into(),
            ));
        }
        let frozen = b.frozen.as_ref().is_some_and(|fz| *fz.get_ref());
        let confining_pressure = match &b.confining_pressure {
            None => 0.0,
            Some(p) if model != Model::Mpm || !matches!(shape, Shape::Box { .. }) => {
                return Err(ctx.err(
                    Some(p.span()),
                    Some(&f("confining_pressure")),
                    "only a model = \"mpm\" body of shape \"box\" can be confined".into(),
                ));
            }
            Some(p) => in_range(ctx, p, &f("confining_pressure"), Closed(0.0), Bound::None)?,
        };
        let velocity = match &b.velocity {
            None => [0.0; 3],
            Some(v) if frozen => {
                return Err(ctx.err(Some(v.span()), Some(&f("velocity")), "a frozen body cannot move".into()));
            }
            Some(v) => vec3(ctx, dim, v, &f("velocity"))?,
        };
        bodies.push(Body {
            material,
            model,
            shape,
            packing,
            frozen,
            confining_pressure,
            velocity,
        });
    }

    let mut walls = Vec::new();
    for (i, w) in raw.wall.iter().enumerate() {
        let f = |name: &str| format!("wall[{i}].{name}");
        let missing = |name: &str| {
            ctx.err(
                Some(w.kind.span()),
                Some(&f(name)),
                format!("a {:?} wall needs `{name}`", w.kind.get_ref()),
            )
        };
        let shape = match w.kind.get_ref().as_str() {
            "plane" => {
                let point = vec3(ctx, dim, w.point.as_ref().ok_or_else(|| missing("point"))?, &f("point"))?;
                let n = w.normal.as_ref().ok_or_else(|| missing("normal"))?;
                let mut normal = vec3(ctx, dim, n, &f("normal"))?;
                let len = normal.iter().map(|x| x * x).sum::<f64>().sqrt();
                if len == 0.0 {
                    return Err(ctx.err(Some(n.span()), Some(&f("normal")), "must not be the zero vector".into()));
                }
                normal.iter_mut().for_each(|x| *x /= len);
                WallShape::Plane { point, normal }
            }
            "box" => {
                let (min, max) = box_corners(
                    ctx,
                    dim,
                    w.min.as_ref().ok_or_else(|| missing("min"))?,
                    w.max.as_ref().ok_or_else(|| missing("max"))?,
                    &f,
                )?;
                WallShape::Box { min, max }
            }
            "drum" => WallShape::Drum {
                center: vec3(ctx, dim, w.center.as_ref().ok_or_else(|| missing("center"))?, &f("center"))?,
                radius: positive(ctx, w.radius.as_ref().ok_or_else(|| missing("radius"))?, &f("radius"))?,
            },
            "segment" => WallShape::Segment {
                from: vec3(ctx, dim, w.from.as_ref().ok_or_else(|| missing("from"))?, &f("from"))?,
                to: vec3(ctx, dim, w.to.as_ref().ok_or_else(|| missing("to"))?, &f("to"))?,
            },
            other => {
                return Err(ctx.err(
                    Some(w.kind.span()),
                    Some(&f("kind")),
                    format!("must be \"plane\", \"box\", \"drum\" or \"segment\", got {other:?}"),
                ));
            }
        };
        if let (Some(spin), false) = (&w.spin, matches!(shape, WallShape::Drum { .. })) {
            return Err(ctx.err(Some(spin.span()), Some(&f("spin")), "only a \"drum\" wall can spin".into()));
        }
        walls.push(Wall {
            shape,
            friction: non_negative(ctx, &w.friction, &f("friction"))?,
            velocity: match &w.velocity {
                Some(v) => vec3(ctx, dim, v, &f("velocity"))?,
                None => [0.0; 3],
            },
            spin: match &w.spin {
                Some(sp) => in_range(ctx, sp, &f("spin"), Bound::None, Bound::None)?,
                None => 0.0,
            },
            sticky: w.sticky.unwrap_or(false),
        });
    }

    let band_default = 2.0 * domain.cell_size;
    let coupling = match &raw.coupling {
        None => Coupling {
            substeps: 10,
            weight: 0.5,
            discrete_layer: band_default,
            hybrid_band: band_default,
            grain_transfer: GrainTransfer::Flip,
            quasi_static: 1e-3,
        },
        Some(c) => Coupling {
            substeps: match &c.substeps {
                None => 10,
                Some(k) if (1..=10_000).contains(k.get_ref()) => *k.get_ref(),
                Some(k) => {
                    return Err(ctx.err(
                        Some(k.span()),
                        Some("coupling.substeps"),
                        format!("must be between 1 and 10000, got {}", k.get_ref()),
                    ));
                }
            },
            weight: match &c.weight {
                None => 0.5,
                Some(w) => in_range(ctx, w, "coupling.weight", Open(0.0), Open(1.0))?,
            },
            discrete_layer: match &c.discrete_layer {
                None => band_default,
                Some(t) => in_range(ctx, t, "coupling.discrete_layer", Closed(0.0), Bound::None)?,
            },
            hybrid_band: match &c.hybrid_band {
                None => band_default,
                Some(t) => in_range(ctx, t, "coupling.hybrid_band", Open(0.0), Bound::None)?,
            },
            grain_transfer: match c.grain_transfer.as_ref().map(|t| (t, t.get_ref().as_str())) {
                Some((_, "pic")) => GrainTransfer::Pic,
                None | Some((_, "flip")) => GrainTransfer::Flip,
                Some((t, other)) => {
                    return Err(ctx.err(
                        Some(t.span()),
                        Some("coupling.grain_transfer"),
                        format!("must be \"flip\" or \"pic\", got {other:?}"),
                    ));
                }
            },
            quasi_static: match &c.quasi_static {
                None => 1e-3,
                Some(i) => in_range(ctx, i, "coupling.quasi_static", Closed(0.0), Bound::None)?,
            },
        },
    };
    let mpm = mpm_settings(ctx, raw.mpm.as_ref())?;
    let oracle = match &raw.oracle {
        None => None,
        Some(o) => Some(Oracle {
            kind: match o.kind.get_ref().as_str() {
                "fixed" => OracleKind::Fixed,
                "layered" => OracleKind::Layered,
                "surface" => OracleKind::Surface,
                other => {
                    return Err(ctx.err(
                        Some(o.kind.span()),
                        Some("oracle.kind"),
                        format!("must be one of \"fixed\", \"layered\", \"surface\", got {other:?}"),
                    ));
                }
            },
            every: match &o.every {
                None => 100,
                Some(e) if *e.get_ref() >= 1 => *e.get_ref(),
                Some(e) => return Err(ctx.err(Some(e.span()), Some("oracle.every"), "must be >= 1, got 0".into())),
            },
            critical_packing: match &o.critical_packing {
                None => 0.5,
                Some(c) => in_range(ctx, c, "oracle.critical_packing", Open(0.0), Open(1.0))?,
            },
            centre: match &o.centre {
                None => None,
                Some(c) => Some(in_range(ctx, c, "oracle.centre", Bound::None, Bound::None)?),
            },
            half_width: match &o.half_width {
                None => None,
                Some(c) => Some(in_range(ctx, c, "oracle.half_width", Closed(0.0), Bound::None)?),
            },
        }),
    };
    let output = Output {
        frames_every: raw.output.as_ref().and_then(|o| o.frames_every).unwrap_or(0),
    };
    let bridge = match &raw.bridge {
        Some(b) if b.enabled => Some(SceneBridge {
            settings: match &b.settings {
                None => None,
                Some(p) => {
                    let path = ctx.path.parent().unwrap_or(Path::new(".")).join(p.get_ref());
                    if !path.is_file() {
                        return Err(ctx.err(
                            Some(p.span()),
                            Some("bridge.settings"),
                            format!(
                                "no bridge settings file at {} (paths are relative to the scene file)",
                                path.display()
                            ),
                        ));
                    }
                    Some(path)
                }
            },
        }),
        _ => None,
    };

    let synthetic = match &raw.synthetic {
        None => None,
        Some(s) => {
            let mut participants = Vec::new();
            match &s.participants {
                None => participants.extend([Role::Dem, Role::Mpm, Role::Coupler]),
                Some(list) => {
                    for p in list.get_ref() {
                        match Role::from_name(p).filter(|r| Role::PARTICIPANTS[..3].contains(r)) {
                            Some(r) if !participants.contains(&r) => participants.push(r),
                            _ => {
                                return Err(ctx.err(
                                    Some(list.span()),
                                    Some("synthetic.participants"),
                                    format!("entries must be distinct and one of \"dem\", \"mpm\", \"coupler\", got {p:?}"),
                                ));
                            }
                        }
                    }
                    participants.sort();
                }
            }
            let solvers = participants.iter().filter(|r| matches!(r, Role::Dem | Role::Mpm)).count();
            let coupled = participants.contains(&Role::Coupler);
            if (coupled && solvers != 2) || (!coupled && solvers != 1) {
                let span = s.participants.as_ref().map(|l| l.span());
                return Err(ctx.err(
                    span,
                    Some("synthetic.participants"),
                    "allowed sets: [\"dem\"], [\"mpm\"], or [\"dem\", \"mpm\", \"coupler\"]".into(),
                ));
            }
            let nodes = |v: &Option<Spanned<u64>>, field: &str| match v {
                None => Ok(1000),
                Some(n) if (1..=100_000_000).contains(n.get_ref()) => Ok(*n.get_ref()),
                Some(n) => Err(ctx.err(
                    Some(n.span()),
                    Some(field),
                    format!("must be between 1 and 100000000, got {}", n.get_ref()),
                )),
            };
            Some(Synthetic {
                participants,
                dem_nodes: nodes(&s.dem_nodes, "synthetic.dem_nodes")?,
                mpm_nodes: nodes(&s.mpm_nodes, "synthetic.mpm_nodes")?,
                overlap: match &s.overlap {
                    None => 0.5,
                    Some(o) => in_range(ctx, o, "synthetic.overlap", Closed(0.0), Closed(1.0))?,
                },
                vary: match &s.vary {
                    None => 0.0,
                    Some(v) => in_range(ctx, v, "synthetic.vary", Closed(0.0), Closed(0.9))?,
                },
                checksum: s.checksum.unwrap_or(true),
                content: match s.content.as_ref().map(|c| c.get_ref().as_str()) {
                    None | Some("hashed") => SyntheticContent::Hashed,
                    Some("plain") => SyntheticContent::Plain,
                    Some(other) => {
                        let span = s.content.as_ref().map(|c| c.span());
                        return Err(ctx.err(
                            span,
                            Some("synthetic.content"),
                            format!("must be \"hashed\" or \"plain\", got {other:?}"),
                        ));
                    }
                },
            })
        }
    };
    if synthetic.is_none() && bodies.is_empty() {
        return Err(ctx.err(
            None,
            Some("body"),
            "the scene has no [[body]] of material (and is not a [synthetic] test scene): nothing to simulate".into(),
        ));
    }
    if synthetic.is_some() && !bodies.is_empty() {
        return Err(ctx.err(
            None,
            Some("synthetic"),
            "a [synthetic] test scene cannot also have [[body]] tables: synthetic rasters never mix with physics".into(),
        ));
    }

    let name = match &run.name {
        Some(n) if !n.is_empty() && n.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-') => n.clone(),
        Some(n) => {
            return Err(ctx.err(
                None,
                Some("run.name"),
                format!("must be non-empty and use only letters, digits, '_' and '-' (it names the output directory), got {n:?}"),
            ));
        }
        None => ctx
            .path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "scene".into()),
    };
    Ok(Scene {
        path: ctx.path.to_path_buf(),
        hash,
        name,
        dimension,
        dt,
        steps,
        seed: run.seed.unwrap_or(0),
        threads,
        domain,
        gravity,
        materials,
        bodies,
        walls,
        coupling,
        mpm,
        oracle,
        output,
        bridge,
        synthetic,
    })
}

fn box_corners(
    ctx: &Ctx,
    dim: usize,
    min: &Spanned<Vec<f64>>,
    max: &Spanned<Vec<f64>>,
    f: &dyn Fn(&str) -> String,
) -> Result<([f64; 3], [f64; 3]), SceneError> {
    let lo = vec3(ctx, dim, min, &f("min"))?;
    let hi = vec3(ctx, dim, max, &f("max"))?;
    if (0..dim).any(|k| hi[k] <= lo[k]) {
        return Err(ctx.err(
            Some(max.span()),
            Some(&f("max")),
            "must be greater than `min` in every component".into(),
        ));
    }
    Ok((lo, hi))
}

#[allow(clippy::too_many_arguments)]
fn shape(
    ctx: &Ctx,
    dim: usize,
    kind: &Spanned<String>,
    min: &Option<Spanned<Vec<f64>>>,
    max: &Option<Spanned<Vec<f64>>>,
    center: &Option<Spanned<Vec<f64>>>,
    radius: &Option<Spanned<f64>>,
    f: &dyn Fn(&str) -> String,
) -> Result<Shape, SceneError> {
    let missing = |name: &str| {
        ctx.err(
            Some(kind.span()),
            Some(&f(name)),
            format!("a {:?} body needs `{name}`", kind.get_ref()),
        )
    };
    match kind.get_ref().as_str() {
        "box" => {
            let (min, max) = box_corners(
                ctx,
                dim,
                min.as_ref().ok_or_else(|| missing("min"))?,
                max.as_ref().ok_or_else(|| missing("max"))?,
                f,
            )?;
            Ok(Shape::Box { min, max })
        }
        "ball" => Ok(Shape::Ball {
            center: vec3(ctx, dim, center.as_ref().ok_or_else(|| missing("center"))?, &f("center"))?,
            radius: positive(ctx, radius.as_ref().ok_or_else(|| missing("radius"))?, &f("radius"))?,
        }),
        other => Err(ctx.err(
            Some(kind.span()),
            Some(&f("shape")),
            format!("must be \"box\" or \"ball\" (disk in 2D, sphere in 3D), got {other:?}"),
        )),
    }
}

/// The file as written: serde structs, unknown fields refused, spans kept.
pub mod raw {
    use super::*;

    #[derive(Deserialize)]
    #[serde(deny_unknown_fields)]
    pub struct RawScene {
        pub schema: Spanned<u32>,
        pub gravity: Option<Spanned<Vec<f64>>>,
        pub run: RawRun,
        pub domain: RawDomain,
        #[serde(default)]
        pub material: Vec<RawMaterial>,
        #[serde(default)]
        pub body: Vec<RawBody>,
        #[serde(default)]
        pub wall: Vec<RawWall>,
        pub coupling: Option<RawCoupling>,
        pub mpm: Option<RawMpm>,
        pub oracle: Option<RawOracle>,
        pub output: Option<RawOutput>,
        pub bridge: Option<RawBridge>,
        pub synthetic: Option<RawSynthetic>,
    }

    #[derive(Deserialize)]
    #[serde(deny_unknown_fields)]
    pub struct RawRun {
        pub name: Option<String>,
        pub dimension: Spanned<u32>,
        pub dt: Spanned<f64>,
        pub steps: Option<Spanned<u64>>,
        pub duration: Option<Spanned<f64>>,
        pub seed: Option<u64>,
        pub threads: Option<Spanned<u32>>,
    }

    #[derive(Deserialize)]
    #[serde(deny_unknown_fields)]
    pub struct RawDomain {
        pub min: Spanned<Vec<f64>>,
        pub max: Spanned<Vec<f64>>,
        pub cell_size: Spanned<f64>,
        pub periodic: Option<Spanned<Vec<bool>>>,
    }

    #[derive(Deserialize)]
    #[serde(deny_unknown_fields)]
    pub struct RawMaterial {
        pub name: Spanned<String>,
        pub density: Spanned<f64>,
        pub dem: Option<RawDemMaterial>,
        pub mpm: Option<RawMpmMaterial>,
    }

    #[derive(Deserialize)]
    #[serde(deny_unknown_fields)]
    pub struct RawDemMaterial {
        pub radius: Spanned<f64>,
        pub radius_std: Option<Spanned<f64>>,
        pub stiffness_normal: Spanned<f64>,
        pub stiffness_tangential: Option<Spanned<f64>>,
        pub restitution: Option<Spanned<f64>>,
        pub damping: Option<Spanned<f64>>,
        pub friction: Spanned<f64>,
        pub cohesion_normal: Option<Spanned<f64>>,
        pub cohesion_tangential: Option<Spanned<f64>>,
    }

    #[derive(Deserialize)]
    #[serde(deny_unknown_fields)]
    pub struct RawMpmMaterial {
        pub young: Spanned<f64>,
        pub poisson: Spanned<f64>,
        pub friction_angle: Spanned<f64>,
        pub cohesion: Option<Spanned<f64>>,
        pub model: Option<Spanned<String>>,
        pub packing: Spanned<f64>,
        pub packing_critical: Option<Spanned<f64>>,
        pub chi: Option<Spanned<f64>>,
        pub xi: Option<Spanned<f64>>,
    }

    #[derive(Deserialize)]
    #[serde(deny_unknown_fields)]
    pub struct RawMpm {
        pub points_per_axis: Option<Spanned<u32>>,
        pub kernel: Option<Spanned<String>>,
        pub transfer: Option<Spanned<String>>,
        pub flip: Option<Spanned<f64>>,
        pub domain_walls: Option<Spanned<String>>,
    }

    #[derive(Deserialize)]
    #[serde(deny_unknown_fields)]
    pub struct RawBody {
        pub material: Spanned<String>,
        pub model: Spanned<String>,
        pub shape: Spanned<String>,
        pub min: Option<Spanned<Vec<f64>>>,
        pub max: Option<Spanned<Vec<f64>>>,
        pub center: Option<Spanned<Vec<f64>>>,
        pub radius: Option<Spanned<f64>>,
        pub packing: Option<Spanned<String>>,
        pub frozen: Option<Spanned<bool>>,
        pub confining_pressure: Option<Spanned<f64>>,
        pub velocity: Option<Spanned<Vec<f64>>>,
    }

    #[derive(Deserialize)]
    #[serde(deny_unknown_fields)]
    pub struct RawWall {
        pub kind: Spanned<String>,
        pub point: Option<Spanned<Vec<f64>>>,
        pub normal: Option<Spanned<Vec<f64>>>,
        pub min: Option<Spanned<Vec<f64>>>,
        pub max: Option<Spanned<Vec<f64>>>,
        pub center: Option<Spanned<Vec<f64>>>,
        pub radius: Option<Spanned<f64>>,
        pub from: Option<Spanned<Vec<f64>>>,
        pub to: Option<Spanned<Vec<f64>>>,
        pub friction: Option<Spanned<f64>>,
        pub velocity: Option<Spanned<Vec<f64>>>,
        pub spin: Option<Spanned<f64>>,
        pub sticky: Option<bool>,
    }

    #[derive(Deserialize)]
    #[serde(deny_unknown_fields)]
    pub struct RawCoupling {
        pub substeps: Option<Spanned<u32>>,
        pub weight: Option<Spanned<f64>>,
        pub discrete_layer: Option<Spanned<f64>>,
        pub hybrid_band: Option<Spanned<f64>>,
        pub grain_transfer: Option<Spanned<String>>,
        pub quasi_static: Option<Spanned<f64>>,
    }

    #[derive(Deserialize)]
    #[serde(deny_unknown_fields)]
    pub struct RawOracle {
        pub kind: Spanned<String>,
        pub every: Option<Spanned<u64>>,
        pub critical_packing: Option<Spanned<f64>>,
        pub centre: Option<Spanned<f64>>,
        pub half_width: Option<Spanned<f64>>,
    }

    #[derive(Deserialize)]
    #[serde(deny_unknown_fields)]
    pub struct RawBridge {
        pub enabled: bool,
        pub settings: Option<Spanned<String>>,
    }

    #[derive(Deserialize)]
    #[serde(deny_unknown_fields)]
    pub struct RawOutput {
        pub frames_every: Option<u64>,
    }

    #[derive(Deserialize)]
    #[serde(deny_unknown_fields)]
    pub struct RawSynthetic {
        pub participants: Option<Spanned<Vec<String>>>,
        pub dem_nodes: Option<Spanned<u64>>,
        pub mpm_nodes: Option<Spanned<u64>>,
        pub overlap: Option<Spanned<f64>>,
        pub vary: Option<Spanned<f64>>,
        pub checksum: Option<bool>,
        pub content: Option<Spanned<String>>,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = r#"
schema = 1
[run]
dimension = 2
dt = 1e-4
steps = 10
[domain]
min = [0.0, 0.0]
max = [1.0, 1.0]
cell_size = 0.01
[synthetic]
dem_nodes = 100
mpm_nodes = 50
"#;

    fn check_err(text: &str, line: Option<usize>, field: &str, needle: &str) {
        let err = from_str(text, Path::new("s.toml"), 0).expect_err("must be refused");
        assert_eq!(err.line_col.map(|l| l.0), line, "{err}");
        assert_eq!(err.field.as_deref(), Some(field), "{err}");
        assert!(err.message.contains(needle), "{err}");
    }

    #[test]
    fn a_good_synthetic_scene_validates() {
        let s = from_str(GOOD, Path::new("dir/good.toml"), 7).unwrap();
        assert_eq!(s.name, "good");
        assert_eq!(s.participants(), vec![Role::Dem, Role::Mpm, Role::Coupler]);
        assert_eq!(s.time_owner(), Role::Coupler);
        assert_eq!(s.steps, 10);
    }

    #[test]
    fn errors_name_line_field_and_allowed_values() {
        check_err(
            &GOOD.replace("cell_size = 0.01", "cell_size = -0.01"),
            Some(10),
            "domain.cell_size",
            "> 0",
        );
        check_err(
            &GOOD.replace("steps = 10", "steps = 10\nbogus = 3"),
            Some(7),
            "run.bogus",
            "unknown field",
        );
        check_err(&GOOD.replace("dt = 1e-4", "dt = \"fast\""), Some(5), "run.dt", "invalid type");
        check_err(&GOOD.replace("dimension = 2", "dimension = 4"), Some(4), "run.dimension", "2 or 3");
        check_err(
            &GOOD.replace("max = [1.0, 1.0]", "max = [1.0, 1.0, 1.0]"),
            Some(9),
            "domain.max",
            "2 components",
        );
        check_err(
            &GOOD.replace("mpm_nodes = 50", "mpm_nodes = 50\nparticipants = [\"dem\", \"coupler\"]"),
            Some(14),
            "synthetic.participants",
            "allowed sets",
        );
        let line = GOOD.lines().count() + 2;
        check_err(
            &format!("{GOOD}[coupling]\nquasi_static = -1e-3\n"),
            Some(line),
            "coupling.quasi_static",
            ">= 0",
        );
        check_err(
            &format!("{GOOD}[oracle]\nkind = \"surface\"\ncritical_packing = 1.5\n"),
            Some(line + 1),
            "oracle.critical_packing",
            "< 1",
        );
        check_err(
            &format!("{GOOD}[oracle]\nkind = \"surface\"\nhalf_width = -0.001\n"),
            Some(line + 1),
            "oracle.half_width",
            ">= 0",
        );
    }

    #[test]
    fn overrides_edit_tables_and_list_entries() {
        let dir = std::env::temp_dir().join(format!("grains-scene-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("s.toml");
        std::fs::write(&path, GOOD).unwrap();
        let (s, text) = load_with_overrides(&path, &["run.steps=25".into(), "synthetic.dem_nodes = 7".into()]).unwrap();
        assert_eq!((s.steps, s.synthetic.as_ref().unwrap().dem_nodes), (25, 7));
        assert_eq!(s.hash, hash_bytes(text.as_bytes()));
        let e = load_with_overrides(&path, &["run.steps=-3".into()]).unwrap_err();
        assert!(e.message.contains("--set"), "{e}");
        let e = load_with_overrides(&path, &["run.dt.x=1".into()]).unwrap_err();
        assert_eq!(e.field.as_deref(), Some("run.dt.x"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn duration_gives_the_step_count() {
        let s = from_str(&GOOD.replace("steps = 10", "duration = 0.01"), Path::new("g.toml"), 0).unwrap();
        assert_eq!(s.steps, 100);
    }
}
