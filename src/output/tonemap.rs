//! From linear radiance to displayable 8-bit sRGB: exposure (a fixed multiplier, or automatic from the
//! log-average luminance), a tone curve per channel, then the sRGB transfer function (IEC 61966-2-1).

use super::image::Image;
use crate::color::Rgb;
use anyhow::Result;
use rayon::prelude::*;
use std::path::Path;

/// How linear radiance is scaled before the tone curve.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Exposure {
    /// Multiply radiance by this factor.
    Multiplier(f64),
    /// Map the log-average (geometric mean) of the non-black luminances to the middle grey [`AUTO_KEY`]
    /// (Reinhard et al.'s photographic key): the light sources, bright but few, barely move it, whereas a
    /// percentile rule keys on the light as soon as it covers more than a percent of the picture.
    Auto,
}

/// The tone curve applied per channel after exposure; its output is display-linear in [0, 1].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum Curve {
    /// Clamp to [0, 1].
    Linear,
    /// x / (1 + x).
    Reinhard,
    /// Narkowicz's fit of the ACES filmic reference rendering transform: a toe, a soft shoulder.
    #[default]
    Filmic,
}

/// Exposure and tone curve; the encoding is always sRGB.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ToneMap {
    pub exposure: Exposure,
    pub curve: Curve,
}

impl Default for ToneMap {
    fn default() -> Self {
        ToneMap {
            exposure: Exposure::Auto,
            curve: Curve::Filmic,
        }
    }
}

/// Exposed luminance that automatic exposure gives the log-average luminance.
pub const AUTO_KEY: f64 = 0.3;

impl ToneMap {
    /// The radiance multiplier for a set of linear colours (the pixels of an image, the vertices of a
    /// model). Automatic exposure ignores black and non-finite values and falls back to 1 when none is left.
    pub fn exposure_scale<I: IntoIterator<Item = Rgb>>(&self, colours: I) -> f64 {
        match self.exposure {
            Exposure::Multiplier(m) => m,
            Exposure::Auto => {
                let (mut log_sum, mut count) = (0.0, 0usize);
                for l in colours.into_iter().map(Rgb::luminance) {
                    if l.is_finite() && l > 0.0 {
                        log_sum += l.ln();
                        count += 1;
                    }
                }
                if count == 0 {
                    return 1.0;
                }
                AUTO_KEY / (log_sum / count as f64).exp()
            }
        }
    }

    /// The tone curve on one exposed channel value; output in [0, 1] (NaN maps to 0).
    pub fn curve(&self, x: f64) -> f64 {
        let x = if x.is_nan() { 0.0 } else { x.max(0.0) };
        let y = match self.curve {
            Curve::Linear => x,
            Curve::Reinhard => {
                if x.is_infinite() {
                    1.0
                } else {
                    x / (1.0 + x)
                }
            }
            Curve::Filmic => {
                if x.is_infinite() {
                    1.0
                } else {
                    let (a, b, c, d, e) = (2.51, 0.03, 2.43, 0.59, 0.14);
                    (x * (a * x + b)) / (x * (c * x + d) + e)
                }
            }
        };
        y.clamp(0.0, 1.0)
    }

    /// Exposure `scale` then the tone curve: display-linear colour in [0, 1] (what glTF's COLOR_0 holds).
    pub fn display_linear(&self, c: Rgb, scale: f64) -> Rgb {
        (c * scale).map(|x| self.curve(x))
    }
}

/// The sRGB transfer function (linear [0, 1] to encoded [0, 1]).
pub fn srgb_encode(linear: f64) -> f64 {
    let x = linear.clamp(0.0, 1.0);
    if x <= 0.0031308 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    }
}

/// Display-linear [0, 1] to an 8-bit sRGB code value, rounded to nearest.
pub fn srgb8(linear: f64) -> u8 {
    (srgb_encode(linear) * 255.0).round() as u8
}

/// Display-linear colour to 8-bit sRGB.
pub fn rgb8(c: Rgb) -> [u8; 3] {
    [srgb8(c.r), srgb8(c.g), srgb8(c.b)]
}

/// Tone-maps a linear radiance image to 8-bit sRGB.
pub fn to_srgb8(image: &Image, tone: &ToneMap) -> image::RgbImage {
    let scale = tone.exposure_scale(image.pixels.iter().copied());
    let mut out = image::RgbImage::new(image.width as u32, image.height as u32);
    // Three powers and a tone curve per pixel: spread over the threads (each pixel is its own).
    out.par_chunks_mut(3)
        .zip(&image.pixels)
        .for_each(|(pixel, &c)| pixel.copy_from_slice(&rgb8(tone.display_linear(c, scale))));
    out
}

/// Writes a tone-mapped PNG.
pub fn write_png(path: &Path, image: &Image, tone: &ToneMap) -> Result<()> {
    // Not `save_with_format`: the image crate's buffered file writer drops the error of its last
    // flush (a full disk went unnoticed).
    super::save_png(path, &to_srgb8(image, tone))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_encoding_at_known_points() {
        assert_eq!(srgb8(0.0), 0);
        assert_eq!(srgb8(1.0), 255);
        assert_eq!(srgb8(0.5), 188);
        assert_eq!(srgb8(-1.0), 0);
        assert_eq!(srgb8(7.0), 255);
        // Both branches meet at the 0.0031308 boundary (continuity to about 1e-7).
        let below = 12.92 * 0.0031308;
        let above = 1.055 * 0.0031308f64.powf(1.0 / 2.4) - 0.055;
        assert!((below - above).abs() < 1e-6);
        assert!((srgb_encode(0.0031308) - below).abs() < 1e-15);
        let just_above = 1.055 * 0.0031309f64.powf(1.0 / 2.4) - 0.055;
        assert_eq!(srgb_encode(0.0031309), just_above);
        assert!(just_above > below && just_above - below < 2e-6);
        // 18% grey encodes to 118 (the familiar mid-grey code value).
        assert_eq!(srgb8(0.18), 118);
    }

    #[test]
    fn curves_are_monotone_and_bounded() {
        for curve in [Curve::Linear, Curve::Reinhard, Curve::Filmic] {
            let tone = ToneMap {
                exposure: Exposure::Multiplier(1.0),
                curve,
            };
            assert_eq!(tone.curve(0.0), 0.0);
            assert_eq!(tone.curve(f64::NAN), 0.0);
            assert_eq!(tone.curve(f64::INFINITY), 1.0);
            let mut last = 0.0;
            for i in 1..2000 {
                let y = tone.curve(i as f64 * 0.01);
                assert!(y >= last && y <= 1.0, "{curve:?} at {i}");
                last = y;
            }
        }
        let reinhard = ToneMap {
            exposure: Exposure::Auto,
            curve: Curve::Reinhard,
        };
        assert!((reinhard.curve(1.0) - 0.5).abs() < 1e-15);
        let linear = ToneMap {
            exposure: Exposure::Auto,
            curve: Curve::Linear,
        };
        assert_eq!(linear.curve(0.25), 0.25);
        assert_eq!(linear.curve(3.0), 1.0);
    }

    #[test]
    fn auto_exposure_maps_the_log_average_to_the_key() {
        // 1000 pixels: 990 of luminance 2 (grey), 10 of 1000 (a light), plus black background.
        let mut pixels = vec![Rgb::splat(2.0); 990];
        pixels.extend(vec![Rgb::splat(1000.0); 10]);
        pixels.extend(vec![Rgb::BLACK; 500]);
        let tone = ToneMap::default();
        let scale = tone.exposure_scale(pixels.iter().copied());
        // Grey luminance is 2 * (0.2126 + 0.7152 + 0.0722) = 2.
        let log_average = ((990.0 * 2f64.ln() + 10.0 * 1000f64.ln()) / 1000.0).exp();
        assert!((scale * log_average - AUTO_KEY).abs() < 1e-12);
        assert_eq!(tone.exposure_scale([Rgb::BLACK]), 1.0);
        let fixed = ToneMap {
            exposure: Exposure::Multiplier(0.25),
            curve: Curve::Linear,
        };
        assert_eq!(fixed.exposure_scale(pixels.iter().copied()), 0.25);
    }

    #[test]
    fn png_round_trip_and_error_context() {
        let mut img = Image::new(4, 2);
        img.set(1, 0, Rgb::new(0.5, 1.0, 0.0));
        let tone = ToneMap {
            exposure: Exposure::Multiplier(1.0),
            curve: Curve::Linear,
        };
        let dir = std::env::temp_dir().join(format!("radiosity-png-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("t.png");
        write_png(&path, &img, &tone).unwrap();
        let back = image::open(&path).unwrap().to_rgb8();
        assert_eq!(back.dimensions(), (4, 2));
        assert_eq!(back.get_pixel(1, 0).0, [188, 255, 0]);
        assert_eq!(back.get_pixel(0, 0).0, [0, 0, 0]);
        let bad = dir.join("missing-dir").join("t.png");
        let err = write_png(&bad, &img, &tone).unwrap_err();
        assert!(format!("{err:#}").contains("missing-dir"));
    }
}
