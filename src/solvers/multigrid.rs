//! Progressive multi-gridding (Sillion–Drettakis §6.2): instead of one refinement at the final
//! threshold, whose cost nobody can predict, a sequence of steps, each creating at most `K` links
//! (`--link-budget`) and then gathering, so that a usable solution comes early and every step costs
//! about the same.
//!
//! The budget is charged by the work a refinement creates, not by the refinements: each refined link
//! costs the links it creates ([`crate::solvers::refine::links_created`]: four for a surface split, a
//! cluster's children for a cluster split), every one of which is judged by the oracle and coupled.
//! Counting refinements instead made steps that split clusters (up to eight children, each link a
//! cluster coupling with its visibility samples and item buffers) 5–8× slower than steps that split
//! surfaces (BENCHMARKS.md, classroom).
//!
//! The paper records a histogram of the links' error bounds during refinement and picks the next
//! threshold so that the bins above it hold at most `k` links. Here the histogram is taken during the
//! first round of each step's refinement, from the very estimates that round compares with the
//! thresholds (the oracles' cached factors times the radiance just gathered, `solvers::refine`), so the
//! promise is exact rather than ignoring "the increase in radiosity values due to the previous gathering
//! step" (§6.2, footnote 7): a step creates at most `K` links. Refinements are taken by decreasing
//! error while their cost fits what is left of the budget; one that does not fit waits for a later
//! step (it is counted as deferred), and one that costs more than the whole budget is charged the whole
//! budget (it then makes a step alone).
//!
//! Step 1 is the coarse solution: the initial links (or, with clustering, the root cluster's self-link
//! split down to links between siblings) all admissible. Each later step's threshold τ is the lower
//! edge of the lowest log-spaced bin that keeps the count at or under `K`; a link is refined when its
//! error is above its own threshold (the target ε, or error control's per-element threshold) and in a
//! bin at or above τ's. Thresholds never rise: when the gathered radiance lifted more than `K` links
//! above the previous τ, τ stays and the `K` largest errors are refined (the rest are reported as
//! deferred). Steps go on until the target is reached (no link above its own threshold, or error
//! control's accuracy), a budget stops refinement, or `max_steps`.

use super::refine::{initial_candidates, Judged, RefinementSchedule, Start};
use super::{
    end_pass, finish_report, refine_pass, start_report, sweep_to_tolerance, SolveReport,
    SolveSettings,
};
use crate::hierarchy::Hierarchy;
use crate::measures::stats::cpu_seconds;
use crate::oracles::RefinementOracle;
use crate::progress::Progress;
use crate::solvers::gathering::GatheringSolver;
use crate::visibility::Visibility;
use serde::Serialize;
use std::collections::BTreeMap;
use std::time::Instant;

/// Histogram bins per decade of link error.
pub const BINS_PER_DECADE: f64 = 16.0;

/// What progressive multi-gridding is asked for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct MultigridSettings {
    /// Most links one step's refinements create (the paper's `k`, in units of work).
    pub link_budget: usize,
    /// Most steps.
    pub max_steps: usize,
}

/// What one step did.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct StepReport {
    /// 1 for the coarse solution.
    pub step: usize,
    /// The step's threshold τ, in the oracle's units: links with a larger error (and above their own
    /// threshold) were refined. ∞ for the coarse step, 0 once every link above its own threshold fits
    /// the budget (the target).
    pub threshold: f64,
    /// Links above their own threshold when the step started: the histogram's population.
    pub above_target: usize,
    /// Links the histogram chose to refine in the step's first round.
    pub selected: usize,
    /// Links above τ left for a later step because more than the budget were (see the module comment).
    pub deferred: usize,
    /// Links refinement refined (`selected` less any the element budget refused).
    pub refined_links: usize,
    /// Links the step's refinements created, as charged to the budget (at most the budget; the
    /// coarse step's are not charged).
    pub created_links: usize,
    pub links: usize,
    pub elements: usize,
    pub leaves: usize,
    /// Gathering sweeps of the step.
    pub sweeps: usize,
    /// Whether they met the tolerance (false: they stopped at the iteration limit).
    pub swept_to_tolerance: bool,
    /// Power absorbed by the leaves after the step's last sweep (W per channel).
    pub absorbed_power: crate::color::Rgb,
    /// Wall-clock seconds of the step's refinement, gathering and error estimate.
    pub seconds: f64,
    /// CPU seconds of the process (all threads) over the same span.
    pub cpu_seconds: f64,
}

/// Links created by refining the links of each error bin (each link weighted by its cost), in
/// log-spaced bins: bin `b` holds errors in [10^(b/B), 10^((b+1)/B)) with `B` = [`BINS_PER_DECADE`];
/// non-finite errors (a link that must split) go to the top bin.
#[derive(Clone, Debug, Default)]
pub struct ErrorHistogram {
    counts: BTreeMap<i32, usize>,
}

/// The bin below every real one: a cut there refines every link in the histogram.
const EVERYTHING: i32 = i32::MIN;

impl ErrorHistogram {
    pub fn bin(error: f64) -> i32 {
        if error.is_nan() || error == f64::INFINITY {
            i32::MAX
        } else {
            ((error.log10() * BINS_PER_DECADE).floor() as i32).max(EVERYTHING + 1)
        }
    }

    /// Counts a link of error `error` whose refinement creates `cost` links.
    pub fn add(&mut self, error: f64, cost: usize) {
        *self.counts.entry(Self::bin(error)).or_default() += cost;
    }

    pub fn total(&self) -> usize {
        self.counts.values().sum()
    }

    /// Created links in bin `from` and above.
    pub fn count_from(&self, from: i32) -> usize {
        self.counts.range(from..).map(|(_, n)| n).sum()
    }

    /// Links predicted to be created by refining every link at or above `cut` down to its lower edge
    /// τ: a link of error `e` ≥ τ becomes a quadtree of links whose errors fall about fourfold per
    /// split, about `e / τ` times its own cost in all (§6.2, footnote 7's linear factor), taken at each
    /// bin's lower edge.
    pub fn predicted_refinements(&self, cut: i32) -> f64 {
        self.counts
            .range(cut..)
            .map(|(&bin, &n)| {
                // A link that must split (infinite error) has no size to fall by: its own cost.
                if bin == i32::MAX {
                    return n as f64;
                }
                let levels = (i64::from(bin) - i64::from(cut)) as f64 / BINS_PER_DECADE;
                n as f64 * 10f64.powf(levels.min(300.0))
            })
            .sum()
    }

    /// The cut that fills a step's `budget`: the highest bin whose predicted refinements reach it (the
    /// lowest bin when all of them together do not; [`EVERYTHING`] when there are none). The step then
    /// refines the largest errors first and stops at the budget.
    pub fn cut(&self, budget: usize) -> i32 {
        self.counts
            .keys()
            .rev()
            .find(|&&bin| self.predicted_refinements(bin) >= budget as f64)
            .or(self.counts.keys().next())
            .copied()
            .unwrap_or(EVERYTHING)
    }

    /// The lower edge of bin `cut`: 0 for [`EVERYTHING`], ∞ for the top bin of non-finite errors.
    pub fn threshold(cut: i32) -> f64 {
        match cut {
            EVERYTHING => 0.0,
            i32::MAX => f64::INFINITY,
            bin => 10f64.powf(f64::from(bin) / BINS_PER_DECADE),
        }
    }
}

/// The refinement schedule of one step (see the module comment).
struct StepSchedule {
    budget: usize,
    coarse: bool,
    /// The previous step's cut: thresholds never rise.
    cap: i32,
    cut: i32,
    /// Links the step's refinements may still create.
    remaining: usize,
    /// Links the step's refinements create (charged against the budget after the coarse step).
    created: usize,
    above_target: usize,
    selected: usize,
    deferred: usize,
}

impl StepSchedule {
    fn start(&mut self, coarse: bool) {
        self.coarse = coarse;
        if coarse {
            self.cut = i32::MAX;
        }
        self.remaining = self.budget;
        (
            self.above_target,
            self.selected,
            self.deferred,
            self.created,
        ) = (0, 0, 0, 0);
    }
}

impl StepSchedule {
    /// What refining `j` is charged: the links it creates, at most the whole budget.
    fn charge(&self, j: &Judged) -> usize {
        j.cost.clamp(1, self.budget)
    }
}

impl RefinementSchedule for StepSchedule {
    fn select(&mut self, round: usize, judged: &mut [Judged]) {
        if self.coarse {
            // Only cluster self-links split (error ∞, the top bin): links between a cluster's parts.
            for j in judged.iter_mut() {
                j.refine &= j.error == f64::INFINITY;
                if j.refine {
                    self.created += j.cost;
                }
            }
            return;
        }
        if round == 1 {
            let mut histogram = ErrorHistogram::default();
            for j in judged.iter().filter(|j| j.refine) {
                histogram.add(j.error, self.charge(j));
            }
            self.cut = histogram.cut(self.budget).min(self.cap);
            self.above_target = judged.iter().filter(|j| j.refine).count();
        }
        // Links at or above the cut, the largest errors first, while their cost fits the budget.
        let mut above: Vec<usize> = (0..judged.len())
            .filter(|&i| judged[i].refine && ErrorHistogram::bin(judged[i].error) >= self.cut)
            .collect();
        above.sort_by(|&a, &b| judged[b].error.total_cmp(&judged[a].error).then(a.cmp(&b)));
        for j in judged.iter_mut() {
            j.refine = false;
        }
        let mut chosen = 0;
        for i in above {
            let cost = self.charge(&judged[i]);
            if cost <= self.remaining {
                self.remaining -= cost;
                self.created += cost;
                judged[i].refine = true;
                chosen += 1;
            } else {
                self.deferred += 1;
            }
        }
        if round == 1 {
            self.selected = chosen;
        }
    }
}

/// Hierarchical radiosity by progressive multi-gridding: like [`super::solve`], but each pass is a
/// step that refines at most `multigrid.link_budget` links; `on_step` sees the solution after every
/// step that changed it (an image per step, `render --progressive`), and its error ends the solve.
#[allow(clippy::too_many_arguments)]
pub fn solve_progressive(
    hierarchy: &mut Hierarchy,
    visibility: &dyn Visibility,
    oracle: &dyn RefinementOracle,
    solver: &dyn GatheringSolver,
    settings: &SolveSettings,
    multigrid: &MultigridSettings,
    progress: &Progress,
    on_step: &mut dyn FnMut(&StepReport, &Hierarchy) -> anyhow::Result<()>,
) -> anyhow::Result<SolveReport> {
    anyhow::ensure!(
        multigrid.link_budget >= 1,
        "the link budget must be at least 1"
    );
    let mut report = start_report(hierarchy, settings);
    report.error.stopped_by = "step limit".into();
    let mut schedule = StepSchedule {
        budget: multigrid.link_budget,
        coarse: true,
        cap: i32::MAX,
        cut: i32::MAX,
        remaining: 0,
        created: 0,
        above_target: 0,
        selected: 0,
        deferred: 0,
    };
    for step in 1..=multigrid.max_steps.max(1) {
        let (start, cpu_start) = (Instant::now(), cpu_seconds());
        report.passes = step;
        let from = if step == 1 {
            Start::Initial(initial_candidates(hierarchy))
        } else {
            Start::StoredLinks
        };
        schedule.start(step == 1);
        let (outcome, direct) = refine_pass(
            hierarchy,
            visibility,
            oracle,
            settings,
            from,
            &mut report,
            progress,
            &format!("step {step}"),
            Some(&mut schedule),
        );
        let sweeps_before = report.iterations;
        let swept = sweep_to_tolerance(
            hierarchy,
            solver,
            settings,
            settings.tolerance,
            &mut report,
            progress,
            step,
        );
        let changed =
            step == 1 || outcome.subdivisions + direct.subdivisions + outcome.refined_links > 0;
        let refused = outcome.refused_by_budget + direct.refused_by_budget > 0;
        // Error control lowers thresholds only once no link is left above its own: a leaf whose links
        // wait for a later step fails for want of refinement, not of a lower threshold.
        let settled = schedule.above_target == 0 && !schedule.coarse;
        let stop = end_pass(
            hierarchy,
            settings,
            &mut report,
            (changed, settled),
            refused,
            swept,
            progress,
        );
        let threshold = if step == 1 {
            f64::INFINITY
        } else {
            ErrorHistogram::threshold(schedule.cut)
        };
        if !schedule.coarse {
            schedule.cap = schedule.cut;
        }
        if changed {
            let step_report = StepReport {
                step,
                threshold,
                above_target: schedule.above_target,
                selected: schedule.selected,
                deferred: schedule.deferred,
                refined_links: outcome.refined_links,
                created_links: schedule.created,
                links: hierarchy.link_count(),
                elements: hierarchy.elements.len(),
                leaves: hierarchy.leaf_count(),
                sweeps: report.iterations - sweeps_before,
                swept_to_tolerance: swept,
                absorbed_power: report.absorbed_power,
                seconds: start.elapsed().as_secs_f64(),
                cpu_seconds: cpu_seconds() - cpu_start,
            };
            on_step(&step_report, hierarchy)?;
            report.steps.push(step_report);
        }
        if stop {
            break;
        }
    }
    finish_report(hierarchy, settings, &mut report);
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The cut is the highest bin whose predicted refinements fill the budget.
    #[test]
    fn histogram_cut_fills_the_budget() {
        let mut h = ErrorHistogram::default();
        for e in [1e-3, 2e-3, 1e-2, 1e-2, 0.5, f64::INFINITY] {
            h.add(e, 1);
        }
        assert_eq!(ErrorHistogram::default().cut(3), EVERYTHING);
        for budget in 1..1000 {
            let cut = h.cut(budget);
            let lowest = *h.counts.keys().next().unwrap();
            assert!(h.predicted_refinements(cut) >= budget as f64 || cut == lowest);
            let above_cut = (std::ops::Bound::Excluded(cut), std::ops::Bound::Unbounded);
            if let Some((&above, _)) = h.counts.range(above_cut).next() {
                assert!(h.predicted_refinements(above) < budget as f64);
            }
        }
        assert_eq!(ErrorHistogram::bin(1.0), 0);
        assert_eq!(ErrorHistogram::bin(10.0), 16);
    }

    /// A link that must split (infinite error) predicts its own cost, not `10^300` refinements: with
    /// one in the histogram every cut used to "fill" any budget, the cut stayed at the previous
    /// step's, and the classroom's steps made 20k, 9.6k and 2.7k links of a 20k budget.
    #[test]
    fn links_that_must_split_do_not_hold_the_cut_up() {
        let mut finite = ErrorHistogram::default();
        for k in 0..1000 {
            finite.add(1e-3 * (1.0 + k as f64 / 100.0), 4);
        }
        let mut with_split = finite.clone();
        with_split.add(f64::INFINITY, 8);
        for &bin in finite.counts.keys() {
            let (a, b) = (
                finite.predicted_refinements(bin),
                with_split.predicted_refinements(bin),
            );
            assert_eq!(b, a + 8.0, "bin {bin}");
        }
        // So the cut is the finite links' cut for what the split link leaves of the budget.
        for budget in [100, 1000, 4000, 100_000] {
            assert_eq!(
                with_split.cut(budget),
                finite.cut(budget - 8),
                "budget {budget}"
            );
        }
    }
}
