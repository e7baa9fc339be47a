//! Radiometric kernels: the point-to-point form factor `F(x, y) = cos θx cos θy / (π r²)` (the unoccluded
//! kernel `G` of Feixas et al. eq. (2) and the K of Bekaert–Willems eq. (1) without ρ and vis) and the
//! exact point-to-polygon form factor (Lambert's contour formula), used for the power oracle's cheap
//! estimate (Feixas et al. eq. (1)) and for the unoccluded part of link form factors.

use super::{DVec3, Shape};
use std::f64::consts::{FRAC_1_PI, FRAC_PI_2, PI};

/// Point-to-point (differential) form factor kernel between `x` with normal `nx` and `y` with normal `ny`,
/// per unit area of `y`; zero when either point faces away (or an input is not finite).
pub fn point_to_point(x: DVec3, nx: DVec3, y: DVec3, ny: DVec3) -> f64 {
    let d = y - x;
    let r2 = d.length_squared();
    if !(r2 > 0.0 && r2.is_finite()) {
        return 0.0;
    }
    let cos_x = nx.dot(d);
    let cos_y = -ny.dot(d);
    if !(cos_x > 0.0 && cos_y > 0.0) {
        return 0.0;
    }
    // Each cosine scaled by 1/r² separately, so that r2 * r2 cannot underflow for very close points;
    // one division (this kernel runs for every node pair of every coupling).
    let inverse_r2 = r2.recip();
    let f = (cos_x * inverse_r2) * (cos_y * inverse_r2) * FRAC_1_PI;
    if f.is_finite() {
        f
    } else {
        0.0
    }
}

/// Exact unoccluded form factor from a differential area at `x` (normal `nx`) to the front side of a
/// polygon, by Lambert's contour integral over the part of the polygon above the tangent plane of `x`.
/// Any triangle or quad is accepted (non-convex, non-planar, degenerate): the result is in [0, 1], and 0
/// for non-finite input.
pub fn point_to_polygon(x: DVec3, nx: DVec3, polygon: &Shape) -> f64 {
    let verts = polygon.vertices();
    // The source emits from its front side only (the side its vector area points to: no square
    // root needed).
    if polygon.vector_area().dot(x - verts[0]) <= 0.0 {
        return 0.0;
    }
    let height = |p: DVec3| nx.dot(p - x);
    let f = if verts.iter().all(|&v| height(v) >= 0.0) {
        contour_integral(x, nx, verts)
    } else {
        // Clip the polygon to the half-space in front of x (Sutherland–Hodgman against one plane).
        // Each vertex contributes at most itself and one crossing, so a non-convex quad needs up to 8
        // slots.
        let mut clipped: [DVec3; 8] = [DVec3::ZERO; 8];
        let mut count = 0;
        for (a, b) in super::edges(verts) {
            let (ha, hb) = (height(a), height(b));
            if ha >= 0.0 {
                clipped[count] = a;
                count += 1;
            }
            if (ha >= 0.0) != (hb >= 0.0) {
                let t = ha / (ha - hb);
                clipped[count] = a + t * (b - a);
                count += 1;
            }
        }
        if count < 3 {
            return 0.0;
        }
        contour_integral(x, nx, &clipped[..count])
    };
    if f.is_finite() {
        f.min(1.0)
    } else {
        0.0
    }
}

/// Lambert's contour integral `|Σ_edges γ_k n_x · (a_k × b_k)/|a_k × b_k|| / 2π` over the polygon
/// `corners`, all on or above the tangent plane of `x`; `γ_k` is the angle the edge subtends at `x`.
/// Both the angle (`atan2(|a × b|, a · b)`) and the edge plane's normal are unchanged by the lengths of
/// `a` and `b`, so the corners' directions are not normalised. The edges go [`EDGE_LANES`] at a time
/// through [`edge_terms`], whose square roots and divisions are then independent of each other (the
/// form factor runs over two million times in the default solve; this is a third faster than an edge
/// at a time, with the same sum).
fn contour_integral(x: DVec3, nx: DVec3, corners: &[DVec3]) -> f64 {
    let mut sum = 0.0;
    let mut edges = super::edges(corners).peekable();
    while edges.peek().is_some() {
        // Lanes without an edge are invalid: they add nothing.
        let (mut sin2, mut cos, mut normal) =
            ([0.0; EDGE_LANES], [1.0; EDGE_LANES], [0.0; EDGE_LANES]);
        let mut valid = [false; EDGE_LANES];
        for (lane, (from, to)) in edges.by_ref().take(EDGE_LANES).enumerate() {
            let (a, b) = (from - x, to - x);
            let cross = a.cross(b);
            sin2[lane] = cross.length_squared();
            cos[lane] = a.dot(b);
            normal[lane] = nx.dot(cross);
            // An edge seen end-on (or a corner at x) subtends no angle: |a × b| ≤ 1e-15 |a| |b|.
            valid[lane] = sin2[lane] > 1e-30 * a.length_squared() * b.length_squared();
        }
        for term in edge_terms(sin2, cos, normal, valid) {
            sum += term;
        }
    }
    (sum / (2.0 * PI)).abs()
}

/// Edges of [`contour_integral`] handled together (a quad's four).
const EDGE_LANES: usize = 4;

/// Each lane's `γ n_x · (a × b) / |a × b|` from `|a × b|²`, `a · b` and `n_x · (a × b)`; 0 where not
/// `valid`. Branch-free, so that the lanes' square roots and divisions overlap.
#[inline(always)]
fn edge_terms(
    sin2: [f64; EDGE_LANES],
    cos: [f64; EDGE_LANES],
    normal: [f64; EDGE_LANES],
    valid: [bool; EDGE_LANES],
) -> [f64; EDGE_LANES] {
    let mut out = [0.0; EDGE_LANES];
    for lane in 0..EDGE_LANES {
        let sin = sin2[lane].sqrt();
        let term = subtended_angle(sin, cos[lane]) * normal[lane] / sin;
        out[lane] = if valid[lane] { term } else { 0.0 };
    }
    out
}

/// `atan2(sin, cos)` for `sin ≥ 0`, both finite and not both zero: the angle in [0, π] between two
/// directions from the sine and cosine of the contour integral's edges, within 1 ulp of π. Cheaper than
/// a general `atan2` (a fifth of the default solve's time went to it): the ratio of the smaller to the
/// larger argument, `t ∈ [0, 1]`, is moved to the nearest of `c = 0, ¼, ½, ¾, 1` by
/// `atan t = atan c + atan z`, `z = (t − c)/(1 + t c)`, one division; with `|z| ≤ ⅛` nine terms of the
/// Taylor series leave a relative error under `z¹⁸/19 < 3·10⁻¹⁸`. Branch-free (selects only).
#[inline(always)]
fn subtended_angle(sin: f64, cos: f64) -> f64 {
    /// `atan((j + 1)/4) − atan(j/4)`: summed up to `j`, each partial sum is `atan(j/4)` correctly
    /// rounded (every difference and sum is exact).
    const ATAN_STEPS: [f64; 4] = [
        0.244_978_663_126_864_14,
        0.218_668_945_873_941_95,
        0.179_853_499_792_478_28,
        0.141_897_054_604_163_9,
    ];
    let along = cos.abs();
    let swapped = sin > along;
    let num = if swapped { along } else { sin };
    let den = if swapped { sin } else { along };
    // c = round(4 num/den)/4 without the division: a quarter for each of the midpoints ⅛, ⅜, ⅝, ⅞
    // that num/den reaches.
    let eighths = 8.0 * num;
    let (mut c, mut atan_c) = (0.0, 0.0);
    for (k, step) in ATAN_STEPS.iter().enumerate() {
        let reached = eighths >= (2 * k + 1) as f64 * den;
        c += if reached { 0.25 } else { 0.0 };
        atan_c += if reached { *step } else { 0.0 };
    }
    let z = (num - c * den) / (den + c * num);
    // atan z = z Σ_k (−z²)^k / (2k + 1), k ≤ 8, by Estrin's scheme (a short dependency chain).
    let w = z * z;
    let (w2, w4) = (w * w, w * w * w * w);
    let a = |k: i32| (1 - 2 * (k & 1)) as f64 / (2 * k + 1) as f64;
    let low = (a(0) + a(1) * w) + (a(2) + a(3) * w) * w2;
    let high = (a(4) + a(5) * w) + (a(6) + a(7) * w) * w2;
    let series = low + high * w4 + a(8) * (w4 * w4);
    let reduced = atan_c + z * series;
    let first_octant = if swapped {
        FRAC_PI_2 - reduced
    } else {
        reduced
    };
    if cos < 0.0 {
        PI - first_octant
    } else {
        first_octant
    }
}

/// Closed-form form factor between two coaxial parallel rectangles a x b at distance c (Howell's catalogue,
/// C-11): the analytic reference for tests.
pub fn parallel_rectangles(a: f64, b: f64, c: f64) -> f64 {
    let (x, y) = (a / c, b / c);
    let (x2, y2) = (x * x, y * y);
    let t1 = (((1.0 + x2) * (1.0 + y2)) / (1.0 + x2 + y2)).sqrt().ln();
    let t2 = x * (1.0 + y2).sqrt() * (x / (1.0 + y2).sqrt()).atan();
    let t3 = y * (1.0 + x2).sqrt() * (y / (1.0 + x2).sqrt()).atan();
    let t4 = x * x.atan() + y * y.atan();
    2.0 / (PI * x * y) * (t1 + t2 + t3 - t4)
}

/// Closed-form form factor between two parallel axis-aligned rectangles in any relative position, from
/// `[x0, x1] × [y0, y1]` to `[ξ0, ξ1] × [η0, η1]` in planes `z` apart (Howell's catalogue, C-12: the
/// sixteen-term superposition of `G`); the analytic reference for offset and adjacent plates.
pub fn parallel_rectangles_offset(from: [f64; 4], to: [f64; 4], z: f64) -> f64 {
    let [x0, x1, y0, y1] = from;
    let [xi0, xi1, eta0, eta1] = to;
    let g = |dx: f64, dy: f64| {
        let (rx, ry) = ((dx * dx + z * z).sqrt(), (dy * dy + z * z).sqrt());
        let along_y = if rx > 0.0 {
            dy * rx * dy.atan2(rx)
        } else {
            0.0
        };
        let along_x = if ry > 0.0 {
            dx * ry * dx.atan2(ry)
        } else {
            0.0
        };
        let r2 = dx * dx + dy * dy + z * z;
        let log = if r2 > 0.0 { 0.5 * z * z * r2.ln() } else { 0.0 };
        (along_y + along_x - log) / (2.0 * PI)
    };
    let mut sum = 0.0;
    for (i, x) in [x0, x1].into_iter().enumerate() {
        for (j, y) in [y0, y1].into_iter().enumerate() {
            for (k, eta) in [eta0, eta1].into_iter().enumerate() {
                for (l, xi) in [xi0, xi1].into_iter().enumerate() {
                    let sign = if (i + j + k + l) % 2 == 0 { 1.0 } else { -1.0 };
                    sum += sign * g(x - xi, y - eta);
                }
            }
        }
    }
    sum / ((x1 - x0) * (y1 - y0))
}

/// Closed-form form factor from a rectangle (width `w` along the common edge, depth `h`) to a perpendicular
/// rectangle (same width, height `l`) sharing that edge (Howell's catalogue, C-14).
pub fn perpendicular_rectangles(w: f64, h: f64, l: f64) -> f64 {
    let (hh, ww) = (l / w, h / w);
    let (h2, w2) = (hh * hh, ww * ww);
    let term1 = ww * (1.0 / ww).atan() + hh * (1.0 / hh).atan()
        - (h2 + w2).sqrt() * (1.0 / (h2 + w2).sqrt()).atan();
    let a = (1.0 + w2) * (1.0 + h2) / (1.0 + w2 + h2);
    let b = (w2 * (1.0 + w2 + h2) / ((1.0 + w2) * (w2 + h2))).powf(w2);
    let c = (h2 * (1.0 + h2 + w2) / ((1.0 + h2) * (h2 + w2))).powf(h2);
    (term1 + 0.25 * (a * b * c).ln()) / (PI * ww)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::cubature::gauss_nodes;

    #[test]
    fn subtended_angle_is_atan2_to_an_ulp() {
        let mut rng = <rand_pcg::Pcg64Mcg as rand::SeedableRng>::seed_from_u64(7);
        let mut worst: f64 = 0.0;
        let mut check = |sin: f64, cos: f64| {
            let (fast, exact) = (subtended_angle(sin, cos), sin.atan2(cos));
            worst = worst.max((fast - exact).abs());
        };
        for _ in 0..200_000 {
            let angle = rand::Rng::random::<f64>(&mut rng) * PI;
            let length = 10f64.powf(rand::Rng::random_range(&mut rng, -30.0f64..30.0));
            check(length * angle.sin(), length * angle.cos());
        }
        // The reduction's breakpoints, both axes, and extreme ratios.
        for t in [0.125, 0.375, 0.625, 0.875, 1.0, 0.0, 1e-300, 1e300] {
            for (sin, cos) in [(t, 1.0), (1.0, t), (t, -1.0), (1.0, -t)] {
                check(sin, cos);
                check(sin.next_up(), cos);
            }
        }
        check(1.0, 0.0);
        check(0.0, -1.0);
        assert!(worst <= 4.5e-16, "{worst:e}");
    }

    #[test]
    fn analytic_references_match_published_values() {
        assert!((parallel_rectangles(1.0, 1.0, 1.0) - 0.1998).abs() < 1e-4);
        assert!((perpendicular_rectangles(1.0, 1.0, 1.0) - 0.2000).abs() < 1e-4);
    }

    #[test]
    fn offset_rectangles_reduce_to_the_coaxial_case_and_obey_reciprocity() {
        let f = parallel_rectangles_offset([0.0, 1.0, 0.0, 2.0], [0.0, 1.0, 0.0, 2.0], 0.7);
        assert!(
            (f - parallel_rectangles(1.0, 2.0, 0.7)).abs() < 1e-12,
            "{f}"
        );
        let (a, b) = ([0.0, 1.0, 0.0, 1.0], [1.2, 2.0, 0.3, 1.5]);
        let (ab, ba) = (
            parallel_rectangles_offset(a, b, 0.5),
            parallel_rectangles_offset(b, a, 0.5),
        );
        assert!((ab * 1.0 - ba * 0.8 * 1.2).abs() < 1e-12, "{ab} {ba}");
        // Against Lambert's formula integrated by a fine Gauss product over the receiver.
        let receiver = Shape::Quad([DVec3::ZERO, DVec3::X, DVec3::new(1.0, 1.0, 0.0), DVec3::Y]);
        let source = Shape::Quad([
            DVec3::new(1.2, 0.3, 0.5),
            DVec3::new(1.2, 1.5, 0.5),
            DVec3::new(2.0, 1.5, 0.5),
            DVec3::new(2.0, 0.3, 0.5),
        ]);
        let lambert: f64 = gauss_nodes(&receiver, 5)
            .iter()
            .map(|q| q.weight * point_to_polygon(q.point, DVec3::Z, &source))
            .sum();
        assert!((lambert - ab).abs() < 1e-6 * ab, "{lambert} vs {ab}");
    }

    #[test]
    fn point_to_polygon_integrates_to_the_area_form_factor() {
        // Receiver: unit square at z = 0 facing +z. Source: unit square at z = 1 facing -z.
        let receiver = Shape::Quad([DVec3::ZERO, DVec3::X, DVec3::new(1.0, 1.0, 0.0), DVec3::Y]);
        let source = Shape::Quad([
            DVec3::new(0.0, 0.0, 1.0),
            DVec3::new(0.0, 1.0, 1.0),
            DVec3::new(1.0, 1.0, 1.0),
            DVec3::new(1.0, 0.0, 1.0),
        ]);
        let f: f64 = gauss_nodes(&receiver, 5)
            .iter()
            .map(|q| q.weight * point_to_polygon(q.point, DVec3::Z, &source))
            .sum();
        assert!((f - parallel_rectangles(1.0, 1.0, 1.0)).abs() < 1e-6, "{f}");
        // A source facing away contributes nothing.
        assert_eq!(
            point_to_polygon(DVec3::new(0.5, 0.5, 0.0), DVec3::Z, &source.flipped()),
            0.0
        );
    }

    #[test]
    fn point_to_polygon_of_a_whole_hemisphere_cap_is_bounded_by_one() {
        let big = Shape::Quad([
            DVec3::new(-1e4, -1e4, 1.0),
            DVec3::new(-1e4, 1e4, 1.0),
            DVec3::new(1e4, 1e4, 1.0),
            DVec3::new(1e4, -1e4, 1.0),
        ]);
        let f = point_to_polygon(DVec3::ZERO, DVec3::Z, &big);
        assert!((f - 1.0).abs() < 1e-3, "{f}");
    }
}
