//! What `--max-memory` counts: the structures that stay for the whole solve (scene, visibility
//! structure, patches and cluster tree, the item-buffer cache, a reserve for the program and its
//! threads) are set aside first, and refinement shares the rest between elements and links at their
//! peak cost: a link's bytes while it is stored at its receiver (with the growth slack of the
//! receiver's list and the allocator's rounding) plus what it costs while a refinement pass judges and
//! couples it (candidate lists). Peak resident memory then stays within the budget (BENCHMARKS.md,
//! "Scale", measures it), and a budget too small for the fixed part is refused before any work.

use crate::bases::BasisKind;
use crate::geometry::{cubature, Domain};
use crate::hierarchy::{
    allocated_bytes, Element, ErrorStorage, Hierarchy, Link, LinkCoupling, Patch,
};
use crate::scene::{Polygon, Scene};
use crate::solvers::refine::Candidate;
use crate::visibility::Visibility;

/// Bytes for the program itself and its threads, beyond the data counted here: code and libraries
/// (about 20 MiB resident), rayon's worker stacks, and per-thread scratch (an item buffer's raster of
/// 128² pixels, 192 KiB; coupling and oracle temporaries), for up to 16 threads.
pub const RUNTIME_RESERVE: usize = 64 << 20;

/// Share of the budget after the fixed part that the item-buffer cache may fill (its answers are
/// redrawn, identically, when it is full).
pub const ITEM_BUFFER_SHARE: usize = 8;

/// Share of the refinement budget reserved for elements (links take the rest: a solve holds tens of
/// links per element).
pub const ELEMENT_SHARE: usize = 8;

/// Hands the allocator's free pages back to the system. glibc keeps what a phase frees (a refinement
/// pass's candidate lists, a solve's links) in its arenas, split among the smaller blocks still in
/// use, and the next phase's large blocks then take fresh pages: office3's resident peak was the
/// solve's plus the render's, 20 MB above its heap's. A no-op elsewhere (other allocators return
/// pages themselves).
pub fn return_free_pages() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        unsafe extern "C" {
            /// glibc's `malloc_trim(3)`: releases free memory at the top of the heap and, since glibc
            /// 2.8, every whole free page inside the arenas.
            fn malloc_trim(pad: usize) -> std::ffi::c_int;
        }
        // SAFETY: malloc_trim takes no pointers and only releases memory no allocation holds.
        unsafe {
            malloc_trim(0);
        }
    }
}

/// Keeps large blocks (128 KiB and up: link lists, candidate lists, coupling scratch) in pages of
/// their own for the whole run. glibc starts so, but each time such a block is freed it raises the
/// threshold to that block's size (up to 32 MiB), and later large blocks then come from the arenas,
/// where growing one copies it and what is freed stays resident among the small blocks around it.
/// Fixing the threshold keeps growth to `mremap` and frees to the system: office3's default render
/// peaked 1.1 MB lower, the classroom's 6 MB, at the same CPU time (BENCHMARKS.md, "Large blocks kept
/// mapped"). Call once, before the threads start. A no-op elsewhere.
pub fn keep_large_blocks_mapped() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        /// `M_MMAP_THRESHOLD` of glibc's `<malloc.h>`.
        const M_MMAP_THRESHOLD: std::ffi::c_int = -3;
        unsafe extern "C" {
            /// glibc's `mallopt(3)`; setting the threshold turns its dynamic adjustment off.
            fn mallopt(param: std::ffi::c_int, value: std::ffi::c_int) -> std::ffi::c_int;
        }
        // SAFETY: mallopt takes no pointers; it only changes the allocator's policy for later calls.
        unsafe {
            mallopt(M_MMAP_THRESHOLD, 128 << 10);
        }
    }
}

/// Smallest array [`vec_on_huge_pages`] advises: below a few huge pages the rounding to 2 MiB costs
/// more than the TLB saves (office3's whole BVH is 2.6 MB).
const HUGE_PAGE_MIN_BYTES: usize = 8 << 20;

/// Size of a transparent huge page on x86-64 and most aarch64 Linux systems.
const HUGE_PAGE: usize = 2 << 20;

/// An empty vector with room for `capacity` elements, whose memory the kernel is asked to back with
/// transparent huge pages (`madvise(MADV_HUGEPAGE)` before any page is touched) when it is large;
/// fill it without growing past `capacity`. Ray casting on a big scene reads its BVH at random: with
/// 4 KiB pages nearly every node fetch of a 400 MB tree also misses the TLB, and Embree, which we
/// measure against, advises huge pages for its own nodes (BENCHMARKS.md, "Huge pages for large
/// BVHs"). Where the system grants them only on request (the common `madvise` setting) this is what
/// gets them; elsewhere, or for small arrays, it is a plain `Vec::with_capacity`.
pub fn vec_on_huge_pages<T>(capacity: usize) -> Vec<T> {
    let mut fresh: Vec<T> = Vec::with_capacity(capacity);
    let bytes = capacity.saturating_mul(std::mem::size_of::<T>());
    #[cfg(target_os = "linux")]
    if bytes >= HUGE_PAGE_MIN_BYTES {
        /// `MADV_HUGEPAGE` of Linux's `<sys/mman.h>`.
        const MADV_HUGEPAGE: std::ffi::c_int = 14;
        unsafe extern "C" {
            /// `madvise(2)`: advice only; a refusal (huge pages off) changes nothing.
            fn madvise(
                addr: *mut std::ffi::c_void,
                length: usize,
                advice: std::ffi::c_int,
            ) -> std::ffi::c_int;
        }
        // The huge pages that fit wholly inside the buffer. An allocation this large is a fresh
        // mapping, not yet touched, under `keep_large_blocks_mapped` (and at any threshold from 32
        // MiB); one glibc reuses from its heap keeps whatever pages it already has.
        let at = fresh.as_mut_ptr() as usize;
        let (start, end) = (
            at.next_multiple_of(HUGE_PAGE),
            (at + bytes) / HUGE_PAGE * HUGE_PAGE,
        );
        if end > start {
            // SAFETY: the range lies inside `fresh`'s allocation, which this function owns; the
            // advice changes how pages are backed, never their contents.
            unsafe {
                madvise(start as *mut std::ffi::c_void, end - start, MADV_HUGEPAGE);
            }
        }
    }
    fresh
}

/// How `--max-memory` is divided.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MemoryBudget {
    /// `--max-memory`.
    pub total: usize,
    /// Scene, visibility structure, patches with their roots and the cluster tree, program reserve.
    pub fixed: usize,
    /// Most bytes the item-buffer cache may hold (0 without item buffers).
    pub item_buffer_cache: usize,
    /// Whether the scene has goniometric luminaires, whose direct light every element keeps too
    /// ([`element_bytes`]).
    pub luminaires: bool,
}

impl MemoryBudget {
    /// The budget for solving `scene` with `visibility` and the initial `hierarchy` (patch roots and
    /// clusters) within `max_memory` bytes; `item_buffers`: whether intra-cluster item buffers will be
    /// cached. An error when the fixed part alone does not fit.
    pub fn new(
        max_memory: usize,
        scene: &Scene,
        visibility: &dyn Visibility,
        hierarchy: &Hierarchy,
        item_buffers: bool,
    ) -> anyhow::Result<Self> {
        let polygons = scene.polygons.len() * std::mem::size_of::<Polygon>();
        // Back ends that do not report their size are counted as a BVH of two nodes per polygon.
        let visibility_bytes = visibility.memory_bytes().unwrap_or(2 * polygons);
        let fixed = RUNTIME_RESERVE
            + polygons
            + visibility_bytes
            + hierarchy.memory_bytes()
            + hierarchy.patches.len() * std::mem::size_of::<Patch>()
            + hierarchy.cluster_surfaces.len() * 4
            + hierarchy.cluster_positions.len() * 4
            + hierarchy.polygon_patches.len() * 16;
        anyhow::ensure!(
            fixed < max_memory,
            "--max-memory {} is too small for this scene: its polygons, visibility structure, patches \
             and clusters, and the program's reserve need {} before refinement can start",
            format_bytes(max_memory),
            format_bytes(fixed)
        );
        let item_buffer_cache = if item_buffers {
            (max_memory - fixed) / ITEM_BUFFER_SHARE
        } else {
            0
        };
        Ok(MemoryBudget {
            total: max_memory,
            fixed: fixed + item_buffer_cache,
            item_buffer_cache,
            luminaires: !hierarchy.luminaires.is_empty(),
        })
    }

    /// A budget that only counts elements and links (for callers without a scene at hand): everything
    /// is refinement's.
    pub fn refinement_only(max_memory: usize) -> Self {
        MemoryBudget {
            total: max_memory,
            fixed: 0,
            item_buffer_cache: 0,
            luminaires: false,
        }
    }

    /// Bytes refinement may fill with elements and links.
    pub fn refinement(&self) -> usize {
        self.total.saturating_sub(self.fixed)
    }

    /// Most links refinement may create, at [`link_peak_bytes`] each.
    pub fn max_links(
        &self,
        basis: BasisKind,
        cubature_degree: usize,
        storage: ErrorStorage,
    ) -> usize {
        let links = self.refinement() - self.refinement() / ELEMENT_SHARE;
        links / link_peak_bytes(basis, cubature_degree, storage)
    }

    /// Most elements refinement may create, at [`element_bytes`] each.
    pub fn max_elements(&self, basis: BasisKind) -> usize {
        self.refinement() / ELEMENT_SHARE / element_bytes(basis, self.luminaires)
    }
}

/// Bytes one stored link holds: the `Link` itself and its coupling's single heap block
/// ([`crate::hierarchy::LinkCoupling`]) with the allocator's rounding, for the largest receiver rule
/// (the square's).
pub fn link_bytes(basis: BasisKind, cubature_degree: usize, storage: ErrorStorage) -> usize {
    let size = basis.size();
    let nodes = cubature::rule(Domain::Square, cubature_degree).nodes.len();
    std::mem::size_of::<Link>() + LinkCoupling::heap_bytes_for(size, nodes, storage)
}

/// Most bytes of a refinement verdict (one per candidate or stored link while a pass judges them).
pub const VERDICT_BYTES: usize = 40;

/// A link's peak cost: [`link_bytes`], one more `Link` for the growth slack of its receiver's list
/// (which doubles), and while a refinement pass runs, the link as a candidate (kept in place when
/// admissible) and its verdict (at most [`VERDICT_BYTES`]); a later pass judges stored links in place,
/// with a verdict each. Links are coupled and stored a chunk at a
/// time, so their copies on the way to their receivers are not counted per link.
pub fn link_peak_bytes(basis: BasisKind, cubature_degree: usize, storage: ErrorStorage) -> usize {
    link_bytes(basis, cubature_degree, storage)
        + std::mem::size_of::<Link>()
        + std::mem::size_of::<Candidate>()
        + VERDICT_BYTES
}

/// Bytes of one element: the struct and its radiance coefficients, with `luminaires` also its
/// direct irradiance coefficients and their projection's residual (`Hierarchy::direct`,
/// `Hierarchy::direct_residual`), twice each for the growth slack of the lists; and its list of
/// four children.
pub fn element_bytes(basis: BasisKind, luminaires: bool) -> usize {
    let coefficients = basis.size() * std::mem::size_of::<crate::color::Rgb>();
    let direct = if luminaires {
        coefficients + std::mem::size_of::<f64>()
    } else {
        0
    };
    2 * (std::mem::size_of::<Element>() + coefficients + direct) + allocated_bytes(4 * 4)
}

/// `1.5 GiB`, `640 MiB`, `12 KiB`, `500 B` (binary units, like `--max-memory`'s suffixes; under a
/// KiB in bytes, so that `--max-memory 1` does not read back as `0 KiB`).
pub fn format_bytes(bytes: usize) -> String {
    let b = bytes as f64;
    if bytes >= 1 << 30 {
        format!("{:.1} GiB", b / f64::from(1u32 << 30))
    } else if bytes >= 1 << 20 {
        format!("{:.0} MiB", b / f64::from(1u32 << 20))
    } else if bytes >= 1 << 10 {
        format!("{:.0} KiB", b / 1024.0)
    } else {
        format!("{bytes} B")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::generators::BoxHall;
    use crate::visibility::bvh::Bvh;

    /// Sizes read back in the unit they are nearest to, a byte budget included.
    #[test]
    fn sizes_read_back_in_their_unit() {
        assert_eq!(format_bytes(1), "1 B");
        assert_eq!(format_bytes(1023), "1023 B");
        assert_eq!(format_bytes(12 << 10), "12 KiB");
        assert_eq!(format_bytes(640 << 20), "640 MiB");
        assert_eq!(format_bytes(3 << 29), "1.5 GiB");
    }

    /// Vectors advised onto huge pages (and the small ones, which are not) hold what is written
    /// into them, in the room asked for, without moving while they fill.
    #[test]
    fn vectors_on_huge_pages_hold_what_is_written() {
        for len in [0, 1000, 3 << 20, (3 << 20) + 12_345] {
            let mut v: Vec<u32> = vec_on_huge_pages(len);
            assert!(v.is_empty() && v.capacity() >= len);
            let at = v.as_ptr();
            v.extend((0..len as u32).map(|k| k.wrapping_mul(2_654_435_761)));
            assert_eq!(
                v.as_ptr(),
                at,
                "filling within the capacity does not move it"
            );
            assert!((0..len).all(|k| v[k] == (k as u32).wrapping_mul(2_654_435_761)));
        }
    }

    #[test]
    fn a_link_costs_less_than_the_three_allocation_layout() {
        // The layout before one heap block per coupling: an 80-byte link with three boxed slices.
        let (size, nodes) = (3, 4);
        let before = 80
            + allocated_bytes(8 * size * size)
            + allocated_bytes(4 * nodes * size)
            + allocated_bytes(4 * nodes);
        assert!(link_bytes(BasisKind::Linear, 2, ErrorStorage::Full) < before);
    }

    #[test]
    fn the_fixed_part_is_set_aside_and_a_budget_below_it_is_refused() {
        let scene = BoxHall::with_polygons(300).scene();
        let shapes: Vec<_> = scene.polygons.iter().map(|p| p.shape).collect();
        let bvh = Bvh::new(&shapes);
        let hierarchy = Hierarchy::new(&scene, BasisKind::Linear);
        let budget = MemoryBudget::new(1 << 30, &scene, &bvh, &hierarchy, true).unwrap();
        assert!(budget.fixed > RUNTIME_RESERVE + budget.item_buffer_cache);
        assert_eq!(
            budget.item_buffer_cache,
            (budget.total - (budget.fixed - budget.item_buffer_cache)) / ITEM_BUFFER_SHARE
        );
        assert!(
            budget.max_links(BasisKind::Linear, 2, ErrorStorage::Full)
                * link_peak_bytes(BasisKind::Linear, 2, ErrorStorage::Full)
                + budget.max_elements(BasisKind::Linear)
                    * element_bytes(BasisKind::Linear, budget.luminaires)
                <= budget.refinement()
        );
        let refused = MemoryBudget::new(RUNTIME_RESERVE, &scene, &bvh, &hierarchy, true);
        assert!(refused.unwrap_err().to_string().contains("too small"));
    }
}
