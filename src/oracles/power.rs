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
//!
//! Both centres miss the light of a source nearer to the receiver than the receiver is large when it
//! arrives in a strip along their outlines (a lamp a millimetre under a ceiling lights the ceiling in
//! a strip as wide as the gap: the centre estimate was 80× too small on office3, so the link was never
//! refined). With [`NearField::Adaptive`] such pairs ([`near_field::is_near`], where the factor varies
//! more than twofold over the receiver's corners and centre, [`near_field::varies_over`]) take
//! `A_i F_ij` from the adaptive receiver integral of the same exact point factor
//! ([`near_field::receiver_integral`]), still without rays. Once found, that light must not be spread
//! over the whole receiver either: a link whose power is below ε but sits in a band of its receiver
//! lights the rest of it. So the uneven spread of the factor over the receiver weighs like the
//! visibility's: `P · max(1, g s)`, with `s` the factor's L¹ deviation from its mean
//! ([`near_field::ReceiverIntegral::spread`]). It helps without curing: cube.mgf's ceiling 20 and 30 cm
//! from its lamp reads 31% and 56% too bright without the term, 12% and 36% with it (BENCHMARKS.md).

use super::{reflected_source_radiance, Estimate, OracleContext, RefinementOracle};
use crate::geometry::form_factor::point_to_polygon;
use crate::geometry::near_field::{self, NearField};
use crate::hierarchy::ElementId;
use rand_pcg::Pcg64Mcg;

/// Relative accuracy of the adaptive transport: an oracle estimate need not be closer than this (eq. (1)
/// compares it with ε, and the spread only has to tell an even factor from one held in a band).
const TRANSPORT_TOLERANCE: f64 = 0.1;

/// Feixas et al. eq. (1), with a visibility term for links that carry a shadow boundary.
///
/// Eq. (1) is blind to visibility: a link whose receiver a shadow boundary crosses is judged by the
/// power it carries, like an unoccluded one, and the shadow is averaged over elements sized for smooth
/// light. Where the link's sampled visibility is partial, the estimate becomes `P · max(1, g s)`,
/// with `s` the L¹ deviation of the visibility over the receiver from its average
/// (Sillion–Drettakis Appendix A, eq. (3); `2v(1 − v)` by eq. (5) across a hard shadow boundary;
/// `solvers::coupling::visibility_spread`): a partially visible link is refined (its receiver split)
/// until that error, `s P`, is below `ε / g`, while unoccluded and wholly blocked links stay at ε.
/// With `g = 2 · 4^N` a link with `s = ½` (a hard boundary through the receiver's middle) ends `N`
/// quadtree levels deeper than eq. (1) alone would leave it (each level quarters `P`).
#[derive(Clone, Copy, Debug, Default)]
pub struct PowerOracle {
    /// `g`; 2 or less leaves eq. (1) as it is.
    pub shadow_gain: f64,
    /// How the transport of near pairs is estimated.
    pub near_field: NearField,
}

impl PowerOracle {
    /// The oracle whose visibility term refines links with `v = ½` `levels` levels deeper (0: eq. (1)).
    pub fn for_shadow_levels(levels: f64) -> Self {
        PowerOracle {
            shadow_gain: if levels > 0.0 {
                2.0 * 4f64.powf(levels)
            } else {
                0.0
            },
            near_field: NearField::default(),
        }
    }
}

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
        let normal = h.patch_of(receiver).normal;
        let transport = if self.near_field == NearField::Adaptive
            && near_field::is_near(r.shape(), s.shape())
            && near_field::varies_over(r.shape(), normal, s.shape())
        {
            let near = near_field::receiver_integral(
                r.shape(),
                normal,
                s.shape(),
                near_field::SEARCH_DEGREE,
                TRANSPORT_TOLERANCE,
            );
            near.value * (self.shadow_gain * near.spread).max(1.0)
        } else {
            let f_ij = point_to_polygon(r.shape().centroid(), normal, s.shape());
            let f_ji = point_to_polygon(s.shape().centroid(), h.patch_of(source).normal, r.shape());
            (r.area * f_ij).max(s.area * f_ji)
        };
        Estimate {
            error: reflected_source_radiance(h, receiver, source) * transport,
            rays: 0,
        }
    }

    fn with_partial_visibility(&self, estimate: f64, spread: f64) -> Option<f64> {
        (self.shadow_gain > 0.0).then(|| estimate * (self.shadow_gain * spread).max(1.0))
    }
}
