//! The link audit (`measures::link_audit`) against ground truth: on two parallel plates its Monte
//! Carlo estimate of the receiver's total transfer matches Howell's closed form (C-11) within four of
//! its standard errors, and so do the couplings within 1%; with an emitter 30% hidden by a strip just
//! under it, it finds the fixed source nodes' bias (Bekaert–Willems Algorithm 4.1 as published) many
//! standard errors away, and none beyond the noise of jittered ones. Links from clusters and what
//! clusters push down are estimated to the closed form of unoccluded sources, and coupled within the
//! centre-to-centre transfer's error. The closure audit of a closed box gives every leaf a total
//! factor of 1.

#[allow(dead_code)] // each test file uses part of the shared module
mod common;
use radiosity::bases::BasisKind;
use radiosity::color::Rgb;
use radiosity::geometry::cubature::{nodes_on, rule};
use radiosity::geometry::form_factor::{parallel_rectangles, point_to_polygon};
use radiosity::geometry::{DVec3, Shape};
use radiosity::hierarchy::clusters::ClusteringKind;
use radiosity::hierarchy::{Hierarchy, Link, OracleFactor};
use radiosity::measures::link_audit::{
    audit_closure, audit_links, audit_transport, AuditSettings, AuditedSource,
};
use radiosity::pipeline::{simulate, SimulationSettings, Solution};
use radiosity::progress::Progress;
use radiosity::scene::{generators, Material, Object, Polygon, Scene};
use radiosity::solvers::coupling::{couple, CouplingSettings, SourceRule};
use radiosity::visibility::brute_force::BruteForce;

fn settings(samples: usize) -> AuditSettings {
    AuditSettings {
        polygons: vec![0],
        samples,
        max_links: 100_000,
        seed: 7,
    }
}

/// The audit's estimate of some light within four of its standard errors of the exact value `exact`
/// (and those errors below 5% of it), and what the solution coupled within `tolerance` of it.
fn assert_matches_exact(
    coupled: f64,
    estimated: f64,
    standard_error: f64,
    exact: f64,
    tolerance: f64,
) {
    eprintln!(
        "coupled {coupled:.6}, estimated {estimated:.6} ± {standard_error:.1e}, exact {exact:.6}"
    );
    assert!(
        (estimated - exact).abs() < 4.0 * standard_error && standard_error < 0.05 * exact,
        "estimated {estimated:.6} ± {standard_error:.1e}, exact {exact:.6}"
    );
    assert!(
        (coupled / exact - 1.0).abs() < tolerance,
        "coupled {coupled:.6}, exact {exact:.6}"
    );
}

#[test]
fn the_audit_of_two_parallel_plates_matches_the_closed_form() {
    let (rho, emission) = (0.5, 1.0);
    let scene = generators::parallel_plates(1.0, 1.0, rho, emission);
    let solution = simulate(
        &scene,
        &SimulationSettings {
            eps: 1e-4,
            ..SimulationSettings::default()
        },
        &Progress::new(true),
    )
    .expect("solve");
    let audit = audit_links(
        &solution.hierarchy,
        solution.visibility.as_ref(),
        &settings(256),
    )
    .expect("audit");
    assert!(audit.total.links > 1, "{} links", audit.total.links);
    // Every point pair of receiver × emitter is covered by exactly one link of the hierarchy, so the
    // links carry A_r F_re L_e in all.
    let exact = parallel_rectangles(1.0, 1.0, 1.0) * emission;
    let t = &audit.total;
    assert_matches_exact(t.coupled, t.estimated, t.standard_error, exact, 0.01);
}

#[test]
fn the_audit_finds_the_bias_of_fixed_source_nodes_behind_a_near_occluder() {
    let scene = common::emitter_hidden_by_a_near_strip(0.5, 1.0);
    let vis = BruteForce::new(scene.polygons.iter().map(|p| p.shape).collect());
    let audited = |source_rule: SourceRule| {
        let mut h = Hierarchy::new(&scene, BasisKind::Linear);
        for _ in 0..3 {
            let mut leaves = Vec::new();
            h.collect_leaves(h.patches[0].root, &mut leaves);
            for leaf in leaves {
                h.subdivide(leaf);
            }
        }
        let coupling = CouplingSettings {
            cubature_degree: BasisKind::Linear.default_cubature_degree(),
            source_rule,
            ..CouplingSettings::default()
        };
        let emitter = h.patches[1].root;
        let mut leaves = Vec::new();
        h.collect_leaves(h.patches[0].root, &mut leaves);
        for leaf in leaves {
            let k = couple(&h, &vis, leaf, emitter, &coupling, None);
            h.elements[leaf as usize].links.push(Link {
                source: emitter,
                coupling: k.coupling.with_shaft(k.shaft),
                oracle_factor: OracleFactor::NONE,
            });
        }
        audit_links(&h, &vis, &settings(1024)).expect("audit").total
    };
    let fixed = audited(SourceRule::Fixed);
    assert!(
        fixed.z() < -8.0,
        "fixed nodes: coupled {:.5}, estimated {:.5} ± {:.1e}",
        fixed.coupled,
        fixed.estimated,
        fixed.standard_error
    );
    // The jittered couplings are themselves random (about 1.5% over these 64 receivers, see
    // galerkin.rs), the audit's estimate much less: four of the couplings' standard errors.
    let jittered = audited(SourceRule::Jittered);
    assert!(
        (jittered.coupled / jittered.estimated - 1.0).abs() < 0.06,
        "jittered nodes: coupled {:.5}, estimated {:.5} ± {:.1e}",
        jittered.coupled,
        jittered.estimated,
        jittered.standard_error
    );
}

/// A closed unit cube of reflectance `rho` whose walls emit `emission`, solved finely (every leaf within
/// 10⁻³ of `E / (1 − ρ)`).
fn solved_furnace(rho: f64, emission: f64) -> (radiosity::scene::Scene, Solution) {
    let scene = generators::furnace(radiosity::geometry::DVec3::ONE, rho, emission);
    let solution = simulate(
        &scene,
        &SimulationSettings {
            eps: 1e-7,
            min_area: 1e-2,
            ..SimulationSettings::default()
        },
        &Progress::new(true),
    )
    .expect("solve");
    (scene, solution)
}

/// The transport audit of a closed white furnace: every ray of the gather meets a surface of radiance
/// `E / (1 − ρ)`, so both the gathered and the solved light are `ρ E / (1 − ρ) A`, each within the
/// solution's own uniformity (every leaf within 10⁻³ of `E / (1 − ρ)` at these settings:
/// `scene_generators.rs::furnace_mgf_solves_to_e_over_one_minus_rho`): 2·10⁻³ allowed, besides four
/// standard errors of the gather's direct part (a point on the emitting walls per ray).
#[test]
fn the_transport_audit_of_a_furnace_is_exact() {
    let (rho, emission) = (0.6, 2.0);
    let (scene, solution) = solved_furnace(rho, emission);
    let polygons: Vec<usize> = (0..scene.polygons.len()).collect();
    let rows = audit_transport(
        &solution.hierarchy,
        solution.visibility.as_ref(),
        &polygons,
        1 << 14,
        3,
    )
    .expect("audit");
    assert_eq!(rows.len(), scene.polygons.len());
    for row in rows {
        let exact = rho * emission / (1.0 - rho) * scene.polygons[row.polygon].shape.area();
        assert!((row.solved / exact - 1.0).abs() < 1e-3, "{row:?}");
        assert!(
            (row.gathered - row.solved).abs() < 2e-3 * row.solved + 4.0 * row.standard_error,
            "{row:?}"
        );
    }
}

/// The closure audit of a closed empty box: the exact point-to-polygon factors the couplings take for
/// their constant part sum to 1 at every receiver node of a closed polyhedron, so every leaf gathers a
/// total factor of 1 up to the couplings' `f32` storage (about 10⁻⁷ relative per link, hundreds of
/// links per leaf): 10⁻⁴ allowed. The box's leaves meet their own walls' links along shared edges,
/// where the kernel is singular, so this also checks that near-field couplings keep the closure.
#[test]
fn the_closure_audit_of_a_closed_box_is_one_everywhere() {
    let (_, solution) = solved_furnace(0.6, 2.0);
    let audit = audit_closure(&solution.hierarchy);
    assert!(audit.rows.len() > 6, "{} leaves", audit.rows.len());
    assert!(
        (audit.area_mean() - 1.0).abs() < 1e-4,
        "{}",
        audit.area_mean()
    );
    for row in &audit.rows {
        assert!((row.factor - 1.0).abs() < 1e-4, "{row:?}");
        assert_eq!(row.pushed, 0.0, "{row:?}");
    }
}

/// The transport audit sees the fixed source nodes' bias behind a near occluder (the whole receiver's
/// reflected light, from a full solve: +6%, its sign set by where refinement leaves the emitter's
/// element boundaries against the strip's edge) and not the jittered ones' beyond their noise (their
/// couplings' own, about 1.5%, and the gather's 0.45% at 2¹⁸ rays: 6% allowed).
#[test]
fn the_transport_audit_finds_the_bias_of_fixed_source_nodes() {
    let scene = common::emitter_hidden_by_a_near_strip(0.5, 1.0);
    let audit = |source_rule: SourceRule| {
        let solution = simulate(
            &scene,
            &SimulationSettings {
                source_rule,
                basis: BasisKind::Linear,
                eps: 1e-3,
                ..SimulationSettings::default()
            },
            &Progress::new(true),
        )
        .expect("solve");
        audit_transport(
            &solution.hierarchy,
            solution.visibility.as_ref(),
            &[0],
            1 << 18,
            5,
        )
        .expect("audit")
        .into_iter()
        .find(|row| row.front)
        .expect("the receiver's front")
    };
    let fixed = audit(SourceRule::Fixed);
    let jittered = audit(SourceRule::Jittered);
    assert!(
        ((fixed.solved - fixed.gathered) / fixed.standard_error).abs() > 8.0,
        "fixed: {fixed:?}"
    );
    assert!(
        (jittered.solved / jittered.gathered - 1.0).abs() < 0.06,
        "jittered: {jittered:?}"
    );
}

/// Twelve 0.1 m squares at height `z`, facing up or down, of material `material`, at least 0.12 m
/// apart: none hides another.
fn twelve_squares(z: f64, up: bool, material: usize) -> Vec<Polygon> {
    (0..12)
        .map(|k| {
            let (x, y) = (
                0.2 + 0.2 * (k % 4) as f64 + 0.04 * (k % 3) as f64,
                0.5 + 0.37 * (k / 4) as f64,
            );
            let s = 0.1;
            let mut corners = [
                DVec3::new(x, y, z),
                DVec3::new(x + s, y, z),
                DVec3::new(x + s, y + s, z),
                DVec3::new(x, y + s, z),
            ];
            if !up {
                corners.reverse();
            }
            Polygon {
                shape: Shape::Quad(corners),
                material,
                object: 0,
                two_sided: false,
                under_contact: false,
            }
        })
        .collect()
}

/// Solves `polygons` (material 0 a grey reflector, 1 a black lamp) with oriented clusters at a
/// coarse ε, so that light goes through cluster links.
fn clustered(polygons: Vec<Polygon>) -> Solution {
    let scene = Scene {
        polygons,
        materials: vec![
            Material::diffuse("grey", Rgb::splat(0.5)),
            Material::emitter("lamp", Rgb::BLACK, Rgb::new(1.0, 2.0, 3.0)),
        ],
        objects: vec![Object {
            name: "test".into(),
        }],
        ..Default::default()
    };
    simulate(
        &scene,
        &SimulationSettings {
            clustering: ClusteringKind::Oriented,
            eps: 1e-2,
            ..SimulationSettings::default()
        },
        &Progress::new(true),
    )
    .expect("solve")
}

/// `Σ A F L` from what `source` stands for (a surface, or a cluster's patches, at their average
/// radiance) to the surface `receiver`, which faces +z; `A F` by cubature of the closed-form
/// point-to-polygon factor. Exact where nothing hides anything and the sources' radiance is constant.
fn exact_light(h: &Hierarchy, receiver: &Shape, source: u32) -> f64 {
    let nodes = nodes_on(receiver, rule(receiver.domain(), 12));
    let sources = match h.cluster(source) {
        Some(cluster) => h.contents(cluster).to_vec(),
        None => vec![source],
    };
    sources
        .iter()
        .map(|&s| {
            let shape = h.element(s).shape();
            let factor: f64 = nodes
                .iter()
                .map(|x| x.weight * point_to_polygon(x.point, DVec3::Z, shape))
                .sum();
            factor * h.average_radiance(s).luminance()
        })
        .sum()
}

#[test]
fn the_audit_of_links_from_clusters_matches_the_exact_transfer_of_their_contents() {
    // A 2 m floor under twelve small black emitting squares 3 m up, facing it: with clusters and a
    // coarse ε the floor's elements gather from clusters of the squares. No square hides another
    // (they are coplanar) and each emits a constant radiance, so the light a link from a cluster
    // stands for is exactly Σ_k A_i F_ik L_k over the squares k it holds.
    let floor = Shape::Quad([
        DVec3::ZERO,
        DVec3::new(2.0, 0.0, 0.0),
        DVec3::new(2.0, 2.0, 0.0),
        DVec3::new(0.0, 2.0, 0.0),
    ]);
    let mut polygons = vec![Polygon {
        shape: floor,
        material: 0,
        object: 0,
        two_sided: false,
        under_contact: false,
    }];
    polygons.extend(twelve_squares(3.0, false, 1));
    let solution = clustered(polygons);
    let h = &solution.hierarchy;
    let audit = audit_links(h, solution.visibility.as_ref(), &settings(4096)).expect("audit");
    let from_clusters: Vec<_> = audit
        .rows
        .iter()
        .filter(|row| matches!(row.source, AuditedSource::Cluster { .. }))
        .collect();
    assert!(
        !from_clusters.is_empty(),
        "the test needs links from clusters"
    );
    // The exact light of every link from a cluster into the floor's elements.
    let mut exact = 0.0;
    for (id, element) in h.elements.iter().enumerate() {
        let id = id as u32;
        if h.is_cluster(id) || h.patch_of(id).polygon != 0 {
            continue;
        }
        for link in element.links.iter().filter(|l| h.is_cluster(l.source)) {
            exact += exact_light(h, element.shape(), link.source);
        }
    }
    let estimated: f64 = from_clusters.iter().map(|row| row.estimated).sum();
    let error = from_clusters
        .iter()
        .map(|row| row.standard_error.powi(2))
        .sum::<f64>()
        .sqrt();
    // The couplings' centre-to-centre transfer is close to it too: clusters about R = 0.5 m across
    // seen from 3 m, a far-field error of order (R / r)² ≈ 3%.
    let coupled: f64 = from_clusters.iter().map(|row| row.coupled).sum();
    assert_matches_exact(coupled, estimated, error, exact, 0.05);
}

#[test]
fn the_audit_of_what_clusters_push_down_matches_the_exact_transfer() {
    // Twelve small grey tiles on the ground, apart, under a black emitting square 3 m up: with
    // clusters and a coarse ε the tiles gather through links into clusters that hold them. Nothing
    // hides anything, so the light that the sources of those links send a tile is exactly
    // Σ A_tile F L over them.
    let mut polygons = twelve_squares(0.0, true, 0);
    // The lamp small against its height, so that the centre-to-centre transfer is accurate.
    polygons.push(Polygon {
        shape: Shape::Quad([
            DVec3::new(0.7, 0.7, 3.0),
            DVec3::new(0.7, 1.3, 3.0),
            DVec3::new(1.3, 1.3, 3.0),
            DVec3::new(1.3, 0.7, 3.0),
        ]),
        material: 1,
        object: 0,
        two_sided: false,
        under_contact: false,
    });
    let solution = clustered(polygons);
    let h = &solution.hierarchy;
    let tiles: Vec<usize> = (0..12).collect();
    let audit = audit_links(
        h,
        solution.visibility.as_ref(),
        &AuditSettings {
            polygons: tiles.clone(),
            ..settings(4096)
        },
    )
    .expect("audit");
    let pushed = &audit.into_clusters;
    assert!(pushed.links > 0, "the test needs links into clusters");
    // The exact light of every link of every cluster above a tile, on that tile.
    let mut exact = 0.0;
    for id in 0..h.elements.len() as u32 {
        let Some(cluster) = h.cluster(id) else {
            continue;
        };
        for &root in h.contents(cluster) {
            if tiles.contains(&h.patch_of(root).polygon) {
                for link in &h.element(id).links {
                    exact += exact_light(h, h.element(root).shape(), link.source);
                }
            }
        }
    }
    // What the clusters push down is the same light, up to the centre-to-centre transfer's error,
    // of order (R / r)² ≈ 5.4% for the tiles' cluster (bounding radius R ≈ 0.7 m) 3 m from the lamp.
    assert_matches_exact(
        pushed.coupled,
        pushed.estimated,
        pushed.standard_error,
        exact,
        0.06,
    );
}
