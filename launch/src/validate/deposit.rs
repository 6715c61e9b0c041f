//! What a run left on disk, read back: its frames (through the VTU reader of
//! `grains_service::vtu`), and the deposit of a column collapse as a height profile and a
//! front.

use super::scenes::column::D;
use anyhow::Context;
use grains_service::vtu::{Frame, collection};
use std::path::{Path, PathBuf};

/// Profile bins [m] and the thinnest deposit that counts for the front [m]. One grain wide:
/// 2-mm bins moved the front of both runs in 2-mm steps, 7% of the runout at a = 0.5.
pub const BIN: f64 = 0.001;
pub const FRONT_HEIGHT: f64 = 0.0035;
/// Grains of the glued floor row have their centres below this [m].
const FLOOR_ROW: f64 = 0.0012;

/// Every frame listed in `frames/<name>.pvd` of a run: (time, file), in order; none without one.
pub fn frames_of(run_dir: &Path, name: &str) -> anyhow::Result<Vec<(f64, PathBuf)>> {
    let pvd = run_dir.join("frames").join(format!("{name}.pvd"));
    if !pvd.exists() {
        return Ok(Vec::new());
    }
    collection(&pvd)
}

/// The last frame listed in `frames/<name>.pvd` of a run, if any.
pub fn last_frame(run_dir: &Path, name: &str) -> anyhow::Result<Option<PathBuf>> {
    Ok(frames_of(run_dir, name)?.pop().map(|(_, f)| f))
}

/// The grains of a frame: (centre, radius).
pub fn grains_of(frame: &Frame, file: &Path) -> anyhow::Result<Vec<([f64; 3], f64)>> {
    let r = frame
        .array("radius")
        .with_context(|| format!("{}: no radius array", file.display()))?;
    Ok(frame.points.iter().copied().zip(r.iter().copied()).collect())
}

/// The final deposit of a run: grains (centre, radius) and material points (centre).
#[derive(Debug, Default)]
pub struct Deposit {
    pub grains: Vec<([f64; 3], f64)>,
    pub points: Vec<[f64; 3]>,
    /// Half the spacing of the material points [m].
    pub point_half: f64,
}

/// The deposit at the end of a run from its last frames.
pub fn deposit(run_dir: &Path, point_half: f64) -> anyhow::Result<Deposit> {
    let mut dep = Deposit {
        point_half,
        ..Deposit::default()
    };
    if let Some(f) = last_frame(run_dir, "grains")? {
        dep.grains = grains_of(&Frame::read(&f)?, &f)?;
    }
    if let Some(f) = last_frame(run_dir, "points")? {
        dep.points = Frame::read(&f)?.points;
    }
    Ok(dep)
}

/// Heights of the deposit on `n` bins of width `bin` from x = 0 (0 where a bin is empty): the
/// highest top of the material in the bin (grains: centre + radius; points: centre + half
/// their spacing), leaving out the glued floor row.
pub fn profile(dep: &Deposit, bin: f64, n: usize) -> Vec<f64> {
    let mut h = vec![0.0f64; n];
    let mut put = |x: f64, top: f64| {
        if x >= 0.0 {
            let i = (x / bin) as usize;
            if i < n {
                h[i] = h[i].max(top);
            }
        }
    };
    for &(x, r) in &dep.grains {
        if x[1] >= FLOOR_ROW {
            put(x[0], x[1] + r);
        }
    }
    for x in &dep.points {
        put(x[0], x[1] + dep.point_half);
    }
    h
}

/// The front: the left edge of the first bin, from the wall, where the mean height of the bin
/// and its two neighbours is below `min`. On one-grain bins a bin whose surface grains sit in
/// the next bins reads a grain lower; the mean keeps such a dip from ending the deposit.
pub fn front(profile: &[f64], bin: f64, min: f64) -> f64 {
    let n = profile.len();
    let mean = |i: usize| {
        let (lo, hi) = (i.saturating_sub(1), (i + 2).min(n));
        profile[lo..hi].iter().sum::<f64>() / (hi - lo) as f64
    };
    (0..n).position(|i| mean(i) < min).unwrap_or(n) as f64 * bin
}

/// Mean |h₁ − h₂| over the bins up to `upto` [m], in grain diameters.
pub fn profile_l1(h1: &[f64], h2: &[f64], upto: f64) -> f64 {
    let n = ((upto / BIN).round() as usize).clamp(1, h1.len().min(h2.len()).max(1));
    h1.iter().zip(h2).take(n).map(|(a, b)| (a - b).abs()).sum::<f64>() / n as f64 / D
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A deposit of known shape: a ramp of grains 10 mm high at the wall down to 0 at 30 mm.
    #[test]
    fn profile_and_front_of_a_known_deposit() {
        let mut dep = Deposit {
            point_half: 0.00025,
            ..Deposit::default()
        };
        // The floor row: never counted.
        for i in 0..100 {
            dep.grains.push(([i as f64 * 0.001, 0.0005, 0.0], 0.0005));
        }
        // A column of grains in every millimetre up to the ramp 0.010 (1 − x / 0.030).
        for i in 0..30 {
            let x = i as f64 * 0.001 + 0.0005;
            let top = 0.010 * (1.0 - x / 0.030);
            let mut y = 0.0018;
            while y + 0.0005 <= top {
                dep.grains.push(([x, y, 0.0], 0.0005));
                y += 0.001;
            }
        }
        let mut h = profile(&dep, BIN, 50);
        // Bin [0, 1) mm: the grain column at x = 0.5 mm reaches 0.0018 + 7 · 0.001 + 0.0005
        // (the next grain would top 10.3 mm, above the ramp's 9.83 mm).
        assert!((h[0] - 0.0093).abs() < 1e-12, "{}", h[0]);
        assert_eq!(h[40], 0.0, "beyond the ramp only the floor row, which does not count");
        // Columns at 15.5-16.5 mm hold three grains (tops 4.3 mm), 17.5-19.5 mm two (3.3 mm):
        // the three-bin mean first falls under 3.5 mm at bin [18, 19) mm (3.3; at 17: 3.63).
        let f = front(&h, BIN, FRONT_HEIGHT);
        assert!((f - 0.018).abs() < 1e-12, "front {f}");
        // One bin reading a grain layer low (10: 6.3 → 2.9 mm, under 3.5) does not end it.
        h[10] = 0.0029;
        let f = front(&h, BIN, FRONT_HEIGHT);
        assert!((f - 0.018).abs() < 1e-12, "front {f} after a one-bin dip");
        // Points count with half their spacing.
        dep.points.push([0.041, 0.005, 0.0]);
        assert!((profile(&dep, BIN, 50)[41] - 0.00525).abs() < 1e-12);
    }

    /// The deposit of a run is its last frame's grains, as the participants' writer wrote them.
    #[test]
    fn the_deposit_is_the_last_frame() {
        use grains_service::vtu::{Field, PointFrames, Values};
        let dir = std::env::temp_dir().join(format!("grains-validate-vtu-{}", std::process::id()));
        let mut frames = PointFrames::new(&dir, "grains").unwrap();
        let x = [[0.001, 0.002, 0.0], [0.25, -0.5, 1e-9]];
        let field = |name, v| Field {
            name,
            components: 1,
            values: Values::F64(v),
        };
        let fields = [field("id_like", &[7.0, 8.0][..]), field("radius", &[5e-4, 6e-4][..])];
        frames
            .write(0, 0.0, &[[9.0; 3]], &[field("id_like", &[1.0][..]), field("radius", &[1.0][..])])
            .unwrap();
        frames.write(40, 0.1, &x, &fields).unwrap();
        let last = last_frame(&dir, "grains").unwrap().unwrap();
        assert!(last.ends_with("grains_00000040.vtu"), "{}", last.display());
        let dep = deposit(&dir, 0.0).unwrap();
        assert_eq!(dep.grains, [(x[0], 5e-4), (x[1], 6e-4)]);
        assert!(dep.points.is_empty());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
