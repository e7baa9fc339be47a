//! A-posteriori error estimation, Bekaert–Willems §4, from the link error coefficients that every
//! coupling carries (Algorithm 4.1). The error at a point `x` of a leaf is eq. (5) without propagation,
//! `ε(x) = δ_e(x) + Σ_j δ_j(x)`, where the sum runs over the links of the leaf *and of all its
//! ancestors* (every level's received radiance is pushed down to the leaf, and with it the error of its
//! projection), `δ_j(x) = ρ Σ_β L_{j,β} δ_{j,β}(x)` (eq. (6)), known at the cubature nodes `x_k` of the
//! element holding the link; the maximum over the nodes stands for the maximum over the element (§4.3).
//! Levels are combined in one of two ways:
//!
//! * per level, as in the paper's hierarchical version: each level's `max_k |Σ_j δ_j(x_k)|` is added to
//!   its descendants' (the extended push-pull of algorithm 6.1). A bound on the local error, which
//!   never falls where the levels' errors cancel (at a room's edges);
//! * with their signs at common points ([`EstimateKind::Signed`]): an ancestor's `Σ_j δ_j` reaches a
//!   child's nodes through the polynomial fitted to it at the ancestor's nodes ([`node_transfer`]:
//!   degree `n − 1` for `n` nodes per direction, the rule's resolution); the child adds its own sum
//!   and passes the total on, and the leaf takes the maximum over its nodes of the total.
//!
//! A leaf lit by luminaires adds its reflectance times the first gather's projection residual
//! ([`Hierarchy::direct_residual`]: the direct term is one more received term whose projection
//! misses its node values). Inner elements get the largest estimate below them (step 2e). Emission is constant per patch and so
//! represented exactly by every basis: `δ_e = 0`. Links at clusters have no surface nodes (their one
//! `δ` is taken at the receiver's visibility sample points, `solvers::clustering::couple_cluster`):
//! their maximum is added to every element below, and to each patch what sharing a cluster's received
//! light by exposure moved to or from it (`solvers::clustering::moved_by_exposure`: the link's one
//! average visibility says how much arrives, one ray per patch where; the patch's share is uncertain
//! by as much as exposure moved it), and to each element what sending by exposure moved on its own
//! partly blocked links from clusters (`solvers::clustering::moved_by_sending`: such a link carries
//! the average of its source's patches that a ray reaches the receiver from, one ray per patch, and
//! the received light is uncertain by as much as that choice moved it from all visible patches'
//! average; a link whose rays all reached has neither this term nor a visibility error, a known gap).
//! To these we add the visibility sampling errors of the links (`LinkCoupling::visibility_error`,
//! Bekaert–Willems §7), which are independent sampling errors of different links: in quadrature over a
//! level's links (per level), or over all the links of the leaf and its ancestors (signed).
//!
//! * [`EstimateKind::Realistic`]: `ε̃_i = max_k |δ_e(x_k) + Σ_j δ_j(x_k)|` per level, ignoring propagation
//!   (§4.3: not conservative, but realistic, and what error control uses by default).
//! * [`EstimateKind::Signed`]: the same sum with the levels' signs at the leaf's nodes.
//! * [`EstimateKind::Conservative`]: eq. (11), `ε̄_i = max_k |Σ_j δ_j(x_k) + Σ_j ε̄_j K_{j,1}(x_k)|` per
//!   level, solved by Jacobi iteration (it converges since `Σ_j ∫ K = ρ < 1`).

use crate::bases::child_parameters;
use crate::color::Rgb;
use crate::geometry::cubature::{rule, MAX_POINTS};
use crate::geometry::{DVec2, Domain};
use crate::hierarchy::{ElementId, Hierarchy};
use crate::parallel::Uneven;
use crate::solvers::clustering::{moved_by_exposure, moved_by_sending, ClusterSweep};
use rayon::prelude::*;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::OnceLock;

/// Which estimate (`--error-estimate`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum EstimateKind {
    /// Local error sources only (§4.3).
    #[default]
    Realistic,
    /// With propagated error, eq. (11): an upper bound up to the node sampling of the maximum.
    Conservative,
    /// Local error sources only, the levels summed with their signs at each leaf's nodes.
    Signed,
}

/// Most Jacobi iterations for eq. (11).
const CONSERVATIVE_ITERATIONS: usize = 100;

/// Computes the estimate of `kind` and stores it in `Element::error`.
pub fn estimate_errors(hierarchy: &mut Hierarchy, kind: EstimateKind) {
    let signed = kind == EstimateKind::Signed;
    let moved = {
        let sweep = ClusterSweep::sent_only(hierarchy);
        Moved {
            receiving: moved_by_exposure(hierarchy, &sweep),
            sending: moved_by_sending(hierarchy, &sweep),
        }
    };
    let mut errors = estimate(hierarchy, None, signed, &moved);
    if kind == EstimateKind::Conservative {
        for _ in 0..CONSERVATIVE_ITERATIONS {
            let next = estimate(hierarchy, Some(&errors), false, &moved);
            let change = next
                .iter()
                .zip(&errors)
                .map(|(a, b)| (a - b).abs() / a.max(1e-300))
                .fold(0.0, f64::max);
            errors = next;
            if change < 1e-4 {
                break;
            }
        }
    }
    for (e, error) in hierarchy.elements.iter_mut().zip(errors) {
        e.error = error;
    }
}

/// Every element's estimate: on a leaf, over its own and its ancestors' links, the sum of the levels'
/// maxima over their nodes, or (`signed`) the maximum over its nodes of the levels' signed sum; on an
/// inner element or cluster, the largest estimate below. `propagated` holds the sources' current
/// conservative estimates (eq. (11)); `moved`, what exposure moved ([`Moved`]).
fn estimate(h: &Hierarchy, propagated: Option<&[f64]>, signed: bool, moved: &Moved) -> Vec<f64> {
    // What the clusters above each patch root add (their links have no surface nodes).
    let mut above = vec![Above::default(); h.patches.len()];
    if let Some(root) = h.root_cluster {
        clusters_down(h, root, Above::default(), propagated, moved, &mut above);
        for (above, patch) in above.iter_mut().zip(&h.patches) {
            let rho = h.reflectance_of(patch.root);
            *above = above.plus(
                (rho * moved.receiving[patch.root as usize]).max_channel(),
                0.0,
            );
        }
    }
    // Each element's estimate written once, by the walk of the one patch tree it is in (the bits of
    // an `f64`: no list per tree, which made a tenth of office3's peak heap).
    let written: Vec<AtomicU64> = (0..h.elements.len()).map(|_| AtomicU64::new(0)).collect();
    h.patches
        .par_iter()
        .zip(&above)
        .uneven()
        .for_each(|(patch, &above)| {
            let walk = TreeWalk {
                h,
                propagated,
                signed,
                moved,
            };
            walk.visit(patch.root, NodeSums::default(), above, &written);
        });
    let mut errors: Vec<f64> = written
        .into_iter()
        .map(|bits| f64::from_bits(bits.into_inner()))
        .collect();
    if let Some(root) = h.root_cluster {
        clusters_up(h, root, &mut errors);
    }
    errors
}

/// The part of a leaf's estimate that has no place on its nodes: the maxima of cluster links above its
/// patch (and, per level, of every level above it), and the squared visibility errors of the links on
/// its path (of the signed estimate; per level, each level's in quadrature is in its maximum).
#[derive(Clone, Copy, Debug, Default)]
struct Above {
    unplaced: f64,
    visibility_squared: f64,
}

impl Above {
    fn plus(self, unplaced: f64, visibility_squared: f64) -> Above {
        Above {
            unplaced: self.unplaced + unplaced,
            visibility_squared: self.visibility_squared + visibility_squared,
        }
    }

    fn total(self) -> f64 {
        self.unplaced + self.visibility_squared.sqrt()
    }
}

/// What sending and sharing by exposure moved (`solvers::clustering`), the uncertainty of the choices
/// one centroid ray per patch makes.
struct Moved {
    /// Per patch root, the irradiance over π that sharing by exposure moved ([`moved_by_exposure`]).
    receiving: Vec<Rgb>,
    /// Per element, the radiance that sending by exposure moved on its own links
    /// ([`moved_by_sending`]).
    sending: Vec<f64>,
}

impl Moved {
    /// What sending by exposure moved on element `id`'s links, times its reflectance (largest channel).
    fn sent_to(&self, id: ElementId) -> f64 {
        self.sending[id as usize]
    }
}

/// Walks the cluster tree from `id`, leaving in `above[patch]` what the clusters on the way to each
/// patch root add.
fn clusters_down(
    h: &Hierarchy,
    id: ElementId,
    above: Above,
    propagated: Option<&[f64]>,
    moved: &Moved,
    out: &mut [Above],
) {
    if !h.is_cluster(id) {
        out[h.element(id).patch() as usize] = above;
        return;
    }
    let own = own_sums(h, id, propagated).map_or(0.0, |s| s.maximum());
    let here = above.plus(
        own + visibility_squared(h, id).sqrt() + moved.sent_to(id),
        0.0,
    );
    for &child in &h.element(id).children {
        clusters_down(h, child, here, propagated, moved, out);
    }
}

/// Sets every cluster's estimate to the largest below it.
fn clusters_up(h: &Hierarchy, id: ElementId, errors: &mut [f64]) -> f64 {
    if h.is_cluster(id) {
        errors[id as usize] = h
            .element(id)
            .children
            .iter()
            .map(|&c| clusters_up(h, c, errors))
            .fold(0.0, f64::max);
    }
    errors[id as usize]
}

/// `Σ_j δ_j(x_k)` (signed) and, for eq. (11), `Σ_j ε̄_j K_{j,1}(x_k)` at an element's nodes, with the
/// receiver's reflectance applied per channel; empty where nothing has been gathered yet.
#[derive(Clone, Debug, Default)]
struct NodeSums {
    signed: Vec<Rgb>,
    spread: Vec<Rgb>,
}

impl NodeSums {
    /// `max_k max_c |signed| + spread`.
    fn maximum(&self) -> f64 {
        let spread = |k: usize| self.spread.get(k).copied().unwrap_or(Rgb::BLACK);
        self.signed
            .iter()
            .enumerate()
            .map(|(k, s)| {
                let p = spread(k);
                (s.r.abs() + p.r).max(s.g.abs() + p.g).max(s.b.abs() + p.b)
            })
            .fold(0.0, f64::max)
    }

    /// `self + other` node by node (`self` may be empty).
    fn add(mut self, other: NodeSums) -> NodeSums {
        if self.signed.is_empty() {
            return other;
        }
        self.signed
            .iter_mut()
            .zip(other.signed)
            .for_each(|(x, y)| *x += y);
        self
    }

    /// The signed sums carried to the nodes of child `child` on `domain` ([`node_transfer`]).
    fn to_child(&self, domain: Domain, child: usize) -> NodeSums {
        let n = self.signed.len();
        if n == 0 {
            return NodeSums::default();
        }
        let t = node_transfer(domain, points_per_direction(n), child);
        let signed = (0..n)
            .map(|a| {
                t[a * n..(a + 1) * n]
                    .iter()
                    .zip(&self.signed)
                    .map(|(&w, &v)| v * w)
                    .sum()
            })
            .collect();
        NodeSums {
            signed,
            spread: Vec::new(),
        }
    }
}

/// Sums over the own links of element `id` at its nodes (`None` without links).
fn own_sums(h: &Hierarchy, id: ElementId, propagated: Option<&[f64]>) -> Option<NodeSums> {
    let e = h.element(id);
    let nodes = e.links.first()?.coupling.node_count();
    let rho = h.reflectance_of(id);
    let mut sums = NodeSums {
        signed: vec![Rgb::BLACK; nodes],
        spread: if propagated.is_some() {
            vec![Rgb::BLACK; nodes]
        } else {
            Vec::new()
        },
    };
    for link in &e.links {
        let radiance = h.radiance(link.source);
        for k in 0..nodes {
            sums.signed[k] += rho * link.coupling.node_error(k, radiance);
        }
        if let Some(bounds) = propagated {
            let bound = bounds[link.source as usize];
            for (s, factor) in sums.spread.iter_mut().zip(link.coupling.node_factors()) {
                *s += rho * (bound * f64::from(factor));
            }
        }
    }
    Some(sums)
}

/// Σ over the links of `id` of the squared visibility error (`LinkCoupling::visibility_error` times
/// the source's radiance and ρ): sampling errors of independent links add in quadrature.
fn visibility_squared(h: &Hierarchy, id: ElementId) -> f64 {
    let rho = h.reflectance_of(id).max_channel();
    h.element(id)
        .links
        .iter()
        .map(|l| {
            (rho * h.average_radiance(l.source).max_channel()
                * f64::from(l.coupling.visibility_error()))
            .powi(2)
        })
        .sum()
}

/// Walk of one patch tree, pushing the levels' maxima or (`signed`) their node sums down.
struct TreeWalk<'a> {
    h: &'a Hierarchy,
    propagated: Option<&'a [f64]>,
    signed: bool,
    moved: &'a Moved,
}

impl TreeWalk<'_> {
    /// Estimates the subtree of `id`, which inherits `inherited` at its nodes and `above` besides,
    /// into `out`; returns its estimate.
    fn visit(&self, id: ElementId, inherited: NodeSums, above: Above, out: &[AtomicU64]) -> f64 {
        let h = self.h;
        let e = h.element(id);
        let visibility = visibility_squared(h, id);
        let mut above = if self.signed {
            above.plus(0.0, visibility)
        } else {
            above.plus(visibility.sqrt(), 0.0)
        }
        .plus(self.moved.sent_to(id), 0.0);
        let mut sums = inherited;
        if let Some(own) = own_sums(h, id, self.propagated) {
            let placed = sums.signed.is_empty() || sums.signed.len() == own.signed.len();
            if self.signed && placed {
                sums = sums.add(own);
            } else {
                // Per level; or links with another receiver rule than their ancestors' (not made by
                // `couple`): their maximum, unplaced.
                above = above.plus(own.maximum(), 0.0);
            }
        }
        let error = if e.is_leaf() {
            // The luminaires' direct term, projected on the leaf's basis, misses its node values by
            // the first gather's residual (irradiance / π), reflected.
            let direct = h.direct_residual.get(id as usize).copied().unwrap_or(0.0)
                * h.reflectance_of(id).max_channel();
            sums.maximum() + above.total() + direct
        } else {
            let domain = e.shape().domain();
            e.children
                .iter()
                .enumerate()
                .map(|(k, &child)| self.visit(child, sums.to_child(domain, k), above, out))
                .fold(0.0, f64::max)
        };
        out[id as usize].store(error.to_bits(), Ordering::Relaxed);
        error
    }
}

/// Estimate over the leaves: how many exceed `accuracy`, the largest estimate, and the area fraction
/// above `accuracy`.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct ErrorSummary {
    pub leaves: usize,
    pub leaves_above: usize,
    /// Of the leaves above the accuracy, those at the minimum element area: refinement cannot split
    /// them, so no later pass can bring them under it (corners and contacts, where the radiance is not
    /// polynomial at any element size).
    pub leaves_above_at_min_area: usize,
    pub max_estimate: f64,
    /// Area-weighted mean of the leaf estimates.
    pub mean_estimate: f64,
    pub area_fraction_above: f64,
    /// The share of the area in leaves above the accuracy that refinement can still split: what a
    /// further pass of error control can improve.
    pub area_fraction_above_splittable: f64,
}

/// Summary of `Element::error` over the leaves, against `allowed` (radiance per leaf,
/// [`crate::solvers::ErrorControl::allowed`]); surface leaves of at most `min_area` cannot be split
/// further.
pub fn summarize(h: &Hierarchy, allowed: impl Fn(ElementId) -> f64, min_area: f64) -> ErrorSummary {
    let mut s = ErrorSummary::default();
    let (mut area, mut area_above, mut area_splittable, mut weighted) = (0.0, 0.0, 0.0, 0.0);
    for id in h.leaves() {
        let e = h.element(id);
        s.leaves += 1;
        area += e.area;
        weighted += e.area * e.error;
        s.max_estimate = s.max_estimate.max(e.error);
        if e.error > allowed(id) {
            s.leaves_above += 1;
            area_above += e.area;
            if !h.is_cluster(id) && e.area <= min_area {
                s.leaves_above_at_min_area += 1;
            } else {
                area_splittable += e.area;
            }
        }
    }
    if area > 0.0 {
        s.mean_estimate = weighted / area;
        s.area_fraction_above = area_above / area;
        s.area_fraction_above_splittable = area_splittable / area;
    }
    s
}

/// `n` for a rule of `n × n` nodes.
fn points_per_direction(nodes: usize) -> usize {
    (1..=MAX_POINTS)
        .find(|n| n * n >= nodes)
        .unwrap_or(MAX_POINTS)
}

/// The `N × N` row-major matrix (N = n²) that takes values at the nodes of [`rule`]`(domain, 2n − 1)`
/// on an element to the values, at the same rule's nodes on child `child` (the order of
/// `Shape::subdivide`), of the polynomial fitted to them: the least-squares fit, with the rule's
/// weights, by polynomials of degree `n − 1` (in each variable on the square, where the fit
/// interpolates the tensor Gauss nodes; in total on the triangle). Both spaces are closed under the
/// children's affine parameter maps ([`child_parameters`]), so values carried down twice are those
/// of the same polynomial.
fn node_transfer(domain: Domain, n: usize, child: usize) -> &'static [f64] {
    static TABLE: [OnceLock<[[Vec<f64>; 4]; 2]>; MAX_POINTS] =
        [const { OnceLock::new() }; MAX_POINTS];
    let n = n.clamp(1, MAX_POINTS);
    let matrices = TABLE[n - 1].get_or_init(|| {
        [Domain::Square, Domain::Triangle].map(|d| [0, 1, 2, 3].map(|c| transfer_matrix(d, n, c)))
    });
    let d = match domain {
        Domain::Square => 0,
        Domain::Triangle => 1,
    };
    &matrices[d][child]
}

fn transfer_matrix(domain: Domain, n: usize, child: usize) -> Vec<f64> {
    // Legendre products P_p(2u − 1) P_q(2v − 1): better conditioned than monomials.
    let exponents: Vec<(usize, usize)> = (0..n)
        .flat_map(|p| (0..n).map(move |q| (p, q)))
        .filter(|&(p, q)| domain == Domain::Square || p + q < n)
        .collect();
    let f = exponents.len();
    let functions = |uv: DVec2| -> Vec<f64> {
        let (lu, lv) = (legendre(n, 2.0 * uv.x - 1.0), legendre(n, 2.0 * uv.y - 1.0));
        exponents.iter().map(|&(p, q)| lu[p] * lv[q]).collect()
    };
    let nodes = &rule(domain, 2 * n - 1).nodes;
    let count = nodes.len();
    // Normal equations G c = Ψᵀ W v, solved for every node value at once: fit = G⁻¹ Ψᵀ W (f × N).
    let mut gram = vec![0.0; f * f];
    let mut fit = vec![0.0; f * count];
    for (k, &(uv, w)) in nodes.iter().enumerate() {
        let psi = functions(uv);
        for a in 0..f {
            fit[a * count + k] = w * psi[a];
            for b in 0..f {
                gram[a * f + b] += w * psi[a] * psi[b];
            }
        }
    }
    solve_in_place(&mut gram, &mut fit, f, count);
    let mut transfer = vec![0.0; count * count];
    for (a, &(uv, _)) in nodes.iter().enumerate() {
        let psi = functions(child_parameters(domain, child, uv));
        for b in 0..count {
            transfer[a * count + b] = (0..f).map(|m| psi[m] * fit[m * count + b]).sum();
        }
    }
    transfer
}

/// `P_0(x) … P_{n−1}(x)` by the three-term recurrence.
fn legendre(n: usize, x: f64) -> Vec<f64> {
    let mut p = vec![1.0; n.max(2)];
    p[1] = x;
    for k in 2..n {
        p[k] = ((2 * k - 1) as f64 * x * p[k - 1] - (k - 1) as f64 * p[k - 2]) / k as f64;
    }
    p.truncate(n);
    p
}

/// Solves `A X = B` for the `f × f` matrix `a` (symmetric positive definite here) and the `f × m`
/// right-hand sides `b`, in place, by Gaussian elimination with partial pivoting.
fn solve_in_place(a: &mut [f64], b: &mut [f64], f: usize, m: usize) {
    for col in 0..f {
        let pivot = (col..f)
            .max_by(|&i, &j| a[i * f + col].abs().total_cmp(&a[j * f + col].abs()))
            .unwrap_or(col);
        if pivot != col {
            for c in 0..f {
                a.swap(col * f + c, pivot * f + c);
            }
            for c in 0..m {
                b.swap(col * m + c, pivot * m + c);
            }
        }
        let d = a[col * f + col];
        for row in col + 1..f {
            let factor = a[row * f + col] / d;
            if factor == 0.0 {
                continue;
            }
            for c in col..f {
                a[row * f + c] -= factor * a[col * f + c];
            }
            for c in 0..m {
                b[row * m + c] -= factor * b[col * m + c];
            }
        }
    }
    for col in (0..f).rev() {
        let d = a[col * f + col];
        for c in 0..m {
            let mut v = b[col * m + c];
            for k in col + 1..f {
                v -= a[col * f + k] * b[k * m + c];
            }
            b[col * m + c] = v / d;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A polynomial of the fitted space, given at an element's nodes, reaches each child's nodes with
    /// its own values there: on the square `u³v³ − 2u²v + v − ½` (degree 3 in each variable), on the
    /// triangle `u³ − 2uv² + v + 1` (total degree 3), with four nodes per direction; and twice down
    /// is the same as evaluating at the grandchild's nodes.
    #[test]
    fn node_transfer_carries_polynomials_to_the_children_exactly() {
        let square = |p: DVec2| p.x.powi(3) * p.y.powi(3) - 2.0 * p.x * p.x * p.y + p.y - 0.5;
        let triangle = |p: DVec2| p.x.powi(3) - 2.0 * p.x * p.y * p.y + p.y + 1.0;
        let n = 4;
        for (domain, f) in [
            (Domain::Square, &square as &dyn Fn(DVec2) -> f64),
            (Domain::Triangle, &triangle),
        ] {
            let nodes = &rule(domain, 2 * n - 1).nodes;
            let parent: Vec<f64> = nodes.iter().map(|&(uv, _)| f(uv)).collect();
            let carry = |values: &[f64], child: usize| -> Vec<f64> {
                let t = node_transfer(domain, n, child);
                let m = values.len();
                (0..m)
                    .map(|a| (0..m).map(|b| t[a * m + b] * values[b]).sum())
                    .collect()
            };
            for child in 0..4 {
                let down = carry(&parent, child);
                let twice = carry(&down, (child + 1) % 4);
                for (k, &(uv, _)) in nodes.iter().enumerate() {
                    let at_child = child_parameters(domain, child, uv);
                    let at_grandchild = child_parameters(
                        domain,
                        child,
                        child_parameters(domain, (child + 1) % 4, uv),
                    );
                    assert!((down[k] - f(at_child)).abs() < 1e-11, "{domain:?} {child}");
                    assert!(
                        (twice[k] - f(at_grandchild)).abs() < 1e-11,
                        "{domain:?} {child}"
                    );
                }
            }
        }
    }
}
