//! `radiosity grid [SCENE] --plane z=0.85 --spacing 0.25 [--region x0,y0,x1,y1] -o BASE`: illuminance
//! in lux on a work plane, with an error estimate per point, as BASE.csv, BASE.json and an isolux plot
//! BASE.svg.

use super::args::{GatherArgs, SceneArgs, SolveArgs};
use crate::measures::illuminance::{
    illuminance_grid, Grid, GridReport, ReferencePaths, Region, WorkPlane,
};
use crate::output::work_plane::{output_paths, write_report};
use crate::pipeline::simulate;
use crate::progress::Progress;
use anyhow::{Context, Result};
use clap::Args;
use std::path::PathBuf;
use std::time::Instant;

#[derive(Args, Debug)]
pub struct GridCommand {
    #[command(flatten)]
    pub scene: SceneArgs,
    #[command(flatten)]
    pub solve: SolveArgs,
    /// The work plane: AXIS=HEIGHT with the points facing +AXIS (z=0.85 for a desk), or -AXIS=HEIGHT
    /// facing -AXIS (-z=2.5 for light reaching a ceiling).
    #[arg(long, value_parser = WorkPlane::parse, allow_hyphen_values = true, value_name = "AXIS=H")]
    pub plane: WorkPlane,
    /// Distance between grid points (scene units, metres).
    #[arg(long, default_value_t = 0.25, value_name = "D")]
    pub spacing: f64,
    /// Rectangle of the grid in the plane's two axes (z: x,y; y: x,z; x: y,z); default: the scene's
    /// bounds at that height, 1% inside on every side. Points inside solids (the surfaces along and
    /// against the normal both seen from behind) are reported but left out of the statistics.
    #[arg(long, value_parser = Region::parse, allow_hyphen_values = true, value_name = "X0,Y0,X1,Y1")]
    pub region: Option<Region>,
    /// Base path of the outputs: BASE.csv, BASE.json and BASE.svg.
    #[arg(short, long, default_value = "grid", value_name = "BASE")]
    pub output: PathBuf,
    /// Also estimate each point's illuminance by unbiased path tracing with N paths, with its standard
    /// error (rounded up to a multiple of 16).
    #[arg(long, value_name = "N", value_parser = super::args::count(2, 1 << 24))]
    pub reference_paths: Option<usize>,
    #[command(flatten)]
    pub gather: GatherArgs,
}

impl GridCommand {
    pub fn run(&self, seed: u64, progress: &Progress) -> Result<()> {
        let gather = self.gather.settings(false, seed)?;
        let paths = output_paths(&self.output);
        let outputs: Vec<(&str, &std::path::Path)> = ["-o (csv)", "-o (json)", "-o (svg)"]
            .into_iter()
            .zip(paths.iter().map(|p| p.as_path()))
            .collect();
        super::args::check_outputs(&outputs, self.scene.scene.as_slice())?;
        let start = Instant::now();
        let (scene, name) = self.scene.load_for_solving(progress)?;
        super::args::check_outputs(&outputs, &scene.sources)?;
        let region = match self.region {
            Some(region) => region,
            None => self
                .plane
                .default_region(&scene.bounds())
                .map_err(anyhow::Error::msg)?,
        };
        let grid = Grid::new(self.plane, region, self.spacing).map_err(anyhow::Error::msg)?;
        if let Some(paths) = self.reference_paths {
            super::args::check_samples(grid.columns, grid.rows, paths)
                .context("--reference-paths")?;
        }
        let settings = self.solve.settings(seed)?;
        let solution = simulate(&scene, &settings, progress)?;
        let solve_seconds = start.elapsed().as_secs_f64();
        let reference = self
            .reference_paths
            .map(|paths| ReferencePaths { paths, seed });
        let start = Instant::now();
        let report = illuminance_grid(
            &scene,
            &solution.hierarchy,
            solution.visibility.as_ref(),
            &grid,
            gather,
            reference,
        );
        let grid_seconds = start.elapsed().as_secs_f64();
        let meta = serde_json::json!({
            "scene": name,
            "simulation": settings,
            "gather": gather,
            "reference": reference,
            "elements": solution.hierarchy.elements.len(),
            "leaves": solution.hierarchy.leaf_count(),
            "seconds": { "load_and_solve": solve_seconds, "grid": grid_seconds },
        });
        let title = format!(
            "{} illuminance (lux), {}={}",
            file_name(&name),
            self.plane.axis.name(),
            self.plane.height
        );
        let written = write_report(&self.output, &report, meta, &title)?;
        if let Some(unlit) = unlit_points(&report) {
            crate::progress::stderr_line(format_args!("warning: {name}: {unlit}"));
        }
        let s = &report.statistics;
        let max_over_min = s
            .max_over_min
            .map_or("∞".to_string(), |r| format!("{r:.2}"));
        outln!(
            "{name}: {} × {} points on {}={}: min {:.1}, mean {:.1}, max {:.1} lux, uniformity \
             (min/mean) {:.3}, max/min {max_over_min}; estimated error ≤ {:.1} lux (mean {:.1}); \
             solve {solve_seconds:.2}s, grid {grid_seconds:.2}s{} -> {}, {}, {}",
            grid.columns,
            grid.rows,
            self.plane.axis.name(),
            self.plane.height,
            s.min,
            s.mean,
            s.max,
            s.uniformity,
            report.max_error_lux,
            report.mean_error_lux,
            if report.inside_solid > 0 {
                format!(
                    "; {} points inside solids left out of the statistics",
                    report.inside_solid
                )
            } else {
                String::new()
            },
            written[0].display(),
            written[1].display(),
            written[2].display()
        )?;
        Ok(())
    }
}

/// Illuminance below this fraction of the grid's mean counts as none at all.
const UNLIT_FRACTION: f64 = 1e-3;

/// What to tell the user about grid points (outside solids) that get no light to speak of, if any: the
/// default grid spans the scene's bounds, which reach past a room's walls wherever something sticks
/// out (office2's window frames: a row of points behind the wall, min 0.0 lux and a uniformity of 0),
/// and the statistics then describe the room and its outside together.
fn unlit_points(report: &GridReport) -> Option<String> {
    let s = &report.statistics;
    let mut unlit = report
        .values
        .iter()
        .filter(|v| !v.inside_solid && v.lux < UNLIT_FRACTION * s.mean);
    let [x, y, z] = unlit.next()?.point;
    Some(format!(
        "{} of {} grid points get under {}% of the mean illuminance (the first at {x:.3}, {y:.3}, \
         {z:.3}), and they count in the minimum and uniformity: outside the room's walls, or in an \
         unlit closed space? --region limits the grid",
        1 + unlit.count(),
        s.count,
        UNLIT_FRACTION * 100.0
    ))
}

fn file_name(name: &str) -> &str {
    name.rsplit('/').next().unwrap_or(name)
}
