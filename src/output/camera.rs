//! Pinhole camera shared by the radiosity renderer and the reference path tracer, so that both produce
//! radiance at the same pixel centres.

use crate::geometry::{Aabb, DVec3, Ray};
use crate::scene::{CameraSpec, Scene};
use crate::visibility::{bvh::Bvh, Visibility};

/// A pinhole camera producing primary rays for a `width` x `height` image.
#[derive(Clone, Copy, Debug)]
pub struct Camera {
    pub eye: DVec3,
    forward: DVec3,
    right: DVec3,
    up: DVec3,
    /// The world's up as given (unit length): what an interactive view keeps vertical.
    sky: DVec3,
    /// tan(fov_y / 2)
    half_height: f64,
    pub width: usize,
    pub height: usize,
}

impl Camera {
    /// Camera at `spec.eye` looking at `spec.look_at`; `fov_degrees` is the vertical field of view.
    pub fn new(spec: &CameraSpec, width: usize, height: usize) -> Self {
        let forward = (spec.look_at - spec.eye).normalize_or(DVec3::Z);
        let mut right = forward.cross(spec.up);
        if right.length_squared() < 1e-20 {
            right = forward.any_orthonormal_vector();
        }
        // Right-handed image plane: x to the right, y up, looking down `forward`.
        let right = right.normalize();
        let up = right.cross(forward);
        Camera {
            eye: spec.eye,
            forward,
            right,
            up,
            sky: spec.up.normalize_or(up),
            half_height: (spec.fov_degrees.to_radians() * 0.5).tan(),
            width: width.max(1),
            height: height.max(1),
        }
    }

    /// A view of the whole bounding box: from the front-upper-right diagonal, far enough back for the
    /// bounding sphere to fill the vertical field of view. MGF files carry no camera, so this is the
    /// default for them.
    pub fn framing(bounds: &Aabb, fov_degrees: f64) -> CameraSpec {
        let center = bounds.center();
        let radius = (bounds.diagonal() * 0.5).max(1e-9);
        let direction = DVec3::new(0.6, 0.45, 1.0).normalize();
        let distance = radius / (fov_degrees.to_radians() * 0.5).sin();
        CameraSpec {
            eye: center + direction * distance,
            look_at: center,
            up: DVec3::Y,
            fov_degrees,
        }
    }

    /// The view used when neither the user nor the scene gives one: the scene's own camera if it has one;
    /// otherwise [`Camera::framing`] from outside, unless the scene is a closed room (most rays from
    /// outside stop on polygons lying in the faces of its bounding box, as with RenderPark's rooms), in
    /// which case the eye stands inside, near one wall, a little above mid-height, looking across the
    /// room. "Up" is the axis of smallest extent, z when the extents are within 10% of each other (the
    /// MGF rooms are z-up or y-up).
    pub fn auto_view(scene: &Scene, fov_degrees: f64) -> CameraSpec {
        if let Some(camera) = scene.camera {
            return CameraSpec {
                fov_degrees,
                ..camera
            };
        }
        let bounds = scene.bounds();
        let outside = Camera::framing(&bounds, fov_degrees);
        if !is_enclosure(scene, &bounds, &outside) {
            return outside;
        }
        let extent = bounds.extent();
        let axes = [DVec3::X, DVec3::Y, DVec3::Z];
        let size = |a: usize| extent[a];
        let min_size = size(0).min(size(1)).min(size(2));
        let up = if size(2) <= 1.1 * min_size {
            2
        } else if size(1) <= size(0) {
            1
        } else {
            0
        };
        let (a, b) = match up {
            0 => (1, 2),
            1 => (0, 2),
            _ => (0, 1),
        };
        let across = if size(a) >= size(b) { a } else { b };
        let centre = bounds.center();
        let eye = centre - axes[across] * (0.4 * size(across)) + axes[up] * (0.1 * size(up));
        let look_at = centre - axes[up] * (0.1 * size(up));
        CameraSpec {
            eye,
            look_at,
            up: axes[up],
            fov_degrees,
        }
    }

    /// The ray through image position (x, y) in pixels, (0, 0) the top-left corner of the image; pixel
    /// (i, j) has its centre at (i + 0.5, j + 0.5).
    pub fn ray(&self, x: f64, y: f64) -> Ray {
        let aspect = self.width as f64 / self.height as f64;
        let sx = (2.0 * x / self.width as f64 - 1.0) * self.half_height * aspect;
        let sy = (1.0 - 2.0 * y / self.height as f64) * self.half_height;
        let direction = (self.forward + sx * self.right + sy * self.up).normalize();
        Ray::new(self.eye, direction)
    }

    /// World-space size of one pixel at distance `t` along a primary ray (for mesh-line widths).
    pub fn pixel_footprint(&self, t: f64) -> f64 {
        2.0 * self.half_height * t / self.height as f64
    }

    /// Direction the camera looks in.
    pub fn forward(&self) -> DVec3 {
        self.forward
    }

    /// The image's up direction (orthogonal to [`Camera::forward`]).
    pub fn up(&self) -> DVec3 {
        self.up
    }

    /// The world's up direction given to [`Camera::new`] (not orthogonalised).
    pub fn sky(&self) -> DVec3 {
        self.sky
    }

    /// Vertical field of view in degrees.
    pub fn vertical_fov_degrees(&self) -> f64 {
        2.0 * self.half_height.atan().to_degrees()
    }
}

/// How far (relative to the box's extent on that axis) a wall may lie inside a face of the bounding box
/// and still count as lying in it, for [`is_enclosure`].
const WALL_TOLERANCE: f64 = 0.02;

/// Whether the scene is a room seen from outside: polygons lie in (within [`WALL_TOLERANCE`] of) at
/// least five of the six faces of the bounding box, and most primary rays of a small view from
/// `outside` stop on them.
fn is_enclosure(scene: &Scene, bounds: &Aabb, outside: &CameraSpec) -> bool {
    let shapes: Vec<_> = scene.polygons.iter().map(|p| p.shape).collect();
    let visibility = Bvh::new(&shapes);
    let camera = Camera::new(outside, 16, 16);
    // Walls within 2% of the extent of a box face count as lying in it: real rooms have sills, frames
    // and skirting that stick out past their walls (RenderPark's classroom: 7.5 cm on a 7 m room).
    let tolerance = |axis: usize| {
        (WALL_TOLERANCE * (bounds.max[axis] - bounds.min[axis])).max(1e-6 * bounds.diagonal())
    };
    let on_box_face = |polygon: usize| {
        (0..3).any(|axis| {
            [bounds.min[axis], bounds.max[axis]].iter().any(|&plane| {
                scene.polygons[polygon]
                    .shape
                    .vertices()
                    .iter()
                    .all(|v| (v[axis] - plane).abs() <= tolerance(axis))
            })
        })
    };
    let faces_covered = (0..3)
        .flat_map(|axis| [(axis, bounds.min[axis]), (axis, bounds.max[axis])])
        .filter(|&(axis, plane)| {
            scene.polygons.iter().any(|p| {
                p.shape
                    .vertices()
                    .iter()
                    .all(|v| (v[axis] - plane).abs() <= tolerance(axis))
            })
        })
        .count();
    if faces_covered < 5 {
        return false;
    }
    let (mut hits, mut walls) = (0, 0);
    for j in 0..16 {
        for i in 0..16 {
            if let Some(hit) = visibility.intersect(
                &camera.ray(i as f64 + 0.5, j as f64 + 0.5),
                0.0,
                f64::INFINITY,
            ) {
                hits += 1;
                walls += usize::from(on_box_face(hit.polygon));
            }
        }
    }
    hits > 0 && 2 * walls > hits
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_closed_room_is_viewed_from_inside_and_an_object_from_outside() {
        use crate::scene::generators::{furnace, parallel_plates};
        let room = furnace(DVec3::new(4.0, 3.0, 2.0), 0.5, 1.0);
        let view = Camera::auto_view(&room, 60.0);
        let bounds = room.bounds();
        assert!(
            (0..3).all(|a| view.eye[a] > bounds.min[a] && view.eye[a] < bounds.max[a]),
            "{view:?}"
        );
        assert_eq!(view.up, DVec3::Z);
        let plates = parallel_plates(1.0, 1.0, 0.5, 1.0);
        let view = Camera::auto_view(&plates, 45.0);
        let bounds = plates.bounds();
        assert!(
            (0..3).any(|a| view.eye[a] < bounds.min[a] || view.eye[a] > bounds.max[a]),
            "{view:?}"
        );
    }

    #[test]
    fn centre_pixel_looks_forward_and_fov_is_vertical() {
        let spec = CameraSpec {
            eye: DVec3::ZERO,
            look_at: DVec3::Z,
            up: DVec3::Y,
            fov_degrees: 90.0,
        };
        let cam = Camera::new(&spec, 200, 100);
        let r = cam.ray(100.0, 50.0);
        assert!((r.direction - DVec3::Z).length() < 1e-12);
        // Top edge of the image is 45 degrees up.
        let top = cam.ray(100.0, 0.0).direction;
        assert!((top.y - top.z).abs() < 1e-12 && top.y > 0.0);
        // Left edge (x = 0) is towards -right; with up = +y and forward = +z, right = -x.
        let left = cam.ray(0.0, 50.0).direction;
        assert!(left.x > 0.0);
    }
}
