//! Seeds: every random choice is seeded from `--seed` and the identity of what it is for (a link, a
//! pixel, a batch), never from thread scheduling, so that results are bit-identical for any
//! `--threads`. The streams themselves are built where they are used (`solvers::link_rng`,
//! `reference`'s per-pixel streams); this is the mixing they share.

/// SplitMix64 finaliser: decorrelates nearby integers (indices, identities) into seeds.
pub fn splitmix64(mut x: u64) -> u64 {
    x = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    x = (x ^ (x >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    x ^ (x >> 31)
}

/// The top 53 bits of `bits` as a uniform number in [0, 1) (every double of the form k 2⁻⁵³).
pub fn unit_interval(bits: u64) -> f64 {
    (bits >> 11) as f64 / (1u64 << 53) as f64
}
