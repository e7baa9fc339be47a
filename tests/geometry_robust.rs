//! Property tests: every geometric kernel takes any triangle or quad (non-convex, non-planar, sliver,
//! near-degenerate) without panicking, and returns finite results (non-negative where that is the
//! contract). The polygon splitter takes any polygon, NaN included.

#[allow(dead_code)] // each test file uses part of the shared module
mod common;
use proptest::prelude::*;
use radiosity::geometry::cubature::gauss_nodes;
use radiosity::geometry::form_factor::{point_to_point, point_to_polygon};
use radiosity::geometry::{subdivide_parameters, DVec2, DVec3, Shape};
use radiosity::scene::polygonize::polygonize;

/// A coordinate: mostly moderate, sometimes tiny or huge (slivers and near-degenerate shapes).
fn coordinate() -> impl Strategy<Value = f64> {
    prop_oneof![
        6 => -10.0..10.0f64,
        1 => -1e-9..1e-9f64,
        1 => -1e6..1e6f64,
        1 => Just(0.0),
    ]
}

fn point() -> impl Strategy<Value = DVec3> {
    (coordinate(), coordinate(), coordinate()).prop_map(|(x, y, z)| DVec3::new(x, y, z))
}

/// A triangle or quad with arbitrary corners, or a flat quad with one corner pulled close to another.
fn shape() -> impl Strategy<Value = Shape> {
    prop_oneof![
        [point(), point(), point()].prop_map(Shape::Triangle),
        [point(), point(), point(), point()].prop_map(Shape::Quad),
        (point(), point(), point(), -1e-6..1e-6f64).prop_map(|(a, b, c, e)| {
            // Sliver: the fourth corner almost on the first.
            Shape::Quad([a, b, c, a + DVec3::splat(e)])
        }),
    ]
}

fn unit() -> impl Strategy<Value = DVec2> {
    (0.0..=1.0f64, 0.0..=1.0f64).prop_map(|(u, v)| DVec2::new(u, v))
}

fn finite(p: DVec3) -> bool {
    p.is_finite()
}

proptest! {
    #![proptest_config(common::proptest_config(2000))]

    #[test]
    fn shape_measures_are_finite(s in shape(), uv in unit()) {
        prop_assert!(s.area().is_finite() && s.area() >= 0.0);
        prop_assert!(finite(s.normal()));
        prop_assert!(finite(s.centroid()));
        prop_assert!(s.diameter().is_finite() && s.diameter() >= 0.0);
        prop_assert!(finite(s.point_at(uv)));
        let j = s.jacobian(uv);
        prop_assert!(j.is_finite() && j >= 0.0);
        prop_assert!(finite(s.sample_uniform(uv)));
        prop_assert!(s.parameters_of(s.point_at(uv)).is_finite());
        prop_assert!(!s.bounds().is_empty());
        prop_assert!(finite(s.flipped().normal()));
    }

    #[test]
    fn subdivision_is_finite(s in shape()) {
        for child in s.subdivide() {
            prop_assert!(child.vertices().iter().all(|p| p.is_finite()));
            prop_assert!(child.area().is_finite());
        }
        let children = subdivide_parameters(s.parameter_corners());
        prop_assert_eq!(children.len(), 4);
    }

    #[test]
    fn cubature_weights_are_finite_and_non_negative(s in shape(), n in 0usize..7) {
        for node in gauss_nodes(&s, n) {
            prop_assert!(node.weight.is_finite() && node.weight >= 0.0);
            prop_assert!(finite(node.point));
        }
    }

    #[test]
    fn form_factors_are_finite_and_bounded(
        s in shape(),
        x in point(),
        nx in point(),
        y in point(),
        ny in point(),
    ) {
        let nx = nx.normalize_or_zero();
        let f = point_to_polygon(x, nx, &s);
        prop_assert!(f.is_finite() && (0.0..=1.0).contains(&f), "{}", f);
        let f = point_to_polygon(x, nx, &s.flipped());
        prop_assert!(f.is_finite() && (0.0..=1.0).contains(&f), "{}", f);
        let g = point_to_point(x, nx, y, ny.normalize_or_zero());
        prop_assert!(g.is_finite() && g >= 0.0, "{}", g);
    }

    #[test]
    fn polygonize_never_panics(points in prop::collection::vec(point(), 0..24)) {
        if let Ok(out) = polygonize(&points) {
            for s in &out.shapes {
                prop_assert!(s.vertices().iter().all(|p| p.is_finite()));
                prop_assert!(s.area().is_finite() && s.area() > 0.0);
            }
        }
    }
}

#[test]
fn non_finite_input_gives_zero_form_factors() {
    let q = Shape::Quad([DVec3::ZERO, DVec3::X, DVec3::new(1.0, 1.0, 0.0), DVec3::Y]);
    let nan = DVec3::splat(f64::NAN);
    assert_eq!(point_to_polygon(nan, DVec3::Z, &q), 0.0);
    assert_eq!(point_to_polygon(DVec3::Z, nan, &q), 0.0);
    let inf = Shape::Quad([DVec3::ZERO, DVec3::X * f64::INFINITY, DVec3::ONE, DVec3::Y]);
    assert!(point_to_polygon(DVec3::new(0.5, 0.5, -1.0), DVec3::Z, &inf).is_finite());
    assert_eq!(point_to_point(DVec3::ZERO, DVec3::Z, nan, -DVec3::Z), 0.0);
    assert!(polygonize(&[DVec3::ZERO, nan, DVec3::X]).is_err());
}

#[test]
fn concave_quad_crossing_the_tangent_plane_has_six_clipped_vertices() {
    // The issue-8 reproducer: a dart-shaped (non-convex) quad whose four edges all cross the tangent
    // plane of x, so that clipping yields six vertices (the old buffer held five).
    let x = DVec3::new(0.0, 0.0, 0.0);
    let nx = DVec3::Y;
    let dart = Shape::Quad([
        DVec3::new(-1.0, 1.0, 1.0),
        DVec3::new(0.0, -1.0, 1.0),
        DVec3::new(1.0, 1.0, 1.0),
        DVec3::new(0.0, -0.5, 1.0),
    ]);
    for s in [dart, dart.flipped()] {
        let f = point_to_polygon(x, nx, &s);
        assert!(f.is_finite() && (0.0..=1.0).contains(&f), "{f}");
    }
}
