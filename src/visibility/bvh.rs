//! Our bounding volume hierarchy: surface-area-heuristic build over the input polygons (quads kept as
//! quads), fast occlusion and closest-hit traversal.
