//! Test scenes with known answers: the analytic form factor configurations and the closed "furnace" box.

use super::{Material, Object, Polygon, Scene};
use crate::color::Rgb;
use crate::geometry::{DVec3, Shape};

fn quad(a: DVec3, b: DVec3, c: DVec3, d: DVec3) -> Shape {
    Shape::Quad([a, b, c, d])
}

fn scene_of(faces: Vec<(Shape, usize, &str)>, materials: Vec<Material>) -> Scene {
    let mut scene = Scene {
        materials,
        ..Default::default()
    };
    for (shape, material, name) in faces {
        let object = scene.objects.len();
        scene.objects.push(Object {
            name: name.to_string(),
        });
        scene.polygons.push(Polygon {
            shape,
            material,
            object,
            two_sided: false,
        });
    }
    scene
}

/// Two coaxial parallel squares of side `size` at `distance`: the lower one (z = 0, facing +z) reflects
/// with `reflectance`, the upper one (facing -z) emits radiance `emission` and reflects nothing. The lower
/// square's radiance is then ρ F E with F the analytic form factor.
pub fn parallel_plates(size: f64, distance: f64, reflectance: f64, emission: f64) -> Scene {
    let s = size;
    let receiver = quad(
        DVec3::ZERO,
        DVec3::new(s, 0.0, 0.0),
        DVec3::new(s, s, 0.0),
        DVec3::new(0.0, s, 0.0),
    );
    let h = distance;
    let emitter = quad(
        DVec3::new(0.0, 0.0, h),
        DVec3::new(0.0, s, h),
        DVec3::new(s, s, h),
        DVec3::new(s, 0.0, h),
    );
    scene_of(
        vec![(receiver, 0, "receiver"), (emitter, 1, "emitter")],
        vec![
            Material::diffuse("receiver", Rgb::splat(reflectance)),
            Material::emitter("emitter", Rgb::BLACK, Rgb::splat(emission)),
        ],
    )
}

/// Two squares of side `size` at a right angle sharing an edge (the x axis): the horizontal one (facing
/// +z) reflects, the vertical one (facing +y) emits.
pub fn perpendicular_plates(size: f64, reflectance: f64, emission: f64) -> Scene {
    let s = size;
    let receiver = quad(
        DVec3::ZERO,
        DVec3::new(s, 0.0, 0.0),
        DVec3::new(s, s, 0.0),
        DVec3::new(0.0, s, 0.0),
    );
    let emitter = quad(
        DVec3::ZERO,
        DVec3::new(0.0, 0.0, s),
        DVec3::new(s, 0.0, s),
        DVec3::new(s, 0.0, 0.0),
    );
    scene_of(
        vec![(receiver, 0, "receiver"), (emitter, 1, "emitter")],
        vec![
            Material::diffuse("receiver", Rgb::splat(reflectance)),
            Material::emitter("emitter", Rgb::BLACK, Rgb::splat(emission)),
        ],
    )
}

/// The six inward-facing faces of an axis-aligned box [0, size]^3, in the order -x, +x, -y, +y, -z, +z.
pub fn box_faces(size: DVec3) -> [Shape; 6] {
    let (x, y, z) = (size.x, size.y, size.z);
    let p = |a: f64, b: f64, c: f64| DVec3::new(a, b, c);
    [
        quad(p(0., 0., 0.), p(0., y, 0.), p(0., y, z), p(0., 0., z)),
        quad(p(x, 0., 0.), p(x, 0., z), p(x, y, z), p(x, y, 0.)),
        quad(p(0., 0., 0.), p(0., 0., z), p(x, 0., z), p(x, 0., 0.)),
        quad(p(0., y, 0.), p(x, y, 0.), p(x, y, z), p(0., y, z)),
        quad(p(0., 0., 0.), p(x, 0., 0.), p(x, y, 0.), p(0., y, 0.)),
        quad(p(0., 0., z), p(0., y, z), p(x, y, z), p(x, 0., z)),
    ]
}

/// The white furnace: a closed box whose faces all reflect ρ and emit E; every point converges to
/// E / (1 - ρ).
pub fn furnace(size: DVec3, reflectance: f64, emission: f64) -> Scene {
    let faces = box_faces(size)
        .into_iter()
        .map(|f| (f, 0, "wall"))
        .collect();
    scene_of(
        faces,
        vec![Material::emitter(
            "furnace",
            Rgb::splat(reflectance),
            Rgb::splat(emission),
        )],
    )
}

/// A closed box of reflectance ρ whose ceiling (+y face) alone emits: all emitted power must be absorbed.
pub fn lit_box(size: DVec3, reflectance: Rgb, emission: f64) -> Scene {
    let faces = box_faces(size)
        .into_iter()
        .enumerate()
        .map(|(k, f)| (f, usize::from(k == 3), "wall"))
        .collect();
    scene_of(
        faces,
        vec![
            Material::diffuse("wall", reflectance),
            Material::emitter("ceiling", reflectance, Rgb::splat(emission)),
        ],
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_faces_point_inward() {
        let size = DVec3::new(1.0, 2.0, 3.0);
        let centre = size * 0.5;
        for f in box_faces(size) {
            assert!(f.normal().dot(centre - f.centroid()) > 0.0);
            assert!(f.area() > 0.0);
        }
    }
}
