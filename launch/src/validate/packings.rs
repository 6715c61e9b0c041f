//! Every packing the validation pours, in one place: each is a `grains pack` of a scene with
//! overrides, kept in `--out` under a name that says what it is and the hash of the pour's
//! scene text, and poured once (later runs of the same pour reuse it). Both models of a
//! comparison start from the same packing.

use super::args::ValidateArgs;
use super::scenes::{
    self,
    column::{BOTTOM, D, L0},
};
use anyhow::bail;
use std::path::PathBuf;

/// A packing poured by `grains pack` from `scene` with `overrides`, kept in `--out` as `name`
/// with the hash of the effective scene text before its extension: a changed pour scene or
/// other overrides pour a new file instead of reusing the old one (the code that pours is not
/// in the hash: after a change to the DEM, use a new `--out`).
pub fn poured(args: &ValidateArgs, name: &str, scene: &str, overrides: Vec<String>) -> anyhow::Result<PathBuf> {
    let scene = args.scenes.join(scene);
    let name = pour_name(name, &scene, &overrides)?;
    let path = std::path::absolute(args.out.join(&name))?;
    if !path.exists() {
        tracing::info!("validate: pouring {name} with grains pack");
        crate::pack::pack(&crate::pack::PackArgs {
            scene,
            out: path.clone(),
            friction: None,
            overrides,
        })?;
    }
    Ok(path)
}

/// The settled packing of `seed` for columns up to aspect ratio `a_max`. The seed draws the
/// radii and the lattice's jitter, so each pour settles into another random packing.
pub fn column(args: &ValidateArgs, a_max: f64, seed: u64) -> anyhow::Result<PathBuf> {
    // A lattice settles to about 0.78 of its height; pour a third more than the column needs.
    let pour_top = BOTTOM + 1.35 * a_max * L0 + 0.005;
    let settle = ((2.0 * pour_top / 9.81).sqrt() + 0.2) * 100.0;
    let name = format!("packing_column_{:.0}mm_seed{seed}.data", pour_top * 1e3);
    let path = poured(
        args,
        &name,
        scenes::column::PACKING,
        vec![
            format!("body.0.max=[{L0},{pour_top}]"),
            format!("run.duration={}", settle.ceil() / 100.0),
            format!("run.seed={seed}"),
        ],
    )?;
    let data = grains_dem_service::lammps_data::read(&path).map_err(anyhow::Error::msg)?;
    let top = data.atoms.iter().filter(|a| a.kind == 1).map(|a| a.x[1]).fold(0.0, f64::max);
    if top < BOTTOM + a_max * L0 + D {
        bail!(
            "{}: the packing is {:.1} mm tall, too short for a column of aspect ratio {a_max}; delete it to pour a new one",
            path.display(),
            top * 1e3
        );
    }
    Ok(path)
}

/// A column packing of grains `s` times the scenes' 1 mm (with the `grain` overrides that make
/// them so), for columns up to a = 1.
pub fn coarse_column(args: &ValidateArgs, s: f64, grain: &[String]) -> anyhow::Result<PathBuf> {
    let pour_top = 1.5 * s * 1e-3 + 1.35 * L0 + 0.005;
    let mut overrides = vec![
        format!("body.0.min=[0.0,{}]", 1.5 * s * 1e-3),
        format!("body.0.max=[{L0},{pour_top}]"),
        format!("body.1.max=[{L0},{}]", 1.3 * s * 1e-3),
        format!("run.duration={:.2}", (2.0 * pour_top / 9.81).sqrt() + 0.2),
    ];
    overrides.extend(grain.iter().cloned());
    poured(args, &format!("packing_column_d{s}mm.data"), scenes::column::PACKING, overrides)
}

/// The silo's fill: the bottom closed, a lattice 80 mm tall settling to about 62 mm.
pub fn silo(args: &ValidateArgs) -> anyhow::Result<PathBuf> {
    use scenes::silo::{BOTTOM, FILL, LATTICE, SCENE};
    let fill = args.silo_fill;
    let mut overrides = vec![
        "body.0.model=\"dem\"".into(),
        "body.0.max=[0.04,0.14]".into(),
        format!("wall.0.to=[0.04,{BOTTOM}]"),
        "run.duration=0.35".into(),
    ];
    if fill == FILL {
        return poured(args, "packing_silo_60mm_seed1.data", SCENE, overrides);
    }
    // A taller lattice, in the raised box, settling for its fall and 0.25 s more.
    let lattice = LATTICE * fill;
    let settle = ((2.0 * lattice / 9.81).sqrt() + 0.25) * 100.0;
    overrides[1] = format!("body.0.max=[0.04,{}]", BOTTOM + lattice);
    overrides[3] = format!("run.duration={}", settle.ceil() / 100.0);
    overrides.extend(super::silo::room(fill));
    poured(args, &format!("packing_silo_{:.0}mm_seed1.data", fill * 1e3), SCENE, overrides)
}

/// The drum at rest, a lattice to 62 mm settling to about half full.
pub fn drum(args: &ValidateArgs) -> anyhow::Result<PathBuf> {
    let overrides = [
        "body.0.model=\"dem\"",
        "body.0.max=[0.095,0.062]",
        "wall.0.spin=0.0",
        "run.duration=0.35",
    ];
    poured(
        args,
        "packing_drum_seed1.data",
        scenes::drum::SCENE,
        overrides.map(String::from).to_vec(),
    )
}

/// `name` with the hash of the effective text of `scene` under `overrides` before its
/// extension.
fn pour_name(name: &str, scene: &std::path::Path, overrides: &[String]) -> anyhow::Result<String> {
    let hash = super::runs::load_with(scene, overrides)?.hash;
    let (stem, ext) = name.rsplit_once('.').unwrap_or((name, "data"));
    Ok(format!("{stem}_{hash:016x}.{ext}"))
}

/// The plate indentation's bed of `seed`: the column's pour over the plate scene's width, a
/// lattice a third taller than the bed's cut at [`scenes::plate::TOP`].
pub fn plate(args: &ValidateArgs, seed: u64) -> anyhow::Result<PathBuf> {
    use scenes::plate::{TOP, WIDTH};
    let pour_top = BOTTOM + 1.35 * (TOP - BOTTOM) + 0.005;
    let overrides = vec![
        format!("domain.max=[{WIDTH},{}]", pour_top + 0.02),
        format!("body.0.max=[{WIDTH},{pour_top}]"),
        format!("body.1.max=[{WIDTH},0.0013]"),
        format!("wall.2.point=[{WIDTH},0.0]"),
        format!("run.duration={:.2}", (2.0 * pour_top / 9.81).sqrt() + 0.2),
        format!("run.seed={seed}"),
    ];
    let path = poured(args, &format!("packing_plate_seed{seed}.data"), scenes::column::PACKING, overrides)?;
    let data = grains_dem_service::lammps_data::read(&path).map_err(anyhow::Error::msg)?;
    let top = data.atoms.iter().filter(|a| a.kind == 1).map(|a| a.x[1]).fold(0.0, f64::max);
    if top < TOP + D {
        bail!(
            "{}: the packing is {:.1} mm tall, too short for the plate's bed cut at {:.1} mm; delete it to pour a new one",
            path.display(),
            top * 1e3,
            TOP * 1e3
        );
    }
    Ok(path)
}

#[cfg(test)]
mod tests {
    /// The same pour has the same name; other overrides or another scene text, another one.
    #[test]
    fn a_changed_pour_gets_a_new_name() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
        let scene = dir.join(super::scenes::column::PACKING);
        let name = |o: &[&str]| super::pour_name("packing_x.data", &scene, &o.iter().map(|s| s.to_string()).collect::<Vec<_>>()).unwrap();
        let a = name(&["run.seed=1"]);
        assert!(a.starts_with("packing_x_") && a.ends_with(".data"), "{a}");
        assert_eq!(a, name(&["run.seed=1"]));
        assert_ne!(a, name(&["run.seed=2"]));
        let tmp = std::env::temp_dir().join(format!("grains-pour-name-{}.toml", std::process::id()));
        let text = std::fs::read_to_string(&scene).unwrap();
        std::fs::write(&tmp, text.replace("friction = 0.5", "friction = 0.4")).unwrap();
        let other = super::pour_name("packing_x.data", &tmp, &["run.seed=1".to_string()]).unwrap();
        std::fs::remove_file(&tmp).unwrap();
        assert_ne!(a, other, "a changed pour scene kept its name");
    }
}
