//! Illuminated models: the leaf elements as a triangle mesh with the solution's radiance per vertex, for
//! viewing in other tools. PLY carries both the tone-mapped sRGB colour and the linear radiance; binary glTF
//! carries display-linear colour (exposure and tone curve, no gamma: viewers encode) with an unlit material
//! so that it is shown as is.

use super::mesh_values::{ShadedMesh, VertexRadiosity};
use super::tonemap::{rgb8, ToneMap};
use crate::hierarchy::Hierarchy;
use anyhow::{bail, Context, Result};
use serde_json::json;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

/// Writes the leaves as a binary little-endian PLY: per vertex position, normal, tone-mapped sRGB colour
/// (`red green blue`, u8) and linear radiance (`radiance_r radiance_g radiance_b`, float); triangle faces.
pub fn write_ply(
    path: &Path,
    hierarchy: &Hierarchy,
    vertices: &VertexRadiosity,
    tone: &ToneMap,
) -> Result<()> {
    let mesh = vertices.mesh(hierarchy);
    let scale = tone.exposure_scale(mesh.radiance.iter().copied());
    let write = |to: &Path| -> std::io::Result<()> {
        let mut out = BufWriter::new(File::create(to)?);
        write!(
            out,
            "ply\n\
             format binary_little_endian 1.0\n\
             comment radiosity solution: per-vertex exitant radiance (linear) and tone-mapped sRGB colour\n\
             element vertex {}\n\
             property float x\nproperty float y\nproperty float z\n\
             property float nx\nproperty float ny\nproperty float nz\n\
             property uchar red\nproperty uchar green\nproperty uchar blue\n\
             property float radiance_r\nproperty float radiance_g\nproperty float radiance_b\n\
             element face {}\n\
             property list uchar uint vertex_indices\n\
             end_header\n",
            mesh.positions.len(),
            mesh.triangles.len()
        )?;
        for i in 0..mesh.positions.len() {
            let (p, n, c) = (mesh.positions[i], mesh.normals[i], mesh.radiance[i]);
            for x in [p.x, p.y, p.z, n.x, n.y, n.z] {
                out.write_all(&(x as f32).to_le_bytes())?;
            }
            out.write_all(&rgb8(tone.display_linear(c, scale)))?;
            for x in c.to_array() {
                out.write_all(&(x as f32).to_le_bytes())?;
            }
        }
        for t in &mesh.triangles {
            out.write_all(&[3u8])?;
            for &i in t {
                out.write_all(&i.to_le_bytes())?;
            }
        }
        out.flush()
    };
    super::write_atomically(path, |to| {
        write(to).with_context(|| format!("writing {}", path.display()))
    })
}

const GLB_MAGIC: u32 = 0x4654_6C67; // "glTF"
const CHUNK_JSON: u32 = 0x4E4F_534A; // "JSON"
const CHUNK_BIN: u32 = 0x004E_4942; // "BIN\0"
const ARRAY_BUFFER: u32 = 34962;
const ELEMENT_ARRAY_BUFFER: u32 = 34963;
const FLOAT: u32 = 5126;
const UNSIGNED_INT: u32 = 5125;

/// Writes the leaves as binary glTF 2.0 (`.glb`): one mesh with POSITION, NORMAL, COLOR_0 (display-linear
/// float RGB: exposure and tone curve applied, no sRGB encoding, as glTF specifies) and an unlit material
/// (KHR_materials_unlit), so that viewers show the radiosity without relighting it.
pub fn write_glb(
    path: &Path,
    hierarchy: &Hierarchy,
    vertices: &VertexRadiosity,
    tone: &ToneMap,
) -> Result<()> {
    let mesh = vertices.mesh(hierarchy);
    if mesh.triangles.is_empty() {
        bail!(
            "writing {}: the scene has no surfaces to export",
            path.display()
        );
    }
    let bytes = glb_bytes(&mesh, tone);
    super::write_atomically(path, |to| {
        std::fs::write(to, &bytes).with_context(|| format!("writing {}", path.display()))
    })
}

/// The whole `.glb` file in memory.
fn glb_bytes(mesh: &ShadedMesh, tone: &ToneMap) -> Vec<u8> {
    let scale = tone.exposure_scale(mesh.radiance.iter().copied());
    let n = mesh.positions.len();
    let mut bin: Vec<u8> = Vec::with_capacity(n * 36 + mesh.triangles.len() * 12);
    let push_vec3 = |bin: &mut Vec<u8>, v: [f64; 3]| {
        for x in v {
            bin.extend_from_slice(&(x as f32).to_le_bytes());
        }
    };
    for p in &mesh.positions {
        push_vec3(&mut bin, p.to_array());
    }
    for v in &mesh.normals {
        push_vec3(&mut bin, v.to_array());
    }
    for c in &mesh.radiance {
        push_vec3(&mut bin, tone.display_linear(*c, scale).to_array());
    }
    for t in &mesh.triangles {
        for i in t {
            bin.extend_from_slice(&i.to_le_bytes());
        }
    }
    let vec3_bytes = n * 12;
    let index_bytes = mesh.triangles.len() * 12;
    // Bounds of the f32 positions as stored (POSITION requires min and max).
    let mut min = [f32::INFINITY; 3];
    let mut max = [f32::NEG_INFINITY; 3];
    for p in &mesh.positions {
        for k in 0..3 {
            let x = p[k] as f32;
            min[k] = min[k].min(x);
            max[k] = max[k].max(x);
        }
    }
    let view = |offset: usize, length: usize, target: u32| json!({"buffer": 0, "byteOffset": offset, "byteLength": length, "target": target});
    let gltf = json!({
        "asset": {"version": "2.0", "generator": "radiosity"},
        "extensionsUsed": ["KHR_materials_unlit"],
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "name": "radiosity"}],
        "meshes": [{"primitives": [{
            "attributes": {"POSITION": 0, "NORMAL": 1, "COLOR_0": 2},
            "indices": 3,
            "material": 0,
            "mode": 4
        }]}],
        "materials": [{
            "name": "radiosity (unlit)",
            "pbrMetallicRoughness": {
                "baseColorFactor": [1.0, 1.0, 1.0, 1.0],
                "metallicFactor": 0.0,
                "roughnessFactor": 1.0
            },
            "extensions": {"KHR_materials_unlit": {}}
        }],
        "buffers": [{"byteLength": bin.len()}],
        "bufferViews": [
            view(0, vec3_bytes, ARRAY_BUFFER),
            view(vec3_bytes, vec3_bytes, ARRAY_BUFFER),
            view(2 * vec3_bytes, vec3_bytes, ARRAY_BUFFER),
            view(3 * vec3_bytes, index_bytes, ELEMENT_ARRAY_BUFFER),
        ],
        "accessors": [
            {"bufferView": 0, "componentType": FLOAT, "count": n, "type": "VEC3",
             "min": min, "max": max},
            {"bufferView": 1, "componentType": FLOAT, "count": n, "type": "VEC3"},
            {"bufferView": 2, "componentType": FLOAT, "count": n, "type": "VEC3"},
            {"bufferView": 3, "componentType": UNSIGNED_INT, "count": mesh.triangles.len() * 3,
             "type": "SCALAR"},
        ],
    });
    let mut json_chunk = gltf.to_string().into_bytes();
    // Chunks are 4-byte aligned: JSON padded with spaces, binary with zeros.
    while !json_chunk.len().is_multiple_of(4) {
        json_chunk.push(b' ');
    }
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let total = 12 + 8 + json_chunk.len() + 8 + bin.len();
    let mut out = Vec::with_capacity(total);
    for word in [
        GLB_MAGIC,
        2,
        total as u32,
        json_chunk.len() as u32,
        CHUNK_JSON,
    ] {
        out.extend_from_slice(&word.to_le_bytes());
    }
    out.extend_from_slice(&json_chunk);
    for word in [bin.len() as u32, CHUNK_BIN] {
        out.extend_from_slice(&word.to_le_bytes());
    }
    out.extend_from_slice(&bin);
    out
}
