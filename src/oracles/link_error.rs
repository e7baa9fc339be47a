//! The link error oracle of Bekaert–Willems §5, eq. (13):
//! `Δ_ij = max_{x ∈ A_i} |δ_j(x) + ∫_{A_j} K(x, y) ε(y) dA_y|`, evaluated at the receiver's cubature nodes
//! from the link's coupling (Algorithm 4.1): `δ_j(x_k) = ρ_i Σ_β L_{j,β} δ_{j,β}(x_k)` and the propagated
//! part `ρ_i ε̃_j K_{j,1}(x_k)`, with `ε(y)` replaced by the source's current realistic estimate
//! `ε̃_j` (§5; its sign unknown, so the two parts add in magnitude). The receiver is split where the
//! receiver's own approximation error `max |δ_j|` dominates, the source where the propagated error does.
//! A third term is the visibility error of the link (`LinkCoupling::visibility_error`, the term §7
//! proposes to add for partial occlusion): where it dominates, the source is split, since that term
//! scales with the source's form factor and splitting the receiver leaves it as it is (the receiver's
//! own term then resolves the shadow's shape on it). A partially occluded link whose source is larger
//! than its receiver splits the source too: the visibility seen from each receiver node is then sampled
//! by only a few source nodes, and the steps this puts into `δ_j` are not removed by a finer receiver.
//! Works with every basis; its estimate is a radiance, compared with each receiver's link error
//! threshold `Δ_i` of algorithm 6.1.

use super::{Decision, Estimate, LinkJudgement, OracleContext, RefinementOracle};
use crate::hierarchy::{ElementId, LinkCoupling};
use crate::solvers::coupling::{couple, CouplingSettings};
use rand_pcg::Pcg64Mcg;

/// Bekaert–Willems eq. (13).
#[derive(Clone, Copy, Debug)]
pub struct LinkErrorOracle {
    /// How couplings are computed when [`RefinementOracle::estimate`] is asked for one.
    pub coupling: CouplingSettings,
}

impl RefinementOracle for LinkErrorOracle {
    fn name(&self) -> &'static str {
        "error"
    }

    /// Δ_ij times the receiver's area (the units of the other oracles), from a freshly computed coupling.
    fn estimate(
        &self,
        context: &OracleContext,
        receiver: ElementId,
        source: ElementId,
        _: &mut Pcg64Mcg,
    ) -> Estimate {
        let k = couple(
            context.hierarchy,
            context.visibility,
            receiver,
            source,
            &self.coupling,
            None,
        );
        let judgement = self
            .link_error(context, receiver, source, &k.coupling)
            .unwrap_or_default();
        Estimate {
            error: judgement.error * context.hierarchy.element(receiver).area,
            rays: k.rays,
        }
    }

    fn judges_couplings(&self) -> bool {
        true
    }

    fn link_error(
        &self,
        context: &OracleContext,
        receiver: ElementId,
        source: ElementId,
        coupling: &LinkCoupling,
    ) -> Option<LinkJudgement> {
        let h = context.hierarchy;
        let rho = h.patch_of(receiver).reflectance;
        let source_element = h.element(source);
        let radiance = h.radiance(source);
        let propagated_error = source_element.error;
        let (mut own, mut propagated, mut total) = (0.0f64, 0.0f64, 0.0f64);
        for (k, factor) in coupling.node_factors().enumerate() {
            let delta = coupling.node_error(k, radiance);
            for (rho_c, delta_c) in [(rho.r, delta.r), (rho.g, delta.g), (rho.b, delta.b)] {
                let d = rho_c * delta_c.abs();
                let p = rho_c * propagated_error * factor as f64;
                own = own.max(d);
                propagated = propagated.max(p);
                total = total.max(d + p);
            }
        }
        let visibility = rho.max_channel()
            * h.average_radiance(source).max_channel().abs()
            * f64::from(coupling.visibility_error());
        let (r_area, s_area) = (h.element(receiver).area, source_element.area);
        let partially_visible = coupling.visibility_error() > 0.0;
        let split = if partially_visible && s_area > r_area {
            // The receiver's own error then comes mostly from the coarse sampling of the occlusion by
            // the source's nodes (steps of 1/m across the receiver), which only a finer source removes.
            Decision::SubdivideSource
        } else if own >= propagated.max(visibility) {
            Decision::SubdivideReceiver
        } else {
            Decision::SubdivideSource
        };
        Some(LinkJudgement {
            error: total + visibility,
            split,
        })
    }
}
