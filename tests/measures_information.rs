//! Information-theoretic scene measures (Feixas et al. eqs. (3), (10); their ref. [5]) against hand
//! values, an independent quadrature, and the inequalities of §2.2: I^d ≤ I^c, I^d grows and Δ shrinks
//! under refinement.

use radiosity::color::Rgb;
use radiosity::geometry::form_factor::{parallel_rectangles, point_to_point};
use radiosity::geometry::DVec3;
use radiosity::measures::global_lines::GlobalLines;
use radiosity::measures::information::{measure, HierarchyLeaves, InformationMeasures, LeafSystem};
use radiosity::pipeline::{simulate, SimulationSettings, Solution};
use radiosity::progress::Progress;
use radiosity::scene::{cornell::cornell_box, generators, Scene};

fn solve(scene: &Scene, eps: f64) -> Solution {
    let settings = SimulationSettings {
        eps,
        ..Default::default()
    };
    simulate(scene, &settings, &Progress::new(true)).expect("solve")
}

fn measures_of(scene: &Scene, solution: &Solution, lines: usize) -> InformationMeasures {
    let lines = GlobalLines::trace(
        scene,
        &solution.hierarchy,
        solution.visibility.as_ref(),
        lines,
        7,
    );
    measure(scene, &solution.hierarchy, &lines).expect("measure")
}

#[test]
fn two_parallel_plates_by_hand() {
    // Two facing unit squares at distance 1: each sees only the other, so the line joining two surfaces
    // tells with certainty where its other end is — one bit, whatever F or the radiosities are.
    let f = parallel_rectangles(1.0, 1.0, 1.0);
    let system = LeafSystem::dense(vec![1.0, 1.0], &[vec![0.0, f], vec![f, 0.0]]);
    assert!((system.discrete_information(&[1.0, 1.0]) - 1.0).abs() < 1e-12);
    assert!((system.discrete_information(&[0.3, 5.0]) - 1.0).abs() < 1e-12);
    // Unequal plates: eq. (3) by hand with A_1 F_12 = A_2 F_21 = g gives p_12 = p_21 = 1/2 again.
    let g = 0.1;
    let system = LeafSystem::dense(vec![2.0, 0.5], &[vec![0.0, g / 2.0], vec![g / 0.5, 0.0]]);
    assert!((system.discrete_information(&[1.0, 1.0]) - 1.0).abs() < 1e-12);
    // The solved scene (two patches, no refinement) agrees, and B_r = ρ F E matches the analytic F.
    let scene = generators::parallel_plates(1.0, 1.0, 0.5, 1.0);
    let solution = solve(&scene, 10.0);
    let leaves = HierarchyLeaves::new(&solution.hierarchy).expect("leaves");
    assert_eq!(leaves.leaves.len(), 2);
    let ones = [1.0, 1.0];
    assert!((leaves.system.discrete_information(&ones) - 1.0).abs() < 1e-9);
    assert!((leaves.system.discrete_information(&leaves.radiosity) - 1.0).abs() < 1e-9);
    let incoming = leaves.system.incoming(&ones);
    assert!((incoming[0] - f).abs() < 0.01 * f, "{incoming:?} vs {f}");
}

#[test]
fn closed_cube_matches_reference_five_formula() {
    // Unit cube: F to the opposite face (Howell C-11) and, by closure, to each adjacent face. In a closed
    // scene eq. (3) with B ≡ 1 is ref. [5]'s I_v^d = Σ_ij (A_i/A_T) F_ij log2(F_ij A_T / A_j).
    let opposite = parallel_rectangles(1.0, 1.0, 1.0);
    let adjacent = (1.0 - opposite) / 4.0;
    let by_hand = opposite * (6.0 * opposite).log2() + 4.0 * adjacent * (6.0 * adjacent).log2();
    let mut f = vec![vec![adjacent; 6]; 6];
    for (i, row) in f.iter_mut().enumerate() {
        row[i] = 0.0;
        row[i ^ 1] = opposite; // box_faces order: -x, +x, -y, +y, -z, +z
    }
    let system = LeafSystem::dense(vec![1.0; 6], &f);
    let ones = [1.0; 6];
    assert!((system.discrete_information(&ones) - by_hand).abs() < 1e-12);
    // Uniform radiosity (the furnace) gives the visibility measure.
    assert!((system.discrete_information(&[2.5; 6]) - by_hand).abs() < 1e-12);
    // The solved furnace with six unrefined patches: its link form factors are close to the analytic ones.
    let scene = generators::furnace(DVec3::ONE, 0.5, 1.0);
    let solution = solve(&scene, 10.0);
    let m = measures_of(&scene, &solution, 20_000);
    assert_eq!(m.leaves, 6);
    assert!(
        (m.visibility_discrete - by_hand).abs() < 0.01,
        "{} vs {by_hand}",
        m.visibility_discrete
    );
    // Uniform radiosity: the radiosity measures are the visibility ones.
    assert!((m.radiosity_discrete - m.visibility_discrete).abs() < 1e-6);
    assert!((m.radiosity_continuous - m.visibility_continuous).abs() < 1e-6);
}

#[test]
fn global_lines_match_quadrature_for_parallel_plates() {
    // I_v^c of two unit squares at distance 1 (B ≡ 1, eq. (10)): B^in = F on both, 𝒜_T = 2F, so
    // I^c = (1/F) ∫∫ F(x,y) log2(2 F(x,y) / F) dx dy. Reference: midpoint rule on a 24^4 grid.
    let f = parallel_rectangles(1.0, 1.0, 1.0);
    let n = 24;
    let h = 1.0 / n as f64;
    let mut reference = 0.0;
    for a in 0..n * n {
        let x = DVec3::new((a % n) as f64 + 0.5, (a / n) as f64 + 0.5, 0.0) * h;
        for b in 0..n * n {
            let y = DVec3::new((b % n) as f64 + 0.5, (b / n) as f64 + 0.5, 1.0 / h) * h;
            let k = point_to_point(x, DVec3::Z, y, -DVec3::Z);
            reference += k * (2.0 * k / f).log2() * h.powi(4);
        }
    }
    reference /= f;
    let scene = generators::parallel_plates(1.0, 1.0, 0.5, 1.0);
    // Degree-9 cubature: link form factors close to the analytic F used by the reference.
    let settings = SimulationSettings {
        eps: 10.0,
        cubature_degree: Some(9),
        ..Default::default()
    };
    let solution = simulate(&scene, &settings, &Progress::new(true)).expect("solve");
    let m = measures_of(&scene, &solution, 200_000);
    let tolerance = 4.0 * m.visibility_continuous_error + 0.01;
    assert!(
        (m.visibility_continuous - reference).abs() < tolerance,
        "global lines {} ± {} vs quadrature {reference}",
        m.visibility_continuous,
        m.visibility_continuous_error
    );
    assert!(m.visibility_continuous > m.visibility_discrete);
}

#[test]
fn incoming_radiosity_is_the_solved_gather() {
    // B^in = Σ_j F_ij B_j over the link blocks equals (B − E)/ρ of the solved leaves (channel average).
    let scene = generators::lit_box(DVec3::new(1.0, 1.5, 2.0), Rgb::new(0.7, 0.5, 0.3), 1.0);
    let solution = solve(&scene, 1e-3);
    let h = &solution.hierarchy;
    let leaves = HierarchyLeaves::new(h).expect("leaves");
    assert!(leaves.leaves.len() > 6);
    let incoming = leaves.system.incoming(&leaves.radiosity);
    for (k, &leaf) in leaves.leaves.iter().enumerate() {
        let patch = h.patch_of(leaf);
        let b = h.average_radiance(leaf);
        let rho = patch.reflectance.to_array();
        let expected: f64 = (0..3)
            .map(|c| (b.to_array()[c] - patch.emission.to_array()[c]) / rho[c])
            .sum::<f64>()
            / 3.0;
        assert!(
            (incoming[k] - expected).abs() <= 1e-3 * expected.abs().max(1e-3),
            "leaf {leaf}: {} vs {expected}",
            incoming[k]
        );
    }
}

#[test]
fn discrete_information_is_below_continuous() {
    let scenes = [
        (
            "lit box",
            generators::lit_box(DVec3::new(1.0, 1.0, 1.0), Rgb::splat(0.6), 1.0),
        ),
        (
            "parallel plates",
            generators::parallel_plates(1.0, 0.5, 0.7, 1.0),
        ),
        (
            "furnace",
            generators::furnace(DVec3::new(1.0, 2.0, 1.5), 0.5, 1.0),
        ),
        ("cornell", cornell_box()),
    ];
    for (name, scene) in &scenes {
        for eps in [1e-1, 1e-2] {
            let solution = solve(scene, eps);
            let m = measures_of(scene, &solution, 40_000);
            let r_margin = 3.0 * m.radiosity_continuous_error;
            let v_margin = 3.0 * m.visibility_continuous_error;
            assert!(
                m.radiosity_discrete >= 0.0 && m.visibility_discrete >= 0.0,
                "{name}: {m:?}"
            );
            assert!(
                m.radiosity_discrete <= m.radiosity_continuous + r_margin,
                "{name} eps {eps}: I_r^d {} > I_r^c {} ± {}",
                m.radiosity_discrete,
                m.radiosity_continuous,
                m.radiosity_continuous_error
            );
            assert!(
                m.visibility_discrete <= m.visibility_continuous + v_margin,
                "{name} eps {eps}: I_v^d {} > I_v^c {} ± {}",
                m.visibility_discrete,
                m.visibility_continuous,
                m.visibility_continuous_error
            );
        }
    }
}

#[test]
fn cornell_refinement_raises_discrete_information_and_shrinks_delta() {
    let scene = cornell_box();
    let mut previous: Option<InformationMeasures> = None;
    // The same global lines for every level: Δ differences are not Monte Carlo noise of I^c.
    let mut lines = None;
    for eps in [1e-1, 1e-2, 1e-3] {
        let solution = solve(&scene, eps);
        let lines = lines.get_or_insert_with(|| {
            GlobalLines::trace(
                &scene,
                &solution.hierarchy,
                solution.visibility.as_ref(),
                40_000,
                3,
            )
        });
        let m = measure(&scene, &solution.hierarchy, lines).expect("measure");
        if let Some(p) = previous {
            assert!(m.leaves > p.leaves);
            assert!(
                m.radiosity_discrete >= p.radiosity_discrete - 1e-3,
                "eps {eps}: I_r^d {} after {}",
                m.radiosity_discrete,
                p.radiosity_discrete
            );
            assert!(
                m.visibility_discrete >= p.visibility_discrete - 1e-3,
                "eps {eps}: I_v^d {} after {}",
                m.visibility_discrete,
                p.visibility_discrete
            );
            assert!(
                m.delta < p.delta,
                "eps {eps}: Δ {} after {}",
                m.delta,
                p.delta
            );
        }
        assert!(m.delta > 0.0 && m.delta < 1.0, "{m:?}");
        previous = Some(m);
    }
}

#[test]
fn measures_do_not_depend_on_thread_count() {
    let scene = cornell_box();
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("pool");
        pool.install(|| {
            let solution = solve(&scene, 1e-2);
            measures_of(&scene, &solution, 5_000)
        })
    };
    assert_eq!(run(1), run(3));
}
