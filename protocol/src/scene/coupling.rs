//! `[coupling]`: how the DEM and the MPM meet in a hybrid body.

use super::errors::{
    Bound::{self, Closed, Open},
    Ctx, SceneError, in_range,
};
use super::raw::RawCoupling;
use crate::number;

#[derive(Clone, Debug, PartialEq)]
pub struct Coupling {
    /// DEM substeps per macro-step k (Yue 2018 Alg. 2). With [`Coupling::auto`] a placeholder
    /// (1) until the launcher resolves it.
    pub substeps: u32,
    /// `substeps = "auto"`: the launcher picks k and the macro-step from the solvers' stable
    /// steps ([`AutoSteps`]) and writes them into the run's copy of the scene; a participant
    /// never runs an unresolved scene.
    pub auto: Option<AutoSteps>,
    /// MPM share w of the mass in the hybrid zone (DEM takes 1 − w).
    pub weight: f64,
    /// Layered zones of a hybrid body (Yue 2018 §4.3), fixed to the material: grains only
    /// within this depth [m] of the body's free faces (those not on a wall or the domain's edge)...
    pub discrete_layer: f64,
    /// ... then a band of this thickness [m] where grains and points overlap and are coupled;
    /// points only below it.
    pub hybrid_band: f64,
    /// Grains also within this height [m] of the faces a hybrid body rests on (a wall or the
    /// domain's edge, periodic axes excepted), with a band of `hybrid_band` over them; 0 (the
    /// default): the continuum reaches the walls. A continuum that cannot carry the shear
    /// near a rough floor leaves it to grains.
    pub discrete_base: f64,
    /// How a hybrid grain takes the constrained velocities back.
    pub grain_transfer: GrainTransfer,
    /// With `"flip"`: the inertial number γ̇ √(d / |g|) of the material around a band grain
    /// (γ̇ its shear rate, d the grain's diameter) below which the grain turns with the
    /// material; above it the grain keeps its own spin and rolls. GDR MiDi (2004) put the
    /// quasi-static regime of dense flows at I < 1e-3; √(d / |g|) takes the pressure under one
    /// grain layer, so deeper in the band the true inertial number is smaller and grains start
    /// rolling at a smaller one (early rather than late). 0 never turns
    /// the grains (Yue 2018 couples translation only); without gravity they always roll.
    pub quasi_static: f64,
    /// Contact radius r_p of a material point against a rigid body [m] (Jiang 2020 eq. 44–45);
    /// `None`: the middle of eq. 45's interval ([`super::Scene::contact_radius`]).
    pub contact_radius: Option<f64>,
    /// Where a rigid body's contact force on a material point acts on the grid.
    pub contact_forces: ContactForces,
}

/// Where the MPM puts a contact force on a point (Jiang 2020 §5.4 compares the two).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ContactForces {
    /// The default, eq. 46–48: on the point, spread to its nodes with its weights (MPM-SDEM).
    Points,
    /// All on the grid node nearest the point (the paper's MPM-GRID scheme, kept to compare
    /// with: the force no longer follows the point within its cell).
    Nodes,
    /// On the point's face towards the body, spread by the linear hat (a surface load as a
    /// finite element takes it): the cells under the contact carry the whole force, where
    /// through the weights part of it reaches nodes past them.
    Faces,
}

/// What `coupling.substeps = "auto"` asks for: the DEM step `dem_dt` (the DEM's own stable
/// step when absent) and the largest macro-step, a multiple of it, that the MPM's stable step
/// and `run.dt` (then an upper bound) allow.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AutoSteps {
    pub dem_dt: Option<f64>,
}

/// How a hybrid grain takes the coupler's node velocities back (Yue 2018 Alg. 5–6).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GrainTransfer {
    /// Alg. 5–6 as written: the grain's velocity becomes the interpolated node velocity (spin:
    /// half the curl) and it moves from its saved position with it. The band's grains move
    /// affinely with the grid: they stay put at rest, but cannot rearrange, and the band holds
    /// faces a granular material would not.
    Pic,
    /// The default. The grain keeps its substepped velocity and position and adds the
    /// coupling's change of the node velocities interpolated to it (times dt / 2 for the
    /// position); where the material is quasi-static (`quasi_static`) its spin is the
    /// material's, elsewhere its own. The substeps carry the last step's coupling force of the
    /// nodes around each grain, so the coupling acts with the contacts rather than as a kick
    /// after them: a resting band stays at rest and a flowing band rolls
    /// (`docs/validate/column_collapse.md`).
    Flip,
    /// Yue 2018 §3.7 as its text reads: the grid's velocities go back to the grains "in the
    /// same manner as MPM points", which blend PIC and FLIP with the share β of §3.4
    /// (`mpm.flip`; APIC's points take the grid's velocity, so β = 0 there); the grain then
    /// moves from its saved position with that velocity (Alg. 6). Translation only: its spin
    /// is its contacts' (§7: a band grain without contacts spins in place). Measured: it
    /// over-runs the column as `Flip` does, and a resting band does not come to rest
    /// (`docs/validation.md`); kept to show what the paper's text gives.
    Points,
}

/// `[coupling]`; the zones default to two cells of `cell_size` each.
pub(super) fn validate(ctx: &Ctx, raw: Option<&RawCoupling>, cell_size: f64, dt: f64) -> Result<Coupling, SceneError> {
    let band_default = 2.0 * cell_size;
    let Some(c) = raw else {
        return Ok(Coupling {
            substeps: 10,
            auto: None,
            weight: 0.5,
            discrete_layer: band_default,
            hybrid_band: band_default,
            discrete_base: 0.0,
            grain_transfer: GrainTransfer::Flip,
            quasi_static: 1e-3,
            contact_radius: None,
            contact_forces: ContactForces::Points,
        });
    };
    let (substeps, auto) = match &c.substeps {
        None => (10, None),
        Some(k) => match k.get_ref() {
            toml::Value::Integer(n) if (1..=10_000).contains(n) => (*n as u32, None),
            toml::Value::String(w) if w == "auto" => (1, Some(AutoSteps { dem_dt: None })),
            other => {
                return Err(ctx.err(
                    Some(k.span()),
                    Some("coupling.substeps"),
                    format!("must be a whole number between 1 and 10000, or \"auto\", got {other}"),
                ));
            }
        },
    };
    let auto = match (auto, &c.dem_dt) {
        (Some(_), Some(d)) => Some(AutoSteps {
            dem_dt: Some(in_range(ctx, d, "coupling.dem_dt", Open(0.0), Bound::None)?),
        }),
        // A resolved scene keeps the DEM step it was resolved with: it must be the one run.dt
        // and the count give.
        (None, Some(d)) if ((*d.get_ref() * substeps as f64) / dt - 1.0).abs() > 1e-9 => {
            return Err(ctx.err(
                Some(d.span()),
                Some("coupling.dem_dt"),
                format!(
                    "with a fixed count the DEM step is run.dt / coupling.substeps = {:.4e}, not {}; dem_dt chooses the DEM step of \
                     `substeps = \"auto\"`",
                    dt / substeps as f64,
                    number(*d.get_ref())
                ),
            ));
        }
        (auto, _) => auto,
    };
    Ok(Coupling {
        substeps,
        auto,
        weight: match &c.weight {
            None => 0.5,
            Some(w) => in_range(ctx, w, "coupling.weight", Open(0.0), Open(1.0))?,
        },
        discrete_layer: match &c.discrete_layer {
            None => band_default,
            Some(t) => in_range(ctx, t, "coupling.discrete_layer", Closed(0.0), Bound::None)?,
        },
        hybrid_band: match &c.hybrid_band {
            None => band_default,
            Some(t) => in_range(ctx, t, "coupling.hybrid_band", Open(0.0), Bound::None)?,
        },
        discrete_base: match &c.discrete_base {
            None => 0.0,
            Some(t) => in_range(ctx, t, "coupling.discrete_base", Closed(0.0), Bound::None)?,
        },
        grain_transfer: match c.grain_transfer.as_ref().map(|t| (t, t.get_ref().as_str())) {
            Some((_, "pic")) => GrainTransfer::Pic,
            Some((_, "points")) => GrainTransfer::Points,
            None | Some((_, "flip")) => GrainTransfer::Flip,
            Some((t, other)) => {
                return Err(ctx.err(
                    Some(t.span()),
                    Some("coupling.grain_transfer"),
                    format!("must be \"flip\", \"pic\" or \"points\", got {other:?}"),
                ));
            }
        },
        quasi_static: match &c.quasi_static {
            None => 1e-3,
            Some(i) => in_range(ctx, i, "coupling.quasi_static", Closed(0.0), Bound::None)?,
        },
        contact_radius: match &c.contact_radius {
            None => None,
            Some(r) => Some(in_range(ctx, r, "coupling.contact_radius", Open(0.0), Bound::None)?),
        },
        contact_forces: match c.contact_forces.as_ref().map(|t| (t, t.get_ref().as_str())) {
            None | Some((_, "points")) => ContactForces::Points,
            Some((_, "nodes")) => ContactForces::Nodes,
            Some((_, "faces")) => ContactForces::Faces,
            Some((t, other)) => {
                return Err(ctx.err(
                    Some(t.span()),
                    Some("coupling.contact_forces"),
                    format!("must be \"points\", \"nodes\" or \"faces\", got {other:?}"),
                ));
            }
        },
    })
}

#[cfg(test)]
mod tests {
    use super::super::testing::{DEM, check_err, edit, line_of};
    use super::super::{Path, from_str};

    /// The DEM fixture with its column made hybrid, and a [coupling] table.
    fn hybrid(coupling: &str) -> String {
        let text = edit(
            DEM,
            "damping = 7.0\nfriction = 0.4\n",
            "damping = 7.0\nfriction = 0.4\n[material.mpm]\nyoung = 2.5e6\npoisson = 0.3\nfriction_angle = 20.0\npacking = 0.8\n",
        );
        let text = edit(&text, "model = \"dem\"", "model = \"hybrid\"");
        let text = edit(
            &text,
            "min = [0.0, 0.0]\nmax = [0.05, 0.05]",
            "min = [0.01, 0.01]\nmax = [0.05, 0.05]",
        );
        format!("{text}\n[coupling]\n{coupling}\n")
    }

    #[test]
    fn substeps_are_a_count_or_auto_in_a_hybrid_scene() {
        let s = from_str(&hybrid("substeps = \"auto\"\ndem_dt = 5e-7"), Path::new("h.toml"), 1).unwrap();
        assert_eq!(s.coupling.auto.and_then(|a| a.dem_dt), Some(5e-7));
        let s = from_str(&hybrid("substeps = \"auto\""), Path::new("h.toml"), 1).unwrap();
        assert_eq!(s.coupling.auto.map(|a| a.dem_dt), Some(None));
        // A resolved scene keeps its dem_dt: run.dt 1e-5 over 20 substeps is 5e-7.
        let s = from_str(&hybrid("substeps = 20\ndem_dt = 5e-7"), Path::new("h.toml"), 1).unwrap();
        assert_eq!((s.coupling.substeps, s.coupling.auto), (20, None));

        let text = hybrid("substeps = \"often\"");
        check_err(
            &text,
            Some(line_of(&text, "substeps")),
            "coupling.substeps",
            "or \"auto\", got \"often\"",
        );
        let text = hybrid("substeps = 10\ndem_dt = 5e-7");
        check_err(
            &text,
            Some(line_of(&text, "dem_dt")),
            "coupling.dem_dt",
            "run.dt / coupling.substeps = 1.0000e-6, not 5e-7",
        );
        let text = format!("{DEM}\n[coupling]\nsubsteps = \"auto\"\n");
        check_err(&text, Some(line_of(&text, "substeps")), "coupling.substeps", "has no hybrid body");
    }

    /// A discrete base is read with the fixed zones and refused with an adaptive oracle,
    /// which would drop it.
    #[test]
    fn a_discrete_base_takes_fixed_zones() {
        let s = from_str(&hybrid("discrete_base = 0.004"), Path::new("h.toml"), 1).unwrap();
        assert_eq!(s.coupling.discrete_base, 0.004);
        let text = format!("{}\n[oracle]\nkind = \"surface\"\n", hybrid("discrete_base = 0.004"));
        check_err(
            &text,
            Some(line_of(&text, "discrete_base")),
            "coupling.discrete_base",
            "oracle.kind = \"fixed\"",
        );
        let text = hybrid("discrete_base = -0.001");
        check_err(&text, Some(line_of(&text, "discrete_base")), "coupling.discrete_base", "got -0.001");
    }

    #[test]
    fn contact_forces_act_on_points_unless_the_scene_says_nodes() {
        use super::ContactForces;
        let s = from_str(&hybrid("weight = 0.5"), Path::new("h.toml"), 1).unwrap();
        assert_eq!(s.coupling.contact_forces, ContactForces::Points);
        let s = from_str(&hybrid("contact_forces = \"nodes\""), Path::new("h.toml"), 1).unwrap();
        assert_eq!(s.coupling.contact_forces, ContactForces::Nodes);
        let s = from_str(&hybrid("contact_forces = \"faces\""), Path::new("h.toml"), 1).unwrap();
        assert_eq!(s.coupling.contact_forces, ContactForces::Faces);
        let text = hybrid("contact_forces = \"grid\"");
        check_err(
            &text,
            Some(line_of(&text, "contact_forces")),
            "coupling.contact_forces",
            "must be \"points\", \"nodes\" or \"faces\", got \"grid\"",
        );
    }
}
