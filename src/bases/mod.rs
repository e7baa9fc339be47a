//! Polynomial bases on the master element domains for Galerkin radiosity (Bekaert–Willems §2).
//!
//! "The basis functions in our implementation were obtained by orthonormalisation of the functions
//! {1, u, v, uv, u², v², u³, u²v, uv², v³} on the unit square and the standard triangle" (§2); they are
//! mapped onto elements by the bilinear or barycentric map ([`Shape::point_at`]). A [`BasisKind`] takes a
//! prefix of that list; [`Basis`] holds the Gram–Schmidt coefficients on both [`Domain`]s and the
//! two-scale (push/pull) matrices between an element and the four children of [`Shape::subdivide`].
//!
//! Normalisation: orthonormal for the *averaged* parametric measure,
//! `(1/|D|) ∫_D φ_α φ_β du dv = δ_αβ`, with `φ_0 ≡ 1`, so coefficient 0 of a function is its parametric
//! average (its area average on triangles and parallelograms, where the Jacobian is constant). On a
//! general quad (a trapezoid) the Jacobian varies and the mapped functions are not orthogonal for the
//! area measure: the overlap matrix of Bekaert–Willems eq. (4) is then not diagonal, and [`Overlap`]
//! turns area moments `(1/A) ∫ f φ_α dA` (what couplings and pulls compute) into coefficients by solving
//! with it. Without that solve a uniformly lit trapezoid got a false gradient (its moments of `φ_1`,
//! `φ_2` are those of the Jacobian), and so did a parent of constant trapezoid children.
//!
//! [`Shape::point_at`]: crate::geometry::Shape::point_at
//! [`Shape::subdivide`]: crate::geometry::Shape::subdivide

use crate::color::Rgb;
use crate::geometry::cubature::{rule, MAX_POINTS};
use crate::geometry::{DVec2, Domain, Shape};
use std::sync::OnceLock;

/// The spanning monomials `u^p v^q` as `(p, q)`, in Bekaert–Willems' order {1, u, v, uv, u², v², u³, u²v,
/// uv², v³}. Every prefix used by a [`BasisKind`] is closed under lowering an exponent, so its span is
/// invariant under the axis-aligned affine child maps of [`child_parameters`].
pub const MONOMIALS: [(u32, u32); 10] = [
    (0, 0),
    (1, 0),
    (0, 1),
    (1, 1),
    (2, 0),
    (0, 2),
    (3, 0),
    (2, 1),
    (1, 2),
    (0, 3),
];

/// Which prefix of [`MONOMIALS`] spans the basis; the same span on both domains (bilinear is {1, u, v, uv}
/// on triangles too).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum BasisKind {
    /// {1}: 1 function.
    Constant,
    /// {1, u, v}: 3 functions.
    Linear,
    /// {1, u, v, uv}: 4 functions.
    Bilinear,
    /// {1, u, v, uv, u², v²}: 6 functions.
    Quadratic,
    /// All ten monomials up to total degree 3.
    Cubic,
}

impl BasisKind {
    pub const ALL: [BasisKind; 5] = [
        BasisKind::Constant,
        BasisKind::Linear,
        BasisKind::Bilinear,
        BasisKind::Quadratic,
        BasisKind::Cubic,
    ];

    /// Number of basis functions.
    pub fn size(self) -> usize {
        match self {
            BasisKind::Constant => 1,
            BasisKind::Linear => 3,
            BasisKind::Bilinear => 4,
            BasisKind::Quadratic => 6,
            BasisKind::Cubic => 10,
        }
    }

    /// Total degree of the highest monomial (bilinear: 2, from uv).
    pub fn polynomial_degree(self) -> usize {
        match self {
            BasisKind::Constant => 0,
            BasisKind::Linear => 1,
            BasisKind::Bilinear | BasisKind::Quadratic => 2,
            BasisKind::Cubic => 3,
        }
    }

    /// Degree of exactness of the receiver cubature rule. Bekaert–Willems §4.3: the minimum is "two times
    /// the order of the approximation on the patch plus one" and "slightly higher than the minimal
    /// required precision" gives visibly better coupling coefficients and error maxima. We take
    /// `2 d + 4`: with [`rule`]'s Gauss products that is `d + 3` points per direction. Fewer points fall
    /// into a trap of the node-sampled maximum of §4.3: the `d + 1` Gauss points are the zeros of the
    /// Legendre polynomial `P_{d+1}` that dominates the projection error (superconvergence), and the
    /// `d + 2` points, zeros of `P_{d+2}`, miss the error of every function symmetric about the element
    /// centre (where `P_{d+1}`'s component vanishes by parity): a constant element under a centred
    /// emitter would report no error at all with a 2×2 rule. The source rule is coarser
    /// ([`source_cubature_degree`]): it only integrates.
    pub fn default_cubature_degree(self) -> usize {
        2 * self.polynomial_degree() + 4
    }

    /// The receiver rule error control needs where refinement does not read the error coefficients
    /// (the power, smoothness and MI oracles under `--accuracy`): the estimate only has to see the
    /// leading error term. For odd `d` (linear, cubic) `d + 2` Gauss points do: the zeros of
    /// `P_{d+2}` are not those of `P_{d+1}`, and `P_{d+1}` is even, so symmetric functions keep that
    /// component. For even `d` (constant, quadratic) they miss every function symmetric about the
    /// centre ([`default_cubature_degree`](Self::default_cubature_degree)), so those keep `d + 3`.
    /// On the Cornell box, office2, office3, cube.mgf and the corridor the estimate with the linear
    /// basis' 3×3 rule still bounds 299–300 of 300 seen points' errors (BENCHMARKS.md, "Error control
    /// by default").
    pub fn estimating_cubature_degree(self) -> usize {
        if self.polynomial_degree() % 2 == 1 {
            2 * self.polynomial_degree() + 2
        } else {
            self.default_cubature_degree()
        }
    }
}

/// Degree of the source-side rule for a receiver rule of `receiver_degree` (eq. (12) allows different
/// rules on `i` and `j`): the source rule only has to integrate `K(x_k, y) φ_β(y)`, not to sample an
/// error maximum, so it is the minimal `2 d + 1` for the basis of degree `d` whose default receiver
/// rule is `receiver_degree` (`d + 1` points per direction, two fewer than the receiver), and at least
/// a 2×2 rule, so that partial visibility of the source is sampled at four points. Each node pair costs
/// a ray, so this halves to quarters the rays of a link.
pub fn source_cubature_degree(receiver_degree: usize) -> usize {
    receiver_degree.saturating_sub(3).max(2)
}

/// Child `child` (0..4, the order of [`Shape::subdivide`]) parameters → parent parameters. Each map is
/// affine, `origin + sign * uv / 2`; the corners come from
/// [`subdivide_parameters`] applied to [`Domain::corners`]: quads split at the parameter midpoints
/// (children at (0,0), (½,0), (½,½), (0,½)); triangles at the edge midpoints, with the middle child 3
/// (corners bc, ca, ab) rotated by a half turn, hence `sign = -1`. For bilinear quads this equality of
/// points holds exactly too, since the parent's bilinear map restricted to an axis-aligned sub-rectangle
/// is the child's bilinear map.
///
/// [`Shape::subdivide`]: crate::geometry::Shape::subdivide
/// [`subdivide_parameters`]: crate::geometry::subdivide_parameters
pub fn child_parameters(domain: Domain, child: usize, uv: DVec2) -> DVec2 {
    let (origin, sign) = child_map(domain, child);
    origin + sign * 0.5 * uv
}

/// The child (0..4) whose parameter domain contains the parent parameters `uv`, and the parameters
/// there: the inverse of [`child_parameters`]. Points on a shared edge go to the first child in the
/// order below; points slightly outside (rounding) to the nearest child.
pub fn child_containing(domain: Domain, uv: DVec2) -> (usize, DVec2) {
    let child = match domain {
        Domain::Square => match (uv.x >= 0.5, uv.y >= 0.5) {
            (false, false) => 0,
            (true, false) => 1,
            (true, true) => 2,
            (false, true) => 3,
        },
        Domain::Triangle if uv.x >= 0.5 => 1,
        Domain::Triangle if uv.y >= 0.5 => 2,
        Domain::Triangle if uv.x + uv.y <= 0.5 => 0,
        Domain::Triangle => 3,
    };
    let (origin, sign) = child_map(domain, child);
    (child, (uv - origin) / (0.5 * sign))
}

fn child_map(domain: Domain, child: usize) -> (DVec2, f64) {
    const SQUARE: [(DVec2, f64); 4] = [
        (DVec2::new(0.0, 0.0), 1.0),
        (DVec2::new(0.5, 0.0), 1.0),
        (DVec2::new(0.5, 0.5), 1.0),
        (DVec2::new(0.0, 0.5), 1.0),
    ];
    const TRIANGLE: [(DVec2, f64); 4] = [
        (DVec2::new(0.0, 0.0), 1.0),
        (DVec2::new(0.5, 0.0), 1.0),
        (DVec2::new(0.0, 0.5), 1.0),
        (DVec2::new(0.5, 0.5), -1.0),
    ];
    match domain {
        Domain::Square => SQUARE[child],
        Domain::Triangle => TRIANGLE[child],
    }
}

fn domain_index(domain: Domain) -> usize {
    match domain {
        Domain::Square => 0,
        Domain::Triangle => 1,
    }
}

/// An orthonormal basis of one [`BasisKind`] on both master domains, with its two-scale matrices.
#[derive(Clone, Debug)]
pub struct Basis {
    kind: BasisKind,
    size: usize,
    /// Per domain, `size × size` row-major and lower triangular: `φ_α = Σ_m c[α][m] x^p_m y^q_m` in the
    /// centred coordinates of [`centred`] (the same functions as with `u^p v^q`, better conditioned).
    coefficients: [Vec<f64>; 2],
    /// Per domain and child, `size × size` row-major push matrices.
    push: [[Vec<f64>; 4]; 2],
    /// `∫ u φ_α φ_α' du dv` and `∫ v φ_α φ_α' du dv` over the unit square (`size × size` row-major):
    /// with `∫ φ_α φ_α' = δ`, the overlap matrix of a planar quad, whose Jacobian is affine in
    /// `(u, v)`, is their combination ([`Basis::overlap`]).
    square_moments: [Vec<f64>; 2],
    /// Per domain, `φ_α` at each corner of [`Domain::corners`] (`corners × size` row-major): an
    /// expansion's value at an element's corner without evaluating the basis there.
    corner_values: [Vec<f64>; 2],
    /// Per domain and rule of [`rule`] (by points per direction, less one), `φ_α` at the rule's nodes,
    /// filled at first use ([`Basis::rule_values`]).
    rule_values: [[OnceLock<Vec<f64>>; MAX_POINTS]; 2],
}

impl Basis {
    /// Gram–Schmidt on the monomials (in [`centred`] coordinates) with their inner products from an
    /// exact cubature [`rule`], two passes per function (classical Gram–Schmidt with
    /// re-orthogonalisation, "twice is enough": Giraud et al. 2005, Numer. Math. 101), then the push
    /// matrices by an exact cubature rule.
    pub fn new(kind: BasisKind) -> Basis {
        let size = kind.size();
        let coefficients = [Domain::Square, Domain::Triangle].map(|d| gram_schmidt(d, size));
        let mut basis = Basis {
            kind,
            size,
            coefficients,
            push: Default::default(),
            square_moments: Default::default(),
            corner_values: Default::default(),
            rule_values: Default::default(),
        };
        for domain in [Domain::Square, Domain::Triangle] {
            for child in 0..4 {
                basis.push[domain_index(domain)][child] = basis.compute_push(domain, child);
            }
        }
        basis.square_moments = basis.compute_square_moments();
        basis.corner_values = [Domain::Square, Domain::Triangle].map(|domain| {
            let mut values = vec![0.0; domain.corners().len() * size];
            for (k, &corner) in domain.corners().iter().enumerate() {
                basis.eval(domain, corner, &mut values[k * size..(k + 1) * size]);
            }
            values
        });
        basis
    }

    /// `φ_α` at corner `k` of `domain` ([`Domain::corners`]).
    pub fn corner_values(&self, domain: Domain, k: usize) -> &[f64] {
        &self.corner_values[domain_index(domain)][k * self.size..(k + 1) * self.size]
    }

    /// `φ_α` at the nodes of [`rule`]`(domain, degree)`, row-major (node, α): the same on every element,
    /// since the basis lives on the master domain. A coupling evaluates the basis at its receiver's
    /// and its source's nodes; the table spares it those evaluations (6% of a cubic solve's instructions).
    pub fn rule_values(&self, domain: Domain, degree: usize) -> &[f64] {
        let rule = rule(domain, degree);
        let points = rule.degree.div_ceil(2);
        self.rule_values[domain_index(domain)][points - 1].get_or_init(|| {
            let mut values = vec![0.0; rule.nodes.len() * self.size];
            for (&(uv, _), phi) in rule.nodes.iter().zip(values.chunks_exact_mut(self.size)) {
                self.eval(domain, uv, phi);
            }
            values
        })
    }

    /// `∫ u φ_α φ_α'` and `∫ v φ_α φ_α'` on the unit square, by a rule exact for their degree 2 d + 1.
    fn compute_square_moments(&self) -> [Vec<f64>; 2] {
        let n = self.size;
        let mut moments = [vec![0.0; n * n], vec![0.0; n * n]];
        let mut phi = [0.0; MAX_BASIS_SIZE];
        let degree = 2 * self.kind.polynomial_degree() + 1;
        for &(uv, w) in &rule(Domain::Square, degree).nodes {
            self.eval(Domain::Square, uv, &mut phi);
            for i in 0..n {
                for j in 0..n {
                    moments[0][i * n + j] += w * uv.x * phi[i] * phi[j];
                    moments[1][i * n + j] += w * uv.y * phi[i] * phi[j];
                }
            }
        }
        moments
    }

    pub fn kind(&self) -> BasisKind {
        self.kind
    }

    pub fn size(&self) -> usize {
        self.size
    }

    /// Writes `φ_α(uv)` into `out[α]` for `α < size`.
    pub fn eval(&self, domain: Domain, uv: DVec2, out: &mut [f64]) {
        let n = self.size;
        let mut mono = [0.0; 10];
        monomials(centred(domain, uv), &mut mono[..n]);
        let c = &self.coefficients[domain_index(domain)];
        match self.kind {
            BasisKind::Constant => lower_triangular_product::<1>(c, &mono, out),
            BasisKind::Linear => lower_triangular_product::<3>(c, &mono, out),
            BasisKind::Bilinear => lower_triangular_product::<4>(c, &mono, out),
            BasisKind::Quadratic => lower_triangular_product::<6>(c, &mono, out),
            BasisKind::Cubic => lower_triangular_product::<10>(c, &mono, out),
        }
    }

    /// `Σ_α c_α φ_α(uv)` (coefficients beyond `size` are ignored, missing ones count as zero).
    pub fn value(&self, domain: Domain, uv: DVec2, coefficients: &[f64]) -> f64 {
        let mut phi = [0.0; 10];
        self.eval(domain, uv, &mut phi);
        phi[..self.size]
            .iter()
            .zip(coefficients)
            .map(|(p, c)| p * c)
            .sum()
    }

    /// L2 projection (orthonormal coefficients) of `f` on `domain`, integrated by [`rule`] of degree
    /// `cubature_degree`: `c_α = (1/|D|) ∫_D f φ_α`.
    pub fn project(
        &self,
        domain: Domain,
        cubature_degree: usize,
        f: impl Fn(DVec2) -> f64,
        out: &mut [f64],
    ) {
        let n = self.size;
        out[..n].fill(0.0);
        let mut phi = [0.0; 10];
        for &(uv, w) in &rule(domain, cubature_degree).nodes {
            self.eval(domain, uv, &mut phi);
            let fw = f(uv) * w / domain.area();
            for a in 0..n {
                out[a] += fw * phi[a];
            }
        }
    }

    /// Push matrix of `child`: `size × size` row-major,
    /// `P[α][β] = (1/|D|) ∫_D φ_α(uv) φ_β(map_k(uv)) du dv` with `map_k` = [`child_parameters`], so that
    /// the child's coefficients of the parent's function restricted to the child are `P · parent`.
    /// For every [`BasisKind`] on both domains this is exact (not just the L2 projection): the spans are
    /// closed under lowering exponents and every child map is `origin ± uv/2` per coordinate (including
    /// the half-turned middle triangle), so `φ_β ∘ map_k` stays in the span — bilinear on triangles
    /// included.
    pub fn push_matrix(&self, domain: Domain, child: usize) -> &[f64] {
        &self.push[domain_index(domain)][child]
    }

    /// Child `child`'s coefficients of the parent function `parent`: `out = P_k · parent` (missing
    /// parent coefficients count as zero, as in [`Basis::value`]).
    pub fn push(&self, domain: Domain, child: usize, parent: &[f64], out: &mut [f64]) {
        let n = self.size;
        let p = self.push_matrix(domain, child);
        for (a, o) in out[..n].iter_mut().enumerate() {
            *o = (0..n).zip(parent).map(|(b, c)| p[a * n + b] * c).sum();
        }
    }

    /// Adds child `child`'s contribution `(1/4) P_kᵀ · child` to the parent coefficients `out` (missing
    /// child coefficients count as zero): the
    /// children cover a quarter of the parent's parameter domain each, so
    /// `(1/|D|) ∫_D f φ_α = Σ_k (1/4) (1/|D|) ∫_D f_k(uv) φ_α(map_k(uv)) du dv`.
    pub fn pull_add(&self, domain: Domain, child: usize, coefficients: &[f64], out: &mut [f64]) {
        let n = self.size;
        let p = self.push_matrix(domain, child);
        for b in 0..n {
            let s: f64 = (0..n)
                .zip(coefficients)
                .map(|(a, c)| p[a * n + b] * c)
                .sum();
            out[b] += 0.25 * s;
        }
    }

    /// Parent coefficients from the four children's: `Σ_k (1/4) P_kᵀ · children[k]`, the adjoint of
    /// [`Basis::push`]. Exactly the L2 projection of the piecewise function onto the parent's span, and
    /// the inverse of push on the parent's span.
    pub fn pull(&self, domain: Domain, children: [&[f64]; 4], out: &mut [f64]) {
        out[..self.size].fill(0.0);
        for (k, c) in children.iter().enumerate() {
            self.pull_add(domain, k, c, out);
        }
    }

    fn compute_push(&self, domain: Domain, child: usize) -> Vec<f64> {
        let n = self.size;
        let mut p = vec![0.0; n * n];
        let (mut phi, mut phi_k) = ([0.0; 10], [0.0; 10]);
        // Integrand of degree 2 * polynomial_degree: exact.
        for &(uv, w) in &rule(domain, 2 * self.kind.polynomial_degree()).nodes {
            self.eval(domain, uv, &mut phi);
            self.eval(domain, child_parameters(domain, child, uv), &mut phi_k);
            let w = w / domain.area();
            for a in 0..n {
                for b in 0..n {
                    p[a * n + b] += w * phi[a] * phi_k[b];
                }
            }
        }
        p
    }
}

fn monomials(uv: DVec2, out: &mut [f64]) {
    let (u, v) = (uv.x, uv.y);
    let all = [
        1.0,
        u,
        v,
        u * v,
        u * u,
        v * v,
        u * u * u,
        u * u * v,
        u * v * v,
        v * v * v,
    ];
    let n = out.len();
    out.copy_from_slice(&all[..n]);
}

/// `out = c x` for the lower triangular `N × N` row-major `c`, each row summed in order from −0.0 (as
/// `Iterator::sum`). The basis is evaluated over a million times in a cubic solve and once per image
/// sample: with `N` known the loops unroll and lose their bounds checks.
#[inline(always)]
fn lower_triangular_product<const N: usize>(c: &[f64], x: &[f64], out: &mut [f64]) {
    let (c, x, out) = (&c[..N * N], &x[..N], &mut out[..N]);
    for a in 0..N {
        let mut sum = -0.0;
        for m in 0..a + 1 {
            sum += c[a * N + m] * x[m];
        }
        out[a] = sum;
    }
}

/// Centred, scaled coordinates `x = 2 (u - c)`, `y = 2 (v - c)` about the domain's centroid (c = ½ on
/// the square, ⅓ on the triangle). Every prefix of [`MONOMIALS`] is closed under lowering exponents, so
/// `{x^p y^q}` and `{u^p v^q}` prefixes span the same nested spaces and Gram–Schmidt yields the same
/// functions (leading coefficients stay positive); but the raw monomials on [0, 1] are nearly dependent
/// (Hilbert-like Gram matrix), which cost ~1e-12 in the two-scale identities for cubics, while the
/// centred ones give Legendre-like coefficients of order 10.
fn centred(domain: Domain, uv: DVec2) -> DVec2 {
    let c = match domain {
        Domain::Square => 0.5,
        Domain::Triangle => 1.0 / 3.0,
    };
    2.0 * (uv - DVec2::splat(c))
}

/// Orthonormal coefficients (lower triangular, `size × size`) of the first `size` [`centred`] monomials
/// on `domain` for the averaged inner product `<f, g> = (1/|D|) ∫_D f g`; the Gram matrix of the
/// monomials is integrated exactly (degree <= 6) by [`rule`].
fn gram_schmidt(domain: Domain, size: usize) -> Vec<f64> {
    let mut gram = vec![0.0; size * size];
    let mut mono = [0.0; 10];
    for &(uv, w) in &rule(domain, 6).nodes {
        monomials(centred(domain, uv), &mut mono[..size]);
        for i in 0..size {
            for j in 0..size {
                gram[i * size + j] += w / domain.area() * mono[i] * mono[j];
            }
        }
    }
    let dot = |a: &[f64], b: &[f64]| -> f64 {
        let mut s = 0.0;
        for i in 0..size {
            for j in 0..size {
                s += a[i] * gram[i * size + j] * b[j];
            }
        }
        s
    };
    let mut c = vec![0.0; size * size];
    for a in 0..size {
        let mut v = vec![0.0; size];
        v[a] = 1.0;
        for _pass in 0..2 {
            for b in 0..a {
                let phi_b = &c[b * size..(b + 1) * size];
                let r = dot(&v, phi_b);
                for (vi, pi) in v.iter_mut().zip(phi_b) {
                    *vi -= r * pi;
                }
            }
        }
        let norm = dot(&v, &v).sqrt();
        for (ci, vi) in c[a * size..(a + 1) * size].iter_mut().zip(&v) {
            *ci = vi / norm;
        }
    }
    // φ_0 ≡ 1 exactly (the averaged measure has mass one), so that the constant basis reproduces
    // element averages bit for bit rather than to the rounding of the Gram matrix.
    c[0] = 1.0;
    c
}

/// Most basis functions of any kind (cubic).
pub const MAX_BASIS_SIZE: usize = 10;

/// The overlap matrix of Bekaert–Willems eq. (4) of one element over its area,
/// `G_{αα'} = (1/A) ∫_A φ_α φ_α' dA`, as its Cholesky factor. It is the identity where the element's
/// Jacobian is constant (triangles, parallelograms: [`Basis::overlap`] returns `None` there), so only
/// trapezoid-like quads carry one. Area moments `μ_α = (1/A) ∫ f φ_α dA` are `G c` for the
/// coefficients `c` of f's area-L2 projection: [`Overlap::solve`] gives `c = G⁻¹ μ`, exact (a
/// constant f gives `c = f e_0`, no gradient), and power is `π A (G c)_0` ([`Overlap::mean`]).
#[derive(Clone, Debug)]
pub struct Overlap {
    size: usize,
    /// Row 0 of G: the area averages of the basis functions.
    means: [f64; MAX_BASIS_SIZE],
    /// Lower Cholesky factor L (G = L Lᵀ), row-major `size × size`.
    factor: [f64; MAX_BASIS_SIZE * MAX_BASIS_SIZE],
}

/// `x ← (L Lᵀ)⁻¹ x` for the lower triangular `N × N` row-major `l` by forward and back substitution, the
/// sums in order from −0.0 (as `Iterator::sum`); `N` known, so that the loops unroll.
#[inline(always)]
fn cholesky_solve<const N: usize>(l: &[f64], x: &mut [f64]) {
    let (l, x) = (&l[..N * N], &mut x[..N]);
    for a in 0..N {
        let mut s = -0.0;
        for b in 0..a {
            s += l[a * N + b] * x[b];
        }
        x[a] = (x[a] - s) / l[a * N + a];
    }
    for a in (0..N).rev() {
        let mut s = -0.0;
        for b in a + 1..N {
            s += l[b * N + a] * x[b];
        }
        x[a] = (x[a] - s) / l[a * N + a];
    }
}

/// Relative departure of a quad from a parallelogram, `|a + c − b − d| / (|a − c| + |b − d|)`, below
/// which its Jacobian is constant to rounding and its overlap matrix the identity.
const AFFINE_TOLERANCE: f64 = 1e-9;

impl Overlap {
    /// `G⁻¹ x` in place: the coefficients of the function whose area moments are `x`.
    pub fn solve(&self, x: &mut [f64]) {
        match self.size {
            3 => cholesky_solve::<3>(&self.factor, x),
            4 => cholesky_solve::<4>(&self.factor, x),
            6 => cholesky_solve::<6>(&self.factor, x),
            10 => cholesky_solve::<10>(&self.factor, x),
            size => unreachable!("no basis of {size} functions has an overlap matrix"),
        }
    }

    /// [`Overlap::solve`] per colour channel.
    pub fn solve_rgb(&self, x: &mut [Rgb]) {
        let n = self.size;
        let mut channels = [[0.0; MAX_BASIS_SIZE]; 3];
        for (a, v) in x[..n].iter().enumerate() {
            [channels[0][a], channels[1][a], channels[2][a]] = [v.r, v.g, v.b];
        }
        for channel in &mut channels {
            self.solve(&mut channel[..n]);
        }
        for (a, v) in x[..n].iter_mut().enumerate() {
            *v = Rgb::new(channels[0][a], channels[1][a], channels[2][a]);
        }
    }

    /// Solves every column of the row-major `size × columns` matrix `block` (rows are basis
    /// functions): the coupling block of moments becomes one of coefficients (Algorithm 4.1 step 4a).
    pub fn solve_columns(&self, block: &mut [f64], columns: usize) {
        let mut column = [0.0; MAX_BASIS_SIZE];
        for b in 0..columns {
            for (a, v) in column[..self.size].iter_mut().enumerate() {
                *v = block[a * columns + b];
            }
            self.solve(&mut column[..self.size]);
            for (a, v) in column[..self.size].iter().enumerate() {
                block[a * columns + b] = *v;
            }
        }
    }

    /// The area moments `G c` of the function with coefficients `c`, into `out`.
    pub fn moments_rgb(&self, c: &[Rgb], out: &mut [Rgb]) {
        let (n, l) = (self.size, &self.factor);
        // G c = L (Lᵀ c).
        let mut lt = [Rgb::BLACK; MAX_BASIS_SIZE];
        for (a, v) in lt[..n].iter_mut().enumerate() {
            *v = (a..n).map(|b| c[b] * l[b * n + a]).sum();
        }
        for (a, v) in out[..n].iter_mut().enumerate() {
            *v = (0..=a).map(|b| lt[b] * l[a * n + b]).sum();
        }
    }

    /// Area average of the function with coefficients `c`: `(G c)_0 = Σ_α c_α (1/A) ∫ φ_α dA`.
    pub fn mean(&self, c: &[Rgb]) -> Rgb {
        c.iter().zip(&self.means).map(|(&c, &m)| c * m).sum()
    }
}

impl Basis {
    /// The overlap matrix of `shape` (see [`Overlap`]) with an exact cubature rule: `None` where it is
    /// the identity (a triangle, a parallelogram to [`AFFINE_TOLERANCE`], or the constant basis, whose
    /// one moment is the area average). `area` is the element's, so that `G_00 = 1`.
    pub fn overlap(&self, shape: &Shape, area: f64) -> Option<Overlap> {
        let Shape::Quad([a, b, c, d]) = *shape else {
            return None;
        };
        let skew = (a + c - b - d).length();
        if self.size == 1 || skew <= AFFINE_TOLERANCE * (a.distance(c) + b.distance(d)) {
            return None;
        }
        let n = self.size;
        let mut g = [0.0; MAX_BASIS_SIZE * MAX_BASIS_SIZE];
        // The bilinear map's `∂p/∂u × ∂p/∂v` is affine in (u, v) on any quad (its uv term is
        // (a + c − b − d) × itself): `c00 + u (c10 − c00) + v (c01 − c00)`. On a planar quad all three
        // are normal to the plane, so the Jacobian, its length, is affine too and G follows from the
        // basis's square moments; a warped quad is integrated by cubature.
        let (c00, c10, c01) = (
            (b - a).cross(d - a),
            (b - a).cross(c - b),
            (c - d).cross(d - a),
        );
        let normal = (c00 + c10 + c01).normalize_or_zero();
        let planar = [c00, c10, c01]
            .iter()
            .all(|c| (*c - normal * normal.dot(*c)).length() <= AFFINE_TOLERANCE * c.length());
        if planar {
            let j0 = normal.dot(c00) / area;
            let (ju, jv) = (normal.dot(c10) / area - j0, normal.dot(c01) / area - j0);
            let [mu, mv] = &self.square_moments;
            for i in 0..n {
                for j in 0..=i {
                    let k = i * n + j;
                    g[k] = ju * mu[k] + jv * mv[k] + if i == j { j0 } else { 0.0 };
                }
            }
        } else {
            let mut phi = [0.0; MAX_BASIS_SIZE];
            // φ_α φ_α' J has degree 2 d + 2 on a warped quad (J is then no polynomial, but nearly
            // affine).
            let degree = 2 * self.kind.polynomial_degree() + 2;
            for &(uv, w) in &rule(Domain::Square, degree).nodes {
                self.eval(Domain::Square, uv, &mut phi);
                let wj = w * shape.jacobian(uv) / area;
                for i in 0..n {
                    for j in 0..=i {
                        g[i * n + j] += wj * phi[i] * phi[j];
                    }
                }
            }
        }
        let mut means = [0.0; MAX_BASIS_SIZE];
        for (i, m) in means[..n].iter_mut().enumerate() {
            *m = g[i * n];
        }
        // Cholesky, in place on the lower triangle.
        for j in 0..n {
            let s: f64 = (0..j).map(|k| g[j * n + k] * g[j * n + k]).sum();
            let pivot = g[j * n + j] - s;
            if pivot <= 0.0 {
                // A degenerate quad (zero area): no solve rather than a division by zero.
                return None;
            }
            g[j * n + j] = pivot.sqrt();
            for i in j + 1..n {
                let s: f64 = (0..j).map(|k| g[i * n + k] * g[j * n + k]).sum();
                g[i * n + j] = (g[i * n + j] - s) / g[j * n + j];
            }
        }
        for i in 0..n {
            for j in i + 1..n {
                g[i * n + j] = 0.0;
            }
        }
        Some(Overlap {
            size: n,
            means,
            factor: g,
        })
    }
}

impl Basis {
    /// Child `child`'s coefficients of the parent function with RGB `coefficients` (push, exact where
    /// the span is closed under the child map): `P_k · c`, into `out`.
    pub fn push_rgb(&self, domain: Domain, child: usize, coefficients: &[Rgb], out: &mut [Rgb]) {
        let size = coefficients.len();
        let p = self.push_matrix(domain, child);
        for (alpha, value) in out[..size].iter_mut().enumerate() {
            *value = p[alpha * size..(alpha + 1) * size]
                .iter()
                .zip(coefficients)
                .map(|(&m, &c)| c * m)
                .sum();
        }
    }

    /// Adds `weight · P_kᵀ · m` to `parent`: the area moments `m` of a function given on child `child`
    /// (its coefficients where the child's [`Overlap`] is the identity), as moments of the parent's
    /// basis, for a child covering the fraction `weight` of the parent's area (pull).
    pub fn pull_add_rgb(
        &self,
        domain: Domain,
        child: usize,
        weight: f64,
        coefficients: &[Rgb],
        parent: &mut [Rgb],
    ) {
        let size = coefficients.len();
        let p = self.push_matrix(domain, child);
        for (alpha, &c) in coefficients.iter().enumerate() {
            for (beta, out) in parent.iter_mut().enumerate() {
                *out += c * (weight * p[alpha * size + beta]);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{subdivide_parameters, DVec3, Shape};

    const DOMAINS: [Domain; 2] = [Domain::Square, Domain::Triangle];

    #[test]
    fn sizes_and_degrees() {
        let sizes: Vec<usize> = BasisKind::ALL.iter().map(|k| k.size()).collect();
        assert_eq!(sizes, [1, 3, 4, 6, 10]);
        let cub: Vec<usize> = BasisKind::ALL
            .iter()
            .map(|k| k.default_cubature_degree())
            .collect();
        assert_eq!(cub, [4, 6, 8, 8, 10]);
        for k in BasisKind::ALL {
            let b = Basis::new(k);
            assert_eq!((b.kind(), b.size()), (k, k.size()));
            // The highest monomial's total degree.
            let (p, q) = MONOMIALS[k.size() - 1];
            assert_eq!((p + q) as usize, k.polynomial_degree());
        }
    }

    #[test]
    fn rule_tables_hold_the_basis_at_every_rules_nodes() {
        for kind in BasisKind::ALL {
            let basis = Basis::new(kind);
            let n = basis.size();
            for domain in DOMAINS {
                for degree in 0..=crate::geometry::cubature::MAX_DEGREE + 2 {
                    let nodes = &rule(domain, degree).nodes;
                    let table = basis.rule_values(domain, degree);
                    assert_eq!(table.len(), nodes.len() * n);
                    let mut phi = [0.0; MAX_BASIS_SIZE];
                    for (&(uv, _), row) in nodes.iter().zip(table.chunks_exact(n)) {
                        basis.eval(domain, uv, &mut phi);
                        assert_eq!(row, &phi[..n], "{kind:?} {domain:?} degree {degree}");
                    }
                }
            }
        }
    }

    #[test]
    fn orthonormal_on_both_domains() {
        for kind in BasisKind::ALL {
            let basis = Basis::new(kind);
            let n = basis.size();
            for domain in DOMAINS {
                let mut gram = vec![0.0; n * n];
                let mut phi = [0.0; 10];
                for &(uv, w) in &rule(domain, 2 * kind.polynomial_degree()).nodes {
                    basis.eval(domain, uv, &mut phi);
                    assert!((phi[0] - 1.0).abs() < 1e-15, "φ_0 ≡ 1");
                    for a in 0..n {
                        for b in 0..n {
                            gram[a * n + b] += w / domain.area() * phi[a] * phi[b];
                        }
                    }
                }
                for a in 0..n {
                    for b in 0..n {
                        let e = if a == b { 1.0 } else { 0.0 };
                        assert!(
                            (gram[a * n + b] - e).abs() < 1e-12,
                            "{kind:?} {domain:?} <φ{a}, φ{b}> = {}",
                            gram[a * n + b]
                        );
                    }
                }
            }
        }
    }

    /// Largest `|f − P f|` over the nodes of `rule(domain, degree)` and over a 64² grid of the domain,
    /// `P` the basis' projection (integrated exactly enough by a degree-12 rule).
    fn node_and_true_error(
        kind: BasisKind,
        domain: Domain,
        degree: usize,
        f: fn(DVec2) -> f64,
    ) -> (f64, f64) {
        let basis = Basis::new(kind);
        let mut c = [0.0; 10];
        basis.project(domain, 12, f, &mut c);
        let error = |uv: DVec2| (f(uv) - basis.value(domain, uv, &c[..kind.size()])).abs();
        let at_nodes = rule(domain, degree)
            .nodes
            .iter()
            .map(|&(uv, _)| error(uv))
            .fold(0.0, f64::max);
        let grid = (0..=64)
            .flat_map(|i| (0..=64).map(move |j| DVec2::new(i as f64, j as f64) / 64.0))
            .filter(|uv| domain == Domain::Square || uv.x + uv.y <= 1.0)
            .map(error)
            .fold(0.0, f64::max);
        (at_nodes, grid)
    }

    /// Error control's node maximum sees the leading projection error with
    /// [`BasisKind::estimating_cubature_degree`]: for a function symmetric about the square's centre
    /// and a skewed one, every basis' largest error at the rule's nodes is at least a quarter of its
    /// largest error over the element (the leading Legendre term sampled away from its zeros: ½ for
    /// `P_2` at the 3-point rule's centre). One point per direction fewer for the constant basis (the
    /// 2×2 rule) reports a symmetric function as exact: the trap the even degrees avoid.
    #[test]
    fn the_estimating_rule_sees_the_leading_projection_error() {
        let symmetric: fn(DVec2) -> f64 =
            |uv| (uv.x - 0.5).powi(2) + (uv.y - 0.5).powi(2) + 2.0 * (uv.x - 0.5).powi(4);
        let skewed: fn(DVec2) -> f64 = |uv| (1.3 * uv.x + 2.1 * uv.y).exp();
        for kind in BasisKind::ALL {
            for f in [symmetric, skewed] {
                let degree = kind.estimating_cubature_degree();
                let (nodes, truth) = node_and_true_error(kind, Domain::Square, degree, f);
                assert!(
                    nodes >= 0.25 * truth,
                    "{kind:?}: {nodes:.3e} at the nodes of degree {degree}, {truth:.3e} in all"
                );
            }
        }
        let (nodes, truth) = node_and_true_error(BasisKind::Constant, Domain::Square, 2, |uv| {
            (uv.x - 0.5).powi(2) + (uv.y - 0.5).powi(2)
        });
        assert!(nodes < 1e-12 * truth, "{nodes} against {truth}");
    }

    #[test]
    fn square_basis_is_tensor_legendre() {
        // Gram–Schmidt in this order yields products of shifted Legendre polynomials on the square,
        // e.g. φ_3 = 12 (u - ½)(v - ½) and φ_7 = √5 (6u² - 6u + 1) · √3 (2v - 1).
        let basis = Basis::new(BasisKind::Cubic);
        let mut phi = [0.0; 10];
        let uv = DVec2::new(0.3, 0.8);
        basis.eval(Domain::Square, uv, &mut phi);
        let l1 = |x: f64| 3f64.sqrt() * (2.0 * x - 1.0);
        let l2 = |x: f64| 5f64.sqrt() * (6.0 * x * x - 6.0 * x + 1.0);
        assert!((phi[3] - l1(uv.x) * l1(uv.y)).abs() < 1e-12);
        assert!((phi[7] - l2(uv.x) * l1(uv.y)).abs() < 1e-12);
    }

    #[test]
    fn projection_reproduces_span() {
        for kind in BasisKind::ALL {
            let basis = Basis::new(kind);
            for domain in DOMAINS {
                // A polynomial in every span: a combination of the kind's monomials.
                let f = |uv: DVec2| -> f64 {
                    MONOMIALS[..kind.size()]
                        .iter()
                        .enumerate()
                        .map(|(i, (p, q))| {
                            (i as f64 - 2.5) * uv.x.powi(*p as i32) * uv.y.powi(*q as i32)
                        })
                        .sum()
                };
                let mut c = [0.0; 10];
                basis.project(domain, kind.default_cubature_degree(), f, &mut c);
                for uv in [DVec2::new(0.1, 0.2), DVec2::new(0.6, 0.3)] {
                    assert!((basis.value(domain, uv, &c) - f(uv)).abs() < 1e-12);
                }
                // Coefficient 0 is the average.
                let avg: f64 = rule(domain, 4)
                    .nodes
                    .iter()
                    .map(|(uv, w)| w * f(*uv))
                    .sum::<f64>()
                    / domain.area();
                assert!((c[0] - avg).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn child_containing_inverts_child_parameters() {
        for domain in [Domain::Square, Domain::Triangle] {
            for child in 0..4 {
                for uv in [
                    DVec2::new(0.2, 0.3),
                    DVec2::new(0.6, 0.1),
                    DVec2::new(0.1, 0.7),
                ] {
                    if domain == Domain::Triangle && uv.x + uv.y > 1.0 {
                        continue;
                    }
                    let parent = child_parameters(domain, child, uv);
                    let (found, back) = child_containing(domain, parent);
                    assert_eq!(found, child, "{domain:?} {uv}");
                    assert!((back - uv).length() < 1e-14);
                }
            }
        }
    }

    #[test]
    fn child_maps_match_subdivide() {
        for domain in DOMAINS {
            let children = subdivide_parameters(domain.corners());
            for (k, corners) in children.iter().enumerate() {
                for (corner, expected) in domain.corners().iter().zip(corners) {
                    assert!((child_parameters(domain, k, *corner) - *expected).length() < 1e-15);
                }
            }
        }
        let quad = Shape::Quad([
            DVec3::ZERO,
            DVec3::new(2.0, 0.0, 0.1),
            DVec3::new(1.5, 1.0, 0.4),
            DVec3::new(0.2, 1.3, 0.0),
        ]);
        let tri = Shape::Triangle([
            DVec3::new(0.1, 0.0, 0.0),
            DVec3::new(2.0, 0.5, 0.0),
            DVec3::new(0.3, 1.7, 0.9),
        ]);
        for shape in [quad, tri] {
            let domain = shape.domain();
            for (k, child) in shape.subdivide().iter().enumerate() {
                for &(uv, _) in &rule(domain, 5).nodes {
                    let p = shape.point_at(child_parameters(domain, k, uv));
                    assert!((p - child.point_at(uv)).length() < 1e-14, "{domain:?} {k}");
                }
            }
        }
    }

    #[test]
    fn push_reproduces_parent_on_children_and_pull_inverts_it() {
        for kind in BasisKind::ALL {
            let basis = Basis::new(kind);
            let n = basis.size();
            for domain in DOMAINS {
                let parent: Vec<f64> = (0..n).map(|a| 1.0 + 0.37 * a as f64).collect();
                let mut children = [[0.0; 10]; 4];
                for (k, child) in children.iter_mut().enumerate() {
                    basis.push(domain, k, &parent, child);
                    for &(uv, _) in &rule(domain, 5).nodes {
                        let on_parent =
                            basis.value(domain, child_parameters(domain, k, uv), &parent);
                        let on_child = basis.value(domain, uv, &child[..n]);
                        assert!(
                            (on_parent - on_child).abs() < 1e-12,
                            "{kind:?} {domain:?} child {k}: {on_parent} vs {on_child}"
                        );
                    }
                }
                let mut back = [0.0; 10];
                basis.pull(
                    domain,
                    [
                        &children[0][..n],
                        &children[1][..n],
                        &children[2][..n],
                        &children[3][..n],
                    ],
                    &mut back,
                );
                for a in 0..n {
                    assert!(
                        (back[a] - parent[a]).abs() < 1e-12,
                        "{kind:?} {domain:?} {a}: {} vs {}",
                        back[a],
                        parent[a]
                    );
                }
            }
        }
    }

    /// A trapezoid (no parallelogram: its Jacobian varies by a factor 3 across it).
    fn trapezoid() -> Shape {
        Shape::Quad([
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(3.0, 0.0, 0.0),
            DVec3::new(2.0, 1.0, 0.0),
            DVec3::new(1.0, 1.0, 0.0),
        ])
    }

    /// Area moments `(1/A) ∫ f φ_α dA` by an exact rule with the Jacobian (eq. (12)), as couplings
    /// compute them.
    fn area_moments(basis: &Basis, shape: &Shape, f: &dyn Fn(DVec2) -> f64) -> Vec<f64> {
        let n = basis.size();
        let mut out = vec![0.0; n];
        let mut phi = [0.0; 10];
        for &(uv, w) in &rule(shape.domain(), 12).nodes {
            basis.eval(shape.domain(), uv, &mut phi);
            for a in 0..n {
                out[a] += w * shape.jacobian(uv) / shape.area() * f(uv) * phi[a];
            }
        }
        out
    }

    #[test]
    fn the_overlap_solve_turns_trapezoid_moments_into_exact_coefficients() {
        // The trapezoid as given and turned into a plane of no particular orientation (the overlap
        // of a planar quad comes from its affine Jacobian, read along the plane's normal).
        let turn = glam::DMat3::from_axis_angle(DVec3::new(1.0, 2.0, 3.0).normalize(), 0.7);
        let Shape::Quad(corners) = trapezoid() else {
            unreachable!()
        };
        let turned = Shape::Quad(corners.map(|p| turn * p + DVec3::new(5.0, -2.0, 1.0)));
        for (shape, kind) in [trapezoid(), turned].into_iter().flat_map(|shape| {
            [
                BasisKind::Linear,
                BasisKind::Bilinear,
                BasisKind::Quadratic,
                BasisKind::Cubic,
            ]
            .map(|kind| (shape, kind))
        }) {
            let basis = Basis::new(kind);
            let n = basis.size();
            // A constant's moment of φ_2 (v runs from the wide side to the narrow one) is the
            // Jacobian's, not zero: read as a coefficient, it was a false gradient.
            let mut constant = area_moments(&basis, &shape, &|_| 2.0);
            assert!(
                constant[2].abs() > 0.1,
                "{kind:?}: the trapezoid shows no gradient"
            );
            let overlap = basis.overlap(&shape, shape.area()).expect("a trapezoid");
            overlap.solve(&mut constant);
            for (a, c) in constant.iter().enumerate() {
                let expected = if a == 0 { 2.0 } else { 0.0 };
                assert!((c - expected).abs() < 1e-12, "{kind:?} c{a} = {c}");
            }
            // Any function of the span is recovered, and its area average is (G c)_0.
            let coefficients: Vec<f64> = (0..n).map(|a| 1.0 - 0.3 * a as f64).collect();
            let f = |uv: DVec2| basis.value(Domain::Square, uv, &coefficients);
            let mut moments = area_moments(&basis, &shape, &f);
            let mean = moments[0];
            overlap.solve(&mut moments);
            for a in 0..n {
                assert!(
                    (moments[a] - coefficients[a]).abs() < 1e-12,
                    "{kind:?} c{a}"
                );
            }
            let rgb: Vec<Rgb> = coefficients.iter().map(|&c| Rgb::splat(c)).collect();
            assert!((overlap.mean(&rgb).r - mean).abs() < 1e-12, "{kind:?} mean");
            let mut back = vec![Rgb::BLACK; n];
            overlap.moments_rgb(&rgb, &mut back);
            let mut solved = back.clone();
            overlap.solve_rgb(&mut solved);
            for a in 0..n {
                assert!((solved[a].g - coefficients[a]).abs() < 1e-12);
            }
        }
        // Identity cases: triangles, parallelograms, the constant basis.
        let linear = Basis::new(BasisKind::Linear);
        let parallelogram = Shape::Quad([
            DVec3::ZERO,
            DVec3::new(2.0, 0.0, 0.0),
            DVec3::new(3.0, 1.0, 0.0),
            DVec3::new(1.0, 1.0, 0.0),
        ]);
        let triangle = Shape::Triangle([DVec3::ZERO, DVec3::X, DVec3::Y]);
        for shape in [parallelogram, triangle] {
            assert!(linear.overlap(&shape, shape.area()).is_none());
        }
        let constant = Basis::new(BasisKind::Constant);
        assert!(constant.overlap(&trapezoid(), trapezoid().area()).is_none());
    }

    #[test]
    fn pull_is_the_projection_of_the_piecewise_function() {
        // Children carrying different constants: the parent gets their projection, whose coefficient 0
        // is the mean of the four.
        let basis = Basis::new(BasisKind::Linear);
        for domain in DOMAINS {
            let vals = [1.0, 2.0, 4.0, 8.0];
            let mut out = [0.0; 3];
            basis.pull(domain, [&[1.0], &[2.0], &[4.0], &[8.0]], &mut out);
            assert!((out[0] - vals.iter().sum::<f64>() / 4.0).abs() < 1e-14);
        }
    }
}
