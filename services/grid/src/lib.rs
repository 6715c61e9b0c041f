//! Shared numerics of grains, in one place for every service (DESIGN §3):
//!
//! - [`space`]: the dimension as a type (`D2`, `D3`) over glam vectors, so that 2D and 3D
//!   share kernels;
//! - [`shape`]: the background grid and its shape functions — GIMP (Bardenhagen & Kober 2004,
//!   as Yue 2018 §3.4 uses it, particle width = cell width / points per cell) and quadratic
//!   B-splines — through which the MPM transfers, and the DEM and the coupler rasterize;
//! - [`gradient`]: a velocity field's gradient, its spin and its shear rate (the DEM's band
//!   grains, the oracle), and the inertial number of a rate (the oracle, the MPM's μ(I));
//! - [`homogenize`]: the grains' stress on the grid from their contacts (Yue 2018 Alg. 11),
//!   computed by the DEM for the oracle's new material points;
//! - [`polygon`]: where a point is against a simple polygon, convex or not (nearest point,
//!   signed distance, the faces and corners a disk touches);
//! - [`reach`]: which disks lie within reach of which circles (the rigid bodies' broad phase,
//!   for the DEM's grains and the MPM's contact points alike);
//! - [`rng`]: seeded SplitMix64 randomness and the polydisperse radius draw, for the DEM's
//!   packings, the oracle's new grains and the synthetic rasters.

pub mod gradient;
pub mod homogenize;
pub mod polygon;
pub mod reach;
pub mod rng;
pub mod shape;
pub mod space;

pub use shape::{Grid, Kernel};
pub use space::{D2, D3, Space, Vector};
