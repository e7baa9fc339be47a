//! Smooth shading (vertex radiosity): exactness on linear and constant data, and continuity across leaf
//! edges with T-vertices, within a patch and across coplanar patches.

use radiosity::color::Rgb;
use radiosity::geometry::{DVec2, DVec3, Shape};
use radiosity::hierarchy::{ElementId, Hierarchy};
use radiosity::output::VertexRadiosity;
use radiosity::scene::{Material, Object, Polygon, Scene};

fn scene(shapes: &[(Shape, usize)], materials: Vec<Material>) -> Scene {
    Scene {
        polygons: shapes
            .iter()
            .map(|&(shape, material)| Polygon {
                shape,
                material,
                object: 0,
                two_sided: false,
                under_contact: false,
            })
            .collect(),
        materials,
        objects: vec![Object {
            name: "test".into(),
        }],
        ..Default::default()
    }
}

fn grey(name: &str) -> Material {
    Material::diffuse(name, Rgb::splat(0.5))
}

fn unit_square() -> Shape {
    Shape::Quad([DVec3::ZERO, DVec3::X, DVec3::new(1.0, 1.0, 0.0), DVec3::Y])
}

/// Subdivides the leaf of `patch` containing `p` until it is at `level`.
fn refine_at(h: &mut Hierarchy, patch: u32, p: DVec3, level: u16) {
    loop {
        let leaf = h.locate(patch, p);
        if h.element(leaf).level >= level {
            return;
        }
        h.subdivide(leaf);
    }
}

/// Deterministic "arbitrary" leaf values: a hash of the leaf centroid.
fn scrambled(c: DVec3) -> Rgb {
    let f = |k: f64| {
        1.0 + ((c.x * 12.9898 + c.y * 78.233 + c.z * 37.719 + k).sin() * 43758.5453)
            .fract()
            .abs()
    };
    Rgb::new(f(0.0), 2.0 * f(1.0), 3.0 * f(2.0))
}

fn set_leaves(h: &mut Hierarchy, value: impl Fn(DVec3) -> Rgb) {
    for leaf in h.leaves() {
        let c = h.element(leaf).shape().centroid();
        h.radiance_mut(leaf)[0] = value(c);
    }
}

/// Signed in-plane distance of `p` inside a convex shape (negative outside).
fn margin(shape: &Shape, p: DVec3) -> f64 {
    let v = shape.vertices();
    let n = shape.normal();
    (0..v.len())
        .map(|k| {
            n.cross(v[(k + 1) % v.len()] - v[k])
                .normalize()
                .dot(p - v[k])
        })
        .fold(f64::INFINITY, f64::min)
}

fn rel_diff(a: Rgb, b: Rgb) -> f64 {
    let d = (a - b).map(f64::abs).max_channel();
    d / a.max_channel().abs().max(b.max_channel().abs()).max(1e-30)
}

/// Samples every leaf edge of `patches` (at dyadic points, which include all T-vertices, and at generic
/// points), steps a tiny distance to both sides and compares the interpolated values, which must agree.
/// Returns the number of comparisons made.
fn check_continuity(h: &Hierarchy, vr: &VertexRadiosity, patches: &[u32]) -> usize {
    let (compared, worst) = edge_differences(h, patches, |leaf, p| vr.evaluate(h, leaf, p));
    assert!(worst < 1e-6, "worst relative difference {worst:e}");
    compared
}

/// [`check_continuity`]'s comparisons of a shading `value(leaf, point)`: their number and the largest
/// relative difference across an edge.
fn edge_differences(
    h: &Hierarchy,
    patches: &[u32],
    value: impl Fn(ElementId, DVec3) -> Rgb,
) -> (usize, f64) {
    let delta = 1e-10;
    let mut params: Vec<f64> = (1..32).map(|k| k as f64 / 32.0).collect();
    params.extend([0.1234, 0.377, 0.618, 0.9001, 1e-6, 1.0 - 1e-6]);
    let mut compared = 0;
    let mut worst = 0.0f64;
    for &patch in patches {
        let mut leaves = Vec::new();
        h.collect_leaves(h.patches[patch as usize].root, &mut leaves);
        for leaf in leaves {
            let shape = *h.element(leaf).shape();
            let n = shape.normal();
            let v = shape.vertices();
            for k in 0..v.len() {
                let (a, b) = (v[k], v[(k + 1) % v.len()]);
                let inward = n.cross(b - a).normalize();
                for &s in &params {
                    let q = a + s * (b - a);
                    let (inside, outside) = (q + delta * inward, q - delta * inward);
                    let Some(&other) = patches
                        .iter()
                        .find(|&&p| margin(h.patch_shape(p), outside) > 0.0)
                    else {
                        continue; // the edge is on the boundary of the surface
                    };
                    let neighbour_leaf: ElementId = h.locate(other, outside);
                    assert_ne!(neighbour_leaf, leaf);
                    let d = rel_diff(value(leaf, inside), value(neighbour_leaf, outside));
                    worst = worst.max(d);
                    compared += 1;
                }
            }
        }
    }
    eprintln!("{compared} comparisons, worst relative difference {worst:e}");
    (compared, worst)
}

#[test]
fn t_vertices_within_a_patch_leave_no_crack() {
    let s = scene(&[(unit_square(), 0)], vec![grey("floor")]);
    let mut h = Hierarchy::new(&s, radiosity::bases::BasisKind::Constant);
    // Coarse leaves beside a refined corner, refined down to three levels: several T-vertices per edge.
    h.subdivide(h.patches[0].root);
    refine_at(&mut h, 0, DVec3::new(0.3, 0.3, 0.0), 3);
    refine_at(&mut h, 0, DVec3::new(0.49, 0.1, 0.0), 4);
    refine_at(&mut h, 0, DVec3::new(0.7, 0.2, 0.0), 2);
    set_leaves(&mut h, scrambled);
    let vr = VertexRadiosity::new(&h);
    assert!(vr.fanned_leaf_count() >= 2, "the test needs T-vertices");
    assert!(check_continuity(&h, &vr, &[0]) > 500);
}

#[test]
fn t_vertices_across_coplanar_patches_leave_no_crack() {
    // A floor quad triangulated into two one-sided triangles of the same material, refined differently:
    // one smoothing group, continuous across the diagonal.
    let (a, b, c, d) = (
        DVec3::ZERO,
        DVec3::new(2.0, 0.0, 0.0),
        DVec3::new(2.0, 1.0, 0.0),
        DVec3::new(0.0, 1.0, 0.0),
    );
    let s = scene(
        &[
            (Shape::Triangle([a, b, c]), 0),
            (Shape::Triangle([a, c, d]), 0),
        ],
        vec![grey("floor")],
    );
    let mut h = Hierarchy::new(&s, radiosity::bases::BasisKind::Constant);
    refine_at(&mut h, 0, DVec3::new(1.0, 0.5, 0.0), 3);
    refine_at(&mut h, 0, DVec3::new(1.5, 0.4, 0.0), 4);
    refine_at(&mut h, 1, DVec3::new(0.3, 0.5, 0.0), 1);
    set_leaves(&mut h, scrambled);
    let vr = VertexRadiosity::new(&h);
    assert!(vr.fanned_leaf_count() >= 1);
    assert!(check_continuity(&h, &vr, &[0, 1]) > 300);
}

#[test]
fn smoothing_stops_at_material_and_orientation_changes() {
    // A floor (radiance 1) and a wall (radiance 5) meeting at an edge, and a differently coloured floor tile
    // beside the first: neither leaks into the floor's values.
    let floor = unit_square();
    let wall = Shape::Quad([
        DVec3::ZERO,
        DVec3::Y,
        DVec3::new(0.0, 1.0, 1.0),
        DVec3::new(0.0, 0.0, 1.0),
    ]);
    let tile = Shape::Quad([
        DVec3::X,
        DVec3::new(2.0, 0.0, 0.0),
        DVec3::new(2.0, 1.0, 0.0),
        DVec3::new(1.0, 1.0, 0.0),
    ]);
    let s = scene(
        &[(floor, 0), (wall, 0), (tile, 1)],
        vec![
            grey("grey"),
            Material::diffuse("red", Rgb::new(0.7, 0.1, 0.1)),
        ],
    );
    let mut h = Hierarchy::new(&s, radiosity::bases::BasisKind::Constant);
    for patch in 0..3 {
        refine_at(&mut h, patch, DVec3::new(0.01, 0.01, 0.0), 3);
    }
    set_leaves(&mut h, |c| {
        if c.z > 1e-9 {
            Rgb::splat(5.0)
        } else if c.x > 1.0 {
            Rgb::splat(9.0)
        } else {
            Rgb::splat(1.0)
        }
    });
    let vr = VertexRadiosity::new(&h);
    for (x, y) in [
        (0.0, 0.5),
        (1e-9, 1e-9),
        (1.0, 0.5),
        (0.999, 0.001),
        (0.5, 0.5),
    ] {
        let p = DVec3::new(x, y, 0.0);
        let leaf = h.locate(0, p);
        assert_eq!(vr.evaluate(&h, leaf, p), Rgb::splat(1.0), "at ({x}, {y})");
    }
}

#[test]
fn linear_radiance_is_reproduced_inside_and_constant_everywhere() {
    let s = scene(&[(unit_square(), 0)], vec![grey("floor")]);
    let mut h = Hierarchy::new(&s, radiosity::bases::BasisKind::Constant);
    for _ in 0..3 {
        for leaf in h.leaves() {
            h.subdivide(leaf);
        }
    }
    let ramp = |p: DVec3| Rgb::new(1.0 + 2.0 * p.x, 3.0 - p.x, 0.5 + 4.0 * p.x);
    set_leaves(&mut h, ramp);
    let vr = VertexRadiosity::new(&h);
    assert_eq!(vr.vertex_count(), 81);
    // Leaves away from the patch border have symmetric vertex neighbourhoods: the interpolation is the ramp.
    for leaf in h.leaves() {
        let shape = *h.element(leaf).shape();
        let b = shape.bounds();
        if b.min.x < 0.1 || b.max.x > 0.9 || b.min.y < 0.1 || b.max.y > 0.9 {
            continue;
        }
        for p in shape.vertices().iter().copied().chain([shape.centroid()]) {
            let d = rel_diff(vr.evaluate(&h, leaf, p), ramp(p));
            assert!(d < 1e-12, "{p} {d}");
        }
    }

    // A constant solution stays exactly constant with T-vertices and fans.
    let mut h = Hierarchy::new(&s, radiosity::bases::BasisKind::Constant);
    refine_at(&mut h, 0, DVec3::new(0.2, 0.7, 0.0), 4);
    set_leaves(&mut h, |_| Rgb::new(0.25, 0.5, 2.0));
    let vr = VertexRadiosity::new(&h);
    assert!(vr.fanned_leaf_count() > 0);
    for leaf in h.leaves() {
        let shape = *h.element(leaf).shape();
        for p in [
            shape.centroid(),
            shape.vertices()[1] * 0.9 + shape.centroid() * 0.1,
        ] {
            let d = rel_diff(vr.evaluate(&h, leaf, p), Rgb::new(0.25, 0.5, 2.0));
            assert!(d < 1e-14);
        }
    }
}

#[test]
fn vertex_values_are_area_weighted_and_t_vertices_interpolated() {
    // The root split in four, the lower-left child split again: its corner (0.5, 0.25) is a T-vertex
    // inside the left edge of the lower-right child. Check the numbers by hand.
    let s = scene(&[(unit_square(), 0)], vec![grey("floor")]);
    let mut h = Hierarchy::new(&s, radiosity::bases::BasisKind::Constant);
    let children = h.subdivide(h.patches[0].root);
    // children: [0,.5]^2, [.5,1]x[0,.5], [.5,1]^2, [0,.5]x[.5,1]
    let grand = h.subdivide(children[0]);
    for (i, &c) in children.iter().enumerate() {
        h.radiance_mut(c)[0] = Rgb::splat(10.0 * (i as f64 + 1.0));
    }
    for (i, &g) in grand.iter().enumerate() {
        h.radiance_mut(g)[0] = Rgb::splat(i as f64 + 1.0);
    }
    let vr = VertexRadiosity::new(&h);
    let at = |x: f64, y: f64| {
        let p = DVec3::new(x, y, 0.0);
        vr.evaluate(&h, h.locate(0, p), p).r
    };
    // Centre vertex (0.5, 0.5): grandchild 2 (area 1/16, value 3), children 1, 2, 3 (area 1/4 each).
    let centre = (3.0 / 16.0 + (20.0 + 30.0 + 40.0) / 4.0) / (1.0 / 16.0 + 3.0 / 4.0);
    assert!((at(0.5, 0.5) - centre).abs() < 1e-12);
    // Vertex (0.5, 0): grandchild 1 (value 2) and child 1 (value 20).
    let bottom = (2.0 / 16.0 + 20.0 / 4.0) / (1.0 / 16.0 + 1.0 / 4.0);
    // The T-vertex (0.5, 0.25) lies inside child 1's left edge: the mean of its end points.
    assert!((at(0.5, 0.25) - 0.5 * (bottom + centre)).abs() < 1e-12);
    assert!((at(0.5 + 1e-12, 0.25) - 0.5 * (bottom + centre)).abs() < 1e-9);
}

/// Gives every leaf arbitrary coefficients of its basis expansion (all of them, not only the mean).
fn scramble_expansions(h: &mut Hierarchy) {
    scramble_expansions_by(h, |k, value| {
        if k == 0 {
            value * 4.0
        } else {
            value - Rgb::splat(1.5)
        }
    });
}

/// Sets coefficient `k` of every leaf to `coefficient(k, v)`, `v` an arbitrary value in [1, 2] ×
/// (1, 2, 3) drawn from the leaf's centroid and `k`.
fn scramble_expansions_by(h: &mut Hierarchy, coefficient: impl Fn(usize, Rgb) -> Rgb) {
    for leaf in h.leaves() {
        let c = h.element(leaf).shape().centroid();
        for (k, value) in h.radiance_mut(leaf).iter_mut().enumerate() {
            *value = coefficient(k, scrambled(c + DVec3::splat(k as f64)));
        }
    }
}

/// A refined unit square with T-vertices of several depths.
fn refined_square(basis: radiosity::bases::BasisKind) -> Hierarchy {
    let s = scene(&[(unit_square(), 0)], vec![grey("floor")]);
    let mut h = Hierarchy::new(&s, basis);
    h.subdivide(h.patches[0].root);
    refine_at(&mut h, 0, DVec3::new(0.3, 0.3, 0.0), 3);
    refine_at(&mut h, 0, DVec3::new(0.49, 0.1, 0.0), 4);
    refine_at(&mut h, 0, DVec3::new(0.7, 0.2, 0.0), 2);
    h
}

/// The basis' stored corner values give every leaf's expansion at its shape's corners (in the order of
/// the shape's vertices), on quads and triangles of every basis: what continuous shading reads there
/// instead of evaluating the basis at each vertex for each sample.
#[test]
fn corner_values_are_the_expansion_at_the_shape_corners() {
    let triangle = Shape::Triangle([
        DVec3::new(2.0, 0.0, 0.0),
        DVec3::new(3.5, 0.2, 0.0),
        DVec3::new(2.3, 1.4, 0.0),
    ]);
    let s = scene(&[(unit_square(), 0), (triangle, 0)], vec![grey("floor")]);
    for basis in radiosity::bases::BasisKind::ALL {
        let mut h = Hierarchy::new(&s, basis);
        for patch in 0..2 {
            h.subdivide(h.patches[patch].root);
        }
        refine_at(&mut h, 1, DVec3::new(2.4, 0.4, 0.0), 3);
        scramble_expansions(&mut h);
        for leaf in h.leaves() {
            let shape = *h.element(leaf).shape();
            for (k, &corner) in shape.vertices().iter().enumerate() {
                let d = rel_diff(h.radiance_at_corner(leaf, k), h.radiance_at(leaf, corner));
                assert!(d < 1e-9, "{basis:?}, leaf {leaf}, corner {k}: {d:e}");
            }
        }
    }
}

#[test]
fn continuous_shading_leaves_no_step_between_linear_and_bilinear_leaves() {
    for basis in [
        radiosity::bases::BasisKind::Linear,
        radiosity::bases::BasisKind::Bilinear,
    ] {
        let mut h = refined_square(basis);
        scramble_expansions(&mut h);
        let vr = VertexRadiosity::new(&h);
        assert!(vr.fanned_leaf_count() >= 2, "the test needs T-vertices");
        // The expansion itself jumps at the leaves' edges; the continuous shading does not.
        let (_, jump) = edge_differences(&h, &[0], |leaf, p| h.radiance_at(leaf, p));
        assert!(jump > 0.1, "{basis:?}: the test needs steps ({jump})");
        let (compared, worst) = edge_differences(&h, &[0], |leaf, p| {
            vr.evaluate_continuous(&h, leaf, p, f64::INFINITY)
        });
        assert!(compared > 500 && worst < 1e-6, "{basis:?}: {worst:e}");
    }
}

#[test]
fn continuous_shading_is_the_expansion_where_neighbours_agree() {
    // Every leaf holds the exact restriction of one quadratic over the square (pushed down from the
    // root, which the quadtree's affine child maps keep exact), positive everywhere: the averaged
    // vertex values are the polynomial's own, and the continuous shading is the expansion itself.
    let mut h = refined_square(radiosity::bases::BasisKind::Quadratic);
    let root = h.patches[0].root;
    let field = |p: DVec3| Rgb::new(2.0 + p.x * p.y, 3.0 - p.x * p.x, 1.0 + p.y * (1.0 - p.y));
    let square = *h.element(root).shape();
    let mut moments = vec![Rgb::BLACK; h.basis_size()];
    let rule = radiosity::geometry::cubature::rule(square.domain(), 8);
    let mut phi = vec![0.0; h.basis_size()];
    for node in radiosity::geometry::cubature::nodes_on(&square, rule) {
        h.basis
            .eval(square.domain(), square.parameters_of(node.point), &mut phi);
        for (m, &b) in moments.iter_mut().zip(&phi) {
            *m += field(node.point) * (b * node.weight / h.element(root).area);
        }
    }
    h.radiance_mut(root).copy_from_slice(&moments);
    let mut stack = vec![root];
    while let Some(id) = stack.pop() {
        let children = h.element(id).children.clone();
        let parent = h.radiance(id).to_vec();
        for (k, &child) in children.iter().enumerate() {
            let mut out = vec![Rgb::BLACK; parent.len()];
            h.basis.push_rgb(square.domain(), k, &parent, &mut out);
            h.radiance_mut(child).copy_from_slice(&out);
            stack.push(child);
        }
    }
    let vr = VertexRadiosity::new(&h);
    assert!(vr.fanned_leaf_count() >= 2);
    for leaf in h.leaves() {
        let shape = *h.element(leaf).shape();
        for p in [
            shape.centroid(),
            shape.vertices()[1] * 0.7 + shape.centroid() * 0.3,
            shape.vertices()[3] * 0.95 + shape.vertices()[0] * 0.05,
        ] {
            assert!(rel_diff(h.radiance_at(leaf, p), field(p)) < 1e-9, "{p}");
            let d = rel_diff(vr.evaluate_continuous(&h, leaf, p, f64::INFINITY), field(p));
            assert!(d < 1e-9, "leaf {leaf} at {p}: {d:e}");
        }
    }
}

/// The unit square split once, its left half's leaves at radiance `left` and its right half's at
/// `right` (constant expansions on the linear basis).
fn two_halves(left: f64, right: f64) -> Hierarchy {
    let s = scene(&[(unit_square(), 0)], vec![grey("floor")]);
    let mut h = Hierarchy::new(&s, radiosity::bases::BasisKind::Linear);
    h.subdivide(h.patches[0].root);
    for leaf in h.leaves() {
        let value = if h.element(leaf).shape().centroid().x < 0.5 {
            left
        } else {
            right
        };
        let coefficients = h.radiance_mut(leaf);
        coefficients.fill(Rgb::BLACK);
        coefficients[0] = Rgb::splat(value);
        let centre = h.element(leaf).shape().centroid();
        assert!((h.radiance_at(leaf, centre).r - value).abs() < 1e-12);
    }
    h
}

/// Seamless shading removes a step of 25% between the halves (elements of a dim face that read as
/// blocks) and keeps one of a factor 2.5 (a steep change the solution resolved, a lamp's outline),
/// which continuous shading smooths over. `SEAMLESS_STEP` is 25%, measured between a leaf's value at
/// a vertex and the other leaves' there relative to the larger (20% and 60% here, from both sides):
/// wholly removed below it, kept from twice it.
#[test]
fn seamless_shading_removes_small_steps_and_keeps_large_ones() {
    use radiosity::output::render::{Shading, SEAMLESS_STEP};
    let below = Shading::Seamless.steps_removed_below().unwrap();
    assert_eq!(below, SEAMLESS_STEP);
    let small = two_halves(1.0, 1.25);
    let vr = VertexRadiosity::new(&small);
    let (_, jump) = edge_differences(&small, &[0], |leaf, p| small.radiance_at(leaf, p));
    assert!(jump > 0.15, "the test needs a step ({jump})");
    let (compared, worst) = edge_differences(&small, &[0], |leaf, p| {
        vr.evaluate_continuous(&small, leaf, p, below)
    });
    assert!(compared > 100 && worst < 1e-9, "small step left: {worst:e}");
    let large = two_halves(1.0, 2.5);
    let vr = VertexRadiosity::new(&large);
    let (_, step) = edge_differences(&large, &[0], |leaf, p| large.radiance_at(leaf, p));
    let (_, kept) = edge_differences(&large, &[0], |leaf, p| {
        vr.evaluate_continuous(&large, leaf, p, below)
    });
    assert!(
        step > 0.5 && (kept - step).abs() < 1e-9,
        "large step {step} became {kept}"
    );
    let (_, smoothed) = edge_differences(&large, &[0], |leaf, p| {
        vr.evaluate_continuous(&large, leaf, p, f64::INFINITY)
    });
    assert!(
        smoothed < 1e-9,
        "continuous shading keeps a step: {smoothed:e}"
    );
}

/// The area mean of `value` over leaf `leaf`: the centroid rule on `n` × `n` cells of its parameter
/// domain weighted by the Jacobian (on a triangle, its `n²` congruent sub-triangles). Second order,
/// also for a field with kinks (a fanned leaf's interpolation).
fn leaf_mean(h: &Hierarchy, leaf: ElementId, n: usize, value: impl Fn(DVec3) -> Rgb) -> Rgb {
    let shape = *h.element(leaf).shape();
    let cell = |a: f64, b: f64| radiosity::geometry::DVec2::new(a / n as f64, b / n as f64);
    let mut centroids = Vec::new();
    for i in 0..n {
        for j in 0..n {
            let (x, y) = (i as f64, j as f64);
            match shape {
                Shape::Quad(_) => centroids.push(cell(x + 0.5, y + 0.5)),
                Shape::Triangle(_) if i + j < n => {
                    centroids.push(cell(x + 1.0 / 3.0, y + 1.0 / 3.0));
                    if i + j + 1 < n {
                        centroids.push(cell(x + 2.0 / 3.0, y + 2.0 / 3.0));
                    }
                }
                Shape::Triangle(_) => {}
            }
        }
    }
    let (mut sum, mut weight) = (Rgb::BLACK, 0.0);
    for uv in centroids {
        let w = shape.jacobian(uv);
        sum += value(shape.point_at(uv)) * w;
        weight += w;
    }
    sum / weight
}

/// Continuous and seamless shading keep every leaf's mean radiance, the solution's power on it: the
/// interpolated step corrections move a leaf's mean, and a bubble (zero on the leaf's edges, so still
/// continuous) gives it back. Quads with and without T-vertices, a refined triangle, linear and
/// quadratic expansions with steps of tens of percent between neighbours.
/// A unit square refined unevenly (T-vertices) beside a refined triangle, with scrambled expansions
/// of means 11 to 16 and gradients of a few tenths: positive everywhere, steps of up to ~20%.
fn uneven_square_and_triangle(basis: radiosity::bases::BasisKind) -> (Hierarchy, VertexRadiosity) {
    let triangle = Shape::Triangle([
        DVec3::new(2.0, 0.0, 0.0),
        DVec3::new(3.5, 0.2, 0.0),
        DVec3::new(2.3, 1.4, 0.0),
    ]);
    let s = scene(&[(unit_square(), 0), (triangle, 0)], vec![grey("floor")]);
    let mut h = Hierarchy::new(&s, basis);
    h.subdivide(h.patches[0].root);
    refine_at(&mut h, 0, DVec3::new(0.3, 0.3, 0.0), 3);
    refine_at(&mut h, 0, DVec3::new(0.7, 0.2, 0.0), 2);
    refine_at(&mut h, 1, DVec3::new(2.4, 0.4, 0.0), 2);
    scramble_expansions_by(&mut h, |k, value| {
        if k == 0 {
            Rgb::splat(10.0) + value
        } else {
            (value - Rgb::splat(1.5)) * 0.3
        }
    });
    let vr = VertexRadiosity::new(&h);
    assert!(vr.fanned_leaf_count() >= 2, "the test needs T-vertices");
    (h, vr)
}

#[test]
fn continuous_shading_keeps_each_leaf_mean() {
    for basis in [
        radiosity::bases::BasisKind::Linear,
        radiosity::bases::BasisKind::Quadratic,
    ] {
        let (h, vr) = uneven_square_and_triangle(basis);
        let mut moved = 0.0f64;
        for leaf in h.leaves() {
            let own = leaf_mean(&h, leaf, 200, |p| h.radiance_at(leaf, p));
            for below in [f64::INFINITY, 0.05] {
                let shaded = leaf_mean(&h, leaf, 200, |p| {
                    vr.evaluate_continuous(&h, leaf, p, below)
                });
                let d = rel_diff(shaded, own);
                assert!(d < 2e-4, "{basis:?} leaf {leaf}, below {below}: {d:e}");
            }
            // What the corrections alone do to the mean (the smooth vertex interpolation differs
            // from the expansion by them): the test must see it.
            let smooth = leaf_mean(&h, leaf, 50, |p| vr.evaluate(&h, leaf, p));
            moved = moved.max(rel_diff(smooth, own));
        }
        assert!(
            moved > 1e-2,
            "{basis:?}: the corrections hardly move a mean ({moved:e})"
        );
    }
}

/// A surface cut along a contact outline (`Polygon::under_contact`: the piece under an object lying
/// on it) keeps its step there under continuous shading, where the radiance really jumps; the same two
/// pieces without the flag are one smooth surface.
#[test]
fn continuous_shading_keeps_the_step_at_a_contact_outline() {
    let right = Shape::Quad([
        DVec3::X,
        DVec3::new(2.0, 0.0, 0.0),
        DVec3::new(2.0, 1.0, 0.0),
        DVec3::new(1.0, 1.0, 0.0),
    ]);
    for under in [false, true] {
        let mut s = scene(&[(unit_square(), 0), (right, 0)], vec![grey("floor")]);
        s.polygons[1].under_contact = under;
        let mut h = Hierarchy::new(&s, radiosity::bases::BasisKind::Linear);
        for patch in 0..2 {
            h.subdivide(h.patches[patch].root);
        }
        for leaf in h.leaves() {
            let value = if h.element(leaf).shape().centroid().x < 1.0 {
                1.0
            } else {
                3.0
            };
            let coefficients = h.radiance_mut(leaf);
            coefficients.fill(Rgb::BLACK);
            coefficients[0] = Rgb::splat(value);
        }
        let vr = VertexRadiosity::new(&h);
        let (compared, step) = edge_differences(&h, &[0, 1], |leaf, p| {
            vr.evaluate_continuous(&h, leaf, p, f64::INFINITY)
        });
        assert!(compared > 50);
        if under {
            // Each side keeps its own value along the outline: 1 against 3.
            assert!((step - 2.0 / 3.0).abs() < 1e-9, "step {step}");
        } else {
            assert!(step < 1e-6, "step {step:e}");
        }
    }
}

/// A render keeps one [`LeafCorrections`] for a run of samples: whatever leaves and step gates it saw
/// before, the value at a point is the one a fresh memo gives, bit for bit (samples over leaves
/// with T-vertices and without, triangles and quads, alternating and repeating leaves and gates).
#[test]
fn continuous_shading_reuses_a_leafs_corrections_exactly() {
    use radiosity::output::mesh_values::LeafCorrections;
    let (h, vr) = uneven_square_and_triangle(radiosity::bases::BasisKind::Linear);
    let leaves = h.leaves();
    let mut memo = LeafCorrections::default();
    for k in 0..4000usize {
        // Runs of a few samples on one leaf, then a jump; the gate changes now and then.
        let leaf = leaves[(k / 3 * 7919) % leaves.len()];
        let below = [0.25, f64::INFINITY, 0.05][k / 50 % 3];
        let shape = h.element(leaf).shape();
        let r = |i: usize| ((k * 2654435761 + i * 40503) % 1000) as f64 / 1000.0;
        let uv = match shape {
            Shape::Triangle(_) => DVec2::new(r(1) * (1.0 - r(2)), r(2) * (1.0 - r(1))),
            Shape::Quad(_) => DVec2::new(r(1), r(2)),
        };
        let p = shape.point_at(uv);
        let kept = vr.evaluate_continuous_at(&h, leaf, p, uv, below, &mut memo);
        let fresh =
            vr.evaluate_continuous_at(&h, leaf, p, uv, below, &mut LeafCorrections::default());
        assert_eq!(
            kept.to_array().map(f64::to_bits),
            fresh.to_array().map(f64::to_bits),
            "sample {k}, leaf {leaf}, below {below}"
        );
    }
}
