//! Linear-radiance images and their files: OpenEXR or Radiance HDR (linear, for measurement) and PNG
//! (exposed, tone-mapped, sRGB-encoded, for looking at).

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
        write_encoded(path, self.exr_bytes())
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

    /// Writes linear radiance in the format the name asks for: Radiance HDR (RGBE, 8-bit mantissas
    /// with a shared exponent: within 0.4% per channel, what most viewers open) for `.hdr` and
    /// `.pic`, else 32-bit float OpenEXR (exact in `f32`; what measurements should use).
    pub fn write_linear(&self, path: &Path) -> Result<()> {
        if is_radiance_name(path) {
            self.write_radiance(path)
        } else {
            self.write_exr(path)
        }
    }

    /// Writes linear radiance as a run-length encoded Radiance HDR (RGBE) file.
    pub fn write_radiance(&self, path: &Path) -> Result<()> {
        write_encoded(path, self.radiance_bytes())
    }

    /// The Radiance HDR file's bytes (negative channels clamped to 0: RGBE has no sign).
    fn radiance_bytes(&self) -> Result<Vec<u8>> {
        let pixels: Vec<image::Rgb<f32>> = self
            .pixels
            .iter()
            .map(|c| image::Rgb(c.to_f32().map(|v| v.max(0.0))))
            .collect();
        let mut bytes = Vec::new();
        image::codecs::hdr::HdrEncoder::new(&mut bytes).encode(&pixels, self.width, self.height)?;
        Ok(bytes)
    }

    /// Reads a linear image of at most [`MAX_FILE_BYTES`](crate::scene::MAX_FILE_BYTES), OpenEXR (its
    /// first RGB(A) layer) or Radiance HDR, told apart by their first bytes, whatever the name.
    pub fn read_linear(path: &Path) -> Result<Image> {
        let bytes = crate::scene::read_bounded(path)
            .map_err(|e| anyhow::anyhow!("reading {}: {e}", path.display()))?;
        let image = if bytes.starts_with(&EXR_MAGIC) {
            Image::from_exr_bytes(&bytes)
        } else if bytes.starts_with(b"#?") {
            Image::from_radiance_bytes(&bytes)
        } else {
            Err(anyhow::anyhow!(
                "not an OpenEXR or Radiance HDR image (a linear image, as `render --hdr` writes)"
            ))
        };
        image.with_context(|| format!("reading {}", path.display()))
    }

    /// Decodes a Radiance HDR (RGBE) file's bytes; images of more than [`MAX_PIXELS`] pixels are
    /// refused before any pixel memory is allocated. Writers truncate each channel to its 8-bit
    /// mantissa (Radiance's `setcolr`, the `image` crate's encoder), so a mantissa `c` stands for
    /// `[c, c + 1)` steps: each channel is read at the middle, `c + ½`, as Radiance's `colr_color`
    /// reads it (the `image` decoder reads `c`: the brightest channel 0.2–0.4% low, dimmer ones more).
    pub fn from_radiance_bytes(bytes: &[u8]) -> Result<Image> {
        use image::ImageDecoder;
        let decoder = image::codecs::hdr::HdrDecoder::new_nonstrict(std::io::Cursor::new(bytes))?;
        let (width, height) = decoder.dimensions();
        let (width, height) = (width as usize, height as usize);
        anyhow::ensure!(
            width as u128 * height as u128 <= MAX_PIXELS as u128,
            "an image of {width}x{height} pixels is larger than the {MAX_PIXELS} pixels read"
        );
        let mut buffer = vec![0u8; decoder.total_bytes() as usize];
        decoder.read_image(&mut buffer)?;
        let pixels = buffer
            .chunks_exact(12)
            .map(|p| {
                let channel = |i: usize| f32::from_ne_bytes(p[i..i + 4].try_into().unwrap());
                let (r, g, b) = (channel(0), channel(4), channel(8));
                // The largest channel's mantissa lies in [128, 256) steps of the shared exponent:
                // half a step is 2^-8 of its power of two (exact, from its exponent bits).
                let exponent = (r.max(g).max(b).to_bits() >> 23) & 0xff;
                let half = if exponent > 8 {
                    f32::from_bits((exponent - 8) << 23)
                } else {
                    0.0
                };
                Rgb::new((r + half).into(), (g + half).into(), (b + half).into())
            })
            .collect();
        Ok(Image {
            width,
            height,
            pixels,
        })
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

/// Writes a file encoded in memory (so that an encoder never leaves a partial file behind), with
/// the file's name in either error.
fn write_encoded(path: &Path, bytes: Result<Vec<u8>>) -> Result<()> {
    let bytes = bytes.with_context(|| format!("encoding {}", path.display()))?;
    super::write_atomically(path, |to| {
        std::fs::write(to, &bytes).with_context(|| format!("writing {}", path.display()))
    })
}

/// An OpenEXR file's first four bytes.
const EXR_MAGIC: [u8; 4] = [0x76, 0x2f, 0x31, 0x01];

/// Whether `path` names a Radiance HDR file (`.hdr`, `.pic`).
fn is_radiance_name(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("hdr") || e.eq_ignore_ascii_case("pic"))
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
        let back = Image::read_linear(&path).unwrap();
        assert_eq!((back.width, back.height), (3, 2));
        for (a, b) in img.pixels.iter().zip(&back.pixels) {
            assert!((a.r - b.r).abs() <= 1e-6 * a.r.abs().max(1.0));
            assert!((a.g - b.g).abs() <= 1e-6 * a.g.abs().max(1.0));
            assert!((a.b - b.b).abs() <= 1e-6 * a.b.abs().max(1.0));
        }
    }

    /// `.hdr` writes Radiance RGBE: each channel within its 8-bit mantissa's rounding (relative
    /// `2^-8` of the pixel's largest channel), negatives clamped to 0; `read_linear` tells the two
    /// formats apart by content, and refuses anything else with the file's name.
    #[test]
    fn radiance_round_trip_within_rgbe_precision_and_formats_told_by_content() {
        let mut img = Image::new(5, 3);
        img.set(4, 2, Rgb::new(0.25, 1.5, 1e3));
        img.set(0, 0, Rgb::new(0.1, 0.2, 0.3));
        img.set(1, 1, Rgb::new(-1.0, 7e-5, 3.0));
        let dir = std::env::temp_dir().join(format!("radiosity-hdr-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let hdr = dir.join("t.hdr");
        img.write_linear(&hdr).unwrap();
        assert!(std::fs::read(&hdr).unwrap().starts_with(b"#?RADIANCE"));
        let back = Image::read_linear(&hdr).unwrap();
        assert_eq!((back.width, back.height), (5, 3));
        for (a, b) in img.pixels.iter().zip(&back.pixels) {
            let tolerance = a.max_channel() / 256.0 + 1e-30;
            for (x, y) in [(a.r, b.r), (a.g, b.g), (a.b, b.b)] {
                assert!(
                    (x.max(0.0) - y).abs() <= tolerance,
                    "{a:?} read back as {b:?}"
                );
            }
        }
        // Unbiased: over many values the mean relative error is far below the 0.66% that reading
        // truncated mantissas as they stand gives (its spread, a uniform half step of 2^-8 to 2^-9
        // relative, averages to about 0.005% over these 12,000 channels).
        let mut ramp = Image::new(40, 1);
        for x in 0..40 {
            let v = 0.013 * 1.37f64.powi(x as i32);
            ramp.set(x, 0, Rgb::new(v, v * 0.61, v * 0.23));
        }
        let mut bias = 0.0;
        let mut shifted = ramp.clone();
        for step in 0..100 {
            for (p, q) in shifted.pixels.iter_mut().zip(&ramp.pixels) {
                *p = *q * (1.0 + step as f64 / 137.0);
            }
            shifted.write_linear(&hdr).unwrap();
            let back = Image::read_linear(&hdr).unwrap();
            for (a, b) in shifted.pixels.iter().zip(&back.pixels) {
                bias += (b.r / a.r - 1.0) + (b.g / a.g - 1.0) + (b.b / a.b - 1.0);
            }
        }
        let bias = bias / 12_000.0;
        assert!(bias.abs() < 5e-4, "mean relative error {bias}");
        // An EXR under a .hdr-less name is read as EXR; a PNG is refused by name.
        let exr = dir.join("t.linear");
        img.write_linear(&exr).unwrap();
        assert_eq!(Image::read_linear(&exr).unwrap().get(4, 2), img.get(4, 2));
        let png = dir.join("t.png");
        std::fs::write(&png, b"\x89PNG\r\n\x1a\n").unwrap();
        let error = format!("{:#}", Image::read_linear(&png).unwrap_err());
        assert!(
            error.contains("t.png") && error.contains("not an OpenEXR or Radiance"),
            "{error}"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// Damaged Radiance files (bytes changed, cut short, headers claiming huge sizes) are errors or
    /// images of the size they claim, never a panic or an allocation past [`MAX_PIXELS`]; the fuzz
    /// target `radiance` explores further.
    #[test]
    fn damaged_radiance_files_are_errors_not_panics() {
        use rand::{Rng, SeedableRng};
        let mut img = Image::new(40, 9);
        for (i, p) in img.pixels.iter_mut().enumerate() {
            *p = Rgb::new(i as f64, 0.5, (i % 7) as f64 * 1e-3);
        }
        let good = img.radiance_bytes().unwrap();
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(7);
        for case in 0..3000 {
            let mut bytes = good.clone();
            match case % 3 {
                0 => {
                    for _ in 0..rng.random_range(1..8) {
                        let at = rng.random_range(0..bytes.len());
                        bytes[at] = rng.random();
                    }
                }
                1 => bytes.truncate(rng.random_range(0..bytes.len())),
                _ => {
                    let header = format!(
                        "#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y {} +X {}\n",
                        rng.random_range(0..1u64 << 20),
                        rng.random_range(0..1u64 << 20)
                    );
                    bytes = header.into_bytes();
                    bytes.extend((0..rng.random_range(0..64)).map(|_| rng.random::<u8>()));
                }
            }
            if let Ok(image) = Image::from_radiance_bytes(&bytes) {
                assert_eq!(image.pixels.len(), image.width * image.height);
                assert!(image.pixels.len() <= MAX_PIXELS);
            }
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
