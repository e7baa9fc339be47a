//! Cubature rules on elements.
//!
//! * [`rule`]: rules of a given polynomial degree of exactness on the master domains of Bekaert–Willems
//!   §2 (unit square, standard triangle), mapped onto an element by [`nodes_on`] as in their eq. (12):
//!   `∫_A f dA ≈ Σ_k w_k f(u_k, v_k) J(u_k, v_k)`. Used for the Galerkin coupling coefficients (eq. 3),
//!   the error estimates at the nodes (§4.2, Algorithm 4.1) and the basis overlaps.
//! * [`gauss_nodes`]: the older tensor Gauss–Legendre rule (collapsed onto triangles), used for form
//!   factors at receiver points.
//!
//! All 1-D Gauss rules are computed, not tabulated: Golub–Welsch (eigenvalues of the Jacobi matrix of
//! the three-term recurrence, Golub & Welsch 1969, *Calculation of Gauss quadrature rules*, Math. Comp.
//! 23) polished by Newton's method on the recurrence, with Christoffel weights `1 / Σ_k p_k(x)²`
//! (orthonormal `p_k`), which gives full double precision.

use std::sync::OnceLock;

use super::{DVec2, DVec3, Domain, Shape};

/// A cubature node on an element: world position, parameters on the element, and weight (weights sum to
/// the element's area).
#[derive(Clone, Copy, Debug)]
pub struct Node {
    pub point: DVec3,
    pub uv: DVec2,
    pub weight: f64,
}

/// A cubature rule on a master domain: nodes `uv` with weights `w` summing to [`Domain::area`], exact for
/// every monomial `u^p v^q` with `p + q <= degree`.
#[derive(Clone, Debug)]
pub struct Rule {
    pub domain: Domain,
    /// Degree of exactness actually reached (at least the requested one: the rules come in odd degrees
    /// `2n - 1` for `n` points per direction).
    pub degree: usize,
    pub nodes: Vec<(DVec2, f64)>,
}

/// Largest number of 1-D points per direction in [`rule`] (degree of exactness `2 * MAX_POINTS - 1`).
pub const MAX_POINTS: usize = 12;

/// Highest degree of exactness available from [`rule`]; higher requests are clamped to it.
pub const MAX_DEGREE: usize = 2 * MAX_POINTS - 1;

/// The cached rule of degree of exactness at least `degree` (0 counts as 1; clamped to [`MAX_DEGREE`])
/// on `domain`, with `n = ceil((degree + 1) / 2)` points per direction:
///
/// * square: tensor product of `n`-point Gauss–Legendre rules on [0, 1] (exact for `u^p v^q`,
///   `p, q <= 2n - 1`);
/// * triangle: Stroud's conical product rule (Stroud 1971, *Approximate Calculation of Multiple
///   Integrals*, §2.4, conical product formulas): with the collapsed map `u = s`, `v = t (1 - s)`
///   (Jacobian `1 - s`), `∫_T f = ∫∫ f(s, t(1-s)) (1-s) ds dt`; `s` takes the `n`-point Gauss–Jacobi
///   rule for the weight `1 - s` on [0, 1] and `t` the `n`-point Gauss–Legendre rule. A monomial of
///   total degree `<= 2n - 1` becomes a polynomial of degree `<= 2n - 1` in each of `s` and `t`, so the
///   rule is exact.
///
/// All nodes lie strictly inside the domain and all weights are positive.
pub fn rule(domain: Domain, degree: usize) -> &'static Rule {
    static TABLE: OnceLock<Vec<[Rule; 2]>> = OnceLock::new();
    let table = TABLE.get_or_init(|| {
        (1..=MAX_POINTS)
            .map(|n| {
                [
                    build_rule(Domain::Square, n),
                    build_rule(Domain::Triangle, n),
                ]
            })
            .collect()
    });
    let degree = degree.clamp(1, MAX_DEGREE);
    // n = ceil((degree + 1) / 2) points per direction reach degree 2n - 1 >= degree.
    let n = (degree / 2 + 1).min(MAX_POINTS);
    &table[n - 1][match domain {
        Domain::Square => 0,
        Domain::Triangle => 1,
    }]
}

fn build_rule(domain: Domain, n: usize) -> Rule {
    let (t, wt) = gauss_legendre01(n);
    let (s, ws) = match domain {
        Domain::Square => (t.clone(), wt.clone()),
        Domain::Triangle => gauss_jacobi_one_minus_x01(n),
    };
    let mut nodes = Vec::with_capacity(n * n);
    for (a, wa) in s.iter().zip(&ws) {
        for (b, wb) in t.iter().zip(&wt) {
            let uv = match domain {
                Domain::Square => DVec2::new(*a, *b),
                // The factor (1 - s) of the collapse is in the Gauss–Jacobi weights.
                Domain::Triangle => DVec2::new(*a, *b * (1.0 - *a)),
            };
            nodes.push((uv, wa * wb));
        }
    }
    Rule {
        domain,
        degree: 2 * n - 1,
        nodes,
    }
}

/// Maps `rule` onto `shape` (Bekaert–Willems eq. 12): weight `w * J(uv)` with `J` from
/// [`Shape::jacobian`]. For a triangle `J` is twice the area and the master triangle has area 1/2, so the
/// weights still sum to the shape's area.
pub fn nodes_on(shape: &Shape, rule: &Rule) -> Vec<Node> {
    let mut nodes = Vec::with_capacity(rule.nodes.len());
    nodes_on_into(shape, rule, &mut nodes);
    nodes
}

/// [`nodes_on`] into `out` (cleared first), for callers that reuse one vector.
pub fn nodes_on_into(shape: &Shape, rule: &Rule, out: &mut Vec<Node>) {
    out.clear();
    out.extend(nodes_of(shape, rule));
}

/// [`nodes_on`] one at a time, for callers that visit each node once.
pub fn nodes_of<'a>(shape: &'a Shape, rule: &'a Rule) -> impl Iterator<Item = Node> + 'a {
    debug_assert_eq!(shape.domain(), rule.domain, "rule for another domain");
    rule.nodes.iter().map(|&(uv, w)| Node {
        point: shape.point_at(uv),
        uv,
        weight: w * shape.jacobian(uv),
    })
}

/// An unbiased random rule of `cells²` nodes on `shape`, one uniform point in each cell of a regular
/// partition of the master domain (`cells × cells` squares of the unit square; the `cells²` congruent
/// triangles of the standard triangle), weighted by the cell's area times the Jacobian there: jittered
/// (stratified) sampling. `unit` draws the uniform numbers in [0, 1), two per node.
///
/// Why strata: a sum over these nodes of a discontinuous integrand (a shadow boundary crossing the
/// element) is unbiased, where fixed nodes err the same way for every receiver that sees the boundary
/// in the same place; and a smooth integrand (the kernel) is sampled with a variance that falls as
/// `cells⁻⁴`, so that a ratio of two such sums (the coupling's normalisation to the exact factor) has
/// a small bias. The Cranley–Patterson shift of the Gauss rule used before (every node moved by one
/// random shift modulo 1) gave a long lamp tube's kernel sum a 25% standard deviation seen from 1 m,
/// against 13% with 2 × 2 strata, and the ratio's bias sent the classroom's walls 1.9% too much of the
/// tubes' light (BENCHMARKS.md, "Partly visible sources by jittered strata").
pub fn jittered_nodes(
    shape: &Shape,
    cells: usize,
    mut unit: impl FnMut() -> f64,
    out: &mut Vec<Node>,
) {
    let cells = cells.max(1);
    let step = 1.0 / cells as f64;
    let cell_weight = shape.domain().area() / (cells * cells) as f64;
    out.clear();
    let mut push = |uv: DVec2| {
        out.push(Node {
            point: shape.point_at(uv),
            uv,
            weight: cell_weight * shape.jacobian(uv),
        })
    };
    match shape {
        Shape::Quad(_) => {
            for i in 0..cells {
                for j in 0..cells {
                    let (a, b) = (unit(), unit());
                    push(DVec2::new((i as f64 + a) * step, (j as f64 + b) * step));
                }
            }
        }
        Shape::Triangle(_) => {
            // Upward cells at corner (i, j) with legs +step; downward ones at (i + 1, j + 1), legs
            // −step. A uniform point of a triangle: a uniform point of the square on its legs, the
            // half beyond the diagonal folded back.
            for i in 0..cells {
                for j in 0..cells - i {
                    for (corner, sign) in [((i, j), 1.0), ((i + 1, j + 1), -1.0)] {
                        if sign < 0.0 && i + j + 2 > cells {
                            continue;
                        }
                        let (mut a, mut b) = (unit(), unit());
                        if a + b > 1.0 {
                            (a, b) = (1.0 - a, 1.0 - b);
                        }
                        let origin = DVec2::new(corner.0 as f64, corner.1 as f64) * step;
                        push(origin + sign * step * DVec2::new(a, b));
                    }
                }
            }
        }
    }
}

/// Gauss–Legendre nodes and weights on [0, 1], for 1 to 5 points (`n` clamped), computed once.
pub fn gauss_legendre_unit(n: usize) -> (&'static [f64], &'static [f64]) {
    static TABLE: OnceLock<Vec<(Vec<f64>, Vec<f64>)>> = OnceLock::new();
    let table = TABLE.get_or_init(|| (1..=5).map(gauss_legendre01).collect());
    let (x, w) = &table[n.clamp(1, 5) - 1];
    (x, w)
}

/// Tensor-product Gauss rule with `n` x `n` nodes (n clamped to 1..=5) on a shape; on triangles the
/// square is collapsed by the Duffy map (Gauss–Legendre in both directions, so of lower degree than
/// [`rule`]'s Gauss–Jacobi product for the same node count).
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

/// `n`-point Gauss–Legendre rule on [0, 1] (weight 1). Recurrence of the shifted Legendre polynomials:
/// `a_k = 1/2`, `b_k = k² / (4 (4k² - 1))`, `μ0 = 1` (Gautschi 2004, *Orthogonal Polynomials*, Table 1.1,
/// mapped from [-1, 1]).
fn gauss_legendre01(n: usize) -> (Vec<f64>, Vec<f64>) {
    let a = vec![0.5; n];
    let b: Vec<f64> = (1..=n)
        .map(|k| {
            let k = k as f64;
            k * k / (4.0 * (4.0 * k * k - 1.0))
        })
        .collect();
    gauss_from_recurrence(&a, &b, 1.0)
}

/// `n`-point Gauss–Jacobi rule on [0, 1] for the weight `1 - s`: Jacobi polynomials `P^(1,0)` on
/// [-1, 1] (weight `(1-x)^α (1+x)^β`, α = 1, β = 0) mapped by `s = (x + 1) / 2`. Recurrence (Gautschi
/// 2004, Table 1.1): `a_k = (β² - α²) / ((2k+α+β)(2k+α+β+2))`,
/// `b_k = 4k(k+α)(k+β)(k+α+β) / ((2k+α+β)² (2k+α+β+1)(2k+α+β-1))`; on [0, 1] `a ↦ (a + 1)/2`,
/// `b ↦ b / 4`, `μ0 = ∫_0^1 (1 - s) ds = 1/2`.
fn gauss_jacobi_one_minus_x01(n: usize) -> (Vec<f64>, Vec<f64>) {
    let (al, be) = (1.0f64, 0.0f64);
    let a: Vec<f64> = (0..n)
        .map(|k| {
            let s = 2.0 * k as f64 + al + be;
            let ak = (be * be - al * al) / (s * (s + 2.0));
            (ak + 1.0) * 0.5
        })
        .collect();
    let b: Vec<f64> = (1..=n)
        .map(|k| {
            let k = k as f64;
            let s = 2.0 * k + al + be;
            let bk =
                4.0 * k * (k + al) * (k + be) * (k + al + be) / (s * s * (s + 1.0) * (s - 1.0));
            bk * 0.25
        })
        .collect();
    gauss_from_recurrence(&a, &b, 0.5)
}

/// Gauss rule from the recurrence `√b_{k+1} p_{k+1} = (x - a_k) p_k - √b_k p_{k-1}` of the orthonormal
/// polynomials (`a` has `n` entries, `b` holds `b_1 ..= b_n`, `μ0` is the total mass): nodes are the
/// eigenvalues of the Jacobi matrix (Golub–Welsch), refined by Newton on `p_n`; weights are the
/// Christoffel numbers `1 / Σ_{k<n} p_k(x)²`. Nodes ascending.
fn gauss_from_recurrence(a: &[f64], b: &[f64], mu0: f64) -> (Vec<f64>, Vec<f64>) {
    let n = a.len();
    assert!(n >= 1 && b.len() >= n);
    let sb: Vec<f64> = b.iter().map(|x| x.sqrt()).collect();
    let mut d = a.to_vec();
    let mut e: Vec<f64> = (0..n)
        .map(|i| if i + 1 < n { sb[i] } else { 0.0 })
        .collect();
    tridiagonal_eigenvalues(&mut d, &mut e);
    d.sort_by(f64::total_cmp);
    // p_0 .. p_n and the derivative of p_n at x.
    let eval = |x: f64| -> (Vec<f64>, f64) {
        let mut p = vec![0.0; n + 1];
        let mut dp = vec![0.0; n + 1];
        p[0] = 1.0 / mu0.sqrt();
        for k in 0..n {
            let (pm, dpm) = if k > 0 {
                (sb[k - 1] * p[k - 1], sb[k - 1] * dp[k - 1])
            } else {
                (0.0, 0.0)
            };
            p[k + 1] = ((x - a[k]) * p[k] - pm) / sb[k];
            dp[k + 1] = ((x - a[k]) * dp[k] + p[k] - dpm) / sb[k];
        }
        let dpn = dp[n];
        (p, dpn)
    };
    let mut w = Vec::with_capacity(n);
    for x in d.iter_mut() {
        for _ in 0..3 {
            let (p, dpn) = eval(*x);
            if dpn == 0.0 {
                break;
            }
            let step = p[n] / dpn;
            *x -= step;
            if step.abs() <= 1e-17 {
                break;
            }
        }
        let (p, _) = eval(*x);
        w.push(1.0 / p[..n].iter().map(|v| v * v).sum::<f64>());
    }
    (d, w)
}

/// Eigenvalues of the symmetric tridiagonal matrix with diagonal `d` and off-diagonal `e` (`e[i]` couples
/// `i` and `i + 1`; the last entry is ignored) by the implicit QL algorithm (Numerical Recipes,
/// `tqli` without eigenvectors). The eigenvalues are left in `d`, unsorted.
fn tridiagonal_eigenvalues(d: &mut [f64], e: &mut [f64]) {
    let n = d.len();
    if n == 0 {
        return;
    }
    e[n - 1] = 0.0;
    for l in 0..n {
        let mut iterations = 0;
        loop {
            let mut m = l;
            while m + 1 < n {
                let dd = d[m].abs() + d[m + 1].abs();
                if e[m].abs() <= f64::EPSILON * dd {
                    break;
                }
                m += 1;
            }
            if m == l {
                break;
            }
            iterations += 1;
            assert!(iterations < 100, "tridiagonal QL did not converge");
            let mut g = (d[l + 1] - d[l]) / (2.0 * e[l]);
            let mut r = g.hypot(1.0);
            g = d[m] - d[l] + e[l] / (g + r.copysign(g));
            let (mut s, mut c, mut p) = (1.0, 1.0, 0.0);
            let mut i = m;
            let mut underflow = false;
            while i > l {
                i -= 1;
                let f = s * e[i];
                let b = c * e[i];
                r = f.hypot(g);
                e[i + 1] = r;
                if r == 0.0 {
                    d[i + 1] -= p;
                    e[m] = 0.0;
                    underflow = true;
                    break;
                }
                s = f / r;
                c = g / r;
                g = d[i + 1] - p;
                r = (d[i] - g) * s + 2.0 * c * b;
                p = s * r;
                d[i + 1] = g + p;
                g = c * r - b;
            }
            if underflow {
                continue;
            }
            d[l] -= p;
            e[l] = g;
            e[m] = 0.0;
        }
    }
}

/// Exact integral of `u^p v^q` over a master domain: `1 / ((p+1)(q+1))` on the unit square,
/// `p! q! / (p+q+2)!` on the standard triangle (Dirichlet integral).
pub fn monomial_integral(domain: Domain, p: usize, q: usize) -> f64 {
    match domain {
        Domain::Square => 1.0 / ((p + 1) as f64 * (q + 1) as f64),
        Domain::Triangle => {
            // p! q! / (p+q+2)! = 1 / ((p+q+2)(p+q+1) C(p+q, p)), evaluated as a product of ratios.
            let mut r = 1.0 / ((p + q + 2) as f64 * (p + q + 1) as f64);
            for k in 1..=q {
                r *= k as f64 / (p + k) as f64;
            }
            r
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rel_err(a: f64, b: f64) -> f64 {
        (a - b).abs() / b.abs()
    }

    #[test]
    fn legendre_matches_known_values() {
        let (x, w) = gauss_legendre_unit(3);
        let r = (0.15f64).sqrt();
        for (xi, ei) in x.iter().zip([0.5 - r, 0.5, 0.5 + r]) {
            assert!((xi - ei).abs() < 1e-15, "{xi} {ei}");
        }
        for (wi, ei) in w.iter().zip([5.0 / 18.0, 8.0 / 18.0, 5.0 / 18.0]) {
            assert!((wi - ei).abs() < 1e-15);
        }
        // One-point Gauss–Jacobi for the weight 1 - s: node at the mean 1/3, weight 1/2.
        let (x, w) = gauss_jacobi_one_minus_x01(1);
        assert!((x[0] - 1.0 / 3.0).abs() < 1e-15 && (w[0] - 0.5).abs() < 1e-15);
    }

    #[test]
    fn rules_are_exact_for_monomials_up_to_their_degree() {
        for domain in [Domain::Square, Domain::Triangle] {
            for requested in 0..=MAX_DEGREE + 2 {
                let r = rule(domain, requested);
                assert_eq!(r.domain, domain);
                assert!(r.degree >= requested.clamp(1, MAX_DEGREE));
                assert!(r.degree <= requested.max(1) + 1);
                let total: f64 = r.nodes.iter().map(|n| n.1).sum();
                assert!(rel_err(total, domain.area()) < 1e-14);
                for &(uv, w) in &r.nodes {
                    assert!(w > 0.0 && uv.x > 0.0 && uv.y > 0.0);
                    assert!(domain == Domain::Square || uv.x + uv.y < 1.0);
                }
                for p in 0..=r.degree {
                    for q in 0..=r.degree - p {
                        let exact = monomial_integral(domain, p, q);
                        let approx: f64 = r
                            .nodes
                            .iter()
                            .map(|(uv, w)| w * uv.x.powi(p as i32) * uv.y.powi(q as i32))
                            .sum();
                        assert!(
                            rel_err(approx, exact) < 1e-12,
                            "{domain:?} degree {} u^{p} v^{q}: {approx} vs {exact}",
                            r.degree
                        );
                    }
                }
            }
        }
    }

    /// One node per cell of the partition, weights that sum to the area where the Jacobian is
    /// constant, and an unbiased integral where it is not (a trapezoid): the mean over many draws of
    /// a quadratic's sum is within four standard errors of the Gauss rule's exact value.
    #[test]
    fn jittered_nodes_stratify_and_integrate_without_bias() {
        let tri = Shape::Triangle([
            DVec3::ZERO,
            DVec3::new(2.0, 0.0, 0.0),
            DVec3::new(0.0, 3.0, 0.0),
        ]);
        let trapezoid = Shape::Quad([
            DVec3::ZERO,
            DVec3::new(2.0, 0.0, 0.0),
            DVec3::new(1.5, 1.0, 0.0),
            DVec3::new(0.0, 1.0, 0.0),
        ]);
        let f = |p: DVec3| 1.0 + p.x * p.x - 2.0 * p.x * p.y + 3.0 * p.y;
        let mut state = 7u64;
        let mut unit = || {
            state = crate::random::splitmix64(state);
            crate::random::unit_interval(state)
        };
        let mut nodes = Vec::new();
        for cells in 1..=4 {
            for shape in [tri, trapezoid] {
                let exact: f64 = nodes_on(&shape, rule(shape.domain(), 6))
                    .iter()
                    .map(|q| q.weight * f(q.point))
                    .sum();
                let draws = 4000;
                let (mut sum, mut sum2) = (0.0, 0.0);
                for _ in 0..draws {
                    jittered_nodes(&shape, cells, &mut unit, &mut nodes);
                    assert_eq!(nodes.len(), cells * cells);
                    // Each node's cell: its square of the grid and, on a triangle, the half of it.
                    let mut cells_hit = std::collections::HashSet::new();
                    for q in &nodes {
                        assert!((shape.point_at(q.uv) - q.point).length() < 1e-15);
                        let scaled = q.uv * cells as f64;
                        let (i, j) = (scaled.x as usize, scaled.y as usize);
                        let upper = scaled.x + scaled.y - (i + j) as f64 > 1.0;
                        cells_hit.insert((i, j, upper && matches!(shape, Shape::Triangle(_))));
                    }
                    assert_eq!(cells_hit.len(), cells * cells, "{shape:?} {cells}");
                    let total: f64 = nodes.iter().map(|q| q.weight).sum();
                    if matches!(shape, Shape::Triangle(_)) {
                        assert!(rel_err(total, shape.area()) < 1e-12);
                    }
                    let estimate: f64 = nodes.iter().map(|q| q.weight * f(q.point)).sum();
                    sum += estimate;
                    sum2 += estimate * estimate;
                }
                let mean = sum / draws as f64;
                let standard_error = ((sum2 / draws as f64 - mean * mean) / draws as f64).sqrt();
                assert!(
                    (mean - exact).abs() < 4.0 * standard_error + 1e-12,
                    "{shape:?} {cells}: {mean} ± {standard_error}, exact {exact}"
                );
            }
        }
    }

    #[test]
    fn monomial_integrals_match_factorials() {
        let fact = |n: usize| (1..=n).map(|k| k as f64).product::<f64>();
        for p in 0..8 {
            for q in 0..8 {
                let e = fact(p) * fact(q) / fact(p + q + 2);
                assert!(rel_err(monomial_integral(Domain::Triangle, p, q), e) < 1e-14);
            }
        }
    }

    #[test]
    fn mapped_rules_sum_to_area_and_integrate_linear_functions() {
        let tri = Shape::Triangle([
            DVec3::ZERO,
            DVec3::new(2.0, 0.0, 0.0),
            DVec3::new(0.0, 3.0, 0.0),
        ]);
        let quad = Shape::Quad([
            DVec3::ZERO,
            DVec3::new(2.0, 0.0, 0.0),
            DVec3::new(1.5, 1.0, 0.0),
            DVec3::new(0.0, 1.0, 0.0),
        ]);
        for degree in 1..=12 {
            for shape in [tri, quad] {
                let nodes = nodes_on(&shape, rule(shape.domain(), degree));
                let s: f64 = nodes.iter().map(|q| q.weight).sum();
                assert!(rel_err(s, shape.area()) < 1e-12, "{shape:?} {degree}");
                for q in &nodes {
                    assert!((shape.point_at(q.uv) - q.point).length() < 1e-15);
                }
            }
            // Integral of x over the triangle = area * centroid.x = 3 * 2/3 = 2.
            let ix: f64 = nodes_on(&tri, rule(Domain::Triangle, degree))
                .iter()
                .map(|q| q.weight * q.point.x)
                .sum();
            assert!((ix - 2.0).abs() < 1e-12);
        }
    }

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
