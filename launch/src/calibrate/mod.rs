//! `grains calibrate`: the continuum's parameters of a hybrid scene from a DEM element test of
//! its own grains, not from the case it is then compared with (Yue 2018 §3.3 tunes the
//! continuum to the DEM; Chen 2021 §2.2 calibrates on DEM element tests).
//!
//! The test is a plane-strain biaxial compression of the scene's grains (2D disks; 3D is not
//! done yet): a jittered lattice of `--grains` grains in a box of four frictionless walls,
//! no gravity, consolidated to the confining pressure p0 (servo-controlled walls), then
//! shortened at a constant axial strain rate with the lateral stress held at p0. The axial
//! rate keeps the inertial number I = ε̇ d √(ρ / p0) at `--inertial` (quasi-static: the
//! measured friction does not depend on the rate below about 1e-3, GDR MiDi 2004).
//!
//! In 2D the Mohr–Coulomb friction angle φ of the principal stresses σ1 ≥ σ3 (compression
//! positive) is sin φ = (σ1 − σ3) / (σ1 + σ3). The continuum of grains is Drucker–Prager with
//! the plane Mohr–Coulomb cone (‖dev τ‖ = √2 sin φ p, `DruckerPragerYue::new`), perfectly
//! plastic, so by default it takes the critical-state angle: the mean over axial strains
//! 15–30 %, after the peak; `--strength peak` takes the peak instead, for a continuum that the
//! run shears less than the peak's strain. Its Young's modulus is the initial one: the
//! deviator's least-squares slope over the first 0.1 % of axial strain, E = (1 − ν²) Δσ1 / Δε1 with the scene's ν (Yue 2018 §3.3:
//! ν = 0.3); the secant modulus at half the peak (E50) is printed beside it. (An isotropic
//! unloading from 1.1 p0 to 0.9 p0 was tried for a bulk modulus: the sample's creep at p0 is
//! of the same size as the elastic volume change, and the modulus came out negative.)
//!
//! `--write` records the result in the scene file: `friction_angle`, `young` and a
//! `calibration` line saying where they come from, in the scene's `[material.mpm]`.
//!
//! `--shear` runs the constant-pressure simple shear of [`shear`] instead: the friction's
//! rate dependence μ(I) and the shear's transient from a consolidated sample (printed only).

pub mod repose;
pub mod shear;

use anyhow::{Context, bail};
use grains_dem::packing::lattice_in_box;
use grains_dem::pipeline::DemPipeline;
use grains_dem::space::{D2, Space};
use grains_dem::state::{DemParams, DemState, Domain, Grains, Wall, WallShape};
use grains_grid::rng::{Rng, radius};
use grains_protocol::scene::{self, Dimension, Model, Scene};
use std::path::PathBuf;

/// Threads of every calibration test, whatever the scene's `run.threads`. A test is one
/// chaotic trajectory, and contact forces summed in two ranges instead of one change its bits:
/// the biaxial test of the drum's and the silo's grains gave 12.79° on two threads, 13.61° on one
/// (another seed moves it as much). On one thread a material's calibration is the same in
/// every scene that uses it.
pub(crate) const THREADS: usize = 1;

#[derive(Debug, Clone, clap::Args)]
pub struct CalibrateArgs {
    /// A hybrid scene: its first hybrid body's material is calibrated.
    pub scene: PathBuf,
    /// Grains in the sample (about twice as tall as wide).
    #[arg(long, default_value_t = 2400)]
    pub grains: usize,
    /// Confining pressure p0 [Pa] (default: the weight of half the hybrid body's height,
    /// ρ_bulk |g| H / 2, the stress level the continuum works at).
    #[arg(long)]
    pub pressure: Option<f64>,
    /// Inertial number of the axial shortening.
    #[arg(long, default_value_t = 1e-3)]
    pub inertial: f64,
    /// Seed of the sample's radii and lattice jitter.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Which strength `--write` records as the friction angle: the biaxial test's critical
    /// state (flows that shear far past the peak: collapses, silos) or peak (dense material
    /// sheared less than the peak's strain over the run: a flow starting from rest), or the
    /// angle of repose of poured DEM piles (Yue 2018 §3.3: layers that flow on a slope and
    /// stop, chutes).
    #[arg(long, value_enum, default_value_t = Strength::Critical, conflicts_with = "shear")]
    pub strength: Strength,
    /// Friction coefficient of the grains while the sample consolidates (restored before the
    /// shortening): lower gives a denser sample, for a peak at the state of a bed poured
    /// denser than the default sample (Chen 2021 §4.1 prepares dense packings at μ = 0.01).
    #[arg(long, conflicts_with = "shear")]
    pub prep_friction: Option<f64>,
    /// Write the result into the scene file's `[material.mpm]` (the biaxial test's).
    #[arg(long)]
    pub write: bool,
    /// Run the constant-pressure simple shear at `--inertials` instead of the biaxial test:
    /// the friction's rate dependence μ(I) and the fit of `friction_angle_2` and `inertial_i0`
    /// (printed, not written: see docs/user-guide.md).
    #[arg(long, conflicts_with = "write")]
    pub shear: bool,
    /// Inertial numbers of the shear, increasing.
    #[arg(long, value_delimiter = ',', default_values_t = [1e-3, 3e-3, 1e-2, 3e-2, 1e-1, 3e-1])]
    pub inertials: Vec<f64>,
    /// Shear strain held at each inertial number (the first quarter is the transient).
    #[arg(long, default_value_t = 2.0)]
    pub strain: f64,
    /// Piles poured for `--strength repose` (seeds `--seed` on), their angles averaged: one
    /// pile's flanks scatter by about a degree.
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u64).range(1..))]
    pub piles: u64,
    /// Width of the piles' rough floor [mean grain diameters] (`--strength repose`).
    #[arg(long, default_value_t = 100.0)]
    pub repose_width: f64,
}

/// The biaxial test's strength a scene's continuum takes as its friction angle.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Strength {
    /// The mean over the critical-state window (axial strain 15–30 %).
    Critical,
    /// The largest mobilized friction.
    Peak,
    /// The continuum whose layer on a slope stops at the poured piles' angle of repose θ_r:
    /// sin φ = tan θ_r ([`repose`]).
    Repose,
}

/// One record of the test.
#[derive(Clone, Copy, Debug)]
pub struct Record {
    /// Axial strain (shortening positive).
    pub axial: f64,
    /// Volumetric strain (compaction positive).
    pub volumetric: f64,
    pub sigma1: f64,
    pub sigma3: f64,
}

impl Record {
    pub fn sin_phi(&self) -> f64 {
        (self.sigma1 - self.sigma3) / (self.sigma1 + self.sigma3)
    }
}

/// What a biaxial test gives.
#[derive(Clone, Debug)]
pub struct Calibration {
    pub records: Vec<Record>,
    pub pressure: f64,
    pub grains: usize,
    pub strain_rate: f64,
    /// Peak and critical-state (mean over 15–30 % axial strain) friction angles [degrees].
    pub peak: f64,
    pub critical: f64,
    /// The spread (standard deviation) of φ over the critical-state window [degrees].
    pub critical_spread: f64,
    /// Plane-strain secant modulus at half the peak deviator Δσ1/Δε1 [Pa].
    pub e50_plane: f64,
    /// Plane-strain initial modulus: the deviator's slope over the first 0.1 % of axial
    /// strain [Pa].
    pub e0_plane: f64,
    /// The mean lateral stress over the critical-state window, over p0 (the servo's hold).
    pub lateral_mean: f64,
    /// The sample's packing fraction when the shortening starts (grain area over the box's):
    /// the peak belongs to this state, and a denser bed has a higher one.
    pub packing: f64,
    /// The piles of `--strength repose` (none otherwise).
    pub piles: Vec<repose::Pile>,
}

impl Calibration {
    /// The friction angle [deg] of `strength`.
    pub fn friction(&self, strength: Strength) -> f64 {
        match strength {
            Strength::Critical => self.critical,
            Strength::Peak => self.peak,
            Strength::Repose => repose::continuum_angle(self.repose_angle()),
        }
    }

    /// The piles' mean angle of repose [deg] (NaN without piles).
    pub fn repose_angle(&self) -> f64 {
        self.piles.iter().map(repose::Pile::angle).sum::<f64>() / self.piles.len() as f64
    }

    fn young_of(&self, plane: f64, poisson: f64) -> f64 {
        (1.0 - poisson * poisson) * plane
    }

    /// Young's modulus of the continuum for Poisson's ratio ν: the initial one, E = (1 − ν²)
    /// E0_plane (plane strain with σ3 held: dσ1/dε1 = E / (1 − ν²)). The continuum's elasticity
    /// is the packing's small-strain response (Yue 2018 §3.3 takes κ from the contact
    /// stiffness), its plasticity Drucker–Prager's.
    pub fn young(&self, poisson: f64) -> f64 {
        self.young_of(self.e0_plane, poisson)
    }
}

/// The material of a scene to calibrate: its first hybrid body's.
pub fn hybrid_material(scene: &Scene) -> anyhow::Result<usize> {
    let Some(b) = scene.bodies.iter().find(|b| b.model == Model::Hybrid) else {
        bail!(crate::run::BadInput(format!(
            "{}: grains calibrate needs a scene with a hybrid body (its DEM grains set the continuum's parameters)",
            scene.path.display()
        )));
    };
    let m = &scene.materials[b.material];
    if m.dem.is_none() || m.mpm.is_none() {
        bail!(crate::run::BadInput(format!(
            "{}: material `{}` needs both [material.dem] and [material.mpm]",
            scene.path.display(),
            m.name
        )));
    }
    Ok(b.material)
}

/// The default confining pressure: the weight of half the hybrid body's height.
pub fn default_pressure(scene: &Scene, material: usize) -> f64 {
    let m = &scene.materials[material];
    let packing = m.mpm.as_ref().map_or(1.0, |p| p.packing);
    let g = scene.gravity.iter().map(|x| x * x).sum::<f64>().sqrt();
    let height = scene
        .bodies
        .iter()
        .filter(|b| b.model == Model::Hybrid)
        .map(|b| match b.shape {
            grains_protocol::scene::Shape::Box { min, max } => max[1] - min[1],
            grains_protocol::scene::Shape::Ball { radius, .. } => 2.0 * radius,
        })
        .fold(0.0, f64::max);
    m.density * packing * g * 0.5 * height
}

/// Runs the biaxial test of material `material` of `scene`.
pub fn biaxial(scene: &Scene, material: usize, o: &CalibrateOptions) -> anyhow::Result<Calibration> {
    let (grains, pressure, inertial, seed) = (o.grains, o.pressure, o.inertial, o.seed);
    if scene.dimension != Dimension::Two {
        bail!(crate::run::BadInput(
            "grains calibrate runs the 2D biaxial test; the 3D triaxial test is not built yet".into()
        ));
    }
    let mat = &scene.materials[material];
    let dem = mat.dem.as_ref().context("a DEM material")?;
    let params = grains_dem_service::setup::contact_params(dem);
    // Frictionless walls: the box's faces are principal planes.
    let d = 2.0 * dem.radius;
    // A lattice of about `grains` sites, twice as tall as wide, spacing just over the largest
    // diameter so that nothing overlaps at the start.
    let r_max = dem.radius + 2.0 * dem.radius_std;
    let spacing = 2.04 * r_max;
    // cols × rows grains, rows = 2 × cols / (√3 / 2) on a box twice as tall as wide.
    let cols = (grains as f64 * 3f64.sqrt() / 4.0).sqrt().round().max(4.0);
    let width = cols * spacing + 2.0 * r_max;
    let height = 2.0 * width;
    let mut state = box_sample(mat, width, height, seed)?;
    let n = state.grains.len();
    let (safe, ..) = grains_dem_service::setup::stable_step(scene).context("the scene's DEM step")?;
    let dt = safe;
    let mut pipe = DemPipeline::<D2>::new(THREADS)?;
    // The axial strain rate of inertial number I: ε̇ = I / (d √(ρ / p0)).
    let rate = inertial / (d * (mat.density / pressure).sqrt());
    const FINE: f64 = 0.0002;
    // The consolidation is preparation: its walls move at the quasi-static rate (I = 1e-3)
    // whatever the shear's (faster, they ring and the sample never settles: seen at 1e-2).
    let settle_rate = rate.min(1e-3 / (d * (mat.density / pressure).sqrt()));
    let run = |st: &mut DemState<D2>, pipe: &mut DemPipeline<D2>, n: usize| box_stresses(st, pipe, dt, n);
    if let Some(mu) = o.prep_friction {
        state.params.materials[0].friction = mu;
    }
    consolidate_box(&mut state, &mut pipe, dt, pressure, settle_rate)?;
    state.params.materials[0].friction = params.friction;
    // Shear: the top wall moves down at ε̇ H0, the right wall holds σ3 = p0, to 30 % of axial
    // strain.
    let (sx0, sy0, w0, h0) = run(&mut state, &mut pipe, SERVO_STEPS);
    let q0 = sy0 - sx0;
    let packing = state.grains.radius.iter().map(|r| std::f64::consts::PI * r * r).sum::<f64>() / (w0 * h0);
    let mut records = Vec::new();
    // Records every 0.02 % of axial strain up to 0.5 % (the start), then every 0.25 %.
    let mut next = FINE;
    let mut integral = 0.0;
    while next <= 0.3 + 1e-9 {
        if grains_service::signals::signalled() {
            bail!("stopped by a signal");
        }
        // The top wall comes up to speed over the first 0.1 % of strain (a sudden start sends a
        // stress wave through the sample).
        let axial_now = 1.0 - (wall_at(&state.walls[3], 1) - wall_at(&state.walls[2], 1)) / h0;
        let ramp = (axial_now / 0.001).clamp(0.05, 1.0);
        state.walls[3].velocity = D2::from_array([0.0, -ramp * rate * h0, 0.0]);
        let (sxx, syy, w, h) = run(&mut state, &mut pipe, SERVO_STEPS);
        if let Some(id) = DemPipeline::first_non_finite(&state) {
            bail!("grain {id} is not finite: the biaxial test blew up");
        }
        // The right wall opens as a sample of constant volume would (ε̇x = −ε̇y), corrected by
        // the lateral stress error (dilation opens it further, contraction less). The
        // correction's gain is low: the stress answers a wall's move only after a wave has
        // crossed the sample (hundreds of steps), and a quicker servo rings.
        // An integral term takes out the lasting error that dilation leaves.
        let error = sxx / pressure - 1.0;
        integral = (integral + 0.02 * error).clamp(-1.0, 1.0);
        let correction = (0.5 * error + integral).clamp(-1.0, 2.0);
        state.walls[1].velocity = D2::from_array([ramp * rate * w * (1.0 + correction), 0.0, 0.0]);
        let axial = 1.0 - h / h0;
        if axial >= next {
            records.push(Record {
                axial,
                volumetric: 1.0 - (w * h) / (w0 * h0),
                sigma1: syy,
                sigma3: sxx,
            });
            next += if next < 0.005 { FINE } else { 0.0025 };
        }
    }
    let angle = |s: f64| s.asin().to_degrees();
    let peak = records.iter().map(Record::sin_phi).fold(f64::MIN, f64::max);
    let window: Vec<f64> = records
        .iter()
        .filter(|r| (0.15..=0.3).contains(&r.axial))
        .map(|r| angle(r.sin_phi()))
        .collect();
    let critical = window.iter().sum::<f64>() / window.len() as f64;
    let lateral: Vec<f64> = records
        .iter()
        .filter(|r| (0.15..=0.3).contains(&r.axial))
        .map(|r| r.sigma3 / pressure)
        .collect();
    let lateral_mean = lateral.iter().sum::<f64>() / lateral.len() as f64;
    if (lateral_mean - 1.0).abs() > 0.1 {
        bail!(
            "the lateral stress was not held at p0 over the critical-state window (mean {lateral_mean:.2} p0): the servo cannot \
             follow this shear rate; lower --inertial"
        );
    }
    let critical_spread = (window.iter().map(|a| (a - critical).powi(2)).sum::<f64>() / window.len() as f64).sqrt();
    // Moduli from the change since the start of the shear (the consolidation leaves the two
    // stresses within 2 % of p0, not equal). E0: the least-squares slope (with an intercept)
    // of the deviator against the axial strain over the first 0.1 %; E50: the secant to the
    // first record past half the peak deviator.
    let q = |r: &Record| r.sigma1 - r.sigma3;
    let q_peak = records.iter().map(q).fold(f64::MIN, f64::max);
    let half = records
        .iter()
        .find(|r| q(r) - q0 >= 0.5 * (q_peak - q0))
        .context("no record reached half the peak")?;
    let e50_plane = (q(half) - q0) / half.axial.max(f64::MIN_POSITIVE);
    let first: Vec<(f64, f64)> = records
        .iter()
        .filter(|r| r.axial <= 0.001 + 1e-12)
        .map(|r| (r.axial, q(r)))
        .collect();
    let m = first.len() as f64;
    let (sx, sy) = (
        first.iter().map(|p| p.0).sum::<f64>() / m,
        first.iter().map(|p| p.1).sum::<f64>() / m,
    );
    let e0_plane = first.iter().map(|p| (p.0 - sx) * (p.1 - sy)).sum::<f64>()
        / first.iter().map(|p| (p.0 - sx).powi(2)).sum::<f64>().max(f64::MIN_POSITIVE);
    Ok(Calibration {
        records,
        pressure,
        grains: n,
        strain_rate: rate,
        peak: angle(peak),
        critical,
        critical_spread,
        e50_plane,
        e0_plane,
        lateral_mean,
        packing,
        piles: Vec::new(),
    })
}

/// A box sample of `mat`'s grains (2D): a jittered lattice spaced just over the largest
/// diameter (so that nothing overlaps) in a box `width` × `height` from the origin, no
/// gravity, between four frictionless plane walls: left, right, bottom, top.
pub(crate) fn box_sample(mat: &scene::Material, width: f64, height: f64, seed: u64) -> anyhow::Result<DemState<D2>> {
    let dem = mat.dem.as_ref().context("a DEM material")?;
    let r_max = dem.radius + 2.0 * dem.radius_std;
    let d = 2.0 * dem.radius;
    let mut rng = Rng::new(seed);
    let sites = lattice_in_box::<D2>(
        [0.0; 3],
        [width, height, 0.0],
        2.04 * r_max,
        1.01 * r_max,
        0.01 * dem.radius,
        &mut rng,
    );
    let params = grains_dem_service::setup::contact_params(dem);
    let mut state = DemState::<D2> {
        grains: Grains::default(),
        bodies: Vec::new(),
        walls: vec![
            Wall::plane(D2::from_array([0.0, 0.0, 0.0]), D2::from_array([1.0, 0.0, 0.0]), 0.0),
            Wall::plane(D2::from_array([width, 0.0, 0.0]), D2::from_array([-1.0, 0.0, 0.0]), 0.0),
            Wall::plane(D2::from_array([0.0, 0.0, 0.0]), D2::from_array([0.0, 1.0, 0.0]), 0.0),
            Wall::plane(D2::from_array([0.0, height, 0.0]), D2::from_array([0.0, -1.0, 0.0]), 0.0),
        ],
        params: DemParams {
            materials: vec![params],
            gravity: D2::from_array([0.0; 3]),
            domain: Domain {
                min: [-width, -height, 0.0],
                max: [2.0 * width, 2.0 * height, 0.0],
                periodic: [false; 3],
            },
            skin: 0.1 * d,
        },
        time: 0.0,
    };
    for (k, &x) in sites.iter().enumerate() {
        let r = radius(&mut rng, dem.radius, dem.radius_std);
        state.grains.push(k as u64, x, r, Grains::<D2>::mass_of(r, mat.density), 0);
    }
    Ok(state)
}

/// The walls of a box sample are servo-controlled every SERVO_STEPS steps: a wall moves at
/// GAIN × 10 ε̇ L times the relative stress error (clamped to ±1), closing while the stress is
/// below the target and opening above it (a larger gain rings: the stress on the walls swings
/// from one interval to the next).
const SERVO_STEPS: usize = 50;
const GAIN: f64 = 0.1;

/// The stresses σxx, σyy [Pa] on the walls of a box sample (walls left, right, bottom, top:
/// planes, in that order) averaged over `n` steps of dt (a single step's load rattles with the
/// grains' vibrations), and the box's width and height after them.
pub(crate) fn box_stresses(st: &mut DemState<D2>, pipe: &mut DemPipeline<D2>, dt: f64, n: usize) -> (f64, f64, f64, f64) {
    let (mut fx, mut fy) = (0.0, 0.0);
    for _ in 0..n {
        pipe.run(st, dt, 1);
        fx += 0.5 * (st.walls[0].load[0].abs() + st.walls[1].load[0].abs());
        fy += 0.5 * (st.walls[2].load[1].abs() + st.walls[3].load[1].abs());
    }
    let w = wall_at(&st.walls[1], 0) - wall_at(&st.walls[0], 0);
    let h = wall_at(&st.walls[3], 1) - wall_at(&st.walls[2], 1);
    // Loads are the grains' push on each wall [N/m]; stress = load / length [Pa].
    (fx / n as f64 / h, fy / n as f64 / w, w, h)
}

/// Isotropic consolidation of a box sample ([`box_stresses`]' walls) to `target` [Pa]: the
/// right and top walls move, at most at `rate` [1/s] times GAIN × 10, until both sides hold it
/// within 2 % and the grains are nearly at rest (at most 2 s of simulated time); the box's
/// width and height then, its walls stopped.
pub(crate) fn consolidate_box(
    st: &mut DemState<D2>,
    pipe: &mut DemPipeline<D2>,
    dt: f64,
    target: f64,
    rate: f64,
) -> anyhow::Result<(f64, f64)> {
    let servo = |st: &mut DemState<D2>, wall: usize, axis: usize, measured: f64, length: f64| {
        let error = ((target - measured) / target).clamp(-1.0, 1.0);
        let mut v = [0.0; 3];
        v[axis] = -error * GAIN * 10.0 * rate * length;
        st.walls[wall].velocity = D2::from_array(v);
    };
    for _ in 0..((2.0 / dt) as usize / SERVO_STEPS) {
        if grains_service::signals::signalled() {
            bail!("stopped by a signal");
        }
        let (sxx, syy, w, h) = box_stresses(st, pipe, dt, SERVO_STEPS);
        // Preparation only: the grains' velocities are damped (2 % per servo interval) so
        // that the sample comes to rest; the shear that is measured runs without it.
        st.grains.v.iter_mut().for_each(|v| *v *= 0.98);
        st.grains.omega.iter_mut().for_each(|w| *w *= 0.98);
        let ke = DemPipeline::kinetic_energy(st);
        tracing::trace!("consolidation to {target:.1} Pa: σxx {sxx:.1} σyy {syy:.1} Pa, w {w:.5} h {h:.5} m, ke {ke:.3e} J");
        if (sxx / target - 1.0).abs() < 0.02 && (syy / target - 1.0).abs() < 0.02 && ke < 1e-5 * target * w * h {
            st.walls.iter_mut().for_each(|w| w.velocity = D2::from_array([0.0; 3]));
            return Ok((w, h));
        }
        servo(st, 1, 0, sxx, w);
        servo(st, 3, 1, syy, h);
    }
    bail!("the sample did not settle at {target:.1} Pa within 2 s: stiffness, pressure or grain count out of reach")
}

/// A plane wall's position along `axis`.
fn wall_at<S: Space>(w: &Wall<S>, axis: usize) -> f64 {
    match w.shape {
        WallShape::Plane { point, .. } => S::to_array(point)[axis],
        _ => 0.0,
    }
}

/// What `--write` puts in the scene: the command that reproduces the numbers (its options, as
/// [`CalibrateOptions::parse`] reads them back) and what they are.
pub fn provenance(c: &Calibration, o: &CalibrateOptions) -> String {
    let friction = match o.strength {
        Strength::Critical => format!("critical state (mean over axial strain 15-30 %, peak {:.1} deg)", c.peak),
        Strength::Peak => format!("peak (critical state {:.1} deg over axial strain 15-30 %)", c.critical),
        Strength::Repose => format!(
            "the continuum whose layer stops at the angle of repose of {} DEM piles poured on a rough floor, {:.2} deg \
             (sin phi = tan theta; biaxial peak {:.1}, critical state {:.1} deg)",
            c.piles.len(),
            c.repose_angle(),
            c.peak,
            c.critical
        ),
    };
    format!(
        "grains calibrate {}: DEM biaxial test of this material ({} grains); friction_angle = {friction}, young = initial \
         slope of the loading (first 0.1 % of axial strain, plane strain)",
        o, c.grains
    )
}

/// The options of a calibration that decide its result.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CalibrateOptions {
    pub grains: usize,
    pub seed: u64,
    pub pressure: f64,
    pub inertial: f64,
    pub strength: Strength,
    pub prep_friction: Option<f64>,
    /// Piles and their floor's width [D50] of `Strength::Repose` (not read otherwise).
    pub piles: u64,
    pub repose_width: f64,
}

impl std::fmt::Display for CalibrateOptions {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "--grains {} --seed {} --pressure {} --inertial {:e}",
            self.grains, self.seed, self.pressure, self.inertial
        )?;
        // Defaults are left out, so that the lines written before the options still read.
        if let Some(mu) = self.prep_friction {
            write!(f, " --prep-friction {mu}")?;
        }
        match self.strength {
            Strength::Critical => Ok(()),
            Strength::Peak => write!(f, " --strength peak"),
            Strength::Repose => write!(f, " --strength repose --piles {} --repose-width {}", self.piles, self.repose_width),
        }
    }
}

impl CalibrateOptions {
    /// The options written at the head of a provenance line (`grains calibrate --grains N
    /// --seed S --pressure P --inertial I: ...`).
    pub fn parse(provenance: &str) -> Option<CalibrateOptions> {
        let flags = provenance.strip_prefix("grains calibrate ")?.split(':').next()?;
        let words: Vec<&str> = flags.split_whitespace().collect();
        let value = |name: &str| words.iter().position(|w| *w == name).and_then(|k| words.get(k + 1));
        Some(CalibrateOptions {
            grains: value("--grains")?.parse().ok()?,
            seed: value("--seed")?.parse().ok()?,
            pressure: value("--pressure")?.parse().ok()?,
            inertial: value("--inertial")?.parse().ok()?,
            strength: match value("--strength") {
                None => Strength::Critical,
                Some(&"peak") => Strength::Peak,
                Some(&"critical") => Strength::Critical,
                Some(&"repose") => Strength::Repose,
                Some(_) => return None,
            },
            prep_friction: match value("--prep-friction") {
                None => None,
                Some(v) => Some(v.parse().ok()?),
            },
            piles: value("--piles").map_or(Some(3), |v| v.parse().ok())?,
            repose_width: value("--repose-width").map_or(Some(100.0), |v| v.parse().ok())?,
        })
    }
}

/// Calibrates the hybrid material of `scene` with `o`: (material index, result).
pub fn run_for(scene: &Scene, o: &CalibrateOptions) -> anyhow::Result<(usize, Calibration)> {
    let material = hybrid_material(scene)?;
    let mut c = biaxial(scene, material, o)?;
    if o.strength == Strength::Repose {
        for seed in o.seed..o.seed + o.piles {
            tracing::info!(
                "calibrate: pile {} of {}, floor {} D50 wide, seed {seed}",
                seed - o.seed + 1,
                o.piles,
                o.repose_width
            );
            c.piles.push(repose::pile(scene, material, o.repose_width, seed)?);
        }
    }
    Ok((material, c))
}

pub fn calibrate(args: &CalibrateArgs) -> anyhow::Result<()> {
    let scene = scene::load(&args.scene)?;
    let material = hybrid_material(&scene)?;
    let options = CalibrateOptions {
        grains: args.grains,
        seed: args.seed,
        pressure: args.pressure.unwrap_or_else(|| default_pressure(&scene, material)),
        inertial: args.inertial,
        strength: args.strength,
        prep_friction: args.prep_friction,
        piles: args.piles,
        repose_width: args.repose_width,
    };
    let mpm = scene.materials[material].mpm.as_ref().expect("checked");
    if args.shear {
        return shear_table(&scene, material, args, &options);
    }
    tracing::info!("calibrate: biaxial test of `{}`: {options}", scene.materials[material].name);
    let (_, c) = run_for(&scene, &options)?;
    println!("axial_strain,volumetric_strain,sigma1_Pa,sigma3_Pa,phi_deg");
    for r in &c.records {
        println!(
            "{:.4},{:.5},{:.2},{:.2},{:.2}",
            r.axial,
            r.volumetric,
            r.sigma1,
            r.sigma3,
            r.sin_phi().asin().to_degrees()
        );
    }
    let young = c.young(mpm.poisson);
    println!(
        "# {} grains at p0 = {:.1} Pa, axial rate {:.3e} 1/s: peak {:.2} deg, critical state {:.2} deg (sd {:.2}); \
         E = {young:.4e} Pa from the initial slope {:.4e} Pa (plane strain, nu = {}); secant E50 = {:.4e} Pa; \
         mean sigma3 over the window {:.3} p0; packing fraction at the start of the shortening {:.4}",
        c.grains,
        c.pressure,
        c.strain_rate,
        c.peak,
        c.critical,
        c.critical_spread,
        c.e0_plane,
        mpm.poisson,
        c.young_of(c.e50_plane, mpm.poisson),
        c.lateral_mean,
        c.packing,
    );
    if !c.piles.is_empty() {
        println!("pile,x_m,height_m");
        for (k, p) in c.piles.iter().enumerate() {
            for (x, h) in &p.surface {
                println!("{k},{x:.5},{h:.5}");
            }
        }
        for (k, p) in c.piles.iter().enumerate() {
            println!(
                "# pile {k} (seed {}): {} grains ({} poured), {:.4} m high, after {:.2} s: flanks {:.2} and {:.2} deg",
                options.seed + k as u64,
                p.grains,
                p.poured,
                p.height,
                p.time,
                p.left,
                p.right
            );
        }
        println!(
            "# angle of repose {:.2} deg over {} piles; the continuum whose layer stops there (sin phi = tan theta): {:.2} deg",
            c.repose_angle(),
            c.piles.len(),
            c.friction(Strength::Repose)
        );
    }
    if args.write {
        let text = std::fs::read_to_string(&args.scene)?;
        let name = &scene.materials[material].name;
        let edited = write_calibration(&text, name, c.friction(options.strength), young, &provenance(&c, &options))
            .with_context(|| format!("{}: writing the calibration", args.scene.display()))?;
        crate::run::outputs::write_atomic(&args.scene, edited.as_bytes())?;
        tracing::info!(
            "calibrate: wrote friction_angle, young and calibration into {}",
            args.scene.display()
        );
    }
    Ok(())
}

/// `--shear`: the shear cell's table and the μ(I) fit.
fn shear_table(scene: &Scene, material: usize, args: &CalibrateArgs, o: &CalibrateOptions) -> anyhow::Result<()> {
    if args.inertials.windows(2).any(|w| w[1] <= w[0]) || args.inertials.iter().any(|&i| i.is_nan() || i <= 0.0) {
        bail!(crate::run::BadInput(format!(
            "--inertials: positive and increasing, got {:?}",
            args.inertials
        )));
    }
    tracing::info!(
        "calibrate: constant-pressure simple shear of `{}`: --grains {} --seed {} --pressure {} at I = {:?}, strain {} each",
        scene.materials[material].name,
        o.grains,
        o.seed,
        o.pressure,
        args.inertials,
        args.strain
    );
    let shear = shear::simple_shear(scene, material, o.grains, o.pressure, &args.inertials, args.strain, o.seed)?;
    println!(
        "# the first shear's start, from the consolidated sample (packing {:.4})",
        shear.packing0
    );
    println!("strain,sin_phi,mu_xy,packing");
    for r in &shear.transient {
        println!("{:.3},{:.4},{:.4},{:.4}", r.strain, r.sin_phi, r.mu, r.packing);
    }
    match shear::critical_state(&shear.transient) {
        Some(c) => println!(
            "# critical state (model = \"critical_state\"): friction_angle = {:.2}, packing_critical = {:.4}, chi = {:.2}, xi = {:.2} \
             (peak sin phi {:.4} at strain {:.2}, packing {:.4})",
            c.friction_angle, c.packing_critical, c.chi, c.xi, c.peak_sin, c.peak_strain, c.peak_packing
        ),
        None => println!("# critical state: no peak denser than the critical state in the first shear"),
    }
    let points = &shear.points;
    println!("inertial_target,inertial,pressure_Pa,sin_phi,sin_phi_sd,phi_deg,mu_xy,sxx_over_syy");
    for p in points {
        println!(
            "{:e},{:.4e},{:.2},{:.4},{:.4},{:.2},{:.4},{:.3}",
            p.target,
            p.inertial,
            p.pressure,
            p.sin_phi,
            p.spread,
            p.sin_phi.asin().to_degrees(),
            p.mu,
            p.normal_ratio
        );
    }
    match shear::fit(&points.iter().map(|p| (p.inertial, p.sin_phi)).collect::<Vec<_>>()) {
        Some(f) if f.sin_dynamic > f.sin_static && f.sin_static > 0.0 && f.sin_dynamic < 1.0 => println!(
            "# mu(I) on sin phi: friction_angle = {:.2}, friction_angle_2 = {:.2}, inertial_i0 = {:.4} (rms {:.4} in sin phi)",
            f.sin_static.asin().to_degrees(),
            f.sin_dynamic.asin().to_degrees(),
            f.i0,
            f.rms
        ),
        Some(f) => println!(
            "# mu(I) fit out of the law's range (sin phi static {:.4}, dynamic {:.4}, I0 {:.4}): the friction does not grow with I here",
            f.sin_static, f.sin_dynamic, f.i0
        ),
        None => println!("# mu(I): fewer than three inertial numbers, no fit"),
    }
    Ok(())
}

/// The scene text with `friction_angle`, `young` and `calibration` of the `[material.mpm]` table
/// of material `name` set (lines replaced in place, or added at the table's end); the rest of
/// the file, comments included, as it was.
pub fn write_calibration(text: &str, name: &str, friction_angle: f64, young: f64, provenance: &str) -> anyhow::Result<String> {
    let lines: Vec<&str> = text.lines().collect();
    let header = |l: &str| l.trim_start().starts_with('[');
    // The [[material]] whose name is `name`, then its [material.mpm].
    let mut start = None;
    for (k, l) in lines.iter().enumerate() {
        if l.trim() == "[[material]]" {
            let table_end = (k + 1..lines.len()).find(|&j| header(lines[j])).unwrap_or(lines.len());
            if lines[k + 1..table_end]
                .iter()
                .any(|l| l.split('#').next().unwrap_or("").replace(' ', "") == format!("name=\"{name}\""))
            {
                start = Some(k);
                break;
            }
        }
    }
    let start = start.with_context(|| format!("no [[material]] named {name:?}"))?;
    let mpm = (start + 1..lines.len())
        .take_while(|&j| lines[j].trim() != "[[material]]")
        .find(|&j| lines[j].trim() == "[material.mpm]")
        .with_context(|| format!("material {name:?} has no [material.mpm] table"))?;
    let end = (mpm + 1..lines.len()).find(|&j| header(lines[j])).unwrap_or(lines.len());
    let values = [
        ("friction_angle", format!("{friction_angle:.2}")),
        ("young", format!("{young:.4e}")),
        ("calibration", toml_string(provenance)),
    ];
    let mut out: Vec<String> = lines.iter().map(|l| l.to_string()).collect();
    let mut missing = Vec::new();
    for (key, value) in &values {
        let at = (mpm + 1..end).find(|&j| {
            let l = lines[j].trim_start();
            l.starts_with(key) && l[key.len()..].trim_start().starts_with('=')
        });
        match at {
            // A comment after the old value stays.
            Some(j) => {
                let comment = lines[j].find(" #").map_or("", |c| &lines[j][c..]);
                out[j] = format!("{key} = {value}{comment}");
            }
            None => missing.push(format!("{key} = {value}")),
        }
    }
    // New keys go after the table's last key line (before blank lines and comments that lead
    // into the next table).
    let last_key = (mpm + 1..end)
        .rev()
        .find(|&j| {
            let l = lines[j].trim();
            !l.is_empty() && !l.starts_with('#')
        })
        .unwrap_or(mpm);
    for (k, l) in missing.into_iter().enumerate() {
        out.insert(last_key + 1 + k, l);
    }
    let mut s = out.join("\n");
    if text.ends_with('\n') {
        s.push('\n');
    }
    Ok(s)
}

/// A TOML basic string of `s`.
fn toml_string(s: &str) -> String {
    let mut out = String::from('"');
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            c if (c as u32) < 0x20 => out.push_str(&format!("\\u{:04X}", c as u32)),
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn provenance_gives_back_its_options() {
        let mut o = CalibrateOptions {
            grains: 2400,
            seed: 3,
            pressure: 812.5,
            inertial: 1e-3,
            strength: Strength::Critical,
            prep_friction: None,
            piles: 3,
            repose_width: 100.0,
        };
        let c = Calibration {
            records: Vec::new(),
            pressure: 812.5,
            grains: 3219,
            strain_rate: 0.5,
            peak: 17.0,
            critical: 14.0,
            critical_spread: 1.0,
            e50_plane: 1e5,
            e0_plane: 5e5,
            lateral_mean: 1.0,
            packing: 0.82,
            piles: Vec::new(),
        };
        let p = provenance(&c, &o);
        assert!(
            p.starts_with("grains calibrate --grains 2400 --seed 3 --pressure 812.5 --inertial 1e-3: "),
            "{p}"
        );
        assert_eq!(CalibrateOptions::parse(&p), Some(o));
        assert!(p.contains("friction_angle = critical state"), "{p}");
        assert_eq!(CalibrateOptions::parse("hand-set"), None);
        // The peak is named in the options and in what the line says the angle is.
        o.strength = Strength::Peak;
        let p = provenance(&c, &o);
        assert!(p.starts_with("grains calibrate --grains 2400 --seed 3 --pressure 812.5 --inertial 1e-3 --strength peak: "));
        assert!(p.contains("friction_angle = peak (critical state 14.0 deg"), "{p}");
        assert_eq!(CalibrateOptions::parse(&p), Some(o));
        assert_eq!((c.friction(Strength::Peak), c.friction(Strength::Critical)), (17.0, 14.0));
        o.prep_friction = Some(0.1);
        let p = provenance(&c, &o);
        assert!(
            p.starts_with("grains calibrate --grains 2400 --seed 3 --pressure 812.5 --inertial 1e-3 --prep-friction 0.1 --strength peak: "),
            "{p}"
        );
        assert_eq!(CalibrateOptions::parse(&p), Some(o));
        // The piles' strength names its piles and floor, and takes sin φ = tan θ_r of their mean.
        o.prep_friction = None;
        o.strength = Strength::Repose;
        o.piles = 2;
        o.repose_width = 150.0;
        let pile = |left, right| repose::Pile {
            grains: 0,
            poured: 0,
            height: 0.0,
            left,
            right,
            time: 0.0,
            surface: Vec::new(),
        };
        let c = Calibration {
            piles: vec![pile(18.0, 19.0), pile(19.0, 20.0)],
            ..c
        };
        let p = provenance(&c, &o);
        assert!(
            p.starts_with(
                "grains calibrate --grains 2400 --seed 3 --pressure 812.5 --inertial 1e-3 --strength repose --piles 2 --repose-width 150: "
            ),
            "{p}"
        );
        assert!(
            p.contains("angle of repose of 2 DEM piles poured on a rough floor, 19.00 deg"),
            "{p}"
        );
        assert_eq!(CalibrateOptions::parse(&p), Some(o));
        let phi = c.friction(Strength::Repose).to_radians();
        assert!((phi.sin() - 19f64.to_radians().tan()).abs() < 1e-12);
    }

    /// A sample consolidated with frictionless grains packs denser than one at the grains'
    /// own friction (μ 0.5), and its peak is higher (a denser sample dilates more), while the
    /// critical state, the state both reach after the peak, moves much less than the peak.
    #[test]
    fn a_sample_prepared_without_friction_is_denser_and_peaks_higher() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/chute_hybrid_2d.toml");
        let scene = grains_protocol::scene::load(&path).unwrap();
        let material = hybrid_material(&scene).unwrap();
        let mut o = CalibrateOptions {
            grains: 400,
            seed: 1,
            pressure: 800.0,
            inertial: 1e-3,
            strength: Strength::Peak,
            prep_friction: None,
            piles: 3,
            repose_width: 100.0,
        };
        let loose = biaxial(&scene, material, &o).unwrap();
        o.prep_friction = Some(0.0);
        let dense = biaxial(&scene, material, &o).unwrap();
        assert!(dense.packing > loose.packing + 0.005, "{} against {}", dense.packing, loose.packing);
        assert!(dense.peak > loose.peak + 2.0, "{} against {}", dense.peak, loose.peak);
        assert!(
            (dense.critical - loose.critical).abs() < dense.peak - loose.peak,
            "critical {} against {}, peaks {} and {}",
            dense.critical,
            loose.critical,
            dense.peak,
            loose.peak
        );
    }

    #[test]
    fn the_calibration_replaces_values_in_their_table_and_keeps_the_rest() {
        let text = "# head\n[[material]]\nname = \"sand\"\n[material.mpm]\nyoung = 1e6\n# why\nfriction_angle = 30.0 # hand-set\n\n[[material]]\nname = \"glass\"\n[material.mpm]\nyoung = 2.5e6\npacking = 0.8\n\n# next\n[[body]]\n";
        let out = write_calibration(text, "glass", 21.456, 1.25e6, "test").unwrap();
        assert!(
            out.starts_with(
                "# head\n[[material]]\nname = \"sand\"\n[material.mpm]\nyoung = 1e6\n# why\nfriction_angle = 30.0 # hand-set\n"
            )
        );
        assert!(
            out.contains("name = \"glass\"\n[material.mpm]\nyoung = 1.2500e6\npacking = 0.8\nfriction_angle = 21.46\ncalibration = \"test\"\n\n# next\n[[body]]\n"),
            "{out}"
        );
        let again = write_calibration(&out, "glass", 20.0, 1e6, "again").unwrap();
        assert!(
            again.contains("young = 1.0000e6\npacking = 0.8\nfriction_angle = 20.00\ncalibration = \"again\"\n"),
            "{again}"
        );
        assert!(write_calibration(text, "clay", 20.0, 1e6, "x").is_err());
        // A comment after a replaced value stays; the provenance is a valid TOML string.
        let kept = write_calibration(text, "sand", 21.0, 1e6, r#"a "quoted" \ test"#).unwrap();
        assert!(kept.contains("friction_angle = 21.00 # hand-set\n"), "{kept}");
        let doc: toml::Table = kept.parse().unwrap();
        assert_eq!(doc["material"][0]["mpm"]["calibration"].as_str(), Some(r#"a "quoted" \ test"#));
    }
}
