//! radiosity: hierarchical radiosity with refinement oracles (Feixas et al.), Galerkin error control
//! (Bekaert–Willems) and feature-based multi-resolution visibility (Sillion–Drettakis).
//!
//! Data flow: [`scene`] (files → polygons and materials) → [`visibility`] (BVH over the polygons) →
//! [`hierarchy`] (patches, element quadtrees, links) refined by an [`oracles`] criterion and solved by
//! [`solvers`] → [`output`] (images, illuminated models) and [`measures`] (statistics, error metrics).
//! See ARCHITECTURE.md.

// The documentation is for the people who work on the engine: public items link to the private
// constants and helpers that explain them (`cargo doc --document-private-items` renders those links).
#![allow(rustdoc::private_intra_doc_links)]

pub mod bases;
pub mod cli;
pub mod color;
pub mod experiments;
pub mod geometry;
pub mod hierarchy;
pub mod measures;
pub mod memory;
pub mod oracles;
pub mod output;
pub mod parallel;
pub mod pipeline;
pub mod progress;
pub mod random;
pub mod reference;
pub mod scene;
pub mod solvers;
pub mod visibility;
