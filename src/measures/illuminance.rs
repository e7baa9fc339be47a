//! Irradiance and illuminance at points that are not on a surface (a work plane floating in a room), from
//! a solved hierarchy, with an error estimate per point; work-plane grids and their statistics.
//!
//! Irradiance at `x` with unit normal `n` is `E(x) = ∫ L(y) cos θx dω = Σ_j ∫_j L_j(y) V(x, y) cos θx
//! cos θy / r² dA_y` (Bekaert–Willems eq. (1) kernel times π, since `K` carries the `1/π` of the
//! Lambertian BRDF). It is gathered *hierarchically* over each patch's element tree (Hanrahan et al.
//! 1991), from the roots down, piece by piece. A piece is an element or, below a leaf, a regular
//! quarter of one (evaluated with the leaf's basis expansion, so shadows finer than the solver's mesh
//! are resolved). For a piece `p` with projected solid angle `Ω_p = π F(x → p)` (the exact
//! point-to-polygon factor, Lambert's formula) the contribution is the ratio estimator of
//! [`crate::solvers::coupling`]: `E_p = Ω_p Σ_l k_l V_l L(y_l) / Σ_l k_l` over the piece's cubature
//! nodes `y_l` (`k_l` the kernel times the node weight, `V_l` the transmittance of the segment `x y_l`
//! through the [`Visibility`] trait), exact for a constant, unoccluded piece.
//!
//! Descent criterion (stated, deterministic): a piece is used as a whole when
//! 1. its projected solid angle is small, `Ω_p ≤ Ω_max` (`max_solid_angle`), and
//! 2. its gather error is small, `g_p ≤ τ L̄ Ω_max`, with `L̄` the scene's mean radiance from the energy
//!    balance ([`crate::pipeline::mean_radiance_estimate`]) and `τ` the relative `tolerance`: the budget
//!    of a piece of the largest solid angle, so that a hemisphere covered by such pieces has a gather
//!    error of at most `τ π L̄` (τ times the mean irradiance). Smaller pieces get the same absolute
//!    budget (the form of the power oracle, Feixas et al. eq. (1)), which is what lets a far or small
//!    element be used whole however much its radiance varies;
//!
//! otherwise its children (or, below a leaf, its quarters, at most `max_depth` levels) are gathered
//! instead. Pieces facing away or below the horizon of `x` (`F = 0`) cost nothing, so a point visits
//! O(π / Ω_max) pieces per layer of depth of the scene plus the refinement near shadow edges and bright
//! gradients, not every leaf.
//!
//! Faint pieces and dim clusters: a piece wholly above the horizon of `x` whose whole unoccluded
//! contribution `U = Ω_p L_max` is within the piece budget is not refined or node-sampled but
//! estimated from one ray to an area-uniform random point `y` of it, `Ω_p V(x, y) L(y)`; a cluster of
//! the scene's cluster tree (Sillion–Drettakis §4) whose bound `U = Ω_s c_max L_max` is within the
//! budget (`Ω_s` its bounding sphere's solid angle, `c_max` the largest `cos θx` over that sphere's
//! cone, `L_max` its brightest radiance) is estimated from one direction `ω` uniform in the cone,
//! `Ω_s cos θx L(y)` with `y` the first surface met that way if it is the cluster's (zero
//! otherwise). Both estimates are unbiased and lie between 0 and that bound, so their error is at most
//! the bound: the budget, as for any piece. A piece or cluster within twice the budget gets four
//! jittered random samples (points of the piece, kernel-weighted as nodes are; directions of the
//! cone) and the binomial error `U / 2` of the sampled fraction: four rays instead of four nodes and
//! four corners, or instead of a ray or more for each patch of the cluster. The cosine bound and the
//! four-ray clusters took the classroom's cached 256² image from 62.8M to 56.7M gather rays with the
//! same errors (BENCHMARKS.md, "Dim clusters from four directions"). A point therefore visits the
//! clusters around it down to the size its budget resolves, not every patch facing it (the
//! classroom's 300 seen points at `τ = 0.2`: 14.2M → 3.0M rays, the same error). The samples are
//! seeded by `seed`, the point and the piece, so that the result does not depend on the thread count.
//! Clusters wholly behind the point's tangent plane are skipped.
//!
//! Error model per point (W/m², largest channel), summed over the pieces used:
//! * solver error propagated through the gather (Bekaert–Willems eq. (11) at a point):
//!   `Σ_p Ω_p v_p ε_p`, with `ε_p` the element's a-posteriori estimate (`Element::error`; on an inner
//!   element the largest of its leaves) and `v_p` the piece's sampled visible fraction;
//! * gather error `g_p`: the visibility sampling error `2 Ω_p L_p √(v (1 − v) / m)` of `m` node rays,
//!   two binomial standard deviations of the sampled visible fraction (a 95% bound where that sampling
//!   is the only error; the `√(v(1 − v))` form of `LinkCoupling::visibility_error`). A piece counts as
//!   partly visible when its nodes disagree or its corners disagree with them (a straight shadow edge
//!   crossing a convex piece separates its corners); `v` is then the nodes' fraction, or that of nodes
//!   and corners together when the nodes agree, and the parent's fraction for the children of a partly
//!   visible piece whose own samples all agree, since a shadow edge may pass between them; plus, for
//!   an inner element used in place of its leaves, `Ω_p v_p ΔL_p` with `ΔL_p` the largest difference
//!   between its leaves' and its own average radiance. Both are added linearly (conservative). The cubature error of the ratio estimator for smoothly varying radiance is
//!   second order in the piece's size and is neglected.

use crate::color::{Rgb, WHITE_EFFICACY};
use crate::geometry::cubature::{nodes_of, rule};
use crate::geometry::form_factor::{point_to_point, point_to_polygon};
use crate::geometry::{Aabb, DVec2, DVec3, Ray, Shape};
use crate::hierarchy::{ElementId, Hierarchy};
use crate::parallel::Uneven;
use crate::random::{splitmix64, unit_interval};
use crate::reference::PhotometricEstimate;
use crate::visibility::{Visibility, SEGMENT_EPSILON};
use rayon::prelude::*;
use serde::Serialize;
use std::f64::consts::PI;

/// How the hierarchical gather refines (see the module documentation for the criterion).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct GatherSettings {
    /// `Ω_max`: largest projected solid angle (sr, of π for the whole hemisphere) a piece may have.
    pub max_solid_angle: f64,
    /// `τ`: largest gather error of a piece, relative to the scene's mean radiance times `Ω_max`.
    pub tolerance: f64,
    /// Most levels of regular quarters below a leaf element.
    pub max_depth: u32,
    /// Degree of the cubature rule on each piece (its nodes are the visibility samples).
    pub cubature_degree: usize,
    /// Seed of the few random samples of pieces and clusters too dim to matter alone (mixed with
    /// the point and the piece, so that results do not depend on the thread count).
    pub seed: u64,
}

impl Default for GatherSettings {
    fn default() -> Self {
        GatherSettings {
            max_solid_angle: 0.02,
            tolerance: 0.01,
            max_depth: 5,
            cubature_degree: 3,
            seed: 0,
        }
    }
}

/// The irradiance at one point and its estimated error.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct PointIrradiance {
    /// Irradiance per channel, W/m².
    pub irradiance: Rgb,
    /// Solver error propagated to the point, W/m² (largest channel).
    pub solver_error: f64,
    /// The gather's own error, W/m² (largest channel).
    pub gather_error: f64,
    /// Pieces used and visibility rays cast.
    pub pieces: u32,
    pub rays: u32,
    /// Of the pieces, clusters gathered whole from a few samples (dim ones; see the module
    /// documentation).
    pub clusters: u32,
}

impl PointIrradiance {
    /// Total estimated error, W/m² (largest channel).
    pub fn error(&self) -> f64 {
        self.solver_error + self.gather_error
    }

    /// Illuminance in lux ([`crate::color::photometric`]).
    pub fn lux(&self) -> f64 {
        crate::color::photometric(self.irradiance)
    }

    /// The error in lux: the luminance weights are positive and sum to one, so `|Y(δ)| ≤ max_c |δ_c|`.
    pub fn error_lux(&self) -> f64 {
        WHITE_EFFICACY * self.error()
    }
}

/// Binomial standard deviations of the visible fraction counted as its error (see the module
/// documentation).
const VISIBILITY_DEVIATIONS: f64 = 2.0;

/// A piece of a patch tree: an element, or a regular quarter of a leaf `depth` levels below it.
#[derive(Clone, Copy, Debug)]
struct Piece {
    element: ElementId,
    shape: Shape,
    depth: u32,
    /// Visible fraction of the nearest partly visible ancestor, if any.
    partial: Option<f64>,
}

impl Piece {
    /// A whole element.
    fn whole(h: &Hierarchy, element: ElementId) -> Piece {
        Piece {
            element,
            shape: *h.element(element).shape(),
            depth: 0,
            partial: None,
        }
    }
}

/// The cone from a point around a cluster's bounding sphere.
#[derive(Clone, Copy, Debug)]
struct Cone {
    /// Unit direction to the sphere's centre.
    axis: DVec3,
    cos_half_angle: f64,
    /// `2π (1 − cos α)`.
    solid_angle: f64,
    /// Distance to the far side of the sphere.
    far: f64,
    /// The solid angle times the cluster's brightest radiance: a bound on what it adds.
    unoccluded: f64,
}

/// Irradiance at arbitrary points of a solved scene (see the module documentation).
pub struct IrradianceGather<'a> {
    hierarchy: &'a Hierarchy,
    visibility: &'a dyn Visibility,
    settings: GatherSettings,
    /// `ΔL` per element: largest |leaf average − own average| over its leaves (largest channel).
    spread: Vec<f64>,
    /// `τ L̄ Ω_max`: the gather error accepted from one piece (W/m²).
    piece_budget: f64,
    /// The clusters from `first_cluster` to the root, as the walk of [`Self::through_clusters`]
    /// reads them, side by side ([`WalkedCluster`]); their children in `cluster_children`.
    clusters: Vec<WalkedCluster>,
    cluster_children: Vec<ElementId>,
    first_cluster: ElementId,
}

/// What the gather's walk down the cluster tree reads of a cluster, in one place: every point's
/// gather starts at the root, and reading the hierarchy's elements, their boxed clusters and
/// children lists instead misses the cache at each (the classroom's cached render phase ran about
/// 7% faster reading these; BENCHMARKS.md, "The gather's walk down the cluster tree").
#[derive(Clone, Copy, Debug)]
struct WalkedCluster {
    center: DVec3,
    /// Half the bounding box's extent, and half its diagonal (the bounding sphere's radius).
    half: DVec3,
    radius: f64,
    /// Its brightest patch's largest leaf average radiance (largest channel).
    brightest: f64,
    /// Its contents' largest a-posteriori error.
    error: f64,
    /// Its children: `cluster_children[children.0 .. children.1]`.
    children: (u32, u32),
    /// Its patch roots, at any depth: `Hierarchy::cluster_surfaces[contents.0 .. contents.1]` (a
    /// cluster's range holds its children's, in the order the tree was walked).
    contents: (u32, u32),
}

impl<'a> IrradianceGather<'a> {
    pub fn new(
        hierarchy: &'a Hierarchy,
        visibility: &'a dyn Visibility,
        settings: GatherSettings,
    ) -> Self {
        let mut spread = vec![0.0; hierarchy.elements.len()];
        for patch in &hierarchy.patches {
            let mut leaves = Vec::new();
            let mut stack = vec![patch.root];
            while let Some(id) = stack.pop() {
                let e = hierarchy.element(id);
                if e.is_leaf() {
                    continue;
                }
                stack.extend(&e.children);
                leaves.clear();
                hierarchy.collect_leaves(id, &mut leaves);
                let own = hierarchy.average_radiance(id);
                spread[id as usize] = leaves
                    .iter()
                    .map(|&l| {
                        let d = hierarchy.average_radiance(l) - own;
                        d.map(f64::abs).max_channel()
                    })
                    .fold(0.0, f64::max);
            }
        }
        // Clusters are stored after everything they hold, from the first to the root: each cluster's
        // bounds from its children's, in one pass.
        let first_cluster = hierarchy
            .elements
            .iter()
            .position(|e| matches!(e.kind, crate::hierarchy::ElementKind::Cluster(_)))
            .unwrap_or(hierarchy.elements.len()) as ElementId;
        let mut clusters: Vec<WalkedCluster> = Vec::new();
        let mut cluster_children = Vec::new();
        for id in first_cluster
            ..hierarchy
                .root_cluster
                .map_or(first_cluster, |root| root + 1)
        {
            let element = hierarchy.element(id);
            let (brightest, error) = element.children.iter().fold((0.0, 0.0), |(l, e), &c| {
                let (cl, ce) = if hierarchy.is_cluster(c) {
                    let child = &clusters[(c - first_cluster) as usize];
                    (child.brightest, child.error)
                } else {
                    (
                        hierarchy.average_radiance(c).max_channel() + spread[c as usize],
                        hierarchy.element(c).error,
                    )
                };
                (f64::max(l, cl), f64::max(e, ce))
            });
            let cluster = hierarchy.cluster(id).expect("a cluster");
            let bounds = cluster.bounds;
            let start = cluster_children.len() as u32;
            cluster_children.extend_from_slice(&element.children);
            clusters.push(WalkedCluster {
                center: bounds.center(),
                half: 0.5 * (bounds.max - bounds.min),
                radius: 0.5 * bounds.diagonal(),
                brightest,
                error,
                children: (start, cluster_children.len() as u32),
                contents: (cluster.contents.start, cluster.contents.end),
            });
        }
        IrradianceGather {
            hierarchy,
            visibility,
            settings,
            spread,
            piece_budget: settings.tolerance
                * settings.max_solid_angle
                * crate::pipeline::mean_radiance_estimate(hierarchy),
            clusters,
            cluster_children,
            first_cluster,
        }
    }

    /// Uniform numbers for the sample of a piece or cluster `key` seen from `x`: a stream seeded by
    /// the settings' seed, the point and the key.
    fn uniforms(&self, x: DVec3, key: DVec3) -> impl FnMut() -> f64 {
        let mut bits = self.settings.seed;
        for v in [x.x, x.y, x.z, key.x, key.y, key.z] {
            bits = splitmix64(bits ^ v.to_bits());
        }
        move || {
            bits = splitmix64(bits);
            unit_interval(bits)
        }
    }

    /// The irradiance at `x` on the side its unit `normal` points to.
    pub fn at(&self, x: DVec3, normal: DVec3) -> PointIrradiance {
        let h = self.hierarchy;
        let mut out = PointIrradiance::default();
        let mut stack: Vec<Piece> = Vec::new();
        match h.root_cluster {
            Some(root) => self.through_clusters(x, normal, root, &mut stack, &mut out),
            None => stack.extend(h.patches.iter().rev().map(|p| Piece::whole(h, p.root))),
        }
        while let Some(piece) = stack.pop() {
            let solid_angle = PI * point_to_polygon(x, normal, &piece.shape);
            if solid_angle <= 0.0 {
                continue;
            }
            let element = h.element(piece.element);
            let divisible = !element.is_leaf() || piece.depth < self.settings.max_depth;
            if divisible && solid_angle > self.settings.max_solid_angle {
                self.push_children(&mut stack, &piece, piece.partial);
                continue;
            }
            let coarse = if element.is_leaf() {
                0.0
            } else {
                self.spread[piece.element as usize]
            };
            let unoccluded =
                solid_angle * (h.average_radiance(piece.element).max_channel() + coarse);
            if unoccluded <= RANDOM_STRATA * self.piece_budget
                && self.random_piece(x, normal, &piece, solid_angle, unoccluded, &mut out)
            {
                continue;
            }
            let sample = self.sample(x, normal, &piece);
            out.rays += sample.rays;
            let v_error = sample.mixed.or(piece.partial).unwrap_or(sample.visible);
            let gather = solid_angle
                * (VISIBILITY_DEVIATIONS
                    * sample.brightest
                    * (v_error * (1.0 - v_error) / sample.nodes).sqrt()
                    + sample.visible * coarse);
            if divisible && gather > self.piece_budget {
                self.push_children(&mut stack, &piece, sample.mixed.or(piece.partial));
                continue;
            }
            out.irradiance += sample.radiance * solid_angle;
            out.solver_error += solid_angle * sample.visible * element.error;
            out.gather_error += gather;
            out.pieces += 1;
        }
        // Goniometric luminaires are not surfaces of the hierarchy: their direct light is added by the
        // same opening-sampled inverse-square law the solver's first gather uses.
        for luminaire in &h.luminaires {
            out.irradiance += luminaire.irradiance(x, normal, |from, to| {
                out.rays += 1;
                self.visibility.transmittance(from, to)
            });
        }
        out
    }

    /// The radiance `patch` leaves `x` with under the irradiance gathered there ([`gathered_radiance`]).
    pub fn radiance_at(&self, patch: u32, x: DVec3) -> Rgb {
        let patch = &self.hierarchy.patches[patch as usize];
        gathered_radiance(patch, self.at(x, patch.normal).irradiance)
    }

    /// The irradiance at every `(point, normal)`, in parallel; each point is gathered on its own, so the
    /// result does not depend on the thread count.
    pub fn at_all(&self, points: &[(DVec3, DVec3)]) -> Vec<PointIrradiance> {
        (points.par_iter().one_per_task())
            .map(|&(x, n)| self.at(x, n))
            .collect()
    }

    /// A piece whose whole unoccluded contribution `U` is within [`RANDOM_STRATA`] piece budgets, from
    /// `k²` rays to area-uniform random points of it, one in each cell of a `k × k` partition of its
    /// master domain (jittered), `k = ⌈U / budget⌉`, weighted by the kernel as the nodes are (the
    /// ratio estimator of the module documentation; for one ray, exactly `Ω_p V(x, y) L(y)`, whose mean
    /// is `Ω_p` times the area average of `V L`: unbiased where the kernel is constant over the piece,
    /// as it nearly is over a faint piece. The exactly unbiased `π A K V L` per stratum measured the
    /// same: the corridor's cached points at sets 11 and 14 +0.93, +1.02% mean signed against +1.03,
    /// +1.08%, both the solution's own bias, its leaves there +1.15, +1.02%).
    /// Its error is at most `U / k` (the `2 √(v (1 − v) / m)` bound at `m = k²` and `v = ½`), within
    /// the budget. One ray for a faint piece (`U` within the budget), four where the nodes and corners
    /// would cost eight. `false`, with nothing added, for a piece that reaches the horizon of `x` (a
    /// corner on or below the tangent plane); the caller samples its nodes. `Ω_p` counts only the part
    /// above, where a point below can be hidden by the object of `x` itself. Measured on the Cornell
    /// box's points, random points in such pieces biased the mean error from −0.41% to −0.60%. Two
    /// synthetic scenes, a cube floating in a furnace and a pillar in one, showed no such bias,
    /// so that explanation is not confirmed.
    fn random_piece(
        &self,
        x: DVec3,
        normal: DVec3,
        piece: &Piece,
        solid_angle: f64,
        unoccluded: f64,
        out: &mut PointIrradiance,
    ) -> bool {
        if unoccluded <= 0.0 {
            out.pieces += 1;
            return true;
        }
        if piece
            .shape
            .vertices()
            .iter()
            .any(|&v| normal.dot(v - x) <= 0.0)
        {
            return false;
        }
        let strata = self.strata(unoccluded);
        let k = strata as usize;
        let h = self.hierarchy;
        let n_y = h.patch_of(piece.element).normal;
        let (mut lit, mut seen, mut open) = (Rgb::BLACK, 0.0, 0.0);
        for cell in jittered_cells(strata, self.uniforms(x, piece.shape.centroid())) {
            let y = piece.shape.sample_uniform(cell);
            let kernel = point_to_point(x, normal, y, n_y);
            open += kernel;
            let t = self.visibility.transmittance(x, y);
            if t > 0.0 {
                seen += kernel * t;
                lit += h.exitant_radiance_at(piece.element, y) * (kernel * t);
            }
        }
        if open <= 0.0 {
            return false;
        }
        out.irradiance += lit * (solid_angle / open);
        out.solver_error += solid_angle * seen / open * h.element(piece.element).error;
        out.gather_error += unoccluded / strata;
        out.pieces += 1;
        out.rays += k as u32 * k as u32;
        true
    }

    /// Walks the cluster tree from `root`: clusters wholly behind the point's tangent plane are
    /// skipped, and a cluster whose bound `U` (its bounding sphere's solid angle times the largest
    /// cosine over that cone times its brightest radiance: a bound on anything it can add to the
    /// irradiance, since each direction meets one surface) is within [`RANDOM_STRATA`] piece budgets
    /// is gathered from one or four random directions ([`Self::dim_cluster`]); the patch roots of the
    /// rest go on `pieces`. Far small objects thus cost a ray or a few each instead of a factor and
    /// rays per patch.
    fn through_clusters(
        &self,
        x: DVec3,
        normal: DVec3,
        root: ElementId,
        pieces: &mut Vec<Piece>,
        out: &mut PointIrradiance,
    ) {
        let h = self.hierarchy;
        let mut clusters = vec![root];
        while let Some(id) = clusters.pop() {
            // Clusters are numbered from the first to the root, after everything they hold.
            if !(self.first_cluster..=root).contains(&id) {
                pieces.push(Piece::whole(h, id));
                continue;
            }
            let cluster = &self.clusters[(id - self.first_cluster) as usize];
            let (center, half, radius) = (cluster.center, cluster.half, cluster.radius);
            // The box's highest corner above the tangent plane.
            if normal.dot(center - x) + normal.abs().dot(half) <= 0.0 {
                continue;
            }
            let distance = center.distance(x);
            if radius < distance {
                let sine = radius / distance;
                let cos_half_angle = (1.0 - sine * sine).sqrt();
                let solid_angle = 2.0 * PI * (1.0 - cos_half_angle);
                let axis = (center - x) / distance;
                let cone = Cone {
                    axis,
                    cos_half_angle,
                    solid_angle,
                    far: distance + radius,
                    unoccluded: solid_angle
                        * largest_cosine(normal.dot(axis), cos_half_angle, sine)
                        * cluster.brightest,
                };
                if cone.unoccluded <= RANDOM_STRATA * self.piece_budget {
                    self.dim_cluster(x, normal, id, cone, out);
                    continue;
                }
            }
            let (start, end) = cluster.children;
            clusters.extend(
                self.cluster_children[start as usize..end as usize]
                    .iter()
                    .rev(),
            );
        }
    }

    /// A cluster too dim to matter alone, from `k²` directions `ω` stratified in the cone of its
    /// bounding sphere (solid angle `Ω_s`), `k = ⌈U / budget⌉` ([`RANDOM_STRATA`] at most) for its bound
    /// `U`: the closest surface each way, if it is the cluster's, adds `Ω_s cos θx L(y) / k²`, an
    /// unbiased estimate of what the cluster adds to the irradiance (each direction counts the first
    /// surface it meets, so anything in front of the cluster hides it). Each sample lies between 0 and
    /// `U`, so one sample's error is at most `U` and `k²` samples' is counted as `U / k`, as for
    /// random pieces. Closest hits rather than the [`Visibility::transmittance`] of segments, so that
    /// a cluster with many layers does not inflate a sample.
    fn dim_cluster(
        &self,
        x: DVec3,
        normal: DVec3,
        id: ElementId,
        cone: Cone,
        out: &mut PointIrradiance,
    ) {
        let h = self.hierarchy;
        out.pieces += 1;
        out.clusters += 1;
        if cone.unoccluded <= 0.0 {
            return;
        }
        let strata = self.strata(cone.unoccluded);
        out.gather_error += cone.unoccluded / strata;
        let walked = &self.clusters[(id - self.first_cluster) as usize];
        // Division by one or four: exact, so the same weight as dividing each sample's.
        let solid_angle_per_ray = cone.solid_angle / (strata * strata);
        let (b, c) = cone.axis.any_orthonormal_pair();
        // Only the cluster's own surfaces count, and they lie in its box: a direction that misses the
        // box (padded against the rounding of hit points) adds nothing, without a ray, and one that
        // meets it needs the closest hit only up to where it leaves the box (the same hit, as
        // anything farther is not the cluster's).
        let reach = Aabb {
            min: walked.center - walked.half,
            max: walked.center + walked.half,
        }
        .padded(BOX_PAD * (walked.radius + walked.center.abs().max_element()));
        for cell in jittered_cells(strata, self.uniforms(x, cone.axis)) {
            let cos_theta = 1.0 - cell.x * (1.0 - cone.cos_half_angle);
            let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
            let phi = 2.0 * PI * cell.y;
            let direction = cone.axis * cos_theta + (b * phi.cos() + c * phi.sin()) * sin_theta;
            let cos_x = normal.dot(direction);
            if cos_x <= 0.0 {
                continue;
            }
            let ray = Ray::new(x, direction * cone.far);
            let Some((_, exit)) = reach.segment_range(x, ray.direction.recip()) else {
                continue;
            };
            out.rays += 1;
            let Some(hit) = self.visibility.intersect(&ray, SEGMENT_EPSILON, exit) else {
                continue;
            };
            let Some(patch) = h.patch_for_side(hit.polygon, hit.front) else {
                continue;
            };
            if !h.contents_hold_patch(walked.contents.0..walked.contents.1, patch) {
                continue;
            }
            let y = x + ray.direction * hit.t;
            let (leaf, uv) = h.locate_with_parameters(patch, y);
            let weight = solid_angle_per_ray * cos_x;
            out.irradiance += h.exitant_radiance_at_parameters(leaf, uv) * weight;
            out.solver_error += weight * walked.error;
        }
    }

    /// Strata per side `k = ⌈U / budget⌉` (at least 1) of a random piece or dim cluster of bound `U`.
    fn strata(&self, unoccluded: f64) -> f64 {
        (unoccluded / self.piece_budget).ceil().max(1.0)
    }

    fn push_children(&self, stack: &mut Vec<Piece>, piece: &Piece, partial: Option<f64>) {
        let element = self.hierarchy.element(piece.element);
        if element.is_leaf() {
            for shape in piece.shape.subdivide().into_iter().rev() {
                stack.push(Piece {
                    element: piece.element,
                    shape,
                    depth: piece.depth + 1,
                    partial,
                });
            }
        } else {
            for &child in element.children.iter().rev() {
                stack.push(Piece {
                    partial,
                    ..Piece::whole(self.hierarchy, child)
                });
            }
        }
    }

    /// Kernel-weighted averages of `V L` and `V` over the piece's cubature nodes, and whether the
    /// piece is partly visible: its nodes disagree, or its corners (moved [`CORNER_INSET`] towards the
    /// centroid, so that walls meeting at its edges do not block them) disagree with each other or the
    /// nodes. A straight shadow edge that crosses a convex piece always separates its corners, so the
    /// corners catch the edges that pass between the nodes.
    fn sample(&self, x: DVec3, normal: DVec3, piece: &Piece) -> NodeSample {
        let h = self.hierarchy;
        let n_y = h.patch_of(piece.element).normal;
        let rule = rule(piece.shape.domain(), self.settings.cubature_degree);
        let (mut open, mut seen, mut lit) = (0.0, 0.0, Rgb::BLACK);
        let mut brightest = h.average_radiance(piece.element).max_channel();
        let (mut rays, mut visible_samples) = (0, 0.0);
        for node in nodes_of(&piece.shape, rule) {
            let k = node.weight * point_to_point(x, normal, node.point, n_y);
            if k <= 0.0 {
                continue;
            }
            open += k;
            rays += 1;
            let t = self.visibility.transmittance(x, node.point);
            visible_samples += t;
            if t > 0.0 {
                let radiance = h.exitant_radiance_at(piece.element, node.point);
                brightest = brightest.max(radiance.max_channel());
                seen += k * t;
                lit += radiance * (k * t);
            }
        }
        if open <= 0.0 {
            // Above the horizon only between the nodes: nothing sampled; half the element's average
            // radiance, with an error of the other half.
            return NodeSample {
                radiance: h.average_radiance(piece.element) * 0.5,
                visible: 0.5,
                mixed: Some(0.5),
                brightest,
                nodes: 1.0,
                rays,
            };
        }
        let nodes_cast = rays;
        let visible = (seen / open).clamp(0.0, 1.0);
        let mixed = if visible > 0.0 && visible < 1.0 {
            // The nodes disagree: the piece is partly visible whatever its corners say.
            Some(visible)
        } else {
            let centroid = piece.shape.centroid();
            for &corner in piece.shape.vertices() {
                let corner = corner + (centroid - corner) * CORNER_INSET;
                if point_to_point(x, normal, corner, n_y) > 0.0 {
                    rays += 1;
                    visible_samples += self.visibility.transmittance(x, corner);
                }
            }
            let fraction = visible_samples / f64::from(rays);
            (fraction > 0.0 && fraction < 1.0).then_some(fraction)
        };
        NodeSample {
            radiance: lit / open,
            visible,
            mixed,
            brightest,
            nodes: f64::from(nodes_cast),
            rays,
        }
    }
}

/// Most strata per side of a piece or cluster gathered from random rays
/// ([`IrradianceGather::random_piece`], [`IrradianceGather::dim_cluster`]): two, four rays, while that
/// is cheaper than a piece's four nodes and four corners.
const RANDOM_STRATA: f64 = 2.0;

/// How far a dim cluster's box is grown, relative to its radius plus its centre's largest coordinate,
/// before directions are clipped to it ([`IrradianceGather::dim_cluster`]): far above the rounding of
/// a hit point (`2^-52` of the coordinates), far below any size that matters.
const BOX_PAD: f64 = 1e-9;

/// The largest `cos θ` between a unit normal and the directions of a cone whose axis makes cosine
/// `cos_axis` with it, of half angle `α` (given as `cos α`, `sin α`): 1 when the normal lies inside
/// the cone, else `cos(θ_axis − α)`, at least 0.
fn largest_cosine(cos_axis: f64, cos_half_angle: f64, sin_half_angle: f64) -> f64 {
    if cos_axis >= cos_half_angle {
        return 1.0;
    }
    let sin_axis = (1.0 - cos_axis * cos_axis).max(0.0).sqrt();
    (cos_axis * cos_half_angle + sin_axis * sin_half_angle).clamp(0.0, 1.0)
}

/// The `k × k` cells of the unit square, `k = strata`, row by row, each with a point jittered in it
/// by two draws of `unit`: the stratified samples of random pieces and dim clusters.
fn jittered_cells(strata: f64, mut unit: impl FnMut() -> f64) -> impl Iterator<Item = DVec2> {
    let k = strata as usize;
    (0..k * k).map(move |cell| {
        let (i, j) = ((cell % k) as f64, (cell / k) as f64);
        DVec2::new((i + unit()) / strata, (j + unit()) / strata)
    })
}

/// Fraction of the way from a piece's corner to its centroid where the corner's visibility is sampled.
const CORNER_INSET: f64 = 0.01;

/// What the nodes of one piece saw.
struct NodeSample {
    /// `Σ k V L / Σ k`: the piece's contribution per unit projected solid angle.
    radiance: Rgb,
    /// `Σ k V / Σ k`.
    visible: f64,
    /// The visible fraction to judge the error by when the piece is partly visible (of the nodes if
    /// they disagree, else of nodes and corners together).
    mixed: Option<f64>,
    /// Largest channel of the brightest radiance seen (or the element's average).
    brightest: f64,
    /// Node rays cast (the `m` of the visibility error).
    nodes: f64,
    /// Rays cast, corners included.
    rays: u32,
}

/// One of the coordinate axes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Axis {
    X,
    Y,
    Z,
}

impl Axis {
    fn index(self) -> usize {
        match self {
            Axis::X => 0,
            Axis::Y => 1,
            Axis::Z => 2,
        }
    }

    /// The two axes spanning a plane normal to this one, in increasing order (z: x, y; y: x, z; x: y, z).
    pub fn plane_axes(self) -> [Axis; 2] {
        match self {
            Axis::X => [Axis::Y, Axis::Z],
            Axis::Y => [Axis::X, Axis::Z],
            Axis::Z => [Axis::X, Axis::Y],
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Axis::X => "x",
            Axis::Y => "y",
            Axis::Z => "z",
        }
    }
}

/// A work plane `axis = height` whose points face along `+axis` (or `-axis` when `facing_negative`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct WorkPlane {
    pub axis: Axis,
    pub height: f64,
    pub facing_negative: bool,
}

impl WorkPlane {
    /// Parses `z=0.85`, `y=1.2`, `x=0` (normal along `+axis`) or `-z=2.5` (normal along `-axis`).
    pub fn parse(text: &str) -> Result<WorkPlane, String> {
        let text = text.trim();
        let (axis, value) = text
            .split_once('=')
            .ok_or_else(|| format!("'{text}': expected AXIS=HEIGHT such as z=0.85 (or -z=2.5)"))?;
        let (facing_negative, axis) = match axis.trim().strip_prefix('-') {
            Some(a) => (true, a),
            None => (false, axis.trim().strip_prefix('+').unwrap_or(axis.trim())),
        };
        let axis = match axis.to_ascii_lowercase().as_str() {
            "x" => Axis::X,
            "y" => Axis::Y,
            "z" => Axis::Z,
            other => return Err(format!("'{other}' is not an axis (x, y or z)")),
        };
        let height: f64 = value
            .trim()
            .parse()
            .ok()
            .filter(|h: &f64| h.is_finite())
            .ok_or_else(|| format!("'{}' is not a finite number", value.trim()))?;
        Ok(WorkPlane {
            axis,
            height,
            facing_negative,
        })
    }

    /// The unit normal the points face.
    pub fn normal(&self) -> DVec3 {
        let mut n = DVec3::ZERO;
        n[self.axis.index()] = if self.facing_negative { -1.0 } else { 1.0 };
        n
    }

    /// The world point with plane coordinates `uv` (along [`Axis::plane_axes`]).
    pub fn point(&self, uv: DVec2) -> DVec3 {
        let [a, b] = self.axis.plane_axes();
        let mut p = DVec3::ZERO;
        p[self.axis.index()] = self.height;
        p[a.index()] = uv.x;
        p[b.index()] = uv.y;
        p
    }

    /// Plane coordinates of a world point.
    pub fn coordinates(&self, p: DVec3) -> DVec2 {
        let [a, b] = self.axis.plane_axes();
        DVec2::new(p[a.index()], p[b.index()])
    }

    /// The default region: the scene's bounds in the plane's two axes, moved inward by
    /// [`REGION_INSET`] of their extent on every side (so that no point lies in a wall). Fails when
    /// the height is outside the bounds along the axis.
    pub fn default_region(&self, bounds: &Aabb) -> Result<Region, String> {
        let i = self.axis.index();
        if bounds.is_empty() || !(bounds.min[i] < self.height && self.height < bounds.max[i]) {
            return Err(format!(
                "the plane {}={} lies outside the scene, which spans {} to {} along {}",
                self.axis.name(),
                self.height,
                bounds.min[i],
                bounds.max[i],
                self.axis.name()
            ));
        }
        let (lo, hi) = (self.coordinates(bounds.min), self.coordinates(bounds.max));
        let inset = (hi - lo) * REGION_INSET;
        Region::new(lo + inset, hi - inset)
    }
}

/// Fraction of the scene's extent by which the default region keeps off the bounds on every side.
pub const REGION_INSET: f64 = 0.01;

/// A rectangle in the plane's coordinates.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Region {
    pub min: DVec2,
    pub max: DVec2,
}

impl Region {
    /// A region with `min < max` in both coordinates (finite).
    pub fn new(min: DVec2, max: DVec2) -> Result<Region, String> {
        if !(min.is_finite() && max.is_finite() && min.x < max.x && min.y < max.y) {
            return Err(format!(
                "the region {},{},{},{} is empty: give x0,y0,x1,y1 with x0 < x1 and y0 < y1",
                min.x, min.y, max.x, max.y
            ));
        }
        Ok(Region { min, max })
    }

    /// Parses `x0,y0,x1,y1` (commas or spaces).
    pub fn parse(text: &str) -> Result<Region, String> {
        let values: Vec<f64> = text
            .split(|c: char| c == ',' || c.is_whitespace())
            .filter(|s| !s.is_empty())
            .map(|s| {
                s.parse::<f64>()
                    .map_err(|_| format!("'{s}' is not a number"))
            })
            .collect::<Result<_, _>>()?;
        let [x0, y0, x1, y1] = values[..] else {
            return Err(format!(
                "expected four numbers x0,y0,x1,y1, got {}",
                values.len()
            ));
        };
        Region::new(DVec2::new(x0, y0), DVec2::new(x1, y1))
    }
}

/// Most points of one grid.
pub const MAX_GRID_POINTS: usize = 1_000_000;

/// A regular grid of points on a work plane: `columns × rows` points `spacing` apart, centred in the
/// region, row-major from the region's minimum corner.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Grid {
    pub plane: WorkPlane,
    pub region: Region,
    pub spacing: f64,
    pub columns: usize,
    pub rows: usize,
}

impl Grid {
    pub fn new(plane: WorkPlane, region: Region, spacing: f64) -> Result<Grid, String> {
        if !(spacing.is_finite() && spacing > 0.0) {
            return Err("the spacing must be a positive number".to_string());
        }
        let size = region.max - region.min;
        let count = |extent: f64| (extent / spacing).floor() + 1.0;
        let (columns, rows) = (count(size.x), count(size.y));
        if columns * rows > MAX_GRID_POINTS as f64 {
            return Err(format!(
                "a spacing of {spacing} gives {columns} × {rows} points, more than the \
                 {MAX_GRID_POINTS} allowed: use a larger spacing or a smaller region"
            ));
        }
        Ok(Grid {
            plane,
            region,
            spacing,
            columns: columns as usize,
            rows: rows as usize,
        })
    }

    /// Plane coordinates of point (column, row).
    pub fn coordinates(&self, column: usize, row: usize) -> DVec2 {
        let size = self.region.max - self.region.min;
        let used = DVec2::new(
            (self.columns - 1) as f64 * self.spacing,
            (self.rows - 1) as f64 * self.spacing,
        );
        let origin = self.region.min + (size - used) * 0.5;
        origin + DVec2::new(column as f64, row as f64) * self.spacing
    }

    /// World points with the plane's normal, row-major.
    pub fn points(&self) -> Vec<(DVec3, DVec3)> {
        let normal = self.plane.normal();
        (0..self.rows)
            .flat_map(|row| (0..self.columns).map(move |column| (column, row)))
            .map(|(column, row)| (self.plane.point(self.coordinates(column, row)), normal))
            .collect()
    }
}

/// Summary statistics of a set of illuminances: min, mean, max, uniformity `U0 = min / mean` (the
/// EN 12464-1 definition) and the ratio max / min (`None` where min is zero).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Statistics {
    pub count: usize,
    pub min: f64,
    pub mean: f64,
    pub max: f64,
    pub uniformity: f64,
    pub max_over_min: Option<f64>,
}

impl Statistics {
    /// Statistics of `values` (NaN for an empty set; uniformity 0 where the mean is 0).
    pub fn of(values: &[f64]) -> Statistics {
        let count = values.len();
        let min = values.iter().copied().fold(f64::INFINITY, f64::min);
        let max = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        if count == 0 {
            return Statistics {
                count,
                min: f64::NAN,
                mean: f64::NAN,
                max: f64::NAN,
                uniformity: f64::NAN,
                max_over_min: None,
            };
        }
        let mean = values.iter().sum::<f64>() / count as f64;
        Statistics {
            count,
            min,
            mean,
            max,
            uniformity: if mean > 0.0 { min / mean } else { 0.0 },
            max_over_min: (min > 0.0).then(|| max / min),
        }
    }
}

/// Paths per point of the independent path-traced estimate (`--reference-paths`), and their seed.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ReferencePaths {
    pub paths: usize,
    pub seed: u64,
}

/// The illuminance at one grid point.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct GridValue {
    pub point: [f64; 3],
    /// Illuminance from the radiosity solution, lux.
    pub lux: f64,
    /// Its estimated error (solver and gather, [`PointIrradiance::error_lux`]), lux.
    pub error_lux: f64,
    /// The path-traced estimate and its standard error (lux), when asked for.
    pub reference: Option<PhotometricEstimate>,
    /// The point lies inside a solid ([`inside_solid`]): reported, but left out of the statistics.
    pub inside_solid: bool,
}

/// Illuminance over a work-plane grid, with its statistics.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct GridReport {
    pub grid: Grid,
    /// Row-major, as [`Grid::points`].
    pub values: Vec<GridValue>,
    /// Over the points outside solids.
    pub statistics: Statistics,
    /// Points inside solids (furniture, walls with thickness), left out of the statistics.
    pub inside_solid: usize,
    /// Largest and mean estimated error, lux.
    pub max_error_lux: f64,
    pub mean_error_lux: f64,
    /// Gather pieces and visibility rays over all points.
    pub pieces: u64,
    pub rays: u64,
}

/// Illuminance at every point of `grid` from the solved `hierarchy`, and optionally the path tracer's
/// independent estimate there (seeded per point from `reference.seed` and the point's index, so the
/// result does not depend on the thread count).
pub fn illuminance_grid(
    scene: &crate::scene::Scene,
    hierarchy: &Hierarchy,
    visibility: &dyn Visibility,
    grid: &Grid,
    settings: GatherSettings,
    reference: Option<ReferencePaths>,
) -> GridReport {
    let points = grid.points();
    let gathered = IrradianceGather::new(hierarchy, visibility, settings).at_all(&points);
    let tracer = crate::reference::PathTracer::new(
        scene,
        visibility,
        crate::reference::ReferenceSettings::default().roulette_depth,
    );
    let references: Vec<Option<PhotometricEstimate>> = points
        .par_iter()
        .one_per_task()
        .enumerate()
        .map(|(index, &(x, n))| {
            reference.map(|r| {
                let seed = crate::reference::derive_seed(r.seed, index as u64);
                tracer.irradiance_at(x, n, r.paths, seed).photometric()
            })
        })
        .collect();
    let values: Vec<GridValue> = points
        .iter()
        .zip(&gathered)
        .zip(references)
        .map(|((&(x, n), g), reference)| GridValue {
            point: x.to_array(),
            lux: g.lux(),
            error_lux: g.error_lux(),
            reference,
            inside_solid: inside_solid(visibility, x, n),
        })
        .collect();
    let lux: Vec<f64> = values
        .iter()
        .filter(|v| !v.inside_solid)
        .map(|v| v.lux)
        .collect();
    let errors = values.iter().map(|v| v.error_lux);
    GridReport {
        grid: grid.clone(),
        statistics: Statistics::of(&lux),
        inside_solid: values.iter().filter(|v| v.inside_solid).count(),
        max_error_lux: errors.clone().fold(0.0, f64::max),
        mean_error_lux: errors.sum::<f64>() / values.len().max(1) as f64,
        pieces: gathered.iter().map(|g| u64::from(g.pieces)).sum(),
        rays: gathered.iter().map(|g| u64::from(g.rays)).sum(),
        values,
    }
}

/// Whether the work-plane point `x` lies inside a solid: the first surfaces along its normal and along
/// the four directions of the plane (two tangents, both ways) are all met from behind (their normals
/// point away from `x`, as the outward faces of a closed object do when seen from within: a cabinet,
/// a block, a wall with thickness; furniture standing on the floor needs no bottom face). A room's
/// own ceiling and walls face into it and are met from the front, so points in the open are kept, and
/// so are points under a desk top (the room's walls around them face them). Relies on solids wound
/// outward, as MGF's solids and most modellers make them; points in open or inward-wound furniture
/// are not caught (`--region` then).
pub fn inside_solid(visibility: &dyn Visibility, x: DVec3, normal: DVec3) -> bool {
    let tangent = normal.any_orthonormal_vector();
    let bitangent = normal.cross(tangent);
    [normal, tangent, -tangent, bitangent, -bitangent]
        .into_iter()
        .all(|d| {
            visibility
                .intersect(&crate::geometry::Ray::new(x, d), 0.0, f64::INFINITY)
                .is_some_and(|hit| !hit.front)
        })
}

/// Photometric values at a surface probe (`radiosity probe --units photometric`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ProbePhotometry {
    /// Luminance of the radiosity solution leaving the point, cd/m².
    pub luminance: f64,
    /// Illuminance arriving at the point, gathered from the solution, lux, and its estimated error.
    pub illuminance: f64,
    pub illuminance_error: f64,
    /// The path-traced luminance and its standard error, when the probe has a reference.
    pub reference_luminance: Option<PhotometricEstimate>,
}

/// Luminance and illuminance at probed surface points, the illuminance `irradiance[k]` gathered at
/// point `k` ([`IrradianceGather::at_all`]).
pub fn probe_photometry(
    results: &[crate::reference::probe::ProbeResult],
    irradiance: &[PointIrradiance],
) -> Vec<ProbePhotometry> {
    results
        .iter()
        .zip(irradiance)
        .map(|(r, e)| ProbePhotometry {
            luminance: crate::color::photometric(r.radiosity),
            illuminance: e.lux(),
            illuminance_error: e.error_lux(),
            reference_luminance: r.reference.map(|e| e.photometric()),
        })
        .collect()
}

/// The probe points' surface normals, where [`IrradianceGather::at_all`] gathers.
pub fn probe_gather_points(
    results: &[crate::reference::probe::ProbeResult],
) -> Vec<(DVec3, DVec3)> {
    results
        .iter()
        .map(|r| (DVec3::from_array(r.point), DVec3::from_array(r.normal)))
        .collect()
}

/// A final gather at probed surface points: each point's radiance becomes `L_e + ρ E / π`, its
/// emission plus the light it reflects of the irradiance `E = irradiance[k]` gathered from the solution
/// at the point itself (the rendering equation's one bounce for a Lambertian surface, Bekaert–Willems
/// eq. (1)), and its error estimate `ρ_max / π` times the gather's (the solver's error propagated to
/// the point plus the gather's own; the module documentation).
///
/// Why: the solution's value at a point is its leaf's basis expansion, which carries what the
/// couplings delivered to the whole element: light pushed down from clusters (shared over a patch by
/// projected area and exposure), a factor that varies faster across the element than its basis (a
/// receiver touching a perpendicular wall). The gather reads the same solution, but at the point,
/// with the exact factor of every piece it uses and rays for its visibility: what the solution's
/// radiance field implies there. Seen points of the classroom go from 6.2% to 1.7% RMS at the same
/// solve, the Cornell box's from 3.0% to 0.7% (BENCHMARKS.md, "A final gather at probed points").
pub fn final_gather(
    h: &Hierarchy,
    results: &mut [crate::reference::probe::ProbeResult],
    irradiance: &[PointIrradiance],
) {
    for (r, e) in results.iter_mut().zip(irradiance) {
        // Probes lie on a side with a patch (`reference::probe` refuses others).
        if let Some(patch) = h.patch_for_side(r.polygon, r.front) {
            let patch = &h.patches[patch as usize];
            r.radiosity = gathered_radiance(patch, e.irradiance);
            r.estimated_error = patch.reflectance.max_channel() / PI * e.error();
        }
    }
}

/// The radiance a Lambertian point of `patch` leaves with under `irradiance`: `L_e + ρ E / π`
/// ([`final_gather`], and `render --final-gather` per pixel sample).
pub fn gathered_radiance(patch: &crate::hierarchy::Patch, irradiance: Rgb) -> Rgb {
    patch.emission + patch.reflectance * irradiance * (1.0 / PI)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The cone bound of dim clusters is the largest cosine over the cone's directions: no direction
    /// of a dense sampling of the cone (its rim included) exceeds it, and the best of them reaches it
    /// to within the sampling's spacing, for normals inside, beside and behind the cone.
    #[test]
    fn the_largest_cosine_over_a_cone_is_attained_and_never_exceeded() {
        let axis = DVec3::new(0.3, -0.5, 0.8).normalize();
        let (b, c) = axis.any_orthonormal_pair();
        for half_angle in [0.01f64, 0.2, 0.7, 1.4] {
            let (sine, cosine) = f64::sin_cos(half_angle);
            for tilt in [0.0f64, 0.1, 0.5, 1.0, 1.6, 2.5, 3.1] {
                let normal = axis * tilt.cos() + b * tilt.sin();
                let bound = largest_cosine(normal.dot(axis), cosine, sine);
                let mut best = f64::NEG_INFINITY;
                for i in 0..=64 {
                    let theta = half_angle * f64::from(i) / 64.0;
                    for j in 0..256 {
                        let phi = 2.0 * PI * f64::from(j) / 256.0;
                        let d = axis * theta.cos() + (b * phi.cos() + c * phi.sin()) * theta.sin();
                        let cos = normal.dot(d);
                        assert!(cos <= bound + 1e-12, "{half_angle} {tilt}: {cos} > {bound}");
                        best = best.max(cos.max(0.0));
                    }
                }
                assert!(
                    best >= bound - 2e-3,
                    "{half_angle} {tilt}: {best} < {bound}"
                );
            }
        }
    }

    /// Jittered cells: `k²` points, one in each cell of the `k × k` grid, row by row.
    #[test]
    fn jittered_cells_put_one_point_in_each_cell() {
        let mut draws = [0.0, 0.999, 0.5, 0.25, 0.75, 0.5, 0.1, 0.9].into_iter();
        let cells: Vec<DVec2> = jittered_cells(2.0, || draws.next().unwrap()).collect();
        assert_eq!(
            cells,
            [
                DVec2::new(0.0, 0.4995),
                DVec2::new(0.75, 0.125),
                DVec2::new(0.375, 0.75),
                DVec2::new(0.55, 0.95)
            ]
        );
    }

    #[test]
    fn planes_and_regions_parse_and_refuse_nonsense() {
        let p = WorkPlane::parse("z=0.85").unwrap();
        assert_eq!((p.axis, p.height, p.normal()), (Axis::Z, 0.85, DVec3::Z));
        let p = WorkPlane::parse("-y = 2").unwrap();
        assert_eq!((p.axis, p.normal()), (Axis::Y, -DVec3::Y));
        assert_eq!(p.point(DVec2::new(1.0, 3.0)), DVec3::new(1.0, 2.0, 3.0));
        assert!(WorkPlane::parse("w=1").is_err());
        assert!(WorkPlane::parse("z=nan").is_err());
        assert!(WorkPlane::parse("z").is_err());
        let r = Region::parse("0,0,2,1").unwrap();
        assert_eq!(r.max, DVec2::new(2.0, 1.0));
        assert!(Region::parse("0,0,0,1").is_err());
        assert!(Region::parse("0,0,1").is_err());
    }

    #[test]
    fn grids_are_centred_in_their_region_and_bounded() {
        let plane = WorkPlane::parse("z=1").unwrap();
        let region = Region::parse("0,0,1,0.6").unwrap();
        let grid = Grid::new(plane, region, 0.25).unwrap();
        assert_eq!((grid.columns, grid.rows), (5, 3));
        // 3 rows use 0.5 of 0.6: 0.05 margin on each side.
        assert!((grid.coordinates(0, 0) - DVec2::new(0.0, 0.05)).length() < 1e-12);
        assert!((grid.coordinates(4, 2) - DVec2::new(1.0, 0.55)).length() < 1e-12);
        let points = grid.points();
        assert_eq!(points.len(), 15);
        assert!((points[1].0 - DVec3::new(0.25, 0.05, 1.0)).length() < 1e-12);
        assert!(Grid::new(plane, region, 1e-4).is_err());
        assert!(Grid::new(plane, region, 0.0).is_err());
    }

    #[test]
    fn statistics_of_a_handmade_grid() {
        let s = Statistics::of(&[100.0, 200.0, 300.0, 400.0]);
        assert_eq!((s.min, s.mean, s.max), (100.0, 250.0, 400.0));
        assert_eq!(s.uniformity, 0.4);
        assert_eq!(s.max_over_min, Some(4.0));
        let dark = Statistics::of(&[0.0, 10.0]);
        assert_eq!((dark.uniformity, dark.max_over_min), (0.0, None));
    }
}
