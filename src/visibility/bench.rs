//! Benchmark helpers: the occlusion rays radiosity casts (segments between area-uniform points on
//! area-weighted random polygons), their throughput on a fixed thread pool, and build timing.

use super::{Visibility, SEGMENT_EPSILON};
use crate::geometry::{DVec2, DVec3, Ray, Shape};
use crate::parallel::Uneven;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;
use rayon::prelude::*;
use std::time::Instant;

/// Throughput of one occlusion run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BenchResult {
    pub rays: usize,
    pub threads: usize,
    pub seconds: f64,
    pub rays_per_second: f64,
    /// Blocked segments (occlusion) or rays that hit (closest hit): independent of thread count, and
    /// the BVH's equal the exhaustive reference's.
    pub blocked: usize,
}

/// `count` segments between two area-uniform random points, each on a polygon chosen with probability
/// proportional to its area. Empty when the scene has no area.
pub fn random_segments(shapes: &[Shape], count: usize, seed: u64) -> Vec<(DVec3, DVec3)> {
    let mut cumulative = Vec::with_capacity(shapes.len());
    let mut total = 0.0;
    for s in shapes {
        total += s.area();
        cumulative.push(total);
    }
    if total.is_nan() || total <= 0.0 {
        return Vec::new();
    }
    let mut rng = Pcg64Mcg::seed_from_u64(seed);
    let point = |rng: &mut Pcg64Mcg| {
        let x = rng.random::<f64>() * total;
        // First polygon whose cumulative area exceeds x (zero-area polygons are never chosen).
        let k = cumulative
            .partition_point(|&c| c <= x)
            .min(shapes.len() - 1);
        shapes[k].sample_uniform(DVec2::new(rng.random(), rng.random()))
    };
    (0..count)
        .map(|_| {
            let a = point(&mut rng);
            (a, point(&mut rng))
        })
        .collect()
}

/// The `segments` that every back end of `backends` finds blocked, or every one finds free
/// (`radiosity bench rays --agreeing`): speed compared at equal answers.
pub fn agreeing_segments(
    backends: &[&dyn Visibility],
    segments: Vec<(DVec3, DVec3)>,
) -> Vec<(DVec3, DVec3)> {
    segments
        .into_par_iter()
        .filter(|&(a, b)| {
            let mut answers = backends.iter().map(|v| v.segment_occluded(a, b));
            let first = answers.next();
            answers.all(|answer| Some(answer) == first)
        })
        .collect()
}

/// Occlusion throughput of `vis` over `segments` (via [`Visibility::segment_occluded`]) on a rayon pool
/// of `threads` threads (0: rayon's default). `blocked` counts the blocked segments.
pub fn occlusion_rate(
    vis: &dyn Visibility,
    segments: &[(DVec3, DVec3)],
    threads: usize,
) -> Result<BenchResult, rayon::ThreadPoolBuildError> {
    rate(segments, threads, |a, b| vis.segment_occluded(a, b))
}

/// Closest-hit throughput of `vis` (the query of rendering and of hit-point lookups): per segment the ray
/// from its start through its end, `t` in `(SEGMENT_EPSILON, inf)`. `blocked` counts the rays that hit.
pub fn closest_hit_rate(
    vis: &dyn Visibility,
    segments: &[(DVec3, DVec3)],
    threads: usize,
) -> Result<BenchResult, rayon::ThreadPoolBuildError> {
    rate(segments, threads, |a, b| {
        vis.intersect(&Ray::new(a, b - a), SEGMENT_EPSILON, f64::INFINITY)
            .is_some()
    })
}

/// Runs `query` over `segments` on a fresh pool of `threads` threads and counts its `true` answers. The
/// pool is built before the clock starts; chunks of 1024 segments keep scheduling overhead negligible,
/// each a task of its own so that no thread waits on another's long run of chunks at the end
/// ([`crate::parallel`]), and each chunk only returns a count, so threads share no written memory.
fn rate(
    segments: &[(DVec3, DVec3)],
    threads: usize,
    query: impl Fn(DVec3, DVec3) -> bool + Sync,
) -> Result<BenchResult, rayon::ThreadPoolBuildError> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()?;
    let start = Instant::now();
    let blocked = pool.install(|| {
        segments
            .par_chunks(1024)
            .one_per_task()
            .map(|chunk| chunk.iter().filter(|(a, b)| query(*a, *b)).count())
            .sum()
    });
    let seconds = start.elapsed().as_secs_f64();
    Ok(BenchResult {
        rays: segments.len(),
        threads: pool.current_num_threads(),
        seconds,
        rays_per_second: segments.len() as f64 / seconds.max(1e-12),
        blocked,
    })
}

/// Runs `build` and returns its result with the wall-clock seconds it took.
pub fn timed<T>(build: impl FnOnce() -> T) -> (T, f64) {
    let start = Instant::now();
    let value = build();
    (value, start.elapsed().as_secs_f64())
}
