//! From a scene to a solved hierarchy: builds the visibility structure and the hierarchy, picks the
//! oracle and solver named in the settings, and runs the hierarchical solve (deterministic, or
//! hierarchical Monte Carlo radiosity). The command line and the
//! tests share this one path.

use crate::hierarchy::Hierarchy;
use crate::oracles::mutual_information::MutualInformationOracle;
use crate::oracles::smoothness::SmoothnessOracle;
use crate::oracles::{power::PowerOracle, RefinementOracle};
use crate::progress::Progress;
use crate::scene::Scene;
use crate::solvers::coupling::CouplingSettings;
use crate::solvers::gathering::{GatheringSolver, GaussSeidel, Jacobi};
use crate::solvers::refine::RefineSettings;
use crate::solvers::stochastic::{solve_stochastic, StochasticSettings};
use crate::solvers::{solve, SolveReport, SolveSettings};
use crate::visibility::{brute_force::BruteForce, bvh::Bvh, Visibility};
use std::time::Instant;

/// Refinement criterion (`--oracle`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum OracleKind {
    /// Transported power, Feixas et al. eq. (1).
    Power,
    /// Kernel smoothness, Feixas et al. eq. (2).
    Smoothness,
    /// Mutual information (continuous minus discrete), Feixas et al. eq. (15).
    #[value(name = "mi", alias = "mutual-information")]
    #[serde(rename = "mi")]
    MutualInformation,
}

/// Solution method (`--method`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum MethodKind {
    /// Hierarchical radiosity: oracle-driven link refinement and gathering sweeps.
    Deterministic,
    /// Hierarchical Monte Carlo radiosity (Bekaert et al. 1998): stochastic Jacobi with local lines and
    /// per-ray refinement by the oracle.
    StochasticJacobi,
}

/// Linear solver (`--solver`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum SolverKind {
    Jacobi,
    GaussSeidel,
}

/// Ray casting back end (`--visibility`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum VisibilityKind {
    /// Our SAH bounding volume hierarchy.
    Bvh,
    /// Embree 3 (build with `--features embree`).
    #[cfg(feature = "embree")]
    Embree,
    /// Exhaustive test of every polygon (reference; only for tiny scenes).
    BruteForce,
}

/// Everything that determines a solution.
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct SimulationSettings {
    pub method: MethodKind,
    pub oracle: OracleKind,
    pub solver: SolverKind,
    pub visibility: VisibilityKind,
    /// Refinement threshold relative to the scene's total emission Σ A max(E) (radiance × area).
    pub eps: f64,
    /// Smallest splittable element area relative to the total patch area.
    pub min_area: f64,
    /// Gauss points per direction on receivers for form factors.
    pub receiver_order: usize,
    /// Visibility rays per receiver node.
    pub visibility_rays: usize,
    /// Random point pairs per evaluation of the sampling oracles (eqs. (2) and (15); the paper uses 10).
    pub oracle_samples: usize,
    /// Relative change of total power at which sweeps stop; for stochastic Jacobi, the fraction of the
    /// emitted power left unshot at which iterations stop.
    pub tolerance: f64,
    pub max_iterations: usize,
    pub max_passes: usize,
    /// Stochastic Jacobi: lines shot in the first iteration (later ones in proportion to their power).
    pub rays_per_iteration: u64,
    /// Stochastic Jacobi: most iterations.
    pub stochastic_iterations: usize,
    pub seed: u64,
}

impl Default for SimulationSettings {
    fn default() -> Self {
        SimulationSettings {
            method: MethodKind::Deterministic,
            oracle: OracleKind::Power,
            solver: SolverKind::GaussSeidel,
            visibility: VisibilityKind::Bvh,
            eps: 1e-3,
            min_area: 1e-5,
            receiver_order: 2,
            visibility_rays: 4,
            oracle_samples: 10,
            tolerance: 1e-5,
            max_iterations: 200,
            max_passes: 12,
            rays_per_iteration: 100_000,
            stochastic_iterations: 100,
            seed: 1,
        }
    }
}

/// A solved scene.
pub struct Solution {
    pub hierarchy: Hierarchy,
    pub visibility: Box<dyn Visibility>,
    pub report: SolveReport,
    /// Seconds spent building the visibility structure.
    pub visibility_seconds: f64,
}

/// Builds the ray-casting structure over the scene's polygons.
pub fn build_visibility(
    scene: &Scene,
    kind: VisibilityKind,
) -> anyhow::Result<Box<dyn Visibility>> {
    let shapes: Vec<_> = scene.polygons.iter().map(|p| p.shape).collect();
    Ok(match kind {
        VisibilityKind::Bvh => Box::new(Bvh::new(&shapes)),
        #[cfg(feature = "embree")]
        VisibilityKind::Embree => Box::new(crate::visibility::embree::EmbreeScene::new(&shapes)?),
        VisibilityKind::BruteForce => Box::new(BruteForce::new(shapes)),
    })
}

/// The oracle named in `settings` for refining `hierarchy` (eq. (2) takes its reference area from it).
pub fn make_oracle(
    settings: &SimulationSettings,
    hierarchy: &Hierarchy,
) -> Box<dyn RefinementOracle> {
    let samples = settings.oracle_samples;
    match settings.oracle {
        OracleKind::Power => Box::new(PowerOracle),
        OracleKind::Smoothness => Box::new(SmoothnessOracle::for_hierarchy(samples, hierarchy)),
        OracleKind::MutualInformation => Box::new(MutualInformationOracle::new(samples)),
    }
}

pub fn make_solver(kind: SolverKind) -> Box<dyn GatheringSolver> {
    match kind {
        SolverKind::Jacobi => Box::new(Jacobi),
        SolverKind::GaussSeidel => Box::new(GaussSeidel),
    }
}

/// The deterministic solver's settings for absolute refinement `threshold` and `min_area` (`simulate`
/// derives both from the relative `eps` and `min_area` of `settings`).
pub fn deterministic_settings(
    settings: &SimulationSettings,
    threshold: f64,
    min_area: f64,
) -> SolveSettings {
    SolveSettings {
        refine: RefineSettings {
            threshold,
            min_area,
            coupling: CouplingSettings {
                receiver_order: settings.receiver_order,
                visibility_rays: settings.visibility_rays,
            },
            seed: settings.seed,
        },
        tolerance: settings.tolerance,
        max_iterations: settings.max_iterations,
        max_passes: settings.max_passes,
    }
}

/// Runs hierarchical radiosity on `scene`.
pub fn simulate(
    scene: &Scene,
    settings: &SimulationSettings,
    progress: &Progress,
) -> anyhow::Result<Solution> {
    let start = Instant::now();
    let visibility = build_visibility(scene, settings.visibility)?;
    let visibility_seconds = start.elapsed().as_secs_f64();
    let mut hierarchy = Hierarchy::new(scene, 1);
    let threshold = settings.eps * hierarchy.total_emission();
    let min_area = settings.min_area * hierarchy.total_area();
    let oracle = make_oracle(settings, &hierarchy);
    if settings.method == MethodKind::StochasticJacobi {
        let stochastic = StochasticSettings {
            threshold,
            min_area,
            rays_per_iteration: settings.rays_per_iteration,
            max_iterations: settings.stochastic_iterations,
            tolerance: settings.tolerance,
            seed: settings.seed,
        };
        let report = solve_stochastic(
            &mut hierarchy,
            visibility.as_ref(),
            oracle.as_ref(),
            &stochastic,
            progress,
        );
        return Ok(Solution {
            hierarchy,
            visibility,
            report,
            visibility_seconds,
        });
    }
    let solve_settings = deterministic_settings(settings, threshold, min_area);
    let solver = make_solver(settings.solver);
    let report = solve(
        &mut hierarchy,
        visibility.as_ref(),
        oracle.as_ref(),
        solver.as_ref(),
        &solve_settings,
        progress,
    );
    Ok(Solution {
        hierarchy,
        visibility,
        report,
        visibility_seconds,
    })
}
