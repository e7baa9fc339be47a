//! Surfaces split along the outlines of objects that touch or nearly touch them (issue #7 item 9), before
//! the hierarchy is built.
//!
//! Why: an element that straddles the outline of an object lying on it averages radiosity from both
//! sides of the contact. `cube.mgf`'s two-sided lamp hangs 1 cm under the ceiling: its back light,
//! trapped in the gap, leaks into the room through ceiling elements that reach past the lamp's edge;
//! light from the room leaks under blocks standing on a floor. Refinement can only shrink such elements
//! down to the minimum area, and they still see both sides; cut along the outline, no element does.
//!
//! Contacts of a polygon P with a polygon Q, gap g = `gap` × min(diameter P, diameter Q):
//! - *lying on P*: all of Q's vertices within g of P's plane (Q parallel to P, on it or just off it): the
//!   outline is Q's, projected onto P;
//! - *standing on P*: edges of Q within g of P's plane (the sides of a block on a floor): the contact
//!   edges of one object that join end to end form a footprint, and its convex hull is the outline (the
//!   Cornell box's blocks have no bottom face).
//!
//! Which contacts cut ([`SplitContacts`]): `on` cuts along every one; `auto` (the default) only along
//! those through which a leak can carry significant light: an *emitter* Q lying on a reflecting P with a
//! real gap between them and Q's emitting side facing P (cube.mgf's two-sided lamp, an uplight under a
//! ceiling, an IES luminaire's opening whose table sends light toward P); up to [`EMITTER_GAP_FACTOR`]
//! times the gap where nothing lies between them (the corridor's lamps 2 cm under its ceiling). An emitter is judged as a
//! whole: adjacent coplanar polygons emitting toward the same sides form one region (a lamp tessellated
//! into triangles, a round opening's fan), which lies on P within the gap of its own size and cuts P
//! along its outline, not along its internal edges ([`regions`]). The light trapped in such a gap is of
//! the emitter's order; an element of P that straddles Q's outline averages it with the room's and
//! sends it into the room. Other contacts leak reflected light, already averaged over the straddling
//! element's neighbourhood (blocks on a floor, one-sided panels facing away from the ceiling they hang
//! under), so `auto` adds few polygons to furnished rooms (the classroom: its 48 lamp housings, into 240
//! pieces; BENCHMARKS.md, "Automatic contact splitting", "Reference images and probes" and "Emitting
//! regions and IES openings"). Refinement does not always resolve them: where a reflecting *lid* hangs
//! across a real gap under a surface several times its size (the classroom's housings 2 cm under the
//! ceiling), the light averaged into the gap bounces between the two, and `gaps` also cuts along such
//! lids ([`reflects_into_gap`]; BENCHMARKS.md, "Reflecting gaps": the ceiling over the housings +90% to
//! +240% uncut, within 14% RMS cut, for 22% more time; office3 gains 1,700 pieces and no clear accuracy,
//! so it is not the default).
//!
//! A one-sided P is not split by what lies behind it (it cannot see it). Candidate pairs come from a
//! uniform grid over the polygons' boxes (no quadratic work); P is then cut along each outline that
//! crosses its interior ([`crate::geometry::clip`]), and each convex piece becomes triangles and
//! parallelograms ([`polygonize`], [`affine_pieces`]) with P's material, object, sidedness and origin.
//! Luminaire openings are not split.

mod overlaps;
mod regions;

pub use overlaps::{remove_covered, Covered};

use super::polygonize::polygonize;
use super::{Diagnostic, Polygon, Scene, MAX_POLYGONS};
use crate::geometry::clip::{convex_hull, outline_planes, split_by_outline, Plane};
use crate::geometry::{Aabb, DVec2, DVec3, Ray, Shape};
use crate::visibility::brute_force::ray_polygon;
use crate::visibility::SEGMENT_EPSILON;
use rayon::prelude::*;
use regions::{emitting_regions, Region};

/// Default contact gap, relative to the smaller polygon's diameter: `cube.mgf`'s lamp hangs 1 cm under
/// the ceiling, 0.7% of the lamp's diagonal.
pub const DEFAULT_CONTACT_GAP: f64 = 0.02;
/// Largest contact gap accepted (relative): beyond it, "contact" would mean any nearby parallel surface.
pub const MAX_CONTACT_GAP: f64 = 0.25;
/// An emitting region lies on a surface within this many times the contact gap (10% of the smaller
/// diameter by default, at most [`MAX_CONTACT_GAP`]) where its light crosses the gap unobstructed
/// ([`gap_is_open`]): its back light stays concentrated within its outline's footprint while the gap
/// is a small fraction of its size (most of it lands within `g` of the outline), and cutting along an
/// emitter costs a few pieces. The corridor's lamps hang 2 cm under the ceiling, 3.5% of their
/// diagonal: missed at 2%, the straddling ceiling elements leaked their back light and the whole
/// corridor read +27% against the path tracer (median of 187 lit points), cut −1.6% (BENCHMARKS.md,
/// "Emitters a little further under a ceiling").
pub const EMITTER_GAP_FACTOR: f64 = 5.0;
/// Points closer than this fraction of P's diameter to an outline's edge lie on it: no piece is thinner.
const SNAP: f64 = 1e-5;
/// Largest area of a reflecting polygon lying across a gap on another, relative to the other's, for
/// `auto` to cut along it ([`reflects_into_gap`]): a lid over a surface (a lamp housing under a
/// ceiling, a book on a desk), not a layer of a thin shell (facets of comparable size).
const LID_AREA_RATIO: f64 = 0.25;
/// Most outlines one polygon is cut along (further ones are left out, with a warning).
const MAX_OUTLINES: usize = 256;
/// Most pieces one polygon may be cut into (the cut stops there, with a warning).
const MAX_PIECES: usize = 4096;
/// Most contact edges gathered on one polygon for footprints (further ones are left out).
const MAX_CONTACT_EDGES: usize = 4096;

/// Which contacts [`split_contacts`] cuts along (`--split-contacts`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum SplitContacts {
    /// None: polygons stay as the scene gives them.
    Off,
    /// Only the outlines of emitters that lie on a surface with their emitting side toward it, across
    /// a real gap (see the module doc): where trapped light would leak.
    #[default]
    Auto,
    /// As auto, and the outlines of reflecting objects lying across a real gap on a surface several
    /// times their size (a lamp housing under a ceiling, a picture off a wall): where reflected light
    /// bounces in the gap.
    Gaps,
    /// Every lying object's outline and every footprint.
    On,
}

/// What [`split_contacts`] did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct ContactSplit {
    /// Outlines (lying objects and footprints) that crossed a polygon's interior.
    pub outlines: usize,
    /// Input polygons that were cut.
    pub polygons_split: usize,
    /// The triangles and quads they became.
    pub pieces: usize,
}

impl std::fmt::Display for ContactSplit {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} polygons split along {} contact outlines into {} pieces",
            self.polygons_split, self.outlines, self.pieces
        )
    }
}

/// A polygon's (or an emitting region's) plane and size, computed once.
#[derive(Clone)]
struct Face {
    normal: DVec3,
    point: DVec3,
    diameter: f64,
    area: f64,
    bounds: Aabb,
}

impl Face {
    fn new(shape: &Shape) -> Self {
        Face {
            normal: shape.normal(),
            point: shape.vertices()[0],
            diameter: shape.diameter(),
            area: shape.area(),
            bounds: shape.bounds(),
        }
    }

    fn distance(&self, p: DVec3) -> f64 {
        self.normal.dot(p - self.point)
    }
}

/// Splits every polygon of `scene` along the outlines of the polygons in contact with it that `mode`
/// selects (`gap` relative to the smaller diameter, see the module doc): each is replaced, in place, by
/// its pieces. Budget overruns are warnings, never errors.
pub fn split_contacts(scene: &mut Scene, mode: SplitContacts, gap: f64) -> ContactSplit {
    let results = contact_pieces(scene, mode, gap);
    let mut report = ContactSplit::default();
    let mut polygons = Vec::with_capacity(scene.polygons.len());
    let mut counts = Vec::with_capacity(scene.polygons.len());
    for (i, result) in results.into_iter().enumerate() {
        let polygon = scene.polygons[i];
        let fits =
            |extra: usize| polygons.len() + extra + (scene.polygons.len() - i) <= MAX_POLYGONS;
        match result {
            Some(pieces) if fits(pieces.shapes.len()) => {
                report.outlines += pieces.outlines;
                report.polygons_split += 1;
                report.pieces += pieces.shapes.len();
                counts.push(pieces.shapes.len());
                polygons.extend(pieces.shapes.iter().map(|piece| Polygon {
                    shape: piece.shape,
                    under_contact: polygon.under_contact || piece.under_contact,
                    ..polygon
                }));
                if let Some(message) = pieces.warning {
                    warn(scene, i, message);
                }
            }
            Some(_) => {
                warn(
                    scene,
                    i,
                    format!(
                        "not split along its contacts: the scene would exceed {MAX_POLYGONS} polygons"
                    ),
                );
                counts.push(1);
                polygons.push(polygon);
            }
            None => {
                counts.push(1);
                polygons.push(polygon);
            }
        }
    }
    scene.origins.repeat(&counts);
    polygons.shrink_to_fit();
    scene.polygons = polygons;
    report
}

/// For each polygon of `scene`, its pieces when outlines of polygons in contact with it that `mode`
/// selects cross it (`None` when none does); the scene is left as it is. Luminaire openings are never cut.
pub fn contact_pieces(scene: &Scene, mode: SplitContacts, gap: f64) -> Vec<Option<Pieces>> {
    if mode == SplitContacts::Off {
        return vec![None; scene.polygons.len()];
    }
    let gap = gap.clamp(0.0, MAX_CONTACT_GAP);
    let faces: Vec<Face> = scene.polygons.iter().map(|p| Face::new(&p.shape)).collect();
    let grid = BoxGrid::new(&faces);
    let regions = emitting_regions(scene, &faces, &grid);
    let region_faces: Vec<Face> = regions.iter().map(|r| r.face.clone()).collect();
    let emitters = Emitters {
        grid: BoxGrid::new(&region_faces),
        regions,
    };
    let openings = scene.opening_luminaires();
    (0..scene.polygons.len())
        .into_par_iter()
        .map(|i| {
            if openings[i].is_some() || faces[i].diameter <= 0.0 {
                return None;
            }
            let outlines = contact_outlines(scene, &faces, &grid, &emitters, i, mode, gap);
            cut_polygon(&scene.polygons[i], &faces[i], outlines)
        })
        .collect()
}

/// The scene's emitting regions and a grid over their boxes.
struct Emitters {
    regions: Vec<Region>,
    grid: BoxGrid,
}

fn warn(scene: &mut Scene, polygon: usize, message: String) {
    let (file, line) = scene.origins.get(polygon);
    scene.warnings.push(Diagnostic {
        file,
        line,
        message,
    });
}

/// The cut of one polygon: convex triangles and quads with its front side, tiling it.
#[derive(Clone, Debug)]
pub struct Pieces {
    pub shapes: Vec<Piece>,
    /// Outlines that crossed it.
    pub outlines: usize,
    /// Why it was cut along fewer outlines than touch it (a budget), if it was.
    pub warning: Option<String>,
}

/// One piece of a cut polygon.
#[derive(Clone, Copy, Debug)]
pub struct Piece {
    pub shape: Shape,
    /// Inside one of the outlines it was cut along ([`Polygon::under_contact`]).
    pub under_contact: bool,
}

/// The outlines (cutting planes through their edges, in P's projection) of the polygons in contact with
/// polygon `i` that `mode` selects, in a deterministic order: the pieces of emitting regions shining
/// into a gap by region, then (`on` only) lying polygons by index, then footprints.
fn contact_outlines(
    scene: &Scene,
    faces: &[Face],
    grid: &BoxGrid,
    emitters: &Emitters,
    i: usize,
    mode: SplitContacts,
    gap: f64,
) -> Vec<Vec<Plane>> {
    let p = &faces[i];
    let two_sided = scene.polygons[i].two_sided;
    if mode != SplitContacts::On && scene.material_of(&scene.polygons[i]).reflectance.is_black() {
        // Light trapped over a black surface is absorbed there: nothing to leak.
        return Vec::new();
    }
    let reach = gap * p.diameter;
    let emitter_gap = (EMITTER_GAP_FACTOR * gap).min(MAX_CONTACT_GAP);
    // The signed distance of the corner farthest from P's plane when every corner lies within `g` of
    // it, else `None`; a one-sided P does not see what lies behind it.
    let lying = |corners: &mut dyn Iterator<Item = DVec3>, g: f64| {
        let distances: Vec<f64> = corners.map(|v| p.distance(v)).collect();
        let offset = farthest(&distances);
        (distances.iter().all(|d| d.abs() <= g) && (two_sided || offset >= -SNAP * p.diameter))
            .then_some(offset)
    };
    let facing_p = |corners: &[DVec3], normal: DVec3| outline_toward(p, corners, normal);
    let mut outlines = Vec::new();
    for r in emitters.grid.near(&p.bounds, emitter_gap * p.diameter) {
        let region = &emitters.regions[r];
        let size = p.diameter.min(region.face.diameter);
        let Some(offset) = lying(&mut region.corners(), emitter_gap * size) else {
            continue;
        };
        // Within the contact gap the emitter is in contact; further, up to the emitter gap, only
        // where its light crosses straight to P.
        let in_contact = offset.abs() <= gap * size;
        if shines_into_gap(region, p, offset) && (in_contact || gap_is_open(scene, grid, i, region))
        {
            outlines.extend(
                region
                    .pieces
                    .iter()
                    .map(|piece| facing_p(piece, region.face.normal)),
            );
        }
    }
    if mode == SplitContacts::Gaps {
        outlines.extend(
            grid.near(&p.bounds, reach)
                .into_iter()
                .filter(|&j| j != i && reflects_into_gap(scene, faces, i, j, gap, &lying))
                .map(|j| facing_p(scene.polygons[j].shape.vertices(), faces[j].normal)),
        );
    }
    if mode != SplitContacts::On {
        return outlines;
    }
    // Contact edges standing on P: (object, end, end, gap).
    let mut edges: Vec<(usize, DVec3, DVec3, f64)> = Vec::new();
    for j in grid.near(&p.bounds, reach) {
        if j == i {
            continue;
        }
        let q = &faces[j];
        let g = gap * p.diameter.min(q.diameter);
        let vertices = scene.polygons[j].shape.vertices();
        let distances: Vec<f64> = vertices.iter().map(|&v| p.distance(v)).collect();
        if !two_sided && farthest(&distances) < -SNAP * p.diameter {
            continue;
        }
        if distances.iter().all(|d| d.abs() <= g) {
            outlines.push(facing_p(vertices, q.normal));
            continue;
        }
        let n = vertices.len();
        for k in 0..n {
            let next = (k + 1) % n;
            if distances[k].abs() <= g
                && distances[next].abs() <= g
                && edges.len() < MAX_CONTACT_EDGES
            {
                edges.push((scene.polygons[j].object, vertices[k], vertices[next], g));
            }
        }
    }
    outlines.extend(footprints(p, &edges));
    outlines
}

/// The cutting planes of the outline of a convex polygon with `corners` and `normal`, projected onto
/// P's plane: the corners taken counter-clockwise seen from P's front.
fn outline_toward(p: &Face, corners: &[DVec3], normal: DVec3) -> Vec<Plane> {
    let mut outline = corners.to_vec();
    if normal.dot(p.normal) < 0.0 {
        outline.reverse();
    }
    outline_planes(&outline, p.normal)
}

/// The signed distance of largest magnitude (0 for none): on which side of a plane a polygon lies.
fn farthest(distances: &[f64]) -> f64 {
    distances
        .iter()
        .copied()
        .fold(0.0, |a: f64, d| if d.abs() > a.abs() { d } else { a })
}

/// Whether an emitting region lying on P at signed distance `offset` (its corner farthest from P's
/// plane) emits into the gap: the gap is real (not coplanar, where no light enters) and the region
/// emits toward P (`-offset` along P's normal). However open the gap's sides, an element of P
/// straddling the outline re-emits the emitter's back light from all its area: the classroom's 4 cm
/// tubes 2 cm under their housings (side openings 34% of the cavity) left the floor 10% and the desks
/// 6% too bright unsplit (BENCHMARKS.md, "Reference images and probes").
fn shines_into_gap(region: &Region, p: &Face, offset: f64) -> bool {
    real_gap(p, offset) && region.shines_toward(-offset * p.normal)
}

/// Whether some of an emitting region's light crosses the gap to P (polygon `i`) unobstructed: the
/// segment from some piece's centroid straight to P's plane meets no other polygon. Asked only of
/// regions beyond the contact gap (within it the emitter is in contact, whatever lies around): a tube
/// inside a lamp housing lies within the emitter gap of the ceiling over the housing, but its light
/// reaches the housing, not the ceiling (the classroom: 126 more ceiling and housing polygons cut along
/// tubes they cannot see without this test).
fn gap_is_open(scene: &Scene, grid: &BoxGrid, i: usize, region: &Region) -> bool {
    let p = &scene.polygons[i].shape;
    let (normal, on_p) = (p.normal(), p.vertices()[0]);
    region.pieces.iter().any(|piece| {
        let start = piece.iter().sum::<DVec3>() / piece.len() as f64;
        let end = start - normal * normal.dot(start - on_p);
        let ray = Ray::new(start, end - start);
        let mut bounds = Aabb::EMPTY;
        bounds.grow(start);
        bounds.grow(end);
        let (t_min, t_max) = (SEGMENT_EPSILON, 1.0 - SEGMENT_EPSILON);
        !grid.near(&bounds, 0.0).into_iter().any(|j| {
            j != i && ray_polygon(&ray, scene.polygons[j].shape.vertices(), t_min, t_max).is_some()
        })
    })
}

/// Whether a polygon lying on P at signed distance `offset` leaves a gap light can enter (not
/// coplanar with P, within [`SNAP`]).
fn real_gap(p: &Face, offset: f64) -> bool {
    offset.abs() > SNAP * p.diameter
}

/// Whether polygon `j` (Q) lies on polygon `i` (P) across a real gap with a reflecting surface toward
/// it (Q two-sided, or its front toward P), emitters aside (their regions are cut by
/// [`shines_into_gap`]). Light that enters such a gap bounces between the two: the classroom's lamp
/// housings hang 2 cm under the ceiling, and ceiling elements straddling a housing's outline averaged
/// the open ceiling's light into the gap, where P and Q reflected it back and forth (ρ 0.8 each): the
/// ceiling over the housings read +90% to +240% against the path tracer, still +100% at a third of the
/// default ε (BENCHMARKS.md, "Reflecting gaps"); `--split-contacts gaps` only. Coplanar and touching
/// pairs (no gap) and pairs where Q's side toward P is not a surface (a one-sided panel facing away)
/// are not cut, nor footprints, nor two parts of one object, nor a Q larger than [`LID_AREA_RATIO`] of
/// P: the nearly coplanar facets of a thin curved shell lie on each other's planes within the gap (the
/// classroom's chair backs: 3000 polygons cut into 13,500 pieces without that bound, for gaps that
/// light hardly enters).
fn reflects_into_gap(
    scene: &Scene,
    faces: &[Face],
    i: usize,
    j: usize,
    gap: f64,
    lying: &dyn Fn(&mut dyn Iterator<Item = DVec3>, f64) -> Option<f64>,
) -> bool {
    let (p, q) = (&faces[i], &faces[j]);
    let polygon = &scene.polygons[j];
    let material = scene.material_of(polygon);
    if material.reflectance.is_black()
        || !material.emission.is_black()
        || polygon.object == scene.polygons[i].object
        || polygon.shape.area() > LID_AREA_RATIO * scene.polygons[i].shape.area()
    {
        return false;
    }
    let g = gap * p.diameter.min(q.diameter);
    let Some(offset) = lying(&mut polygon.shape.vertices().iter().copied(), g) else {
        return false;
    };
    let toward_p = -offset * p.normal;
    real_gap(p, offset) && (polygon.two_sided || q.normal.dot(toward_p) > 0.0)
}

/// Convex hulls, in P's plane, of the chains of contact edges of one object that join end to end (within
/// their gap); a chain of fewer than three edges (a wall's foot) has no area and is no footprint.
fn footprints(p: &Face, edges: &[(usize, DVec3, DVec3, f64)]) -> Vec<Vec<Plane>> {
    let joined = |a: usize, b: usize| {
        let (ea, eb) = (&edges[a], &edges[b]);
        let joint = ea.3.max(eb.3);
        ea.0 == eb.0
            && [ea.1, ea.2]
                .iter()
                .any(|x| x.distance(eb.1) <= joint || x.distance(eb.2) <= joint)
    };
    // Chains: connected components of the "joined" relation, by flood fill.
    let mut chain_of = vec![usize::MAX; edges.len()];
    let mut members: Vec<Vec<usize>> = Vec::new();
    for start in 0..edges.len() {
        if chain_of[start] != usize::MAX {
            continue;
        }
        let chain = members.len();
        chain_of[start] = chain;
        let mut stack = vec![start];
        let mut chain_members = Vec::new();
        while let Some(a) = stack.pop() {
            chain_members.push(a);
            for (b, slot) in chain_of.iter_mut().enumerate() {
                if *slot == usize::MAX && joined(a, b) {
                    *slot = chain;
                    stack.push(b);
                }
            }
        }
        members.push(chain_members);
    }
    let (u, v) = p.normal.any_orthonormal_pair();
    members
        .into_iter()
        .filter(|chain| chain.len() >= 3)
        .filter_map(|chain| {
            let flat: Vec<DVec2> = chain
                .iter()
                .flat_map(|&k| [edges[k].1, edges[k].2])
                .map(|x| DVec2::new((x - p.point).dot(u), (x - p.point).dot(v)))
                .collect();
            let hull = convex_hull(&flat);
            let area2: f64 = crate::geometry::edges(&hull)
                .map(|(a, b)| a.perp_dot(b))
                .sum();
            (hull.len() >= 3 && area2 > (SNAP * p.diameter).powi(2)).then(|| {
                let outline: Vec<DVec3> =
                    hull.iter().map(|h| p.point + h.x * u + h.y * v).collect();
                outline_planes(&outline, p.normal)
            })
        })
        .collect()
}

/// Cuts `polygon` along `outlines`; `None` when none crosses its interior.
fn cut_polygon(polygon: &Polygon, face: &Face, outlines: Vec<Vec<Plane>>) -> Option<Pieces> {
    let snap = SNAP * face.diameter;
    let outlines: Vec<&[Plane]> = outlines.iter().map(Vec::as_slice).collect();
    cut_polygon_by(polygon, face, &outlines, &|piece, planes| {
        split_by_outline(piece, planes, snap)
    })
}

/// One convex piece cut by one outline's planes ([`split_by_outline`], [`split_pinwheel`]), the part
/// inside the outline last; `None` when the outline does not cross it.
///
/// [`split_pinwheel`]: crate::geometry::clip::split_pinwheel
type OutlineSplit<'a> = dyn Fn(&[DVec3], &[Plane]) -> Option<Vec<Vec<DVec3>>> + 'a;

/// Cuts `polygon` along `outlines` with `split` (one convex piece by one outline, `None` when it does
/// not cross the piece), within [`MAX_OUTLINES`] and [`MAX_PIECES`]; the pieces as triangles and
/// parallelograms, `None` when no outline crossed it.
fn cut_polygon_by(
    polygon: &Polygon,
    face: &Face,
    outlines: &[&[Plane]],
    split: &OutlineSplit<'_>,
) -> Option<Pieces> {
    let snap = SNAP * face.diameter;
    // Each piece with whether it lies inside an outline already cut along.
    let mut pieces = vec![(polygon.shape.vertices().to_vec(), false)];
    let mut used = 0;
    let mut warning = None;
    if outlines.len() > MAX_OUTLINES {
        warning = Some(format!(
            "{} objects touch this polygon: split along the first {MAX_OUTLINES} only",
            outlines.len()
        ));
    }
    for planes in outlines.iter().take(MAX_OUTLINES) {
        let mut next = Vec::with_capacity(pieces.len() + planes.len());
        let mut crossed = false;
        for (piece, inside) in &pieces {
            match split(piece, planes) {
                Some(parts) => {
                    crossed = true;
                    let last = parts.len() - 1;
                    next.extend(
                        parts
                            .into_iter()
                            .enumerate()
                            .map(|(k, part)| (part, *inside || k == last)),
                    );
                }
                None => next.push((piece.clone(), *inside)),
            }
        }
        if next.len() > MAX_PIECES {
            warning = Some(format!(
                "splitting this polygon along its contacts would give more than {MAX_PIECES} pieces: \
                 split along {used} of {} outlines",
                outlines.len()
            ));
            break;
        }
        if crossed {
            used += 1;
            pieces = next;
        }
    }
    if used == 0 {
        return None;
    }
    let mut shapes = Vec::new();
    for (piece, inside) in &pieces {
        match polygonize(piece) {
            Ok(convex) => shapes.extend(
                convex
                    .shapes
                    .into_iter()
                    .flat_map(|shape| affine_pieces(shape, snap))
                    .map(|shape| Piece {
                        shape,
                        under_contact: *inside,
                    }),
            ),
            // A piece with no area left after polygonize's tolerances: keep the polygon whole rather
            // than lose area.
            Err(_) => return None,
        }
    }
    Some(Pieces {
        shapes,
        outlines: used,
        warning,
    })
}

/// `shape` as shapes whose parametrisation is affine: a triangle or a parallelogram (opposite corners
/// summing to the same point within `snap`) as it is, any other quad as two triangles along its shorter
/// diagonal, same winding.
///
/// Why: the bases are orthonormal for the parametric measure ([`crate::bases`]), which is the area
/// measure only where the Jacobian is constant. Before push-pull and couplings solved with the overlap
/// matrix of a trapezoid ([`crate::bases::Overlap`]), a parent whose children were all constant got a
/// spurious gradient: cube.mgf's lamp, cut along the ceiling's diagonal into trapezoids, sent 8% more
/// power into the room under `--accuracy 10%` (BENCHMARKS.md, "Splitting surfaces along contacts").
/// Trapezoids are handled exactly now; pieces stay affine because their overlap matrix is the identity
/// (no solve per element and sweep) and the cube.mgf measurements were made with them.
fn affine_pieces(shape: Shape, snap: f64) -> Vec<Shape> {
    match shape {
        Shape::Quad([a, b, c, d]) if (a + c - b - d).length() > snap => {
            if a.distance(c) <= b.distance(d) {
                vec![Shape::Triangle([a, b, c]), Shape::Triangle([a, c, d])]
            } else {
                vec![Shape::Triangle([a, b, d]), Shape::Triangle([b, c, d])]
            }
        }
        shape => vec![shape],
    }
}

/// Uniform grid over the polygons' boxes: the polygons whose boxes come within a distance of a box.
struct BoxGrid {
    origin: DVec3,
    cell: f64,
    dims: [usize; 3],
    cells: Vec<Vec<u32>>,
}

impl BoxGrid {
    fn new(faces: &[Face]) -> Self {
        let bounds = faces.iter().fold(Aabb::EMPTY, |b, f| b.union(&f.bounds));
        let extent = bounds.extent();
        // About one cell per polygon, at most 64 per axis.
        let volume_side =
            (extent.x.max(1e-300) * extent.y.max(1e-300) * extent.z.max(1e-300)).cbrt();
        let side = faces.len().max(1) as f64;
        let cell = (extent.max_element() / 64.0)
            .max(volume_side / side.cbrt())
            .max(1e-300);
        let dims =
            [extent.x, extent.y, extent.z].map(|e| ((e / cell).floor() as usize + 1).min(64));
        let mut grid = BoxGrid {
            origin: if bounds.is_empty() {
                DVec3::ZERO
            } else {
                bounds.min
            },
            cell,
            dims,
            cells: vec![Vec::new(); dims[0] * dims[1] * dims[2]],
        };
        for (k, f) in faces.iter().enumerate() {
            if !f.bounds.is_empty() && f.bounds.min.is_finite() && f.bounds.max.is_finite() {
                for c in grid.cells_of(&f.bounds, 0.0) {
                    grid.cells[c].push(k as u32);
                }
            }
        }
        grid
    }

    fn cells_of(&self, b: &Aabb, margin: f64) -> Vec<usize> {
        let index = |p: DVec3| {
            let c = ((p - self.origin) / self.cell).floor();
            [c.x, c.y, c.z]
        };
        let (lo, hi) = (
            index(b.min - DVec3::splat(margin)),
            index(b.max + DVec3::splat(margin)),
        );
        let clamp = |x: f64, axis: usize| (x.max(0.0) as usize).min(self.dims[axis] - 1);
        let mut out = Vec::new();
        for x in clamp(lo[0], 0)..=clamp(hi[0], 0) {
            for y in clamp(lo[1], 1)..=clamp(hi[1], 1) {
                for z in clamp(lo[2], 2)..=clamp(hi[2], 2) {
                    out.push((x * self.dims[1] + y) * self.dims[2] + z);
                }
            }
        }
        out
    }

    /// Polygons whose boxes come within `margin` of `b`, each once, in index order.
    fn near(&self, b: &Aabb, margin: f64) -> Vec<usize> {
        let mut found: Vec<usize> = self
            .cells_of(b, margin)
            .into_iter()
            .flat_map(|c| self.cells[c].iter().map(|&k| k as usize))
            .collect();
        found.sort_unstable();
        found.dedup();
        found
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn corners(shape: &Shape) -> Vec<DVec3> {
        shape.vertices().to_vec()
    }

    #[test]
    fn trapezoids_become_two_triangles_and_parallelograms_stay() {
        let v = |x: f64, y: f64| DVec3::new(x, y, 0.0);
        let trapezoid = Shape::Quad([v(0.0, 0.0), v(4.0, 0.0), v(3.0, 1.0), v(1.0, 1.0)]);
        let pieces = affine_pieces(trapezoid, 1e-9);
        assert_eq!(pieces.len(), 2);
        let area: f64 = pieces.iter().map(Shape::area).sum();
        assert!((area - trapezoid.area()).abs() <= 1e-12 * area);
        for piece in &pieces {
            assert!(matches!(piece, Shape::Triangle(_)));
            assert!(
                piece.normal().dot(trapezoid.normal()) > 1.0 - 1e-12,
                "winding kept"
            );
            assert!(corners(piece)
                .iter()
                .all(|p| corners(&trapezoid).contains(p)));
        }
        let parallelogram = Shape::Quad([v(0.0, 0.0), v(4.0, 0.0), v(5.0, 1.0), v(1.0, 1.0)]);
        assert_eq!(affine_pieces(parallelogram, 1e-9), vec![parallelogram]);
        let triangle = Shape::Triangle([v(0.0, 0.0), v(1.0, 0.0), v(0.0, 1.0)]);
        assert_eq!(affine_pieces(triangle, 1e-9), vec![triangle]);
    }
}
