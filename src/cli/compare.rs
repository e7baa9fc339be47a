//! `radiosity compare A.exr B.exr`: error metrics of image A against reference B, a false-colour error
//! image, and the feature-based error metric of Sillion & Drettakis (§2.2) for chosen feature sizes.

use crate::measures::fbem::{self, Fbem, Mask};
use crate::measures::image_metrics::{self, ChannelErrors, ImageErrors, ReferenceNoise};
use crate::output::false_colour::{self, ErrorScale};
use crate::output::image::Image;
use anyhow::{ensure, Context, Result};
use clap::Args;
use serde::Serialize;
use std::path::{Path, PathBuf};

#[derive(Args, Debug)]
pub struct CompareCommand {
    /// Approximation (linear: OpenEXR or Radiance HDR).
    pub a: PathBuf,
    /// Reference (linear: OpenEXR or Radiance HDR); relative errors are relative to it.
    pub b: PathBuf,
    /// The reference's standard-error image (`radiosity reference --stderr`): reports the reference's own
    /// noise and the luminance error with that noise removed in quadrature.
    #[arg(long, value_name = "EXR")]
    pub reference_stderr: Option<PathBuf>,
    /// PNG of pixels to ignore (nonzero = ignore), the size of the images.
    #[arg(long, value_name = "PNG")]
    pub mask: Option<PathBuf>,
    /// Also ignore pixels where the reference is exactly black (background).
    #[arg(long)]
    pub ignore_black_reference: bool,
    /// Write a false-colour PNG of the per-pixel luminance error (log scale) with a colour bar.
    #[arg(long, value_name = "PNG")]
    pub diff: Option<PathBuf>,
    /// Show the relative luminance error |L(a) − L(b)| / L(b) in --diff instead of the absolute one.
    #[arg(long)]
    pub relative: bool,
    /// Print every number as JSON on standard output.
    #[arg(long)]
    pub json: bool,
    /// Feature-based error metric for each feature size (pixels).
    #[arg(long, num_args = 1.., value_name = "SIZE", value_parser = super::args::count(0, 4096))]
    pub fbem: Vec<usize>,
    /// Exponent p of the FBEM norm.
    #[arg(long, default_value_t = 2.0, value_name = "P")]
    pub fbem_p: f64,
    /// Rendering of the reference view without the occluders (or with visibility ignored): the feature
    /// mask is then the reference's shadow region. Without it, the mask is estimated from the reference.
    #[arg(long, value_name = "EXR")]
    pub unoccluded: Option<PathBuf>,
    /// Relative darkening that marks a pixel as shadowed (feature) for the FBEM mask.
    #[arg(long, default_value_t = 0.1, value_name = "T")]
    pub shadow_threshold: f64,
    /// Largest shadow width (pixels) detected when the mask is estimated from the reference alone;
    /// default: a quarter of the smaller image side.
    #[arg(long, value_name = "PIXELS", value_parser = super::args::count(0, 4096))]
    pub feature_window: Option<usize>,
    /// Write the feature mask 𝓕^s as PNG (white = feature, grey = ignored); with several sizes, one file
    /// per size named with `-sSIZE` before the extension.
    #[arg(long, value_name = "PNG")]
    pub mask_out: Option<PathBuf>,
}

#[derive(Serialize)]
struct Report<'a> {
    a: &'a Path,
    b: &'a Path,
    errors: ImageErrors,
    #[serde(skip_serializing_if = "Option::is_none")]
    reference_noise: Option<ReferenceNoise>,
    #[serde(skip_serializing_if = "Option::is_none")]
    diff: Option<DiffReport<'a>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    fbem_mask: Option<&'static str>,
    fbem: Vec<Fbem>,
}

#[derive(Serialize)]
struct DiffReport<'a> {
    path: &'a Path,
    relative: bool,
    scale: ErrorScale,
}

impl CompareCommand {
    pub fn run(&self) -> Result<()> {
        ensure!(
            self.mask_out.is_none() || !self.fbem.is_empty(),
            "--mask-out needs --fbem SIZE"
        );
        self.check_outputs()?;
        let a = Image::read_linear(&self.a)?;
        let b = Image::read_linear(&self.b)?;
        image_metrics::ensure_same_size(&a, &b)
            .with_context(|| format!("comparing {} with {}", self.a.display(), self.b.display()))?;
        let ignore = self.ignore_mask(&b)?;
        let ignore = ignore.as_deref();
        let errors = image_metrics::compare(&a, &b, ignore)?;
        let reference_noise = match &self.reference_stderr {
            Some(path) => Some(
                image_metrics::reference_noise(&errors, &Image::read_linear(path)?, ignore)
                    .with_context(|| format!("reference noise from {}", path.display()))?,
            ),
            None => None,
        };

        let diff = match &self.diff {
            Some(path) => {
                let map = image_metrics::luminance_error_map(&a, &b, ignore, self.relative)?;
                let scale = false_colour::write_png(path, &map, a.width, a.height)?;
                Some(DiffReport {
                    path,
                    relative: self.relative,
                    scale,
                })
            }
            None => None,
        };

        let mut fbem_mask = None;
        let mut results = Vec::new();
        if !self.fbem.is_empty() {
            let (features, kind) = self.features(&b, ignore)?;
            fbem_mask = Some(kind);
            for &size in &self.fbem {
                results.push(fbem::fbem(&a, &b, &features, size, self.fbem_p, ignore)?);
                if let Some(path) = self.mask_out_path(size) {
                    fbem::feature_mask(&features, size).write_png(&path, ignore)?;
                }
            }
        }

        let report = Report {
            a: &self.a,
            b: &self.b,
            errors,
            reference_noise,
            diff,
            fbem_mask,
            fbem: results,
        };
        if self.json {
            outln!("{}", serde_json::to_string_pretty(&report)?)?;
        } else {
            print_text(&report)?;
        }
        Ok(())
    }

    /// Pixels to ignore: the --mask PNG, plus black reference pixels with --ignore-black-reference.
    fn ignore_mask(&self, b: &Image) -> Result<Option<Vec<bool>>> {
        let mut ignore: Option<Vec<bool>> = None;
        if let Some(path) = &self.mask {
            let m = Mask::read_png(path)?;
            ensure!(
                m.width == b.width && m.height == b.height,
                "mask {} is {}×{} but the images are {}×{}",
                path.display(),
                m.width,
                m.height,
                b.width,
                b.height
            );
            ignore = Some(m.bits);
        }
        if self.ignore_black_reference {
            let black = image_metrics::black_pixels(b);
            ignore = Some(match ignore {
                Some(m) => m.iter().zip(&black).map(|(&x, &y)| x || y).collect(),
                None => black,
            });
        }
        Ok(ignore)
    }

    /// The unfiltered feature mask of the reference and how it was obtained.
    fn features(&self, b: &Image, ignore: Option<&[bool]>) -> Result<(Mask, &'static str)> {
        match &self.unoccluded {
            Some(path) => {
                let u = Image::read_linear(path)?;
                let m = fbem::shadow_mask(b, &u, self.shadow_threshold)
                    .with_context(|| format!("shadow mask from {}", path.display()))?;
                Ok((m, "shadow"))
            }
            None => {
                let window = self
                    .feature_window
                    .unwrap_or(b.width.min(b.height) / 4)
                    .max(1);
                let m =
                    fbem::feature_mask_from_reference(b, window, self.shadow_threshold, ignore)?;
                Ok((m, "reference"))
            }
        }
    }
}

/// `mask.png` → `mask-s12.png`.
impl CompareCommand {
    /// Refuses a --diff or --mask-out file that is one of the images read (or that is written twice).
    fn check_outputs(&self) -> Result<()> {
        let mut inputs = vec![self.a.clone(), self.b.clone()];
        inputs.extend(
            self.mask
                .iter()
                .chain(&self.unoccluded)
                .chain(&self.reference_stderr)
                .cloned(),
        );
        let masks: Vec<PathBuf> = self
            .fbem
            .iter()
            .filter_map(|&size| self.mask_out_path(size))
            .collect();
        let mut outputs: Vec<(&str, &Path)> =
            self.diff.iter().map(|p| ("--diff", p.as_path())).collect();
        outputs.extend(masks.iter().map(|p| ("--mask-out", p.as_path())));
        super::args::check_outputs(&outputs, &inputs)
    }
}

impl CompareCommand {
    /// The --mask-out file of feature size `size` (suffixed with the size when there are several).
    fn mask_out_path(&self, size: usize) -> Option<PathBuf> {
        let out = self.mask_out.as_ref()?;
        Some(if self.fbem.len() > 1 {
            with_size_suffix(out, size)
        } else {
            out.clone()
        })
    }
}

fn with_size_suffix(path: &Path, size: usize) -> PathBuf {
    let stem = path.file_stem().unwrap_or_default().to_string_lossy();
    let name = match path.extension() {
        Some(ext) => format!("{stem}-s{size}.{}", ext.to_string_lossy()),
        None => format!("{stem}-s{size}"),
    };
    path.with_file_name(name)
}

fn print_text(r: &Report) -> std::io::Result<()> {
    let e = &r.errors;
    outln!("a: {}", r.a.display())?;
    outln!("b: {} (reference)", r.b.display())?;
    outln!(
        "{}×{} pixels, {} compared, {} ignored",
        e.width,
        e.height,
        e.compared,
        e.ignored
    )?;
    outln!(
        "{:<10} {:>12} {:>12} {:>12} {:>12} {:>12}",
        "",
        "RMSE",
        "rel. RMSE",
        "MAE",
        "max",
        "max at"
    )?;
    let row = |name: &str, c: &ChannelErrors| {
        let rel = c
            .relative_rmse
            .map_or_else(|| "-".to_string(), |v| format!("{v:.6e}"));
        outln!(
            "{name:<10} {:>12.6e} {rel:>12} {:>12.6e} {:>12.6e} {:>12}",
            c.rmse,
            c.mae,
            c.max,
            format!("({}, {})", c.max_at[0], c.max_at[1])
        )
    };
    row("r", &e.r)?;
    row("g", &e.g)?;
    row("b", &e.b)?;
    row("luminance", &e.luminance)?;
    if let Some(n) = &r.reference_noise {
        let pct =
            |v: Option<f64>| v.map_or_else(|| "-".to_string(), |v| format!("{:.2}%", 100.0 * v));
        outln!(
            "reference noise (luminance standard error, RMS): {:.6e} ({}); error with it removed: {:.6e} ({})",
            n.rms,
            pct(n.relative_rms),
            n.corrected_rmse,
            pct(n.corrected_relative_rmse)
        )?;
    }
    if let Some(d) = &r.diff {
        outln!(
            "diff: {} ({} luminance error, colour scale {:.3e} .. {:.3e})",
            d.path.display(),
            if d.relative { "relative" } else { "absolute" },
            d.scale.min,
            d.scale.max
        )?;
    }
    if let Some(kind) = r.fbem_mask {
        let source = match kind {
            "shadow" => "shadow region (with --unoccluded)",
            _ => "estimated from the reference alone",
        };
        outln!(
            "FBEM of luminance, p = {}; feature mask: {source}",
            r.fbem.first().map_or(2.0, |f| f.p)
        )?;
        outln!(
            "{:>6} {:>12} {:>10} {:>14}",
            "size",
            "FBEM",
            "openings",
            "feature frac."
        )?;
        for f in &r.fbem {
            outln!(
                "{:>6} {:>12.6e} {:>10} {:>14.4}",
                f.size,
                f.value,
                f.openings,
                f.feature_fraction
            )?;
        }
    }
    Ok(())
}
