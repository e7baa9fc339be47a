//! The oracle experiment's machinery: the ε search reaches a target element count for every oracle, and
//! the side-by-side image keeps every run in place.

use radiosity::experiments::oracles::{solve_at_target, tile};
use radiosity::output::image::Image;
use radiosity::pipeline::{OracleKind, SimulationSettings};
use radiosity::progress::Progress;
use radiosity::scene::cornell::cornell_box;

#[test]
fn eps_search_reaches_the_target_element_count_for_each_oracle() {
    let scene = cornell_box();
    for oracle in [
        OracleKind::Power,
        OracleKind::Smoothness,
        OracleKind::MutualInformation,
    ] {
        let base = SimulationSettings {
            oracle,
            min_area: 1e-6,
            ..Default::default()
        };
        let (solution, eps, solves, _) =
            solve_at_target(&scene, &base, 300, 0.05, 20, &Progress::new(true)).unwrap();
        let leaves = solution.hierarchy.leaf_count();
        assert!(
            (leaves as f64 - 300.0).abs() <= 15.0,
            "{oracle:?}: {leaves} leaves at eps {eps} after {solves} solves"
        );
    }
}

#[test]
fn tiles_are_placed_row_by_row() {
    let mut a = Image::new(2, 1);
    a.set(1, 0, radiosity::color::Rgb::splat(1.0));
    let b = Image::new(2, 1);
    let grid = tile(&[&a, &b, &b, &a], 2);
    assert_eq!((grid.width, grid.height), (2 + 4 + 2, 1 + 4 + 1));
    assert_eq!(grid.get(1, 0).r, 1.0);
    assert_eq!(grid.get(7, 5).r, 1.0);
    assert_eq!(grid.get(7, 0).r, 0.0);
}
