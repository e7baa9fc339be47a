//! Direct light from goniometric luminaires ([`crate::scene::luminaire`]) by a first gather: at every
//! leaf's cubature nodes x_k the irradiance E(x_k) = Σ_luminaires I(ω) cos θ_x / d² × transmittance is
//! evaluated (with the opening sampled by several points when the receiver is near), divided by π and
//! projected on the leaf's basis like a gathered term (`H_α = (1/A) Σ_k w_k φ_α(x_k) E(x_k)/π`, the
//! coupling of Bekaert–Willems eq. (3) with a point source). The coefficients are a fixed part of the
//! leaf's irradiance in every sweep ([`super::push_pull`] adds them, so L = E_self + ρ (H + H_direct)).
//!
//! Refinement: a leaf whose projected direct term misses its own node values (and its centroid's) by more than the threshold
//! is split, max_k |E(x_k)/π − Ê(x_k)/π| × A against the power oracle's threshold (radiance × area), or
//! that residual against the leaf's error-control threshold (algorithm 6.1), until the minimum area or
//! the element budget stops it; the residual is raised to what a luminaire's beam may put between the
//! nodes where the cone toward the leaf holds over twice what the nodes see ([`missed_beam`]: a
//! narrow beam can fall between them). The receiver's reflectance is left out (the leaf is judged as if white)
//! so that illuminance comes out accurate on black surfaces too. Elements never merge and luminaires do not move, so a leaf's
//! coefficients are computed once and kept across passes.

use super::refine::RefineSettings;
use crate::color::Rgb;
use crate::geometry::cubature::{nodes_on, rule, Node};
use crate::hierarchy::{ElementId, Hierarchy};
use crate::parallel::Uneven;
use crate::visibility::Visibility;
use rayon::prelude::*;
use std::f64::consts::PI;

/// What one call of [`refine_and_gather`] did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DirectOutcome {
    pub subdivisions: usize,
    /// Shadow rays cast toward luminaire openings.
    pub rays: u64,
    pub refused_by_budget: usize,
}

/// Computes the direct coefficients (and projection residuals, [`Hierarchy::direct_residual`]) of
/// every leaf not yet computed and splits leaves whose direct term the basis misses (see the module
/// comment), repeating on the new leaves, against the leaf's threshold
/// ([`RefineSettings::threshold_into`]): a radiance when `radiance_thresholds` (the link error
/// oracle's, Bekaert–Willems algorithm 6.1), else radiance × area like eq. (1)'s. Elements never
/// merge, so what earlier passes computed is kept.
pub fn refine_and_gather(
    hierarchy: &mut Hierarchy,
    visibility: &dyn Visibility,
    settings: &RefineSettings,
    radiance_thresholds: bool,
) -> DirectOutcome {
    let mut outcome = DirectOutcome::default();
    if hierarchy.luminaires.is_empty() {
        return outcome;
    }
    let size = hierarchy.basis_size();
    let degree = settings.coupling.cubature_degree;
    loop {
        let done = hierarchy.direct_residual.len();
        let h = &*hierarchy;
        let fresh: Vec<ElementId> = (done..h.elements.len())
            .filter(|&id| h.elements[id].is_leaf())
            .map(|id| id as ElementId)
            .collect();
        let results: Vec<(Vec<Rgb>, f64, u64)> = fresh
            .par_iter()
            .uneven()
            .map(|&id| leaf_direct(h, visibility, id, degree))
            .collect();
        hierarchy
            .direct
            .resize(hierarchy.elements.len() * size, Rgb::BLACK);
        hierarchy
            .direct_residual
            .resize(hierarchy.elements.len(), 0.0);
        let mut split = Vec::new();
        for (&id, (coefficients, residual, rays)) in fresh.iter().zip(results) {
            let i = id as usize;
            hierarchy.direct[i * size..(i + 1) * size].copy_from_slice(&coefficients);
            hierarchy.direct_residual[i] = residual;
            outcome.rays += rays;
        }
        // Judge every leaf (thresholds fall between passes under error control), as if it were
        // white: illuminance is wanted accurate on every surface, black ones included.
        for id in hierarchy.leaves() {
            let e = hierarchy.element(id);
            let error =
                hierarchy.direct_residual[id as usize].max(missed_beam(hierarchy, id, degree));
            let too_coarse = if radiance_thresholds {
                error > e.threshold
            } else {
                error * e.area > settings.threshold_into(hierarchy, id)
            };
            if too_coarse && e.area > settings.min_area {
                split.push(id);
            }
        }
        if split.is_empty() {
            return outcome;
        }
        let before = outcome.subdivisions;
        hierarchy.reserve_splits(split.len());
        for id in split {
            if hierarchy.elements.len() + 4 > settings.max_elements {
                outcome.refused_by_budget += 1;
                continue;
            }
            hierarchy.subdivide(id);
            outcome.subdivisions += 1;
        }
        if outcome.subdivisions == before {
            hierarchy
                .direct
                .resize(hierarchy.elements.len() * size, Rgb::BLACK);
            return outcome;
        }
    }
}

/// Angle (degrees) a leaf may subtend from a luminaire before [`missed_beam`] asks whether a beam
/// falls between its nodes.
const BEAM_ANGLE: f64 = 10.0;

/// A bound on the direct radiance (E/π, largest channel) that a luminaire's beam may put on the leaf
/// between its nodes, 0 where none can. The residual test judges the light only at the nodes and
/// the centroid: a spot 2 m over a 20 m floor of two triangles lit none of them, and the floor
/// stayed dark. The directions from the luminaire to the leaf lie in a cone: toward its bounding
/// sphere, or, when the luminaire is inside that sphere, toward its plane (around the normal, out to
/// its farthest corner). Where the leaf faces the luminaire, the cone is wider than [`BEAM_ANGLE`]
/// and the brightest intensity toward any node is under half the brightest in the cone (a spot
/// light's edge, a narrow beam's peak), the bound is that brightest less the nodes', at the cone's
/// nearest distance (the sphere's, or the plane's), with cos θ ≤ 1. A leaf that subtends at most
/// 10° has nodes 5° apart or closer, so only beams narrower than that can still be missed; where the
/// nodes see the cone's brightest (an isotropic source, a broad distribution) the residual alone
/// decides.
fn missed_beam(hierarchy: &Hierarchy, id: ElementId, degree: usize) -> f64 {
    let shape = hierarchy.element(id).shape();
    let normal = hierarchy.patch_of(id).normal;
    let centre = shape.centroid();
    let corners = shape.vertices();
    let radius = corners
        .iter()
        .map(|&v| v.distance(centre))
        .fold(0.0, f64::max);
    let mut nodes = None;
    hierarchy
        .luminaires
        .iter()
        .map(|l| {
            let height = normal.dot(l.position - centre);
            if height <= 0.0 {
                return 0.0;
            }
            let to = centre - l.position;
            let distance = to.length();
            let (axis, half, nearest) = if distance > radius {
                (
                    to,
                    (radius / distance).asin().to_degrees(),
                    distance - radius,
                )
            } else {
                let farthest = corners
                    .iter()
                    .map(|&v| (v - l.position).reject_from_normalized(normal).length())
                    .fold(0.0, f64::max);
                (-normal, farthest.atan2(height).to_degrees(), height)
            };
            if 2.0 * half <= BEAM_ANGLE {
                return 0.0;
            }
            let (theta, _) = l.angles(axis);
            let (_, brightest) = l.photometry.intensity_bounds(theta - half, theta + half);
            let brightest = brightest * l.scale.max_channel();
            let seen = nodes
                .get_or_insert_with(|| judged_nodes(shape, degree))
                .iter()
                .map(|node: &Node| l.intensity(node.point - l.position).max_channel())
                .fold(0.0, f64::max);
            if seen >= 0.5 * brightest {
                return 0.0;
            }
            (brightest - seen) / (nearest * nearest) / PI
        })
        .fold(0.0, f64::max)
}

/// The points at which a leaf's direct light is computed and judged: its cubature nodes, and its
/// centroid with weight 0 (judged, not integrated): the nodes of a symmetric rule can all see the
/// same value of a peak centred on the leaf (a luminaire straight above its middle), which a
/// constant then fits exactly at every node.
fn judged_nodes(shape: &crate::geometry::Shape, degree: usize) -> Vec<Node> {
    let centre_uv = shape
        .parameter_corners()
        .iter()
        .copied()
        .sum::<crate::geometry::DVec2>()
        / shape.vertex_count() as f64;
    nodes_on(shape, rule(shape.domain(), degree))
        .into_iter()
        .chain(std::iter::once(Node {
            point: shape.point_at(centre_uv),
            uv: centre_uv,
            weight: 0.0,
        }))
        .collect()
}

/// A leaf's direct coefficients, its projection residual and the rays cast.
fn leaf_direct(
    hierarchy: &Hierarchy,
    visibility: &dyn Visibility,
    id: ElementId,
    degree: usize,
) -> (Vec<Rgb>, f64, u64) {
    let basis = &hierarchy.basis;
    let size = basis.size();
    let e = hierarchy.element(id);
    let shape = e.shape();
    let patch = hierarchy.patch_of(id);
    let (normal, polygon) = (patch.normal, patch.polygon);
    let nodes = judged_nodes(shape, degree);
    let phi = super::coupling::basis_values(basis, shape, &nodes);
    let mut rays = 0u64;
    let values: Vec<Rgb> = nodes
        .iter()
        .map(|node| {
            hierarchy
                .luminaires
                .iter()
                .map(|l| {
                    l.irradiance(node.point, normal, |from, to| {
                        rays += 1;
                        visibility.transmittance_onto(from, to, polygon)
                    })
                })
                .sum::<Rgb>()
                * (1.0 / PI)
        })
        .collect();
    let mut coefficients = vec![Rgb::BLACK; size];
    for (k, node) in nodes.iter().enumerate() {
        let w = node.weight / e.area;
        for (alpha, c) in coefficients.iter_mut().enumerate() {
            *c += values[k] * (w * phi[k * size + alpha]);
        }
    }
    // Moments to coefficients on a trapezoid-like quad (as couplings do).
    if let Some(overlap) = basis.overlap(shape, e.area) {
        overlap.solve_rgb(&mut coefficients);
    }
    let residual = values
        .iter()
        .enumerate()
        .map(|(k, &v)| {
            let projected: Rgb = (0..size)
                .map(|alpha| coefficients[alpha] * phi[k * size + alpha])
                .sum();
            let d = v - projected;
            d.r.abs().max(d.g.abs()).max(d.b.abs())
        })
        .fold(0.0, f64::max);
    (coefficients, residual, rays)
}
