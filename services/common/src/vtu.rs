//! VTU frames of point clouds (grains, material points) for ParaView: open
//! `frames/<name>.pvd`.
//!
//! Each frame is an XML UnstructuredGrid of vertices with the given point data, written to a
//! temporary file and renamed; the `.pvd` collection listing every frame with its time is
//! rewritten the same way after each one, so a crash never leaves a half-written frame listed.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Values of a point-data array (`components` values per point, point after point).
pub enum Values<'a> {
    F64(&'a [f64]),
    U64(&'a [u64]),
    I32(&'a [i32]),
}

pub struct Field<'a> {
    pub name: &'a str,
    pub components: usize,
    pub values: Values<'a>,
}

pub struct PointFrames {
    dir: PathBuf,
    name: String,
    written: Vec<(f64, String)>,
}

fn write_atomic(path: &Path, text: &str) -> std::io::Result<()> {
    let tmp = path.with_extension("tmp");
    std::fs::write(&tmp, text)?;
    std::fs::rename(&tmp, path)
}

/// A frame's time as the collection lists it: rounded to 12 significant digits, which takes
/// off the float noise a sum of steps gathers (0.0009999999999999705 s is 0.001 s).
pub fn frame_time(t: f64) -> f64 {
    format!("{t:.11e}").parse().unwrap_or(t)
}

impl PointFrames {
    /// Frames `frames/<name>_<step>.vtu` in the run directory.
    pub fn new(run_dir: &Path, name: &str) -> std::io::Result<Self> {
        let dir = run_dir.join("frames");
        std::fs::create_dir_all(&dir)?;
        Ok(PointFrames {
            dir,
            name: name.into(),
            written: Vec::new(),
        })
    }

    pub fn write(&mut self, step: u64, time: f64, positions: &[[f64; 3]], fields: &[Field]) -> std::io::Result<PathBuf> {
        let n = positions.len();
        let mut s = String::with_capacity(100 * n * (1 + fields.len()) + 1024);
        s.push_str("<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"0.1\" byte_order=\"LittleEndian\">\n<UnstructuredGrid>\n");
        let _ = writeln!(s, "<Piece NumberOfPoints=\"{n}\" NumberOfCells=\"{n}\">");
        s.push_str("<Points>\n<DataArray type=\"Float64\" NumberOfComponents=\"3\" format=\"ascii\">\n");
        for a in positions {
            let _ = writeln!(s, "{} {} {}", a[0], a[1], a[2]);
        }
        s.push_str("</DataArray>\n</Points>\n<Cells>\n<DataArray type=\"Int64\" Name=\"connectivity\" format=\"ascii\">\n");
        for i in 0..n {
            let _ = write!(s, "{i} ");
        }
        s.push_str("\n</DataArray>\n<DataArray type=\"Int64\" Name=\"offsets\" format=\"ascii\">\n");
        for i in 1..=n {
            let _ = write!(s, "{i} ");
        }
        s.push_str("\n</DataArray>\n<DataArray type=\"UInt8\" Name=\"types\" format=\"ascii\">\n");
        for _ in 0..n {
            s.push_str("1 ");
        }
        s.push_str("\n</DataArray>\n</Cells>\n<PointData>\n");
        for f in fields {
            let ty = match f.values {
                Values::F64(_) => "Float64",
                Values::U64(_) => "UInt64",
                Values::I32(_) => "Int32",
            };
            let _ = writeln!(
                s,
                "<DataArray type=\"{ty}\" Name=\"{}\" NumberOfComponents=\"{}\" format=\"ascii\">",
                f.name, f.components
            );
            let sep = |k: usize| if (k + 1).is_multiple_of(f.components) { '\n' } else { ' ' };
            match f.values {
                Values::F64(v) => v.iter().enumerate().for_each(|(k, x)| {
                    let _ = write!(s, "{x}{}", sep(k));
                }),
                Values::U64(v) => v.iter().enumerate().for_each(|(k, x)| {
                    let _ = write!(s, "{x}{}", sep(k));
                }),
                Values::I32(v) => v.iter().enumerate().for_each(|(k, x)| {
                    let _ = write!(s, "{x}{}", sep(k));
                }),
            }
            s.push_str("</DataArray>\n");
        }
        s.push_str("</PointData>\n</Piece>\n</UnstructuredGrid>\n</VTKFile>\n");

        let file = format!("{}_{step:08}.vtu", self.name);
        let path = self.dir.join(&file);
        write_atomic(&path, &s)?;
        self.written.push((time, file));
        let mut pvd = String::from("<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\">\n<Collection>\n");
        for (t, f) in &self.written {
            let _ = writeln!(pvd, "<DataSet timestep=\"{}\" file=\"{f}\"/>", frame_time(*t));
        }
        pvd.push_str("</Collection>\n</VTKFile>\n");
        write_atomic(&self.dir.join(format!("{}.pvd", self.name)), &pvd)?;
        Ok(path)
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn frame_times_lose_the_float_noise_of_summed_steps() {
        let t: f64 = (0..1000).map(|_| 1e-6).sum();
        assert_ne!(t, 0.001, "the sum must carry noise, or the test proves nothing");
        assert_eq!(super::frame_time(t), 0.001);
        assert_eq!(super::frame_time(0.123456789), 0.123456789);
    }
}
