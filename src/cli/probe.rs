//! `radiosity probe [SCENE] --points pts.csv|--random N|--seen N [--reference --spp N]`: the
//! radiosity solution's radiance at given surface points (or random ones: over all surfaces, or where
//! the camera looks), or with `--final-gather` what a gather of the solution finds at each point,
//! optionally beside the unbiased path-traced estimate.

use super::args::{cache_settings, CameraArgs, GatherArgs, SceneArgs, SolveArgs};
use crate::color::Units;
use crate::geometry::DVec3;
use crate::measures::illuminance::{
    final_gather, probe_gather_points, probe_photometry, IrradianceGather,
};
use crate::measures::irradiance_cache::CacheSettings;
use crate::measures::point_errors::{point_errors, LIT_FRACTION};
use crate::output::render::{radiance_as_rendered, RenderOptions, Shading};
use crate::pipeline::simulate;
use crate::progress::Progress;
use crate::reference::probe::{
    attach_stored_reference, probe_points, random_points, read_points, read_stored_points,
    seen_points, ProbeReference,
};
use crate::solvers::{allowed_error, LOCAL_ACCURACY_FLOOR};
use anyhow::{Context, Result};
use clap::Args;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct ProbeCommand {
    #[command(flatten)]
    pub scene: SceneArgs,
    #[command(flatten)]
    pub solve: SolveArgs,
    /// Points file: one `x y z nx ny nz` per line (whitespace or commas, `#` comments); the normal points
    /// out of the probed side.
    #[arg(long, value_name = "FILE", required_unless_present_any = ["random", "seen", "against"])]
    pub points: Option<PathBuf>,
    /// Instead of a points file: N points uniform by area over the surfaces that do not emit (each side
    /// of a two-sided polygon by its area), from --seed.
    #[arg(long, value_name = "N", conflicts_with = "points", value_parser = super::args::count(1, 1_000_000))]
    pub random: Option<usize>,
    /// Instead of a points file: N points the camera sees (the first non-emitting surface along rays
    /// through uniformly random image positions; the camera options as for `render`), from --seed:
    /// the error where a viewer looks.
    #[arg(long, value_name = "N", conflicts_with_all = ["points", "random"], value_parser = super::args::count(1, 1_000_000))]
    pub seen: Option<usize>,
    #[command(flatten)]
    pub camera: CameraArgs,
    /// Also estimate the radiance by unbiased path tracing, with its standard error.
    #[arg(long)]
    pub reference: bool,
    /// A stored reference: the JSON of an earlier `probe --reference --json` at the same points (same
    /// scene, --points, --random N or --seen N with the same camera, and --seed), compared instead of
    /// path tracing anew. Alone (without --points, --random or --seen) it probes the reference's own
    /// points, with any --seed: the solution's noise over seeds at fixed points.
    #[arg(long, value_name = "REF.json", conflicts_with = "reference")]
    pub against: Option<PathBuf>,
    /// Paths per point for `--reference` (rounded up to a multiple of 16).
    #[arg(long, default_value_t = 16384, value_name = "N", value_parser = super::args::count(0, 1 << 24))]
    pub spp: usize,
    /// Print JSON instead of the table.
    #[arg(long)]
    pub json: bool,
    /// Radiometric: radiance per channel, W/(m² sr). Photometric: also luminance (cd/m²) and the
    /// illuminance arriving at the point (lux, gathered from the solution, with its estimated error).
    #[arg(long, value_enum, default_value_t = Units::Radiometric)]
    pub units: Units,
    /// Each point's radiance by a final gather of the solution at the point (its emission plus ρ/π
    /// times the irradiance gathered hierarchically from the solved radiances, with exact factors
    /// and visibility rays; `measures::illuminance::final_gather`) instead of its leaf's value, and
    /// its error estimate the gather's.
    #[arg(long)]
    pub final_gather: bool,
    /// With --final-gather: each point's radiance as `render --final-gather` shows it through this
    /// camera (--width, --height, --eye, ...): the default seamless shading plus the correction its
    /// irradiance cache interpolates between records placed at that camera's pixels (errors still the
    /// leaves' estimates). With --seen, what the image shows at the points it sees.
    #[arg(long, requires = "final_gather")]
    pub cached: bool,
    /// With --cached: Ward's a (`render --cache-accuracy`).
    #[arg(long, requires = "cached", value_name = "A", default_value_t = CacheSettings::default().accuracy)]
    pub cache_accuracy: f64,
    #[command(flatten)]
    pub gather: GatherArgs,
}

impl ProbeCommand {
    pub fn run(&self, seed: u64, progress: &Progress) -> Result<()> {
        anyhow::ensure!(
            !self.reference || self.spp >= 2,
            "--spp must be at least 2 (the standard error needs two samples)"
        );
        let (scene, name) = self.scene.load_for_solving(progress)?;
        // Whether the points are the stored reference's own (`--against` alone): then `--seed` varies
        // the solve at one point set, which says nothing of another set (a note in the header).
        let own_points = self.points.is_none() && self.random.is_none() && self.seen.is_none();
        let camera = self.camera.camera(&scene, 512)?;
        let cache = self
            .cached
            .then(|| cache_settings(self.cache_accuracy, self.solve.method))
            .transpose()?;
        if cache.is_some() {
            super::args::check_gathered_samples(camera.width, camera.height, 1)?;
        }
        let (points, file) = match (&self.points, self.random, self.seen) {
            (Some(path), _, _) => (read_points(path)?, path.clone()),
            (None, Some(n), _) => (
                random_points(&scene, n, seed),
                PathBuf::from("random points"),
            ),
            (None, None, Some(n)) => {
                let points = seen_points(&scene, &camera, n, seed);
                anyhow::ensure!(
                    !points.is_empty(),
                    "the camera sees no surface that does not emit: give --eye/--look-at"
                );
                if points.len() < n {
                    crate::progress::stderr_line(format_args!(
                        "warning: {name}: only {} of {n} points found (the camera sees mostly \
                         background or emitters)",
                        points.len()
                    ));
                }
                (points, PathBuf::from("points seen by the camera"))
            }
            (None, None, None) => match &self.against {
                Some(path) => (read_stored_points(path)?, path.clone()),
                None => {
                    anyhow::bail!("give --points FILE, --random N, --seen N or --against REF.json")
                }
            },
        };
        let gather_settings = self.gather.settings(self.cached, seed)?;
        let settings = self.solve.settings(seed)?;
        let solution = simulate(&scene, &settings, progress)?;
        let reference = self.reference.then_some(ProbeReference {
            spp: self.spp,
            seed,
        });
        let mut results = probe_points(
            &scene,
            solution.visibility.as_ref(),
            &solution.hierarchy,
            &points,
            reference,
            &file,
        )?;
        if let Some(path) = &self.against {
            attach_stored_reference(&mut results, path)?;
        }
        // The irradiance at the points, once, for the final gather and the illuminance column.
        let gathered = ((self.final_gather && !self.cached) || self.units == Units::Photometric)
            .then(|| {
                let start = std::time::Instant::now();
                let gather = IrradianceGather::new(
                    &solution.hierarchy,
                    solution.visibility.as_ref(),
                    gather_settings,
                );
                let irradiance = gather.at_all(&probe_gather_points(&results));
                (irradiance, start.elapsed().as_secs_f64())
            });
        let gather_note = match (cache, &gathered) {
            (Some(cache), _) => {
                let start = std::time::Instant::now();
                let options = RenderOptions {
                    shading: Shading::Seamless,
                    final_gather: Some(gather_settings),
                    gather_cache: Some(cache),
                    seed,
                    ..Default::default()
                };
                let h = &solution.hierarchy;
                let points: Vec<(u32, DVec3)> = results
                    .iter()
                    .map(|r| {
                        let patch = h.patch_for_side(r.polygon, r.front).context("a patch")?;
                        Ok((patch, h.onto_patch_plane(patch, DVec3::from_array(r.point))))
                    })
                    .collect::<Result<_>>()?;
                let visibility = solution.visibility.as_ref();
                let (radiances, report) =
                    radiance_as_rendered(h, visibility, &camera, &options, &points);
                for (r, radiance) in results.iter_mut().zip(radiances) {
                    r.radiosity = radiance;
                }
                format!(
                    "\n# final gather as rendered: seamless shading plus the correction cached at {} \
                     records for a {}x{} image ({:.2} s)",
                    report.gather_records,
                    camera.width,
                    camera.height,
                    start.elapsed().as_secs_f64()
                )
            }
            (None, Some((irradiance, seconds))) if self.final_gather => {
                final_gather(&solution.hierarchy, &mut results, irradiance);
                let rays: u64 = irradiance.iter().map(|e| u64::from(e.rays)).sum();
                format!(
                    "\n# final gather: radiance = emission + ρ/π × the irradiance gathered from the \
                     solution at each point ({rays} rays, {seconds:.2} s)"
                )
            }
            _ => String::new(),
        };
        let compared = self.reference || self.against.is_some();
        let h = &solution.hierarchy;
        let points_note = if own_points {
            " (the reference's own: --seed changes the solve, not the points; another set needs its \
             own reference)"
        } else {
            ""
        };
        let solved = format!(
            "# solution: {}; {} elements ({} leaves), {} links, {} passes",
            super::render::error_summary(
                &solution.report.error,
                self.units,
                crate::pipeline::mean_radiance_estimate(h)
            ),
            h.elements.len(),
            h.leaf_count(),
            h.link_count(),
            solution.report.passes
        ) + &gather_note;
        if self.units == Units::Photometric {
            let (irradiance, _) = gathered.as_ref().expect("gathered for photometric units");
            let photometry = probe_photometry(&results, irradiance);
            if self.json {
                let rows: Vec<_> = results
                    .iter()
                    .zip(&photometry)
                    .map(|(r, p)| serde_json::json!({"probe": r, "photometric": p}))
                    .collect();
                outln!("{}", serde_json::to_string_pretty(&rows)?)?;
                return Ok(());
            }
            outln!(
                "# {name}: {} points{points_note}; luminance cd/m², illuminance lux (179 lm/W × Y)",
                results.len()
            )?;
            outln!("{solved}")?;
            out!(
                "{:>5} {:>30} {:>6} {:>12} {:>12} {:>10}",
                "line",
                "point",
                "poly",
                "luminance",
                "illuminance",
                "± error"
            )?;
            if compared {
                out!(" {:>12} {:>10}", "reference", "stderr")?;
            }
            outln!()?;
            for (r, p) in results.iter().zip(&photometry) {
                let point = format!("{:.4} {:.4} {:.4}", r.point[0], r.point[1], r.point[2]);
                let side = if r.front { "" } else { "b" };
                out!(
                    "{:>5} {point:>30} {:>6} {:>12.4} {:>12.4} {:>10.4}",
                    r.line,
                    format!("{}{side}", r.polygon),
                    p.luminance,
                    p.illuminance,
                    p.illuminance_error
                )?;
                if let Some(e) = p.reference_luminance {
                    out!(" {:>12.4} {:>10.4}", e.value, e.stderr)?;
                }
                outln!()?;
            }
            return Ok(());
        }
        if self.json {
            outln!("{}", serde_json::to_string_pretty(&results)?)?;
            return Ok(());
        }
        outln!("# {name}: {} points{points_note}", results.len())?;
        outln!("{solved}")?;
        out!(
            "{:>5} {:>30} {:>6} {:>35}",
            "line",
            "point",
            "poly",
            "radiosity (r g b)"
        )?;
        if compared {
            out!(
                " {:>35} {:>35} {:>6}",
                "reference (r g b)",
                "stderr (r g b)",
                "z"
            )?;
        }
        outln!()?;
        let triple = |v: [f64; 3]| format!("{:>11.4e} {:>11.4e} {:>11.4e}", v[0], v[1], v[2]);
        for r in &results {
            let point = format!("{:.4} {:.4} {:.4}", r.point[0], r.point[1], r.point[2]);
            let side = if r.front { "" } else { "b" };
            out!(
                "{:>5} {point:>30} {:>6} {}",
                r.line,
                format!("{}{side}", r.polygon),
                triple(r.radiosity.to_array())
            )?;
            if let Some(e) = r.reference {
                // Largest deviation of the radiosity value in standard errors of the reference.
                let z = (0..3)
                    .map(|c| {
                        let d = r.radiosity.to_array()[c] - e.mean.to_array()[c];
                        let s = e.stderr.to_array()[c];
                        if s > 0.0 {
                            d.abs() / s
                        } else if d == 0.0 {
                            0.0
                        } else {
                            f64::INFINITY
                        }
                    })
                    .fold(0.0, f64::max);
                out!(
                    " {} {} {z:>6.2}",
                    triple(e.mean.to_array()),
                    triple(e.stderr.to_array())
                )?;
            }
            outln!()?;
        }
        if let (true, Some(accuracy)) = (compared, solution.report.error.accuracy) {
            let local = solution.report.error.local_accuracy;
            let within = results
                .iter()
                .filter(|r| {
                    r.reference.is_some_and(|e| {
                        within_accuracy(
                            r.radiosity,
                            e,
                            allowed_error(accuracy, local, e.mean.max_channel()),
                        )
                    })
                })
                .count();
            let and_local = local.map_or(String::new(), |p| {
                format!(
                    " and {:.0}% of the reference's radiance (down to {:.0}% of it)",
                    100.0 * p,
                    100.0 * LOCAL_ACCURACY_FLOOR
                )
            });
            outln!(
                "# {within} of {} points within the accuracy {} W/m²sr{and_local} \
                 (largest channel, allowing two standard errors of the reference); Bekaert–Willems \
                 promise at least 95%",
                results.len(),
                super::render::significant(accuracy)
            )?;
        }
        if compared {
            // Whether the error bar holds: the estimate is realistic, not a bound (§4.3).
            let within = results
                .iter()
                .filter(|r| {
                    r.reference
                        .is_some_and(|e| within_accuracy(r.radiosity, e, r.estimated_error))
                })
                .count();
            outln!(
                "# {within} of {} points within their a-posteriori error estimate (largest channel, \
                 allowing two standard errors of the reference)",
                results.len()
            )?;
        }
        let pairs = results
            .iter()
            .filter_map(|r| r.reference.map(|e| (r.radiosity, e.mean)));
        if let Some(e) = point_errors(pairs) {
            outln!(
                "# luminance error at {} lit points (reference above {:.0}% of the mean {:.4e}): RMS \
                 {:.2}%, median {:.2}%, 90th percentile {:.2}%, largest {:.1}%, mean signed {:+.2}%",
                e.lit_points,
                100.0 * LIT_FRACTION,
                e.mean_reference,
                100.0 * e.relative_rms,
                100.0 * e.relative_median,
                100.0 * e.relative_p90,
                100.0 * e.relative_max,
                100.0 * e.relative_mean_signed
            )?;
            outln!(
                "# |error| / mean reference over {} points: RMS {:.2}%, 95th percentile {:.2}%, \
                 largest {:.1}% (the reference's noise not removed)",
                e.points,
                100.0 * e.absolute_rms,
                100.0 * e.absolute_p95,
                100.0 * e.absolute_max
            )?;
            if e.black_points > 0 {
                outln!(
                    "# {} points the reference finds black, left out above: the solution's largest \
                     luminance there is {:.2}% of the mean reference",
                    e.black_points,
                    100.0 * e.black_largest
                )?;
            }
        }
        Ok(())
    }
}

/// Whether the solution is within `accuracy` (the one asked for, or a point's estimated error) of the
/// reference in every channel, up to twice the reference's standard error (its resolution).
fn within_accuracy(
    radiosity: crate::color::Rgb,
    reference: crate::reference::Estimate,
    accuracy: f64,
) -> bool {
    (0..3).all(|c| {
        let d = (radiosity.to_array()[c] - reference.mean.to_array()[c]).abs();
        d <= accuracy + 2.0 * reference.stderr.to_array()[c]
    })
}
