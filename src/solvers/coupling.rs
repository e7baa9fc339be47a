//! Link coupling, Bekaert–Willems Algorithm 4.1: the coupling block `K_{i,α;j,β}` of eq. (3), the link
//! error coefficients `δ_{j,β}(x_k)` of eq. (6) at the receiver's cubature nodes, and the point-to-source
//! factors `K_{j,1}(x_k)` that carry propagated error in eqs. (11) and (13).
//!
//! The receiver gets a cubature rule of `--cubature-degree` (eq. (12)), the source a coarser one
//! ([`crate::bases::source_cubature_degree`]: it only integrates). The kernel is
//! evaluated at every pair of receiver node `x_k` and source node `y_l`, with the transmittance of the
//! segment between them (a ray per pair: this is where shadows come from, and what the error
//! coefficients see). One refinement over the paper's step 2: the inner integrals
//! `K_{j,β}(x_k) = ∫ K(x_k, y) φ_β(y) dA_y` are scaled so that their unoccluded constant part equals the
//! exact point-to-polygon factor (Lambert's formula, which §7 recommends for `K_{j,1}`): a ratio
//! estimator that removes the cubature error of the near-singular kernel between adjacent elements while
//! keeping the cubature's visibility and its shape across the source.
//!
//! With the averaged-orthonormal bases of [`crate::bases`] the overlap matrix of eq. (4) is `A_i I` on
//! triangles and parallelograms, so the solve of step 4a is a division by `A_i`; on other convex quads
//! the bilinear map's varying Jacobian makes it `A_i G` with a full `G` ([`crate::bases::Overlap`]),
//! which step 4a solves with (else a uniformly lit trapezoid would get a false gradient).
//!
//! Partly visible sources (`--source-rule jittered`): where the shaft test leaves visibility open,
//! each receiver node sees the source through its own random nodes, one in each cell of a regular
//! partition of the source ([`jittered_nodes`]), so that a shadow boundary across the source is sampled
//! without a bias common to all receivers; at least [`NEAR_SOURCE`] of the source's diameter away the
//! plain sum replaces the ratio estimator, which is biased at random nodes (`SourceSampler::rows`).
//!
//! Near sources: where the source lies within half the receiver's diameter of its centroid or of a
//! corner and the exact point factor varies more than twofold over the receiver's nodes, the light may
//! arrive in a band the nodes miss (a lamp hung just under a ceiling).
//! [`crate::geometry::near_field`] then integrates the point factor adaptively, and where the regular
//! rule is off by more than [`NEAR_FIELD_MISS`] the block, the unoccluded and the visible transfer
//! come from its composite rule; the error coefficients and node factors stay at the regular nodes,
//! where the error estimate reads them.
//!
//! Visibility reuse: where the visibility back end offers shaft tests ([`Visibility::shafts`]), a
//! surface link whose shaft is Clear takes transmittance 1 at every node pair and a Blocked one 0,
//! without rays; the verdict is the one inherited from the parent link, or this link's own test. With
//! exact ray casting the conservative verdicts are what the rays would find, so the coupling is the same
//! to the bit ([`crate::visibility::shaft`]).

use super::clustering::couple_cluster;
use crate::geometry::cubature::{jittered_nodes, nodes_on, nodes_on_into, rule, Node};
use crate::geometry::form_factor::{point_to_point, point_to_polygon};
use crate::geometry::near_field::{self, distance_to_polygon, is_near, NearField};
use crate::geometry::{DVec3, Shape};
use crate::hierarchy::{ElementId, ErrorStorage, Hierarchy, LinkCoupling};
use crate::random::{splitmix64, unit_interval};
use crate::visibility::shaft::{
    ShaftPrior, ShaftTest, ShaftVerdict, MAX_OWN_OCCLUDERS, MAX_PARTIAL_OCCLUDERS,
};
use crate::visibility::Visibility;

/// How link couplings are computed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CouplingSettings {
    /// Polynomial degree integrated exactly by the receiver's cubature rule (eq. (12)); the source's is
    /// [`crate::bases::source_cubature_degree`] of it.
    pub cubature_degree: usize,
    /// Seed of the visibility samples of cluster links.
    pub seed: u64,
    /// How the link error coefficients are stored (`--error-storage`, Bekaert–Willems §4.3).
    pub error_storage: ErrorStorage,
    /// Integrate the receiver side of near links adaptively where the regular rule misses their light
    /// (`--near-field`, [`crate::geometry::near_field`]).
    pub near_field: NearField,
    /// Where partly visible sources are sampled (`--source-rule`).
    pub source_rule: SourceRule,
}

/// Where the visibility rays of a link whose shaft test left visibility open end on its source
/// (`--source-rule`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum SourceRule {
    /// At the source rule's fixed nodes (Bekaert–Willems Algorithm 4.1 as published; the library's
    /// default): a shadow boundary across the source is sampled at the same places from every
    /// receiver.
    #[default]
    Fixed,
    /// At random nodes per receiver node, one in each cell of a regular partition of the source (the
    /// command line's default): unbiased over a shadow boundary across the source, at the price of
    /// noise (BENCHMARKS.md, "Shadow boundaries across sources" and "Partly visible sources by
    /// jittered strata"). `shifted` names it too: a random shift of the fixed nodes, which it
    /// replaced.
    ///
    /// The nodes are [`jittered_nodes`].
    #[value(alias = "shifted")]
    Jittered,
}

/// Relative difference between the regular receiver rule's unoccluded transfer and the adaptive one
/// above which a near link's block is integrated with the adaptive rule. Below it the regular rule is
/// kept: its point factors of a closed scene sum to exactly 1 at every node, which a mix of rules would
/// break by up to the difference.
pub const NEAR_FIELD_MISS: f64 = 0.1;

/// Receiver nodes nearer a partly visible source than this share of its diameter take the ratio
/// estimator at their jittered source nodes; farther ones the plain sum (`SourceSampler::rows`). At
/// half the diameter `1/r²` varies at most ninefold across the source, which bounds (cosines aside)
/// how far one jittered node can carry more than its share.
pub const NEAR_SOURCE: f64 = 0.5;

impl Default for CouplingSettings {
    fn default() -> Self {
        CouplingSettings {
            cubature_degree: 4,
            seed: 1,
            error_storage: ErrorStorage::Full,
            near_field: NearField::Adaptive,
            source_rule: SourceRule::Fixed,
        }
    }
}

/// A link's coupling and what it cost.
#[derive(Clone, Debug, PartialEq)]
pub struct Coupling {
    pub coupling: LinkCoupling,
    /// The receiver-averaged form factor without visibility (zero: the elements cannot interact).
    pub unoccluded: f64,
    /// Nodes of the source rule (visibility samples per receiver node).
    pub source_nodes: usize,
    pub rays: u64,
    /// The shaft verdict the coupling used (`None`: no shaft test, every pair cast a ray).
    pub shaft: Option<ShaftVerdict>,
    /// Rays a Clear or Blocked shaft made unnecessary.
    pub rays_saved: u64,
}

/// Algorithm 4.1 for the link `source` → `receiver`, with the shaft verdict `known` inherited from the
/// parent link (or found earlier), if any; links with a cluster at either end are coupled by
/// [`couple_cluster`].
pub fn couple(
    hierarchy: &Hierarchy,
    visibility: &dyn Visibility,
    receiver: ElementId,
    source: ElementId,
    settings: &CouplingSettings,
    known: Option<ShaftVerdict>,
) -> Coupling {
    let prior = known.map_or(ShaftPrior::Unknown, ShaftPrior::Verdict);
    couple_with_prior(hierarchy, visibility, receiver, source, settings, prior)
}

/// [`couple`], with what the parent link's shaft test left to this one: a verdict to take as is, or
/// the occluder list its own test only needs to examine. The error coefficients are stored as
/// `settings.error_storage` says.
pub fn couple_with_prior(
    hierarchy: &Hierarchy,
    visibility: &dyn Visibility,
    receiver: ElementId,
    source: ElementId,
    settings: &CouplingSettings,
    prior: ShaftPrior,
) -> Coupling {
    let coupled = couple_in_full(hierarchy, visibility, receiver, source, settings, prior);
    match settings.error_storage {
        ErrorStorage::Full => coupled,
        ErrorStorage::Reduced => Coupling {
            coupling: coupled.coupling.reduced(hierarchy.radiance(source)),
            ..coupled
        },
    }
}

/// [`couple_with_prior`] with every error coefficient `δ_{j,β}(x_k)`.
fn couple_in_full(
    hierarchy: &Hierarchy,
    visibility: &dyn Visibility,
    receiver: ElementId,
    source: ElementId,
    settings: &CouplingSettings,
    prior: ShaftPrior,
) -> Coupling {
    if hierarchy.is_cluster(receiver) || hierarchy.is_cluster(source) {
        return couple_cluster(hierarchy, visibility, receiver, source, settings);
    }
    let (known, tested) = match prior {
        ShaftPrior::Verdict(verdict) => (Some(verdict), None),
        ShaftPrior::Among(list) => (
            None,
            shaft_test(
                hierarchy,
                visibility,
                receiver,
                source,
                Some(list),
                MAX_PARTIAL_OCCLUDERS,
            ),
        ),
        // The list serves only this link's rays: a short walk (see `MAX_OWN_OCCLUDERS`).
        ShaftPrior::Unknown => (
            None,
            shaft_test(
                hierarchy,
                visibility,
                receiver,
                source,
                None,
                MAX_OWN_OCCLUDERS,
            ),
        ),
    };
    let shaft = known.or(tested.map(|t| t.verdict));
    // A Partial shaft with few polygons in it: rays test only those.
    let occluders = tested
        .as_ref()
        .and_then(ShaftTest::occluders)
        .zip(visibility.shafts());
    let basis = &hierarchy.basis;
    let size = basis.size();
    let (r, s) = (hierarchy.element(receiver), hierarchy.element(source));
    let (r_shape, s_shape) = (r.shape(), s.shape());
    let n_r = hierarchy.patch_of(receiver).normal;
    let n_s = hierarchy.patch_of(source).normal;
    let degree = settings.cubature_degree;
    let mut buffers = COUPLING_BUFFERS.take();
    let CouplingBuffers {
        x_nodes,
        y_nodes,
        inner: inner_buffer,
        block,
        errors,
        node_factors,
    } = &mut buffers;
    let source_degree = crate::bases::source_cubature_degree(degree);
    nodes_on_into(r_shape, rule(r_shape.domain(), degree), x_nodes);
    nodes_on_into(s_shape, rule(s_shape.domain(), source_degree), y_nodes);
    let phi_x = basis.rule_values(r_shape.domain(), degree);
    let phi_y = basis.rule_values(s_shape.domain(), source_degree);
    let x_nodes = &*x_nodes;

    let n = x_nodes.len();
    let sampler = SourceSampler {
        visibility,
        shaft,
        occluders,
        n_r,
        n_s,
        receiver_polygon: hierarchy.patch_of(receiver).polygon,
        source: s_shape,
        y_nodes,
        phi_y,
        basis,
        source_rule: settings.source_rule,
        seed: settings.seed,
    };
    // Step 2: K_{j,β}(x_k), without ρ_i, at the receiver's regular nodes (the error coefficients' and
    // node factors' points).
    let regular = sampler.rows(x_nodes, std::mem::take(inner_buffer));
    let (mut rays, mut rays_saved) = (regular.rays, regular.rays_saved);
    // A near source whose light the regular nodes miss: the block, the unoccluded and the visible
    // transfer come from the adaptive composite rule instead (`geometry::near_field`). Where the
    // factor is nearly even over the nodes the regular rule is trusted without looking.
    let (low, high) = regular.factor_range;
    let near = (settings.near_field == NearField::Adaptive
        && high > near_field::EVEN_RATIO * low
        && is_near(r_shape, s_shape))
    .then(|| {
        near_field::receiver_integral(
            r_shape,
            n_r,
            s_shape,
            near_field::SEARCH_DEGREE,
            near_field::TOLERANCE,
        )
    })
    .filter(|near| (near.value - regular.unoccluded).abs() > NEAR_FIELD_MISS * near.value);
    let composite = near.map(|near| {
        let nodes = near.nodes(r_shape, degree);
        let phi = basis_values(basis, r_shape, &nodes);
        let rows = sampler.rows(&nodes, Vec::new());
        rays += rows.rays;
        rays_saved += rows.rays_saved;
        (nodes, phi, rows)
    });
    let (block_nodes, phi_block, block_rows) = match &composite {
        Some((nodes, phi, rows)) => (nodes.as_slice(), phi.as_slice(), rows),
        None => (x_nodes.as_slice(), phi_x, &regular),
    };
    let inner = &regular.inner;
    let unoccluded = block_rows.unoccluded;
    // Step 3: the block, divided by A_i (step 4a with O = A_i I).
    block.clear();
    block.resize(size * size, 0.0);
    let node_rows = phi_block
        .chunks_exact(size)
        .zip(block_rows.inner.chunks_exact(size));
    for (x, (phi, inner)) in block_nodes.iter().zip(node_rows) {
        let w = x.weight / r.area;
        for (block_row, &p) in block.chunks_exact_mut(size).zip(phi) {
            let wa = w * p;
            for (b, &k) in block_row.iter_mut().zip(inner) {
                *b += wa * k;
            }
        }
    }
    // Step 4a on a quad whose overlap matrix is not A_i I.
    if let Some(overlap) = basis.overlap(r_shape, r.area) {
        overlap.solve_columns(block, size);
    }
    // Step 4b: δ_{j,β}(x_k) = Σ_α R_{α,β} φ_α(x_k) − K_{j,β}(x_k).
    // Summed over α in order for every β at once (from −0.0, as `Iterator::sum` does).
    errors.clear();
    for (phi, inner) in phi_x.chunks_exact(size).zip(inner.chunks_exact(size)) {
        let mut projected = [-0.0; crate::bases::MAX_BASIS_SIZE];
        let projected = &mut projected[..size];
        for (block_row, &p) in block.chunks_exact(size).zip(phi) {
            for (sum, &b) in projected.iter_mut().zip(block_row) {
                *sum += b * p;
            }
        }
        errors.extend(projected.iter().zip(inner).map(|(p, k)| (p - k) as f32));
    }
    node_factors.clear();
    node_factors.extend((0..n).map(|k| inner[k * size] as f32));
    let visible: f64 = block_nodes
        .iter()
        .enumerate()
        .map(|(k, x)| x.weight * block_rows.inner[k * size])
        .sum();
    let visibility = visible_fraction(visible, unoccluded);
    let source_nodes = sampler.y_nodes.len();
    let coupled = Coupling {
        coupling: LinkCoupling::new(
            block,
            errors,
            node_factors,
            visibility as f32,
            visibility_error(unoccluded / r.area, visibility, source_nodes),
        ),
        unoccluded: unoccluded / r.area,
        source_nodes,
        rays,
        shaft,
        rays_saved,
    };
    *inner_buffer = regular.inner;
    COUPLING_BUFFERS.set(buffers);
    coupled
}

/// A receiver node set's share of Algorithm 4.1's step 2: `K_{j,β}(x_k)` per node (row-major, node by
/// β), the unoccluded transfer `Σ_k w_k F(x_k → S)` and the rays it cost.
struct NodeRows {
    inner: Vec<f64>,
    unoccluded: f64,
    /// The smallest and largest `F(x_k → S)` over the nodes.
    factor_range: (f64, f64),
    rays: u64,
    rays_saved: u64,
}

/// What step 2 needs of the source and of visibility, to evaluate it at any receiver nodes.
struct SourceSampler<'a> {
    visibility: &'a dyn Visibility,
    shaft: Option<ShaftVerdict>,
    occluders: Option<(&'a [u32], &'a crate::visibility::shaft::ShaftCuller)>,
    n_r: DVec3,
    n_s: DVec3,
    /// The receiver's polygon (for a feature size of its own, [`Visibility::transmittance_onto`]).
    receiver_polygon: usize,
    source: &'a Shape,
    y_nodes: &'a [Node],
    phi_y: &'a [f64],
    basis: &'a crate::bases::Basis,
    source_rule: SourceRule,
    /// Seed of the jittered source nodes of partly visible links.
    seed: u64,
}

impl SourceSampler<'_> {
    /// Step 1 (the kernel at each node pair, with its transmittance) and step 2 at `nodes`.
    ///
    /// With [`SourceRule::Jittered`], where the shaft test left the source's visibility open, each
    /// receiver node sees the source through its own jittered nodes, as many as the source rule has
    /// ([`jittered_nodes`], seeded by `--seed` and the node's position), not through the fixed nodes:
    /// with fixed nodes a shadow boundary across the source is sampled at the same places from every
    /// receiver, and the error adds up instead of averaging out. A lamp housing's reflector above its
    /// tube, 4 cm wide with nodes at 21% and 79% of its width, was seen 10% brighter from the whole
    /// floor below, the housing sent 1–2% too much light, and the classroom read 2% bright; a
    /// corridor's ceiling pieces beside its lamps were seen from a wall with 27% of their light
    /// (random nodes: 77%; BENCHMARKS.md, "Shadow boundaries across sources"). Links with a Clear or
    /// Blocked shaft keep the fixed rule, whose higher-order moments are exact. The command line's
    /// default; the library's stays the published fixed rule, which is less noisy where occluders are
    /// far from the sources they hide (the Cornell box: 1.78% against 1.9% |error|/mean).
    ///
    /// Random nodes and the exact factor: the fixed rule's rows are scaled to the exact
    /// point-to-polygon factor (a ratio `F Σ w G V φ / Σ w G`), but at random nodes that ratio is
    /// biased wherever the kernel and the visibility vary together across the source, both sums
    /// coming from the same draw: a strip whose near end is hidden was seen 12% too bright with
    /// jittered nodes, 26% with the randomly shifted Gauss nodes used before (`tests/galerkin.rs`),
    /// and the classroom's tubes sent its walls 1.9% too much through their housings' openings. So
    /// receiver nodes at least [`NEAR_SOURCE`] of the source's diameter away take the plain sum
    /// `Σ w G V φ`, which is unbiased (every jittered node is uniform over its cell); only nearer
    /// ones, where a node may land next to the receiver point and the plain sum has no bound, keep
    /// the ratio (BENCHMARKS.md, "Partly visible sources by jittered strata").
    /// `inner`: a vector to fill (its contents are replaced).
    fn rows(&self, nodes: &[Node], mut inner: Vec<f64>) -> NodeRows {
        let size = self.basis.size();
        inner.clear();
        inner.resize(nodes.len() * size, 0.0);
        let mut out = NodeRows {
            inner,
            unoccluded: 0.0,
            factor_range: (f64::INFINITY, 0.0),
            rays: 0,
            rays_saved: 0,
        };
        let decided = self.source_rule == SourceRule::Fixed
            || matches!(
                self.shaft,
                Some(ShaftVerdict::Clear) | Some(ShaftVerdict::Blocked)
            );
        // Jittered source nodes, refilled for each receiver node: as many cells as the rule has nodes
        // (`m × m` on either domain).
        let mut jittered = Vec::new();
        let cells = (self.y_nodes.len() as f64).sqrt().round() as usize;
        let far = NEAR_SOURCE * self.source.diameter();
        // Most nodes are far from the source: its corner sphere tells without the exact distance.
        let (centre, radius) = self.source.corner_sphere();
        for (k, x) in nodes.iter().enumerate() {
            let exact = point_to_polygon(x.point, self.n_r, self.source);
            out.factor_range = (out.factor_range.0.min(exact), out.factor_range.1.max(exact));
            if exact <= 0.0 {
                continue;
            }
            out.unoccluded += x.weight * exact;
            let row = &mut out.inner[k * size..(k + 1) * size];
            let (rays, saved) = if decided {
                self.row(x.point, Some(exact), self.y_nodes, Some(self.phi_y), row)
            } else {
                let mut state = self.stream_at(x.point);
                let unit = || {
                    state = splitmix64(state);
                    unit_interval(state)
                };
                jittered_nodes(self.source, cells, unit, &mut jittered);
                let near = x.point.distance(centre) - radius < far
                    && distance_to_polygon(x.point, self.source) < far;
                self.row(x.point, near.then_some(exact), &jittered, None, row)
            };
            out.rays += rays;
            out.rays_saved += saved;
        }
        out
    }

    /// The random stream of the source nodes seen from receiver point `x`: a function of the seed and
    /// of `x` alone, so that a coupling is the same whichever thread or pass computes it.
    fn stream_at(&self, x: DVec3) -> u64 {
        splitmix64(
            self.seed
                ^ x.x.to_bits()
                ^ x.y.to_bits().rotate_left(21)
                ^ x.z.to_bits().rotate_left(42),
        )
    }

    /// One receiver point's row `K_{j,β}(x)` from the source nodes `y_nodes` (basis values `phi_y`,
    /// or, for `None`, evaluated at the nodes that let light through: jittered nodes are used once,
    /// and a blocked one needs none), scaled so that its unoccluded constant part is the exact factor
    /// where `exact` is given, the plain cubature sum where not; the rays cast and saved.
    fn row(
        &self,
        x: DVec3,
        exact: Option<f64>,
        y_nodes: &[Node],
        phi_y: Option<&[f64]>,
        row: &mut [f64],
    ) -> (u64, u64) {
        let size = row.len();
        let (mut rays, mut saved) = (0, 0);
        let mut open_sum = 0.0;
        for (l, y) in y_nodes.iter().enumerate() {
            let g = y.weight * point_to_point(x, self.n_r, y.point, self.n_s);
            if g <= 0.0 {
                continue;
            }
            open_sum += g;
            let t = match self.shaft {
                Some(ShaftVerdict::Clear) => {
                    saved += 1;
                    1.0
                }
                Some(ShaftVerdict::Blocked) => {
                    saved += 1;
                    0.0
                }
                _ => {
                    rays += 1;
                    match self.occluders {
                        Some((list, culler)) => {
                            if culler.segment_occluded_among(list, x, y.point) {
                                0.0
                            } else {
                                1.0
                            }
                        }
                        None => {
                            self.visibility
                                .transmittance_onto(x, y.point, self.receiver_polygon)
                        }
                    }
                }
            };
            if t > 0.0 {
                let gt = g * t;
                let mut evaluated = [0.0; 10];
                let phi = match phi_y {
                    Some(table) => &table[l * size..(l + 1) * size],
                    None => {
                        self.basis.eval(self.source.domain(), y.uv, &mut evaluated);
                        &evaluated[..size]
                    }
                };
                for (value, p) in row.iter_mut().zip(phi) {
                    *value += gt * p;
                }
            }
        }
        if let Some(exact) = exact.filter(|_| open_sum > 0.0) {
            let scale = exact / open_sum;
            row.iter_mut().for_each(|v| *v *= scale);
        }
        (rays, saved)
    }
}

/// The shaft test of the surface link `source` → `receiver`, where the visibility back end offers one;
/// `among`: the complete occluder list of a test of a shaft that holds this one, if known; a Partial
/// verdict lists its occluders when there are at most `list_room` ([`ShaftCuller::classify`]).
///
/// [`ShaftCuller::classify`]: crate::visibility::shaft::ShaftCuller::classify
pub fn shaft_test(
    hierarchy: &Hierarchy,
    visibility: &dyn Visibility,
    receiver: ElementId,
    source: ElementId,
    among: Option<&[u32]>,
    list_room: usize,
) -> Option<ShaftTest> {
    let culler = visibility.shafts()?;
    let (r, s) = (hierarchy.patch_of(receiver), hierarchy.patch_of(source));
    Some(culler.classify(
        hierarchy.element(receiver).shape(),
        r.polygon,
        hierarchy.element(source).shape(),
        s.polygon,
        among,
        list_room,
    ))
}

/// How much the visibility of `coupling`'s source varies over its receiver: Sillion–Drettakis
/// Appendix A eq. (3) with the receiver's cubature nodes `x_k` (weights `w_k`, the degree the coupling
/// was made with) and an area source, `Σ w_k F_k |v_k − v| / Σ w_k F_k`, where `F_k` is the unoccluded
/// point-to-source factor at `x_k`, `v_k` the fraction of it the node's rays found visible (the node
/// factor over `F_k`) and `v` the link's visibility. It is eq. (5)'s `2v(1 − v)` where every node sees
/// the source wholly or not at all (a shadow boundary crossing the receiver), and 0 where every node
/// sees the same part of the source (an occluder cutting the source, not the receiver).
pub fn visibility_spread(
    hierarchy: &Hierarchy,
    receiver: ElementId,
    source: ElementId,
    coupling: &LinkCoupling,
    cubature_degree: usize,
) -> f64 {
    let shape = hierarchy.element(receiver).shape();
    let nodes = nodes_on(shape, rule(shape.domain(), cubature_degree));
    let normal = hierarchy.patch_of(receiver).normal;
    let source = hierarchy.element(source).shape();
    let v = f64::from(coupling.visibility);
    let (mut spread, mut total) = (0.0, 0.0);
    for (x, visible) in nodes.iter().zip(coupling.node_factors()) {
        let unoccluded = x.weight * point_to_polygon(x.point, normal, source);
        if unoccluded > 0.0 {
            let v_k = (x.weight * f64::from(visible) / unoccluded).clamp(0.0, 1.0);
            spread += unoccluded * (v_k - v).abs();
            total += unoccluded;
        }
    }
    if total > 0.0 {
        spread / total
    } else {
        0.0
    }
}

/// `v`: the visible part of a link's transfer over its unoccluded part (1 when nothing can arrive).
pub fn visible_fraction(visible: f64, unoccluded: f64) -> f64 {
    if unoccluded > 0.0 {
        (visible / unoccluded).clamp(0.0, 1.0)
    } else {
        1.0
    }
}

/// `F_unoccluded · sqrt(v (1 − v) / m)`: see `LinkCoupling::visibility_error`.
pub fn visibility_error(unoccluded: f64, visibility: f64, source_nodes: usize) -> f32 {
    let v = visibility.clamp(0.0, 1.0);
    (unoccluded * (v * (1.0 - v) / source_nodes.max(1) as f64).sqrt()) as f32
}

/// `φ_α` at each node, row-major (node, α): for nodes not of a [`rule`], whose values
/// [`crate::bases::Basis::rule_values`] holds.
pub fn basis_values(
    basis: &crate::bases::Basis,
    shape: &crate::geometry::Shape,
    nodes: &[Node],
) -> Vec<f64> {
    let size = basis.size();
    let mut out = vec![0.0; nodes.len() * size];
    for (node, values) in nodes.iter().zip(out.chunks_exact_mut(size)) {
        basis.eval(shape.domain(), node.uv, values);
    }
    out
}

/// The vectors of a surface coupling, kept per thread from one coupling to the next
/// ([`COUPLING_BUFFERS`]).
#[derive(Default)]
struct CouplingBuffers {
    x_nodes: Vec<Node>,
    y_nodes: Vec<Node>,
    inner: Vec<f64>,
    block: Vec<f64>,
    errors: Vec<f32>,
    node_factors: Vec<f32>,
}

thread_local! {
    /// Each thread's [`CouplingBuffers`], taken by a coupling and put back when it is done: a solve
    /// couples hundreds of thousands of links, and eight short-lived vectors each were about a
    /// twentieth of the default solve's time. (A coupling made while another holds them, were there
    /// one, would find empty vectors: slower, the same result.)
    static COUPLING_BUFFERS: std::cell::Cell<CouplingBuffers> = std::cell::Cell::default();
}
