//! Clustering hierarchical radiosity (Smits, Arvo, Greenberg 1994; Sillion 1995; Sillion–Drettakis §4
//! and §6): light exchanged between clusters of surfaces as between single elements. Refinement starts
//! from one self-link on the root cluster ([`crate::solvers::refine::initial_candidates`]); a cluster is
//! split into its contents; links involving a cluster are judged by [`transport_bound`] and coupled here.
//!
//! Transfer between two ends at distance `r` (centres), each a surface (its own cosine) or a cluster:
//!
//! `F_ij = A_j c_i c_j v / (π r²)`,
//!
//! the point-to-point kernel with each cosine replaced by the end's *mean cosine* toward the other:
//! * isotropic (Sillion 1995, the volume model Sillion–Drettakis §3.1 builds on): a cluster radiates and
//!   receives like an isotropic volume whose projected area in any direction is a quarter of the area of
//!   its contents (Cauchy's formula: randomly oriented one-sided surfaces project `A/4` on average), so
//!   `c = 1/4`; a cluster of area `A` and radiance `L` then has intensity `L A / 4` in every direction
//!   and radiates `π L A`, its power;
//! * oriented (Smits et al. 1994): `c = Σ_k A_k max(0, n_k · d_k) / A`, the projected area of its
//!   patches toward the other end over their area, summed over the cluster's groups of patches of
//!   nearly equal normal ([`crate::hierarchy::clusters::Orientation`]) so that it costs one term per
//!   normal direction, not one per patch.
//!
//! `v` is the transmittance averaged over sample segments between the two ends (rays from points on the
//! receiver to area-sampled points on the source's contents; with `--visibility extinction` these are
//! extinction estimates, Sillion–Drettakis §3.1). The coupling is constant in the source (clusters carry
//! one average radiance); on a surface receiver it is evaluated at the receiver's cubature nodes and
//! projected onto its basis like any coupling (Bekaert–Willems Algorithm 4.1), so every basis works.
//!
//! Near links ([`SourceSphere`]): the estimate holds for ends far enough apart: seen from a receiver
//! point outside the sphere of radius `R` about the source's centre that holds it, the source subtends
//! at most the sphere's silhouette (a factor `(R/r)² < 1`, which the centre estimate approaches with
//! the visibility samples discounting the source's own hidden parts); where that sphere reaches the
//! receiver's bounding box some receiver point may lie inside it and nothing bounds the estimate.
//! Centre estimates of near clusters made a receiver's links gather a total factor up to 2.9 on
//! office2's coarse solution, where the exact factors of the disjoint sources they stand for sum to at
//! most 1 (closure): the gathering iteration's spectral radius passed 1 and the sweeps diverged. So a
//! *near* link into a surface sums the exact factors of the source's patches at each node
//! ([`near_coupling`]; refinement splits a source of more than [`NEAR_SOURCE_PATCHES`]), and one
//! into a cluster, whose sharing cannot place light from beside it, is split at its receiver when
//! that holds at most [`NEAR_RECEIVER_PATCHES`] and otherwise carries nothing
//! ([`unplaced_near_coupling`]; its refinement bound, [`transport_bound`], is then the largest
//! there is; RenderPark's Galerkin radiosity does the same for overlapping bounding boxes).
//!
//! Push-pull through clusters ([`ClusterSweep`], [`crate::hierarchy::Hierarchy::pull_clusters`]):
//! radiance is pulled up area-weighted; irradiance gathered at a cluster is pushed to the patches it
//! contains, evenly (isotropic) or with each patch group's cosine toward the link's source, normalised so
//! that the power the link delivered is what the patches receive (oriented).
//!
//! Intra-cluster visibility (Sillion–Drettakis §6.1, `--intra-cluster item-buffer`): an item buffer
//! of the cluster seen from the other end ([`crate::visibility::item_buffer`]) scales each patch's
//! projected area by its visible fraction. Those visible projected areas are then the cluster's
//! projected area in the kernel (`c = Σ_k w_k / A`, for either transfer kind: the isotropic 1/4 is
//! only an estimate of it), the weights of its visibility samples, whose rays pass the end
//! clusters' own contents ([`Visibility::transmittance_past`]: a point drawn on a partly hidden
//! patch would otherwise count its hiding twice, darkening furniture by ~2% on a chair's own
//! parts), so that `v` only counts occluders outside them; and, taken along the item buffer's
//! direction bucket once per sweep ([`ClusterSweep`]), the shares of received irradiance (hidden
//! patches get none) and the weights of the radiance it sends (hidden patches send none). The item
//! buffer sees only the cluster's contents; what stands outside it between a patch and the source
//! only the link's one average visibility knew, so the shares of received irradiance go to the
//! parts of patches *exposed* toward the source (rays from four nodes of each patch with linear
//! bases and up, from its centroid with the constant basis, [`expose`]), each taking the visibility
//! its own rays found rather than the link's average: what it would receive unoccluded, or nothing
//! ([`exposure_shares`]), so that no patch receives more from a link than it would unoccluded.
//!
//! Cost: a coupling reads its cluster ends by normal group ([`groups_toward`]: each group's visible
//! area, cached per (cluster, bucket) with the fractions, [`VisibleAreas`]), so a cluster link costs
//! O(groups) however many patches the cluster holds. Until 2026-11-26 it summed `A_k f_k max(0, n_k ·
//! d_k)` over every patch with its own direction `d_k` (21% of a 300k-polygon hall's profile); the
//! group sum takes the group's mean normal and the direction from its centroid instead, the
//! approximation the oriented transfer already made without item buffers (exact while every member
//! faces the other end, up to the parallax of the members within the group). Power is conserved as
//! before: pushes share what a link delivered by weights that sum to one.
//!
//! Visibility error of a cluster link (Sillion–Drettakis Appendix A): spreading the average visibility
//! `v` over the receiver deviates from the binary visibility by `2v(1−v)` in L¹ and `sqrt(v(1−v))` in L²
//! (eqs. (5), (10)); the L² form times the unoccluded factor is the link's `visibility_error`, which the
//! a-posteriori estimate and the link error oracle read as for any link. Kernel error of a link whose
//! receiver is a cluster (eq. (6)'s `δ_j`, which surface receivers take at their cubature nodes): a
//! cluster has no nodes, so its one `δ` is the largest difference, over the receiver points the
//! visibility rays start from, between what the sweep gives the point's patch (the centres' distance,
//! the patch's cosine toward the source's centre) and the point kernel there; a row of plates under a
//! lamp (tests/clustering.rs) is covered at 93% of its plates, none without it.

use super::coupling::{visible_fraction, Coupling, CouplingSettings};
use super::link_rng;
use crate::color::Rgb;
use crate::geometry::cubature::{nodes_on, rule};
use crate::geometry::form_factor::point_to_polygon;
use crate::geometry::{DVec2, DVec3};
use crate::geometry::{Domain, Shape};
use crate::hierarchy::clusters::{ClusteringKind, Orientation, VisibleAreas};
use crate::hierarchy::{ElementId, ElementKind, Hierarchy, LinkCoupling};
use crate::parallel::Uneven;
use crate::visibility::item_buffer::{
    bucket_direction, direction_bucket, exposed, exposed_nodes, pack_exposure, visible_fractions,
    Exposure, ItemBuffers,
};
use crate::visibility::Visibility;
use rand::Rng;
use rand_pcg::Pcg64Mcg;
use rayon::prelude::*;
use std::f64::consts::PI;

/// Visibility samples per receiver node of a cluster link (per link for a cluster receiver: twice this).
pub const CLUSTER_VISIBILITY_SAMPLES: usize = 4;

const CLUSTER_STREAM: u64 = 3;

/// The mean cosine `c` of element `id` toward the point `toward` (see the module documentation); with
/// item buffers, a cluster's is its visible projected area over its area for either transfer kind.
pub fn mean_cosine(h: &Hierarchy, id: ElementId, toward: DVec3, kind: ClusteringKind) -> f64 {
    let e = h.element(id);
    match &e.kind {
        ElementKind::Surface(s) => {
            let d = (toward - s.shape.centroid()).normalize_or_zero();
            h.patches[s.patch as usize].normal.dot(d).max(0.0)
        }
        ElementKind::Cluster(_)
            if kind == ClusteringKind::Isotropic && h.item_buffers.is_none() =>
        {
            0.25
        }
        ElementKind::Cluster(_) if e.area <= 0.0 => 0.0,
        ElementKind::Cluster(_) => {
            groups_toward(h, id, toward)
                .projected_areas(toward)
                .sum::<f64>()
                / e.area
        }
    }
}

/// The normal groups ([`Orientation`]) of a cluster as the other end of a link sees them: with item
/// buffers, by what the direction bucket toward the other end leaves visible of each group (cached,
/// [`ItemBuffers`]).
pub struct Groups<'a> {
    orientation: &'a Orientation,
    visible: Option<VisibleAreas>,
}

/// Draws by area within a group before a visible-area draw of a group walks its members (each draw is
/// kept with the patch's visible fraction as probability).
const REJECTION_TRIES: usize = 32;

impl Groups<'_> {
    /// Visible fraction of the patch at position `k` of the cluster's contents (1 without item
    /// buffers).
    pub fn fraction(&self, k: u32) -> f32 {
        self.visible
            .as_ref()
            .map_or(1.0, |visible| visible.fraction(k as usize))
    }

    /// Projected area of each group toward the point `toward`, of its visible area with item buffers
    /// ([`Orientation::projected_areas_with`]).
    pub fn projected_areas(&self, toward: DVec3) -> impl Iterator<Item = f64> + '_ {
        // The area of each group the other end can see: its visible area, or without item buffers
        // all of it.
        let mut visible = self
            .visible
            .as_ref()
            .map(|visible| visible.group_areas(self.orientation));
        let areas = self
            .orientation
            .groups
            .iter()
            .map(move |g| match &mut visible {
                Some(areas) => areas.next().map_or(0.0, f64::from),
                None => g.area,
            });
        self.orientation.projected_areas_with(areas, toward)
    }

    /// A member (a position in the cluster's contents) of group `group` drawn with probability
    /// proportional to its visible area `A_k f_k`: drawn by area and kept with probability `f_k`,
    /// which takes `A_g / Σ_k A_k f_k` draws on average, or after [`REJECTION_TRIES`] failures
    /// (a group nearly all hidden) found by walking the group's running visible area.
    fn sample_member(&self, group: usize, rng: &mut Pcg64Mcg) -> u32 {
        let Some(visible) = &self.visible else {
            return self.orientation.member_at(group, rng.random());
        };
        for _ in 0..REJECTION_TRIES {
            let k = self.orientation.member_at(group, rng.random());
            if rng.random::<f32>() < visible.fraction(k as usize) {
                return k;
            }
        }
        let o = self.orientation;
        let range = o.groups[group].members.start as usize..o.groups[group].members.end as usize;
        let visible_area = |i: usize| {
            let before = if i == 0 {
                0.0
            } else {
                o.cumulative_area[i - 1]
            };
            (o.cumulative_area[i] - before) * f64::from(visible.fraction(o.members[i] as usize))
        };
        let target = rng.random::<f64>() * range.clone().map(visible_area).sum::<f64>();
        let mut running = 0.0;
        for i in range.clone() {
            running += visible_area(i);
            if running > target {
                return o.members[i];
            }
        }
        o.members[range.end - 1]
    }
}

/// The normal groups of cluster `id` seen from the point `toward` (see [`Groups`]). With item buffers
/// a group's projected area is `Σ_k A_k f_k max(0, n̄ · d)` (its visible area, its own mean normal
/// `n̄` and the direction `d` from its centroid), standing for the sum over its patches with each
/// patch's own normal and direction to `toward` (Smits et al. 1994's oriented transfer times §6.1's
/// visible fractions): the approximation [`Orientation`] makes without item buffers (exact while every
/// member faces `toward`, up to the parallax of the visible members about the group's centroid), and
/// what lets a cluster link cost O(groups) instead of O(patches).
pub fn groups_toward(h: &Hierarchy, id: ElementId, toward: DVec3) -> Groups<'_> {
    let orientation = &h.cluster(id).expect("a cluster").orientation;
    let visible = h
        .item_buffers
        .as_ref()
        .map(|buffers| visible_areas(h, buffers, id, bucket_toward(h, id, toward)));
    Groups {
        orientation,
        visible,
    }
}

/// What the item buffer of cluster `id` along direction bucket `bucket` leaves visible: each patch's
/// visible fraction `f_k` (Sillion–Drettakis §6.1: "the projected area of each patch visible from the
/// direction of the source") and each normal group's visible area, drawn once per (cluster, bucket)
/// and cached.
fn visible_areas(h: &Hierarchy, buffers: &ItemBuffers, id: ElementId, bucket: u16) -> VisibleAreas {
    buffers.visible_areas(id, bucket, |along| {
        let cluster = h.cluster(id).expect("a cluster");
        let contents = h.contents(cluster);
        let shapes: Vec<Shape> = contents.iter().map(|&s| *h.element(s).shape()).collect();
        let areas: Vec<f64> = contents.iter().map(|&s| h.element(s).area).collect();
        let fractions = visible_fractions(&shapes, along);
        VisibleAreas::new(&cluster.orientation, &areas, &fractions)
    })
}

/// The transport `A_i F_ij` a link can carry (per unit source radiance, in the power oracle's units of
/// area): `min(A_i, A_j, A_i A_j / (π r²))` between well-separated ends (centre distance `r` at least
/// the sum of the bounding-sphere radii), every cosine and the visibility bounded by 1 (`F_ij ≤ 1` and
/// reciprocity give the first two); `min(A_i, A_j)` when the bounding spheres overlap, so that close
/// ends are always split. Like eq. (1)'s centre estimate it is not a strict bound across the ends.
pub fn transport_bound(h: &Hierarchy, receiver: ElementId, source: ElementId) -> f64 {
    let (a_i, a_j) = (h.element(receiver).area, h.element(source).area);
    let r = (h.center_of(receiver) - h.center_of(source)).length();
    let near = a_i.min(a_j);
    if r <= SourceSphere::of(h, receiver).radius + SourceSphere::of(h, source).radius {
        return near;
    }
    near.min(a_i * a_j / (PI * r * r))
}

/// The sphere about an element's centre ([`Hierarchy::center_of`]) that holds its bounding box: outside
/// it a link's centre estimate is bounded (see the module documentation).
pub struct SourceSphere {
    pub centre: DVec3,
    pub radius: f64,
}

impl SourceSphere {
    pub fn of(h: &Hierarchy, id: ElementId) -> Self {
        let (centre, b) = (h.center_of(id), h.bounds_of(id));
        let farthest = (centre - b.min).abs().max((b.max - centre).abs());
        SourceSphere {
            centre,
            radius: farthest.length(),
        }
    }

    /// Whether the sphere reaches into the box `bounds` (a receiver's): some receiver point may then
    /// lie inside it, where nothing bounds the centre estimate.
    pub fn reaches(&self, bounds: &crate::geometry::Aabb) -> bool {
        let nearest = self.centre.clamp(bounds.min, bounds.max);
        (nearest - self.centre).length() < self.radius
    }
}

/// Whether the pair can exchange light, when one end is a cluster: a surface must have part of the
/// cluster's box strictly in front of it.
pub fn cluster_can_interact(h: &Hierarchy, receiver: ElementId, source: ElementId) -> bool {
    let faces_box = |surface: ElementId, cluster: ElementId| {
        let shape = h.element(surface).shape();
        let (n, p) = (shape.normal(), shape.vertices()[0]);
        let b = h.bounds_of(cluster);
        let tolerance = 1e-9 * shape.diameter().max(b.diagonal());
        (0..8).any(|k| {
            let corner = DVec3::new(
                if k & 1 == 0 { b.min.x } else { b.max.x },
                if k & 2 == 0 { b.min.y } else { b.max.y },
                if k & 4 == 0 { b.min.z } else { b.max.z },
            );
            n.dot(corner - p) > tolerance
        })
    };
    match (h.is_cluster(receiver), h.is_cluster(source)) {
        (true, true) => receiver != source,
        (true, false) => faces_box(source, receiver),
        (false, true) => faces_box(receiver, source),
        (false, false) => unreachable!("surface pairs are tested by refine::can_interact"),
    }
}

/// Where visibility samples of a link end are drawn: uniformly on a surface, or on a cluster's patches
/// with probability proportional to their projected area toward the other end (`A_k max(0, cos_k)`:
/// by normal group, then by area within the group; with item buffers the visible areas `A_k f_k` of
/// the bucket toward the other end, [`groups_toward`]), so that what the mean cosine already discounts
/// (back faces, patches hidden by the cluster's own contents) is not counted a second time as
/// occluded.
enum SampleEnd<'a> {
    Surface {
        shape: &'a crate::geometry::Shape,
        polygon: usize,
    },
    Cluster {
        surfaces: &'a [ElementId],
        groups: Groups<'a>,
        /// Running projected area over the groups.
        cumulative: Vec<f64>,
    },
}

impl<'a> SampleEnd<'a> {
    fn new(h: &'a Hierarchy, id: ElementId, toward: DVec3) -> Self {
        match &h.element(id).kind {
            ElementKind::Surface(s) => SampleEnd::Surface {
                shape: &s.shape,
                polygon: h.patch_of(id).polygon,
            },
            ElementKind::Cluster(c) => {
                let groups = groups_toward(h, id, toward);
                let cumulative = groups
                    .projected_areas(toward)
                    .scan(0.0, |sum, a| {
                        *sum += a;
                        Some(*sum)
                    })
                    .collect();
                SampleEnd::Cluster {
                    surfaces: h.contents(c),
                    groups,
                    cumulative,
                }
            }
        }
    }

    /// [`mean_cosine`] of this end (element `id`, toward `toward`); with item buffers, from the visible
    /// projected areas its sampling weights already hold (their running sum, the same additions in the
    /// same order), rather than drawing on the item buffer cache a second time.
    fn mean_cosine(
        &self,
        h: &Hierarchy,
        id: ElementId,
        toward: DVec3,
        kind: ClusteringKind,
    ) -> f64 {
        let area = h.element(id).area;
        match self {
            SampleEnd::Cluster {
                groups: Groups {
                    visible: Some(_), ..
                },
                cumulative,
                ..
            } if area > 0.0 => cumulative.last().copied().unwrap_or(0.0) / area,
            _ => mean_cosine(h, id, toward, kind),
        }
    }

    /// A sample point, the normal of the surface it lies on and its polygon, or `None` when nothing
    /// at this end faces the other.
    fn sample(&self, h: &Hierarchy, rng: &mut Pcg64Mcg) -> Option<(DVec3, DVec3, usize)> {
        let uv = DVec2::new(rng.random(), rng.random());
        match self {
            SampleEnd::Surface { shape, polygon } => {
                Some((shape.sample_uniform(uv), shape.normal(), *polygon))
            }
            SampleEnd::Cluster {
                surfaces,
                groups,
                cumulative,
            } => {
                let total = *cumulative.last()?;
                if total <= 0.0 {
                    return None;
                }
                let target = rng.random::<f64>() * total;
                let index = cumulative
                    .partition_point(|&p| p <= target)
                    .min(cumulative.len() - 1);
                let member = surfaces[groups.sample_member(index, rng) as usize];
                let point = h.element(member).shape().sample_uniform(uv);
                let patch = h.patch_of(member);
                Some((point, patch.normal, patch.polygon))
            }
        }
    }
}

/// The coupling of a link with a cluster at one or both ends (see the module documentation).
pub fn couple_cluster(
    h: &Hierarchy,
    visibility: &dyn Visibility,
    receiver: ElementId,
    source: ElementId,
    settings: &CouplingSettings,
) -> Coupling {
    let size = h.basis_size();
    let kind = h.clustering;
    let (r, s) = (h.element(receiver), h.element(source));
    let (r_centre, s_centre) = (h.center_of(receiver), h.center_of(source));
    if SourceSphere::of(h, source).reaches(&h.bounds_of(receiver)) {
        return match &r.kind {
            ElementKind::Cluster(_) => unplaced_near_coupling(h),
            ElementKind::Surface(_) => near_coupling(h, visibility, receiver, source, settings),
        };
    }
    let mut rng = link_rng(settings.seed, receiver, source, CLUSTER_STREAM);
    let mut rays = 0u64;
    let (receiver_end, source_end) = (
        SampleEnd::new(h, receiver, s_centre),
        SampleEnd::new(h, source, r_centre),
    );
    // With item buffers the end clusters' own contents are transparent to the link's rays: how much of
    // each patch the others hide is what the buffers weigh the sample points by (§6.1), and a ray from
    // a point of a partly hidden patch must not count that hiding again. Without them the rays are
    // all that sees the contents' mutual occlusion.
    let inside_an_end = |polygon: usize| {
        h.item_buffers.is_some()
            && [receiver, source]
                .into_iter()
                .any(|end| h.is_cluster(end) && h.cluster_holds_polygon(end, polygon))
    };
    // The receiver's sample points (with their surfaces' normals) are kept when drawn here (`x`
    // `None`): a cluster receiver's kernel error is taken at them.
    let mut receiver_points = Vec::new();
    // `x`: a receiver point and its polygon, or `None` to draw one per sample.
    let mut sample_visibility = |x: Option<(DVec3, usize)>, samples: usize, rng: &mut Pcg64Mcg| {
        let mut total = 0.0;
        for _ in 0..samples {
            let from = match x {
                Some(x) => Some(x),
                None => receiver_end.sample(h, rng).map(|(point, normal, polygon)| {
                    receiver_points.push((point, normal));
                    (point, polygon)
                }),
            };
            if let (Some((from, polygon)), Some((to, ..))) = (from, source_end.sample(h, rng)) {
                total += visibility.transmittance_past_onto(from, to, polygon, &inside_an_end);
                rays += 1;
            }
        }
        total / samples as f64
    };
    let c_source = source_end.mean_cosine(h, source, r_centre, kind);
    let mut block = vec![0.0; size * size];
    // Per receiver node: δ_{j,1}(x_k) (the only non-zero δ_{j,β}) and the point factor K_{j,1}(x_k);
    // the receiver-averaged transfer with visibility, and without.
    let (errors, node_factors, transfer, unoccluded) = match &r.kind {
        ElementKind::Cluster(_) => {
            let c_receiver = receiver_end.mean_cosine(h, receiver, s_centre, kind);
            let r2 = (s_centre - r_centre).length_squared().max(1e-300);
            // The source's factor is bounded by 1 before the receiver's mean cosine scales it, so that
            // no patch the cluster shares the irradiance with (by its projected area) gets a factor
            // above its own cosine: a patch-level bound that keeps near clusters from feeding back
            // more than they receive (with item buffers the shares concentrate on few patches).
            let open = c_receiver * (s.area * c_source / (PI * r2)).min(1.0);
            let v = if open > 0.0 {
                sample_visibility(None, CLUSTER_RECEIVER_SAMPLES, &mut rng)
            } else {
                1.0
            };
            block[0] = open * v;
            // δ at the cluster's one node: the largest difference, over the receiver's sample
            // points, between the factor the sweep gives the point's patch (a patch shares the
            // cluster's irradiance by its cosine toward the source's centre, all at the centres'
            // distance; evenly when isotropic without item buffers) and the point kernel there (its
            // own distance and cosine), times the link's visibility: what the centre-to-centre
            // transfer misplaces across the cluster (eq. (6)'s δ_j for a receiver without surface
            // nodes).
            let to_source = (s_centre - r_centre) / r2.sqrt();
            let factor = |cosines: f64, distance_squared: f64| {
                (s.area * cosines.max(0.0) / (PI * distance_squared.max(1e-300))).min(1.0)
            };
            // The source's cosine toward the point: exact for a surface source, the mean toward the
            // receiver's centre for a cluster (its groups' cosines change little across a far
            // receiver).
            let source_cosine = |d: DVec3| match &s.kind {
                ElementKind::Surface(surface) => {
                    (-h.patches[surface.patch as usize].normal.dot(d)).max(0.0)
                }
                ElementKind::Cluster(_) => c_source,
            };
            let error = receiver_points
                .iter()
                .map(|&(x, n)| {
                    let shared = match kind {
                        ClusteringKind::Isotropic if h.item_buffers.is_none() => open,
                        _ => factor(c_source * n.dot(to_source), r2),
                    };
                    let d = s_centre - x;
                    let unit = d / d.length().max(1e-300);
                    let kernel = factor(source_cosine(unit) * n.dot(unit), d.length_squared());
                    v * (shared - kernel)
                })
                .fold(0.0f64, |a, b| if b.abs() > a.abs() { b } else { a });
            (vec![error as f32], vec![block[0] as f32], block[0], open)
        }
        ElementKind::Surface(surface) => {
            let shape = &surface.shape;
            let patch = &h.patches[surface.patch as usize];
            let (normal, polygon) = (patch.normal, patch.polygon);
            let nodes = nodes_on(shape, rule(shape.domain(), settings.cubature_degree));
            let mut inner = vec![0.0; nodes.len()];
            let mut unoccluded = 0.0;
            for (k, x) in nodes.iter().enumerate() {
                let d = s_centre - x.point;
                let r2 = d.length_squared().max(1e-300);
                let cos = normal.dot(d) / r2.sqrt();
                let open = (s.area * c_source * cos.max(0.0) / (PI * r2)).min(1.0);
                if open <= 0.0 {
                    continue;
                }
                unoccluded += x.weight * open / r.area;
                inner[k] = open
                    * sample_visibility(
                        Some((x.point, polygon)),
                        CLUSTER_VISIBILITY_SAMPLES,
                        &mut rng,
                    );
            }
            let (transfer, errors) = project_onto_receiver(
                h,
                shape,
                &nodes,
                settings.cubature_degree,
                &inner,
                &mut block,
            );
            (
                errors,
                inner.iter().map(|&f| f as f32).collect(),
                transfer,
                unoccluded,
            )
        }
    };
    sampled_coupling(&block, &errors, &node_factors, transfer, unoccluded, rays)
}

/// A surface receiver's coupling block from the point factors `inner` (the constant source's
/// `K_{j,1}(x_k)`, visibility included) at its cubature `nodes`, those of the rule of `degree`
/// (Bekaert–Willems Algorithm 4.1 steps 3–4): the moments `Σ_k w_k φ_α(x_k) K(x_k) / A_i` into the
/// block's first column, solved for coefficients on a quad that is not a parallelogram; returns the
/// receiver-averaged transfer (the constant moment) and `δ_{j,1}(x_k)`, the projection's value at
/// each node minus the point factor.
fn project_onto_receiver(
    h: &Hierarchy,
    shape: &Shape,
    nodes: &[crate::geometry::cubature::Node],
    degree: usize,
    inner: &[f64],
    block: &mut [f64],
) -> (f64, Vec<f32>) {
    let size = h.basis_size();
    let area = shape.area();
    let phi = h.basis.rule_values(shape.domain(), degree);
    debug_assert_eq!(phi.len(), nodes.len() * size, "nodes of another rule");
    for (k, (x, value)) in nodes.iter().zip(inner).enumerate() {
        let w = x.weight / area;
        for alpha in 0..size {
            block[alpha * size] += w * phi[k * size + alpha] * value;
        }
    }
    let transfer = block[0];
    // Moments to coefficients on a trapezoid-like quad (Algorithm 4.1 step 4a).
    if let Some(overlap) = h.basis.overlap(shape, area) {
        overlap.solve_columns(block, size);
    }
    let errors = inner
        .iter()
        .enumerate()
        .map(|(k, value)| {
            let projected: f64 = (0..size)
                .map(|alpha| block[alpha * size] * phi[k * size + alpha])
                .sum();
            (projected - value) as f32
        })
        .collect();
    (transfer, errors)
}

/// The most patches a near link's cluster source may hold: refinement splits a larger one
/// (`solvers::refine`), so that [`near_coupling`] sums every patch's exact factor at a bounded cost.
pub const NEAR_SOURCE_PATCHES: usize = 64;

/// The most patches a cluster receiver of a near link may hold to be split into them by refinement
/// (`solvers::refine`), whatever the link's bound: what a cluster gathers is shared among its
/// patches by their visible projected areas along one direction ([`ClusterSweep`]), which cannot
/// place light from a source beside it (the patches that face it may not face the direction from
/// centre to centre), so such a link carries nothing ([`unplaced_near_coupling`]) unless its
/// receiver is split. Four is a plate's two polygons, both sides each, the thinnest object a scene
/// holds: a lamp housing's end plate 10 cm from the next housing took 29% of its light that way.
/// A larger receiver is left as it was (splitting every one costs office3 2.6× the memory and the
/// classroom 1.9× the time for no gain in error; up to 8 patches, office3 +11 MB; BENCHMARKS.md,
/// "Near links carry light").
pub const NEAR_RECEIVER_PATCHES: usize = 4;

/// A patch a near link's source stands for, with the weight its exact factor counts by.
struct NearPatch<'a> {
    shape: &'a Shape,
    /// 1 when every patch is summed; `A / (n A_k)` for one of `n` draws by area.
    weight: f64,
}

/// The patches of `source` for [`near_coupling`]: a surface itself; a cluster's patch roots, all of
/// them up to [`NEAR_SOURCE_PATCHES`] (what refinement leaves). A larger cluster (a link admitted
/// unsplit because a budget stopped refinement) has that many drawn with probability `A_k / A` (by
/// normal group, then within it) and weighted `A / (n A_k)`: an unbiased estimate of the sum of
/// factors at a bounded number of contour integrals.
fn near_source_patches<'a>(
    h: &'a Hierarchy,
    source: ElementId,
    rng: &mut Pcg64Mcg,
) -> Vec<NearPatch<'a>> {
    let Some(cluster) = h.cluster(source) else {
        return vec![NearPatch {
            shape: h.element(source).shape(),
            weight: 1.0,
        }];
    };
    let contents = h.contents(cluster);
    if contents.len() <= NEAR_SOURCE_PATCHES {
        return contents
            .iter()
            .map(|&p| NearPatch {
                shape: h.element(p).shape(),
                weight: 1.0,
            })
            .collect();
    }
    let o = &cluster.orientation;
    let total: f64 = o.groups.iter().map(|g| g.area).sum();
    if total <= 0.0 {
        return Vec::new();
    }
    (0..NEAR_SOURCE_PATCHES)
        .map(|_| {
            let mut target = rng.random::<f64>() * total;
            let group = o
                .groups
                .iter()
                .position(|g| {
                    target -= g.area;
                    target < 0.0
                })
                .unwrap_or(o.groups.len() - 1);
            let patch = contents[o.member_at(group, rng.random()) as usize];
            NearPatch {
                shape: h.element(patch).shape(),
                weight: total / (NEAR_SOURCE_PATCHES as f64 * h.element(patch).area.max(1e-300)),
            }
        })
        .collect()
}

/// The coupling of a near link into a surface (the source's sphere reaches the receiver's box,
/// where the centre estimate is unbounded): at each receiver cubature node, the exact unoccluded
/// factor of the source's patches (Lambert's contour integral per patch, [`point_to_polygon`],
/// clipped to the node's horizon; [`near_source_patches`]) times the transmittance of
/// [`CLUSTER_VISIBILITY_SAMPLES`] rays to points drawn on those patches in proportion to their
/// factors, rays that see the source's own contents (their mutual hiding is what they measure here:
/// no item buffer is read); projected onto the receiver's basis like any coupling
/// ([`project_onto_receiver`]). The source sends what [`ClusterSweep`] says it sends toward the
/// receiver.
///
/// Why not nothing, as RenderPark's Galerkin radiosity does for overlapping bounding boxes (and this
/// solver until 2026-11-30): a near link's bound `ρ B min(A_i, A_j)` is small at a small end, so
/// refinement leaves many of them in place, and between neighbouring objects they hold much of the
/// light: 11% of what clusters should send to the classroom's receivers, half of it within two
/// source radii (BENCHMARKS.md, "The end plate in the slot"). Exact per-patch factors cannot exceed
/// what the patches subtend, so the factors a receiver gathers stay bounded (closure), as the centre
/// estimate did not (module documentation); a node's factor is capped at 1 where overlapping patches'
/// open factors add up past it.
fn near_coupling(
    h: &Hierarchy,
    visibility: &dyn Visibility,
    receiver: ElementId,
    source: ElementId,
    settings: &CouplingSettings,
) -> Coupling {
    let size = h.basis_size();
    let mut rng = link_rng(settings.seed, receiver, source, CLUSTER_STREAM);
    let patches = near_source_patches(h, source, &mut rng);
    let r = h.element(receiver);
    let shape = r.shape();
    let patch = h.patch_of(receiver);
    let nodes = nodes_on(shape, rule(shape.domain(), settings.cubature_degree));
    let (mut rays, mut unoccluded) = (0u64, 0.0);
    // The running sum of the patches' factors at a node, one buffer for all nodes.
    let mut running = Vec::with_capacity(patches.len());
    let inner: Vec<f64> = nodes
        .iter()
        .map(|x| {
            running.clear();
            running.extend(patches.iter().scan(0.0, |sum, p| {
                *sum += p.weight * point_to_polygon(x.point, patch.normal, p.shape);
                Some(*sum)
            }));
            let open = running.last().copied().unwrap_or(0.0);
            if open <= 0.0 {
                return 0.0;
            }
            let mut seen = 0.0;
            for _ in 0..CLUSTER_VISIBILITY_SAMPLES {
                let target = rng.random::<f64>() * open;
                let k = running
                    .partition_point(|&p| p <= target)
                    .min(running.len() - 1);
                let y = patches[k]
                    .shape
                    .sample_uniform(DVec2::new(rng.random(), rng.random()));
                seen += visibility.transmittance_onto(x.point, y, patch.polygon);
                rays += 1;
            }
            unoccluded += x.weight * open.min(1.0) / r.area;
            (open * seen / CLUSTER_VISIBILITY_SAMPLES as f64).min(1.0)
        })
        .collect();
    let mut block = vec![0.0; size * size];
    let (transfer, errors) = project_onto_receiver(
        h,
        shape,
        &nodes,
        settings.cubature_degree,
        &inner,
        &mut block,
    );
    let node_factors: Vec<f32> = inner.iter().map(|&f| f as f32).collect();
    sampled_coupling(&block, &errors, &node_factors, transfer, unoccluded, rays)
}

/// A cluster link's [`Coupling`] from its block, node errors and node factors, its receiver-averaged
/// `transfer` with visibility and without (`unoccluded`), and the rays its
/// [`CLUSTER_VISIBILITY_SAMPLES`] per node cast: `v` is their ratio, the visibility error
/// `F_unoccluded √(v (1 − v))` (Sillion–Drettakis Appendix A, eq. (10)).
fn sampled_coupling(
    block: &[f64],
    errors: &[f32],
    node_factors: &[f32],
    transfer: f64,
    unoccluded: f64,
    rays: u64,
) -> Coupling {
    let v = visible_fraction(transfer, unoccluded);
    Coupling {
        coupling: LinkCoupling::constant_source(
            block,
            errors,
            node_factors,
            v as f32,
            (unoccluded * (v * (1.0 - v)).sqrt()) as f32,
        ),
        unoccluded,
        source_nodes: CLUSTER_VISIBILITY_SAMPLES,
        rays,
        shaft: None,
        rays_saved: 0,
    }
}

/// The coupling of a near link into a cluster (larger than [`NEAR_RECEIVER_PATCHES`], or left
/// unsplit by a budget): nothing is transferred, since the cluster's sharing could not place it
/// (RenderPark's Galerkin radiosity does the same for overlapping bounding boxes), and its error
/// coefficient is 0: its bound is already below the refinement threshold, and counting it as error
/// made office3's error control refine past its memory (95 → 106 MB) for the classroom 6.8 → 6.0%
/// (BENCHMARKS.md, "The end plate in the slot").
fn unplaced_near_coupling(h: &Hierarchy) -> Coupling {
    let size = h.basis_size();
    Coupling {
        coupling: LinkCoupling::constant_source(&vec![0.0; size * size], &[0.0], &[0.0], 1.0, 0.0),
        unoccluded: 0.0,
        source_nodes: CLUSTER_VISIBILITY_SAMPLES,
        rays: 0,
        shaft: None,
        rays_saved: 0,
    }
}

/// The visible projected area of each patch of cluster `id` seen along the centre direction `d` of
/// direction bucket `bucket` (the one its item buffer is drawn along), `w_k = A_k max(0, n_k · d) f_k`,
/// with `f_k` its visible fraction in the cluster's item buffer of that bucket (Sillion–Drettakis
/// §6.1): every link in the bucket shares one set of weights; couplings take the groups' directions
/// to a point instead ([`groups_toward`]).
fn visible_areas_along(
    h: &Hierarchy,
    contents: &Contents,
    buffers: &ItemBuffers,
    id: ElementId,
    bucket: u16,
) -> Vec<f64> {
    let along = bucket_direction(bucket);
    let visible = visible_areas(h, buffers, id, bucket);
    contents
        .of(h, id)
        .iter()
        .zip(visible.fractions())
        .map(|(&(normal, area), f)| area * normal.dot(along).max(0.0) * f64::from(f))
        .collect()
}

/// What a sweep reads of the clusters' patch roots, by position in
/// [`Hierarchy::cluster_surfaces`] (each cluster's contents are a range of it): their normals and
/// areas, and their radiances as the sweep begins. Walking a cluster's contents then reads these
/// dense arrays in order instead of an element record per patch scattered over the hierarchy (most
/// of a sweep's cost on office3).
#[derive(Default)]
struct Contents {
    geometry: Vec<(DVec3, f64)>,
    radiance: Vec<Rgb>,
}

impl Contents {
    fn new(h: &Hierarchy) -> Self {
        Contents {
            geometry: h
                .cluster_surfaces
                .iter()
                .map(|&s| (h.patch_of(s).normal, h.element(s).area))
                .collect(),
            radiance: h
                .cluster_surfaces
                .iter()
                .map(|&s| h.average_radiance(s))
                .collect(),
        }
    }

    /// The range of [`Hierarchy::cluster_surfaces`] that cluster `id` holds.
    fn range(h: &Hierarchy, id: ElementId) -> std::ops::Range<usize> {
        let contents = &h.cluster(id).expect("a cluster").contents;
        contents.start as usize..contents.end as usize
    }

    /// Normal and area of each patch of cluster `id`, in content order.
    fn of(&self, h: &Hierarchy, id: ElementId) -> &[(DVec3, f64)] {
        &self.geometry[Self::range(h, id)]
    }
}

/// What the clusters exchange in one gathering sweep, computed once per sweep (the part that depends
/// on the links alone, [`ClusterPlan`], once per solve) so that a cluster link costs O(1) however many
/// patches its ends hold, plus O(cluster size) per (cluster, direction bucket) that links carrying
/// light use ([`carries_light`]):
/// * *sent*: with item buffers, the radiance a cluster sends along a bucket, the average of its
///   patches' radiances over their visible projected areas along the bucket's centre direction,
///   `Σ_k L_k w_k / Σ_k w_k` ([`visible_areas_along`]), so that the coupling (which holds the exact
///   `Σ_k w_k` toward the receiver) carries the intensity of the patches the other end can see (§6.1,
///   "the energy leaving a cluster"); without item buffers, the cluster's average radiance;
/// * *pushed*: the irradiance every patch root receives from the links of the clusters above it
///   (push-pull through clusters): per cluster, each link's gathered irradiance `H = F L_sent` is
///   spread evenly (isotropic), by normal group (oriented, [`crate::hierarchy::clusters::Orientation`]:
///   O(groups) per link), or, with item buffers, summed per bucket of the direction toward the link's
///   source and shared once per bucket by the visible projected areas along its centre direction,
///   `H_s = H A_cluster w_s / (A_s Σ_k w_k)`: the patches receive the power the links delivered.
///
/// Approximation (item buffers only): the per-patch direction toward the other end's centre is
/// replaced by the bucket's centre direction, the one the item buffer already assumes; each cosine
/// then changes by at most the angle between the two directions (the bucket's half-diagonal, under
/// 0.2 rad, plus the parallax of the patch within the cluster seen from the other end). Shares still
/// sum to one, so the power each link delivers is unchanged and energy is conserved exactly.
///
/// Every value is a pure function of the hierarchy's radiances (sorted keys, sums in link order), so
/// the result does not depend on the thread count. Gauss–Seidel and Southwell read it as of the start
/// of the sweep, as they already read a cluster's pulled-up average radiance.
pub struct ClusterSweep {
    /// (source cluster, direction bucket) in use by links, sorted, with the radiance sent along it;
    /// empty without item buffers.
    sent: Vec<(u16, Sent)>,
    /// Where each cluster's entries of `sent` begin, by cluster id less the first cluster's (clusters
    /// are the elements from the first after the patch roots up to the root), and where they end: a
    /// cluster link finds its source's few buckets without a binary search over every key (a cache
    /// miss per step on large scenes, 10% of a 100k-polygon hall's time).
    first: Vec<u32>,
    /// Irradiance pushed from the clusters to each patch root, by the root's element id (patch roots
    /// are the first elements); empty without clusters.
    pushed: Vec<Rgb>,
    /// The zero-mean variation over the patch roots that have one of what [`ClusterSweep::pushed`]
    /// gives them, as coefficients of the basis' first three functions ([`Gradient`]), sorted by id.
    slopes: Vec<(ElementId, Slope)>,
    /// The patch roots' geometry and radiances in content order; empty without item buffers.
    contents: Contents,
}

/// The part of [`ClusterSweep`] that depends on the links alone: the (source cluster, direction
/// bucket) pairs that links carrying light use, sorted, and where each cluster's pairs begin. Every
/// sweep over one set of links reads the same plan, so a solve makes it once for all its sweeps (with
/// the rest of their [`super::gathering::SweepPlan`]) instead of once per sweep (a sort of a million
/// cluster links' keys: 0.23 s of the classroom's sixteen sweeps, BENCHMARKS.md, "One cross product
/// per vector area"). Valid while the links are unchanged; made anew after refinement.
#[derive(Default)]
pub struct ClusterPlan {
    /// The buckets of each cluster in use, sorted, the clusters one after another (a bucket alone:
    /// `first` says whose it is, and a plan held through the sweeps then costs office3 2 bytes an
    /// entry instead of 8).
    buckets: Vec<u16>,
    /// Where each cluster's entries of `buckets` begin, by cluster id less the first cluster's, and
    /// where they end ([`ClusterSweep`]'s `first`).
    first: Vec<u32>,
    /// The links the plan was made for (checked in debug builds).
    links: usize,
}

impl ClusterPlan {
    /// The plan of the hierarchy's current links (empty without clusters or item buffers, where
    /// clusters send their average radiance).
    pub fn new(h: &Hierarchy) -> Self {
        let links = if cfg!(debug_assertions) {
            h.link_count()
        } else {
            0
        };
        let (Some(root), Some(_)) = (h.root_cluster, &h.item_buffers) else {
            return ClusterPlan {
                links,
                ..ClusterPlan::default()
            };
        };
        let mut keys: Vec<(ElementId, u16)> = (0..h.elements.len() as ElementId)
            .into_par_iter()
            .flat_map_iter(|id| {
                h.element(id)
                    .links
                    .iter()
                    .filter(|l| h.is_cluster(l.source) && carries_light(l))
                    .map(move |l| (l.source, bucket_toward(h, l.source, h.center_of(id))))
            })
            .collect();
        keys.par_sort_unstable();
        keys.dedup();
        let base = h.patches.len();
        let mut first = vec![0u32; root as usize + 2 - base];
        for &(cluster, _) in &keys {
            first[cluster as usize - base + 1] += 1;
        }
        for k in 1..first.len() {
            first[k] += first[k - 1];
        }
        ClusterPlan {
            buckets: keys.into_iter().map(|(_, bucket)| bucket).collect(),
            first,
            links,
        }
    }
}

impl ClusterSweep {
    /// The exchange for the hierarchy's current radiances and links.
    pub fn new(h: &Hierarchy) -> Self {
        Self::planned(h, &ClusterPlan::new(h))
    }

    /// [`ClusterSweep::new`] with the links' part already made (`plan`, of the current links).
    pub fn planned(h: &Hierarchy, plan: &ClusterPlan) -> Self {
        let mut sweep = Self::sent_planned(h, plan);
        if h.root_cluster.is_some() {
            let pushed = sweep.push_from_clusters(h, Sharing::Pushed);
            (sweep.pushed, sweep.slopes) = (pushed.means, pushed.slopes);
        }
        sweep
    }

    /// The table of what clusters send, without the irradiance pushed down from them: what the error
    /// estimate's terms ([`moved_by_exposure`], [`moved_by_sending`]) read, each (cluster, bucket)
    /// computed once however many links ask for it. Computing it per link instead cost the
    /// classroom's estimates (`--accuracy 10% --max-passes 6`, a million cluster links) 2.1 s against
    /// 1.8 s, office3's 0.46 s against 0.40 s.
    pub fn sent_only(h: &Hierarchy) -> Self {
        Self::sent_planned(h, &ClusterPlan::new(h))
    }

    /// [`ClusterSweep::sent_only`] with the links' part already made.
    fn sent_planned(h: &Hierarchy, plan: &ClusterPlan) -> Self {
        debug_assert_eq!(plan.links, h.link_count(), "a plan of other links");
        let mut sweep = ClusterSweep {
            sent: Vec::new(),
            first: Vec::new(),
            pushed: Vec::new(),
            slopes: Vec::new(),
            contents: Contents::default(),
        };
        if let (Some(_), Some(buffers)) = (h.root_cluster, &h.item_buffers) {
            sweep.contents = Contents::new(h);
            sweep.first = plan.first.clone();
            let contents = &sweep.contents;
            let base = h.patches.len() as ElementId;
            sweep.sent = (0..plan.first.len().saturating_sub(1))
                .into_par_iter()
                .uneven()
                .flat_map_iter(|k| {
                    let cluster = base + k as ElementId;
                    let own = plan.first[k] as usize..plan.first[k + 1] as usize;
                    plan.buckets[own].iter().map(move |&bucket| {
                        (bucket, sent_along(h, contents, buffers, cluster, bucket))
                    })
                })
                .collect();
        }
        sweep
    }

    /// The (average) radiance that `source` sends toward the point `toward`, to multiply a link's
    /// coupling with (see the type's documentation).
    pub fn radiance_toward(
        &self,
        h: &Hierarchy,
        source: ElementId,
        toward: DVec3,
        visibility: f32,
    ) -> Rgb {
        self.sent_toward(h, source, toward).map_or_else(
            || h.average_radiance(source),
            |sent| {
                sent.through(
                    f64::from(visibility),
                    (toward - h.center_of(source)).length(),
                )
            },
        )
    }

    /// What cluster `source` sends toward the point `toward` ([`sent_along`]); `None` for a surface
    /// source or without item buffers (it sends its average radiance).
    fn sent_toward(&self, h: &Hierarchy, source: ElementId, toward: DVec3) -> Option<Sent> {
        let buffers = h.item_buffers.as_deref().filter(|_| h.is_cluster(source))?;
        let bucket = bucket_toward(h, source, toward);
        let index = source as usize - h.patches.len();
        let own = match (self.first.get(index), self.first.get(index + 1)) {
            (Some(&start), Some(&end)) => &self.sent[start as usize..end as usize],
            _ => &[],
        };
        Some(match own.binary_search_by_key(&bucket, |&(b, _)| b) {
            Ok(k) => own[k].1,
            // Not asked for by any link when the sweep began: computed on the spot, the same value.
            Err(_) => sent_along(h, &self.contents, buffers, source, bucket),
        })
    }

    /// The irradiance pushed from the clusters to element `id`, its mean over the element: non-zero
    /// at patch roots only.
    pub fn pushed(&self, id: ElementId) -> Rgb {
        self.pushed.get(id as usize).copied().unwrap_or(Rgb::BLACK)
    }

    /// How what [`ClusterSweep::pushed`] gives element `id` varies over it: coefficients of the basis'
    /// first three functions, of zero mean ([`Gradient`]); `None` but at patch roots with gradients.
    pub fn pushed_slope(&self, id: ElementId) -> Option<[Rgb; 3]> {
        let k = self.slopes.binary_search_by_key(&id, |&(p, _)| p).ok()?;
        Some(self.slopes[k].1.map(Rgb::from_f32))
    }

    /// Per patch root, by its element id: the irradiance [`ClusterSweep::pushed`] gives it from the
    /// clusters above it, or, for [`Sharing::MovedByExposure`], the sum over those clusters of how
    /// much sharing by exposure moved its share (zero without item buffers).
    fn push_from_clusters(&self, h: &Hierarchy, sharing: Sharing) -> Pushed {
        let kind = h.clustering;
        // Node rays where gradients use them ([`expose`]); the error estimate's sharing takes the
        // same fractions, without the slopes.
        let gradients = Gradient::new(h);
        let node_rays = gradients.is_some();
        let gradient = gradients.filter(|_| sharing == Sharing::Pushed);
        let with_links: Vec<ElementId> = (0..h.elements.len() as ElementId)
            .filter(|&id| h.is_cluster(id) && !h.element(id).links.is_empty())
            .collect();
        let share_of = |id: ElementId| {
            let cluster = h.cluster(id).expect("cluster");
            let e = h.element(id);
            let centre = h.center_of(id);
            let gathered = |link: &crate::hierarchy::Link| {
                self.radiance_toward(h, link.source, centre, link.coupling.visibility)
                    * link.coupling.form_factor()
            };
            let mut share = vec![Rgb::BLACK; h.contents(cluster).len()];
            // Per member, allocated at the first gradient: most clusters have none.
            let mut slopes: Vec<[Rgb; 3]> = Vec::new();
            match (&h.item_buffers, kind) {
                (Some(buffers), _) => {
                    let contents = h.contents(cluster);
                    let mut by_bucket: Vec<(u16, ElementId, Rgb, f64)> = e
                        .links
                        .iter()
                        .filter(|l| carries_light(l))
                        .map(|l| {
                            let target = h.center_of(l.source);
                            let v = f64::from(l.coupling.visibility);
                            (bucket_toward(h, id, target), l.source, gathered(l), v)
                        })
                        .collect();
                    // Stable: equal buckets keep link order, so the sums below do too.
                    by_bucket.sort_by_key(|&(bucket, ..)| bucket);
                    let geometry = self.contents.of(h, id);
                    // Shares `gathered` by `weights` into `into`, each patch's part varying over it
                    // as its gradient nodes' rays found (`nodes`, empty without), its mean as
                    // without gradients.
                    let share_exposed =
                        |gathered: Rgb,
                         weights: &[f64],
                         nodes: &[u8],
                         into: &mut [Rgb],
                         slopes: &mut Vec<[Rgb; 3]>| {
                            let Some(gradient) = gradient.as_ref().filter(|_| !nodes.is_empty())
                            else {
                                share_by_areas(geometry, e.area, gathered, weights, into);
                                return;
                            };
                            let factors = area_factors(geometry, e.area, weights);
                            for (k, (factor, &bits)) in factors.zip(nodes).enumerate() {
                                let Some(factor) = factor else {
                                    continue;
                                };
                                let p = gathered * factor;
                                into[k] += p;
                                let Some(d) = gradient.slope(h.element(contents[k]).shape(), bits)
                                else {
                                    continue;
                                };
                                if slopes.is_empty() {
                                    *slopes = vec![[Rgb::BLACK; 3]; into.len()];
                                }
                                for (s, d) in slopes[k].iter_mut().zip(d) {
                                    *s += p * d;
                                }
                            }
                        };
                    for run in by_bucket.chunk_by(|a, b| a.0 == b.0) {
                        let areas = visible_areas_along(h, &self.contents, buffers, id, run[0].0);
                        if areas.iter().sum::<f64>() > 0.0 {
                            let total: Rgb = run.iter().map(|&(_, _, g, _)| g).sum();
                            let (split, nodes) = buffers
                                .exposure(id, run[0].0, |exposure| {
                                    let nodes = if node_rays {
                                        exposed_nodes(exposure, areas.len())
                                    } else {
                                        Vec::new()
                                    };
                                    let split =
                                        ExposureSplit::new(&areas, |k| match nodes.get(k) {
                                            Some(&bits) => {
                                                node_fraction(h.element(contents[k]).shape(), bits)
                                            }
                                            None => exposed_bit(exposure, k),
                                        });
                                    (split, nodes)
                                })
                                .unwrap_or((None, Vec::new()));
                            let Some(split) = split else {
                                // Every visible patch reached, or none: all alike.
                                if sharing == Sharing::Pushed {
                                    share_exposed(total, &areas, &nodes, &mut share, &mut slopes);
                                }
                                continue;
                            };
                            // What each link gathered, to the exposed patches and to the others.
                            let (mut to_exposed, mut to_others) = (Rgb::BLACK, Rgb::BLACK);
                            for &(_, _, g, v) in run {
                                let (exposed, others) = exposure_shares(split.exposed_share(), v);
                                to_exposed += g * exposed;
                                to_others += g * others;
                            }
                            let mut shared = vec![Rgb::BLACK; share.len()];
                            let into = match sharing {
                                Sharing::Pushed => &mut share,
                                Sharing::MovedByExposure => &mut shared,
                            };
                            share_exposed(to_exposed, &split.exposed, &nodes, into, &mut slopes);
                            share_by_areas(geometry, e.area, to_others, &split.others, into);
                            if sharing == Sharing::MovedByExposure {
                                let mut plain = vec![Rgb::BLACK; share.len()];
                                share_by_areas(geometry, e.area, total, &areas, &mut plain);
                                for ((s, p), m) in share.iter_mut().zip(plain).zip(shared) {
                                    *s += (m - p).map(f64::abs);
                                }
                            }
                            continue;
                        }
                        if sharing == Sharing::MovedByExposure {
                            continue;
                        }
                        // Nothing visible faces the bucket's centre direction, yet the couplings
                        // (directions to the source) may have carried light: shared per link by
                        // the visible groups' directions to its source, as the coupling took
                        // them, so that no delivered power is lost.
                        let groups = Groups {
                            orientation: &cluster.orientation,
                            visible: Some(visible_areas(h, buffers, id, run[0].0)),
                        };
                        let mut group_share = vec![Rgb::BLACK; cluster.orientation.groups.len()];
                        for &(_, source, g, _) in run {
                            let target = h.center_of(source);
                            share_by_groups(&groups, e.area, g, target, &mut group_share);
                        }
                        spread_to_members(h, contents, &groups, &group_share, &mut share);
                    }
                }
                (None, ClusteringKind::Isotropic) => {
                    let even: Rgb = e.links.iter().map(gathered).sum();
                    share.iter_mut().for_each(|s| *s = even);
                }
                (None, _) => {
                    // H_s = H A_cluster cos_s / Σ_k A_k cos_k by normal group.
                    let groups = Groups {
                        orientation: &cluster.orientation,
                        visible: None,
                    };
                    let mut group_share = vec![Rgb::BLACK; cluster.orientation.groups.len()];
                    for link in &e.links {
                        let target = h.center_of(link.source);
                        share_by_groups(&groups, e.area, gathered(link), target, &mut group_share);
                    }
                    let contents = h.contents(cluster);
                    spread_to_members(h, contents, &groups, &group_share, &mut share);
                }
            }
            // Sparse, in single precision (a gradient is a coarse estimate): only what has one is
            // held while the run's other clusters are shared.
            let contents = h.contents(cluster);
            let slopes: Vec<(ElementId, Slope)> = contents
                .iter()
                .zip(slopes)
                .filter(|(_, s)| s.iter().any(|&s| s != Rgb::BLACK))
                .map(|(&p, s)| (p, s.map(Rgb::to_f32)))
                .collect();
            (share, slopes)
        };
        // Shares are computed in parallel a run of clusters at a time and added in cluster order
        // (the same sums whatever the threads), so that only a run's shares are held at once: all of
        // them hold an entry per patch per level of the cluster tree (4.7 MB a sweep on office3).
        let mut out = Pushed {
            means: vec![Rgb::BLACK; h.patches.len()],
            slopes: Vec::new(),
        };
        let mut rest = with_links.as_slice();
        while !rest.is_empty() {
            let mut entries = 0;
            let run = rest
                .iter()
                .take_while(|&&id| {
                    let fits = entries == 0 || entries < SHARE_RUN;
                    entries += h.contents(h.cluster(id).expect("cluster")).len();
                    fits
                })
                .count();
            let (now, later) = rest.split_at(run);
            let shares: Vec<_> = now.par_iter().uneven().map(|&id| share_of(id)).collect();
            for (&id, (share, slopes)) in now.iter().zip(shares) {
                let contents = h.contents(h.cluster(id).expect("cluster"));
                for (&p, s) in contents.iter().zip(share) {
                    out.means[p as usize] += s;
                }
                out.slopes.extend(slopes);
            }
            // One entry per patch, its terms summed in cluster order (the sort is stable and the
            // entries of earlier runs, already one per patch, come first).
            out.slopes.sort_by_key(|&(p, _)| p);
            out.slopes.dedup_by(|(p, slope), (q, sum)| {
                let same = p == q;
                if same {
                    for (sum, s) in sum.iter_mut().zip(slope.iter()) {
                        for (sum, s) in sum.iter_mut().zip(s) {
                            *sum += s;
                        }
                    }
                }
                same
            });
            rest = later;
        }
        out
    }
}

/// What [`ClusterSweep::push_from_clusters`] returns per patch root, by element id.
struct Pushed {
    /// The irradiance (or, for [`Sharing::MovedByExposure`], what exposure moved) averaged over the
    /// patch.
    means: Vec<Rgb>,
    /// Its zero-mean variation over the patches that have one ([`Gradient`]), sorted by patch root:
    /// a minority of patches (28% of office3's), kept sparse for memory.
    slopes: Vec<(ElementId, Slope)>,
}

/// A zero-mean variation of irradiance over a patch ([`Gradient`]): its coefficients of the first
/// three basis functions, each an RGB triple in single precision.
type Slope = [[f32; 3]; 3];

/// What [`ClusterSweep::push_from_clusters`] sums per patch.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Sharing {
    /// The irradiance shared from the clusters' links.
    Pushed,
    /// `|H_exposed − H_visible|`: how far sharing by exposure moved each patch's share from sharing
    /// by visible projected area alone.
    MovedByExposure,
}

/// Per patch root (by element id), the irradiance over π that sharing by exposure ([`expose`]) moved
/// to or from it, summed over the clusters above it with the current radiances: the size of what the
/// sharing decides with a few rays per patch, which the error estimate adds to the cluster
/// links' (`solvers::error_estimate`). Zero without item buffers or exposures.
pub fn moved_by_exposure(h: &Hierarchy, sweep: &ClusterSweep) -> Vec<Rgb> {
    if h.item_buffers.is_none() || h.root_cluster.is_none() {
        return vec![Rgb::BLACK; h.patches.len()];
    }
    sweep.push_from_clusters(h, Sharing::MovedByExposure).means
}

/// Per element (by id), the radiance that sending by exposure ([`Sent::through`]) moved on the
/// element's own links with the current radiances: the largest channel of
/// `ρ Σ_l F_l |L_carried − L_visible|` over its partly blocked links from clusters, `L_carried` as
/// [`Sent::through`] gives it (one number an element: this list is alive at the solve's peak of
/// memory). The link's visibility says how much of its source reaches, the
/// one centroid ray per patch which part; the received light is uncertain by as much as that choice
/// moved it, which the error estimate adds to the element's level (`solvers::error_estimate`), as it
/// adds [`moved_by_exposure`] for the receiving side. Zero without item buffers.
pub fn moved_by_sending(h: &Hierarchy, sweep: &ClusterSweep) -> Vec<f64> {
    if h.item_buffers.is_none() || h.root_cluster.is_none() {
        return vec![0.0; h.elements.len()];
    }
    (0..h.elements.len() as ElementId)
        .into_par_iter()
        .map(|id| {
            let centre = h.center_of(id);
            let moved: Rgb = h
                .element(id)
                .links
                .iter()
                .filter(|l| carries_light(l) && l.coupling.visibility < 1.0)
                .filter_map(|l| {
                    let sent = sweep.sent_toward(h, l.source, centre)?;
                    let distance = (centre - h.center_of(l.source)).length();
                    let carried = sent.through(f64::from(l.coupling.visibility), distance);
                    Some((carried - sent.visible()).map(f64::abs) * l.coupling.form_factor())
                })
                .sum();
            (h.reflectance_of(id) * moved).max_channel()
        })
        .collect()
}

/// Stores each cluster's *exposure* along the direction buckets of its links that carry light, where
/// not stored yet: for every patch the bucket's item buffer leaves visible, which of the rays from its
/// four gradient nodes ([`gradient_rule`]) reach the centre of the bucket's nearest link source, past
/// the cluster's own contents and the source's (their mutual hiding is the item buffer's, §6.1): its
/// exposed fraction, the nodes' quadrature of its part in the open ([`node_fraction`]). Without
/// gradients (the constant basis) one ray from its centroid decides, 1 or 0. [`ClusterSweep`] shares
/// what the cluster gathers along the bucket among the exposed parts.
///
/// Why: a cluster link's visibility is one average over the whole cluster (rays between random points
/// of both ends), and the item buffer sees only the cluster's own contents, so the light a link
/// delivers went to every visible patch by its projected area, whether or not something outside the
/// cluster stands between it and the source. Where the visibility is partial the exposed patches got
/// too little and the sheltered ones too much: the classroom's chair backs, at the height of the desks
/// in front of them, read 60–68% too dark, while a final gather of the same solution at those points
/// agrees with the reference (BENCHMARKS.md, "Exposure"). Sharing by exposure gives each exposed
/// part what it would receive unoccluded, and the rest only what the link's rays saw beyond what the
/// exposed parts explain ([`exposure_shares`]). Until 2026-11-30 one ray from the centroid decided
/// for the whole patch, which then got the light of all its area or none: a chair seat half under a
/// desk, a plate half in a shadow (tests/intra_cluster.rs); the nodes' fractions took the
/// classroom's error at its seen points from 5.18% to 4.96% (BENCHMARKS.md, "Exposed fractions").
/// With the constant basis, whose elements hold a patch's light evenly, the fractions took the dim
/// chair points lit through clusters further below the reference (six point sets 8.87 → 9.26%), so
/// there the centroid still decides.
///
/// The same for sending, keyed apart ([`sending_key`]): per (cluster, bucket) that links from the
/// cluster use, which visible patches a ray from their centroid reaches the bucket's nearest
/// *receiver* by; a partly blocked link then carries those patches' average radiance ([`Sent`]). A
/// single ray per patch: a partly exposed patch counts as its centroid does.
pub fn expose(h: &Hierarchy, visibility: &dyn Visibility) {
    let Some(buffers) = h.item_buffers.as_deref() else {
        return;
    };
    let Some(root) = h.root_cluster else {
        return;
    };
    let clusters: Vec<ElementId> = (h.patches.len() as ElementId..=root)
        .filter(|&id| h.is_cluster(id) && !h.element(id).links.is_empty())
        .collect();
    let gradients = Gradient::taken(h);
    let mut exposures: Vec<((u32, u16), Exposure)> = clusters
        .par_iter()
        .uneven()
        .flat_map_iter(|&id| {
            let centre = h.center_of(id);
            // The nearest light-carrying source of each bucket (ties by element id).
            let mut nearest: Vec<(u16, f64, ElementId)> = h
                .element(id)
                .links
                .iter()
                .filter(|l| carries_light(l))
                .map(|l| {
                    let target = h.center_of(l.source);
                    (
                        bucket_toward(h, id, target),
                        (target - centre).length_squared(),
                        l.source,
                    )
                })
                .collect();
            nearest.sort_by(|a, b| a.0.cmp(&b.0).then(a.1.total_cmp(&b.1)).then(a.2.cmp(&b.2)));
            nearest.dedup_by_key(|n| n.0);
            nearest
                .into_iter()
                .filter(|&(bucket, _, _)| !buffers.has_exposure(id, bucket))
                .map(|(bucket, _, source)| {
                    (
                        (id, bucket),
                        exposure(h, visibility, buffers, id, bucket, source, gradients),
                    )
                })
                .collect::<Vec<_>>()
        })
        .collect();
    // Sending: the nearest receiver of each (source cluster, bucket) of light-carrying links that
    // some of their rays found blocked (a fully visible link carries the visible average), which are
    // stored at their receivers.
    let mut toward: Vec<((ElementId, u16), f64, ElementId)> = (0..h.elements.len() as ElementId)
        .into_par_iter()
        .flat_map_iter(|receiver| {
            h.element(receiver)
                .links
                .iter()
                .filter(|l| {
                    h.is_cluster(l.source) && carries_light(l) && l.coupling.visibility < 1.0
                })
                .map(move |l| {
                    let target = h.center_of(receiver);
                    (
                        (l.source, sending_key(bucket_toward(h, l.source, target))),
                        (target - h.center_of(l.source)).length_squared(),
                        receiver,
                    )
                })
        })
        .collect();
    toward.par_sort_unstable_by(|a, b| a.0.cmp(&b.0).then(a.1.total_cmp(&b.1)).then(a.2.cmp(&b.2)));
    toward.dedup_by_key(|t| t.0);
    let sending: Vec<((u32, u16), Exposure)> = toward
        .into_par_iter()
        .uneven()
        .filter(|&((id, key), _, _)| !buffers.has_exposure(id, key))
        .map(|((id, key), distance_squared, receiver)| {
            let bits = exposure(h, visibility, buffers, id, key & !SENDING, receiver, false);
            ((id, key), with_reach(bits, distance_squared.sqrt()))
        })
        .collect();
    exposures.extend(sending);
    buffers.store_exposures(exposures);
}

/// Marks an exposure key as toward the bucket's nearest *receiver* (what the cluster sends) rather than
/// its nearest source (what it gathers): buckets are below `6 × 8² = 384`.
const SENDING: u16 = 1 << 15;
const _: () =
    assert!(6 * crate::visibility::item_buffer::BUCKETS_PER_FACE.pow(2) < SENDING as usize);

/// The exposure key of what a cluster sends along `bucket` ([`expose`]).
fn sending_key(bucket: u16) -> u16 {
    bucket | SENDING
}

/// A sending exposure with the distance from the cluster's centre to the receiver it was taken toward
/// appended as one more word ([`sending_reach`] reads it): the patch bits before it are unchanged.
fn with_reach(bits: Exposure, reach: f64) -> Exposure {
    let mut words = bits.into_vec();
    words.push(reach.to_bits());
    words.into_boxed_slice()
}

/// The reach [`with_reach`] appended to a sending exposure.
fn sending_reach(exposure: &[u64]) -> f64 {
    exposure
        .last()
        .map_or(f64::INFINITY, |&word| f64::from_bits(word))
}

/// [`expose`] for one (cluster, bucket) toward the link end `other` (a source, or a receiver): with
/// `nodes` (toward a source, with gradients), a ray from each of a patch's four gradient nodes
/// ([`gradient_rule`]), the patch reached where any of them does; without, one ray from its centroid.
fn exposure(
    h: &Hierarchy,
    visibility: &dyn Visibility,
    buffers: &ItemBuffers,
    id: ElementId,
    bucket: u16,
    other: ElementId,
    nodes: bool,
) -> Exposure {
    let along = bucket_direction(bucket);
    let visible = visible_areas(h, buffers, id, bucket);
    let target = h.center_of(other);
    let transparent = |polygon: usize| {
        h.cluster_holds_polygon(id, polygon)
            || (h.is_cluster(other) && h.cluster_holds_polygon(other, polygon))
    };
    let contents = h.contents(h.cluster(id).expect("a cluster"));
    let patches = contents.iter().enumerate().map(|(k, &patch)| {
        let facing = h.patches[patch as usize].normal.dot(along) > 0.0;
        if !facing || visible.fraction(k) <= 0.0 {
            return (false, 0);
        }
        let polygon = h.patch_of(patch).polygon;
        let reaches = |from: DVec3| {
            visibility.transmittance_past_onto(from, target, polygon, &transparent) >= 0.5
        };
        let shape = h.element(patch).shape();
        if !nodes {
            return (reaches(shape.centroid()), 0);
        }
        let node_bits = gradient_rule(shape.domain())
            .nodes
            .iter()
            .enumerate()
            .filter(|&(_, &(uv, _))| reaches(shape.point_at(uv)))
            .fold(0, |bits, (n, _)| bits | 1 << n);
        (node_bits != 0, node_bits)
    });
    pack_exposure(patches, nodes)
}

/// Patch `k`'s exposure, 1 or 0, where one ray decided it ([`exposure`] without nodes).
fn exposed_bit(exposure: &[u64], k: usize) -> f64 {
    f64::from(u8::from(exposed(exposure, k)))
}

/// The exposed fraction of `shape` whose gradient nodes' rays reached as the bits of `nodes` say
/// ([`exposure`]): their share of the patch's area by the rule's weights and Jacobian.
pub fn node_fraction(shape: &Shape, nodes: u8) -> f64 {
    match all_or_none(nodes) {
        true => f64::from(nodes.min(1)),
        false => NodeAreas::of(shape).fraction(nodes),
    }
}

/// Whether every gradient node's ray reached, or none: the patch is exposed evenly.
fn all_or_none(nodes: u8) -> bool {
    nodes == 0 || u32::from(nodes) == (1 << GRADIENT_NODES) - 1
}

/// A patch's area element at each node of its gradient rule ([`gradient_rule`]): the node's weight
/// times the Jacobian there, all that [`node_fraction`] and [`Gradient::slope`] read of its shape.
#[derive(Clone, Copy, Debug)]
struct NodeAreas {
    domain: Domain,
    da: [f64; GRADIENT_NODES],
}

impl NodeAreas {
    fn of(shape: &Shape) -> Self {
        let domain = shape.domain();
        let mut da = [0.0; GRADIENT_NODES];
        for (da, &(uv, w)) in da.iter_mut().zip(&gradient_rule(domain).nodes) {
            *da = w * shape.jacobian(uv);
        }
        NodeAreas { domain, da }
    }

    /// [`node_fraction`].
    fn fraction(&self, nodes: u8) -> f64 {
        if all_or_none(nodes) {
            return f64::from(nodes.min(1));
        }
        let (mut reached, mut all) = (0.0, 0.0);
        for (n, &da) in self.da.iter().enumerate() {
            all += da;
            if nodes >> n & 1 == 1 {
                reached += da;
            }
        }
        if all > 0.0 {
            reached / all
        } else {
            0.0
        }
    }
}

/// The degree of the rule whose nodes ([`gradient_rule`]) tell how exposure varies over a patch.
const GRADIENT_DEGREE: usize = 3;

/// The nodes a gradient is taken at: the 2 × 2 Gauss product rule of both domains (collapsed on the
/// triangle), four nodes, one bit each in an [`Exposure`].
fn gradient_rule(domain: Domain) -> &'static crate::geometry::cubature::Rule {
    let rule = rule(domain, GRADIENT_DEGREE);
    debug_assert!(rule.nodes.len() == GRADIENT_NODES);
    rule
}

/// Nodes of [`gradient_rule`] on both domains, one bit each in an [`Exposure`].
const GRADIENT_NODES: usize = 4;
const _: () = assert!(GRADIENT_NODES <= crate::visibility::item_buffer::NODE_BITS);

/// How the light a cluster shares among its exposed patches varies over each patch.
///
/// Why: sharing by exposure ([`expose`]) gives a patch the same irradiance all over, its exposed
/// fraction's. A patch half in the shadow of something outside its cluster (a chair back behind
/// a desk) was then lit evenly, too dark at its exposed top and too bright below: at the classroom's
/// seen points lit mostly through clusters the error was 15.9% RMS, with a mean of −6.8%, against
/// 4.4% elsewhere; with gradients 14.1% and −1.5% (BENCHMARKS.md, "Gradients of what clusters
/// push"). The rays from its four nodes that gave that fraction say which part is exposed; the
/// patch's share then follows the linear function through them (the projection of the node values
/// on the basis' linear functions, `c_α = (1/|D|) Σ_n w_n φ_α(uv_n) b_n`), scaled to the same mean,
/// so that the power each patch receives is unchanged, and flattened as far as needed to stay
/// non-negative at every corner.
/// Needs a basis with linear functions (linear or above) and item buffers.
struct Gradient {
    square: GradientTable,
    triangle: GradientTable,
}

/// What [`Gradient::slope`] reads of the basis on one domain: its first three functions at the
/// gradient rule's nodes and at the domain's corners, and the nodes' weights over the domain's area.
struct GradientTable {
    weights: [f64; GRADIENT_NODES],
    at_nodes: [[f64; 3]; GRADIENT_NODES],
    at_corners: Vec<[f64; 3]>,
}

impl GradientTable {
    fn new(basis: &crate::bases::Basis, domain: Domain) -> Self {
        let first_three = |uv: DVec2| {
            let mut phi = [0.0; crate::bases::MAX_BASIS_SIZE];
            basis.eval(domain, uv, &mut phi);
            [phi[0], phi[1], phi[2]]
        };
        let nodes = &gradient_rule(domain).nodes;
        GradientTable {
            weights: std::array::from_fn(|n| nodes[n].1 / domain.area()),
            at_nodes: std::array::from_fn(|n| first_three(nodes[n].0)),
            at_corners: domain.corners().iter().map(|&c| first_three(c)).collect(),
        }
    }
}

/// `Σ_α c_α φ_α` of the basis' first three functions, their values `phi` at a point (as
/// [`crate::bases::Basis::value`] sums them).
fn linear_value(phi: &[f64; 3], c: &[f64; 3]) -> f64 {
    phi.iter().zip(c).map(|(p, c)| p * c).sum()
}

impl Gradient {
    fn new(h: &Hierarchy) -> Option<Self> {
        Gradient::taken(h).then(|| Gradient::of(&h.basis))
    }

    /// Whether `h` takes gradients: item buffers and a basis with linear functions.
    fn taken(h: &Hierarchy) -> bool {
        h.item_buffers.is_some() && h.basis_size() >= 3
    }

    /// The tables of a basis with linear functions (linear or above).
    fn of(basis: &crate::bases::Basis) -> Self {
        Gradient {
            square: GradientTable::new(basis, Domain::Square),
            triangle: GradientTable::new(basis, Domain::Triangle),
        }
    }

    /// The zero-mean variation, per unit mean, over `shape` of a share whose gradient nodes' rays
    /// reached as the bits of `nodes` say, as coefficients of the first three basis functions;
    /// `None` where every node or none reached, or the pattern has no linear part (the share is
    /// even). The basis comes from the tables, the shape only by its [`NodeAreas`]: a sweep asks
    /// for 2.9M patches' shares on the classroom, and evaluating the basis there each time took a
    /// fifth of the sharing's time.
    fn slope(&self, shape: &Shape, nodes: u8) -> Option<[f64; 3]> {
        if all_or_none(nodes) {
            return None;
        }
        let patch = NodeAreas::of(shape);
        let table = match patch.domain {
            Domain::Square => &self.square,
            Domain::Triangle => &self.triangle,
        };
        let mut c = [0.0; 3];
        for n in 0..GRADIENT_NODES {
            if nodes >> n & 1 == 1 {
                for (c, &phi) in c.iter_mut().zip(&table.at_nodes[n]) {
                    *c += table.weights[n] * phi;
                }
            }
        }
        // Its mean over the patch, exact by the same rule (the function times the Jacobian has
        // degree 2).
        let (mut integral, mut area) = (0.0, 0.0);
        for (&da, phi) in patch.da.iter().zip(&table.at_nodes) {
            integral += da * linear_value(phi, &c);
            area += da;
        }
        if integral <= 0.0 || area <= 0.0 {
            return None;
        }
        let mut slope = c.map(|c| c * area / integral);
        slope[0] -= 1.0;
        if slope.iter().all(|s| s.abs() < 1e-9) {
            return None; // no linear part (two diagonal nodes of a quad)
        }
        // The largest t ≤ 1 with 1 + t · slope ≥ 0 at every corner (the function is linear).
        let t = table.at_corners.iter().fold(1.0f64, |t, phi| {
            let v = linear_value(phi, &slope);
            if v < 0.0 {
                t.min(-1.0 / v)
            } else {
                t
            }
        });
        Some(slope.map(|s| s * t))
    }
}

/// Patch entries of the shares [`ClusterSweep`] computes at once when pushing what clusters gather to
/// their patches.
const SHARE_RUN: usize = 1 << 15;

/// Whether a link's coupling carries any light: a near link into a cluster
/// ([`unplaced_near_coupling`]) or a fully occluded one has a zero block (its constant entry is a
/// mean of non-negative node values, zero only when all are), and asking what its source sends
/// would draw item buffers for nothing.
pub fn carries_light(link: &crate::hierarchy::Link) -> bool {
    link.form_factor() > 0.0
}

/// The direction bucket ([`direction_bucket`]) of the direction from cluster `id`'s centre toward the
/// point `toward`.
fn bucket_toward(h: &Hierarchy, id: ElementId, toward: DVec3) -> u16 {
    direction_bucket(toward - h.center_of(id))
}

/// What cluster `id` sends along the centre direction of bucket `bucket`: its patches' radiances
/// averaged over their visible projected areas along it (its average radiance when nothing faces that
/// way), and averaged over the exposed ones only ([`expose`], toward the bucket's nearest receiver).
fn sent_along(
    h: &Hierarchy,
    contents: &Contents,
    buffers: &ItemBuffers,
    id: ElementId,
    bucket: u16,
) -> Sent {
    let areas = visible_areas_along(h, contents, buffers, id, bucket);
    let total: f64 = areas.iter().sum();
    if total <= 0.0 {
        return Sent::even(h.average_radiance(id));
    }
    let radiances = &contents.radiance[Contents::range(h, id)];
    let average = |weights: &[f64], total: f64| -> Rgb {
        radiances
            .iter()
            .zip(weights)
            .map(|(&radiance, &w)| radiance * (w / total))
            .sum()
    };
    let visible = average(&areas, total);
    let Some((split, reach)) = buffers
        .exposure(id, sending_key(bucket), |exposure| {
            ExposureSplit::new(&areas, |k| exposed_bit(exposure, k))
                .map(|split| (split, sending_reach(exposure)))
        })
        .flatten()
    else {
        return Sent::even(visible);
    };
    Sent::new(
        visible,
        average(&split.exposed, split.exposed_total),
        split.exposed_share(),
        reach,
    )
}

/// A cluster's visible projected areas along a bucket split by exposure ([`expose`]): each patch's
/// exposed part and the rest.
struct ExposureSplit {
    /// Each patch's visible projected area times its exposed fraction.
    exposed: Vec<f64>,
    /// Each patch's visible projected area times its unexposed fraction.
    others: Vec<f64>,
    exposed_total: f64,
    total: f64,
}

impl ExposureSplit {
    /// The split of `areas` by each patch's exposed fraction `exposed(k)` in [0, 1]. `None` where
    /// nothing with an area is exposed, or everything is: exposure then tells no patch from
    /// another, and sharing and sending take all visible patches alike.
    fn new(areas: &[f64], exposed: impl Fn(usize) -> f64) -> Option<Self> {
        let (exposed, others): (Vec<f64>, Vec<f64>) = areas
            .iter()
            .enumerate()
            .map(|(k, &w)| {
                let x = exposed(k);
                (w * x, w * (1.0 - x))
            })
            .unzip();
        let exposed_total: f64 = exposed.iter().sum();
        let total: f64 = areas.iter().sum();
        (exposed_total > 0.0 && exposed_total < total).then_some(ExposureSplit {
            exposed,
            others,
            exposed_total,
            total,
        })
    }

    /// `e`, the exposed patches' share of the visible projected area.
    fn exposed_share(&self) -> f64 {
        self.exposed_total / self.total
    }
}

/// Visibility samples of a link whose receiver is a cluster ([`couple_cluster`]).
pub const CLUSTER_RECEIVER_SAMPLES: usize = 2 * CLUSTER_VISIBILITY_SAMPLES;

/// What a cluster link gathered, `g` (its sampled visibility `v` included), goes to the exposed
/// parts of the patches, `g e / v`, and to the rest, `g max(0, v − v_e) / v` with
/// `v_e = e + 3 √(e (1 − e) / N)`, where `e` is the exposed parts' share of the visible projected
/// area along the link's bucket and `N` = [`CLUSTER_RECEIVER_SAMPLES`]; shared within each by
/// visible projected area. Returns the two factors of `g`.
///
/// Why: each patch takes the visibility its own rays found ([`expose`]), 1 where all reached
/// the source, rather than the cluster's average `v`: an exposed part gets what it would unoccluded,
/// a hidden one nothing, whatever the few rays of `v` found (exact where the occlusion is all or
/// nothing per node row: a chair back behind a desk, the ceiling over a corridor lamp lit by the
/// lamp's back). `v` only adds what those rays cannot explain: its excess over `e` beyond three
/// standard deviations of `N` Bernoulli samples at `e`, spread over the unexposed parts (a source
/// whose centre is hidden from most patches while most of it is not). Until 2026-11-28 the exposed
/// patches got all of `g`, `v / e` times what they would unoccluded: a patch holding 0.45% of a
/// desk's visible area took the floor's light for the whole desk, one patch of the classroom
/// gathered 223 times what a white furnace allows, and the sweeps of its progressive
/// multi-gridding diverged (BENCHMARKS.md, "Exposure: each patch its own visibility"). Now no patch
/// receives more from a link than it would unoccluded; the power delivered is the patches', not
/// exactly the link's `g`.
pub fn exposure_shares(e: f64, v: f64) -> (f64, f64) {
    if v <= 0.0 {
        return (0.0, 0.0);
    }
    let explained = e + 3.0 * (e * (1.0 - e) / CLUSTER_RECEIVER_SAMPLES as f64).sqrt();
    (e / v, (v - explained).max(0.0) / v)
}

/// What a cluster sends along a direction bucket ([`sent_along`]), before a link's visibility picks
/// the average it carries ([`Sent::through`]).
#[derive(Clone, Copy, Debug)]
struct Sent {
    /// Radiance averaged over the visible projected areas of the patches facing the bucket.
    visible: [f32; 3],
    /// The same over the patches exposed toward the bucket's nearest receiver ([`expose`]).
    exposed: [f32; 3],
    /// `e`, the exposed patches' share of the visible projected area, in (0, 1); 0 where exposure
    /// tells no patch from another ([`ExposureSplit::new`]). (The other patches' average is
    /// `(visible − e exposed) / (1 − e)`.)
    ///
    /// Single precision (a relative rounding of 6·10⁻⁸, far below what the averages estimate) and
    /// no third average: the table holds one entry per (cluster, bucket) in use, 50k on office3.
    exposed_share: f32,
    /// Distance from the cluster's centre to the receiver the exposure was taken toward (the bucket's
    /// nearest, [`expose`]); infinite without an exposure.
    reach: f32,
}

impl Sent {
    fn new(visible: Rgb, exposed: Rgb, exposed_share: f64, reach: f64) -> Self {
        Sent {
            visible: visible.to_f32(),
            exposed: exposed.to_f32(),
            exposed_share: exposed_share as f32,
            reach: reach as f32,
        }
    }

    fn even(radiance: Rgb) -> Self {
        Sent::new(radiance, radiance, 0.0, f64::INFINITY)
    }

    /// Radiance averaged over the visible projected areas of the patches facing the bucket.
    fn visible(self) -> Rgb {
        Rgb::from_f32(self.visible)
    }

    /// The radiance a link with visibility `v` carries: the visible average where every ray of the
    /// link reached (`v = 1`) or where exposure tells no patch from another; where some were blocked,
    /// what the patches send by their own exposure, as a receiving cluster shares by it
    /// ([`exposure_shares`]): `(e/v) L_exposed + (max(0, v − v_e)/v) L_others`, so that the link's
    /// `F v` times it is `F_unoccluded (e L_exposed + max(0, v − v_e) L_others)`: each exposed patch
    /// sends what it would unoccluded, the others only what the link's rays saw beyond what the exposed
    /// ones explain (with the receiving side's margin for `N` = 8 rays, conservative where a link into
    /// a surface sampled more).
    ///
    /// Why not one average by `v`: where what the link's rays find blocked is the bright part of the
    /// cluster (the ceiling over a lamp hung 2 cm under it, lit by the lamp's back) the product of the
    /// averages sends the hidden light into the room (the corridor read 11% too bright with clusters;
    /// BENCHMARKS.md, "Exposure of what clusters send"). Why not the exposed average alone (until
    /// 2026-11-29): where the exposed patches are a small bright part of what the rays see (a
    /// window's white frame around a black pane, the pane's centroid hidden behind desks), `F v`
    /// counts the whole visible area at the frame's radiance: links from the classroom's windows
    /// sent the ceiling 9 to 12 times the light of their contents (`radiosity audit`; BENCHMARKS.md,
    /// "What clusters send, by exposure").
    fn through(self, v: f64, distance: f64) -> Rgb {
        let e = f64::from(self.exposed_share);
        let visible = self.visible();
        if v >= 1.0 || e <= 0.0 {
            return visible;
        }
        let exposed = Rgb::from_f32(self.exposed);
        let others = ((visible - exposed * e) / (1.0 - e)).map(|c| c.max(0.0));
        let (mut to_exposed, to_others) = exposure_shares(e, v);
        if distance > f64::from(self.reach) * (1.0 + 1e-6) {
            to_exposed = to_exposed.min(1.0);
        }
        exposed * to_exposed + others * to_others
    }
}

/// Adds irradiance `gathered` at a cluster of area `cluster_area` to its patches' `share`, each by its
/// projected area `areas[k]`: `H_k = H A_cluster w_k / (A_k Σ w)`, so that the patches receive the
/// power `π H A_cluster` the links delivered.
fn share_by_areas(
    geometry: &[(DVec3, f64)],
    cluster_area: f64,
    gathered: Rgb,
    areas: &[f64],
    share: &mut [Rgb],
) {
    for (s, factor) in share
        .iter_mut()
        .zip(area_factors(geometry, cluster_area, areas))
    {
        if let Some(factor) = factor {
            *s += gathered * factor;
        }
    }
}

/// Per patch, the factor `A_cluster w_k / (A_k Σ w)` of [`share_by_areas`]; `None` for a patch
/// without area, and for all where no patch has a weight.
fn area_factors<'a>(
    geometry: &'a [(DVec3, f64)],
    cluster_area: f64,
    areas: &'a [f64],
) -> impl Iterator<Item = Option<f64>> + 'a {
    let total: f64 = areas.iter().sum();
    areas.iter().zip(geometry).map(move |(&w, &(_, area))| {
        (total > 0.0 && area > 0.0).then(|| cluster_area * w / (area * total))
    })
}

/// Adds irradiance `gathered` at a cluster of area `cluster_area` to its normal groups' `group_share`
/// (power over π, `H A_cluster p_g / Σ p`), each by its (visible) projected area `p_g` toward the
/// point `toward`.
fn share_by_groups(
    groups: &Groups,
    cluster_area: f64,
    gathered: Rgb,
    toward: DVec3,
    group_share: &mut [Rgb],
) {
    let projected: Vec<f64> = groups.projected_areas(toward).collect();
    let total: f64 = projected.iter().sum();
    if total > 0.0 {
        for (s, p) in group_share.iter_mut().zip(&projected) {
            *s += gathered * (cluster_area * p / total);
        }
    }
}

/// Adds each group's `group_share` (power over π) to its members' irradiance `share` (content order
/// of `contents`) by their visible areas `A_k f_k`: `H_k = s_g f_k / Σ_{k in g} A_k f_k` (`s_g / A_g`
/// without item buffers), so that the members receive what the group did (the visible sum is taken
/// again here in `f64`, so that the power is conserved to rounding, not to the cached `f32` area).
fn spread_to_members(
    h: &Hierarchy,
    contents: &[ElementId],
    groups: &Groups,
    group_share: &[Rgb],
    share: &mut [Rgb],
) {
    let o = groups.orientation;
    for (group, s) in o.groups.iter().zip(group_share) {
        let members = &o.members[group.members.start as usize..group.members.end as usize];
        let area = match groups.visible {
            Some(_) => members
                .iter()
                .map(|&k| h.element(contents[k as usize]).area * f64::from(groups.fraction(k)))
                .sum(),
            None => group.area,
        };
        if area <= 0.0 {
            continue;
        }
        for &k in members {
            share[k as usize] += *s * f64::from(groups.fraction(k)) / area;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bases::{Basis, BasisKind};

    /// A right triangle, a parallelogram and a quad that is neither (its overlap matrix is not the
    /// identity), 1 to 3 m across.
    fn shapes() -> [Shape; 3] {
        let p = |x: f64, y: f64| DVec3::new(x, y, 0.0);
        [
            Shape::Triangle([p(0.0, 0.0), p(2.0, 0.0), p(0.0, 1.0)]),
            Shape::Quad([p(0.0, 0.0), p(2.0, 0.5), p(2.5, 1.5), p(0.5, 1.0)]),
            Shape::Quad([p(0.0, 0.0), p(3.0, 0.0), p(2.0, 1.0), p(0.5, 1.2)]),
        ]
    }

    /// Every mixed node pattern on every shape and basis with linear functions: the variation has
    /// zero mean over the shape (the power a patch receives is unchanged), the share it shapes is
    /// non-negative at every corner (hence everywhere, being linear), and it is larger at the nodes
    /// whose rays reached than at those whose rays did not, on average. All or no nodes, or a
    /// pattern without a linear part (a quad's diagonal pair): no variation. Ground truth: the area
    /// mean by a cubature rule of degree 9 on the mapped shape.
    #[test]
    fn gradients_keep_the_mean_stay_non_negative_and_rise_toward_the_reached_nodes() {
        for kind in [
            BasisKind::Linear,
            BasisKind::Bilinear,
            BasisKind::Quadratic,
            BasisKind::Cubic,
        ] {
            let basis = Basis::new(kind);
            let gradient = Gradient::of(&basis);
            for shape in shapes() {
                let domain = shape.domain();
                let nodes = &gradient_rule(domain).nodes;
                assert_eq!(nodes.len(), 4);
                assert!(gradient.slope(&shape, 0).is_none());
                assert!(gradient.slope(&shape, 0b1111).is_none());
                for pattern in 1..0b1111u8 {
                    let Some(slope) = gradient.slope(&shape, pattern) else {
                        assert!(
                            domain == crate::geometry::Domain::Square
                                && (pattern == 0b0110 || pattern == 0b1001),
                            "{kind:?} {pattern:04b}: no variation"
                        );
                        continue;
                    };
                    let fine = nodes_on(&shape, rule(domain, 9));
                    let area: f64 = fine.iter().map(|n| n.weight).sum();
                    let mean = fine
                        .iter()
                        .map(|n| n.weight * basis.value(domain, n.uv, &slope))
                        .sum::<f64>()
                        / area;
                    assert!(mean.abs() < 1e-12, "{kind:?} {pattern:04b}: mean {mean}");
                    for &corner in domain.corners() {
                        let share = 1.0 + basis.value(domain, corner, &slope);
                        assert!(
                            share >= -1e-12,
                            "{kind:?} {pattern:04b}: {share} at a corner"
                        );
                    }
                    let at = |reached: bool| {
                        let values: Vec<f64> = nodes
                            .iter()
                            .enumerate()
                            .filter(|&(n, _)| (pattern >> n & 1 == 1) == reached)
                            .map(|(_, &(uv, _))| basis.value(domain, uv, &slope))
                            .collect();
                        values.iter().sum::<f64>() / values.len() as f64
                    };
                    assert!(at(true) > at(false), "{kind:?} {pattern:04b}");
                }
            }
        }
    }
}
