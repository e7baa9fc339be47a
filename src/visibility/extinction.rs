//! Extinction visibility (Sillion–Drettakis §3.1, after Sillion 1995): the scene's polygons grouped into
//! a cluster tree ([`crate::hierarchy::clusters`]), each cluster an absorbing volume with extinction
//! coefficient `κ = ΣA / (4V)`, and the transmittance of a segment `T(P, Q) = exp(−Σ_i κ_i l_i)` over the
//! clusters it crosses, `l_i` the length inside cluster `i`.
//!
//! Level: the lowest one. Each polygon is counted once, in the cluster that holds it directly, so a
//! cluster's `κ_i` is the area of its *own* polygons over its volume (for a cluster whose members are
//! all polygons, the leaf clusters of the tree, that is the paper's κ; a cluster that also holds
//! sub-clusters adds only its direct polygons, which the sub-clusters do not count). Higher levels would
//! average the same area over larger, emptier boxes.
//!
//! Area: `A` counts both faces of every polygon. Cauchy's formula gives the mean projected area of a
//! convex body as a quarter of its surface area, and a flat polygon of area `a` has surface `2a` (mean
//! projection `a/2` over uniform directions), which is the blocking cross-section behind `κ = ΣA/(4V)`;
//! one-sided polygons block rays from both sides in ray casting too.
//!
//! Only [`Visibility::transmittance`] is approximate: [`Visibility::intersect`] and
//! [`Visibility::occluded`] (rendering, the reference, the sampling oracles) stay exact, through a BVH.
//! The model is asymptotically exact for homogeneous isotropic clusters of objects small compared with
//! the cluster; it also attenuates a segment by the cluster of the surface it starts on (a known bias of
//! extinction clustering, largest for big flat polygons).

use super::bvh::Bvh;
use super::{Hit, Visibility};
use crate::geometry::{Aabb, DVec3, Ray, Shape};
use crate::hierarchy::clusters::{Child, ClusterTree, ClusterTreeKind, Item};

/// Exact ray casting plus cluster extinction for transmittance.
pub struct Extinction {
    exact: Bvh,
    tree: ClusterTree,
    /// Per node: the padded bounds the segment is clipped against.
    bounds: Vec<Aabb>,
    /// Per node: `κ` of the polygons it holds directly (zero for a node of sub-clusters only).
    kappa: Vec<f64>,
    /// Per node: `κ = ΣA/(4V)` of every polygon below it over its own box: the paper's extinction of a
    /// cluster taken as a whole (§3.1), which multi-resolution visibility may use for a cluster it
    /// does not descend into ([`super::multires::Averaging::Cluster`]).
    kappa_below: Vec<f64>,
}

impl Extinction {
    pub fn new(shapes: &[Shape], kind: ClusterTreeKind) -> Self {
        let items: Vec<Item> = shapes
            .iter()
            .map(|s| Item {
                bounds: s.bounds(),
                area: 2.0 * s.area(),
            })
            .collect();
        let tree = ClusterTree::build(&items, kind);
        // Flat clusters (coplanar contents) have no volume: every box is padded by a small fraction of
        // the scene so that κ stays finite; κ·l is then the same for any small padding.
        let scene = tree
            .root()
            .map_or(Aabb::EMPTY, |r| tree.nodes[r as usize].bounds);
        let pad = DVec3::splat(1e-4 * scene.diagonal().max(1e-12));
        let bounds: Vec<Aabb> = tree
            .nodes
            .iter()
            .map(|n| Aabb {
                min: n.bounds.min - pad,
                max: n.bounds.max + pad,
            })
            .collect();
        // κ = ΣA/(4V) over a node's padded box.
        let per_volume = |area: f64, b: &Aabb| {
            let e = b.extent();
            area / (4.0 * e.x * e.y * e.z)
        };
        let kappa = tree
            .nodes
            .iter()
            .zip(&bounds)
            .map(|(node, b)| {
                let direct: f64 = node
                    .children
                    .iter()
                    .map(|&c| match c {
                        Child::Item(i) => items[i as usize].area,
                        Child::Node(_) => 0.0,
                    })
                    .sum();
                per_volume(direct, b)
            })
            .collect();
        let kappa_below = tree
            .nodes
            .iter()
            .zip(&bounds)
            .map(|(node, b)| per_volume(node.area, b))
            .collect();
        Extinction {
            exact: Bvh::new(shapes),
            tree,
            bounds,
            kappa,
            kappa_below,
        }
    }

    /// `Σ κ_i l_i` along the segment from `from` to `to`.
    pub fn optical_depth(&self, from: DVec3, to: DVec3) -> f64 {
        match (self.tree.root(), Segment::new(from, to)) {
            (Some(root), Some(segment)) => self.optical_depth_below(root, &segment),
            _ => 0.0,
        }
    }

    /// `Σ κ_i l_i` over cluster `node` and the clusters below it: the extinction multi-resolution
    /// visibility uses for a cluster it does not descend into.
    pub(super) fn optical_depth_below(&self, node: u32, segment: &Segment) -> f64 {
        let mut depth = 0.0;
        let mut stack = WalkStack::new();
        stack.push(node);
        while let Some(n) = stack.pop() {
            let Some((t0, t1)) = segment.clip(&self.bounds[n as usize]) else {
                continue;
            };
            depth += self.kappa[n as usize] * (t1 - t0) * segment.length;
            for &c in &self.tree.nodes[n as usize].children {
                if let Child::Node(m) = c {
                    stack.push(m);
                }
            }
        }
        depth
    }

    /// `κ l` of cluster `node` taken as a whole (`κ` of everything below it, [`Extinction::new`]) over
    /// the part `(t0, t1)` of `segment` inside its box: O(1), where [`Extinction::optical_depth_below`]
    /// walks the subtree.
    pub(super) fn optical_depth_as_a_whole(
        &self,
        node: u32,
        (t0, t1): (f64, f64),
        segment: &Segment,
    ) -> f64 {
        self.kappa_below[node as usize] * (t1 - t0) * segment.length
    }

    /// The cluster tree over the polygons (indices of `Child::Item` are polygon indices).
    pub(super) fn tree(&self) -> &ClusterTree {
        &self.tree
    }

    /// The padded bounds of cluster `node`, which contain every polygon below it with a margin.
    pub(super) fn padded_bounds(&self, node: u32) -> &Aabb {
        &self.bounds[node as usize]
    }

    /// The exact ray caster over the same polygons.
    pub(super) fn exact(&self) -> &Bvh {
        &self.exact
    }
}

/// The clusters still to visit in a walk down the cluster tree: on the stack for any tree but a very
/// wide one (a walk runs per ray: office3 under `--visibility extinction` 10.5 → 9.8 s without a heap
/// allocation per walk, under multires 1%).
pub(super) type WalkStack = smallvec::SmallVec<[u32; 64]>;

/// A segment `from + t (to − from)`, `t ∈ [0, 1]`, ready for clipping against boxes.
pub(super) struct Segment {
    pub from: DVec3,
    /// `1 / (to − from)` per axis.
    pub inverse: DVec3,
    pub length: f64,
}

impl Segment {
    /// `None` for a segment of zero length.
    pub fn new(from: DVec3, to: DVec3) -> Option<Self> {
        let d = to - from;
        let length = d.length();
        (length > 0.0).then(|| Segment {
            from,
            inverse: DVec3::ONE / d,
            length,
        })
    }

    /// The parameter interval of the segment inside `b` ([`Aabb::segment_range`]).
    pub fn clip(&self, b: &Aabb) -> Option<(f64, f64)> {
        b.segment_range(self.from, self.inverse)
    }
}

impl Visibility for Extinction {
    fn intersect(&self, ray: &Ray, t_min: f64, t_max: f64) -> Option<Hit> {
        self.exact.intersect(ray, t_min, t_max)
    }

    fn occluded(&self, ray: &Ray, t_min: f64, t_max: f64) -> bool {
        self.exact.occluded(ray, t_min, t_max)
    }

    fn transmittance(&self, from: DVec3, to: DVec3) -> f64 {
        (-self.optical_depth(from, to)).exp()
    }

    fn transmittance_past(
        &self,
        from: DVec3,
        to: DVec3,
        _transparent: &dyn Fn(usize) -> bool,
    ) -> f64 {
        self.transmittance(from, to)
    }

    fn name(&self) -> &'static str {
        "extinction"
    }
}
