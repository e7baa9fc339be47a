//! Work-plane illuminance reports (`radiosity grid`): CSV and JSON of the points, and the isolux plot
//! (SVG through plotters: filled false-colour cells, iso-lines at round lux values by marching squares,
//! and a colour bar in lux).

use super::false_colour::ramp;
use crate::measures::illuminance::GridReport;
use anyhow::{Context, Result};
use plotters::prelude::*;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// `x,y,z,lux,error_lux` per point (and `reference_lux,reference_stderr_lux` when the report has a
/// path-traced reference, `inside_solid` (0 or 1) when some point lies inside a solid), row-major.
pub fn csv(report: &GridReport) -> String {
    let reference = report.values.iter().any(|v| v.reference.is_some());
    let inside = report.inside_solid > 0;
    let mut out = String::from("x,y,z,lux,error_lux");
    if reference {
        out.push_str(",reference_lux,reference_stderr_lux");
    }
    if inside {
        out.push_str(",inside_solid");
    }
    out.push('\n');
    for v in &report.values {
        let [x, y, z] = v.point;
        let _ = write!(out, "{x},{y},{z},{},{}", v.lux, v.error_lux);
        if let Some(r) = v.reference {
            let _ = write!(out, ",{},{}", r.value, r.stderr);
        }
        if inside {
            let _ = write!(out, ",{}", u8::from(v.inside_solid));
        }
        out.push('\n');
    }
    out
}

/// The report as JSON: `summary` (statistics in lux, errors, work), `grid`, `settings` (whatever the
/// caller passes, e.g. the solver's and the gather's settings) and `points`.
pub fn json(report: &GridReport, settings: serde_json::Value) -> Result<String> {
    let s = &report.statistics;
    let value = serde_json::json!({
        "units": {
            "illuminance": "lux",
            "conversion": "lux = 179 lm/W × Y(irradiance in W/m²), Y = 0.2126 R + 0.7152 G + 0.0722 B",
        },
        "summary": {
            "points": s.count,
            "points_inside_solids": report.inside_solid,
            "min_lux": s.min,
            "mean_lux": s.mean,
            "max_lux": s.max,
            "uniformity_min_over_mean": s.uniformity,
            "max_over_min": s.max_over_min,
            "max_error_lux": report.max_error_lux,
            "mean_error_lux": report.mean_error_lux,
            "gather_pieces": report.pieces,
            "gather_rays": report.rays,
        },
        "grid": report.grid,
        "settings": settings,
        "points": report.values,
    });
    Ok(serde_json::to_string_pretty(&value)? + "\n")
}

/// The three files `radiosity grid` writes from its `-o` base path (a `.csv`, `.json` or `.svg`
/// extension of the base is replaced).
pub fn output_paths(base: &Path) -> [PathBuf; 3] {
    let own = ["csv", "json", "svg"];
    let base = match base.extension().and_then(|e| e.to_str()) {
        Some(ext) if own.contains(&ext.to_ascii_lowercase().as_str()) => base.with_extension(""),
        _ => base.to_path_buf(),
    };
    own.map(|ext| {
        let mut name = base.as_os_str().to_owned();
        name.push(".");
        name.push(ext);
        PathBuf::from(name)
    })
}

/// Writes CSV, JSON and the isolux SVG next to `base` (see [`output_paths`]); any failed write is an
/// error and leaves no partial file.
pub fn write_report(
    base: &Path,
    report: &GridReport,
    settings: serde_json::Value,
    title: &str,
) -> Result<[PathBuf; 3]> {
    let paths = output_paths(base);
    let texts = [
        csv(report),
        json(report, settings)?,
        isolux_svg(report, title)?,
    ];
    for (path, text) in paths.iter().zip(&texts) {
        super::write_atomically(path, |to| {
            std::fs::write(to, text).with_context(|| format!("writing {}", path.display()))
        })?;
    }
    Ok(paths)
}

/// Iso-line levels: multiples of a round step (1, 2 or 5 × 10^k) strictly between `min` and `max`, about
/// eight of them.
pub fn contour_levels(min: f64, max: f64) -> Vec<f64> {
    let range = max - min;
    if !(range > 0.0 && range.is_finite()) {
        return Vec::new();
    }
    let step = super::round_step(range, 8.0);
    let first = (min / step).floor() as i64 + 1;
    (first..)
        .map(|k| k as f64 * step)
        .take_while(|&l| l < max)
        .collect()
}

/// A straight piece of an iso-line, in plane coordinates.
pub type Segment = [(f64, f64); 2];

/// Marching squares over the grid's values at `level`: a segment per square the level crosses (two in a
/// saddle, separated according to the square's mean value).
pub fn contour(report: &GridReport, level: f64) -> Vec<Segment> {
    let g = &report.grid;
    let value = |c: usize, r: usize| report.values[r * g.columns + c].lux;
    let at = |c: usize, r: usize| {
        let p = g.coordinates(c, r);
        (p.x, p.y)
    };
    let mut segments = Vec::new();
    for r in 0..g.rows.saturating_sub(1) {
        for c in 0..g.columns.saturating_sub(1) {
            // Corners counter-clockwise from (c, r); edges bottom, right, top, left.
            let corners = [(c, r), (c + 1, r), (c + 1, r + 1), (c, r + 1)];
            let v = corners.map(|(c, r)| value(c, r));
            let crossing = |a: usize, b: usize| {
                let (va, vb) = (v[a], v[b]);
                ((va >= level) != (vb >= level)).then(|| {
                    let t = (level - va) / (vb - va);
                    let (pa, pb) = (
                        at(corners[a].0, corners[a].1),
                        at(corners[b].0, corners[b].1),
                    );
                    (pa.0 + t * (pb.0 - pa.0), pa.1 + t * (pb.1 - pa.1))
                })
            };
            let edges = [
                crossing(0, 1),
                crossing(1, 2),
                crossing(3, 2),
                crossing(0, 3),
            ];
            let found: Vec<(f64, f64)> = edges.iter().flatten().copied().collect();
            match found[..] {
                [a, b] => segments.push([a, b]),
                [bottom, right, top, left] => {
                    let centre = v.iter().sum::<f64>() / 4.0;
                    if (centre >= level) == (v[0] >= level) {
                        // The centre joins corners 0 and 2: cut off corners 1 and 3.
                        segments.push([bottom, right]);
                        segments.push([top, left]);
                    } else {
                        segments.push([left, bottom]);
                        segments.push([right, top]);
                    }
                }
                _ => {}
            }
        }
    }
    segments
}

/// The isolux plot: each point's cell (a square of the grid spacing around it) filled with the false
/// colour of its illuminance on a linear scale from the smallest to the largest value, iso-lines at
/// [`contour_levels`], and a colour bar labelled in lux with the iso-line levels marked.
pub fn isolux_svg(report: &GridReport, title: &str) -> Result<String> {
    let g = &report.grid;
    anyhow::ensure!(!report.values.is_empty(), "no grid points to plot");
    let (lo, hi) = (report.statistics.min, report.statistics.max);
    let span = if hi > lo { hi - lo } else { 1.0 };
    let colour = |lux: f64| {
        let p = ramp((lux - lo) / span);
        RGBColor(p.0[0], p.0[1], p.0[2])
    };
    let half = g.spacing / 2.0;
    let (first, last) = (
        g.coordinates(0, 0),
        g.coordinates(g.columns - 1, g.rows - 1),
    );
    let x_range = (first.x - half)..(last.x + half);
    let y_range = (first.y - half)..(last.y + half);
    let aspect = (y_range.end - y_range.start) / (x_range.end - x_range.start);
    let plot_width = 700u32;
    let height = ((plot_width as f64 - 100.0) * aspect + 120.0).clamp(320.0, 1400.0) as u32;
    let [a, b] = g.plane.axis.plane_axes();
    let levels = contour_levels(lo, hi);
    let mut out = String::new();
    {
        let root =
            SVGBackend::with_string(&mut out, (plot_width + 170, height)).into_drawing_area();
        root.fill(&WHITE).map_err(draw_error)?;
        let (left, right) = root.split_horizontally(plot_width);
        let mut chart = ChartBuilder::on(&left)
            .caption(title, ("sans-serif", 18))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(56)
            .build_cartesian_2d(x_range, y_range)
            .map_err(draw_error)?;
        chart
            .configure_mesh()
            .disable_mesh()
            .x_desc(a.name())
            .y_desc(b.name())
            .label_style(("sans-serif", 12))
            .draw()
            .map_err(draw_error)?;
        let cells = (0..g.rows).flat_map(|r| (0..g.columns).map(move |c| (c, r)));
        chart
            .draw_series(cells.map(|(c, r)| {
                let p = g.coordinates(c, r);
                let lux = report.values[r * g.columns + c].lux;
                Rectangle::new(
                    [(p.x - half, p.y - half), (p.x + half, p.y + half)],
                    colour(lux).filled(),
                )
            }))
            .map_err(draw_error)?;
        for &level in &levels {
            chart
                .draw_series(
                    contour(report, level)
                        .into_iter()
                        .map(|s| PathElement::new(s.to_vec(), BLACK.stroke_width(1))),
                )
                .map_err(draw_error)?;
        }
        let mut bar = ChartBuilder::on(&right)
            .margin_top(40)
            .margin_bottom(52)
            .margin_right(12)
            .y_label_area_size(70)
            .build_cartesian_2d(0.0..1.0, lo..(if hi > lo { hi } else { lo + 1.0 }))
            .map_err(draw_error)?;
        bar.configure_mesh()
            .disable_mesh()
            .disable_x_axis()
            .y_desc("illuminance (lux)")
            .label_style(("sans-serif", 12))
            .draw()
            .map_err(draw_error)?;
        let steps = 64;
        bar.draw_series((0..steps).map(|k| {
            let (y0, y1) = (
                lo + span * k as f64 / steps as f64,
                lo + span * (k + 1) as f64 / steps as f64,
            );
            Rectangle::new([(0.0, y0), (1.0, y1)], colour(0.5 * (y0 + y1)).filled())
        }))
        .map_err(draw_error)?;
        bar.draw_series(
            levels
                .iter()
                .map(|&l| PathElement::new(vec![(0.0, l), (1.0, l)], BLACK.stroke_width(1))),
        )
        .map_err(draw_error)?;
        root.present().map_err(draw_error)?;
    }
    Ok(out)
}

fn draw_error<E: std::fmt::Debug>(e: E) -> anyhow::Error {
    anyhow::anyhow!("drawing the isolux plot: {e:?}")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::DVec2;
    use crate::measures::illuminance::{Grid, GridValue, Region, Statistics, WorkPlane};

    fn report(values: &[f64], columns: usize) -> GridReport {
        let plane = WorkPlane::parse("z=1").unwrap();
        let rows = values.len() / columns;
        let region = Region::new(
            DVec2::ZERO,
            DVec2::new((columns - 1) as f64, (rows - 1) as f64),
        )
        .unwrap();
        let grid = Grid::new(plane, region, 1.0).unwrap();
        GridReport {
            values: grid
                .points()
                .iter()
                .zip(values)
                .map(|(p, &lux)| GridValue {
                    point: p.0.to_array(),
                    lux,
                    error_lux: 0.0,
                    reference: None,
                    inside_solid: false,
                })
                .collect(),
            grid,
            statistics: Statistics::of(values),
            inside_solid: 0,
            max_error_lux: 0.0,
            mean_error_lux: 0.0,
            pieces: 0,
            rays: 0,
        }
    }

    #[test]
    fn levels_are_round_and_inside_the_range() {
        assert_eq!(
            contour_levels(0.0, 400.0),
            vec![50.0, 100.0, 150.0, 200.0, 250.0, 300.0, 350.0]
        );
        assert_eq!(
            contour_levels(12.0, 19.0),
            vec![13.0, 14.0, 15.0, 16.0, 17.0, 18.0]
        );
        assert!(contour_levels(5.0, 5.0).is_empty());
    }

    #[test]
    fn marching_squares_follow_a_linear_ramp() {
        // lux = 100 x on a 3 × 2 grid: the 150 lux iso-line is the straight line x = 1.5.
        let r = report(&[0.0, 100.0, 200.0, 0.0, 100.0, 200.0], 3);
        let segments = contour(&r, 150.0);
        assert_eq!(segments.len(), 1);
        for (x, _) in segments[0] {
            assert!((x - 1.5).abs() < 1e-12);
        }
        let svg = isolux_svg(&r, "ramp").unwrap();
        assert!(svg.contains("<svg") && svg.contains("lux"));
        let text = csv(&r);
        assert_eq!(text.lines().count(), 7);
        assert!(text.starts_with("x,y,z,lux,error_lux\n0,0,1,0,0\n"));
    }
}
