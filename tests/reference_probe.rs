//! Probe points: file parsing with line numbers, locating points on surfaces, and the radiosity solution
//! against the path-traced reference there.

#[allow(dead_code)] // each test file uses part of the shared module
mod common;
use radiosity::geometry::form_factor::point_to_polygon;
use radiosity::geometry::DVec3;
use radiosity::pipeline::{simulate, SimulationSettings};
use radiosity::progress::Progress;
use radiosity::reference::probe::{parse_points, probe_points};
use radiosity::scene::generators;
use std::path::Path;

fn error_of(text: &str) -> String {
    parse_points(text, Path::new("pts.csv"))
        .expect_err("malformed input")
        .to_string()
}

#[test]
fn points_parse_with_commas_spaces_and_comments() {
    let text = "# probes\n0.5, 0.5, 0 0 0 2\n\n  1 2 3,1,0,0   # trailing comment\n";
    let points = parse_points(text, Path::new("pts.csv")).expect("valid");
    assert_eq!(points.len(), 2);
    assert_eq!(points[0].line, 2);
    assert_eq!(points[0].point, DVec3::new(0.5, 0.5, 0.0));
    assert_eq!(points[0].normal, DVec3::Z);
    assert_eq!(points[1].line, 4);
    assert_eq!(points[1].normal, DVec3::X);
}

#[test]
fn malformed_points_report_their_line() {
    let e = error_of("0 0 0 0 0 1\n# ok\n1 2 3 4 5\n");
    assert!(
        e.starts_with("pts.csv:3:") && e.contains("6 numbers"),
        "{e}"
    );
    let e = error_of("0 0 0 0 0 1\n0 0 x 0 0 1\n");
    assert!(e.starts_with("pts.csv:2:") && e.contains("'x'"), "{e}");
    let e = error_of("\n\n\n0 0 0 0 0 0\n");
    assert!(
        e.starts_with("pts.csv:4:") && e.contains("zero length"),
        "{e}"
    );
    let e = error_of("0 0 0 0 0 1 7\n");
    assert!(e.starts_with("pts.csv:1:"), "{e}");
    let e = error_of("0 0 nan 0 0 1\n");
    assert!(e.starts_with("pts.csv:1:") && e.contains("finite"), "{e}");
}

#[test]
fn probes_compare_the_solution_with_the_reference_on_parallel_plates() {
    let (rho, e) = (0.5, 1.0);
    let scene = generators::parallel_plates(1.0, 1.0, rho, e);
    let settings = SimulationSettings {
        eps: 1e-4,
        min_area: 1e-6,
        ..Default::default()
    };
    let solution = simulate(&scene, &settings, &Progress::new(true)).expect("solve");
    // The receiver's centre slightly above the surface, and the emitter's centre seen from below.
    let text = "0.5 0.5 0.0001 0 0 1\n0.5 0.5 1 0 0 -1\n";
    let results = common::probe_with_reference(&scene, &solution, text, 20_000, 2);
    let centre = DVec3::new(0.5, 0.5, 0.0);
    let exact = rho * e * point_to_polygon(centre, DVec3::Z, &scene.polygons[1].shape);
    let receiver = &results[0];
    assert_eq!((receiver.polygon, receiver.front), (0, true));
    assert!((DVec3::from_array(receiver.point) - centre).length() < 1e-9);
    let estimate = receiver.reference.expect("reference asked for");
    assert!((estimate.mean.g - exact).abs() <= 3.0 * estimate.stderr.g);
    // The solution's leaf average near the centre is close to the point value.
    assert!(
        (receiver.radiosity.g - exact).abs() < 0.03 * exact,
        "{} vs {exact}",
        receiver.radiosity.g
    );
    // The emitter reflects nothing: its radiance is exactly its emission in both.
    let emitter = &results[1];
    assert_eq!(emitter.polygon, 1);
    assert_eq!(emitter.reference.expect("reference").mean.g, e);
    assert_eq!(emitter.reference.expect("reference").stderr.g, 0.0);
    assert!((emitter.radiosity.g - e).abs() < 1e-12);

    // A point in mid-air, and the black back of the receiver, are errors naming the line.
    let file = Path::new("pts.csv");
    let bad = parse_points("0.5 0.5 0 0 0 1\n0.5 0.5 0.5 0 0 1\n", file).expect("valid");
    let error = probe_points(
        &scene,
        solution.visibility.as_ref(),
        &solution.hierarchy,
        &bad,
        None,
        file,
    )
    .expect_err("mid-air point")
    .to_string();
    assert!(
        error.starts_with("pts.csv:2:") && error.contains("no surface"),
        "{error}"
    );
    let back = parse_points("# back\n0.5 0.5 0 0 0 -1\n", file).expect("valid");
    let error = probe_points(
        &scene,
        solution.visibility.as_ref(),
        &solution.hierarchy,
        &back,
        None,
        file,
    )
    .expect_err("back side")
    .to_string();
    assert!(
        error.starts_with("pts.csv:2:") && error.contains("back"),
        "{error}"
    );
}

#[test]
fn random_points_lie_on_non_emitting_surfaces_uniformly_by_area() {
    use radiosity::reference::probe::random_points;
    let scene = radiosity::scene::cornell::cornell_box();
    let points = random_points(&scene, 2000, 5);
    assert_eq!(points.len(), 2000);
    assert_eq!(points, random_points(&scene, 2000, 5), "seeded");
    let areas: Vec<f64> = scene.polygons.iter().map(|p| p.shape.area()).collect();
    let mut counts = vec![0usize; scene.polygons.len()];
    for p in &points {
        // On exactly one polygon's plane and inside it, with that polygon's normal.
        let owner = scene
            .polygons
            .iter()
            .position(|q| {
                let n = q.shape.normal();
                (n.dot(p.point - q.shape.vertices()[0])).abs() < 1e-6
                    && n.dot(p.normal) > 0.999
                    && radiosity::geometry::convex_contains(
                        q.shape.parameter_corners(),
                        q.shape.parameters_of(p.point),
                        1e-9,
                    )
            })
            .expect("on a polygon");
        assert!(scene
            .material_of(&scene.polygons[owner])
            .emission
            .is_black());
        counts[owner] += 1;
    }
    // Counts follow the areas: binomial, within 4 standard deviations.
    let total: f64 = scene
        .polygons
        .iter()
        .zip(&areas)
        .filter(|(p, _)| scene.material_of(p).emission.is_black())
        .map(|(_, a)| a)
        .sum();
    for (k, &c) in counts.iter().enumerate() {
        if !scene.material_of(&scene.polygons[k]).emission.is_black() {
            continue;
        }
        let p = areas[k] / total;
        let sd = (2000.0 * p * (1.0 - p)).sqrt();
        assert!(
            (c as f64 - 2000.0 * p).abs() <= 4.0 * sd + 1.0,
            "polygon {k}: {c} points, expected {}",
            2000.0 * p
        );
    }
}

/// Every random point of office3 is found again on its own polygon's plane: there a steep object
/// standing within δ of a point used to take the locating ray and fail the probe ("the normal does not
/// match"), so `probe --random` could not run on the scene.
#[test]
fn random_points_of_a_furnished_office_are_found_on_their_planes() {
    use radiosity::reference::probe::{find_surface, random_points};
    use radiosity::scene::{load, LoadOptions};
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/scenes/renderpark/office3/office.mgf");
    let scene = load(&path, &LoadOptions::default()).expect("office3 loads");
    let shapes: Vec<_> = scene.polygons.iter().map(|p| p.shape).collect();
    let visibility = radiosity::visibility::bvh::Bvh::new(&shapes);
    let tolerance = 1e-3 * scene.bounds().diagonal();
    for probe in random_points(&scene, 500, 1) {
        let found = find_surface(&scene, &visibility, &probe)
            .unwrap_or_else(|e| panic!("point {}: {e}", probe.line));
        assert!(found.normal.dot(probe.normal) >= 0.5);
        let shape = &scene.polygons[found.polygon].shape;
        let off_plane = shape.normal().dot(probe.point - shape.vertices()[0]).abs();
        assert!(
            off_plane <= tolerance,
            "point {}: {off_plane} off its plane",
            probe.line
        );
    }
}

/// Two coplanar overlapping squares of different objects (z-fighting, as office3's two desk tops): a
/// probe in the overlap is found on the first object's square whatever the order of the polygons, so
/// that a solution measured before and after contact splitting renumbers them reads the same surface.
#[test]
fn a_probe_on_coplanar_overlapping_polygons_takes_the_first_objects() {
    use radiosity::color::Rgb;
    use radiosity::geometry::Shape;
    use radiosity::reference::probe::{find_surface, ProbePoint};
    use radiosity::scene::{Material, Object, Polygon, Scene};
    let square = |x0: f64| {
        let p = |x: f64, y: f64| DVec3::new(x, y, 0.0);
        Shape::Quad([p(x0, 0.0), p(x0 + 1.0, 0.0), p(x0 + 1.0, 1.0), p(x0, 1.0)])
    };
    let probe = ProbePoint {
        line: 1,
        point: DVec3::new(0.75, 0.5, 0.0),
        normal: DVec3::Z,
    };
    for order in [[0, 1], [1, 0]] {
        let mut scene = Scene {
            materials: vec![Material::diffuse("grey", Rgb::splat(0.5))],
            objects: vec![
                Object {
                    name: "first".into(),
                },
                Object {
                    name: "second".into(),
                },
            ],
            ..Default::default()
        };
        for object in order {
            scene.polygons.push(Polygon {
                shape: square(0.5 * object as f64),
                material: 0,
                object,
                two_sided: false,
                under_contact: false,
            });
        }
        let shapes: Vec<_> = scene.polygons.iter().map(|p| p.shape).collect();
        let visibility = radiosity::visibility::bvh::Bvh::new(&shapes);
        let found = find_surface(&scene, &visibility, &probe).expect("on both squares");
        assert_eq!(
            scene.polygons[found.polygon].object, 0,
            "polygon order {order:?}"
        );
    }
}

/// A scene of one-sided grey `shapes` (`common::one_polygon_per_material`), with a BVH over them.
fn one_sided_grey(
    shapes: &[radiosity::geometry::Shape],
) -> (radiosity::scene::Scene, radiosity::visibility::bvh::Bvh) {
    let grey = radiosity::scene::Material::diffuse("grey", radiosity::color::Rgb::splat(0.5));
    let scene =
        common::one_polygon_per_material(vec![grey; shapes.len()], shapes.iter().copied(), |_| {
            false
        });
    (scene, radiosity::visibility::bvh::Bvh::new(shapes))
}

/// A thin object's two one-sided faces back to back in one plane: a probe facing up lies on the upward
/// face, whatever the order of the polygons. The locating ray meets both at the same distance and may
/// take the downward face's black back, and the search for the probe's own plane took either.
#[test]
fn a_probe_between_back_to_back_faces_takes_the_side_that_radiates() {
    use radiosity::geometry::Shape;
    use radiosity::reference::probe::{find_surface, ProbePoint};
    let p = |x: f64, y: f64| DVec3::new(x, y, 0.0);
    let up = Shape::Quad([p(0.0, 0.0), p(1.0, 0.0), p(1.0, 1.0), p(0.0, 1.0)]);
    let down = Shape::Quad([p(0.0, 0.0), p(0.0, 1.0), p(1.0, 1.0), p(1.0, 0.0)]);
    assert!(up.normal().z > 0.0 && down.normal().z < 0.0);
    for (probe_normal, side) in [(DVec3::Z, up), (-DVec3::Z, down)] {
        for order in [[up, down], [down, up]] {
            let (scene, visibility) = one_sided_grey(&order);
            // Points over the whole plate, so that the ray's tie falls both ways.
            for k in 0..25 {
                let probe = ProbePoint {
                    line: k + 1,
                    point: p(0.1 + 0.2 * (k % 5) as f64, 0.1 + 0.2 * (k / 5) as f64),
                    normal: probe_normal,
                };
                let found = find_surface(&scene, &visibility, &probe)
                    .unwrap_or_else(|e| panic!("point {k}, normal {probe_normal}: {e}"));
                assert!(found.front, "point {k}: on a back");
                assert_eq!(scene.polygons[found.polygon].shape, side);
            }
        }
    }
}

/// Two one-sided faces 1 cm apart looking at each other (as a leg of the classroom's desks with
/// `--one-sided`), in a scene whose δ (10⁻³ of its diagonal) is 2 cm: the locating ray from δ in front
/// of a point on one face meets the back of the other first, and that black back failed the probe
/// ("the point is on the back of one-sided polygon"); the point's own face is found instead.
#[test]
fn a_probe_looks_past_the_black_back_of_a_face_in_front_of_it() {
    use radiosity::geometry::Shape;
    use radiosity::reference::probe::{find_surface, ProbePoint};
    let wall = |x: f64, facing_minus_x: bool| {
        let p = |y: f64, z: f64| DVec3::new(x, y, z);
        let mut corners = [p(0.0, 0.0), p(1.0, 0.0), p(1.0, 1.0), p(0.0, 1.0)];
        if facing_minus_x {
            corners.reverse();
        }
        Shape::Quad(corners)
    };
    let (near, far) = (wall(0.0, false), wall(0.01, true));
    assert!(near.normal().x > 0.0 && far.normal().x < 0.0);
    let p = |x: f64, y: f64, z: f64| DVec3::new(x, y, z);
    let floor = Shape::Quad([
        p(-10.0, -10.0, -5.0),
        p(10.0, -10.0, -5.0),
        p(10.0, 10.0, -5.0),
        p(-10.0, 10.0, -5.0),
    ]);
    let (scene, visibility) = one_sided_grey(&[near, far, floor]);
    assert!(1e-3 * scene.bounds().diagonal() > 0.015);
    for (x, normal, polygon) in [(0.01, -DVec3::X, 1), (0.0, DVec3::X, 0)] {
        let probe = ProbePoint {
            line: 1,
            point: p(x, 0.5, 0.5),
            normal,
        };
        let found = find_surface(&scene, &visibility, &probe)
            .unwrap_or_else(|e| panic!("face {polygon}: {e}"));
        assert_eq!((found.polygon, found.front), (polygon, true));
    }
}

/// Points the Cornell box's camera sees: seeded, on non-emitting polygons facing the eye, and nothing
/// between the eye and each of them.
#[test]
fn seen_points_are_visible_from_the_eye_on_the_side_it_sees() {
    use radiosity::output::camera::Camera;
    use radiosity::reference::probe::{find_surface, seen_points};
    use radiosity::visibility::Visibility;
    let scene = radiosity::scene::cornell::cornell_box();
    let fov = scene.camera.map_or(40.0, |c| c.fov_degrees);
    let camera = Camera::new(&Camera::auto_view(&scene, fov), 64, 48);
    let points = seen_points(&scene, &camera, 400, 3);
    assert_eq!(points.len(), 400, "the box fills the image");
    assert_eq!(points, seen_points(&scene, &camera, 400, 3), "seeded");
    assert_ne!(points, seen_points(&scene, &camera, 400, 4));
    let shapes: Vec<_> = scene.polygons.iter().map(|p| p.shape).collect();
    let visibility = radiosity::visibility::bvh::Bvh::new(&shapes);
    for p in &points {
        let to_eye = camera.eye - p.point;
        assert!(p.normal.dot(to_eye) > 0.0, "point {}: faces away", p.line);
        let ray = radiosity::geometry::Ray::new(camera.eye, -to_eye);
        assert!(
            !visibility.occluded(&ray, 0.0, 1.0 - 1e-6),
            "point {}: hidden from the eye",
            p.line
        );
        let found = find_surface(&scene, &visibility, p).expect("on a surface");
        assert!(scene
            .material_of(&scene.polygons[found.polygon])
            .emission
            .is_black());
    }
}
