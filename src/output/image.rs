//! Linear-radiance images and their files: OpenEXR (linear, for measurement) and PNG (exposed,
//! tone-mapped, sRGB-encoded, for looking at).

use crate::color::Rgb;
use anyhow::{Context, Result};
use std::path::Path;

/// A linear RGB image, row-major, row 0 at the top.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    pub width: usize,
    pub height: usize,
    pub pixels: Vec<Rgb>,
}

impl Image {
    pub fn new(width: usize, height: usize) -> Self {
        Image {
            width,
            height,
            pixels: vec![Rgb::BLACK; width * height],
        }
    }

    pub fn get(&self, x: usize, y: usize) -> Rgb {
        self.pixels[y * self.width + x]
    }

    pub fn set(&mut self, x: usize, y: usize, c: Rgb) {
        self.pixels[y * self.width + x] = c;
    }

    /// Writes linear radiance as 32-bit float OpenEXR.
    pub fn write_exr(&self, path: &Path) -> Result<()> {
        let bytes = self
            .exr_bytes()
            .with_context(|| format!("encoding {}", path.display()))?;
        super::write_atomically(path, |to| {
            std::fs::write(to, &bytes).with_context(|| format!("writing {}", path.display()))
        })
    }

    /// The OpenEXR file's bytes (RLE in 64² tiles, exr's default), encoded in memory: exr's `to_file`
    /// deletes its target on a write error, even a device. The tiles are stored in increasing order,
    /// not in the order exr's threads finish compressing them, so that the file, not only its
    /// pixels, is the same on any number of threads.
    fn exr_bytes(&self) -> Result<Vec<u8>> {
        use exr::prelude::{
            Encoding, Image as Exr, LineOrder, SpecificChannels, Vec2, WritableImage,
        };
        let channels = SpecificChannels::rgb(|Vec2(x, y)| {
            let [r, g, b] = self.get(x, y).to_f32();
            (r, g, b)
        });
        let encoding = Encoding {
            line_order: LineOrder::Increasing,
            ..Encoding::FAST_LOSSLESS
        };
        let mut bytes = std::io::Cursor::new(Vec::new());
        Exr::from_encoded_channels((self.width, self.height), encoding, channels)
            .write()
            .to_buffered(&mut bytes)?;
        Ok(bytes.into_inner())
    }

    /// Reads the first RGB(A) layer of an OpenEXR file of at most
    /// [`MAX_FILE_BYTES`](crate::scene::MAX_FILE_BYTES).
    pub fn read_exr(path: &Path) -> Result<Image> {
        let bytes = crate::scene::read_bounded(path)
            .map_err(|e| anyhow::anyhow!("reading {}: {e}", path.display()))?;
        Image::from_exr_bytes(&bytes).with_context(|| format!("reading {}", path.display()))
    }

    /// Decodes the first RGB(A) layer of OpenEXR bytes. Layers of more than [`MAX_PIXELS`] pixels
    /// are refused before any pixel memory is allocated.
    pub fn from_exr_bytes(bytes: &[u8]) -> Result<Image> {
        use exr::prelude::*;
        let meta = exr::meta::MetaData::read_from_buffered(bytes, false)?;
        for header in &meta.headers {
            let size = header.layer_size;
            anyhow::ensure!(
                size.width() as u128 * size.height() as u128 <= MAX_PIXELS as u128,
                "a layer of {}x{} pixels is larger than the {MAX_PIXELS} pixels read",
                size.width(),
                size.height()
            );
        }
        let image = read()
            .no_deep_data()
            .largest_resolution_level()
            .rgba_channels(
                |resolution, _| Self::new(resolution.width(), resolution.height()),
                |image: &mut Self, position, (r, g, b, _a): (f32, f32, f32, f32)| {
                    image.set(
                        position.x(),
                        position.y(),
                        Rgb::new(r as f64, g as f64, b as f64),
                    )
                },
            )
            .first_valid_layer()
            .all_attributes()
            .from_buffered(std::io::Cursor::new(bytes))?;
        Ok(image.layer_data.channel_data.pixels)
    }
}

/// Most pixels in one image (8192 x 4096): a larger image needs gigabytes.
pub const MAX_PIXELS: usize = 1 << 25;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exr_round_trip_is_exact_in_f32() {
        let mut img = Image::new(3, 2);
        img.set(2, 1, Rgb::new(0.25, 1.5, 1e3));
        img.set(0, 0, Rgb::new(0.1, 0.2, 0.3));
        let dir = std::env::temp_dir().join(format!("radiosity-exr-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("t.exr");
        img.write_exr(&path).unwrap();
        let back = Image::read_exr(&path).unwrap();
        assert_eq!((back.width, back.height), (3, 2));
        for (a, b) in img.pixels.iter().zip(&back.pixels) {
            assert!((a.r - b.r).abs() <= 1e-6 * a.r.abs().max(1.0));
            assert!((a.g - b.g).abs() <= 1e-6 * a.g.abs().max(1.0));
            assert!((a.b - b.b).abs() <= 1e-6 * a.b.abs().max(1.0));
        }
    }

    /// exr compresses tiles on its own threads; stored in the order they finish, the same pixels
    /// gave files that differ from run to run (the classroom's `--hdr` on one and two threads).
    #[test]
    fn exr_files_store_their_tiles_in_order() {
        let mut img = Image::new(300, 200); // 5 × 4 tiles of 64²
        for y in 0..img.height {
            for x in 0..img.width {
                // Flat in some tiles, noisy in others: their compression takes unequal time.
                let noisy = (x / 64 + y / 64) % 2 == 0;
                let v = if noisy {
                    ((x * 7919 + y * 104729) % 1000) as f64
                } else {
                    1.0
                };
                img.set(x, y, Rgb::new(v, 0.5 * v, 0.25));
            }
        }
        let bytes = img.exr_bytes().unwrap();
        let meta = exr::meta::MetaData::read_from_buffered(bytes.as_slice(), false).unwrap();
        assert_eq!(
            meta.headers[0].line_order,
            exr::meta::attribute::LineOrder::Increasing
        );
        for _ in 0..8 {
            assert_eq!(img.exr_bytes().unwrap(), bytes);
        }
        let back = Image::from_exr_bytes(&bytes).unwrap();
        assert_eq!(back.pixels, img.pixels);
    }
}
