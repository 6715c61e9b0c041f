//! Per-step CSV logs of a participant (`walls.csv`, `bodies.csv`).

/// A CSV of one row per macro-step (`walls.csv`, `bodies.csv`), flushed every row: a run
/// resumed from a checkpoint finds every row up to it.
pub struct StepLog(std::io::BufWriter<std::fs::File>);

impl StepLog {
    /// A new log with the columns `step,time` + `columns`; or, resuming after a step, the
    /// existing one with its rows up to that step kept, open to append.
    pub fn open(path: &std::path::Path, columns: &str, resume: Option<u64>) -> std::io::Result<StepLog> {
        use std::io::Write as _;
        let Some(step) = resume else {
            let mut f = std::io::BufWriter::new(std::fs::File::create(path)?);
            writeln!(f, "step,time{columns}")?;
            return Ok(StepLog(f));
        };
        let text = std::fs::read_to_string(path)?;
        let mut kept = String::new();
        for (k, line) in text.lines().enumerate() {
            let row_step = line.split(',').next().and_then(|s| s.parse::<u64>().ok());
            if k == 0 || row_step.is_some_and(|s| s <= step) {
                kept.push_str(line);
                kept.push('\n');
            }
        }
        std::fs::write(path, kept)?;
        Ok(StepLog(std::io::BufWriter::new(
            std::fs::OpenOptions::new().append(true).open(path)?,
        )))
    }

    pub fn row(&mut self, row: &str) -> std::io::Result<()> {
        use std::io::Write as _;
        writeln!(self.0, "{row}")?;
        self.0.flush()
    }
}
