//! Visibility: ray casting against the scene's polygons. The [`Visibility`] trait is the extension point:
//! our own SAH BVH ([`bvh::Bvh`]), an exhaustive reference ([`brute_force::BruteForce`]) for testing and,
//! behind the `embree` cargo feature, Embree 3. Later the cluster hierarchy's extinction-based visibility
//! (Sillion–Drettakis §3.1) and multi-resolution visibility (§3.2) become further implementations.

pub mod bench;
pub mod brute_force;
pub mod bvh;
#[cfg(feature = "embree")]
pub mod embree;
pub mod extinction;
pub mod item_buffer;
pub mod multires;
pub mod shaft;

use crate::geometry::{DVec3, Ray};

/// The first surface hit by a ray.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Ray parameter of the hit (`ray.origin + t * ray.direction`).
    pub t: f64,
    /// Index of the polygon in `Scene::polygons`.
    pub polygon: usize,
    /// Whether the ray arrives on the polygon's front side (against its normal).
    pub front: bool,
}

/// Ray queries against a fixed set of polygons. Implementations are shared between threads.
pub trait Visibility: Sync + Send {
    /// Closest hit with `t` in `(t_min, t_max)`.
    fn intersect(&self, ray: &Ray, t_min: f64, t_max: f64) -> Option<Hit>;

    /// Whether any polygon blocks the ray for `t` in `(t_min, t_max)`; may stop at the first blocker.
    fn occluded(&self, ray: &Ray, t_min: f64, t_max: f64) -> bool {
        self.intersect(ray, t_min, t_max).is_some()
    }

    /// Whether the open segment between two surface points is blocked. The ends are trimmed by a small
    /// relative margin so that the surfaces the points lie on do not block it.
    fn segment_occluded(&self, from: DVec3, to: DVec3) -> bool {
        let ray = Ray::new(from, to - from);
        self.occluded(&ray, SEGMENT_EPSILON, 1.0 - SEGMENT_EPSILON)
    }

    /// Fraction of light that passes along the open segment between two surface points, in [0, 1]: the
    /// `vis(x, y)` of the radiosity kernel (Bekaert–Willems eq. (1)). Exact ray casting gives 0 or 1;
    /// extinction through clusters (Sillion–Drettakis §3.1) gives values in between. `from` is the
    /// receiving end and `to` the source end: multi-resolution visibility (§3.2) sizes the shadows that
    /// light from `to` casts toward `from`.
    fn transmittance(&self, from: DVec3, to: DVec3) -> f64 {
        if self.segment_occluded(from, to) {
            0.0
        } else {
            1.0
        }
    }

    /// [`transmittance`](Self::transmittance) of light arriving on polygon `receiver` (an index of
    /// `Scene::polygons`). Multi-resolution visibility sizes the shadows by that surface's own feature
    /// size where the user gave one (Sillion–Drettakis §6: importance as a feature size per surface);
    /// the other back ends do not depend on the receiver.
    fn transmittance_onto(&self, from: DVec3, to: DVec3, _receiver: usize) -> f64 {
        self.transmittance(from, to)
    }

    /// [`occluded`](Self::occluded) with the polygons `transparent` accepts let through. The default
    /// steps from closest hit to closest hit; a back end with its own any-hit traversal skips them there.
    fn occluded_past(
        &self,
        ray: &Ray,
        t_min: f64,
        t_max: f64,
        transparent: &dyn Fn(usize) -> bool,
    ) -> bool {
        let mut start = t_min;
        for _ in 0..MAX_TRANSPARENT_HITS {
            match self.intersect(ray, start, t_max) {
                None => return false,
                Some(hit) if transparent(hit.polygon) => start = hit.t + TRANSPARENT_STEP,
                Some(_) => return true,
            }
        }
        true
    }

    /// [`transmittance`](Self::transmittance) with the polygons `transparent` accepts let through: the
    /// rays of a cluster link, whose end clusters' own contents must not shadow them a second time (their
    /// mutual occlusion is the item buffers' to count: Sillion–Drettakis §6.1). Exact back ends cast
    /// [`occluded_past`](Self::occluded_past) rays; the approximate ones (extinction, multi-resolution)
    /// keep their own model.
    fn transmittance_past(
        &self,
        from: DVec3,
        to: DVec3,
        transparent: &dyn Fn(usize) -> bool,
    ) -> f64 {
        let ray = Ray::new(from, to - from);
        if self.occluded_past(&ray, SEGMENT_EPSILON, 1.0 - SEGMENT_EPSILON, transparent) {
            0.0
        } else {
            1.0
        }
    }

    /// [`transmittance_past`](Self::transmittance_past) of light arriving on polygon `receiver`, as
    /// [`transmittance_onto`](Self::transmittance_onto) is of [`transmittance`](Self::transmittance).
    fn transmittance_past_onto(
        &self,
        from: DVec3,
        to: DVec3,
        _receiver: usize,
        transparent: &dyn Fn(usize) -> bool,
    ) -> f64 {
        self.transmittance_past(from, to, transparent)
    }

    /// Short name for reports ("bvh", "embree", "brute-force").
    fn name(&self) -> &'static str;

    /// Bytes of the acceleration structure, where the back end knows them (for benchmarks).
    fn memory_bytes(&self) -> Option<usize> {
        None
    }

    /// Shaft tests over the same polygons, where the back end casts exact rays and the solve asked for
    /// visibility reuse (`--visibility-reuse shaft`, [`shaft::ShaftCulled`]).
    fn shafts(&self) -> Option<&shaft::ShaftCuller> {
        None
    }
}

/// Relative trim of a segment's ends in [`Visibility::segment_occluded`].
pub const SEGMENT_EPSILON: f64 = 1e-5;

/// Most transparent polygons the default [`Visibility::occluded_past`] steps past before it calls the
/// ray blocked (a bound on its work; a cluster's contents rarely stack this deep along one ray).
pub const MAX_TRANSPARENT_HITS: usize = 64;

/// Step past a transparent hit, in segment parameter: beyond coincident polygons' rounding, well under
/// [`SEGMENT_EPSILON`].
const TRANSPARENT_STEP: f64 = 1e-9;
