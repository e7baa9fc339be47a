//! Shaft culling (Haines & Wallace 1991, "Shaft culling for efficient ray-cast radiosity"): the volume
//! that every segment between two elements sweeps, the convex hull of the two polygons, tested against
//! a cluster tree of the scene's polygons without casting rays. It decides, for every segment at once,
//! what the link coupling would otherwise sample with one ray per pair of cubature nodes
//! (Bekaert–Willems Algorithm 4.1 step 1): nothing in the way ([`ShaftVerdict::Clear`]), one polygon
//! across all of it ([`ShaftVerdict::Blocked`]), or neither ([`ShaftVerdict::Partial`]). A refined
//! link's shaft lies inside its parent's, so its children inherit a Clear or Blocked verdict with no
//! test at all (Sillion–Drettakis issue item "visibility reuse"; `solvers::refine`), and a Partial
//! verdict's complete occluder list, so that their own tests examine only those polygons instead of
//! walking the tree ([`ShaftPrior::Among`], Haines–Wallace's candidate list passed down).
//!
//! The verdicts are conservative, so that with exact ray casting a coupling computed from them is the
//! one the rays would give: Clear only when no polygon but the two the elements lie on reaches into
//! the open hull, Blocked only when a single convex occluder has both elements strictly on opposite
//! sides of its plane and every segment between vertices of the two crosses that plane inside it (by
//! convexity the cross-section of the hull with the plane is the convex hull of those crossings, so
//! every segment between the elements crosses inside too).

use super::brute_force::ray_polygon;
use super::{Hit, Visibility, SEGMENT_EPSILON};
use crate::geometry::{Aabb, DVec3, Ray, Shape};
use crate::hierarchy::clusters::{Child, ClusterTree, ClusterTreeKind, Item};
use std::ops::ControlFlow;

/// How link couplings find their visibility (`--visibility-reuse`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum VisibilityReuse {
    /// A shaft test per link whose parent's shaft was partial; Clear and Blocked verdicts are
    /// inherited by the link's children and cost no rays (exact visibility back ends and multires).
    #[default]
    Shaft,
    /// A ray per pair of cubature nodes for every link.
    None,
}

/// What a shaft test says about every segment between two elements.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ShaftVerdict {
    /// No polygon other than the two the elements lie on reaches into the shaft: transmittance 1.
    Clear,
    /// One convex polygon cuts every segment: transmittance 0.
    Blocked,
    /// Neither could be shown: sample with rays.
    Partial,
}

impl ShaftVerdict {
    /// The verdict a link between sub-elements inherits: its shaft lies inside this one.
    pub fn inherited(self) -> Option<ShaftVerdict> {
        (self != ShaftVerdict::Partial).then_some(self)
    }
}

/// What a link knows of its shaft before any test of its own, from the link it was refined from (whose
/// shaft holds its own).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum ShaftPrior<'a> {
    /// Nothing: a test walks the whole cluster tree.
    #[default]
    Unknown,
    /// A Clear or Blocked verdict, taken as is without a test.
    Verdict(ShaftVerdict),
    /// The complete occluder list of a Partial test of the parent's shaft: a test examines only these.
    Among(&'a [u32]),
}

/// Relative distance (to the coordinates' magnitude) within which a polygon counts as touching a face
/// of the shaft rather than reaching into it. A segment between interior points of the two elements
/// stays far inside the hull except near its own ends, which lie on the elements (and whose first and
/// last `SEGMENT_EPSILON` the rays ignore), so a polygon within this distance of a face is never hit;
/// the same bound as the ray test's in-plane rule (`brute_force::ray_triangle`).
const TOUCH: f64 = 1e-10;

/// Crossing parameters a Blocked verdict needs on every vertex segment: well inside the part of a
/// segment the ray tests (`SEGMENT_EPSILON` = 1e-5 trimmed at each end).
const BLOCK_T_MARGIN: f64 = 1e-3;

/// Polygons that reach into a shaft without blocking it, after which the search for a single blocker
/// stops and the verdict is Partial (bounds the cost of large shafts, which are rarely blocked): the
/// most a Partial test's occluder list holds, and what a test whose list its link's descendants
/// inherit keeps ([`ShaftPrior::Among`]).
pub const MAX_PARTIAL_OCCLUDERS: usize = 16;

/// The occluders kept by a test whose list serves only its own link's rays (a coupling's test of a
/// link with no ancestor's list): past this many a walk stops, and the rays go to the ray-casting back
/// end. Such a walk costs about as much as the rays it might make cheaper: on the classroom
/// (`--accuracy 10% --max-passes 7`) the tree walks that went on to the 17th occluder took 4.7 µs
/// each and were 37% of all tests. Stopping at the 5th saved 3% of the solve's CPU time there with the
/// same couplings: a blocker met after the fifth occluder leaves the verdict Partial instead of
/// Blocked, and the link's rays then find every pair blocked, as exact verdicts and rays agree
/// (BENCHMARKS.md, "Shaft tests that stop early").
pub const MAX_OWN_OCCLUDERS: usize = 4;

/// Most vertices of a shaft: the corners of two quads.
const MAX_SHAFT_POINTS: usize = 8;

/// Candidate faces of a shaft: each element's own plane, and every plane through an edge of one element
/// and a vertex of the other (2 + 2 · 4 · 4).
const MAX_SHAFT_PLANES: usize = 34;

/// The convex hull of two elements' vertices as outward planes `n · p ≤ d`, with its bounding box; kept
/// in fixed arrays, since a shaft is built for every test.
#[derive(Clone, Debug)]
pub struct Shaft {
    points: [DVec3; MAX_SHAFT_POINTS],
    point_count: usize,
    planes: [(DVec3, f64); MAX_SHAFT_PLANES],
    plane_count: usize,
    bounds: Aabb,
    /// `TOUCH` times the coordinates' magnitude.
    touch: f64,
}

impl Shaft {
    /// The hull of the vertices of `a` and `b`. A face of the hull of two convex planar polygons meets
    /// each of them in a vertex, an edge or the whole polygon (it is a supporting plane), and holds at
    /// least three points, so it is one polygon's plane or a plane through an edge of one and a vertex
    /// of the other (Haines–Wallace's edge–vertex planes): only those candidates are tried, and one is a
    /// face when all the points lie on one side of it. A plane is moved out to the farthest point, so
    /// the hull lies inside the shaft up to the rounding of one dot product; a face the rounding hides
    /// only makes the shaft larger (conservative).
    pub fn new(a: &Shape, b: &Shape) -> Shaft {
        let mut shaft = Shaft {
            points: [DVec3::ZERO; MAX_SHAFT_POINTS],
            point_count: 0,
            planes: [(DVec3::ZERO, 0.0); MAX_SHAFT_PLANES],
            plane_count: 0,
            bounds: Aabb::EMPTY,
            touch: 0.0,
        };
        for &p in a.vertices().iter().chain(b.vertices()) {
            shaft.points[shaft.point_count] = p;
            shaft.point_count += 1;
            shaft.bounds.grow(p);
        }
        let bounds = shaft.bounds;
        let magnitude = bounds.min.abs().max(bounds.max.abs()).max_element() + bounds.diagonal();
        shaft.touch = TOUCH * magnitude;
        let support = 1e-12 * magnitude;
        for (own, other) in [(a.vertices(), b.vertices()), (b.vertices(), a.vertices())] {
            shaft.add_face(own[0], own[1], own[2], support);
            for (e, &p) in own.iter().enumerate() {
                let q = own[(e + 1) % own.len()];
                for &r in other {
                    shaft.add_face(p, q, r, support);
                }
            }
        }
        shaft
    }

    /// The shaft's corners (the two elements' vertices).
    fn points(&self) -> &[DVec3] {
        &self.points[..self.point_count]
    }

    /// The outward planes `(n, d)` found so far.
    fn planes(&self) -> &[(DVec3, f64)] {
        &self.planes[..self.plane_count]
    }

    /// Adds the plane through `p`, `q`, `r` as a face, oriented outward and moved out to the farthest
    /// point, when every point lies on one side of it (within `support`) and no face holds it already.
    fn add_face(&mut self, p: DVec3, q: DVec3, r: DVec3, support: f64) {
        let (e1, e2) = (q - p, r - p);
        // Sides are judged with the unnormalised normal (most candidate faces have points on both
        // sides and are dropped), the support scaled to it.
        let normal = e1.cross(e2);
        let length = normal.length();
        if length <= 1e-9 * e1.length() * e2.length() {
            return;
        }
        let offset = normal.dot(p);
        let scaled_support = support * length;
        let (mut low, mut high) = (0.0f64, 0.0f64);
        for x in self.points() {
            let s = normal.dot(*x) - offset;
            low = low.min(s);
            high = high.max(s);
            if low < -scaled_support && high > scaled_support {
                return;
            }
        }
        let inverse = length.recip();
        let (normal, offset) = (normal * inverse, offset * inverse);
        let plane = if high <= scaled_support {
            (normal, offset + high * inverse)
        } else {
            (-normal, -(offset + low * inverse))
        };
        let known = self
            .planes()
            .iter()
            .any(|(m, d)| m.dot(plane.0) > 1.0 - 1e-12 && (d - plane.1).abs() <= support);
        if !known {
            self.planes[self.plane_count] = plane;
            self.plane_count += 1;
        }
    }

    /// Whether a box lies outside the shaft (at most touching it).
    fn excludes_box(&self, b: &Aabb) -> bool {
        let t = self.touch;
        if self.beside_bounds(b) {
            return true;
        }
        self.planes().iter().any(|&(n, d)| {
            // The box corner deepest inside the plane.
            let corner = DVec3::select(n.cmpge(DVec3::ZERO), b.min, b.max);
            n.dot(corner) - d >= -t
        })
    }

    /// Whether a box lies outside the shaft's bounding box (at most touching it).
    fn beside_bounds(&self, b: &Aabb) -> bool {
        let t = self.touch;
        (b.max - self.bounds.min).min_element() <= t || (self.bounds.max - b.min).min_element() <= t
    }

    /// Whether a point set lies outside the shaft (at most touching it) by one of its faces.
    fn excludes_points(&self, vertices: &[DVec3]) -> bool {
        self.planes()
            .iter()
            .any(|&(n, d)| vertices.iter().all(|v| n.dot(*v) - d >= -self.touch))
    }

    /// Whether the whole shaft lies on one side of a plane (touching it at most): a polygon in that
    /// plane cannot reach into it.
    fn beside_plane(&self, normal: DVec3, offset: f64) -> bool {
        let signed = |p: &DVec3| normal.dot(*p) - offset;
        let t = self.touch;
        self.points().iter().all(|p| signed(p) >= -t)
            || self.points().iter().all(|p| signed(p) <= t)
    }
}

/// A convex planar piece of an occluder: a triangle, or a quad whose fourth vertex lies in the plane of
/// the first three (a non-planar quad is its two triangles, as the ray tests see it).
fn convex_pieces(shape: &Shape) -> impl Iterator<Item = [DVec3; 4]> + '_ {
    let v = shape.vertices();
    let planar_quad = v.len() == 4 && {
        let normal = (v[1] - v[0]).cross(v[2] - v[0]).normalize_or_zero();
        let magnitude = v.iter().map(|p| p.abs().max_element()).fold(0.0, f64::max);
        normal.dot(v[3] - v[0]).abs() <= 1e-12 * magnitude
    };
    let pieces: [Option<[DVec3; 4]>; 2] = match v.len() {
        3 => [Some([v[0], v[1], v[2], v[2]]), None],
        _ if planar_quad => [Some([v[0], v[1], v[2], v[3]]), None],
        _ => [
            Some([v[0], v[1], v[2], v[2]]),
            Some([v[0], v[2], v[3], v[3]]),
        ],
    };
    pieces.into_iter().flatten()
}

/// The distinct corners of a piece (a triangle repeats its last one).
fn corners(piece: &[DVec3; 4]) -> &[DVec3] {
    if piece[3] == piece[2] {
        &piece[..3]
    } else {
        piece
    }
}

/// Whether the convex polygon `occluder` cuts every segment between the vertices of `a` and `b` strictly
/// inside it and strictly inside the tested part of the segment (see the module's convexity argument).
fn blocks(occluder: &[DVec3], a: &[DVec3], b: &[DVec3], touch: f64) -> bool {
    let normal = (occluder[1] - occluder[0])
        .cross(occluder[2] - occluder[0])
        .normalize_or_zero();
    if normal == DVec3::ZERO {
        return false;
    }
    let offset = normal.dot(occluder[0]);
    let side = |p: &[DVec3]| {
        let mut s = [0.0; 4];
        s.iter_mut()
            .zip(p)
            .for_each(|(s, p)| *s = normal.dot(*p) - offset);
        s
    };
    let (sa, sb) = (side(a), side(b));
    let (sa, sb) = (&sa[..a.len()], &sb[..b.len()]);
    let opposite = (sa.iter().all(|&s| s > touch) && sb.iter().all(|&s| s < -touch))
        || (sa.iter().all(|&s| s < -touch) && sb.iter().all(|&s| s > touch));
    if !opposite {
        return false;
    }
    let m = occluder.len();
    a.iter().zip(sa).all(|(pa, &da)| {
        b.iter().zip(sb).all(|(pb, &db)| {
            let t = da / (da - db);
            if !(BLOCK_T_MARGIN..=1.0 - BLOCK_T_MARGIN).contains(&t) {
                return false;
            }
            let x = *pa + t * (*pb - *pa);
            (0..m).all(|e| {
                let (p, q) = (occluder[e], occluder[(e + 1) % m]);
                (q - p).cross(x - p).dot(normal) > touch * (q - p).length()
            })
        })
    })
}

thread_local! {
    /// The tree walk's stack of [`ShaftCuller::classify`], reused by every test on a thread.
    static STACK: std::cell::RefCell<Vec<Child>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// A cluster tree over the scene's polygons (the same polygons, in the same order, as the ray-casting
/// back end) for shaft tests.
#[derive(Clone, Debug)]
pub struct ShaftCuller {
    shapes: Vec<Shape>,
    tree: ClusterTree,
}

impl ShaftCuller {
    pub fn new(shapes: &[Shape]) -> Self {
        let items: Vec<Item> = shapes
            .iter()
            .map(|s| Item {
                bounds: s.bounds(),
                area: s.area(),
            })
            .collect();
        ShaftCuller {
            shapes: shapes.to_vec(),
            tree: ClusterTree::build(&items, ClusterTreeKind::Kdtree),
        }
    }

    /// Bytes of the polygons' copy and the tree.
    pub fn memory_bytes(&self) -> usize {
        self.shapes.len() * std::mem::size_of::<Shape>()
            + self
                .tree
                .nodes
                .iter()
                .map(|n| std::mem::size_of_val(n) + n.children.len() * std::mem::size_of::<Child>())
                .sum::<usize>()
    }

    /// The verdict on every segment between `a` (on polygon `polygon_a`) and `b` (on `polygon_b`);
    /// the two polygons themselves are not occluders when planar (segments leave their planes at once,
    /// and the rays ignore hits in the plane of their origin). With `among`, the complete occluder list
    /// of a Partial test of a shaft that holds this one (the parent link's, [`ShaftTest::occluders`]),
    /// only those polygons are examined: nothing else can reach into this shaft (Haines–Wallace's
    /// candidate list, passed down the link hierarchy), so no tree walk is needed. A Partial test
    /// lists its occluders when there are at most `list_room` of them (at most
    /// [`MAX_PARTIAL_OCCLUDERS`]), and stops looking when it meets one more.
    pub fn classify(
        &self,
        a: &Shape,
        polygon_a: usize,
        b: &Shape,
        polygon_b: usize,
        among: Option<&[u32]>,
        list_room: usize,
    ) -> ShaftTest {
        let mut test = ShaftTest {
            verdict: ShaftVerdict::Clear,
            occluders: [0; MAX_PARTIAL_OCCLUDERS],
            count: 0,
        };
        let Some(root) = self.tree.root() else {
            return test;
        };
        let query = Query {
            shaft: Shaft::new(a, b),
            a,
            polygon_a,
            b,
            polygon_b,
            list_room: list_room.min(MAX_PARTIAL_OCCLUDERS),
        };
        if let Some(list) = among {
            for &i in list {
                if query.examine(self, i as usize, &mut test).is_break() {
                    break;
                }
            }
            return test;
        }
        // The walk's stack is kept per thread: a shaft test runs for every link, and allocating it
        // each time showed in profiles.
        STACK.with_borrow_mut(|stack| {
            stack.clear();
            stack.push(Child::Node(root));
            while let Some(child) = stack.pop() {
                match child {
                    Child::Node(n) => {
                        let node = &self.tree.nodes[n as usize];
                        if !query.shaft.excludes_box(&node.bounds) {
                            stack.extend(node.children.iter().rev());
                        }
                    }
                    Child::Item(i) => {
                        if query.examine(self, i as usize, &mut test).is_break() {
                            break;
                        }
                    }
                }
            }
        });
        test
    }

    /// Whether the open segment between two surface points is blocked by one of `occluders`, by the
    /// same ray–polygon test on the same numbers as the exhaustive reference (and the BVH,
    /// `visibility::bvh`), trimmed as [`Visibility::segment_occluded`] trims it.
    pub fn segment_occluded_among(&self, occluders: &[u32], from: DVec3, to: DVec3) -> bool {
        let ray = Ray::new(from, to - from);
        occluders.iter().any(|&i| {
            let v = self.shapes[i as usize].vertices();
            ray_polygon(&ray, v, SEGMENT_EPSILON, 1.0 - SEGMENT_EPSILON).is_some()
        })
    }
}

/// One shaft test in progress: the shaft and the two elements with the polygons they lie on.
struct Query<'a> {
    shaft: Shaft,
    a: &'a Shape,
    polygon_a: usize,
    b: &'a Shape,
    polygon_b: usize,
    /// Occluders the test may list before it stops ([`ShaftCuller::classify`]).
    list_room: usize,
}

impl Query<'_> {
    /// Examines scene polygon `i` against the shaft and records what it does in `test`; breaks when
    /// the verdict is final (Blocked, or more occluders than the list has room for).
    fn examine(&self, culler: &ShaftCuller, i: usize, test: &mut ShaftTest) -> ControlFlow<()> {
        let shape = &culler.shapes[i];
        if self.shaft.beside_bounds(&shape.bounds()) || self.shaft.excludes_points(shape.vertices())
        {
            return ControlFlow::Continue(());
        }
        for piece in convex_pieces(shape) {
            let occluder = corners(&piece);
            let normal = (occluder[1] - occluder[0])
                .cross(occluder[2] - occluder[0])
                .normalize_or_zero();
            let whole = occluder.len() == shape.vertices().len();
            let in_plane =
                normal != DVec3::ZERO && self.shaft.beside_plane(normal, normal.dot(occluder[0]));
            if in_plane || (whole && (i == self.polygon_a || i == self.polygon_b)) {
                continue;
            }
            if blocks(
                occluder,
                self.a.vertices(),
                self.b.vertices(),
                self.shaft.touch,
            ) {
                test.verdict = ShaftVerdict::Blocked;
                return ControlFlow::Break(());
            }
            test.verdict = ShaftVerdict::Partial;
            let count = usize::from(test.count);
            if test.occluders[..count].last() != Some(&(i as u32)) {
                if count == self.list_room {
                    test.count = u8::MAX;
                    return ControlFlow::Break(());
                }
                test.occluders[count] = i as u32;
                test.count += 1;
            }
        }
        ControlFlow::Continue(())
    }
}

/// A shaft test's verdict and, for a Partial one, the polygons that reach into the shaft when there
/// are few: segments between the two elements can only be blocked by them, so rays test just these
/// instead of the whole scene (Haines–Wallace's candidate list).
#[derive(Clone, Copy, Debug)]
pub struct ShaftTest {
    pub verdict: ShaftVerdict,
    occluders: [u32; MAX_PARTIAL_OCCLUDERS],
    /// Polygons in `occluders`; `u8::MAX` when there were more than fit.
    count: u8,
}

impl ShaftTest {
    /// Every polygon that can block a segment of a Partial shaft, where the list is complete.
    pub fn occluders(&self) -> Option<&[u32]> {
        if self.verdict != ShaftVerdict::Partial {
            return None;
        }
        self.occluders.get(..usize::from(self.count))
    }
}

/// An exact ray-casting back end, or multi-resolution visibility, with a [`ShaftCuller`] over the same
/// polygons: rays go to the back end unchanged, and link couplings ask [`Visibility::shafts`] for shaft
/// tests. Under multires a shaft's verdict is the exact answer its queries approximate: transmittance 1
/// through a clear shaft, where averaging the clusters it crosses would darken the link (Sillion–Drettakis
/// §3.2 ask exact visibility wherever it is affordable), 0 through a blocked one.
pub struct ShaftCulled {
    pub rays: Box<dyn Visibility>,
    pub culler: ShaftCuller,
}

impl Visibility for ShaftCulled {
    fn intersect(&self, ray: &Ray, t_min: f64, t_max: f64) -> Option<Hit> {
        self.rays.intersect(ray, t_min, t_max)
    }

    fn occluded(&self, ray: &Ray, t_min: f64, t_max: f64) -> bool {
        self.rays.occluded(ray, t_min, t_max)
    }

    fn segment_occluded(&self, from: DVec3, to: DVec3) -> bool {
        self.rays.segment_occluded(from, to)
    }

    fn transmittance(&self, from: DVec3, to: DVec3) -> f64 {
        self.rays.transmittance(from, to)
    }

    fn transmittance_onto(&self, from: DVec3, to: DVec3, receiver: usize) -> f64 {
        self.rays.transmittance_onto(from, to, receiver)
    }

    fn occluded_past(
        &self,
        ray: &Ray,
        t_min: f64,
        t_max: f64,
        transparent: &dyn Fn(usize) -> bool,
    ) -> bool {
        self.rays.occluded_past(ray, t_min, t_max, transparent)
    }

    fn transmittance_past(
        &self,
        from: DVec3,
        to: DVec3,
        transparent: &dyn Fn(usize) -> bool,
    ) -> f64 {
        self.rays.transmittance_past(from, to, transparent)
    }

    fn transmittance_past_onto(
        &self,
        from: DVec3,
        to: DVec3,
        receiver: usize,
        transparent: &dyn Fn(usize) -> bool,
    ) -> f64 {
        self.rays
            .transmittance_past_onto(from, to, receiver, transparent)
    }

    fn name(&self) -> &'static str {
        self.rays.name()
    }

    fn memory_bytes(&self) -> Option<usize> {
        Some(self.rays.memory_bytes()? + self.culler.memory_bytes())
    }

    fn shafts(&self) -> Option<&ShaftCuller> {
        Some(&self.culler)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::DVec2;
    use crate::visibility::brute_force::BruteForce;
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64Mcg;

    fn point(rng: &mut Pcg64Mcg, low: DVec3, high: DVec3) -> DVec3 {
        low + (high - low) * DVec3::new(rng.random(), rng.random(), rng.random())
    }

    /// A random triangle or parallelogram (planar, convex) with a corner at `centre` and edges up to
    /// `size`, its normal tilted from `up` by up to about `tilt` radians.
    fn polygon(rng: &mut Pcg64Mcg, centre: DVec3, size: f64, up: DVec3, tilt: f64) -> Shape {
        let tilt = point(rng, DVec3::splat(-tilt), DVec3::splat(tilt));
        let n = (up + tilt - up * up.dot(tilt)).normalize();
        let u = n.any_orthonormal_vector();
        let w = n.cross(u);
        let a = centre;
        let e1 = (u * rng.random_range(0.2..1.0) + w * rng.random_range(-0.5..0.5)) * size;
        let e2 = (w * rng.random_range(0.2..1.0) + u * rng.random_range(-0.5..0.5)) * size;
        let (e1, e2) = if e1.cross(e2).dot(n) > 0.0 {
            (e1, e2)
        } else {
            (e2, e1)
        };
        if rng.random_bool(0.5) {
            Shape::Triangle([a, a + e1, a + e2])
        } else {
            Shape::Quad([a, a + e1, a + e1 + e2, a + e2])
        }
    }

    /// How many of `n` random segments between the pair are open to the brute-force rays, checking on
    /// each that the occluder list of `test` (if any) blocks exactly what the rays block.
    fn open_segments(
        rng: &mut Pcg64Mcg,
        culler: &ShaftCuller,
        rays: &BruteForce,
        test: &ShaftTest,
        (a, b): (&Shape, &Shape),
        n: usize,
    ) -> usize {
        (0..n)
            .filter(|_| {
                let x = a.sample_uniform(DVec2::new(rng.random(), rng.random()));
                let y = b.sample_uniform(DVec2::new(rng.random(), rng.random()));
                let blocked = rays.segment_occluded(x, y);
                if let Some(list) = test.occluders() {
                    assert_eq!(culler.segment_occluded_among(list, x, y), blocked);
                }
                !blocked
            })
            .count()
    }

    /// Ground truth for the verdicts: random configurations of two facing polygons and random
    /// occluders (small and large, between them, beside them, and in the receiver's plane), with the
    /// brute-force ray test on random segments between the two. A Clear verdict must never see a
    /// blocked segment, a Blocked one never an open one, and the occluder list of a Partial one must
    /// block exactly the segments that the whole scene blocks; every verdict must occur often enough
    /// for the test to mean something.
    #[test]
    fn verdicts_hold_for_every_segment() {
        let mut rng = Pcg64Mcg::seed_from_u64(7);
        let (mut clear, mut blocked, mut partial) = (0, 0, 0);
        let mut sub_verdicts = [0; 3];
        for _ in 0..2000 {
            let a = polygon(&mut rng, DVec3::ZERO, 1.0, DVec3::Z, 0.4);
            let top = point(
                &mut rng,
                DVec3::new(-1.0, -1.0, 1.5),
                DVec3::new(1.0, 1.0, 3.0),
            );
            let b = polygon(&mut rng, top, 1.0, -DVec3::Z, 0.4);
            let mut shapes = vec![a, b];
            for _ in 0..rng.random_range(0..5) {
                let kind = rng.random_range(0..6).max(2) - 2;
                let (centre, size, up, tilt) = match kind {
                    // Small occluders in and around the space between the pair.
                    0 => (
                        point(
                            &mut rng,
                            DVec3::new(-0.5, -0.5, 0.3),
                            DVec3::new(1.0, 1.0, 1.4),
                        ),
                        0.3,
                        DVec3::X,
                        1.0,
                    ),
                    // Large boards between the two (some not quite large enough), below.
                    1 => (DVec3::ZERO, 0.0, DVec3::Z, 0.0),
                    // Boards beside them, likely outside the shaft.
                    2 => (
                        point(
                            &mut rng,
                            DVec3::new(2.0, -2.0, 0.0),
                            DVec3::new(4.0, 2.0, 3.0),
                        ),
                        1.0,
                        DVec3::Y,
                        0.5,
                    ),
                    // A neighbour in the receiver's plane, touching the shaft's base.
                    _ => (a.vertices()[1], 1.0, a.normal(), 0.5),
                };
                let mut occluder = polygon(&mut rng, centre, size, up, tilt);
                if kind == 1 {
                    let low = point(
                        &mut rng,
                        DVec3::new(-4.0, -4.0, 0.9),
                        DVec3::new(-1.0, -1.0, 1.3),
                    );
                    let high = point(
                        &mut rng,
                        DVec3::new(1.5, 1.5, 0.0),
                        DVec3::new(4.5, 4.5, 0.0),
                    );
                    let slope = point(&mut rng, DVec3::splat(-0.05), DVec3::splat(0.05));
                    let at = |x: f64, y: f64| DVec3::new(x, y, low.z + slope.x * x + slope.y * y);
                    occluder = Shape::Quad([
                        at(low.x, low.y),
                        at(high.x, low.y),
                        at(high.x, high.y),
                        at(low.x, high.y),
                    ]);
                }
                if kind == 3 {
                    // Flatten it into the receiver's plane.
                    let (n, p) = (a.normal(), a.vertices()[0]);
                    let v: Vec<DVec3> = occluder
                        .vertices()
                        .iter()
                        .map(|&q| q - n * n.dot(q - p))
                        .collect();
                    occluder = Shape::Triangle([v[0], v[1], v[2]]);
                }
                shapes.push(occluder);
            }
            let culler = ShaftCuller::new(&shapes);
            let test = culler.classify(&a, 0, &b, 1, None, MAX_PARTIAL_OCCLUDERS);
            let rays = BruteForce::new(shapes.clone());
            let open = open_segments(&mut rng, &culler, &rays, &test, (&a, &b), 200);
            match test.verdict {
                ShaftVerdict::Clear => {
                    clear += 1;
                    assert_eq!(open, 200, "Clear verdict with blocked segments: {shapes:?}");
                }
                ShaftVerdict::Blocked => {
                    blocked += 1;
                    assert_eq!(open, 0, "Blocked verdict with open segments: {shapes:?}");
                }
                ShaftVerdict::Partial => partial += 1,
            }
            // A sub-element pair's shaft lies inside this one: its test among this one's complete
            // occluder list must hold for its own segments as well.
            let Some(list) = test.occluders() else {
                continue;
            };
            let (ca, cb) = (a.subdivide(), b.subdivide());
            let (ca, cb) = (ca[rng.random_range(0..4)], cb[rng.random_range(0..4)]);
            let sub = culler.classify(&ca, 0, &cb, 1, Some(list), MAX_PARTIAL_OCCLUDERS);
            let open = open_segments(&mut rng, &culler, &rays, &sub, (&ca, &cb), 50);
            match sub.verdict {
                ShaftVerdict::Clear => assert_eq!(open, 50, "Clear sub-shaft blocked: {shapes:?}"),
                ShaftVerdict::Blocked => assert_eq!(open, 0, "Blocked sub-shaft open: {shapes:?}"),
                ShaftVerdict::Partial => {}
            }
            sub_verdicts[sub.verdict as usize] += 1;
        }
        assert!(
            clear >= 100 && blocked >= 100 && partial >= 100,
            "{clear} {blocked} {partial}"
        );
        // Sub-shafts of Partial ones are rarely blocked by a single polygon, so only Clear (the list
        // deciding without rays) and Partial must both occur often enough to mean something.
        assert!(
            sub_verdicts[ShaftVerdict::Clear as usize] >= 50
                && sub_verdicts[ShaftVerdict::Partial as usize] >= 50,
            "sub-shaft verdicts (clear, blocked, partial): {sub_verdicts:?}"
        );
    }

    /// A Partial test lists its occluders only when they fit the room it is given, and with room
    /// for all of them lists every one: six small squares between two parallel plates, none
    /// covering the shaft.
    #[test]
    fn partial_lists_fit_their_room() {
        let square = |x: f64, y: f64, z: f64, s: f64| {
            Shape::Quad([
                DVec3::new(x, y, z),
                DVec3::new(x + s, y, z),
                DVec3::new(x + s, y + s, z),
                DVec3::new(x, y + s, z),
            ])
        };
        let (a, b) = (
            square(0.0, 0.0, 0.0, 1.0),
            square(0.0, 0.0, 2.0, 1.0).flipped(),
        );
        let mut shapes = vec![a, b];
        shapes.extend((0..6).map(|k| square(0.1 + 0.13 * f64::from(k), 0.4, 1.0, 0.1)));
        let culler = ShaftCuller::new(&shapes);
        let roomy = culler.classify(&a, 0, &b, 1, None, MAX_PARTIAL_OCCLUDERS);
        assert_eq!(roomy.verdict, ShaftVerdict::Partial);
        let mut listed = roomy.occluders().expect("a list").to_vec();
        listed.sort_unstable();
        assert_eq!(listed, (2..8).collect::<Vec<u32>>());
        let short = culler.classify(&a, 0, &b, 1, None, MAX_OWN_OCCLUDERS);
        assert_eq!(short.verdict, ShaftVerdict::Partial);
        assert_eq!(short.occluders(), None);
        // With an ancestor's list the test examines only that list, under the same room.
        let among = culler.classify(&a, 0, &b, 1, Some(&listed[..3]), MAX_OWN_OCCLUDERS);
        assert_eq!(among.occluders(), Some(&listed[..3]));
    }

    /// The shaft holds the two polygons' convex hull: points on segments between them are inside
    /// every plane (up to rounding), and the hull of two parallel squares has their six faces.
    #[test]
    fn shaft_holds_the_hull() {
        let square = |z: f64, s: f64| {
            Shape::Quad([
                DVec3::new(0.0, 0.0, z),
                DVec3::new(s, 0.0, z),
                DVec3::new(s, s, z),
                DVec3::new(0.0, s, z),
            ])
        };
        let shaft = Shaft::new(&square(0.0, 1.0), &square(1.0, 1.0).flipped());
        assert_eq!(shaft.planes().len(), 6);
        let mut rng = Pcg64Mcg::seed_from_u64(3);
        for _ in 0..100 {
            let a = polygon(&mut rng, DVec3::ZERO, 1.0, DVec3::Z, 0.5);
            let b = polygon(&mut rng, DVec3::new(0.3, 0.2, 1.5), 1.0, -DVec3::Z, 0.5);
            let shaft = Shaft::new(&a, &b);
            for _ in 0..50 {
                let x = a.sample_uniform(DVec2::new(rng.random(), rng.random()));
                let y = b.sample_uniform(DVec2::new(rng.random(), rng.random()));
                let p = x.lerp(y, rng.random());
                assert!(shaft.planes().iter().all(|&(n, d)| n.dot(p) - d <= 1e-12));
            }
        }
    }
}
