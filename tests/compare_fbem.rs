//! The Table 1 behaviour of the feature-based error metric (Sillion & Drettakis §2.3) on synthetic images:
//! a lit wall with four groups of square shadows of different sizes, and approximations in which one
//! group's shadows are replaced by their local average. L² errors cannot tell the groups apart (§2.1,
//! Appendix A); the FBEM is small once the feature size exceeds the averaged shadows, and stays large
//! below.

use radiosity::color::Rgb;
use radiosity::measures::fbem::{self, Mask};
use radiosity::measures::image_metrics;
use radiosity::output::image::Image;

const TILE: usize = 144;
const GROUPS: usize = 4;
/// Side of the square shadows of each group; each sits in a cell twice as wide (a quarter in shadow).
const SIDES: [usize; GROUPS] = [3, 6, 12, 24];
/// The shadowed area of each tile is [MARGIN, TILE − MARGIN)², a whole number of cells of every group,
/// surrounded by lit wall.
const MARGIN: usize = 24;

/// Unoccluded illumination: a gentle vertical gradient, as from a source above, the same in every tile.
fn unoccluded(y: usize) -> f64 {
    1.0 - 0.002 * y as f64
}

fn in_shadow(x: usize, y: usize) -> bool {
    let group = x / TILE;
    let (lx, ly) = (x % TILE, y);
    let side = SIDES[group];
    let inside = (MARGIN..TILE - MARGIN).contains(&lx) && (MARGIN..TILE - MARGIN).contains(&ly);
    inside && (lx - MARGIN) % (2 * side) < side && (ly - MARGIN) % (2 * side) < side
}

fn wall(shadows: bool) -> Image {
    let (w, h) = (TILE * GROUPS, TILE);
    let mut img = Image::new(w, h);
    for y in 0..h {
        for x in 0..w {
            let lit = unoccluded(y);
            let v = if shadows && in_shadow(x, y) {
                0.2 * lit
            } else {
                lit
            };
            img.set(x, y, Rgb::new(v, 0.9 * v, 0.8 * v));
        }
    }
    img
}

/// The reference with the shadows of `group` averaged: inside that tile, each pixel takes the mean of
/// the reference over the shadow cell (2·side square) that contains it — what a mesh as coarse as the
/// cells computes (§2.3, Figure 1 middle row).
fn averaged(reference: &Image, group: usize) -> Image {
    let mut img = reference.clone();
    let cell = 2 * SIDES[group];
    let x0 = group * TILE + MARGIN;
    for cy in (MARGIN..TILE - MARGIN).step_by(cell) {
        for cx in (x0..x0 + TILE - 2 * MARGIN).step_by(cell) {
            let mut sum = Rgb::BLACK;
            for y in cy..cy + cell {
                for x in cx..cx + cell {
                    sum += reference.get(x, y);
                }
            }
            let mean = sum / (cell * cell) as f64;
            for y in cy..cy + cell {
                for x in cx..cx + cell {
                    img.set(x, y, mean);
                }
            }
        }
    }
    img
}

fn fbem_value(approx: &Image, reference: &Image, features: &Mask, size: usize) -> f64 {
    fbem::fbem(approx, reference, features, size, 2.0, None)
        .unwrap()
        .value
}

#[test]
fn shadow_mask_is_the_shadowed_region() {
    let mask = fbem::shadow_mask(&wall(true), &wall(false), 0.1).unwrap();
    let (w, h) = (TILE * GROUPS, TILE);
    assert_eq!(mask, Mask::from_fn(w, h, in_shadow));
    // With a single image, the closing estimate finds the same region when its window exceeds the
    // largest shadow.
    let estimated = fbem::feature_mask_from_reference(&wall(true), 30, 0.1, None).unwrap();
    assert_eq!(estimated, mask);
}

#[test]
fn fbem_ignores_averaged_shadows_smaller_than_the_feature_size() {
    let reference = wall(true);
    let features = fbem::shadow_mask(&reference, &wall(false), 0.1).unwrap();
    let approx = averaged(&reference, 0);
    let rmse = image_metrics::compare(&approx, &reference, None)
        .unwrap()
        .luminance
        .rmse;
    // s ≤ 1: no filtering and no opening, the FBEM is the L² (RMS) error (§2.3).
    for s in [0, 1] {
        let e = fbem_value(&approx, &reference, &features, s);
        assert!((e - rmse).abs() < 1e-12 * rmse, "s={s}: {e} vs {rmse}");
    }
    // Below the 3-pixel shadows they are features and their loss counts (one opening rounds the squares'
    // corners off the mask, where only the box averages are compared).
    let below = fbem_value(&approx, &reference, &features, 2);
    assert!(below > 0.7 * rmse, "FBEM(2) = {below}, RMSE = {rmse}");
    // Above them the mask loses them and their average is right: what is left comes from windows that
    // cut averaged cells at the edge of the group (the paper's residual "due to the mesh size", §2.3).
    let above = fbem_value(&approx, &reference, &features, 12);
    assert!(above < 0.1 * below, "FBEM(12) = {above}, FBEM(2) = {below}");
}

#[test]
fn table_1_behaviour() {
    let reference = wall(true);
    let features = fbem::shadow_mask(&reference, &wall(false), 0.1).unwrap();
    let sizes = [1usize, 4, 8, 16, 30, 48];
    let table: Vec<Vec<f64>> = (0..GROUPS)
        .map(|g| {
            let approx = averaged(&reference, g);
            sizes
                .iter()
                .map(|&s| fbem_value(&approx, &reference, &features, s))
                .collect()
        })
        .collect();
    for (i, s) in sizes.iter().enumerate() {
        let row: Vec<String> = table.iter().map(|c| format!("{:8.5}", c[i])).collect();
        println!("s = {s:3}: {}", row.join(" "));
    }
    // Equal shadowed fractions give nearly equal L² errors (§2.1, Appendix A).
    let l2: Vec<f64> = table.iter().map(|c| c[0]).collect();
    let lo = l2.iter().copied().fold(f64::MAX, f64::min);
    let hi = l2.iter().copied().fold(0.0, f64::max);
    assert!(hi < 1.02 * lo, "L2 errors {l2:?}");
    // Beyond s = 1 each row grows with the size of the averaged shadows, as in Table 1.
    for (i, s) in sizes.iter().enumerate().skip(1) {
        for g in 1..GROUPS {
            assert!(table[g][i] > table[g - 1][i], "s={s}: row not increasing");
        }
    }
    // The FBEM of a group falls once s exceeds its shadows, and the larger the shadows, the later.
    for (g, &side) in SIDES.iter().enumerate() {
        for (i, &s) in sizes.iter().enumerate() {
            let ratio = table[g][i] / table[g][0];
            if s > 2 * side {
                assert!(ratio < 0.25, "group {g} (side {side}) s={s}: ratio {ratio}");
            } else if 2 * s <= side {
                assert!(ratio > 0.9, "group {g} (side {side}) s={s}: ratio {ratio}");
            }
        }
    }
}

#[test]
fn compare_command_reports_the_fbem() {
    let dir = std::env::temp_dir().join(format!("radiosity-compare-fbem-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let reference = wall(true);
    let approx = averaged(&reference, 1);
    let paths = ["a.exr", "b.exr", "u.exr"].map(|n| dir.join(n));
    approx.write_exr(&paths[0]).unwrap();
    reference.write_exr(&paths[1]).unwrap();
    wall(false).write_exr(&paths[2]).unwrap();
    let [a, b, u] = paths.each_ref().map(|p| p.to_str().unwrap());
    let diff = dir.join("diff.png");
    let mask = dir.join("mask.png");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_radiosity"))
        .args([
            "compare",
            a,
            b,
            "--unoccluded",
            u,
            "--json",
            "--fbem",
            "4",
            "16",
        ])
        .args([
            "--diff",
            diff.to_str().unwrap(),
            "--mask-out",
            mask.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(json["fbem_mask"], "shadow");
    // The EXR files hold f32: compare with the library on the same rounded images.
    let (approx, reference) = (
        Image::read_linear(&paths[0]).unwrap(),
        Image::read_linear(&paths[1]).unwrap(),
    );
    let features =
        fbem::shadow_mask(&reference, &Image::read_linear(&paths[2]).unwrap(), 0.1).unwrap();
    for (entry, s) in json["fbem"].as_array().unwrap().iter().zip([4, 16]) {
        assert_eq!(entry["size"].as_u64().unwrap(), s as u64);
        let expected = fbem_value(&approx, &reference, &features, s);
        assert!((entry["value"].as_f64().unwrap() - expected).abs() < 1e-12);
    }
    // The written feature mask of s = 16 keeps the 24-pixel shadows and drops the 6-pixel ones.
    let m16 = Mask::read_png(&dir.join("mask-s16.png")).unwrap();
    assert_eq!(m16, fbem::feature_mask(&features, 16));
    assert!(m16.get(3 * TILE + MARGIN + 12, MARGIN + 12));
    assert!(!m16.get(TILE + MARGIN + 3, MARGIN + 3));
    assert!(diff.exists());
    std::fs::remove_dir_all(&dir).unwrap();
}
