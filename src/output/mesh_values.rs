//! Radiosity at the vertices of the leaf elements, for smooth (Gouraud, as in RenderPark) shading and for
//! illuminated-model export.
//!
//! Leaves carry constant radiance; smooth shading averages it to their corners and interpolates. Two things
//! make the result free of cracks:
//! - vertices are welded by position within a *smoothing group*: the patches that are coplanar, share a
//!   material and face the same way (a triangulated floor is one group), so the average runs across patch
//!   borders;
//! - *T-vertices* (a corner of a small leaf lying inside an edge of a larger neighbour) take the value
//!   interpolated along that larger edge, and the larger leaf interpolates through them (a fan from its
//!   centre), so both sides of every edge agree.
//!
//! The quadtree splits edges at their midpoints, so T-vertices sit at dyadic points of an edge: they are
//! found by looking up the edge midpoint among the welded vertices, recursively.

use crate::color::Rgb;
use crate::geometry::cubature::gauss_nodes;
use crate::geometry::{Aabb, DVec2, DVec3, Shape};
use crate::hierarchy::{ElementId, Hierarchy};
use rayon::prelude::*;
use smallvec::SmallVec;
use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

/// Marks an element that is not a leaf in [`VertexRadiosity::leaf_slot`].
const NOT_A_LEAF: u32 = u32::MAX;
/// Vertices closer than this fraction of the scene diagonal are the same vertex.
const WELD_TOLERANCE: f64 = 1e-7;
/// Patches whose unit normals' dot product is at least this are coplanar-compatible (about 0.08 degrees).
const SAME_NORMAL_COS: f64 = 1.0 - 1e-6;
/// Deepest midpoint recursion along one edge (far below any element size that matters).
const MAX_EDGE_DEPTH: u32 = 40;

/// Radiosity averaged to the welded vertices of the leaf elements of a [`Hierarchy`], with the T-vertex
/// structure needed to interpolate it continuously. Build once, then use for rendering and export; it
/// refers to the hierarchy it was built from by element id.
#[derive(Clone, Debug)]
pub struct VertexRadiosity {
    positions: Vec<DVec3>,
    /// Per vertex, its smoothing group: the patch whose normal it takes.
    vertex_group: Vec<u32>,
    /// Smooth shading's vertex values: the leaves' own values at their corners, area-weighted, with
    /// T-vertices interpolated along the longest edge holding them.
    values: Vec<Rgb>,
    /// Continuous shading's vertex values ([`VertexRadiosity::evaluate_continuous`]): the own
    /// values, area-weighted, of every leaf whose outline passes through the vertex, with the range
    /// of their luminances, leaves of patches cut out under a contact
    /// ([`crate::hierarchy::Patch::under_contact`]) apart.
    outline_values: Vec<SharedValue>,
    /// The same for the leaves under a contact, at the vertices they touch: across a contact
    /// outline each side averages its own leaves, so that the step there stays.
    under_outline_values: FastMap<u32, SharedValue>,
    /// Per element of the hierarchy: index into `leaves`, or [`NOT_A_LEAF`].
    leaf_slot: Vec<u32>,
    leaves: Vec<LeafVertices>,
}

/// What [`VertexRadiosity::evaluate_continuous_at`] computes once per leaf: the correction at each
/// of its vertices, the mean of their interpolation over the leaf, the bubble's normalisation. A
/// render keeps one per row of pixels, where consecutive samples mostly fall on the same leaf:
/// seamless shading's render phase at 1024² went from 0.59 to 0.43 s on one thread, against 0.36 s
/// for the plain expansion (BENCHMARKS.md, "Seamless shading's corrections once per leaf"). For
/// one [`VertexRadiosity`] and the hierarchy it was built from.
#[derive(Clone, Debug)]
pub struct LeafCorrections {
    /// The leaf these are for ([`NOT_A_LEAF`]: none yet).
    leaf: ElementId,
    below: f64,
    corrections: SmallVec<[(u32, Rgb); 8]>,
    mean: Rgb,
    bubble_mean: f64,
}

impl LeafCorrections {
    /// The correction at vertex `v` (0 for a vertex that is not the leaf's).
    fn at(&self, v: u32) -> Rgb {
        self.corrections
            .iter()
            .find(|&&(w, _)| w == v)
            .map_or(Rgb::BLACK, |&(_, c)| c)
    }
}

impl Default for LeafCorrections {
    fn default() -> Self {
        LeafCorrections {
            leaf: NOT_A_LEAF,
            below: f64::NAN,
            corrections: SmallVec::new(),
            mean: Rgb::BLACK,
            bubble_mean: 1.0,
        }
    }
}

#[derive(Clone, Debug)]
struct LeafVertices {
    element: ElementId,
    /// Vertex ids of the shape's corners (the first 3 for a triangle).
    corners: [u32; 4],
    /// The boundary loop (corners and T-vertices, counter-clockwise) when some edge carries T-vertices.
    boundary: Option<Box<[u32]>>,
}

/// A triangle mesh of the leaf elements with radiance per vertex (T-vertices fanned as in rendering).
#[derive(Clone, Debug, Default)]
pub struct ShadedMesh {
    pub positions: Vec<DVec3>,
    pub normals: Vec<DVec3>,
    /// Linear exitant radiance at each vertex.
    pub radiance: Vec<Rgb>,
    /// Counter-clockwise seen from the front (the radiating side).
    pub triangles: Vec<[u32; 3]>,
}

/// A T-vertex found inside edge `(a, b)` of a leaf at parameter `s` along it.
#[derive(Clone, Copy, Debug)]
struct Anchor {
    a: u32,
    b: u32,
    s: f64,
    edge_length: f64,
}

impl VertexRadiosity {
    /// Welds the leaves' corners, averages leaf radiance to them (area-weighted) and anchors T-vertices.
    pub fn new(hierarchy: &Hierarchy) -> Self {
        let leaves = hierarchy.leaves();
        let bounds = hierarchy.patch_bounds();
        let tolerance = (WELD_TOLERANCE * bounds.diagonal()).max(1e-300);

        // Pass 1: weld corner positions regardless of patch, and note which patches meet at each point.
        let mut welder = Welder::new(tolerance);
        let mut corner_points: Vec<[u32; 4]> = Vec::with_capacity(leaves.len());
        let mut point_patches: Vec<Ids> = Vec::new();
        for &leaf in &leaves {
            let element = hierarchy.element(leaf);
            let mut ids = [0u32; 4];
            for (k, &p) in element.shape().vertices().iter().enumerate() {
                let id = welder.insert(p);
                if id as usize == point_patches.len() {
                    point_patches.push(Ids::new());
                }
                let list = &mut point_patches[id as usize];
                if !list.contains(&element.patch()) {
                    list.push(element.patch());
                }
                ids[k] = id;
            }
            corner_points.push(ids);
        }

        // Smoothing groups: patches meeting at a point with the same material and normal.
        let mut groups = UnionFind::new(hierarchy.patches.len());
        for list in &point_patches {
            for (i, &p) in list.iter().enumerate() {
                for &q in &list[i + 1..] {
                    if compatible(hierarchy, p, q) {
                        groups.union(p, q);
                    }
                }
            }
        }
        let group_of: Vec<u32> = (0..hierarchy.patches.len() as u32)
            .map(|p| groups.find(p))
            .collect();
        drop(point_patches);

        // Pass 2: one vertex per (point, group); area-weighted average of the leaves touching it.
        let mut vertex_of: FastMap<(u32, u32), u32> = FastMap::default();
        let mut positions = Vec::new();
        let mut sums: Vec<VertexSum> = Vec::new();
        // Leaves under a contact count apart (see `under_outline_values`).
        let under = |leaf: ElementId| hierarchy.patch_of(leaf).under_contact;
        let mut under_sums: FastMap<u32, VertexSum> = FastMap::default();
        let mut vertex_group: Vec<u32> = Vec::new();
        let mut leaf_slot = vec![NOT_A_LEAF; hierarchy.elements.len()];
        let mut records = Vec::with_capacity(leaves.len());
        for (slot, (&leaf, points)) in leaves.iter().zip(&corner_points).enumerate() {
            let element = hierarchy.element(leaf);
            let group = group_of[element.patch() as usize];
            let mut corners = [0u32; 4];
            for k in 0..element.shape().vertex_count() {
                let id = *vertex_of.entry((points[k], group)).or_insert_with(|| {
                    positions.push(welder.points[points[k] as usize]);
                    vertex_group.push(group);
                    sums.push(VertexSum::default());
                    positions.len() as u32 - 1
                });
                let sum = if under(leaf) {
                    under_sums.entry(id).or_default()
                } else {
                    &mut sums[id as usize]
                };
                // The leaf's own value at this corner (its average with the constant basis).
                let corner = hierarchy.exitant_radiance_at(leaf, element.shape().vertices()[k]);
                sum.add(corner, element.area);
                corners[k] = id;
            }
            leaf_slot[leaf as usize] = slot as u32;
            records.push(LeafVertices {
                element: leaf,
                corners,
                boundary: None,
            });
        }
        drop(corner_points);
        let mut values: Vec<Rgb> = sums.iter().map(VertexSum::average).collect();
        // Smooth shading averages both sides of a contact outline (RenderPark's look).
        for (&v, under) in &under_sums {
            let open = &sums[v as usize];
            values[v as usize] = (open.value + under.value) / (open.area + under.area);
        }

        // T-vertices: dyadic points of each leaf edge that are vertices of the same group.
        let lookup = VertexLookup {
            welder: &welder,
            vertex_of: &vertex_of,
            positions: &positions,
            tolerance,
        };
        // Where patches of a group meet without sharing whole edges (a surface split along a contact
        // outline, scene::contacts), a corner of one lies inside the other's edge at any parameter: such
        // vertices join the edge's outline (fanned), with their own averaged value, on both sides.
        let outline =
            OutlineVertices::new(hierarchy, &records, &positions, &vertex_group, tolerance);
        let found: Vec<_> = records
            .par_iter()
            .map(|record| {
                let element = hierarchy.element(record.element);
                let group = group_of[element.patch() as usize];
                let root = hierarchy.patch_shape(element.patch());
                let n = element.shape().vertex_count();
                let mut loop_ids = Vec::with_capacity(n);
                let mut anchors = Vec::new();
                for k in 0..n {
                    let (a, b) = (record.corners[k], record.corners[(k + 1) % n]);
                    loop_ids.push(a);
                    let before = anchors.len();
                    lookup.edge_vertices(group, a, b, &mut anchors);
                    let mut inside: Vec<(f64, u32)> = anchors[before..]
                        .iter()
                        .map(|(v, anchor)| (anchor.s, *v))
                        .collect();
                    let (pa, pb) = (positions[a as usize], positions[b as usize]);
                    if along_outline(root, pa, pb, tolerance) {
                        for found in outline.inside(pa, pb, group, (a, b)) {
                            if !inside.iter().any(|&(_, v)| v == found.1) {
                                inside.push(found);
                            }
                        }
                        inside.sort_by(|x, y| x.0.total_cmp(&y.0));
                    }
                    loop_ids.extend(inside.iter().map(|&(_, v)| v));
                }
                let boundary = (loop_ids.len() > n).then(|| loop_ids.into_boxed_slice());
                (boundary, anchors)
            })
            .collect();
        // The welding structures are done with; what follows holds one entry per vertex.
        drop(outline);
        drop(vertex_of);
        drop(welder);

        // Anchor each T-vertex on the longest edge containing it; resolve in dependency order so that an
        // edge's end points (themselves possibly T-vertices of larger edges) are final first.
        // Only T-vertices have one (a few percent of the vertices).
        let mut anchor_of: FastMap<u32, Anchor> = FastMap::default();
        // For continuous shading every leaf whose outline passes through a vertex counts there with
        // its own expansion, T-vertices included (not anchored): a polynomial the leaves share is
        // then every vertex's value.
        let mut outline_sums = sums;
        for (record, (boundary, anchors)) in records.iter_mut().zip(found) {
            if let Some(boundary) = &boundary {
                let element = hierarchy.element(record.element);
                for &v in boundary.iter().filter(|v| !record.corners.contains(v)) {
                    let sum = if under(record.element) {
                        under_sums.entry(v).or_default()
                    } else {
                        &mut outline_sums[v as usize]
                    };
                    let at = hierarchy.exitant_radiance_at(record.element, positions[v as usize]);
                    sum.add(at, element.area);
                }
            }
            record.boundary = boundary;
            for (v, anchor) in anchors {
                let slot = anchor_of.entry(v).or_insert(anchor);
                if anchor.edge_length > slot.edge_length {
                    *slot = anchor;
                }
            }
        }
        resolve_anchors(&anchor_of, &mut values);

        VertexRadiosity {
            positions,
            vertex_group,
            values,
            outline_values: outline_sums.iter().map(VertexSum::shared).collect(),
            under_outline_values: under_sums
                .into_iter()
                .map(|(v, sum)| (v, sum.shared()))
                .collect(),
            leaf_slot,
            leaves: records,
        }
    }

    pub fn vertex_count(&self) -> usize {
        self.positions.len()
    }

    /// Radiance at the welded vertex `id`.
    pub fn vertex_value(&self, id: usize) -> Rgb {
        self.values[id]
    }

    pub fn vertex_position(&self, id: usize) -> DVec3 {
        self.positions[id]
    }

    /// The outline of leaf `leaf` as welded vertex ids (corners and T-vertices, counter-clockwise) when
    /// corners of its neighbours lie inside its edges; `None` when its own corners are its whole outline.
    /// Triangulating such a leaf from its corners alone leaves cracks where the neighbours' edges meet it.
    pub fn outline(&self, leaf: ElementId) -> Option<&[u32]> {
        let slot = *self.leaf_slot.get(leaf as usize)?;
        if slot == NOT_A_LEAF {
            return None;
        }
        self.leaves[slot as usize].boundary.as_deref()
    }

    /// Number of leaves whose edges carry T-vertices (interpolated by a fan from their centre).
    pub fn fanned_leaf_count(&self) -> usize {
        self.leaves.iter().filter(|l| l.boundary.is_some()).count()
    }

    /// Smoothly interpolated radiance at point `p` of leaf element `leaf`: barycentric on a triangle,
    /// bilinear on a quad, or barycentric in the fan triangle containing `p` when the leaf has T-vertices.
    /// Returns the leaf's own radiance for an element that was not a leaf when this was built.
    pub fn evaluate(&self, hierarchy: &Hierarchy, leaf: ElementId, p: DVec3) -> Rgb {
        let uv = hierarchy.element(leaf).shape().parameters_of(p);
        self.interpolate(hierarchy, leaf, p, uv, |v| self.values[v as usize])
            .unwrap_or_else(|| hierarchy.average_radiance(leaf))
    }

    /// The leaf's basis expansion at `p` with its jumps at the leaf's edges removed: the expansion,
    /// plus the smooth interpolation of the averaged vertex values ([`Self::evaluate`]), minus the same
    /// interpolation of the leaf's own expansion at those vertices. Along an edge a linear or
    /// bilinear expansion equals the interpolation of its own values at the edge's vertices (corners
    /// and T-vertices), so there the value is the smooth one, which both sides share: continuous across
    /// every edge of a smoothing group; inside the leaf it keeps the expansion's shape (with quadratic
    /// and cubic bases the jumps shrink to the expansion's curvature along the edge). The added
    /// interpolation moves the leaf's mean, the solution's power on it; a bubble, zero on the leaf's
    /// edges, gives it back ([`unit_bubble`]), which on cube.mgf's ceiling around its lamp brings the
    /// error from 203% to 12% (BENCHMARKS.md, "Continuous shading that keeps each element's mean").
    /// A surface cut along a contact outline keeps its step there: leaves of pieces under the contact
    /// average among themselves at the outline's vertices (`Patch::under_contact`). Returns the
    /// leaf's expansion for an element that was not a leaf when this was built.
    ///
    /// `below`: the relative luminance step between the leaf's own value at a vertex and the farthest
    /// of the other leaves' values there below which the leaf's step is removed wholly
    /// (`f64::INFINITY`: every step); steps of twice that or more are kept, those in between removed
    /// in part ([`Shading::Seamless`]).
    ///
    /// [`Shading::Seamless`]: super::render::Shading::Seamless
    pub fn evaluate_continuous(
        &self,
        hierarchy: &Hierarchy,
        leaf: ElementId,
        p: DVec3,
        below: f64,
    ) -> Rgb {
        let uv = hierarchy.element(leaf).shape().parameters_of(p);
        self.evaluate_continuous_at(
            hierarchy,
            leaf,
            p,
            uv,
            below,
            &mut LeafCorrections::default(),
        )
    }

    /// [`Self::evaluate_continuous`] where the caller knows `p`'s parameters `uv` in the leaf (a
    /// renderer's point location gives them): the leaf's own values at its corners come from the
    /// basis' corner values, so that a sample evaluates the basis once, not at every vertex too.
    /// What depends on the leaf alone comes from `memo` when it holds this leaf (and `below`), and
    /// goes into it otherwise: a caller whose samples run over the same leaf (a row of pixels, a
    /// pixel's strata) keeps one per run. The value is the same either way, bit for bit.
    pub fn evaluate_continuous_at(
        &self,
        hierarchy: &Hierarchy,
        leaf: ElementId,
        p: DVec3,
        uv: DVec2,
        below: f64,
        memo: &mut LeafCorrections,
    ) -> Rgb {
        let expansion = hierarchy.radiance_at_parameters(leaf, uv);
        let Some(record) = self.record(leaf) else {
            return expansion.map(|c| c.max(0.0));
        };
        let shape = hierarchy.element(leaf).shape();
        if memo.leaf != leaf || memo.below.to_bits() != below.to_bits() {
            *memo = self.leaf_corrections(hierarchy, leaf, record, shape, below);
        }
        let at = self.interpolate(hierarchy, leaf, p, uv, |v| memo.at(v));
        (expansion + at.unwrap_or(Rgb::BLACK)
            - memo.mean * unit_bubble(shape, memo.bubble_mean, uv))
        .map(|c| c.max(0.0))
    }

    /// [`LeafCorrections`] of leaf `leaf` (its vertices `record`, its shape `shape`) for steps
    /// removed below `below`.
    fn leaf_corrections(
        &self,
        hierarchy: &Hierarchy,
        leaf: ElementId,
        record: &LeafVertices,
        shape: &Shape,
        below: f64,
    ) -> LeafCorrections {
        let corners = &record.corners[..shape.vertex_count()];
        let under = hierarchy.patch_of(leaf).under_contact;
        let correction = |v: u32| {
            let own = match corners.iter().position(|&id| id == v) {
                Some(k) => hierarchy.radiance_at_corner(leaf, k),
                None => hierarchy.radiance_at(leaf, self.positions[v as usize]),
            };
            let under_side = if under {
                self.under_outline_values.get(&v).copied()
            } else {
                None
            };
            let shared = under_side.unwrap_or(self.outline_values[v as usize]);
            // The step to the leaf farthest from this one there, relative to the larger: two
            // neighbours a factor r apart both see (r - 1) / r.
            let a = own.luminance();
            let (low, high) = (f64::from(shared.low), f64::from(shared.high));
            let b = if a - low > high - a { low } else { high };
            let step = (a - b).abs() / a.abs().max(b.abs()).max(f64::MIN_POSITIVE);
            (shared.value - own) * (2.0 - step / below).clamp(0.0, 1.0)
        };
        let vertices = record.boundary.as_deref().unwrap_or(corners);
        let nodes = area_nodes(shape);
        let mut memo = LeafCorrections {
            leaf,
            below,
            corrections: vertices.iter().map(|&v| (v, correction(v))).collect(),
            mean: Rgb::BLACK,
            bubble_mean: bubble_mean(shape, &nodes),
        };
        memo.mean = self.interpolation_mean(record, shape, &nodes, |v| memo.at(v));
        memo
    }

    /// The mean over leaf `record`'s area (its shape `shape`, area nodes `nodes`: [`area_nodes`])
    /// of [`Self::interpolate`]'s field for `value`: exact for triangles, fans (linear on each fan
    /// triangle) and quads (bilinear in the parameters times a Jacobian linear in them).
    fn interpolation_mean(
        &self,
        record: &LeafVertices,
        shape: &Shape,
        nodes: &AreaNodes,
        value: impl Fn(u32) -> Rgb,
    ) -> Rgb {
        let n = shape.vertex_count();
        let c = |k: usize| value(record.corners[k]);
        match (&record.boundary, shape) {
            (None, Shape::Triangle(_)) => (c(0) + c(1) + c(2)) / 3.0,
            (None, Shape::Quad(_)) => {
                let corners = [c(0), c(1), c(2), c(3)];
                nodes
                    .iter()
                    .fold(Rgb::BLACK, |sum, &(uv, w)| sum + bilinear(corners, uv) * w)
            }
            (Some(boundary), _) => {
                let centre = fan_centre(shape);
                let centre_value = corner_average(&record.corners[..n], &value);
                let (mut sum, mut area) = (Rgb::BLACK, 0.0);
                for i in 0..boundary.len() {
                    let (a, b) = (boundary[i], boundary[(i + 1) % boundary.len()]);
                    let (pa, pb) = (self.positions[a as usize], self.positions[b as usize]);
                    let piece = (pa - centre).cross(pb - centre).length();
                    sum += (centre_value + value(a) + value(b)) * (piece / 3.0);
                    area += piece;
                }
                if area > 0.0 {
                    sum / area
                } else {
                    centre_value
                }
            }
        }
    }

    /// The vertices of leaf `leaf`; `None` for an element that was not a leaf when this was built.
    fn record(&self, leaf: ElementId) -> Option<&LeafVertices> {
        let slot = self
            .leaf_slot
            .get(leaf as usize)
            .copied()
            .filter(|&slot| slot != NOT_A_LEAF)?;
        Some(&self.leaves[slot as usize])
    }

    /// Interpolation at point `p` (parameters `uv`) of leaf `leaf` of the values `value` gives its
    /// vertices (by welded vertex id): barycentric on a triangle, bilinear on a quad, or barycentric in the fan triangle
    /// containing `p` when the leaf has T-vertices. `None` for an element that was not a leaf when
    /// this was built.
    fn interpolate(
        &self,
        hierarchy: &Hierarchy,
        leaf: ElementId,
        p: DVec3,
        uv: DVec2,
        value: impl Fn(u32) -> Rgb,
    ) -> Option<Rgb> {
        let element = hierarchy.element(leaf);
        let record = self.record(leaf)?;
        let shape = element.shape();
        let c = |k: usize| value(record.corners[k]);
        Some(match &record.boundary {
            None => match shape {
                Shape::Triangle(_) => c(0) * (1.0 - uv.x - uv.y) + c(1) * uv.x + c(2) * uv.y,
                Shape::Quad(_) => {
                    let uv = uv.clamp(DVec2::ZERO, DVec2::ONE);
                    bilinear([c(0), c(1), c(2), c(3)], uv)
                }
            },
            Some(boundary) => {
                let normal = hierarchy.patch_of(leaf).normal;
                let centre = fan_centre(shape);
                let mut best = (f64::NEG_INFINITY, 0, [0.0; 3]);
                for i in 0..boundary.len() {
                    let (a, b) = (boundary[i], boundary[(i + 1) % boundary.len()]);
                    let w = barycentric(
                        centre,
                        self.positions[a as usize],
                        self.positions[b as usize],
                        p,
                        normal,
                    );
                    let margin = w[0].min(w[1]).min(w[2]);
                    if margin > best.0 {
                        best = (margin, i, w);
                    }
                }
                let (_, i, w) = best;
                let (a, b) = (boundary[i], boundary[(i + 1) % boundary.len()]);
                let corners = &record.corners[..shape.vertex_count()];
                corner_average(corners, &value) * w[0] + value(a) * w[1] + value(b) * w[2]
            }
        })
    }

    /// The leaves as a triangle mesh: triangles as they are, quads split along the diagonal (0, 2), and
    /// leaves with T-vertices fanned from an extra centre vertex, exactly as [`Self::evaluate`] does.
    pub fn mesh(&self, hierarchy: &Hierarchy) -> ShadedMesh {
        let mut mesh = ShadedMesh {
            positions: self.positions.clone(),
            normals: self
                .vertex_group
                .iter()
                .map(|&g| hierarchy.patches[g as usize].normal)
                .collect(),
            radiance: self.values.clone(),
            triangles: Vec::new(),
        };
        for record in &self.leaves {
            let shape = hierarchy.element(record.element).shape();
            let c = record.corners;
            match (&record.boundary, shape) {
                (None, Shape::Triangle(_)) => mesh.triangles.push([c[0], c[1], c[2]]),
                (None, Shape::Quad(_)) => {
                    mesh.triangles.push([c[0], c[1], c[2]]);
                    mesh.triangles.push([c[0], c[2], c[3]]);
                }
                (Some(boundary), _) => {
                    let n = shape.vertex_count();
                    let centre = fan_centre(shape);
                    let value = corner_average(&c[..n], |v| self.values[v as usize]);
                    let centre_id = mesh.positions.len() as u32;
                    mesh.positions.push(centre);
                    let group = self.vertex_group[c[0] as usize];
                    mesh.normals.push(hierarchy.patches[group as usize].normal);
                    mesh.radiance.push(value);
                    for i in 0..boundary.len() {
                        let next = boundary[(i + 1) % boundary.len()];
                        mesh.triangles.push([centre_id, boundary[i], next]);
                    }
                }
            }
        }
        mesh
    }
}

/// The average of `value` over a leaf's corners: its interpolation at the [`fan_centre`].
fn corner_average(corners: &[u32], value: impl Fn(u32) -> Rgb) -> Rgb {
    corners.iter().map(|&v| value(v)).sum::<Rgb>() / corners.len() as f64
}

/// Centre of a fanned leaf, where the interpolation of its corners is their average (barycentric at a
/// triangle's centroid, bilinear at a quad's (1/2, 1/2)).
fn fan_centre(shape: &Shape) -> DVec3 {
    match shape {
        Shape::Triangle(v) => (v[0] + v[1] + v[2]) / 3.0,
        Shape::Quad(_) => shape.point_at(DVec2::splat(0.5)),
    }
}

/// What the leaves through a vertex give it, summed: area-weighted values and the range of their
/// luminances.
#[derive(Clone, Copy, Debug)]
struct VertexSum {
    value: Rgb,
    area: f64,
    low: f32,
    high: f32,
}

impl Default for VertexSum {
    fn default() -> Self {
        VertexSum {
            value: Rgb::BLACK,
            area: 0.0,
            low: f32::INFINITY,
            high: f32::NEG_INFINITY,
        }
    }
}

impl VertexSum {
    fn add(&mut self, value: Rgb, area: f64) {
        self.value += value * area;
        self.area += area;
        let luminance = value.luminance() as f32;
        self.low = self.low.min(luminance);
        self.high = self.high.max(luminance);
    }

    fn average(&self) -> Rgb {
        if self.area > 0.0 {
            self.value / self.area
        } else {
            Rgb::BLACK
        }
    }

    fn shared(&self) -> SharedValue {
        SharedValue {
            value: self.average(),
            low: self.low,
            high: self.high,
        }
    }
}

/// A vertex's value for continuous shading: the area-weighted average of the leaves through it and
/// the range of their luminances (which tells a leaf how far it is from the farthest of them).
#[derive(Clone, Copy, Debug)]
struct SharedValue {
    value: Rgb,
    low: f32,
    high: f32,
}

/// A quad's 2 × 2 Gauss–Legendre nodes in its parameters with their area weights (the Jacobian
/// there, normalised to sum to 1): the exact area mean of a function of degree at most 3 in each
/// parameter over a planar quad, whose Jacobian is linear in each. Unused (empty) on a triangle.
type AreaNodes = SmallVec<[(DVec2, f64); 4]>;

/// [`AreaNodes`] of `shape`: [`gauss_nodes`]' 2 × 2 rule, its weights normalised.
fn area_nodes(shape: &Shape) -> AreaNodes {
    let mut nodes = AreaNodes::new();
    if let Shape::Quad(_) = shape {
        nodes.extend(gauss_nodes(shape, 2).iter().map(|n| (n.uv, n.weight)));
        let total: f64 = nodes.iter().map(|&(_, w)| w).sum();
        for (_, w) in &mut nodes {
            *w /= total.max(f64::MIN_POSITIVE);
        }
    }
    nodes
}

/// A bubble over the shape's parameter domain, zero on its boundary and of mean 1 over its area
/// (`60 λ₀λ₁λ₂` on a triangle; `u(1 − u) v(1 − v)` over its area mean `mean` on a quad:
/// [`bubble_mean`]): adding a multiple of it to a field continuous across a leaf's edges keeps it
/// continuous and moves its mean over the leaf by that multiple.
fn unit_bubble(shape: &Shape, mean: f64, uv: DVec2) -> f64 {
    match shape {
        Shape::Triangle(_) => {
            let (u, v) = (uv.x.max(0.0), uv.y.max(0.0));
            60.0 * (1.0 - u - v).max(0.0) * u * v
        }
        Shape::Quad(_) => quad_bubble(uv.clamp(DVec2::ZERO, DVec2::ONE)) / mean,
    }
}

/// `u(1 − u) v(1 − v)`: zero on the unit square's edges.
fn quad_bubble(uv: DVec2) -> f64 {
    uv.x * (1.0 - uv.x) * uv.y * (1.0 - uv.y)
}

/// The area mean of [`quad_bubble`] over a quad from its [`area_nodes`] (exact: the bubble is
/// biquadratic and the Jacobian bilinear); 1 for a triangle, whose bubble is normalised as it is.
fn bubble_mean(shape: &Shape, nodes: &AreaNodes) -> f64 {
    match shape {
        Shape::Triangle(_) => 1.0,
        Shape::Quad(_) => {
            let mean: f64 = nodes.iter().map(|&(uv, w)| quad_bubble(uv) * w).sum();
            mean.max(f64::MIN_POSITIVE)
        }
    }
}

fn bilinear(c: [Rgb; 4], uv: DVec2) -> Rgb {
    let (u, v) = (uv.x, uv.y);
    c[0] * ((1.0 - u) * (1.0 - v))
        + c[1] * (u * (1.0 - v))
        + c[2] * (u * v)
        + c[3] * ((1.0 - u) * v)
}

/// Barycentric weights of `p` in triangle (a, b, c), measured in the plane with normal `n`.
fn barycentric(a: DVec3, b: DVec3, c: DVec3, p: DVec3, n: DVec3) -> [f64; 3] {
    let area = (b - a).cross(c - a).dot(n);
    if area.abs() < 1e-300 {
        return [f64::NEG_INFINITY, 0.0, 0.0];
    }
    let wa = (b - p).cross(c - p).dot(n) / area;
    let wb = (c - p).cross(a - p).dot(n) / area;
    [wa, wb, 1.0 - wa - wb]
}

/// Same smoothing group: same material (reflectance and emission) and the same facing direction. Patches
/// meeting at a point with the same normal lie in the same plane.
fn compatible(hierarchy: &Hierarchy, p: u32, q: u32) -> bool {
    let (a, b) = (
        &hierarchy.patches[p as usize],
        &hierarchy.patches[q as usize],
    );
    a.reflectance == b.reflectance
        && a.emission == b.emission
        && a.normal.dot(b.normal) >= SAME_NORMAL_COS
}

/// Sets each T-vertex to the interpolation along its anchoring edge, end points first (an explicit-stack
/// depth-first walk; a cycle, which planar meshes do not produce, falls back to the current value).
fn resolve_anchors(anchor_of: &FastMap<u32, Anchor>, values: &mut [Rgb]) {
    #[derive(Clone, Copy, PartialEq)]
    enum State {
        Todo,
        Visiting,
        Done,
    }
    // The T-vertices in vertex order (deterministic), each with its walk state.
    let mut anchored: Vec<(u32, Anchor)> = anchor_of.iter().map(|(&v, &a)| (v, a)).collect();
    anchored.sort_unstable_by_key(|&(v, _)| v);
    let slot = |v: u32| anchored.binary_search_by_key(&v, |&(w, _)| w).ok();
    let mut state = vec![State::Todo; anchored.len()];
    let mut stack = Vec::new();
    for start in 0..anchored.len() {
        if state[start] == State::Done {
            continue;
        }
        stack.push(start);
        while let Some(&i) = stack.last() {
            if state[i] == State::Done {
                stack.pop();
                continue;
            }
            state[i] = State::Visiting;
            let (v, anchor) = anchored[i];
            let pending: Vec<usize> = [anchor.a, anchor.b]
                .into_iter()
                .filter_map(slot)
                .filter(|&e| state[e] == State::Todo)
                .collect();
            if pending.is_empty() {
                values[v as usize] = values[anchor.a as usize] * (1.0 - anchor.s)
                    + values[anchor.b as usize] * anchor.s;
                state[i] = State::Done;
                stack.pop();
            } else {
                stack.extend(pending);
            }
        }
    }
}

/// Read-only access to the welded vertices for the T-vertex search.
struct VertexLookup<'a> {
    welder: &'a Welder,
    vertex_of: &'a FastMap<(u32, u32), u32>,
    positions: &'a [DVec3],
    tolerance: f64,
}

impl VertexLookup<'_> {
    /// Appends, in order from `a` to `b`, the vertices of `group` at dyadic points strictly inside the
    /// leaf edge (a, b), each with its anchor on that edge.
    fn edge_vertices(&self, group: u32, a: u32, b: u32, out: &mut Vec<(u32, Anchor)>) {
        let edge = Anchor {
            a,
            b,
            s: 0.0,
            edge_length: self.positions[a as usize].distance(self.positions[b as usize]),
        };
        self.split(group, &edge, (a, b), (0.0, 1.0), 0, out);
    }

    /// Recursion of [`Self::edge_vertices`] on the part (from, to) spanning parameters `range` of `edge`.
    fn split(
        &self,
        group: u32,
        edge: &Anchor,
        (from, to): (u32, u32),
        range: (f64, f64),
        depth: u32,
        out: &mut Vec<(u32, Anchor)>,
    ) {
        let (pa, pb) = (self.positions[from as usize], self.positions[to as usize]);
        if depth >= MAX_EDGE_DEPTH || pa.distance(pb) < 4.0 * self.tolerance {
            return;
        }
        let Some(m) = self
            .welder
            .find((pa + pb) * 0.5, 2.0 * self.tolerance)
            .and_then(|point| self.vertex_of.get(&(point, group)).copied())
        else {
            return;
        };
        if m == from || m == to {
            return;
        }
        let s = 0.5 * (range.0 + range.1);
        self.split(group, edge, (from, m), (range.0, s), depth + 1, out);
        out.push((m, Anchor { s, ..*edge }));
        self.split(group, edge, (m, to), (s, range.1), depth + 1, out);
    }
}

/// Whether `p` lies on edge `k` of `shape` (within `tolerance`).
fn on_edge(shape: &Shape, k: usize, p: DVec3, tolerance: f64) -> bool {
    let v = shape.vertices();
    let (a, b) = (v[k], v[(k + 1) % v.len()]);
    let d = b - a;
    let t = ((p - a).dot(d) / d.length_squared().max(1e-300)).clamp(0.0, 1.0);
    p.distance(a + d * t) <= tolerance
}

/// Whether `p` lies on the outline of `shape`.
fn on_outline(shape: &Shape, p: DVec3, tolerance: f64) -> bool {
    (0..shape.vertex_count()).any(|k| on_edge(shape, k, p, tolerance))
}

/// Whether the segment (pa, pb) runs along one edge of `shape` (a corner lies on two edges).
fn along_outline(shape: &Shape, pa: DVec3, pb: DVec3, tolerance: f64) -> bool {
    (0..shape.vertex_count())
        .any(|k| on_edge(shape, k, pa, tolerance) && on_edge(shape, k, pb, tolerance))
}

/// The welded vertices that lie on the outline of their patch, on a uniform grid: the candidates for
/// T-vertices inside a neighbouring patch's edge (see [`VertexRadiosity::new`]).
struct OutlineVertices<'a> {
    positions: &'a [DVec3],
    vertex_group: &'a [u32],
    tolerance: f64,
    cell: f64,
    grid: FastMap<[i64; 3], Ids>,
}

impl<'a> OutlineVertices<'a> {
    fn new(
        hierarchy: &Hierarchy,
        records: &[LeafVertices],
        positions: &'a [DVec3],
        vertex_group: &'a [u32],
        tolerance: f64,
    ) -> Self {
        let mut ids: Vec<u32> = Vec::new();
        for record in records {
            let element = hierarchy.element(record.element);
            let root = hierarchy.patch_shape(element.patch());
            for &id in &record.corners[..element.shape().vertex_count()] {
                if on_outline(root, positions[id as usize], tolerance) {
                    ids.push(id);
                }
            }
        }
        ids.sort_unstable();
        ids.dedup();
        let bounds = ids.iter().fold(Aabb::EMPTY, |mut b, &id| {
            b.grow(positions[id as usize]);
            b
        });
        // About one vertex per cell along a surface.
        let cell =
            (bounds.diagonal() / (ids.len().max(1) as f64).sqrt()).max(CELL_SIZE * tolerance);
        let mut grid: FastMap<[i64; 3], Ids> = FastMap::default();
        for &id in &ids {
            grid.entry(cell_index(positions[id as usize], cell))
                .or_default()
                .push(id);
        }
        OutlineVertices {
            positions,
            vertex_group,
            tolerance,
            cell,
            grid,
        }
    }

    /// Vertices of `group` strictly inside the segment (pa, pb), other than its ends, with their
    /// parameter along it.
    fn inside(&self, pa: DVec3, pb: DVec3, group: u32, ends: (u32, u32)) -> Vec<(f64, u32)> {
        let d = pb - pa;
        let length = d.length();
        if self.grid.is_empty() || length <= 2.0 * self.tolerance {
            return Vec::new();
        }
        let steps = (2.0 * length / self.cell).ceil() as usize + 1;
        let mut cells: Vec<[i64; 3]> = Vec::new();
        for step in 0..=steps {
            let c = cell_index(pa + d * (step as f64 / steps as f64), self.cell);
            for dx in -1..=1 {
                for dy in -1..=1 {
                    for dz in -1..=1 {
                        cells.push([c[0] + dx, c[1] + dy, c[2] + dz]);
                    }
                }
            }
        }
        cells.sort_unstable();
        cells.dedup();
        let mut found = Vec::new();
        for cell in cells {
            for &v in self.grid.get(&cell).into_iter().flatten() {
                if v == ends.0 || v == ends.1 || self.vertex_group[v as usize] != group {
                    continue;
                }
                let p = self.positions[v as usize];
                let t = (p - pa).dot(d) / (length * length);
                let margin = self.tolerance / length;
                if t > margin && t < 1.0 - margin && p.distance(pa + d * t) <= self.tolerance {
                    found.push((t, v));
                }
            }
        }
        found
    }
}

fn cell_index(p: DVec3, cell: f64) -> [i64; 3] {
    let c = (p / cell).floor();
    [c.x as i64, c.y as i64, c.z as i64]
}

/// A short list of ids kept inline: most welded points meet one patch and most grid cells hold one
/// point, so a heap allocation each would cost more than the entries (the 100k hall: half a million).
type Ids = SmallVec<[u32; 2]>;

/// Welding grid cells are this many tolerances wide: a query usually touches a single cell.
const CELL_SIZE: f64 = 64.0;

/// Position welding on a hash grid; sequential, hence deterministic.
struct Welder {
    tolerance: f64,
    cell: f64,
    grid: FastMap<[i64; 3], Ids>,
    points: Vec<DVec3>,
}

impl Welder {
    fn new(tolerance: f64) -> Self {
        Welder {
            tolerance,
            cell: CELL_SIZE * tolerance,
            grid: FastMap::default(),
            points: Vec::new(),
        }
    }

    fn cell_of(&self, p: DVec3) -> [i64; 3] {
        cell_index(p, self.cell)
    }

    /// The lowest-numbered point within `radius` of `p`.
    fn find(&self, p: DVec3, radius: f64) -> Option<u32> {
        let lo = self.cell_of(p - DVec3::splat(radius));
        let hi = self.cell_of(p + DVec3::splat(radius));
        let mut best: Option<u32> = None;
        for x in lo[0]..=hi[0] {
            for y in lo[1]..=hi[1] {
                for z in lo[2]..=hi[2] {
                    let Some(ids) = self.grid.get(&[x, y, z]) else {
                        continue;
                    };
                    for &id in ids {
                        if self.points[id as usize].distance(p) <= radius
                            && best.is_none_or(|b| id < b)
                        {
                            best = Some(id);
                        }
                    }
                }
            }
        }
        best
    }

    fn insert(&mut self, p: DVec3) -> u32 {
        if let Some(id) = self.find(p, self.tolerance) {
            return id;
        }
        let id = self.points.len() as u32;
        self.points.push(p);
        let cell = self.cell_of(p);
        self.grid.entry(cell).or_default().push(id);
        id
    }
}

/// Keys here are small integers: a multiply-rotate hash (the Fx hash of rustc) is much faster than SipHash
/// and needs no protection against adversarial keys.
type FastMap<K, V> = HashMap<K, V, BuildHasherDefault<FxHasher>>;

#[derive(Default)]
struct FxHasher {
    hash: u64,
}

impl Hasher for FxHasher {
    fn write(&mut self, bytes: &[u8]) {
        for chunk in bytes.chunks(8) {
            let mut word = [0u8; 8];
            word[..chunk.len()].copy_from_slice(chunk);
            self.write_u64(u64::from_le_bytes(word));
        }
    }

    fn write_u64(&mut self, i: u64) {
        self.hash = (self.hash.rotate_left(5) ^ i).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
    }

    fn write_u32(&mut self, i: u32) {
        self.write_u64(u64::from(i));
    }

    fn write_usize(&mut self, i: usize) {
        self.write_u64(i as u64);
    }

    fn finish(&self) -> u64 {
        self.hash
    }
}

/// Disjoint sets of patches with path halving; the representative is the smallest index, so group ids do
/// not depend on union order.
struct UnionFind {
    parent: Vec<u32>,
}

impl UnionFind {
    fn new(n: usize) -> Self {
        UnionFind {
            parent: (0..n as u32).collect(),
        }
    }

    fn find(&mut self, mut x: u32) -> u32 {
        while self.parent[x as usize] != x {
            let grand = self.parent[self.parent[x as usize] as usize];
            self.parent[x as usize] = grand;
            x = grand;
        }
        x
    }

    fn union(&mut self, a: u32, b: u32) {
        let (ra, rb) = (self.find(a), self.find(b));
        let (lo, hi) = (ra.min(rb), ra.max(rb));
        self.parent[hi as usize] = lo;
    }
}
