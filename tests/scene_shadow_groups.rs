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

use radiosity::experiments::shadow_groups::Wall;
use radiosity::measures::fbem::{self, Mask};
use radiosity::output::image::Image;
use radiosity::progress::Progress;
use radiosity::scene::generators::ShadowGroups;
use radiosity::visibility::bvh::Bvh;

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
    // Black cubes (Wall makes them so): pure occluders, direct shadows as in Appendix A. Wall elements
    // stop at quadtree level 7 (side 1/128 of a tile, about 0.012, a third of the smallest shadow).
    let wall = Wall::new(&ShadowGroups::default());
    let groups = &wall.groups;
    let quiet = Progress::new(true);
    let (reference, _) = wall.solve(&Bvh::new(&wall.shapes), 7, &quiet);
    let (unoccluded, _) = wall.solve(&Bvh::new(wall.unoccluded()), 7, &quiet);
    eprintln!("reference: {} leaf elements", reference.leaf_count());

    let sizes = [2usize, 12];
    let mut table = Vec::new();
    for k in 0..groups.cube_sizes.len() {
        let r = wall.image(&reference, k);
        let u = wall.image(&unoccluded, k);
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
