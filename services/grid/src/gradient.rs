//! The gradient of a velocity field and the measures of it the solvers and the oracle share:
//! the spin ½ ∇ × v and the shear rate √(2 D′:D′).

use crate::Space;

/// The gradient L[a][b] = ∂v_a/∂x_b of an interpolated velocity field (zero rows and columns
/// beyond the space's dimension).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Gradient(pub [[f64; 3]; 3]);

impl Gradient {
    /// The spin ½ ∇ × v.
    pub fn spin<S: Space>(&self) -> S::Ang {
        let l = &self.0;
        S::ang_from_array([0.5 * (l[2][1] - l[1][2]), 0.5 * (l[0][2] - l[2][0]), 0.5 * (l[1][0] - l[0][1])])
    }

    /// The shear rate √(2 D′:D′), D′ the deviatoric part of the strain rate (of the space's
    /// `dim` dimensions): γ̇ of a simple shear v_x = γ̇ y.
    pub fn shear_rate(&self, dim: usize) -> f64 {
        let l = &self.0;
        let mean = (0..dim).map(|a| l[a][a]).sum::<f64>() / dim as f64;
        let pairs = (0..dim).flat_map(|a| (0..dim).map(move |b| (a, b)));
        let dd: f64 = pairs
            .map(|(a, b)| 0.5 * (l[a][b] + l[b][a]) - if a == b { mean } else { 0.0 })
            .map(|d| d * d)
            .sum();
        (2.0 * dd).sqrt()
    }
}

/// The inertial number I = rate · d √(ρ_s / p) (GDR MiDi 2004) of material shearing at
/// `rate` [1/s] (the caller's measure of it: the oracle's shear rate, the MPM's plastic
/// rate as calibrate counts it) with grains of diameter d and density ρ_s under pressure p;
/// `None` where p ≤ 0 (no contact network: each caller says what that means for it).
pub fn inertial_number(rate: f64, diameter: f64, grain_density: f64, pressure: f64) -> Option<f64> {
    (pressure > 0.0).then(|| rate * diameter * (grain_density / pressure).sqrt())
}
