//! Pinhole camera shared by the radiosity renderer and the reference path tracer, so that both produce
//! radiance at the same pixel centres.

use crate::geometry::{Aabb, DVec3, Ray};
use crate::scene::CameraSpec;

/// A pinhole camera producing primary rays for a `width` x `height` image.
#[derive(Clone, Copy, Debug)]
pub struct Camera {
    pub eye: DVec3,
    forward: DVec3,
    right: DVec3,
    up: DVec3,
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
}

#[cfg(test)]
mod tests {
    use super::*;

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
