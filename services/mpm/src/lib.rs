//! MPM of grains (issue 4, in progress). This build has the constitutive kernels only:
//!
//! - [`matrix`]: the few 2×2 / 3×3 operations the models need, on glam `DMat2`/`DMat3`;
//! - [`constitutive::plasticity_drucker_prager`]: Yue 2018's `b^e` elasticity (eqs. 9–10),
//!   Drucker–Prager yield (eq. 11), volume-preserving return mapping (eqs. 12–17, Cardano in
//!   3D) and free flow under extension.
//!
//! Transfers (P2G/G2P over `grains-grid`), the two-phase step and the service come next.

pub mod constitutive;
pub mod matrix;
