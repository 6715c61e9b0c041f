//! What `grains validate` is asked to do: its flags, and the registry of its parts (their
//! names, order and whether CI runs them; `super::run_part` runs one).

use std::path::PathBuf;

/// The parts of the validation, in the order they run: the one registry of cases, with
/// what each checks and whether CI's `--quick` runs it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum PartName {
    /// DEM restitution of a head-on impact against its analytic value.
    Contact,
    /// Stability maps: DEM step, MPM CFL number, hybrid substeps and cell size.
    Stability,
    /// Column collapse against the pure DEM and the published runout laws.
    Column,
    /// Silo discharge, Beverloo fits, clogging, bouncing grains.
    Silo,
    /// The free-surface angle in a turning drum.
    Drum,
    /// Accuracy against wall time, with the Pareto front.
    Cost,
    /// Rigid bodies in contact with a continuum (Jiang 2020 §5).
    Sdem,
    /// Shear bands (Chen 2021): the planar shear as DEM and as a continuum with the oracle.
    Shear,
    /// Plate indentation (Chen 2021 §6.3): the plate's force against its depth, DEM and
    /// continuum.
    Plate,
    /// Biaxial compression (Chen 2021 §6.2) as a DEM with a membrane: the band's thickness
    /// and inclination, stress and volume against the axial strain.
    Biaxial,
}

impl PartName {
    pub const ALL: [PartName; 10] = [
        PartName::Contact,
        PartName::Stability,
        PartName::Column,
        PartName::Silo,
        PartName::Drum,
        PartName::Cost,
        PartName::Sdem,
        PartName::Shear,
        PartName::Plate,
        PartName::Biaxial,
    ];

    pub fn name(self) -> &'static str {
        match self {
            PartName::Contact => "contact",
            PartName::Stability => "stability",
            PartName::Column => "column",
            PartName::Silo => "silo",
            PartName::Drum => "drum",
            PartName::Cost => "cost",
            PartName::Sdem => "sdem",
            PartName::Shear => "shear",
            PartName::Plate => "plate",
            PartName::Biaxial => "biaxial",
        }
    }

    /// In CI's `--quick` set (the drum, the accuracy–cost runs and the plate take too long for
    /// it; the rigid bodies' and the band measure's checks that CI needs are tests of their
    /// own).
    pub fn quick(self) -> bool {
        !matches!(
            self,
            PartName::Drum | PartName::Cost | PartName::Sdem | PartName::Shear | PartName::Plate | PartName::Biaxial
        )
    }
}

#[derive(Debug, Clone, clap::Args)]
pub struct ValidateArgs {
    /// The CI subset, each part in its quick form (e.g. the column at aspect ratio 1 only; with
    /// `--part shear`: one sample, no cohesive run, no tall shear).
    #[arg(long)]
    pub quick: bool,
    /// Aspect ratios to run instead of the default set.
    #[arg(long, value_delimiter = ',')]
    pub aspect: Vec<f64>,
    /// Directory of column_collapse_2d.toml and column_collapse_hybrid_2d.toml.
    #[arg(long, default_value = "scenes")]
    pub scenes: PathBuf,
    /// Where the runs and the report go (default `out/validate/<today>`).
    #[arg(long = "out", value_name = "DIR")]
    pub out_dir: Option<PathBuf>,
    /// `--out`, or its default, once `validate` has chosen it.
    #[arg(skip)]
    pub out: PathBuf,
    /// DEM substeps per MPM step to sweep for stability (hybrid, a = 1, first 0.2 s); the
    /// default set 2, 5, 10, 20, 40, 80, 160 runs without `--quick`.
    #[arg(long, value_delimiter = ',')]
    pub sweep_k: Vec<u32>,
    /// The hybrid pile at rest whose surface drift is measured with both grain transfers.
    #[arg(long, default_value = "tests/scenes/hybrid_pile_2d.toml")]
    pub pile: PathBuf,
    /// Extra `--set` overrides for the hybrid runs (to explore; the report lists them).
    #[arg(long = "set-hybrid", value_name = "KEY=VALUE")]
    pub hybrid_overrides: Vec<String>,
    /// Also copy the report and its charts (PNG, SVG, CSV), without the runs, into this
    /// directory (the repository's `docs/validate` keeps the last published one).
    #[arg(long)]
    pub publish: Option<PathBuf>,
    /// Packings poured (seeds 1..=N) and run at every aspect ratio; the check compares the
    /// runouts averaged over them. Default 3, `--quick` 1. `--part plate`: the DEM beds
    /// (default 2).
    #[arg(long)]
    pub packings: Option<u64>,
    /// The grains' transfers back that `--part shear`'s hybrid runs, one run each on every DEM
    /// sample: `pic` (Yue 2018 Alg. 5–6 as written), `flip` (ours), `points:B` (Yue 2018 §3.7
    /// as its text reads: FLIP share B of the grid's velocity change, PIC the rest, moving from
    /// the saved position; spin from the contacts).
    #[arg(long = "shear-transfer", value_delimiter = ',', default_value = "pic,flip")]
    pub shear_transfers: Vec<String>,
    /// The DEM samples of `--part shear`'s planar shear (§6.1), by seed: each is a DEM run and
    /// a hybrid run per transfer of `--shear-transfer`. The first is the one the continuum,
    /// the kinematic training and the large planar shear take; `--quick` runs it alone.
    #[arg(long = "shear-seeds", value_delimiter = ',', default_value = "1,2", value_parser = clap::value_parser!(u64).range(1..))]
    pub shear_seeds: Vec<u64>,
    /// The large planar shear's height in §6.1's heights (`--part shear`, not in `--quick`:
    /// Chen 2021 §6.4 at this machine's size).
    #[arg(long = "shear-large-times", default_value_t = 20, value_parser = clap::value_parser!(u64).range(1..))]
    pub shear_large_times: u64,
    /// The large planar shear's continuum cells in D50 (Chen's large shear: 0.75-cm cells in
    /// 1-mm grains; the cell is the period over a whole number of cells, so 8 gives 7.5).
    #[arg(long = "shear-large-cells", default_value_t = 8.0, value_parser = positive_d50)]
    pub shear_large_cells: f64,
    /// Height the silo is filled to over its bottom [m] (`--part silo` and `--part cost`):
    /// the scene's 0.06 by default; taller silos are poured and run in a box raised to hold
    /// them (the orifice, the bin and the grains the same), where the continuum takes more of
    /// the material.
    #[arg(long = "silo-fill", default_value_t = super::scenes::silo::FILL, value_parser = silo_fill)]
    pub silo_fill: f64,
    /// What holds the DEM biaxial sample's sides at the confining pressure (`--part
    /// biaxial`): `fluid` (the pressure on the packing's surface on a grid, as the MPM's
    /// confining fluid takes it: `grains_dem::fluid`; Chen 2021 App. B's membrane also acts
    /// on the grains through the background grid) or `membrane` (a chain of spring nodes in
    /// contact with the grains: App. B's springs, our discretisation).
    #[arg(long = "biaxial-confinement", value_enum, default_value = "fluid")]
    pub biaxial_confinement: Confinement,
    /// The hybrid biaxial's enrichment distances φ0 in D50 (`--part biaxial`; Chen 2021 Table
    /// 6: 10), one run each per transfer of `--shear-transfer` (Fig. 19–20: the band against
    /// the discrete zone's thickness).
    #[arg(long = "biaxial-phi0", value_delimiter = ',', default_value = "10")]
    pub biaxial_phi0: Vec<f64>,
    /// The hybrid biaxial's continuum cells in D50 (Fig. 21: the band against the grid).
    #[arg(long = "biaxial-cells", value_delimiter = ',', default_value = "2")]
    pub biaxial_cells: Vec<f64>,
    /// Parts to run (default all; `--quick`: those of the CI subset, each in its quick form).
    #[arg(long, value_enum, value_delimiter = ',')]
    pub part: Vec<PartName>,
}

/// A length in D50 for a continuum cell: finite, at least 1 (a cell under a grain holds no
/// grain's worth of material for the band measure).
fn positive_d50(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v >= 1.0 => Ok(v),
        Ok(v) => Err(format!("{v} D50: a cell must be at least 1 D50")),
        Err(e) => Err(format!("{s:?}: {e} (a number of D50, e.g. 8)")),
    }
}

fn silo_fill(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && (0.02..=2.0).contains(&v) => Ok(v),
        Ok(v) => Err(format!("{v} m: the fill must be 0.02 to 2 m (the scene's is 0.06)")),
        Err(e) => Err(format!("{s:?}: {e} (a height in m, e.g. 0.25)")),
    }
}

/// What holds a DEM sample's sides at a pressure.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Confinement {
    /// Chains of mass–spring nodes among the grains (Chen 2021 App. B).
    Membrane,
    /// The pressure of a fluid on the packing's surface, on a grid (`grains_dem::fluid`).
    Fluid,
}

impl ValidateArgs {
    /// `--shear-seeds` as the planar shear runs them: each seed once (the first alone with
    /// `--quick`).
    pub fn shear_seeds(&self) -> anyhow::Result<&[u64]> {
        let seeds = &self.shear_seeds;
        if let Some((k, s)) = seeds.iter().enumerate().find(|(k, s)| seeds[..*k].contains(s)) {
            anyhow::bail!(crate::run::BadInput(format!(
                "--shear-seeds: seed {s} is listed twice (at {} and {}); each seed is one DEM sample, list it once",
                seeds.iter().position(|x| x == s).unwrap_or(0) + 1,
                k + 1
            )));
        }
        Ok(&seeds[..if self.quick { seeds.len().min(1) } else { seeds.len() }])
    }

    /// The parts this invocation runs, in order: those named, else all (`--quick`: the quick ones).
    pub fn parts(&self) -> Vec<PartName> {
        PartName::ALL
            .into_iter()
            .filter(|p| {
                if self.part.is_empty() {
                    !self.quick || p.quick()
                } else {
                    self.part.contains(p)
                }
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(clap::Parser)]
    struct Wrapper {
        #[command(flatten)]
        args: ValidateArgs,
    }

    /// `--shear-seeds`: the DEM samples, the first alone in `--quick`; a seed below 1 or twice
    /// is refused, saying which.
    #[test]
    fn the_planar_shear_takes_its_seeds_each_once() {
        let parsed = |extra: &[&str]| Wrapper::try_parse_from(std::iter::once("validate").chain(extra.iter().copied()));
        assert_eq!(parsed(&[]).unwrap().args.shear_seeds().unwrap(), &[1, 2]);
        assert_eq!(parsed(&["--quick"]).unwrap().args.shear_seeds().unwrap(), &[1]);
        assert_eq!(parsed(&["--shear-seeds", "3,1,5"]).unwrap().args.shear_seeds().unwrap(), &[3, 1, 5]);
        assert_eq!(
            parsed(&["--shear-seeds", "3,1", "--quick"]).unwrap().args.shear_seeds().unwrap(),
            &[3]
        );
        for bad in [["--shear-seeds", "0"], ["--shear-seeds", "1,x"]] {
            let e = parsed(&bad).err().unwrap_or_else(|| panic!("{bad:?} was taken"));
            assert_eq!(e.kind(), clap::error::ErrorKind::ValueValidation, "{bad:?}: {e}");
        }
        let twice = parsed(&["--shear-seeds", "2,4,2"]).unwrap().args;
        let e = twice.shear_seeds().unwrap_err().to_string();
        assert!(e.contains("seed 2") && e.contains("1 and 3"), "{e}");
    }

    #[test]
    fn the_large_shear_takes_its_height_and_cells_and_refuses_what_cannot_run() {
        let parsed = |extra: &[&str]| Wrapper::try_parse_from(std::iter::once("validate").chain(extra.iter().copied()));
        let default = parsed(&[]).unwrap().args;
        assert_eq!((default.shear_large_times, default.shear_large_cells), (20, 8.0));
        let set = parsed(&["--shear-large-times", "5", "--shear-large-cells", "4"]).unwrap().args;
        assert_eq!((set.shear_large_times, set.shear_large_cells), (5, 4.0));
        for bad in [
            ["--shear-large-times", "0"],
            ["--shear-large-cells", "0.5"],
            ["--shear-large-cells", "nan"],
            ["--shear-large-cells", "eight"],
        ] {
            let e = parsed(&bad).err().unwrap_or_else(|| panic!("{bad:?} was taken"));
            assert_eq!(e.kind(), clap::error::ErrorKind::ValueValidation, "{bad:?}: {e}");
        }
    }

    #[test]
    fn the_silo_fill_defaults_to_the_scene_s_and_refuses_what_cannot_be_a_fill() {
        let parsed = |extra: &[&str]| Wrapper::try_parse_from(std::iter::once("validate").chain(extra.iter().copied()));
        assert_eq!(parsed(&[]).unwrap().args.silo_fill, 0.06);
        assert_eq!(parsed(&["--silo-fill", "0.25"]).unwrap().args.silo_fill, 0.25);
        for bad in ["0", "-0.1", "3", "nan", "tall"] {
            let arg = format!("--silo-fill={bad}");
            let e = parsed(&[arg.as_str()]).err().unwrap_or_else(|| panic!("{bad:?} was taken"));
            assert_eq!(e.kind(), clap::error::ErrorKind::ValueValidation, "{bad:?}: {e}");
        }
    }
}
