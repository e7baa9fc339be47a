//! Exhaustive ray casting over every polygon: the slow, obviously correct reference the BVH is tested
//! against.
