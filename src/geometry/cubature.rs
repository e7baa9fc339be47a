//! Fixed cubature rules on elements: tensor Gauss–Legendre on the unit square, mapped onto quads by the
//! bilinear map and onto triangles by the collapsed (Duffy) map. Used for form factors (receiver
//! points) and, later, for the Galerkin coupling coefficients of Bekaert–Willems eq. (3).

use super::{DVec2, DVec3, Shape};

/// A cubature node on an element: world position, parameters on the element, and weight (weights sum to
/// the element's area).
#[derive(Clone, Copy, Debug)]
pub struct Node {
    pub point: DVec3,
    pub uv: DVec2,
    pub weight: f64,
}

/// Gauss–Legendre nodes and weights on [0, 1], for 1 to 5 points.
pub fn gauss_legendre_unit(n: usize) -> (&'static [f64], &'static [f64]) {
    const X1: [f64; 1] = [0.5];
    const W1: [f64; 1] = [1.0];
    const X2: [f64; 2] = [0.211_324_865_405_187_1, 0.788_675_134_594_812_9];
    const W2: [f64; 2] = [0.5, 0.5];
    const X3: [f64; 3] = [0.112_701_665_379_258_3, 0.5, 0.887_298_334_620_741_7];
    const W3: [f64; 3] = [
        0.277_777_777_777_777_8,
        0.444_444_444_444_444_4,
        0.277_777_777_777_777_8,
    ];
    const X4: [f64; 4] = [
        0.069_431_844_202_973_7,
        0.330_009_478_207_571_9,
        0.669_990_521_792_428_1,
        0.930_568_155_797_026_3,
    ];
    const W4: [f64; 4] = [
        0.173_927_422_568_726_9,
        0.326_072_577_431_273_1,
        0.326_072_577_431_273_1,
        0.173_927_422_568_726_9,
    ];
    const X5: [f64; 5] = [
        0.046_910_077_030_668_0,
        0.230_765_344_947_158_5,
        0.5,
        0.769_234_655_052_841_5,
        0.953_089_922_969_332,
    ];
    const W5: [f64; 5] = [
        0.118_463_442_528_094_5,
        0.239_314_335_249_683_2,
        0.284_444_444_444_444_4,
        0.239_314_335_249_683_2,
        0.118_463_442_528_094_5,
    ];
    match n {
        0 | 1 => (&X1, &W1),
        2 => (&X2, &W2),
        3 => (&X3, &W3),
        4 => (&X4, &W4),
        _ => (&X5, &W5),
    }
}

/// Tensor-product Gauss rule with `n` x `n` nodes (n clamped to 1..=5) on a shape.
pub fn gauss_nodes(shape: &Shape, n: usize) -> Vec<Node> {
    let (x, w) = gauss_legendre_unit(n);
    let mut nodes = Vec::with_capacity(x.len() * x.len());
    for (a, wa) in x.iter().zip(w) {
        for (b, wb) in x.iter().zip(w) {
            let (uv, collapse) = match shape {
                Shape::Quad(_) => (DVec2::new(*a, *b), 1.0),
                // Duffy map of the square onto the triangle u + v <= 1.
                Shape::Triangle(_) => (DVec2::new(*a, *b * (1.0 - *a)), 1.0 - *a),
            };
            nodes.push(Node {
                point: shape.point_at(uv),
                uv,
                weight: wa * wb * collapse * shape.jacobian(uv),
            });
        }
    }
    nodes
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn weights_sum_to_area_and_integrate_polynomials() {
        let tri = Shape::Triangle([
            DVec3::ZERO,
            DVec3::new(2.0, 0.0, 0.0),
            DVec3::new(0.0, 3.0, 0.0),
        ]);
        for n in 1..=5 {
            let s: f64 = gauss_nodes(&tri, n).iter().map(|q| q.weight).sum();
            assert!((s - 3.0).abs() < 1e-12);
        }
        // Integral of x over the triangle = area * centroid.x = 3 * 2/3 = 2.
        let ix: f64 = gauss_nodes(&tri, 3)
            .iter()
            .map(|q| q.weight * q.point.x)
            .sum();
        assert!((ix - 2.0).abs() < 1e-12);
        let quad = Shape::Quad([
            DVec3::ZERO,
            DVec3::new(2.0, 0.0, 0.0),
            DVec3::new(1.5, 1.0, 0.0),
            DVec3::new(0.0, 1.0, 0.0),
        ]);
        let s: f64 = gauss_nodes(&quad, 3).iter().map(|q| q.weight).sum();
        assert!((s - quad.area()).abs() < 1e-12);
    }
}
