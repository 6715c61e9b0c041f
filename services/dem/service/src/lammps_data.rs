//! LAMMPS data files (`atom_style sphere`): the packing format grains shares with LAMMPS and
//! LIGGGHTS, so that a benchmark runs both codes on the same grains and a packing built once
//! can be reused by scenes.
//!
//! Read: the header counts and box bounds, `Atoms # sphere` lines `id type diameter density x
//! y z [ix iy iz]`, and the optional `Velocities` section `id vx vy vz wx wy wz`. Other
//! sections are skipped. Errors name the file and the line.

use std::path::Path;

#[derive(Clone, Debug, PartialEq)]
pub struct Atom {
    pub id: u64,
    /// LAMMPS atom type (the benchmark beds freeze type 2).
    pub kind: u32,
    /// [m]
    pub diameter: f64,
    /// [kg/m³]
    pub density: f64,
    pub x: [f64; 3],
    pub v: [f64; 3],
    pub omega: [f64; 3],
}

#[derive(Clone, Debug, PartialEq)]
pub struct DataFile {
    /// [lo, hi] per axis [m].
    pub bounds: [[f64; 2]; 3],
    pub atoms: Vec<Atom>,
}

fn parse<T: std::str::FromStr>(path: &Path, line_no: usize, field: &str, what: &str) -> Result<T, String> {
    field
        .parse()
        .map_err(|_| format!("{}:{line_no}: {what} must be a number, got {field:?}", path.display()))
}

pub fn read(path: &Path) -> Result<DataFile, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: cannot read the data file: {e}", path.display()))?;
    let mut bounds = [[0.0; 2]; 3];
    let mut atoms: Vec<Atom> = Vec::new();
    let mut section = "";
    let mut index = std::collections::HashMap::new();
    for (k, raw) in text.lines().enumerate() {
        let line_no = k + 1;
        let line = raw.split('#').next().unwrap_or("").trim();
        if k == 0 || line.is_empty() {
            // The first line is a free title; a section title is followed by a blank line.
            if k > 0 && raw.trim_start().starts_with(char::is_alphabetic) {
                section = raw.split('#').next().unwrap_or("").trim();
            }
            continue;
        }
        if line.starts_with(char::is_alphabetic) {
            section = line;
            continue;
        }
        let f: Vec<&str> = line.split_whitespace().collect();
        match section {
            "Atoms" => {
                if f.len() < 7 {
                    return Err(format!(
                        "{}:{line_no}: an `Atoms # sphere` line has 7 fields (id type diameter density x y z), got {}",
                        path.display(),
                        f.len()
                    ));
                }
                let atom = Atom {
                    id: parse(path, line_no, f[0], "id")?,
                    kind: parse(path, line_no, f[1], "type")?,
                    diameter: parse(path, line_no, f[2], "diameter")?,
                    density: parse(path, line_no, f[3], "density")?,
                    x: [
                        parse(path, line_no, f[4], "x")?,
                        parse(path, line_no, f[5], "y")?,
                        parse(path, line_no, f[6], "z")?,
                    ],
                    v: [0.0; 3],
                    omega: [0.0; 3],
                };
                index.insert(atom.id, atoms.len());
                atoms.push(atom);
            }
            "Velocities" => {
                if f.len() < 7 {
                    return Err(format!(
                        "{}:{line_no}: a `Velocities` line has 7 fields (id vx vy vz wx wy wz), got {}",
                        path.display(),
                        f.len()
                    ));
                }
                let id: u64 = parse(path, line_no, f[0], "id")?;
                let Some(&a) = index.get(&id) else {
                    return Err(format!(
                        "{}:{line_no}: velocity of atom {id}, which the Atoms section does not have",
                        path.display()
                    ));
                };
                for c in 0..3 {
                    atoms[a].v[c] = parse(path, line_no, f[1 + c], "velocity")?;
                    atoms[a].omega[c] = parse(path, line_no, f[4 + c], "angular velocity")?;
                }
            }
            "" => {
                // Header: counts and bounds.
                if let Some(axis) = ["xlo xhi", "ylo yhi", "zlo zhi"].iter().position(|t| line.ends_with(t)) {
                    bounds[axis] = [
                        parse(path, line_no, f[0], "a box bound")?,
                        parse(path, line_no, f[1], "a box bound")?,
                    ];
                }
            }
            _ => {}
        }
    }
    if atoms.is_empty() {
        return Err(format!("{}: no `Atoms` section with atoms", path.display()));
    }
    Ok(DataFile { bounds, atoms })
}

/// Writes a data file LAMMPS reads with `atom_style sphere` (and grains reads back).
pub fn write(path: &Path, data: &DataFile, title: &str) -> std::io::Result<()> {
    use std::fmt::Write as _;
    let mut s = format!(
        "{title}\n\n{} atoms\n{} atom types\n\n",
        data.atoms.len(),
        data.atoms.iter().map(|a| a.kind).max().unwrap_or(1)
    );
    for (k, t) in ["xlo xhi", "ylo yhi", "zlo zhi"].iter().enumerate() {
        let _ = writeln!(s, "{:.12e} {:.12e} {t}", data.bounds[k][0], data.bounds[k][1]);
    }
    s.push_str("\nAtoms # sphere\n\n");
    for a in &data.atoms {
        let _ = writeln!(
            s,
            "{} {} {:.12e} {} {:.12e} {:.12e} {:.12e}",
            a.id, a.kind, a.diameter, a.density, a.x[0], a.x[1], a.x[2]
        );
    }
    s.push_str("\nVelocities\n\n");
    for a in &data.atoms {
        let _ = writeln!(
            s,
            "{} {:e} {:e} {:e} {:e} {:e} {:e}",
            a.id, a.v[0], a.v[1], a.v[2], a.omega[0], a.omega[1], a.omega[2]
        );
    }
    let tmp = path.with_extension("tmp");
    std::fs::write(&tmp, s)?;
    std::fs::rename(tmp, path)
}

/// `n` copies side by side along x (LAMMPS `replicate n 1 1`); ids renumbered.
pub fn replicate_x(data: &DataFile, n: usize) -> DataFile {
    let len = data.bounds[0][1] - data.bounds[0][0];
    let mut atoms = Vec::with_capacity(data.atoms.len() * n);
    for k in 0..n {
        for a in &data.atoms {
            let mut b = a.clone();
            b.x[0] += k as f64 * len;
            b.id = atoms.len() as u64 + 1;
            atoms.push(b);
        }
    }
    let mut bounds = data.bounds;
    bounds[0][1] = bounds[0][0] + n as f64 * len;
    DataFile { bounds, atoms }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_written_file_reads_back_and_errors_name_the_line() {
        let dir = std::env::temp_dir().join(format!("grains-lmp-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let data = DataFile {
            bounds: [[0.0, 0.03], [0.0, 0.03], [0.0, 0.025]],
            atoms: vec![
                Atom {
                    id: 1,
                    kind: 1,
                    diameter: 1.1e-3,
                    density: 2530.0,
                    x: [1e-3, 2e-3, 3e-3],
                    v: [0.1, 0.0, -0.2],
                    omega: [0.0, 5.0, 0.0],
                },
                Atom {
                    id: 2,
                    kind: 2,
                    diameter: 0.9e-3,
                    density: 2530.0,
                    x: [4e-3, 5e-3, 6e-4],
                    v: [0.0; 3],
                    omega: [0.0; 3],
                },
            ],
        };
        let path = dir.join("bed.data");
        write(&path, &data, "test bed").unwrap();
        assert_eq!(read(&path).unwrap(), data);
        let doubled = replicate_x(&data, 2);
        assert_eq!(doubled.atoms.len(), 4);
        assert!((doubled.atoms[2].x[0] - 0.031).abs() < 1e-15 && doubled.bounds[0][1] == 0.06);

        let text = std::fs::read_to_string(&path).unwrap().replace("2 2 9.0", "2 2 nine");
        std::fs::write(&path, text).unwrap();
        let err = read(&path).unwrap_err();
        assert!(err.contains("bed.data:13") && err.contains("diameter"), "{err}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
