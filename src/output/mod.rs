//! Output: pinhole camera, ray-cast rendering of the solution (flat, smooth, mesh overlay), PNG and
//! OpenEXR images, illuminated models (PLY, glTF), the interactive viewer page (HTML).

pub mod camera;
pub mod export;
pub mod false_colour;
pub mod image;
pub mod mesh_values;
pub mod plot;
pub mod render;
pub mod tonemap;
pub mod viewer;
pub mod work_plane;

use anyhow::{Context, Result};
use std::path::{Path, PathBuf};

/// The round step (1, 2 or 5 × 10^k) at or just above `range / count`: about `count` steps over
/// `range` (iso-line levels of lux plots, ticks of chart axes).
pub fn round_step(range: f64, count: f64) -> f64 {
    let raw = range / count;
    let decade = 10f64.powf(raw.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * decade)
        .find(|&s| s >= raw)
        .unwrap_or(10.0 * decade)
}

/// Writes a file through `write` so that a failure leaves no partial file behind: into a temporary
/// sibling renamed over `path` on success, or straight into `path` when it is a device (`/dev/null`).
pub fn write_atomically(path: &Path, write: impl FnOnce(&Path) -> Result<()>) -> Result<()> {
    if path.exists() && !path.is_file() {
        anyhow::ensure!(
            !path.is_dir(),
            "cannot write {}: it is a directory",
            path.display()
        );
        return write(path);
    }
    let name = path
        .file_name()
        .with_context(|| format!("cannot write {}: no file name", path.display()))?;
    let mut temporary_name = std::ffi::OsString::from(".");
    temporary_name.push(name);
    temporary_name.push(format!(".{}.partial", std::process::id()));
    let temporary: PathBuf = path.with_file_name(temporary_name);
    let result = write(&temporary).and_then(|()| {
        std::fs::rename(&temporary, path).with_context(|| format!("writing {}", path.display()))
    });
    if result.is_err() {
        let _ = std::fs::remove_file(&temporary);
    }
    result
}

/// Writes an image as PNG through [`write_atomically`], reporting every write error (a full disk).
pub fn save_png(path: &Path, image: &impl WritePng) -> Result<()> {
    let mut png = Vec::new();
    image
        .write_png(&mut std::io::Cursor::new(&mut png))
        .with_context(|| format!("encoding {}", path.display()))?;
    write_atomically(path, |to| {
        std::fs::write(to, &png).with_context(|| format!("writing {}", path.display()))
    })
}

/// An image the `image` crate can encode as PNG.
pub trait WritePng {
    fn write_png(&self, to: &mut std::io::Cursor<&mut Vec<u8>>) -> ::image::ImageResult<()>;
}

impl WritePng for ::image::RgbImage {
    fn write_png(&self, to: &mut std::io::Cursor<&mut Vec<u8>>) -> ::image::ImageResult<()> {
        self.write_to(to, ::image::ImageFormat::Png)
    }
}

impl WritePng for ::image::GrayImage {
    fn write_png(&self, to: &mut std::io::Cursor<&mut Vec<u8>>) -> ::image::ImageResult<()> {
        self.write_to(to, ::image::ImageFormat::Png)
    }
}

pub use export::{write_glb, write_ply};
pub use mesh_values::{ShadedMesh, VertexRadiosity};
pub use render::{render, render_with, Antialias, RenderOptions, Shading};
pub use tonemap::{to_srgb8, write_png, Curve, Exposure, ToneMap};
