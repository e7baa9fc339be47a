//! Progressive multi-gridding (Sillion–Drettakis §6.2): the final solution agrees with the one-shot
//! solve at the same threshold within both solutions' own a-posteriori error estimates, every step
//! creates at most the link budget, thresholds never rise, with and without clustering and with every
//! oracle, every step's sweeps converge on a real room (office2, whose coarse steps diverged), and the
//! steps do not depend on the thread count.

use radiosity::hierarchy::clusters::{ClusteringKind, MAX_CHILDREN};
use radiosity::hierarchy::Hierarchy;
use radiosity::pipeline::{simulate, Accuracy, OracleKind, SimulationSettings, Solution};
use radiosity::progress::Progress;
use radiosity::scene::cornell::cornell_box;
use radiosity::scene::{self, LoadOptions, Scene};
use radiosity::solvers::error_estimate::EstimateKind;
use radiosity::solvers::multigrid::{MultigridSettings, StepReport};

fn solve(settings: &SimulationSettings) -> Solution {
    solve_scene(&cornell_box(), settings)
}

fn solve_scene(scene: &Scene, settings: &SimulationSettings) -> Solution {
    simulate(scene, settings, &Progress::new(true)).expect("solve")
}

fn progressive(settings: &SimulationSettings, link_budget: usize) -> SimulationSettings {
    SimulationSettings {
        multigrid: Some(MultigridSettings {
            link_budget,
            max_steps: 1000,
        }),
        ..settings.clone()
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
                    for (sum, value) in radiance.iter_mut().zip(h.average_radiance(id).to_array()) {
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

/// The promises of every step after the coarse first: at most the budget of links created (and so of
/// refinements, each creating at least one), thresholds never rising, and no step that does nothing.
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
            after.created_links <= budget
                && after.refined_links <= after.created_links
                && after.selected <= after.refined_links,
            "{label}: step {} refined {} links creating {} ({} selected), budget {budget}",
            after.step,
            after.refined_links,
            after.created_links,
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
        // A refinement waits for a later step only when its cost, at most MAX_CHILDREN² links (a
        // cluster's self-link), exceeds what is left of the budget.
        assert!(
            stepped
                .report
                .steps
                .iter()
                .any(|s| s.created_links + MAX_CHILDREN * MAX_CHILDREN > budget),
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
            accuracy: Some(Accuracy::Relative(0.5)),
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
    assert_eq!(
        one.hierarchy.radiance_coefficients(),
        three.hierarchy.radiance_coefficients()
    );
}

/// office2 (RenderPark), oriented clusters: the coarse step left links between near sibling clusters
/// whose centre-to-centre transfer made a receiver gather a total factor up to 2.9 (the exact factors
/// of the disjoint sources it stands for sum to at most 1), and its sweeps diverged (the power grew 22%
/// per sweep for 200 sweeps). With the bounded cluster transfer (`solvers::clustering`) every step's
/// sweeps meet the tolerance, no step absorbs more than is emitted, and the final solution agrees with
/// the one-shot solve within the sum of both solutions' error estimates: the conservative ones (eq.
/// (11)), since the two reach ε by different refinements and so differ by propagated error too, which
/// the realistic estimate leaves out (§4.3; with it the gap was 1.07× the estimates).
#[test]
fn office2_steps_converge_and_match_the_one_shot_solve() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/scenes/renderpark/office2/office2.mgf");
    let scene = scene::load(&path, &LoadOptions::default()).expect("office2");
    let base = SimulationSettings {
        eps: 1e-3,
        clustering: ClusteringKind::Oriented,
        estimate: EstimateKind::Conservative,
        ..Default::default()
    };
    let budget = 5000;
    let one_shot = solve_scene(&scene, &base);
    let stepped = solve_scene(&scene, &progressive(&base, budget));
    check_steps(&stepped.report.steps, budget, "office2");
    let emitted = stepped.report.emitted_power;
    for step in &stepped.report.steps {
        assert!(
            step.swept_to_tolerance,
            "step {}: {} sweeps did not converge",
            step.step, step.sweeps
        );
        // The sweeps stop when the power changes by less than the tolerance; what is left of the
        // iteration is at most that change times 1 / (1 − ρ) ≤ 100 for reflectances below 0.99.
        let slack = 1.0 + 100.0 * base.tolerance;
        for (a, e) in [
            (step.absorbed_power.r, emitted.r),
            (step.absorbed_power.g, emitted.g),
            (step.absorbed_power.b, emitted.b),
        ] {
            assert!(a <= e * slack, "step {}: absorbed {a} of {e} W", step.step);
        }
    }
    assert_eq!(stepped.report.error.stopped_by, "stable");
    let ratio = difference_in_estimates(&stepped.hierarchy, &one_shot.hierarchy);
    assert!(ratio <= 1.0, "difference {ratio} × the estimates");
}
