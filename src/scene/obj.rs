//! OBJ/MTL reader through `tobj`: `Kd` is the diffuse reflectance, `Ke` the emitted radiance in
//! W/(m² sr); faces are one-sided, front by counter-clockwise winding. Polygons are kept (no `tobj`
//! triangulation) and split by [`polygonize`](super::polygonize). Objects are named after OBJ `o`/`g`.
//!
//! `tobj` reports errors without line numbers, so the file is first checked line by line for the
//! problems users make (bad numbers, face indices out of range), which are reported with their line.

use super::polygonize::polygonize;
use super::{Diagnostic, LoadOptions, Material, Object, Polygon, Scene, SceneError};
use crate::color::Rgb;
use glam::DVec3;
use std::collections::HashMap;
use std::path::Path;

/// Reflectance of faces without a usable material.
const DEFAULT_GREY: f64 = 0.5;
const MAX_REFLECTANCE: f64 = 0.999;

/// Reads an OBJ file and its MTL libraries.
pub fn load(path: &Path, _options: &LoadOptions) -> Result<Scene, SceneError> {
    let text = std::fs::read(path)
        .map_err(|e| SceneError::new(path, 0, format!("cannot read file: {e}")))?;
    let face_lines = check(path, &String::from_utf8_lossy(&text))?;
    let load_options = tobj::LoadOptions {
        triangulate: false,
        single_index: false,
        ignore_points: true,
        ignore_lines: true,
    };
    let (models, materials) = tobj::load_obj(path, &load_options)
        .map_err(|e| SceneError::new(path, 0, format!("invalid OBJ: {e}")))?;
    let mut scene = Scene::default();
    let warn = |scene: &mut Scene, line: usize, message: String| {
        scene.warnings.push(Diagnostic {
            file: path.to_path_buf(),
            line,
            message,
        })
    };
    let mtl = match materials {
        Ok(m) => m,
        Err(e) => {
            warn(
                &mut scene,
                0,
                format!("material library not loaded ({e}): using a default grey material"),
            );
            Vec::new()
        }
    };
    // Scene materials: one per MTL material, plus the default grey on demand.
    for m in &mtl {
        let kd = m.diffuse.map_or(Rgb::splat(DEFAULT_GREY), |d| {
            Rgb::new(d[0] as f64, d[1] as f64, d[2] as f64)
        });
        let reflectance = kd.map(|c| c.clamp(0.0, MAX_REFLECTANCE));
        if reflectance != kd {
            warn(
                &mut scene,
                0,
                format!(
                    "material '{}': Kd ({}, {}, {}) outside [0, 1) clamped",
                    m.name, kd.r, kd.g, kd.b
                ),
            );
        }
        let emission = m.emissive.map_or(Rgb::BLACK, |e| {
            Rgb::new(e[0] as f64, e[1] as f64, e[2] as f64).map(|c| c.max(0.0))
        });
        if !emission.is_finite() || !reflectance.is_finite() {
            return Err(SceneError::new(
                path,
                0,
                format!("material '{}' has a non-finite Kd or Ke", m.name),
            ));
        }
        scene
            .materials
            .push(Material::emitter(&m.name, reflectance, emission));
    }
    let mut default_material = None;
    let mut object_lookup: HashMap<String, usize> = HashMap::new();
    let mut face_number = 0;
    for model in &models {
        let mesh = &model.mesh;
        let material = match mesh.material_id.filter(|&i| i < mtl.len()) {
            Some(i) => i,
            None => *default_material.get_or_insert_with(|| {
                scene
                    .materials
                    .push(Material::diffuse("default", Rgb::splat(DEFAULT_GREY)));
                scene.materials.len() - 1
            }),
        };
        let object = *object_lookup.entry(model.name.clone()).or_insert_with(|| {
            scene.objects.push(Object {
                name: model.name.clone(),
            });
            scene.objects.len() - 1
        });
        let arities: Vec<usize> = if mesh.face_arities.is_empty() {
            vec![3; mesh.indices.len() / 3]
        } else {
            mesh.face_arities.iter().map(|&a| a as usize).collect()
        };
        let mut start = 0;
        for arity in arities {
            let line = face_lines.get(face_number).copied().unwrap_or(0);
            face_number += 1;
            let points: Vec<DVec3> = mesh.indices[start..start + arity]
                .iter()
                .map(|&i| {
                    let k = 3 * i as usize;
                    DVec3::new(
                        mesh.positions[k] as f64,
                        mesh.positions[k + 1] as f64,
                        mesh.positions[k + 2] as f64,
                    )
                })
                .collect();
            start += arity;
            match polygonize(&points) {
                Ok(out) => {
                    for w in out.warnings {
                        warn(&mut scene, line, w);
                    }
                    scene
                        .polygons
                        .extend(out.shapes.into_iter().map(|shape| Polygon {
                            shape,
                            material,
                            object,
                            two_sided: false,
                        }));
                }
                Err(e) => warn(&mut scene, line, format!("{e}: polygon dropped")),
            }
        }
    }
    Ok(scene)
}

/// Checks vertex and face lines; returns the line number of every face (faces of three or more
/// vertices, in file order, as `tobj` returns them).
fn check(path: &Path, text: &str) -> Result<Vec<usize>, SceneError> {
    let mut vertices = 0usize;
    let mut faces = Vec::new();
    for (k, raw) in text.lines().enumerate() {
        let number = k + 1;
        let mut words = raw.split_whitespace();
        let error = |m: String| SceneError::new(path, number, m);
        match words.next() {
            Some("v") => {
                let values: Vec<&str> = words.collect();
                if values.len() < 3 {
                    return Err(error("a vertex needs three coordinates".into()));
                }
                for w in &values[..3] {
                    match w.parse::<f64>() {
                        Ok(v) if v.is_finite() => {}
                        Ok(_) => return Err(error(format!("number '{w}' is not finite"))),
                        Err(_) => return Err(error(format!("'{w}' is not a number"))),
                    }
                }
                vertices += 1;
            }
            Some("f") => {
                let corners: Vec<&str> = words.collect();
                for c in &corners {
                    let first = c.split('/').next().unwrap_or("");
                    let index: i64 = first
                        .parse()
                        .map_err(|_| error(format!("bad face vertex '{c}'")))?;
                    let resolved = if index < 0 {
                        vertices as i64 + index
                    } else {
                        index - 1
                    };
                    if index == 0 || resolved < 0 || resolved >= vertices as i64 {
                        return Err(error(format!(
                            "face vertex {index} does not exist ({vertices} vertices so far)"
                        )));
                    }
                }
                if corners.len() >= 3 {
                    faces.push(number);
                }
            }
            _ => {}
        }
    }
    Ok(faces)
}
