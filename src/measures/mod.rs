//! Measures: run statistics, and later error metrics and information-theoretic scene measures.

pub mod fbem;
pub mod image_metrics;
pub mod stats;
