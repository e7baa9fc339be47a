//! `radiosity plot`: charts of stats JSON files, series by label, clear errors for missing fields.

use std::path::PathBuf;
use std::process::Command;

struct TempDir(PathBuf);

impl TempDir {
    fn new(name: &str) -> Self {
        let dir =
            std::env::temp_dir().join(format!("radiosity-plot-{name}-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        TempDir(dir)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn stats(oracle: &str, elements: usize, solve: f64, error: f64) -> String {
    serde_json::json!({
        "scene": "cornell",
        "elements": elements,
        "rays": 1000 * elements,
        "seconds": {"load": 0.01, "bvh": 0.02, "refine": 0.5 * solve, "solve": solve, "render": 0.1},
        "settings": {"oracle": oracle, "eps": 1e-3},
        "error": {"relative_rmse": error},
    })
    .to_string()
}

/// The contents of the SVG's text elements (plotters writes each on its own line).
fn texts(svg: &str) -> Vec<String> {
    svg.split("<text")
        .skip(1)
        .filter_map(|t| {
            let body = &t[t.find('>')? + 1..];
            Some(body[..body.find("</text>")?].trim().to_string())
        })
        .collect()
}

fn radiosity(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_radiosity"))
        .args(args)
        .output()
        .expect("run radiosity")
}

#[test]
fn plot_writes_an_svg_with_one_series_per_label() {
    let dir = TempDir::new("series");
    let files = [
        ("a.json", stats("power", 100, 0.5, 0.2)),
        ("b.json", stats("power", 400, 1.5, 0.08)),
        ("c.json", stats("mi", 250, 0.9, 0.1)),
    ];
    let mut args: Vec<String> = vec!["plot".into()];
    for (name, text) in &files {
        let path = dir.0.join(name);
        std::fs::write(&path, text).unwrap();
        args.push(path.display().to_string());
    }
    let svg = dir.0.join("chart.svg");
    let mut by_label = args.clone();
    by_label.extend(
        [
            "--x",
            "seconds.refine+seconds.solve",
            "--y",
            "error.relative_rmse",
            "--label",
            "settings.oracle",
            "--log-y",
            "-o",
        ]
        .map(String::from),
    );
    by_label.push(svg.display().to_string());
    let refs: Vec<&str> = by_label.iter().map(String::as_str).collect();
    let out = radiosity(&refs);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(String::from_utf8_lossy(&out.stdout).contains("2 series, 3 points"));
    let text = std::fs::read_to_string(&svg).unwrap();
    assert!(text.starts_with("<svg") && text.trim_end().ends_with("</svg>"));
    let labels = texts(&text);
    for needle in [
        "power",
        "mi",
        "error.relative_rmse",
        "seconds.refine+seconds.solve",
    ] {
        assert!(
            labels.iter().any(|l| l == needle),
            "missing {needle}: {labels:?}"
        );
    }
    // The power series (two runs) is a 2-pixel line, the mi series a lone marker; each legend entry
    // is a 2-pixel line with a marker.
    let thick = text
        .lines()
        .filter(|l| l.starts_with("<polyline") && l.contains("stroke-width=\"2\""))
        .count();
    assert_eq!(thick, 1 + 2, "{text}");
    assert_eq!(text.matches("<circle").count(), 3 + 2, "{text}");

    // Without --label: one series per file, named by the file.
    // A file may hold an array of runs: each is a point of that file's series.
    let sweep = dir.0.join("d.json");
    let runs = format!(
        "[{}, {}]",
        stats("power", 50, 0.2, 0.3),
        stats("power", 90, 0.4, 0.25)
    );
    std::fs::write(&sweep, runs).unwrap();
    let mut per_file = args.clone();
    per_file.push(sweep.display().to_string());
    per_file.extend(["--x", "elements", "-o"].map(String::from));
    per_file.push(svg.display().to_string());
    let refs: Vec<&str> = per_file.iter().map(String::as_str).collect();
    let out = radiosity(&refs);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let labels = texts(&std::fs::read_to_string(&svg).unwrap());
    for needle in ["a", "b", "c", "elements"] {
        assert!(
            labels.iter().any(|l| l == needle),
            "missing {needle}: {labels:?}"
        );
    }
}

#[test]
fn missing_keys_name_the_file_and_the_key() {
    let dir = TempDir::new("errors");
    let good = dir.0.join("good.json");
    std::fs::write(&good, stats("power", 10, 1.0, 0.5)).unwrap();
    let bad = dir.0.join("bad.json");
    std::fs::write(&bad, r#"{"elements": 5, "seconds": {"solve": 1.0}}"#).unwrap();
    let svg = dir.0.join("chart.svg");
    let (g, b, s) = (
        good.display().to_string(),
        bad.display().to_string(),
        svg.display().to_string(),
    );
    let out = radiosity(&["plot", &g, &b, "-o", &s]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("bad.json") && err.contains("'error.relative_rmse'"),
        "{err}"
    );
    let out = radiosity(&["plot", &g, "--x", "seconds.total", "-o", &s]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("good.json") && err.contains("'seconds.total'"),
        "{err}"
    );
    let out = radiosity(&["plot", &g, "--label", "settings.solver", "-o", &s]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("'settings.solver'"),
        "{err}"
    );
    let out = radiosity(&[
        "plot",
        &g,
        "-o",
        &dir.0.join("chart.png").display().to_string(),
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("SVG"), "{err}");
}
