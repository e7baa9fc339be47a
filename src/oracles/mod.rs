//! Refinement oracles: decide whether a link is admissible or which of its two elements to subdivide.
