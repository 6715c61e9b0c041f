//! VTU frames of point clouds (grains, material points) for ParaView: open
//! `frames/<name>.pvd`. Written by the solvers ([`PointFrames`]) and read back by validation
//! and tests ([`Frame::read`], [`collection`]) in this one place.
//!
//! Each frame is an XML UnstructuredGrid of vertices with the given point data, written to a
//! temporary file and renamed; the `.pvd` collection listing every frame with its time is
//! rewritten the same way after each one, so a crash never leaves a half-written frame listed.

use anyhow::{Context, bail};
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

/// A frame read back: the points and every point-data array (values as numbers, point after
/// point, `components` per point).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Frame {
    pub points: Vec<[f64; 3]>,
    pub arrays: Vec<(String, usize, Vec<f64>)>,
}

impl Frame {
    /// Reads a VTU file as [`PointFrames`] writes it (ASCII data arrays).
    pub fn read(path: &Path) -> anyhow::Result<Frame> {
        let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        Self::parse(&text).with_context(|| format!("{}: not a VTU frame of grains or points", path.display()))
    }

    pub fn parse(text: &str) -> anyhow::Result<Frame> {
        let doc = roxmltree::Document::parse(text)?;
        let piece = doc.descendants().find(|n| n.has_tag_name("Piece")).context("no <Piece>")?;
        let n: usize = piece
            .attribute("NumberOfPoints")
            .context("<Piece> without NumberOfPoints")?
            .parse()
            .context("NumberOfPoints is not a count")?;
        let points = piece.children().find(|c| c.has_tag_name("Points")).context("no <Points>")?;
        let xyz = points
            .children()
            .find(|c| c.has_tag_name("DataArray"))
            .context("<Points> without a DataArray")?;
        let flat = values(&xyz, n * 3)?;
        let mut frame = Frame {
            points: flat.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
            arrays: Vec::new(),
        };
        if let Some(data) = piece.children().find(|c| c.has_tag_name("PointData")) {
            for a in data.children().filter(|c| c.has_tag_name("DataArray")) {
                let name = a.attribute("Name").context("a point-data array without a Name")?;
                let components: usize = a.attribute("NumberOfComponents").unwrap_or("1").parse()?;
                let v = values(&a, n * components).with_context(|| format!("array {name}"))?;
                frame.arrays.push((name.to_string(), components, v));
            }
        }
        Ok(frame)
    }

    /// Point-data array `name`, if the frame has it.
    pub fn array(&self, name: &str) -> Option<&[f64]> {
        self.arrays.iter().find(|(n, _, _)| n == name).map(|(_, _, v)| v.as_slice())
    }
}

/// The values of an ASCII data array, which must hold `expected` of them.
fn values(node: &roxmltree::Node, expected: usize) -> anyhow::Result<Vec<f64>> {
    let format = node.attribute("format").unwrap_or("ascii");
    if format != "ascii" {
        bail!("data array in format {format:?}: this reader takes \"ascii\"");
    }
    let v: Vec<f64> = node
        .text()
        .unwrap_or("")
        .split_ascii_whitespace()
        .map(|w| w.parse::<f64>().with_context(|| format!("{w:?} is not a number")))
        .collect::<anyhow::Result<_>>()?;
    if v.len() != expected {
        bail!("{} values, expected {expected}", v.len());
    }
    Ok(v)
}

/// The frames a `.pvd` collection lists: (time, file), in order, the files resolved next to
/// the collection.
pub fn collection(pvd: &Path) -> anyhow::Result<Vec<(f64, PathBuf)>> {
    let text = std::fs::read_to_string(pvd).with_context(|| format!("reading {}", pvd.display()))?;
    let doc = roxmltree::Document::parse(&text).with_context(|| format!("{}: not XML", pvd.display()))?;
    let dir = pvd.parent().unwrap_or(Path::new("."));
    doc.descendants()
        .filter(|n| n.has_tag_name("DataSet"))
        .map(|d| {
            let time = d
                .attribute("timestep")
                .and_then(|t| t.parse().ok())
                .with_context(|| format!("{}: a data set without a timestep", pvd.display()))?;
            let file = d
                .attribute("file")
                .with_context(|| format!("{}: a data set without a file", pvd.display()))?;
            Ok((time, dir.join(file)))
        })
        .collect()
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

    /// What the writer writes, the reader reads: points, arrays of 1 and 3 components, ids;
    /// the collection lists every frame at its time.
    #[test]
    fn frames_and_collections_read_back_what_was_written() {
        use super::*;
        let dir = std::env::temp_dir().join(format!("grains-vtu-test-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let mut frames = PointFrames::new(&dir, "grains").unwrap();
        let x = [[0.5, 1.0, 0.0], [1e-3, -2.25, 3.0]];
        let radius = [5e-4, 6e-4];
        let v = [1.0, 2.0, 3.0, -4.0, -5.0, -6.0];
        let ids = [7u64, 9];
        let fields = [
            Field {
                name: "id",
                components: 1,
                values: Values::U64(&ids),
            },
            Field {
                name: "radius",
                components: 1,
                values: Values::F64(&radius),
            },
            Field {
                name: "velocity",
                components: 3,
                values: Values::F64(&v),
            },
        ];
        let first = frames.write(0, 0.0, &x, &fields).unwrap();
        frames.write(10, 0.0009999999999999705, &x, &fields).unwrap();
        let f = Frame::read(&first).unwrap();
        assert_eq!(f.points, x);
        assert_eq!(f.array("radius").unwrap(), radius);
        assert_eq!(f.array("velocity").unwrap(), v);
        assert_eq!(f.array("id").unwrap(), [7.0, 9.0]);
        assert!(f.array("mass").is_none());
        let list = collection(&dir.join("frames/grains.pvd")).unwrap();
        assert_eq!(list.iter().map(|(t, _)| *t).collect::<Vec<_>>(), [0.0, 0.001]);
        assert_eq!(list[1].1, dir.join("frames/grains_00000010.vtu"));
        // A truncated frame is an error, not a shorter frame.
        let text = std::fs::read_to_string(&first).unwrap();
        let cut = text.replacen("0.5 1 0", "0.5 1", 1);
        assert!(Frame::parse(&cut).is_err());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
