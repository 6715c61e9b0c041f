//! MPM of grains: an elastoplastic granular continuum in 2D and 3D, as plain functions over
//! plain data (no I/O, no transport).
//!
//! - [`points`]: material points (structure of arrays), seeding from boxes and balls, confining
//!   loads;
//! - [`sparse`]: the sparse block grid (memory follows the material);
//! - [`boundary`]: sticky, slip, frictional and moving walls on grid nodes;
//! - [`pipeline`]: the explicit step in two phases (Yue 2018 Alg. 20/21) with GIMP or quadratic
//!   B-spline weights from `grains-grid`, PIC/FLIP or APIC, on a rayon pool; NaN and
//!   out-of-domain checks naming the phase; the CFL limit;
//! - [`constitutive`]: Yue 2018's `b^e` elasticity with Drucker–Prager and a volume-preserving
//!   return (eqs. 9–17), Chen 2021's Hencky elasticity with cohesive Drucker–Prager and
//!   critical-state softening (eqs. 4–8);
//! - [`matrix`]: the few 2×2 / 3×3 operations the models need, on glam `DMat2`/`DMat3`.

pub mod boundary;
pub mod constitutive;
pub mod matrix;
pub mod pipeline;
pub mod points;
pub mod sparse;
