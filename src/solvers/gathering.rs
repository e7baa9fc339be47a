//! Gathering iterations over the links of a refined hierarchy for the coefficient system of
//! Bekaert–Willems eq. (2), each followed by push-pull: Jacobi (all elements gather from the previous
//! iterate, in parallel), Gauss–Seidel (patches in order, each seeing the radiance already updated by the
//! patches before it; sequential but converging about twice as fast), its over-relaxed form (each
//! patch's step extrapolated by a factor learned from the sweeps' rate) and Southwell (the patch with
//! the largest unshot change first). Within one patch the elements gather in parallel where the patch is
//! large enough to pay for it ([`relax`]): what they gather reads only other patches and the sweep's
//! cluster values, so the order is Gauss–Seidel's whatever the threads. Runs of patches that do not
//! gather from each other relax in parallel too ([`PatchRuns`]), Gauss–Seidel's sweep all the same.

use super::clustering::{carries_light, ClusterPlan, ClusterSweep};
use super::push_pull::{leaf_exitant, push_pull, PatchUpdate};
use crate::bases::MAX_BASIS_SIZE;
use crate::color::Rgb;
use crate::hierarchy::{ElementId, Hierarchy, Link};
use crate::parallel::Uneven;
use rayon::prelude::*;
use std::f64::consts::PI;
use std::ops::Range;

/// Power totals after one sweep.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Sweep {
    /// Σ π A B over leaves (W per channel).
    pub exitant: Rgb,
    /// Σ π A (1 - ρ) H over leaves (W per channel).
    pub absorbed: Rgb,
}

/// One iterative method for the coefficient system `L_i = E_i + ρ_i Σ_j K_ij L_j` on the current links.
pub trait GatheringSolver: Sync + Send {
    fn name(&self) -> &'static str;
    /// Performs one sweep, updating the radiance coefficients of every element; `plan` is the
    /// current links' [`SweepPlan`], made once for all the sweeps between two refinements.
    fn sweep(&self, hierarchy: &mut Hierarchy, plan: &SweepPlan) -> Sweep;
}

/// Adds the irradiance coefficients gathered over the links stored at `id` to `out`:
/// `H_α += Σ_links Σ_β K_{αβ} L_{j,β}` (eq. (2) with the averaged-orthonormal basis, before ρ_i), and at
/// a patch root the irradiance pushed down from the clusters above it; what clusters send and push
/// comes from `clusters`, computed once per sweep.
pub fn gather(hierarchy: &Hierarchy, clusters: &ClusterSweep, id: ElementId, out: &mut [Rgb]) {
    let size = out.len();
    // This element's centre, found once for all its cluster links (a surface's is its centroid).
    let mut centre = None;
    for link in &hierarchy.element(id).links {
        if hierarchy.is_cluster(link.source) {
            if !carries_light(link) {
                continue;
            }
            // A cluster's coupling is constant in the source (column 0 only); with item buffers what
            // it sends this way comes from its visible patches (§6.1).
            let centre = *centre.get_or_insert_with(|| hierarchy.center_of(id));
            let l =
                clusters.radiance_toward(hierarchy, link.source, centre, link.coupling.visibility);
            for (alpha, h) in out.iter_mut().enumerate() {
                *h += l * f64::from(link.coupling.block()[alpha * size]);
            }
            continue;
        }
        if !reads_source_radiance(hierarchy, link) {
            continue; // blocked: more than half of office3's links
        }
        let source = hierarchy.radiance(link.source);
        for (alpha, h) in out.iter_mut().enumerate() {
            let row = &link.coupling.block()[alpha * size..(alpha + 1) * size];
            *h += row
                .iter()
                .zip(source)
                .map(|(&k, &l)| l * f64::from(k))
                .sum::<Rgb>();
        }
    }
    out[0] += clusters.pushed(id);
    if let Some(slope) = clusters.pushed_slope(id) {
        for (h, s) in out.iter_mut().zip(slope) {
            *h += s;
        }
    }
}

/// Whether [`gather`] reads the radiance coefficients of `link`'s source: a surface source whose
/// coupling is not zero (a cluster's radiance comes from the sweep's [`ClusterSweep`] instead).
/// [`PatchRuns`] orders the patches by it.
fn reads_source_radiance(hierarchy: &Hierarchy, link: &Link) -> bool {
    !hierarchy.is_cluster(link.source) && !link.coupling.is_zero()
}

/// What every sweep between two refinements reads of the links alone, made once for them all
/// (`solvers::sweep_to_tolerance`): what the clusters send ([`ClusterPlan`]) and the runs of patches
/// that relax together ([`PatchRuns`], found at the first sweep that orders its patches: Jacobi and
/// Southwell never ask). Valid while the links are unchanged.
pub struct SweepPlan {
    pub clusters: ClusterPlan,
    runs: std::sync::OnceLock<PatchRuns>,
}

impl SweepPlan {
    /// The plan of the hierarchy's current links.
    pub fn new(hierarchy: &Hierarchy) -> Self {
        SweepPlan {
            clusters: ClusterPlan::new(hierarchy),
            runs: std::sync::OnceLock::new(),
        }
    }

    /// The runs of patches of `hierarchy`'s links (the links the plan was made for).
    fn runs(&self, hierarchy: &Hierarchy) -> &PatchRuns {
        self.runs.get_or_init(|| PatchRuns::new(hierarchy))
    }
}

/// Consecutive patches (in patch order) none of which gathers from an earlier patch of its run: each
/// reads the radiance of the run's other patches as it was before the run, whether they relax one
/// after another, as Gauss–Seidel orders them, or all at once. A run's patches therefore relax in
/// parallel and their updates are applied in patch order: Gauss–Seidel's sweep, bit for bit, whatever
/// the threads. Most patches of a furnished room gather from clusters and from a few surfaces nearby:
/// the classroom's 12,462 patches make about 1,900 runs, and its sweeps, which had left one of two
/// threads idle half the time, take 1.92–1.95 s instead of 2.35 s (BENCHMARKS.md, "Uneven loops").
struct PatchRuns {
    /// The first patch of each run, then the number of patches.
    starts: Vec<u32>,
}

/// Most elements in the trees of one run of several patches: a run holds all its patches' updates at
/// once, so this bounds that memory (a patch alone makes a run whatever its size; its elements gather
/// in parallel, [`relax`]).
const RUN_ELEMENTS: usize = 4096;

impl PatchRuns {
    fn new(h: &Hierarchy) -> Self {
        let trees: Vec<(Option<u32>, usize)> = (0..h.patches.len() as u32)
            .into_par_iter()
            .uneven()
            .map(|p| latest_earlier_source(h, h.patches[p as usize].root, p))
            .collect();
        let mut starts = Vec::new();
        let mut elements = 0;
        for (p, &(latest, size)) in trees.iter().enumerate() {
            let start = starts.last().copied().unwrap_or(0);
            if starts.is_empty()
                || latest.is_some_and(|q| q >= start)
                || elements + size > RUN_ELEMENTS
            {
                starts.push(p as u32);
                elements = 0;
            }
            elements += size;
        }
        starts.push(h.patches.len() as u32);
        PatchRuns { starts }
    }

    /// The runs, each a range of patches, in patch order.
    fn runs(&self) -> impl Iterator<Item = Range<u32>> + '_ {
        self.starts.windows(2).map(|w| w[0]..w[1])
    }
}

/// The latest patch before `patch` whose radiance the links of the tree under `id` (in `patch`) read,
/// and the tree's element count.
fn latest_earlier_source(h: &Hierarchy, id: ElementId, patch: u32) -> (Option<u32>, usize) {
    let element = h.element(id);
    let own = (element.links.iter())
        .filter(|link| reads_source_radiance(h, link))
        .map(|link| h.element(link.source).patch())
        .filter(|&q| q < patch)
        .max();
    element
        .children
        .iter()
        .fold((own, 1), |(latest, size), &child| {
            let (child_latest, child_size) = latest_earlier_source(h, child, patch);
            (latest.max(child_latest), size + child_size)
        })
}

/// Patches whose trees hold fewer elements gather on the calling thread: spreading a few dozen gathers
/// over the pool costs more than it saves.
const PARALLEL_GATHER_ELEMENTS: usize = 256;

/// One patch's Gauss–Seidel step: every element of its tree gathers over its links (in parallel on a
/// tree of [`PARALLEL_GATHER_ELEMENTS`] or more), then push-pull. The result does not depend on the
/// thread count: each element's links are summed in their order into zero before the sum is added to
/// what its ancestors pushed down, and the patch's own radiance is not read until the update is applied.
fn relax(hierarchy: &Hierarchy, clusters: &ClusterSweep, patch: u32) -> PatchUpdate {
    let size = hierarchy.basis_size();
    let add = |out: &mut [Rgb], gathered: &[Rgb]| {
        out.iter_mut().zip(gathered).for_each(|(o, &g)| *o += g);
    };
    let root = hierarchy.patches[patch as usize].root;
    if hierarchy.element(root).is_leaf() {
        // Most patches of a furnished room: one element, gathered without a list.
        return push_pull(hierarchy, patch, &|id, out| {
            let mut gathered = [Rgb::BLACK; MAX_BASIS_SIZE];
            gather(hierarchy, clusters, id, &mut gathered[..size]);
            add(out, &gathered[..size]);
        });
    }
    let tree = hierarchy.subtree(root);
    let mut gathered = vec![Rgb::BLACK; tree.len() * size];
    let gather_into = |(out, &id): (&mut [Rgb], &ElementId)| gather(hierarchy, clusters, id, out);
    if tree.len() >= PARALLEL_GATHER_ELEMENTS {
        gathered
            .par_chunks_mut(size)
            .zip(tree.par_iter())
            .with_min_len(PARALLEL_GATHER_ELEMENTS / 4)
            .for_each(gather_into);
    } else {
        gathered.chunks_mut(size).zip(&tree).for_each(gather_into);
    }
    // Push-pull visits the tree in the same pre-order as `subtree`.
    let next = std::cell::Cell::new(0);
    push_pull(hierarchy, patch, &|id, out| {
        let k = next.get();
        debug_assert_eq!(tree[k], id, "push-pull's order is the subtree's");
        next.set(k + 1);
        add(out, &gathered[k * size..(k + 1) * size]);
    })
}

fn apply(hierarchy: &mut Hierarchy, update: &PatchUpdate, totals: &mut Sweep) {
    update.apply(hierarchy);
    totals.exitant += update.exitant;
    totals.absorbed += update.absorbed;
}

/// Jacobi iteration: gather everywhere from the previous iterate, then push-pull every patch.
#[derive(Clone, Copy, Debug, Default)]
pub struct Jacobi;

impl GatheringSolver for Jacobi {
    fn name(&self) -> &'static str {
        "jacobi"
    }

    fn sweep(&self, hierarchy: &mut Hierarchy, plan: &SweepPlan) -> Sweep {
        let h = &*hierarchy;
        let size = h.basis_size();
        let clusters = ClusterSweep::planned(h, &plan.clusters);
        let mut gathered = vec![Rgb::BLACK; h.elements.len() * size];
        gathered
            .par_chunks_mut(size)
            .enumerate()
            .for_each(|(id, out)| gather(h, &clusters, id as ElementId, out));
        let updates: Vec<PatchUpdate> = (0..h.patches.len() as u32)
            .into_par_iter()
            .uneven()
            .map(|p| {
                push_pull(h, p, &|id, out| {
                    let g = &gathered[id as usize * size..(id as usize + 1) * size];
                    out.iter_mut().zip(g).for_each(|(o, &g)| *o += g);
                })
            })
            .collect();
        let mut totals = Sweep::default();
        for update in &updates {
            apply(hierarchy, update, &mut totals);
        }
        hierarchy.pull_clusters();
        totals
    }
}

/// Gauss–Seidel iteration over patches.
#[derive(Clone, Copy, Debug, Default)]
pub struct GaussSeidel;

impl GatheringSolver for GaussSeidel {
    fn name(&self) -> &'static str {
        "gauss-seidel"
    }

    fn sweep(&self, hierarchy: &mut Hierarchy, plan: &SweepPlan) -> Sweep {
        sweep_in_order(hierarchy, plan, |hierarchy, update, totals| {
            apply(hierarchy, &update, totals)
        })
    }
}

/// A sweep over the patches in order, each patch's step taken by `take` (which applies it and adds
/// its power to the totals). Links at clusters gather once per sweep (Jacobi-like); patches see each
/// other's updates. The patches of a run ([`PatchRuns`]) relax in parallel, their steps taken in order.
fn sweep_in_order(
    hierarchy: &mut Hierarchy,
    plan: &SweepPlan,
    take: impl Fn(&mut Hierarchy, PatchUpdate, &mut Sweep),
) -> Sweep {
    let clusters = ClusterSweep::planned(hierarchy, &plan.clusters);
    let mut totals = Sweep::default();
    for run in plan.runs(hierarchy).runs() {
        if run.len() == 1 {
            let update = relax(hierarchy, &clusters, run.start);
            take(hierarchy, update, &mut totals);
            continue;
        }
        let h = &*hierarchy;
        let updates: Vec<PatchUpdate> = run
            .into_par_iter()
            .uneven()
            .map(|p| relax(h, &clusters, p))
            .collect();
        for update in updates {
            take(hierarchy, update, &mut totals);
        }
    }
    hierarchy.pull_clusters();
    totals
}

/// Successive over-relaxation: Gauss–Seidel's sweep with each patch's step extrapolated,
/// `L ← L + ω (L_GS − L)` on every coefficient of its tree. The same fixed point as Gauss–Seidel in
/// fewer sweeps where its steps keep one sign from sweep to sweep (the classroom's solve, 24 sweeps →
/// 16; `BENCHMARKS.md`, "Over-relaxed Gauss–Seidel").
///
/// `ω` starts at [`OVER_RELAXATION`] and follows the scene ([`Relaxation::observe`]): the brighter the
/// room, the slower Gauss–Seidel's error falls and the larger the best `ω` (a closed white box of
/// reflectance 0.98: 222 Gauss–Seidel sweeps, 160 at ω = 1.2, 47 at 1.8; `BENCHMARKS.md`, "SOR by
/// default").
///
/// Why it converges: with reciprocal form factors (`A_i F_ij = A_j F_ji`), row `i` of `I − ρF` times
/// `A_i / ρ_i` gives a symmetric matrix, strictly diagonally dominant for `ρ < 1`, so positive definite,
/// and SOR (pointwise or by blocks, which row scaling does not change) converges for every `0 < ω < 2`
/// (Ostrowski–Reich). The hierarchy's links are reciprocal only to within their form factors' error,
/// and a patch's step is one gather rather than an exact block solve, so beyond the bound
/// `2 / (1 + ρ_max)` that holds for any `I − ρF` (an H-matrix whose Jacobi matrix has spectral radius
/// at most `ρ_max`) convergence is what the measurements show; a sweep sequence that grows is caught
/// as for every solver (`solvers::DIVERGING_SWEEPS`). The command line's default solver: at the held-out
/// scenes' points its RMS error is Gauss–Seidel's within 0.05 points (`BENCHMARKS.md`, "SOR by
/// default").
#[derive(Debug, Default)]
pub struct OverRelaxed {
    relaxation: std::sync::Mutex<Relaxation>,
}

/// The smallest `ω` of [`OverRelaxed`]: on the classroom 1.1, 1.15 and 1.2 took 21, 19 and 16 sweeps
/// where Gauss–Seidel takes 24, and 1.4 overshot (25). Young's formula for Gauss–Seidel's rate there
/// (0.46 a sweep) gives 1.15, a little under the best measured; from SOR's own sweeps
/// [`Relaxation::observe`] settles at 1.2026.
pub const OVER_RELAXATION: f64 = 1.2;

/// The largest `ω` the estimate may set: the best measured for a closed box of reflectance 0.98 (47
/// sweeps; 1.6: 64), with room below 2, where SOR stops converging.
pub const MAX_OVER_RELAXATION: f64 = 1.8;

/// What [`OverRelaxed`] has seen of its sweeps: the total exitant power after the last, the change of
/// the one before, the ratio of the last two changes, and the `ω` in use.
#[derive(Debug)]
struct Relaxation {
    omega: f64,
    power: Option<f64>,
    change: Option<f64>,
    ratio: Option<f64>,
}

impl Default for Relaxation {
    fn default() -> Self {
        Relaxation {
            omega: OVER_RELAXATION,
            power: None,
            change: None,
            ratio: None,
        }
    }
}

impl Relaxation {
    fn omega(&self) -> f64 {
        self.omega
    }

    /// Takes the total exitant power after a sweep and sets the next sweep's `ω` (Young's adaptive
    /// SOR, as in Hageman and Young 1981, ch. 9): once two successive ratios `λ` of the power's changes
    /// agree within [`STEADY_RATIO`] (the iteration's slowest mode has taken over, not a refinement's
    /// transient), the Jacobi spectral radius `μ` follows from SOR's eigenvalue relation
    /// `(λ + ω − 1)² = λ ω² μ²`, and the best `ω` for it is `2 / (1 + √(1 − μ²))`, kept within
    /// [`OVER_RELAXATION`] and [`MAX_OVER_RELAXATION`]. At or past the best `ω`, `λ = ω − 1` and the
    /// relation returns `ω` itself, so the estimate does not creep up. The theory assumes a
    /// consistently ordered matrix, which a room's is not; it is what fits the measurements (module
    /// documentation of [`OverRelaxed`]). Every value comes from totals summed in patch order, so `ω`
    /// does not depend on the thread count.
    fn observe(&mut self, power: f64) {
        let omega = self.omega();
        let change = self.power.map(|last| (power - last).abs());
        let ratio = match (change, self.change) {
            (Some(c), Some(last)) if last > 0.0 => Some(c / last),
            _ => None,
        };
        if let (Some(r), Some(last)) = (ratio, self.ratio) {
            let steady = (r - last).abs() <= STEADY_RATIO * r.max(last);
            if steady && r > 0.0 && r < 1.0 && last < 1.0 {
                let lambda = (r * last).sqrt();
                let mu_squared =
                    ((lambda + omega - 1.0).powi(2) / (lambda * omega * omega)).min(1.0);
                let best = 2.0 / (1.0 + (1.0 - mu_squared).sqrt());
                self.omega = best.clamp(OVER_RELAXATION, MAX_OVER_RELAXATION);
            }
        }
        self.power = Some(power);
        self.change = change;
        self.ratio = ratio;
    }
}

/// How far apart, relative to the larger, two successive ratios of power changes may be and still be
/// read as one steady rate ([`Relaxation::observe`]).
const STEADY_RATIO: f64 = 0.2;

impl GatheringSolver for OverRelaxed {
    fn name(&self) -> &'static str {
        "sor"
    }

    fn sweep(&self, hierarchy: &mut Hierarchy, plan: &SweepPlan) -> Sweep {
        let mut relaxation = self
            .relaxation
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner());
        let omega = relaxation.omega();
        let totals = sweep_in_order(hierarchy, plan, |hierarchy, mut update, totals| {
            let size = hierarchy.basis_size();
            for (&id, step) in update
                .elements
                .iter()
                .zip(update.radiance.chunks_exact_mut(size))
            {
                for (n, &o) in step.iter_mut().zip(hierarchy.radiance(id)) {
                    *n = o + (*n - o) * omega;
                }
            }
            update.apply(hierarchy);
            // What the patch's leaves now send (the step's own total is Gauss–Seidel's); the absorbed
            // power is the step's, exact at the fixed point.
            totals.exitant += (update.elements.iter())
                .filter(|&&id| hierarchy.element(id).is_leaf())
                .map(|&id| leaf_exitant(hierarchy, id))
                .sum::<Rgb>();
            totals.absorbed += update.absorbed;
        });
        relaxation.observe(totals.exitant.r + totals.exitant.g + totals.exitant.b);
        totals
    }
}

/// Southwell iteration over patches (block Southwell relaxation): each sweep relaxes every patch once,
/// in decreasing order of its residual, estimated by the power change π A |ΔL| (largest channel) of its
/// update in the previous sweep, so that the patches whose radiance is furthest from converged are
/// updated first and the others already see their new values.
#[derive(Debug, Default)]
pub struct Southwell {
    residuals: std::sync::Mutex<Vec<f64>>,
}

impl GatheringSolver for Southwell {
    fn name(&self) -> &'static str {
        "southwell"
    }

    fn sweep(&self, hierarchy: &mut Hierarchy, plan: &SweepPlan) -> Sweep {
        let patches = hierarchy.patches.len();
        let mut residuals = self
            .residuals
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner());
        residuals.resize(patches, f64::INFINITY);
        let mut order: Vec<usize> = (0..patches).collect();
        order.sort_by(|&a, &b| residuals[b].total_cmp(&residuals[a]).then(a.cmp(&b)));
        let clusters = ClusterSweep::planned(hierarchy, &plan.clusters);
        let mut totals = Sweep::default();
        for p in order {
            let update = relax(hierarchy, &clusters, p as u32);
            let root = hierarchy.patches[p].root;
            let before = hierarchy.average_radiance(root);
            apply(hierarchy, &update, &mut totals);
            let after = hierarchy.average_radiance(root);
            let change = Rgb::new(
                (after.r - before.r).abs(),
                (after.g - before.g).abs(),
                (after.b - before.b).abs(),
            );
            residuals[p] = change.max_channel() * PI * hierarchy.element(root).area;
        }
        hierarchy.pull_clusters();
        totals
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::{simulate, SimulationSettings};
    use crate::scene::generators::BoxHall;

    /// Relaxing each run's patches together is Gauss–Seidel's and SOR's sweep bit for bit: the same
    /// radiances as relaxing the patches one at a time, on a clustered hall of boxes whose patches
    /// make runs of several; and no patch of a run reads the radiance of an earlier one of its run.
    #[test]
    fn runs_of_patches_sweep_as_the_patches_one_at_a_time() {
        let settings = SimulationSettings {
            clustering: crate::hierarchy::clusters::ClusteringKind::Oriented,
            max_passes: 1,
            ..Default::default()
        };
        let progress = crate::progress::Progress::new(true);
        let scene = BoxHall::with_polygons(300).scene();
        let solved = simulate(&scene, &settings, &progress).expect("hall");
        let h = &solved.hierarchy;
        assert!(h.root_cluster.is_some(), "the hall was not clustered");
        let plan = SweepPlan::new(h);
        for run in plan.runs(h).runs() {
            for p in run.clone() {
                let (latest, _) = latest_earlier_source(h, h.patches[p as usize].root, p);
                assert!(
                    latest.is_none_or(|q| q < run.start),
                    "patch {p} of run {run:?} reads patch {latest:?}"
                );
            }
        }
        let longest = plan.runs(h).runs().map(|r| r.len()).max().unwrap_or(0);
        assert!(longest > 1, "no run holds more than one patch");
        let one_by_one = SweepPlan {
            clusters: ClusterPlan::new(h),
            runs: PatchRuns {
                starts: (0..=h.patches.len() as u32).collect(),
            }
            .into(),
        };
        let swept = |plan: &SweepPlan, solver: &dyn GatheringSolver| {
            let mut h = h.clone();
            for _ in 0..3 {
                solver.sweep(&mut h, plan);
            }
            h.radiance_coefficients().to_vec()
        };
        let differing = |a: Vec<Rgb>, b: Vec<Rgb>| a.iter().zip(&b).filter(|(x, y)| x != y).count();
        let gauss_seidel = differing(swept(&plan, &GaussSeidel), swept(&one_by_one, &GaussSeidel));
        let sor = differing(
            swept(&plan, &OverRelaxed::default()),
            swept(&one_by_one, &OverRelaxed::default()),
        );
        assert_eq!(
            (gauss_seidel, sor),
            (0, 0),
            "coefficients that differ (Gauss–Seidel, SOR)"
        );
    }

    /// The rate `λ` at which SOR with `omega` shrinks the error of a consistently ordered system whose
    /// Jacobi matrix has spectral radius `mu`, below the best `ω`: the larger root of
    /// `(λ + ω − 1)² = λ ω² μ²` (Young's relation).
    fn sor_rate(omega: f64, mu: f64) -> f64 {
        let b = omega * mu;
        let root = (b + (b * b - 4.0 * (omega - 1.0)).sqrt()) / 2.0;
        root * root
    }

    /// Feeds `relaxation` the total powers of `sweeps` sweeps whose changes shrink by the rate SOR has
    /// at each sweep's `ω`.
    fn feed(relaxation: &mut Relaxation, mu: f64, sweeps: usize) {
        let (mut power, mut change) = (relaxation.power.unwrap_or(0.0), 1.0);
        for _ in 0..sweeps {
            power += change;
            relaxation.observe(power);
            let omega = relaxation.omega();
            let best = 2.0 / (1.0 + (1.0 - mu * mu).sqrt());
            change *= if omega < best {
                sor_rate(omega, mu)
            } else {
                omega - 1.0
            };
        }
    }

    /// From the powers of a system with a known `μ`, the estimate finds the best `ω`,
    /// `2 / (1 + √(1 − μ²))`, and stays there; below [`OVER_RELAXATION`]'s `ω` it keeps that floor, and
    /// a bright room's is held to [`MAX_OVER_RELAXATION`].
    #[test]
    fn the_relaxation_factor_is_the_best_for_the_rate_the_sweeps_show() {
        for mu in [0.5, 0.8, 0.95, 0.97, 0.995] {
            let mut relaxation = Relaxation::default();
            feed(&mut relaxation, mu, 12);
            let best = 2.0 / (1.0 + (1.0 - mu * mu).sqrt());
            let expected = best.clamp(OVER_RELAXATION, MAX_OVER_RELAXATION);
            assert!(
                (relaxation.omega() - expected).abs() < 1e-9,
                "μ = {mu}: ω {} against {expected}",
                relaxation.omega()
            );
        }
    }

    /// A refinement between passes makes one large change: neither it nor the first ratio after it
    /// moves `ω`, since two successive ratios must agree first.
    #[test]
    fn a_jump_in_power_does_not_move_the_relaxation_factor() {
        let mut relaxation = Relaxation::default();
        for power in [1.0, 1.5, 1.75, 10.0, 10.5, 10.6] {
            relaxation.observe(power);
        }
        assert_eq!(relaxation.omega(), OVER_RELAXATION);
    }
}
