//! Every real MGF file loads (issue #8 item 6): chromaticities on the edge of the diagram read as black,
//! exact duplicate polygons kept once with a warning naming both places, and degenerate input in each
//! reader warned about or refused, never silently used.

use radiosity::color::Rgb;
use radiosity::scene::{self, LoadOptions, Scene, SceneError};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

/// A fresh temporary folder holding the given files.
fn temp_dir(files: &[(&str, &str)]) -> PathBuf {
    static COUNTER: AtomicUsize = AtomicUsize::new(0);
    let dir = std::env::temp_dir().join(format!(
        "radiosity-duplicates-{}-{}",
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed)
    ));
    std::fs::create_dir_all(&dir).unwrap();
    for (name, text) in files {
        std::fs::write(dir.join(name), text).unwrap();
    }
    dir
}

fn load_with(files: &[(&str, &str)], options: &LoadOptions) -> Result<Scene, SceneError> {
    let dir = temp_dir(files);
    scene::load(&dir.join(files[0].0), options)
}

fn load(files: &[(&str, &str)]) -> Scene {
    load_with(files, &LoadOptions::default()).unwrap_or_else(|e| panic!("{e}"))
}

/// A unit square a b c d in z = 0 (lines 1-8) and an emitter material (lines 9-10).
const SQUARE: &str =
    "v a =\n p 0 0 0\nv b =\n p 1 0 0\nv c =\n p 1 1 0\nv d =\n p 0 1 0\nm lamp =\n ed 100\n";

fn warnings_with(scene: &Scene, text: &str) -> Vec<String> {
    scene
        .warnings
        .iter()
        .map(|w| w.to_string())
        .filter(|w| w.contains(text))
        .collect()
}

#[test]
fn chromaticities_on_the_lower_edge_are_black_with_a_warning() {
    for cxy in ["0.4 0", "0 0", "1 0"] {
        let text = format!("{SQUARE}m grey =\n c\n cxy {cxy}\n rd 0.5\n ed 10\nf a b c d\n");
        let scene = load(&[("edge.mgf", &text)]);
        let warned = warnings_with(&scene, "no luminance");
        assert_eq!(warned.len(), 1, "{:?}", scene.warnings);
        assert!(warned[0].contains("edge.mgf:13:"), "{}", warned[0]);
        let m = scene.material_of(&scene.polygons[0]);
        assert_eq!((m.reflectance, m.emission), (Rgb::BLACK, Rgb::BLACK));
    }
    // Off the square it stays an error.
    for cxy in ["0.8 0.5", "-0.1 0", "0.2 -0.1"] {
        let text = format!("c\n cxy {cxy}\n");
        let e = load_with(&[("bad.mgf", &text)], &LoadOptions::default()).unwrap_err();
        assert_eq!(e.0.line, 2, "{cxy}: {e}");
    }
}

#[test]
fn exact_duplicates_are_kept_once_with_both_places() {
    // The same face three times (once cyclically shifted), plus its reverse, which faces the other way.
    let text = format!("{SQUARE}f a b c d\nf c d a b\nf a b c d\nf d c b a\n");
    let scene = load(&[("twice.mgf", &text)]);
    assert_eq!(scene.polygons.len(), 2, "one of each side");
    let warned = warnings_with(&scene, "repeat exactly");
    assert_eq!(
        warned.len(),
        1,
        "one warning per group: {:?}",
        scene.warnings
    );
    assert!(
        warned[0].contains("twice.mgf:12: 2 polygon(s)"),
        "{}",
        warned[0]
    );
    assert!(warned[0].contains("those from /") && warned[0].contains("twice.mgf:11:"));
    // Emitted power is that of the two sides, not doubled.
    // Φ = π L_e A per side, L_e = ed / (179 π): two unit squares, each two-sided (MGF's default).
    let power = scene.emitted_power().luminance();
    let expected = 2.0 * 2.0 * 100.0 / 179.0;
    // The sRGB matrix has 7 significant digits: neutral white maps to RGB (1, 1, 1) within ~1e-7.
    assert!(
        (power - expected).abs() < 1e-6 * expected,
        "{power} vs {expected}"
    );

    let kept = load_with(
        &[("twice.mgf", &text)],
        &LoadOptions {
            keep_duplicates: true,
            ..LoadOptions::default()
        },
    )
    .unwrap();
    assert_eq!(kept.polygons.len(), 4);
    assert!(warnings_with(&kept, "repeat exactly").is_empty());
}

#[test]
fn different_materials_or_places_are_not_duplicates() {
    let text = format!(
        "{SQUARE}f a b c d\nm other =\n rd 0.3\nf a b c d\nv e =\n p 0 0 1e-6\nm lamp\nf e b c d\n"
    );
    let scene = load(&[("distinct.mgf", &text)]);
    assert_eq!(scene.polygons.len(), 3, "{:?}", scene.warnings);
    assert!(warnings_with(&scene, "repeat exactly").is_empty());
}

#[test]
fn furniture_included_twice_is_one_warning_naming_both_include_lines() {
    let lamp = format!("{SQUARE}f a b c d\nf a b c\n");
    let room = "i lamp.mgf\nc\ni lamp.mgf\n";
    let scene = load(&[("room.mgf", room), ("lamp.mgf", &lamp)]);
    // The square becomes one quad, the triangle one triangle: each kept once.
    assert_eq!(scene.polygons.len(), 2);
    let warned = warnings_with(&scene, "repeat exactly");
    assert_eq!(warned.len(), 1, "{:?}", scene.warnings);
    assert!(warned[0].contains("room.mgf:3 -> "), "{}", warned[0]);
    assert!(warned[0].contains("room.mgf:1 -> "), "{}", warned[0]);
    assert!(warned[0].contains("2 polygon(s)"), "{}", warned[0]);
}

#[test]
fn duplicates_in_obj_are_found_too() {
    let obj = "v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\nf 2 3 1\n";
    let scene = load(&[("dup.obj", obj)]);
    assert_eq!(scene.polygons.len(), 1);
    let warned = warnings_with(&scene, "repeat exactly");
    assert!(warned[0].contains("dup.obj:5: 1 polygon(s)") && warned[0].contains("dup.obj:4:"));
}

/// RenderPark's own scenes as shipped here hold no exact duplicates (`info --keep-duplicates` gives the
/// same polygon counts): the detector must not invent any, and every removal must be reported.
#[test]
fn renderpark_scenes_duplicates() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/scenes/renderpark");
    for (file, expected) in RENDERPARK_DUPLICATES {
        let path = dir.join(file);
        let kept = scene::load(
            &path,
            &LoadOptions {
                keep_duplicates: true,
                ..LoadOptions::default()
            },
        )
        .unwrap_or_else(|e| panic!("{file}: {e}"));
        let deduplicated =
            scene::load(&path, &LoadOptions::default()).unwrap_or_else(|e| panic!("{e}"));
        let removed = kept.polygons.len() - deduplicated.polygons.len();
        let warned: usize = deduplicated
            .warnings
            .iter()
            .filter(|w| w.message.contains("repeat exactly"))
            .map(|w| {
                w.message
                    .split(' ')
                    .next()
                    .unwrap()
                    .parse::<usize>()
                    .unwrap()
            })
            .sum();
        assert_eq!(removed, warned, "{file}: every removed polygon is reported");
        assert_eq!(removed, expected, "{file}: {:?}", deduplicated.warnings);
        // Removing a duplicate never removes area that is not there twice.
        let area_kept = kept.total_area();
        let area_dedup = deduplicated.total_area();
        assert!(area_dedup <= area_kept && area_dedup > 0.0, "{file}");
    }
}

const RENDERPARK_DUPLICATES: [(&str, usize); 7] = [
    ("cube.mgf", 0),
    ("corridor.mgf", 0),
    ("examp1.mgf", 0),
    ("floor_gloss.mgf", 0),
    ("office2/office2.mgf", 0),
    ("office3/office.mgf", 0),
    ("salon/classroom.mgf", 0),
];

#[test]
fn negative_emission_and_reflectance_above_one_warn_in_obj() {
    let obj = "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl x\nf 1 2 3\n";
    let mtl = "newmtl x\nKd 1.5 0.2 0.2\nKe -1 0 2\n";
    let scene = load(&[("neg.obj", obj), ("m.mtl", mtl)]);
    assert_eq!(
        warnings_with(&scene, "negative Ke").len(),
        1,
        "{:?}",
        scene.warnings
    );
    assert_eq!(
        warnings_with(&scene, "clamped").len(),
        2,
        "{:?}",
        scene.warnings
    );
    let m = &scene.materials[0];
    assert!(m.reflectance.r < 1.0 && m.emission == Rgb::new(0.0, 0.0, 2.0));
}

#[test]
fn non_planar_concave_and_overflowing_mgf_polygons() {
    // Non-planar: warned at its line, kept as triangles.
    let text = "v a =\n p 0 0 0\nv b =\n p 1 0 0\nv c =\n p 1 1 0.5\nv d =\n p 0 1 0\nf a b c d\n";
    let scene = load(&[("bent.mgf", text)]);
    assert!(!scene.polygons.is_empty());
    assert!(
        scene
            .warnings
            .iter()
            .any(|w| w.line == 9 && w.message.contains("planar")),
        "{:?}",
        scene.warnings
    );
    // Concave (an L of area 3): split into convex pieces of the same area, no warning needed.
    let l = "v a =\n p 0 0 0\nv b =\n p 2 0 0\nv c =\n p 2 1 0\nv d =\n p 1 1 0\nv e =\n p 1 2 0\nv f =\n p 0 2 0\nf a b c d e f\n";
    let scene = load(&[("l.mgf", l)]);
    assert!(
        (scene.total_area() - 3.0).abs() < 1e-12,
        "{}",
        scene.total_area()
    );
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
    // Transforms that overflow to infinity drop the polygon with a warning at its line.
    let text = format!("xf -s 1e200\nxf -s 1e200\n{SQUARE}f a b c d\nxf\nxf\n");
    let scene = load(&[("huge.mgf", &text)]);
    assert!(scene.polygons.is_empty());
    assert!(
        scene
            .warnings
            .iter()
            .any(|w| w.line == 13 && w.message.contains("non-finite")),
        "{:?}",
        scene.warnings
    );
}
