//! The experiment of Feixas et al. §4: for each refinement oracle (power eq. (1), kernel smoothness eq. (2),
//! mutual information eq. (15)), adjust ε until the mesh has a target number of elements (the paper's
//! ~1000 and ~2000 patches on the Cornell box, ~14000 on the cube room), then compare the meshes at equal
//! element count: elements, links, rays (solution and oracle), time, relative RMSE against the reference
//! path tracer and the feature-based error metric (Sillion–Drettakis §2.2) at a few feature sizes.
//! The paper's robustness run repeats this with 4 instead of 10 oracle samples.

use crate::measures::fbem::{self, Mask};
use crate::measures::image_metrics::{black_pixels, compare};
use crate::output::camera::Camera;
use crate::output::image::Image;
use crate::output::render::{render_with, RenderOptions, Shading};
use crate::output::VertexRadiosity;
use crate::pipeline::{simulate, OracleKind, SimulationSettings, Solution};
use crate::progress::Progress;
use crate::scene::Scene;
use anyhow::Result;
use serde::Serialize;
use std::time::Instant;

/// What to run.
#[derive(Clone, Debug)]
pub struct OracleExperiment {
    pub oracles: Vec<OracleKind>,
    /// Target leaf-element counts ("patches" in the paper's figures).
    pub targets: Vec<usize>,
    /// Oracle samples per evaluation for the main run (the paper's 10) and the robustness run (4).
    pub samples: Vec<usize>,
    /// Settings shared by every solve (ε is searched).
    pub base: SimulationSettings,
    /// Accept a mesh within this fraction of the target count.
    pub tolerance: f64,
    /// Most solves per ε search.
    pub max_solves: usize,
    /// Feature sizes (pixels) at which the FBEM is reported.
    pub fbem_sizes: Vec<usize>,
}

/// One oracle at one target and sample count.
#[derive(Clone, Debug, Serialize)]
pub struct OracleRun {
    pub oracle: OracleKind,
    pub oracle_samples: usize,
    pub target: usize,
    pub eps: f64,
    pub leaf_elements: usize,
    pub elements: usize,
    pub links: usize,
    /// Rays of the solution (form factors, or shooting rays of the stochastic method).
    pub solution_rays: u64,
    /// Rays of the oracle evaluations.
    pub oracle_rays: u64,
    /// Seconds of the accepted solve (refine + solve), not of the search.
    pub seconds: f64,
    /// Relative RMSE of the smooth-shaded image against the reference (luminance).
    pub relative_rmse: f64,
    /// (feature size in pixels, FBEM).
    pub fbem: Vec<(usize, f64)>,
    /// Solves the ε search took.
    pub solves: usize,
}

/// A finished run with its images.
pub struct RunImages {
    pub mesh: Image,
    pub smooth: Image,
}

/// Solves with the ε that brings the leaf count within `tolerance` of `target`. The leaf count falls as ε
/// grows, and fine solves cost far more than coarse ones, so the search starts coarse (ε = 1, relative to
/// the scene's emission) and divides by 8 until the mesh is fine enough, then bisects geometrically.
pub fn solve_at_target(
    scene: &Scene,
    base: &SimulationSettings,
    target: usize,
    tolerance: f64,
    max_solves: usize,
    progress: &Progress,
) -> Result<(Solution, f64, usize, f64)> {
    let mut eps = 1.0;
    let (mut low, mut high): (Option<f64>, Option<f64>) = (None, None); // low ε: too many leaves
    let mut best: Option<(Solution, f64, f64)> = None;
    let mut solves = 0;
    while solves < max_solves.max(1) {
        solves += 1;
        let settings = SimulationSettings {
            eps,
            ..base.clone()
        };
        let start = Instant::now();
        let solution = simulate(scene, &settings, progress)?;
        let seconds = start.elapsed().as_secs_f64();
        let leaves = solution.hierarchy.leaf_count();
        let miss = (leaves as f64 - target as f64).abs() / target as f64;
        let better = best.as_ref().is_none_or(|(b, _, _)| {
            miss < (b.hierarchy.leaf_count() as f64 - target as f64).abs() / target as f64
        });
        if better {
            best = Some((solution, eps, seconds));
        }
        if miss <= tolerance {
            break;
        }
        if leaves > target {
            low = Some(eps);
        } else {
            high = Some(eps);
        }
        eps = match (low, high) {
            (Some(l), Some(h)) => (l * h).sqrt(),
            (Some(l), None) => l * 8.0,
            (None, Some(h)) => h / 8.0,
            (None, None) => unreachable!("one bound was just set"),
        };
    }
    let (solution, eps, seconds) = best.expect("at least one solve");
    Ok((solution, eps, solves, seconds))
}

/// What every run is measured against: the view, the reference image of that view and its feature mask.
pub struct Yardstick<'a> {
    pub camera: &'a Camera,
    pub reference: &'a Image,
    pub features: &'a Mask,
}

/// Runs one oracle at one target: ε search, images, errors against the reference.
pub fn run_one(
    scene: &Scene,
    experiment: &OracleExperiment,
    oracle: OracleKind,
    samples: usize,
    target: usize,
    yardstick: &Yardstick,
    progress: &Progress,
) -> Result<(OracleRun, RunImages)> {
    let Yardstick {
        camera,
        reference,
        features,
    } = *yardstick;
    let base = SimulationSettings {
        oracle,
        oracle_samples: samples,
        // The paper's eq. (1), without the power oracle's visibility term.
        shadow_levels: 0.0,
        ..experiment.base.clone()
    };
    let (solution, eps, solves, seconds) = solve_at_target(
        scene,
        &base,
        target,
        experiment.tolerance,
        experiment.max_solves,
        progress,
    )?;
    let h = &solution.hierarchy;
    let vertices = VertexRadiosity::new(h);
    let draw = |shading, mesh| {
        let options = RenderOptions {
            shading,
            mesh,
            ..Default::default()
        };
        render_with(
            h,
            solution.visibility.as_ref(),
            camera,
            &options,
            Some(&vertices),
        )
    };
    let images = RunImages {
        mesh: draw(Shading::Flat, true),
        smooth: draw(Shading::Smooth, false),
    };
    let ignore = black_pixels(reference);
    let errors = compare(&images.smooth, reference, Some(&ignore))?;
    let fbem = experiment
        .fbem_sizes
        .iter()
        .map(|&size| {
            Ok((
                size,
                fbem::fbem(
                    &images.smooth,
                    reference,
                    features,
                    size,
                    2.0,
                    Some(&ignore),
                )?
                .value,
            ))
        })
        .collect::<Result<Vec<_>>>()?;
    let r = &solution.report;
    let run = OracleRun {
        oracle,
        oracle_samples: samples,
        target,
        eps,
        leaf_elements: h.leaf_count(),
        elements: h.elements.len(),
        links: h.link_count(),
        solution_rays: r.form_factor_rays + r.shooting_rays,
        oracle_rays: r.oracle_rays,
        seconds,
        relative_rmse: errors.luminance.relative_rmse.unwrap_or(f64::NAN),
        fbem,
        solves,
    };
    Ok((run, images))
}

/// The feature mask of a reference image used for the FBEM: shadows narrower than a quarter of the
/// image, found from the reference alone (`fbem::feature_mask_from_reference`).
pub fn reference_features(reference: &Image) -> Result<Mask> {
    let ignore = black_pixels(reference);
    let window = (reference.width.min(reference.height) / 4).max(1);
    fbem::feature_mask_from_reference(reference, window, 0.1, Some(&ignore))
}

/// The table as Markdown, one row per run.
pub fn markdown_table(runs: &[OracleRun]) -> String {
    let sizes: Vec<usize> = runs
        .first()
        .map(|r| r.fbem.iter().map(|f| f.0).collect())
        .unwrap_or_default();
    let mut out = String::from("| oracle | samples | target | ε | leaves | links | solution rays | oracle rays | time (s) | rel. RMSE |");
    for s in &sizes {
        out += &format!(" FBEM s={s} |");
    }
    out += "\n|---|---|---|---|---|---|---|---|---|---|";
    out += &"---|".repeat(sizes.len());
    out += "\n";
    for r in runs {
        out += &format!(
            "| {} | {} | {} | {:.3e} | {} | {} | {} | {} | {:.2} | {:.2}% |",
            oracle_name(r.oracle),
            r.oracle_samples,
            r.target,
            r.eps,
            r.leaf_elements,
            r.links,
            r.solution_rays,
            r.oracle_rays,
            r.seconds,
            r.relative_rmse * 100.0
        );
        for (_, v) in &r.fbem {
            out += &format!(" {v:.4} |");
        }
        out += "\n";
    }
    out
}

/// The command-line name of an oracle.
pub fn oracle_name(kind: OracleKind) -> &'static str {
    match kind {
        OracleKind::Power => "power",
        OracleKind::Smoothness => "smoothness",
        OracleKind::MutualInformation => "mi",
        OracleKind::Error => "error",
    }
}

/// Tiles images into a grid, `columns` wide, in row-major order, with a 4-pixel black gutter.
pub fn tile(images: &[&Image], columns: usize) -> Image {
    let columns = columns.max(1);
    let (w, h) = images.first().map_or((0, 0), |i| (i.width, i.height));
    let rows = images.len().div_ceil(columns);
    let gutter = 4;
    let mut out = Image::new(
        columns * (w + gutter) - gutter,
        (rows * (h + gutter)).saturating_sub(gutter),
    );
    for (k, image) in images.iter().enumerate() {
        let (ox, oy) = ((k % columns) * (w + gutter), (k / columns) * (h + gutter));
        for y in 0..h.min(image.height) {
            for x in 0..w.min(image.width) {
                out.set(ox + x, oy + y, image.get(x, y));
            }
        }
    }
    out
}
