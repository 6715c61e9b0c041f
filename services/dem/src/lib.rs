//! DEM of grains: 2D disks and 3D spheres (Yue 2018 §3.2, Chen 2021 §2.1).
//!
//! - [`space`] (from `grains-grid`): the dimension as a type ([`space::D2`], [`space::D3`]) so
//!   2D and 3D share kernels;
//! - [`state`]: plain data — [`state::Grains`] (structure of arrays), walls, domain, parameters;
//! - [`bodies`]: rigid spheropolygons (2D, Jiang 2020 §3): shapes, mass properties,
//!   vertex–edge contacts with each other, the grains and the walls;
//! - [`contact`]: the contact law kernels (normal spring–dashpot from restitution, tangential
//!   anchor spring with the Coulomb cap, cohesion);
//! - [`neighbors`]: cell lists → Verlet list with a skin, history carried by grain ids;
//! - [`pipeline`]: the velocity-Verlet step over all of it, parallel and deterministic;
//! - [`packing`]: initial placements (seeded jittered lattices; the radii are drawn with
//!   `grains_grid::rng`);
//! - [`coupling`]: the kernels of the DEM side of the grid-vs-grid coupling (Yue 2018 Alg. 4–5);
//! - [`fluid`]: a confining fluid's pressure on a packing's surface, on a grid as the MPM's;
//! - [`training`]: kinematic training of a packing through a continuum's deformation history
//!   by its boundary (Chen 2021 §4.1.1);
//! - [`coupled`]: the DEM half of a coupled macro-step over them (Alg. 2, 4–6), split at the
//!   coupling point: [`coupled::CoupledStep`].
//!
//! No I/O, no transport, no wall clock: the service wraps it.

pub mod bodies;
pub mod contact;
pub mod coupled;
pub mod coupling;
pub mod fluid;
pub mod neighbors;
pub mod packing;
pub mod pipeline;
pub mod state;
pub mod training;

/// The dimension as a type, shared with every service (`grains-grid`).
pub use grains_grid::space;

pub use contact::ContactParams;
pub use coupled::{CoupledStep, CouplingParams, GrainTransfer};
pub use pipeline::DemPipeline;
pub use space::{D2, D3, Space};
pub use state::{DemParams, DemState, Domain, Grains, Wall, WallShape};
