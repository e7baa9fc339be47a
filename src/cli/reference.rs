//! `radiosity reference [SCENE] --hdr ref.exr --spp N`: the unbiased path-traced reference image, with the
//! radiosity renderer's camera and pixel centres, in linear radiance.

use super::args::{CameraArgs, SceneArgs};
use crate::pipeline::{build_visibility, VisibilityKind};
use crate::progress::Progress;
use crate::reference::{render_reference, samples_taken, PixelFilter, ReferenceSettings};
use anyhow::Result;
use clap::Args;
use std::path::PathBuf;
use std::time::Instant;

/// Every sample of a pixel goes through the pixel centre: each pixel estimates the radiance leaving the
/// surface point seen through its centre, comparable pixel by pixel with the radiosity image.
#[derive(Args, Debug)]
pub struct ReferenceCommand {
    #[command(flatten)]
    pub scene: SceneArgs,
    #[command(flatten)]
    pub camera: CameraArgs,
    /// Output file of the mean radiance (linear): Radiance HDR for .hdr or .pic, else OpenEXR.
    #[arg(long, value_name = "FILE")]
    pub hdr: PathBuf,
    /// Paths per pixel (at least 2; rounded up to a multiple of 16, the independent batches the standard
    /// error is estimated from).
    #[arg(long, default_value_t = 64, value_name = "N", value_parser = super::args::count(0, 1 << 24))]
    pub spp: usize,
    /// Output file of the per-pixel standard error of the mean (linear radiance), in the same
    /// formats as --hdr.
    #[arg(long, value_name = "FILE")]
    pub stderr: Option<PathBuf>,
    /// Bounces before Russian roulette may end a path.
    #[arg(long, default_value_t = 3, value_name = "N", value_parser = super::args::count(0, 1000))]
    pub roulette_depth: usize,
    /// Ray casting back end.
    #[arg(long, value_enum, default_value_t = VisibilityKind::Bvh)]
    pub visibility: VisibilityKind,
    /// Pixel footprint: the average over the pixel (box, comparable with `render --spp 16`), or its
    /// centre.
    #[arg(long, value_enum, default_value_t = PixelFilter::Box)]
    pub filter: PixelFilter,
}

impl ReferenceCommand {
    pub fn run(&self, seed: u64, progress: &Progress) -> Result<()> {
        anyhow::ensure!(
            self.spp >= 2,
            "--spp must be at least 2 (the standard error needs two samples)"
        );
        let (scene, name) = self.scene.load_for_solving(progress)?;
        let mut outputs = vec![("--hdr", self.hdr.as_path())];
        outputs.extend(self.stderr.iter().map(|p| ("--stderr", p.as_path())));
        super::args::check_outputs(&outputs, &scene.sources)?;
        anyhow::ensure!(
            scene.emitter_count() > 0 || !scene.luminaires.is_empty(),
            "{name} has no emitting surface or luminaire"
        );
        let camera = self.camera.camera(&scene, 512)?;
        super::args::check_samples(camera.width, camera.height, self.spp)?;
        let settings = ReferenceSettings {
            spp: self.spp,
            seed,
            roulette_depth: self.roulette_depth,
            filter: self.filter,
        };
        let start = Instant::now();
        let visibility = build_visibility(&scene, self.visibility)?;
        let image = render_reference(&scene, visibility.as_ref(), &camera, &settings, progress);
        let seconds = start.elapsed().as_secs_f64();
        image.mean.write_linear(&self.hdr)?;
        if let Some(path) = &self.stderr {
            image.stderr.write_linear(path)?;
        }
        if !progress.quiet {
            let relative = image
                .mean_relative_stderr()
                .map_or("n/a (all black)".to_string(), |r| {
                    format!("{:.3}%", 100.0 * r)
                });
            outln!(
                "reference: {name}, {}x{} at {} spp in {seconds:.2} s ({}); mean relative standard error {relative} over non-black pixels",
                camera.width,
                camera.height,
                samples_taken(self.spp),
                visibility.name()
            )?;
        }
        Ok(())
    }
}
