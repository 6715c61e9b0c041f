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

/// xorshift64 for the unit tests: reproducible "random-ish" numbers in [−1, 1) without a
/// dependency.
#[cfg(test)]
mod test_rng {
    pub struct Rng(pub u64);
    impl Rng {
        pub fn next(&mut self) -> f64 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            (self.0 >> 11) as f64 / (1u64 << 52) as f64 - 1.0
        }
    }
}
