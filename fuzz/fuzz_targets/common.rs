//! What every scene reader must guarantee for any input: no panic (libFuzzer reports it), and a scene
//! it accepts is one the solver can use.

use radiosity::scene::Scene;

/// Panics (a crash libFuzzer reports) when an accepted scene holds a value no reader may let through.
pub fn check_scene(scene: &Scene) {
    for polygon in &scene.polygons {
        let area = polygon.shape.area();
        assert!(
            area.is_finite() && area > 0.0,
            "polygon of area {area} accepted"
        );
        assert!(polygon.material < scene.materials.len());
        assert!(polygon.object < scene.objects.len());
    }
    for material in &scene.materials {
        let (rho, emission) = (material.reflectance, material.emission);
        for c in [rho.r, rho.g, rho.b] {
            assert!((0.0..1.0).contains(&c), "reflectance {c} accepted");
        }
        for c in [emission.r, emission.g, emission.b] {
            assert!(c.is_finite() && c >= 0.0, "emission {c} accepted");
        }
    }
    let _ = radiosity::scene::summary(scene);
}
