//! The mutual-information oracle of Feixas et al., eq. (15): the difference between the continuous and
//! the discrete element-to-element radiosity mutual information (eq. 14), a measure of the information
//! transfer lost by representing the interaction with one constant link:
//!
//! `δ = A_i ρ_i A_j B_j ( (1/N) Σ F_k log F_k − ((1/N) Σ F_k) log((1/N) Σ F_k) )`, log base 2,
//!
//! over N random point pairs (x_k uniform on the receiver, y_k on the source; the paper uses N = 10).
//! The paper's substitutions are applied as in eq. (15): the total 𝒜_T is dropped ("as it does not change
//! much from interaction to interaction") and the receiver's B_i is replaced by ρ_i ("as, for a non-source
//! patch, B_i is proportional to ρ_i"). ρ_i B_j is the largest per-channel product, as for every oracle.
//!
//! **Visibility is included**: F(x_k, y_k) is the kernel G = F vis of [`sample_kernel`], zero for blocked
//! pairs (with 0 log 0 = 0). The paper writes F(x_k, y_k) but (i) eq. (14) rests on "taking F_ij / A_j ≃
//! (1/N_ij) Σ F(x_k, y_k)", where F_ij "is the form factor between patches i and j", the occluded one, so
//! the samples must carry visibility for the discrete term to be I^d; (ii) eq. (11) is computed "with
//! lines joining both elements", like the global lines of eq. (10), which join mutually visible points;
//! (iii) §4 counts the cost as "10 rays are cast for each oracle evaluation" and the abstract claims the
//! oracle "needs less visibility computations"; (iv) the MI oracle is credited with resolving the small
//! cube's shadow on a coarse mesh, which an unoccluded kernel cannot see.
//!
//! **Non-negativity**: x log x is convex, so by Jensen (the log-sum inequality, eq. (7) with b_k = 1)
//! the bracket, [`mi_bracket`], is ≥ 0 and is zero exactly when all samples are equal. It scales like F
//! (the log's argument is F / mean F once Σ F_k log mean F = N mean log mean is moved inside), so δ is in
//! radiance × area like the threshold and eq. (1), whatever the scene's length unit.
//!
//! **Early in the solution.** The paper: "at the beginning of the radiosity computation most of the
//! receiver B_j values are null". Its remedy, B_i → ρ_i, removes the receiver's radiosity from eq. (15),
//! which is what lets the oracle work from the first iteration; the source's B_j stays, as in eqs. (1)
//! and (2). We take B_j as the source element's current average radiance (emission included). On the first
//! refinement pass only links from emitters can therefore be refined; the solver re-refines every link
//! after each solve pass with the new radiance (the counterpart of the paper's hierarchical Monte Carlo
//! radiosity, which refines while radiosity is being propagated), until a pass refines nothing. We add no
//! a-priori guess of B_j (such as E_j + ρ_j × an ambient term): the re-refinement passes make it
//! unnecessary, and it would make the three oracles' meshes differ from the criteria the paper compares.

use super::{reflected_source_radiance, sample_kernel, Estimate, OracleContext, RefinementOracle};
use crate::hierarchy::ElementId;
use rand_pcg::Pcg64Mcg;

/// Feixas et al. eq. (15) with N sampled point pairs.
#[derive(Clone, Copy, Debug)]
pub struct MutualInformationOracle {
    /// Point pairs per estimate (the paper uses 10, and 4 in its robustness test).
    pub samples: usize,
}

impl MutualInformationOracle {
    pub fn new(samples: usize) -> Self {
        MutualInformationOracle { samples }
    }
}

/// The bracket of eqs. (14)–(15): `mean(F log₂ F) − mean(F) log₂ mean(F)` over non-negative kernel
/// samples, with 0 log 0 = 0; zero without samples. Computed as `mean(F log₂(F / mean F))`, the same
/// quantity, which avoids cancelling two large terms when F is far from 1.
pub fn mi_bracket(samples: &[f64]) -> f64 {
    if samples.is_empty() {
        return 0.0;
    }
    let n = samples.len() as f64;
    let mean = samples.iter().sum::<f64>() / n;
    if mean <= 0.0 {
        return 0.0;
    }
    samples
        .iter()
        .filter(|&&f| f > 0.0)
        .map(|&f| f * (f / mean).log2())
        .sum::<f64>()
        / n
}

impl RefinementOracle for MutualInformationOracle {
    fn name(&self) -> &'static str {
        "mi"
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
        let (a_i, a_j) = (h.element(receiver).area, h.element(source).area);
        Estimate {
            error: a_i
                * a_j
                * reflected_source_radiance(h, receiver, source)
                * mi_bracket(&kernel.values),
            rays: kernel.rays,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{DVec3, Shape};
    use crate::oracles::tests::{context_for, two_squares};
    use proptest::prelude::*;
    use rand::SeedableRng;

    /// The bracket exactly as printed in eq. (15).
    fn literal_bracket(f: &[f64]) -> f64 {
        let n = f.len() as f64;
        let xlogx = |x: f64| if x > 0.0 { x * x.log2() } else { 0.0 };
        let mean = f.iter().sum::<f64>() / n;
        f.iter().map(|&x| xlogx(x)).sum::<f64>() / n - xlogx(mean)
    }

    #[test]
    fn bracket_by_hand() {
        // All samples equal: no information lost.
        for f in [0.1, 1.0, 3.7e4] {
            assert!(mi_bracket(&[f; 10]).abs() <= 1e-15 * f, "{f}");
        }
        // {1, 0}: mean(F log F) = 0, mean = 1/2, (1/2) log₂(1/2) = −1/2.
        assert_eq!(mi_bracket(&[1.0, 0.0]), 0.5);
        // {1, 2}: mean(F log F) = 1, mean = 3/2.
        let expected = 1.0 - 1.5 * 1.5f64.log2();
        assert!((mi_bracket(&[1.0, 2.0]) - expected).abs() < 1e-15);
        assert!((expected - 0.122_556_248_918_265_66).abs() < 1e-15);
        // Fully blocked and empty: 0 log 0 = 0, no NaN.
        assert_eq!(mi_bracket(&[0.0; 4]), 0.0);
        assert_eq!(mi_bracket(&[]), 0.0);
    }

    proptest! {
        /// Eq. (7): the bracket is non-negative, equals the literal form of eq. (15) and scales like F.
        #[test]
        fn bracket_is_non_negative_and_scales_like_f(
            f in prop::collection::vec(0.0f64..1e3, 1..40),
            scale in 1e-6f64..1e6,
        ) {
            let b = mi_bracket(&f);
            let mean = f.iter().sum::<f64>() / f.len() as f64;
            let max = f.iter().copied().fold(0.0, f64::max);
            let tolerance = 1e-12 * max;
            prop_assert!(b >= -tolerance, "bracket {b}");
            // The literal form cancels terms of size max·|log₂ max|.
            let literal_tolerance = 1e-12 * max * (1.0 + max.log2().abs() + mean.log2().abs());
            prop_assert!((b - literal_bracket(&f)).abs() <= literal_tolerance);
            let scaled: Vec<f64> = f.iter().map(|x| x * scale).collect();
            prop_assert!((mi_bracket(&scaled) - scale * b).abs() <= 1e-9 * scale * (b.abs() + max));
        }
    }

    #[test]
    fn parallel_squares_give_a_positive_mi_error_that_vanishes_when_the_kernel_is_flat() {
        // Unit squares at distance 1: F varies by a factor of 9 across point pairs.
        let scene = two_squares(1.0, 1.0, 0.5, 2.0, None);
        let (h, vis) = context_for(&scene);
        let context = OracleContext {
            hierarchy: &h,
            visibility: vis.as_ref(),
        };
        let (receiver, source) = (h.patches[0].root, h.patches[1].root);
        let oracle = MutualInformationOracle::new(10);
        let e = oracle.estimate(&context, receiver, source, &mut Pcg64Mcg::seed_from_u64(5));
        let kernel = sample_kernel(
            &context,
            receiver,
            source,
            10,
            &mut Pcg64Mcg::seed_from_u64(5),
        );
        // A_i = A_j = 1, ρ_i B_j = 1.
        let expected = mi_bracket(&kernel.values);
        assert!(expected > 0.0 && (e.error - expected).abs() <= 1e-12 * expected);
        assert_eq!(e.rays, 10);

        // Tiny squares far apart: same scale of F × A_j, bracket ~ (s/d)⁴ relative.
        let (side, d) = (0.01, 10.0);
        let far = two_squares(side, d, 0.5, 2.0, None);
        let (h, vis) = context_for(&far);
        let context = OracleContext {
            hierarchy: &h,
            visibility: vis.as_ref(),
        };
        let (receiver, source) = (h.patches[0].root, h.patches[1].root);
        let e = oracle.estimate(&context, receiver, source, &mut Pcg64Mcg::seed_from_u64(5));
        let power = side * side * 1.0 / (std::f64::consts::PI * d * d) * side * side;
        assert!(
            e.error >= 0.0 && e.error < 1e-8 * power,
            "{} vs {power}",
            e.error
        );
    }

    #[test]
    fn blocked_pairs_count_as_zero_kernel_and_raise_the_error() {
        let blocker = Shape::Quad([
            DVec3::new(-0.1, -0.1, 0.9),
            DVec3::new(-0.1, 1.1, 0.9),
            DVec3::new(0.5, 1.1, 0.9),
            DVec3::new(0.5, -0.1, 0.9),
        ]);
        let mut errors = Vec::new();
        for blocker in [None, Some(blocker)] {
            let scene = two_squares(1.0, 1.0, 0.5, 2.0, blocker);
            let (h, vis) = context_for(&scene);
            let context = OracleContext {
                hierarchy: &h,
                visibility: vis.as_ref(),
            };
            let (receiver, source) = (h.patches[0].root, h.patches[1].root);
            let e = MutualInformationOracle::new(40).estimate(
                &context,
                receiver,
                source,
                &mut Pcg64Mcg::seed_from_u64(2),
            );
            assert_eq!(e.rays, 40);
            errors.push(e.error);
        }
        // Half the pairs blocked: the bracket is at least about mean·log₂(1/visible fraction) ~ mean.
        assert!(errors[1] > 2.0 * errors[0], "{errors:?}");
    }
}
