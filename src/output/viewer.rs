//! The interactive viewer: one self-contained HTML page (inline hand-written WebGL, no library, no
//! network, no server) that shows the illuminated leaf elements with orbit, pan, zoom and walk controls.
//!
//! Vertices carry *linear* radiance and the fragment shader applies exactly the PNG pipeline's tone
//! mapping ([`super::tonemap`]: the exposure multiplier, the tone curve, the sRGB transfer function), with
//! the exposure the PNG used embedded as a number; the initial view is the render [`Camera`] (eye,
//! direction, up, vertical field of view; the aspect follows the window). So the page at load, in a window
//! of the PNG's size, shows the PNG up to rasterisation: pixel centres are the same samples, and a
//! primary ray and the rasteriser interpolate the same per-triangle values.
//!
//! Shading follows `render --shading`: `basis` samples each leaf's expansion (Bekaert–Willems §2) on a
//! grid of `max(1, degree)` cells per edge (exact for constant and linear bases on triangles and
//! parallelograms, whose parametrisation is affine; piecewise linear otherwise), `flat` draws the leaf
//! averages, `smooth` the crack-free vertex values of [`VertexRadiosity`] (as PLY/GLB export does),
//! `continuous` the expansion with its jumps at edges removed, on the grid of `basis`.
//! Elements keep their own vertices in `basis` and `flat`, so discontinuities between them stay; a leaf
//! with T-vertices (a smaller neighbour's corner inside one of its edges) is a fan from its centre
//! through its whole outline instead, so that no crack opens where the neighbours meet it (again exact
//! for the linear basis on a parallelogram).

use super::camera::Camera;
use super::mesh_values::VertexRadiosity;
use super::render::Shading;
use super::tonemap::Curve;
use crate::color::Rgb;
use crate::geometry::{DVec2, DVec3, Domain, Shape};
use crate::hierarchy::{ElementId, Hierarchy};
use anyhow::{Context, Result};
use serde_json::json;
use std::path::Path;

/// Default triangle budget of a page: about 60 bytes per triangle, 80 after base64 (the Cornell box at
/// the default settings: 8179 triangles, 657 kB), so that a page stays below about 100 MB.
pub const DEFAULT_MAX_TRIANGLES: usize = 1_250_000;

/// The page's HTML, CSS and JavaScript, with `@NAME@` markers for the data.
const TEMPLATE: &str = include_str!("viewer.html");

/// The triangles the page draws: positions relative to `origin` (the centre of the scene's bounds, so
/// that single precision keeps sub-millimetre detail in a large model), linear exitant radiance per
/// vertex, triangles counter-clockwise seen from their radiating side.
#[derive(Clone, Debug, Default)]
pub struct ViewerMesh {
    pub origin: DVec3,
    /// Half the diagonal of the scene's bounds.
    pub radius: f64,
    pub positions: Vec<[f32; 3]>,
    pub radiance: Vec<[f32; 3]>,
    pub triangles: Vec<[u32; 3]>,
}

/// What the page shows at load, besides the mesh.
#[derive(Clone, Copy, Debug)]
pub struct Page<'a> {
    /// Shown in the title bar.
    pub title: &'a str,
    /// The initial view (reset with `R`).
    pub camera: &'a Camera,
    pub curve: Curve,
    /// Radiance multiplier before the tone curve: the one the PNG of this view used
    /// ([`super::tonemap::ToneMap::exposure_scale`] of its pixels), so that both agree.
    pub exposure: f64,
    /// Recorded in the page (the help panel says which).
    pub shading: Shading,
}

impl ViewerMesh {
    /// The leaf elements of `hierarchy` shaded as `shading` says (see the module documentation);
    /// `vertices` is reused for smooth shading when given. Refuses more than `max_triangles` triangles.
    pub fn new(
        hierarchy: &Hierarchy,
        shading: Shading,
        vertices: Option<&VertexRadiosity>,
        max_triangles: usize,
    ) -> Result<ViewerMesh> {
        let bounds = hierarchy.patch_bounds();
        anyhow::ensure!(
            !bounds.is_empty(),
            "the scene has no surfaces to show in the viewer"
        );
        let mut mesh = ViewerMesh {
            origin: bounds.center(),
            radius: 0.5 * bounds.diagonal(),
            ..ViewerMesh::default()
        };
        let check = |count: usize| {
            anyhow::ensure!(
                count <= max_triangles,
                "the viewer page would hold {count} triangles, more than its budget of {max_triangles} \
                 (--max-triangles): coarsen the solution (--eps, --accuracy, --max-elements) or use \
                 --shading smooth, which shares vertices"
            );
            Ok(())
        };
        let leaves = hierarchy.leaves();
        let built;
        let vertices = match vertices {
            Some(v) => v,
            None => {
                built = VertexRadiosity::new(hierarchy);
                &built
            }
        };
        match shading {
            Shading::Smooth => {
                let shaded = vertices.mesh(hierarchy);
                check(shaded.triangles.len())?;
                for (&p, &c) in shaded.positions.iter().zip(&shaded.radiance) {
                    mesh.push_vertex(p, c);
                }
                mesh.triangles = shaded.triangles;
            }
            Shading::Flat | Shading::Basis | Shading::Continuous | Shading::Seamless => {
                let cells = match shading {
                    Shading::Basis | Shading::Continuous | Shading::Seamless => {
                        hierarchy.basis.kind().polynomial_degree().max(1)
                    }
                    _ => 1,
                };
                let per_leaf = |leaf: ElementId| match vertices.outline(leaf) {
                    Some(outline) => outline.len(),
                    None => match hierarchy.element(leaf).shape().domain() {
                        Domain::Triangle => cells * cells,
                        Domain::Square => 2 * cells * cells,
                    },
                };
                let count = leaves
                    .iter()
                    .map(|&l| per_leaf(l))
                    .try_fold(0usize, usize::checked_add)
                    .unwrap_or(usize::MAX);
                check(count)?;
                mesh.triangles.reserve(count);
                for &leaf in &leaves {
                    let element = hierarchy.element(leaf);
                    // The expansion itself, not clamped: the page interpolates these vertex values
                    // and clamps per pixel, as the PNG render clamps the expansion at each pixel.
                    let value = |uv: DVec2| match shading {
                        Shading::Basis => hierarchy.radiance_at_parameters(leaf, uv),
                        Shading::Continuous | Shading::Seamless => {
                            let p = hierarchy.element(leaf).shape().point_at(uv);
                            let below = shading.steps_removed_below().unwrap_or(0.0);
                            vertices.evaluate_continuous(hierarchy, leaf, p, below)
                        }
                        _ => hierarchy.average_radiance(leaf),
                    };
                    let shape = element.shape();
                    match vertices.outline(leaf) {
                        Some(outline) => {
                            let points = outline
                                .iter()
                                .map(|&v| vertices.vertex_position(v as usize));
                            mesh.push_fan(shape, points, value);
                        }
                        None => mesh.push_grid(shape, cells, value),
                    }
                }
            }
        }
        mesh.push_openings(hierarchy);
        Ok(mesh)
    }

    /// The luminaires' openings, which have no patches: each face at its luminance along its normal
    /// (outward, or toward the nadir for a flat opening), I(n)/A_proj(n)
    /// ([`crate::scene::luminaire::Luminaire::luminance`]),
    /// since the page shades per vertex and not per direction; so that the fixture shows as in the
    /// PNG seen from its main direction rather than as a hole.
    fn push_openings(&mut self, hierarchy: &Hierarchy) {
        for luminaire in &hierarchy.luminaires {
            for face in &luminaire.faces {
                let radiance = luminaire.luminance(face.normal());
                let first = self.positions.len() as u32;
                for &v in face.vertices() {
                    self.push_vertex(v, radiance);
                }
                for k in 1..face.vertices().len() as u32 - 1 {
                    self.triangles.push([first, first + k, first + k + 1]);
                }
            }
        }
    }

    fn push_vertex(&mut self, p: DVec3, radiance: Rgb) {
        let p = p - self.origin;
        self.positions.push([p.x as f32, p.y as f32, p.z as f32]);
        self.radiance.push(radiance.to_f32());
    }

    /// A `cells` × `cells` grid in the parameter domain of `shape` (the triangle's grid of lines parallel
    /// to its edges, the quad's bilinear grid), with `value` at each grid point.
    fn push_grid(&mut self, shape: &Shape, cells: usize, value: impl Fn(DVec2) -> Rgb) {
        let first = self.positions.len() as u32;
        let step = 1.0 / cells as f64;
        let n = cells as u32;
        match shape.domain() {
            Domain::Triangle => {
                // Row j holds n + 1 - j points (i + j <= n); `index` is the point's number.
                let row_start = |j: u32| j * (n + 1) - j * (j.saturating_sub(1)) / 2;
                let index = |i: u32, j: u32| first + row_start(j) + i;
                for j in 0..=n {
                    for i in 0..=(n - j) {
                        let uv = DVec2::new(i as f64 * step, j as f64 * step);
                        self.push_vertex(shape.point_at(uv), value(uv));
                    }
                }
                for j in 0..n {
                    for i in 0..(n - j) {
                        self.triangles
                            .push([index(i, j), index(i + 1, j), index(i, j + 1)]);
                        if i + j + 1 < n {
                            self.triangles.push([
                                index(i + 1, j),
                                index(i + 1, j + 1),
                                index(i, j + 1),
                            ]);
                        }
                    }
                }
            }
            Domain::Square => {
                let index = |i: u32, j: u32| first + j * (n + 1) + i;
                for j in 0..=n {
                    for i in 0..=n {
                        let uv = DVec2::new(i as f64 * step, j as f64 * step);
                        self.push_vertex(shape.point_at(uv), value(uv));
                    }
                }
                // Split along the (0,0)-(1,1) diagonal of each cell, as the smooth mesh splits quads.
                for j in 0..n {
                    for i in 0..n {
                        let (a, b) = (index(i, j), index(i + 1, j));
                        let (c, d) = (index(i + 1, j + 1), index(i, j + 1));
                        self.triangles.push([a, b, c]);
                        self.triangles.push([a, c, d]);
                    }
                }
            }
        }
    }

    /// A fan from the centre of `shape` through its `outline` (counter-clockwise points on its edges),
    /// with `value` at the parameters of each point.
    fn push_fan(
        &mut self,
        shape: &Shape,
        outline: impl ExactSizeIterator<Item = DVec3>,
        value: impl Fn(DVec2) -> Rgb,
    ) {
        let centre = match shape.domain() {
            Domain::Triangle => DVec2::splat(1.0 / 3.0),
            Domain::Square => DVec2::splat(0.5),
        };
        let first = self.positions.len() as u32;
        let n = outline.len() as u32;
        self.push_vertex(shape.point_at(centre), value(centre));
        for p in outline {
            self.push_vertex(p, value(shape.parameters_of(p)));
        }
        for k in 0..n {
            self.triangles
                .push([first, first + 1 + k, first + 1 + (k + 1) % n]);
        }
    }

    /// Linear radiance of every vertex (for an exposure computed from the model, as PLY/GLB export does).
    pub fn vertex_radiance(&self) -> impl Iterator<Item = Rgb> + '_ {
        self.radiance
            .iter()
            .map(|c| Rgb::new(f64::from(c[0]), f64::from(c[1]), f64::from(c[2])))
    }
}

/// Writes the page through [`super::write_atomically`].
pub fn write_page(path: &Path, mesh: &ViewerMesh, page: &Page) -> Result<()> {
    let html = page_html(mesh, page)?;
    super::write_atomically(path, |to| {
        std::fs::write(to, &html).with_context(|| format!("writing {}", path.display()))
    })
}

/// The whole page as one string.
pub fn page_html(mesh: &ViewerMesh, page: &Page) -> Result<String> {
    anyhow::ensure!(
        page.exposure.is_finite() && page.exposure > 0.0,
        "the viewer's exposure must be a positive number"
    );
    let camera = page.camera;
    let eye = camera.eye - mesh.origin;
    // Orbit pivot: the point straight ahead as far away as the scene's centre (the radius when the
    // centre lies behind or beside the eye).
    let ahead = (-eye).dot(camera.forward());
    let distance = if ahead > 0.1 * mesh.radius {
        ahead
    } else {
        mesh.radius.max(1e-9)
    };
    let target = eye + camera.forward() * distance;
    let curve = match page.curve {
        Curve::Linear => 0,
        Curve::Reinhard => 1,
        Curve::Filmic => 2,
    };
    let shading = match page.shading {
        Shading::Basis => "basis",
        Shading::Flat => "flat",
        Shading::Smooth => "smooth",
        Shading::Continuous => "continuous",
        Shading::Seamless => "seamless",
    };
    let config = json!({
        "title": page.title,
        "eye": eye.to_array(),
        "target": target.to_array(),
        "up": camera.up().to_array(),
        "sky": camera.sky().to_array(),
        "fov": camera.vertical_fov_degrees(),
        "exposure": page.exposure,
        "curve": curve,
        "shading": shading,
        "radius": mesh.radius,
        "vertices": mesh.positions.len(),
        "triangles": mesh.triangles.len(),
    });
    // `<` escaped so that no string in the JSON can close the script element.
    let config = config.to_string().replace('<', "\\u003c");
    let positions = base64(
        mesh.positions
            .iter()
            .flatten()
            .flat_map(|x| x.to_le_bytes()),
    );
    let radiance = base64(mesh.radiance.iter().flatten().flat_map(|x| x.to_le_bytes()));
    let indices = base64(
        mesh.triangles
            .iter()
            .flatten()
            .flat_map(|i| i.to_le_bytes()),
    );
    let mut html = String::with_capacity(
        TEMPLATE.len() + config.len() + positions.len() + radiance.len() + indices.len(),
    );
    let mut rest = TEMPLATE;
    while let Some(start) = rest.find('@') {
        html.push_str(&rest[..start]);
        let after = &rest[start + 1..];
        let end = after
            .find('@')
            .context("viewer template: unclosed marker")?;
        match &after[..end] {
            "TITLE" => html.push_str(&escape_html(page.title)),
            "CURVE" => html.push_str(&curve.to_string()),
            "CONFIG" => html.push_str(&config),
            "POSITIONS" => html.push_str(&positions),
            "RADIANCE" => html.push_str(&radiance),
            "INDICES" => html.push_str(&indices),
            other => anyhow::bail!("viewer template: unknown marker @{other}@"),
        }
        rest = &after[end + 1..];
    }
    html.push_str(rest);
    Ok(html)
}

/// Text as HTML character data.
fn escape_html(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// Standard base64 with padding (RFC 4648 §4), what the page's `atob` decodes.
fn base64(bytes: impl Iterator<Item = u8>) -> String {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::new();
    let mut bytes = bytes.peekable();
    while bytes.peek().is_some() {
        let chunk: Vec<u8> = bytes.by_ref().take(3).collect();
        let word = chunk
            .iter()
            .enumerate()
            .fold(0u32, |w, (k, &b)| w | u32::from(b) << (16 - 8 * k));
        for k in 0..4 {
            if k <= chunk.len() {
                out.push(ALPHABET[(word >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_matches_rfc_4648_test_vectors() {
        for (plain, encoded) in [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ] {
            assert_eq!(base64(plain.bytes()), encoded);
        }
        assert_eq!(base64([0xffu8, 0xfe, 0xfd].into_iter()), "//79");
    }

    #[test]
    fn html_escaping() {
        assert_eq!(escape_html("a<b>&\"c\""), "a&lt;b&gt;&amp;&quot;c&quot;");
    }
}
