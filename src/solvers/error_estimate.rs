//! A-posteriori error estimation, Bekaert–Willems §4, from the link error coefficients that every
//! coupling carries (Algorithm 4.1). On each element `l` and at each of its cubature nodes `x_k`, the
//! error sources of the links stored at `l` add up with their signs: `Σ_j δ_j(x_k)` with
//! `δ_j(x_k) = ρ_l Σ_β L_{j,β} δ_{j,β}(x_k)` (eq. (6)); the maximum over the nodes stands for the maximum
//! over the element (§4.3). As in the paper's hierarchical version, each level is estimated separately,
//! the estimates of ancestors are added on the way down, and an inner element gets the largest estimate
//! below it (the extended push-pull of algorithm 6.1). Emission is constant per patch and so represented
//! exactly by every basis: `δ_e = 0`. To these we add the visibility sampling errors of the links
//! (`LinkCoupling::visibility_error`, Bekaert–Willems §7), in quadrature.
//!
//! * [`EstimateKind::Realistic`]: `ε̃_i = max_k |δ_e(x_k) + Σ_j δ_j(x_k)|`, ignoring propagation (§4.3: not
//!   conservative, but realistic, and what error control uses).
//! * [`EstimateKind::Conservative`]: eq. (11), `ε̄_i = max_k |Σ_j δ_j(x_k) + Σ_j ε̄_j K_{j,1}(x_k)|`, solved
//!   by Jacobi iteration (it converges since `Σ_j ∫ K = ρ < 1`).

use crate::color::Rgb;
use crate::hierarchy::{ElementId, Hierarchy};
use rayon::prelude::*;

/// Which estimate (`--error-estimate`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum EstimateKind {
    /// Local error sources only (§4.3).
    #[default]
    Realistic,
    /// With propagated error, eq. (11): an upper bound up to the node sampling of the maximum.
    Conservative,
}

/// Most Jacobi iterations for eq. (11).
const CONSERVATIVE_ITERATIONS: usize = 100;

/// Computes the estimate of `kind` and stores it in `Element::error` (after the extended push-pull).
pub fn estimate_errors(hierarchy: &mut Hierarchy, kind: EstimateKind) {
    let mut errors = level_errors(hierarchy, None);
    extended_push_pull(hierarchy, &mut errors);
    if kind == EstimateKind::Conservative {
        for _ in 0..CONSERVATIVE_ITERATIONS {
            let mut next = level_errors(hierarchy, Some(&errors));
            extended_push_pull(hierarchy, &mut next);
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

/// The error of each element's own links, per element: `max_k |Σ_j δ_j(x_k) (+ Σ_j ε̄_j K_{j,1}(x_k))|`,
/// largest channel; `propagated` holds the sources' current conservative estimates.
fn level_errors(h: &Hierarchy, propagated: Option<&[f64]>) -> Vec<f64> {
    (0..h.elements.len())
        .into_par_iter()
        .map(|id| {
            let e = &h.elements[id];
            let Some(first) = e.links.first() else {
                return 0.0;
            };
            let nodes = first.coupling.node_count();
            let rho = h.reflectance_of(id as ElementId);
            // Visibility errors (see `LinkCoupling::visibility_error`) are sampling errors of independent
            // links: they add in quadrature.
            let visibility: f64 = e
                .links
                .iter()
                .map(|l| {
                    (h.element(l.source).average_radiance().max_channel()
                        * f64::from(l.coupling.visibility_error))
                    .powi(2)
                })
                .sum::<f64>()
                .sqrt()
                * rho.max_channel();
            let mut worst = 0.0f64;
            for k in 0..nodes {
                let mut sum = Rgb::BLACK;
                let mut spread = 0.0;
                for link in &e.links {
                    sum += link
                        .coupling
                        .node_error(k, &h.element(link.source).radiance);
                    if let Some(bounds) = propagated {
                        spread +=
                            bounds[link.source as usize] * link.coupling.node_factors()[k] as f64;
                    }
                }
                for (rho_c, sum_c) in [(rho.r, sum.r), (rho.g, sum.g), (rho.b, sum.b)] {
                    worst = worst.max(rho_c * (sum_c.abs() + spread));
                }
            }
            worst + visibility
        })
        .collect()
}

/// Adds each element's estimate to its descendants, then sets every inner element to the largest
/// estimate of its leaves (algorithm 6.1, steps 2b and 2e of the extended push-pull).
fn extended_push_pull(h: &Hierarchy, errors: &mut [f64]) {
    for root in h.roots() {
        down_then_up(h, root, 0.0, errors);
    }
}

fn down_then_up(h: &Hierarchy, id: ElementId, above: f64, errors: &mut [f64]) -> f64 {
    let own = errors[id as usize] + above;
    let e = h.element(id);
    let total = if e.is_leaf() {
        own
    } else {
        e.children
            .iter()
            .map(|&c| down_then_up(h, c, own, errors))
            .fold(0.0, f64::max)
    };
    errors[id as usize] = total;
    total
}

/// Estimate over the leaves: how many exceed `accuracy`, the largest estimate, and the area fraction
/// above `accuracy`.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct ErrorSummary {
    pub leaves: usize,
    pub leaves_above: usize,
    pub max_estimate: f64,
    /// Area-weighted mean of the leaf estimates.
    pub mean_estimate: f64,
    pub area_fraction_above: f64,
}

/// Summary of `Element::error` over the leaves, against `accuracy` (radiance).
pub fn summarize(h: &Hierarchy, accuracy: f64) -> ErrorSummary {
    let mut s = ErrorSummary::default();
    let (mut area, mut area_above, mut weighted) = (0.0, 0.0, 0.0);
    for id in h.leaves() {
        let e = h.element(id);
        s.leaves += 1;
        area += e.area;
        weighted += e.area * e.error;
        s.max_estimate = s.max_estimate.max(e.error);
        if e.error > accuracy {
            s.leaves_above += 1;
            area_above += e.area;
        }
    }
    if area > 0.0 {
        s.mean_estimate = weighted / area;
        s.area_fraction_above = area_above / area;
    }
    s
}
