//! MPM of grains (issue 4, in progress):
//!
//! - [`matrix`]: the few 2×2 / 3×3 operations the models need, on glam `DMat2`/`DMat3`;
//! - [`constitutive::plasticity_drucker_prager`]: Yue 2018's `b^e` elasticity (eqs. 9–10),
//!   Drucker–Prager yield (eq. 11), volume-preserving return mapping (eqs. 12–17, Cardano in
//!   3D) and free flow under extension;
//! - [`pipeline`]: the explicit step in two phases (Alg. 20/21) over a dense grid with GIMP or
//!   quadratic B-spline weights from `grains-grid`, PIC/FLIP or APIC.
//!
//! Not yet: Chen 2021's Hencky / critical-state model, sparse grid blocks, rayon,
//! traction boundaries, the stability checks and the service.

pub mod constitutive;
pub mod matrix;
pub mod pipeline;
