//! The shear-band oracle in a run (`oracle.kind = "shear_band"`, Chen 2021 Alg. 1 and §4):
//! at every epoch the MPM's points' plastic strain rate and recent plastic strain per cell
//! ([`grains_oracle::shear_band`]); once the flagged cells have stayed the same for τ_g, the
//! cells within φ0 of them take grains cut from the scene's prepared packing
//! ([`grains_oracle::band_epoch::enrich`]) and the points of the discrete ones go. Later
//! epochs go on detecting: a band that grows enriches again, and no cell goes back.
//!
//! Not done here: kinematic training (§4.1.1, `grains_dem::training`, which
//! `grains validate --part shear` runs in process). The new grains arrive at the packing's
//! own state with the continuum's velocity.

use grains_grid::Grid;
use grains_oracle::band_epoch::Packing;
use grains_oracle::shear_band::{self as sb, Coefficients, Persistence, RecentStrain};
use grains_protocol::scene::{Model, Scene};
use grains_protocol::wire::{EPOCH_FIXED, EpochItem, Zone};

/// What the shear-band oracle carries from one epoch to the next.
#[derive(Clone, Debug)]
pub struct BandState {
    coefficients: Coefficients,
    /// D50 [m]: twice the hybrid material's mean radius.
    d50: f64,
    /// φ0 [m] and the overlap t_h (one cell).
    phi0: f64,
    overlap: f64,
    pub packing: Packing,
    recent: RecentStrain,
    persistence: Persistence,
    /// Epochs that found a band and enriched it.
    pub enrichments: u64,
}

impl BandState {
    /// From the scene's `[oracle]` (kind `"shear_band"`) and its hybrid material; reads the
    /// packing file (the grains that are not frozen).
    pub fn new(scene: &Scene) -> anyhow::Result<Self> {
        let o = scene.oracle.as_ref().and_then(|o| o.shear_band.as_ref());
        let Some(o) = o else {
            anyhow::bail!("the scene has no shear-band oracle");
        };
        let body = scene
            .bodies
            .iter()
            .find(|b| b.model == Model::Hybrid)
            .ok_or_else(|| anyhow::anyhow!("oracle.kind = \"shear_band\" needs a model = \"hybrid\" body"))?;
        let dem = scene.materials[body.material]
            .dem
            .as_ref()
            .ok_or_else(|| anyhow::anyhow!("the hybrid body's material has no [material.dem]"))?;
        let data = grains_dem_service::lammps_data::read(&o.packing).map_err(anyhow::Error::msg)?;
        let dim = scene.dim();
        if data.atoms.is_empty() {
            anyhow::bail!("{}: oracle.packing has no grains", o.packing.display());
        }
        let period: [f64; 3] = std::array::from_fn(|k| {
            if k < dim && scene.domain.periodic[k] {
                data.bounds[k][1] - data.bounds[k][0]
            } else {
                0.0
            }
        });
        let packing = Packing {
            min: std::array::from_fn(|k| data.bounds[k][0]),
            period,
            grains: data.atoms.iter().map(|a| (a.x, 0.5 * a.diameter)).collect(),
        };
        Ok(BandState {
            coefficients: Coefficients {
                c0: o.c0,
                c1: o.c1,
                cl: o.c_l,
                cg: o.c_g,
            },
            d50: 2.0 * dem.radius,
            phi0: o.band_distance,
            overlap: scene.domain.cell_size,
            packing,
            recent: RecentStrain::default(),
            persistence: Persistence::default(),
            enrichments: 0,
        })
    }

    /// Alg. 1 at `time` over the points (the MPM's epoch items): the band's zones (§4) when
    /// the flagged set has held for τ_g, else None. The points' recent plastic strain counts
    /// from the record a window τ_l ago.
    pub fn detect(&mut self, cells: &Grid, dim: usize, time: f64, points: &[EpochItem]) -> Option<Vec<Zone>> {
        let points: Vec<&EpochItem> = points.iter().filter(|p| p.flags & EPOCH_FIXED == 0).collect();
        let max_rate = points.iter().map(|p| p.plastic_rate).fold(0.0, f64::max);
        let c = &self.coefficients;
        let (tau_l, tau_g) = (sb::window(c.cl, max_rate), sb::window(c.cg, max_rate));
        let ids: Vec<u64> = points.iter().map(|p| p.id).collect();
        let strain: Vec<f64> = points.iter().map(|p| p.plastic_strain).collect();
        let recent = self.recent.recent(time, tau_l, &ids, &strain);
        self.recent.record(time, &ids, &strain);
        let rate = sb::cell_average(cells, dim, points.iter().map(|p| (p.position, p.mass, p.plastic_rate)));
        let recent = sb::cell_average(cells, dim, points.iter().zip(&recent).map(|(p, &r)| (p.position, p.mass, r)));
        let flagged = sb::flag(cells, dim, &rate, &recent, self.d50, c);
        if !self.persistence.update(time, flagged, tau_g) {
            return None;
        }
        Some(sb::zones(cells, dim, self.persistence.flagged(), self.phi0, self.overlap))
    }

    /// What a checkpoint holds of it: the recent strain's records, the persistence's set and
    /// clock, the enrichments so far.
    pub fn save(&self) -> (&RecentStrain, &Persistence, u64) {
        (&self.recent, &self.persistence, self.enrichments)
    }

    /// Takes back [`BandState::save`]'s parts.
    pub fn restore(&mut self, (recent, persistence, enrichments): (RecentStrain, Persistence, u64)) {
        (self.recent, self.persistence, self.enrichments) = (recent, persistence, enrichments);
    }
}
