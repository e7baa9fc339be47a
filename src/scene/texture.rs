//! Textures as the solver sees them: a surface's reflectance is one colour per material, so an image
//! texture enters as its mean colour (glTF's base colour texture, OBJ's `map_Kd`), multiplying the
//! material's own factor. Texture coordinates are not read: the mean is over the whole image.
//!
//! Texels are sRGB-encoded (as both formats define colour textures) and are linearised before
//! averaging. PNG is decoded; other image formats are reported by the caller, which then uses the
//! factor alone.

use crate::color::Rgb;

/// Widest and tallest texture decoded (pixels).
pub const MAX_TEXTURE_SIDE: u32 = 8192;

/// Mean linear colour of an sRGB-encoded image (alpha ignored), decoding at most `max_alloc` bytes
/// of pixels and images of at most [`MAX_TEXTURE_SIDE`] pixels a side.
pub fn mean_linear_colour(bytes: &[u8], max_alloc: u64) -> Result<Rgb, String> {
    use image::GenericImageView;
    let mut reader = image::ImageReader::new(std::io::Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|e| e.to_string())?;
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(MAX_TEXTURE_SIDE);
    limits.max_image_height = Some(MAX_TEXTURE_SIDE);
    limits.max_alloc = Some(max_alloc);
    reader.limits(limits);
    if reader.format().is_none() {
        return Err("unknown image format".into());
    }
    let image = reader.decode().map_err(|e| e.to_string())?;
    let (w, h) = image.dimensions();
    if w == 0 || h == 0 {
        return Err("empty image".into());
    }
    let table: Vec<f64> = (0..=255u32)
        .map(|v| {
            let c = v as f64 / 255.0;
            if c <= 0.04045 {
                c / 12.92
            } else {
                ((c + 0.055) / 1.055).powf(2.4)
            }
        })
        .collect();
    let mut sum = [0.0f64; 3];
    for (_, _, pixel) in image.pixels() {
        for (s, &v) in sum.iter_mut().zip(&pixel.0[..3]) {
            *s += table[v as usize];
        }
    }
    let n = w as f64 * h as f64;
    Ok(Rgb::new(sum[0] / n, sum[1] / n, sum[2] / n))
}
