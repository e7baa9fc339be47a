//! The element hierarchy of hierarchical radiosity (Hanrahan, Salzman, Aupperle 1991): every radiating
//! side of an input polygon is a *patch* whose root element is regularly split into a quadtree (4 children,
//! quads at parameter midpoints, triangles at edge midpoints). Links between elements live at the
//! receiving element and carry the form factor of the interaction.
//!
//! An element has a vector of basis coefficients ([`Hierarchy::radiance`], constant function first:
//! see [`crate::bases`]), and every link a coupling block with one entry per pair of receiver and source
//! basis functions (Bekaert–Willems eq. (3)) plus the link error coefficients of their Algorithm 4.1.
//! Elements come in two kinds ([`ElementKind`]): a piece of one patch's surface, or a cluster
//! (Sillion–Drettakis §4): a box of other elements, with no patch, that links and push-pull treat as one
//! element whose radiance is the area-weighted average of its contents.

pub mod clusters;
mod thin_words;

use crate::bases::{Basis, BasisKind, MAX_BASIS_SIZE};
use crate::color::Rgb;
use crate::geometry::{Aabb, DVec2, DVec3, Shape};
use crate::scene::luminaire::Luminaire;
use crate::scene::Scene;
use crate::visibility::item_buffer::ItemBuffers;
use rayon::prelude::*;
use std::sync::atomic::{AtomicU8, Ordering};
use std::sync::Arc;

/// Index of an element in [`Hierarchy::elements`].
pub type ElementId = u32;

/// One radiating side of an input polygon.
#[derive(Clone, Debug)]
pub struct Patch {
    /// Index of the polygon in `Scene::polygons`.
    pub polygon: usize,
    /// Front side (true) or back side of a two-sided polygon.
    pub front: bool,
    /// Normal of this side (its shape, oriented to match, is its root element's:
    /// [`Hierarchy::patch_shape`]).
    pub normal: DVec3,
    pub reflectance: Rgb,
    pub emission: Rgb,
    pub root: ElementId,
    /// Its polygon's [`crate::scene::Polygon::under_contact`].
    pub under_contact: bool,
}

/// An interaction from `source` to the element holding the link (the receiver).
#[derive(Clone, Debug, PartialEq)]
pub struct Link {
    pub source: ElementId,
    /// The coupling block and link error coefficients (Bekaert–Willems Algorithm 4.1).
    pub coupling: LinkCoupling,
    /// The refinement oracle's radiance-independent factor for this link (its error estimate divided by
    /// ρ_i B_j), kept so that re-refinement after a solve needs no new kernel samples; `None` when the
    /// source was dark when the link was judged (or for the link error oracle, which reads `coupling`).
    pub oracle_factor: OracleFactor,
}

// Links are what a large solve is made of: 24 bytes each besides their coupling's words
// (BENCHMARKS.md, "Links in fixed point" and "Twenty-four-byte links").
#[cfg(target_pointer_width = "64")]
const _: () = assert!(std::mem::size_of::<Link>() == 24);

impl Link {
    /// Receiver-area-averaged form factor F_ij (visibility included): the constant–constant entry.
    pub fn form_factor(&self) -> f64 {
        self.coupling.form_factor()
    }
}

/// The oracle factor a link or candidate caches ([`Link::oracle_factor`]): an `Option<f64>` in 4 bytes
/// instead of 16, single precision with NaN standing for none, since every link and every refinement
/// candidate holds one. Single precision (a relative rounding of 6·10⁻⁸, saturating at `f32::MAX`)
/// moves a re-judged link's estimate by far less than the oracle's own sampling resolves, and makes a
/// [`Link`] 8 bytes smaller. A factor that is itself NaN reads as none and is recomputed, from
/// the link's own seed, to the same NaN.
#[derive(Clone, Copy, Debug)]
pub struct OracleFactor(f32);

impl OracleFactor {
    pub const NONE: Self = OracleFactor(f32::NAN);

    pub fn get(self) -> Option<f64> {
        (!self.0.is_nan()).then_some(f64::from(self.0))
    }
}

impl From<Option<f64>> for OracleFactor {
    fn from(factor: Option<f64>) -> Self {
        OracleFactor(factor.map_or(f32::NAN, |f| {
            f.clamp(-f64::from(f32::MAX), f64::from(f32::MAX)) as f32
        }))
    }
}

impl PartialEq for OracleFactor {
    fn eq(&self, other: &Self) -> bool {
        self.get() == other.get()
    }
}

/// What Algorithm 4.1 of Bekaert–Willems returns for a link i ← j, without the receiver's reflectance
/// ρ_i (applied when gathering, so one block serves all three colour channels), and divided by A_i so
/// that with the averaged-orthonormal bases of [`crate::bases`] the gathered irradiance coefficients are
/// `H_α = Σ_β block[α·b + β] L_{j,β}` and the constant–constant entry is the form factor F_ij.
///
/// Storage: one allocation of 32-bit words per link holds the block in `f32`, then the error
/// coefficients and the node factors in 16-bit fixed point, each list relative to its own largest
/// magnitude (two scales in `f32`), because links are what a large solve is made of (BENCHMARKS.md,
/// "Scale" and "Links in fixed point"). The block keeps single precision (a relative rounding of 6·10⁻⁸
/// per coefficient, far below the cubature error of the coupling itself, eq. (12) with a handful of
/// nodes): it carries the light. The error coefficients and node factors only estimate error and
/// choose what to split; a step of 1/32767 of the link's largest one (3·10⁻⁵) is far below what an
/// estimate resolves, and halves their bytes (a linear surface link with 9 receiver nodes: 192 → 128
/// bytes).
///
/// With [`ErrorStorage::Reduced`] (Bekaert–Willems §4.3) the `n × b` error coefficients are replaced by
/// `n` ratios `Σ_β L_{j,β} δ_{j,β}(x_k) / L_{j,1}` for the source radiance at coupling time, so that the
/// block is followed by `2n` values instead of `n (b + 1)`.
///
/// A coupling that is zero throughout (every node pair blocked: the link carries nothing, estimates no
/// error, and stays only so that later passes may judge it again) holds no words at all: on office3
/// more than half the links are such (BENCHMARKS.md, "Blocked links without words").
#[derive(Clone, Debug, PartialEq)]
pub struct LinkCoupling {
    /// The block (`f32` bits); [`HEADER_WORDS`]: the scales of the error coefficients and of the node
    /// factors and the visibility error (`f32` bits; here rather than beside `visibility`, so that a
    /// `Link` is 24 bytes); then the error coefficients (or their reduced form) and the node
    /// factors as `i16` steps of their scale, two per word (see the accessors). Empty where every word
    /// would be zero. Behind a thin pointer, the length in the allocation ([`thin_words`]).
    words: thin_words::ThinWords,
    /// Basis size `b` of both ends, and [`REDUCED`] where the error coefficients are stored one per
    /// node: §4.3's reduced form, or the exact `δ_{j,1}(x_k)` of a [`LinkCoupling::constant_source`]
    /// coupling.
    form: u8,
    /// Number of receiver cubature nodes `n`.
    nodes: u16,
    /// The verdict of the shaft test of the link this coupling belongs to (`None`: not tested), which
    /// the links of its sub-elements inherit when Clear or Blocked ([`crate::visibility::shaft`]).
    /// Kept here, in what would be padding, so that a [`Link`] is 24 bytes.
    pub shaft: Option<crate::visibility::shaft::ShaftVerdict>,
    /// Fraction `v` of the unoccluded transfer that the node pairs found visible (1 when nothing blocks).
    pub visibility: f32,
}

/// [`LinkCoupling::form`]'s flag for error coefficients stored one per node.
const REDUCED: u8 = 0x80;

/// Words between a coupling's block and its fixed-point values: two scales and the visibility error.
const HEADER_WORDS: usize = 3;

/// The block of a coupling without words ([`LinkCoupling`]).
static ZERO_BLOCK: [f32; MAX_BASIS_SIZE * MAX_BASIS_SIZE] = [0.0; MAX_BASIS_SIZE * MAX_BASIS_SIZE];

/// Largest magnitude of a fixed-point step count ([`LinkCoupling`]'s error coefficients and node
/// factors).
const STEPS: f32 = i16::MAX as f32;

/// The scale of `values` in fixed point (their largest finite magnitude over [`STEPS`]), and their step
/// counts (rounded; saturating, NaN to 0).
fn fixed_point(values: impl Iterator<Item = f32> + Clone) -> (f32, impl Iterator<Item = i16>) {
    let largest = values
        .clone()
        .filter(|v| v.is_finite())
        .fold(0.0f32, |m, v| m.max(v.abs()));
    let scale = largest / STEPS;
    let inverse = if scale > 0.0 { 1.0 / scale } else { 0.0 };
    (scale, values.map(move |v| round_to_i16(v * inverse)))
}

/// `x.round() as i16` (half away from zero, saturating, NaN to 0) without `roundf`, a library call on
/// the baseline x86-64 target (1% of the default solve): in `f64` adding ½ to an `f32` is exact, and
/// the cast truncates toward zero.
fn round_to_i16(x: f32) -> i16 {
    let x = f64::from(x);
    (x + 0.5f64.copysign(x)) as i16
}

impl LinkCoupling {
    /// A coupling from its `b × b` block, `n × b` error coefficients and `n` node factors (see the
    /// accessors).
    pub fn new(
        block: &[f64],
        errors: &[f32],
        node_factors: &[f32],
        visibility: f32,
        visibility_error: f32,
    ) -> Self {
        let size = (block.len() as f64).sqrt().round() as usize;
        assert!(
            size * size == block.len() && errors.len() == node_factors.len() * size,
            "a coupling block is b × b and there are b error coefficients per node"
        );
        Self::stored(
            block.iter().map(|&k| k as f32),
            errors.iter().copied(),
            node_factors.iter().copied(),
            false,
            visibility,
            visibility_error,
        )
    }

    /// A coupling whose error coefficients vary with the constant source function only
    /// (`δ_{j,β}(x_k) = 0` for β > 1, as for every link with a cluster at one end, whose source is seen
    /// as a constant): from the `n` coefficients `δ_{j,1}(x_k)`, stored one per node in the layout of
    /// the reduced form, where `δ_j(x_k) = L_{j,1} δ_{j,1}(x_k)` is then exact for any source radiance.
    /// The `n (b − 1)` zeros are not stored (BENCHMARKS.md, "Peak memory of office3 and the classroom").
    pub fn constant_source(
        block: &[f64],
        node_errors: &[f32],
        node_factors: &[f32],
        visibility: f32,
        visibility_error: f32,
    ) -> Self {
        assert_eq!(
            node_errors.len(),
            node_factors.len(),
            "one error coefficient per node"
        );
        Self::stored(
            block.iter().map(|&k| k as f32),
            node_errors.iter().copied(),
            node_factors.iter().copied(),
            true,
            visibility,
            visibility_error,
        )
    }

    /// Words of a coupling's allocation: the `b × b` block, the [`HEADER_WORDS`], and `tail` 16-bit
    /// values (error coefficients and node factors) two per word.
    fn word_count(block_len: usize, tail: usize) -> usize {
        block_len + HEADER_WORDS + tail.div_ceil(2)
    }

    /// Heap bytes of the coupling of a link whose ends have basis size `b` and whose receiver has
    /// `nodes` cubature nodes, with the error coefficients stored as `storage` says (for
    /// [`crate::memory`]'s budget).
    pub fn heap_bytes_for(size: usize, nodes: usize, storage: ErrorStorage) -> usize {
        let errors_per_node = match storage {
            ErrorStorage::Full => size,
            ErrorStorage::Reduced => 1,
        };
        allocated_bytes(
            4 * Self::allocated_words(Self::word_count(size * size, nodes * (errors_per_node + 1))),
        )
    }

    /// The single allocation of [`LinkCoupling`]: block, scales, error coefficients
    /// (`errors_per_node` per node: `b`, or 1 when `reduced`) and node factors in fixed point.
    fn stored(
        block: impl ExactSizeIterator<Item = f32>,
        errors: impl ExactSizeIterator<Item = f32> + Clone,
        node_factors: impl ExactSizeIterator<Item = f32> + Clone,
        reduced: bool,
        visibility: f32,
        visibility_error: f32,
    ) -> Self {
        let block_len = block.len();
        let size = (block_len as f64).sqrt().round() as usize;
        let nodes = node_factors.len();
        let tail_len = errors.len() + nodes;
        // Filled in place: couplings are made by the million, one allocation each.
        let mut words = thin_words::ThinWords::zeroed(Self::word_count(block_len, tail_len));
        let (error_scale, error_steps) = fixed_point(errors);
        let (factor_scale, factor_steps) = fixed_point(node_factors);
        for (w, k) in words.iter_mut().zip(block) {
            *w = k.to_bits();
        }
        words[block_len] = error_scale.to_bits();
        words[block_len + 1] = factor_scale.to_bits();
        words[block_len + 2] = visibility_error.to_bits();
        let tail: &mut [i16] = bytemuck::cast_slice_mut(&mut words[block_len + HEADER_WORDS..]);
        for (t, q) in tail.iter_mut().zip(error_steps.chain(factor_steps)) {
            *t = q;
        }
        if words.iter().all(|&w| w == 0) {
            words = thin_words::ThinWords::default();
        }
        LinkCoupling {
            words,
            form: u8::try_from(size)
                .ok()
                .filter(|&b| b < REDUCED)
                .expect("basis sizes are at most MAX_BASIS_SIZE")
                | if reduced { REDUCED } else { 0 },
            shaft: None,
            nodes: u16::try_from(nodes).expect("at most 65535 cubature nodes"),
            visibility,
        }
    }

    /// This coupling with its error coefficients in the reduced form of Bekaert–Willems §4.3: per
    /// receiver node one ratio `r_k = Σ_β L_{j,β} δ_{j,β}(x_k) / L_{j,1}` for the source's radiance
    /// coefficients `source` now, so that `δ_j(x_k) = r_k L_{j,1}` stays exact while the source keeps the
    /// shape it has (§4.3: "When this coefficient is multiplied with `L_{j,1}` the exact `δ_j(x_k)` is
    /// recovered"). Colour: the ratio is taken for the sum of the channels (one coefficient per node, as
    /// in the paper), exact for a source whose channels share one shape. A dark source (`L_{j,1} = 0`)
    /// gets the ratio of a constant one, `δ_{j,1}(x_k)`: most sources are still dark when their first
    /// links are made, and a later change of shape is what this form cannot follow (BENCHMARKS.md
    /// measures what that costs the estimate). For the constant basis both forms hold the same numbers.
    pub fn reduced(self, source: &[Rgb]) -> Self {
        if self.is_reduced() {
            return self;
        }
        let size = self.size();
        let mut grey = [0.0; MAX_BASIS_SIZE];
        for (g, c) in grey.iter_mut().zip(source) {
            *g = c.r + c.g + c.b;
        }
        let grey = &grey[..source.len()];
        // Computed twice by `stored` (its scale, then its steps) rather than collected: couplings are
        // made by the hundred thousand.
        let ratios = (0..self.node_count()).map(|k| {
            let delta = |beta: usize| self.error(k * size + beta);
            if grey[0] > 0.0 {
                let sum: f64 = grey
                    .iter()
                    .enumerate()
                    .map(|(beta, &l)| l * f64::from(delta(beta)))
                    .sum();
                (sum / grey[0]) as f32
            } else {
                delta(0)
            }
        });
        Self::stored(
            self.block().iter().copied(),
            ratios,
            self.node_factors(),
            true,
            self.visibility,
            self.visibility_error(),
        )
    }

    /// This coupling on a link whose shaft test gave `shaft`.
    pub fn with_shaft(self, shaft: Option<crate::visibility::shaft::ShaftVerdict>) -> Self {
        LinkCoupling { shaft, ..self }
    }

    /// Basis size `b` of both ends.
    fn size(&self) -> usize {
        usize::from(self.form & !REDUCED)
    }

    /// Whether the error coefficients are stored one per node.
    fn is_reduced(&self) -> bool {
        self.form & REDUCED != 0
    }

    fn block_len(&self) -> usize {
        self.size() * self.size()
    }

    /// Error coefficients per receiver node: `b`, or 1 in the reduced form.
    fn errors_per_node(&self) -> usize {
        if self.is_reduced() {
            1
        } else {
            self.size()
        }
    }

    /// Number of receiver cubature nodes `n`.
    pub fn node_count(&self) -> usize {
        usize::from(self.nodes)
    }

    /// `b × b` row-major coupling coefficients `K_{i,α;j,β} / (ρ_i A_i)` (eq. (3)).
    pub fn block(&self) -> &[f32] {
        match self.words.get(..self.block_len()) {
            Some(words) => bytemuck::cast_slice(words),
            None => &ZERO_BLOCK[..self.block_len()],
        }
    }

    /// Word `i` (0 for a coupling without words).
    fn word(&self, i: usize) -> u32 {
        self.words.get(i).copied().unwrap_or(0)
    }

    /// The fixed-point error coefficients then node factors (none without words: all zero).
    fn steps(&self) -> &[i16] {
        self.words
            .get(self.block_len() + HEADER_WORDS..)
            .map_or(&[], bytemuck::cast_slice)
    }

    /// Link error coefficient `i` of the `n × b` row-major `δ_{j,β}(x_k) / ρ_i` at the receiver's `n`
    /// cubature nodes (Algorithm 4.1 step 4b); in the reduced form ([`LinkCoupling::reduced`]), of the
    /// `n` ratios.
    fn error(&self, i: usize) -> f32 {
        self.steps()
            .get(i)
            .map_or(0.0, |&q| f32::from(q) * self.error_scale())
    }

    fn error_scale(&self) -> f32 {
        f32::from_bits(self.word(self.block_len()))
    }

    /// `n` point-to-source factors `K_{j,1}(x_k) / ρ_i` (unoccluded ∫ K(x_k, y) dA_y with visibility),
    /// which carry propagated error in eqs. (11) and (13).
    pub fn node_factors(&self) -> impl ExactSizeIterator<Item = f32> + Clone + '_ {
        let scale = f32::from_bits(self.word(self.block_len() + 1));
        let start = self.node_count() * self.errors_per_node();
        let steps = self.steps();
        (start..start + self.node_count())
            .map(move |i| steps.get(i).map_or(0.0, |&q| f32::from(q) * scale))
    }

    /// Visibility error per unit source radiance, before ρ_i: `F_unoccluded · sqrt(v (1 − v) / m)`, the
    /// standard deviation of a visibility `v` sampled with `m` source nodes (the `sqrt(v(1 − v))` form of
    /// Sillion–Drettakis Appendix A). It is the "term describing visibility error" that Bekaert–Willems
    /// §7 proposes to add to eq. (5): δ_j cannot see a partial occlusion that the node pairs sample
    /// wrongly.
    pub fn visibility_error(&self) -> f32 {
        f32::from_bits(self.word(self.block_len() + 2))
    }

    /// Replaces [`LinkCoupling::visibility_error`] (a coupling without words gets them, zero, unless
    /// the error is zero too).
    pub fn set_visibility_error(&mut self, error: f32) {
        if self.words.is_empty() {
            if error.to_bits() == 0 {
                return;
            }
            let tail = self.node_count() * (self.errors_per_node() + 1);
            self.words = thin_words::ThinWords::zeroed(Self::word_count(self.block_len(), tail));
        }
        let at = self.block_len() + 2;
        self.words[at] = error.to_bits();
    }

    /// Whether the coupling is zero throughout (it then holds no words): the link carries nothing and
    /// estimates no error.
    pub fn is_zero(&self) -> bool {
        self.words.is_empty()
    }

    /// The constant–constant entry of the block: the form factor F_ij.
    pub fn form_factor(&self) -> f64 {
        f64::from(self.block()[0])
    }

    /// `δ_j(x_k) / ρ_i = Σ_β L_{j,β} δ_{j,β}(x_k)` at receiver node `k`, for the source's radiance
    /// coefficients `source` (Bekaert–Willems §4.2).
    pub fn node_error(&self, k: usize, source: &[Rgb]) -> Rgb {
        if self.is_reduced() {
            return source[0] * f64::from(self.error(k));
        }
        let size = source.len();
        let scale = self.error_scale();
        let steps = self.steps().get(k * size..(k + 1) * size).unwrap_or(&[]);
        source
            .iter()
            .zip(steps)
            .map(|(&l, &q)| l * f64::from(f32::from(q) * scale))
            .sum()
    }

    /// Heap bytes held by this coupling, as the allocator hands them out (for memory budgets and
    /// reports).
    pub fn heap_bytes(&self) -> usize {
        allocated_bytes(Self::allocated_words(self.words.len()) * std::mem::size_of::<u32>())
    }

    /// Words a coupling with `words` words allocates: none for none, else one more for the length
    /// ([`thin_words`]).
    fn allocated_words(words: usize) -> usize {
        if words == 0 {
            0
        } else {
            words + 1
        }
    }
}

/// How links store their error coefficients (`--error-storage`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum ErrorStorage {
    /// All `n × b` coefficients `δ_{j,β}(x_k)` (Algorithm 4.1): exact for any later source radiance.
    #[default]
    Full,
    /// One ratio per receiver node (Bekaert–Willems §4.3), for the source's radiance when the link is
    /// made: `2n` values after the block instead of `n (b + 1)`.
    Reduced,
}

/// Bytes an allocation of `requested` bytes occupies: glibc's malloc adds an 8-byte header and rounds up
/// to 16 bytes, with a 32-byte minimum.
pub fn allocated_bytes(requested: usize) -> usize {
    if requested == 0 {
        0
    } else {
        (requested + 8).next_multiple_of(16).max(32)
    }
}

/// A piece of one patch's surface: a node of the patch's quadtree.
#[derive(Clone, Debug, PartialEq)]
pub struct Surface {
    pub patch: u32,
    pub shape: Shape,
}

/// A cluster (Sillion–Drettakis §4): a box of elements that exchanges light as a whole.
#[derive(Clone, Debug, PartialEq)]
pub struct Cluster {
    pub bounds: Aabb,
    /// Largest reflectance of its contents, per channel (the refinement bound's ρ_max).
    pub reflectance: Rgb,
    /// Largest emission of its contents, per channel.
    pub emission: Rgb,
    /// Its patch roots: `Hierarchy::cluster_surfaces[contents]`.
    pub contents: std::ops::Range<u32>,
    /// Its patch roots grouped by normal: projected area and push-down without a loop over every
    /// patch ([`clusters::Orientation`]).
    pub orientation: clusters::Orientation,
}

/// The two kinds of element. A cluster is boxed: surfaces are most elements (office3: 50k of them
/// against a few thousand clusters), and the larger cluster would make every element 48 bytes larger.
#[derive(Clone, Debug, PartialEq)]
pub enum ElementKind {
    Surface(Surface),
    Cluster(Box<Cluster>),
}

/// A node of the element hierarchy: a surface element or a cluster.
#[derive(Clone, Debug)]
pub struct Element {
    pub kind: ElementKind,
    /// The element this one is a child of ([`NO_PARENT`] for none; see [`Element::parent`]).
    parent: ElementId,
    /// Four regular children for a split surface, the contents for a cluster, empty for a leaf.
    pub children: Box<[ElementId]>,
    pub level: u16,
    /// Surface area (for a cluster, the total area of its contents).
    pub area: f64,
    /// Incoming links: the sources this element gathers from.
    pub links: Vec<Link>,
    /// A-posteriori error estimate of the radiance (Bekaert–Willems §4, W/(m² sr)): after the extended
    /// push-pull of algorithm 6.1, on a leaf the estimate there, on an inner element the largest below.
    pub error: f64,
    /// Link error threshold `Δ_l` of algorithm 6.1 for links into this element, in the oracle's units
    /// (radiance for the link error oracle, radiance × area for the others:
    /// `solvers::refine::RefineSettings::threshold_into`); infinite when error control is off.
    pub threshold: f64,
    /// Whether something lies over part of the element, found by rays on first need
    /// (`solvers::refine::straddles_outline`).
    pub straddles_outline: LazyVerdict,
}

/// A yes/no fact about an element that costs rays to establish: found on first need by whichever
/// thread asks, and kept. It depends on the element alone, so which thread finds it (or whether two
/// race to) changes nothing.
#[derive(Debug, Default)]
pub struct LazyVerdict(AtomicU8);

impl LazyVerdict {
    const NO: u8 = 1;
    const YES: u8 = 2;

    /// The verdict, established with `find` if it was not yet.
    pub fn get_or(&self, find: impl FnOnce() -> bool) -> bool {
        match self.0.load(Ordering::Relaxed) {
            Self::NO => false,
            Self::YES => true,
            _ => {
                let verdict = find();
                let code = if verdict { Self::YES } else { Self::NO };
                self.0.store(code, Ordering::Relaxed);
                verdict
            }
        }
    }
}

impl Clone for LazyVerdict {
    fn clone(&self) -> Self {
        LazyVerdict(AtomicU8::new(self.0.load(Ordering::Relaxed)))
    }
}

/// [`Element::parent`] of an element without one: a patch root outside clusters, the root cluster.
const NO_PARENT: ElementId = ElementId::MAX;

// Elements are a solve's second largest list after the links: 184 bytes each (an `Option` for the
// parent would make it 192; office3 holds 50k).
#[cfg(target_pointer_width = "64")]
const _: () = assert!(std::mem::size_of::<Element>() == 184);

impl Element {
    /// The element this one is a child of: the surface element it was split from, or the cluster
    /// that contains it; `None` for a patch root outside clusters and for the root cluster.
    pub fn parent(&self) -> Option<ElementId> {
        (self.parent != NO_PARENT).then_some(self.parent)
    }

    pub fn is_leaf(&self) -> bool {
        self.children.is_empty()
    }

    /// The surface this element covers; `None` for a cluster.
    pub fn surface(&self) -> Option<&Surface> {
        match &self.kind {
            ElementKind::Surface(s) => Some(s),
            ElementKind::Cluster(_) => None,
        }
    }

    /// The element's surface, for code that walks patch trees (which hold surface elements only).
    pub fn surface_of_patch_tree(&self) -> &Surface {
        self.surface()
            .expect("patch trees hold surface elements only")
    }

    /// The element's shape (see [`Element::surface_of_patch_tree`]).
    pub fn shape(&self) -> &Shape {
        &self.surface_of_patch_tree().shape
    }

    /// The element's patch (see [`Element::surface_of_patch_tree`]).
    pub fn patch(&self) -> u32 {
        self.surface_of_patch_tree().patch
    }
}

/// All patches and their element trees.
#[derive(Clone, Debug)]
pub struct Hierarchy {
    pub patches: Vec<Patch>,
    pub elements: Vec<Element>,
    /// Basis coefficients of each element's exitant radiance, RGB, `basis size` per element in element
    /// order; an element's first is the constant (its average). One list rather than one per element:
    /// office3's 50k elements saved 1.6 MB of list headers and allocator rounding.
    radiance: Vec<Rgb>,
    /// Patch index of each polygon's front and back side (`None` for the back of a one-sided polygon).
    pub polygon_patches: Vec<[Option<u32>; 2]>,
    /// The radiance basis of every element (Bekaert–Willems §2).
    pub basis: Arc<Basis>,
    /// The scene's goniometric luminaires, whose light reaches the elements by a first gather.
    pub luminaires: Vec<Luminaire>,
    /// For each polygon, the luminaire whose opening it is: such polygons have no patch (they reflect
    /// nothing, and their emission is the luminaire's), but they occlude.
    pub openings: Vec<Option<u32>>,
    /// Irradiance coefficients (divided by π, like gathered ones) from the luminaires, `basis size` per
    /// element, on leaves only; empty without luminaires ([`crate::solvers::direct`]).
    pub direct: Vec<Rgb>,
    /// Per element, `max_k |E(x_k)/π − Ê(x_k)/π|` (largest channel) over the nodes of a leaf whose
    /// direct coefficients were computed: their projection's error, part of the leaf's a-posteriori
    /// estimate ([`crate::solvers::error_estimate`]); empty without luminaires.
    pub direct_residual: Vec<f64>,
    /// The root of the cluster tree over the patch roots, when clustering is on
    /// ([`Hierarchy::add_clusters`]).
    pub root_cluster: Option<ElementId>,
    /// Patch roots in cluster-tree order: each cluster's contents are one contiguous range.
    pub cluster_surfaces: Vec<ElementId>,
    /// Per patch, the position of its root in `cluster_surfaces` (empty without clusters): whether a
    /// cluster holds a patch is then whether its contents' range holds that position
    /// ([`Hierarchy::cluster_holds_patch`]).
    pub cluster_positions: Vec<u32>,
    /// How clusters exchange light (`ClusteringKind::None` without clusters).
    pub clustering: clusters::ClusteringKind,
    /// Intra-cluster visibility (Sillion–Drettakis §6.1): item buffers of the clusters, or `None` when
    /// a cluster's contents are taken as mutually unoccluded.
    pub item_buffers: Option<Arc<ItemBuffers>>,
}

impl Hierarchy {
    /// One patch per radiating side of each polygon, each with a root element whose radiance starts at the
    /// patch's emission.
    pub fn new(scene: &Scene, basis: BasisKind) -> Self {
        let mut h = Hierarchy {
            patches: Vec::new(),
            elements: Vec::new(),
            radiance: Vec::new(),
            polygon_patches: vec![[None, None]; scene.polygons.len()],
            basis: Arc::new(Basis::new(basis)),
            luminaires: scene.luminaires.clone(),
            openings: scene.opening_luminaires(),
            direct: Vec::new(),
            direct_residual: Vec::new(),
            root_cluster: None,
            cluster_surfaces: Vec::new(),
            cluster_positions: Vec::new(),
            clustering: clusters::ClusteringKind::None,
            item_buffers: None,
        };
        // One patch and one root element per radiating side, reserved exactly: a doubling vector
        // would keep up to half its room unused for the whole solve (megabytes on office3).
        let sides: usize = scene
            .polygons
            .iter()
            .zip(&h.openings)
            .filter(|(_, opening)| opening.is_none())
            .map(|(polygon, _)| if polygon.two_sided { 2 } else { 1 })
            .sum();
        h.patches.reserve_exact(sides);
        h.elements.reserve_exact(sides);
        h.radiance.reserve_exact(sides * h.basis_size());
        for (index, polygon) in scene.polygons.iter().enumerate() {
            if h.openings[index].is_some() {
                continue;
            }
            let material = scene.material_of(polygon);
            let sides: &[bool] = if polygon.two_sided {
                &[true, false]
            } else {
                &[true]
            };
            for &front in sides {
                let shape = if front {
                    polygon.shape
                } else {
                    polygon.shape.flipped()
                };
                let patch = h.patches.len() as u32;
                let root = h.elements.len() as ElementId;
                h.radiance.push(material.emission);
                h.radiance
                    .extend(std::iter::repeat_n(Rgb::BLACK, h.basis_size() - 1));
                h.elements.push(Element {
                    kind: ElementKind::Surface(Surface { patch, shape }),
                    parent: NO_PARENT,
                    children: Box::default(),
                    level: 0,
                    area: shape.area(),
                    links: Vec::new(),
                    error: 0.0,
                    threshold: f64::INFINITY,
                    straddles_outline: LazyVerdict::default(),
                });
                h.patches.push(Patch {
                    polygon: index,
                    front,
                    normal: shape.normal(),
                    reflectance: material.reflectance,
                    emission: material.emission,
                    root,
                    under_contact: polygon.under_contact,
                });
                h.polygon_patches[index][usize::from(!front)] = Some(patch);
            }
        }
        h
    }

    /// Number of basis coefficients per element.
    pub fn basis_size(&self) -> usize {
        self.basis.size()
    }

    pub fn element(&self, id: ElementId) -> &Element {
        &self.elements[id as usize]
    }

    /// The shape of patch `patch` (its root element's: the polygon's, oriented so that its normal
    /// points out of this side; kept once, with the element, not again with the patch).
    pub fn patch_shape(&self, patch: u32) -> &Shape {
        self.element(self.patches[patch as usize].root).shape()
    }

    /// Bounds of every patch's shape (the scene without luminaire openings).
    pub fn patch_bounds(&self) -> Aabb {
        self.patches.iter().fold(Aabb::EMPTY, |b, p| {
            b.union(&self.element(p.root).shape().bounds())
        })
    }

    /// The patch of a surface element.
    pub fn patch_of(&self, id: ElementId) -> &Patch {
        &self.patches[self.elements[id as usize].patch() as usize]
    }

    /// Groups the patch roots into a tree of cluster elements (Sillion–Drettakis §4) built by `kind`,
    /// exchanging light by `transfer`; cluster radiance starts at the area-weighted average emission
    /// of the contents (`ClusteringKind::Auto` is resolved before, by the pipeline; here it builds
    /// oriented clusters). Call before any element is split; does nothing for `ClusteringKind::None`,
    /// without patches, or if clusters exist already.
    pub fn add_clusters(
        &mut self,
        kind: clusters::ClusterTreeKind,
        transfer: clusters::ClusteringKind,
    ) {
        if transfer == clusters::ClusteringKind::None
            || self.patches.is_empty()
            || self.root_cluster.is_some()
        {
            return;
        }
        self.clustering = transfer;
        let items: Vec<clusters::Item> = self
            .patches
            .iter()
            .map(|p| clusters::Item {
                bounds: self.element(p.root).shape().bounds(),
                area: self.element(p.root).area,
            })
            .collect();
        let tree = clusters::ClusterTree::build(&items, kind);
        let first = self.elements.len() as ElementId;
        let size = self.basis_size();
        self.elements.reserve_exact(tree.nodes.len());
        self.radiance.reserve_exact(tree.nodes.len() * size);
        for node in &tree.nodes {
            let id = self.elements.len() as ElementId;
            let children: Vec<ElementId> = node
                .children
                .iter()
                .map(|&c| match c {
                    clusters::Child::Item(i) => self.patches[i as usize].root,
                    clusters::Child::Node(n) => first + n,
                })
                .collect();
            let (mut reflectance, mut emission) = (Rgb::BLACK, Rgb::BLACK);
            for &c in &children {
                self.elements[c as usize].parent = id;
                let (r, e) = self.optics_of(c);
                reflectance = reflectance.channel_max(r);
                emission = emission.channel_max(e);
            }
            self.elements.push(Element {
                kind: ElementKind::Cluster(Box::new(Cluster {
                    bounds: node.bounds,
                    reflectance,
                    emission,
                    contents: 0..0,
                    orientation: clusters::Orientation::default(),
                })),
                parent: NO_PARENT,
                children: children.into_boxed_slice(),
                level: 0,
                area: node.area,
                links: Vec::new(),
                error: 0.0,
                threshold: f64::INFINITY,
                straddles_outline: LazyVerdict::default(),
            });
            self.radiance.extend(std::iter::repeat_n(Rgb::BLACK, size));
        }
        let root = self.elements.len() as ElementId - 1;
        self.root_cluster = Some(root);
        self.cluster_positions = vec![u32::MAX; self.patches.len()];
        self.order_contents(root);
        self.orient_clusters(first);
        self.pull_clusters();
    }

    /// Builds every cluster's [`clusters::Orientation`] (clusters are the elements from `first` on).
    fn orient_clusters(&mut self, first: ElementId) {
        let h = &*self;
        let orientations: Vec<clusters::Orientation> = (first as usize..h.elements.len())
            .into_par_iter()
            .map(|id| {
                let cluster = h
                    .cluster(id as ElementId)
                    .expect("clusters follow the patch roots");
                let facings: Vec<clusters::Facing> = h
                    .contents(cluster)
                    .iter()
                    .map(|&s| clusters::Facing {
                        normal: h.patch_of(s).normal,
                        area: h.element(s).area,
                        centroid: h.element(s).shape().centroid(),
                    })
                    .collect();
                clusters::Orientation::new(&facings)
            })
            .collect();
        for (e, orientation) in self.elements[first as usize..].iter_mut().zip(orientations) {
            if let ElementKind::Cluster(c) = &mut e.kind {
                c.orientation = orientation;
            }
        }
    }

    /// Lists the patch roots below `id` into `cluster_surfaces` (and their positions there) and records
    /// each cluster's range.
    fn order_contents(&mut self, id: ElementId) {
        if !self.is_cluster(id) {
            let patch = self.elements[id as usize].patch();
            self.cluster_positions[patch as usize] = self.cluster_surfaces.len() as u32;
            self.cluster_surfaces.push(id);
            return;
        }
        let start = self.cluster_surfaces.len() as u32;
        for c in self.elements[id as usize].children.clone() {
            self.order_contents(c);
        }
        let end = self.cluster_surfaces.len() as u32;
        if let ElementKind::Cluster(cluster) = &mut self.elements[id as usize].kind {
            cluster.contents = start..end;
        }
    }

    /// Cluster radiance as the area-weighted average of the children's average radiance (the pull of
    /// push-pull through clusters), bottom-up. Only the constant coefficient of a cluster is used.
    pub fn pull_clusters(&mut self) {
        let Some(root) = self.root_cluster else {
            return;
        };
        let first = self.patches.len().min(root as usize);
        // Clusters are stored after every surface element they contain and after their child clusters.
        for id in first..=root as usize {
            if !self.is_cluster(id as ElementId) {
                continue;
            }
            let e = &self.elements[id];
            let sum: Rgb = e
                .children
                .iter()
                .map(|&c| self.average_radiance(c) * self.elements[c as usize].area)
                .sum();
            let average = if e.area > 0.0 {
                sum / e.area
            } else {
                Rgb::BLACK
            };
            self.radiance_mut(id as ElementId)[0] = average;
        }
    }

    pub fn is_cluster(&self, id: ElementId) -> bool {
        matches!(self.elements[id as usize].kind, ElementKind::Cluster(_))
    }

    /// The cluster of element `id`; `None` for a surface.
    pub fn cluster(&self, id: ElementId) -> Option<&Cluster> {
        match &self.elements[id as usize].kind {
            ElementKind::Cluster(c) => Some(c.as_ref()),
            ElementKind::Surface(_) => None,
        }
    }

    /// Whether a side of `polygon` is in the contents of `cluster`, at any depth (false where `cluster`
    /// is not a cluster).
    pub fn cluster_holds_polygon(&self, cluster: ElementId, polygon: usize) -> bool {
        self.cluster(cluster).is_some_and(|c| {
            self.polygon_patches[polygon]
                .iter()
                .flatten()
                .any(|&patch| self.cluster_holds_patch(c, patch))
        })
    }

    /// Whether `patch` is in the contents of `cluster`, at any depth: a range test on the position of its
    /// root ([`Hierarchy::cluster_positions`]) rather than a walk up its root's parents, each a fetch
    /// from the element records (the final gather asks it of every surface a dim cluster's rays hit).
    pub fn cluster_holds_patch(&self, cluster: &Cluster, patch: u32) -> bool {
        self.contents_hold_patch(cluster.contents.clone(), patch)
    }

    /// Whether the range `contents` of `cluster_surfaces` (a cluster's contents) holds `patch`'s root.
    pub fn contents_hold_patch(&self, contents: std::ops::Range<u32>, patch: u32) -> bool {
        self.cluster_positions
            .get(patch as usize)
            .is_some_and(|position| contents.contains(position))
    }

    /// The patch roots inside cluster `id`.
    pub fn contents(&self, cluster: &Cluster) -> &[ElementId] {
        &self.cluster_surfaces[cluster.contents.start as usize..cluster.contents.end as usize]
    }

    /// Reflectance and emission of a surface element's patch, or a cluster's per-channel maxima.
    pub fn optics_of(&self, id: ElementId) -> (Rgb, Rgb) {
        match &self.elements[id as usize].kind {
            ElementKind::Surface(s) => {
                let p = &self.patches[s.patch as usize];
                (p.reflectance, p.emission)
            }
            ElementKind::Cluster(c) => (c.reflectance, c.emission),
        }
    }

    /// The reflectance refinement scales by: the patch's, or a cluster's largest per channel.
    pub fn reflectance_of(&self, id: ElementId) -> Rgb {
        self.optics_of(id).0
    }

    /// Bounds of a surface element's shape or of a cluster.
    pub fn bounds_of(&self, id: ElementId) -> Aabb {
        match &self.elements[id as usize].kind {
            ElementKind::Surface(s) => s.shape.bounds(),
            ElementKind::Cluster(c) => c.bounds,
        }
    }

    /// Centroid of a surface element, centre of a cluster's bounds.
    pub fn center_of(&self, id: ElementId) -> DVec3 {
        match &self.elements[id as usize].kind {
            ElementKind::Surface(s) => s.shape.centroid(),
            ElementKind::Cluster(c) => c.bounds.center(),
        }
    }

    /// The children refinement links to when it splits `id`: a cluster's contents, or a surface's four
    /// regular children (created on first use).
    pub fn split(&mut self, id: ElementId) -> Vec<ElementId> {
        if self.is_cluster(id) {
            self.elements[id as usize].children.to_vec()
        } else {
            self.subdivide(id).to_vec()
        }
    }

    /// Room for `leaves` more surface splits (four children each) in the element list, reserved
    /// exactly: the list then grows by what a round of splits needs instead of doubling past it (at
    /// office3's 40k elements, a doubling can leave megabytes unused).
    pub fn reserve_splits(&mut self, leaves: usize) {
        self.elements.reserve_exact(4 * leaves);
        self.radiance.reserve_exact(4 * leaves * self.basis_size());
    }

    /// Basis coefficients of element `id`'s exitant radiance, RGB; the first is the constant (the
    /// element's average).
    pub fn radiance(&self, id: ElementId) -> &[Rgb] {
        let size = self.basis_size();
        &self.radiance[id as usize * size..(id as usize + 1) * size]
    }

    /// [`Hierarchy::radiance`], to write.
    pub fn radiance_mut(&mut self, id: ElementId) -> &mut [Rgb] {
        let size = self.basis_size();
        &mut self.radiance[id as usize * size..(id as usize + 1) * size]
    }

    /// Every element's radiance coefficients, `basis size` per element in element order (to compare
    /// two solutions whole).
    pub fn radiance_coefficients(&self) -> &[Rgb] {
        &self.radiance
    }

    /// Average exitant radiance over element `id` (the constant coefficient).
    pub fn average_radiance(&self, id: ElementId) -> Rgb {
        self.radiance[id as usize * self.basis_size()]
    }

    /// Splits a surface leaf into its four regular children (returning the existing children if it is
    /// already split). Children inherit the parent's radiance, pushed through the basis's two-scale
    /// relation so that the piecewise function is unchanged.
    pub fn subdivide(&mut self, id: ElementId) -> [ElementId; 4] {
        let parent = &self.elements[id as usize];
        if let [a, b, c, d] = parent.children[..] {
            return [a, b, c, d];
        }
        let surface = parent.surface_of_patch_tree().clone();
        let (level, error, threshold) = (parent.level + 1, parent.error, parent.threshold);
        let domain = surface.shape.domain();
        let first = self.elements.len() as ElementId;
        for (k, shape) in surface.shape.subdivide().into_iter().enumerate() {
            let mut radiance = [Rgb::BLACK; crate::bases::MAX_BASIS_SIZE];
            let radiance = &mut radiance[..self.basis_size()];
            self.basis.push_rgb(domain, k, self.radiance(id), radiance);
            self.radiance.extend_from_slice(radiance);
            self.elements.push(Element {
                kind: ElementKind::Surface(Surface {
                    patch: surface.patch,
                    shape,
                }),
                parent: id,
                children: Box::default(),
                level,
                area: shape.area(),
                links: Vec::new(),
                error,
                threshold,
                straddles_outline: LazyVerdict::default(),
            });
        }
        let children = [first, first + 1, first + 2, first + 3];
        self.elements[id as usize].children = Box::new(children);
        children
    }

    /// The tops of the element trees: the root cluster, or every patch root without clusters.
    pub fn roots(&self) -> Vec<ElementId> {
        match self.root_cluster {
            Some(root) => vec![root],
            None => self.patches.iter().map(|p| p.root).collect(),
        }
    }

    /// Ids of all leaf elements, patch by patch in tree order.
    pub fn leaves(&self) -> Vec<ElementId> {
        let mut out = Vec::new();
        for patch in &self.patches {
            self.collect_leaves(patch.root, &mut out);
        }
        out
    }

    /// Leaves below (and including) `id`, in tree order.
    pub fn collect_leaves(&self, id: ElementId, out: &mut Vec<ElementId>) {
        let mut stack = vec![id];
        while let Some(e) = stack.pop() {
            let children = &self.elements[e as usize].children;
            if children.is_empty() {
                out.push(e);
            } else {
                stack.extend(children.iter().rev());
            }
        }
    }

    /// `root` and every element below it, in pre-order (an element, then its children's subtrees in
    /// order): the order in which push-pull visits a patch's tree.
    pub fn subtree(&self, root: ElementId) -> Vec<ElementId> {
        let mut order = Vec::new();
        let mut stack = vec![root];
        while let Some(id) = stack.pop() {
            order.push(id);
            stack.extend(self.element(id).children.iter().rev());
        }
        order
    }

    /// The luminaire whose opening `polygon` is, if any.
    pub fn opening_at(&self, polygon: usize) -> Option<&Luminaire> {
        let k = (*self.openings.get(polygon)?)?;
        self.luminaires.get(k as usize)
    }

    /// The patch seen by a ray hitting `polygon` on its front (`front = true`) or back side; `None` for the
    /// back of a one-sided polygon (an opaque black surface) and for a luminaire's opening.
    pub fn patch_for_side(&self, polygon: usize, front: bool) -> Option<u32> {
        self.polygon_patches[polygon][usize::from(!front)]
    }

    /// `p` moved along the normal of `patch` onto its plane, so that parameter inversion sees an
    /// in-plane point (a ray's hit, a probe's point, off the plane by rounding).
    pub fn onto_patch_plane(&self, patch: u32, p: DVec3) -> DVec3 {
        let normal = self.patches[patch as usize].normal;
        let corner = self.patch_shape(patch).vertices()[0];
        p - normal * normal.dot(p - corner)
    }

    /// The leaf element of `patch` containing the world point `p` (which lies on the patch): its
    /// parameters on the root, then one child per level by the two-scale map of the parameters
    /// ([`crate::bases::child_containing`]), with no geometry below the root.
    pub fn locate(&self, patch: u32, p: DVec3) -> ElementId {
        self.locate_with_parameters(patch, p).0
    }

    /// [`Hierarchy::locate`], with `p`'s parameters on the leaf: the children's parameter maps are
    /// the restrictions of the parent's (exactly, for triangles and bilinear quads alike), so the
    /// descent carries them down and a renderer need not invert the leaf's bilinear map again.
    pub fn locate_with_parameters(&self, patch: u32, p: DVec3) -> (ElementId, DVec2) {
        let mut id = self.patches[patch as usize].root;
        let shape = self.elements[id as usize].shape();
        let domain = shape.domain();
        let mut uv = domain.clamp(shape.parameters_of(p));
        while let [_, ..] = self.elements[id as usize].children[..] {
            let (child, child_uv) = crate::bases::child_containing(domain, uv);
            id = self.elements[id as usize].children[child];
            uv = child_uv;
        }
        (id, uv)
    }

    /// The radiance leaving surface element `id` at `p` as outputs report it (images, probes, lux
    /// grids, exported models; the viewer page clamps per pixel what it interpolates):
    /// [`radiance_at`](Self::radiance_at) with each channel clamped at zero. A linear or higher expansion undershoots beside steep gradients (1–3% of probe points in dark
    /// corners read below zero, down to −0.7 W/(m² sr) inside examp1's fixture, whose reference is 0),
    /// and no radiance is negative; solver and error estimates keep the expansion itself.
    pub fn exitant_radiance_at(&self, id: ElementId, p: DVec3) -> Rgb {
        self.radiance_at(id, p).map(|c| c.max(0.0))
    }

    /// [`Hierarchy::exitant_radiance_at`] at parameters `uv` of the element (from
    /// [`Hierarchy::locate_with_parameters`]).
    pub fn exitant_radiance_at_parameters(&self, id: ElementId, uv: DVec2) -> Rgb {
        self.radiance_at_parameters(id, uv).map(|c| c.max(0.0))
    }

    /// Exitant radiance of surface element `id` at the point `p` on it: its basis expansion evaluated
    /// at the point's parameters (clamped into the element).
    pub fn radiance_at(&self, id: ElementId, p: DVec3) -> Rgb {
        let shape = self.element(id).shape();
        self.radiance_at_parameters(id, shape.parameters_of(p))
    }

    /// Exitant radiance of surface element `id` at parameters `uv` of its shape (clamped into the
    /// domain): the basis expansion, without inverting the parametrisation.
    pub fn radiance_at_parameters(&self, id: ElementId, uv: DVec2) -> Rgb {
        let e = self.element(id);
        let domain = e.shape().domain();
        let uv = domain.clamp(uv);
        let mut phi = [0.0; crate::bases::MAX_BASIS_SIZE];
        let phi = &mut phi[..self.basis_size()];
        self.basis.eval(domain, uv, phi);
        self.radiance(id)
            .iter()
            .zip(phi.iter())
            .map(|(&c, &f)| c * f)
            .sum()
    }

    /// Exitant radiance of surface element `id` at its shape's corner `k` (the order of
    /// [`Domain::corners`](crate::geometry::Domain::corners) and of the shape's vertices): the basis
    /// expansion from the basis' stored corner values.
    pub fn radiance_at_corner(&self, id: ElementId, k: usize) -> Rgb {
        let domain = self.element(id).shape().domain();
        self.radiance(id)
            .iter()
            .zip(self.basis.corner_values(domain, k))
            .map(|(&c, &f)| c * f)
            .sum()
    }

    /// Sum of the patch areas: the total surface area A_T (a two-sided polygon counts twice).
    pub fn total_area(&self) -> f64 {
        self.patches.iter().map(|p| self.element(p.root).area).sum()
    }

    /// Σ A·max(E) over patches, plus Φ/π (the same radiance × area) of each luminaire: the scale
    /// relative refinement thresholds are given in.
    pub fn total_emission(&self) -> f64 {
        let surfaces: f64 = self
            .patches
            .iter()
            .map(|p| p.emission.max_channel() * self.element(p.root).area)
            .sum();
        let luminaires: f64 = self
            .luminaires
            .iter()
            .map(|l| l.power().max_channel() / std::f64::consts::PI)
            .sum();
        surfaces + luminaires
    }

    /// The luminaires' irradiance coefficients at leaf `id` (empty when there are none).
    pub fn direct_at(&self, id: ElementId) -> &[Rgb] {
        let size = self.basis_size();
        self.direct
            .get(id as usize * size..(id as usize + 1) * size)
            .unwrap_or(&[])
    }

    /// Frees the growth slack of every element's link list: lists grow by doubling as links arrive,
    /// and keep their capacity when a later pass takes the links out to judge them again.
    pub fn shrink_link_lists(&mut self) {
        for e in &mut self.elements {
            e.links.shrink_to_fit();
        }
    }

    pub fn link_count(&self) -> usize {
        self.elements.iter().map(|e| e.links.len()).sum()
    }

    /// Drops what only refinement and the sweeps read: every element's links with their couplings,
    /// and the item buffers' cache. For a solution that is final and will only be looked at (an
    /// image, an export): office3 holds about 50 MB of them, which the image and the vertex values
    /// then reuse instead of adding to the peak (BENCHMARKS.md, "The solver's state released before
    /// the render"). Counts of links ([`Hierarchy::link_count`]) are 0 afterwards.
    pub fn release_solver_state(&mut self) {
        for element in &mut self.elements {
            element.links = Vec::new();
        }
        self.item_buffers = None;
        crate::memory::return_free_pages();
    }

    /// Bytes held by elements, coefficients and links, as the allocator hands them out (the part of
    /// `--max-memory` that refinement fills, [`crate::memory`]).
    pub fn memory_bytes(&self) -> usize {
        self.elements.capacity() * std::mem::size_of::<Element>()
            + self.radiance.capacity() * std::mem::size_of::<Rgb>()
            + self.direct.capacity() * std::mem::size_of::<Rgb>()
            + self.direct_residual.capacity() * std::mem::size_of::<f64>()
            + self
                .elements
                .iter()
                .map(|e| {
                    let cluster = match e.kind {
                        ElementKind::Cluster(_) => allocated_bytes(std::mem::size_of::<Cluster>()),
                        ElementKind::Surface(_) => 0,
                    };
                    cluster
                        + allocated_bytes(e.children.len() * 4)
                        + e.links.capacity() * std::mem::size_of::<Link>()
                        + e.links
                            .iter()
                            .map(|l| l.coupling.heap_bytes())
                            .sum::<usize>()
                })
                .sum::<usize>()
    }

    /// Leaf surface elements (clusters always have children).
    pub fn leaf_count(&self) -> usize {
        self.elements.iter().filter(|e| e.is_leaf()).count()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_to_i16_is_round_then_cast() {
        let mut cases = vec![
            0.0f32,
            -0.0,
            0.5,
            -0.5,
            1.5,
            -2.5,
            0.499_999_97,
            -0.499_999_97,
            32_766.5,
            32_767.49,
            -32_768.5,
            1e9,
            -1e9,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
        ];
        let mut bits = 0x3f80_0001u32;
        for _ in 0..100_000 {
            bits = bits.wrapping_mul(747_796_405).wrapping_add(2_891_336_453);
            let x = f32::from_bits(bits);
            if x.is_finite() && x.abs() < 70_000.0 {
                cases.push(x);
            }
            cases.push((bits % 131_072) as f32 * 0.5 - 32_768.0);
        }
        for x in cases {
            assert_eq!(round_to_i16(x), x.round() as i16, "{x}");
        }
    }

    /// A linear-basis coupling (b = 3) with `n` nodes and made-up coefficients.
    fn linear_coupling(n: usize) -> LinkCoupling {
        let block: Vec<f64> = (0..9).map(|i| 0.01 * (i as f64 + 1.0)).collect();
        let errors: Vec<f32> = (0..3 * n)
            .map(|i| ((i * 7 % 11) as f32 - 5.0) * 1e-3)
            .collect();
        let factors: Vec<f32> = (0..n).map(|k| 0.1 + 0.01 * k as f32).collect();
        LinkCoupling::new(&block, &errors, &factors, 0.5, 0.01)
    }

    /// The fixed-point error coefficients and node factors come back within half a step (1/65534) of
    /// their list's largest magnitude, whatever their range (here ten decades and both signs), the
    /// largest one exactly; the block stays the `f32` of its value.
    #[test]
    fn couplings_keep_errors_and_factors_to_half_a_step() {
        let n = 9;
        let block: Vec<f64> = (0..9).map(|i| 1e-7 * (i as f64 + 1.0)).collect();
        let errors: Vec<f32> = (0..3 * n)
            .map(|i| (-1.0f32).powi(i as i32) * 10f32.powi(-(i as i32 % 11)) * 3e-2)
            .collect();
        let factors: Vec<f32> = (0..n).map(|k| 0.5 * 0.3f32.powi(k as i32)).collect();
        let c = LinkCoupling::new(&block, &errors, &factors, 0.5, 0.01);
        assert!(c.block().iter().zip(&block).all(|(&a, &b)| a == b as f32));
        let half_step =
            |list: &[f32]| list.iter().fold(0.0f32, |m, v| m.max(v.abs())) * 0.5 / STEPS;
        for (i, &e) in errors.iter().enumerate() {
            assert!(
                (c.error(i) - e).abs() <= half_step(&errors) * 1.0001,
                "error {i}"
            );
        }
        for (k, (f, &expected)) in c.node_factors().zip(&factors).enumerate() {
            assert!(
                (f - expected).abs() <= half_step(&factors) * 1.0001,
                "factor {k}"
            );
        }
        assert_eq!(c.error(0), errors[0]);
        assert_eq!(c.node_factors().next(), Some(factors[0]));
        assert_eq!(
            c.heap_bytes(),
            LinkCoupling::heap_bytes_for(3, n, ErrorStorage::Full)
        );
        // The visibility error lives among the words, beside the scales, and leaves them alone.
        assert_eq!(c.visibility_error(), 0.01);
        let mut changed = c.clone();
        changed.set_visibility_error(0.25);
        assert_eq!(changed.visibility_error(), 0.25);
        assert!(changed.node_factors().eq(c.node_factors()));
        assert!((0..3 * n).all(|i| changed.error(i) == c.error(i)));
    }

    /// A coupling that is zero throughout (every node pair blocked) allocates nothing and reads as the
    /// zero coupling it is, in both error storages; a visibility error set on it gives it its words,
    /// and only that value is then non-zero.
    #[test]
    fn blocked_couplings_hold_no_words() {
        let n = 9;
        let zero = LinkCoupling::new(&[0.0; 9], &[0.0; 27], &[0.0; 9], 0.0, 0.0);
        assert!(zero.is_zero() && zero.heap_bytes() == 0);
        assert_eq!(zero.block(), &[0.0; 9]);
        assert_eq!(zero.form_factor(), 0.0);
        assert!((0..3 * n).all(|i| zero.error(i) == 0.0));
        assert!(zero.node_factors().len() == n && zero.node_factors().all(|f| f == 0.0));
        let source = [Rgb::WHITE, Rgb::WHITE, Rgb::WHITE];
        assert!((0..n).all(|k| zero.node_error(k, &source) == Rgb::BLACK));
        assert_eq!(zero.visibility_error(), 0.0);
        let reduced = zero.clone().reduced(&source);
        assert!(reduced.is_zero() && (0..n).all(|k| reduced.node_error(k, &source) == Rgb::BLACK));
        let mut seen = zero.clone();
        seen.set_visibility_error(0.0);
        assert!(seen.is_zero());
        seen.set_visibility_error(0.125);
        assert!(!seen.is_zero());
        assert_eq!(seen.visibility_error(), 0.125);
        assert_eq!(seen.block(), zero.block());
        assert!(seen.node_factors().eq(zero.node_factors()));
        assert!((0..3 * n).all(|i| seen.error(i) == 0.0));
        assert_eq!(
            seen.heap_bytes(),
            LinkCoupling::heap_bytes_for(3, n, ErrorStorage::Full)
        );
        // One non-zero value anywhere keeps the words.
        let mut factors = [0.0; 9];
        factors[4] = 1e-3;
        assert!(!LinkCoupling::new(&[0.0; 9], &[0.0; 27], &factors, 0.0, 0.0).is_zero());
    }

    /// §4.3: "When this coefficient is multiplied with `L_{j,1}` the exact `δ_j(x_k)` is recovered",
    /// for the source radiance the ratio was taken with (channels of one shape), to f32 rounding; the
    /// block and node factors are untouched and the error storage shrinks from `n (b + 1)` to `2n`.
    #[test]
    fn reduced_errors_recover_delta_for_the_source_they_were_made_with() {
        let n = 16;
        let full = linear_coupling(n);
        let source = [
            Rgb::new(2.0, 1.0, 0.5),
            Rgb::new(0.4, 0.2, 0.1),
            Rgb::new(-0.6, -0.3, -0.15),
        ];
        let reduced = full.clone().reduced(&source);
        assert_eq!(reduced.node_count(), n);
        assert_eq!(reduced.block(), full.block());
        assert!(reduced.node_factors().eq(full.node_factors()));
        // Block, header, and n ratios and n factors two per word.
        assert_eq!(reduced.words.len(), 9 + HEADER_WORDS + n);
        // The ratios are stored in fixed point: within half a step of the largest one, per channel
        // times that channel's L_{j,1}.
        let largest = (0..n)
            .map(|k| full.node_error(k, &source).g.abs())
            .fold(0.0, f64::max);
        for k in 0..n {
            let (a, b) = (full.node_error(k, &source), reduced.node_error(k, &source));
            for (x, y) in [(a.r, b.r), (a.g, b.g), (a.b, b.b)] {
                assert!(
                    (x - y).abs() <= 2.0 * largest * (0.5 / f64::from(STEPS) + 1e-7),
                    "node {k}: {x} vs {y}"
                );
            }
        }
        // A dark source gets the constant source's ratio, δ_{j,1}(x_k): exact once it lights up evenly.
        let dark = full.clone().reduced(&[Rgb::BLACK; 3]);
        let even = [Rgb::splat(1.5), Rgb::BLACK, Rgb::BLACK];
        for k in 0..n {
            let (a, b) = (full.node_error(k, &even), dark.node_error(k, &even));
            assert!((a.g - b.g).abs() <= 1e-6 * (1.0 + a.g.abs()), "node {k}");
        }
    }

    /// A cluster link's coupling ([`LinkCoupling::constant_source`]) gives every source radiance the
    /// node errors of the full form whose `δ_{j,β}` vanish for β > 1, exactly, in fewer values.
    #[test]
    fn constant_source_couplings_keep_the_full_node_errors() {
        let n = 16;
        let block: Vec<f64> = (0..9).map(|i| 0.01 * (i as f64 + 1.0)).collect();
        let deltas: Vec<f32> = (0..n).map(|k| (k as f32 - 7.5) * 1e-3).collect();
        let full_errors: Vec<f32> = deltas.iter().flat_map(|&d| [d, 0.0, 0.0]).collect();
        let factors = vec![0.1f32; n];
        let full = LinkCoupling::new(&block, &full_errors, &factors, 0.5, 0.01);
        let compact = LinkCoupling::constant_source(&block, &deltas, &factors, 0.5, 0.01);
        assert_eq!(compact.node_count(), n);
        assert_eq!(compact.block(), full.block());
        assert!(compact.node_factors().eq(full.node_factors()));
        assert_eq!(compact.words.len(), 9 + HEADER_WORDS + n);
        let source = [
            Rgb::new(2.0, 1.0, 0.5),
            Rgb::new(-0.4, 0.2, 0.1),
            Rgb::new(0.6, -0.3, 0.15),
        ];
        for k in 0..n {
            assert_eq!(compact.node_error(k, &source), full.node_error(k, &source));
        }
        assert_eq!(compact.clone().reduced(&source), compact);
    }

    /// For the constant basis the reduced form holds the same numbers.
    #[test]
    fn constant_basis_couplings_are_already_reduced() {
        let full = LinkCoupling::new(&[0.2], &[0.01, -0.02, 0.03, 0.0], &[0.1; 4], 1.0, 0.0);
        let reduced = full.clone().reduced(&[Rgb::splat(0.7)]);
        assert_eq!(reduced.words, full.words);
    }

    /// The range test of [`Hierarchy::cluster_holds_patch`] says what the tree says: a cluster holds a
    /// patch exactly when it is an ancestor of the patch's root, for every cluster, patch and kind of
    /// cluster tree (a furnished hall, whose trees are several levels deep).
    #[test]
    fn clusters_hold_exactly_the_patches_below_them() {
        let scene = crate::scene::generators::BoxHall::with_polygons(200).scene();
        for kind in [
            clusters::ClusterTreeKind::Grid,
            clusters::ClusterTreeKind::Kdtree,
            clusters::ClusterTreeKind::Octree,
        ] {
            let mut h = Hierarchy::new(&scene, BasisKind::Constant);
            h.add_clusters(kind, clusters::ClusteringKind::Oriented);
            let root = h.root_cluster.expect("a cluster tree");
            let ancestors = |patch: usize| {
                let mut chain = Vec::new();
                let mut id = h.patches[patch].root;
                while let Some(parent) = h.elements[id as usize].parent() {
                    chain.push(parent);
                    id = parent;
                }
                chain
            };
            let (mut held, mut depth) = (0, 0);
            for patch in 0..h.patches.len() {
                let chain = ancestors(patch);
                depth = depth.max(chain.len());
                for id in 0..=root {
                    let Some(cluster) = h.cluster(id) else {
                        continue;
                    };
                    let holds = h.cluster_holds_patch(cluster, patch as u32);
                    assert_eq!(
                        holds,
                        chain.contains(&id),
                        "{kind:?}: cluster {id}, patch {patch}"
                    );
                    held += usize::from(holds);
                }
            }
            assert!(
                depth >= 3,
                "{kind:?}: a tree of {depth} levels tests little"
            );
            assert!(held >= h.patches.len() * depth / 2);
        }
    }

    /// An expansion that undershoots (mean 0.25, a steep first-order term) reads its own values in the
    /// solver's `radiance_at` and zero where they are negative in what outputs report.
    #[test]
    fn outputs_never_report_negative_radiance() {
        let scene = crate::scene::generators::parallel_plates(1.0, 1.0, 0.5, 1.0);
        let mut h = Hierarchy::new(&scene, BasisKind::Linear);
        let root = h.patches[0].root;
        h.radiance_mut(root)
            .copy_from_slice(&[Rgb::splat(0.25), Rgb::splat(0.5), Rgb::BLACK]);
        let mut negative = 0;
        for k in 0..=10 {
            for l in 0..=10 {
                let p = DVec3::new(k as f64 / 10.0, l as f64 / 10.0, 0.0);
                let expansion = h.radiance_at(root, p);
                negative += usize::from(expansion.g < 0.0);
                assert_eq!(
                    h.exitant_radiance_at(root, p),
                    expansion.map(|c| c.max(0.0))
                );
            }
        }
        assert!(
            negative > 0,
            "the expansion never undershoots: nothing tested"
        );
    }
}
