//! Measures: run statistics, and later error metrics and information-theoretic scene measures.

pub mod stats;
