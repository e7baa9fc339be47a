//! Clustering and extinction visibility (Sillion–Drettakis §3.1, §4, §6) against ground truth: the
//! Boolean-model transmittance of a cloud of small triangles, energy balance in a closed furnace full of
//! small objects, agreement with the unclustered solver, and independence of the thread count.

use radiosity::geometry::{DVec3, Shape};
use radiosity::hierarchy::clusters::{ClusterTreeKind, ClusteringKind};
use radiosity::hierarchy::Hierarchy;
use radiosity::pipeline::{build_visibility_with, simulate, SimulationSettings, VisibilityKind};
use radiosity::scene::{cornell::cornell_box, generators, Polygon, Scene};
use radiosity::visibility::item_buffer::IntraClusterKind;
use radiosity::visibility::multires::{Averaging, Multires};
use radiosity::visibility::Visibility;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;

#[allow(dead_code)] // each test file uses part of the shared module
mod common;
use common::{furnace_with_cubes, mean_radiance_of, quiet, with_threads};

/// `n` equilateral triangles of side `side`, centres uniform in the unit cube, uniformly random
/// orientations (independent placements: a Boolean model).
fn triangle_cloud(n: usize, side: f64, seed: u64) -> Scene {
    let mut rng = Pcg64Mcg::seed_from_u64(seed);
    let mut scene = generators::parallel_plates(1.0, 1.0, 0.5, 1.0);
    scene.polygons.clear();
    let unit = |rng: &mut Pcg64Mcg| loop {
        let v = DVec3::new(rng.random(), rng.random(), rng.random()) * 2.0 - DVec3::ONE;
        let l = v.length();
        if l > 0.1 && l <= 1.0 {
            return v / l;
        }
    };
    for _ in 0..n {
        let centre = DVec3::new(rng.random(), rng.random(), rng.random());
        let normal = unit(&mut rng);
        let u = normal.any_orthonormal_vector();
        let w = normal.cross(u);
        let radius = side / 3f64.sqrt();
        let corner = |k: f64| {
            let a = k * std::f64::consts::TAU / 3.0;
            centre + (u * a.cos() + w * a.sin()) * radius
        };
        scene.polygons.push(Polygon {
            shape: Shape::Triangle([corner(0.0), corner(1.0), corner(2.0)]),
            material: 0,
            object: 0,
            two_sided: false,
            under_contact: false,
        });
    }
    scene
}

/// Extinction (§3.1) against exact visibility in a cloud of small random triangles. Ground truth: for
/// independently placed objects (a Boolean model) a segment of length `l` is free with probability
/// `exp(−n σ̄ l)`, `σ̄ = a/2` the mean projected area of a triangle of area `a` (Cauchy), which is the
/// paper's `κ = ΣA/(4V)` with both faces counted. Errors: the sampling noise of the exact mean (binomial,
/// 4σ) and, for extinction, the grid clusters' departure from a homogeneous medium (their boxes hold a
/// handful of triangles each, so κ_i fluctuates and Jensen's inequality biases the mean transmittance
/// up; "within a few percent" by the statement: 3% absolute).
#[test]
fn extinction_matches_exact_mean_visibility_in_a_random_cloud() {
    let (n, side) = (10_000, 0.03);
    let scene = triangle_cloud(n, side, 11);
    let area = 3f64.sqrt() / 4.0 * side * side;
    let kappa = n as f64 * area / 2.0;
    let exact = build_visibility_with(&scene, VisibilityKind::Bvh, ClusterTreeKind::Grid).unwrap();
    let mut rng = Pcg64Mcg::seed_from_u64(5);
    let inner = |rng: &mut Pcg64Mcg| {
        DVec3::new(rng.random(), rng.random(), rng.random()) * 0.7 + DVec3::splat(0.15)
    };
    let segments: Vec<(DVec3, DVec3)> = (0..4000)
        .map(|_| (inner(&mut rng), inner(&mut rng)))
        .collect();
    let m = segments.len() as f64;
    let free = segments
        .iter()
        .filter(|(a, b)| !exact.segment_occluded(*a, *b))
        .count() as f64
        / m;
    let boolean: Vec<f64> = segments
        .iter()
        .map(|(a, b)| (-kappa * (*b - *a).length()).exp())
        .collect();
    let expected = boolean.iter().sum::<f64>() / m;
    let sigma = (boolean.iter().map(|p| p * (1.0 - p)).sum::<f64>()).sqrt() / m;
    assert!(
        (free - expected).abs() < 4.0 * sigma,
        "exact {free} vs Boolean model {expected} (σ {sigma})"
    );
    for tree in [ClusterTreeKind::Grid, ClusterTreeKind::Octree] {
        let extinction = build_visibility_with(&scene, VisibilityKind::Extinction, tree).unwrap();
        let mean = segments
            .iter()
            .map(|(a, b)| extinction.transmittance(*a, *b))
            .sum::<f64>()
            / m;
        assert!(
            (mean - free).abs() < 0.03 + 4.0 * sigma,
            "{tree:?}: extinction {mean} vs exact {free}"
        );
        // Rendering rays stay exact.
        let (a, b) = segments[0];
        assert_eq!(
            extinction.segment_occluded(a, b),
            exact.segment_occluded(a, b)
        );
        // Multi-resolution visibility that averages every cluster as a whole (the paper's §3.2, at
        // an infinite feature size): the root cluster's single κ = ΣA/(4V) over its box. The box holds
        // the triangles' corners, up to side/√3 past the unit cube of their centres: κ is diluted by
        // the box's volume V, a known error of the model. Bound: the Boolean model with κ/V, whose
        // transmittance lies above the true one by `dilution`, plus the exact mean's 4σ.
        let shapes: Vec<Shape> = scene.polygons.iter().map(|p| p.shape).collect();
        let corners = shapes.iter().flat_map(|s| s.vertices().iter().copied());
        let (lo, hi) = corners.fold(
            (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
            |(lo, hi), v| (lo.min(v), hi.max(v)),
        );
        let volume = (hi - lo).x * (hi - lo).y * (hi - lo).z;
        let diluted = segments
            .iter()
            .map(|(a, b)| (-kappa / volume * (*b - *a).length()).exp())
            .sum::<f64>()
            / m;
        let dilution = diluted - expected;
        let whole = Multires::new(&shapes, tree, f64::INFINITY, Averaging::Cluster);
        let mean = segments
            .iter()
            .map(|(a, b)| whole.transmittance(*a, *b))
            .sum::<f64>()
            / m;
        assert!(
            (mean - free).abs() < dilution + 4.0 * sigma,
            "{tree:?}: cluster-averaged multires {mean} vs exact {free} (dilution {dilution})"
        );
    }
}

/// White furnace full of small objects: closed, every surface ρ and E, so every radiance is
/// `E / (1 − ρ)` and the total exitant power `Φ_e / (1 − ρ)`. Clustering starts from one self-link on the
/// root cluster; energy is conserved when the links' form factors out of every source add up to one,
/// which the cluster transfers approximate (centre-to-centre kernel, sampled visibility) only as far as
/// refinement drives cluster links to weak interactions: the power oracle's threshold bounds each
/// link's transported power, so the error falls with ε (measured with oriented transfer: −1.6% at
/// ε = 1e-4, −0.5% at 2e-5). Tolerance: the 0.5%, at ε = 1e-5.
#[test]
fn clustered_furnace_with_small_objects_conserves_energy() {
    let (rho, e) = (0.5, 1.0);
    let scene = furnace_with_cubes(4, rho, e);
    // Without item buffers (tests/intra_cluster.rs has the furnace with them). Isotropic transfer is
    // left out here: its mean cosine 1/4 is exact only for isotropic contents, and the room's flat
    // walls are not; it creates 0.76% (BENCHMARKS.md) unless item buffers give the projected areas.
    let clustering = ClusteringKind::Oriented;
    let settings = SimulationSettings {
        clustering,
        intra_cluster: IntraClusterKind::None,
        eps: 1e-5,
        min_area: 1e-4,
        ..Default::default()
    };
    let solution = simulate(&scene, &settings, &quiet()).expect("solve");
    let h = &solution.hierarchy;
    assert!(h.root_cluster.is_some());
    let mean = mean_radiance_of(h, |_| true);
    let expected = e / (1.0 - rho);
    assert!(
        (mean - expected).abs() / expected < 0.005,
        "{clustering:?}: mean radiance {mean}, expected {expected}"
    );
    let r = &solution.report;
    let exitant = r.exitant_power.g;
    let analytic = r.emitted_power.g / (1.0 - rho);
    assert!(
        (exitant - analytic).abs() / analytic < 0.005,
        "{clustering:?}: exitant power {exitant}, analytic {analytic}"
    );
}

/// Area-weighted relative RMSE between the patch radiances of two solutions of the same scene.
fn relative_rmse(a: &Hierarchy, b: &Hierarchy) -> f64 {
    let (mut squared, mut sum, mut area) = (0.0, 0.0, 0.0);
    for (pa, pb) in a.patches.iter().zip(&b.patches) {
        let ea = a.element(pa.root);
        for (x, y) in a
            .average_radiance(pa.root)
            .to_array()
            .iter()
            .zip(b.average_radiance(pb.root).to_array())
        {
            squared += ea.area * (x - y).powi(2);
            sum += ea.area * y;
            area += ea.area;
        }
    }
    (squared / area).sqrt() / (sum / area)
}

/// Clustering changes the answer little: on the Cornell box, at the same oracle and threshold, the
/// clustered and unclustered solutions agree within 2% relative RMSE of the patch radiances. Error
/// model: both are refined to the same power threshold, so their link errors are of the same size;
/// what clustering adds is the centre-to-centre transfer of the cluster links the threshold admits,
/// each carrying at most ε of the emitted power (1e-4 here, a few tens of links): well under 2%.
#[test]
fn clustered_and_unclustered_cornell_box_agree() {
    let scene = cornell_box();
    let base = SimulationSettings {
        eps: 1e-4,
        ..Default::default()
    };
    let plain = simulate(&scene, &base, &quiet()).expect("solve");
    for clustering in [ClusteringKind::Isotropic, ClusteringKind::Oriented] {
        for cluster_tree in [
            ClusterTreeKind::Grid,
            ClusterTreeKind::Kdtree,
            ClusterTreeKind::Octree,
        ] {
            let settings = SimulationSettings {
                clustering,
                cluster_tree,
                ..base.clone()
            };
            let clustered = simulate(&scene, &settings, &quiet()).expect("solve");
            let error = relative_rmse(&clustered.hierarchy, &plain.hierarchy);
            assert!(
                error < 0.02,
                "{clustering:?} {cluster_tree:?}: relative RMSE {error}"
            );
        }
    }
}

/// Results do not depend on the thread count, with clustering on.
#[test]
fn clustered_solution_is_identical_for_any_thread_count() {
    let scene = furnace_with_cubes(2, 0.5, 1.0);
    let settings = SimulationSettings {
        clustering: ClusteringKind::Oriented,
        eps: 1e-3,
        ..Default::default()
    };
    let run = |threads| {
        with_threads(threads, || {
            simulate(&scene, &settings, &quiet()).expect("solve")
        })
    };
    let (one, two) = (run(1), run(3));
    assert_eq!(one.hierarchy.elements.len(), two.hierarchy.elements.len());
    assert_eq!(one.hierarchy.link_count(), two.hierarchy.link_count());
    assert_eq!(
        one.hierarchy.radiance_coefficients(),
        two.hierarchy.radiance_coefficients()
    );
}

/// `--clustering auto` estimates the unclustered initial links from a sample of patch rows and counts
/// exactly only near the budget: its choice must be the one the exact count gives, for budgets from far
/// below to far above the count (a generated hall of 3k polygons, 6k patches, and floor_gloss.mgf,
/// whose two-sided polygons' two patches are consecutive: sampling every other row saw one side of
/// each and estimated its 19k links as none). The bound the pipeline
/// adds: past [`AUTO_CLUSTERING_LINKS`] it clusters under any oracle whatever the budget (which follows
/// the machine's memory), and under the power oracle past [`AUTO_CLUSTERING_LINKS_POWER`], which the
/// hall's count passes and the Cornell box's does not.
#[test]
fn automatic_clustering_agrees_with_the_exact_count() {
    use radiosity::pipeline::{
        auto_clustering_links, OracleKind, AUTO_CLUSTERING_LINKS, AUTO_CLUSTERING_LINKS_POWER,
    };
    use radiosity::scene::generators::BoxHall;
    use radiosity::solvers::refine::{automatic_clustering, initial_link_count};
    let floor_gloss = radiosity::scene::load(
        &std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../shared/scenes/renderpark/floor_gloss.mgf"),
        &radiosity::scene::LoadOptions::default(),
    )
    .expect("floor_gloss.mgf");
    for (name, scene) in [
        ("hall", BoxHall::with_polygons(3000).scene()),
        ("floor_gloss", floor_gloss),
    ] {
        let h = Hierarchy::new(&scene, radiosity::bases::BasisKind::Linear);
        let total = initial_link_count(&h, usize::MAX);
        assert!(total > AUTO_CLUSTERING_LINKS_POWER, "{name}: {total}");
        for budget in [
            total / 10,
            total / 3,
            total - 1,
            total,
            total * 3,
            total * 10,
            usize::MAX,
        ] {
            let exact = if total > budget {
                ClusteringKind::Oriented
            } else {
                ClusteringKind::None
            };
            assert_eq!(
                automatic_clustering(&h, budget),
                exact,
                "{name}: budget {budget}, count {total}"
            );
        }
    }
    let scene = BoxHall::with_polygons(3000).scene();
    let h = Hierarchy::new(&scene, radiosity::bases::BasisKind::Linear);
    assert_eq!(
        automatic_clustering(&h, auto_clustering_links(OracleKind::Power)),
        ClusteringKind::Oriented
    );
    let cornell = Hierarchy::new(&cornell_box(), radiosity::bases::BasisKind::Linear);
    assert!(initial_link_count(&cornell, usize::MAX) <= AUTO_CLUSTERING_LINKS_POWER);
    assert_eq!(
        automatic_clustering(&cornell, auto_clustering_links(OracleKind::Power)),
        ClusteringKind::None
    );
    // A hall whose initial links pass the bound: clustered under every oracle.
    let scene = BoxHall::with_polygons(7000).scene();
    let h = Hierarchy::new(&scene, radiosity::bases::BasisKind::Linear);
    assert!(initial_link_count(&h, AUTO_CLUSTERING_LINKS) > AUTO_CLUSTERING_LINKS);
    for oracle in [
        OracleKind::Power,
        OracleKind::Smoothness,
        OracleKind::MutualInformation,
        OracleKind::Error,
    ] {
        assert_eq!(
            automatic_clustering(&h, auto_clustering_links(oracle)),
            ClusteringKind::Oriented
        );
    }
}

/// The pipeline resolves `--clustering auto` with the oracle's bound: a hall over ten thousand initial
/// links solves clustered under the power oracle, the Cornell box unclustered.
#[test]
fn automatic_clustering_under_the_power_oracle_clusters_past_ten_thousand_links() {
    use radiosity::scene::generators::BoxHall;
    let settings = SimulationSettings {
        clustering: ClusteringKind::Auto,
        max_passes: 1,
        ..Default::default()
    };
    let hall = simulate(&BoxHall::with_polygons(3000).scene(), &settings, &quiet()).expect("hall");
    assert!(
        hall.hierarchy.root_cluster.is_some(),
        "the hall was not clustered"
    );
    let cornell = simulate(&cornell_box(), &settings, &quiet()).expect("Cornell box");
    assert!(
        cornell.hierarchy.root_cluster.is_none(),
        "the Cornell box was clustered"
    );
}

/// A row of small plates on the ground, from under a small lamp to 2.7 m away, lit by the lamp 2 m up
/// and by nothing else (coplanar, nothing above but the lamp): coarse refinement leaves the row
/// receiving through cluster links, whose centre-to-centre transfer gives each plate the irradiance
/// of the cluster's centre distance, and each plate's exact radiance is `ρ F` with `F` its factor from
/// the lamp (point factors over a 10 × 10 grid of the plate). The a-posteriori estimate must see that
/// misplacement (eq. (6)'s `δ_j` at a cluster receiver, taken at the link's receiver sample points).
/// Error model: the estimate is the largest `|δ|` over a link's m = 8 receiver samples, drawn about
/// uniformly along the row, and a plate's error is `|δ|` at its own place, so a plate at quantile `q`
/// of the row's errors is covered with probability `1 − q^8`: about 8/9 of plates on average, and
/// over 16 seeds × 10 plates the covered fraction's standard deviation is under 3%; at least 75%
/// must be covered (without the δ the estimate is zero here and covers none).
#[test]
fn the_estimate_sees_what_a_cluster_link_misplaces_across_its_receiver() {
    use radiosity::color::Rgb;
    use radiosity::scene::Material;
    const PLATES: usize = 10;
    const RHO: f64 = 0.5;
    let mut materials = vec![Material::emitter("lamp", Rgb::BLACK, Rgb::splat(1.0))];
    let mut shapes = vec![common::rectangle([-0.1, 0.1, -0.1, 0.1], 2.0, false)];
    for k in 0..PLATES {
        let x = 0.3 * k as f64;
        materials.push(Material::diffuse(&format!("plate {k}"), Rgb::splat(RHO)));
        shapes.push(common::rectangle([x, x + 0.1, -0.05, 0.05], 0.0, true));
    }
    let scene = common::one_polygon_per_material(materials, shapes.clone(), |_| false);
    let exact: Vec<f64> = shapes[1..]
        .iter()
        .map(|plate| RHO * common::mean_factor_up(plate, &shapes[0], 10))
        .collect();
    let (mut covered, mut misplaced, mut total) = (0, 0, 0);
    for seed in 1..=16 {
        let settings = SimulationSettings {
            seed,
            clustering: ClusteringKind::Oriented,
            eps: 0.1,
            ..Default::default()
        };
        let solution = simulate(&scene, &settings, &quiet()).expect("solve");
        let h = &solution.hierarchy;
        for (k, &exact) in exact.iter().enumerate() {
            let patch = k + 1;
            let element = h.element(h.patches[patch].root);
            assert!(element.links.is_empty(), "plate {k} links on its own");
            let error = (mean_radiance_of(h, |p| p == patch) - exact).abs();
            total += 1;
            misplaced += usize::from(error > 0.05 * exact);
            covered += usize::from(error <= element.error);
        }
    }
    assert!(
        misplaced * 2 > total,
        "only {misplaced} of {total} plates misplaced"
    );
    assert!(
        covered * 4 >= total * 3,
        "{covered} of {total} plates within their estimate"
    );
}
