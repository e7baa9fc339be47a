//! Splitting surfaces along the outlines of objects that touch or nearly touch them (`scene::contacts`,
//! issue #7 item 9): the split is an exact tiling of each polygon, no piece straddles an outline, and
//! on cube.mgf as MGF defines it (a two-sided lamp 1 cm under the ceiling) the solution agrees with the
//! path-traced reference, which it did not while ceiling elements straddled the lamp's outline.

use radiosity::bases::BasisKind;
use radiosity::geometry::{DVec2, DVec3, Shape};
use radiosity::measures::image_metrics::compare;
use radiosity::output::camera::Camera;
use radiosity::output::render::{emitter_mask, render, RenderOptions, Shading};
use radiosity::pipeline::{simulate, SimulationSettings};
use radiosity::progress::Progress;
use radiosity::reference::{render_reference, ReferenceSettings};
use radiosity::scene::contacts::{contact_pieces, split_contacts, DEFAULT_CONTACT_GAP};
use radiosity::scene::{cornell::cornell_box, load, CameraSpec, LoadOptions, Scene};
use std::path::Path;

fn renderpark(name: &str) -> Scene {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/scenes/renderpark")
        .join(name);
    load(&path, &LoadOptions::default()).unwrap()
}

/// Corners of `shape` in a plane basis of `normal` (counter-clockwise seen from its front).
fn flat(shape: &Shape, origin: DVec3, normal: DVec3) -> Vec<DVec2> {
    let (u, v) = normal.any_orthonormal_pair();
    shape
        .vertices()
        .iter()
        .map(|p| DVec2::new((*p - origin).dot(u), (*p - origin).dot(v)))
        .collect()
}

/// Whether 2D point `p` is inside the convex counter-clockwise polygon `corners` by at least `margin`.
fn strictly_inside(corners: &[DVec2], p: DVec2, margin: f64) -> bool {
    (0..corners.len()).all(|k| {
        let (a, b) = (corners[k], corners[(k + 1) % corners.len()]);
        (b - a).perp_dot(p - a) > margin * (b - a).length()
    })
}

/// The split tiles every polygon it cuts: piece areas sum to the polygon's to 1e-12 relative (the pieces
/// share their cut vertices bit for bit, so only rounding of the area sums remains), every piece is a
/// convex shape in the polygon's plane facing the same way, and points spread over the polygon lie in
/// exactly one piece (area sum + no overlap + cover = a partition).
fn check_tiling(scene: &Scene, name: &str) -> usize {
    let cut = contact_pieces(scene, DEFAULT_CONTACT_GAP);
    let mut split = 0;
    for (polygon, pieces) in scene.polygons.iter().zip(&cut) {
        let Some(pieces) = pieces else { continue };
        split += 1;
        let shape = polygon.shape;
        let (area, normal, size) = (shape.area(), shape.normal(), shape.diameter());
        let origin = shape.vertices()[0];
        // Quads may be planar only to polygonize's tolerance: pieces stay within P's own deviation.
        let warp = shape
            .vertices()
            .iter()
            .map(|p| (*p - origin).dot(normal).abs())
            .fold(0.0, f64::max);
        let sum: f64 = pieces.shapes.iter().map(Shape::area).sum();
        assert!(
            (sum - area).abs() <= 1e-12 * area,
            "{name}: pieces cover {sum} of area {area}"
        );
        let corners: Vec<Vec<DVec2>> = pieces
            .shapes
            .iter()
            .map(|piece| {
                assert!(
                    piece.normal().dot(normal) > 1.0 - 1e-9,
                    "{name}: piece turned"
                );
                for p in piece.vertices() {
                    assert!(
                        (*p - origin).dot(normal).abs() <= warp + 1e-9 * size,
                        "{name}: off plane"
                    );
                }
                let c = flat(piece, origin, normal);
                for k in 0..c.len() {
                    let (a, b, d) = (c[k], c[(k + 1) % c.len()], c[(k + 2) % c.len()]);
                    assert!(
                        (b - a).perp_dot(d - b) >= -1e-9 * size * size,
                        "{name}: non-convex piece {piece:?}"
                    );
                }
                c
            })
            .collect();
        for s in 0..256 {
            let sample = DVec2::new((s % 16) as f64 + 0.37, (s / 16) as f64 + 0.61) / 16.0;
            let point = shape.sample_uniform(sample);
            let p = flat(&Shape::Triangle([point; 3]), origin, normal)[0];
            let inside = corners
                .iter()
                .filter(|c| strictly_inside(c, p, -1e-9 * size))
                .count();
            let deep = corners
                .iter()
                .filter(|c| strictly_inside(c, p, 1e-9 * size))
                .count();
            assert!(
                inside >= 1,
                "{name}: point {point} of a split polygon in no piece"
            );
            assert!(deep <= 1, "{name}: point {point} inside {deep} pieces");
        }
    }
    split
}

#[test]
fn splitting_tiles_every_polygon_it_cuts() {
    assert_eq!(check_tiling(&renderpark("cube.mgf"), "cube.mgf"), 4);
    // The floor (the blocks' footprints, no bottom faces) and the ceiling (the light's outline).
    assert_eq!(check_tiling(&cornell_box(), "Cornell box"), 2);
    assert!(check_tiling(&renderpark("office2/office2.mgf"), "office2") > 0);
}

/// Area of the convex 2D polygon `a` clipped to the convex counter-clockwise polygon `b`
/// (Sutherland–Hodgman, written out here independently of the library's 3D clipper).
fn overlap_area(a: &[DVec2], b: &[DVec2]) -> f64 {
    let mut poly = a.to_vec();
    for k in 0..b.len() {
        let (p, q) = (b[k], b[(k + 1) % b.len()]);
        let side = |x: DVec2| (q - p).perp_dot(x - p);
        let mut next = Vec::new();
        for i in 0..poly.len() {
            let (x, y) = (poly[i], poly[(i + 1) % poly.len()]);
            let (sx, sy) = (side(x), side(y));
            if sx >= 0.0 {
                next.push(x);
            }
            if (sx >= 0.0) != (sy >= 0.0) {
                next.push(x + (y - x) * (sx / (sx - sy)));
            }
        }
        poly = next;
        if poly.is_empty() {
            return 0.0;
        }
    }
    0.5 * (0..poly.len())
        .map(|k| poly[k].perp_dot(poly[(k + 1) % poly.len()]))
        .sum::<f64>()
}

/// Whether `shape`'s interior meets both the inside and the outside of the convex counter-clockwise
/// outline (by more than 1e-9 of its area).
fn straddles(shape: &Shape, outline: &[DVec2], origin: DVec3, normal: DVec3) -> bool {
    let overlap = overlap_area(&flat(shape, origin, normal), outline);
    let area = shape.area();
    overlap > 1e-9 * area && overlap < (1.0 - 1e-9) * area
}

#[test]
fn no_piece_straddles_the_cube_lamp_or_a_cornell_block() {
    let mut cube = renderpark("cube.mgf");
    let ceiling = cube
        .materials
        .iter()
        .position(|m| m.name == "plafondwit")
        .unwrap();
    let before = cube.polygons.clone();
    // The lamp's outline, 1 cm under the ceiling: x, y in [4.4, 5.4].
    let lamp: Vec<DVec3> = [(4.4, 4.4), (5.4, 4.4), (5.4, 5.4), (4.4, 5.4)]
        .iter()
        .map(|&(x, y)| DVec3::new(x, y, 10.0))
        .collect();
    let square = |shape: &Shape| {
        let origin = shape.vertices()[0];
        let outline = flat(
            // Counter-clockwise seen from below, the ceiling's front.
            &Shape::Quad([lamp[3], lamp[2], lamp[1], lamp[0]]),
            origin,
            -DVec3::Z,
        );
        straddles(shape, &outline, origin, -DVec3::Z)
    };
    assert!(
        before
            .iter()
            .any(|p| p.material == ceiling && square(&p.shape)),
        "the unsplit ceiling straddles the lamp (else this test tests nothing)"
    );
    let report = split_contacts(&mut cube, DEFAULT_CONTACT_GAP);
    assert_eq!(report.polygons_split, 4, "{report}");
    let pieces: Vec<_> = cube
        .polygons
        .iter()
        .filter(|p| p.material == ceiling)
        .collect();
    assert!(pieces.len() > 2);
    for p in pieces {
        assert!(
            !square(&p.shape),
            "ceiling piece {:?} straddles the lamp",
            p.shape
        );
    }
    // Every piece keeps its polygon's place in the file.
    assert!(cube.origins.get(cube.polygons.len() - 1).1 > 0);

    let mut cornell = cornell_box();
    let floor = cornell
        .objects
        .iter()
        .position(|o| o.name == "floor")
        .unwrap();
    split_contacts(&mut cornell, DEFAULT_CONTACT_GAP);
    for block in ["short_block", "tall_block"] {
        let object = cornell
            .objects
            .iter()
            .position(|o| o.name == block)
            .unwrap();
        // The footprint: the bottom edges of the block's sides, as a convex outline seen from above.
        let feet: Vec<DVec3> = cornell
            .polygons
            .iter()
            .filter(|p| p.object == object)
            .flat_map(|p| p.shape.vertices().to_vec())
            .filter(|v| v.y.abs() < 1e-9)
            .collect();
        for p in cornell.polygons.iter().filter(|p| p.object == floor) {
            let origin = p.shape.vertices()[0];
            let hull = radiosity::geometry::clip::convex_hull(
                &feet
                    .iter()
                    .map(|&f| flat(&Shape::Triangle([f; 3]), origin, DVec3::Y)[0])
                    .collect::<Vec<_>>(),
            );
            assert!(
                !straddles(&p.shape, &hull, origin, DVec3::Y),
                "floor piece straddles {block}"
            );
        }
    }
}

/// cube.mgf as MGF defines it (every surface two-sided, the lamp 1 cm under the ceiling) against the
/// path-traced reference, emitters masked, the CLI's default solver (linear basis, power oracle, ε =
/// 3e-5). Error model: the measured relative RMSE e_m² = e² + n², where e is the solution's error and
/// n the reference's noise, √(Σ σ²)/√(Σ 1) / mean over the compared pixels from its per-pixel standard
/// errors σ (kept below 1% by the path count); the issue asks e ≤ 3%. Unsplit, e was 16.5%
/// (BENCHMARKS.md).
#[test]
fn cube_mgf_with_its_two_sided_lamp_agrees_with_the_reference() {
    let mut scene = renderpark("cube.mgf");
    split_contacts(&mut scene, DEFAULT_CONTACT_GAP);
    let spec = CameraSpec {
        eye: DVec3::new(5.0, 0.8, 6.5),
        look_at: DVec3::new(5.0, 6.0, 3.5),
        up: DVec3::Z,
        fov_degrees: 60.0,
    };
    let camera = Camera::new(&spec, 32, 32);
    let quiet = Progress::new(true);
    let solution = simulate(
        &scene,
        &SimulationSettings {
            basis: BasisKind::Linear,
            eps: 3e-5,
            ..Default::default()
        },
        &quiet,
    )
    .unwrap();
    let options = RenderOptions {
        shading: Shading::Basis,
        samples_per_pixel: 16,
        ..Default::default()
    };
    let image = render(
        &solution.hierarchy,
        solution.visibility.as_ref(),
        &camera,
        &options,
    );
    let reference = render_reference(
        &scene,
        solution.visibility.as_ref(),
        &camera,
        &ReferenceSettings {
            spp: 1024,
            seed: 3,
            ..Default::default()
        },
        &quiet,
    );
    let lamp = emitter_mask(&solution.hierarchy, solution.visibility.as_ref(), &camera);
    let errors = compare(&image, &reference.mean, Some(&lamp.bits)).unwrap();
    let measured = errors.luminance.relative_rmse.unwrap();
    let (mut variance, mut count) = (0.0, 0.0);
    for (s, _) in reference
        .stderr
        .pixels
        .iter()
        .zip(&lamp.bits)
        .filter(|(_, l)| !**l)
    {
        variance += s.luminance().powi(2);
        count += 1.0;
    }
    let noise = (variance / count).sqrt() / errors.luminance.reference_mean;
    eprintln!("cube.mgf: relative RMSE {measured:.4}, reference noise {noise:.4}");
    assert!(noise < 0.01, "reference too noisy: {noise}");
    let error = (measured.powi(2) - noise.powi(2)).max(0.0).sqrt();
    assert!(
        error <= 0.03,
        "relative RMSE {measured:.4} (noise {noise:.4}): error {error:.4}"
    );
}
