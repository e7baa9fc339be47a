//! The path tracer against ground truth: the white furnace, the exact point-to-polygon form factor, and
//! bit-identical results for any thread count.

use radiosity::color::Rgb;
use radiosity::geometry::form_factor::point_to_polygon;
use radiosity::geometry::DVec3;
use radiosity::output::camera::Camera;
use radiosity::pipeline::{build_visibility, VisibilityKind};
use radiosity::progress::Progress;
use radiosity::reference::{
    render_reference, Estimate, PathTracer, PixelFilter, ReferenceSettings,
};
use radiosity::scene::{generators, CameraSpec};

fn quiet() -> Progress {
    Progress::new(true)
}

/// |estimate - exact| <= 3 standard errors in every channel, and the standard error is meaningful.
fn assert_within_three_sigma(estimate: Estimate, exact: Rgb, what: &str) {
    for c in 0..3 {
        let (m, s, x) = (
            estimate.mean.to_array()[c],
            estimate.stderr.to_array()[c],
            exact.to_array()[c],
        );
        assert!(s > 0.0, "{what}: zero standard error");
        assert!(
            (m - x).abs() <= 3.0 * s,
            "{what}: channel {c}: {m} ± {s}, exact {x}"
        );
    }
}

#[test]
fn furnace_pixels_converge_to_e_over_one_minus_rho() {
    let (rho, e) = (0.5, 1.0);
    let size = DVec3::new(1.0, 1.5, 2.0);
    let scene = generators::furnace(size, rho, e);
    let visibility = build_visibility(&scene, VisibilityKind::Bvh).expect("bvh");
    let spec = CameraSpec {
        eye: size * 0.5,
        look_at: DVec3::new(0.2, 0.3, 0.0),
        up: DVec3::Y,
        fov_degrees: 100.0,
    };
    let camera = Camera::new(&spec, 4, 4);
    let settings = ReferenceSettings {
        spp: 4000,
        seed: 3,
        filter: PixelFilter::Centre,
        ..Default::default()
    };
    let image = render_reference(&scene, visibility.as_ref(), &camera, &settings, &quiet());
    let exact = Rgb::splat(e / (1.0 - rho));
    for (x, y) in [(0, 0), (1, 2), (2, 1), (3, 3), (0, 3)] {
        let estimate = Estimate {
            mean: image.mean.get(x, y),
            stderr: image.stderr.get(x, y),
        };
        assert_within_three_sigma(estimate, exact, &format!("pixel ({x}, {y})"));
    }
    let relative = image.mean_relative_stderr().expect("lit pixels");
    assert!(relative < 0.02, "mean relative standard error {relative}");
}

#[test]
fn parallel_plates_centre_radiance_is_rho_e_times_the_point_form_factor() {
    let (rho, e) = (0.5, 1.0);
    let scene = generators::parallel_plates(1.0, 1.0, rho, e);
    let visibility = build_visibility(&scene, VisibilityKind::Bvh).expect("bvh");
    let centre = DVec3::new(0.5, 0.5, 0.0);
    let f = point_to_polygon(centre, DVec3::Z, &scene.polygons[1].shape);
    // The exact unit-square value from the centre, 4 · (1/2π)(·) by symmetry, is about 0.2398.
    assert!(f > 0.23 && f < 0.25, "{f}");
    let exact = Rgb::splat(rho * e * f);

    let estimate = PathTracer::new(
        &scene,
        visibility.as_ref(),
        ReferenceSettings::default().roulette_depth,
    )
    .radiance_leaving(centre, DVec3::Z, 0, true, 20_000, 5);
    assert_within_three_sigma(estimate, exact, "radiance_leaving");
    assert!(estimate.stderr.g < 0.01 * exact.g, "{estimate:?}");

    // The centre pixel of an odd-sized image looks straight down at the centre point.
    let spec = CameraSpec {
        eye: DVec3::new(0.5, 0.5, 0.5),
        look_at: centre,
        up: DVec3::Y,
        fov_degrees: 30.0,
    };
    let camera = Camera::new(&spec, 3, 3);
    let settings = ReferenceSettings {
        spp: 20_000,
        seed: 9,
        filter: PixelFilter::Centre,
        ..Default::default()
    };
    let image = render_reference(&scene, visibility.as_ref(), &camera, &settings, &quiet());
    let pixel = Estimate {
        mean: image.mean.get(1, 1),
        stderr: image.stderr.get(1, 1),
    };
    assert_within_three_sigma(pixel, exact, "centre pixel");

    // The black back of the one-sided receiver leaves nothing.
    let back = PathTracer::new(
        &scene,
        visibility.as_ref(),
        ReferenceSettings::default().roulette_depth,
    )
    .radiance_leaving(centre, -DVec3::Z, 0, false, 100, 5);
    assert_eq!(back, Estimate::default());
}

#[test]
fn results_are_identical_for_one_and_two_threads() {
    let scene = generators::lit_box(DVec3::new(1.0, 1.0, 1.0), Rgb::new(0.7, 0.5, 0.3), 1.0);
    let visibility = build_visibility(&scene, VisibilityKind::Bvh).expect("bvh");
    let spec = CameraSpec {
        eye: DVec3::new(0.5, 0.5, 0.95),
        look_at: DVec3::new(0.5, 0.5, 0.0),
        up: DVec3::Y,
        fov_degrees: 80.0,
    };
    let camera = Camera::new(&spec, 12, 9);
    let settings = ReferenceSettings {
        spp: 16,
        seed: 11,
        filter: PixelFilter::Centre,
        ..Default::default()
    };
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("thread pool");
        pool.install(|| {
            let image = render_reference(&scene, visibility.as_ref(), &camera, &settings, &quiet());
            let point = PathTracer::new(
                &scene,
                visibility.as_ref(),
                ReferenceSettings::default().roulette_depth,
            )
            .radiance_leaving(DVec3::new(0.3, 0.0, 0.6), DVec3::Y, 2, true, 3000, 11);
            (image, point)
        })
    };
    let (one, two) = (run(1), run(2));
    assert_eq!(one.0, two.0);
    assert_eq!(one.1, two.1);
    assert!(one.0.mean_relative_stderr().is_some());
    // A different seed gives a different image.
    let other = ReferenceSettings {
        seed: 12,
        ..settings
    };
    let image = render_reference(&scene, visibility.as_ref(), &camera, &other, &quiet());
    assert_ne!(image.mean, one.0.mean);
}

/// The standard errors are honest: over many seeds, about 94% of the estimates (Student's t with 15
/// degrees of freedom at ±2) fall within two standard errors of the exact value.
#[test]
fn standard_errors_cover_the_exact_value_at_the_nominal_rate() {
    let (rho, e) = (0.5, 1.0);
    let scene = generators::parallel_plates(1.0, 1.0, rho, e);
    let visibility = build_visibility(&scene, VisibilityKind::Bvh).expect("bvh");
    let centre = DVec3::new(0.3, 0.6, 0.0);
    let exact = rho * e * point_to_polygon(centre, DVec3::Z, &scene.polygons[1].shape);
    let tracer = radiosity::reference::PathTracer::new(&scene, visibility.as_ref(), 3);
    let trials = 400;
    let covered = (0..trials)
        .filter(|&seed| {
            let estimate = tracer.radiance_leaving(centre, DVec3::Z, 0, true, 32, seed);
            (estimate.mean.g - exact).abs() <= 2.0 * estimate.stderr.g
        })
        .count();
    let rate = covered as f64 / trials as f64;
    assert!(rate > 0.88 && rate < 0.98, "coverage {rate}");
}

/// The box filter's standard errors are those of the pixel average, edges included: two references of
/// the Cornell box with different seeds differ, pixel by pixel and channel by channel, as much as their
/// standard errors say: z² = (a − b)² / (σ_a² + σ_b²) averages 1. When all of a batch's paths shared one
/// subpixel point, the batches' spread counted the variation within edge pixels (a fixed, stratified
/// part of the estimate) as noise, and z² fell far below 1 there.
///
/// Error model: with σ² each from 16 batches (15 degrees of freedom, 30 for the sum), z² follows an F
/// distribution of mean 30/28 ≈ 1.07 and variance about 2.5; averaged over 32² pixels × 3 channels its
/// standard deviation is about 0.03, so [0.88, 1.25] is more than 5 of them on either side.
#[test]
fn box_filter_standard_errors_match_the_spread_between_seeds() {
    let scene = radiosity::scene::cornell::cornell_box();
    let visibility = build_visibility(&scene, VisibilityKind::Bvh).expect("bvh");
    let camera = Camera::new(&scene.camera.expect("the built-in camera"), 32, 32);
    let render = |seed| {
        let settings = ReferenceSettings {
            spp: 1024,
            seed,
            filter: PixelFilter::Box,
            ..Default::default()
        };
        render_reference(&scene, visibility.as_ref(), &camera, &settings, &quiet())
    };
    let (a, b) = (render(1), render(2));
    // z² = (a − b)² / (σ_a² + σ_b²) per pixel and channel, averaged with equal weights (the emitter's
    // edge pixels, whose values are a hundred times the room's, would dominate plain sums).
    let (mut sum, mut count) = (0.0, 0usize);
    for i in 0..a.mean.pixels.len() {
        let (ma, mb) = (a.mean.pixels[i].to_array(), b.mean.pixels[i].to_array());
        let (sa, sb) = (a.stderr.pixels[i].to_array(), b.stderr.pixels[i].to_array());
        for c in 0..3 {
            let variance = sa[c].powi(2) + sb[c].powi(2);
            if variance > 0.0 {
                sum += (ma[c] - mb[c]).powi(2) / variance;
                count += 1;
            }
        }
    }
    let mean_z2 = sum / count as f64;
    assert!(count > 2000);
    assert!(
        (0.88..=1.25).contains(&mean_z2),
        "mean squared difference between seeds in claimed standard errors: {mean_z2}"
    );
}
