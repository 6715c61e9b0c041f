//! The report of `grains validate`: every part contributes a markdown section, its charts and
//! its checks; `report.md` opens with the table of all checks (reference, measured value,
//! tolerance, pass/fail) and the command exits non-zero when one fails.

pub mod chart;

use chart::Chart;
use std::fmt::Write as _;
use std::path::Path;

/// One comparison with a reference.
#[derive(Clone, Debug)]
pub struct Check {
    pub name: String,
    /// What the value is compared with: a paper, an equation, a reference run.
    pub reference: String,
    pub measured: String,
    pub tolerance: String,
    pub pass: bool,
}

/// What one part of the validation produced.
#[derive(Default)]
pub struct Part {
    /// Markdown, headed `## ...`; the charts are appended after it.
    pub md: String,
    pub checks: Vec<Check>,
    /// File stem and caption of each chart written into the report's directory.
    pub charts: Vec<(String, String)>,
    /// File stem and caption of each picture of the runs (a PNG in the report's directory).
    pub pictures: Vec<(String, String)>,
}

impl Part {
    pub fn check(
        &mut self,
        name: impl Into<String>,
        reference: impl Into<String>,
        measured: impl Into<String>,
        tolerance: impl Into<String>,
        pass: bool,
    ) {
        self.checks.push(Check {
            name: name.into(),
            reference: reference.into(),
            measured: measured.into(),
            tolerance: tolerance.into(),
            pass,
        });
    }

    /// Writes the chart (SVG, PNG, CSV) into `dir` and lists it under the part.
    pub fn chart(&mut self, dir: &Path, stem: &str, caption: impl Into<String>, chart: &Chart) -> anyhow::Result<()> {
        chart.write(dir, stem)?;
        self.charts.push((stem.to_string(), caption.into()));
        Ok(())
    }

    pub fn passes(&self) -> bool {
        self.checks.iter().all(|c| c.pass)
    }
}

/// The whole report as markdown: header, the checks of every part, then the parts.
pub fn markdown(title: &str, preamble: &str, parts: &[Part]) -> String {
    let checks: Vec<&Check> = parts.iter().flat_map(|p| &p.checks).collect();
    let failed = checks.iter().filter(|c| !c.pass).count();
    let mut md = format!("# {title}\n\n{preamble}\n\n");
    let _ = writeln!(
        md,
        "**{}**: {} checks, {} failed.\n",
        if failed == 0 { "PASS" } else { "FAIL" },
        checks.len(),
        failed
    );
    md.push_str("| check | reference | measured | tolerance | result |\n|---|---|---|---|---|\n");
    for c in &checks {
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} | {} |",
            cell(&c.name),
            cell(&c.reference),
            cell(&c.measured),
            cell(&c.tolerance),
            if c.pass { "pass" } else { "**FAIL**" }
        );
    }
    for p in parts {
        md.push('\n');
        md.push_str(p.md.trim_end());
        md.push('\n');
        for (stem, caption) in &p.pictures {
            let _ = writeln!(md, "\n![{caption}]({stem}.png)\n\n*{caption}*");
        }
        for (stem, caption) in &p.charts {
            let _ = writeln!(
                md,
                "\n![{caption}]({stem}.png)\n\n*{caption}* ([SVG]({stem}.svg), [data]({stem}.csv))"
            );
        }
    }
    md
}

fn cell(s: &str) -> String {
    s.replace('|', "/").replace('\n', " ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_report_fails_when_one_check_does() {
        let mut a = Part::default();
        a.check("x", "paper", "1.0", "±1", true);
        let mut b = Part::default();
        b.check("y|z", "eq. 2", "3", "±1", false);
        b.md = "## B".into();
        let md = markdown("t", "p", &[a, b]);
        assert!(md.contains("**FAIL**: 2 checks, 1 failed."), "{md}");
        assert!(md.contains("| y/z | eq. 2 | 3 | ±1 | **FAIL** |"), "{md}");
    }
}
