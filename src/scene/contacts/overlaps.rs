//! Coplanar overlaps: two polygons in one plane whose interiors overlap are two surfaces at the same
//! place (a renderer shows whichever wins its depth test). A radiosity solve cannot tell which is in
//! front: each receives the light that arrives there and reflects it, so the place sends up to twice
//! its light; a reflecting cavity containing such a place can send back more than it receives, and the
//! iteration diverges. The classroom's window sill, a closed 1 cm box of ρ 0.84 whose back face is
//! coplanar with a strip of the window frame: under `--accuracy 10%` its elements grew by 2.3% per
//! sweep (without the strip they shrink by ρ² = 0.71 per sweep; BENCHMARKS.md, "Coplanar overlaps").
//!
//! Of two overlapping coplanar polygons one keeps the place whole and the other is cut along its
//! outline (a pinwheel cut, [`split_pinwheel`]: no strips as narrow as a foot across a floor) and
//! loses, inside it, the sides the first covers: a piece both of whose sides are covered is dropped,
//! a two-sided piece covered on one side becomes one-sided toward the other. Sides are judged in the
//! cut polygon's frame: a one-sided polygon covers the side its normal points to, a two-sided one
//! both. Two steps, each by a strict order of the polygons, so that no place is left without a
//! surface: first among polygons of one material the larger keeps the place (the window frame strip
//! goes, the sill's face stays whole; office3's desk-top end pieces lose what lies on the desk top),
//! then among all the smaller does (a decal, a rug; the later one where the areas are equal). One order for both could not do it: with mixed rules three overlapping polygons
//! can each lose to another. Coplanar means within [`SNAP`] of the larger diameter (0.1 mm in a 10 m
//! room): `cube.mgf`'s lamp, 1 cm under its ceiling, is a contact ([`super::split_contacts`]), not an
//! overlap. Luminaire openings take no part.

use super::regions::coplanar;
use super::{cut_polygon_by, outline_toward, BoxGrid, Face, SNAP};
use crate::geometry::clip::{split_pinwheel, Plane};
use crate::geometry::{DVec3, Shape};
use crate::scene::{Diagnostic, Polygon, Scene};
use rayon::prelude::*;

/// What [`remove_covered`] did.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct Covered {
    /// Polygons that lost a covered part (a side of it, or all of it).
    pub polygons: usize,
    /// Area of the sides dropped, each side counted once (scene units squared).
    pub area: f64,
}

/// The sides of a polygon that are surfaces, in some polygon's frame: toward its normal, away from it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Sides {
    front: bool,
    back: bool,
}

impl Sides {
    fn of(polygon: &Polygon, same_facing: bool) -> Self {
        Sides {
            front: polygon.two_sided || same_facing,
            back: polygon.two_sided || !same_facing,
        }
    }

    fn without(self, covered: Sides) -> Self {
        Sides {
            front: self.front && !covered.front,
            back: self.back && !covered.back,
        }
    }

    fn count(self) -> usize {
        usize::from(self.front) + usize::from(self.back)
    }
}

/// One polygon that covers part of another: its outline projected on the other, the sides it covers.
struct Cover {
    polygon: usize,
    outline: Vec<Plane>,
    sides: Sides,
}

/// The result for one polygon that loses something: what replaces it, the area of sides dropped, and
/// the first polygon covering it (for the warning).
struct Uncovered {
    polygons: Vec<Polygon>,
    area: f64,
    covered_by: usize,
}

/// Cuts every polygon of `scene` that a larger coplanar polygon of the same material overlaps, then
/// every polygon that a smaller coplanar one overlaps, and drops the covered sides of the pieces
/// inside (see the module doc); one warning per pair of places (files, include chains) involved.
/// Candidate pairs come from a uniform grid over the polygons' boxes (no quadratic work).
pub fn remove_covered(scene: &mut Scene) -> Covered {
    let mut notes = Notes::default();
    let mut planes = Planes::new(scene);
    if cut_overlapped(scene, &planes, &mut notes, Step::SameMaterial) {
        planes = Planes::new(scene);
    }
    cut_overlapped(scene, &planes, &mut notes, Step::Decals);
    notes.warn(scene)
}

/// Each polygon's plane and size, and the polygons in its plane whose boxes touch its own (found once
/// through a uniform grid over the boxes, for both steps unless the first changes the scene).
struct Planes {
    faces: Vec<Face>,
    coplanar: Vec<Vec<u32>>,
}

impl Planes {
    fn new(scene: &Scene) -> Self {
        let faces: Vec<Face> = scene.polygons.iter().map(|p| Face::new(&p.shape)).collect();
        let grid = BoxGrid::new(&faces);
        let openings = scene.opening_luminaires();
        let coplanar = (0..faces.len())
            .into_par_iter()
            .map(|i| {
                if openings[i].is_some() || faces[i].diameter <= 0.0 {
                    return Vec::new();
                }
                grid.near(&faces[i].bounds, SNAP * faces[i].diameter)
                    .into_iter()
                    .filter(|&j| j != i && openings[j].is_none())
                    .filter(|&j| coplanar(scene, &faces, i, j, SNAP))
                    .map(|j| j as u32)
                    .collect()
            })
            .collect();
        Planes { faces, coplanar }
    }
}

/// What was dropped, one group per pair of places (covered, covering).
#[derive(Default)]
struct Notes {
    groups: Vec<Group>,
}

/// One group of [`Notes`]: its places, the first pair's files and lines, the number of polygons that
/// lost something and the side area they lost.
struct Group {
    places: (usize, usize),
    covered: (std::path::PathBuf, usize),
    cover: (std::path::PathBuf, usize),
    polygons: usize,
    area: f64,
}

impl Notes {
    fn add(&mut self, scene: &Scene, covered: usize, cover: usize, area: f64) {
        let places = (
            scene.origins.place_of(covered),
            scene.origins.place_of(cover),
        );
        match self.groups.iter_mut().find(|g| g.places == places) {
            Some(group) => {
                group.polygons += 1;
                group.area += area;
            }
            None => self.groups.push(Group {
                places,
                covered: scene.origins.get(covered),
                cover: scene.origins.get(cover),
                polygons: 1,
                area,
            }),
        }
    }

    fn warn(self, scene: &mut Scene) -> Covered {
        let mut report = Covered::default();
        for group in self.groups {
            let (count, area) = (group.polygons, group.area);
            report.polygons += count;
            report.area += area;
            let ((file, line), (cover_file, cover_line)) = (group.covered, group.cover);
            scene.warnings.push(Diagnostic {
                file,
                line,
                message: format!(
                    "{count} polygon(s) from here (the first at this line) lie in the plane of others \
                     from {}:{} and overlap them: one surface per side is kept where they overlap \
                     ({area:.3e} of sides dropped), two at one place would double its light \
                     (--keep-duplicates keeps them)",
                    cover_file.display(),
                    cover_line
                ),
            });
        }
        report
    }
}

/// Which polygon of an overlapping pair keeps the place: the larger one, the later where the areas
/// are equal (a strict order, so no place is left without a surface).
fn precedes(faces: &[Face], i: usize, j: usize) -> bool {
    let (a, b) = (faces[i].area, faces[j].area);
    a > b || (a == b && i > j)
}

/// Which overlaps a step resolves, and which polygon of a pair keeps the place.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Step {
    /// Pairs of one material: the larger ([`precedes`]); nothing is cut off it.
    SameMaterial,
    /// Any pair: the smaller (a decal, a rug).
    Decals,
}

/// Cuts every polygon that `step` lets another coplanar polygon cover ([`covers_of`], [`uncover`]);
/// whether it changed anything.
fn cut_overlapped(scene: &mut Scene, planes: &Planes, notes: &mut Notes, step: Step) -> bool {
    let results: Vec<Option<Uncovered>> = (0..scene.polygons.len())
        .into_par_iter()
        .map(|i| {
            let covers = covers_of(scene, planes, i, step);
            (!covers.is_empty())
                .then(|| uncover(&scene.polygons[i], &planes.faces[i], &covers))
                .flatten()
        })
        .collect();
    if results.iter().all(Option::is_none) {
        return false;
    }
    let mut polygons = Vec::with_capacity(scene.polygons.len());
    let mut counts = Vec::with_capacity(scene.polygons.len());
    for (i, result) in results.into_iter().enumerate() {
        match result {
            Some(uncovered) => {
                notes.add(scene, i, uncovered.covered_by, uncovered.area);
                counts.push(uncovered.polygons.len());
                polygons.extend(uncovered.polygons);
            }
            None => {
                counts.push(1);
                polygons.push(scene.polygons[i]);
            }
        }
    }
    scene.origins.repeat(&counts);
    scene.polygons = polygons;
    true
}

/// The polygons that cover part of polygon `i` in `step`: coplanar with it, keeping the place over it,
/// and covering one of its sides; their outlines may or may not cross it ([`uncover`] finds out).
fn covers_of(scene: &Scene, planes: &Planes, i: usize, step: Step) -> Vec<Cover> {
    let faces = &planes.faces;
    let p = &faces[i];
    let own = Sides::of(&scene.polygons[i], true);
    planes.coplanar[i]
        .iter()
        .map(|&j| j as usize)
        .filter(|&j| match step {
            Step::SameMaterial => {
                scene.polygons[j].material == scene.polygons[i].material && precedes(faces, j, i)
            }
            Step::Decals => precedes(faces, i, j),
        })
        .filter_map(|j| {
            let q = &scene.polygons[j];
            let sides = Sides::of(q, faces[j].normal.dot(p.normal) > 0.0);
            (own.without(sides) != own).then(|| Cover {
                polygon: j,
                outline: outline_toward(p, q.shape.vertices(), faces[j].normal),
                sides,
            })
        })
        .collect()
}

/// `polygon` cut along the outlines of `covers`, each piece with the sides no cover of it leaves; `None`
/// when no piece lies inside a cover (the outlines only touch it).
fn uncover(polygon: &Polygon, face: &Face, covers: &[Cover]) -> Option<Uncovered> {
    let outlines: Vec<&[Plane]> = covers.iter().map(|c| c.outline.as_slice()).collect();
    let snap = SNAP * face.diameter;
    let pinwheel = |piece: &[DVec3], planes: &[Plane]| split_pinwheel(piece, planes, snap);
    let shapes = match cut_polygon_by(polygon, face, &outlines, &pinwheel) {
        Some(pieces) => pieces.shapes.iter().map(|piece| piece.shape).collect(),
        None => vec![polygon.shape],
    };
    let own = Sides::of(polygon, true);
    let mut result = Uncovered {
        polygons: Vec::with_capacity(shapes.len()),
        area: 0.0,
        covered_by: usize::MAX,
    };
    for shape in shapes {
        let centre = shape.centroid();
        let mut sides = own;
        for cover in covers {
            if cover
                .outline
                .iter()
                .all(|plane| plane.distance(centre) <= 0.0)
            {
                sides = sides.without(cover.sides);
                result.covered_by = result.covered_by.min(cover.polygon);
            }
        }
        result.area += (own.count() - sides.count()) as f64 * shape.area();
        let piece = |shape: Shape, two_sided: bool| Polygon {
            shape,
            two_sided,
            ..*polygon
        };
        match (sides.front, sides.back) {
            (true, true) => result.polygons.push(piece(shape, true)),
            (true, false) => result.polygons.push(piece(shape, false)),
            (false, true) => result.polygons.push(piece(shape.flipped(), false)),
            (false, false) => {}
        }
    }
    (result.covered_by != usize::MAX).then_some(result)
}
