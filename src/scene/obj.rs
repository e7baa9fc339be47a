//! OBJ/MTL reader through `tobj`: `Kd` is the diffuse reflectance, times the mean colour of its
//! `map_Kd` texture when there is one ([`super::texture`]; named relative to the OBJ file, a texture
//! that cannot be read leaves `Kd` alone, with a warning), `Ke` the emitted radiance in W/(m² sr).
//! What MTL says beyond that (`Ks`, `d`/`Tr`) is not simulated and is named in a warning. Faces are
//! one-sided, front by counter-clockwise winding. Polygons are kept (no `tobj`
//! triangulation) and split by [`polygonize`](super::polygonize). Objects are named after OBJ `o`/`g`.
//!
//! `tobj` reports errors without line numbers (and panics on short MTL colours), so the OBJ and its MTL
//! libraries are first checked line by line for what `tobj` rejects (bad numbers, short colours, face
//! indices out of range, invalid UTF-8), which is reported with its file and line. Files are read with
//! the size limit of [`read_bounded`](super::read_bounded).

use super::polygonize::{polygonize, PolygonError};
use super::texture::mean_linear_colour;
use super::{
    Diagnostic, LoadOptions, Material, Object, Polygon, Scene, SceneError, DEFAULT_GREY,
    MAX_REFLECTANCE,
};
use crate::color::Rgb;
use glam::DVec3;
use std::collections::HashMap;
use std::path::Path;

/// Reads an OBJ file, its MTL libraries and their `map_Kd` textures (named relative to it; an absent
/// one gives a warning).
pub fn load(path: &Path, _options: &LoadOptions) -> Result<Scene, SceneError> {
    let text = super::read_bounded(path).map_err(|e| SceneError::new(path, 0, e))?;
    let mut scene = parse_bytes(&text, path, |mtl_path| {
        if !mtl_path.exists() {
            return Ok(None);
        }
        super::read_bounded(mtl_path).map(Some)
    })?;
    for source in &mut scene.sources {
        *source = std::fs::canonicalize(&*source).unwrap_or_else(|_| source.clone());
    }
    Ok(scene)
}

/// Reads OBJ text held in memory: `path` names it in messages and anchors `mtllib` and `map_Kd`
/// names, whose bytes `library` returns (`Ok(None)`: absent; a library's faces then get a default
/// grey, a texture's material its `Kd` alone, with a warning).
pub fn parse_bytes(
    text: &[u8],
    path: &Path,
    library: impl Fn(&Path) -> Result<Option<Vec<u8>>, String>,
) -> Result<Scene, SceneError> {
    let face_lines = check(path, text)?;
    let load_options = tobj::LoadOptions {
        triangulate: false,
        single_index: false,
        ignore_points: true,
        ignore_lines: true,
    };
    // Material libraries are read and checked here (tobj panics on short colour lines); the first
    // problem found with a line number wins over tobj's line-less error.
    let mtl_error: std::cell::RefCell<Option<SceneError>> = Default::default();
    let sources = std::cell::RefCell::new(vec![path.to_path_buf()]);
    let missing: std::cell::RefCell<Vec<std::path::PathBuf>> = Default::default();
    let loaded = tobj::load_obj_buf(&mut &text[..], &load_options, |name| {
        let mtl_path = path
            .parent()
            .map_or(name.to_path_buf(), |dir| dir.join(name));
        let bytes = match library(&mtl_path) {
            Ok(Some(bytes)) => bytes,
            Ok(None) => {
                missing.borrow_mut().push(mtl_path);
                return Err(tobj::LoadError::OpenFileFailed);
            }
            Err(e) => {
                mtl_error
                    .borrow_mut()
                    .get_or_insert(SceneError::new(&mtl_path, 0, e));
                return Err(tobj::LoadError::MaterialParseError);
            }
        };
        sources.borrow_mut().push(mtl_path.clone());
        match check_mtl(&mtl_path, &bytes) {
            Ok(()) => tobj::load_mtl_buf(&mut bytes.as_slice()),
            Err(e) => {
                mtl_error.borrow_mut().get_or_insert(e);
                Err(tobj::LoadError::MaterialParseError)
            }
        }
    });
    if let Some(e) = mtl_error.into_inner() {
        return Err(e);
    }
    let (models, materials) =
        loaded.map_err(|e| SceneError::new(path, 0, format!("invalid OBJ: {e}")))?;
    let mut scene = Scene {
        sources: sources.into_inner(),
        ..Scene::default()
    };
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
            let (line, reason) = match missing.into_inner().first() {
                // Named where the file names it: the first `mtllib` statement.
                Some(library) => (
                    mtllib_line(text),
                    format!("material library {} not found", library.display()),
                ),
                None => (0, format!("material library not loaded ({e})")),
            };
            warn(
                &mut scene,
                line,
                format!("{reason}: using a default grey material"),
            );
            Vec::new()
        }
    };
    // Scene materials: one per MTL material, plus the default grey on demand.
    let mut textures = Textures::default();
    for m in &mtl {
        let texture = m.diffuse_texture.as_deref().and_then(|name| {
            textures
                .mean(path, name, &library, &mut scene.sources)
                .map_or_else(
                    |e| {
                        warn(
                            &mut scene,
                            0,
                            format!("material '{}': map_Kd {e}: Kd alone", m.name),
                        );
                        None
                    },
                    Some,
                )
        });
        // MTL's Kd multiplies its texture; a texture without Kd is the colour itself.
        let kd = match (m.diffuse, texture) {
            (Some(d), _) => Rgb::new(d[0] as f64, d[1] as f64, d[2] as f64),
            (None, Some(_)) => Rgb::splat(1.0),
            (None, None) => Rgb::splat(DEFAULT_GREY),
        } * texture.unwrap_or(Rgb::splat(1.0));
        if m.specular.is_some_and(|k| k.iter().any(|&c| c > 0.0)) {
            warn(
                &mut scene,
                0,
                format!(
                    "material '{}': Ks (specular reflection) ignored, only diffuse reflection and \
                     emission are simulated",
                    m.name
                ),
            );
        }
        if m.dissolve.is_some_and(|d| d < 1.0) {
            warn(
                &mut scene,
                0,
                format!(
                    "material '{}': d/Tr (transparency) ignored, the surface is opaque",
                    m.name
                ),
            );
        }
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
        let raw_emission = m.emissive.map_or(Rgb::BLACK, |e| {
            Rgb::new(e[0] as f64, e[1] as f64, e[2] as f64)
        });
        let emission = raw_emission.map(|c| c.max(0.0));
        if emission != raw_emission && raw_emission.is_finite() {
            warn(
                &mut scene,
                0,
                format!(
                    "material '{}': negative Ke ({}, {}, {}) clamped to 0",
                    m.name, raw_emission.r, raw_emission.g, raw_emission.b
                ),
            );
        }
        if !raw_emission.is_finite() || !kd.is_finite() {
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
                            under_contact: false,
                        }));
                    let count = scene.polygons.len();
                    scene.origins.record(path, line, count);
                }
                Err(e @ PolygonError::TooManyVertices(_)) => {
                    return Err(SceneError::new(path, line, e.to_string()))
                }
                Err(e) => warn(&mut scene, line, format!("{e}: polygon dropped")),
            }
        }
    }
    Ok(scene)
}

/// Checks the MTL statements `tobj` parses: colours need three numbers, scalars one.
/// The 1-based line of the first `mtllib` statement in OBJ `text` (0 if none).
fn mtllib_line(text: &[u8]) -> usize {
    text.split(|&b| b == b'\n')
        .position(|line| line.trim_ascii_start().starts_with(b"mtllib"))
        .map_or(0, |index| index + 1)
}

fn check_mtl(path: &Path, bytes: &[u8]) -> Result<(), SceneError> {
    for (k, raw) in bytes.split(|&b| b == b'\n').enumerate() {
        let error = |m: String| SceneError::new(path, k + 1, m);
        let line = std::str::from_utf8(raw).map_err(|_| error("not UTF-8 text".into()))?;
        let mut words = line.split_whitespace();
        let Some(keyword) = words.next() else {
            continue;
        };
        let count = match keyword {
            "Ka" | "Kd" | "Ks" | "Ke" | "Kt" | "Tf" => 3,
            "Ns" | "Ni" | "d" | "Tr" | "illum" => 1,
            _ => continue,
        };
        let values: Vec<&str> = words.collect();
        if keyword.starts_with('K') && values.first() == Some(&"spectral")
            || values.first() == Some(&"xyz")
        {
            return Err(error(format!("{keyword}: only RGB colours are supported")));
        }
        if values.len() < count {
            return Err(error(format!(
                "{keyword} needs {count} number(s), got {}",
                values.len()
            )));
        }
        for w in &values[..count] {
            match w.parse::<f32>() {
                Ok(v) if v.is_finite() => {}
                Ok(_) => return Err(error(format!("{keyword}: number '{w}' is not finite"))),
                Err(_) => return Err(error(format!("{keyword}: '{w}' is not a number"))),
            }
        }
    }
    Ok(())
}

/// Checks vertex and face lines (and the UTF-8 `tobj` needs); returns the line number of every face
/// (faces of three or more vertices, in file order, as `tobj` returns them).
fn check(path: &Path, bytes: &[u8]) -> Result<Vec<usize>, SceneError> {
    let (mut vertices, mut texcoords, mut normals) = (0usize, 0usize, 0usize);
    let mut faces = Vec::new();
    for (k, raw) in bytes.split(|&b| b == b'\n').enumerate() {
        let number = k + 1;
        let error = |m: String| SceneError::new(path, number, m);
        let raw = std::str::from_utf8(raw).map_err(|_| error("not UTF-8 text".into()))?;
        let mut words = raw.split_whitespace();
        match words.next() {
            Some(keyword @ ("vt" | "vn")) => {
                let count = if keyword == "vn" { 3 } else { 2 };
                if keyword == "vn" {
                    normals += 1;
                } else {
                    texcoords += 1;
                }
                let values: Vec<&str> = words.take(count).collect();
                if values.len() < count {
                    return Err(error(format!("{keyword} needs {count} numbers")));
                }
                if let Some(w) = values.iter().find(|w| w.parse::<f32>().is_err()) {
                    return Err(error(format!("'{w}' is not a number")));
                }
            }
            Some("usemtl") if words.next().is_none() => {
                return Err(error("usemtl needs a material name".into()));
            }
            Some("v") => {
                let values: Vec<&str> = words.collect();
                if values.len() < 3 {
                    return Err(error("a vertex needs three coordinates".into()));
                }
                if !matches!(values.len(), 3 | 4 | 6) {
                    return Err(error(format!(
                        "a vertex has x y z [w] or x y z r g b, not {} numbers",
                        values.len()
                    )));
                }
                if values.len() == 4 && values[3].parse::<f32>().is_ok_and(|w| w == 0.0) {
                    return Err(error("vertex weight w is zero".into()));
                }
                for w in &values {
                    match w.parse::<f32>() {
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
                    // v, v/vt, v//vn or v/vt/vn: every index given must exist (tobj overflows on
                    // out-of-range texture and normal indices).
                    let tables = [
                        ("vertex", vertices),
                        ("texture", texcoords),
                        ("normal", normals),
                    ];
                    for (k, field) in c.split('/').enumerate() {
                        let Some(&(what, count)) = tables.get(k) else {
                            return Err(error(format!("bad face vertex '{c}'")));
                        };
                        if k > 0 && field.is_empty() {
                            continue;
                        }
                        let index: i64 = field
                            .parse()
                            .map_err(|_| error(format!("bad face vertex '{c}'")))?;
                        let resolved = if index < 0 {
                            count as i64 + index
                        } else {
                            index - 1
                        };
                        if index == 0 || resolved < 0 || resolved >= count as i64 {
                            return Err(error(format!(
                                "face {what} index {index} does not exist ({count} so far)"
                            )));
                        }
                    }
                }
                if corners.len() >= 3 {
                    faces.push(number);
                }
                if faces.len() > super::MAX_POLYGONS {
                    return Err(error(format!("more than {} faces", super::MAX_POLYGONS)));
                }
            }
            _ => {}
        }
    }
    Ok(faces)
}

/// The `map_Kd` textures read for one OBJ file: each file's mean colour once, and the bytes read in
/// all bounded by [`MAX_LOADED_BYTES`](super::MAX_LOADED_BYTES), as for a glTF's images.
#[derive(Default)]
struct Textures {
    means: HashMap<std::path::PathBuf, Result<Rgb, String>>,
    loaded_bytes: u64,
}

impl Textures {
    /// The mean linear colour of the texture `name` (its last word: `map_Kd` options such as `-bm 1`
    /// come first), read through `library` beside `obj`; the reason when it cannot be used.
    fn mean(
        &mut self,
        obj: &Path,
        name: &str,
        library: &impl Fn(&Path) -> Result<Option<Vec<u8>>, String>,
        sources: &mut Vec<std::path::PathBuf>,
    ) -> Result<Rgb, String> {
        let file = name.split_whitespace().last().unwrap_or(name);
        let texture = obj.parent().map_or(file.into(), |dir| dir.join(file));
        if let Some(mean) = self.means.get(&texture) {
            return mean.clone();
        }
        let shown = super::sanitise(file, 80);
        let mean = match library(&texture) {
            Ok(None) => Err(format!("{shown} not found")),
            Err(e) => Err(format!("{shown}: {e}")),
            Ok(Some(bytes)) => {
                sources.push(texture.clone());
                self.loaded_bytes += bytes.len() as u64;
                if self.loaded_bytes > super::MAX_LOADED_BYTES {
                    Err(format!(
                        "{shown}: textures of more than {} MiB in all are not read",
                        super::MAX_LOADED_BYTES >> 20
                    ))
                } else {
                    mean_linear_colour(&bytes, super::MAX_LOADED_BYTES)
                        .map_err(|e| format!("{shown} not used ({e})"))
                        .and_then(|mean| {
                            mean.is_finite()
                                .then_some(mean)
                                .ok_or_else(|| format!("{shown}: no finite mean colour"))
                        })
                }
            }
        };
        self.means.insert(texture, mean.clone());
        mean
    }
}
