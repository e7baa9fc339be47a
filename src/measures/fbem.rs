//! Feature-based error metric (FBEM) of Sillion & Drettakis 1995, §2.2–2.4.
//!
//! Features are connected regions of varying illumination, i.e. shadows (umbra or penumbra) of a source
//! (§2). A binary *feature mask* 𝓕 is computed from the reference (§2.4), then opened (n erosions followed
//! by n expansions) so that only features of diameter > 2n survive: 𝓕^s with n = ⌊s/2⌋ for feature size s.
//! The FBEM of §2.2 compares approximation f̂ and reference f exactly inside 𝓕^s and only through their
//! box-filtered averages (box of size s) outside it:
//!
//! ‖f̂ − f‖ₚˢ = ( ∫ |f̂ − f|ᵖ 𝓕^s dx + ∫ |f̂ˢ − fˢ|ᵖ (1 − 𝓕^s) dx )^(1/p)
//!
//! All quantities are per-pixel luminance. The image is taken as a domain of unit area (dx = 1 / number of
//! compared pixels), so the FBEM does not grow with resolution and equals the RMSE for s ≤ 1 (p = 2): the
//! "L² metric in the limit s = 0" of §2.3.

use super::morphology::open;
use crate::output::image::Image;
use anyhow::{ensure, Result};
use serde::Serialize;
use std::collections::VecDeque;

/// Feature masks are binary images of [`super::morphology`].
pub use super::morphology::Mask;

/// Number of erosions (and expansions) that remove the features smaller than `size` pixels: "applying
/// p/2 successive erosions, followed by p/2 successive expansions" (§2.4), rounded down.
pub fn openings_for_size(size: usize) -> usize {
    size / 2
}

/// The feature mask 𝓕^s of §2.2 for feature size `size` (pixels) from the unfiltered feature mask.
pub fn feature_mask(features: &Mask, size: usize) -> Mask {
    open(features, openings_for_size(size))
}

/// The paper's feature mask (§2.4: "all areas of the receiver that have a partial or occluded view of the
/// light source"), computed from two renderings of the same view: `lit` with shadows and `unoccluded` with
/// the occluders removed (or visibility ignored). A pixel is in shadow when its luminance is below
/// (1 − threshold) times the unoccluded luminance; the relative threshold makes the mask independent of
/// exposure and of the falloff of direct light.
pub fn shadow_mask(lit: &Image, unoccluded: &Image, threshold: f64) -> Result<Mask> {
    crate::measures::image_metrics::ensure_same_size(lit, unoccluded)?;
    ensure!(
        (0.0..1.0).contains(&threshold),
        "the shadow threshold must be in [0, 1), not {threshold}"
    );
    let bits = lit
        .pixels
        .iter()
        .zip(&unoccluded.pixels)
        .map(|(l, u)| {
            let u = u.luminance();
            u > 0.0 && l.luminance() < (1.0 - threshold) * u
        })
        .collect();
    Ok(Mask {
        width: lit.width,
        height: lit.height,
        bits,
    })
}

/// A feature mask when only the reference exists. The unoccluded illumination is estimated by a
/// greyscale morphological *closing* of the reference luminance (a max filter then a min filter over a
/// square window of side ≥ `window` + 1): closing fills every dark region narrower than `window` pixels
/// with the surrounding light level while leaving smooth (e.g. linear) illumination gradients unchanged,
/// the same size-selective morphology the paper uses for masks (§2.4). A pixel is a feature when it is
/// darker than (1 − threshold) times that estimate — the black top-hat transform, thresholded relatively.
///
/// Shadows wider than `window` are missed; dark regions that are not shadows (darker materials, corners
/// receiving less light) of width ≤ `window` are marked. Prefer [`shadow_mask`] when an unoccluded
/// rendering is available. Ignored pixels take no part in the filters and are never features.
pub fn feature_mask_from_reference(
    reference: &Image,
    window: usize,
    threshold: f64,
    ignore: Option<&[bool]>,
) -> Result<Mask> {
    crate::measures::image_metrics::ensure_mask_len(ignore, reference)?;
    ensure!(
        (0.0..1.0).contains(&threshold),
        "the feature threshold must be in [0, 1), not {threshold}"
    );
    let (w, h) = (reference.width, reference.height);
    let ignored = |i: usize| ignore.is_some_and(|m| m[i]);
    let lum: Vec<f64> = reference.pixels.iter().map(|c| c.luminance()).collect();
    let radius = window.div_ceil(2).max(1);
    // Ignored pixels are neutral: -∞ for the max filter, +∞ for the min filter.
    let mut v: Vec<f64> = (0..w * h)
        .map(|i| {
            if ignored(i) {
                f64::NEG_INFINITY
            } else {
                lum[i]
            }
        })
        .collect();
    v = filter_2d(&v, w, h, radius, true);
    for (i, x) in v.iter_mut().enumerate() {
        if ignored(i) {
            *x = f64::INFINITY;
        }
    }
    let closed = filter_2d(&v, w, h, radius, false);
    let bits = (0..w * h)
        .map(|i| !ignored(i) && closed[i] > 0.0 && lum[i] < (1.0 - threshold) * closed[i])
        .collect();
    Ok(Mask {
        width: w,
        height: h,
        bits,
    })
}

/// Separable square max (or min) filter of radius `r`.
fn filter_2d(v: &[f64], w: usize, h: usize, r: usize, max: bool) -> Vec<f64> {
    let mut out = vec![0.0; w * h];
    for y in 0..h {
        let row = sliding_extreme(&v[y * w..(y + 1) * w], r, max);
        out[y * w..(y + 1) * w].copy_from_slice(&row);
    }
    let mut col = vec![0.0; h];
    for x in 0..w {
        for y in 0..h {
            col[y] = out[y * w + x];
        }
        for (y, e) in sliding_extreme(&col, r, max).into_iter().enumerate() {
            out[y * w + x] = e;
        }
    }
    out
}

/// Max (or min) of `v` over the window [i − r, i + r] clipped to the slice, for every i, in linear time
/// with a monotone deque.
fn sliding_extreme(v: &[f64], r: usize, max: bool) -> Vec<f64> {
    let better = |a: f64, b: f64| if max { a >= b } else { a <= b };
    let mut deque: VecDeque<usize> = VecDeque::new();
    let mut out = Vec::with_capacity(v.len());
    let mut next = 0;
    for i in 0..v.len() {
        while next < v.len() && next <= i + r {
            while deque.back().is_some_and(|&j| better(v[next], v[j])) {
                deque.pop_back();
            }
            deque.push_back(next);
            next += 1;
        }
        while deque.front().is_some_and(|&j| j + r < i) {
            deque.pop_front();
        }
        out.push(deque.front().map_or(v[i], |&j| v[j]));
    }
    out
}

/// The box filter "of size s around the point of interest" (§2.2): the average over a square of side s
/// centred on the pixel centre, each pixel weighted by its overlap with the square (so even sizes give the
/// two end pixels of each row of the window half weight). Pixels outside the image or `valid == false`
/// take no part: the average is over the part of the window that holds data.
fn box_filter(values: &[f64], valid: &[bool], w: usize, h: usize, size: usize) -> Vec<f64> {
    let num: Vec<f64> = values
        .iter()
        .zip(valid)
        .map(|(&v, &ok)| if ok { v } else { 0.0 })
        .collect();
    let den: Vec<f64> = valid.iter().map(|&ok| f64::from(u8::from(ok))).collect();
    let num = box_2d(&num, w, h, size);
    let den = box_2d(&den, w, h, size);
    num.iter()
        .zip(&den)
        .zip(values)
        .map(|((&n, &d), &v)| if d > 0.0 { n / d } else { v })
        .collect()
}

/// Unnormalised separable box sum of side `size` (see [`box_filter`]).
fn box_2d(v: &[f64], w: usize, h: usize, size: usize) -> Vec<f64> {
    let mut out = vec![0.0; w * h];
    for y in 0..h {
        let row = box_1d(&v[y * w..(y + 1) * w], size);
        out[y * w..(y + 1) * w].copy_from_slice(&row);
    }
    let mut col = vec![0.0; h];
    for x in 0..w {
        for y in 0..h {
            col[y] = out[y * w + x];
        }
        for (y, s) in box_1d(&col, size).into_iter().enumerate() {
            out[y * w + x] = s;
        }
    }
    out
}

/// Sum over offsets |k| ≤ (size − 1)/2 with weight 1 plus, for even sizes, offsets ±size/2 with weight ½.
fn box_1d(v: &[f64], size: usize) -> Vec<f64> {
    let size = size.max(1);
    let n = v.len();
    let mut prefix = vec![0.0; n + 1];
    for i in 0..n {
        prefix[i + 1] = prefix[i] + v[i];
    }
    let full = (size - 1) / 2;
    let half = size.is_multiple_of(2);
    (0..n)
        .map(|i| {
            let lo = i.saturating_sub(full);
            let hi = (i + full + 1).min(n);
            let mut s = prefix[hi] - prefix[lo];
            if half {
                let k = size / 2;
                if i >= k {
                    s += 0.5 * v[i - k];
                }
                if i + k < n {
                    s += 0.5 * v[i + k];
                }
            }
            s
        })
        .collect()
}

/// The FBEM of one feature size, with its two terms.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Fbem {
    /// Feature size s in pixels.
    pub size: usize,
    /// Exponent p of the norm.
    pub p: f64,
    /// ‖f̂ − f‖ₚˢ of §2.2.
    pub value: f64,
    /// Erosions and expansions applied to the feature mask (⌊s/2⌋).
    pub openings: usize,
    /// Fraction of the compared pixels inside 𝓕^s.
    pub feature_fraction: f64,
    /// ∫ |f̂ − f|ᵖ 𝓕^s dx: the exact comparison inside the features.
    pub feature_term: f64,
    /// ∫ |f̂ˢ − fˢ|ᵖ (1 − 𝓕^s) dx: the comparison of averages elsewhere.
    pub filtered_term: f64,
}

/// The feature-based error metric of §2.2 between `approx` (f̂) and `reference` (f), on luminance.
///
/// `features` is the unfiltered feature mask of the reference (from [`shadow_mask`] or
/// [`feature_mask_from_reference`]); it is opened here by ⌊size/2⌋ to give 𝓕^s. Pixels where `ignore` is
/// true are left out of the integrals and of the box filter.
pub fn fbem(
    approx: &Image,
    reference: &Image,
    features: &Mask,
    size: usize,
    p: f64,
    ignore: Option<&[bool]>,
) -> Result<Fbem> {
    crate::measures::image_metrics::ensure_same_size(approx, reference)?;
    crate::measures::image_metrics::ensure_mask_len(ignore, reference)?;
    let (w, h) = (reference.width, reference.height);
    ensure!(
        features.width == w && features.height == h,
        "the feature mask is {}×{} but the images are {w}×{h}",
        features.width,
        features.height
    );
    ensure!(
        p.is_finite() && p >= 1.0,
        "the FBEM exponent p must be finite and at least 1, not {p}"
    );
    let valid: Vec<bool> = (0..w * h).map(|i| !ignore.is_some_and(|m| m[i])).collect();
    let compared = valid.iter().filter(|&&v| v).count();
    ensure!(compared > 0, "every pixel is masked: nothing to compare");
    let fa: Vec<f64> = approx.pixels.iter().map(|c| c.luminance()).collect();
    let fr: Vec<f64> = reference.pixels.iter().map(|c| c.luminance()).collect();
    let openings = openings_for_size(size);
    let mask = open(features, openings);
    let fa_s = box_filter(&fa, &valid, w, h, size);
    let fr_s = box_filter(&fr, &valid, w, h, size);
    let dx = 1.0 / compared as f64;
    let (mut feature_term, mut filtered_term, mut in_mask) = (0.0, 0.0, 0usize);
    for i in (0..w * h).filter(|&i| valid[i]) {
        if mask.bits[i] {
            feature_term += (fa[i] - fr[i]).abs().powf(p) * dx;
            in_mask += 1;
        } else {
            filtered_term += (fa_s[i] - fr_s[i]).abs().powf(p) * dx;
        }
    }
    Ok(Fbem {
        size,
        p,
        value: (feature_term + filtered_term).powf(1.0 / p),
        openings,
        feature_fraction: in_mask as f64 * dx,
        feature_term,
        filtered_term,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::color::Rgb;

    #[test]
    fn box_filter_weights() {
        let v = [0.0, 0.0, 4.0, 0.0, 0.0];
        assert_eq!(box_1d(&v, 1), v.to_vec());
        assert_eq!(box_1d(&v, 3), vec![0.0, 4.0, 4.0, 4.0, 0.0]);
        assert_eq!(box_1d(&v, 4), vec![2.0, 4.0, 4.0, 4.0, 2.0]);
        // Normalised filtering preserves a linear ramp away from the borders, for odd and even sizes.
        let (w, h) = (20, 3);
        let ramp: Vec<f64> = (0..w * h).map(|i| (i % w) as f64).collect();
        for size in [3, 4, 7, 8] {
            let f = box_filter(&ramp, &vec![true; w * h], w, h, size);
            for x in size..w - size {
                assert!((f[w + x] - x as f64).abs() < 1e-12, "size {size} x {x}");
            }
        }
        // Invalid pixels are left out of the average.
        let valid = [true, false, true];
        let f = box_filter(&[1.0, 100.0, 3.0], &valid, 3, 1, 3);
        assert_eq!(f, vec![1.0, 2.0, 3.0]);
    }

    #[test]
    fn sliding_extremes_match_brute_force() {
        let v: Vec<f64> = (0..37).map(|i| ((i * 7919) % 23) as f64).collect();
        for r in 0..6 {
            for max in [true, false] {
                let fast = sliding_extreme(&v, r, max);
                for (i, &e) in fast.iter().enumerate() {
                    let window = &v[i.saturating_sub(r)..(i + r + 1).min(v.len())];
                    let slow = window.iter().copied().fold(
                        if max { f64::MIN } else { f64::MAX },
                        |a, b| if max { a.max(b) } else { a.min(b) },
                    );
                    assert_eq!(e, slow);
                }
            }
        }
    }

    #[test]
    fn reference_mask_finds_dark_squares_on_a_gradient() {
        let (w, h) = (60, 40);
        let shadow = |x: usize, y: usize| (10..16).contains(&x) && (12..20).contains(&y);
        let mut img = Image::new(w, h);
        for y in 0..h {
            for x in 0..w {
                let lit = 0.5 + 0.01 * x as f64 + 0.005 * y as f64;
                img.set(x, y, Rgb::splat(if shadow(x, y) { 0.3 * lit } else { lit }));
            }
        }
        let m = feature_mask_from_reference(&img, 10, 0.2, None).unwrap();
        assert_eq!(m, Mask::from_fn(w, h, shadow));
        // A window narrower than the shadow misses its inside.
        let narrow = feature_mask_from_reference(&img, 3, 0.2, None).unwrap();
        assert!(!narrow.get(13, 16));
        // Ignored pixels (here a black band of background) are neither features nor light sources for
        // the closing: the shadow beside them is still found, the band is not marked.
        for y in 0..h {
            for x in 0..4 {
                img.set(x, y, Rgb::BLACK);
            }
        }
        let ignore: Vec<bool> = (0..w * h).map(|i| i % w < 4).collect();
        let with_bg = feature_mask_from_reference(&img, 10, 0.2, Some(&ignore)).unwrap();
        assert_eq!(with_bg, Mask::from_fn(w, h, shadow));
        let unmasked = feature_mask_from_reference(&img, 10, 0.2, None).unwrap();
        assert!(
            unmasked.get(0, 0),
            "the black band is a dark feature when not ignored"
        );
    }

    #[test]
    fn fbem_rejects_bad_input() {
        let a = Image::new(4, 4);
        let m = Mask::new(4, 4);
        assert!(fbem(&a, &a, &m, 2, 0.5, None).is_err());
        assert!(fbem(&a, &Image::new(4, 5), &m, 2, 2.0, None).is_err());
        assert!(fbem(&a, &a, &Mask::new(3, 4), 2, 2.0, None).is_err());
        assert!(fbem(&a, &a, &m, 2, 2.0, Some(&[true; 16])).is_err());
        assert_eq!(fbem(&a, &a, &m, 2, 2.0, None).unwrap().value, 0.0);
    }
}
