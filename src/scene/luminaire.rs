//! A placed goniometric luminaire: an IES intensity table ([`super::ies`]) with a position, an
//! orientation and a luminous opening in the scene. It is a scene-level light source, not a Lambertian
//! material: its emitted radiance depends on direction, L_e(y, ω) = I(ω) / A_proj(ω).
//!
//! Model: the intensity distribution I(ω) leaves every point of the opening's horizontal mid-section (a
//! length × width rectangle, or an ellipse for round openings) in equal shares. Far from the luminaire
//! this is the photometric definition (intensity from the photometric centre); near it the light spreads
//! over the opening as a real fixture's does. The opening has no geometry of its own: it neither blocks
//! nor reflects light.
//!
//! Frame (LM-63 and MGF's IES notes): the luminaire aims down its −z axis (vertical angle 0° is the
//! nadir), the 0° horizontal plane contains its x axis (the opening's length), the 90° plane its y axis
//! (the width). A placement transform carries this frame into the scene.
//!
//! Units: an intensity of I_v candela becomes I_v / 179 W/sr per channel times the luminaire's colour
//! (luminance 1 for white), the 179 lm/W of equal-energy white that MGF's `ed` uses too
//! ([`super::mgf::WHITE_EFFICACY`]); geometry is in the scene's units, taken as metres.

use super::ies::Photometry;
use super::mgf::WHITE_EFFICACY;
use crate::color::Rgb;
use crate::geometry::{DVec2, DVec3};
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
    /// Half-extents of the opening's mid-section along the frame's x and y axes, in scene units.
    pub half_extent: DVec2,
    /// Elliptic rather than rectangular mid-section.
    pub round: bool,
    /// Extra candela multiplier (MGF `ies -m`), on top of the file's own.
    pub multiplier: f64,
    /// W/sr per candela, per channel: colour × multiplier / 179.
    pub scale: Rgb,
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
        let axes = [m.x_axis, m.y_axis, m.z_axis];
        let frame = axes.map(|a| a.normalize_or_zero());
        let opening = photometry.opening;
        let half_extent = DVec2::new(
            0.5 * opening.length * axes[0].length(),
            0.5 * opening.width * axes[1].length(),
        );
        Luminaire {
            position: transform.translation,
            frame,
            half_extent,
            round: opening.round,
            multiplier,
            scale: colour * (multiplier / WHITE_EFFICACY),
            photometry,
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

    /// Largest dimension of the opening (scene units).
    pub fn size(&self) -> f64 {
        2.0 * self.half_extent.max_element()
    }

    /// The opening point for a point `s` of the unit square, area-preserving (uniform `s` gives uniform
    /// points): the rectangle directly, the ellipse by the polar map.
    pub fn opening_point(&self, s: DVec2) -> DVec3 {
        let (a, b) = if self.round {
            let (r, angle) = (s.x.sqrt(), 2.0 * PI * s.y);
            (r * angle.cos(), r * angle.sin())
        } else {
            (2.0 * s.x - 1.0, 2.0 * s.y - 1.0)
        };
        self.position
            + self.frame[0] * (a * self.half_extent.x)
            + self.frame[1] * (b * self.half_extent.y)
    }

    /// Opening points, each carrying an equal share of the intensity, for a receiver at `distance`: one
    /// (the centre) when the opening looks small from there, else the cell centres of an n × n grid with
    /// n = ⌈16 × size / distance⌉ (at most [`MAX_OPENING_GRID`]): cells at most 1/16 of the distance
    /// (3.6°) wide. The midpoint rule's error then stays at a few 1e-3, from the curvature of
    /// cos θ / d² ((1/16)² / 24 × 3) and mostly from the table's kinks (the slope jumps of linear
    /// interpolation, δI′ h² / 8 on the cells that straddle a table angle); fewer points were measured 2%
    /// off a 10°-step table.
    pub fn opening_points(&self, distance: f64) -> Vec<DVec3> {
        let n = if distance > 0.0 {
            (16.0 * self.size() / distance).ceil() as usize
        } else {
            MAX_OPENING_GRID
        }
        .clamp(1, MAX_OPENING_GRID);
        if n == 1 {
            return vec![self.position];
        }
        let mut out = Vec::with_capacity(n * n);
        for i in 0..n {
            for j in 0..n {
                let s = DVec2::new((i as f64 + 0.5) / n as f64, (j as f64 + 0.5) / n as f64);
                out.push(self.opening_point(s));
            }
        }
        out
    }

    /// Irradiance (W/m² per channel) at `x` with unit normal `normal` from this luminaire, the opening
    /// points weighted equally: Σ_points I(ω) cos θ_x / d² × `transmittance(x, point)` / points (receiving
    /// end first, as [`crate::visibility::Visibility::transmittance`] reads it).
    pub fn irradiance(
        &self,
        x: DVec3,
        normal: DVec3,
        mut transmittance: impl FnMut(DVec3, DVec3) -> f64,
    ) -> Rgb {
        let points = self.opening_points((x - self.position).length());
        let share = 1.0 / points.len() as f64;
        let mut sum = Rgb::BLACK;
        for y in points {
            let d = x - y;
            let r2 = d.length_squared();
            let cos_x = -normal.dot(d);
            if r2 <= 0.0 || cos_x <= 0.0 {
                continue;
            }
            let intensity = self.intensity(d);
            if intensity.is_black() {
                continue;
            }
            let t = transmittance(x, y);
            if t > 0.0 {
                sum += intensity * (share * t * cos_x / (r2 * r2.sqrt()));
            }
        }
        sum
    }
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

/// Most opening points per direction used for one receiver point (64 shadow rays).
pub const MAX_OPENING_GRID: usize = 8;
