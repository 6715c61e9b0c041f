//! `metrics.csv`, one row per macro-step of a run: written here by the launcher
//! ([`MetricsWriter`]) and read back here by everything that looks at a run afterwards
//! ([`MetricsTable`]: validation, benchmarks, tests). The columns are `step`, `time`, then per
//! participant `<role>_<field>` for each of [`FIELDS`], then the timing columns (`wall_s`,
//! `<role>_compute_ms`, `<role>_wait_ms`), the only ones that differ between two runs.
//!
//! Nothing is half-written: rows stream into `metrics.csv.part` (flushed about once a second,
//! so a crash of the launcher itself loses at most that) and the file is renamed to
//! `metrics.csv` when the run ends, however it ends.

use anyhow::{Context, bail};
use grains_protocol::Role;
use grains_protocol::wire::Summary;
use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// The physics columns of each participant, `<role>_<field>`: items (grains, points, shared
/// nodes, zone cells), raster nodes, mass, momentum, kinetic energy, checksum (hex).
pub const FIELDS: [&str; 8] = ["items", "nodes", "mass", "px", "py", "pz", "ke", "checksum"];

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

/// How many of the last rows [`MetricsWriter`] remembers for a late `checkpoint` acknowledgement.
const RECENT_ROWS: usize = 1024;

/// The header of a run with `roles`.
pub fn header(roles: &[Role]) -> Vec<String> {
    let mut header = vec!["step".to_string(), "time".to_string()];
    for r in roles {
        header.extend(FIELDS.iter().map(|f| format!("{}_{f}", r.name())));
    }
    header.push("wall_s".into());
    for r in roles {
        header.push(format!("{}_compute_ms", r.name()));
        header.push(format!("{}_wait_ms", r.name()));
    }
    header
}

/// Assembles rows from the participants' summaries and streams them to disk in step order.
pub struct MetricsWriter {
    roles: Vec<Role>,
    pending: BTreeMap<u64, Vec<Option<Summary>>>,
    next_step: u64,
    out: BufWriter<File>,
    part: PathBuf,
    last_flush: Instant,
    started: Instant,
    /// `wall_s` of the run before it was resumed (0 for a fresh run).
    wall_before: f64,
    /// Bytes in the file so far.
    bytes: u64,
    /// Last complete row: (step, simulated time at its end).
    pub last: Option<(u64, f64)>,
    /// Steps whose rows close a checkpoint ([`MetricsWriter::checkpoint_at`]), written and
    /// not yet taken: (step, time, the file's length after the row, its `wall_s`).
    pub checkpoint_rows: Vec<(u64, f64, u64, f64)>,
    /// `output.checkpoint_every` and `run.steps` of the run (0: no checkpoints).
    checkpoints: (u64, u64),
    /// Checkpoints asked for by a command, whose rows are not written yet.
    asked: Vec<u64>,
    /// The last rows written, as `checkpoint_rows` lists them (an acknowledgement of a
    /// `checkpoint` command may be read after its step's row is written).
    recent: std::collections::VecDeque<(u64, f64, u64, f64)>,
}

impl MetricsWriter {
    pub fn create(dir: &Path, roles: &[Role]) -> std::io::Result<Self> {
        let part = dir.join("metrics.csv.part");
        let mut out = BufWriter::new(File::create(&part)?);
        let head = format!("{}\n", header(roles).join(","));
        out.write_all(head.as_bytes())?;
        Ok(Self::writer(roles, out, part, 1, head.len() as u64))
    }

    /// Appends to the `metrics.csv.part` of a run resumed after `step` (at `time`, `wall_s`),
    /// already cut back to its rows up to that step.
    pub fn resume(dir: &Path, roles: &[Role], step: u64, time: f64, wall_s: f64) -> std::io::Result<Self> {
        let part = dir.join("metrics.csv.part");
        let file = std::fs::OpenOptions::new().append(true).open(&part)?;
        let bytes = file.metadata()?.len();
        let mut m = Self::writer(roles, BufWriter::new(file), part, step + 1, bytes);
        m.last = Some((step, time));
        m.wall_before = wall_s;
        Ok(m)
    }

    fn writer(roles: &[Role], out: BufWriter<File>, part: PathBuf, next_step: u64, bytes: u64) -> Self {
        MetricsWriter {
            roles: roles.to_vec(),
            pending: BTreeMap::new(),
            next_step,
            out,
            part,
            last_flush: Instant::now(),
            started: Instant::now(),
            wall_before: 0.0,
            bytes,
            last: None,
            checkpoint_rows: Vec::new(),
            checkpoints: (0, 0),
            asked: Vec::new(),
            recent: std::collections::VecDeque::new(),
        }
    }

    /// The rows of the run's checkpoint steps are listed in `checkpoint_rows`.
    pub fn checkpoint_at(&mut self, every: u64, steps: u64) {
        self.checkpoints = (every, steps);
    }

    /// A checkpoint after `step` too (a `checkpoint` command's).
    pub fn checkpoint_also(&mut self, step: u64) {
        match self.recent.iter().find(|r| r.0 == step) {
            Some(row) => self.checkpoint_rows.push(*row),
            None if step >= self.next_step => self.asked.push(step),
            None => tracing::warn!("a checkpoint after step {step} was asked for too late to record"),
        }
    }

    /// Every row written so far on disk, synced (before a checkpoint's manifest names them).
    pub fn sync(&mut self) -> std::io::Result<()> {
        self.out.flush()?;
        self.out.get_ref().sync_data()
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
        let wall = self.wall_before + self.started.elapsed().as_secs_f64();
        line.push_str(&format!(",{wall:.6}"));
        for s in row.iter().flatten() {
            line.push_str(&format!(",{:.4},{:.4}", s.compute_ns as f64 * 1e-6, s.wait_ns as f64 * 1e-6));
        }
        line.push('\n');
        self.out.write_all(line.as_bytes())?;
        self.bytes += line.len() as u64;
        self.last = Some((first.step, first.time));
        let row = (first.step, first.time, self.bytes, wall);
        let asked = self.asked.contains(&first.step);
        if asked || grains_service::checkpoint::due_at(self.checkpoints.0, self.checkpoints.1, first.step) {
            self.asked.retain(|s| *s != first.step);
            self.checkpoint_rows.push(row);
        }
        if self.recent.len() == RECENT_ROWS {
            self.recent.pop_front();
        }
        self.recent.push_back(row);
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

/// A run's `metrics.csv`, read back by column name. A column that is not there is an error
/// (a misspelt name must not read as zeros); a participant the run did not have is `None`
/// only where the caller asks for it by role ([`MetricsTable::participant`]).
#[derive(Clone, Debug)]
pub struct MetricsTable {
    path: PathBuf,
    columns: Vec<(String, Vec<String>)>,
    rows: usize,
}

impl MetricsTable {
    /// Reads `<run_dir>/metrics.csv`.
    pub fn read(run_dir: &Path) -> anyhow::Result<Self> {
        let path = run_dir.join("metrics.csv");
        let text = std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
        Self::parse(&text, &path)
    }

    /// Parses the text of a metrics file (`path` names it in errors).
    pub fn parse(text: &str, path: &Path) -> anyhow::Result<Self> {
        let mut lines = text.lines();
        let header = lines.next().with_context(|| format!("{}: empty, no header", path.display()))?;
        let mut columns: Vec<(String, Vec<String>)> = header.split(',').map(|c| (c.to_string(), Vec::new())).collect();
        let mut rows = 0;
        for (k, line) in lines.enumerate() {
            let values: Vec<&str> = line.split(',').collect();
            if values.len() != columns.len() {
                bail!(
                    "{}: line {} has {} values, the header {} columns",
                    path.display(),
                    k + 2,
                    values.len(),
                    columns.len()
                );
            }
            for (c, v) in columns.iter_mut().zip(values) {
                c.1.push(v.to_string());
            }
            rows += 1;
        }
        Ok(MetricsTable {
            path: path.to_path_buf(),
            columns,
            rows,
        })
    }

    /// Number of rows (macro-steps written).
    pub fn len(&self) -> usize {
        self.rows
    }

    pub fn is_empty(&self) -> bool {
        self.rows == 0
    }

    /// The values of column `name` as written (checksums are hex).
    pub fn text(&self, name: &str) -> anyhow::Result<&[String]> {
        match self.columns.iter().find(|(c, _)| c == name) {
            Some((_, v)) => Ok(v),
            None => {
                let names: Vec<&str> = self.columns.iter().map(|(c, _)| c.as_str()).collect();
                bail!("{}: no column {name:?}; the columns are {}", self.path.display(), names.join(", "))
            }
        }
    }

    /// Column `name` as numbers.
    pub fn column(&self, name: &str) -> anyhow::Result<Vec<f64>> {
        self.text(name)?
            .iter()
            .enumerate()
            .map(|(k, v)| {
                v.parse::<f64>()
                    .with_context(|| format!("{}: line {}, column {name}: {v:?} is not a number", self.path.display(), k + 2))
            })
            .collect()
    }

    /// Whether the run had `role` (its columns are there).
    pub fn has(&self, role: Role) -> bool {
        let items = format!("{}_items", role.name());
        self.columns.iter().any(|(c, _)| *c == items)
    }

    /// Column `<role>_<field>` when the run had `role`, `None` when it did not.
    pub fn participant(&self, role: Role, field: &str) -> anyhow::Result<Option<Vec<f64>>> {
        if !self.has(role) {
            return Ok(None);
        }
        self.column(&format!("{}_{field}", role.name())).map(Some)
    }

    /// First value of column `name` (error without rows).
    pub fn first(&self, name: &str) -> anyhow::Result<f64> {
        self.nonempty(name)?.first().copied().context("no rows")
    }

    /// Last value of column `name` (error without rows).
    pub fn last(&self, name: &str) -> anyhow::Result<f64> {
        self.nonempty(name)?.last().copied().context("no rows")
    }

    /// Mean of column `name` over the rows (error without rows).
    pub fn mean(&self, name: &str) -> anyhow::Result<f64> {
        let v = self.nonempty(name)?;
        Ok(v.iter().sum::<f64>() / v.len() as f64)
    }

    fn nonempty(&self, name: &str) -> anyhow::Result<Vec<f64>> {
        let v = self.column(name)?;
        if v.is_empty() {
            bail!("{}: column {name} has no rows", self.path.display());
        }
        Ok(v)
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
        let mut m = MetricsWriter::create(&dir, &[Role::Dem, Role::Coupler]).unwrap();
        let s = |role: Role, step: u64| Summary {
            role: role as u32,
            step,
            time: step as f64,
            kinetic_energy: 0.5 * step as f64,
            ..Summary::default()
        };
        m.add(&s(Role::Dem, 2)).unwrap();
        m.add(&s(Role::Dem, 1)).unwrap();
        m.add(&s(Role::Coupler, 2)).unwrap();
        assert_eq!(m.last, None, "step 1 is incomplete, so step 2 must wait");
        m.add(&s(Role::Coupler, 1)).unwrap();
        assert_eq!(m.last, Some((2, 2.0)));
        assert!(m.add(&s(Role::Dem, 1)).is_err(), "a late summary is an error");
        m.finish().unwrap();
        // Read back by the typed reader: the columns the writer wrote, by name.
        let t = MetricsTable::read(&dir).unwrap();
        assert_eq!(t.column("step").unwrap(), [1.0, 2.0]);
        assert_eq!(t.column("dem_ke").unwrap(), [0.5, 1.0]);
        assert_eq!(t.last("coupler_ke").unwrap(), 1.0);
        assert_eq!(t.text("dem_checksum").unwrap()[0], "0000000000000000");
        assert!(t.participant(Role::Mpm, "items").unwrap().is_none(), "the run had no MPM");
        assert_eq!(t.participant(Role::Dem, "items").unwrap(), Some(vec![0.0, 0.0]));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A misspelt column or one a participant does not write is an error naming it, not zeros.
    #[test]
    fn a_missing_column_is_an_error() {
        let t = MetricsTable::parse("step,time,dem_items,wall_s\n1,0.1,5,0.2\n", Path::new("m.csv")).unwrap();
        let e = t.column("dem_itmes").unwrap_err().to_string();
        assert!(e.contains("dem_itmes") && e.contains("dem_items"), "{e}");
        assert!(t.participant(Role::Dem, "kee").is_err());
        assert!(t.first("mpm_items").is_err());
        let bad = MetricsTable::parse("step,time\n1\n", Path::new("m.csv")).unwrap_err().to_string();
        assert!(bad.contains("line 2"), "{bad}");
    }
}
