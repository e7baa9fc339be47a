//! Our bounding volume hierarchy: surface-area-heuristic build over the input polygons (quads kept as
//! quads), collapsed into an 8-wide tree with quantised child boxes for fast occlusion and closest-hit
//! traversal.
//!
//! The binary SAH tree is built first (binned, subtrees in parallel, leaves of at most four triangles),
//! then collapsed into 8-wide nodes of two cache lines each, the binary nodes to keep chosen by dynamic
//! programming for the least total node area (see [`Cuts`]). A node stores its children's boxes as 8-bit coordinates on a per-node grid
//! (`origin + q * scale`, `scale` a power of two, rounded outward), half the bytes per child of `f32`
//! boxes: on large scenes traversal waits on node fetches from memory, so bytes per child and levels per
//! ray are what count. One visit tests the eight boxes in one SIMD pass: AVX2 + FMA where the CPU has them
//! (detected at run time; the same kernels compiled with AVX-512 enabled where it has that too, see
//! `avx_kernels!`), a portable lane loop elsewhere; all give the same answers. A leaf is one block
//! of up to four triangles (a quad fills two lanes), stored coordinate by coordinate with the first
//! vertex in `f64` and the edge vectors in `f32` (three cache lines), so that one AVX2 pass of `f64`
//! lanes filters all four (see [`Block`], [`classify`]).
//!
//! Precision split: node boxes and traversal are `f32`, but every box is padded by a margin far above
//! `f32` rounding, so culling is conservative; the primitive tests are the exact double precision test of
//! the exhaustive reference ([`super::brute_force::ray_triangle`]) on the same numbers (rebuilt from the
//! `f64` vertices), behind a filter on the `f32` edges with a rigorous error bound, which drops a lane
//! only where the reference surely misses and ends an occlusion query only where it surely hits.
//! Answers are therefore the reference's answers (up to ties between polygons at the same `t`), including its
//! robustness: a segment between two points on scene polygons is not blocked by those polygons, nor by
//! polygons coplanar with its start.

use super::brute_force::{ray_triangle as triangle, IN_PLANE};
use super::{Hit, Visibility};
use crate::geometry::{DVec3, Ray, Shape};
use crate::memory::vec_on_huge_pages;
use glam::{Vec3A, Vec4};
use std::mem::MaybeUninit;

/// Triangle lanes of a leaf block: one 256-bit register of `f64`. Every leaf is one block: a set of
/// primitives that fits is always a leaf (its four lanes are filtered in one pass, about the cost of a
/// node visit), a larger one is always split.
const LANES: usize = 4;
/// Polygon index of an unused lane (its edges are zero, so the filter rejects it).
const EMPTY_LANE: u32 = u32::MAX;
/// Centroid bins per axis of the binned SAH split. 32 rather than 16: office3's occlusion rays 2–3%
/// faster (79.6–81.8% of Embree's rate instead of 76.1–79.2%), the 2.7M-triangle room and the
/// classroom unchanged within their noise, builds 3% longer; 64 was slower again (BENCHMARKS.md, "SAH
/// with 32 bins").
const BINS: usize = 32;
/// Subtrees larger than this are built in parallel.
const PARALLEL_THRESHOLD: usize = 4096;
/// Beyond this depth splits are median splits. With at most 2^27 primitives (see [`LEAF_FLAG`]) the
/// binary depth is then below `MAX_SAH_DEPTH + 28`, the wide depth is no larger, and a traversal pushes
/// at most `WIDTH - 1` entries per level: the bound behind [`STACK_SIZE`].
const MAX_SAH_DEPTH: usize = 64;
const STACK_SIZE: usize = (WIDTH - 1) * (MAX_SAH_DEPTH + 28) + 1;
/// Box padding relative to the largest coordinate magnitude of the scene: 2^-18, far above the `f32`
/// rounding of coordinates (2^-24) and of slab distances (a few 2^-24 of the scene's size, see
/// [`Simd::slab`]), and it also gives flat boxes a thickness.
const RELATIVE_PAD: f64 = 1.0 / 262_144.0;
/// High bit of a binary child reference marks a leaf; the low bits are then the first primitive.
const LEAF_FLAG: u32 = 1 << 31;
/// Most primitives a tree can hold (first-primitive indices must fit below [`LEAF_FLAG`], vertex
/// offsets below [`SECOND_TRIANGLE`], and polygon indices below [`EMPTY_LANE`]).
const MAX_PRIMS: usize = 1 << 27;
/// High bit of a lane's vertex offset marks a quad.
const QUAD_FLAG: u32 = 1 << 31;
/// Next bit marks a quad's second triangle, `v0 v2 v3`.
const SECOND_TRIANGLE: u32 = 1 << 30;
/// The vertex offset under the flags (below `4 * MAX_PRIMS`).
const VERTEX_OFFSET: u32 = SECOND_TRIANGLE - 1;
/// Children per wide node.
const WIDTH: usize = 8;
/// Grid steps of a node's quantised boxes: coordinates `0..=QUANT_MAX`.
const QUANT_MAX: u8 = 255;

/// 8-wide node (128 bytes, two cache lines): a grid per axis, the children's boxes on it, then where each
/// child lives.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
struct Node {
    /// Grid origin per axis: the lower corner of the union of the children's boxes.
    origin: [f32; 3],
    /// Grid step per axis, a power of two, so that `origin + q * scale` is exact in `f64`.
    scale: [f32; 3],
    /// `[min x, max x, min y, max y, min z, max z]` on the grid, lane `k` for child `k`: minima rounded
    /// down, maxima up, so each box contains its child's (zero for unused slots).
    planes: [[u8; WIDTH]; 6],
    /// Wide node index of an interior child, or the block of a leaf child.
    child: [u32; WIDTH],
    /// Bit `k` set when slot `k` holds a child.
    valid: u8,
    /// Bit `k` set when child `k` is a leaf.
    leaves: u8,
}

const _: () = assert!(std::mem::size_of::<Node>() == 128);

/// A leaf's hot data: up to [`LANES`] triangles, coordinate by coordinate (`a[axis][lane]`), with the
/// reference test's first vertex `a` in `f64` (so `s = origin - a` is the reference's own) and its edges
/// `e1 = v1 - v0`, `e2 = v2 - v0` rounded to `f32` (a quad fills two adjacent lanes, `v0 v1 v2` then
/// `v0 v2 v3`, as `brute_force::ray_polygon` splits it). 192 bytes, three cache lines, against 320
/// for `f64` edges: on large scenes traversal waits on memory, and this is what every visited leaf
/// costs. The filter [`classify`] reads only this; the exact test of the lanes it keeps rebuilds the
/// `f64` edges bit for bit from [`Bvh::vertices`] (see [`LaneRefs`]).
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
struct Block {
    a: [[f64; LANES]; 3],
    /// `f32` edges, each component within `2^-24` of the `f64` edge relative to itself, or NaN in every
    /// component when that cannot hold (outside `f32`'s normal range): the filter then keeps the lane.
    e1: [[f32; LANES]; 3],
    e2: [[f32; LANES]; 3],
}

const _: () = assert!(std::mem::size_of::<Block>() == 192);

/// A leaf's cold data, read only for the lanes the filter keeps and for the closest hit's record.
#[derive(Clone, Copy, Debug)]
struct LaneRefs {
    /// Offset of the lane's polygon's first vertex in `Bvh::vertices`, with [`QUAD_FLAG`] for quads
    /// and [`SECOND_TRIANGLE`] for a quad's `v0 v2 v3` lane.
    vertex: [u32; LANES],
    /// The lane's polygon, or [`EMPTY_LANE`].
    polygon: [u32; LANES],
}

impl Block {
    /// Unused lanes are all zero: their determinant is 0, which the filter rejects.
    const EMPTY: Block = Block {
        a: [[0.0; LANES]; 3],
        e1: [[0.0; LANES]; 3],
        e2: [[0.0; LANES]; 3],
    };

    /// Stores the triangle `(a, e1, e2)` in lane `k`.
    fn set_lane(&mut self, k: usize, a: DVec3, e1: DVec3, e2: DVec3) {
        let (f1, f2) = (to_f32_edge(e1), to_f32_edge(e2));
        for axis in 0..3 {
            self.a[axis][k] = a[axis];
            self.e1[axis][k] = f1[axis];
            self.e2[axis][k] = f2[axis];
        }
    }

    /// Lane `k`'s `(a, e1, e2)` as the filter sees them (edges widened from `f32`).
    #[inline(always)]
    fn lane(&self, k: usize) -> (DVec3, DVec3, DVec3) {
        let get =
            |v: &[[f32; LANES]; 3]| DVec3::new(v[0][k].into(), v[1][k].into(), v[2][k].into());
        let a = DVec3::new(self.a[0][k], self.a[1][k], self.a[2][k]);
        (a, get(&self.e1), get(&self.e2))
    }
}

/// `e` rounded to `f32` when every component keeps its relative error within `2^-24` (the filter's
/// error model), else NaN (a lane the filter always keeps).
fn to_f32_edge(e: DVec3) -> [f32; 3] {
    let rounded = e.as_vec3().to_array();
    let faithful = (0..3).all(|i| {
        let r = f64::from(rounded[i]);
        r.is_finite() && (r - e[i]).abs() <= e[i].abs() / 16_777_216.0
    });
    if faithful {
        rounded
    } else {
        [f32::NAN; 3]
    }
}

/// `-2^-60`: `x < -2^-60 |det|` means that `x / det` is negative and far from underflowing to `-0`
/// (one comparison with a bound computed once per lane, where testing the sign and the size of `x`
/// cost five operations).
const NEG_TINY_RATIO: f64 = -1.0 / 1_152_921_504_606_846_976.0;
/// Bound on the filter's error relative to the absolute sum of the products it adds up (see
/// [`classify`]): `2^-22`, twice the `2^-23` that the `f32` edges and the `f64` roundings can cause.
const FILTER_ERROR: f64 = 1.0 / 4_194_304.0;
/// [`FILTER_ERROR`] of six products, each bounded by the product of its factors' largest components.
const FILTER_ERROR_6: f64 = 6.0 * FILTER_ERROR;
/// Absolute term of the filter's error bounds: far above the underflow of a few `f64` products
/// (`2^-1074` each) and far below the reference's `1e-300` determinant cutoff.
const FILTER_FLOOR: f64 = 1e-305;

/// The ray as the leaf filter reads it: the reference's origin and direction, their absolute values,
/// and the parameter range.
#[derive(Clone, Copy, Debug)]
struct FilterRay {
    origin: DVec3,
    direction: DVec3,
    direction_abs: DVec3,
    /// [`FILTER_ERROR_6`] times the direction's largest component: the part of the error bounds of
    /// `U` and `W` that the ray gives.
    error_d: f64,
    /// The origin's largest component: with the lane's `|s|`, the reference's in-plane `scale`.
    origin_max: f64,
    /// Rejection below `t_min`: `t_min`, or `-inf` when negative (the test assumes `t_min >= 0`).
    reject_lo: f64,
    /// Rejection above `t_max`: `t_max`, or `inf` when negative (likewise).
    reject_hi: f64,
    /// Sure hits above `max(t_min, 0)`.
    sure_lo: f64,
    /// Sure hits below `t_max`.
    sure_hi: f64,
}

impl FilterRay {
    fn new(ray: &Ray, t_min: f64, t_max: f64) -> FilterRay {
        let mut f = FilterRay {
            origin: ray.origin,
            direction: ray.direction,
            direction_abs: ray.direction.abs(),
            error_d: FILTER_ERROR_6 * largest(ray.direction.abs()),
            origin_max: ray.origin.abs().max_element(),
            reject_lo: if t_min >= 0.0 {
                t_min
            } else {
                f64::NEG_INFINITY
            },
            reject_hi: 0.0,
            sure_lo: t_min.max(0.0),
            sure_hi: 0.0,
        };
        f.set_t_max(t_max);
        f
    }

    #[inline(always)]
    fn set_t_max(&mut self, t_max: f64) {
        self.reject_hi = if t_max >= 0.0 { t_max } else { f64::INFINITY };
        self.sure_hi = t_max;
    }
}

/// What the filter knows of a block's lanes, bit `k` for lane `k`: the lanes the reference test may
/// accept, and among them those it surely accepts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Lanes {
    maybe: u32,
    sure: u32,
}
/// `x . y` as the filter computes it: a product and two fused multiply-adds (one rounding fewer
/// per term, and two operations fewer than a product per term and two sums; the SIMD filters
/// compute the same fused operations, so they agree bit for bit). The filter is a chain of such
/// operations on every leaf a ray visits, and fusing them took 5-10% of its time off office3's
/// rays. Where the CPU has no FMA only the portable kernel runs, and `mul_add` is a library call
/// there: correctly rounded, as the error model needs, only slower.
#[inline(always)]
fn dot(x: DVec3, y: DVec3) -> f64 {
    x.z.mul_add(y.z, x.y.mul_add(y.y, x.x * y.x))
}

/// `x x y` as the filter computes it: per component a product and a fused multiply-subtract.
#[inline(always)]
fn cross(x: DVec3, y: DVec3) -> DVec3 {
    DVec3::new(
        x.y.mul_add(y.z, -(y.y * x.z)),
        x.z.mul_add(y.x, -(y.z * x.x)),
        x.x.mul_add(y.y, -(y.x * x.y)),
    )
}

/// `x x y` with every term's sign made positive, for `x, y >= 0`: the absolute sums of the cross
/// product's terms (each a product and a fused multiply-add).
#[inline(always)]
fn abs_cross(x: DVec3, y: DVec3) -> DVec3 {
    DVec3::new(
        x.y.mul_add(y.z, y.y * x.z),
        x.z.mul_add(y.x, y.z * x.x),
        x.x.mul_add(y.y, y.x * x.y),
    )
}

/// The largest component of `v` as `_mm256_max_pd(x, _mm256_max_pd(y, z))` computes it (`max(a, b)`
/// is `if a > b { a } else { b }`), so that the scalar and SIMD filters agree bit for bit.
#[inline(always)]
fn largest(v: DVec3) -> f64 {
    let max = |a: f64, b: f64| if a > b { a } else { b };
    max(v.x, max(v.y, v.z))
}

/// Whether [`triangle`] (`ray_triangle(ray, s, e1, e2, t_min, t_max)`, with the `f64` edges) can
/// return a hit, and whether it surely does, computed from the `f32` edges `e1`, `e2` (widened; `s =
/// origin - a` and the ray are the reference's own), as `(maybe, sure)`: it answers `maybe = false`
/// only where the reference surely rejects, and `sure = true` only where it surely accepts (so an
/// occlusion query needs no exact test, nor its vertex fetch, for a ray blocked well inside a
/// triangle). The portable filter, and the reference for the AVX2 one, which computes the same
/// operations.
///
/// Error model: the determinant `det = e1 . (d x e2)` and the numerators `U = s . (d x e2)`,
/// `W = d . (s x e1)`, `T = e2 . (s x e1)` are sums of six products of three inputs. The `f32` edges
/// change each product by at most `2 * 2^-24` of itself (one rounding per edge, relative `2^-24`),
/// and both `f64` evaluations add a few `2^-53` (the filter's fewer: it fuses its products and
/// sums), so each computed value is within about `2^-23` of the products' absolute sum of the
/// reference's value. `det` and `T` are triple products of `e1`,
/// `e2` and `d` or `s`, so their sums are `|d| . n` and `|s| . n` with one `n = |e1| x+ |e2|`
/// ([`abs_cross`]). For `U` and `W` a cheaper bound serves: each product is at most the product of
/// its factors' largest components (`m_d`, `m_s`, `m_1`, `m_2` for `d`, `s`, `e1`, `e2`), so their
/// sums are at most `6 m_s m_d m_2` and `6 m_d m_s m_1` (looser, by a factor that only matters within
/// about `1e-6` of a barycentric edge; the exact sums would cost two more cross products and dot
/// products). `det` and `T` keep the exact sums: they decide the `t` range, tightly needed on the
/// axis-aligned polygons of buildings, where the rays' own and end polygons sit within `1e-5` of it
/// (the largest-component bound there kept more lanes and measured slower).
/// The bounds `err = FILTER_ERROR * sum + FILTER_FLOOR` are twice the error, which also covers the
/// roundings of the bounds themselves and of the comparisons below (each `2^-53` of terms no larger
/// than the sum) and of the reference's divisions (`2^-52`). Given `|det| > err_det`, the
/// determinant's sign is the reference's, and (sign-normalised, `a = |det|`):
/// - `U + err_U < -2^-60 a` means `u < 0` (and `U / det` does not underflow to `-0`),
///   `U - err_U > a + err_det` means `u > 1`; likewise `w < 0` and `u + w > 1`;
/// - `T + err_T < t_min (a - err_det)` means `t < t_min` (for `t_min >= 0`), `T - err_T > t_max (a +
///   err_det)` means `t > t_max` (for `t_max >= 0`): a ray leaving a surface is rejected by its own
///   polygon here, without the exact test's fetch of its vertices;
/// - `a + err_det < 1e-300` is the reference's degenerate cutoff (and rejects unused, all-zero lanes).
///
/// It is a sure hit when the opposite bounds hold: `a - err_det >= 1e-300`, `U - err_U > 0`,
/// `W - err_W > 0`, `(U + err_U) + (W + err_W) < a - err_det`, `t` within `(max(t_min, 0), t_max)`
/// by the same margins, and the origin surely off the plane: `|T| - err_T > 2 IN_PLANE scale L`,
/// with `L`, the sum of `n`'s components, at least `|e1 x e2|`.
///
/// NaN anywhere (a lane whose edges do not fit `f32`) keeps the lane, never surely.
#[inline(always)]
fn classify(ray: &FilterRay, a: DVec3, e1: DVec3, e2: DVec3) -> (bool, bool) {
    let (d, s) = (ray.direction, ray.origin - a);
    let p = cross(d, e2);
    let det = dot(e1, p);
    let abs = det.abs();
    let (s_abs, e1_abs, e2_abs) = (s.abs(), e1.abs(), e2.abs());
    let n = abs_cross(e1_abs, e2_abs);
    let err_det = FILTER_ERROR.mul_add(dot(ray.direction_abs, n), FILTER_FLOOR);
    if abs + err_det < 1e-300 {
        return (false, false);
    }
    // The determinant's sign is surely the reference's (false for NaN).
    let signed = abs > err_det;
    if !signed {
        return (true, false);
    }
    let sign = if det < 0.0 { -1.0 } else { 1.0 };
    let far = abs + err_det;
    let tiny = abs * NEG_TINY_RATIO;
    let (m_s, m_1, m_2) = (largest(s_abs), largest(e1_abs), largest(e2_abs));
    let u = sign * dot(s, p);
    let err_u = ray.error_d.mul_add(m_s * m_2, FILTER_FLOOR);
    let (u_lo, u_hi) = (u - err_u, u + err_u);
    if u_hi < tiny || u_lo > far {
        return (false, false);
    }
    let q = cross(s, e1);
    let w = sign * dot(d, q);
    let err_w = ray.error_d.mul_add(m_s * m_1, FILTER_FLOOR);
    let (w_lo, w_hi) = (w - err_w, w + err_w);
    if w_hi < tiny || u_lo + w_lo > far {
        return (false, false);
    }
    let t = sign * dot(e2, q);
    let err_t = FILTER_ERROR.mul_add(dot(s_abs, n), FILTER_FLOOR);
    let (t_lo, t_hi) = (t - err_t, t + err_t);
    let near = abs - err_det;
    if t_hi < ray.reject_lo * near || t_lo > ray.reject_hi * far {
        return (false, false);
    }
    // `max` as `_mm256_max_pd` computes it.
    let scale = if ray.origin_max > m_s {
        ray.origin_max
    } else {
        m_s
    };
    let off_plane = (2.0 * IN_PLANE) * scale * ((n.x + n.y) + n.z);
    let sure = near >= 1e-300
        && u_lo > 0.0
        && w_lo > 0.0
        && u_hi + w_hi < near
        && t_lo > ray.sure_lo * far
        && t_hi < ray.sure_hi * near
        && t.abs() - err_t > off_plane;
    (true, sure)
}

/// SAH bounding volume hierarchy over the scene's polygons.
pub struct Bvh {
    /// Wide nodes, the root first; none when the whole scene is one leaf (block 0).
    nodes: Vec<Node>,
    /// Root box in double precision (padded), used to clip rays before going to `f32`.
    root_min: DVec3,
    root_max: DVec3,
    /// The leaves, in the order traversal meets them.
    blocks: Vec<Block>,
    /// Per block, where its lanes' exact triangles and polygons are.
    lanes: Vec<LaneRefs>,
    /// The polygons' vertices in leaf order, for the parameters and side of the final closest hit.
    vertices: Vec<DVec3>,
    /// The SIMD kernels this CPU runs.
    kernel: Kernel,
}

#[derive(Clone, Copy)]
struct BuildPrim {
    min: Vec3A,
    max: Vec3A,
    centroid: Vec3A,
    /// Triangle lanes it fills (1, or 2 for a quad): its SAH cost and its share of a leaf block.
    cost: f32,
    index: u32,
}

#[derive(Clone, Copy)]
struct Bounds {
    min: Vec3A,
    max: Vec3A,
}

impl Bounds {
    const EMPTY: Bounds = Bounds {
        min: Vec3A::splat(f32::INFINITY),
        max: Vec3A::splat(f32::NEG_INFINITY),
    };

    fn grow(&mut self, min: Vec3A, max: Vec3A) {
        self.min = self.min.min(min);
        self.max = self.max.max(max);
    }

    fn area(&self) -> f32 {
        let e = (self.max - self.min).max(Vec3A::ZERO);
        e.x * e.y + e.y * e.z + e.z * e.x
    }
}

/// The build records of the shapes: boxes padded by [`RELATIVE_PAD`] of the scene's largest coordinate.
fn build_prims(shapes: &[Shape]) -> Vec<BuildPrim> {
    use rayon::prelude::*;
    let max_abs = shapes
        .par_iter()
        .map(|s| {
            s.vertices()
                .iter()
                .map(|v| v.abs().max_element())
                .fold(0.0, f64::max)
        })
        .reduce(|| 0.0, f64::max);
    let pad = (max_abs * RELATIVE_PAD).max(f64::MIN_POSITIVE * 1e10);
    shapes
        .par_iter()
        .enumerate()
        .map(|(index, shape)| {
            let b = shape.bounds();
            let min = (b.min - pad).as_vec3a();
            let max = (b.max + pad).as_vec3a();
            BuildPrim {
                min,
                max,
                centroid: (min + max) * 0.5,
                cost: if shape.vertex_count() == 4 { 2.0 } else { 1.0 },
                index: index as u32,
            }
        })
        .collect()
}

fn bounds_of(prims: &[BuildPrim]) -> Bounds {
    let mut b = Bounds::EMPTY;
    for p in prims {
        b.grow(p.min, p.max);
    }
    b
}

impl Bvh {
    /// Builds the hierarchy (binned SAH, subtrees in parallel; the tree does not depend on thread count).
    pub fn new(shapes: &[Shape]) -> Bvh {
        assert!(
            shapes.len() < MAX_PRIMS,
            "too many polygons for a BVH: {}",
            shapes.len()
        );
        let mut prims = build_prims(shapes);
        let bounds = bounds_of(&prims);
        let mut leaves = Leaves {
            shapes,
            blocks: Vec::new(),
            lanes: Vec::new(),
            vertices: Vec::new(),
        };
        let mut nodes = Vec::new();
        if is_leaf(&prims) {
            if !prims.is_empty() {
                leaves.push(&prims);
            }
        } else {
            let binary = build(&mut prims, 0, 0);
            // The wide tree's leaves are the binary tree's, each of its polygons' vertices stored
            // once: room for all of it, on huge pages when large, before the collapse writes it.
            let leaf_count = (binary.iter().flat_map(|n| n.child))
                .filter(|c| c & LEAF_FLAG != 0)
                .count();
            let vertex_count = shapes.iter().map(Shape::vertex_count).sum();
            leaves.blocks = vec_on_huge_pages(leaf_count);
            leaves.lanes = vec_on_huge_pages(leaf_count);
            leaves.vertices = vec_on_huge_pages(vertex_count);
            nodes = vec_on_huge_pages(binary.len() / 2 + 1);
            let cuts = Cuts::new(&binary);
            collapse(&binary, &cuts, 0, &prims, &mut nodes, &mut leaves);
        }
        // The BVH lives as long as the solve: no room reserved while building stays unused.
        nodes.shrink_to_fit();
        leaves.blocks.shrink_to_fit();
        leaves.lanes.shrink_to_fit();
        leaves.vertices.shrink_to_fit();
        Bvh {
            nodes,
            root_min: bounds.min.as_dvec3(),
            root_max: bounds.max.as_dvec3(),
            blocks: leaves.blocks,
            lanes: leaves.lanes,
            vertices: leaves.vertices,
            kernel: Kernel::detect(),
        }
    }

    /// Number of (8-wide) interior nodes (for statistics).
    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// The shape of lane `k` of block `index`, rebuilt bit-exactly from the stored vertices.
    fn shape(&self, index: usize, k: usize) -> Shape {
        let tagged = self.lanes[index].vertex[k];
        let o = (tagged & VERTEX_OFFSET) as usize;
        let v = &self.vertices;
        if tagged & QUAD_FLAG != 0 {
            Shape::Quad([v[o], v[o + 1], v[o + 2], v[o + 3]])
        } else {
            Shape::Triangle([v[o], v[o + 1], v[o + 2]])
        }
    }

    /// Lane `k` of block `index` as the reference test's `(a, e1, e2)`: `v0` and the `f64` edges, computed
    /// from the vertices as the reference computes them (so bit for bit its numbers).
    #[inline(always)]
    fn exact_lane(&self, index: usize, k: usize) -> (DVec3, DVec3, DVec3) {
        let tag = self.lanes[index].vertex[k];
        let o = (tag & VERTEX_OFFSET) as usize;
        let i = o + 1 + usize::from(tag & SECOND_TRIANGLE != 0);
        let v = &self.vertices;
        (v[o], v[i] - v[o], v[i + 1] - v[o])
    }

    /// Ray parameter in `(t_min, t_max)` of lane `k` of block `index`, with its barycentric (u, v): the
    /// reference test on the same numbers as `brute_force::ray_polygon`.
    #[inline(always)]
    fn hit(
        &self,
        index: usize,
        k: usize,
        ray: &Ray,
        t_min: f64,
        t_max: f64,
    ) -> Option<(f64, f64, f64)> {
        let (a, e1, e2) = self.exact_lane(index, k);
        triangle(ray, ray.origin - a, e1, e2, t_min, t_max)
    }

    /// Whether any lane of block `index` blocks the ray in `(t_min, t_max)`: the filter `K` first, the
    /// exact test for the lanes it keeps. For occlusion a quad's two triangles are independent (the
    /// reference's quad hits iff either does). Polygons `transparent` accepts block nothing.
    #[inline(always)]
    fn block_occludes<K: Simd>(
        &self,
        index: usize,
        ray: &Ray,
        filter: &FilterRay,
        (t_min, t_max): (f64, f64),
        transparent: &impl Fn(usize) -> bool,
    ) -> bool {
        let lanes = K::filter(filter, &self.blocks[index]);
        let opaque = |k: usize| !transparent(self.lanes[index].polygon[k] as usize);
        let mut sure = lanes.sure;
        while sure != 0 {
            let k = sure.trailing_zeros() as usize;
            sure &= sure - 1;
            if opaque(k) {
                return true;
            }
        }
        let mut lanes = lanes.maybe;
        while lanes != 0 {
            let k = lanes.trailing_zeros() as usize;
            lanes &= lanes - 1;
            if self.hit(index, k, ray, t_min, t_max).is_some() && opaque(k) {
                return true;
            }
        }
        false
    }

    /// Clips the ray to the root box in double precision and prepares the `f32` traversal ray. Traversal
    /// parameters are `t' = (t - t0) * scale`.
    #[inline(always)]
    fn setup(&self, ray: &Ray, t_min: f64, t_max: f64) -> Option<TravRay> {
        if t_max.is_nan() || t_min.is_nan() || t_max <= t_min || self.blocks.is_empty() {
            return None;
        }
        let (mut lo, mut hi) = (t_min, t_max);
        for axis in 0..3 {
            let (o, d) = (ray.origin[axis], ray.direction[axis]);
            let (bmin, bmax) = (self.root_min[axis], self.root_max[axis]);
            if d == 0.0 {
                if o < bmin || o > bmax {
                    return None;
                }
            } else {
                let inv = 1.0 / d;
                let (a, b) = ((bmin - o) * inv, (bmax - o) * inv);
                lo = lo.max(a.min(b));
                hi = hi.min(a.max(b));
            }
        }
        if lo.is_nan() || hi.is_nan() || lo > hi {
            return None;
        }
        let scale = ray.direction.abs().max_element();
        let dir = ray.direction / scale;
        let origin = (ray.origin + lo * ray.direction).as_vec3a();
        // Direction components below 2^-32 (of the largest, 1) are raised to it: over the clipped ray
        // (`t' <= ` twice the scene's largest coordinate `M`) that moves the ray by under 2^-30 M, far
        // inside the box padding, and keeps every slab product finite for coordinates below 2^90.
        let tiny = 1.0 / 4_294_967_296.0;
        let inv = dir.map(|d| 1.0 / if d.abs() < tiny { tiny.copysign(d) } else { d });
        let inv = inv.as_vec3a();
        let mut trav = TravRay {
            origin: origin.to_array(),
            inv: inv.to_array(),
            // A negative direction enters a slab at its maximum.
            negative: [0, 1, 2].map(|a| usize::from(inv[a] < 0.0)),
            t_far: 0.0,
            t0: lo,
            scale,
        };
        trav.set_far(hi);
        Some(trav)
    }

    /// Any-hit traversal with kernels `K`, past the polygons `transparent` accepts (monomorphised:
    /// plain occlusion passes `|_| false`, which compiles away).
    #[inline(always)]
    fn occluded_with<K: Simd>(
        &self,
        ray: &Ray,
        t_min: f64,
        t_max: f64,
        transparent: &impl Fn(usize) -> bool,
    ) -> bool {
        let Some(trav) = self.setup(ray, t_min, t_max) else {
            return false;
        };
        let filter = FilterRay::new(ray, t_min, t_max);
        if self.nodes.is_empty() {
            return self.block_occludes::<K>(0, ray, &filter, (t_min, t_max), transparent);
        }
        let mut stack = Stack::new();
        let mut current = 0u32;
        loop {
            let node = &self.nodes[current as usize];
            let slabs = K::slab(&trav, node);
            let mask = slabs.hit;
            let leaves = mask & node.leaves as u32;
            // The next node is the interior child whose box holds the longest stretch of the ray, the
            // others pushed (their entry parameters are not needed: any blocker ends the ray). All are
            // fetched now, so that the fetches overlap each other and the leaf tests. One child, the
            // common case on small scenes, takes no loop (their branches mispredict).
            let inner = mask & !leaves;
            let mut next = None;
            if inner != 0 {
                let k = if inner & (inner - 1) == 0 {
                    inner.trailing_zeros() as usize
                } else {
                    let k = K::longest(inner, &slabs);
                    let mut others = inner & !(1 << k);
                    while others != 0 {
                        let c = node.child[others.trailing_zeros() as usize];
                        others &= others - 1;
                        prefetch(self.nodes.as_ptr().wrapping_add(c as usize));
                        stack.push(c, 0.0);
                    }
                    k
                };
                let c = node.child[k];
                prefetch(self.nodes.as_ptr().wrapping_add(c as usize));
                next = Some(c);
            }
            // Leaves before descending: a blocker ends the ray. Each test starts the fetch of the next
            // leaf's block, so that on large scenes the fetches overlap the tests (a separate loop that
            // fetched every block first cost 2-3% of the time on office3, which sits in cache).
            let mut bits = leaves;
            while bits != 0 {
                let k = bits.trailing_zeros() as usize;
                bits &= bits - 1;
                if bits != 0 {
                    let next = node.child[bits.trailing_zeros() as usize] as usize;
                    prefetch(self.blocks.as_ptr().wrapping_add(next));
                }
                let block = node.child[k] as usize;
                if self.block_occludes::<K>(block, ray, &filter, (t_min, t_max), transparent) {
                    return true;
                }
            }
            current = match next.or_else(|| stack.pop().map(|(c, _)| c)) {
                Some(c) => c,
                None => return false,
            };
        }
    }

    /// Closest-hit traversal with kernels `K`.
    #[inline(always)]
    fn intersect_with<K: Simd>(&self, ray: &Ray, t_min: f64, t_max: f64) -> Option<Hit> {
        let mut trav = self.setup(ray, t_min, t_max)?;
        // Closest lane so far: (t, block, lane).
        let mut best: Option<(f64, usize, usize)> = None;
        let mut limit = t_max;
        let mut filter = FilterRay::new(ray, t_min, t_max);
        // Lanes in order, each tested up to the nearest hit so far: a quad's second triangle replaces
        // its first only when strictly nearer, as in the reference.
        let mut leaf = |index: u32, trav: &mut TravRay| {
            let index = index as usize;
            let mut lanes = K::filter(&filter, &self.blocks[index]).maybe;
            while lanes != 0 {
                let k = lanes.trailing_zeros() as usize;
                lanes &= lanes - 1;
                if let Some((t, _, _)) = self.hit(index, k, ray, t_min, limit) {
                    best = Some((t, index, k));
                    limit = t;
                    filter.set_t_max(t);
                    trav.set_far(t);
                }
            }
        };
        if self.nodes.is_empty() {
            leaf(0, &mut trav);
        } else {
            let mut stack = Stack::new();
            let mut current = 0u32;
            loop {
                let node = &self.nodes[current as usize];
                let Slabs {
                    hit: mask, enter, ..
                } = K::slab(&trav, node);
                // Hit children sorted by entry distance (insertion sort of at most eight).
                let mut order = [(0f32, 0usize); WIDTH];
                let mut n = 0;
                let mut bits = mask;
                while bits != 0 {
                    let k = bits.trailing_zeros() as usize;
                    bits &= bits - 1;
                    let mut j = n;
                    while j > 0 && order[j - 1].0 > enter[k] {
                        order[j] = order[j - 1];
                        j -= 1;
                    }
                    order[j] = (enter[k], k);
                    n += 1;
                }
                // Every child is fetched before the first leaf test, the interior ones while the
                // leaves are tested; a leaf's lane references too, which its exact tests read (a
                // closest hit needs one per hit lane).
                for &(_, k) in &order[..n] {
                    let c = node.child[k] as usize;
                    if node.leaves & (1 << k) == 0 {
                        prefetch(self.nodes.as_ptr().wrapping_add(c));
                    } else {
                        prefetch(self.blocks.as_ptr().wrapping_add(c));
                        prefetch(self.lanes.as_ptr().wrapping_add(c));
                    }
                }
                // Leaves first, nearer first, so that their hits cull the interior children.
                for &(t, k) in &order[..n] {
                    if node.leaves & (1 << k) != 0 && t <= trav.t_far {
                        leaf(node.child[k], &mut trav);
                    }
                }
                // Interior children: far ones pushed first, the nearest visited next.
                let mut next = None;
                for &(t, k) in order[..n].iter().rev() {
                    if node.leaves & (1 << k) == 0 && t <= trav.t_far {
                        if let Some((c, tc)) = next {
                            stack.push(c, tc);
                        }
                        next = Some((node.child[k], t));
                    }
                }
                if let Some((c, _)) = next {
                    current = c;
                    continue;
                }
                // Pop the nearest pending child still within reach.
                loop {
                    match stack.pop() {
                        Some((c, t)) if t <= trav.t_far => {
                            current = c;
                            break;
                        }
                        Some(_) => {}
                        None => return self.finish(ray, best),
                    }
                }
            }
        }
        self.finish(ray, best)
    }

    /// The hit record of the closest lane found.
    fn finish(&self, ray: &Ray, best: Option<(f64, usize, usize)>) -> Option<Hit> {
        let (t, index, k) = best?;
        Some(Hit {
            t,
            polygon: self.lanes[index].polygon[k] as usize,
            front: ray.direction.dot(self.shape(index, k).vector_area()) < 0.0,
        })
    }
}

/// Asks the CPU to start loading the item at `item` into cache (a hint: no effect on results; nothing
/// where the target has no prefetch instruction). Traversal waits on memory on large scenes, and this
/// lets the fetches of nodes and leaves that will be visited overlap. The pointer is never read, so
/// callers form it with `wrapping_add` instead of a bounds-checked index.
#[inline(always)]
fn prefetch<T>(item: *const T) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        let size = std::mem::size_of::<T>();
        // Every cache line the item touches: a fixed count of whole lines for the 64-byte aligned nodes
        // and blocks (the loop unrolls), else from the line of its start to the line of its end.
        let (start, lines) = if std::mem::align_of::<T>() >= 64 {
            (item.cast::<i8>(), size.div_ceil(64))
        } else {
            let offset = item as usize & 63;
            (
                item.cast::<i8>().wrapping_sub(offset),
                (offset + size).div_ceil(64),
            )
        };
        for line in 0..lines {
            // SAFETY: prefetching is only a hint, which never faults, and SSE is part of x86_64.
            unsafe { _mm_prefetch::<_MM_HINT_T0>(start.wrapping_add(64 * line)) };
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = item;
}

/// Traversal stack of (node, entry parameter): a fixed array, left uninitialised so that each ray does
/// not pay for clearing it.
struct Stack {
    entries: [MaybeUninit<(u32, f32)>; STACK_SIZE],
    top: usize,
}

impl Stack {
    #[inline(always)]
    fn new() -> Stack {
        Stack {
            entries: [const { MaybeUninit::uninit() }; STACK_SIZE],
            top: 0,
        }
    }

    /// Pushes an entry; the depth bound of the tree (see [`STACK_SIZE`]) keeps `top` in range, and the
    /// indexing checks it anyway.
    #[inline(always)]
    fn push(&mut self, node: u32, t: f32) {
        self.entries[self.top] = MaybeUninit::new((node, t));
        self.top += 1;
    }

    #[inline(always)]
    fn pop(&mut self) -> Option<(u32, f32)> {
        if self.top == 0 {
            return None;
        }
        self.top -= 1;
        // SAFETY: every entry below `top` was written by `push`.
        Some(unsafe { self.entries[self.top].assume_init() })
    }
}

/// The ray in `f32` traversal coordinates: origin moved to the root box entry, direction scaled to unit
/// maximum component.
struct TravRay {
    origin: [f32; 3],
    inv: [f32; 3],
    /// Per axis 1 where the direction is negative (the ray enters the slab at its maximum), else 0.
    negative: [usize; 3],
    /// Conservative far end of the interval, in traversal parameters.
    t_far: f32,
    t0: f64,
    scale: f64,
}

impl TravRay {
    /// Sets the far end from a ray parameter `t`, rounded up with margin so no box reaching `t` is culled.
    #[inline(always)]
    fn set_far(&mut self, t: f64) {
        let t = ((t - self.t0) * self.scale) as f32;
        self.t_far = t * (1.0 + 1e-5) + 1e-30;
    }

    /// The grid coordinates of `node`'s children where the ray enters the slabs of `axis`, and where it
    /// leaves them (the index, masked, is provably in range: no bounds check).
    #[inline(always)]
    fn planes<'a>(&self, node: &'a Node, axis: usize) -> (&'a [u8; WIDTH], &'a [u8; WIDTH]) {
        let near = self.negative[axis] & 1;
        (
            &node.planes[2 * axis + near],
            &node.planes[2 * axis + (near ^ 1)],
        )
    }

    /// Per axis the slab parameter of grid coordinate `q` of `node` is `q * a + b`: `(a, b)`.
    #[inline(always)]
    fn grid(&self, node: &Node, axis: usize) -> (f32, f32) {
        let inv = self.inv[axis];
        (
            node.scale[axis] * inv,
            (node.origin[axis] - self.origin[axis]) * inv,
        )
    }
}

/// The SIMD kernels of a traversal: the slab tests of a node's children and the hit filter of a leaf's
/// lanes.
trait Simd {
    /// Slab tests of a node's eight children against `[0, t_far]`.
    ///
    /// Error bound: a slab parameter is `(origin + q scale - o) inv`, computed as `q (scale inv) +
    /// (origin - o) inv` with at most four roundings of terms below `4 M |inv|` (`M` the scene's largest
    /// coordinate), so it is off by under `2^-20 M |inv|`, while the box padding ([`RELATIVE_PAD`]) moves
    /// every slab by `2^-18 M |inv|`: a box the exact ray meets is never culled.
    fn slab(ray: &TravRay, node: &Node) -> Slabs;

    /// Of the children in `mask` (hit ones, at least one), the one whose box holds the longest stretch
    /// of the ray, `exit - enter` (the first of equals): the occlusion traversal visits it next. Any
    /// blocker ends an occlusion ray, and a box that holds more of the ray is likelier to hold one: on
    /// a 2.7M-triangle room of boxes, where nearly every ray is blocked, this cut the nodes visited per
    /// ray from 9.9 to 7.5 and the leaf blocks from 1.8 to 1.2 against the first child in slot order
    /// (on office3 from 3.2 to 3.1 nodes). Visiting the nearest first had measured slower on both.
    fn longest(mask: u32, slabs: &Slabs) -> usize;

    /// [`classify`] of each lane of `block`, computed with exactly its operations, so bit-identical and
    /// conservative in every kernel.
    fn filter(ray: &FilterRay, block: &Block) -> Lanes;
}

/// What the slab tests of a node's children give.
struct Slabs {
    /// Bit `k` set when child `k` exists and the ray meets its box within `[0, t_far]`.
    hit: u32,
    /// Lane `k`: the traversal parameter where the ray enters child `k`'s box (or 0)...
    enter: [f32; WIDTH],
    /// ... and where it leaves it (or `t_far`).
    exit: [f32; WIDTH],
}

/// Lane loops in plain Rust (any CPU).
struct Portable;

impl Simd for Portable {
    #[inline(always)]
    fn slab(ray: &TravRay, node: &Node) -> Slabs {
        let mut enter = [0f32; WIDTH];
        let mut exit = [ray.t_far; WIDTH];
        for axis in 0..3 {
            let (a, b) = ray.grid(node, axis);
            let (near, far) = ray.planes(node, axis);
            for k in 0..WIDTH {
                enter[k] = enter[k].max(f32::from(near[k]) * a + b);
                exit[k] = exit[k].min(f32::from(far[k]) * a + b);
            }
        }
        let mut mask = 0;
        for k in 0..WIDTH {
            mask |= u32::from(enter[k] <= exit[k]) << k;
        }
        Slabs {
            hit: mask & u32::from(node.valid),
            enter,
            exit,
        }
    }

    #[inline(always)]
    fn longest(mask: u32, slabs: &Slabs) -> usize {
        let mut bits = mask;
        let (mut best, mut length) = (mask.trailing_zeros() as usize, f32::NEG_INFINITY);
        while bits != 0 {
            let k = bits.trailing_zeros() as usize;
            bits &= bits - 1;
            let l = slabs.exit[k] - slabs.enter[k];
            if l > length {
                (best, length) = (k, l);
            }
        }
        best
    }

    #[inline(always)]
    fn filter(ray: &FilterRay, block: &Block) -> Lanes {
        let mut lanes = Lanes { maybe: 0, sure: 0 };
        for k in 0..LANES {
            let (a, e1, e2) = block.lane(k);
            let (maybe, sure) = classify(ray, a, e1, e2);
            lanes.maybe |= u32::from(maybe) << k;
            lanes.sure |= u32::from(sure) << k;
        }
        lanes
    }
}

/// Defines an AVX2 kernel type `$kernel` ([`Simd`] on the eight slab lanes in one 256-bit register and
/// four `f64` filter lanes in another) and its traversals `$occluded` and `$intersect`, all compiled with
/// the target features `$features` (which include AVX2 and FMA): one source, compiled once for AVX2 and
/// once more with AVX-512 enabled, where the same code has 32 vector registers instead of 16 (the leaf
/// filter no longer spills) and compares into mask registers.
macro_rules! avx_kernels {
    (
        $features:literal,
        $kernel:ident,
        $filter:ident,
        $slab:ident,
        $longest:ident,
        $occluded:ident,
        $intersect:ident
    ) => {
        #[cfg(target_arch = "x86_64")]
        struct $kernel;

        #[cfg(target_arch = "x86_64")]
        impl Simd for $kernel {
            #[inline(always)]
            fn slab(ray: &TravRay, node: &Node) -> Slabs {
                // SAFETY: this kernel only runs on CPUs with `$features`: inside the traversals
                // `Kernel::detect` chooses for them, and in tests that check the CPU first.
                unsafe { $slab(ray, node) }
            }

            #[inline(always)]
            fn longest(mask: u32, slabs: &Slabs) -> usize {
                // SAFETY: as above.
                unsafe { $longest(mask, slabs) }
            }

            #[inline(always)]
            fn filter(ray: &FilterRay, block: &Block) -> Lanes {
                // SAFETY: as above.
                unsafe { $filter(ray, block) }
            }
        }

        /// [`classify`] on four lanes of `f64` (the `f32` edges widened on load): the same products,
        /// fused multiply-adds, sums and comparisons in the same order, so every lane's answer is
        /// bit for bit the scalar one.
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = $features)]
        #[inline]
        fn $filter(ray: &FilterRay, block: &Block) -> Lanes {
            use std::arch::x86_64::*;
            type V = [__m256d; 3];
            // SAFETY: each row is four `f64` (32-byte aligned) or four `f32` (16-byte aligned) at an aligned
            // offset of the 64-byte aligned block.
            let load =
                |rows: &[[f64; LANES]; 3]| rows.map(|r| unsafe { _mm256_load_pd(r.as_ptr()) });
            let widen = |rows: &[[f32; LANES]; 3]| {
                rows.map(|r| _mm256_cvtps_pd(unsafe { _mm_load_ps(r.as_ptr()) }))
            };
            let splat = |v: DVec3| v.to_array().map(|x| _mm256_set1_pd(x));
            let (mul, add, sub, max) = (_mm256_mul_pd, _mm256_add_pd, _mm256_sub_pd, _mm256_max_pd);
            let (and, or) = (_mm256_and_pd, _mm256_or_pd);
            let (gt, lt) = (_mm256_cmp_pd::<_CMP_GT_OQ>, _mm256_cmp_pd::<_CMP_LT_OQ>);
            let (fmadd, fmsub) = (_mm256_fmadd_pd, _mm256_fmsub_pd);
            // The scalar `cross`, `abs_cross` and `dot`, term for term.
            let cross = |x: V, y: V| {
                [
                    fmsub(x[1], y[2], mul(y[1], x[2])),
                    fmsub(x[2], y[0], mul(y[2], x[0])),
                    fmsub(x[0], y[1], mul(y[0], x[1])),
                ]
            };
            let abs_cross = |x: V, y: V| {
                [
                    fmadd(x[1], y[2], mul(y[1], x[2])),
                    fmadd(x[2], y[0], mul(y[2], x[0])),
                    fmadd(x[0], y[1], mul(y[0], x[1])),
                ]
            };
            let dot = |x: V, y: V| fmadd(x[2], y[2], fmadd(x[1], y[1], mul(x[0], y[0])));
            let sign_bit = _mm256_set1_pd(-0.0);
            let abs = |x: __m256d| _mm256_andnot_pd(sign_bit, x);
            // `max_pd(x, y)` is `if x > y { x } else { y }`, as in `largest`, NaN included.
            let largest = |x: V| max(x[0], max(x[1], x[2]));
            let (d, o, d_abs) = (
                splat(ray.direction),
                splat(ray.origin),
                splat(ray.direction_abs),
            );
            let a = load(&block.a);
            let s = [0, 1, 2].map(|i| sub(o[i], a[i]));
            let (e1, e2) = (widen(&block.e1), widen(&block.e2));
            let p = cross(d, e2);
            let det = dot(e1, p);
            let det_abs = abs(det);
            let (s_abs, e1_abs, e2_abs) = (s.map(abs), e1.map(abs), e2.map(abs));
            let n = abs_cross(e1_abs, e2_abs);
            let (error, floor) = (_mm256_set1_pd(FILTER_ERROR), _mm256_set1_pd(FILTER_FLOOR));
            let err_det = fmadd(error, dot(d_abs, n), floor);
            let degenerate = lt(add(det_abs, err_det), _mm256_set1_pd(1e-300));
            let signed = gt(det_abs, err_det);
            // `sign * x` with `sign = ±1` is `x` with the determinant's sign bit flipped in.
            let sign = and(det, sign_bit);
            let (far, near) = (add(det_abs, err_det), sub(det_abs, err_det));
            let zero = _mm256_setzero_pd();
            let tiny = mul(det_abs, _mm256_set1_pd(NEG_TINY_RATIO));
            let u = _mm256_xor_pd(dot(s, p), sign);
            let (m_s, m_1, m_2) = (largest(s_abs), largest(e1_abs), largest(e2_abs));
            let error_d = _mm256_set1_pd(ray.error_d);
            let err_u = fmadd(error_d, mul(m_s, m_2), floor);
            let (u_lo, u_hi) = (sub(u, err_u), add(u, err_u));
            let q = cross(s, e1);
            let w = _mm256_xor_pd(dot(d, q), sign);
            let err_w = fmadd(error_d, mul(m_s, m_1), floor);
            let (w_lo, w_hi) = (sub(w, err_w), add(w, err_w));
            let t = _mm256_xor_pd(dot(e2, q), sign);
            let err_t = fmadd(error, dot(s_abs, n), floor);
            let (t_lo, t_hi) = (sub(t, err_t), add(t, err_t));
            let splat1 = _mm256_set1_pd;
            let reject = or(
                or(
                    or(lt(u_hi, tiny), gt(u_lo, far)),
                    or(lt(w_hi, tiny), gt(add(u_lo, w_lo), far)),
                ),
                or(
                    lt(t_hi, mul(splat1(ray.reject_lo), near)),
                    gt(t_lo, mul(splat1(ray.reject_hi), far)),
                ),
            );
            // Kept: not degenerate, and the sign uncertain or nothing rejects. Most blocks a ray visits
            // keep no lane: they skip the sure-hit tests.
            let dropped = or(degenerate, and(signed, reject));
            let maybe = !(_mm256_movemask_pd(dropped) as u32) & ((1 << LANES) - 1);
            if maybe == 0 {
                return Lanes { maybe, sure: 0 };
            }
            let scale = max(splat1(ray.origin_max), m_s);
            let off_plane = mul(
                mul(splat1(2.0 * IN_PLANE), scale),
                add(add(n[0], n[1]), n[2]),
            );
            let sure = and(
                and(
                    and(
                        _mm256_cmp_pd::<_CMP_GE_OQ>(near, splat1(1e-300)),
                        gt(u_lo, zero),
                    ),
                    and(gt(w_lo, zero), lt(add(u_hi, w_hi), near)),
                ),
                and(
                    and(
                        gt(t_lo, mul(splat1(ray.sure_lo), far)),
                        lt(t_hi, mul(splat1(ray.sure_hi), near)),
                    ),
                    gt(sub(abs(t), err_t), off_plane),
                ),
            );
            // Sure: signed, kept and sure.
            let sure = _mm256_movemask_pd(_mm256_andnot_pd(reject, and(signed, sure))) as u32;
            Lanes {
                maybe,
                sure: sure & maybe,
            }
        }

        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = $features)]
        #[inline]
        fn $slab(ray: &TravRay, node: &Node) -> Slabs {
            use std::arch::x86_64::*;
            // Eight grid coordinates as `f32` lanes.
            let lanes = |plane: &[u8; WIDTH]| {
                // SAFETY: `plane` is eight readable bytes; the load has no alignment requirement.
                let bytes = unsafe { _mm_loadl_epi64(plane.as_ptr().cast()) };
                _mm256_cvtepi32_ps(_mm256_cvtepu8_epi32(bytes))
            };
            let mut enter = _mm256_setzero_ps();
            let mut exit = _mm256_set1_ps(ray.t_far);
            for axis in 0..3 {
                let (a, b) = ray.grid(node, axis);
                let (a, b) = (_mm256_set1_ps(a), _mm256_set1_ps(b));
                let (near, far) = ray.planes(node, axis);
                let near = _mm256_fmadd_ps(lanes(near), a, b);
                let far = _mm256_fmadd_ps(lanes(far), a, b);
                enter = _mm256_max_ps(enter, near);
                exit = _mm256_min_ps(exit, far);
            }
            let hit = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(enter, exit)) as u32;
            let store = |v: __m256| {
                let mut lanes = [0f32; WIDTH];
                // SAFETY: `lanes` holds eight `f32`; the store has no alignment requirement.
                unsafe { _mm256_storeu_ps(lanes.as_mut_ptr(), v) };
                lanes
            };
            Slabs {
                hit: hit & u32::from(node.valid),
                enter: store(enter),
                exit: store(exit),
            }
        }

        /// The lengths `exit - enter` on eight lanes, those outside `mask` at -inf, their maximum
        /// spread to every lane by three swaps and maxima, and the first lane equal to it (without the
        /// scalar loop's branches, which mispredict).
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = $features)]
        #[inline]
        fn $longest(mask: u32, slabs: &Slabs) -> usize {
            use std::arch::x86_64::*;
            // SAFETY: each array is eight readable `f32`; the load has no alignment requirement.
            let load = |v: &[f32; WIDTH]| unsafe { _mm256_loadu_ps(v.as_ptr()) };
            let length = _mm256_sub_ps(load(&slabs.exit), load(&slabs.enter));
            let lane_bits = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
            let bits = _mm256_and_si256(_mm256_set1_epi32(mask as i32), lane_bits);
            let outside = _mm256_cmpeq_epi32(bits, _mm256_setzero_si256());
            let length = _mm256_blendv_ps(
                length,
                _mm256_set1_ps(f32::NEG_INFINITY),
                _mm256_castsi256_ps(outside),
            );
            let max = _mm256_max_ps(length, _mm256_permute2f128_ps::<1>(length, length));
            let max = _mm256_max_ps(max, _mm256_permute_ps::<0b01_00_11_10>(max));
            let max = _mm256_max_ps(max, _mm256_permute_ps::<0b10_11_00_01>(max));
            let equal = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_EQ_OQ>(length, max)) as u32 & mask;
            // No lane equals the maximum only where a length is NaN: then any child will do.
            (if equal != 0 { equal } else { mask }).trailing_zeros() as usize
        }

        /// The traversals compiled with the kernel's features (the leaf tests too: they stay
        /// bit-identical, as Rust never fuses a multiply and an add on its own).
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = $features)]
        fn $occluded(
            bvh: &Bvh,
            ray: &Ray,
            t_min: f64,
            t_max: f64,
            transparent: &impl Fn(usize) -> bool,
        ) -> bool {
            bvh.occluded_with::<$kernel>(ray, t_min, t_max, transparent)
        }

        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = $features)]
        fn $intersect(bvh: &Bvh, ray: &Ray, t_min: f64, t_max: f64) -> Option<Hit> {
            bvh.intersect_with::<$kernel>(ray, t_min, t_max)
        }
    };
}

avx_kernels!(
    "avx2,fma",
    Avx2,
    filter_avx2,
    slab_avx2,
    longest_avx2,
    occluded_avx2,
    intersect_avx2
);
avx_kernels!(
    "avx2,fma,avx512f,avx512vl",
    Avx512,
    filter_avx512,
    slab_avx512,
    longest_avx512,
    occluded_avx512,
    intersect_avx512
);

/// Which traversals run, chosen once per tree from the CPU's features.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kernel {
    Portable,
    /// The [`Avx2`] kernels.
    #[cfg(target_arch = "x86_64")]
    Avx2,
    /// The same kernels compiled with AVX-512 F and VL enabled too (see [`avx_kernels`]).
    #[cfg(target_arch = "x86_64")]
    Avx512,
}

impl Kernel {
    /// The fastest kernel this CPU runs.
    fn detect() -> Kernel {
        *Kernel::available().last().unwrap_or(&Kernel::Portable)
    }

    /// The kernels this CPU runs, slowest first.
    fn available() -> Vec<Kernel> {
        #[allow(unused_mut)]
        let mut kernels = vec![Kernel::Portable];
        #[cfg(target_arch = "x86_64")]
        if is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma") {
            kernels.push(Kernel::Avx2);
            if is_x86_feature_detected!("avx512f") && is_x86_feature_detected!("avx512vl") {
                kernels.push(Kernel::Avx512);
            }
        }
        kernels
    }
}

/// A child of a binary node: interior node index (count 0) or leaf (`LEAF_FLAG | first`, count), with
/// its box.
#[derive(Clone, Copy)]
struct ChildRef {
    child: u32,
    count: u32,
    bounds: Bounds,
}

fn binary_children(node: &BinNode) -> [ChildRef; 2] {
    [0, 1].map(|side| ChildRef {
        child: node.child[side],
        count: node.count[side],
        bounds: Bounds {
            min: Vec3A::from_array([0, 1, 2].map(|a| node.bounds[a][side])),
            max: Vec3A::from_array([0, 1, 2].map(|a| node.bounds[a][side + 2])),
        },
    })
}

/// The leaf blocks and the vertices they point to, as the collapse writes them.
struct Leaves<'a> {
    shapes: &'a [Shape],
    blocks: Vec<Block>,
    lanes: Vec<LaneRefs>,
    vertices: Vec<DVec3>,
}

impl Leaves<'_> {
    /// Appends the block of `prims` (at most [`LANES`] lanes) and returns its index.
    fn push(&mut self, prims: &[BuildPrim]) -> u32 {
        let mut block = Block::EMPTY;
        let mut refs = LaneRefs {
            vertex: [0; LANES],
            polygon: [EMPTY_LANE; LANES],
        };
        let mut k = 0;
        for p in prims {
            let v = self.shapes[p.index as usize].vertices();
            let offset = self.vertices.len() as u32;
            self.vertices.extend_from_slice(v);
            let tag = if v.len() == 4 {
                offset | QUAD_FLAG
            } else {
                offset
            };
            // `v0 v1 v2`, and `v0 v2 v3` for a quad.
            for i in 1..v.len() - 1 {
                block.set_lane(k, v[0], v[i] - v[0], v[i + 1] - v[0]);
                refs.vertex[k] = if i == 2 { tag | SECOND_TRIANGLE } else { tag };
                refs.polygon[k] = p.index;
                k += 1;
            }
        }
        self.blocks.push(block);
        self.lanes.push(refs);
        (self.blocks.len() - 1) as u32
    }
}

/// Which binary nodes become wide nodes, chosen by dynamic programming over the binary tree (Ylitie,
/// Karras and Laine 2017, "Efficient incoherent ray traversal on GPUs through compressed wide BVHs",
/// §3.1). The leaves are the binary tree's, so the part of the SAH cost that the choice changes is the
/// sum of the wide nodes' surface areas (each visit costs about the same, full or not), minimised exactly;
/// greedily expanding the widest child until eight left nodes half full.
struct Cuts {
    /// Per binary node, slot `i - 1`: the least area sum of its subtree cut into at most `i` roots
    /// (wide nodes or leaves).
    cost: Vec<[f32; WIDTH]>,
    /// Per binary node, slot `i - 1` for `i >= 2`: how many of the `i` roots its left child's subtree
    /// gives, or 0 when the node itself is best kept as one root (a wide node). Slot 0: the left child's
    /// share of the node's eight children when it is a wide node.
    left: Vec<[u8; WIDTH]>,
}

impl Cuts {
    /// Bottom up: binary children come after their parents.
    fn new(binary: &[BinNode]) -> Cuts {
        let mut cuts = Cuts {
            cost: vec![[0.0; WIDTH]; binary.len()],
            left: vec![[0; WIDTH]; binary.len()],
        };
        for index in (0..binary.len()).rev() {
            let [l, r] = binary_children(&binary[index]);
            let child = |c: &ChildRef, i: usize| {
                if c.count > 0 {
                    0.0
                } else {
                    cuts.cost[c.child as usize][i - 1]
                }
            };
            // Slot `j`: the best share of at most `j` roots between the two children.
            let mut split = [(f32::INFINITY, 0u8); WIDTH + 1];
            for (j, best) in split.iter_mut().enumerate().skip(2) {
                for k in 1..j {
                    let c = child(&l, k) + child(&r, j - k);
                    if c < best.0 {
                        *best = (c, k as u8);
                    }
                }
            }
            let mut union = l.bounds;
            union.grow(r.bounds.min, r.bounds.max);
            let node = union.area() + split[WIDTH].0;
            let (cost, left) = (&mut cuts.cost[index], &mut cuts.left[index]);
            (cost[0], left[0]) = (node, split[WIDTH].1);
            for i in 2..=WIDTH {
                (cost[i - 1], left[i - 1]) = if split[i].0 < node {
                    split[i]
                } else {
                    (node, 0)
                };
            }
        }
        cuts
    }

    /// Appends the roots of `c`'s subtree cut into at most `i`.
    fn roots(&self, binary: &[BinNode], c: ChildRef, i: usize, out: &mut Vec<ChildRef>) {
        let k = if c.count > 0 || i == 1 {
            0
        } else {
            usize::from(self.left[c.child as usize][i - 1])
        };
        if k == 0 {
            out.push(c);
        } else {
            let [l, r] = binary_children(&binary[c.child as usize]);
            self.roots(binary, l, k, out);
            self.roots(binary, r, i - k, out);
        }
    }
}

/// Turns the binary subtree at `index` into 8-wide nodes appended to `out` (parent before children) as
/// `cuts` says, and its leaves into blocks of `leaves` (a node's leaves next to each other), and returns
/// its wide index.
fn collapse(
    binary: &[BinNode],
    cuts: &Cuts,
    index: u32,
    prims: &[BuildPrim],
    out: &mut Vec<Node>,
    leaves: &mut Leaves,
) -> u32 {
    let [l, r] = binary_children(&binary[index as usize]);
    let share = usize::from(cuts.left[index as usize][0]);
    let mut refs = Vec::with_capacity(WIDTH);
    cuts.roots(binary, l, share, &mut refs);
    cuts.roots(binary, r, WIDTH - share, &mut refs);
    let wide = out.len();
    let mut node = quantised(&refs);
    out.push(node);
    for (k, r) in refs.iter().enumerate() {
        if r.count > 0 {
            let first = (r.child & !LEAF_FLAG) as usize;
            node.leaves |= 1 << k;
            node.child[k] = leaves.push(&prims[first..first + r.count as usize]);
        }
    }
    for (k, r) in refs.iter().enumerate() {
        if r.count == 0 {
            node.child[k] = collapse(binary, cuts, r.child, prims, out, leaves);
        }
    }
    out[wide] = node;
    wide as u32
}

/// A node with the children's boxes on its grid (children still to be filled in): the grid starts at
/// the union's lower corner, its step is the smallest power of two that spans the union in
/// [`QUANT_MAX`] steps, and each box is rounded outward to grid points (checked in `f64`, whose rounding is
/// far below the box padding).
fn quantised(refs: &[ChildRef]) -> Node {
    let mut union = Bounds::EMPTY;
    for r in refs {
        union.grow(r.bounds.min, r.bounds.max);
    }
    let mut node = Node {
        origin: union.min.to_array(),
        scale: [0.0; 3],
        planes: [[0; WIDTH]; 6],
        child: [0; WIDTH],
        valid: ((1u32 << refs.len()) - 1) as u8,
        leaves: 0,
    };
    let top = f64::from(QUANT_MAX);
    for axis in 0..3 {
        let (lo, hi) = (f64::from(union.min[axis]), f64::from(union.max[axis]));
        // Smallest normal `f32` power of two with `lo + 255 scale >= hi`.
        let mut scale = f64::from(f32::MIN_POSITIVE);
        let needed = (hi - lo) / top;
        if needed > scale {
            scale = 2f64.powi(needed.log2().ceil() as i32);
        }
        while lo + top * scale < hi {
            scale *= 2.0;
        }
        node.scale[axis] = scale as f32;
        let point = |q: f64| lo + q * scale;
        for (k, r) in refs.iter().enumerate() {
            let (min, max) = (f64::from(r.bounds.min[axis]), f64::from(r.bounds.max[axis]));
            let mut q = ((min - lo) / scale).floor().clamp(0.0, top);
            while q > 0.0 && point(q) > min {
                q -= 1.0;
            }
            node.planes[2 * axis][k] = q as u8;
            let mut q = ((max - lo) / scale).ceil().clamp(0.0, top);
            while q < top && point(q) < max {
                q += 1.0;
            }
            node.planes[2 * axis + 1][k] = q as u8;
        }
    }
    node
}

/// Binary interior node of the SAH build: both children's boxes; per axis the lanes are (min left,
/// min right, max left, max right).
#[derive(Clone, Copy, Debug)]
struct BinNode {
    bounds: [Vec4; 3],
    /// Interior node index, or `LEAF_FLAG | first primitive`.
    child: [u32; 2],
    /// Primitive count of leaf children (0 for interior children).
    count: [u32; 2],
}

/// Builds the subtree over `prims` (which sit at offset `base` of the whole primitive array) and returns
/// its nodes, root first; child indices are local to the returned vector.
fn build(prims: &mut [BuildPrim], base: usize, depth: usize) -> Vec<BinNode> {
    let mut nodes = Vec::new();
    build_into(prims, base, depth, &mut nodes);
    nodes
}

/// Appends the subtree's nodes to `nodes` (root first) and returns the root's index.
fn build_into(prims: &mut [BuildPrim], base: usize, depth: usize, nodes: &mut Vec<BinNode>) -> u32 {
    let index = nodes.len();
    let mid = split(prims, depth);
    nodes.push(BinNode {
        bounds: [Vec4::ZERO; 3],
        child: [0; 2],
        count: [0; 2],
    });
    let (left, right) = prims.split_at_mut(mid);
    let parts = [(left, base), (right, base + mid)];
    let mut children = [(0u32, 0u32); 2];
    let parallel = parts[0].0.len() + parts[1].0.len() > PARALLEL_THRESHOLD;
    if parallel {
        let [(l, lb), (r, rb)] = parts;
        let (lnodes, rnodes) = rayon::join(
            || child_subtree(l, lb, depth + 1),
            || child_subtree(r, rb, depth + 1),
        );
        for (side, sub) in [lnodes, rnodes].into_iter().enumerate() {
            children[side] = match sub {
                Subtree::Leaf(first, count) => (first, count),
                Subtree::Nodes(sub) => {
                    let offset = nodes.len() as u32;
                    nodes.extend(sub.into_iter().map(|mut n| {
                        for c in 0..2 {
                            if n.count[c] == 0 {
                                n.child[c] += offset;
                            }
                        }
                        n
                    }));
                    (offset, 0)
                }
            };
        }
    } else {
        for (side, (part, part_base)) in parts.into_iter().enumerate() {
            children[side] = if is_leaf(part) {
                (LEAF_FLAG | part_base as u32, part.len() as u32)
            } else {
                (build_into(part, part_base, depth + 1, nodes), 0)
            };
        }
    }
    let node = &mut nodes[index];
    let (l, r) = (bounds_of(&prims[..mid]), bounds_of(&prims[mid..]));
    for axis in 0..3 {
        node.bounds[axis] = Vec4::new(l.min[axis], r.min[axis], l.max[axis], r.max[axis]);
    }
    node.child = [children[0].0, children[1].0];
    node.count = [children[0].1, children[1].1];
    index as u32
}

enum Subtree {
    Leaf(u32, u32),
    Nodes(Vec<BinNode>),
}

fn child_subtree(prims: &mut [BuildPrim], base: usize, depth: usize) -> Subtree {
    if is_leaf(prims) {
        Subtree::Leaf(LEAF_FLAG | base as u32, prims.len() as u32)
    } else {
        Subtree::Nodes(build(prims, base, depth))
    }
}

/// Whether the primitives become one leaf: whether they fit one block.
fn is_leaf(prims: &[BuildPrim]) -> bool {
    prims.iter().map(|p| p.cost).sum::<f32>() <= LANES as f32
}

/// Best binned SAH split: (axis, bin boundary). The cost of a side is its box's area times its triangle
/// lanes.
fn best_split(prims: &[BuildPrim]) -> Option<(usize, usize)> {
    let mut cmin = Vec3A::splat(f32::INFINITY);
    let mut cmax = Vec3A::splat(f32::NEG_INFINITY);
    for p in prims {
        cmin = cmin.min(p.centroid);
        cmax = cmax.max(p.centroid);
    }
    let mut best: Option<(usize, usize, f32)> = None;
    for axis in 0..3 {
        let extent = cmax[axis] - cmin[axis];
        if extent.is_nan() || extent <= 0.0 {
            continue;
        }
        let k = BINS as f32 / extent;
        let mut bins = [(Bounds::EMPTY, 0f32); BINS];
        for p in prims {
            let b = bin_of(p.centroid[axis], cmin[axis], k);
            bins[b].0.grow(p.min, p.max);
            bins[b].1 += p.cost;
        }
        // Sweep from the right, then from the left.
        let mut right_cost = [0f32; BINS];
        let mut acc = Bounds::EMPTY;
        let mut acc_cost = 0.0;
        for b in (1..BINS).rev() {
            acc.grow(bins[b].0.min, bins[b].0.max);
            acc_cost += bins[b].1;
            right_cost[b] = if acc_cost > 0.0 {
                acc.area() * acc_cost
            } else {
                f32::INFINITY
            };
        }
        let mut acc = Bounds::EMPTY;
        let mut acc_cost = 0.0;
        for b in 1..BINS {
            acc.grow(bins[b - 1].0.min, bins[b - 1].0.max);
            acc_cost += bins[b - 1].1;
            if acc_cost == 0.0 {
                continue;
            }
            let cost = acc.area() * acc_cost + right_cost[b];
            if cost.is_finite() && best.is_none_or(|(_, _, c)| cost < c) {
                best = Some((axis, b, cost));
            }
        }
    }
    best.map(|(axis, b, _)| (axis, b))
}

#[inline(always)]
fn bin_of(c: f32, min: f32, k: f32) -> usize {
    (((c - min) * k) as usize).min(BINS - 1)
}

/// Reorders `prims` into two non-empty groups and returns the size of the first.
fn split(prims: &mut [BuildPrim], depth: usize) -> usize {
    let n = prims.len();
    if depth < MAX_SAH_DEPTH {
        if let Some((axis, boundary)) = best_split(prims) {
            let (mut cmin, mut cmax) = (f32::INFINITY, f32::NEG_INFINITY);
            for p in prims.iter() {
                cmin = cmin.min(p.centroid[axis]);
                cmax = cmax.max(p.centroid[axis]);
            }
            let k = BINS as f32 / (cmax - cmin);
            let mid = partition(prims, |p| bin_of(p.centroid[axis], cmin, k) < boundary);
            if mid > 0 && mid < n {
                return mid;
            }
        }
    }
    // Coincident centroids or too deep: median split along the longest centroid axis (index order
    // breaks ties, so the result is deterministic).
    let b = bounds_of(prims);
    let axis = (b.max - b.min).max_position();
    let mid = n / 2;
    prims.select_nth_unstable_by(mid, |a, b| {
        a.centroid[axis]
            .total_cmp(&b.centroid[axis])
            .then(a.index.cmp(&b.index))
    });
    mid
}

/// In-place partition; returns the number of elements satisfying `pred`, now at the front.
fn partition(prims: &mut [BuildPrim], pred: impl Fn(&BuildPrim) -> bool) -> usize {
    let mut i = 0;
    let mut j = prims.len();
    loop {
        while i < j && pred(&prims[i]) {
            i += 1;
        }
        while i < j && !pred(&prims[j - 1]) {
            j -= 1;
        }
        if i >= j {
            return i;
        }
        prims.swap(i, j - 1);
        i += 1;
        j -= 1;
    }
}

impl Visibility for Bvh {
    fn intersect(&self, ray: &Ray, t_min: f64, t_max: f64) -> Option<Hit> {
        match self.kernel {
            // SAFETY: `Kernel::Avx2` is only chosen on CPUs with AVX2 and FMA.
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx2 => unsafe { intersect_avx2(self, ray, t_min, t_max) },
            // SAFETY: `Kernel::Avx512` is only chosen on CPUs that also have AVX-512 F and VL.
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx512 => unsafe { intersect_avx512(self, ray, t_min, t_max) },
            Kernel::Portable => self.intersect_with::<Portable>(ray, t_min, t_max),
        }
    }

    fn occluded(&self, ray: &Ray, t_min: f64, t_max: f64) -> bool {
        match self.kernel {
            // SAFETY: as above.
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx2 => unsafe { occluded_avx2(self, ray, t_min, t_max, &|_| false) },
            // SAFETY: as above.
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx512 => unsafe { occluded_avx512(self, ray, t_min, t_max, &|_| false) },
            Kernel::Portable => self.occluded_with::<Portable>(ray, t_min, t_max, &|_| false),
        }
    }

    /// One any-hit traversal that skips transparent hits, rather than a closest hit per polygon passed.
    fn occluded_past(
        &self,
        ray: &Ray,
        t_min: f64,
        t_max: f64,
        transparent: &dyn Fn(usize) -> bool,
    ) -> bool {
        let transparent = &|polygon| transparent(polygon);
        match self.kernel {
            // SAFETY: as above.
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx2 => unsafe { occluded_avx2(self, ray, t_min, t_max, transparent) },
            // SAFETY: as above.
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx512 => unsafe { occluded_avx512(self, ray, t_min, t_max, transparent) },
            Kernel::Portable => self.occluded_with::<Portable>(ray, t_min, t_max, transparent),
        }
    }

    fn name(&self) -> &'static str {
        "bvh"
    }

    /// Nodes, leaf blocks (hot and cold parts) and vertices.
    fn memory_bytes(&self) -> Option<usize> {
        use std::mem::size_of_val;
        Some(
            size_of_val(self.nodes.as_slice())
                + size_of_val(self.blocks.as_slice())
                + size_of_val(self.lanes.as_slice())
                + size_of_val(self.vertices.as_slice()),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::visibility::SEGMENT_EPSILON;
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64Mcg;

    fn random_triangles(count: usize, seed: u64) -> Vec<Shape> {
        let mut rng = Pcg64Mcg::seed_from_u64(seed);
        let mut point = || DVec3::new(rng.random(), rng.random(), rng.random());
        (0..count)
            .map(|_| {
                let c = point();
                Shape::Triangle([c, c + 0.05 * point(), c + 0.05 * point()])
            })
            .collect()
    }

    /// Child `k` of a wide node as (min, max), its grid points in `f64`.
    fn child_box(node: &Node, k: usize) -> (DVec3, DVec3) {
        let plane = |p: usize| {
            DVec3::from_array([0, 1, 2].map(|a| {
                f64::from(node.origin[a])
                    + f64::from(node.planes[2 * a + p][k]) * f64::from(node.scale[a])
            }))
        };
        (plane(0), plane(1))
    }

    /// Visits the wide subtree at `index`, whose ancestors' boxes intersect in `(min, max)`, checking
    /// that each leaf's primitives lie inside its box and all its ancestors' boxes, and that leaves are
    /// non-empty and small; returns the subtree's depth.
    fn check(bvh: &Bvh, index: u32, min: DVec3, max: DVec3, seen: &mut [u32]) -> usize {
        let node = &bvh.nodes[index as usize];
        assert!(
            node.valid.count_ones() >= 2,
            "a wide node has 2 to 8 children"
        );
        assert_eq!(
            node.valid & node.valid.wrapping_add(1),
            0,
            "children fill the first slots"
        );
        assert_eq!(node.leaves & !node.valid, 0);
        assert!(node.scale.iter().all(|s| s.is_normal() && *s > 0.0));
        assert!(
            node.scale.iter().all(|s| s.to_bits() & 0x7f_ffff == 0),
            "powers of two"
        );
        let mut depth = 0;
        for k in 0..WIDTH {
            if node.valid & (1 << k) == 0 {
                continue;
            }
            let (cmin, cmax) = child_box(node, k);
            let (cmin, cmax) = (cmin.max(min), cmax.min(max));
            if node.leaves & (1 << k) != 0 {
                for v in check_block(bvh, node.child[k] as usize, seen) {
                    assert!(
                        v.cmpge(cmin).all() && v.cmple(cmax).all(),
                        "{v} outside box"
                    );
                }
            } else {
                assert!(node.child[k] > index, "children after their parent");
                depth = depth.max(check(bvh, node.child[k], cmin, cmax, seen));
            }
        }
        depth + 1
    }

    /// Counts the polygons of leaf block `index` in `seen` (a quad fills two adjacent lanes), checks that
    /// its lanes are the polygons' triangles (the exact ones bit for bit, the filter's edges their `f32`
    /// roundings), that used lanes come first and unused lanes are zero; returns the polygons' vertices.
    fn check_block(bvh: &Bvh, index: usize, seen: &mut [u32]) -> Vec<DVec3> {
        let (block, polygon) = (&bvh.blocks[index], &bvh.lanes[index].polygon);
        let mut vertices = Vec::new();
        let used = polygon.iter().take_while(|&&p| p != EMPTY_LANE).count();
        assert!(used > 0 && polygon[used..].iter().all(|&p| p == EMPTY_LANE));
        let mut k = 0;
        while k < used {
            let shape = bvh.shape(index, k);
            seen[polygon[k] as usize] += 1;
            let v = shape.vertices();
            for i in 1..v.len() - 1 {
                assert_eq!(polygon[k], polygon[k + 1 - i]);
                let (e1, e2) = (v[i] - v[0], v[i + 1] - v[0]);
                assert_eq!(bvh.exact_lane(index, k), (v[0], e1, e2));
                let f32_edge = |e: DVec3| e.as_vec3().as_dvec3();
                assert_eq!(block.lane(k), (v[0], f32_edge(e1), f32_edge(e2)));
                k += 1;
            }
            vertices.extend_from_slice(v);
        }
        for k in used..LANES {
            assert_eq!(block.lane(k), (DVec3::ZERO, DVec3::ZERO, DVec3::ZERO));
        }
        vertices
    }

    #[test]
    fn every_primitive_is_in_exactly_one_leaf_inside_its_boxes() {
        for count in [1, 3, 5, 9, 100, 5000] {
            let shapes = random_mixed(count, count as u64);
            let bvh = Bvh::new(&shapes);
            let mut seen = vec![0; count];
            if bvh.nodes.is_empty() {
                assert_eq!(bvh.blocks.len(), 1);
                check_block(&bvh, 0, &mut seen);
            } else {
                let inf = DVec3::splat(f64::INFINITY);
                let depth = check(&bvh, 0, -inf, inf, &mut seen);
                assert!((WIDTH - 1) * depth < STACK_SIZE);
            }
            assert!(seen.iter().all(|&n| n == 1));
        }
    }

    #[test]
    fn collapse_fills_wide_nodes() {
        let shapes = random_triangles(20_000, 3);
        let bvh = Bvh::new(&shapes);
        let mut prims = build_prims(&shapes);
        let binary = build(&mut prims, 0, 0);
        // A wide node with n children absorbs n - 1 binary nodes (itself and n - 2 expanded children),
        // so every binary node lands in exactly one wide node.
        let absorbed: usize = bvh
            .nodes
            .iter()
            .map(|n| n.valid.count_ones() as usize - 1)
            .sum();
        assert_eq!(absorbed, binary.len());
        // Random triangles split well: on average at least four children per wide node (a node whose
        // binary subtree has fewer leaves is not full).
        assert!(
            absorbed >= 3 * bvh.nodes.len(),
            "{absorbed} of {}",
            bvh.nodes.len()
        );
    }

    #[test]
    fn median_splits_bound_the_depth() {
        // Identical triangles: no SAH split exists, every split is a median split.
        let t = Shape::Triangle([DVec3::ZERO, DVec3::X, DVec3::Y]);
        let shapes = vec![t; 3000];
        let bvh = Bvh::new(&shapes);
        let mut seen = vec![0; shapes.len()];
        let inf = DVec3::splat(f64::INFINITY);
        let depth = check(&bvh, 0, -inf, inf, &mut seen);
        assert!(
            (WIDTH - 1) * depth < STACK_SIZE && depth <= 12,
            "depth {depth}"
        );
        assert!(seen.iter().all(|&n| n == 1));
        let ray = Ray::new(DVec3::new(0.2, 0.2, 1.0), -DVec3::Z);
        let hit = bvh.intersect(&ray, 0.0, f64::INFINITY).expect("hit");
        assert_eq!(hit.t, 1.0);
        assert!(bvh.occluded(&ray, 0.0, 2.0));
    }

    #[test]
    fn flat_boxes_get_a_thickness() {
        let quad = Shape::Quad([DVec3::ZERO, DVec3::X, DVec3::new(1.0, 1.0, 0.0), DVec3::Y]);
        let shapes: Vec<Shape> = (0..20)
            .map(|k| {
                let offset = DVec3::new(k as f64, 0.0, 0.0);
                match quad {
                    Shape::Quad(v) => Shape::Quad(v.map(|p| p + offset)),
                    Shape::Triangle(_) => unreachable!(),
                }
            })
            .collect();
        let bvh = Bvh::new(&shapes);
        assert!(!bvh.nodes.is_empty());
        for node in &bvh.nodes {
            for k in 0..WIDTH {
                if node.valid & (1 << k) != 0 {
                    let (min, max) = child_box(node, k);
                    assert!(min.z < 0.0 && max.z > 0.0);
                }
            }
        }
    }

    /// Random triangles and quads in the unit cube, some large, most small.
    fn random_mixed(count: usize, seed: u64) -> Vec<Shape> {
        let mut rng = Pcg64Mcg::seed_from_u64(seed);
        (0..count)
            .map(|k| {
                let mut point = || DVec3::new(rng.random(), rng.random(), rng.random());
                let c = point();
                let size = if k % 10 == 0 { 0.3 } else { 0.04 };
                let (u, v) = (size * (point() - 0.5), size * (point() - 0.5));
                if k % 2 == 0 {
                    Shape::Triangle([c, c + u, c + v])
                } else {
                    // A planar parallelogram.
                    Shape::Quad([c, c + u, c + u + v, c + v])
                }
            })
            .collect()
    }

    /// The slab kernels never cull a child box that the exact ray meets: every point of a primitive lies
    /// at least the padding inside its leaf's box and its ancestors' boxes, so a box shrunk by the
    /// padding that the exact (`f64`) ray crosses must be reported hit by every kernel, at an entry
    /// parameter no later than the exact one (and an exit no earlier). Each kernel's choice of the
    /// longest stretch is one of the children it is given, none longer.
    #[test]
    fn slab_kernels_are_conservative() {
        let shapes = random_mixed(3000, 11);
        let bvh = Bvh::new(&shapes);
        // The scene's largest coordinate is at least 1, so its boxes are padded by at least this.
        let pad = RELATIVE_PAD;
        let mut rng = Pcg64Mcg::seed_from_u64(12);
        type SlabFn = fn(&TravRay, &Node) -> Slabs;
        type LongestFn = fn(u32, &Slabs) -> usize;
        let mut kernels: Vec<(SlabFn, LongestFn)> = vec![(Portable::slab, Portable::longest)];
        #[cfg(target_arch = "x86_64")]
        for kernel in Kernel::available() {
            match kernel {
                Kernel::Portable => {}
                Kernel::Avx2 => kernels.push((Avx2::slab, Avx2::longest)),
                Kernel::Avx512 => kernels.push((Avx512::slab, Avx512::longest)),
            }
        }
        let mut met = 0;
        for i in 0..3000 {
            let mut point = || DVec3::new(rng.random(), rng.random(), rng.random()) * 1.2 - 0.1;
            let origin = point();
            let mut direction = point() - origin;
            if i % 4 == 0 {
                // Nearly axis-parallel rays: tiny direction components.
                direction[i % 3] *= 1e-12;
            }
            let ray = Ray::new(origin, direction);
            let Some(trav) = bvh.setup(&ray, 0.0, 1.0) else {
                continue;
            };
            for node in bvh.nodes.iter().step_by(7) {
                for (slab, longest) in &kernels {
                    let slabs = slab(&trav, node);
                    // Every subset of two or more hit children: the longest is one of them, and
                    // no other is longer.
                    let length = |k: usize| slabs.exit[k] - slabs.enter[k];
                    let mut subset = slabs.hit;
                    while subset.count_ones() >= 2 {
                        let k = longest(subset, &slabs);
                        assert!(subset & (1 << k) != 0);
                        assert!(
                            (0..WIDTH).all(|j| subset & (1 << j) == 0 || length(j) <= length(k))
                        );
                        subset &= subset - 1;
                    }
                    let Slabs {
                        hit: mask,
                        enter,
                        exit,
                    } = slabs;
                    for (k, &entry) in enter.iter().enumerate() {
                        if node.valid & (1 << k) == 0 {
                            continue;
                        }
                        let (min, max) = child_box(node, k);
                        let (min, max) = (min + pad, max - pad);
                        let (mut lo, mut hi) = (0.0f64, 1.0f64);
                        for a in 0..3 {
                            let inv = 1.0 / ray.direction[a];
                            let (t0, t1) = ((min[a] - origin[a]) * inv, (max[a] - origin[a]) * inv);
                            lo = lo.max(t0.min(t1));
                            hi = hi.min(t0.max(t1));
                        }
                        if lo <= hi {
                            met += 1;
                            assert!(mask & (1 << k) != 0, "ray {i} culls a box it meets");
                            let exact = |t: f64| ((t - trav.t0) * trav.scale) as f32;
                            assert!(entry <= exact(lo).max(0.0) * (1.0 + 1e-6) + 1e-6);
                            assert!(exit[k] >= exact(hi) * (1.0 - 1e-6) - 1e-6);
                        }
                    }
                }
            }
        }
        assert!(met > 10_000, "rays meet boxes: {met}");
    }

    /// Both kernels give the exhaustive reference's answers, on rays between surface points (the rays
    /// radiosity casts) and on random rays.
    #[test]
    fn kernels_agree_with_brute_force() {
        use crate::visibility::bench::random_segments;
        use crate::visibility::brute_force::BruteForce;
        let shapes = random_mixed(2000, 21);
        let mut bvh = Bvh::new(&shapes);
        let reference = BruteForce::new(shapes.clone());
        let segments = random_segments(&shapes, 3000, 22);
        for kernel in Kernel::available() {
            bvh.kernel = kernel;
            let mut blocked = 0;
            for (i, &(a, b)) in segments.iter().enumerate() {
                let occluded = reference.segment_occluded(a, b);
                blocked += usize::from(occluded);
                assert_eq!(
                    bvh.segment_occluded(a, b),
                    occluded,
                    "{kernel:?} segment {i}"
                );
                let ray = Ray::new(a, b - a);
                let (got, want) = (
                    bvh.intersect(&ray, 1e-5, f64::INFINITY),
                    reference.intersect(&ray, 1e-5, f64::INFINITY),
                );
                match (got, want) {
                    (None, None) => {}
                    // Polygons tied at the same `t` may be reported either way.
                    (Some(g), Some(w)) => assert_eq!(g.t, w.t, "{kernel:?} ray {i}"),
                    _ => panic!("{kernel:?} ray {i}: {got:?} vs {want:?}"),
                }
            }
            assert!(blocked > 300 && blocked < 2700, "{blocked} blocked");
        }
    }

    /// An adversarial triangle `(a, e1, e2)` for the filter, the point its ray aims at and the ray with
    /// its parameter range: targets on the triangle's edges and corners or within a few `f32`
    /// roundings of them, rays nearly in its plane, rays leaving its own surface (the rays radiosity
    /// casts: hit at `t = 0`, below `t_min`), rays ending just before or after it and rays in any
    /// direction, at scales from
    /// `1e-30` to `1e30`, far from the origin, degenerate, or with edges `f32` cannot hold.
    fn filter_case(rng: &mut Pcg64Mcg, i: usize) -> ((DVec3, DVec3, DVec3), DVec3, Ray, f64, f64) {
        let v =
            |rng: &mut Pcg64Mcg| DVec3::new(rng.random(), rng.random(), rng.random()) * 2.0 - 1.0;
        let scale = [1.0, 1e-3, 1e3, 1e-30, 1e30][i % 5];
        let offset = if i.is_multiple_of(3) {
            v(rng) * 1e3
        } else {
            DVec3::ZERO
        };
        let (a, mut e1, mut e2) = ((offset + v(rng)) * scale, v(rng) * scale, v(rng) * scale);
        match i % 13 {
            // Degenerate, nearly degenerate, axis-aligned, and an edge below `f32`'s normal range.
            0 => e1 = e2 * 3.0,
            1 => e1 = e2 * 3.0 + v(rng) * scale * 1e-9,
            2 => (e1, e2) = (DVec3::new(e1.x, 0.0, 0.0), DVec3::new(0.0, e2.y, 0.0)),
            3 => e1.x = 1e-40,
            _ => {}
        }
        // About one `f32` rounding of a barycentric coordinate.
        let f = 6e-8 * f64::from(rng.random_range(-3..=3));
        let (bu, bw) = match (i / 5) % 7 {
            0 => (0.0, 0.5 + f),
            1 => (0.5 + f, 0.5),
            2 => (1.0, f),
            3 => (f, f),
            4 => (f, 1.0 - f),
            5 => (0.3, f),
            _ => (rng.random::<f64>() * 0.5, rng.random::<f64>() * 0.5),
        };
        let target = a + bu * e1 + bw * e2;
        let mut origin = target + v(rng) * 3.0 * scale;
        let (mut t_min, mut t_max) = (0.0, f64::INFINITY);
        let d = match (i / 35) % 6 {
            // From a point of the triangle's own surface to a random point: a radiosity segment.
            0 => {
                origin = target;
                (t_min, t_max) = (SEGMENT_EPSILON, 1.0 - SEGMENT_EPSILON);
                v(rng) * 3.0 * scale
            }
            // Ending just before, at, or just after the triangle.
            1 => {
                t_max = 1.0 + 1e-9 * f64::from(rng.random_range(-2..=2));
                t_min = SEGMENT_EPSILON;
                target - origin
            }
            // Nearly in the plane.
            2 => {
                let (d, n) = (target - origin, e1.cross(e2).normalize_or_zero());
                d - n * n.dot(d) * (1.0 - 1e-12)
            }
            // Negative parameter ranges.
            3 => {
                (t_min, t_max) = (-2.0, -0.5);
                origin - target
            }
            // Any direction: mostly misses.
            4 => v(rng) * scale,
            _ => target - origin,
        };
        if i.is_multiple_of(17) {
            e2.z = 1e39;
        }
        ((a, e1, e2), target, Ray::new(origin, d), t_min, t_max)
    }

    /// The leaf filter on `f32` edges never rejects a triangle that the exact test on the `f64` edges
    /// hits, nor calls a hit sure that the exact test rejects (random and adversarial rays, see
    /// [`filter_case`]); away from the edge cases it decides: it rejects rays in any direction that
    /// miss and the polygon a segment starts on, and calls hits well inside a triangle sure.
    #[test]
    fn hit_filter_is_conservative() {
        let mut rng = Pcg64Mcg::seed_from_u64(5);
        let (mut hits, mut own, mut any, mut inside) = (0, [0; 2], [0; 2], [0; 2]);
        for i in 0..300_000 {
            let ((a, e1, e2), _, ray, t_min, t_max) = filter_case(&mut rng, i);
            let mut block = Block::EMPTY;
            block.set_lane(0, a, e1, e2);
            let reference = triangle(&ray, ray.origin - a, e1, e2, t_min, t_max);
            let lanes = Portable::filter(&FilterRay::new(&ray, t_min, t_max), &block);
            assert!(
                lanes.maybe & 1 != 0 || reference.is_none(),
                "case {i}: {reference:?}"
            );
            assert!(
                lanes.sure & 1 == 0 || reference.is_some(),
                "case {i}: sure miss"
            );
            assert!(lanes.maybe >> 1 == 0, "empty lanes are rejected");
            hits += usize::from(reference.is_some());
            // Well-formed triangles (not degenerate, edges that fit `f32`).
            if i % 13 > 3 && !i.is_multiple_of(17) {
                let rejected = usize::from(lanes.maybe == 0);
                match (i / 35) % 6 {
                    0 => own[rejected] += 1,
                    4 if reference.is_none() => any[rejected] += 1,
                    5 if (i / 5) % 7 == 6 => inside[usize::from(lanes.sure != 0)] += 1,
                    _ => {}
                }
            }
        }
        eprintln!("{hits} hits; own {own:?}, any {any:?} (kept, rejected); inside {inside:?} (not sure, sure)");
        assert!(hits > 50_000, "{hits} hits");
        assert!(own[1] > 10 * own[0], "rays leaving a triangle: {own:?}");
        assert!(any[1] > 10 * any[0], "misses in any direction: {any:?}");
        assert!(
            inside[1] > 10 * inside[0],
            "hits inside a triangle: {inside:?}"
        );
    }

    /// The AVX2 filters (as compiled for AVX2 and for AVX-512) give, lane for lane, the scalar
    /// filter's answer, on the adversarial cases of [`filter_case`] (each lane's triangle moved so
    /// that the ray passes its target) and empty lanes.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn filter_kernels_agree() {
        type FilterFn = fn(&FilterRay, &Block) -> Lanes;
        let mut kernels: Vec<FilterFn> = Vec::new();
        for kernel in Kernel::available() {
            match kernel {
                Kernel::Portable => {}
                Kernel::Avx2 => kernels.push(Avx2::filter),
                Kernel::Avx512 => kernels.push(Avx512::filter),
            }
        }
        let mut rng = Pcg64Mcg::seed_from_u64(6);
        let (mut kept, mut dropped, mut sure) = (0, 0, 0);
        for i in 0..60_000 {
            let (lane, target, ray, t_min, t_max) = filter_case(&mut rng, i);
            let mut block = Block::EMPTY;
            block.set_lane(0, lane.0, lane.1, lane.2);
            for k in 1..LANES - usize::from(i % 3 == 0) {
                let ((a, e1, e2), to, ..) = filter_case(&mut rng, i + k * 7919);
                let a = if k % 2 == 0 { a + (target - to) } else { a };
                block.set_lane(k, a, e1, e2);
            }
            let ray = FilterRay::new(&ray, t_min, t_max);
            let want = Portable::filter(&ray, &block);
            for kernel in &kernels {
                assert_eq!(kernel(&ray, &block), want, "case {i}");
            }
            kept += want.maybe.count_ones();
            dropped += LANES as u32 - want.maybe.count_ones();
            sure += want.sure.count_ones();
        }
        assert!(
            kept > 20_000 && dropped > 20_000 && sure > 1_000,
            "{kept} kept ({sure} surely), {dropped} dropped"
        );
    }

    #[test]
    fn partition_splits_by_predicate() {
        let mut prims: Vec<BuildPrim> = (0..50u32)
            .map(|i| BuildPrim {
                min: Vec3A::ZERO,
                max: Vec3A::ONE,
                centroid: Vec3A::splat((i * 7 % 50) as f32),
                cost: 1.0,
                index: i,
            })
            .collect();
        let mid = partition(&mut prims, |p| p.centroid.x < 20.0);
        assert_eq!(mid, 20);
        assert!(prims[..mid].iter().all(|p| p.centroid.x < 20.0));
        assert!(prims[mid..].iter().all(|p| p.centroid.x >= 20.0));
    }
}
