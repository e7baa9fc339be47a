//! The BVH (and Embree, with the `embree` feature) against the exhaustive double-precision reference.

#[allow(dead_code)] // each test file uses part of the shared module
mod common;
use radiosity::geometry::{DVec2, DVec3, Ray, Shape};
use radiosity::visibility::bench::random_segments;
use radiosity::visibility::brute_force::BruteForce;
use radiosity::visibility::bvh::Bvh;
use radiosity::visibility::{Hit, Visibility};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;

fn random_point(rng: &mut Pcg64Mcg, lo: f64, hi: f64) -> DVec3 {
    DVec3::new(
        rng.random_range(lo..hi),
        rng.random_range(lo..hi),
        rng.random_range(lo..hi),
    )
}

fn random_direction(rng: &mut Pcg64Mcg) -> DVec3 {
    loop {
        let d = random_point(rng, -1.0, 1.0);
        if d.length_squared() > 1e-4 && d.length_squared() <= 1.0 {
            return d;
        }
    }
}

/// Random triangles and planar convex quads (trapezoids in random planes) of size about `size`.
fn random_scene(count: usize, size: f64, seed: u64) -> Vec<Shape> {
    let mut rng = Pcg64Mcg::seed_from_u64(seed);
    (0..count)
        .map(|k| {
            let c = random_point(&mut rng, 0.0, 1.0);
            if k % 2 == 0 {
                Shape::Triangle([
                    c,
                    c + size * random_point(&mut rng, -1.0, 1.0),
                    c + size * random_point(&mut rng, -1.0, 1.0),
                ])
            } else {
                let u = random_direction(&mut rng).normalize();
                let v = u.any_orthonormal_vector();
                let (a, b) = (rng.random_range(0.2..1.0), rng.random_range(0.2..1.0));
                let shear = rng.random_range(-0.5..0.5);
                let s = size;
                Shape::Quad([
                    c + s * (-a * u - b * v),
                    c + s * (a * u - b * v),
                    c + s * ((a + shear) * u + b * v),
                    c + s * ((-a + shear * 0.5) * u + b * v),
                ])
            }
        })
        .collect()
}

/// Closest hits agree: same polygon (or a tie at the same `t`), same `t` and side.
fn assert_same_hit(got: Option<Hit>, want: Option<Hit>, context: &str) {
    match (got, want) {
        (None, None) => {}
        (Some(g), Some(w)) => {
            let tol = 1e-9 * w.t.abs().max(1.0);
            assert!((g.t - w.t).abs() <= tol, "{context}: t {} vs {}", g.t, w.t);
            if g.polygon == w.polygon {
                assert_eq!(g.front, w.front, "{context}: side");
            }
        }
        _ => panic!("{context}: {got:?} vs {want:?}"),
    }
}

fn compare_random_rays(vis: &dyn Visibility, reference: &BruteForce, rays: usize, seed: u64) {
    let mut rng = Pcg64Mcg::seed_from_u64(seed);
    for i in 0..rays {
        let ray = Ray::new(
            random_point(&mut rng, -0.2, 1.2),
            random_direction(&mut rng) * rng.random_range(0.1..3.0),
        );
        let t_max = if i % 3 == 0 {
            f64::INFINITY
        } else {
            rng.random_range(0.0..2.0)
        };
        let context = format!("{} ray {i}", vis.name());
        assert_same_hit(
            vis.intersect(&ray, 0.0, t_max),
            reference.intersect(&ray, 0.0, t_max),
            &context,
        );
        assert_eq!(
            vis.occluded(&ray, 0.0, t_max),
            reference.occluded(&ray, 0.0, t_max),
            "{context}: occlusion"
        );
    }
}

#[test]
fn random_triangles_and_quads_agree_with_brute_force() {
    for (count, size, seed) in [(40, 0.3, 1), (400, 0.1, 2), (2000, 0.03, 3)] {
        let shapes = random_scene(count, size, seed);
        let bvh = Bvh::new(&shapes);
        let reference = BruteForce::new(shapes);
        compare_random_rays(&bvh, &reference, 2000, seed + 100);
    }
}

#[test]
fn parallel_build_of_a_large_scene_agrees() {
    let shapes = random_scene(12_000, 0.02, 7);
    let bvh = Bvh::new(&shapes);
    let reference = BruteForce::new(shapes);
    compare_random_rays(&bvh, &reference, 300, 8);
}

#[test]
fn results_do_not_depend_on_thread_count() {
    let shapes = random_scene(10_000, 0.02, 11);
    let build = |threads| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("thread pool");
        pool.install(|| Bvh::new(&shapes))
    };
    let (one, two) = (build(1), build(2));
    assert_eq!(one.node_count(), two.node_count());
    let mut rng = Pcg64Mcg::seed_from_u64(12);
    for _ in 0..2000 {
        let ray = Ray::new(random_point(&mut rng, 0.0, 1.0), random_direction(&mut rng));
        assert_eq!(
            one.intersect(&ray, 0.0, f64::INFINITY),
            two.intersect(&ray, 0.0, f64::INFINITY)
        );
    }
}

#[test]
fn empty_scene_and_single_polygon() {
    let empty = Bvh::new(&[]);
    let ray = Ray::new(DVec3::ZERO, DVec3::X);
    assert!(empty.intersect(&ray, 0.0, f64::INFINITY).is_none());
    assert!(!empty.occluded(&ray, 0.0, f64::INFINITY));

    let quad = Shape::Quad([DVec3::ZERO, DVec3::X, DVec3::new(1.0, 1.0, 0.0), DVec3::Y]);
    let bvh = Bvh::new(&[quad]);
    let down = Ray::new(DVec3::new(0.25, 0.75, 2.0), DVec3::new(0.0, 0.0, -1.0));
    let hit = bvh.intersect(&down, 0.0, f64::INFINITY).expect("hit");
    assert!((hit.t - 2.0).abs() < 1e-12);
    assert_eq!(hit.polygon, 0);
    assert!(hit.front, "arrives against the +z normal");
    let uv = quad.parameters_of(down.at(hit.t));
    assert!((uv - DVec2::new(0.25, 0.75)).length() < 1e-9);
    let up = Ray::new(DVec3::new(0.5, 0.5, -1.0), DVec3::Z);
    assert!(!bvh.intersect(&up, 0.0, f64::INFINITY).expect("hit").front);
    assert!(!bvh.occluded(&up, 0.0, 0.999));
    assert!(bvh.occluded(&up, 0.0, 1.001));
    let miss = Ray::new(DVec3::new(1.5, 0.5, 1.0), DVec3::new(0.0, 0.0, -1.0));
    assert!(bvh.intersect(&miss, 0.0, f64::INFINITY).is_none());
}

/// A closed box of `n`×`n` quads per wall with inward normals.
fn closed_box(n: usize, corner: DVec3, size: f64) -> Vec<Shape> {
    let mut shapes = Vec::new();
    let axes = [DVec3::X, DVec3::Y, DVec3::Z];
    for axis in 0..3 {
        let (u, v) = (axes[(axis + 1) % 3], axes[(axis + 2) % 3]);
        for side in [0.0, 1.0] {
            for i in 0..n {
                for j in 0..n {
                    let p = |a: usize, b: usize| {
                        corner
                            + size
                                * (side * axes[axis]
                                    + (a as f64 / n as f64) * u
                                    + (b as f64 / n as f64) * v)
                    };
                    let q = Shape::Quad([p(i, j), p(i + 1, j), p(i + 1, j + 1), p(i, j + 1)]);
                    shapes.push(if side == 0.0 { q } else { q.flipped() });
                }
            }
        }
    }
    shapes
}

#[test]
fn segments_between_surface_points_are_not_blocked_by_their_own_polygons() {
    // Far from the origin too, where f32 coordinates are coarse.
    for corner in [DVec3::ZERO, DVec3::new(1000.0, -2000.0, 500.0)] {
        // A closed convex box: nothing inside blocks any segment between two wall points.
        let shapes = closed_box(4, corner, 1.0);
        let bvh = Bvh::new(&shapes);
        let segments = random_segments(&shapes, 20_000, 5);
        let blocked = segments
            .iter()
            .filter(|(a, b)| bvh.segment_occluded(*a, *b))
            .count();
        assert_eq!(blocked, 0, "box at {corner}");
        // Points on adjacent walls right next to their shared edge, and on a floor quad and its coplanar
        // neighbour (the wall quads are 0.25 wide).
        let e = 1e-4;
        let pairs = [
            (
                corner + DVec3::new(0.0, 0.5, e),
                corner + DVec3::new(e, 0.5, 0.0),
            ),
            (
                corner + DVec3::new(0.3, 0.0, 0.2),
                corner + DVec3::new(0.0, 0.7, 0.9),
            ),
            (
                corner + DVec3::new(0.2, 0.1, 0.0),
                corner + DVec3::new(0.3, 0.9, 0.0),
            ),
            (
                corner + DVec3::new(0.2499, 0.1, 0.0),
                corner + DVec3::new(0.2501, 0.1, 0.0),
            ),
        ];
        for (a, b) in pairs {
            assert!(!bvh.segment_occluded(a, b), "{a} to {b}");
            assert!(!bvh.segment_occluded(b, a), "{b} to {a}");
        }
    }
}

#[test]
fn rays_starting_on_surfaces_agree_with_brute_force() {
    let mut shapes = random_scene(300, 0.15, 21);
    shapes.extend(closed_box(3, DVec3::splat(-0.5), 2.0));
    let bvh = Bvh::new(&shapes);
    let reference = BruteForce::new(shapes.clone());
    let segments = random_segments(&shapes, 3000, 22);
    let mut blocked = 0;
    for (i, (a, b)) in segments.iter().enumerate() {
        let occluded = bvh.segment_occluded(*a, *b);
        assert_eq!(occluded, reference.segment_occluded(*a, *b), "segment {i}");
        blocked += occluded as usize;
        let ray = Ray::new(*a, *b - *a);
        assert_same_hit(
            bvh.intersect(&ray, 1e-5, f64::INFINITY),
            reference.intersect(&ray, 1e-5, f64::INFINITY),
            &format!("surface ray {i}"),
        );
    }
    assert!(
        blocked > 100 && blocked < 2900,
        "a mixed workload: {blocked}"
    );
}

#[test]
fn axis_aligned_flat_scenes_agree_with_brute_force() {
    let mut rng = Pcg64Mcg::seed_from_u64(31);
    // Every polygon lies in a plane x, y or z = const: all boxes are flat.
    let mut shapes = Vec::new();
    for k in 0..600 {
        let axis = k % 3;
        let level = (rng.random_range(0..5) as f64) * 0.25;
        let (a, b) = (rng.random_range(0.0..0.9), rng.random_range(0.0..0.9));
        let s = rng.random_range(0.02..0.1);
        let p = |x: f64, y: f64| {
            let mut v = [0.0; 3];
            v[axis] = level;
            v[(axis + 1) % 3] = x;
            v[(axis + 2) % 3] = y;
            DVec3::from_array(v)
        };
        shapes.push(if k % 2 == 0 {
            Shape::Quad([p(a, b), p(a + s, b), p(a + s, b + s), p(a, b + s)])
        } else {
            Shape::Triangle([p(a, b), p(a + s, b), p(a, b + s)])
        });
    }
    // Also a scene that is a single plane.
    let plane: Vec<Shape> = shapes
        .iter()
        .filter(|s| s.vertices().iter().all(|v| v.z == 0.5))
        .copied()
        .collect();
    assert!(plane.len() > 10);
    for scene in [shapes, plane] {
        let bvh = Bvh::new(&scene);
        let reference = BruteForce::new(scene);
        compare_random_rays(&bvh, &reference, 3000, 32);
        // Axis-parallel rays: zero direction components.
        let mut rng = Pcg64Mcg::seed_from_u64(33);
        for i in 0..1500 {
            let mut d = DVec3::ZERO;
            d[i % 3] = if i % 2 == 0 { 1.0 } else { -1.0 };
            let ray = Ray::new(random_point(&mut rng, -0.1, 1.1), d);
            assert_same_hit(
                bvh.intersect(&ray, 0.0, f64::INFINITY),
                reference.intersect(&ray, 0.0, f64::INFINITY),
                &format!("axis ray {i}"),
            );
            assert_eq!(
                bvh.occluded(&ray, 0.0, 0.5),
                reference.occluded(&ray, 0.0, 0.5)
            );
        }
    }
}

#[cfg(feature = "embree")]
#[test]
fn embree_agrees_with_brute_force() {
    use radiosity::visibility::embree::EmbreeScene;
    let shapes = random_scene(400, 0.1, 41);
    let embree = EmbreeScene::new(&shapes).expect("Embree scene");
    let reference = BruteForce::new(shapes.clone());
    let mut rng = Pcg64Mcg::seed_from_u64(42);
    let mut mismatches = 0;
    let rays = 3000;
    for _ in 0..rays {
        let ray = Ray::new(
            random_point(&mut rng, -0.2, 1.2),
            random_direction(&mut rng),
        );
        let (got, want) = (
            embree.intersect(&ray, 0.0, f64::INFINITY),
            reference.intersect(&ray, 0.0, f64::INFINITY),
        );
        // Embree is single precision: rays grazing an edge may go either way.
        match (got, want) {
            (Some(g), Some(w)) if g.polygon == w.polygon => {
                assert!((g.t - w.t).abs() < 1e-4 * w.t.max(1.0));
                assert_eq!(g.front, w.front);
            }
            (None, None) => {}
            _ => mismatches += 1,
        }
        if embree.occluded(&ray, 0.0, 1.0) != reference.occluded(&ray, 0.0, 1.0) {
            mismatches += 1;
        }
    }
    assert!(mismatches <= 3, "{mismatches} mismatches in {rays} rays");
    // Single precision also puts the polygons at a short segment's ends inside its trimmed interval now
    // and then: a few spurious blockers are expected, never a missed one.
    let segments = random_segments(&shapes, 2000, 43);
    let missed = segments
        .iter()
        .filter(|(a, b)| !embree.segment_occluded(*a, *b) && reference.segment_occluded(*a, *b))
        .count();
    assert_eq!(missed, 0);
    let differ = segments
        .iter()
        .filter(|(a, b)| embree.segment_occluded(*a, *b) != reference.segment_occluded(*a, *b))
        .count();
    assert!(differ <= 20, "{differ} segment mismatches");
}

/// A bumpy `n`×`n` height field around `corner`: triangles and (non-planar) quads sharing every vertex and
/// edge with their neighbours, with the vertex grid returned too.
fn height_field(n: usize, corner: DVec3, seed: u64) -> (Vec<Shape>, Vec<DVec3>) {
    let mut rng = Pcg64Mcg::seed_from_u64(seed);
    let grid: Vec<DVec3> = (0..(n + 1) * (n + 1))
        .map(|k| {
            let (i, j) = ((k % (n + 1)) as f64, (k / (n + 1)) as f64);
            corner + DVec3::new(i, j, rng.random_range(-0.3..0.3)) / n as f64
        })
        .collect();
    let at = |i: usize, j: usize| grid[j * (n + 1) + i];
    let mut shapes = Vec::new();
    for j in 0..n {
        for i in 0..n {
            let q = [at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1)];
            if (i + j) % 3 == 0 {
                shapes.push(Shape::Quad(q));
            } else {
                shapes.push(Shape::Triangle([q[0], q[1], q[2]]));
                shapes.push(Shape::Triangle([q[0], q[2], q[3]]));
            }
        }
    }
    (shapes, grid)
}

proptest::proptest! {
    #![proptest_config(common::proptest_config(24))]

    /// Rays through shared vertices, along and across shared edges, and grazing the surface agree with the
    /// exhaustive reference, near the origin and far from it (where `f32` rounding is coarsest).
    #[test]
    fn rays_grazing_shared_edges_and_vertices_agree_with_brute_force(
        seed in 0u64..1_000_000,
        far in proptest::bool::ANY,
    ) {
        let corner = if far { DVec3::new(3e4, -2e4, 1e4) } else { DVec3::ZERO };
        let (shapes, grid) = height_field(8, corner, seed);
        let bvh = Bvh::new(&shapes);
        let reference = BruteForce::new(shapes);
        let mut rng = Pcg64Mcg::seed_from_u64(seed ^ 0x5eed);
        for i in 0..300 {
            let k = rng.random_range(0..grid.len());
            let a = grid[k];
            // Targets: a shared vertex, a point on a grid edge (to the next vertex in the row or column),
            // or on the segment between two random vertices.
            let target = match i % 3 {
                0 => a,
                1 => {
                    let next = grid[(k + if i % 2 == 0 { 1 } else { 9 }) % grid.len()];
                    a + (next - a) * rng.random::<f64>()
                }
                _ => a + (grid[rng.random_range(0..grid.len())] - a) * rng.random::<f64>(),
            };
            // From above, from below, or almost in the surface's mean plane (grazing).
            let lift = [1.0, -1.0, 1e-3][(i / 3) % 3] * rng.random_range(0.05..1.0);
            let origin = target
                + DVec3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), lift);
            let ray = Ray::new(origin, target - origin);
            let context = format!("seed {seed} far {far} ray {i}");
            for t_max in [1.0, 2.0, f64::INFINITY] {
                assert_same_hit(
                    bvh.intersect(&ray, 0.0, t_max),
                    reference.intersect(&ray, 0.0, t_max),
                    &context,
                );
                proptest::prop_assert_eq!(
                    bvh.occluded(&ray, 0.0, t_max),
                    reference.occluded(&ray, 0.0, t_max),
                    "{}: occlusion to {}", context, t_max
                );
            }
        }
    }
}
