//! Gathering iterations over the links of a refined hierarchy, followed by push-pull: Jacobi (all
//! elements gather from the previous iterate, in parallel) and Gauss–Seidel (patches in order, each seeing
//! the radiance already updated by the patches before it; sequential but converging about twice as fast).

use super::push_pull::{push_pull, PatchUpdate};
use crate::color::Rgb;
use crate::hierarchy::{ElementId, Hierarchy};
use rayon::prelude::*;

/// Power totals after one sweep.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Sweep {
    /// Σ π A B over leaves (W per channel).
    pub exitant: Rgb,
    /// Σ π A (1 - ρ) H over leaves (W per channel).
    pub absorbed: Rgb,
}

/// One iterative method for the linear system `B = E + ρ Σ F B` on the current links.
pub trait GatheringSolver: Sync + Send {
    fn name(&self) -> &'static str;
    /// Performs one sweep, updating `radiance[0]` of every element.
    fn sweep(&self, hierarchy: &mut Hierarchy) -> Sweep;
}

/// Incident radiance gathered over the links stored at `id`: Σ F_ij B_j.
pub fn gather(hierarchy: &Hierarchy, id: ElementId) -> Rgb {
    hierarchy
        .element(id)
        .links
        .iter()
        .map(|l| hierarchy.element(l.source).average_radiance() * l.form_factor)
        .sum()
}

fn apply(hierarchy: &mut Hierarchy, update: &PatchUpdate, totals: &mut Sweep) {
    for &(id, b) in &update.radiance {
        hierarchy.elements[id as usize].radiance[0] = b;
    }
    totals.exitant += update.exitant;
    totals.absorbed += update.absorbed;
}

/// Jacobi iteration: gather everywhere from the previous iterate, then push-pull every patch.
#[derive(Clone, Copy, Debug, Default)]
pub struct Jacobi;

impl GatheringSolver for Jacobi {
    fn name(&self) -> &'static str {
        "jacobi"
    }

    fn sweep(&self, hierarchy: &mut Hierarchy) -> Sweep {
        let h = &*hierarchy;
        let gathered: Vec<Rgb> = (0..h.elements.len() as ElementId)
            .into_par_iter()
            .map(|id| gather(h, id))
            .collect();
        let updates: Vec<PatchUpdate> = (0..h.patches.len() as u32)
            .into_par_iter()
            .map(|p| push_pull(h, p, &|id| gathered[id as usize]))
            .collect();
        let mut totals = Sweep::default();
        for update in &updates {
            apply(hierarchy, update, &mut totals);
        }
        totals
    }
}

/// Gauss–Seidel iteration over patches.
#[derive(Clone, Copy, Debug, Default)]
pub struct GaussSeidel;

impl GatheringSolver for GaussSeidel {
    fn name(&self) -> &'static str {
        "gauss-seidel"
    }

    fn sweep(&self, hierarchy: &mut Hierarchy) -> Sweep {
        let mut totals = Sweep::default();
        for p in 0..hierarchy.patches.len() as u32 {
            let update = {
                let h = &*hierarchy;
                push_pull(h, p, &|id| gather(h, id))
            };
            apply(hierarchy, &update, &mut totals);
        }
        totals
    }
}
