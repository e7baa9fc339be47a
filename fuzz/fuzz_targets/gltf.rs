#![no_main]
//! glTF reader on arbitrary bytes (JSON or GLB). External URIs are relative to a directory that does
//! not exist; data URIs and the GLB binary chunk are read.

mod common;

use libfuzzer_sys::fuzz_target;
use radiosity::scene::gltf;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let path = Path::new("/nonexistent-fuzz-dir/fuzz.gltf");
    if let Ok(scene) = gltf::parse_bytes(data, path) {
        common::check_scene(&scene);
    }
});
