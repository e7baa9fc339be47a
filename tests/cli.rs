//! The command line as a user meets it: one-line errors with file and line, non-zero exit status, and
//! the outputs it promises.

use std::path::PathBuf;
use std::process::Command;

fn radiosity(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_radiosity"))
        .args(args)
        .output()
        .expect("run radiosity")
}

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("radiosity-cli-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

#[test]
fn a_bad_scene_file_fails_with_one_line_naming_file_and_line() {
    let dir = temp_dir("bad");
    let path = dir.join("bad.mgf");
    std::fs::write(&path, "v v1 =\n\tp 0 0 0\nf v1 v2 v3\n").unwrap();
    let out = radiosity(&[
        "render",
        "-q",
        path.to_str().unwrap(),
        "-o",
        dir.join("x.png").to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    let lines: Vec<_> = stderr.lines().collect();
    assert_eq!(lines.len(), 1, "{stderr}");
    assert!(lines[0].starts_with("error: "), "{stderr}");
    assert!(lines[0].contains("bad.mgf:3"), "{stderr}");
    assert!(!dir.join("x.png").exists());
}

#[test]
fn missing_files_and_bad_options_are_errors_not_panics() {
    let out = radiosity(&["info", "/nonexistent/scene.mgf"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("/nonexistent/scene.mgf"));
    let out = radiosity(&["render", "-q", "--eye", "1,2", "-o", "/tmp/never.png"]);
    assert!(!out.status.success());
    let out = radiosity(&["render", "-q", "--threads", "0", "-o", "/tmp/never.png"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--threads"));
}

#[test]
fn render_writes_png_exr_models_and_stats() {
    let dir = temp_dir("render");
    let file = |name: &str| dir.join(name).to_str().unwrap().to_string();
    let out = radiosity(&[
        "render",
        "-q",
        "--width",
        "48",
        "--height",
        "40",
        "--eps",
        "2e-3",
        "--mesh",
        "-o",
        &file("c.png"),
        "--hdr",
        &file("c.exr"),
        "--export",
        &file("c.ply"),
        "--export",
        &file("c.glb"),
        "--stats",
        &file("s.json"),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let png = image::open(file("c.png")).expect("png").to_rgb8();
    assert_eq!(png.dimensions(), (48, 40));
    let exr = radiosity::output::image::Image::read_exr(&dir.join("c.exr")).expect("exr");
    assert_eq!((exr.width, exr.height), (48, 40));
    assert!(exr.pixels.iter().any(|p| p.luminance() > 0.0));
    assert!(std::fs::read(file("c.ply")).unwrap().starts_with(b"ply"));
    assert!(std::fs::read(file("c.glb")).unwrap().starts_with(b"glTF"));
    let stats: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(file("s.json")).unwrap()).unwrap();
    for key in [
        "elements",
        "leaf_elements",
        "links",
        "rays",
        "iterations",
        "emitted_power",
        "absorbed_power",
    ] {
        assert!(stats.get(key).is_some(), "stats lack {key}");
    }
    for phase in ["load", "bvh", "refine", "solve", "render"] {
        assert!(
            stats["seconds"][phase].is_number(),
            "stats lack seconds.{phase}"
        );
    }
    assert!(stats["leaf_elements"].as_u64().unwrap() > 17);
}

#[test]
fn info_prints_counts_of_a_renderpark_scene() {
    let scene =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/scenes/renderpark/cube.mgf");
    let out = radiosity(&["info", scene.to_str().unwrap()]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("66"), "{stdout}");
}

#[test]
fn every_subcommand_has_help() {
    for sub in ["render", "info", "bench", "compare"] {
        let out = radiosity(&[sub, "--help"]);
        assert!(out.status.success(), "{sub} --help");
        assert!(
            String::from_utf8_lossy(&out.stdout).contains("Usage"),
            "{sub}"
        );
    }
}
