//! Link coupling for the constant basis: the receiver-averaged form factor
//! `F_ij = 1/A_i ∫_{A_i} F(x → j) V(x, j) dA_x`, integrated with a fixed Gauss rule over the receiver
//! (`geometry::cubature`). At each receiver node the unoccluded point-to-polygon form factor is exact
//! (Lambert's formula) and the visibility V is estimated by rays to stratified random points on the source,
//! each weighted by the point-to-point kernel G(x, y) so that parts of the source that do not contribute
//! do not count. Higher-order bases (Bekaert–Willems eq. (3)) extend this to a coupling matrix.

use crate::geometry::cubature::gauss_nodes;
use crate::geometry::form_factor::{point_to_point, point_to_polygon};
use crate::geometry::DVec2;
use crate::hierarchy::{ElementId, Hierarchy};
use crate::visibility::Visibility;
use rand::Rng;
use rand_pcg::Pcg64Mcg;

/// How link form factors are computed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CouplingSettings {
    /// Gauss points per parameter direction on the receiver (1..=5): n² nodes.
    pub receiver_order: usize,
    /// Visibility rays from each receiver node to the source.
    pub visibility_rays: usize,
}

impl Default for CouplingSettings {
    fn default() -> Self {
        CouplingSettings {
            receiver_order: 2,
            visibility_rays: 4,
        }
    }
}

/// A link's form factor and the rays spent on it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Coupling {
    pub form_factor: f64,
    /// The same integral without visibility (zero means the elements cannot interact at all).
    pub unoccluded: f64,
    pub rays: u64,
}

/// Form factor from receiver element `receiver` to source element `source`, visibility included.
pub fn form_factor(
    hierarchy: &Hierarchy,
    visibility: &dyn Visibility,
    receiver: ElementId,
    source: ElementId,
    settings: &CouplingSettings,
    rng: &mut Pcg64Mcg,
) -> Coupling {
    let r = hierarchy.element(receiver);
    let s = hierarchy.element(source);
    let n_r = hierarchy.patch_of(receiver).normal;
    let n_s = hierarchy.patch_of(source).normal;
    let rays_per_node = settings.visibility_rays.max(1);
    let (mut visible, mut unoccluded, mut rays) = (0.0, 0.0, 0u64);
    for node in gauss_nodes(&r.shape, settings.receiver_order) {
        let f = point_to_polygon(node.point, n_r, &s.shape);
        if f <= 0.0 {
            continue;
        }
        let (mut seen, mut total) = (0.0, 0.0);
        let mut plain_seen = 0usize;
        for k in 0..rays_per_node {
            let sample = DVec2::new(
                (k as f64 + rng.random::<f64>()) / rays_per_node as f64,
                rng.random::<f64>(),
            );
            let y = s.shape.sample_uniform(sample);
            let g = point_to_point(node.point, n_r, y, n_s);
            rays += 1;
            let open = !visibility.segment_occluded(node.point, y);
            if open {
                seen += g;
                plain_seen += 1;
            }
            total += g;
        }
        let v = if total > 0.0 {
            seen / total
        } else {
            plain_seen as f64 / rays_per_node as f64
        };
        unoccluded += node.weight * f;
        visible += node.weight * f * v;
    }
    Coupling {
        form_factor: visible / r.area,
        unoccluded: unoccluded / r.area,
        rays,
    }
}
