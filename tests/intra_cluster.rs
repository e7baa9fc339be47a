//! Intra-cluster visibility by item buffer (Sillion–Drettakis §6.1) against ground truth: a stack of
//! plates lit from above (only the top plate can receive) and emitting under a dark lid (nothing can
//! leave), both with analytic answers, the energy extinction creates without it, energy balance in a
//! closed furnace full of small objects, and the per-sweep exchange by direction bucket against the
//! per-link exchange it stands for.

use radiosity::bases::BasisKind;
use radiosity::color::Rgb;
use radiosity::geometry::form_factor::parallel_rectangles;
use radiosity::geometry::{DVec2, DVec3, Shape};
use radiosity::hierarchy::clusters::ClusteringKind;
use radiosity::hierarchy::{ElementId, Hierarchy};
use radiosity::pipeline::{simulate, SimulationSettings, VisibilityKind};
use radiosity::scene::{generators, Material, Polygon, Scene};
use radiosity::solvers::clustering::{exposure_shares, groups_toward, node_fraction, ClusterSweep};
use radiosity::visibility::extinction::Extinction;
use radiosity::visibility::item_buffer::{
    bucket_direction, direction_bucket, exposed, exposed_nodes, IntraClusterKind,
};
use radiosity::visibility::Visibility;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;
use std::f64::consts::SQRT_2;

#[allow(dead_code)] // each test file uses part of the shared module
mod common;
use common::{
    furnace_with_cubes, mean_factor_up, mean_radiance_of, one_polygon_per_material, quiet,
    rectangle,
};

/// Plates in the stack, their gap, and the height of the square above the lowest plate.
const PLATES: usize = 8;
const GAP: f64 = 0.02;
const HEIGHT: f64 = 4.0;
const RHO: f64 = 0.5;

/// `PLATES` unit squares facing up, `GAP` apart, lowest at z = 0, with materials by plate index (from
/// the bottom), and a unit square at `HEIGHT` facing down with material 0 (polygon 0).
fn plate_stack(above: Material, plate: impl Fn(usize) -> Material) -> Scene {
    let mut scene = generators::parallel_plates(1.0, HEIGHT, 0.0, 0.0);
    let square = scene.polygons[0].shape;
    scene.polygons.swap(0, 1);
    scene.polygons.truncate(1);
    scene.polygons[0].material = 0;
    scene.materials = vec![above];
    for k in 0..PLATES {
        let Shape::Quad(v) = square else {
            unreachable!("parallel_plates makes quads")
        };
        scene.materials.push(plate(k));
        scene.polygons.push(Polygon {
            shape: Shape::Quad(v.map(|x| x + DVec3::new(0.0, 0.0, k as f64 * GAP))),
            material: k + 1,
            object: 0,
            two_sided: false,
            under_contact: false,
        });
    }
    scene
}

/// Patch index of plate `k` (patches follow the polygons, all one-sided).
fn plate(k: usize) -> usize {
    k + 1
}

const TOP: usize = PLATES - 1;

/// Distance between the top plate and the square above.
fn top_distance() -> f64 {
    HEIGHT - TOP as f64 * GAP
}

/// Upper bound on the mean irradiance factor between the square above and a plate below the top one,
/// the light that passes the slits: seen from a plate point at distance `x` from the nearest edge, the
/// square lies at elevation `θ` with `tan θ ≥ d / √2` (`d` the smallest vertical distance, `√2` the
/// largest horizontal offset between two points of coaxial unit squares), and such a ray leaves the gap
/// only if `x ≤ GAP / tan θ`; so only edge strips of width `√2 GAP / d` (area at most 4 × that) see it,
/// each point with a point factor at most `A / (π d²)`.
fn slit_factor_bound() -> f64 {
    let d = top_distance();
    4.0 * SQRT_2 * GAP / d / (std::f64::consts::PI * d * d)
}

/// Whether refinement left the interaction at cluster level (what this file tests).
fn has_cluster_link(h: &Hierarchy, cluster_receiver: bool) -> bool {
    (0..h.elements.len() as u32).any(|id| {
        h.element(id).links.iter().any(|l| {
            if cluster_receiver {
                h.is_cluster(id)
            } else {
                h.is_cluster(l.source)
            }
        })
    })
}

fn settings(intra_cluster: IntraClusterKind) -> SimulationSettings {
    SimulationSettings {
        clustering: ClusteringKind::Oriented,
        intra_cluster,
        // Coarse: the square and the stack stay linked as a whole.
        eps: 0.1,
        ..Default::default()
    }
}

/// A stack of plates lit by an emitter above: with the item buffer the cluster's irradiance goes to
/// the top plate alone, which then has the analytic radiance `ρ F E`, and the hidden plates get no more
/// than the slits let through; without it, all plates share the light (the light leak of §6.1's
/// Figure 10). Error model for the top plate: the cluster link's centre-to-centre kernel, which is off
/// by the centre offset (`2 Δz / d`, Δz the half height of the stack) and by the point kernel's
/// `(a/d)²` for squares of side `a`: 10% here.
#[test]
fn item_buffer_gives_a_clusters_irradiance_to_the_patches_that_see_the_source() {
    let scene = plate_stack(
        Material::emitter("lamp", Rgb::BLACK, Rgb::splat(1.0)),
        |_| Material::diffuse("plate", Rgb::splat(RHO)),
    );
    let analytic = RHO * parallel_rectangles(1.0, 1.0, top_distance());
    let leak = RHO * slit_factor_bound();
    let tolerance = 2.0 * (TOP as f64 * GAP / 2.0) / top_distance() + top_distance().powi(-2);
    let hidden = |k: usize| k != 0 && k != plate(TOP);
    let solution =
        simulate(&scene, &settings(IntraClusterKind::ItemBuffer), &quiet()).expect("solve");
    let h = &solution.hierarchy;
    assert!(has_cluster_link(h, true), "no cluster receives");
    let top = mean_radiance_of(h, |k| k == plate(TOP));
    let below = mean_radiance_of(h, hidden);
    assert!(
        (top - analytic).abs() <= tolerance * analytic,
        "top plate {top}, analytic {analytic}"
    );
    assert!(below <= leak, "hidden plates {below}, slit bound {leak}");
    // Without it every plate facing the square gets the same share, and the link's visibility is the
    // fraction `v` of its samples (on the plates, by projected area) that see the square: 1/8 in
    // expectation, from 2 × 4 Bernoulli samples, so one seed may give 0. Over 16 seeds the mean of `v`
    // is 1/8 with standard deviation sqrt(7/64 / 128) = 0.029, and the leak bound (0.03 of the analytic
    // top radiance) is 3.3 standard deviations below it.
    const SEEDS: u64 = 16;
    let mut hidden_mean = 0.0;
    for seed in 1..=SEEDS {
        let settings = SimulationSettings {
            seed,
            ..settings(IntraClusterKind::None)
        };
        let solution = simulate(&scene, &settings, &quiet()).expect("solve");
        let h = &solution.hierarchy;
        assert!(
            has_cluster_link(h, true),
            "seed {seed}: no cluster receives"
        );
        let top = mean_radiance_of(h, |k| k == plate(TOP));
        let below = mean_radiance_of(h, hidden);
        assert!(
            (top - below).abs() <= 1e-9 * top,
            "seed {seed}: without item buffer the plates share alike: top {top}, hidden {below}"
        );
        hidden_mean += below / SEEDS as f64;
    }
    assert!(
        hidden_mean > leak,
        "without item buffer the hidden plates are lit: mean {hidden_mean}, slit bound {leak}"
    );
}

/// A unit plate partly hidden by a half-size plate `GAP` above its centre, lit by a unit emitter at
/// `HEIGHT`: nothing outside the pair shadows it, so the link's visibility must be 1 and the plate's
/// mean radiance `ρ f F E` with `f = 3/4` its visible fraction (the item buffer's) and `F` the factor
/// from the emitter. Its rays start at points drawn uniformly on the plate, a quarter of them under
/// the small one: counted as blocked they would take the plate down by ~19% on average (a 1 in 5
/// chance per seed that all 8 rays miss the small plate), counting that hiding twice. Error model as
/// above (centre-to-centre kernel: 7% here), over 16 seeds.
#[test]
fn a_clusters_own_contents_do_not_shadow_its_links_rays() {
    let big = common::rectangle([0.0, 1.0, 0.0, 1.0], 0.0, true);
    let small = common::rectangle([0.25, 0.75, 0.25, 0.75], GAP, true);
    let lamp = common::rectangle([0.0, 1.0, 0.0, 1.0], HEIGHT, false);
    let scene = common::one_polygon_per_material(
        vec![
            Material::diffuse("plate", Rgb::splat(RHO)),
            Material::diffuse("cover", Rgb::splat(RHO)),
            Material::emitter("lamp", Rgb::BLACK, Rgb::splat(1.0)),
        ],
        [big, small, lamp],
        |_| false,
    );
    let analytic = RHO * 0.75 * parallel_rectangles(1.0, 1.0, HEIGHT);
    let tolerance = 2.0 * (GAP / 2.0) / HEIGHT + HEIGHT.powi(-2);
    for seed in 1..=16 {
        let settings = SimulationSettings {
            seed,
            ..settings(IntraClusterKind::ItemBuffer)
        };
        let solution = simulate(&scene, &settings, &quiet()).expect("solve");
        let h = &solution.hierarchy;
        assert!(
            has_cluster_link(h, true),
            "seed {seed}: no cluster receives"
        );
        let plate = mean_radiance_of(h, |k| k == 0);
        assert!(
            (plate - analytic).abs() <= tolerance * analytic,
            "seed {seed}: partly hidden plate {plate}, analytic {analytic}"
        );
    }
}

/// Plates emitting under a dark lid (the top plate, black): no light can leave the stack but through
/// the slits, so the square above stays below `ρ (PLATES − 1) E × slit factor`; with the item buffer
/// the cluster sends the radiance of the patches the square sees (the lid's), without it the average
/// of its contents, and light leaves through the lid (§6.1, "the energy leaving a cluster").
#[test]
fn item_buffer_lets_only_visible_patches_send_light_out_of_a_cluster() {
    let scene = plate_stack(Material::diffuse("receiver", Rgb::splat(RHO)), |k| {
        if k == TOP {
            Material::diffuse("lid", Rgb::BLACK)
        } else {
            Material::emitter("lamp", Rgb::BLACK, Rgb::splat(1.0))
        }
    });
    let leak = RHO * (PLATES - 1) as f64 * slit_factor_bound();
    for intra in [IntraClusterKind::ItemBuffer, IntraClusterKind::None] {
        let solution = simulate(&scene, &settings(intra), &quiet()).expect("solve");
        let h = &solution.hierarchy;
        assert!(has_cluster_link(h, false), "{intra:?}: no cluster sends");
        let above = mean_radiance_of(h, |k| k == 0);
        if intra == IntraClusterKind::ItemBuffer {
            assert!(above <= leak, "receiver {above}, slit bound {leak}");
        } else {
            assert!(
                above > leak,
                "without item buffer light leaves the box: {above}"
            );
        }
    }
}

/// The white furnace of `tests/clustering.rs` (closed, every surface ρ and E, analytic radiance
/// `E / (1 − ρ)` everywhere) with item buffers and the *isotropic* transfer: the buffer's visible
/// projected areas replace the isotropic mean cosine 1/4, whose misfit to the room's walls gave +0.76%
/// (BENCHMARKS.md), so the balance holds like the oriented transfer's (that test runs without item
/// buffers). Tolerance: the 0.5%, at ε = 1e-5 (the oriented transfer's error falls with ε:
/// −1.6% at 1e-4, −0.5% at 2e-5).
#[test]
fn isotropic_furnace_with_item_buffers_conserves_energy() {
    let (rho, e) = (0.5, 1.0);
    let scene = furnace_with_cubes(4, rho, e);
    let settings = SimulationSettings {
        clustering: ClusteringKind::Isotropic,
        intra_cluster: IntraClusterKind::ItemBuffer,
        eps: 1e-5,
        min_area: 1e-4,
        ..Default::default()
    };
    let solution = simulate(&scene, &settings, &quiet()).expect("solve");
    let mean = mean_radiance_of(&solution.hierarchy, |_| true);
    let expected = e / (1.0 - rho);
    assert!(
        (mean - expected).abs() / expected < 0.005,
        "mean radiance {mean}, expected {expected}"
    );
    let r = &solution.report;
    let analytic = r.emitted_power.g / (1.0 - rho);
    assert!(
        (r.exitant_power.g - analytic).abs() / analytic < 0.005,
        "exitant power {}, analytic {analytic}",
        r.exitant_power.g
    );
}

/// With item buffers the isotropic transfer is the oriented one (`ClusteringKind::Isotropic`'s
/// documentation: both take a cluster's visible projected areas), error estimate included: a cluster
/// receiver's kernel error compares the point kernel with the share the sweep gives the point's patch,
/// which with item buffers is by projected area for both kinds. A consistency check, on the furnace
/// full of cubes: every element's radiance and estimate, to the last bit.
#[test]
fn with_item_buffers_isotropic_clusters_solve_and_estimate_as_oriented_ones() {
    let scene = furnace_with_cubes(4, 0.5, 1.0);
    let solve = |clustering| {
        let settings = SimulationSettings {
            clustering,
            intra_cluster: IntraClusterKind::ItemBuffer,
            eps: 1e-4,
            ..Default::default()
        };
        simulate(&scene, &settings, &quiet())
            .expect("solve")
            .hierarchy
    };
    let (isotropic, oriented) = (
        solve(ClusteringKind::Isotropic),
        solve(ClusteringKind::Oriented),
    );
    assert!(has_cluster_link(&oriented, true), "no cluster receives");
    assert_eq!(isotropic.elements.len(), oriented.elements.len());
    for (id, (a, b)) in isotropic
        .elements
        .iter()
        .zip(&oriented.elements)
        .enumerate()
    {
        assert_eq!(
            (a.error.to_bits(), a.links.len()),
            (b.error.to_bits(), b.links.len()),
            "element {id}: estimate {} against {}",
            a.error,
            b.error
        );
        let (a, b) = (
            isotropic.average_radiance(id as ElementId),
            oriented.average_radiance(id as ElementId),
        );
        assert_eq!(a, b, "element {id}");
    }
}

/// Near clusters stay stable: in the shadow-groups scene (clusters of cubes close to each other and to
/// the wall) an open scene can absorb at most what is emitted, `Φ_a ≤ Φ_e`, and the sweeps converge.
/// With item buffers a cluster's irradiance goes to its visible patches and it sends their radiance, so
/// a centre-to-centre factor above one per patch fed back more than it received (the solve diverged
/// before the source's factor was bounded per patch).
#[test]
fn near_clusters_with_item_buffers_stay_within_the_emitted_power() {
    let scene = generators::ShadowGroups::default().scene();
    let settings = SimulationSettings {
        clustering: ClusteringKind::Oriented,
        intra_cluster: IntraClusterKind::ItemBuffer,
        eps: 1e-4,
        ..Default::default()
    };
    let solution = simulate(&scene, &settings, &quiet()).expect("solve");
    let r = &solution.report;
    assert!(r.converged, "sweeps did not converge");
    assert!(
        r.absorbed_power.g <= r.emitted_power.g,
        "absorbed {} of emitted {}",
        r.absorbed_power.g,
        r.emitted_power.g
    );
}

/// The energy creation of §6.1 ("since bounds are computed on irradiance values, that irradiance is
/// distributed to many surfaces which should be shadowed"): with extinction visibility the link from the
/// square to the stack sees each plate through the stack's own extinction `exp(−κ l)` (κ = ΣA/(4V)
/// assumes isotropic contents, but these plates all face the source), so without the item buffer the
/// plates together receive about `Σ_j exp(−j/2) ≈ 2.3` times the top plate's share, though the top
/// plate absorbs all it gets. Ground truth under the same visibility model: the stack can intercept at
/// most what reaches its top face plus what passes the slits, `π L A T (F_top + (PLATES − 1) × slit
/// bound)`, `T` the largest extinction transmittance from the square to the top plate (the segment
/// crosses the cluster holding the square, whose κ smears that polygon over its box: the model's own
/// bias, the same for both runs); with the item buffer the received power stays under it within the
/// cluster link's centre-kernel error (the first test's tolerance).
#[test]
fn without_item_buffer_extinction_creates_energy_in_a_cluster() {
    let scene = plate_stack(
        Material::emitter("lamp", Rgb::BLACK, Rgb::splat(1.0)),
        |_| Material::diffuse("plate", Rgb::splat(RHO)),
    );
    let extinction = Extinction::new(
        &scene.polygons.iter().map(|p| p.shape).collect::<Vec<_>>(),
        SimulationSettings::default().cluster_tree,
    );
    let grid = |s: &Shape| {
        let s = *s;
        (0..9).map(move |k| s.point_at(DVec2::new((k % 3) as f64, (k / 3) as f64) * 0.5))
    };
    let transmittance = grid(&scene.polygons[0].shape)
        .flat_map(|p| grid(&scene.polygons[1 + TOP].shape).map(move |q| (p, q)))
        .map(|(p, q)| extinction.transmittance(p, q))
        .fold(0.0, f64::max);
    let reachable = transmittance
        * (parallel_rectangles(1.0, 1.0, top_distance())
            + (PLATES - 1) as f64 * slit_factor_bound());
    let tolerance = 2.0 * (TOP as f64 * GAP / 2.0) / top_distance() + top_distance().powi(-2);
    // Received power over π L A of the square: Σ_k A_k B_k / ρ (unit plates, no emission).
    let received = |intra, seed| {
        let settings = SimulationSettings {
            visibility: VisibilityKind::Extinction,
            seed,
            ..settings(intra)
        };
        let solution = simulate(&scene, &settings, &quiet()).expect("solve");
        let h = &solution.hierarchy;
        assert!(has_cluster_link(h, true), "{intra:?}: no cluster receives");
        (0..PLATES)
            .map(|k| mean_radiance_of(h, |p| p == plate(k)) / RHO)
            .sum::<f64>()
    };
    // The link's transmittance is the mean over 8 samples on the plates (by projected area) of
    // `exp(−0.57 j)`, j plates below the top: expectation 0.285 with standard deviation 0.12 per seed,
    // creation needs more than 1.33/8 = 0.167; over 16 seeds the mean's deviation is 0.03, so the margin
    // is about 4 standard deviations.
    const SEEDS: u64 = 16;
    let mut without = 0.0;
    for seed in 1..=SEEDS {
        let with_buffer = received(IntraClusterKind::ItemBuffer, seed);
        assert!(
            with_buffer <= reachable * (1.0 + tolerance),
            "seed {seed}: with item buffer the stack receives {with_buffer}, at most {reachable} \
             can reach it"
        );
        without += received(IntraClusterKind::None, seed) / SEEDS as f64;
    }
    assert!(
        without > reachable * (1.0 + tolerance),
        "without item buffer the stack receives {without} on average, no more than {reachable} \
         reaches it"
    );
}

/// The visible area `A_k f_k` of each patch of cluster `id` (content order) in its item buffer of the
/// direction bucket toward `toward`.
fn visible_areas(h: &Hierarchy, id: ElementId, toward: DVec3) -> Vec<f64> {
    let groups = groups_toward(h, id, toward);
    let contents = h.contents(h.cluster(id).expect("cluster"));
    (0..contents.len() as u32)
        .map(|k| h.element(contents[k as usize]).area * f64::from(groups.fraction(k)))
        .collect()
}

/// The visible projected area of each patch of cluster `id` toward `toward`, with the patch's own
/// direction `d_k` to it: `A_k f_k max(0, n_k · d_k)` (Sillion–Drettakis §6.1).
fn projected_areas(h: &Hierarchy, id: ElementId, toward: DVec3) -> Vec<f64> {
    let contents = h.contents(h.cluster(id).expect("cluster"));
    contents
        .iter()
        .zip(visible_areas(h, id, toward))
        .map(|(&s, a)| {
            let d = (toward - h.element(s).shape().centroid()).normalize_or_zero();
            a * h.patch_of(s).normal.dot(d).max(0.0)
        })
        .collect()
}

/// The per-link exchange of a cluster with item buffers that [`ClusterSweep`] stands for: the radiance
/// `source` sends toward `toward`, averaged over its patches' visible projected areas with each
/// patch's own direction to `toward`, [`projected_areas`]; its average radiance when none is visible.
fn per_link_radiance(h: &Hierarchy, source: ElementId, toward: DVec3) -> Rgb {
    let areas = projected_areas(h, source, toward);
    let total: f64 = areas.iter().sum();
    if total <= 0.0 {
        return h.average_radiance(source);
    }
    let contents = h.contents(h.cluster(source).expect("cluster"));
    contents
        .iter()
        .zip(&areas)
        .map(|(&s, &w)| h.average_radiance(s) * (w / total))
        .sum()
}

/// Relative L¹ change of cluster `id`'s patch weights toward `toward` when each patch's direction
/// `d_k` is replaced by its direction bucket's centre `d_b`: `w_k = A_k max(0, n_k · d) f_k` changes by
/// at most `A_k f_k |d_k − d_b|` (the clamped cosine is 1-Lipschitz in `d`; `f_k` is the same bucket's
/// visible fraction in both), so `Σ_k |w_k − w'_k| / Σ_k w_k` is at most what this returns (infinite
/// when no patch is visible toward `toward`).
fn bucket_weight_change(h: &Hierarchy, id: ElementId, toward: DVec3) -> f64 {
    let along = bucket_direction(direction_bucket(toward - h.center_of(id)));
    let contents = h.contents(h.cluster(id).expect("cluster"));
    let change: f64 = contents
        .iter()
        .zip(visible_areas(h, id, toward))
        .map(|(&s, a)| {
            let d = (toward - h.element(s).shape().centroid()).normalize_or_zero();
            a * (d - along).length()
        })
        .sum();
    let total: f64 = projected_areas(h, id, toward).iter().sum();
    if total > 0.0 {
        change / total
    } else {
        f64::INFINITY
    }
}

/// The factor by which sharing by exposure scales what a link of visibility `v` from `source`
/// delivers to cluster `id` (`solvers::clustering::exposure_shares`): the sum of its two parts where
/// the bucket's exposure tells some visible patches from others, else 1. The exposed share `e` is
/// taken from the bucket's visible projected areas along its centre direction, each times its
/// exposed fraction, as the sweep weighs them.
fn exposure_scale(h: &Hierarchy, id: ElementId, source: ElementId, v: f64) -> f64 {
    let toward = h.center_of(source);
    let bucket = direction_bucket(toward - h.center_of(id));
    let along = bucket_direction(bucket);
    let exposure = h
        .item_buffers
        .as_ref()
        .and_then(|b| b.exposure(id, bucket, <[u64]>::to_vec));
    let Some(exposure) = exposure else {
        return 1.0;
    };
    let contents = h.contents(h.cluster(id).expect("cluster"));
    // Node rays come with gradients (linear bases and up); otherwise the centroid's ray decides.
    let nodes = exposed_nodes(&exposure, contents.len());
    let (mut exposed_area, mut total) = (0.0, 0.0);
    for (k, (&s, a)) in contents
        .iter()
        .zip(visible_areas(h, id, toward))
        .enumerate()
    {
        let w = a * h.patch_of(s).normal.dot(along).max(0.0);
        total += w;
        exposed_area += w * if h.basis_size() >= 3 {
            node_fraction(h.element(s).shape(), nodes[k])
        } else {
            f64::from(u8::from(exposed(&exposure, k)))
        };
    }
    if exposed_area <= 0.0 || exposed_area >= total {
        return 1.0;
    }
    let (to_exposed, to_others) = exposure_shares(exposed_area / total, v);
    to_exposed + to_others
}

/// Largest per-channel spread `max_k L_k − min_k L_k` of the patch radiances in cluster `id`.
fn radiance_spread(h: &Hierarchy, id: ElementId) -> f64 {
    let contents = h.contents(h.cluster(id).expect("cluster"));
    let channel = |c: fn(Rgb) -> f64| {
        let values = contents.iter().map(|&s| c(h.average_radiance(s)));
        let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
        hi - lo
    };
    channel(|l| l.r).max(channel(|l| l.g)).max(channel(|l| l.b))
}

/// [`ClusterSweep`] (one sweep's exchange by direction bucket, O(1) per cluster link) against the
/// per-link exchange, on a closed box full of cubes whose patches carry seeded random radiances:
/// * conservation, exact up to rounding: the power pushed into the patches, `Σ_p π A_p H_p`, is the
///   power the clusters' links delivered, `Σ π A_c F L_sent`, as sharing by exposure scales it
///   ([`exposure_scale`]: a consistency check of the sharing, not of that rule);
/// * the radiance a cluster sends, per link: both are averages of the same patch radiances with weights
///   `p`, `q` that sum to one, so they differ by at most `(max L − min L) Σ|p − q| / 2`, and
///   `Σ|p − q| ≤ 2 Σ|w − w'| / Σ w` ([`bucket_weight_change`] bounds the last ratio);
/// * the irradiance pushed to the patches, in power (L¹ over patches): per receiving link, `π A_c`
///   times the change of what it gathered plus what it gathered times `Σ|p − q|`.
#[test]
fn per_bucket_cluster_exchange_conserves_power_and_stays_within_the_bucket_error_of_per_link() {
    let scene = furnace_with_cubes(4, 0.5, 1.0);
    let settings = SimulationSettings {
        clustering: ClusteringKind::Oriented,
        intra_cluster: IntraClusterKind::ItemBuffer,
        eps: 1e-3,
        ..Default::default()
    };
    let mut h = simulate(&scene, &settings, &quiet())
        .expect("solve")
        .hierarchy;
    assert!(has_cluster_link(&h, true) && has_cluster_link(&h, false));
    let mut rng = Pcg64Mcg::seed_from_u64(9);
    for p in 0..h.patches.len() {
        let root = h.patches[p].root as usize;
        h.radiance_mut(root as u32)[0] = Rgb::new(rng.random(), rng.random(), rng.random());
    }
    h.pull_clusters();
    let sweep = ClusterSweep::new(&h);
    let rounding = 1e-9;

    let mut sent_links = 0;
    let mut reference = vec![Rgb::BLACK; h.patches.len()];
    let (mut delivered, mut push_bound) = (Rgb::BLACK, 0.0);
    for id in 0..h.elements.len() as ElementId {
        let centre = h.center_of(id);
        for link in &h.element(id).links {
            // What the link carries, and the visible average it stands for: they differ where the
            // link is partly blocked and its source sends its exposed patches' light instead
            // (`solvers::clustering::expose`); the bucket error below is about the visible average.
            let carried = sweep.radiance_toward(&h, link.source, centre, link.coupling.visibility);
            let new = sweep.radiance_toward(&h, link.source, centre, 1.0);
            let (old, sent_bound) = if h.is_cluster(link.source) {
                sent_links += 1;
                let spread = radiance_spread(&h, link.source);
                (
                    per_link_radiance(&h, link.source, centre),
                    spread * bucket_weight_change(&h, link.source, centre).min(1.0),
                )
            } else {
                (h.average_radiance(link.source), 0.0)
            };
            for (n, o) in [(new.r, old.r), (new.g, old.g), (new.b, old.b)] {
                assert!(
                    (n - o).abs() <= sent_bound + rounding,
                    "link {id} ← {}: sent {n}, per link {o}, bound {sent_bound}",
                    link.source
                );
            }
            if !h.is_cluster(id) {
                continue;
            }
            let (area, factor) = (h.element(id).area, link.form_factor());
            let v = f64::from(link.coupling.visibility);
            delivered += carried * (factor * area * exposure_scale(&h, id, link.source, v));
            // The per-link value moved by what exposure moved the bucket's.
            let old = old + (carried - new);
            // The per-link push: shares by the exact visible projected areas toward the source.
            let target = h.center_of(link.source);
            let areas = projected_areas(&h, id, target);
            let total: f64 = areas.iter().sum();
            let contents = h.contents(h.cluster(id).expect("cluster"));
            for (&s, &w) in contents.iter().zip(&areas) {
                if total > 0.0 {
                    // In power: π A_s H_s = π A_c F L w_s / Σ w (π dropped on both sides).
                    reference[h.element(s).patch() as usize] += old * (factor * area * w / total);
                }
            }
            let share_change = (2.0 * bucket_weight_change(&h, id, target)).min(2.0);
            push_bound += area * (factor * sent_bound + old.max_channel() * factor * share_change);
        }
    }
    assert!(sent_links > 0);
    let mut pushed = Rgb::BLACK;
    let mut difference = [0.0; 3];
    for (k, p) in h.patches.iter().enumerate() {
        let area = h.element(p.root).area;
        let (new, old) = (sweep.pushed(p.root) * area, reference[k]);
        pushed += new;
        for (d, (n, o)) in
            difference
                .iter_mut()
                .zip([(new.r, old.r), (new.g, old.g), (new.b, old.b)])
        {
            *d += (n - o).abs();
        }
    }
    for (p, d) in [
        (pushed.r, delivered.r),
        (pushed.g, delivered.g),
        (pushed.b, delivered.b),
    ] {
        assert!(
            (p - d).abs() <= rounding * d,
            "pushed {p}, delivered {d}: power lost or made"
        );
    }
    for d in difference {
        assert!(
            d <= push_bound * (1.0 + rounding),
            "pushed power differs by {d} from per link, bound {push_bound}"
        );
    }
}

/// A closed box whose walls reflect and whose cubes alone emit: at convergence the walls and cubes
/// absorb all the emitted power (closed: every ray ends on a surface), `Φ_a = Φ_e`. Radiances differ
/// from patch to patch (lit and shadowed sides), so the per-bucket exchange's weights matter, unlike in
/// the white furnace. Tolerance: the 0.5% for energy balance with clustering.
#[test]
fn closed_box_lit_by_its_cubes_absorbs_what_they_emit_with_item_buffers() {
    let (rho, e) = (0.5, 1.0);
    let mut scene = furnace_with_cubes(4, rho, e);
    let cube_faces = 4 * 4 * 4 * 6;
    let walls = scene.polygons.len() - cube_faces;
    scene.materials = vec![
        Material::diffuse("wall", Rgb::splat(rho)),
        Material::emitter("cube", Rgb::splat(rho), Rgb::splat(e)),
    ];
    for polygon in &mut scene.polygons[walls..] {
        polygon.material = 1;
    }
    let settings = SimulationSettings {
        clustering: ClusteringKind::Oriented,
        intra_cluster: IntraClusterKind::ItemBuffer,
        eps: 1e-5,
        min_area: 1e-4,
        ..Default::default()
    };
    let solution = simulate(&scene, &settings, &quiet()).expect("solve");
    assert!(has_cluster_link(&solution.hierarchy, false));
    let r = &solution.report;
    assert!(r.converged, "sweeps did not converge");
    assert!(
        (r.absorbed_power.g - r.emitted_power.g).abs() / r.emitted_power.g < 0.005,
        "absorbed {} of emitted {}",
        r.absorbed_power.g,
        r.emitted_power.g
    );
}

/// The square at `HEIGHT` facing down (polygon 0), two small plates side by side on the ground facing
/// up (polygons 1, the left, `left_width` wide from x = −0.5, and 2, the right, 0.2 by 0.2 m) and a
/// black square 2.4 m wide at 0.2 m over the left plate (polygon 3) that hides the whole square above
/// from it (large, so that the cluster hierarchy keeps it out of the plates' cluster); the right plate
/// sees all of it past the black square.
fn plates_under_a_square(
    square: Material,
    left: Material,
    right: Material,
    left_width: f64,
) -> Scene {
    one_polygon_per_material(
        vec![
            square,
            left,
            right,
            Material::diffuse("black square", Rgb::BLACK),
        ],
        [
            rectangle([-0.5, 0.5, -0.5, 0.5], HEIGHT, false),
            rectangle([-0.5, -0.5 + left_width, -0.1, 0.1], 0.0, true),
            rectangle([0.3, 0.5, -0.1, 0.1], 0.0, true),
            rectangle([-2.5, -0.1, -1.2, 1.2], 0.2, false),
        ],
        |_| false,
    )
}

/// Seeds of the cluster links' visibility samples over which the plate tests average.
const PLATE_SEEDS: u64 = 16;

/// Solves `scene` with item buffers and elements of `basis` (coarse: the plates and the square stay
/// linked as clusters) for each of [`PLATE_SEEDS`] seeds, handing each solution to `each` with its
/// seed.
fn for_each_seed(scene: &Scene, basis: BasisKind, mut each: impl FnMut(u64, &Hierarchy)) {
    for seed in 1..=PLATE_SEEDS {
        let settings = SimulationSettings {
            seed,
            basis,
            ..settings(IntraClusterKind::ItemBuffer)
        };
        each(
            seed,
            &simulate(scene, &settings, &quiet())
                .expect("solve")
                .hierarchy,
        );
    }
}

/// Whether element `id` is a cluster holding both plates of [`plates_under_a_square`].
fn holds_both_plates(h: &Hierarchy, id: ElementId) -> bool {
    h.cluster(id).is_some_and(|c| {
        let contents = h.contents(c);
        contents.contains(&h.patches[1].root) && contents.contains(&h.patches[2].root)
    })
}

/// Two small plates side by side on the ground under a unit emitter at `HEIGHT`, the left one under
/// a black square 2.4 m wide at 0.2 m that hides the whole emitter from it (large, so that the
/// cluster hierarchy keeps it out of the pair's cluster), the right one in the open: the pair
/// receives through one cluster link whose sampled visibility `v` is about ½ (8 rays from either
/// plate), and the item buffer, which sees only the pair, hides neither. Ground truth: the left
/// plate's radiance is 0 (nothing else lights it: the plates are coplanar, the square is black),
/// the right one's `ρ E F` with `F` its exact factor from the emitter (the square is outside every
/// ray from it). Shared by visible projected area alone, both got the link's average, half of the
/// right plate's light each. Shared by exposure (a ray from each plate's centroid to the source),
/// each plate takes the visibility its own ray found (`solvers::clustering::exposure_shares`): in
/// every seed whose link carries light (`v` > 0; all 8 rays blocked has probability 2⁻⁸) the right
/// plate gets what it would unoccluded, whatever `v`, with the centre-to-centre point kernel's
/// error as its only one: the pair's centre 0.4 m from the plate's at a height of 4 m,
/// `1 / cos⁴θ` = 1.0202, times the point kernel's excess over the unit source's exact factor,
/// about `1 + a² / (π d²)` = 1.0199: 4.05%, and 5% with the couplings' `f32` storage and the
/// item buffer's fractions; and the left one nothing (`v` never exceeds what `e` = ½ explains
/// within three standard deviations of 8 samples). Until 2026-11-28 the exposed plate got all the
/// link delivered, `2v` times the truth: 0.25 to 2 from seed to seed.
#[test]
fn a_cluster_shares_its_light_among_the_patches_that_the_source_reaches() {
    let scene = plates_under_a_square(
        Material::emitter("lamp", Rgb::BLACK, Rgb::splat(1.0)),
        Material::diffuse("shaded plate", Rgb::splat(RHO)),
        Material::diffuse("open plate", Rgb::splat(RHO)),
        0.2,
    );
    let (shaded, open) = (1, 2);
    let emitter = scene.polygons[0].shape;
    let right = scene.polygons[open].shape;
    // The right plate's exact mean factor from the emitter: the point factor over a 20 × 20 grid.
    let factor = mean_factor_up(&right, &emitter, 20);
    let analytic = RHO * factor;
    let mut lit_seeds = 0;
    for_each_seed(&scene, BasisKind::Constant, |seed, h| {
        let lit = (0..h.elements.len() as ElementId).any(|id| {
            holds_both_plates(h, id)
                && h.element(id)
                    .links
                    .iter()
                    .any(|l| l.coupling.visibility > 0.0)
        });
        let dark = mean_radiance_of(h, |k| k == shaded);
        assert!(dark <= 1e-12, "seed {seed}: the hidden plate got {dark}");
        if lit {
            lit_seeds += 1;
            let radiance = mean_radiance_of(h, |k| k == open);
            assert!(
                (radiance - analytic).abs() <= 0.05 * analytic,
                "seed {seed}: open plate {radiance}, analytic {analytic}"
            );
        }
    });
    assert!(
        lit_seeds > PLATE_SEEDS / 2,
        "only {lit_seeds} seeds lit the pair through a cluster link"
    );
}

/// The black square of [`plates_beside_a_square_edge`]: 2.4 m wide, its right edge at `x = edge`, at
/// `height` over the ground.
#[derive(Clone, Copy)]
struct BlackSquare {
    edge: f64,
    height: f64,
}

impl BlackSquare {
    /// Whether the segment from ground point `p` to emitter point `q` crosses the square.
    fn hides(self, p: DVec3, q: DVec3) -> bool {
        let x = p + (q - p) * ((self.height - p.z) / (q.z - p.z));
        (self.edge - 2.4..=self.edge).contains(&x.x) && (-1.2..=1.2).contains(&x.y)
    }
}

/// The plates of [`plates_under_a_square`] (the left one 0.2 m wide, from x = −0.5) under the unit
/// emitter, with the black square moved to `square`.
fn plates_beside_a_square_edge(square: BlackSquare) -> Scene {
    let BlackSquare { edge, height } = square;
    one_polygon_per_material(
        vec![
            Material::emitter("lamp", Rgb::BLACK, Rgb::splat(1.0)),
            Material::diffuse("partly shaded plate", Rgb::splat(RHO)),
            Material::diffuse("open plate", Rgb::splat(RHO)),
            Material::diffuse("black square", Rgb::BLACK),
        ],
        [
            rectangle([-0.5, 0.5, -0.5, 0.5], HEIGHT, false),
            rectangle([-0.5, -0.3, -0.1, 0.1], 0.0, true),
            rectangle([0.3, 0.5, -0.1, 0.1], 0.0, true),
            rectangle([edge - 2.4, edge, -1.2, 1.2], height, false),
        ],
        |_| false,
    )
}

/// The irradiance factor at ground point `p` (facing up) from `emitter`, past `square` where given:
/// `∫ cos cos' / (π r²)` over a 64 × 64 grid of the emitter, the square tested exactly.
fn irradiance_past(emitter: &Shape, p: DVec3, square: Option<BlackSquare>) -> f64 {
    const GRID: usize = 64;
    let cell = emitter.area() / (GRID * GRID) as f64;
    (0..GRID * GRID)
        .map(|i| {
            let uv = DVec2::new((i % GRID) as f64 + 0.5, (i / GRID) as f64 + 0.5) / GRID as f64;
            let q = emitter.point_at(uv);
            if square.is_some_and(|s| s.hides(p, q)) {
                return 0.0;
            }
            let d = q - p;
            let r2 = d.length_squared();
            let cos = d.z / r2.sqrt();
            cos * cos * cell / (std::f64::consts::PI * r2)
        })
        .sum()
}

/// Points over the left plate of [`plates_beside_a_square_edge`], 40 across and 4 deep.
fn left_plate_points() -> Vec<DVec3> {
    (0..160)
        .map(|i| {
            let (u, v) = (
                ((i % 40) as f64 + 0.5) / 40.0,
                ((i / 40) as f64 + 0.5) / 4.0,
            );
            DVec3::new(-0.5 + 0.2 * u, -0.1 + 0.2 * v, 0.0)
        })
        .collect()
}

/// How the light a cluster shares varies over a patch partly in the shadow of something outside the
/// cluster (`solvers::clustering::Gradient`): the two plates of [`plates_under_a_square`] under the
/// unit emitter 4 m up, linear elements, with the black square at 0.2 m moved right so that its
/// edge (x = −0.42) crosses the left plate (x from −0.5 to −0.3): a ground point at x sees emitter
/// points x_e with `0.95 x + 0.05 x_e ≥ −0.42`, so the plate's first 16% is in umbra and the next
/// 26% in penumbra, while its centroid (x = −0.4) sees the emitter's centre. The square is large
/// enough to stay out of the plates' cluster, which the emitter lights through one cluster link.
/// Ground truth: the irradiance at each point, `∫ cos cos' / (π r²)` over the part of the emitter
/// the point sees, on a 64 × 64 grid with the square tested exactly. Compared is the shape of the
/// light over the plate, the solution's radiance over its mean against the truth's (the mean is
/// sharing by exposure's, the share of the patch's nodes that see the source, which the tests
/// around this one check). An even share, the plates' shape until 2026-11-30, has an L² shape error
/// of 0.57 here. The rays from the 2 × 2 Gauss nodes (at 21% and 79% of the width) find one row
/// shaded and one lit, and the plate's light follows the linear function through them, flattened to
/// zero at the shaded edge (twice the mean at the lit one): against the true profile (the penumbra
/// as a ramp over an emitter of even brightness) that line's error is 0.53 of the even share's,
/// computed from the geometry above. The cosines and the point factor's variation over the plate
/// (under 2% at 4 m) move the ratio by a few hundredths; the test asks for under 0.6, where an even
/// share gives 1.
#[test]
fn a_patch_half_in_a_shadow_outside_its_cluster_gets_the_shadow_across_it() {
    let square = BlackSquare {
        edge: -0.42,
        height: 0.2,
    };
    let scene = plates_beside_a_square_edge(square);
    let plate = 1;
    let emitter = scene.polygons[0].shape;
    let points = left_plate_points();
    let truth: Vec<f64> = points
        .iter()
        .map(|&p| irradiance_past(&emitter, p, Some(square)))
        .collect();
    let shape_error = |values: &[f64]| -> f64 {
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
        let (m, t) = (mean(values), mean(&truth));
        let squares: Vec<f64> = values
            .iter()
            .zip(&truth)
            .map(|(v, tr)| (v / m - tr / t).powi(2))
            .collect();
        mean(&squares).sqrt()
    };
    let even = shape_error(&vec![1.0; points.len()]);
    let mut varying_seeds = 0;
    for_each_seed(&scene, BasisKind::Linear, |seed, h| {
        let root = h.patches[plate].root;
        if ClusterSweep::new(h).pushed_slope(root).is_none() {
            return;
        }
        varying_seeds += 1;
        let radiance: Vec<f64> = points
            .iter()
            .map(|&p| h.radiance_at(h.locate(root, p), p).g)
            .collect();
        let ratio = shape_error(&radiance) / even;
        assert!(
            ratio < 0.6,
            "seed {seed}: the plate's shape error is {ratio:.3} of an even share's ({even:.3})"
        );
    });
    assert!(
        varying_seeds > PLATE_SEEDS / 2,
        "only {varying_seeds} seeds gave the plate a gradient"
    );
}

/// The mean light of a patch partly in a shadow cast from outside its cluster: the plates of
/// [`plates_under_a_square`] under the unit emitter 4 m up, the black square at 0.2 m moved so that
/// its edge (x = −0.38) casts the shadow of the emitter's centre across the left plate's middle
/// (x = −0.4: a ground point at x sees emitter points x_e with `0.95 x + 0.05 x_e ≥ −0.38`), a
/// penumbra 5 cm wide about it; the square stays out of the plates' cluster, which the emitter
/// lights through one cluster link. Ground truth: the plate's mean irradiance, `∫ cos cos' / (π r²)`
/// over the part of the emitter each point sees, on a 40 × 4 grid of points and a 64 × 64 grid on
/// the emitter with the square tested exactly: half the unshadowed mean. With linear elements (the
/// node rays come with gradients), a patch's exposed fraction is the share of its 2 × 2 Gauss nodes
/// whose rays reach the source's centre
/// (`solvers::clustering::node_fraction`), the quadrature of its lit part: one row of two here (the
/// nodes at 21% and 79% of the width lie either side of the edge). Error model: that quadrature's
/// error, `|½ − f| / f` relative for the true fraction `f`, plus the 5% of the centre-to-centre point
/// kernel and `f32` storage of the first plate test. Decided by the centroid's ray alone (until
/// 2026-11-30), the plate took the light of its whole area or none: twice the truth or nothing.
#[test]
fn a_patch_partly_in_a_shadow_outside_its_cluster_gets_the_light_of_its_lit_part() {
    let square = BlackSquare {
        edge: -0.38,
        height: 0.2,
    };
    let scene = plates_beside_a_square_edge(square);
    let plate = 1;
    let emitter = scene.polygons[0].shape;
    let points = left_plate_points();
    let mean = |square: Option<BlackSquare>| {
        points
            .iter()
            .map(|&p| irradiance_past(&emitter, p, square))
            .sum::<f64>()
            / points.len() as f64
    };
    let (truth, open) = (mean(Some(square)), mean(None));
    let lit = truth / open;
    assert!((0.45..0.55).contains(&lit), "lit fraction {lit}");
    let tolerance = (0.5 - lit).abs() / lit + 0.05;
    let mut lit_seeds = 0;
    for_each_seed(&scene, BasisKind::Linear, |seed, h| {
        let square = h.patches[3].root;
        let through_cluster = (0..h.elements.len() as ElementId).any(|id| {
            holds_both_plates(h, id)
                && !h
                    .contents(h.cluster(id).expect("a cluster"))
                    .contains(&square)
                && h.element(id)
                    .links
                    .iter()
                    .any(|l| l.coupling.visibility > 0.0)
        });
        if !through_cluster {
            return;
        }
        lit_seeds += 1;
        let radiance = mean_radiance_of(h, |k| k == plate);
        let ratio = radiance / (RHO * truth);
        assert!(
            (ratio - 1.0).abs() <= tolerance,
            "seed {seed}: the plate's mean is {ratio:.3} of the truth (tolerance {tolerance:.3})"
        );
    });
    assert!(
        lit_seeds > PLATE_SEEDS / 2,
        "only {lit_seeds} seeds lit the pair through a cluster link"
    );
}

/// The sending side of the test above, by reciprocity: the two small plates are now lamps facing up,
/// the left one `BRIGHT` times the right one's emission and hidden from the unit square at `HEIGHT`
/// (now a receiver facing down) by the same black square, which lies outside the pair's cluster. The
/// square gathers from the pair through one cluster link whose sampled visibility is about ½. Ground
/// truth: only the right lamp lights it, mean irradiance `E A_lamp F_lamp→square / A_square` (the
/// lamps and the black square reflect nothing). Sent as the pair's visible average the link carried
/// `(BRIGHT + 1) / 2` times the right lamp's radiance through the half of its rays that reach: 5× too
/// much here. Sent by exposure (a ray from each lamp's centroid to the square's centre), each lamp
/// sends what it would unoccluded or nothing, whatever `v` (`Sent::through`, the sending side of
/// `exposure_shares`): in every seed the right lamp's light alone, with the error model of the test
/// above (5%). Until 2026-11-29 the link carried the exposed lamp's radiance times its own `F v`, so
/// that `v`'s noise (8 Bernoulli samples per seed) went straight into the square: 0.51 to 1.54 of the
/// truth from seed to seed.
#[test]
fn a_cluster_sends_only_the_light_of_the_patches_that_reach_the_receiver() {
    const BRIGHT: f64 = 9.0;
    let scene = plates_under_a_square(
        Material::diffuse("square", Rgb::splat(RHO)),
        Material::emitter("hidden lamp", Rgb::BLACK, Rgb::splat(BRIGHT)),
        Material::emitter("open lamp", Rgb::BLACK, Rgb::splat(1.0)),
        0.2,
    );
    let (square, open) = (0, 2);
    let receiver = scene.polygons[square].shape;
    let lamp = scene.polygons[open].shape;
    // Reciprocity: A_square F_square→lamp = A_lamp F_lamp→square, the latter over a 20 × 20 grid.
    let analytic = RHO * lamp.area() * mean_factor_up(&lamp, &receiver, 20) / receiver.area();
    let mut cluster_links = 0;
    for_each_seed(&scene, BasisKind::Constant, |seed, h| {
        cluster_links += h
            .element(h.patches[square].root)
            .links
            .iter()
            .filter(|l| holds_both_plates(h, l.source))
            .count();
        let radiance = mean_radiance_of(h, |k| k == square);
        assert!(
            (radiance - analytic).abs() <= 0.05 * analytic,
            "seed {seed}: square {radiance}, analytic {analytic}"
        );
    });
    assert!(
        cluster_links > 0,
        "the square gathers from no cluster holding both lamps"
    );
}

/// The error bar of a receiver of a cluster link whose hidden part is small and bright: the sending
/// test's scene with the hidden lamp a quarter of the open one's area and 100 times its emission, so
/// that the link is mostly visible (`v` ≈ 0.8) and its visibility error, `√(v(1 − v))` times the
/// pair's average radiance, is about half of what choosing the exposed patches over all visible ones
/// moves (`√(a(1 − a)) (a B + 1 − a)` against `(1 − a) a (B − 1)` per unit coupling, `a` = 0.2 the
/// hidden share, `B` = 100). Over the seeds where some of the link's rays were blocked: as a
/// consistency check, the estimate of every leaf of the square (the link sits above them all) spans
/// both averages the link could carry, since which patches reach is decided by one centroid ray each
/// (`solvers::clustering::moved_by_sending`; the estimate is taken with the final radiances,
/// `end_pass`, so only rounding separates the two sides); against ground truth, the analytic
/// irradiance from the open lamp alone lies within the estimate.
///
/// Left out, a known gap: a seed whose 8 rays all reached (probability 0.8⁸ ≈ 0.17) sends the visible
/// average, 26× the truth here, with neither a visibility error (`v = 1`) nor a sending term (no
/// exposure is taken for fully visible links): its estimate does not cover its error.
#[test]
fn the_error_bar_of_a_receiver_spans_what_choosing_the_exposed_patches_moved() {
    let scene = plates_under_a_square(
        Material::diffuse("square", Rgb::splat(RHO)),
        Material::emitter("hidden lamp", Rgb::BLACK, Rgb::splat(100.0)),
        Material::emitter("open lamp", Rgb::BLACK, Rgb::splat(1.0)),
        0.05,
    );
    let (square, open) = (0, 2);
    let receiver = scene.polygons[square].shape;
    let lamp = scene.polygons[open].shape;
    let analytic = RHO * lamp.area() * mean_factor_up(&lamp, &receiver, 20) / receiver.area();
    let mut partly_blocked = 0;
    for_each_seed(&scene, BasisKind::Constant, |seed, h| {
        let root = h.patches[square].root;
        let sweep = ClusterSweep::new(h);
        let centre = h.center_of(root);
        let moved: f64 = h
            .element(root)
            .links
            .iter()
            .filter(|l| holds_both_plates(h, l.source) && l.coupling.visibility < 1.0)
            .map(|l| {
                let carried = sweep.radiance_toward(h, l.source, centre, l.coupling.visibility);
                let visible = sweep.radiance_toward(h, l.source, centre, 1.0);
                RHO * l.form_factor() * (carried - visible).map(f64::abs).max_channel()
            })
            .sum();
        if moved == 0.0 {
            // Every ray of the link reached: see the test's documentation.
            return;
        }
        partly_blocked += 1;
        let mut leaves = vec![root];
        while let Some(id) = leaves.pop() {
            let e = h.element(id);
            if !e.is_leaf() {
                leaves.extend(&e.children);
                continue;
            }
            assert!(
                e.error >= moved * (1.0 - 1e-9),
                "seed {seed}: leaf {id} estimates {}, the choice moved {moved}",
                e.error
            );
        }
        let radiance = mean_radiance_of(h, |k| k == square);
        let estimate = h.element(root).error;
        assert!(
            (radiance - analytic).abs() <= estimate,
            "seed {seed}: square {radiance}, analytic {analytic}, estimate {estimate}"
        );
    });
    // A link from the pair has visibility below one with probability 1 − 0.8⁸ ≈ 0.83 per seed: 16
    // seeds fail to give 8 such with probability below 10⁻³.
    assert!(
        partly_blocked >= 8,
        "{partly_blocked} seeds had a partly blocked cluster link to the square"
    );
}
