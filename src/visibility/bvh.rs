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
//! (detected at run time), a portable lane loop elsewhere; both give the same answers. A leaf is one block
//! of up to four triangles (a quad fills two lanes), stored coordinate by coordinate with their edge
//! vectors precomputed, so that one AVX2 pass of `f64` lanes filters all four (see [`Block`]).
//!
//! Precision split: node boxes and traversal are `f32`, but every box is padded by a margin far above
//! `f32` rounding, so culling is conservative; the primitive tests are the exact double precision test of
//! the exhaustive reference ([`super::brute_force::ray_triangle`]) on the same numbers, behind a filter
//! that computes the reference's own determinant and numerators (bit-identical in every lane). Answers are
//! therefore the reference's answers (up to ties between polygons at the same `t`), including its
//! robustness: a segment between two points on scene polygons is not blocked by those polygons, nor by
//! polygons coplanar with its start.

use super::brute_force::ray_triangle as triangle;
use super::{Hit, Visibility};
use crate::geometry::{DVec2, DVec3, Ray, Shape};
use glam::{Vec3A, Vec4};
use std::mem::MaybeUninit;

/// Triangle lanes of a leaf block: one 256-bit register of `f64`. Every leaf is one block: a set of
/// primitives that fits is always a leaf (its four lanes are filtered in one pass, about the cost of a
/// node visit), a larger one is always split.
const LANES: usize = 4;
/// Polygon index of an unused lane (its edges are zero, so the filter rejects it).
const EMPTY_LANE: u32 = u32::MAX;
const BINS: usize = 16;
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
/// offsets below [`QUAD_FLAG`], and polygon indices below [`EMPTY_LANE`]).
const MAX_PRIMS: usize = 1 << 27;
/// High bit of a primitive's vertex offset marks a quad.
const QUAD_FLAG: u32 = 1 << 31;
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

/// A leaf: up to [`LANES`] triangles, coordinate by coordinate (`a[axis][lane]`), with the reference
/// test's inputs precomputed (`e1 = v1 - v0`, `e2 = v2 - v0`; a quad fills two adjacent lanes, `v0 v1 v2`
/// then `v0 v2 v3`, as `brute_force::ray_polygon` splits it), so that the test runs on bit-identical
/// numbers without gathering vertices, and four lanes load as one register per coordinate. 320 bytes:
/// 72 per triangle lane, 8 for which polygon it belongs to.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
struct Block {
    a: [[f64; LANES]; 3],
    e1: [[f64; LANES]; 3],
    e2: [[f64; LANES]; 3],
    /// Offset of the lane's polygon's first vertex in `Bvh::vertices`, with `QUAD_FLAG` for quads.
    vertex: [u32; LANES],
    /// The lane's polygon, or [`EMPTY_LANE`].
    polygon: [u32; LANES],
}

const _: () = assert!(std::mem::size_of::<Block>() == 320);

impl Block {
    const EMPTY: Block = Block {
        a: [[0.0; LANES]; 3],
        e1: [[0.0; LANES]; 3],
        e2: [[0.0; LANES]; 3],
        vertex: [0; LANES],
        polygon: [EMPTY_LANE; LANES],
    };

    /// Lane `k`'s triangle `(a, e1, e2)`.
    #[inline(always)]
    fn lane(&self, k: usize) -> (DVec3, DVec3, DVec3) {
        let get = |v: &[[f64; LANES]; 3]| DVec3::new(v[0][k], v[1][k], v[2][k]);
        (get(&self.a), get(&self.e1), get(&self.e2))
    }

    /// Ray parameter in `(t_min, t_max)` of lane `k`'s triangle, with its barycentric (u, v): the
    /// reference test on the same numbers as `brute_force::ray_polygon`.
    #[inline(always)]
    fn hit(&self, k: usize, ray: &Ray, t_min: f64, t_max: f64) -> Option<(f64, f64, f64)> {
        let (a, e1, e2) = self.lane(k);
        triangle(ray, ray.origin - a, e1, e2, t_min, t_max)
    }

    /// Whether any lane blocks the ray in `(t_min, t_max)`: the filter `K` first, the exact test for the
    /// lanes it keeps. For occlusion a quad's two triangles are independent (the reference's quad hits
    /// iff either does).
    #[inline(always)]
    fn occludes<K: Simd>(&self, ray: &Ray, t_min: f64, t_max: f64) -> bool {
        let mut lanes = K::filter(ray, self);
        while lanes != 0 {
            let k = lanes.trailing_zeros() as usize;
            lanes &= lanes - 1;
            if self.hit(k, ray, t_min, t_max).is_some() {
                return true;
            }
        }
        false
    }
}

/// 2^900: `|x| * 2^900 > |det|` means `x / det` is far from underflowing to zero.
const TWO_POW_900: f64 = f64::from_bits((1023 + 900) << 52);

/// Whether [`triangle`] (`ray_triangle(ray, s, e1, e2, ..)`, with direction `d`) can return a hit: the
/// same determinant and barycentric numerators, compared against `det` without its division, so most
/// misses skip the division's latency (the portable filter, and the reference for the AVX2 one). It answers `false` only where the reference surely rejects:
/// `u = U * (1 / det)` is negative when `U` and `det` have opposite signs and `U` is too large for the
/// product to underflow to `-0`, and exceeds 1 when `|U| > |det| (1 + 1e-14)`, far beyond the two
/// roundings (2^-52); likewise for `w` and `u + w`.
#[inline(always)]
fn may_hit(d: DVec3, s: DVec3, e1: DVec3, e2: DVec3) -> bool {
    let p = d.cross(e2);
    let det = e1.dot(p);
    let a = det.abs();
    // The reference's `det.abs() < 1e-300` (and a NaN determinant, whose u fails every test).
    if a.is_nan() || a < 1e-300 {
        return false;
    }
    let sign = if det < 0.0 { -1.0 } else { 1.0 };
    let far = a * (1.0 + 1e-14);
    let negative = |x: f64| x < 0.0 && x.abs() * TWO_POW_900 > a;
    let u = sign * s.dot(p);
    if negative(u) || u > far {
        return false;
    }
    let w = sign * d.dot(s.cross(e1));
    if negative(w) {
        return false;
    }
    !(u >= 0.0 && w >= 0.0 && u + w > far)
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
            vertices: Vec::new(),
        };
        let mut nodes = Vec::new();
        if is_leaf(&prims) {
            if !prims.is_empty() {
                leaves.push(&prims);
            }
        } else {
            let binary = build(&mut prims, 0, 0);
            nodes.reserve(binary.len() / 2 + 1);
            let cuts = Cuts::new(&binary);
            collapse(&binary, &cuts, 0, &prims, &mut nodes, &mut leaves);
        }
        Bvh {
            nodes,
            root_min: bounds.min.as_dvec3(),
            root_max: bounds.max.as_dvec3(),
            blocks: leaves.blocks,
            vertices: leaves.vertices,
            kernel: Kernel::detect(),
        }
    }

    /// Number of (8-wide) interior nodes (for statistics).
    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// The shape of lane `k` of `block`, rebuilt bit-exactly from the stored vertices.
    fn shape(&self, block: &Block, k: usize) -> Shape {
        let tagged = block.vertex[k];
        let o = (tagged & !QUAD_FLAG) as usize;
        let v = &self.vertices;
        if tagged & QUAD_FLAG != 0 {
            Shape::Quad([v[o], v[o + 1], v[o + 2], v[o + 3]])
        } else {
            Shape::Triangle([v[o], v[o + 1], v[o + 2]])
        }
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
        // A negative direction enters a slab at its maximum.
        let near = [0, 1, 2].map(|a| 2 * a + usize::from(inv[a] < 0.0));
        let mut trav = TravRay {
            origin: origin.to_array(),
            inv: inv.to_array(),
            near,
            far: near.map(|p| p ^ 1),
            t_far: 0.0,
            t0: lo,
            scale,
        };
        trav.set_far(hi);
        Some(trav)
    }

    /// Any-hit traversal with kernels `K`.
    #[inline(always)]
    fn occluded_with<K: Simd>(&self, ray: &Ray, t_min: f64, t_max: f64) -> bool {
        let Some(trav) = self.setup(ray, t_min, t_max) else {
            return false;
        };
        if self.nodes.is_empty() {
            return self.blocks[0].occludes::<K>(ray, t_min, t_max);
        }
        let mut stack = Stack::new();
        let mut current = 0u32;
        loop {
            let node = &self.nodes[current as usize];
            let (mask, enter) = K::slab(&trav, node);
            // The leaves' blocks and the interior children are fetched first, so that the fetches
            // overlap each other and the leaf tests.
            let leaves = mask & node.leaves as u32;
            let mut bits = leaves;
            while bits != 0 {
                let k = bits.trailing_zeros() as usize;
                bits &= bits - 1;
                prefetch(std::slice::from_ref(&self.blocks[node.child[k] as usize]));
            }
            // The next node is the nearest interior child, the others pushed: rays from a surface find
            // nearby blockers soonest.
            let mut inner = mask & !leaves;
            let mut next = None;
            if inner != 0 {
                let k = inner.trailing_zeros() as usize;
                inner &= inner - 1;
                let (mut best, mut best_t) = (node.child[k], enter[k]);
                prefetch(std::slice::from_ref(&self.nodes[best as usize]));
                while inner != 0 {
                    let k = inner.trailing_zeros() as usize;
                    inner &= inner - 1;
                    let (c, t) = (node.child[k], enter[k]);
                    prefetch(std::slice::from_ref(&self.nodes[c as usize]));
                    if t < best_t {
                        stack.push(best, best_t);
                        (best, best_t) = (c, t);
                    } else {
                        stack.push(c, t);
                    }
                }
                next = Some(best);
            }
            // Leaves before descending: a blocker ends the ray.
            let mut bits = leaves;
            while bits != 0 {
                let k = bits.trailing_zeros() as usize;
                bits &= bits - 1;
                if self.blocks[node.child[k] as usize].occludes::<K>(ray, t_min, t_max) {
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
        // Closest lane so far: (t, block, lane, barycentric u, v).
        let mut best: Option<(f64, usize, usize, f64, f64)> = None;
        let mut limit = t_max;
        // Lanes in order, each tested up to the nearest hit so far: a quad's second triangle replaces
        // its first only when strictly nearer, as in the reference.
        let mut leaf = |index: u32, trav: &mut TravRay| {
            let block = &self.blocks[index as usize];
            let mut lanes = K::filter(ray, block);
            while lanes != 0 {
                let k = lanes.trailing_zeros() as usize;
                lanes &= lanes - 1;
                if let Some((t, u, v)) = block.hit(k, ray, t_min, limit) {
                    best = Some((t, index as usize, k, u, v));
                    limit = t;
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
                let (mask, enter) = K::slab(&trav, node);
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
                // Interior children are fetched while the leaves are tested.
                for &(_, k) in &order[..n] {
                    if node.leaves & (1 << k) == 0 {
                        prefetch(std::slice::from_ref(&self.nodes[node.child[k] as usize]));
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
    fn finish(&self, ray: &Ray, best: Option<(f64, usize, usize, f64, f64)>) -> Option<Hit> {
        let (t, index, k, u, v) = best?;
        let block = &self.blocks[index];
        let shape = self.shape(block, k);
        let uv = match shape {
            Shape::Triangle(_) => DVec2::new(u, v),
            Shape::Quad(_) => shape.parameters_of(ray.at(t)),
        };
        Some(Hit {
            t,
            polygon: block.polygon[k] as usize,
            uv,
            front: ray.direction.dot(shape.vector_area()) < 0.0,
        })
    }
}

/// Asks the CPU to start loading `items` into cache (a hint: no effect on results; nothing where the
/// target has no prefetch instruction). Traversal waits on memory on large scenes, and this lets the
/// fetches of nodes and leaves that will be visited overlap.
#[inline(always)]
fn prefetch<T>(items: &[T]) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        let start = items.as_ptr() as usize;
        let end = start + std::mem::size_of_val(items);
        // Every cache line the items touch.
        for line in (start & !63..end).step_by(64) {
            // SAFETY: prefetching is only a hint, which never faults, and SSE is part of x86_64.
            unsafe { _mm_prefetch::<_MM_HINT_T0>(line as *const i8) };
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = items;
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
    /// Per axis the plane (index into [`Node::planes`]) where the ray enters a slab, and where it leaves.
    near: [usize; 3],
    far: [usize; 3],
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
    /// Slab tests of a node's eight children against `[0, t_far]`: bit `k` of the mask is set when child
    /// `k` exists and is hit; lane `k` of the array is its entry parameter.
    ///
    /// Error bound: a slab parameter is `(origin + q scale - o) inv`, computed as `q (scale inv) +
    /// (origin - o) inv` with at most four roundings of terms below `4 M |inv|` (`M` the scene's largest
    /// coordinate), so it is off by under `2^-20 M |inv|`, while the box padding ([`RELATIVE_PAD`]) moves
    /// every slab by `2^-18 M |inv|`: a box the exact ray meets is never culled.
    fn slab(ray: &TravRay, node: &Node) -> (u32, [f32; WIDTH]);

    /// [`may_hit`] of each lane of `block` (bit `k` for lane `k`), computed with exactly its operations,
    /// so bit-identical and conservative in every kernel.
    fn filter(ray: &Ray, block: &Block) -> u32;
}

/// Lane loops in plain Rust (any CPU).
struct Portable;

impl Simd for Portable {
    #[inline(always)]
    fn slab(ray: &TravRay, node: &Node) -> (u32, [f32; WIDTH]) {
        let mut enter = [0f32; WIDTH];
        let mut exit = [ray.t_far; WIDTH];
        for axis in 0..3 {
            let (a, b) = ray.grid(node, axis);
            let (near, far) = (&node.planes[ray.near[axis]], &node.planes[ray.far[axis]]);
            for k in 0..WIDTH {
                enter[k] = enter[k].max(f32::from(near[k]) * a + b);
                exit[k] = exit[k].min(f32::from(far[k]) * a + b);
            }
        }
        let mut mask = 0;
        for k in 0..WIDTH {
            mask |= u32::from(enter[k] <= exit[k]) << k;
        }
        (mask & u32::from(node.valid), enter)
    }

    #[inline(always)]
    fn filter(ray: &Ray, block: &Block) -> u32 {
        let mut lanes = 0;
        for k in 0..LANES {
            let (a, e1, e2) = block.lane(k);
            lanes |= u32::from(may_hit(ray.direction, ray.origin - a, e1, e2)) << k;
        }
        lanes
    }
}

/// AVX2 + FMA: the eight lanes in one 256-bit register.
#[cfg(target_arch = "x86_64")]
struct Avx2;

#[cfg(target_arch = "x86_64")]
impl Simd for Avx2 {
    #[inline(always)]
    fn slab(ray: &TravRay, node: &Node) -> (u32, [f32; WIDTH]) {
        // SAFETY: this kernel only runs inside `occluded_avx2` / `intersect_avx2`, which are only called
        // when the CPU has AVX2 and FMA (`Kernel::detect`).
        unsafe { slab_avx2(ray, node) }
    }

    #[inline(always)]
    fn filter(ray: &Ray, block: &Block) -> u32 {
        // SAFETY: as above.
        unsafe { filter_avx2(ray, block) }
    }
}

/// [`may_hit`] on four lanes of `f64`: the same products, sums and comparisons in the same order (no
/// fused multiply-add), so every lane's answer is bit for bit the scalar one.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
fn filter_avx2(ray: &Ray, block: &Block) -> u32 {
    use std::arch::x86_64::*;
    type V = [__m256d; 3];
    // SAFETY: each row is four `f64` at a 32-byte aligned offset of the 64-byte aligned block.
    let load = |rows: &[[f64; LANES]; 3]| rows.map(|r| unsafe { _mm256_load_pd(r.as_ptr()) });
    let splat = |v: DVec3| v.to_array().map(|x| _mm256_set1_pd(x));
    let (mul, add, sub) = (_mm256_mul_pd, _mm256_add_pd, _mm256_sub_pd);
    // `glam`'s `DVec3::cross` and `DVec3::dot`, term for term.
    let cross = |x: V, y: V| {
        [
            sub(mul(x[1], y[2]), mul(y[1], x[2])),
            sub(mul(x[2], y[0]), mul(y[2], x[0])),
            sub(mul(x[0], y[1]), mul(y[0], x[1])),
        ]
    };
    let dot = |x: V, y: V| add(add(mul(x[0], y[0]), mul(x[1], y[1])), mul(x[2], y[2]));
    let (d, o) = (splat(ray.direction), splat(ray.origin));
    let a = load(&block.a);
    let s = [0, 1, 2].map(|i| sub(o[i], a[i]));
    let (e1, e2) = (load(&block.e1), load(&block.e2));
    let p = cross(d, e2);
    let det = dot(e1, p);
    let sign_bit = _mm256_set1_pd(-0.0);
    // `sign * x` with `sign = ±1` is `x` with the determinant's sign bit flipped in.
    let sign = _mm256_and_pd(det, sign_bit);
    let abs = _mm256_andnot_pd(sign_bit, det);
    let zero = _mm256_setzero_pd();
    let usable = _mm256_cmp_pd::<_CMP_GE_OQ>(abs, _mm256_set1_pd(1e-300));
    let far = mul(abs, _mm256_set1_pd(1.0 + 1e-14));
    let negative = |x: __m256d| {
        let huge = mul(_mm256_andnot_pd(sign_bit, x), _mm256_set1_pd(TWO_POW_900));
        _mm256_and_pd(
            _mm256_cmp_pd::<_CMP_LT_OQ>(x, zero),
            _mm256_cmp_pd::<_CMP_GT_OQ>(huge, abs),
        )
    };
    let u = _mm256_xor_pd(dot(s, p), sign);
    let w = _mm256_xor_pd(dot(d, cross(s, e1)), sign);
    let both = _mm256_and_pd(
        _mm256_cmp_pd::<_CMP_GE_OQ>(u, zero),
        _mm256_cmp_pd::<_CMP_GE_OQ>(w, zero),
    );
    let reject = _mm256_or_pd(
        _mm256_or_pd(negative(u), _mm256_cmp_pd::<_CMP_GT_OQ>(u, far)),
        _mm256_or_pd(
            negative(w),
            _mm256_and_pd(both, _mm256_cmp_pd::<_CMP_GT_OQ>(add(u, w), far)),
        ),
    );
    _mm256_movemask_pd(_mm256_andnot_pd(reject, usable)) as u32
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
fn slab_avx2(ray: &TravRay, node: &Node) -> (u32, [f32; WIDTH]) {
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
        let near = _mm256_fmadd_ps(lanes(&node.planes[ray.near[axis]]), a, b);
        let far = _mm256_fmadd_ps(lanes(&node.planes[ray.far[axis]]), a, b);
        enter = _mm256_max_ps(enter, near);
        exit = _mm256_min_ps(exit, far);
    }
    let hit = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(enter, exit)) as u32;
    let mut lanes_out = [0f32; WIDTH];
    // SAFETY: `lanes_out` holds eight `f32`; the store has no alignment requirement.
    unsafe { _mm256_storeu_ps(lanes_out.as_mut_ptr(), enter) };
    (hit & u32::from(node.valid), lanes_out)
}

/// Which [`Simd`] kernels traversal runs, chosen once per tree from the CPU's features.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kernel {
    Portable,
    #[cfg(target_arch = "x86_64")]
    Avx2,
}

impl Kernel {
    fn detect() -> Kernel {
        #[cfg(target_arch = "x86_64")]
        if is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma") {
            return Kernel::Avx2;
        }
        Kernel::Portable
    }
}

/// The traversals compiled for AVX2 + FMA (the leaf tests too: they stay bit-identical, as Rust never
/// fuses a multiply and an add on its own).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn occluded_avx2(bvh: &Bvh, ray: &Ray, t_min: f64, t_max: f64) -> bool {
    bvh.occluded_with::<Avx2>(ray, t_min, t_max)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn intersect_avx2(bvh: &Bvh, ray: &Ray, t_min: f64, t_max: f64) -> Option<Hit> {
    bvh.intersect_with::<Avx2>(ray, t_min, t_max)
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
    vertices: Vec<DVec3>,
}

impl Leaves<'_> {
    /// Appends the block of `prims` (at most [`LANES`] lanes) and returns its index.
    fn push(&mut self, prims: &[BuildPrim]) -> u32 {
        let mut block = Block::EMPTY;
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
                let (e1, e2) = (v[i] - v[0], v[i + 1] - v[0]);
                for axis in 0..3 {
                    block.a[axis][k] = v[0][axis];
                    block.e1[axis][k] = e1[axis];
                    block.e2[axis][k] = e2[axis];
                }
                block.vertex[k] = tag;
                block.polygon[k] = p.index;
                k += 1;
            }
        }
        self.blocks.push(block);
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
            Kernel::Portable => self.intersect_with::<Portable>(ray, t_min, t_max),
        }
    }

    fn occluded(&self, ray: &Ray, t_min: f64, t_max: f64) -> bool {
        match self.kernel {
            // SAFETY: as above.
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx2 => unsafe { occluded_avx2(self, ray, t_min, t_max) },
            Kernel::Portable => self.occluded_with::<Portable>(ray, t_min, t_max),
        }
    }

    fn name(&self) -> &'static str {
        "bvh"
    }

    /// Nodes, leaf blocks and vertices.
    fn memory_bytes(&self) -> Option<usize> {
        use std::mem::size_of_val;
        Some(
            size_of_val(self.nodes.as_slice())
                + size_of_val(self.blocks.as_slice())
                + size_of_val(self.vertices.as_slice()),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
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
                let block = &bvh.blocks[node.child[k] as usize];
                for v in check_block(bvh, block, seen) {
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

    /// Counts the polygons of a leaf block in `seen` (a quad fills two adjacent lanes), checks that its
    /// lanes are the polygons' triangles, bit for bit, and that used lanes come first; returns the
    /// polygons' vertices.
    fn check_block(bvh: &Bvh, block: &Block, seen: &mut [u32]) -> Vec<DVec3> {
        let mut vertices = Vec::new();
        let used = block
            .polygon
            .iter()
            .take_while(|&&p| p != EMPTY_LANE)
            .count();
        assert!(used > 0 && block.polygon[used..].iter().all(|&p| p == EMPTY_LANE));
        let mut k = 0;
        while k < used {
            let shape = bvh.shape(block, k);
            seen[block.polygon[k] as usize] += 1;
            let v = shape.vertices();
            for i in 1..v.len() - 1 {
                assert_eq!(block.polygon[k], block.polygon[k + 1 - i]);
                assert_eq!(block.lane(k), (v[0], v[i] - v[0], v[i + 1] - v[0]));
                k += 1;
            }
            vertices.extend_from_slice(v);
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
                check_block(&bvh, &bvh.blocks[0], &mut seen);
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
    /// parameter no later than the exact one.
    #[test]
    fn slab_kernels_are_conservative() {
        let shapes = random_mixed(3000, 11);
        let bvh = Bvh::new(&shapes);
        // The scene's largest coordinate is at least 1, so its boxes are padded by at least this.
        let pad = RELATIVE_PAD;
        let mut rng = Pcg64Mcg::seed_from_u64(12);
        type SlabFn = fn(&TravRay, &Node) -> (u32, [f32; WIDTH]);
        let mut kernels: Vec<SlabFn> = vec![Portable::slab];
        #[cfg(target_arch = "x86_64")]
        if Kernel::detect() == Kernel::Avx2 {
            kernels.push(Avx2::slab);
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
                for kernel in &kernels {
                    let (mask, enter) = kernel(&trav, node);
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
                            let exact = ((lo - trav.t0) * trav.scale) as f32;
                            assert!(entry <= exact.max(0.0) * (1.0 + 1e-6) + 1e-6);
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
        let mut kernels = vec![Kernel::Portable];
        #[cfg(target_arch = "x86_64")]
        if Kernel::detect() == Kernel::Avx2 {
            kernels.push(Kernel::Avx2);
        }
        for kernel in kernels {
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

    /// The division-free filter never rejects what the reference test accepts, also at the triangle's
    /// edges and vertices and for nearly parallel rays.
    #[test]
    fn hit_filter_is_conservative() {
        let mut rng = Pcg64Mcg::seed_from_u64(5);
        let mut rejected = 0;
        for i in 0..200_000 {
            let mut v = || DVec3::new(rng.random(), rng.random(), rng.random()) * 2.0 - 1.0;
            let (e1, e2, o) = (v(), v(), v() * 3.0);
            // Targets on the triangle's edges and corners (barycentrics 0 or 1) or near them.
            let (bu, bw) = match i % 4 {
                0 => (0.0, 0.5),
                1 => (0.5, 0.5),
                2 => (1.0, 0.0),
                _ => (1e-9 * (i % 7) as f64, 1.0 - 1e-9),
            };
            let target = bu * e1 + bw * e2;
            let mut d = target - o;
            if i % 5 == 0 {
                // Nearly in the plane: tiny determinant.
                let n = e1.cross(e2).normalize();
                d -= n * n.dot(d) * (1.0 - 1e-12);
            }
            let ray = Ray::new(o, d);
            let reference = triangle(&ray, o, e1, e2, 0.0, f64::INFINITY);
            if !may_hit(d, o, e1, e2) {
                rejected += 1;
                assert!(reference.is_none(), "ray {i}: {reference:?}");
            }
        }
        assert!(rejected > 1000, "the filter rejects misses: {rejected}");
    }

    /// The AVX2 filter gives, lane for lane, the scalar filter's answer, on triangles hit at their edges
    /// and corners, nearly parallel rays, degenerate triangles and empty lanes.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn filter_kernels_agree() {
        if Kernel::detect() != Kernel::Avx2 {
            return;
        }
        let mut rng = Pcg64Mcg::seed_from_u64(6);
        let (mut kept, mut dropped) = (0, 0);
        for i in 0..50_000 {
            let mut v = || DVec3::new(rng.random(), rng.random(), rng.random()) * 2.0 - 1.0;
            let (o, target) = (v() * 3.0, v());
            let mut block = Block::EMPTY;
            for k in 0..LANES - usize::from(i % 3 == 0) {
                let (a, mut e1, e2) = (v(), v(), v());
                match (i + k) % 5 {
                    // Through an edge or a corner.
                    0 => e1 = (target - a) * 2.0,
                    1 => e1 = target - a,
                    // Degenerate.
                    2 if i % 7 == 0 => e1 = e2 * 3.0,
                    _ => {}
                }
                for axis in 0..3 {
                    block.a[axis][k] = a[axis];
                    block.e1[axis][k] = e1[axis];
                    block.e2[axis][k] = e2[axis];
                }
                block.polygon[k] = k as u32;
            }
            let mut d = target - o;
            if i % 4 == 0 {
                // Nearly in the plane of lane 0.
                let (_, e1, e2) = block.lane(0);
                let n = e1.cross(e2).normalize();
                d -= n * n.dot(d) * (1.0 - 1e-12);
            }
            let ray = Ray::new(o, d);
            let want = Portable::filter(&ray, &block);
            assert_eq!(Avx2::filter(&ray, &block), want, "case {i}");
            kept += want.count_ones();
            dropped += LANES as u32 - want.count_ones();
        }
        assert!(
            kept > 10_000 && dropped > 10_000,
            "{kept} kept, {dropped} dropped"
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
