//! `radiosity experiment oracles [SCENE]`: the experiment of Feixas et al. §4 (see
//! `experiments::oracles`): tables in Markdown and JSON, and the meshes and smooth-shaded images side by
//! side as one PNG per target and sample count.

use super::args::{CameraArgs, SceneArgs, SolveArgs};
use crate::experiments::oracles::{
    markdown_table, oracle_name, reference_features, run_one, tile, OracleExperiment, OracleRun,
    Yardstick,
};
use crate::output::camera::Camera;
use crate::output::image::Image;
use crate::output::tonemap::{write_png, ToneMap};
use crate::pipeline::{build_visibility_for, OracleKind};
use crate::progress::Progress;
use crate::reference::{render_reference, ReferenceSettings};
use anyhow::{Context, Result};
use clap::{Args, Subcommand};
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct ExperimentCommand {
    #[command(subcommand)]
    pub which: Experiment,
}

#[derive(Subcommand, Debug)]
pub enum Experiment {
    /// Power, smoothness and MI oracles at equal element counts (Feixas et al. §4, figures 1-5).
    Oracles(Box<OraclesExperiment>),
    /// Multi-resolution visibility on the shadow-groups scene: time and FBEM against feature size
    /// (Sillion–Drettakis §5, Figure 9).
    ShadowGroups(ShadowGroupsExperiment),
}

#[derive(Args, Debug)]
pub struct ShadowGroupsExperiment {
    /// Feature sizes s in world units on the wall (the scene's cubes are 0.03 to 0.24); 0 is multires
    /// at its exact limit.
    #[arg(long, value_delimiter = ',', default_values_t = [0.0, 0.02, 0.04, 0.08, 0.16, 0.32])]
    pub feature_sizes: Vec<f64>,
    /// Quadtree level of the compared walls' elements (side 1/2^level of a wall tile).
    #[arg(long, default_value_t = 6, value_parser = clap::value_parser!(u32).range(1..=9))]
    pub level: u32,
    /// Quadtree level of the exact reference's elements.
    #[arg(long, default_value_t = 7, value_parser = clap::value_parser!(u32).range(1..=9))]
    pub reference_level: u32,
    /// Cluster tree of extinction and multires visibility.
    #[arg(long = "hierarchy", value_enum, default_value_t = crate::hierarchy::clusters::ClusterTreeKind::Grid)]
    pub cluster_tree: crate::hierarchy::clusters::ClusterTreeKind,
    /// Folder for table.md and runs.json (`radiosity plot runs.json --x feature_size --y seconds
    /// --label visibility`).
    #[arg(short, long, default_value = "experiment-shadow-groups")]
    pub out: PathBuf,
}

impl ShadowGroupsExperiment {
    fn run(&self, progress: &Progress) -> Result<()> {
        let experiment = crate::experiments::shadow_groups::MultiresExperiment {
            groups: crate::scene::generators::ShadowGroups::default(),
            feature_sizes: self.feature_sizes.clone(),
            level: self.level,
            reference_level: self.reference_level,
            tree: self.cluster_tree,
        };
        std::fs::create_dir_all(&self.out)
            .with_context(|| format!("creating {}", self.out.display()))?;
        let runs = experiment.run(progress)?;
        let table = crate::experiments::shadow_groups::markdown_table(&runs);
        let json = serde_json::to_string_pretty(&runs)? + "\n";
        write_files(
            &self.out,
            [("table.md", table.clone()), ("runs.json", json)],
        )?;
        out!("{table}")?;
        Ok(())
    }
}

#[derive(Args, Debug)]
pub struct OraclesExperiment {
    #[command(flatten)]
    pub scene: SceneArgs,
    #[command(flatten)]
    pub solve: SolveArgs,
    /// Target leaf-element counts (the paper: 1000 and 2000 on the Cornell box, 14000 on the cube room).
    #[arg(long, value_delimiter = ',', default_values_t = [1000, 2000], value_parser = super::args::count(0, 10_000_000))]
    pub targets: Vec<usize>,
    /// Oracles to compare.
    #[arg(long, value_enum, value_delimiter = ',', default_values_t = [OracleKind::Power, OracleKind::Smoothness, OracleKind::MutualInformation])]
    pub oracles: Vec<OracleKind>,
    /// Oracle sample counts: the main run (the paper's 10) and the robustness run (4).
    #[arg(long, value_delimiter = ',', default_values_t = [10, 4], value_parser = super::args::count(0, 100_000))]
    pub samples: Vec<usize>,
    /// Accept an element count within this fraction of the target.
    #[arg(long, default_value_t = 0.05)]
    pub count_tolerance: f64,
    /// Most solves per ε search.
    #[arg(long, default_value_t = 14, value_parser = super::args::count(0, 1000))]
    pub max_solves: usize,
    /// Feature sizes (pixels) for the FBEM columns.
    #[arg(long, value_delimiter = ',', default_values_t = [2, 4, 8, 16], value_parser = super::args::count(0, 4096))]
    pub fbem_sizes: Vec<usize>,
    /// Reference image (linear EXR at this view and size); computed and written there when missing.
    #[arg(long)]
    pub reference: Option<PathBuf>,
    /// Paths per pixel when the reference is computed.
    #[arg(long, default_value_t = 1024, value_parser = super::args::count(0, 1 << 24))]
    pub reference_spp: usize,
    #[command(flatten)]
    pub camera: CameraArgs,
    /// Folder for table.md, table.json and the images.
    #[arg(short, long, default_value = "experiment-oracles")]
    pub out: PathBuf,
}

/// Writes each (name, text) into the folder `out`, atomically.
fn write_files(out: &std::path::Path, files: [(&str, String); 2]) -> Result<()> {
    for (name, text) in files {
        let path = out.join(name);
        crate::output::write_atomically(&path, |to| {
            std::fs::write(to, text).with_context(|| format!("writing {}", path.display()))
        })?;
    }
    Ok(())
}

impl ExperimentCommand {
    pub fn run(&self, seed: u64, progress: &Progress) -> Result<()> {
        match &self.which {
            Experiment::Oracles(e) => e.run(seed, progress),
            Experiment::ShadowGroups(e) => e.run(progress),
        }
    }
}

impl OraclesExperiment {
    fn run(&self, seed: u64, progress: &Progress) -> Result<()> {
        anyhow::ensure!(
            !self.targets.is_empty() && self.targets.iter().all(|&t| t > 0),
            "--targets must be positive"
        );
        anyhow::ensure!(
            self.samples.iter().all(|&s| s >= 2),
            "--samples must be at least 2"
        );
        let (scene, name) = self.scene.load_for_solving(progress)?;
        self.check_outputs(&scene.sources)?;
        std::fs::create_dir_all(&self.out)
            .with_context(|| format!("creating {}", self.out.display()))?;
        let camera = self.camera.camera(&scene, 256)?;
        let mut base = self.solve.settings(seed)?;
        if self.solve.accuracy.is_none() {
            // The experiment compares the oracles alone (Feixas et al. §4), at equal element counts: the
            // power oracle's default error control stays off unless asked for.
            base.accuracy = None;
        }
        let reference = self.reference(&scene, &camera, seed, progress)?;
        let features = reference_features(&reference)?;
        let yardstick = Yardstick {
            camera: &camera,
            reference: &reference,
            features: &features,
        };
        let experiment = OracleExperiment {
            oracles: self.oracles.clone(),
            targets: self.targets.clone(),
            samples: self.samples.clone(),
            base,
            tolerance: self.count_tolerance,
            max_solves: self.max_solves,
            fbem_sizes: self.fbem_sizes.clone(),
        };
        let tone = ToneMap::default();
        let mut runs: Vec<OracleRun> = Vec::new();
        for &samples in &experiment.samples {
            for &target in &experiment.targets {
                let mut meshes = Vec::new();
                let mut smooth = Vec::new();
                for &oracle in &experiment.oracles {
                    // The power oracle takes no samples: run it once, with the main sample count.
                    if oracle == OracleKind::Power && samples != experiment.samples[0] {
                        continue;
                    }
                    let (run, images) = run_one(
                        &scene,
                        &experiment,
                        oracle,
                        samples,
                        target,
                        &yardstick,
                        progress,
                    )?;
                    if !progress.quiet {
                        crate::progress::stderr_line(format_args!(
                            "{name}: {} ({samples} samples) target {target}: {} leaves at eps {:.3e}, rel. RMSE {:.2}%",
                            oracle_name(oracle),
                            run.leaf_elements,
                            run.eps,
                            run.relative_rmse * 100.0
                        ));
                    }
                    runs.push(run);
                    meshes.push(images.mesh);
                    smooth.push(images.smooth);
                }
                let columns = meshes.len();
                let all: Vec<&Image> = meshes.iter().chain(smooth.iter()).collect();
                let path = self.tiles_path(target, samples);
                write_png(&path, &tile(&all, columns), &tone)?;
            }
        }
        let table = markdown_table(&runs);
        let header = format!(
            "Scene: {name}. Columns of oracles-TARGET-sSAMPLES.png, left to right: {}; top row mesh, bottom row \
             smooth shading.\n\n",
            self.oracles.iter().map(|&o| oracle_name(o)).collect::<Vec<_>>().join(", ")
        );
        let json = serde_json::to_string_pretty(&runs)? + "\n";
        write_files(
            &self.out,
            [("table.md", header + &table), ("table.json", json)],
        )?;
        out!("{table}")?;
        Ok(())
    }

    fn tiles_path(&self, target: usize, samples: usize) -> PathBuf {
        self.out.join(format!("oracles-{target}-s{samples}.png"))
    }

    /// Refuses an output folder whose tables or images would overwrite a file the scene is read from.
    fn check_outputs(&self, inputs: &[PathBuf]) -> Result<()> {
        let mut outputs = vec![self.out.join("table.md"), self.out.join("table.json")];
        for &samples in &self.samples {
            outputs.extend(self.targets.iter().map(|&t| self.tiles_path(t, samples)));
        }
        for path in &outputs {
            if let Some(input) = inputs.iter().find(|i| super::args::same_file(path, i)) {
                anyhow::bail!(
                    "--out {}: {} is an input ({}); refusing to overwrite it",
                    self.out.display(),
                    path.display(),
                    input.display()
                );
            }
        }
        Ok(())
    }

    /// Reads the reference, or renders it with the path tracer and writes it where asked (or into the output
    /// folder).
    fn reference(
        &self,
        scene: &crate::scene::Scene,
        camera: &Camera,
        seed: u64,
        progress: &Progress,
    ) -> Result<Image> {
        let path = self
            .reference
            .clone()
            .unwrap_or_else(|| self.out.join("reference.exr"));
        if path.exists() {
            let image = Image::read_linear(&path)?;
            anyhow::ensure!(
                image.width == camera.width && image.height == camera.height,
                "{} is {}x{}, not the requested {}x{}",
                path.display(),
                image.width,
                image.height,
                camera.width,
                camera.height
            );
            return Ok(image);
        }
        super::args::check_samples(camera.width, camera.height, self.reference_spp.max(2))?;
        let visibility = build_visibility_for(scene, &self.solve.settings(seed)?)?;
        let settings = ReferenceSettings {
            spp: self.reference_spp.max(2),
            seed,
            // The experiment's renders sample pixel centres.
            filter: crate::reference::PixelFilter::Centre,
            ..Default::default()
        };
        let reference = render_reference(scene, visibility.as_ref(), camera, &settings, progress);
        reference.mean.write_exr(&path)?;
        Ok(reference.mean)
    }
}
