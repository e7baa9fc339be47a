//! Ray-cast rendering of a radiosity solution: each camera ray finds the visible surface point, and the
//! image holds the solution's exitant radiance there (linear, so that it can be compared with a reference
//! renderer pixel by pixel). Flat shading shows the leaf elements' constant radiance, smooth shading the
//! vertex interpolation of [`VertexRadiosity`]; the mesh overlay draws the leaf edges. A final gather
//! corrects the shading where the solution misplaced its light within elements, at cached records
//! ([`IrradianceCache`]) or at every sample.

use super::camera::Camera;
use super::image::Image;
use super::mesh_values::{LeafCorrections, VertexRadiosity};
use crate::color::Rgb;
use crate::geometry::{DVec2, DVec3, Shape};
use crate::hierarchy::{ElementId, Hierarchy};
use crate::measures::fbem::Mask;
use crate::measures::illuminance::{GatherSettings, IrradianceGather};
use crate::measures::irradiance_cache::{CacheSettings, Candidate, IrradianceCache, Placement};
use crate::parallel::Uneven;
use crate::visibility::Visibility;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;
use rayon::prelude::*;

/// How the radiance of the visible leaf element is shown.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum Shading {
    /// The leaf's constant radiance: exactly the computed solution.
    #[default]
    Flat,
    /// Vertex-averaged radiance interpolated over each leaf (RenderPark's Gouraud look), crack free.
    Smooth,
    /// The leaf's basis expansion evaluated at the point (Bekaert–Willems §2): exactly the computed
    /// solution, smooth within elements for non-constant bases.
    Basis,
    /// The basis expansion with its jumps at element edges removed and each element's mean kept:
    /// continuous across edges for linear and bilinear bases, no steps between leaves of different
    /// sizes, except along contact outlines.
    ///
    /// Computed by [`VertexRadiosity::evaluate_continuous`].
    Continuous,
    /// The basis expansion with its small jumps at element edges removed, the large ones kept: no
    /// banding where the light is smooth, no smearing of a steep change the solution resolved (a
    /// lamp's outline, a shadow's edge).
    ///
    /// The step between small and large is [`SEAMLESS_STEP`].
    Seamless,
}

/// The relative luminance step between a leaf's value at a vertex and the farthest of the other
/// leaves' values there (relative to the larger) below which [`Shading::Seamless`] removes the leaf's
/// step wholly; it keeps steps of twice this or more, and removes a share in between: neighbours
/// within a factor 1.33 of each other are joined, a factor 2 or more apart kept. Why 25%: the
/// elements of a dim face lit in its near field (the Cornell box's short block) read as blocks when
/// only steps under 5% or 10% go; a lamp's outline steps by far more. With each element's mean kept,
/// the image error is that of 5% or better (Cornell box 1.88%, cube.mgf 3.42%, around cube.mgf's
/// lamp 6.22%, the corridor 2.01%, office3 0.27%; at 5%: 1.89, 3.38, 6.33, 2.10, 0.27%), while
/// removing every step (as [`Shading::Continuous`] does) spreads the steep light at cube.mgf's lamp
/// over its neighbours (12% there; BENCHMARKS.md, "Seamless shading at 25%").
pub const SEAMLESS_STEP: f64 = 0.25;

impl Shading {
    /// Whether this shading reads radiance averaged to the leaves' vertices ([`VertexRadiosity`]).
    pub fn needs_vertices(self) -> bool {
        matches!(
            self,
            Shading::Smooth | Shading::Continuous | Shading::Seamless
        )
    }

    /// For the shadings that remove steps at element edges, the relative step below which they do
    /// ([`VertexRadiosity::evaluate_continuous`]): every step for `continuous`.
    pub fn steps_removed_below(self) -> Option<f64> {
        match self {
            Shading::Continuous => Some(f64::INFINITY),
            Shading::Seamless => Some(SEAMLESS_STEP),
            _ => None,
        }
    }
}

/// Where a pixel takes its `samples_per_pixel` stratified samples.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum Antialias {
    /// In every pixel: the box filter's unbiased estimate everywhere.
    #[default]
    Stratified,
    /// Only in pixels whose four corners (one ray each, shared with the neighbours) differ by more than
    /// 5% (`ADAPTIVE_CONTRAST`); elsewhere the corners' mean, the box filter of a smooth field to
    /// second order in the pixel size (Mitchell 1987's adaptive supersampling with a contrast test).
    /// A ray and a half a pixel on the Cornell box at 4 samples; a feature smaller than a pixel that
    /// no corner sees is missed. With the mesh overlay (lines a pixel wide between the corners) every
    /// pixel is sampled.
    Adaptive,
}

/// Largest relative difference between a pixel's corners (per channel, of the brightest) that
/// [`Antialias::Adaptive`] averages instead of sampling the pixel. A step that faint is drawn without
/// antialiasing (its jaggies are below what the eye sees at that contrast), and a pixel it crosses is
/// off by at most half of it, as often up as down along the step. On the Cornell box at 256² and 16
/// samples the error against the reference is the same at 2%, 5% and 10% (1.99%, 1.99%, 2.00%;
/// stratified 1.99%), while 75%, 27% and 13% of the pixels are sampled (BENCHMARKS.md, "The default
/// Cornell command under half a second").
pub const ADAPTIVE_CONTRAST: f64 = 0.05;
/// Pixel rows per band of adaptive antialiasing: the corners held at once are `(width + 1) ×
/// (ADAPTIVE_BAND + 1)` radiances instead of a second image (a 4096² render: 6 MB instead of 400 MB).
const ADAPTIVE_BAND: usize = 64;

/// What the image shows.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum Quantity {
    /// Exitant radiance.
    #[default]
    Radiance,
    /// The leaf's a-posteriori error estimate (Bekaert–Willems §4), W/(m² sr), in every channel.
    ErrorEstimate,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderOptions {
    pub shading: Shading,
    pub quantity: Quantity,
    /// Draw the leaf elements' edges on top.
    pub mesh: bool,
    /// 1: the pixel centre only. n > 1: n stratified, jittered samples inside the pixel, averaged.
    pub samples_per_pixel: u32,
    /// Which pixels take the `samples_per_pixel` samples (with more than one).
    pub antialias: Antialias,
    /// Seed of the jitter (the image depends only on it, never on the thread count).
    pub seed: u64,
    /// Colour of the mesh lines (linear radiance).
    pub mesh_colour: Rgb,
    /// A final gather of the solution ([`IrradianceGather::radiance_at`]: `L_e + ρ E / π` with the
    /// irradiance gathered at the point, as `probe --final-gather` gives): what the solution's
    /// radiance field implies at a point, at 1–30 ms a gather on 2 cores (BENCHMARKS.md, "A final
    /// gather at probed points"). `None`: the shading's value.
    pub final_gather: Option<GatherSettings>,
    /// With `final_gather`: gather at records placed where the camera looks and add the gather's
    /// correction to the shading, interpolated between them, to each sample ([`IrradianceCache`]);
    /// `None`: gather at every sample instead of shading it.
    pub gather_cache: Option<CacheSettings>,
}

impl Default for RenderOptions {
    fn default() -> Self {
        RenderOptions {
            shading: Shading::Flat,
            quantity: Quantity::Radiance,
            mesh: false,
            samples_per_pixel: 1,
            antialias: Antialias::Stratified,
            seed: 0,
            mesh_colour: Rgb::BLACK,
            final_gather: None,
            gather_cache: None,
        }
    }
}

/// Mesh lines are drawn where the hit point is closer to a leaf edge than this many pixel footprints; both
/// leaves beside an edge draw their half, so the line is about one pixel wide.
const MESH_HALF_WIDTH: f64 = 0.5;

/// Renders linear radiance; builds the vertex radiosity first when shading is smooth.
pub fn render(
    hierarchy: &Hierarchy,
    visibility: &dyn Visibility,
    camera: &Camera,
    options: &RenderOptions,
) -> Image {
    let vertices = options
        .shading
        .needs_vertices()
        .then(|| VertexRadiosity::new(hierarchy));
    render_with(hierarchy, visibility, camera, options, vertices.as_ref())
}

/// [`render`] reusing vertex radiosity already computed (for export too); built here if smooth shading
/// needs it and `vertices` is `None`.
pub fn render_with(
    hierarchy: &Hierarchy,
    visibility: &dyn Visibility,
    camera: &Camera,
    options: &RenderOptions,
    vertices: Option<&VertexRadiosity>,
) -> Image {
    render_reporting(hierarchy, visibility, camera, options, vertices).0
}

/// What a render did besides its image.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RenderReport {
    /// Records of the final gather's irradiance cache ([`RenderOptions::gather_cache`]).
    pub gather_records: usize,
}

/// [`render_with`], with what the render did.
pub fn render_reporting(
    hierarchy: &Hierarchy,
    visibility: &dyn Visibility,
    camera: &Camera,
    options: &RenderOptions,
    vertices: Option<&VertexRadiosity>,
) -> (Image, RenderReport) {
    with_tracer(hierarchy, visibility, camera, options, vertices, |tracer| {
        draw(tracer)
    })
}

/// The radiance a render with `options` shows at each surface point `(patch, point)` (on the patch's
/// plane), the irradiance cache's records placed for `camera` as [`render_with`] places them: the
/// shading, with a cached final gather its interpolated correction added (the shading alone where no
/// record reaches the point), with an uncached one the gather at the point. What `probe
/// --final-gather --cached` measures against a reference at points the camera sees.
pub fn radiance_as_rendered(
    hierarchy: &Hierarchy,
    visibility: &dyn Visibility,
    camera: &Camera,
    options: &RenderOptions,
    points: &[(u32, DVec3)],
) -> (Vec<Rgb>, RenderReport) {
    with_tracer(hierarchy, visibility, camera, options, None, |tracer| {
        points
            .par_iter()
            .map_init(LeafCorrections::default, |memo, &(patch, point)| {
                let (leaf, uv) = hierarchy.locate_with_parameters(patch, point);
                tracer.finish(patch, leaf, point, tracer.shade(leaf, point, uv, memo))
            })
            .collect()
    })
}

/// Builds what a render's primary rays need (vertex radiosity if the shading needs it and `vertices`
/// is `None`; the final gather and its cache if asked for) and hands it to `work`, with the report.
fn with_tracer<T>(
    hierarchy: &Hierarchy,
    visibility: &dyn Visibility,
    camera: &Camera,
    options: &RenderOptions,
    vertices: Option<&VertexRadiosity>,
    work: impl FnOnce(&Tracer) -> T,
) -> (T, RenderReport) {
    let built;
    let vertices = match (options.shading.needs_vertices(), vertices) {
        (true, None) => {
            built = VertexRadiosity::new(hierarchy);
            Some(&built)
        }
        (_, v) => v,
    };
    let gather = options
        .final_gather
        .filter(|_| options.quantity == Quantity::Radiance)
        .map(|settings| IrradianceGather::new(hierarchy, visibility, settings));
    let mut tracer = Tracer {
        hierarchy,
        visibility,
        camera,
        options,
        vertices,
        gather: gather.as_ref(),
        cache: None,
    };
    let cache = gather
        .as_ref()
        .zip(options.gather_cache)
        .map(|(gather, settings)| {
            let extent = hierarchy.patch_bounds().diagonal();
            let mut cache = IrradianceCache::new(settings, extent, options.seed);
            for lattice in [Lattice::PixelCentres, Lattice::PixelCorners] {
                let (columns, rows) = lattice.size(camera);
                // A block of candidates at a time: traced in parallel, offered in order.
                for block in coarse_to_fine(columns, rows).chunks(CANDIDATE_BLOCK) {
                    for candidate in tracer.cache_candidates(lattice, block) {
                        cache.offer(&candidate, visibility, lattice.placement());
                    }
                }
            }
            // Then every record's gather in one parallel pass: where records go depends on the
            // records' places and radii alone, never on what they gathered, and one pass leaves the
            // threads one tail to wait on instead of one per block (the classroom's render phase
            // 16.3 → 15.5 s, the image bit for bit the same; BENCHMARKS.md, "SOR by default").
            cache.gather(gather);
            cache
        });
    tracer.cache = cache.as_ref();
    let report = RenderReport {
        gather_records: cache.as_ref().map_or(0, IrradianceCache::len),
    };
    (work(&tracer), report)
}

/// The image of the tracer's camera.
fn draw(tracer: &Tracer) -> Image {
    let (camera, options) = (tracer.camera, tracer.options);
    let mut image = Image::new(camera.width, camera.height);
    let samples = options.samples_per_pixel.max(1);
    let cells = strata(samples);
    let width = camera.width;
    let stratified_pixel = |x: usize, y: usize, memo: &mut LeafCorrections| {
        let mut rng = Pcg64Mcg::seed_from_u64(mix(options.seed, (y * width + x) as u64));
        let mut sum = Rgb::BLACK;
        for (sx, sy) in stratified(&cells, &mut rng) {
            sum += tracer.radiance(x as f64 + sx, y as f64 + sy, memo);
        }
        sum / samples as f64
    };
    let adaptive = samples > 1 && options.antialias == Antialias::Adaptive && !options.mesh;
    if !adaptive {
        image
            .pixels
            .par_chunks_mut(width)
            .one_per_task()
            .enumerate()
            .for_each(|(y, row)| {
                let mut memo = LeafCorrections::default();
                for (x, pixel) in row.iter_mut().enumerate() {
                    *pixel = if samples == 1 {
                        tracer.radiance(x as f64 + 0.5, y as f64 + 0.5, &mut memo)
                    } else {
                        stratified_pixel(x, y, &mut memo)
                    };
                }
            });
        return image;
    }
    // Adaptive: the radiance at the pixel corners first, a band of rows at a time, so that the corners
    // held are a band's (`ADAPTIVE_BAND` rows) rather than a second image; a band's last corner row is
    // the next band's first. Every value is the same whatever the banding.
    let mut corners = vec![Rgb::BLACK; (width + 1) * (ADAPTIVE_BAND + 1)];
    for (band, rows) in image.pixels.chunks_mut(width * ADAPTIVE_BAND).enumerate() {
        let y0 = band * ADAPTIVE_BAND;
        let height = rows.len() / width;
        let first_new = if band == 0 {
            0
        } else {
            corners.copy_within(ADAPTIVE_BAND * (width + 1).., 0);
            1
        };
        corners[first_new * (width + 1)..(height + 1) * (width + 1)]
            .par_chunks_mut(width + 1)
            .one_per_task()
            .enumerate()
            .for_each(|(dy, row)| {
                let y = y0 + first_new + dy;
                let mut memo = LeafCorrections::default();
                for (x, corner) in row.iter_mut().enumerate() {
                    *corner = tracer.radiance(x as f64, y as f64, &mut memo);
                }
            });
        let corners = &corners;
        rows.par_chunks_mut(width)
            .one_per_task()
            .enumerate()
            .for_each(|(dy, row)| {
                let mut memo = LeafCorrections::default();
                for (x, pixel) in row.iter_mut().enumerate() {
                    let at = |dx: usize, cy: usize| corners[(dy + cy) * (width + 1) + x + dx];
                    let four = [at(0, 0), at(1, 0), at(0, 1), at(1, 1)];
                    *pixel = if corners_agree(&four) {
                        four.iter().fold(Rgb::BLACK, |sum, &c| sum + c) / 4.0
                    } else {
                        stratified_pixel(x, y0 + dy, &mut memo)
                    };
                }
            });
    }
    image
}

/// Whether a pixel's four corner radiances differ, channel by channel, by at most
/// [`ADAPTIVE_CONTRAST`] of the brightest (never where one is not finite).
fn corners_agree(corners: &[Rgb; 4]) -> bool {
    corners.iter().all(|c| c.is_finite())
        && (0..3).all(|channel| {
            let values = corners.map(|c| c.to_array()[channel]);
            let low = values.iter().copied().fold(f64::INFINITY, f64::min);
            let high = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            high - low <= ADAPTIVE_CONTRAST * high.abs()
        })
}

/// Everything a primary ray needs.
struct Tracer<'a> {
    hierarchy: &'a Hierarchy,
    visibility: &'a dyn Visibility,
    camera: &'a Camera,
    options: &'a RenderOptions,
    vertices: Option<&'a VertexRadiosity>,
    /// The final gather of [`RenderOptions::final_gather`], when asked for.
    gather: Option<&'a IrradianceGather<'a>>,
    /// Its records, when the gather is cached ([`RenderOptions::gather_cache`]).
    cache: Option<&'a IrradianceCache>,
}

impl Tracer<'_> {
    /// Radiance seen through image position (x, y) in pixels; `memo` keeps the corrections of the
    /// last leaf continuous shading saw ([`LeafCorrections`]).
    fn radiance(&self, x: f64, y: f64, memo: &mut LeafCorrections) -> Rgb {
        let surface = match self.seen(x, y) {
            Seen::Shown(radiance) => return radiance,
            Seen::Surface(surface) => surface,
        };
        let shaded = self.shade(surface.leaf, surface.point, surface.uv, memo);
        self.finish(surface.patch, surface.leaf, surface.point, shaded)
    }

    /// The radiance shown at a point of `patch` whose shading gives `shaded`: corrected by the cached
    /// final gather, replaced by the uncached one, or as it is.
    fn finish(&self, patch: u32, leaf: ElementId, point: DVec3, shaded: Rgb) -> Rgb {
        match (self.cache, self.gather) {
            (Some(cache), _) => cache
                .corrected(patch, leaf, point, shaded)
                .unwrap_or(shaded),
            (None, Some(gather)) => gather.radiance_at(patch, point),
            (None, None) => shaded,
        }
    }

    /// What the primary ray through image position (x, y) meets.
    fn seen(&self, x: f64, y: f64) -> Seen {
        let ray = self.camera.ray(x, y);
        let Some(hit) = self.visibility.intersect(&ray, 0.0, f64::INFINITY) else {
            return Seen::Shown(self.nothing());
        };
        // A luminaire's opening glows at I(ω)/A_proj(ω) toward the eye.
        if let Some(luminaire) = self.hierarchy.opening_at(hit.polygon) {
            return Seen::Shown(match self.options.quantity {
                Quantity::Radiance => luminaire.luminance(-ray.direction),
                Quantity::ErrorEstimate => self.nothing(),
            });
        }
        // The back of a one-sided polygon is an opaque black surface.
        let Some(patch) = self.hierarchy.patch_for_side(hit.polygon, hit.front) else {
            return Seen::Shown(self.nothing());
        };
        let patch_ref = &self.hierarchy.patches[patch as usize];
        let p = self.hierarchy.onto_patch_plane(patch, ray.at(hit.t));
        let (leaf, uv) = self.hierarchy.locate_with_parameters(patch, p);
        let element = self.hierarchy.element(leaf);
        // Camera rays are unit length, so t is the distance from the eye.
        let footprint = self.camera.pixel_footprint(hit.t);
        if self.options.mesh && boundary_distance(element.shape(), p) < MESH_HALF_WIDTH * footprint
        {
            return Seen::Shown(self.options.mesh_colour);
        }
        if self.options.quantity == Quantity::ErrorEstimate {
            return Seen::Shown(Rgb::new(element.error, element.error, element.error));
        }
        Seen::Surface(Surface {
            patch,
            point: p,
            leaf,
            uv,
            // Along the surface: a grazing view stretches a pixel over it.
            footprint: footprint
                / patch_ref
                    .normal
                    .dot(ray.direction)
                    .abs()
                    .max(GRAZING_COSINE),
        })
    }

    /// The shading's radiance at a seen surface point.
    fn shade(&self, leaf: ElementId, p: DVec3, uv: DVec2, memo: &mut LeafCorrections) -> Rgb {
        match (self.options.shading, self.vertices) {
            (Shading::Smooth, Some(vertices)) => vertices.evaluate(self.hierarchy, leaf, p),
            (Shading::Continuous | Shading::Seamless, Some(vertices)) => {
                let below = self.options.shading.steps_removed_below().unwrap_or(0.0);
                vertices.evaluate_continuous_at(self.hierarchy, leaf, p, uv, below, memo)
            }
            (Shading::Basis, _) => self.hierarchy.exitant_radiance_at_parameters(leaf, uv),
            _ => self.hierarchy.average_radiance(leaf),
        }
    }

    /// The irradiance cache's candidates: the surface points seen through the `lattice` positions
    /// `points`, in their order.
    fn cache_candidates(&self, lattice: Lattice, points: &[(usize, usize)]) -> Vec<Candidate> {
        points
            .par_iter()
            .map_init(LeafCorrections::default, |memo, &(x, y)| {
                let (image_x, image_y) = lattice.position(x, y);
                let Seen::Surface(surface) = self.seen(image_x, image_y) else {
                    return None;
                };
                Some(Candidate {
                    patch: surface.patch,
                    leaf: surface.leaf,
                    point: surface.point,
                    normal: self.hierarchy.patches[surface.patch as usize].normal,
                    footprint: surface.footprint,
                    key: lattice.key(self.camera, x, y),
                    shaded: self.shade(surface.leaf, surface.point, surface.uv, memo),
                })
            })
            .flatten()
            .collect()
    }

    /// What a pixel shows where no surface of the solution is seen (the background, the black back of
    /// a one-sided polygon): black radiance, or no error estimate at all (NaN, shown grey).
    fn nothing(&self) -> Rgb {
        match self.options.quantity {
            Quantity::Radiance => Rgb::BLACK,
            Quantity::ErrorEstimate => Rgb::new(f64::NAN, f64::NAN, f64::NAN),
        }
    }
}

/// What a primary ray meets: a value to show as is, or a surface point of a patch to shade.
enum Seen {
    Shown(Rgb),
    Surface(Surface),
}

/// A surface point seen by a primary ray.
struct Surface {
    patch: u32,
    /// On the patch's plane.
    point: DVec3,
    leaf: ElementId,
    uv: DVec2,
    /// A pixel's size along the surface there.
    footprint: f64,
}

/// The image positions whose surface points are offered to the irradiance cache, in two passes.
///
/// Pixel centres first, each a record unless a record of its leaf lies within
/// [`COVERED`](crate::measures::irradiance_cache::COVERED) of that record's radius: Ward's spacing
/// ([`Placement::Spaced`]). Then pixel corners, each a record only
/// where the cache would otherwise show its shading uncorrected ([`Placement::WhereUncorrected`]: no
/// record of its leaf reaches it, nor, for Monte Carlo radiosity's noisy leaves, one of its patch). A
/// leaf that no pixel centre sees (a strip along a contact or a corner, narrower than a pixel)
/// otherwise has no record, and its samples keep the shading uncorrected, just where the shading's
/// error is largest: on the classroom a ceiling strip at a wall showed +54% where the gather at the
/// point is +6%. The corners are where adaptive antialiasing samples first, so every one of them is
/// corrected. The corner pass adds about 11% more records on the classroom at 256² (BENCHMARKS.md,
/// "Records at pixel corners").
#[derive(Clone, Copy, Debug)]
enum Lattice {
    PixelCentres,
    PixelCorners,
}

impl Lattice {
    /// Columns and rows of positions.
    fn size(self, camera: &Camera) -> (usize, usize) {
        match self {
            Lattice::PixelCentres => (camera.width, camera.height),
            Lattice::PixelCorners => (camera.width + 1, camera.height + 1),
        }
    }

    /// Image position of column `x`, row `y`.
    fn position(self, x: usize, y: usize) -> (f64, f64) {
        let offset = match self {
            Lattice::PixelCentres => 0.5,
            Lattice::PixelCorners => 0.0,
        };
        (x as f64 + offset, y as f64 + offset)
    }

    /// A key per position of both lattices, distinct, for the radius rays' seeds.
    fn key(self, camera: &Camera, x: usize, y: usize) -> u64 {
        let (columns, _) = self.size(camera);
        let before = match self {
            Lattice::PixelCentres => 0,
            Lattice::PixelCorners => camera.width * camera.height,
        };
        (before + y * columns + x) as u64
    }

    /// Where its candidates become records.
    fn placement(self) -> Placement {
        match self {
            Lattice::PixelCentres => Placement::Spaced,
            Lattice::PixelCorners => Placement::WhereUncorrected,
        }
    }
}

/// Pixels whose candidates are traced at once for the irradiance cache: the candidates held are a
/// block's, not an image's.
const CANDIDATE_BLOCK: usize = 16_384;

/// Smallest cosine between a primary ray and the surface it meets used to stretch the pixel's
/// footprint along the surface (at most 20 times).
const GRAZING_COSINE: f64 = 0.05;

/// Pixels `(x, y)` of a `width × height` image, each once: every 32nd pixel of every 32nd row first,
/// then the ones halfway between them, and so on down to every pixel.
fn coarse_to_fine(width: usize, height: usize) -> Vec<(usize, usize)> {
    let mut order = Vec::with_capacity(width * height);
    let mut step = 32;
    loop {
        for y in (0..height).step_by(step) {
            for x in (0..width).step_by(step) {
                let coarser = step < 32 && x % (2 * step) == 0 && y % (2 * step) == 0;
                if !coarser {
                    order.push((x, y));
                }
            }
        }
        if step == 1 {
            return order;
        }
        step /= 2;
    }
}

/// Distance from a point in the shape's plane to the nearest of its edges.
fn boundary_distance(shape: &Shape, p: DVec3) -> f64 {
    crate::geometry::edges(shape.vertices())
        .map(|(a, b)| segment_distance(a, b, p))
        .fold(f64::INFINITY, f64::min)
}

fn segment_distance(a: DVec3, b: DVec3, p: DVec3) -> f64 {
    let ab = b - a;
    let len2 = ab.length_squared();
    let t = if len2 > 0.0 {
        ((p - a).dot(ab) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    p.distance(a + t * ab)
}

/// `n` equal-area strata `(x0, y0, width, height)` tiling the unit pixel: rows of equal-width cells, each
/// row as high as its share of the cells, so that any `n` stratifies exactly.
fn strata(n: u32) -> Vec<(f64, f64, f64, f64)> {
    let columns = (n as f64).sqrt().ceil() as u32;
    let rows = n.div_ceil(columns);
    let mut out = Vec::with_capacity(n as usize);
    let mut y0 = 0.0;
    for row in 0..rows {
        // Spread the remainder over the first rows.
        let cells = n / rows + u32::from(row < n % rows);
        let height = cells as f64 / n as f64;
        for cell in 0..cells {
            out.push((cell as f64 / cells as f64, y0, 1.0 / cells as f64, height));
        }
        y0 += height;
    }
    out
}

/// One jittered position in each of the `strata` of the unit pixel (from [`strata`], made once per image).
fn stratified<'a>(
    strata: &'a [(f64, f64, f64, f64)],
    rng: &'a mut Pcg64Mcg,
) -> impl Iterator<Item = (f64, f64)> + 'a {
    strata
        .iter()
        .map(|&(x0, y0, w, h)| (x0 + rng.random::<f64>() * w, y0 + rng.random::<f64>() * h))
}

/// Pixels that see an emitting surface or a luminaire's opening through any of 16 stratified points, and their 8 neighbours (so
/// that a pixel the emitter's outline grazes is masked whatever the jitter of either image): the mask
/// that leaves light sources out of an image comparison, where their radiance, orders of magnitude above
/// the rest, would dominate every norm.
pub fn emitter_mask(hierarchy: &Hierarchy, visibility: &dyn Visibility, camera: &Camera) -> Mask {
    let hits_emitter = |x: f64, y: f64| {
        let ray = camera.ray(x, y);
        visibility
            .intersect(&ray, 0.0, f64::INFINITY)
            .is_some_and(|hit| {
                hierarchy.opening_at(hit.polygon).is_some()
                    || hierarchy
                        .patch_for_side(hit.polygon, hit.front)
                        .is_some_and(|p| !hierarchy.patches[p as usize].emission.is_black())
            })
    };
    let rows: Vec<Vec<bool>> = (0..camera.height)
        .into_par_iter()
        .map(|y| {
            (0..camera.width)
                .map(|x| {
                    strata(16).into_iter().any(|(x0, y0, w, h)| {
                        hits_emitter(x as f64 + x0 + 0.5 * w, y as f64 + y0 + 0.5 * h)
                    })
                })
                .collect()
        })
        .collect();
    let (w, h) = (camera.width as isize, camera.height as isize);
    Mask::from_fn(camera.width, camera.height, |x, y| {
        (-1..=1).any(|dy| {
            (-1..=1).any(|dx| {
                let (nx, ny) = (x as isize + dx, y as isize + dy);
                (0..w).contains(&nx) && (0..h).contains(&ny) && rows[ny as usize][nx as usize]
            })
        })
    })
}

/// SplitMix64 finaliser of (seed, pixel): independent per-pixel streams whatever the thread schedule.
fn mix(seed: u64, index: u64) -> u64 {
    let mut z = seed ^ index.wrapping_mul(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strata_tile_the_pixel_with_equal_areas() {
        for n in 1..=17u32 {
            let cells = strata(n);
            assert_eq!(cells.len(), n as usize);
            let total: f64 = cells.iter().map(|c| c.2 * c.3).sum();
            assert!((total - 1.0).abs() < 1e-12);
            for &(x0, y0, w, h) in &cells {
                assert!((w * h - 1.0 / n as f64).abs() < 1e-12);
                assert!(x0 >= 0.0 && y0 >= 0.0 && x0 + w <= 1.0 + 1e-12 && y0 + h <= 1.0 + 1e-12);
            }
            // Disjoint: no two cells overlap with positive area.
            for (i, a) in cells.iter().enumerate() {
                for b in &cells[i + 1..] {
                    let ox = (a.0 + a.2).min(b.0 + b.2) - a.0.max(b.0);
                    let oy = (a.1 + a.3).min(b.1 + b.3) - a.1.max(b.1);
                    assert!(ox <= 1e-12 || oy <= 1e-12, "n = {n}: {a:?} overlaps {b:?}");
                }
            }
            let mut rng = Pcg64Mcg::seed_from_u64(u64::from(n));
            for ((x, y), &(x0, y0, w, h)) in stratified(&cells, &mut rng).zip(&cells) {
                assert!(x >= x0 && x <= x0 + w && y >= y0 && y <= y0 + h);
            }
        }
    }
}
