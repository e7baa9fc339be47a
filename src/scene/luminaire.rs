//! A placed goniometric luminaire: an IES intensity table ([`super::ies`]) with a position, an
//! orientation and a luminous opening in the scene. It is a scene-level light source, not a Lambertian
//! material: its emitted radiance depends on direction.
//!
//! Geometry (LM-63's luminous opening, which MGF's `ies` entity places; the MGF notes on IES files call
//! it the "gross geometric specification of emitting surfaces", centred on the photometric centre): a
//! box of the file's length × width × height, a flat rectangle when the height is zero, an elliptic
//! prism or disk for round openings ([`ROUND_SEGMENTS`]-gon outlines), or a point when it has no area.
//! Its faces are scene polygons ([`super::Scene::add_luminaire`]): black (they reflect nothing), they
//! occlude like any surface, and camera rays see them glow.
//!
//! Emission: every visible point of the opening's surface leaves the same radiance toward ω,
//! L(ω) = I(ω) / A_proj(ω), with A_proj(ω) = Σ_faces A_f max(0, n_f · ω) the opening's projected area
//! (|n_f · ω| for a flat opening, which shines from both sides). The faces toward ω then carry exactly
//! I(ω) in the far field, the photometric definition, while near the fixture the light leaves its
//! whole surface, as a real fixture's does. This is Radiance's `ies2rad` model (its `boxcorr`, `flatcorr`
//! source corrections divide by the same projected area). A point opening emits I(ω) from its centre.
//!
//! Frame (LM-63 and MGF's IES notes): the luminaire aims down its −z axis (vertical angle 0° is the
//! nadir), the 0° horizontal plane contains its x axis (the opening's length), the 90° plane its y axis
//! (the width). A placement transform carries this frame and the opening into the scene.
//!
//! Units: an intensity of I_v candela becomes I_v / 179 W/sr per channel times the luminaire's colour
//! (luminance 1 for white), the 179 lm/W of equal-energy white that MGF's `ed` uses too
//! ([`super::mgf::WHITE_EFFICACY`]); geometry is in the scene's units, taken as metres.

use super::ies::{Opening, Photometry};
use super::mgf::WHITE_EFFICACY;
use crate::color::Rgb;
use crate::geometry::{DVec2, DVec3, Ray, Shape};
use glam::DAffine3;
use std::f64::consts::PI;
use std::sync::Arc;

/// A goniometric light source placed in a scene.
#[derive(Clone, Debug)]
pub struct Luminaire {
    pub photometry: Arc<Photometry>,
    /// Photometric centre.
    pub position: DVec3,
    /// Unit axes of the luminaire frame in the scene: x (0° plane), y (90° plane), z (up, θ = 180°).
    pub frame: [DVec3; 3],
    /// The luminous opening's faces in the scene: outward normals for a box or prism; for a flat
    /// opening (see `flat`) normals toward the nadir side. Empty for a point.
    pub faces: Vec<Shape>,
    /// The opening has no height: its faces shine from both sides.
    pub flat: bool,
    /// Extra candela multiplier (MGF `ies -m`), on top of the file's own.
    pub multiplier: f64,
    /// W/sr per candela, per channel: colour × multiplier / 179.
    pub scale: Rgb,
    /// The scene object holding the faces as polygons, once [`super::Scene::add_luminaire`] added them.
    pub object: Option<usize>,
}

impl Luminaire {
    /// Places `photometry` by `transform` (its linear part orients the frame and scales the opening; a
    /// mirror mirrors the distribution), with `colour` (luminance 1 for white) and an extra candela
    /// `multiplier`.
    pub fn place(
        photometry: Arc<Photometry>,
        transform: DAffine3,
        colour: Rgb,
        multiplier: f64,
    ) -> Self {
        let m = transform.matrix3;
        let frame = [m.x_axis, m.y_axis, m.z_axis].map(|a| a.normalize_or_zero());
        let (local, flat) = opening_faces(&photometry.opening);
        let position = transform.translation;
        let faces = local
            .into_iter()
            .map(|face| {
                let shape = match face {
                    Shape::Triangle(v) => Shape::Triangle(v.map(|p| transform.transform_point3(p))),
                    Shape::Quad(v) => Shape::Quad(v.map(|p| transform.transform_point3(p))),
                };
                // Outward for a solid (a mirroring transform reverses windings), nadir side if flat.
                let outward = if flat {
                    -frame[2]
                } else {
                    shape.centroid() - position
                };
                if shape.normal().dot(outward) < 0.0 {
                    shape.flipped()
                } else {
                    shape
                }
            })
            .filter(|f| f.area() > 0.0)
            .collect();
        Luminaire {
            position,
            frame,
            faces,
            flat,
            multiplier,
            scale: colour * (multiplier / WHITE_EFFICACY),
            photometry,
            object: None,
        }
    }

    /// Vertical (from the nadir) and horizontal angles, in degrees, of the scene direction `d`.
    pub fn angles(&self, d: DVec3) -> (f64, f64) {
        let local = DVec3::new(
            d.dot(self.frame[0]),
            d.dot(self.frame[1]),
            d.dot(self.frame[2]),
        );
        let length = local.length();
        if length == 0.0 {
            return (0.0, 0.0);
        }
        let theta = (-local.z / length).clamp(-1.0, 1.0).acos().to_degrees();
        let phi = local.y.atan2(local.x).to_degrees();
        (theta, phi)
    }

    /// Radiant intensity (W/sr per channel) toward the scene direction `d` (any length).
    pub fn intensity(&self, d: DVec3) -> Rgb {
        let (theta, phi) = self.angles(d);
        self.scale * self.photometry.intensity(theta, phi)
    }

    /// Radiant flux (W per channel): the table's ∫ I dΩ converted.
    pub fn power(&self) -> Rgb {
        self.scale * self.photometry.flux()
    }

    /// The opening's area projected along the unit direction `d`: Σ A_f max(0, n_f · d), or
    /// Σ A_f |n_f · d| for a flat opening (zero for a point).
    pub fn projected_area(&self, d: DVec3) -> f64 {
        self.faces
            .iter()
            .map(|f| {
                let c = f.normal().dot(d);
                f.area() * if self.flat { c.abs() } else { c.max(0.0) }
            })
            .sum()
    }

    /// Total area of the opening's faces.
    pub fn surface_area(&self) -> f64 {
        self.faces.iter().map(Shape::area).sum()
    }

    /// Radiance (W/(m² sr) per channel) leaving any point of the opening toward the direction `d` (any
    /// length): I(ω) / A_proj(ω). Zero where the opening shows no area (edge-on, or a point).
    pub fn luminance(&self, d: DVec3) -> Rgb {
        let d = d.normalize_or_zero();
        let area = self.projected_area(d);
        if area <= GRAZING * self.surface_area() {
            return Rgb::BLACK;
        }
        self.intensity(d) * (1.0 / area)
    }

    /// Whether the luminaire sends light into the open half-space of directions d with d · `side` > 0:
    /// some direction there has a positive table intensity. Tested on every cone of a table vertical
    /// angle, at the table's horizontal angles in all their mirror images and at the azimuth of `side`
    /// (where d · side is largest on the cone). Used to find openings that shine into a gap
    /// ([`super::contacts`]); interpolated light between table angles that only grazes the half-space
    /// is not seen.
    pub fn shines_toward(&self, side: DVec3) -> bool {
        let s = DVec3::new(
            side.dot(self.frame[0]),
            side.dot(self.frame[1]),
            side.dot(self.frame[2]),
        );
        let table = &self.photometry;
        let mut azimuths: Vec<f64> = table
            .horizontal
            .iter()
            .flat_map(|&phi| [phi, -phi, 180.0 - phi, 180.0 + phi])
            .collect();
        azimuths.push(s.y.atan2(s.x).to_degrees());
        table.vertical.iter().any(|&theta| {
            let (sin, cos) = theta.to_radians().sin_cos();
            azimuths.iter().any(|&phi| {
                let (sp, cp) = phi.to_radians().sin_cos();
                sin * (cp * s.x + sp * s.y) - cos * s.z > 1e-9 * s.length()
                    && table.intensity(theta, phi) > 0.0
            })
        })
    }

    /// Largest dimension of the opening (scene units; zero for a point).
    pub fn size(&self) -> f64 {
        self.faces
            .iter()
            .flat_map(|f| f.vertices())
            .map(|v| 2.0 * v.distance(self.position))
            .fold(0.0, f64::max)
    }

    /// The nearest hit of `ray` on the opening's faces with `t` in `(t_min, t_max)`.
    pub fn intersect(&self, ray: &Ray, t_min: f64, t_max: f64) -> Option<f64> {
        self.faces
            .iter()
            .filter_map(|f| {
                crate::visibility::brute_force::ray_polygon(ray, f.vertices(), t_min, t_max)
            })
            .map(|(t, _, _)| t)
            .min_by(f64::total_cmp)
    }

    /// Where light from the photometric centre toward `x` leaves the opening (the centre itself for a
    /// flat or point opening): the start of a shadow segment that the opening's own faces do not block.
    pub fn exit_point(&self, x: DVec3) -> DVec3 {
        let ray = Ray::new(self.position, x - self.position);
        match self.intersect(&ray, 0.0, 1.0) {
            Some(t) if !self.flat => ray.at(t),
            _ => self.position,
        }
    }

    /// Irradiance (W/m² per channel) at `x` with unit normal `normal` from this luminaire, the shadow
    /// segments' `transmittance(x, from)` applied (receiving end first, as
    /// [`crate::visibility::Visibility::transmittance`] reads it).
    ///
    /// Far away (the opening smaller than 1/16 of the distance) the photometric law from the centre,
    /// I(ω) cos θ_x / d², with one shadow segment from [`Luminaire::exit_point`]. Near it, the
    /// opening's surface integral Σ_faces ∫ L(ω) cos θ_x cos θ_y / r² dA by the midpoint rule on every
    /// face that `x` sees, split regularly into cells at most about 1/16 of the distance wide (up to
    /// [`MAX_CELL_LEVELS`] halvings): the error of the midpoint rule then stays at a few 1e-3, from
    /// the curvature of the kernel ((1/16)² / 24 × 3) and mostly from the table's kinks (the slope jumps
    /// of linear interpolation, δI′ h² / 8 on the cells that straddle a table angle).
    pub fn irradiance(
        &self,
        x: DVec3,
        normal: DVec3,
        mut transmittance: impl FnMut(DVec3, DVec3) -> f64,
    ) -> Rgb {
        let distance = (x - self.position).length();
        if self.faces.is_empty() || FAR_FIELD * self.size() <= distance {
            let d = x - self.position;
            let r2 = d.length_squared();
            let cos_x = -normal.dot(d);
            if r2 <= 0.0 || cos_x <= 0.0 {
                return Rgb::BLACK;
            }
            let intensity = self.intensity(d);
            if intensity.is_black() {
                return Rgb::BLACK;
            }
            let t = transmittance(x, self.exit_point(x));
            return intensity * (t * cos_x / (r2 * r2.sqrt()));
        }
        let mut sum = Rgb::BLACK;
        for face in &self.faces {
            let n = face.normal();
            let side = n.dot(x - face.centroid());
            if side == 0.0 || (!self.flat && side < 0.0) {
                continue;
            }
            let levels = (FAR_FIELD * face.diameter() / distance)
                .log2()
                .ceil()
                .clamp(0.0, MAX_CELL_LEVELS as f64) as u32;
            for cell in cells(face, levels) {
                let y = cell.centroid();
                let d = x - y;
                let r2 = d.length_squared();
                let r = r2.sqrt();
                let cos_x = -normal.dot(d) / r;
                let cos_y = n.dot(d).abs() / r;
                if r2 <= 0.0 || cos_x <= 0.0 {
                    continue;
                }
                let radiance = self.luminance(d);
                if radiance.is_black() {
                    continue;
                }
                let t = transmittance(x, y);
                if t > 0.0 {
                    sum += radiance * (t * cos_x * cos_y * cell.area() / r2);
                }
            }
        }
        sum
    }

    /// One point of the opening for next-event estimation from `x`: a face chosen with probability
    /// proportional to its area × the cosine toward `x` at its centroid (only faces `x` sees), then a
    /// uniform point on it, both from the unit-square sample `s`. Returns the point, its face's
    /// normal and its density per unit area; `None` when `x` sees no face. A point opening returns its
    /// centre with density 0 (a delta: the caller uses the photometric law).
    pub fn sample_point(&self, x: DVec3, s: DVec2) -> Option<(DVec3, DVec3, f64)> {
        if self.faces.is_empty() {
            return Some((self.position, DVec3::ZERO, 0.0));
        }
        let weights: Vec<f64> = self
            .faces
            .iter()
            .map(|f| {
                let c = f.normal().dot((x - f.centroid()).normalize_or_zero());
                f.area() * if self.flat { c.abs() } else { c.max(0.0) }
            })
            .collect();
        let total: f64 = weights.iter().sum();
        if total <= 0.0 {
            return None;
        }
        let mut u = s.x * total;
        for (face, &w) in self.faces.iter().zip(&weights) {
            if w <= 0.0 {
                continue;
            }
            if u < w {
                let point = face.sample_uniform(DVec2::new((u / w).clamp(0.0, 1.0), s.y));
                return Some((point, face.normal(), w / (total * face.area())));
            }
            u -= w;
        }
        let (face, w) = self
            .faces
            .iter()
            .zip(&weights)
            .rev()
            .find(|(_, &w)| w > 0.0)?;
        Some((
            face.sample_uniform(DVec2::new(1.0 - f64::EPSILON, s.y)),
            face.normal(),
            w / (total * face.area()),
        ))
    }
}

/// The opening's faces in the luminaire frame (metres) and whether it is flat: a box, or a rectangle
/// when one extent is zero; for round openings an elliptic prism, or disk when the height is zero; none
/// (a point) when it has no area.
fn opening_faces(opening: &Opening) -> (Vec<Shape>, bool) {
    let h = DVec3::new(opening.length, opening.width, opening.height) * 0.5;
    let positive = [h.x > 0.0, h.y > 0.0, h.z > 0.0];
    let extents = positive.iter().filter(|&&p| p).count();
    if opening.round {
        if !(positive[0] && positive[1]) {
            return (Vec::new(), true);
        }
        let ring = |z: f64| -> Vec<DVec3> {
            (0..ROUND_SEGMENTS)
                .map(|k| {
                    let a = 2.0 * PI * k as f64 / ROUND_SEGMENTS as f64;
                    DVec3::new(h.x * a.cos(), h.y * a.sin(), z)
                })
                .collect()
        };
        let fan = |v: &[DVec3]| -> Vec<Shape> {
            (0..(ROUND_SEGMENTS - 2) / 2)
                .map(|k| Shape::Quad([v[0], v[2 * k + 1], v[2 * k + 2], v[2 * k + 3]]))
                .collect()
        };
        if !positive[2] {
            return (fan(&ring(0.0)), true);
        }
        let (bottom, top) = (ring(-h.z), ring(h.z));
        let mut faces = fan(&bottom);
        faces.extend(fan(&top));
        for k in 0..ROUND_SEGMENTS {
            let j = (k + 1) % ROUND_SEGMENTS;
            faces.push(Shape::Quad([bottom[k], bottom[j], top[j], top[k]]));
        }
        return (faces, false);
    }
    if extents < 2 {
        return (Vec::new(), true);
    }
    // The face perpendicular to `axis` at offset `sign` × its half extent.
    let rectangle = |axis: usize, sign: f64| {
        let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
        let unit = |i: usize| DVec3::AXES[i] * h[i];
        let c = unit(axis) * sign;
        Shape::Quad([
            c - unit(u) - unit(v),
            c + unit(u) - unit(v),
            c + unit(u) + unit(v),
            c - unit(u) + unit(v),
        ])
    };
    if extents == 2 {
        let axis = positive.iter().position(|&p| !p).unwrap_or(2);
        return (vec![rectangle(axis, 0.0)], true);
    }
    let faces = (0..3)
        .flat_map(|axis| [rectangle(axis, -1.0), rectangle(axis, 1.0)])
        .collect();
    (faces, false)
}

/// The 4^`levels` cells of regular splits of `face` (equal areas for parallelograms and triangles).
fn cells(face: &Shape, levels: u32) -> Vec<Shape> {
    let mut out = vec![*face];
    for _ in 0..levels {
        out = out.iter().flat_map(Shape::subdivide).collect();
    }
    out
}

/// Where the command line puts a luminaire (`--luminaire FILE.ies@X,Y,Z[@DX,DY,DZ[@SPIN]]`): the file,
/// the photometric centre, the aiming direction (where the nadir, θ = 0°, points; default −z) and a
/// spin in degrees about that direction (turning the 0° plane, which starts as close to the scene's x
/// axis as the aim allows, or its y axis when aiming along x).
#[derive(Clone, Debug, PartialEq)]
pub struct Placement {
    pub file: std::path::PathBuf,
    pub position: DVec3,
    pub aim: DVec3,
    pub spin_degrees: f64,
}

impl std::str::FromStr for Placement {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, String> {
        let syntax = "expected FILE.ies@X,Y,Z[@DX,DY,DZ[@SPIN]]";
        let start = text.rfind('/').map_or(0, |i| i + 1);
        let at = text[start..]
            .find('@')
            .map(|i| start + i)
            .ok_or_else(|| format!("no position: {syntax}"))?;
        let file = std::path::PathBuf::from(&text[..at]);
        let parts: Vec<&str> = text[at + 1..].split('@').collect();
        let vector = |word: &str| -> Result<DVec3, String> {
            let v: Vec<f64> = word
                .split(',')
                .map(|x| {
                    x.trim()
                        .parse::<f64>()
                        .map_err(|_| format!("'{x}': {syntax}"))
                })
                .collect::<Result<_, _>>()?;
            match v[..] {
                [x, y, z] if v.iter().all(|c| c.is_finite()) => Ok(DVec3::new(x, y, z)),
                _ => Err(format!("'{word}' is not three finite numbers: {syntax}")),
            }
        };
        if parts.len() > 3 {
            return Err(format!("too many '@' parts: {syntax}"));
        }
        let position = vector(parts[0])?;
        let aim = parts.get(1).map_or(Ok(DVec3::NEG_Z), |w| vector(w))?;
        if aim.length_squared() == 0.0 {
            return Err("the aiming direction must not be zero".into());
        }
        let spin_degrees = match parts.get(2) {
            Some(w) => w
                .trim()
                .parse::<f64>()
                .ok()
                .filter(|s| s.is_finite())
                .ok_or_else(|| format!("spin '{w}' is not a finite number: {syntax}"))?,
            None => 0.0,
        };
        Ok(Placement {
            file,
            position,
            aim: aim.normalize(),
            spin_degrees,
        })
    }
}

impl Placement {
    /// The luminaire frame's transform: z opposite the aim, x the scene's x axis (y when aiming along
    /// x) made perpendicular and turned by the spin, y = z × x; translated to the position.
    pub fn transform(&self) -> DAffine3 {
        let z = -self.aim;
        let reference = if z.x.abs() > 0.9 { DVec3::Y } else { DVec3::X };
        let x0 = (reference - z * reference.dot(z)).normalize();
        let x = glam::DQuat::from_axis_angle(z, self.spin_degrees.to_radians()) * x0;
        let y = z.cross(x);
        DAffine3::from_cols(x, y, z, self.position)
    }

    /// Reads the file and places a white luminaire.
    pub fn load(&self) -> Result<Luminaire, super::SceneError> {
        let photometry = Arc::new(super::ies::load(&self.file)?);
        Ok(Luminaire::place(
            photometry,
            self.transform(),
            Rgb::WHITE,
            1.0,
        ))
    }
}

/// Most luminaires one scene may have (each costs shadow rays at every receiver node).
pub const MAX_LUMINAIRES: usize = 10_000;

/// Segments of a round opening's outline (as many as MGF's default tessellation of curved solids).
pub const ROUND_SEGMENTS: usize = 16;

/// A receiver farther than this many opening sizes sees the opening as a point; nearer, cells are at
/// most this fraction of the distance wide (1/16: 3.6°).
const FAR_FIELD: f64 = 16.0;

/// Most halvings of a face for one receiver point (64 cells, 64 shadow rays per face).
pub const MAX_CELL_LEVELS: u32 = 3;

/// Projected areas below this fraction of the opening's area count as edge-on (no radiance).
const GRAZING: f64 = 1e-9;
