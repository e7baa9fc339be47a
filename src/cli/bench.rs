//! `radiosity bench`: BVH build time and occlusion-ray throughput (`rays`), and full render times of whole
//! scenes (`render`), printed as Markdown table rows for BENCHMARKS.md. Speed is measured here, never
//! asserted in tests.

use super::args::{SceneArgs, SolveArgs};
use crate::output::camera::Camera;
use crate::output::render::{render, RenderOptions, Shading};
use crate::pipeline::{build_visibility, simulate, VisibilityKind};
use crate::progress::Progress;
use crate::scene::{self, LoadOptions};
use crate::visibility::bench::{agreeing_segments, random_segments, rates_in_turns, timed, Query};
use crate::visibility::Visibility;
use anyhow::Result;
use clap::{Args, Subcommand};
use std::path::PathBuf;
use std::time::Instant;

#[derive(Args, Debug)]
pub struct BenchCommand {
    #[command(subcommand)]
    pub what: BenchKind,
}

#[derive(Subcommand, Debug)]
pub enum BenchKind {
    /// Build time and occlusion rays per second of the ray-casting back ends on one scene.
    Rays(RaysBench),
    /// Full solve + render time of each scene (the built-in Cornell box when none is given).
    Render(RenderBench),
}

#[derive(Args, Debug)]
pub struct RaysBench {
    #[command(flatten)]
    pub scene: SceneArgs,
    /// Random polygon-to-polygon segments to cast.
    #[arg(long, default_value_t = 2_000_000, value_parser = super::args::count(1, 1_000_000_000))]
    pub rays: usize,
    /// Back ends to measure (repeatable).
    #[arg(long = "backend", value_enum, default_values_t = [VisibilityKind::Bvh])]
    pub backends: Vec<VisibilityKind>,
    /// Measurement rounds; within a round the back ends cast the segments in turns, a block of 32,768
    /// at a time each, so that load from other processes and changes of the machine's speed hit them
    /// alike and the ratio to the first back end holds (`visibility::bench::rates_in_turns`).
    #[arg(long, default_value_t = 1, value_parser = super::args::count(1, 100))]
    pub repeat: usize,
    /// Time the back ends only on the segments where they all give the same answer (how many do not
    /// is printed first): a back end that stops at a hit the exact answer does not have (Embree's
    /// single precision on office3: 5% of the segments) does less work than one that is right.
    #[arg(long)]
    pub agreeing: bool,
}

#[derive(Args, Debug)]
pub struct RenderBench {
    /// Scene files; "cornell" names the built-in Cornell box.
    #[arg(default_values_t = ["cornell".to_string()])]
    pub scenes: Vec<String>,
    #[command(flatten)]
    pub solve: SolveArgs,
    #[arg(long, default_value_t = 512, value_parser = super::args::count(1, super::args::MAX_IMAGE_SIDE))]
    pub width: usize,
    #[arg(long, default_value_t = 512, value_parser = super::args::count(1, super::args::MAX_IMAGE_SIDE))]
    pub height: usize,
}

impl BenchCommand {
    pub fn run(&self, seed: u64, progress: &Progress) -> Result<()> {
        match &self.what {
            BenchKind::Rays(b) => b.run(seed),
            BenchKind::Render(b) => b.run(seed, progress),
        }
    }
}

impl RaysBench {
    fn run(&self, seed: u64) -> Result<()> {
        let (scene, name) = self.scene.load()?;
        let shapes: Vec<_> = scene.polygons.iter().map(|p| p.shape).collect();
        let triangles: usize = shapes.iter().map(|s| s.vertex_count() - 2).sum();
        let mut segments = random_segments(&shapes, self.rays, seed);
        let mut backends = Vec::with_capacity(self.backends.len());
        for &kind in &self.backends {
            let (visibility, build_seconds) = timed(|| build_visibility(&scene, kind));
            backends.push((visibility?, build_seconds));
        }
        let views: Vec<&dyn Visibility> = backends.iter().map(|(v, _)| v.as_ref()).collect();
        if self.agreeing {
            let before = segments.len();
            segments = agreeing_segments(&views, segments);
            outln!(
                "# {} of {before} segments answered differently by the back ends, left out",
                before - segments.len()
            )?;
            anyhow::ensure!(!segments.is_empty(), "the back ends agree on no segment");
        }
        outln!(
            "| scene | polygons (triangles) | back end | build (s) | memory (MB) | threads | round | rays/s | vs first | blocked |"
        )?;
        outln!("|---|---|---|---|---|---|---|---|---|---|")?;
        let all = rayon::current_num_threads();
        let thread_counts = if all > 1 { vec![1, all] } else { vec![1] };
        for round in 1..=self.repeat {
            for &threads in &thread_counts {
                let rates = rates_in_turns(&views, &segments, threads, Query::Occlusion)?;
                let first = rates[0].rays_per_second;
                for ((visibility, build_seconds), r) in backends.iter().zip(&rates) {
                    let memory = visibility
                        .memory_bytes()
                        .map_or("–".to_string(), |b| format!("{:.1}", b as f64 / 1e6));
                    outln!(
                        "| {name} | {} ({triangles}) | {} | {build_seconds:.3} | {memory} | {threads} | {round} | {:.3} M | {:.0}% | {} |",
                        shapes.len(),
                        visibility.name(),
                        r.rays_per_second / 1e6,
                        100.0 * r.rays_per_second / first,
                        r.blocked
                    )?;
                }
            }
        }
        Ok(())
    }
}

impl RenderBench {
    fn run(&self, seed: u64, progress: &Progress) -> Result<()> {
        let settings = self.solve.settings(seed)?;
        super::args::check_pixels(self.width, self.height)?;
        outln!("| scene | polygons | elements | leaves | links | rays | load (s) | solve (s) | render (s) | total (s) |")?;
        outln!("|---|---|---|---|---|---|---|---|---|---|")?;
        for name in &self.scenes {
            let start = Instant::now();
            let mut scene = if name == "cornell" {
                scene::cornell::cornell_box()
            } else {
                scene::load(&PathBuf::from(name), &LoadOptions::default())?
            };
            // The CLI's default: cut only along contacts that would leak emitted light.
            scene::contacts::split_contacts(
                &mut scene,
                scene::contacts::SplitContacts::Auto,
                scene::contacts::DEFAULT_CONTACT_GAP,
            );
            let load = start.elapsed().as_secs_f64();
            let solution = simulate(&scene, &settings, progress)?;
            let solve = start.elapsed().as_secs_f64() - load;
            let spec = scene
                .camera
                .unwrap_or_else(|| Camera::auto_view(&scene, 50.0));
            let camera = Camera::new(&spec, self.width, self.height);
            let options = RenderOptions {
                shading: Shading::Smooth,
                ..Default::default()
            };
            let (_, render_seconds) = timed(|| {
                render(
                    &solution.hierarchy,
                    solution.visibility.as_ref(),
                    &camera,
                    &options,
                )
            });
            let h = &solution.hierarchy;
            let r = &solution.report;
            outln!(
                "| {name} | {} | {} | {} | {} | {} | {load:.3} | {solve:.3} | {render_seconds:.3} | {:.3} |",
                scene.polygons.len(),
                h.elements.len(),
                h.leaf_count(),
                h.link_count(),
                r.form_factor_rays + r.oracle_rays + r.shooting_rays,
                start.elapsed().as_secs_f64()
            )?;
        }
        Ok(())
    }
}
