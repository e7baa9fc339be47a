//! The whole path: Cornell box solve converging under refinement, and results independent of the
//! thread count.

use radiosity::color::Rgb;
use radiosity::hierarchy::Hierarchy;
use radiosity::measures::stats::RunStats;
use radiosity::output::camera::Camera;
use radiosity::output::render::{render, RenderOptions, Shading};
use radiosity::pipeline::{simulate, SimulationSettings};
use radiosity::progress::Progress;
use radiosity::scene::{cornell::cornell_box, Scene};

/// Area-weighted mean radiance of every object whose name is given.
fn object_means(scene: &Scene, h: &Hierarchy, names: &[&str]) -> Vec<Rgb> {
    names
        .iter()
        .map(|name| {
            let (mut sum, mut area) = (Rgb::BLACK, 0.0);
            for patch in &h.patches {
                let polygon = &scene.polygons[patch.polygon];
                if scene.objects[polygon.object].name == *name {
                    let root = h.element(patch.root);
                    sum += h.average_radiance(patch.root) * root.area;
                    area += root.area;
                }
            }
            assert!(area > 0.0, "no object named {name}");
            sum / area
        })
        .collect()
}

#[test]
fn cornell_wall_radiance_converges_as_eps_halves() {
    let scene = cornell_box();
    let walls = ["floor", "ceiling", "back_wall", "left_wall", "right_wall"];
    let means: Vec<Vec<Rgb>> = [1e-4, 5e-5, 2.5e-5]
        .iter()
        .map(|&eps| {
            let settings = SimulationSettings {
                eps,
                ..Default::default()
            };
            let solution = simulate(&scene, &settings, &Progress::new(true)).expect("solve");
            object_means(&scene, &solution.hierarchy, &walls)
        })
        .collect();
    for (w, wall) in walls.iter().enumerate() {
        let (coarse, fine) = (means[1][w], means[2][w]);
        for (c, f) in coarse.to_array().iter().zip(fine.to_array()) {
            let change = (c - f).abs() / f;
            assert!(
                change < 0.01,
                "{wall}: mean radiance changed by {:.2}% ({c} -> {f})",
                change * 100.0
            );
        }
    }
}

/// `solution` rendered through `camera`.
fn image_of(
    solution: &radiosity::pipeline::Solution,
    camera: &Camera,
    options: &RenderOptions,
) -> radiosity::output::image::Image {
    render(
        &solution.hierarchy,
        solution.visibility.as_ref(),
        camera,
        options,
    )
}

#[test]
fn stats_and_images_do_not_depend_on_thread_count() {
    let scene = cornell_box();
    let settings = SimulationSettings {
        eps: 5e-4,
        ..Default::default()
    };
    let camera = Camera::new(&scene.camera.expect("Cornell camera"), 64, 64);
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let solution = simulate(&scene, &settings, &Progress::new(true)).expect("solve");
            let stats = RunStats::new("cornell", scene.polygons.len(), &solution, &settings);
            let images: Vec<_> = [Shading::Flat, Shading::Smooth]
                .iter()
                .map(|&shading| {
                    let options = RenderOptions {
                        shading,
                        mesh: true,
                        ..Default::default()
                    };
                    image_of(&solution, &camera, &options)
                })
                .collect();
            (stats.deterministic_part(), images)
        })
    };
    let (stats1, images1) = run(1);
    let (stats2, images2) = run(2);
    assert_eq!(stats1, stats2);
    assert_eq!(images1, images2);
}

#[test]
fn links_stay_in_the_hierarchy_when_the_pass_limit_ends_the_solve() {
    let scene = cornell_box();
    for max_passes in [1, 2] {
        let settings = SimulationSettings {
            eps: 1e-5,
            max_passes,
            ..Default::default()
        };
        let solution = simulate(&scene, &settings, &Progress::new(true)).expect("solve");
        assert_eq!(solution.report.passes, max_passes);
        assert!(!solution.report.converged);
        assert!(
            solution.hierarchy.link_count() > 1000,
            "{max_passes} passes: links lost"
        );
    }
}

/// `render` and `view` drop the links and the item buffers' cache once the solve is done, so that the
/// image reuses their memory: what they show must not read them. Clustered (cluster links, item
/// buffers cached), every shading and the error estimate, rendered before and after the release.
#[test]
fn images_do_not_change_when_the_solvers_state_is_released() {
    use radiosity::hierarchy::clusters::ClusteringKind;
    use radiosity::output::render::Quantity;
    let scene = cornell_box();
    let settings = SimulationSettings {
        eps: 5e-4,
        clustering: ClusteringKind::Oriented,
        ..Default::default()
    };
    let camera = Camera::new(&scene.camera.expect("Cornell camera"), 48, 48);
    let mut solution = simulate(&scene, &settings, &Progress::new(true)).expect("solve");
    assert!(solution.hierarchy.root_cluster.is_some());
    assert!(solution.hierarchy.item_buffers.is_some());
    assert!(solution.hierarchy.link_count() > 0);
    let images =
        |solution: &radiosity::pipeline::Solution| -> Vec<radiosity::output::image::Image> {
            let shadings = [
                Shading::Flat,
                Shading::Smooth,
                Shading::Basis,
                Shading::Continuous,
                Shading::Seamless,
            ];
            let looks = shadings
                .iter()
                .map(|&shading| (shading, Quantity::Radiance))
                .chain([(Shading::Flat, Quantity::ErrorEstimate)]);
            looks
                .map(|(shading, quantity)| {
                    let options = RenderOptions {
                        shading,
                        quantity,
                        ..Default::default()
                    };
                    image_of(solution, &camera, &options)
                })
                .collect()
        };
    let before = images(&solution);
    solution.hierarchy.release_solver_state();
    assert_eq!(solution.hierarchy.link_count(), 0);
    assert!(solution.hierarchy.item_buffers.is_none());
    // Bit for bit: the error estimate's background is NaN (no estimate), which `==` never equals.
    let bits = |images: &[radiosity::output::image::Image]| -> Vec<u64> {
        images
            .iter()
            .flat_map(|image| &image.pixels)
            .flat_map(|c| [c.r, c.g, c.b])
            .map(f64::to_bits)
            .collect()
    };
    assert_eq!(bits(&images(&solution)), bits(&before));
}
