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
//! Buffers are cached per (cluster, direction bucket) ([`ItemBuffers`], with each normal group's
//! visible area beside the fractions): directions are quantised on a cube map of `6 ×`
//! [`BUCKETS_PER_FACE`]² cells and each buffer is drawn along its cell's centre direction, so the
//! answer is a pure function of the cluster and the bucket and does not depend on which thread (or
//! in which order) first asked for it.

use crate::geometry::{DVec2, DVec3, Shape};
use crate::hierarchy::clusters::VisibleAreas;
use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};
use std::ops::Range;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Mutex, RwLock};

/// Pixels across the smallest object of a buffer.
pub const PIXELS_ACROSS_SMALLEST: f64 = 4.0;
/// Most pixels along a side of one buffer (the bound on its work and memory: 128² pixels). A buffer's
/// cost is its pixels, and clusters whose smallest object is tiny beside their extent reach the
/// bound: on office3 a quarter of the 85,529 buffers drawn would want more than 128 pixels across
/// (8,600 pixels a buffer on average at 256², up to 65,536 at the bound). At 128² office3's refinement
/// takes a tenth less time and the seen points' errors are those of 256² within 0.05 points on office3,
/// office2, the corridor and the classroom; at 64² a classroom seed's worst point moved from 24% to 29%
/// (BENCHMARKS.md, "Item buffers at 128² pixels").
pub const MAX_SIDE: usize = 128;
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

/// The cube-map cell of direction `d` (not necessarily unit); [`bucket_direction`] gives its centre.
pub fn direction_bucket(d: DVec3) -> u16 {
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
    ((face * n + i) * n + j) as u16
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
    SCRATCH.with_borrow_mut(|scratch| {
        scratch.prepare(nx, ny);
        let mut spans = Vec::new();
        let mut covered = vec![0u32; shapes.len()];
        for (k, shape) in shapes.iter().enumerate() {
            let n = shape.normal();
            let facing = n.dot(toward);
            if facing.abs() < 1e-12 {
                continue; // edge-on: no area in the buffer
            }
            let offset = if facing > 0.0 { 0.0 } else { -bias };
            let mut corners = [DVec2::ZERO; 4];
            for (c, &v) in corners.iter_mut().zip(shape.vertices()) {
                *c = (project(v) - lo) / pixel;
            }
            let plane = n.dot(shape.vertices()[0]);
            let (nu, nw) = (n.dot(u) * pixel, n.dot(w) * pixel);
            let (cu, cw) = (lo.x * n.dot(u), lo.y * n.dot(w));
            // Depth toward the viewer of the plane at pixel coordinates (x, y) is
            // `(plane - cu - cw - x nu - y nw) / facing + offset`, evaluated in that order.
            let base = plane - cu - cw;
            spans.clear();
            spans_inside(&corners[..shape.vertex_count()], nx, ny, &mut spans);
            for (y, xs) in spans.drain(..) {
                covered[k] += xs.len() as u32;
                let y_nw = (y as f64 + 0.5) * nw;
                scratch.draw_span(y, xs, k as u32, |x| {
                    (base - x * nu - y_nw) / facing + offset
                });
            }
        }
        let depth_at_centroid: Vec<Option<f64>> = shapes
            .iter()
            .zip(&covered)
            .map(|(shape, &c)| {
                (c == 0).then(|| {
                    let q = (project(shape.centroid()) - lo) / pixel;
                    let (x, y) = (q.x as usize, q.y as usize);
                    scratch.depth[y.min(ny - 1) * nx + x.min(nx - 1)]
                })
            })
            .collect();
        let won = scratch.count_and_clear(shapes.len());
        shapes
            .iter()
            .enumerate()
            .map(|(k, shape)| match depth_at_centroid[k] {
                None => won[k] as f32 / covered[k] as f32,
                // Too small for the buffer (or edge-on): judged at its centroid.
                Some(depth) if depth <= shape.centroid().dot(toward) + bias => 1.0,
                Some(_) => 0.0,
            })
            .collect()
    })
}

thread_local! {
    /// Each thread's buffer, kept between draws so that a draw touches only the rows it covers.
    static SCRATCH: std::cell::RefCell<Scratch> = std::cell::RefCell::default();
}

/// An item buffer's pixels, reused between draws: between draws every depth is −∞ and every owner
/// empty ([`Scratch::count_and_clear`] restores them where a draw wrote).
#[derive(Default)]
struct Scratch {
    nx: usize,
    depth: Vec<f64>,
    owner: Vec<u32>,
    /// Per row, the first and end column a draw wrote (none when first ≥ end).
    written: Vec<(usize, usize)>,
}

impl Scratch {
    /// Room for an `nx × ny` buffer (pixel `(x, y)` at `y nx + x`).
    fn prepare(&mut self, nx: usize, ny: usize) {
        self.nx = nx;
        if self.depth.len() < nx * ny {
            self.depth.resize(nx * ny, f64::NEG_INFINITY);
            self.owner.resize(nx * ny, u32::MAX);
        }
        self.written.clear();
        self.written.resize(ny, (usize::MAX, 0));
    }

    /// Draws item `k` over columns `xs` of row `y`, its depth at pixel coordinate `x` being
    /// `depth_at(x)`: the nearer item (larger depth) keeps each pixel, the earlier one a tie.
    #[inline]
    fn draw_span(&mut self, y: usize, xs: Range<usize>, k: u32, depth_at: impl Fn(f64) -> f64) {
        let written = &mut self.written[y];
        *written = (written.0.min(xs.start), written.1.max(xs.end));
        let row = y * self.nx;
        let depth = &mut self.depth[row + xs.start..row + xs.end];
        let owner = &mut self.owner[row + xs.start..row + xs.end];
        for (i, (d, o)) in depth.iter_mut().zip(owner.iter_mut()).enumerate() {
            // Column as an `i32` (at most `MAX_SIDE`): packed conversions let this loop vectorise.
            let z = depth_at(f64::from((xs.start + i) as i32) + 0.5);
            let nearer = z > *d;
            *d = if nearer { z } else { *d };
            *o = if nearer { k } else { *o };
        }
    }

    /// Pixels each of `items` items won, restoring the written pixels to empty.
    fn count_and_clear(&mut self, items: usize) -> Vec<u32> {
        let mut won = vec![0u32; items];
        for (y, &(first, end)) in self.written.iter().enumerate() {
            if first >= end {
                continue; // a row the draw did not write
            }
            let row = y * self.nx;
            for p in row + first..row + end {
                if self.owner[p] != u32::MAX {
                    won[self.owner[p] as usize] += 1;
                }
                self.owner[p] = u32::MAX;
                self.depth[p] = f64::NEG_INFINITY;
            }
        }
        won
    }
}

/// Pixels of an `nx × ny` buffer whose centres lie in the convex polygon `corners` (pixel units), as
/// one span of columns per row, appended to `out`.
///
/// A scanline over the polygon's half-planes: per row each edge bounds the centres from one side at
/// its crossing. Where a crossing falls within rounding of a pixel centre ([`AMBIGUOUS`]) the span's end
/// is settled by the exact edge test, so the pixels are the ones a test of every pixel would keep; a
/// row costs one crossing per edge otherwise (item buffers draw tens of millions of rows per solve).
fn spans_inside(corners: &[DVec2], nx: usize, ny: usize, out: &mut Vec<(usize, Range<usize>)>) {
    let count = corners.len();
    // Each edge as its start and direction, found once (at most 4: a triangle or a quad).
    let mut edge_array = [(DVec2::ZERO, DVec2::ZERO); 4];
    for (e, (a, b)) in edge_array.iter_mut().zip(crate::geometry::edges(corners)) {
        *e = (a, b - a);
    }
    let edges = &edge_array[..count];
    let signed_area: f64 = crate::geometry::edges(corners)
        .map(|(a, b)| a.perp_dot(b))
        .sum();
    if signed_area == 0.0 {
        return;
    }
    let sign = signed_area.signum();
    // The edges that bound a row's centres from the left and from the right: a point of each and
    // its x step per unit of height.
    let (mut bounds, mut used) = ([(DVec2::ZERO, 0.0, false); 4], 0);
    for &(a, d) in edges {
        if d.y != 0.0 {
            bounds[used] = (a, d.x / d.y, sign * d.y > 0.0);
            used += 1;
        }
    }
    let bounds = &bounds[..used];
    let (lo, hi) = corners.iter().fold(
        (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY)),
        |(lo, hi), &c| (lo.min(c), hi.max(c)),
    );
    let inside = |x: usize, y: usize| {
        let p = DVec2::new(x as f64 + 0.5, y as f64 + 0.5);
        edges.iter().all(|&(a, d)| sign * d.perp_dot(p - a) >= 0.0)
    };
    let (x_lo, x_hi) = (first_centre_from(lo.x), end_centre_to(hi.x, nx));
    if x_lo >= x_hi {
        return;
    }
    for y in first_centre_from(lo.y)..end_centre_to(hi.y, ny) {
        let cy = y as f64 + 0.5;
        let (mut left, mut right) = (lo.x, hi.x);
        for &(a, step, is_right) in bounds {
            let crossing = a.x + step * (cy - a.y);
            if is_right {
                right = right.min(crossing);
            } else {
                left = left.max(crossing);
            }
        }
        if left > right + 1.0 {
            continue;
        }
        let mut x0 = first_centre_from(left).clamp(x_lo, x_hi);
        let mut x1 = end_centre_to(right, nx).clamp(x_lo, x_hi);
        if near_a_centre(left) {
            while x0 > x_lo && inside(x0 - 1, y) {
                x0 -= 1;
            }
            while x0 < x1 && !inside(x0, y) {
                x0 += 1;
            }
        }
        if near_a_centre(right) {
            while x1 < x_hi && inside(x1, y) {
                x1 += 1;
            }
            while x1 > x0 && !inside(x1 - 1, y) {
                x1 -= 1;
            }
        }
        if x0 < x1 {
            out.push((y, x0..x1));
        }
    }
}

/// Relative distance from a pixel centre within which a span's end is checked by the exact edge test:
/// far above the rounding of a crossing (a few units in the last place), far below a pixel.
const AMBIGUOUS: f64 = 1e-9;

/// Whether `x` (pixel units) may lie on the other side of a pixel centre than rounding made it.
fn near_a_centre(x: f64) -> bool {
    let t = x - 0.5;
    if t.is_nan() || t.abs() >= 1e15 {
        return true;
    }
    // Nearest integer, written out (`f64::round` is a library call on the baseline target).
    let nearest = (t + 0.5f64.copysign(t)) as i64 as f64;
    (t - nearest).abs() <= AMBIGUOUS * (1.0 + x.abs())
}

/// The first pixel whose centre is at or after `v` (pixel units; 0 before the buffer). Written out
/// rather than with `f64::ceil`, a library call on the baseline x86-64 target.
fn first_centre_from(v: f64) -> usize {
    let t = v - 0.5;
    if t > 0.0 {
        let i = t as usize;
        i + usize::from((i as f64) < t)
    } else {
        0
    }
}

/// One past the last pixel (of `n`) whose centre is at or before `v` (pixel units).
fn end_centre_to(v: f64, n: usize) -> usize {
    let t = v - 0.5;
    if t >= 0.0 {
        (t as usize).saturating_add(1).min(n)
    } else {
        0
    }
}

/// The visible areas and exposures of the clusters whose index is the shard's modulo [`SHARDS`].
/// Keyed by cluster, with each cluster's buckets in a short sorted list, rather than by (cluster,
/// bucket): office3 caches 60k buffers of a few thousand clusters, and a table of 60k entries held 5
/// MB at its peak (while it doubled), the lists about 1.5 MB.
#[derive(Debug, Default)]
struct Shard {
    clusters: HashMap<u32, ClusterBuffers, BuildHasherDefault<KeyHasher>>,
    /// Exposure bits per (cluster, bucket) ([`ItemBuffers::exposure`]).
    exposures: HashMap<(u32, u16), Box<[u64]>, BuildHasherDefault<KeyHasher>>,
}

/// Shards of the cache, each behind its own lock. Couplings and sweeps look buffers up millions of
/// times on the classroom; behind one lock every lookup wrote the lock's word, which the other
/// threads' lookups then had to fetch back (BENCHMARKS.md, "The item-buffer cache in shards").
const SHARDS: usize = 64;

/// A shard on cache lines of its own, so that threads using different shards write no common line.
#[derive(Debug, Default)]
#[repr(align(128))]
struct PaddedShard(RwLock<Shard>);

/// One cluster's cached buffers, sorted by direction bucket (parallel lists rather than one of
/// tuples, which padding would make 24 bytes an entry instead of 19), each with whether it was asked
/// for since the last [`ItemBuffers::forget_unused`].
#[derive(Debug, Default)]
struct ClusterBuffers {
    buckets: Vec<u16>,
    visible: Vec<VisibleAreas>,
    used: Vec<AtomicBool>,
}

impl ClusterBuffers {
    /// The buffer of `bucket`, marked used, or where it would go in the sorted list.
    fn get(&self, bucket: u16) -> Result<&VisibleAreas, usize> {
        self.buckets.binary_search(&bucket).map(|at| {
            // Written only when clear: a store on every hit would take the mark's cache line from
            // the other threads each time (sweeps look buffers up over a million times).
            if !self.used[at].load(Ordering::Relaxed) {
                self.used[at].store(true, Ordering::Relaxed);
            }
            &self.visible[at]
        })
    }

    /// Drops the buffers not used since the last call and clears the marks of the others; returns
    /// the bytes dropped (as [`ItemBuffers::visible_areas`] counted them).
    fn forget_unused(&mut self) -> usize {
        let keep: Vec<bool> = self
            .used
            .iter()
            .map(|used| used.swap(false, Ordering::Relaxed))
            .collect();
        let mut dropped = 0;
        let mut kept = keep.iter();
        self.visible.retain(|visible| {
            let keep = *kept.next().expect("one mark per buffer");
            if !keep {
                dropped += ENTRY_OVERHEAD + visible.bytes();
            }
            keep
        });
        let mut kept = keep.iter();
        self.buckets
            .retain(|_| *kept.next().expect("one mark per buffer"));
        // Every mark is clear now, so the first ones serve the buffers kept.
        self.used.truncate(self.buckets.len());
        self.buckets.shrink_to_fit();
        self.visible.shrink_to_fit();
        self.used.shrink_to_fit();
        dropped
    }
}

/// Hashes a cache key by one rotation and multiplication per field (as rustc's Fx hash): the keys are
/// small integers chosen by the program, and SipHash was most of the cost of a cache hit (sweeps ask
/// for cached buffers over a million times on the classroom).
#[derive(Debug, Default)]
struct KeyHasher(u64);

impl KeyHasher {
    fn add(&mut self, x: u64) {
        self.0 = (self.0.rotate_left(5) ^ x).wrapping_mul(0x517c_c1b7_2722_0a95);
    }
}

impl Hasher for KeyHasher {
    fn write(&mut self, bytes: &[u8]) {
        bytes.iter().for_each(|&b| self.add(u64::from(b)));
    }
    fn write_u16(&mut self, n: u16) {
        self.add(u64::from(n));
    }
    fn write_u32(&mut self, n: u32) {
        self.add(u64::from(n));
    }
    fn finish(&self) -> u64 {
        self.0
    }
}

/// What clusters keep of their item buffers, cached per (cluster, direction bucket) up to a number of
/// bytes (a share of `--max-memory`, [`crate::memory::MemoryBudget`]); past it buffers are drawn again
/// on every request, with the same answer. Shared between threads.
///
/// A buffer's answer is kept with each normal group's visible area beside the patches' fractions
/// ([`VisibleAreas`]): a link then finds its cluster end's visible projected area in O(groups), where
/// the bare fractions cost a walk over every patch of the cluster for every link.
///
/// Beside the buffers it keeps the clusters' exposures ([`ItemBuffers::exposure`]) in a share of the
/// bytes of their own: unlike a buffer, an exposure that does not fit changes the answer, so which
/// ones fit must not depend on which buffers the threads cached first.
#[derive(Debug)]
pub struct ItemBuffers {
    shards: Box<[PaddedShard]>,
    /// Bytes the cached buffers hold.
    bytes: AtomicUsize,
    /// Bytes of the exposures, counted apart: which buffers the threads happened to cache first must
    /// not decide which exposures fit, since those change the answer. Held while exposures are
    /// stored, so that they are stored in the order given.
    exposure_bytes: Mutex<usize>,
    max_bytes: usize,
}

/// Bytes one cached entry holds besides its values' allocation ([`VisibleAreas::bytes`]): its bucket
/// and pointer in its cluster's lists with their spare room, a share of the cluster's map entry, and
/// the allocator's rounding.
const ENTRY_OVERHEAD: usize = 64;

/// The cache's bytes kept for exposures are `1 / EXPOSURE_SHARE` of them, the buffers' the rest (a
/// few bits per patch against a buffer's fractions: a small share holds them all).
const EXPOSURE_SHARE: usize = 8;

/// Which patches of a cluster (by position in its contents) the link sources of one direction bucket
/// reach from outside the cluster, or which reach its link receivers ([`ItemBuffers::exposure`]): a bit
/// per patch, whether it is reached: by the ray from its centroid, or (toward a source with gradients,
/// `solvers::clustering::expose`) by the ray from any of its nodes, followed by [`NODE_BITS`] per
/// reached patch in order, whether the rays from its nodes do. An exposure toward a receiver holds
/// one more word after the bits, the receiver's distance.
pub type Exposure = Box<[u64]>;

/// Bits per reached patch for its gradient nodes: one per node.
pub const NODE_BITS: usize = 4;

/// Reached patches whose node bits one word of an [`Exposure`] holds.
const NODE_PATCHES_PER_WORD: usize = 64 / NODE_BITS;

/// Whether bit `k` of `exposure` is set: patch `k` is reached (by its centroid's ray, or some node's).
pub fn exposed(exposure: &[u64], k: usize) -> bool {
    exposure
        .get(k / 64)
        .is_some_and(|word| word >> (k % 64) & 1 == 1)
}

/// Per patch of an exposure of `patches` patches, which of its gradient nodes' rays reach (bit `n`
/// for node `n`): 0 where the patch is not reached or no nodes were tried.
pub fn exposed_nodes(exposure: &[u64], patches: usize) -> Vec<u8> {
    let nodes = exposure.get(patches.div_ceil(64)..).unwrap_or(&[]);
    let mut rank = 0;
    (0..patches)
        .map(|k| {
            if !exposed(exposure, k) {
                return 0;
            }
            let word = nodes
                .get(rank / NODE_PATCHES_PER_WORD)
                .copied()
                .unwrap_or(0);
            let bits =
                word >> (NODE_BITS * (rank % NODE_PATCHES_PER_WORD)) & ((1 << NODE_BITS) - 1);
            rank += 1;
            bits as u8
        })
        .collect()
}

/// Packs per patch whether it is reached and which of its nodes' rays do into an [`Exposure`]; the
/// nodes' bits are kept with `nodes` only.
pub fn pack_exposure(patches: impl ExactSizeIterator<Item = (bool, u8)>, nodes: bool) -> Exposure {
    let mut words = vec![0u64; patches.len().div_ceil(64)];
    let mut node_words: Vec<u64> = Vec::new();
    let mut rank = 0;
    for (k, (reached, node_bits)) in patches.enumerate() {
        if !reached {
            continue;
        }
        words[k / 64] |= 1 << (k % 64);
        if nodes {
            debug_assert!(usize::from(node_bits) < 1 << NODE_BITS);
            if rank % NODE_PATCHES_PER_WORD == 0 {
                node_words.push(0);
            }
            if let Some(word) = node_words.last_mut() {
                *word |= u64::from(node_bits) << (NODE_BITS * (rank % NODE_PATCHES_PER_WORD));
            }
            rank += 1;
        }
    }
    words.extend(node_words);
    words.into_boxed_slice()
}

impl ItemBuffers {
    /// The shard that holds `cluster`'s buffers and exposures.
    fn shard(&self, cluster: u32) -> &RwLock<Shard> {
        &self.shards[cluster as usize % SHARDS].0
    }

    /// Whether the exposure of `cluster` along `bucket` is stored.
    pub fn has_exposure(&self, cluster: u32, bucket: u16) -> bool {
        self.shard(cluster)
            .read()
            .expect("item buffer cache")
            .exposures
            .contains_key(&(cluster, bucket))
    }

    /// The exposure of `cluster` along `bucket`, when stored: which of its patches (and which of
    /// their nodes) rays reach the bucket's nearest link source from (or, for a sending key, its
    /// nearest receiver, from their centroids), past the cluster's own contents (the item buffer
    /// answers for those). See `solvers::clustering::expose`. `read` is given the bits in place,
    /// under the cache's read lock: sweeps ask for exposures hundreds of thousands of times, and a
    /// copy each was an allocation each.
    pub fn exposure<T>(
        &self,
        cluster: u32,
        bucket: u16,
        read: impl FnOnce(&[u64]) -> T,
    ) -> Option<T> {
        self.shard(cluster)
            .read()
            .expect("item buffer cache")
            .exposures
            .get(&(cluster, bucket))
            .map(|bits| read(bits))
    }

    /// Stores exposures, in order, while they fit in their share of the cache's bytes
    /// ([`EXPOSURE_SHARE`]), counted apart from the buffers (past that, sharing goes on without them,
    /// the same whatever the threads).
    pub fn store_exposures(&self, exposures: Vec<((u32, u16), Exposure)>) {
        let mut stored = self.exposure_bytes.lock().expect("item buffer cache");
        for (key, bits) in exposures {
            let bytes = ENTRY_OVERHEAD + 8 * bits.len();
            if *stored + bytes > self.max_bytes / EXPOSURE_SHARE {
                break;
            }
            let mut shard = self.shard(key.0).write().expect("item buffer cache");
            if shard.exposures.insert(key, bits).is_none() {
                *stored += bytes;
            }
        }
    }

    /// Drops the buffers that no one asked for since the last call (the first call: since the
    /// cache was made); called as each refinement pass starts, so that the cache holds what the
    /// present links use rather than every (cluster, direction) that earlier, since refined, links
    /// asked for. office3's peak: 107 → 101 MB, for 1–5% more time (BENCHMARKS.md, "The item-buffer
    /// cache holds what the links use"). Answers are unchanged: a dropped buffer is drawn again, the
    /// same.
    pub fn forget_unused(&self) {
        for shard in &self.shards {
            let mut shard = shard.0.write().expect("item buffer cache");
            let mut dropped = 0;
            shard.clusters.retain(|_, buffers| {
                dropped += buffers.forget_unused();
                !buffers.buckets.is_empty()
            });
            self.bytes.fetch_sub(dropped, Ordering::Relaxed);
        }
    }

    /// An empty cache that holds at most `max_bytes`.
    pub fn new(max_bytes: usize) -> Self {
        ItemBuffers {
            shards: (0..SHARDS).map(|_| PaddedShard::default()).collect(),
            bytes: AtomicUsize::new(0),
            exposure_bytes: Mutex::new(0),
            max_bytes,
        }
    }

    /// The visible areas of `cluster` seen along direction bucket `bucket` ([`direction_bucket`]);
    /// when not cached, `draw` makes them from the item buffer along the bucket's centre direction
    /// (its argument, [`bucket_direction`]).
    pub fn visible_areas(
        &self,
        cluster: u32,
        bucket: u16,
        draw: impl FnOnce(DVec3) -> VisibleAreas,
    ) -> VisibleAreas {
        let shard = self.shard(cluster);
        if let Some(Ok(hit)) = shard
            .read()
            .expect("item buffer cache")
            .clusters
            .get(&cluster)
            .map(|buffers| buffers.get(bucket))
        {
            return hit.clone();
        }
        let visible = draw(bucket_direction(bucket));
        let bytes = ENTRY_OVERHEAD + visible.bytes();
        // Threads adding at once may pass the bound by a buffer each; what is cached never changes
        // an answer.
        if self.bytes.load(Ordering::Relaxed) + bytes
            <= self.max_bytes - self.max_bytes / EXPOSURE_SHARE
        {
            let mut shard = shard.write().expect("item buffer cache");
            let buffers = shard.clusters.entry(cluster).or_default();
            if let Err(at) = buffers.get(bucket) {
                buffers.buckets.insert(at, bucket);
                buffers.visible.insert(at, visible.clone());
                buffers.used.insert(at, AtomicBool::new(true));
                self.bytes.fetch_add(bytes, Ordering::Relaxed);
            }
        }
        visible
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hierarchy::clusters::{Facing, Orientation};

    /// The areas of [`three_unit_patches`].
    const UNIT_AREAS: [f64; 3] = [1.0; 3];

    /// The orientation of a cluster of three unit patches, two facing up and one down: the cache
    /// tests' cluster.
    fn three_unit_patches() -> Orientation {
        let facing = |z: f64| Facing {
            normal: DVec3::new(0.0, 0.0, z),
            area: 1.0,
            centroid: DVec3::ZERO,
        };
        Orientation::new(&[facing(1.0), facing(-1.0), facing(1.0)])
    }

    /// Exposures of many patches (more than a word of each part) give back what was packed: the
    /// patches' bits, and the nodes' bits of the reached patches only, or none where no nodes were
    /// kept; a word appended after them (a sending exposure's reach) changes neither.
    #[test]
    fn exposures_unpack_to_what_was_packed() {
        let patches: Vec<(bool, u8)> = (0..150u32)
            .map(|k| (k % 3 != 0, (k * 7 % 16) as u8))
            .collect();
        let with_nodes = pack_exposure(patches.iter().copied(), true);
        let nodes = exposed_nodes(&with_nodes, patches.len());
        for (k, &(reached, bits)) in patches.iter().enumerate() {
            assert_eq!(exposed(&with_nodes, k), reached, "patch {k}");
            assert_eq!(nodes[k], if reached { bits } else { 0 }, "patch {k}");
        }
        let mut without = pack_exposure(patches.iter().copied(), false).into_vec();
        assert_eq!(without.len(), patches.len().div_ceil(64));
        without.push(f64::to_bits(2.5));
        assert!(exposed_nodes(&without[..without.len() - 1], patches.len())
            .iter()
            .all(|&b| b == 0));
        for (k, &(reached, _)) in patches.iter().enumerate() {
            assert_eq!(exposed(&without, k), reached, "patch {k}");
        }
    }

    /// Threads asking for the same buffers at once, across many shards, each get the one answer
    /// its draw gives, and every buffer is cached and counted once, whichever thread drew it first.
    #[test]
    fn threads_share_the_cache_and_count_each_buffer_once() {
        use rayon::prelude::*;
        let orientation = three_unit_patches();
        let draw = |cluster: u32, bucket: u16| {
            let seen = ((cluster * 7 + u32::from(bucket)) % 5) as f32 / 4.0;
            VisibleAreas::new(&orientation, &UNIT_AREAS, &[seen, 1.0 - seen, 0.5])
        };
        let keys: Vec<(u32, u16)> = (0..200u32)
            .flat_map(|c| (0..3u16).map(move |b| (c, b * 11)))
            .collect();
        let buffers = ItemBuffers::new(1 << 24);
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(4)
            .build()
            .unwrap();
        // Every key asked for eight times over, in an order that keeps the threads on the same keys.
        let asks: Vec<(u32, u16)> = (0..8).flat_map(|_| keys.iter().copied()).collect();
        pool.install(|| {
            asks.par_iter().for_each(|&(c, b)| {
                assert_eq!(buffers.visible_areas(c, b, |_| draw(c, b)), draw(c, b));
            });
        });
        let expected: usize = (keys.iter())
            .map(|&(c, b)| ENTRY_OVERHEAD + draw(c, b).bytes())
            .sum();
        assert_eq!(buffers.bytes.load(Ordering::Relaxed), expected);
        let cached: usize = (buffers.shards.iter())
            .map(|shard| {
                let shard = shard.0.read().unwrap();
                shard
                    .clusters
                    .values()
                    .map(|c| c.buckets.len())
                    .sum::<usize>()
            })
            .sum();
        assert_eq!(cached, keys.len());
    }

    /// The cache keeps what was asked for since the last `forget_unused` (drawn or found) and drops
    /// the rest, bytes included, and a dropped buffer comes back the same when asked for again.
    #[test]
    fn the_cache_forgets_buffers_unused_since_the_last_pass() {
        let orientation = three_unit_patches();
        let buffers = ItemBuffers::new(1 << 20);
        let draws = std::cell::Cell::new(0);
        let ask = |cluster: u32, bucket: u16| {
            buffers.visible_areas(cluster, bucket, |_| {
                draws.set(draws.get() + 1);
                let seen = f32::from(bucket % 3) / 2.0;
                VisibleAreas::new(&orientation, &UNIT_AREAS, &[seen, 1.0 - seen, 0.25])
            })
        };
        let first: Vec<VisibleAreas> = [(1, 0), (1, 5), (2, 4)]
            .iter()
            .map(|&(c, b)| ask(c, b))
            .collect();
        assert_eq!(draws.get(), 3);
        let bytes = |buffers: &ItemBuffers| buffers.bytes.load(Ordering::Relaxed);
        let full = bytes(&buffers);
        // Drawn since the cache was made: all kept, their marks cleared.
        buffers.forget_unused();
        assert_eq!(bytes(&buffers), full);
        assert_eq!(ask(1, 5), first[1]);
        assert_eq!(draws.get(), 3, "a kept buffer is not drawn again");
        // Only (1, 5) was asked for since: the other two go, and their bytes with them.
        buffers.forget_unused();
        assert_eq!(
            bytes(&buffers),
            ENTRY_OVERHEAD + first[1].bytes(),
            "only the used buffer's bytes stay"
        );
        let clusters: usize = (buffers.shards.iter())
            .map(|shard| shard.0.read().unwrap().clusters.len())
            .sum();
        assert_eq!(clusters, 1);
        assert_eq!(ask(1, 5), first[1]);
        assert_eq!(draws.get(), 3);
        assert_eq!(ask(1, 0), first[0]);
        assert_eq!(ask(2, 4), first[2]);
        assert_eq!(
            draws.get(),
            5,
            "forgotten buffers are drawn again, the same"
        );
    }

    /// The scanline keeps exactly the pixels whose centres pass every edge test, for random convex
    /// triangles and quads of either winding (some reaching past the buffer, some thinner than a pixel,
    /// some with corners on pixel centres and edges, whose crossings fall on centres).
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
            if case % 5 < 2 {
                let snap = if case % 5 == 0 { 2.0 } else { 4.0 };
                corners
                    .iter_mut()
                    .for_each(|c| *c = (*c * snap).round() / snap);
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
            let mut spans = Vec::new();
            spans_inside(&corners, nx, ny, &mut spans);
            let spans: Vec<(usize, usize)> = spans
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
            let b = direction_bucket(d);
            let c = bucket_direction(b);
            assert!((b as usize) < 6 * BUCKETS_PER_FACE * BUCKETS_PER_FACE);
            assert!(d.angle_between(c) < 0.2, "{d} {c}");
            assert_eq!(direction_bucket(c), b, "a bucket's centre lies in it");
            assert_ne!(direction_bucket(-d), b);
        }
    }
}
