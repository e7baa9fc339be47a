//! False-colour error images: a per-pixel error on a logarithmic jet-like ramp (blue = small, red =
//! large) with a colour bar along the right side labelled with the minimum and maximum of the scale.
//! Labels are drawn with a built-in 3×5 bitmap font, so no font dependency is needed.

use anyhow::{ensure, Result};
use image::{Rgb as Px, RgbImage};
use serde::Serialize;
use std::path::Path;

/// The log scale mapped onto the colour ramp: `min` at the blue end, `max` at the red end.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ErrorScale {
    pub min: f64,
    pub max: f64,
}

/// Decades shown below the largest error: smaller errors (and zeros) saturate at the blue end, so that
/// rounding noise does not stretch the scale.
const MAX_DECADES: f64 = 6.0;

/// Colour of pixels without an error value (masked, or relative error on a black reference).
const NO_VALUE: Px<u8> = Px([96, 96, 96]);
const BACKGROUND: Px<u8> = Px([0, 0, 0]);
const INK: Px<u8> = Px([255, 255, 255]);

impl ErrorScale {
    /// The scale of a set of errors: from the smallest positive error (but no more than `MAX_DECADES`
    /// below the largest) to the largest. `None` entries are skipped; all-zero errors give [0, 0].
    pub fn of(errors: &[Option<f64>]) -> ErrorScale {
        let values = errors.iter().flatten().copied().filter(|e| e.is_finite());
        let max = values.clone().fold(0.0, f64::max);
        if max <= 0.0 {
            return ErrorScale { min: 0.0, max: 0.0 };
        }
        let floor = max * 10f64.powf(-MAX_DECADES);
        let min = values.filter(|&e| e > 0.0).fold(max, f64::min).max(floor);
        ErrorScale { min, max }
    }

    /// Position in [0, 1] of an error on the log scale.
    pub fn position(&self, e: f64) -> f64 {
        if self.max <= self.min || self.min <= 0.0 {
            return if e > 0.0 && self.max > 0.0 { 1.0 } else { 0.0 };
        }
        if e <= self.min {
            return 0.0;
        }
        ((e.ln() - self.min.ln()) / (self.max.ln() - self.min.ln())).clamp(0.0, 1.0)
    }
}

/// Jet-like ramp: blue, cyan, green, yellow, red as `t` goes from 0 to 1 (the middle three quarters of
/// the classic jet map, leaving out its dark ends so that the largest errors read as bright red).
pub fn ramp(t: f64) -> Px<u8> {
    let t = 0.125 + 0.75 * t.clamp(0.0, 1.0);
    let channel = |centre: f64| {
        let v = (1.5 - (4.0 * t - centre).abs()).clamp(0.0, 1.0);
        (v * 255.0).round() as u8
    };
    Px([channel(3.0), channel(2.0), channel(1.0)])
}

/// Renders the errors (`width × height`, row-major) as a false-colour image with its colour bar, and
/// returns the image with the scale used.
pub fn render(
    errors: &[Option<f64>],
    width: usize,
    height: usize,
) -> Result<(RgbImage, ErrorScale)> {
    ensure!(
        errors.len() == width * height && width > 0 && height > 0,
        "error map of {} values for a {width}×{height} image",
        errors.len()
    );
    let scale = ErrorScale::of(errors);
    let max_label = label(scale.max);
    let min_label = label(scale.min);
    // Glyphs are 3×5 cells scaled by `k`; larger images get larger text.
    let k = (height / 100).clamp(2, 4);
    let margin = 3 * k;
    let bar_width = 5 * k;
    let text_width = max_label.len().max(min_label.len()) * 4 * k;
    let glyph_height = 5 * k;
    let out_w = width + margin + bar_width + margin + text_width + margin;
    let out_h = height.max(2 * glyph_height + 2 * margin + 4 * k);
    let mut img = RgbImage::from_pixel(out_w as u32, out_h as u32, BACKGROUND);
    for y in 0..height {
        for x in 0..width {
            let c = errors[y * width + x].map_or(NO_VALUE, |e| ramp(scale.position(e)));
            img.put_pixel(x as u32, y as u32, c);
        }
    }
    // The bar runs from the maximum (top) to the minimum (bottom) between the margins.
    let bar_x = width + margin;
    let (top, bottom) = (margin, out_h - margin);
    for y in top..bottom {
        let t = 1.0 - (y - top) as f64 / (bottom - top - 1).max(1) as f64;
        for x in bar_x..bar_x + bar_width {
            img.put_pixel(x as u32, y as u32, ramp(t));
        }
    }
    let text_x = bar_x + bar_width + margin;
    draw_text(&mut img, &max_label, text_x, top, k);
    draw_text(&mut img, &min_label, text_x, bottom - glyph_height, k);
    Ok((img, scale))
}

/// Writes [`render`]'s image as PNG.
pub fn write_png(
    path: &Path,
    errors: &[Option<f64>],
    width: usize,
    height: usize,
) -> Result<ErrorScale> {
    let (img, scale) = render(errors, width, height)?;
    super::save_png(path, &img)?;
    Ok(scale)
}

/// Scale labels: three significant digits in scientific notation, e.g. `1.23E-4`.
fn label(v: f64) -> String {
    format!("{v:.2E}")
}

/// 3×5 glyphs, one row per 3-bit group (most significant bit on the left).
fn glyph(c: char) -> Option<[u8; 5]> {
    Some(match c {
        '0' => [0b111, 0b101, 0b101, 0b101, 0b111],
        '1' => [0b010, 0b110, 0b010, 0b010, 0b111],
        '2' => [0b111, 0b001, 0b111, 0b100, 0b111],
        '3' => [0b111, 0b001, 0b111, 0b001, 0b111],
        '4' => [0b101, 0b101, 0b111, 0b001, 0b001],
        '5' => [0b111, 0b100, 0b111, 0b001, 0b111],
        '6' => [0b111, 0b100, 0b111, 0b101, 0b111],
        '7' => [0b111, 0b001, 0b001, 0b001, 0b001],
        '8' => [0b111, 0b101, 0b111, 0b101, 0b111],
        '9' => [0b111, 0b101, 0b111, 0b001, 0b111],
        '.' => [0b000, 0b000, 0b000, 0b000, 0b010],
        '-' => [0b000, 0b000, 0b111, 0b000, 0b000],
        '+' => [0b000, 0b010, 0b111, 0b010, 0b000],
        'E' => [0b111, 0b100, 0b111, 0b100, 0b111],
        _ => return None,
    })
}

/// Draws `text` with its top-left corner at (x, y), each font cell a k×k block; unknown characters are
/// left blank. Pixels falling outside the image are skipped.
fn draw_text(img: &mut RgbImage, text: &str, x: usize, y: usize, k: usize) {
    for (i, c) in text.chars().enumerate() {
        let Some(rows) = glyph(c) else { continue };
        for (row, bits) in rows.iter().enumerate() {
            for col in 0..3 {
                if bits & (0b100 >> col) == 0 {
                    continue;
                }
                for dy in 0..k {
                    for dx in 0..k {
                        let px = x + (4 * i + col) * k + dx;
                        let py = y + row * k + dy;
                        if px < img.width() as usize && py < img.height() as usize {
                            img.put_pixel(px as u32, py as u32, INK);
                        }
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ramp_ends_are_blue_and_red() {
        let lo = ramp(0.0);
        let hi = ramp(1.0);
        assert_eq!(lo, Px([0, 0, 255]));
        assert_eq!(hi, Px([255, 0, 0]));
        assert_eq!(ramp(0.5), Px([128, 255, 128]));
    }

    #[test]
    fn scale_is_logarithmic_and_capped() {
        let s = ErrorScale::of(&[Some(0.0), Some(1e-3), None, Some(1e-1)]);
        assert_eq!((s.min, s.max), (1e-3, 1e-1));
        assert!((s.position(1e-2) - 0.5).abs() < 1e-12);
        assert_eq!(s.position(0.0), 0.0);
        let capped = ErrorScale::of(&[Some(1e-20), Some(1.0)]);
        assert!((capped.min - 1e-6).abs() < 1e-18);
        let zero = ErrorScale::of(&[Some(0.0), None]);
        assert_eq!((zero.min, zero.max), (0.0, 0.0));
        assert_eq!(zero.position(0.0), 0.0);
    }

    #[test]
    fn every_label_character_has_a_glyph() {
        for v in [0.0, 1.0, 1.234e-7, 9.99e12, 5.5] {
            let text = label(v);
            assert!(text.chars().all(|c| glyph(c).is_some()), "{text}");
        }
    }
}
