//! The `grains` command as a library: [`run`] (one run from scene to outputs, over processes
//! or threads), [`participants`] (children and threads behind one trait), [`outputs`]
//! (metrics and summary, atomic), [`bridge`] (the optional zenoh bridge of a run), [`bench`]
//! (transport benchmarks).

pub mod bench;
pub mod bench_dem;
pub mod bench_hybrid;
pub mod bench_mpm;
pub mod bridge;
pub mod chart;
pub mod outputs;
pub mod pack;
pub mod participants;
pub mod report;
pub mod run;
pub mod validate;
pub mod validate_cost;
pub mod validate_drum;
pub mod validate_silo;
pub mod validate_stability;

/// Exit code for an error of `grains`: 2 for bad input (scene, flags), 1 otherwise.
pub fn exit_code(err: &anyhow::Error) -> u8 {
    if err.downcast_ref::<grains_protocol::scene::SceneError>().is_some() || err.downcast_ref::<run::BadInput>().is_some() {
        2
    } else {
        1
    }
}
