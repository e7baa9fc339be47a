//! IESNA LM-63 photometric data files (`.ies`): the 1986 (untagged), 1991, 1995 and 2002 formats, type C
//! photometry, `TILT=NONE`.
//!
//! A file is a header (a version line such as `IESNA:LM-63-2002`, then `[KEYWORD] text` lines, or free
//! text in the 1986 form) up to the `TILT=` line, then whitespace- or comma-separated numbers: lamps,
//! lumens per lamp (−1: absolute photometry), candela multiplier, the counts of vertical and horizontal
//! angles, the photometric type (1 = C), the units of the luminous opening (1 = feet, 2 = metres), its
//! width, length and height, the ballast factor, the ballast–lamp factor (1995; "future use" in 2002),
//! input watts, the vertical angles, the horizontal angles, and the candela values, one vertical column
//! per horizontal angle.
//!
//! Type C angles: the vertical angle θ is measured from the nadir (0° straight down, 180° straight up),
//! the horizontal angle φ counterclockwise, seen from above, from the 0° plane. Tables may cover one
//! horizontal angle (rotational symmetry), 0–90° (symmetric in both vertical planes), 0–180° (symmetric
//! about the 0–180° plane), 90–270° (symmetric about the 90–270° plane) or 0–360°. Intensities between
//! table angles are bilinear in (θ, φ); outside the vertical range they are zero.
//!
//! Errors name the file, line and reason; every count and size is bounded ([`MAX_ANGLES`],
//! [`MAX_VALUES`]), so no input panics or exhausts memory.

use super::{Diagnostic, SceneError};
use std::f64::consts::PI;
use std::path::{Path, PathBuf};

/// Most vertical or horizontal angles a table may have (real files have a few hundred at most).
pub const MAX_ANGLES: usize = 10_000;
/// Most candela values a table may have.
pub const MAX_VALUES: usize = 1_000_000;
/// Metres per foot (LM-63 units type 1).
const FOOT: f64 = 0.3048;

/// The luminous opening as LM-63 describes it, in metres, centred on the photometric centre: a
/// rectangle (height 0), a box, a disk (`round`, height 0), a vertical cylinder (`round`) or a point
/// (all zero). The luminaire frame has x along the 0° plane (length), y along the 90° plane (width) and
/// z up (height).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Opening {
    /// Along x (the 0°–180° plane).
    pub length: f64,
    /// Along y (the 90°–270° plane).
    pub width: f64,
    /// Along z.
    pub height: f64,
    /// Elliptic cross-section (LM-63-2002 negative dimensions: disk, cylinder, sphere as its cylinder).
    pub round: bool,
}

/// How the horizontal angles cover the circle.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Symmetry {
    /// One horizontal angle: the same in every vertical plane.
    Rotational,
    /// 0°–90°: mirrored in the 0°–180° and 90°–270° planes.
    Quadrant,
    /// 0°–180°: mirrored in the 0°–180° plane.
    Bilateral,
    /// 90°–270°: mirrored in the 90°–270° plane.
    BilateralAcross,
    /// Up to 360°: no symmetry (the gap up to 360° interpolates back to 0°).
    Full,
}

/// A parsed photometric file: the candela table with every multiplier applied.
#[derive(Clone, Debug, PartialEq)]
pub struct Photometry {
    pub file: PathBuf,
    /// Version line (`IESNA:LM-63-2002`, `IESNA91`, ...; empty for the 1986 form).
    pub version: String,
    /// `[KEYWORD] value` pairs of the header, in file order.
    pub keywords: Vec<(String, String)>,
    pub lamps: f64,
    /// Rated lumens per lamp; `None` for absolute photometry (−1 in the file).
    pub lumens_per_lamp: Option<f64>,
    /// Candela multiplier × ballast factor × ballast–lamp factor (1995 and older), as applied to `candela`.
    pub multiplier: f64,
    /// How far the flux and the rated lumens may differ from the file's rounding alone (lm): half a
    /// unit of the coarsest printed candela digit integrated like the table, plus half a unit of the
    /// lumens' last digit per lamp, multipliers applied.
    pub flux_precision: f64,
    pub input_watts: f64,
    pub opening: Opening,
    /// Vertical angles θ in degrees, increasing, within [0, 180].
    pub vertical: Vec<f64>,
    /// Horizontal angles φ in degrees, increasing.
    pub horizontal: Vec<f64>,
    pub symmetry: Symmetry,
    /// Candela values, `candela[h * vertical.len() + v]`, multipliers applied.
    pub candela: Vec<f64>,
    /// Warnings found while reading (flux above the lamps' lumens, ...).
    pub warnings: Vec<Diagnostic>,
}

type Result<T> = std::result::Result<T, SceneError>;

/// Reads an LM-63 file (at most [`super::MAX_FILE_BYTES`]).
pub fn load(path: &Path) -> Result<Photometry> {
    let bytes = super::read_bounded(path).map_err(|e| SceneError::new(path, 0, e))?;
    parse(path, &String::from_utf8_lossy(&bytes))
}

/// Parses the text of an LM-63 file; `path` only names it in messages.
pub fn parse(path: &Path, text: &str) -> Result<Photometry> {
    let error = |line: usize, message: String| SceneError::new(path, line, message);
    let mut lines = text.lines().enumerate().map(|(i, l)| (i + 1, l.trim()));
    let mut version = String::new();
    let mut keywords = Vec::new();
    let mut ballast_lamp_factor_applies = true;
    let tilt_line = loop {
        let Some((n, line)) = lines.next() else {
            return Err(error(
                text.lines().count(),
                "no TILT= line: not an IES (LM-63) file".into(),
            ));
        };
        if n == 1 && line.to_ascii_uppercase().starts_with("IESNA") {
            version = super::sanitise(line, 40);
            ballast_lamp_factor_applies = !line.contains("2002");
            continue;
        }
        if let Some(rest) = line.strip_prefix("TILT=").or(line.strip_prefix("TILT =")) {
            let tilt = rest.trim();
            if !tilt.eq_ignore_ascii_case("NONE") {
                return Err(error(
                    n,
                    format!(
                        "TILT={} is not supported (only TILT=NONE: lamp tilt factors are not modelled)",
                        super::sanitise(tilt, 60)
                    ),
                ));
            }
            break n;
        }
        if let Some(rest) = line.strip_prefix('[') {
            if let Some((key, value)) = rest.split_once(']') {
                keywords.push((super::sanitise(key, 60), super::sanitise(value.trim(), 240)));
            }
        }
    };
    let mut numbers = Numbers {
        path,
        tokens: lines
            .flat_map(|(n, line)| {
                line.split(|c: char| c.is_whitespace() || c == ',')
                    .filter(|w| !w.is_empty())
                    .map(move |w| (n, w))
            })
            .peekable(),
        last_line: tilt_line,
        last_unit: 1.0,
    };
    let lamps = numbers.next("number of lamps")?;
    let lumens = numbers.next("lumens per lamp")?;
    let lumens_unit = numbers.last_unit;
    let candela_multiplier = numbers.next("candela multiplier")?;
    let n_vertical = numbers.count("number of vertical angles")?;
    let n_horizontal = numbers.count("number of horizontal angles")?;
    let (line, photometric_type) = numbers.next_at("photometric type")?;
    match photometric_type as i64 {
        1 => {}
        2 | 3 => {
            return Err(error(
                line,
                format!(
                    "type {} photometry is not supported (only type C)",
                    if photometric_type == 2.0 { "B" } else { "A" }
                ),
            ))
        }
        _ => return Err(error(line, "photometric type must be 1, 2 or 3".into())),
    }
    let (line, units) = numbers.next_at("units type")?;
    let unit = match units as i64 {
        1 => FOOT,
        2 => 1.0,
        _ => {
            return Err(error(
                line,
                "units type must be 1 (feet) or 2 (metres)".into(),
            ))
        }
    };
    let width = numbers.next("luminous width")?;
    let length = numbers.next("luminous length")?;
    let height = numbers.next("luminous height")?;
    let ballast = numbers.next("ballast factor")?;
    let ballast_lamp = numbers.next("ballast-lamp photometric factor")?;
    let input_watts = numbers.next("input watts")?;
    let line = numbers.peek_line();
    if n_vertical.saturating_mul(n_horizontal) > MAX_VALUES {
        return Err(error(
            line,
            format!("{n_vertical} × {n_horizontal} candela values: more than {MAX_VALUES} refused"),
        ));
    }
    let vertical = numbers.angles(n_vertical, "vertical")?;
    let horizontal = numbers.angles(n_horizontal, "horizontal")?;
    if vertical[0] < 0.0 || vertical[n_vertical - 1] > 180.0 {
        return Err(error(
            line,
            "vertical angles must lie within 0..180 degrees (type C)".into(),
        ));
    }
    let symmetry = symmetry(&horizontal).map_err(|m| error(line, m))?;
    let mut multiplier = candela_multiplier * ballast;
    if ballast_lamp_factor_applies {
        multiplier *= ballast_lamp;
    }
    if !multiplier.is_finite() || multiplier < 0.0 {
        return Err(error(
            tilt_line + 1,
            "multipliers must be non-negative".into(),
        ));
    }
    let mut candela = Vec::with_capacity(n_vertical * n_horizontal);
    let mut candela_unit: f64 = 0.0;
    for _ in 0..n_vertical * n_horizontal {
        let (line, value) = numbers.next_at("candela value")?;
        if value < 0.0 {
            return Err(error(line, format!("negative candela value {value}")));
        }
        candela_unit = candela_unit.max(numbers.last_unit);
        candela.push(value * multiplier);
    }
    let opening = Opening {
        length: length.abs() * unit,
        width: width.abs() * unit,
        height: height.abs() * unit,
        round: width < 0.0 || length < 0.0,
    };
    let mut photometry = Photometry {
        file: path.to_path_buf(),
        version,
        keywords,
        lamps,
        lumens_per_lamp: (lumens > 0.0).then_some(lumens),
        multiplier,
        flux_precision: 0.0,
        input_watts,
        opening,
        vertical,
        horizontal,
        symmetry,
        candela,
        warnings: Vec::new(),
    };
    // The flux of a table of half units of the last printed digit bounds the flux's rounding error.
    let mut unit_table = photometry.clone();
    unit_table.candela.fill(0.5 * candela_unit * multiplier);
    photometry.flux_precision = unit_table.flux() + 0.5 * lumens_unit * lamps.abs() * multiplier;
    if let Some(rated) = photometry.rated_lumens() {
        let flux = photometry.flux();
        if flux > rated + photometry.flux_precision {
            photometry.warnings.push(Diagnostic {
                file: path.to_path_buf(),
                line: tilt_line,
                message: format!(
                    "the intensity table integrates to {flux:.1} lm, more than the lamps' rated \
                     {rated:.1} lm (lamps × lumens × multipliers) beyond the file's rounding \
                     (±{:.2} lm): an efficiency above 1, check the file",
                    photometry.flux_precision
                ),
            });
        }
    }
    Ok(photometry)
}

/// The symmetry the horizontal angles express (see [`Symmetry`]).
fn symmetry(horizontal: &[f64]) -> std::result::Result<Symmetry, String> {
    let (first, last) = (horizontal[0], horizontal[horizontal.len() - 1]);
    let close = |a: f64, b: f64| (a - b).abs() < 1e-6;
    Ok(match horizontal.len() {
        1 => Symmetry::Rotational,
        _ if close(first, 0.0) && close(last, 90.0) => Symmetry::Quadrant,
        _ if close(first, 0.0) && close(last, 180.0) => Symmetry::Bilateral,
        _ if close(first, 90.0) && close(last, 270.0) => Symmetry::BilateralAcross,
        _ if close(first, 0.0) && last > 180.0 && last <= 360.0 + 1e-6 => Symmetry::Full,
        _ => {
            return Err(format!(
                "horizontal angles {first}..{last}: expected one angle, 0..90, 0..180, 90..270 or \
                 0..360 degrees"
            ))
        }
    })
}

/// The numbers after `TILT=`, each with its line.
struct Numbers<'a, I: Iterator<Item = (usize, &'a str)>> {
    path: &'a Path,
    tokens: std::iter::Peekable<I>,
    last_line: usize,
    /// One unit of the last number's last printed digit (1 for "12", 0.01 for "1.25", 1e3 for "2e3").
    last_unit: f64,
}

impl<'a, I: Iterator<Item = (usize, &'a str)>> Numbers<'a, I> {
    fn next_at(&mut self, what: &str) -> Result<(usize, f64)> {
        let Some((line, word)) = self.tokens.next() else {
            return Err(SceneError::new(
                self.path,
                self.last_line,
                format!("file ends before the {what}"),
            ));
        };
        self.last_line = line;
        self.last_unit = printed_unit(word);
        match word.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok((line, v)),
            _ => Err(SceneError::new(
                self.path,
                line,
                format!(
                    "{what}: '{}' is not a finite number",
                    super::sanitise(word, 40)
                ),
            )),
        }
    }

    fn next(&mut self, what: &str) -> Result<f64> {
        self.next_at(what).map(|(_, v)| v)
    }

    /// The line of the next number (or of the last one, at the end).
    fn peek_line(&mut self) -> usize {
        self.tokens.peek().map_or(self.last_line, |&(line, _)| line)
    }

    /// A count of angles: an integer in 1..=[`MAX_ANGLES`].
    fn count(&mut self, what: &str) -> Result<usize> {
        let (line, v) = self.next_at(what)?;
        if v.fract() != 0.0 || v < 1.0 || v > MAX_ANGLES as f64 {
            return Err(SceneError::new(
                self.path,
                line,
                format!("{what} must be an integer from 1 to {MAX_ANGLES}, not {v}"),
            ));
        }
        Ok(v as usize)
    }

    /// `n` strictly increasing angles.
    fn angles(&mut self, n: usize, what: &str) -> Result<Vec<f64>> {
        let mut out = Vec::with_capacity(n);
        for _ in 0..n {
            let (line, a) = self.next_at(&format!("{what} angle"))?;
            if out.last().is_some_and(|&p| a <= p) {
                return Err(SceneError::new(
                    self.path,
                    line,
                    format!(
                        "{what} angles must increase ({a} follows {})",
                        out[out.len() - 1]
                    ),
                ));
            }
            out.push(a);
        }
        Ok(out)
    }
}

impl Photometry {
    /// Lamps × rated lumens per lamp × multipliers: the lamps' flux in lumens; `None` for absolute
    /// photometry.
    pub fn rated_lumens(&self) -> Option<f64> {
        self.lumens_per_lamp
            .map(|l| l * self.lamps * self.multiplier)
    }

    /// Intensity (cd, multipliers applied) at vertical angle `theta` from the nadir and horizontal angle
    /// `phi` (degrees), bilinear in the table after folding φ by the symmetry; zero outside the vertical
    /// range.
    pub fn intensity(&self, theta: f64, phi: f64) -> f64 {
        let Some((v, tv)) = bracket(&self.vertical, theta) else {
            return 0.0;
        };
        let column = |h: usize| self.column_at(h, v, tv);
        if self.symmetry == Symmetry::Rotational {
            return column(0);
        }
        let phi = self.fold(phi.rem_euclid(360.0));
        let last = self.horizontal.len() - 1;
        match bracket(&self.horizontal, phi) {
            Some((h, 0.0)) => column(h),
            Some((h, th)) => column(h) * (1.0 - th) + column(h + 1) * th,
            None => {
                // Full table ending before 360°: interpolate from the last angle back to 0° (= 360°).
                let span = 360.0 - self.horizontal[last];
                let t = if span > 0.0 {
                    ((phi - self.horizontal[last]) / span).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                column(last) * (1.0 - t) + column(0) * t
            }
        }
    }

    /// Column `h` of the table interpolated at `tv` between vertical angles `v` and `v + 1`.
    fn column_at(&self, h: usize, v: usize, tv: f64) -> f64 {
        let nv = self.vertical.len();
        let c = &self.candela[h * nv..(h + 1) * nv];
        if tv == 0.0 {
            c[v]
        } else {
            c[v] * (1.0 - tv) + c[v + 1] * tv
        }
    }

    /// The least and the greatest intensity (cd) toward any direction whose vertical angle lies in
    /// `[theta_lo, theta_hi]` (degrees), whatever its horizontal angle: exact bounds of the bilinear
    /// interpolant (linear in φ between columns, so its extremes over φ are the columns'; linear in θ
    /// between table angles, so a column's are at the range's ends or its table angles within), with
    /// the zero outside the table's vertical range when the range reaches past it.
    pub fn intensity_bounds(&self, theta_lo: f64, theta_hi: f64) -> (f64, f64) {
        let nv = self.vertical.len();
        let (first, last) = (self.vertical[0], self.vertical[nv - 1]);
        let (mut low, mut high) = if theta_lo < first || theta_hi > last {
            (0.0, 0.0)
        } else {
            (f64::INFINITY, f64::NEG_INFINITY)
        };
        let (lo, hi) = (theta_lo.max(first), theta_hi.min(last));
        if lo > hi {
            return (0.0, 0.0);
        }
        let inside = self
            .vertical
            .iter()
            .enumerate()
            .filter(|&(_, &a)| lo < a && a < hi);
        for h in 0..self.candela.len() / nv {
            let ends = [lo, hi].into_iter().filter_map(|theta| {
                bracket(&self.vertical, theta).map(|(v, tv)| self.column_at(h, v, tv))
            });
            for value in ends.chain(inside.clone().map(|(v, _)| self.candela[h * nv + v])) {
                low = low.min(value);
                high = high.max(value);
            }
        }
        (low, high)
    }

    /// Maps φ in [0, 360) into the range the table covers.
    fn fold(&self, phi: f64) -> f64 {
        match self.symmetry {
            Symmetry::Rotational | Symmetry::Full => phi,
            Symmetry::Bilateral if phi > 180.0 => 360.0 - phi,
            Symmetry::Bilateral => phi,
            Symmetry::Quadrant => {
                let half = if phi > 180.0 { 360.0 - phi } else { phi };
                if half > 90.0 {
                    180.0 - half
                } else {
                    half
                }
            }
            Symmetry::BilateralAcross if phi < 90.0 => 180.0 - phi,
            Symmetry::BilateralAcross if phi > 270.0 => 540.0 - phi,
            Symmetry::BilateralAcross => phi,
        }
    }

    /// The luminaire's flux ∫ I dΩ in lumens, exact for the bilinear interpolant: each vertical column is
    /// integrated in closed form (piecewise linear in θ times sin θ), and the columns by the trapezoid
    /// rule in φ (exact, the interpolant being linear in φ between table angles), times the symmetry's
    /// copies.
    pub fn flux(&self) -> f64 {
        let nv = self.vertical.len();
        let column_integral = |h: usize| -> f64 {
            let c = &self.candela[h * nv..(h + 1) * nv];
            (0..nv.saturating_sub(1))
                .map(|v| {
                    let (a, b) = (
                        self.vertical[v].to_radians(),
                        self.vertical[v + 1].to_radians(),
                    );
                    linear_times_sine(a, b, c[v], c[v + 1])
                })
                .sum()
        };
        let columns: Vec<f64> = (0..self.horizontal.len()).map(column_integral).collect();
        if self.symmetry == Symmetry::Rotational {
            return 2.0 * PI * columns[0];
        }
        let mut sum: f64 = self
            .horizontal
            .windows(2)
            .zip(columns.windows(2))
            .map(|(h, c)| (h[1] - h[0]).to_radians() * 0.5 * (c[0] + c[1]))
            .sum();
        let last = self.horizontal.len() - 1;
        let copies = match self.symmetry {
            Symmetry::Quadrant => 4.0,
            Symmetry::Bilateral | Symmetry::BilateralAcross => 2.0,
            Symmetry::Full => {
                let gap = (360.0 - self.horizontal[last]).to_radians();
                sum += gap * 0.5 * (columns[last] + columns[0]);
                1.0
            }
            Symmetry::Rotational => unreachable!("handled above"),
        };
        copies * sum
    }
}

/// One unit of the last digit of a printed number: 10^−(digits after the point) × 10^exponent.
fn printed_unit(word: &str) -> f64 {
    let (mantissa, exponent) = match word.find(['e', 'E']) {
        Some(i) => (&word[..i], word[i + 1..].parse::<i32>().unwrap_or(0)),
        None => (word, 0),
    };
    let decimals = mantissa
        .split_once('.')
        .map_or(0, |(_, fraction)| fraction.len().min(300) as i32);
    10f64.powi(exponent.clamp(-300, 300) - decimals)
}

/// `∫_a^b f(θ) sin θ dθ` for `f` linear from `fa` at `a` to `fb` at `b` (closed form).
fn linear_times_sine(a: f64, b: f64, fa: f64, fb: f64) -> f64 {
    if b <= a {
        return 0.0;
    }
    let slope = (fb - fa) / (b - a);
    let offset = fa - slope * a;
    // ∫ (c + s θ) sin θ dθ = −c cos θ + s (sin θ − θ cos θ)
    let antiderivative = |t: f64| -offset * t.cos() + slope * (t.sin() - t * t.cos());
    antiderivative(b) - antiderivative(a)
}

/// The interval `(i, t)` of the increasing `angles` holding `x` (`x = angles[i] + t (angles[i+1] −
/// angles[i])`, `t = 0` at a table angle, including the last); `None` outside the table.
fn bracket(angles: &[f64], x: f64) -> Option<(usize, f64)> {
    let (first, last) = (angles[0], angles[angles.len() - 1]);
    const SLACK: f64 = 1e-9;
    if x.is_nan() || x < first - SLACK || x > last + SLACK {
        return None;
    }
    if x >= last {
        return Some((angles.len() - 1, 0.0));
    }
    let i = angles.partition_point(|&a| a <= x).saturating_sub(1);
    let t = ((x - angles[i]) / (angles[i + 1] - angles[i])).clamp(0.0, 1.0);
    Some((i, t))
}
