//! Irradiance caching of the final gather for images (Ward, Rubinstein and Clear 1988, "A ray tracing
//! solution for diffuse interreflection"): the hierarchical gather of [`IrradianceGather`] at a sparse
//! set of record points where the camera looks, its correction to the shading interpolated between
//! them, instead of a gather at every sample.
//!
//! **Records.** The candidates are the surface points seen through pixel centres, offered coarse to
//! fine (every 32nd pixel of every 32nd row first, then the pixels halfway between, and so on), so
//! that records spread evenly over what is seen rather than along the first rows. A candidate becomes
//! a record unless a record on the same leaf element lies within [`COVERED`] of that record's radius.
//! Then the pixel corners, in the same order, each a record only where the cache would otherwise show
//! the shading uncorrected ([`Placement::WhereUncorrected`]): leaves narrower than a pixel, along
//! contacts and corners, that no pixel centre sees (the renderer's `Lattice`).
//! A record's radius is Ward's `a R`, `R` the harmonic mean distance to the surfaces seen from the
//! point (over [`RADIUS_RAYS`] cosine-distributed rays): where irradiance changes fast (near other
//! surfaces: corners, contacts, under furniture) records are dense. It is clamped to between
//! `min_pixels` and `max_pixels` pixel footprints at the point (Tabellion and Lamorlette 2004's
//! screen-space bounds; the footprint measured along the surface, so that a grazing floor is not
//! over-sampled), so that an open wall still takes several records and a corner not thousands.
//!
//! **What is interpolated** is the gather's correction to the shading, `Δ_i = L_gather(x_i) −
//! L_shade(x_i)`, added to the shading at the sample: the solution's own variation within elements
//! (shadows the mesh resolved) stays as sharp as the shading draws it, and only the gather's
//! smoother correction is spread between records. Interpolating the gathered radiance itself
//! instead blurs the shadows the mesh resolved: the Cornell box's 128² image at 16 samples is 8.2%
//! off the reference that way against 1.9% (`a = 0.3`; BENCHMARKS.md, "A cached final gather").
//!
//! **Interpolation.** At a sample on leaf `e`, the records of `e` whose radius `r_i` reaches it,
//! weighted `w_i = 1/(d_i/r_i + κ) − 1/(1 + κ)` ([`KAPPA`]): Ward's `1/ε` weight, which keeps the
//! records' own values near them, shifted to reach zero at the radius so that the field is continuous
//! where a record's reach ends. Only records of the same leaf take part: the shading steps at leaf
//! edges (contact outlines, a light's outline, between leaves of different sizes), so a correction
//! taken on one side is wrong on the other, and a polygon's edge is a leaf's too (a wall's correction
//! never reaches the floor it stands on). Per leaf rather than per polygon: seen points 1.63 → 1.39%
//! on the Cornell box, 4.8 → 3.3% on office2 (BENCHMARKS.md). A sample no record reaches (a sliver
//! that neither a pixel centre nor a pixel corner sees) keeps the shading's value, or for a Monte Carlo
//! solution's noisy leaves takes the gathered radiance of its patch's records
//! ([`CacheSettings::noisy_leaves`]).
//!
//! Every step is deterministic: candidates in a fixed order, records chosen one at a time, each
//! record's rays seeded from its pixel, gathers in parallel but each on its own: the image does not
//! depend on the thread count.

use super::illuminance::IrradianceGather;
use crate::color::Rgb;
use crate::geometry::{cosine_direction, DVec2, DVec3, Ray};
use crate::hierarchy::ElementId;
use crate::parallel::Uneven;
use crate::random::{splitmix64, unit_interval};
use crate::visibility::Visibility;
use rayon::prelude::*;
use std::collections::HashMap;

/// Cosine-distributed rays that measure a record's harmonic mean distance (a 4 × 8 stratification).
pub const RADIUS_RAYS: usize = 32;

/// A candidate within this fraction of a same-leaf record's radius is covered by it (no new record).
pub const COVERED: f64 = 0.5;

/// Offset of Ward's weight: a sample at a record takes `1/κ − 1/(1 + κ)` against a weight that falls to
/// zero at the radius, so records dominate their own neighbourhood without a singularity.
pub const KAPPA: f64 = 0.05;

/// Where an offered candidate becomes a record.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Placement {
    /// Unless a record of its leaf lies within [`COVERED`] of that record's radius: Ward's spacing.
    Spaced,
    /// Only where the cache would otherwise show the plain shading ([`IrradianceCache::corrected`]
    /// gives `None`): no record of the leaf reaches the point, nor, for noisy leaves, one of its patch.
    WhereUncorrected,
}

/// How records are placed.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct CacheSettings {
    /// Ward's `a`: a record's radius as a fraction of its harmonic mean distance to the surfaces around.
    pub accuracy: f64,
    /// Smallest radius, in pixel footprints at the record.
    pub min_pixels: f64,
    /// Largest radius, in pixel footprints at the record.
    pub max_pixels: f64,
    /// The leaves' values are Monte Carlo estimates, each with its own noise (hierarchical Monte
    /// Carlo radiosity): where no record of the sample's leaf reaches it, the gathered radiance of
    /// its patch's records is shown instead of the leaf's shading (see
    /// [`IrradianceCache::corrected`]).
    pub noisy_leaves: bool,
}

impl Default for CacheSettings {
    fn default() -> Self {
        CacheSettings {
            accuracy: 0.1,
            min_pixels: 1.0,
            max_pixels: 32.0,
            noisy_leaves: false,
        }
    }
}

/// A surface point seen through a pixel centre that may become a record.
#[derive(Clone, Copy, Debug)]
pub struct Candidate {
    /// The patch (polygon side) seen.
    pub patch: u32,
    /// The leaf element seen: records interpolate only within one leaf.
    pub leaf: ElementId,
    pub point: DVec3,
    /// The patch's unit normal (the side seen).
    pub normal: DVec3,
    /// Size of one pixel on the surface there (world units, along the surface).
    pub footprint: f64,
    /// Identity for the radius rays' seed (the pixel's index).
    pub key: u64,
    /// The shading's radiance at the point: what the gather corrects.
    pub shaded: Rgb,
}

#[derive(Clone, Copy, Debug)]
struct Record {
    patch: u32,
    leaf: ElementId,
    point: DVec3,
    radius: f64,
    /// `L_gather − L_shade` at the record.
    correction: Rgb,
    /// `L_gather` at the record.
    gathered: Rgb,
}

/// Records and the grid that finds them: a record of radius `r` sits at the level whose cell is at
/// least `r` wide, in the at most eight cells its sphere's box overlaps, so a point looks up one cell
/// per level.
#[derive(Debug, Default)]
pub struct IrradianceCache {
    settings: CacheSettings,
    seed: u64,
    records: Vec<Record>,
    /// Records whose gather is done: the first this many.
    gathered: usize,
    /// Cell size of level 0.
    base: f64,
    cells: HashMap<(u8, [i64; 3]), Vec<u32>>,
    /// The levels holding records, ascending.
    levels: Vec<u8>,
}

/// Cell size of level 0 relative to the scene's diagonal.
const LEVEL_ZERO: f64 = 1.0 / (1u64 << 24) as f64;

/// Most grid levels: radii up to `2^48 base`, 2^24 scene diagonals.
const MAX_LEVEL: u8 = 48;

impl IrradianceCache {
    /// An empty cache for a scene of diagonal `extent`; `seed` seeds the radius rays.
    pub fn new(settings: CacheSettings, extent: f64, seed: u64) -> Self {
        IrradianceCache {
            settings,
            seed,
            base: if extent > 0.0 && extent.is_finite() {
                extent * LEVEL_ZERO
            } else {
                LEVEL_ZERO
            },
            ..Default::default()
        }
    }

    /// Makes `candidate` a record where `placement` says so, measuring its radius; its gather waits
    /// for [`IrradianceCache::gather`]. Candidates are offered in a fixed order, one at a time: which
    /// become records depends on that order only.
    pub fn offer(
        &mut self,
        candidate: &Candidate,
        visibility: &dyn Visibility,
        placement: Placement,
    ) {
        let placed = match placement {
            Placement::Spaced => !self.covers(candidate.leaf, candidate.point),
            Placement::WhereUncorrected => self
                .corrected(
                    candidate.patch,
                    candidate.leaf,
                    candidate.point,
                    candidate.shaded,
                )
                .is_none(),
        };
        if !(placed && candidate.footprint > 0.0 && candidate.footprint.is_finite()) {
            return;
        }
        let harmonic = harmonic_mean_distance(visibility, candidate, self.seed);
        let radius = (self.settings.accuracy * harmonic).clamp(
            self.settings.min_pixels * candidate.footprint,
            self.settings.max_pixels * candidate.footprint,
        );
        self.insert(Record {
            patch: candidate.patch,
            leaf: candidate.leaf,
            point: candidate.point,
            radius,
            // Until the gather: minus the shading, to which the gathered radiance is added.
            correction: candidate.shaded * -1.0,
            gathered: Rgb::BLACK,
        });
    }

    /// Gathers at the records offered since the last call, in parallel (each on its own, so the result
    /// does not depend on the thread count).
    pub fn gather(&mut self, gather: &IrradianceGather) {
        self.records[self.gathered..]
            .par_iter_mut()
            .one_per_task()
            .for_each(|r| {
                r.gathered = gather.radiance_at(r.patch, r.point);
                r.correction += r.gathered;
            });
        self.gathered = self.records.len();
    }

    /// Records made.
    pub fn len(&self) -> usize {
        self.records.len()
    }

    pub fn is_empty(&self) -> bool {
        self.records.is_empty()
    }

    /// The radiance at `point` on `leaf` of `patch`, whose shading gives `shaded`: the shading plus
    /// the corrections of the leaf's records that reach it; where none does, with `noisy_leaves` the
    /// gathered radiance of the patch's records that reach it; `None` where none does.
    ///
    /// Why the two: a Galerkin solution's leaf is deterministic and smooth, and where no record of it
    /// reaches (a sliver at an edge that neither a pixel centre nor a pixel corner sees) its shading is
    /// nearer than the patch's gathered values spread over it (the Cornell box's 128² image 1.69% against 1.83%)
    /// or another leaf's correction (the same 1.69%). A Monte Carlo solution's leaves are noisy and
    /// outnumber the pixels (40,073 leaves at 128² on the Cornell box): most samples meet a leaf
    /// without a record, and the patch's gathered values give 3.69% where its noisy shading gives
    /// 21.42% and other leaves' corrections 23.63% (BENCHMARKS.md, "A cached final gather").
    pub fn corrected(&self, patch: u32, leaf: ElementId, point: DVec3, shaded: Rgb) -> Option<Rgb> {
        let mean = |same: &dyn Fn(&Record) -> bool, value: fn(&Record) -> Rgb| {
            let (mut sum, mut weights) = (Rgb::BLACK, 0.0);
            self.for_each_near(point, same, |record, d| {
                let w = 1.0 / (d / record.radius + KAPPA) - 1.0 / (1.0 + KAPPA);
                if w > 0.0 {
                    sum += value(record) * w;
                    weights += w;
                }
            });
            (weights > 0.0).then(|| sum / weights)
        };
        mean(&|r| r.leaf == leaf, |r| r.correction)
            .map(|correction| shaded + correction)
            .or_else(|| {
                self.settings
                    .noisy_leaves
                    .then(|| mean(&|r| r.patch == patch, |r| r.gathered))
                    .flatten()
            })
    }

    /// Whether a record of `leaf` lies within [`COVERED`] of its radius from `point`.
    fn covers(&self, leaf: ElementId, point: DVec3) -> bool {
        let mut covered = false;
        self.for_each_near(point, &|r| r.leaf == leaf, |record, d| {
            covered |= d < COVERED * record.radius;
        });
        covered
    }

    /// Calls `visit` with each record that `same` accepts within its radius of `point` and the
    /// distance, each once.
    fn for_each_near(
        &self,
        point: DVec3,
        same: &dyn Fn(&Record) -> bool,
        mut visit: impl FnMut(&Record, f64),
    ) {
        for &level in &self.levels {
            let size = self.cell_size(level);
            let key = (level, cell_of(point, size));
            for &i in self.cells.get(&key).into_iter().flatten() {
                let record = &self.records[i as usize];
                if !same(record) {
                    continue;
                }
                let d = record.point.distance(point);
                if d < record.radius {
                    visit(record, d);
                }
            }
        }
    }

    fn cell_size(&self, level: u8) -> f64 {
        self.base * 2f64.powi(i32::from(level))
    }

    fn insert(&mut self, record: Record) {
        let mut level = 0u8;
        while level < MAX_LEVEL && self.cell_size(level) < record.radius {
            level += 1;
        }
        let size = self.cell_size(level);
        let low = cell_of(record.point - DVec3::splat(record.radius), size);
        let high = cell_of(record.point + DVec3::splat(record.radius), size);
        let index = self.records.len() as u32;
        for x in low[0]..=high[0] {
            for y in low[1]..=high[1] {
                for z in low[2]..=high[2] {
                    self.cells
                        .entry((level, [x, y, z]))
                        .or_default()
                        .push(index);
                }
            }
        }
        if let Err(at) = self.levels.binary_search(&level) {
            self.levels.insert(at, level);
        }
        self.records.push(record);
    }
}

fn cell_of(p: DVec3, size: f64) -> [i64; 3] {
    [p.x, p.y, p.z].map(|c| (c / size).floor() as i64)
}

/// Harmonic mean of the distances to the surfaces hit by [`RADIUS_RAYS`] stratified cosine-distributed
/// rays from the candidate (rays that leave the scene count as infinitely far); infinite when all leave.
fn harmonic_mean_distance(visibility: &dyn Visibility, candidate: &Candidate, seed: u64) -> f64 {
    const COLUMNS: usize = 4;
    const ROWS: usize = RADIUS_RAYS / COLUMNS;
    let mut state = splitmix64(seed ^ splitmix64(candidate.key));
    let mut next = || {
        state = splitmix64(state);
        unit_interval(state)
    };
    // Rays start a footprint's hundredth off the surface: past its own polygon's rounding, well short
    // of anything the footprint could resolve.
    let t_min = 1e-2 * candidate.footprint;
    let mut inverse = 0.0;
    for i in 0..RADIUS_RAYS {
        let (column, row) = (i % COLUMNS, i / COLUMNS);
        let s = DVec2::new(
            (column as f64 + next()) / COLUMNS as f64,
            (row as f64 + next()) / ROWS as f64,
        );
        let ray = Ray::new(candidate.point, cosine_direction(candidate.normal, s));
        if let Some(hit) = visibility.intersect(&ray, t_min, f64::INFINITY) {
            inverse += 1.0 / hit.t.max(t_min);
        }
    }
    RADIUS_RAYS as f64 / inverse
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The level grid finds exactly the records a linear scan finds: every record of the leaf whose
    /// radius reaches the point, each once, whatever its level and however its sphere straddles cells.
    #[test]
    fn the_grid_finds_what_a_scan_finds() {
        let mut state = 7u64;
        let mut next = || {
            state = splitmix64(state);
            unit_interval(state)
        };
        let mut cache = IrradianceCache::new(CacheSettings::default(), 10.0, 1);
        for _ in 0..2000 {
            let point = DVec3::new(next(), next(), next()) * 10.0 - 5.0;
            cache.insert(Record {
                patch: 0,
                leaf: (next() * 3.0) as u32,
                point,
                // Radii over five decades: many levels.
                radius: 1e-3 * 10f64.powf(5.0 * next()),
                correction: Rgb::BLACK,
                gathered: Rgb::BLACK,
            });
        }
        assert!(cache.levels.len() >= 10, "{} levels", cache.levels.len());
        for _ in 0..2000 {
            let (leaf, point) = (
                (next() * 3.0) as u32,
                DVec3::new(next(), next(), next()) * 10.0 - 5.0,
            );
            let mut found = Vec::new();
            cache.for_each_near(point, &|r| r.leaf == leaf, |r, d| {
                found.push((r.point.to_array(), d))
            });
            let mut scanned: Vec<_> = cache
                .records
                .iter()
                .filter(|r| r.leaf == leaf && r.point.distance(point) < r.radius)
                .map(|r| (r.point.to_array(), r.point.distance(point)))
                .collect();
            let key = |a: &([f64; 3], f64), b: &([f64; 3], f64)| a.partial_cmp(b).unwrap();
            found.sort_by(key);
            scanned.sort_by(key);
            assert_eq!(found, scanned);
        }
    }

    /// The corner pass's placement: a candidate becomes a record only where the cache would show its
    /// shading uncorrected. Beside a record of leaf 10 (radius 32 footprints in an empty scene): a
    /// candidate of the same leaf is corrected already; one of leaf 11 on the same patch gets a record
    /// unless the leaves are noisy, when the patch's record corrects it; Ward's spacing makes a record
    /// of leaf 11 either way, and none of leaf 10 within half the radius.
    #[test]
    fn records_where_uncorrected_follow_what_corrected_shows() {
        let empty = crate::visibility::brute_force::BruteForce::new(Vec::new());
        let candidate = |leaf: ElementId, x: f64| Candidate {
            patch: 1,
            leaf,
            point: DVec3::new(x, 0.0, 0.0),
            normal: DVec3::Z,
            footprint: 0.01,
            key: leaf as u64,
            shaded: Rgb::new(0.5, 0.5, 0.5),
        };
        for noisy_leaves in [false, true] {
            let settings = CacheSettings {
                noisy_leaves,
                ..CacheSettings::default()
            };
            let records_after = |placement: Placement, leaf: ElementId| {
                let mut cache = IrradianceCache::new(settings, 10.0, 1);
                cache.offer(&candidate(10, 0.0), &empty, Placement::Spaced);
                assert_eq!(cache.len(), 1);
                cache.offer(&candidate(leaf, 0.1), &empty, placement);
                cache.len()
            };
            assert_eq!(records_after(Placement::WhereUncorrected, 10), 1);
            assert_eq!(
                records_after(Placement::WhereUncorrected, 11),
                if noisy_leaves { 1 } else { 2 }
            );
            assert_eq!(records_after(Placement::Spaced, 11), 2);
            assert_eq!(records_after(Placement::Spaced, 10), 1);
        }
    }

    /// A sample reached by a record of its own leaf takes its shading plus that record's correction;
    /// one on another leaf of the same patch keeps its shading (`None`), unless the leaves are noisy,
    /// when it takes the records' gathered radiance; another patch's records never reach it.
    #[test]
    fn leaves_take_their_own_corrections_and_noisy_leaves_the_patch_gather() {
        let record = Record {
            patch: 1,
            leaf: 10,
            point: DVec3::ZERO,
            radius: 1.0,
            correction: Rgb::new(0.1, 0.2, 0.3),
            gathered: Rgb::new(1.0, 2.0, 3.0),
        };
        let shaded = Rgb::new(0.5, 0.5, 0.5);
        let near = DVec3::new(0.3, 0.0, 0.0);
        for noisy_leaves in [false, true] {
            let settings = CacheSettings {
                noisy_leaves,
                ..CacheSettings::default()
            };
            let mut cache = IrradianceCache::new(settings, 10.0, 1);
            cache.insert(record);
            let close = |a: Rgb, b: Rgb| (a - b).map(f64::abs).max_channel() < 1e-12;
            let own = cache.corrected(1, 10, near, shaded).expect("its own leaf");
            assert!(close(own, shaded + record.correction), "{own:?}");
            let other = cache.corrected(1, 11, near, shaded);
            assert_eq!(other.is_some(), noisy_leaves);
            if let Some(other) = other {
                assert!(close(other, record.gathered), "{other:?}");
            }
            assert_eq!(cache.corrected(2, 12, near, shaded), None);
            assert_eq!(
                cache.corrected(1, 10, DVec3::new(1.5, 0.0, 0.0), shaded),
                None
            );
        }
    }
}
