//! Visibility reuse (shaft culling, `--visibility-reuse shaft`) against its ground truth, the solve
//! that casts a ray for every node pair (`none`): with exact visibility a Clear shaft means every ray
//! would be open and a Blocked one every ray blocked, so the two solutions must agree to the bit, and
//! every ray the shafts saved is one the other solve cast. Also: independence of the thread count.

use radiosity::bases::BasisKind;
use radiosity::hierarchy::clusters::ClusteringKind;
use radiosity::pipeline::{simulate, OracleKind, SimulationSettings, Solution};
use radiosity::scene::{cornell::cornell_box, Scene};
use radiosity::visibility::shaft::VisibilityReuse;

// Shared with the clustering tests, which use more of it.
#[allow(dead_code)]
mod common;
use common::{furnace_with_cubes, quiet, with_threads};

fn solve(scene: &Scene, settings: &SimulationSettings, reuse: VisibilityReuse) -> Solution {
    let settings = SimulationSettings {
        visibility_reuse: reuse,
        ..settings.clone()
    };
    simulate(scene, &settings, &quiet()).expect("solve")
}

/// Same elements, links and radiance coefficients, bit for bit.
fn assert_identical(a: &Solution, b: &Solution) {
    assert_eq!(a.hierarchy.elements.len(), b.hierarchy.elements.len());
    assert_eq!(a.hierarchy.link_count(), b.hierarchy.link_count());
    assert_eq!(
        a.hierarchy.radiance_coefficients(),
        b.hierarchy.radiance_coefficients()
    );
}

/// Shaft reuse gives the ray-per-pair solution exactly, and its saved rays are exactly the rays it did
/// not cast.
fn assert_same_solution_fewer_rays(scene: &Scene, settings: &SimulationSettings) {
    let shaft = solve(scene, settings, VisibilityReuse::Shaft);
    let none = solve(scene, settings, VisibilityReuse::None);
    assert_identical(&shaft, &none);
    let (s, n) = (&shaft.report, &none.report);
    assert_eq!((n.shaft_tests, n.rays_saved), (0, 0));
    assert!(s.shaft_tests > 0 && s.rays_saved > 0);
    assert_eq!(s.form_factor_rays + s.rays_saved, n.form_factor_rays);
}

#[test]
fn cornell_box_solution_is_unchanged_by_shafts() {
    let settings = SimulationSettings {
        basis: BasisKind::Linear,
        eps: 1e-4,
        ..Default::default()
    };
    assert_same_solution_fewer_rays(&cornell_box(), &settings);
}

/// The link error oracle computes couplings while judging (a different path through refinement).
#[test]
fn cornell_box_under_error_control_is_unchanged_by_shafts() {
    let settings = SimulationSettings {
        basis: BasisKind::Linear,
        oracle: OracleKind::Error,
        max_passes: 3,
        ..Default::default()
    };
    assert_same_solution_fewer_rays(&cornell_box(), &settings);
}

/// A room full of occluding cubes, clustered: surface links below cluster links use shafts too.
#[test]
fn clustered_room_of_cubes_is_unchanged_by_shafts() {
    let settings = SimulationSettings {
        clustering: ClusteringKind::Oriented,
        eps: 1e-3,
        ..Default::default()
    };
    assert_same_solution_fewer_rays(&furnace_with_cubes(2, 0.5, 1.0), &settings);
}

#[test]
fn shaft_solution_is_identical_for_any_thread_count() {
    let scene = furnace_with_cubes(2, 0.5, 1.0);
    let settings = SimulationSettings {
        eps: 3e-4,
        ..Default::default()
    };
    let run = |threads| with_threads(threads, || solve(&scene, &settings, VisibilityReuse::Shaft));
    let (one, three) = (run(1), run(3));
    assert_identical(&one, &three);
    assert_eq!(one.report.rays_saved, three.report.rays_saved);
}
