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

/// Runs the binary with `args`, asserts that it succeeded (showing its standard error if not) and
/// returns its standard output.
fn succeeds(args: &[&str]) -> String {
    let out = radiosity(args);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Renders `scene` to an 8 × 8 `png` with the default settings, asserts that it succeeded and returns
/// its standard error (warnings and the summary line).
fn render_8x8(scene: &std::path::Path, png: &std::path::Path) -> String {
    let out = radiosity(&[
        "render",
        scene.to_str().unwrap(),
        "-o",
        png.to_str().unwrap(),
        "--width",
        "8",
        "--height",
        "8",
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "{stderr}");
    stderr
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
    let small = [
        "render", "-q", "--width", "48", "--height", "40", "--eps", "2e-3", "--mesh",
    ];
    let out = radiosity(
        &[
            &small[..],
            &[
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
            ],
        ]
        .concat(),
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let png = image::open(file("c.png")).expect("png").to_rgb8();
    assert_eq!(png.dimensions(), (48, 40));
    let exr = radiosity::output::image::Image::read_linear(&dir.join("c.exr")).expect("exr");
    assert_eq!((exr.width, exr.height), (48, 40));
    assert!(exr.pixels.iter().any(|p| p.luminance() > 0.0));
    // The same render as Radiance HDR: the same pixels within RGBE's half step (2^-8 of a pixel's
    // brightest channel).
    let out = radiosity(&[&small[..], &["-o", &file("d.png"), "--hdr", &file("d.hdr")]].concat());
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(std::fs::read(file("d.hdr"))
        .unwrap()
        .starts_with(b"#?RADIANCE"));
    let hdr = radiosity::output::image::Image::read_linear(&dir.join("d.hdr")).expect("hdr");
    for (a, b) in exr.pixels.iter().zip(&hdr.pixels) {
        let half_step = a.max_channel() / 256.0;
        assert!(
            (a.r - b.r)
                .abs()
                .max((a.g - b.g).abs())
                .max((a.b - b.b).abs())
                <= half_step
        );
    }
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
    for phase in ["load", "bvh", "refine", "solve", "estimate", "render"] {
        assert!(
            stats["seconds"][phase].is_number(),
            "stats lack seconds.{phase}"
        );
    }
    assert!(stats["leaf_elements"].as_u64().unwrap() > 17);
}

#[test]
fn every_shading_renders() {
    let dir = temp_dir("shadings");
    for shading in ["seamless", "basis", "continuous", "flat", "smooth"] {
        let png = dir.join(format!("{shading}.png"));
        let png = png.to_str().unwrap();
        succeeds(&[
            "render",
            "-q",
            "--width",
            "32",
            "--height",
            "24",
            "--eps",
            "2e-3",
            "--shading",
            shading,
            "-o",
            png,
        ]);
        let image = image::open(png).expect("png").to_rgb8();
        assert!(image.pixels().any(|p| p.0 != [0, 0, 0]), "{shading}");
    }
}

#[test]
fn info_prints_counts_of_a_renderpark_scene() {
    let scene =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/scenes/renderpark/cube.mgf");
    let stdout = succeeds(&["info", scene.to_str().unwrap(), "--split-contacts", "off"]);
    assert!(stdout.contains("polygons:      66 "), "{stdout}");
    assert!(stdout.contains("not split"), "{stdout}");
    // By default (auto) only the ceiling is cut, along the outline of the two-sided lamp under it.
    let out = radiosity(&["info", scene.to_str().unwrap()]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("2 polygons split"), "{stdout}");
    // With the split on, the ceiling and the lamp 1 cm under it are cut along each other's outlines.
    let out = radiosity(&["info", scene.to_str().unwrap(), "--split-contacts", "on"]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    // 78 pieces, of which the 7 trapezoids are cut into two triangles each (scene::contacts).
    assert!(stdout.contains("polygons:      85 "), "{stdout}");
    assert!(stdout.contains("4 polygons split"), "{stdout}");
    let out = radiosity(&["info", scene.to_str().unwrap(), "--contact-gap", "2"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("contact gap"));
}

/// `info --near X,Y,Z` names the polygon `probe` finds at a point first (on cube.mgf, split along its
/// lamp's contact as both commands split it), and refuses a negative distance before loading.
#[test]
fn info_near_lists_the_polygon_probe_finds_at_a_point() {
    let scene =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/scenes/renderpark/cube.mgf");
    let scene = scene.to_str().unwrap();
    let probed = succeeds(&[
        "probe", scene, "--random", "4", "--seed", "5", "--eps", "1e-3",
    ]);
    let mut checked = 0;
    for line in probed.lines().filter(|l| !l.starts_with('#')) {
        let f: Vec<&str> = line.split_whitespace().collect();
        // A polygon's back side reads `Nb`.
        let Some(polygon) = f
            .get(4)
            .and_then(|p| p.trim_end_matches('b').parse::<usize>().ok())
        else {
            continue;
        };
        let point = format!("{},{},{}", f[1], f[2], f[3]);
        let listed = succeeds(&["info", scene, "--near", &point]);
        let first = listed
            .lines()
            .find(|l| l.starts_with("polygon "))
            .unwrap_or_else(|| panic!("no polygon at {point}: {listed}"));
        assert_eq!(
            first.split_whitespace().nth(1),
            Some(polygon.to_string().as_str()),
            "{point}: {listed}"
        );
        checked += 1;
    }
    assert_eq!(checked, 4, "{probed}");
    let out = radiosity(&["info", scene, "--near", "1,1,1", "--within=-1"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--within"));
}

/// Every subcommand the top-level help lists has its own help, written for users: no rustdoc link
/// syntax (a doc comment's first paragraph is what clap shows).
#[test]
fn every_subcommand_has_help() {
    let top = radiosity(&["--help"]);
    let top = String::from_utf8_lossy(&top.stdout).into_owned();
    let commands: Vec<&str> = top
        .lines()
        .skip_while(|l| !l.starts_with("Commands:"))
        .skip(1)
        .take_while(|l| l.starts_with("  "))
        .filter_map(|l| l.split_whitespace().next())
        .filter(|&c| c != "help")
        .collect();
    assert!(commands.len() >= 10, "{top}");
    for sub in commands {
        let out = radiosity(&[sub, "--help"]);
        assert!(out.status.success(), "{sub} --help");
        let help = String::from_utf8_lossy(&out.stdout);
        assert!(help.contains("Usage"), "{sub}");
        assert!(
            !help.contains("[`"),
            "{sub} --help shows a rustdoc link: {help}"
        );
    }
}

fn renderpark(name: &str) -> String {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/scenes/renderpark")
        .join(name)
        .to_str()
        .unwrap()
        .to_string()
}

/// Runs radiosity with its standard output a pipe whose reader has already gone.
fn into_closed_pipe(args: &[&str]) -> std::process::Output {
    use std::process::Stdio;
    let mut child = Command::new(env!("CARGO_BIN_EXE_radiosity"))
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run radiosity");
    drop(child.stdout.take());
    child.wait_with_output().expect("wait for radiosity")
}

#[test]
fn a_closed_standard_output_ends_quietly() {
    let dir = temp_dir("pipe");
    let exr = dir.join("a.exr");
    radiosity::output::image::Image::new(4, 4)
        .write_exr(&exr)
        .unwrap();
    let exr = exr.to_str().unwrap();
    let corridor = renderpark("corridor.mgf");
    for args in [
        vec!["info", corridor.as_str(), "--materials"],
        vec!["compare", exr, exr, "--json"],
        vec!["compare", exr, exr],
    ] {
        let out = into_closed_pipe(&args);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!stderr.contains("panicked"), "{args:?}: {stderr}");
        assert!(out.status.success(), "{args:?}: {stderr}");
    }
}

#[test]
fn outputs_never_overwrite_the_scene_and_failed_writes_fail() {
    let dir = temp_dir("outputs");
    let scene = dir.join("scene.mgf");
    let out = radiosity(&["scene", "cornell", "-o", scene.to_str().unwrap()]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let before = std::fs::read(&scene).unwrap();
    let s = scene.to_str().unwrap();
    let exr = dir.join("image.exr");
    let fast = ["--width", "8", "--height", "8", "--eps", "0.05", "-q"];
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (vec!["-o", s], "scene file"),
        (vec!["--hdr", s], "scene file"),
        (vec!["--stats", s], "scene file"),
        (vec!["-o", "/nonexistent-dir/x.png"], "does not exist"),
        (vec!["-o", dir.to_str().unwrap()], "directory"),
        (vec!["-o", exr.to_str().unwrap()], "PNG"),
    ];
    for (extra, reason) in cases {
        let mut args = vec!["render", s];
        args.extend(&fast);
        args.extend(&extra);
        let out = radiosity(&args);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{extra:?}");
        assert!(
            stderr.lines().count() == 1 && stderr.contains(reason),
            "{extra:?}: {stderr}"
        );
    }
    assert_eq!(
        std::fs::read(&scene).unwrap(),
        before,
        "the scene is untouched"
    );
    // A full disk: an error, with no partial file claimed (and the device left alone).
    let is_device = |p: &str| {
        use std::os::unix::fs::FileTypeExt;
        std::fs::metadata(p).is_ok_and(|m| m.file_type().is_char_device())
    };
    if !is_device("/dev/full") {
        return;
    }
    let png = dir.join("ok.png");
    let mut args = vec!["render", s];
    args.extend(&fast);
    args.extend(["-o", png.to_str().unwrap(), "--hdr", "/dev/full"]);
    let out = radiosity(&args);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    assert!(
        stderr.contains("/dev/full") && !stderr.contains("panicked"),
        "{stderr}"
    );
    let mut args = vec!["render", s];
    args.extend(&fast);
    args.extend(["-o", "/dev/full"]);
    assert!(!radiosity(&args).status.success());
    assert!(is_device("/dev/full"), "/dev/full must never be replaced");
    let leftovers: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().contains("partial"))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
}

#[test]
fn resource_options_are_bounded() {
    for args in [
        vec!["render", "-q", "--width", "16384", "--height", "16384"],
        vec!["render", "-q", "--spp", "1000000000"],
        vec![
            "render", "-q", "--width", "4096", "--height", "4096", "--spp", "60000",
        ],
        vec!["render", "-q", "--tessellation", "1000000000"],
        vec!["render", "-q", "--rays", "1000000000000"],
        vec!["render", "-q", "--vis-rays", "100000000"],
        vec!["reference", "-q", "--spp", "1000000000"],
        vec!["render", "-q", "--threads", "100000000"],
        vec!["render", "-q", "--width", "0"],
    ] {
        let start = std::time::Instant::now();
        let mut args = args.clone();
        args.extend(["-o", "/tmp/radiosity-never.png"]);
        let out = radiosity(&args);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{args:?}");
        assert!(
            !stderr.contains("panicked") && stderr.contains("error"),
            "{args:?}: {stderr}"
        );
        assert!(
            start.elapsed().as_secs() < 20,
            "{args:?} took {:?}",
            start.elapsed()
        );
    }
}

#[test]
fn a_scene_without_light_warns_and_a_written_scene_renders_as_it_was() {
    let dir = temp_dir("light");
    let dark = dir.join("dark.mgf");
    std::fs::write(
        &dark,
        "m grey =\n c\n rd 0.5\nv a =\n p 0 0 0\nv b =\n p 1 0 0\nv c =\n p 1 1 0\nf a b c\n",
    )
    .unwrap();
    let stderr = render_8x8(&dark, &dir.join("dark.png"));
    assert!(stderr.contains("no surface emits light"), "{stderr}");
    // `scene cornell -o c.mgf`, then `render c.mgf`: the camera comes back, the image is lit.
    let scene = dir.join("c.mgf");
    assert!(
        radiosity(&["scene", "cornell", "-o", scene.to_str().unwrap()])
            .status
            .success()
    );
    let png = dir.join("c.png");
    let out = radiosity(&[
        "render",
        "-q",
        scene.to_str().unwrap(),
        "-o",
        png.to_str().unwrap(),
        "--width",
        "24",
        "--height",
        "24",
        "--eps",
        "0.01",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let image = image::open(&png).unwrap().to_rgb8();
    let mean = image
        .pixels()
        .map(|p| p.0.iter().map(|&c| c as f64).sum::<f64>())
        .sum::<f64>()
        / (3.0 * image.pixels().len() as f64);
    assert!(mean > 30.0, "mean pixel value {mean}");
}

#[test]
fn warnings_of_one_kind_are_counted_after_three_and_info_lists_them_all() {
    let dir = temp_dir("warnings");
    let scene = dir.join("bent.mgf");
    // Five non-planar quads (one corner lifted 5% of their size) beside an emitting triangle.
    let mut text = String::from(
        "m white =\n c\n rd 0.5\nm lamp =\n c\n ed 10\nv l1 =\n p 0 0 3\nv l2 =\n p 1 0 3\n\
         v l3 =\n p 0 1 3\nm lamp\nf l1 l3 l2\nm white\n",
    );
    for k in 0..5 {
        let x = 2 * k;
        text.push_str(&format!(
            "v a{k} =\n p {x} 0 0\nv b{k} =\n p {} 0 0\nv c{k} =\n p {} 1 0.05\nv d{k} =\n p {x} 1 0\nf a{k} b{k} c{k} d{k}\n",
            x + 1,
            x + 1
        ));
    }
    std::fs::write(&scene, text).unwrap();
    let stderr = render_8x8(&scene, &dir.join("bent.png"));
    let warnings: Vec<_> = stderr
        .lines()
        .filter(|l| l.starts_with("warning: "))
        .collect();
    assert_eq!(warnings.len(), 4, "{stderr}");
    assert!(
        warnings[..3].iter().all(|w| w.contains("non-planar")),
        "{stderr}"
    );
    assert!(
        warnings[3].contains("2 more like the one above"),
        "{stderr}"
    );
    let out = radiosity(&["info", scene.to_str().unwrap()]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(stderr.matches("non-planar").count(), 5, "{stderr}");
}

#[test]
fn error_control_reports_its_accuracy_and_draws_its_estimate() {
    let dir = temp_dir("accuracy");
    let (png, stats, errors) = (dir.join("c.png"), dir.join("c.json"), dir.join("e.png"));
    // The summary line and the stats of a render with `options`.
    let run = |options: &[&str]| {
        let mut args = vec!["render", "--width", "32", "--height", "32"];
        args.extend_from_slice(options);
        args.extend([
            "-o",
            png.to_str().unwrap(),
            "--stats",
            stats.to_str().unwrap(),
        ]);
        let out = radiosity(&args);
        let summary = String::from_utf8_lossy(&out.stderr).to_string();
        assert!(out.status.success(), "{summary}");
        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&stats).unwrap()).unwrap();
        (summary, json)
    };
    let stats_of = |options: &[&str]| run(options).1;
    // A render controlled to 30% (the power oracle's default) with `oracle` options says so.
    let controlled = |oracle: &[&str]| {
        let (summary, json) = run(&[&["--accuracy", "30%"], oracle].concat());
        assert!(summary.contains("accuracy"), "{summary}");
        assert!(json["error"]["accuracy"].as_f64().unwrap() > 0.0);
        json
    };
    // Alone, the accuracy controls the default power oracle: the same as no options at all.
    let json = controlled(&[]);
    assert_eq!(json["settings"]["oracle"], "power");
    assert!(json["residuals"].as_array().is_some_and(|r| !r.is_empty()));
    let default = stats_of(&[]);
    assert_eq!(default["settings"]["oracle"], "power");
    assert_eq!(default["error"]["accuracy"], json["error"]["accuracy"]);
    assert_eq!(default["leaf_elements"], json["leaf_elements"]);
    // The paper's own link error oracle.
    let json = controlled(&["--oracle", "error"]);
    assert_eq!(json["settings"]["oracle"], "error");
    // A render with `options` is refused with a message containing `reason`.
    let refused = |options: &[&str], reason: &str| {
        let out = radiosity(&[&["render", "-q"], options, &["-o", png.to_str().unwrap()]].concat());
        assert!(!out.status.success(), "{options:?}");
        assert!(
            String::from_utf8_lossy(&out.stderr).contains(reason),
            "{options:?}"
        );
    };
    // The link error oracle has no thresholds without control: off is refused, not ignored.
    refused(
        &["--oracle", "error", "--accuracy", "off"],
        "--oracle error refines only under",
    );
    // Off, and off by default for the oracles of the Feixas et al. experiments.
    for options in [&["--accuracy", "off"][..], &["--oracle", "mi"]] {
        let json = stats_of(options);
        assert!(json["error"]["accuracy"].is_null(), "{options:?}: {json}");
    }
    // A local accuracy is reported in the summary line and the stats, and it refines at least as far.
    let (summary, json) = run(&["--local-accuracy", "20%"]);
    assert!(
        summary.contains("20% of each element's own radiance"),
        "{summary}"
    );
    assert_eq!(json["error"]["local_accuracy"].as_f64(), Some(0.2));
    assert!(json["leaf_elements"].as_u64() >= default["leaf_elements"].as_u64());
    // It needs error control, and a percentage.
    refused(
        &["--accuracy", "off", "--local-accuracy", "20%"],
        "--local-accuracy refines under error control",
    );
    refused(&["--local-accuracy", "0.2"], "not a percentage");
    refused(&["--local-accuracy", "0%"], "above 0");
    // Outline levels are in the stats and refine at least as far; they need the power oracle's
    // visibility term and the outline rule, and a bounded number of levels.
    // One level by default where the rule applies, none where it does not (not refused).
    assert_eq!(default["settings"]["outline_levels"].as_f64(), Some(1.0));
    let json = stats_of(&["--outlines", "ignore"]);
    assert_eq!(json["settings"]["outline_levels"].as_f64(), Some(0.0));
    let json = stats_of(&["--outline-levels", "2"]);
    assert_eq!(json["settings"]["outline_levels"].as_f64(), Some(2.0));
    assert!(json["leaf_elements"].as_u64() >= default["leaf_elements"].as_u64());
    for options in [
        &["--outlines", "ignore"][..],
        &["--shadow-levels", "0"],
        &["--oracle", "error"],
    ] {
        refused(
            &[options, &["--outline-levels", "1"]].concat(),
            "--outline-levels deepens",
        );
    }
    refused(&["--outline-levels", "9"], "between 0 and 8");
    // Monte Carlo radiosity has no error control: refused, not ignored.
    refused(
        &[
            "--method",
            "stochastic-jacobi",
            "--basis",
            "constant",
            "--accuracy",
            "10%",
        ],
        "deterministic",
    );
    let out = radiosity(&[
        "render",
        "-q",
        "--basis",
        "quadratic",
        "--show",
        "error-estimate",
        "--width",
        "32",
        "--height",
        "32",
        "-o",
        errors.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(errors.exists());
    let out = radiosity(&[
        "render",
        "-q",
        "--accuracy=-3%",
        "-o",
        png.to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("accuracy"));
}

#[test]
fn multires_visibility_needs_a_feature_size_and_solves_with_one() {
    // The names a rule can match: `info --objects` lists the built-in box's.
    let objects = succeeds(&["info", "--objects"]);
    assert!(
        objects.contains("object floor") && objects.contains("object short_block"),
        "{objects}"
    );
    // Extinction everywhere but where `rule` says.
    let multires_for = |rule: &'static str| {
        vec![
            "--visibility",
            "multires",
            "--feature-size",
            "inf",
            "--feature-size-for",
            rule,
        ]
    };
    for (args, says) in [
        (vec!["--visibility", "multires"], "--feature-size"),
        (
            vec!["--visibility", "multires", "--feature-size=-1"],
            "--feature-size",
        ),
        (vec!["--feature-size", "0.1"], "--visibility multires"),
        (
            vec!["--multires-averaging", "cluster"],
            "--visibility multires",
        ),
        (
            vec!["--feature-size-for", "floor=0"],
            "--visibility multires",
        ),
        (multires_for("floor"), "NAME=S"),
        (multires_for("floor=-2"), ">= 0"),
        (multires_for("flor=0"), "'flor'"),
    ] {
        let mut args = [vec!["render", "-q"], args].concat();
        args.extend(["-o", "/tmp/radiosity-never.png"]);
        let out = radiosity(&args);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{args:?}");
        assert!(
            stderr.contains(says) && !stderr.contains("panicked"),
            "{args:?}: {stderr}"
        );
    }
    let dir = temp_dir("multires");
    let png = dir.join("box.png");
    let small_render = |options: &[&str]| {
        let mut args = vec!["render", "-q", "--visibility", "multires"];
        args.extend(options);
        args.extend([
            "--width",
            "32",
            "--height",
            "32",
            "-o",
            png.to_str().unwrap(),
        ]);
        succeeds(&args);
        assert!(png.exists());
    };
    small_render(&["--feature-size", "0.05", "--multires-averaging", "cluster"]);
    // Exact shadows on the floor and the blocks, extinction elsewhere.
    small_render(&[
        "--feature-size",
        "inf",
        "--feature-size-for",
        "floor=0",
        "--feature-size-for",
        "*_block=0.01",
    ]);
}

/// `probe --final-gather` evaluates the points by a gather of the solution (other values than the
/// leaves', at the same points) and says so with the rays it cast; a bad gather setting is refused
/// by name before any solve; with `--cached`, the values a cached render shows, said as such.
#[test]
fn probe_final_gather_says_what_it_did_and_refuses_bad_settings() {
    let common = ["probe", "-q", "--random", "10", "--eps", "1e-3"];
    let rows = |out: &std::process::Output| -> Vec<String> {
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stdout)
            .lines()
            .filter(|l| !l.starts_with('#'))
            .map(str::to_owned)
            .collect()
    };
    let plain = radiosity(&common);
    let gathered = radiosity(&[&common[..], &["--final-gather"]].concat());
    let (plain_rows, gathered_rows) = (rows(&plain), rows(&gathered));
    assert_eq!(plain_rows.len(), gathered_rows.len());
    assert!(plain_rows.iter().zip(&gathered_rows).any(|(a, b)| a != b));
    let stdout = String::from_utf8_lossy(&gathered.stdout);
    assert!(
        stdout.contains("# final gather: radiance = emission + ρ/π") && stdout.contains(" rays, "),
        "{stdout}"
    );
    assert!(!String::from_utf8_lossy(&plain.stdout).contains("# final gather"));
    let bad = radiosity(&[&common[..], &["--final-gather", "--max-solid-angle", "0"]].concat());
    assert!(!bad.status.success());
    let stderr = String::from_utf8_lossy(&bad.stderr);
    assert!(stderr.contains("--max-solid-angle"), "{stderr}");
    // At points a 32² image sees, `--cached` gives the image's values: other than the leaves'.
    let seen = [
        "probe", "-q", "--seen", "10", "--eps", "1e-3", "--width", "32", "--height", "32",
    ];
    let plain = radiosity(&seen);
    let cached = radiosity(&[&seen[..], &["--final-gather", "--cached"]].concat());
    let (plain_rows, cached_rows) = (rows(&plain), rows(&cached));
    assert_eq!(plain_rows.len(), cached_rows.len());
    assert!(plain_rows.iter().zip(&cached_rows).any(|(a, b)| a != b));
    let stdout = String::from_utf8_lossy(&cached.stdout);
    assert!(
        stdout.contains("# final gather as rendered: ")
            && stdout.contains("records for a 32x32 image"),
        "{stdout}"
    );
    let orphan = radiosity(&[&seen[..], &["--cached"]].concat());
    assert!(!orphan.status.success(), "--cached needs --final-gather");
}

/// `render --final-gather` writes its image and says how many records its cache gathered at (or that
/// it gathered at every sample), and an image of more gathers than it may make is refused with the
/// budget named, before any solve: a record per pixel for the cache, every sample without it.
#[test]
fn render_final_gather_writes_small_images_and_refuses_large_ones() {
    let dir = temp_dir("final_gather");
    let png = dir.join("g.png");
    let small = |extra: &[&str]| {
        let mut args = vec![
            "render",
            "--eps",
            "1e-3",
            "--final-gather",
            "--width",
            "8",
            "--height",
            "8",
            "--spp",
            "1",
            "-o",
        ];
        args.push(png.to_str().unwrap());
        args.extend(extra);
        let out = radiosity(&args);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(png.exists());
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let cached = small(&[]);
    assert!(cached.contains(" cached records) -> "), "{cached}");
    let every = small(&["--gather-every-sample"]);
    assert!(
        every.contains("(final gather at every sample) -> "),
        "{every}"
    );
    let large = dir.join("h.png");
    let refused = |size: [&str; 2], spp: &str, extra: &[&str]| {
        let mut args = vec![
            "render",
            "-q",
            "--final-gather",
            "--width",
            size[0],
            "--height",
        ];
        args.extend([size[1], "--spp", spp, "-o", large.to_str().unwrap()]);
        args.extend(extra);
        let out = radiosity(&args);
        assert!(!out.status.success());
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let stderr = refused(["1024", "1024"], "16", &["--gather-every-sample"]);
    assert!(
        stderr.contains("--final-gather gathers at up to a record per pixel")
            && stderr.contains("1048576"),
        "{stderr}"
    );
    let stderr = refused(["2048", "1024"], "16", &[]);
    assert!(stderr.contains("2097152 samples"), "{stderr}");
    let stderr = refused(["8", "8"], "1", &["--cache-accuracy", "0"]);
    assert!(stderr.contains("--cache-accuracy"), "{stderr}");
}

/// A reference path traced once (`probe --reference --json`) is compared with later solutions at the
/// same points (`probe --against`): the same error summary (and count of points within their
/// estimated error) as a fresh reference gives, and a clear error when the points are not the same.
#[test]
fn probe_compares_with_a_stored_reference_at_the_same_points() {
    let dir = temp_dir("against");
    let common = ["probe", "-q", "--random", "30", "--eps", "1e-3"];
    let fresh = radiosity(&[&common[..], &["--reference", "--spp", "64"]].concat());
    assert!(
        fresh.status.success(),
        "{}",
        String::from_utf8_lossy(&fresh.stderr)
    );
    let stored = radiosity(&[&common[..], &["--reference", "--spp", "64", "--json"]].concat());
    assert!(stored.status.success());
    let path = dir.join("ref.json");
    std::fs::write(&path, &stored.stdout).unwrap();
    let against = radiosity(&[&common[..], &["--against", path.to_str().unwrap()]].concat());
    assert!(
        against.status.success(),
        "{}",
        String::from_utf8_lossy(&against.stderr)
    );
    let summary = |out: &std::process::Output| -> Vec<String> {
        String::from_utf8_lossy(&out.stdout)
            .lines()
            .filter(|l| {
                l.starts_with("# luminance error")
                    || l.starts_with("# |error|")
                    || l.contains("within their a-posteriori error estimate")
            })
            .map(str::to_owned)
            .collect()
    };
    assert_eq!(
        summary(&against).len(),
        3,
        "{}",
        String::from_utf8_lossy(&against.stdout)
    );
    // The same seed draws the same paths: the stored reference is the fresh one.
    assert_eq!(summary(&against), summary(&fresh));
    let other = radiosity(
        &[
            &common[..],
            &["--seed", "7", "--against", path.to_str().unwrap()],
        ]
        .concat(),
    );
    assert!(!other.status.success());
    let stderr = String::from_utf8_lossy(&other.stderr);
    assert!(stderr.contains("ref.json: point 1 is"), "{stderr}");
    // Alone, --against probes the reference's own points, whatever the seed.
    let own_points = [
        "probe",
        "-q",
        "--eps",
        "1e-3",
        "--seed",
        "7",
        "--against",
        path.to_str().unwrap(),
    ];
    let reseeded = radiosity(&own_points);
    assert!(
        reseeded.status.success(),
        "{}",
        String::from_utf8_lossy(&reseeded.stderr)
    );
    assert_eq!(summary(&reseeded).len(), 3);
    // ... and says so: another seed is not another point set.
    assert!(
        String::from_utf8_lossy(&reseeded.stdout).contains("the reference's own"),
        "{}",
        String::from_utf8_lossy(&reseeded.stdout)
    );
    assert!(!String::from_utf8_lossy(&against.stdout).contains("the reference's own"));
    let as_json = radiosity(&[&own_points[..], &["--json"]].concat());
    let points = |out: &std::process::Output| -> Vec<serde_json::Value> {
        let rows: Vec<serde_json::Value> = serde_json::from_slice(&out.stdout).expect("probe JSON");
        rows.iter().map(|row| row["point"].clone()).collect()
    };
    assert_eq!(points(&as_json), points(&stored));
    assert_eq!(points(&stored).len(), 30);
    let not_a_probe = dir.join("not_a_probe.json");
    std::fs::write(&not_a_probe, "{\"rows\": []}").unwrap();
    let refused = radiosity(&["probe", "-q", "--against", not_a_probe.to_str().unwrap()]);
    assert!(!refused.status.success());
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert!(
        stderr.contains("not_a_probe.json: not the JSON"),
        "{stderr}"
    );
}

/// `probe --seen N`: points the camera sees, the same for the same camera and seed (a stored reference
/// applies), others for another camera (refused against that reference), none for a camera looking
/// away from the scene (a clear error).
#[test]
fn probe_at_points_the_camera_sees() {
    let dir = temp_dir("seen");
    let common = ["probe", "-q", "--seen", "20", "--eps", "1e-3"];
    let stored = radiosity(&[&common[..], &["--reference", "--spp", "16", "--json"]].concat());
    assert!(
        stored.status.success(),
        "{}",
        String::from_utf8_lossy(&stored.stderr)
    );
    let path = dir.join("seen.json");
    std::fs::write(&path, &stored.stdout).unwrap();
    let again = radiosity(&[&common[..], &["--against", path.to_str().unwrap()]].concat());
    assert!(
        again.status.success(),
        "{}",
        String::from_utf8_lossy(&again.stderr)
    );
    assert!(String::from_utf8_lossy(&again.stdout).contains("# luminance error at"));
    // What was probed: the solution's accuracy (the default error control's) and size.
    let header = String::from_utf8_lossy(&again.stdout);
    assert!(
        header.contains("# solution: accuracy")
            && header.contains("of the mean radiance")
            && header.contains(" links, "),
        "{header}"
    );
    let moved = radiosity(
        &[
            &common[..],
            &["--eye", "278,273,-700", "--look-at", "278,273,0"],
            &["--against", path.to_str().unwrap()],
        ]
        .concat(),
    );
    assert!(!moved.status.success());
    let stderr = String::from_utf8_lossy(&moved.stderr);
    assert!(stderr.contains("points or camera"), "{stderr}");
    let away = radiosity(&[
        "probe",
        "-q",
        "--seen",
        "5",
        "--eye",
        "0,0,-10000",
        "--look-at",
        "0,0,-20000",
    ]);
    assert!(!away.status.success());
    let stderr = String::from_utf8_lossy(&away.stderr);
    assert!(stderr.contains("sees no surface"), "{stderr}");
}

#[test]
fn audit_lists_clusters_with_what_they_hold_and_what_they_push_down() {
    let dir = temp_dir("audit_clusters");
    let scene = dir.join("groups.mgf");
    let scene = scene.to_str().unwrap();
    succeeds(&["scene", "shadow-groups", "-o", scene]);
    let text = succeeds(&[
        "audit",
        scene,
        "--clustering",
        "oriented",
        "--polygon",
        "0",
        "--samples",
        "16",
        "--rows",
        "8",
    ]);
    let cluster_rows = text
        .lines()
        .filter(|l| l.trim_start().starts_with('c') && !l.starts_with('#'))
        .count();
    let held = text.lines().filter(|l| l.starts_with("# c")).count();
    assert!(cluster_rows > 0 && held == cluster_rows, "{text}");
    assert!(
        text.lines().any(|l| l.trim_start().starts_with("pushed")),
        "{text}"
    );
}

#[test]
fn audit_lists_the_sources_of_a_polygon_its_closure_and_rejects_an_unknown_one() {
    let text = succeeds(&["audit", "--polygon", "0", "--samples", "16", "--rows", "3"]);
    assert!(text.contains("coupled") && text.contains("total"), "{text}");
    // Header, column names, three sources and the total.
    assert_eq!(text.lines().count(), 6, "{text}");
    let text = succeeds(&[
        "audit",
        "--transport",
        "--polygon",
        "0",
        "--transport-rays",
        "64",
    ]);
    assert!(
        text.contains("gathered") && text.contains("total"),
        "{text}"
    );
    let text = succeeds(&["audit", "--closure", "--polygon", "0", "--rows", "2"]);
    // Header, column names and the two floor leaves that gather most.
    assert!(text.contains("closure of the links"), "{text}");
    assert_eq!(text.lines().count(), 4, "{text}");
    let stochastic = [
        "audit",
        "--closure",
        "--method",
        "stochastic-jacobi",
        "--basis",
        "constant",
    ];
    let out = radiosity(&stochastic);
    assert!(!out.status.success());
    let error = String::from_utf8_lossy(&out.stderr);
    assert!(error.contains("no links to audit"), "{error}");
    let out = radiosity(&["audit", "--polygon", "9999"]);
    assert!(!out.status.success());
    let error = String::from_utf8_lossy(&out.stderr);
    assert!(error.contains("--polygon 9999"), "{error}");
    let out = radiosity(&["audit", "--max-links", "10"]);
    assert!(!out.status.success());
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("--max-links"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// `bench rays --agreeing` times the back ends on the segments where their answers agree and says how
/// many it left out: none between the BVH and the brute-force reference, which are both exact.
#[test]
fn bench_rays_at_equal_answers() {
    let out = succeeds(&[
        "bench",
        "rays",
        "--rays",
        "2000",
        "--backend",
        "bvh",
        "--backend",
        "brute-force",
        "--agreeing",
    ]);
    assert!(
        out.contains("# 0 of 2000 segments answered differently by the back ends, left out"),
        "{out}"
    );
    assert!(
        out.contains("| bvh |") && out.contains("| brute-force |"),
        "{out}"
    );
}

/// floor_gloss.mgf's stand is a slab standing on the floor, its lamp high on the slab's +x side: the
/// floor along the slab's lit foot (x 4.52–4.535) is wholly lit, and elements there straddle the
/// shadow edge at the foot within the outer part that their Gauss nodes leave unsampled, so that
/// every node saw the lamp hidden: those elements read 1e-5 where the light is 0.015, until the
/// corners of such a link's receiver were made to look (`refine::corners_disagree`). Error model:
/// the default error control promises its accuracy at 95% of points (Bekaert–Willems), against a
/// reference of 4096 paths a point whose two standard errors `probe` allows; 80 points along the
/// stand's whole length.
#[test]
fn the_lit_floor_at_the_foot_of_a_standing_slab_is_lit() {
    let dir = temp_dir("foot");
    let points = dir.join("foot.txt");
    let text: String = (0..20)
        .flat_map(|i| {
            let y = 1.05 + 0.1 * i as f64;
            [4.522, 4.526, 4.530, 4.534].map(|x| format!("{x} {y} 0 0 0 1\n"))
        })
        .collect();
    std::fs::write(&points, text).unwrap();
    let probed = succeeds(&[
        "probe",
        "-q",
        &renderpark("floor_gloss.mgf"),
        "--points",
        points.to_str().unwrap(),
        "--reference",
        "--spp",
        "4096",
    ]);
    let summary = probed
        .lines()
        .find(|l| l.contains("points within the accuracy"))
        .unwrap_or_else(|| panic!("no accuracy summary: {probed}"));
    let counts: Vec<usize> = summary
        .split_whitespace()
        .filter_map(|w| w.parse().ok())
        .take(2)
        .collect();
    assert_eq!(counts.len(), 2, "{summary}");
    assert!(
        counts[0] as f64 >= 0.95 * counts[1] as f64,
        "{summary}\n{probed}"
    );
    std::fs::remove_dir_all(dir).ok();
}
