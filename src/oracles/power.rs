//! The power-based oracle of Hanrahan et al., Feixas et al. eq. (1): `ρ_i A_i F̃_ij B_j < ε`, with the
//! cheap unoccluded point-to-polygon form factor estimate F̃ the paper uses (§4: no rays).
//!
//! F̃_ij is the exact point-to-polygon form factor from the receiver's centre to the source. As in
//! Hanrahan et al. the transported power A_i F_ij is estimated from both ends (A_i F̃_ij and A_j F̃_ji,
//! equal by reciprocity for exact form factors) and the larger is kept: a centre-only estimate is zero
//! when that centre lies behind the other element's plane although part of the element does not.
//! Taking the largest value over the element's vertices as well was tried: it costs five times more and
//! does not cure the known weakness of eq. (1) (coarse links whose power is pushed evenly over a receiver
//! across which the kernel varies strongly: corner elements of a closed furnace box stay 10-20% off; see
//! BENCHMARKS.md), which is what the smoothness and MI oracles address.

use super::{reflected_source_radiance, Estimate, OracleContext, RefinementOracle};
use crate::geometry::form_factor::point_to_polygon;
use crate::hierarchy::ElementId;
use rand_pcg::Pcg64Mcg;

/// Feixas et al. eq. (1).
#[derive(Clone, Copy, Debug, Default)]
pub struct PowerOracle;

impl RefinementOracle for PowerOracle {
    fn name(&self) -> &'static str {
        "power"
    }

    fn estimate(
        &self,
        context: &OracleContext,
        receiver: ElementId,
        source: ElementId,
        _: &mut Pcg64Mcg,
    ) -> Estimate {
        let h = context.hierarchy;
        let (r, s) = (h.element(receiver), h.element(source));
        let f_ij = point_to_polygon(r.shape().centroid(), h.patch_of(receiver).normal, s.shape());
        let f_ji = point_to_polygon(s.shape().centroid(), h.patch_of(source).normal, r.shape());
        let transport = (r.area * f_ij).max(s.area * f_ji);
        Estimate {
            error: reflected_source_radiance(h, receiver, source) * transport,
            rays: 0,
        }
    }
}
