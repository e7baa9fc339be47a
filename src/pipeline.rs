//! From a scene to a solved hierarchy: builds the visibility structure and the hierarchy, picks the
//! oracle and solver named in the settings, and runs the hierarchical solve (deterministic, or
//! hierarchical Monte Carlo radiosity). The command line and the
//! tests share this one path.

use crate::bases::BasisKind;
use crate::geometry::near_field::NearField;
use crate::hierarchy::clusters::{ClusterTreeKind, ClusteringKind};
use crate::hierarchy::{ErrorStorage, Hierarchy};
use crate::memory::MemoryBudget;
use crate::oracles::link_error::LinkErrorOracle;
use crate::oracles::mutual_information::MutualInformationOracle;
use crate::oracles::smoothness::SmoothnessOracle;
use crate::oracles::{power::PowerOracle, RefinementOracle};
use crate::progress::Progress;
use crate::scene::Scene;
use crate::solvers::coupling::{CouplingSettings, SourceRule};
use crate::solvers::error_estimate::EstimateKind;
use crate::solvers::gathering::{GatheringSolver, GaussSeidel, Jacobi, OverRelaxed, Southwell};
use crate::solvers::multigrid::{solve_progressive, MultigridSettings, StepReport};
use crate::solvers::refine::{OutlineRule, RefineSettings};
use crate::solvers::stochastic::{solve_stochastic, StochasticSettings};
use crate::solvers::{solve, ErrorControl, SolveReport, SolveSettings};
use crate::visibility::extinction::Extinction;
use crate::visibility::item_buffer::{IntraClusterKind, ItemBuffers};
use crate::visibility::multires::{Averaging, Multires, SurfaceFeatureSize};
use crate::visibility::shaft::{ShaftCulled, ShaftCuller, VisibilityReuse};
use crate::visibility::{brute_force::BruteForce, bvh::Bvh, Visibility};
use std::sync::Arc;
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
    /// Link error from the coupling's error coefficients, Bekaert–Willems eq. (13), with error control
    /// (algorithm 6.1) to the accuracy asked for.
    Error,
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
    /// Every element gathers from the previous iterate, in parallel.
    Jacobi,
    /// Patches in order, each seeing the updates of those before it.
    GaussSeidel,
    /// Gauss–Seidel with each patch's step extrapolated by a factor ω from 1.2 to 1.8, learned from
    /// the sweeps' rate (successive over-relaxation, Young's adaptive form): the same solution in
    /// fewer sweeps, far fewer in bright rooms.
    Sor,
    /// The patch with the largest change first.
    Southwell,
}

/// The accuracy error control aims at (`--accuracy`).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Accuracy {
    /// Absolute radiance error, W/(m² sr) (scene units).
    Absolute(f64),
    /// A fraction of the scene's mean radiance (`--accuracy 2%` is 0.02).
    Relative(f64),
}

impl Accuracy {
    /// The absolute radiance error for `hierarchy`: a relative accuracy is taken of the mean radiance
    /// the energy balance predicts before solving, `L̄ = Φ_e / (π A_T (1 − ρ̄))` with ρ̄ the
    /// area-weighted mean reflectance (exact for a closed room of uniform reflectance), averaged over
    /// the colour channels.
    pub fn absolute(self, hierarchy: &Hierarchy) -> f64 {
        match self {
            Accuracy::Absolute(value) => value,
            Accuracy::Relative(fraction) => fraction * mean_radiance_estimate(hierarchy),
        }
    }
}

/// `Φ_e / (π A_T (1 − ρ̄))`, mean over channels (see [`Accuracy::absolute`]).
pub fn mean_radiance_estimate(hierarchy: &Hierarchy) -> f64 {
    let area = hierarchy.total_area();
    if area <= 0.0 {
        return 0.0;
    }
    let emitted = crate::solvers::emitted_power(hierarchy);
    let rho: crate::color::Rgb = hierarchy
        .patches
        .iter()
        .map(|p| p.reflectance * hierarchy.element(p.root).area)
        .sum::<crate::color::Rgb>()
        / area;
    let channel = |phi: f64, rho: f64| phi / (std::f64::consts::PI * area * (1.0 - rho).max(1e-3));
    (channel(emitted.r, rho.r) + channel(emitted.g, rho.g) + channel(emitted.b, rho.b)) / 3.0
}

/// Visibility back end (`--visibility`): exact ray casting, or extinction through clusters.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum VisibilityKind {
    /// Exact ray casting with our SAH bounding volume hierarchy.
    #[value(alias = "exact")]
    Bvh,
    /// Transmittance by extinction through the clusters a segment crosses (Sillion–Drettakis §3.1;
    /// clusters built by `--hierarchy`); rays for rendering stay exact.
    Extinction,
    /// Multi-resolution visibility (Sillion–Drettakis §3.2–3.3): exact where a cluster could cast a
    /// shadow feature larger than --feature-size, extinction where not.
    Multires,
    /// Embree 3 (build with `--features embree`).
    #[cfg(feature = "embree")]
    Embree,
    /// Exhaustive test of every polygon (reference; only for tiny scenes).
    BruteForce,
}

/// Everything that determines a solution.
#[derive(Clone, Debug, serde::Serialize)]
pub struct SimulationSettings {
    pub method: MethodKind,
    pub oracle: OracleKind,
    pub solver: SolverKind,
    pub visibility: VisibilityKind,
    /// Shaft tests in link couplings, their verdicts inherited by refined links (exact visibility
    /// back ends only; extinction and multires transmittances are not a matter of polygons alone).
    pub visibility_reuse: VisibilityReuse,
    /// Cluster transfer model; `None` links every pair of patches at the start.
    pub clustering: ClusteringKind,
    /// How the cluster tree is built (clustering and extinction visibility).
    pub cluster_tree: ClusterTreeKind,
    /// Multi-resolution visibility: the smallest shadow feature (world units on the receiver) computed
    /// exactly; 0 is exact visibility, ∞ extinction.
    pub feature_size: f64,
    /// Multi-resolution visibility: feature sizes of their own for the surfaces they name, the first
    /// that names a surface applying (Sillion–Drettakis §6, importance).
    pub surface_feature_sizes: Vec<SurfaceFeatureSize>,
    /// Multi-resolution visibility: how a cluster it does not descend into attenuates.
    pub multires_averaging: Averaging,
    /// Intra-cluster visibility (Sillion–Drettakis §6.1) when clustering is on.
    pub intra_cluster: IntraClusterKind,
    /// Refinement threshold relative to the scene's total emission Σ A max(E) (radiance × area).
    pub eps: f64,
    /// Extra quadtree levels the power oracle's visibility term gives a link whose sampled visibility
    /// is ½ ([`PowerOracle::for_shadow_levels`]); 0: eq. (1) alone.
    pub shadow_levels: f64,
    /// How the receiver side of links to a near source is integrated (couplings and the power
    /// oracle's transport, [`crate::geometry::near_field`]).
    pub near_field: NearField,
    /// Where partly visible sources are sampled ([`SourceRule`]).
    pub source_rule: SourceRule,
    /// Whether a receiver that something lies over in part counts as crossed by a shadow boundary
    /// ([`OutlineRule`]).
    pub outlines: OutlineRule,
    /// Quadtree levels that receivers under an outline ([`OutlineRule::Split`]) are refined beyond
    /// what `shadow_levels` gives a shadow boundary, and may go below `min_area`; 0: as deep.
    pub outline_levels: f64,
    /// Smallest splittable element area relative to the total patch area.
    pub min_area: f64,
    /// Radiance basis on every element (Bekaert–Willems §2).
    pub basis: BasisKind,
    /// Degree of the cubature rules for couplings; `None`: the basis's default (§4.3).
    pub cubature_degree: Option<usize>,
    /// How links store their error coefficients (Bekaert–Willems §4.3).
    pub error_storage: ErrorStorage,
    /// Error control's target (Bekaert–Willems algorithm 6.1), with any oracle; `None`: no error
    /// control, except with the link error oracle, which always controls
    /// ([`SimulationSettings::controlled_accuracy`]).
    pub accuracy: Option<Accuracy>,
    /// Error control also to this fraction of each leaf's own radiance
    /// ([`crate::solvers::ErrorControl::allowed`]); needs error control.
    pub local_accuracy: Option<f64>,
    /// Algorithm 6.1's threshold factor.
    pub threshold_factor: f64,
    /// Which a-posteriori estimate to compute (and control).
    pub estimate: EstimateKind,
    /// Most elements refinement may create.
    pub max_elements: usize,
    /// Most bytes of the whole solve ([`MemoryBudget`]); refinement stops where elements and links would
    /// pass what the fixed structures leave.
    pub max_memory: usize,
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
    /// Progressive multi-gridding (Sillion–Drettakis §6.2, `--link-budget`); `None`: one refinement per
    /// pass at the final threshold.
    pub multigrid: Option<MultigridSettings>,
}

/// The default accuracy of error control with the link error oracle: 10% of the mean radiance (in max
/// norm per element, which on the Cornell box means about 4% relative RMSE over the image;
/// BENCHMARKS.md). The command line's power oracle has its own, `cli::args::DEFAULT_POWER_ACCURACY`.
pub const DEFAULT_RELATIVE_ACCURACY: f64 = 0.1;

/// Half of the machine's memory (from /proc/meminfo), or 4 GiB where that cannot be read.
pub fn default_max_memory() -> usize {
    let total_kib = std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|text| {
            text.lines()
                .find(|l| l.starts_with("MemTotal:"))
                .and_then(|l| l.split_whitespace().nth(1)?.parse::<usize>().ok())
        });
    total_kib.map_or(4 << 30, |kib| kib * 1024 / 2)
}

impl SimulationSettings {
    /// The cubature degree couplings use: the basis's default with the link error oracle, whose
    /// refinement reads the error coefficients at the nodes (`d + 3` receiver nodes per direction, see
    /// [`BasisKind::default_cubature_degree`]); one point per direction fewer otherwise (a 2×2 receiver
    /// rule for the constant basis), also under error control where the estimate's maximum over the
    /// nodes sees the leading error term ([`BasisKind::estimating_cubature_degree`]).
    pub fn cubature_degree(&self) -> usize {
        self.cubature_degree
            .unwrap_or_else(|| match self.controlled_accuracy() {
                Some(_) if self.oracle == OracleKind::Error => self.basis.default_cubature_degree(),
                Some(_) => self.basis.estimating_cubature_degree(),
                None => self.basis.default_cubature_degree() - 2,
            })
    }

    /// The accuracy error control aims at, if it runs: the one asked for, or
    /// [`DEFAULT_RELATIVE_ACCURACY`] with the link error oracle, whose thresholds only error control
    /// sets.
    pub fn controlled_accuracy(&self) -> Option<Accuracy> {
        match (self.accuracy, self.oracle) {
            (None, OracleKind::Error) => Some(Accuracy::Relative(DEFAULT_RELATIVE_ACCURACY)),
            (accuracy, _) => accuracy,
        }
    }
}

/// The library's default is the classic solver the oracle experiments start from (constant basis,
/// power oracle, `eps`, Gauss–Seidel, visibility at fixed source nodes); the command line's defaults
/// differ (linear basis, ε = 3e-5, one shadow level, clustering where needed, jittered source nodes,
/// over-relaxed Gauss–Seidel, error control to 30% of the mean radiance: `radiosity render --help`).
impl Default for SimulationSettings {
    fn default() -> Self {
        SimulationSettings {
            method: MethodKind::Deterministic,
            oracle: OracleKind::Power,
            solver: SolverKind::GaussSeidel,
            visibility: VisibilityKind::Bvh,
            visibility_reuse: VisibilityReuse::Shaft,
            clustering: ClusteringKind::None,
            cluster_tree: ClusterTreeKind::Grid,
            feature_size: 0.0,
            surface_feature_sizes: Vec::new(),
            multires_averaging: Averaging::default(),
            intra_cluster: IntraClusterKind::ItemBuffer,
            eps: 1e-3,
            shadow_levels: 0.0,
            near_field: NearField::Adaptive,
            source_rule: SourceRule::Fixed,
            outlines: OutlineRule::Ignore,
            outline_levels: 0.0,
            min_area: 1e-5,
            basis: BasisKind::Constant,
            cubature_degree: None,
            error_storage: ErrorStorage::Full,
            accuracy: None,
            local_accuracy: None,
            threshold_factor: 1.4,
            estimate: EstimateKind::Realistic,
            max_elements: 2_000_000,
            max_memory: default_max_memory(),
            oracle_samples: 10,
            tolerance: 1e-5,
            max_iterations: 200,
            max_passes: 12,
            rays_per_iteration: 100_000,
            stochastic_iterations: 100,
            seed: 1,
            multigrid: None,
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

/// Builds the ray-casting structure over the scene's polygons (extinction on grid clusters).
pub fn build_visibility(
    scene: &Scene,
    kind: VisibilityKind,
) -> anyhow::Result<Box<dyn Visibility>> {
    build_visibility_with(scene, kind, ClusterTreeKind::Grid)
}

/// [`build_visibility`] with the cluster tree extinction visibility uses.
pub fn build_visibility_with(
    scene: &Scene,
    kind: VisibilityKind,
    tree: ClusterTreeKind,
) -> anyhow::Result<Box<dyn Visibility>> {
    let shapes: Vec<_> = scene.polygons.iter().map(|p| p.shape).collect();
    Ok(match kind {
        VisibilityKind::Bvh => Box::new(Bvh::new(&shapes)),
        VisibilityKind::Extinction => Box::new(Extinction::new(&shapes, tree)),
        VisibilityKind::Multires => {
            anyhow::bail!(
                "multi-resolution visibility needs a feature size: use build_visibility_for"
            )
        }
        #[cfg(feature = "embree")]
        VisibilityKind::Embree => Box::new(crate::visibility::embree::EmbreeScene::new(&shapes)?),
        VisibilityKind::BruteForce => Box::new(BruteForce::new(shapes)),
    })
}

/// The visibility structure `settings` names, with its cluster tree and (multires) feature size, and
/// shaft culling over the same polygons where `--visibility-reuse shaft` applies (exact back ends and
/// multires; extinction stays the paper's model on every segment).
pub fn build_visibility_for(
    scene: &Scene,
    settings: &SimulationSettings,
) -> anyhow::Result<Box<dyn Visibility>> {
    let shapes: Vec<_> = scene.polygons.iter().map(|p| p.shape).collect();
    anyhow::ensure!(
        settings.surface_feature_sizes.is_empty()
            || settings.visibility == VisibilityKind::Multires,
        "--feature-size-for applies to --visibility multires only"
    );
    let rays: Box<dyn Visibility> = match settings.visibility {
        VisibilityKind::Multires => {
            let multires = Multires::new(
                &shapes,
                settings.cluster_tree,
                settings.feature_size,
                settings.multires_averaging,
            );
            Box::new(if settings.surface_feature_sizes.is_empty() {
                multires
            } else {
                multires.with_surface_feature_sizes(surface_feature_sizes(
                    scene,
                    settings.feature_size,
                    &settings.surface_feature_sizes,
                )?)
            })
        }
        VisibilityKind::Extinction => {
            return build_visibility_with(scene, settings.visibility, settings.cluster_tree)
        }
        exact => build_visibility_with(scene, exact, settings.cluster_tree)?,
    };
    Ok(match settings.visibility_reuse {
        VisibilityReuse::None => rays,
        VisibilityReuse::Shaft => Box::new(ShaftCulled {
            rays,
            culler: ShaftCuller::new(&shapes),
        }),
    })
}

/// Per polygon of `scene`, the feature size of the first of `rules` that names it
/// ([`Scene::polygon_named`]), else `default`; a rule that names no polygon is an error (a misspelt
/// name would otherwise go unnoticed).
fn surface_feature_sizes(
    scene: &Scene,
    default: f64,
    rules: &[SurfaceFeatureSize],
) -> anyhow::Result<Vec<f64>> {
    let mut named = vec![false; rules.len()];
    let sizes = scene
        .polygons
        .iter()
        .map(|polygon| {
            match rules
                .iter()
                .position(|rule| scene.polygon_named(polygon, &rule.pattern))
            {
                Some(k) => {
                    named[k] = true;
                    rules[k].size
                }
                None => default,
            }
        })
        .collect();
    if let Some(k) = named.iter().position(|&n| !n) {
        anyhow::bail!(
            "--feature-size-for {}: no surface's object or material name matches '{}' (or an \
             earlier pattern took all it names)",
            rules[k].pattern,
            rules[k].pattern
        );
    }
    Ok(sizes)
}

/// The oracle named in `settings` for refining `hierarchy` (eq. (2) takes its reference area from it).
pub fn make_oracle(
    settings: &SimulationSettings,
    hierarchy: &Hierarchy,
) -> Box<dyn RefinementOracle> {
    let samples = settings.oracle_samples;
    match settings.oracle {
        OracleKind::Power => Box::new(PowerOracle {
            near_field: settings.near_field,
            ..PowerOracle::for_shadow_levels(settings.shadow_levels)
        }),
        OracleKind::Smoothness => Box::new(SmoothnessOracle::for_hierarchy(samples, hierarchy)),
        OracleKind::MutualInformation => Box::new(MutualInformationOracle::new(samples)),
        OracleKind::Error => Box::new(LinkErrorOracle {
            coupling: CouplingSettings {
                cubature_degree: settings.cubature_degree(),
                seed: settings.seed,
                error_storage: settings.error_storage,
                near_field: settings.near_field,
                source_rule: settings.source_rule,
            },
        }),
    }
}

pub fn make_solver(kind: SolverKind) -> Box<dyn GatheringSolver> {
    match kind {
        SolverKind::Jacobi => Box::new(Jacobi),
        SolverKind::GaussSeidel => Box::new(GaussSeidel),
        SolverKind::Sor => Box::new(OverRelaxed::default()),
        SolverKind::Southwell => Box::new(Southwell::default()),
    }
}

/// The deterministic solver's settings for `hierarchy`: absolute refinement threshold and minimum area
/// from the relative `eps` and `min_area`, the element and link budgets from `max_elements` and
/// `budget` (`--max-memory` less what it sets aside, [`MemoryBudget`]), and error control (with the
/// link error oracle) at the absolute accuracy.
pub fn deterministic_settings(
    settings: &SimulationSettings,
    hierarchy: &Hierarchy,
    budget: &MemoryBudget,
) -> SolveSettings {
    SolveSettings {
        refine: RefineSettings {
            threshold: settings.eps * hierarchy.total_emission(),
            min_area: settings.min_area * hierarchy.total_area(),
            max_elements: settings
                .max_elements
                .min(hierarchy.elements.len() + budget.max_elements(settings.basis)),
            max_links: budget.max_links(
                settings.basis,
                settings.cubature_degree(),
                settings.error_storage,
            ),
            coupling: CouplingSettings {
                cubature_degree: settings.cubature_degree(),
                seed: settings.seed,
                error_storage: settings.error_storage,
                near_field: settings.near_field,
                source_rule: settings.source_rule,
            },
            outlines: settings.outlines,
            outline_gain: 4f64.powf(settings.outline_levels),
            receiver_thresholds: settings.oracle != OracleKind::Error
                && settings.controlled_accuracy().is_some(),
            seed: settings.seed,
        },
        tolerance: settings.tolerance,
        max_iterations: settings.max_iterations,
        max_passes: settings.max_passes,
        estimate: settings.estimate,
        error_control: settings.controlled_accuracy().map(|accuracy| ErrorControl {
            accuracy: accuracy.absolute(hierarchy),
            local: settings.local_accuracy,
            threshold_factor: settings.threshold_factor,
        }),
    }
}

/// Runs hierarchical radiosity on `scene`.
pub fn simulate(
    scene: &Scene,
    settings: &SimulationSettings,
    progress: &Progress,
) -> anyhow::Result<Solution> {
    simulate_observed(scene, settings, progress, &mut |_, _, _| Ok(()))
}

/// What sees each step of progressive multi-gridding: the step, the solution so far, and the
/// visibility to render it with.
pub type StepObserver<'a> =
    dyn FnMut(&StepReport, &Hierarchy, &dyn Visibility) -> anyhow::Result<()> + 'a;

/// Unclustered initial links above which `--clustering auto` clusters whatever the memory budget.
/// Measured (BENCHMARKS.md, "`--clustering auto` without the machine's memory"): the classroom's 39.9M
/// initial links take 397 s and 3.0 GB unclustered against 18 s and 173 MB clustered. Before this
/// bound the choice followed the budget alone, which `--max-memory`'s default takes from the machine's
/// memory: a machine with more memory solved the classroom without clusters.
pub const AUTO_CLUSTERING_LINKS: usize = 4_000_000;

/// The same bound under the power oracle (the default), past which clusters cost no accuracy and
/// save time (BENCHMARKS.md, "`--clustering auto` from ten thousand links"): at the seen points of six
/// scenes clustered solves are as accurate or more (the corridor 4.7% → 3.4% RMS) and faster from
/// floor_gloss's 19k initial links up (0.24 → 0.12 s; office2's 214k 4.3 → 3.7 s), equal at cube.mgf's
/// 5k and below. Under error control clusters held its promise on office2 but took 16–25% more time
/// and memory there, so the other oracles keep [`AUTO_CLUSTERING_LINKS`].
pub const AUTO_CLUSTERING_LINKS_POWER: usize = 10_000;

/// The bound on unclustered initial links past which `--clustering auto` clusters with `oracle`.
pub fn auto_clustering_links(oracle: OracleKind) -> usize {
    match oracle {
        OracleKind::Power => AUTO_CLUSTERING_LINKS_POWER,
        _ => AUTO_CLUSTERING_LINKS,
    }
}

/// [`simulate`], with `on_step` called after every step of progressive multi-gridding.
pub fn simulate_observed(
    scene: &Scene,
    settings: &SimulationSettings,
    progress: &Progress,
    on_step: &mut StepObserver,
) -> anyhow::Result<Solution> {
    let start = Instant::now();
    let visibility = build_visibility_for(scene, settings)?;
    let visibility_seconds = start.elapsed().as_secs_f64();
    let mut hierarchy = Hierarchy::new(scene, settings.basis);
    let clustering = match settings.clustering {
        ClusteringKind::Auto if settings.method == MethodKind::Deterministic => {
            let budget = MemoryBudget::new(
                settings.max_memory,
                scene,
                visibility.as_ref(),
                &hierarchy,
                false,
            )?;
            let max_links = deterministic_settings(settings, &hierarchy, &budget)
                .refine
                .max_links;
            crate::solvers::refine::automatic_clustering(
                &hierarchy,
                max_links.min(auto_clustering_links(settings.oracle)),
            )
        }
        ClusteringKind::Auto => ClusteringKind::None,
        chosen => chosen,
    };
    anyhow::ensure!(
        clustering == ClusteringKind::None || settings.method == MethodKind::Deterministic,
        "clustering works with the deterministic method (use --clustering none with \
         --method stochastic-jacobi)"
    );
    hierarchy.add_clusters(settings.cluster_tree, clustering);
    let item_buffers =
        hierarchy.root_cluster.is_some() && settings.intra_cluster == IntraClusterKind::ItemBuffer;
    let budget = MemoryBudget::new(
        settings.max_memory,
        scene,
        visibility.as_ref(),
        &hierarchy,
        item_buffers,
    )?;
    if item_buffers {
        hierarchy.item_buffers = Some(Arc::new(ItemBuffers::new(budget.item_buffer_cache)));
    }
    let threshold = settings.eps * hierarchy.total_emission();
    let min_area = settings.min_area * hierarchy.total_area();
    let oracle = make_oracle(settings, &hierarchy);
    if settings.method == MethodKind::StochasticJacobi {
        anyhow::ensure!(
            settings.multigrid.is_none(),
            "progressive multi-gridding (--link-budget) works with the deterministic method"
        );
        anyhow::ensure!(
            settings.accuracy.is_none(),
            "error control (--accuracy) works with the deterministic method"
        );
        anyhow::ensure!(
            settings.basis == BasisKind::Constant && settings.oracle != OracleKind::Error,
            "hierarchical Monte Carlo radiosity works with the constant basis and the power, smoothness \
             or mi oracle (use --basis constant and --oracle power|smoothness|mi)"
        );
        let stochastic = StochasticSettings {
            threshold,
            min_area,
            rays_per_iteration: settings.rays_per_iteration,
            max_iterations: settings.stochastic_iterations,
            tolerance: settings.tolerance,
            seed: settings.seed,
        };
        // Goniometric luminaires light the leaves by the deterministic first gather; the Monte Carlo
        // iterations shoot that light onward with the emitters' (solvers::stochastic).
        let refine = deterministic_settings(settings, &hierarchy, &budget).refine;
        crate::solvers::direct::refine_and_gather(
            &mut hierarchy,
            visibility.as_ref(),
            &refine,
            false,
        );
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
    let solve_settings = deterministic_settings(settings, &hierarchy, &budget);
    crate::solvers::refine::check_initial_links(&hierarchy, solve_settings.refine.max_links)?;
    let solver = make_solver(settings.solver);
    let report = match &settings.multigrid {
        None => solve(
            &mut hierarchy,
            visibility.as_ref(),
            oracle.as_ref(),
            solver.as_ref(),
            &solve_settings,
            progress,
        ),
        Some(multigrid) => solve_progressive(
            &mut hierarchy,
            visibility.as_ref(),
            oracle.as_ref(),
            solver.as_ref(),
            &solve_settings,
            multigrid,
            progress,
            &mut |step, hierarchy| on_step(step, hierarchy, visibility.as_ref()),
        )?,
    };
    if let (Some(pass), false) = (report.diverged_in_pass, progress.quiet) {
        crate::progress::stderr_line(format_args!(
            "warning: the sweeps of pass {pass} diverged (the change of the exitant power grew for {} \
             sweeps in a row, or the power passed {} times what the emission and the largest \
             reflectance allow) and the solve stopped there, not converged: somewhere the scene sends \
             back more light than it receives (surfaces at one place kept by --keep-duplicates, a \
             reflectance of 1 or more, links whose couplings overestimate)",
            crate::solvers::DIVERGING_SWEEPS,
            crate::solvers::RUNAWAY_FACTOR
        ));
    }
    if report.refused_by_budget > 0 && !progress.quiet {
        crate::progress::stderr_line(format_args!(
            "warning: the element and link budget ({} elements, {} links, from --max-elements and \
             --max-memory {}, of which {} go to the scene, visibility, clusters, item-buffer cache and \
             program) stopped refinement: {} splits refused, the solution is coarser than the settings \
             ask",
            solve_settings.refine.max_elements,
            solve_settings.refine.max_links,
            crate::memory::format_bytes(budget.total),
            crate::memory::format_bytes(budget.fixed),
            report.refused_by_budget
        ));
    }
    Ok(Solution {
        hierarchy,
        visibility,
        report,
        visibility_seconds,
    })
}
