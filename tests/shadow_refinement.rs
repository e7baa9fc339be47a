//! The power oracle's visibility term (`--shadow-levels`, Sillion–Drettakis Appendix A) against an
//! analytic penumbra: a receiver square [0, 1]² (z = 0, facing +z) lit by a small emitting square
//! [c ± w]² at height `HEIGHT`, half of it shadowed by a black half-plane x < a at height `HEIGHT / 2`.
//! The segment from a receiver point (x, y, 0) to an emitter point (u, v, HEIGHT) passes the blocker's
//! plane at x + (u − x)/2, so the point sees exactly the emitter's part u ≥ 2a − x, and its radiance is
//! ρ E F(x → that rectangle), Lambert's exact point-to-polygon factor, with no interreflection (the
//! emitter and the blocker reflect nothing): a penumbra 2w wide around x = 2a − c, which a = 0.53 keeps
//! off the quadtree's edges.

use radiosity::color::Rgb;
use radiosity::geometry::form_factor::point_to_polygon;
use radiosity::geometry::DVec3;
use radiosity::hierarchy::Hierarchy;
use radiosity::pipeline::{simulate, SimulationSettings};
use radiosity::progress::Progress;
use radiosity::scene::{Material, Scene};

#[allow(dead_code)] // each test file uses part of the shared module
mod common;
use common::{one_polygon_per_material, rectangle};

/// The blocker's edge, the emitter's height, centre and half-width, the receiver's reflectance, the
/// emitted radiance.
const A: f64 = 0.53;
const HEIGHT: f64 = 1.0;
const C: f64 = 0.5;
const W: f64 = 0.15;
const RHO: f64 = 0.5;
const EMISSION: f64 = 1.0;

fn penumbra_scene() -> Scene {
    one_polygon_per_material(
        vec![
            Material::diffuse("receiver", Rgb::splat(RHO)),
            Material::emitter("emitter", Rgb::BLACK, Rgb::splat(EMISSION)),
            Material::diffuse("blocker", Rgb::BLACK),
        ],
        [
            rectangle([0.0, 1.0, 0.0, 1.0], 0.0, true),
            rectangle([C - W, C + W, C - W, C + W], HEIGHT, false),
            rectangle([-1.0, A, -1.0, 2.0], HEIGHT / 2.0, true),
        ],
        |material| material == 2,
    )
}

/// The exact radiance at receiver point (x, y).
fn exact(x: f64, y: f64) -> f64 {
    let u0 = (2.0 * A - x).max(C - W);
    if u0 >= C + W {
        return 0.0;
    }
    let visible = rectangle([u0, C + W, C - W, C + W], HEIGHT, false);
    RHO * EMISSION * point_to_polygon(DVec3::new(x, y, 0.0), DVec3::Z, &visible)
}

/// L¹ error of the receiver's radiance (midpoint rule on an M × M grid), split into the band
/// |x − (2a − c)| < `band` around the penumbra and the rest.
fn l1_errors(h: &Hierarchy, band: f64) -> (f64, f64) {
    const M: usize = 300;
    let patch = h
        .patches
        .iter()
        .position(|p| p.polygon == 0)
        .expect("receiver") as u32;
    let (mut near, mut far) = (0.0, 0.0);
    for i in 0..M {
        for j in 0..M {
            let (x, y) = ((i as f64 + 0.5) / M as f64, (j as f64 + 0.5) / M as f64);
            let p = DVec3::new(x, y, 0.0);
            let leaf = h.locate(patch, p);
            let e = (h.radiance_at(leaf, p).g - exact(x, y)).abs() / (M * M) as f64;
            if (x - (2.0 * A - C)).abs() < band {
                near += e;
            } else {
                far += e;
            }
        }
    }
    (near, far)
}

/// Error model: the visibility term refines only links whose visibility varies over the receiver,
/// so away from the penumbra (|x − (2a − c)| > 2w: wholly lit or in umbra) elements keep their links
/// and the error cannot grow (it falls where an element reaching into the penumbra was split); in
/// the penumbra each level halves the size of the elements it refines, and the error of
/// representing the varying visibility (Appendix A eq. (3), first order in the element size for the
/// constant basis) falls with it: strictly at every level, and two levels at least halve it (a
/// quarter where the term acted, the penumbra's elements it left alone at most as before).
#[test]
fn shadow_levels_resolve_an_analytic_penumbra() {
    let scene = penumbra_scene();
    for basis in [
        radiosity::bases::BasisKind::Constant,
        radiosity::bases::BasisKind::Linear,
    ] {
        let errors: Vec<(f64, f64)> = [0.0, 1.0, 2.0]
            .into_iter()
            .map(|levels| {
                let settings = SimulationSettings {
                    basis,
                    eps: 3e-3,
                    shadow_levels: levels,
                    min_area: 1e-6,
                    ..Default::default()
                };
                let solution = simulate(&scene, &settings, &Progress::new(true)).expect("solve");
                let h = &solution.hierarchy;
                let (near, far) = l1_errors(h, 2.0 * W);
                eprintln!(
                    "{basis:?}, {levels} shadow levels: {} leaves, L¹ error in the penumbra \
                     {near:.3e}, elsewhere {far:.3e}",
                    h.leaf_count()
                );
                (near, far)
            })
            .collect();
        for pair in errors.windows(2) {
            assert!(
                pair[1].1 <= pair[0].1,
                "{basis:?}: error outside the penumbra grew: {errors:?}"
            );
            assert!(
                pair[1].0 < pair[0].0,
                "{basis:?}: penumbra error did not fall: {errors:?}"
            );
        }
        assert!(
            errors[2].0 <= 0.5 * errors[0].0,
            "{basis:?}: two levels did not halve the penumbra error: {errors:?}"
        );
    }
}
