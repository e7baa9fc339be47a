//! Near cluster links (the source's bounding sphere reaches the receiver's box, where the centre
//! estimate of a cluster link is unbounded) against analytic form factors: a receiver beside a
//! cluster gets the light of the cluster's patches by their exact factors, and a small cluster beside
//! a source is split into its patches, each lit as the analytic factor says. Until 2026-11-30 such
//! links carried nothing and these receivers stayed black.

use radiosity::color::Rgb;
use radiosity::geometry::form_factor::parallel_rectangles_offset;
use radiosity::hierarchy::clusters::ClusteringKind;
use radiosity::hierarchy::{ElementId, Hierarchy};
use radiosity::pipeline::{simulate, SimulationSettings};
use radiosity::scene::{Material, Scene};
use radiosity::solvers::clustering::{SourceSphere, NEAR_RECEIVER_PATCHES};

#[allow(dead_code)] // each test file uses part of the shared module
mod common;
use common::{mean_radiance_of, one_polygon_per_material, quiet, rectangle};

const RHO: f64 = 0.5;
/// The small plate's extent in x and y, and the height of the large square over it.
const SMALL: [f64; 4] = [-0.1, 0.1, -0.1, 0.1];
const LARGE: [f64; 4] = [-0.5, 0.5, -0.5, 0.5];
const HEIGHT: f64 = 0.2;

/// The large square as `TILES`² tiles facing down at `HEIGHT` (so that they make a cluster of their
/// own beside the plate), then the small plate facing up at z = 0: polygon `TILES`².
fn plate_under_tiles(plate_two_sided: bool, tiles_two_sided: bool) -> Scene {
    let n = TILES * TILES;
    let mut materials = vec![Material::emitter("square", Rgb::BLACK, Rgb::splat(1.0)); n];
    materials.push(Material::diffuse("plate", Rgb::splat(RHO)));
    let side = (LARGE[1] - LARGE[0]) / TILES as f64;
    let tiles = (0..n).map(|k| {
        let (i, j) = ((k % TILES) as f64, (k / TILES) as f64);
        let (x, y) = (LARGE[0] + i * side, LARGE[2] + j * side);
        rectangle([x, x + side, y, y + side], HEIGHT, false)
    });
    one_polygon_per_material(materials, tiles.chain([rectangle(SMALL, 0.0, true)]), |k| {
        if k == n {
            plate_two_sided
        } else {
            tiles_two_sided
        }
    })
}

const TILES: usize = 4;
const PLATE: usize = TILES * TILES;

/// Clustered, coarse: the ends stay linked as clusters where the near rules let them.
fn solve(scene: &Scene) -> Hierarchy {
    let settings = SimulationSettings {
        clustering: ClusteringKind::Oriented,
        eps: 0.1,
        ..Default::default()
    };
    simulate(scene, &settings, &quiet())
        .expect("solve")
        .hierarchy
}

/// Whether the link from `source` into `receiver` is near ([`SourceSphere::reaches`]).
fn is_near(h: &Hierarchy, receiver: ElementId, source: ElementId) -> bool {
    SourceSphere::of(h, source).reaches(&h.bounds_of(receiver))
}

/// The mean factor from the small plate (facing up, at z = 0) to the large square `HEIGHT` above it:
/// Howell's C-12 for parallel rectangles.
fn small_to_large() -> f64 {
    parallel_rectangles_offset(SMALL, LARGE, HEIGHT)
}

/// A small plate (one-sided, facing up) `HEIGHT` under a large emitting square of two-sided tiles
/// that reflect nothing: the tiles make clusters of their own, and the plate gathers from them
/// through near links (a tile cluster's sphere, radius about 0.5, reaches 0.2 down). Ground truth:
/// the plate's radiance is `ρ E F`, `F` the analytic factor to the square (the tiles' upper sides face
/// away; what the plate reflects the black tiles absorb). Error model: the near coupling sums each
/// patch's exact factor (Lambert's contour integral) at the plate's cubature nodes and its rays are
/// all unblocked, so what is left is the cubature of the point factor over the plate, smooth across
/// it (it falls by about 15% from centre to corner), far under 1% at the default degree; 1% is
/// asked.
#[test]
fn a_receiver_beside_a_cluster_gets_its_patches_light_by_their_exact_factors() {
    let scene = plate_under_tiles(false, true);
    let h = solve(&scene);
    let plate = PLATE;
    let near_from_clusters = (0..h.elements.len() as ElementId)
        .filter(|&id| !h.is_cluster(id) && h.patch_of(id).polygon == plate)
        .flat_map(|id| h.element(id).links.iter().map(move |l| (id, l.source)))
        .filter(|&(id, source)| h.is_cluster(source) && is_near(&h, id, source))
        .count();
    assert!(
        near_from_clusters > 0,
        "the plate gathers through no near link from a cluster"
    );
    let analytic = RHO * small_to_large();
    let radiance = mean_radiance_of(&h, |k| h.patches[k].polygon == plate);
    assert!(
        (radiance - analytic).abs() <= 0.01 * analytic,
        "plate {radiance}, analytic {analytic}"
    );
}

/// The receiving side: a small two-sided plate `HEIGHT` under the large square of one-sided tiles.
/// The plate's two sides make a cluster of two patches (at most [`NEAR_RECEIVER_PATCHES`]) beside
/// the tiles' clusters, and a cluster's sharing (by the visible areas along the direction between
/// centres) could not place their light: refinement splits it into its patches, and no near link
/// into so small a cluster is left. Ground truth: the plate's upper side has the radiance `ρ E F` of
/// the test above, its lower side 0 (nothing under it). Error model as above: 1%.
#[test]
fn a_small_cluster_beside_a_source_is_split_into_patches_lit_as_the_analytic_factor_says() {
    let scene = plate_under_tiles(true, false);
    let h = solve(&scene);
    let plate_sides: Vec<ElementId> = (0..h.patches.len())
        .filter(|&k| h.patches[k].polygon == PLATE)
        .map(|k| h.patches[k].root)
        .collect();
    let plate_cluster = (0..h.elements.len() as ElementId).any(|id| {
        h.cluster(id).is_some_and(|c| {
            h.contents(c).len() <= NEAR_RECEIVER_PATCHES
                && plate_sides.iter().all(|p| h.contents(c).contains(p))
        })
    });
    assert!(
        plate_cluster,
        "no small cluster holds the plate's two sides"
    );
    let small_near = (0..h.elements.len() as ElementId)
        .filter(|&id| {
            h.cluster(id)
                .is_some_and(|c| h.contents(c).len() <= NEAR_RECEIVER_PATCHES)
        })
        .flat_map(|id| h.element(id).links.iter().map(move |l| (id, l.source)))
        .filter(|&(id, source)| is_near(&h, id, source))
        .count();
    assert_eq!(small_near, 0, "near links into small clusters are left");
    let upper = |k: usize| h.patches[k].normal.z > 0.0 && h.patches[k].polygon == PLATE;
    let lower = |k: usize| h.patches[k].normal.z < 0.0 && h.patches[k].polygon == PLATE;
    let analytic = RHO * small_to_large();
    let lit = mean_radiance_of(&h, upper);
    assert!(
        (lit - analytic).abs() <= 0.01 * analytic,
        "upper side {lit}, analytic {analytic}"
    );
    let dark = mean_radiance_of(&h, lower);
    assert!(dark <= 1e-12, "lower side {dark}");
}
