//! Admission of participants: the launcher's answer to each hello (protocol version, scene,
//! role), and what it learned of them for `summary.json`.

use super::RunCtx;
use super::participants::Participants;
use grains_protocol::wire::{HELLO_READY, Hello, Verdict, Welcome};
use grains_protocol::{HELLO_MAGIC, PROTOCOL_VERSION, Role, run_id_bytes};
use std::collections::{BTreeMap, BTreeSet};

/// What the launcher learned about the participants, for `summary.json`.
#[derive(Default)]
pub struct Roster {
    pub admitted: BTreeMap<Role, u32>,
    pub ready: BTreeSet<Role>,
    pub exits: BTreeMap<Role, String>,
}

/// Decides on one hello; returns the answer to send (none for the "ready" hello).
pub fn admit(h: &Hello, ctx: &RunCtx, roster: &mut Roster) -> Option<Welcome> {
    if h.magic != HELLO_MAGIC {
        tracing::warn!("ignored a hello without the grains magic (pid {})", h.pid);
        return None;
    }
    let role = Role::from_code(h.role);
    let who = role.map_or_else(|| format!("participant with role code {}", h.role), |r| r.binary().to_string());
    let verdict = if h.protocol_version != PROTOCOL_VERSION {
        tracing::warn!(
            "refused {who} (pid {}): it speaks protocol version {}, this run speaks version {PROTOCOL_VERSION}",
            h.pid,
            h.protocol_version
        );
        Verdict::WrongProtocolVersion
    } else if h.scene_hash != ctx.scene.hash {
        tracing::warn!(
            "refused {who} (pid {}): it loaded another scene file than {}",
            h.pid,
            ctx.scene_path.display()
        );
        Verdict::WrongScene
    } else if role.is_none_or(|r| !ctx.roles.contains(&r)) {
        tracing::warn!("refused {who} (pid {}): the scene has no such participant", h.pid);
        Verdict::RoleNotInRun
    } else {
        let role = role.expect("checked above");
        match roster.admitted.get(&role) {
            Some(&pid) if pid != h.pid => {
                tracing::warn!("refused {who} (pid {}): {who} (pid {pid}) has already joined", h.pid);
                Verdict::RoleTaken
            }
            _ if h.flags == HELLO_READY => {
                roster.ready.insert(role);
                return None;
            }
            _ => {
                if ctx.opts.external.contains(&role) {
                    tracing::info!("external {who} (pid {}) attached", h.pid);
                }
                roster.admitted.insert(role, h.pid);
                Verdict::Accepted
            }
        }
    };
    Some(Welcome {
        magic: HELLO_MAGIC,
        scene_hash: ctx.scene.hash,
        protocol_version: PROTOCOL_VERSION,
        role: h.role,
        pid: h.pid,
        verdict: verdict as u32,
        run_id: run_id_bytes(ctx.run_id),
    })
}

pub fn roster_json(roster: &Roster, parts: &dyn Participants, ctx: &RunCtx) -> serde_json::Value {
    let spawned = parts.pids();
    let list: Vec<_> = ctx
        .roles
        .iter()
        .map(|r| {
            serde_json::json!({
                "role": r.name(),
                "binary": r.binary(),
                "pid": roster.admitted.get(r).copied().or_else(|| spawned.iter().find(|(x, _)| x == r).map(|(_, p)| *p)),
                "external": ctx.opts.external.contains(r),
                "exit": roster.exits.get(r),
            })
        })
        .collect();
    serde_json::Value::Array(list)
}
