//! Intra-cluster visibility by item buffer (Sillion–Drettakis §6.1): the contents of a cluster drawn
//! into a small orthographic z-buffer seen from the direction of the other end of a link, each pixel
//! holding the item (patch) nearest to that direction. Counting an item's pixels estimates the part of
//! its projected area that the cluster's other contents leave visible, which clustering uses both where
//! a cluster receives (irradiance is shared among the visible patches only) and where it emits (only
//! visible patches send light out of the cluster).
//!
//! It lives with visibility because it is one: a rasterised answer to "what does a direction see", over
//! a set of polygons. The clustering solver ([`crate::solvers::clustering`]) decides where it is asked.
//!
//! Resolution follows the paper: fitted to the smallest object, [`PIXELS_ACROSS_SMALLEST`] pixels across
//! it (`√area` as its size), and bounded to [`MAX_SIDE`]² pixels; objects that then cover no pixel
//! centre are judged at their centroid. The answer per item is a *visible fraction* (pixels where it won
//! the depth test over pixels it covers), so an unoccluded item gets exactly 1 whatever the aliasing, and
//! the caller multiplies it by the item's exact projected area.
//!
//! Buffers are cached per (cluster, direction bucket): directions are quantised on a cube map of
//! `6 ×` [`BUCKETS_PER_FACE`]² cells and each buffer is drawn along its cell's centre direction, so the
//! answer is a pure function of the cluster and the bucket and does not depend on which thread (or in
//! which order) first asked for it.

use crate::geometry::{DVec2, DVec3, Shape};
use std::collections::HashMap;
use std::ops::Range;
use std::sync::{Arc, RwLock};

/// Pixels across the smallest object of a buffer.
pub const PIXELS_ACROSS_SMALLEST: f64 = 4.0;
/// Most pixels along a side of one buffer (the bound on its work and memory: 256² pixels).
pub const MAX_SIDE: usize = 256;
/// Direction cells per cube-map face side: 6 × 8² = 384 buckets, each under 13° across.
pub const BUCKETS_PER_FACE: usize = 8;

/// Whether a cluster's contents shadow each other (`--intra-cluster`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum IntraClusterKind {
    /// Contents mutually unoccluded: every patch facing the other end receives and emits.
    None,
    /// Item buffer per (cluster, direction): hidden patches neither receive nor emit (§6.1).
    #[default]
    ItemBuffer,
}

/// The cube-map cell of direction `d` (not necessarily unit) and that cell's centre direction (unit).
pub fn direction_bucket(d: DVec3) -> (u16, DVec3) {
    let a = d.abs();
    let axis = if a.x >= a.y && a.x >= a.z {
        0
    } else if a.y >= a.z {
        1
    } else {
        2
    };
    let major = d[axis];
    let face = 2 * axis + usize::from(major < 0.0);
    let (s, t) = ((axis + 1) % 3, (axis + 2) % 3);
    let n = BUCKETS_PER_FACE;
    let cell = |c: f64| (((c / major.abs() + 1.0) * 0.5 * n as f64) as usize).min(n - 1);
    let (i, j) = (cell(d[s]), cell(d[t]));
    let bucket = ((face * n + i) * n + j) as u16;
    (bucket, bucket_direction(bucket))
}

/// The centre direction (unit) of cube-map cell `bucket` ([`direction_bucket`]), along which its item
/// buffers are drawn.
pub fn bucket_direction(bucket: u16) -> DVec3 {
    let n = BUCKETS_PER_FACE;
    let (face, i, j) = (
        bucket as usize / (n * n),
        bucket as usize / n % n,
        bucket as usize % n,
    );
    let axis = face / 2;
    let (s, t) = ((axis + 1) % 3, (axis + 2) % 3);
    let centre = |k: usize| (k as f64 + 0.5) / n as f64 * 2.0 - 1.0;
    let mut c = DVec3::ZERO;
    c[axis] = if face % 2 == 0 { 1.0 } else { -1.0 };
    c[s] = centre(i);
    c[t] = centre(j);
    c.normalize()
}

/// The visible fraction of each shape seen from infinitely far along `toward` (unit), in [0, 1]: an
/// orthographic item buffer over all `shapes`, the nearest shape to the viewer winning each pixel.
/// Shapes facing away occlude like the others but lose exact depth ties, so that the front side of a
/// two-sided polygon is the one seen.
pub fn visible_fractions(shapes: &[Shape], toward: DVec3) -> Vec<f32> {
    if shapes.is_empty() {
        return Vec::new();
    }
    let u = toward.any_orthonormal_vector();
    let w = toward.cross(u);
    let project = |p: DVec3| DVec2::new(p.dot(u), p.dot(w));
    let (mut lo, mut hi) = (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY));
    let (mut depth_lo, mut depth_hi) = (f64::INFINITY, f64::NEG_INFINITY);
    let mut smallest = f64::INFINITY;
    for shape in shapes {
        for &v in shape.vertices() {
            let q = project(v);
            lo = lo.min(q);
            hi = hi.max(q);
            depth_lo = depth_lo.min(v.dot(toward));
            depth_hi = depth_hi.max(v.dot(toward));
        }
        let size = shape.area().sqrt();
        if size > 0.0 {
            smallest = smallest.min(size);
        }
    }
    let extent = (hi - lo).max_element();
    if extent <= 0.0 || !smallest.is_finite() {
        return vec![1.0; shapes.len()];
    }
    let pixel = (smallest / PIXELS_ACROSS_SMALLEST).max(extent / MAX_SIDE as f64);
    let nx = (((hi.x - lo.x) / pixel).ceil() as usize).clamp(1, MAX_SIDE);
    let ny = (((hi.y - lo.y) / pixel).ceil() as usize).clamp(1, MAX_SIDE);
    // Back faces are drawn this much further away, far below any real gap between surfaces.
    let bias = 1e-9 * (extent + depth_hi - depth_lo);
    let mut depth = vec![f64::NEG_INFINITY; nx * ny];
    let mut owner = vec![u32::MAX; nx * ny];
    let mut covered = vec![0u32; shapes.len()];
    for (k, shape) in shapes.iter().enumerate() {
        let n = shape.normal();
        let facing = n.dot(toward);
        if facing.abs() < 1e-12 {
            continue; // edge-on: no area in the buffer
        }
        let offset = if facing > 0.0 { 0.0 } else { -bias };
        let corners: Vec<DVec2> = shape
            .vertices()
            .iter()
            .map(|&v| (project(v) - lo) / pixel)
            .collect();
        let plane = n.dot(shape.vertices()[0]);
        let (nu, nw) = (n.dot(u) * pixel, n.dot(w) * pixel);
        let (cu, cw) = (lo.x * n.dot(u), lo.y * n.dot(w));
        // Depth toward the viewer of the plane at pixel coordinates (x, y).
        let depth_at = |x: f64, y: f64| (plane - cu - cw - x * nu - y * nw) / facing + offset;
        for (y, xs) in spans_inside(&corners, nx, ny) {
            let cy = y as f64 + 0.5;
            covered[k] += xs.len() as u32;
            for x in xs {
                let z = depth_at(x as f64 + 0.5, cy);
                let p = y * nx + x;
                if z > depth[p] {
                    depth[p] = z;
                    owner[p] = k as u32;
                }
            }
        }
    }
    let mut won = vec![0u32; shapes.len()];
    for &o in &owner {
        if o != u32::MAX {
            won[o as usize] += 1;
        }
    }
    shapes
        .iter()
        .enumerate()
        .map(|(k, shape)| {
            if covered[k] > 0 {
                return won[k] as f32 / covered[k] as f32;
            }
            // Too small for the buffer (or edge-on): judged at its centroid.
            let c = shape.centroid();
            let q = (project(c) - lo) / pixel;
            let (x, y) = (q.x as usize, q.y as usize);
            let p = y.min(ny - 1) * nx + x.min(nx - 1);
            if depth[p] <= c.dot(toward) + bias {
                1.0
            } else {
                0.0
            }
        })
        .collect()
}

/// Pixels of an `nx × ny` buffer whose centres lie in the convex polygon `corners` (pixel units), as
/// one span of columns per row.
fn spans_inside(corners: &[DVec2], nx: usize, ny: usize) -> Vec<(usize, Range<usize>)> {
    let signed_area: f64 = (0..corners.len())
        .map(|i| corners[i].perp_dot(corners[(i + 1) % corners.len()]))
        .sum();
    if signed_area == 0.0 {
        return Vec::new();
    }
    let sign = signed_area.signum();
    let (lo, hi) = corners.iter().fold(
        (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY)),
        |(lo, hi), &c| (lo.min(c), hi.max(c)),
    );
    let first = |v: f64| (v - 0.5).ceil().max(0.0) as usize;
    let last = |v: f64, n: usize| ((v - 0.5).floor().max(-1.0) + 1.0).min(n as f64) as usize;
    let inside = |x: usize, y: usize| {
        let p = DVec2::new(x as f64 + 0.5, y as f64 + 0.5);
        (0..corners.len()).all(|i| {
            let (a, b) = (corners[i], corners[(i + 1) % corners.len()]);
            sign * (b - a).perp_dot(p - a) >= 0.0
        })
    };
    let (x_lo, x_hi) = (first(lo.x), last(hi.x, nx));
    let mut out = Vec::new();
    if x_lo >= x_hi {
        return out;
    }
    for y in first(lo.y)..last(hi.y, ny) {
        // Scanline: each edge bounds the row's centres from one side; the span's ends are then
        // settled by the exact edge test, so the pixels are the ones a test of every pixel would keep.
        let cy = y as f64 + 0.5;
        let (mut left, mut right) = (lo.x, hi.x);
        for i in 0..corners.len() {
            let (a, b) = (corners[i], corners[(i + 1) % corners.len()]);
            let d = b - a;
            let slope = sign * d.y;
            if slope == 0.0 {
                continue;
            }
            let crossing = a.x + d.x * (cy - a.y) / d.y;
            if slope > 0.0 {
                right = right.min(crossing);
            } else {
                left = left.max(crossing);
            }
        }
        if left > right + 1.0 {
            continue;
        }
        let mut x0 = first(left).clamp(x_lo, x_hi);
        let mut x1 = last(right, nx).clamp(x_lo, x_hi);
        while x0 > x_lo && inside(x0 - 1, y) {
            x0 -= 1;
        }
        while x0 < x1 && !inside(x0, y) {
            x0 += 1;
        }
        while x1 < x_hi && inside(x1, y) {
            x1 += 1;
        }
        while x1 > x0 && !inside(x1 - 1, y) {
            x1 -= 1;
        }
        if x0 < x1 {
            out.push((y, x0..x1));
        }
    }
    out
}

/// Visible fractions by (cluster, direction bucket), and the bytes they hold.
#[derive(Debug, Default)]
struct Cache {
    buffers: HashMap<(u32, u16), Arc<[f32]>>,
    bytes: usize,
}

/// Item buffers of clusters, cached per (cluster, direction bucket) up to a number of bytes (a share of
/// `--max-memory`, [`crate::memory::MemoryBudget`]); past it buffers are drawn again on every request,
/// with the same answer. Shared between threads.
#[derive(Debug)]
pub struct ItemBuffers {
    cache: RwLock<Cache>,
    max_bytes: usize,
}

/// Bytes one cached entry holds besides its fractions: the `Arc`'s counts, the map's key, pointer and
/// control byte at its load factor, and the allocator's rounding.
const ENTRY_OVERHEAD: usize = 80;

impl ItemBuffers {
    /// An empty cache that holds at most `max_bytes`.
    pub fn new(max_bytes: usize) -> Self {
        ItemBuffers {
            cache: RwLock::default(),
            max_bytes,
        }
    }

    /// Visible fractions of `cluster`'s contents (drawn by `contents` when not cached) seen along the
    /// bucket of `toward`.
    pub fn fractions(
        &self,
        cluster: u32,
        toward: DVec3,
        contents: impl FnOnce() -> Vec<Shape>,
    ) -> Arc<[f32]> {
        let (bucket, direction) = direction_bucket(toward);
        let key = (cluster, bucket);
        if let Some(hit) = self
            .cache
            .read()
            .expect("item buffer cache")
            .buffers
            .get(&key)
        {
            return hit.clone();
        }
        let fractions: Arc<[f32]> = visible_fractions(&contents(), direction).into();
        let mut cache = self.cache.write().expect("item buffer cache");
        let bytes = ENTRY_OVERHEAD + 4 * fractions.len();
        if cache.bytes + bytes <= self.max_bytes && !cache.buffers.contains_key(&key) {
            cache.bytes += bytes;
            cache.buffers.insert(key, fractions.clone());
        }
        fractions
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The scanline keeps exactly the pixels whose centres pass every edge test, for random convex
    /// triangles and quads of either winding (some reaching past the buffer, some thinner than a pixel).
    #[test]
    fn scanline_keeps_the_pixels_every_edge_test_keeps() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(5);
        let (nx, ny) = (37, 23);
        for case in 0..3000 {
            let centre = DVec2::new(rng.random_range(-5.0..42.0), rng.random_range(-5.0..28.0));
            let radius = rng.random_range(0.05..30.0);
            let sides = 3 + case % 2;
            let start: f64 = rng.random_range(0.0..std::f64::consts::TAU);
            let mut corners: Vec<DVec2> = (0..sides)
                .map(|k| {
                    let t = start
                        + k as f64 * std::f64::consts::TAU / sides as f64
                        + rng.random_range(-0.3..0.3);
                    centre + radius * DVec2::new(t.cos(), t.sin() * rng.random_range(0.05..1.0))
                })
                .collect();
            if case % 3 == 0 {
                corners.reverse();
            }
            let area: f64 = (0..sides)
                .map(|i| corners[i].perp_dot(corners[(i + 1) % sides]))
                .sum();
            let every: Vec<(usize, usize)> = (0..ny)
                .flat_map(|y| (0..nx).map(move |x| (x, y)))
                .filter(|&(x, y)| {
                    let p = DVec2::new(x as f64 + 0.5, y as f64 + 0.5);
                    area != 0.0
                        && (0..sides).all(|i| {
                            let (a, b) = (corners[i], corners[(i + 1) % sides]);
                            area.signum() * (b - a).perp_dot(p - a) >= 0.0
                        })
                })
                .collect();
            let spans: Vec<(usize, usize)> = spans_inside(&corners, nx, ny)
                .into_iter()
                .flat_map(|(y, xs)| xs.map(move |x| (x, y)))
                .collect();
            assert_eq!(spans, every, "case {case}");
        }
    }

    fn square(z: f64, size: f64, up: bool) -> Shape {
        let h = size / 2.0;
        let mut v = [
            DVec3::new(-h, -h, z),
            DVec3::new(h, -h, z),
            DVec3::new(h, h, z),
            DVec3::new(-h, h, z),
        ];
        if !up {
            v.reverse();
        }
        Shape::Quad(v)
    }

    /// A stack of equal squares seen from above: only the top one is visible; from the side none hides
    /// another (edge-on, each judged at its centroid).
    #[test]
    fn a_stack_shows_its_top_only() {
        let stack: Vec<Shape> = (0..4).map(|k| square(k as f64 * 0.1, 1.0, true)).collect();
        let from_above = visible_fractions(&stack, DVec3::Z);
        assert_eq!(from_above, vec![0.0, 0.0, 0.0, 1.0]);
        let from_below = visible_fractions(&stack, -DVec3::Z);
        assert_eq!(from_below, vec![1.0, 0.0, 0.0, 0.0]);
    }

    /// A small square over the middle of a large one hides the share of its area, to the accuracy of
    /// the pixel grid (the small square is 4 pixels across: its edges are exact on pixel boundaries).
    #[test]
    fn a_small_square_hides_its_area_share() {
        let shapes = [square(0.0, 1.0, true), square(0.5, 0.25, true)];
        let f = visible_fractions(&shapes, DVec3::Z);
        assert_eq!(f[1], 1.0);
        assert!((f[0] as f64 - (1.0 - 0.0625)).abs() < 1e-6, "{f:?}");
    }

    /// Of a two-sided polygon's two coplanar sides, the one facing the viewer is seen.
    #[test]
    fn the_facing_side_wins_a_depth_tie() {
        let shapes = [square(0.0, 1.0, false), square(0.0, 1.0, true)];
        assert_eq!(visible_fractions(&shapes, DVec3::Z), vec![0.0, 1.0]);
        assert_eq!(visible_fractions(&shapes, -DVec3::Z), vec![1.0, 0.0]);
    }

    /// Buckets cover the sphere: every direction falls in a cell whose centre is within the cell's
    /// half-diagonal, and opposite directions get different cells.
    #[test]
    fn buckets_are_near_their_directions() {
        for k in 0..1000 {
            let a = k as f64 * 2.399_963;
            let z = 1.0 - 2.0 * (k as f64 + 0.5) / 1000.0;
            let d = DVec3::new(
                (1.0 - z * z).sqrt() * a.cos(),
                (1.0 - z * z).sqrt() * a.sin(),
                z,
            );
            let (b, c) = direction_bucket(d);
            assert!((b as usize) < 6 * BUCKETS_PER_FACE * BUCKETS_PER_FACE);
            assert!(d.angle_between(c) < 0.2, "{d} {c}");
            assert_eq!(direction_bucket(c).0, b, "a bucket's centre lies in it");
            assert_ne!(direction_bucket(-d).0, b);
        }
    }
}
