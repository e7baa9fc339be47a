//! Solvers: hierarchical radiosity as alternating refinement ([`refine`], driven by an oracle) and
//! gathering sweeps ([`gathering`]: Jacobi or Gauss–Seidel, with [`push_pull`]) until the refinement
//! is stable and the total power has converged. Link form factors come from [`coupling`]. Hierarchical
//! Monte Carlo radiosity ([`stochastic`]) replaces links by power-carrying random lines.

pub mod coupling;
pub mod gathering;
pub mod push_pull;
pub mod refine;
pub mod stochastic;

use crate::color::Rgb;
use crate::hierarchy::{ElementId, Hierarchy};
use crate::oracles::RefinementOracle;
use crate::progress::Progress;
use crate::visibility::Visibility;
use gathering::GatheringSolver;
use rand::SeedableRng;
use rand_pcg::Pcg64Mcg;
use refine::{initial_candidates, refine, take_links, RefineSettings};
use serde::Serialize;
use std::f64::consts::PI;
use std::time::Instant;

/// Random numbers for one link: the stream depends only on the seed and the link's identity, never on
/// which thread evaluates it.
pub fn link_rng(seed: u64, receiver: ElementId, source: ElementId, stream: u64) -> Pcg64Mcg {
    let key = ((receiver as u64) << 32) | source as u64;
    Pcg64Mcg::seed_from_u64(splitmix64(seed ^ splitmix64(key ^ splitmix64(stream))))
}

/// SplitMix64 finaliser: decorrelates nearby integers into seeds.
pub fn splitmix64(mut x: u64) -> u64 {
    x = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    x = (x ^ (x >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    x ^ (x >> 31)
}

/// Parameters of a hierarchical solve.
#[derive(Clone, Copy, Debug)]
pub struct SolveSettings {
    pub refine: RefineSettings,
    /// Stop sweeping when the relative change of the total exitant power falls below this.
    pub tolerance: f64,
    /// Most sweeps per solve phase.
    pub max_iterations: usize,
    /// Most refine/solve passes (refinement uses the radiance of the previous pass).
    pub max_passes: usize,
}

/// What a solve did.
#[derive(Clone, Debug, Default, Serialize)]
pub struct SolveReport {
    pub passes: usize,
    pub iterations: usize,
    pub oracle_rays: u64,
    pub form_factor_rays: u64,
    /// Power-carrying lines of Monte Carlo radiosity ([`stochastic`]).
    pub shooting_rays: u64,
    pub emitted_power: Rgb,
    pub absorbed_power: Rgb,
    pub exitant_power: Rgb,
    pub refine_seconds: f64,
    pub solve_seconds: f64,
    /// Whether the last pass refined nothing and the sweeps met the tolerance.
    pub converged: bool,
}

/// Total self-emitted power Σ π A E of the patches.
pub fn emitted_power(hierarchy: &Hierarchy) -> Rgb {
    hierarchy
        .patches
        .iter()
        .map(|p| p.emission * (PI * hierarchy.element(p.root).area))
        .sum()
}

/// Hierarchical radiosity: refine with `oracle`, sweep with `solver` to convergence, re-refine with the
/// new radiance, until refinement stops changing the hierarchy.
pub fn solve(
    hierarchy: &mut Hierarchy,
    visibility: &dyn Visibility,
    oracle: &dyn RefinementOracle,
    solver: &dyn GatheringSolver,
    settings: &SolveSettings,
    progress: &Progress,
) -> SolveReport {
    let mut report = SolveReport {
        emitted_power: emitted_power(hierarchy),
        ..Default::default()
    };
    for pass in 1..=settings.max_passes.max(1) {
        report.passes = pass;
        // Later passes re-judge every link with the new radiance; the links stay in the hierarchy
        // whenever the loop ends.
        let candidates = if pass == 1 {
            initial_candidates(hierarchy)
        } else {
            take_links(hierarchy)
        };
        let start = Instant::now();
        let spinner = progress.spinner("refine");
        let outcome = refine(
            hierarchy,
            visibility,
            oracle,
            &settings.refine,
            candidates,
            &mut |round, n| {
                spinner.set_message(format!("pass {pass}, round {round}: {n} candidate links"))
            },
        );
        spinner.finish_and_clear();
        report.refine_seconds += start.elapsed().as_secs_f64();
        report.oracle_rays += outcome.oracle_rays;
        report.form_factor_rays += outcome.form_factor_rays;

        let start = Instant::now();
        let bar = progress.bar(settings.max_iterations as u64, "solve");
        let mut previous = f64::NAN;
        let mut swept_to_tolerance = false;
        for _ in 0..settings.max_iterations {
            let sweep = solver.sweep(hierarchy);
            report.iterations += 1;
            report.absorbed_power = sweep.absorbed;
            report.exitant_power = sweep.exitant;
            bar.inc(1);
            let total = sweep.exitant.r + sweep.exitant.g + sweep.exitant.b;
            let change = ((total - previous) / total).abs();
            bar.set_message(format!("pass {pass}: relative power change {change:.2e}"));
            previous = total;
            if change < settings.tolerance || total == 0.0 {
                swept_to_tolerance = true;
                break;
            }
        }
        bar.finish_and_clear();
        report.solve_seconds += start.elapsed().as_secs_f64();
        if outcome.subdivisions == 0 && outcome.refined_links == 0 && pass > 1 {
            report.converged = swept_to_tolerance;
            break;
        }
    }
    report
}
