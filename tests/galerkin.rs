//! Galerkin radiosity with higher-order bases and error control (Bekaert–Willems) against ground truth:
//! single-bounce configurations whose exact radiance is `ρ E F(x → emitter)` with the exact
//! point-to-polygon factor (and, with a blocker, the same integral with visibility, computed by a fine
//! midpoint rule over the emitter), the white furnace, and energy balance.

#[allow(dead_code)] // each test file uses part of the shared module
mod common;
use radiosity::bases::BasisKind;
use radiosity::color::Rgb;
use radiosity::geometry::form_factor::{point_to_point, point_to_polygon};
use radiosity::geometry::{DVec2, DVec3, Shape};
use radiosity::hierarchy::{ErrorStorage, Hierarchy, Link, OracleFactor};
use radiosity::pipeline::{simulate, Accuracy, OracleKind, SimulationSettings, SolverKind};
use radiosity::progress::Progress;
use radiosity::scene::{generators, Material, Polygon, Scene};
use radiosity::solvers::coupling::{couple, CouplingSettings};
use radiosity::solvers::error_estimate::{estimate_errors, EstimateKind};
use radiosity::solvers::gathering::{GatheringSolver, GaussSeidel, SweepPlan};
use radiosity::visibility::brute_force::BruteForce;
use radiosity::visibility::Visibility;

const RHO: f64 = 0.5;
const EMISSION: f64 = 1.0;
const KINDS: [BasisKind; 4] = [
    BasisKind::Constant,
    BasisKind::Linear,
    BasisKind::Quadratic,
    BasisKind::Cubic,
];

fn quiet() -> Progress {
    Progress::new(true)
}

fn brute_force(scene: &Scene) -> BruteForce {
    BruteForce::new(scene.polygons.iter().map(|p| p.shape).collect())
}

/// Splits every leaf of `patch` until the tree is `level` deep.
fn subdivide_uniformly(h: &mut Hierarchy, patch: usize, level: u16) {
    loop {
        let mut leaves = Vec::new();
        h.collect_leaves(h.patches[patch].root, &mut leaves);
        if h.element(leaves[0]).level >= level {
            return;
        }
        for leaf in leaves {
            h.subdivide(leaf);
        }
    }
}

/// Links every leaf of patch 0 (the receiver) to the root of patch 1 (the emitter) and solves.
fn solve_receiver(scene: &Scene, kind: BasisKind, level: u16, vis: &dyn Visibility) -> Hierarchy {
    let mut h = Hierarchy::new(scene, kind);
    subdivide_uniformly(&mut h, 0, level);
    let emitter = h.patches[1].root;
    let settings = CouplingSettings {
        cubature_degree: kind.default_cubature_degree(),
        ..CouplingSettings::default()
    };
    let mut leaves = Vec::new();
    h.collect_leaves(h.patches[0].root, &mut leaves);
    for leaf in leaves {
        let k = couple(&h, vis, leaf, emitter, &settings, None);
        h.elements[leaf as usize].links.push(Link {
            source: emitter,
            coupling: k.coupling.with_shaft(k.shaft),
            oracle_factor: OracleFactor::NONE,
        });
    }
    let plan = SweepPlan::new(&h);
    for _ in 0..3 {
        GaussSeidel.sweep(&mut h, &plan);
    }
    h
}

/// Points of an `n` × `n` midpoint grid on the unit receiver square (z = 0).
fn grid(n: usize) -> Vec<DVec3> {
    (0..n * n)
        .map(|k| {
            DVec3::new(
                ((k % n) as f64 + 0.5) / n as f64,
                ((k / n) as f64 + 0.5) / n as f64,
                0.0,
            )
        })
        .collect()
}

/// Root-mean-square error of the receiver's radiance against `exact`, relative to the mean of `exact`.
fn relative_rms_error(h: &Hierarchy, exact: &dyn Fn(DVec3) -> f64) -> f64 {
    let points = grid(96);
    let (mut sq, mut mean) = (0.0, 0.0);
    for &x in &points {
        let leaf = h.locate(0, x);
        let approx = h.radiance_at(leaf, x).g;
        let truth = exact(x);
        sq += (approx - truth).powi(2);
        mean += truth;
    }
    let n = points.len() as f64;
    (sq / n).sqrt() / (mean / n)
}

fn emitter_shape(scene: &Scene) -> Shape {
    scene.polygons[1].shape
}

#[test]
fn higher_orders_converge_faster_on_the_lit_plate() {
    let scene = generators::parallel_plates(1.0, 1.0, RHO, EMISSION);
    let emitter = emitter_shape(&scene);
    let exact = |x: DVec3| RHO * EMISSION * point_to_polygon(x, DVec3::Z, &emitter);
    let vis = brute_force(&scene);
    let mut rates = Vec::new();
    let mut errors = Vec::new();
    for kind in KINDS {
        let e: Vec<f64> = (1..=3)
            .map(|level| relative_rms_error(&solve_receiver(&scene, kind, level, &vis), &exact))
            .collect();
        // Halving the element size divides the L2 error by 2^(p+1) for a degree-p basis.
        let rate = (e[1] / e[2]).log2();
        rates.push(rate);
        errors.push(e);
    }
    eprintln!("relative L2 errors at levels 1..3: {errors:?}; rates {rates:?}");
    for (kind, rate) in KINDS.iter().zip(&rates) {
        let order = kind.polynomial_degree() as f64 + 1.0;
        // Asymptotic rate p + 1, within half an order (the finest level is not fully asymptotic).
        assert!(
            *rate > order - 0.5,
            "{kind:?}: rate {rate:.2}, expected about {order}"
        );
    }
    // At equal unknowns, higher orders are more accurate: linear on 16 elements (48 unknowns) beats
    // constant on 64 (64 unknowns); quadratic on 16 (96) beats linear on 64 (192); cubic on 16 (160)
    // beats quadratic on 64 (384).
    for k in 1..KINDS.len() {
        assert!(
            errors[k][1] < errors[k - 1][2],
            "{:?} at level 2 ({}) vs {:?} at level 3 ({})",
            KINDS[k],
            errors[k][1],
            KINDS[k - 1],
            errors[k - 1][2]
        );
    }
}

/// The realistic estimate `max_k |δ_j(x_k)|` of a single unoccluded link is the true error at the
/// receiver's cubature nodes, so it cannot exceed the true maximum over the element, and the nodes of a
/// rule of degree 2p + 2 see most of it.
#[test]
fn the_error_estimate_tracks_the_true_error_per_element() {
    let scene = generators::perpendicular_plates(1.0, RHO, EMISSION);
    let vis = brute_force(&scene);
    for kind in KINDS {
        let mut h = solve_receiver(&scene, kind, 2, &vis);
        assert_estimates_track_the_true_error(&scene, &mut h, kind, EstimateKind::Realistic);
    }
}

/// Links at two levels of the receiver under a parallel emitter one plate's size above it: two of the
/// emitter's children gathered at the receiver's root, the other two at each leaf. The error at a point
/// of a leaf is then the signed sum of both levels' `δ_j` (eq. (5)): summed at the leaf's nodes, with
/// the root's carried there by its fitted polynomial (`--error-estimate signed`), the estimate still
/// cannot exceed the true maximum over the leaf (beyond that fit's error, small for a kernel whose
/// singularities lie a plate's size away), where adding the root's maximum to every leaf (the paper's
/// per-level estimate) does, by up to a quarter with the constant basis: the root's `δ_j` changes sign
/// across it.
#[test]
fn the_error_estimate_sums_the_levels_with_their_signs() {
    let scene = generators::parallel_plates(1.0, 1.0, RHO, EMISSION);
    let vis = brute_force(&scene);
    for kind in KINDS {
        let mut h = Hierarchy::new(&scene, kind);
        subdivide_uniformly(&mut h, 0, 2);
        let (receiver, emitter) = (h.patches[0].root, h.patches[1].root);
        let settings = CouplingSettings {
            cubature_degree: kind.default_cubature_degree(),
            ..CouplingSettings::default()
        };
        let mut leaves = Vec::new();
        h.collect_leaves(receiver, &mut leaves);
        for (k, source) in h.subdivide(emitter).into_iter().enumerate() {
            let receivers = if k < 2 {
                vec![receiver]
            } else {
                leaves.clone()
            };
            for r in receivers {
                let c = couple(&h, &vis, r, source, &settings, None);
                h.elements[r as usize].links.push(Link {
                    source,
                    coupling: c.coupling.with_shaft(c.shaft),
                    oracle_factor: OracleFactor::NONE,
                });
            }
        }
        let plan = SweepPlan::new(&h);
        for _ in 0..3 {
            GaussSeidel.sweep(&mut h, &plan);
        }
        assert_estimates_track_the_true_error(&scene, &mut h, kind, EstimateKind::Signed);
    }
}

/// Every receiver leaf's realistic estimate against the true maximum error over it (a 24 × 24 grid),
/// for a receiver lit by the emitter alone (radiance `ρ E F(x → emitter)`): at most 5% above it (the
/// nodes lie inside the leaf; 5% for the fit that carries ancestors' errors to them), and not below a
/// quarter of it (the nodes of a rule of degree 2p + 4 see most of the maximum).
fn assert_estimates_track_the_true_error(
    scene: &Scene,
    h: &mut Hierarchy,
    kind: BasisKind,
    estimate: EstimateKind,
) {
    let emitter = emitter_shape(scene);
    assert_eq!(
        h.patches[0].normal,
        DVec3::Z,
        "the receiver lies in z = 0, facing up"
    );
    let exact = |x: DVec3| RHO * EMISSION * point_to_polygon(x, DVec3::Z, &emitter);
    estimate_errors(h, estimate);
    let mut leaves = Vec::new();
    h.collect_leaves(h.patches[0].root, &mut leaves);
    for leaf in leaves {
        let shape = *h.element(leaf).shape();
        let mut worst: f64 = 0.0;
        for a in 0..24 {
            for b in 0..24 {
                let uv = DVec2::new((a as f64 + 0.5) / 24.0, (b as f64 + 0.5) / 24.0);
                let x = shape.point_at(uv);
                worst = worst.max((h.radiance_at(leaf, x).g - exact(x)).abs());
            }
        }
        let error = h.element(leaf).error;
        assert!(
            error <= 1.05 * worst + 1e-9,
            "{kind:?} {estimate:?} leaf {leaf}: {error} above the true maximum {worst}"
        );
        assert!(
            error >= 0.25 * worst,
            "{kind:?} {estimate:?} leaf {leaf}: {error} far below the true maximum {worst}"
        );
    }
}

/// Receiver square, emitter square above it, and a black one-sided square blocker between them that
/// casts a shadow with umbra and penumbra on the receiver.
fn shadowed_plate() -> Scene {
    let mut scene = generators::parallel_plates(1.0, 1.0, RHO, EMISSION);
    let material = scene.materials.len();
    scene
        .materials
        .push(Material::diffuse("blocker", Rgb::BLACK));
    let (lo, hi, z) = (0.3, 0.6, 0.4);
    scene.polygons.push(Polygon {
        shape: Shape::Quad([
            DVec3::new(lo, lo, z),
            DVec3::new(lo, hi, z),
            DVec3::new(hi, hi, z),
            DVec3::new(hi, lo, z),
        ]),
        material,
        object: 0,
        two_sided: false,
        under_contact: false,
    });
    scene
}

/// `ρ E ∫ G(x, y) vis(x, y) dA_y` by the midpoint rule on a 160 × 160 grid over the emitter; its
/// discretisation error (about 1e-4 relative away from shadow boundaries, 1e-3 at them) is far below
/// the accuracies tested.
fn shadowed_exact(scene: &Scene, vis: &dyn Visibility, x: DVec3) -> f64 {
    let emitter = emitter_shape(scene);
    let n = 160;
    let area = emitter.area() / (n * n) as f64;
    let mut sum = 0.0;
    for a in 0..n {
        for b in 0..n {
            let y = emitter.point_at(DVec2::new(
                (a as f64 + 0.5) / n as f64,
                (b as f64 + 0.5) / n as f64,
            ));
            let g = point_to_point(x, DVec3::Z, y, -DVec3::Z);
            if g > 0.0 && !vis.segment_occluded(x, y) {
                sum += g * area;
            }
        }
    }
    RHO * EMISSION * sum
}

/// 400 random points of the shadowed plate's receiver (seeded) and their exact radiance.
fn shadowed_points(scene: &Scene, seed: u64) -> (Vec<DVec3>, Vec<f64>) {
    use rand::{Rng, SeedableRng};
    let vis = brute_force(scene);
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(seed);
    let points: Vec<DVec3> = (0..400)
        .map(|_| DVec3::new(rng.random(), rng.random(), 0.0))
        .collect();
    let truth = points
        .iter()
        .map(|&x| shadowed_exact(scene, &vis, x))
        .collect();
    (points, truth)
}

/// How many of the plate's `points` (patch 0) the solution `h` gets within `tolerance(t)` of their
/// exact radiance `t` (green channel).
fn points_within(
    h: &Hierarchy,
    points: &[DVec3],
    truth: &[f64],
    tolerance: impl Fn(f64) -> f64,
) -> usize {
    points
        .iter()
        .zip(truth)
        .filter(|(&x, &t)| {
            let leaf = h.locate(0, x);
            (h.radiance_at(leaf, x).g - t).abs() <= tolerance(t)
        })
        .count()
}

/// Error control (algorithm 6.1) meets its promise: at 95% of 400 random points the measured error is
/// within the accuracy asked for (Bekaert–Willems §6.2), at two accuracies a factor of four apart, with
/// a shadow: with the link error oracle, and with eq. (1)'s power oracle, whose thresholds algorithm 6.1
/// lowers from a coarse ε where the estimate fails (without error control that ε misses the promise).
#[test]
fn error_control_meets_the_accuracy_at_95_percent_of_points() {
    let scene = shadowed_plate();
    let (points, truth) = shadowed_points(&scene, 7);
    // A factor of four in accuracy for the linear basis; the constant basis needs ~10⁴ elements for the
    // coarser one already.
    // The reduced error storage of §4.3 is exact here (the one source keeps its shape), so it must keep
    // the promise too.
    let within = |settings: &SimulationSettings, accuracy: f64| {
        let solution = simulate(&scene, settings, &quiet()).expect("solve");
        let h = &solution.hierarchy;
        let within = points_within(h, &points, &truth, |_| accuracy);
        eprintln!(
            "{:?} {:?} {:?} accuracy {accuracy}: {within}/400 within, {} leaves, {}",
            settings.oracle,
            settings.basis,
            settings.error_storage,
            h.leaf_count(),
            solution.report.error.stopped_by
        );
        within
    };
    // A coarse ε for the power oracle, so that error control has to do the work.
    let coarse = 1e-2;
    for (oracle, basis, accuracy, error_storage) in [
        (
            OracleKind::Error,
            BasisKind::Constant,
            0.008,
            ErrorStorage::Full,
        ),
        (
            OracleKind::Error,
            BasisKind::Linear,
            0.008,
            ErrorStorage::Full,
        ),
        (
            OracleKind::Error,
            BasisKind::Linear,
            0.008,
            ErrorStorage::Reduced,
        ),
        (
            OracleKind::Error,
            BasisKind::Linear,
            0.002,
            ErrorStorage::Full,
        ),
        (
            OracleKind::Power,
            BasisKind::Linear,
            0.008,
            ErrorStorage::Full,
        ),
        (
            OracleKind::Power,
            BasisKind::Linear,
            0.008,
            ErrorStorage::Reduced,
        ),
        (
            OracleKind::Power,
            BasisKind::Linear,
            0.002,
            ErrorStorage::Reduced,
        ),
    ] {
        let settings = SimulationSettings {
            oracle,
            basis,
            error_storage,
            accuracy: Some(Accuracy::Absolute(accuracy)),
            eps: if oracle == OracleKind::Power {
                coarse
            } else {
                SimulationSettings::default().eps
            },
            min_area: 1e-6,
            max_passes: 40,
            ..Default::default()
        };
        let n = within(&settings, accuracy);
        assert!(
            n >= 380,
            "{oracle:?} {basis:?} {error_storage:?} at accuracy {accuracy}: only {n} of 400 points within"
        );
    }
    let uncontrolled = SimulationSettings {
        oracle: OracleKind::Power,
        basis: BasisKind::Linear,
        error_storage: ErrorStorage::Reduced,
        eps: coarse,
        min_area: 1e-6,
        max_passes: 40,
        ..Default::default()
    };
    let n = within(&uncontrolled, 0.002);
    assert!(
        n < 380,
        "the power oracle at ε {coarse} alone already meets the accuracy ({n} of 400): the test \
         shows nothing of error control"
    );
}

#[test]
fn the_white_furnace_is_solved_to_the_accuracy_with_every_solver() {
    let (rho, e) = (0.5, 1.0);
    let scene = generators::furnace(DVec3::new(1.0, 1.5, 2.0), rho, e);
    let expected = e / (1.0 - rho);
    const ACCURACY: f64 = 0.03;
    for (basis, solver) in [
        (BasisKind::Linear, SolverKind::Jacobi),
        (BasisKind::Quadratic, SolverKind::GaussSeidel),
        (BasisKind::Linear, SolverKind::Southwell),
        (BasisKind::Quadratic, SolverKind::Sor),
    ] {
        let settings = SimulationSettings {
            oracle: OracleKind::Error,
            basis,
            solver,
            accuracy: Some(Accuracy::Absolute(ACCURACY * expected)),
            min_area: 1e-5,
            ..Default::default()
        };
        let solution = simulate(&scene, &settings, &quiet()).expect("solve");
        let h = &solution.hierarchy;
        // The paper's promise (§6.2) where the estimate says the accuracy is met: the error is within
        // it almost everywhere; checked at the corners of those leaves (where the error of a polynomial
        // fit is largest). At the box's edges the estimate stays above the accuracy (the δ_j of links at
        // different levels cancel in the furnace, but their maxima add), and those leaves are reported
        // as failing, not counted here.
        let (mut points, mut within) = (0, 0);
        for id in h.leaves() {
            if h.element(id).error > ACCURACY * expected {
                continue;
            }
            let shape = *h.element(id).shape();
            for corner in shape.vertices() {
                let x = *corner * 0.999 + shape.centroid() * 0.001;
                let b = h.radiance_at(id, x).g;
                points += 1;
                within += usize::from((b - expected).abs() <= ACCURACY * expected);
            }
        }
        assert!(
            points > 0 && within * 100 >= 95 * points,
            "{basis:?} {solver:?}: {within} of {points} leaf corners within the accuracy ({:?})",
            solution.report.error
        );
        let r = &solution.report;
        // One estimate per pass, the last one the solve's own; refinement only adds elements.
        let passes = &r.error.passes;
        assert_eq!(passes.len(), r.passes, "{basis:?}: one estimate per pass");
        assert_eq!(passes.last().map(|p| p.summary), Some(r.error.summary));
        for (k, pair) in passes.windows(2).enumerate() {
            assert_eq!(pair[0].pass, k + 1);
            assert!(
                pair[1].summary.leaves >= pair[0].summary.leaves
                    && pair[1].refine_seconds >= pair[0].refine_seconds,
                "{basis:?}: pass {} after pass {}",
                pair[1].pass,
                pair[0].pass
            );
        }
        let (emitted, absorbed) = (r.emitted_power.g, r.absorbed_power.g);
        assert!(
            (emitted - absorbed).abs() / emitted < 0.01,
            "{basis:?}: emitted {emitted}, absorbed {absorbed}"
        );
    }
}

/// Where the accuracy cannot be met at any element size (the furnace's edges, where the estimates of
/// links at different levels add up), error control stops once every failing leaf is at the minimum
/// element area, says so and counts them, instead of lowering thresholds until the pass limit: a
/// further pass could only split those leaves' sources.
#[test]
fn error_control_stops_when_only_leaves_at_the_minimum_area_fail() {
    let (rho, e) = (0.5, 1.0);
    let scene = generators::furnace(DVec3::new(1.0, 1.5, 2.0), rho, e);
    let min_area = 2e-3;
    let settings = SimulationSettings {
        oracle: OracleKind::Error,
        basis: BasisKind::Linear,
        accuracy: Some(Accuracy::Absolute(0.01 * e / (1.0 - rho))),
        min_area,
        max_passes: 40,
        ..Default::default()
    };
    let solution = simulate(&scene, &settings, &quiet()).expect("solve");
    let (h, error) = (&solution.hierarchy, &solution.report.error);
    let accuracy = error.accuracy.expect("error control");
    let smallest = min_area * h.total_area();
    let failing: Vec<_> = h
        .leaves()
        .into_iter()
        .filter(|&id| h.element(id).error > accuracy)
        .collect();
    eprintln!(
        "{} passes, {} of {} leaves failing, {}",
        solution.report.passes,
        failing.len(),
        h.leaf_count(),
        error.stopped_by
    );
    assert_eq!(error.stopped_by, "minimum element area");
    assert!(solution.report.passes < settings.max_passes);
    assert!(!failing.is_empty());
    assert_eq!(error.summary.leaves_above, failing.len());
    assert_eq!(error.summary.leaves_above_at_min_area, failing.len());
    for id in failing {
        assert!(
            h.element(id).area <= smallest,
            "leaf {id} could still be split"
        );
    }
}

/// Eq. (11) adds the propagated error `Σ_j ε̄_j ∫ K` to the realistic estimate's sources, so it bounds the
/// realistic estimate from above on every element, strictly where light is reflected onto it, and it
/// stays finite (the Jacobi iteration converges since Σ_j ∫ K = ρ < 1).
#[test]
fn the_conservative_estimate_bounds_the_realistic_one() {
    let scene = generators::lit_box(DVec3::new(2.0, 1.0, 1.5), Rgb::new(0.5, 0.4, 0.3), 10.0);
    let settings = SimulationSettings {
        basis: BasisKind::Linear,
        eps: 1e-3,
        ..Default::default()
    };
    let mut solution = simulate(&scene, &settings, &quiet()).expect("solve");
    let h = &mut solution.hierarchy;
    estimate_errors(h, EstimateKind::Realistic);
    let realistic: Vec<f64> = h.elements.iter().map(|e| e.error).collect();
    estimate_errors(h, EstimateKind::Conservative);
    let mut larger = 0;
    for (e, &r) in h.elements.iter().zip(&realistic) {
        assert!(e.error.is_finite());
        assert!(
            e.error >= r - 1e-12,
            "conservative {} < realistic {r}",
            e.error
        );
        larger += usize::from(e.error > r * (1.0 + 1e-9));
    }
    assert!(
        larger * 2 > h.elements.len(),
        "propagation adds error almost everywhere"
    );
}

/// Push-pull on trapezoids (quads whose Jacobian varies): with every basis, a patch whose leaves all
/// carry the same radiance (a constant emitter, or a reflector under uniform irradiance) is that
/// constant at every level, with no false gradient; and the pull keeps power: each parent's ∫ B dA
/// (integrated here with the Jacobian by an exact rule, independently of the overlap matrices) equals
/// the sum over its children, whatever their functions. Before the overlap solve (eq. (4)), the pull
/// by area weights gave a constant-emission trapezoid's inner elements a false gradient.
#[test]
fn push_pull_on_trapezoids_keeps_constants_constant_and_power_unchanged() {
    use radiosity::geometry::cubature::rule;
    use radiosity::hierarchy::ElementId;
    use radiosity::solvers::push_pull::push_pull;
    let trapezoid = |z: f64, up: bool| {
        let v = [
            DVec3::new(0.0, 0.0, z),
            DVec3::new(3.0, 0.0, z),
            DVec3::new(2.2, 1.0, z),
            DVec3::new(0.5, 1.3, z),
        ];
        Shape::Quad(if up { v } else { [v[3], v[2], v[1], v[0]] })
    };
    let scene = Scene {
        polygons: vec![
            Polygon {
                shape: trapezoid(0.0, true),
                material: 0,
                object: 0,
                two_sided: false,
                under_contact: false,
            },
            Polygon {
                shape: trapezoid(1.0, false),
                material: 1,
                object: 0,
                two_sided: false,
                under_contact: false,
            },
        ],
        materials: vec![
            Material::diffuse("grey", Rgb::splat(RHO)),
            Material::emitter("lamp", Rgb::BLACK, Rgb::splat(EMISSION)),
        ],
        objects: vec![radiosity::scene::Object {
            name: "plates".into(),
        }],
        ..Default::default()
    };
    for kind in radiosity::bases::BasisKind::ALL {
        let mut h = Hierarchy::new(&scene, kind);
        subdivide_uniformly(&mut h, 0, 3);
        subdivide_uniformly(&mut h, 1, 3);
        let n = h.basis_size();
        // ∫ B dA of an element's expansion.
        let power = |h: &Hierarchy, id: ElementId| -> f64 {
            let e = h.element(id);
            rule(e.shape().domain(), 12)
                .nodes
                .iter()
                .map(|&(uv, w)| w * e.shape().jacobian(uv) * h.radiance_at_parameters(id, uv).g)
                .sum()
        };
        let constant_everywhere = |h: &Hierarchy, patch: usize, value: f64, what: &str| {
            let mut stack = vec![h.patches[patch].root];
            while let Some(id) = stack.pop() {
                let e = h.element(id);
                for (a, c) in h.radiance(id).iter().enumerate() {
                    let expected = if a == 0 { value } else { 0.0 };
                    assert!(
                        (c.g - expected).abs() <= 1e-12 * value,
                        "{kind:?} {what}: level {} coefficient {a} = {}",
                        e.level,
                        c.g
                    );
                }
                stack.extend(e.children.iter().copied());
            }
        };
        // The emitter: constant emission at its leaves.
        let update = push_pull(&h, 1, &|_, _| {});
        update.apply(&mut h);
        constant_everywhere(&h, 1, EMISSION, "constant emitter");
        let area = h.element(h.patches[1].root).area;
        let exitant = std::f64::consts::PI * EMISSION * area;
        assert!((update.exitant.g - exitant).abs() <= 1e-12 * exitant);
        // The reflector under uniform irradiance H = 1, gathered at its root.
        let root = h.patches[0].root;
        let update = push_pull(&h, 0, &|id, out: &mut [Rgb]| {
            if id == root {
                out[0] += Rgb::splat(1.0);
            }
        });
        update.apply(&mut h);
        constant_everywhere(&h, 0, RHO, "uniformly lit reflector");
        // Non-uniform irradiance, a different function at every leaf: power kept by every pull.
        let update = push_pull(&h, 0, &|id, out: &mut [Rgb]| {
            if h.element(id).is_leaf() {
                for (a, o) in out.iter_mut().enumerate().take(n) {
                    *o += Rgb::splat(1.0 + 0.1 * ((id as usize * 7 + a * 3) % 11) as f64);
                }
            }
        });
        update.apply(&mut h);
        let mut stack = vec![root];
        while let Some(id) = stack.pop() {
            let e = h.element(id);
            if !e.is_leaf() {
                let children: f64 = e.children.iter().map(|&c| power(&h, c)).sum();
                let parent = power(&h, id);
                assert!(
                    (parent - children).abs() <= 1e-11 * children.abs(),
                    "{kind:?}: level {} pulls power {parent} from children's {children}",
                    e.level
                );
            }
            stack.extend(e.children.iter().copied());
        }
        let total = std::f64::consts::PI * power(&h, root);
        assert!((update.exitant.g - total).abs() <= 1e-11 * total);
    }
}

/// `∫_R ∫_E G V dA dA` from the upward `receiver` to the downward `emitter` by the midpoint rule with
/// visibility, `n_x²` receiver and `n_y²` emitter points.
fn visible_transfer(
    receiver: &Shape,
    emitter: &Shape,
    vis: &BruteForce,
    n_x: usize,
    n_y: usize,
) -> f64 {
    let midpoint = |k: usize, n: usize| {
        DVec2::new(
            ((k % n) as f64 + 0.5) / n as f64,
            ((k / n) as f64 + 0.5) / n as f64,
        )
    };
    let mut sum = 0.0;
    for a in 0..n_x * n_x {
        let x = receiver.point_at(midpoint(a, n_x));
        for b in 0..n_y * n_y {
            let y = emitter.point_at(midpoint(b, n_y));
            let g = point_to_point(x, DVec3::Z, y, -DVec3::Z);
            if g > 0.0 && !vis.segment_occluded(x, y) {
                sum += g;
            }
        }
    }
    sum * receiver.area() * emitter.area() / (n_x * n_x * n_y * n_y) as f64
}

/// `Σ A_i F_i` over the leaves of patch 0, each coupled with the root of patch 1 (linear basis, its
/// default cubature) by `source_rule` with `seed`.
fn coupled_transfer(
    h: &Hierarchy,
    vis: &BruteForce,
    source_rule: radiosity::solvers::coupling::SourceRule,
    seed: u64,
) -> f64 {
    let settings = CouplingSettings {
        cubature_degree: BasisKind::Linear.default_cubature_degree(),
        source_rule,
        seed,
        ..CouplingSettings::default()
    };
    let mut leaves = Vec::new();
    h.collect_leaves(h.patches[0].root, &mut leaves);
    leaves
        .iter()
        .map(|&leaf| {
            let k = couple(h, vis, leaf, h.patches[1].root, &settings, None);
            h.element(leaf).area * k.coupling.form_factor()
        })
        .sum()
}

/// A shadow boundary across the source (Bekaert–Willems Algorithm 4.1 samples visibility between
/// cubature nodes): a black strip 1 cm under the emitter hides its first 30% along `x` from every
/// point of the receiver below. The linear basis's 2 × 2 source nodes lie at 21% and 79%, so with
/// fixed nodes every receiver sees half the emitter instead of about 70% of its light, and the total
/// transfer comes out a quarter low however finely the receiver is split. With `--source-rule
/// jittered` each receiver node sees its own random nodes, one per quarter of the emitter, which is
/// unbiased: over the
/// 576 receiver nodes of 64 leaves, whose single estimates are ½ or 1, the transfer's relative
/// standard error is about 1.5%, and the test allows four of them. Exact: the midpoint rule with
/// visibility over 16 × 16 receiver points and 80 × 80 emitter points (discretisation error near 1%
/// at the shadow's edge of the emitter, far below the bias it separates).
#[test]
fn jittered_source_nodes_see_a_shadow_boundary_across_the_source_without_bias() {
    use radiosity::solvers::coupling::SourceRule;
    let scene = common::emitter_hidden_by_a_near_strip(RHO, EMISSION);
    let vis = brute_force(&scene);
    let emitter = emitter_shape(&scene);
    let exact = visible_transfer(&scene.polygons[0].shape, &emitter, &vis, 16, 80);
    let mut h = Hierarchy::new(&scene, BasisKind::Linear);
    subdivide_uniformly(&mut h, 0, 3);
    let transfer = |source_rule| coupled_transfer(&h, &vis, source_rule, 1);
    let (fixed, jittered) = (transfer(SourceRule::Fixed), transfer(SourceRule::Jittered));
    assert!(
        fixed < 0.85 * exact,
        "fixed nodes {fixed:.4}, exact {exact:.4}: the configuration no longer shows their bias"
    );
    assert!(
        (jittered / exact - 1.0).abs() < 0.06,
        "jittered nodes {jittered:.4}, exact {exact:.4} (fixed {fixed:.4})"
    );
}

/// The fixed rule's rows are normalised so that their unoccluded part is the exact point-to-polygon
/// factor: at random source nodes that ratio `Σ w G V / Σ w G` of two sums over the same draw is
/// biased where the kernel and the visibility vary together across the source. Here a 2 m emitting
/// strip is seen from a plate beyond its end, past a black plate that hides the strip's near part
/// (where the kernel is largest) from every receiver point, up to a place that moves with the point.
/// Over sixteen seeds the ratio came out 26% high with randomly shifted Gauss nodes (the rule the
/// jittered nodes replaced) and 12% high with jittered ones; the plain sum, which receiver nodes half
/// the strip's length or more away now take, 0.999 ± 0.010 (fixed nodes: 0.88). Exact: the midpoint
/// rule with visibility over 16 × 16 receiver points and 160 × 160 strip points (discretisation error
/// well under 1%). Allowance: four standard errors of the mean over the sixteen seeds, plus 1.5% for
/// the receiver side, whose fixed nodes sample the shadow's edge sweeping across the plate.
#[test]
fn jittered_source_nodes_keep_the_normalised_coupling_unbiased_where_kernel_and_visibility_vary_together(
) {
    use radiosity::solvers::coupling::SourceRule;
    let mut scene = generators::parallel_plates(1.0, 1.0, RHO, EMISSION);
    let quad = |x0: f64, x1: f64, y0: f64, y1: f64, z: f64, up: bool| {
        let (a, b) = (DVec3::new(x1, y0, z), DVec3::new(x0, y1, z));
        let (first, third) = (DVec3::new(x0, y0, z), DVec3::new(x1, y1, z));
        Shape::Quad(if up {
            [first, a, third, b]
        } else {
            [first, b, third, a]
        })
    };
    scene.polygons[0].shape = quad(-1.5, -0.5, -0.5, 0.5, 0.0, true);
    scene.polygons[1].shape = quad(0.0, 2.0, -0.05, 0.05, 1.0, false);
    let material = scene.materials.len();
    scene
        .materials
        .push(Material::diffuse("blocker", Rgb::BLACK));
    scene.polygons.push(Polygon {
        shape: quad(-0.5, -0.1, -1.0, 1.0, 0.5, true),
        material,
        object: 0,
        two_sided: true,
        under_contact: false,
    });
    let vis = brute_force(&scene);
    let (receiver, emitter) = (scene.polygons[0].shape, emitter_shape(&scene));
    assert_eq!(receiver.normal(), DVec3::Z);
    assert_eq!(emitter.normal(), -DVec3::Z);
    let exact = visible_transfer(&receiver, &emitter, &vis, 16, 160);
    let mut h = Hierarchy::new(&scene, BasisKind::Linear);
    subdivide_uniformly(&mut h, 0, 2);
    let transfer = |source_rule, seed| coupled_transfer(&h, &vis, source_rule, seed);
    let seeds = 16;
    let samples: Vec<f64> = (1..=seeds)
        .map(|seed| transfer(SourceRule::Jittered, seed) / exact)
        .collect();
    let mean = samples.iter().sum::<f64>() / seeds as f64;
    let variance = samples.iter().map(|s| (s - mean).powi(2)).sum::<f64>() / (seeds - 1) as f64;
    let standard_error = (variance / seeds as f64).sqrt();
    assert!(
        (mean - 1.0).abs() < 4.0 * standard_error + 0.015,
        "jittered nodes: transfer / exact {mean:.4} ± {standard_error:.4} (exact {exact:.5}; \
         fixed nodes {:.4})",
        transfer(SourceRule::Fixed, 1) / exact
    );
}

/// A local accuracy (`--local-accuracy`) keeps its promise where the absolute one alone does not: on the
/// shadowed plate, at a coarse absolute accuracy (a fifth of the brightest radiance) and 10% of each
/// leaf's own radiance, at least 95% of 400 random points are within `allowed_error` of the exact
/// radiance (the local target, floored at a tenth of the absolute accuracy), with eq. (1)'s power
/// oracle and with the link error oracle; the same absolute accuracy without it misses that target.
#[test]
fn local_accuracy_meets_its_relative_promise() {
    use radiosity::solvers::allowed_error;
    let scene = shadowed_plate();
    let (points, truth) = shadowed_points(&scene, 11);
    let brightest = truth.iter().copied().fold(0.0, f64::max);
    let (accuracy, local) = (0.2 * brightest, 0.1);
    let within = |oracle: OracleKind, local_accuracy: Option<f64>| {
        let settings = SimulationSettings {
            oracle,
            basis: BasisKind::Linear,
            error_storage: ErrorStorage::Reduced,
            accuracy: Some(Accuracy::Absolute(accuracy)),
            local_accuracy,
            eps: 1e-2,
            min_area: 1e-6,
            max_passes: 40,
            ..Default::default()
        };
        let solution = simulate(&scene, &settings, &quiet()).expect("solve");
        let h = &solution.hierarchy;
        let n = points_within(h, &points, &truth, |t| {
            allowed_error(accuracy, Some(local), t)
        });
        eprintln!(
            "{oracle:?} local {local_accuracy:?}: {n}/400 within, {} leaves, {}",
            h.leaf_count(),
            solution.report.error.stopped_by
        );
        n
    };
    for oracle in [OracleKind::Power, OracleKind::Error] {
        let n = within(oracle, Some(local));
        assert!(
            n >= 380,
            "{oracle:?}: only {n} of 400 points within the local accuracy"
        );
    }
    let n = within(OracleKind::Power, None);
    assert!(
        n < 380,
        "the absolute accuracy alone already meets the local target ({n} of 400): the test shows \
         nothing of the local accuracy"
    );
}
