//! The crate's one pseudo-random generator: SplitMix64 (Steele, Lea & Flood, "Fast Splittable Pseudorandom Number
//! Generators", OOPSLA 2014), small, seedable and well mixed, with no dependency.
//!
//! It draws the RANSAC samples of slanted-plane smoothing (`post::planes`, one generator per segment), the
//! synthetic scenes of `jem synth`, and the random inputs of the tests. Outputs are a pure function of the seed,
//! so the same seed gives the same numbers on every platform and thread count.
//!
//! Two bounded-integer draws exist, [`SplitMix64::below`] (multiply-shift) and [`SplitMix64::below_by_remainder`]
//! (`%`), because RANSAC and the scene generator were written with different reductions and their outputs (the
//! reference disparity maps, the committed example scene) must stay byte-identical. New code should use `below`.
//!
//! Hidden from the documentation: it is a tool of the implementation and the tests, not part of the stereo API.

/// SplitMix64's output function: a bijective 64-bit mixer, also usable as a hash of integer coordinates.
#[inline]
pub(crate) fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// FNV-1a (64 bits) of `bytes`, continuing from `hash` ([`FNV_OFFSET`] to start): a stable hash of names and
/// sizes (the per-scene streams of `jem degrade`, the fingerprint of a data set in its results folder).
#[inline]
pub(crate) fn fnv1a(hash: u64, bytes: &[u8]) -> u64 {
    bytes.iter().fold(hash, |h, &b| (h ^ u64::from(b)).wrapping_mul(0x100_0000_01b3))
}

/// FNV-1a's starting value.
pub(crate) const FNV_OFFSET: u64 = 0xcbf2_9ce4_8422_2325;

/// A SplitMix64 stream: the state advances by the golden-ratio increment and each output is `mix64` of it.
#[derive(Clone, Debug)]
pub struct SplitMix64(u64);

impl SplitMix64 {
    /// A stream starting from `seed` (any value, 0 included).
    pub fn new(seed: u64) -> Self {
        SplitMix64(seed)
    }

    /// The next 64 random bits.
    #[inline]
    pub fn next_u64(&mut self) -> u64 {
        // ⌊2⁶⁴/φ⌋, odd, so the state visits all 2⁶⁴ values.
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        mix64(self.0)
    }

    /// Uniform in [0, 1): the top 53 bits as a multiple of 2⁻⁵³ (exact in `f64`).
    #[inline]
    pub fn next_f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in [`lo`, `hi`): `lo + (hi − lo) · next_f64()`.
    #[inline]
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next_f64()
    }

    /// Uniform in `0..n` for 1 ≤ n ≤ 2³², by the multiply-shift method on the top 32 bits: ⌊hi32 · n / 2³²⌋
    /// (each value has probability within 2⁻³² of 1/n; no division).
    #[inline]
    pub fn below(&mut self, n: usize) -> usize {
        debug_assert!(n >= 1 && n as u64 <= 1 << 32, "below({n})");
        (((self.next_u64() >> 32) * n as u64) >> 32) as usize
    }

    /// Uniform in `0..n` for n ≥ 1, as the remainder `next_u64() % n` (bias below n / 2⁶⁴). Kept for the scene
    /// generator, whose scenes depend on it; prefer [`below`](Self::below).
    ///
    /// # Panics
    /// If `n` is 0.
    #[inline]
    pub fn below_by_remainder(&mut self, n: usize) -> usize {
        (self.next_u64() % n as u64) as usize
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn example_of_mix64() {
        assert_eq!(crate::rng::mix64(0), 0);
        assert_ne!(crate::rng::mix64(1), crate::rng::mix64(2));
    }

    #[test]
    fn example_of_fnv1a() {
        use crate::rng::{FNV_OFFSET, fnv1a};
        assert_eq!(fnv1a(FNV_OFFSET, b""), FNV_OFFSET);
        assert_eq!(fnv1a(fnv1a(FNV_OFFSET, b"a"), b"b"), fnv1a(FNV_OFFSET, b"ab"));
    }

    #[test]
    fn example_of_split_mix64() {
        use crate::rng::SplitMix64;
        let (mut a, mut b) = (SplitMix64::new(7), SplitMix64::new(7));
        assert_eq!(a.next_u64(), b.next_u64());
        let u = a.next_f64();
        assert!((0.0..1.0).contains(&u));
        assert!(a.below(10) < 10);
    }

    #[test]
    fn known_outputs() {
        // The first outputs from seed 0 of the reference SplitMix64 (Vigna's splitmix64.c).
        let mut r = SplitMix64::new(0);
        assert_eq!(r.next_u64(), 0xe220_a839_7b1d_cdaf);
        assert_eq!(r.next_u64(), 0x6e78_9e6a_a1b9_65f4);
        assert_eq!(r.next_u64(), 0x06c4_5d18_8009_454f);
    }

    #[test]
    fn bounded_draws_stay_in_range_and_cover_it() {
        let mut r = SplitMix64::new(42);
        for n in [1usize, 2, 3, 7, 1000] {
            let mut seen = vec![false; n.min(16)];
            for _ in 0..2000 {
                let (a, b) = (r.below(n), r.below_by_remainder(n));
                assert!(a < n && b < n);
                if a < seen.len() {
                    seen[a] = true;
                }
            }
            assert!(n > 16 || seen.iter().all(|&s| s), "n = {n}: {seen:?}");
        }
        for _ in 0..1000 {
            let v = r.range(-2.0, 3.0);
            assert!((-2.0..3.0).contains(&v));
        }
    }
}
