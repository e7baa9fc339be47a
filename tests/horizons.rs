//! Light across a horizon: floor_gloss.mgf's configuration, a 10 m × 4 m floor (ρ = 0.7, facing up)
//! under a small tilted two-sided lamp whose plane cuts the floor at x ≈ 9.3: the floor beyond sees
//! only the lamp's back side. The lamp is black and the floor sees nothing else, so there the floor's
//! radiance is exactly `ρ E F(x → lamp's back)` (point-to-polygon factor, closed form).
//!
//! The coupling of a link between the floor and the lamp's back integrates with cubature nodes; on
//! the floor's coarse elements they all lie behind the lamp's plane, the coupling was zero and the link
//! was dropped: the strip read 0 (floor_gloss.mgf: 0.00005 against a reference of 0.0007).
//! Refinement now splits an end whose nodes cannot see the other across such a horizon
//! (`solvers::refine`'s `horizon_split`).
//!
//! Error model for the strip's mean: the power oracle admits a link whose estimated power
//! `ρ A F B` is below `ε Φ` (Feixas et al. eq. (1); `eps` relative to the total emission Φ), so a
//! receiver element whose light comes from one admitted link can be off by that much power; the
//! strip (0.7 × 4 m) overlaps at most a few such elements. Bound: 4 ε Φ over the strip's analytic
//! power, plus the 10% that the regular rule is trusted to where it sees any light (as in
//! tests/near_field.rs).

use radiosity::bases::BasisKind;
use radiosity::color::Rgb;
use radiosity::geometry::form_factor::point_to_polygon;
use radiosity::geometry::{DVec3, Shape};
use radiosity::pipeline::{simulate, SimulationSettings};
use radiosity::progress::Progress;
use radiosity::scene::Material;

#[allow(dead_code)] // each test file uses part of the shared module
mod common;
use common::{one_polygon_per_material, rectangle};

const RHO: f64 = 0.7;
const EMISSION: f64 = 1.0;

fn lamp() -> [DVec3; 4] {
    [
        DVec3::new(6.5, 2.1, 2.8),
        DVec3::new(6.5, 1.9, 2.8),
        DVec3::new(6.3, 1.9, 3.0),
        DVec3::new(6.3, 2.1, 3.0),
    ]
}

#[test]
fn the_back_of_a_tilted_lamp_lights_the_floor_beyond_its_plane() {
    let scene = one_polygon_per_material(
        vec![
            Material::diffuse("floor", Rgb::splat(RHO)),
            Material::emitter("lamp", Rgb::BLACK, Rgb::splat(EMISSION)),
        ],
        [
            rectangle([0.0, 10.0, 0.0, 4.0], 0.0, true),
            Shape::Quad(lamp()),
        ],
        |k| k == 1,
    );
    let settings = SimulationSettings {
        basis: BasisKind::Linear,
        eps: 3e-5,
        ..Default::default()
    };
    let solution = simulate(&scene, &settings, &Progress::new(true)).unwrap();
    let h = &solution.hierarchy;
    let floor = h.patch_for_side(0, true).expect("the floor's lit side");
    let [a, b, c, d] = lamp();
    let back = Shape::Quad([d, c, b, a]);
    // The lamp's plane meets the floor at x = 6.4 + 2.9 = 9.3; the strip beyond it, on a grid.
    let (nx, ny) = (28, 80);
    let (mut solved, mut exact) = (0.0, 0.0);
    for i in 0..nx {
        for j in 0..ny {
            let p = DVec3::new(
                9.3 + 0.7 * (i as f64 + 0.5) / nx as f64,
                4.0 * (j as f64 + 0.5) / ny as f64,
                0.0,
            );
            solved += h.exitant_radiance_at(h.locate(floor, p), p).g;
            exact += RHO * EMISSION * point_to_polygon(p, DVec3::Z, &back);
        }
    }
    let cells = (nx * ny) as f64;
    let (solved, exact) = (solved / cells, exact / cells);
    // In the threshold's units (radiance × area): Φ = Σ A E over the lamp's two sides, and the
    // strip's L A.
    let emitted = 2.0 * EMISSION * back.area();
    let strip_power = exact * 0.7 * 4.0;
    let bound = 0.1 + 4.0 * settings.eps * emitted / strip_power;
    eprintln!("strip mean {solved:.6} exact {exact:.6} bound {bound:.3}");
    assert!(exact > 0.0);
    assert!(
        ((solved - exact) / exact).abs() < bound,
        "the strip beyond the lamp's plane reads {solved:.3e}, its closed form {exact:.3e} (bound {bound:.2})"
    );
}
