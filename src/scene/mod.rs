//! Scene model: planar convex polygons with Lambertian materials, grouped into named objects, and the
//! loaders that build it (MGF, OBJ/MTL, glTF 2.0, the built-in Cornell box).
//!
//! Units: reflectance is a fraction per channel (< 1); emission is the emitted *radiance*
//! L_e in W/(m² sr) (radiant exitance is π L_e). Radiosity is solved as exitant radiance throughout, so
//! a closed box of reflectance ρ emitting L_e everywhere converges to L_e / (1 - ρ).

pub mod contacts;
pub mod cornell;
pub mod duplicates;
pub mod generators;
pub mod gltf;
pub mod ies;
pub mod luminaire;
pub mod mgf;
pub mod obj;
pub mod polygonize;
pub mod texture;

use crate::color::Rgb;
use crate::geometry::{Aabb, DVec3, Shape};
use std::collections::HashMap;
use std::f64::consts::PI;
use std::fmt;
use std::path::{Path, PathBuf};

/// A Lambertian material.
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    pub name: String,
    /// Diffuse reflectance ρ per channel, each in [0, 1).
    pub reflectance: Rgb,
    /// Emitted radiance L_e per channel, W/(m² sr).
    pub emission: Rgb,
    /// Whether surfaces made of it reflect and emit on both sides (MGF `sides 2`).
    pub two_sided: bool,
}

impl Material {
    pub fn diffuse(name: &str, reflectance: Rgb) -> Self {
        Material {
            name: name.to_string(),
            reflectance,
            emission: Rgb::BLACK,
            two_sided: false,
        }
    }

    pub fn emitter(name: &str, reflectance: Rgb, emission: Rgb) -> Self {
        Material {
            name: name.to_string(),
            reflectance,
            emission,
            two_sided: false,
        }
    }
}

/// A planar convex input polygon: the root of an element quadtree (two roots when two-sided).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Polygon {
    pub shape: Shape,
    pub material: usize,
    pub object: usize,
    /// Both sides are surfaces: the radiosity mesh of a two-sided polygon is two meshes.
    pub two_sided: bool,
    /// A piece of a larger surface cut out inside the outline of an object that touches or nearly
    /// touches it ([`contacts::split_contacts`]: the ceiling over a lamp hung under it, the floor
    /// under a block). Radiance jumps across such an outline and nowhere else on a flat surface of
    /// one material, so continuous shading keeps the step there
    /// ([`crate::output::VertexRadiosity::evaluate_continuous`]).
    pub under_contact: bool,
}

/// A named group of polygons (MGF `o`, OBJ object or group).
#[derive(Clone, Debug, PartialEq)]
pub struct Object {
    pub name: String,
}

/// A camera stored with a scene (the built-in Cornell box has the published one; MGF has none).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraSpec {
    pub eye: DVec3,
    pub look_at: DVec3,
    pub up: DVec3,
    /// Vertical field of view in degrees.
    pub fov_degrees: f64,
}

/// A problem found while reading input: file, line and reason.
#[derive(Clone, Debug, PartialEq)]
pub struct Diagnostic {
    pub file: PathBuf,
    /// 1-based; 0 for the file as a whole (it cannot be read, or its format has no lines: glTF).
    pub line: usize,
    pub message: String,
}

impl fmt::Display for Diagnostic {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let file = sanitise(&self.file.display().to_string(), MAX_SHOWN_CHARS);
        if self.line == 0 {
            write!(f, "{file}: ")?;
        } else {
            write!(f, "{file}:{}: ", self.line)?;
        }
        f.write_str(&sanitise(&self.message, MAX_SHOWN_CHARS))
    }
}

/// Warnings of one kind shown in full when a scene is loaded for solving; the rest are counted.
pub const WARNINGS_SHOWN_PER_KIND: usize = 3;

/// The lines to print for `warnings`: at most `shown` of each kind (the same message but for its
/// numbers: the classroom has 576 non-planar polygons, whose warnings buried everything else), each
/// kind's rest as one line naming how many and where the last lies. `radiosity info` lists them all.
pub fn grouped_warnings(warnings: &[Diagnostic], shown: usize) -> Vec<String> {
    let kind = |message: &str| {
        let mut key = String::new();
        for c in message.chars() {
            if c.is_ascii_digit() || c == '.' {
                if !key.ends_with('#') {
                    key.push('#');
                }
            } else {
                key.push(c);
            }
        }
        key
    };
    // Kinds in order of first appearance, found by hash (a file may hold many kinds: one per
    // unknown material name).
    let mut index: HashMap<String, usize> = HashMap::new();
    let mut kinds: Vec<Vec<&Diagnostic>> = Vec::new();
    for warning in warnings {
        let next = kinds.len();
        let k = *index.entry(kind(&warning.message)).or_insert(next);
        if k == next {
            kinds.push(Vec::new());
        }
        kinds[k].push(warning);
    }
    let mut lines = Vec::new();
    for members in kinds {
        lines.extend(members.iter().take(shown).map(|w| w.to_string()));
        if let Some(last) = members.last().filter(|_| members.len() > shown) {
            let file = sanitise(&last.file.display().to_string(), MAX_SHOWN_CHARS);
            lines.push(format!(
                "{} more like the one above, the last at {file}:{} (`radiosity info` lists them all)",
                members.len() - shown,
                last.line
            ));
        }
    }
    lines
}

/// Longest file name or message shown in a diagnostic, in characters.
const MAX_SHOWN_CHARS: usize = 240;

/// Makes input text safe to echo: control characters escaped, cut to `max` characters.
pub fn sanitise(text: &str, max: usize) -> String {
    let mut out = String::new();
    for (count, c) in text.chars().enumerate() {
        if count == max {
            let rest = text.chars().count() - count;
            out.push_str(&format!("... ({rest} more characters)"));
            break;
        }
        if c.is_control() {
            out.extend(c.escape_default());
        } else {
            out.push(c);
        }
    }
    out
}

/// Most bytes of buffers and images (glTF's buffers and textures, OBJ's `map_Kd` textures) loaded for
/// one scene, in all.
pub const MAX_LOADED_BYTES: u64 = 4 * MAX_FILE_BYTES;

/// Reflectance of surfaces without a usable material (OBJ faces, glTF primitives).
pub const DEFAULT_GREY: f64 = 0.5;
/// Largest reflectance kept (the readers clamp above it with a warning): a reflectance of 1 or more
/// makes a closed room's light grow without bound.
pub const MAX_REFLECTANCE: f64 = 0.999;

/// Most polygons one scene may have (a few hundred bytes each before meshing).
pub const MAX_POLYGONS: usize = 1_000_000;

/// Largest scene, material or include file read (bytes): bigger inputs are refused, not exhausted.
/// Room for [`MAX_POLYGONS`] as MGF: the million-polygon box hall (`radiosity scene box-hall
/// --polygons 1000000`) is 100 MB.
pub const MAX_FILE_BYTES: u64 = 256 << 20;

/// Reads a regular file of at most [`MAX_FILE_BYTES`]; devices, pipes and directories are refused.
pub fn read_bounded(path: &Path) -> Result<Vec<u8>, String> {
    use std::io::Read;
    let meta = std::fs::metadata(path).map_err(|e| format!("cannot read file: {e}"))?;
    if !meta.is_file() {
        return Err("cannot read file: not a regular file".into());
    }
    let too_big = || format!("file larger than {} MiB refused", MAX_FILE_BYTES >> 20);
    if meta.len() > MAX_FILE_BYTES {
        return Err(too_big());
    }
    let file = std::fs::File::open(path).map_err(|e| format!("cannot read file: {e}"))?;
    let mut bytes = Vec::with_capacity(meta.len() as usize);
    file.take(MAX_FILE_BYTES + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| format!("cannot read file: {e}"))?;
    if bytes.len() as u64 > MAX_FILE_BYTES {
        return Err(too_big());
    }
    Ok(bytes)
}

/// A fatal error reading a scene, with file, line and reason.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct SceneError(pub Diagnostic);

impl SceneError {
    pub fn new(file: impl Into<PathBuf>, line: usize, message: impl Into<String>) -> Self {
        SceneError(Diagnostic {
            file: file.into(),
            line,
            message: message.into(),
        })
    }
}

/// How a scene is read.
#[derive(Clone, Debug)]
pub struct LoadOptions {
    /// Make every surface two-sided, whatever the file says.
    pub force_two_sided: bool,
    /// Make every surface one-sided (front by winding), whatever the file says. MGF's default is two
    /// sides; `cube.mgf`'s light hangs 1 cm below the ceiling and, two-sided, shines half its power into
    /// that gap.
    pub force_one_sided: bool,
    /// Quality of curved MGF solids: segments per full circle. A cylinder, cone or ring becomes this
    /// many quads, a sphere half as many latitude bands of this many, a torus its square. The default 16
    /// (4 per quarter circle, RenderPark's setting) loses about 2.6% of a sphere's area; 64 loses 0.16%.
    /// Values below 3 are read as 3. See [`mgf::solids`].
    pub tessellation: usize,
    /// Keep exact duplicate polygons (see [`duplicates`]) instead of one of each, and coplanar
    /// overlaps instead of one surface where they overlap (see [`contacts::remove_covered`]).
    pub keep_duplicates: bool,
}

impl Default for LoadOptions {
    fn default() -> Self {
        LoadOptions {
            force_two_sided: false,
            force_one_sided: false,
            tessellation: 16,
            keep_duplicates: false,
        }
    }
}

/// A scene ready for lighting simulation.
#[derive(Clone, Debug, Default)]
pub struct Scene {
    pub polygons: Vec<Polygon>,
    pub materials: Vec<Material>,
    pub objects: Vec<Object>,
    pub camera: Option<CameraSpec>,
    /// Warnings collected while loading (ignored entities, dropped degenerate polygons, ...).
    pub warnings: Vec<Diagnostic>,
    /// Every file the scene was read from (the scene, its includes, material libraries, buffers,
    /// images, photometric files it names), canonical where possible: no output may overwrite one.
    pub sources: Vec<PathBuf>,
    /// Where each polygon was read (file or include chain, and line), for messages about polygons.
    pub origins: duplicates::Origins,
    /// Goniometric light sources (IES luminaires: MGF `ies`, `--luminaire`).
    pub luminaires: Vec<luminaire::Luminaire>,
}

impl Scene {
    pub fn material_of(&self, polygon: &Polygon) -> &Material {
        &self.materials[polygon.material]
    }

    /// Whether `polygon`'s object or material name matches `pattern`, in which `*` stands for any run
    /// of characters (`desk*`, `*glass*`): how options name surfaces (`--feature-size-for`).
    pub fn polygon_named(&self, polygon: &Polygon, pattern: &str) -> bool {
        let object = self.objects.get(polygon.object).map(|o| o.name.as_str());
        let material = self
            .materials
            .get(polygon.material)
            .map(|m| m.name.as_str());
        [object, material]
            .into_iter()
            .flatten()
            .any(|name| matches_pattern(pattern, name))
    }

    /// Total surface area of the input polygons (each polygon counted once, whatever its sidedness).
    pub fn total_area(&self) -> f64 {
        self.polygons.iter().map(|p| p.shape.area()).sum()
    }

    pub fn bounds(&self) -> Aabb {
        self.polygons
            .iter()
            .fold(Aabb::EMPTY, |b, p| b.union(&p.shape.bounds()))
    }

    /// Total emitted power Φ = Σ π L_e A over emitting sides, plus the luminaires' flux (W per
    /// channel).
    pub fn emitted_power(&self) -> Rgb {
        let surfaces: Rgb = self
            .polygons
            .iter()
            .map(|p| {
                let sides = if p.two_sided { 2.0 } else { 1.0 };
                self.material_of(p).emission * (PI * p.shape.area() * sides)
            })
            .sum();
        surfaces + self.luminaires.iter().map(|l| l.power()).sum::<Rgb>()
    }

    /// Polygons whose material emits.
    pub fn emitter_count(&self) -> usize {
        self.polygons
            .iter()
            .filter(|p| !self.material_of(p).emission.is_black())
            .count()
    }

    /// Adds a luminaire and its opening's faces as black, two-sided polygons of an object of its own
    /// (they occlude, reflect nothing, and renderers draw them at the luminaire's luminance).
    pub fn add_luminaire(&mut self, mut luminaire: luminaire::Luminaire) {
        if !luminaire.faces.is_empty() {
            let name = "luminaire opening";
            let material =
                match self.materials.iter().position(|m| {
                    m.name == name && m.reflectance.is_black() && m.emission.is_black()
                }) {
                    Some(m) => m,
                    None => {
                        self.materials.push(Material::diffuse(name, Rgb::BLACK));
                        self.materials.len() - 1
                    }
                };
            let object = self.objects.len();
            self.objects.push(Object {
                name: format!(
                    "luminaire {} ({})",
                    self.luminaires.len() + 1,
                    luminaire.photometry.file.display()
                ),
            });
            self.polygons
                .extend(luminaire.faces.iter().map(|&shape| Polygon {
                    shape,
                    material,
                    object,
                    two_sided: true,
                    under_contact: false,
                }));
            luminaire.object = Some(object);
        }
        self.luminaires.push(luminaire);
    }

    /// For each polygon, the index of the luminaire whose opening it is (see [`Scene::add_luminaire`]).
    pub fn opening_luminaires(&self) -> Vec<Option<u32>> {
        let mut of_object = vec![None; self.objects.len()];
        for (k, l) in self.luminaires.iter().enumerate() {
            if let Some(slot) = l.object.and_then(|o| of_object.get_mut(o)) {
                *slot = Some(k as u32);
            }
        }
        self.polygons
            .iter()
            .map(|p| of_object.get(p.object).copied().flatten())
            .collect()
    }

    /// Makes every polygon two-sided or one-sided (the `--two-sided` / `--one-sided` overrides).
    pub fn set_two_sided(&mut self, two_sided: bool) {
        for p in &mut self.polygons {
            p.two_sided = two_sided;
        }
    }
}

/// Reads a scene, choosing the reader by extension (`.mgf`, `.obj`, `.gltf`, `.glb`).
pub fn load(path: &Path, options: &LoadOptions) -> Result<Scene, SceneError> {
    let extension = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    let mut scene = match extension.as_str() {
        "mgf" => mgf::load(path, options)?,
        "obj" => obj::load(path, options)?,
        "gltf" | "glb" => gltf::load(path, options)?,
        other => {
            let what = if path.is_dir() {
                "a directory, not a scene file".to_string()
            } else if other.is_empty() {
                "no file extension to tell its format".to_string()
            } else {
                format!("unknown scene format '.{other}'")
            };
            return Err(SceneError::new(
                path,
                0,
                format!("{what} (expected .mgf, .obj, .gltf or .glb)"),
            ));
        }
    };
    if options.force_two_sided || options.force_one_sided {
        scene.set_two_sided(options.force_two_sided);
    }
    if !options.keep_duplicates {
        duplicates::remove_duplicates(&mut scene);
        contacts::remove_covered(&mut scene);
    }
    Ok(scene)
}

/// Counts and totals describing a scene (printed by the `info` command).
#[derive(Clone, Debug, PartialEq)]
pub struct SceneSummary {
    pub polygons: usize,
    pub triangles: usize,
    pub quads: usize,
    pub two_sided: usize,
    pub objects: usize,
    pub materials: usize,
    /// Total area of the input polygons, each counted once (scene units squared).
    pub total_area: f64,
    pub bounds: Aabb,
    /// Polygons whose material emits.
    pub emitters: usize,
    /// IES luminaires.
    pub luminaires: usize,
    /// Their flux ∫ I dΩ from the intensity tables (lm, multipliers applied), and the lamps' rated
    /// lumens × multipliers where every file gives them (not for absolute photometry).
    pub luminaire_lumens: f64,
    pub rated_lumens: Option<f64>,
    /// Φ = Σ π L_e A over emitting sides plus the luminaires' flux, per channel.
    pub emitted_power: Rgb,
    pub warnings: usize,
}

/// Summarises a scene: polygon, object and material counts, area, bounds and emission.
pub fn summary(scene: &Scene) -> SceneSummary {
    let triangles = scene
        .polygons
        .iter()
        .filter(|p| p.shape.vertex_count() == 3)
        .count();
    SceneSummary {
        polygons: scene.polygons.len(),
        triangles,
        quads: scene.polygons.len() - triangles,
        two_sided: scene.polygons.iter().filter(|p| p.two_sided).count(),
        objects: scene.objects.len(),
        materials: scene.materials.len(),
        total_area: scene.total_area(),
        bounds: scene.bounds(),
        emitters: scene.emitter_count(),
        luminaires: scene.luminaires.len(),
        luminaire_lumens: scene
            .luminaires
            .iter()
            .map(|l| l.photometry.flux() * l.multiplier)
            .sum(),
        rated_lumens: scene
            .luminaires
            .iter()
            .map(|l| Some(l.photometry.rated_lumens()? * l.multiplier))
            .sum(),
        emitted_power: scene.emitted_power(),
        warnings: scene.warnings.len(),
    }
}

impl fmt::Display for SceneSummary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "polygons:      {} ({} triangles, {} quads; {} two-sided)",
            self.polygons, self.triangles, self.quads, self.two_sided
        )?;
        writeln!(f, "objects:       {}", self.objects)?;
        writeln!(f, "materials:     {}", self.materials)?;
        writeln!(f, "total area:    {:.6}", self.total_area)?;
        if self.bounds.is_empty() {
            writeln!(f, "bounds:        empty")?;
        } else {
            let (lo, hi) = (self.bounds.min, self.bounds.max);
            writeln!(
                f,
                "bounds:        ({:.4}, {:.4}, {:.4}) .. ({:.4}, {:.4}, {:.4})",
                lo.x, lo.y, lo.z, hi.x, hi.y, hi.z
            )?;
        }
        writeln!(f, "emitters:      {}", self.emitters)?;
        write!(f, "luminaires:    {}", self.luminaires)?;
        if self.luminaires > 0 {
            write!(f, " ({:.1} lm from the tables", self.luminaire_lumens)?;
            match self.rated_lumens {
                Some(rated) if rated > 0.0 => write!(
                    f,
                    "; lamps rated {rated:.1} lm, efficiency {:.1}%",
                    100.0 * self.luminaire_lumens / rated
                )?,
                Some(rated) => write!(f, "; lamps rated {rated:.1} lm")?,
                None => write!(f, "; absolute photometry, no lamp rating")?,
            }
            write!(f, ")")?;
        }
        writeln!(f)?;
        let p = self.emitted_power;
        writeln!(f, "emitted power: ({:.6}, {:.6}, {:.6}) W", p.r, p.g, p.b)?;
        write!(f, "warnings:      {}", self.warnings)
    }
}

/// Whether `name` matches `pattern`, where each `*` matches any run of characters (none included) and
/// everything else itself.
fn matches_pattern(pattern: &str, name: &str) -> bool {
    let mut parts = pattern.split('*');
    let first = parts.next().unwrap_or("");
    let Some(mut rest) = name.strip_prefix(first) else {
        return false;
    };
    let middle: Vec<&str> = parts.collect();
    let Some((last, between)) = middle.split_last() else {
        return rest.is_empty();
    };
    for part in between {
        match rest.find(part) {
            Some(at) => rest = &rest[at + part.len()..],
            None => return false,
        }
    }
    rest.len() >= last.len() && rest.ends_with(last)
}

#[cfg(test)]
mod tests {
    use super::{grouped_warnings, matches_pattern, Diagnostic};
    use std::path::PathBuf;

    #[test]
    fn warnings_of_a_kind_are_shown_a_few_times_then_counted() {
        let at = |line, message: String| Diagnostic {
            file: PathBuf::from("room.mgf"),
            line,
            message,
        };
        let mut warnings: Vec<Diagnostic> = (1..=10)
            .map(|k| at(k, format!("non-planar polygon ({}.5% off its plane)", k)))
            .collect();
        warnings.insert(2, at(40, "unknown entity 'foo': ignored".into()));
        let lines = grouped_warnings(&warnings, 3);
        assert_eq!(lines.len(), 5, "{lines:#?}");
        assert_eq!(
            lines[0],
            "room.mgf:1: non-planar polygon (1.5% off its plane)"
        );
        assert_eq!(
            lines[2],
            "room.mgf:3: non-planar polygon (3.5% off its plane)"
        );
        assert!(lines[3].starts_with("7 more like the one above, the last at room.mgf:10 "));
        assert_eq!(lines[4], "room.mgf:40: unknown entity 'foo': ignored");
        // Different words are different kinds, however alike their numbers.
        let two = [at(1, "a 1".into()), at(2, "b 1".into())];
        assert_eq!(grouped_warnings(&two, 1).len(), 2);
        assert_eq!(
            grouped_warnings(&warnings, usize::MAX).len(),
            warnings.len()
        );
    }

    #[test]
    fn patterns_match_whole_names_with_stars_for_any_run() {
        for (pattern, name) in [
            ("desk", "desk"),
            ("desk*", "desk"),
            ("desk*", "desk_top"),
            ("*top", "desk_top"),
            ("*", ""),
            ("d*k*p", "desk_top"),
            ("a*b", "ab"),
        ] {
            assert!(matches_pattern(pattern, name), "{pattern} {name}");
        }
        for (pattern, name) in [
            ("desk", "desk_top"),
            ("desk", "des"),
            ("*top", "topdesk"),
            ("a*a", "a"),
            ("d*z*p", "desk_top"),
        ] {
            assert!(!matches_pattern(pattern, name), "{pattern} {name}");
        }
    }
}
