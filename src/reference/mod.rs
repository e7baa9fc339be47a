//! Ground truth: an unbiased path tracer for the diffuse scenes the radiosity solver handles, and point
//! probes comparing the two ([`probe`]).
//!
//! The estimator is the rendering equation for Lambertian surfaces, L(x) = L_e(x) + ρ(x)/π ∫ L_i(x, ω)
//! cos θ dω, evaluated by path tracing with
//! - next-event estimation: at every vertex one emitting polygon side is chosen with probability
//!   proportional to its power π L_e A, a point on it uniformly by area, and a shadow segment tests it;
//!   every goniometric luminaire ([`crate::scene::luminaire`]) gets a shadow segment to a point of its
//!   opening's faces that the vertex sees (chosen by projected area), weighted by the opening's
//!   radiance I(ω)/A_proj(ω) toward the vertex (a point opening: I(ω) from its centre); a bounce ray
//!   that hits an opening ends there (the opening is black, its light is all counted by this estimate);
//! - cosine-weighted bounce directions, so the throughput only picks up ρ;
//! - Russian roulette after [`ReferenceSettings::roulette_depth`] bounces with survival probability
//!   max(ρ) (unbiased: the surviving throughput is divided by it).
//!
//! Emission seen by the camera ray (or at the probed point) is added directly. Light reaching a path
//! vertex straight from an emitter is estimated twice, by next-event estimation and by the bounce ray when
//! it hits an emitter, and the two are combined with the power-heuristic weights of multiple importance
//! sampling (Veach–Guibas 1995), which sum to one: nothing is counted twice. Next-event estimation alone
//! has infinite variance wherever emitters meet reflectors at a concave edge (area sampling's 1/r² near
//! the edge; the white furnace is all such edges), so its sample standard errors would not be
//! trustworthy; the weighted combination is bounded by ρ L_e per vertex.
//!
//! Each estimate is made of [`BATCHES`] independent batches. Within a batch the first vertex's emitter
//! points and bounce directions are stratified (a randomly shifted (0, 2)-sequence, randomised quasi-Monte
//! Carlo), which lowers the variance of the direct and first-bounce light; the batches' independent random
//! shifts make their means independent and unbiased, and the standard error of the mean is estimated from
//! their spread (an unbiased variance estimate with `BATCHES - 1` degrees of freedom).
//!
//! A pixel's value is the average radiance over the pixel (the default box filter, comparable with
//! `render --spp 16` and above: each path starts at its own point of the pixel, see [`PixelFilter`]) or the
//! radiance leaving the surface point seen through its centre (`--filter centre`, comparable with a
//! one-sample render, which shades the same centre ray). Each pixel's random numbers come from its own
//! generator seeded from (seed, pixel), so images are bit-identical for any thread count.

pub mod probe;

use crate::color::Rgb;
use crate::geometry::{cosine_direction, DVec2, DVec3, Ray, Shape};
use crate::output::camera::Camera;
use crate::output::image::Image;
use crate::progress::Progress;
use crate::random::splitmix64;
use crate::scene::luminaire::Luminaire;
use crate::scene::Scene;
use crate::visibility::{Hit, Visibility};
use rand::{Rng, RngCore, SeedableRng};
use rand_pcg::Pcg64Mcg;
use rayon::prelude::*;
use std::f64::consts::PI;

/// How the reference image is computed.
#[derive(Clone, Copy, Debug)]
pub struct ReferenceSettings {
    /// Paths per pixel (at least 2, so that a standard error can be estimated); rounded up to a multiple
    /// of [`BATCHES`] (see [`samples_taken`]).
    pub spp: usize,
    pub seed: u64,
    /// Bounces taken before Russian roulette may end a path.
    pub roulette_depth: usize,
    /// Where in the pixel paths start.
    pub filter: PixelFilter,
}

/// The pixel footprint of a reference image (`--filter`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum PixelFilter {
    /// The radiance at the pixel centre.
    Centre,
    /// The average radiance over the pixel (box filter), comparable with `render --spp 16` (and above):
    /// every path starts at its own jittered point of one cell of a 4 × 4 grid over the pixel, path `i`
    /// of batch `b` in cell `(i + b) mod 16`, so that every cell gets the same number of paths and, from
    /// 256 paths per pixel (16 per batch) on, each batch covers the whole pixel. The estimate converges to the pixel's average as `--spp` grows
    /// (edges included), and the standard error from the batches' spread is that of this average.
    #[default]
    Box,
}

impl Default for ReferenceSettings {
    fn default() -> Self {
        ReferenceSettings {
            spp: 64,
            seed: 1,
            roulette_depth: 3,
            filter: PixelFilter::Box,
        }
    }
}

/// A Monte Carlo estimate per channel: the mean and its standard error (the standard deviation of the
/// independent batch means over √batches).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Estimate {
    pub mean: Rgb,
    pub stderr: Rgb,
}

impl Estimate {
    /// The photometric value of the estimate (luminance in cd/m² of a radiance, illuminance in lux of
    /// an irradiance: [`crate::color::photometric`]) and its standard error.
    pub fn photometric(&self) -> PhotometricEstimate {
        PhotometricEstimate {
            value: crate::color::photometric(self.mean),
            stderr: crate::color::photometric(self.stderr),
        }
    }
}

/// A photometric Monte Carlo estimate: the value and its standard error, `179 Σ_c w_c σ_c`, an upper
/// bound of the standard error of the luminance-weighted sum whatever the correlation between the
/// channels' estimates.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct PhotometricEstimate {
    pub value: f64,
    pub stderr: f64,
}

/// A reference image: per pixel the mean radiance and its standard error.
#[derive(Clone, Debug, PartialEq)]
pub struct ReferenceImage {
    pub mean: Image,
    pub stderr: Image,
}

impl ReferenceImage {
    /// Mean over non-black pixels of the relative standard error, measured on the channel average
    /// (stderr.average() / mean.average(), which bounds the relative error of the channel average from
    /// above); `None` when every pixel is black.
    pub fn mean_relative_stderr(&self) -> Option<f64> {
        let (sum, count) = self
            .mean
            .pixels
            .iter()
            .zip(&self.stderr.pixels)
            .filter(|(m, _)| m.average() > 0.0)
            .fold((0.0, 0usize), |(s, n), (m, e)| {
                (s + e.average() / m.average(), n + 1)
            });
        (count > 0).then(|| sum / count as f64)
    }
}

/// Per-polygon data the inner loop needs, gathered once.
#[derive(Clone, Copy, Debug)]
struct Surface {
    normal: DVec3,
    reflectance: Rgb,
    emission: Rgb,
    two_sided: bool,
}

/// One emitting polygon side: its shape oriented so that the normal points out of the emitting side.
#[derive(Clone, Copy, Debug)]
struct EmitterSide {
    /// The side as one or two triangles (a quad split along its 0-2 diagonal), so that sampling needs no
    /// area computations.
    triangles: [Shape; 2],
    /// Fraction of the area in the first triangle (1 for a triangle).
    split: f64,
    normal: DVec3,
    area: f64,
    emission: Rgb,
    /// Probability of choosing this side.
    probability: f64,
}

impl EmitterSide {
    /// Area-uniform point from a point of the unit square (stratification preserved, as in
    /// [`Shape::sample_uniform`]).
    fn sample(&self, s: DVec2) -> DVec3 {
        if s.x < self.split {
            self.triangles[0].sample_uniform(DVec2::new(s.x / self.split, s.y))
        } else {
            let x = ((s.x - self.split) / (1.0 - self.split)).min(1.0 - f64::EPSILON);
            self.triangles[1].sample_uniform(DVec2::new(x, s.y))
        }
    }
}

/// The path tracer over one scene and its ray-casting structure; cheap to share between threads.
pub struct PathTracer<'a> {
    visibility: &'a dyn Visibility,
    surfaces: Vec<Surface>,
    emitters: Vec<EmitterSide>,
    /// Cumulative probabilities of `emitters` (last entry 1).
    emitter_cdf: Vec<f64>,
    /// Index in `emitters` of each polygon's front and back side, when it emits.
    emitter_sides: Vec<[Option<u32>; 2]>,
    /// Smallest accepted hit distance for rays leaving a surface, relative to the scene size.
    t_min: f64,
    roulette_depth: usize,
    /// Goniometric luminaires, reached by next-event estimation; their openings are black polygons.
    luminaires: Vec<Luminaire>,
    /// For each polygon, the luminaire whose opening it is.
    openings: Vec<Option<u32>>,
}

/// Relative (to the scene diagonal) distance below which a hit of a ray leaving a surface is taken to be
/// that surface itself.
const SELF_HIT_EPSILON: f64 = 1e-9;

/// A surface point a path leaves from.
#[derive(Clone, Copy, Debug)]
struct Vertex {
    point: DVec3,
    /// Unit normal of the side the path is on.
    normal: DVec3,
    reflectance: Rgb,
}

impl<'a> PathTracer<'a> {
    /// Prepares the emitter table (sides chosen by power π L_e A, power measured by the channel average).
    pub fn new(scene: &Scene, visibility: &'a dyn Visibility, roulette_depth: usize) -> Self {
        let surfaces: Vec<Surface> = scene
            .polygons
            .iter()
            .map(|p| {
                let m = scene.material_of(p);
                Surface {
                    normal: p.shape.normal(),
                    reflectance: m.reflectance,
                    emission: m.emission,
                    two_sided: p.two_sided,
                }
            })
            .collect();
        let mut emitters = Vec::new();
        let mut emitter_sides = vec![[None, None]; scene.polygons.len()];
        for (index, p) in scene.polygons.iter().enumerate() {
            let emission = scene.material_of(p).emission;
            let area = p.shape.area();
            let power = emission.average() * PI * area;
            if power.is_nan() || power <= 0.0 {
                continue;
            }
            let sides: &[bool] = if p.two_sided { &[true, false] } else { &[true] };
            for &front in sides {
                let shape = if front { p.shape } else { p.shape.flipped() };
                emitter_sides[index][usize::from(!front)] = Some(emitters.len() as u32);
                let (triangles, split) = match shape {
                    Shape::Triangle(_) => ([shape, shape], 1.0),
                    Shape::Quad([a, b, c, d]) => {
                        let (first, second) =
                            (Shape::Triangle([a, b, c]), Shape::Triangle([a, c, d]));
                        let total = first.area() + second.area();
                        let split = if total > 0.0 {
                            first.area() / total
                        } else {
                            0.5
                        };
                        ([first, second], split)
                    }
                };
                emitters.push(EmitterSide {
                    triangles,
                    split,
                    normal: shape.normal(),
                    area,
                    emission,
                    probability: power,
                });
            }
        }
        let total: f64 = emitters.iter().map(|e| e.probability).sum();
        let mut cumulative = 0.0;
        let mut emitter_cdf = Vec::with_capacity(emitters.len());
        for e in &mut emitters {
            e.probability /= total;
            cumulative += e.probability;
            emitter_cdf.push(cumulative);
        }
        if let Some(last) = emitter_cdf.last_mut() {
            *last = 1.0;
        }
        let diagonal = scene.bounds().diagonal();
        PathTracer {
            visibility,
            surfaces,
            emitters,
            emitter_cdf,
            emitter_sides,
            t_min: SELF_HIT_EPSILON * if diagonal > 0.0 { diagonal } else { 1.0 },
            roulette_depth,
            luminaires: scene.luminaires.clone(),
            openings: scene.opening_luminaires(),
        }
    }

    /// The vertex where a ray arriving at `polygon` on side `front` leaves from, or `None` for the back of
    /// a one-sided polygon and for a luminaire's opening (opaque black absorbers).
    fn vertex(&self, point: DVec3, polygon: usize, front: bool) -> Option<(Vertex, Rgb)> {
        let s = &self.surfaces[polygon];
        if (!front && !s.two_sided) || self.openings[polygon].is_some() {
            return None;
        }
        let normal = if front { s.normal } else { -s.normal };
        Some((
            Vertex {
                point,
                normal,
                reflectance: s.reflectance,
            },
            s.emission,
        ))
    }

    /// One sample of the reflected radiance ρ/π ∫ L_i cos θ dω leaving `start` (emission at `start` not
    /// included). The first vertex's emitter point and bounce direction come from `first` (light, bounce:
    /// uniform points of the unit square), every later number from `rng`.
    fn sample_reflected(&self, start: Vertex, first: [DVec2; 2], rng: &mut Pcg64Mcg) -> Rgb {
        let mut radiance = Rgb::BLACK;
        let mut throughput = Rgb::WHITE;
        let mut vertex = start;
        let mut depth = 0;
        loop {
            if vertex.reflectance.is_black() {
                break;
            }
            let (light_u, bounce_u) = if depth == 0 {
                (first[0], first[1])
            } else {
                (
                    DVec2::new(rng.random(), rng.random()),
                    DVec2::new(rng.random(), rng.random()),
                )
            };
            // Next-event estimation: ρ/π L_e cos θx cos θy / r² · A / P(side).
            if let Some(direct) = self.sample_emitter(&vertex, light_u, rng) {
                radiance += throughput * vertex.reflectance * direct;
            }
            radiance += throughput * vertex.reflectance * self.sample_luminaires(&vertex, light_u);
            // Cosine-weighted bounce: pdf cos θ / π cancels the ρ/π cos θ of the integrand, leaving ρ.
            throughput = throughput * vertex.reflectance;
            depth += 1;
            if depth > self.roulette_depth {
                let survival = vertex.reflectance.max_channel().min(MAX_SURVIVAL);
                if rng.random::<f64>() >= survival {
                    break;
                }
                throughput *= 1.0 / survival;
            }
            let direction = cosine_direction(vertex.normal, bounce_u);
            let ray = Ray::new(vertex.point, direction);
            let Some(hit) = self.visibility.intersect(&ray, self.t_min, f64::INFINITY) else {
                break;
            };
            // The bounce's share of the direct light: emission at the hit, MIS-weighted against
            // next-event estimation (cosine pdf cos θx / π versus the emitter's solid-angle pdf).
            if let Some(side) = self.emitter_sides[hit.polygon][usize::from(!hit.front)] {
                let emitter = &self.emitters[side as usize];
                let cos_y = -emitter.normal.dot(direction);
                if cos_y > 0.0 {
                    let light_pdf = emitter.probability * hit.t * hit.t / (emitter.area * cos_y);
                    let bounce_pdf = vertex.normal.dot(direction) / PI;
                    radiance +=
                        throughput * emitter.emission * power_heuristic(bounce_pdf, light_pdf);
                }
            }
            match self.vertex(ray.at(hit.t), hit.polygon, hit.front) {
                Some((next, _)) => vertex = next,
                None => break,
            }
        }
        radiance
    }

    /// L_e cos θx cos θy / (π r²) / pdf for one emitter point (the BRDF's ρ is applied by the caller; the
    /// 1/π here is the Lambertian BRDF's), MIS-weighted against the cosine-sampled bounce; `None` when it
    /// contributes nothing.
    fn sample_emitter(&self, vertex: &Vertex, point_u: DVec2, rng: &mut Pcg64Mcg) -> Option<Rgb> {
        if self.emitters.is_empty() {
            return None;
        }
        let u: f64 = rng.random();
        let index = self
            .emitter_cdf
            .partition_point(|&c| c <= u)
            .min(self.emitters.len() - 1);
        let emitter = &self.emitters[index];
        let y = emitter.sample(point_u);
        let d = y - vertex.point;
        let r2 = d.length_squared();
        if r2 <= 0.0 {
            return None;
        }
        let cos_x = vertex.normal.dot(d);
        let cos_y = -emitter.normal.dot(d);
        if cos_x <= 0.0 || cos_y <= 0.0 {
            return None;
        }
        if self.visibility.segment_occluded(vertex.point, y) {
            return None;
        }
        // Both pdfs in solid angle at the vertex: P r² / (A cos θy) for the emitter point, cos θx / π for
        // the bounce (d is not normalised: cos θx = n·d / r, and r² = |d|²).
        let r = r2.sqrt();
        let light_pdf = emitter.probability * r2 * r / (emitter.area * cos_y);
        let bounce_pdf = cos_x / (PI * r);
        let weight = power_heuristic(light_pdf, bounce_pdf);
        Some(emitter.emission * (bounce_pdf * weight / light_pdf))
    }

    /// Next-event estimation of every luminaire, one opening point each from `point_u`
    /// ([`Luminaire::sample_point`]): L(ω) cos θx cos θy / (π r²) / pdf, or I(ω) cos θx / (π r²) for a
    /// point opening; the BRDF's ρ is applied by the caller. Bounce rays that hit an opening add
    /// nothing, so no MIS is needed.
    fn sample_luminaires(&self, vertex: &Vertex, point_u: DVec2) -> Rgb {
        let mut sum = Rgb::BLACK;
        for luminaire in &self.luminaires {
            let Some((y, face_normal, density)) = luminaire.sample_point(vertex.point, point_u)
            else {
                continue;
            };
            let d = vertex.point - y;
            let r2 = d.length_squared();
            let cos_x = -vertex.normal.dot(d);
            if r2 <= 0.0 || cos_x <= 0.0 {
                continue;
            }
            let r = r2.sqrt();
            let contribution = if density > 0.0 {
                let cos_y = face_normal.dot(d).abs() / r;
                luminaire.luminance(d) * (cos_x * cos_y / (PI * r2 * r * density))
            } else {
                luminaire.intensity(d) * (cos_x / (PI * r2 * r))
            };
            if contribution.is_black() || self.visibility.segment_occluded(vertex.point, y) {
                continue;
            }
            sum += contribution;
        }
        sum
    }

    /// Sum of `n` samples of the reflected radiance leaving `start`: one randomised quasi-Monte Carlo
    /// batch. The first vertex's emitter points and bounce directions are a (0, 2)-sequence in base 2
    /// (van der Corput and Sobol's second dimension), each randomised by its own random digital shift
    /// (XOR), the light points indexed by i and the bounce points with their coordinates swapped, so that
    /// both are stratified over the batch while every pair is uniform in the 4-cube: the batch mean is
    /// unbiased, and batches with independent shifts are independent.
    fn batch(&self, start: Vertex, n: usize, rng: &mut Pcg64Mcg) -> Rgb {
        let sequence = FirstVertexSequence::new(rng);
        let mut sum = Rgb::BLACK;
        for i in 0..n as u32 {
            sum += self.sample_reflected(start, sequence.point(i), rng);
        }
        sum
    }

    /// The estimate of the radiance leaving a vertex with emission `emission` (added exactly) from the sums
    /// of its batches of `per_batch` samples each, combined in batch order.
    fn combine(emission: Rgb, batch_sums: &[Rgb], per_batch: usize) -> Estimate {
        let estimate = batch_statistics(batch_sums, per_batch);
        Estimate {
            mean: emission + estimate.mean,
            stderr: estimate.stderr,
        }
    }

    /// Radiance leaving `point` on side `front` of `polygon`, L_e + ρ/π ∫ L_i cos θ dω, from `spp`
    /// paths (a path-traced final gather). `normal` orients the hemisphere; it should be the
    /// unit normal of that side. The back of a one-sided polygon leaves nothing (exactly zero).
    pub fn radiance_leaving(
        &self,
        point: DVec3,
        normal: DVec3,
        polygon: usize,
        front: bool,
        spp: usize,
        seed: u64,
    ) -> Estimate {
        let Some((mut start, emission)) = self.vertex(point, polygon, front) else {
            return Estimate::default();
        };
        start.normal = normal.normalize_or(start.normal);
        self.estimate_leaving(start, emission, spp, seed)
    }

    /// Irradiance E = ∫ L_i cos θ dω (W/m²) arriving at any point, on a surface or floating in space,
    /// from the side its `normal` points to, from `spp` paths: π times the reflected radiance of a white
    /// (ρ = 1) Lambertian vertex there, so the estimator, its batches and its standard error are those of
    /// [`PathTracer::radiance_leaving`].
    pub fn irradiance_at(&self, point: DVec3, normal: DVec3, spp: usize, seed: u64) -> Estimate {
        let start = Vertex {
            point,
            normal: normal.normalize_or(DVec3::Z),
            reflectance: Rgb::WHITE,
        };
        let reflected = self.estimate_leaving(start, Rgb::BLACK, spp, seed);
        Estimate {
            mean: reflected.mean * PI,
            stderr: reflected.stderr * PI,
        }
    }

    /// The batches of `spp` paths from `start`, each with its own generator seeded from (seed, batch),
    /// in parallel and combined in batch order: the result does not depend on the thread count.
    fn estimate_leaving(&self, start: Vertex, emission: Rgb, spp: usize, seed: u64) -> Estimate {
        let (batches, per_batch) = batch_layout(spp);
        let sums: Vec<Rgb> = (0..batches)
            .into_par_iter()
            .map(|b| self.batch(start, per_batch, &mut stream(seed, b as u64)))
            .collect();
        Self::combine(emission, &sums, per_batch)
    }

    /// The reference image seen by `camera`: per pixel, `settings.spp` paths from the surface points seen
    /// through the pixel (see [`PixelFilter`]). Rows run in parallel; each pixel has its own generator.
    pub fn render(
        &self,
        camera: &Camera,
        settings: &ReferenceSettings,
        progress: &Progress,
    ) -> ReferenceImage {
        let (width, height) = (camera.width, camera.height);
        let bar = progress.bar(height as u64, "reference");
        let rows: Vec<(Vec<Rgb>, Vec<Rgb>)> = (0..height)
            .into_par_iter()
            .map(|y| {
                let mut means = Vec::with_capacity(width);
                let mut errors = Vec::with_capacity(width);
                for x in 0..width {
                    let pixel = (y * width + x) as u64;
                    let estimate = self.pixel(camera, x, y, pixel, settings);
                    means.push(estimate.mean);
                    errors.push(estimate.stderr);
                }
                bar.inc(1);
                (means, errors)
            })
            .collect();
        bar.finish_and_clear();
        let mut mean = Image::new(width, height);
        let mut stderr = Image::new(width, height);
        for (y, (means, errors)) in rows.into_iter().enumerate() {
            mean.pixels[y * width..(y + 1) * width].copy_from_slice(&means);
            stderr.pixels[y * width..(y + 1) * width].copy_from_slice(&errors);
        }
        ReferenceImage { mean, stderr }
    }

    /// One path's estimate of the radiance seen along a camera ray whose first hit is `hit`: the
    /// emission of the surface hit plus one reflected-light sample with first-vertex points `first`, or a
    /// luminaire opening's radiance.
    fn camera_sample(
        &self,
        ray: &Ray,
        hit: Option<Hit>,
        first: [DVec2; 2],
        rng: &mut Pcg64Mcg,
    ) -> Rgb {
        let Some(hit) = hit else {
            return Rgb::BLACK;
        };
        if let Some(k) = self.openings[hit.polygon] {
            return self.luminaires[k as usize].luminance(-ray.direction);
        }
        match self.vertex(ray.at(hit.t), hit.polygon, hit.front) {
            Some((start, emission)) => emission + self.sample_reflected(start, first, rng),
            None => Rgb::BLACK,
        }
    }

    fn pixel(
        &self,
        camera: &Camera,
        x: usize,
        y: usize,
        pixel: u64,
        settings: &ReferenceSettings,
    ) -> Estimate {
        let (batches, per_batch) = batch_layout(settings.spp);
        let seed = derive_seed(settings.seed, pixel);
        let mut sums = [Rgb::BLACK; BATCHES];
        let side = (BATCHES as f64).sqrt() as usize;
        let first_hit = |ray: &Ray| self.visibility.intersect(ray, 0.0, f64::INFINITY);
        // Every path of the centre filter follows the same camera ray: it is cast once per pixel.
        let centre = (settings.filter == PixelFilter::Centre).then(|| {
            let ray = camera.ray(x as f64 + 0.5, y as f64 + 0.5);
            (ray, first_hit(&ray))
        });
        for (b, sum) in sums.iter_mut().enumerate().take(batches) {
            let mut rng = stream(seed, b as u64);
            let sequence = FirstVertexSequence::new(&mut rng);
            for i in 0..per_batch {
                let (ray, hit) = match centre {
                    Some(centre) => centre,
                    None => {
                        let cell = (i + b) % BATCHES;
                        let ray = camera.ray(
                            x as f64 + ((cell % side) as f64 + rng.random::<f64>()) / side as f64,
                            y as f64 + ((cell / side) as f64 + rng.random::<f64>()) / side as f64,
                        );
                        (ray, first_hit(&ray))
                    }
                };
                *sum += self.camera_sample(&ray, hit, sequence.point(i as u32), &mut rng);
            }
        }
        Self::combine(Rgb::BLACK, &sums[..batches], per_batch)
    }
}

/// Independent batches per estimate: the standard error comes from the spread of the batch means (each
/// batch is a randomised quasi-Monte Carlo estimate, so its samples are not independent).
pub const BATCHES: usize = 16;

/// The first path vertex's emitter points and bounce directions of one batch: a (0, 2)-sequence (van der
/// Corput and Sobol's second dimension), randomly shifted by digital XOR per batch, so that each batch is
/// an unbiased randomised quasi-Monte Carlo estimate and the batches are independent.
struct FirstVertexSequence {
    light_shift: [u32; 2],
    bounce_shift: [u32; 2],
}

impl FirstVertexSequence {
    fn new(rng: &mut Pcg64Mcg) -> Self {
        FirstVertexSequence {
            light_shift: [rng.next_u32(), rng.next_u32()],
            bounce_shift: [rng.next_u32(), rng.next_u32()],
        }
    }

    /// The `i`-th (light, bounce) pair of unit-square points.
    fn point(&self, i: u32) -> [DVec2; 2] {
        let (a, b) = (i.reverse_bits(), sobol_second(i));
        [
            unit_square(a ^ self.light_shift[0], b ^ self.light_shift[1]),
            unit_square(b ^ self.bounce_shift[0], a ^ self.bounce_shift[1]),
        ]
    }
}

/// (batches, samples per batch) for `spp` samples: `BATCHES` batches (fewer, of one sample each, for
/// smaller `spp`), so `spp` is rounded up to a multiple of `BATCHES`.
fn batch_layout(spp: usize) -> (usize, usize) {
    let batches = spp.clamp(1, BATCHES);
    (batches, spp.div_ceil(batches))
}

/// The number of samples actually taken for a requested `spp` (rounded up to a multiple of
/// [`BATCHES`]).
pub fn samples_taken(spp: usize) -> usize {
    let (batches, per_batch) = batch_layout(spp);
    batches * per_batch
}

/// Upper bound of the Russian roulette survival probability, so that paths end even if a material's
/// reflectance reaches 1.
const MAX_SURVIVAL: f64 = 0.99;

/// Renders the reference image of `scene` (see the module documentation for the estimator).
pub fn render_reference(
    scene: &Scene,
    visibility: &dyn Visibility,
    camera: &Camera,
    settings: &ReferenceSettings,
    progress: &Progress,
) -> ReferenceImage {
    PathTracer::new(scene, visibility, settings.roulette_depth).render(camera, settings, progress)
}

/// Mean and standard error from the sums of equally sized independent batches: the standard error is
/// the sample standard deviation of the batch means over √(batches) (zero for a single batch).
fn batch_statistics(sums: &[Rgb], per_batch: usize) -> Estimate {
    let k = sums.len();
    if k == 0 || per_batch == 0 {
        return Estimate::default();
    }
    let n = per_batch as f64;
    let mean = sums.iter().copied().sum::<Rgb>() / (k as f64 * n);
    let stderr = if k < 2 {
        Rgb::BLACK
    } else {
        let squares: Rgb = sums
            .iter()
            .map(|s| {
                let d = *s / n - mean;
                d * d
            })
            .sum();
        (squares / (k as f64 * (k as f64 - 1.0))).map(f64::sqrt)
    };
    Estimate { mean, stderr }
}

/// An independent generator for stream `index` of `seed` (splitmix64 finalisers decorrelate nearby
/// seeds and indices).
fn stream(seed: u64, index: u64) -> Pcg64Mcg {
    Pcg64Mcg::seed_from_u64(derive_seed(seed, index))
}

/// The seed of sub-stream `index` of `seed`.
pub(crate) fn derive_seed(seed: u64, index: u64) -> u64 {
    splitmix64(splitmix64(seed) ^ index)
}

/// Veach's power heuristic (β = 2): the weight of the strategy with pdf `a` against one with pdf `b`.
fn power_heuristic(a: f64, b: f64) -> f64 {
    let (a2, b2) = (a * a, b * b);
    if a2 + b2 > 0.0 {
        a2 / (a2 + b2)
    } else {
        0.0
    }
}

/// Sobol's second dimension (generator matrix: Pascal's triangle mod 2) of point `i`, as 32-bit fraction;
/// with the bit-reversed `i` (van der Corput) it makes a (0, 2)-sequence in base 2.
fn sobol_second(mut i: u32) -> u32 {
    let mut v: u32 = 1 << 31;
    let mut r = 0;
    while i != 0 {
        if i & 1 != 0 {
            r ^= v;
        }
        i >>= 1;
        v ^= v >> 1;
    }
    r
}

/// A point of the unit square [0, 1)² from two 32-bit fractions.
fn unit_square(a: u32, b: u32) -> DVec2 {
    const SCALE: f64 = 1.0 / 4_294_967_296.0;
    DVec2::new(a as f64 * SCALE, b as f64 * SCALE)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn batch_statistics_match_the_textbook_formulas() {
        let means = [1.0, 2.0, 4.0, 7.0];
        let sums: Vec<Rgb> = means.iter().map(|m| Rgb::splat(m * 10.0)).collect();
        let e = batch_statistics(&sums, 10);
        let mean = 3.5;
        let var = means.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / 3.0;
        assert!((e.mean.r - mean).abs() < 1e-12);
        assert!((e.stderr.g - (var / 4.0).sqrt()).abs() < 1e-12);
        assert_eq!(samples_taken(100), 112);
        assert_eq!(samples_taken(5), 5);
    }

    #[test]
    fn the_first_points_stratify_the_unit_square() {
        // Any 2^m consecutive points from 0 fill each of the 2^m elementary intervals of every shape once.
        let m = 4;
        for shape in 0..=m {
            let mut seen = vec![false; 1 << m];
            for i in 0..1u32 << m {
                let (x, y) = (i.reverse_bits(), sobol_second(i));
                let cell = (x.checked_shr(32 - shape).unwrap_or(0) << (m - shape)) as usize
                    | (y.checked_shr(32 - (m - shape)).unwrap_or(0)) as usize;
                assert!(!seen[cell], "shape {shape}, point {i}");
                seen[cell] = true;
            }
        }
    }
}
