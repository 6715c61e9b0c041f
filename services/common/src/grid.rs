//! The background grid of a scene and its shape functions: the MPM's grid, which the DEM
//! rasterizes onto in a coupled run (Yue 2018 Alg. 4 uses the MPM's own weights). One place,
//! so that both solvers number and weigh nodes alike.

use grains_grid::{Grid, Kernel};
use grains_protocol::scene::{MpmKernel, Scene};

/// The grid covering the scene's domain with its cell size, and the MPM kernel (GIMP of
/// half-width h / (2 · points per axis), or quadratic B-splines).
pub fn scene_grid(scene: &Scene) -> (Grid, Kernel) {
    let h = scene.domain.cell_size;
    let grid = Grid::covering(scene.domain.min, scene.domain.max, h, scene.dim()).with_periodic(scene.domain.periodic);
    let kernel = match scene.mpm.kernel {
        MpmKernel::Gimp => Kernel::Gimp {
            half_width: 0.5 * h / scene.mpm.points_per_axis as f64,
        },
        MpmKernel::Bspline => Kernel::Bspline2,
    };
    (grid, kernel)
}

/// The domain's largest extent [m] (what gravity or a wall can move material across).
pub fn scene_extent(scene: &Scene) -> f64 {
    (0..scene.dim())
        .map(|k| scene.domain.max[k] - scene.domain.min[k])
        .fold(0.0, f64::max)
}
