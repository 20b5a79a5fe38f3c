//! Helpers shared by the unit tests.

/// Seeded uniform noise in 0..1 ([`crate::rng::SplitMix64`]): reproducible test inputs.
pub(crate) fn rand_vec(n: usize, seed: u64) -> Vec<f32> {
    let mut rng = crate::rng::SplitMix64::new(seed);
    (0..n).map(|_| (rng.next_u64() >> 40) as f32 / (1u64 << 24) as f32).collect()
}
