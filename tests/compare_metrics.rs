//! Image error metrics against hand-computed values, the false-colour error image, and the `compare`
//! command end to end.

use radiosity::color::Rgb;
use radiosity::measures::image_metrics::{compare, luminance_error_map};
use radiosity::output::false_colour;
use radiosity::output::image::Image;
use std::path::PathBuf;
use std::process::Command;

/// Values that are multiples of 1/64, so that sums and differences below are exact in f64.
fn test_image(w: usize, h: usize) -> Image {
    let mut img = Image::new(w, h);
    for y in 0..h {
        for x in 0..w {
            let v = ((3 * x + 5 * y) % 17) as f64 / 64.0;
            img.set(x, y, Rgb::new(v, 0.5 + v, 1.0 - v));
        }
    }
    img
}

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("radiosity-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

#[test]
fn an_image_compared_with_itself_has_no_error() {
    let img = test_image(7, 5);
    let e = compare(&img, &img, None).unwrap();
    assert_eq!((e.compared, e.ignored), (35, 0));
    for c in [e.r, e.g, e.b, e.luminance] {
        assert_eq!((c.rmse, c.mae, c.max), (0.0, 0.0, 0.0));
        assert_eq!(c.relative_rmse, Some(0.0));
    }
}

#[test]
fn a_constant_offset_on_one_channel() {
    let b = test_image(8, 6);
    let mut a = b.clone();
    for p in &mut a.pixels {
        p.g += 0.125;
    }
    let e = compare(&a, &b, None).unwrap();
    assert_eq!((e.g.rmse, e.g.mae, e.g.max), (0.125, 0.125, 0.125));
    assert_eq!((e.r.rmse, e.r.mae, e.r.max), (0.0, 0.0, 0.0));
    assert_eq!((e.b.rmse, e.b.mae, e.b.max), (0.0, 0.0, 0.0));
    let mean_g = b.pixels.iter().map(|p| p.g).sum::<f64>() / 48.0;
    assert!((e.g.relative_rmse.unwrap() - 0.125 / mean_g).abs() < 1e-15);
    // Luminance error is the green weight times the offset everywhere.
    let dl = 0.7152 * 0.125;
    assert!((e.luminance.rmse - dl).abs() < 1e-15);
    assert!((e.luminance.max - dl).abs() < 1e-15);
}

#[test]
fn one_changed_pixel() {
    let b = test_image(10, 10);
    let mut a = b.clone();
    a.set(3, 7, b.get(3, 7) + Rgb::new(0.5, 0.0, -0.25));
    let e = compare(&a, &b, None).unwrap();
    // RMSE = sqrt(0.5² / 100) = 0.05, MAE = 0.5 / 100.
    assert_eq!(
        (e.r.rmse, e.r.mae, e.r.max, e.r.max_at),
        (0.05, 0.005, 0.5, [3, 7])
    );
    assert_eq!((e.b.rmse, e.b.mae, e.b.max), (0.025, 0.0025, 0.25));
    assert_eq!(e.g.max, 0.0);
}

#[test]
fn masked_pixels_are_ignored() {
    let b = test_image(4, 4);
    let mut a = b.clone();
    a.set(0, 0, Rgb::splat(100.0));
    a.set(1, 0, b.get(1, 0) + Rgb::splat(0.25));
    let mut mask = vec![false; 16];
    mask[0] = true;
    let e = compare(&a, &b, Some(&mask)).unwrap();
    assert_eq!((e.compared, e.ignored), (15, 1));
    assert_eq!(e.r.max, 0.25);
    assert_eq!(e.r.mae, 0.25 / 15.0);
    // Without the mask the outlier dominates.
    assert!(compare(&a, &b, None).unwrap().r.max > 90.0);
    // Wrong mask length and an all-masked image are errors, not panics.
    assert!(compare(&a, &b, Some(&[false; 15])).is_err());
    assert!(compare(&a, &b, Some(&[true; 16])).is_err());
}

#[test]
fn different_sizes_are_a_clear_error() {
    let err = compare(&test_image(4, 3), &test_image(3, 4), None).unwrap_err();
    let text = format!("{err:#}");
    assert!(text.contains("4×3") && text.contains("3×4"), "{text}");
}

#[test]
fn false_colour_image_has_a_colour_bar_and_the_ramp_ends() {
    let (w, h) = (64, 48);
    let b = test_image(w, h);
    let mut a = b.clone();
    // Errors grow along x over four decades; pixel (0, 0) smallest, (w − 1, 0) largest.
    for y in 0..h {
        for x in 0..w {
            let e = 1e-4 * 10f64.powf(4.0 * x as f64 / (w - 1) as f64);
            a.set(x, y, b.get(x, y) + Rgb::splat(e));
        }
    }
    let map = luminance_error_map(&a, &b, None, false).unwrap();
    let path = temp_dir("false-colour").join("diff.png");
    let scale = false_colour::write_png(&path, &map, w, h).unwrap();
    assert!((scale.min / 1e-4 - 1.0).abs() < 1e-6 && (scale.max - 1.0).abs() < 1e-6);
    let png = image::open(&path).unwrap().to_rgb8();
    // Same height; the bar and its labels are added on the right.
    assert_eq!(png.height() as usize, h);
    assert!(png.width() as usize > w + 40, "no room for the colour bar");
    let small = png.get_pixel(0, 0).0;
    let large = png.get_pixel(w as u32 - 1, 0).0;
    assert!(
        small[2] > 100 && small[0] < 30 && small[1] < 30,
        "{small:?}"
    );
    assert!(
        large[0] > 100 && large[1] < 30 && large[2] < 30,
        "{large:?}"
    );
    // The bar holds the whole ramp: red at the top, blue at the bottom, in one column right of the
    // image.
    let column: Vec<[u8; 3]> = (0..png.height())
        .map(|y| png.get_pixel(w as u32 + 10, y).0)
        .collect();
    assert!(column.iter().any(|p| p[0] > 100 && p[1] < 30 && p[2] < 30));
    assert!(column.iter().any(|p| p[2] > 100 && p[0] < 30 && p[1] < 30));
    let first_red = column.iter().position(|p| p[0] > 100 && p[2] < 30).unwrap();
    let first_blue = column.iter().position(|p| p[2] > 100 && p[0] < 30).unwrap();
    assert!(first_red < first_blue);
    // White label pixels exist right of the bar.
    let labels = (w as u32 + 20..png.width())
        .flat_map(|x| (0..png.height()).map(move |y| (x, y)))
        .filter(|&(x, y)| png.get_pixel(x, y).0 == [255, 255, 255])
        .count();
    assert!(labels > 20);
    std::fs::remove_dir_all(path.parent().unwrap()).unwrap();
}

fn run(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_radiosity"))
        .args(args)
        .output()
        .unwrap()
}

#[test]
fn compare_command_prints_json_and_writes_images() {
    let dir = temp_dir("compare-cli");
    let b = test_image(20, 12);
    let mut a = b.clone();
    a.set(5, 5, b.get(5, 5) + Rgb::new(0.5, 0.0, 0.0));
    let (pa, pb) = (dir.join("a.exr"), dir.join("b.exr"));
    a.write_exr(&pa).unwrap();
    b.write_exr(&pb).unwrap();
    let diff = dir.join("diff.png");
    let mask_out = dir.join("mask.png");
    let out = run(&[
        "compare",
        pa.to_str().unwrap(),
        pb.to_str().unwrap(),
        "--json",
        "--diff",
        diff.to_str().unwrap(),
        "--fbem",
        "2",
        "4",
        "--mask-out",
        mask_out.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let r = &json["errors"]["r"];
    assert_eq!(r["max"].as_f64().unwrap(), 0.5);
    assert_eq!(r["max_at"], serde_json::json!([5, 5]));
    assert!((r["rmse"].as_f64().unwrap() - 0.5 / 240f64.sqrt()).abs() < 1e-12);
    assert_eq!(json["fbem"].as_array().unwrap().len(), 2);
    assert!(diff.exists());
    assert!(dir.join("mask-s2.png").exists() && dir.join("mask-s4.png").exists());

    // An ignore mask covering the changed pixel removes the error.
    let mut ignore = image::GrayImage::new(20, 12);
    ignore.put_pixel(5, 5, image::Luma([255]));
    let ignore_path = dir.join("ignore.png");
    ignore.save(&ignore_path).unwrap();
    let out = run(&[
        "compare",
        pa.to_str().unwrap(),
        pb.to_str().unwrap(),
        "--json",
        "--mask",
        ignore_path.to_str().unwrap(),
    ]);
    assert!(out.status.success());
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(json["errors"]["r"]["max"].as_f64().unwrap(), 0.0);
    assert_eq!(json["errors"]["ignored"].as_u64().unwrap(), 1);

    // Different sizes: exit status 1 and a one-line error naming both sizes.
    let pc = dir.join("c.exr");
    test_image(10, 12).write_exr(&pc).unwrap();
    let out = run(&["compare", pc.to_str().unwrap(), pb.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.starts_with("error:") && stderr.contains("10×12") && stderr.contains("20×12"));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn compare_command_ignores_black_reference_pixels() {
    let dir = temp_dir("compare-black");
    let mut b = test_image(6, 6);
    b.set(0, 0, Rgb::BLACK);
    let mut a = b.clone();
    a.set(0, 0, Rgb::splat(1.0));
    let (pa, pb) = (dir.join("a.exr"), dir.join("b.exr"));
    a.write_exr(&pa).unwrap();
    b.write_exr(&pb).unwrap();
    let args = [pa.to_str().unwrap(), pb.to_str().unwrap(), "--json"];
    let plain = run(&[&["compare"], &args[..]].concat());
    let json: serde_json::Value = serde_json::from_slice(&plain.stdout).unwrap();
    assert_eq!(json["errors"]["g"]["max"].as_f64().unwrap(), 1.0);
    let ignoring = run(&[&["compare", "--ignore-black-reference"], &args[..]].concat());
    let json: serde_json::Value = serde_json::from_slice(&ignoring.stdout).unwrap();
    assert_eq!(json["errors"]["g"]["max"].as_f64().unwrap(), 0.0);
    std::fs::remove_dir_all(&dir).unwrap();
}
