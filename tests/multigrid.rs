//! Progressive multi-gridding (Sillion–Drettakis §6.2): the final solution agrees with the one-shot
//! solve at the same threshold within both solutions' own a-posteriori error estimates, every step
//! refines at most the link budget, thresholds never rise, with and without clustering and with every
//! oracle, and the steps do not depend on the thread count.

use radiosity::hierarchy::clusters::ClusteringKind;
use radiosity::hierarchy::Hierarchy;
use radiosity::pipeline::{simulate, Accuracy, OracleKind, SimulationSettings, Solution};
use radiosity::progress::Progress;
use radiosity::scene::cornell::cornell_box;
use radiosity::solvers::multigrid::{MultigridSettings, StepReport};

fn solve(settings: &SimulationSettings) -> Solution {
    simulate(&cornell_box(), settings, &Progress::new(true)).expect("solve")
}

fn progressive(settings: &SimulationSettings, link_budget: usize) -> SimulationSettings {
    SimulationSettings {
        multigrid: Some(MultigridSettings {
            link_budget,
            max_steps: 1000,
        }),
        ..*settings
    }
}

/// Per patch: the area-weighted mean of its leaves' radiance (largest channel difference is taken
/// by the caller) and of their a-posteriori error estimates.
fn patch_means(h: &Hierarchy) -> Vec<([f64; 3], f64)> {
    h.patches
        .iter()
        .map(|p| {
            let (mut radiance, mut error, mut area) = ([0.0; 3], 0.0, 0.0);
            let mut stack = vec![p.root];
            while let Some(id) = stack.pop() {
                let e = h.element(id);
                if e.is_leaf() {
                    for (sum, value) in radiance.iter_mut().zip(e.average_radiance().to_array()) {
                        *sum += e.area * value;
                    }
                    error += e.area * e.error;
                    area += e.area;
                } else {
                    stack.extend(e.children.iter().copied());
                }
            }
            (radiance.map(|r| r / area), error / area)
        })
        .collect()
}

/// The largest patch-average difference between two solutions, in units of the sum of their own
/// patch-average error estimates (each solution is within its estimate of the exact one, so two
/// solutions of the same accuracy differ by at most the sum).
fn difference_in_estimates(a: &Hierarchy, b: &Hierarchy) -> f64 {
    patch_means(a)
        .iter()
        .zip(patch_means(b))
        .map(|((ra, ea), (rb, eb))| {
            let gap = (0..3).map(|c| (ra[c] - rb[c]).abs()).fold(0.0, f64::max);
            gap / (ea + eb).max(1e-12)
        })
        .fold(0.0, f64::max)
}

/// The promises of every step after the coarse first: at most the budget refined, thresholds never
/// rising, and no step that does nothing.
fn check_steps(steps: &[StepReport], budget: usize, label: &str) {
    assert!(steps.len() >= 3, "{label}: only {} steps", steps.len());
    assert!(
        steps[0].threshold.is_infinite(),
        "{label}: coarse first step"
    );
    for pair in steps.windows(2) {
        let (before, after) = (&pair[0], &pair[1]);
        assert!(
            after.threshold <= before.threshold,
            "{label}: threshold rose from {} to {} at step {}",
            before.threshold,
            after.threshold,
            after.step
        );
        assert!(
            after.refined_links <= budget && after.selected <= after.refined_links,
            "{label}: step {} refined {} links ({} selected), budget {budget}",
            after.step,
            after.refined_links,
            after.selected
        );
        assert!(after.links >= before.links && after.leaves >= before.leaves);
    }
}

/// Power oracle, constant basis, without and with clustering: the progressive run refines until no
/// link is above ε (it stops "stable", like the one-shot solve), and the two agree within the sum of
/// their a-posteriori estimates on every patch.
#[test]
fn progressive_solution_matches_the_one_shot_solve() {
    for clustering in [ClusteringKind::None, ClusteringKind::Oriented] {
        let base = SimulationSettings {
            eps: 3e-4,
            clustering,
            ..Default::default()
        };
        let budget = 300;
        let one_shot = solve(&base);
        let stepped = solve(&progressive(&base, budget));
        let label = format!("{clustering:?}");
        check_steps(&stepped.report.steps, budget, &label);
        assert_eq!(stepped.report.error.stopped_by, "stable", "{label}");
        assert!(
            stepped
                .report
                .steps
                .iter()
                .any(|s| s.refined_links == budget),
            "{label}: no step filled the budget"
        );
        let ratio = difference_in_estimates(&stepped.hierarchy, &one_shot.hierarchy);
        assert!(ratio <= 1.0, "{label}: difference {ratio} × the estimates");
        let absorbed = |s: &Solution| s.report.absorbed_power.r + s.report.absorbed_power.g;
        let emitted = one_shot.report.emitted_power.r + one_shot.report.emitted_power.g;
        // Energy balance: the closed box absorbs what it emits, to the sweeps' tolerance and the
        // link errors the same ε admits in both.
        let gap = (absorbed(&stepped) - absorbed(&one_shot)).abs() / emitted;
        assert!(gap < 0.01, "{label}: absorbed power differs by {gap}");
    }
}

/// Every other oracle, with clustering: the step promises hold (30 steps; reaching the threshold is
/// checked with the power oracle above).
#[test]
fn every_oracle_steps_within_the_budget() {
    for oracle in [
        OracleKind::Smoothness,
        OracleKind::MutualInformation,
        OracleKind::Error,
    ] {
        let settings = SimulationSettings {
            oracle,
            eps: 1e-3,
            accuracy: Accuracy::Relative(0.5),
            clustering: ClusteringKind::Isotropic,
            multigrid: Some(MultigridSettings {
                link_budget: 100,
                max_steps: 30,
            }),
            ..Default::default()
        };
        let stepped = solve(&settings);
        check_steps(&stepped.report.steps, 100, &format!("{oracle:?}"));
    }
}

/// The steps and the solution are the same for any number of threads.
#[test]
fn progressive_steps_do_not_depend_on_threads() {
    let settings = progressive(
        &SimulationSettings {
            eps: 1e-3,
            clustering: ClusteringKind::Oriented,
            ..Default::default()
        },
        150,
    );
    let run = |threads| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| solve(&settings))
    };
    let (one, three) = (run(1), run(3));
    let strip = |s: &Solution| -> Vec<StepReport> {
        s.report
            .steps
            .iter()
            .map(|step| StepReport {
                seconds: 0.0,
                cpu_seconds: 0.0,
                ..step.clone()
            })
            .collect()
    };
    assert_eq!(strip(&one), strip(&three));
    for (a, b) in one.hierarchy.elements.iter().zip(&three.hierarchy.elements) {
        assert_eq!(a.radiance, b.radiance);
    }
}
