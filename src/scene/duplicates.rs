//! Exact duplicate polygons: the same vertices in the same cyclic order with the same material, e.g. a
//! piece of furniture included twice. Both copies would emit and reflect, doubling the light of that
//! place, so one is kept (unless `--keep-duplicates`) and each group of duplicates is reported once.
//!
//! Vertices are compared after quantising to [`RELATIVE_STEP`] of the scene's diagonal, which absorbs the
//! rounding of different transform paths to the same place; each polygon's vertex cycle is rotated to
//! start at its smallest quantised vertex, so that cyclically shifted copies have the same key. A hash
//! map over the keys finds every duplicate in O(n). Reversed copies face the other way and are kept.

use super::{Diagnostic, Scene};
use std::collections::HashMap;
use std::path::PathBuf;

/// Quantisation step of vertex coordinates, relative to the scene's bounding-box diagonal.
pub const RELATIVE_STEP: f64 = 1e-9;

/// A polygon's identity for duplicate detection: material, sidedness and rotated quantised vertices.
type Key = (usize, bool, Vec<[i64; 3]>);

/// Removes exact duplicates, keeping the first of each, and adds one warning per group: the duplicates
/// that come from one place (file or include chain) and repeat polygons of one other place. Returns the
/// number of polygons removed.
pub fn remove_duplicates(scene: &mut Scene) -> usize {
    let diagonal = scene.bounds().diagonal();
    if !(diagonal.is_finite() && diagonal > 0.0) {
        return 0;
    }
    let step = diagonal * RELATIVE_STEP;
    let mut first: HashMap<Key, usize> = HashMap::with_capacity(scene.polygons.len());
    // (place of the duplicate, place of the original) -> the (duplicate, original) polygon pairs.
    let mut groups: HashMap<(usize, usize), Vec<(usize, usize)>> = HashMap::new();
    let mut group_order = Vec::new();
    let mut keep = vec![true; scene.polygons.len()];
    for (index, polygon) in scene.polygons.iter().enumerate() {
        let mut vertices: Vec<[i64; 3]> = polygon
            .shape
            .vertices()
            .iter()
            .map(|v| [v.x, v.y, v.z].map(|c| (c / step).round() as i64))
            .collect();
        let smallest = (0..vertices.len())
            .min_by_key(|&k| vertices[k])
            .unwrap_or(0);
        vertices.rotate_left(smallest);
        let key = (polygon.material, polygon.two_sided, vertices);
        match first.get(&key) {
            None => {
                first.insert(key, index);
            }
            Some(&original) => {
                keep[index] = false;
                let places = (
                    scene.origins.place_of(index),
                    scene.origins.place_of(original),
                );
                groups
                    .entry(places)
                    .or_insert_with(|| {
                        group_order.push(places);
                        Vec::new()
                    })
                    .push((index, original));
            }
        }
    }
    for places in group_order {
        let pairs = &groups[&places];
        let (duplicate, original) = pairs[0];
        let (file, line) = scene.origins.get(duplicate);
        let (original_file, original_line) = scene.origins.get(original);
        let message = format!(
            "{} polygon(s) from here repeat exactly (same vertices, same material) those from {}:{}: \
             one of each kept, copies would double the light (--keep-duplicates keeps them)",
            pairs.len(),
            original_file.display(),
            original_line,
        );
        scene.warnings.push(Diagnostic {
            file,
            line,
            message,
        });
    }
    let removed = keep.iter().filter(|k| !**k).count();
    if removed > 0 {
        let mut k = 0;
        scene.polygons.retain(|_| {
            k += 1;
            keep[k - 1]
        });
        scene.origins.retain(&keep);
    }
    removed
}

/// Where each polygon was read: a place (a file, or for an included MGF file the include chain that
/// reached it, `a.mgf:30 -> b.mgf`) and a line. Empty for generated scenes.
#[derive(Clone, Debug, Default)]
pub struct Origins {
    places: Vec<PathBuf>,
    lookup: HashMap<PathBuf, usize>,
    /// (place, line) of each polygon, parallel to `Scene::polygons`.
    polygons: Vec<(u32, u32)>,
}

impl Origins {
    /// Records that the polygons up to `polygon_count` (those added since the last call) were read at
    /// `place`:`line`.
    pub fn record(&mut self, place: &std::path::Path, line: usize, polygon_count: usize) {
        let next = self.places.len();
        let index = *self.lookup.entry(place.to_path_buf()).or_insert(next);
        if index == next {
            self.places.push(place.to_path_buf());
        }
        let entry = (index as u32, line.min(u32::MAX as usize) as u32);
        self.polygons
            .resize(polygon_count.max(self.polygons.len()), entry);
    }

    /// The place and line polygon `index` was read at (an empty path and 0 when unknown).
    pub fn get(&self, index: usize) -> (PathBuf, usize) {
        match self.polygons.get(index) {
            Some(&(place, line)) => (self.places[place as usize].clone(), line as usize),
            None => (PathBuf::new(), 0),
        }
    }

    pub(crate) fn place_of(&self, index: usize) -> usize {
        self.polygons
            .get(index)
            .map_or(usize::MAX, |&(place, _)| place as usize)
    }

    /// Gives polygon `i`'s origin to `counts[i]` consecutive polygons (a polygon split into pieces, see
    /// [`super::contacts`]); polygons without a recorded origin stay without one.
    pub fn repeat(&mut self, counts: &[usize]) {
        if self.polygons.is_empty() {
            return;
        }
        let mut repeated = Vec::with_capacity(counts.iter().sum());
        for (k, &count) in counts.iter().enumerate() {
            match self.polygons.get(k) {
                Some(&entry) => repeated.extend(std::iter::repeat_n(entry, count)),
                None => break,
            }
        }
        self.polygons = repeated;
    }

    fn retain(&mut self, keep: &[bool]) {
        let mut k = 0;
        self.polygons.retain(|_| {
            k += 1;
            keep.get(k - 1).copied().unwrap_or(true)
        });
    }
}
