//! Refinement oracles: for a candidate link (source element j → receiver element i) estimate the error of
//! representing the interaction by that single link, and decide whether it is admissible or which of the
//! two elements to subdivide. One implementation per criterion, chosen with `--oracle`:
//! [`power::PowerOracle`] (Feixas et al. eq. (1)), [`smoothness::SmoothnessOracle`] (kernel smoothness,
//! eq. (2)), [`mutual_information::MutualInformationOracle`] (eq. (15)) and the Bekaert–Willems link
//! error oracle [`link_error::LinkErrorOracle`] (eq. (13)), which judges a link from its coupling.
//!
//! Shared conventions: ρ and B are RGB and every oracle scales by the largest per-channel product ρ_i B_j
//! ([`reflected_source_radiance`]); the sampling oracles evaluate the kernel at random point pairs with
//! [`sample_kernel`] and report its visibility rays.

pub mod link_error;
pub mod mutual_information;
pub mod power;
pub mod smoothness;

use crate::geometry::form_factor::point_to_point;
use crate::geometry::DVec2;
use crate::hierarchy::{ElementId, Hierarchy, LinkCoupling};
use crate::visibility::Visibility;
use rand::Rng;
use rand_pcg::Pcg64Mcg;

/// What to do with a candidate link.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Decision {
    /// Keep the link at this level.
    #[default]
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

/// A link error estimate from the link's coupling, with the element whose subdivision reduces it most.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LinkJudgement {
    /// Estimated error of the link, in radiance (W/(m² sr)).
    pub error: f64,
    pub split: Decision,
}

/// A refinement criterion.
pub trait RefinementOracle: Sync + Send {
    /// Name used on the command line and in reports.
    fn name(&self) -> &'static str;

    /// Error estimate for the link `source` → `receiver`; `rng` is seeded from the link's identity, so the
    /// estimate does not depend on thread scheduling.
    ///
    /// Contract: the estimate is [`reflected_source_radiance`] times a factor that does not depend on
    /// radiance (true of eqs. (1), (2) and (15)). Refinement caches that factor on the link and, after
    /// each solve pass, re-judges the link from the new radiance without calling the oracle again; since
    /// the samples come from the link's own seed, this gives the same answer as a fresh estimate.
    fn estimate(
        &self,
        context: &OracleContext,
        receiver: ElementId,
        source: ElementId,
        rng: &mut Pcg64Mcg,
    ) -> Estimate;

    /// Whether the oracle judges links from their computed coupling ([`RefinementOracle::link_error`])
    /// rather than from [`RefinementOracle::estimate`]; refinement then computes the coupling first,
    /// keeps it on the link, and compares with each receiver's own threshold.
    fn judges_couplings(&self) -> bool {
        false
    }

    /// The link's error and the element to split, from its coupling (Bekaert–Willems eq. (13)); `None`
    /// for oracles that do not judge couplings.
    fn link_error(
        &self,
        _context: &OracleContext,
        _receiver: ElementId,
        _source: ElementId,
        _coupling: &LinkCoupling,
    ) -> Option<LinkJudgement> {
        None
    }

    /// The estimate of a partially visible link from its visibility-blind `estimate` (same units,
    /// compared with the same threshold) and `spread`, the L¹ variation of its visibility over the
    /// receiver (`solvers::coupling::visibility_spread`, at most ½); `None`: the oracle does not weigh
    /// visibility (the default). Refinement asks only about links that `estimate` finds admissible,
    /// and samples their visibility only where the answer at `spread = ½` would refine them.
    fn with_partial_visibility(&self, _estimate: f64, _spread: f64) -> Option<f64> {
        None
    }

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
    let rho = hierarchy.reflectance_of(receiver);
    let b = hierarchy.average_radiance(source);
    (rho * b).max_channel()
}

/// Kernel values at random point pairs of a candidate link, with the rays they cost.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct KernelSamples {
    /// G(x_k, y_k) = F(x_k, y_k) vis(x_k, y_k), per unit source area.
    pub values: Vec<f64>,
    /// Visibility rays cast (one per pair whose unoccluded kernel is positive).
    pub rays: u64,
}

/// The radiosity kernel G(x, y) = F(x, y) vis(x, y) (Feixas et al. §2.1) at `n` independent random point
/// pairs, x uniform on the receiver and y uniform on the source: the "point-to-point form factor
/// computations between a pair of elements" of the smoothness and MI oracles (§4). Pairs that face away
/// from each other have G = 0 without a ray; every other pair casts one shadow ray.
pub fn sample_kernel(
    context: &OracleContext,
    receiver: ElementId,
    source: ElementId,
    n: usize,
    rng: &mut Pcg64Mcg,
) -> KernelSamples {
    let h = context.hierarchy;
    let (r, s) = (h.element(receiver).shape(), h.element(source).shape());
    let (nx, ny) = (h.patch_of(receiver).normal, h.patch_of(source).normal);
    let mut out = KernelSamples {
        values: Vec::with_capacity(n),
        rays: 0,
    };
    for _ in 0..n {
        let x = r.sample_uniform(DVec2::new(rng.random(), rng.random()));
        let y = s.sample_uniform(DVec2::new(rng.random(), rng.random()));
        let f = point_to_point(x, nx, y, ny);
        let g = if f > 0.0 {
            out.rays += 1;
            if context.visibility.segment_occluded(x, y) {
                0.0
            } else {
                f
            }
        } else {
            0.0
        };
        out.values.push(g);
    }
    out
}

#[cfg(test)]
pub(crate) mod tests {
    use crate::geometry::Shape;
    use crate::hierarchy::Hierarchy;
    use crate::pipeline::{build_visibility, VisibilityKind};
    use crate::scene::{generators, Polygon, Scene};
    use crate::visibility::Visibility;

    /// Receiver square [0, side]² at z = 0 (facing +z, patch 0) under an emitting square at height
    /// `distance` (patch 1), with an optional black one-sided blocker.
    pub fn two_squares(
        side: f64,
        distance: f64,
        reflectance: f64,
        emission: f64,
        blocker: Option<Shape>,
    ) -> Scene {
        let mut scene = generators::parallel_plates(side, distance, reflectance, emission);
        if let Some(shape) = blocker {
            let material = scene.materials.len();
            scene.materials.push(crate::scene::Material::diffuse(
                "blocker",
                crate::color::Rgb::BLACK,
            ));
            scene.polygons.push(Polygon {
                shape,
                material,
                object: 0,
                two_sided: false,
                under_contact: false,
            });
        }
        scene
    }

    pub fn context_for(scene: &Scene) -> (Hierarchy, Box<dyn Visibility>) {
        (
            Hierarchy::new(scene, crate::bases::BasisKind::Constant),
            build_visibility(scene, VisibilityKind::BruteForce).expect("brute force"),
        )
    }
}
