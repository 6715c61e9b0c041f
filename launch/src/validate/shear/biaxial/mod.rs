//! Chen 2021 §6.2, the biaxial compression (its "triaxial" test, in 2D), as a DEM: the
//! specimen of Table 5 (6 × 9.42 cm, 5,910 grains: 60 × 94.2 D50 of the planar shear's
//! grains), the confining pressure held by a membrane on both sides (App. B: a chain of
//! mass–spring nodes, k_ms and γ_ms of Table B.1), shortened at Chen's 2 cm/s to 10.61% of
//! axial strain, the bottom no-slip (the grains within 1.5 D50 of it glued to it), the top a
//! frictionless platen. The band by App. A over axial strain 5.5–8.5% (Fig. 18: 10 D50 for the
//! DEM and the hybrid), its inclination against the Mohr–Coulomb and Roscoe angles of the
//! same run (a band in a biaxial test lies between 45° + ψ/2 and 45° + φ/2 from the σ1 plane:
//! Vardoulakis 1980, Vermeer 1990), and the stress and volume against the axial strain
//! (Fig. 17). The membrane is [`super::membrane`]; then the same specimen as Chen's
//! critical-state continuum on two grids, confined by a fluid's pressure, with the shear-band
//! oracle watching.

mod continuum;
mod hybrid;

use super::SCENE;
use super::membrane::{GAMMA_MS, K_MS, MEMBRANE, NODE_SPACING_D, Sides, plane_point, slab_area};
use crate::calibrate::{box_sample, consolidate_box};
use crate::report::Part;
use crate::report::chart::{Chart, Kind, Series};
use crate::validate::args::Confinement;
use anyhow::Context;
use grains_dem::pipeline::DemPipeline;
use grains_dem::space::{D2, Space};
use grains_dem::state::DemState;
use grains_oracle::band;
use std::collections::HashMap;
use std::fmt::Write as _;

/// Chen's Table 5 in D50, and its 100 kPa over a 1-cm-thick disk as a stress over a
/// unit-thick one (the planar shear's scaling, [`super::PRESSURE`]'s).
const HEIGHT_OVER_WIDTH: f64 = 9.42 / 6.0;
const GRAINS: usize = 5910;
const PRESSURE: f64 = 1.0e3;
/// Chen: the top at 2 cm/s for 0.5 s, 10.61% of axial strain.
const SPEED_OVER_HEIGHT: f64 = 0.02 / 0.0942;
const END: f64 = 0.1061;
/// Fig. 18: the incremental strain from 5.5% to 8.5% of axial strain; t_s = 10 D50 (DEM and
/// hybrid), 7 D50 for the continuum.
const WINDOW: (f64, f64) = (0.055, 0.085);
const PAPER_BAND: f64 = 10.0;
/// As the planar shear's ([`super::BAND_TOLERANCE`]).
const BAND_TOLERANCE: f64 = 4.0;
/// Steps between two records.
const RECORD: usize = 50;
/// The span of axial strain the peak friction is averaged over, and the dilatancy at the peak
/// measured over.
const PEAK_SPAN: f64 = 0.005;
/// Steps the membrane settles for before the compression.
const SETTLE: usize = 2000;
/// The samples.
const SEEDS: [u64; 3] = [1, 2, 3];
/// The glued layer at the bottom [D50].
const GLUE_D: f64 = 1.5;
/// App. A counts the grains and points at least this many continuum cells inside the
/// specimen's faces (the DEM: cells of the finer grid) ([`inner_band`]).
const EDGE_CELLS: f64 = 2.0;

/// Continuum cells of the biaxial compression [D50] (the planar shear's two grids).
const CELLS_D: [f64; 2] = [2.0, 4.0];

/// One record of the compression.
#[derive(Clone, Copy, Debug)]
struct Record {
    axial: f64,
    /// 1 − A / A0 (compression positive).
    volumetric: f64,
    /// (σ1 − σ3) / (σ1 + σ3), σ3 the membrane's pressure.
    sin_phi: f64,
}

/// The DEM biaxial compression of seed `seed`.
pub(super) struct BiaxialRun {
    seed: u64,
    grains: usize,
    width: f64,
    height: f64,
    packing: f64,
    records: Vec<Record>,
    /// App. A's band: thickness [D50], the width at half peak of the incremental strain's
    /// profile across its centre line [D50], the line's angle from the horizontal [°], the
    /// grains counted.
    t_s: f64,
    fwhm: f64,
    angle: f64,
    counted: usize,
    /// The band's volumetric strain against the axial strain ([`band_volume`]).
    band_volume: Vec<[f64; 2]>,
    /// The grains' positions at the window's start and the band's (indices into them).
    x0: Vec<[f64; 2]>,
    band: Vec<usize>,
    /// Peak friction (axial strain, °) and the dilatancy angle there [°], and the friction and
    /// dilatancy angles over the window [°].
    peak: (f64, f64),
    psi_peak: f64,
    phi: f64,
    psi: f64,
    /// The lateral stress the grains took from the membrane over the window (the mean of a
    /// reading per record), over the pressure ([`Membrane::traction`]).
    lateral: f64,
    /// The springs' net pull on the free nodes over the window, likewise ([`Membrane::pull`]).
    pull: f64,
    wall: f64,
    /// The specimen at the start of its shortening (the hybrid's prepared packing), and the
    /// DEM's step.
    sample: DemState<D2>,
    dt: f64,
}

fn run(scene: &grains_protocol::scene::Scene, material: usize, seed: u64, confinement: Confinement) -> anyhow::Result<BiaxialRun> {
    let t0 = std::time::Instant::now();
    let mat = &scene.materials[material];
    let dem = mat.dem.as_ref().context("a DEM material")?;
    let (mu, d) = (dem.friction, 2.0 * dem.radius);
    let spacing = crate::calibrate::shear::ShearCell::spacing(dem);
    // A triangular lattice of cols × rows ≈ GRAINS sites in a box HEIGHT_OVER_WIDTH as tall.
    let cols = (GRAINS as f64 * 3f64.sqrt() / (2.0 * HEIGHT_OVER_WIDTH)).sqrt().round();
    let width = cols * spacing;
    let mut state = box_sample(mat, width, HEIGHT_OVER_WIDTH * width, seed)?;
    let (dt, ..) = grains_dem_service::setup::stable_step(scene).context("the scene's DEM step")?;
    let mut pipe = DemPipeline::<D2>::new(2)?;
    // Prepared as the planar shear's (Cundall 1989): consolidated with μ = 0.01.
    state.params.materials[0].friction = 0.01;
    let quasi_static = 1e-3 * (PRESSURE / mat.density).sqrt() / d;
    let (w0, h0) = consolidate_box(&mut state, &mut pipe, dt, PRESSURE, quasi_static).context("consolidating the biaxial sample")?;
    state.params.materials[0].friction = mu;
    let sample = state.grains.len();
    let packing = state.grains.radius.iter().map(|r| std::f64::consts::PI * r * r).sum::<f64>() / (w0 * h0);
    for i in 0..state.grains.len() {
        if D2::to_array(state.grains.x[i])[1] < GLUE_D * d {
            state.grains.frozen[i] = true;
            state.grains.v[i] = D2::from_array([0.0; 3]);
            state.grains.omega[i] = 0.0;
        }
    }
    let sides = Sides::wrap(confinement, &mut state, PRESSURE, d, mat.density, packing);
    pipe.invalidate();
    // The membrane settles into the valleys between the outermost grains (its centre lines
    // enclose some 3% less than the walls did), the fluid's grains out to its surface, before
    // the area is taken as the start's.
    for _ in 0..SETTLE {
        sides.load(&mut state, dt);
        pipe.run(&mut state, dt, 1);
    }
    let a0 = sides.area(&state);
    let prepared = state.clone();
    let speed = SPEED_OVER_HEIGHT * h0;
    tracing::info!(
        "validate shear: biaxial, seed {seed}: {sample} grains, {:.1} x {:.1} D50, packing {packing:.3}, top at {:.1} mm/s",
        w0 / d,
        h0 / d,
        1e3 * speed
    );
    let top = |st: &DemState<D2>| D2::to_array(plane_point(st, 1))[1];
    let free = |st: &DemState<D2>| -> std::collections::HashMap<u64, [f64; 2]> {
        let g = &st.grains;
        (0..g.len())
            .filter(|&i| !g.frozen[i] && g.id[i] < MEMBRANE)
            .map(|i| {
                let x = D2::to_array(g.x[i]);
                (g.id[i], [x[0], x[1]])
            })
            .collect()
    };
    let start = free(&state);
    let mut snapshots = vec![(0.0, disks(&state))];
    let mut records = Vec::new();
    let (mut from, mut to) = (None, None);
    let (mut traction, mut pulls) = (Vec::new(), Vec::new());
    let mut axial = 0.0;
    while axial < END {
        if grains_service::signals::signalled() {
            anyhow::bail!("stopped by a signal");
        }
        // The top comes up to speed over the first 0.1% of strain (as the calibration's).
        let ramp = (axial / 0.001).clamp(0.05, 1.0);
        state.walls[1].velocity = D2::from_array([0.0, -ramp * speed, 0.0]);
        let mut load = 0.0;
        for _ in 0..RECORD {
            sides.load(&mut state, dt);
            pipe.run(&mut state, dt, 1);
            load += state.walls[1].load[1].abs();
        }
        if let Some(id) = DemPipeline::first_non_finite(&state) {
            anyhow::bail!("grain {id} is not finite: the biaxial test blew up at axial strain {axial:.4}");
        }
        let h = top(&state);
        axial = 1.0 - h / h0;
        let area = sides.area(&state);
        // The sample's width: the consolidated box's, changed as the chains' mean distance.
        let width = w0 * (area / h) / (a0 / h0);
        let sigma1 = load / RECORD as f64 / width + sides.on_top();
        records.push(Record {
            axial,
            volumetric: 1.0 - area / a0,
            sin_phi: (sigma1 - PRESSURE) / (sigma1 + PRESSURE),
        });
        if axial >= snapshots.len() as f64 * SNAPSHOT {
            snapshots.push((axial, disks(&state)));
        }
        if from.is_none() && axial >= WINDOW.0 {
            from = Some(free(&state));
        }
        if from.is_some() && to.is_none() {
            let (t, p) = sides.lateral(&pipe, &state);
            traction.push(t);
            pulls.push(p);
        }
        if to.is_none() && axial >= WINDOW.1 {
            to = Some(free(&state));
        }
        if records.len() % 200 == 0 {
            tracing::info!(
                "validate shear: biaxial, seed {seed}: axial strain {axial:.4}, sin phi {:.3}, volumetric {:.4}",
                records.last().map_or(0.0, |r| r.sin_phi),
                records.last().map_or(0.0, |r| r.volumetric)
            );
        }
    }
    let (from, to) = (from.context("the window's start")?, to.context("the window's end")?);
    let lateral = traction.iter().sum::<f64>() / traction.len() as f64;
    let pull = pulls.iter().sum::<f64>() / pulls.len() as f64;
    let (ids, x0, strain) = super::best_fit(&from, &to, d);
    let start: Vec<[f64; 2]> = ids.iter().map(|id| start[id]).collect();
    let found = inner_band(&x0, &strain, &start, EDGE_CELLS * CELLS_D[0] * d, d, d, w0.hypot(h0))?;
    let (peak, psi_peak) = peak_angles(&records);
    let (phi, psi) = window_angles(&records);
    let band_volume = band_volume(&found.bbox, &snapshots[0].1, &snapshots);
    Ok(BiaxialRun {
        seed,
        grains: sample,
        width: w0,
        height: h0,
        packing,
        records,
        t_s: found.t_s,
        fwhm: found.fwhm,
        angle: found.angle,
        counted: found.members.len(),
        band_volume,
        x0,
        band: found.members,
        peak,
        psi_peak,
        phi,
        psi,
        lateral,
        pull,
        wall: t0.elapsed().as_secs_f64(),
        sample: prepared,
        dt,
    })
}

/// App. A on the members of `x0` (positions at the window's start, their incremental
/// `strain` over it) that lay at least `edge` inside the box bounding their centres at the
/// start of the shortening (`start`; for the DEM the free grains', so the bottom margin is
/// counted from the glued layer's top): nearer, the strain is the boundary's (the membrane's,
/// the free faces', the platens'), not the band's, and the 98th percentile
/// picks the band's ends where it meets them. `size`: the members' diameter (a grain's, a
/// point's spacing).
fn inner_band(x0: &[[f64; 2]], strain: &[f64], start: &[[f64; 2]], edge: f64, size: f64, d: f64, reach: f64) -> anyhow::Result<InnerBand> {
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in start {
        for k in 0..2 {
            (lo[k], hi[k]) = (lo[k].min(p[k]), hi[k].max(p[k]));
        }
    }
    let inner: Vec<usize> = (0..x0.len())
        .filter(|&i| (0..2).all(|k| start[i][k] > lo[k] + edge && start[i][k] < hi[k] - edge))
        .collect();
    let (x, e): (Vec<[f64; 2]>, Vec<f64>) = inner.iter().map(|&i| (x0[i], strain[i])).unzip();
    let found =
        band::measure(&x, &e, band::percentile(&e, 0.98), size).context("no band: fewer than three members above the 98th percentile")?;
    let (angle, fwhm) = band_line(&x, &e, &found.grains, d, reach);
    let members: Vec<[f64; 2]> = found.grains.iter().map(|&i| x[i]).collect();
    Ok(InnerBand {
        bbox: BandBox::around(&members, found.angle, size),
        members: found.grains.iter().map(|&i| inner[i]).collect(),
        t_s: found.thickness / d,
        length: found.length / d,
        angle,
        fwhm,
    })
}

/// What [`inner_band`] measures.
struct InnerBand {
    /// App. A's band (indices into the positions), its box's thickness and length [D50], the
    /// box.
    members: Vec<usize>,
    bbox: BandBox,
    t_s: f64,
    length: f64,
    /// [`band_line`]'s inclination [°] and profile width [D50].
    angle: f64,
    fwhm: f64,
}

/// App. A's box around a band: its centre, the unit direction of its length, and its half
/// length and half thickness [m].
#[derive(Clone, Copy, Debug)]
struct BandBox {
    centre: [f64; 2],
    dir: [f64; 2],
    half: [f64; 2],
}

impl BandBox {
    /// The box of the centres `x` with its length along `angle` (radians from +x), grown by
    /// `size` (App. A's box of the grains, not of their centres: `band::measure`'s).
    fn around(x: &[[f64; 2]], angle: f64, size: f64) -> Self {
        let dir = [angle.cos(), angle.sin()];
        let normal = [-dir[1], dir[0]];
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for p in x {
            let uv = [p[0] * dir[0] + p[1] * dir[1], p[0] * normal[0] + p[1] * normal[1]];
            for k in 0..2 {
                (lo[k], hi[k]) = (lo[k].min(uv[k]), hi[k].max(uv[k]));
            }
        }
        let mid = [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])];
        BandBox {
            centre: [mid[0] * dir[0] + mid[1] * normal[0], mid[0] * dir[1] + mid[1] * normal[1]],
            dir,
            half: [0.5 * (hi[0] - lo[0] + size), 0.5 * (hi[1] - lo[1] + size)],
        }
    }

    /// The area of the `disks` (centre, radius) inside the box over the box's area, each disk
    /// clipped by the four sides (one that crosses a corner loses the corner's overlap twice:
    /// a few of the several hundred grains of a band's box).
    fn packing(&self, disks: impl IntoIterator<Item = ([f64; 2], f64)>) -> f64 {
        let normal = [-self.dir[1], self.dir[0]];
        let inside: f64 = disks
            .into_iter()
            .map(|(x, r)| {
                let rel = [x[0] - self.centre[0], x[1] - self.centre[1]];
                let (u, v) = (rel[0] * self.dir[0] + rel[1] * self.dir[1], rel[0] * normal[0] + rel[1] * normal[1]);
                let [a, b] = self.half;
                (std::f64::consts::PI * r * r - cap(r, a - u) - cap(r, a + u) - cap(r, b - v) - cap(r, b + v)).max(0.0)
            })
            .sum();
        inside / (4.0 * self.half[0] * self.half[1])
    }
}

/// The area of a disk of radius `r` beyond a line at signed distance `h` from its centre.
fn cap(r: f64, h: f64) -> f64 {
    if h >= r {
        0.0
    } else if h <= -r {
        std::f64::consts::PI * r * r
    } else {
        r * r * (h / r).acos() - h * (r * r - h * h).sqrt()
    }
}

/// The volumetric strain of the band's box (compression positive, as [`Record::volumetric`])
/// at each snapshot (axial strain, the grains as disks): 1 − Φ0 / Φ, Φ the grains' area in the
/// box over its area and Φ0 that of `start`'s grains (the specimen at the start of the
/// shortening). The box is App. A's at the window, fixed in space: the material flows
/// through it as the top comes down.
fn band_volume(bbox: &BandBox, start: &[([f64; 2], f64)], snapshots: &[(f64, Disks)]) -> Vec<[f64; 2]> {
    let phi0 = bbox.packing(start.iter().copied());
    snapshots
        .iter()
        .map(|(axial, disks)| [*axial, 1.0 - phi0 / bbox.packing(disks.iter().copied())])
        .collect()
}

/// Axial strain between the snapshots of the grains that [`band_volume`] reads.
const SNAPSHOT: f64 = 0.0025;

/// Grains as disks: centre and radius.
type Disks = Vec<([f64; 2], f64)>;

/// The disks of `state`'s specimen (not the membrane's nodes).
fn disks(state: &DemState<D2>) -> Disks {
    let g = &state.grains;
    (0..g.len())
        .filter(|&i| g.id[i] < MEMBRANE)
        .map(|i| ([g.x[i].x, g.x[i].y], g.radius[i]))
        .collect()
}

/// The band's centre line, the principal axis of the band's members `band` among the
/// positions `x0` (the least-squares line through them; App. A's box may lean from it): its
/// inclination from the horizontal (the σ1 plane) in 0–90° [°], and the width at half peak
/// [D50] of the incremental `strain`'s profile across it (slabs SLAB_D thick by the distance
/// from it, shifted by `reach`, at least the specimen's diagonal, to be positive).
fn band_line(x0: &[[f64; 2]], strain: &[f64], band: &[usize], d: f64, reach: f64) -> (f64, f64) {
    let n = band.len() as f64;
    let c = band.iter().fold([0.0, 0.0], |a, &i| [a[0] + x0[i][0] / n, a[1] + x0[i][1] / n]);
    let (mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0);
    for &i in band {
        let (dx, dy) = (x0[i][0] - c[0], x0[i][1] - c[1]);
        (sxx, syy, sxy) = (sxx + dx * dx, syy + dy * dy, sxy + dx * dy);
    }
    let axis = 0.5 * (2.0 * sxy).atan2(sxx - syy);
    let angle = axis.to_degrees().abs();
    let angle = if angle > 90.0 { 180.0 - angle } else { angle };
    let normal = [-axis.sin(), axis.cos()];
    let across = x0
        .iter()
        .zip(strain)
        .map(|(p, &e)| ((p[0] - c[0]) * normal[0] + (p[1] - c[1]) * normal[1] + reach, e));
    let profile = super::slab_profile(across, 2.0 * reach, d);
    (angle, super::half_peak_width(&profile, super::SLAB_D))
}

/// The dilatancy angle of the records in `from..=to` of axial strain: sin ψ = −Δε_v / (Δε_1 −
/// Δε_3) in plane strain with ε_3 = ε_v − ε_1 (compression positive), from the volume's
/// least-squares slope against the axial strain [°].
fn dilatancy(records: &[Record], from: f64, to: f64) -> f64 {
    let w: Vec<&Record> = records.iter().filter(|r| (from..=to).contains(&r.axial)).collect();
    let n = w.len().max(1) as f64;
    let (ma, mv) = (
        w.iter().map(|r| r.axial).sum::<f64>() / n,
        w.iter().map(|r| r.volumetric).sum::<f64>() / n,
    );
    let slope = w.iter().map(|r| (r.axial - ma) * (r.volumetric - mv)).sum::<f64>()
        / w.iter().map(|r| (r.axial - ma).powi(2)).sum::<f64>().max(f64::MIN_POSITIVE);
    // dε_v / dε_1 = slope; Δε_1 − Δε_3 = 2 Δε_1 − Δε_v.
    (-slope / (2.0 - slope)).asin().to_degrees()
}

/// The peak of the mobilised friction, as a running mean over PEAK_SPAN of axial strain (a
/// single record rattles by a few degrees), its axial strain and angle [°]; and the dilatancy
/// angle over the PEAK_SPAN after it [°].
fn peak_angles(records: &[Record]) -> ((f64, f64), f64) {
    let mut best = (0.0, f64::MIN);
    for (k, r) in records.iter().enumerate() {
        let span: Vec<f64> = records[k..]
            .iter()
            .take_while(|q| q.axial <= r.axial + PEAK_SPAN)
            .map(|q| q.sin_phi.asin().to_degrees())
            .collect();
        let mean = span.iter().sum::<f64>() / span.len() as f64;
        if mean > best.1 {
            best = (r.axial + 0.5 * PEAK_SPAN, mean);
        }
    }
    (best, dilatancy(records, best.0, best.0 + PEAK_SPAN))
}

/// The mobilised friction angle (mean over the window) and the dilatancy angle over it [°].
fn window_angles(records: &[Record]) -> (f64, f64) {
    let w: Vec<&Record> = records.iter().filter(|r| (WINDOW.0..=WINDOW.1).contains(&r.axial)).collect();
    let phi = w.iter().map(|r| r.sin_phi.asin().to_degrees()).sum::<f64>() / w.len().max(1) as f64;
    (phi, dilatancy(records, WINDOW.0, WINDOW.1))
}

/// Chen 2021 §6.2 as a DEM: the band's thickness against the paper's, its inclination
/// between Roscoe's and Coulomb's, the stress and volume against the axial strain.
pub(in crate::validate) fn validate(args: &super::ValidateArgs) -> anyhow::Result<Part> {
    let mut part = Part::default();
    let mut md = String::from("## Biaxial compression (Chen 2021 §6.2)\n\n");
    let path = args.scenes.join(SCENE);
    let scene = grains_protocol::scene::load(&path).with_context(|| format!("loading {}", path.display()))?;
    let material = scene.bodies[0].material;
    let d = 2.0 * scene.materials[material].dem.as_ref().context("a DEM material")?.radius;
    let runs: Vec<BiaxialRun> = SEEDS
        .iter()
        .map(|&seed| run(&scene, material, seed, args.biaxial_confinement))
        .collect::<anyhow::Result<_>>()?;
    let r = &runs[0];
    let _ = writeln!(
        &mut md,
        "### DEM\n\nChen 2021 Table 5 in D50: {} grains of `{SCENE}`, {:.1} × {:.1} D50 after \
         consolidation at {PRESSURE:.0} Pa with μ = 0.01 (packing {:.3}; seed {}), then shortened with μ = {} at {:.1}% of its \
         height a second (Chen's 2 cm/s) to {:.2}% of axial strain, the sides held at {PRESSURE:.0} Pa by {}, the bottom no-slip \
         (grains within {GLUE_D} D50 glued), the top frictionless. Band (App. A) over axial strain {:.1}–{:.1}% (Fig. 18), \
         counting the grains that started the shortening {:.0} D50 or more inside the box their centres spanned (the free \
         grains'; nearer, the strain is the membrane's and the platens'), \
         its inclination the least-squares line through App. A's grains; the profile of the incremental strain across that \
         line in {}-D50 slabs. One run per seed (the samples differ in their lattice's jitter and radii).\n\n\
         | seed | t_s (App. A) | profile across the band at half peak | grains counted | band's inclination from horizontal | peak φ (axial strain), ψ after it | φ, ψ over the window | the sides' push over the window / p (the membrane's springs' net pull) | wall |\n\
         |---:|---:|---:|---:|---:|---:|---:|---:|---:|",
        r.grains,
        r.width / d,
        r.height / d,
        r.packing,
        r.seed,
        scene.materials[material].dem.as_ref().map_or(0.0, |m| m.friction),
        100.0 * SPEED_OVER_HEIGHT,
        100.0 * END,
        match args.biaxial_confinement {
            Confinement::Membrane =>
                format!("a membrane of nodes {NODE_SPACING_D} D50 apart (App. B: k_ms = {K_MS:.0} N/m, γ_ms = {GAMMA_MS} N s/m)"),
            Confinement::Fluid =>
                "a fluid on the packing's surface (`--biaxial-confinement fluid`: `grains_dem::fluid`, cells of 2 D50)".into(),
        },
        100.0 * WINDOW.0,
        100.0 * WINDOW.1,
        EDGE_CELLS * CELLS_D[0],
        super::SLAB_D,
    );
    for r in &runs {
        let _ = writeln!(
            &mut md,
            "| {} | {:.1} D50 | {:.0} D50 | {} | {:.1}° | {:.2}° ({:.2}%), {:.2}° | {:.2}°, {:.2}° | {:.4} (springs {:+.4}) | {:.0} s |",
            r.seed,
            r.t_s,
            r.fwhm,
            r.counted,
            r.angle,
            r.peak.1,
            100.0 * r.peak.0,
            r.psi_peak,
            r.phi,
            r.psi,
            r.lateral,
            r.pull,
            r.wall
        );
    }
    let _ = writeln!(
        &mut md,
        "\nPaper: t_s = {PAPER_BAND} D50 for the DEM and the hybrid, 7 D50 for the continuum (Fig. 18).\n"
    );
    let list = |f: &dyn Fn(&BiaxialRun) -> String| runs.iter().map(f).collect::<Vec<_>>().join(", ");
    let t_s = runs.iter().map(|r| r.t_s).sum::<f64>() / runs.len() as f64;
    part.check(
        "biaxial (DEM): band thickness",
        format!("Chen 2021 Fig. 18: {PAPER_BAND} D50 (DEM and hybrid)"),
        format!(
            "{t_s:.1} D50, the mean of {} seeds ({}; the profiles across them at half peak: {} D50)",
            runs.len(),
            list(&|r| format!("{:.1}", r.t_s)),
            list(&|r| format!("{:.0}", r.fwhm))
        ),
        format!("±{BAND_TOLERANCE} D50"),
        (t_s - PAPER_BAND).abs() <= BAND_TOLERANCE,
    );
    // The band forms at the peak: its angles are the peak's (Vermeer 1990's bifurcation).
    let range = |r: &BiaxialRun| (45.0 + 0.5 * r.psi_peak, 45.0 + 0.5 * r.peak.1);
    part.check(
        "biaxial (DEM): the band's inclination",
        "between Roscoe's 45° + ψ/2 and Coulomb's 45° + φ/2 (Vardoulakis 1980; Vermeer 1990), φ and ψ at each run's peak",
        list(&|r| {
            let (roscoe, coulomb) = range(r);
            format!("{:.1}° (Roscoe {roscoe:.1}°, Coulomb {coulomb:.1}°)", r.angle)
        }),
        "within 3° of that range on every seed",
        runs.iter().all(|r| {
            let (roscoe, coulomb) = range(r);
            r.angle >= roscoe - 3.0 && r.angle <= coulomb + 3.0
        }),
    );
    part.check(
        "biaxial (DEM): the sides hold the confining pressure",
        "App. B: σ3 = p on the grains",
        format!(
            "{} {} p over the window",
            match args.biaxial_confinement {
                Confinement::Membrane => "the grains' contacts with the membrane's free nodes carry",
                Confinement::Fluid => "the fluid's net push on each half of the sample over its height is",
            },
            list(&|r| format!("{:.4}", r.lateral))
        ),
        "within 2% on every seed",
        runs.iter().all(|r| (r.lateral - 1.0).abs() <= 0.02),
    );
    let curve = |f: fn(&Record) -> f64| {
        runs.iter()
            .map(|r| {
                Series::new(
                    format!("DEM, seed {}", r.seed),
                    Kind::Line,
                    r.records.iter().map(|x| (100.0 * x.axial, f(x))).collect(),
                )
            })
            .collect::<Vec<_>>()
    };
    for (stem, caption, y_label, points) in [
        (
            "shear_biaxial_friction",
            "Biaxial compression (DEM): the mobilised friction against the axial strain (Chen Fig. 17, left)",
            "phi = asin((s1 - s3) / (s1 + s3)) [deg]",
            curve(|x| x.sin_phi.asin().to_degrees()),
        ),
        (
            "shear_biaxial_volume",
            "Biaxial compression (DEM): the volumetric strain against the axial strain (Chen Fig. 17, middle)",
            "volumetric strain [%] (compression +)",
            curve(|x| 100.0 * x.volumetric),
        ),
    ] {
        let chart = Chart {
            title: caption.into(),
            x_label: "axial strain [%]".into(),
            y_label: y_label.into(),
            series: points,
            ..Chart::default()
        };
        part.chart(&args.out, stem, caption, &chart)?;
    }
    for r in &runs {
        let chart = super::band_chart(
            format!("Biaxial compression (DEM, seed {}): the band's grains (App. A)", r.seed),
            &r.x0,
            &r.band,
            d,
            "grains",
        );
        part.chart(
            &args.out,
            &format!("shear_biaxial_band_s{}", r.seed),
            format!(
                "Biaxial compression (DEM, seed {}): the grains App. A counts in the band, where they were at {:.1}% of axial strain",
                r.seed,
                100.0 * WINDOW.0
            ),
            &chart,
        )?;
    }
    if let Err(e) = continuum::continuum(&scene, material, &runs, args, &mut part, &mut md) {
        super::unfinished(&mut part, &mut md, "Continuum", "biaxial (continuum)", &e);
    }
    part.md = md;
    Ok(part)
}

#[cfg(test)]
mod tests {
    use super::continuum::platen;
    use super::*;
    use crate::calibrate::box_stresses;
    use crate::validate::shear::membrane::Membrane;

    /// σyy by row of points (mean of −τ_yy / J, bottom first) of an elastic block of 20 × 30
    /// points (two per cell and axis, the continuum biaxial's layout) in a fluid at p, fixed at
    /// the bottom, pressed 0.3% by a frictionless top moving down, held there, and the top's
    /// force over the block's width. The top is [`platen`] on the points, or a slip plane of
    /// the grid's nodes as the biaxial had it.
    fn pressed_block(on_points: bool) -> (Vec<f64>, f64) {
        use grains_grid::{Grid, Kernel};
        use grains_mpm::boundary::{Contact, Geometry, Wall};
        use grains_mpm::constitutive::plasticity_drucker_prager::DruckerPragerYue;
        use grains_mpm::matrix::{Matrix, MpmSpace};
        use grains_mpm::pipeline::{MAX_CFL, Model, MpmParams, MpmPipeline, Transfer, cfl_time_step};
        use grains_mpm::points::Points;
        let (spacing, cols, rows, rho, p) = (1e-3, 20usize, 30usize, 1600.0, PRESSURE);
        let (w, height, h) = (cols as f64 * spacing, rows as f64 * spacing, 2.0 * spacing);
        let model = Model::Elastic(DruckerPragerYue {
            bulk: 1e6,
            shear: 0.6e6,
            alpha: 0.0,
            rate: None,
        });
        let top = Wall {
            geometry: Geometry::Plane {
                point: D2::from_array([0.0, height, 0.0]),
                normal: D2::from_array([0.0, -1.0, 0.0]),
            },
            contact: Contact::Slip,
            velocity: D2::from_array([0.0; 3]),
            shift: D2::from_array([0.0; 3]),
            id: 0,
        };
        let mut params = MpmParams::<D2> {
            grid: Grid {
                origin: [-4.0 * h, -2.0 * h, 0.0],
                h,
                nodes: [cols as u64 / 2 + 9, rows as u64 / 2 + 8, 1],
                period: [0, 0, 0],
            },
            kernel: Kernel::Gimp { half_width: 0.5 * spacing },
            model,
            gravity: D2::from_array([0.0; 3]),
            transfer: Transfer::Apic,
            domain_walls: Some(Contact::Sticky),
            walls: if on_points { Vec::new() } else { vec![top] },
            point_loads: grains_mpm::pipeline::PointLoads::Face,
            ambient_pressure: p,
        };
        let mut pts = Points::<D2>::default();
        let b_e = model.strain_of_stress(&(<D2 as MpmSpace>::M::identity() * -p));
        for j in 0..rows {
            for i in 0..cols {
                let x = D2::from_array([(i as f64 + 0.5) * spacing, (j as f64 + 0.5) * spacing, 0.0]);
                pts.push(x, rho * spacing * spacing, spacing * spacing, 0.6);
                let k = pts.len() - 1;
                pts.b_e[k] = b_e;
                pts.tau[k] = model.kirchhoff(&b_e);
            }
        }
        let modulus = model.p_wave_modulus(2);
        let dt = 0.5 * MAX_CFL * cfl_time_step(&model, rho, h, 2);
        let transit = height / (modulus / rho).sqrt();
        // Pressed over 40 transits, held for 40.
        let (press, hold) = ((40.0 * transit / dt) as usize, (40.0 * transit / dt) as usize);
        let speed = 0.003 * height / (press as f64 * dt);
        let mut pipe = MpmPipeline::<D2>::new(1).unwrap();
        let (mut travel, mut rows_syy, mut force) = (0.0, vec![0.0; rows], 0.0);
        for step in 0..press + hold {
            let vy = if step < press { -speed } else { 0.0 };
            if on_points {
                platen(&mut pts, height - travel, vy, 0.5 * spacing, modulus);
            } else {
                params.walls[0].set_velocity(D2::from_array([0.0, vy, 0.0]), pipe.time);
            }
            travel -= vy * dt;
            pipe.phase1(&pts, &params, dt).unwrap();
            pipe.phase2(&mut pts, &params, dt).unwrap();
            if step >= press + hold / 2 {
                let mut by_row = vec![(0.0, 0usize); rows];
                for k in 0..pts.len() {
                    let j = ((pts.id[k] as usize) / cols).min(rows - 1);
                    by_row[j].0 -= pts.tau[k].y_axis.y / pts.jacobian[k];
                    by_row[j].1 += 1;
                }
                for (r, (s, c)) in rows_syy.iter_mut().zip(by_row) {
                    *r += s / c as f64 / (hold - hold / 2) as f64;
                }
                force += if on_points {
                    pts.loads.iter().map(|(_, f)| -f.y).sum::<f64>()
                } else {
                    pipe.wall_loads[0].y
                } / (hold - hold / 2) as f64;
            }
        }
        (rows_syy, force / w)
    }

    /// The top platen on the points' faces passes an even σyy to the top row of an elastic
    /// block (statics: σyy the same in every row, and the platen's force over the width with
    /// the fluid's p): 0.7% worst, where a slip plane of the grid's nodes (the platen the
    /// biaxial had) puts the top rows 4% over (printed). Fails with the loads through the
    /// points' weights (`PointLoads::Weights`: the top cell carries 3/4, 21.7% off), or with
    /// the platen's force lost or of the wrong sign.
    /// App. A's box as the band-volume measure reads it (Chen Fig. 17, right): the box of a
    /// rectangle's corners, turned, is that rectangle (grown by the size); a square lattice
    /// of disks (r = 0.5, spacing 1.1 mm) reads π r² / s² = 0.6491 in a turned box of
    /// 41 × 13 mm at two places on it (the disks clipped by its sides; within 0.5%, measured
    /// 0.02% and 0.08%); a disk whose centre lies on a side counts half; the lattice spread
    /// by 1% along both axes reads a volumetric strain of 1 − 1.01² = −2.01% (within 0.1%,
    /// measured −2.08%: the box's edges cut the two lattices differently).
    #[test]
    fn a_band_box_reads_the_packing_of_its_grains() {
        use std::f64::consts::PI;
        let (angle, size) = (0.6f64, 1e-3);
        let (c, sn) = (angle.cos(), angle.sin());
        let turn = |p: [f64; 2]| [p[0] * c - p[1] * sn + 0.003, p[0] * sn + p[1] * c - 0.002];
        let corners = [[0.0, 0.0], [0.04, 0.0], [0.04, 0.012], [0.0, 0.012]].map(turn);
        let b = BandBox::around(&corners, angle, size);
        let centre = turn([0.02, 0.006]);
        assert!(
            (b.centre[0] - centre[0]).abs() < 1e-12 && (b.centre[1] - centre[1]).abs() < 1e-12,
            "{:?}",
            b.centre
        );
        assert!(
            (b.half[0] - 0.0205).abs() < 1e-12 && (b.half[1] - 0.0065).abs() < 1e-12,
            "{:?}",
            b.half
        );
        let (r, s) = (0.5e-3, 1.1e-3);
        let lattice = |stretch: f64| -> Vec<([f64; 2], f64)> {
            (-60..60)
                .flat_map(|i| (-60..60).map(move |j| ([i as f64 * s * stretch, j as f64 * s * stretch], r)))
                .collect()
        };
        let want = PI * r * r / (s * s);
        for centre in [[0.0, 0.0], [0.0123, -0.0071]] {
            let b = BandBox { centre, ..b };
            let got = b.packing(lattice(1.0));
            assert!((got / want - 1.0).abs() < 0.005, "packing {got} against {want}");
        }
        let flat = BandBox {
            centre: [0.0; 2],
            dir: [1.0, 0.0],
            half: [0.01, 0.005],
        };
        let half = flat.packing([([0.002, 0.005], r)]) * 4.0 * 0.01 * 0.005;
        assert!((half / (0.5 * PI * r * r) - 1.0).abs() < 1e-12, "{half}");
        let strain = band_volume(&b, &lattice(1.0), &[(0.01, lattice(1.01))]);
        assert!((strain[0][1] - (1.0 - 1.01f64.powi(2))).abs() < 1e-3, "{strain:?}");
    }

    #[test]
    fn the_platen_on_the_points_loads_the_top_row_as_the_rest() {
        for on_points in [false, true] {
            let (rows, platen) = pressed_block(on_points);
            let n = rows.len();
            let middle = rows[n / 3..2 * n / 3].iter().sum::<f64>() / (n / 3) as f64;
            let worst = rows.iter().map(|s| (s / middle - 1.0).abs()).fold(0.0, f64::max);
            eprintln!(
                "platen on the {}: σyy middle {middle:.1} Pa, top rows {:.1} {:.1} {:.1} {:.1}, bottom {:.1} {:.1}, worst row {:.1}% off, the platen's force / width {platen:.1} Pa",
                if on_points { "points" } else { "nodes" },
                rows[n - 1],
                rows[n - 2],
                rows[n - 3],
                rows[n - 4],
                rows[0],
                rows[1],
                100.0 * worst
            );
            if on_points {
                assert!(middle > 1.5 * PRESSURE, "the block is pressed: σyy {middle:.1} Pa");
                assert!(worst < 0.05, "a row's σyy is {:.1}% off the middle's", 100.0 * worst);
                // The platen carries σyy less the fluid's p on the top face.
                assert!(
                    ((platen + PRESSURE) / middle - 1.0).abs() < 0.05,
                    "{platen:.1} + p against {middle:.1}"
                );
            }
        }
    }

    /// The membrane's and the fluid's tests' sample: a box of about 400 grains of the scene's
    /// material, consolidated at p by its servo walls (one thread).
    struct Consolidated {
        density: f64,
        d: f64,
        state: DemState<D2>,
        pipe: DemPipeline<D2>,
        dt: f64,
        w0: f64,
        h0: f64,
    }

    /// `steps` steps of the sample held by `sides` with its top platen fixed: the platen's
    /// mean load and the area at the end.
    fn held(sides: &Sides, state: &mut DemState<D2>, pipe: &mut DemPipeline<D2>, dt: f64, steps: usize) -> (f64, f64) {
        let mut load = 0.0;
        for _ in 0..steps {
            sides.load(state, dt);
            pipe.run(state, dt, 1);
            load += state.walls[1].load[1].abs();
        }
        (load / steps as f64, sides.area(state))
    }

    fn consolidated() -> Consolidated {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes").join(SCENE);
        let scene = grains_protocol::scene::load(&path).unwrap();
        let mat = &scene.materials[scene.bodies[0].material];
        let d = 2.0 * mat.dem.as_ref().unwrap().radius;
        let spacing = crate::calibrate::shear::ShearCell::spacing(mat.dem.as_ref().unwrap());
        let width = 16.0 * spacing;
        let mut state = box_sample(mat, width, 1.5 * width, 3).unwrap();
        let (dt, ..) = grains_dem_service::setup::stable_step(&scene).unwrap();
        let mut pipe = DemPipeline::<D2>::new(1).unwrap();
        let rate = 1e-3 * (PRESSURE / mat.density).sqrt() / d;
        let (w0, h0) = consolidate_box(&mut state, &mut pipe, dt, PRESSURE, rate).unwrap();
        Consolidated {
            density: mat.density,
            d,
            state,
            pipe,
            dt,
            w0,
            h0,
        }
    }

    /// App. B's membrane holds a sample at its pressure: a 400-grain box consolidated at p,
    /// its side walls replaced by membranes at p and its top platen held, passes p to the
    /// grains (its traction, and their lateral stress by Love–Weber within 5%: 0.967 p, the
    /// estimator's own error at the boundary), keeps its area, and no grain gets out between
    /// the nodes. (The vertical stress is not p: at a fixed height a frictional packing may keep
    /// less; it settles at 0.92 p here.) With the membrane's pressure at zero the sample
    /// springs out and σxx falls: the test fails then.
    #[test]
    fn a_membrane_holds_the_sample_at_its_pressure() {
        let Consolidated {
            density,
            d,
            mut state,
            mut pipe,
            dt,
            w0,
            h0,
        } = consolidated();
        let (sxx, syy, ..) = box_stresses(&mut state, &mut pipe, dt, 200);
        assert!(
            (sxx / PRESSURE - 1.0).abs() < 0.03 && (syy / PRESSURE - 1.0).abs() < 0.03,
            "{sxx} {syy}"
        );
        let membrane = Membrane::wrap(&mut state, PRESSURE, d, density);
        pipe.invalidate();
        let sides = Sides::Membrane(membrane);
        let (_, a0) = held(&sides, &mut state, &mut pipe, dt, SETTLE);
        let (load, area) = held(&sides, &mut state, &mut pipe, dt, 4000);
        let Sides::Membrane(membrane) = sides else { unreachable!() };
        let width = w0 * area / a0;
        let syy = load / width;
        let s = crate::calibrate::shear::love_weber(&pipe, &state, width * h0);
        let traction = membrane.traction(&pipe, &state);
        eprintln!(
            "membrane: width {w0:.6} -> {width:.6} m, σyy on the platen {syy:.1} Pa, traction {traction:.1} Pa, the grains' σxx {:.1} σyy {:.1} Pa (Love–Weber)",
            s[0], s[1]
        );
        assert!(
            (traction / PRESSURE - 1.0).abs() < 0.02,
            "the membrane's traction is {traction:.1} Pa"
        );
        // No grain gets out between the nodes.
        let g = &state.grains;
        let node_x = |side: usize| membrane.chains[side].iter().map(|&id| g.x[g.index_of(id).unwrap()].x);
        let (left, right) = (node_x(0).fold(f64::MAX, f64::min), node_x(1).fold(f64::MIN, f64::max));
        assert!(
            (0..g.len())
                .filter(|&i| g.id[i] < MEMBRANE)
                .all(|i| (left..=right).contains(&g.x[i].x)),
            "a grain got out"
        );
        assert!((s[0] / PRESSURE - 1.0).abs() < 0.05, "the grains' σxx is {:.1} Pa", s[0]);
        assert!(
            (area / a0 - 1.0).abs() < 0.005,
            "the area moved by {:.3}%",
            100.0 * (area / a0 - 1.0)
        );
    }

    /// The fluid holds a sample at its pressure as the membrane does (the same 400-grain box,
    /// consolidated at p, its side walls replaced by the fluid at p, its top held): the
    /// contacts carry σxx across the middle within 5% of p, the area is kept within 0.5%,
    /// and no grain gets out past where the walls were (a diameter of slack). Love–Weber over
    /// the whole box reads less (0.85 p, printed): the fluid's forces act on the centres of
    /// the grains within about a cell of the surface, so the outer grains' contacts carry
    /// less than p. With the fluid's pressure at zero the sample springs out and σxx falls:
    /// the test fails then (checked).
    #[test]
    fn a_fluid_holds_the_sample_at_its_pressure() {
        let Consolidated {
            density,
            d,
            mut state,
            mut pipe,
            dt,
            w0,
            h0,
        } = consolidated();
        let walls = (plane_point(&state, 0).x, plane_point(&state, 1).x);
        let packing = state.grains.radius.iter().map(|r| std::f64::consts::PI * r * r).sum::<f64>() / (w0 * h0);
        let sides = Sides::wrap(Confinement::Fluid, &mut state, PRESSURE, d, density, packing);
        pipe.invalidate();
        let (_, a0) = held(&sides, &mut state, &mut pipe, dt, SETTLE);
        let (load, area) = held(&sides, &mut state, &mut pipe, dt, 4000);
        let width = w0 * area / a0;
        let s = crate::calibrate::shear::love_weber(&pipe, &state, width * h0);
        let (lateral, _) = sides.lateral(&pipe, &state);
        // σxx through the vertical cut at mid-width: the contacts' x-force across it over
        // the height between the platens.
        let g = &state.grains;
        let mid = g.x.iter().map(|x| x.x).sum::<f64>() / g.len() as f64;
        let across: f64 = pipe
            .contact_forces(&state)
            .into_iter()
            .filter(|&(i, _, _, b)| (g.x[i].x < mid) != (g.x[i].x - b.x < mid))
            .map(|(i, _, f, _)| if g.x[i].x < mid { f.x } else { -f.x })
            .sum();
        let cut = -across / (plane_point(&state, 1).y - plane_point(&state, 0).y);
        eprintln!(
            "fluid: area {:.4} of the start's, σyy on the platen + p {:.1} Pa, the fluid's push {lateral:.4} p, σxx across the middle {cut:.1} Pa, the grains' σxx {:.1} σyy {:.1} Pa (Love–Weber over the box)",
            area / a0,
            load / width + PRESSURE,
            s[0],
            s[1]
        );
        assert!(g.x.iter().all(|x| x.x > walls.0 - d && x.x < walls.1 + d), "a grain got out");
        assert!((cut / PRESSURE - 1.0).abs() < 0.05, "σxx across the middle is {cut:.1} Pa");
        assert!(
            (area / a0 - 1.0).abs() < 0.005,
            "the area moved by {:.3}%",
            100.0 * (area / a0 - 1.0)
        );
    }
}
