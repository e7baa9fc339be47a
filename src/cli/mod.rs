//! Command line: `render` (default), `info`, `bench`. Every subcommand has `--help`; failures print one
//! line `error: ...` with the file, line and reason where there is one, and exit with status 1.

/// `println!` to stdout that returns the I/O error (a closed pipe) instead of panicking.
macro_rules! outln {
    () => {
        std::io::Write::write_all(&mut std::io::stdout().lock(), b"\n")
    };
    ($($arg:tt)*) => {
        std::io::Write::write_fmt(&mut std::io::stdout().lock(), format_args!("{}\n", format_args!($($arg)*)))
    };
}

/// `print!` to stdout that returns the I/O error instead of panicking.
macro_rules! out {
    ($($arg:tt)*) => {
        std::io::Write::write_fmt(&mut std::io::stdout().lock(), format_args!($($arg)*))
    };
}

mod args;
mod audit;
mod bench;
mod compare;
mod experiment;
mod grid;
mod info;
mod measure;
mod plot;
mod probe;
mod reference;
mod render;
mod scene;
mod view;

pub use args::parse_vec3;

use crate::progress::Progress;
use anyhow::{Context, Result};
use clap::{Parser, Subcommand};

/// Hierarchical radiosity: refinement oracles, error control and feature-based visibility.
#[derive(Parser, Debug)]
#[command(name = "radiosity", version, about, long_about = None)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Option<Command>,
    /// Worker threads (default: all cores). Results do not depend on it.
    #[arg(long, global = true, value_name = "N", value_parser = args::count(1, 1024))]
    pub threads: Option<usize>,
    /// Seed of every random choice; the same seed gives the same result.
    #[arg(long, global = true, default_value_t = 1)]
    pub seed: u64,
    /// No progress bars or summaries.
    #[arg(long, short, global = true)]
    pub quiet: bool,
}

// Parsed once per run: the size difference between variants does not matter.
#[allow(clippy::large_enum_variant)]
#[derive(Subcommand, Debug)]
pub enum Command {
    /// Solve a scene (the built-in Cornell box by default) and render it to PNG / EXR / PLY / glTF.
    Render(render::RenderCommand),
    /// Print counts, bounds and materials of a scene.
    Info(info::InfoCommand),
    /// Measure BVH build time, ray throughput and full render times.
    Bench(bench::BenchCommand),
    /// Reproduce a paper's experiment with tables and images.
    Experiment(experiment::ExperimentCommand),
    /// Error metrics of an image against a reference, false-colour error image, feature-based error.
    Compare(compare::CompareCommand),
    /// Render an unbiased path-traced reference image (radiance at pixel centres, with standard errors).
    Reference(reference::ReferenceCommand),
    /// Print the radiosity solution's radiance (and a path-traced reference) at given surface points.
    Probe(probe::ProbeCommand),
    /// Information-theoretic scene measures: discrete and continuous mutual information, Δ (Feixas et al.).
    Measure(measure::MeasureCommand),
    /// Solve, then compare the couplings of the links into chosen polygons with an unbiased Monte Carlo
    /// estimate with visibility, per source polygon.
    Audit(audit::AuditCommand),
    /// Write a test scene with a known answer (plates, furnace, Cornell box, shadow groups) as MGF.
    Scene(scene::SceneCommand),
    /// Chart one field of run statistics against another (error vs time or elements) as SVG.
    Plot(plot::PlotCommand),
    /// Illuminance (lux) on a work-plane grid with an error per point: CSV, JSON and an isolux plot.
    Grid(grid::GridCommand),
    /// Solve a scene, write the interactive viewer page (HTML, WebGL) and open it in the browser.
    View(view::ViewCommand),
}

/// Runs the command line and returns the process exit code.
pub fn main() -> i32 {
    crate::memory::keep_large_blocks_mapped();
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => 0,
        // A reader that went away (`radiosity info ... | head`) is not a failure: stop quietly.
        Err(error) if is_broken_pipe(&error) => 0,
        Err(error) => {
            crate::progress::stderr_line(format_args!("error: {error:#}"));
            1
        }
    }
}

/// Whether `error` is, or was caused by, a write to a closed pipe.
fn is_broken_pipe(error: &anyhow::Error) -> bool {
    error.chain().any(|e| {
        e.downcast_ref::<std::io::Error>()
            .is_some_and(|e| e.kind() == std::io::ErrorKind::BrokenPipe)
    })
}

/// Runs a parsed command line on a thread pool of the requested size.
pub fn run(cli: Cli) -> Result<()> {
    let mut pool = rayon::ThreadPoolBuilder::new();
    if let Some(n) = cli.threads {
        anyhow::ensure!(n > 0, "--threads must be at least 1");
        pool = pool.num_threads(n);
    }
    let pool = pool.build().context("starting the thread pool")?;
    let progress = Progress::new(cli.quiet);
    let seed = cli.seed;
    // Without a subcommand: render the built-in Cornell box with the defaults.
    let command = match cli.command {
        Some(command) => command,
        None => Cli::try_parse_from(["radiosity", "render"])?
            .command
            .context("default command")?,
    };
    pool.install(|| match command {
        Command::Render(c) => c.run(seed, &progress),
        Command::Info(c) => c.run(),
        Command::Bench(c) => c.run(seed, &progress),
        Command::Compare(c) => c.run(),
        Command::Experiment(c) => c.run(seed, &progress),
        Command::Reference(c) => c.run(seed, &progress),
        Command::Probe(c) => c.run(seed, &progress),
        Command::Measure(c) => c.run(seed, &progress),
        Command::Audit(c) => c.run(seed, &progress),
        Command::Scene(c) => c.run(),
        Command::Plot(c) => c.run(),
        Command::Grid(c) => c.run(seed, &progress),
        Command::View(c) => c.run(seed, &progress),
    })
}
