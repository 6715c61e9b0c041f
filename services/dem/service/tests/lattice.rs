//! The lattice a body without a packing file is built on, against its formula.

use grains_dem::D2;
use grains_dem_service::setup;
use grains_protocol::scene;

/// `setup::lattice_packing` is the packing the setup builds: on `dem_small_2d.toml`'s box of
/// 1-mm grains (σ = 0.04 mm) the rows' spacing and the sites' spacing along them, measured
/// from the grains' centres, with the grains' mean area give the formula's packing within 2%
/// (the sample's mean r² over some 300 grains; measured: printed). A spacing or a lattice
/// other than the setup's fails it.
#[test]
fn the_lattice_packs_as_its_formula_says() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../tests/scenes/dem_small_2d.toml");
    let s = scene::load(&path).unwrap();
    let dem = s.materials[0].dem.as_ref().unwrap();
    let state = setup::build_state::<D2>(&s, &grains_service::zones::ZoneField::layered(&s)).unwrap();
    let g = &state.grains;
    // Rows: centres sorted by height, split where the height jumps by a quarter spacing.
    let mut at: Vec<[f64; 2]> = g.x.iter().map(|x| [x.x, x.y]).collect();
    at.sort_by(|a, b| a[1].total_cmp(&b[1]));
    let mut rows: Vec<Vec<f64>> = vec![vec![at[0][0]]];
    let mut heights = vec![at[0][1]];
    for w in at.windows(2) {
        if w[1][1] - w[0][1] > 0.25 * dem.radius {
            rows.push(Vec::new());
            heights.push(w[1][1]);
        }
        rows.last_mut().unwrap().push(w[1][0]);
    }
    let dy = (heights[heights.len() - 1] - heights[0]) / (heights.len() - 1) as f64;
    let along: Vec<f64> = rows
        .iter()
        .filter(|r| r.len() > 1)
        .map(|r| {
            let (lo, hi) = r.iter().fold((f64::MAX, f64::MIN), |(lo, hi), &x| (lo.min(x), hi.max(x)));
            (hi - lo) / (r.len() - 1) as f64
        })
        .collect();
    let dx = along.iter().sum::<f64>() / along.len() as f64;
    let area = g.radius.iter().map(|r| std::f64::consts::PI * r * r).sum::<f64>() / g.len() as f64;
    let measured = area / (dx * dy);
    let formula = setup::lattice_packing(dem, 2);
    eprintln!(
        "lattice: {} grains in {} rows, {:.4} mm apart along them, rows {:.4} mm apart: packing {measured:.4}, the formula {formula:.4}",
        g.len(),
        rows.len(),
        1e3 * dx,
        1e3 * dy
    );
    assert!((measured / formula - 1.0).abs() < 0.02, "{measured} against {formula}");
}
