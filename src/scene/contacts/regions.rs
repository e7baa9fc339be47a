//! Emitting regions: adjacent coplanar polygons that emit toward the same sides, taken together.
//!
//! Why: a lamp is rarely one polygon. OBJ and glTF lamps are triangle meshes, MGF lamps may be several
//! faces, round IES openings are fans of quads. Judged one polygon at a time, such a lamp lies on a
//! ceiling only within each small triangle's gap (2% of the triangle's size, which a 1 cm gap exceeds),
//! and when it is found, the ceiling is cut along every internal edge. A region is judged by its own
//! size and cuts along its own outline.
//!
//! A region's outline is given as convex pieces whose union is the region (the clipper,
//! [`crate::geometry::clip::split_by_outline`], cuts along convex outlines only): the convex hull when
//! the region is convex (a rectangular or round lamp, however tessellated: one outline), otherwise the
//! members merged greedily while two adjacent pieces' union is convex (Hertel–Mehlhorn style: at most
//! about four times the fewest convex pieces). A surface under a non-convex lamp is then also cut along
//! the few diagonals between its pieces, which lie under the lamp, inside the gap.

use super::{BoxGrid, Face, SNAP};
use crate::geometry::clip::convex_hull;
use crate::geometry::{Aabb, DVec2, DVec3};
use crate::scene::Scene;

/// Normals of coplanar members differ by at most this angle (radians), and their vertices lie within
/// this fraction of the larger member's diameter of each other's plane: lamps from single-precision
/// files (OBJ, glTF) are coplanar to about 1e-6 of the scene's size, i.e. much worse for small
/// triangles.
const COPLANAR: f64 = 1e-3;
/// Members touch along an edge when two points of one lie, at least this fraction of the smaller
/// member's diameter apart, within it of the other's boundary.
const TOUCH: f64 = 1e-4;
/// Regions with more members are not merged into convex pieces (each member is its own piece):
/// greedy merging is quadratic in a region's pieces at worst.
const MAX_MERGED_MEMBERS: usize = 4096;

/// Adjacent coplanar polygons that emit toward the same sides.
pub(super) struct Region {
    /// Plane (the first member's normal), size and box of the whole region.
    pub face: Face,
    /// Whether it emits toward `face.normal` and toward its opposite.
    pub shines: [bool; 2],
    /// Convex outlines whose union is the region, counter-clockwise seen from `face.normal`.
    pub pieces: Vec<Vec<DVec3>>,
}

impl Region {
    /// Whether it emits toward the half-space of `direction`.
    pub fn shines_toward(&self, direction: DVec3) -> bool {
        let along = self.face.normal.dot(direction);
        (self.shines[0] && along > 0.0) || (self.shines[1] && along < 0.0)
    }

    /// Every corner of its pieces (its extreme points among them).
    pub fn corners(&self) -> impl Iterator<Item = DVec3> + '_ {
        self.pieces.iter().flatten().copied()
    }
}

/// The sides toward which polygon `i` emits: [front, back]. A Lambertian emitter toward its front, and
/// its back when two-sided; an IES luminaire's opening face toward its outward normal (both sides of a
/// flat opening), where the luminaire's table sends light
/// ([`crate::scene::luminaire::Luminaire::shines_toward`]).
fn emitting_sides(scene: &Scene, i: usize, opening: Option<u32>) -> [bool; 2] {
    let polygon = &scene.polygons[i];
    match opening {
        Some(k) => {
            let luminaire = &scene.luminaires[k as usize];
            let n = polygon.shape.normal();
            [
                luminaire.shines_toward(n),
                luminaire.flat && luminaire.shines_toward(-n),
            ]
        }
        None if !scene.material_of(polygon).emission.is_black() => [true, polygon.two_sided],
        None => [false, false],
    }
}

/// The emitting regions of `scene` (`faces` and `grid` are its polygons'), in the order of their first
/// members.
pub(super) fn emitting_regions(scene: &Scene, faces: &[Face], grid: &BoxGrid) -> Vec<Region> {
    let openings = scene.opening_luminaires();
    let sides: Vec<[bool; 2]> = (0..scene.polygons.len())
        .map(|i| emitting_sides(scene, i, openings[i]))
        .collect();
    let emits = |i: usize| faces[i].diameter > 0.0 && (sides[i][0] || sides[i][1]);
    // The sides as seen from the plane of polygon `to`'s normal.
    let sides_as = |i: usize, to: usize| {
        if faces[i].normal.dot(faces[to].normal) >= 0.0 {
            sides[i]
        } else {
            [sides[i][1], sides[i][0]]
        }
    };
    let mut root: Vec<usize> = (0..faces.len()).collect();
    let mut neighbours: Vec<Vec<usize>> = vec![Vec::new(); faces.len()];
    for i in (0..faces.len()).filter(|&i| emits(i)) {
        let reach = TOUCH * faces[i].diameter;
        for j in grid.near(&faces[i].bounds, reach) {
            if j <= i
                || !emits(j)
                || openings[i] != openings[j]
                || sides_as(j, i) != sides[i]
                || !coplanar(scene, faces, i, j, COPLANAR)
                || !touch_along_an_edge(scene, faces, i, j)
            {
                continue;
            }
            neighbours[i].push(j);
            neighbours[j].push(i);
            let (a, b) = (find(&mut root, i), find(&mut root, j));
            root[a.max(b)] = a.min(b);
        }
    }
    let mut members: Vec<Vec<usize>> = vec![Vec::new(); faces.len()];
    for i in (0..faces.len()).filter(|&i| emits(i)) {
        let r = find(&mut root, i);
        members[r].push(i);
    }
    members
        .into_iter()
        .filter(|m| !m.is_empty())
        .map(|m| region(scene, faces, &neighbours, sides[m[0]], &m))
        .collect()
}

/// The representative of `i`'s set (union–find with path halving).
fn find(root: &mut [usize], mut i: usize) -> usize {
    while root[i] != i {
        root[i] = root[root[i]];
        i = root[i];
    }
    i
}

/// Whether polygons `i` and `j` lie in one plane: normals within `tolerance` radians, and every vertex
/// of each within `tolerance` times the larger diameter of the other's plane.
pub(super) fn coplanar(scene: &Scene, faces: &[Face], i: usize, j: usize, tolerance: f64) -> bool {
    let distance = tolerance * faces[i].diameter.max(faces[j].diameter);
    // cos(t) to within t⁴/24.
    faces[i].normal.dot(faces[j].normal).abs() >= 1.0 - 0.5 * tolerance * tolerance
        && [(i, j), (j, i)].iter().all(|&(a, b)| {
            scene.polygons[a]
                .shape
                .vertices()
                .iter()
                .all(|&v| faces[b].distance(v).abs() <= distance)
        })
}

/// Whether polygons `i` and `j` share a piece of boundary (not just a corner): two points, apart by
/// more than the tolerance, each a vertex of one on the other's boundary.
fn touch_along_an_edge(scene: &Scene, faces: &[Face], i: usize, j: usize) -> bool {
    let tolerance = TOUCH * faces[i].diameter.min(faces[j].diameter);
    let on_boundary = |p: DVec3, of: usize| {
        let v = scene.polygons[of].shape.vertices();
        crate::geometry::edges(v).any(|(a, b)| segment_distance(p, a, b) <= tolerance)
    };
    let mut touching: Vec<DVec3> = Vec::new();
    for (a, b) in [(i, j), (j, i)] {
        for &p in scene.polygons[a].shape.vertices() {
            if on_boundary(p, b) {
                if touching.iter().any(|q| q.distance(p) > tolerance) {
                    return true;
                }
                touching.push(p);
            }
        }
    }
    false
}

fn segment_distance(p: DVec3, a: DVec3, b: DVec3) -> f64 {
    let d = b - a;
    let t = if d.length_squared() > 0.0 {
        ((p - a).dot(d) / d.length_squared()).clamp(0.0, 1.0)
    } else {
        0.0
    };
    p.distance(a + d * t)
}

/// Members, or convex unions of members: corners counter-clockwise in the region's plane, the same
/// corners in the scene (as the scene has them: a lone member cuts exactly as the polygon did) and the
/// area.
struct Piece {
    corners: Vec<DVec2>,
    points: Vec<DVec3>,
    area: f64,
}

impl Piece {
    /// The convex hull of `pieces`' corners as a piece of their total area (hull corners are among
    /// theirs, so their scene points are found by equality).
    fn hull(pieces: &[&Piece]) -> Piece {
        let corners: Vec<DVec2> = pieces.iter().flat_map(|p| p.corners.clone()).collect();
        let points: Vec<DVec3> = pieces.iter().flat_map(|p| p.points.clone()).collect();
        let hull = convex_hull(&corners);
        let points = hull
            .iter()
            .map(|h| points[corners.iter().position(|c| c == h).unwrap_or(0)])
            .collect();
        Piece {
            corners: hull,
            points,
            area: pieces.iter().map(|p| p.area).sum(),
        }
    }

    /// For a piece made by [`Piece::hull`]: whether its members cover it, up to a strip `SNAP` × its
    /// diameter wide (the clipper's own tolerance), so that their union is convex (they do not overlap:
    /// a scene's polygons do not).
    fn is_covered(&self) -> bool {
        let size = diameter(&self.corners);
        self.corners.len() >= 3 && area(&self.corners) - self.area <= SNAP * size * size
    }
}

/// Area of a counter-clockwise polygon in the plane.
fn area(corners: &[DVec2]) -> f64 {
    0.5 * (0..corners.len())
        .map(|k| corners[k].perp_dot(corners[(k + 1) % corners.len()]))
        .sum::<f64>()
}

/// The largest distance between two of `points`.
fn diameter(points: &[DVec2]) -> f64 {
    let mut d: f64 = 0.0;
    for (k, a) in points.iter().enumerate() {
        for b in &points[k + 1..] {
            d = d.max(a.distance(*b));
        }
    }
    d
}

/// The convex hull of `a` and `b` when it is their union, else `None`.
fn convex_union(a: &Piece, b: &Piece) -> Option<Piece> {
    let hull = Piece::hull(&[a, b]);
    hull.is_covered().then_some(hull)
}

/// The region of `members` (adjacent through `neighbours`), emitting toward `shines` of its first
/// member's normal: its convex pieces (see the module doc).
fn region(
    scene: &Scene,
    faces: &[Face],
    neighbours: &[Vec<usize>],
    shines: [bool; 2],
    members: &[usize],
) -> Region {
    let first = &faces[members[0]];
    let normal = first.normal;
    let origin = first.point;
    let (u, v) = normal.any_orthonormal_pair();
    let flat = |p: DVec3| DVec2::new((p - origin).dot(u), (p - origin).dot(v));
    let mut pieces: Vec<Piece> = members
        .iter()
        .map(|&m| {
            let mut points = scene.polygons[m].shape.vertices().to_vec();
            if faces[m].normal.dot(normal) < 0.0 {
                points.reverse();
            }
            let corners: Vec<DVec2> = points.iter().map(|&p| flat(p)).collect();
            let area = area(&corners);
            Piece {
                corners,
                points,
                area,
            }
        })
        .collect();
    let hull = Piece::hull(&pieces.iter().collect::<Vec<_>>());
    let size = diameter(&hull.corners);
    if members.len() > 1 && hull.is_covered() {
        pieces = vec![hull];
    } else if members.len() <= MAX_MERGED_MEMBERS {
        pieces = merge_convex(pieces, members, neighbours);
    }
    let bounds = members
        .iter()
        .fold(Aabb::EMPTY, |b, &m| b.union(&faces[m].bounds));
    Region {
        face: Face {
            normal,
            point: origin,
            diameter: size,
            area: members.iter().map(|&m| faces[m].area).sum(),
            bounds,
        },
        shines,
        pieces: pieces.into_iter().map(|p| p.points).collect(),
    }
}

/// Greedy merging of adjacent pieces while their union is convex, in member order (deterministic).
fn merge_convex(pieces: Vec<Piece>, members: &[usize], neighbours: &[Vec<usize>]) -> Vec<Piece> {
    let index_of = |m: usize| members.binary_search(&m).ok();
    let mut adjacent: Vec<Vec<usize>> = members
        .iter()
        .map(|&m| neighbours[m].iter().filter_map(|&n| index_of(n)).collect())
        .collect();
    let mut pieces: Vec<Option<Piece>> = pieces.into_iter().map(Some).collect();
    let mut merged = true;
    while merged {
        merged = false;
        for a in 0..pieces.len() {
            let mut k = 0;
            while k < adjacent[a].len() {
                let b = adjacent[a][k];
                k += 1;
                if b == a {
                    continue;
                }
                let (Some(pa), Some(pb)) = (&pieces[a], &pieces[b]) else {
                    continue;
                };
                if let Some(union) = convex_union(pa, pb) {
                    pieces[a] = Some(union);
                    pieces[b] = None;
                    let moved = std::mem::take(&mut adjacent[b]);
                    for &n in &moved {
                        for x in adjacent[n].iter_mut() {
                            if *x == b {
                                *x = a;
                            }
                        }
                    }
                    adjacent[a].extend(moved.into_iter().filter(|&n| n != a));
                    adjacent[a].sort_unstable();
                    adjacent[a].dedup();
                    k = 0;
                    merged = true;
                }
            }
        }
    }
    pieces.into_iter().flatten().collect()
}
