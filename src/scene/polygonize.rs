//! Splits an arbitrary planar simple polygon (convex or not, with MGF seam holes) into the planar convex
//! triangles and quads of the scene model.
//!
//! Method: drop repeated and collinear vertices, project onto the plane of the Newell normal, then clip
//! ears in that plane (an ear is a convex corner whose triangle holds no other vertex). Adjacent triangle
//! pairs that form a convex quad are merged back. Seam holes (a boundary that runs out to a hole and back
//! along the same edge) are weakly simple polygons: vertices coincident with an ear's corners are copies
//! of the same seam point and are not counted as "inside", which lets the clipper walk around the hole.

use crate::geometry::{vector_area, DVec2, DVec3, Shape};
use std::fmt;

/// Vertices closer than this fraction of the polygon's size are the same vertex.
const MERGE_TOLERANCE: f64 = 1e-9;
/// Twice-area (cross product) below this fraction of size² is zero: collinear corners, degenerate ears.
const AREA_TOLERANCE: f64 = 1e-12;
/// A polygon whose vertices leave its mean plane by more than this fraction of its size is non-planar.
pub const PLANARITY_TOLERANCE: f64 = 1e-3;
/// Most vertices of one polygon (ear clipping is quadratic in them).
pub const MAX_VERTICES: usize = 10_000;

/// Why a polygon was rejected.
#[derive(Clone, Debug, PartialEq)]
pub enum PolygonError {
    /// Fewer than three distinct vertices after merging repeats.
    TooFewVertices(usize),
    /// A coordinate is NaN or infinite.
    NotFinite,
    /// So large that its area overflows (its extent squared is not a finite `f64`).
    TooLarge,
    /// The polygon encloses no area (collinear or coincident vertices).
    ZeroArea,
    /// More than [`MAX_VERTICES`] vertices.
    TooManyVertices(usize),
}

impl fmt::Display for PolygonError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            PolygonError::TooFewVertices(n) => {
                write!(f, "degenerate polygon: only {n} distinct vertices")
            }
            PolygonError::NotFinite => write!(f, "polygon has a non-finite coordinate"),
            PolygonError::TooLarge => write!(f, "polygon too large: its area overflows"),
            PolygonError::ZeroArea => write!(f, "degenerate polygon: zero area"),
            PolygonError::TooManyVertices(n) => {
                write!(f, "polygon has {n} vertices, more than {MAX_VERTICES}")
            }
        }
    }
}

/// The convex pieces of one polygon and the problems met on the way (non-planarity, self-overlap).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Polygonized {
    pub shapes: Vec<Shape>,
    pub warnings: Vec<String>,
}

/// Splits `points` (the boundary in order; its winding gives the front side by the right-hand rule) into
/// triangles and convex quads with the same front side. Non-planar polygons become triangles only.
pub fn polygonize(points: &[DVec3]) -> Result<Polygonized, PolygonError> {
    if points.len() > MAX_VERTICES {
        return Err(PolygonError::TooManyVertices(points.len()));
    }
    if points.iter().any(|p| !p.is_finite()) {
        return Err(PolygonError::NotFinite);
    }
    let size = extent(points);
    if !(size * size).is_finite() {
        return Err(PolygonError::TooLarge);
    }
    let mut pts = merge_repeats(points, MERGE_TOLERANCE * size);
    if pts.len() < 3 {
        return Err(PolygonError::TooFewVertices(pts.len()));
    }
    let normal = vector_area(&pts);
    let area = normal.length();
    if area <= AREA_TOLERANCE * size * size || size == 0.0 {
        return Err(PolygonError::ZeroArea);
    }
    let n = normal / normal.length();
    let (u, v) = n.any_orthonormal_pair();
    let origin = pts.iter().copied().sum::<DVec3>() / pts.len() as f64;
    let mut warnings = Vec::new();
    let deviation = pts
        .iter()
        .map(|p| (*p - origin).dot(n).abs())
        .fold(0.0, f64::max);
    let planar = deviation <= PLANARITY_TOLERANCE * size;
    if !planar {
        warnings.push(format!(
            "non-planar polygon (a vertex is {:.3}% of its size off its plane): split into triangles",
            100.0 * deviation / size
        ));
    }
    // (u, v, n) is right-handed, so the boundary is counter-clockwise in (u, v).
    let project = |p: &DVec3| DVec2::new((*p - origin).dot(u), (*p - origin).dot(v));
    let mut flat: Vec<DVec2> = pts.iter().map(project).collect();
    drop_collinear(&mut pts, &mut flat, AREA_TOLERANCE * size * size);
    if pts.len() < 3 {
        return Err(PolygonError::ZeroArea);
    }
    let eps = AREA_TOLERANCE * size * size;
    let shapes = if pts.len() == 3 {
        vec![Shape::Triangle([pts[0], pts[1], pts[2]])]
    } else if pts.len() == 4 && planar && strictly_convex(&flat, eps) {
        vec![Shape::Quad([pts[0], pts[1], pts[2], pts[3]])]
    } else {
        let triangles = ear_clip(&flat, eps, MERGE_TOLERANCE * size);
        let covered: f64 = triangles
            .iter()
            .map(|t| 0.5 * cross(flat[t[0]], flat[t[1]], flat[t[2]]))
            .sum();
        let expected = 0.5 * signed_area2(&flat);
        if (covered - expected).abs() > 1e-6 * expected.abs() {
            warnings.push(format!(
                "self-intersecting polygon: its triangles cover {:.4}% of its signed area",
                100.0 * covered / expected
            ));
        }
        let pieces = if planar {
            merge_quads(&flat, triangles, eps)
        } else {
            triangles.into_iter().map(|t| t.to_vec()).collect()
        };
        pieces
            .iter()
            .map(|p| match p.as_slice() {
                [a, b, c] => Shape::Triangle([pts[*a], pts[*b], pts[*c]]),
                [a, b, c, d] => Shape::Quad([pts[*a], pts[*b], pts[*c], pts[*d]]),
                _ => unreachable!("pieces have three or four corners"),
            })
            .collect()
    };
    Ok(Polygonized { shapes, warnings })
}

fn extent(points: &[DVec3]) -> f64 {
    let (lo, hi) = points.iter().fold(
        (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    );
    if points.is_empty() {
        0.0
    } else {
        (hi - lo).max_element()
    }
}

/// Removes consecutive repeats (and a closing copy of the first vertex).
fn merge_repeats(points: &[DVec3], tolerance: f64) -> Vec<DVec3> {
    let mut out: Vec<DVec3> = Vec::with_capacity(points.len());
    for p in points {
        if out.last().is_none_or(|q| q.distance(*p) > tolerance) {
            out.push(*p);
        }
    }
    while out.len() > 1 && out[0].distance(out[out.len() - 1]) <= tolerance {
        out.pop();
    }
    out
}

/// Twice the signed area of triangle (a, b, c): positive when counter-clockwise.
fn cross(a: DVec2, b: DVec2, c: DVec2) -> f64 {
    (b - a).perp_dot(c - a)
}

fn signed_area2(p: &[DVec2]) -> f64 {
    (0..p.len())
        .map(|k| p[k].perp_dot(p[(k + 1) % p.len()]))
        .sum()
}

/// Drops corners with zero turn (straight-through points and zero-width spikes): they carry no area.
fn drop_collinear(pts: &mut Vec<DVec3>, flat: &mut Vec<DVec2>, eps: f64) {
    let mut k = 0;
    let mut unchanged = 0;
    while flat.len() >= 3 && unchanged < flat.len() {
        let m = flat.len();
        let (a, b, c) = (flat[(k + m - 1) % m], flat[k % m], flat[(k + 1) % m]);
        if cross(a, b, c).abs() <= eps {
            flat.remove(k % m);
            pts.remove(k % m);
            unchanged = 0;
            if k >= flat.len() {
                k = 0;
            }
        } else {
            k = (k + 1) % m;
            unchanged += 1;
        }
    }
}

fn strictly_convex(p: &[DVec2], eps: f64) -> bool {
    let m = p.len();
    (0..m).all(|k| cross(p[(k + m - 1) % m], p[k], p[(k + 1) % m]) > eps)
}

/// Whether `p` lies in triangle (a, b, c) (counter-clockwise), boundary included within `eps`.
fn in_triangle(p: DVec2, a: DVec2, b: DVec2, c: DVec2, eps: f64) -> bool {
    cross(a, b, p) >= -eps && cross(b, c, p) >= -eps && cross(c, a, p) >= -eps
}

/// Whether `p` lies on segment (a, b) within the area tolerance.
fn on_segment(p: DVec2, a: DVec2, b: DVec2, eps: f64) -> bool {
    cross(a, b, p).abs() <= eps && (p - a).dot(b - a) >= 0.0 && (p - b).dot(a - b) >= 0.0
}

/// Ear clipping of a counter-clockwise polygon; returns counter-clockwise index triangles.
fn ear_clip(p: &[DVec2], eps: f64, same: f64) -> Vec<[usize; 3]> {
    let mut ring: Vec<usize> = (0..p.len()).collect();
    let mut triangles = Vec::with_capacity(p.len().saturating_sub(2));
    // The search for the next ear starts where the last one was clipped (linear per ear on the
    // polygons met in practice instead of rescanning the same reflex corners).
    let mut start = 0;
    while ring.len() > 3 {
        let m = ring.len();
        let corner = |k: usize| (ring[(k + m - 1) % m], ring[k], ring[(k + 1) % m]);
        let is_ear = |k: usize| {
            let (a, b, c) = corner(k);
            let (pa, pb, pc) = (p[a], p[b], p[c]);
            if cross(pa, pb, pc) <= eps {
                return false;
            }
            ring.iter().all(|&i| {
                let q = p[i];
                if i == a || i == b || i == c {
                    return true;
                }
                // Seam copies of a corner are the same point, not an obstacle.
                if q.distance(pa) <= same || q.distance(pb) <= same || q.distance(pc) <= same {
                    return true;
                }
                if !in_triangle(q, pa, pb, pc, eps) {
                    return true;
                }
                // Points on the polygon's own edges (a, b) and (b, c) stay on the boundary afterwards;
                // anything else inside or on the new diagonal (c, a) blocks the ear.
                !on_segment(q, pc, pa, eps)
                    && (on_segment(q, pa, pb, eps) || on_segment(q, pb, pc, eps))
            })
        };
        // Prefer the best-shaped ear on small polygons; take the first one on large ones.
        let mut chosen: Option<(usize, f64)> = None;
        for k in (start.min(m)..m).chain(0..start.min(m)) {
            if is_ear(k) {
                let (a, b, c) = corner(k);
                let quality = shape_quality(p[a], p[b], p[c]);
                if chosen.is_none_or(|(_, q)| quality > q) {
                    chosen = Some((k, quality));
                }
                if m > 64 {
                    break;
                }
            }
        }
        // No ear: the polygon self-intersects. Clip the most convex corner so the loop always ends; the
        // caller reports the area mismatch.
        let k = chosen.map(|(k, _)| k).unwrap_or_else(|| {
            (0..m)
                .max_by(|&i, &j| {
                    let (a, b, c) = corner(i);
                    let (d, e, f) = corner(j);
                    cross(p[a], p[b], p[c]).total_cmp(&cross(p[d], p[e], p[f]))
                })
                .unwrap_or(0)
        });
        let (a, b, c) = corner(k);
        if cross(p[a], p[b], p[c]) > eps {
            triangles.push([a, b, c]);
        }
        ring.remove(k);
        start = k.saturating_sub(1);
    }
    if let [a, b, c] = ring[..] {
        if cross(p[a], p[b], p[c]) > eps {
            triangles.push([a, b, c]);
        }
    }
    triangles
}

/// Area over squared perimeter: 0 for slivers, largest for equilateral triangles.
fn shape_quality(a: DVec2, b: DVec2, c: DVec2) -> f64 {
    let perimeter = a.distance(b) + b.distance(c) + c.distance(a);
    cross(a, b, c) / (perimeter * perimeter)
}

/// Greedily merges triangles sharing an edge into strictly convex quads.
fn merge_quads(p: &[DVec2], triangles: Vec<[usize; 3]>, eps: f64) -> Vec<Vec<usize>> {
    let mut used = vec![false; triangles.len()];
    let mut out = Vec::with_capacity(triangles.len());
    // Directed edge -> triangle holding it, so that neighbours are found without a quadratic search.
    let mut edges = std::collections::HashMap::with_capacity(3 * triangles.len());
    for (j, t) in triangles.iter().enumerate() {
        for r in 0..3 {
            edges.entry((t[r], t[(r + 1) % 3])).or_insert(j);
        }
    }
    for i in 0..triangles.len() {
        if used[i] {
            continue;
        }
        used[i] = true;
        let mut merged = None;
        let mut neighbours: Vec<usize> = (0..3)
            .filter_map(|r| {
                let (a, b) = (triangles[i][r], triangles[i][(r + 1) % 3]);
                edges.get(&(b, a)).copied()
            })
            .collect();
        neighbours.sort_unstable();
        'search: for j in neighbours {
            if used[j] || j <= i {
                continue;
            }
            for r in 0..3 {
                // Triangle i rotated to (x, y, z) with shared edge y -> z.
                let (x, y, z) = (
                    triangles[i][r],
                    triangles[i][(r + 1) % 3],
                    triangles[i][(r + 2) % 3],
                );
                for s in 0..3 {
                    let (z2, y2, w) = (
                        triangles[j][s],
                        triangles[j][(s + 1) % 3],
                        triangles[j][(s + 2) % 3],
                    );
                    if z2 == z && y2 == y {
                        let quad = [x, y, w, z];
                        let corners: Vec<DVec2> = quad.iter().map(|&q| p[q]).collect();
                        if strictly_convex(&corners, eps) {
                            merged = Some((j, quad));
                            break 'search;
                        }
                    }
                }
            }
        }
        match merged {
            Some((j, quad)) => {
                used[j] = true;
                out.push(quad.to_vec());
            }
            None => out.push(triangles[i].to_vec()),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn v(x: f64, y: f64) -> DVec3 {
        DVec3::new(x, y, 0.0)
    }

    fn total_area(shapes: &[Shape]) -> f64 {
        shapes.iter().map(Shape::area).sum()
    }

    fn assert_front(shapes: &[Shape], normal: DVec3) {
        for s in shapes {
            assert!(s.normal().dot(normal) > 0.999, "{s:?} faces the wrong way");
        }
    }

    #[test]
    fn triangles_and_convex_quads_pass_through() {
        let t = polygonize(&[v(0.0, 0.0), v(1.0, 0.0), v(0.0, 1.0)]).unwrap();
        assert_eq!(t.shapes.len(), 1);
        let q = polygonize(&[v(0.0, 0.0), v(1.0, 0.0), v(1.0, 1.0), v(0.0, 1.0)]).unwrap();
        assert!(matches!(q.shapes[..], [Shape::Quad(_)]));
        assert!(q.warnings.is_empty());
    }

    #[test]
    fn l_shape_keeps_area_and_orientation() {
        // The corridor floor: an L-shaped hexagon.
        let l = [
            v(-5.0, 0.0),
            v(5.0, 0.0),
            v(5.0, 10.0),
            v(15.0, 10.0),
            v(15.0, 20.0),
            v(-5.0, 20.0),
        ];
        let out = polygonize(&l).unwrap();
        assert!((total_area(&out.shapes) - 300.0).abs() < 1e-9);
        assert_front(&out.shapes, DVec3::Z);
        assert!(out.shapes.len() <= 4);
        // Reversed winding gives the back side.
        let mut r = l;
        r.reverse();
        let out = polygonize(&r).unwrap();
        assert_front(&out.shapes, -DVec3::Z);
    }

    #[test]
    fn seam_hole_is_cut_out() {
        // 10 x 10 square with a 4 x 4 hole joined by a seam (vertex 0 -> hole -> back to vertex 0).
        let poly = [
            v(0.0, 0.0),
            v(10.0, 0.0),
            v(10.0, 10.0),
            v(0.0, 10.0),
            v(0.0, 0.0),
            v(3.0, 3.0),
            v(3.0, 7.0),
            v(7.0, 7.0),
            v(7.0, 3.0),
            v(3.0, 3.0),
        ];
        let out = polygonize(&poly).unwrap();
        assert!((total_area(&out.shapes) - 84.0).abs() < 1e-9, "{out:?}");
        assert_front(&out.shapes, DVec3::Z);
        assert!(out.warnings.is_empty(), "{:?}", out.warnings);
        // No piece covers the hole centre.
        for s in &out.shapes {
            let c = s.centroid();
            assert!(!(c.x > 3.0 && c.x < 7.0 && c.y > 3.0 && c.y < 7.0));
        }
    }

    #[test]
    fn window_with_t_junction_seam() {
        // office3's wall: the seam runs back along the window's lower edge through a hole vertex.
        let poly = [
            v(30.0, 15.5),
            v(-30.0, 15.5),
            v(-30.0, 51.0),
            v(30.0, 51.0),
            v(30.0, 26.0),
            v(23.5, 26.0),
            v(23.5, 43.0),
            v(-23.5, 43.0),
            v(-23.5, 26.0),
            v(30.0, 26.0),
        ];
        let out = polygonize(&poly).unwrap();
        let expected = 60.0 * 35.5 - 47.0 * 17.0;
        assert!((total_area(&out.shapes) - expected).abs() < 1e-9, "{out:?}");
        assert_front(&out.shapes, -DVec3::Z);
        assert!(out.warnings.is_empty(), "{:?}", out.warnings);
    }

    #[test]
    fn degenerate_and_non_planar() {
        assert_eq!(
            polygonize(&[v(0.0, 0.0), v(1.0, 0.0), v(2.0, 0.0)]),
            Err(PolygonError::ZeroArea)
        );
        assert_eq!(
            polygonize(&[v(0.0, 0.0), v(1.0, 0.0), v(1.0, 0.0)]),
            Err(PolygonError::TooFewVertices(2))
        );
        assert_eq!(
            polygonize(&[v(0.0, 0.0), v(f64::NAN, 0.0), v(1.0, 1.0)]),
            Err(PolygonError::NotFinite)
        );
        assert_eq!(
            polygonize(&[v(0.0, 0.0), v(1e300, 0.0), v(0.0, 1e300)]),
            Err(PolygonError::TooLarge)
        );
        let bent = [
            v(0.0, 0.0),
            v(1.0, 0.0),
            DVec3::new(1.0, 1.0, 0.2),
            v(0.0, 1.0),
        ];
        let out = polygonize(&bent).unwrap();
        assert_eq!(out.shapes.len(), 2);
        assert!(out.shapes.iter().all(|s| s.vertex_count() == 3));
        assert!(out.warnings[0].contains("non-planar"));
    }

    #[test]
    fn bow_tie_is_reported() {
        let out = polygonize(&[v(0.0, 0.0), v(1.0, 1.0), v(1.0, 0.0), v(0.0, 1.0)]);
        // A symmetric bow tie has zero signed area.
        assert_eq!(out, Err(PolygonError::ZeroArea));
        let out =
            polygonize(&[v(0.0, 0.0), v(2.0, 2.0), v(2.0, 0.0), v(0.0, 1.0)]).unwrap_or_default();
        assert!(out.warnings.iter().any(|w| w.contains("self-intersecting")));
    }

    #[test]
    fn regular_polygon_merges_into_quads() {
        let n = 12;
        let pts: Vec<DVec3> = (0..n)
            .map(|k| {
                let a = std::f64::consts::TAU * k as f64 / n as f64;
                v(a.cos(), a.sin())
            })
            .collect();
        let out = polygonize(&pts).unwrap();
        let exact = 0.5 * n as f64 * (std::f64::consts::TAU / n as f64).sin();
        assert!((total_area(&out.shapes) - exact).abs() < 1e-12);
        assert!(
            out.shapes.len() < n - 2,
            "quads merged: {}",
            out.shapes.len()
        );
        for s in &out.shapes {
            let corners = s.vertices();
            let m = corners.len();
            for k in 0..m {
                let e1 = corners[(k + 1) % m] - corners[k];
                let e2 = corners[(k + 2) % m] - corners[(k + 1) % m];
                assert!(e1.cross(e2).z > 0.0, "convex");
            }
        }
    }
}
