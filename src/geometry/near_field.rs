//! Near-field receiver cubature: an adaptive composite rule for the receiver side of a link whose source
//! comes closer to the receiver than the receiver's own size.
//!
//! Bekaert–Willems eq. (12) integrates the receiver side of the coupling (eq. (3)) with one fixed rule.
//! Its nodes are a fixed fraction of the element's size apart, and the point-to-source factor
//! `F(x → S)` (exact per point: [`point_to_polygon`]) is smooth at that scale only while the source is
//! farther away than the element is large. A lamp hung a millimetre under a ceiling is the failing
//! case: its back light reaches the ceiling in a strip about as wide as the gap along the lamp's
//! outline, where `F` rises to ½; the regular nodes, centimetres away, see almost none of it (a real
//! office3 ceiling element: 3.6·10⁻⁶ against an exact 2.9·10⁻⁴, 80× too little). The same holds for the
//! centre estimate of the power oracle (Feixas et al. eq. (1)), so such a link was never refined.
//!
//! [`receiver_integral`] integrates `F(x → S)` over the receiver adaptively, by global subdivision of the
//! cell whose halves disagree most with it (the classic error indicator of adaptive cubature, e.g.
//! Berntsen–Espelid–Genz 1991). Cells are bisected, each along the direction whose halves change the
//! integral most (a quad across `u` or `v`, a triangle through one of its edges), so a peak along a
//! line (a lamp's outline) is followed by one cell per level rather than the 2^level cells of a
//! quadtree along it. [`is_near`] says when that is worth doing. The cells found with a cheap rule
//! carry a composite rule of any degree ([`ReceiverIntegral::nodes`], with parameters on the receiver
//! for its basis).

use super::cubature::{rule, Node};
use super::form_factor::point_to_polygon;
use super::{DVec2, DVec3, Shape};

/// How the receiver side of links whose source is near is integrated (`--near-field`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum NearField {
    /// The adaptive receiver integral (`receiver_integral`) where the source is near the receiver
    /// (`is_near`), in couplings (where the regular rule misses more than a tenth of the light) and in
    /// the power oracle's transport estimate.
    #[default]
    Adaptive,
    /// The regular rule in couplings and the centre estimate in the power oracle (Feixas et al. §4 as
    /// published).
    Regular,
}

/// Relative accuracy couplings ask of [`receiver_integral`]: the sum of the cells' error indicators
/// within 3% of the integral (1% cost cube.mgf a fifth more refinement time for the same probe errors).
pub const TOLERANCE: f64 = 0.03;

/// Largest ratio of the factor's values at a receiver's sample points (its regular nodes, or its
/// corners and centroid: [`varies_over`]) at which the regular rule is trusted without the adaptive
/// one: a factor that changes less than twofold over the receiver has no peak that its nodes miss.
pub const EVEN_RATIO: f64 = 2.0;

/// Whether `F(x → source)` changes more than [`EVEN_RATIO`]-fold between the receiver's corners and
/// its centroid (five point factors: the cheap test before a [`receiver_integral`]).
pub fn varies_over(receiver: &Shape, normal: DVec3, source: &Shape) -> bool {
    let (low, high) = receiver
        .vertices()
        .iter()
        .chain([receiver.centroid()].iter())
        .map(|&x| point_to_polygon(x, normal, source))
        .fold((f64::INFINITY, 0.0f64), |(lo, hi), f| {
            (lo.min(f), hi.max(f))
        });
    high > EVEN_RATIO * low
}

/// Degree of the rule [`receiver_integral`]'s callers search cells with (2 × 2 nodes on a quad): the
/// subdivision, not the rule, reaches the tolerance.
pub const SEARCH_DEGREE: usize = 3;

/// Most leaf cells of [`receiver_integral`]; past it the rule stops where it is (a peak along a line is
/// then resolved to about 2⁻⁶⁰ of the element, one at a point to about 2⁻³⁰).
pub const MAX_CELLS: usize = 64;

/// Whether the source comes nearer to the receiver than about half the receiver's size (its centroid
/// or one of its corners is closer to the source than half its diameter, which holds for every
/// element along a source's outline): only then can `F(x → S)` vary over the receiver faster than its
/// regular rule resolves (farther away, `1/r²` changes by less than a factor of 4 between
/// neighbouring nodes). The corners count for elongated elements: a 2 cm × 65 cm strip lying end to
/// end with a source 1.8 cm below it has its centroid just over half its diameter away, and its
/// nodes, the nearest 7 cm from the source, missed the light arriving within a few centimetres of its
/// end (the classroom's lamp housings over their tubes, BENCHMARKS.md).
pub fn is_near(receiver: &Shape, source: &Shape) -> bool {
    let reach = 0.5 * receiver.diameter();
    // Most links are far: no point of the receiver within reach of a sphere around the source's
    // corners.
    let (centre, radius) = source.corner_sphere();
    let points = || std::iter::once(receiver.centroid()).chain(receiver.vertices().iter().copied());
    if points().all(|x| x.distance(centre) - radius >= reach) {
        return false;
    }
    let normal = source.normal();
    points().any(|x| distance_to_plane_polygon(x, source, normal) < reach)
}

/// The receiver integral `∫_R F(x → S) dA_x` of the exact unoccluded point-to-source factor, with the
/// cells that reached it.
#[derive(Clone, Debug)]
pub struct ReceiverIntegral {
    /// `∫_R F(x → S) dA_x` (divide by the receiver's area for the receiver-averaged form factor).
    pub value: f64,
    /// The halves of every leaf cell, in the receiver's parameter domain: a composite rule's cells
    /// ([`ReceiverIntegral::nodes`]).
    pub cells: Vec<Shape>,
    /// How unevenly the factor spreads over the receiver: `Σ_c |I_c − F̄ A_c| / Σ_c I_c` over the
    /// halves `c` of the leaf cells (`I_c` a half's integral, `A_c` its area, `F̄` the mean factor), the
    /// L¹ deviation from the mean of the factor averaged per cell, relative to the integral: 0 for an
    /// even factor, toward 2 where a narrow band holds all of it.
    pub spread: f64,
}

/// A cell of the receiver's parameter domain (cells are triangles or quads in the `z = 0` plane, so that
/// their [`Shape::point_at`] and [`Shape::jacobian`] map a master rule into them): the integral of its
/// own rule, and its best bisection, the halves whose integrals differ most from it, and theirs.
struct Cell {
    coarse: f64,
    halves: [Shape; 2],
    fine: [f64; 2],
    /// The halves' areas on the receiver.
    areas: [f64; 2],
}

impl Cell {
    fn new(domain: Shape, coarse: f64, integrate: &dyn Fn(&Shape) -> (f64, f64)) -> Cell {
        bisections(&domain)
            .into_iter()
            .map(|halves| {
                let [(f0, a0), (f1, a1)] = halves.map(|h| integrate(&h));
                Cell {
                    coarse,
                    halves,
                    fine: [f0, f1],
                    areas: [a0, a1],
                }
            })
            .max_by(|a, b| a.error().total_cmp(&b.error()))
            .expect("every cell has a bisection")
    }

    fn value(&self) -> f64 {
        self.fine[0] + self.fine[1]
    }

    fn error(&self) -> f64 {
        (self.coarse - self.value()).abs()
    }
}

/// [`ReceiverIntegral`] of `F(x → source)` over `receiver` (normal `normal`) with rules of `degree`,
/// refined until the cells' error indicators sum to `tolerance` of the integral (couplings:
/// [`TOLERANCE`]) or [`MAX_CELLS`] cells are in use.
pub fn receiver_integral(
    receiver: &Shape,
    normal: DVec3,
    source: &Shape,
    degree: usize,
    tolerance: f64,
) -> ReceiverIntegral {
    // A cell's integral and area.
    let integrate = |domain: &Shape| -> (f64, f64) {
        nodes_in(receiver, domain, degree).fold((0.0, 0.0), |(f, a), x| {
            (
                f + x.weight * point_to_polygon(x.point, normal, source),
                a + x.weight,
            )
        })
    };
    let whole = parameter_domain(receiver);
    let mut cells = vec![Cell::new(whole, integrate(&whole).0, &integrate)];
    while cells.len() < MAX_CELLS {
        let value: f64 = cells.iter().map(Cell::value).sum();
        let error: f64 = cells.iter().map(Cell::error).sum();
        if error <= tolerance * value {
            break;
        }
        let worst = (0..cells.len())
            .max_by(|&a, &b| cells[a].error().total_cmp(&cells[b].error()))
            .expect("at least one cell");
        let split = cells.swap_remove(worst);
        for (half, coarse) in split.halves.into_iter().zip(split.fine) {
            cells.push(Cell::new(half, coarse, &integrate));
        }
    }
    let value: f64 = cells.iter().map(Cell::value).sum();
    let area: f64 = cells.iter().flat_map(|c| c.areas).sum();
    let mean = value / area.max(f64::MIN_POSITIVE);
    let deviation: f64 = cells
        .iter()
        .flat_map(|c| c.fine.into_iter().zip(c.areas))
        .map(|(f, a)| (f - mean * a).abs())
        .sum();
    ReceiverIntegral {
        value,
        spread: if value > 0.0 { deviation / value } else { 0.0 },
        cells: cells.iter().flat_map(|c| c.halves).collect(),
    }
}

impl ReceiverIntegral {
    /// The composite rule of `rule(degree)` on every cell, mapped onto `receiver` (the shape integrated),
    /// with parameters on it for its basis.
    pub fn nodes(&self, receiver: &Shape, degree: usize) -> Vec<Node> {
        self.cells
            .iter()
            .flat_map(|cell| nodes_in(receiver, cell, degree))
            .collect()
    }
}

/// The ways to halve a parameter cell: a quad across either parameter, a triangle through the midpoint
/// of any of its edges.
fn bisections(cell: &Shape) -> Vec<[Shape; 2]> {
    let mid = |a: DVec3, b: DVec3| 0.5 * (a + b);
    match *cell {
        Shape::Quad([p0, p1, p2, p3]) => {
            let (m01, m32) = (mid(p0, p1), mid(p3, p2));
            let (m03, m12) = (mid(p0, p3), mid(p1, p2));
            vec![
                [
                    Shape::Quad([p0, m01, m32, p3]),
                    Shape::Quad([m01, p1, p2, m32]),
                ],
                [
                    Shape::Quad([p0, p1, m12, m03]),
                    Shape::Quad([m03, m12, p2, p3]),
                ],
            ]
        }
        Shape::Triangle(v) => (0..3)
            .map(|k| {
                let (a, b, o) = (v[k], v[(k + 1) % 3], v[(k + 2) % 3]);
                let m = mid(a, b);
                [Shape::Triangle([a, m, o]), Shape::Triangle([m, b, o])]
            })
            .collect(),
    }
}

/// The receiver's whole parameter domain as a cell.
fn parameter_domain(shape: &Shape) -> Shape {
    let c = shape
        .parameter_corners()
        .iter()
        .map(|p| DVec3::new(p.x, p.y, 0.0));
    match shape {
        Shape::Triangle(_) => {
            let v: Vec<DVec3> = c.collect();
            Shape::Triangle([v[0], v[1], v[2]])
        }
        Shape::Quad(_) => {
            let v: Vec<DVec3> = c.collect();
            Shape::Quad([v[0], v[1], v[2], v[3]])
        }
    }
}

/// `rule(degree)` mapped into the parameter cell `domain` and on to `shape` (weights: the rule's times
/// the cell's Jacobian times the shape's, so that they sum to the area of the cell's image).
fn nodes_in<'a>(
    shape: &'a Shape,
    domain: &'a Shape,
    degree: usize,
) -> impl Iterator<Item = Node> + 'a {
    rule(shape.domain(), degree)
        .nodes
        .iter()
        .map(move |&(st, w)| {
            let p = domain.point_at(st);
            let uv = DVec2::new(p.x, p.y);
            Node {
                point: shape.point_at(uv),
                uv,
                weight: w * domain.jacobian(st) * shape.jacobian(uv),
            }
        })
}

/// Distance from `p` to the convex planar polygon `shape`.
pub fn distance_to_polygon(p: DVec3, shape: &Shape) -> f64 {
    distance_to_plane_polygon(p, shape, shape.normal())
}

/// [`distance_to_polygon`] with the polygon's unit normal `n` known.
fn distance_to_plane_polygon(p: DVec3, shape: &Shape, n: DVec3) -> f64 {
    let v = shape.vertices();
    let height = n.dot(p - v[0]);
    let foot = p - height * n;
    let inside = super::edges(v).all(|(a, b)| (b - a).cross(foot - a).dot(n) >= 0.0);
    if inside {
        return height.abs();
    }
    super::edges(v)
        .map(|(a, b)| {
            let ab = b - a;
            let t = ((p - a).dot(ab) / ab.length_squared().max(1e-300)).clamp(0.0, 1.0);
            p.distance(a + t * ab)
        })
        .fold(f64::INFINITY, f64::min)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::cubature::nodes_on;

    fn square(x0: f64, x1: f64, y0: f64, y1: f64, z: f64, up: bool) -> Shape {
        let q = [
            DVec3::new(x0, y0, z),
            DVec3::new(x1, y0, z),
            DVec3::new(x1, y1, z),
            DVec3::new(x0, y1, z),
        ];
        let s = Shape::Quad(q);
        if up {
            s
        } else {
            s.flipped()
        }
    }

    #[test]
    fn composite_rules_integrate_polynomials_and_areas_exactly() {
        let tri = Shape::Triangle([
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(2.0, 0.1, 0.0),
            DVec3::new(0.3, 1.5, 0.2),
        ]);
        let quad = Shape::Quad([
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(2.0, 0.0, 0.0),
            DVec3::new(1.8, 1.0, 0.0),
            DVec3::new(0.2, 1.2, 0.0),
        ]);
        for shape in [tri, quad] {
            let whole = parameter_domain(&shape);
            let nodes: Vec<Node> = whole
                .subdivide()
                .iter()
                .flat_map(|c| c.subdivide())
                .flat_map(|c| nodes_in(&shape, &c, 4).collect::<Vec<_>>())
                .collect();
            let area: f64 = nodes.iter().map(|n| n.weight).sum();
            assert!((area - shape.area()).abs() < 1e-12 * shape.area());
            // ∫ x² over the shape, against the shape's own degree-12 rule.
            let exact: f64 = nodes_on(&shape, rule(shape.domain(), 12))
                .iter()
                .map(|n| n.weight * n.point.x * n.point.x)
                .sum();
            let composite: f64 = nodes.iter().map(|n| n.weight * n.point.x * n.point.x).sum();
            assert!((composite - exact).abs() < 1e-12, "{composite} vs {exact}");
            for n in &nodes {
                assert!(n.point.distance(shape.point_at(n.uv)) < 1e-12);
            }
        }
    }

    /// A plate 1 m square facing down, beside a 0.2 m lamp facing up `gap` under its plane, the two
    /// outlines adjacent (a ceiling cut along a lamp hung under it): the adaptive integral matches
    /// Howell's closed form within its tolerance at every gap, where the plate's regular rule misses
    /// more than 10% (it finds a tenth of the light at 1 cm, a hundredth at 1 mm).
    #[test]
    fn adjacent_lamp_light_matches_the_closed_form() {
        use crate::geometry::form_factor::parallel_rectangles_offset;
        let plate = square(0.0, 1.0, 0.0, 1.0, 0.0, false);
        for gap in [1e-3, 1e-2, 1e-1] {
            let lamp = square(-0.2, 0.0, 0.0, 1.0, -gap, true);
            let exact =
                parallel_rectangles_offset([0.0, 1.0, 0.0, 1.0], [-0.2, 0.0, 0.0, 1.0], gap);
            let adaptive =
                receiver_integral(&plate, plate.normal(), &lamp, SEARCH_DEGREE, TOLERANCE);
            assert!(
                (adaptive.value - exact).abs() <= 2.0 * TOLERANCE * exact,
                "gap {gap}: {} vs {exact} ({} cells)",
                adaptive.value,
                adaptive.cells.len()
            );
            let regular: f64 = nodes_on(&plate, rule(plate.domain(), 4))
                .iter()
                .map(|x| x.weight * point_to_polygon(x.point, plate.normal(), &lamp))
                .sum();
            assert!(
                regular < 0.9 * exact,
                "gap {gap}: regular {regular} vs {exact}"
            );
            let weights: f64 = adaptive.nodes(&plate, 6).iter().map(|n| n.weight).sum();
            assert!((weights - 1.0).abs() < 1e-12);
            // Most of the light falls on a band of the plate: the factor is far from even.
            assert!(
                adaptive.spread > 1.0,
                "gap {gap}: spread {}",
                adaptive.spread
            );
        }
        // Under a large parallel source the factor is nearly 1 everywhere.
        let ceiling = square(-10.0, 11.0, -10.0, 11.0, 0.01, false);
        let floor = square(0.0, 1.0, 0.0, 1.0, 0.0, true);
        let even = receiver_integral(&floor, floor.normal(), &ceiling, 4, TOLERANCE);
        assert!(even.spread < 0.01, "spread {}", even.spread);
    }

    #[test]
    fn far_sources_are_not_near() {
        let receiver = square(0.0, 1.0, 0.0, 1.0, 0.0, false);
        assert!(!is_near(&receiver, &square(3.0, 4.0, 0.0, 1.0, -0.5, true)));
        assert!(is_near(
            &receiver,
            &square(-0.2, 0.0, 0.0, 1.0, -0.001, true)
        ));
        // A long strip with a source lying end to end with it, 1.8 cm below: the centroid is just over
        // half the diameter away, the near corners 1.8 cm.
        let strip = square(0.0, 0.02, 0.0, 0.65, 0.0, false);
        let beyond_its_end = square(0.0, 0.02, -0.65, 0.0, -0.018, true);
        assert!(
            distance_to_polygon(strip.centroid(), &beyond_its_end) > 0.5 * strip.diameter(),
            "the centroid test alone would not find it near"
        );
        assert!(is_near(&strip, &beyond_its_end));
        assert_eq!(
            distance_to_polygon(DVec3::new(0.5, 0.5, 2.0), &receiver),
            2.0
        );
        assert!((distance_to_polygon(DVec3::new(2.0, 0.5, 0.0), &receiver) - 1.0).abs() < 1e-15);
    }
}
