//! Output: pinhole camera, ray-cast rendering of the solution (flat, smooth, mesh overlay), PNG and
//! OpenEXR images, illuminated models (PLY, glTF).

pub mod camera;
pub mod export;
pub mod false_colour;
pub mod image;
pub mod mesh_values;
pub mod plot;
pub mod render;
pub mod tonemap;

pub use export::{write_glb, write_ply};
pub use mesh_values::{ShadedMesh, VertexRadiosity};
pub use render::{render, render_with, RenderOptions, Shading};
pub use tonemap::{to_srgb8, write_png, Curve, Exposure, ToneMap};
