//! Convex clipping: a planar convex polygon cut by a plane, and cut along the outline of a convex polygon
//! into the piece inside the outline and convex pieces covering the rest (the regions outside one edge of
//! the outline and inside the edges before it). Used to split surfaces along the outlines of objects that
//! touch them ([`crate::scene::contacts`]).
//!
//! Exactness: the pieces share their vertices bit for bit (an edge crossing a plane is cut at one point,
//! computed from the edge's lexicographically smaller end whichever way the edge is walked), and vertices
//! within `snap` of a plane count as lying on it, so that no piece is thinner than `snap` and the pieces
//! tile the polygon: their areas sum to its area up to rounding.

use super::{DVec2, DVec3};

/// A cutting plane through `point` with unit `normal`: points with `normal · (p − point) > 0` are outside.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Plane {
    pub point: DVec3,
    pub normal: DVec3,
}

impl Plane {
    pub fn distance(&self, p: DVec3) -> f64 {
        self.normal.dot(p - self.point)
    }
}

/// The planes through the edges of the convex `outline` that contain the direction `normal`: cutting a
/// polygon of that plane with them cuts it along the outline projected onto it. `outline` must be
/// counter-clockwise seen from the front of `normal`; its inside is the inside of every plane.
pub fn outline_planes(outline: &[DVec3], normal: DVec3) -> Vec<Plane> {
    (0..outline.len())
        .filter_map(|k| {
            let (a, b) = (outline[k], outline[(k + 1) % outline.len()]);
            let outward = (b - a).cross(normal);
            (outward.length_squared() > 0.0).then(|| Plane {
                point: a,
                normal: outward.normalize(),
            })
        })
        .collect()
}

/// Splits the convex polygon `polygon` by `plane` into its parts inside and outside (each empty when the
/// polygon lies, up to `snap`, on the other side). Vertex order, and so the winding, is kept.
pub fn split_by_plane(polygon: &[DVec3], plane: &Plane, snap: f64) -> (Vec<DVec3>, Vec<DVec3>) {
    let distances: Vec<f64> = polygon.iter().map(|&p| plane.distance(p)).collect();
    let side = |d: f64| {
        if d > snap {
            1
        } else if d < -snap {
            -1
        } else {
            0
        }
    };
    let sides: Vec<i32> = distances.iter().map(|&d| side(d)).collect();
    if !sides.contains(&1) {
        return (polygon.to_vec(), Vec::new());
    }
    if !sides.contains(&-1) {
        return (Vec::new(), polygon.to_vec());
    }
    let (mut inside, mut outside) = (Vec::new(), Vec::new());
    let n = polygon.len();
    for k in 0..n {
        let j = (k + 1) % n;
        if sides[k] <= 0 {
            inside.push(polygon[k]);
        }
        if sides[k] >= 0 {
            outside.push(polygon[k]);
        }
        if sides[k] * sides[j] < 0 {
            let cut = crossing(polygon[k], distances[k], polygon[j], distances[j]);
            inside.push(cut);
            outside.push(cut);
        }
    }
    (inside, outside)
}

/// Where the segment from `a` (signed distance `da`) to `b` (`db`, of the other sign) crosses the plane,
/// computed the same way whichever end comes first.
fn crossing(a: DVec3, da: f64, b: DVec3, db: f64) -> DVec3 {
    let (p, dp, q, dq) = if a.to_array() <= b.to_array() {
        (a, da, b, db)
    } else {
        (b, db, a, da)
    };
    p + (q - p) * (dp / (dp - dq))
}

/// Cuts the convex `polygon` along a convex outline given by its [`outline_planes`]: the pieces outside
/// each edge (and inside the edges before it), then the piece inside the outline. `None` when the outline
/// does not cross the polygon's interior (they do not overlap by more than `snap`, or the polygon lies
/// inside the outline).
pub fn split_by_outline(polygon: &[DVec3], planes: &[Plane], snap: f64) -> Option<Vec<Vec<DVec3>>> {
    let mut remaining = polygon.to_vec();
    let mut pieces = Vec::new();
    for plane in planes {
        let (inside, outside) = split_by_plane(&remaining, plane, snap);
        if inside.is_empty() {
            return None;
        }
        if !outside.is_empty() {
            pieces.push(outside);
        }
        remaining = inside;
    }
    if pieces.is_empty() {
        return None;
    }
    pieces.push(remaining);
    Some(pieces)
}

/// Cuts the convex `polygon` along a convex outline given by its [`outline_planes`] like a pinwheel:
/// for each edge k, the part of the polygon outside edge k and inside the line of edge k + 1 (the
/// outside of a convex outline is split by which edge a point is last outside of, going round), then
/// the part inside the outline. Each part is convex and reaches from the outline to the polygon's
/// boundary; [`split_by_outline`] instead cuts the rest of the polygon along each edge's whole line,
/// which around an outline inside the polygon leaves strips as wide as the outline across it (a
/// chair's 2.5 cm foot cut a 4.5 m floor into 2.5 cm strips). `None` when the outline does not cross
/// the polygon's interior.
pub fn split_pinwheel(polygon: &[DVec3], planes: &[Plane], snap: f64) -> Option<Vec<Vec<DVec3>>> {
    let mut inside = polygon.to_vec();
    for plane in planes {
        inside = split_by_plane(&inside, plane, snap).0;
        if inside.is_empty() {
            return None;
        }
    }
    let n = planes.len();
    let mut pieces: Vec<Vec<DVec3>> = (0..n)
        .filter_map(|k| {
            let outside = split_by_plane(polygon, &planes[k], snap).1;
            let piece = split_by_plane(&outside, &planes[(k + 1) % n], snap).0;
            (piece.len() >= 3 && polygon_area(&piece) > snap * snap).then_some(piece)
        })
        .collect();
    if pieces.is_empty() {
        return None;
    }
    pieces.push(inside);
    Some(pieces)
}

/// Area of a planar polygon (Newell's vector area).
pub fn polygon_area(polygon: &[DVec3]) -> f64 {
    super::vector_area(polygon).length()
}

/// Convex hull of points in the plane (Andrew's monotone chain), counter-clockwise, without collinear
/// points; fewer than three points when they are collinear.
pub fn convex_hull(points: &[DVec2]) -> Vec<DVec2> {
    let mut sorted: Vec<DVec2> = points.to_vec();
    sorted.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
    sorted.dedup();
    if sorted.len() < 3 {
        return sorted;
    }
    let turn = |o: DVec2, a: DVec2, b: DVec2| (a - o).perp_dot(b - o);
    let mut hull: Vec<DVec2> = Vec::with_capacity(2 * sorted.len());
    for pass in 0..2 {
        let start = hull.len();
        let points: Box<dyn Iterator<Item = &DVec2>> = if pass == 0 {
            Box::new(sorted.iter())
        } else {
            Box::new(sorted.iter().rev())
        };
        for &p in points {
            while hull.len() >= start + 2
                && turn(hull[hull.len() - 2], hull[hull.len() - 1], p) <= 0.0
            {
                hull.pop();
            }
            hull.push(p);
        }
        hull.pop();
    }
    hull
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square(x0: f64, y0: f64, side: f64) -> Vec<DVec3> {
        vec![
            DVec3::new(x0, y0, 0.0),
            DVec3::new(x0 + side, y0, 0.0),
            DVec3::new(x0 + side, y0 + side, 0.0),
            DVec3::new(x0, y0 + side, 0.0),
        ]
    }

    #[test]
    fn a_square_inside_a_square_gives_the_hole_and_four_pieces_around_it() {
        let outer = square(0.0, 0.0, 10.0);
        let planes = outline_planes(&square(4.0, 4.0, 1.0), DVec3::Z);
        let pieces = split_by_outline(&outer, &planes, 1e-9).unwrap();
        assert_eq!(pieces.len(), 5);
        let total: f64 = pieces.iter().map(|p| polygon_area(p)).sum();
        assert!((total - 100.0).abs() <= 1e-12 * 100.0);
        assert!((polygon_area(pieces.last().unwrap()) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn outlines_that_miss_touch_or_cover_the_polygon_do_not_split_it() {
        let polygon = square(0.0, 0.0, 1.0);
        for outline in [
            square(2.0, 0.0, 1.0),
            square(1.0, 0.0, 1.0),
            square(-1.0, -1.0, 3.0),
        ] {
            let planes = outline_planes(&outline, DVec3::Z);
            assert!(split_by_outline(&polygon, &planes, 1e-9).is_none());
            assert!(split_pinwheel(&polygon, &planes, 1e-9).is_none());
        }
    }

    /// A 0.1 square foot inside a 4 × 4 floor: the pinwheel's four pieces are each at least as wide as
    /// the foot's distance to the floor's edges (no strip as narrow as the foot, which the straight cut
    /// leaves), and with the foot they tile the floor; a foot across the floor's edge cuts it too.
    #[test]
    fn a_pinwheel_cut_leaves_no_strip_as_narrow_as_the_outline() {
        let floor = square(0.0, 0.0, 4.0);
        let foot = outline_planes(&square(1.0, 2.0, 0.1), DVec3::Z);
        let pinwheel = split_pinwheel(&floor, &foot, 1e-9).unwrap();
        assert_eq!(pinwheel.len(), 5);
        let areas: Vec<f64> = pinwheel.iter().map(|p| polygon_area(p)).collect();
        assert!((areas.iter().sum::<f64>() - 16.0).abs() < 1e-12);
        assert!((areas[4] - 0.01).abs() < 1e-12, "the foot last");
        // Bottom [0, 1.1] × [0, 2], right [1.1, 4] × [0, 2.1], top [1, 4] × [2.1, 4], left [0, 1] × [2, 4].
        for (area, expected) in areas.iter().zip([2.2, 6.09, 5.7, 2.0]) {
            assert!((area - expected).abs() < 1e-12, "{areas:?}");
        }
        let straight = split_by_outline(&floor, &foot, 1e-9).unwrap();
        // Its pieces around the foot (the foot last) include 0.1-wide strips of area 0.2 and 0.19.
        let around = &straight[..straight.len() - 1];
        let narrowest = around
            .iter()
            .map(|p| polygon_area(p))
            .fold(f64::MAX, f64::min);
        assert!(
            narrowest < 0.2 + 1e-12,
            "the straight cut's strips: {narrowest}"
        );
        let across = split_pinwheel(
            &floor,
            &outline_planes(&square(3.5, 1.0, 1.0), DVec3::Z),
            1e-9,
        )
        .unwrap();
        let total: f64 = across.iter().map(|p| polygon_area(p)).sum();
        assert!((total - 16.0).abs() < 1e-12);
        assert!((polygon_area(across.last().unwrap()) - 0.5).abs() < 1e-12);
    }

    #[test]
    fn the_hull_of_a_footprint_drops_inner_and_collinear_points() {
        let points = [
            (0.0, 0.0),
            (2.0, 0.0),
            (1.0, 0.0),
            (2.0, 1.0),
            (0.0, 1.0),
            (1.0, 0.5),
            (0.0, 1.0),
        ]
        .map(|(x, y)| DVec2::new(x, y));
        let hull = convex_hull(&points);
        assert_eq!(hull.len(), 4);
        let area2: f64 = (0..4).map(|k| hull[k].perp_dot(hull[(k + 1) % 4])).sum();
        assert!((area2 - 4.0).abs() < 1e-12, "counter-clockwise, area 2");
        assert!(
            convex_hull(&points[..3]).len() < 3,
            "collinear points have no hull"
        );
    }

    #[test]
    fn an_outline_edge_within_snap_of_a_vertex_leaves_no_sliver() {
        let polygon = square(0.0, 0.0, 1.0);
        // The outline's left edge passes 1e-10 from the polygon's right side: no piece that thin.
        let planes = outline_planes(&square(1.0 - 1e-10, 0.25, 0.5), DVec3::Z);
        assert!(split_by_outline(&polygon, &planes, 1e-9).is_none());
    }
}
