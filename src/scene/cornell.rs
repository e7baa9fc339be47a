//! The built-in Cornell box: the published Cornell University geometry (Program of Computer Graphics,
//! "Cornell Box Data"), in millimetres, used when no scene file is given.
//!
//! Differences from the published list, all deliberate: the light quad sits at y = 548.7, 0.1 mm below
//! the ceiling (548.8), so that it is not coplanar with it; the red (left) wall of the data set is not
//! planar (its bottom edge leans 3.2 mm), so it is split into two triangles by
//! [`polygonize`](super::polygonize), while every other surface is one quad. Walls face into the room,
//! block faces outward, the light faces down and is one-sided.
//!
//! Materials: reflectances white (0.73, 0.73, 0.73), red (0.63, 0.065, 0.05), green (0.14, 0.45, 0.091),
//! the usual RGB reductions of the measured spectra. The light emits radiance (17, 12, 4) W/(m² sr), the
//! common RGB stand-in for its warm spectrum: with these values the lit walls reach a radiance of order
//! 0.1–1, so an image at exposure 1 is well exposed.

use super::polygonize::polygonize;
use super::{CameraSpec, Material, Object, Polygon, Scene};
use crate::color::Rgb;
use glam::DVec3;

/// Height of the light quad (mm); the ceiling is at 548.8.
pub const LIGHT_Y: f64 = 548.7;

/// The Cornell box with its published camera.
pub fn cornell_box() -> Scene {
    let mut scene = Scene {
        materials: vec![
            Material::diffuse("white", Rgb::splat(0.73)),
            Material::diffuse("red", Rgb::new(0.63, 0.065, 0.05)),
            Material::diffuse("green", Rgb::new(0.14, 0.45, 0.091)),
            Material::emitter("light", Rgb::splat(0.78), Rgb::new(17.0, 12.0, 4.0)),
        ],
        camera: Some(CameraSpec {
            eye: DVec3::new(278.0, 273.0, -800.0),
            look_at: DVec3::new(278.0, 273.0, 0.0),
            up: DVec3::Y,
            // 2 atan(12.5 / 35): a 25 mm film at 35 mm focal length.
            fov_degrees: 39.3,
        }),
        ..Scene::default()
    };
    let (white, red, green, light) = (0, 1, 2, 3);
    let p = |x: f64, y: f64, z: f64| DVec3::new(x, y, z);
    let l = LIGHT_Y;
    let parts: Vec<(&str, usize, Vec<Vec<DVec3>>)> = vec![
        (
            "floor",
            white,
            vec![vec![
                p(552.8, 0.0, 0.0),
                p(0.0, 0.0, 0.0),
                p(0.0, 0.0, 559.2),
                p(549.6, 0.0, 559.2),
            ]],
        ),
        (
            "light",
            light,
            vec![vec![
                p(343.0, l, 227.0),
                p(343.0, l, 332.0),
                p(213.0, l, 332.0),
                p(213.0, l, 227.0),
            ]],
        ),
        (
            "ceiling",
            white,
            vec![vec![
                p(556.0, 548.8, 0.0),
                p(556.0, 548.8, 559.2),
                p(0.0, 548.8, 559.2),
                p(0.0, 548.8, 0.0),
            ]],
        ),
        (
            "back_wall",
            white,
            vec![vec![
                p(549.6, 0.0, 559.2),
                p(0.0, 0.0, 559.2),
                p(0.0, 548.8, 559.2),
                p(556.0, 548.8, 559.2),
            ]],
        ),
        (
            "right_wall",
            green,
            vec![vec![
                p(0.0, 0.0, 559.2),
                p(0.0, 0.0, 0.0),
                p(0.0, 548.8, 0.0),
                p(0.0, 548.8, 559.2),
            ]],
        ),
        (
            "left_wall",
            red,
            vec![vec![
                p(552.8, 0.0, 0.0),
                p(549.6, 0.0, 559.2),
                p(556.0, 548.8, 559.2),
                p(556.0, 548.8, 0.0),
            ]],
        ),
        (
            "short_block",
            white,
            block(
                165.0,
                [
                    p(130.0, 0.0, 65.0),
                    p(82.0, 0.0, 225.0),
                    p(240.0, 0.0, 272.0),
                    p(290.0, 0.0, 114.0),
                ],
            ),
        ),
        (
            "tall_block",
            white,
            block(
                330.0,
                [
                    p(423.0, 0.0, 247.0),
                    p(265.0, 0.0, 296.0),
                    p(314.0, 0.0, 456.0),
                    p(472.0, 0.0, 406.0),
                ],
            ),
        ),
    ];
    for (name, material, faces) in parts {
        scene.objects.push(Object {
            name: name.to_string(),
        });
        let object = scene.objects.len() - 1;
        for face in faces {
            // The data are fixed and non-degenerate, so polygonize always succeeds here.
            let shapes = polygonize(&face).map(|p| p.shapes).unwrap_or_default();
            scene
                .polygons
                .extend(shapes.into_iter().map(|shape| Polygon {
                    shape,
                    material,
                    object,
                    two_sided: false,
                    under_contact: false,
                }));
        }
    }
    scene
}

/// A block standing on the floor: its top (the footprint raised to `height`, counter-clockwise seen from
/// above) and four sides, all facing outward, as in the published data (no bottom face).
fn block(height: f64, footprint: [DVec3; 4]) -> Vec<Vec<DVec3>> {
    let up = DVec3::new(0.0, height, 0.0);
    let mut faces = vec![footprint.iter().map(|p| *p + up).collect::<Vec<_>>()];
    for k in 0..4 {
        let (a, b) = (footprint[k], footprint[(k + 1) % 4]);
        faces.push(vec![b, b + up, a + up, a]);
    }
    faces
}
