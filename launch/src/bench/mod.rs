//! `grains bench`: figures that say how fast grains is, each measured side by side in one run
//! (two codes, two transports, two models) so that a shared machine's noise cancels in the
//! ratio: [`ipc`] (transport cost per macro-step, iceoryx2 processes against threads),
//! [`dem`] (µs per grain-step beside LAMMPS), [`mpm`] (µs per point-step beside Taichi),
//! [`hybrid`] (the hybrid column against the pure DEM one). [`machine`] measures the
//! machine itself.

pub mod dem;
pub mod hybrid;
pub mod ipc;
pub mod machine;
pub mod mpm;
