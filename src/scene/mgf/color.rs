//! MGF colours (`cxy`, `cspec`, `cct`, `cmix`) to linear sRGB.
//!
//! Every MGF colour is a chromaticity: it is kept as CIE 1931 XYZ normalised to Y = 1, and the luminous
//! quantity (`rd`, `ed`) scales it. Spectra are integrated against the CIE 1931 2° colour matching
//! functions in the multi-lobe Gaussian fit of Wyman, Sloan and Shirley ("Simple Analytic
//! Approximations to the CIE XYZ Color Matching Functions", JCGT 2013), accurate to about 1% of the
//! tabulated functions, which moves chromaticities by less than 0.003.
//!
//! XYZ → RGB: MGF's neutral colour (the bare `c`) is equal-energy white (illuminant E, x = y = 1/3), while
//! sRGB's white is D65. A neutral grey must stay grey, so XYZ is first adapted from E to D65 with the
//! Bradford transform and then mapped by the sRGB (IEC 61966-2-1) matrix: E maps to RGB (1, 1, 1).

use crate::color::Rgb;
use glam::{DMat3, DVec3};

/// CIE XYZ tristimulus values.
pub type Xyz = DVec3;

/// MGF's neutral colour: equal-energy white with Y = 1.
pub const NEUTRAL: Xyz = DVec3::ONE;

/// A colour without luminance (see [`is_black_edge`]).
pub const BLACK: Xyz = DVec3::ZERO;

/// Whether (x, y) lies on the lower edge y = 0 of the chromaticity square: MGF's parser accepts it,
/// but no XYZ with Y = 1 has it; RenderPark reads it as black, and so do we.
pub fn is_black_edge(x: f64, y: f64) -> bool {
    y == 0.0 && (0.0..=1.0).contains(&x)
}

/// Chromaticity (x, y) as XYZ with Y = 1.
pub fn from_xy(x: f64, y: f64) -> Result<Xyz, String> {
    if !(x >= 0.0 && y > 0.0 && x + y <= 1.0) {
        return Err(format!(
            "chromaticity ({x}, {y}) is outside the CIE diagram (need x >= 0, y > 0, x + y <= 1)"
        ));
    }
    Ok(DVec3::new(x / y, 1.0, (1.0 - x - y) / y))
}

/// A relative spectrum sampled evenly from `lambda_min` to `lambda_max` nm, as XYZ with Y = 1.
pub fn from_spectrum(lambda_min: f64, lambda_max: f64, values: &[f64]) -> Result<Xyz, String> {
    if lambda_min >= lambda_max {
        return Err(format!(
            "spectrum range {lambda_min}..{lambda_max} nm is empty"
        ));
    }
    if values.len() < 2 {
        return Err("a spectrum needs at least two samples".into());
    }
    let step = (lambda_max - lambda_min) / (values.len() - 1) as f64;
    let sample = |lambda: f64| {
        if lambda < lambda_min || lambda > lambda_max {
            return 0.0;
        }
        let t = (lambda - lambda_min) / step;
        let i = (t.floor() as usize).min(values.len() - 2);
        let f = t - i as f64;
        values[i] * (1.0 - f) + values[i + 1] * f
    };
    normalise(integrate(sample), "spectrum")
}

/// The spectrum of a black body at `kelvin`, as XYZ with Y = 1.
pub fn blackbody(kelvin: f64) -> Result<Xyz, String> {
    if kelvin <= 0.0 {
        return Err(format!(
            "black body temperature {kelvin} K must be positive"
        ));
    }
    // Planck's law up to a constant factor; c2 = hc/k in m K.
    const C2: f64 = 1.438_776_9e-2;
    let planck = |lambda_nm: f64| {
        let l = lambda_nm * 1e-9;
        1.0 / (l.powi(5) * (C2 / (l * kelvin)).exp_m1())
    };
    normalise(integrate(planck), "black body")
}

/// Mixes colours with weights that are their relative luminances (MGF `cmix`), as XYZ with Y = 1.
pub fn mix(parts: &[(f64, Xyz)]) -> Result<Xyz, String> {
    if parts.iter().any(|(w, _)| *w < 0.0) {
        return Err("cmix weights must not be negative".into());
    }
    // Each colour has Y = 1 (or is black), so weight w contributes luminance w (or none).
    let sum: Xyz = parts.iter().map(|(w, c)| *w * *c).sum();
    if parts.iter().all(|(_, c)| *c == BLACK) {
        return Ok(BLACK);
    }
    normalise(sum, "cmix")
}

/// Linear sRGB of a colour (E white adapted to D65 as described in the module documentation).
pub fn to_linear_srgb(xyz: Xyz) -> Rgb {
    let rgb = xyz_to_rgb() * xyz;
    Rgb::new(rgb.x, rgb.y, rgb.z)
}

/// The colour whose [`to_linear_srgb`] is `rgb` (the exact inverse, used by the MGF writer); its Y is the
/// luminance.
pub fn from_linear_srgb(rgb: Rgb) -> Xyz {
    xyz_to_rgb().inverse() * DVec3::new(rgb.r, rgb.g, rgb.b)
}

fn rows(m: [[f64; 3]; 3]) -> DMat3 {
    DMat3::from_cols_array_2d(&m).transpose()
}

fn xyz_to_rgb() -> DMat3 {
    let srgb = rows([
        [3.240_454_2, -1.537_138_5, -0.498_531_4],
        [-0.969_266_0, 1.876_010_8, 0.041_556_0],
        [0.055_643_4, -0.204_025_9, 1.057_225_2],
    ]);
    let bradford = rows([
        [0.8951, 0.2664, -0.1614],
        [-0.7502, 1.7135, 0.0367],
        [0.0389, -0.0685, 1.0296],
    ]);
    let d65 = DVec3::new(0.950_47, 1.0, 1.088_83);
    let gain = (bradford * d65) / (bradford * NEUTRAL);
    srgb * bradford.inverse() * DMat3::from_diagonal(gain) * bradford
}

fn normalise(xyz: Xyz, what: &str) -> Result<Xyz, String> {
    if !xyz.is_finite() || xyz.y <= 0.0 {
        return Err(format!("{what} has no luminance"));
    }
    Ok(xyz / xyz.y)
}

/// ∫ s(λ) (x̄, ȳ, z̄)(λ) dλ over 360..830 nm in 1 nm steps.
fn integrate(s: impl Fn(f64) -> f64) -> Xyz {
    (360..=830)
        .map(|l| {
            let lambda = l as f64;
            s(lambda) * cmf(lambda)
        })
        .sum()
}

/// CIE 1931 2° colour matching functions, Wyman–Sloan–Shirley multi-lobe fit.
fn cmf(lambda: f64) -> DVec3 {
    let g = |mu: f64, below: f64, above: f64| {
        let sigma = if lambda < mu { below } else { above };
        let t = (lambda - mu) / sigma;
        (-0.5 * t * t).exp()
    };
    DVec3::new(
        1.056 * g(599.8, 37.9, 31.0) + 0.362 * g(442.0, 16.0, 26.7) - 0.065 * g(501.1, 20.4, 26.2),
        0.821 * g(568.8, 46.9, 40.5) + 0.286 * g(530.9, 16.3, 31.1),
        1.217 * g(437.0, 11.8, 36.0) + 0.681 * g(459.0, 26.0, 13.8),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn xy(c: Xyz) -> (f64, f64) {
        let s = c.x + c.y + c.z;
        (c.x / s, c.y / s)
    }

    #[test]
    fn neutral_is_white() {
        let rgb = to_linear_srgb(from_xy(1.0 / 3.0, 1.0 / 3.0).unwrap());
        for c in rgb.to_array() {
            assert!((c - 1.0).abs() < 1e-4, "{rgb:?}");
        }
    }

    #[test]
    fn flat_spectrum_is_equal_energy() {
        let (x, y) = xy(from_spectrum(380.0, 780.0, &[0.5, 0.5, 0.5]).unwrap());
        assert!(
            (x - 1.0 / 3.0).abs() < 0.003 && (y - 1.0 / 3.0).abs() < 0.003,
            "{x} {y}"
        );
    }

    #[test]
    fn black_bodies_lie_on_the_planckian_locus() {
        // CIE illuminant A (2856 K): (0.4476, 0.4074); 6500 K: (0.3135, 0.3236).
        for (t, ex, ey) in [(2856.0, 0.4476, 0.4074), (6500.0, 0.3135, 0.3236)] {
            let (x, y) = xy(blackbody(t).unwrap());
            assert!(
                (x - ex).abs() < 0.004 && (y - ey).abs() < 0.004,
                "{t}: {x} {y}"
            );
        }
    }

    #[test]
    fn mixing_is_luminance_weighted() {
        let r = from_xy(0.64, 0.33).unwrap();
        let g = from_xy(0.30, 0.60).unwrap();
        let m = mix(&[(1.0, r), (1.0, g)]).unwrap();
        assert!((m - (r + g) / 2.0).length() < 1e-12);
        assert!(mix(&[(0.0, r)]).is_err());
        assert!(from_xy(0.5, 0.6).is_err());
        assert!(from_spectrum(400.0, 400.0, &[1.0, 1.0]).is_err());
        assert!(blackbody(-5.0).is_err());
    }
}
