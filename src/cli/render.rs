//! `radiosity render`: load, solve, render to PNG (and EXR, PLY/GLB, stats JSON).

use super::args::{CameraArgs, SceneArgs, SolveArgs, ToneArgs};
use crate::color::Units;
use crate::hierarchy::Hierarchy;
use crate::measures::irradiance_cache::CacheSettings;
use crate::measures::stats::RunStats;
use crate::output::export::{write_glb, write_ply};
use crate::output::false_colour;
use crate::output::image::Image;
use crate::output::mesh_values::VertexRadiosity;
use crate::output::render::{
    emitter_mask, render_reporting, render_with, Antialias, Quantity, RenderOptions, Shading,
};
use crate::output::tonemap::write_png;
use crate::output::viewer::{write_page, Page, ViewerMesh, DEFAULT_MAX_TRIANGLES};
use crate::pipeline::simulate_observed;
use crate::progress::Progress;
use crate::solvers::multigrid::StepReport;
use crate::visibility::Visibility;
use anyhow::{Context, Result};
use clap::Args;
use std::path::{Path, PathBuf};
use std::time::Instant;

#[derive(Args, Debug)]
pub struct RenderCommand {
    #[command(flatten)]
    pub scene: SceneArgs,
    #[command(flatten)]
    pub solve: SolveArgs,
    #[command(flatten)]
    pub camera: CameraArgs,
    /// PNG image to write (exposed, tone-mapped, sRGB).
    #[arg(short, long, default_value = "radiosity.png")]
    pub output: PathBuf,
    /// Seamless (the default): each element's basis expansion with its small steps at element edges
    /// removed (neighbours within a factor 1.33 joined, a factor 2 apart kept), each element's mean
    /// kept. Basis: the expansion itself (the computed solution). Continuous: every step removed but
    /// along contact outlines (vertex averages of the expansions; spreads steep light). Flat: element averages. Smooth: values averaged to vertices and interpolated
    /// (Gouraud, crack free).
    #[arg(long, value_enum, default_value_t = Shading::Seamless)]
    pub shading: Shading,
    /// What the PNG shows: the radiance, or each element's a-posteriori error estimate in false colour
    /// with a colour bar (W/(m² sr); compare with `compare --diff`).
    #[arg(long, value_enum, default_value_t = Quantity::Radiance)]
    pub show: Quantity,
    /// Draw the element mesh on top.
    #[arg(long)]
    pub mesh: bool,
    /// Samples per pixel, stratified and box-filtered (antialiased edges; use 16 or more to compare with
    /// `reference`); 1 = pixel centres (comparable with `reference --filter centre`).
    #[arg(long, default_value_t = 4, value_parser = clap::value_parser!(u32).range(1..=65_536))]
    pub spp: u32,
    /// Which pixels take the --spp samples: adaptive, those whose four corners differ by more than 5%
    /// (edges, shadow boundaries; the others average their corners: 12% of the Cornell box's pixels
    /// at 512², 1.5 rays a pixel at the default --spp 4), or stratified, every pixel (the box
    /// filter's unbiased estimate everywhere, as `reference` renders).
    #[arg(long, value_enum, default_value_t = Antialias::Adaptive)]
    pub antialias: Antialias,
    /// Each sample's radiance corrected by a final gather of the solution (emission plus ρ/π times
    /// the irradiance gathered there, as `probe --final-gather`): gathers at records where the camera
    /// looks and adds their correction to the --shading value, interpolated within each leaf element
    /// (an irradiance cache, `measures::irradiance_cache`), or with --gather-every-sample gathers at
    /// every sample. Nearer the truth where a leaf's expansion misplaces its light (the Cornell box's
    /// 128² image 2.04 → 1.71%), at about a millisecond a record: 1.5 s instead of 0.6 s there, and a
    /// render phase of 13 s for the classroom's 256² image at --gather-tolerance 1 (exported models
    /// keep the shading).
    #[arg(long)]
    pub final_gather: bool,
    /// With --final-gather: gather at every sample instead of at cached records (at most 2^20 samples).
    #[arg(long, requires = "final_gather")]
    pub gather_every_sample: bool,
    /// With --final-gather: Ward's a, a record's radius as a fraction of the harmonic mean distance to
    /// the surfaces around it, within 1 and 32 pixels (smaller: more records, less interpolation).
    #[arg(long, requires = "final_gather", value_name = "A", default_value_t = CacheSettings::default().accuracy)]
    pub cache_accuracy: f64,
    #[command(flatten)]
    pub gather: super::args::GatherArgs,
    #[command(flatten)]
    pub tone: ToneArgs,
    /// Also write linear radiance: Radiance HDR (RGBE) when FILE ends in .hdr or .pic, else 32-bit
    /// float OpenEXR (exact; what `compare` measures best).
    #[arg(long, value_name = "FILE.exr|FILE.hdr")]
    pub hdr: Option<PathBuf>,
    /// Write the illuminated mesh (.ply or .glb; repeatable), or the interactive viewer (.html: one
    /// self-contained page, the same view and tone mapping as the PNG).
    #[arg(long, value_name = "FILE")]
    pub export: Vec<PathBuf>,
    /// Most triangles in an --export .html page.
    #[arg(long, default_value_t = DEFAULT_MAX_TRIANGLES, value_name = "N", value_parser = super::args::count(1, 1 << 28))]
    pub max_triangles: usize,
    /// Write a PNG mask of the pixels that see a light source (white), for `compare --mask`.
    #[arg(long, value_name = "FILE.png")]
    pub emitter_mask: Option<PathBuf>,
    /// Write run statistics as JSON.
    #[arg(long, value_name = "FILE.json")]
    pub stats: Option<PathBuf>,
    /// Units of the EXR values, the error-estimate colour bar and the summary: radiance in W/(m² sr), or
    /// luminance in cd/m² (179 lm/W × each channel, so that Y of a pixel is its luminance). The PNG's
    /// tone mapping is the same in both.
    #[arg(long, value_enum, default_value_t = Units::Radiometric)]
    pub units: Units,
    /// With --link-budget: write the image after every step of progressive multi-gridding too, beside
    /// --output as NAME-stepNN.png.
    #[arg(long, requires = "link_budget")]
    pub progressive: bool,
}

impl RenderCommand {
    pub fn run(&self, seed: u64, progress: &Progress) -> Result<()> {
        for path in &self.export {
            let ext = extension(path);
            anyhow::ensure!(
                ext == "ply" || ext == "glb" || ext == "html",
                "--export {}: expected a .ply, .glb or .html file",
                path.display()
            );
        }
        let tone = self.tone.tone_map()?;
        self.check_outputs(self.scene.scene.as_slice())?;
        let start = Instant::now();
        let (scene, name) = self.scene.load_for_solving(progress)?;
        self.check_outputs(&scene.sources)?;
        let load_seconds = start.elapsed().as_secs_f64();
        let settings = self.solve.settings(seed)?;
        let camera = self.camera.camera(&scene, 512)?;
        super::args::check_samples(camera.width, camera.height, self.spp as usize)?;
        let gather_cache = (self.final_gather && !self.gather_every_sample)
            .then(|| super::args::cache_settings(self.cache_accuracy, self.solve.method))
            .transpose()?;
        let gather = self.gather.settings(gather_cache.is_some(), seed)?;
        if self.final_gather {
            // A cache gathers at most once per pixel.
            let samples = if gather_cache.is_some() {
                1
            } else {
                self.spp as usize
            };
            super::args::check_gathered_samples(camera.width, camera.height, samples)?;
        }
        let options = RenderOptions {
            shading: self.shading,
            quantity: self.show,
            mesh: self.mesh,
            samples_per_pixel: self.spp.max(1),
            antialias: self.antialias,
            seed,
            final_gather: self.final_gather.then_some(gather),
            gather_cache,
            ..Default::default()
        };
        let mut on_step = |step: &StepReport,
                           hierarchy: &Hierarchy,
                           visibility: &dyn Visibility| {
            let path = self.progressive.then(|| step_path(&self.output, step.step));
            if let Some(path) = &path {
                super::args::check_outputs(&[("--progressive", path.as_path())], &scene.sources)?;
                let vertices = self
                    .shading
                    .needs_vertices()
                    .then(|| VertexRadiosity::new(hierarchy));
                let image =
                    render_with(hierarchy, visibility, &camera, &options, vertices.as_ref());
                self.write_image(path, &image, &tone)?;
            }
            if !progress.quiet {
                crate::progress::stderr_line(format_args!(
                    "step {}: threshold {:.3e}, {} links refined creating {} ({} above target, \
                     {} deferred), {} leaves, {} links, {} sweeps, {:.2}s ({:.2}s CPU){}",
                    step.step,
                    step.threshold,
                    step.refined_links,
                    step.created_links,
                    step.above_target,
                    step.deferred,
                    step.leaves,
                    step.links,
                    step.sweeps,
                    step.seconds,
                    step.cpu_seconds,
                    path.map(|p| format!(" -> {}", p.display()))
                        .unwrap_or_default()
                ));
            }
            Ok(())
        };
        let mut solution = simulate_observed(&scene, &settings, progress, &mut on_step)?;
        let mut stats = RunStats::new(&name, scene.polygons.len(), &solution, &settings);
        stats.seconds.load = load_seconds;
        // From here on only the radiance is read: the links' memory goes to the image.
        solution.hierarchy.release_solver_state();

        let start = Instant::now();
        let vertices = (self.shading.needs_vertices() || !self.export.is_empty())
            .then(|| VertexRadiosity::new(&solution.hierarchy));
        let (image, report) = render_reporting(
            &solution.hierarchy,
            solution.visibility.as_ref(),
            &camera,
            &options,
            vertices.as_ref(),
        );
        let render_seconds = start.elapsed().as_secs_f64();
        self.write_image(&self.output, &image, &tone)?;
        if let Some(path) = &self.emitter_mask {
            emitter_mask(&solution.hierarchy, solution.visibility.as_ref(), &camera)
                .write_png(path, None)?;
        }
        if let Some(path) = &self.hdr {
            // In the chosen units; copied only here, as a large image's floats are many MB.
            let mut scaled = image.clone();
            scaled
                .pixels
                .iter_mut()
                .for_each(|c| *c *= self.units.scale());
            scaled.write_linear(path)?;
        }
        for path in &self.export {
            let vertices = vertices.as_ref().context("vertex radiosity")?;
            match extension(path).as_str() {
                "ply" => write_ply(path, &solution.hierarchy, vertices, &tone)?,
                "glb" => write_glb(path, &solution.hierarchy, vertices, &tone)?,
                _ => {
                    let mesh = ViewerMesh::new(
                        &solution.hierarchy,
                        self.shading,
                        Some(vertices),
                        self.max_triangles,
                    )?;
                    // The PNG's own exposure; an error-estimate PNG has none, so the model's.
                    let exposure = match self.show {
                        Quantity::Radiance => tone.exposure_scale(image.pixels.iter().copied()),
                        Quantity::ErrorEstimate => tone.exposure_scale(mesh.vertex_radiance()),
                    };
                    let page = Page {
                        title: &name,
                        camera: &camera,
                        curve: tone.curve,
                        exposure,
                        shading: self.shading,
                    };
                    write_page(path, &mesh, &page)?;
                }
            }
        }
        stats.seconds.render = render_seconds;
        if let Some(path) = &self.stats {
            let json = serde_json::to_string_pretty(&stats)? + "\n";
            crate::output::write_atomically(path, |to| {
                std::fs::write(to, &json).with_context(|| format!("writing {}", path.display()))
            })?;
        }
        if !progress.quiet {
            let s = &stats.seconds;
            crate::progress::stderr_line(format_args!(
                "{name}: {}; {} elements ({} leaves), {} links, {} rays ({} saved by shaft tests), \
                 {} passes, {} sweeps; \
                 load {:.2}s, bvh {:.2}s, refine {:.2}s, solve {:.2}s, estimate {:.2}s, render {:.2}s{} -> {}",
                error_summary(
                    &solution.report.error,
                    self.units,
                    crate::pipeline::mean_radiance_estimate(&solution.hierarchy)
                ),
                stats.elements,
                stats.leaf_elements,
                stats.links,
                stats.rays,
                stats.rays_saved,
                stats.passes,
                stats.iterations,
                s.load,
                s.bvh,
                s.refine,
                s.solve,
                s.estimate,
                s.render,
                match (self.final_gather, gather_cache) {
                    (false, _) => String::new(),
                    (true, None) => " (final gather at every sample)".to_string(),
                    (true, Some(_)) => {
                        format!(" (final gather at {} cached records)", report.gather_records)
                    }
                },
                self.output.display()
            ));
        }
        Ok(())
    }
}

/// "estimated error ≤ X: accuracy Y reached" or how many leaves missed the accuracy, and by how much,
/// in `units` (a radiance error's largest channel bounds the error of its luminance), with the
/// accuracy (or, without error control, the estimate) as a share of `mean_radiance` (the energy
/// balance's, what `--accuracy P%` is relative to), so that the figures read without knowing the
/// scene's scale.
pub fn error_summary(
    error: &crate::solvers::ErrorReport,
    units: Units,
    mean_radiance: f64,
) -> String {
    let s = &error.summary;
    let (k, unit) = (units.scale(), units.radiance());
    // The accuracy as a share of the mean radiance, as `--accuracy P%` gives it, and any local
    // accuracy (`ErrorControl::allowed`).
    let share = |accuracy: f64| {
        let mut parts = Vec::new();
        if mean_radiance > 0.0 {
            parts.push(format!(
                "{}% of the mean radiance",
                percent(100.0 * accuracy / mean_radiance)
            ));
        }
        if let Some(p) = error.local_accuracy {
            parts.push(format!("{:.0}% of each element's own radiance", 100.0 * p));
        }
        match parts.is_empty() {
            true => String::new(),
            false => format!(" ({})", parts.join(", and ")),
        }
    };
    match error.accuracy {
        Some(accuracy) if s.leaves_above == 0 => format!(
            "estimated error ≤ {} {unit}: accuracy {} {unit}{} reached",
            significant(k * s.max_estimate),
            significant(k * accuracy),
            share(accuracy)
        ),
        Some(accuracy) => format!(
            "accuracy {} {unit}{} NOT reached on {} of {} leaves, {:.1}% of the area ({} at the \
             minimum element area; stopped: {}), worst estimate {}",
            significant(k * accuracy),
            share(accuracy),
            s.leaves_above,
            s.leaves,
            100.0 * s.area_fraction_above,
            s.leaves_above_at_min_area,
            error.stopped_by,
            significant(k * s.max_estimate)
        ),
        None if mean_radiance > 0.0 => format!(
            "estimated error: max {}, mean {} {unit} ({:.0}%, {:.1}% of the mean radiance {})",
            significant(k * s.max_estimate),
            significant(k * s.mean_estimate),
            100.0 * s.max_estimate / mean_radiance,
            100.0 * s.mean_estimate / mean_radiance,
            significant(k * mean_radiance)
        ),
        None => format!(
            "estimated error: max {}, mean {} {unit}",
            significant(k * s.max_estimate),
            significant(k * s.mean_estimate)
        ),
    }
}

/// `x` to three significant digits: radiances span decades between scenes, and a fixed three
/// decimals printed the classroom's accuracy of 7.24·10⁻⁴ W/(m² sr) as 0.001. Plain decimals from
/// 10⁻⁴ to below 10⁶, scientific notation beyond (a scene in other units, or an emitter of 10³⁰ W,
/// printed hundreds of digits).
pub(crate) fn significant(x: f64) -> String {
    if x == 0.0 || !x.is_finite() {
        return format!("{x}");
    }
    let exponent = x.abs().log10().floor() as i32;
    if !(-4..6).contains(&exponent) {
        return format!("{x:.2e}");
    }
    let decimals = (2 - exponent).max(0) as usize;
    format!("{x:.decimals$}")
}

/// A percentage as the summary line prints it: whole from 1% up (as `--accuracy 30%` is given),
/// [`significant`] below, where a whole number would read 0% (`--accuracy 1e-6` on the Cornell box
/// is 0.000520% of its mean radiance).
fn percent(p: f64) -> String {
    if p.abs() >= 1.0 {
        format!("{p:.0}")
    } else {
        significant(p)
    }
}

impl RenderCommand {
    /// Writes `image` as the PNG --show asks for: tone-mapped radiance, or the error estimate in false
    /// colour (in --units).
    fn write_image(
        &self,
        path: &Path,
        image: &Image,
        tone: &crate::output::tonemap::ToneMap,
    ) -> Result<()> {
        match self.show {
            Quantity::Radiance => write_png(path, image, tone),
            Quantity::ErrorEstimate => {
                // Pixels that see no solution (NaN) have no value and show grey.
                let errors: Vec<Option<f64>> = image
                    .pixels
                    .iter()
                    .map(|c| c.r.is_finite().then_some(c.r * self.units.scale()))
                    .collect();
                false_colour::write_png(path, &errors, image.width, image.height).map(|_| ())
            }
        }
    }

    /// Refuses outputs that would overwrite the scene, a file it reads, any scene file or each other,
    /// that go into a directory that does not exist, and an image not named .png (it holds PNG data).
    fn check_outputs(&self, inputs: &[PathBuf]) -> Result<()> {
        let mut outputs: Vec<(&str, &Path)> = vec![("--output", self.output.as_path())];
        outputs.extend(self.hdr.iter().map(|p| ("--hdr", p.as_path())));
        outputs.extend(self.export.iter().map(|p| ("--export", p.as_path())));
        outputs.extend(self.stats.iter().map(|p| ("--stats", p.as_path())));
        outputs.extend(
            self.emitter_mask
                .iter()
                .map(|p| ("--emitter-mask", p.as_path())),
        );
        super::args::check_outputs(&outputs, inputs)?;
        let is_png = self
            .output
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("png"));
        if !is_png {
            anyhow::bail!(
                "--output {}: the rendered image is written as PNG, so name it .png (for linear \
                 radiance add --hdr FILE.exr or FILE.hdr)",
                self.output.display()
            );
        }
        Ok(())
    }
}

/// `out.png` → `out-step03.png`, beside it.
fn step_path(output: &Path, step: usize) -> PathBuf {
    let stem = output
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or("radiosity");
    output.with_file_name(format!("{stem}-step{step:02}.png"))
}

fn extension(path: &Path) -> String {
    path.extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase()
}

#[cfg(test)]
mod tests {
    use super::{percent, significant};

    /// Three significant digits at every scale, where three decimals lost the classroom's accuracy.
    #[test]
    fn figures_keep_three_significant_digits() {
        assert_eq!(significant(7.2409e-4), "0.000724");
        assert_eq!(significant(0.05803), "0.0580");
        assert_eq!(significant(0.158), "0.158");
        assert_eq!(significant(12.345), "12.3");
        assert_eq!(significant(98_765.4), "98765");
        assert_eq!(significant(-0.00123), "-0.00123");
        assert_eq!(significant(0.0), "0");
        assert_eq!(significant(5.3348e300), "5.33e300");
        assert_eq!(significant(1.2345e-7), "1.23e-7");
        assert_eq!(significant(-3.0e6), "-3.00e6");
        assert_eq!(percent(30.0), "30");
        assert_eq!(percent(26.3), "26");
        assert_eq!(percent(0.4), "0.400");
        assert_eq!(percent(5.2e-4), "0.000520");
    }
}
