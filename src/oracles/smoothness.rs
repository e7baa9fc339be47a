//! The classic kernel-smoothness oracle, Feixas et al. eq. (2) (after Gortler et al.'s wavelet radiosity):
//! `ρ_i max(G_max − G_av, G_av − G_min) A_j B_j < ε`, with the radiosity kernel G(x, y) = F(x, y) vis(x, y).
//!
//! G_max and G_min are the largest and smallest of G at N random point pairs (x uniform on the receiver,
//! y uniform on the source, one shadow ray per pair: [`sample_kernel`]), as in the paper ("estimated by
//! taking the maximum and minimum value computed between pairs of random points on both elements"). The
//! paper defines G_av = F_ij / A_j; we estimate it by the sample mean of the same N values, which is the
//! unbiased Monte Carlo estimate of F_ij / A_j and costs no further rays.
//!
//! Units: eq. (2) is a radiance, while the refinement threshold is in radiance × area (ε = eps Σ A max(E)).
//! The estimate is therefore multiplied by a constant reference area, the scene's total surface area A_T:
//! the criterion becomes eq. (2) < eps × (area-averaged emitted radiance), independent of the scene's
//! length unit, and links are ranked exactly as by eq. (2). We deliberately do not weight by the receiver
//! area A_i: the paper points out that A_i is what distinguishes eq. (15) from eq. (2).
//!
//! B_j is the source's current average radiance, as for the other oracles (see
//! [`super::mutual_information`] for why this is enough from the first iteration). Where the kernel is
//! unbounded (elements sharing an edge) G_max − G_av does not shrink with the elements, so this oracle
//! refines down to the minimum area along such edges: the weakness the paper's MI oracle addresses.

use super::{reflected_source_radiance, sample_kernel, Estimate, OracleContext, RefinementOracle};
use crate::hierarchy::{ElementId, Hierarchy};
use rand_pcg::Pcg64Mcg;

/// Feixas et al. eq. (2) with N sampled point pairs.
#[derive(Clone, Copy, Debug)]
pub struct SmoothnessOracle {
    /// Point pairs per estimate (the paper uses 10, and 4 in its robustness test).
    pub samples: usize,
    /// Area that turns eq. (2)'s radiance into the threshold's radiance × area (the total scene area).
    pub reference_area: f64,
}

impl SmoothnessOracle {
    pub fn new(samples: usize, reference_area: f64) -> Self {
        SmoothnessOracle {
            samples,
            reference_area,
        }
    }

    /// The oracle for a scene: the reference area is the hierarchy's total patch area.
    pub fn for_hierarchy(samples: usize, hierarchy: &Hierarchy) -> Self {
        Self::new(samples, hierarchy.total_area())
    }
}

/// `max(G_max − G_av, G_av − G_min)` of eq. (2) over kernel samples, with G_av their mean; zero without
/// samples.
pub fn kernel_range(samples: &[f64]) -> f64 {
    if samples.is_empty() {
        return 0.0;
    }
    let mean = samples.iter().sum::<f64>() / samples.len() as f64;
    let (min, max) = samples
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &g| {
            (lo.min(g), hi.max(g))
        });
    (max - mean).max(mean - min).max(0.0)
}

impl RefinementOracle for SmoothnessOracle {
    fn name(&self) -> &'static str {
        "smoothness"
    }

    fn estimate(
        &self,
        context: &OracleContext,
        receiver: ElementId,
        source: ElementId,
        rng: &mut Pcg64Mcg,
    ) -> Estimate {
        let h = context.hierarchy;
        let kernel = sample_kernel(context, receiver, source, self.samples, rng);
        let a_j = h.element(source).area;
        Estimate {
            error: self.reference_area
                * reflected_source_radiance(h, receiver, source)
                * kernel_range(&kernel.values)
                * a_j,
            rays: kernel.rays,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::color::Rgb;
    use crate::geometry::{DVec3, Shape};
    use crate::oracles::tests::{context_for, two_squares};
    use rand::SeedableRng;
    use std::f64::consts::PI;

    #[test]
    fn kernel_range_is_the_larger_deviation_from_the_mean() {
        // Mean 3: max − mean = 3, mean − min = 2.
        assert_eq!(kernel_range(&[1.0, 2.0, 3.0, 6.0]), 3.0);
        // Mean 4: max − mean = 1, mean − min = 4.
        assert_eq!(kernel_range(&[0.0, 5.0, 5.0, 6.0]), 4.0);
        assert_eq!(kernel_range(&[2.5; 7]), 0.0);
        assert_eq!(kernel_range(&[]), 0.0);
    }

    #[test]
    fn tiny_far_apart_elements_have_an_almost_constant_kernel() {
        // Squares of side 0.01 facing each other at distance 10: G = 1/(π d²) up to (s/d)² ~ 1e-6.
        let (side, d) = (0.01, 10.0);
        let scene = two_squares(side, d, 0.5, 2.0, None);
        let (h, vis) = context_for(&scene);
        let context = OracleContext {
            hierarchy: &h,
            visibility: vis.as_ref(),
        };
        let (receiver, source) = (h.patches[0].root, h.patches[1].root);
        let mut rng = Pcg64Mcg::seed_from_u64(3);
        let kernel = sample_kernel(&context, receiver, source, 10, &mut rng);
        let g = 1.0 / (PI * d * d);
        assert_eq!(kernel.rays, 10);
        for v in &kernel.values {
            assert!((v - g).abs() / g < 1e-5, "{v} vs {g}");
        }
        let oracle = SmoothnessOracle::for_hierarchy(10, &h);
        let e = oracle.estimate(&context, receiver, source, &mut rng);
        // Eq. (2) relative to its scale ρ G_av A_j B_j A_T is of order (s/d)².
        let scale = oracle.reference_area * 0.5 * g * side * side * 2.0;
        assert!(e.error / scale < 1e-5, "{} vs scale {scale}", e.error);
        assert_eq!(e.rays, 10);
    }

    #[test]
    fn a_receiver_partly_in_shadow_has_kernel_minimum_zero() {
        // Unit squares at distance 1; a blocker just below the source covers half of it (x < 0.5).
        let blocker = Shape::Quad([
            DVec3::new(-0.1, -0.1, 0.9),
            DVec3::new(-0.1, 1.1, 0.9),
            DVec3::new(0.5, 1.1, 0.9),
            DVec3::new(0.5, -0.1, 0.9),
        ]);
        let open = two_squares(1.0, 1.0, 0.5, 1.0, None);
        let shadowed = two_squares(1.0, 1.0, 0.5, 1.0, Some(blocker));
        let mut ranges = Vec::new();
        for (scene, shadowed) in [(&open, false), (&shadowed, true)] {
            let (h, vis) = context_for(scene);
            let context = OracleContext {
                hierarchy: &h,
                visibility: vis.as_ref(),
            };
            let (receiver, source) = (h.patches[0].root, h.patches[1].root);
            let n = 40;
            let kernel = sample_kernel(
                &context,
                receiver,
                source,
                n,
                &mut Pcg64Mcg::seed_from_u64(9),
            );
            let min = kernel.values.iter().copied().fold(f64::INFINITY, f64::min);
            let mean = kernel.values.iter().sum::<f64>() / n as f64;
            let range = kernel_range(&kernel.values);
            // The estimate is eq. (2) on these samples: ρ = 0.5, A_j = 1, B_j = 1.
            let oracle = SmoothnessOracle::for_hierarchy(n, &h);
            let e = oracle.estimate(&context, receiver, source, &mut Pcg64Mcg::seed_from_u64(9));
            let expected = oracle.reference_area * 0.5 * range;
            assert!((e.error - expected).abs() <= 1e-12 * expected);
            assert_eq!(e.rays, n as u64);
            if shadowed {
                assert_eq!(min, 0.0, "some pairs must be blocked");
                // With G_min = 0 the range is at least G_av.
                assert!(range >= mean && mean > 0.0);
            } else {
                // Unit squares at distance 1: G lies between cos⁴/(π r²) at the farthest pair (r² = 3)
                // and 1/π straight across.
                assert!(min >= 1.0 / (9.0 * PI) && range < 1.0 / PI);
            }
            ranges.push(range);
        }
        assert!(
            ranges[1] > ranges[0],
            "shadow must widen the kernel range: {ranges:?}"
        );
    }

    #[test]
    fn the_estimate_scales_with_the_largest_channel_of_rho_times_b() {
        let mut scene = two_squares(1.0, 1.0, 0.5, 1.0, None);
        scene.materials[0].reflectance = Rgb::new(0.8, 0.1, 0.1);
        scene.materials[1].emission = Rgb::new(1.0, 1.0, 4.0);
        let (h, vis) = context_for(&scene);
        let context = OracleContext {
            hierarchy: &h,
            visibility: vis.as_ref(),
        };
        let (receiver, source) = (h.patches[0].root, h.patches[1].root);
        let oracle = SmoothnessOracle::for_hierarchy(10, &h);
        let e = oracle.estimate(&context, receiver, source, &mut Pcg64Mcg::seed_from_u64(1));
        let kernel = sample_kernel(
            &context,
            receiver,
            source,
            10,
            &mut Pcg64Mcg::seed_from_u64(1),
        );
        // max(0.8 × 1, 0.1 × 1, 0.1 × 4) = 0.8.
        let expected = oracle.reference_area * 0.8 * kernel_range(&kernel.values);
        assert!((e.error - expected).abs() <= 1e-12 * expected);
    }
}
