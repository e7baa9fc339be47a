//! Charts of run statistics (`radiosity plot`): any numeric field of the stats JSON against any other,
//! e.g. error against time or element count, one series per label (e.g. the oracle) or per file.
//!
//! Fields are named by JSON paths with dots (`seconds.solve`, `error.relative_rmse`, `settings.eps`);
//! `a+b` sums fields (`seconds.refine+seconds.solve`). A file holds one run (an object) or several (an
//! array of objects); every run is one point. Either axis may be logarithmic. Charts are SVG: its text needs no font files, whereas
//! plotters' PNG backend needs system font libraries to draw labels, so PNG is not offered.

use anyhow::{bail, ensure, Context, Result};
use plotters::coord::ranged1d::{AsRangedCoord, ValueFormatter};
use plotters::prelude::*;
use serde_json::Value;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// What to plot.
#[derive(Clone, Debug, PartialEq)]
pub struct PlotSpec {
    /// Path of the x value (`elements`, `seconds.solve`, `a+b`).
    pub x: String,
    /// Path of the y value (`error.relative_rmse`).
    pub y: String,
    /// Path of the series label (`settings.oracle`); the file name when `None`.
    pub label: Option<String>,
    pub log_x: bool,
    pub log_y: bool,
    pub title: Option<String>,
}

/// One series: its label and its points sorted by x.
#[derive(Clone, Debug, PartialEq)]
pub struct Series {
    pub label: String,
    pub points: Vec<(f64, f64)>,
}

/// The value at a dotted path, if present.
fn lookup<'a>(value: &'a Value, path: &str) -> Option<&'a Value> {
    path.split('.').try_fold(value, |v, key| match v {
        Value::Object(map) => map.get(key),
        Value::Array(items) => key.parse::<usize>().ok().and_then(|i| items.get(i)),
        _ => None,
    })
}

/// The number at `path` (a sum for `a+b`), or a message naming the missing or non-numeric field.
pub fn json_number(value: &Value, path: &str) -> std::result::Result<f64, String> {
    let mut total = 0.0;
    for part in path.split('+') {
        let part = part.trim();
        let v = lookup(value, part).ok_or_else(|| format!("no field '{part}'"))?;
        let n = v
            .as_f64()
            .ok_or_else(|| format!("field '{part}' is not a number ({v})"))?;
        total += n;
    }
    Ok(total)
}

/// The label at `path`: a string as is, any other value in its JSON form.
pub fn json_label(value: &Value, path: &str) -> Option<String> {
    lookup(value, path).map(|v| match v {
        Value::String(s) => s.clone(),
        other => other.to_string(),
    })
}

/// Reads the runs of every file and groups their points into series (in order of first appearance).
pub fn collect_series(files: &[PathBuf], spec: &PlotSpec) -> Result<Vec<Series>> {
    ensure!(!files.is_empty(), "no stats files to plot");
    let mut labelled = Vec::new();
    for file in files {
        let bytes = crate::scene::read_bounded(file)
            .map_err(|e| anyhow::anyhow!("{}: {e}", file.display()))?;
        labelled.extend(run_points(&bytes, file, spec)?);
    }
    Ok(group_series(labelled))
}

/// Groups labelled points into series, in order of first appearance, each sorted by x.
pub fn group_series(labelled: Vec<(String, (f64, f64))>) -> Vec<Series> {
    let mut order: Vec<String> = Vec::new();
    let mut points: BTreeMap<String, Vec<(f64, f64)>> = BTreeMap::new();
    for (label, point) in labelled {
        if !points.contains_key(&label) {
            order.push(label.clone());
        }
        points.entry(label).or_default().push(point);
    }
    order
        .into_iter()
        .map(|label| {
            let mut p = points.remove(&label).unwrap_or_default();
            p.sort_by(|a, b| a.0.total_cmp(&b.0));
            Series { label, points: p }
        })
        .collect()
}

/// The (label, (x, y)) point of every run in one stats file's bytes; `file` names it in messages and
/// labels its runs when `spec.label` is `None`.
pub fn run_points(bytes: &[u8], file: &Path, spec: &PlotSpec) -> Result<Vec<(String, (f64, f64))>> {
    let json: Value = serde_json::from_slice(bytes)
        .with_context(|| format!("{}: not valid JSON", file.display()))?;
    let runs: Vec<&Value> = match &json {
        Value::Array(items) => items.iter().collect(),
        other => vec![other],
    };
    let mut points = Vec::with_capacity(runs.len());
    for (i, run) in runs.into_iter().enumerate() {
        let at = if matches!(json, Value::Array(_)) {
            format!("{} (run {i})", file.display())
        } else {
            file.display().to_string()
        };
        let x = json_number(run, &spec.x).map_err(|e| anyhow::anyhow!("{at}: x: {e}"))?;
        let y = json_number(run, &spec.y).map_err(|e| anyhow::anyhow!("{at}: y: {e}"))?;
        for (axis, v, log) in [("x", x, spec.log_x), ("y", y, spec.log_y)] {
            ensure!(v.is_finite(), "{at}: {axis} value {v} is not finite");
            ensure!(
                !log || v > 0.0,
                "{at}: {axis} value {v} cannot be shown on a log scale"
            );
        }
        let label = match &spec.label {
            Some(path) => json_label(run, path)
                .ok_or_else(|| anyhow::anyhow!("{at}: label: no field '{path}'"))?,
            None => file_label(file),
        };
        points.push((label, (x, y)));
    }
    Ok(points)
}

fn file_label(file: &Path) -> String {
    file.file_stem().map_or_else(
        || file.display().to_string(),
        |s| s.to_string_lossy().into_owned(),
    )
}

/// Series colours: the Tableau 10 palette, distinct and legible on white.
const PALETTE: [(u8, u8, u8); 10] = [
    (31, 119, 180),
    (255, 127, 14),
    (44, 160, 44),
    (214, 39, 40),
    (148, 103, 189),
    (140, 86, 75),
    (227, 119, 194),
    (127, 127, 127),
    (188, 189, 34),
    (23, 190, 207),
];

/// The data range over `values`, padded by 5% of its width (a factor on log axes); a single value gets
/// a range around it.
fn axis_range(values: impl Iterator<Item = f64>, log: bool) -> std::ops::Range<f64> {
    let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
        (a.min(v), b.max(v))
    });
    if log {
        let pad = if hi > lo { (hi / lo).powf(0.05) } else { 2.0 };
        return (lo / pad)..(hi * pad);
    }
    let pad = if hi > lo {
        0.05 * (hi - lo)
    } else {
        0.5 * lo.abs().max(1.0)
    };
    (lo - pad)..(hi + pad)
}

/// One axis as drawn: a log axis is plotted in `log10` of its values, with labelled ticks at 1, 2 and 5
/// times the powers of ten inside it (plotters' own log scale labels only whole powers at or above the
/// range's first one, so a range within 0.01–0.15 got a single label).
struct Axis {
    log: bool,
    /// In plotted coordinates.
    range: std::ops::Range<f64>,
}

impl Axis {
    fn new(values: impl Iterator<Item = f64>, log: bool) -> Self {
        let range = axis_range(values, log);
        let range = if log {
            range.start.log10()..range.end.log10()
        } else {
            range
        };
        Axis { log, range }
    }

    fn plotted(&self, value: f64) -> f64 {
        if self.log {
            value.log10()
        } else {
            value
        }
    }

    /// A log axis as a plotters coordinate with [`Axis::log_ticks`] as its key points.
    fn log_coord(&self) -> LogTicks {
        LogTicks {
            range: self.range.clone(),
            ticks: self.log_ticks(),
        }
    }

    /// Ticks of a log axis, in plotted coordinates: 1, 2, 5 per decade (1 alone past four decades; every
    /// digit where the range holds fewer than two of those, as 1.1 to 1.9 does).
    fn log_ticks(&self) -> Vec<f64> {
        let ticks = |mantissas: &[f64]| -> Vec<f64> {
            let (first, last) = (
                self.range.start.floor() as i32,
                self.range.end.ceil() as i32,
            );
            (first..=last)
                .flat_map(|k| mantissas.iter().map(move |m| (m * 10f64.powi(k)).log10()))
                .filter(|t| self.range.contains(t))
                .collect()
        };
        if self.range.end - self.range.start > 4.0 {
            return ticks(&[1.0]);
        }
        for mantissas in [
            &[1.0, 2.0, 5.0][..],
            &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0],
        ] {
            let found = ticks(mantissas);
            if found.len() >= 2 {
                return found;
            }
        }
        // Within one digit's step: evenly spaced round values, as on a linear axis.
        let (lo, hi) = (10f64.powf(self.range.start), 10f64.powf(self.range.end));
        let step = super::round_step(hi - lo, 4.0);
        let first = (lo / step).ceil() as i64;
        (first..)
            .map(|k| k as f64 * step)
            .take_while(|&v| v <= hi)
            .map(f64::log10)
            .collect()
    }

    /// The label of plotted coordinate `at`: the value, rounded to ten significant digits (a tick's
    /// `10^log10(v)`, or a key point's `0.1 · 3`, gives back a few ulps off), in exponent form outside
    /// 0.0001 to 100000 on a log axis.
    fn label(&self, at: f64) -> String {
        let value = if self.log { 10f64.powf(at) } else { at };
        let value: f64 = format!("{value:.9e}").parse().unwrap_or(value);
        if self.log && !(-4.0..6.0).contains(&value.log10().floor()) {
            format!("{value:e}")
        } else {
            format!("{value}")
        }
    }
}

/// A log axis in plotted (`log10`) coordinates: linear mapping, labelled at its own ticks.
struct LogTicks {
    range: std::ops::Range<f64>,
    ticks: Vec<f64>,
}

impl Ranged for LogTicks {
    type FormatOption = plotters::coord::ranged1d::DefaultFormatting;
    type ValueType = f64;

    fn map(&self, value: &f64, limit: (i32, i32)) -> i32 {
        let fraction = (value - self.range.start) / (self.range.end - self.range.start);
        limit.0 + (fraction * f64::from(limit.1 - limit.0)).round() as i32
    }

    fn key_points<Hint: plotters::coord::ranged1d::KeyPointHint>(&self, _hint: Hint) -> Vec<f64> {
        self.ticks.clone()
    }

    fn range(&self) -> std::ops::Range<f64> {
        self.range.clone()
    }
}

/// The chart as SVG text.
pub fn svg(series: &[Series], spec: &PlotSpec) -> Result<String> {
    ensure!(
        series.iter().any(|s| !s.points.is_empty()),
        "no points to plot"
    );
    let all = || series.iter().flat_map(|s| s.points.iter().copied());
    let x = Axis::new(all().map(|p| p.0), spec.log_x);
    let y = Axis::new(all().map(|p| p.1), spec.log_y);
    let plotted: Vec<Series> = series
        .iter()
        .map(|s| Series {
            label: s.label.clone(),
            points: s
                .points
                .iter()
                .map(|&(px, py)| (x.plotted(px), y.plotted(py)))
                .collect(),
        })
        .collect();
    let mut out = String::new();
    {
        let root = SVGBackend::with_string(&mut out, (800, 560)).into_drawing_area();
        let (xr, yr) = (x.range.clone(), y.range.clone());
        match (x.log, y.log) {
            (false, false) => draw(&root, &plotted, spec, (&x, &y), xr, yr)?,
            (true, false) => draw(&root, &plotted, spec, (&x, &y), x.log_coord(), yr)?,
            (false, true) => draw(&root, &plotted, spec, (&x, &y), xr, y.log_coord())?,
            (true, true) => draw(
                &root,
                &plotted,
                spec,
                (&x, &y),
                x.log_coord(),
                y.log_coord(),
            )?,
        }
        root.present().map_err(draw_error)?;
    }
    Ok(out)
}

/// Draws axes, one line with markers per series, and the legend; `series` are in plotted coordinates
/// and `axes` label them.
fn draw<X, Y>(
    root: &DrawingArea<SVGBackend, plotters::coord::Shift>,
    series: &[Series],
    spec: &PlotSpec,
    axes: (&Axis, &Axis),
    x: X,
    y: Y,
) -> Result<()>
where
    X: AsRangedCoord<Value = f64>,
    Y: AsRangedCoord<Value = f64>,
    X::CoordDescType: ValueFormatter<f64>,
    Y::CoordDescType: ValueFormatter<f64>,
{
    root.fill(&WHITE).map_err(draw_error)?;
    let title = spec
        .title
        .clone()
        .unwrap_or_else(|| format!("{} vs {}", spec.y, spec.x));
    let mut chart = ChartBuilder::on(root)
        .caption(title, ("sans-serif", 22))
        .margin(16)
        .x_label_area_size(52)
        .y_label_area_size(80)
        .build_cartesian_2d(x, y)
        .map_err(draw_error)?;
    let (x_label, y_label) = (|v: &f64| axes.0.label(*v), |v: &f64| axes.1.label(*v));
    chart
        .configure_mesh()
        .x_desc(spec.x.as_str())
        .y_desc(spec.y.as_str())
        .x_label_formatter(&x_label)
        .y_label_formatter(&y_label)
        .label_style(("sans-serif", 13))
        .axis_desc_style(("sans-serif", 15))
        .draw()
        .map_err(draw_error)?;
    for (i, s) in series.iter().enumerate() {
        let (r, g, b) = PALETTE[i % PALETTE.len()];
        let colour = RGBColor(r, g, b);
        if s.points.len() > 1 {
            chart
                .draw_series(LineSeries::new(
                    s.points.iter().copied(),
                    colour.stroke_width(2),
                ))
                .map_err(draw_error)?;
        }
        chart
            .draw_series(s.points.iter().map(|&p| Circle::new(p, 4, colour.filled())))
            .map_err(draw_error)?
            .label(s.label.clone())
            .legend(move |(x, y)| {
                EmptyElement::at((x, y))
                    + PathElement::new(vec![(0, 0), (20, 0)], colour.stroke_width(2))
                    + Circle::new((10, 0), 4, colour.filled())
            });
    }
    chart
        .configure_series_labels()
        .label_font(("sans-serif", 14))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .position(SeriesLabelPosition::UpperRight)
        .draw()
        .map_err(draw_error)?;
    Ok(())
}

fn draw_error<E: std::fmt::Debug>(e: E) -> anyhow::Error {
    anyhow::anyhow!("drawing the chart: {e:?}")
}

/// Reads the stats files and writes the chart; the output must be `.svg`.
pub fn plot(files: &[PathBuf], spec: &PlotSpec, output: &Path) -> Result<Vec<Series>> {
    let extension = output
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    if extension != "svg" {
        bail!(
            "{}: charts are written as SVG only (PNG would need system fonts); use a .svg name",
            output.display()
        );
    }
    let series = collect_series(files, spec)?;
    let text = svg(&series, spec)?;
    super::write_atomically(output, |to| {
        std::fs::write(to, &text).with_context(|| format!("{}: cannot write", output.display()))
    })?;
    Ok(series)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paths_and_sums() {
        let v: Value = serde_json::json!({"a": 1, "b": {"c": 2.5, "d": "x"}, "e": [4, 5]});
        assert_eq!(json_number(&v, "a"), Ok(1.0));
        assert_eq!(json_number(&v, "a+b.c"), Ok(3.5));
        assert_eq!(json_number(&v, "e.1"), Ok(5.0));
        assert!(json_number(&v, "b.z").unwrap_err().contains("'b.z'"));
        assert!(json_number(&v, "b.d").unwrap_err().contains("not a number"));
        assert_eq!(json_label(&v, "b.d").as_deref(), Some("x"));
        assert_eq!(json_label(&v, "a").as_deref(), Some("1"));
    }

    #[test]
    fn log_axes_are_labelled_at_one_two_and_five_times_powers_of_ten() {
        let labels = |values: &[f64]| {
            let axis = Axis::new(values.iter().copied(), true);
            let ticks = axis.log_ticks();
            ticks.iter().map(|&t| axis.label(t)).collect::<Vec<_>>()
        };
        // Within one decade below 1 (plotters' own log scale labelled only 0.1 here).
        assert_eq!(labels(&[0.012, 0.15]), ["0.02", "0.05", "0.1"]);
        assert_eq!(labels(&[0.17, 5.7]), ["0.2", "0.5", "1", "2", "5"]);
        assert_eq!(
            labels(&[30.0, 4000.0]),
            ["50", "100", "200", "500", "1000", "2000", "5000"]
        );
        assert_eq!(labels(&[1.25, 1.9]), ["1.4", "1.6", "1.8"]);
        assert_eq!(labels(&[2.1, 3.9]), ["3", "4"]);
        assert_eq!(labels(&[0.11, 0.45]), ["0.2", "0.3", "0.4"]);
        let linear = Axis::new([0.0, 1.0].into_iter(), false);
        assert_eq!(linear.label(0.1 * 3.0), "0.3");
        // Past four decades, the powers alone.
        assert_eq!(
            labels(&[1e-6, 1.0]),
            ["1e-6", "1e-5", "0.0001", "0.001", "0.01", "0.1", "1"]
        );
    }
}
