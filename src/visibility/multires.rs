//! Multi-resolution visibility (Sillion–Drettakis §3.2–3.3): exact ray casting where a cluster's contents
//! could cast a shadow feature larger than the user's feature size `s` on the receiver, extinction
//! (§3.1, [`super::extinction`]) where they could not.
//!
//! **BSIZE (§3.3).** Each cluster's contents are projected orthographically into a small binary image
//! ([`RESOLUTION`] pixels along the longer side of the cluster's projected bounds). The number of Erosions
//! that make the blocked pixels vanish, and the number of Expansions that fill the free pixels, both from
//! [`crate::measures::morphology`] (shared with the FBEM's feature masks), give the largest connected
//! regions of shadow and of light: a region of diameter 2n goes after n steps (§2.4). BSIZE is the larger
//! of the two, `(2n + 1)` pixels: the extra pixel bounds the error of sampling polygons at pixel centres,
//! so BSIZE does not under-estimate a feature by more than rounding.
//!
//! Directions: the paper assumes isotropic clusters and projects once; its footnote 3 suggests sampling
//! a fixed set of directions for general ones. Cubes, walls and furniture are not isotropic (a grid of
//! cubes seen obliquely closes its gaps into one large blocker; a row of faces seen edge-on is nothing),
//! so the contents are projected along the 13 directions of the cube's faces, edges and corners (up to
//! sign), and BSIZE is the largest of the 13. Not the one nearest the query's direction: the cluster is
//! replaced by an isotropic extinction `κ`, which attenuates every direction alike, so what it may hide is
//! the feature of its worst direction. (Tried first, the nearest direction's BSIZE averaged rows of
//! vertical faces seen edge-on from the source, whose flat boxes' `κ` then darkened the lit wall between
//! the cubes: FBEM 1.4× exact's already at the smallest feature size.) The rasters are made once, at
//! build time; a projection along each query's own direction would rasterise per ray.
//!
//! **Query (§3.2, Figure 6).** `transmittance(from, to)` reads `to` as the source end and `from` as the
//! receiving end (the order the solvers use). The clusters the segment crosses are visited from the root.
//! A fictitious blocker of size `b` = BSIZE is put at the middle of the part of the segment inside the
//! cluster, at distance `d` from the source end, on a segment of length `D`. By similar triangles
//! (Figure 5: the umbra's edges are the lines through opposite ends of emitter and blocker), an emitter
//! of width `e` gives the receiver an umbra of width `b·D/d − e·(D − d)/d`; the query knows only one
//! point of the emitter, so `e = 0`: the umbra `b·D/d`, the largest any emitter gives (conservative: a
//! larger emitter only shrinks the umbra). If that is smaller than `s` the cluster is treated by
//! extinction ([`Averaging`]): by default by the leaf-level `Σ κ_i l_i` of its subtree, the same sum as
//! [`super::extinction::Extinction`] (exact agreement at `s = ∞`, at the price of walking the subtree's
//! boxes), or with `--multires-averaging cluster` as the paper does, with the single `κ = ΣA/(4V)` of
//! the stopped cluster taken as a whole (O(1) per stopped cluster). Otherwise the polygons it holds directly are intersected exactly (a hit makes the
//! transmittance 0) and its sub-clusters are visited in turn.
//!
//! Limits: `s = 0` descends everywhere and gives exactly the BVH's answer (the same ray–polygon test on
//! the same numbers, `brute_force::ray_polygon`); `s = ∞` descends nowhere: exactly extinction, or with
//! cluster averaging the root cluster's `κ`. In a solve, links whose shaft test is clear or blocked
//! take that exact verdict instead of a query ([`super::shaft::ShaftCulled`], `--visibility-reuse`):
//! office3 at `s` = 0.05, 18.0 → 14.1 s; BENCHMARKS.md, "Shaft tests under multires".
//!
//! **A feature size per surface** (§6: "using the concept of importance to assign different feature
//! sizes of interest to different surfaces"): `--feature-size-for NAME=S` gives the surfaces whose
//! object or material name matches `NAME` their own `s` ([`SurfaceFeatureSize`],
//! [`Multires::with_surface_feature_sizes`]); queries that know the receiving polygon
//! ([`Visibility::transmittance_onto`]: surface and cluster links, the luminaires' first gather) use
//! it, the others the scene's `--feature-size`. A desk whose shadows matter can be solved exactly in
//! a room averaged elsewhere.

use super::brute_force::ray_polygon;
use super::extinction::{Extinction, Segment, WalkStack};
use super::{Hit, Visibility, SEGMENT_EPSILON};
use crate::geometry::{Aabb, DVec3, Ray, Shape};
use crate::hierarchy::clusters::{Child, ClusterTree, ClusterTreeKind};
use crate::measures::morphology::{erosions_to_vanish, Mask};
use rayon::prelude::*;

/// Pixels along the longer side of a cluster's projection: BSIZE is known to `1/RESOLUTION` of the
/// cluster's extent, and building costs `RESOLUTION²` pixels per cluster and direction.
pub const RESOLUTION: usize = 48;

/// The sampled projection directions, unnormalised: 3 faces, 6 edges and 4 corners of a cube.
const DIRECTIONS: [[f64; 3]; 13] = [
    [1.0, 0.0, 0.0],
    [0.0, 1.0, 0.0],
    [0.0, 0.0, 1.0],
    [1.0, 1.0, 0.0],
    [1.0, -1.0, 0.0],
    [1.0, 0.0, 1.0],
    [1.0, 0.0, -1.0],
    [0.0, 1.0, 1.0],
    [0.0, 1.0, -1.0],
    [1.0, 1.0, 1.0],
    [1.0, 1.0, -1.0],
    [1.0, -1.0, 1.0],
    [-1.0, 1.0, 1.0],
];

/// How multi-resolution visibility attenuates through a cluster it does not descend into
/// (`--multires-averaging`). The paper's O(1) `Cluster` saved no time where we measured it (the
/// shadow groups, office3: BENCHMARKS.md, "Multi-resolution visibility … again") and its one κ over
/// the box of a whole group of cubes is the coarser answer (FBEM 7.7× exact visibility's at s = 2.56
/// against 5.8×), so `Leaves` is the default.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Averaging {
    /// The cluster as a whole: `exp(−κ l)` with `κ = ΣA/(4V)` of everything it holds over its box
    /// (Sillion–Drettakis §3.2: "use its extinction"), O(1) per cluster.
    Cluster,
    /// Its leaf clusters: `exp(−Σ κ_i l_i)` over the subtree, as `--visibility extinction` sums it
    /// (equal to it at `s = ∞`), O(subtree) per cluster.
    #[default]
    Leaves,
}

/// Exact ray casting near large features, cluster extinction for small ones.
pub struct Multires {
    extinction: Extinction,
    averaging: Averaging,
    shapes: Vec<Shape>,
    /// Per cluster, BSIZE (world units): the largest over the [`DIRECTIONS`].
    bsize: Vec<f64>,
    /// The user's feature size `s` on the receiver (world units), in `[0, ∞]`.
    feature_size: f64,
    /// Per polygon (receiver), its own `s` ([`Multires::with_surface_feature_sizes`]); empty: every
    /// receiver takes `feature_size`.
    surface_feature_sizes: Vec<f64>,
}

/// `--feature-size-for NAME=S`: the feature size `S` (world units, `inf` allowed) for the surfaces whose
/// object or material name matches `NAME` (`*` matches any run of characters).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct SurfaceFeatureSize {
    pub pattern: String,
    pub size: f64,
}

impl std::str::FromStr for SurfaceFeatureSize {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, Self::Err> {
        let (pattern, size) = text
            .rsplit_once('=')
            .ok_or_else(|| format!("'{text}' is not NAME=S"))?;
        let size: f64 = size
            .trim()
            .parse()
            .map_err(|_| format!("'{size}' is not a feature size (a number, or inf)"))?;
        if size.is_nan() || size < 0.0 {
            return Err(format!(
                "the feature size of '{pattern}' must be >= 0, not {size}"
            ));
        }
        if pattern.is_empty() {
            return Err(format!("'{text}' names no surface"));
        }
        Ok(SurfaceFeatureSize {
            pattern: pattern.to_string(),
            size,
        })
    }
}

impl Multires {
    /// Multi-resolution visibility over `shapes` with clusters built by `kind`, for feature size
    /// `feature_size` (≥ 0, world units; `f64::INFINITY` allowed), averaging the clusters it does not
    /// descend into as `averaging` says.
    pub fn new(
        shapes: &[Shape],
        kind: ClusterTreeKind,
        feature_size: f64,
        averaging: Averaging,
    ) -> Self {
        assert!(
            feature_size >= 0.0,
            "the feature size must be non-negative, not {feature_size}"
        );
        let extinction = Extinction::new(shapes, kind);
        let directions = DIRECTIONS.map(|d| DVec3::from_array(d).normalize());
        let tree = extinction.tree();
        let bsize = (0..tree.nodes.len())
            .into_par_iter()
            .map(|n| {
                let polygons = polygons_below(tree, n as u32);
                directions
                    .iter()
                    .map(|&d| blocker_size(shapes, &polygons, &tree.nodes[n].bounds, d))
                    .fold(0.0, f64::max)
            })
            .collect();
        Multires {
            extinction,
            averaging,
            shapes: shapes.to_vec(),
            bsize,
            feature_size,
            surface_feature_sizes: Vec::new(),
        }
    }

    /// The same structure with a feature size per polygon of `shapes` (receivers; `sizes[i] >= 0`),
    /// which queries that name their receiving polygon ([`Visibility::transmittance_onto`]) use
    /// instead of the scene's.
    pub fn with_surface_feature_sizes(mut self, sizes: Vec<f64>) -> Self {
        assert_eq!(
            sizes.len(),
            self.shapes.len(),
            "one feature size per polygon"
        );
        assert!(
            sizes.iter().all(|&s| s >= 0.0),
            "feature sizes must be non-negative"
        );
        self.surface_feature_sizes = sizes;
        self
    }

    /// The feature size of receiving polygon `receiver`: its own, or the scene's.
    pub fn feature_size_on(&self, receiver: usize) -> f64 {
        self.surface_feature_sizes
            .get(receiver)
            .copied()
            .unwrap_or(self.feature_size)
    }

    /// BSIZE of cluster `node` (world units).
    pub fn blocker_size(&self, node: u32) -> f64 {
        self.bsize[node as usize]
    }

    /// The cluster tree the query walks.
    pub fn tree(&self) -> &ClusterTree {
        self.extinction.tree()
    }

    /// The feature size `s` this structure was built for.
    pub fn feature_size(&self) -> f64 {
        self.feature_size
    }
}

/// One query's answer and the work it took.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Trace {
    /// Fraction of light that passes, in [0, 1].
    pub transmittance: f64,
    /// Exact ray–polygon tests made.
    pub polygon_tests: usize,
    /// Clusters replaced by their extinction.
    pub averaged_clusters: usize,
}

impl Multires {
    /// The transmittance from the receiving end `from` to the source end `to` (module documentation),
    /// with the work it took, at the scene's feature size.
    pub fn trace(&self, from: DVec3, to: DVec3) -> Trace {
        self.trace_at(from, to, self.feature_size)
    }

    /// [`Multires::trace`] for feature size `feature_size` on the receiver.
    pub fn trace_at(&self, from: DVec3, to: DVec3, feature_size: f64) -> Trace {
        let mut trace = Trace {
            transmittance: 1.0,
            ..Default::default()
        };
        let (Some(root), Some(segment)) = (self.tree().root(), Segment::new(from, to)) else {
            return trace;
        };
        let ray = Ray::new(from, to - from);
        let mut depth = 0.0;
        let mut stack = WalkStack::new();
        stack.push(root);
        while let Some(n) = stack.pop() {
            let Some((t0, t1)) = segment.clip(self.extinction.padded_bounds(n)) else {
                continue;
            };
            // The fictitious blocker at the middle of the crossed part, seen from the source end.
            let to_source = (1.0 - 0.5 * (t0 + t1)) * segment.length;
            let umbra = self.bsize[n as usize] * segment.length / to_source;
            if umbra < feature_size {
                depth += match self.averaging {
                    Averaging::Cluster => {
                        self.extinction
                            .optical_depth_as_a_whole(n, (t0, t1), &segment)
                    }
                    Averaging::Leaves => self.extinction.optical_depth_below(n, &segment),
                };
                trace.averaged_clusters += 1;
                continue;
            }
            for &c in &self.tree().nodes[n as usize].children {
                match c {
                    Child::Item(i) => {
                        trace.polygon_tests += 1;
                        let polygon = self.shapes[i as usize].vertices();
                        if ray_polygon(&ray, polygon, SEGMENT_EPSILON, 1.0 - SEGMENT_EPSILON)
                            .is_some()
                        {
                            trace.transmittance = 0.0;
                            return trace;
                        }
                    }
                    Child::Node(m) => stack.push(m),
                }
            }
        }
        trace.transmittance = (-depth).exp();
        trace
    }
}

/// The polygons anywhere below cluster `node`.
fn polygons_below(tree: &ClusterTree, node: u32) -> Vec<u32> {
    let mut out = Vec::new();
    let mut stack = vec![node];
    while let Some(n) = stack.pop() {
        for &c in &tree.nodes[n as usize].children {
            match c {
                Child::Item(i) => out.push(i),
                Child::Node(m) => stack.push(m),
            }
        }
    }
    out
}

/// BSIZE (§3.3) of `polygons` inside `bounds`, projected orthographically along the unit `direction`.
fn blocker_size(shapes: &[Shape], polygons: &[u32], bounds: &Aabb, direction: DVec3) -> f64 {
    let (u, v) = direction.any_orthonormal_pair();
    let mut lo = [f64::INFINITY; 2];
    let mut hi = [f64::NEG_INFINITY; 2];
    for k in 0..8 {
        let corner = DVec3::new(
            if k & 1 == 0 {
                bounds.min.x
            } else {
                bounds.max.x
            },
            if k & 2 == 0 {
                bounds.min.y
            } else {
                bounds.max.y
            },
            if k & 4 == 0 {
                bounds.min.z
            } else {
                bounds.max.z
            },
        );
        for (axis, e) in [u, v].into_iter().enumerate() {
            lo[axis] = lo[axis].min(corner.dot(e));
            hi[axis] = hi[axis].max(corner.dot(e));
        }
    }
    let pixel = (hi[0] - lo[0]).max(hi[1] - lo[1]) / RESOLUTION as f64;
    if !(pixel > 0.0 && pixel.is_finite()) {
        return 0.0;
    }
    let side = |axis: usize| (((hi[axis] - lo[axis]) / pixel).ceil() as usize).clamp(1, RESOLUTION);
    // One pixel of free margin: the blocked regions' erosion starts from every side.
    let (w, h) = (side(0) + 2, side(1) + 2);
    let mut blocked = Mask::new(w, h);
    for &p in polygons {
        let corners: Vec<[f64; 2]> = shapes[p as usize]
            .vertices()
            .iter()
            .map(|&x| {
                [
                    (x.dot(u) - lo[0]) / pixel + 1.0,
                    (x.dot(v) - lo[1]) / pixel + 1.0,
                ]
            })
            .collect();
        fill_convex(&mut blocked, &corners);
    }
    let shadow = erosions_to_vanish(&blocked).unwrap_or(0);
    // Free space inside the bounds (margin excluded): Expansions of the blocked pixels until it is filled
    // are Erosions of the free pixels with the image border counting as free.
    let free = Mask::from_fn(w - 2, h - 2, |x, y| !blocked.get(x + 1, y + 1));
    let light = if free.count() == free.bits.len() {
        0
    } else {
        erosions_to_vanish(&free).unwrap_or(0)
    };
    (2 * shadow.max(light) + 1) as f64 * pixel
}

/// Sets the pixels whose centres lie in the convex polygon `corners` (pixel coordinates); a polygon seen
/// edge-on covers no centre.
fn fill_convex(mask: &mut Mask, corners: &[[f64; 2]]) {
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for c in corners {
        x0 = x0.min(c[0]);
        x1 = x1.max(c[0]);
        y0 = y0.min(c[1]);
        y1 = y1.max(c[1]);
    }
    let first = |a: f64| (a - 0.5).ceil().max(0.0) as usize;
    let last = |b: f64, n: usize| ((b - 0.5).floor().max(-1.0) + 1.0).min(n as f64) as usize;
    let n = corners.len();
    for y in first(y0)..last(y1, mask.height) {
        for x in first(x0)..last(x1, mask.width) {
            let p = [x as f64 + 0.5, y as f64 + 0.5];
            let (mut positive, mut negative) = (false, false);
            for k in 0..n {
                let (a, b) = (corners[k], corners[(k + 1) % n]);
                let cross = (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0]);
                positive |= cross > 0.0;
                negative |= cross < 0.0;
            }
            if !(positive && negative) && (positive || negative) {
                mask.bits[y * mask.width + x] = true;
            }
        }
    }
}

impl Visibility for Multires {
    fn intersect(&self, ray: &Ray, t_min: f64, t_max: f64) -> Option<Hit> {
        self.extinction.exact().intersect(ray, t_min, t_max)
    }

    fn occluded(&self, ray: &Ray, t_min: f64, t_max: f64) -> bool {
        self.extinction.exact().occluded(ray, t_min, t_max)
    }

    /// `to` is the source end, `from` the receiving end (module documentation).
    fn transmittance(&self, from: DVec3, to: DVec3) -> f64 {
        self.trace(from, to).transmittance
    }

    fn transmittance_onto(&self, from: DVec3, to: DVec3, receiver: usize) -> f64 {
        self.trace_at(from, to, self.feature_size_on(receiver))
            .transmittance
    }

    fn transmittance_past(
        &self,
        from: DVec3,
        to: DVec3,
        _transparent: &dyn Fn(usize) -> bool,
    ) -> f64 {
        self.transmittance(from, to)
    }

    fn transmittance_past_onto(
        &self,
        from: DVec3,
        to: DVec3,
        receiver: usize,
        _transparent: &dyn Fn(usize) -> bool,
    ) -> f64 {
        self.transmittance_onto(from, to, receiver)
    }

    fn name(&self) -> &'static str {
        "multires"
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square(centre: DVec3, side: f64) -> Shape {
        let h = side / 2.0;
        Shape::Quad([
            centre + DVec3::new(-h, -h, 0.0),
            centre + DVec3::new(h, -h, 0.0),
            centre + DVec3::new(h, h, 0.0),
            centre + DVec3::new(-h, h, 0.0),
        ])
    }

    #[test]
    fn bsize_of_one_square_is_its_side_within_the_raster_error() {
        // Seen head-on, a square of side a covers a raster of RESOLUTION pixels: it vanishes after
        // RESOLUTION / 2 erosions, and BSIZE is a plus one pixel.
        let a = 0.3;
        let shapes = [square(DVec3::ZERO, a)];
        let b = blocker_size(&shapes, &[0], &shapes[0].bounds(), DVec3::Z);
        let pixel = a / RESOLUTION as f64;
        assert!(
            (b - (a + pixel)).abs() < 1e-12,
            "BSIZE {b} for a square of {a}"
        );
        // Edge-on it covers no pixel centre: nothing blocks, BSIZE is the one pixel of sampling error.
        let edge_on = blocker_size(&shapes, &[0], &shapes[0].bounds(), DVec3::X);
        assert!((edge_on - pixel).abs() < 1e-12, "edge-on BSIZE {edge_on}");
    }

    #[test]
    fn bsize_of_a_checkerboard_is_its_square_not_the_cluster() {
        // 4×4 squares of side a at pitch 2a: shadows and lit gaps of width a, in a cluster 7a wide.
        let a = 0.1;
        let shapes: Vec<Shape> = (0..16)
            .map(|k| {
                square(
                    DVec3::new((k % 4) as f64 * 2.0 * a, (k / 4) as f64 * 2.0 * a, 0.0),
                    a,
                )
            })
            .collect();
        let all: Vec<u32> = (0..16).collect();
        let bounds = shapes.iter().fold(Aabb::EMPTY, |b, s| b.union(&s.bounds()));
        let b = blocker_size(&shapes, &all, &bounds, DVec3::Z);
        // The largest region is the lit crossing of two gaps: 4-neighbour Expansions fill it as a diamond
        // of L¹ radius a (centre to the four square corners), so it counts as 2a. Raster: pixel centres
        // sit up to half a pixel inside each corner on both axes (+2 pixels) and BSIZE adds one pixel; the
        // corners themselves fall anywhere on the 7a / RESOLUTION grid (±2 pixels).
        let pixel = 7.0 * a / RESOLUTION as f64;
        assert!(
            (b - (2.0 * a + 3.0 * pixel)).abs() <= 2.0 * pixel,
            "BSIZE {b} for squares and gaps of {a}"
        );
        // A lone square in the same bounds leaves a free region as wide as the cluster (the paper's
        // Expansions fill free space from the blockers).
        let lone = blocker_size(&shapes, &[0], &bounds, DVec3::Z);
        assert!(lone > 5.0 * a, "free space around a lone square: {lone}");
    }
}
