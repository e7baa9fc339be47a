//! The element hierarchy of hierarchical radiosity (Hanrahan, Salzman, Aupperle 1991): every radiating
//! side of an input polygon is a *patch* whose root element is regularly split into a quadtree (4 children,
//! quads at parameter midpoints, triangles at edge midpoints). Links between elements live at the
//! receiving element and carry the form factor of the interaction.
//!
//! An element carries a vector of basis coefficients (`radiance`, constant basis first: see
//! [`crate::bases`]). Clusters (Sillion–Drettakis §4) will be elements too: an element without a patch
//! whose children are other elements.

use crate::color::Rgb;
use crate::geometry::{DVec3, Shape};
use crate::scene::Scene;

/// Index of an element in [`Hierarchy::elements`].
pub type ElementId = u32;

/// One radiating side of an input polygon.
#[derive(Clone, Debug)]
pub struct Patch {
    /// Index of the polygon in `Scene::polygons`.
    pub polygon: usize,
    /// Front side (true) or back side of a two-sided polygon.
    pub front: bool,
    /// The polygon's shape oriented so that its normal points out of this side.
    pub shape: Shape,
    pub normal: DVec3,
    pub reflectance: Rgb,
    pub emission: Rgb,
    pub root: ElementId,
}

/// An interaction from `source` to the element holding the link (the receiver).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Link {
    pub source: ElementId,
    /// Receiver-area-averaged form factor F_ij from the receiver i to the source j, visibility included.
    pub form_factor: f64,
    /// The refinement oracle's radiance-independent factor for this link (its error estimate divided by
    /// ρ_i B_j), kept so that re-refinement after a solve needs no new kernel samples; `None` when the
    /// source was dark when the link was judged.
    pub oracle_factor: Option<f64>,
}

/// A node of a patch's quadtree.
#[derive(Clone, Debug)]
pub struct Element {
    pub patch: u32,
    pub parent: Option<ElementId>,
    pub children: Option<[ElementId; 4]>,
    pub level: u16,
    pub shape: Shape,
    pub area: f64,
    /// Basis coefficients of the exitant radiance, RGB; index 0 is the constant (element average).
    pub radiance: Vec<Rgb>,
    /// Incoming links: the sources this element gathers from.
    pub links: Vec<Link>,
}

impl Element {
    pub fn is_leaf(&self) -> bool {
        self.children.is_none()
    }

    /// Average exitant radiance over the element (the constant coefficient).
    pub fn average_radiance(&self) -> Rgb {
        self.radiance[0]
    }
}

/// All patches and their element trees.
#[derive(Clone, Debug)]
pub struct Hierarchy {
    pub patches: Vec<Patch>,
    pub elements: Vec<Element>,
    /// Patch index of each polygon's front and back side (`None` for the back of a one-sided polygon).
    pub polygon_patches: Vec<[Option<u32>; 2]>,
    /// Number of basis coefficients per element.
    pub basis_size: usize,
}

impl Hierarchy {
    /// One patch per radiating side of each polygon, each with a root element whose radiance starts at the
    /// patch's emission.
    pub fn new(scene: &Scene, basis_size: usize) -> Self {
        let mut h = Hierarchy {
            patches: Vec::new(),
            elements: Vec::new(),
            polygon_patches: vec![[None, None]; scene.polygons.len()],
            basis_size: basis_size.max(1),
        };
        for (index, polygon) in scene.polygons.iter().enumerate() {
            let material = scene.material_of(polygon);
            let sides: &[bool] = if polygon.two_sided {
                &[true, false]
            } else {
                &[true]
            };
            for &front in sides {
                let shape = if front {
                    polygon.shape
                } else {
                    polygon.shape.flipped()
                };
                let patch = h.patches.len() as u32;
                let root = h.elements.len() as ElementId;
                let mut radiance = vec![Rgb::BLACK; h.basis_size];
                radiance[0] = material.emission;
                h.elements.push(Element {
                    patch,
                    parent: None,
                    children: None,
                    level: 0,
                    shape,
                    area: shape.area(),
                    radiance,
                    links: Vec::new(),
                });
                h.patches.push(Patch {
                    polygon: index,
                    front,
                    shape,
                    normal: shape.normal(),
                    reflectance: material.reflectance,
                    emission: material.emission,
                    root,
                });
                h.polygon_patches[index][usize::from(!front)] = Some(patch);
            }
        }
        h
    }

    pub fn element(&self, id: ElementId) -> &Element {
        &self.elements[id as usize]
    }

    pub fn patch_of(&self, id: ElementId) -> &Patch {
        &self.patches[self.elements[id as usize].patch as usize]
    }

    /// Splits a leaf into its four regular children (no-op returning the existing children otherwise).
    /// Children inherit the parent's radiance coefficients.
    pub fn subdivide(&mut self, id: ElementId) -> [ElementId; 4] {
        if let Some(children) = self.elements[id as usize].children {
            return children;
        }
        let parent = &self.elements[id as usize];
        let (patch, level, radiance) = (parent.patch, parent.level + 1, parent.radiance.clone());
        let shapes = parent.shape.subdivide();
        let first = self.elements.len() as ElementId;
        for shape in shapes {
            self.elements.push(Element {
                patch,
                parent: Some(id),
                children: None,
                level,
                shape,
                area: shape.area(),
                radiance: radiance.clone(),
                links: Vec::new(),
            });
        }
        let children = [first, first + 1, first + 2, first + 3];
        self.elements[id as usize].children = Some(children);
        children
    }

    /// Ids of all leaf elements, patch by patch in tree order.
    pub fn leaves(&self) -> Vec<ElementId> {
        let mut out = Vec::new();
        for patch in &self.patches {
            self.collect_leaves(patch.root, &mut out);
        }
        out
    }

    /// Leaves below (and including) `id`, in tree order.
    pub fn collect_leaves(&self, id: ElementId, out: &mut Vec<ElementId>) {
        let mut stack = vec![id];
        while let Some(e) = stack.pop() {
            match self.elements[e as usize].children {
                Some(c) => stack.extend(c.iter().rev()),
                None => out.push(e),
            }
        }
    }

    /// The patch seen by a ray hitting `polygon` on its front (`front = true`) or back side; `None` for the
    /// back of a one-sided polygon (an opaque black surface).
    pub fn patch_for_side(&self, polygon: usize, front: bool) -> Option<u32> {
        self.polygon_patches[polygon][usize::from(!front)]
    }

    /// The leaf element of `patch` containing the world point `p` (which lies on the patch).
    pub fn locate(&self, patch: u32, p: DVec3) -> ElementId {
        let mut id = self.patches[patch as usize].root;
        let normal = self.patches[patch as usize].normal;
        while let Some(children) = self.elements[id as usize].children {
            id = *children
                .iter()
                .max_by(|a, b| {
                    let da = inside_margin(&self.elements[**a as usize].shape, normal, p);
                    let db = inside_margin(&self.elements[**b as usize].shape, normal, p);
                    da.total_cmp(&db)
                })
                .expect("four children");
        }
        id
    }

    /// Sum of the patch areas: the total surface area A_T (a two-sided polygon counts twice).
    pub fn total_area(&self) -> f64 {
        self.patches.iter().map(|p| self.element(p.root).area).sum()
    }

    /// Σ A·max(E) over patches: the scale relative refinement thresholds are given in.
    pub fn total_emission(&self) -> f64 {
        self.patches
            .iter()
            .map(|p| p.emission.max_channel() * self.element(p.root).area)
            .sum()
    }

    pub fn link_count(&self) -> usize {
        self.elements.iter().map(|e| e.links.len()).sum()
    }

    pub fn leaf_count(&self) -> usize {
        self.elements.iter().filter(|e| e.is_leaf()).count()
    }
}

/// Signed distance of `p` inside the convex shape's boundary, measured in its plane (negative outside):
/// the child with the largest margin contains the point, robustly even on shared edges.
fn inside_margin(shape: &Shape, normal: DVec3, p: DVec3) -> f64 {
    let v = shape.vertices();
    (0..v.len())
        .map(|k| {
            let edge = v[(k + 1) % v.len()] - v[k];
            let inward = normal.cross(edge).normalize_or_zero();
            inward.dot(p - v[k])
        })
        .fold(f64::INFINITY, f64::min)
}
