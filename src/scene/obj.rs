//! OBJ/MTL reader through `tobj`: `Kd` is reflectance, `Ke` emitted radiance; faces are one-sided, front by
//! counter-clockwise winding.

use super::{LoadOptions, Scene, SceneError};
use std::path::Path;

/// Reads an OBJ file and its MTL libraries.
pub fn load(path: &Path, _options: &LoadOptions) -> Result<Scene, SceneError> {
    Err(SceneError::new(
        path,
        0,
        "the OBJ reader is not written yet",
    ))
}
