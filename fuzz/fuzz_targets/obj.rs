#![no_main]
//! OBJ/MTL reader on arbitrary bytes: up to the first NUL byte is the OBJ file, the rest the material
//! library that every `mtllib` names.

mod common;

use libfuzzer_sys::fuzz_target;
use radiosity::scene::obj;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let split = data.iter().position(|&b| b == 0).unwrap_or(data.len());
    let (text, library) = (&data[..split], data.get(split + 1..).unwrap_or(&[]));
    let path = Path::new("/nonexistent-fuzz-dir/fuzz.obj");
    if let Ok(scene) = obj::parse_bytes(text, path, |_| Ok(Some(library.to_vec()))) {
        common::check_scene(&scene);
    }
});
