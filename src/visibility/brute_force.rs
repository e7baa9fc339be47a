//! Exhaustive ray casting over every polygon: the slow, obviously correct reference the BVH is tested
//! against.

use super::{Hit, Visibility};
use crate::geometry::{Ray, Shape};

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
    let v = shape.vertices();
    let triangles: &[[usize; 3]] = if v.len() == 3 {
        &[[0, 1, 2]]
    } else {
        &[[0, 1, 2], [0, 2, 3]]
    };
    for tri in triangles {
        let (a, b, c) = (v[tri[0]], v[tri[1]], v[tri[2]]);
        let (e1, e2) = (b - a, c - a);
        let p = ray.direction.cross(e2);
        let det = e1.dot(p);
        if det.abs() < 1e-300 {
            continue;
        }
        let inv = 1.0 / det;
        let s = ray.origin - a;
        let u = s.dot(p) * inv;
        if !(0.0..=1.0).contains(&u) {
            continue;
        }
        let q = s.cross(e1);
        let w = ray.direction.dot(q) * inv;
        if w < 0.0 || u + w > 1.0 {
            continue;
        }
        let t = e2.dot(q) * inv;
        if t <= t_min || t >= t_max {
            continue;
        }
        let point = ray.at(t);
        let front = ray.direction.dot(shape.vector_area()) < 0.0;
        return Some(Hit {
            t,
            polygon: index,
            uv: shape.parameters_of(point),
            front,
        });
    }
    None
}
