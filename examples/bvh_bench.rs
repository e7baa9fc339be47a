//! Ray-casting benchmark on synthetic scenes: build time and occlusion rays/s of our BVH (and Embree with
//! `--features embree`) on the segments radiosity casts.
//!
//! `cargo run --release --example bvh_bench [-- small|large|both|SCENE_FILE] [rays] [rounds]`: `small`
//! is a room of ~12k quads (walls tessellated, random boxes inside), `large` ~2.6M triangles (a
//! tessellated room with many small tessellated boxes); any other argument is a scene file (.mgf /
//! .obj). Occlusion ("occluded") and closest-hit ("closest") rates on 1 and 2 threads, the back ends
//! casting the segments in turns (`rates_in_turns`), all of it `rounds` times over (default 1).

use radiosity::geometry::{DVec3, Shape};
use radiosity::scene::{self, LoadOptions};
use radiosity::visibility::bench::{random_segments, rates_in_turns, timed, Query};
use radiosity::visibility::bvh::Bvh;
use radiosity::visibility::Visibility;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;

/// The six faces of an axis-aligned box, each split into `n`×`n` quads (or twice as many triangles).
fn tessellated_box(min: DVec3, max: DVec3, n: usize, triangles: bool, out: &mut Vec<Shape>) {
    let size = max - min;
    let axes = [DVec3::X, DVec3::Y, DVec3::Z];
    for axis in 0..3 {
        let (u, v) = (axes[(axis + 1) % 3], axes[(axis + 2) % 3]);
        for side in [0.0, 1.0] {
            for i in 0..n {
                for j in 0..n {
                    let p = |a: usize, b: usize| {
                        min + size
                            * (side * axes[axis]
                                + (a as f64 / n as f64) * u
                                + (b as f64 / n as f64) * v)
                    };
                    let q = [p(i, j), p(i + 1, j), p(i + 1, j + 1), p(i, j + 1)];
                    let q = if side == 0.0 {
                        q
                    } else {
                        [q[0], q[3], q[2], q[1]]
                    };
                    if triangles {
                        out.push(Shape::Triangle([q[0], q[1], q[2]]));
                        out.push(Shape::Triangle([q[0], q[2], q[3]]));
                    } else {
                        out.push(Shape::Quad(q));
                    }
                }
            }
        }
    }
}

/// A 10×8×3 room with walls of `wall_n`² elements per face and `objects` random boxes of `object_n`²
/// elements per face on and above the floor.
fn room(wall_n: usize, objects: usize, object_n: usize, triangles: bool, seed: u64) -> Vec<Shape> {
    let mut rng = Pcg64Mcg::seed_from_u64(seed);
    let mut shapes = Vec::new();
    let extent = DVec3::new(10.0, 8.0, 3.0);
    tessellated_box(DVec3::ZERO, extent, wall_n, triangles, &mut shapes);
    for _ in 0..objects {
        let size = DVec3::new(
            rng.random_range(0.05..0.6),
            rng.random_range(0.05..0.6),
            rng.random_range(0.05..0.8),
        );
        let corner = DVec3::new(
            rng.random_range(0.0..extent.x - size.x),
            rng.random_range(0.0..extent.y - size.y),
            if rng.random_bool(0.5) {
                0.0
            } else {
                rng.random_range(0.0..extent.z - size.z)
            },
        );
        tessellated_box(corner, corner + size, object_n, triangles, &mut shapes);
    }
    shapes
}

fn report(name: &str, shapes: &[Shape], rays: usize, rounds: usize) {
    let quads = shapes.iter().filter(|s| s.vertex_count() == 4).count();
    println!(
        "== {name}: {} polygons ({quads} quads, {} triangles)",
        shapes.len(),
        shapes.len() - quads
    );
    let segments = random_segments(shapes, rays, 1);
    let (bvh, seconds) = timed(|| Bvh::new(shapes));
    println!(
        "bvh build {seconds:.3} s ({} wide nodes, {:.1} MB)",
        bvh.node_count(),
        bvh.memory_bytes().unwrap_or(0) as f64 / 1e6
    );
    let mut backends: Vec<Box<dyn Visibility>> = vec![Box::new(bvh)];
    backends.extend(embree(shapes));
    let views: Vec<&dyn Visibility> = backends.iter().map(|b| b.as_ref()).collect();
    // The back ends in turns within each measurement, so that load from other processes and changes
    // of the machine's speed hit them alike.
    let modes = [
        ("occluded", Query::Occlusion),
        ("closest", Query::ClosestHit),
    ];
    for (mode, query) in (0..rounds).flat_map(|_| modes) {
        for threads in [1, 2] {
            match rates_in_turns(&views, &segments, threads, query) {
                Ok(rates) => {
                    for (vis, r) in views.iter().zip(&rates) {
                        println!(
                            "{:>8} {mode:>8} {} thread(s): {:.3} M rays/s ({:.1}% of the first), {} of {} blocked/hit",
                            vis.name(),
                            r.threads,
                            r.rays_per_second / 1e6,
                            100.0 * r.rays_per_second / rates[0].rays_per_second,
                            r.blocked,
                            r.rays
                        );
                    }
                }
                Err(e) => println!("thread pool: {e}"),
            }
        }
    }
}

/// Embree over the shapes, when the `embree` feature is on and the scene builds.
#[cfg(feature = "embree")]
fn embree(shapes: &[Shape]) -> Option<Box<dyn Visibility>> {
    use radiosity::visibility::embree::EmbreeScene;
    match timed(|| EmbreeScene::new(shapes)) {
        (Ok(embree), seconds) => {
            println!("embree build {seconds:.3} s");
            Some(Box::new(embree))
        }
        (Err(e), _) => {
            println!("embree: {e:#}");
            None
        }
    }
}

#[cfg(not(feature = "embree"))]
fn embree(_: &[Shape]) -> Option<Box<dyn Visibility>> {
    None
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let which = args.get(1).map_or("both", String::as_str);
    let rays = args
        .get(2)
        .and_then(|s| s.parse().ok())
        .unwrap_or(2_000_000);
    // Rounds of every measurement (this machine's rates drift between runs: ratios of back ends
    // measured back to back within one run are what compare).
    let rounds = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(1);
    if which == "small" || which == "both" {
        // 6·10² wall quads + 493 boxes · 6·2² quads ≈ 12k quads.
        report(
            "room, ~12k quads",
            &room(10, 493, 2, false, 7),
            rays,
            rounds,
        );
    }
    if which == "large" || which == "both" {
        // 6·100²·2 wall triangles + 26k boxes · 6·8²·2 triangles ≈ 2.6M triangles.
        report(
            "room, ~2.6M triangles",
            &room(100, 3370, 8, true, 8),
            rays,
            rounds,
        );
    }
    if !["small", "large", "both"].contains(&which) {
        match scene::load(std::path::Path::new(which), &LoadOptions::default()) {
            Ok(scene) => {
                let shapes: Vec<Shape> = scene.polygons.iter().map(|p| p.shape).collect();
                report(which, &shapes, rays, rounds);
            }
            Err(e) => println!("{which}: {e}"),
        }
    }
}
