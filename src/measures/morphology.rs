//! Binary-image morphology of Sillion & Drettakis §2.4: *Erosion* and *Expansion* with the 4-neighbour
//! structuring element, and the openings built from them. Two users share it: the feature masks of the
//! feature-based error metric ([`crate::measures::fbem`], §2.2–2.4) and the blocker sizes (BSIZE) of
//! multi-resolution visibility ([`crate::visibility::multires`], §3.3), which counts the erosions that
//! make a cluster's projection vanish.
//!
//! `n` successive 4-neighbour steps reach exactly the pixels within L¹ (city-block) distance `n`, so every
//! operator here reads one L¹ distance transform ([`distance_to`], two raster passes) instead of iterating:
//! the cost does not grow with `n`.

use anyhow::{Context, Result};
use std::path::Path;

/// A binary image, row-major, row 0 at the top; `true` marks a feature (or, for ignore masks, an
/// ignored pixel).
#[derive(Clone, PartialEq, Eq)]
pub struct Mask {
    pub width: usize,
    pub height: usize,
    pub bits: Vec<bool>,
}

impl Mask {
    pub fn new(width: usize, height: usize) -> Self {
        Mask {
            width,
            height,
            bits: vec![false; width * height],
        }
    }

    /// The mask whose pixel (x, y) is `f(x, y)`.
    pub fn from_fn(width: usize, height: usize, f: impl Fn(usize, usize) -> bool) -> Self {
        let bits = (0..width * height)
            .map(|i| f(i % width, i / width))
            .collect();
        Mask {
            width,
            height,
            bits,
        }
    }

    pub fn get(&self, x: usize, y: usize) -> bool {
        self.bits[y * self.width + x]
    }

    /// Number of pixels set.
    pub fn count(&self) -> usize {
        self.bits.iter().filter(|&&b| b).count()
    }

    /// Reads a PNG mask: a pixel is set when any of its channels is nonzero (alpha ignored).
    pub fn read_png(path: &Path) -> Result<Mask> {
        let img = image::open(path)
            .with_context(|| format!("reading mask {}", path.display()))?
            .to_rgb8();
        let (width, height) = (img.width() as usize, img.height() as usize);
        let bits = img.pixels().map(|p| p.0.iter().any(|&c| c != 0)).collect();
        Ok(Mask {
            width,
            height,
            bits,
        })
    }

    /// Writes the mask as a PNG: set pixels white, others black, pixels in `ignored` mid-grey.
    pub fn write_png(&self, path: &Path, ignored: Option<&[bool]>) -> Result<()> {
        let mut img = image::GrayImage::new(self.width as u32, self.height as u32);
        for (i, p) in img.pixels_mut().enumerate() {
            p.0[0] = if ignored.is_some_and(|m| m[i]) {
                128
            } else if self.bits[i] {
                255
            } else {
                0
            };
        }
        crate::output::save_png(path, &img)
    }
}

/// A picture of the mask ('#' set, '.' clear) for small masks, a summary for large ones: test failures
/// stay readable.
impl std::fmt::Debug for Mask {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "Mask {}×{}, {} set",
            self.width,
            self.height,
            self.count()
        )?;
        if self.width <= 80 && self.height <= 80 {
            for row in self.bits.chunks(self.width.max(1)) {
                let line: String = row.iter().map(|&b| if b { '#' } else { '.' }).collect();
                writeln!(f, "{line}")?;
            }
        }
        Ok(())
    }
}

/// For every pixel, the L¹ distance to the nearest pixel of the image whose bit equals `target` (0 on
/// such pixels), `u32::MAX` when there is none. Pixels outside the image are never targets. Exact for the
/// city-block metric with the classic two-pass (forward, backward) sweep.
pub fn distance_to(mask: &Mask, target: bool) -> Vec<u32> {
    let (w, h) = (mask.width, mask.height);
    let mut d: Vec<u32> = mask
        .bits
        .iter()
        .map(|&b| if b == target { 0 } else { u32::MAX })
        .collect();
    let step = |from: u32| from.saturating_add(1);
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            if x > 0 {
                d[i] = d[i].min(step(d[i - 1]));
            }
            if y > 0 {
                d[i] = d[i].min(step(d[i - w]));
            }
        }
    }
    for y in (0..h).rev() {
        for x in (0..w).rev() {
            let i = y * w + x;
            if x + 1 < w {
                d[i] = d[i].min(step(d[i + 1]));
            }
            if y + 1 < h {
                d[i] = d[i].min(step(d[i + w]));
            }
        }
    }
    d
}

/// `n` Erosions (§2.4): a set pixel stays set only if its four neighbours are set, `n` times over, which
/// keeps the pixels whose whole L¹ ball of radius n (a diamond) lies in the mask. The paper's definition
/// uses 4-connectivity (§2.4, footnote 2), which we follow exactly. Pixels outside the image count as set,
/// so that the border does not shrink features it cuts.
pub fn erode(mask: &Mask, n: usize) -> Mask {
    let clear = distance_to(mask, false);
    Mask {
        width: mask.width,
        height: mask.height,
        bits: clear.iter().map(|&d| d as usize > n).collect(),
    }
}

/// `n` Expansions (dilations, §2.4): adds every pixel within L¹ distance n of the mask.
pub fn expand(mask: &Mask, n: usize) -> Mask {
    let set = distance_to(mask, true);
    Mask {
        width: mask.width,
        height: mask.height,
        bits: set.iter().map(|&d| (d as usize) <= n).collect(),
    }
}

/// `n` erosions then `n` expansions (§2.4, Figure 3): removes features of diameter ≤ 2n and keeps larger
/// ones (slightly rounding their shape).
pub fn open(mask: &Mask, n: usize) -> Mask {
    expand(&erode(mask, n), n)
}

/// The number of Erosions after which nothing of the mask is left (§3.3: "Erosions are computed until all
/// objects have disappeared"), 0 for an empty mask; `None` when the mask fills the image, which erosion
/// (the border counting as set) never empties. A region of diameter 2n vanishes after n (§2.4).
pub fn erosions_to_vanish(mask: &Mask) -> Option<usize> {
    let clear = distance_to(mask, false);
    let deepest = clear.iter().copied().max().unwrap_or(0);
    (deepest != u32::MAX).then_some(deepest as usize)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The definitions of §2.4, one step at a time: the ground truth of the distance-transform operators.
    fn erode_once(m: &Mask) -> Mask {
        let (w, h) = (m.width, m.height);
        Mask::from_fn(w, h, |x, y| {
            m.get(x, y)
                && (x == 0 || m.get(x - 1, y))
                && (x + 1 == w || m.get(x + 1, y))
                && (y == 0 || m.get(x, y - 1))
                && (y + 1 == h || m.get(x, y + 1))
        })
    }

    fn expand_once(m: &Mask) -> Mask {
        let (w, h) = (m.width, m.height);
        Mask::from_fn(w, h, |x, y| {
            m.get(x, y)
                || (x > 0 && m.get(x - 1, y))
                || (x + 1 < w && m.get(x + 1, y))
                || (y > 0 && m.get(x, y - 1))
                || (y + 1 < h && m.get(x, y + 1))
        })
    }

    #[test]
    fn distance_transform_operators_match_repeated_steps() {
        // Pseudo-random masks of several densities, borders included.
        for (seed, density) in [(1u64, 3u64), (2, 5), (3, 8), (4, 9)] {
            // A hash of the pixel index: deterministic, irregular.
            let mask = Mask::from_fn(23, 17, |x, y| {
                let i = (y * 23 + x) as u64 ^ (seed << 32);
                let hash = i.wrapping_mul(0x9E37_79B9_7F4A_7C15).rotate_left(29);
                hash.wrapping_mul(0xBF58_476D_1CE4_E5B9) >> 60 < density * 16 / 10
            });
            let (mut eroded, mut expanded) = (mask.clone(), mask.clone());
            for n in 0..12 {
                assert_eq!(erode(&mask, n), eroded, "erode {n}, seed {seed}");
                assert_eq!(expand(&mask, n), expanded, "expand {n}, seed {seed}");
                eroded = erode_once(&eroded);
                expanded = expand_once(&expanded);
            }
            let steps = (0..64).find(|&n| erode(&mask, n).count() == 0);
            assert_eq!(erosions_to_vanish(&mask), steps, "seed {seed}");
        }
        assert_eq!(erosions_to_vanish(&Mask::new(4, 4)), Some(0));
        assert_eq!(erosions_to_vanish(&Mask::from_fn(4, 4, |_, _| true)), None);
    }

    /// Disc of diameter d (pixels whose centres lie within d/2 of the centre `c`, c on a pixel corner for
    /// even d and on a pixel centre for odd d), inside a margin.
    fn disc(d: usize) -> Mask {
        let size = d + 20;
        let c = 10.0 + d as f64 / 2.0;
        let r = d as f64 / 2.0;
        Mask::from_fn(size, size, |x, y| {
            let (dx, dy) = (x as f64 + 0.5 - c, y as f64 + 0.5 - c);
            dx * dx + dy * dy <= r * r
        })
    }

    #[test]
    fn disc_survives_opening_exactly_when_n_below_half_diameter() {
        for d in [2usize, 3, 5, 6, 9, 12, 15, 20] {
            let m = disc(d);
            assert!(m.count() > 0);
            for n in 0..=d {
                let opened = open(&m, n);
                if 2 * n < d {
                    assert!(opened.count() > 0, "d={d} n={n} vanished");
                    // Opening only removes pixels.
                    assert!(opened.bits.iter().zip(&m.bits).all(|(&o, &b)| !o || b));
                } else {
                    assert_eq!(opened.count(), 0, "d={d} n={n} survived");
                }
            }
        }
    }

    #[test]
    fn erosion_and_expansion_of_rectangles() {
        let (w, h) = (40, 30);
        let (x0, y0, rw, rh) = (10usize, 8usize, 13usize, 9usize);
        let inside = |x: usize, y: usize| (x0..x0 + rw).contains(&x) && (y0..y0 + rh).contains(&y);
        let rect = Mask::from_fn(w, h, inside);
        for n in 0..6 {
            let e = erode(&rect, n);
            let expected = Mask::from_fn(w, h, |x, y| {
                (x0 + n..x0 + rw.saturating_sub(n)).contains(&x)
                    && (y0 + n..y0 + rh.saturating_sub(n)).contains(&y)
            });
            assert_eq!(e, expected, "erosion by {n}");
            assert_eq!(
                e.count(),
                rw.saturating_sub(2 * n) * rh.saturating_sub(2 * n)
            );
            // Expansion adds every pixel within L1 distance n of the rectangle.
            let x_gap = |x: usize| (x0.saturating_sub(x)).max(x.saturating_sub(x0 + rw - 1));
            let y_gap = |y: usize| (y0.saturating_sub(y)).max(y.saturating_sub(y0 + rh - 1));
            let grown = expand(&rect, n);
            assert_eq!(
                grown,
                Mask::from_fn(w, h, |x, y| x_gap(x) + y_gap(y) <= n),
                "expansion by {n}"
            );
            assert_eq!(
                grown.count(),
                rw * rh + 2 * n * (rw + rh) + 2 * n * n.saturating_sub(1)
            );
        }
        // Opening keeps the rectangle, corners cut by the diamond, while its smaller side exceeds 2n.
        let n = 4;
        let opened = open(&rect, n);
        assert!(opened.bits.iter().zip(&rect.bits).all(|(&o, &r)| !o || r));
        let (ew, eh) = (rw - 2 * n, rh - 2 * n);
        assert_eq!(
            opened.count(),
            ew * eh + 2 * n * (ew + eh) + 2 * n * (n - 1)
        );
        assert_eq!(rect.count() - opened.count(), 4 * n * (n + 1) / 2);
        assert_eq!(open(&rect, 5).count(), 0);
    }

    #[test]
    fn border_does_not_erode_features_it_cuts() {
        let m = Mask::from_fn(10, 10, |x, _| x < 4);
        assert_eq!(erode(&m, 1), Mask::from_fn(10, 10, |x, _| x < 3));
        assert_eq!(open(&m, 1), m);
    }
}
