//! VTU frames of point clouds (grains, material points) for ParaView: open
//! `frames/<name>.pvd`. Written by the solvers ([`PointFrames`]) and read back by validation
//! and tests ([`Frame::read`], [`collection`]) in this one place.
//!
//! Each frame is an XML UnstructuredGrid of vertices with the given point data, every array in
//! VTK's inline binary format (base64 of a UInt64 byte count and the little-endian values:
//! exact by construction; about the ASCII's size, 16.0 kB against 16.7 kB for a small hybrid
//! frame, as most ASCII values are short), written to a temporary file and renamed; the `.pvd` collection listing every frame with its time is
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

/// The cells of a piece: their points' indices, where each cell ends, the VTK cell type
/// (1 vertex, 7 polygon).
struct Cells {
    connectivity: Vec<i64>,
    offsets: Vec<i64>,
    kind: u8,
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

    /// The frames of a run resumed after `step`: those up to it stay listed, later ones (a
    /// killed run may have written some) are deleted; `None` starts afresh as [`PointFrames::new`].
    pub fn open(run_dir: &Path, name: &str, resume: Option<u64>) -> std::io::Result<Self> {
        let mut frames = Self::new(run_dir, name)?;
        let Some(after) = resume else { return Ok(frames) };
        let step_of = |file: &str| {
            file.strip_prefix(&format!("{name}_"))
                .and_then(|f| f.strip_suffix(".vtu"))
                .and_then(|s| s.parse::<u64>().ok())
        };
        let pvd = frames.dir.join(format!("{name}.pvd"));
        if let Ok(listed) = collection(&pvd) {
            for (t, path) in listed {
                let file = path.file_name().map(|f| f.to_string_lossy().into_owned()).unwrap_or_default();
                if step_of(&file).is_some_and(|s| s <= after) {
                    frames.written.push((t, file));
                }
            }
        }
        for entry in std::fs::read_dir(&frames.dir)?.flatten() {
            let file = entry.file_name().to_string_lossy().into_owned();
            if step_of(&file).is_some_and(|s| s > after) {
                std::fs::remove_file(entry.path())?;
            }
        }
        frames.write_collection()?;
        Ok(frames)
    }

    pub fn write(&mut self, step: u64, time: f64, positions: &[[f64; 3]], fields: &[Field]) -> std::io::Result<PathBuf> {
        let n = positions.len() as i64;
        let cells = Cells {
            connectivity: (0..n).collect(),
            offsets: (1..=n).collect(),
            kind: 1,
        };
        self.write_piece(step, time, positions, &cells, "PointData", fields)
    }

    /// A frame of polygons (rigid bodies' outlines), one cell each (VTK_POLYGON), `fields`
    /// per cell.
    pub fn write_polygons(&mut self, step: u64, time: f64, outlines: &[Vec<[f64; 3]>], fields: &[Field]) -> std::io::Result<PathBuf> {
        let points: Vec<[f64; 3]> = outlines.iter().flatten().copied().collect();
        let mut offsets = Vec::with_capacity(outlines.len());
        let mut end = 0;
        for o in outlines {
            end += o.len() as i64;
            offsets.push(end);
        }
        let cells = Cells {
            connectivity: (0..end).collect(),
            offsets,
            kind: 7,
        };
        self.write_piece(step, time, &points, &cells, "CellData", fields)
    }

    fn write_piece(
        &mut self,
        step: u64,
        time: f64,
        points: &[[f64; 3]],
        cells: &Cells,
        data: &str,
        fields: &[Field],
    ) -> std::io::Result<PathBuf> {
        let (n, m) = (points.len(), cells.offsets.len());
        let mut s = String::with_capacity(40 * n * (2 + fields.len()) + 1024);
        s.push_str(
            "<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\" header_type=\"UInt64\">\n<UnstructuredGrid>\n",
        );
        let _ = writeln!(s, "<Piece NumberOfPoints=\"{n}\" NumberOfCells=\"{m}\">");
        s.push_str("<Points>\n");
        array(&mut s, "Float64", None, 3, points.iter().flatten().flat_map(|x| x.to_le_bytes()));
        s.push_str("</Points>\n<Cells>\n");
        array(
            &mut s,
            "Int64",
            Some("connectivity"),
            1,
            cells.connectivity.iter().flat_map(|i| i.to_le_bytes()),
        );
        array(
            &mut s,
            "Int64",
            Some("offsets"),
            1,
            cells.offsets.iter().flat_map(|i| i.to_le_bytes()),
        );
        array(&mut s, "UInt8", Some("types"), 1, std::iter::repeat_n(cells.kind, m));
        let _ = writeln!(s, "</Cells>\n<{data}>");
        for f in fields {
            let (name, c) = (Some(f.name), f.components);
            match f.values {
                Values::F64(v) => array(&mut s, "Float64", name, c, v.iter().flat_map(|x| x.to_le_bytes())),
                Values::U64(v) => array(&mut s, "UInt64", name, c, v.iter().flat_map(|x| x.to_le_bytes())),
                Values::I32(v) => array(&mut s, "Int32", name, c, v.iter().flat_map(|x| x.to_le_bytes())),
            }
        }
        let _ = writeln!(s, "</{data}>\n</Piece>\n</UnstructuredGrid>\n</VTKFile>");

        let file = format!("{}_{step:08}.vtu", self.name);
        let path = self.dir.join(&file);
        write_atomic(&path, &s)?;
        self.written.push((time, file));
        self.write_collection()?;
        Ok(path)
    }

    fn write_collection(&self) -> std::io::Result<()> {
        let mut pvd = String::from("<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\">\n<Collection>\n");
        for (t, f) in &self.written {
            let _ = writeln!(pvd, "<DataSet timestep=\"{}\" file=\"{f}\"/>", frame_time(*t));
        }
        pvd.push_str("</Collection>\n</VTKFile>\n");
        write_atomic(&self.dir.join(format!("{}.pvd", self.name)), &pvd)
    }
}

/// One `<DataArray>` in the inline binary format: base64 of the byte count (UInt64) followed
/// by the bytes.
fn array(s: &mut String, ty: &str, name: Option<&str>, components: usize, bytes: impl Iterator<Item = u8>) {
    let bytes: Vec<u8> = bytes.collect();
    let mut block = (bytes.len() as u64).to_le_bytes().to_vec();
    block.extend_from_slice(&bytes);
    let name = name.map(|n| format!(" Name=\"{n}\"")).unwrap_or_default();
    let _ = writeln!(
        s,
        "<DataArray type=\"{ty}\"{name} NumberOfComponents=\"{components}\" format=\"binary\">"
    );
    base64_encode(&block, s);
    s.push_str("\n</DataArray>\n");
}

const BASE64: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";

/// RFC 4648 base64 with padding, appended to `out`.
fn base64_encode(bytes: &[u8], out: &mut String) {
    out.reserve(bytes.len().div_ceil(3) * 4);
    for chunk in bytes.chunks(3) {
        let b = [chunk[0], *chunk.get(1).unwrap_or(&0), *chunk.get(2).unwrap_or(&0)];
        let w = u32::from(b[0]) << 16 | u32::from(b[1]) << 8 | u32::from(b[2]);
        for k in 0..4 {
            if k <= chunk.len() {
                out.push(BASE64[(w >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
}

/// RFC 4648 base64 (whitespace ignored, padding required where it belongs).
fn base64_decode(text: &str) -> anyhow::Result<Vec<u8>> {
    let digits: Vec<u8> = text.bytes().filter(|b| !b.is_ascii_whitespace()).collect();
    if !digits.len().is_multiple_of(4) {
        bail!("base64 of {} characters: not a multiple of 4", digits.len());
    }
    let mut out = Vec::with_capacity(digits.len() / 4 * 3);
    for (q, quad) in digits.chunks(4).enumerate() {
        let last = q + 1 == digits.len() / 4;
        let pad = quad.iter().rev().take_while(|&&b| b == b'=').count();
        if pad > 2 || (pad > 0 && !last) {
            bail!("misplaced base64 padding");
        }
        let mut w = 0u32;
        for &b in &quad[..4 - pad] {
            let v = BASE64
                .iter()
                .position(|&c| c == b)
                .with_context(|| format!("{:?} is not a base64 digit", b as char))?;
            w = w << 6 | v as u32;
        }
        w <<= 6 * pad as u32;
        out.extend_from_slice(&w.to_be_bytes()[1..4 - pad]);
    }
    Ok(out)
}

/// A frame read back: the points, where each cell's points end (a frame of polygons: one
/// outline per cell), and every point- or cell-data array (values as numbers, item after
/// item, `components` per item).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Frame {
    pub points: Vec<[f64; 3]>,
    pub arrays: Vec<(String, usize, Vec<f64>)>,
    pub cell_ends: Vec<usize>,
}

impl Frame {
    /// Reads a VTU file as [`PointFrames`] writes it (inline binary data arrays; ASCII ones
    /// too, as earlier versions wrote).
    pub fn read(path: &Path) -> anyhow::Result<Frame> {
        let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        Self::parse(&text).with_context(|| format!("{}: not a VTU frame of grains or points", path.display()))
    }

    pub fn parse(text: &str) -> anyhow::Result<Frame> {
        let doc = roxmltree::Document::parse(text)?;
        let header = match doc.root_element().attribute("header_type").unwrap_or("UInt32") {
            "UInt32" => 4,
            "UInt64" => 8,
            h => bail!("header_type {h:?}: this reader takes UInt32 or UInt64"),
        };
        if let Some(c) = doc.root_element().attribute("compressor") {
            bail!("compressed data ({c}): this reader takes uncompressed frames");
        }
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
        let flat = values(&xyz, n * 3, header)?;
        let cells: usize = piece
            .attribute("NumberOfCells")
            .unwrap_or("0")
            .parse()
            .context("NumberOfCells is not a count")?;
        let offsets = piece
            .children()
            .find(|c| c.has_tag_name("Cells"))
            .and_then(|c| c.children().find(|a| a.attribute("Name") == Some("offsets")));
        let mut frame = Frame {
            points: flat.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
            arrays: Vec::new(),
            cell_ends: match offsets {
                Some(a) => values(&a, cells, header)?.into_iter().map(|o| o as usize).collect(),
                None => Vec::new(),
            },
        };
        for (tag, count) in [("PointData", n), ("CellData", cells)] {
            let Some(data) = piece.children().find(|c| c.has_tag_name(tag)) else {
                continue;
            };
            for a in data.children().filter(|c| c.has_tag_name("DataArray")) {
                let name = a.attribute("Name").context("a data array without a Name")?;
                let components: usize = a.attribute("NumberOfComponents").unwrap_or("1").parse()?;
                let v = values(&a, count * components, header).with_context(|| format!("array {name}"))?;
                frame.arrays.push((name.to_string(), components, v));
            }
        }
        Ok(frame)
    }

    /// Data array `name` (per point, or per cell in a frame of polygons), if the frame has it.
    pub fn array(&self, name: &str) -> Option<&[f64]> {
        self.arrays.iter().find(|(n, _, _)| n == name).map(|(_, _, v)| v.as_slice())
    }
}

/// The values of a data array, ASCII or inline binary (with a byte count of `header` bytes),
/// which must hold `expected` of them.
fn values(node: &roxmltree::Node, expected: usize, header: usize) -> anyhow::Result<Vec<f64>> {
    let text = node.text().unwrap_or("");
    let v: Vec<f64> = match node.attribute("format").unwrap_or("ascii") {
        "ascii" => text
            .split_ascii_whitespace()
            .map(|w| w.parse::<f64>().with_context(|| format!("{w:?} is not a number")))
            .collect::<anyhow::Result<_>>()?,
        "binary" => {
            let block = base64_decode(text)?;
            if block.len() < header {
                bail!("a binary data array of {} bytes has no byte count", block.len());
            }
            let (count, data) = block.split_at(header);
            let count = count.iter().rev().fold(0usize, |acc, &b| acc << 8 | usize::from(b));
            if count != data.len() {
                bail!("a binary data array says {count} bytes and holds {}", data.len());
            }
            let ty = node.attribute("type").context("a data array without a type")?;
            decode(ty, data)?
        }
        f => bail!("data array in format {f:?}: this reader takes \"ascii\" and \"binary\""),
    };
    if v.len() != expected {
        bail!("{} values, expected {expected}", v.len());
    }
    Ok(v)
}

/// Little-endian values of VTK type `ty` as numbers.
fn decode(ty: &str, data: &[u8]) -> anyhow::Result<Vec<f64>> {
    fn each<const N: usize>(data: &[u8], f: impl Fn([u8; N]) -> f64) -> anyhow::Result<Vec<f64>> {
        if !data.len().is_multiple_of(N) {
            bail!("{} bytes are not a whole number of {N}-byte values", data.len());
        }
        Ok(data.chunks_exact(N).map(|c| f(c.try_into().expect("N bytes"))).collect())
    }
    match ty {
        "Float64" => each(data, f64::from_le_bytes),
        "Float32" => each(data, |b| f32::from_le_bytes(b).into()),
        "Int64" => each(data, |b| i64::from_le_bytes(b) as f64),
        "UInt64" => each(data, |b| u64::from_le_bytes(b) as f64),
        "Int32" => each(data, |b| i32::from_le_bytes(b).into()),
        "UInt32" => each(data, |b| u32::from_le_bytes(b).into()),
        "UInt8" => each(data, |b: [u8; 1]| b[0].into()),
        t => bail!("data type {t:?}: this reader takes Float64, Float32, Int64, UInt64, Int32, UInt32, UInt8"),
    }
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
    /// RFC 4648 §10's vectors, and every byte value through a round trip.
    #[test]
    fn base64_follows_rfc_4648() {
        let enc = |b: &[u8]| {
            let mut s = String::new();
            super::base64_encode(b, &mut s);
            s
        };
        for (plain, coded) in [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ] {
            assert_eq!(enc(plain.as_bytes()), coded);
            assert_eq!(super::base64_decode(coded).unwrap(), plain.as_bytes());
        }
        let all: Vec<u8> = (0..=255).collect();
        assert_eq!(super::base64_decode(&enc(&all)).unwrap(), all);
        assert!(super::base64_decode("Zm9").is_err() && super::base64_decode("Zg==Zg==").is_err() && super::base64_decode("Z!==").is_err());
    }

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
        // A frame with a value cut off is an error, not a shorter frame: one Float64 fewer in
        // the positions (its byte count says 40, not 48).
        let text = std::fs::read_to_string(&first).unwrap();
        let mut short = String::new();
        let mut block = 40u64.to_le_bytes().to_vec();
        x.iter().flatten().take(5).for_each(|v| block.extend(v.to_le_bytes()));
        base64_encode(&block, &mut short);
        let start = text.find("format=\"binary\">\n").unwrap() + "format=\"binary\">\n".len();
        let end = start + text[start..].find('\n').unwrap();
        let cut = format!("{}{short}{}", &text[..start], &text[end..]);
        let err = Frame::parse(&cut).unwrap_err();
        assert!(format!("{err:#}").contains("5 values, expected 6"), "{err:#}");
        // The frame is binary, and ASCII frames of earlier runs still read.
        assert!(text.contains("format=\"binary\"") && !text.contains("format=\"ascii\""));
        let ascii = "<VTKFile type=\"UnstructuredGrid\"><UnstructuredGrid><Piece NumberOfPoints=\"1\" NumberOfCells=\"1\">\
            <Points><DataArray type=\"Float64\" NumberOfComponents=\"3\" format=\"ascii\">1 2 3</DataArray></Points>\
            </Piece></UnstructuredGrid></VTKFile>";
        assert_eq!(Frame::parse(ascii).unwrap().points, [[1.0, 2.0, 3.0]]);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
