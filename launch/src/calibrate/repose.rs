//! The angle of repose of a DEM pile of a scene's grains (Yue 2018 §3.3: the continuum's
//! Drucker–Prager angle is set so that a pile stands at the DEM pile's angle).
//!
//! Grains are poured from a narrow stream onto a rough floor (one row of frozen grains) of a
//! fixed width; the heap grows until its flanks reach the floor's ends, the excess rolls off
//! and is removed. After the pour the heap settles, and the angle of each flank is the
//! least-squares slope of its surface (the highest grain top in bins one diameter wide) over
//! the middle of the flank, away from the rounded top and the toe.
//!
//! The continuum's angle from it: a Drucker–Prager layer on a slope θ (the plane Mohr–Coulomb
//! cone of `DruckerPragerYue`) flows once tan θ > sin φ (the MPM test
//! `a_continuum_layer_on_an_incline_slides_as_a_coulomb_block`), so the continuum whose
//! flanks stop where the grains' do has sin φ = tan θ_r.

use crate::validate::stats::slope;
use anyhow::{Context, bail};
use grains_dem::pipeline::DemPipeline;
use grains_dem::space::{D2, Space};
use grains_dem::state::{DemParams, DemState, Domain, Grains};
use grains_grid::rng::{Rng, radius};
use grains_protocol::scene::{Dimension, Scene};

/// What the pile gives.
#[derive(Clone, Debug)]
pub struct Pile {
    /// Grains on the floor at the end (the frozen row not counted).
    pub grains: usize,
    /// Grains poured, those that rolled off included.
    pub poured: usize,
    /// The heap's height over the floor's top [m].
    pub height: f64,
    /// Angles of the left and right flanks [deg].
    pub left: f64,
    pub right: f64,
    /// Simulated time of the pour and the settling [s].
    pub time: f64,
    /// The surface (bin centre from the floor's middle, height over the floor's top) [m].
    pub surface: Vec<(f64, f64)>,
}

impl Pile {
    /// The mean of the two flanks [deg].
    pub fn angle(&self) -> f64 {
        0.5 * (self.left + self.right)
    }
}

/// The continuum's friction angle [deg] whose layer stops at a slope of `repose` [deg]:
/// sin φ = tan θ_r.
pub fn continuum_angle(repose: f64) -> f64 {
    repose.to_radians().tan().asin().to_degrees()
}

/// The flank angles [deg] (left, right) of a heap on a floor of half-width `half` centred at
/// x = 0: the surface (bin centre, height) fitted over 15–85 % of each half, so that neither
/// the rounded top nor the toe at the floor's end weighs in.
pub fn flank_angles(surface: &[(f64, f64)], half: f64) -> Option<(f64, f64)> {
    let side = |sign: f64| {
        let pts: Vec<(f64, f64)> = surface
            .iter()
            .filter(|p| p.0 * sign > 0.0 && (0.15 * half..=0.85 * half).contains(&(p.0 * sign)))
            .map(|p| (p.0 * sign, p.1))
            .collect();
        // At least three bins, and a slope (the fit is validate's).
        let s = slope(&pts);
        (pts.len() >= 3 && s.is_finite()).then(|| (-s).atan().to_degrees())
    };
    Some((side(-1.0)?, side(1.0)?))
}

/// The surface of the grains above the floor: in bins of `bin` across [−half, half], the
/// highest grain top (y + r) over `floor_top`; empty bins left out.
pub fn surface(x: &[[f64; 2]], r: &[f64], half: f64, bin: f64, floor_top: f64) -> Vec<(f64, f64)> {
    let bins = (2.0 * half / bin).ceil() as usize;
    let mut top = vec![f64::NEG_INFINITY; bins];
    for (p, &ri) in x.iter().zip(r) {
        if p[0] < -half || p[0] >= half {
            continue;
        }
        let k = (((p[0] + half) / bin) as usize).min(bins - 1);
        top[k] = top[k].max(p[1] + ri - floor_top);
    }
    top.iter()
        .enumerate()
        .filter(|(_, h)| h.is_finite() && **h > 0.0)
        .map(|(k, &h)| (-half + (k as f64 + 0.5) * bin, h))
        .collect()
}

/// Pours a pile of `material`'s grains of `scene` on a rough floor `width_d` mean diameters
/// wide (one thread: the same pile from the same seed).
pub fn pile(scene: &Scene, material: usize, width_d: f64, seed: u64) -> anyhow::Result<Pile> {
    if scene.dimension != Dimension::Two {
        bail!(crate::run::BadInput(
            "grains calibrate --strength repose pours a 2D pile; the 3D pile is not built yet".into()
        ));
    }
    if !(width_d.is_finite() && width_d >= 20.0) {
        bail!(crate::run::BadInput(format!(
            "--repose-width: at least 20 grain diameters, got {width_d}"
        )));
    }
    let mat = &scene.materials[material];
    let dem = mat.dem.as_ref().context("a DEM material")?;
    let d = 2.0 * dem.radius;
    let g = scene.gravity.iter().map(|x| x * x).sum::<f64>().sqrt();
    if g <= 0.0 {
        bail!(crate::run::BadInput(
            "grains calibrate --strength repose needs the scene's gravity".into()
        ));
    }
    let half = 0.5 * width_d * d;
    // The tallest heap the pour can build (flanks at 35°), and room above it for the stream.
    let tallest = half * 35f64.to_radians().tan();
    let mut rng = Rng::new(seed);
    let mut state = DemState::<D2> {
        grains: Grains::default(),
        bodies: Vec::new(),
        walls: Vec::new(),
        params: DemParams {
            materials: vec![grains_dem_service::setup::contact_params(dem)],
            gravity: D2::from_array([0.0, -g, 0.0]),
            domain: Domain {
                min: [-half - 40.0 * d, -20.0 * d, 0.0],
                max: [half + 40.0 * d, tallest + 20.0 * d, 0.0],
                periodic: [false; 3],
            },
            skin: 0.1 * d,
        },
        time: 0.0,
    };
    // The floor: frozen grains side by side, touching, centres at y = 0.
    let mut id = 0u64;
    let mut x = -half;
    while x < half {
        let r = radius(&mut rng, dem.radius, dem.radius_std);
        let i = state
            .grains
            .push(id, D2::from_array([x + r, 0.0, 0.0]), r, Grains::<D2>::mass_of(r, mat.density), 0);
        state.grains.frozen[i] = true;
        id += 1;
        x += 2.0 * r;
    }
    let floor_top = dem.radius;
    // Grains the heap holds at 35° with a packing of 0.8, and a fifth more to roll off (the
    // flanks come to rest under 25°: most of the fifth and more rolls off).
    let area = half * tallest;
    let target = (1.2 * 0.8 * area / (std::f64::consts::PI * dem.radius * dem.radius)) as usize;
    let (dt, ..) = grains_dem_service::setup::stable_step(scene).context("the scene's DEM step")?;
    let mut pipe = DemPipeline::<D2>::new(super::THREADS)?;
    // The stream: grains placed 4 D50 above the heap's top within ±3 D50 of its axis, at the
    // speed of a fall of one diameter; a place is taken only when no grain is within reach.
    let stream = 3.0 * d;
    let speed = (2.0 * g * d).sqrt();
    let every = ((0.25 * d / speed) / dt).ceil().max(1.0) as usize;
    let mut poured = 0usize;
    let mut removed = 0usize;
    let settle_limit = 2.0;
    let mut settle_time = 0.0;
    loop {
        if grains_service::signals::signalled() {
            bail!("stopped by a signal");
        }
        pipe.run(&mut state, dt, every);
        if let Some(gid) = DemPipeline::first_non_finite(&state) {
            bail!("grain {gid} is not finite: the pile blew up");
        }
        // Grains that rolled off the floor's ends.
        let gr = &state.grains;
        let keep: Vec<u32> = (0..gr.len())
            .filter(|&i| gr.frozen[i] || (D2::to_array(gr.x[i])[1] > -10.0 * d))
            .map(|i| i as u32)
            .collect();
        if keep.len() != gr.len() {
            removed += gr.len() - keep.len();
            state.grains.permute(&keep);
            pipe.invalidate();
        }
        if poured < target {
            let gr = &state.grains;
            let top = (0..gr.len())
                .map(|i| D2::to_array(gr.x[i]))
                .zip(gr.radius.iter().zip(&gr.v))
                // Grains at rest on the heap, not those falling in the stream.
                .filter(|(p, (_, v))| p[0].abs() < stream + 2.0 * d && D2::to_array(**v)[1].abs() < 0.25 * speed)
                .map(|(p, (r, _))| p[1] + r)
                .fold(floor_top, f64::max);
            let r = radius(&mut rng, dem.radius, dem.radius_std);
            let site = [stream * rng.signed(), top + 4.0 * d];
            let free = (0..gr.len()).all(|i| {
                let p = D2::to_array(gr.x[i]);
                (p[0] - site[0]).hypot(p[1] - site[1]) > r + gr.radius[i] + 0.05 * d
            });
            if free {
                let i = state.grains.push(
                    id,
                    D2::from_array([site[0], site[1], 0.0]),
                    r,
                    Grains::<D2>::mass_of(r, mat.density),
                    0,
                );
                state.grains.v[i] = D2::from_array([0.0, -speed, 0.0]);
                id += 1;
                poured += 1;
                pipe.invalidate();
            }
            if poured.is_multiple_of(500) && free {
                tracing::info!(
                    "calibrate: pile: {poured} of {target} grains poured, {removed} rolled off, t = {:.2} s",
                    state.time
                );
            }
            continue;
        }
        // Settling: until the grains are nearly at rest (mean speed under 1e-2 √(g d)).
        settle_time += every as f64 * dt;
        let moving = (0..state.grains.len()).filter(|&i| !state.grains.frozen[i]).count().max(1);
        let ke = DemPipeline::kinetic_energy(&state) / moving as f64;
        let m = Grains::<D2>::mass_of(dem.radius, mat.density);
        if ke < 0.5 * m * 1e-4 * g * d {
            break;
        }
        if settle_time > settle_limit {
            bail!("the pile did not come to rest within {settle_limit} s after the pour");
        }
    }
    let gr = &state.grains;
    let (xs, rs): (Vec<[f64; 2]>, Vec<f64>) = (0..gr.len())
        .filter(|&i| !gr.frozen[i])
        .map(|i| {
            let p = D2::to_array(gr.x[i]);
            ([p[0], p[1]], gr.radius[i])
        })
        .unzip();
    let surface = surface(&xs, &rs, half, d, floor_top);
    let (left, right) = flank_angles(&surface, half).context("the pile has too few grains on a flank to fit")?;
    let height = surface.iter().map(|p| p.1).fold(0.0, f64::max);
    Ok(Pile {
        grains: xs.len(),
        poured,
        height,
        left,
        right,
        time: state.time,
        surface,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A synthetic heap of known flanks (20° left, 25° right, a rounded top, toes at the
    /// floor's ends) reads back its angles; the fit window keeps the top and toe out.
    #[test]
    fn a_heap_of_known_flanks_reads_back_its_angles() {
        let half = 0.1;
        let (tl, tr) = (20f64.to_radians().tan(), 25f64.to_radians().tan());
        let surface: Vec<(f64, f64)> = (0..200)
            .map(|k| {
                let x = -half + (k as f64 + 0.5) * 0.001;
                let flank = if x < 0.0 { tl * (half + x) } else { tr * (half - x) };
                // A rounded top (lower than the flanks' meeting point) within 5 mm of the axis.
                let y = flank.min(0.02 + tl.min(tr) * (half - 0.005)) - if x.abs() < 0.005 { 0.002 } else { 0.0 };
                (x, y)
            })
            .collect();
        let (l, r) = flank_angles(&surface, half).unwrap();
        assert!((l - 20.0).abs() < 0.01 && (r - 25.0).abs() < 0.01, "{l} {r}");
    }

    /// The surface is the highest grain top in each bin, over the floor.
    #[test]
    fn the_surface_is_the_highest_grain_top_of_each_bin() {
        let x = [[-0.5, 1.0], [-0.4, 2.0], [0.5, 0.5], [2.0, 9.0]];
        let r = [0.1, 0.1, 0.2, 0.1];
        let s = surface(&x, &r, 1.0, 1.0, 0.5);
        let want = [(-0.5, 1.6), (0.5, 0.2)];
        assert_eq!(s.len(), 2, "{s:?}");
        for (a, b) in s.iter().zip(want) {
            assert!((a.0 - b.0).abs() < 1e-12 && (a.1 - b.1).abs() < 1e-12, "{s:?}");
        }
    }

    /// Friction steepens the pile. Frictionless disks of this narrow size spread (8%) still
    /// stand, on their interlocking: a 2D heap of nearly equal disks orders, and its faces
    /// lean on each other (15.8° measured on a floor 40 D50 wide), but the scene's grains
    /// (μ = 0.5) stand steeper on the same floor (22.5°). Both poured the same way.
    #[test]
    fn friction_steepens_the_pile() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/chute_hybrid_2d.toml");
        let mut scene = grains_protocol::scene::load(&path).unwrap();
        let material = super::super::hybrid_material(&scene).unwrap();
        let rough = pile(&scene, material, 40.0, 1).unwrap();
        scene.materials[material].dem.as_mut().unwrap().friction = 0.0;
        let smooth = pile(&scene, material, 40.0, 1).unwrap();
        assert!(
            rough.left > 15.0 && rough.right > 15.0,
            "μ = 0.5: {} and {}",
            rough.left,
            rough.right
        );
        assert!(
            smooth.angle() < rough.angle() - 3.0,
            "μ = 0: {} and {}; μ = 0.5: {} and {}",
            smooth.left,
            smooth.right,
            rough.left,
            rough.right
        );
    }

    /// sin φ = tan θ_r: a 20° pile gives a continuum of 21.34°.
    #[test]
    fn the_continuum_angle_stops_its_layer_at_the_piles_angle() {
        let phi = continuum_angle(20.0);
        assert!((phi.to_radians().sin() - 20f64.to_radians().tan()).abs() < 1e-12, "{phi}");
    }
}
