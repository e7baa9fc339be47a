//! IES luminaires: the LM-63 reader on RenderPark's example and on malformed files, placement, and the
//! goniometric first gather against ground truth (inverse-square cosine law, flux balance, the path
//! tracer).

use glam::DAffine3;
use radiosity::color::Rgb;
use radiosity::geometry::{DVec3, Shape};
use radiosity::pipeline::{simulate, SimulationSettings};
use radiosity::progress::Progress;
use radiosity::reference::PathTracer;
use radiosity::scene::ies::{load, parse, Photometry, Symmetry};
use radiosity::scene::luminaire::{Luminaire, Placement};
use radiosity::scene::mgf::WHITE_EFFICACY;
use radiosity::scene::{Material, Polygon, Scene};
use std::f64::consts::PI;
use std::path::Path;
use std::sync::Arc;

/// RenderPark's example luminaire, in the shared scenes beside the repository.
const EXAMPLE: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../shared/scenes/renderpark/examp1.ies"
);

fn table(header: &str, numbers: &str) -> std::result::Result<Photometry, String> {
    parse(
        Path::new("t.ies"),
        &format!("{header}\nTILT=NONE\n{numbers}\n"),
    )
    .map_err(|e| e.to_string())
}

/// An isotropic 1000 cd source: flux 4π × 1000 lm, every direction 1000 cd.
#[test]
fn isotropic_table_integrates_to_four_pi_i() {
    let p = table(
        "IESNA:LM-63-2002",
        "1 -1 1 3 1 1 2 0 0 0\n1 1 100\n0 90 180\n0\n1000 1000 1000",
    )
    .unwrap();
    assert_eq!(p.symmetry, Symmetry::Rotational);
    assert!((p.flux() - 4.0 * PI * 1000.0).abs() < 1e-9 * p.flux());
    assert_eq!(p.intensity(37.0, 211.0), 1000.0);
    assert_eq!(p.rated_lumens(), None);
}

/// A cosine table (Lambertian downlight, I = I0 cos θ on 0–90°) sampled every 1°: flux π I0 up to
/// the chord error of linear interpolation of cos, O(h²) ≈ 1e-4.
#[test]
fn cosine_table_integrates_to_pi_i0() {
    let angles: Vec<String> = (0..=90).map(|a| a.to_string()).collect();
    let values: Vec<String> = (0..=90)
        .map(|a| (500.0 * f64::from(a).to_radians().cos()).to_string())
        .collect();
    let p = table(
        "IESNA:LM-63-1995",
        &format!(
            "1 1571 1 91 1 1 2 0 0 0 1 1 10 {} 0 {}",
            angles.join(" "),
            values.join(" ")
        ),
    )
    .unwrap();
    assert!((p.flux() / (PI * 500.0) - 1.0).abs() < 1e-4, "{}", p.flux());
    assert!(p.warnings.is_empty());
    assert_eq!(p.intensity(120.0, 0.0), 0.0);
}

/// RenderPark's examp1.ies: IESNA95, 73 vertical (0–180° every 2.5°) × 5 horizontal angles (0–90°,
/// quadrant symmetry), two 2900 lm lamps, all multipliers 1, a 0.85 × 4.04 × 0.292 ft opening.
#[test]
fn reads_renderparks_example() {
    let p = load(Path::new(EXAMPLE)).unwrap();
    assert_eq!(p.version, "IESNA95");
    assert_eq!((p.vertical.len(), p.horizontal.len()), (73, 5));
    assert_eq!(p.symmetry, Symmetry::Quadrant);
    assert!(p
        .keywords
        .iter()
        .any(|(k, v)| k == "LUMINOUSGEOMETRY" && v == "examp1.mgf"));
    assert_eq!((p.multiplier, p.lamps, p.input_watts), (1.0, 2.0, 63.7));
    assert!((p.opening.width - 0.85 * 0.3048).abs() < 1e-12);
    assert!((p.opening.length - 4.04 * 0.3048).abs() < 1e-12);
    assert!((p.opening.height - 0.292 * 0.3048).abs() < 1e-12);
    // Table values: nadir 778.4 cd; θ = 2.5° in the 45° plane 777.1; zenith in the 90° plane 801.4.
    assert!((p.intensity(0.0, 0.0) - 778.4).abs() < 1e-9);
    assert!((p.intensity(2.5, 45.0) - 777.1).abs() < 1e-9);
    assert!((p.intensity(180.0, 90.0) - 801.4).abs() < 1e-9);
    // Symmetry: the 135°, 225° and 315° planes mirror the 45° plane.
    for phi in [135.0, 225.0, 315.0, -45.0] {
        assert!((p.intensity(60.0, phi) - p.intensity(60.0, 45.0)).abs() < 1e-9);
    }
    // Midway between table angles the value is the mean of its neighbours.
    let mid = p.intensity(1.25, 11.25);
    let corners = [(0.0, 0.0), (2.5, 0.0), (0.0, 22.5), (2.5, 22.5)];
    let mean = corners.iter().map(|&(t, f)| p.intensity(t, f)).sum::<f64>() / 4.0;
    assert!((mid - mean).abs() < 1e-9);
    // A luminaire emits less than its lamps: 0 < flux < 2 × 2900.
    let rated = p.rated_lumens().unwrap();
    assert_eq!(rated, 5800.0);
    assert!(
        p.flux() > 0.3 * rated && p.flux() < rated,
        "{} of {rated}",
        p.flux()
    );
    assert!(p.warnings.is_empty());
}

/// Quadrant, half and full tables describing the same distribution integrate to the same flux.
#[test]
fn symmetric_tables_agree() {
    // I(θ, φ) = (1 + |cos φ|) g(θ): tabulated on 0..90, 0..180 and 0..360 every 45°.
    let g = [100.0, 50.0, 0.0];
    let make = |phis: &[f64]| {
        let cols: Vec<String> = phis
            .iter()
            .map(|p| {
                let f = 1.0 + p.to_radians().cos().abs();
                g.iter()
                    .map(|v| (v * f).to_string())
                    .collect::<Vec<_>>()
                    .join(" ")
            })
            .collect();
        let angles: Vec<String> = phis.iter().map(|p| p.to_string()).collect();
        table(
            "IESNA:LM-63-2002",
            &format!(
                "1 -1 1 3 {} 1 2 0 0 0 1 1 10 0 45 90 {} {}",
                phis.len(),
                angles.join(" "),
                cols.join(" ")
            ),
        )
        .unwrap()
    };
    let quadrant = make(&[0.0, 45.0, 90.0]);
    let half = make(&[0.0, 45.0, 90.0, 135.0, 180.0]);
    let full = make(&[0.0, 45.0, 90.0, 135.0, 180.0, 225.0, 270.0, 315.0]);
    assert_eq!(quadrant.symmetry, Symmetry::Quadrant);
    assert_eq!(half.symmetry, Symmetry::Bilateral);
    assert_eq!(full.symmetry, Symmetry::Full);
    for p in [&half, &full] {
        assert!((p.flux() - quadrant.flux()).abs() < 1e-9 * quadrant.flux());
        for (t, f) in [(10.0, 10.0), (30.0, 200.0), (80.0, 300.0), (45.0, 170.0)] {
            assert!((p.intensity(t, f) - quadrant.intensity(t, f)).abs() < 1e-9);
        }
    }
}

#[test]
fn malformed_files_are_one_line_errors() {
    let cases = [
        ("IESNA:LM-63-2002\n[TEST] x\n1 1 1", "no TILT= line"),
        (
            "IESNA:LM-63-2002\nTILT=INCLUDE\n1 1",
            ":2: TILT=INCLUDE is not supported",
        ),
        (
            "IESNA91\nTILT=lamp.tlt\n",
            ":2: TILT=lamp.tlt is not supported",
        ),
        (
            "IESNA:LM-63-2002\nTILT=NONE\n1 1000 1 3 1 2 2 0 0 0",
            ":3: type B photometry",
        ),
        (
            "IESNA:LM-63-2002\nTILT=NONE\n1 1000 1 3 1 1 7 0 0 0",
            ":3: units type",
        ),
        (
            "IESNA:LM-63-2002\nTILT=NONE\n1 1000 1 0 1 1 2 0 0 0",
            ":3: number of vertical angles",
        ),
        (
            "IESNA:LM-63-2002\nTILT=NONE\n1 1000 1 99999 1 1 2",
            ":3: number of vertical angles",
        ),
        (
            "IESNA:LM-63-2002\nTILT=NONE\n1 1000 1 3.5 1 1 2",
            ":3: number of vertical angles",
        ),
        (
            "IESNA:LM-63-2002\nTILT=NONE\n1 x 1",
            ":3: lumens per lamp: 'x' is not a finite number",
        ),
        (
            "IESNA:LM-63-2002\nTILT=NONE\n1 nan 1",
            ":3: lumens per lamp",
        ),
        (
            "IESNA:LM-63-2002\nTILT=NONE\n1 1000 1 2 1 1 2 0 0 0\n1 1 10\n0 90\n0\n5",
            ":7: file ends before the candela value",
        ),
        (
            "IESNA:LM-63-2002\nTILT=NONE\n1 1000 1 2 1 1 2 0 0 0\n1 1 10\n0 90\n0\n5 -1",
            ":7: negative candela",
        ),
        (
            "IESNA:LM-63-2002\nTILT=NONE\n1 1000 1 2 1 1 2 0 0 0\n1 1 10\n90 0\n0\n5 1",
            ":5: vertical angles must increase",
        ),
        (
            "IESNA:LM-63-2002\nTILT=NONE\n1 1000 1 2 1 1 2 0 0 0\n1 1 10\n0 200\n0\n5 1",
            "within 0..180",
        ),
        (
            "IESNA:LM-63-2002\nTILT=NONE\n1 1000 1 2 2 1 2 0 0 0\n1 1 10\n0 90\n0 45\n5 1 5 1",
            "horizontal angles 0..45",
        ),
        (
            "IESNA:LM-63-2002\nTILT=NONE\n1 1000 -2 2 1 1 2 0 0 0\n1 1 10\n0 90\n0\n5 1",
            "multipliers must be non-negative",
        ),
        (
            "IESNA:LM-63-2002\nTILT=NONE\n1 1000 1 1001 1000 1 2 0 0 0\n1 1 10\n",
            "more than 1000000",
        ),
    ];
    for (text, expected) in cases {
        let e = parse(Path::new("bad.ies"), text).unwrap_err().to_string();
        assert!(e.contains(expected), "{e:?} should contain {expected:?}");
        assert!(e.starts_with("bad.ies:"), "{e}");
        assert_eq!(e.lines().count(), 1, "{e}");
    }
}

/// A table whose integral exceeds the rated lumens gets a warning (an efficiency above 1).
#[test]
fn flux_above_the_rated_lumens_warns() {
    let p = table(
        "IESNA:LM-63-2002",
        "1 100 1 2 1 1 2 0 0 0 1 1 10 0 90 0 1000 1000",
    )
    .unwrap();
    assert_eq!(p.warnings.len(), 1, "{:?}", p.warnings);
    assert!(p.warnings[0].message.contains("rated"));
}

fn photometry_of(width: f64, length: f64) -> Arc<Photometry> {
    // I(θ) = 1000 cd on 0–90° in the 0° plane, 0 in the 90° plane (0..90 table, linear in φ).
    let text = format!(
        "IESNA:LM-63-2002\nTILT=NONE\n1 -1 1 2 2 1 2 {width} {length} 0\n1 1 10\n0 90\n0 90\n\
             1000 1000 0 0\n"
    );
    Arc::new(parse(Path::new("t.ies"), &text).unwrap())
}

/// Aimed down, the 0° plane along +x: a point below and along +x sees the 0° plane's value; a
/// quarter turn about z moves that plane onto +y.
#[test]
fn frame_maps_the_planes() {
    let lum = Luminaire::place(photometry_of(0.0, 0.0), DAffine3::IDENTITY, Rgb::WHITE, 1.0);
    let per_cd = 1.0 / WHITE_EFFICACY;
    assert!((lum.intensity(DVec3::new(1.0, 0.0, -1.0)).r - 1000.0 * per_cd).abs() < 1e-9);
    assert!(lum.intensity(DVec3::new(0.0, 1.0, -1.0)).r.abs() < 1e-9);
    assert!(lum.intensity(DVec3::new(0.0, 0.0, 1.0)).is_black());
    let turned = Luminaire::place(
        photometry_of(0.0, 0.0),
        DAffine3::from_rotation_z(PI / 2.0),
        Rgb::WHITE,
        2.0,
    );
    assert!((turned.intensity(DVec3::new(0.0, 1.0, -1.0)).r - 2000.0 * per_cd).abs() < 1e-9);
    assert!((turned.power().r - 2.0 * lum.power().r).abs() < 1e-9);
}

/// Aimed along +x with a quarter spin, the nadir looks along +x and the 0° plane contains ±z.
#[test]
fn placements_parse_and_aim() {
    let p: Placement = "d@r/a.ies@1,2,3@1,0,0@90".parse().unwrap();
    assert_eq!(p.file, std::path::PathBuf::from("d@r/a.ies"));
    assert_eq!(p.position, DVec3::new(1.0, 2.0, 3.0));
    let t = p.transform();
    assert!((t.matrix3.z_axis - DVec3::NEG_X).length() < 1e-12);
    assert!(t.matrix3.x_axis.z.abs() > 1.0 - 1e-12);
    assert!((t.matrix3.determinant() - 1.0).abs() < 1e-12);
    let down: Placement = "l.ies@0,0,2".parse().unwrap();
    assert_eq!(down.transform().matrix3, glam::DMat3::IDENTITY);
    for bad in [
        "l.ies",
        "l.ies@1,2",
        "l.ies@1,2,x",
        "l.ies@1,2,3@0,0,0",
        "l.ies@1,2,3@0,0,1@s",
        "l.ies@1,2,3@0,0,1@4@5",
        "l.ies@inf,0,0",
    ] {
        assert!(bad.parse::<Placement>().is_err(), "{bad}");
    }
}

/// The opening is the file's length × width × height box (metres) centred on the position and carried by
/// the transform (here scaled by 2): six outward faces whose projected area along each axis is the
/// matching cross-section; a zero height makes it one flat rectangle, a round one an elliptic prism, and
/// no area a point.
#[test]
fn the_opening_is_the_files_box() {
    let t = DAffine3::from_scale_rotation_translation(
        DVec3::splat(2.0),
        glam::DQuat::IDENTITY,
        DVec3::new(0.0, 0.0, 3.0),
    );
    let with = |w: f64, l: f64, h: f64| {
        let text = format!(
            "IESNA:LM-63-2002\nTILT=NONE\n1 -1 1 2 1 1 2 {w} {l} {h}\n1 1 10\n0 180\n0\n100 100\n"
        );
        Luminaire::place(
            Arc::new(parse(Path::new("t.ies"), &text).unwrap()),
            t,
            Rgb::WHITE,
            1.0,
        )
    };
    let solid = with(0.5, 1.0, 0.25);
    assert_eq!(solid.faces.len(), 6);
    assert!(!solid.flat);
    // Length 2, width 1, height 0.5 after scaling.
    for (axis, area) in [(DVec3::Z, 2.0), (DVec3::X, 0.5), (DVec3::Y, 1.0)] {
        assert!((solid.projected_area(axis) - area).abs() < 1e-12);
        assert!((solid.projected_area(-axis) - area).abs() < 1e-12);
    }
    for f in &solid.faces {
        assert!(f.normal().dot(f.centroid() - solid.position) > 0.0);
    }
    let flat = with(0.5, 1.0, 0.0);
    assert_eq!(flat.faces.len(), 1);
    assert!(flat.flat);
    assert!((flat.projected_area(DVec3::new(0.6, 0.0, 0.8)) - 1.6).abs() < 1e-12);
    assert!((flat.projected_area(DVec3::new(0.6, 0.0, -0.8)) - 1.6).abs() < 1e-12);
    // Round (negative width): the 16-gon prism's top and bottom areas equal the polygon's.
    let round = with(-0.5, -1.0, 0.25);
    let n = radiosity::scene::luminaire::ROUND_SEGMENTS as f64;
    let polygon_area = 0.5 * n * (2.0 * PI / n).sin() * 1.0 * 0.5;
    assert!((round.projected_area(DVec3::Z) - polygon_area).abs() < 1e-12);
    assert!(with(0.0, 0.0, 0.0).faces.is_empty());
}

/// Near the opening the light leaves its whole surface (the midpoint rule over the faces a point sees);
/// far away it is the photometric law from the centre. The two agree where the model switches (16
/// opening sizes away) to the surface model's own difference from a point source there, O((size /
/// distance)²) = 1/256, plus the midpoint rule's few 1e-3: within 1%.
#[test]
fn the_opening_surface_meets_the_photometric_law() {
    let table = photometry(
        &[0.0, 90.0],
        &[
            [1000.0, 950.0, 800.0, 500.0, 200.0, 50.0, 0.0, 0.0, 0.0, 0.0],
            [1000.0, 800.0, 400.0, 250.0, 100.0, 25.0, 0.0, 0.0, 0.0, 0.0],
        ],
        0.4,
    );
    let text = |h: f64| {
        format!(
            "IESNA:LM-63-2002\nTILT=NONE\n1 -1 1 10 2 1 2 0.3 0.4 {h}\n1 1 10\n{}\n0 90\n{}\n",
            (0..10)
                .map(|k| (10 * k).to_string())
                .collect::<Vec<_>>()
                .join(" "),
            table
                .candela
                .iter()
                .map(|v| v.to_string())
                .collect::<Vec<_>>()
                .join(" ")
        )
    };
    for height in [0.0, 0.2] {
        let p = Arc::new(parse(Path::new("box.ies"), &text(height)).unwrap());
        let placement: Placement = "x.ies@0,0,0@0.2,0.1,-1@25".parse().unwrap();
        let lum = Luminaire::place(p, placement.transform(), Rgb::WHITE, 1.0);
        let size = lum.size();
        for dir in [
            DVec3::new(0.0, 0.0, -1.0),
            DVec3::new(0.3, -0.2, -1.0),
            DVec3::new(-0.5, 0.4, -0.7),
        ] {
            let dir = dir.normalize();
            let near = dir * (16.0 * size * (1.0 - 1e-9));
            let far = dir * (16.0 * size);
            let facing = -dir;
            let e_near = lum.irradiance(near, facing, |_, _| 1.0).r;
            let e_far = lum.irradiance(far, facing, |_, _| 1.0).r
                * (far.length_squared() / near.length_squared());
            assert!(
                (e_near / e_far - 1.0).abs() < 0.01,
                "height {height}, {dir:?}: near {e_near} vs far {e_far}"
            );
        }
    }
}

/// A table of intensities (cd) on vertical angles 0..90 every 10°, for the horizontal angles given
/// (one column each, all equal at the nadir, which is one direction), with a square opening of `size`
/// metres.
fn photometry(horizontal: &[f64], columns: &[[f64; 10]], size: f64) -> Arc<Photometry> {
    let vertical: Vec<String> = (0..10).map(|k| (10 * k).to_string()).collect();
    let h: Vec<String> = horizontal.iter().map(|a| a.to_string()).collect();
    let values: Vec<String> = columns.iter().flatten().map(|v| v.to_string()).collect();
    let text = format!(
        "IESNA:LM-63-2002\nTILT=NONE\n1 -1 1 10 {} 1 2 {size} {size} 0\n1 1 10\n{}\n{}\n{}\n",
        horizontal.len(),
        vertical.join(" "),
        h.join(" "),
        values.join(" ")
    );
    Arc::new(parse(Path::new("table.ies"), &text).unwrap())
}

/// A point-like (size 0) table with a 0° and a 90° plane, tabulated every 10° down to 50°.
fn directional_point_source() -> Arc<Photometry> {
    photometry(
        &[0.0, 90.0],
        &[
            [1000.0, 950.0, 800.0, 500.0, 200.0, 50.0, 0.0, 0.0, 0.0, 0.0],
            [1000.0, 800.0, 400.0, 250.0, 100.0, 25.0, 0.0, 0.0, 0.0, 0.0],
        ],
        0.0,
    )
}

fn quad(a: DVec3, b: DVec3, c: DVec3, d: DVec3) -> Shape {
    Shape::Quad([a, b, c, d])
}

/// A square floor of half-size `half` at z = 0 facing +z, reflectance `rho`, with `luminaire`.
fn floor_scene(half: f64, rho: f64, luminaire: Luminaire) -> Scene {
    let p = DVec3::new;
    let polygons = vec![Polygon {
        shape: quad(
            p(-half, -half, 0.0),
            p(half, -half, 0.0),
            p(half, half, 0.0),
            p(-half, half, 0.0),
        ),
        material: 0,
        object: 0,
        two_sided: false,
        under_contact: false,
    }];
    let mut scene = Scene {
        polygons,
        materials: vec![Material::diffuse("floor", Rgb::splat(rho))],
        objects: vec![radiosity::scene::Object {
            name: "floor".into(),
        }],
        ..Default::default()
    };
    scene.add_luminaire(luminaire);
    scene
}

/// The solution's radiance at a point of the floor (patch 0).
fn floor_radiance(solution: &radiosity::pipeline::Solution, x: f64, y: f64) -> Rgb {
    let h = &solution.hierarchy;
    let point = DVec3::new(x, y, 0.0);
    h.radiance_at(h.locate(0, point), point)
}

fn temp_dir(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("radiosity-ies-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn quiet() -> Progress {
    Progress::new(true)
}

/// Illuminance under a point-like luminaire at height 2 m over a floor that cannot see itself (no
/// interreflection): E = I(θ, φ) cos θ / d², so the floor's radiance is ρ/π × E / 179 per channel.
/// Error model: linear elements refined until the projected direct term misses its cubature nodes by
/// at most eps × Φ/π per element (eps = 1e-6 makes elements near the luminaire a few cm wide, where the
/// linear fit of E is within 0.1%); the issue asks for 1%.
#[test]
fn illuminance_follows_the_inverse_square_cosine_law() {
    let isotropic = photometry(&[0.0], &[[1000.0; 10]], 0.0);
    let directional = directional_point_source();
    let height = 2.0;
    let rho = 0.5;
    let settings = SimulationSettings {
        basis: radiosity::bases::BasisKind::Linear,
        eps: 1e-6,
        min_area: 1e-7,
        ..Default::default()
    };
    let t = |deg: f64| height * f64::to_radians(deg).tan();
    // (x, y, expected intensity in cd): table values, or the linear interpolation between them.
    let cases = [
        (
            &isotropic,
            vec![(0.0, 0.0, 1000.0), (1.0, 0.5, 1000.0), (-3.0, 2.0, 1000.0)],
        ),
        (
            &directional,
            vec![
                (0.0, 0.0, 1000.0),
                (t(20.0), 0.0, 800.0),
                (-t(35.0), 0.0, 350.0),
                (0.0, t(20.0), 400.0),
                (0.0, -t(35.0), 175.0),
                (t(20.0) / 2f64.sqrt(), t(20.0) / 2f64.sqrt(), 600.0),
            ],
        ),
    ];
    for (table, points) in cases {
        let luminaire = Luminaire::place(
            Arc::clone(table),
            DAffine3::from_translation(DVec3::new(0.0, 0.0, height)),
            Rgb::WHITE,
            1.0,
        );
        let scene = floor_scene(10.0, rho, luminaire);
        let solution = simulate(&scene, &settings, &quiet()).unwrap();
        for (x, y, intensity) in points {
            let d2 = x * x + y * y + height * height;
            let cos = height / d2.sqrt();
            let expected = rho / PI * intensity / WHITE_EFFICACY * cos / d2;
            let got = floor_radiance(&solution, x, y).r;
            assert!(
                (got / expected - 1.0).abs() < 0.01,
                "at ({x}, {y}): {got} vs {expected} ({} elements)",
                solution.hierarchy.leaf_count()
            );
        }
    }
}

/// An MGF file of a closed black 4 × 3 × 3 m room (one-sided walls facing in) followed by `entity`.
fn black_room(name: &str, entity: &str) -> std::path::PathBuf {
    let dir = temp_dir(name);
    let room = dir.join("room.mgf");
    let faces = radiosity::scene::generators::box_faces(DVec3::new(4.0, 3.0, 3.0));
    let mut text = String::from("m black =\n\tsides 1\n");
    for (k, face) in faces.iter().enumerate() {
        for (j, v) in face.vertices().iter().enumerate() {
            text += &format!("v v{k}{j} =\n\tp {} {} {}\n", v.x, v.y, v.z);
        }
        text += &format!("f v{k}0 v{k}1 v{k}2 v{k}3\n");
    }
    text += entity;
    text += "\n";
    std::fs::write(&room, text).unwrap();
    room
}

/// LM-63's lumens field with relative photometry (lumens > 0): the lamps' rated flux, which the table's
/// ∫ I dΩ equals times the luminaire's efficiency (−1 marks absolute photometry, with no rating). A
/// table written with efficiency 1: 100 cd in every direction (0–180°, one plane), so ∫ I dΩ = 400π lm
/// exactly (linear interpolation of a constant), from two lamps of 200π lm, with a candela multiplier
/// of 1.5 and MGF's `ies -m 2`. Its flux is lamps × lumens × multipliers up to the file's rounding (no
/// warning), the room absorbs that flux / 179 W per channel (cubature error well under 1%, as for
/// examp1 below), and a file claiming 10% fewer lumens warns of an efficiency above 1.
#[test]
fn a_consistent_table_emits_its_rated_lumens() {
    let dir = temp_dir("rated");
    let write = |name: &str, lumens: f64| {
        let path = dir.join(name);
        std::fs::write(
            &path,
            format!(
                "IESNA:LM-63-2002\nTILT=NONE\n2 {lumens:.4} 1.5 3 1 1 2 0.3 0.3 0.1\n1 1 20\n0 90 180\n0\n\
                 100 100 100\n"
            ),
        )
        .unwrap();
        path
    };
    let consistent = write("consistent.ies", 200.0 * PI);
    let p = load(&consistent).unwrap();
    assert!(p.warnings.is_empty(), "{:?}", p.warnings);
    let rated = p.rated_lumens().unwrap();
    assert!((rated - 2.0 * 200.0 * PI * 1.5).abs() < 1e-3);
    assert!((p.flux() - rated).abs() <= p.flux_precision);
    let room = black_room(
        "rated-room",
        &format!("ies {} -m 2 -t 2 1.5 2", consistent.display()),
    );
    let scene = radiosity::scene::load(&room, &Default::default()).unwrap();
    let summary = radiosity::scene::summary(&scene);
    assert_eq!(summary.rated_lumens, Some(2.0 * rated));
    assert!(
        summary.to_string().contains("efficiency 100.0%"),
        "{summary}"
    );
    let settings = SimulationSettings {
        eps: 1e-4,
        ..Default::default()
    };
    let solution = simulate(&scene, &settings, &quiet()).unwrap();
    let expected = 2.0 * rated / WHITE_EFFICACY;
    let absorbed = solution.report.absorbed_power.g;
    assert!(
        (absorbed / expected - 1.0).abs() < 0.01,
        "{absorbed} vs {expected}"
    );
    let overrated = load(&write("overrated.ies", 0.9 * 200.0 * PI)).unwrap();
    assert_eq!(overrated.warnings.len(), 1);
    assert!(overrated.warnings[0].message.contains("efficiency above 1"));
}

/// Flux balance: RenderPark's examp1.ies (up- and downlight) placed by MGF's `ies` entity with `-m 2`
/// in a closed black room: the power absorbed by the walls equals 2 × ∫ I dΩ / 179 W per channel, up
/// to the cubature error of ∫ E dA (elements refined until the direct term's projection residual is
/// below eps = 1e-4 of the emission per element; well under 1% in total).
#[test]
fn a_black_room_absorbs_the_luminaires_flux() {
    let room = black_room("room", &format!("ies {EXAMPLE} -m 2 -rz 30 -t 2 1.5 1.5"));
    let scene = radiosity::scene::load(&room, &Default::default()).unwrap();
    assert_eq!(scene.luminaires.len(), 1);
    assert!(scene.warnings.iter().any(|w| w
        .message
        .contains("fixture geometry 'examp1.mgf' not loaded")));
    let flux = load(Path::new(EXAMPLE)).unwrap().flux();
    let expected = 2.0 * flux / WHITE_EFFICACY;
    assert!((scene.emitted_power().r / expected - 1.0).abs() < 1e-12);
    let settings = SimulationSettings {
        eps: 1e-4,
        ..Default::default()
    };
    let solution = simulate(&scene, &settings, &quiet()).unwrap();
    let absorbed = solution.report.absorbed_power;
    assert!(
        (absorbed.r / expected - 1.0).abs() < 0.01 && (absorbed.b / expected - 1.0).abs() < 0.01,
        "{absorbed:?} vs {expected}"
    );
}

/// MGF `ies` with a transform array places one luminaire per instance; a broken IES file is an error
/// naming both the MGF line and the IES file's line.
#[test]
fn mgf_ies_entities_place_arrays_and_report_errors() {
    let dir = temp_dir("entities");
    let good = dir.join("good.mgf");
    std::fs::write(
        &good,
        format!("# two rows\nies {EXAMPLE} -t 1 2 3 -a 3 -t 2 0 0\n"),
    )
    .unwrap();
    let scene = radiosity::scene::load(&good, &Default::default()).unwrap();
    let positions: Vec<DVec3> = scene.luminaires.iter().map(|l| l.position).collect();
    assert_eq!(
        positions,
        [1.0, 3.0, 5.0].map(|x| DVec3::new(x, 2.0, 3.0)).to_vec()
    );
    std::fs::write(dir.join("bad.ies"), "IESNA:LM-63-2002\nTILT=INCLUDE\n").unwrap();
    let bad = dir.join("bad.mgf");
    std::fs::write(&bad, "\n\nies bad.ies\n").unwrap();
    let e = radiosity::scene::load(&bad, &Default::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("bad.mgf:3:") && e.contains("bad.ies:2: TILT=INCLUDE"),
        "{e}"
    );
    assert_eq!(e.lines().count(), 1);
}

/// The path tracer (next-event estimation toward uniform points of the opening) agrees with the
/// solver's first gather (a grid of opening points, projected on linear elements) under a tilted,
/// spun directional luminaire with a 0.4 m opening 1.5 m above the floor (near field: the opening is a
/// quarter of the distance): within 4 standard errors of the path tracer (a false alarm once in 16000
/// per point) plus 0.5% for the solver's opening grid (midpoint rule, a few 1e-3) and projection.
/// The floor alone cannot see itself, so both see only the luminaire's light.
#[test]
fn the_path_tracer_agrees_with_the_solver() {
    let placement: Placement = "unused.ies@0,0,1.5@0.3,0,-1@15".parse().unwrap();
    let table = photometry(
        &[0.0, 90.0],
        &[
            [1000.0, 950.0, 800.0, 500.0, 200.0, 50.0, 0.0, 0.0, 0.0, 0.0],
            [1000.0, 800.0, 400.0, 250.0, 100.0, 25.0, 0.0, 0.0, 0.0, 0.0],
        ],
        0.4,
    );
    let luminaire = Luminaire::place(table, placement.transform(), Rgb::WHITE, 1.0);
    let scene = floor_scene(3.0, 0.6, luminaire);
    let settings = SimulationSettings {
        basis: radiosity::bases::BasisKind::Linear,
        eps: 1e-5,
        ..Default::default()
    };
    let solution = simulate(&scene, &settings, &quiet()).unwrap();
    let tracer = PathTracer::new(&scene, solution.visibility.as_ref(), 3);
    for (k, (x, y)) in [(0.0, 0.0), (0.2, 0.3), (1.0, -0.5), (-1.0, 1.0)]
        .into_iter()
        .enumerate()
    {
        let point = DVec3::new(x, y, 0.0);
        let reference = tracer.radiance_leaving(point, DVec3::Z, 0, true, 4096, k as u64 + 1);
        let solver = floor_radiance(&solution, x, y);
        let tolerance = 4.0 * reference.stderr.r + 0.005 * reference.mean.r;
        assert!(
            (solver.r - reference.mean.r).abs() < tolerance,
            "at ({x}, {y}): solver {} vs path tracer {} ± {}",
            solver.r,
            reference.mean.r,
            reference.stderr.r
        );
    }
}

/// `--luminaire` adds a luminaire to any scene (here the built-in Cornell box) and `info` reports its
/// flux from the table next to the lamps' rating; a bad placement is an error naming the bad part.
#[test]
fn the_command_line_places_luminaires() {
    let run = |args: &[&str]| {
        std::process::Command::new(env!("CARGO_BIN_EXE_radiosity"))
            .args(args)
            .output()
            .expect("run radiosity")
    };
    let placement = format!("{EXAMPLE}@278,500,278@0,-1,0");
    let out = run(&["info", "--luminaire", &placement]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    let flux = load(Path::new(EXAMPLE)).unwrap().flux();
    let line = format!(
        "luminaires:    1 ({flux:.1} lm from the tables; lamps rated 5800.0 lm, efficiency {:.1}%)",
        100.0 * flux / 5800.0
    );
    assert!(stdout.contains(&line), "{stdout}");
    let out = run(&["info", "--luminaire", "missing.ies@1,2"]);
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    let first = stderr.lines().next().unwrap_or_default();
    assert!(
        first.contains("'1,2' is not three finite numbers"),
        "{stderr}"
    );
}

/// The lux grid's gather adds the luminaires' direct light: on a floating work plane 1.15 m under a
/// point-like directional luminaire, over a black floor (nothing else lights the plane), the
/// illuminance is I(θ, φ) cos θ / d² lux, the inverse-square cosine law in photometric units. Error
/// model: the opening is a point (size 0), so the law is exact up to the table's linear interpolation,
/// which the expected intensities reproduce; 1e-9 covers rounding.
#[test]
fn the_lux_grid_sees_the_luminaires() {
    use radiosity::measures::illuminance::{GatherSettings, IrradianceGather};
    let directional = directional_point_source();
    let height = 2.0;
    let plane = 0.85;
    let luminaire = Luminaire::place(
        directional,
        DAffine3::from_translation(DVec3::new(0.0, 0.0, height)),
        Rgb::WHITE,
        1.0,
    );
    let scene = floor_scene(10.0, 0.0, luminaire);
    let solution = simulate(&scene, &SimulationSettings::default(), &quiet()).unwrap();
    let gather = IrradianceGather::new(
        &solution.hierarchy,
        solution.visibility.as_ref(),
        GatherSettings::default(),
    );
    let drop = height - plane;
    let t = |deg: f64| drop * f64::to_radians(deg).tan();
    for (x, y, intensity) in [
        (0.0, 0.0, 1000.0),
        (t(20.0), 0.0, 800.0),
        (0.0, -t(35.0), 175.0),
    ] {
        let d2 = x * x + y * y + drop * drop;
        let expected = intensity * (drop / d2.sqrt()) / d2;
        let got = gather.at(DVec3::new(x, y, plane), DVec3::Z).lux();
        assert!(
            (got / expected - 1.0).abs() < 1e-9,
            "at ({x}, {y}): {got} lux vs {expected}"
        );
    }
}

/// A box luminaire (0.6 × 0.3 × 0.2 m, spun 30°) seen from three sides, its centre in the middle pixel:
/// both renderers show I(ω) / A_proj(ω) there, with A_proj(ω) = |ω_z| L W + |ω_x| W H + |ω_y| L H in
/// the luminaire frame, and the emitter mask covers it. The path tracer adds a camera ray's
/// emission exactly, so both are exact up to rounding.
#[test]
fn the_opening_is_drawn_at_its_luminance() {
    use radiosity::output::camera::Camera;
    use radiosity::output::render::{emitter_mask, render, RenderOptions};
    use radiosity::reference::{PixelFilter, ReferenceSettings};
    let (length, width, height) = (0.6, 0.3, 0.2);
    let vertical: Vec<String> = (0..=18).map(|k| (10 * k).to_string()).collect();
    // Up and down light, varying with θ: I = 1000 + 600 cos θ (cd).
    let values: Vec<String> = (0..=18)
        .map(|k| (1000.0 + 600.0 * f64::from(10 * k).to_radians().cos()).to_string())
        .collect();
    let text = format!(
        "IESNA:LM-63-2002\nTILT=NONE\n1 -1 1 19 1 1 2 {width} {length} {height}\n1 1 10\n{}\n0\n{}\n",
        vertical.join(" "),
        values.join(" ")
    );
    let table = Arc::new(parse(Path::new("box.ies"), &text).unwrap());
    let placement: Placement = "box.ies@0,0,1@0,0,-1@30".parse().unwrap();
    let luminaire = Luminaire::place(Arc::clone(&table), placement.transform(), Rgb::WHITE, 1.0);
    let frame = luminaire.frame;
    let scene = floor_scene(3.0, 0.5, luminaire);
    let settings = SimulationSettings {
        eps: 1e-3,
        ..Default::default()
    };
    let solution = simulate(&scene, &settings, &quiet()).unwrap();
    let tracer = PathTracer::new(&scene, solution.visibility.as_ref(), 3);
    let centre = DVec3::new(0.0, 0.0, 1.0);
    for eye in [
        DVec3::new(2.0, 0.5, 1.8),
        DVec3::new(-1.5, 1.2, 0.4),
        DVec3::new(0.3, -2.0, 1.0),
    ] {
        let spec = radiosity::scene::CameraSpec {
            eye,
            look_at: centre,
            up: DVec3::Z,
            fov_degrees: 5.0,
        };
        let camera = Camera::new(&spec, 9, 9);
        let image = render(
            &solution.hierarchy,
            solution.visibility.as_ref(),
            &camera,
            &RenderOptions::default(),
        );
        let reference = tracer.render(
            &camera,
            &ReferenceSettings {
                spp: 16,
                filter: PixelFilter::Centre,
                ..Default::default()
            },
            &quiet(),
        );
        let w = (eye - centre).normalize();
        let local = DVec3::new(w.dot(frame[0]), w.dot(frame[1]), w.dot(frame[2]));
        let a_proj = local.z.abs() * length * width
            + local.x.abs() * width * height
            + local.y.abs() * length * height;
        let theta = (-local.z).acos().to_degrees();
        let expected = table.intensity(theta, 0.0) / WHITE_EFFICACY / a_proj;
        let drawn = image.pixels[4 * 9 + 4].r;
        let traced = reference.mean.pixels[4 * 9 + 4].r;
        assert!(
            (drawn / expected - 1.0).abs() < 1e-9,
            "{eye}: {drawn} vs {expected}"
        );
        assert!(
            (traced / expected - 1.0).abs() < 1e-9,
            "{eye}: {traced} vs {expected}"
        );
        let mask = emitter_mask(&solution.hierarchy, solution.visibility.as_ref(), &camera);
        assert!(mask.get(4, 4));
    }
    // The viewer page draws the opening too, each face at its luminance along its normal: the bottom
    // face (z = 1 − H/2, seen from the nadir, θ = 0) at I(0) / (L W), the top one (θ = 180°) at
    // I(180°) / (L W); f32 vertex data, hence 1e-6.
    let mesh = radiosity::output::viewer::ViewerMesh::new(
        &solution.hierarchy,
        radiosity::output::render::Shading::Flat,
        None,
        usize::MAX,
    )
    .unwrap();
    for (z, theta) in [(1.0 - height / 2.0, 0.0), (1.0 + height / 2.0, 180.0)] {
        let expected = table.intensity(theta, 0.0) / WHITE_EFFICACY / (length * width);
        let shown: Vec<f64> = mesh
            .positions
            .iter()
            .zip(mesh.vertex_radiance())
            .filter(|(p, _)| (f64::from(p[2]) + mesh.origin.z - z).abs() < 1e-6)
            .map(|(_, c)| c.r)
            .collect();
        assert!(
            shown.len() >= 4
                && shown
                    .iter()
                    .filter(|&&r| (r / expected - 1.0).abs() < 1e-6)
                    .count()
                    == 4,
            "face at z = {z}: {shown:?}, expected four at {expected}"
        );
    }
}

/// Path tracer and solver agree on an image with a luminaire in view: a 0.5 × 0.4 × 0.25 m box of a
/// directional table 1 m over a floor (ρ 0.6, which cannot see itself, so only the luminaire lights
/// it), a black plate between them casting a shadow in both renderers, seen obliquely at 32 × 24.
/// Opening pixels are the same to rounding. Over the lit floor pixels the relative RMS difference d
/// (Σ (solver − reference)² / Σ reference²) is the path tracer's noise n (Σ σ² / Σ reference², σ its
/// per-pixel standard error) plus the solver's own error: d² < 1.5 n² + (2%)², the 1.5 for the
/// spread of the noise estimate itself (a few hundred pixels, the brightest few dozen dominating),
/// 2% for the solver's near-field midpoint rule (a few 1e-3), the linear projection of the table's
/// kinks and the plate's penumbra. Forgetting cos θ_y on the faces or the opening's occlusion moves d
/// by well over 2%.
#[test]
fn path_tracer_and_solver_agree_on_an_image_with_the_luminaire() {
    use radiosity::output::camera::Camera;
    use radiosity::output::render::{render, RenderOptions, Shading};
    use radiosity::reference::{PixelFilter, ReferenceSettings};
    let table = directional_box();
    let placement: Placement = "box.ies@0,0,1@0,0,-1@20".parse().unwrap();
    let luminaire = Luminaire::place(table, placement.transform(), Rgb::WHITE, 1.0);
    let mut scene = floor_scene(3.0, 0.6, luminaire);
    let p = DVec3::new;
    scene.materials.push(Material::diffuse("plate", Rgb::BLACK));
    scene.polygons.push(Polygon {
        shape: quad(
            p(0.3, -0.2, 0.5),
            p(0.7, -0.2, 0.5),
            p(0.7, 0.2, 0.5),
            p(0.3, 0.2, 0.5),
        ),
        material: 1,
        object: 0,
        two_sided: true,
        under_contact: false,
    });
    let settings = SimulationSettings {
        basis: radiosity::bases::BasisKind::Linear,
        eps: 1e-5,
        ..Default::default()
    };
    let solution = simulate(&scene, &settings, &quiet()).unwrap();
    let spec = radiosity::scene::CameraSpec {
        eye: p(2.6, -2.2, 2.0),
        look_at: p(0.0, 0.0, 0.4),
        up: DVec3::Z,
        fov_degrees: 45.0,
    };
    let camera = Camera::new(&spec, 32, 24);
    let image = render(
        &solution.hierarchy,
        solution.visibility.as_ref(),
        &camera,
        &RenderOptions {
            shading: Shading::Basis,
            ..Default::default()
        },
    );
    let tracer = PathTracer::new(&scene, solution.visibility.as_ref(), 3);
    let reference = tracer.render(
        &camera,
        &ReferenceSettings {
            spp: 256,
            filter: PixelFilter::Centre,
            ..Default::default()
        },
        &quiet(),
    );
    let (mut openings, mut lit) = (0, 0);
    let (mut difference, mut signal, mut noise) = (0.0, 0.0, 0.0);
    for y in 0..camera.height {
        for x in 0..camera.width {
            let ray = camera.ray(x as f64 + 0.5, y as f64 + 0.5);
            let hit = solution.visibility.intersect(&ray, 0.0, f64::INFINITY);
            let k = y * camera.width + x;
            let (s, r, sigma) = (
                image.pixels[k].r,
                reference.mean.pixels[k].r,
                reference.stderr.pixels[k].r,
            );
            if hit.is_some_and(|h| solution.hierarchy.opening_at(h.polygon).is_some()) {
                openings += 1;
                assert!(
                    (s - r).abs() <= 1e-9 * r,
                    "opening pixel ({x}, {y}): {s} vs {r}"
                );
            } else if r > 0.0 {
                lit += 1;
                difference += (s - r) * (s - r);
                signal += r * r;
                noise += sigma * sigma;
            }
        }
    }
    assert!(
        openings >= 4,
        "the luminaire is in view ({openings} pixels)"
    );
    assert!(lit > 300, "{lit} lit pixels");
    let (d2, n2) = (difference / signal, noise / signal);
    assert!(
        d2 < 1.5 * n2 + 0.02f64.powi(2),
        "relative RMS difference {} against noise {} over {lit} pixels",
        d2.sqrt(),
        n2.sqrt()
    );
}

/// Hierarchical Monte Carlo radiosity lights from luminaires too (their deterministic first gather is
/// the first iteration's unshot light): in a closed 4 × 3 × 3 m room of uniform reflectance ρ = 0.5
/// around a point-like luminaire (a box opening would absorb the light that comes back to it, about its
/// share of the area), every watt is reflected ρ + ρ² + ... times, so the exitant power is
/// Φ ρ/(1 − ρ) and the absorbed power Φ. Errors: the first gather's cubature (well under 1%, as in the
/// black rooms) and the unshot power left when the iterations stop (`tolerance` × Φ, each watt of which
/// would have become ρ/(1 − ρ) more); each local line carries its power to some wall of the closed room,
/// so the balance holds for any sample.
#[test]
fn stochastic_jacobi_shoots_the_luminaires_light() {
    let rho = 0.5;
    let faces = radiosity::scene::generators::box_faces(DVec3::new(4.0, 3.0, 3.0));
    let mut scene = Scene {
        polygons: faces
            .iter()
            .map(|&shape| Polygon {
                shape,
                material: 0,
                object: 0,
                two_sided: false,
                under_contact: false,
            })
            .collect(),
        materials: vec![Material::diffuse("wall", Rgb::splat(rho))],
        objects: vec![radiosity::scene::Object {
            name: "room".into(),
        }],
        ..Default::default()
    };
    let placement: Placement = "box.ies@1.7,1.4,2.2@0.2,0,-1@30".parse().unwrap();
    scene.add_luminaire(Luminaire::place(
        directional_point_source(),
        placement.transform(),
        Rgb::WHITE,
        1.0,
    ));
    let settings = SimulationSettings {
        method: radiosity::pipeline::MethodKind::StochasticJacobi,
        basis: radiosity::bases::BasisKind::Constant,
        rays_per_iteration: 20_000,
        tolerance: 1e-3,
        ..Default::default()
    };
    let solution = simulate(&scene, &settings, &quiet()).unwrap();
    let flux = scene.emitted_power().r;
    let report = &solution.report;
    let slack = 0.01 + settings.tolerance * rho / (1.0 - rho);
    assert!(
        (report.absorbed_power.r / flux - 1.0).abs() < slack,
        "absorbed {} of {flux}",
        report.absorbed_power.r
    );
    let reflected = flux * rho / (1.0 - rho);
    assert!(
        (report.exitant_power.r / reflected - 1.0).abs() < slack,
        "exitant {} vs {reflected}",
        report.exitant_power.r
    );
}

/// A 0.4 × 0.5 × 0.25 m box opening with the directional table of the image test.
fn directional_box() -> Arc<Photometry> {
    let columns = [
        [1000.0, 950.0, 800.0, 500.0, 200.0, 50.0, 0.0, 0.0, 0.0, 0.0],
        [1000.0, 800.0, 400.0, 250.0, 100.0, 25.0, 0.0, 0.0, 0.0, 0.0],
    ];
    let vertical: Vec<String> = (0..10).map(|k| (10 * k).to_string()).collect();
    let values: Vec<String> = columns.iter().flatten().map(|v| v.to_string()).collect();
    let text = format!(
        "IESNA:LM-63-2002\nTILT=NONE\n1 -1 1 10 2 1 2 0.4 0.5 0.25\n1 1 10\n{}\n0 90\n{}\n",
        vertical.join(" "),
        values.join(" ")
    );
    Arc::new(parse(Path::new("box.ies"), &text).unwrap())
}

/// `intensity_bounds` holds every intensity toward the vertical range, whatever the horizontal
/// angle, and is attained (the table's bilinear interpolant has its extremes at the range's ends or
/// at table angles); a range reaching past the table's vertical angles includes the zero there.
#[test]
fn intensity_bounds_hold_and_are_attained() {
    let table = directional_point_source();
    for (lo, hi) in [
        (0.0, 5.0),
        (12.0, 37.0),
        (25.0, 70.0),
        (55.0, 80.0),
        (-10.0, 15.0),
        (80.0, 200.0),
    ] {
        let (low, high) = table.intensity_bounds(lo, hi);
        let (mut seen_low, mut seen_high) = (f64::INFINITY, f64::NEG_INFINITY);
        for i in 0..=200 {
            let theta = lo + (hi - lo) * i as f64 / 200.0;
            for j in 0..72 {
                let v = if (0.0..=180.0).contains(&theta) {
                    table.intensity(theta, 5.0 * j as f64)
                } else {
                    0.0
                };
                assert!(
                    low - 1e-9 <= v && v <= high + 1e-9,
                    "[{lo}, {hi}]: {v} outside [{low}, {high}]"
                );
                seen_low = seen_low.min(v);
                seen_high = seen_high.max(v);
            }
        }
        assert!(
            (seen_low - low).abs() < 1e-9 && (seen_high - high).abs() < 1e-9,
            "[{lo}, {hi}]: sampled [{seen_low}, {seen_high}] against [{low}, {high}]"
        );
    }
}

/// The luminaires' direct light is kept per element (`Hierarchy::direct`, `direct_residual`): the
/// hierarchy's byte count holds it, and `--max-memory`'s bytes per element (`element_bytes`) leave
/// room for it in a lit scene, as the lists' growth slack allows (twice the coefficients).
#[test]
fn direct_light_is_counted_in_the_memory_of_elements() {
    use radiosity::memory::element_bytes;
    let isotropic = photometry(&[0.0], &[[1000.0; 10]], 0.0);
    let luminaire = Luminaire::place(
        isotropic,
        DAffine3::from_translation(DVec3::new(0.0, 0.0, 2.0)),
        Rgb::WHITE,
        1.0,
    );
    let scene = floor_scene(3.0, 0.5, luminaire);
    let settings = SimulationSettings {
        eps: 1e-5,
        ..Default::default()
    };
    let solution = simulate(&scene, &settings, &quiet()).unwrap();
    let h = &solution.hierarchy;
    let direct = h.direct.capacity() * std::mem::size_of::<Rgb>()
        + h.direct_residual.capacity() * std::mem::size_of::<f64>();
    assert!(h.direct.len() >= h.elements.len() && direct > 0);
    let per_element = element_bytes(settings.basis, true) - element_bytes(settings.basis, false);
    assert!(
        direct <= h.elements.len() * per_element,
        "{direct} bytes of direct light for {} elements at {per_element} each",
        h.elements.len()
    );
    let links: usize = h
        .elements
        .iter()
        .map(|e| e.links.capacity() * std::mem::size_of::<radiosity::hierarchy::Link>())
        .sum();
    assert!(h.memory_bytes() >= direct + links);
}
