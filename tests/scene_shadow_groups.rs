//! The feature-based error metric on the scene of Sillion & Drettakis, Figures 1 and 9 (Table 1): a wall
//! lit by a small source through four groups of cubes of sizes 0.03 to 0.24.
//!
//! Reference: a finely refined radiosity solution (wall elements of 0.012, a third of the smallest
//! shadow), rendered flat and head-on, one image per group region, pixels of 0.009 so that the shadows
//! are about 4, 8, 16 and 34 pixels wide. Approximation of group k: its occlusion averaged, the way a
//! cluster's visibility is replaced by its mean transmittance — the unoccluded wall (the same solve
//! without cubes) times the mean over the region of reference / unoccluded. Its L² error is alike for the
//! four groups (each covers a quarter of its footprint: Appendix A), but the FBEM at a feature size s
//! between the shadow sizes is small for the groups whose shadows are smaller than s and stays large
//! for the others.

use radiosity::geometry::{DVec3, Shape};
use radiosity::hierarchy::Hierarchy;
use radiosity::measures::fbem::{self, Mask};
use radiosity::output::camera::Camera;
use radiosity::output::image::Image;
use radiosity::output::render::{render, RenderOptions, Shading};
use radiosity::pipeline::{deterministic_settings, make_oracle, make_solver, SimulationSettings};
use radiosity::progress::Progress;
use radiosity::scene::generators::ShadowGroups;
use radiosity::scene::{CameraSpec, Scene};
use radiosity::solvers::solve;
use radiosity::visibility::bvh::Bvh;

/// Image pixel size on the wall.
const PIXEL: f64 = 0.009;
const FOV_DEGREES: f64 = 30.0;

/// Hierarchical radiosity on the receivers (wall tiles and source) with rays cast against `occluders`.
/// With black cubes this is the solution of the whole scene: black cubes emit and reflect nothing, so
/// they act on the wall only by blocking rays; leaving their ~2000 patches out of the hierarchy spares
/// the four million initial patch pairs that would cost a minute.
fn solve_wall(receivers: &Scene, occluders: &[Shape], tile_area: f64) -> Hierarchy {
    let settings = SimulationSettings {
        eps: 1e-7,
        // A degree-1 cubature (one node on each element, one visibility ray per link): the elements are
        // tiny next to their distance to the source, so the form factor needs no more.
        cubature_degree: Some(1),
        ..Default::default()
    };
    let mut h = Hierarchy::new(receivers, radiosity::bases::BasisKind::Constant);
    // Wall elements stop at quadtree level 7 (side 1/128 of a tile, about 0.012, a third of the smallest
    // shadow): level-6 elements are still splittable, level-7 ones not.
    let mut solve_settings = deterministic_settings(&settings, &h);
    solve_settings.refine.min_area = 0.5 * tile_area / 4f64.powi(6);
    let oracle = make_oracle(&settings, &h);
    let solver = make_solver(settings.solver);
    solve(
        &mut h,
        &Bvh::new(occluders),
        oracle.as_ref(),
        solver.as_ref(),
        &solve_settings,
        &Progress::new(true),
    );
    h
}

/// Flat render of the wall tiles alone (the cubes and source are not in the view), head-on over the
/// shadow region of group `k`.
fn wall_image(solution: &Hierarchy, groups: &ShadowGroups, tiles: &Bvh, k: usize) -> Image {
    let [x0, x1, y0, y1] = groups.shadow_region(k);
    let side = (x1 - x0).max(y1 - y0);
    let n = (side / PIXEL).round() as usize;
    let centre = DVec3::new(0.5 * (x0 + x1), 0.5 * (y0 + y1), 0.0);
    let half_height = 0.5 * n as f64 * PIXEL;
    let distance = half_height / (0.5 * FOV_DEGREES).to_radians().tan();
    let spec = CameraSpec {
        eye: centre + DVec3::Z * distance,
        look_at: centre,
        up: DVec3::Y,
        fov_degrees: FOV_DEGREES,
    };
    let options = RenderOptions {
        shading: Shading::Flat,
        ..Default::default()
    };
    render(solution, tiles, &Camera::new(&spec, n, n), &options)
}

/// The occlusion of the region averaged: unoccluded × mean(reference / unoccluded).
fn averaged_occlusion(reference: &Image, unoccluded: &Image) -> Image {
    let ratios: Vec<f64> = reference
        .pixels
        .iter()
        .zip(&unoccluded.pixels)
        .map(|(r, u)| r.luminance() / u.luminance())
        .collect();
    let mean = ratios.iter().sum::<f64>() / ratios.len() as f64;
    let mut out = unoccluded.clone();
    for p in &mut out.pixels {
        *p *= mean;
    }
    out
}

#[test]
fn fbem_separates_the_groups_by_shadow_size() {
    let groups = ShadowGroups {
        // Black cubes: pure occluders, direct shadows as in Appendix A.
        cube_reflectance: 0.0,
        ..Default::default()
    };
    let scene = groups.scene();
    let t = groups.wall_tiles();
    let tile_area = scene.polygons[0].shape.area();
    let shapes: Vec<Shape> = scene.polygons.iter().map(|p| p.shape).collect();
    let mut bare = scene.clone();
    bare.polygons.truncate(t + 1);
    let reference = solve_wall(&bare, &shapes, tile_area);
    let unoccluded = solve_wall(&bare, &shapes[..t + 1], tile_area);
    eprintln!("reference: {} leaf elements", reference.leaf_count());
    let tiles = Bvh::new(&shapes[..t]);

    let sizes = [2usize, 12];
    let mut table = Vec::new();
    for k in 0..groups.cube_sizes.len() {
        let r = wall_image(&reference, &groups, &tiles, k);
        let u = wall_image(&unoccluded, &groups, &tiles, k);
        assert!(
            u.pixels.iter().all(|p| p.luminance() > 0.0),
            "wall fully lit"
        );
        let approx = averaged_occlusion(&r, &u);
        let features: Mask = fbem::shadow_mask(&r, &u, 0.2).expect("mask");
        let covered = features.count() as f64 / features.bits.len() as f64;
        assert!(
            (0.1..0.6).contains(&covered),
            "group {k}: shadows cover {covered}"
        );
        let values: Vec<f64> = sizes
            .iter()
            .map(|&s| {
                fbem::fbem(&approx, &r, &features, s, 2.0, None)
                    .expect("fbem")
                    .value
            })
            .collect();
        let mean = r.pixels.iter().map(|p| p.luminance()).sum::<f64>() / r.pixels.len() as f64;
        eprintln!(
            "group {k} (cubes {}): {}x{} px, shadows {covered:.3}, mean {mean:.4}, FBEM s=2 {:.5}, s=12 {:.5}",
            groups.cube_sizes[k], r.width, r.height, values[0], values[1]
        );
        table.push((values[0] / mean, values[1] / mean));
    }
    // s = 2 is nearly the L² error: alike for the four groups (same mean occlusion).
    let small: Vec<f64> = table.iter().map(|v| v.0).collect();
    let (lo, hi) = small
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(a, b), &v| (a.min(v), b.max(v)));
    assert!(hi < 2.0 * lo, "relative L² errors {small:?}");
    // s = 12 px lies between the shadows of groups 1 (8 px) and 2 (16 px): the averaged small shadows
    // cost little, the averaged large ones stay costly.
    // As in Table 1, the FBEM falls with s the faster, the smaller the cubes.
    for pair in table.windows(2) {
        assert!(
            pair[0].1 / pair[0].0 < pair[1].1 / pair[1].0,
            "FBEM(12) / FBEM(2) should grow with the cube size: {table:?}"
        );
    }
    for (k, &(s2, s12)) in table.iter().enumerate() {
        if k < 2 {
            assert!(
                s12 < 0.3 * s2,
                "group {k}: FBEM {s12} at s = 12 vs {s2} at s = 2"
            );
        } else {
            assert!(
                s12 > 0.6 * s2,
                "group {k}: FBEM {s12} at s = 12 vs {s2} at s = 2"
            );
        }
    }
}
