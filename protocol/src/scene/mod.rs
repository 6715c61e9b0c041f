//! Scene schema v1: TOML in, a validated [`Scene`] out.
//!
//! Two levels (ripgrep's low-level/high-level args): [`raw`] mirrors the file with serde
//! (`deny_unknown_fields`, spans kept for every value that has a range), [`load`] checks
//! types, ranges and cross-references and derives what the run needs (its participants, its
//! time owner). Every error names the file, the line and column, the field and what is
//! allowed; see [`SceneError`]. The format is documented field by field in `scenes/README.md`.
//!
//! One module per section of the file validates that section (`run`, `domain`, `materials`,
//! `bodies`, `walls`, `coupling`, `mpm`, `oracle`, `output`, `bridge`, `synthetic`); the
//! checks they share are in `errors`, `--set` overrides in `overrides`. Every type is
//! re-exported here.

mod bodies;
mod bridge;
mod coupling;
mod domain;
mod errors;
mod materials;
mod mpm;
mod oracle;
mod output;
mod overrides;
pub mod raw;
mod rigid;
mod run;
mod steps;
mod synthetic;
#[cfg(test)]
mod testing;
mod walls;

pub use bodies::{Body, Model, Shape};
pub use bridge::SceneBridge;
pub use coupling::{AutoSteps, ContactForces, Coupling, GrainTransfer};
pub use domain::Domain;
pub use errors::SceneError;
pub use materials::{DemDamping, DemMaterial, Material, MpmMaterial, MpmModel, RateFriction};
pub use mpm::{MpmDomainWalls, MpmInitialStress, MpmKernel, MpmSettings};
pub use oracle::{Oracle, OracleKind, ShearBand};
pub use output::Output;
pub use overrides::{FieldPath, Override, OverrideParseError, PathSegment};
pub use rigid::{Rigid, RigidMotion, check_polygon};
pub use run::Dimension;
pub use steps::{Rescaled, with_resolved_steps};
pub use synthetic::{Synthetic, SyntheticContent};
pub use walls::{Wall, WallShape};

use crate::Role;
use errors::Ctx;
use std::path::{Path, PathBuf};

/// The only schema version this build reads.
pub const SCHEMA_VERSION: u32 = 1;

/// A validated scene.
#[derive(Clone, Debug, PartialEq)]
pub struct Scene {
    pub path: PathBuf,
    /// Hash of the scene text (the file's bytes, or the effective text of [`load_with_overrides`]):
    /// every participant of a run must have loaded the same scene.
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
    /// `[[rigid]]`: rigid spheropolygons (2D), run by the DEM.
    pub rigids: Vec<Rigid>,
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
        let grains = self.has_grains();
        let dem = grains || !self.rigids.is_empty();
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
        // The oracle publishes the zone field of every run with grains and a continuum, fixed
        // or adaptive (rigid bodies meet the continuum by contact, without zones).
        if grains && mpm {
            out.push(Role::Oracle);
        }
        out
    }

    /// The participant that owns time: the coupler when there is one, else the only solver.
    pub fn time_owner(&self) -> Role {
        let parts = self.participants();
        if parts.contains(&Role::Coupler) { Role::Coupler } else { parts[0] }
    }

    /// Whether the scene has grains (a `dem` or `hybrid` body).
    pub fn has_grains(&self) -> bool {
        self.bodies.iter().any(|b| b.model != Model::Mpm)
    }

    /// Whether rigid bodies meet a continuum by contact (Jiang 2020 §4): the DEM and the MPM
    /// then exchange the bodies' reach, the points near them and their contact forces each
    /// step (`protocol/README.md`).
    pub fn contact_coupling(&self) -> bool {
        !self.rigids.is_empty() && self.bodies.iter().any(|b| b.model == Model::Mpm)
    }

    /// The contact radius r_p of a material point against a rigid body [m]
    /// (`coupling.contact_radius`, or by default the lower end of Jiang 2020 eq. 45's interval
    /// h (1/√n, 1) with n points per cell: the point spacing, as the paper's own runs take
    /// it, r_p = 0.1 cm in 0.3-cm cells).
    pub fn contact_radius(&self) -> f64 {
        self.coupling.contact_radius.unwrap_or(contact_radius_bounds(self)[0])
    }

    /// The mass of the lightest material point [kg] (2D: per metre): the bulk density
    /// (density × packing) of the continuum bodies' material times the volume of a point,
    /// (h / points_per_axis)^d. `None` without a continuum.
    pub fn point_mass(&self) -> Option<f64> {
        let volume = (self.domain.cell_size / self.mpm.points_per_axis as f64).powi(self.dim() as i32);
        self.bodies
            .iter()
            .filter(|b| b.model != Model::Dem)
            .filter_map(|b| {
                let m = &self.materials[b.material];
                m.mpm.as_ref().map(|c| m.density * c.packing * volume)
            })
            .reduce(f64::min)
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

/// Jiang 2020 eq. 45: the contact radius of a material point lies between the spacing of the
/// n points of a cell, h / √n (n = points_per_axis^d, in 2D), and the cell size h.
fn contact_radius_bounds(scene: &Scene) -> [f64; 2] {
    let h = scene.domain.cell_size;
    let n = (scene.mpm.points_per_axis as f64).powi(scene.dim() as i32);
    [h / n.sqrt(), h]
}

/// FNV-1a of the file bytes.
pub fn hash_bytes(bytes: &[u8]) -> u64 {
    bytes
        .iter()
        .fold(0xcbf2_9ce4_8422_2325u64, |h, &b| (h ^ b as u64).wrapping_mul(0x100_0000_01b3))
}

/// The text of a scene file and the hash of its bytes.
fn read(path: &Path) -> Result<(String, u64), SceneError> {
    let plain = |message: String| SceneError {
        path: path.to_path_buf(),
        line_col: None,
        field: None,
        message,
    };
    let bytes = std::fs::read(path).map_err(|e| plain(format!("cannot read the scene file: {e}")))?;
    let hash = hash_bytes(&bytes);
    match String::from_utf8(bytes) {
        Ok(text) => Ok((text, hash)),
        Err(e) => Err(plain(format!(
            "not a text file: invalid UTF-8 at byte {} (a scene is a TOML text file)",
            e.utf8_error().valid_up_to()
        ))),
    }
}

/// Reads and validates a scene file.
pub fn load(path: &Path) -> Result<Scene, SceneError> {
    let (text, hash) = read(path)?;
    from_str(&text, path, hash)
}

/// Reads a scene file, applies `--set key=value` overrides (dotted keys, list entries by
/// index: `body.0.max=[0.1, 0.2]`, values in TOML syntax; see [`Override`]) and validates the
/// result. Returns the scene and the effective text, which is what a run hands to its
/// participants: its file paths (`body.N.packing`, `oracle.packing`, `bridge.settings`) are absolute, so that it loads
/// wherever it is copied. A file without overrides and without relative paths comes back as it
/// is, with the hash of its bytes.
pub fn load_with_overrides(path: &Path, overrides: &[String]) -> Result<(Scene, String), SceneError> {
    let (text, hash) = read(path)?;
    with_overrides(&text, path, hash, overrides)
}

/// [`load_with_overrides`] of a scene's text (as read from `path`, whose hash is `hash`).
pub fn with_overrides(text: &str, path: &Path, hash: u64, overrides: &[String]) -> Result<(Scene, String), SceneError> {
    let scene = from_str(text, path, hash)?; // the file itself must be sound before it is edited
    let parsed = overrides::parse(path, overrides)?;
    let mut doc = toml::Value::Table(text.parse::<toml::Table>().map_err(|e| SceneError {
        path: path.into(),
        line_col: None,
        field: None,
        message: e.message().to_string(),
    })?);
    overrides::apply(path, &mut doc, &parsed, overrides)?;
    let made_absolute = absolute_file_paths(&mut doc, path)?;
    if parsed.is_empty() && !made_absolute {
        return Ok((scene, text.to_string()));
    }
    let text = toml::to_string(&doc).map_err(|e| SceneError {
        path: path.into(),
        line_col: None,
        field: None,
        message: format!("cannot write the overridden scene: {e}"),
    })?;
    let scene = from_str(&text, path, hash_bytes(text.as_bytes())).map_err(|mut e| {
        if !overrides.is_empty() {
            e.message = format!("{} (after --set {})", e.message, overrides.join(" --set "));
        }
        e.line_col = None; // a place in the written text, not in the file
        e
    })?;
    Ok((scene, text))
}

/// The fields of the schema that name files (relative to the scene file unless absolute):
/// `body.N.packing` of every body, `oracle.packing` and `bridge.settings`.
fn file_fields(doc: &toml::Value) -> Vec<FieldPath> {
    let bodies = doc.get("body").and_then(toml::Value::as_array).map_or(0, Vec::len);
    (0..bodies)
        .map(|i| FieldPath::root("body").index(i).key("packing"))
        .chain([FieldPath::root("oracle").key("packing"), FieldPath::root("bridge").key("settings")])
        .collect()
}

/// Makes every relative file path of `doc` absolute, resolved against the directory of the
/// scene file at `scene_path`; whether there was one.
fn absolute_file_paths(doc: &mut toml::Value, scene_path: &Path) -> Result<bool, SceneError> {
    let mut changed = false;
    for field in file_fields(doc) {
        let Some(written) = field.get(doc).and_then(toml::Value::as_str) else {
            continue;
        };
        if Path::new(written).is_absolute() {
            continue;
        }
        let file = errors::resolve(scene_path, written);
        let absolute = std::path::absolute(&file).map_err(|e| SceneError {
            path: scene_path.into(),
            line_col: None,
            field: Some(field.to_string()),
            message: format!("cannot make {} absolute: {e}", file.display()),
        })?;
        let Some(absolute) = absolute.to_str() else { continue }; // TOML text is UTF-8; keep the relative path
        field
            .set(doc, toml::Value::String(absolute.into()))
            .expect("the field holds a value");
        changed = true;
    }
    Ok(changed)
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

/// Each section in turn (the order decides which of several errors is reported), then what
/// holds between sections.
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
    let run = run::validate(ctx, &raw.run)?;
    let dim = run.dimension as usize;
    let domain = domain::validate(ctx, dim, &raw.domain)?;
    let gravity = run::gravity(ctx, dim, raw.gravity.as_ref())?;
    let materials = materials::validate(ctx, &raw.material)?;
    let bodies = bodies::validate(ctx, dim, &raw.body, &materials)?;
    // A confining pressure is one fluid around all the material that moves
    // (`MpmParams::ambient_pressure` on points, `grains_dem::fluid` on grains): every body that
    // is not frozen takes the same one.
    if let Some(first) = bodies.iter().position(|b| b.confining_pressure > 0.0) {
        let p = bodies[first].confining_pressure;
        if let Some(k) = bodies.iter().position(|b| !b.frozen && b.confining_pressure != p) {
            let span = raw.body[k]
                .confining_pressure
                .as_ref()
                .map_or(raw.body[k].model.span(), |c| c.span());
            return Err(ctx.err(
                Some(span),
                Some(&format!("body.{k}.confining_pressure")),
                format!(
                    "the confining pressure acts as one fluid around all the material that moves, so every body that is not \
                     frozen takes the same: body.{first} has {} Pa (a hybrid body cannot be confined)",
                    crate::number(p)
                ),
            ));
        }
    }
    let walls = walls::validate(ctx, dim, &raw.wall)?;
    let rigids = rigid::validate(ctx, dim, &raw.rigid, &materials)?;
    let coupling = coupling::validate(ctx, raw.coupling.as_ref(), domain.cell_size, run.dt)?;
    let mpm = mpm::validate(ctx, raw.mpm.as_ref())?;
    let oracle = oracle::validate(ctx, raw.oracle.as_ref())?;
    let output = output::validate(raw.output.as_ref());
    let bridge = bridge::validate(ctx, raw.bridge.as_ref())?;
    let synthetic = synthetic::validate(ctx, raw.synthetic.as_ref())?;
    if synthetic.is_none() && bodies.is_empty() && rigids.is_empty() {
        return Err(ctx.err(
            None,
            Some("body"),
            "the scene has no [[body]] of material or [[rigid]] body (and is not a [synthetic] test scene): nothing to simulate".into(),
        ));
    }
    if coupling.discrete_base > 0.0 && oracle.as_ref().is_some_and(|o| o.kind.adaptive()) {
        let span = raw.coupling.as_ref().and_then(|c| c.discrete_base.as_ref()).map(|t| t.span());
        return Err(ctx.err(
            span,
            Some("coupling.discrete_base"),
            "a discrete base is a layered zone fixed to the material: it takes oracle.kind = \"fixed\" (an adaptive oracle \
             places the zones itself and would drop the base at its first epoch)"
                .into(),
        ));
    }
    if !rigids.is_empty() && domain.periodic.iter().any(|&p| p) {
        return Err(ctx.err(
            None,
            Some("rigid"),
            "rigid bodies do not cross periodic boundaries yet: a scene with [[rigid]] bodies takes no `domain.periodic` axis".into(),
        ));
    }
    if !rigids.is_empty() && bodies.iter().any(|b| b.model == Model::Mpm) && bodies.iter().any(|b| b.model == Model::Dem) {
        return Err(ctx.err(
            None,
            Some("rigid"),
            "rigid bodies meet either grains or a continuum for now: with [[rigid]] bodies, \"dem\" and \"mpm\" [[body]] \
             tables do not mix (grains and points meet only in a hybrid band)"
                .into(),
        ));
    }
    if !rigids.is_empty() && bodies.iter().any(|b| b.model == Model::Hybrid) {
        return Err(ctx.err(
            None,
            Some("rigid"),
            "rigid bodies meet grains, walls and a continuum (Jiang 2020 §4), not a hybrid band yet: a scene with [[rigid]] \
             bodies takes \"dem\" and \"mpm\" [[body]] tables only"
                .into(),
        ));
    }
    if synthetic.is_some() && !(bodies.is_empty() && rigids.is_empty()) {
        return Err(ctx.err(
            None,
            Some("synthetic"),
            "a [synthetic] test scene cannot also have [[body]] tables: synthetic rasters never mix with physics".into(),
        ));
    }
    let scene = Scene {
        path: ctx.path.to_path_buf(),
        hash,
        name: run::name(ctx, &raw.run)?,
        dimension: run.dimension,
        dt: run.dt,
        steps: run.steps,
        seed: run.seed,
        threads: run.threads,
        domain,
        gravity,
        materials,
        bodies,
        walls,
        rigids,
        coupling,
        mpm,
        oracle,
        output,
        bridge,
        synthetic,
    };
    periodic_fits(ctx, &raw, &scene)?;
    if let (Some(r), Some(span)) = (
        scene.coupling.contact_radius,
        raw.coupling.as_ref().and_then(|c| c.contact_radius.as_ref()).map(|r| r.span()),
    ) {
        // Eq. 45's lower end is a guide (the paper's runs sit at it or below); its upper end
        // keeps a contact within the cell next to the body.
        let [lo, hi] = contact_radius_bounds(&scene);
        if r >= hi {
            return Err(ctx.err(
                Some(span),
                Some("coupling.contact_radius"),
                format!(
                    "must be below the cell size h = {hi:.4e} m (Jiang 2020 eq. 45: a contact stays within the cell at the body; \
                     the point spacing h / √n = {lo:.4e} m is the default), got {}",
                    crate::number(r)
                ),
            ));
        }
    }
    if scene.coupling.auto.is_some() && (scene.synthetic.is_some() || !scene.bodies.iter().any(|b| b.model == Model::Hybrid)) {
        let span = raw.coupling.as_ref().and_then(|c| c.substeps.as_ref()).map(|s| s.span());
        return Err(ctx.err(
            span,
            Some("coupling.substeps"),
            "\"auto\" picks the DEM and MPM steps of a hybrid scene (a DEM and an MPM coupled); this scene has no hybrid body: give a number".into(),
        ));
    }
    Ok(scene)
}

/// A periodic axis of a scene with a continuum: the MPM's grid wraps around, so the period
/// must be a whole number of cells; the adaptive oracles' surface searches do not wrap, so
/// a coupled periodic scene keeps its zones fixed.
fn periodic_fits(ctx: &Ctx, raw: &raw::RawScene, scene: &Scene) -> Result<(), SceneError> {
    let Some(span) = raw.domain.periodic.as_ref().map(|p| p.span()) else {
        return Ok(());
    };
    let roles = scene.participants();
    if !roles.contains(&Role::Mpm) {
        return Ok(());
    }
    let d = &scene.domain;
    for k in (0..scene.dim()).filter(|&k| d.periodic[k]) {
        let cells = (d.max[k] - d.min[k]) / d.cell_size;
        if (cells - cells.round()).abs() > 1e-6 * cells.max(1.0) {
            return Err(ctx.err(
                Some(span),
                Some("domain.periodic"),
                format!(
                    "a periodic axis of a scene with a continuum must be a whole number of cells long: axis {k} is {:.6} cells of `domain.cell_size` {} m (make `domain.max` − `domain.min` a multiple of it)",
                    cells, d.cell_size
                ),
            ));
        }
    }
    if roles.contains(&Role::Coupler) && scene.oracle.as_ref().is_some_and(|o| o.kind != OracleKind::Fixed) {
        let span = raw.oracle.as_ref().map(|o| o.kind.span()).unwrap_or(span);
        return Err(ctx.err(
            Some(span),
            Some("oracle.kind"),
            "a hybrid scene on a periodic domain needs `kind = \"fixed\"` (the layered, surface and shear-band oracles do not yet look across a periodic boundary)".into(),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::testing::{DEM, GOOD, TempDir, check_err, edit};
    use super::*;

    /// A confining pressure is a fluid around every body of material points: two mpm boxes
    /// take the same, or the scene says which body differs and what the other has.
    #[test]
    fn a_confining_pressure_is_the_same_on_every_mpm_body() {
        let box_at = |x: f64, p: &str| {
            format!(
                "[[body]]\nmaterial = \"m\"\nmodel = \"mpm\"\nshape = \"box\"\nmin = [{x}, 0.0]\nmax = [{}, 0.02]\n{p}",
                x + 0.02
            )
        };
        let scene = |a: &str, b: &str| {
            format!(
                "schema = 1\n[run]\ndimension = 2\ndt = 1e-5\nsteps = 1\n[domain]\nmin = [-0.01, -0.01]\nmax = [0.1, 0.1]\ncell_size = 0.002\n\
                 [[material]]\nname = \"m\"\ndensity = 2500.0\n[material.mpm]\nyoung = 1e6\npoisson = 0.3\nfriction_angle = 20.0\npacking = 0.8\n{}{}",
                box_at(0.0, a),
                box_at(0.05, b)
            )
        };
        let same = scene("confining_pressure = 1000.0\n", "confining_pressure = 1000.0\n");
        let s = from_str(&same, std::path::Path::new("c.toml"), 1).unwrap();
        assert!(s.bodies.iter().all(|b| b.confining_pressure == 1000.0));
        let text = scene("confining_pressure = 1000.0\n", "confining_pressure = 500.0\n");
        let line = text.lines().position(|l| l == "confining_pressure = 500.0").unwrap() + 1;
        check_err(&text, Some(line), "body.1.confining_pressure", "body.0 has 1000 Pa");
        // Unconfined, the second body is named at its model.
        let text = scene("confining_pressure = 1000.0\n", "");
        let line = text.lines().enumerate().filter(|(_, l)| l.starts_with("model")).nth(1).unwrap().0 + 1;
        check_err(
            &text,
            Some(line),
            "body.1.confining_pressure",
            "every body that is not frozen takes the same",
        );
    }

    /// Grains can be confined too (`grains_dem::fluid`): a DEM box takes the pressure, a frozen
    /// DEM body (a wall) needs none beside a confined one and cannot take one.
    #[test]
    fn a_dem_box_can_be_confined_and_a_frozen_one_cannot() {
        let scene = |bodies: &str| {
            format!(
                "schema = 1\n[run]\ndimension = 2\ndt = 1e-5\nsteps = 1\n[domain]\nmin = [-0.01, -0.01]\nmax = [0.1, 0.1]\ncell_size = 0.002\n\
                 [[material]]\nname = \"g\"\ndensity = 2500.0\n[material.dem]\nradius = 5e-4\nstiffness_normal = 1e6\nfriction = 0.5\nrestitution = 0.5\n\
                 [[body]]\nmaterial = \"g\"\nmodel = \"dem\"\nshape = \"box\"\nmin = [0.0, 0.002]\nmax = [0.02, 0.04]\n\
                 confining_pressure = 1000.0\n{bodies}"
            )
        };
        let floor = |p: &str| {
            format!(
                "[[body]]\nmaterial = \"g\"\nmodel = \"dem\"\nshape = \"box\"\nmin = [0.0, 0.0]\nmax = [0.02, 0.002]\nfrozen = true\n{p}"
            )
        };
        let s = from_str(&scene(&floor("")), std::path::Path::new("c.toml"), 1).unwrap();
        assert_eq!(s.bodies[0].confining_pressure, 1000.0);
        assert_eq!(s.bodies[1].confining_pressure, 0.0);
        let text = scene(&floor("confining_pressure = 1000.0\n"));
        let line = text
            .lines()
            .enumerate()
            .filter(|(_, l)| l.starts_with("confining_pressure"))
            .nth(1)
            .unwrap()
            .0
            + 1;
        check_err(&text, Some(line), "body.1.confining_pressure", "not frozen can be confined");
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
        // The shear-band oracle's fields: its own only, φ0 and the packing required, the
        // coefficients positive.
        check_err(
            &format!("{GOOD}[oracle]\nkind = \"surface\"\nc1 = 0.01\n"),
            Some(line + 1),
            "oracle.c1",
            "kind = \"shear_band\"",
        );
        check_err(
            &format!("{GOOD}[oracle]\nkind = \"shear_band\"\npacking = \"good.toml\"\n"),
            Some(line),
            "oracle.band_distance",
            "φ0",
        );
        check_err(
            &format!("{GOOD}[oracle]\nkind = \"shear_band\"\nband_distance = 0.01\npacking = \"none.data\"\n"),
            Some(line + 2),
            "oracle.packing",
            "no packing file",
        );
        check_err(
            &format!("{GOOD}[oracle]\nkind = \"shear_band\"\nband_distance = 0.01\nc_g = 0.0\n"),
            Some(line + 2),
            "oracle.c_g",
            "> 0",
        );
    }

    #[test]
    fn overrides_edit_tables_and_list_entries() {
        let dir = TempDir::new("overrides");
        let path = dir.write("s.toml", GOOD);
        let (s, text) = load_with_overrides(&path, &["run.steps=25".into(), "synthetic.dem_nodes = 7".into()]).unwrap();
        assert_eq!((s.steps, s.synthetic.as_ref().unwrap().dem_nodes), (25, 7));
        assert_eq!(s.hash, hash_bytes(text.as_bytes()));
        let e = load_with_overrides(&path, &["run.steps=-3".into()]).unwrap_err();
        assert!(e.message.contains("--set"), "{e}");
        let e = load_with_overrides(&path, &["run.dt.x=1".into()]).unwrap_err();
        assert_eq!(e.field.as_deref(), Some("run.dt.x"), "{e}");
        let e = load_with_overrides(&path, &["body.0.model=\"dem\"".into()]).unwrap_err();
        assert_eq!(e.field.as_deref(), Some("body.0.model"), "{e}");
        assert!(e.message.ends_with("index 0 is out of range: the list has 0 entries"), "{e}");
    }

    #[test]
    fn relative_file_paths_become_absolute_so_the_text_loads_anywhere() {
        let (a, b) = (TempDir::new("paths-a"), TempDir::new("paths-b"));
        let scene = format!(
            "{}\n[bridge]\nenabled = true\nsettings = \"bridge.toml\"\n",
            edit(DEM, "shape = \"box\"", "shape = \"box\"\npacking = \"bed.data\"")
        );
        let path = a.write("s.toml", &scene);
        let (packing, settings) = (a.write("bed.data", "0 atoms\n"), a.write("bridge.toml", ""));
        let (loaded, text) = load_with_overrides(&path, &[]).unwrap();
        assert_eq!(loaded.hash, hash_bytes(text.as_bytes()));
        // In B the file's own relative paths find nothing; the effective text's still do.
        let copy = b.write("s.toml", &text);
        let e = load(&b.write("as_written.toml", &scene)).unwrap_err();
        assert_eq!(e.field.as_deref(), Some("body.0.packing"), "{e}");
        let there = from_str(&text, &copy, 0).unwrap();
        assert_eq!(there.bodies[0].packing.as_deref(), Some(packing.as_path()));
        assert_eq!(there.bridge.unwrap().settings.as_deref(), Some(settings.as_path()));
        assert_eq!(loaded.bodies[0].packing.as_deref(), Some(packing.as_path()));
    }

    #[test]
    fn a_relative_path_given_by_an_override_is_relative_to_the_scene_file() {
        let dir = TempDir::new("paths-override");
        let path = dir.write("s.toml", DEM);
        let packing = dir.write("bed.data", "0 atoms\n");
        let (_, text) = load_with_overrides(&path, &["body.0.packing=\"bed.data\"".into()]).unwrap();
        let there = from_str(&text, Path::new("elsewhere/s.toml"), 0).unwrap();
        assert_eq!(there.bodies[0].packing.as_deref(), Some(packing.as_path()));
    }

    #[test]
    fn a_scene_without_relative_paths_or_overrides_comes_back_as_written() {
        let dir = TempDir::new("as-written");
        let packing = dir.write("bed.data", "0 atoms\n");
        let absolute = format!("packing = {:?}", packing.to_str().unwrap());
        for text in [
            DEM.to_string(),
            edit(DEM, "shape = \"box\"", &format!("shape = \"box\"\n{absolute}")),
        ] {
            let path = dir.write("s.toml", &text);
            let (scene, effective) = load_with_overrides(&path, &[]).unwrap();
            assert_eq!(effective, text);
            assert_eq!(scene.hash, hash_bytes(text.as_bytes()));
            assert_eq!(scene, load(&path).unwrap());
        }
    }

    #[test]
    fn duration_gives_the_step_count() {
        let s = from_str(&GOOD.replace("steps = 10", "duration = 0.01"), Path::new("g.toml"), 0).unwrap();
        assert_eq!(s.steps, 100);
    }

    /// The shipped periodic chute validates; a period that is not a whole number of cells
    /// and an adaptive oracle across the periodic boundary are refused, naming the field.
    #[test]
    fn a_periodic_continuum_needs_whole_cells_and_fixed_zones() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/chute_hybrid_2d.toml");
        let (s, _) = load_with_overrides(&path, &[]).unwrap();
        assert_eq!(s.domain.periodic, [true, false, false]);
        let e = load_with_overrides(&path, &["domain.max=[0.201,0.08]".into()]).unwrap_err();
        assert_eq!(e.field.as_deref(), Some("domain.periodic"), "{e}");
        assert!(e.to_string().contains("100.500000 cells"), "{e}");
        let e = load_with_overrides(&path, &["oracle={kind=\"surface\"}".into()]).unwrap_err();
        assert_eq!(e.field.as_deref(), Some("oracle.kind"), "{e}");
        // So is the shear-band oracle (its band distance does not wrap either).
        let band = format!("oracle={{kind=\"shear_band\", band_distance=0.01, packing=\"{}\"}}", path.display());
        let e = load_with_overrides(&path, &[band]).unwrap_err();
        assert_eq!(e.field.as_deref(), Some("oracle.kind"), "{e}");
        // A DEM-only periodic domain needs neither.
        let dem = [
            "domain.max=[0.201,0.08]".into(),
            "body.0.model=\"dem\"".into(),
            "coupling.substeps=1".into(),
            "run.dt=5e-6".into(),
        ];
        load_with_overrides(&path, &dem).unwrap();
    }

    /// `friction_angle_2` and `inertial_i0` come together, above `friction_angle`, with
    /// `drucker_prager`; errors name the missing or wrong field.
    #[test]
    fn a_rate_dependent_friction_needs_both_fields_above_the_static_angle() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/chute_hybrid_2d.toml");
        let set = |o: &[&str]| load_with_overrides(&path, &o.iter().map(|s| s.to_string()).collect::<Vec<_>>());
        let (s, _) = set(&["material.0.mpm.friction_angle_2=30.0", "material.0.mpm.inertial_i0=0.3"]).unwrap();
        let rate = s.materials[0].mpm.as_ref().unwrap().rate.unwrap();
        assert_eq!((rate.friction_angle_2, rate.i0), (30.0, 0.3));
        let e = set(&["material.0.mpm.friction_angle_2=30.0"]).unwrap_err();
        assert_eq!(e.field.as_deref(), Some("material.0.mpm.inertial_i0"), "{e}");
        let e = set(&["material.0.mpm.inertial_i0=0.3"]).unwrap_err();
        assert_eq!(e.field.as_deref(), Some("material.0.mpm.friction_angle_2"), "{e}");
        let e = set(&["material.0.mpm.friction_angle_2=10.0", "material.0.mpm.inertial_i0=0.3"]).unwrap_err();
        assert_eq!(e.field.as_deref(), Some("material.0.mpm.friction_angle_2"), "{e}");
        assert!(set(&["material.0.mpm.friction_angle_2=30.0", "material.0.mpm.inertial_i0=0.0"]).is_err());
        assert!(
            load_with_overrides(&path, &[]).unwrap().0.materials[0]
                .mpm
                .as_ref()
                .unwrap()
                .rate
                .is_none()
        );
    }

    #[test]
    fn a_good_dem_scene_validates() {
        let s = from_str(DEM, Path::new("dem.toml"), 0).unwrap();
        assert_eq!((s.materials.len(), s.bodies.len(), s.walls.len()), (2, 1, 2));
        assert_eq!(s.bodies[0].material, 1);
        assert_eq!(s.participants(), vec![Role::Dem]);
    }
}
