//! `radiosity measure`: the information-theoretic scene measures of Feixas et al. (§2.2, §3.1): discrete
//! and continuous radiosity and visibility mutual information and the discretisation error Δ, for one
//! solution or for a sweep of refinement thresholds.

use super::args::{SceneArgs, SolveArgs};
use crate::measures::global_lines::GlobalLines;
use crate::measures::information::{measure, InformationMeasures};
use crate::measures::stats::RunStats;
use crate::pipeline::simulate;
use crate::progress::Progress;
use anyhow::{Context, Result};
use clap::Args;
use serde::Serialize;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct MeasureCommand {
    #[command(flatten)]
    pub scene: SceneArgs,
    #[command(flatten)]
    pub solve: SolveArgs,
    /// Global lines for the continuous measures (eq. 10); the Monte Carlo error falls as 1/√N.
    #[arg(long, default_value_t = 100_000, value_name = "N", value_parser = super::args::count(1, 100_000_000))]
    pub lines: usize,
    /// Solve at each of these ε (comma separated) and report every level; without values, 100·ε down to
    /// ε in steps of √10.
    #[arg(long, value_delimiter = ',', num_args = 0.., value_name = "EPS")]
    pub sweep: Option<Vec<f64>>,
    /// Print JSON instead of a table.
    #[arg(long)]
    pub json: bool,
    /// Write run statistics, with the measures of the (finest) solution, as JSON.
    #[arg(long, value_name = "FILE.json")]
    pub stats: Option<PathBuf>,
}

/// The measures of one refinement level.
#[derive(Clone, Debug, Serialize)]
struct Level {
    eps: f64,
    #[serde(flatten)]
    measures: InformationMeasures,
}

impl MeasureCommand {
    pub fn run(&self, seed: u64, progress: &Progress) -> Result<()> {
        anyhow::ensure!(self.lines >= 2, "--lines must be at least 2");
        let (scene, name) = self.scene.load_for_solving(progress)?;
        if let Some(path) = &self.stats {
            super::args::check_output("--stats", path, &scene.sources)?;
        }
        let settings = self.solve.settings(seed)?;
        let eps_levels = match &self.sweep {
            None => vec![settings.eps],
            Some(v) if v.is_empty() => (0..5)
                .map(|k| settings.eps * 10f64.powf(2.0 - 0.5 * k as f64))
                .collect(),
            Some(v) => v.clone(),
        };
        for &eps in &eps_levels {
            anyhow::ensure!(
                eps.is_finite() && eps >= 0.0,
                "--sweep: {eps} is not a non-negative number"
            );
        }
        let mut lines: Option<GlobalLines> = None;
        let mut levels = Vec::new();
        let mut last_stats = None;
        for &eps in &eps_levels {
            let mut level_settings = settings.clone();
            level_settings.eps = eps;
            let solution = simulate(&scene, &level_settings, progress)?;
            let lines = lines.get_or_insert_with(|| {
                GlobalLines::trace(
                    &scene,
                    &solution.hierarchy,
                    solution.visibility.as_ref(),
                    self.lines,
                    seed,
                )
            });
            let measures = measure(&scene, &solution.hierarchy, lines)
                .with_context(|| format!("{name}: measuring the solution at eps {eps}"))?;
            if !self.json && !progress.quiet && levels.is_empty() {
                crate::progress::stderr_line(format_args!(
                    "{name}: {} global lines, {} chords",
                    lines.lines,
                    lines.chords.len()
                ));
            }
            if !self.json {
                if levels.is_empty() {
                    outln!(
                        "{:>10} {:>8} {:>9} {:>9} {:>8} {:>7} {:>9} {:>9} {:>7}",
                        "eps",
                        "leaves",
                        "I_r^d",
                        "I_r^c",
                        "+-",
                        "Delta",
                        "I_v^d",
                        "I_v^c",
                        "Dv"
                    )?;
                }
                let m = &measures;
                outln!(
                    "{:>10.3e} {:>8} {:>9.4} {:>9.4} {:>8.4} {:>7.4} {:>9.4} {:>9.4} {:>7.4}",
                    eps,
                    m.leaves,
                    m.radiosity_discrete,
                    m.radiosity_continuous,
                    m.radiosity_continuous_error,
                    m.delta,
                    m.visibility_discrete,
                    m.visibility_continuous,
                    m.delta_v
                )?;
            }
            let mut stats = RunStats::new(&name, scene.polygons.len(), &solution, &level_settings);
            stats.information = Some(measures);
            last_stats = Some(stats);
            levels.push(Level { eps, measures });
        }
        if self.json {
            let last = levels.last().context("no refinement level")?;
            let mut value = serde_json::to_value(last)?;
            if self.sweep.is_some() {
                if let Some(map) = value.as_object_mut() {
                    map.insert("levels".to_string(), serde_json::to_value(&levels)?);
                }
            }
            outln!("{}", serde_json::to_string_pretty(&value)?)?;
        }
        if let (Some(path), Some(stats)) = (&self.stats, &last_stats) {
            let json = serde_json::to_string_pretty(stats)?;
            crate::output::write_atomically(path, |to| {
                std::fs::write(to, json + "\n")
                    .with_context(|| format!("writing {}", path.display()))
            })?;
        }
        Ok(())
    }
}
