//! `grains render`: a picture of a run's frame as PNG, for people who watch flows rather than
//! read them. Grains are drawn as disks of their own radius (2D, or the x–y projection of 3D
//! spheres), material points as dots of half their cell's point spacing; colour by model
//! (points blue, grains sand), by speed or by the incremental strain since the frame before
//! (where shear bands form). The view is the scene's domain, x to the right and
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
    #[arg(long, conflicts_with = "every")]
    pub step: Option<u64>,
    /// Every K-th frame written, to `<run>/render/frame_<step>.png`, and with `ffmpeg` on the
    /// PATH the film `<run>/render/render.mp4`.
    #[arg(long, value_name = "K", value_parser = clap::value_parser!(u64).range(1..))]
    pub every: Option<u64>,
    /// Frames per second of the film.
    #[arg(long, default_value_t = 10)]
    pub fps: u32,
    /// The PNG to write (default `<run>/frames/render_<step>.png`; not with `--every`).
    #[arg(long, conflicts_with = "every")]
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
    /// Which model: material points blue, grains sand (where the oracle put the continuum).
    Model,
    /// Speed |v|, from dark blue (at rest) to yellow (the fastest material of the frame, or of
    /// all the frames drawn with `--every`).
    Speed,
    /// Incremental strain since the frame written before (with `--every`, since the frame
    /// drawn before): Cundall's best-fit deviatoric strain of each grain or point with its
    /// neighbours (Chen 2021 App. A), from dark blue (none) to yellow (the 98th percentile of
    /// the picture's strains, or of all the pictures' with `--every`, and above). Shear bands
    /// show; the first frame has none. In 2D (a 3D run's is its x–y projection's).
    Strain,
}

/// The 98th percentile of the strains of `pictures` (made by [`strain_frame`]): yellow on the
/// strain colour scale.
const STRAIN_TOP: f64 = 0.98;

/// What a picture shows: the view's box [m] and the material in it.
pub struct Scene2 {
    pub min: [f64; 2],
    pub max: [f64; 2],
    /// Grains: centre [m], radius [m], speed [m/s] (in a [`strain_frame`], the strain).
    pub grains: Vec<([f64; 2], f64, f64)>,
    /// Points: centre [m], half their spacing [m], speed [m/s].
    pub points: Vec<([f64; 2], f64, f64)>,
    /// Rigid bodies: outline [m], speed of the centre of mass [m/s].
    pub bodies: Vec<(Vec<[f64; 2]>, f64)>,
}

impl Scene2 {
    /// The fastest material's speed [m/s].
    pub fn fastest(&self) -> f64 {
        let bodies = self.bodies.iter().map(|b| b.1);
        self.grains
            .iter()
            .chain(&self.points)
            .map(|m| m.2)
            .chain(bodies)
            .fold(0.0, f64::max)
    }
}

const BACKGROUND: RGBColor = RGBColor(255, 255, 255);
const SAND: RGBColor = RGBColor(194, 138, 64);
const CONTINUUM: RGBColor = RGBColor(70, 130, 200);
/// Rigid bodies: grey stone, outlined.
const BODY: RGBColor = RGBColor(140, 140, 140);

/// `grains render`: reads the frames and writes the pictures (and the film); returns what it
/// wrote.
pub fn render(args: &RenderArgs) -> anyhow::Result<Vec<PathBuf>> {
    let view = match args.view.as_deref() {
        Some(&[x0, y0, x1, y1]) if x1 > x0 && y1 > y0 => Some(([x0, y0], [x1, y1])),
        Some(v) => bail!("--view {v:?}: give xmin,ymin,xmax,ymax with xmax > xmin and ymax > ymin"),
        None => None,
    };
    let Some(every) = args.every else {
        let step = match args.step {
            Some(s) => s,
            None => *frame_steps(&args.run)?.last().expect("frame_steps is never empty"),
        };
        let out = args
            .out
            .clone()
            .unwrap_or_else(|| args.run.join("frames").join(format!("render_{step:08}.png")));
        let (picture, top) = if args.colour == Colour::Strain {
            let before = frame_steps(&args.run)?.into_iter().take_while(|&s| s < step).last().unwrap_or(step);
            let picture = strain_frame(&args.run, before, step, view)?;
            let top = strain_top(std::slice::from_ref(&picture));
            (picture, top)
        } else {
            let picture = frame(&args.run, step, view)?;
            let fastest = picture.fastest();
            (picture, fastest)
        };
        write_png(&picture, args.colour, top, args.width, &out)?;
        return Ok(vec![out]);
    };
    let steps: Vec<u64> = frame_steps(&args.run)?.into_iter().step_by(every as usize).collect();
    // Each picture's strain since the one drawn before it.
    let picture = |k: usize| match args.colour {
        Colour::Strain => strain_frame(&args.run, steps[k.saturating_sub(1)], steps[k], view),
        _ => frame(&args.run, steps[k], view),
    };
    // One scale for the whole film: a colour means the same speed (strain) in every picture.
    let top = match args.colour {
        Colour::Speed => (0..steps.len())
            .map(|k| picture(k).map(|f| f.fastest()))
            .try_fold(0.0, |m, f| f.map(|f| f64::max(m, f)))?,
        Colour::Strain => (0..steps.len())
            .map(|k| picture(k).map(|f| strain_top(std::slice::from_ref(&f))))
            .try_fold(0.0, |m, f| f.map(|f| f64::max(m, f)))?,
        Colour::Model => 0.0,
    };
    let dir = args.run.join("render");
    // Pictures of an earlier render would join the film.
    if dir.exists() {
        std::fs::remove_dir_all(&dir).with_context(|| format!("removing the earlier {}", dir.display()))?;
    }
    let mut written = Vec::new();
    for (k, &step) in steps.iter().enumerate() {
        let out = dir.join(format!("frame_{step:08}.png"));
        write_png(&picture(k)?, args.colour, top, args.width, &out)?;
        tracing::info!("render: {}/{} pictures", k + 1, steps.len());
        written.push(out);
    }
    match film(&dir, args.fps)? {
        Some(mp4) => written.push(mp4),
        None => tracing::info!("render: no ffmpeg on the PATH: pictures only (install ffmpeg for the film)"),
    }
    Ok(written)
}

/// The film of the pictures `frame_*.png` in `dir`, in their order, by `ffmpeg` (H.264,
/// padded to even sizes as the codec needs); `None` without ffmpeg.
fn film(dir: &Path, fps: u32) -> anyhow::Result<Option<PathBuf>> {
    let out = dir.join("render.mp4");
    let status = std::process::Command::new("ffmpeg")
        .args([
            "-loglevel",
            "error",
            "-y",
            "-framerate",
            &fps.to_string(),
            "-pattern_type",
            "glob",
            "-i",
        ])
        .arg(dir.join("frame_*.png"))
        .args([
            "-vf",
            "pad=ceil(iw/2)*2:ceil(ih/2)*2:color=white",
            "-c:v",
            "libx264",
            "-pix_fmt",
            "yuv420p",
        ])
        .arg(&out)
        .status();
    match status {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
        Err(e) => Err(e).context("starting ffmpeg"),
        Ok(s) if s.success() => Ok(Some(out)),
        Ok(s) => bail!(
            "ffmpeg failed ({s}) making {} from the pictures in {}",
            out.display(),
            dir.display()
        ),
    }
}

/// The picture of step `step` of a run: its grains and points, in `view` (default the
/// scene's domain).
pub fn frame(run: &Path, step: u64, view: Option<([f64; 2], [f64; 2])>) -> anyhow::Result<Scene2> {
    let scene = grains_protocol::scene::load(&run.join("scene.toml"))
        .with_context(|| format!("{}: not a run directory (it needs the run's scene.toml)", run.display()))?;
    let frames = run.join("frames");
    let read = |name: &str| -> anyhow::Result<Option<Frame>> {
        let file = frames.join(format!("{name}_{step:08}.vtu"));
        if file.exists() { Frame::read(&file).map(Some) } else { Ok(None) }
    };
    let (grains, points, bodies) = (read("grains")?, read("points")?, read("bodies")?);
    if grains.is_none() && points.is_none() {
        bail!(
            "{}: no frame of step {step} (frames are written every output.frames_every steps)",
            frames.display()
        );
    }
    let point_half = 0.5 * scene.domain.cell_size / scene.mpm.points_per_axis as f64;
    let d = &scene.domain;
    let (min, max) = view.unwrap_or(([d.min[0], d.min[1]], [d.max[0], d.max[1]]));
    Ok(Scene2 {
        min,
        max,
        grains: grains.map_or(Ok(Vec::new()), |f| material(&f, None))?,
        points: points.map_or(Ok(Vec::new()), |f| material(&f, Some(point_half)))?,
        bodies: bodies.map_or(Ok(Vec::new()), |f| outlines(&f))?,
    })
}

/// Cundall's best-fit deviatoric strain of each item of frame `after` since frame `before`
/// (items matched by their `id`, each fitted with its neighbours within `reach` in `before`;
/// `grains_oracle::band`), in `after`'s order; 0 for an item `before` does not have.
pub fn strain_between(before: &Frame, after: &Frame, reach: f64) -> anyhow::Result<Vec<f64>> {
    use grains_oracle::band::{best_fit_strain, neighbours};
    let ids = |f: &Frame| -> anyhow::Result<Vec<u64>> {
        Ok(f.array("id")
            .context("a frame without an id array")?
            .iter()
            .map(|&i| i as u64)
            .collect())
    };
    let then: std::collections::HashMap<u64, [f64; 3]> = ids(before)?.into_iter().zip(before.points.iter().copied()).collect();
    let (mut x0, mut x1, mut at) = (Vec::new(), Vec::new(), Vec::new());
    for (k, (id, x)) in ids(after)?.into_iter().zip(&after.points).enumerate() {
        if let Some(p) = then.get(&id) {
            x0.push([p[0], p[1]]);
            x1.push([x[0], x[1]]);
            at.push(k);
        }
    }
    let mut out = vec![0.0; after.points.len()];
    for (e, k) in best_fit_strain(&x0, &x1, &neighbours(&x0, reach)).into_iter().zip(at) {
        out[k] = e;
    }
    Ok(out)
}

/// The picture of step `step` of a run (as [`frame`]) with each grain's and point's strain
/// since step `since` in place of its speed ([`strain_between`]: grains with their neighbours
/// within 1.5 mean diameters, points within 1.5 spacings); the bodies carry none.
pub fn strain_frame(run: &Path, since: u64, step: u64, view: Option<([f64; 2], [f64; 2])>) -> anyhow::Result<Scene2> {
    let mut picture = frame(run, step, view)?;
    let read = |name: &str, s: u64| Frame::read(&run.join("frames").join(format!("{name}_{s:08}.vtu")));
    if !picture.grains.is_empty() {
        let d = 2.0 * picture.grains.iter().map(|g| g.1).sum::<f64>() / picture.grains.len() as f64;
        let e = strain_between(&read("grains", since)?, &read("grains", step)?, 1.5 * d)?;
        picture.grains.iter_mut().zip(e).for_each(|(g, e)| g.2 = e);
    }
    if let Some(&(_, half, _)) = picture.points.first() {
        let e = strain_between(&read("points", since)?, &read("points", step)?, 3.0 * half)?;
        picture.points.iter_mut().zip(e).for_each(|(p, e)| p.2 = e);
    }
    picture.bodies.iter_mut().for_each(|b| b.1 = 0.0);
    Ok(picture)
}

/// The top of the strain colour scale of `pictures` ([`strain_frame`]s): the
/// [`STRAIN_TOP`] quantile of all their strains.
pub fn strain_top(pictures: &[Scene2]) -> f64 {
    let all: Vec<f64> = pictures
        .iter()
        .flat_map(|p| p.grains.iter().chain(&p.points).map(|m| m.2))
        .collect();
    grains_oracle::band::percentile(&all, STRAIN_TOP)
}

/// Draws `view` into the PNG `out`, `width` pixels across; speeds are coloured against
/// `fastest`.
pub fn write_png(view: &Scene2, colour: Colour, fastest: f64, width: u32, out: &Path) -> anyhow::Result<()> {
    if let Some(dir) = out.parent() {
        std::fs::create_dir_all(dir)?;
    }
    let root = BitMapBackend::new(out, size(view, width)).into_drawing_area();
    draw(view, colour, fastest, &root).with_context(|| format!("writing {}", out.display()))
}

/// Height of the label strip over each panel [pixels].
const LABEL: u32 = 26;

/// A grid of labelled pictures (`rows` of panels, each `width` pixels across, all of the
/// first panel's aspect) in the PNG `out`, for side-by-side comparisons (`grains validate`).
/// Speeds are coloured against the fastest material of all the panels.
pub fn panels(rows: &[Vec<(String, Scene2)>], colour: Colour, width: u32, out: &Path) -> anyhow::Result<()> {
    let fastest = rows.iter().flatten().map(|(_, v)| v.fastest()).fold(0.0, f64::max);
    panels_scaled(rows, colour, fastest, width, out)
}

/// [`panels`] with the top of the colour scale given (`top`: the speed or strain drawn yellow).
pub fn panels_scaled(rows: &[Vec<(String, Scene2)>], colour: Colour, top: f64, width: u32, out: &Path) -> anyhow::Result<()> {
    if let Some(dir) = out.parent() {
        std::fs::create_dir_all(dir)?;
    }
    let root = BitMapBackend::new(out, panels_size(rows, width)?).into_drawing_area();
    draw_panels(rows, colour, top, width, &root).with_context(|| format!("writing {}", out.display()))
}

/// The size of [`panels`]' picture.
pub fn panels_size(rows: &[Vec<(String, Scene2)>], width: u32) -> anyhow::Result<(u32, u32)> {
    let first = &rows.first().and_then(|r| r.first()).context("no panel to draw")?.1;
    let cols = rows.iter().map(Vec::len).max().unwrap_or(1) as u32;
    let (w, h) = size(first, width);
    Ok((cols * w, rows.len() as u32 * (h + LABEL)))
}

/// Draws [`panels`]' grid on `root`, speeds (strains) coloured against `top`.
pub fn draw_panels<DB: DrawingBackend>(
    rows: &[Vec<(String, Scene2)>],
    colour: Colour,
    top: f64,
    width: u32,
    root: &DrawingArea<DB, plotters::coord::Shift>,
) -> anyhow::Result<()> {
    let first = &rows.first().and_then(|r| r.first()).context("no panel to draw")?.1;
    let (w, h) = size(first, width);
    crate::report::chart::font()?;
    let fail = |e: DrawingAreaErrorKind<DB::ErrorType>| anyhow::anyhow!("drawing: {e}");
    root.fill(&BACKGROUND).map_err(fail)?;
    for (r, row) in rows.iter().enumerate() {
        for (c, (label, view)) in row.iter().enumerate() {
            let (x, y) = (c as u32 * w, r as u32 * (h + LABEL));
            let cell = root.clone().shrink((x, y), (w, h + LABEL));
            cell.draw_text(label, &("sans-serif", 18).into_font().color(&BLACK), (6, 4))
                .map_err(fail)?;
            draw(view, colour, top, &cell.clone().shrink((0, LABEL), (w, h)))?;
        }
    }
    root.present().map_err(fail)?;
    Ok(())
}

/// The macro-steps of a run's frames (grains or points), in order; an error if there is none.
pub fn frame_steps(run: &Path) -> anyhow::Result<Vec<u64>> {
    Ok(frame_times(run)?.into_iter().map(|(_, s)| s).collect())
}

/// The (time [s], macro-step) of a run's frames (grains or points), in order of step; an
/// error if there is none.
pub fn frame_times(run: &Path) -> anyhow::Result<Vec<(f64, u64)>> {
    let mut steps = std::collections::BTreeMap::new();
    for name in ["grains", "points"] {
        let pvd = run.join("frames").join(format!("{name}.pvd"));
        if !pvd.exists() {
            continue;
        }
        for (time, file) in collection(&pvd)? {
            let stem = file.file_stem().and_then(|s| s.to_str()).unwrap_or("");
            let step: u64 = stem
                .rsplit('_')
                .next()
                .and_then(|s| s.parse().ok())
                .with_context(|| format!("{}: a frame file without its step", file.display()))?;
            steps.insert(step, time);
        }
    }
    if steps.is_empty() {
        bail!("{}: the run wrote no frames", run.display());
    }
    Ok(steps.into_iter().map(|(s, t)| (t, s)).collect())
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

/// The rigid bodies of a frame of polygons: each cell's outline and its speed.
fn outlines(f: &Frame) -> anyhow::Result<Vec<(Vec<[f64; 2]>, f64)>> {
    let v = f.array("velocity").context("a frame of bodies without a velocity array")?;
    let mut start = 0;
    let mut out = Vec::new();
    for (k, &end) in f.cell_ends.iter().enumerate() {
        let outline = f.points.get(start..end).context("a cell beyond the frame's points")?;
        out.push((outline.iter().map(|p| [p[0], p[1]]).collect(), v[3 * k].hypot(v[3 * k + 1])));
        start = end;
    }
    Ok(out)
}

/// Picture size for `width` pixels across the view.
pub fn size(view: &Scene2, width: u32) -> (u32, u32) {
    let aspect = (view.max[1] - view.min[1]) / (view.max[0] - view.min[0]);
    (width.max(16), ((width as f64 * aspect).round() as u32).max(16))
}

/// Draws the view on `root` (a picture of [`size`] pixels); speeds are coloured against
/// `fastest`.
pub fn draw<DB: DrawingBackend>(
    view: &Scene2,
    colour: Colour,
    fastest: f64,
    root: &DrawingArea<DB, plotters::coord::Shift>,
) -> anyhow::Result<()> {
    let (w, _) = root.dim_in_pixel();
    let scale = w as f64 / (view.max[0] - view.min[0]);
    let at = |x: [f64; 2]| {
        (
            (((x[0] - view.min[0]) * scale).round() as i32),
            (((view.max[1] - x[1]) * scale).round() as i32),
        )
    };
    let paint = |base: RGBColor, speed: f64| match colour {
        Colour::Model => base,
        Colour::Speed | Colour::Strain => ramp(if fastest > 0.0 { (speed / fastest).min(1.0) } else { 0.0 }),
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
    for (outline, speed) in &view.bodies {
        let corners: Vec<(i32, i32)> = outline.iter().map(|&p| at(p)).collect();
        root.draw(&Polygon::new(corners.clone(), paint(BODY, *speed).filled()))
            .map_err(fail)?;
        let mut edge = corners;
        edge.push(edge[0]);
        root.draw(&PathElement::new(edge, BLACK.stroke_width(1))).map_err(fail)?;
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

    /// Two panels side by side, one grain each: each disk is drawn in its own panel, under its
    /// label strip, at its place in that panel's view, and not in the other panel.
    #[test]
    fn panels_put_each_view_in_its_own_cell() {
        let view = |x: [f64; 2]| Scene2 {
            min: [0.0, 0.0],
            max: [0.1, 0.075],
            grains: vec![(x, 0.002, 0.0)],
            points: Vec::new(),
            bodies: Vec::new(),
        };
        let rows = vec![vec![("a".to_string(), view([0.025, 0.05])), ("b".to_string(), view([0.07, 0.02]))]];
        let (w, h) = panels_size(&rows, 1000).unwrap();
        assert_eq!((w, h), (2000, 750 + LABEL));
        let mut px = vec![0u8; (w * h * 3) as usize];
        draw_panels(
            &rows,
            Colour::Model,
            0.0,
            1000,
            &BitMapBackend::with_buffer(&mut px, (w, h)).into_drawing_area(),
        )
        .unwrap();
        let sand = |x: u32, y: u32| {
            let k = 3 * (y * w + x) as usize;
            (px[k], px[k + 1], px[k + 2]) == (SAND.0, SAND.1, SAND.2)
        };
        // At 1000 px across 0.1 m: (0.025, 0.05) is pixel (250, 250) of panel a, (0.07, 0.02)
        // pixel (700, 550) of panel b, which starts 1000 px to the right.
        assert!(sand(250, LABEL + 250) && sand(1700, LABEL + 550));
        assert!(!sand(700, LABEL + 550) && !sand(1250, LABEL + 250));
        // The label strips hold no material.
        assert!((0..w).all(|x| (0..LABEL).all(|y| !sand(x, y))));
    }

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
            bodies: Vec::new(),
        };
        let (w, h) = size(&view, 1000);
        assert_eq!((w, h), (1000, 750));
        let mut px = vec![0u8; (w * h * 3) as usize];
        draw(
            &view,
            Colour::Model,
            0.0,
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

    /// A square lattice sheared uniformly by γ (x += γ y) has e_d = γ / √2 at every point (a
    /// homogeneous deformation is fitted exactly), the points matched by id whatever their
    /// order; a point the earlier frame lacks has none.
    #[test]
    fn a_uniform_shear_gives_its_deviatoric_strain_to_every_point() {
        use grains_service::vtu::Frame;
        let gamma = 0.02;
        let sites: Vec<[f64; 3]> = (0..100).map(|k| [(k % 10) as f64 * 1e-3, (k / 10) as f64 * 1e-3, 0.0]).collect();
        let before = Frame {
            points: sites.clone(),
            arrays: vec![("id".into(), 1, (0..100).map(|k| k as f64).collect())],
            cell_ends: Vec::new(),
        };
        // The later frame lists the points backwards and has one more (id 100).
        let mut points: Vec<[f64; 3]> = sites.iter().rev().map(|x| [x[0] + gamma * x[1], x[1], 0.0]).collect();
        points.push([0.02, 0.02, 0.0]);
        let mut ids: Vec<f64> = (0..100).rev().map(|k| k as f64).collect();
        ids.push(100.0);
        let after = Frame {
            points,
            arrays: vec![("id".into(), 1, ids)],
            cell_ends: Vec::new(),
        };
        let e = super::strain_between(&before, &after, 1.5e-3).unwrap();
        assert_eq!(e.len(), 101);
        assert_eq!(e[100], 0.0, "a point without a past has no strain");
        for (k, e) in e[..100].iter().enumerate() {
            assert!((e - gamma / 2f64.sqrt()).abs() < 1e-9, "point {k}: {e}");
        }
    }

    /// A rigid body's outline, a 20 mm square from (0.04, 0.02) at 1000 px across 0.1 m, is
    /// painted grey over its 200 × 200 px, not outside it.
    #[test]
    fn a_rigid_body_draws_as_its_outline() {
        let view = Scene2 {
            min: [0.0, 0.0],
            max: [0.1, 0.075],
            grains: Vec::new(),
            points: Vec::new(),
            bodies: vec![(vec![[0.04, 0.02], [0.06, 0.02], [0.06, 0.04], [0.04, 0.04]], 0.0)],
        };
        let (w, h) = size(&view, 1000);
        let mut px = vec![0u8; (w * h * 3) as usize];
        draw(
            &view,
            Colour::Model,
            0.0,
            &BitMapBackend::with_buffer(&mut px, (w, h)).into_drawing_area(),
        )
        .unwrap();
        let colour = |x: u32, y: u32| {
            let k = 3 * (y * w + x) as usize;
            (px[k], px[k + 1], px[k + 2])
        };
        // Rows 350..550 from the top (y from 0.04 down to 0.02), columns 400..600.
        assert_eq!(colour(500, 450), (BODY.0, BODY.1, BODY.2));
        assert_eq!(colour(405, 355), (BODY.0, BODY.1, BODY.2));
        for (x, y) in [(390, 450), (610, 450), (500, 340), (500, 560)] {
            assert_eq!(colour(x, y), (BACKGROUND.0, BACKGROUND.1, BACKGROUND.2), "({x}, {y})");
        }
    }
}
