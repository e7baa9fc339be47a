//! Exhaustive ray casting over every polygon: the slow, obviously correct reference the BVH is tested
//! against.

use super::{Hit, Visibility};
use crate::geometry::{DVec3, Ray, Shape};

/// Tests every polygon for every ray.
pub struct BruteForce {
    shapes: Vec<Shape>,
}

impl BruteForce {
    pub fn new(shapes: Vec<Shape>) -> Self {
        BruteForce { shapes }
    }
}

impl Visibility for BruteForce {
    fn intersect(&self, ray: &Ray, t_min: f64, t_max: f64) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        for (index, shape) in self.shapes.iter().enumerate() {
            let limit = best.map_or(t_max, |h| h.t);
            if let Some(hit) = intersect_shape(shape, index, ray, t_min, limit) {
                best = Some(hit);
            }
        }
        best
    }

    fn name(&self) -> &'static str {
        "brute-force"
    }
}

/// Ray–polygon intersection in double precision (Möller–Trumbore on the shape's triangles), returning the
/// hit's parameters on the shape.
pub fn intersect_shape(
    shape: &Shape,
    index: usize,
    ray: &Ray,
    t_min: f64,
    t_max: f64,
) -> Option<Hit> {
    let (t, _, _) = ray_polygon(ray, shape.vertices(), t_min, t_max)?;
    Some(Hit {
        t,
        polygon: index,
        front: ray.direction.dot(shape.vector_area()) < 0.0,
    })
}

/// The nearest hit on a triangle (3 vertices) or quad (4, tested as `v0 v1 v2` and `v0 v2 v3`) with `t` in
/// `(t_min, t_max)`: `t` and the barycentrics of the triangle hit. A non-planar quad can be crossed twice,
/// so the second triangle is tested up to the first's hit: the answer does not depend on `t_max` as long
/// as the nearest hit lies below it.
#[inline(always)]
pub fn ray_polygon(ray: &Ray, v: &[DVec3], t_min: f64, t_max: f64) -> Option<(f64, f64, f64)> {
    let s = ray.origin - v[0];
    let e2 = v[2] - v[0];
    let first = ray_triangle(ray, s, v[1] - v[0], e2, t_min, t_max);
    if v.len() == 4 {
        let limit = first.map_or(t_max, |(t, _, _)| t);
        if let Some(second) = ray_triangle(ray, s, e2, v[3] - v[0], t_min, limit) {
            return Some(second);
        }
    }
    first
}

/// Relative distance (to the coordinates' magnitude) below which a ray origin counts as lying in a
/// polygon's plane: far above the rounding of points sampled on the polygon (~1e-16), far below any
/// geometric feature.
pub(super) const IN_PLANE: f64 = 1e-10;

/// Möller–Trumbore on the triangle `a, a + e1, a + e2` with `s = origin - a`: the ray parameter in
/// `(t_min, t_max)` and the barycentric (u, v) of the hit.
///
/// A ray whose origin lies in the triangle's plane (up to rounding) never hits it: the only true
/// intersection is the origin itself, which `t_min > 0` excludes, and a ray along a floor would otherwise
/// "cross" the floor, or its coplanar neighbours, wherever the rounding of its end points puts it. This
/// is what keeps segments between surface points from being blocked by the surfaces they start on.
#[inline(always)]
pub fn ray_triangle(
    ray: &Ray,
    s: DVec3,
    e1: DVec3,
    e2: DVec3,
    t_min: f64,
    t_max: f64,
) -> Option<(f64, f64, f64)> {
    let p = ray.direction.cross(e2);
    let det = e1.dot(p);
    if det.abs() < 1e-300 {
        return None;
    }
    let inv = 1.0 / det;
    let u = s.dot(p) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = s.cross(e1);
    let w = ray.direction.dot(q) * inv;
    if w < 0.0 || u + w > 1.0 {
        return None;
    }
    // e2 . (s x e1) = s . (e1 x e2): the origin's height above the plane times |e1 x e2|.
    let height = e2.dot(q);
    let t = height * inv;
    if t <= t_min || t >= t_max {
        return None;
    }
    let scale = ray
        .origin
        .abs()
        .max_element()
        .max((ray.origin - s).abs().max_element());
    if height.abs() <= IN_PLANE * scale * e1.cross(e2).length() {
        return None;
    }
    Some((t, u, w))
}
