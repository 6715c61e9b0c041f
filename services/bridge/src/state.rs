//! The run's state as remote clients see it: the participants' per-step summaries gathered
//! into one JSON document per macro-step.

use grains_protocol::Role;
use grains_protocol::wire::{StepHeader, Summary, ViewPoint};
use serde_json::{Value, json};
use std::collections::{BTreeMap, VecDeque};
use std::time::Instant;

/// Gathers summaries until every participant of a step has reported.
pub struct Gather {
    roles: Vec<Role>,
    partial: BTreeMap<u64, Vec<Summary>>,
    /// The last complete step, and when it completed.
    latest: Option<(Vec<Summary>, Instant)>,
    /// (step, when) of the complete steps of the last few seconds, oldest first, for steps/s
    /// (thousands at thousands of steps a second: dropped from the front, not scanned).
    recent: VecDeque<(u64, Instant)>,
}

impl Gather {
    pub fn new(roles: &[Role]) -> Self {
        Gather {
            roles: roles.to_vec(),
            partial: BTreeMap::new(),
            latest: None,
            recent: VecDeque::new(),
        }
    }

    /// Adds one summary; returns whether it completed a step newer than the latest.
    pub fn add(&mut self, s: Summary) -> bool {
        if self.latest.as_ref().is_some_and(|(l, _)| l[0].step >= s.step) {
            return false;
        }
        let entry = self.partial.entry(s.step).or_default();
        entry.retain(|x| x.role != s.role);
        entry.push(s);
        if entry.len() < self.roles.len() {
            return false;
        }
        let mut done = self.partial.remove(&s.step).unwrap_or_default();
        done.sort_by_key(|x| x.role);
        self.partial.retain(|&k, _| k > s.step);
        let now = Instant::now();
        self.recent.push_back((s.step, now));
        while self
            .recent
            .front()
            .is_some_and(|(_, t)| now.duration_since(*t).as_secs_f64() >= 5.0)
        {
            self.recent.pop_front();
        }
        self.latest = Some((done, now));
        true
    }

    pub fn latest_step(&self) -> Option<u64> {
        self.latest.as_ref().map(|(l, _)| l[0].step)
    }

    /// Macro-steps per second over the last few seconds up to now (so that it falls to 0
    /// while the run is paused; 0 before two steps are known).
    pub fn steps_per_second(&self) -> f64 {
        match (self.recent.front(), self.recent.back()) {
            (Some((s0, t0)), Some((s1, t1))) if s1 > s0 => {
                let span = t1.duration_since(*t0).as_secs_f64();
                let idle = t1.elapsed().as_secs_f64();
                // Steps arrive in bursts between summaries: only a pause longer than the
                // window between them counts as idle time.
                let idle = if idle > 1.0 { idle } else { 0.0 };
                (s1 - s0) as f64 / (span + idle).max(1e-9)
            }
            _ => 0.0,
        }
    }

    /// The summary document of the latest complete step (`None` before the first).
    pub fn document(&self, run_id: &str, scene: &str, steps: u64, paused: bool) -> Option<Value> {
        let (list, _) = self.latest.as_ref()?;
        Some(document(list, run_id, scene, steps, paused, self.steps_per_second()))
    }
}

/// One step's summaries as a JSON object (keys documented in `protocol/README.md` §9).
pub fn document(list: &[Summary], run_id: &str, scene: &str, steps: u64, paused: bool, steps_per_s: f64) -> Value {
    let step = list.first().map_or(0, |s| s.step);
    let time = list.first().map_or(0.0, |s| s.time);
    let items = |role: Role| list.iter().find(|s| s.role == role as u32).map(|s| s.n_items);
    // Energy, mass and momentum of the material: the solvers' (the coupler and oracle carry
    // node and cell counts).
    let solvers = list.iter().filter(|s| s.role == Role::Dem as u32 || s.role == Role::Mpm as u32);
    let mut momentum = [0.0; 3];
    let (mut ke, mut mass) = (0.0, 0.0);
    for s in solvers {
        ke += s.kinetic_energy;
        mass += s.mass;
        for (total, p) in momentum.iter_mut().zip(s.momentum) {
            *total += p;
        }
    }
    let participants: serde_json::Map<String, Value> = list
        .iter()
        .map(|s| {
            let name = Role::from_code(s.role).map_or("unknown", Role::name);
            (
                name.to_string(),
                json!({
                    "items": s.n_items,
                    "nodes": s.n_nodes,
                    "mass": s.mass,
                    "momentum": s.momentum,
                    "kinetic_energy": s.kinetic_energy,
                    "compute_ms": s.compute_ns as f64 * 1e-6,
                    "wait_ms": s.wait_ns as f64 * 1e-6,
                    "status": if s.status == 0 { "ok" } else { "failed" },
                }),
            )
        })
        .collect();
    json!({
        "run": run_id,
        "scene": scene,
        "step": step,
        "steps": steps,
        "time": time,
        "paused": paused,
        "grains": items(Role::Dem),
        "points": items(Role::Mpm),
        "zone_nodes": items(Role::Coupler),
        "zone_cells": items(Role::Oracle),
        "kinetic_energy": ke,
        "mass": mass,
        "momentum": momentum,
        "steps_per_s": steps_per_s,
        "participants": participants,
    })
}

/// A solver's view (decimated grains or points) as JSON: positions, velocities and sizes in
/// single precision (enough to draw), the step, and how many the solver has in all.
pub fn view_document(run: &str, role: Role, header: &StepHeader, points: &[ViewPoint]) -> Value {
    let f32s = |a: &[f64; 3]| [a[0] as f32, a[1] as f32, a[2] as f32];
    json!({
        "run": run,
        "role": role.name(),
        "step": header.step,
        "time": header.time,
        "total": header.flags,
        "count": points.len(),
        "id": points.iter().map(|p| p.id).collect::<Vec<_>>(),
        "position": points.iter().map(|p| f32s(&p.position)).collect::<Vec<_>>(),
        "velocity": points.iter().map(|p| f32s(&p.velocity)).collect::<Vec<_>>(),
        "size": points.iter().map(|p| p.size as f32).collect::<Vec<_>>(),
        // NaN (not said) is null.
        "pressure": points.iter().map(|p| p.pressure.is_finite().then_some(p.pressure as f32)).collect::<Vec<_>>(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn summary(role: Role, step: u64, items: u64, ke: f64) -> Summary {
        Summary {
            role: role as u32,
            step,
            time: step as f64 * 1e-3,
            n_items: items,
            kinetic_energy: ke,
            mass: 1.0,
            momentum: [0.5, -1.0, 0.0],
            ..Summary::default()
        }
    }

    #[test]
    fn a_step_completes_when_every_participant_reported() {
        let mut g = Gather::new(&[Role::Dem, Role::Mpm, Role::Coupler]);
        assert!(!g.add(summary(Role::Dem, 1, 10, 1.0)));
        assert!(!g.add(summary(Role::Mpm, 1, 20, 2.0)));
        assert!(!g.add(summary(Role::Dem, 2, 10, 1.0)));
        assert!(g.add(summary(Role::Coupler, 1, 5, 0.0)));
        let doc = g.document("r", "s", 100, false).unwrap();
        assert_eq!(doc["step"], 1);
        assert_eq!(doc["grains"], 10);
        assert_eq!(doc["points"], 20);
        assert_eq!(doc["zone_nodes"], 5);
        assert_eq!(doc["kinetic_energy"], 3.0);
        assert_eq!(doc["momentum"][1], -2.0);
        assert_eq!(doc["participants"]["mpm"]["items"], 20);
        // A late summary of a step already shown changes nothing.
        assert!(!g.add(summary(Role::Mpm, 1, 99, 9.0)));
        assert_eq!(g.latest_step(), Some(1));
    }
}
