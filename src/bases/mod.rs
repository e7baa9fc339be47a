//! Basis functions for the radiance on an element (Bekaert–Willems §2): constant now; the orthonormal
//! linear, quadratic and cubic bases on quads and triangles plug in here.
