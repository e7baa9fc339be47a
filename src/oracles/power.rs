//! The power-based oracle of Hanrahan et al., Feixas et al. eq. (1): `ρ_i A_i F̃_ij B_j < ε`, with the
//! cheap unoccluded point-to-polygon form factor estimate F̃ (no rays).
//!
//! F̃_ij is the largest exact point-to-polygon form factor from the receiver's centre and vertices to the
//! source, and, as in Hanrahan et al., the transported power A_i F_ij is estimated from both ends
//! (A_i F̃_ij and A_j F̃_ji, equal by reciprocity for exact form factors) keeping the larger. A centre-only
//! estimate misses the case that matters most: a large receiver whose corner touches a small source gets a
//! tiny centre value, the link is accepted, and the power it carries is spread evenly over the receiver
//! instead of landing at the corner (in a closed furnace box this leaves corner elements 20-30% too
//! bright however small ε is). Five evaluations per end instead of one keep the oracle ray-free.

use super::{reflected_source_radiance, Estimate, OracleContext, RefinementOracle};
use crate::geometry::form_factor::point_to_polygon;
use crate::geometry::{DVec3, Shape};
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
        let f_ij = largest_point_form_factor(&r.shape, h.patch_of(receiver).normal, &s.shape);
        let f_ji = largest_point_form_factor(&s.shape, h.patch_of(source).normal, &r.shape);
        let transport = (r.area * f_ij).max(s.area * f_ji);
        Estimate {
            error: reflected_source_radiance(h, receiver, source) * transport,
            rays: 0,
        }
    }
}

/// Largest unoccluded form factor from the centre and the vertices of `from` (normal `normal`) to `to`.
fn largest_point_form_factor(from: &Shape, normal: DVec3, to: &Shape) -> f64 {
    from.vertices()
        .iter()
        .chain(std::iter::once(&from.centroid()))
        .map(|x| point_to_polygon(*x, normal, to))
        .fold(0.0, f64::max)
}
