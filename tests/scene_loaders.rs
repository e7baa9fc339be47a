//! Scene loaders against real RenderPark scenes, hand-made MGF/OBJ snippets and random garbage.

#[allow(dead_code)] // each test file uses part of the shared module
mod common;
use common::{png, srgb_to_linear};
use proptest::prelude::*;
use radiosity::geometry::DVec3;
use radiosity::scene::{self, cornell, LoadOptions, Scene, SceneError};
use std::f64::consts::PI;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

fn renderpark() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/scenes/renderpark")
}

/// A fresh temporary folder holding the given files.
fn temp_dir(files: &[(&str, &str)]) -> PathBuf {
    static COUNTER: AtomicUsize = AtomicUsize::new(0);
    let dir = std::env::temp_dir().join(format!(
        "radiosity-loaders-{}-{}",
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed)
    ));
    std::fs::create_dir_all(&dir).unwrap();
    for (name, text) in files {
        let path = dir.join(name);
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(path, text).unwrap();
    }
    dir
}

fn load_text(name: &str, text: &str) -> Result<Scene, SceneError> {
    let dir = temp_dir(&[(name, text)]);
    scene::load(&dir.join(name), &LoadOptions::default())
}

fn load_mgf(text: &str) -> Scene {
    load_text("scene.mgf", text).unwrap_or_else(|e| panic!("{e}"))
}

const SQUARE: &str = "v a =\n p 0 0 0\nv b =\n p 1 0 0\nv c =\n p 1 1 0\nv d =\n p 0 1 0\n";

#[test]
fn renderpark_scenes_load() {
    // (file, RenderPark's single-sided polygon count)
    let expected = [
        ("cube.mgf", 66),
        ("corridor.mgf", 488),
        ("examp1.mgf", 294),
        ("floor_gloss.mgf", 136),
        ("office2/office2.mgf", 422),
        ("office3/office.mgf", 12607),
        ("salon/classroom.mgf", 5250),
    ];
    for (file, renderpark_count) in expected {
        let scene = scene::load(&renderpark().join(file), &LoadOptions::default())
            .unwrap_or_else(|e| panic!("{file}: {e}"));
        let n = scene.polygons.len();
        // Our split into triangles/quads and tessellation differ in detail from RenderPark's.
        assert!(
            n as f64 >= 0.8 * renderpark_count as f64 && n as f64 <= 1.5 * renderpark_count as f64,
            "{file}: {n} polygons vs RenderPark's {renderpark_count}"
        );
        assert!(scene.emitter_count() > 0, "{file} has lights");
        assert!(scene.emitted_power().luminance() > 0.0);
        for p in &scene.polygons {
            assert!(p.shape.area() > 0.0 && p.shape.area().is_finite(), "{file}");
            let m = scene.material_of(p);
            assert!(m.reflectance.max_channel() < 1.0 && m.reflectance.min_channel() >= 0.0);
        }
        let s = scene::summary(&scene);
        assert_eq!(s.polygons, n);
        assert!(s.to_string().contains("emitters:"));
    }
}

#[test]
fn material_libraries_parse() {
    for entry in std::fs::read_dir(renderpark().join("Materials")).unwrap() {
        let path = entry.unwrap().path();
        let scene = scene::load(&path, &LoadOptions::default())
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        if path.ends_with("test.mgf") {
            // Includes all libraries, then a face with a library material and a light.
            assert_eq!(scene.polygons.len(), 2);
            assert_eq!(scene.emitter_count(), 1);
            let oak = &scene.materials[scene.polygons[0].material];
            assert_eq!(oak.name, "OakWood");
            assert!(
                oak.reflectance.r > oak.reflectance.b,
                "oak is warm: {oak:?}"
            );
        }
    }
}

#[test]
fn cornell_box_geometry() {
    let scene = cornell::cornell_box();
    let camera = scene.camera.expect("camera");
    assert_eq!(camera.eye, DVec3::new(278.0, 273.0, -800.0));
    assert!((camera.fov_degrees - 39.3).abs() < 1e-9);
    let centre = DVec3::new(278.0, 274.4, 279.6);
    for p in &scene.polygons {
        let name = scene.objects[p.object].name.as_str();
        let towards_centre = (centre - p.shape.centroid()).normalize();
        let n = p.shape.normal();
        assert!(!p.two_sided);
        match name {
            "floor" | "ceiling" | "back_wall" | "left_wall" | "right_wall" => {
                assert!(n.dot(towards_centre) > 0.5, "{name} faces into the room")
            }
            "light" => {
                assert!((n - DVec3::new(0.0, -1.0, 0.0)).length() < 1e-12);
                assert!(p.shape.vertices().iter().all(|v| v.y == cornell::LIGHT_Y));
            }
            "short_block" | "tall_block" => {
                let block_centre = scene
                    .polygons
                    .iter()
                    .filter(|q| q.object == p.object)
                    .map(|q| q.shape.centroid())
                    .sum::<DVec3>()
                    / 5.0;
                assert!(
                    n.dot(p.shape.centroid() - block_centre) > 0.0,
                    "{name} outward"
                )
            }
            other => panic!("unexpected object {other}"),
        }
    }
    // Areas from the published dimensions (trapezoids, rectangles, block sides = edge x height).
    let left_wall = {
        let (a, b, c, d) = (
            DVec3::new(552.8, 0.0, 0.0),
            DVec3::new(549.6, 0.0, 559.2),
            DVec3::new(556.0, 548.8, 559.2),
            DVec3::new(556.0, 548.8, 0.0),
        );
        0.5 * ((b - a).cross(c - a).length() + (c - a).cross(d - a).length())
    };
    let shoelace = |p: &[(f64, f64)]| {
        0.5 * (0..p.len())
            .map(|k| p[k].0 * p[(k + 1) % 4].1 - p[(k + 1) % 4].0 * p[k].1)
            .sum::<f64>()
            .abs()
    };
    let perimeter = |p: &[(f64, f64)]| {
        (0..4)
            .map(|k| {
                ((p[k].0 - p[(k + 1) % 4].0).powi(2) + (p[k].1 - p[(k + 1) % 4].1).powi(2)).sqrt()
            })
            .sum::<f64>()
    };
    let short = [(130.0, 65.0), (82.0, 225.0), (240.0, 272.0), (290.0, 114.0)];
    let tall = [
        (423.0, 247.0),
        (265.0, 296.0),
        (314.0, 456.0),
        (472.0, 406.0),
    ];
    let expected = 0.5 * (552.8 + 549.6) * 559.2 // floor
        + 556.0 * 559.2 // ceiling
        + 0.5 * (549.6 + 556.0) * 548.8 // back wall
        + 559.2 * 548.8 // right wall
        + left_wall
        + 130.0 * 105.0 // light
        + shoelace(&short) + 165.0 * perimeter(&short)
        + shoelace(&tall) + 330.0 * perimeter(&tall);
    assert!((scene.total_area() - expected).abs() < 1e-6 * expected);
    assert_eq!(scene.emitter_count(), 1);
    let power = scene.emitted_power();
    assert!((power.r - PI * 17.0 * 13650.0).abs() < 1e-6 * power.r);
}

#[test]
fn mgf_entities() {
    let text = format!(
        "{SQUARE}\
         # defaults: two-sided black\n\
         o room\no floor\nf a b c d\no\no\n\
         m grey =\n c\n rd 0.5\n sides 1\n\
         c warm =\n cct 3000\n\
         m lamp =\n c warm\n ed 1000\n\
         o lamps\nm lamp\nxf -t 0 0 2 -a 3 -t 2 0 0\nf a b c d\nxf\no\n\
         m grey\nxf -mz\nf a b c d\nxf\n\
         m grey =\n c\n rd 0.2\n\
         f a b c d\n"
    );
    // As read: the three squares in z = 0 overlap (scene::contacts::overlaps would keep one sheet).
    let dir = temp_dir(&[("scene.mgf", &text)]);
    let options = LoadOptions {
        keep_duplicates: true,
        ..LoadOptions::default()
    };
    let scene = scene::load(&dir.join("scene.mgf"), &options).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(scene.polygons.len(), 1 + 3 + 1 + 1);
    let names: Vec<&str> = scene.objects.iter().map(|o| o.name.as_str()).collect();
    assert_eq!(names, ["room/floor", "lamps", "default"]);
    // Default material: two-sided black.
    let first = &scene.polygons[0];
    assert!(first.two_sided && scene.material_of(first).reflectance.is_black());
    // Lamps: translated array instances at x = 0, 2, 4 and z = 2, emission ed / (179 pi).
    for (k, p) in scene.polygons[1..4].iter().enumerate() {
        assert!((p.shape.centroid() - DVec3::new(0.5 + 2.0 * k as f64, 0.5, 2.0)).length() < 1e-12);
        let e = scene.material_of(p).emission;
        assert!((e.luminance() - 1000.0 / (179.0 * PI)).abs() < 0.02 * e.luminance());
        assert!(e.r > e.b, "3000 K is reddish");
        assert!(!p.two_sided || scene.material_of(p).two_sided);
    }
    // Mirror in z keeps the face the mirror image: the normal flips with the geometry... a face in the
    // z = 0 plane stays there, and reversing the winding turns its front to -z.
    let mirrored = &scene.polygons[4];
    assert!((mirrored.shape.normal() - DVec3::new(0.0, 0.0, -1.0)).length() < 1e-12);
    assert!(!mirrored.two_sided);
    assert!((scene.material_of(mirrored).reflectance.g - 0.5).abs() < 1e-3);
    // Redefinition: later faces get the new values, earlier ones keep theirs.
    let last = &scene.polygons[5];
    assert!((scene.material_of(last).reflectance.g - 0.2).abs() < 1e-3);
    assert!(
        last.two_sided,
        "a redefined material starts from the defaults (2 sides)"
    );
}

#[test]
fn mgf_include_with_transform_and_relative_path() {
    let dir = temp_dir(&[
        (
            "main.mgf",
            "m white =\n rd 0.6\ni parts/piece.mgf -t 10 0 0\ni parts/piece.mgf -a 2 -t 0 5 0\n",
        ),
        ("parts/piece.mgf", &format!("{SQUARE}i sub.mgf\n")),
        ("parts/sub.mgf", "o sub\nf a b c d\no\n"),
    ]);
    let scene = scene::load(&dir.join("main.mgf"), &LoadOptions::default()).unwrap();
    let centres: Vec<DVec3> = scene.polygons.iter().map(|p| p.shape.centroid()).collect();
    assert_eq!(
        centres,
        [
            DVec3::new(10.5, 0.5, 0.0),
            DVec3::new(0.5, 0.5, 0.0),
            DVec3::new(0.5, 5.5, 0.0)
        ]
    );
    assert_eq!(scene.objects[0].name, "sub");
}

#[test]
fn mgf_seam_hole_and_solids() {
    // A 10 x 10 wall with a 4 x 4 window joined by a seam.
    let text = "v o0 =\n p 0 0 0\nv o1 =\n p 10 0 0\nv o2 =\n p 10 10 0\nv o3 =\n p 0 10 0\n\
                v h0 =\n p 3 3 0\nv h1 =\n p 3 7 0\nv h2 =\n p 7 7 0\nv h3 =\n p 7 3 0\n\
                f o0 o1 o2 o3 o0 h0 h1 h2 h3 h0\n";
    let scene = load_mgf(text);
    assert!((scene.total_area() - 84.0).abs() < 1e-9);
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
    let fh = load_mgf(&text.replace(
        "f o0 o1 o2 o3 o0 h0 h1 h2 h3 h0",
        "fh o0 o1 o2 o3 - h0 h1 h2 h3",
    ));
    assert!((fh.total_area() - 84.0).abs() < 1e-9);
    // Tessellation quality: segments per full circle.
    let sphere = "v c =\n p 0 0 0\nsph c 1\n";
    let dir = temp_dir(&[("s.mgf", sphere)]);
    let mut options = LoadOptions::default();
    let coarse = scene::load(&dir.join("s.mgf"), &options).unwrap();
    assert_eq!(coarse.polygons.len(), 8 * 16);
    options.tessellation = 64;
    let fine = scene::load(&dir.join("s.mgf"), &options).unwrap();
    assert!(fine.total_area() > coarse.total_area());
    assert!((fine.total_area() - 4.0 * PI).abs() < 0.01 * 4.0 * PI);
    for p in &fine.polygons {
        assert!(p.shape.normal().dot(p.shape.centroid()) > 0.0, "outward");
    }
}

#[test]
fn malformed_mgf_is_reported() {
    // (snippet, substring of the reason, line, fatal)
    let cases: &[(&str, &str, usize, bool)] = &[
        (
            "o a\nfrobnicate 1 2\n",
            "unknown entity 'frobnicate'",
            2,
            false,
        ),
        ("v a =\n p 0 0\n", "p takes 3 argument(s)", 2, true),
        ("v a =\n p 0 zero 0\n", "'zero' is not a number", 2, true),
        ("v a =\n p 0 nan 0\n", "not finite", 2, true),
        ("v a =\n p 0 inf 0\n", "not finite", 2, true),
        (SQUARE, "", 0, false),
        ("\n\nf a b c\n", "undefined vertex 'a'", 3, true),
        ("i missing.mgf\n", "cannot include", 1, true),
        ("xf -t 1 2\n", "missing an argument", 1, true),
        ("xf -q\n", "unknown transform argument", 1, true),
        ("xf\n", "xf end without", 1, true),
        ("o\n", "o end without", 1, true),
        ("m nothing\n", "undefined material 'nothing'", 1, true),
        ("c nothing\n", "undefined colour 'nothing'", 1, true),
        ("m x =\n sides 3\n", "sides must be 1 or 2", 2, true),
        ("m x =\n rd -0.5\n", "negative reflectance", 2, true),
        ("c\n cxy 0.8 0.5\n", "outside the CIE diagram", 2, true),
        (
            "v c =\n p 0 0 0\nsph c 0\n",
            "sphere radius is zero",
            3,
            true,
        ),
        ("v c =\n p 0 0 0\nring c 0 1\n", "has no normal", 3, true),
        ("p 1 2 3\n", "outside a vertex context", 1, true),
        ("ies lamp.ies\n", "cannot read file", 1, true),
        (
            "m x =\n rs 0.5 0.1\n ts 0.2 0.1\n",
            "rs (specular",
            2,
            false,
        ),
    ];
    for &(snippet, reason, line, fatal) in cases {
        match load_text("bad.mgf", snippet) {
            Err(SceneError(d)) => {
                assert!(fatal, "{snippet:?} should only warn, got error {d}");
                assert!(d.message.contains(reason), "{snippet:?}: {d}");
                assert_eq!(d.line, line, "{snippet:?}: {d}");
                assert!(d.file.ends_with("bad.mgf"));
            }
            Ok(scene) => {
                assert!(!fatal, "{snippet:?} should fail");
                if !reason.is_empty() {
                    assert!(
                        scene
                            .warnings
                            .iter()
                            .any(|w| w.message.contains(reason) && w.line == line),
                        "{snippet:?}: {:?}",
                        scene.warnings
                    );
                    // One warning per material for non-diffuse terms.
                    assert_eq!(scene.warnings.len(), 1, "{:?}", scene.warnings);
                }
            }
        }
    }
}

#[test]
fn reflectance_of_one_or_more_is_clamped() {
    let scene = load_mgf(&format!("{SQUARE}m x =\n rd 1.5\nf a b c d\n"));
    let w = &scene.warnings[0];
    assert!(w.message.contains("clamped") && w.line == 10, "{w}");
    assert_eq!(scene.materials[0].reflectance.max_channel(), 0.999);
}

#[test]
fn degenerate_polygons_are_dropped_with_a_warning() {
    let text = format!(
        "{SQUARE}v e =\n p 2 0 0\nv f =\n p 1 1 0.5\n\
         f a b e\n\
         f a a b\n\
         f a b c f\n"
    );
    let scene = load_mgf(&text);
    let w = &scene.warnings;
    assert!(
        w[0].message.contains("zero area") && w[0].line == 13,
        "{w:?}"
    );
    assert!(
        w[1].message.contains("distinct vertices") && w[1].line == 14,
        "{w:?}"
    );
    assert!(
        w[2].message.contains("non-planar") && w[2].line == 15,
        "{w:?}"
    );
    assert_eq!(
        scene.polygons.len(),
        2,
        "the bent quad becomes two triangles"
    );
}

const CUBE_OBJ: &str = "mtllib box.mtl\n\
v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 0 0\nv 2 2 0\nv 0 2 0\n\
o floor\nusemtl white\nf 1 2 3 4\n\
o ell\nusemtl lamp\nf 2 5 6 7 4 3\n";

/// `map_Kd` multiplies `Kd` by its texture's mean linear colour (a texture without `Kd` is the colour
/// itself); a texture that cannot be read leaves `Kd` alone with a warning naming it; `Ks` and `d`
/// are named as not simulated; a texture read is one of the scene's sources (no output may replace it).
#[test]
fn obj_textures_enter_as_their_mean_colour() {
    let texels = [[255, 128, 0], [0, 128, 255], [255, 255, 255], [0, 0, 0]];
    let mean = |channel: usize| {
        texels
            .iter()
            .map(|t| srgb_to_linear(t[channel]))
            .sum::<f64>()
            / 4.0
    };
    let mtl = "newmtl white\nKd 0.5 0.4 0.3\nmap_Kd -bm 1 tex/wood.png\nKs 0.5 0.5 0.5\n\
               newmtl lamp\nmap_Kd tex/wood.png\nKe 1 1 1\nd 0.5\n";
    let dir = temp_dir(&[("box.obj", CUBE_OBJ), ("box.mtl", mtl)]);
    std::fs::create_dir_all(dir.join("tex")).unwrap();
    std::fs::write(dir.join("tex/wood.png"), png(texels)).unwrap();
    let scene = scene::load(&dir.join("box.obj"), &LoadOptions::default()).unwrap();
    let white = scene.materials.iter().find(|m| m.name == "white").unwrap();
    let expected = [0.5 * mean(0), 0.4 * mean(1), 0.3 * mean(2)];
    for (got, want) in white.reflectance.to_array().iter().zip(expected) {
        // MTL numbers are read as f32.
        assert!(
            (got - want).abs() < 1e-7,
            "{:?} against {expected:?}",
            white.reflectance
        );
    }
    let lamp = scene.materials.iter().find(|m| m.name == "lamp").unwrap();
    assert!(
        (lamp.reflectance.g - mean(1)).abs() < 1e-12,
        "{:?}",
        lamp.reflectance
    );
    let warned = |what: &str| scene.warnings.iter().any(|w| w.message.contains(what));
    assert!(
        warned("'white': Ks (specular reflection) ignored"),
        "{:?}",
        scene.warnings
    );
    assert!(
        warned("'lamp': d/Tr (transparency) ignored"),
        "{:?}",
        scene.warnings
    );
    assert!(
        scene.sources.iter().any(|s| s.ends_with("tex/wood.png")),
        "{:?}",
        scene.sources
    );
    // Without the image: Kd alone, and a warning naming the texture.
    std::fs::remove_file(dir.join("tex/wood.png")).unwrap();
    let scene = scene::load(&dir.join("box.obj"), &LoadOptions::default()).unwrap();
    let white = scene.materials.iter().find(|m| m.name == "white").unwrap();
    assert_eq!(
        white.reflectance.to_array(),
        [0.5, 0.4f32 as f64, 0.3f32 as f64]
    );
    assert!(
        scene.warnings.iter().any(|w| w
            .message
            .contains("map_Kd tex/wood.png not found: Kd alone")),
        "{:?}",
        scene.warnings
    );
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn obj_with_mtl() {
    let dir = temp_dir(&[
        ("box.obj", CUBE_OBJ),
        (
            "box.mtl",
            "newmtl white\nKd 0.8 0.8 0.8\nnewmtl lamp\nKd 1.2 0.5 0.5\nKe 5 4 3\n",
        ),
    ]);
    let scene = scene::load(&dir.join("box.obj"), &LoadOptions::default()).unwrap();
    let names: Vec<&str> = scene.objects.iter().map(|o| o.name.as_str()).collect();
    assert_eq!(names, ["floor", "ell"]);
    assert!((scene.total_area() - 4.0).abs() < 1e-9);
    for p in &scene.polygons {
        assert!(!p.two_sided);
        assert!(
            (p.shape.normal() - DVec3::Z).length() < 1e-9,
            "counter-clockwise is the front"
        );
    }
    let lamp = scene.materials.iter().find(|m| m.name == "lamp").unwrap();
    assert_eq!(lamp.emission.to_array(), [5.0, 4.0, 3.0]);
    assert_eq!(lamp.reflectance.r, 0.999);
    assert!(scene.warnings.iter().any(|w| w.message.contains("clamped")));
    // Missing MTL: a warning at the `mtllib` line naming the library, and default grey.
    let dir = temp_dir(&[("box.obj", CUBE_OBJ)]);
    let scene = scene::load(&dir.join("box.obj"), &LoadOptions::default()).unwrap();
    assert!(scene.warnings.iter().any(|w| w.line == 1
        && w.message.contains("box.mtl not found")
        && w.message.contains("default grey")));
    assert!(scene
        .polygons
        .iter()
        .all(|p| scene.material_of(p).reflectance.r == 0.5));
    // The two-sided override.
    let forced = LoadOptions {
        force_two_sided: true,
        ..LoadOptions::default()
    };
    let scene = scene::load(&dir.join("box.obj"), &forced).unwrap();
    assert!(scene.polygons.iter().all(|p| p.two_sided));
}

#[test]
fn malformed_obj_is_reported() {
    let cases: &[(&str, &str, usize, bool)] = &[
        ("v 0 0 0\nv 1 0\n", "three coordinates", 2, true),
        ("v 0 0 0\nv 1 x 0\n", "'x' is not a number", 2, true),
        ("v 0 0 0\nv 1 inf 0\n", "not finite", 2, true),
        (
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n",
            "does not exist",
            4,
            true,
        ),
        (
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 q\n",
            "bad face vertex",
            4,
            true,
        ),
        (
            "v 0 0 0\nv 1 0 0\nv 2 0 0\n\nf 1 2 3\n",
            "zero area",
            5,
            false,
        ),
        (
            "v 0 0 0\nv 1 0 0\nv 1 1 1\nv 0 1 0\nf 1 2 3 4\n",
            "non-planar",
            5,
            false,
        ),
    ];
    for &(snippet, reason, line, fatal) in cases {
        match load_text("bad.obj", snippet) {
            Err(SceneError(d)) => {
                assert!(fatal, "{snippet:?}: {d}");
                assert!(
                    d.message.contains(reason) && d.line == line,
                    "{snippet:?}: {d}"
                );
            }
            Ok(scene) => {
                assert!(!fatal, "{snippet:?} should fail");
                assert!(
                    scene
                        .warnings
                        .iter()
                        .any(|w| w.message.contains(reason) && w.line == line),
                    "{snippet:?}: {:?}",
                    scene.warnings
                );
            }
        }
    }
    let e = load_text("scene.ply", "").unwrap_err();
    assert!(e.0.message.contains("unknown scene format '.ply'"));
    // A file that cannot be read, or the wrong kind of path, is named without a line.
    let missing = std::env::temp_dir().join("radiosity-no-such-scene.mgf");
    let e = scene::load(&missing, &LoadOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with(&format!("{}: cannot read file", missing.display())),
        "{e}"
    );
    let e = scene::load(&std::env::temp_dir(), &LoadOptions::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains(": a directory, not a scene file"), "{e}");
}

fn garbage_line() -> impl Strategy<Value = String> {
    let keyword = prop::sample::select(vec![
        "v", "p", "n", "f", "fh", "o", "xf", "m", "c", "cxy", "cspec", "cct", "cmix", "rd", "ed",
        "rs", "sides", "sph", "cyl", "cone", "ring", "torus", "prism", "i", "#", "zz", "-",
    ]);
    let word = prop::sample::select(vec![
        "a", "b", "c", "=", "0", "1", "-1", "2.5", "1e300", "-1e-300", "nan", "inf", "-a", "-t",
        "-s", "-i", "-mx", "-rx", "3", "\\", "", "x", "100",
    ]);
    (keyword, prop::collection::vec(word, 0..7)).prop_map(|(k, ws)| format!("{k} {}", ws.join(" ")))
}

/// A solid whose size overflows the area (found by `mgf_garbage_never_panics`: a cone of radius
/// 1e300 gave triangles of infinite area) is dropped with a warning, never kept with such an area.
#[test]
fn solids_too_large_for_their_area_are_dropped() {
    let text = format!("{SQUARE}m w =\n rd 0.5\ncone a 1e300 b 0\nxf -s 1e200\nf a b c d\nxf\n");
    let dir = temp_dir(&[("big.mgf", &text)]);
    let scene = scene::load(&dir.join("big.mgf"), &LoadOptions::default()).expect("loads");
    assert!(scene.polygons.iter().all(|p| p.shape.area().is_finite()));
    let dropped = scene
        .warnings
        .iter()
        .filter(|w| w.message.contains("too large"))
        .count();
    assert!(dropped >= 2, "{:?}", scene.warnings);
    let _ = std::fs::remove_dir_all(dir);
}

proptest! {
    #![proptest_config(common::proptest_config(200))]
    #[test]
    fn mgf_garbage_never_panics(lines in prop::collection::vec(garbage_line(), 0..40)) {
        let text = format!("{SQUARE}v c =\n p 0 0 1\n n 0 0 1\n{}\n", lines.join("\n"));
        let dir = temp_dir(&[("g.mgf", &text)]);
        if let Ok(scene) = scene::load(&dir.join("g.mgf"), &LoadOptions::default()) {
            for p in &scene.polygons {
                prop_assert!(p.shape.area().is_finite());
            }
        }
        let _ = std::fs::remove_dir_all(dir);
    }
}

#[test]
fn the_one_sided_override_turns_mgf_default_two_sided_surfaces_one_sided() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/scenes/renderpark/cube.mgf");
    let as_written = scene::load(&path, &LoadOptions::default()).unwrap();
    assert!(
        as_written.polygons.iter().all(|p| p.two_sided),
        "MGF's default is two sides"
    );
    let options = LoadOptions {
        force_one_sided: true,
        ..LoadOptions::default()
    };
    let one_sided = scene::load(&path, &options).unwrap();
    assert!(one_sided.polygons.iter().all(|p| !p.two_sided));
    let (e2, e1) = (as_written.emitted_power(), one_sided.emitted_power());
    assert!(
        (e2.g - 2.0 * e1.g).abs() < 1e-9 * e2.g,
        "a two-sided light emits twice: {e2:?} vs {e1:?}"
    );
}

/// Issue 8: inputs that used to panic, exhaust memory or hang end in a one-line error at file:line.
#[test]
fn short_mtl_colours_are_errors_at_their_line() {
    for (mtl, line, reason) in [
        ("newmtl white\nKd 1\n", 2, "Kd needs 3 number(s), got 1"),
        ("newmtl a\n\nKa 0.1 0.2\n", 3, "Ka needs 3"),
        ("newmtl a\nKs\n", 2, "Ks needs 3"),
        ("newmtl a\nKe 1 x 1\n", 2, "'x' is not a number"),
        ("newmtl a\nNs\n", 2, "Ns needs 1"),
        ("newmtl a\nKd 1 1 1e99\n", 2, "not finite"),
    ] {
        let dir = temp_dir(&[("box.obj", CUBE_OBJ), ("box.mtl", mtl)]);
        let e = scene::load(&dir.join("box.obj"), &LoadOptions::default()).unwrap_err();
        assert!(e.0.file.ends_with("box.mtl"), "{e}");
        assert_eq!(e.0.line, line, "{e}");
        assert!(e.0.message.contains(reason), "{mtl:?}: {e}");
    }
}

#[test]
fn obj_lines_tobj_rejects_are_reported_with_their_line() {
    for (obj, line, reason) in [
        ("v 0 0 0\nvn 0 1\n", 2, "vn needs 3"),
        ("v 0 0 0\nvt x 1\n", 2, "not a number"),
        ("v 0 0 0\nv 1 1 1 0\n", 2, "weight w is zero"),
        ("v 0 0 0\nv 1 1 1 1 1\n", 2, "not 5 numbers"),
        ("v 0 0 0\nusemtl\n", 2, "usemtl needs"),
    ] {
        let dir = temp_dir(&[("bad.obj", obj)]);
        let e = scene::load(&dir.join("bad.obj"), &LoadOptions::default()).unwrap_err();
        assert_eq!(
            (e.0.line, e.0.message.contains(reason)),
            (line, true),
            "{e}"
        );
    }
    let dir = temp_dir(&[]);
    std::fs::write(dir.join("bad.obj"), b"v 0 0 0\nv 1 \xff 0\n").unwrap();
    let e = scene::load(&dir.join("bad.obj"), &LoadOptions::default()).unwrap_err();
    assert!(e.0.line == 2 && e.0.message.contains("not UTF-8"), "{e}");
}

#[test]
fn echoed_tokens_are_sanitised_and_truncated() {
    let huge = "x".repeat(5 << 20);
    let e = load_text("bad.mgf", &format!("v a =\n p 0 {huge} 0\n")).unwrap_err();
    let shown = e.to_string();
    assert!(shown.len() < 1000, "{} bytes", shown.len());
    assert!(shown.contains("bad.mgf:2"), "{shown}");
    let e = load_text("bad.mgf", "v a =\n p 0 \u{1b}[31mred\u{7} 0\n").unwrap_err();
    let shown = e.to_string();
    assert!(!shown.chars().any(|c| c.is_control()), "{shown:?}");
    assert!(shown.contains("\\u{1b}"), "{shown}");
}

#[test]
fn devices_huge_files_and_include_cycles_are_refused() {
    // mtllib /dev/zero: refused, not read forever.
    let dir = temp_dir(&[("box.obj", &CUBE_OBJ.replace("box.mtl", "/dev/zero"))]);
    let e = scene::load(&dir.join("box.obj"), &LoadOptions::default()).unwrap_err();
    assert!(e.to_string().contains("not a regular file"), "{e}");
    // MGF include of a device.
    let e = load_text("a.mgf", "i /dev/zero\n").unwrap_err();
    assert!(
        e.0.line == 1 && e.0.message.contains("not a regular file"),
        "{e}"
    );
    // The scene itself.
    let e = scene::load(Path::new("/dev/zero.mgf"), &LoadOptions::default()).unwrap_err();
    assert!(e.to_string().contains("/dev/zero"), "{e}");
    // Oversized files (sparse, so the test costs no disk).
    let dir = temp_dir(&[]);
    let big = std::fs::File::create(dir.join("big.mgf")).unwrap();
    big.set_len(scene::MAX_FILE_BYTES + 1).unwrap();
    let e = scene::load(&dir.join("big.mgf"), &LoadOptions::default()).unwrap_err();
    assert!(e.to_string().contains("larger than"), "{e}");
    // Self-inclusion, with a long body: the cycle is found at the first include.
    let body = format!("i self.mgf\n{}", "# padding\n".repeat(400_000));
    let e = load_text("self.mgf", &body).unwrap_err();
    assert!(e.0.message.contains("include cycle"), "{e}");
    assert!(e.0.message.contains("self.mgf:1 -> "), "{e}");
    // A two-file cycle names the chain.
    let dir = temp_dir(&[("a.mgf", "\ni b.mgf\n"), ("b.mgf", "i a.mgf\n")]);
    let e = scene::load(&dir.join("a.mgf"), &LoadOptions::default()).unwrap_err();
    let (message, file) = (&e.0.message, &e.0.file);
    assert!(file.ends_with("b.mgf") && e.0.line == 1, "{e}");
    assert!(
        message.contains("a.mgf:2 -> ") && message.contains("b.mgf:1 -> "),
        "{e}"
    );
    // Deep but acyclic nesting is bounded.
    let files: Vec<(String, String)> = (0..40)
        .map(|k| (format!("n{k}.mgf"), format!("i n{}.mgf\n", k + 1)))
        .collect();
    let refs: Vec<(&str, &str)> = files
        .iter()
        .map(|(a, b)| (a.as_str(), b.as_str()))
        .collect();
    let dir = temp_dir(&refs);
    let e = scene::load(&dir.join("n0.mgf"), &LoadOptions::default()).unwrap_err();
    assert!(e.0.message.contains("nested deeper"), "{e}");
}

#[test]
fn huge_arrays_and_polygons_are_bounded_and_fast() {
    let start = std::time::Instant::now();
    // A million-instance array used to be quadratic (each instance's transform built step by step).
    let scene = load_mgf("xf -a 1000000 -t 0 0 1\nv a =\nxf\n");
    assert!(scene.polygons.is_empty());
    let scene = load_mgf(&format!(
        "{SQUARE}xf -a 100000 -rz 1 -t 0 0 1\nf a b c d\nxf\n"
    ));
    assert_eq!(scene.polygons.len(), 100_000);
    // Nested arrays past the polygon or entity budget: an error, not an exhausted machine.
    let text = format!("{SQUARE}xf -a 1000 -t 0 0 1\nxf -a 1000 -t 1 0 0\nxf -a 1000 -t 0 1 0\nf a b c d\nxf\nxf\nxf\n");
    let e = load_text("big.mgf", &text).unwrap_err();
    assert!(e.0.message.contains("more than 1000000 polygons"), "{e}");
    let e = load_text("big.mgf", "xf -a 100000\nxf -a 1000\nv a =\nxf\nxf\n").unwrap_err();
    assert!(e.0.message.contains("entities"), "{e}");
    // A polygon with a million vertices: refused at its line.
    let mut text = String::new();
    let n = 1_000_000;
    for k in 0..n {
        let a = std::f64::consts::TAU * k as f64 / n as f64;
        text.push_str(&format!("v v{k} =\n p {} {} 0\n", a.cos(), a.sin()));
    }
    text.push('f');
    for k in 0..n {
        text.push_str(&format!(" v{k}"));
    }
    text.push('\n');
    let e = load_text("round.mgf", &text).unwrap_err();
    assert_eq!(e.0.line, 2 * n + 1, "{e}");
    assert!(e.0.message.contains("more than"), "{e}");
    // Large polygons under the bound are split quickly.
    let n = 5000;
    let mut text = String::new();
    for k in 0..n {
        let a = std::f64::consts::TAU * k as f64 / n as f64;
        let r = if k % 2 == 0 { 1.0 } else { 0.8 };
        text.push_str(&format!("v v{k} =\n p {} {} 0\n", r * a.cos(), r * a.sin()));
    }
    text.push('f');
    for k in 0..n {
        text.push_str(&format!(" v{k}"));
    }
    text.push('\n');
    let scene = load_mgf(&text);
    assert!(scene.polygons.len() >= n / 2);
    assert!(start.elapsed().as_secs() < 60, "{:?}", start.elapsed());
}

#[test]
fn the_camera_comment_round_trips() {
    let dir = temp_dir(&[]);
    let path = dir.join("c.mgf");
    scene::mgf::writer::save(&cornell::cornell_box(), &path).unwrap();
    let back = scene::load(&path, &LoadOptions::default()).unwrap();
    assert_eq!(back.camera, cornell::cornell_box().camera);
    let e = load_text(
        "c.mgf",
        "# camera: eye 0 0 0 look_at 0 0 x up 0 1 0 fov 40\n",
    )
    .unwrap_err();
    assert!(e.0.line == 1 && e.0.message.contains("'x'"), "{e}");
    let scene = load_mgf("# camera: eye 0 0 0 look_at 0 0 0 up 0 1 0 fov 40\n");
    assert!(scene.camera.is_none() && scene.warnings.len() == 1);
}

#[test]
fn nan_and_degenerate_polygons_in_readers() {
    let e = load_text("bad.obj", "v 0 0 0\nv nan 0 0\n").unwrap_err();
    assert_eq!(e.0.line, 2, "{e}");
    // Collinear and zero-area faces warn at their line.
    let scene = load_mgf(&format!("{SQUARE}v e =\n p 2 0 0\nf a b e\nf a a b\n"));
    assert!(scene.polygons.is_empty());
    let lines: Vec<usize> = scene.warnings.iter().map(|w| w.line).collect();
    assert_eq!(lines, [11, 12], "{:?}", scene.warnings);
}
