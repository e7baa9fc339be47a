//! Link audit: every surface link's coupled form factor against an unbiased Monte Carlo estimate of the
//! same double integral with visibility, `F_ij = (1/A_i) ∫_i ∫_j G(x, y) V(x, y) dA_y dA_x`, with its
//! standard error.
//!
//! A coupling (Bekaert–Willems Algorithm 4.1) samples the kernel and visibility at cubature nodes; its
//! errors are systematic where the same geometry defeats the same nodes for many links (a source half
//! hidden behind a nearby occluder, seen through a sliver), and then they add up instead of averaging
//! out. The probe (`radiosity probe`) shows that a solution is off at a point; the audit shows which
//! links carry the error: per source polygon, the light the audited links carry, `Σ A_i F_ij L_j` with
//! `L_j` the luminance of the source element's average radiance, as coupled and as estimated, with
//! the estimate's standard error. It found a classroom lamp housing's reflector seen 3% too bright
//! from the floor below and a corridor's ceiling beside its lamps seen with a quarter of its light
//! (BENCHMARKS.md, "`radiosity audit`"). A link from a cluster is audited as the light it carries,
//! `A_i F_ij L_sent` with the radiance the cluster sends toward the receiver
//! ([`ClusterSweep::radiance_toward`]), against `∫_i ∫ G V L dA_y dA_x` over the cluster's contents
//! with each point's own radiance: the centre-to-centre transfer, its mean cosines, its few visibility
//! rays and what the cluster sends, all at once. Links into clusters are audited per patch root, in
//! one row ([`LinkAudit::into_clusters`]): what the clusters above it push down
//! ([`ClusterSweep::pushed`]) against the light all their links' sources send it. Between elements
//! that share an edge the kernel's variance is unbounded (`1/r²` at the edge), so there the standard
//! error understates the estimate's spread.
//!
//! [`audit_closure`] checks the links' closure: a white furnace gathered once over the solution's own
//! links, every element at radiance 1 and reflectance 1, gives each leaf the total factor it gathers,
//! `Σ F` over its links, its ancestors' and what the clusters above it push down. A closed scene's
//! exact factors sum to 1 at every point and an open one's to less; a leaf above 1 gathers more light
//! than a hemisphere of the brightest source could send it, and a loop of such leaves makes the sweeps
//! diverge. It found the exposure rule's unbounded shares (a desk's underside at 49, a 1 cm² patch
//! of the classroom's back wall at 223; `solvers::clustering::exposure_shares`).
//!
//! [`audit_transport`] checks the whole transport instead, whatever the link structure: each polygon
//! side's reflected light as solved against one unbiased gather of the solution's own radiance field
//! (cosine rays for the reflected part, a point on the emitters for the emitted part), cluster links,
//! what clusters share and push down included.

use crate::color::Rgb;
use crate::geometry::form_factor::point_to_point;
use crate::geometry::{cosine_direction, DVec2, DVec3, Ray};
use crate::hierarchy::{ElementId, ElementKind, Hierarchy, Link};
use crate::oracles::{sample_kernel, OracleContext};
use crate::solvers::clustering::ClusterSweep;
use crate::solvers::gathering::{GatheringSolver, Jacobi, SweepPlan};
use crate::solvers::link_rng;
use crate::visibility::Visibility;
use rand::Rng;
use rayon::prelude::*;
use serde::Serialize;
use std::collections::BTreeMap;

/// What to audit and how finely.
#[derive(Clone, Debug)]
pub struct AuditSettings {
    /// Polygons whose elements' incoming links are audited; empty: every polygon.
    pub polygons: Vec<usize>,
    /// Independent uniform point pairs (one ray each) per link.
    pub samples: usize,
    /// Most links audited; more stops the audit with an error (a budget, not a sample).
    pub max_links: usize,
    pub seed: u64,
}

/// Random stream of the audit's point pairs (apart from the solver's streams of the same link).
const AUDIT_STREAM: u64 = 0xA0D1;

/// Where the light of audited links comes from: one side of a polygon, or a cluster.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Serialize)]
pub enum AuditedSource {
    /// The links from the elements of one side of one polygon (the front unless `front` is false).
    Polygon { polygon: usize, front: bool },
    /// The links from one cluster (its element id).
    Cluster { element: ElementId },
    /// What the clusters above the audited patches push down to them ([`LinkAudit::into_clusters`]).
    IntoClusters,
    /// Every audited link ([`LinkAudit::total`]).
    #[default]
    All,
}

impl std::fmt::Display for AuditedSource {
    /// As the audit's table names it: `12` or `12b` (the back side), `c4711`, `total`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            AuditedSource::Polygon { polygon, front } => {
                write!(f, "{polygon}{}", if *front { "" } else { "b" })
            }
            AuditedSource::Cluster { element } => write!(f, "c{element}"),
            AuditedSource::IntoClusters => write!(f, "pushed"),
            AuditedSource::All => write!(f, "total"),
        }
    }
}

/// The audited links from one source.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct SourceRow {
    pub source: AuditedSource,
    pub links: usize,
    /// `Σ A_i F_ij L_j` with the coupled form factors.
    pub coupled: f64,
    /// The same with the Monte Carlo form factors.
    pub estimated: f64,
    /// Standard error of `estimated`.
    pub standard_error: f64,
}

impl SourceRow {
    /// `(coupled − estimated) / standard error`: how many standard errors the couplings are off.
    pub fn z(&self) -> f64 {
        if self.standard_error > 0.0 {
            (self.coupled - self.estimated) / self.standard_error
        } else if self.coupled == self.estimated {
            0.0
        } else {
            f64::INFINITY.copysign(self.coupled - self.estimated)
        }
    }
}

/// An audit's result: per source polygon side, sorted by `|coupled − estimated|`, largest first, and
/// the total.
#[derive(Clone, Debug, Default, Serialize)]
pub struct LinkAudit {
    pub rows: Vec<SourceRow>,
    pub total: SourceRow,
    /// What the clusters above the audited patches push down to their patch roots
    /// ([`ClusterSweep::pushed`]), against the light the sources of those clusters' links send the
    /// patch roots; `links` counts (patch root, link) pairs. Not in `total`.
    pub into_clusters: SourceRow,
}

/// Audits the links into the surface elements of `settings.polygons`, and what the clusters above
/// their patches push down to them (see the module doc).
pub fn audit_links(
    h: &Hierarchy,
    visibility: &dyn Visibility,
    settings: &AuditSettings,
) -> anyhow::Result<LinkAudit> {
    anyhow::ensure!(settings.samples >= 2, "at least 2 samples per link");
    let chosen = polygon_mask(h, &settings.polygons);
    let audited = |id: usize| {
        !h.is_cluster(id as ElementId)
            && (settings.polygons.is_empty() || chosen[h.patch_of(id as ElementId).polygon])
    };
    let mut links = Vec::new();
    for (id, e) in h.elements.iter().enumerate().filter(|&(id, _)| audited(id)) {
        links.extend(e.links.iter().map(|link| (id as ElementId, link)));
    }
    // The links into the clusters above the audited patches, per patch root: what those clusters
    // push down to it is audited against the light of all their links' sources on it.
    let mut above: BTreeMap<ElementId, Vec<ElementId>> = BTreeMap::new();
    for id in 0..h.elements.len() as ElementId {
        if !h.is_cluster(id) || h.element(id).links.is_empty() {
            continue;
        }
        for &root in h.contents(h.cluster(id).expect("a cluster")) {
            if settings.polygons.is_empty() || chosen[h.patch_of(root).polygon] {
                above.entry(root).or_default().push(id);
            }
        }
    }
    let pairs: Vec<(ElementId, &Link)> = above
        .iter()
        .flat_map(|(&root, clusters)| {
            clusters
                .iter()
                .flat_map(move |&c| h.element(c).links.iter().map(move |l| (root, l)))
        })
        .collect();
    anyhow::ensure!(
        links.len() + pairs.len() <= settings.max_links,
        "{} links to audit (and patches under clusters' links), more than --max-links {}: name fewer \
         receiving polygons (--polygon) or raise the bound",
        links.len() + pairs.len(),
        settings.max_links
    );
    // The clusters' exchange, only where a cluster link is audited (a sweep over the whole scene).
    let sweep = (!pairs.is_empty() || links.iter().any(|(_, link)| h.is_cluster(link.source)))
        .then(|| ClusterSweep::new(h));
    // Per link: its source, and the light it carries as coupled and as estimated, with the
    // estimate's standard error (luminance times receiver area).
    let audited: Vec<(AuditedSource, f64, f64, f64)> = links
        .par_iter()
        .map(|&(receiver, link)| {
            let area = h.element(receiver).area;
            let (estimated, standard_error) =
                light_from(h, visibility, receiver, link.source, settings);
            // What the link multiplies its form factor with: what a cluster sends toward the
            // receiver, a surface's average radiance.
            let (source, radiance) = match &sweep {
                Some(sweep) if h.is_cluster(link.source) => (
                    AuditedSource::Cluster {
                        element: link.source,
                    },
                    sweep.radiance_toward(
                        h,
                        link.source,
                        h.center_of(receiver),
                        link.coupling.visibility,
                    ),
                ),
                _ => {
                    let patch = h.patch_of(link.source);
                    let source = AuditedSource::Polygon {
                        polygon: patch.polygon,
                        front: patch.front,
                    };
                    (source, h.average_radiance(link.source))
                }
            };
            let coupled = area * link.form_factor() * radiance.luminance();
            (source, coupled, estimated, standard_error)
        })
        .collect();
    // Into clusters: per patch root, what the clusters above it push down, against the light of
    // their links' sources on it.
    let estimates: Vec<(ElementId, f64, f64)> = pairs
        .par_iter()
        .map(|&(root, link)| {
            let (estimated, standard_error) =
                light_from(h, visibility, root, link.source, settings);
            (root, estimated, standard_error)
        })
        .collect();
    let mut into_clusters = SourceRow {
        source: AuditedSource::IntoClusters,
        links: pairs.len(),
        ..SourceRow::default()
    };
    if let Some(sweep) = &sweep {
        into_clusters.coupled = above
            .keys()
            .map(|&root| h.element(root).area * sweep.pushed(root).luminance())
            .sum();
    }
    for (_, estimated, standard_error) in estimates {
        into_clusters.estimated += estimated;
        into_clusters.standard_error += standard_error.powi(2);
    }
    into_clusters.standard_error = into_clusters.standard_error.sqrt();
    let mut by_source: BTreeMap<AuditedSource, SourceRow> = BTreeMap::new();
    for (source, coupled, estimated, standard_error) in audited {
        let row = by_source.entry(source).or_insert_with(|| SourceRow {
            source,
            ..SourceRow::default()
        });
        row.links += 1;
        row.coupled += coupled;
        row.estimated += estimated;
        // Variances add; the square root is taken below.
        row.standard_error += standard_error.powi(2);
    }
    let mut rows: Vec<SourceRow> = by_source.into_values().collect();
    let mut total = SourceRow::default();
    for row in &mut rows {
        total.links += row.links;
        total.coupled += row.coupled;
        total.estimated += row.estimated;
        total.standard_error += row.standard_error;
        row.standard_error = row.standard_error.sqrt();
    }
    total.standard_error = total.standard_error.sqrt();
    rows.sort_by(|a, b| {
        (b.coupled - b.estimated)
            .abs()
            .total_cmp(&(a.coupled - a.estimated).abs())
            .then(a.source.cmp(&b.source))
    });
    Ok(LinkAudit {
        rows,
        total,
        into_clusters,
    })
}

/// The light (luminance times receiver area) that `source` sends to surface element `receiver`,
/// estimated ([`estimate`] times the source's average radiance for a surface, [`estimate_from_cluster`]
/// for a cluster), with its standard error.
fn light_from(
    h: &Hierarchy,
    visibility: &dyn Visibility,
    receiver: ElementId,
    source: ElementId,
    settings: &AuditSettings,
) -> (f64, f64) {
    let area = h.element(receiver).area;
    let (mean, standard_error, weight) = if h.is_cluster(source) {
        let (mean, standard_error) =
            estimate_from_cluster(h, visibility, receiver, source, settings);
        (mean, standard_error, area)
    } else {
        let (mean, standard_error) = estimate(h, visibility, receiver, source, settings);
        (
            mean,
            standard_error,
            area * h.average_radiance(source).luminance(),
        )
    };
    (weight * mean, weight * standard_error)
}

/// The light per unit receiver area that the contents of cluster `cluster` send to surface element
/// `receiver`, `(1/A_i) ∫_i ∫_c G(x, y) V(x, y) L(y) dA_y dA_x` (luminance): the mean over independent
/// pairs of `A_c G V L(y)`, x uniform on the receiver, y uniform over the cluster's patches (by area),
/// `L(y)` the exitant radiance of the leaf there, exact occlusion (the cluster's own contents
/// included); with its standard error.
fn estimate_from_cluster(
    h: &Hierarchy,
    visibility: &dyn Visibility,
    receiver: ElementId,
    cluster: ElementId,
    settings: &AuditSettings,
) -> (f64, f64) {
    let mut rng = link_rng(settings.seed, receiver, cluster, AUDIT_STREAM);
    let contents = h.contents(h.cluster(cluster).expect("a cluster"));
    let cumulative: Vec<f64> = contents
        .iter()
        .scan(0.0, |sum, &s| {
            *sum += h.element(s).area;
            Some(*sum)
        })
        .collect();
    let total = cumulative.last().copied().unwrap_or(0.0);
    if total <= 0.0 {
        return (0.0, 0.0);
    }
    let shape = h.element(receiver).shape();
    let normal = h.patch_of(receiver).normal;
    let values: Vec<f64> = (0..settings.samples)
        .map(|_| {
            let x = shape.sample_uniform(DVec2::new(rng.random(), rng.random()));
            let pick = rng.random::<f64>() * total;
            let k = cumulative
                .partition_point(|&c| c <= pick)
                .min(contents.len() - 1);
            let surface = contents[k];
            let uv = DVec2::new(rng.random(), rng.random());
            let y = h.element(surface).shape().sample_uniform(uv);
            let patch = h.element(surface).patch();
            let f = point_to_point(x, normal, y, h.patches[patch as usize].normal);
            if f <= 0.0 || visibility.segment_occluded(x, y) {
                return 0.0;
            }
            let leaf = h.locate(patch, y);
            total * f * h.exitant_radiance_at(leaf, y).luminance()
        })
        .collect();
    mean_and_standard_error(&values)
}

/// `A_j · mean(G V)` over independent uniform point pairs on the receiver and the source, with exact
/// occlusion ([`sample_kernel`], the smoothness and MI oracles' samples), and its standard error (the
/// sample standard deviation over √n): an unbiased estimate of `F_ij` whatever the visibility, with a
/// variance that the near-singular kernel of adjacent elements makes large (and that the standard
/// error then shows).
fn estimate(
    h: &Hierarchy,
    visibility: &dyn Visibility,
    receiver: ElementId,
    source: ElementId,
    settings: &AuditSettings,
) -> (f64, f64) {
    let mut rng = link_rng(settings.seed, receiver, source, AUDIT_STREAM);
    let context = OracleContext {
        hierarchy: h,
        visibility,
    };
    let area = h.element(source).area;
    let values = sample_kernel(&context, receiver, source, settings.samples, &mut rng).values;
    let (mean, standard_error) = mean_and_standard_error(&values);
    (area * mean, area * standard_error)
}

/// The sample mean of `values` (at least two) and its standard error, `s / √n`.
fn mean_and_standard_error(values: &[f64]) -> (f64, f64) {
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    let variance = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, (variance / n).sqrt())
}

/// Per polygon of the scene, whether it is among `polygons` (indices past the scene are ignored).
fn polygon_mask(h: &Hierarchy, polygons: &[usize]) -> Vec<bool> {
    let mut chosen = vec![false; h.polygon_patches.len()];
    for &p in polygons {
        if let Some(c) = chosen.get_mut(p) {
            *c = true;
        }
    }
    chosen
}

/// One polygon side's reflected light, as solved and as gathered anew from the solution.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct TransportRow {
    pub polygon: usize,
    pub front: bool,
    /// `∫ (L − E) dA` over the side's leaves (luminance): the light the solution reflects there.
    pub solved: f64,
    /// `∫ ρ/π ∫ L(hit(x, ω)) cos θ dω dA` by Monte Carlo with the solution's own radiance `L` where
    /// cosine-distributed rays land (its emitted part by a point on the emitters instead): what one
    /// exact gather of that solution reflects.
    pub gathered: f64,
    /// Standard error of `gathered`.
    pub standard_error: f64,
}

/// The transport audit of the polygon sides of `polygons`: the solution's reflected light against an
/// unbiased one-bounce gather of the same solution (`samples` cosine rays from uniform points per
/// side). Where they differ the solver's transport is off — couplings, cluster links and what they
/// share, visibility — whatever the link structure, since the gather reads the solution's radiance
/// field and nothing else. Light from goniometric luminaires is not in the gather: scenes with them
/// are refused.
pub fn audit_transport(
    h: &Hierarchy,
    visibility: &dyn Visibility,
    polygons: &[usize],
    samples: usize,
    seed: u64,
) -> anyhow::Result<Vec<TransportRow>> {
    anyhow::ensure!(samples >= 2, "at least 2 samples per polygon side");
    anyhow::ensure!(
        h.luminaires.is_empty(),
        "the transport audit does not gather the direct light of IES luminaires yet"
    );
    let chosen = polygon_mask(h, polygons);
    let patches: Vec<u32> = (0..h.patches.len() as u32)
        .filter(|&p| chosen[h.patches[p as usize].polygon])
        .collect();
    // Hits nearer than this (relative to the scene's size) are the surface the ray leaves.
    let t_min = 1e-9 * h.patch_bounds().diagonal().max(f64::MIN_POSITIVE);
    let emitters = Emitters::of(h);
    Ok(patches
        .par_iter()
        .map(|&patch| {
            let p = &h.patches[patch as usize];
            let mut leaves = Vec::new();
            h.collect_leaves(p.root, &mut leaves);
            let solved: f64 = leaves
                .iter()
                .map(|&id| h.element(id).area * (h.average_radiance(id) - p.emission).luminance())
                .sum();
            let shape = h.patch_shape(patch);
            let area = shape.area();
            let mut rng = link_rng(seed, p.root, p.root, AUDIT_STREAM);
            let values: Vec<f64> = (0..samples)
                .map(|_| {
                    let x = shape.sample_uniform(DVec2::new(rng.random(), rng.random()));
                    let direction =
                        cosine_direction(p.normal, DVec2::new(rng.random(), rng.random()));
                    let reflected = radiance_seen(h, visibility, x, direction, t_min);
                    let direct = emitters.direct(h, visibility, x, p.normal, &mut rng);
                    (p.reflectance * (reflected + direct)).luminance()
                })
                .collect();
            let (mean, standard_error) = mean_and_standard_error(&values);
            TransportRow {
                polygon: p.polygon,
                front: p.front,
                solved,
                gathered: area * mean,
                standard_error: area * standard_error,
            }
        })
        .collect())
}

/// The emitting patches, for the direct part of the transport audit's gather (next-event estimation:
/// a cosine ray alone rarely finds a small lamp).
struct Emitters {
    patches: Vec<u32>,
    /// Cumulative areas of `patches`.
    cumulative: Vec<f64>,
}

impl Emitters {
    fn of(h: &Hierarchy) -> Self {
        let patches: Vec<u32> = (0..h.patches.len() as u32)
            .filter(|&p| h.patches[p as usize].emission.max_channel() > 0.0)
            .collect();
        let cumulative = patches
            .iter()
            .scan(0.0, |total, &p| {
                *total += h.patch_shape(p).area();
                Some(*total)
            })
            .collect();
        Emitters {
            patches,
            cumulative,
        }
    }

    /// `∫ E(y) G(x, y) V(x, y) dA_y` over the emitters, by one point chosen in proportion to area:
    /// the emitted part of what the cosine ray's hit stands for (`radiance_seen` leaves it out).
    fn direct(
        &self,
        h: &Hierarchy,
        visibility: &dyn Visibility,
        x: DVec3,
        normal: DVec3,
        rng: &mut impl Rng,
    ) -> Rgb {
        let Some(&total) = self.cumulative.last() else {
            return Rgb::BLACK;
        };
        let pick = rng.random::<f64>() * total;
        let index = self
            .cumulative
            .partition_point(|&c| c <= pick)
            .min(self.patches.len() - 1);
        let emitter = &h.patches[self.patches[index] as usize];
        let y = h
            .patch_shape(self.patches[index])
            .sample_uniform(DVec2::new(rng.random(), rng.random()));
        let g = point_to_point(x, normal, y, emitter.normal);
        if g > 0.0 && !visibility.segment_occluded(x, y) {
            emitter.emission * (g * total)
        } else {
            Rgb::BLACK
        }
    }
}

/// The solution's reflected radiance (exitant less emitted: the emitted part is gathered directly,
/// [`Emitters::direct`]) where the ray from `x` along `direction` first meets a polygon (black past
/// the scene, on a side without a patch, or on a luminaire's opening).
fn radiance_seen(
    h: &Hierarchy,
    visibility: &dyn Visibility,
    x: DVec3,
    direction: DVec3,
    t_min: f64,
) -> Rgb {
    let ray = Ray::new(x, direction);
    let Some(hit) = visibility.intersect(&ray, t_min, f64::INFINITY) else {
        return Rgb::BLACK;
    };
    let Some(patch) = h.patch_for_side(hit.polygon, hit.front) else {
        return Rgb::BLACK;
    };
    let point = x + hit.t * direction;
    let (id, uv) = h.locate_with_parameters(patch, point);
    h.exitant_radiance_at_parameters(id, uv) - h.patches[patch as usize].emission
}

/// One leaf's closure ([`audit_closure`]).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ClosureRow {
    pub element: ElementId,
    pub polygon: usize,
    pub front: bool,
    pub centre: [f64; 3],
    pub area: f64,
    /// `Σ F` the leaf gathers: its links', its ancestors', and what clusters push to its patch.
    pub factor: f64,
    /// The part of `factor` that the clusters above its patch push down.
    pub pushed: f64,
}

/// Every surface leaf's closure, largest factor first.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct ClosureAudit {
    pub rows: Vec<ClosureRow>,
}

impl ClosureAudit {
    /// Leaves whose factor exceeds `bound`.
    pub fn above(&self, bound: f64) -> usize {
        self.rows.iter().filter(|r| r.factor > bound).count()
    }

    /// The largest factor (0 without leaves).
    pub fn largest(&self) -> f64 {
        self.rows.first().map_or(0.0, |r| r.factor)
    }

    /// The factor averaged over the leaves by area: in a closed scene 1 up to the couplings' cubature
    /// over their receivers, whatever the link structure (pushes keep what each link delivers over its
    /// receiver, and the sources along any point's ancestors cover the scene once); less in an open
    /// one by the share of its light that escapes (and the outer sides of a room's two-sided walls
    /// see nothing: the classroom and office3 read 0.52). Where it is 1 and leaves are not, the
    /// hierarchy misplaces light without losing or making it.
    pub fn area_mean(&self) -> f64 {
        let area: f64 = self.rows.iter().map(|r| r.area).sum();
        if area > 0.0 {
            self.rows.iter().map(|r| r.area * r.factor).sum::<f64>() / area
        } else {
            0.0
        }
    }
}

/// The closure of the solution's links: one Jacobi sweep of a white furnace on a copy of the
/// hierarchy (every element at constant radiance 1, reflectance 1, nothing emitted, no luminaire),
/// which leaves each surface leaf at the total factor it gathers (green channel; all are equal).
pub fn audit_closure(h: &Hierarchy) -> ClosureAudit {
    let mut furnace = h.clone();
    for patch in &mut furnace.patches {
        patch.reflectance = Rgb::WHITE;
        patch.emission = Rgb::BLACK;
    }
    for element in &mut furnace.elements {
        if let ElementKind::Cluster(c) = &mut element.kind {
            c.reflectance = Rgb::WHITE;
            c.emission = Rgb::BLACK;
        }
    }
    furnace.direct.iter_mut().for_each(|d| *d = Rgb::BLACK);
    for id in 0..furnace.elements.len() as ElementId {
        let radiance = furnace.radiance_mut(id);
        radiance.iter_mut().for_each(|l| *l = Rgb::BLACK);
        radiance[0] = Rgb::WHITE;
    }
    furnace.pull_clusters();
    let pushed = ClusterSweep::new(&furnace);
    let pushed: Vec<f64> = furnace
        .patches
        .iter()
        .map(|p| pushed.pushed(p.root).g)
        .collect();
    let plan = SweepPlan::new(&furnace);
    Jacobi.sweep(&mut furnace, &plan);
    let mut rows: Vec<ClosureRow> = furnace
        .leaves()
        .into_iter()
        .filter(|&id| !furnace.is_cluster(id))
        .map(|id| {
            let e = furnace.element(id);
            let patch = &furnace.patches[e.patch() as usize];
            ClosureRow {
                element: id,
                polygon: patch.polygon,
                front: patch.front,
                centre: furnace.center_of(id).to_array(),
                area: e.area,
                factor: furnace.average_radiance(id).g,
                pushed: pushed[e.patch() as usize],
            }
        })
        .collect();
    rows.sort_by(|a, b| {
        b.factor
            .total_cmp(&a.factor)
            .then(a.element.cmp(&b.element))
    });
    ClosureAudit { rows }
}
