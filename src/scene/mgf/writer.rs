//! MGF writer: any [`Scene`] as an MGF file that our reader ([`super::load`]) reads back with the same
//! polygons, reflectances and emissions.
//!
//! Colours: the reader turns a chromaticity `cxy x y` and a luminous factor (`rd`, or `ed` / (179 π) for
//! emission) into linear sRGB by a fixed linear map (see [`color`]). The writer inverts that
//! map: the XYZ of an RGB value gives the chromaticity (x, y) = (X, Y) / (X + Y + Z) and the factor Y, so
//! every RGB inside the gamut of MGF chromaticities (X, Y, Z ≥ 0, which holds for every non-negative sRGB
//! triple) reads back exactly up to floating-point rounding. Greys are written the same way rather than
//! with the neutral colour `c`, whose sRGB is white only to about 1e-4. Numbers are written in Rust's
//! shortest round-trip form.
//!
//! Structure: one `m` per (material, sidedness) pair in use, one `o` block per run of polygons of the same
//! object (a reopened object name maps back to the same object), shared vertices `v`/`p`, faces `f`. The
//! scene's camera, which MGF cannot express, is kept as a comment that the reader reads back.

use super::color;
use super::WHITE_EFFICACY;
use crate::color::Rgb;
use crate::scene::{Scene, SceneError};
use glam::DVec3;
use std::collections::{HashMap, HashSet};
use std::f64::consts::PI;
use std::fmt::Write as _;
use std::path::Path;

/// A colour as MGF states it: chromaticity (x, y) and the luminance Y that scales it (0 for black).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MgfColour {
    pub x: f64,
    pub y: f64,
    pub luminance: f64,
}

/// The chromaticity and luminance whose linear sRGB (as the reader computes it) is `rgb`. Black gives
/// luminance 0 and equal-energy white; a colour outside the CIE diagram (a negative X, Y or Z: only
/// negative or wildly out-of-gamut RGB) is an error.
pub fn mgf_colour(rgb: Rgb) -> Result<MgfColour, String> {
    if rgb.is_black() {
        return Ok(MgfColour {
            x: 1.0 / 3.0,
            y: 1.0 / 3.0,
            luminance: 0.0,
        });
    }
    if !rgb.is_finite() {
        return Err(format!("colour {rgb:?} is not finite"));
    }
    let xyz = color::from_linear_srgb(rgb);
    let sum = xyz.x + xyz.y + xyz.z;
    // Rounding can leave a component a hair below zero at the gamut boundary.
    let snap = |v: f64| {
        if v < 0.0 && v > -1e-12 * sum.abs() {
            0.0
        } else {
            v
        }
    };
    let xyz = DVec3::new(snap(xyz.x), snap(xyz.y), snap(xyz.z));
    if !(xyz.x >= 0.0 && xyz.y > 0.0 && xyz.z >= 0.0) {
        return Err(format!(
            "RGB ({}, {}, {}) has no MGF colour (CIE XYZ ({:.4}, {:.4}, {:.4}) is not in the diagram)",
            rgb.r, rgb.g, rgb.b, xyz.x, xyz.y, xyz.z
        ));
    }
    let sum = xyz.x + xyz.y + xyz.z;
    Ok(MgfColour {
        x: xyz.x / sum,
        y: xyz.y / sum,
        luminance: xyz.y,
    })
}

/// MGF names are single words: whitespace becomes `_`, an empty name `unnamed`.
fn word(name: &str) -> String {
    let w: String = name
        .chars()
        .map(|c| if c.is_whitespace() { '_' } else { c })
        .collect();
    if w.is_empty() {
        "unnamed".to_string()
    } else {
        w
    }
}

/// The scene as MGF text.
pub fn to_mgf(scene: &Scene) -> Result<String, String> {
    let mut out = String::new();
    // Writing to a String cannot fail; the results of writeln! are ignored below for that reason.
    let _ = writeln!(
        out,
        "# Written by radiosity {}: {} polygons, {} objects, {} materials.",
        env!("CARGO_PKG_VERSION"),
        scene.polygons.len(),
        scene.objects.len(),
        scene.materials.len()
    );
    if let Some(c) = &scene.camera {
        let _ = writeln!(
            out,
            "# camera: eye {} {} {} look_at {} {} {} up {} {} {} fov {}",
            c.eye.x,
            c.eye.y,
            c.eye.z,
            c.look_at.x,
            c.look_at.y,
            c.look_at.z,
            c.up.x,
            c.up.y,
            c.up.z,
            c.fov_degrees
        );
    }

    // Materials: one MGF material per (scene material, sidedness) used.
    let mut material_names: HashMap<(usize, bool), String> = HashMap::new();
    let mut taken: HashSet<String> = HashSet::new();
    for p in &scene.polygons {
        let key = (p.material, p.two_sided);
        if material_names.contains_key(&key) {
            continue;
        }
        let m = scene
            .materials
            .get(p.material)
            .ok_or_else(|| format!("polygon refers to missing material {}", p.material))?;
        let base = if p.two_sided == m.two_sided {
            word(&m.name)
        } else {
            format!("{}_{}sided", word(&m.name), if p.two_sided { 2 } else { 1 })
        };
        let mut name = base.clone();
        let mut k = 1;
        while !taken.insert(name.clone()) {
            k += 1;
            name = format!("{base}_{k}");
        }
        let rd = mgf_colour(m.reflectance).map_err(|e| format!("material '{}': {e}", m.name))?;
        let ed = mgf_colour(m.emission).map_err(|e| format!("material '{}': {e}", m.name))?;
        let _ = writeln!(out, "m {name} =");
        let _ = writeln!(out, "\tsides {}", if p.two_sided { 2 } else { 1 });
        let _ = writeln!(out, "\tc\n\t\tcxy {} {}\n\trd {}", rd.x, rd.y, rd.luminance);
        let _ = writeln!(
            out,
            "\tc\n\t\tcxy {} {}\n\ted {}",
            ed.x,
            ed.y,
            ed.luminance * WHITE_EFFICACY * PI
        );
        material_names.insert(key, name);
    }

    // Distinct objects get distinct names, since the reader merges objects of the same name.
    let mut object_names = Vec::with_capacity(scene.objects.len());
    let mut taken: HashSet<String> = HashSet::new();
    for o in &scene.objects {
        let base = word(&o.name);
        let mut name = base.clone();
        let mut k = 1;
        while !taken.insert(name.clone()) {
            k += 1;
            name = format!("{base}_{k}");
        }
        object_names.push(name);
    }

    // Geometry, in polygon order, so that the reader rebuilds the same list.
    let mut vertices: HashMap<[u64; 3], String> = HashMap::new();
    let mut object: Option<usize> = None;
    let mut material: Option<(usize, bool)> = None;
    for p in &scene.polygons {
        if object != Some(p.object) {
            if object.is_some() {
                let _ = writeln!(out, "o");
            }
            let name = object_names
                .get(p.object)
                .ok_or_else(|| format!("polygon refers to missing object {}", p.object))?;
            let _ = writeln!(out, "o {name}");
            object = Some(p.object);
        }
        let key = (p.material, p.two_sided);
        if material != Some(key) {
            let _ = writeln!(out, "m {}", material_names[&key]);
            material = Some(key);
        }
        let mut face = String::from("f");
        for v in p.shape.vertices() {
            let bits = [v.x.to_bits(), v.y.to_bits(), v.z.to_bits()];
            let next = vertices.len();
            let name = vertices.entry(bits).or_insert_with(|| {
                let name = format!("v{next}");
                let _ = writeln!(out, "v {name} =\n\tp {} {} {}", v.x, v.y, v.z);
                name
            });
            face.push(' ');
            face.push_str(name);
        }
        let _ = writeln!(out, "{face}");
    }
    if object.is_some() {
        let _ = writeln!(out, "o");
    }
    Ok(out)
}

/// Writes the scene to an MGF file, through a temporary file renamed into place: a failed write
/// leaves no truncated scene behind.
pub fn save(scene: &Scene, path: &Path) -> Result<(), SceneError> {
    let text = to_mgf(scene).map_err(|e| SceneError::new(path, 0, e))?;
    crate::output::write_atomically(path, |to| Ok(std::fs::write(to, &text)?))
        .map_err(|e| SceneError::new(path, 0, format!("cannot write: {e:#}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read_back(rgb: Rgb) -> Rgb {
        let c = mgf_colour(rgb).unwrap();
        let xyz = color::from_xy(c.x, c.y).unwrap();
        color::to_linear_srgb(xyz) * c.luminance
    }

    #[test]
    fn greys_round_trip_exactly() {
        for g in [0.0, 0.05, 0.5, 0.73, 0.999, 17.0] {
            let back = read_back(Rgb::splat(g));
            for c in back.to_array() {
                assert!((c - g).abs() <= 1e-12 * g.max(1.0), "{g}: {back:?}");
            }
        }
    }

    #[test]
    fn colours_round_trip() {
        for rgb in [
            Rgb::new(0.63, 0.065, 0.05),
            Rgb::new(0.14, 0.45, 0.091),
            Rgb::new(17.0, 12.0, 4.0),
            Rgb::new(1.0, 0.0, 0.0),
            Rgb::new(0.0, 1.0, 0.0),
            Rgb::new(0.0, 0.0, 1.0),
        ] {
            let back = read_back(rgb);
            assert!((back - rgb).max_channel().abs() < 1e-9, "{rgb:?} {back:?}");
            assert!((rgb - back).max_channel().abs() < 1e-9, "{rgb:?} {back:?}");
        }
        assert!(mgf_colour(Rgb::new(-1.0, 0.5, 0.5)).is_err());
    }

    #[test]
    fn names_are_single_words() {
        assert_eq!(word("a b\tc"), "a_b_c");
        assert_eq!(word(""), "unnamed");
    }
}
