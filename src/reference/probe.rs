//! Point probes: surface points given as `x y z nx ny nz` lines, located on the scene's polygons, where the
//! radiosity solution and the unbiased path-traced estimate are compared.

use super::{derive_seed, Estimate, PathTracer};
use crate::color::Rgb;
use crate::geometry::{convex_contains, DVec2, DVec3, Ray};
use crate::hierarchy::{ElementId, Hierarchy};
use crate::output::camera::Camera;
use crate::scene::{Diagnostic, Scene};
use crate::visibility::Visibility;
use anyhow::Context;
use std::path::{Path, PathBuf};

/// A point with the normal of the surface side it probes, from line `line` of the points file.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProbePoint {
    pub line: usize,
    pub point: DVec3,
    /// Unit normal pointing out of the probed side.
    pub normal: DVec3,
}

/// `n` points uniform by area over the sides of the polygons that do not emit and are no luminaire's
/// opening (a two-sided polygon's sides each by its area), with the normal of the side: a seeded sample
/// for checking a solution against the reference anywhere in a scene. `line` numbers the points from 1.
pub fn random_points(scene: &Scene, n: usize, seed: u64) -> Vec<ProbePoint> {
    use rand::{Rng, SeedableRng};
    let openings = scene.opening_luminaires();
    let sides: Vec<(f64, usize, bool)> = scene
        .polygons
        .iter()
        .enumerate()
        .filter(|&(i, p)| scene.material_of(p).emission.is_black() && openings[i].is_none())
        .flat_map(|(i, p)| {
            let area = p.shape.area();
            let back = p.two_sided.then_some((area, i, false));
            std::iter::once((area, i, true)).chain(back)
        })
        .filter(|(area, _, _)| *area > 0.0 && area.is_finite())
        .collect();
    let total: f64 = sides.iter().map(|s| s.0).sum();
    if sides.is_empty() || total <= 0.0 {
        return Vec::new();
    }
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(derive_seed(seed, u64::MAX));
    (0..n)
        .map(|k| {
            let mut target = rng.random::<f64>() * total;
            let &(_, index, front) = sides
                .iter()
                .find(|s| {
                    target -= s.0;
                    target <= 0.0
                })
                .unwrap_or(&sides[sides.len() - 1]);
            let shape = &scene.polygons[index].shape;
            let point = shape.sample_uniform(DVec2::new(rng.random(), rng.random()));
            let normal = if front {
                shape.normal()
            } else {
                -shape.normal()
            };
            ProbePoint {
                line: k + 1,
                point,
                normal,
            }
        })
        .collect()
}

/// Tries per point asked for by [`seen_points`] before it gives up (rays into the background, onto
/// emitters or onto the black back of a one-sided polygon find no point).
const SEEN_ATTEMPTS_PER_POINT: usize = 64;

/// Up to `n` points where the camera's rays through uniformly random positions of its image first meet
/// a surface side that does not emit (and is no luminaire's opening), with the normal of the side the
/// camera sees: what an image of the solution shows, by image area. A seeded sample for checking a
/// solution against the reference where a viewer looks, without the pixel-sized noise of a reference
/// image (`random_points` weighs hidden surfaces as much as seen ones). Fewer than `n` only where
/// fewer than one ray in [`SEEN_ATTEMPTS_PER_POINT`] finds a point.
pub fn seen_points(scene: &Scene, camera: &Camera, n: usize, seed: u64) -> Vec<ProbePoint> {
    use rand::{Rng, SeedableRng};
    let shapes: Vec<_> = scene.polygons.iter().map(|p| p.shape).collect();
    let bvh = crate::visibility::bvh::Bvh::new(&shapes);
    let openings = scene.opening_luminaires();
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(derive_seed(seed, u64::MAX - 1));
    let mut points = Vec::with_capacity(n);
    for _ in 0..n.saturating_mul(SEEN_ATTEMPTS_PER_POINT) {
        if points.len() == n {
            break;
        }
        let x = rng.random::<f64>() * camera.width as f64;
        let y = rng.random::<f64>() * camera.height as f64;
        let ray = camera.ray(x, y);
        let Some(hit) = bvh.intersect(&ray, 0.0, f64::INFINITY) else {
            continue;
        };
        let polygon = &scene.polygons[hit.polygon];
        let radiates = hit.front || polygon.two_sided;
        if !radiates
            || openings[hit.polygon].is_some()
            || !scene.material_of(polygon).emission.is_black()
        {
            continue;
        }
        let normal = polygon.shape.normal();
        points.push(ProbePoint {
            line: points.len() + 1,
            point: ray.at(hit.t),
            normal: if hit.front { normal } else { -normal },
        });
    }
    points
}

/// A malformed points file: file, line and reason.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct PointsError(pub Diagnostic);

/// Parses points, one `x y z nx ny nz` per line separated by whitespace and/or commas; `#` starts a
/// comment, blank lines are skipped. `file` names the source in errors.
pub fn parse_points(text: &str, file: &Path) -> Result<Vec<ProbePoint>, PointsError> {
    let error = |line: usize, message: String| {
        PointsError(Diagnostic {
            file: file.to_path_buf(),
            line,
            message,
        })
    };
    let mut points = Vec::new();
    for (index, raw) in text.lines().enumerate() {
        let line = index + 1;
        let content = raw.split('#').next().unwrap_or("");
        let fields: Vec<&str> = content
            .split(|c: char| c == ',' || c.is_whitespace())
            .filter(|s| !s.is_empty())
            .collect();
        if fields.is_empty() {
            continue;
        }
        if fields.len() != 6 {
            return Err(error(
                line,
                format!(
                    "expected 6 numbers 'x y z nx ny nz', found {}",
                    fields.len()
                ),
            ));
        }
        let mut values = [0.0; 6];
        for (value, field) in values.iter_mut().zip(&fields) {
            *value = field
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| error(line, format!("'{field}' is not a finite number")))?;
        }
        let normal = DVec3::new(values[3], values[4], values[5]);
        let length = normal.length();
        if length.is_nan() || length <= 1e-12 {
            return Err(error(line, "the normal has zero length".to_string()));
        }
        points.push(ProbePoint {
            line,
            point: DVec3::new(values[0], values[1], values[2]),
            normal: normal / length,
        });
    }
    Ok(points)
}

/// Reads and parses a points file.
pub fn read_points(path: &Path) -> anyhow::Result<Vec<ProbePoint>> {
    let bytes = crate::scene::read_bounded(path)
        .map_err(|e| anyhow::anyhow!("reading {}: {e}", path.display()))?;
    let text = String::from_utf8(bytes)
        .map_err(|_| anyhow::anyhow!("reading {}: not UTF-8 text", path.display()))?;
    Ok(parse_points(&text, path)?)
}

/// A probe point placed on a radiating polygon side.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfacePoint {
    pub polygon: usize,
    pub front: bool,
    /// The point moved onto the polygon's plane.
    pub point: DVec3,
    /// Unit normal of the side.
    pub normal: DVec3,
}

/// Distance (relative to the scene diagonal) a probe point may lie off its surface.
const SURFACE_TOLERANCE: f64 = 1e-3;

/// Smallest cosine between a probe's normal and its surface's normal.
const NORMAL_AGREEMENT: f64 = 0.5;

/// Finds the polygon side a probe lies on: first by a ray from `point + δ normal` back along `-normal`
/// (δ = 10⁻³ of the scene diagonal), then, for points on a crack between polygons or where another
/// surface crosses that ray with a normal that does not agree, the nearest polygon whose plane is within
/// δ, whose normal agrees and which contains the point's projection, a radiating side taken over the
/// black back of a one-sided polygon. Fails for points on no surface and for the black back of
/// one-sided polygons.
pub fn find_surface(
    scene: &Scene,
    visibility: &dyn Visibility,
    probe: &ProbePoint,
) -> Result<SurfacePoint, String> {
    let delta = SURFACE_TOLERANCE * scene.bounds().diagonal().max(f64::MIN_POSITIVE);
    let n = probe.normal;
    let ray = Ray::new(probe.point + delta * n, -n);
    let side_normal = |polygon: usize, front: bool| {
        let normal = scene.polygons[polygon].shape.normal();
        if front {
            normal
        } else {
            -normal
        }
    };
    let hit = visibility
        .intersect(&ray, 0.0, 2.0 * delta)
        .map(|hit| (hit.polygon, hit.front, ray.at(hit.t)));
    let radiates = |polygon: usize, front: bool| front || scene.polygons[polygon].two_sided;
    let found = match hit {
        // Coplanar overlapping polygons at the hit (z-fighting, which the ray settles by chance) are
        // settled as in `nearest_containing`.
        Some((polygon, front, at))
            if radiates(polygon, front)
                && side_normal(polygon, front).dot(n) >= NORMAL_AGREEMENT =>
        {
            nearest_containing(scene, probe, delta)
                .filter(|&(_, _, p)| p.distance(at) <= 1e-6 * delta)
                .or(hit)
        }
        // Nothing, another surface crossing the short ray (a steep object standing on the surface
        // within δ of the point), or the black back of a one-sided polygon within δ in front of the
        // point (the other face of a thin object whose faces look at each other): look for the
        // probe's own plane, and report the hit only if there is none.
        _ => nearest_containing(scene, probe, delta).or(hit),
    };
    let Some((polygon, front, point)) = found else {
        return Err(format!(
            "no surface within {delta:.3e} of the point ({}, {}, {}) facing ({}, {}, {})",
            probe.point.x, probe.point.y, probe.point.z, n.x, n.y, n.z
        ));
    };
    let normal = side_normal(polygon, front);
    if !front && !scene.polygons[polygon].two_sided {
        return Err(format!(
            "the point is on the back of one-sided polygon {polygon} (an opaque black side); \
             flip the normal to probe its front"
        ));
    }
    if normal.dot(n) < NORMAL_AGREEMENT {
        return Err(format!(
            "the normal does not match polygon {polygon}'s ({:.3}, {:.3}, {:.3})",
            normal.x, normal.y, normal.z
        ));
    }
    Ok(SurfacePoint {
        polygon,
        front,
        point,
        normal,
    })
}

/// The polygon nearest to the probe (by plane distance, at most `delta`) containing its projection, with a
/// normal agreeing with the probe's on either side. Among coplanar overlapping polygons (a scene's
/// z-fighting pairs, such as office3's two desk tops), the one of the first object: a choice that does
/// not change when contact splitting renumbers the polygons (their solutions differ there, as only one
/// wins each item buffer's depth test).
fn nearest_containing(
    scene: &Scene,
    probe: &ProbePoint,
    delta: f64,
) -> Option<(usize, bool, DVec3)> {
    let mut best: Option<((f64, usize), usize, bool, DVec3)> = None;
    let tie = COPLANAR * (1.0 + probe.point.abs().max_element());
    for (index, polygon) in scene.polygons.iter().enumerate() {
        let shape = &polygon.shape;
        let normal = shape.normal();
        let cos = normal.dot(probe.normal);
        // The black back of a one-sided polygon is never the side a probe means when another
        // polygon's radiating side lies in the same place (a thin object's two one-sided faces back to
        // back): the locating ray settles such a tie by chance.
        if cos.abs() < NORMAL_AGREEMENT || (cos < 0.0 && !polygon.two_sided) {
            continue;
        }
        let distance = normal.dot(probe.point - shape.vertices()[0]);
        // Plane distances within `tie` of each other count as equal.
        let key = ((distance.abs() / tie).round() * tie, polygon.object);
        if distance.abs() > delta || best.is_some_and(|b| b.0 <= key) {
            continue;
        }
        let projected = probe.point - distance * normal;
        let uv = shape.parameters_of(projected);
        if convex_contains(shape.parameter_corners(), uv, 1e-9) {
            best = Some((key, index, cos > 0.0, projected));
        }
    }
    best.map(|(_, index, front, point)| (index, front, point))
}

/// Relative difference of plane distances under which [`nearest_containing`] takes two polygons as
/// coplanar.
const COPLANAR: f64 = 1e-9;

/// The leaf element containing a surface point; `None` on the back of a one-sided polygon.
fn solution_leaf(hierarchy: &Hierarchy, surface: &SurfacePoint) -> Option<ElementId> {
    hierarchy
        .patch_for_side(surface.polygon, surface.front)
        .map(|patch| hierarchy.locate(patch, surface.point))
}

/// The radiosity solution's radiance at a surface point: the basis expansion of the leaf element
/// containing it, evaluated there and clamped at zero ([`Hierarchy::exitant_radiance_at`]).
pub fn solution_radiance(hierarchy: &Hierarchy, surface: &SurfacePoint) -> Rgb {
    solution_leaf(hierarchy, surface).map_or(Rgb::BLACK, |leaf| {
        hierarchy.exitant_radiance_at(leaf, surface.point)
    })
}

/// One probe's results.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct ProbeResult {
    /// Line of the points file.
    pub line: usize,
    /// The point on the surface.
    pub point: [f64; 3],
    pub normal: [f64; 3],
    pub polygon: usize,
    pub front: bool,
    /// Radiance of the radiosity solution there.
    pub radiosity: Rgb,
    /// The a-posteriori error estimate of the leaf element there (Bekaert–Willems §4, W/(m² sr)).
    pub estimated_error: f64,
    /// Unbiased path-traced radiance with its standard error, when asked for.
    pub reference: Option<Estimate>,
}

/// The points of an earlier `probe --json` run, read from `path` (`probe --against REF.json` without
/// `--points`, `--random` or `--seen`): a stored reference compared at its own points with solutions of
/// any `--seed`, so that the solver's random choices vary and the points do not.
pub fn read_stored_points(path: &Path) -> anyhow::Result<Vec<ProbePoint>> {
    #[derive(serde::Deserialize)]
    struct Stored {
        point: [f64; 3],
        normal: [f64; 3],
    }
    let stored: Vec<Stored> = serde_json::from_str(&read_stored(path)?).with_context(|| {
        format!(
            "{}: not the JSON of `radiosity probe --json`",
            path.display()
        )
    })?;
    anyhow::ensure!(!stored.is_empty(), "{}: no points", path.display());
    Ok(stored
        .into_iter()
        .enumerate()
        .map(|(k, entry)| ProbePoint {
            line: k + 1,
            point: DVec3::from_array(entry.point),
            normal: DVec3::from_array(entry.normal),
        })
        .collect())
}

/// The text of a stored probe run, bounded like every input.
fn read_stored(path: &Path) -> anyhow::Result<String> {
    let bytes = crate::scene::read_bounded(path)
        .map_err(|e| anyhow::anyhow!("cannot read the stored reference {}: {e}", path.display()))?;
    String::from_utf8(bytes).map_err(|_| anyhow::anyhow!("{}: not UTF-8 text", path.display()))
}

/// Puts on `results` the reference estimates of an earlier `probe --reference --json` run at the same
/// points, read from `path` (`probe --against`): a reference is path traced once and compared with
/// many solutions. Every entry's point must be the result's (same scene, points and seed).
pub fn attach_stored_reference(results: &mut [ProbeResult], path: &Path) -> anyhow::Result<()> {
    #[derive(serde::Deserialize)]
    struct Stored {
        point: [f64; 3],
        reference: Option<Estimate>,
    }
    let stored: Vec<Stored> = serde_json::from_str(&read_stored(path)?).with_context(|| {
        format!(
            "{}: not the JSON of `radiosity probe --reference --json`",
            path.display()
        )
    })?;
    anyhow::ensure!(
        stored.len() == results.len(),
        "{}: {} points, this run has {} (same scene, points or camera, and --seed?)",
        path.display(),
        stored.len(),
        results.len()
    );
    for (k, (result, entry)) in results.iter_mut().zip(stored).enumerate() {
        let scale = 1.0 + result.point.iter().map(|c| c.abs()).fold(0.0, f64::max);
        let same = result
            .point
            .iter()
            .zip(entry.point)
            .all(|(a, b)| (a - b).abs() <= 1e-9 * scale);
        anyhow::ensure!(
            same,
            "{}: point {} is {:?}, this run's is {:?} (same scene, points or camera, and --seed?)",
            path.display(),
            k + 1,
            entry.point,
            result.point
        );
        result.reference = Some(entry.reference.with_context(|| {
            format!(
                "{}: point {} has no reference estimate (made without --reference)",
                path.display(),
                k + 1
            )
        })?);
    }
    Ok(())
}

/// How many paths per probe point the reference estimate uses, and their seed.
#[derive(Clone, Copy, Debug)]
pub struct ProbeReference {
    pub spp: usize,
    pub seed: u64,
}

/// Locates every probe and evaluates the solution (and the reference) there; the first probe on no
/// surface is an error naming its line.
pub fn probe_points(
    scene: &Scene,
    visibility: &dyn Visibility,
    hierarchy: &Hierarchy,
    points: &[ProbePoint],
    reference: Option<ProbeReference>,
    file: &Path,
) -> Result<Vec<ProbeResult>, PointsError> {
    let tracer = PathTracer::new(
        scene,
        visibility,
        super::ReferenceSettings::default().roulette_depth,
    );
    points
        .iter()
        .enumerate()
        .map(|(index, probe)| {
            let surface = find_surface(scene, visibility, probe).map_err(|message| {
                PointsError(Diagnostic {
                    file: PathBuf::from(file),
                    line: probe.line,
                    message,
                })
            })?;
            let reference = reference.map(|r| {
                tracer.radiance_leaving(
                    surface.point,
                    surface.normal,
                    surface.polygon,
                    surface.front,
                    r.spp,
                    derive_seed(r.seed, index as u64),
                )
            });
            Ok(ProbeResult {
                line: probe.line,
                point: surface.point.to_array(),
                normal: surface.normal.to_array(),
                polygon: surface.polygon,
                front: surface.front,
                radiosity: solution_radiance(hierarchy, &surface),
                estimated_error: solution_leaf(hierarchy, &surface)
                    .map_or(0.0, |leaf| hierarchy.element(leaf).error),
                reference,
            })
        })
        .collect()
}
