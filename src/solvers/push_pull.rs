//! Push-pull (Hanrahan et al. 1991) for basis coefficients: irradiance gathered at any level of a patch's
//! tree is pushed down to the leaves through the basis's two-scale relation ([`crate::bases`]), where
//! `L = E + ρ H` coefficient by coefficient, and radiance is pulled up as the area-L2 projection of
//! the children's functions onto the parent's basis, so that links to interior elements see the
//! children's radiance. With the constant basis this is the classic average.
//!
//! The pull sums the children's area moments (`(A_k/A) P_kᵀ G_k c_k`, exact: the parent's functions
//! restricted to child k are `P_k` combinations of the child's) and solves with the parent's overlap
//! matrix `G` of eq. (4) ([`crate::bases::Overlap`]). `G` is the identity on triangles and
//! parallelograms, where this is the plain area-weighted pull; on a trapezoid it keeps constant
//! children constant (no false gradient) and the pulled function's power equal to the children's.

use crate::bases::MAX_BASIS_SIZE;
use crate::color::Rgb;
use crate::hierarchy::{ElementId, Hierarchy};
use std::f64::consts::PI;

/// Area average of the function with coefficients `c` on an element whose overlap matrix is
/// `overlap` ([`crate::bases::Basis::overlap`]): coefficient 0, or on a trapezoid
/// `Σ_α c_α (1/A) ∫ φ_α dA`.
fn area_mean(overlap: Option<&crate::bases::Overlap>, c: &[Rgb]) -> Rgb {
    overlap.map_or(c[0], |overlap| overlap.mean(c))
}

/// Power leaf `id` sends, `π A` times its radiance's area average: a leaf's term of
/// [`PatchUpdate::exitant`], from the coefficients the hierarchy holds.
pub fn leaf_exitant(h: &Hierarchy, id: ElementId) -> Rgb {
    let e = h.element(id);
    area_mean(h.basis.overlap(e.shape(), e.area).as_ref(), h.radiance(id)) * (PI * e.area)
}

/// New radiance of every element of one patch tree.
#[derive(Clone, Debug, Default)]
pub struct PatchUpdate {
    /// Elements of the tree, in the order of `radiance`.
    pub elements: Vec<ElementId>,
    /// Their new radiance coefficients, `basis size` per element.
    pub radiance: Vec<Rgb>,
    /// Power absorbed by the patch's leaves: Σ π A (1 - ρ) H, per channel.
    pub absorbed: Rgb,
    /// Exitant power of the leaves: Σ π A B, per channel.
    pub exitant: Rgb,
}

impl PatchUpdate {
    /// (element, coefficients) pairs.
    pub fn entries(&self) -> impl Iterator<Item = (ElementId, &[Rgb])> {
        let size = self.radiance.len() / self.elements.len().max(1);
        self.elements
            .iter()
            .copied()
            .zip(self.radiance.chunks_exact(size.max(1)))
    }

    /// Writes the new coefficients into the hierarchy.
    pub fn apply(&self, hierarchy: &mut Hierarchy) {
        for (id, coefficients) in self.entries() {
            hierarchy.radiance_mut(id).copy_from_slice(coefficients);
        }
    }
}

/// Pushes `gathered` (which adds the irradiance coefficients gathered over an element's own links into
/// its second argument) down the tree of `patch` and pulls the resulting radiance up.
pub fn push_pull(
    hierarchy: &Hierarchy,
    patch: u32,
    gathered: &dyn Fn(ElementId, &mut [Rgb]),
) -> PatchUpdate {
    let p = &hierarchy.patches[patch as usize];
    let mut update = PatchUpdate::default();
    let mut walk = Walk {
        h: hierarchy,
        size: hierarchy.basis_size(),
        emission: p.emission,
        reflectance: p.reflectance,
        gathered,
        update: &mut update,
    };
    walk.visit(p.root, [Rgb::BLACK; MAX_BASIS_SIZE]);
    update
}

/// One element's coefficients (the first `size` of them), on the stack: push-pull visits every element
/// of every patch in every sweep.
type Coefficients = [Rgb; MAX_BASIS_SIZE];

struct Walk<'a> {
    h: &'a Hierarchy,
    size: usize,
    emission: Rgb,
    reflectance: Rgb,
    gathered: &'a dyn Fn(ElementId, &mut [Rgb]),
    update: &'a mut PatchUpdate,
}

impl Walk<'_> {
    /// `incident` arrives holding the irradiance pushed down from the ancestors; returns the radiance
    /// and, where the element's overlap matrix is not the identity, its area moments `G c`, which its
    /// parent's pull needs instead of the coefficients (the overlap is computed once per element and
    /// sweep: on a trapezoid a small Cholesky factorisation, and a cubature where it is warped).
    fn visit(
        &mut self,
        id: ElementId,
        mut incident: Coefficients,
    ) -> (Coefficients, Option<Coefficients>) {
        let (h, n) = (self.h, self.size);
        let e = h.element(id);
        (self.gathered)(id, &mut incident[..n]);
        let overlap = h.basis.overlap(e.shape(), e.area);
        let mut radiance = [Rgb::BLACK; MAX_BASIS_SIZE];
        if e.is_leaf() {
            // The luminaires' first gather, a fixed part of the leaf's irradiance.
            for (h, &d) in incident.iter_mut().zip(h.direct_at(id)) {
                *h += d;
            }
            for (b, &x) in radiance[..n].iter_mut().zip(&incident[..n]) {
                *b = self.reflectance * x;
            }
            // Emission is constant over a patch: the constant function represents it exactly (δ_e = 0).
            radiance[0] += self.emission;
            // Area averages: coefficient 0, or on a trapezoid Σ_α c_α (1/A) ∫ φ_α dA.
            let (mean_incident, mean_exitant) = (
                area_mean(overlap.as_ref(), &incident[..n]),
                area_mean(overlap.as_ref(), &radiance[..n]),
            );
            self.update.absorbed += (Rgb::WHITE - self.reflectance) * mean_incident * (PI * e.area);
            self.update.exitant += mean_exitant * (PI * e.area);
        } else {
            let domain = e.shape().domain();
            for (k, &child) in e.children.iter().enumerate() {
                let mut down = [Rgb::BLACK; MAX_BASIS_SIZE];
                h.basis.push_rgb(domain, k, &incident[..n], &mut down[..n]);
                let (child_radiance, child_moments) = self.visit(child, down);
                let c = h.element(child);
                let moments = child_moments.as_ref().unwrap_or(&child_radiance);
                h.basis.pull_add_rgb(
                    domain,
                    k,
                    c.area / e.area,
                    &moments[..n],
                    &mut radiance[..n],
                );
            }
            if let Some(overlap) = &overlap {
                overlap.solve_rgb(&mut radiance[..n]);
            }
        }
        self.update.elements.push(id);
        self.update.radiance.extend_from_slice(&radiance[..n]);
        let moments = overlap.map(|overlap| {
            let mut moments = [Rgb::BLACK; MAX_BASIS_SIZE];
            overlap.moments_rgb(&radiance[..n], &mut moments[..n]);
            moments
        });
        (radiance, moments)
    }
}
