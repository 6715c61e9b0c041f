//! `grains validate`: the validation report (issue 8). The parts ([`PartName`], in the order
//! they run; `--part` picks some, `--quick` is the CI subset, under 15 minutes):
//!
//! - [`contact`]: the DEM restitution against its analytic value;
//! - [`stability`]: stability maps of the DEM step, the MPM CFL number and, in a full run, the
//!   hybrid's substeps and cell / grain ratio;
//! - [`column`]: the hybrid and MPM column collapse against the pure DEM one (Yue 2018 §5,
//!   Fig. 5), runouts against Lube et al. 2005 and Yue 2018's laws;
//! - [`silo`], [`drum`]: discharge, Beverloo, clogging, bouncing; the angle of a turning drum;
//! - [`cost`]: error against wall time, with the Pareto front;
//! - [`sdem`]: rigid bodies in contact with a continuum (Jiang 2020 §5);
//! - [`shear`]: shear bands (Chen 2021): the planar shear as DEM and as a continuum with the
//!   shear-band oracle;
//! - [`plate`]: plate indentation (Chen 2021 §6.3), the plate's force against its depth as DEM
//!   and as the calibrated continuum.
//!
//! Below the parts: [`runs`] (running scenes, reading what a run did), [`packings`] (every
//! packing poured, in one place), [`deposit`] (frames and deposits read back), [`pictures`]
//! (the runs drawn side by side), [`scenes`]
//! (the scenes and their geometry), [`stats`]. Nothing below a part depends on a part.
//!
//! Everything goes to `--out` (default `out/validate/<date>`): `report.md` opens with every
//! check (reference, measured, tolerance, pass/fail), then each part's tables and charts
//! (PNG, SVG and the CSV behind each). The command exits 1 when a check fails.

mod args;
pub mod column;
pub mod contact;
pub mod cost;
pub mod deposit;
pub mod drum;
pub mod packings;
pub mod pictures;
pub mod plate;
pub mod runs;
pub mod scenes;
pub mod sdem;
pub mod shear;
pub mod silo;
pub mod stability;
pub mod stats;

pub use args::{PartName, ValidateArgs};

use crate::report::Part;
use anyhow::Context;
use std::path::PathBuf;

/// Runs the parts, writes the report (and publishes it if asked); whether every check passed.
pub fn validate(args: &ValidateArgs) -> anyhow::Result<bool> {
    let mut args = args.clone();
    args.out = args
        .out_dir
        .clone()
        .unwrap_or_else(|| PathBuf::from("out/validate").join(crate::clock::today()));
    std::fs::create_dir_all(&args.out)?;
    let args = &args;
    let t0 = std::time::Instant::now();
    let mut parts = Vec::new();
    for p in args.parts() {
        // A part that cannot finish (a run refused or failed) is a failed check; the other
        // parts still run and report.
        parts.push(run_part(p, args).unwrap_or_else(|e| unfinished(p, &e)));
    }
    let preamble = format!(
        "`grains validate{}` (grains {}), {} UTC, {:.0} min on {} threads. Parts: {}. Every check names what it is \
         compared with; the figures below each part hold the runs' numbers, with the data of every chart as CSV.",
        std::env::args().skip(2).map(|a| format!(" {a}")).collect::<String>(),
        env!("CARGO_PKG_VERSION"),
        crate::clock::today(),
        t0.elapsed().as_secs_f64() / 60.0,
        std::thread::available_parallelism().map_or(1, |n| n.get()),
        args.parts().iter().map(|p| p.name()).collect::<Vec<_>>().join(", ")
    );
    let md = crate::report::markdown("grains validate", &preamble, &parts);
    let path = args.out.join("report.md");
    std::fs::write(&path, &md)?;
    if let Some(dir) = &args.publish {
        std::fs::create_dir_all(dir)?;
        std::fs::write(dir.join("report.md"), &md)?;
        let charts = parts.iter().flat_map(|p| &p.charts).map(|(s, _)| (s, &["png", "svg", "csv"][..]));
        let pictures = parts.iter().flat_map(|p| &p.pictures).map(|(s, _)| (s, &["png"][..]));
        for (stem, exts) in charts.chain(pictures) {
            for ext in exts {
                let name = format!("{stem}.{ext}");
                std::fs::copy(args.out.join(&name), dir.join(&name)).with_context(|| format!("publishing {name}"))?;
            }
        }
        tracing::info!("validate: report and charts published to {}", dir.display());
    }
    let failed: Vec<&crate::report::Check> = parts.iter().flat_map(|p| &p.checks).filter(|c| !c.pass).collect();
    for c in &failed {
        tracing::error!(
            "validate: FAIL {}: measured {} against {} (tolerance {})",
            c.name,
            c.measured,
            c.reference,
            c.tolerance
        );
    }
    tracing::info!(
        "validate: {} checks, {} failed; report in {}",
        parts.iter().map(|p| p.checks.len()).sum::<usize>(),
        failed.len(),
        path.display()
    );
    Ok(failed.is_empty())
}

/// Runs one part of the registry.
fn run_part(p: PartName, args: &ValidateArgs) -> anyhow::Result<Part> {
    match p {
        PartName::Contact => contact::validate(args),
        PartName::Stability => stability::validate(args),
        PartName::Column => column::validate(args),
        PartName::Silo => silo::validate(args),
        PartName::Drum => drum::validate(args),
        PartName::Cost => cost::validate(args),
        PartName::Sdem => sdem::validate(args),
        PartName::Shear => shear::validate(args),
        PartName::Plate => plate::validate(args),
        PartName::Biaxial => shear::biaxial::validate(args),
    }
}

/// The report's section for a part that stopped with an error: one failed check naming it.
fn unfinished(p: PartName, e: &anyhow::Error) -> Part {
    let p = p.name();
    tracing::error!("validate: part {p} failed: {e:#}");
    let mut part = Part {
        md: format!("## Part `{p}`: did not finish\n\n{e:#}\n"),
        ..Part::default()
    };
    part.check(
        format!("part {p} ran to its end"),
        "every run of the part completes",
        format!("{e:#}"),
        "no error",
        false,
    );
    part
}
