//! VTU frames of the grains (ParaView: open `frames/grains.pvd`, glyph by `radius`).
//!
//! Each frame is an XML UnstructuredGrid of vertices with point data id, radius, velocity,
//! angular_velocity and contacts, written to a temporary file and renamed; the `.pvd`
//! collection that lists every frame with its time is rewritten the same way after each one.

use grains_dem::pipeline::DemPipeline;
use grains_dem::space::Space;
use grains_dem::state::DemState;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

pub struct FrameWriter {
    dir: PathBuf,
    written: Vec<(f64, String)>,
}

fn write_atomic(path: &Path, text: &str) -> std::io::Result<()> {
    let tmp = path.with_extension("tmp");
    std::fs::write(&tmp, text)?;
    std::fs::rename(&tmp, path)
}

impl FrameWriter {
    pub fn new(run_dir: &Path) -> std::io::Result<Self> {
        let dir = run_dir.join("frames");
        std::fs::create_dir_all(&dir)?;
        Ok(FrameWriter { dir, written: Vec::new() })
    }

    pub fn write<S: Space>(&mut self, step: u64, state: &DemState<S>, pipeline: &DemPipeline<S>) -> std::io::Result<PathBuf> {
        let g = &state.grains;
        let n = g.len();
        let mut s = String::with_capacity(200 * n + 1024);
        s.push_str("<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"0.1\" byte_order=\"LittleEndian\">\n<UnstructuredGrid>\n");
        let _ = writeln!(s, "<Piece NumberOfPoints=\"{n}\" NumberOfCells=\"{n}\">");
        s.push_str("<Points>\n<DataArray type=\"Float64\" NumberOfComponents=\"3\" format=\"ascii\">\n");
        for &x in &g.x {
            let a = S::to_array(x);
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
        s.push_str("\n</DataArray>\n</Cells>\n<PointData Scalars=\"radius\" Vectors=\"velocity\">\n");
        s.push_str("<DataArray type=\"UInt64\" Name=\"id\" format=\"ascii\">\n");
        for id in &g.id {
            let _ = write!(s, "{id} ");
        }
        s.push_str("\n</DataArray>\n<DataArray type=\"Float64\" Name=\"radius\" format=\"ascii\">\n");
        for r in &g.radius {
            let _ = write!(s, "{r} ");
        }
        s.push_str("\n</DataArray>\n<DataArray type=\"Float64\" Name=\"velocity\" NumberOfComponents=\"3\" format=\"ascii\">\n");
        for &v in &g.v {
            let a = S::to_array(v);
            let _ = writeln!(s, "{} {} {}", a[0], a[1], a[2]);
        }
        s.push_str("</DataArray>\n<DataArray type=\"Float64\" Name=\"angular_velocity\" NumberOfComponents=\"3\" format=\"ascii\">\n");
        for &w in &g.omega {
            let a = S::ang_array(w);
            let _ = writeln!(s, "{} {} {}", a[0], a[1], a[2]);
        }
        s.push_str("</DataArray>\n<DataArray type=\"Int32\" Name=\"contacts\" format=\"ascii\">\n");
        for i in 0..n {
            let _ = write!(s, "{} ", pipeline.forces.get(i).map_or(0, |f| f.contacts));
        }
        s.push_str("\n</DataArray>\n</PointData>\n</Piece>\n</UnstructuredGrid>\n</VTKFile>\n");

        let name = format!("grains_{step:08}.vtu");
        let path = self.dir.join(&name);
        write_atomic(&path, &s)?;
        self.written.push((state.time, name));
        let mut pvd = String::from("<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\">\n<Collection>\n");
        for (t, f) in &self.written {
            let _ = writeln!(pvd, "<DataSet timestep=\"{t}\" file=\"{f}\"/>");
        }
        pvd.push_str("</Collection>\n</VTKFile>\n");
        write_atomic(&self.dir.join("grains.pvd"), &pvd)?;
        Ok(path)
    }
}
