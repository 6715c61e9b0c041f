//! The `grains` command as a library, by what a reader comes for:
//!
//! - [`run`]: one run from scene to outputs, over processes or threads (participants,
//!   admission, supervision, the bridge of a run, progress, outputs);
//! - [`metrics`]: `metrics.csv`, written and read back in one place;
//! - [`validate`]: `grains validate`, its registry of parts and the report they write
//!   ([`report`]: markdown, checks and charts);
//! - [`bench`]: `grains bench`, figures measured side by side;
//! - [`render`]: `grains render`, a picture of a frame;
//! - [`calibrate`]: `grains calibrate`, the continuum's parameters from a DEM element test;
//! - [`cost`]: what a hybrid scene and its pure DEM will cost, from measured costs;
//! - [`pack`], [`remote`], [`clock`]: `grains pack`, the remote clients' glue, calendar dates.
//!
//! Nothing here depends on what depends on it: `validate` and `bench` use `run`, never the
//! other way round.

pub mod bench;
pub mod calibrate;
pub mod clock;
pub mod cost;
pub mod metrics;
pub mod pack;
pub mod remote;
pub mod render;
pub mod report;
pub mod run;
pub mod validate;

/// Exit code for an error of `grains`: 2 for bad input (scene, flags), 1 otherwise.
pub fn exit_code(err: &anyhow::Error) -> u8 {
    if err.downcast_ref::<grains_protocol::scene::SceneError>().is_some() || err.downcast_ref::<run::BadInput>().is_some() {
        2
    } else {
        1
    }
}
