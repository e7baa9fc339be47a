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

/// What a rate measures.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Query {
    /// [`Visibility::segment_occluded`] of each segment (`blocked` counts the blocked ones).
    Occlusion,
    /// The closest hit of the ray from a segment's start through its end, `t` in
    /// `(SEGMENT_EPSILON, inf)` (the query of rendering and of hit-point lookups; `blocked` counts the
    /// rays that hit).
    ClosestHit,
}

impl Query {
    fn answer(self, vis: &dyn Visibility, a: DVec3, b: DVec3) -> bool {
        match self {
            Query::Occlusion => vis.segment_occluded(a, b),
            Query::ClosestHit => vis
                .intersect(&Ray::new(a, b - a), SEGMENT_EPSILON, f64::INFINITY)
                .is_some(),
        }
    }
}

/// Segments per turn of [`rates_in_turns`]: tens of milliseconds of work, far above the cost of
/// handing a block to the threads, far below the time over which the machine's speed drifts.
pub const TURN_SEGMENTS: usize = 32_768;

/// The throughput of `query` for each of `backends` over `segments` on one rayon pool of `threads`
/// threads (0: rayon's default), measured in turns: the segments are cut into blocks of
/// [`TURN_SEGMENTS`], every back end casts each block in turn (the one to go first rotating from
/// block to block), and each back end's rate is all the segments over its summed time. A drift of the
/// machine's speed (other load, clock changes: the same binary's rate over a whole set of segments
/// moved by a third between runs a second apart on 2026-12-03's machine) then slows every back end
/// alike, and the ratios between them hold. Within a block, chunks of 1024 segments are each a task of
/// their own, so that no thread waits on another's long run of chunks at the end
/// ([`crate::parallel`]), and return only a count, so threads share no written memory. The pool is
/// built before any clock starts.
pub fn rates_in_turns(
    backends: &[&dyn Visibility],
    segments: &[(DVec3, DVec3)],
    threads: usize,
    query: Query,
) -> Result<Vec<BenchResult>, rayon::ThreadPoolBuildError> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()?;
    let n = backends.len();
    let (mut seconds, mut blocked) = (vec![0.0; n], vec![0; n]);
    for (turn, block) in segments.chunks(TURN_SEGMENTS).enumerate() {
        for k in (0..n).map(|k| (turn + k) % n) {
            let vis = backends[k];
            let start = Instant::now();
            blocked[k] += pool.install(|| {
                block
                    .par_chunks(1024)
                    .one_per_task()
                    .map(|chunk| {
                        chunk
                            .iter()
                            .filter(|(a, b)| query.answer(vis, *a, *b))
                            .count()
                    })
                    .sum::<usize>()
            });
            seconds[k] += start.elapsed().as_secs_f64();
        }
    }
    Ok((0..n)
        .map(|k| BenchResult {
            rays: segments.len(),
            threads: pool.current_num_threads(),
            seconds: seconds[k],
            rays_per_second: segments.len() as f64 / seconds[k].max(1e-12),
            blocked: blocked[k],
        })
        .collect())
}

/// Runs `build` and returns its result with the wall-clock seconds it took.
pub fn timed<T>(build: impl FnOnce() -> T) -> (T, f64) {
    let start = Instant::now();
    let value = build();
    (value, start.elapsed().as_secs_f64())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::visibility::brute_force::BruteForce;
    use crate::visibility::bvh::Bvh;

    /// Measured in turns, every back end still casts every segment once: the BVH's counts equal the
    /// exhaustive reference's, for both queries, on one thread and on two, with blocks left over.
    #[test]
    fn back_ends_in_turns_answer_every_segment() {
        let shapes: Vec<Shape> = crate::scene::cornell::cornell_box()
            .polygons
            .iter()
            .map(|p| p.shape)
            .collect();
        let segments = random_segments(&shapes, 2 * TURN_SEGMENTS + 1000, 3);
        let (bvh, exhaustive) = (Bvh::new(&shapes), BruteForce::new(shapes.clone()));
        let backends: [&dyn Visibility; 2] = [&bvh, &exhaustive];
        for query in [Query::Occlusion, Query::ClosestHit] {
            let expected = segments
                .iter()
                .filter(|(a, b)| query.answer(&exhaustive, *a, *b))
                .count();
            assert!(expected > 0 && expected < segments.len());
            for threads in [1, 2] {
                let rates = rates_in_turns(&backends, &segments, threads, query).unwrap();
                for r in rates {
                    assert_eq!(
                        (r.rays, r.threads, r.blocked),
                        (segments.len(), threads, expected)
                    );
                    assert!(r.seconds > 0.0 && r.rays_per_second > 0.0);
                }
            }
        }
    }
}
