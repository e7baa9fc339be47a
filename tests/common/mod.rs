//! Scenes and measures shared by the test suites (each uses part of it).

use radiosity::geometry::{DVec3, Shape};
use radiosity::hierarchy::Hierarchy;
use radiosity::progress::Progress;
use radiosity::scene::{generators, Material, Object, Polygon, Scene};

/// Proptest settings with `cases` cases whose failures are saved next to the test's source file
/// (`tests/NAME.proptest-regressions`) and replayed first on every run. Proptest's default looks for a
/// `lib.rs` or `main.rs` above the source file, which integration tests do not have: it then warns
/// and neither saves nor replays anything.
pub fn proptest_config(cases: u32) -> proptest::test_runner::Config {
    proptest::test_runner::Config {
        failure_persistence: Some(Box::new(
            proptest::test_runner::FileFailurePersistence::WithSource("proptest-regressions"),
        )),
        ..proptest::test_runner::Config::with_cases(cases)
    }
}

pub fn quiet() -> Progress {
    Progress::new(true)
}

/// Runs `work` on a pool of `threads` threads (results must not depend on the count).
pub fn with_threads<T: Send>(threads: usize, work: impl FnOnce() -> T + Send) -> T {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("thread pool")
        .install(work)
}

/// A closed furnace (all surfaces reflect ρ and emit E) holding a grid of small cubes.
pub fn furnace_with_cubes(per_axis: usize, rho: f64, e: f64) -> Scene {
    furnace_with_cubes_of(DVec3::new(2.0, 1.5, 1.8), per_axis, 0.12, rho, e)
}

/// A furnace of `size` holding `per_axis³` cubes of side `side`, one at the centre of each cell of a
/// regular grid.
pub fn furnace_with_cubes_of(size: DVec3, per_axis: usize, side: f64, rho: f64, e: f64) -> Scene {
    let mut scene = generators::furnace(size, rho, e);
    for i in 0..per_axis {
        for j in 0..per_axis {
            for k in 0..per_axis {
                let cell = DVec3::new(i as f64, j as f64, k as f64) + DVec3::splat(0.5);
                let corner = cell * size / per_axis as f64 - DVec3::splat(side / 2.0);
                for f in generators::box_faces(DVec3::splat(side)) {
                    let v = f.vertices();
                    scene.polygons.push(Polygon {
                        // Reversed: the cube's faces look outward.
                        shape: Shape::Quad([
                            v[3] + corner,
                            v[2] + corner,
                            v[1] + corner,
                            v[0] + corner,
                        ]),
                        material: 0,
                        object: 0,
                        two_sided: false,
                        under_contact: false,
                    });
                }
            }
        }
    }
    scene
}

/// Area-weighted mean radiance (green) of the patches `which` selects.
pub fn mean_radiance_of(h: &Hierarchy, which: impl Fn(usize) -> bool) -> f64 {
    let (mut sum, mut area) = (0.0, 0.0);
    for (k, p) in h.patches.iter().enumerate() {
        if !which(k) {
            continue;
        }
        let e = h.element(p.root);
        sum += e.area * h.average_radiance(p.root).g;
        area += e.area;
    }
    sum / area
}

/// The axis-aligned rectangle `[x0, x1] × [y0, y1]` in the plane `z`, facing `+z` if `up`, else `−z`.
pub fn rectangle([x0, x1, y0, y1]: [f64; 4], z: f64, up: bool) -> Shape {
    let p = |x, y| DVec3::new(x, y, z);
    if up {
        Shape::Quad([p(x0, y0), p(x1, y0), p(x1, y1), p(x0, y1)])
    } else {
        Shape::Quad([p(x0, y0), p(x0, y1), p(x1, y1), p(x1, y0)])
    }
}

/// A scene of one polygon per material: polygon `k` is `shapes[k]`, of material `k` and its own
/// object, two-sided where `two_sided(k)`.
pub fn one_polygon_per_material(
    materials: Vec<Material>,
    shapes: impl IntoIterator<Item = Shape>,
    two_sided: impl Fn(usize) -> bool,
) -> Scene {
    let mut scene = Scene {
        materials,
        ..Default::default()
    };
    for (material, shape) in shapes.into_iter().enumerate() {
        scene.objects.push(Object {
            name: scene.materials[material].name.clone(),
        });
        scene.polygons.push(Polygon {
            shape,
            material,
            object: material,
            two_sided: two_sided(material),
            under_contact: false,
        });
    }
    scene
}

/// The exact factor from `emitter` to `receiver` (facing `+z`), averaged over an `n × n` grid of
/// the receiver: the point-to-polygon factor at each cell centre.
pub fn mean_factor_up(receiver: &Shape, emitter: &Shape, n: usize) -> f64 {
    (0..n * n)
        .map(|i| {
            let uv = radiosity::geometry::DVec2::new((i % n) as f64 + 0.5, (i / n) as f64 + 0.5)
                / n as f64;
            radiosity::geometry::form_factor::point_to_polygon(
                receiver.point_at(uv),
                DVec3::Z,
                emitter,
            )
        })
        .sum::<f64>()
        / (n * n) as f64
}

/// Two parallel unit plates a unit apart (receiver polygon 0, emitter polygon 1, `generators::
/// parallel_plates`) and a black two-sided strip 1 cm under the emitter that hides its first 30% along
/// `x` from every point of the receiver: a shadow boundary across the source, at the same place for
/// every receiver.
pub fn emitter_hidden_by_a_near_strip(reflectance: f64, emission: f64) -> Scene {
    let mut scene = generators::parallel_plates(1.0, 1.0, reflectance, emission);
    let material = scene.materials.len();
    scene
        .materials
        .push(Material::diffuse("blocker", radiosity::color::Rgb::BLACK));
    let z = 0.99;
    scene.polygons.push(Polygon {
        shape: Shape::Quad([
            DVec3::new(-0.1, -0.1, z),
            DVec3::new(-0.1, 1.1, z),
            DVec3::new(0.3, 1.1, z),
            DVec3::new(0.3, -0.1, z),
        ]),
        material,
        object: 0,
        two_sided: true,
        under_contact: false,
    });
    scene
}

/// The probes of `text` (one `x y z nx ny nz` a line) on `solution` of `scene`, each with a
/// path-traced reference of `spp` paths from `seed`.
pub fn probe_with_reference(
    scene: &Scene,
    solution: &radiosity::pipeline::Solution,
    text: &str,
    spp: usize,
    seed: u64,
) -> Vec<radiosity::reference::probe::ProbeResult> {
    use radiosity::reference::probe::{parse_points, probe_points, ProbeReference};
    let file = std::path::Path::new("points.txt");
    let points = parse_points(text, file).expect("valid points");
    probe_points(
        scene,
        solution.visibility.as_ref(),
        &solution.hierarchy,
        &points,
        Some(ProbeReference { spp, seed }),
        file,
    )
    .expect("points on surfaces")
}

/// A 2×2 RGB PNG.
pub fn png(pixels: [[u8; 3]; 4]) -> Vec<u8> {
    let image = image::RgbImage::from_fn(2, 2, |x, y| image::Rgb(pixels[(2 * y + x) as usize]));
    let mut bytes = Vec::new();
    image
        .write_to(
            &mut std::io::Cursor::new(&mut bytes),
            image::ImageFormat::Png,
        )
        .unwrap();
    bytes
}

/// The linear value of an 8-bit sRGB-encoded channel.
pub fn srgb_to_linear(v: u8) -> f64 {
    let c = v as f64 / 255.0;
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}
