//! Refinement oracles: for a candidate link (source element j → receiver element i) estimate the error of
//! representing the interaction by that single link, and decide whether it is admissible or which of the
//! two elements to subdivide. One implementation per criterion, chosen with `--oracle`:
//! [`power::PowerOracle`] (Feixas et al. eq. (1)); the kernel-smoothness (eq. 2), mutual-information
//! (eq. 15) and Bekaert–Willems link-error oracles implement the same trait.

pub mod power;

use crate::hierarchy::{ElementId, Hierarchy};
use crate::visibility::Visibility;
use rand_pcg::Pcg64Mcg;

/// What to do with a candidate link.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Decision {
    /// Keep the link at this level.
    Admissible,
    /// Split the receiver and link its children to the source.
    SubdivideReceiver,
    /// Split the source and link the receiver to its children.
    SubdivideSource,
}

/// Everything an oracle may look at.
pub struct OracleContext<'a> {
    pub hierarchy: &'a Hierarchy,
    pub visibility: &'a dyn Visibility,
}

/// An oracle's error estimate for one candidate link.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Estimate {
    /// Error estimate in units of radiance × area (power / π), compared with the refinement threshold.
    pub error: f64,
    /// Visibility rays the estimate cast (the oracle's share of the ray count).
    pub rays: u64,
}

/// A refinement criterion.
pub trait RefinementOracle: Sync + Send {
    /// Name used on the command line and in reports.
    fn name(&self) -> &'static str;

    /// Error estimate for the link `source` → `receiver`; `rng` is seeded from the link's identity, so the
    /// estimate does not depend on thread scheduling.
    fn estimate(
        &self,
        context: &OracleContext,
        receiver: ElementId,
        source: ElementId,
        rng: &mut Pcg64Mcg,
    ) -> Estimate;

    /// Which element to split when the estimate exceeds the threshold. The classic rule (Hanrahan et al.,
    /// used with eqs. (1), (2) and (15)) splits the larger of the two elements.
    fn element_to_split(
        &self,
        context: &OracleContext,
        receiver: ElementId,
        source: ElementId,
    ) -> Decision {
        let h = context.hierarchy;
        if h.element(receiver).area >= h.element(source).area {
            Decision::SubdivideReceiver
        } else {
            Decision::SubdivideSource
        }
    }
}

/// Largest per-channel product ρ_i B_j: the receiver-weighted source radiance that oracles scale by.
pub fn reflected_source_radiance(
    hierarchy: &Hierarchy,
    receiver: ElementId,
    source: ElementId,
) -> f64 {
    let rho = hierarchy.patch_of(receiver).reflectance;
    let b = hierarchy.element(source).average_radiance();
    (rho * b).max_channel()
}
