//! Reproductions of the papers' experiments, with numbers: each runs the library end to end and reports
//! tables (Markdown and JSON) and images.

pub mod oracles;
pub mod shadow_groups;
