//! Charts of `grains validate`: one plain description ([`Chart`]) drawn twice with `plotters`,
//! as SVG and as PNG, with the data behind it as CSV (`series,x,y`), so that every picture of a
//! report can be checked against its numbers.
//!
//! Text is drawn in DejaVu Sans, built into the binary: charts need no font on the machine.

use anyhow::{Context, anyhow};
use plotters::coord::Shift;
use plotters::prelude::*;
use std::fmt::Write as _;
use std::path::Path;
use std::sync::OnceLock;

/// How a series is drawn.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Kind {
    /// A line through the points in order.
    Line,
    /// A dashed line (fits, references).
    Dashed,
    /// Filled circles.
    Points,
    /// Crosses (failures, unstable runs).
    Crosses,
    /// Filled circles joined by a line.
    LinePoints,
}

#[derive(Clone, Debug)]
pub struct Series {
    pub name: String,
    pub points: Vec<(f64, f64)>,
    pub kind: Kind,
}

impl Series {
    pub fn new(name: impl Into<String>, kind: Kind, points: Vec<(f64, f64)>) -> Self {
        Series {
            name: name.into(),
            points,
            kind,
        }
    }
}

/// A vertical line at x with its label (an analytic limit, a paper's crossover).
#[derive(Clone, Debug)]
pub struct VLine {
    pub x: f64,
    pub label: String,
}

#[derive(Clone, Debug, Default)]
pub struct Chart {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub log_x: bool,
    pub log_y: bool,
    pub series: Vec<Series>,
    pub vlines: Vec<VLine>,
    /// Small text at data points (x, y): which run a point is.
    pub notes: Vec<(f64, f64, String)>,
    /// Legend in the lower left instead of the upper left.
    pub legend_low: bool,
}

const COLOURS: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
];

/// Registers the chart font once per process: DejaVu Sans, built into the binary (the
/// `dejavu` crate), so that charts need nothing from the machine.
pub(crate) fn font() -> anyhow::Result<()> {
    static FONT: OnceLock<Result<(), String>> = OnceLock::new();
    FONT.get_or_init(|| {
        plotters::style::register_font("sans-serif", FontStyle::Normal, dejavu::sans::regular())
            .map_err(|_| "the built-in DejaVu Sans is not a font plotters can read".to_string())
    })
    .clone()
    .map_err(|e| anyhow!(e))
}

impl Chart {
    /// Writes `<stem>.svg`, `<stem>.png` and `<stem>.csv` into `dir`.
    pub fn write(&self, dir: &Path, stem: &str) -> anyhow::Result<()> {
        font()?;
        std::fs::create_dir_all(dir)?;
        std::fs::write(dir.join(format!("{stem}.csv")), self.csv())?;
        let size = (900, 560);
        let svg = dir.join(format!("{stem}.svg"));
        self.draw(SVGBackend::new(&svg, size).into_drawing_area())
            .map_err(|e| anyhow!("{}: {e}", svg.display()))?;
        let png = dir.join(format!("{stem}.png"));
        self.draw(BitMapBackend::new(&png, size).into_drawing_area())
            .map_err(|e| anyhow!("{}: {e}", png.display()))
            .with_context(|| format!("chart {stem}"))?;
        Ok(())
    }

    /// The data of every series, one row per point (and `vline` rows for the lines).
    pub fn csv(&self) -> String {
        let mut s = String::from("series,x,y\n");
        for series in &self.series {
            for (x, y) in &series.points {
                let _ = writeln!(s, "{},{x},{y}", series.name.replace(',', ";"));
            }
        }
        for v in &self.vlines {
            let _ = writeln!(s, "vline: {},{},", v.label.replace(',', ";"), v.x);
        }
        s
    }

    fn map(log: bool, v: f64) -> f64 {
        if log { v.log10() } else { v }
    }

    /// Range of the axis over all finite (and, on a log axis, positive) values, padded 5%.
    fn range(&self, log: bool, pick: impl Fn(&(f64, f64)) -> f64, extra: &[f64]) -> (f64, f64) {
        let values = self
            .series
            .iter()
            .flat_map(|s| s.points.iter().map(&pick))
            .chain(extra.iter().copied())
            .filter(|v| v.is_finite() && (!log || *v > 0.0))
            .map(|v| Self::map(log, v));
        let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| (a.min(v), b.max(v)));
        if !lo.is_finite() {
            return (0.0, 1.0);
        }
        let pad = if hi > lo { 0.05 * (hi - lo) } else { 0.5 * lo.abs().max(1.0) };
        (lo - pad, hi + pad)
    }

    fn draw<DB: DrawingBackend>(&self, root: DrawingArea<DB, Shift>) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
        root.fill(&WHITE)?;
        let vx: Vec<f64> = self.vlines.iter().map(|v| v.x).collect();
        let (x0, x1) = self.range(self.log_x, |p| p.0, &vx);
        let (y0, y1) = self.range(self.log_y, |p| p.1, &[]);
        let axis = |log: bool| {
            move |v: &f64| {
                if log { significant(10f64.powf(*v)) } else { format!("{v:.4}") }
            }
        };
        let (fx, fy) = (axis(self.log_x), axis(self.log_y));
        let mut chart = ChartBuilder::on(&root)
            .caption(&self.title, ("sans-serif", 20))
            .margin(12)
            .x_label_area_size(45)
            .y_label_area_size(70)
            .build_cartesian_2d(x0..x1, y0..y1)?;
        chart
            .configure_mesh()
            .x_desc(&self.x_label)
            .y_desc(&self.y_label)
            .x_label_formatter(&|v| trim(fx(v)))
            .y_label_formatter(&|v| trim(fy(v)))
            .light_line_style(WHITE.mix(0.0))
            .draw()?;
        let (lx, ly) = (self.log_x, self.log_y);
        let pt = |&(x, y): &(f64, f64)| (Self::map(lx, x), Self::map(ly, y));
        let ok = |p: &(f64, f64)| p.0.is_finite() && p.1.is_finite() && (!lx || p.0 > 0.0) && (!ly || p.1 > 0.0);
        for (i, s) in self.series.iter().enumerate() {
            let colour = COLOURS[i % COLOURS.len()];
            let pts: Vec<(f64, f64)> = s.points.iter().filter(|p| ok(p)).map(pt).collect();
            let style = colour.stroke_width(2);
            // Lines break where a point is not finite (two laws on either side of a gap).
            let pieces = || s.points.split(|p| !ok(p)).map(|piece| piece.iter().map(pt).collect::<Vec<_>>());
            let anno = match s.kind {
                Kind::Line => chart.draw_series(pieces().flat_map(|p| LineSeries::new(p, style)))?,
                Kind::Dashed => chart.draw_series(pieces().flat_map(|p| DashedLineSeries::new(p, 8, 5, style)))?,
                Kind::Points => chart.draw_series(pts.into_iter().map(|p| Circle::new(p, 5, colour.filled())))?,
                Kind::Crosses => chart.draw_series(pts.into_iter().map(|p| Cross::new(p, 6, colour.stroke_width(2))))?,
                Kind::LinePoints => {
                    chart.draw_series(pts.iter().map(|&p| Circle::new(p, 4, colour.filled())))?;
                    chart.draw_series(LineSeries::new(pts, style))?
                }
            };
            anno.label(s.name.as_str())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], colour.stroke_width(3)));
        }
        for v in &self.vlines {
            let x = Self::map(lx, v.x);
            chart.draw_series(DashedLineSeries::new(vec![(x, y0), (x, y1)], 6, 4, BLACK.stroke_width(1)))?;
            chart.draw_series(std::iter::once(Text::new(
                v.label.clone(),
                (x, y1 - 0.04 * (y1 - y0)),
                ("sans-serif", 14).into_font(),
            )))?;
        }
        for (x, y, text) in &self.notes {
            let p = (Self::map(lx, *x), Self::map(ly, *y));
            if ok(&(*x, *y)) {
                chart.draw_series(std::iter::once(Text::new(text.clone(), p, ("sans-serif", 11).into_font())))?;
            }
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK.mix(0.4))
            .position(if self.legend_low {
                SeriesLabelPosition::LowerLeft
            } else {
                SeriesLabelPosition::UpperLeft
            })
            .draw()?;
        root.present()
    }
}

/// A tick of a log axis with two significant digits: 0.063, 1.6, 250, 1e-6.
fn significant(p: f64) -> String {
    if !(1e-3..1e5).contains(&p) {
        return format!("{p:.0e}");
    }
    let decimals = (1 - p.log10().floor() as i32).max(0) as usize;
    trim(format!("{p:.decimals$}"))
}

/// "1.500" → "1.5", "2.000" → "2".
fn trim(s: String) -> String {
    if s.contains('.') && !s.contains('e') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

/// Indices of the points on the Pareto front of (cost, error), both to be small: no other
/// point is at most as costly and at most as wrong while better in one of them.
pub fn pareto_front(points: &[(f64, f64)]) -> Vec<usize> {
    (0..points.len())
        .filter(|&i| {
            let (c, e) = points[i];
            !points.iter().any(|&(c2, e2)| c2 <= c && e2 <= e && (c2 < c || e2 < e))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pareto_front_keeps_the_points_nothing_beats() {
        // (wall, error): (1, 9) cheapest, (3, 2) and (10, 1) better in error; (4, 5) is beaten
        // by (3, 2); (3, 3) by (3, 2).
        let pts = [(10.0, 1.0), (4.0, 5.0), (1.0, 9.0), (3.0, 2.0), (3.0, 3.0)];
        assert_eq!(pareto_front(&pts), vec![0, 2, 3]);
    }

    /// Both pictures are written and the CSV holds every point.
    #[test]
    fn a_chart_writes_svg_png_and_its_data() {
        let dir = std::env::temp_dir().join(format!("grains-chart-{}", std::process::id()));
        let chart = Chart {
            title: "test".into(),
            x_label: "x".into(),
            y_label: "y".into(),
            log_x: true,
            series: vec![
                Series::new("a", Kind::LinePoints, vec![(1.0, 1.0), (10.0, 2.0), (100.0, 3.0)]),
                Series::new("b, fit", Kind::Dashed, vec![(1.0, 0.5), (100.0, 2.5)]),
            ],
            vlines: vec![VLine {
                x: 20.0,
                label: "limit".into(),
            }],
            ..Chart::default()
        };
        chart.write(&dir, "c").unwrap();
        let svg = std::fs::read_to_string(dir.join("c.svg")).unwrap();
        assert!(svg.contains("<svg") && svg.contains("limit"), "{svg}");
        let png = std::fs::read(dir.join("c.png")).unwrap();
        assert_eq!(&png[1..4], b"PNG");
        let csv = std::fs::read_to_string(dir.join("c.csv")).unwrap();
        assert_eq!(csv.lines().count(), 1 + 3 + 2 + 1, "{csv}");
        assert!(csv.contains("b; fit,100,2.5"), "{csv}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
