//! Outputs of a run in `out/<scene>/<run-id>/`: `metrics.csv` (one row per macro-step) and
//! `summary.json`. Nothing is half-written: metrics stream into `metrics.csv.part` (flushed
//! about once a second, so a crash of the launcher itself loses at most that) and are renamed
//! to `metrics.csv` when the run ends, however it ends; `summary.json` is written to a
//! temporary file and renamed.

use grains_protocol::Role;
use grains_protocol::wire::Summary;
use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// Writes `bytes` to `path` atomically (temporary file in the same directory, then rename).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let tmp = path.with_extension("tmp");
    {
        let mut f = File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
    }
    std::fs::rename(&tmp, path)
}

/// Columns whose values vary from run to run (wall-clock timings): they come last, and a
/// comparison of two runs leaves them out (see [`physics_columns`]).
pub fn is_timing_column(name: &str) -> bool {
    name == "wall_s" || name.ends_with("_compute_ms") || name.ends_with("_wait_ms")
}

/// The content of a `metrics.csv` without its timing columns (for byte comparisons).
pub fn physics_columns(csv: &str) -> String {
    let mut lines = csv.lines();
    let Some(header) = lines.next() else { return String::new() };
    let keep: Vec<bool> = header.split(',').map(|c| !is_timing_column(c)).collect();
    let pick = |line: &str| {
        line.split(',')
            .zip(&keep)
            .filter(|(_, k)| **k)
            .map(|(v, _)| v)
            .collect::<Vec<_>>()
            .join(",")
    };
    std::iter::once(header).chain(lines).map(pick).collect::<Vec<_>>().join("\n")
}

/// Assembles rows from the participants' summaries and streams them to disk in step order.
pub struct Metrics {
    roles: Vec<Role>,
    pending: BTreeMap<u64, Vec<Option<Summary>>>,
    next_step: u64,
    out: BufWriter<File>,
    part: PathBuf,
    last_flush: Instant,
    started: Instant,
    /// Last complete row: (step, simulated time at its end).
    pub last: Option<(u64, f64)>,
}

impl Metrics {
    pub fn create(dir: &Path, roles: &[Role]) -> std::io::Result<Self> {
        let part = dir.join("metrics.csv.part");
        let mut out = BufWriter::new(File::create(&part)?);
        let mut header = vec!["step".to_string(), "time".to_string()];
        for r in roles {
            for col in ["items", "nodes", "mass", "px", "py", "pz", "ke", "checksum"] {
                header.push(format!("{}_{col}", r.name()));
            }
        }
        header.push("wall_s".into());
        for r in roles {
            header.push(format!("{}_compute_ms", r.name()));
            header.push(format!("{}_wait_ms", r.name()));
        }
        writeln!(out, "{}", header.join(","))?;
        Ok(Metrics {
            roles: roles.to_vec(),
            pending: BTreeMap::new(),
            next_step: 1,
            out,
            part,
            last_flush: Instant::now(),
            started: Instant::now(),
            last: None,
        })
    }

    /// Restarts the wall clock of the `wall_s` column (at the start of step 1).
    pub fn start_clock(&mut self) {
        self.started = Instant::now();
    }

    /// Takes one summary; writes every row that became complete. Returns an error message
    /// for a summary that cannot belong to the run.
    pub fn add(&mut self, s: &Summary) -> Result<(), String> {
        let Some(col) = Role::from_code(s.role).and_then(|r| self.roles.iter().position(|x| *x == r)) else {
            return Err(format!("summary from an unexpected participant (role code {})", s.role));
        };
        if s.step < self.next_step {
            return Err(format!(
                "summary of step {} from {} arrived after that row was written",
                s.step,
                self.roles[col].binary()
            ));
        }
        let row = self.pending.entry(s.step).or_insert_with(|| vec![None; self.roles.len()]);
        row[col] = Some(*s);
        while let Some(row) = self.pending.get(&self.next_step) {
            if row.iter().any(Option::is_none) {
                break;
            }
            let row = self.pending.remove(&self.next_step).expect("present");
            self.write_row(&row).map_err(|e| format!("writing {}: {e}", self.part.display()))?;
            self.next_step += 1;
        }
        if self.last_flush.elapsed() > Duration::from_secs(1) {
            let _ = self.out.flush();
            self.last_flush = Instant::now();
        }
        Ok(())
    }

    fn write_row(&mut self, row: &[Option<Summary>]) -> std::io::Result<()> {
        let first = row[0].expect("complete row");
        let mut line = format!("{},{}", first.step, first.time);
        for s in row.iter().flatten() {
            line.push_str(&format!(
                ",{},{},{},{},{},{},{},{:016x}",
                s.n_items, s.n_nodes, s.mass, s.momentum[0], s.momentum[1], s.momentum[2], s.kinetic_energy, s.checksum
            ));
        }
        line.push_str(&format!(",{:.6}", self.started.elapsed().as_secs_f64()));
        for s in row.iter().flatten() {
            line.push_str(&format!(",{:.4},{:.4}", s.compute_ns as f64 * 1e-6, s.wait_ns as f64 * 1e-6));
        }
        writeln!(self.out, "{line}")?;
        self.last = Some((first.step, first.time));
        Ok(())
    }

    /// Flushes and renames `metrics.csv.part` to `metrics.csv`. Returns the final path.
    pub fn finish(mut self) -> std::io::Result<PathBuf> {
        self.out.flush()?;
        self.out.get_ref().sync_all()?;
        let done = self.part.with_file_name("metrics.csv");
        std::fs::rename(&self.part, &done)?;
        Ok(done)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn timing_columns_are_left_out_of_comparisons() {
        let csv = "step,time,dem_ke,wall_s,dem_compute_ms,dem_wait_ms\n1,0.1,3.5,0.01,2.0,1.0\n";
        assert_eq!(physics_columns(csv), "step,time,dem_ke\n1,0.1,3.5");
    }

    #[test]
    fn rows_are_written_in_step_order_once_complete() {
        let dir = std::env::temp_dir().join(format!("grains-metrics-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut m = Metrics::create(&dir, &[Role::Dem, Role::Coupler]).unwrap();
        let s = |role: Role, step: u64| Summary {
            role: role as u32,
            step,
            time: step as f64,
            ..Summary::default()
        };
        m.add(&s(Role::Dem, 2)).unwrap();
        m.add(&s(Role::Dem, 1)).unwrap();
        m.add(&s(Role::Coupler, 2)).unwrap();
        assert_eq!(m.last, None, "step 1 is incomplete, so step 2 must wait");
        m.add(&s(Role::Coupler, 1)).unwrap();
        assert_eq!(m.last, Some((2, 2.0)));
        assert!(m.add(&s(Role::Dem, 1)).is_err(), "a late summary is an error");
        let path = m.finish().unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        let steps: Vec<&str> = text.lines().skip(1).map(|l| l.split(',').next().unwrap()).collect();
        assert_eq!(steps, ["1", "2"]);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
