//! Argument groups shared by several subcommands.

use crate::bases::BasisKind;
use crate::geometry::near_field::NearField;
use crate::geometry::DVec3;
use crate::hierarchy::clusters::{ClusterTreeKind, ClusteringKind};
use crate::hierarchy::ErrorStorage;
use crate::measures::illuminance::GatherSettings;
use crate::measures::irradiance_cache::CacheSettings;
use crate::pipeline::{
    default_max_memory, Accuracy, MethodKind, OracleKind, SimulationSettings, SolverKind,
    VisibilityKind,
};
use crate::scene::{self, LoadOptions, Scene};
use crate::solvers::coupling::SourceRule;
use crate::solvers::error_estimate::EstimateKind;
use crate::solvers::multigrid::MultigridSettings;
use crate::solvers::refine::OutlineRule;
use crate::visibility::item_buffer::IntraClusterKind;
use crate::visibility::multires::Averaging;
use crate::visibility::shaft::VisibilityReuse;
use anyhow::{Context, Result};
use clap::Args;
use std::path::PathBuf;

/// Which scene to read.
#[derive(Args, Debug, Clone)]
pub struct SceneArgs {
    /// Scene file (.mgf, .obj, .gltf or .glb); the built-in Cornell box when omitted.
    pub scene: Option<PathBuf>,
    /// Treat every surface as two-sided, whatever the file says.
    #[arg(long, conflicts_with = "one_sided")]
    pub two_sided: bool,
    /// Treat every surface as one-sided (front by winding), whatever the file says (MGF defaults to two).
    #[arg(long)]
    pub one_sided: bool,
    /// Segments per full circle when tessellating MGF spheres, cylinders, cones, rings and tori.
    #[arg(long, default_value_t = 16, value_name = "N", value_parser = count(0, 1024))]
    pub tessellation: usize,
    /// Keep exact duplicate polygons (same vertices and material, e.g. furniture included twice)
    /// instead of one of each, and coplanar polygons that overlap (a frame on a board) instead of
    /// one surface where they overlap.
    #[arg(long)]
    pub keep_duplicates: bool,
    /// Adds an IES (LM-63) luminaire at X,Y,Z, aimed along DX,DY,DZ (default 0,0,-1: its nadir down a
    /// z-up scene) and spun SPIN degrees about that direction; repeatable.
    #[arg(long, value_name = "FILE.ies@X,Y,Z[@DX,DY,DZ[@SPIN]]")]
    pub luminaire: Vec<scene::luminaire::Placement>,
    /// Split surfaces along the outlines of objects that touch or nearly touch them, so that no
    /// element straddles a contact and light cannot leak through it. auto (the default): only along
    /// emitters that shine into the gap between them and a surface (a two-sided lamp hung just under a
    /// ceiling, as in cube.mgf, however tessellated; an IES luminaire's opening that shines up); gaps:
    /// also along reflecting lids across a gap (lamp housings under a ceiling); on: every lying object
    /// and footprint (blocks on a floor, furniture), which multiplies the polygons of furnished rooms
    /// (classroom 6.2k → 20k); off: none.
    #[arg(long, value_enum, default_value_t = scene::contacts::SplitContacts::Auto,
          value_name = "auto|gaps|on|off")]
    pub split_contacts: scene::contacts::SplitContacts,
    /// Largest gap that still counts as a contact, relative to the smaller polygon's diameter (an
    /// emitter with nothing between it and the surface: five times that).
    #[arg(long, default_value_t = scene::contacts::DEFAULT_CONTACT_GAP, value_name = "G",
          value_parser = parse_contact_gap)]
    pub contact_gap: f64,
}

/// Parses `--contact-gap`: a fraction in [0, MAX_CONTACT_GAP].
fn parse_contact_gap(text: &str) -> Result<f64> {
    let value: f64 = text
        .trim()
        .parse()
        .with_context(|| format!("'{text}' is not a number"))?;
    let max = scene::contacts::MAX_CONTACT_GAP;
    anyhow::ensure!(
        (0.0..=max).contains(&value),
        "the contact gap must be between 0 and {max} (a fraction of the smaller polygon's size)"
    );
    Ok(value)
}

impl SceneArgs {
    /// Loads a scene to be solved: prints the loader's warnings (file:line: reason, at most
    /// [`scene::WARNINGS_SHOWN_PER_KIND`] of a kind) unless quiet, and refuses a scene without polygons.
    pub fn load_for_solving(
        &self,
        progress: &crate::progress::Progress,
    ) -> Result<(Scene, String)> {
        let (scene, name) = self.load()?;
        if !progress.quiet {
            let shown = scene::WARNINGS_SHOWN_PER_KIND;
            for line in scene::grouped_warnings(&scene.warnings, shown) {
                crate::progress::stderr_line(format_args!("warning: {line}"));
            }
        }
        anyhow::ensure!(
            !scene.polygons.is_empty(),
            "{name}: the scene has no polygons"
        );
        if scene.emitter_count() == 0 && scene.luminaires.is_empty() && !progress.quiet {
            crate::progress::stderr_line(format_args!(
                "warning: {name}: no surface emits light: the solution is black"
            ));
        }
        Ok((scene, name))
    }

    /// Loads the scene (or builds the Cornell box) and returns it with a display name.
    pub fn load(&self) -> Result<(Scene, String)> {
        let (scene, name, _) = self.load_with_contacts()?;
        Ok((scene, name))
    }

    /// [`Self::load`], with what splitting along contacts did (`None` when `--split-contacts off`).
    pub fn load_with_contacts(
        &self,
    ) -> Result<(Scene, String, Option<scene::contacts::ContactSplit>)> {
        let (mut scene, name) = self.load_file()?;
        anyhow::ensure!(
            scene.luminaires.len() + self.luminaire.len() <= scene::luminaire::MAX_LUMINAIRES,
            "more than {} luminaires",
            scene::luminaire::MAX_LUMINAIRES
        );
        for placement in &self.luminaire {
            let luminaire = placement.load()?;
            scene
                .warnings
                .extend(luminaire.photometry.warnings.iter().cloned());
            scene.add_luminaire(luminaire);
        }
        let split = (self.split_contacts != scene::contacts::SplitContacts::Off).then(|| {
            scene::contacts::split_contacts(&mut scene, self.split_contacts, self.contact_gap)
        });
        Ok((scene, name, split))
    }

    fn load_file(&self) -> Result<(Scene, String)> {
        let options = LoadOptions {
            force_two_sided: self.two_sided,
            force_one_sided: self.one_sided,
            tessellation: self.tessellation.max(3),
            keep_duplicates: self.keep_duplicates,
        };
        match &self.scene {
            Some(path) => {
                let scene = scene::load(path, &options)?;
                Ok((scene, path.display().to_string()))
            }
            None => {
                let mut scene = scene::cornell::cornell_box();
                if self.two_sided || self.one_sided {
                    scene.set_two_sided(self.two_sided);
                }
                Ok((scene, "built-in Cornell box".to_string()))
            }
        }
    }
}

/// How the radiosity solution is computed.
#[derive(Args, Debug, Clone)]
pub struct SolveArgs {
    /// Solution method: deterministic hierarchical radiosity, or hierarchical Monte Carlo radiosity.
    #[arg(long, value_enum, default_value_t = MethodKind::Deterministic)]
    pub method: MethodKind,
    /// Refinement oracle: power (eq. (1) of Feixas et al., the default), smoothness, mi, or error (the
    /// Bekaert–Willems link error oracle with error control to --accuracy; the default when --accuracy
    /// is given).
    #[arg(long, value_enum)]
    pub oracle: Option<OracleKind>,
    /// Radiance basis on every element (Bekaert–Willems §2).
    #[arg(long, value_enum, default_value_t = BasisKind::Linear)]
    pub basis: BasisKind,
    /// Polynomial degree the receiver's coupling cubature integrates exactly (1-12); default: 2·order + 4
    /// with --oracle error (order + 3 nodes per direction, so that the error at the nodes does not
    /// vanish by superconvergence or symmetry), 2·order + 2 otherwise. The source rule is coarser.
    #[arg(long, value_parser = clap::value_parser!(u8).range(1..=12), value_name = "D")]
    pub cubature_degree: Option<u8>,
    /// How links store their error coefficients: full (every δ_{j,β}(x_k), exact for any later source
    /// radiance) or reduced (one ratio per receiver node for the source's radiance when the link is
    /// made, Bekaert–Willems §4.3: less memory per link, estimates that miss later changes of shape).
    /// Default: full with --oracle error, whose refinement reads them; reduced with the other oracles,
    /// for which they only make the a-posteriori estimate (the same solution in 5–15% less memory).
    #[arg(long, value_enum)]
    pub error_storage: Option<ErrorStorage>,
    /// Error control (Bekaert–Willems algorithm 6.1) to this largest radiance error per element: an
    /// absolute radiance in W/(m² sr) (e.g. 0.05), a percentage of the scene's mean radiance (e.g.
    /// 10%), or off. With the power oracle (the default) algorithm 6.1 lowers eq. (1)'s threshold
    /// (from --eps) at the receivers whose estimate fails; default 30% (BENCHMARKS.md, "Error control
    /// by default" and "The default accuracy at 30%"). With --oracle error it is the paper's own link
    /// error oracle, default 10%. With --oracle mi or smoothness it is off unless given, so that the
    /// oracle experiments compare the oracles alone. Given with no --oracle, it keeps the power oracle.
    #[arg(long, value_parser = parse_accuracy, value_name = "EPS|P%|off")]
    pub accuracy: Option<AccuracyArg>,
    /// Error control also to this percentage of each element's own radiance (e.g. 20%), down to a
    /// tenth of --accuracy: a relative error bar on dim surfaces too (the ceiling above a lamp
    /// housing, a corner), where --accuracy alone, absolute, allows errors of half their radiance.
    /// Needs error control; off by default (BENCHMARKS.md, "Local accuracy").
    #[arg(long, value_parser = parse_percentage, value_name = "P%")]
    pub local_accuracy: Option<f64>,
    /// Factor by which error control lowers a failing element's link error threshold per pass.
    #[arg(long, default_value_t = 1.4, value_name = "F")]
    pub threshold_factor: f64,
    /// Which a-posteriori error estimate to compute and control (Bekaert–Willems §4.3, eq. (11); signed:
    /// the levels' error terms summed with their signs at each leaf's nodes).
    #[arg(long, value_enum, default_value_t = EstimateKind::Realistic)]
    pub error_estimate: EstimateKind,
    /// Most elements refinement may create.
    #[arg(long, default_value_t = 2_000_000, value_name = "N", value_parser = count(1, 1 << 31))]
    pub max_elements: usize,
    /// Most memory for the solve, e.g. 2G, 500M: scene, visibility structure, clusters, item-buffer
    /// cache and program first, elements and links in the rest (default: half the machine's memory).
    #[arg(long, value_parser = parse_bytes, value_name = "BYTES")]
    pub max_memory: Option<usize>,
    /// Iterative solver for the linear system: over-relaxed Gauss–Seidel by default (the same solution
    /// as Gauss–Seidel in a third fewer sweeps, a sixth as many in a room of reflectance 0.98).
    #[arg(long, value_enum, default_value_t = SolverKind::Sor)]
    pub solver: SolverKind,
    /// Visibility: exact ray casting (bvh, alias exact), extinction through clusters, or multires.
    #[arg(long, value_enum, default_value_t = VisibilityKind::Bvh)]
    pub visibility: VisibilityKind,
    /// Visibility reuse in link couplings: a shaft test per link (Haines–Wallace shaft culling), whose
    /// clear or blocked verdict its sub-links inherit without rays; none casts a ray per node pair.
    /// Exact visibility (bvh, embree, brute-force) and multires, whose answer a clear or blocked shaft
    /// makes exact; not extinction, the paper's model everywhere.
    #[arg(long, value_enum, default_value_t = VisibilityReuse::Shaft)]
    pub visibility_reuse: VisibilityReuse,
    /// Multires visibility: smallest shadow feature (world units on the receiver) computed exactly;
    /// 0 is exact visibility, inf extinction.
    #[arg(long, value_name = "S")]
    pub feature_size: Option<f64>,
    /// Multires visibility: feature size S for the surfaces whose object or material name matches NAME
    /// (`*` for any run of characters; the first option that names a surface applies), the others
    /// keeping --feature-size: a small S where the shadows matter (Sillion–Drettakis §6). It acts on
    /// the visibility queries shaft tests leave open (--visibility-reuse). Repeatable.
    #[arg(long, value_name = "NAME=S")]
    pub feature_size_for: Vec<crate::visibility::multires::SurfaceFeatureSize>,
    /// Multires visibility: a cluster it does not descend into attenuates by the κ of its leaf clusters
    /// summed along the ray (leaves, the default: equal to --visibility extinction at --feature-size
    /// inf), or as a whole by its own κ = ΣA/(4V) (cluster: the paper's, O(1) per cluster, coarser).
    #[arg(long, value_enum)]
    pub multires_averaging: Option<Averaging>,
    /// Clustering (Sillion–Drettakis §4): start from one self-link on the root cluster; clusters
    /// exchange light as isotropic volumes or by the projected area of their patches (with
    /// --intra-cluster item-buffer, the default, both by the visible projected area the buffer gives:
    /// isotropic transfer needs --intra-cluster none).
    #[arg(long, value_enum, default_value_t = ClusteringKind::Auto)]
    pub clustering: ClusteringKind,
    /// How clusters are built: the paper's multi-level grid, a median-split k-d tree or an octree.
    #[arg(long = "hierarchy", value_enum, default_value_t = ClusterTreeKind::Grid)]
    pub cluster_tree: ClusterTreeKind,
    /// Intra-cluster visibility (Sillion–Drettakis §6.1): an item buffer per cluster and direction
    /// shares light among the patches the direction sees, or none (contents mutually unoccluded).
    #[arg(long, value_enum, default_value_t = IntraClusterKind::ItemBuffer)]
    pub intra_cluster: IntraClusterKind,
    /// Refinement threshold ε of the power, smoothness and mi oracles, relative to the scene's total
    /// emission (Σ A·max(E)); smaller is finer. Default: 3e-5 with power and mi, 1e-2 with smoothness
    /// (eq. (2) is scaled by the whole scene's area, not the receiver's: a thousand elements' worth
    /// larger; at 3e-5 it refines every edge of the Cornell box to the minimum area, in gigabytes).
    #[arg(long)]
    pub eps: Option<f64>,
    /// Power oracle: links that a shadow boundary crosses (their sampled visibility varies over the
    /// receiver, by s in L¹; Sillion–Drettakis Appendix A) are refined until s·ρBAF is below --eps/g,
    /// g = 2·4^N: N quadtree levels deeper than eq. (1) alone where a hard boundary halves the
    /// receiver; 0 is eq. (1) alone.
    #[arg(long, value_name = "N", default_value_t = 1.0)]
    pub shadow_levels: f64,
    /// Receiver side of links whose source is nearer than the receiver is large (a lamp hung just under
    /// a ceiling, a block standing on a floor): adaptive integrates the point-to-source factor over the
    /// receiver with cells bisected toward its peak, in couplings where the regular cubature misses more
    /// than a tenth of the light and in the power oracle's transport; regular keeps the fixed rule and the
    /// centre estimate.
    #[arg(long, value_enum, default_value_t = NearField::Adaptive)]
    pub near_field: NearField,
    /// Where visibility rays of a link whose shaft is partly blocked end on its source: jittered (the
    /// default; `shifted` is accepted), random nodes per receiver node, one in each cell of a regular
    /// partition of the source, unbiased across a shadow boundary on the source (a lamp reflector hidden
    /// behind its tube, a ceiling seen past a fixture); fixed, the cubature nodes themselves
    /// (Bekaert–Willems as published), less noisy but biased there.
    #[arg(long, value_enum, default_value_t = SourceRule::Jittered)]
    pub source_rule: SourceRule,
    /// Receivers that something lies over in part, nearer than half their size (a lamp housing under
    /// a ceiling, a shelf, a picture off a wall; found by five rays along the normal): split (the
    /// default) counts them in the --shadow-levels term as crossed by a hard shadow boundary, so that no
    /// element spreads the open side's light into the gap; ignore leaves them to their links' rays.
    #[arg(long, value_enum, default_value_t = OutlineRule::Split)]
    pub outlines: OutlineRule,
    /// Receivers under an outline (--outlines split) are refined N quadtree levels deeper than
    /// --shadow-levels takes shadow boundaries, down to N levels below --min-area: the penumbra of a
    /// gap is as wide as the gap (2 cm under a lamp housing), finer than the elements the minimum
    /// area allows on a ceiling. 0: as deep as shadow boundaries. Default: 1 where the rule applies
    /// (the deterministic method, --oracle power, --shadow-levels above 0, --outlines split), else 0.
    #[arg(long, value_name = "N")]
    pub outline_levels: Option<f64>,
    /// Smallest splittable element area, relative to the total surface area.
    #[arg(long, default_value_t = 1e-5)]
    pub min_area: f64,
    /// Random point pairs (one visibility ray each) per evaluation of the smoothness and MI oracles.
    #[arg(long, default_value_t = 10, value_name = "N", value_parser = count(2, 100_000))]
    pub oracle_samples: usize,
    /// Stop iterating when the relative change of total power is below this.
    #[arg(long, default_value_t = 1e-5)]
    pub tolerance: f64,
    /// Most solver sweeps per refinement pass.
    #[arg(long, default_value_t = 200, value_parser = count(0, 1_000_000))]
    pub max_iterations: usize,
    /// Most refine/solve passes.
    #[arg(long, default_value_t = 12, value_parser = count(0, 1000))]
    pub max_passes: usize,
    /// Stochastic Jacobi: rays shot in the first iteration; later iterations get a share proportional
    /// to the power they shoot.
    #[arg(long, default_value_t = 100_000, value_name = "N",
          value_parser = clap::value_parser!(u64).range(1..=1_000_000_000))]
    pub rays: u64,
    /// Stochastic Jacobi: most iterations (they also stop when the unshot power falls below
    /// --tolerance times the emitted power).
    #[arg(long, default_value_t = 100, value_name = "N", value_parser = count(0, 100_000))]
    pub iterations: usize,
    /// Progressive multi-gridding (Sillion–Drettakis §6.2): solve in steps whose refinements each
    /// create at most K links, lowering the threshold from a coarse solution to --eps (or --accuracy).
    #[arg(long, value_name = "K", value_parser = count(1, 1 << 31))]
    pub link_budget: Option<usize>,
    /// Most steps of progressive multi-gridding.
    #[arg(long, default_value_t = 1000, value_name = "N", value_parser = count(1, 1_000_000))]
    pub max_steps: usize,
}

/// `--eps` of the power and MI oracles (chosen over four scenes: BENCHMARKS.md, "Which basis and ε
/// for the default").
const DEFAULT_EPS: f64 = 3e-5;

/// `--eps` of the smoothness oracle: Cornell box 16.8k leaves, 4.6% image error in 1.8 s; office2 72k
/// leaves, 28 s (BENCHMARKS.md, "Error against time, per basis and per oracle").
const DEFAULT_SMOOTHNESS_EPS: f64 = 1e-2;

/// `--outline-levels` where the outline rule applies: the classroom 6.1% → 4.8% RMS at the points its
/// camera sees (the ceiling over its lamp housings), office3's render 93.6 → 96.0 MB, the other
/// scenes within ±0.05 points (BENCHMARKS.md, "Near links carry light"); 2 would take office3 past
/// its 99 MB goal.
const DEFAULT_OUTLINE_LEVELS: f64 = 1.0;

/// Most `--shadow-levels`: each level quarters the area of the elements along shadow boundaries.
const MAX_SHADOW_LEVELS: f64 = 8.0;

impl SolveArgs {
    pub fn settings(&self, seed: u64) -> Result<SimulationSettings> {
        anyhow::ensure!(
            (0.0..=MAX_SHADOW_LEVELS).contains(&self.shadow_levels),
            "--shadow-levels must be between 0 and {MAX_SHADOW_LEVELS}"
        );
        anyhow::ensure!(
            self.min_area.is_finite() && self.min_area >= 0.0,
            "--min-area must be non-negative"
        );
        anyhow::ensure!(
            self.threshold_factor.is_finite() && self.threshold_factor > 1.0,
            "--threshold-factor must be a number above 1"
        );
        anyhow::ensure!(self.max_elements >= 1, "--max-elements must be at least 1");
        anyhow::ensure!(
            self.oracle_samples >= 2,
            "--oracle-samples must be at least 2 (a kernel variation needs two samples)"
        );
        anyhow::ensure!(self.rays >= 1, "--rays must be at least 1");
        let feature_size = match (self.visibility, self.feature_size) {
            (VisibilityKind::Multires, Some(s)) if s >= 0.0 => s,
            (VisibilityKind::Multires, _) => anyhow::bail!(
                "--visibility multires needs --feature-size S with S >= 0 (world units, or inf)"
            ),
            (_, None) => 0.0,
            (_, Some(_)) => anyhow::bail!("--feature-size applies to --visibility multires only"),
        };
        anyhow::ensure!(
            self.feature_size_for.is_empty() || self.visibility == VisibilityKind::Multires,
            "--feature-size-for applies to --visibility multires only"
        );
        anyhow::ensure!(
            self.multires_averaging.is_none() || self.visibility == VisibilityKind::Multires,
            "--multires-averaging applies to --visibility multires only"
        );
        let oracle = self.oracle.unwrap_or(OracleKind::Power);
        let accuracy = match self.accuracy {
            Some(AccuracyArg::Target(accuracy)) => Some(accuracy),
            Some(AccuracyArg::Off) => {
                anyhow::ensure!(
                    oracle != OracleKind::Error,
                    "--oracle error refines only under error control: give it an --accuracy (default 10%)"
                );
                None
            }
            None if oracle == OracleKind::Power && self.method == MethodKind::Deterministic => {
                Some(Accuracy::Relative(DEFAULT_POWER_ACCURACY))
            }
            None => None,
        };
        anyhow::ensure!(
            self.local_accuracy.is_none() || accuracy.is_some() || oracle == OracleKind::Error,
            "--local-accuracy refines under error control: it needs an --accuracy (not off) and the \
             deterministic method"
        );
        let outlines_refined = oracle == OracleKind::Power
            && self.method == MethodKind::Deterministic
            && self.shadow_levels > 0.0
            && self.outlines == OutlineRule::Split;
        let outline_levels = self.outline_levels.unwrap_or(if outlines_refined {
            DEFAULT_OUTLINE_LEVELS
        } else {
            0.0
        });
        anyhow::ensure!(
            (0.0..=MAX_SHADOW_LEVELS).contains(&outline_levels),
            "--outline-levels must be between 0 and {MAX_SHADOW_LEVELS}"
        );
        anyhow::ensure!(
            outline_levels == 0.0 || outlines_refined,
            "--outline-levels deepens the power oracle's visibility term under outlines: it needs the \
             deterministic method, --oracle power (the default), --shadow-levels above 0 and \
             --outlines split (the defaults)"
        );
        let eps = self.eps.unwrap_or(match oracle {
            OracleKind::Smoothness => DEFAULT_SMOOTHNESS_EPS,
            _ => DEFAULT_EPS,
        });
        anyhow::ensure!(
            eps.is_finite() && eps >= 0.0,
            "--eps must be a non-negative number"
        );
        Ok(SimulationSettings {
            method: self.method,
            oracle,
            solver: self.solver,
            visibility: self.visibility,
            visibility_reuse: self.visibility_reuse,
            clustering: self.clustering,
            cluster_tree: self.cluster_tree,
            feature_size,
            surface_feature_sizes: self.feature_size_for.clone(),
            multires_averaging: self.multires_averaging.unwrap_or_default(),
            intra_cluster: self.intra_cluster,
            eps,
            shadow_levels: self.shadow_levels,
            near_field: self.near_field,
            source_rule: self.source_rule,
            outlines: self.outlines,
            outline_levels,
            min_area: self.min_area,
            basis: self.basis,
            cubature_degree: self.cubature_degree.map(usize::from),
            error_storage: self.error_storage.unwrap_or(match oracle {
                OracleKind::Error => ErrorStorage::Full,
                _ => ErrorStorage::Reduced,
            }),
            accuracy,
            local_accuracy: self.local_accuracy,
            threshold_factor: self.threshold_factor,
            estimate: self.error_estimate,
            max_elements: self.max_elements,
            max_memory: self.max_memory.unwrap_or_else(default_max_memory),
            oracle_samples: self.oracle_samples,
            tolerance: self.tolerance,
            max_iterations: self.max_iterations,
            max_passes: self.max_passes,
            rays_per_iteration: self.rays,
            stochastic_iterations: self.iterations,
            seed,
            multigrid: self.link_budget.map(|link_budget| MultigridSettings {
                link_budget,
                max_steps: self.max_steps,
            }),
        })
    }
}

/// How the hierarchical gather of irradiance at points refines (`measures::illuminance`): for work-plane
/// grids and for `probe --final-gather`.
#[derive(Args, Debug, Clone, Copy)]
pub struct GatherArgs {
    /// Largest gather error of one piece of surface, relative to the scene's mean radiance times
    /// --max-solid-angle (see `measures::illuminance`) [default: 0.01; 0.2 for the cached gather of
    /// `render --final-gather` and `probe --final-gather --cached`].
    #[arg(long, value_name = "T")]
    pub gather_tolerance: Option<f64>,
    /// Largest projected solid angle (sr) of a piece of surface gathered as a whole.
    #[arg(long, default_value_t = GatherSettings::default().max_solid_angle, value_name = "SR")]
    pub max_solid_angle: f64,
}

impl GatherArgs {
    /// The gather's settings, refusing values that would not end or would cost without bound; with
    /// `cached`, the default tolerance is [`CACHED_GATHER_TOLERANCE`]; `seed` seeds the single samples
    /// of faint pieces and clusters.
    pub fn settings(&self, cached: bool, seed: u64) -> Result<GatherSettings> {
        let tolerance = self.gather_tolerance.unwrap_or(if cached {
            CACHED_GATHER_TOLERANCE
        } else {
            GatherSettings::default().tolerance
        });
        anyhow::ensure!(
            tolerance.is_finite() && tolerance > 0.0,
            "--gather-tolerance must be a positive number"
        );
        anyhow::ensure!(
            self.max_solid_angle.is_finite() && self.max_solid_angle >= 1e-4,
            "--max-solid-angle must be at least 1e-4 sr"
        );
        Ok(GatherSettings {
            tolerance,
            max_solid_angle: self.max_solid_angle,
            seed,
            ..GatherSettings::default()
        })
    }
}

/// Pinhole camera; without `--eye` the scene's own camera (the Cornell box has one) or an automatic view
/// (`Camera::auto_view`: from outside, or from inside a closed room).
#[derive(Args, Debug, Clone)]
pub struct CameraArgs {
    /// Eye position "x,y,z".
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub eye: Option<DVec3>,
    /// Point looked at "x,y,z".
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub look_at: Option<DVec3>,
    /// Up direction "x,y,z".
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub up: Option<DVec3>,
    /// Vertical field of view in degrees.
    #[arg(long)]
    pub fov: Option<f64>,
    /// Image width in pixels (default 512, 256 for experiments).
    #[arg(long, value_parser = count(1, MAX_IMAGE_SIDE))]
    pub width: Option<usize>,
    /// Image height in pixels (default 512, 256 for experiments).
    #[arg(long, value_parser = count(1, MAX_IMAGE_SIDE))]
    pub height: Option<usize>,
}

impl CameraArgs {
    /// The camera for `scene`, `default_size` pixels square unless `--width`/`--height` say otherwise.
    pub fn camera(
        &self,
        scene: &Scene,
        default_size: usize,
    ) -> Result<crate::output::camera::Camera> {
        use crate::output::camera::Camera;
        let (width, height) = (
            self.width.unwrap_or(default_size),
            self.height.unwrap_or(default_size),
        );
        anyhow::ensure!(
            width > 0 && height > 0,
            "--width and --height must be positive"
        );
        check_pixels(width, height)?;
        let fov = self
            .fov
            .unwrap_or(scene.camera.map_or(50.0, |c| c.fov_degrees));
        anyhow::ensure!(
            fov > 0.0 && fov < 180.0,
            "--fov must be between 0 and 180 degrees"
        );
        let mut spec = match self.eye {
            None => Camera::auto_view(scene, fov),
            Some(_) => Camera::framing(&scene.bounds(), fov),
        };
        spec.fov_degrees = fov;
        if let Some(eye) = self.eye {
            spec.eye = eye;
        }
        if let Some(look_at) = self.look_at {
            spec.look_at = look_at;
        }
        if let Some(up) = self.up {
            spec.up = up;
        }
        anyhow::ensure!(
            (spec.look_at - spec.eye).length() > 0.0,
            "--eye and --look-at must differ"
        );
        Ok(Camera::new(&spec, width, height))
    }
}

/// From linear radiance to display: exposure and tone curve (PNG images and the viewer page).
#[derive(Args, Debug, Clone)]
pub struct ToneArgs {
    /// Exposure multiplier for the PNG and the viewer page; automatic (log-average luminance to middle
    /// grey) when omitted.
    #[arg(long)]
    pub exposure: Option<f64>,
    /// Tone curve for the PNG and the viewer page.
    #[arg(long, value_enum, default_value_t = crate::output::tonemap::Curve::Filmic)]
    pub tone: crate::output::tonemap::Curve,
}

impl ToneArgs {
    pub fn tone_map(&self) -> Result<crate::output::tonemap::ToneMap> {
        use crate::output::tonemap::{Exposure, ToneMap};
        if let Some(e) = self.exposure {
            anyhow::ensure!(
                e.is_finite() && e > 0.0,
                "--exposure must be a positive number"
            );
        }
        Ok(ToneMap {
            exposure: self.exposure.map_or(Exposure::Auto, Exposure::Multiplier),
            curve: self.tone,
        })
    }
}

/// Widest or tallest image, in pixels.
pub const MAX_IMAGE_SIDE: u64 = 32_768;
pub use crate::output::image::MAX_PIXELS;
/// Most samples (pixels times samples per pixel) one image may take.
pub const MAX_SAMPLES: u128 = 1 << 32;

/// A clap parser for a count between `lo` and `hi` (inclusive): out-of-range values are refused
/// with the range instead of exhausting memory or time.
pub fn count(lo: u64, hi: u64) -> clap::builder::RangedU64ValueParser<usize> {
    clap::builder::RangedU64ValueParser::<usize>::new().range(lo..=hi)
}

/// Refuses images above the pixel budget.
pub fn check_pixels(width: usize, height: usize) -> Result<()> {
    anyhow::ensure!(
        width as u128 * height as u128 <= MAX_PIXELS as u128,
        "image of {width}x{height} pixels is too large (at most {MAX_PIXELS} pixels)"
    );
    Ok(())
}

/// Refuses images above the sample budget (pixels times samples per pixel).
pub fn check_samples(width: usize, height: usize, spp: usize) -> Result<()> {
    samples_within(width, height, spp, MAX_SAMPLES, "")
}

/// Most samples `render --final-gather` gathers at: each costs a hierarchical gather (3–30 ms on 2
/// cores on the scenes of BENCHMARKS.md), so 256² pixels at 16 samples is already minutes to hours.
pub const MAX_GATHERED_SAMPLES: u128 = 1 << 20;

/// The gather tolerance a cached final gather defaults to: its records' corrections are interpolated,
/// and the interpolation's error, not the gather's, is what remains. On the Cornell box's 128² image
/// (16 samples) 0.2 gives 1.69% against 1.68% at the points' 0.01, in a sixth of the time (1.3 s
/// against 8.6 s); at the classroom's seen points the uncached gather is at 1.66% against 1.64%
/// (BENCHMARKS.md, "A cached final gather").
pub const CACHED_GATHER_TOLERANCE: f64 = 0.2;

/// The irradiance cache's settings for Ward's `a` of `--cache-accuracy`, refused outside [0.01, 10]
/// (records nearly at every pixel already at 0.01 on the scenes of BENCHMARKS.md; past 10 the
/// largest radius always holds), for a solution by `method` (Monte Carlo radiosity's leaves are
/// noisy: `CacheSettings::noisy_leaves`).
pub fn cache_settings(accuracy: f64, method: MethodKind) -> Result<CacheSettings> {
    anyhow::ensure!(
        accuracy.is_finite() && (0.01..=10.0).contains(&accuracy),
        "--cache-accuracy must lie between 0.01 and 10"
    );
    Ok(CacheSettings {
        accuracy,
        noisy_leaves: method == MethodKind::StochasticJacobi,
        ..Default::default()
    })
}

/// Refuses a `render --final-gather` of more than [`MAX_GATHERED_SAMPLES`] gathers (`spp` 1 for the
/// cache's at most one record per pixel).
pub fn check_gathered_samples(width: usize, height: usize, spp: usize) -> Result<()> {
    samples_within(
        width,
        height,
        spp,
        MAX_GATHERED_SAMPLES,
        "--final-gather gathers at up to a record per pixel, or with --gather-every-sample at every \
         sample (milliseconds each): ",
    )
}

/// Refuses `width × height × spp` samples above `limit`, the message led by `why`.
fn samples_within(width: usize, height: usize, spp: usize, limit: u128, why: &str) -> Result<()> {
    let total = width as u128 * height as u128 * spp as u128;
    anyhow::ensure!(
        total <= limit,
        "{why}{width}x{height} pixels at {spp} samples per pixel is {total} samples, more than the \
         {limit} allowed: lower --spp or the image size"
    );
    Ok(())
}

/// Parses "x,y,z" (commas or spaces).
pub fn parse_vec3(text: &str) -> Result<DVec3> {
    let parts: Vec<f64> = text
        .split(|c: char| c == ',' || c.is_whitespace())
        .filter(|s| !s.is_empty())
        .map(|s| {
            s.parse::<f64>()
                .with_context(|| format!("'{s}' is not a number"))
        })
        .collect::<Result<_>>()?;
    anyhow::ensure!(
        parts.len() == 3,
        "expected three numbers x,y,z, got {}",
        parts.len()
    );
    anyhow::ensure!(
        parts.iter().all(|v| v.is_finite()),
        "coordinates must be finite"
    );
    Ok(DVec3::new(parts[0], parts[1], parts[2]))
}

/// `--accuracy`: a target for error control, or none.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum AccuracyArg {
    Off,
    Target(Accuracy),
}

/// The command line's accuracy with the power oracle: 30% of the mean radiance. It keeps the promise at
/// the seen points of six scenes (every point within it on five, 297 of 300 on the classroom), at the
/// power oracle's own image error or better (BENCHMARKS.md, "Error control by default"). It was 40%
/// until near cluster links carried their light and error control got cheaper; 30% takes the
/// classroom's error 10% lower over three seeds (5.10 → 4.59% RMS) for 1.2× its time and leaves
/// office3's render under its 99 MB goal (97 MB); 25% would take that to 98 MB, and no scene's error
/// rises (BENCHMARKS.md, "The default accuracy at 30%").
pub const DEFAULT_POWER_ACCURACY: f64 = 0.3;

/// Parses `--accuracy`: "0.05" (absolute radiance), "2%" (of the mean radiance) or "off".
pub fn parse_accuracy(text: &str) -> Result<AccuracyArg> {
    let text = text.trim();
    if text.eq_ignore_ascii_case("off") || text.eq_ignore_ascii_case("none") {
        return Ok(AccuracyArg::Off);
    }
    let (number, relative) = match text.strip_suffix('%') {
        Some(n) => (n.trim(), true),
        None => (text, false),
    };
    let value: f64 = number
        .parse()
        .with_context(|| format!("'{text}' is not a number or a percentage"))?;
    anyhow::ensure!(
        value.is_finite() && value > 0.0,
        "the accuracy must be positive"
    );
    Ok(AccuracyArg::Target(if relative {
        Accuracy::Relative(value / 100.0)
    } else {
        Accuracy::Absolute(value)
    }))
}

/// Parses `--local-accuracy`: a percentage above 0 and at most 100 ("20%").
pub fn parse_percentage(text: &str) -> Result<f64> {
    let text = text.trim();
    let number = text
        .strip_suffix('%')
        .with_context(|| format!("'{text}' is not a percentage (e.g. 20%)"))?;
    let value: f64 = number
        .trim()
        .parse()
        .with_context(|| format!("'{text}' is not a percentage (e.g. 20%)"))?;
    anyhow::ensure!(
        value > 0.0 && value <= 100.0,
        "the percentage must be above 0 and at most 100"
    );
    Ok(value / 100.0)
}

/// Parses a byte count with an optional K, M, G or T suffix (powers of 1024).
pub fn parse_bytes(text: &str) -> Result<usize> {
    let text = text.trim();
    let (number, scale) = match text.chars().last().map(|c| c.to_ascii_uppercase()) {
        Some('K') => (&text[..text.len() - 1], 1u64 << 10),
        Some('M') => (&text[..text.len() - 1], 1 << 20),
        Some('G') => (&text[..text.len() - 1], 1 << 30),
        Some('T') => (&text[..text.len() - 1], 1 << 40),
        _ => (text, 1),
    };
    let value: f64 = number
        .trim()
        .parse()
        .with_context(|| format!("'{text}' is not a size such as 512M or 2G"))?;
    anyhow::ensure!(
        value.is_finite() && value > 0.0 && value * (scale as f64) < 1e18,
        "the size must be positive"
    );
    Ok((value * scale as f64) as usize)
}

/// Checks an output path before it is written: not a scene file (`.mgf`, `.obj`, `.mtl`), not one of
/// the files read (`inputs`: the scene and every file it includes or names, images, points, stats),
/// not a directory, and in a directory that exists.
pub fn check_output(
    option: &str,
    path: &std::path::Path,
    inputs: &[std::path::PathBuf],
) -> Result<()> {
    let shown = path.display();
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    anyhow::ensure!(
        !matches!(ext.as_str(), "mgf" | "obj" | "mtl"),
        "{option} {shown}: refusing to write an output over a scene file (.{ext})"
    );
    if let Some(input) = inputs.iter().find(|input| same_file(path, input)) {
        anyhow::bail!(
            "{option} {shown}: is an input ({}); refusing to overwrite it",
            input.display()
        );
    }
    anyhow::ensure!(!path.is_dir(), "{option} {shown}: is a directory");
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        anyhow::ensure!(
            dir.is_dir(),
            "{option} {shown}: directory {} does not exist",
            dir.display()
        );
    }
    Ok(())
}

/// Checks every output (option, path) with [`check_output`] and refuses one file written twice.
pub fn check_outputs(
    outputs: &[(&str, &std::path::Path)],
    inputs: &[std::path::PathBuf],
) -> Result<()> {
    for (k, &(option, path)) in outputs.iter().enumerate() {
        check_output(option, path, inputs)?;
        anyhow::ensure!(
            !outputs[..k]
                .iter()
                .any(|&(_, p)| p == path || same_file(p, path)),
            "{option} {}: the same file is written twice",
            path.display()
        );
    }
    Ok(())
}

/// Whether two paths name one existing file (the same device and inode: links and `..` included).
pub fn same_file(a: &std::path::Path, b: &std::path::Path) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        if let (Ok(a), Ok(b)) = (std::fs::metadata(a), std::fs::metadata(b)) {
            return a.dev() == b.dev() && a.ino() == b.ino();
        }
    }
    matches!((a.canonicalize(), b.canonicalize()), (Ok(a), Ok(b)) if a == b)
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Solve {
        #[command(flatten)]
        solve: SolveArgs,
    }

    fn eps_of(args: &[&str]) -> f64 {
        let parsed =
            Solve::try_parse_from(std::iter::once("radiosity").chain(args.iter().copied()))
                .expect("parse");
        parsed.solve.settings(1).expect("settings").eps
    }

    #[test]
    fn eps_defaults_per_oracle_and_an_explicit_one_wins() {
        assert_eq!(eps_of(&[]), DEFAULT_EPS);
        assert_eq!(eps_of(&["--oracle", "mi"]), DEFAULT_EPS);
        assert_eq!(eps_of(&["--oracle", "smoothness"]), DEFAULT_SMOOTHNESS_EPS);
        assert_eq!(eps_of(&["--oracle", "smoothness", "--eps", "0.2"]), 0.2);
        assert_eq!(eps_of(&["--eps", "1e-4"]), 1e-4);
    }
}
