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
pub(crate) fn exp_nonpositive(x: f32) -> f32 {
    const LOG2E: f32 = std::f32::consts::LOG2_E;
    // ln 2 split so that n·LN2_HI is exact in f32 (Cody & Waite): keeps r accurate for large |n|.
    const LN2_HI: f32 = 0.693_359_4;
    const LN2_LO: f32 = -2.121_944_4e-4;
    let ok = x >= -87.0;
    // (A compare and a select: `f32::min` adds a NaN fix-up, and NaN is not `ok` anyway.)
    let x = if ok && x < 0.0 { x } else { 0.0 };
    // Round to nearest by adding and subtracting 1.5·2²³ (exact for |v| < 2²²; `round` is a libm call on
    // baseline x86-64 and would block vectorisation).
    const MAGIC: f32 = 12_582_912.0;
    let shifted = x * LOG2E + MAGIC;
    let n = shifted - MAGIC;
    let r = (x - n * LN2_HI) - n * LN2_LO;
    let p = 1.0 + r * (1.0 + r * (0.5 + r * (1.0 / 6.0 + r * (1.0 / 24.0 + r * (1.0 / 120.0 + r * (1.0 / 720.0))))));
    // 2^n from the bits of `shifted` = 1.5·2²³ + n, which are MAGIC_BITS + n for the integer n (|n| < 2²²): the
    // same bits as `(n as i32 + 127) << 23`, without a float-to-integer conversion: Rust's `as` saturates, and its
    // vectorised form needs a conversion plus range and NaN fix-ups.
    const MAGIC_BITS: u32 = 0x4B40_0000;
    let scale = f32::from_bits(shifted.to_bits().wrapping_sub(MAGIC_BITS).wrapping_add(127) << 23);
    if ok { p * scale } else { 0.0 }
}

/// The integer value of `v`, which must be integral with |v| < 2²² (checked in debug builds), without a
/// float-to-integer conversion: adding 1.5·2²³ puts v in the low bits of the sum. Rust's `as` saturates, and its
/// vectorised form (a conversion plus range and NaN fix-ups) is several times slower.
#[inline(always)]
pub(crate) fn integral_to_i32(v: f32) -> i32 {
    debug_assert!(v == v.trunc() && v.abs() < 4_194_304.0, "{v} is not a small integer");
    const MAGIC: f32 = 12_582_912.0;
    const MAGIC_BITS: i32 = 0x4B40_0000;
    ((v + MAGIC).to_bits() as i32).wrapping_sub(MAGIC_BITS)
}

/// Sum with eight independent accumulators, combined in a fixed order: vectorisable (a single running float
/// sum is a serial dependency chain) and still deterministic.
#[inline]
pub(crate) fn lane_sum(values: &[f32]) -> f32 {
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
pub(crate) fn lane_min(values: &[f32]) -> f32 {
    let mut acc = [f32::INFINITY; 8];
    let chunks = values.chunks_exact(8);
    let rest = chunks.remainder();
    for c in chunks {
        for (a, v) in acc.iter_mut().zip(c) {
            // A compare and a select (`f32::min` adds a NaN fix-up): a NaN value compares false and is skipped,
            // as `f32::min` skips it.
            *a = if *v < *a { *v } else { *a };
        }
    }
    acc.iter().chain(rest).copied().fold(f32::INFINITY, |a, v| if v < a { v } else { a })
}

/// Maximum with eight lanes (NaN is ignored, as by `f32::max`); −∞ for an empty slice.
#[inline]
pub(crate) fn lane_max(values: &[f32]) -> f32 {
    let mut acc = [f32::NEG_INFINITY; 8];
    let chunks = values.chunks_exact(8);
    let rest = chunks.remainder();
    for c in chunks {
        for (a, v) in acc.iter_mut().zip(c) {
            *a = if *v > *a { *v } else { *a };
        }
    }
    acc.iter().chain(rest).copied().fold(f32::NEG_INFINITY, |a, v| if v > a { v } else { a })
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
            // NaN is skipped as by `f32::min` / `f32::max`, also inside the lanes (their compares and selects).
            let mut with_nan = v.clone();
            with_nan.iter_mut().step_by(3).for_each(|x| *x = f32::NAN);
            let finite = || with_nan.iter().copied().filter(|x| !x.is_nan());
            assert_eq!(lane_min(&with_nan), finite().fold(f32::INFINITY, f32::min), "min of {n} with NaN");
            assert_eq!(lane_max(&with_nan), finite().fold(f32::NEG_INFINITY, f32::max), "max of {n} with NaN");
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
        for v in [0.0f32, 1.0, -1.0, 126.0, -126.0, 31_200.0, -31_200.0, 4_194_303.0, -4_194_303.0] {
            assert_eq!(integral_to_i32(v), v as i32, "{v}");
        }
        // 2^n from the bits of the rounding sum, against the integer conversion it replaced, bit for bit.
        for k in 0..=1_000_000 {
            let x = -(k as f32) * 8.7e-5;
            let n = (x * std::f32::consts::LOG2_E + 12_582_912.0) - 12_582_912.0;
            let by_cast = f32::from_bits(((n as i32 + 127) as u32) << 23);
            let by_bits = f32::from_bits(
                (x * std::f32::consts::LOG2_E + 12_582_912.0).to_bits().wrapping_sub(0x4B40_0000).wrapping_add(127)
                    << 23,
            );
            assert_eq!(by_cast.to_bits(), by_bits.to_bits(), "2^n at x = {x}");
        }
        assert_eq!(exp_nonpositive(0.0), 1.0);
        assert_eq!(exp_nonpositive(-100.0), 0.0);
        assert_eq!(exp_nonpositive(f32::NEG_INFINITY), 0.0);
        assert_eq!(exp_nonpositive(f32::NAN), 0.0);
    }
}
