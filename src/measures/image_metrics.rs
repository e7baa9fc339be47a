//! Image error metrics between an approximation `a` and a reference `b`: RMSE, relative RMSE, mean absolute
//! error and maximum error, per channel and for luminance, over the pixels a mask does not ignore.
//!
//! These are the usual L² / L¹ / L^∞ norms of Sillion–Drettakis §2.1: they add error contributions from all
//! pixels and cannot tell which feature sizes are missing; `measures::fbem` is the feature-based metric.

use crate::color::Rgb;
use crate::output::image::Image;
use anyhow::{bail, ensure, Result};
use serde::Serialize;

/// Error norms of one scalar quantity (a channel or luminance).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ChannelErrors {
    /// Root mean square of a − b.
    pub rmse: f64,
    /// RMSE divided by the mean of the reference `b`; `None` when that mean is zero.
    pub relative_rmse: Option<f64>,
    /// Mean of |a − b|.
    pub mae: f64,
    /// Largest |a − b|.
    pub max: f64,
    /// Pixel (x, y) of the largest error, the first one in row-major order.
    pub max_at: [usize; 2],
    /// Mean of the reference over the compared pixels.
    pub reference_mean: f64,
}

/// Errors of an approximation against a reference image.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ImageErrors {
    pub width: usize,
    pub height: usize,
    /// Pixels compared (not ignored by the mask).
    pub compared: usize,
    /// Pixels ignored by the mask.
    pub ignored: usize,
    pub r: ChannelErrors,
    pub g: ChannelErrors,
    pub b: ChannelErrors,
    /// Errors of the Rec. 709 luminance of each pixel.
    pub luminance: ChannelErrors,
}

/// Fails with both sizes when the images differ in size: a per-pixel comparison would be meaningless.
pub fn ensure_same_size(a: &Image, b: &Image) -> Result<()> {
    ensure!(
        a.width == b.width && a.height == b.height,
        "image sizes differ: {}×{} against reference {}×{}",
        a.width,
        a.height,
        b.width,
        b.height
    );
    Ok(())
}

/// Fails when a mask does not have one entry per pixel.
pub fn ensure_mask_len(mask: Option<&[bool]>, image: &Image) -> Result<()> {
    if let Some(m) = mask {
        ensure!(
            m.len() == image.width * image.height,
            "the mask has {} pixels but the images have {}×{} = {}",
            m.len(),
            image.width,
            image.height,
            image.width * image.height
        );
    }
    Ok(())
}

/// Pixels where the reference is exactly black (`--ignore-black-reference`): typically background that
/// no ray hit, where any error is an artefact of the renderer rather than of the solution.
pub fn black_pixels(reference: &Image) -> Vec<bool> {
    reference.pixels.iter().map(|c| c.is_black()).collect()
}

/// Compares approximation `a` with reference `b`, skipping pixels where `mask` is true.
///
/// Fails on different sizes, a mask of the wrong length, non-finite pixels, or when every pixel is masked.
pub fn compare(a: &Image, b: &Image, mask: Option<&[bool]>) -> Result<ImageErrors> {
    ensure_same_size(a, b)?;
    ensure_mask_len(mask, a)?;
    let mut acc = [Accumulator::default(); 4];
    let mut compared = 0;
    for (i, (&pa, &pb)) in a.pixels.iter().zip(&b.pixels).enumerate() {
        if mask.is_some_and(|m| m[i]) {
            continue;
        }
        let (x, y) = (i % a.width, i / a.width);
        for (name, p) in [("a", pa), ("b", pb)] {
            if !p.is_finite() {
                bail!("pixel ({x}, {y}) of image {name} is not finite: {p:?}");
            }
        }
        compared += 1;
        for (k, (va, vb)) in channels(pa).into_iter().zip(channels(pb)).enumerate() {
            acc[k].add(va, vb, [x, y]);
        }
    }
    ensure!(compared > 0, "every pixel is masked: nothing to compare");
    let [r, g, b_, l] = acc.map(|c| c.finish(compared));
    Ok(ImageErrors {
        width: a.width,
        height: a.height,
        compared,
        ignored: a.pixels.len() - compared,
        r,
        g,
        b: b_,
        luminance: l,
    })
}

/// What the reference's own Monte Carlo noise contributes to a measured luminance error.
///
/// With an unbiased reference b = t + n (n of zero mean and per-pixel standard error σ, independent of the
/// approximation a), E[(a − b)²] = (a − t)² + σ², so the error against the truth t is estimated by
/// √(RMSE² − mean σ²). The luminance standard error is bounded by the luminance of the channel standard
/// errors (a positive combination of correlated estimates), so the noise is an upper bound and the
/// corrected error a lower estimate; both are reported so that a reader sees how much of a measured error
/// is the reference's.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ReferenceNoise {
    /// Root mean square of the reference's luminance standard error over the compared pixels.
    pub rms: f64,
    /// `rms` over the reference's mean luminance.
    pub relative_rms: Option<f64>,
    /// √(max(0, RMSE² − rms²)) of luminance: the error against the noiseless truth.
    pub corrected_rmse: f64,
    /// `corrected_rmse` over the reference's mean luminance.
    pub corrected_relative_rmse: Option<f64>,
}

/// The reference noise in `errors` (luminance) from the reference's standard-error image `stderr`
/// (`radiosity reference --stderr`), over the pixels `mask` does not ignore.
pub fn reference_noise(
    errors: &ImageErrors,
    stderr: &Image,
    mask: Option<&[bool]>,
) -> Result<ReferenceNoise> {
    ensure!(
        stderr.width == errors.width && stderr.height == errors.height,
        "the standard-error image is {}×{} but the images are {}×{}",
        stderr.width,
        stderr.height,
        errors.width,
        errors.height
    );
    ensure_mask_len(mask, stderr)?;
    let mut sum_sq = 0.0;
    for (i, s) in stderr.pixels.iter().enumerate() {
        if mask.is_some_and(|m| m[i]) {
            continue;
        }
        let (x, y) = (i % stderr.width, i / stderr.width);
        ensure!(
            s.is_finite(),
            "standard error at pixel ({x}, {y}) is not finite: {s:?}"
        );
        let sigma = Rgb::new(s.r.abs(), s.g.abs(), s.b.abs()).luminance();
        sum_sq += sigma * sigma;
    }
    let l = &errors.luminance;
    let rms = (sum_sq / errors.compared as f64).sqrt();
    let corrected_rmse = (l.rmse * l.rmse - rms * rms).max(0.0).sqrt();
    let relative = |v: f64| (l.reference_mean != 0.0).then(|| v / l.reference_mean.abs());
    Ok(ReferenceNoise {
        rms,
        relative_rms: relative(rms),
        corrected_rmse,
        corrected_relative_rmse: relative(corrected_rmse),
    })
}

/// Per-pixel luminance error |L(a) − L(b)|, or |L(a) − L(b)| / L(b) when `relative`; `None` where the mask
/// ignores the pixel or where a relative error is undefined (black reference).
pub fn luminance_error_map(
    a: &Image,
    b: &Image,
    mask: Option<&[bool]>,
    relative: bool,
) -> Result<Vec<Option<f64>>> {
    ensure_same_size(a, b)?;
    ensure_mask_len(mask, a)?;
    Ok(a.pixels
        .iter()
        .zip(&b.pixels)
        .enumerate()
        .map(|(i, (&pa, &pb))| {
            if mask.is_some_and(|m| m[i]) {
                return None;
            }
            let (la, lb) = (pa.luminance(), pb.luminance());
            let e = (la - lb).abs();
            let e = if relative {
                (lb != 0.0).then(|| e / lb.abs())?
            } else {
                e
            };
            e.is_finite().then_some(e)
        })
        .collect())
}

fn channels(c: Rgb) -> [f64; 4] {
    [c.r, c.g, c.b, c.luminance()]
}

#[derive(Clone, Copy, Default)]
struct Accumulator {
    sum_sq: f64,
    sum_abs: f64,
    sum_ref: f64,
    max: f64,
    max_at: [usize; 2],
}

impl Accumulator {
    fn add(&mut self, a: f64, b: f64, at: [usize; 2]) {
        let e = (a - b).abs();
        self.sum_sq += e * e;
        self.sum_abs += e;
        self.sum_ref += b;
        if e > self.max {
            self.max = e;
            self.max_at = at;
        }
    }

    fn finish(self, n: usize) -> ChannelErrors {
        let n = n as f64;
        let rmse = (self.sum_sq / n).sqrt();
        let reference_mean = self.sum_ref / n;
        ChannelErrors {
            rmse,
            relative_rmse: (reference_mean != 0.0).then(|| rmse / reference_mean.abs()),
            mae: self.sum_abs / n,
            max: self.max,
            max_at: self.max_at,
            reference_mean,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp(w: usize, h: usize) -> Image {
        let mut img = Image::new(w, h);
        for y in 0..h {
            for x in 0..w {
                let v = (x + w * y) as f64 / 64.0;
                img.set(x, y, Rgb::new(v, 0.5 * v, 0.25));
            }
        }
        img
    }

    #[test]
    fn relative_error_is_undefined_on_black_reference() {
        let mut b = Image::new(2, 1);
        b.set(1, 0, Rgb::splat(2.0));
        let a = Image {
            width: 2,
            height: 1,
            pixels: vec![Rgb::splat(1.0); 2],
        };
        let map = luminance_error_map(&a, &b, None, true).unwrap();
        assert_eq!(map[0], None);
        assert!((map[1].unwrap() - 0.5).abs() < 1e-12);
        let abs = luminance_error_map(&a, &b, Some(&[false, true]), false).unwrap();
        assert!((abs[0].unwrap() - 1.0).abs() < 1e-12);
        assert_eq!(abs[1], None);
    }

    #[test]
    fn max_location_is_reported() {
        let b = ramp(4, 3);
        let mut a = b.clone();
        a.set(2, 1, b.get(2, 1) + Rgb::new(0.0, 0.5, 0.0));
        let e = compare(&a, &b, None).unwrap();
        assert_eq!(e.g.max_at, [2, 1]);
        assert_eq!(e.g.max, 0.5);
        assert_eq!(e.r.max, 0.0);
    }

    #[test]
    fn non_finite_pixels_are_reported() {
        let b = ramp(2, 2);
        let mut a = b.clone();
        a.set(1, 1, Rgb::new(f64::NAN, 0.0, 0.0));
        let err = compare(&a, &b, None).unwrap_err().to_string();
        assert!(err.contains("(1, 1)"), "{err}");
        // Masked non-finite pixels are not looked at.
        let mut mask = vec![false; 4];
        mask[3] = true;
        assert!(compare(&a, &b, Some(&mask)).is_ok());
    }

    #[test]
    fn reference_noise_is_removed_in_quadrature() {
        // Truth t = 1 everywhere; the approximation is off by 0.3, the reference by ±0.4 (its noise, with
        // standard error 0.4): the measured RMSE is 0.5 and the corrected one the true 0.3.
        let (w, h) = (4, 2);
        let truth = Image {
            width: w,
            height: h,
            pixels: vec![Rgb::splat(1.0); w * h],
        };
        let mut a = truth.clone();
        let mut b = truth.clone();
        for (i, (pa, pb)) in a.pixels.iter_mut().zip(&mut b.pixels).enumerate() {
            *pa = Rgb::splat(1.3);
            *pb = Rgb::splat(if i % 2 == 0 { 1.4 } else { 0.6 });
        }
        // The approximation sits 0.3 above t; b is t ± 0.4, so (a − b)² averages 0.1² and 0.7² → 0.25.
        let stderr = Image {
            width: w,
            height: h,
            pixels: vec![Rgb::splat(0.4); w * h],
        };
        let e = compare(&a, &b, None).unwrap();
        assert!((e.luminance.rmse - 0.5).abs() < 1e-12);
        let n = reference_noise(&e, &stderr, None).unwrap();
        assert!((n.rms - 0.4).abs() < 1e-12);
        assert!((n.corrected_rmse - 0.3).abs() < 1e-12);
        assert!(n.corrected_relative_rmse.is_some());
        let wrong = Image::new(2, 2);
        assert!(reference_noise(&e, &wrong, None).is_err());
    }
}
