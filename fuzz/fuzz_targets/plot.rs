#![no_main]
//! Stats JSON of `radiosity plot` on arbitrary bytes, through to the SVG chart. The first byte chooses
//! the axes' scales and whether runs are labelled by a field.

use libfuzzer_sys::fuzz_target;
use radiosity::output::plot::{group_series, run_points, svg, PlotSpec};
use std::path::Path;

fuzz_target!(|data: &[u8]| {
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
    if let Ok(points) = run_points(json, Path::new("fuzz.json"), &spec) {
        let _ = svg(&group_series(points), &spec);
    }
});
