//! The refinement oracles (Feixas et al. eqs. (1), (2), (15)) driving full hierarchical solves, and their
//! determinism.

use radiosity::color::Rgb;
use radiosity::geometry::form_factor::parallel_rectangles;
use radiosity::geometry::DVec3;
use radiosity::hierarchy::Hierarchy;
use radiosity::oracles::OracleContext;
use radiosity::pipeline::{
    build_visibility, make_oracle, simulate, OracleKind, SimulationSettings, VisibilityKind,
};
use radiosity::progress::Progress;
use radiosity::scene::generators;
use rand::SeedableRng;
use rand_pcg::Pcg64Mcg;

const ORACLES: [OracleKind; 3] = [
    OracleKind::Power,
    OracleKind::Smoothness,
    OracleKind::MutualInformation,
];

/// Per-oracle ε giving meshes of comparable size: eq. (2) is scaled by the total area and eq. (15) by a
/// squared coefficient of variation, so the three thresholds are not interchangeable.
fn settings(oracle: OracleKind) -> SimulationSettings {
    let eps = match oracle {
        OracleKind::Power => 1e-3,
        OracleKind::Smoothness => 1e-2,
        OracleKind::MutualInformation => 1e-4,
        OracleKind::Error => unreachable!("the link error oracle is tested in tests/galerkin.rs"),
    };
    SimulationSettings {
        oracle,
        eps,
        min_area: 1e-3,
        ..Default::default()
    }
}

#[test]
fn every_oracle_solves_the_closed_box_with_energy_balance() {
    let scene = generators::lit_box(DVec3::new(2.0, 1.0, 1.5), Rgb::new(0.5, 0.4, 0.3), 10.0);
    for oracle in ORACLES {
        let solution = simulate(&scene, &settings(oracle), &Progress::new(true)).expect("solve");
        let (h, r) = (&solution.hierarchy, &solution.report);
        for (emitted, absorbed) in r
            .emitted_power
            .to_array()
            .iter()
            .zip(r.absorbed_power.to_array())
        {
            assert!(
                (emitted - absorbed).abs() / emitted < 0.01,
                "{oracle:?}: emitted {emitted}, absorbed {absorbed}"
            );
        }
        let leaves = h.leaf_count();
        assert!(
            leaves > 4 * h.patches.len(),
            "{oracle:?}: no refinement ({leaves} leaves)"
        );
        match oracle {
            OracleKind::Power => assert_eq!(r.oracle_rays, 0),
            _ => assert!(r.oracle_rays > 0, "{oracle:?}: oracle rays not counted"),
        }
        eprintln!(
            "{oracle:?}: {leaves} leaves, {} links, {} oracle rays, {} form factor rays, {} passes",
            h.link_count(),
            r.oracle_rays,
            r.form_factor_rays,
            r.passes
        );
    }
}

#[test]
fn every_oracle_reproduces_the_parallel_plates_form_factor() {
    let (rho, e) = (0.5, 1.0);
    let scene = generators::parallel_plates(1.0, 1.0, rho, e);
    let exact = parallel_rectangles(1.0, 1.0, 1.0);
    for oracle in ORACLES {
        let solution = simulate(&scene, &settings(oracle), &Progress::new(true)).expect("solve");
        let h = &solution.hierarchy;
        let root = h.patches[0].root;
        let f = h.average_radiance(root).g / (rho * e);
        assert!(
            (f - exact).abs() / exact < 0.01,
            "{oracle:?}: F = {f}, exact {exact}"
        );
        assert!(
            h.leaf_count() > h.patches.len(),
            "{oracle:?}: no refinement"
        );
        eprintln!(
            "{oracle:?}: F = {f:.5} (exact {exact:.5}), {} leaves, {} oracle rays",
            h.leaf_count(),
            solution.report.oracle_rays
        );
    }
}

#[test]
fn every_oracle_estimate_is_deterministic_for_a_seed() {
    let scene = generators::lit_box(DVec3::new(2.0, 1.0, 1.5), Rgb::new(0.5, 0.4, 0.3), 10.0);
    let h = Hierarchy::new(&scene, radiosity::bases::BasisKind::Constant);
    let visibility = build_visibility(&scene, VisibilityKind::BruteForce).expect("visibility");
    let context = OracleContext {
        hierarchy: &h,
        visibility: visibility.as_ref(),
    };
    // Floor (-y face) receiving from the emitting ceiling (+y face).
    let (receiver, source) = (h.patches[2].root, h.patches[3].root);
    for kind in ORACLES {
        let oracle = make_oracle(&settings(kind), &h);
        let run = |seed| {
            oracle.estimate(
                &context,
                receiver,
                source,
                &mut Pcg64Mcg::seed_from_u64(seed),
            )
        };
        let first = run(11);
        assert_eq!(first, run(11), "{kind:?}");
        assert!(first.error > 0.0, "{kind:?}");
        match kind {
            OracleKind::Power => assert_eq!(first.rays, 0),
            _ => {
                assert_eq!(first.rays, 10, "{kind:?}: one ray per sample pair");
                assert_ne!(first, run(12), "{kind:?}: the estimate must use the rng");
            }
        }
    }
}

#[test]
fn oracle_names_match_the_command_line() {
    let scene = generators::parallel_plates(1.0, 1.0, 0.5, 1.0);
    let h = Hierarchy::new(&scene, radiosity::bases::BasisKind::Constant);
    for (kind, name) in ORACLES.iter().zip(["power", "smoothness", "mi"]) {
        assert_eq!(make_oracle(&settings(*kind), &h).name(), name);
        let parsed = <OracleKind as clap::ValueEnum>::from_str(name, false);
        assert_eq!(parsed, Ok(*kind));
    }
}
