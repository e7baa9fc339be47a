//! Measures: run statistics, and later error metrics and information-theoretic scene measures.

pub mod fbem;
pub mod global_lines;
pub mod illuminance;
pub mod image_metrics;
pub mod information;
pub mod irradiance_cache;
pub mod link_audit;
pub mod morphology;
pub mod point_errors;
pub mod stats;
