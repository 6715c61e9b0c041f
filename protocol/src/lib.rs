//! The contract between grains processes.
//!
//! - [`wire`]: the `#[repr(C)]` message types exchanged every macro-step (layouts pinned by
//!   `tests/layout.rs` and written in `protocol/README.md`),
//! - [`names`]: every service name of a run, one function each,
//! - [`checksum`]: the payload checksum carried in [`wire::StepHeader::checksum`],
//! - [`scene`]: scene schema v1 — TOML in, a validated [`scene::Scene`] out, errors that name
//!   the file, line, field and what is allowed.
//!
//! Nothing here moves bytes: the transports live in `grains-transport`.

pub mod checksum;
pub mod names;
pub mod scene;
pub mod wire;

/// Version of the macro-step protocol. Every [`wire::StepHeader`] and every
/// [`wire::Hello`] carries it; the run owner refuses a participant that speaks another one.
pub const PROTOCOL_VERSION: u32 = 1;

/// First field of [`wire::Hello`] and [`wire::Welcome`]: ASCII `GRAINS` + two zero bytes,
/// read as a little-endian `u64`.
pub const HELLO_MAGIC: u64 = u64::from_le_bytes(*b"GRAINS\0\0");

/// A participant of a run. The code is what goes on the wire (`role` fields).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[repr(u32)]
pub enum Role {
    Launcher = 1,
    Dem = 2,
    Mpm = 3,
    Coupler = 4,
    Oracle = 5,
    Bridge = 6,
}

impl Role {
    /// The participants a scene can ask for, in start order.
    pub const PARTICIPANTS: [Role; 4] = [Role::Dem, Role::Mpm, Role::Coupler, Role::Oracle];

    pub fn from_code(code: u32) -> Option<Role> {
        [Role::Launcher, Role::Dem, Role::Mpm, Role::Coupler, Role::Oracle, Role::Bridge]
            .into_iter()
            .find(|r| *r as u32 == code)
    }

    /// Short name used in scene files, service names and messages (`dem`, `mpm`, …).
    pub fn name(self) -> &'static str {
        match self {
            Role::Launcher => "launcher",
            Role::Dem => "dem",
            Role::Mpm => "mpm",
            Role::Coupler => "coupler",
            Role::Oracle => "oracle",
            Role::Bridge => "bridge",
        }
    }

    /// Name of the binary that plays this role (`grains-dem`, …).
    pub fn binary(self) -> &'static str {
        match self {
            Role::Launcher => "grains",
            Role::Dem => "grains-dem",
            Role::Mpm => "grains-mpm",
            Role::Coupler => "grains-coupler",
            Role::Oracle => "grains-oracle",
            Role::Bridge => "grains-bridge",
        }
    }

    pub fn from_name(name: &str) -> Option<Role> {
        [Role::Launcher, Role::Dem, Role::Mpm, Role::Coupler, Role::Oracle, Role::Bridge]
            .into_iter()
            .find(|r| r.name() == name)
    }
}

impl std::fmt::Display for Role {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// A run id as it travels in headers: ASCII, zero-padded to 32 bytes.
pub fn run_id_bytes(run_id: &str) -> [u8; 32] {
    let mut out = [0u8; 32];
    let n = run_id.len().min(32);
    out[..n].copy_from_slice(&run_id.as_bytes()[..n]);
    out
}

/// The inverse of [`run_id_bytes`] (invalid UTF-8 is replaced, so that a message can say what
/// it received).
pub fn run_id_str(bytes: &[u8; 32]) -> String {
    let end = bytes.iter().position(|&b| b == 0).unwrap_or(32);
    String::from_utf8_lossy(&bytes[..end]).into_owned()
}

/// A number for a message: as written when that is short (`-9.81`, `0.0005`), in scientific
/// notation when it is very large or small (`1e308`, not a 309-digit integer).
pub fn number(x: f64) -> String {
    if x != 0.0 && x.is_finite() && !(1e-4..1e7).contains(&x.abs()) {
        format!("{x:e}")
    } else {
        format!("{x}")
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn numbers_in_messages_stay_short() {
        assert_eq!(super::number(1e308), "1e308");
        assert_eq!(super::number(-2.5e-9), "-2.5e-9");
        assert_eq!(super::number(-9.81), "-9.81");
        assert_eq!(super::number(0.0), "0");
        assert_eq!(super::number(1e6), "1000000");
    }
}
