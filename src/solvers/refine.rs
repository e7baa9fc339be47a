//! Hierarchical refinement (Hanrahan et al. 1991) as deterministic parallel rounds: every pending
//! candidate link is judged by the oracle in parallel; the elements to split are split sequentially in
//! candidate order; split candidates are replaced by links to the children and judged in the next round.
//! Admissible links get their form factors in parallel at the end. The element and link sets therefore
//! do not depend on the number of threads.

use super::coupling::{form_factor, CouplingSettings};
use super::link_rng;
use crate::geometry::Shape;
use crate::hierarchy::{ElementId, Hierarchy, Link};
use crate::oracles::{reflected_source_radiance, Decision, OracleContext, RefinementOracle};
use crate::visibility::Visibility;
use rayon::prelude::*;

/// A link under consideration; `form_factor` and `oracle_factor` are cached for links that were already
/// computed and judged.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Candidate {
    pub receiver: ElementId,
    pub source: ElementId,
    pub form_factor: Option<f64>,
    pub oracle_factor: Option<f64>,
}

/// Refinement parameters.
#[derive(Clone, Copy, Debug)]
pub struct RefineSettings {
    /// Oracle threshold ε, in the oracle's units (radiance × area).
    pub threshold: f64,
    /// Elements of at most this area are never split.
    pub min_area: f64,
    pub coupling: CouplingSettings,
    pub seed: u64,
}

/// What one refinement pass did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RefineOutcome {
    /// Elements split in this pass.
    pub subdivisions: usize,
    /// Candidates the oracle asked to refine.
    pub refined_links: usize,
    /// Rays cast by the oracle.
    pub oracle_rays: u64,
    /// Rays cast for form factors.
    pub form_factor_rays: u64,
}

/// Whether two elements can exchange light at all: each has a vertex strictly in front of the other.
pub fn can_interact(receiver: &Shape, source: &Shape) -> bool {
    fn in_front(plane: &Shape, other: &Shape) -> bool {
        let (n, p) = (plane.normal(), plane.vertices()[0]);
        let tolerance = 1e-9 * plane.diameter().max(other.diameter());
        other.vertices().iter().any(|v| n.dot(*v - p) > tolerance)
    }
    in_front(receiver, source) && in_front(source, receiver)
}

/// Root-to-root candidates for every ordered pair of patches that can interact (Hanrahan's initial
/// linking; quadratic in the number of patches, which clustering removes). Receivers that reflect
/// nothing and sources that can never radiate are skipped.
pub fn initial_candidates(hierarchy: &Hierarchy) -> Vec<Candidate> {
    let patches = &hierarchy.patches;
    (0..patches.len())
        .into_par_iter()
        .flat_map_iter(|i| {
            let receiver = &patches[i];
            patches.iter().enumerate().filter_map(move |(j, source)| {
                let useful = !receiver.reflectance.is_black()
                    && (!source.emission.is_black() || !source.reflectance.is_black());
                (i != j
                    && useful
                    && receiver.polygon != source.polygon
                    && can_interact(&receiver.shape, &source.shape))
                .then_some(Candidate {
                    receiver: receiver.root,
                    source: source.root,
                    form_factor: None,
                    oracle_factor: None,
                })
            })
        })
        .collect()
}

/// Removes every link from the hierarchy and returns them as candidates (for re-refinement after the
/// radiance changed), keeping their form factors.
pub fn take_links(hierarchy: &mut Hierarchy) -> Vec<Candidate> {
    let mut out = Vec::with_capacity(hierarchy.link_count());
    for (id, e) in hierarchy.elements.iter_mut().enumerate() {
        for link in e.links.drain(..) {
            out.push(Candidate {
                receiver: id as ElementId,
                source: link.source,
                form_factor: Some(link.form_factor),
                oracle_factor: link.oracle_factor,
            });
        }
    }
    out
}

const ORACLE_STREAM: u64 = 1;
const COUPLING_STREAM: u64 = 2;

/// Refines `candidates` until every one is admissible, then stores them as links at their receivers.
pub fn refine(
    hierarchy: &mut Hierarchy,
    visibility: &dyn Visibility,
    oracle: &dyn RefinementOracle,
    settings: &RefineSettings,
    mut candidates: Vec<Candidate>,
    on_round: &mut dyn FnMut(usize, usize),
) -> RefineOutcome {
    let mut outcome = RefineOutcome::default();
    let mut admissible: Vec<Candidate> = Vec::new();
    let mut round = 0;
    while !candidates.is_empty() {
        round += 1;
        on_round(round, candidates.len());
        let decisions: Vec<Verdict> = {
            let context = OracleContext {
                hierarchy,
                visibility,
            };
            candidates
                .par_iter()
                .map(|c| decide(&context, oracle, settings, c))
                .collect()
        };
        let mut next = Vec::new();
        for (c, verdict) in candidates.iter().zip(decisions) {
            outcome.oracle_rays += verdict.rays;
            match verdict.decision {
                Decision::Admissible => admissible.push(Candidate {
                    oracle_factor: verdict.oracle_factor,
                    ..*c
                }),
                Decision::SubdivideReceiver => {
                    outcome.refined_links += 1;
                    if hierarchy.element(c.receiver).is_leaf() {
                        outcome.subdivisions += 1;
                    }
                    for child in hierarchy.subdivide(c.receiver) {
                        push_if_interacting(hierarchy, &mut next, child, c.source);
                    }
                }
                Decision::SubdivideSource => {
                    outcome.refined_links += 1;
                    if hierarchy.element(c.source).is_leaf() {
                        outcome.subdivisions += 1;
                    }
                    for child in hierarchy.subdivide(c.source) {
                        push_if_interacting(hierarchy, &mut next, c.receiver, child);
                    }
                }
            }
        }
        candidates = next;
    }
    let h = &*hierarchy;
    let computed: Vec<(Option<Link>, u64)> = admissible
        .par_iter()
        .map(|c| match c.form_factor {
            Some(f) => (
                Some(Link {
                    source: c.source,
                    form_factor: f,
                    oracle_factor: c.oracle_factor,
                }),
                0,
            ),
            None => {
                let mut rng = link_rng(settings.seed, c.receiver, c.source, COUPLING_STREAM);
                let k = form_factor(
                    h,
                    visibility,
                    c.receiver,
                    c.source,
                    &settings.coupling,
                    &mut rng,
                );
                let link = (k.unoccluded > 0.0).then_some(Link {
                    source: c.source,
                    form_factor: k.form_factor,
                    oracle_factor: c.oracle_factor,
                });
                (link, k.rays)
            }
        })
        .collect();
    for (c, (link, rays)) in admissible.iter().zip(computed) {
        outcome.form_factor_rays += rays;
        if let Some(link) = link {
            hierarchy.elements[c.receiver as usize].links.push(link);
        }
    }
    outcome
}

fn push_if_interacting(
    h: &Hierarchy,
    out: &mut Vec<Candidate>,
    receiver: ElementId,
    source: ElementId,
) {
    if can_interact(&h.element(receiver).shape, &h.element(source).shape) {
        out.push(Candidate {
            receiver,
            source,
            form_factor: None,
            oracle_factor: None,
        });
    }
}

/// An oracle verdict on one candidate.
struct Verdict {
    decision: Decision,
    rays: u64,
    /// Radiance-independent factor of the estimate, to cache on the link.
    oracle_factor: Option<f64>,
}

/// The oracle's verdict, with the minimum-area rule: if the element it wants to split is too small the
/// other one is split instead, and if both are too small the link is admissible. A cached oracle factor
/// is reused (see the contract of [`RefinementOracle::estimate`]).
fn decide(
    context: &OracleContext,
    oracle: &dyn RefinementOracle,
    settings: &RefineSettings,
    c: &Candidate,
) -> Verdict {
    let h = context.hierarchy;
    let splittable = |id: ElementId| h.element(id).area > settings.min_area;
    if !splittable(c.receiver) && !splittable(c.source) {
        return Verdict {
            decision: Decision::Admissible,
            rays: 0,
            oracle_factor: c.oracle_factor,
        };
    }
    let weight = reflected_source_radiance(h, c.receiver, c.source);
    let (error, rays, oracle_factor) = match c.oracle_factor {
        Some(factor) => (weight * factor, 0, Some(factor)),
        None => {
            let mut rng = link_rng(settings.seed, c.receiver, c.source, ORACLE_STREAM);
            let estimate = oracle.estimate(context, c.receiver, c.source, &mut rng);
            let factor = (weight > 0.0).then(|| estimate.error / weight);
            (estimate.error, estimate.rays, factor)
        }
    };
    if error <= settings.threshold {
        return Verdict {
            decision: Decision::Admissible,
            rays,
            oracle_factor,
        };
    }
    let decision = match oracle.element_to_split(context, c.receiver, c.source) {
        Decision::SubdivideReceiver if !splittable(c.receiver) => Decision::SubdivideSource,
        Decision::SubdivideSource if !splittable(c.source) => Decision::SubdivideReceiver,
        other => other,
    };
    Verdict {
        decision,
        rays,
        oracle_factor,
    }
}
