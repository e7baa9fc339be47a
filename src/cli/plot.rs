//! `radiosity plot STATS.json... -o chart.svg`: one numeric field of run statistics against another.

use crate::output::plot::{plot, PlotSpec};
use anyhow::Result;
use clap::Args;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct PlotCommand {
    /// Stats JSON files (from `--stats`), each one run or an array of runs.
    #[arg(required = true)]
    pub files: Vec<PathBuf>,
    /// Output chart (.svg).
    #[arg(short, long, value_name = "FILE.svg")]
    pub output: PathBuf,
    /// x value: a dotted JSON path, `+` to add fields (elements, rays, seconds.refine+seconds.solve).
    #[arg(long, default_value = "elements")]
    pub x: String,
    /// y value: a dotted JSON path (error.relative_rmse).
    #[arg(long, default_value = "error.relative_rmse")]
    pub y: String,
    /// Group runs into series by this field (settings.oracle); one series per file by default.
    #[arg(long, value_name = "PATH")]
    pub label: Option<String>,
    /// Logarithmic x axis.
    #[arg(long)]
    pub log_x: bool,
    /// Logarithmic y axis.
    #[arg(long)]
    pub log_y: bool,
    /// Chart title (default: "Y vs X").
    #[arg(long)]
    pub title: Option<String>,
}

impl PlotCommand {
    pub fn run(&self) -> Result<()> {
        let spec = PlotSpec {
            x: self.x.clone(),
            y: self.y.clone(),
            label: self.label.clone(),
            log_x: self.log_x,
            log_y: self.log_y,
            title: self.title.clone(),
        };
        super::args::check_output("--output", &self.output, &self.files)?;
        let series = plot(&self.files, &spec, &self.output)?;
        let points: usize = series.iter().map(|s| s.points.len()).sum();
        outln!(
            "wrote {}: {} series, {points} points",
            self.output.display(),
            series.len()
        )?;
        Ok(())
    }
}
