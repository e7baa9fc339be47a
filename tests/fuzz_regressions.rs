//! Inputs that crashed (or were found slow by) a fuzz target, kept in `fuzz/regressions/TARGET/`: each must
//! give `Ok` or `Err` from the same entry point the target calls, without panicking. A new crash found
//! by `scripts/fuzz.sh` is fixed, then its input is copied here.

use radiosity::output::image::Image;
use radiosity::output::plot::{group_series, run_points, svg, PlotSpec};
use radiosity::reference::probe::parse_points;
use radiosity::scene::{gltf, ies, mgf, obj, LoadOptions};
use std::path::Path;

/// Runs one input through the entry point of `target`, as `fuzz/fuzz_targets/TARGET.rs` does.
fn run(target: &str, data: &[u8]) {
    let nowhere = Path::new("/nonexistent-fuzz-dir/fuzz");
    match target {
        "mgf" => drop(mgf::parse_bytes(data, nowhere, &LoadOptions::default())),
        "obj" => {
            let split = data.iter().position(|&b| b == 0).unwrap_or(data.len());
            let library = data.get(split + 1..).unwrap_or(&[]).to_vec();
            drop(obj::parse_bytes(&data[..split], nowhere, |_| {
                Ok(Some(library.clone()))
            }))
        }
        "gltf" => drop(gltf::parse_bytes(data, nowhere)),
        "exr" => drop(Image::from_exr_bytes(data)),
        "radiance" => drop(Image::from_radiance_bytes(data)),
        "ies" => {
            if let Ok(p) = ies::parse(nowhere, &String::from_utf8_lossy(data)) {
                assert!(p.flux().is_finite() && p.intensity(45.0, 30.0).is_finite());
            }
        }
        "points" => {
            if let Ok(text) = std::str::from_utf8(data) {
                drop(parse_points(text, nowhere));
            }
        }
        "plot" => {
            let Some((&flags, json)) = data.split_first() else {
                return;
            };
            let spec = PlotSpec {
                x: "elements".into(),
                y: "error.relative_rmse".into(),
                label: (flags & 4 != 0).then(|| "settings.oracle".into()),
                log_x: flags & 1 != 0,
                log_y: flags & 2 != 0,
                title: None,
            };
            if let Ok(points) = run_points(json, nowhere, &spec) {
                drop(svg(&group_series(points), &spec));
            }
        }
        other => panic!("fuzz/regressions/{other}: no such fuzz target"),
    }
}

#[test]
fn fuzz_regressions_neither_panic_nor_hang() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/regressions");
    let mut count = 0;
    for target in std::fs::read_dir(&root).unwrap() {
        let target = target.unwrap().path();
        let name = target.file_name().unwrap().to_string_lossy().into_owned();
        for input in std::fs::read_dir(&target).unwrap() {
            let input = input.unwrap().path();
            if input.file_name().is_some_and(|n| n == ".gitkeep") {
                continue;
            }
            let data = std::fs::read(&input).unwrap();
            let outcome = std::panic::catch_unwind(|| run(&name, &data));
            assert!(outcome.is_ok(), "{} panicked", input.display());
            count += 1;
        }
    }
    println!("{count} fuzz regression inputs");
}
