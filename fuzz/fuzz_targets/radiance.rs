#![no_main]
//! Radiance HDR (RGBE) loader of `radiosity compare` on arbitrary bytes.

use libfuzzer_sys::fuzz_target;
use radiosity::output::image::Image;

fuzz_target!(|data: &[u8]| {
    if let Ok(image) = Image::from_radiance_bytes(data) {
        assert_eq!(image.pixels.len(), image.width * image.height);
    }
});
