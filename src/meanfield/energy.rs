//! One pixel's energies and their softmax (paper §3, eqs. 7–9 and the update of Algorithm 1), and the local
//! term's edge weights (paper eq. 8).
//!
//! E(d) = `unary_scale`·cost(d) − ω·Q̃(d) − ω̃·(P̃(d) + (1 − β)(P̃(d−1) + P̃(d+1))), with the label-independent
//! constants left out (they cancel in the softmax), then Q = softmax(−E). Also here, our addition: the floor
//! under tiny probabilities ([`MIN_RELATIVE_PROBABILITY`]) that keeps subnormal floats out of the lattice.

use rayon::prelude::*;

use crate::fastmath::{exp_nonpositive, lane_min, lane_sum};
use crate::image::{Plane, RgbImage};
use crate::params::MeanFieldParams;

/// Local edge weights w̃(i, j) towards the right and lower neighbours (the left/upper ones are their mirrors).
#[derive(Clone, Debug)]
pub(crate) struct LocalWeights {
    /// w̃ between (x, y) and (x+1, y); 0 in the last column.
    pub right: Plane<f32>,
    /// w̃ between (x, y) and (x, y+1); 0 in the last row.
    pub down: Plane<f32>,
}

/// w̃ = λ1 if Σ_rgb |I_i − I_j| < μ1, λ2 if < μ2, else λ3 (paper eq. 8).
pub(crate) fn local_edge_weight(a: [f32; 3], b: [f32; 3], p: &MeanFieldParams) -> f32 {
    let diff = (a[0] - b[0]).abs() + (a[1] - b[1]).abs() + (a[2] - b[2]).abs();
    if diff < p.mu1 {
        p.lambda1
    } else if diff < p.mu2 {
        p.lambda2
    } else {
        p.lambda3
    }
}

/// Computes the 4-neighbour edge weights of an image.
pub(crate) fn local_weights(image: &RgbImage, p: &MeanFieldParams) -> LocalWeights {
    let (w, h) = image.dims();
    let mut right = Plane::new(w, h, 0.0f32);
    let mut down = Plane::new(w, h, 0.0f32);
    // Row by row in parallel: every weight depends on its two pixels only.
    right.data.par_chunks_mut(w.max(1)).zip(down.data.par_chunks_mut(w.max(1))).enumerate().for_each(
        |(y, (right, down))| {
            for x in 0..w {
                let i = y * w + x;
                if x + 1 < w {
                    right[x] = local_edge_weight(image.rgb(i), image.rgb(i + 1), p);
                }
                if y + 1 < h {
                    down[x] = local_edge_weight(image.rgb(i), image.rgb(i + w), p);
                }
            }
        },
    );
    LocalWeights { right, down }
}

/// The local term's contribution to E_i(d) for all d, given P̃_i (the O(M) form without the constant S_i):
/// `out[d] += −ω̃·(P̃(d) + (1 − β)(P̃(d−1) + P̃(d+1)))`. (The update computes the same through
/// its one-pass energy function; this form is for tests and callers with an unpadded P̃.)
#[cfg(test)]
pub(crate) fn add_local_energy(p_tilde: &[f32], omega: f32, beta: f32, out: &mut [f32]) {
    let m = p_tilde.len();
    let mut padded = vec![0.0f32; m + 2];
    padded[1..=m].copy_from_slice(p_tilde);
    let mut term = vec![0.0f32; m];
    pixel_energies(&vec![0.0; m], 0.0, None, Some(LocalTerm { p_padded: &padded, omega, beta }), &mut term);
    out.iter_mut().zip(&term).for_each(|(o, t)| *o += t);
}

/// The fully connected term of one pixel: Q̃(l) = `out_scale`·(`msg`(l) − `self_weight`·`own`(l)), clamped at 0.
#[derive(Clone, Copy)]
pub(super) struct FullTerm<'s> {
    pub(super) msg: &'s [f32],
    pub(super) own: &'s [f32],
    pub(super) omega: f32,
    pub(super) out_scale: f32,
    pub(super) self_weight: f32,
}

/// The local term of one pixel: P̃ with a zero at each end (`p_padded[d + 1]` = P̃(d)), ω̃ and β.
#[derive(Clone, Copy)]
pub(super) struct LocalTerm<'s> {
    pub(super) p_padded: &'s [f32],
    pub(super) omega: f32,
    pub(super) beta: f32,
}

/// E(d) = `unary_scale`·cost(d) − ω·Q̃(d) − ω̃·(P̃(d) + (1 − β)(P̃(d−1) + P̃(d+1))) into `en`, in one pass, with
/// either pairwise term optional (the label-independent constants are left out; see the module doc of [`crate::meanfield`]).
#[inline(always)]
pub(super) fn pixel_energies(
    cost: &[f32],
    unary_scale: f32,
    full: Option<FullTerm<'_>>,
    local: Option<LocalTerm<'_>>,
    en: &mut [f32],
) {
    let m = en.len();
    let cost = &cost[..m];
    match (full, local) {
        (None, None) => en.iter_mut().zip(cost).for_each(|(e, c)| *e = unary_scale * c),
        (Some(f), None) => {
            let (msg, own, k) = (&f.msg[..m], &f.own[..m], f.omega * f.out_scale);
            for d in 0..m {
                en[d] = unary_scale * cost[d] - k * non_negative(msg[d] - f.self_weight * own[d]);
            }
        }
        (None, Some(l)) => {
            let (p, kb) = (&l.p_padded[..m + 2], 1.0 - l.beta);
            for d in 0..m {
                en[d] = unary_scale * cost[d] - l.omega * (p[d + 1] + kb * (p[d] + p[d + 2]));
            }
        }
        (Some(f), Some(l)) => {
            let (msg, own, k) = (&f.msg[..m], &f.own[..m], f.omega * f.out_scale);
            let (p, kb) = (&l.p_padded[..m + 2], 1.0 - l.beta);
            for d in 0..m {
                en[d] = unary_scale * cost[d]
                    - k * non_negative(msg[d] - f.self_weight * own[d])
                    - l.omega * (p[d + 1] + kb * (p[d] + p[d + 2]));
            }
        }
    }
}

/// max(v, 0) as a compare and a select (`f32::max` adds a NaN fix-up; NaN gives 0 either way).
#[inline(always)]
fn non_negative(v: f32) -> f32 {
    if v > 0.0 { v } else { 0.0 }
}

/// Labels less likely than this, relative to a pixel's most likely label, get probability 0.
///
/// Without a floor, cold marginals (a large unary scale) carry values down to e^−87 ≈ 1e−38, which the lattice's
/// splat weights and blur turn into subnormal floats, and x86 computes with those through microcode assists, tens
/// of times slower. At 1e−20 every value that reaches the lattice stays a normal float; the probabilities removed
/// are far below anything that can change a decision.
pub(crate) const MIN_RELATIVE_PROBABILITY: f32 = 1e-20;

/// e^x for x ≤ 0, or 0 below [`MIN_RELATIVE_PROBABILITY`].
#[inline(always)]
fn unnormalised_weight(x: f32) -> f32 {
    let v = exp_nonpositive(x);
    if v < MIN_RELATIVE_PROBABILITY { 0.0 } else { v }
}

/// `out ← softmax(−en[..M])`, M = `out.len()`, bit-identical to [`softmax_neg_in_place`] on a copy of
/// `en[..M]`, with the exponentials computed into `ex`: `en` and `ex` have the same length, padded past M to
/// whole vectors of 8 lanes (`en`'s padding finite), so the exp loop has no scalar tail; the reductions still
/// see exactly M values.
#[inline(always)]
pub(super) fn softmax_neg_padded(en: &[f32], ex: &mut [f32], out: &mut [f32]) {
    let m = out.len();
    let min = lane_min(&en[..m]);
    let min = if min.is_finite() { min } else { 0.0 };
    for (x, e) in ex.iter_mut().zip(en) {
        *x = unnormalised_weight(min - e);
    }
    let sum = lane_sum(&ex[..m]);
    if sum > 0.0 && sum.is_finite() {
        let inv = 1.0 / sum;
        out.iter_mut().zip(&ex[..m]).for_each(|(o, v)| *o = v * inv);
    } else {
        out.fill(1.0 / m as f32);
    }
}

/// In place: `e ← softmax(−e)`, subtracting the minimum energy first.
#[inline(always)]
pub(super) fn softmax_neg_in_place(e: &mut [f32]) {
    let min = lane_min(e);
    let min = if min.is_finite() { min } else { 0.0 };
    for v in e.iter_mut() {
        *v = unnormalised_weight(min - *v);
    }
    normalise(e);
}

/// Divides non-negative weights by their sum, or, if the sum is 0 or not finite (only with non-finite
/// energies), makes them uniform rather than NaN.
#[inline(always)]
fn normalise(q: &mut [f32]) {
    let sum = lane_sum(q);
    if sum > 0.0 && sum.is_finite() {
        let inv = 1.0 / sum;
        q.iter_mut().for_each(|v| *v *= inv);
    } else {
        let u = 1.0 / q.len() as f32;
        q.iter_mut().for_each(|v| *v = u);
    }
}

/// Q = softmax(−`scale`·cost) for consecutive pixels of `m` labels. Compiled for AVX2 + FMA as well (same
/// results).
#[cfg_attr(not(feature = "force-baseline"), multiversion::multiversion(targets("x86_64+avx2+fma")))]
pub(super) fn unary_marginals(cost: &[f32], scale: f32, m: usize, q: &mut [f32]) {
    for (e, c) in q.chunks_exact_mut(m).zip(cost.chunks_exact(m)) {
        e.iter_mut().zip(c).for_each(|(v, c)| *v = c * scale);
        softmax_neg_in_place(e);
    }
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)] // index loops read best in reference implementations
mod tests {
    use super::*;
    use crate::test_util::rand_vec;

    #[test]
    fn meanfield_local_message_o_m_form_equals_naive_sum() {
        let m = 9;
        let (omega, beta) = (1.7, 0.35);
        let p_tilde: Vec<f32> = rand_vec(m, 3).iter().map(|v| v * 4.0).collect();
        // Naive O(M²): P̂(d) = ω̃ Σ_l φ̃(d, l) P̃(l).
        let phi = |d: usize, l: usize| match d.abs_diff(l) {
            0 => 0.0,
            1 => beta,
            _ => 1.0,
        };
        let naive: Vec<f32> = (0..m).map(|d| omega * (0..m).map(|l| phi(d, l) * p_tilde[l]).sum::<f32>()).collect();
        // O(M) form without the constant ω̃·S, which add_local_energy leaves out.
        let mut fast = vec![0.0; m];
        add_local_energy(&p_tilde, omega, beta, &mut fast);
        let s: f32 = p_tilde.iter().sum();
        for d in 0..m {
            assert!(
                (fast[d] + omega * s - naive[d]).abs() < 1e-4,
                "label {d}: {} vs {}",
                fast[d] + omega * s,
                naive[d]
            );
        }
    }

    #[test]
    fn meanfield_padded_softmax_is_bit_identical_to_in_place() {
        for m in [1usize, 5, 8, 13, 70, 191] {
            let lanes = m.next_multiple_of(8);
            let mut en: Vec<f32> = rand_vec(lanes, m as u64).iter().map(|v| v * 40.0 - 10.0).collect();
            if m > 5 {
                en[3] = f32::INFINITY;
            }
            for all_infinite in [false, true] {
                if all_infinite {
                    en[..m].fill(f32::INFINITY);
                }
                let mut reference = en[..m].to_vec();
                softmax_neg_in_place(&mut reference);
                let (mut exps, mut out) = (vec![0.0; lanes], vec![0.0; m]);
                softmax_neg_padded(&en, &mut exps, &mut out);
                assert!(out.iter().zip(&reference).all(|(a, b)| a.to_bits() == b.to_bits()), "m = {m}");
            }
        }
    }

    /// The one-pass energy with both pairwise terms against the terms written out separately.
    #[test]
    fn meanfield_pixel_energies_match_the_terms() {
        let m = 11;
        let (cost, msg, own) = (rand_vec(m, 1), rand_vec(m, 2), rand_vec(m, 3));
        let p_tilde: Vec<f32> = rand_vec(m, 4).iter().map(|v| v * 3.0).collect();
        let mut p_padded = vec![0.0; m + 2];
        p_padded[1..=m].copy_from_slice(&p_tilde);
        let (us, fcm, out_scale, self_weight, lcm, beta) = (0.7, 9.0, 0.3, 0.8, 2.0, 0.25);
        let full = FullTerm { msg: &msg, own: &own, omega: fcm, out_scale, self_weight };
        let local = LocalTerm { p_padded: &p_padded, omega: lcm, beta };
        let mut en = vec![0.0; m];
        pixel_energies(&cost, us, Some(full), Some(local), &mut en);
        let mut expected: Vec<f32> =
            (0..m).map(|d| us * cost[d] - fcm * out_scale * (msg[d] - self_weight * own[d]).max(0.0)).collect();
        add_local_energy(&p_tilde, lcm, beta, &mut expected);
        for d in 0..m {
            assert!((en[d] - expected[d]).abs() < 1e-5, "label {d}: {} vs {}", en[d], expected[d]);
        }
    }
}
