//! Hierarchical refinement (Hanrahan et al. 1991) as deterministic parallel rounds: every pending
//! candidate link is judged by the oracle in parallel; the elements to split are split sequentially in
//! candidate order; split candidates are replaced by links to the children and judged in the next round.
//! Admissible links get their couplings in parallel at the end, except under the link error oracle
//! (Bekaert–Willems §5), which judges a link from its coupling and so computes it first. The element and
//! link sets therefore do not depend on the number of threads. A later pass judges the links where they
//! are stored ([`Start::StoredLinks`]): only the links that refine leave their lists.

use super::clustering::{
    cluster_can_interact, transport_bound, SourceSphere, NEAR_RECEIVER_PATCHES, NEAR_SOURCE_PATCHES,
};
use super::coupling::{
    couple_with_prior, shaft_test, visibility_error, visibility_spread, CouplingSettings,
};
use super::link_rng;
use crate::geometry::{DVec3, Ray, Shape};
use crate::hierarchy::clusters::ClusteringKind;
use crate::hierarchy::{ElementId, Hierarchy, Link, LinkCoupling, OracleFactor};
use crate::oracles::{reflected_source_radiance, Decision, OracleContext, RefinementOracle};
use crate::parallel::Uneven;
use crate::random::splitmix64;
use crate::visibility::shaft::{ShaftPrior, ShaftTest, ShaftVerdict, MAX_PARTIAL_OCCLUDERS};
use crate::visibility::Visibility;
use rayon::prelude::*;

/// A link under consideration; `coupling` and `oracle_factor` are cached for links that were already
/// computed and judged.
#[derive(Clone, Debug, PartialEq)]
pub struct Candidate {
    pub receiver: ElementId,
    pub source: ElementId,
    /// The coupling computed while judging it (link error oracle; boxed: most candidates have none,
    /// and a pass holds many candidates).
    pub coupling: Option<Box<LinkCoupling>>,
    pub oracle_factor: OracleFactor,
    /// Visibility `v` of the parent link when that link was partially occluded (NaN: none; see
    /// [`Candidate::inherited_visibility`]).
    inherited_visibility: f32,
    /// The shaft verdict on this link: its own test's, or a Clear or Blocked one inherited from the
    /// link it was refined from (whose shaft holds this one's).
    pub shaft: Option<ShaftVerdict>,
    /// Where the verdict is not known: the complete occluder list of a Partial test of an ancestor
    /// link's shaft (`u32::MAX`: none; see [`Candidate::occluders`]).
    occluders: u32,
}

// A pass holds its candidates together: 32 bytes each (`Option`s of their own would make it 40).
#[cfg(target_pointer_width = "64")]
const _: () = assert!(std::mem::size_of::<Candidate>() == 32);

impl Candidate {
    fn new(
        receiver: ElementId,
        source: ElementId,
        inherited_visibility: Option<f32>,
        shaft: Option<ShaftVerdict>,
        occluders: Option<u32>,
    ) -> Self {
        Candidate {
            receiver,
            source,
            coupling: None,
            oracle_factor: OracleFactor::NONE,
            inherited_visibility: inherited_visibility.unwrap_or(f32::NAN),
            shaft,
            occluders: occluders.map_or(u32::MAX, |k| {
                assert!(k < u32::MAX, "shaft tests are indexed below u32::MAX");
                k
            }),
        }
    }

    /// Visibility `v` of the parent link when that link was partially occluded: a link between
    /// sub-elements whose own node pairs all agree (all open or all blocked) may have sampled a
    /// partial occlusion too coarsely, so it keeps the parent's visibility error (one generation).
    pub fn inherited_visibility(&self) -> Option<f32> {
        (!self.inherited_visibility.is_nan()).then_some(self.inherited_visibility)
    }

    /// Where the shaft verdict is not known: the complete occluder list of a Partial test of an
    /// ancestor link's shaft, as an index into the table of such tests that one [`refine`] call
    /// keeps, so that this link's own test examines only those polygons ([`ShaftPrior::Among`]).
    pub fn occluders(&self) -> Option<u32> {
        (self.occluders != u32::MAX).then_some(self.occluders)
    }

    /// This candidate as the oracle judges it.
    fn judging(&self) -> Judging<'_> {
        Judging {
            receiver: self.receiver,
            source: self.source,
            coupling: self.coupling.as_deref(),
            oracle_factor: self.oracle_factor,
            inherited_visibility: self.inherited_visibility(),
            shaft: self.shaft,
            occluders: self.occluders(),
        }
    }

    /// Takes what the verdict on this candidate kept ([`Admitted`]).
    fn admit(&mut self, admitted: Admitted) {
        self.oracle_factor = admitted.oracle_factor;
        if let Some(coupling) = admitted.coupling {
            self.coupling = Some(coupling);
        }
        self.shaft = admitted.shaft;
    }
}

/// A link as the oracle judges it: a [`Candidate`], or a link stored at `receiver` (a later pass,
/// [`Start::StoredLinks`]), borrowed either way.
#[derive(Clone, Copy)]
struct Judging<'c> {
    receiver: ElementId,
    source: ElementId,
    coupling: Option<&'c LinkCoupling>,
    oracle_factor: OracleFactor,
    inherited_visibility: Option<f32>,
    shaft: Option<ShaftVerdict>,
    occluders: Option<u32>,
}

impl<'c> Judging<'c> {
    /// The link `link` stored at `receiver`: its coupling is known, its shaft verdict its own.
    fn stored(receiver: ElementId, link: &'c Link) -> Self {
        Judging {
            receiver,
            source: link.source,
            coupling: Some(&link.coupling),
            oracle_factor: link.oracle_factor,
            inherited_visibility: None,
            shaft: link.coupling.shaft,
            occluders: None,
        }
    }

    /// What this link knows of its shaft before a test of its own; `tests` is the table its
    /// `occluders` index.
    fn shaft_prior<'a>(&self, tests: &'a [ShaftTest]) -> ShaftPrior<'a> {
        match (self.shaft, self.occluders) {
            (Some(verdict), _) => ShaftPrior::Verdict(verdict),
            (None, Some(k)) => tests[k as usize]
                .occluders()
                .map_or(ShaftPrior::Unknown, ShaftPrior::Among),
            (None, None) => ShaftPrior::Unknown,
        }
    }
}

/// Refinement parameters.
#[derive(Clone, Copy, Debug)]
pub struct RefineSettings {
    /// Oracle threshold ε, in the oracle's units (radiance × area). The link error oracle uses each
    /// receiver's own threshold `Element::threshold` instead (Bekaert–Willems algorithm 6.1).
    pub threshold: f64,
    /// Error control with an oracle that does not judge couplings: each link is compared with its
    /// receiver's own threshold (`Element::threshold`, in the oracle's units: it starts at
    /// `threshold` and algorithm 6.1 lowers it where the a-posteriori estimate fails) instead of
    /// `threshold` ([`RefineSettings::threshold_into`]).
    pub receiver_thresholds: bool,
    /// Elements of at most this area are never split.
    pub min_area: f64,
    /// Elements are not split beyond this count (the element budget); links stay where they are.
    pub max_elements: usize,
    /// Links are not refined beyond this count (the link budget, from `--max-memory`).
    pub max_links: usize,
    pub coupling: CouplingSettings,
    /// Whether receivers that straddle the outline of something lying over them count as crossed by
    /// a shadow boundary.
    pub outlines: OutlineRule,
    /// `4^N` for `--outline-levels N`: how much more a receiver under an outline weighs than one a
    /// shadow boundary crosses ([`OutlineRule::Split`]), and how far below `min_area` it may be split.
    pub outline_gain: f64,
    pub seed: u64,
}

impl RefineSettings {
    /// The threshold a link into `receiver` is compared with when its oracle does not judge
    /// couplings: the receiver's own under error control ([`RefineSettings::receiver_thresholds`]),
    /// else the uniform ε of eq. (1).
    pub fn threshold_into(&self, h: &Hierarchy, receiver: ElementId) -> f64 {
        if self.receiver_thresholds {
            h.element(receiver).threshold
        } else {
            self.threshold
        }
    }
}

/// Whether a receiver that something lies over in part counts as crossed by a shadow boundary
/// (`--outlines`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum OutlineRule {
    /// The oracle and its links' rays alone decide (the papers' refinement).
    #[default]
    Ignore,
    /// A receiver that straddles the outline of something lying over it (`straddles_outline`) counts
    /// in the power oracle's visibility term (`--shadow-levels`) as crossed by a hard shadow
    /// boundary, spread ½, and is refined as deep as such a link.
    Split,
}

/// What the outline probe of [`straddles_outline`] reaches, relative to the element's diameter.
const OUTLINE_REACH: f64 = 0.5;

/// How far the probe's corner points are moved toward the centroid, relative to the way there: off
/// the edges an element shares with its neighbours (and with walls meeting it).
const PROBE_INSET: f64 = 0.02;

/// Whether something lies over part of element `id` but not over all of it, nearer than half its
/// diameter ([`OUTLINE_REACH`]): rays along its normal from its centroid and from its corners (moved
/// [`PROBE_INSET`] toward the centroid) meet a surface within that reach from some of these points and
/// not from the others.
///
/// Why: across the outline of a lid at height `d` over a surface (a lamp housing 2 cm under a ceiling,
/// a shelf, a picture off a wall) the light changes within about `d`, the width of the edge's
/// penumbra, while the oracles judge a link by what it carries, and eq. (1) lets dim ones stay coarse.
/// An element wider than about `2d` across the outline then spreads the light of the open side into
/// the gap (where the lid's underside and the surface reflect it back and forth) and the gap's
/// darkness over the open side. Such a receiver is one that a shadow boundary crosses, whatever its
/// link's rays saw (the lid need not lie between it and the source: it holds the light that enters
/// the gap to a band along the outline): [`OutlineRule::Split`] refines it as the visibility term of
/// Sillion–Drettakis Appendix A eq. (5) refines those, which resolves the outline as
/// `--split-contacts` cutting would, without new polygons, as deep as `--shadow-levels` takes those
/// (and no finer than about twice the gap, where the probe stops straddling). The
/// classroom's ceiling over its housings read up to +93% against the path tracer without it
/// (BENCHMARKS.md, "Outlines"). A surface lying at a distance of more than half the element is left to
/// the oracle: its shadow edge is wider than half the element, which the basis follows.
pub fn straddles_outline(h: &Hierarchy, visibility: &dyn Visibility, id: ElementId) -> bool {
    let shape = h.element(id).shape();
    let normal = h.patch_of(id).normal;
    let size = shape.diameter();
    let centre = shape.centroid();
    let (near, far) = (1e-9 * size, OUTLINE_REACH * size);
    let covered = |p: DVec3| visibility.occluded(&Ray::new(p, normal), near, far);
    let first = covered(centre);
    inset_corners(shape).any(|p| covered(p) != first)
}

/// The corners of `shape`, each moved [`PROBE_INSET`] of the way toward its centroid.
fn inset_corners(shape: &Shape) -> impl Iterator<Item = DVec3> + '_ {
    let centre = shape.centroid();
    shape
        .vertices()
        .iter()
        .map(move |&v| v + (centre - v) * PROBE_INSET)
}

/// Whether a corner of the receiver ([`inset_corners`]) sees the source's centroid otherwise than
/// the link's cubature nodes saw the source: `lit` when their rays found it wholly visible, not when
/// wholly hidden. Why: a shadow edge that crosses the receiver between its outermost nodes and its
/// side (the lit sliver beside a slab standing on a floor: a three-point Gauss rule leaves the outer
/// 11% of the element unsampled) gives every node the same verdict, so the visibility term of
/// Sillion–Drettakis Appendix A eq. (5) reads 0 and the element stays whole and wrongly dark or lit.
/// One ray per corner finds such an edge where it runs past a corner's side of the nodes.
fn corners_disagree(
    h: &Hierarchy,
    visibility: &dyn Visibility,
    receiver: ElementId,
    source: ElementId,
    lit: bool,
) -> bool {
    let target = h.element(source).shape().centroid();
    let polygon = h.patch_of(receiver).polygon;
    inset_corners(h.element(receiver).shape())
        .any(|p| (visibility.transmittance_onto(p, target, polygon) >= 0.5) != lit)
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
    /// Rays cast for link couplings.
    pub form_factor_rays: u64,
    /// Splits refused because the element budget was reached.
    pub refused_by_budget: usize,
    /// Shaft tests of surface links (`--visibility-reuse shaft`).
    pub shaft_tests: u64,
    /// Coupling rays that Clear or Blocked shafts made unnecessary.
    pub rays_saved: u64,
}

/// Whether two elements can exchange light at all: each has a vertex strictly in front of the other.
pub fn can_interact(receiver: &Shape, source: &Shape) -> bool {
    let (r, s) = (Facing::of(receiver), Facing::of(source));
    r.has_in_front(&s) && s.has_in_front(&r)
}

/// What [`can_interact`] needs of a shape, computed once per shape (the initial-link count tests every
/// pair of patches, a split each of its children against the other end).
struct Facing<'a> {
    shape: &'a Shape,
    normal: DVec3,
    origin: DVec3,
    /// Largest distance between two vertices in the L¹ norm: at least the diameter, without roots.
    l1_diameter: f64,
}

impl<'a> Facing<'a> {
    fn of(shape: &'a Shape) -> Self {
        let v = shape.vertices();
        let mut l1_diameter: f64 = 0.0;
        for i in 0..v.len() {
            for j in i + 1..v.len() {
                l1_diameter = l1_diameter.max((v[i] - v[j]).abs().element_sum());
            }
        }
        Facing {
            shape,
            normal: shape.normal(),
            origin: v[0],
            l1_diameter,
        }
    }

    /// Whether `other` has a vertex strictly in front of this shape's plane. The tolerance `1e-9 · max
    /// diameter` only matters for a vertex within it of the plane: the clear cases are decided with the
    /// L¹ bound.
    fn has_in_front(&self, other: &Facing) -> bool {
        let highest = other
            .shape
            .vertices()
            .iter()
            .map(|v| self.normal.dot(*v - self.origin))
            .fold(f64::NEG_INFINITY, f64::max);
        if highest <= 0.0 {
            return false;
        }
        if highest > 1e-9 * self.l1_diameter.max(other.l1_diameter) {
            return true;
        }
        highest > 1e-9 * self.shape.diameter().max(other.shape.diameter())
    }
}

/// The end of a surface link whose coupling nodes all lie behind the other end's plane although the
/// two face each other (every link passed [`Facing::has_in_front`] both ways: some vertex is in
/// front): the plane cuts that end near one of its edges, a horizon, and Algorithm 4.1's nodes see
/// none of the part in front. Such a coupling is zero and the link would be dropped with all the light
/// that reaches that part: floor_gloss.mgf's far floor, lit only by the back of a tilted two-sided
/// lamp, got none of it (BENCHMARKS.md, "Horizons"). Splitting that end until some node is in front
/// (or the minimum area, or until what the link could carry is below the threshold: `decide`) finds
/// the light. `None` when the nodes see each other, or no plane cuts the other end.
fn horizon_split(
    h: &Hierarchy,
    receiver: ElementId,
    source: ElementId,
    cubature_degree: usize,
) -> Option<Decision> {
    let plane = |id: ElementId| (h.patch_of(id).normal, h.element(id).shape().vertices()[0]);
    // Whether every node of `id`'s rule of `degree` lies behind the plane of `other`: only looked at
    // when that plane cuts `id` (a vertex behind it; most pairs have none, and cost four products).
    let blind = |id: ElementId, other: ElementId, degree: usize| {
        let (normal, origin) = plane(other);
        let shape = h.element(id).shape();
        let behind = |p: DVec3| normal.dot(p - origin) <= 0.0;
        shape.vertices().iter().any(|&v| behind(v))
            && crate::geometry::cubature::rule(shape.domain(), degree)
                .nodes
                .iter()
                .all(|&(uv, _)| behind(shape.point_at(uv)))
    };
    let receiver_blind = blind(receiver, source, cubature_degree);
    let source_blind = blind(
        source,
        receiver,
        crate::bases::source_cubature_degree(cubature_degree),
    );
    match (receiver_blind, source_blind) {
        (false, false) => None,
        (true, false) => Some(Decision::SubdivideReceiver),
        (false, true) => Some(Decision::SubdivideSource),
        (true, true) if h.element(receiver).area >= h.element(source).area => {
            Some(Decision::SubdivideReceiver)
        }
        (true, true) => Some(Decision::SubdivideSource),
    }
}

/// The first candidates: with clusters, one self-link on the root cluster (Sillion–Drettakis §4, Smits
/// et al. 1994), refined from there; without, root-to-root candidates for every ordered pair of patches
/// that can interact (Hanrahan's initial linking, quadratic in the number of patches). Receivers that
/// reflect nothing and sources that can never radiate are skipped.
pub fn initial_candidates(hierarchy: &Hierarchy) -> Vec<Candidate> {
    if let Some(root) = hierarchy.root_cluster {
        return vec![Candidate::new(root, root, None, None, None)];
    }
    let patches = &hierarchy.patches;
    let facings = patch_facings(hierarchy);
    let facings = &facings;
    (0..patches.len())
        .into_par_iter()
        .flat_map_iter(|i| {
            (0..patches.len())
                .filter(move |&j| initially_linked(hierarchy, facings, i, j))
                .map(move |j| Candidate::new(patches[i].root, patches[j].root, None, None, None))
        })
        .collect()
}

/// Whether patch `j` starts linked to receiver patch `i` without clusters (see [`initial_candidates`]).
fn initially_linked(hierarchy: &Hierarchy, facings: &[Facing], i: usize, j: usize) -> bool {
    let (receiver, source) = (&hierarchy.patches[i], &hierarchy.patches[j]);
    i != j
        && !receiver.reflectance.is_black()
        && (!source.emission.is_black() || !source.reflectance.is_black())
        && receiver.polygon != source.polygon
        && facings[i].has_in_front(&facings[j])
        && facings[j].has_in_front(&facings[i])
}

/// [`Facing`] of every patch.
fn patch_facings(hierarchy: &Hierarchy) -> Vec<Facing<'_>> {
    hierarchy
        .patches
        .iter()
        .map(|p| Facing::of(hierarchy.element(p.root).shape()))
        .collect()
}

/// The number of initial links without clusters ([`initial_candidates`]), counted without storing a
/// pair; the count stops soon after it passes `limit` (the result is then only known to exceed it).
pub fn initial_link_count(hierarchy: &Hierarchy, limit: usize) -> usize {
    use std::sync::atomic::{AtomicUsize, Ordering::Relaxed};
    let n = hierarchy.patches.len();
    let facings = patch_facings(hierarchy);
    let counted = AtomicUsize::new(0);
    (0..n).into_par_iter().for_each(|i| {
        if counted.load(Relaxed) <= limit {
            let row = (0..n)
                .filter(|&j| initially_linked(hierarchy, &facings, i, j))
                .count();
            counted.fetch_add(row, Relaxed);
        }
    });
    counted.into_inner()
}

/// Rows of the patch-pair matrix [`automatic_clustering`] samples before counting exactly.
const AUTO_CLUSTERING_SAMPLE_ROWS: usize = 256;

/// Oriented clusters when the unclustered initial links of `hierarchy` (before clusters are added)
/// would exceed `max_links`, none otherwise: `--clustering auto`, whose bound the pipeline chooses
/// (`pipeline::auto_clustering_links`).
pub fn automatic_clustering(hierarchy: &Hierarchy, max_links: usize) -> ClusteringKind {
    let n = hierarchy.patches.len();
    if n.saturating_mul(n) <= max_links {
        return ClusteringKind::None;
    }
    // A deterministic sample of whole rows decides clear cases: office3's 25k patches would otherwise
    // cost 6·10⁸ pair tests (40% of its first 150 s) before refinement starts. Only estimates within a
    // factor 2 of the budget are settled by the exact count. The rows are picked by a hash of their
    // index, not every stride-th: a two-sided polygon's patches are consecutive, and an even stride
    // sampled only one side of each (floor_gloss's 19k initial links were estimated as none).
    let stride = n.div_ceil(AUTO_CLUSTERING_SAMPLE_ROWS) as u64;
    let facings = patch_facings(hierarchy);
    let rows: Vec<usize> = (0..n)
        .filter(|&i| splitmix64(i as u64).is_multiple_of(stride))
        .collect();
    let sampled: usize = rows
        .par_iter()
        .map(|&i| {
            (0..n)
                .filter(|&j| initially_linked(hierarchy, &facings, i, j))
                .count()
        })
        .sum();
    if !rows.is_empty() {
        let estimate = sampled as u128 * n as u128 / rows.len() as u128;
        if estimate > 2 * max_links as u128 {
            return ClusteringKind::Oriented;
        }
        if estimate < max_links as u128 / 2 {
            return ClusteringKind::None;
        }
    }
    if initial_link_count(hierarchy, max_links) > max_links {
        ClusteringKind::Oriented
    } else {
        ClusteringKind::None
    }
}

/// Refuses a solve without clusters whose initial links alone exceed the link budget `max_links`
/// (from `--max-memory`): they are all built before any budget can stop refinement, so they are
/// counted first ([`initial_link_count`]).
pub fn check_initial_links(hierarchy: &Hierarchy, max_links: usize) -> anyhow::Result<()> {
    if hierarchy.root_cluster.is_some() {
        return Ok(());
    }
    let counted = initial_link_count(hierarchy, max_links);
    anyhow::ensure!(
        counted <= max_links,
        "without clustering every facing pair of the {} patches starts linked: at least {counted} \
         initial links, over the link budget of {max_links} that --max-memory allows; use \
         --clustering oriented (or auto, or isotropic), or a larger --max-memory",
        hierarchy.patches.len()
    );
    Ok(())
}

/// What a refinement pass starts from.
pub enum Start {
    /// The first pass: candidates not yet linked ([`initial_candidates`]).
    Initial(Vec<Candidate>),
    /// A later pass (after the radiance changed): every link stored in the hierarchy, judged where it
    /// is stored with its coupling and cached oracle factor, so that the links are never held a second
    /// time as candidates.
    StoredLinks,
}

const ORACLE_STREAM: u64 = 1;

/// A candidate link's receiver and source, each with its [`Facing`] when already known.
type Ends<'a, 'f> = (
    (ElementId, Option<&'f Facing<'a>>),
    (ElementId, Option<&'f Facing<'a>>),
);

/// Most candidates one refinement creates (a cluster self-link: every ordered pair of its children).
const MAX_NEW_CANDIDATES: usize =
    crate::hierarchy::clusters::MAX_CHILDREN * crate::hierarchy::clusters::MAX_CHILDREN;

/// One candidate's verdict in a round, as a [`RefinementSchedule`] sees it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Judged {
    /// The oracle's error estimate (∞ for a cluster self-link, which always splits).
    pub error: f64,
    /// Whether the oracle asks to refine it (its error is above its own threshold).
    pub refine: bool,
    /// Candidate links refining it creates ([`links_created`]): the work it costs.
    pub cost: usize,
}

/// The candidate links refining the link `(receiver, source)` as `decision` creates, known before the
/// split: the children of the end that splits (a surface leaf gets four), or for a cluster's self-link
/// every ordered pair of its children plus the self-links of those that are clusters. Counted before the interaction test drops
/// pairs that cannot exchange light, so an upper bound on the links it adds.
pub fn links_created(
    h: &Hierarchy,
    receiver: ElementId,
    source: ElementId,
    decision: Decision,
) -> usize {
    let children = |id: ElementId| match h.element(id).children.len() {
        0 if !h.is_cluster(id) => 4,
        n => n,
    };
    match decision {
        Decision::Admissible => 0,
        Decision::SubdivideReceiver if receiver == source => {
            let parts = &h.element(receiver).children;
            let clusters = parts.iter().filter(|&&p| h.is_cluster(p)).count();
            parts.len() * parts.len().saturating_sub(1) + clusters
        }
        Decision::SubdivideReceiver => children(receiver),
        Decision::SubdivideSource => children(source),
    }
}

/// What a refinement call refines, beyond the oracle's verdicts: progressive multi-gridding
/// (`solvers::multigrid`, Sillion–Drettakis §6.2) raises the threshold per step and refines one level.
pub trait RefinementSchedule {
    /// Sees the verdicts of round `round` (1 = the links refinement starts from) in candidate order and
    /// clears `refine` on those to keep admissible.
    fn select(&mut self, round: usize, judged: &mut [Judged]);
}

/// Refines from `start` until every link is admissible, then stores the new links at their receivers.
pub fn refine(
    hierarchy: &mut Hierarchy,
    visibility: &dyn Visibility,
    oracle: &dyn RefinementOracle,
    settings: &RefineSettings,
    start: Start,
    on_round: &mut dyn FnMut(usize, usize),
) -> RefineOutcome {
    refine_scheduled(
        hierarchy, visibility, oracle, settings, start, on_round, None,
    )
}

/// [`refine`], with the oracle's verdicts of each round passed through `schedule`.
pub fn refine_scheduled(
    hierarchy: &mut Hierarchy,
    visibility: &dyn Visibility,
    oracle: &dyn RefinementOracle,
    settings: &RefineSettings,
    start: Start,
    on_round: &mut dyn FnMut(usize, usize),
    mut schedule: Option<&mut dyn RefinementSchedule>,
) -> RefineOutcome {
    let mut pass = Pass::default();
    // Each round's admissible candidates, in order (one list per round: appending them to one list
    // would reallocate it, doubling, after a large round).
    let mut admissible: Vec<Vec<Candidate>> = Vec::new();
    let mut round = 0;
    let mut candidates = match start {
        Start::Initial(candidates) => candidates,
        Start::StoredLinks => {
            round = 1;
            on_round(round, hierarchy.link_count());
            refine_stored_links(
                hierarchy,
                visibility,
                oracle,
                settings,
                &mut pass,
                schedule.as_deref_mut(),
            );
            std::mem::take(&mut pass.next)
        }
    };
    while !candidates.is_empty() {
        round += 1;
        on_round(round, candidates.len());
        let mut verdicts: Vec<Verdict> = {
            let context = OracleContext {
                hierarchy,
                visibility,
            };
            let tests = &pass.partial_tests;
            candidates
                .par_iter()
                .uneven()
                .map(|c| decide(&context, oracle, settings, c.judging(), tests))
                .collect()
        };
        if let Some(schedule) = schedule.as_deref_mut() {
            let judged = candidates.iter().map(Candidate::judging).zip(&verdicts);
            let selection = select(schedule, round, hierarchy, judged);
            keep_unselected_admissible(verdicts.iter_mut(), selection);
        }
        let judged = candidates.iter().map(Candidate::judging).zip(&verdicts);
        let leaves = leaves_split(hierarchy, judged);
        hierarchy.reserve_splits(leaves);
        pass.start_round(verdicts.len());
        let mut verdicts = verdicts.into_iter();
        // This round's admissible candidates stay in place, in order, and the list becomes the round's
        // admissible one.
        candidates.retain_mut(|c| {
            let verdict = verdicts.next().expect("one verdict per candidate");
            match pass.settle(hierarchy, settings, c.judging(), verdict) {
                Some(admitted) => {
                    c.admit(admitted);
                    true
                }
                None => false,
            }
        });
        admissible.push(candidates);
        candidates = std::mem::take(&mut pass.next);
    }
    // Each receiver's list grows once, by the links it is about to get, instead of doubling.
    let mut arriving = vec![0u32; hierarchy.elements.len()];
    for c in admissible.iter().flatten() {
        arriving[c.receiver as usize] += 1;
    }
    for (e, n) in hierarchy.elements.iter_mut().zip(arriving) {
        e.links.reserve_exact(n as usize);
    }
    // Coupled a chunk at a time, so that the links on their way to their receivers are never all held
    // twice (as candidates and as computed links); couplings do not read the link lists.
    let mut pending = admissible.into_iter().flatten();
    loop {
        let chunk: Vec<Candidate> = pending.by_ref().take(COUPLING_CHUNK).collect();
        if chunk.is_empty() {
            break;
        }
        couple_chunk(
            hierarchy,
            visibility,
            settings,
            &pass.partial_tests,
            chunk,
            &mut pass.outcome,
        );
    }
    pass.outcome
}

/// The first round of a later pass ([`Start::StoredLinks`]): every stored link judged where it is, in
/// element order, then settled in that order as a candidate list would be; admissible links stay in
/// their lists (with what judging them cached), refined ones leave them, and their replacements wait
/// in `pass.next`. Without a schedule the elements are judged and settled a run of about
/// [`STORED_CHUNK`] links at a time, so that the verdicts of every stored link are never held at once
/// (they were office3's largest block after the couplings: 37 MB); a schedule ranks the whole
/// round's verdicts, so it gets them together.
fn refine_stored_links(
    hierarchy: &mut Hierarchy,
    visibility: &dyn Visibility,
    oracle: &dyn RefinementOracle,
    settings: &RefineSettings,
    pass: &mut Pass,
    mut schedule: Option<&mut (dyn RefinementSchedule + '_)>,
) {
    pass.start_round(hierarchy.link_count());
    let chunk = if schedule.is_some() {
        usize::MAX
    } else {
        STORED_CHUNK
    };
    // Elements that splits add on the way have no links yet.
    let stored = hierarchy.elements.len();
    let mut start = 0;
    while start < stored {
        let mut end = start;
        let mut links = 0;
        while end < stored && links < chunk {
            links += hierarchy.elements[end].links.len();
            end += 1;
        }
        judge_and_settle_stored(
            hierarchy,
            visibility,
            oracle,
            settings,
            pass,
            schedule.as_deref_mut(),
            start..end,
        );
        start = end;
    }
}

/// Stored links judged and settled per run of elements ([`refine_stored_links`]).
const STORED_CHUNK: usize = 1 << 16;

/// [`refine_stored_links`] for the elements `range`.
fn judge_and_settle_stored(
    hierarchy: &mut Hierarchy,
    visibility: &dyn Visibility,
    oracle: &dyn RefinementOracle,
    settings: &RefineSettings,
    pass: &mut Pass,
    schedule: Option<&mut (dyn RefinementSchedule + '_)>,
    range: std::ops::Range<usize>,
) {
    // One list of verdicts per element, each of its exact size (a flattened parallel collect would
    // gather pieces of unknown length and copy them, holding the verdicts more than twice).
    let mut verdicts: Vec<Vec<Verdict>> = {
        let context = &OracleContext {
            hierarchy,
            visibility,
        };
        let tests = &pass.partial_tests;
        hierarchy.elements[range.clone()]
            .par_iter()
            .zip(range.clone())
            .uneven()
            .map(|(e, id)| {
                e.links
                    .iter()
                    .map(|link| {
                        let judging = Judging::stored(id as ElementId, link);
                        decide(context, oracle, settings, judging, tests)
                    })
                    .collect()
            })
            .collect()
    };
    if let Some(schedule) = schedule {
        let judged = stored_links(hierarchy, range.clone()).zip(verdicts.iter().flatten());
        let selection = select(schedule, 1, hierarchy, judged);
        keep_unselected_admissible(verdicts.iter_mut().flatten(), selection);
    }
    let judged = stored_links(hierarchy, range.clone()).zip(verdicts.iter().flatten());
    let leaves = leaves_split(hierarchy, judged);
    hierarchy.reserve_splits(leaves);
    for (id, element_verdicts) in range.zip(verdicts) {
        if element_verdicts.is_empty() {
            continue;
        }
        let mut element_verdicts = element_verdicts.into_iter();
        // Out of the hierarchy while its links are settled, as splits change the element list.
        let mut links = std::mem::take(&mut hierarchy.elements[id].links);
        links.retain_mut(|link| {
            let verdict = element_verdicts.next().expect("one verdict per link");
            match pass.settle(
                hierarchy,
                settings,
                Judging::stored(id as ElementId, link),
                verdict,
            ) {
                Some(admitted) => {
                    link.oracle_factor = admitted.oracle_factor;
                    if let Some(coupling) = admitted.coupling {
                        link.coupling = *coupling;
                    }
                    link.coupling.shaft = admitted.shaft;
                    true
                }
                None => false,
            }
        });
        hierarchy.elements[id].links = links;
    }
}

/// The links stored at the elements `range`, in element order, as the oracle judges them.
fn stored_links(h: &Hierarchy, range: std::ops::Range<usize>) -> impl Iterator<Item = Judging<'_>> {
    h.elements[range.clone()]
        .iter()
        .zip(range)
        .flat_map(|(e, id)| {
            e.links
                .iter()
                .map(move |link| Judging::stored(id as ElementId, link))
        })
}

/// Passes one round's verdicts on its links (`judged`, in order) through `schedule`; returns its
/// selection, for [`keep_unselected_admissible`].
fn select<'a>(
    schedule: &mut dyn RefinementSchedule,
    round: usize,
    hierarchy: &Hierarchy,
    judged: impl Iterator<Item = (Judging<'a>, &'a Verdict)>,
) -> Vec<Judged> {
    let mut selection: Vec<Judged> = judged
        .map(|(c, v)| Judged {
            error: f64::from(v.error),
            refine: v.decision != Decision::Admissible,
            cost: links_created(hierarchy, c.receiver, c.source, v.decision),
        })
        .collect();
    schedule.select(round, &mut selection);
    selection
}

/// Makes admissible the verdicts that a schedule's `selection` keeps from refining.
fn keep_unselected_admissible<'v>(
    verdicts: impl Iterator<Item = &'v mut Verdict>,
    selection: Vec<Judged>,
) {
    for (verdict, j) in verdicts.zip(selection) {
        if !j.refine {
            verdict.decision = Decision::Admissible;
        }
    }
}

/// The surface leaves that the verdicts on a round's links (`judged`, in order) split, each counted
/// once: the room the round reserves in the element list ([`Hierarchy::reserve_splits`]).
fn leaves_split<'a>(
    h: &Hierarchy,
    judged: impl Iterator<Item = (Judging<'a>, &'a Verdict)>,
) -> usize {
    let mut leaves: Vec<ElementId> = judged
        .filter_map(|(c, v)| match v.decision {
            Decision::Admissible => None,
            Decision::SubdivideReceiver => Some(c.receiver),
            Decision::SubdivideSource => Some(c.source),
        })
        .filter(|&id| !h.is_cluster(id) && h.element(id).is_leaf())
        .collect();
    leaves.sort_unstable();
    leaves.dedup();
    leaves.len()
}

/// What an admissible link keeps of its verdict.
struct Admitted {
    oracle_factor: OracleFactor,
    /// The coupling computed to judge it, if it had none.
    coupling: Option<Box<LinkCoupling>>,
    shaft: Option<ShaftVerdict>,
}

/// The state of one refinement pass between its rounds.
#[derive(Default)]
struct Pass {
    outcome: RefineOutcome,
    /// Partial shaft tests of refined links whose occluder lists their descendants' tests examine.
    partial_tests: Vec<ShaftTest>,
    /// The next round's candidates.
    next: Vec<Candidate>,
    /// Links admitted so far (in every round).
    kept: usize,
    /// Links of this round settled so far, of `round_size`.
    settled: usize,
    round_size: usize,
}

impl Pass {
    fn start_round(&mut self, round_size: usize) {
        self.round_size = round_size;
        self.settled = 0;
    }

    /// Applies `verdict` on link `c`, in candidate order: splits what it refines (within the element
    /// and link budgets) and pushes the links replacing it to `next`. Returns what an admissible link
    /// keeps; `None` when the link leaves (refined, or its ends cannot exchange light).
    fn settle(
        &mut self,
        hierarchy: &mut Hierarchy,
        settings: &RefineSettings,
        c: Judging,
        verdict: Verdict,
    ) -> Option<Admitted> {
        let outcome = &mut self.outcome;
        self.settled += 1;
        outcome.oracle_rays += u64::from(verdict.rays);
        outcome.form_factor_rays += u64::from(verdict.coupling_rays);
        outcome.shaft_tests += u64::from(verdict.shaft_tested);
        outcome.rays_saved += u64::from(verdict.rays_saved);
        let mut decision = verdict.decision;
        let splits_surface = match decision {
            Decision::Admissible => false,
            Decision::SubdivideReceiver => !hierarchy.is_cluster(c.receiver),
            Decision::SubdivideSource => !hierarchy.is_cluster(c.source),
        };
        // Every link of this round not settled yet becomes at least one link too.
        let links =
            self.kept + self.next.len() + (self.round_size - self.settled) + MAX_NEW_CANDIDATES;
        if decision != Decision::Admissible
            && ((splits_surface && hierarchy.elements.len() + 4 > settings.max_elements)
                || links > settings.max_links)
        {
            outcome.refused_by_budget += 1;
            decision = Decision::Admissible;
        }
        let partial = verdict
            .coupling
            .as_deref()
            .or(c.coupling)
            .map(|k| k.visibility)
            .filter(|v| *v > 0.0 && *v < 1.0);
        let shaft = verdict.shaft.or(c.shaft);
        let inherited = shaft.and_then(ShaftVerdict::inherited);
        // Children test only the polygons this link's Partial shaft holds (or an ancestor's).
        let occluders = match verdict.partial_test {
            _ if inherited.is_some() || decision == Decision::Admissible => c.occluders,
            Some(test) => {
                self.partial_tests.push(*test);
                Some(self.partial_tests.len() as u32 - 1)
            }
            None => c.occluders,
        };
        let next = &mut self.next;
        match decision {
            Decision::Admissible if verdict.no_interaction => return None,
            Decision::Admissible => {
                self.kept += 1;
                return Some(Admitted {
                    oracle_factor: verdict.oracle_factor,
                    coupling: verdict.coupling,
                    shaft,
                });
            }
            Decision::SubdivideReceiver if c.receiver == c.source => {
                // A cluster's self-link: links among its contents, and their own self-links.
                outcome.refined_links += 1;
                let children = hierarchy.split(c.receiver);
                let h = &*hierarchy;
                let facings: Vec<_> = children.iter().map(|&a| facing_of(h, a)).collect();
                for (&a, fa) in children.iter().zip(&facings) {
                    for (&b, fb) in children.iter().zip(&facings) {
                        if a != b || h.is_cluster(a) {
                            let ends = ((a, fa.as_ref()), (b, fb.as_ref()));
                            push_if_interacting(h, next, ends, None, None, None);
                        }
                    }
                }
            }
            Decision::SubdivideReceiver => {
                outcome.refined_links += 1;
                if hierarchy.element(c.receiver).is_leaf() {
                    outcome.subdivisions += 1;
                }
                let children = hierarchy.split(c.receiver);
                let h = &*hierarchy;
                let source = facing_of(h, c.source);
                for child in children {
                    let ends = ((child, None), (c.source, source.as_ref()));
                    push_if_interacting(h, next, ends, partial, inherited, occluders);
                }
            }
            Decision::SubdivideSource => {
                outcome.refined_links += 1;
                if hierarchy.element(c.source).is_leaf() {
                    outcome.subdivisions += 1;
                }
                let children = hierarchy.split(c.source);
                let h = &*hierarchy;
                let receiver = facing_of(h, c.receiver);
                for child in children {
                    let ends = ((c.receiver, receiver.as_ref()), (child, None));
                    push_if_interacting(h, next, ends, partial, inherited, occluders);
                }
            }
        }
        None
    }
}

/// Admissible candidates coupled per chunk by [`refine_scheduled`]: enough for every thread, few enough
/// that a chunk's candidates and computed links held together stay small (32k of them put office3's
/// peak RSS 1 MB higher, at the same time).
const COUPLING_CHUNK: usize = 1 << 13;

/// Couples `chunk` in parallel (keeping the couplings that candidates carry) and stores the links at
/// their receivers in candidate order; costs go to `outcome`.
fn couple_chunk(
    hierarchy: &mut Hierarchy,
    visibility: &dyn Visibility,
    settings: &RefineSettings,
    partial_tests: &[ShaftTest],
    chunk: Vec<Candidate>,
    outcome: &mut RefineOutcome,
) {
    let h = &*hierarchy;
    let computed: Vec<(Option<(ElementId, Link)>, Coupled)> = chunk
        .into_par_iter()
        .uneven()
        .map(|c| match c.coupling {
            Some(coupling) => (
                Some((
                    c.receiver,
                    Link {
                        source: c.source,
                        coupling: coupling.with_shaft(c.shaft),
                        oracle_factor: c.oracle_factor,
                    },
                )),
                Coupled::default(),
            ),
            None => {
                let k = couple_with_prior(
                    h,
                    visibility,
                    c.receiver,
                    c.source,
                    &settings.coupling,
                    c.judging().shaft_prior(partial_tests),
                );
                let cost = Coupled {
                    rays: k.rays,
                    shaft_tests: u64::from(c.shaft.is_none() && k.shaft.is_some()),
                    rays_saved: k.rays_saved,
                };
                // A cluster link that carries nothing now is kept all the same: its centre-to-centre
                // cosines can be zero while parts of its ends face each other (`solvers::clustering`),
                // and only a kept link is judged again, and split, in the next pass. Dropping them
                // left whole faces of the Cornell box's tall block black (11.6% RMSE, oriented octree).
                let keep = k.unoccluded > 0.0 || h.is_cluster(c.receiver) || h.is_cluster(c.source);
                let link = keep.then_some(Link {
                    source: c.source,
                    coupling: k.coupling.with_shaft(k.shaft),
                    oracle_factor: c.oracle_factor,
                });
                (link.map(|l| (c.receiver, l)), cost)
            }
        })
        .collect();
    for (link, cost) in computed {
        outcome.form_factor_rays += cost.rays;
        outcome.shaft_tests += cost.shaft_tests;
        outcome.rays_saved += cost.rays_saved;
        if let Some((receiver, link)) = link {
            hierarchy.elements[receiver as usize].links.push(link);
        }
    }
}

/// What one coupling cost: rays cast, shaft tests run, rays saved by their verdicts.
#[derive(Clone, Copy, Debug, Default)]
struct Coupled {
    rays: u64,
    shaft_tests: u64,
    rays_saved: u64,
}

/// [`Facing`] of a surface element (`None` for a cluster), computed once where a split pairs it with
/// several children.
fn facing_of(h: &Hierarchy, id: ElementId) -> Option<Facing<'_>> {
    (!h.is_cluster(id)).then(|| Facing::of(h.element(id).shape()))
}

/// Pushes the candidate link `(receiver, source)` when the two can exchange light. Each end comes with
/// its [`Facing`] where the caller already has it (a surface's is computed here otherwise).
fn push_if_interacting(
    h: &Hierarchy,
    out: &mut Vec<Candidate>,
    ((receiver, receiver_facing), (source, source_facing)): Ends,
    inherited_visibility: Option<f32>,
    shaft: Option<ShaftVerdict>,
    occluders: Option<u32>,
) {
    let (reflectance, _) = h.optics_of(receiver);
    let (source_reflectance, source_emission) = h.optics_of(source);
    if reflectance.is_black() || (source_reflectance.is_black() && source_emission.is_black()) {
        return;
    }
    let interacting = if receiver == source {
        h.is_cluster(receiver)
    } else if h.is_cluster(receiver) || h.is_cluster(source) {
        cluster_can_interact(h, receiver, source)
    } else {
        let (own_r, own_s);
        let r = match receiver_facing {
            Some(f) => f,
            None => {
                own_r = Facing::of(h.element(receiver).shape());
                &own_r
            }
        };
        let s = match source_facing {
            Some(f) => f,
            None => {
                own_s = Facing::of(h.element(source).shape());
                &own_s
            }
        };
        r.has_in_front(s) && s.has_in_front(r)
    };
    if interacting {
        out.push(Candidate::new(
            receiver,
            source,
            inherited_visibility,
            shaft,
            occluders,
        ));
    }
}

/// An oracle verdict on one candidate (one per stored link while a pass judges them: its counters of
/// one link's rays and tests are 32-bit, [`ray_count`]).
struct Verdict {
    decision: Decision,
    /// Rays cast by the oracle's own samples.
    rays: u32,
    /// Radiance-independent factor of the estimate, to cache on the link.
    oracle_factor: OracleFactor,
    /// The coupling computed to judge the link (link error oracle), to keep on it (boxed: other
    /// oracles leave it empty, and a round holds a verdict per candidate).
    coupling: Option<Box<LinkCoupling>>,
    coupling_rays: u32,
    /// The elements cannot exchange light at all (drop the link).
    no_interaction: bool,
    /// The shaft verdict found while judging (a coupling's, or the test of a link to be refined, which
    /// its children inherit when Clear or Blocked).
    shaft: Option<ShaftVerdict>,
    /// The Partial test of a link to be refined, when its occluder list is complete (boxed: few
    /// verdicts carry one).
    partial_test: Option<Box<ShaftTest>>,
    /// Whether judging it ran a shaft test (one at most).
    shaft_tested: bool,
    rays_saved: u32,
    /// The error estimate compared with the threshold (for a [`RefinementSchedule`]'s histogram:
    /// single precision, as the verdicts of a pass are held together).
    error: f32,
}

// `memory::link_peak_bytes` counts a verdict as at most this.
const _: () = assert!(std::mem::size_of::<Verdict>() <= crate::memory::VERDICT_BYTES);

/// One link's count of rays in a [`Verdict`] (a link casts at most its node pairs' and the oracle's
/// samples' rays, far below `u32::MAX`; saturating all the same).
fn ray_count(rays: u64) -> u32 {
    u32::try_from(rays).unwrap_or(u32::MAX)
}

impl Verdict {
    fn admissible(oracle_factor: OracleFactor) -> Self {
        Verdict {
            decision: Decision::Admissible,
            rays: 0,
            oracle_factor,
            coupling: None,
            coupling_rays: 0,
            no_interaction: false,
            shaft: None,
            partial_test: None,
            shaft_tested: false,
            rays_saved: 0,
            error: 0.0,
        }
    }
}

/// The oracle's verdict, with the minimum-area rule: if the element it wants to split is too small the
/// other one is split instead (the link error oracle: the link is admissible), and if both are too small
/// the link is admissible. A cached oracle factor
/// or coupling is reused (see the contract of [`RefinementOracle::estimate`]).
fn decide(
    context: &OracleContext,
    oracle: &dyn RefinementOracle,
    settings: &RefineSettings,
    c: Judging,
    partial_tests: &[ShaftTest],
) -> Verdict {
    let h = context.hierarchy;
    if c.receiver == c.source {
        return Verdict {
            decision: Decision::SubdivideReceiver,
            error: f32::INFINITY,
            ..Verdict::admissible(OracleFactor::NONE)
        };
    }
    let splittable = |id: ElementId| h.is_cluster(id) || h.element(id).area > settings.min_area;
    if h.is_cluster(c.receiver) || h.is_cluster(c.source) {
        return decide_cluster_link(context, oracle, settings, c, &splittable);
    }
    if !splittable(c.receiver) && !splittable(c.source) {
        return Verdict::admissible(c.oracle_factor);
    }
    // Across a horizon the coupling sees nothing, so the link's error is all it could carry: bounded
    // as a cluster link's is (`transport_bound`), and split only where that exceeds the threshold.
    let could_carry = || {
        let carried = reflected_source_radiance(h, c.receiver, c.source)
            * transport_bound(h, c.receiver, c.source);
        if oracle.judges_couplings() {
            carried / h.element(c.receiver).area.max(1e-300) > h.element(c.receiver).threshold
        } else {
            carried > settings.threshold_into(h, c.receiver)
        }
    };
    let horizon = horizon_split(h, c.receiver, c.source, settings.coupling.cubature_degree)
        .filter(|&d| match d {
            Decision::SubdivideReceiver => splittable(c.receiver),
            Decision::SubdivideSource => splittable(c.source),
            Decision::Admissible => false,
        })
        .filter(|_| could_carry());
    if let Some(decision) = horizon {
        return Verdict {
            decision,
            error: f32::INFINITY,
            ..Verdict::admissible(OracleFactor::NONE)
        };
    }
    let mut verdict = Verdict::admissible(OracleFactor::NONE);
    // A receiver under an outline may be split below the minimum area (`--outline-levels`).
    let mut under_outline = false;
    let (error, threshold, split) = if oracle.judges_couplings() {
        if c.coupling.is_none() {
            let mut k = couple_for_verdict(context, settings, c, partial_tests, &mut verdict);
            if let Some(v) = c.inherited_visibility {
                if k.coupling.visibility == 0.0 || k.coupling.visibility == 1.0 {
                    k.coupling.set_visibility_error(visibility_error(
                        k.unoccluded,
                        f64::from(v),
                        k.source_nodes,
                    ));
                }
            }
            verdict.coupling = Some(Box::new(k.coupling));
        }
        let coupling = verdict.coupling.as_deref().or(c.coupling);
        let judgement = coupling
            .and_then(|k| oracle.link_error(context, c.receiver, c.source, k))
            .unwrap_or_default();
        (
            judgement.error,
            h.element(c.receiver).threshold,
            Some(judgement.split),
        )
    } else {
        let weight = reflected_source_radiance(h, c.receiver, c.source);
        let error = match c.oracle_factor.get() {
            Some(factor) => {
                verdict.oracle_factor = c.oracle_factor;
                weight * factor
            }
            None => {
                let mut rng = link_rng(settings.seed, c.receiver, c.source, ORACLE_STREAM);
                let estimate = oracle.estimate(context, c.receiver, c.source, &mut rng);
                verdict.rays = ray_count(estimate.rays);
                verdict.oracle_factor = (weight > 0.0).then(|| estimate.error / weight).into();
                estimate.error
            }
        };
        let threshold = settings.threshold_into(h, c.receiver);
        if error > threshold {
            (error, threshold, None)
        } else {
            // What the visibility term refines is the receiver's average of the visibility
            // (Sillion–Drettakis Appendix A): splitting the source would not reduce it.
            let seen = with_visibility(
                context,
                oracle,
                settings,
                c,
                partial_tests,
                error,
                &mut verdict,
            );
            under_outline = seen.under_outline;
            (seen.error, threshold, Some(Decision::SubdivideReceiver))
        }
    };
    verdict.error = error as f32;
    if error <= threshold || verdict.no_interaction {
        return verdict;
    }
    verdict.decision = match split {
        // The link error oracle names the element whose subdivision reduces the error (§5): splitting
        // the other one instead would only multiply links without helping.
        Some(Decision::SubdivideReceiver) if !(splittable(c.receiver) || under_outline) => {
            Decision::Admissible
        }
        Some(Decision::SubdivideSource) if !splittable(c.source) => Decision::Admissible,
        Some(decision) => decision,
        None => match oracle.element_to_split(context, c.receiver, c.source) {
            Decision::SubdivideReceiver if !splittable(c.receiver) => Decision::SubdivideSource,
            Decision::SubdivideSource if !splittable(c.source) => Decision::SubdivideReceiver,
            other => other,
        },
    };
    // A link about to be refined tests its shaft once, so that its children inherit a Clear or
    // Blocked verdict instead of each casting its own rays (or testing its own, smaller shaft).
    // Where its own test finds it Partial, they examine only the occluders it lists.
    if verdict.decision != Decision::Admissible && c.shaft.is_none() && verdict.shaft.is_none() {
        let among = match c.shaft_prior(partial_tests) {
            ShaftPrior::Among(list) => Some(list),
            _ => None,
        };
        let test = shaft_test(
            h,
            context.visibility,
            c.receiver,
            c.source,
            among,
            MAX_PARTIAL_OCCLUDERS,
        );
        verdict.shaft = test.map(|t| t.verdict);
        verdict.shaft_tested = test.is_some();
        verdict.partial_test = test.filter(|t| t.occluders().is_some()).map(Box::new);
    }
    verdict
}

/// Algorithm 4.1 for a candidate while judging it, its costs and shaft verdict put on `verdict`.
fn couple_for_verdict(
    context: &OracleContext,
    settings: &RefineSettings,
    c: Judging,
    partial_tests: &[ShaftTest],
    verdict: &mut Verdict,
) -> super::coupling::Coupling {
    let k = couple_with_prior(
        context.hierarchy,
        context.visibility,
        c.receiver,
        c.source,
        &settings.coupling,
        c.shaft_prior(partial_tests),
    );
    verdict.shaft = k.shaft;
    verdict.shaft_tested = c.shaft.is_none() && k.shaft.is_some();
    verdict.rays_saved = ray_count(k.rays_saved);
    verdict.coupling_rays = ray_count(k.rays);
    verdict.no_interaction = k.unoccluded <= 0.0;
    k
}

/// What [`with_visibility`] makes of an admissible link's estimate.
struct Seen {
    /// The estimate with its visibility weighed.
    error: f64,
    /// Whether the receiver counted as under an outline ([`OutlineRule::Split`]), and so may be
    /// split below the minimum area (`--outline-levels`).
    under_outline: bool,
}

/// The estimate `error` of a link its oracle finds admissible, once the variation of its visibility
/// over the receiver is weighed ([`RefinementOracle::with_partial_visibility`],
/// [`visibility_spread`]). The visibility is the one its coupling sampled: the cached coupling, or one
/// computed here and kept on `verdict` (the link's own if it stays); a Clear or Blocked shaft verdict
/// says it is whole without rays. Links that no spread could refine are not looked at. With
/// [`OutlineRule::Split`] a receiver that something lies over in part ([`straddles_outline`]) counts
/// as crossed by a hard boundary, spread ½, whatever the link's rays saw, weighed
/// [`RefineSettings::outline_gain`] more (`--outline-levels N`: N levels deeper) and splittable as far
/// below the minimum area.
fn with_visibility(
    context: &OracleContext,
    oracle: &dyn RefinementOracle,
    settings: &RefineSettings,
    c: Judging,
    partial_tests: &[ShaftTest],
    error: f64,
    verdict: &mut Verdict,
) -> Seen {
    let plain = Seen {
        error,
        under_outline: false,
    };
    let h = context.hierarchy;
    let threshold = settings.threshold_into(h, c.receiver);
    let Some(across_boundary) = oracle.with_partial_visibility(error, 0.5) else {
        return plain;
    };
    // The gain is at least 1: links that not even an outline would refine are not looked at.
    let across_outline = across_boundary * settings.outline_gain;
    if across_outline <= threshold {
        return plain;
    }
    let receiver = h.element(c.receiver);
    if settings.outlines == OutlineRule::Split
        && receiver.area > settings.min_area / settings.outline_gain
        && receiver
            .straddles_outline
            .get_or(|| straddles_outline(h, context.visibility, c.receiver))
    {
        // Something lies over part of the receiver: a hard boundary through it (eq. (5) at v = ½),
        // whatever the link's rays saw.
        return Seen {
            error: across_outline,
            under_outline: true,
        };
    }
    if across_boundary <= threshold {
        return plain;
    }
    if c.coupling.is_none() {
        if let Some(ShaftVerdict::Clear | ShaftVerdict::Blocked) = c.shaft {
            return plain;
        }
        let k = couple_for_verdict(context, settings, c, partial_tests, verdict);
        verdict.coupling = Some(Box::new(k.coupling));
    }
    let coupling = verdict
        .coupling
        .as_deref()
        .or(c.coupling)
        .expect("a coupling, cached or just computed");
    if coupling.visibility <= 0.0 || coupling.visibility >= 1.0 {
        // Whole by a Clear or Blocked shaft, or by rays that may have missed an edge near the
        // receiver's boundary: then eq. (5) at v = ½, as for a boundary the nodes straddle.
        if coupling.shaft.and_then(ShaftVerdict::inherited).is_none() {
            // Counted among the oracle's rays: one per corner, as if none agreed before the last.
            let corners = h.element(c.receiver).shape().vertices().len() as u32;
            verdict.rays = verdict.rays.saturating_add(corners);
            let lit = coupling.visibility >= 1.0;
            if corners_disagree(h, context.visibility, c.receiver, c.source, lit) {
                return Seen {
                    error: across_boundary,
                    under_outline: false,
                };
            }
        }
        return plain;
    }
    let spread = visibility_spread(
        h,
        c.receiver,
        c.source,
        coupling,
        settings.coupling.cubature_degree,
    );
    Seen {
        error: oracle
            .with_partial_visibility(error, spread)
            .unwrap_or(error),
        under_outline: false,
    }
}

/// The end a near cluster link (the source's sphere reaches the receiver's box,
/// `solvers::clustering::SourceSphere`) must be split at whatever its bound: a cluster receiver of at
/// most [`NEAR_RECEIVER_PATCHES`] patches (a cluster's sharing cannot place light from beside it),
/// a cluster source of more than [`NEAR_SOURCE_PATCHES`] (the near coupling sums every patch's exact
/// factor). `None` for a link the bound judges.
fn near_split(h: &Hierarchy, receiver: ElementId, source: ElementId) -> Option<Decision> {
    let patches = |id: ElementId| h.cluster(id).map(|cluster| h.contents(cluster).len());
    let decision = match (patches(receiver), patches(source)) {
        (Some(n), _) if n <= NEAR_RECEIVER_PATCHES => Decision::SubdivideReceiver,
        (_, Some(n)) if n > NEAR_SOURCE_PATCHES => Decision::SubdivideSource,
        _ => return None,
    };
    SourceSphere::of(h, source)
        .reaches(&h.bounds_of(receiver))
        .then_some(decision)
}

/// A link with a cluster at one end, judged by the power-type bound of [`transport_bound`]:
/// `ρ_max B_j · min(A_i, A_j, A_i A_j / (π d²))` (ρ_max the largest reflectance in a receiver cluster,
/// B_j the source's average radiance; visibility bounded by 1, as Sillion–Drettakis §6.1 notes of
/// cluster bounds). The link error oracle compares the same bound per unit receiver area, plus the
/// error the source's own estimate propagates through it (eq. (13) with the whole transfer as its
/// error), with the receiver's threshold. Above the threshold the larger end (by bounding box) is
/// split; a surface too small to split passes the split to the other end, a cluster always splits.
/// Before the bound, a near link is split where [`near_split`] says it must be.
fn decide_cluster_link(
    context: &OracleContext,
    oracle: &dyn RefinementOracle,
    settings: &RefineSettings,
    c: Judging,
    splittable: &dyn Fn(ElementId) -> bool,
) -> Verdict {
    let h = context.hierarchy;
    if let Some(decision) = near_split(h, c.receiver, c.source) {
        return Verdict {
            decision,
            error: f32::INFINITY,
            ..Verdict::admissible(OracleFactor::NONE)
        };
    }
    let bound = transport_bound(h, c.receiver, c.source);
    let weight = reflected_source_radiance(h, c.receiver, c.source);
    let (error, threshold) = if oracle.judges_couplings() {
        let rho = h.reflectance_of(c.receiver).max_channel();
        let area = h.element(c.receiver).area.max(1e-300);
        (
            (weight + rho * h.element(c.source).error) * bound / area,
            h.element(c.receiver).threshold,
        )
    } else {
        (weight * bound, settings.threshold_into(h, c.receiver))
    };
    let mut verdict = Verdict {
        error: error as f32,
        ..Verdict::admissible(OracleFactor::NONE)
    };
    if error <= threshold {
        return verdict;
    }
    let size = |id| h.bounds_of(id).diagonal();
    let larger = if size(c.receiver) >= size(c.source) {
        Decision::SubdivideReceiver
    } else {
        Decision::SubdivideSource
    };
    verdict.decision = match larger {
        Decision::SubdivideReceiver if !splittable(c.receiver) => Decision::SubdivideSource,
        Decision::SubdivideSource if !splittable(c.source) => Decision::SubdivideReceiver,
        other => other,
    };
    verdict
}
