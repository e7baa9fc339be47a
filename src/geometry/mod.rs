//! Geometry: planar convex shapes (triangles and quads) with their parametrisation, sampling and cubature,
//! rays and boxes, and the radiometric kernels in [`form_factor`].
//!
//! Every element of the radiosity hierarchy is a [`Shape`]: the papers' elements are planar triangles and
//! quadrilaterals (Bekaert–Willems §2 maps its bases onto them with a barycentric or bilinear map).

pub mod clip;
pub mod cubature;
pub mod form_factor;
pub mod near_field;

pub use glam::{DVec2, DVec3};

/// Master parameter domain of an element (Bekaert–Willems §2): the unit square \[0,1\]² for quads (bilinear
/// map) and the standard triangle (0,0), (1,0), (0,1) for triangles (barycentric map). Bases and cubature
/// rules are defined once on these and mapped onto elements by [`Shape::point_at`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Domain {
    Square,
    Triangle,
}

impl Domain {
    /// The nearest point of the domain to `uv` (parameters of points slightly outside an element, from
    /// rounding, are moved onto its boundary).
    pub fn clamp(self, uv: DVec2) -> DVec2 {
        let uv = uv.clamp(DVec2::ZERO, DVec2::ONE);
        match self {
            Domain::Square => uv,
            Domain::Triangle => {
                let excess = uv.x + uv.y - 1.0;
                if excess > 0.0 {
                    (uv - DVec2::splat(0.5 * excess)).max(DVec2::ZERO)
                } else {
                    uv
                }
            }
        }
    }

    /// Parametric area |D|: 1 for the unit square, 1/2 for the standard triangle.
    pub fn area(self) -> f64 {
        match self {
            Domain::Square => 1.0,
            Domain::Triangle => 0.5,
        }
    }

    /// Corners of the domain, counter-clockwise, in the order of a shape's vertices.
    pub fn corners(self) -> &'static [DVec2] {
        const TRI: [DVec2; 3] = [
            DVec2::new(0.0, 0.0),
            DVec2::new(1.0, 0.0),
            DVec2::new(0.0, 1.0),
        ];
        const QUAD: [DVec2; 4] = [
            DVec2::new(0.0, 0.0),
            DVec2::new(1.0, 0.0),
            DVec2::new(1.0, 1.0),
            DVec2::new(0.0, 1.0),
        ];
        match self {
            Domain::Triangle => &TRI,
            Domain::Square => &QUAD,
        }
    }
}

/// A planar convex triangle or quadrilateral; vertices are counter-clockwise seen from the front side.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Shape {
    Triangle([DVec3; 3]),
    Quad([DVec3; 4]),
}

/// Vector area of a closed polygon (Newell's method): its length is the area and its direction the
/// normal of the side its corners turn counter-clockwise around.
pub fn vector_area(corners: &[DVec3]) -> DVec3 {
    0.5 * edges(corners).map(|(a, b)| a.cross(b)).sum::<DVec3>()
}

/// The edges of a closed polygon: each corner with the next, the last with the first (without a `%`
/// per edge, an integer division that cost the contour integral a fifth of its time).
pub fn edges<T: Copy>(corners: &[T]) -> impl Iterator<Item = (T, T)> + '_ {
    let next = corners.iter().skip(1).chain(corners.first());
    corners.iter().copied().zip(next.copied())
}

impl Shape {
    pub fn vertices(&self) -> &[DVec3] {
        match self {
            Shape::Triangle(v) => v,
            Shape::Quad(v) => v,
        }
    }

    pub fn vertex_count(&self) -> usize {
        self.vertices().len()
    }

    /// Vector area: its length is the area and its direction the front normal. Newell's sum over the
    /// edges ([`vector_area`]) is, for a triangle, half the cross product of two edges and, for a
    /// quadrilateral (planar or not), half that of its diagonals: one cross product instead of one
    /// per edge, and of differences, which keeps the digits that corners far from the origin lose.
    pub fn vector_area(&self) -> DVec3 {
        match self {
            Shape::Triangle([a, b, c]) => 0.5 * (*b - *a).cross(*c - *a),
            Shape::Quad([a, b, c, d]) => 0.5 * (*c - *a).cross(*d - *b),
        }
    }

    pub fn area(&self) -> f64 {
        self.vector_area().length()
    }

    /// Unit front normal (zero for a degenerate shape).
    pub fn normal(&self) -> DVec3 {
        self.vector_area().normalize_or_zero()
    }

    pub fn centroid(&self) -> DVec3 {
        match self {
            Shape::Triangle(v) => (v[0] + v[1] + v[2]) / 3.0,
            // Area centroid of the quad as two triangles (their doubled areas: the factor cancels).
            Shape::Quad(v) => {
                let (a1, a2) = diagonal_halves(v);
                let c1 = (v[0] + v[1] + v[2]) / 3.0;
                let c2 = (v[0] + v[2] + v[3]) / 3.0;
                if a1 + a2 > 0.0 {
                    (a1 * c1 + a2 * c2) / (a1 + a2)
                } else {
                    (v[0] + v[1] + v[2] + v[3]) / 4.0
                }
            }
        }
    }

    /// Point at parameters (u, v): barycentric `p0 + u (p1 - p0) + v (p2 - p0)` (u, v >= 0, u + v <= 1) on a
    /// triangle, bilinear on a quad (u, v in [0, 1]).
    pub fn point_at(&self, uv: DVec2) -> DVec3 {
        let (u, v) = (uv.x, uv.y);
        match self {
            Shape::Triangle(p) => p[0] + u * (p[1] - p[0]) + v * (p[2] - p[0]),
            Shape::Quad(p) => {
                (1.0 - u) * (1.0 - v) * p[0]
                    + u * (1.0 - v) * p[1]
                    + u * v * p[2]
                    + (1.0 - u) * v * p[3]
            }
        }
    }

    /// Area Jacobian |dp/du x dp/dv| of [`Shape::point_at`] at (u, v).
    pub fn jacobian(&self, uv: DVec2) -> f64 {
        let (u, v) = (uv.x, uv.y);
        match self {
            Shape::Triangle(p) => (p[1] - p[0]).cross(p[2] - p[0]).length(),
            Shape::Quad(p) => {
                let du = (1.0 - v) * (p[1] - p[0]) + v * (p[2] - p[3]);
                let dv = (1.0 - u) * (p[3] - p[0]) + u * (p[2] - p[1]);
                du.cross(dv).length()
            }
        }
    }

    /// The master parameter domain of [`Shape::point_at`].
    pub fn domain(&self) -> Domain {
        match self {
            Shape::Triangle(_) => Domain::Triangle,
            Shape::Quad(_) => Domain::Square,
        }
    }

    /// Corners of the parameter domain, in the order of the vertices.
    pub fn parameter_corners(&self) -> &'static [DVec2] {
        self.domain().corners()
    }

    /// Parameters of a point lying in the shape's plane (inverse of [`Shape::point_at`]); for a quad this
    /// solves the bilinear map by Newton iteration, except on a parallelogram, where the map is affine.
    pub fn parameters_of(&self, p: DVec3) -> DVec2 {
        match self {
            Shape::Triangle(v) => barycentric_uv(v[0], v[1], v[2], p),
            Shape::Quad(v) => {
                // The affine map of the triangle (p0, p1, p3): exact on a parallelogram (to rounding
                // where the skew is below 1e-13 of the diagonals), the start of Newton's iteration
                // elsewhere.
                let mut uv = barycentric_uv(v[0], v[1], v[3], p);
                let skew = (v[0] + v[2] - v[1] - v[3]).length_squared();
                let diagonals = v[0].distance_squared(v[2]) + v[1].distance_squared(v[3]);
                if skew <= 1e-26 * diagonals {
                    return uv;
                }
                // Any vector off the plane serves the projections below (its length cancels): the
                // diagonals' cross product, twice the vector area of a planar quad, without a root.
                let n = (v[2] - v[0]).cross(v[3] - v[1]);
                for _ in 0..8 {
                    let (u, w) = (uv.x, uv.y);
                    let r = self.point_at(uv) - p;
                    let du = (1.0 - w) * (v[1] - v[0]) + w * (v[2] - v[3]);
                    let dv = (1.0 - u) * (v[3] - v[0]) + u * (v[2] - v[1]);
                    // Solve the 2x2 system in the plane: [du dv] d = r, projected with cross products.
                    let det = du.cross(dv).dot(n);
                    if det.abs() < 1e-300 {
                        break;
                    }
                    let d_u = r.cross(dv).dot(n) / det;
                    let d_v = du.cross(r).dot(n) / det;
                    uv -= DVec2::new(d_u, d_v);
                    if d_u.abs() + d_v.abs() < 1e-13 {
                        break;
                    }
                }
                // Newton can diverge on non-convex or degenerate quads: keep the affine guess then.
                if uv.is_finite() {
                    uv
                } else {
                    barycentric_uv(v[0], v[1], v[3], p)
                }
            }
        }
    }

    /// Area-uniform point from a sample `s` in the unit square (stratified samples stay stratified).
    pub fn sample_uniform(&self, s: DVec2) -> DVec3 {
        match self {
            Shape::Triangle(v) => sample_triangle(v[0], v[1], v[2], s),
            Shape::Quad(v) => {
                let (a1, a2) = diagonal_halves(v);
                let split = if a1 + a2 > 0.0 { a1 / (a1 + a2) } else { 0.5 };
                if s.x < split {
                    sample_triangle(v[0], v[1], v[2], DVec2::new(s.x / split, s.y))
                } else {
                    let x = ((s.x - split) / (1.0 - split)).min(1.0 - f64::EPSILON);
                    sample_triangle(v[0], v[2], v[3], DVec2::new(x, s.y))
                }
            }
        }
    }

    /// The four children of a regular split: quads at the parameter midpoints, triangles at the edge
    /// midpoints (the middle child keeps the parent's orientation).
    pub fn subdivide(&self) -> [Shape; 4] {
        match self {
            Shape::Triangle([a, b, c]) => {
                let (ab, bc, ca) = ((*a + *b) * 0.5, (*b + *c) * 0.5, (*c + *a) * 0.5);
                [
                    Shape::Triangle([*a, ab, ca]),
                    Shape::Triangle([ab, *b, bc]),
                    Shape::Triangle([ca, bc, *c]),
                    Shape::Triangle([bc, ca, ab]),
                ]
            }
            Shape::Quad(_) => {
                let m = |u: f64, v: f64| self.point_at(DVec2::new(u, v));
                let (c00, c10, c20) = (m(0.0, 0.0), m(0.5, 0.0), m(1.0, 0.0));
                let (c01, c11, c21) = (m(0.0, 0.5), m(0.5, 0.5), m(1.0, 0.5));
                let (c02, c12, c22) = (m(0.0, 1.0), m(0.5, 1.0), m(1.0, 1.0));
                [
                    Shape::Quad([c00, c10, c11, c01]),
                    Shape::Quad([c10, c20, c21, c11]),
                    Shape::Quad([c11, c21, c22, c12]),
                    Shape::Quad([c01, c11, c12, c02]),
                ]
            }
        }
    }

    /// The same shape seen from the other side (reversed winding, opposite normal).
    pub fn flipped(&self) -> Shape {
        match self {
            Shape::Triangle([a, b, c]) => Shape::Triangle([*a, *c, *b]),
            Shape::Quad([a, b, c, d]) => Shape::Quad([*a, *d, *c, *b]),
        }
    }

    pub fn bounds(&self) -> Aabb {
        let mut b = Aabb::EMPTY;
        for v in self.vertices() {
            b.grow(*v);
        }
        b
    }

    /// The sphere about the mean of the corners through the farthest corner: it holds the convex
    /// shape, so `|x − centre| − radius` bounds the distance from `x` to the shape from below, a
    /// cheap test before an exact one.
    pub fn corner_sphere(&self) -> (DVec3, f64) {
        let corners = self.vertices();
        let centre = corners.iter().sum::<DVec3>() / corners.len() as f64;
        let radius = corners
            .iter()
            .map(|v| v.distance(centre))
            .fold(0.0, f64::max);
        (centre, radius)
    }

    /// Largest distance between two corners (a quad's diagonals included): the element "size" used by
    /// minimum-size rules.
    pub fn diameter(&self) -> f64 {
        let v = self.vertices();
        let mut d: f64 = 0.0;
        for i in 0..v.len() {
            for j in i + 1..v.len() {
                d = d.max(v[i].distance(v[j]));
            }
        }
        d
    }
}

/// Cosine-distributed unit direction about the unit `normal` from a uniform sample `s` of the unit
/// square (Malley's method: a uniform point on the disc lifted to the hemisphere); density `cos θ / π`.
pub fn cosine_direction(normal: DVec3, s: DVec2) -> DVec3 {
    let r = s.x.sqrt();
    let phi = 2.0 * std::f64::consts::PI * s.y;
    let (t, b) = normal.any_orthonormal_pair();
    let z = (1.0 - s.x).max(0.0).sqrt();
    r * phi.cos() * t + r * phi.sin() * b + z * normal
}

/// Children parameter domains of a regular split, matching [`Shape::subdivide`] for the same kind of shape
/// (none for a domain that is not a triangle or quad).
pub fn subdivide_parameters(corners: &[DVec2]) -> Vec<Vec<DVec2>> {
    match corners {
        [a, b, c] => {
            let (ab, bc, ca) = ((*a + *b) * 0.5, (*b + *c) * 0.5, (*c + *a) * 0.5);
            vec![
                vec![*a, ab, ca],
                vec![ab, *b, bc],
                vec![ca, bc, *c],
                vec![bc, ca, ab],
            ]
        }
        [a, b, c, d] => {
            let mid = (*a + *b + *c + *d) * 0.25;
            let (ab, bc, cd, da) = (
                (*a + *b) * 0.5,
                (*b + *c) * 0.5,
                (*c + *d) * 0.5,
                (*d + *a) * 0.5,
            );
            vec![
                vec![*a, ab, mid, da],
                vec![ab, *b, bc, mid],
                vec![mid, bc, *c, cd],
                vec![da, mid, cd, *d],
            ]
        }
        _ => Vec::new(),
    }
}

/// Whether a 2D point lies inside (or on the boundary, within `tolerance`) of a convex counter-clockwise
/// polygon.
pub fn convex_contains(corners: &[DVec2], p: DVec2, tolerance: f64) -> bool {
    (0..corners.len()).all(|k| {
        let a = corners[k];
        let b = corners[(k + 1) % corners.len()];
        (b - a).perp_dot(p - a) >= -tolerance * (b - a).length()
    })
}

fn barycentric_uv(a: DVec3, b: DVec3, c: DVec3, p: DVec3) -> DVec2 {
    let (e1, e2, r) = (b - a, c - a, p - a);
    let (d11, d12, d22) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
    let (r1, r2) = (r.dot(e1), r.dot(e2));
    let det = d11 * d22 - d12 * d12;
    if det.abs() < 1e-300 {
        return DVec2::ZERO;
    }
    DVec2::new((d22 * r1 - d12 * r2) / det, (d11 * r2 - d12 * r1) / det)
}

/// Doubled areas of a quadrilateral's triangles `(v0, v1, v2)` and `(v0, v2, v3)` (callers use
/// only their ratio).
fn diagonal_halves(v: &[DVec3; 4]) -> (f64, f64) {
    (
        (v[1] - v[0]).cross(v[2] - v[0]).length(),
        (v[2] - v[0]).cross(v[3] - v[0]).length(),
    )
}

fn sample_triangle(a: DVec3, b: DVec3, c: DVec3, s: DVec2) -> DVec3 {
    let su = s.x.sqrt();
    let (u, v) = (1.0 - su, s.y * su);
    a * u + b * v + c * (1.0 - u - v)
}

/// A ray `origin + t * direction`; `direction` need not be normalised for occlusion queries.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    pub origin: DVec3,
    pub direction: DVec3,
}

impl Ray {
    pub fn new(origin: DVec3, direction: DVec3) -> Self {
        Ray { origin, direction }
    }

    pub fn at(&self, t: f64) -> DVec3 {
        self.origin + t * self.direction
    }
}

/// Axis-aligned bounding box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    pub min: DVec3,
    pub max: DVec3,
}

impl Aabb {
    pub const EMPTY: Aabb = Aabb {
        min: DVec3::splat(f64::INFINITY),
        max: DVec3::splat(f64::NEG_INFINITY),
    };

    pub fn grow(&mut self, p: DVec3) {
        self.min = self.min.min(p);
        self.max = self.max.max(p);
    }

    pub fn union(&self, o: &Aabb) -> Aabb {
        Aabb {
            min: self.min.min(o.min),
            max: self.max.max(o.max),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.min.x > self.max.x
    }

    pub fn extent(&self) -> DVec3 {
        if self.is_empty() {
            DVec3::ZERO
        } else {
            self.max - self.min
        }
    }

    pub fn center(&self) -> DVec3 {
        (self.min + self.max) * 0.5
    }

    pub fn diagonal(&self) -> f64 {
        self.extent().length()
    }

    pub fn surface_area(&self) -> f64 {
        let e = self.extent();
        2.0 * (e.x * e.y + e.y * e.z + e.z * e.x)
    }

    /// The box grown by `pad` on every side.
    pub fn padded(&self, pad: f64) -> Aabb {
        Aabb {
            min: self.min - DVec3::splat(pad),
            max: self.max + DVec3::splat(pad),
        }
    }

    /// The parameter interval of the segment `from + t d`, `t ∈ [0, 1]`, inside the box
    /// (`inverse = 1/d` per axis), `None` where it misses or only touches it. A segment parallel to a
    /// slab and on one of its planes counts as inside that slab.
    pub fn segment_range(&self, from: DVec3, inverse: DVec3) -> Option<(f64, f64)> {
        let (mut t0, mut t1) = (0.0f64, 1.0f64);
        for axis in 0..3 {
            let (lo, hi) = (
                (self.min[axis] - from[axis]) * inverse[axis],
                (self.max[axis] - from[axis]) * inverse[axis],
            );
            if lo.is_nan() || hi.is_nan() {
                continue;
            }
            t0 = t0.max(lo.min(hi));
            t1 = t1.min(lo.max(hi));
        }
        (t1 > t0).then_some((t0, t1))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Entry and exit parameters of segments through the unit cube, against the planes they cross; a
    /// miss, a touch and a flat box (which only padding gives an inside).
    #[test]
    fn segment_ranges_are_where_segments_cross_the_box() {
        let cube = Aabb {
            min: DVec3::ZERO,
            max: DVec3::ONE,
        };
        let range = |b: &Aabb, from: DVec3, to: DVec3| b.segment_range(from, (to - from).recip());
        // Along x through the middle, from x = −1 to x = 3: inside for x ∈ [0, 1].
        let (from, to) = (DVec3::new(-1.0, 0.5, 0.5), DVec3::new(3.0, 0.5, 0.5));
        assert_eq!(range(&cube, from, to), Some((0.25, 0.5)));
        // Diagonally, from outside one corner to beyond the opposite one.
        let (t0, t1) = range(&cube, DVec3::splat(-1.0), DVec3::splat(2.0)).unwrap();
        assert!((t0 - 1.0 / 3.0).abs() < 1e-15 && (t1 - 2.0 / 3.0).abs() < 1e-15);
        // Ending before the box, passing beside it, and starting inside.
        assert_eq!(range(&cube, from, DVec3::new(-0.5, 0.5, 0.5)), None);
        assert_eq!(
            range(&cube, DVec3::new(-1.0, 2.0, 0.5), DVec3::new(3.0, 2.0, 0.5)),
            None
        );
        assert_eq!(
            range(&cube, DVec3::splat(0.5), DVec3::new(0.5, 0.5, 2.5)),
            Some((0.0, 0.25))
        );
        // Parallel to a slab on its plane counts as inside it; a segment touching an edge does not.
        assert_eq!(
            range(&cube, DVec3::new(-1.0, 0.0, 0.5), DVec3::new(3.0, 0.0, 0.5)),
            Some((0.25, 0.5))
        );
        assert_eq!(
            range(
                &cube,
                DVec3::new(-1.0, 1.0, 0.0),
                DVec3::new(1.0, -1.0, 0.0)
            ),
            None
        );
        // A flat box (a single plane's contents) is crossed only once padded.
        let flat = Aabb {
            min: DVec3::new(0.0, 0.0, 0.5),
            max: DVec3::new(1.0, 1.0, 0.5),
        };
        let (down, up) = (DVec3::new(0.5, 0.5, 1.0), DVec3::new(0.5, 0.5, 0.0));
        assert_eq!(range(&flat, down, up), None);
        let (t0, t1) = range(&flat.padded(1e-6), down, up).unwrap();
        assert!(t0 < 0.5 && t1 > 0.5 && t1 - t0 < 1e-5);
    }

    #[test]
    fn cosine_directions_have_the_lambertian_moments() {
        use rand::{Rng, SeedableRng};
        let normal = DVec3::new(1.0, 2.0, -0.5).normalize();
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(7);
        let n = 200_000;
        let (mut cos, mut cos2) = (0.0, 0.0);
        for _ in 0..n {
            let d = cosine_direction(normal, DVec2::new(rng.random(), rng.random()));
            assert!((d.length() - 1.0).abs() < 1e-12);
            let c = d.dot(normal);
            assert!(c >= 0.0);
            cos += c;
            cos2 += c * c;
        }
        // For p(ω) = cos θ / π: E[cos θ] = 2/3, E[cos² θ] = 1/2.
        assert!((cos / n as f64 - 2.0 / 3.0).abs() < 3e-3);
        assert!((cos2 / n as f64 - 0.5).abs() < 3e-3);
    }

    fn unit_quad() -> Shape {
        Shape::Quad([DVec3::ZERO, DVec3::X, DVec3::new(1.0, 1.0, 0.0), DVec3::Y])
    }

    #[test]
    fn areas_normals_and_children() {
        let q = unit_quad();
        assert!((q.area() - 1.0).abs() < 1e-12);
        assert!((q.normal() - DVec3::Z).length() < 1e-12);
        let children = q.subdivide();
        let total: f64 = children.iter().map(Shape::area).sum();
        assert!((total - 1.0).abs() < 1e-12);
        for c in &children {
            assert!((c.normal() - DVec3::Z).length() < 1e-12);
        }
        let t = Shape::Triangle([DVec3::ZERO, DVec3::X, DVec3::Y]);
        let total: f64 = t.subdivide().iter().map(Shape::area).sum();
        assert!((total - 0.5).abs() < 1e-12);
        for c in t.subdivide() {
            assert!(c.normal().dot(DVec3::Z) > 0.999);
        }
    }

    #[test]
    fn parameters_invert_point_at() {
        let q = Shape::Quad([
            DVec3::ZERO,
            DVec3::new(2.0, 0.0, 0.0),
            DVec3::new(1.5, 1.0, 0.0),
            DVec3::new(0.2, 1.3, 0.0),
        ]);
        for &(u, v) in &[(0.1, 0.2), (0.9, 0.7), (0.5, 0.5)] {
            let uv = DVec2::new(u, v);
            assert!((q.parameters_of(q.point_at(uv)) - uv).length() < 1e-9);
        }
        let t = Shape::Triangle([
            DVec3::ZERO,
            DVec3::new(2.0, 0.0, 1.0),
            DVec3::new(0.0, 1.0, 0.0),
        ]);
        let uv = DVec2::new(0.3, 0.4);
        assert!((t.parameters_of(t.point_at(uv)) - uv).length() < 1e-12);
    }

    #[test]
    fn child_parameter_domains_match_child_shapes() {
        for shape in [
            unit_quad(),
            Shape::Triangle([DVec3::ZERO, DVec3::X, DVec3::Y]),
        ] {
            let domains = subdivide_parameters(shape.parameter_corners());
            for (child, domain) in shape.subdivide().iter().zip(&domains) {
                for (p, uv) in child.vertices().iter().zip(domain) {
                    assert!((shape.point_at(*uv) - *p).length() < 1e-12);
                }
            }
        }
    }
}
