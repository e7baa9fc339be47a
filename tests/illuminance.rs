//! Illuminance at points off the surfaces (`measures::illuminance`) against analytic ground truth: a small
//! emitter (Howell's differential-element-to-rectangle factor and the inverse-square cosine law), the
//! white furnace (uniform radiance L gives π L from every direction), and a penumbra cast by an
//! occluder, where the exact answer is the emitter's factor minus that of its occluded part.

use radiosity::color::Rgb;
use radiosity::geometry::form_factor::point_to_polygon;
use radiosity::geometry::{DVec3, Shape};
use radiosity::hierarchy::clusters::ClusteringKind;
use radiosity::measures::illuminance::{GatherSettings, IrradianceGather};
use radiosity::pipeline::{simulate, SimulationSettings, Solution};
use radiosity::progress::Progress;
use radiosity::reference::PathTracer;
use radiosity::scene::{generators, Material, Object, Polygon, Scene};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;
use std::f64::consts::PI;

#[allow(dead_code)] // each test file uses part of the shared module
mod common;

/// A scene of axis-aligned squares `[x0, x1] × [y0, y1]` at height `z`, facing down (emitting or
/// reflecting towards -z) when `down`, each with its material.
fn squares(faces: &[([f64; 4], f64, bool, Material)]) -> Scene {
    let mut scene = Scene::default();
    for (k, &([x0, y0, x1, y1], z, down, ref material)) in faces.iter().enumerate() {
        let p = |x: f64, y: f64| DVec3::new(x, y, z);
        let up = [p(x0, y0), p(x1, y0), p(x1, y1), p(x0, y1)];
        let shape = if down {
            Shape::Quad([up[0], up[3], up[2], up[1]])
        } else {
            Shape::Quad(up)
        };
        scene.materials.push(material.clone());
        scene.objects.push(Object {
            name: format!("square{k}"),
        });
        scene.polygons.push(Polygon {
            shape,
            material: k,
            object: k,
            two_sided: false,
            under_contact: false,
        });
    }
    scene
}

fn solve(scene: &Scene) -> Solution {
    simulate(scene, &SimulationSettings::default(), &Progress::new(true)).expect("solve")
}

/// Howell's catalogue B-3: a differential element at height `c` below the corner of a parallel `a × b`
/// rectangle, facing it; odd in `a` and `b` so that offsets superpose with signs.
fn corner_factor(a: f64, b: f64, c: f64) -> f64 {
    let (x, y) = (a.abs() / c, b.abs() / c);
    let (sx, sy) = ((1.0 + x * x).sqrt(), (1.0 + y * y).sqrt());
    let f = (x / sx * (y / sx).atan() + y / sy * (x / sy).atan()) / (2.0 * PI);
    a.signum() * b.signum() * f
}

/// Factor from `(px, py, 0)` facing +z to the rectangle `[x0, x1] × [y0, y1]` at height `c`.
fn rectangle_factor(px: f64, py: f64, [x0, y0, x1, y1]: [f64; 4], c: f64) -> f64 {
    let g = |x: f64, y: f64| corner_factor(x - px, y - py, c);
    g(x1, y1) - g(x0, y1) - g(x1, y0) + g(x0, y0)
}

#[test]
fn a_small_emitter_gives_the_analytic_illuminance() {
    let le = 3.0;
    let side = 0.02;
    let rect = [-side / 2.0, -side / 2.0, side / 2.0, side / 2.0];
    let scene = squares(&[(
        rect,
        1.0,
        true,
        Material::emitter("lamp", Rgb::BLACK, Rgb::splat(le)),
    )]);
    let solution = solve(&scene);
    let gather = IrradianceGather::new(
        &solution.hierarchy,
        solution.visibility.as_ref(),
        GatherSettings::default(),
    );
    // Facing up, under and beside the lamp: Howell's closed form, exact up to rounding.
    for (px, py) in [(0.0, 0.0), (0.5, 0.0), (0.3, -0.7), (2.0, 1.0)] {
        let e = gather.at(DVec3::new(px, py, 0.0), DVec3::Z);
        let exact = PI * le * rectangle_factor(px, py, rect, 1.0);
        assert!(
            (e.irradiance.g - exact).abs() <= 1e-9 * exact,
            "({px}, {py}): {} vs {exact}",
            e.irradiance.g
        );
        // No shadow and no solver error; a piece too faint to matter (far beside the lamp) reports
        // its bound as its gather error, although its one ray gives the exact value too.
        assert!(e.solver_error <= 1e-9 * exact, "no solver error");
    }
    // Tilted normals at known distance and angle: the inverse-square cosine law L A cos θx cos θy / d²,
    // whose relative error for a source of size s at distance d is O((s/d)²) ≈ 4e-4 here: within 1%.
    for (x, normal) in [
        (DVec3::new(0.0, 0.0, 0.0), DVec3::new(1.0, 0.0, 1.0)),
        (DVec3::new(0.4, 0.2, 0.1), DVec3::new(-1.0, 0.5, 0.3)),
        (DVec3::new(-0.6, 0.0, 0.5), DVec3::new(1.0, 0.0, 0.0)),
    ] {
        let n = normal.normalize();
        let to_lamp = DVec3::new(0.0, 0.0, 1.0) - x;
        let d = to_lamp.length();
        let (cos_x, cos_y) = (n.dot(to_lamp) / d, to_lamp.z / d);
        let law = le * side * side * cos_x * cos_y / (d * d);
        let e = gather.at(x, n).irradiance.g;
        assert!((e - law).abs() <= 0.01 * law, "{x}: {e} vs {law}");
    }
}

#[test]
fn the_white_furnace_gives_pi_l_in_every_direction() {
    let (rho, le) = (0.5, 1.0);
    let scene = generators::furnace(DVec3::new(1.0, 2.0, 1.5), rho, le);
    // Refined to the minimum element size, as in tests/physics.rs, where every leaf is within 0.5% of
    // the exact L = E / (1 - ρ).
    let settings = SimulationSettings {
        eps: 1e-7,
        min_area: 1e-2,
        ..Default::default()
    };
    let mut solution = simulate(&scene, &settings, &Progress::new(true)).expect("solve");
    let exact = le / (1.0 - rho);
    let points = [
        DVec3::new(0.5, 1.0, 0.75),
        DVec3::new(0.1, 0.2, 0.3),
        DVec3::new(0.95, 1.9, 0.05),
    ];
    let directions = [
        DVec3::X,
        -DVec3::Y,
        DVec3::Z,
        DVec3::new(1.0, 1.0, 1.0),
        DVec3::new(-0.3, 0.8, -0.2),
    ];
    let check = |solution: &Solution, tolerance: f64| {
        let gather = IrradianceGather::new(
            &solution.hierarchy,
            solution.visibility.as_ref(),
            GatherSettings::default(),
        );
        for x in points {
            for d in directions {
                let e = gather.at(x, d.normalize());
                let allowed = tolerance * PI * exact + e.gather_error + 1e-9;
                assert!(
                    (e.irradiance.g - PI * exact).abs() <= allowed,
                    "{x} facing {d}: {} vs π L = {}, allowed {allowed}",
                    e.irradiance.g,
                    PI * exact
                );
            }
        }
    };
    // The solved radiance: within the leaves' 0.5% of π L, up to the gather's own error.
    check(&solution, 0.005);
    // The exact uniform radiance: the pieces' exact factors close the sphere, so π L up to rounding and
    // the gather's own error (pieces cut by the horizon between their nodes).
    for id in 0..solution.hierarchy.elements.len() as u32 {
        let coefficients = solution.hierarchy.radiance_mut(id);
        coefficients.iter_mut().for_each(|c| *c = Rgb::BLACK);
        coefficients[0] = Rgb::splat(exact);
    }
    check(&solution, 0.0);
}

/// Dim clusters and faint pieces, gathered from one or four random samples each, against the
/// furnace's exact answer: in a closed box full of small cubes where every surface emits L and reflects
/// nothing, every free point receives π L from any direction, whatever the cubes hide. Each sample
/// lies between 0 and its bound, so every point is within its gather error of π L, with the cluster
/// tree and without; the clusters' samples are unbiased, so the two gathers' differences average out
/// (their mean within four standard errors, an error model of the samples' own spread). Tolerance 1,
/// so that the cubes' clusters are dim from a metre or so.
#[test]
fn dim_clusters_sampled_from_few_rays_keep_a_furnace_full_of_cubes_exact() {
    let le = 1.0;
    let (per_axis, side) = (10, 0.06);
    let size = DVec3::splat(6.0);
    let scene = common::furnace_with_cubes_of(size, per_axis, side, 0.0, le);
    let mut rng = Pcg64Mcg::seed_from_u64(3);
    let mut points = Vec::new();
    while points.len() < 200 {
        let x = DVec3::new(rng.random(), rng.random(), rng.random()) * size;
        let cell = (x / size * per_axis as f64).floor() + DVec3::splat(0.5);
        if (x - cell * size / per_axis as f64).abs().max_element() < side {
            continue;
        }
        let v = DVec3::new(rng.random(), rng.random(), rng.random()) * 2.0 - DVec3::ONE;
        if v.length() > 0.1 && v.length() <= 1.0 {
            points.push((x, v.normalize()));
        }
    }
    // Each point's irradiance, and the pieces used over all points.
    let gathered = |clustering: ClusteringKind| {
        let settings = SimulationSettings {
            clustering,
            ..Default::default()
        };
        let solution = simulate(&scene, &settings, &common::quiet()).expect("solve");
        assert_eq!(
            solution.hierarchy.root_cluster.is_some(),
            clustering != ClusteringKind::None
        );
        let gather = IrradianceGather::new(
            &solution.hierarchy,
            solution.visibility.as_ref(),
            GatherSettings {
                tolerance: 1.0,
                seed: 7,
                ..Default::default()
            },
        );
        let mut clusters = 0;
        let values: Vec<f64> = points
            .iter()
            .map(|&(x, normal)| {
                let e = gather.at(x, normal);
                assert!(
                    (e.irradiance.g - PI * le).abs() <= e.gather_error + 1e-9,
                    "{clustering:?}, {x} facing {normal}: {} against π L, gather error {}",
                    e.irradiance.g,
                    e.gather_error
                );
                clusters += e.clusters;
                e.irradiance.g
            })
            .collect();
        (values, clusters)
    };
    let (whole, clusters) = gathered(ClusteringKind::Oriented);
    let (patches, _) = gathered(ClusteringKind::None);
    assert!(
        clusters >= 100 * points.len() as u32,
        "{clusters} clusters gathered whole at {} points",
        points.len()
    );
    let differences: Vec<f64> = whole.iter().zip(&patches).map(|(a, b)| a - b).collect();
    let n = differences.len() as f64;
    let mean = differences.iter().sum::<f64>() / n;
    let spread = (differences.iter().map(|d| (d - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    assert!(
        mean.abs() <= 4.0 * spread / n.sqrt(),
        "mean difference {mean} (spread {spread})"
    );
}

/// An emitter square [0, 1]² at z = 1 facing down, a black occluder square at z = 0.5 below part of it:
/// the points on z = 0 see the emitter minus the occluder's shadow-projection onto the emitter plane.
const EMITTER: [f64; 4] = [0.0, 0.0, 1.0, 1.0];
const OCCLUDER: [f64; 4] = [0.3, 0.2, 0.8, 0.6];

fn shadow_scene() -> Scene {
    squares(&[
        (
            EMITTER,
            1.0,
            true,
            Material::emitter("lamp", Rgb::BLACK, Rgb::splat(1.0)),
        ),
        (OCCLUDER, 0.5, false, Material::diffuse("black", Rgb::BLACK)),
        (OCCLUDER, 0.5, true, Material::diffuse("black", Rgb::BLACK)),
    ])
}

/// The exact irradiance at `(px, py, 0)` facing up: π L (F(emitter) − F(occluded part)), where the
/// occluded part is the occluder projected from the point onto the emitter plane (a rectangle, scaled
/// by 2 about the point), clipped to the emitter; both by Lambert's exact formula.
fn shadow_truth(px: f64, py: f64) -> f64 {
    let x = DVec3::new(px, py, 0.0);
    let quad = |[x0, y0, x1, y1]: [f64; 4]| {
        let p = |x: f64, y: f64| DVec3::new(x, y, 1.0);
        Shape::Quad([p(x0, y0), p(x0, y1), p(x1, y1), p(x1, y0)])
    };
    let scale = 2.0;
    let [ox0, oy0, ox1, oy1] = OCCLUDER;
    let shadow = [
        (px + scale * (ox0 - px)).max(EMITTER[0]),
        (py + scale * (oy0 - py)).max(EMITTER[1]),
        (px + scale * (ox1 - px)).min(EMITTER[2]),
        (py + scale * (oy1 - py)).min(EMITTER[3]),
    ];
    let blocked = if shadow[0] < shadow[2] && shadow[1] < shadow[3] {
        point_to_polygon(x, DVec3::Z, &quad(shadow))
    } else {
        0.0
    };
    PI * (point_to_polygon(x, DVec3::Z, &quad(EMITTER)) - blocked)
}

/// Points across the shadow and penumbra, on z = 0.
fn shadow_points() -> Vec<(f64, f64)> {
    (0..9)
        .flat_map(|i| (0..9).map(move |j| (0.05 + 0.11 * i as f64, 0.05 + 0.11 * j as f64)))
        .collect()
}

#[test]
fn in_a_penumbra_the_gather_converges_and_its_error_estimate_covers_the_error() {
    let scene = shadow_scene();
    let solution = solve(&scene);
    let visibility = solution.visibility.as_ref();
    let fine = IrradianceGather::new(&solution.hierarchy, visibility, GatherSettings::default());
    let coarse = IrradianceGather::new(
        &solution.hierarchy,
        visibility,
        GatherSettings {
            max_solid_angle: 0.3,
            tolerance: 0.05,
            max_depth: 1,
            cubature_degree: 1,
            seed: 0,
        },
    );
    let (mut fine_error, mut coarse_error) = (0.0, 0.0);
    let (mut fine_covered, mut coarse_covered) = (0, 0);
    let points = shadow_points();
    for &(px, py) in &points {
        let truth = shadow_truth(px, py);
        let x = DVec3::new(px, py, 0.0);
        let f = fine.at(x, DVec3::Z);
        let c = coarse.at(x, DVec3::Z);
        fine_error += (f.irradiance.g - truth).abs();
        coarse_error += (c.irradiance.g - truth).abs();
        fine_covered += usize::from((f.irradiance.g - truth).abs() <= f.error());
        coarse_covered += usize::from((c.irradiance.g - truth).abs() <= c.error());
    }
    assert!(
        fine_error < 0.25 * coarse_error,
        "refinement helps: {fine_error} vs {coarse_error}"
    );
    // The visibility term is two binomial standard deviations of the sampled visible fraction, a 95%
    // bound where sampling the fraction is the only error (the solution itself is exact here: nothing
    // reflects).
    for (name, covered) in [("fine", fine_covered), ("coarse", coarse_covered)] {
        assert!(
            covered as f64 >= 0.95 * points.len() as f64,
            "{name}: {covered} of {} points covered by the estimate",
            points.len()
        );
    }
}

#[test]
fn the_path_traced_irradiance_at_a_floating_point_is_unbiased() {
    let scene = shadow_scene();
    let solution = solve(&scene);
    let tracer = PathTracer::new(&scene, solution.visibility.as_ref(), 3);
    // Four standard errors: a 6e-5 chance per point for a normal batch mean.
    for (k, (px, py)) in [(0.5, 0.5), (0.15, 0.4), (0.9, 0.1)]
        .into_iter()
        .enumerate()
    {
        let e = tracer.irradiance_at(DVec3::new(px, py, 0.0), DVec3::Z, 4096, k as u64);
        let truth = shadow_truth(px, py);
        assert!(
            (e.mean.g - truth).abs() <= 4.0 * e.stderr.g + 1e-12,
            "({px}, {py}): {} ± {} vs {truth}",
            e.mean.g,
            e.stderr.g
        );
    }
}

fn radiosity(args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_radiosity"))
        .args(args)
        .output()
        .expect("run radiosity")
}

#[test]
fn grid_writes_csv_json_and_isolux_svg_and_never_overwrites_the_scene() {
    let dir = std::env::temp_dir().join(format!("radiosity-grid-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let scene = dir.join("cornell.mgf");
    let s = scene.to_str().unwrap();
    assert!(radiosity(&["scene", "cornell", "-o", s]).status.success());
    let before = std::fs::read(&scene).unwrap();
    let base = dir.join("floor");
    let fast = ["--eps", "0.05", "--plane", "y=100", "--spacing", "100"];
    let mut args = vec!["grid", s, "-o", base.to_str().unwrap()];
    args.extend(fast);
    let out = radiosity(&args);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let unlit_warning = "grid points get under 0.1% of the mean illuminance";
    assert!(!String::from_utf8_lossy(&out.stderr).contains(unlit_warning));
    let csv = std::fs::read_to_string(dir.join("floor.csv")).unwrap();
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("floor.json")).unwrap()).unwrap();
    let svg = std::fs::read_to_string(dir.join("floor.svg")).unwrap();
    let points = json["points"].as_array().unwrap();
    assert_eq!(csv.lines().count(), points.len() + 1);
    assert!(csv.starts_with("x,y,z,lux,error_lux,inside_solid\n"));
    // Points inside the blocks (closed, wound outward) are flagged and left out of the statistics:
    // exactly those that see only the blocks' black insides (zero lux, up to the gather's estimated
    // error); every other point of the lit room receives light.
    let inside = json["summary"]["points_inside_solids"].as_u64().unwrap();
    assert!(inside > 0);
    assert_eq!(
        json["summary"]["points"].as_u64().unwrap() + inside,
        points.len() as u64
    );
    for p in points {
        let (lux, error) = (p["lux"].as_f64().unwrap(), p["error_lux"].as_f64().unwrap());
        if p["inside_solid"].as_bool().unwrap() {
            assert!(lux <= error, "{p}");
        } else {
            assert!(lux > 0.0, "{p}");
        }
    }
    let (min, mean) = (
        json["summary"]["min_lux"].as_f64().unwrap(),
        json["summary"]["mean_lux"].as_f64().unwrap(),
    );
    assert!(min > 0.0 && mean > min);
    let uniformity = json["summary"]["uniformity_min_over_mean"]
        .as_f64()
        .unwrap();
    assert!((uniformity - min / mean).abs() < 1e-12);
    assert!(svg.contains("<svg") && svg.contains("illuminance (lux)"));
    // A grid reaching past the box's walls: the points outside get no light, and the user is told
    // that they pull the minimum and uniformity down.
    let wide = dir.join("wide");
    let mut args = vec!["grid", s, "-o", wide.to_str().unwrap()];
    args.extend(fast);
    args.extend(["--region", "-300,-300,850,850"]);
    let out = radiosity(&args);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success() && stderr.contains(unlit_warning),
        "{stderr}"
    );
    // An output that is the scene (through a link) is refused before any work; so is a bad plane.
    std::os::unix::fs::symlink(&scene, dir.join("link.csv")).unwrap();
    let link = dir.join("link");
    let mut args = vec!["grid", s, "-o", link.to_str().unwrap()];
    args.extend(fast);
    let out = radiosity(&args);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && stderr.contains("is an input"),
        "{stderr}"
    );
    assert_eq!(
        std::fs::read(&scene).unwrap(),
        before,
        "the scene is untouched"
    );
    let out = radiosity(&["grid", s, "--plane", "y=5000", "-o", base.to_str().unwrap()]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && stderr.contains("outside the scene"),
        "{stderr}"
    );
}

#[test]
fn photometric_units_scale_exr_and_probe_values_by_179_lm_per_w() {
    use radiosity::output::image::Image;
    let dir = std::env::temp_dir().join(format!("radiosity-units-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = |name: &str| dir.join(name).to_str().unwrap().to_string();
    let fast = ["-q", "--eps", "0.05", "--width", "12", "--height", "10"];
    for (units, exr) in [("radiometric", "w.exr"), ("photometric", "cd.exr")] {
        let mut args = vec!["render", "--units", units, "--hdr"];
        let (exr, png) = (file(exr), file(&format!("{units}.png")));
        args.extend([exr.as_str(), "-o", png.as_str()]);
        args.extend(fast);
        let out = radiosity(&args);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    let w = Image::read_linear(std::path::Path::new(&file("w.exr"))).unwrap();
    let cd = Image::read_linear(std::path::Path::new(&file("cd.exr"))).unwrap();
    for (a, b) in w.pixels.iter().zip(&cd.pixels) {
        for (x, y) in a.to_array().into_iter().zip(b.to_array()) {
            // EXR stores 32-bit floats: relative rounding 2^-24 on each value.
            assert!(
                (179.0 * x - y).abs() <= 1e-6 * y.abs().max(1e-30),
                "{x} {y}"
            );
        }
    }
    let out = radiosity(&[
        "probe",
        "-q",
        "--eps",
        "0.05",
        "--random",
        "4",
        "--units",
        "photometric",
        "--json",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let rows: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    for row in rows.as_array().unwrap() {
        let c = &row["probe"]["radiosity"];
        let radiance = Rgb::new(
            c["r"].as_f64().unwrap(),
            c["g"].as_f64().unwrap(),
            c["b"].as_f64().unwrap(),
        );
        let luminance = row["photometric"]["luminance"].as_f64().unwrap();
        assert!((luminance - 179.0 * radiance.luminance()).abs() <= 1e-9 * luminance);
        assert!(row["photometric"]["illuminance"].as_f64().unwrap() > 0.0);
    }
}

/// Which work-plane points lie inside solids, against the geometry by construction: a 4 × 3 × 3 room
/// (walls facing in), a closed cabinet standing on the floor (1 × 1 × 1.2 at x, y in [0.5, 1.5], faces
/// wound outward, no bottom face, as furniture usually has), and a desk top (a single quad facing up,
/// 0.7 high over x in [2.5, 3.5], y in [1, 2]). On the plane z = 0.5 exactly the points over the
/// cabinet's footprint are inside; those under the desk and in the open are not.
#[test]
fn points_inside_furniture_are_found_and_points_under_desks_are_not() {
    use radiosity::measures::illuminance::inside_solid;
    let mut polygons: Vec<Shape> = generators::box_faces(DVec3::new(4.0, 3.0, 3.0)).to_vec();
    let cabinet = generators::box_faces(DVec3::new(1.0, 1.0, 1.2));
    // box_faces are wound inward, in the order -x, +x, -y, +y, -z, +z: flip them, drop the bottom.
    for (k, face) in cabinet.iter().enumerate() {
        if k != 4 {
            let moved = face
                .vertices()
                .iter()
                .map(|v| *v + DVec3::new(0.5, 0.5, 0.0));
            let v: Vec<DVec3> = moved.collect();
            polygons.push(Shape::Quad([v[0], v[3], v[2], v[1]]));
        }
    }
    let p = |x: f64, y: f64| DVec3::new(x, y, 0.7);
    polygons.push(Shape::Quad([
        p(2.5, 1.0),
        p(3.5, 1.0),
        p(3.5, 2.0),
        p(2.5, 2.0),
    ]));
    let visibility = radiosity::visibility::bvh::Bvh::new(&polygons);
    for i in 0..40 {
        for j in 0..30 {
            let (x, y) = (0.05 + 0.1 * f64::from(i), 0.05 + 0.1 * f64::from(j));
            let expected = (0.5..1.5).contains(&x) && (0.5..1.5).contains(&y);
            assert_eq!(
                inside_solid(&visibility, DVec3::new(x, y, 0.5), DVec3::Z),
                expected,
                "({x}, {y})"
            );
        }
    }
}

/// The unit plate 0.5 under a parallel emitting square of radiance 2 with black reflectance, its own
/// reflectance 0.6, solved on coarse elements (at least a tenth of the plate): the scene and solution
/// of the final-gather tests.
fn coarse_lit_plate() -> (Scene, Solution) {
    let scene = generators::parallel_plates(1.0, 0.5, 0.6, 2.0);
    let settings = SimulationSettings {
        min_area: 0.1,
        ..Default::default()
    };
    let solution = simulate(&scene, &settings, &Progress::new(true)).expect("solve");
    (scene, solution)
}

/// A 12 × 12 view of [`coarse_lit_plate`]'s plate from between the plates, looking down.
fn plate_camera() -> radiosity::output::camera::Camera {
    let spec = radiosity::scene::CameraSpec {
        eye: DVec3::new(0.5, 0.5, 0.4),
        look_at: DVec3::new(0.5, 0.5, 0.0),
        up: DVec3::Y,
        fov_degrees: 100.0,
    };
    radiosity::output::camera::Camera::new(&spec, 12, 12)
}

/// The exact radiance at `(x, y, 0)` on [`coarse_lit_plate`]'s plate: `ρ L_e F(x)`, Howell's factor.
fn lit_plate_radiance(x: f64, y: f64) -> f64 {
    0.6 * 2.0 * rectangle_factor(x, y, [0.0, 0.0, 1.0, 1.0], 0.5)
}

/// A final gather at probed points (`probe --final-gather`) against Howell's analytic factor: a plate
/// lit by a parallel emitting square of the same size (the emitter black, so the plate's radiance is
/// exactly `ρ L_e F(x)`), solved on coarse elements (at least a tenth of the plate) whose linear
/// expansion cannot follow the factor's fall toward the plate's edges and corner. The gather reads the
/// emitter's constant radiance with its exact piece factors and no occluder, so its value is exact up
/// to rounding, and its error estimate (the solver's error propagated plus the gather's own) covers
/// the rest, while the leaf values at the same points miss by several percent.
#[test]
fn a_final_gather_gives_the_analytic_radiance_where_coarse_elements_do_not() {
    use radiosity::measures::illuminance::{final_gather, probe_gather_points};
    use radiosity::reference::probe::{parse_points, probe_points};
    let (scene, solution) = coarse_lit_plate();
    let xy = [
        (0.5, 0.5),
        (0.02, 0.5),
        (0.02, 0.02),
        (0.3, 0.9),
        (0.98, 0.1),
    ];
    let text: String = xy
        .iter()
        .map(|(x, y)| format!("{x} {y} 0 0 0 1\n"))
        .collect();
    let file = std::path::Path::new("plate.csv");
    let points = parse_points(&text, file).expect("points");
    let visibility = solution.visibility.as_ref();
    let mut results = probe_points(&scene, visibility, &solution.hierarchy, &points, None, file)
        .expect("on the plate");
    let exact: Vec<f64> = xy.iter().map(|&(x, y)| lit_plate_radiance(x, y)).collect();
    let leaf_worst = results
        .iter()
        .zip(&exact)
        .map(|(r, &e)| (r.radiosity.g - e).abs() / e)
        .fold(0.0, f64::max);
    assert!(leaf_worst > 0.03, "the coarse leaves miss by {leaf_worst}");
    let gather = IrradianceGather::new(&solution.hierarchy, visibility, GatherSettings::default());
    let irradiance = gather.at_all(&probe_gather_points(&results));
    final_gather(&solution.hierarchy, &mut results, &irradiance);
    for ((r, &e), (x, y)) in results.iter().zip(&exact).zip(xy) {
        let error = (r.radiosity.g - e).abs();
        assert!(error <= 1e-9 * e, "({x}, {y}): {} vs {e}", r.radiosity.g);
        assert!(error <= r.estimated_error + 1e-12, "({x}, {y}): estimate");
        assert_eq!(
            (r.radiosity.r, r.radiosity.b),
            (r.radiosity.g, r.radiosity.g)
        );
    }
}

/// `render --final-gather`: each pixel of a view of the coarsely solved plate above (from between the
/// plates, looking down) is the analytic `ρ L_e F(x)` at the point its centre ray meets, as the
/// probe's final gather gives, on one thread and on three alike; without it the leaves' values.
#[test]
fn a_final_gather_render_shows_the_analytic_radiance_at_every_pixel() {
    use radiosity::output::render::{render, RenderOptions, Shading};
    let (_, solution) = coarse_lit_plate();
    let camera = plate_camera();
    let visibility = solution.visibility.as_ref();
    let options = RenderOptions {
        shading: Shading::Basis,
        final_gather: Some(GatherSettings::default()),
        ..Default::default()
    };
    let on_threads = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("pool")
            .install(|| render(&solution.hierarchy, visibility, &camera, &options))
    };
    let image = on_threads(1);
    assert_eq!(image, on_threads(3));
    let leaves = render(
        &solution.hierarchy,
        visibility,
        &camera,
        &RenderOptions {
            final_gather: None,
            ..options
        },
    );
    let mut leaf_worst = 0.0f64;
    for y in 0..12 {
        for x in 0..12 {
            let ray = camera.ray(x as f64 + 0.5, y as f64 + 0.5);
            let t = -ray.origin.z / ray.direction.z;
            let p = ray.origin + ray.direction * t;
            let exact = lit_plate_radiance(p.x, p.y);
            let got = image.get(x, y).g;
            assert!(
                (got - exact).abs() <= 1e-9 * exact,
                "({x}, {y}): {got} vs {exact}"
            );
            leaf_worst = leaf_worst.max((leaves.get(x, y).g - exact).abs() / exact);
        }
    }
    assert!(leaf_worst > 0.03, "the coarse leaves miss by {leaf_worst}");
}

/// The irradiance cache's second pass: where no pixel centre's record reaches a pixel corner (radii
/// of 0.1 pixel footprint, which this wide view overestimates at most 3.4× at its edges, against the
/// corner's 0.71 pixel to the nearest centre), the corner gets a record of its own, so at every
/// corner, where adaptive antialiasing samples first, the cached render shows the gather's exact
/// value (Howell's analytic `ρ L_e F` on [`coarse_lit_plate`]), while the coarse leaves' shading
/// there is off by several percent; halfway between two corners on a pixel's edge, which no record
/// reaches, the shading stays as it is.
#[test]
fn every_pixel_corner_is_a_record_or_reached_by_one() {
    use radiosity::measures::irradiance_cache::CacheSettings;
    use radiosity::output::render::{radiance_as_rendered, RenderOptions, Shading};
    let (_, solution) = coarse_lit_plate();
    let camera = plate_camera();
    let visibility = solution.visibility.as_ref();
    let h = &solution.hierarchy;
    let plate = h
        .patches
        .iter()
        .position(|patch| patch.normal.z > 0.5)
        .expect("the lit plate faces up") as u32;
    let on_plate = |x: f64, y: f64| {
        let ray = camera.ray(x, y);
        let t = -ray.origin.z / ray.direction.z;
        ray.origin + ray.direction * t
    };
    let corners: Vec<(u32, DVec3)> = (0..=12)
        .flat_map(|y| (0..=12).map(move |x| (x, y)))
        .map(|(x, y)| (plate, on_plate(x as f64, y as f64)))
        .collect();
    let edge_midpoints: Vec<(u32, DVec3)> = (0..12)
        .flat_map(|y| (0..12).map(move |x| (x, y)))
        .map(|(x, y)| (plate, on_plate(x as f64 + 0.5, y as f64)))
        .collect();
    let options = |cache: Option<CacheSettings>| RenderOptions {
        shading: Shading::Basis,
        final_gather: Some(GatherSettings::default()),
        gather_cache: cache,
        ..Default::default()
    };
    let small_radii = options(Some(CacheSettings {
        accuracy: 1e-9,
        min_pixels: 0.1,
        max_pixels: 0.1,
        ..CacheSettings::default()
    }));
    let shading = |points: &[(u32, DVec3)]| {
        let leaves = RenderOptions {
            final_gather: None,
            ..options(None)
        };
        radiance_as_rendered(h, visibility, &camera, &leaves, points).0
    };
    let (at_corners, report) = radiance_as_rendered(h, visibility, &camera, &small_radii, &corners);
    assert_eq!(report.gather_records, 144 + 13 * 13);
    let mut shading_worst = 0.0f64;
    for ((_, p), (got, leaf)) in corners.iter().zip(at_corners.iter().zip(shading(&corners))) {
        let exact = lit_plate_radiance(p.x, p.y);
        assert!(
            (got.g - exact).abs() <= 1e-9 * exact,
            "{p}: {} vs {exact}",
            got.g
        );
        shading_worst = shading_worst.max((leaf.g - exact).abs() / exact);
    }
    assert!(
        shading_worst > 0.03,
        "the coarse leaves miss by {shading_worst}"
    );
    let (at_midpoints, _) =
        radiance_as_rendered(h, visibility, &camera, &small_radii, &edge_midpoints);
    assert_eq!(at_midpoints, shading(&edge_midpoints));
}

/// `render --final-gather` with its irradiance cache (`measures::irradiance_cache`) on the coarsely
/// solved plate of [`coarse_lit_plate`], against Howell's analytic radiance at the pixel centres:
/// * with a record at every pixel centre and radii too small to reach another (spp 1, so each sample is
///   a record's own point), every pixel is the gather's exact value: the cache adds nothing of its own;
/// * with the default records, each pixel is its shading plus a weighted mean of records' corrections
///   `L_gather − L_shade`, exact at the records: its correction lies between the least and the largest
///   correction at any pixel centre, and the image is nearer the analytic radiance than the leaves'
///   (RMS), since the corrections it spreads are exact and vary no faster than the leaves' error;
/// * one thread and three give the same image.
#[test]
fn a_cached_final_gather_interpolates_exact_corrections_between_records() {
    use radiosity::measures::irradiance_cache::CacheSettings;
    use radiosity::output::render::{render, render_reporting, RenderOptions, Shading};
    let (_, solution) = coarse_lit_plate();
    let camera = plate_camera();
    let visibility = solution.visibility.as_ref();
    let h = &solution.hierarchy;
    let cached = RenderOptions {
        shading: Shading::Basis,
        final_gather: Some(GatherSettings::default()),
        gather_cache: Some(CacheSettings::default()),
        ..Default::default()
    };
    let leaves = render(
        h,
        visibility,
        &camera,
        &RenderOptions {
            final_gather: None,
            gather_cache: None,
            ..cached
        },
    );
    let exact = |x: usize, y: usize| {
        let ray = camera.ray(x as f64 + 0.5, y as f64 + 0.5);
        let t = -ray.origin.z / ray.direction.z;
        let p = ray.origin + ray.direction * t;
        lit_plate_radiance(p.x, p.y)
    };
    let pixels = || (0..12).flat_map(|y| (0..12).map(move |x| (x, y)));

    let dense = RenderOptions {
        gather_cache: Some(CacheSettings {
            accuracy: 1e-9,
            min_pixels: 1e-3,
            max_pixels: 1e-3,
            ..CacheSettings::default()
        }),
        ..cached
    };
    let (image, report) = render_reporting(h, visibility, &camera, &dense, None);
    // A record at every pixel centre, and one at every pixel corner, since none reaches another.
    assert_eq!(report.gather_records, 144 + 13 * 13);
    for (x, y) in pixels() {
        let (got, want) = (image.get(x, y).g, exact(x, y));
        assert!(
            (got - want).abs() <= 1e-9 * want,
            "({x}, {y}): {got} vs {want}"
        );
    }

    let on_threads = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("pool")
            .install(|| render_reporting(h, visibility, &camera, &cached, None))
    };
    let (image, report) = on_threads(1);
    assert_eq!((image.clone(), report), on_threads(3));
    assert!(
        (1..144).contains(&report.gather_records),
        "{} records",
        report.gather_records
    );
    let corrections: Vec<f64> = pixels()
        .map(|(x, y)| exact(x, y) - leaves.get(x, y).g)
        .collect();
    let low = corrections.iter().copied().fold(f64::INFINITY, f64::min);
    let high = corrections
        .iter()
        .copied()
        .fold(f64::NEG_INFINITY, f64::max);
    let (mut cached_squares, mut leaf_squares) = (0.0, 0.0);
    for (x, y) in pixels() {
        let (got, want, leaf) = (image.get(x, y).g, exact(x, y), leaves.get(x, y).g);
        let slack = 1e-9 * want;
        assert!(
            (low - slack..=high + slack).contains(&(got - leaf)),
            "({x}, {y}): correction {} outside [{low}, {high}]",
            got - leaf
        );
        cached_squares += ((got - want) / want).powi(2);
        leaf_squares += ((leaf - want) / want).powi(2);
    }
    assert!(
        cached_squares < leaf_squares,
        "cached RMS {} against the leaves' {}",
        (cached_squares / 144.0).sqrt(),
        (leaf_squares / 144.0).sqrt()
    );
}
