//! `--max-memory` (issue 9 item 10): a budget below what the scene needs before refinement is refused
//! with a message and no work; a budget that leaves refinement little room stops it, and the solve
//! still ends with a valid solution (finite, non-negative, creating no energy) whose links fit it.

use radiosity::hierarchy::clusters::ClusteringKind;
use radiosity::hierarchy::Hierarchy;
use radiosity::memory::{link_peak_bytes, MemoryBudget, ITEM_BUFFER_SHARE};
use radiosity::pipeline::{build_visibility_for, simulate, SimulationSettings};
use radiosity::progress::Progress;
use radiosity::scene::generators::BoxHall;
use radiosity::scene::Scene;

fn settings(max_memory: usize) -> SimulationSettings {
    SimulationSettings {
        clustering: ClusteringKind::Oriented,
        eps: 1e-4,
        max_memory,
        ..Default::default()
    }
}

/// The budget's fixed part for `scene` (everything but the item-buffer cache, which is a share of
/// what remains).
fn fixed_part(scene: &Scene) -> usize {
    let s = settings(usize::MAX / 2);
    let visibility = build_visibility_for(scene, &s).unwrap();
    let mut hierarchy = Hierarchy::new(scene, s.basis);
    hierarchy.add_clusters(s.cluster_tree, ClusteringKind::Oriented);
    let budget =
        MemoryBudget::new(s.max_memory, scene, visibility.as_ref(), &hierarchy, false).unwrap();
    budget.fixed
}

#[test]
fn a_budget_below_the_fixed_part_is_refused_with_a_message() {
    let scene = BoxHall::with_polygons(300).scene();
    let error = simulate(
        &scene,
        &settings(fixed_part(&scene) / 2),
        &Progress::new(true),
    )
    .err()
    .expect("refused");
    assert!(error.to_string().contains("--max-memory"), "{error}");
}

#[test]
fn a_small_budget_stops_refinement_with_a_valid_solution_within_it() {
    let scene = BoxHall::with_polygons(300).scene();
    let free = simulate(&scene, &settings(1 << 30), &Progress::new(true)).unwrap();
    assert_eq!(free.report.refused_by_budget, 0);
    let links = free.hierarchy.link_count();
    // Room for about a quarter of those links once the item-buffer cache has taken its share.
    let s = settings(0);
    let peak = link_peak_bytes(s.basis, s.cubature_degree(), s.error_storage);
    let refinement = links / 4 * peak * 8 / 7;
    let max_memory = fixed_part(&scene) + refinement * ITEM_BUFFER_SHARE / (ITEM_BUFFER_SHARE - 1);
    let tight = simulate(&scene, &settings(max_memory), &Progress::new(true)).unwrap();
    assert!(tight.report.refused_by_budget > 0);
    assert!(tight.hierarchy.link_count() <= links / 4 + links / 100 + 1);
    // A valid solution, if a coarse one: finite, non-negative radiance everywhere, and no energy
    // created (a closed room absorbs at most what it emits; coarse cluster links lose some of it:
    // BENCHMARKS.md, "Scale").
    let (e, a) = (tight.report.emitted_power, tight.report.absorbed_power);
    for (e, a) in [(e.r, a.r), (e.g, a.g), (e.b, a.b)] {
        assert!(a > 0.0 && a <= e * (1.0 + 1e-9), "absorbed {a} of {e}");
    }
    for leaf in tight.hierarchy.leaves() {
        let l = tight.hierarchy.average_radiance(leaf);
        assert!(
            [l.r, l.g, l.b].iter().all(|c| c.is_finite() && *c >= 0.0),
            "{l:?}"
        );
    }
}
