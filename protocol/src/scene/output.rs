//! `[output]`: what a run writes besides its metrics.

use super::raw::RawOutput;

#[derive(Clone, Debug, PartialEq)]
pub struct Output {
    /// Macro-steps between VTU frames; 0 writes none.
    pub frames_every: u64,
    /// Macro-steps between checkpoints (`<run dir>/checkpoints/`, for `grains resume`); 0
    /// writes none.
    pub checkpoint_every: u64,
}

pub(super) fn validate(raw: Option<&RawOutput>) -> Output {
    Output {
        frames_every: raw.and_then(|o| o.frames_every).unwrap_or(0),
        checkpoint_every: raw.and_then(|o| o.checkpoint_every).unwrap_or(0),
    }
}
