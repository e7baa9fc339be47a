//! Multi-resolution visibility (Sillion–Drettakis §3.2–3.3) on the shadow-groups scene of Figures 1 and 9:
//! its two limits are the exact and the extinction back ends, bit for bit, and between them the feature
//! size trades exact polygon tests for averaging, group by group.

use radiosity::geometry::{DVec3, Shape};
use radiosity::hierarchy::clusters::ClusterTreeKind;
use radiosity::scene::generators::ShadowGroups;
use radiosity::visibility::bvh::Bvh;
use radiosity::visibility::extinction::Extinction;
use radiosity::visibility::multires::{Averaging, Multires};
use radiosity::visibility::Visibility;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;

/// Segments from the wall (receiving end) to the source (source end), `per_group` over the shadow region
/// of each group, in group order.
fn wall_to_source(groups: &ShadowGroups, per_group: usize) -> Vec<(DVec3, DVec3)> {
    let mut rng = Pcg64Mcg::seed_from_u64(9);
    let l = groups.light_size / 2.0;
    let mut out = Vec::new();
    for k in 0..groups.cube_sizes.len() {
        let [x0, x1, y0, y1] = groups.shadow_region(k);
        for _ in 0..per_group {
            let wall = DVec3::new(rng.random_range(x0..x1), rng.random_range(y0..y1), 0.0);
            let source = DVec3::new(
                rng.random_range(-l..l),
                rng.random_range(-l..l),
                groups.light_distance,
            );
            out.push((wall, source));
        }
    }
    out
}

fn shapes(groups: &ShadowGroups) -> Vec<Shape> {
    groups.scene().polygons.iter().map(|p| p.shape).collect()
}

#[test]
fn feature_size_below_every_blocker_is_exact_visibility() {
    let groups = ShadowGroups::default();
    let shapes = shapes(&groups);
    let segments = wall_to_source(&groups, 500);
    let exact = Bvh::new(&shapes);
    let zero = Multires::new(&shapes, ClusterTreeKind::Grid, 0.0, Averaging::Cluster);
    // The umbra b·D/d is at least BSIZE b (d ≤ D), so any s up to the smallest BSIZE also descends
    // everywhere.
    let smallest = (0..zero.tree().nodes.len() as u32)
        .map(|n| zero.blocker_size(n))
        .fold(f64::INFINITY, f64::min);
    assert!(smallest > 0.0);
    let below = Multires::new(&shapes, ClusterTreeKind::Grid, smallest, Averaging::Cluster);
    let mut blocked = 0;
    for &(from, to) in &segments {
        let truth = exact.transmittance(from, to);
        blocked += usize::from(truth == 0.0);
        for m in [&zero, &below] {
            let trace = m.trace(from, to);
            assert_eq!(
                trace.transmittance.to_bits(),
                truth.to_bits(),
                "{from} → {to}"
            );
            assert_eq!(trace.averaged_clusters, 0);
        }
    }
    // Each group covers a quarter of its footprint: a good share of the segments is blocked.
    assert!(
        (segments.len() / 10..segments.len() / 2).contains(&blocked),
        "{blocked} of {} blocked",
        segments.len()
    );
}

#[test]
fn infinite_feature_size_with_leaf_averaging_is_extinction() {
    let groups = ShadowGroups::default();
    let shapes = shapes(&groups);
    for kind in [ClusterTreeKind::Grid, ClusterTreeKind::Octree] {
        let extinction = Extinction::new(&shapes, kind);
        let infinite = Multires::new(&shapes, kind, f64::INFINITY, Averaging::Leaves);
        for (from, to) in wall_to_source(&groups, 250) {
            let trace = infinite.trace(from, to);
            assert_eq!(
                trace.transmittance.to_bits(),
                extinction.transmittance(from, to).to_bits()
            );
            assert_eq!(trace.polygon_tests, 0);
        }
    }
}

#[test]
fn larger_feature_sizes_test_fewer_polygons_and_average_small_cubes_first() {
    let groups = ShadowGroups::default();
    let shapes = shapes(&groups);
    let per_group = 400;
    let segments = wall_to_source(&groups, per_group);
    let exact = Bvh::new(&shapes);
    let open: Vec<bool> = segments
        .iter()
        .map(|&(from, to)| exact.transmittance(from, to) == 1.0)
        .collect();
    let sizes = [0.0, 0.02, 0.04, 0.08, 0.16, 0.32, 0.64, f64::INFINITY];
    let mut previous: Option<Vec<usize>> = None;
    let mut totals = Vec::new();
    for &s in &sizes {
        let m = Multires::new(&shapes, ClusterTreeKind::Grid, s, Averaging::Leaves);
        let traces: Vec<_> = segments.iter().map(|&(f, t)| m.trace(f, t)).collect();
        // A segment no polygon blocks visits every descended cluster; a larger s descends into a subset
        // of them, so its polygon tests cannot grow.
        let tests: Vec<usize> = traces.iter().map(|t| t.polygon_tests).collect();
        if let Some(before) = &previous {
            for (i, (&now, &then)) in tests.iter().zip(before).enumerate() {
                if open[i] {
                    assert!(now <= then, "s = {s}: segment {i} tests {now} > {then}");
                }
            }
        }
        // Per group: the share of segments whose answer differs from exact visibility.
        let differing: Vec<f64> = (0..groups.cube_sizes.len())
            .map(|k| {
                let range = k * per_group..(k + 1) * per_group;
                range
                    .clone()
                    .filter(|&i| {
                        let (f, t) = segments[i];
                        traces[i].transmittance != exact.transmittance(f, t)
                    })
                    .count() as f64
                    / per_group as f64
            })
            .collect();
        eprintln!(
            "s = {s}: {} polygon tests, averaged share per group {differing:?}",
            tests.iter().sum::<usize>()
        );
        totals.push((s, tests.iter().sum::<usize>(), differing));
        previous = Some(tests);
    }
    // Work falls from exact to extinction.
    let work: Vec<usize> = totals.iter().map(|t| t.1).collect();
    assert!(
        work[sizes.len() - 2] < work[0] && work[sizes.len() - 1] == 0,
        "{work:?}"
    );
    // The paper's selectivity (§5): a feature size between the cube sizes averages the small cubes'
    // shadows and keeps the large ones exact.
    let at = |s: f64| &totals.iter().find(|t| t.0 == s).unwrap().2;
    // Largest cubes (c = 0.24): every cluster holding a face of one has BSIZE at least c (the face seen
    // head-on along one of the sampled axes), an umbra above c > 0.16 ≥ s, so it is descended and every
    // segment there gets the exact answer.
    let largest = groups.cube_sizes.len() - 1;
    assert!(groups.cube_sizes[largest] > 0.16);
    for s in [0.08, 0.16] {
        assert_eq!(at(s)[largest], 0.0, "s = {s}: {:?}", at(s));
    }
    // Small features are averaged first: at every s the share of segments answered by averaging does
    // not grow with the cube size, and some averaging happens before s reaches the largest cubes' 0.24.
    for (s, _, share) in &totals {
        assert!(share.windows(2).all(|w| w[0] >= w[1]), "s = {s}: {share:?}");
    }
    assert!(at(0.16)[0] > 0.0, "{:?}", at(0.16));
}

/// Averaging clusters as a whole (the paper's §3.2) stops at the first cluster whose umbra is below
/// `s`: at an infinite feature size every segment averages the root alone, with no polygon test, and
/// the transmittance is a Boolean-model `exp(−κ l)` in (0, 1] (the root holds the wall, the cubes and
/// the source, so every segment crosses it).
#[test]
fn averaging_clusters_as_a_whole_stops_at_the_first_small_umbra() {
    let groups = ShadowGroups::default();
    let shapes = shapes(&groups);
    let whole = Multires::new(
        &shapes,
        ClusterTreeKind::Grid,
        f64::INFINITY,
        Averaging::Cluster,
    );
    for (from, to) in wall_to_source(&groups, 100) {
        let trace = whole.trace(from, to);
        assert_eq!((trace.averaged_clusters, trace.polygon_tests), (1, 0));
        assert!(trace.transmittance > 0.0 && trace.transmittance <= 1.0);
    }
}

/// Where a link's shaft test proves that nothing lies between its elements, multi-resolution visibility
/// answers exactly (transmittance 1) at every feature size, as exact visibility does: two parallel unit
/// squares with a cloud of small black triangles beside the gap (outside every segment between them,
/// inside the boxes of clusters those segments cross). The receiver gets the analytic form factor at
/// `s = ∞`, where every cluster the segments cross would otherwise be averaged into an extinction that
/// darkens it. Tolerance: the 0.5% of the unoccluded plates in `physics.rs` (the same solve settings).
#[test]
fn clear_shafts_are_exact_under_multires_at_every_feature_size() {
    use radiosity::geometry::form_factor::parallel_rectangles;
    use radiosity::pipeline::{simulate, SimulationSettings, VisibilityKind};
    use radiosity::progress::Progress;
    use radiosity::scene::{generators, Material, Object, Polygon};

    let (rho, e) = (0.5, 1.0);
    let mut scene = generators::parallel_plates(1.0, 1.0, rho, e);
    let black = scene.materials.len();
    scene
        .materials
        .push(Material::diffuse("black", radiosity::color::Rgb::BLACK));
    scene.objects.push(Object {
        name: "cloud".into(),
    });
    let mut rng = Pcg64Mcg::seed_from_u64(3);
    for _ in 0..400 {
        let corner = DVec3::new(
            rng.random_range(1.05..1.4),
            rng.random_range(-0.4..1.4),
            rng.random_range(0.05..0.95),
        );
        let mut point = || {
            corner
                + DVec3::new(
                    rng.random_range(-0.03..0.03),
                    rng.random_range(-0.03..0.03),
                    rng.random_range(-0.03..0.03),
                )
        };
        let (b, c) = (point(), point());
        scene.polygons.push(Polygon {
            shape: Shape::Triangle([corner, b, c]),
            material: black,
            object: scene.objects.len() - 1,
            two_sided: true,
            under_contact: false,
        });
    }
    let exact = parallel_rectangles(1.0, 1.0, 1.0);
    for feature_size in [0.0, 0.1, f64::INFINITY] {
        let settings = SimulationSettings {
            eps: 1e-4,
            min_area: 1e-6,
            visibility: VisibilityKind::Multires,
            feature_size,
            ..Default::default()
        };
        let solution = simulate(&scene, &settings, &Progress::new(true)).expect("solve");
        let h = &solution.hierarchy;
        let patch = h.patch_for_side(0, true).expect("front patch");
        let f = h.average_radiance(h.patches[patch as usize].root).g / (rho * e);
        assert!(
            (f - exact).abs() / exact < 0.005,
            "s = {feature_size}: F = {f}, exact {exact}"
        );
    }
}

/// Sillion–Drettakis §6's importance as a feature size per surface: queries onto a receiver with its
/// own `s` answer as a structure built for that `s` does, bit for bit, and the others keep the scene's.
#[test]
fn a_surface_with_its_own_feature_size_is_queried_at_it() {
    let groups = ShadowGroups::default();
    let scene = groups.scene();
    let shapes = shapes(&groups);
    let wall = scene
        .polygons
        .iter()
        .position(|p| scene.objects[p.object].name == "wall")
        .expect("a wall tile");
    let cube = scene
        .polygons
        .iter()
        .position(|p| scene.objects[p.object].name.starts_with("group"))
        .expect("a cube face");
    let sizes: Vec<f64> = (0..shapes.len())
        .map(|i| if i == wall { 0.0 } else { f64::INFINITY })
        .collect();
    let averaged = Multires::new(
        &shapes,
        ClusterTreeKind::Grid,
        f64::INFINITY,
        Averaging::Leaves,
    );
    let per_surface = Multires::new(
        &shapes,
        ClusterTreeKind::Grid,
        f64::INFINITY,
        Averaging::Leaves,
    )
    .with_surface_feature_sizes(sizes);
    let exact = Bvh::new(&shapes);
    let mut differ = 0;
    for (from, to) in wall_to_source(&groups, 200) {
        let truth = exact.transmittance(from, to);
        let onto_wall = per_surface.transmittance_onto(from, to, wall);
        assert_eq!(onto_wall.to_bits(), truth.to_bits(), "{from} → {to}");
        let elsewhere = averaged.transmittance(from, to);
        assert_eq!(
            per_surface.transmittance_onto(from, to, cube).to_bits(),
            elsewhere.to_bits()
        );
        assert_eq!(
            per_surface.transmittance(from, to).to_bits(),
            elsewhere.to_bits()
        );
        differ += usize::from(onto_wall != elsewhere);
    }
    // Extinction never gives exact 0 or 1 through the groups: nearly every answer differs.
    assert!(differ > 700, "{differ} of 800 differ");
}

/// In a solve: with black cubes the wall receives only the source's direct light, so a wall given
/// `--feature-size-for wall=0` in a scene averaged everywhere else (s = ∞) gets exact visibility's
/// solution, while the scene's s alone washes its shadows out.
#[test]
fn a_solve_gives_the_named_surfaces_their_own_feature_size() {
    use radiosity::pipeline::{simulate, SimulationSettings, VisibilityKind};
    use radiosity::progress::Progress;
    use radiosity::visibility::multires::SurfaceFeatureSize;
    use radiosity::visibility::shaft::VisibilityReuse;

    let groups = ShadowGroups {
        cube_sizes: vec![0.12, 0.24],
        cube_reflectance: 0.0,
        ..ShadowGroups::default()
    };
    let scene = groups.scene();
    let wall_radiance = |feature_size: f64, for_wall: Option<f64>| {
        let settings = SimulationSettings {
            visibility: VisibilityKind::Multires,
            // Every query to multires: shaft tests would settle these links exactly.
            visibility_reuse: VisibilityReuse::None,
            feature_size,
            surface_feature_sizes: for_wall
                .map(|size| SurfaceFeatureSize {
                    pattern: "wall".into(),
                    size,
                })
                .into_iter()
                .collect(),
            ..Default::default()
        };
        let solution = simulate(&scene, &settings, &Progress::new(true)).expect("solve");
        let h = &solution.hierarchy;
        let wall: Vec<f64> = (0..h.elements.len() as u32)
            .filter(|&id| {
                h.element(id).surface().is_some()
                    && h.element(id).is_leaf()
                    && scene.objects[scene.polygons[h.patch_of(id).polygon].object].name == "wall"
            })
            .map(|id| h.average_radiance(id).g)
            .collect();
        wall
    };
    let exact = wall_radiance(0.0, None);
    let per_surface = wall_radiance(f64::INFINITY, Some(0.0));
    let averaged = wall_radiance(f64::INFINITY, None);
    assert_eq!(per_surface, exact);
    // Averaged, the umbrae the shaft tests do not find wholly blocked wash out: the wall's leaves
    // move by a good share of their light.
    let moved: f64 = averaged
        .iter()
        .zip(&exact)
        .map(|(a, e)| (a - e).abs())
        .sum();
    let total: f64 = exact.iter().sum();
    eprintln!("moved {}", moved / total);
    assert!(moved > 0.05 * total, "{moved} of {total}");
}
