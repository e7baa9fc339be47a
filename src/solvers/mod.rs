//! Solvers: hierarchical radiosity as alternating refinement ([`refine`], driven by an oracle) and
//! gathering sweeps ([`gathering`]: Jacobi or Gauss–Seidel, with [`push_pull`]) until the refinement
//! is stable and the total power has converged. Link form factors come from [`coupling`]. Hierarchical
//! Monte Carlo radiosity ([`stochastic`]) replaces links by power-carrying random lines.

pub mod clustering;
pub mod coupling;
pub mod direct;
pub mod error_estimate;
pub mod gathering;
pub mod multigrid;
pub mod push_pull;
pub mod refine;
pub mod stochastic;

use crate::color::Rgb;
use crate::hierarchy::{ElementId, Hierarchy};
use crate::oracles::RefinementOracle;
use crate::progress::Progress;
use crate::random::splitmix64;
use crate::visibility::Visibility;
use error_estimate::{estimate_errors, summarize, ErrorSummary, EstimateKind};
use gathering::GatheringSolver;
use rand::SeedableRng;
use rand_pcg::Pcg64Mcg;
use refine::{
    initial_candidates, refine_scheduled, RefineOutcome, RefineSettings, RefinementSchedule, Start,
};
use serde::Serialize;
use std::f64::consts::PI;
use std::time::Instant;

/// Random numbers for one link: the stream depends only on the seed and the link's identity, never on
/// which thread evaluates it.
pub fn link_rng(seed: u64, receiver: ElementId, source: ElementId, stream: u64) -> Pcg64Mcg {
    let key = ((receiver as u64) << 32) | source as u64;
    Pcg64Mcg::seed_from_u64(splitmix64(seed ^ splitmix64(key ^ splitmix64(stream))))
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
    /// The a-posteriori estimate computed after each pass (and used by error control).
    pub estimate: EstimateKind,
    /// Error control (Bekaert–Willems algorithm 6.1), with any oracle: the link error oracle compares
    /// its links' error with their receivers' thresholds (radiance), the others their estimates with
    /// them when `refine.receiver_thresholds` is set (radiance × area, starting at `refine.threshold`).
    pub error_control: Option<ErrorControl>,
}

/// What error control aims at (Bekaert–Willems §6).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct ErrorControl {
    /// Largest acceptable absolute radiance error ε, W/(m² sr).
    pub accuracy: f64,
    /// Also at most this fraction of each leaf's own radiance (`--local-accuracy`), never below
    /// [`LOCAL_ACCURACY_FLOOR`] of ε; `None`: ε alone, as algorithm 6.1.
    pub local: Option<f64>,
    /// Factor by which a leaf's link error threshold falls after a pass that left its estimate above
    /// ε (the paper uses 1.4).
    pub threshold_factor: f64,
}

/// The lowest a local accuracy takes a leaf's target, as a fraction of the absolute accuracy ε: a leaf
/// in near darkness would otherwise be refined toward an error of nothing.
pub const LOCAL_ACCURACY_FLOOR: f64 = 0.1;

impl ErrorControl {
    /// The largest estimate leaf `id` may keep: [`allowed_error`] at its average radiance.
    pub fn allowed(&self, h: &Hierarchy, id: ElementId) -> f64 {
        allowed_error(
            self.accuracy,
            self.local,
            h.average_radiance(id).max_channel(),
        )
    }
}

/// The error error control accepts where the radiance is `radiance` (largest channel, the estimate's):
/// the absolute accuracy ε, or with a local accuracy `p` `min(ε, max(p L, ε · LOCAL_ACCURACY_FLOOR))`.
/// Algorithm 6.1 bounds the absolute error everywhere alike, which lets dim surfaces (the ceiling above
/// a lamp housing, a corner) keep errors of half their radiance where the scene's mean radiance sets ε;
/// a relative error bar per leaf asks for more there.
pub fn allowed_error(accuracy: f64, local: Option<f64>, radiance: f64) -> f64 {
    local.map_or(accuracy, |fraction| {
        accuracy.min((fraction * radiance).max(accuracy * LOCAL_ACCURACY_FLOOR))
    })
}

/// How a solve under error control ended.
#[derive(Clone, Debug, Default, Serialize)]
pub struct ErrorReport {
    /// The accuracy asked for (absolute radiance); `None` without error control.
    pub accuracy: Option<f64>,
    /// The local accuracy asked for, a fraction of each leaf's radiance ([`ErrorControl::allowed`]).
    pub local_accuracy: Option<f64>,
    pub estimate: Option<EstimateKind>,
    /// The estimate over the leaves after the last pass.
    pub summary: ErrorSummary,
    /// Why refinement stopped: "accuracy reached", "element budget", "minimum element area", "the
    /// splittable rest under 0.1% of the area", "pass limit", "stable", "diverging sweeps".
    pub stopped_by: String,
    /// The estimate after each refine/solve pass: how error control (or refinement) progressed, and
    /// what each pass cost.
    pub passes: Vec<PassEstimate>,
}

/// The a-posteriori estimate over the leaves after one pass, with the hierarchy's size and the time
/// spent so far.
#[derive(Clone, Debug, Default, Serialize)]
pub struct PassEstimate {
    pub pass: usize,
    pub links: usize,
    /// The estimate's summary against the accuracy (against ∞ without error control: no leaf above).
    pub summary: ErrorSummary,
    /// Refinement, sweep and estimate seconds of the solve up to the end of this pass.
    pub refine_seconds: f64,
    pub solve_seconds: f64,
    pub estimate_seconds: f64,
}

/// What a solve did.
#[derive(Clone, Debug, Default, Serialize)]
pub struct SolveReport {
    pub passes: usize,
    pub iterations: usize,
    pub oracle_rays: u64,
    pub form_factor_rays: u64,
    /// Shaft tests of surface links and the coupling rays their Clear or Blocked verdicts made
    /// unnecessary (`--visibility-reuse shaft`).
    pub shaft_tests: u64,
    pub rays_saved: u64,
    /// Power-carrying lines of Monte Carlo radiosity ([`stochastic`]).
    pub shooting_rays: u64,
    pub emitted_power: Rgb,
    /// What the reflecting surfaces absorb ([`crate::measures::stats::RunStats::absorbed_power`]).
    pub absorbed_power: Rgb,
    pub exitant_power: Rgb,
    pub refine_seconds: f64,
    pub solve_seconds: f64,
    /// The a-posteriori estimates after the passes (Bekaert–Willems §4).
    pub estimate_seconds: f64,
    /// Whether the last pass refined (almost) nothing, fewer than [`SETTLED_FRACTION`] of the links,
    /// and the sweeps met the tolerance (under error control: whether every leaf's estimate is within
    /// the accuracy).
    pub converged: bool,
    /// Relative change of the total exitant power after each sweep (the residual of the iteration).
    pub residuals: Vec<f64>,
    /// The pass whose sweeps diverged, if one did ([`DIVERGING_SWEEPS`]): the solve stops there.
    pub diverged_in_pass: Option<usize>,
    /// The a-posteriori error estimate and, under error control, how it ended.
    pub error: ErrorReport,
    /// Splits refused because the element budget was reached.
    pub refused_by_budget: usize,
    /// Progressive multi-gridding's steps (empty for a one-shot solve).
    pub steps: Vec<multigrid::StepReport>,
}

/// Total self-emitted power Σ π A E of the patches plus the luminaires' flux.
pub fn emitted_power(hierarchy: &Hierarchy) -> Rgb {
    let patches: Rgb = hierarchy
        .patches
        .iter()
        .map(|p| p.emission * (PI * hierarchy.element(p.root).area))
        .sum();
    patches + hierarchy.luminaires.iter().map(|l| l.power()).sum::<Rgb>()
}

/// Hierarchical radiosity: refine with `oracle`, sweep with `solver` to convergence, re-refine with the
/// new radiance, until refinement (almost: [`SETTLED_FRACTION`]) stops changing the hierarchy.
pub fn solve(
    hierarchy: &mut Hierarchy,
    visibility: &dyn Visibility,
    oracle: &dyn RefinementOracle,
    solver: &dyn GatheringSolver,
    settings: &SolveSettings,
    progress: &Progress,
) -> SolveReport {
    let mut report = start_report(hierarchy, settings);
    report.error.stopped_by = "pass limit".into();
    // Passes that may be followed by another sweep to a looser tolerance: the refinement after them
    // (and error control's thresholds) needs the radiance to about a part in a thousand, and changes it
    // by more.
    let pass_tolerance = settings.tolerance.max(INTERMEDIATE_TOLERANCE);
    for pass in 1..=settings.max_passes.max(1) {
        report.passes = pass;
        // Later passes re-judge every link with the new radiance; the links stay in the hierarchy
        // whenever the loop ends.
        let from = if pass == 1 {
            Start::Initial(initial_candidates(hierarchy))
        } else {
            Start::StoredLinks
        };
        let (outcome, direct) = refine_pass(
            hierarchy,
            visibility,
            oracle,
            settings,
            from,
            &mut report,
            progress,
            &format!("pass {pass}"),
            None,
        );
        let swept_to_tolerance = sweep_to_tolerance(
            hierarchy,
            solver,
            settings,
            pass_tolerance,
            &mut report,
            progress,
            pass,
        );
        let refined = outcome.subdivisions + direct.subdivisions + outcome.refined_links;
        let changed = refined as f64 > SETTLED_FRACTION * hierarchy.link_count() as f64;
        let refused = outcome.refused_by_budget + direct.refused_by_budget > 0;
        let pass_state = (changed || pass == 1, true);
        if end_pass(
            hierarchy,
            settings,
            &mut report,
            pass_state,
            refused,
            swept_to_tolerance,
            progress,
        ) {
            break;
        }
    }
    if pass_tolerance > settings.tolerance && report.diverged_in_pass.is_none() {
        // The last pass's radiance, to the tolerance asked for, and its estimate again.
        let last = report.passes;
        report.converged &= sweep_to_tolerance(
            hierarchy,
            solver,
            settings,
            settings.tolerance,
            &mut report,
            progress,
            last,
        );
        timed_estimate(
            hierarchy,
            settings,
            &mut report,
            progress,
            "after the last sweeps",
        );
        if let Some(control) = &settings.error_control {
            // The summary the user reads is the final radiance's; a pass judged at a part in a
            // thousand may have passed a leaf that the last sweeps move over the accuracy.
            report.error.summary = summarize(
                hierarchy,
                |id| control.allowed(hierarchy, id),
                settings.refine.min_area,
            );
            if let Some(last) = report.error.passes.last_mut() {
                last.summary = report.error.summary;
                last.solve_seconds = report.solve_seconds;
                last.estimate_seconds = report.estimate_seconds;
            }
            if report.error.summary.leaves_above > 0 && report.error.stopped_by == ACCURACY_REACHED
            {
                report.error.stopped_by = "accuracy reached before the last sweeps".into();
            }
        }
    }
    finish_report(hierarchy, settings, &mut report);
    report
}

/// An empty report for a solve of `hierarchy`; under error control the thresholds are initialised.
fn start_report(hierarchy: &mut Hierarchy, settings: &SolveSettings) -> SolveReport {
    let mut report = SolveReport {
        emitted_power: emitted_power(hierarchy),
        ..Default::default()
    };
    report.error.estimate = Some(settings.estimate);
    if let Some(control) = &settings.error_control {
        report.error.accuracy = Some(control.accuracy);
        report.error.local_accuracy = control.local;
        initialise_thresholds(hierarchy, &settings.refine, control.accuracy);
    }
    report
}

/// Without error control, the estimate's summary over every leaf (error control summarises each pass).
fn finish_report(hierarchy: &Hierarchy, settings: &SolveSettings, report: &mut SolveReport) {
    if settings.error_control.is_none() {
        report.error.summary = summarize(hierarchy, |_| f64::INFINITY, settings.refine.min_area);
    }
}

/// The a-posteriori estimate of every element ([`estimate_errors`]) under a spinner saying `when`,
/// its time added to the report's.
fn timed_estimate(
    hierarchy: &mut Hierarchy,
    settings: &SolveSettings,
    report: &mut SolveReport,
    progress: &Progress,
    when: &str,
) {
    let start = Instant::now();
    let spinner = progress.spinner("estimate");
    spinner.set_message(when.to_string());
    estimate_errors(hierarchy, settings.estimate);
    spinner.finish_and_clear();
    report.estimate_seconds += start.elapsed().as_secs_f64();
}

/// After a pass: the a-posteriori estimate, then whether to stop: under error control when the accuracy
/// is reached or the element budget `refused` a split (else, once refinement has `settled` every link
/// at its threshold, the failing leaves' thresholds are lowered), without it when the pass left the
/// hierarchy as it was (`changed` false).
fn end_pass(
    hierarchy: &mut Hierarchy,
    settings: &SolveSettings,
    report: &mut SolveReport,
    (changed, settled): (bool, bool),
    refused: bool,
    swept_to_tolerance: bool,
    progress: &Progress,
) -> bool {
    let after_pass = format!("after pass {}", report.passes);
    timed_estimate(hierarchy, settings, report, progress, &after_pass);
    let control = settings.error_control;
    let summary = summarize(
        hierarchy,
        |id| control.map_or(f64::INFINITY, |c| c.allowed(hierarchy, id)),
        settings.refine.min_area,
    );
    report.error.passes.push(PassEstimate {
        pass: report.passes,
        links: hierarchy.link_count(),
        summary,
        refine_seconds: report.refine_seconds,
        solve_seconds: report.solve_seconds,
        estimate_seconds: report.estimate_seconds,
    });
    if report.diverged_in_pass.is_some() {
        if settings.error_control.is_some() {
            report.error.summary = summary;
        }
        report.error.stopped_by = "diverging sweeps".into();
        return true;
    }
    if let Some(control) = &settings.error_control {
        // The pass's summary is the solve's so far (the same accuracy): one walk over the leaves.
        report.error.summary = summary;
        if report.passes == 1 && !refused {
            // The first pass judged its links by the emitters' light alone, as without error control
            // (which never stops there either): the estimate misses what the next pass refines for the
            // interreflected light (cube.mgf: 169 of 300 seen points within it after pass 1, 298
            // after pass 2).
            if settled {
                lower_thresholds(hierarchy, control, settings.refine.min_area);
            }
            return false;
        }
        if summary.leaves_above == 0 {
            report.converged = swept_to_tolerance;
            report.error.stopped_by = ACCURACY_REACHED.into();
            return true;
        }
        if refused {
            report.error.stopped_by = "element budget".into();
            return true;
        }
        if summary.leaves_above == summary.leaves_above_at_min_area {
            // Every failing leaf is as small as elements get: lowering thresholds further would only
            // split their sources, and their own approximation error would stay.
            report.error.stopped_by = "minimum element area".into();
            return true;
        }
        if summary.area_fraction_above_splittable < NEGLIGIBLE_SPLITTABLE_AREA {
            // The rest would take a pass each for a few leaves (about a tenth of a second to half a
            // second per pass on office3 and the classroom), and change no area average.
            report.error.stopped_by = "the splittable rest under 0.1% of the area".into();
            return true;
        }
        if settled {
            lower_thresholds(hierarchy, control, settings.refine.min_area);
        }
    } else if !changed {
        report.converged = swept_to_tolerance;
        report.error.stopped_by = "stable".into();
        return true;
    }
    false
}

/// One refinement: links by `oracle` (through `schedule`, if any), then the luminaires' first gather;
/// counts and seconds go to `report`.
#[allow(clippy::too_many_arguments)]
fn refine_pass(
    hierarchy: &mut Hierarchy,
    visibility: &dyn Visibility,
    oracle: &dyn RefinementOracle,
    settings: &SolveSettings,
    from: refine::Start,
    report: &mut SolveReport,
    progress: &Progress,
    label: &str,
    schedule: Option<&mut dyn RefinementSchedule>,
) -> (RefineOutcome, direct::DirectOutcome) {
    let start = Instant::now();
    if let Some(buffers) = &hierarchy.item_buffers {
        buffers.forget_unused();
    }
    let spinner = progress.spinner("refine");
    let outcome = refine_scheduled(
        hierarchy,
        visibility,
        oracle,
        &settings.refine,
        from,
        &mut |round, n| spinner.set_message(format!("{label}, round {round}: {n} candidate links")),
        schedule,
    );
    hierarchy.shrink_link_lists();
    crate::memory::return_free_pages();
    clustering::expose(hierarchy, visibility);
    let direct = direct::refine_and_gather(
        hierarchy,
        visibility,
        &settings.refine,
        oracle.judges_couplings(),
    );
    spinner.finish_and_clear();
    report.refine_seconds += start.elapsed().as_secs_f64();
    report.oracle_rays += outcome.oracle_rays;
    report.form_factor_rays += outcome.form_factor_rays + direct.rays;
    report.shaft_tests += outcome.shaft_tests;
    report.rays_saved += outcome.rays_saved;
    report.refused_by_budget += outcome.refused_by_budget + direct.refused_by_budget;
    (outcome, direct)
}

/// Error control ends when the leaves above the accuracy that refinement can still split cover less
/// than this share of the surface area. Algorithm 6.1 would go on until each passes; on office2,
/// office3, the corridor and the classroom at 40% the last three to six passes each split a few of
/// them (under 0.1% of the area in all) at 3–5% of the solve's time a pass (BENCHMARKS.md, "Error
/// control by default"). The summary still counts them as failing.
const NEGLIGIBLE_SPLITTABLE_AREA: f64 = 1e-3;

/// `ErrorReport::stopped_by` when every leaf's estimate is within the accuracy.
const ACCURACY_REACHED: &str = "accuracy reached";

/// A pass without error control that refines fewer than this fraction of the links ends the passes
/// ([`solve`]): the links it still refined crossed their threshold by a small margin as the radiance
/// moved, and the solution's error bound, the sum of its links' (each below ε), changes by about that
/// fraction if the ones the next pass would refine are left (office3 once ran passes 6 to 12 that
/// refined 265, 131, 28, 37, 113, 5 and 0 of 526k links; the built-in Cornell box 3, 3 and 0 of 118k
/// in its last three; BENCHMARKS.md, "Passes that refine under 0.1%").
const SETTLED_FRACTION: f64 = 1e-3;

/// The relative change of the exitant power at which a pass stops sweeping when another pass may
/// follow ([`solve`]); the last sweeps on to `SolveSettings::tolerance`.
const INTERMEDIATE_TOLERANCE: f64 = 1e-3;

/// Sweeps in a row whose change of the total exitant power grew, after which a pass's iteration is
/// taken to diverge: somewhere the scene sends back more light than it receives (two surfaces kept at
/// one place, a reflectance of 1 or more), and more sweeps only make it worse. Converging solves of the
/// Cornell box, cube.mgf, office2, office3 and the classroom, with and without error control, grow
/// for at most 2 sweeps in a row (after a refinement); the classroom's coplanar window sills, kept,
/// grew for more than 100 (BENCHMARKS.md, "Coplanar overlaps").
pub const DIVERGING_SWEEPS: usize = 10;

/// How far past [`runaway_power`] the exitant power may go before a pass is taken to diverge: the
/// discrete system's row sums exceed 1 by a few percent (cubature), which at the largest reflectance
/// can double the geometric series but not multiply it by ten.
pub const RUNAWAY_FACTOR: f64 = 10.0;

/// Exitant power a converging solve of `hierarchy` cannot reach: each watt emitted comes back at most
/// `ρ_max` times per bounce, so what leaves the surfaces sums to at most `Σ_c E_c / (1 − ρ_max,c)` per
/// channel (the white furnace's `E / (1 − ρ)`, which a refined furnace meets). Infinite where a channel
/// of some patch reflects everything or more. A sweep whose total passes [`RUNAWAY_FACTOR`] times this has
/// diverged, even where its change did not grow for [`DIVERGING_SWEEPS`] sweeps in a row (the
/// classroom's progressive step 8 at `--link-budget 20000`: 200 sweeps to 10¹⁹ W without a warning).
pub fn runaway_power(hierarchy: &Hierarchy, emitted: Rgb) -> f64 {
    let rho = (hierarchy.patches.iter()).fold(Rgb::BLACK, |m, p| m.channel_max(p.reflectance));
    std::iter::zip(emitted.to_array(), rho.to_array())
        .map(|(e, r)| match e {
            e if e <= 0.0 => 0.0,
            e if r < 1.0 => e / (1.0 - r),
            _ => f64::INFINITY,
        })
        .sum()
}

/// Sweeps with `solver` until the relative change of the total exitant power is below the tolerance
/// (then returns true), the iteration limit, or [`DIVERGING_SWEEPS`] sweeps of growing change or a
/// total past [`RUNAWAY_FACTOR`] × [`runaway_power`] (then `report.diverged_in_pass` is set). The
/// first sweep of a later pass is compared with the last of the pass before (the same iterate,
/// refined): a pass that changed little ends after one.
fn sweep_to_tolerance(
    hierarchy: &mut Hierarchy,
    solver: &dyn GatheringSolver,
    settings: &SolveSettings,
    tolerance: f64,
    report: &mut SolveReport,
    progress: &Progress,
    pass: usize,
) -> bool {
    let start = Instant::now();
    let bar = progress.bar(settings.max_iterations as u64, "solve");
    let mut previous = if report.iterations > 0 {
        let last = report.exitant_power;
        last.r + last.g + last.b
    } else {
        f64::NAN
    };
    let mut swept_to_tolerance = false;
    // The absolute change (not the relative: a system that diverges as a whole grows by a constant
    // ratio, its relative change tending to a constant) and how many sweeps in a row it grew.
    let (mut last_step, mut growing) = (f64::NAN, 0);
    let runaway = RUNAWAY_FACTOR * runaway_power(hierarchy, report.emitted_power);
    // The links stay as they are until the next refinement.
    let plan = gathering::SweepPlan::new(hierarchy);
    for _ in 0..settings.max_iterations {
        let sweep = solver.sweep(hierarchy, &plan);
        report.iterations += 1;
        report.absorbed_power = sweep.absorbed;
        report.exitant_power = sweep.exitant;
        bar.inc(1);
        let total = sweep.exitant.r + sweep.exitant.g + sweep.exitant.b;
        let change = ((total - previous) / total).abs();
        bar.set_message(format!("pass {pass}: relative power change {change:.2e}"));
        report.residuals.push(change);
        let step = (total - previous).abs();
        growing = if step > last_step { growing + 1 } else { 0 };
        last_step = step;
        previous = total;
        if change < tolerance || total == 0.0 {
            swept_to_tolerance = true;
            break;
        }
        if growing >= DIVERGING_SWEEPS || total > runaway {
            report.diverged_in_pass = Some(pass);
            break;
        }
    }
    bar.finish_and_clear();
    report.solve_seconds += start.elapsed().as_secs_f64();
    swept_to_tolerance
}

/// Algorithm 6.1 step 1b: `Δ_p = (1 − ρ_p) ε − max |δ_e|` on every element, with `δ_e = 0` (emission is
/// constant per patch) and ρ_p the patch's largest channel. With the other oracles
/// (`refine.receiver_thresholds`) the thresholds are in their own units and start at their uniform
/// `refine.threshold` (eq. (1)'s ε), which the later steps lower where the estimate fails.
fn initialise_thresholds(hierarchy: &mut Hierarchy, refine: &RefineSettings, accuracy: f64) {
    for id in 0..hierarchy.elements.len() {
        hierarchy.elements[id].threshold = if refine.receiver_thresholds {
            refine.threshold
        } else {
            let rho = hierarchy.reflectance_of(id as ElementId).max_channel();
            (1.0 - rho).max(0.0) * accuracy
        };
    }
}

/// Extended push-pull, steps 1c and 2f: leaves whose estimate exceeds ε ([`ErrorControl::allowed`])
/// get their threshold divided by the factor, and every inner element takes the smallest threshold
/// below it. Leaves at the minimum area keep theirs: no refinement can help them (they are reported as failing), and lowering their
/// threshold would only drag the links of all their ancestors down.
fn lower_thresholds(hierarchy: &mut Hierarchy, control: &ErrorControl, min_area: f64) {
    fn visit(h: &mut Hierarchy, id: ElementId, control: &ErrorControl, min_area: f64) -> f64 {
        let children = h.elements[id as usize].children.clone();
        if children.is_empty() {
            let allowed = control.allowed(h, id);
            let e = &mut h.elements[id as usize];
            if e.error > allowed && e.area > min_area {
                e.threshold /= control.threshold_factor;
            }
            return e.threshold;
        }
        let lowest = children
            .iter()
            .map(|&c| visit(h, c, control, min_area))
            .fold(f64::INFINITY, f64::min);
        let e = &mut h.elements[id as usize];
        e.threshold = e.threshold.min(lowest);
        e.threshold
    }
    for root in hierarchy.roots() {
        visit(hierarchy, root, control, min_area);
    }
}
