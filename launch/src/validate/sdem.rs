//! `grains validate --part sdem`: rigid spheropolygons in contact with a continuum (Jiang 2020
//! §5), through real runs (the DEM and the MPM as processes, the contacts crossing between
//! them each step):
//!
//! - §5.1.1: an elastic MPM disk hits a resting rigid disk of the same mass at 2 cm/s; the
//!   share of the kinetic energy of a perfectly elastic collision of rigid disks the rigid disk
//!   leaves with, hard and ten times softer, against the paper's 99.2% and 92.2%;
//! - §5.1.2: the same disk dropped on a fixed slab; the energy back after the bounce, hard
//!   and soft, against the paper's 98.95% and 93.05%;
//! - §5.2.2: the block slides along the slab; friction over normal force against μ, and its
//!   deceleration against μ g;
//! - §5.2.1: an elastic block comes to rest on a fixed rigid slab; the slab's force against the
//!   block's weight on four grids (statics, 1%: the force does not depend on the grid), beside
//!   the same block on a grid-node wall (the MPM alone), and the cost of a step of each;
//! - §5.3: MPM sand discharging from a silo whose bottom is two rigid slabs, over five
//!   orifices: Beverloo's law fitted, against the paper's C = 0.58, k_c = 2.2 (in r_p);
//! - §5.4: an MPM bar hits a rigid bar on six grids, the forces on the points (MPM-SDEM) and
//!   on the nearest nodes (MPM-GRID): the energy error against the grid;
//! - §7: a granular matrix of rigid pentagons and MPM fines compressed by a rigid bar, at
//!   three fine contents: the bar's force against its travel (the paper: more fines, stiffer).

use super::args::ValidateArgs;
use super::runs::{finished, load_with};
use super::scenes::sdem::{
    BLOCK, DISK, DROP, FILLS, GRIDS, MATRIX, MATRIX_GAP, ORIFICES, ROD, ROD_GRIDS, ROD_LENGTH, SILO, SLAB_RADIUS, SLIDE, SLIDE_WINDOW,
    SOFTER,
};
use super::scenes::silo::{BOTTOM, CENTRE, D};
use crate::metrics::MetricsTable;
use crate::report::Part;
use crate::report::chart::{Chart, Kind, Series};
use grains_dem::space::{D2, Space};
use std::fmt::Write as _;
use std::path::Path;

type DVec2 = <D2 as Space>::V;

/// The paper's shares of the ideal kinetic energy (§5.1.1: hard, soft disk).
const PAPER_HARD: f64 = 0.99202;
const PAPER_SOFT: f64 = 0.9216;
/// §5.1.2: the potential energy back as kinetic energy after the bounce (hard, soft disk).
const PAPER_DROP_HARD: f64 = 0.9895;
const PAPER_DROP_SOFT: f64 = 1.0 - 0.06947;
/// The silo's discharge-rate window [s]: after the start-up, while the silo is still filled
/// higher than 2.5 times its widest orifice.
const SILO_WINDOW: (f64, f64) = (0.05, 0.25);
/// The soft disk's share within this of the paper's (points of the share): the share moves by
/// about a point with the contact radius within eq. 45's range and with the grid.
const SOFT_TOLERANCE: f64 = 0.02;
/// Statics: the slab carries the block's weight to this share.
const REST_TOLERANCE: f64 = 0.01;

/// A run's `bodies.csv`.
fn bodies(dir: &Path) -> anyhow::Result<MetricsTable> {
    let path = dir.join("bodies.csv");
    MetricsTable::parse(&std::fs::read_to_string(&path)?, &path)
}

pub fn validate(args: &ValidateArgs) -> anyhow::Result<Part> {
    let mut part = Part::default();
    let mut md = String::from("## Rigid bodies in contact with a continuum (Jiang 2020 §5)\n\n");
    disk_impact(args, &mut part, &mut md)?;
    disk_drop(args, &mut part, &mut md)?;
    block_at_rest(args, &mut part, &mut md)?;
    block_sliding(args, &mut part, &mut md)?;
    silo(args, &mut part, &mut md)?;
    rod(args, &mut part, &mut md)?;
    matrix(args, &mut part, &mut md)?;
    part.md = md;
    Ok(part)
}

/// §5.1.1, hard and soft: the rigid disk's speed after the impact against a perfectly elastic
/// collision of rigid disks of the two masses, v = 2 m_A v0 / (m_A + m_B).
fn disk_impact(args: &ValidateArgs, part: &mut Part, md: &mut String) -> anyhow::Result<()> {
    let path = args.scenes.join(DISK);
    let scene = load_with(&path, &[])?;
    let v0 = scene.bodies[0].velocity[0];
    let rigid = &scene.rigids[0];
    let shape: Vec<_> = rigid.vertices.iter().map(|&[x, y]| D2::from_array([x, y, 0.0])).collect();
    let m_b = grains_dem::bodies::mass_properties(&shape, rigid.radius).area * scene.materials[rigid.material].density;
    let young = scene.materials[0].mpm.as_ref().map_or(0.0, |m| m.young);
    let _ = writeln!(
        md,
        "### §5.1.1: an elastic disk hits a rigid disk\n\n`{DISK}`: an MPM disk at {v0} m/s hits a resting rigid disk of \
         the same size and density (k_n = {:.1e} N/m, e = 1, r_p = {:.2e} m). Measured: the rigid disk's kinetic energy \
         after the impact over that of a perfectly elastic collision of rigid disks of the same masses. Reference: the \
         paper's 99.2% (hard) and 92.2% (soft, ten times softer).\n\n| disk | E [Pa] | MPM disk mass [kg/m] | rigid disk \
         [m/s] | ideal [m/s] | share | paper |\n|---|---:|---:|---:|---:|---:|---:|",
        scene.materials[rigid.material].dem.as_ref().map_or(0.0, |d| d.stiffness_normal),
        scene.contact_radius()
    );
    let mut shares = Vec::new();
    for (name, softness, paper) in [("hard", 1.0, PAPER_HARD), ("soft", SOFTER, PAPER_SOFT)] {
        let run = finished(args, &path, vec![format!("material.0.mpm.young={}", young / softness)])?;
        let m_a = MetricsTable::read(&run.dir)?.first("mpm_mass")?;
        let v_b = bodies(&run.dir)?.last("body0_vx")?;
        let ideal = 2.0 * m_a * v0 / (m_a + m_b);
        let share = (v_b / ideal).powi(2);
        let _ = writeln!(
            md,
            "| {name} | {:.2e} | {m_a:.4} | {v_b:.4} | {ideal:.4} | {:.2}% | {:.1}% |",
            young / softness,
            100.0 * share,
            100.0 * paper
        );
        shares.push(share);
    }
    hard_and_soft(
        part,
        "MPM disk → rigid disk",
        "the rigid disk's share of the ideal kinetic energy",
        "§5.1.1",
        [PAPER_HARD, PAPER_SOFT],
        &shares,
        0.99,
    );
    part.check(
        "MPM disk → rigid disk, soft: the rigid disk's share of the ideal kinetic energy",
        "Jiang 2020 §5.1.1: 92.2%",
        format!("{:.2}%", 100.0 * shares[1]),
        format!("within {:.0} points", 100.0 * SOFT_TOLERANCE),
        (shares[1] - PAPER_SOFT).abs() <= SOFT_TOLERANCE,
    );
    let _ = writeln!(
        md,
        "\nThe paper's text says 2 m/s, but its Fig. 6 is in cm/s and its disks meet 1.46 s after the start, which is \
         2 cm/s. The speed matters because the contact is a disk meeting a lattice of point disks, not one linear spring: \
         at 2 m/s the rigid disk's share was 88.95% (hard) and 79.13% (soft) through this scene. On 2026-12-03, at 2 cm/s, \
         r_p = 1.0 mm (under eq. 45's range, 1.5–3 mm here), 1.5 mm (the scene's) and 2.0 mm gave 97.84/92.33%, 97.79/92.31% and 97.69/92.10% \
         (hard/soft); the hard disk stays 1.4 points under the paper's 99.2%.\n"
    );
    Ok(())
}

/// §5.1.2, hard and soft: the disk's fall speed just before it first touches the slab and its
/// highest rising speed after, from its momentum (metrics.csv) and the slab's force
/// (bodies.csv).
fn disk_drop(args: &ValidateArgs, part: &mut Part, md: &mut String) -> anyhow::Result<()> {
    let path = args.scenes.join(DROP);
    let scene = load_with(&path, &[])?;
    let young = scene.materials[0].mpm.as_ref().map_or(0.0, |m| m.young);
    let _ = writeln!(
        md,
        "### §5.1.2: an elastic disk dropped on a rigid slab\n\n`{DROP}`: the disk of §5.1.1 dropped about 2 cm onto a fixed \
         rigid slab at g = {} m/s² (the paper's 10 cm/s²). Measured: the disk's largest rising speed after the bounce over its \
         speed at the first touch, squared (its centre of mass; metrics.csv). Reference: the paper's 98.95% (hard) and 93.05% \
         (soft) of the potential energy back as kinetic energy.\n\n| disk | E [Pa] | impact [m/s] | rebound [m/s] | share | \
         paper |\n|---|---:|---:|---:|---:|---:|",
        scene.gravity[1].abs()
    );
    let mut shares = Vec::new();
    for (name, softness, paper) in [("hard", 1.0, PAPER_DROP_HARD), ("soft", SOFTER, PAPER_DROP_SOFT)] {
        let run = finished(args, &path, vec![format!("material.0.mpm.young={}", young / softness)])?;
        let m = MetricsTable::read(&run.dir)?;
        let (py, mass) = (m.column("mpm_py")?, m.first("mpm_mass")?);
        let fy = bodies(&run.dir)?.column("body0_fy")?;
        let touch = fy.iter().position(|&f| f != 0.0).unwrap_or(fy.len()).min(py.len());
        let impact = py[..touch].iter().fold(0.0f64, |a, &p| a.max(-p / mass));
        let rebound = py[touch..].iter().fold(0.0f64, |a, &p| a.max(p / mass));
        let share = (rebound / impact).powi(2);
        let _ = writeln!(
            md,
            "| {name} | {:.2e} | {impact:.4} | {rebound:.4} | {:.2}% | {:.2}% |",
            young / softness,
            100.0 * share,
            100.0 * paper
        );
        shares.push(share);
    }
    hard_and_soft(
        part,
        "MPM disk dropped on a rigid slab",
        "the energy back after the bounce",
        "§5.1.2",
        [PAPER_DROP_HARD, PAPER_DROP_SOFT],
        &shares,
        0.98,
    );
    Ok(())
}

/// The two checks of a hard and a soft disk's energy shares (§5.1.1, §5.1.2; `paper` and
/// `shares` hard first): the hard one at least `hard_min`, the soft one below it and no energy
/// made.
fn hard_and_soft(part: &mut Part, case: &str, measure: &str, section: &str, paper: [f64; 2], shares: &[f64], hard_min: f64) {
    part.check(
        format!("{case}, hard: {measure}"),
        format!("Jiang 2020 {section}: {:.2}%", 100.0 * paper[0]),
        format!("{:.2}%", 100.0 * shares[0]),
        format!("≥ {:.0}%", 100.0 * hard_min),
        shares[0] >= hard_min,
    );
    part.check(
        format!("{case}: the soft disk gives less, and no energy is made"),
        format!("Jiang 2020 {section}: {:.2}% < {:.2}% ≤ 100%", 100.0 * paper[1], 100.0 * paper[0]),
        format!("soft {:.2}%, hard {:.2}%", 100.0 * shares[1], 100.0 * shares[0]),
        "soft < hard ≤ 100%",
        shares[1] < shares[0] && shares[0] <= 1.0,
    );
}

/// §5.2.1 on four grids, on the rigid slab and on a grid-node wall in its place (the MPM
/// alone), then the cost of a step of each.
fn block_at_rest(args: &ValidateArgs, part: &mut Part, md: &mut String) -> anyhow::Result<()> {
    let path = args.scenes.join(BLOCK);
    let g = load_with(&path, &[])?.gravity[1].abs();
    // The same block on a plane wall of the MPM's grid nodes at the slab's top face.
    let text = std::fs::read_to_string(&path)?;
    let cut = text
        .find("[[rigid]]")
        .ok_or_else(|| anyhow::anyhow!("{}: no [[rigid]] table", path.display()))?;
    let end = text[cut..].find("\n[coupling]").map_or(text.len(), |k| cut + k);
    let wall_text = format!(
        "{}[[wall]]\nkind = \"plane\"\npoint = [0.0, 0.0]\nnormal = [0.0, 1.0]\n{}",
        &text[..cut],
        &text[end..]
    );
    let wall_path = args.out.join("sdem_block_wall_2d.toml");
    std::fs::write(&wall_path, wall_text)?;
    let _ = writeln!(
        md,
        "### §5.2.1: an elastic block at rest on a rigid slab, and on a grid-node wall\n\n`{BLOCK}`: an elastic block dropped \
         1.5–2.3 mm onto a fixed rigid slab (contact by points, the DEM's law, e = 0.2), and the same block on a plane wall \
         of the MPM's grid nodes at the slab's face (the MPM alone: the nodes behind it lose their velocity into it), each \
         run for 0.3 s on four grids. Measured: the force on the slab (bodies.csv) and on the wall (walls.csv) at the end, \
         and its RMS deviation from the weight over the last 0.1 s. Reference: statics (the weight of the block's points).\n\n\
         | cell [m] | points | weight [N/m] | slab, end | slab, RMS dev. | grid wall, end | grid wall, RMS dev. | wall s slab / grid \
         wall |\n|---:|---:|---:|---:|---:|---:|---:|---:|"
    );
    // Force at the end and RMS deviation from `weight` over the last third of the rows.
    let settle = |f: Vec<f64>, weight: f64| -> (f64, f64) {
        let tail = &f[2 * f.len() / 3..];
        let rms = (tail.iter().map(|x| (-x - weight).powi(2)).sum::<f64>() / tail.len() as f64).sqrt();
        (-f.last().copied().unwrap_or(0.0), rms)
    };
    let mut worst: f64 = 0.0;
    let mut cost = None;
    for h in GRIDS {
        let set = vec![format!("domain.cell_size={h}")];
        let (slab_run, wall_run) = (finished(args, &path, set.clone())?, finished(args, &wall_path, set)?);
        let t = MetricsTable::read(&slab_run.dir)?;
        let weight = t.first("mpm_mass")? * g;
        let (slab, slab_rms) = settle(bodies(&slab_run.dir)?.column("body0_fy")?, weight);
        let walls_csv = wall_run.dir.join("walls.csv");
        let (wall, wall_rms) = settle(
            MetricsTable::parse(&std::fs::read_to_string(&walls_csv)?, &walls_csv)?.column("wall0_fy")?,
            weight,
        );
        worst = worst.max((slab / weight - 1.0).abs());
        let _ = writeln!(
            md,
            "| {h} | {} | {weight:.4} | {slab:.4} ({:+.3}%) | {:.2}% | {wall:.4} ({:+.2}%) | {:.2}% | {:.1} / {:.1} |",
            slab_run.points,
            100.0 * (slab / weight - 1.0),
            100.0 * slab_rms / weight,
            100.0 * (wall / weight - 1.0),
            100.0 * wall_rms / weight,
            slab_run.wall,
            wall_run.wall
        );
        cost.get_or_insert((
            h,
            slab_run.points,
            slab_run.wall / t.len() as f64,
            wall_run.wall / MetricsTable::read(&wall_run.dir)?.len() as f64,
        ));
    }
    part.check(
        format!("a block at rest on a rigid slab: its weight on {} grids", GRIDS.len()),
        "statics (Jiang 2020 §5.2.1, Fig. 12: the force does not depend on the grid)",
        format!("worst {:.3}%", 100.0 * worst),
        format!("±{:.0}%", 100.0 * REST_TOLERANCE),
        worst <= REST_TOLERANCE,
    );
    if let Some((h, points, coupled, alone)) = cost {
        let _ = writeln!(
            md,
            "\nCost on {h} m cells ({points} points): the coupled run (DEM, MPM and coupler as processes, the contacts crossing \
             each step) took {:.1} µs per step, the block on the grid-node wall (the MPM alone, one process) {:.1} µs: {:.2}×.\n",
            1e6 * coupled,
            1e6 * alone,
            coupled / alone
        );
    }
    Ok(())
}

/// §5.2.2: the block launched along the slab; over [`SLIDE_WINDOW`] (after its landing's
/// bounces) the slab's friction against its normal force, and the block's deceleration.
fn block_sliding(args: &ValidateArgs, part: &mut Part, md: &mut String) -> anyhow::Result<()> {
    let path = args.scenes.join(SLIDE);
    let scene = load_with(&path, &[])?;
    let mu = scene.materials[scene.rigids[0].material].dem.as_ref().map_or(0.0, |d| d.friction);
    let g = scene.gravity[1].abs();
    let run = finished(args, &path, Vec::new())?;
    let (b, m) = (bodies(&run.dir)?, MetricsTable::read(&run.dir)?);
    let (t, fx, fy) = (b.column("time")?, b.column("body0_fx")?, b.column("body0_fy")?);
    let (px, mass, tm) = (m.column("mpm_px")?, m.first("mpm_mass")?, m.column("time")?);
    let from = t.iter().position(|&t| t >= SLIDE_WINDOW).unwrap_or(t.len());
    let ratios: Vec<f64> = (from..t.len()).filter(|&k| fy[k] != 0.0).map(|k| (fx[k] / fy[k]).abs()).collect();
    let ratio = ratios.iter().sum::<f64>() / ratios.len().max(1) as f64;
    let k0 = tm.iter().position(|&t| t >= SLIDE_WINDOW).unwrap_or(0);
    let k1 = tm.len() - 1;
    let decel = (px[k0] - px[k1]) / mass / (tm[k1] - tm[k0]);
    let _ = writeln!(
        md,
        "### §5.2.2: the block sliding on the slab\n\n`{SLIDE}`: the block of §5.2.1 launched at {:.1} m/s along the slab, \
         μ = {mu}. Measured from {SLIDE_WINDOW} s (after its landing's bounces), over {} rows of which {} in contact: the \
         slab's friction over its normal force (bodies.csv) {ratio:.4}; the block's deceleration (metrics.csv) {decel:.3} \
         m/s² against μ g = {:.3}.\n",
        scene.bodies[0].velocity[0],
        t.len() - from,
        ratios.len(),
        mu * g
    );
    part.check(
        "a block sliding on a rigid slab: friction over normal force",
        "Coulomb, μ (Jiang 2020 §5.2.2: μ F_n on the points in contact)",
        format!("{ratio:.4}"),
        "within 1% of μ",
        ratios.len() == t.len() - from && (ratio / mu - 1.0).abs() <= 0.01,
    );
    part.check(
        "a block sliding on a rigid slab: its deceleration",
        "Coulomb block: μ g",
        format!("{decel:.3} m/s²"),
        "within 2% of μ g",
        (decel / (mu * g) - 1.0).abs() <= 0.02,
    );
    Ok(())
}

/// Jiang 2020 §5.3 (Fig. 16): the discharge rate over five orifices (the slabs' inner ends
/// moved), fitted by Beverloo's 2D law W = C ρ_b √g (w − k_c r_p)^{3/2}.
fn silo(args: &ValidateArgs, part: &mut Part, md: &mut String) -> anyhow::Result<()> {
    let path = args.scenes.join(SILO);
    let scene = load_with(&path, &[])?;
    let mat = &scene.materials[0];
    let rho_b = mat.density * mat.mpm.as_ref().map_or(1.0, |m| m.packing);
    let (g, r_p) = (scene.gravity[1].abs(), scene.contact_radius());
    let _ = writeln!(
        md,
        "### §5.3: a silo on rigid slabs\n\n`{SILO}`: calibrated MPM sand (ρ_b = {rho_b:.0} kg/m³, 1-mm cells, r_p = {:.1} mm) \
         discharging through the orifice between two fixed rigid slabs (contact by points), over orifices of {} mm. Measured: \
         the discharge rate W, the slope of the mass below the bottom over {:.2}–{:.2} s. Reference: Beverloo's law in 2D, \
         W = C ρ_b √g (w − k_c r_p)^3/2, which the paper fits with C = 0.58, k_c = 2.2 (Fig. 16).\n\n| orifice [mm] | W \
         [kg/(m s)] | wall s |\n|---:|---:|---:|",
        r_p * 1e3,
        ORIFICES.map(|w| format!("{:.0}", w * 1e3)).join(", "),
        SILO_WINDOW.0,
        SILO_WINDOW.1
    );
    let mut rates = Vec::new();
    for w in ORIFICES {
        // The slabs' rounded inner ends at CENTRE ∓ w / 2.
        let (left, right) = (CENTRE - w / 2.0 - SLAB_RADIUS, CENTRE + w / 2.0 + SLAB_RADIUS);
        let (lo, hi) = (BOTTOM - 0.005, BOTTOM - SLAB_RADIUS);
        let overrides = vec![
            format!("rigid.0.vertices=[[-0.001,{lo}],[{left},{lo}],[{left},{hi}],[-0.001,{hi}]]"),
            format!("rigid.1.vertices=[[{right},{lo}],[0.041,{lo}],[0.041,{hi}],[{right},{hi}]]"),
        ];
        let run = finished(args, &path, overrides)?;
        let (discharged, _) = super::silo::discharge(&run.dir, w)?;
        let window: Vec<(f64, f64)> = discharged
            .into_iter()
            .filter(|p| (SILO_WINDOW.0..=SILO_WINDOW.1).contains(&p.0))
            .collect();
        let rate = super::stats::slope(&window);
        let _ = writeln!(md, "| {:.0} | {rate:.4} | {:.1} |", w * 1e3, run.wall);
        rates.push((w, rate));
    }
    let flowing: Vec<(f64, f64)> = rates.iter().copied().filter(|&(_, q)| q > 0.0).collect();
    if flowing.len() < 3 {
        part.check(
            "MPM silo on rigid slabs: Beverloo's law",
            "Jiang 2020 §5.3",
            format!("{} of {} orifices flowed", flowing.len(), rates.len()),
            "≥ 3 flowing",
            false,
        );
        return Ok(());
    }
    // `beverloo` gives k in grain diameters D; the paper's k_c is in r_p.
    let (c, k, worst) = super::silo::beverloo(&flowing, rho_b, g);
    let k_c = k * D / r_p;
    let _ = writeln!(
        md,
        "\nBeverloo fit over the flowing orifices: C = {c:.3}, k_c = {k_c:.2} (in r_p; the paper 0.58 and 2.2), largest \
         residual {:.1}%.\n",
        100.0 * worst
    );
    part.check(
        "MPM silo on rigid slabs: the discharge follows Beverloo's law",
        "Jiang 2020 §5.3, Fig. 16 (C = 0.58, k_c = 2.2)",
        format!("C = {c:.3}, k_c = {k_c:.2}, largest residual {:.1}%", 100.0 * worst),
        "residual ≤ 10%",
        worst <= 0.1,
    );
    Ok(())
}

/// §5.4 on [`ROD_GRIDS`], both schemes: the energy the rigid bar misses of a perfectly
/// elastic collision of rigid bars, 1 − (v_B / v_ideal)².
fn rod(args: &ValidateArgs, part: &mut Part, md: &mut String) -> anyhow::Result<()> {
    let path = args.scenes.join(ROD);
    let scene = load_with(&path, &[])?;
    let v0 = scene.bodies[0].velocity[0];
    let a = SLAB_RADIUS;
    let _ = writeln!(
        md,
        "### §5.4: contact schemes on coarsening grids\n\n`{ROD}`: an elastic MPM bar ({0} × {0} m) at {v0} m/s hits a resting rigid \
         bar of its size and density, on cells of 1–10 mm (the bar {0} m long: L/d_g = 10 to 1, as the paper's 1 to 10). The \
         contact force acts on the point, spread by its weights (`\"points\"`, MPM-SDEM, eq. 46–48), or all on the node nearest \
         the point (`\"nodes\"`, the paper's MPM-GRID), or the rigid bar is nine material points on the grid that meet the \
         continuum's at shared nodes by Bardenhagen's grid contact (MPM-DEM, Liu et al. 2018, the paper's third scheme; in \
         process, [`grid_contact_run`]). Measured: the energy error 1 − (v_B / v_ideal)², v_ideal = 2 m_A v0 / \
         (m_A + m_B). Reference: Jiang 2020 Fig. 18 (MPM-SDEM best, its error falling with the grid; MPM-GRID distinctly \
         worse at L/d_g = 1–2, MPM-DEM as MPM-GRID). Beside them, the error of a 1D elastic bar hitting a free rigid mass of its own mass \
         through a contact spring of the same stiffness (its points on the face times k_n, over the bar's E A / L; \
         [`bar_on_mass_share`], Saint-Venant's impact resolved on 400 nodes): an elastic bar keeps part of its energy \
         as vibration, the more the stiffer the contact.\n\n| cell [m] | L/d_g | points | error, points | error, nodes | \
         error, grid contact | 1D bar, contact/bar stiffness | 1D bar error |\n|---:|---:|---:|---:|---:|---:|---:|---:|",
        ROD_LENGTH
    );
    let (k_n, young) = {
        let m = &scene.materials[scene.rigids[0].material];
        (
            m.dem.as_ref().map_or(0.0, |d| d.stiffness_normal),
            m.mpm.as_ref().map_or(0.0, |m| m.young),
        )
    };
    let mut chart = Chart {
        title: "MPM bar hitting a rigid bar: energy error against the grid".into(),
        x_label: "cell size [m]".into(),
        y_label: "energy error 1 - (v_B / v_ideal)^2".into(),
        log_x: true,
        log_y: true,
        ..Chart::default()
    };
    let mut errors = [Vec::new(), Vec::new(), Vec::new()];
    for h in ROD_GRIDS {
        // The rigid bar's face 1 mm beyond the frontmost points' contact disks (r_p = h/2, the
        // points h/4 inside the MPM bar's face at x = 0).
        let x = 0.25 * h + 0.001;
        let vertices = format!(
            "rigid.0.vertices=[[{},{a}],[{},{a}],[{},{}],[{},{}]]",
            x + a,
            x + ROD_LENGTH - a,
            x + ROD_LENGTH - a,
            ROD_LENGTH - a,
            x + a,
            ROD_LENGTH - a
        );
        let shape: Vec<_> = [
            [x + a, a],
            [x + ROD_LENGTH - a, a],
            [x + ROD_LENGTH - a, ROD_LENGTH - a],
            [x + a, ROD_LENGTH - a],
        ]
        .iter()
        .map(|&[x, y]| D2::from_array([x, y, 0.0]))
        .collect();
        let density = scene.materials[scene.rigids[0].material].density;
        let props = grains_dem::bodies::mass_properties(&shape, a);
        let m_b = props.area * density;
        let mut row = Vec::new();
        let mut points = 0;
        let mut m_a = 0.0;
        for (k, scheme) in ["points", "nodes"].into_iter().enumerate() {
            let set = vec![
                format!("domain.cell_size={h}"),
                vertices.clone(),
                format!("coupling.contact_forces=\"{scheme}\""),
            ];
            let run = finished(args, &path, set)?;
            m_a = MetricsTable::read(&run.dir)?.first("mpm_mass")?;
            let v_b = bodies(&run.dir)?.last("body0_vx")?;
            let error = 1.0 - (v_b * (m_a + m_b) / (2.0 * m_a * v0)).powi(2);
            errors[k].push((h, error));
            row.push(error);
            points = run.points;
        }
        // The third scheme in process, on the same scene with this grid.
        let at_h = load_with(&path, &[format!("domain.cell_size={h}"), vertices.clone()])?;
        tracing::info!("validate: sdem, bar impact on {h}-m cells, grid contact (Liu)");
        let v_b = grid_contact_run(
            &at_h,
            DVec2::new(x, 0.0),
            DVec2::new(x + ROD_LENGTH, ROD_LENGTH),
            m_b,
            props.second_moment * density,
        )?;
        let error = 1.0 - (v_b.x * (m_a + m_b) / (2.0 * m_a * v0)).powi(2);
        errors[2].push((h, error));
        row.push(error);
        // The face's points (spacing h / points_per_axis) against E A / L = E (square bar, 2D).
        let ratio = (ROD_LENGTH / (h / scene.mpm.points_per_axis as f64)).round() * k_n / young;
        let _ = writeln!(
            md,
            "| {h} | {:.1} | {points} | {:.2}% | {:.2}% | {:.2}% | {ratio:.1} | {:.2}% |",
            ROD_LENGTH / h,
            100.0 * row[0],
            100.0 * row[1],
            100.0 * row[2],
            100.0 * (1.0 - bar_on_mass_share(ratio))
        );
    }
    for (name, e) in [
        ("MPM-SDEM (points)", &errors[0]),
        ("MPM-GRID (nodes)", &errors[1]),
        ("MPM-DEM (grid contact, Liu)", &errors[2]),
    ] {
        chart.series.push(Series::new(
            name,
            Kind::Line,
            e.iter().map(|&(h, e)| (h, e.abs().max(1e-6))).collect(),
        ));
    }
    part.chart(
        &args.out,
        "sdem_rod",
        "Energy error of the bar impact against the cell size, the three schemes",
        &chart,
    )?;
    // The two coarsest grids: L/d_g = 2 and 1.
    let coarse = ROD_GRIDS.len() - 2..ROD_GRIDS.len();
    for (k, other, short) in [(1, "on the nodes", "nodes'"), (2, "the grid contact (Liu)", "grid contact's")] {
        part.check(
            format!("bar impact: forces on the points keep energy better than {other} at L/d_g = 1–2"),
            "Jiang 2020 §5.4, Fig. 18",
            coarse
                .clone()
                .map(|g| {
                    format!(
                        "h = {}: {:.2}% vs {:.2}%",
                        ROD_GRIDS[g],
                        100.0 * errors[0][g].1,
                        100.0 * errors[k][g].1
                    )
                })
                .collect::<Vec<_>>()
                .join("; "),
            format!("points' error < {short} error on both"),
            coarse.clone().all(|g| errors[0][g].1.abs() < errors[k][g].1.abs()),
        );
    }
    let _ = writeln!(
        md,
        "\nThe paper's measure counts as error the energy an elastic bar keeps as vibration, which 1D theory says stays \
         (the last column); on a grid fine enough to carry the bar's waves the coupled run approaches that, and on the \
         coarsest the bar, one cell long, moves nearly as a rigid body.\n"
    );
    let (fine, coarsest) = (errors[0][0].1, errors[0][ROD_GRIDS.len() - 1].1);
    part.check(
        "bar impact, forces on the points: the error falls as the grid refines",
        "Jiang 2020 §5.4, Fig. 18",
        format!(
            "{:.2}% at {} m, {:.2}% at {} m",
            100.0 * fine,
            ROD_GRIDS[0],
            100.0 * coarsest,
            ROD_GRIDS[ROD_GRIDS.len() - 1]
        ),
        "finest < coarsest",
        fine.abs() < coarsest.abs(),
    );
    Ok(())
}

/// Bardenhagen et al. 2000's contact at one node that two bodies share (frictionless): `a`
/// with mass `m_a` and velocity `v_a`, `b` with `m_b`, `v_b`, `n` the unit normal from `a`
/// into `b`. Where they approach along `n` both take their centre of mass's normal velocity;
/// the impulse on `b` that does so (`a` takes its opposite), `None` where they part or slide.
fn node_contact(m_a: f64, v_a: DVec2, m_b: f64, v_b: DVec2, n: DVec2) -> Option<DVec2> {
    let approach = (v_a - v_b).dot(n);
    (approach > 0.0).then(|| n * (approach * m_a * m_b / (m_a + m_b)))
}

/// The rigid bar on one grid node: its mass, momentum and mass gradient there, and each of its
/// points' offset from its centre and mass on the node.
#[derive(Default)]
struct BarNode {
    mass: f64,
    momentum: DVec2,
    gradient: DVec2,
    parts: Vec<(DVec2, f64)>,
}

/// §5.4's third scheme, MPM-DEM (Liu et al. 2018; Jiang 2020 Fig. 17C), in process: the rigid
/// bar (`lo`–`hi`, mass `m_b`, moment of inertia `inertia`) is carried on the grid by nine
/// material points fixed to it, as Liu's blocks (its corners, the middles of its sides, its
/// centre; the paper's 1D rod takes three), each of a ninth of its mass. At each node both
/// the bar's points and the continuum's reach, [`node_contact`] with the normal along the
/// bar's mass gradient there (into the bar); the continuum's node takes its share, and the bar the
/// opposite impulse, spread over its points by their mass on that node (force and torque). The
/// continuum is the scene's own points and step (`grains_mpm_service::setup::build`), so only
/// the contact differs from the runs of the other two schemes. `grains run` has no such
/// scheme: it is the one the paper argues against. Returns the bar's final velocity.
fn grid_contact_run(scene: &grains_protocol::scene::Scene, lo: DVec2, hi: DVec2, m_b: f64, inertia: f64) -> anyhow::Result<DVec2> {
    use grains_mpm::pipeline::MpmPipeline;
    use std::collections::HashMap;
    let zones = grains_service::zones::ZoneField::layered(scene);
    let (mut pts, params) = grains_mpm_service::setup::build::<D2>(scene, &zones).map_err(anyhow::Error::msg)?;
    let mut pipe = MpmPipeline::<D2>::new(scene.threads as usize).map_err(anyhow::Error::msg)?;
    let mut centre = 0.5 * (lo + hi);
    let offsets: Vec<DVec2> = [lo.y, centre.y, hi.y]
        .iter()
        .flat_map(|&y| [lo.x, centre.x, hi.x].map(|x| DVec2::new(x, y) - centre))
        .collect();
    let share = m_b / offsets.len() as f64;
    let (mut v, mut angle, mut spin) = (DVec2::ZERO, 0.0f64, 0.0);
    let dt = scene.dt;
    let mut nodes: HashMap<u64, BarNode> = HashMap::new();
    for _ in 0..scene.steps {
        pipe.phase1(&pts, &params, dt)
            .map_err(|e| anyhow::anyhow!("bar impact, grid contact: {e}"))?;
        nodes.clear();
        let turn = DVec2::from_angle(angle);
        for o in &offsets {
            let r = turn.rotate(*o);
            let velocity = v + spin * r.perp();
            grains_grid::shape::for_each_node::<D2>(&params.grid, params.kernel, centre + r, |node, w, grad| {
                let e = nodes.entry(node).or_default();
                e.mass += w * share;
                e.momentum += velocity * (w * share);
                e.gradient += grad * share;
                e.parts.push((r, w * share));
            });
        }
        let (mut impulse, mut torque) = (DVec2::ZERO, 0.0);
        pipe.for_each_node_mut(|ijk, m_a, v_a| {
            let Some(BarNode {
                mass: m,
                momentum: p,
                gradient: grad,
                parts,
            }) = params.grid.index(ijk).and_then(|i| nodes.get(&i))
            else {
                return;
            };
            if *m <= 0.0 || grad.length_squared() == 0.0 {
                return;
            }
            // Σ m ∇w over the bar's points is its outward normal at the node (the weights fall
            // away from its points); the continuum meets it along its inward one.
            if let Some(j) = node_contact(m_a, *v_a, *m, *p / *m, -grad.normalize()) {
                *v_a -= j / m_a;
                for &(r, mass) in parts {
                    let jk = j * (mass / m);
                    impulse += jk;
                    torque += r.perp_dot(jk);
                }
            }
        });
        pipe.phase2(&mut pts, &params, dt)
            .map_err(|e| anyhow::anyhow!("bar impact, grid contact: {e}"))?;
        v += impulse / m_b;
        spin += torque / inertia;
        centre += v * dt;
        angle += spin * dt;
    }
    Ok(v)
}

/// Saint-Venant's impact in 1D: an elastic bar (mass m, length L, wave speed c) at v0 hits a
/// free rigid mass m through a unilateral contact spring k = `ratio` E A / L; the mass's
/// kinetic energy once they have parted, over v0²'s (the whole of it for rigid bodies). The bar
/// is 400 lumped masses joined by springs (velocity Verlet at a fifth of the stable step), run
/// until the contact has been open for 5 L / c, at least 20 L / c.
pub fn bar_on_mass_share(ratio: f64) -> f64 {
    let n = 400;
    // Units: L = c = ρ A = 1, so m = 1 and E A = 1.
    let (mi, ks, k) = (1.0 / n as f64, n as f64, ratio);
    let dt = 0.2 * (mi / ks).sqrt().min((mi / k).sqrt());
    let (mut x, mut v, mut f) = (vec![0.0; n], vec![1.0; n], vec![0.0; n]);
    let (mut xm, mut vm) = (0.0, 0.0);
    let forces = |x: &[f64], xm: f64, f: &mut [f64]| -> f64 {
        f.iter_mut().for_each(|f| *f = 0.0);
        for i in 0..n - 1 {
            let s = ks * (x[i + 1] - x[i]);
            f[i] += s;
            f[i + 1] -= s;
        }
        let contact = (k * (x[n - 1] - xm)).max(0.0);
        f[n - 1] -= contact;
        contact
    };
    let mut fm = forces(&x, xm, &mut f);
    let (mut t, mut last_contact) = (0.0, f64::INFINITY);
    while t < 20.0 || t - last_contact < 5.0 || last_contact == f64::INFINITY {
        t += dt;
        if fm > 0.0 {
            last_contact = t;
        }
        for i in 0..n {
            v[i] += 0.5 * dt * f[i] / mi;
            x[i] += dt * v[i];
        }
        vm += 0.5 * dt * fm;
        xm += dt * vm;
        fm = forces(&x, xm, &mut f);
        for i in 0..n {
            v[i] += 0.5 * dt * f[i] / mi;
        }
        vm += 0.5 * dt * fm;
    }
    vm * vm
}

/// §7: the matrix at three fine contents (the fines' height), the bar's force against its
/// travel past the skeleton's top (it starts [`MATRIX_GAP`] above it). The paper's finding
/// (Fig. 23): more fines, a stiffer matrix.
fn matrix(args: &ValidateArgs, part: &mut Part, md: &mut String) -> anyhow::Result<()> {
    let path = args.scenes.join(MATRIX);
    let scene = load_with(&path, &[])?;
    let bar = scene.rigids.len() - 1;
    let rock: f64 = scene.rigids[..bar]
        .iter()
        .map(|r| {
            let shape: Vec<_> = r.vertices.iter().map(|&[x, y]| D2::from_array([x, y, 0.0])).collect();
            grains_dem::bodies::mass_properties(&shape, r.radius).area * scene.materials[r.material].density
        })
        .sum();
    let g = scene.gravity[1].abs();
    let _ = writeln!(
        md,
        "### §7: a granular matrix under compression\n\n`{MATRIX}`: a settled skeleton of {bar} rigid pentagons ({rock:.3} kg/m, \
         weight {:.1} N/m) with MPM fines in its voids up to a height H, compressed by a rigid bar at {:.2} m/s from {} mm above \
         the skeleton. Measured: the bar's force (bodies.csv) against its travel past the skeleton's top. Reference: Jiang \
         2020 §7, Fig. 23: the more fines, the stiffer the matrix.\n\n| H [m] | fines [kg/m] | fine content (mass) | force at \
         2 mm [N/m] | at 4 mm | at 8 mm | wall [s] |\n|---:|---:|---:|---:|---:|---:|---:|",
        rock * g,
        -scene.rigids[bar].velocity[1],
        1e3 * MATRIX_GAP
    );
    let mut chart = Chart {
        title: "Granular matrix: the bar's force against its travel".into(),
        x_label: "the bar's travel past the skeleton's top [mm]".into(),
        y_label: "force on the bar [N/m]".into(),
        ..Chart::default()
    };
    let travels = [0.002, 0.004, 0.008];
    let mut stiff = Vec::new();
    for height in FILLS {
        let run = finished(args, &path, vec![format!("body.0.max=[0.1,{height}]")])?;
        let fines = MetricsTable::read(&run.dir)?.first("mpm_mass")?;
        let b = bodies(&run.dir)?;
        let (y, f) = (b.column(&format!("body{bar}_y"))?, b.column(&format!("body{bar}_fy"))?);
        let curve: Vec<(f64, f64)> = y
            .iter()
            .zip(&f)
            .map(|(&y_k, &f_k)| (1e3 * (y[0] - y_k - MATRIX_GAP), f_k))
            .collect();
        let at = |d: f64| curve.iter().find(|p| p.0 >= 1e3 * d).map_or(f64::NAN, |p| p.1);
        let forces: Vec<f64> = travels.iter().map(|&d| at(d)).collect();
        let _ = writeln!(
            md,
            "| {height} | {fines:.3} | {:.1}% | {:.1} | {:.1} | {:.1} | {:.1} |",
            100.0 * fines / (fines + rock),
            forces[0],
            forces[1],
            forces[2],
            run.wall
        );
        chart.series.push(Series::new(
            format!("H = {height} m ({:.0}% fines)", 100.0 * fines / (fines + rock)),
            Kind::Line,
            curve,
        ));
        stiff.push(forces);
    }
    part.chart(
        &args.out,
        "sdem_matrix",
        "The bar's force against its travel at three fine contents",
        &chart,
    )?;
    // More fines, more force at every travel measured.
    let rising = travels.iter().enumerate().all(|(k, _)| stiff.windows(2).all(|w| w[1][k] > w[0][k]));
    part.check(
        "granular matrix: more fines, stiffer",
        "Jiang 2020 §7, Fig. 23",
        stiff
            .iter()
            .map(|f| format!("{:.0}", f[travels.len() - 1]))
            .collect::<Vec<_>>()
            .join(" < "),
        format!(
            "the force at {} mm rises with the fines at every travel",
            1e3 * travels[travels.len() - 1]
        ),
        rising,
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::DVec2;

    /// The grid contact on the finest grid of the bar impact (`sdem_rod_2d.toml` on 1-mm cells,
    /// L/d_g = 10): no energy made, and at least Saint-Venant's share for a rigid contact
    /// between an elastic bar and a free mass of its own mass, (1 − e⁻²)² = 0.748 (a contact
    /// with any give hands over more; [`super::bar_on_mass_share`]'s limits). With the normal
    /// turned the wrong way the bar passes into the rigid bar's nodes and sticks there: 0.25.
    #[test]
    fn the_grid_contact_hands_the_rigid_bar_its_energy_on_a_fine_grid() {
        use super::super::scenes::sdem::{ROD, ROD_LENGTH as L, SLAB_RADIUS as A};
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes").join(ROD);
        let h = 0.001;
        let x = 0.25 * h + 0.001;
        let corners = [[x + A, A], [x + L - A, A], [x + L - A, L - A], [x + A, L - A]];
        let set = vec![format!("domain.cell_size={h}"), format!("rigid.0.vertices={corners:?}")];
        let scene = super::load_with(&path, &set).unwrap();
        let shape: Vec<_> = corners.iter().map(|&[x, y]| DVec2::new(x, y)).collect();
        let props = grains_dem::bodies::mass_properties(&shape, A);
        let rho = scene.materials[scene.rigids[0].material].density;
        let (m_b, v0) = (props.area * rho, scene.bodies[0].velocity[0]);
        let m_a = L * L * rho;
        let v = super::grid_contact_run(&scene, DVec2::new(x, 0.0), DVec2::new(x + L, L), m_b, props.second_moment * rho).unwrap();
        let share = (v.x * (m_a + m_b) / (2.0 * m_a * v0)).powi(2);
        let saint_venant = (1.0 - (-2.0f64).exp()).powi(2);
        assert!(
            share >= saint_venant && share <= 1.0 + 1e-9,
            "share {share} (Saint-Venant {saint_venant})"
        );
    }

    /// Bardenhagen's node contact: approaching bodies leave the node with their centre of
    /// mass's normal velocity, momentum kept and the tangential velocities untouched; parting
    /// or sliding ones are left alone.
    #[test]
    fn the_node_contact_stops_the_approach_and_keeps_momentum() {
        let n = DVec2::new(0.6, 0.8);
        let (m_a, v_a, m_b, v_b) = (2.0, DVec2::new(1.0, 0.5), 3.0, DVec2::new(-0.2, 0.1));
        let j = super::node_contact(m_a, v_a, m_b, v_b, n).expect("they approach");
        let (a, b) = (v_a - j / m_a, v_b + j / m_b);
        let centre = (v_a * m_a + v_b * m_b) / (m_a + m_b);
        assert!((a.dot(n) - centre.dot(n)).abs() < 1e-12 && (b.dot(n) - centre.dot(n)).abs() < 1e-12);
        assert!(((a * m_a + b * m_b) - (v_a * m_a + v_b * m_b)).length() < 1e-12);
        assert!((a.perp_dot(n) - v_a.perp_dot(n)).abs() < 1e-12, "tangential velocity changed");
        assert!(super::node_contact(m_a, v_b, m_b, v_a, n).is_none(), "parting bodies were held");
        assert!(
            super::node_contact(m_a, n.perp(), m_b, DVec2::ZERO, n).is_none(),
            "sliding bodies were held"
        );
    }

    /// The 1D reference at its two limits: through a soft contact the bar moves as a rigid body
    /// and gives the mass all its energy; through a rigid one the mass is pushed at
    /// m dV/dt = ρ A c (v0 − V) until the wave returns from the far end at 2L/c (Saint-Venant),
    /// V = v0 (1 − e^{−2}) for equal masses.
    #[test]
    fn the_1d_bar_gives_all_through_a_soft_contact_and_saint_venant_s_share_through_a_stiff_one() {
        let soft = super::bar_on_mass_share(0.01);
        assert!(soft > 0.99 && soft <= 1.0 + 1e-9, "soft contact: {soft}");
        let stiff = super::bar_on_mass_share(1e3);
        let saint_venant = (1.0 - (-2.0f64).exp()).powi(2);
        assert!(
            (stiff / saint_venant - 1.0).abs() < 0.02,
            "stiff contact: {stiff} against {saint_venant}"
        );
    }
}
