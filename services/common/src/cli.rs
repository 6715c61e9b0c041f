//! Flags every participant binary shares (flattened into each binary's `Cli`).

use std::path::PathBuf;
use std::time::Duration;

#[derive(Debug, Clone, clap::Args)]
pub struct CommonArgs {
    /// Scene file of the run (the same file the launcher loaded).
    #[arg(long)]
    pub scene: PathBuf,
    /// Run id to join (printed by `grains run`).
    #[arg(long)]
    pub run_id: String,
    /// Seconds to wait for the launcher and the peers to connect; 0 waits without limit
    /// (used while a run waits for an external participant).
    #[arg(long, default_value_t = 60.0)]
    pub connect_timeout: f64,
    /// The run's output directory: frames are written under it (none if not given).
    #[arg(long)]
    pub out_dir: Option<PathBuf>,
    /// Join over zenoh, as a client of the launcher's router at this endpoint
    /// (`grains run --transport zenoh` prints it), instead of over iceoryx2 shared memory:
    /// a participant on another host.
    #[arg(long, value_name = "ENDPOINT")]
    pub zenoh: Option<String>,
    /// Resume from this checkpoint directory (`<run dir>/checkpoints/<step>`, one with a
    /// `manifest.json`): the state of this participant's file there, then the next step.
    #[arg(long)]
    pub resume: Option<PathBuf>,
    /// Test hook: announce this protocol version instead of the one built in, to check that a
    /// run refuses a participant of another version.
    #[arg(long, hide = true)]
    pub claim_protocol_version: Option<u32>,
}

impl CommonArgs {
    pub fn connect_timeout(&self) -> Option<Duration> {
        (self.connect_timeout > 0.0).then(|| Duration::from_secs_f64(self.connect_timeout))
    }
}
