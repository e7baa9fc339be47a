//! Linear RGB triples: reflectance, emitted radiance and radiosity are all solved per channel together.

use serde::{Deserialize, Serialize};
use std::ops::{Add, AddAssign, Div, Mul, MulAssign, Sub};

/// Luminous efficacy of equal-energy white light, lm/W (the Radiance and RenderPark convention): the one
/// factor between our radiometric unit and photometric units. MGF's `ed` (lm/m²) becomes radiance
/// `ed / (179 π)` W/(m² sr) (`scene::mgf`), so luminance is `179 Y(L)` cd/m² and illuminance `179 Y(E)` lux,
/// with `Y` the luminance-weighted sum of the linear sRGB channels ([`Rgb::luminance`]).
pub const WHITE_EFFICACY: f64 = 179.0;

/// The photometric value of a radiometric RGB quantity: luminance in cd/m² of a radiance in W/(m² sr), or
/// illuminance in lux of an irradiance in W/m² (`179 × Y`).
pub fn photometric(radiometric: Rgb) -> f64 {
    WHITE_EFFICACY * radiometric.luminance()
}

/// Units of reported radiance and irradiance (`--units`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Units {
    /// Radiance in W/(m² sr), irradiance in W/m², per RGB channel.
    #[default]
    Radiometric,
    /// Luminance in cd/m², illuminance in lux (`WHITE_EFFICACY`, 179 lm/W, × the channels, so that the
    /// luminance-weighted sum of an RGB value is its photometric value).
    Photometric,
}

impl Units {
    /// Factor from radiometric values to these units, applied per channel.
    pub fn scale(self) -> f64 {
        match self {
            Units::Radiometric => 1.0,
            Units::Photometric => WHITE_EFFICACY,
        }
    }

    /// Unit of radiance.
    pub fn radiance(self) -> &'static str {
        match self {
            Units::Radiometric => "W/m²sr",
            Units::Photometric => "cd/m²",
        }
    }
}

/// A linear RGB value (reflectance, radiance in W/(m^2 sr), or any per-channel quantity).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Rgb {
    pub r: f64,
    pub g: f64,
    pub b: f64,
}

impl Rgb {
    pub const BLACK: Rgb = Rgb::splat(0.0);
    pub const WHITE: Rgb = Rgb::splat(1.0);

    pub const fn new(r: f64, g: f64, b: f64) -> Self {
        Rgb { r, g, b }
    }

    pub const fn splat(v: f64) -> Self {
        Rgb { r: v, g: v, b: v }
    }

    /// Luminance with Rec. 709 / sRGB primaries (the weights of the Y row of the sRGB matrix).
    pub fn luminance(self) -> f64 {
        0.2126 * self.r + 0.7152 * self.g + 0.0722 * self.b
    }

    /// Mean of the three channels: the scalar used where a "grey" value is needed (oracles, MI measures).
    pub fn average(self) -> f64 {
        (self.r + self.g + self.b) / 3.0
    }

    /// The channels in single precision (EXR pixels, the viewer's vertex colours, compact tables).
    pub fn to_f32(self) -> [f32; 3] {
        [self.r as f32, self.g as f32, self.b as f32]
    }

    /// [`Rgb::to_f32`] back.
    pub fn from_f32(c: [f32; 3]) -> Rgb {
        Rgb::new(f64::from(c[0]), f64::from(c[1]), f64::from(c[2]))
    }

    pub fn max_channel(self) -> f64 {
        self.r.max(self.g).max(self.b)
    }

    /// The larger of two colours, channel by channel.
    pub fn channel_max(self, other: Rgb) -> Rgb {
        Rgb::new(
            self.r.max(other.r),
            self.g.max(other.g),
            self.b.max(other.b),
        )
    }

    pub fn min_channel(self) -> f64 {
        self.r.min(self.g).min(self.b)
    }

    pub fn is_black(self) -> bool {
        self.r == 0.0 && self.g == 0.0 && self.b == 0.0
    }

    pub fn is_finite(self) -> bool {
        self.r.is_finite() && self.g.is_finite() && self.b.is_finite()
    }

    pub fn map(self, f: impl Fn(f64) -> f64) -> Rgb {
        Rgb::new(f(self.r), f(self.g), f(self.b))
    }

    pub fn to_array(self) -> [f64; 3] {
        [self.r, self.g, self.b]
    }

    pub fn from_array(a: [f64; 3]) -> Self {
        Rgb::new(a[0], a[1], a[2])
    }
}

impl Add for Rgb {
    type Output = Rgb;
    fn add(self, o: Rgb) -> Rgb {
        Rgb::new(self.r + o.r, self.g + o.g, self.b + o.b)
    }
}

impl AddAssign for Rgb {
    fn add_assign(&mut self, o: Rgb) {
        *self = *self + o;
    }
}

impl Sub for Rgb {
    type Output = Rgb;
    fn sub(self, o: Rgb) -> Rgb {
        Rgb::new(self.r - o.r, self.g - o.g, self.b - o.b)
    }
}

impl Mul for Rgb {
    type Output = Rgb;
    fn mul(self, o: Rgb) -> Rgb {
        Rgb::new(self.r * o.r, self.g * o.g, self.b * o.b)
    }
}

impl Mul<f64> for Rgb {
    type Output = Rgb;
    fn mul(self, s: f64) -> Rgb {
        Rgb::new(self.r * s, self.g * s, self.b * s)
    }
}

impl Mul<Rgb> for f64 {
    type Output = Rgb;
    fn mul(self, c: Rgb) -> Rgb {
        c * self
    }
}

impl MulAssign<f64> for Rgb {
    fn mul_assign(&mut self, s: f64) {
        *self = *self * s;
    }
}

impl Div<f64> for Rgb {
    type Output = Rgb;
    fn div(self, s: f64) -> Rgb {
        Rgb::new(self.r / s, self.g / s, self.b / s)
    }
}

impl std::iter::Sum for Rgb {
    fn sum<I: Iterator<Item = Rgb>>(iter: I) -> Rgb {
        iter.fold(Rgb::BLACK, |a, b| a + b)
    }
}
