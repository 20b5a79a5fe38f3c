//! Small numeric kernels written so that the compiler vectorises them on baseline x86-64: an `exp` for
//! non-positive arguments (libm's `expf` is a scalar call) and reductions with eight independent lanes (a single
//! running float sum or minimum is a serial dependency chain). Lanes are combined in a fixed order, so results
//! do not depend on the thread count. Used by the mean-field softmax and the weighted median's weights.
//!
//! # SIMD in jem
//!
//! There is no `std::arch`: every kernel is plain Rust that the compiler vectorises. The hottest ones (the cost
//! row in [`crate::cost`], the splat, blur, slice and embedding of [`crate::lattice`], the mean-field unary and row
//! updates in [`crate::meanfield`], the row of [`crate::post::wmedian`]) are also compiled for AVX2 + FMA by the
//! `multiversion` crate, which picks a version at run time. Both versions give bit-identical results: Rust neither
//! contracts `a·b + c` into a fused multiply-add nor reorders float operations, so the AVX2 clone performs the same
//! IEEE operations in the same order, only more of them per instruction.
//!
//! The cargo feature `force-baseline` compiles those kernels without the AVX2 clone, so that the baseline code also
//! runs (and is tested) on an AVX2 machine. Each kernel carries
//! `#[cfg_attr(not(feature = "force-baseline"), multiversion::multiversion(targets("x86_64+avx2+fma")))]`; `.ci/run`
//! builds the binary both ways and checks that they write byte-identical disparity maps.

/// e^x for x ≤ 0, in plain arithmetic that the compiler vectorises (libm's `expf` is a scalar call).
///
/// x = n·ln 2 + r with |r| ≤ ln 2 / 2; e^r by its degree-6 Taylor polynomial (relative error < 3·10⁻⁷ on that
/// interval), 2^n by writing the exponent bits. Arguments below −87 (where e^x is subnormal) give 0, and so does
/// −∞; NaN gives 0 as well, so a bad energy can never put NaN into Q.
#[inline(always)]
pub fn exp_nonpositive(x: f32) -> f32 {
    const LOG2E: f32 = std::f32::consts::LOG2_E;
    // ln 2 split so that n·LN2_HI is exact in f32 (Cody & Waite): keeps r accurate for large |n|.
    const LN2_HI: f32 = 0.693_359_4;
    const LN2_LO: f32 = -2.121_944_4e-4;
    let ok = x >= -87.0;
    let x = if ok { x.min(0.0) } else { 0.0 };
    // Round to nearest by adding and subtracting 1.5·2²³ (exact for |v| < 2²²; `round` is a libm call on
    // baseline x86-64 and would block vectorisation).
    const MAGIC: f32 = 12_582_912.0;
    let n = (x * LOG2E + MAGIC) - MAGIC;
    let r = (x - n * LN2_HI) - n * LN2_LO;
    let p = 1.0 + r * (1.0 + r * (0.5 + r * (1.0 / 6.0 + r * (1.0 / 24.0 + r * (1.0 / 120.0 + r * (1.0 / 720.0))))));
    let scale = f32::from_bits(((n as i32 + 127) as u32) << 23);
    if ok { p * scale } else { 0.0 }
}

/// Sum with eight independent accumulators, combined in a fixed order: vectorisable (a single running float
/// sum is a serial dependency chain) and still deterministic.
#[inline]
pub fn lane_sum(values: &[f32]) -> f32 {
    let mut acc = [0.0f32; 8];
    let chunks = values.chunks_exact(8);
    let rest = chunks.remainder();
    for c in chunks {
        for (a, v) in acc.iter_mut().zip(c) {
            *a += v;
        }
    }
    let mut total = ((acc[0] + acc[4]) + (acc[1] + acc[5])) + ((acc[2] + acc[6]) + (acc[3] + acc[7]));
    for v in rest {
        total += v;
    }
    total
}

/// Minimum with eight lanes (NaN is ignored, as by `f32::min`); +∞ for an empty slice.
#[inline]
pub fn lane_min(values: &[f32]) -> f32 {
    let mut acc = [f32::INFINITY; 8];
    let chunks = values.chunks_exact(8);
    let rest = chunks.remainder();
    for c in chunks {
        for (a, v) in acc.iter_mut().zip(c) {
            *a = a.min(*v);
        }
    }
    acc.iter().chain(rest).copied().fold(f32::INFINITY, f32::min)
}

/// Maximum with eight lanes (NaN is ignored, as by `f32::max`); −∞ for an empty slice.
#[inline]
pub fn lane_max(values: &[f32]) -> f32 {
    let mut acc = [f32::NEG_INFINITY; 8];
    let chunks = values.chunks_exact(8);
    let rest = chunks.remainder();
    for c in chunks {
        for (a, v) in acc.iter_mut().zip(c) {
            *a = a.max(*v);
        }
    }
    acc.iter().chain(rest).copied().fold(f32::NEG_INFINITY, f32::max)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_util::rand_vec;

    #[test]
    fn lane_reductions_match_plain_ones() {
        for n in [0, 1, 7, 8, 9, 70, 291] {
            let v: Vec<f32> = rand_vec(n, n as u64 + 1).iter().map(|x| x * 10.0 - 3.0).collect();
            let plain: f64 = v.iter().map(|&x| f64::from(x)).sum();
            assert!((f64::from(lane_sum(&v)) - plain).abs() < 1e-3, "sum of {n}");
            assert_eq!(lane_min(&v), v.iter().copied().fold(f32::INFINITY, f32::min), "min of {n}");
            assert_eq!(lane_max(&v), v.iter().copied().fold(f32::NEG_INFINITY, f32::max), "max of {n}");
        }
    }

    #[test]
    fn fast_exp_matches_std_exp() {
        let mut worst = 0.0f32;
        for k in 0..=870_000 {
            let x = -(k as f32) * 1e-4;
            let (fast, exact) = (exp_nonpositive(x), x.exp());
            worst = worst.max((fast - exact).abs() / exact);
        }
        assert!(worst < 5e-7, "relative error {worst}");
        assert_eq!(exp_nonpositive(0.0), 1.0);
        assert_eq!(exp_nonpositive(-100.0), 0.0);
        assert_eq!(exp_nonpositive(f32::NEG_INFINITY), 0.0);
        assert_eq!(exp_nonpositive(f32::NAN), 0.0);
    }
}
