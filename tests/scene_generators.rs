//! `radiosity scene NAME -o FILE.mgf` and the MGF writer: every generated scene reads back with the same
//! polygons, area, emitted power and materials, and the furnace MGF solves to E / (1 - rho).

use radiosity::color::Rgb;
use radiosity::geometry::DVec3;
use radiosity::pipeline::{simulate, SimulationSettings};
use radiosity::progress::Progress;
use radiosity::scene::generators::{self, ShadowGroups};
use radiosity::scene::mgf::writer;
use radiosity::scene::{self, cornell, LoadOptions, Scene};
use std::path::{Path, PathBuf};
use std::process::Command;

struct TempDir(PathBuf);

impl TempDir {
    fn new(name: &str) -> Self {
        let dir =
            std::env::temp_dir().join(format!("radiosity-scene-{name}-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        TempDir(dir)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn generate(dir: &Path, args: &[&str]) -> Scene {
    let path = dir.join(format!("{}.mgf", args[0]));
    let out = Command::new(env!("CARGO_BIN_EXE_radiosity"))
        .arg("scene")
        .args(args)
        .arg("-o")
        .arg(&path)
        .output()
        .expect("run radiosity");
    assert!(
        out.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let scene = scene::load(&path, &LoadOptions::default()).expect("load generated MGF");
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
    scene
}

fn close(a: Rgb, b: Rgb, tolerance: f64) -> bool {
    (a - b)
        .to_array()
        .iter()
        .zip(b.to_array())
        .all(|(d, v)| d.abs() <= tolerance * v.abs().max(1.0))
}

/// Same polygon count, area, emitted power, per-polygon sidedness and materials.
fn assert_same(read: &Scene, original: &Scene, tolerance: f64) {
    assert_eq!(read.polygons.len(), original.polygons.len());
    let (a, b) = (read.total_area(), original.total_area());
    assert!((a - b).abs() <= 1e-12 * b, "area {a} vs {b}");
    assert!(close(
        read.emitted_power(),
        original.emitted_power(),
        tolerance
    ));
    for (p, q) in read.polygons.iter().zip(&original.polygons) {
        assert!((p.shape.area() - q.shape.area()).abs() <= 1e-12 * q.shape.area());
        assert!((p.shape.normal() - q.shape.normal()).length() < 1e-12);
        assert_eq!(p.two_sided, q.two_sided);
        let (m, n) = (read.material_of(p), original.material_of(q));
        assert_eq!(m.name, n.name);
        assert!(
            close(m.reflectance, n.reflectance, tolerance),
            "{m:?} vs {n:?}"
        );
        assert!(close(m.emission, n.emission, tolerance), "{m:?} vs {n:?}");
    }
}

#[test]
fn generated_scenes_read_back_the_same() {
    let dir = TempDir::new("generators");
    let d = &dir.0;
    let cases = [
        (
            generate(
                d,
                &[
                    "parallel-plates",
                    "--size",
                    "2",
                    "--distance",
                    "0.5",
                    "--rho",
                    "0.3",
                ],
            ),
            generators::parallel_plates(2.0, 0.5, 0.3, 1.0),
        ),
        (
            generate(d, &["perpendicular-plates", "--emission", "3.5"]),
            generators::perpendicular_plates(1.0, 0.5, 3.5),
        ),
        (
            generate(d, &["furnace", "--size", "1,2,3", "--rho", "0.8"]),
            generators::furnace(DVec3::new(1.0, 2.0, 3.0), 0.8, 1.0),
        ),
        (
            generate(d, &["shadow-groups", "--floor"]),
            ShadowGroups {
                floor: true,
                ..Default::default()
            }
            .scene(),
        ),
    ];
    // Grey materials round trip to 1e-6 (in fact to rounding).
    for (read, original) in &cases {
        assert_same(read, original, 1e-9);
    }
    let shadow = &cases[3].0;
    assert_eq!(shadow.objects.len(), 7, "wall, light, four groups, floor");
    // Colours too: the Cornell box's red, green and warm light.
    let read = generate(d, &["cornell"]);
    assert_same(&read, &cornell::cornell_box(), 1e-9);
    assert_eq!(read.objects.len(), cornell::cornell_box().objects.len());
}

#[test]
fn writer_keeps_per_polygon_sidedness_and_distinct_object_names() {
    let mut scene = generators::lit_box(DVec3::ONE, Rgb::new(0.2, 0.5, 0.7), 2.0);
    scene.polygons[2].two_sided = true;
    scene.materials[0].name = "white wall".into();
    let dir = TempDir::new("writer");
    let path = dir.0.join("box.mgf");
    writer::save(&scene, &path).expect("write");
    let read = scene::load(&path, &LoadOptions::default()).expect("read");
    assert_eq!(read.polygons.len(), 6);
    assert_eq!(
        read.objects.len(),
        6,
        "six faces named 'wall' stay six objects"
    );
    for (p, q) in read.polygons.iter().zip(&scene.polygons) {
        assert_eq!(p.two_sided, q.two_sided);
        let (m, n) = (read.material_of(p), scene.material_of(q));
        assert!(close(m.reflectance, n.reflectance, 1e-9));
        assert!(close(m.emission, n.emission, 1e-9));
    }
    assert!(close(read.emitted_power(), scene.emitted_power(), 1e-9));
}

#[test]
fn furnace_mgf_solves_to_e_over_one_minus_rho() {
    let dir = TempDir::new("furnace");
    let (rho, e) = (0.6, 2.0);
    let scene = generate(
        &dir.0,
        &["furnace", "--rho", "0.6", "--emission", "2", "--size", "1"],
    );
    let settings = SimulationSettings {
        eps: 1e-7,
        min_area: 1e-2,
        ..Default::default()
    };
    let solution = simulate(&scene, &settings, &Progress::new(true)).expect("solve");
    let h = &solution.hierarchy;
    let expected = e / (1.0 - rho);
    let leaves = h.leaves();
    assert!(leaves.len() > 100, "refined: {} leaves", leaves.len());
    for id in leaves {
        for c in h.average_radiance(id).to_array() {
            assert!(
                (c - expected).abs() / expected < 1e-3,
                "leaf radiance {c}, expected {expected}"
            );
        }
    }
}

#[test]
fn bad_parameters_are_clear_errors() {
    let dir = TempDir::new("errors");
    for (args, needle) in [
        (vec!["furnace", "--rho", "1.2"], "--rho"),
        (vec!["furnace", "--size", "1,x,2"], "--size"),
        (vec!["parallel-plates", "--distance=-1"], "--distance"),
        (
            vec!["shadow-groups", "--distance", "5"],
            "between the wall and the source",
        ),
        (vec!["shadow-groups", "--cube-sizes", "0.1,abc"], "abc"),
    ] {
        let out = Command::new(env!("CARGO_BIN_EXE_radiosity"))
            .arg("scene")
            .args(&args)
            .arg("-o")
            .arg(dir.0.join("x.mgf"))
            .output()
            .expect("run radiosity");
        assert!(!out.status.success(), "{args:?} should fail");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(needle), "{args:?}: {err}");
    }
}
