//! Global lines (Sbert 1996): uniformly distributed random lines through the scene's bounding sphere.
//! Each line crosses the scene at several points; consecutive crossings `x`, `y` are mutually visible, and
//! the side of each polygon that faces the other point is where the line carries light between them. The
//! lines crossing a polygon are uniform over its area and, seen from a crossing point, their directions are
//! cosine distributed on either side — so a crossing and its neighbour sample the point-to-point form
//! factor `F(x, y)` (Feixas et al. eq. (10), and the visibility measure of their ref. \[5\]).

use crate::geometry::{DVec3, Ray};
use crate::hierarchy::Hierarchy;
use crate::scene::Scene;
use crate::visibility::Visibility;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;
use rayon::prelude::*;
use std::f64::consts::PI;

/// Two consecutive crossings of one line: `x` then `y` along the line's direction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Chord {
    pub x: DVec3,
    pub y: DVec3,
    pub polygon_x: usize,
    pub polygon_y: usize,
    /// The patch (polygon side) of `x` that faces `y`; `None` for the back of a one-sided polygon.
    pub patch_x: Option<u32>,
    /// The patch of `y` that faces `x`.
    pub patch_y: Option<u32>,
}

/// The chords of N global lines and how often each polygon was crossed.
#[derive(Clone, Debug)]
pub struct GlobalLines {
    /// Number of lines cast (including those that missed the scene).
    pub lines: usize,
    /// Chords, grouped by line in line order: `line_chords[k]..line_chords[k + 1]` belong to line k.
    pub chords: Vec<Chord>,
    pub line_chords: Vec<usize>,
    /// Crossings per polygon: the number of lines' half-lines leaving each side of the polygon.
    pub crossings: Vec<u64>,
    /// Radius of the bounding sphere the lines were drawn in.
    pub radius: f64,
}

impl GlobalLines {
    /// Casts `lines` global lines through the bounding sphere of `scene` with the seed `seed`. Line k's
    /// parameters come from one sequential random stream, and lines are traced in parallel but collected in
    /// order, so the result does not depend on the thread count.
    pub fn trace(
        scene: &Scene,
        hierarchy: &Hierarchy,
        visibility: &dyn Visibility,
        lines: usize,
        seed: u64,
    ) -> GlobalLines {
        let bounds = scene.bounds();
        let centre = bounds.center();
        let radius = (0.5 * bounds.diagonal()).max(f64::MIN_POSITIVE) * 1.001;
        let mut rng = Pcg64Mcg::seed_from_u64(seed ^ 0x6c69_6e65_735f_6d69);
        let rays: Vec<Ray> = (0..lines)
            .map(|_| random_line(&mut rng, centre, radius))
            .collect();
        let per_line: Vec<Vec<(usize, DVec3, bool)>> = rays
            .par_iter()
            .map(|ray| crossings(visibility, ray, radius))
            .collect();
        let mut out = GlobalLines {
            lines,
            chords: Vec::new(),
            line_chords: vec![0],
            crossings: vec![0; scene.polygons.len()],
            radius,
        };
        for hits in &per_line {
            for &(polygon, _, _) in hits {
                out.crossings[polygon] += 1;
            }
            for pair in hits.windows(2) {
                let (px, x, front_x) = pair[0];
                let (py, y, front_y) = pair[1];
                // Travelling from x to y, the ray arrived on x's front when x faces back towards the
                // line's origin: the side of x facing y is then its back, and vice versa. At y the ray
                // arrives on the side facing x.
                out.chords.push(Chord {
                    x,
                    y,
                    polygon_x: px,
                    polygon_y: py,
                    patch_x: hierarchy.patch_for_side(px, !front_x),
                    patch_y: hierarchy.patch_for_side(py, front_y),
                });
            }
            out.line_chords.push(out.chords.len());
        }
        out
    }

    /// Estimator weight of a half-line leaving `polygon`: its area over its crossings, so that summing a
    /// function of the crossing over its half-lines estimates the function's integral over the polygon
    /// (a ratio estimator; zero for a polygon no line crossed).
    pub fn weight(&self, scene: &Scene, polygon: usize) -> f64 {
        match self.crossings[polygon] {
            0 => 0.0,
            n => scene.polygons[polygon].shape.area() / n as f64,
        }
    }

    /// Chords of line `k`.
    pub fn line(&self, k: usize) -> &[Chord] {
        &self.chords[self.line_chords[k]..self.line_chords[k + 1]]
    }
}

/// A uniformly distributed line meeting the sphere (`centre`, `radius`): an isotropic direction and a
/// uniform point on the disc through the centre perpendicular to it. The ray starts outside the sphere.
fn random_line(rng: &mut Pcg64Mcg, centre: DVec3, radius: f64) -> Ray {
    let z: f64 = 2.0 * rng.random::<f64>() - 1.0;
    let phi = 2.0 * PI * rng.random::<f64>();
    let s = (1.0 - z * z).max(0.0).sqrt();
    let dir = DVec3::new(s * phi.cos(), s * phi.sin(), z);
    let (u, v) = dir.any_orthonormal_pair();
    let r = radius * rng.random::<f64>().sqrt();
    let a = 2.0 * PI * rng.random::<f64>();
    let p = centre + r * (a.cos() * u + a.sin() * v);
    Ray::new(p - 1.01 * radius * dir, dir)
}

/// All crossings of a line with the scene, in order: (polygon, point, arrived on the front side).
fn crossings(visibility: &dyn Visibility, ray: &Ray, radius: f64) -> Vec<(usize, DVec3, bool)> {
    let end = 2.02 * radius;
    // Successive hits closer than this (a line through a shared edge) count once.
    let gap = 1e-9 * radius;
    let mut out = Vec::new();
    let mut t = 0.0;
    while let Some(hit) = visibility.intersect(ray, t, end) {
        out.push((hit.polygon, ray.at(hit.t), hit.front));
        t = hit.t + gap;
    }
    out
}
