//! Error of a solution at surface points against reference estimates there (`probe --reference` or
//! `probe --against`), in luminance: the statistics an outsider checks a solver with at held-out points.
//!
//! Two views, since neither alone is fair. Relative errors `(L − L_ref) / L_ref` say how wrong a point
//! looks, but explode where the reference is nearly black (the underside of a desk, the outside of a
//! two-sided wall), so they are taken only at *lit* points, whose reference is above
//! [`LIT_FRACTION`] of the mean reference. Errors relative to the mean reference luminance,
//! `|L − L_ref| / mean(L_ref)`, count every point on one scale (the scale of `--accuracy P%`). The
//! reference's own noise is not removed: with its standard error `σ` a point's error is
//! overestimated by about `σ²/2|e|`, negligible once `σ` is well below the errors reported.
//!
//! Which points count is decided by the reference alone, so that two solutions compared at the same
//! points are measured on the same set and the same mean: points the reference finds black (the back
//! of a two-sided wall, where no path arrives) are left out of both views, and what a solution puts
//! there (light leaking where none arrives) is reported apart ([`PointErrors::black_points`]).

use crate::color::Rgb;

/// Lit points: reference luminance above this fraction of the mean reference luminance.
pub const LIT_FRACTION: f64 = 0.1;

/// Error statistics over probe points (fractions, not percent).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct PointErrors {
    /// Points compared: those whose reference is not black.
    pub points: usize,
    /// Points whose reference is black (luminance 0), left out of everything else here, and the
    /// largest solution luminance at them relative to the mean reference (a leak; 0 without one).
    pub black_points: usize,
    pub black_largest: f64,
    /// Mean reference luminance over the points compared.
    pub mean_reference: f64,
    /// Points whose reference exceeds [`LIT_FRACTION`] of the mean.
    pub lit_points: usize,
    /// Relative error at lit points: root mean square, median, 90th percentile and largest magnitude,
    /// and the mean of the signed errors (a bias).
    pub relative_rms: f64,
    pub relative_median: f64,
    pub relative_p90: f64,
    pub relative_max: f64,
    pub relative_mean_signed: f64,
    /// `|L − L_ref| / mean(L_ref)` over all points: root mean square, 95th percentile, largest.
    pub absolute_rms: f64,
    pub absolute_p95: f64,
    pub absolute_max: f64,
}

/// The statistics of `(solution, reference)` radiance pairs; `None` if the reference finds no light.
pub fn point_errors(pairs: impl IntoIterator<Item = (Rgb, Rgb)>) -> Option<PointErrors> {
    let (values, black): (Vec<_>, Vec<_>) = pairs
        .into_iter()
        .map(|(solution, reference)| (solution.luminance(), reference.luminance()))
        .partition(|&(_, r)| r != 0.0);
    let mean_reference = values.iter().map(|&(_, r)| r).sum::<f64>() / values.len() as f64;
    if values.is_empty() || mean_reference <= 0.0 {
        return None;
    }
    let relative: Vec<f64> = values
        .iter()
        .filter(|&&(_, r)| r > LIT_FRACTION * mean_reference)
        .map(|&(l, r)| (l - r) / r)
        .collect();
    let absolute: Vec<f64> = values
        .iter()
        .map(|&(l, r)| (l - r).abs() / mean_reference)
        .collect();
    let magnitudes: Vec<f64> = relative.iter().map(|e| e.abs()).collect();
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    let rms = |v: &[f64]| mean(&v.iter().map(|e| e * e).collect::<Vec<_>>()).sqrt();
    Some(PointErrors {
        points: values.len(),
        black_points: black.len(),
        black_largest: black.iter().map(|&(l, _)| l.abs()).fold(0.0, f64::max) / mean_reference,
        mean_reference,
        lit_points: relative.len(),
        relative_rms: rms(&relative),
        relative_median: quantile(&magnitudes, 0.5),
        relative_p90: quantile(&magnitudes, 0.9),
        relative_max: quantile(&magnitudes, 1.0),
        relative_mean_signed: mean(&relative),
        absolute_rms: rms(&absolute),
        absolute_p95: quantile(&absolute, 0.95),
        absolute_max: quantile(&absolute, 1.0),
    })
}

/// The `q`-quantile of `values` (the smallest value with at least a fraction `q` of them at or below
/// it); 0 for none.
fn quantile(values: &[f64], q: f64) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    let mut sorted = values.to_vec();
    sorted.sort_by(f64::total_cmp);
    let rank = ((q * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len());
    sorted[rank - 1]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn statistics_of_known_errors() {
        let grey = Rgb::splat;
        // References 1 (nine points) and 0.05 (one point, below 10% of the mean 0.905: not lit);
        // solutions off by +1%…+9% and by +0.05 on the dark point; one black pair left out.
        let mut pairs: Vec<(Rgb, Rgb)> = (1..=9)
            .map(|k| (grey(1.0 + 0.01 * k as f64), grey(1.0)))
            .collect();
        pairs.push((grey(0.1), grey(0.05)));
        pairs.push((grey(0.0), grey(0.0)));
        let e = point_errors(pairs.clone()).expect("lit points");
        assert_eq!((e.points, e.lit_points, e.black_points), (10, 9, 1));
        assert_eq!(e.black_largest, 0.0);
        assert!((e.mean_reference - 0.905).abs() < 1e-12);
        assert!((e.relative_median - 0.05).abs() < 1e-12);
        assert!((e.relative_p90 - 0.09).abs() < 1e-12);
        assert!((e.relative_max - 0.09).abs() < 1e-12);
        assert!((e.relative_mean_signed - 0.05).abs() < 1e-12);
        let rms = ((1..=9).map(|k| (0.01 * k as f64).powi(2)).sum::<f64>() / 9.0).sqrt();
        assert!((e.relative_rms - rms).abs() < 1e-12);
        // The largest error on the mean's scale is the +9% point's (the dark point is off by 0.05).
        assert!((e.absolute_max - 0.09 / 0.905).abs() < 1e-12);
        assert!(point_errors([(grey(0.0), grey(0.0))]).is_none());
        // A solution with light where the reference has none is measured on the same points and
        // mean as one without; the leak is reported apart, on the mean's scale.
        let last = pairs.len() - 1;
        pairs[last].0 = grey(0.181);
        let leaking = point_errors(pairs).expect("lit points");
        assert_eq!(
            (leaking.points, leaking.mean_reference, leaking.absolute_rms),
            (e.points, e.mean_reference, e.absolute_rms)
        );
        assert_eq!(leaking.black_points, 1);
        assert!((leaking.black_largest - 0.181 / 0.905).abs() < 1e-12);
    }
}
