//! Cluster hierarchies over a set of objects (Sillion–Drettakis §4): the paper's multi-level uniform grid
//! construction, and, to compare with it (§4.2), a k-d tree split at the median and an octree
//! (`--hierarchy grid|kdtree|octree`). The same trees serve the clustering solver (patches grouped into
//! cluster elements, [`crate::hierarchy::Hierarchy::add_clusters`]) and extinction visibility (polygons
//! grouped into absorbing volumes, [`crate::visibility::extinction`]).
//!
//! Every construction is deterministic: ties are broken by object index, never by hashing or threads.

use crate::geometry::{Aabb, DVec3};
use std::sync::Arc;

/// How the cluster tree is built (`--hierarchy`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum ClusterTreeKind {
    /// Sillion–Drettakis §4.1: objects inserted into the level of a hierarchy of uniform grids whose
    /// voxel fits their size, grouped per voxel to minimise empty space, leftovers moved up.
    #[default]
    Grid,
    /// Median split of the object centres along the longest axis (the hierarchy of Sillion 1995).
    Kdtree,
    /// Regular octree: each cell split at its centre into eight, objects by their centre.
    Octree,
}

/// How clusters exchange light (`--clustering`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum ClusteringKind {
    /// No clusters: every pair of patches that can interact starts linked (quadratic).
    #[default]
    None,
    /// Clusters as isotropic volumes (Sillion 1995): mean cosine 1/4. With item buffers a cluster's
    /// mean cosine is its visible projected area over its area for either kind
    /// (`solvers::clustering::mean_cosine`), so this differs from `Oriented` only without them.
    Isotropic,
    /// Clusters by the projected area of their patches toward the other end (Smits et al. 1994).
    Oriented,
    /// Oriented where the unclustered start (every facing pair of patches linked) would exceed the
    /// link budget of `--max-memory` or a bound: 10k links under the power oracle (the default), 4M
    /// under the others; none otherwise (`pipeline::auto_clustering_links`).
    Auto,
}

/// An object to cluster: its bounds and the area it contributes to a cluster's total.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Item {
    pub bounds: Aabb,
    pub area: f64,
}

/// A member of a cluster: an object or a cluster below it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Child {
    Item(u32),
    Node(u32),
}

/// A cluster: the bounds and total area of its contents.
#[derive(Clone, Debug, PartialEq)]
pub struct Node {
    pub bounds: Aabb,
    /// Total area of all objects below.
    pub area: f64,
    pub children: Vec<Child>,
}

/// A tree of clusters over items; `nodes` is in post-order (every node after its children), so the
/// root is the last node and bottom-up passes walk the nodes in order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ClusterTree {
    pub nodes: Vec<Node>,
}

/// Most members of one cluster.
pub const MAX_CHILDREN: usize = 8;

impl ClusterTree {
    /// The cluster tree of `items` by `kind`; empty for no items, and a root holding the lone item for
    /// one.
    pub fn build(items: &[Item], kind: ClusterTreeKind) -> Self {
        let mut tree = ClusterTree::default();
        if items.is_empty() {
            return tree;
        }
        let all: Vec<Child> = (0..items.len() as u32).map(Child::Item).collect();
        let top = match kind {
            ClusterTreeKind::Grid => grid::build(&mut tree, items, all),
            ClusterTreeKind::Kdtree => tree.kdtree(items, all),
            ClusterTreeKind::Octree => {
                let cell = cube_around(&union(items, &tree, &all));
                tree.octree(items, all, cell, 0)
            }
        };
        if let Child::Item(_) = top {
            tree.push(items, vec![top]);
        }
        tree
    }

    pub fn root(&self) -> Option<u32> {
        self.nodes.len().checked_sub(1).map(|r| r as u32)
    }

    fn bounds_of(&self, items: &[Item], child: Child) -> Aabb {
        match child {
            Child::Item(i) => items[i as usize].bounds,
            Child::Node(n) => self.nodes[n as usize].bounds,
        }
    }

    fn area_of(&self, items: &[Item], child: Child) -> f64 {
        match child {
            Child::Item(i) => items[i as usize].area,
            Child::Node(n) => self.nodes[n as usize].area,
        }
    }

    /// Appends a cluster of `children` and returns it.
    fn push(&mut self, items: &[Item], children: Vec<Child>) -> Child {
        let bounds = union(items, self, &children);
        let area = children.iter().map(|&c| self.area_of(items, c)).sum();
        self.nodes.push(Node {
            bounds,
            area,
            children,
        });
        Child::Node(self.nodes.len() as u32 - 1)
    }

    /// Median split of the centres along the longest axis of their bounds, down to leaves of at most
    /// [`MAX_CHILDREN`] objects.
    fn kdtree(&mut self, items: &[Item], mut members: Vec<Child>) -> Child {
        if members.len() == 1 {
            return members[0];
        }
        if members.len() <= MAX_CHILDREN {
            return self.push(items, members);
        }
        let upper = self.median_split(items, &mut members);
        let children = vec![self.kdtree(items, members), self.kdtree(items, upper)];
        self.push(items, children)
    }

    /// Sorts `members` by centre along the longest axis of their centres' bounds and splits off the
    /// upper half (ties by identity, so the split is deterministic).
    fn median_split(&self, items: &[Item], members: &mut Vec<Child>) -> Vec<Child> {
        let centres: Aabb = members.iter().fold(Aabb::EMPTY, |mut b, &c| {
            b.grow(self.bounds_of(items, c).center());
            b
        });
        let axis = longest_axis(centres.extent());
        members.sort_by(|&a, &b| {
            let (ca, cb) = (
                self.bounds_of(items, a).center()[axis],
                self.bounds_of(items, b).center()[axis],
            );
            ca.total_cmp(&cb).then(a.cmp(&b))
        });
        members.split_off(members.len() / 2)
    }

    /// The cube `cell` split at its centre; each object goes to the octant of its centre. Cells with at
    /// most [`MAX_CHILDREN`] objects (or too deep to separate coincident centres) become leaf clusters.
    fn octree(&mut self, items: &[Item], members: Vec<Child>, cell: Aabb, depth: usize) -> Child {
        const MAX_DEPTH: usize = 24;
        if members.len() == 1 {
            return members[0];
        }
        if members.len() <= MAX_CHILDREN || depth >= MAX_DEPTH {
            return self.push_in_chunks(items, members);
        }
        let mid = cell.center();
        let mut octants: [Vec<Child>; 8] = Default::default();
        for &m in &members {
            let c = self.bounds_of(items, m).center();
            let k = usize::from(c.x >= mid.x)
                | usize::from(c.y >= mid.y) << 1
                | usize::from(c.z >= mid.z) << 2;
            octants[k].push(m);
        }
        let mut children = Vec::new();
        for (k, octant) in octants.into_iter().enumerate() {
            if octant.is_empty() {
                continue;
            }
            let pick = |bit: usize, lo: f64, m: f64, hi: f64| {
                if k & bit != 0 {
                    (m, hi)
                } else {
                    (lo, m)
                }
            };
            let (x0, x1) = pick(1, cell.min.x, mid.x, cell.max.x);
            let (y0, y1) = pick(2, cell.min.y, mid.y, cell.max.y);
            let (z0, z1) = pick(4, cell.min.z, mid.z, cell.max.z);
            let sub = Aabb {
                min: DVec3::new(x0, y0, z0),
                max: DVec3::new(x1, y1, z1),
            };
            children.push(self.octree(items, octant, sub, depth + 1));
        }
        if children.len() == 1 {
            return children[0];
        }
        self.push(items, children)
    }

    /// Clusters of at most [`MAX_CHILDREN`] members over `members` (in their order), then clusters of
    /// those, up to one.
    fn push_in_chunks(&mut self, items: &[Item], mut members: Vec<Child>) -> Child {
        while members.len() > MAX_CHILDREN {
            members = members
                .chunks(MAX_CHILDREN)
                .map(|chunk| {
                    if chunk.len() == 1 {
                        chunk[0]
                    } else {
                        self.push(items, chunk.to_vec())
                    }
                })
                .collect();
        }
        if members.len() == 1 {
            members[0]
        } else {
            self.push(items, members)
        }
    }
}

fn union(items: &[Item], tree: &ClusterTree, members: &[Child]) -> Aabb {
    members
        .iter()
        .fold(Aabb::EMPTY, |b, &c| b.union(&tree.bounds_of(items, c)))
}

fn longest_axis(e: DVec3) -> usize {
    if e.x >= e.y && e.x >= e.z {
        0
    } else if e.y >= e.z {
        1
    } else {
        2
    }
}

fn largest_extent(b: &Aabb) -> f64 {
    b.extent().max_element()
}

/// The cube with the same centre whose side is the largest extent of `b` (at least a tiny positive
/// size, so that degenerate scenes still have cells).
fn cube_around(b: &Aabb) -> Aabb {
    let half = DVec3::splat(0.5 * largest_extent(b).max(1e-12));
    Aabb {
        min: b.center() - half,
        max: b.center() + half,
    }
}

/// The multi-level grid construction of Sillion–Drettakis §4.1.
mod grid {
    use super::*;
    use std::collections::BTreeMap;

    /// Deepest grid level (2^16 voxels per axis); smaller objects all start there.
    const MAX_LEVEL: usize = 16;
    /// A group takes a further member only while at most this fraction of its bounds is empty (the
    /// proximity criterion), unless the member is very small for the voxel.
    const MAX_EMPTY_FRACTION: f64 = 0.85;
    /// Members smaller than this fraction of the voxel are grouped regardless of the empty space they
    /// add ("objects very small compared to the grid size are grouped into an appropriate cluster,
    /// even if the resulting cluster is largely empty").
    const SMALL_FRACTION: f64 = 0.25;
    /// Voxels holding more members than this are first split at the median (kd) into runs of this size
    /// so that the quadratic greedy grouping stays bounded.
    const MAX_RUN: usize = 256;

    struct Grid {
        origin: DVec3,
        size: f64,
    }

    impl Grid {
        fn voxel(&self, level: usize) -> f64 {
            self.size / (1u64 << level) as f64
        }

        /// The level whose voxel fits an object of this largest extent.
        fn level_of(&self, extent: f64) -> usize {
            if extent <= 0.0 {
                return MAX_LEVEL;
            }
            ((self.size / extent).log2().floor().max(0.0) as usize).min(MAX_LEVEL)
        }

        fn cell(&self, p: DVec3, level: usize) -> [i64; 3] {
            let q = (p - self.origin) / self.voxel(level);
            [q.x.floor() as i64, q.y.floor() as i64, q.z.floor() as i64]
        }
    }

    /// Padded volume: flat objects (polygons) have empty boxes, so every extent is padded by a small
    /// fraction of the voxel for the empty-space measure.
    fn volume(b: &Aabb, pad: f64) -> f64 {
        let e = b.extent() + DVec3::splat(pad);
        e.x * e.y * e.z
    }

    pub(super) fn build(tree: &mut ClusterTree, items: &[Item], all: Vec<Child>) -> Child {
        let scene = union(items, tree, &all);
        let grid = Grid {
            origin: scene.min,
            size: largest_extent(&scene).max(1e-12),
        };
        let mut pending: Vec<Vec<Child>> = vec![Vec::new(); MAX_LEVEL + 1];
        for c in all {
            let level = grid.level_of(largest_extent(&tree.bounds_of(items, c)));
            pending[level].push(c);
        }
        for level in (1..=MAX_LEVEL).rev() {
            let members = std::mem::take(&mut pending[level]);
            if members.is_empty() {
                continue;
            }
            let moved_up = group_level(tree, items, &grid, level, members);
            pending[level - 1].extend(moved_up);
        }
        // Level 0 is one voxel, the scene: group until one cluster remains.
        let mut members = std::mem::take(&mut pending[0]);
        let pad = 0.01 * grid.size;
        loop {
            if members.len() == 1 {
                return members[0];
            }
            let before = members.len();
            members = group_voxel(tree, items, members, grid.size, pad);
            if members.len() == before {
                // Nothing merged (every candidate too empty): force one level of chunks.
                return tree.push_in_chunks(items, members);
            }
        }
    }

    /// Size class of an object in a voxel: how many halvings of the voxel it fits (0 for objects of the
    /// voxel's size, up to 3 for objects at most an eighth of it, which count as one class of "very
    /// small" objects).
    fn size_class(extent: f64, voxel: f64) -> usize {
        if extent <= 0.0 {
            return 3;
        }
        ((voxel / extent).log2().floor().max(0.0) as usize).min(3)
    }

    /// One level: groups the members contained in one voxel (by size class), adds the leftovers (members straddling
    /// voxels) to the groups they overlap where that grows them least, and returns everything that
    /// moves up to the next coarser level.
    fn group_level(
        tree: &mut ClusterTree,
        items: &[Item],
        grid: &Grid,
        level: usize,
        members: Vec<Child>,
    ) -> Vec<Child> {
        let voxel = grid.voxel(level);
        let pad = 0.01 * voxel;
        let mut contained: BTreeMap<[i64; 3], Vec<Child>> = BTreeMap::new();
        let mut leftovers = Vec::new();
        for c in members {
            let b = tree.bounds_of(items, c);
            let (lo, hi) = (grid.cell(b.min, level), grid.cell(b.max, level));
            if lo == hi {
                contained.entry(lo).or_default().push(c);
            } else {
                leftovers.push(c);
            }
        }
        let mut up = Vec::new();
        // The clusters made at this level, by voxel, that leftovers may join (all made after every
        // leftover, so that the nodes stay in post-order).
        let mut made: BTreeMap<[i64; 3], Vec<u32>> = BTreeMap::new();
        let first_new = tree.nodes.len() as u32;
        for (cell, voxel_members) in contained {
            // Homogeneity: objects are grouped with objects of their own size class only.
            let mut classes: BTreeMap<usize, Vec<Child>> = BTreeMap::new();
            for c in voxel_members {
                let extent = largest_extent(&tree.bounds_of(items, c));
                classes
                    .entry(size_class(extent, voxel))
                    .or_default()
                    .push(c);
            }
            let groups: Vec<Child> = classes
                .into_values()
                .flat_map(|class| group_voxel(tree, items, class, voxel, pad))
                .collect();
            for g in groups {
                if let Child::Node(n) = g {
                    if n >= first_new {
                        made.entry(cell).or_default().push(n);
                    }
                }
                up.push(g);
            }
        }
        for c in leftovers {
            let b = tree.bounds_of(items, c);
            let (lo, hi) = (grid.cell(b.min, level), grid.cell(b.max, level));
            let mut best: Option<(f64, u32)> = None;
            for x in lo[0]..=hi[0] {
                for y in lo[1]..=hi[1] {
                    for z in lo[2]..=hi[2] {
                        for &n in made.get(&[x, y, z]).into_iter().flatten() {
                            let node = &tree.nodes[n as usize];
                            if node.children.len() >= MAX_CHILDREN {
                                continue;
                            }
                            let merged = node.bounds.union(&b);
                            let filled = volume(&node.bounds, pad) + volume(&b, pad);
                            let empty = 1.0 - (filled / volume(&merged, pad)).min(1.0);
                            if empty <= MAX_EMPTY_FRACTION && best.is_none_or(|(e, _)| empty < e) {
                                best = Some((empty, n));
                            }
                        }
                    }
                }
            }
            match best {
                Some((_, n)) => {
                    let area = tree.area_of(items, c);
                    let node = &mut tree.nodes[n as usize];
                    node.bounds = node.bounds.union(&b);
                    node.area += area;
                    node.children.push(c);
                }
                None => up.push(c),
            }
        }
        up
    }

    /// Greedy grouping of the members of one voxel into clusters of at most [`MAX_CHILDREN`]: each group
    /// is seeded with the largest remaining member and grows by the member that leaves the least empty
    /// space, while the empty fraction stays acceptable. Returns the new clusters and the members left
    /// alone.
    fn group_voxel(
        tree: &mut ClusterTree,
        items: &[Item],
        mut members: Vec<Child>,
        voxel: f64,
        pad: f64,
    ) -> Vec<Child> {
        if members.len() > MAX_RUN {
            // Bounded work: median runs first (a kd split), then each run on its own.
            let mut out = Vec::new();
            let upper = tree.median_split(items, &mut members);
            out.extend(group_voxel(tree, items, members, voxel, pad));
            out.extend(group_voxel(tree, items, upper, voxel, pad));
            return out;
        }
        let bounds: Vec<Aabb> = members.iter().map(|&c| tree.bounds_of(items, c)).collect();
        let mut order: Vec<usize> = (0..members.len()).collect();
        order.sort_by(|&a, &b| {
            largest_extent(&bounds[b])
                .total_cmp(&largest_extent(&bounds[a]))
                .then(members[a].cmp(&members[b]))
        });
        let mut taken = vec![false; members.len()];
        let mut out = Vec::new();
        for &seed in &order {
            if taken[seed] {
                continue;
            }
            taken[seed] = true;
            let mut group = vec![members[seed]];
            let mut b = bounds[seed];
            let mut filled = volume(&b, pad);
            while group.len() < MAX_CHILDREN {
                let mut best: Option<(f64, usize)> = None;
                for (k, other) in bounds.iter().enumerate() {
                    if taken[k] {
                        continue;
                    }
                    let merged = volume(&b.union(other), pad);
                    let empty = 1.0 - ((filled + volume(other, pad)) / merged).min(1.0);
                    if best.is_none_or(|(e, _)| empty < e) {
                        best = Some((empty, k));
                    }
                }
                let Some((empty, k)) = best else { break };
                let small = largest_extent(&bounds[k]) < SMALL_FRACTION * voxel;
                if empty > MAX_EMPTY_FRACTION && !small {
                    break;
                }
                taken[k] = true;
                group.push(members[k]);
                filled += volume(&bounds[k], pad);
                b = b.union(&bounds[k]);
            }
            out.push(if group.len() == 1 {
                group[0]
            } else {
                tree.push(items, group)
            });
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The sparse visible fractions give back every patch's fraction (hidden and fully visible ones
    /// exactly, the rest within half a fixed-point step) across block boundaries, and each group's
    /// area is the sum of its members' areas times their stored fractions, 0 exactly for a group whose
    /// members are all hidden (up to 70 groups: the groups' bitmap spans several words).
    #[test]
    fn visible_areas_keep_every_fraction() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(3);
        for (patches, directions) in [(1, 3), (63, 3), (64, 3), (65, 3), (200, 3), (1000, 70)] {
            // Directions on a spiral over the sphere, one normal group each; every fifth hidden,
            // every seventh seen whole.
            let direction = |k: usize| {
                let z = 1.0 - 2.0 * (k % directions) as f64 / directions as f64 - 0.01;
                let phi = 2.4 * (k % directions) as f64;
                let r = (1.0 - z * z).sqrt();
                DVec3::new(r * phi.cos(), r * phi.sin(), z)
            };
            let facings: Vec<Facing> = (0..patches)
                .map(|k| Facing {
                    normal: direction(k),
                    area: rng.random_range(0.1..2.0),
                    centroid: DVec3::new(k as f64, 0.0, 0.0),
                })
                .collect();
            let orientation = Orientation::new(&facings);
            let areas: Vec<f64> = facings.iter().map(|f| f.area).collect();
            let fractions: Vec<f32> = (0..patches)
                .map(|k| match rng.random_range(0..4) {
                    _ if k % directions % 5 == 4 => 0.0,
                    _ if k % directions % 7 == 3 => 1.0,
                    0 | 1 => 0.0,
                    2 => 1.0,
                    _ => rng.random(),
                })
                .collect();
            let visible = VisibleAreas::new(&orientation, &areas, &fractions);
            for (k, (&f, stored)) in fractions.iter().zip(visible.fractions()).enumerate() {
                assert_eq!(stored, visible.fraction(k));
                if f == 0.0 || f == 1.0 {
                    assert_eq!(stored, f, "patch {k} of {patches}");
                } else {
                    assert!(
                        (stored - f).abs() <= 0.5 / FRACTION_STEPS,
                        "patch {k}: {stored} vs {f}"
                    );
                }
            }
            for (g, group) in orientation.groups.iter().enumerate() {
                let members =
                    &orientation.members[group.members.start as usize..group.members.end as usize];
                let sum: f64 = members
                    .iter()
                    .map(|&k| areas[k as usize] * f64::from(visible.fraction(k as usize)))
                    .sum();
                let area = visible.group_area(&orientation, g);
                assert!((f64::from(area) - sum).abs() <= 1e-6 * sum.max(1e-30));
                if sum == 0.0 {
                    assert_eq!(area, 0.0);
                }
                if members.iter().all(|&k| fractions[k as usize] == 1.0) {
                    assert_eq!(area, group.area as f32, "a group seen whole");
                }
            }
            let listed: Vec<f32> = visible.group_areas(&orientation).collect();
            let single: Vec<f32> = (0..orientation.groups.len())
                .map(|g| visible.group_area(&orientation, g))
                .collect();
            assert_eq!(listed, single);
            if directions > 32 {
                assert!(
                    orientation.groups.len() > 32,
                    "{}",
                    orientation.groups.len()
                );
                assert!(listed.contains(&0.0));
                assert!(orientation
                    .groups
                    .iter()
                    .zip(&listed)
                    .any(|(g, &a)| a == g.area as f32));
            }
        }
    }

    fn boxes(n: usize) -> Vec<Item> {
        // A deterministic scatter of small boxes of a few sizes.
        (0..n)
            .map(|i| {
                let f = |k: usize| ((i * 7919 + k * 104_729) % 1000) as f64 / 1000.0;
                let size = [0.01, 0.03, 0.1][i % 3];
                let min = DVec3::new(f(1), f(2), f(3)) * 4.0;
                Item {
                    bounds: Aabb {
                        min,
                        max: min + DVec3::new(size, size, 0.0),
                    },
                    area: size * size,
                }
            })
            .collect()
    }

    /// Every item appears exactly once, post-order holds, bounds contain the contents, areas add up,
    /// and no cluster exceeds the fan-out.
    #[test]
    fn every_kind_builds_a_proper_tree() {
        let items = boxes(500);
        let total: f64 = items.iter().map(|i| i.area).sum();
        for kind in [
            ClusterTreeKind::Grid,
            ClusterTreeKind::Kdtree,
            ClusterTreeKind::Octree,
        ] {
            let tree = ClusterTree::build(&items, kind);
            let root = tree.root().expect("root") as usize;
            assert!(
                (tree.nodes[root].area - total).abs() < 1e-9 * total,
                "{kind:?}"
            );
            let mut seen = vec![0; items.len()];
            for (n, node) in tree.nodes.iter().enumerate() {
                assert!(!node.children.is_empty() && node.children.len() <= MAX_CHILDREN);
                for &c in &node.children {
                    let b = tree.bounds_of(&items, c);
                    assert!(
                        b.min.cmpge(node.bounds.min).all() && b.max.cmple(node.bounds.max).all()
                    );
                    match c {
                        Child::Item(i) => seen[i as usize] += 1,
                        Child::Node(m) => assert!((m as usize) < n, "{kind:?}: not post-order"),
                    }
                }
            }
            assert!(
                seen.iter().all(|&s| s == 1),
                "{kind:?}: items not once each"
            );
            assert_eq!(
                tree,
                ClusterTree::build(&items, kind),
                "{kind:?}: deterministic"
            );
        }
    }

    /// Share of the objects in clusters of two or more objects that belong to their cluster's most
    /// common size class.
    fn homogeneity(items: &[Item], tree: &ClusterTree) -> f64 {
        let (mut same, mut total) = (0, 0);
        for node in &tree.nodes {
            let sizes: Vec<u64> = node
                .children
                .iter()
                .filter_map(|&c| match c {
                    Child::Item(i) => Some(largest_extent(&items[i as usize].bounds).to_bits()),
                    Child::Node(_) => None,
                })
                .collect();
            if sizes.len() >= 2 {
                total += sizes.len();
                same += sizes
                    .iter()
                    .map(|s| sizes.iter().filter(|&t| t == s).count())
                    .max()
                    .unwrap_or(0);
            }
        }
        same as f64 / total.max(1) as f64
    }

    /// The grid construction groups objects of similar size (§4.1's homogeneity), which the k-d tree,
    /// blind to size, does not (§4.2).
    #[test]
    fn grid_clusters_are_more_homogeneous_in_size_than_kdtree_clusters() {
        let items = boxes(3000);
        let grid = homogeneity(&items, &ClusterTree::build(&items, ClusterTreeKind::Grid));
        let kd = homogeneity(&items, &ClusterTree::build(&items, ClusterTreeKind::Kdtree));
        assert!(grid > kd + 0.1, "grid {grid}, kd-tree {kd}");
    }

    #[test]
    fn one_item_gets_a_root_and_none_gets_none() {
        let items = boxes(1);
        for kind in [
            ClusterTreeKind::Grid,
            ClusterTreeKind::Kdtree,
            ClusterTreeKind::Octree,
        ] {
            let tree = ClusterTree::build(&items, kind);
            assert_eq!(tree.nodes.len(), 1);
            assert_eq!(tree.nodes[0].children, vec![Child::Item(0)]);
            assert!(ClusterTree::build(&[], kind).root().is_none());
        }
    }
}

/// Octahedral cells per axis of the normal quantisation of [`Orientation`]: cells of about 5°.
pub const NORMAL_CELLS: u32 = 32;

/// A cluster's patches grouped by normal direction: its projected area toward any point (Smits et al.
/// 1994's oriented transfer, `Σ_k A_k max(0, n_k · d_k)`) costs one term per group instead of one per
/// patch, and so does pushing what the cluster gathers down to its patches. Patches whose normals fall
/// in one octahedral cell of [`NORMAL_CELLS`]² form a group with their area-weighted mean normal
/// `n̄ = Σ A_k n_k / A` and centroid: `A max(0, n̄ · d)` equals the group's projected area exactly while
/// every member faces `d`, and it is what the push distributes by, so the push conserves the power a
/// link delivers whatever the grouping.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Orientation {
    /// Exactly as many as there are (a cluster keeps its orientation for the whole solve).
    pub groups: Box<[NormalGroup]>,
    /// Positions in the cluster's contents, group after group.
    pub members: Box<[u32]>,
    /// Running area over `members` (inclusive), to sample a member by area within its group.
    pub cumulative_area: Box<[f64]>,
}

/// Patches of a cluster with nearly the same normal (see [`Orientation`]).
#[derive(Clone, Debug, PartialEq)]
pub struct NormalGroup {
    /// Area-weighted mean normal (length at most 1).
    pub normal: DVec3,
    pub area: f64,
    /// Area-weighted centroid.
    pub centroid: DVec3,
    /// Range in [`Orientation::members`].
    pub members: std::ops::Range<u32>,
}

/// A patch as [`Orientation::new`] groups it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Facing {
    pub normal: DVec3,
    pub area: f64,
    pub centroid: DVec3,
}

impl Orientation {
    /// Groups `patches` (a cluster's contents, in order) by the octahedral cell of their normal;
    /// members keep content order within a group, groups are in cell order (deterministic).
    pub fn new(patches: &[Facing]) -> Self {
        let mut order: Vec<(u32, u32)> = patches
            .iter()
            .enumerate()
            .map(|(k, p)| (octahedral_cell(p.normal), k as u32))
            .collect();
        order.sort_unstable();
        let mut groups: Vec<NormalGroup> = Vec::new();
        let mut cumulative = Vec::with_capacity(order.len());
        let mut running = 0.0;
        let mut previous = None;
        for (position, &(cell, k)) in order.iter().enumerate() {
            let p = &patches[k as usize];
            if previous != Some(cell) {
                groups.push(NormalGroup {
                    normal: DVec3::ZERO,
                    area: 0.0,
                    centroid: DVec3::ZERO,
                    members: position as u32..position as u32,
                });
                previous = Some(cell);
            }
            let g = groups.last_mut().expect("a group was just pushed");
            g.normal += p.normal * p.area;
            g.centroid += p.centroid * p.area;
            g.area += p.area;
            g.members.end += 1;
            running += p.area;
            cumulative.push(running);
        }
        for g in &mut groups {
            if g.area > 0.0 {
                g.normal /= g.area;
                g.centroid /= g.area;
            } else {
                let first = &patches[order[g.members.start as usize].1 as usize];
                g.centroid = first.centroid;
            }
        }
        Orientation {
            groups: groups.into_boxed_slice(),
            members: order.into_iter().map(|(_, k)| k).collect(),
            cumulative_area: cumulative.into(),
        }
    }

    /// Projected area of each group toward the point `toward`: `A max(0, n̄ · d)`, `d` the unit
    /// direction from the group's centroid.
    pub fn projected_areas(&self, toward: DVec3) -> impl Iterator<Item = f64> + '_ {
        self.projected_areas_with(self.groups.iter().map(|g| g.area), toward)
    }

    /// Projected area of each group toward `toward` with `areas` (one per group: their visible areas,
    /// [`VisibleAreas`]) in place of the groups' own, `A' max(0, n̄ · d)`: exact while every member
    /// faces `d`, up to the parallax of the visible members about the group's centroid.
    pub fn projected_areas_with<'a>(
        &'a self,
        areas: impl Iterator<Item = f64> + 'a,
        toward: DVec3,
    ) -> impl Iterator<Item = f64> + 'a {
        self.groups.iter().zip(areas).map(move |(g, area)| {
            let d = (toward - g.centroid).normalize_or_zero();
            area * g.normal.dot(d).max(0.0)
        })
    }

    /// The member (a position in the cluster's contents) of group `group` at `fraction` ∈ [0, 1) of
    /// the group's area.
    pub fn member_at(&self, group: usize, fraction: f64) -> u32 {
        let range = self.groups[group].members.clone();
        let (start, end) = (range.start as usize, range.end as usize);
        let base = if start == 0 {
            0.0
        } else {
            self.cumulative_area[start - 1]
        };
        let target = base + fraction * (self.cumulative_area[end - 1] - base);
        let k = start + self.cumulative_area[start..end].partition_point(|&c| c <= target);
        self.members[k.min(end - 1)]
    }
}

/// The cell of unit vector `n` on a [`NORMAL_CELLS`]² octahedral map of the sphere.
fn octahedral_cell(n: DVec3) -> u32 {
    let l1 = n.x.abs() + n.y.abs() + n.z.abs();
    if l1 <= 0.0 {
        return 0;
    }
    let (mut u, mut v) = (n.x / l1, n.y / l1);
    if n.z < 0.0 {
        let (fu, fv) = (u, v);
        u = (1.0 - fv.abs()) * fu.signum();
        v = (1.0 - fu.abs()) * fv.signum();
    }
    let cell = |t: f64| (((t + 1.0) * 0.5 * NORMAL_CELLS as f64) as u32).min(NORMAL_CELLS - 1);
    cell(u) * NORMAL_CELLS + cell(v)
}

/// What one direction bucket's item buffer leaves visible of a cluster (Sillion–Drettakis §6.1): each
/// patch's visible fraction `f_k` (content order) and each normal group's visible area `Σ_k A_k f_k`
/// ([`Orientation`]'s group order), so that a link finds the cluster's visible projected area toward
/// its other end in O(groups) instead of a walk over every patch.
///
/// The cache of these answers is office3's largest heap block after the links (60k of them), and
/// most of what they hold is 0 or 1: 77% of the fractions are 0 (patches hidden behind others, or
/// facing away), 19% are 1 and 4.5% in between; 47% of the groups' areas are 0 and 18% the group's
/// whole area. So they are stored sparsely, in one shared allocation of 32-bit words
/// ([`VisibleAreas::new`] gives the layout): bitmaps of the groups seen and of those seen whole, and
/// the other seen groups' areas (`f32`); per 64 patches a bitmap of the visible ones, a
/// bitmap of the partly visible ones and the count of partly visible patches before them (a rank);
/// then the partial fractions in 16-bit fixed point ([`FRACTION_STEPS`]), two per word. About 3 bits
/// per patch and `f_k` in O(1) (a popcount). The fixed point's rounding (7.6·10⁻⁶) is far below the
/// item buffer's own (one pixel of a patch's projection, of at most 65,536).
#[derive(Clone, Debug, PartialEq)]
pub struct VisibleAreas {
    words: Arc<[u32]>,
}

/// Fixed-point steps of a visible fraction (fully visible, exactly).
const FRACTION_STEPS: f32 = u16::MAX as f32;

/// Patches per block of [`VisibleAreas`]: a rank word, then two words of each bitmap.
const BLOCK: usize = 64;

/// Words per block of patches in [`VisibleAreas`].
const BLOCK_WORDS: usize = 5;

/// [`VisibleAreas`]'s header: patches, groups, where the patch blocks start, where the partial
/// fractions start.
const HEADER: usize = 4;

/// Bit `bit` of the 64-bit bitmap at `words[at..at + 2]`, and the set bits below it.
fn bit_and_rank(words: &[u32], at: usize, bit: usize) -> (bool, u32) {
    let bitmap = u64::from(words[at]) | u64::from(words[at + 1]) << 32;
    (
        bitmap >> bit & 1 == 1,
        (bitmap & ((1u64 << bit) - 1)).count_ones(),
    )
}

impl VisibleAreas {
    /// The visible areas of a cluster grouped by `orientation` whose patches (content order) have
    /// areas `areas` and visible fractions `fractions` (rounded to [`FRACTION_STEPS`], a fraction
    /// that rounds to 0 hidden; the groups' areas are summed from the rounded fractions, so that both
    /// agree).
    ///
    /// Layout of the words: the [`HEADER`]; a bitmap of the groups whose visible area is not 0 and
    /// one of those whose visible area is the group's whole area as `f32` (`⌈groups/32⌉` words each),
    /// then the bits of the other seen groups' areas; per [`BLOCK`] patches the count of partly
    /// visible patches before the block, the bitmap of visible patches and the bitmap of partly
    /// visible ones (two words each); the partial fractions' steps, two per word.
    pub fn new(orientation: &Orientation, areas: &[f64], fractions: &[f32]) -> Self {
        let steps: Vec<u16> = fractions
            .iter()
            .map(|&f| (f.clamp(0.0, 1.0) * FRACTION_STEPS).round() as u16)
            .collect();
        let fraction = |k: u32| f64::from(f32::from(steps[k as usize]) / FRACTION_STEPS);
        let group_areas: Vec<u32> = orientation
            .groups
            .iter()
            .map(|g| {
                let members =
                    &orientation.members[g.members.start as usize..g.members.end as usize];
                let visible: f64 = members
                    .iter()
                    .map(|&k| areas[k as usize] * fraction(k))
                    .sum();
                (visible as f32).to_bits()
            })
            .collect();
        let whole: Vec<bool> = orientation
            .groups
            .iter()
            .zip(&group_areas)
            .map(|(g, &bits)| bits != 0 && bits == (g.area as f32).to_bits())
            .collect();
        let groups = group_areas.len();
        let bitmap = |keep: &dyn Fn(usize) -> bool| -> Vec<u32> {
            (0..groups)
                .step_by(32)
                .map(|start| {
                    (start..(start + 32).min(groups))
                        .fold(0u32, |m, g| m | u32::from(keep(g)) << (g - start))
                })
                .collect()
        };
        let mut words = vec![0u32; HEADER];
        words.extend(bitmap(&|g| group_areas[g] != 0));
        words.extend(bitmap(&|g| whole[g]));
        words.extend(
            (0..group_areas.len())
                .filter(|&g| group_areas[g] != 0 && !whole[g])
                .map(|g| group_areas[g]),
        );
        let blocks_at = words.len();
        let mut rank = 0u32;
        for block in steps.chunks(BLOCK) {
            let bitmap = |keep: &dyn Fn(u16) -> bool| {
                block
                    .iter()
                    .enumerate()
                    .fold(0u64, |m, (i, &q)| m | u64::from(keep(q)) << i)
            };
            let visible = bitmap(&|q| q > 0);
            let partial = bitmap(&|q| q > 0 && q < u16::MAX);
            words.extend([
                rank,
                visible as u32,
                (visible >> 32) as u32,
                partial as u32,
                (partial >> 32) as u32,
            ]);
            rank += partial.count_ones();
        }
        let values_at = words.len();
        let partial: Vec<u16> = steps
            .iter()
            .copied()
            .filter(|&q| q > 0 && q < u16::MAX)
            .collect();
        words.extend(
            partial.chunks(2).map(|pair| {
                u32::from(pair[0]) | u32::from(pair.get(1).copied().unwrap_or(0)) << 16
            }),
        );
        let count = |n: usize| u32::try_from(n).expect("a cluster's patches and groups fit in u32");
        words[..HEADER].copy_from_slice(&[
            count(fractions.len()),
            count(group_areas.len()),
            count(blocks_at),
            count(values_at),
        ]);
        VisibleAreas {
            words: words.into(),
        }
    }

    fn patches(&self) -> usize {
        self.words[0] as usize
    }

    fn groups(&self) -> usize {
        self.words[1] as usize
    }

    /// The `index`-th partial fraction.
    fn partial(&self, index: usize) -> f32 {
        let word = self.words[self.words[3] as usize + index / 2];
        f32::from((word >> (16 * (index % 2))) as u16) / FRACTION_STEPS
    }

    /// Visible fraction of the patch at position `k` of the cluster's contents.
    pub fn fraction(&self, k: usize) -> f32 {
        let at = self.words[2] as usize + BLOCK_WORDS * (k / BLOCK);
        let bit = k % BLOCK;
        if !bit_and_rank(&self.words, at + 1, bit).0 {
            return 0.0;
        }
        match bit_and_rank(&self.words, at + 3, bit) {
            (false, _) => 1.0,
            (true, before) => self.partial((self.words[at] + before) as usize),
        }
    }

    /// Visible fraction of each patch, in content order.
    pub fn fractions(&self) -> impl Iterator<Item = f32> + '_ {
        let blocks_at = self.words[2] as usize;
        let mut index = 0;
        (0..self.patches()).map(move |k| {
            let at = blocks_at + BLOCK_WORDS * (k / BLOCK) + k % BLOCK / 32;
            let bit = k % 32;
            if self.words[at + 1] >> bit & 1 == 0 {
                0.0
            } else if self.words[at + 3] >> bit & 1 == 0 {
                1.0
            } else {
                index += 1;
                self.partial(index - 1)
            }
        })
    }

    /// Visible area of normal group `g` of `orientation` (the one these areas were made with).
    pub fn group_area(&self, orientation: &Orientation, g: usize) -> f32 {
        let bitmap_words = self.groups().div_ceil(32);
        let (seen, whole) = (&self.words[HEADER..], &self.words[HEADER + bitmap_words..]);
        let bit = |map: &[u32], g: usize| map[g / 32] >> (g % 32) & 1 == 1;
        if !bit(seen, g) {
            return 0.0;
        }
        if bit(whole, g) {
            return orientation.groups[g].area as f32;
        }
        let below = |map: &[u32]| {
            map[..g / 32].iter().map(|w| w.count_ones()).sum::<u32>()
                + (map[g / 32] & ((1u32 << (g % 32)) - 1)).count_ones()
        };
        let before = (below(seen) - below(whole)) as usize;
        f32::from_bits(self.words[HEADER + 2 * bitmap_words + before])
    }

    /// Visible area of each normal group of `orientation` (the one these areas were made with), in
    /// its group order.
    pub fn group_areas<'a>(
        &'a self,
        orientation: &'a Orientation,
    ) -> impl Iterator<Item = f32> + 'a {
        let bitmap_words = self.groups().div_ceil(32);
        let mut next = HEADER + 2 * bitmap_words;
        orientation
            .groups
            .iter()
            .enumerate()
            .map(move |(g, group)| {
                let bit = |at: usize| self.words[at + g / 32] >> (g % 32) & 1 == 1;
                if !bit(HEADER) {
                    0.0
                } else if bit(HEADER + bitmap_words) {
                    group.area as f32
                } else {
                    next += 1;
                    f32::from_bits(self.words[next - 1])
                }
            })
    }

    /// Bytes of the shared allocation.
    pub fn bytes(&self) -> usize {
        16 + 4 * self.words.len()
    }
}
