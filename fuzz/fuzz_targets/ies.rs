#![no_main]
//! IES (LM-63) photometric files on arbitrary bytes, read as `scene::ies::load` reads them (lossy
//! UTF-8); an accepted table must give finite, non-negative intensities and flux.

use libfuzzer_sys::fuzz_target;
use radiosity::scene::ies::parse;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    if let Ok(photometry) = parse(Path::new("fuzz.ies"), &text) {
        let flux = photometry.flux();
        assert!(flux.is_finite() && flux >= 0.0, "flux {flux}");
        for (theta, phi) in [(0.0, 0.0), (45.0, 30.0), (90.0, 200.0), (135.0, 359.0)] {
            let i = photometry.intensity(theta, phi);
            assert!(i.is_finite() && i >= 0.0, "I({theta}, {phi}) = {i}");
        }
    }
});
