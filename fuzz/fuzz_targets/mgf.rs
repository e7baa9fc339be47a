#![no_main]
//! MGF reader on arbitrary bytes. Includes are named relative to a directory that does not exist.

mod common;

use libfuzzer_sys::fuzz_target;
use radiosity::scene::{mgf, LoadOptions};
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let path = Path::new("/nonexistent-fuzz-dir/fuzz.mgf");
    if let Ok(scene) = mgf::parse_bytes(data, path, &LoadOptions::default()) {
        common::check_scene(&scene);
    }
});
