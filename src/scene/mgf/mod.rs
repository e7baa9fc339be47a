//! MGF reader (Greg Ward's Materials and Geometry Format 1.0–2.0, the scene format of RenderPark).
//!
//! Supported: comments, `o` (objects named by their full path, "office/desk"), `xf` with every flag and
//! arrays, `i` (relative to the including file, with a transform), colours `c` `cxy` `cspec` `cct` `cmix`,
//! materials `m` `sides` `rd` `ed` (`rs` `ts` `td` are read and ignored with one warning per material,
//! `ir` is ignored), IES luminaires `ies` ([`super::ies`], [`super::luminaire`]), vertices `v` `p` `n`, faces `f` (any planar polygon, seam holes included) and `fh`
//! (MGF 2.0 face with holes), and the solids `sph` `cyl` `cone` `prism` `ring` `torus`, tessellated as
//! [`solids`] describes. Named contexts follow MGF scoping: `m name =` (re)defines, `m name` reuses,
//! the bare `m`/`c` is the default black material / neutral colour. Unknown entities are ignored with a
//! warning (as MGF prescribes); malformed known entities are errors. The comment
//! `# camera: eye x y z look_at x y z up x y z fov f` that [`writer`] leaves sets the scene camera.
//!
//! Limits (errors naming the line): files of at most [`MAX_FILE_BYTES`](super::MAX_FILE_BYTES), regular
//! files only, include cycles (reported with the include chain), include depth, entities run and
//! polygons made (see [`MAX_POLYGONS`]).
//!
//! Units: geometry keeps the file's units. Reflectance is `rd` times the colour normalised to luminance 1
//! (see [`color`]). Emission: MGF's `ed` is the diffuse emittance in lumens per m² (luminous exitance).
//! Following RenderPark, it is turned into radiometric exitance with the luminous efficacy of
//! equal-energy white, 179 lm/W (the Radiance convention), and into radiance by dividing by π:
//! L_e = ed / (179 π) × RGB(colour), in W/(m² sr).

pub mod color;
pub mod solids;
pub mod transform;
pub mod writer;

use self::color::Xyz;
use self::transform::XfSpec;
use super::luminaire::MAX_LUMINAIRES;
use super::polygonize::{polygonize, PolygonError};
use super::{
    Diagnostic, LoadOptions, Material, Object, Polygon, Scene, SceneError, MAX_POLYGONS,
    MAX_REFLECTANCE,
};
use glam::{DAffine3, DVec3};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::rc::Rc;

pub use crate::color::WHITE_EFFICACY;
/// Deepest include nesting (guards against recursive includes).
const MAX_INCLUDE_DEPTH: usize = 32;
/// Most entities one load may run, counting array replays (guards against runaway nested arrays).
const MAX_ENTITIES: usize = 20_000_000;

/// Reads an MGF file and its includes.
pub fn load(path: &Path, options: &LoadOptions) -> Result<Scene, SceneError> {
    let bytes = super::read_bounded(path).map_err(|e| SceneError::new(path, 0, e))?;
    parse_bytes(bytes, path, options)
}

/// Reads MGF text held in memory: `path` names it in messages and anchors relative includes.
pub fn parse_bytes(
    bytes: impl Into<Vec<u8>>,
    path: &Path,
    options: &LoadOptions,
) -> Result<Scene, SceneError> {
    let entities = Entities::split(bytes.into()).map_err(|e| SceneError::new(path, 0, e))?;
    let mut reader = Reader::new(options);
    let canonical = std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf());
    reader.scene.sources.push(canonical.clone());
    reader.includes.push(Include {
        canonical,
        file: path.to_path_buf(),
        line: 0,
    });
    reader.place = path.to_path_buf();
    reader.run_file(path, &entities)?;
    Ok(reader.scene)
}

/// Parses a finite number (MGF allows forms like `.5`, `5.` and `1e3`).
pub(crate) fn parse_number(word: &str) -> Result<f64, String> {
    match word.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        Ok(_) => Err(format!("number '{word}' is not finite")),
        Err(_) => Err(format!("'{word}' is not a number")),
    }
}

/// One entity: its words and the number of the physical line it starts on.
struct Line<'t> {
    number: usize,
    words: Vec<&'t str>,
}

/// A file split into entities. The text is kept once and words are byte ranges into it: one owned
/// string per word made a 64 MiB file take about 1.5 GB.
struct Entities {
    text: String,
    /// Byte range of every word, in file order.
    words: Vec<(u32, u32)>,
    /// Each entity: the physical line it starts on and its range in `words`.
    entities: Vec<(usize, std::ops::Range<u32>)>,
}

impl Entities {
    /// Splits text into entities, joining lines continued with a backslash.
    fn split(bytes: Vec<u8>) -> Result<Entities, String> {
        if bytes.len() as u64 > super::MAX_FILE_BYTES {
            return Err(format!(
                "file larger than {} MiB refused",
                super::MAX_FILE_BYTES >> 20
            ));
        }
        let text = String::from_utf8(bytes)
            .unwrap_or_else(|e| String::from_utf8_lossy(e.as_bytes()).into_owned());
        let mut words = Vec::new();
        let mut entities = Vec::new();
        let mut pending: Option<(usize, u32)> = None;
        let base = text.as_ptr() as usize;
        for (k, raw) in text.lines().enumerate() {
            let trimmed = raw.trim_end();
            let (body, continued) = match trimmed.strip_suffix('\\') {
                Some(b) => (b, true),
                None => (trimmed, false),
            };
            let (number, first) = *pending.get_or_insert((k + 1, words.len() as u32));
            // Offsets fit in u32: the text is at most MAX_FILE_BYTES long.
            words.extend(body.split_whitespace().map(|w| {
                let start = (w.as_ptr() as usize - base) as u32;
                (start, start + w.len() as u32)
            }));
            if !continued {
                pending = None;
                if words.len() as u32 > first {
                    entities.push((number, first..words.len() as u32));
                }
            }
        }
        if let Some((number, first)) = pending {
            if words.len() as u32 > first {
                entities.push((number, first..words.len() as u32));
            }
        }
        Ok(Entities {
            text,
            words,
            entities,
        })
    }

    fn len(&self) -> usize {
        self.entities.len()
    }

    fn line(&self, k: usize) -> Line<'_> {
        let (number, range) = &self.entities[k];
        let words = self.words[range.start as usize..range.end as usize]
            .iter()
            .map(|&(a, b)| &self.text[a as usize..b as usize])
            .collect();
        Line {
            number: *number,
            words,
        }
    }

    /// The line of the last entity (0 for an empty file).
    fn last_line(&self) -> usize {
        self.entities.last().map_or(0, |e| e.0)
    }
}

/// An MGF vertex context: position and (optional, zero when absent) normal, untransformed.
#[derive(Clone, Copy, Debug, Default)]
struct Vertex {
    p: DVec3,
    n: DVec3,
}

/// An MGF material context (the diffuse part we use).
#[derive(Clone, Debug)]
struct MgfMaterial {
    two_sided: bool,
    rd: f64,
    rd_colour: Xyz,
    /// Where `rd` was last set (file, line), for the clamping warning.
    rd_at: (PathBuf, usize),
    ed: f64,
    ed_colour: Xyz,
    /// `rs`, `ts` or `td` met and reported once.
    non_diffuse_reported: bool,
}

impl Default for MgfMaterial {
    /// MGF's default: a perfect two-sided black absorber.
    fn default() -> Self {
        MgfMaterial {
            two_sided: true,
            rd: 0.0,
            rd_colour: color::NEUTRAL,
            rd_at: (PathBuf::new(), 0),
            ed: 0.0,
            ed_colour: color::NEUTRAL,
            non_diffuse_reported: false,
        }
    }
}

/// An open `xf` context.
struct XfFrame {
    spec: XfSpec,
    index: Vec<usize>,
    /// Total transform (this context's arguments, then the enclosing contexts').
    total: DAffine3,
    /// First line of the body, replayed for each array instance.
    body_start: usize,
    /// Include depth of the file that opened it.
    depth: usize,
}

/// A file being read, and the line of its including file that included it.
struct Include {
    canonical: PathBuf,
    file: PathBuf,
    line: usize,
}

struct Reader<'a> {
    options: &'a LoadOptions,
    /// The chain of files being read, outermost first (include cycles are errors).
    includes: Vec<Include>,
    /// Files already read, by canonical path: an include in an array is read once.
    read_cache: HashMap<PathBuf, Rc<Entities>>,
    scene: Scene,
    file: PathBuf,
    /// The file being read as messages about its polygons name it: its include chain (see
    /// [`Origins`](super::duplicates::Origins)).
    place: PathBuf,
    depth: usize,
    colours: HashMap<String, Xyz>,
    colour: Xyz,
    colour_name: Option<String>,
    materials: HashMap<String, MgfMaterial>,
    material: MgfMaterial,
    material_name: Option<String>,
    /// Scene material of the current MGF material; `None` after any change.
    material_index: Option<usize>,
    vertices: HashMap<String, Vertex>,
    vertex_name: Option<String>,
    objects: Vec<String>,
    object_index: Option<usize>,
    object_lookup: HashMap<String, usize>,
    xf: Vec<XfFrame>,
    /// Entities run so far (see [`MAX_ENTITIES`]).
    entities: usize,
}

type Result<T, E = SceneError> = std::result::Result<T, E>;

impl<'a> Reader<'a> {
    fn new(options: &'a LoadOptions) -> Self {
        Reader {
            options,
            includes: Vec::new(),
            read_cache: HashMap::new(),
            scene: Scene::default(),
            file: PathBuf::new(),
            place: PathBuf::new(),
            depth: 0,
            colours: HashMap::new(),
            colour: color::NEUTRAL,
            colour_name: None,
            materials: HashMap::new(),
            material: MgfMaterial::default(),
            material_name: None,
            material_index: None,
            vertices: HashMap::new(),
            vertex_name: None,
            objects: Vec::new(),
            object_index: None,
            object_lookup: HashMap::new(),
            xf: Vec::new(),
            entities: 0,
        }
    }

    fn error(&self, line: usize, message: impl Into<String>) -> SceneError {
        SceneError::new(&self.file, line, message)
    }

    fn warn(&mut self, line: usize, message: impl Into<String>) {
        self.scene.warnings.push(Diagnostic {
            file: self.file.clone(),
            line,
            message: message.into(),
        });
    }

    fn run_file(&mut self, path: &Path, lines: &Entities) -> Result<()> {
        let outer_file = std::mem::replace(&mut self.file, path.to_path_buf());
        let frames_before = self.xf.len();
        let mut k = 0;
        while k < lines.len() {
            let line = lines.line(k);
            self.entities += 1;
            if self.entities > MAX_ENTITIES {
                return Err(self.error(
                    line.number,
                    format!("more than {MAX_ENTITIES} entities to run (runaway transform arrays?)"),
                ));
            }
            if line.words[0] == "xf" {
                k = self.xf_entity(&line, k)?;
                continue;
            }
            self.entity(&line)?;
            k += 1;
        }
        let open = self.xf.len() - frames_before;
        if open > 0 {
            let last = lines.last_line();
            self.warn(
                last,
                format!("{open} xf context(s) left open at end of file: closed"),
            );
            self.xf.truncate(frames_before);
        }
        self.file = outer_file;
        Ok(())
    }

    fn current_transform(&self) -> DAffine3 {
        self.xf.last().map_or(DAffine3::IDENTITY, |f| f.total)
    }

    /// Handles an `xf` line at index `k`; returns the index of the next line to run.
    fn xf_entity(&mut self, line: &Line, k: usize) -> Result<usize> {
        if line.words.len() == 1 {
            let Some(frame) = self.xf.last_mut() else {
                return Err(self.error(line.number, "xf end without a matching xf"));
            };
            if frame.depth != self.depth {
                return Err(self.error(
                    line.number,
                    "xf end closes a transform opened in another file",
                ));
            }
            if frame.spec.advance(&mut frame.index) {
                let local = frame.spec.matrix(&frame.index);
                let start = frame.body_start;
                let n = self.xf.len();
                let parent = if n >= 2 {
                    self.xf[n - 2].total
                } else {
                    DAffine3::IDENTITY
                };
                self.xf[n - 1].total = parent * local;
                return Ok(start);
            }
            self.xf.pop();
            return Ok(k + 1);
        }
        let spec = transform::parse(&line.words[1..]).map_err(|e| self.error(line.number, e))?;
        self.push_xf(spec, k + 1);
        Ok(k + 1)
    }

    fn push_xf(&mut self, spec: XfSpec, body_start: usize) {
        let index = vec![0; spec.dims.len()];
        let total = self.current_transform() * spec.matrix(&index);
        self.xf.push(XfFrame {
            spec,
            index,
            total,
            body_start,
            depth: self.depth,
        });
    }

    fn entity(&mut self, line: &Line) -> Result<()> {
        let w = &line.words;
        let n = line.number;
        let keyword = w[0];
        if keyword.starts_with('#') {
            if keyword == "#" && w.get(1) == Some(&"camera:") && self.depth == 0 {
                self.camera_comment(line)?;
            }
            return Ok(());
        }
        match keyword {
            "o" => self.object(line),
            "i" => self.include(line),
            "ies" => self.ies(line),
            "c" => self.colour_context(line),
            "cxy" => {
                let v = self.numbers(line, 2)?;
                let c = if color::is_black_edge(v[0], v[1]) {
                    self.warn(
                        n,
                        format!(
                            "chromaticity ({}, {}) has no luminance (y = 0): read as black, as \
                             RenderPark does",
                            v[0], v[1]
                        ),
                    );
                    color::BLACK
                } else {
                    color::from_xy(v[0], v[1]).map_err(|e| self.error(n, e))?
                };
                self.set_colour(c);
                Ok(())
            }
            "cspec" => {
                if w.len() < 5 {
                    return Err(self.error(n, "cspec needs l_min l_max and at least two values"));
                }
                let v = self.numbers(line, w.len() - 1)?;
                let c = color::from_spectrum(v[0], v[1], &v[2..]).map_err(|e| self.error(n, e))?;
                self.set_colour(c);
                Ok(())
            }
            "cct" => {
                let v = self.numbers(line, 1)?;
                let c = color::blackbody(v[0]).map_err(|e| self.error(n, e))?;
                self.set_colour(c);
                Ok(())
            }
            "cmix" => self.cmix(line),
            "m" => self.material_context(line),
            "sides" => {
                self.arity(line, 1)?;
                let two = match w[1] {
                    "1" => false,
                    "2" => true,
                    other => {
                        return Err(self.error(n, format!("sides must be 1 or 2, not '{other}'")))
                    }
                };
                self.modify_material(|m| m.two_sided = two);
                Ok(())
            }
            "rd" => {
                let v = self.numbers(line, 1)?;
                if v[0] < 0.0 {
                    return Err(self.error(n, format!("negative reflectance rd {}", v[0])));
                }
                let colour = self.colour;
                let at = (self.file.clone(), n);
                self.modify_material(|m| {
                    m.rd = v[0];
                    m.rd_colour = colour;
                    m.rd_at = at;
                });
                Ok(())
            }
            "ed" => {
                let v = self.numbers(line, 1)?;
                if v[0] < 0.0 {
                    return Err(self.error(n, format!("negative emittance ed {}", v[0])));
                }
                let colour = self.colour;
                self.modify_material(|m| {
                    m.ed = v[0];
                    m.ed_colour = colour;
                });
                Ok(())
            }
            "rs" | "ts" | "td" => {
                let count = if keyword == "td" { 1 } else { 2 };
                let v = self.numbers(line, count)?;
                if v[0] > 0.0 && !self.material.non_diffuse_reported {
                    let name = self.material_display_name();
                    self.warn(
                        n,
                        format!(
                            "material '{name}': {keyword} (specular or transmitted light) ignored, \
                             only diffuse reflection and emission are simulated"
                        ),
                    );
                    self.modify_material(|m| m.non_diffuse_reported = true);
                }
                Ok(())
            }
            "ir" => {
                self.numbers(line, 2)?;
                Ok(())
            }
            "v" => self.vertex_context(line),
            "p" | "n" => {
                let v = self.numbers(line, 3)?;
                let Some(name) = self.vertex_name.clone() else {
                    return Err(self.error(n, format!("{keyword} outside a vertex context")));
                };
                let value = DVec3::new(v[0], v[1], v[2]);
                let vertex = self.vertices.entry(name).or_default();
                if keyword == "p" {
                    vertex.p = value;
                } else {
                    vertex.n = value;
                }
                Ok(())
            }
            "f" => {
                if w.len() < 4 {
                    return Err(self.error(n, "a face needs at least three vertices"));
                }
                let points = w[1..]
                    .iter()
                    .map(|name| self.vertex(n, name).map(|v| v.p))
                    .collect::<Result<Vec<_>>>()?;
                self.add_polygons(n, vec![points])
            }
            "fh" => self.face_with_holes(line),
            "sph" => {
                self.arity(line, 2)?;
                let c = self.vertex(n, w[1])?;
                let r = self.number(n, w[2])?;
                let loops =
                    solids::sphere(c.p, r, self.segments()).map_err(|e| self.error(n, e))?;
                self.add_polygons(n, loops)
            }
            "cyl" | "cone" => {
                let (v1, r1, v2, r2) = if keyword == "cyl" {
                    self.arity(line, 3)?;
                    let r = self.number(n, w[2])?;
                    (self.vertex(n, w[1])?, r, self.vertex(n, w[3])?, r)
                } else {
                    self.arity(line, 4)?;
                    (
                        self.vertex(n, w[1])?,
                        self.number(n, w[2])?,
                        self.vertex(n, w[3])?,
                        self.number(n, w[4])?,
                    )
                };
                let loops = solids::cone(v1.p, r1, v2.p, r2, self.segments())
                    .map_err(|e| self.error(n, e))?;
                self.add_polygons(n, loops)
            }
            "ring" | "torus" => {
                self.arity(line, 3)?;
                let c = self.vertex(n, w[1])?;
                let (r0, r1) = (self.number(n, w[2])?, self.number(n, w[3])?);
                let loops = if keyword == "ring" {
                    solids::ring(c.p, c.n, r0, r1, self.segments())
                } else {
                    solids::torus(c.p, c.n, r0, r1, self.segments())
                }
                .map_err(|e| self.error(n, e))?;
                self.add_polygons(n, loops)
            }
            "prism" => {
                if w.len() < 5 {
                    return Err(self.error(n, "a prism needs at least three vertices and a length"));
                }
                let length = self.number(n, w[w.len() - 1])?;
                let base = w[1..w.len() - 1]
                    .iter()
                    .map(|name| self.vertex(n, name).map(|v| v.p))
                    .collect::<Result<Vec<_>>>()?;
                let loops = solids::prism(&base, length).map_err(|e| self.error(n, e))?;
                self.add_polygons(n, loops)
            }
            other => {
                self.warn(n, format!("unknown entity '{other}' ignored"));
                Ok(())
            }
        }
    }

    /// `# camera: eye x y z look_at x y z up x y z fov degrees`, as [`writer`] keeps the scene camera.
    fn camera_comment(&mut self, line: &Line) -> Result<()> {
        let n = line.number;
        let w = &line.words[2..];
        let labels = ["eye", "look_at", "up", "fov"];
        let well_formed = w.len() == 14
            && [0usize, 4, 8, 12]
                .iter()
                .zip(labels)
                .all(|(&k, label)| w[k] == label);
        if !well_formed {
            self.warn(n, "malformed camera comment ignored");
            return Ok(());
        }
        let number = |k: usize| self.number(n, w[k]);
        let vector = |k: usize| -> Result<DVec3> {
            Ok(DVec3::new(number(k)?, number(k + 1)?, number(k + 2)?))
        };
        let camera = super::CameraSpec {
            eye: vector(1)?,
            look_at: vector(5)?,
            up: vector(9)?,
            fov_degrees: number(13)?,
        };
        let usable = camera.eye != camera.look_at
            && camera.up.cross(camera.look_at - camera.eye).length() > 0.0
            && camera.fov_degrees > 0.0
            && camera.fov_degrees < 180.0;
        if usable {
            self.scene.camera = Some(camera);
        } else {
            self.warn(n, "degenerate camera comment ignored");
        }
        Ok(())
    }

    fn segments(&self) -> usize {
        self.options.tessellation.max(3)
    }

    fn arity(&self, line: &Line, count: usize) -> Result<()> {
        if line.words.len() != count + 1 {
            return Err(self.error(
                line.number,
                format!(
                    "{} takes {count} argument(s), got {}",
                    line.words[0],
                    line.words.len() - 1
                ),
            ));
        }
        Ok(())
    }

    fn number(&self, line: usize, word: &str) -> Result<f64> {
        parse_number(word).map_err(|e| self.error(line, e))
    }

    /// Exactly `count` numeric arguments.
    fn numbers(&self, line: &Line, count: usize) -> Result<Vec<f64>> {
        self.arity(line, count)?;
        line.words[1..]
            .iter()
            .map(|w| self.number(line.number, w))
            .collect()
    }

    fn vertex(&self, line: usize, name: &str) -> Result<Vertex> {
        self.vertices
            .get(name)
            .copied()
            .ok_or_else(|| self.error(line, format!("undefined vertex '{name}'")))
    }

    fn object(&mut self, line: &Line) -> Result<()> {
        match line.words.len() {
            1 => {
                if self.objects.pop().is_none() {
                    return Err(self.error(line.number, "o end without a matching o"));
                }
            }
            2 => self.objects.push(line.words[1].to_string()),
            _ => return Err(self.error(line.number, "o takes at most one name")),
        }
        self.object_index = None;
        Ok(())
    }

    fn current_object(&mut self) -> usize {
        if let Some(i) = self.object_index {
            return i;
        }
        let name = if self.objects.is_empty() {
            "default".to_string()
        } else {
            self.objects.join("/")
        };
        let scene = &mut self.scene;
        let i = *self.object_lookup.entry(name.clone()).or_insert_with(|| {
            scene.objects.push(Object { name });
            scene.objects.len() - 1
        });
        self.object_index = Some(i);
        i
    }

    fn include(&mut self, line: &Line) -> Result<()> {
        let n = line.number;
        if line.words.len() < 2 {
            return Err(self.error(n, "i needs a file name"));
        }
        let name = &line.words[1];
        let target = match self.file.parent() {
            Some(dir) => dir.join(name),
            None => PathBuf::from(name),
        };
        let canonical = std::fs::canonicalize(&target).unwrap_or_else(|_| target.clone());
        if self.includes.iter().any(|i| i.canonical == canonical) {
            return Err(self.error(
                n,
                format!("include cycle: {}", self.include_chain(n, &target)),
            ));
        }
        if self.depth >= MAX_INCLUDE_DEPTH {
            return Err(self.error(
                n,
                format!(
                    "includes nested deeper than {MAX_INCLUDE_DEPTH}: {}",
                    self.include_chain(n, &target)
                ),
            ));
        }
        let lines = match self.read_cache.get(&canonical) {
            Some(lines) => Rc::clone(lines),
            None => {
                let lines = super::read_bounded(&target)
                    .and_then(Entities::split)
                    .map_err(|e| {
                        self.error(n, format!("cannot include '{}': {e}", target.display()))
                    })?;
                let lines = Rc::new(lines);
                self.read_cache.insert(canonical.clone(), Rc::clone(&lines));
                self.scene.sources.push(canonical.clone());
                lines
            }
        };
        let mut place = self.place.clone().into_os_string();
        place.push(format!(":{n} -> {}", target.display()));
        let outer_place = std::mem::replace(&mut self.place, place.into());
        self.includes.push(Include {
            canonical,
            file: target.clone(),
            line: n,
        });
        let result = self.include_lines(line, &target, &lines);
        self.includes.pop();
        self.place = outer_place;
        result
    }

    /// `ies file [-m multiplier] [transform]`: a goniometric luminaire ([`super::luminaire`]) per
    /// instance of the transform (inside the enclosing ones), white, candela values times the multiplier.
    /// The file's `[LUMINOUSGEOMETRY]` fixture model is not loaded: it encloses the lamps that the
    /// intensity table already accounts for, so its surfaces would shadow the luminaire's own light and
    /// its emitters would count that light twice.
    fn ies(&mut self, line: &Line) -> Result<()> {
        let (n, w) = (line.number, &line.words);
        if w.len() < 2 {
            return Err(self.error(n, "ies needs a file name"));
        }
        let (multiplier, rest) = if w.get(2).is_some_and(|f| *f == "-m") {
            let word = w
                .get(3)
                .ok_or_else(|| self.error(n, "ies -m needs a multiplier"))?;
            let m = self.number(n, word)?;
            if m < 0.0 {
                return Err(self.error(n, "ies -m multiplier must be non-negative"));
            }
            (m, &w[4..])
        } else {
            (1.0, &w[2..])
        };
        let spec = transform::parse(rest).map_err(|e| self.error(n, e))?;
        let target = match self.file.parent() {
            Some(dir) => dir.join(w[1]),
            None => PathBuf::from(&w[1]),
        };
        // Read, so protected from being overwritten by an output.
        let canonical = std::fs::canonicalize(&target).unwrap_or_else(|_| target.clone());
        self.scene.sources.push(canonical);
        let photometry = std::sync::Arc::new(
            super::ies::load(&target)
                .map_err(|e| self.error(n, format!("in luminaire file: {e}")))?,
        );
        self.scene
            .warnings
            .extend(photometry.warnings.iter().cloned());
        if let Some((_, fixture)) = photometry
            .keywords
            .iter()
            .find(|(k, _)| k == "LUMINOUSGEOMETRY")
        {
            self.warn(
                n,
                format!(
                    "luminaire fixture geometry '{fixture}' not loaded: the intensity table carries \
                     the light, and the luminaire is drawn as its luminous opening"
                ),
            );
        }
        let mut index = vec![0; spec.dims.len()];
        loop {
            if self.scene.luminaires.len() >= MAX_LUMINAIRES {
                return Err(self.error(n, format!("more than {MAX_LUMINAIRES} luminaires")));
            }
            let placement = self.current_transform() * spec.matrix(&index);
            self.scene.add_luminaire(super::luminaire::Luminaire::place(
                std::sync::Arc::clone(&photometry),
                placement,
                crate::color::Rgb::WHITE,
                multiplier,
            ));
            if !spec.advance(&mut index) {
                return Ok(());
            }
        }
    }

    /// "a.mgf:3 -> b.mgf:7 -> a.mgf": the files being read, each with its including line, then `target`.
    fn include_chain(&self, line: usize, target: &Path) -> String {
        let mut chain: Vec<String> = Vec::new();
        for (k, include) in self.includes.iter().enumerate() {
            let at = self.includes.get(k + 1).map_or(line, |next| next.line);
            chain.push(format!("{}:{at}", include.file.display()));
        }
        chain.push(target.display().to_string());
        chain.join(" -> ")
    }

    /// Runs an included file's lines, once or once per instance of its transform array.
    fn include_lines(&mut self, line: &Line, target: &Path, lines: &Entities) -> Result<()> {
        let n = line.number;
        let spec = if line.words.len() > 2 {
            Some(transform::parse(&line.words[2..]).map_err(|e| self.error(n, e))?)
        } else {
            None
        };
        match spec {
            None => self.run_include(target, lines),
            Some(spec) => {
                self.push_xf(spec, 0);
                loop {
                    self.run_include(target, lines)?;
                    let Some(frame) = self.xf.last_mut() else {
                        break;
                    };
                    if !frame.spec.advance(&mut frame.index) {
                        break;
                    }
                    let local = frame.spec.matrix(&frame.index);
                    let n = self.xf.len();
                    let parent = if n >= 2 {
                        self.xf[n - 2].total
                    } else {
                        DAffine3::IDENTITY
                    };
                    self.xf[n - 1].total = parent * local;
                }
                self.xf.pop();
                Ok(())
            }
        }
    }

    fn run_include(&mut self, target: &Path, lines: &Entities) -> Result<()> {
        self.depth += 1;
        let result = self.run_file(target, lines);
        self.depth -= 1;
        result
    }

    fn colour_context(&mut self, line: &Line) -> Result<()> {
        let w = &line.words;
        match w.len() {
            1 => {
                self.colour = color::NEUTRAL;
                self.colour_name = None;
            }
            2 => {
                let Some(c) = self.colours.get(w[1]) else {
                    return Err(self.error(line.number, format!("undefined colour '{}'", w[1])));
                };
                self.colour = *c;
                self.colour_name = Some(w[1].to_string());
            }
            3 | 4 if w[2] == "=" => {
                let c = match w.get(3) {
                    None => color::NEUTRAL,
                    Some(t) => *self.colours.get(*t).ok_or_else(|| {
                        self.error(line.number, format!("undefined colour template '{t}'"))
                    })?,
                };
                self.colours.insert(w[1].to_string(), c);
                self.colour = c;
                self.colour_name = Some(w[1].to_string());
            }
            _ => return Err(self.error(line.number, "expected c [name [= [template]]]")),
        }
        Ok(())
    }

    fn set_colour(&mut self, c: Xyz) {
        self.colour = c;
        if let Some(name) = &self.colour_name {
            self.colours.insert(name.clone(), c);
        }
    }

    fn cmix(&mut self, line: &Line) -> Result<()> {
        let w = &line.words;
        let n = line.number;
        if w.len() < 3 || w.len().is_multiple_of(2) {
            return Err(self.error(n, "cmix needs weight/colour pairs"));
        }
        let mut parts = Vec::new();
        for pair in w[1..].chunks(2) {
            let weight = self.number(n, pair[0])?;
            let c = self
                .colours
                .get(pair[1])
                .ok_or_else(|| self.error(n, format!("undefined colour '{}'", pair[1])))?;
            parts.push((weight, *c));
        }
        let c = color::mix(&parts).map_err(|e| self.error(n, e))?;
        self.set_colour(c);
        Ok(())
    }

    fn material_context(&mut self, line: &Line) -> Result<()> {
        let w = &line.words;
        match w.len() {
            1 => {
                self.material = MgfMaterial::default();
                self.material_name = None;
            }
            2 => {
                let Some(m) = self.materials.get(w[1]) else {
                    return Err(self.error(line.number, format!("undefined material '{}'", w[1])));
                };
                self.material = m.clone();
                self.material_name = Some(w[1].to_string());
            }
            3 | 4 if w[2] == "=" => {
                let m = match w.get(3) {
                    None => MgfMaterial::default(),
                    Some(t) => self.materials.get(*t).cloned().ok_or_else(|| {
                        self.error(line.number, format!("undefined material template '{t}'"))
                    })?,
                };
                self.materials.insert(w[1].to_string(), m.clone());
                self.material = m;
                self.material_name = Some(w[1].to_string());
            }
            _ => return Err(self.error(line.number, "expected m [name [= [template]]]")),
        }
        self.material_index = None;
        Ok(())
    }

    fn modify_material(&mut self, change: impl FnOnce(&mut MgfMaterial)) {
        change(&mut self.material);
        if let Some(name) = &self.material_name {
            self.materials.insert(name.clone(), self.material.clone());
        }
        self.material_index = None;
    }

    fn material_display_name(&self) -> String {
        self.material_name
            .clone()
            .unwrap_or_else(|| "(unnamed)".to_string())
    }

    /// The scene material for the current MGF material, created on first use after a change.
    fn current_material(&mut self) -> usize {
        if let Some(i) = self.material_index {
            return i;
        }
        let m = &self.material;
        let name = self.material_display_name();
        let raw = color::to_linear_srgb(m.rd_colour) * m.rd;
        let reflectance = raw.map(|c| c.clamp(0.0, MAX_REFLECTANCE));
        let emission = (color::to_linear_srgb(m.ed_colour)
            * (m.ed / (WHITE_EFFICACY * std::f64::consts::PI)))
            .map(|c| c.max(0.0));
        let material = Material {
            name: name.clone(),
            reflectance,
            emission,
            two_sided: m.two_sided,
        };
        let index = match self.scene.materials.iter().position(|x| *x == material) {
            Some(i) => i,
            None => {
                if reflectance != raw {
                    let (file, line) = m.rd_at.clone();
                    self.scene.warnings.push(Diagnostic {
                        file,
                        line,
                        message: format!(
                            "material '{name}': reflectance ({:.4}, {:.4}, {:.4}) outside [0, 1) \
                             (or outside the sRGB gamut) clamped to ({:.4}, {:.4}, {:.4})",
                            raw.r, raw.g, raw.b, reflectance.r, reflectance.g, reflectance.b
                        ),
                    });
                }
                self.scene.materials.push(material);
                self.scene.materials.len() - 1
            }
        };
        self.material_index = Some(index);
        index
    }

    fn vertex_context(&mut self, line: &Line) -> Result<()> {
        let w = &line.words;
        match w.len() {
            2 => {
                if !self.vertices.contains_key(w[1]) {
                    return Err(self.error(line.number, format!("undefined vertex '{}'", w[1])));
                }
            }
            3 | 4 if w[2] == "=" => {
                let v = match w.get(3) {
                    None => Vertex::default(),
                    Some(t) => self.vertex(line.number, t)?,
                };
                self.vertices.insert(w[1].to_string(), v);
            }
            _ => return Err(self.error(line.number, "expected v name [= [template]]")),
        }
        self.vertex_name = Some(w[1].to_string());
        Ok(())
    }

    /// `fh outer... - hole... - hole...`: each hole is joined to the outline by a seam between their
    /// closest vertices, then the seamed polygon is split like any face.
    fn face_with_holes(&mut self, line: &Line) -> Result<()> {
        let n = line.number;
        let mut contours: Vec<Vec<DVec3>> = vec![Vec::new()];
        for name in &line.words[1..] {
            if *name == "-" {
                contours.push(Vec::new());
            } else if let Some(last) = contours.last_mut() {
                last.push(self.vertex(n, name)?.p);
            }
        }
        if contours.iter().any(|c| c.len() < 3) {
            return Err(self.error(n, "every contour of fh needs at least three vertices"));
        }
        let mut outline = contours[0].clone();
        for hole in &contours[1..] {
            let mut best = (0, 0, f64::INFINITY);
            for (i, p) in outline.iter().enumerate() {
                for (j, q) in hole.iter().enumerate() {
                    let d = p.distance_squared(*q);
                    if d < best.2 {
                        best = (i, j, d);
                    }
                }
            }
            let (i, j, _) = best;
            let mut seamed = outline[..=i].to_vec();
            seamed.extend(hole[j..].iter().chain(&hole[..=j]));
            seamed.extend(&outline[i..]);
            outline = seamed;
        }
        self.add_polygons(n, vec![outline])
    }

    /// Transforms polygons given in the current (untransformed) coordinates, splits them into shapes and
    /// adds them with the current material and object.
    fn add_polygons(&mut self, line: usize, loops: Vec<Vec<DVec3>>) -> Result<()> {
        if self.scene.polygons.len() >= MAX_POLYGONS {
            return Err(self.error(
                line,
                format!("more than {MAX_POLYGONS} polygons (runaway transform arrays?)"),
            ));
        }
        let xf = self.current_transform();
        let mirrored = xf.matrix3.determinant() < 0.0;
        for local in loops {
            let mut points: Vec<DVec3> = local.iter().map(|p| xf.transform_point3(*p)).collect();
            // A mirror flips the winding; reversing keeps the front side the mirror image of the original.
            if mirrored {
                points.reverse();
            }
            match polygonize(&points) {
                Ok(out) => {
                    for w in out.warnings {
                        self.warn(line, w);
                    }
                    if out.shapes.is_empty() {
                        continue;
                    }
                    let material = self.current_material();
                    let object = self.current_object();
                    let two_sided = self.scene.materials[material].two_sided;
                    self.scene
                        .polygons
                        .extend(out.shapes.into_iter().map(|shape| Polygon {
                            shape,
                            material,
                            object,
                            two_sided,
                            under_contact: false,
                        }));
                    let count = self.scene.polygons.len();
                    self.scene.origins.record(&self.place, line, count);
                }
                Err(e @ PolygonError::TooManyVertices(_)) => {
                    return Err(self.error(line, e.to_string()))
                }
                Err(e) => self.warn(line, format!("{e}: polygon dropped")),
            }
        }
        Ok(())
    }
}
