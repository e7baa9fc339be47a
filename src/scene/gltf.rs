//! glTF 2.0 reader (`.gltf` JSON, `.glb` binary) through the `gltf` crate.
//!
//! What is read:
//! - **Geometry**: the mesh primitives of the default scene (else the first scene; a file without scenes
//!   gives all root nodes), through the whole node graph with matrix or TRS transforms. Triangle lists,
//!   strips and fans, indexed or not, become [`Shape::Triangle`](crate::geometry::Shape) polygons (kept
//!   as triangles), front side by counter-clockwise winding (reversed under a mirroring transform, as
//!   glTF says). Points and lines are skipped with a warning; degenerate triangles are dropped with one
//!   warning counting them. Skins, morph targets and instancing extensions are not applied.
//! - **Materials**: reflectance ρ = `baseColorFactor` (rgb) × the mean colour of the base colour
//!   texture when there is one (embedded in a buffer view, a data URI or a file beside the glTF; PNG is
//!   decoded, other formats give a warning and the factor alone; [`super::texture`]). Texture
//!   coordinates and transforms are ignored: the mean is over the whole image. Reflectance is clamped below 1 with a warning.
//!   Metallic-roughness, transmission and alpha are ignored: every surface is Lambertian.
//!   Emission L_e = `emissiveFactor` × `KHR_materials_emissive_strength` (1 without it);
//!   `emissiveTexture` is ignored with a warning. `doubleSided` makes two-sided surfaces.
//!   Primitives without a material get a grey of reflectance 0.5 (as OBJ faces without one do).
//! - **Lights** (`KHR_lights_punctual`): point and spot lights become point luminaires
//!   ([`super::luminaire`], as IES luminaires are) at their node's origin, aimed down its −Z (its
//!   scale ignored, as the extension says); the intensity is candela, as the extension defines it, so
//!   a light of `intensity` I and `color` c sends c × I / 179 W/sr (the luminaires' white efficacy).
//!   A spot light keeps I within its inner cone, none beyond its outer cone, and in between the
//!   extension's recommended smooth falloff (see [`punctual_photometry`]). `range` is not applied
//!   (the inverse-square law is physical). Directional lights are left out with a warning.
//! - **Camera**: the first perspective camera reached through the node graph (depth first, children
//!   in order) becomes the scene camera; it looks down −Z of its node with +Y up, and `yfov` (radians)
//!   becomes the vertical field of view in degrees. The aspect ratio is not kept.
//!
//! Units: glTF colours are linear, so factors are used as they are; texels of a base colour texture
//! are sRGB-encoded and are linearised before averaging. Emission is taken as emitted *radiance* in the
//! scene's units, W/(m² sr), as MGF and OBJ emission are here (glTF's own "nits" are cd/m², a
//! photometric radiance: the numbers are used unconverted). Punctual lights are the one place glTF
//! fixes a unit (candela), so they alone are converted: a scene lit by them reads in physical units
//! (`grid` in lux), and in a file that mixes them with emissive materials the emission counts 179
//! times what a photometric reading of it would. Lengths are glTF metres, unscaled.
//!
//! Safety: the file and every external buffer or image is read with the size limit of
//! [`read_bounded`], all loaded buffers and images together are bounded by
//! [`MAX_LOADED_BYTES`], accessors are read with checked offsets (the crate's own readers can panic on
//! bad strides or counts), the node graph is checked for shared children and cycles, node visits and
//! instanced triangles are bounded (by [`MAX_NODE_VISITS`] and [`MAX_POLYGONS`]),
//! and images larger than [`MAX_TEXTURE_SIDE`](super::texture::MAX_TEXTURE_SIDE) pixels a side are
//! not decoded.

use super::ies::{Opening, Photometry, Symmetry};
use super::luminaire::Luminaire;
use super::polygonize::polygonize;
use super::texture::mean_linear_colour;
use super::{
    read_bounded, sanitise, CameraSpec, Diagnostic, LoadOptions, Material, Object, Polygon, Scene,
    SceneError, DEFAULT_GREY, MAX_LOADED_BYTES, MAX_POLYGONS, MAX_REFLECTANCE,
};
use crate::color::Rgb;
use ::gltf::accessor::{DataType, Dimensions};
use ::gltf::json;
use ::gltf::mesh::Mode;
use glam::{DMat4, DQuat, DVec3};
use std::borrow::Cow;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::rc::Rc;

/// Most node visits while walking the scene graph (a scene may list a big subtree many times).
pub const MAX_NODE_VISITS: usize = 1_000_000;
/// Most elements of one accessor.
const MAX_ACCESSOR_ELEMENTS: usize = 1 << 26;
/// Longest URI echoed in a message.
const MAX_SHOWN_URI: usize = 80;

/// Reads a glTF 2.0 file (JSON or binary, told apart by content).
pub fn load(path: &Path, _options: &LoadOptions) -> Result<Scene, SceneError> {
    let bytes = read_bounded(path).map_err(|e| SceneError::new(path, 0, e))?;
    let mut scene = parse_bytes(&bytes, path)?;
    scene.sources[0] = std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf());
    Ok(scene)
}

/// Reads glTF JSON or GLB held in memory: `path` names it in messages and anchors relative URIs.
pub fn parse_bytes(bytes: &[u8], path: &Path) -> Result<Scene, SceneError> {
    let error = |message: String| SceneError::new(path, 0, message);
    let (json_bytes, bin) = if bytes.starts_with(b"glTF") {
        let (json_bytes, bin) = split_glb(bytes).map_err(|e| error(format!("invalid GLB: {e}")))?;
        (json_bytes, Some(bin))
    } else {
        (bytes, None)
    };
    let root: json::Root = json::deserialize::from_slice(json_bytes).map_err(|e| {
        // Lines only mean something in a text file; a GLB's JSON chunk has its own numbering.
        let line = if bin.is_none() { e.line() } else { 0 };
        SceneError::new(path, line, format!("invalid glTF JSON: {e}"))
    })?;
    check_position_indices(&root).map_err(error)?;
    let document = ::gltf::Document::from_json(root).map_err(|e| error(validation_message(e)))?;
    let mut reader = Reader {
        path,
        document: &document,
        buffers: Vec::new(),
        loaded_bytes: 0,
        scene: Scene {
            sources: vec![path.to_path_buf()],
            ..Scene::default()
        },
        materials: HashMap::new(),
        textures: HashMap::new(),
        meshes: HashMap::new(),
        triangles: 0,
        degenerate: 0,
        skipped_modes: HashMap::new(),
    };
    for buffer in document.buffers() {
        let index = buffer.index();
        let data: Cow<[u8]> = match buffer.source() {
            ::gltf::buffer::Source::Bin => match bin.flatten() {
                Some(b) => Cow::Borrowed(b),
                None => {
                    return Err(error(format!(
                        "buffer {index} refers to the GLB binary chunk, which is missing"
                    )))
                }
            },
            ::gltf::buffer::Source::Uri(uri) => Cow::Owned(
                reader
                    .resolve_uri(uri)
                    .map_err(|e| error(format!("buffer {index}: {e}")))?,
            ),
        };
        if data.len() < buffer.length() {
            return Err(error(format!(
                "buffer {index} has {} bytes, but its byteLength is {}",
                data.len(),
                buffer.length()
            )));
        }
        reader.buffers.push(data);
    }
    reader.walk()?;
    Ok(reader.finish())
}

/// Splits a GLB container into its JSON chunk and its binary chunk (if any).
fn split_glb(bytes: &[u8]) -> Result<(&[u8], Option<&[u8]>), String> {
    let word = |at: usize| -> Option<u32> {
        let b = bytes.get(at..at.checked_add(4)?)?;
        Some(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    };
    let version = word(4).ok_or("header shorter than 12 bytes")?;
    let length = word(8).ok_or("header shorter than 12 bytes")? as usize;
    if version != 2 {
        return Err(format!("version {version}, only 2 is read"));
    }
    if length > bytes.len() || length < 12 {
        return Err(format!(
            "header gives length {length}, the file has {} bytes",
            bytes.len()
        ));
    }
    let bytes = &bytes[..length];
    let mut at = 12;
    let mut json_chunk = None;
    let mut bin_chunk = None;
    while at < length {
        let (Some(chunk_length), Some(kind)) = (word(at), word(at + 4)) else {
            return Err(format!("truncated chunk header at byte {at}"));
        };
        let start = at + 8;
        let end = start
            .checked_add(chunk_length as usize)
            .filter(|&e| e <= length)
            .ok_or_else(|| format!("chunk at byte {at} runs past the end of the file"))?;
        match (&kind.to_le_bytes(), json_chunk.is_none()) {
            (b"JSON", true) => json_chunk = Some(&bytes[start..end]),
            (_, true) => return Err("the first chunk is not JSON".into()),
            (b"BIN\0", false) if bin_chunk.is_none() => bin_chunk = Some(&bytes[start..end]),
            _ => {} // Unknown chunks are skipped, as the specification asks.
        }
        // Chunks are 4-byte aligned.
        at = end.div_ceil(4) * 4;
    }
    let json_chunk = json_chunk.ok_or("no JSON chunk")?;
    Ok((json_chunk, bin_chunk))
}

/// The crate's validation indexes the POSITION accessor without checking it exists: check first.
fn check_position_indices(root: &json::Root) -> Result<(), String> {
    use json::validation::Checked;
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, primitive) in mesh.primitives.iter().enumerate() {
            let key = Checked::Valid(json::mesh::Semantic::Positions);
            if let Some(index) = primitive.attributes.get(&key) {
                if index.value() >= root.accessors.len() {
                    return Err(format!(
                        "invalid glTF: meshes[{m}].primitives[{p}].attributes.POSITION: accessor {} \
                         does not exist",
                        index.value()
                    ));
                }
            }
        }
    }
    Ok(())
}

/// The first few validation errors on one line.
fn validation_message(error: ::gltf::Error) -> String {
    match error {
        ::gltf::Error::Validation(errors) => {
            let shown: Vec<String> = errors
                .iter()
                .take(3)
                .map(|(path, e)| format!("{path}: {e}"))
                .collect();
            let more = errors.len().saturating_sub(3);
            let tail = if more > 0 {
                format!(" (and {more} more)")
            } else {
                String::new()
            };
            format!("invalid glTF: {}{tail}", shown.join("; "))
        }
        other => format!("invalid glTF: {other}"),
    }
}

/// Decodes standard base64 (padding optional, ASCII whitespace skipped).
fn decode_base64(text: &str) -> Result<Vec<u8>, String> {
    let mut out = Vec::with_capacity(text.len() / 4 * 3);
    let mut acc = 0u32;
    let mut bits = 0;
    for (k, c) in text.bytes().enumerate() {
        let value = match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' => 62,
            b'/' => 63,
            b'=' => break,
            c if c.is_ascii_whitespace() => continue,
            _ => return Err(format!("invalid base64 character at position {k}")),
        };
        acc = (acc << 6) | value as u32;
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
            acc &= (1 << bits) - 1;
        }
    }
    Ok(out)
}

/// Decodes `%XX` escapes of a relative URI.
fn percent_decode(uri: &str) -> Result<String, String> {
    let bytes = uri.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut k = 0;
    while k < bytes.len() {
        if bytes[k] == b'%' {
            let hex = bytes
                .get(k + 1..k + 3)
                .and_then(|h| std::str::from_utf8(h).ok())
                .and_then(|h| u8::from_str_radix(h, 16).ok())
                .ok_or("bad %-escape in URI")?;
            out.push(hex);
            k += 3;
        } else {
            out.push(bytes[k]);
            k += 1;
        }
    }
    String::from_utf8(out).map_err(|_| "URI is not UTF-8 after %-decoding".to_string())
}

/// Vertical angles (degrees) between a spot light's inner and outer cones in its table: its falloff
/// is smooth, and the table is interpolated linearly between them.
const SPOT_FALLOFF_STEPS: usize = 64;

/// The candela table of a punctual light: `candela` in every direction for a point light; for a spot
/// light with cones `(inner, outer)` (radians from its axis, the nadir of the table), `candela` within
/// the inner cone, none outside the outer one, and in between `candela` times the square of
/// `(cos θ − cos outer) / (cos inner − cos outer)`, the falloff `KHR_lights_punctual` recommends.
fn punctual_photometry(
    path: &Path,
    name: &str,
    candela: f64,
    cones: Option<(f64, f64)>,
) -> Photometry {
    let (vertical, values): (Vec<f64>, Vec<f64>) = match cones {
        None => (vec![0.0, 180.0], vec![candela, candela]),
        Some((inner, outer)) => {
            let mut table = vec![(0.0, candela)];
            // Equal cones make a hard edge, kept a hair wide so that the angles increase.
            let outer = inner + (outer - inner).max(1e-6);
            for k in 0..=SPOT_FALLOFF_STEPS {
                let theta = inner + (outer - inner) * k as f64 / SPOT_FALLOFF_STEPS as f64;
                let t = ((theta.cos() - outer.cos()) / (inner.cos() - outer.cos())).clamp(0.0, 1.0);
                table.push((theta.to_degrees(), candela * t * t));
            }
            table.push((180.0, 0.0));
            table.dedup_by(|b, a| b.0 <= a.0);
            table.into_iter().unzip()
        }
    };
    Photometry {
        file: PathBuf::from(format!("{} {name}", path.display())),
        version: "glTF KHR_lights_punctual".into(),
        keywords: Vec::new(),
        lamps: 1.0,
        lumens_per_lamp: None,
        multiplier: 1.0,
        flux_precision: 0.0,
        input_watts: 0.0,
        opening: Opening {
            length: 0.0,
            width: 0.0,
            height: 0.0,
            round: false,
        },
        vertical,
        horizontal: vec![0.0],
        symmetry: Symmetry::Rotational,
        candela: values,
        warnings: Vec::new(),
    }
}

/// Triangles of one primitive in mesh coordinates.
struct PrimitiveTriangles {
    material: Option<usize>,
    positions: Vec<DVec3>,
    triangles: Vec<[u32; 3]>,
}

struct Reader<'a> {
    path: &'a Path,
    document: &'a ::gltf::Document,
    buffers: Vec<Cow<'a, [u8]>>,
    loaded_bytes: u64,
    scene: Scene,
    /// glTF material (None: the default) → scene material.
    materials: HashMap<Option<usize>, usize>,
    /// glTF image → mean linear colour (None when it could not be decoded).
    textures: HashMap<usize, Option<Rgb>>,
    meshes: HashMap<usize, Rc<Vec<PrimitiveTriangles>>>,
    /// Triangles instanced so far (degenerate ones included).
    triangles: usize,
    degenerate: usize,
    /// Primitive modes skipped (points and lines) and how many primitives had each.
    skipped_modes: HashMap<&'static str, usize>,
}

impl Reader<'_> {
    fn error(&self, message: String) -> SceneError {
        SceneError::new(self.path, 0, message)
    }

    fn warn(&mut self, message: String) {
        self.scene.warnings.push(Diagnostic {
            file: self.path.to_path_buf(),
            line: 0,
            message,
        });
    }

    /// Reads a data URI or a file relative to the glTF file.
    fn resolve_uri(&mut self, uri: &str) -> Result<Vec<u8>, String> {
        let shown = sanitise(uri, MAX_SHOWN_URI);
        let data = if let Some(rest) = uri.strip_prefix("data:") {
            let (header, payload) = rest
                .split_once(',')
                .ok_or_else(|| format!("data URI without a comma: '{shown}'"))?;
            if !header.ends_with(";base64") {
                return Err(format!("data URI is not base64: '{shown}'"));
            }
            decode_base64(payload).map_err(|e| format!("data URI: {e}"))?
        } else {
            let scheme = uri.split_once(':').map(|(s, _)| s);
            if scheme.is_some_and(|s| {
                s.len() > 1
                    && !s.contains('/')
                    && s.chars()
                        .all(|c| c.is_ascii_alphanumeric() || "+-.".contains(c))
            }) {
                return Err(format!("unsupported URI scheme in '{shown}'"));
            }
            let relative = percent_decode(uri)?;
            let file = self
                .path
                .parent()
                .map_or_else(|| relative.clone().into(), |dir| dir.join(&relative));
            let data = read_bounded(&file).map_err(|e| format!("'{shown}': {e}"))?;
            let canonical = std::fs::canonicalize(&file).unwrap_or(file);
            self.scene.sources.push(canonical);
            data
        };
        self.loaded_bytes += data.len() as u64;
        if self.loaded_bytes > MAX_LOADED_BYTES {
            return Err(format!(
                "buffers and images larger than {} MiB in all refused",
                MAX_LOADED_BYTES >> 20
            ));
        }
        Ok(data)
    }

    /// Walks the scene's node graph, instancing meshes and finding the camera.
    fn walk(&mut self) -> Result<(), SceneError> {
        let document = self.document;
        let count = document.nodes().len();
        let mut parents = vec![0usize; count];
        for node in document.nodes() {
            for child in node.children() {
                parents[child.index()] += 1;
                if parents[child.index()] > 1 {
                    return Err(self.error(format!(
                        "node {} is the child of more than one node",
                        child.index()
                    )));
                }
            }
        }
        // With at most one parent each, nodes not reached from the parentless ones lie on cycles.
        let mut reached = vec![false; count];
        let mut stack: Vec<::gltf::Node> = document
            .nodes()
            .filter(|n| parents[n.index()] == 0)
            .collect();
        while let Some(node) = stack.pop() {
            reached[node.index()] = true;
            stack.extend(node.children());
        }
        if let Some(k) = reached.iter().position(|r| !r) {
            return Err(self.error(format!("node {k} is part of a cycle of children")));
        }
        let roots: Vec<::gltf::Node> = match document
            .default_scene()
            .or_else(|| document.scenes().next())
        {
            Some(scene) => scene.nodes().collect(),
            None => {
                if count > 0 {
                    self.warn("no scene: all root nodes are loaded".into());
                }
                document
                    .nodes()
                    .filter(|n| parents[n.index()] == 0)
                    .collect()
            }
        };
        let mut stack: Vec<(::gltf::Node, DMat4)> = roots
            .into_iter()
            .rev()
            .map(|n| (n, DMat4::IDENTITY))
            .collect();
        let mut visits = 0;
        let mut orthographic = false;
        while let Some((node, parent)) = stack.pop() {
            visits += 1;
            if visits > MAX_NODE_VISITS {
                return Err(self.error(format!(
                    "more than {MAX_NODE_VISITS} node visits walking the scene graph"
                )));
            }
            let world = parent * local_transform(&node);
            if !world.is_finite() {
                return Err(self.error(format!("node {} has a non-finite transform", node.index())));
            }
            if let Some(camera) = node.camera() {
                match camera.projection() {
                    ::gltf::camera::Projection::Perspective(p) => {
                        if self.scene.camera.is_none() {
                            self.set_camera(&node, &world, p.yfov() as f64);
                        }
                    }
                    ::gltf::camera::Projection::Orthographic(_) => orthographic = true,
                }
            }
            if let Some(mesh) = node.mesh() {
                self.instance(&node, mesh, &world)?;
            }
            if let Some(light) = node.light() {
                self.place_light(&node, &light, &world);
            }
            let children: Vec<::gltf::Node> = node.children().collect();
            stack.extend(children.into_iter().rev().map(|c| (c, world)));
        }
        if orthographic {
            self.warn("orthographic cameras are not used".into());
        }
        Ok(())
    }

    fn set_camera(&mut self, node: &::gltf::Node, world: &DMat4, yfov: f64) {
        let eye = world.transform_point3(DVec3::ZERO);
        let forward = world.transform_vector3(DVec3::NEG_Z).normalize_or_zero();
        let up = world.transform_vector3(DVec3::Y).normalize_or_zero();
        let usable = yfov > 0.0
            && yfov < std::f64::consts::PI
            && forward != DVec3::ZERO
            && up.cross(forward).length() > 1e-9
            && eye.is_finite();
        if usable {
            self.scene.camera = Some(CameraSpec {
                eye,
                look_at: eye + forward,
                up,
                fov_degrees: yfov.to_degrees(),
            });
        } else {
            self.warn(format!(
                "camera of node {} ignored: degenerate orientation or yfov {yfov} outside (0, π)",
                node.index()
            ));
        }
    }

    /// Places a `KHR_lights_punctual` point or spot light as a point luminaire (see the module
    /// documentation); a directional light, or one whose numbers or node cannot place it, is named
    /// in a warning and left out.
    fn place_light(
        &mut self,
        node: &::gltf::Node,
        light: &::gltf::khr_lights_punctual::Light,
        world: &DMat4,
    ) {
        use ::gltf::khr_lights_punctual::Kind;
        let name = light.name().map_or_else(
            || format!("light {}", light.index()),
            |n| format!("light '{n}'"),
        );
        let name = sanitise(&name, MAX_SHOWN_URI);
        let c = light.color();
        let colour = Rgb::new(c[0] as f64, c[1] as f64, c[2] as f64);
        let candela = light.intensity() as f64;
        let position = world.transform_point3(DVec3::ZERO);
        // Scale does not shape the light: the frame is the node's rotation alone.
        let axes =
            [DVec3::X, DVec3::Y, DVec3::Z].map(|a| world.transform_vector3(a).normalize_or_zero());
        let cones = match light.kind() {
            Kind::Directional => {
                self.warn(format!(
                    "{name} of node {} ignored: a directional light (at infinite distance) is not \
                     simulated; an emitting polygon or an IES luminaire can stand for the sun",
                    node.index()
                ));
                return;
            }
            Kind::Point => None,
            Kind::Spot {
                inner_cone_angle,
                outer_cone_angle,
            } => Some((inner_cone_angle as f64, outer_cone_angle as f64)),
        };
        let usable = colour.is_finite()
            && colour.min_channel() >= 0.0
            && candela.is_finite()
            && candela >= 0.0
            && position.is_finite()
            && axes.iter().all(|a| *a != DVec3::ZERO)
            && cones.is_none_or(|(inner, outer)| {
                (0.0..=std::f64::consts::FRAC_PI_2).contains(&outer)
                    && (0.0..=outer).contains(&inner)
            });
        if !usable {
            self.warn(format!(
                "{name} of node {} ignored: negative or non-finite colour or intensity, cone angles \
                 outside 0 <= inner <= outer <= π/2, or a degenerate transform",
                node.index()
            ));
            return;
        }
        let photometry = punctual_photometry(self.path, &name, candela, cones);
        let transform = glam::DAffine3::from_cols(axes[0], axes[1], axes[2], position);
        self.scene.add_luminaire(Luminaire::place(
            std::sync::Arc::new(photometry),
            transform,
            colour,
            1.0,
        ));
    }

    /// Adds the triangles of `mesh` placed by `world` as one object.
    fn instance(
        &mut self,
        node: &::gltf::Node,
        mesh: ::gltf::Mesh,
        world: &DMat4,
    ) -> Result<(), SceneError> {
        let primitives = match self.meshes.get(&mesh.index()) {
            Some(p) => p.clone(),
            None => {
                let p = Rc::new(self.read_mesh(&mesh)?);
                self.meshes.insert(mesh.index(), p.clone());
                p
            }
        };
        let name = node
            .name()
            .or(mesh.name())
            .map_or_else(|| format!("node {}", node.index()), str::to_string);
        self.scene.objects.push(Object { name });
        let object = self.scene.objects.len() - 1;
        let mirrored = world.determinant() < 0.0;
        for primitive in primitives.iter() {
            self.triangles += primitive.triangles.len();
            if self.triangles > MAX_POLYGONS {
                return Err(self.error(format!("more than {MAX_POLYGONS} triangles")));
            }
            let material = self.material(primitive.material)?;
            let two_sided = self.scene.materials[material].two_sided;
            let placed: Vec<DVec3> = primitive
                .positions
                .iter()
                .map(|&p| world.transform_point3(p))
                .collect();
            for t in &primitive.triangles {
                let [a, mut b, mut c] = t.map(|i| placed[i as usize]);
                if mirrored {
                    std::mem::swap(&mut b, &mut c);
                }
                match polygonize(&[a, b, c]) {
                    Ok(out) => self
                        .scene
                        .polygons
                        .extend(out.shapes.into_iter().map(|shape| Polygon {
                            shape,
                            material,
                            object,
                            two_sided,
                            under_contact: false,
                        })),
                    Err(_) => self.degenerate += 1,
                }
            }
        }
        Ok(())
    }

    /// Reads the triangles of every primitive of a mesh.
    fn read_mesh(&mut self, mesh: &::gltf::Mesh) -> Result<Vec<PrimitiveTriangles>, SceneError> {
        let mut out = Vec::new();
        for primitive in mesh.primitives() {
            let at = format!("mesh {} primitive {}", mesh.index(), primitive.index());
            let mode = primitive.mode();
            let skipped = match mode {
                Mode::Points => Some("points"),
                Mode::Lines | Mode::LineLoop | Mode::LineStrip => Some("lines"),
                _ => None,
            };
            if let Some(kind) = skipped {
                *self.skipped_modes.entry(kind).or_default() += 1;
                continue;
            }
            let accessor = primitive
                .get(&::gltf::Semantic::Positions)
                .ok_or_else(|| self.error(format!("{at}: no POSITION")))?;
            if accessor.dimensions() != Dimensions::Vec3 || accessor.data_type() != DataType::F32 {
                return Err(self.error(format!("{at}: POSITION is not a VEC3 FLOAT accessor")));
            }
            let flat = self.read_accessor(&accessor).map_err(|e| {
                self.error(format!("{at}: POSITION accessor {}: {e}", accessor.index()))
            })?;
            let positions: Vec<DVec3> = flat
                .chunks_exact(3)
                .map(|c| DVec3::new(c[0], c[1], c[2]))
                .collect();
            let vertices = positions.len();
            let indices: Vec<u32> = match primitive.indices() {
                Some(accessor) => {
                    if accessor.dimensions() != Dimensions::Scalar
                        || !matches!(
                            accessor.data_type(),
                            DataType::U8 | DataType::U16 | DataType::U32
                        )
                    {
                        return Err(self
                            .error(format!("{at}: indices are not an unsigned SCALAR accessor")));
                    }
                    let raw = self.read_accessor(&accessor).map_err(|e| {
                        self.error(format!("{at}: indices accessor {}: {e}", accessor.index()))
                    })?;
                    let mut indices = Vec::with_capacity(raw.len());
                    for v in raw {
                        if v >= vertices as f64 {
                            return Err(self.error(format!(
                                "{at}: index {v} out of range ({vertices} vertices)"
                            )));
                        }
                        indices.push(v as u32);
                    }
                    indices
                }
                None => (0..vertices as u32).collect(),
            };
            let n = indices.len();
            let triangles: Vec<[u32; 3]> = match mode {
                Mode::TriangleStrip => (0..n.saturating_sub(2))
                    .map(|i| {
                        let odd = i % 2;
                        [indices[i], indices[i + 1 + odd], indices[i + 2 - odd]]
                    })
                    .collect(),
                Mode::TriangleFan => (1..n.saturating_sub(1))
                    .map(|i| [indices[i], indices[i + 1], indices[0]])
                    .collect(),
                _ => {
                    if !n.is_multiple_of(3) {
                        self.warn(format!(
                            "{at}: {n} indices is not a multiple of 3: the last {} ignored",
                            n % 3
                        ));
                    }
                    indices
                        .chunks_exact(3)
                        .map(|c| [c[0], c[1], c[2]])
                        .collect()
                }
            };
            if self.triangles + triangles.len() > MAX_POLYGONS {
                return Err(self.error(format!("more than {MAX_POLYGONS} triangles")));
            }
            out.push(PrimitiveTriangles {
                material: primitive.material().index(),
                positions,
                triangles,
            });
        }
        Ok(out)
    }

    /// The components of an accessor's elements, as numbers (sparse substitution applied).
    fn read_accessor(&self, accessor: &::gltf::Accessor) -> Result<Vec<f64>, String> {
        let count = accessor.count();
        if count > MAX_ACCESSOR_ELEMENTS {
            return Err(format!(
                "{count} elements, more than {MAX_ACCESSOR_ELEMENTS}"
            ));
        }
        let data_type = accessor.data_type();
        let components = accessor.dimensions().multiplicity();
        let mut out = match accessor.view() {
            Some(view) => {
                self.read_elements(&view, accessor.offset(), count, data_type, components)?
            }
            None => vec![0.0; count * components],
        };
        if let Some(sparse) = accessor.sparse() {
            let k = sparse.count();
            let indices = sparse.indices();
            let index_type = match indices.index_type() {
                ::gltf::accessor::sparse::IndexType::U8 => DataType::U8,
                ::gltf::accessor::sparse::IndexType::U16 => DataType::U16,
                ::gltf::accessor::sparse::IndexType::U32 => DataType::U32,
            };
            let at = self.read_elements(&indices.view(), indices.offset(), k, index_type, 1)?;
            let values = sparse.values();
            let values =
                self.read_elements(&values.view(), values.offset(), k, data_type, components)?;
            for (i, value) in at.iter().zip(values.chunks_exact(components)) {
                let i = *i as usize;
                if i >= count {
                    return Err(format!("sparse index {i} out of range ({count} elements)"));
                }
                out[i * components..(i + 1) * components].copy_from_slice(value);
            }
        }
        Ok(out)
    }

    /// Reads `count` elements of `components` numbers from a buffer view, checking every bound.
    fn read_elements(
        &self,
        view: &::gltf::buffer::View,
        offset: usize,
        count: usize,
        data_type: DataType,
        components: usize,
    ) -> Result<Vec<f64>, String> {
        if count > MAX_ACCESSOR_ELEMENTS {
            return Err(format!(
                "{count} elements, more than {MAX_ACCESSOR_ELEMENTS}"
            ));
        }
        let buffer = &self.buffers[view.buffer().index()];
        let view_end = view
            .offset()
            .checked_add(view.length())
            .filter(|&e| e <= buffer.len())
            .ok_or_else(|| format!("buffer view {} runs past its buffer", view.index()))?;
        let data = &buffer[view.offset()..view_end];
        let size = data_type.size();
        let element = size * components;
        let stride = view.stride().unwrap_or(element);
        if stride < element {
            return Err(format!(
                "byteStride {stride} is less than the element size {element}"
            ));
        }
        if count == 0 {
            return Ok(Vec::new());
        }
        let end = (count - 1)
            .checked_mul(stride)
            .and_then(|s| s.checked_add(offset))
            .and_then(|s| s.checked_add(element))
            .filter(|&e| e <= data.len())
            .ok_or_else(|| {
                format!(
                    "{count} elements from byte {offset} run past buffer view {} ({} bytes)",
                    view.index(),
                    data.len()
                )
            })?;
        let data = &data[..end];
        let mut out = Vec::with_capacity(count * components);
        for e in 0..count {
            let start = offset + e * stride;
            for c in 0..components {
                let b = &data[start + c * size..start + (c + 1) * size];
                out.push(match data_type {
                    DataType::I8 => b[0] as i8 as f64,
                    DataType::U8 => b[0] as f64,
                    DataType::I16 => i16::from_le_bytes([b[0], b[1]]) as f64,
                    DataType::U16 => u16::from_le_bytes([b[0], b[1]]) as f64,
                    DataType::U32 => u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
                    DataType::F32 => f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
                });
            }
        }
        Ok(out)
    }

    /// The scene material of a glTF material (None: the default grey), made on first use.
    fn material(&mut self, index: Option<usize>) -> Result<usize, SceneError> {
        if let Some(&m) = self.materials.get(&index) {
            return Ok(m);
        }
        let material = match index.and_then(|i| self.document.materials().nth(i)) {
            None => Material::diffuse("default", Rgb::splat(DEFAULT_GREY)),
            Some(m) => self.read_material(&m)?,
        };
        self.scene.materials.push(material);
        let m = self.scene.materials.len() - 1;
        self.materials.insert(index, m);
        Ok(m)
    }

    fn read_material(&mut self, m: &::gltf::Material) -> Result<Material, SceneError> {
        let name = m.name().map_or_else(
            || format!("material {}", m.index().unwrap_or(0)),
            str::to_string,
        );
        let pbr = m.pbr_metallic_roughness();
        let f = pbr.base_color_factor();
        let mut base = Rgb::new(f[0] as f64, f[1] as f64, f[2] as f64);
        if let Some(info) = pbr.base_color_texture() {
            let image = info.texture().source();
            if let Some(mean) = self.texture_mean(&image, &name) {
                base = base * mean;
            }
        }
        let reflectance = base.map(|c| c.clamp(0.0, MAX_REFLECTANCE));
        if reflectance != base && base.is_finite() {
            self.warn(format!(
                "material '{name}': reflectance ({}, {}, {}) outside [0, 1) clamped",
                base.r, base.g, base.b
            ));
        }
        let e = m.emissive_factor();
        let strength = m.emissive_strength().unwrap_or(1.0) as f64;
        let raw_emission = Rgb::new(e[0] as f64, e[1] as f64, e[2] as f64) * strength;
        let emission = raw_emission.map(|c| c.max(0.0));
        if emission != raw_emission && raw_emission.is_finite() {
            self.warn(format!(
                "material '{name}': negative emission ({}, {}, {}) clamped to 0",
                raw_emission.r, raw_emission.g, raw_emission.b
            ));
        }
        if m.emissive_texture().is_some() {
            self.warn(format!(
                "material '{name}': emissiveTexture ignored (emissiveFactor used alone)"
            ));
        }
        if !base.is_finite() || !raw_emission.is_finite() {
            return Err(self.error(format!(
                "material '{name}' has a non-finite colour or emission"
            )));
        }
        Ok(Material {
            name,
            reflectance,
            emission,
            two_sided: m.double_sided(),
        })
    }

    /// Mean linear colour of an image (cached); None with a warning when it cannot be decoded.
    fn texture_mean(&mut self, image: &::gltf::Image, material: &str) -> Option<Rgb> {
        if let Some(&mean) = self.textures.get(&image.index()) {
            return mean;
        }
        let bytes: Result<Cow<[u8]>, String> = match image.source() {
            ::gltf::image::Source::View { view, .. } => {
                let buffer = &self.buffers[view.buffer().index()];
                view.offset()
                    .checked_add(view.length())
                    .and_then(|end| buffer.get(view.offset()..end))
                    .map(|b| Cow::Owned(b.to_vec()))
                    .ok_or_else(|| format!("buffer view {} runs past its buffer", view.index()))
            }
            ::gltf::image::Source::Uri { uri, .. } => self.resolve_uri(uri).map(Cow::Owned),
        };
        let mean = bytes.and_then(|b| mean_linear_colour(&b, MAX_LOADED_BYTES));
        let mean = match mean {
            Ok(mean) if mean.is_finite() => Some(mean),
            Ok(_) => None,
            Err(e) => {
                self.warn(format!(
                    "material '{material}': base colour texture (image {}) not used ({e}): \
                     baseColorFactor alone",
                    image.index()
                ));
                None
            }
        };
        self.textures.insert(image.index(), mean);
        mean
    }

    fn finish(mut self) -> Scene {
        if self.degenerate > 0 {
            self.warn(format!("{} degenerate triangles dropped", self.degenerate));
        }
        let mut skipped: Vec<(&str, usize)> =
            self.skipped_modes.iter().map(|(k, v)| (*k, *v)).collect();
        skipped.sort();
        for (kind, n) in skipped {
            self.warn(format!(
                "{n} primitive(s) of {kind} skipped: only triangles are read"
            ));
        }
        let count = self.scene.polygons.len();
        self.scene.origins.record(self.path, 0, count);
        self.scene
    }
}

/// A node's own transform: its matrix, or translation × rotation × scale.
fn local_transform(node: &::gltf::Node) -> DMat4 {
    match node.transform() {
        ::gltf::scene::Transform::Matrix { matrix } => {
            DMat4::from_cols_array_2d(&matrix.map(|c| c.map(|v| v as f64)))
        }
        ::gltf::scene::Transform::Decomposed {
            translation: t,
            rotation: r,
            scale: s,
        } => {
            let q = DQuat::from_xyzw(r[0] as f64, r[1] as f64, r[2] as f64, r[3] as f64);
            let q = if q.length() > 0.0 {
                q.normalize()
            } else {
                DQuat::IDENTITY
            };
            DMat4::from_scale_rotation_translation(
                DVec3::new(s[0] as f64, s[1] as f64, s[2] as f64),
                q,
                DVec3::new(t[0] as f64, t[1] as f64, t[2] as f64),
            )
        }
    }
}
