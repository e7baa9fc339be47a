//! The multi-resolution visibility experiment of Sillion & Drettakis §5 on the scene of Figures 1 and 9
//! ([`ShadowGroups`]): the wall lit through four groups of black cubes, solved with exact visibility,
//! with multi-resolution visibility at several feature sizes `s`, and with extinction alone; each wall
//! compared with a finer exact reference by the FBEM at feature size `s` (§2.2), one group region at a
//! time, as the paper does. The claim under test: as `s` grows the time drops, and the FBEM at `s` stays
//! of the order of exact visibility's.
//!
//! Black cubes emit and reflect nothing, so they act on the wall only by blocking rays: the hierarchy
//! holds the receivers alone (wall tiles and source) and the visibility structure every polygon, which
//! spares the cubes' ~2000 patches and their four million initial pairs.

use crate::bases::BasisKind;
use crate::geometry::{DVec3, Shape};
use crate::hierarchy::clusters::ClusterTreeKind;
use crate::hierarchy::Hierarchy;
use crate::measures::fbem::{self, Mask};
use crate::output::camera::Camera;
use crate::output::image::Image;
use crate::output::render::{render, RenderOptions, Shading};
use crate::pipeline::{deterministic_settings, make_oracle, make_solver, SimulationSettings};
use crate::progress::Progress;
use crate::scene::generators::ShadowGroups;
use crate::scene::{CameraSpec, Scene};
use crate::solvers::{solve, SolveReport};
use crate::visibility::bvh::Bvh;
use crate::visibility::extinction::Extinction;
use crate::visibility::multires::{Averaging, Multires};
use crate::visibility::Visibility;
use anyhow::{ensure, Result};
use serde::Serialize;
use std::time::Instant;

/// Image pixel size on the wall: the smallest shadows (~0.035) are about 4 pixels wide.
pub const PIXEL: f64 = 0.009;
const FOV_DEGREES: f64 = 30.0;
/// A pixel is in a shadow feature when it gets less than 80% of the unoccluded light (§2.4's mask).
const SHADOW_THRESHOLD: f64 = 0.2;

/// The shadow-groups scene split for the experiment: receivers for the hierarchy, every polygon for rays.
pub struct Wall {
    pub groups: ShadowGroups,
    /// Wall tiles and source.
    pub receivers: Scene,
    /// Every polygon of the scene (tiles, source, cubes), for the visibility structures.
    pub shapes: Vec<Shape>,
    /// The wall tiles alone, for rendering the wall head-on.
    pub tiles: Bvh,
}

impl Wall {
    /// The scene of `groups` with black cubes (pure occluders: the direct shadows of Appendix A).
    pub fn new(groups: &ShadowGroups) -> Wall {
        let groups = ShadowGroups {
            cube_reflectance: 0.0,
            ..groups.clone()
        };
        let scene = groups.scene();
        let t = groups.wall_tiles();
        let shapes: Vec<Shape> = scene.polygons.iter().map(|p| p.shape).collect();
        let mut receivers = scene;
        receivers.polygons.truncate(t + 1);
        let tiles = Bvh::new(&shapes[..t]);
        Wall {
            groups,
            receivers,
            shapes,
            tiles,
        }
    }

    /// Tiles and source: the polygons that block nothing between wall and source.
    pub fn unoccluded(&self) -> &[Shape] {
        &self.shapes[..self.groups.wall_tiles() + 1]
    }

    /// Hierarchical radiosity on the receivers with rays cast by `visibility`, wall elements refined to
    /// quadtree `level` (side 1/2^level of a tile) everywhere the power oracle asks.
    pub fn solve(
        &self,
        visibility: &dyn Visibility,
        level: u32,
        progress: &Progress,
    ) -> (Hierarchy, SolveReport) {
        let settings = SimulationSettings {
            eps: 1e-7,
            // A degree-1 cubature (one node on each element, one visibility ray per link): the elements
            // are tiny next to their distance to the source, so the form factor needs no more.
            cubature_degree: Some(1),
            ..Default::default()
        };
        let mut h = Hierarchy::new(&self.receivers, BasisKind::Constant);
        let tile_area = self.receivers.polygons[0].shape.area();
        // Elements of level `level - 1` are still splittable, those of `level` not.
        let budget = crate::memory::MemoryBudget::refinement_only(settings.max_memory);
        let mut solve_settings = deterministic_settings(&settings, &h, &budget);
        solve_settings.refine.min_area = 0.5 * tile_area / 4f64.powi(level as i32 - 1);
        let oracle = make_oracle(&settings, &h);
        let solver = make_solver(settings.solver);
        let report = solve(
            &mut h,
            visibility,
            oracle.as_ref(),
            solver.as_ref(),
            &solve_settings,
            progress,
        );
        (h, report)
    }

    /// Flat render of the wall alone (cubes and source out of view), head-on over the shadow region of
    /// group `k`, pixels of [`PIXEL`].
    pub fn image(&self, solution: &Hierarchy, k: usize) -> Image {
        let [x0, x1, y0, y1] = self.groups.shadow_region(k);
        let side = (x1 - x0).max(y1 - y0);
        let n = (side / PIXEL).round() as usize;
        let centre = DVec3::new(0.5 * (x0 + x1), 0.5 * (y0 + y1), 0.0);
        let half_height = 0.5 * n as f64 * PIXEL;
        let distance = half_height / (0.5 * FOV_DEGREES).to_radians().tan();
        let spec = CameraSpec {
            eye: centre + DVec3::Z * distance,
            look_at: centre,
            up: DVec3::Y,
            fov_degrees: FOV_DEGREES,
        };
        let options = RenderOptions {
            shading: Shading::Flat,
            ..Default::default()
        };
        render(solution, &self.tiles, &Camera::new(&spec, n, n), &options)
    }

    /// One image per group region.
    pub fn images(&self, solution: &Hierarchy) -> Vec<Image> {
        (0..self.groups.cube_sizes.len())
            .map(|k| self.image(solution, k))
            .collect()
    }
}

/// What to run.
#[derive(Clone, Debug)]
pub struct MultiresExperiment {
    pub groups: ShadowGroups,
    /// Feature sizes `s` (world units on the wall), each one multires run and one FBEM size.
    pub feature_sizes: Vec<f64>,
    /// Quadtree level of the compared solutions' wall elements.
    pub level: u32,
    /// Quadtree level of the reference's wall elements (finer).
    pub reference_level: u32,
    /// Cluster tree of the extinction and multires structures.
    pub tree: ClusterTreeKind,
}

/// One solve of the experiment, its cost and its error per group.
#[derive(Clone, Debug, Serialize)]
pub struct Run {
    /// "exact", "multires" (clusters averaged as a whole, [`Averaging::Cluster`]), "multires-leaves"
    /// ([`Averaging::Leaves`]) or "extinction".
    pub visibility: &'static str,
    /// The multires run's `s` (world units); for exact and extinction runs, the `s` of the FBEM columns.
    pub feature_size: f64,
    /// The FBEM's feature size in pixels, `s / PIXEL` rounded.
    pub fbem_pixels: usize,
    pub build_seconds: f64,
    /// Refinement and solution, visibility included.
    pub seconds: f64,
    pub rays: u64,
    /// FBEM at `s` per group (smallest cubes first), luminance of the wall.
    pub fbem: Vec<f64>,
    /// L² error (RMSE) per group.
    pub l2: Vec<f64>,
    /// Root mean square of the groups' FBEM.
    pub fbem_all: f64,
    /// `fbem_all` over the exact run's at the same `s`.
    pub fbem_over_exact: f64,
}

/// The per-group error of `images` against the reference, at FBEM size `pixels`.
fn errors(
    images: &[Image],
    reference: &[Image],
    masks: &[Mask],
    pixels: usize,
) -> Result<(Vec<f64>, Vec<f64>)> {
    let mut fbem_values = Vec::new();
    let mut l2 = Vec::new();
    for ((a, r), m) in images.iter().zip(reference).zip(masks) {
        fbem_values.push(fbem::fbem(a, r, m, pixels, 2.0, None)?.value);
        l2.push(fbem::fbem(a, r, m, 1, 2.0, None)?.value);
    }
    Ok((fbem_values, l2))
}

fn root_mean_square(v: &[f64]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt()
}

impl MultiresExperiment {
    /// Runs the reference, then exact, multires at every `s` and extinction; rows in that order for
    /// each `s`.
    pub fn run(&self, progress: &Progress) -> Result<Vec<Run>> {
        self.groups.validate().map_err(anyhow::Error::msg)?;
        ensure!(
            !self.feature_sizes.is_empty()
                && self
                    .feature_sizes
                    .iter()
                    .all(|s| s.is_finite() && *s >= 0.0),
            "feature sizes must be finite and non-negative"
        );
        ensure!(
            (1..=9).contains(&self.level) && (self.level..=9).contains(&self.reference_level),
            "levels must satisfy 1 <= level <= reference level <= 9"
        );
        let wall = Wall::new(&self.groups);
        let quiet = Progress::new(true);
        let say = |what: std::fmt::Arguments| {
            if !progress.quiet {
                crate::progress::stderr_line(what);
            }
        };
        say(format_args!(
            "shadow groups: reference (exact, level {})",
            self.reference_level
        ));
        let exact_rays = Bvh::new(&wall.shapes);
        let (reference, _) = wall.solve(&exact_rays, self.reference_level, &quiet);
        let reference = wall.images(&reference);
        let (unoccluded, _) =
            wall.solve(&Bvh::new(wall.unoccluded()), self.reference_level, &quiet);
        let masks = wall
            .images(&unoccluded)
            .iter()
            .zip(&reference)
            .map(|(u, r)| fbem::shadow_mask(r, u, SHADOW_THRESHOLD))
            .collect::<Result<Vec<_>>>()?;

        let solve = |name: &'static str, build: &dyn Fn() -> Box<dyn Visibility>| {
            say(format_args!(
                "shadow groups: {name} at level {}",
                self.level
            ));
            let start = Instant::now();
            let visibility = build();
            let build_seconds = start.elapsed().as_secs_f64();
            let start = Instant::now();
            let (h, report) = wall.solve(visibility.as_ref(), self.level, &quiet);
            let seconds = start.elapsed().as_secs_f64();
            (
                wall.images(&h),
                build_seconds,
                seconds,
                report.form_factor_rays + report.oracle_rays,
            )
        };
        let exact = solve("exact", &|| Box::new(Bvh::new(&wall.shapes)));
        let extinction = solve("extinction", &|| {
            Box::new(Extinction::new(&wall.shapes, self.tree))
        });
        let mut runs = Vec::new();
        for &s in &self.feature_sizes {
            let multires = solve("multires", &|| {
                Box::new(Multires::new(
                    &wall.shapes,
                    self.tree,
                    s,
                    Averaging::Cluster,
                ))
            });
            let multires_leaves = solve("multires, leaf averaging", &|| {
                Box::new(Multires::new(&wall.shapes, self.tree, s, Averaging::Leaves))
            });
            let pixels = (s / PIXEL).round() as usize;
            let (exact_fbem, _) = errors(&exact.0, &reference, &masks, pixels)?;
            let exact_all = root_mean_square(&exact_fbem);
            for (name, result) in [
                ("exact", &exact),
                ("multires", &multires),
                ("multires-leaves", &multires_leaves),
                ("extinction", &extinction),
            ] {
                let (fbem_values, l2) = errors(&result.0, &reference, &masks, pixels)?;
                let fbem_all = root_mean_square(&fbem_values);
                runs.push(Run {
                    visibility: name,
                    feature_size: s,
                    fbem_pixels: pixels,
                    build_seconds: result.1,
                    seconds: result.2,
                    rays: result.3,
                    fbem: fbem_values,
                    l2,
                    fbem_all,
                    fbem_over_exact: fbem_all / exact_all,
                });
            }
        }
        Ok(runs)
    }
}

/// The runs as a Markdown table: one row per run, FBEM per group.
pub fn markdown_table(runs: &[Run]) -> String {
    let groups = runs.first().map_or(0, |r| r.fbem.len());
    let mut out = String::from("| s | s (px) | visibility | build s | solve s |");
    for k in 0..groups {
        out += &format!(" FBEM g{} | L² g{} |", k + 1, k + 1);
    }
    out += " FBEM rms | / exact |\n|---|---|---|---|---|";
    out += &"---|---|".repeat(groups);
    out += "---|---|\n";
    for r in runs {
        out += &format!(
            "| {} | {} | {} | {:.3} | {:.2} |",
            r.feature_size, r.fbem_pixels, r.visibility, r.build_seconds, r.seconds
        );
        for (f, l) in r.fbem.iter().zip(&r.l2) {
            out += &format!(" {f:.4} | {l:.4} |");
        }
        out += &format!(" {:.4} | {:.2} |\n", r.fbem_all, r.fbem_over_exact);
    }
    out
}
