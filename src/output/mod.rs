//! Output: pinhole camera, ray-cast rendering of the solution (flat, smooth, mesh overlay), PNG and
//! OpenEXR images, illuminated models (PLY, glTF).

pub mod camera;
pub mod false_colour;
pub mod image;
