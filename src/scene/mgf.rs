//! MGF reader (Greg Ward's Materials and Geometry Format, the scene format of RenderPark).

use super::{LoadOptions, Scene, SceneError};
use std::path::Path;

/// Reads an MGF file and its includes.
pub fn load(path: &Path, _options: &LoadOptions) -> Result<Scene, SceneError> {
    Err(SceneError::new(
        path,
        0,
        "the MGF reader is not written yet",
    ))
}
