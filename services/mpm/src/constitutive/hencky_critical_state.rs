//! Chen et al. 2021 §2.2: Hencky elasticity on the elastic left Cauchy–Green strain `b^e`,
//! a cohesive Drucker–Prager yield surface with non-associated flow, and critical-state
//! softening driven by the packing fraction Φ.
//!
//! Symbols (d = 2 or 3 the dimension): ε = ½ ln b^e the elastic Hencky strain, K bulk and G
//! shear modulus [Pa], τ the Kirchhoff stress, p = tr τ / d, s = dev τ, √J₂ = √(½ s:s).
//! - Elasticity (eq. 4): τ = K tr ε I + 2G dev ε, so p = K tr ε and s = 2G dev ε.
//! - Yield (eq. 5) f = √J₂ + η p − ζ c, flow potential (eq. 6) g = √J₂ + η̄ p, plastic flow
//!   Δε^p = Δλ ∂g/∂τ = Δλ (s / (2√J₂) + η̄/d I), hence tr Δε^p = Δλ η̄ (ψ > 0 dilates).
//! - Critical state (eq. 7): tan ψ = χ (Φ − Φ_cs), tan φ = tan φ_cs + tan ψ, with tan φ clamped
//!   to ≥ 0: a very loose state (Φ < Φ_cs − tan φ_cs / χ) has no friction instead of a negative
//!   one, and keeps its negative ψ (it goes on contracting).
//! - Packing fraction (eq. 8): dΦ/dt = −ξ Φ (Φ − Φ_cs) ‖ε̇^p‖, integrated exactly over a step.
//!
//! Sign convention: the paper's, tension positive: τ and p are positive in tension, so a
//! compressed grain pack has p < 0 (the opposite of [`super::plasticity_drucker_prager`]'s
//! pressure). Hence [`mean_stress`] rather than "pressure".
//!
//! Cone constants: in 2D the paper's plane Mohr–Coulomb match η = sin φ, η̄ = sin ψ, ζ = cos φ.
//! In 3D the Drucker–Prager cone through the Mohr–Coulomb compression corners (de Souza Neto
//! et al. 2008, §6.4): η = 2√3 sin φ / (3 − sin φ), ζ = 2√3 cos φ / (3 − sin φ),
//! η̄ = 2√3 sin ψ / (3 − sin ψ).
//!
//! Return mapping, in the principal frame of b^e (the return is coaxial, so one
//! eigendecomposition per point): smooth return Δλ = f_trial / (G + K η η̄), which moves √J₂
//! by −G Δλ and p by −K η̄ Δλ. When that would reverse the deviator (√J₂ − G Δλ < 0) or leave
//! p beyond the apex, the state goes to the apex: s = 0, p = ζ c / η. Cohesionless material
//! (c = 0) therefore ends stress-free in extension, also when φ = 0 where the cone is a
//! cylinder whose "apex" is taken as p = 0 (no tension without cohesion); with c > 0 and φ = 0
//! the cylinder has no apex.
//!
//! Φ is read at the start of the step (for φ, ψ) and advanced with this step's plastic strain.
//! Requires b^e symmetric positive definite and G + K η η̄ > 0. The latter holds at every Φ
//! when G > K tan²φ_cs / 2: η η̄ < 0 only when ψ < 0 < φ, where tan φ + |tan ψ| = tan φ_cs
//! bounds |η η̄| by tan²φ_cs / 4 in 2D and tan²φ_cs / 2 in 3D (Table 2: G = 460 MPa > 24 MPa).

use crate::matrix::Matrix;

/// Material constants of the model.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HenckyCriticalState {
    /// Bulk modulus K [Pa].
    pub bulk: f64,
    /// Shear modulus G [Pa].
    pub shear: f64,
    /// tan φ_cs of the critical-state friction angle (eq. 7 is written in tangents; kept as one
    /// so the per-point update needs no trigonometry).
    pub tan_friction_cs: f64,
    /// Critical packing fraction Φ_cs.
    pub packing_cs: f64,
    /// Dilatancy slope χ: tan ψ = χ (Φ − Φ_cs).
    pub chi: f64,
    /// ξ: relaxation of Φ towards Φ_cs per unit plastic strain (eq. 8).
    pub xi: f64,
    /// Cohesion c [Pa].
    pub cohesion: f64,
}

/// The cone of f = √J₂ + η p − ζ c and g = √J₂ + η̄ p at one packing fraction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cone {
    pub eta: f64,
    pub eta_bar: f64,
    pub zeta: f64,
}

impl Cone {
    /// The largest mean stress p the yield surface admits: the apex ζ c / η; for η = 0 (the
    /// cylinder of a frictionless loose state) 0 without cohesion, unbounded with.
    #[inline]
    pub fn apex(&self, cohesion: f64) -> f64 {
        if self.eta > 0.0 {
            self.zeta * cohesion / self.eta
        } else if cohesion > 0.0 {
            f64::INFINITY
        } else {
            0.0
        }
    }
}

impl HenckyCriticalState {
    /// Table 2 of Chen et al. 2021, cohesionless. φ_cs = 0.27 is read as radians (15.47°): the
    /// table gives no unit and eq. 7 writes tan φ_cs, so φ_cs is an angle; read as tan φ_cs it
    /// would be 15.11°, 0.36° less. Φ_cs = 81.5 %.
    pub fn chen_2021_table_2() -> Self {
        HenckyCriticalState {
            bulk: 630e6,
            shear: 460e6,
            tan_friction_cs: 0.27f64.tan(),
            packing_cs: 0.815,
            chi: 7.0,
            xi: 0.01,
            cohesion: 0.0,
        }
    }

    /// (tan φ, tan ψ) of eq. 7, tan φ clamped to ≥ 0.
    #[inline]
    fn tangents(&self, packing: f64) -> (f64, f64) {
        let tan_psi = self.chi * (packing - self.packing_cs);
        ((self.tan_friction_cs + tan_psi).max(0.0), tan_psi)
    }

    /// Friction and dilation angles (φ, ψ) [radians] at a packing fraction (eq. 7).
    pub fn angles(&self, packing: f64) -> (f64, f64) {
        let (tan_phi, tan_psi) = self.tangents(packing);
        (tan_phi.atan(), tan_psi.atan())
    }

    /// The yield and flow cone at a packing fraction in `dim` dimensions (see the module docs).
    #[inline]
    pub fn cone(&self, packing: f64, dim: usize) -> Cone {
        let (tan_phi, tan_psi) = self.tangents(packing);
        // sin and cos from the tangent: no trig on the per-point path.
        let cos_phi = 1.0 / (1.0 + tan_phi * tan_phi).sqrt();
        let sin_phi = tan_phi * cos_phi;
        let sin_psi = tan_psi / (1.0 + tan_psi * tan_psi).sqrt();
        if dim == 2 {
            Cone {
                eta: sin_phi,
                eta_bar: sin_psi,
                zeta: cos_phi,
            }
        } else {
            let k = 2.0 * 3f64.sqrt();
            Cone {
                eta: k * sin_phi / (3.0 - sin_phi),
                eta_bar: k * sin_psi / (3.0 - sin_psi),
                zeta: k * cos_phi / (3.0 - sin_phi),
            }
        }
    }

    /// P-wave modulus K + 2(1 − 1/d) G (K + G in 2D, K + 4G/3 in 3D), for the CFL time step.
    pub fn wave_speed_modulus(&self, dim: usize) -> f64 {
        self.bulk + 2.0 * (1.0 - 1.0 / dim as f64) * self.shear
    }
}

/// Per-point history of the model.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PointState {
    /// Packing fraction Φ (set it: the default 0 is the loosest possible state).
    pub packing: f64,
    /// Accumulated plastic strain Σ ‖Δε^p‖ (Frobenius norm).
    pub plastic_strain: f64,
    /// ‖Δε^p‖ / dt of the last step [1/s].
    pub plastic_strain_rate: f64,
}

/// Mean stress p = tr τ / d [Pa], the paper's "pressure": positive in tension.
pub fn mean_stress<M: Matrix>(tau: &M) -> f64 {
    tau.trace() / M::DIM as f64
}

/// Hencky strain ε = ½ ln b.
pub fn hencky_strain<M: Matrix>(b: &M) -> M {
    let (e, q) = principal_log_strain(b);
    M::from_eigen(e, &q)
}

/// Principal values of ½ ln b and its eigenvectors (unused entries 0).
fn principal_log_strain<M: Matrix>(b: &M) -> ([f64; 3], M) {
    let (l, q) = b.sym_eigen();
    let mut e = [0.0; 3];
    for i in 0..M::DIM {
        debug_assert!(l[i] > 0.0, "b^e must be positive definite, eigenvalue {}", l[i]);
        e[i] = 0.5 * l[i].ln();
    }
    (e, q)
}

/// Principal Kirchhoff stresses of principal Hencky strains (eq. 4).
#[inline]
fn principal_stress(m: &HenckyCriticalState, e: &[f64; 3], dim: usize) -> [f64; 3] {
    let tr: f64 = e[..dim].iter().sum();
    let mut tau = [0.0; 3];
    for i in 0..dim {
        tau[i] = m.bulk * tr + 2.0 * m.shear * (e[i] - tr / dim as f64);
    }
    tau
}

/// Kirchhoff stress τ of an elastic strain b^e (eq. 4).
pub fn kirchhoff<M: Matrix>(m: &HenckyCriticalState, b_e: &M) -> M {
    let (e, q) = principal_log_strain(b_e);
    M::from_eigen(principal_stress(m, &e, M::DIM), &q)
}

/// The elastic strain b^e whose Cauchy stress σ = τ / J is `sigma` (for new points made
/// from grains, Yue 2018 §4.2 with this model's elasticity): in the principal frame of σ,
/// τᵢ = J σᵢ with J = e^θ, θ = tr ε, so the trace of eq. 4 reads d K θ = e^θ tr σ (solved
/// by Newton from θ = tr σ / (d K); one root in compression, the small one under a small
/// tension); then εᵢ = J dev σᵢ / (2G) + θ / d and b^e = exp(2ε).
pub fn strain_of_stress<M: Matrix>(m: &HenckyCriticalState, sigma: &M) -> M {
    let d = M::DIM as f64;
    let (s, q) = sigma.sym_eigen();
    let tr: f64 = s[..M::DIM].iter().sum();
    let mut theta = tr / (d * m.bulk);
    for _ in 0..50 {
        let f = d * m.bulk * theta - theta.exp() * tr;
        let slope = d * m.bulk - theta.exp() * tr;
        let step = f / slope;
        theta -= step;
        if step.abs() <= 1e-15 * theta.abs().max(1e-12) {
            break;
        }
    }
    let j = theta.exp();
    let mut b = [0.0; 3];
    for i in 0..M::DIM {
        b[i] = (2.0 * (j * (s[i] - tr / d) / (2.0 * m.shear) + theta / d)).exp();
    }
    M::from_eigen(b, &q)
}

/// Yield function f = √J₂ + η p − ζ c (eq. 5) at a packing fraction; admissible when f ≤ 0.
pub fn yield_function<M: Matrix>(m: &HenckyCriticalState, tau: &M, packing: f64) -> f64 {
    let cone = m.cone(packing, M::DIM);
    std::f64::consts::FRAC_1_SQRT_2 * tau.dev().norm() + cone.eta * mean_stress(tau) - cone.zeta * m.cohesion
}

/// Packing fraction after a plastic strain increment ‖Δε^p‖ (eq. 8). With s the accumulated
/// plastic strain, eq. 8 is the logistic equation dΦ/ds = ξ Φ (Φ_cs − Φ), solved exactly:
/// Φ(s) = Φ_cs Φ₀ / (Φ₀ + (Φ_cs − Φ₀) e^(−ξ Φ_cs s)). Exact for any step size, and never
/// overshoots Φ_cs.
#[inline]
pub fn evolve_packing(m: &HenckyCriticalState, packing: f64, plastic_strain_increment: f64) -> f64 {
    let decay = (-m.xi * m.packing_cs * plastic_strain_increment).exp();
    m.packing_cs * packing / (packing + (m.packing_cs - packing) * decay)
}

/// The return mapping of a trial strain b^e (after b^e ← f b^e fᵀ). Returns the admissible
/// b^e and its Kirchhoff stress (so the caller need not decompose again), and updates the
/// point's plastic strain, its rate ‖Δε^p‖ / dt and its packing fraction. An admissible trial
/// is returned unchanged (rate 0, Φ kept).
pub fn return_map<M: Matrix>(m: &HenckyCriticalState, b_trial: &M, state: &mut PointState, dt: f64) -> (M, M) {
    debug_assert!(dt > 0.0);
    let d = M::DIM;
    let (e, q) = principal_log_strain(b_trial);
    let cone = m.cone(state.packing, d);
    let tau = principal_stress(m, &e, d);
    let tr: f64 = e[..d].iter().sum();
    let p = m.bulk * tr;
    let mut s = [0.0; 3];
    for i in 0..d {
        s[i] = tau[i] - p;
    }
    let sqrt_j2 = (0.5 * s.iter().map(|x| x * x).sum::<f64>()).sqrt();
    let f = sqrt_j2 + cone.eta * p - cone.zeta * m.cohesion;
    let p_apex = cone.apex(m.cohesion);
    if f <= 0.0 && p <= p_apex {
        state.plastic_strain_rate = 0.0;
        return (*b_trial, M::from_eigen(tau, &q));
    }

    let mut e_new = [0.0; 3];
    let hardening = m.shear + m.bulk * cone.eta * cone.eta_bar;
    debug_assert!(hardening > 0.0, "G + K η η̄ = {hardening} must be positive");
    let dlambda = f / hardening;
    // The smooth return keeps f = 0 along the way, so its deviator √J₂ − G Δλ turns negative
    // exactly when its p passes the apex: one test covers both. √J₂ > 0 only guards s / √J₂
    // against rounding at a hydrostatic trial (which always goes to the apex).
    if sqrt_j2 > 0.0 && p - m.bulk * dlambda * cone.eta_bar <= p_apex {
        // Δε^p = Δλ (s / (2√J₂) + η̄/d I).
        for i in 0..d {
            e_new[i] = e[i] - dlambda * (s[i] / (2.0 * sqrt_j2) + cone.eta_bar / d as f64);
        }
    } else {
        // Apex: s = 0, p = p_apex = K tr ε (finite here: see Cone::apex and the module docs).
        debug_assert!(p_apex.is_finite());
        e_new[..d].fill(p_apex / (m.bulk * d as f64));
    }

    let increment = (0..d).map(|i| (e[i] - e_new[i]).powi(2)).sum::<f64>().sqrt();
    state.plastic_strain += increment;
    state.plastic_strain_rate = increment / dt;
    state.packing = evolve_packing(m, state.packing, increment);

    let b = M::from_eigen(e_new.map(|x| (2.0 * x).exp()), &q);
    (b, M::from_eigen(principal_stress(m, &e_new, d), &q))
}

/// One state of the model's [`simple_shear`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShearState {
    /// Time since the start [s] and shear strain γ (the top's travel over the height).
    pub time: f64,
    pub strain: f64,
    /// The normal strain rate ε̇_yy over the step that held σ_yy [1/s] (dilation positive).
    pub normal_rate: f64,
    /// Cauchy stress after the step [Pa], tension positive.
    pub sxx: f64,
    pub syy: f64,
    pub sxy: f64,
    pub packing: f64,
}

/// The model's 2D simple shear under a constant normal stress: the shear cell's test as one
/// element. From the isotropic stress −p (Hencky: b^e = e^(−p/K) I) at packing `packing`, the
/// velocity gradient [[0, γ̇], [0, ε̇_yy]] to shear strain `strain` in `steps` steps, ε̇_yy
/// each step the one that keeps σ_yy = −p (secant iterations). The states after each step.
pub fn simple_shear(m: &HenckyCriticalState, packing: f64, pressure: f64, rate: f64, strain: f64, steps: usize) -> Vec<ShearState> {
    use glam::{DMat2, DVec2};
    let dt = strain / rate / steps as f64;
    let mut b = DMat2::IDENTITY * (-pressure / m.bulk).exp();
    let mut state = PointState {
        packing,
        ..PointState::default()
    };
    let mut jacobian = 1.0;
    let mut normal_rate = 0.0;
    let trial = |e: f64, b: &DMat2, state: &PointState, jacobian: f64| {
        let f = DMat2::IDENTITY + DMat2::from_cols(DVec2::ZERO, DVec2::new(rate, e)) * dt;
        let mut s = *state;
        let (b_new, tau) = return_map(m, &(f * *b * f.transpose()), &mut s, dt);
        let j = jacobian * f.determinant();
        (b_new, tau, s, j, tau.y_axis.y / j + pressure)
    };
    let mut out = Vec::with_capacity(steps);
    for step in 0..steps {
        let (mut e0, mut e1) = (normal_rate, normal_rate + 1e-3 * rate);
        let mut r0 = trial(e0, &b, &state, jacobian).4;
        let mut next = trial(e1, &b, &state, jacobian);
        for _ in 0..30 {
            if next.4.abs() <= 1e-9 * pressure || next.4 == r0 {
                break;
            }
            let e2 = e1 - next.4 * (e1 - e0) / (next.4 - r0);
            (e0, r0, e1) = (e1, next.4, e2);
            next = trial(e1, &b, &state, jacobian);
        }
        let (b_new, tau, s, j, _) = next;
        (b, state, jacobian, normal_rate) = (b_new, s, j, e1);
        out.push(ShearState {
            time: (step + 1) as f64 * dt,
            strain: (step + 1) as f64 * dt * rate,
            normal_rate,
            sxx: tau.x_axis.x / j,
            syy: tau.y_axis.y / j,
            sxy: tau.y_axis.x / j,
            packing: state.packing,
        });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{DMat2, DMat3, DQuat, DVec2, DVec3};

    use grains_grid::rng::Rng;

    fn table2() -> HenckyCriticalState {
        HenckyCriticalState::chen_2021_table_2()
    }

    /// Packing fractions: very loose (φ clamped to 0), loose, critical, dense, very dense.
    const PACKINGS: [f64; 5] = [0.70, 0.79, 0.815, 0.84, 0.87];

    fn rot2(rng: &mut Rng) -> DMat2 {
        DMat2::from_angle(rng.signed() * 4.0)
    }
    fn rot3(rng: &mut Rng) -> DMat3 {
        let axis = DVec3::new(rng.signed(), rng.signed(), rng.signed() + 2.0).normalize();
        DMat3::from_quat(DQuat::from_axis_angle(axis, rng.signed() * 4.0))
    }
    /// b = R exp(2 diag e) Rᵀ: the strain whose Hencky strain is R diag(e) Rᵀ.
    fn b2(r: &DMat2, e: [f64; 3]) -> DMat2 {
        *r * DMat2::from_diagonal(DVec2::new((2.0 * e[0]).exp(), (2.0 * e[1]).exp())) * r.transpose()
    }
    fn b3(r: &DMat3, e: [f64; 3]) -> DMat3 {
        *r * DMat3::from_diagonal(DVec3::from_array(e.map(|x| (2.0 * x).exp()))) * r.transpose()
    }

    /// b^e → σ = τ(b^e) / J → b^e again (rotated, compressed, sheared; 2D and 3D).
    #[test]
    fn strain_of_stress_inverts_the_stress() {
        let m = table2();
        let mut rng = Rng::new(13);
        for _ in 0..50 {
            let e = [-2e-3 * rng.signed(), -1e-3 * rng.signed() + 2e-4, -3e-3 * rng.signed()];
            let b = b2(&rot2(&mut rng), e);
            let sigma = kirchhoff(&m, &b) * (1.0 / b.det().sqrt());
            let back = strain_of_stress(&m, &sigma);
            assert!((back - b).norm() < 1e-12, "2D {back:?} vs {b:?}");
            let b = b3(&rot3(&mut rng), e);
            let sigma = kirchhoff(&m, &b) * (1.0 / b.det().sqrt());
            let back = strain_of_stress(&m, &sigma);
            assert!((back - b).norm() < 1e-12, "3D {back:?} vs {b:?}");
        }
    }
    fn isotropic<M: Matrix>(e: f64) -> M {
        M::from_eigen([(2.0 * e).exp(); 3], &M::identity())
    }

    /// (√J₂, p) of a stress.
    fn invariants<M: Matrix>(tau: &M) -> (f64, f64) {
        (std::f64::consts::FRAC_1_SQRT_2 * tau.dev().norm(), mean_stress(tau))
    }

    #[test]
    fn elastic_stress_is_hencky() {
        // Analytic: for b = R diag(λ) Rᵀ, ε = R diag(½ ln λ) Rᵀ and τ = R (K tr ε I + 2G dev ε) Rᵀ.
        let m = table2();
        let (k, g) = (m.bulk, m.shear);
        let mut rng = Rng::new(7);
        for _ in 0..50 {
            let e = [rng.signed() * 1e-3, rng.signed() * 1e-3, rng.signed() * 1e-3];
            let r = rot2(&mut rng);
            let tr = e[0] + e[1];
            let want =
                r * DMat2::from_diagonal(DVec2::new(
                    k * tr + 2.0 * g * (e[0] - tr / 2.0),
                    k * tr + 2.0 * g * (e[1] - tr / 2.0),
                )) * r.transpose();
            let got = kirchhoff(&m, &b2(&r, e));
            assert!((got - want).norm() < 1e-9 * want.norm(), "2D: {got:?} vs {want:?}");

            let r = rot3(&mut rng);
            let tr = e[0] + e[1] + e[2];
            let want = r * DMat3::from_diagonal(DVec3::from_array(e.map(|x| k * tr + 2.0 * g * (x - tr / 3.0)))) * r.transpose();
            let got = kirchhoff(&m, &b3(&r, e));
            assert!((got - want).norm() < 1e-9 * want.norm(), "3D: {got:?} vs {want:?}");
        }
        // Small strain b = I + 2h: τ = K tr h I + 2G dev h to first order (relative error ~ ‖h‖).
        let h = DMat3::from_cols(
            DVec3::new(1e-6, 2e-7, -3e-7),
            DVec3::new(2e-7, -4e-7, 5e-7),
            DVec3::new(-3e-7, 5e-7, 2e-7),
        );
        let want = DMat3::IDENTITY * (k * h.trace()) + h.dev() * (2.0 * g);
        let got = kirchhoff(&m, &(DMat3::IDENTITY + h * 2.0));
        assert!((got - want).norm() < 1e-5 * want.norm(), "linearized: {got:?} vs {want:?}");
    }

    #[test]
    fn critical_state_angles_follow_eq_7() {
        let m = table2();
        let phi_cs = m.tan_friction_cs.atan();
        assert!((phi_cs - 0.27).abs() < 1e-15);
        let (phi, psi) = m.angles(m.packing_cs);
        assert!((phi - phi_cs).abs() < 1e-15 && psi == 0.0, "at Φ_cs: φ {phi} ψ {psi}");
        let c2 = m.cone(m.packing_cs, 2);
        assert!((c2.eta - phi_cs.sin()).abs() < 1e-15 && (c2.zeta - phi_cs.cos()).abs() < 1e-15 && c2.eta_bar == 0.0);
        for packing in [0.79, 0.80, 0.84, 0.87] {
            let (phi, psi) = m.angles(packing);
            assert!((psi.tan() - 7.0 * (packing - 0.815)).abs() < 1e-14, "tan ψ = χ (Φ − Φ_cs)");
            assert!((phi.tan() - psi.tan() - phi_cs.tan()).abs() < 1e-14, "tan φ = tan φ_cs + tan ψ");
            assert_eq!(psi > 0.0, packing > m.packing_cs, "dense dilates, loose contracts");
            let c2 = m.cone(packing, 2);
            assert!((c2.eta - phi.sin()).abs() < 1e-15 && (c2.eta_bar - psi.sin()).abs() < 1e-15);
        }
        // Very loose: the friction angle is clamped at 0, ψ stays negative.
        let (phi, psi) = m.angles(0.70);
        assert!(phi == 0.0 && psi < 0.0);
        assert_eq!(m.cone(0.70, 3).eta, 0.0);
        assert_eq!(m.wave_speed_modulus(2), 630e6 + 460e6);
        assert!((m.wave_speed_modulus(3) - (630e6 + 4.0 / 3.0 * 460e6)).abs() < 1e-6);
    }

    /// The element simple shear holds σ_yy at −p on every step; while elastic its shear
    /// stress is G γ (Hencky at small strain); it ends at the critical state of steady simple
    /// shear: Φ = Φ_cs, no volume change, and (the principal axes at 45°, σ_xx = σ_yy) the
    /// 2D cone's √J₂ = sin φ_cs p is |σ_xy| = sin φ_cs p (Mohr–Coulomb in simple shear).
    #[test]
    fn simple_shear_holds_its_normal_stress_and_ends_at_the_critical_state() {
        let m = HenckyCriticalState {
            bulk: 2.0e5,
            shear: 1.08e5,
            tan_friction_cs: 0.28,
            packing_cs: 0.8157,
            chi: 7.0,
            xi: 5.5,
            cohesion: 0.0,
        };
        let (p, rate) = (4.0e3, 2.0);
        let out = simple_shear(&m, 0.83, p, rate, 3.0, 30_000);
        let worst = out.iter().map(|s| (s.syy + p).abs()).fold(0.0, f64::max);
        assert!(worst < 1e-6 * p, "σ_yy off by {worst} Pa");
        let first = out[0];
        assert!((first.sxy.abs() / (m.shear * first.strain) - 1.0).abs() < 1e-3, "{first:?}");
        // A dense start dilates, then stops.
        assert!(out.iter().any(|s| s.normal_rate > 0.05 * rate));
        let end = *out.last().unwrap();
        assert!((end.packing - m.packing_cs).abs() < 1e-4, "{end:?}");
        assert!(end.normal_rate.abs() < 1e-3 * rate, "{end:?}");
        let sin_cs = m.tan_friction_cs / (1.0 + m.tan_friction_cs.powi(2)).sqrt();
        let pressure = -0.5 * (end.sxx + end.syy);
        assert!((end.sxy.abs() / pressure / sin_cs - 1.0).abs() < 0.01, "{end:?}, sin φ_cs {sin_cs}");
    }

    #[test]
    fn cones_pass_through_the_mohr_coulomb_compression_corners() {
        // Analytic: Mohr–Coulomb (tension positive) is (σ_max − σ_min)/2 = −(σ_max + σ_min)/2 sin φ
        // + c cos φ, i.e. σ_min = (σ_max (1 + sin φ) − 2c cos φ) / (1 − sin φ). The 2D cone holds
        // it for (σ_min, σ_max); the 3D cone on the triaxial-compression meridian (σ_min, σ_max, σ_max).
        for cohesion in [0.0, 2e5] {
            let m = HenckyCriticalState { cohesion, ..table2() };
            for packing in PACKINGS {
                let (phi, _) = m.angles(packing);
                let sigma_max = -1e6;
                let sigma_min = (sigma_max * (1.0 + phi.sin()) - 2.0 * cohesion * phi.cos()) / (1.0 - phi.sin());
                let f2 = yield_function(&m, &DMat2::from_diagonal(DVec2::new(sigma_min, sigma_max)), packing);
                let f3 = yield_function(&m, &DMat3::from_diagonal(DVec3::new(sigma_min, sigma_max, sigma_max)), packing);
                assert!(
                    f2.abs() < 1e-9 * sigma_min.abs() && f3.abs() < 1e-9 * sigma_min.abs(),
                    "Φ {packing}: f {f2} {f3}"
                );
                // The 3D cone is outside Mohr–Coulomb in triaxial extension (σ_min, σ_min, σ_max).
                if phi > 0.0 {
                    let f3 = yield_function(&m, &DMat3::from_diagonal(DVec3::new(sigma_min, sigma_min, sigma_max)), packing);
                    assert!(f3 < 0.0, "Φ {packing}: f {f3}");
                }
            }
        }
    }

    /// Trial principal Hencky strains: compression (sometimes extension) with shear up to
    /// several times the volumetric strain, so most are far outside the cone.
    fn trial_strain(rng: &mut Rng) -> [f64; 3] {
        let volumetric = -1e-3 * (rng.signed() + 0.8);
        [0, 1, 2].map(|_| volumetric / 3.0 + 2e-3 * rng.signed())
    }

    /// Lands on f = 0, checks the returned τ against b^e, and counts elastic and plastic states.
    fn check_return<M: Matrix>(m: &HenckyCriticalState, b: &M, packing: f64, counts: &mut [usize; 2]) {
        let tau_trial = kirchhoff(m, b);
        let f_trial = yield_function(m, &tau_trial, packing);
        let (sqrt_j2, p) = invariants(&tau_trial);
        let scale = p.abs() + sqrt_j2 + m.cohesion;
        let mut state = PointState {
            packing,
            ..Default::default()
        };
        let (b_new, tau) = return_map(m, b, &mut state, 1e-5);
        assert!(
            (kirchhoff(m, &b_new) - tau).norm() < 1e-8 * scale,
            "returned τ must be the stress of b^e"
        );
        if f_trial <= 0.0 && p <= m.cone(packing, M::DIM).apex(m.cohesion) {
            assert_eq!(
                (b_new, state.packing, state.plastic_strain),
                (*b, packing, 0.0),
                "admissible state changed"
            );
            counts[0] += 1;
        } else {
            let f = yield_function(m, &tau, packing);
            assert!(
                f.abs() < 1e-8 * scale,
                "{}D: f = {f} after return, scale {scale}, Φ {packing}",
                M::DIM
            );
            assert!(state.plastic_strain > 0.0);
            counts[1] += 1;
        }
    }

    #[test]
    fn return_mapping_lands_on_the_yield_surface() {
        let mut rng = Rng::new(11);
        let mut counts = [0; 2];
        for cohesion in [0.0, 1e5] {
            let m = HenckyCriticalState { cohesion, ..table2() };
            for packing in PACKINGS {
                for _ in 0..100 {
                    let e = trial_strain(&mut rng);
                    let r = rot2(&mut rng);
                    check_return(&m, &b2(&r, e), packing, &mut counts);
                    let r = rot3(&mut rng);
                    check_return(&m, &b3(&r, e), packing, &mut counts);
                }
                // Near-isotropic small compression: admissible.
                let e = [-1e-4, -1.01e-4, -0.99e-4];
                check_return(&m, &b3(&rot3(&mut rng), e), packing, &mut counts);
                check_return(&m, &b2(&rot2(&mut rng), e), packing, &mut counts);
            }
        }
        assert!(counts[0] >= 16 && counts[1] >= 1000, "elastic / plastic trials: {counts:?}");
    }

    /// Δε^p = ε_trial − ε_new, Δλ = f_trial / (G + K η η̄), the trial deviator and the state.
    fn plastic_increment<M: Matrix>(m: &HenckyCriticalState, b: &M, packing: f64) -> (M, f64, M, PointState) {
        let cone = m.cone(packing, M::DIM);
        let tau_trial = kirchhoff(m, b);
        let dlambda = yield_function(m, &tau_trial, packing) / (m.shear + m.bulk * cone.eta * cone.eta_bar);
        let mut state = PointState {
            packing,
            ..Default::default()
        };
        let dt = 2e-5;
        let (b_new, _) = return_map(m, b, &mut state, dt);
        (hencky_strain(b) - hencky_strain(&b_new), dlambda, tau_trial.dev(), state)
    }

    #[test]
    fn plastic_flow_follows_the_potential_and_the_dilatancy() {
        // Analytic (smooth return): Δε^p = Δλ (s / (2√J₂) + η̄/d I), so tr Δε^p = Δλ η̄ and
        // dev Δε^p = Δλ s / (2√J₂) with norm Δλ/√2.
        let m = table2();
        let mut rng = Rng::new(5);
        for packing in [0.79, 0.80, 0.815, 0.83, 0.86] {
            let eta_bar = [m.cone(packing, 2).eta_bar, m.cone(packing, 3).eta_bar];
            for _ in 0..20 {
                // Compression with a larger deviator: outside the cone at every Φ here, yet the
                // (loose) contraction does not push p past the apex, so the return is smooth.
                let (a, c) = (2e-3 * (1.0 + 0.2 * rng.signed()), 1e-3 * rng.signed());
                let e2 = [-1.5e-3 + a, -1.5e-3 - a, 0.0];
                let e3 = [-2e-3 / 3.0 + a, -2e-3 / 3.0 - a + c, -2e-3 / 3.0 - c];
                let check = |dep_tr: f64, dep_dev: f64, dev_err: f64, dlambda: f64, eta_bar: f64| {
                    assert!(dlambda > 0.0);
                    assert!(
                        (dep_tr - dlambda * eta_bar).abs() < 1e-9 * dlambda,
                        "tr Δε^p {dep_tr} vs Δλη̄ {}",
                        dlambda * eta_bar
                    );
                    assert!((dep_dev - dlambda * std::f64::consts::FRAC_1_SQRT_2).abs() < 1e-9 * dlambda);
                    assert!(dev_err < 1e-9 * dlambda, "dev Δε^p not along s: {dev_err}");
                    match packing {
                        p if p > m.packing_cs => assert!(dep_tr > 0.0, "dense must dilate"),
                        p if p < m.packing_cs => assert!(dep_tr < 0.0, "loose must contract"),
                        _ => assert!(dep_tr.abs() < 1e-9 * dlambda, "critical: isochoric"),
                    }
                };
                let b = b2(&rot2(&mut rng), e2);
                let (dep, dlambda, s, _) = plastic_increment(&m, &b, packing);
                let dev_err = (dep.dev() - s * (dlambda / (std::f64::consts::SQRT_2 * s.norm()))).norm();
                check(dep.trace(), dep.dev().norm(), dev_err, dlambda, eta_bar[0]);
                let b = b3(&rot3(&mut rng), e3);
                let (dep, dlambda, s, _) = plastic_increment(&m, &b, packing);
                let dev_err = (dep.dev() - s * (dlambda / (std::f64::consts::SQRT_2 * s.norm()))).norm();
                check(dep.trace(), dep.dev().norm(), dev_err, dlambda, eta_bar[1]);
            }
        }
    }

    #[test]
    fn cohesionless_extension_ends_stress_free() {
        let m = table2();
        let mut rng = Rng::new(3);
        for packing in PACKINGS {
            for _ in 0..20 {
                // Extension in every direction, with or without shear.
                let e = [0, 1, 2].map(|_| 1e-3 * (1.1 + rng.signed()));
                for (b, tau) in [
                    {
                        let b = b2(&rot2(&mut rng), e);
                        let (b, tau) = return_map(
                            &m,
                            &b,
                            &mut PointState {
                                packing,
                                ..Default::default()
                            },
                            1e-5,
                        );
                        ((b - DMat2::IDENTITY).norm(), tau.norm())
                    },
                    {
                        let b = b3(&rot3(&mut rng), e);
                        let (b, tau) = return_map(
                            &m,
                            &b,
                            &mut PointState {
                                packing,
                                ..Default::default()
                            },
                            1e-5,
                        );
                        ((b - DMat3::IDENTITY).norm(), tau.norm())
                    },
                ] {
                    assert!(b < 1e-14 && tau < 1e-6, "Φ {packing}: ‖b − I‖ {b}, ‖τ‖ {tau}");
                }
            }
            // Hydrostatic tension too, where the frictionless cylinder (Φ = 0.70) has f = 0.
            let (_, tau) = return_map(
                &m,
                &isotropic::<DMat3>(1e-4),
                &mut PointState {
                    packing,
                    ..Default::default()
                },
                1e-5,
            );
            assert_eq!(tau, DMat3::ZERO);
        }
    }

    #[test]
    fn cohesion_carries_tension_up_to_the_apex() {
        // Analytic: the apex is p = ζ c / η (= c / tan φ in 2D); p = K tr ε under isotropic strain.
        let m = HenckyCriticalState { cohesion: 1e5, ..table2() };
        for packing in [0.79, 0.815, 0.84, 0.87] {
            let (phi, _) = m.angles(packing);
            for dim in [2, 3] {
                let cone = m.cone(packing, dim);
                let apex = cone.zeta * m.cohesion / cone.eta;
                if dim == 2 {
                    assert!((apex - m.cohesion / phi.tan()).abs() < 1e-9 * apex);
                }
                for ratio in [0.5, 0.99, 1.5, 10.0] {
                    let e = ratio * apex / (m.bulk * dim as f64);
                    let mut state = PointState {
                        packing,
                        ..Default::default()
                    };
                    let (sqrt_j2, p) = if dim == 2 {
                        invariants(&return_map(&m, &isotropic::<DMat2>(e), &mut state, 1e-5).1)
                    } else {
                        invariants(&return_map(&m, &isotropic::<DMat3>(e), &mut state, 1e-5).1)
                    };
                    let want = ratio.min(1.0) * apex;
                    assert!(
                        (p - want).abs() < 1e-9 * apex && sqrt_j2 < 1e-9 * apex,
                        "{dim}D Φ {packing} ratio {ratio}: p {p} vs {want}"
                    );
                    assert_eq!(state.plastic_strain > 0.0, ratio > 1.0);
                }
            }
        }
    }

    #[test]
    fn packing_follows_the_logistic_solution() {
        // Analytic: for a constant rate r, Φ(t) = Φ_cs / (1 + (Φ_cs/Φ₀ − 1) e^(−ξ Φ_cs r t)).
        let m = table2();
        let (rate, dt) = (50.0, 1e-3);
        let logistic = |phi0: f64, t: f64| m.packing_cs / (1.0 + (m.packing_cs / phi0 - 1.0) * (-m.xi * m.packing_cs * rate * t).exp());
        for phi0 in [0.6, 0.9] {
            let mut phi = phi0;
            for step in 1..=10_000 {
                phi = evolve_packing(&m, phi, rate * dt);
                assert_eq!(phi > m.packing_cs, phi0 > m.packing_cs, "crossed Φ_cs at step {step}");
                if step % 1000 == 0 {
                    let want = logistic(phi0, step as f64 * dt);
                    assert!((phi - want).abs() < 1e-12, "step {step}: {phi} vs {want}");
                }
            }
            // RK4 on eq. 8 itself, so the closed form is checked against the ODE too.
            let rhs = |x: f64| -(x - m.packing_cs) * x * m.xi * rate;
            let (mut x, h) = (phi0, 1e-2);
            for _ in 0..1000 {
                let k1 = rhs(x);
                let k2 = rhs(x + 0.5 * h * k1);
                let k3 = rhs(x + 0.5 * h * k2);
                let k4 = rhs(x + h * k3);
                x += h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4);
            }
            assert!((x - phi).abs() < 1e-10, "RK4 {x} vs closed form {phi}");
            // Φ tends to Φ_cs from both sides.
            let far = evolve_packing(&m, phi0, 1e4);
            assert!((far - m.packing_cs).abs() < 1e-12, "{far}");
            assert!((phi - m.packing_cs).abs() < (phi0 - m.packing_cs).abs() * 0.05);
        }
    }

    #[test]
    fn plastic_strain_rate_is_the_increment_norm_over_dt() {
        let m = table2();
        let mut rng = Rng::new(9);
        let dt = 2e-5;
        for packing in PACKINGS {
            let e = [-2e-3, 1e-3, 1.5e-3];
            let b = b2(&rot2(&mut rng), e);
            let (dep, _, _, state) = plastic_increment(&m, &b, packing);
            let norm = dep.norm();
            assert!(norm > 0.0);
            assert!(
                (state.plastic_strain_rate - norm / dt).abs() < 1e-9 * norm / dt,
                "2D {} vs {}",
                state.plastic_strain_rate,
                norm / dt
            );
            assert!((state.plastic_strain - norm).abs() < 1e-9 * norm);
            assert!((state.packing - evolve_packing(&m, packing, norm)).abs() < 1e-15);
            let b = b3(&rot3(&mut rng), e);
            let (dep, _, _, state) = plastic_increment(&m, &b, packing);
            let norm = dep.norm();
            assert!(
                (state.plastic_strain_rate - norm / dt).abs() < 1e-9 * norm / dt,
                "3D {} vs {}",
                state.plastic_strain_rate,
                norm / dt
            );
        }
    }
}
