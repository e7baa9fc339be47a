//! Hierarchical Monte Carlo radiosity (Bekaert, Neumann, Neumann, Sbert, Willems 1998): stochastic Jacobi
//! iterations in power-shooting form with local lines, refined per ray by a refinement oracle. This is
//! the solver Feixas et al. ran their oracles on.
//!
//! **Stochastic Jacobi.** Iteration k shoots the unshot power ΔP_j = π A_j ΔB_j of every leaf j (in the
//! first iteration the self-emitted power, ΔB = E: the direct illumination, plus ρ H of the IES
//! luminaires' deterministic first gather, [`super::direct`]) with N_k local lines: the
//! source leaf is chosen with probability proportional to its unshot power (stratified over the
//! cumulative distribution), the origin uniformly on it and the direction cosine-distributed about its
//! normal; the line's first hit receives the power it carries, ΔP_j / (N_k p_j). The power received by
//! each patch is then an unbiased estimate of Σ_j ΔP_j F_ji, the flux form of one Jacobi step. The new
//! unshot radiance is ΔB_i = ρ_i Φ_i / (π A_i) and B += ΔB. Iterations stop once the unshot power falls
//! below `tolerance` times the emitted power. N_1 is `rays_per_iteration`; later iterations get rays in
//! proportion to the power they shoot, so every line carries about the same power (Bekaert et al. §3).
//!
//! **Per-ray hierarchical refinement** (Bekaert et al. 1998 §4). When a line from source leaf j hits
//! patch P at y, both trees are descended: the receiver's from P's root towards y and the source's from
//! its patch root towards j. At each level the oracle judges the link (receiver element, source element)
//! against the threshold, with B the source element's current radiance; where it is admissible (or
//! neither element can be split further) the line's power is deposited at the receiver element; otherwise
//! the oracle's choice (the larger element) moves the receiver into its child containing y, splitting a
//! leaf on the way, or the source into its child containing j. Decisions are cached per (receiver,
//! source) pair within an iteration. Power deposited at any level becomes incident radiance
//! H = Φ / (π A) there, and push-pull carries it to the leaves and back up, so B is consistent on every
//! level.
//!
//! **Determinism.** Lines are traced in parallel batches of fixed size whose random numbers are seeded
//! from (seed, iteration, batch); the oracle's from (seed, iteration, receiver, source). Refinement runs
//! in rounds: the undecided pairs of all lines are judged in parallel, then lines advance and leaves are
//! split in line order, and power is summed in a fixed order. The result does not depend on the thread
//! count.

use super::push_pull::{push_pull, PatchUpdate};
use super::{emitted_power, link_rng, SolveReport};
use crate::color::Rgb;
use crate::geometry::{cosine_direction, DVec2, DVec3, Ray};
use crate::hierarchy::{ElementId, Hierarchy};
use crate::oracles::{Decision, OracleContext, RefinementOracle};
use crate::parallel::Uneven;
use crate::progress::Progress;
use crate::random::splitmix64;
use crate::visibility::Visibility;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;
use rayon::prelude::*;
use std::collections::{HashMap, HashSet};
use std::f64::consts::PI;
use std::time::Instant;

/// Parameters of a hierarchical Monte Carlo radiosity solve.
#[derive(Clone, Copy, Debug)]
pub struct StochasticSettings {
    /// Oracle threshold ε, in the oracle's units (radiance × area).
    pub threshold: f64,
    /// Elements of at most this area are never split.
    pub min_area: f64,
    /// Lines shot in the first iteration (the self-emitted power); later iterations get a share
    /// proportional to their unshot power.
    pub rays_per_iteration: u64,
    /// Most iterations.
    pub max_iterations: usize,
    /// Stop when the unshot power falls below this fraction of the emitted power.
    pub tolerance: f64,
    pub seed: u64,
}

/// Lines per parallel batch (fixed, so that the random streams do not depend on the thread count).
const BATCH: u64 = 4096;
/// Lines traced before their power is deposited: bounds the memory of one iteration.
const CHUNK: u64 = 1 << 20;
/// Random stream of the oracle's estimates (distinct from the deterministic refiner's streams).
const ORACLE_STREAM: u64 = 3;

/// A line that hit a radiating side.
#[derive(Clone, Copy, Debug)]
struct Shot {
    source: ElementId,
    patch: u32,
    point: DVec3,
    power: Rgb,
}

/// The leaves that shoot in one iteration, with the cumulative distribution of their scalar power.
struct Sources {
    leaves: Vec<ElementId>,
    /// Unshot power π A ΔB of each leaf.
    power: Vec<Rgb>,
    /// Running sum of the scalar power (sum of the channels).
    cumulative: Vec<f64>,
}

impl Sources {
    fn new(hierarchy: &Hierarchy, unshot: &[Rgb]) -> Self {
        let mut sources = Sources {
            leaves: Vec::new(),
            power: Vec::new(),
            cumulative: Vec::new(),
        };
        let mut total = 0.0;
        for id in hierarchy.leaves() {
            let power = unshot[id as usize] * (PI * hierarchy.element(id).area);
            let s = scalar(power);
            if s > 0.0 {
                total += s;
                sources.leaves.push(id);
                sources.power.push(power);
                sources.cumulative.push(total);
            }
        }
        sources
    }

    fn total(&self) -> f64 {
        self.cumulative.last().copied().unwrap_or(0.0)
    }

    /// The leaf at cumulative power `u` in `[0, total)`.
    fn pick(&self, u: f64) -> usize {
        self.cumulative
            .partition_point(|&c| c <= u)
            .min(self.leaves.len() - 1)
    }
}

/// Scalar power used for sampling: the sum of the channels, so every channel is estimated unbiasedly.
fn scalar(c: Rgb) -> f64 {
    c.r + c.g + c.b
}

/// Random numbers of one batch of lines.
fn batch_rng(seed: u64, iteration: usize, batch: u64) -> Pcg64Mcg {
    Pcg64Mcg::seed_from_u64(splitmix64(
        seed ^ splitmix64(iteration as u64 ^ splitmix64(batch)),
    ))
}

/// Traces lines `first..first + count` of the `n` lines of an iteration.
#[allow(clippy::too_many_arguments)]
fn shoot_batch(
    hierarchy: &Hierarchy,
    visibility: &dyn Visibility,
    sources: &Sources,
    first: u64,
    count: u64,
    n: u64,
    t_min: f64,
    rng: &mut Pcg64Mcg,
) -> Vec<Shot> {
    let total = sources.total();
    let mut shots = Vec::with_capacity(count as usize);
    for i in first..first + count {
        // Stratified choice of the source over the cumulative power.
        let k = sources.pick((i as f64 + rng.random::<f64>()) / n as f64 * total);
        let source = sources.leaves[k];
        let power = sources.power[k] * (total / (n as f64 * scalar(sources.power[k])));
        let element = hierarchy.element(source);
        let origin = element
            .shape()
            .sample_uniform(DVec2::new(rng.random(), rng.random()));
        let normal = hierarchy.patch_of(source).normal;
        let direction = cosine_direction(normal, DVec2::new(rng.random(), rng.random()));
        let ray = Ray::new(origin, direction);
        let Some(hit) = visibility.intersect(&ray, t_min, f64::INFINITY) else {
            continue;
        };
        // The back of a one-sided polygon is black: the power is lost there, as it is to the sky.
        if let Some(patch) = hierarchy.patch_for_side(hit.polygon, hit.front) {
            shots.push(Shot {
                source,
                patch,
                point: ray.at(hit.t),
                power,
            });
        }
    }
    shots
}

/// The ancestor of the leaf containing `point` one level below `parent` (which must have children).
fn child_towards(hierarchy: &Hierarchy, patch: u32, parent: ElementId, point: DVec3) -> ElementId {
    ancestor_below(hierarchy, parent, hierarchy.locate(patch, point))
}

/// The ancestor of `descendant` one level below `ancestor` (a proper ancestor of `descendant`).
fn ancestor_below(hierarchy: &Hierarchy, ancestor: ElementId, descendant: ElementId) -> ElementId {
    let level = hierarchy.element(ancestor).level + 1;
    let mut id = descendant;
    while hierarchy.element(id).level > level {
        match hierarchy.element(id).parent() {
            Some(p) => id = p,
            None => break,
        }
    }
    id
}

/// What one chunk of lines added.
#[derive(Default)]
struct Deposit {
    oracle_rays: u64,
    refine_seconds: f64,
}

/// A line on its way down both trees: the receiver element containing its end point and the source
/// element containing its origin (an ancestor of, or equal to, the leaf it was shot from).
#[derive(Clone, Copy)]
struct Descent {
    shot: usize,
    receiver: ElementId,
    source: ElementId,
}

/// Descends the receivers' and sources' trees for every shot (per-ray refinement) and adds each shot's
/// power to the receiver element it settles at. `cache` holds this iteration's oracle verdicts per
/// (receiver, source) pair.
///
/// Both ends are descended, as in the deterministic refiner: the link is judged between the receiver and
/// the source element at the current level (starting from the source's patch root), and the oracle's
/// choice of which to split moves the receiver towards the end point or the source towards the line's
/// leaf. Judging every receiver against the tiny leaf a line came from would admit each link at a coarse
/// receiver: the many small errors of the leaves of one large source then add up coherently, smearing
/// incident power across shadow boundaries and under objects resting on the receiver (the Cornell box's
/// floor in front of and under its blocks), which biased the blocks' dark faces by 20-40%.
#[allow(clippy::too_many_arguments)]
fn deposit(
    hierarchy: &mut Hierarchy,
    visibility: &dyn Visibility,
    oracle: &dyn RefinementOracle,
    settings: &StochasticSettings,
    oracle_seed: u64,
    shots: &[Shot],
    cache: &mut HashMap<(ElementId, ElementId), Decision>,
    received: &mut Vec<Rgb>,
) -> Deposit {
    let start = Instant::now();
    let mut out = Deposit::default();
    let mut active: Vec<Descent> = shots
        .iter()
        .enumerate()
        .map(|(k, s)| Descent {
            shot: k,
            receiver: hierarchy.patches[s.patch as usize].root,
            source: hierarchy.patch_of(s.source).root,
        })
        .collect();
    let receiver_splittable = |h: &Hierarchy, id: ElementId| {
        let e = h.element(id);
        !e.is_leaf() || e.area > settings.min_area
    };
    while !active.is_empty() {
        // The pairs this round needs that were never judged, in order of first appearance.
        let mut pending = Vec::new();
        let mut seen = HashSet::new();
        for d in &active {
            let key = (d.receiver, d.source);
            let movable =
                receiver_splittable(hierarchy, d.receiver) || d.source != shots[d.shot].source;
            if movable && !cache.contains_key(&key) && seen.insert(key) {
                pending.push(key);
            }
        }
        let verdicts: Vec<_> = {
            let context = OracleContext {
                hierarchy,
                visibility,
            };
            pending
                .par_iter()
                .uneven()
                .map(|&(r, s)| {
                    let mut rng = link_rng(oracle_seed, r, s, ORACLE_STREAM);
                    let estimate = oracle.estimate(&context, r, s, &mut rng);
                    let decision = if estimate.error <= settings.threshold {
                        Decision::Admissible
                    } else {
                        oracle.element_to_split(&context, r, s)
                    };
                    (estimate.rays, decision)
                })
                .collect()
        };
        for (key, (rays, decision)) in pending.iter().zip(verdicts) {
            out.oracle_rays += rays;
            cache.insert(*key, decision);
        }
        let mut next = Vec::with_capacity(active.len());
        for mut d in active {
            let shot = &shots[d.shot];
            let can_split_receiver = receiver_splittable(hierarchy, d.receiver);
            let can_descend_source = d.source != shot.source;
            // The minimum-area rule of the deterministic refiner: split the other element when the
            // chosen one cannot be, and keep the link when neither can.
            let decision = if !can_split_receiver && !can_descend_source {
                Decision::Admissible
            } else {
                match cache[&(d.receiver, d.source)] {
                    Decision::SubdivideReceiver if !can_split_receiver => Decision::SubdivideSource,
                    Decision::SubdivideSource if !can_descend_source => Decision::SubdivideReceiver,
                    other => other,
                }
            };
            match decision {
                Decision::Admissible => received[d.receiver as usize] += shot.power,
                Decision::SubdivideReceiver => {
                    hierarchy.subdivide(d.receiver);
                    received.resize(hierarchy.elements.len(), Rgb::BLACK);
                    d.receiver = child_towards(hierarchy, shot.patch, d.receiver, shot.point);
                    next.push(d);
                }
                Decision::SubdivideSource => {
                    d.source = ancestor_below(hierarchy, d.source, shot.source);
                    next.push(d);
                }
            }
        }
        active = next;
    }
    out.refine_seconds = start.elapsed().as_secs_f64();
    out
}

/// Hierarchical Monte Carlo radiosity on `hierarchy` (whose radiance is reset to the emission): stochastic
/// Jacobi iterations with per-ray refinement by `oracle`. Stores no links; the result is the radiance of
/// every element.
pub fn solve_stochastic(
    hierarchy: &mut Hierarchy,
    visibility: &dyn Visibility,
    oracle: &dyn RefinementOracle,
    settings: &StochasticSettings,
    progress: &Progress,
) -> SolveReport {
    let mut report = SolveReport {
        passes: 1,
        emitted_power: emitted_power(hierarchy),
        ..Default::default()
    };
    let emission: Vec<Rgb> = hierarchy.patches.iter().map(|p| p.emission).collect();
    for id in 0..hierarchy.elements.len() as ElementId {
        let patch = hierarchy.element(id).patch();
        hierarchy.radiance_mut(id)[0] = emission[patch as usize];
    }
    // Goniometric luminaires: their first gather (`hierarchy.direct`, from solvers::direct) reflected,
    // ρ H_direct, joins the self-emitted radiance as unshot light of the first iteration; it is then
    // dropped so that later push-pulls do not add it again.
    if !hierarchy.direct.is_empty() {
        let h = &*hierarchy;
        let updates: Vec<PatchUpdate> = (0..h.patches.len() as u32)
            .into_par_iter()
            .uneven()
            .map(|p| push_pull(h, p, &|_, _| {}))
            .collect();
        for update in &updates {
            report.absorbed_power += update.absorbed;
            for (id, b) in update.entries() {
                hierarchy.radiance_mut(id)[0] = b[0];
            }
        }
        hierarchy.direct.clear();
    }
    let mut unshot: Vec<Rgb> = (0..hierarchy.elements.len() as ElementId)
        .map(|id| hierarchy.average_radiance(id))
        .collect();
    let t_min = 1e-9 * scene_diameter(hierarchy);
    let emitted = scalar(report.emitted_power);
    let bar = progress.bar(settings.max_iterations as u64, "shoot");
    for iteration in 1..=settings.max_iterations {
        let sources = Sources::new(hierarchy, &unshot);
        let shooting = sources.total();
        if shooting <= 0.0 || shooting <= settings.tolerance * emitted {
            report.converged = true;
            break;
        }
        report.iterations = iteration;
        let n =
            ((settings.rays_per_iteration.max(1) as f64 * shooting / emitted).ceil() as u64).max(1);
        bar.set_message(format!(
            "iteration {iteration}: {n} rays, unshot power {:.2e}",
            shooting / emitted
        ));
        let oracle_seed = splitmix64(settings.seed ^ splitmix64(iteration as u64));
        let mut cache = HashMap::new();
        let mut received = vec![Rgb::BLACK; hierarchy.elements.len()];
        let mut first = 0;
        while first < n {
            let count = CHUNK.min(n - first);
            let start = Instant::now();
            let shots: Vec<Shot> = {
                let h = &*hierarchy;
                let batches = count.div_ceil(BATCH);
                let per_batch: Vec<Vec<Shot>> = (0..batches)
                    .into_par_iter()
                    .map(|b| {
                        let lo = first + b * BATCH;
                        let hi = (lo + BATCH).min(first + count);
                        let mut rng = batch_rng(settings.seed, iteration, lo / BATCH);
                        shoot_batch(h, visibility, &sources, lo, hi - lo, n, t_min, &mut rng)
                    })
                    .collect();
                per_batch.into_iter().flatten().collect()
            };
            report.solve_seconds += start.elapsed().as_secs_f64();
            let d = deposit(
                hierarchy,
                visibility,
                oracle,
                settings,
                oracle_seed,
                &shots,
                &mut cache,
                &mut received,
            );
            report.oracle_rays += d.oracle_rays;
            report.refine_seconds += d.refine_seconds;
            first += count;
        }
        report.shooting_rays += n;

        let start = Instant::now();
        let h = &*hierarchy;
        let incident: Vec<Rgb> = received
            .iter()
            .zip(&h.elements)
            .map(|(p, e)| *p / (PI * e.area))
            .collect();
        let updates: Vec<PatchUpdate> = (0..h.patches.len() as u32)
            .into_par_iter()
            .uneven()
            .map(|p| push_pull(h, p, &|id, out| out[0] += incident[id as usize]))
            .collect();
        unshot.resize(hierarchy.elements.len(), Rgb::BLACK);
        for update in &updates {
            report.absorbed_power += update.absorbed;
            for (id, b) in update.entries() {
                let b = b[0];
                // push-pull returns E + ρ H; this iteration's share is ρ H.
                let delta = b - emission[hierarchy.element(id).patch() as usize];
                unshot[id as usize] = delta;
                hierarchy.radiance_mut(id)[0] += delta;
            }
        }
        report.solve_seconds += start.elapsed().as_secs_f64();
        bar.inc(1);
    }
    bar.finish_and_clear();
    report.exitant_power = hierarchy
        .leaves()
        .iter()
        .map(|&id| hierarchy.average_radiance(id) * (PI * hierarchy.element(id).area))
        .sum();
    report
}

/// Diagonal of the bounding box of all patches: the scale of the self-intersection margin.
fn scene_diameter(hierarchy: &Hierarchy) -> f64 {
    hierarchy.patch_bounds().diagonal()
}
