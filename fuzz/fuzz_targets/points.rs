#![no_main]
//! Probe points file (`radiosity probe --points`) on arbitrary text.

use libfuzzer_sys::fuzz_target;
use radiosity::reference::probe::parse_points;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(points) = parse_points(text, Path::new("fuzz.csv")) {
        for p in points {
            assert!(p.point.is_finite() && (p.normal.length() - 1.0).abs() < 1e-9);
        }
    }
});
