//! The rigid bodies' broad phase: which disks (grains, or material points as disks of their
//! contact radius) lie within reach of which circles (a body's bounding circle). With many
//! circles the disks are binned once on a uniform grid and each circle looks only at the bins
//! it covers, so the cost grows with the disks plus the bins the circles cover, not with their
//! product; with a few, checking every pair is cheaper (binning 14,000 disks costs about as
//! much as checking them against 25 circles).

use glam::DVec2;

/// Up to this many circles every pair is checked.
const PAIRWISE: usize = 24;

/// For each circle (centre, radius), the indices of the `n` disks (`disk(k)`: centre, radius)
/// that meet it, |x − c| ≤ R + r, in increasing order.
pub fn within_reach(n: usize, disk: impl Fn(usize) -> (DVec2, f64), circles: &[(DVec2, f64)]) -> Vec<Vec<usize>> {
    let mut out = vec![Vec::new(); circles.len()];
    if n == 0 || circles.is_empty() {
        return out;
    }
    if circles.len() <= PAIRWISE {
        for k in 0..n {
            let (x, r) = disk(k);
            for (found, &(c, radius)) in out.iter_mut().zip(circles) {
                if (x - c).length_squared() <= (radius + r) * (radius + r) {
                    found.push(k);
                }
            }
        }
        return out;
    }
    binned(n, disk, circles, out)
}

fn binned(n: usize, disk: impl Fn(usize) -> (DVec2, f64), circles: &[(DVec2, f64)], mut out: Vec<Vec<usize>>) -> Vec<Vec<usize>> {
    let (mut lo, mut hi) = (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY));
    let mut r_max: f64 = 0.0;
    for (x, r) in (0..n).map(&disk) {
        lo = lo.min(x);
        hi = hi.max(x);
        r_max = r_max.max(r);
    }
    // Bins about as wide as the smallest circle (a body meets the disks of a few bins), never
    // narrower than a disk, and no more of them than about four per disk.
    let r_min = circles.iter().map(|c| c.1).fold(f64::INFINITY, f64::min);
    let span = (hi - lo).max(DVec2::splat(f64::MIN_POSITIVE));
    let mut bin = (2.0 * r_max).max(r_min).max(f64::MIN_POSITIVE);
    let cap = 4.0 * n as f64 + 16.0;
    while ((span.x / bin).floor() + 1.0) * ((span.y / bin).floor() + 1.0) > cap {
        bin *= 2.0;
    }
    let dims = [(span.x / bin) as usize + 1, (span.y / bin) as usize + 1];
    let cell = |x: f64, lo: f64, n: usize| (((x - lo) / bin).floor().max(0.0) as usize).min(n - 1);
    let bin_of = |x: DVec2| cell(x.y, lo.y, dims[1]) * dims[0] + cell(x.x, lo.x, dims[0]);
    // Counting sort of the disks by bin: bin b holds order[start[b]..start[b + 1]].
    let mut start = vec![0usize; dims[0] * dims[1] + 1];
    for (x, _) in (0..n).map(&disk) {
        start[bin_of(x) + 1] += 1;
    }
    for b in 0..dims[0] * dims[1] {
        start[b + 1] += start[b];
    }
    let mut fill = start.clone();
    let mut order = vec![0usize; n];
    for k in 0..n {
        let b = bin_of(disk(k).0);
        order[fill[b]] = k;
        fill[b] += 1;
    }
    for (found, &(c, radius)) in out.iter_mut().zip(circles) {
        let reach = radius + r_max;
        if c.x + reach < lo.x || c.y + reach < lo.y || c.x - reach > hi.x || c.y - reach > hi.y {
            continue;
        }
        let (x0, x1) = (cell(c.x - reach, lo.x, dims[0]), cell(c.x + reach, lo.x, dims[0]));
        let (y0, y1) = (cell(c.y - reach, lo.y, dims[1]), cell(c.y + reach, lo.y, dims[1]));
        for by in y0..=y1 {
            let row = by * dims[0];
            for &k in &order[start[row + x0]..start[row + x1 + 1]] {
                let (x, r) = disk(k);
                if (x - c).length_squared() <= (radius + r) * (radius + r) {
                    found.push(k);
                }
            }
        }
        found.sort_unstable();
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    fn brute(disks: &[(DVec2, f64)], circles: &[(DVec2, f64)]) -> Vec<Vec<usize>> {
        circles
            .iter()
            .map(|&(c, radius)| {
                (0..disks.len())
                    .filter(|&k| (disks[k].0 - c).length() <= radius + disks[k].1)
                    .collect()
            })
            .collect()
    }

    /// Against every pair checked: random disks of two sizes, circles from a grain's size to
    /// wider than the cloud, inside it, on its edge and outside it (40 of them: binned).
    #[test]
    fn finds_what_checking_every_pair_finds() {
        let mut rng = Rng::new(7);
        let mut u = |a: f64, b: f64| a + (b - a) * rng.uniform();
        for n in [1usize, 2, 50, 3000] {
            let disks: Vec<(DVec2, f64)> = (0..n)
                .map(|_| (DVec2::new(u(-1.0, 3.0), u(0.0, 0.5)), if u(0.0, 1.0) < 0.5 { 0.001 } else { 0.004 }))
                .collect();
            let circles: Vec<(DVec2, f64)> = (0..40)
                .map(|k| (DVec2::new(u(-1.5, 3.5), u(-0.5, 1.0)), [0.002, 0.02, 0.2, 5.0][k % 4]))
                .collect();
            let found = within_reach(n, |k| disks[k], &circles);
            assert_eq!(found, brute(&disks, &circles), "n = {n}");
            // A few circles: checked pairwise.
            assert_eq!(
                within_reach(n, |k| disks[k], &circles[..3]),
                brute(&disks, &circles[..3]),
                "n = {n}"
            );
            if n == 3000 {
                let met: usize = found.iter().map(Vec::len).sum();
                assert!(met > 3000, "the test must find pairs: {met}");
            }
        }
    }

    /// Disks all at one spot (a zero span) and a circle exactly at reach.
    #[test]
    fn degenerate_clouds_and_touching_circles() {
        let disks = [(DVec2::new(1.0, 1.0), 0.5); 3];
        let mut circles = vec![
            (DVec2::new(2.0, 1.0), 0.5),
            (DVec2::new(2.0, 1.0), 0.49),
            (DVec2::new(1.0, 1.0), 0.0),
        ];
        let expected = vec![vec![0, 1, 2], vec![], vec![0, 1, 2]];
        assert_eq!(within_reach(3, |k| disks[k], &circles), expected);
        // The same binned: past the pairwise limit, far circles that meet nothing.
        circles.extend((0..PAIRWISE).map(|k| (DVec2::new(10.0 + k as f64, 0.0), 0.1)));
        assert_eq!(within_reach(3, |k| disks[k], &circles)[..3], expected[..]);
        assert_eq!(within_reach(0, |k| disks[k], &circles[..3]), vec![Vec::<usize>::new(); 3]);
    }
}
