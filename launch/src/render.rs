//! `grains render`: a picture of a run's frame as PNG, for people who watch flows rather than
//! read them. Grains are drawn as disks of their own radius (2D, or the x–y projection of 3D
//! spheres), material points as dots of half their cell's point spacing; colour by model
//! (points blue, grains sand) or by speed. The view is the scene's domain, x to the right and
//! y up, at `--width` pixels across.

use anyhow::{Context, bail};
use grains_service::vtu::{Frame, collection};
use plotters::prelude::*;
use std::path::{Path, PathBuf};

#[derive(Debug, Clone, clap::Args)]
pub struct RenderArgs {
    /// A run's output directory (`out/<scene>/<run-id>`).
    pub run: PathBuf,
    /// The frame's macro-step (default: the last frame written).
    #[arg(long)]
    pub step: Option<u64>,
    /// The PNG to write (default `<run>/frames/render_<step>.png`).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Width of the picture [pixels]; the height follows the domain's aspect.
    #[arg(long, default_value_t = 1200)]
    pub width: u32,
    /// What the colour shows.
    #[arg(long, value_enum, default_value_t = Colour::Model)]
    pub colour: Colour,
    /// The part of the domain to draw, `xmin,ymin,xmax,ymax` [m] (default: the whole domain).
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    pub view: Option<Vec<f64>>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Colour {
    /// Material points blue, grains sand.
    Model,
    /// Speed |v|, from dark blue (at rest) to yellow (the fastest material of the frame).
    Speed,
}

/// What a picture shows: the view's box [m] and the material in it.
pub struct Scene2 {
    pub min: [f64; 2],
    pub max: [f64; 2],
    /// Grains: centre [m], radius [m], speed [m/s].
    pub grains: Vec<([f64; 2], f64, f64)>,
    /// Points: centre [m], half their spacing [m], speed [m/s].
    pub points: Vec<([f64; 2], f64, f64)>,
}

const BACKGROUND: RGBColor = RGBColor(255, 255, 255);
const SAND: RGBColor = RGBColor(194, 138, 64);
const CONTINUUM: RGBColor = RGBColor(70, 130, 200);

/// `grains render`: reads the frame and writes the picture; returns its path.
pub fn render(args: &RenderArgs) -> anyhow::Result<PathBuf> {
    let scene = grains_protocol::scene::load(&args.run.join("scene.toml"))
        .with_context(|| format!("{}: not a run directory (it needs the run's scene.toml)", args.run.display()))?;
    let step = match args.step {
        Some(s) => s,
        None => last_step(&args.run)?,
    };
    let frames = args.run.join("frames");
    let read = |name: &str| -> anyhow::Result<Option<Frame>> {
        let file = frames.join(format!("{name}_{step:08}.vtu"));
        if file.exists() { Frame::read(&file).map(Some) } else { Ok(None) }
    };
    let (grains, points) = (read("grains")?, read("points")?);
    if grains.is_none() && points.is_none() {
        bail!(
            "{}: no frame of step {step} (frames are written every output.frames_every steps)",
            frames.display()
        );
    }
    let point_half = 0.5 * scene.domain.cell_size / scene.mpm.points_per_axis as f64;
    let d = &scene.domain;
    let (min, max) = match args.view.as_deref() {
        Some(&[x0, y0, x1, y1]) if x1 > x0 && y1 > y0 => ([x0, y0], [x1, y1]),
        Some(v) => bail!("--view {v:?}: give xmin,ymin,xmax,ymax with xmax > xmin and ymax > ymin"),
        None => ([d.min[0], d.min[1]], [d.max[0], d.max[1]]),
    };
    let view = Scene2 {
        min,
        max,
        grains: grains.map_or(Ok(Vec::new()), |f| material(&f, None))?,
        points: points.map_or(Ok(Vec::new()), |f| material(&f, Some(point_half)))?,
    };
    let out = args.out.clone().unwrap_or_else(|| frames.join(format!("render_{step:08}.png")));
    if let Some(dir) = out.parent() {
        std::fs::create_dir_all(dir)?;
    }
    {
        let root = BitMapBackend::new(&out, size(&view, args.width)).into_drawing_area();
        draw(&view, args.colour, &root).with_context(|| format!("writing {}", out.display()))?;
    }
    Ok(out)
}

/// The step of the last frame of a run (grains or points).
fn last_step(run: &Path) -> anyhow::Result<u64> {
    let mut last = None;
    for name in ["grains", "points"] {
        let pvd = run.join("frames").join(format!("{name}.pvd"));
        if pvd.exists()
            && let Some((_, file)) = collection(&pvd)?.pop()
        {
            let stem = file.file_stem().and_then(|s| s.to_str()).unwrap_or("");
            let step: u64 = stem
                .rsplit('_')
                .next()
                .and_then(|s| s.parse().ok())
                .context("a frame file without its step")?;
            last = last.max(Some(step));
        }
    }
    last.with_context(|| format!("{}: the run wrote no frames", run.display()))
}

/// The material of a frame: grains with their `radius`, or points with `half` their spacing.
fn material(f: &Frame, half: Option<f64>) -> anyhow::Result<Vec<([f64; 2], f64, f64)>> {
    let size: Vec<f64> = match half {
        Some(h) => vec![h; f.points.len()],
        None => f.array("radius").context("a grain frame without a radius array")?.to_vec(),
    };
    let v = f.array("velocity").context("a frame without a velocity array")?;
    Ok(f.points
        .iter()
        .zip(size)
        .enumerate()
        .map(|(k, (x, s))| {
            (
                [x[0], x[1]],
                s,
                (v[3 * k].powi(2) + v[3 * k + 1].powi(2) + v[3 * k + 2].powi(2)).sqrt(),
            )
        })
        .collect())
}

/// Picture size for `width` pixels across the view.
pub fn size(view: &Scene2, width: u32) -> (u32, u32) {
    let aspect = (view.max[1] - view.min[1]) / (view.max[0] - view.min[0]);
    (width.max(16), ((width as f64 * aspect).round() as u32).max(16))
}

/// Draws the view on `root` (a picture of [`size`] pixels).
pub fn draw<DB: DrawingBackend>(view: &Scene2, colour: Colour, root: &DrawingArea<DB, plotters::coord::Shift>) -> anyhow::Result<()> {
    let (w, _) = root.dim_in_pixel();
    let scale = w as f64 / (view.max[0] - view.min[0]);
    let at = |x: [f64; 2]| {
        (
            (((x[0] - view.min[0]) * scale).round() as i32),
            (((view.max[1] - x[1]) * scale).round() as i32),
        )
    };
    let fastest = view.grains.iter().chain(&view.points).map(|m| m.2).fold(0.0, f64::max);
    let paint = |base: RGBColor, speed: f64| match colour {
        Colour::Model => base,
        Colour::Speed => ramp(if fastest > 0.0 { speed / fastest } else { 0.0 }),
    };
    let fail = |e: DrawingAreaErrorKind<DB::ErrorType>| anyhow::anyhow!("drawing: {e}");
    root.fill(&BACKGROUND).map_err(fail)?;
    for (x, half, speed) in &view.points {
        let r = ((half * scale).round() as i32).max(1);
        let (px, py) = at(*x);
        root.draw(&Rectangle::new(
            [(px - r, py - r), (px + r - 1, py + r - 1)],
            paint(CONTINUUM, *speed).filled(),
        ))
        .map_err(fail)?;
    }
    for (x, radius, speed) in &view.grains {
        let r = ((radius * scale).round() as i32).max(1);
        root.draw(&Circle::new(at(*x), r, paint(SAND, *speed).filled())).map_err(fail)?;
    }
    root.present().map_err(fail)?;
    Ok(())
}

/// Dark blue → teal → yellow, for t in [0, 1].
fn ramp(t: f64) -> RGBColor {
    let t = t.clamp(0.0, 1.0);
    let stops = [(30.0, 30.0, 110.0), (30.0, 150.0, 140.0), (250.0, 220.0, 40.0)];
    let (i, f) = if t < 0.5 { (0, 2.0 * t) } else { (1, 2.0 * t - 1.0) };
    let mix = |a: f64, b: f64| (a + f * (b - a)).round() as u8;
    RGBColor(
        mix(stops[i].0, stops[i + 1].0),
        mix(stops[i].1, stops[i + 1].1),
        mix(stops[i].2, stops[i + 1].2),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two grains of known radii: two disks of the right pixel radius at the right places,
    /// nothing else painted. At 1000 px across a 0.1 m view, 1 px = 0.1 mm: a grain of 2 mm
    /// at (0.025, 0.05) is a disk of radius 20 px centred on pixel (250, 250), one of 1 mm at
    /// (0.07, 0.02) a disk of 10 px at (700, 550).
    #[test]
    fn two_grains_draw_two_disks_of_their_radius_where_they_are() {
        let view = Scene2 {
            min: [0.0, 0.0],
            max: [0.1, 0.075],
            grains: vec![([0.025, 0.05], 0.002, 0.0), ([0.07, 0.02], 0.001, 0.0)],
            points: Vec::new(),
        };
        let (w, h) = size(&view, 1000);
        assert_eq!((w, h), (1000, 750));
        let mut px = vec![0u8; (w * h * 3) as usize];
        draw(
            &view,
            Colour::Model,
            &BitMapBackend::with_buffer(&mut px, (w, h)).into_drawing_area(),
        )
        .unwrap();
        let painted = |x: u32, y: u32| {
            let k = 3 * (y * w + x) as usize;
            (px[k], px[k + 1], px[k + 2]) != (BACKGROUND.0, BACKGROUND.1, BACKGROUND.2)
        };
        for (cx, cy, r) in [(250u32, 250u32, 20u32), (700, 550, 10)] {
            // Painted inside, not beyond the radius (±1 px of rasterization), along both axes.
            for d in 0..r - 1 {
                assert!(
                    painted(cx + d, cy) && painted(cx - d, cy) && painted(cx, cy + d) && painted(cx, cy - d),
                    "({cx}, {cy}) d = {d}"
                );
            }
            for d in [r + 2, r + 5] {
                assert!(
                    !painted(cx + d, cy) && !painted(cx - d, cy) && !painted(cx, cy + d) && !painted(cx, cy - d),
                    "({cx}, {cy}) d = {d}"
                );
            }
            // Its area says the same: the radius of a disk of that many pixels is r within a
            // pixel (the rim's rasterization).
            let n = (cy - r - 3..cy + r + 3)
                .flat_map(|y| (cx - r - 3..cx + r + 3).map(move |x| (x, y)))
                .filter(|&(x, y)| painted(x, y))
                .count() as f64;
            let radius = (n / std::f64::consts::PI).sqrt();
            assert!(
                (radius - r as f64).abs() <= 1.0,
                "disk at ({cx}, {cy}): {n} px, the area of a disk of radius {radius:.2} px, not {r}"
            );
        }
        // Nothing else is painted: all the pixels are the two disks' (each within a pixel of its radius).
        let total = (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .filter(|&(x, y)| painted(x, y))
            .count() as f64;
        let (lo, hi) = (
            std::f64::consts::PI * (19.0f64.powi(2) + 9.0f64.powi(2)),
            std::f64::consts::PI * (21.0f64.powi(2) + 11.0f64.powi(2)),
        );
        assert!((lo..=hi).contains(&total), "{total} px painted, two disks are {lo:.0} to {hi:.0}");
    }
}
