//! Our bounding volume hierarchy: surface-area-heuristic build over the input polygons (quads kept as
//! quads), fast occlusion and closest-hit traversal.
//!
//! Precision split: node boxes and traversal are `f32` (SSE through `glam::Vec3A`), but every box is padded
//! by a margin far above `f32` rounding, so culling is conservative; the primitive tests are the exact
//! double precision test of the exhaustive reference ([`super::brute_force::ray_triangle`]). Answers are
//! therefore the reference's answers (up to ties between polygons at the same `t`), including its
//! robustness: a segment between two points on scene polygons is not blocked by those polygons, nor by
//! polygons coplanar with its start.

use super::brute_force::ray_triangle as triangle;
use super::{Hit, Visibility};
use crate::geometry::{DVec2, DVec3, Ray, Shape};
use glam::{Vec3A, Vec4, Vec4Swizzles};

/// SAH cost of one ray–triangle test, relative to one ray–box test pair in a node.
const TRIANGLE_COST: f32 = 1.0;
/// A quad is two triangle tests sharing the ray–origin difference; usually the first already decides.
const QUAD_COST: f32 = 1.5;
/// Cost of visiting an interior node (two box tests).
const NODE_COST: f32 = 1.0;
/// Leaves hold at most this many primitives (unless their centroids coincide).
const MAX_LEAF: usize = 8;
const BINS: usize = 16;
/// Subtrees larger than this are built in parallel.
const PARALLEL_THRESHOLD: usize = 4096;
/// Beyond this depth splits are median splits, so the tree depth stays below [`STACK_SIZE`].
const MAX_SAH_DEPTH: usize = 96;
const STACK_SIZE: usize = 192;
/// Box padding relative to the largest coordinate magnitude of the scene: 2^-18, far above the `f32`
/// rounding of coordinates (2^-24) and of slab distances, and it also gives flat boxes a thickness.
const RELATIVE_PAD: f64 = 1.0 / 262_144.0;
/// High bit of a child reference marks a leaf; the low bits are then the first primitive.
const LEAF_FLAG: u32 = 1 << 31;
/// High bit of a primitive's vertex offset marks a quad.
const QUAD_FLAG: u32 = 1 << 31;

/// Interior node: both children's boxes, so one visit decides which children to enter (64 bytes). Per
/// axis the lanes are (min left, min right, max left, max right): both slab tests are one SIMD pass.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
struct Node {
    bounds: [Vec4; 3],
    /// Interior node index, or `LEAF_FLAG | first primitive`.
    child: [u32; 2],
    /// Primitive count of leaf children (0 for interior children).
    count: [u32; 2],
}

/// The root: an interior node index, or a leaf (`LEAF_FLAG | 0`, count) for tiny scenes.
#[derive(Clone, Copy, Debug)]
struct Root {
    child: u32,
    count: u32,
}

/// SAH bounding volume hierarchy over the scene's polygons.
pub struct Bvh {
    nodes: Vec<Node>,
    root: Root,
    /// Root box in double precision (padded), used to clip rays before going to `f32`.
    root_min: DVec3,
    root_max: DVec3,
    /// Per primitive in leaf order: offset of its first vertex in `vertices` (`QUAD_FLAG` for quads).
    prim_vertex: Vec<u32>,
    /// Per primitive in leaf order: its polygon index.
    prim_polygon: Vec<u32>,
    vertices: Vec<DVec3>,
}

#[derive(Clone, Copy)]
struct BuildPrim {
    min: Vec3A,
    max: Vec3A,
    centroid: Vec3A,
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
        use rayon::prelude::*;
        assert!(
            shapes.len() < (LEAF_FLAG as usize) && 4 * shapes.len() < QUAD_FLAG as usize,
            "too many polygons for a BVH: {}",
            shapes.len()
        );
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
        let mut prims: Vec<BuildPrim> = shapes
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
                    cost: if shape.vertex_count() == 4 {
                        QUAD_COST
                    } else {
                        TRIANGLE_COST
                    },
                    index: index as u32,
                }
            })
            .collect();
        let bounds = bounds_of(&prims);
        let (nodes, root_child, root_count) = if prims.len() <= MAX_LEAF {
            (Vec::new(), LEAF_FLAG, prims.len() as u32)
        } else {
            (build(&mut prims, 0, 0), 0, 0)
        };
        let root = Root {
            child: root_child,
            count: root_count,
        };
        let mut prim_vertex = Vec::with_capacity(prims.len());
        let mut prim_polygon = Vec::with_capacity(prims.len());
        let mut vertices = Vec::with_capacity(prims.len() * 3);
        for p in &prims {
            let shape = &shapes[p.index as usize];
            let offset = vertices.len() as u32;
            prim_vertex.push(if shape.vertex_count() == 4 {
                offset | QUAD_FLAG
            } else {
                offset
            });
            prim_polygon.push(p.index);
            vertices.extend_from_slice(shape.vertices());
        }
        Bvh {
            nodes,
            root,
            root_min: bounds.min.as_dvec3(),
            root_max: bounds.max.as_dvec3(),
            prim_vertex,
            prim_polygon,
            vertices,
        }
    }

    /// Number of interior nodes (for statistics).
    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// The shape of primitive `k` (leaf order), rebuilt bit-exactly from the stored vertices.
    fn shape(&self, k: usize) -> Shape {
        let tagged = self.prim_vertex[k];
        let o = (tagged & !QUAD_FLAG) as usize;
        let v = &self.vertices;
        if tagged & QUAD_FLAG != 0 {
            Shape::Quad([v[o], v[o + 1], v[o + 2], v[o + 3]])
        } else {
            Shape::Triangle([v[o], v[o + 1], v[o + 2]])
        }
    }

    /// Ray parameter of primitive `k` in `(t_min, t_max)`, with the triangle's barycentric (u, v) for
    /// triangles. The same test, on the same numbers, as `brute_force::intersect_shape`.
    #[inline(always)]
    fn hit_prim(&self, k: usize, ray: &Ray, t_min: f64, t_max: f64) -> Option<(f64, f64, f64)> {
        let tagged = self.prim_vertex[k];
        let o = (tagged & !QUAD_FLAG) as usize;
        let v = &self.vertices;
        let a = v[o];
        let s = ray.origin - a;
        let e2 = v[o + 2] - a;
        if let Some(hit) = triangle(ray, s, v[o + 1] - a, e2, t_min, t_max) {
            return Some(hit);
        }
        if tagged & QUAD_FLAG != 0 {
            return triangle(ray, s, e2, v[o + 3] - a, t_min, t_max);
        }
        None
    }

    /// Clips the ray to the root box in double precision and prepares the `f32` traversal ray. Traversal
    /// parameters are `t' = (t - t0) * scale`.
    fn setup(&self, ray: &Ray, t_min: f64, t_max: f64) -> Option<TravRay> {
        if t_max.is_nan() || t_min.is_nan() || t_max <= t_min || self.prim_polygon.is_empty() {
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
                let (a, b) = ((bmin - o) / d, (bmax - o) / d);
                lo = lo.max(a.min(b));
                hi = hi.min(a.max(b));
            }
        }
        if lo.is_nan() || hi.is_nan() || lo > hi {
            return None;
        }
        let scale = ray.direction.abs().max_element();
        let dir = ray.direction / scale;
        let origin = ray.origin + lo * ray.direction;
        let tiny = 1e-20;
        let inv = DVec3::new(
            1.0 / if dir.x.abs() < tiny {
                tiny.copysign(dir.x)
            } else {
                dir.x
            },
            1.0 / if dir.y.abs() < tiny {
                tiny.copysign(dir.y)
            } else {
                dir.y
            },
            1.0 / if dir.z.abs() < tiny {
                tiny.copysign(dir.z)
            } else {
                dir.z
            },
        );
        let origin = origin.as_vec3a();
        let inv = inv.as_vec3a();
        let neg_origin_inv = -origin * inv;
        let mut trav = TravRay {
            inv: [0, 1, 2].map(|a| Vec4::splat(inv[a])),
            neg_origin_inv: [0, 1, 2].map(|a| Vec4::splat(neg_origin_inv[a])),
            t_far: 0.0,
            t0: lo,
            scale,
        };
        trav.set_far(hi);
        Some(trav)
    }

    fn occluded_impl(&self, ray: &Ray, t_min: f64, t_max: f64) -> bool {
        let Some(trav) = self.setup(ray, t_min, t_max) else {
            return false;
        };
        let leaf = |first: u32, count: u32| -> bool {
            let first = (first & !LEAF_FLAG) as usize;
            (first..first + count as usize).any(|k| self.hit_prim(k, ray, t_min, t_max).is_some())
        };
        if self.root.count > 0 {
            return leaf(self.root.child, self.root.count);
        }
        let mut stack = [0u32; STACK_SIZE];
        let mut top = 0;
        let mut current = self.root.child;
        loop {
            let node = &self.nodes[current as usize];
            let (mask, enter) = trav.slab(node);
            // Nearer child first: rays from a surface find nearby blockers soonest.
            let order = if enter.x <= enter.y { [0, 1] } else { [1, 0] };
            let mut next = [0u32; 2];
            let mut n = 0;
            for side in order {
                if mask & (1 << side) == 0 {
                    continue;
                }
                if node.count[side] > 0 {
                    if leaf(node.child[side], node.count[side]) {
                        return true;
                    }
                } else {
                    next[n] = node.child[side];
                    n += 1;
                }
            }
            match n {
                0 => {
                    if top == 0 {
                        return false;
                    }
                    top -= 1;
                    current = stack[top];
                }
                1 => current = next[0],
                _ => {
                    stack[top] = next[1];
                    top += 1;
                    current = next[0];
                }
            }
        }
    }

    fn intersect_impl(&self, ray: &Ray, t_min: f64, t_max: f64) -> Option<Hit> {
        let mut trav = self.setup(ray, t_min, t_max)?;
        // Closest primitive so far: (t, primitive, barycentric u, v).
        let mut best: Option<(f64, usize, f64, f64)> = None;
        let mut limit = t_max;
        let mut leaf = |first: u32, count: u32, trav: &mut TravRay| {
            let first = (first & !LEAF_FLAG) as usize;
            for k in first..first + count as usize {
                if let Some((t, u, v)) = self.hit_prim(k, ray, t_min, limit) {
                    best = Some((t, k, u, v));
                    limit = t;
                    trav.set_far(t);
                }
            }
        };
        if self.root.count > 0 {
            leaf(self.root.child, self.root.count, &mut trav);
        } else {
            let mut stack = [(0u32, 0f32); STACK_SIZE];
            let mut top = 0;
            let mut current = self.root.child;
            'done: loop {
                let node = &self.nodes[current as usize];
                let (mask, enter) = trav.slab(node);
                let (mut hit_l, mut hit_r) = (mask & 1 != 0, mask & 2 != 0);
                let (t_l, t_r) = (enter.x, enter.y);
                // Leaves first, nearer one first, so that the far side is culled by their hits.
                let near_first = t_l <= t_r;
                for side in if near_first { [0, 1] } else { [1, 0] } {
                    let hit = if side == 0 { hit_l } else { hit_r };
                    let t_enter = if side == 0 { t_l } else { t_r };
                    if hit && node.count[side] > 0 && t_enter <= trav.t_far {
                        leaf(node.child[side], node.count[side], &mut trav);
                    }
                }
                if node.count[0] > 0 {
                    hit_l = false;
                }
                if node.count[1] > 0 {
                    hit_r = false;
                }
                hit_l &= t_l <= trav.t_far;
                hit_r &= t_r <= trav.t_far;
                match (hit_l, hit_r) {
                    (true, true) => {
                        let (near, far, t_far_child) = if near_first {
                            (node.child[0], node.child[1], t_r)
                        } else {
                            (node.child[1], node.child[0], t_l)
                        };
                        stack[top] = (far, t_far_child);
                        top += 1;
                        current = near;
                    }
                    (true, false) => current = node.child[0],
                    (false, true) => current = node.child[1],
                    (false, false) => loop {
                        if top == 0 {
                            break 'done;
                        }
                        top -= 1;
                        let (node, t_enter) = stack[top];
                        if t_enter <= trav.t_far {
                            current = node;
                            break;
                        }
                    },
                }
            }
        }
        let (t, k, u, v) = best?;
        let shape = self.shape(k);
        let uv = match shape {
            Shape::Triangle(_) => DVec2::new(u, v),
            Shape::Quad(_) => shape.parameters_of(ray.at(t)),
        };
        Some(Hit {
            t,
            polygon: self.prim_polygon[k] as usize,
            uv,
            front: ray.direction.dot(shape.vector_area()) < 0.0,
        })
    }
}

/// The ray in `f32` traversal coordinates (origin moved to the root box entry, direction scaled to unit
/// maximum component).
struct TravRay {
    inv: [Vec4; 3],
    neg_origin_inv: [Vec4; 3],
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

    /// Slab tests of both children of `node` against `[0, t_far]`: bit 0 (left) and 1 (right) of the
    /// mask are set for hit children; lanes x and y of the vector are their entry parameters.
    #[inline(always)]
    fn slab(&self, node: &Node) -> (u32, Vec4) {
        let mut enter = Vec4::ZERO;
        let mut exit = Vec4::splat(self.t_far);
        for axis in 0..3 {
            let t = node.bounds[axis] * self.inv[axis] + self.neg_origin_inv[axis];
            let swapped = t.zwxy();
            enter = enter.max(t.min(swapped));
            exit = exit.min(t.max(swapped));
        }
        (enter.cmple(exit).bitmask() & 3, enter)
    }
}

/// Builds the subtree over `prims` (which sit at offset `base` of the whole primitive array) and returns
/// its nodes, root first; child indices are local to the returned vector.
fn build(prims: &mut [BuildPrim], base: usize, depth: usize) -> Vec<Node> {
    let mut nodes = Vec::new();
    build_into(prims, base, depth, &mut nodes);
    nodes
}

/// Appends the subtree's nodes to `nodes` (root first) and returns the root's index.
fn build_into(prims: &mut [BuildPrim], base: usize, depth: usize, nodes: &mut Vec<Node>) -> u32 {
    let index = nodes.len();
    let mid = split(prims, depth);
    nodes.push(Node {
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
    Nodes(Vec<Node>),
}

fn child_subtree(prims: &mut [BuildPrim], base: usize, depth: usize) -> Subtree {
    if is_leaf(prims) {
        Subtree::Leaf(LEAF_FLAG | base as u32, prims.len() as u32)
    } else {
        Subtree::Nodes(build(prims, base, depth))
    }
}

/// Whether the primitives become one leaf: few enough that the SAH split would not pay for itself.
fn is_leaf(prims: &[BuildPrim]) -> bool {
    if prims.len() <= 1 {
        return true;
    }
    if prims.len() > MAX_LEAF {
        return false;
    }
    let leaf_cost: f32 = prims.iter().map(|p| p.cost).sum();
    match best_split(prims) {
        Some((_, _, cost)) => leaf_cost <= cost,
        None => true,
    }
}

/// Best binned SAH split: (axis, bin boundary, cost relative to the parent box).
fn best_split(prims: &[BuildPrim]) -> Option<(usize, usize, f32)> {
    let mut cmin = Vec3A::splat(f32::INFINITY);
    let mut cmax = Vec3A::splat(f32::NEG_INFINITY);
    for p in prims {
        cmin = cmin.min(p.centroid);
        cmax = cmax.max(p.centroid);
    }
    let parent_area = bounds_of(prims).area();
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
            let cost = NODE_COST + (acc.area() * acc_cost + right_cost[b]) / parent_area;
            if cost.is_finite() && best.is_none_or(|(_, _, c)| cost < c) {
                best = Some((axis, b, cost));
            }
        }
    }
    best
}

#[inline(always)]
fn bin_of(c: f32, min: f32, k: f32) -> usize {
    (((c - min) * k) as usize).min(BINS - 1)
}

/// Reorders `prims` into two non-empty groups and returns the size of the first.
fn split(prims: &mut [BuildPrim], depth: usize) -> usize {
    let n = prims.len();
    if depth < MAX_SAH_DEPTH {
        if let Some((axis, boundary, _)) = best_split(prims) {
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
        self.intersect_impl(ray, t_min, t_max)
    }

    fn occluded(&self, ray: &Ray, t_min: f64, t_max: f64) -> bool {
        self.occluded_impl(ray, t_min, t_max)
    }

    fn name(&self) -> &'static str {
        "bvh"
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

    /// Visits the leaves under `child`, checking that each box contains its primitives' vertices.
    fn check(bvh: &Bvh, child: u32, count: u32, min: Vec3A, max: Vec3A, seen: &mut [u32]) {
        if count > 0 {
            let first = (child & !LEAF_FLAG) as usize;
            for k in first..first + count as usize {
                seen[bvh.prim_polygon[k] as usize] += 1;
                for v in bvh.shape(k).vertices() {
                    let v = v.as_vec3a();
                    assert!(v.cmpge(min).all() && v.cmple(max).all(), "{v} outside box");
                }
            }
            return;
        }
        let node = &bvh.nodes[child as usize];
        for side in 0..2 {
            let b = |lane: usize| Vec3A::from_array([0, 1, 2].map(|a| node.bounds[a][lane]));
            let (cmin, cmax) = (b(side), b(side + 2));
            assert!(
                cmin.cmpge(min).all() && cmax.cmple(max).all(),
                "child outside parent"
            );
            check(bvh, node.child[side], node.count[side], cmin, cmax, seen);
        }
    }

    #[test]
    fn every_primitive_is_in_exactly_one_leaf_inside_its_boxes() {
        for count in [1, 5, 100, 5000] {
            let shapes = random_triangles(count, count as u64);
            let bvh = Bvh::new(&shapes);
            let mut seen = vec![0; count];
            let inf = Vec3A::splat(f32::INFINITY);
            check(&bvh, bvh.root.child, bvh.root.count, -inf, inf, &mut seen);
            assert!(seen.iter().all(|&n| n == 1));
        }
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
        for node in &bvh.nodes {
            for side in 0..2 {
                assert!(node.bounds[2][side] < 0.0 && node.bounds[2][side + 2] > 0.0);
            }
        }
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
