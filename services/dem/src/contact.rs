//! Contact kernels (Cundall & Strack 1979 as in Yue 2018 §3.2; cohesion as in Chen 2021 §2.1).
//!
//! Symbols: overlap δ [m] (> 0 in contact), unit normal n pointing from the other body to this
//! grain, relative velocity of the contact points v_rel = v_this − v_other [m/s], normal
//! velocity v_n = v_rel·n (< 0 approaching), tangential velocity v_t = v_rel − v_n n.
//!
//! - Normal: f_n = k_n δ − γ_n v_n along n, *not* clamped at zero, so that the linear
//!   spring–dashpot gives exactly the restitution its damping was derived from.
//! - Damping, γ_t = γ_n (Kamrin & Koval 2014 heuristics), either from a restitution
//!   coefficient e: γ = −2 ln e √(m k_n / (π² + ln² e)), with m the **reduced mass of the
//!   pair** m_i m_j/(m_i + m_j) (the grain's own mass against a wall), which is the mass of the
//!   two-body oscillator, so a head-on impact rebounds at exactly e (Yue 2018 and Chen 2021
//!   write the mean grain mass; for equal grains that is twice the reduced mass and gives a
//!   larger e than asked); or a constant γ [N s/m] as in Chen 2021 Table 1 and LAMMPS
//!   `granular ... damping velocity`.
//! - Tangential anchor spring Δs: Δs ← Δs + v_t dt, its normal component projected out;
//!   f_t = −k_t Δs − γ_t v_t; when |f_t| > μ|f_n| + e_t, f_t is scaled back to the cap and Δs
//!   is rescaled to match (k_t Δs = −f_t), which is the Coulomb slip of the anchor.
//! - Cohesion (bonds only after contact): a bonded pair keeps the normal law in tension while
//!   −k_n δ < e_n; beyond that the bond breaks and the pair is free until it touches again.

use crate::space::{Space, Vector};

/// Contact law parameters of a material [SI].
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ContactParams {
    /// Normal stiffness k_n [N/m].
    pub stiffness_normal: f64,
    /// Tangential stiffness k_t [N/m].
    pub stiffness_tangential: f64,
    /// How contacts dissipate.
    pub damping: Damping,
    /// Coulomb friction coefficient μ.
    pub friction: f64,
    /// Normal cohesion e_n [N] (the tensile force a bond holds).
    pub cohesion_normal: f64,
    /// Tangential cohesion e_t [N] (added to the Coulomb cap).
    pub cohesion_tangential: f64,
    /// Multiplies the damping derived from a restitution e > 0: 1, except to inject a fault
    /// (a deliberately broken contact law, for the test that shows `grains validate --quick`
    /// failing; the services read it once from the environment,
    /// `grains_service::fault::restitution_damping_scale`).
    pub damping_scale: f64,
}

/// Normal (and tangential) damping of a contact.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum Damping {
    /// From the restitution coefficient e ∈ [0, 1] (0: critically damped) and the pair's
    /// reduced mass.
    Restitution(f64),
    /// A constant coefficient γ [N s/m].
    Viscous(f64),
}

impl ContactParams {
    /// Damping coefficient γ [N s/m] of a pair of reduced mass `m_red` [kg].
    #[inline]
    pub fn gamma(&self, factor: f64, m_red: f64) -> f64 {
        match self.damping {
            Damping::Restitution(_) => factor * m_red.sqrt(),
            Damping::Viscous(g) => g,
        }
    }

    /// The mass-independent part of γ, computed once per material: γ/√m for restitution
    /// (times [`ContactParams::damping_scale`] for e > 0).
    pub fn damping_factor(&self) -> f64 {
        match self.damping {
            // e = 0 (critical damping) is not scaled: the fault doubles the damping of e > 0.
            Damping::Restitution(e) if e == 0.0 => damping_factor(e, self.stiffness_normal),
            Damping::Restitution(e) => damping_factor(e, self.stiffness_normal) * self.damping_scale,
            Damping::Viscous(_) => 0.0,
        }
    }

    /// Restitution of a head-on impact of a pair of reduced mass `m_red` (inverts the
    /// formula for viscous damping; 0 when overdamped).
    pub fn restitution(&self, m_red: f64) -> f64 {
        match self.damping {
            Damping::Restitution(e) => e,
            Damping::Viscous(g) => {
                let zeta = g / (2.0 * (self.stiffness_normal * m_red).sqrt());
                if zeta >= 1.0 {
                    0.0
                } else {
                    (-std::f64::consts::PI * zeta / (1.0 - zeta * zeta).sqrt()).exp()
                }
            }
        }
    }
}

/// γ_n / √m for restitution e and stiffness k [N/m]: −2 ln e √(k / (π² + ln² e)).
pub fn damping_factor(restitution: f64, stiffness: f64) -> f64 {
    if restitution == 0.0 {
        // The limit e → 0: critical damping, γ = 2 √(m k).
        return 2.0 * stiffness.sqrt();
    }
    let ln_e = restitution.ln();
    -2.0 * ln_e * (stiffness / (std::f64::consts::PI.powi(2) + ln_e * ln_e)).sqrt()
}

/// Reduced mass of a pair [kg]; a wall or a frozen grain (infinite mass) is `f64::INFINITY`,
/// on either side (∞ · m / ∞ would be NaN).
#[inline]
pub fn reduced_mass(m_i: f64, m_j: f64) -> f64 {
    if m_j.is_infinite() {
        m_i
    } else if m_i.is_infinite() {
        m_j
    } else {
        m_i * m_j / (m_i + m_j)
    }
}

/// History of one contact: the tangential anchor spring and whether a cohesive bond holds.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ContactState<V> {
    pub spring: V,
    pub bonded: bool,
}

/// Result of one contact evaluation: the force on "this" grain (the other body gets the
/// opposite), with its normal part for stress and wall-load accounting.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ContactForce<V> {
    pub force: V,
    pub normal_force: f64,
    pub active: bool,
}

/// Evaluates one contact and advances its history by dt.
///
/// `scale` multiplies the springs (hybrid weighting, 1 − w); `gamma` is the pair's damping
/// coefficient γ = damping_factor · √m_red (already scaled).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub fn contact_force<S: Space>(
    p: &ContactParams,
    overlap: f64,
    n: S::V,
    v_rel: S::V,
    gamma: f64,
    scale: f64,
    dt: f64,
    state: &mut ContactState<S::V>,
) -> ContactForce<S::V> {
    let kn = p.stiffness_normal * scale;
    let in_contact = overlap > 0.0;
    let holds_bond = state.bonded && p.cohesion_normal > 0.0 && -kn * overlap < p.cohesion_normal * scale;
    if !in_contact && !holds_bond {
        *state = ContactState::default();
        return ContactForce::default();
    }
    if in_contact && p.cohesion_normal > 0.0 {
        state.bonded = true;
    }
    let vn = v_rel.dot(n);
    let fn_mag = kn * overlap - gamma * vn;
    let vt = v_rel - n * vn;

    // Anchor spring: integrate, remove the normal part (the contact plane turns).
    let mut spring = state.spring + vt * dt;
    spring -= n * spring.dot(n);
    let kt = p.stiffness_tangential * scale;
    let mut ft = spring * (-kt) - vt * gamma;
    let cap = p.friction * fn_mag.abs() + p.cohesion_tangential * scale;
    let ft_len2 = ft.length_squared();
    if ft_len2 > cap * cap {
        // Slip: the force sits on the cap, the anchor moves so that the spring alone carries it.
        // (Squared lengths first: the square root is only needed when sliding.)
        ft = ft * (cap / ft_len2.sqrt());
        spring = if kt > 0.0 { ft * (-1.0 / kt) } else { spring };
    }
    state.spring = spring;
    ContactForce {
        force: n * fn_mag + ft,
        normal_force: fn_mag,
        active: true,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::space::D2;
    use glam::DVec2;

    fn params(mu: f64) -> ContactParams {
        ContactParams {
            stiffness_normal: 1e5,
            stiffness_tangential: 5e4,
            damping: Damping::Restitution(0.5),
            friction: mu,
            cohesion_normal: 0.0,
            cohesion_tangential: 0.0,
            damping_scale: 1.0,
        }
    }

    #[test]
    fn no_force_apart_and_history_reset() {
        let mut st = ContactState {
            spring: DVec2::X,
            bonded: false,
        };
        let f = contact_force::<D2>(&params(0.5), -1e-6, DVec2::Y, DVec2::ZERO, 1.0, 1.0, 1e-6, &mut st);
        assert!(!f.active);
        assert_eq!(st, ContactState::default());
    }

    #[test]
    fn coulomb_cap_holds_and_spring_matches_the_force() {
        let p = params(0.3);
        let mut st = ContactState {
            spring: DVec2::new(1e-3, 0.0),
            bonded: false,
        };
        let f = contact_force::<D2>(&p, 1e-5, DVec2::Y, DVec2::new(1.0, 0.0), 0.0, 1.0, 1e-6, &mut st);
        let ft = f.force.x;
        assert!((ft.abs() - 0.3 * f.normal_force).abs() < 1e-12, "{f:?}");
        assert!((st.spring.x * -p.stiffness_tangential - ft).abs() < 1e-12);
        assert!(ft < 0.0, "friction opposes sliding");
    }

    #[test]
    fn a_bond_holds_in_tension_up_to_its_strength() {
        let mut p = params(0.5);
        p.cohesion_normal = 1.0;
        let mut st = ContactState::default();
        contact_force::<D2>(&p, 1e-6, DVec2::Y, DVec2::ZERO, 0.0, 1.0, 1e-6, &mut st);
        assert!(st.bonded);
        // k_n δ = −0.5 N: within the bond, pulls back.
        let f = contact_force::<D2>(&p, -5e-6, DVec2::Y, DVec2::ZERO, 0.0, 1.0, 1e-6, &mut st);
        assert!(f.active && (f.normal_force + 0.5).abs() < 1e-12, "{f:?}");
        // k_n δ = −1.5 N: the bond breaks.
        let f = contact_force::<D2>(&p, -1.5e-5, DVec2::Y, DVec2::ZERO, 0.0, 1.0, 1e-6, &mut st);
        assert!(!f.active && !st.bonded);
        // Never bonded: no tension at all.
        let f = contact_force::<D2>(&p, -5e-6, DVec2::Y, DVec2::ZERO, 0.0, 1.0, 1e-6, &mut ContactState::default());
        assert!(!f.active);
    }

    /// The fault-injection knob scales the damping of a restitution e > 0 and nothing else.
    #[test]
    fn damping_scale_multiplies_the_restitution_damping() {
        let mut p = params(0.5);
        let base = p.damping_factor();
        p.damping_scale = 2.0;
        assert_eq!(p.damping_factor(), 2.0 * base);
        assert_eq!(base, damping_factor(0.5, p.stiffness_normal));
        p.damping = Damping::Restitution(0.0);
        assert_eq!(p.damping_factor(), damping_factor(0.0, p.stiffness_normal));
        p.damping = Damping::Viscous(3.0);
        assert_eq!(p.gamma(p.damping_factor(), 1.0), 3.0);
    }

    #[test]
    fn damping_vanishes_for_elastic_contacts() {
        assert_eq!(damping_factor(1.0, 1e5), 0.0);
        assert!(damping_factor(0.1, 1e5) > damping_factor(0.9, 1e5));
    }
}
