//! `grains calibrate --shear`: the rate dependence of the grains' friction, μ(I), from a
//! constant-pressure simple shear of the scene's grains (2D disks), the element test of GDR
//! MiDi 2004 and da Cruz et al. 2005. The biaxial test of the parent module gives the
//! quasi-static angle; a flow (a chute, a collapsing column) shears at larger inertial numbers.
//!
//! The cell: periodic along x, `--grains` grains between a floor row of frozen grains (rough,
//! at rest) and a plate row of frozen grains driven at (V, v_y) (see `Grains::frozen`), no
//! gravity. The plate's v_y holds σ_yy at p (a servo, as the biaxial test's walls); its V
//! shears the layer at γ̇ = V / H, H the gap between the rows, for the inertial number
//! I = γ̇ d / √(p / ρ). The stress is the Love–Weber average of the contacts' elastic forces
//! over the cell, σ = (1 / A) Σ f ⊗ (x_i − x_j) (compression positive; the contacts' damping
//! and the grains' kinetic stress are left out, small below I ≈ 0.3), and the friction is the
//! continuum's own measure, sin φ = ‖dev σ‖ / (√2 p) with p = tr σ / 2, the plane
//! Mohr–Coulomb ratio that `DruckerPragerYue` and its `InertialFriction` use. Each inertial
//! number is held for `strain` of shear; the first quarter is left to the transient, the rest
//! averaged. The targets run in increasing order on one sample, each starting from the state
//! the slower one left.

use anyhow::{Context, bail};
use grains_dem::packing::lattice_in_box;
use grains_dem::pipeline::DemPipeline;
use grains_dem::space::{D2, Space};
use grains_dem::state::{DemParams, DemState, Domain, Grains};
use grains_grid::rng::{Rng, radius};
use grains_protocol::scene::{Dimension, Scene};

/// One inertial number's result.
#[derive(Clone, Copy, Debug)]
pub struct ShearPoint {
    /// The inertial number asked for and the one measured (γ̇ d / √(p / ρ) with the measured
    /// mean pressure).
    pub target: f64,
    pub inertial: f64,
    /// Mean pressure tr σ / 2 over the window [Pa].
    pub pressure: f64,
    /// sin φ over the window, and its spread (standard deviation of ten sub-windows' means).
    pub sin_phi: f64,
    pub spread: f64,
    /// The shear stress over the normal stress on the plate, τ_xy / σ_yy (GDR MiDi's μ): equal
    /// to sin φ only when σ_xx = σ_yy, as in a Drucker–Prager continuum's simple shear.
    pub mu: f64,
    /// σ_xx / σ_yy over the window (the normal stress difference a coaxial continuum lacks).
    pub normal_ratio: f64,
}

/// The first shear's start from the consolidated sample, averaged over every 0.01 of strain:
/// the peak and the softening to the critical state that a rate-only law does not have.
#[derive(Clone, Copy, Debug)]
pub struct TransientRecord {
    /// Shear strain γ since the start.
    pub strain: f64,
    pub sin_phi: f64,
    /// τ_xy / σ_yy.
    pub mu: f64,
    /// Packing fraction Φ of the middle half of the layer.
    pub packing: f64,
}

/// What the shear cell gives.
#[derive(Clone, Debug)]
pub struct Shear {
    pub points: Vec<ShearPoint>,
    pub transient: Vec<TransientRecord>,
    /// Φ of the consolidated sample before the shear.
    pub packing0: f64,
}

/// The μ(I) law on sin φ fitted to the points: sin φ(I) = s₁ + (s₂ − s₁) / (1 + I₀ / I).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RateFit {
    pub sin_static: f64,
    pub sin_dynamic: f64,
    pub i0: f64,
    /// Root-mean-square residual of sin φ.
    pub rms: f64,
}

/// Least squares of the law over I₀ (a log grid, 1e-3..10, refined once) with s₁, s₂ linear
/// for each I₀: sin φ = s₁ (1 − w) + s₂ w with w = I / (I + I₀).
pub fn fit(points: &[(f64, f64)]) -> Option<RateFit> {
    if points.len() < 3 {
        return None;
    }
    let solve = |i0: f64| -> Option<RateFit> {
        // Normal equations of the two basis functions 1 − w and w.
        let (mut a11, mut a12, mut a22, mut b1, mut b2) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for &(i, s) in points {
            let w = i / (i + i0);
            let u = 1.0 - w;
            a11 += u * u;
            a12 += u * w;
            a22 += w * w;
            b1 += u * s;
            b2 += w * s;
        }
        let det = a11 * a22 - a12 * a12;
        if det.abs() < 1e-14 {
            return None;
        }
        let s1 = (b1 * a22 - b2 * a12) / det;
        let s2 = (a11 * b2 - a12 * b1) / det;
        let sq: f64 = points
            .iter()
            .map(|&(i, s)| {
                let w = i / (i + i0);
                (s1 * (1.0 - w) + s2 * w - s).powi(2)
            })
            .sum();
        Some(RateFit {
            sin_static: s1,
            sin_dynamic: s2,
            i0,
            rms: (sq / points.len() as f64).sqrt(),
        })
    };
    let best_on = |lo: f64, hi: f64| {
        (0..=200)
            .filter_map(|k| solve(lo * (hi / lo).powf(k as f64 / 200.0)))
            .min_by(|a, b| a.rms.total_cmp(&b.rms))
    };
    let coarse = best_on(1e-3, 10.0)?;
    best_on(coarse.i0 / 1.2, coarse.i0 * 1.2)
}

/// Chen 2021's critical-state softening (`model = "critical_state"`: tan φ = tan φ_cs +
/// χ (Φ − Φ_cs), dΦ/ds = −ξ Φ (Φ − Φ_cs) per unit plastic strain s) read off the first
/// shear's start: Φ_cs and sin φ_cs the means over its second half; the peak the largest
/// five-record (0.05 of strain) running mean of sin φ in its first half, with Φ's running mean
/// there, for χ; ξ the least-squares fit of the exact solution of the Φ law from the peak on,
/// with the plastic strain taken as the shear's Frobenius norm γ / √2 (the elastic part is
/// small past the peak).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CriticalStateFit {
    /// φ_cs [degrees].
    pub friction_angle: f64,
    pub packing_critical: f64,
    pub chi: f64,
    pub xi: f64,
    /// The peak: sin φ, Φ and γ.
    pub peak_sin: f64,
    pub peak_packing: f64,
    pub peak_strain: f64,
}

/// `None` when the records hold no peak denser than the critical state (a loose sample).
pub fn critical_state(t: &[TransientRecord]) -> Option<CriticalStateFit> {
    let last = t.last()?.strain;
    let late: Vec<&TransientRecord> = t.iter().filter(|r| r.strain > 0.5 * last).collect();
    if late.len() < 5 || t.len() < 10 {
        return None;
    }
    let mean = |f: &dyn Fn(&TransientRecord) -> f64, rs: &[&TransientRecord]| rs.iter().map(|r| f(r)).sum::<f64>() / rs.len() as f64;
    let packing_critical = mean(&|r| r.packing, &late);
    let sin_cs = mean(&|r| r.sin_phi, &late);
    let tan = |s: f64| s / (1.0 - s * s).sqrt();
    let (k, peak_sin, peak_packing) = (2..t.len() - 2)
        .filter(|&k| t[k].strain <= 0.5 * last)
        .map(|k| {
            let w = &t[k - 2..=k + 2];
            (
                k,
                w.iter().map(|r| r.sin_phi).sum::<f64>() / 5.0,
                w.iter().map(|r| r.packing).sum::<f64>() / 5.0,
            )
        })
        .max_by(|a, b| a.1.total_cmp(&b.1))?;
    if peak_packing <= packing_critical || peak_sin <= sin_cs {
        return None;
    }
    let chi = (tan(peak_sin) - tan(sin_cs)) / (peak_packing - packing_critical);
    let peak_strain = t[k].strain;
    let after: Vec<(f64, f64)> = t[k..].iter().map(|r| ((r.strain - peak_strain) / 2f64.sqrt(), r.packing)).collect();
    let model = |xi: f64, s: f64| {
        let decay = (-xi * packing_critical * s).exp();
        packing_critical * peak_packing / (peak_packing + (packing_critical - peak_packing) * decay)
    };
    let sse = |xi: f64| after.iter().map(|&(s, phi)| (model(xi, s) - phi).powi(2)).sum::<f64>();
    let xi = (0..=400)
        .map(|j| 0.1 * 1e4f64.powf(j as f64 / 400.0))
        .min_by(|a, b| sse(*a).total_cmp(&sse(*b)))?;
    Some(CriticalStateFit {
        friction_angle: sin_cs.asin().to_degrees(),
        packing_critical,
        chi,
        xi,
        peak_sin,
        peak_packing,
        peak_strain,
    })
}

/// The packing fraction of disks (centre height y, radius r) whose centres lie in the band
/// lo ≤ y < hi of a layer `width` wide: the estimator the shear cell reads its sample with and
/// `grains bench chute` its poured bed (the layers by a wall or a row are looser: keep the band
/// inside).
pub fn band_packing(disks: impl Iterator<Item = (f64, f64)>, lo: f64, hi: f64, width: f64) -> f64 {
    let solid: f64 = disks
        .filter(|(y, _)| (lo..hi).contains(y))
        .map(|(_, r)| std::f64::consts::PI * r * r)
        .sum();
    solid / (width * (hi - lo))
}

/// Grain ids: the floor row from 0, the plate row from `PLATE`, the sample from `SAMPLE`.
const PLATE: u64 = 1 << 32;
pub const SAMPLE: u64 = 1 << 33;

/// Steps between two reads of the stress (the mean over a run is over these reads).
const MEASURE: usize = 10;
/// Steps between two servo updates of the plate.
pub const SERVO: usize = 50;

/// The shear cell (module doc): a sample of disks between a frozen floor row at y = 0 and a
/// frozen plate row, periodic along x, no gravity, the plate's vertical speed a servo on σ_yy.
pub struct ShearCell {
    pub state: DemState<D2>,
    pub pipe: DemPipeline<D2>,
    /// The scene's stable DEM step [s].
    pub dt: f64,
    /// The period along x [m].
    pub width: f64,
    /// σ_yy held by the plate [Pa].
    pub pressure: f64,
    /// Mean grain diameter [m] and grain density [kg/m³].
    pub diameter: f64,
    pub density: f64,
    /// Sample grains glued to the plate (sorted ids) and the glued layers' thickness [m]
    /// ([`ShearCell::glue`]).
    glued: Vec<u64>,
    glued_thickness: f64,
}

impl ShearCell {
    /// `grains` disks of material `material` of `scene` on a jittered lattice of `cols` columns
    /// (the period is `cols` lattice spacings), at rest, not yet consolidated.
    pub fn new(
        scene: &Scene,
        material: usize,
        grains: usize,
        cols: usize,
        pressure: f64,
        seed: u64,
        threads: usize,
    ) -> anyhow::Result<Self> {
        if scene.dimension != Dimension::Two {
            bail!(crate::run::BadInput("the shear cell is 2D (disks); 3D is not built yet".into()));
        }
        let mat = &scene.materials[material];
        let dem = mat.dem.as_ref().context("a DEM material")?;
        let params = grains_dem_service::setup::contact_params(dem);
        let r = dem.radius;
        let d = 2.0 * r;
        let r_max = r + 2.0 * dem.radius_std;
        let spacing = Self::spacing(dem);
        let cols = cols.max(8) as f64;
        let width = cols * spacing;
        let rows = (grains as f64 / cols).ceil();
        let height = rows * spacing * 3f64.sqrt() / 2.0 + 2.0 * r_max;
        let mut state = DemState::<D2> {
            grains: Grains::default(),
            bodies: Vec::new(),
            walls: Vec::new(),
            params: DemParams {
                materials: vec![params],
                gravity: D2::from_array([0.0; 3]),
                domain: Domain {
                    min: [0.0, -height, 0.0],
                    max: [width, 3.0 * height, 0.0],
                    periodic: [true, false, false],
                },
                skin: 0.1 * d,
            },
            time: 0.0,
        };
        // The rows: grains of the mean radius a shade apart (a whole number across the period).
        let per_row = (width / (2.02 * r)).floor() as u64;
        let plate_y0 = r + height + r;
        for k in 0..per_row {
            let x = (k as f64 + 0.5) * width / per_row as f64;
            for (id, y) in [(k, 0.0), (PLATE + k, plate_y0)] {
                let i = state
                    .grains
                    .push(id, D2::from_array([x, y, 0.0]), r, Grains::<D2>::mass_of(r, mat.density), 0);
                state.grains.frozen[i] = true;
            }
        }
        let mut rng = Rng::new(seed);
        let sites = lattice_in_box::<D2>([0.0, r, 0.0], [width, r + height, 0.0], spacing, 1.01 * r_max, 0.01 * r, &mut rng);
        for (k, &x) in sites.iter().enumerate() {
            let ri = radius(&mut rng, r, dem.radius_std);
            state
                .grains
                .push(SAMPLE + k as u64, x, ri, Grains::<D2>::mass_of(ri, mat.density), 0);
        }
        let (dt, ..) = grains_dem_service::setup::stable_step(scene).context("the scene's DEM step")?;
        Ok(Self {
            state,
            pipe: DemPipeline::<D2>::new(threads)?,
            dt,
            width,
            pressure,
            diameter: d,
            density: mat.density,
            glued: Vec::new(),
            glued_thickness: 0.0,
        })
    }

    /// The lattice spacing the sample starts on: the largest grain (mean + 2 std) with 2% room.
    pub fn spacing(dem: &grains_protocol::scene::DemMaterial) -> f64 {
        2.04 * (dem.radius + 2.0 * dem.radius_std)
    }

    /// The plate row's height (the floor row is at y = 0) [m].
    pub fn plate_y(&self) -> f64 {
        let k = self
            .state
            .grains
            .id
            .iter()
            .position(|id| (PLATE..SAMPLE).contains(id))
            .expect("the plate");
        D2::to_array(self.state.grains.x[k])[1]
    }

    /// Glues the sample's grains within `thickness` of the floor row to the floor and those
    /// within `thickness` of the plate row to the plate: boundaries as rough as the packing,
    /// so that a band need not form along them (one row of grains is smoother than the bulk).
    pub fn glue(&mut self, thickness: f64) {
        let top = self.plate_y();
        let g = &mut self.state.grains;
        for i in 0..g.len() {
            let y = D2::to_array(g.x[i])[1];
            if g.id[i] >= SAMPLE && (y < thickness || y > top - thickness) {
                g.frozen[i] = true;
                g.v[i] = D2::from_array([0.0; 3]);
                g.omega[i] = 0.0;
                if y > top - thickness {
                    self.glued.push(g.id[i]);
                }
            }
        }
        self.glued.sort_unstable();
        self.glued_thickness = thickness;
    }

    /// Drives the plate row (and the grains glued to it) at (vx, vy).
    pub fn drive(&mut self, vx: f64, vy: f64) {
        let glued = &self.glued;
        for (id, v) in self.state.grains.id.iter().zip(self.state.grains.v.iter_mut()) {
            if (PLATE..SAMPLE).contains(id) || glued.binary_search(id).is_ok() {
                *v = D2::from_array([vx, vy, 0.0]);
            }
        }
    }

    /// The shear rate of inertial number `i` at the cell's pressure [1/s].
    pub fn rate_of(&self, i: f64) -> f64 {
        i * (self.pressure / self.density).sqrt() / self.diameter
    }

    /// Runs `n` steps; the cell's stress [σxx, σyy, σxy] (Love–Weber, symmetrized, compression
    /// positive) averaged over reads every MEASURE steps.
    pub fn run(&mut self, n: usize) -> [f64; 3] {
        let mut sum = [0.0; 3];
        let reads = (n / MEASURE).max(1);
        for _ in 0..reads {
            self.pipe.run(&mut self.state, self.dt, MEASURE);
            let s = self.stress();
            (0..3).for_each(|k| sum[k] += s[k]);
        }
        sum.map(|s| s / reads as f64)
    }

    /// The small-strain moduli of the cell as it stands, from two probes of `strain` (Chen
    /// 2021 §2.2 takes K and G of its continuum from DEM element tests): the plate moved
    /// sideways (simple shear, G = Δσ_xy / Δγ), then down with the sides periodic (confined
    /// compression, the constrained modulus M = Δσ_yy / Δε_yy = K + G for a 2D bulk modulus
    /// K). Each probe ramps over 2,000 steps and rests 2,000 more; the stress is the mean
    /// over the last 500. Returns (K, G) [Pa]; the cell is left strained by both probes.
    pub fn moduli(&mut self, strain: f64) -> (f64, f64) {
        const RAMP: usize = 2000;
        let rested = |cell: &mut Self| {
            cell.drive(0.0, 0.0);
            cell.run(RAMP - 500);
            cell.run(500)
        };
        let s0 = rested(self);
        let speed = strain * self.plate_y() / (RAMP as f64 * self.dt);
        self.drive(speed, 0.0);
        self.run(RAMP);
        let s1 = rested(self);
        self.drive(0.0, -speed);
        self.run(RAMP);
        let s2 = rested(self);
        let shear = (s1[2] - s0[2]).abs() / strain;
        let constrained = (s2[1] - s1[1]) / strain;
        (constrained - shear, shear)
    }

    /// The cell's stress now [σxx, σyy, σxy] (Love–Weber over the contacts, symmetrized,
    /// compression positive); the contacts must be known (after a step).
    pub fn stress(&self) -> [f64; 3] {
        // Contacts between frozen grains are not computed: the glued layers are not counted.
        love_weber(&self.pipe, &self.state, self.width * (self.plate_y() - 2.0 * self.glued_thickness))
    }

    /// The plate's servo: v_y = −(1 − σyy / p) γ̇_ref H, γ̇_ref the rate of I = 1e-3 or
    /// `rate` if faster (a quicker servo rings, as in the biaxial test); v_x as given.
    pub fn servo(&mut self, syy: f64, vx: f64, rate: f64) {
        let h = self.plate_y();
        let error = (1.0 - syy / self.pressure).clamp(-1.0, 1.0);
        let vy = -error * rate.max(self.rate_of(1e-3)) * h;
        self.drive(vx, vy);
    }

    /// Consolidation to the pressure at rest (damped, as the biaxial test's), at most 2 s.
    pub fn consolidate(&mut self) -> anyhow::Result<()> {
        let pressure = self.pressure;
        for _ in 0..((2.0 / self.dt) as usize / SERVO) {
            if grains_service::signals::signalled() {
                bail!("stopped by a signal");
            }
            let s = self.run(SERVO);
            let g = &mut self.state.grains;
            g.v.iter_mut().zip(&g.frozen).filter(|(_, f)| !**f).for_each(|(v, _)| *v *= 0.98);
            g.omega.iter_mut().for_each(|w| *w *= 0.98);
            let h = self.plate_y();
            // The sample's translational energy (the plate's own motion is not the sample's).
            let g = &self.state.grains;
            let ke: f64 = (0..g.len())
                .filter(|&i| !g.frozen[i])
                .map(|i| 0.5 * g.mass[i] * g.v[i].length_squared())
                .sum();
            if (s[1] / pressure - 1.0).abs() < 0.02 && ke < 1e-5 * pressure * self.width * h {
                return Ok(());
            }
            self.servo(s[1], 0.0, 0.0);
        }
        bail!("the shear cell did not settle at {pressure:.1} Pa within 2 s: stiffness, pressure or grain count out of reach")
    }

    /// The packing fraction of the middle half of the gap (the layers by the rows are looser,
    /// as by any wall): the disks whose centres lie in it over its area, the estimator that
    /// reads a bed's packing the same way (`grains pack`'s output by depth).
    pub fn packing(&self) -> f64 {
        let top = self.plate_y();
        let g = &self.state.grains;
        let disks = (0..g.len())
            .filter(|&i| !g.frozen[i])
            .map(|i| (D2::to_array(g.x[i])[1], g.radius[i]));
        band_packing(disks, 0.25 * top, 0.75 * top, self.width)
    }
}

/// The stress of a 2D packing over `area` [σxx, σyy, σxy] (Love–Weber over its contacts,
/// symmetrized, compression positive); the contacts must be known (after a step).
pub fn love_weber(pipe: &DemPipeline<D2>, state: &DemState<D2>, area: f64) -> [f64; 3] {
    let mut sum = [0.0; 3];
    for (_, _, f, b) in pipe.contact_forces(state) {
        let (f, b) = (D2::to_array(f), D2::to_array(b));
        sum[0] += f[0] * b[0] / area;
        sum[1] += f[1] * b[1] / area;
        sum[2] += 0.5 * (f[0] * b[1] + f[1] * b[0]) / area;
    }
    sum
}

/// Runs the shear cell of material `material` of `scene` at each of `inertials` (increasing).
pub fn simple_shear(
    scene: &Scene,
    material: usize,
    grains: usize,
    pressure: f64,
    inertials: &[f64],
    strain: f64,
    seed: u64,
) -> anyhow::Result<Shear> {
    // Twice as wide as tall: cols ≈ √(N √3) columns of N / cols rows.
    let cols = (grains as f64 * 3f64.sqrt()).sqrt().round() as usize;
    let mut cell = ShearCell::new(scene, material, grains, cols, pressure, seed, super::THREADS)?;
    cell.consolidate()?;
    let dt = cell.dt;
    let d = cell.diameter;
    let density = cell.density;
    let packing0 = cell.packing();
    let mut out = Vec::new();
    let mut transient = Vec::new();
    for &target in inertials {
        let rate = cell.rate_of(target);
        let total = (strain / rate / dt) as usize;
        let warm = total / 4;
        let mut windows: Vec<[f64; 3]> = Vec::new();
        let (mut step, mut s) = (0, [pressure, pressure, 0.0]);
        while step < total {
            if grains_service::signals::signalled() {
                bail!("stopped by a signal");
            }
            let v = rate * cell.plate_y();
            cell.servo(s[1], v, rate);
            s = cell.run(SERVO);
            if let Some(id) = DemPipeline::first_non_finite(&cell.state) {
                bail!("grain {id} is not finite: the shear cell blew up at I = {target}");
            }
            if step >= warm {
                windows.push(s);
            }
            step += SERVO;
            if out.is_empty() {
                let strain = rate * dt * step as f64;
                let bin = (strain / 0.01).ceil() * 0.01;
                let p = 0.5 * (s[0] + s[1]);
                let rec = TransientRecord {
                    strain: bin,
                    sin_phi: (0.25 * (s[0] - s[1]).powi(2) + s[2] * s[2]).sqrt() / p,
                    mu: s[2].abs() / s[1],
                    packing: cell.packing(),
                };
                transient.push((1usize, rec));
                // Merge into the bin's running mean.
                if transient.len() >= 2 && (transient[transient.len() - 2].1.strain - bin).abs() < 1e-9 {
                    let (n, last) = transient.pop().expect("pushed");
                    let (m, prev) = transient.last_mut().expect("two");
                    let w = n as f64 / (*m + n) as f64;
                    prev.sin_phi += w * (last.sin_phi - prev.sin_phi);
                    prev.mu += w * (last.mu - prev.mu);
                    prev.packing += w * (last.packing - prev.packing);
                    *m += n;
                }
            }
        }
        // Ten sub-windows' means: their mean is the point, their spread its noise.
        let chunk = windows.len().div_ceil(10).max(1);
        let of = |m: &[f64; 3]| {
            let p = 0.5 * (m[0] + m[1]);
            (p, (0.25 * (m[0] - m[1]).powi(2) + m[2] * m[2]).sqrt() / p)
        };
        let means: Vec<[f64; 3]> = windows
            .chunks(chunk)
            .map(|c| {
                let mut m = [0.0; 3];
                c.iter().for_each(|w| (0..3).for_each(|a| m[a] += w[a] / c.len() as f64));
                m
            })
            .collect();
        let mut all = [0.0; 3];
        windows
            .iter()
            .for_each(|w| (0..3).for_each(|a| all[a] += w[a] / windows.len() as f64));
        let (p, sin_phi) = of(&all);
        let subs: Vec<f64> = means.iter().map(|m| of(m).1).collect();
        let spread = (subs.iter().map(|x| (x - sin_phi).powi(2)).sum::<f64>() / subs.len() as f64).sqrt();
        let inertial = rate * d / (p / density).sqrt();
        tracing::info!(
            "calibrate --shear: I = {target:e} (measured {inertial:.3e}): p {p:.1} Pa, phi {:.2} deg (sd {:.2})",
            sin_phi.asin().to_degrees(),
            spread.asin().to_degrees()
        );
        out.push(ShearPoint {
            target,
            inertial,
            pressure: p,
            sin_phi,
            spread,
            mu: all[2].abs() / all[1],
            normal_ratio: all[0] / all[1],
        });
    }
    Ok(Shear {
        points: out,
        transient: transient.into_iter().map(|(_, r)| r).collect(),
        packing0,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The cell shears at the inertial number asked (γ̇ = V / H with the plate driven at V)
    /// with σ_yy held at p by the plate's servo: the measured I within 10 % (its p is the mean
    /// pressure, below σ_yy by the normal-stress difference), σ_yy within 5 %, and a friction between zero and the contacts' μ (a layer that did not
    /// shear, with the plate sliding over it or standing still, gives none of these).
    #[test]
    fn the_cell_shears_at_the_inertial_number_asked_at_constant_pressure() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/chute_hybrid_2d.toml");
        let scene = grains_protocol::scene::load(&path).unwrap();
        let material = scene.bodies[0].material;
        let mu_contact = scene.materials[material].dem.as_ref().unwrap().friction;
        let out = simple_shear(&scene, material, 400, 800.0, &[0.03], 0.5, 1).unwrap();
        let p = out.points[0];
        assert!((p.inertial / 0.03 - 1.0).abs() < 0.1, "{p:?}");
        let syy = 2.0 * p.pressure / (1.0 + p.normal_ratio);
        assert!((syy / 800.0 - 1.0).abs() < 0.05, "σ_yy {syy:.1} Pa: {p:?}");
        assert!(p.mu > 0.05 && p.mu < mu_contact, "{p:?}");
        assert!(out.packing0 > 0.7 && out.packing0 < 0.9, "{}", out.packing0);
        assert!(!out.transient.is_empty());
    }

    /// Records made by the critical-state law itself (Φ from 0.83 to Φ_cs = 0.816 by the
    /// exact solution with ξ = 10 over s = γ / √2, tan φ = tan φ_cs + χ (Φ − Φ_cs) with
    /// χ = 12 and φ_cs = 15°, after a rise to the peak over the first 0.1 of strain, as the
    /// cell's elastic start) give those parameters back.
    #[test]
    fn the_critical_state_fit_recovers_the_law_it_is_fed() {
        let (pcs, chi, xi, p0) = (0.816, 12.0, 10.0, 0.83);
        let tan_cs = 15f64.to_radians().tan();
        let sin_of = |tan: f64| tan / (1.0 + tan * tan).sqrt();
        let peak_at = 0.1;
        let records: Vec<TransientRecord> = (1..=200)
            .map(|k| {
                let strain = 0.01 * k as f64;
                let s = (strain - peak_at).max(0.0) / 2f64.sqrt();
                let packing = pcs * p0 / (p0 + (pcs - p0) * (-xi * pcs * s).exp());
                let tan = tan_cs + chi * (packing - pcs);
                let sin_phi = sin_of(tan) * (strain / peak_at).min(1.0);
                TransientRecord {
                    strain,
                    sin_phi,
                    mu: sin_phi,
                    packing,
                }
            })
            .collect();
        let f = critical_state(&records).unwrap();
        assert!((f.packing_critical - pcs).abs() < 1e-4, "{f:?}");
        assert!((f.friction_angle - 15.0).abs() < 0.05, "{f:?}");
        // The five-record mean rounds the peak off: χ within 5 %.
        assert!((f.chi / chi - 1.0).abs() < 0.05, "{f:?}");
        assert!((f.xi / xi - 1.0).abs() < 0.05, "{f:?}");
        // A sample looser than its critical state has no peak to read.
        let loose: Vec<TransientRecord> = records
            .iter()
            .map(|r| TransientRecord {
                packing: 2.0 * pcs - r.packing,
                ..*r
            })
            .collect();
        assert!(critical_state(&loose).is_none());
    }

    /// The fit gives back the law it is fed (sin φ from known s₁, s₂, I₀ at six inertial
    /// numbers), and refuses fewer than three points.
    #[test]
    fn the_fit_recovers_a_known_law() {
        let (s1, s2, i0) = (0.25, 0.55, 0.08);
        let points: Vec<(f64, f64)> = [1e-3, 3e-3, 1e-2, 3e-2, 0.1, 0.3]
            .iter()
            .map(|&i| (i, s1 + (s2 - s1) / (1.0 + i0 / i)))
            .collect();
        let f = fit(&points).unwrap();
        assert!((f.sin_static - s1).abs() < 1e-3, "{f:?}");
        assert!((f.sin_dynamic - s2).abs() < 5e-3, "{f:?}");
        assert!((f.i0 / i0 - 1.0).abs() < 0.02, "{f:?}");
        assert!(fit(&points[..2]).is_none());
    }
}
