//! Embree 3 ray casting (cargo feature `embree`, system library from `scripts/install-embree.sh`): the
//! yardstick for our BVH's speed. Triangles and quads go into one Embree triangle mesh and one quad mesh;
//! Embree works in `f32`, and closest hits are refined in double precision on the polygon it found.

use super::brute_force::intersect_shape;
use super::{Hit, Visibility};
use crate::geometry::{Ray, Shape};
use anyhow::{anyhow, Result};
use embree3::{BufferUsage, Device, Format, GeometryKind, IntersectContext, RayHit, Scene};

/// An Embree scene over the polygons, with the map from Embree's (geometry, primitive) ids back to
/// polygon indices.
pub struct EmbreeScene {
    scene: Scene<'static>,
    shapes: Vec<Shape>,
    /// Polygon index of each primitive, per Embree geometry id.
    polygons: Vec<Vec<u32>>,
    // Declared last: dropped after the scene that uses it.
    _device: Device,
}

impl EmbreeScene {
    pub fn new(shapes: &[Shape]) -> Result<EmbreeScene> {
        let device = Device::new().map_err(|e| anyhow!("creating the Embree device: {e}"))?;
        let mut scene = device
            .create_scene()
            .map_err(|e| anyhow!("creating the Embree scene: {e}"))?;
        let mut polygons = Vec::new();
        for (kind, corners) in [(GeometryKind::TRIANGLE, 3), (GeometryKind::QUAD, 4)] {
            let (indices, vertices): (Vec<u32>, Vec<[f32; 3]>) = shapes
                .iter()
                .enumerate()
                .filter(|(_, s)| s.vertex_count() == corners)
                .map(|(i, s)| {
                    (
                        i as u32,
                        s.vertices().iter().map(|v| v.as_vec3().to_array()),
                    )
                })
                .fold((Vec::new(), Vec::new()), |(mut ids, mut vs), (i, v)| {
                    ids.push(i);
                    vs.extend(v);
                    (ids, vs)
                });
            if indices.is_empty() {
                continue;
            }
            let fail = |what: &str, e: embree3::Error| anyhow!("Embree {what} buffer: {e}");
            let mut geometry = device
                .create_geometry(kind)
                .map_err(|e| anyhow!("creating an Embree geometry: {e}"))?;
            geometry
                .set_new_buffer::<[f32; 3]>(
                    BufferUsage::VERTEX,
                    0,
                    Format::FLOAT3,
                    12,
                    vertices.len(),
                )
                .map_err(|e| fail("vertex", e))?
                .copy_from_slice(&vertices);
            if corners == 3 {
                let index: Vec<[u32; 3]> = (0..indices.len() as u32)
                    .map(|k| [3 * k, 3 * k + 1, 3 * k + 2])
                    .collect();
                geometry
                    .set_new_buffer::<[u32; 3]>(
                        BufferUsage::INDEX,
                        0,
                        Format::UINT3,
                        12,
                        index.len(),
                    )
                    .map_err(|e| fail("index", e))?
                    .copy_from_slice(&index);
            } else {
                let index: Vec<[u32; 4]> = (0..indices.len() as u32)
                    .map(|k| [4 * k, 4 * k + 1, 4 * k + 2, 4 * k + 3])
                    .collect();
                geometry
                    .set_new_buffer::<[u32; 4]>(
                        BufferUsage::INDEX,
                        0,
                        Format::UINT4,
                        16,
                        index.len(),
                    )
                    .map_err(|e| fail("index", e))?
                    .copy_from_slice(&index);
            }
            let geometry = geometry.commit();
            let id = scene.attach_geometry(&geometry) as usize;
            if polygons.len() <= id {
                polygons.resize(id + 1, Vec::new());
            }
            polygons[id] = indices;
        }
        scene.commit();
        Ok(EmbreeScene {
            scene,
            shapes: shapes.to_vec(),
            polygons,
            _device: device,
        })
    }

    fn embree_ray(ray: &Ray, t_min: f64, t_max: f64) -> embree3::Ray {
        embree3::Ray::segment(
            ray.origin.as_vec3().to_array(),
            ray.direction.as_vec3().to_array(),
            t_min.max(0.0) as f32,
            t_max.min(f32::MAX as f64) as f32,
        )
    }
}

impl Visibility for EmbreeScene {
    fn intersect(&self, ray: &Ray, t_min: f64, t_max: f64) -> Option<Hit> {
        if t_max.is_nan() || t_min.is_nan() || t_max <= t_min {
            return None;
        }
        let mut ray_hit = RayHit::from_ray(Self::embree_ray(ray, t_min, t_max));
        self.scene
            .intersect(&mut IntersectContext::incoherent(), &mut ray_hit);
        let polygon = *self
            .polygons
            .get(ray_hit.hit.geomID as usize)?
            .get(ray_hit.hit.primID as usize)? as usize;
        let shape = &self.shapes[polygon];
        // Exact hit on the polygon Embree found; Embree's f32 answer where the double test just misses.
        intersect_shape(shape, polygon, ray, t_min, t_max).or_else(|| {
            let t = f64::from(ray_hit.ray.tfar);
            Some(Hit {
                t,
                polygon,
                front: ray.direction.dot(shape.vector_area()) < 0.0,
            })
        })
    }

    fn occluded(&self, ray: &Ray, t_min: f64, t_max: f64) -> bool {
        if t_max.is_nan() || t_min.is_nan() || t_max <= t_min {
            return false;
        }
        let mut r = Self::embree_ray(ray, t_min, t_max);
        self.scene
            .occluded(&mut IntersectContext::incoherent(), &mut r)
    }

    fn name(&self) -> &'static str {
        "embree"
    }
}
