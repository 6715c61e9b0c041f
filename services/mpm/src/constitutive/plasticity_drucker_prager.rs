//! Yue 2018 §3.3: elasticity on the elastic left Cauchy–Green strain `b^e`, Drucker–Prager
//! yield, a volume-preserving return mapping, free flow under extension.
//!
//! Symbols (d = 2 or 3): κ bulk and μ shear modulus [Pa], α the friction coefficient of the
//! yield surface, J^e = √det b^e, b̄ = det(b^e)^(−1/d) b^e.
//! - Kirchhoff stress (eq. 10): τ = κ/2 (J^e² − 1) I + μ dev b̄.
//! - Yield (eq. 11): Φ = s − α p with s = ‖dev τ‖ = μ ‖dev b̄‖ and p = −tr τ / d = −κ/2 (J^e² − 1).
//! - Return mapping (eqs. 12–17): b^{e,p} = λ₁ I + λ₂ dev b^{e,*} with det b^{e,p} = det b^{e,*}
//!   (plastic flow keeps the volume) and Φ(b^{e,p}) = 0 (λ₂ from eq. 13, written here with the
//!   b̄ normalization the stress uses; λ₁ from eq. 16 in 2D and from the cubic eq. 17 in 3D by
//!   Cardano's method).
//! - Free flow (extension cannot be resisted): det b^e > 1 ⇒ b^e ← det(b^e)^(−1/d) b^e.

use crate::matrix::Matrix;

/// Material constants of the model.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DruckerPragerYue {
    /// Bulk modulus κ [Pa].
    pub bulk: f64,
    /// Shear modulus μ [Pa].
    pub shear: f64,
    /// Yield slope α (sets the angle of repose).
    pub alpha: f64,
    /// A friction that grows with the inertial number (`None`: α fixed).
    pub rate: Option<InertialFriction>,
}

/// The μ(I) law (GDR MiDi 2004, Jop et al. 2006) on the plane Mohr–Coulomb ratio that α sets:
/// sin φ(I) = sin φ_s + (sin φ₂ − sin φ_s) / (1 + I₀ / I), with the inertial number as `grains
/// calibrate --inertial` defines it, I = ε̇ d √(ρ_s / p): ε̇ the axial strain rate of a plane
/// isochoric compression, ‖ε̇^p‖ / √2 for a point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InertialFriction {
    pub sin_static: f64,
    pub sin_dynamic: f64,
    pub i0: f64,
    /// Grain diameter d [m] and the grains' own density ρ_s [kg/m³].
    pub diameter: f64,
    pub grain_density: f64,
    pub dim: usize,
}

impl InertialFriction {
    /// The inertial number of a point flowing at plastic strain rate ‖ε̇^p‖ under pressure p
    /// (infinite at p ≤ 0: a point in extension flows freely anyway).
    pub fn inertial_number(&self, plastic_rate: f64, pressure: f64) -> f64 {
        let axial_rate = plastic_rate * std::f64::consts::FRAC_1_SQRT_2;
        grains_grid::gradient::inertial_number(axial_rate, self.diameter, self.grain_density, pressure).unwrap_or(f64::INFINITY)
    }

    /// α at inertial number I.
    pub fn alpha(&self, i: f64) -> f64 {
        let s = if i > 0.0 {
            self.sin_static + (self.sin_dynamic - self.sin_static) / (1.0 + self.i0 / i)
        } else {
            self.sin_static
        };
        alpha_of_sin(s, self.dim)
    }
}

/// α of a friction angle's sine: √2 sin φ in 2D, 2√6 sin φ / (3 − sin φ) in 3D.
fn alpha_of_sin(s: f64, dim: usize) -> f64 {
    if dim == 2 {
        std::f64::consts::SQRT_2 * s
    } else {
        2.0 * 6f64.sqrt() * s / (3.0 - s)
    }
}

impl DruckerPragerYue {
    /// From Young's modulus, Poisson's ratio and a friction angle φ [degrees]. With
    /// Φ = ‖dev τ‖ − α p: α = √2 sin φ in 2D (Mohr–Coulomb in the plane: max shear = p sin φ),
    /// α = 2√6 sin φ / (3 − sin φ) in 3D (the cone through Mohr–Coulomb's compression corners).
    pub fn new(young: f64, poisson: f64, friction_angle_deg: f64, dim: usize) -> Self {
        let bulk = young / (dim as f64 * (1.0 - (dim as f64 - 1.0) * poisson));
        let shear = young / (2.0 * (1.0 + poisson));
        let alpha = alpha_of_sin(friction_angle_deg.to_radians().sin(), dim);
        DruckerPragerYue {
            bulk,
            shear,
            alpha,
            rate: None,
        }
    }

    /// The return mapping of a trial strain over a step dt and the plastic strain increment
    /// ‖Δε^p‖ it implies (ε = ½ ln b ≈ ½ (b − I) for the small elastic strains of sand).
    /// With a rate dependence α and the rate are found together (bisection on α between the
    /// static and the dynamic slope: the plastic increment falls as α grows, α(I) grows with
    /// it): taking the rate of the last step instead flips between an elastic and a doubled
    /// plastic step every step.
    pub fn return_map_rate<M: Matrix>(&self, trial: &M, dt: f64) -> (M, f64) {
        let plastic = |m: &DruckerPragerYue| {
            let b = return_map(m, trial);
            (b, 0.5 * (*trial - b).norm())
        };
        let (b, de) = plastic(self);
        let Some(r) = &self.rate else {
            return (b, de);
        };
        if de == 0.0 {
            return (b, de);
        }
        // The return keeps det b: the pressure is the trial's.
        let p = pressure(self, trial);
        let (mut lo, mut hi) = (self.alpha, r.alpha(f64::INFINITY));
        let mut best = (b, de);
        for _ in 0..40 {
            let mid = 0.5 * (lo + hi);
            let (b, de) = plastic(&DruckerPragerYue { alpha: mid, ..*self });
            best = (b, de);
            if mid < r.alpha(r.inertial_number(de / dt, p)) {
                lo = mid;
            } else {
                hi = mid;
            }
            if hi - lo < 1e-9 * hi {
                break;
            }
        }
        best
    }
}

/// x^(1/d): a square or a cube root, a third of the cost of `powf` on the hot path.
#[inline(always)]
fn root_d<M: Matrix>(x: f64) -> f64 {
    if M::DIM == 2 { x.sqrt() } else { x.cbrt() }
}

/// The isochoric part b̄ = det(b)^(−1/d) b of a strain whose determinant is `det`.
#[inline(always)]
fn bar_of<M: Matrix>(b: &M, det: f64) -> M {
    *b * (1.0 / root_d::<M>(det))
}

/// Kirchhoff stress τ of an elastic strain b^e (eq. 10).
pub fn kirchhoff<M: Matrix>(m: &DruckerPragerYue, b: &M) -> M {
    let j2 = b.det();
    M::identity() * (0.5 * m.bulk * (j2 - 1.0)) + bar_of(b, j2).dev() * m.shear
}

/// Pressure p = −tr τ / d [Pa] (positive in compression).
pub fn pressure<M: Matrix>(m: &DruckerPragerYue, b: &M) -> f64 {
    -0.5 * m.bulk * (b.det() - 1.0)
}

/// Yield function Φ = ‖dev τ‖ − α p (eq. 11); the state is admissible when Φ ≤ 0.
pub fn yield_function<M: Matrix>(m: &DruckerPragerYue, b: &M) -> f64 {
    let det = b.det();
    let p = -0.5 * m.bulk * (det - 1.0);
    m.shear * bar_of(b, det).dev().norm() - m.alpha * p
}

/// Free flow: a strain in extension (det b^e > 1) is projected to det b^e = 1, which makes
/// the pressure zero.
pub fn free_flow<M: Matrix>(b: &M) -> M {
    let det = b.det();
    if det > 1.0 { bar_of(b, det) } else { *b }
}

/// The volume-preserving return mapping (eqs. 12–17): an admissible state is returned
/// unchanged; otherwise the state on the yield surface with the same det and the same
/// deviatoric direction.
pub fn return_map<M: Matrix>(m: &DruckerPragerYue, b_star: &M) -> M {
    let b = free_flow(b_star);
    if yield_function(m, &b) <= 0.0 {
        return b;
    }
    let det = b.det();
    let dev = b.dev();
    let dev_norm = dev.norm();
    if dev_norm == 0.0 {
        return b;
    }
    // Φ = μ det^(−1/d) λ₂ ‖dev b*‖ − α p(det) = 0  (the pressure depends on det only, kept).
    let lambda2 = m.alpha * pressure(m, &b) * root_d::<M>(det) / (m.shear * dev_norm);
    let lambda1 = if M::DIM == 2 {
        // det(λ₁ I + λ₂ D) = λ₁² + λ₂² det D for traceless 2×2 D (eq. 16).
        (det - lambda2 * lambda2 * dev.det()).sqrt()
    } else {
        // λ₁³ − (λ₂² ‖D‖²/2) λ₁ + (λ₂³ det D − det) = 0 (eq. 17).
        cardano_largest_root(-0.5 * lambda2 * lambda2 * dev_norm * dev_norm, lambda2.powi(3) * dev.det() - det)
    };
    M::identity() * lambda1 + dev * lambda2
}

/// The elastic strain b^e whose Cauchy stress σ = τ / J^e is `sigma` (Yue 2018 §4.2, for
/// new points made from grains): the trace of eq. 10, J tr σ = d κ/2 (J² − 1), gives J (its
/// positive root); its deviator gives dev b̄ = J dev σ / μ; b̄ = dev b̄ + t I with det b̄ = 1
/// gives t (2D: t² + det dev b̄ = 1; 3D: the cubic t³ − ½‖dev b̄‖² t + det dev b̄ − 1 = 0);
/// b^e = J^(2/d) b̄.
pub fn strain_of_stress<M: Matrix>(m: &DruckerPragerYue, sigma: &M) -> M {
    let d = M::DIM as f64;
    let tr = sigma.trace();
    let j = (tr + (tr * tr + d * d * m.bulk * m.bulk).sqrt()) / (d * m.bulk);
    let dev = sigma.dev() * (j / m.shear);
    let t = if M::DIM == 2 {
        (1.0 - dev.det()).sqrt()
    } else {
        cardano_largest_root(-0.5 * dev.norm().powi(2), dev.det() - 1.0)
    };
    (M::identity() * t + dev) * j.powf(2.0 / d)
}

/// The largest real root of the depressed cubic x³ + p x + q = 0 (Cardano; trigonometric
/// form when there are three real roots), polished by one Newton step against the
/// cancellation of the closed form.
#[inline]
pub fn cardano_largest_root(p: f64, q: f64) -> f64 {
    let disc = (q / 2.0).powi(2) + (p / 3.0).powi(3);
    let x = if disc >= 0.0 {
        let s = disc.sqrt();
        (-q / 2.0 + s).cbrt() + (-q / 2.0 - s).cbrt()
    } else {
        let r = (-p / 3.0).sqrt();
        let phi = ((-q / 2.0) / r.powi(3)).clamp(-1.0, 1.0).acos();
        2.0 * r * (phi / 3.0).cos()
    };
    let slope = 3.0 * x * x + p;
    if slope != 0.0 { x - (x * x * x + p * x + q) / slope } else { x }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{DMat2, DMat3, DVec2, DVec3};

    fn material(dim: usize) -> DruckerPragerYue {
        DruckerPragerYue::new(1e6, 0.3, 30.0, dim)
    }

    /// Symmetric positive-definite strains in compression with a large shear: far outside
    /// the yield surface.
    fn strained2(k: usize) -> DMat2 {
        let t = k as f64 * 0.37;
        let (a, b, c) = (0.95 - 0.01 * (k % 3) as f64, 0.99 + 0.002 * (k % 5) as f64, 0.04 + 0.01 * t.sin());
        DMat2::from_cols(DVec2::new(a, c), DVec2::new(c, b))
    }

    /// Steady simple shear at rate γ̇ under pressure p, stepped as the pipeline steps a point
    /// (b* = F b Fᵀ, the return mapping at the last step's plastic rate): the stress ratio
    /// τ_xy / p settles on the μ(I) law at the inertial number of calibrate's definition,
    /// I = (γ̇ / 2) d √(ρ_s / p) (the axial rate of the equivalent plane compression is half
    /// the shear rate), for shear rates across I₀. Rate-independent it stays at sin φ.
    #[test]
    fn steady_simple_shear_follows_the_mu_of_i_law() {
        let (young, phi_s, phi_2, i0, d, rho_s) = (1e6, 15.0f64, 35.0f64, 0.05, 1e-3, 2500.0);
        let mut m = DruckerPragerYue::new(young, 0.3, phi_s, 2);
        let (sin_s, sin_2) = (phi_s.to_radians().sin(), phi_2.to_radians().sin());
        m.rate = Some(InertialFriction {
            sin_static: sin_s,
            sin_dynamic: sin_2,
            i0,
            diameter: d,
            grain_density: rho_s,
            dim: 2,
        });
        let p0 = 1000.0;
        for gamma_dot in [2.0, 20.0, 200.0] {
            let dt = 1e-6;
            let f = DMat2::IDENTITY + DMat2::from_cols(DVec2::ZERO, DVec2::new(gamma_dot * dt, 0.0));
            // Isotropic compression at p0: det b = 1 − 2 p0 / κ.
            let mut b = DMat2::IDENTITY * (1.0 - 2.0 * p0 / m.bulk).sqrt();
            let mut rate = 0.0;
            // Shear strain 0.5: well past yield, the rate settled.
            for _ in 0..(0.5 / (gamma_dot * dt)) as usize {
                let trial = f * b * f.transpose();
                let (next, de) = m.return_map_rate(&trial, dt);
                rate = de / dt;
                b = next;
            }
            let tau = kirchhoff(&m, &b);
            let p = pressure(&m, &b);
            let ratio = tau.col(1).x / p;
            let i = 0.5 * gamma_dot * d * (rho_s / p).sqrt();
            let expected = sin_s + (sin_2 - sin_s) / (1.0 + i0 / i);
            // Steady: all of the shear is plastic, ‖ε̇^p‖ = γ̇ / √2.
            assert!(
                (rate - gamma_dot * std::f64::consts::FRAC_1_SQRT_2).abs() < 0.01 * gamma_dot,
                "{rate}"
            );
            assert!(
                (ratio - expected).abs() < 0.01 * expected,
                "γ̇ = {gamma_dot}: I = {i:.4}, τ/p = {ratio:.4}, μ(I) = {expected:.4}"
            );
            // And the law is not the constant.
            assert!(
                i < 0.2 * i0 || (ratio - sin_s) > 0.1 * (sin_2 - sin_s),
                "γ̇ = {gamma_dot}: I = {i}, τ/p = {ratio}"
            );
        }
    }

    fn strained3(k: usize) -> DMat3 {
        let t = k as f64 * 0.37;
        let (a, b, c) = (0.90 + 0.005 * (k % 4) as f64, 0.985, 1.03 - 0.003 * (k % 3) as f64);
        let (d, e, f) = (0.04 * t.cos(), 0.03 * t.sin(), 0.02);
        DMat3::from_cols(DVec3::new(a, d, e), DVec3::new(d, b, f), DVec3::new(e, f, c))
    }

    /// b^e → σ = τ(b^e) / J → b^e again, for compressed and sheared strains in 2D and 3D.
    #[test]
    fn strain_of_stress_inverts_the_stress() {
        for k in 0..50 {
            let (m2, m3) = (material(2), material(3));
            let b = strained2(k);
            let sigma = kirchhoff(&m2, &b) * (1.0 / b.det().sqrt());
            let back = strain_of_stress(&m2, &sigma);
            assert!((back - b).norm() < 1e-12, "2D {k}: {back:?} vs {b:?}");
            let b = strained3(k);
            let sigma = kirchhoff(&m3, &b) * (1.0 / b.det().sqrt());
            let back = strain_of_stress(&m3, &sigma);
            assert!((back - b).norm() < 1e-12, "3D {k}: {back:?} vs {b:?}");
        }
        // Stress-free: no strain.
        assert!((strain_of_stress(&material(3), &DMat3::ZERO) - DMat3::IDENTITY).norm() < 1e-15);
    }

    #[test]
    fn return_mapping_lands_on_the_yield_surface_and_keeps_the_volume() {
        for k in 0..50 {
            let (m2, m3) = (material(2), material(3));
            let b = strained2(k);
            assert!(yield_function(&m2, &b) > 0.0, "test state {k} must violate the yield condition");
            let r = return_map(&m2, &b);
            let scale = m2.alpha * pressure(&m2, &b).abs();
            assert!(yield_function(&m2, &r).abs() < 1e-8 * scale, "2D Φ = {}", yield_function(&m2, &r));
            assert!((r.det() - b.det()).abs() < 1e-12, "2D volume: {} vs {}", r.det(), b.det());

            let b = strained3(k);
            assert!(yield_function(&m3, &b) > 0.0, "3D test state {k} must violate the yield condition");
            let r = return_map(&m3, &b);
            let scale = m3.alpha * pressure(&m3, &b).abs();
            assert!(yield_function(&m3, &r).abs() < 1e-8 * scale, "3D Φ = {}", yield_function(&m3, &r));
            assert!((r.det() - b.det()).abs() < 1e-12, "3D volume: {} vs {}", r.det(), b.det());
            // Idempotent: a state on the surface stays.
            assert!((return_map(&m3, &r) - r).norm() < 1e-12);
        }
    }

    #[test]
    fn admissible_states_are_untouched_and_extension_flows_freely() {
        let m = material(2);
        let b = DMat2::from_diagonal(DVec2::new(0.999, 0.999));
        assert_eq!(return_map(&m, &b), b);
        let stretched = DMat2::from_cols(DVec2::new(1.02, 0.01), DVec2::new(0.01, 1.03));
        let r = free_flow(&stretched);
        assert!((r.det() - 1.0).abs() < 1e-14 && pressure(&m, &r).abs() < 1e-6);
    }

    #[test]
    fn cardano_matches_a_numerical_root() {
        for (p, q) in [(-3.0, 1.0), (-0.5, -1.0), (0.2, -2.0), (-1e-3, -0.98), (-2.0, 0.0)] {
            let x = cardano_largest_root(p, q);
            let f = |x: f64| x * x * x + p * x + q;
            // Bisection on [x − 1, x + 1] for the largest sign change confirms the root.
            let (mut lo, mut hi) = (x - 0.5, 10.0);
            assert!(f(hi) > 0.0);
            if f(lo) > 0.0 {
                lo = x - 1e-9;
            }
            for _ in 0..200 {
                let mid = 0.5 * (lo + hi);
                if f(mid) > 0.0 { hi = mid } else { lo = mid }
            }
            assert!((x - 0.5 * (lo + hi)).abs() < 1e-9, "p {p} q {q}: {x} vs {}", 0.5 * (lo + hi));
            assert!(
                f(x).abs() < 1e-12 * (x.abs().powi(3) + (p * x).abs() + q.abs()),
                "residual {}",
                f(x)
            );
        }
    }
}
