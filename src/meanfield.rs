//! Joint mean-field inference on the FCM + LCM energy (paper §3, Algorithm 1; SPEC §3).
//!
//! Q_i(d) ∝ exp(−ψ_u(d) − Q̂_i(d) − P̂_i(d)), all pixels updated from the previous iterate (Jacobi), where
//! - ψ_u = `unary_scale` × cost (the cost volume as a log-likelihood up to a temperature);
//! - the fully connected Potts message Q̂_i(d) = ω·(Σ_l Q̃_i(l) − Q̃_i(d)), Q̃_i(l) = Σ_{j≠i} k(i, j) Q_j(l), with
//!   Q̃ from the permutohedral lattice ([`crate::lattice`]) for all labels at once, optionally normalised
//!   ([`Normalization`]) and without the pixel's own term (`exclude_self`, the paper's j ≠ i);
//! - the local message P̂_i(d) = ω̃·Σ_l φ̃(d, l) P̃_i(l), P̃_i(l) = Σ_{j∈N4(i)} w̃(i, j) Q_j(l), in its O(M) form
//!   P̂_i(d) = ω̃·(S_i − P̃_i(d) − (1 − β)(P̃_i(d−1) + P̃_i(d+1))), S_i = Σ_l P̃_i(l).
//!
//! The terms ω·Σ_l Q̃_i(l) and ω̃·S_i do not depend on d, so they cancel in the normalisation of Q_i and are not
//! computed; the update uses E_i(d) = ψ_u(d) − ω·Q̃_i(d) − ω̃·(P̃_i(d) + (1 − β)(P̃_i(d−1) + P̃_i(d+1))), and
//! Q_i = softmax(−E_i) with the maximum subtracted first (no overflow, never NaN for finite costs).
//!
//! Deterministic annealing (`unary_scale_start` > 0, off by default): the unary temperature changes over the
//! iterations, geometrically from `unary_scale_start` (the initial marginals) to `unary_scale` (the last
//! iteration); see [`UnarySchedule`]. Starting hot (a small scale) keeps the marginals soft while the neighbours'
//! evidence accumulates, ending cold sharpens them to the unary's full strength, the classic remedy for mean
//! field freezing into its first, winner-take-all-like state.
//!
//! Label-aware local coupling (`lcm_weight_ref_labels` > 0, off by default): ω̃ is multiplied by M / reference.
//! Around the uniform marginal the softmax has slope 1/M, so a perturbation of the neighbours' marginals comes
//! back amplified by ~ω̃·Σ_j w̃(i, j)·(3 − 2β) / M: with a fixed ω̃ the local term propagates evidence through diffuse
//! regions far less for M = 190 than for M = 60 (and a hot start, which keeps the marginals diffuse for longer,
//! ruins the large-range scenes). Scaling ω̃ with M keeps that gain the same for every M. Measured on trainingQ
//! in docs/RESULTS.md ("Sweep log: LCM — annealing / label-aware temperature").
//!
//! Models: `lcm` sets ω = 0, `fcm` sets ω̃ = 0 (same code path). After T iterations the disparity is argmax Q (the
//! paper's WTA) with an optional sub-pixel offset from a parabola through ln Q at d−1, d, d+1; the confidence is
//! max Q.
//!
//! Default normalisation: the paper writes the message unnormalised (Σ_{j≠i} k(i,j) Q_j). Its magnitude then
//! depends on how many similar pixels surround i (≈ 2πσx² = 157 in a uniform region, a few near thin
//! structures), so one ω cannot suit both; we default to `symmetric` (D^{-1/2} K D^{-1/2}, as in Krähenbühl's
//! dense-CRF code), chosen by measurement on trainingQ (docs/RESULTS.md); `none` and `pixel` remain available.
//!
//! Memory: Q, `N × M` f32 (and the next Q with the Jacobi schedule; the checkerboard updates Q in place), plus
//! the lattice's two `vertices × M` buffers (the fully connected message is sliced per pixel inside the update,
//! never stored); each iteration is O(N·M) and allocation-free apart from a few `M`-long scratch vectors per
//! thread.

use multiversion::multiversion;
use rayon::prelude::*;

use crate::fastmath::{exp_nonpositive, lane_max, lane_min, lane_sum};
use crate::image::{CostVolume, DisparityMap, Plane, RgbImage};
use crate::lattice::{Lattice, LatticeScratch};
use crate::params::{MeanFieldParams, Normalization, Schedule};

/// Per-pixel label distributions, laid out like a [`CostVolume`]: `data[(y·w + x)·M + d]`.
pub type Marginals = CostVolume;

/// The weights of the two pairwise terms for one run (0 switches a term off).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PairwiseWeights {
    /// ω, fully connected.
    pub fcm: f32,
    /// ω̃, locally connected.
    pub lcm: f32,
}

/// Local edge weights w̃(i, j) towards the right and lower neighbours (the left/upper ones are their mirrors).
#[derive(Clone, Debug)]
pub struct LocalWeights {
    /// w̃ between (x, y) and (x+1, y); 0 in the last column.
    pub right: Plane<f32>,
    /// w̃ between (x, y) and (x, y+1); 0 in the last row.
    pub down: Plane<f32>,
}

/// w̃ = λ1 if Σ_rgb |I_i − I_j| < μ1, λ2 if < μ2, else λ3 (paper eq. 8).
pub fn local_edge_weight(a: [f32; 3], b: [f32; 3], p: &MeanFieldParams) -> f32 {
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
pub fn local_weights(image: &RgbImage, p: &MeanFieldParams) -> LocalWeights {
    let (w, h) = image.dims();
    let mut right = Plane::new(w, h, 0.0f32);
    let mut down = Plane::new(w, h, 0.0f32);
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            if x + 1 < w {
                right.data[i] = local_edge_weight(image.rgb(i), image.rgb(i + 1), p);
            }
            if y + 1 < h {
                down.data[i] = local_edge_weight(image.rgb(i), image.rgb(i + w), p);
            }
        }
    }
    LocalWeights { right, down }
}

/// The local term's contribution to E_i(d) for all d, given P̃_i (the O(M) form without the constant S_i):
/// `out[d] += −ω̃·(P̃(d) + (1 − β)(P̃(d−1) + P̃(d+1)))`. (The update computes the same through
/// its one-pass energy function; this form is for tests and callers with an unpadded P̃.)
pub fn add_local_energy(p_tilde: &[f32], omega: f32, beta: f32, out: &mut [f32]) {
    let m = p_tilde.len();
    let mut padded = vec![0.0f32; m + 2];
    padded[1..=m].copy_from_slice(p_tilde);
    let mut term = vec![0.0f32; m];
    pixel_energies(&vec![0.0; m], 0.0, None, Some(LocalTerm { p_padded: &padded, omega, beta }), &mut term);
    out.iter_mut().zip(&term).for_each(|(o, t)| *o += t);
}

/// The fully connected term of one pixel: Q̃(l) = `out_scale`·(`msg`(l) − `self_weight`·`own`(l)), clamped at 0.
#[derive(Clone, Copy)]
struct FullTerm<'s> {
    msg: &'s [f32],
    own: &'s [f32],
    omega: f32,
    out_scale: f32,
    self_weight: f32,
}

/// The local term of one pixel: P̃ with a zero at each end (`p_padded[d + 1]` = P̃(d)), ω̃ and β.
#[derive(Clone, Copy)]
struct LocalTerm<'s> {
    p_padded: &'s [f32],
    omega: f32,
    beta: f32,
}

/// E(d) = `unary_scale`·cost(d) − ω·Q̃(d) − ω̃·(P̃(d) + (1 − β)(P̃(d−1) + P̃(d+1))) into `en`, in one pass, with
/// either pairwise term optional (SPEC §3; the label-independent constants are left out).
#[inline(always)]
fn pixel_energies(
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
                en[d] = unary_scale * cost[d] - k * (msg[d] - f.self_weight * own[d]).max(0.0);
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
                    - k * (msg[d] - f.self_weight * own[d]).max(0.0)
                    - l.omega * (p[d + 1] + kb * (p[d] + p[d + 2]));
            }
        }
    }
}

/// Labels less likely than this, relative to a pixel's most likely label, get probability 0.
///
/// Without a floor, cold marginals (a large unary scale) carry values down to e^−87 ≈ 1e−38, which the lattice's
/// splat weights and blur turn into subnormal floats, and x86 computes with those through microcode assists, tens
/// of times slower (one JEM iteration of `jem-lrc.toml` on Motorcycle Q went from ~90 to ~160 ms at unary scale
/// 1.0). At 1e−20 every value that reaches the lattice stays a normal float; the probabilities removed are far
/// below anything that can change a decision.
pub const MIN_RELATIVE_PROBABILITY: f32 = 1e-20;

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
fn softmax_neg_padded(en: &[f32], ex: &mut [f32], out: &mut [f32]) {
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
fn softmax_neg_in_place(e: &mut [f32]) {
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
#[multiversion(targets("x86_64+avx2+fma"))]
fn unary_marginals(cost: &[f32], scale: f32, m: usize, q: &mut [f32]) {
    for (e, c) in q.chunks_exact_mut(m).zip(cost.chunks_exact(m)) {
        e.iter_mut().zip(c).for_each(|(v, c)| *v = c * scale);
        softmax_neg_in_place(e);
    }
}

/// The weights `weights` with the label-aware local coupling of `p` applied for `m` labels: ω̃ × m /
/// `lcm_weight_ref_labels`, or unchanged when that is 0.
pub fn label_aware_weights(weights: PairwiseWeights, p: &MeanFieldParams, m: usize) -> PairwiseWeights {
    if p.lcm_weight_ref_labels == 0 {
        return weights;
    }
    PairwiseWeights { lcm: weights.lcm * (m as f32 / p.lcm_weight_ref_labels as f32), ..weights }
}

/// The unary scale (inverse temperature of the cost) of each mean-field iteration.
///
/// Without annealing (`unary_scale_start` = 0) every iteration uses `unary_scale`. With it, step t (0 = the
/// initial marginals, 1..=T the iterations) uses s_t = s_0·(s_K / s_0)^(t/K), s_0 = `unary_scale_start`,
/// s_K = `unary_scale`, K = `unary_anneal_iterations` (0 = T): a geometric schedule, i.e. equal ratios between
/// consecutive temperatures, reaching `unary_scale` exactly at step K and staying there. With T = 0 there is
/// nothing to anneal and the initial marginals use `unary_scale`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UnarySchedule {
    start: f32,
    end: f32,
    iterations: usize,
}

impl UnarySchedule {
    /// The schedule configured in `p`.
    pub fn new(p: &MeanFieldParams) -> Self {
        let iterations = if p.unary_anneal_iterations > 0 { p.unary_anneal_iterations } else { p.iterations };
        UnarySchedule { start: p.unary_scale_start, end: p.unary_scale, iterations }
    }

    /// The scale of step `t` (0 = the initial marginals, 1..=T the iterations).
    pub fn at(&self, t: usize) -> f32 {
        if self.start <= 0.0 || self.iterations == 0 || t >= self.iterations {
            return self.end;
        }
        let frac = t as f64 / self.iterations as f64;
        let (start, end) = (f64::from(self.start), f64::from(self.end));
        (start * (end / start).powf(frac)) as f32
    }
}

/// Large buffers a [`MeanField`] can take over from a previous one (the other view), so that they are not
/// allocated and page-faulted again.
#[derive(Debug, Default)]
pub struct Buffers {
    q: Vec<f32>,
    next: Vec<f32>,
    scratch: LatticeScratch,
}

impl Buffers {
    /// Gives back an `N × M` allocation that is no longer needed (old marginals, a dropped cost volume): the next
    /// [`MeanField`] keeps its marginals in it.
    pub fn recycle(&mut self, storage: Vec<f32>) {
        self.q = storage;
    }

    /// Takes the spare `N × M` allocation out (empty if there is none), e.g. to build a cost volume in it.
    pub fn take_spare(&mut self) -> Vec<f32> {
        std::mem::take(&mut self.q)
    }
}

/// Per-thread scratch of the row update, `M` labels.
struct RowScratch {
    /// The sliced fully connected message.
    msg: Vec<f32>,
    /// P̃ with a zero at each end.
    p_padded: Vec<f32>,
    /// The energies E(d), padded with zeros to a multiple of 8 labels.
    energy: Vec<f32>,
    /// exp(min E − E(d)), as long as `energy`.
    exps: Vec<f32>,
    /// A row of zeros standing in for missing neighbours.
    zeros: Vec<f32>,
}

impl RowScratch {
    fn new(m: usize) -> Self {
        let lanes = m.next_multiple_of(8);
        RowScratch {
            msg: vec![0.0; m],
            p_padded: vec![0.0; m + 2],
            energy: vec![0.0; lanes],
            exps: vec![0.0; lanes],
            zeros: vec![0.0; m],
        }
    }
}

/// Which pixels one update pass computes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Pass {
    All,
    Even,
    Odd,
}

/// Mean-field state for one view: build once, then [`MeanField::step`] T times.
pub struct MeanField<'a> {
    cost: &'a CostVolume,
    /// The unary scale of the current step, from `unary_schedule`.
    unary_scale: f32,
    unary_schedule: UnarySchedule,
    /// Iterations done so far.
    done: usize,
    weights: PairwiseWeights,
    beta: f32,
    schedule: Schedule,
    lattice: Option<Lattice>,
    local: LocalWeights,
    /// Per-pixel factor applied to Q before filtering (symmetric normalisation) — empty if 1.
    in_scale: Vec<f32>,
    /// Per-pixel factor applied to the filtered message — empty if 1.
    out_scale: Vec<f32>,
    /// Per-pixel self-weight to subtract (scaled like the input) — empty if the self term is kept.
    self_weight: Vec<f32>,
    q: Vec<f32>,
    /// The next Q (Jacobi schedule only; the checkerboard updates Q in place).
    next: Vec<f32>,
    /// Two rows per band of rows for the in-place checkerboard.
    edges: Vec<f32>,
    scratch: LatticeScratch,
}

impl<'a> MeanField<'a> {
    /// Prepares inference: the lattice (only if ω > 0), the local weights, and Q initialised to softmax(−ψ_u).
    ///
    /// # Panics
    /// If the image and the cost volume differ in size.
    pub fn new(cost: &'a CostVolume, image: &RgbImage, p: &MeanFieldParams, weights: PairwiseWeights) -> Self {
        Self::with_buffers(cost, image, p, weights, Buffers::default())
    }

    /// Like [`MeanField::new`], reusing `buffers` (from [`MeanField::into_marginals_and_buffers`]).
    ///
    /// # Panics
    /// If the image and the cost volume differ in size.
    pub fn with_buffers(
        cost: &'a CostVolume,
        image: &RgbImage,
        p: &MeanFieldParams,
        weights: PairwiseWeights,
        buffers: Buffers,
    ) -> Self {
        Self::build(cost, image, p, weights, buffers, None)
    }

    /// Like [`MeanField::with_buffers`], but Q starts from the marginals of a level reduced 2 times instead of
    /// the unary: every pixel takes its 2 × 2 block's (coarse-to-fine inference, [`infer_coarse_to_fine`]).
    ///
    /// # Panics
    /// If the image and the cost volume differ in size, or `coarse` is not their size reduced 2 times or has
    /// another number of labels.
    pub fn from_coarse(
        cost: &'a CostVolume,
        image: &RgbImage,
        p: &MeanFieldParams,
        weights: PairwiseWeights,
        buffers: Buffers,
        coarse: &Marginals,
    ) -> Self {
        Self::build(cost, image, p, weights, buffers, Some(coarse))
    }

    /// The constructors' common body: Q from `coarse` if given, else softmax(−ψ_u).
    fn build(
        cost: &'a CostVolume,
        image: &RgbImage,
        p: &MeanFieldParams,
        weights: PairwiseWeights,
        buffers: Buffers,
        coarse: Option<&Marginals>,
    ) -> Self {
        assert_eq!((cost.width, cost.height), image.dims(), "cost volume and image differ in size");
        let n = image.len();
        let m = cost.ndisp;
        let weights = label_aware_weights(weights, p, m);
        let lattice = (weights.fcm > 0.0).then(|| Lattice::build(image, p.sigma_xy, p.sigma_rgb));
        let (mut in_scale, mut out_scale, mut self_weight) = (Vec::new(), Vec::new(), Vec::new());
        if let Some(lat) = &lattice {
            let mut norm = vec![0.0f32; n];
            lat.filter(&vec![1.0f32; n], &mut norm, 1, &mut LatticeScratch::default());
            let sw = lat.self_weight();
            if p.exclude_self {
                // Never let the normaliser reach 0: a pixel with no similar neighbours gets a tiny message.
                norm.iter_mut().zip(sw).for_each(|(v, s)| *v = (*v - s).max(1e-3));
            }
            match p.normalization {
                Normalization::None => {}
                Normalization::Pixel => out_scale = norm.iter().map(|v| 1.0 / v).collect(),
                Normalization::Symmetric => {
                    in_scale = norm.iter().map(|v| 1.0 / v.sqrt()).collect();
                    out_scale = in_scale.clone();
                }
            }
            if p.exclude_self {
                self_weight = sw.to_vec();
            }
        }
        let Buffers { mut q, mut next, scratch } = buffers;
        // Fresh buffers are zeroed by the OS (no fill pass); Q is then written in parallel, and `next` (needed by
        // the Jacobi schedule only) is written by each iteration before it is read.
        if q.len() != n * m {
            q = vec![0.0; n * m];
        }
        let next_len = if p.schedule == Schedule::Jacobi { n * m } else { 0 };
        if next.len() != next_len {
            next = vec![0.0; next_len];
        }
        let edges = match p.schedule {
            Schedule::Jacobi => Vec::new(),
            Schedule::Checkerboard => {
                vec![0.0; 2 * checkerboard_bands(cost.height, rayon::current_num_threads()).len() * cost.width * m]
            }
        };
        let unary_schedule = UnarySchedule::new(p);
        let scale = unary_schedule.at(0);
        match coarse {
            Some(coarse) => copy_from_coarse(&mut q, cost.width, cost.height, m, coarse),
            None => {
                const CHUNK: usize = 256;
                q.par_chunks_mut(m * CHUNK).zip(cost.data.par_chunks(m * CHUNK)).for_each(|(q, c)| {
                    unary_marginals(c, scale, m, q);
                });
            }
        }
        MeanField {
            cost,
            unary_scale: scale,
            unary_schedule,
            done: 0,
            weights,
            beta: p.beta,
            schedule: p.schedule,
            lattice,
            local: local_weights(image, p),
            in_scale,
            out_scale,
            self_weight,
            q,
            next,
            edges,
            scratch,
        }
    }

    /// One mean-field iteration over all pixels, with the configured [`Schedule`] and the next unary scale of the
    /// [`UnarySchedule`].
    pub fn step(&mut self) {
        self.done += 1;
        self.unary_scale = self.unary_schedule.at(self.done);
        let m = self.cost.ndisp;
        let mut next = std::mem::take(&mut self.next);
        let mut q = std::mem::take(&mut self.q);
        let mut scratch = std::mem::take(&mut self.scratch);
        let mut edges = std::mem::take(&mut self.edges);
        let vals: &[f32] = match &self.lattice {
            Some(lat) => {
                let scale = (!self.in_scale.is_empty()).then_some(self.in_scale.as_slice());
                lat.splat_blur(&q, scale, m, &mut scratch)
            }
            None => &[],
        };
        let this = &*self;
        match self.schedule {
            Schedule::Jacobi => {
                this.sweep(Pass::All, &q, true, vals, &mut next);
                std::mem::swap(&mut q, &mut next);
            }
            Schedule::Checkerboard => {
                let bands = checkerboard_bands(self.cost.height, rayon::current_num_threads());
                // Sized in `with_buffers` for the current thread count; only a different pool resizes it.
                edges.resize(2 * bands.len() * self.cost.width * m, 0.0);
                this.checkerboard_in_place(&mut q, vals, &bands, &mut edges);
            }
        }
        self.q = q;
        self.scratch = scratch;
        self.next = next;
        self.edges = edges;
    }

    /// Red-black update in two sweeps over the image: pass 1 computes the pixels with x + y even from the
    /// previous Q into `next`; pass 2 the odd ones, whose 4 neighbours are all even, from the pass-1 values,
    /// written over the previous Q (each pixel reads its own old value first), with the even ones copied in.
    /// The reference for [`MeanField::checkerboard_in_place`].
    #[cfg(test)]
    fn checkerboard_two_pass(&self, q: &mut [f32], next: &mut [f32], vals: &[f32]) {
        self.sweep(Pass::Even, q, true, vals, next);
        self.sweep(Pass::Odd, next, false, vals, q);
    }

    /// One parallel sweep of `pass` over all rows of `out`: neighbours from `src`, each pixel's own previous
    /// marginal from `src` (`own_in_src`) or from `out` itself.
    fn sweep(&self, pass: Pass, src: &[f32], own_in_src: bool, vals: &[f32], out: &mut [f32]) {
        let m = self.cost.ndisp;
        let len = self.cost.width * m;
        out.par_chunks_mut(len).enumerate().for_each_init(
            || RowScratch::new(m),
            |s, (y, row)| {
                let own = own_in_src.then(|| &src[y * len..][..len]);
                update_row(self, y, pass, NeighbourRows::of(src, y, len), own, vals, row, s);
            },
        );
    }

    /// The same update as [`MeanField::checkerboard_two_pass`] in place, in one buffer: pass 1 writes the even
    /// pixels over their old values (an even pixel reads only odd neighbours and its own old value), pass 2 the
    /// odd ones (reading the new even values). No second N × M buffer, and no copy of the even pixels.
    ///
    /// The rows run in one sweep per band of rows: pass 2 of row y − 1 right after pass 1 of row y, while rows
    /// y − 1 … y + 1 are in cache. Bands run in parallel; each band's first and last rows are read by the
    /// neighbouring bands during the sweep, so their pass 1 goes into `edges` (two rows per band, copies of the
    /// old rows) and is copied back afterwards, when pass 2 of those rows runs. Without bands (fewer than 3 rows)
    /// the two passes run one after the other. Same results as the two sweeps, bit for bit, for any banding.
    fn checkerboard_in_place(&self, q: &mut [f32], vals: &[f32], bands: &[(usize, usize)], edges: &mut [f32]) {
        let m = self.cost.ndisp;
        let len = self.cost.width * m;
        let h = self.cost.height;
        let mut s = RowScratch::new(m);
        if bands.is_empty() {
            for pass in [Pass::Even, Pass::Odd] {
                for y in 0..h {
                    let (nbrs, row) = split_rows(q, y, len);
                    update_row(self, y, pass, nbrs, None, vals, row, &mut s);
                }
            }
            return;
        }
        {
            // Per band: its first and last rows of Q (read-only here), its interior rows (updated in place), and
            // its two edge buffers.
            let mut tasks = Vec::with_capacity(bands.len());
            let mut rest: &mut [f32] = q;
            let mut edge_rest: &mut [f32] = edges;
            for &(a, b) in bands {
                let (band, r) = std::mem::take(&mut rest).split_at_mut((b - a) * len);
                rest = r;
                let (first, r) = band.split_at_mut(len);
                let (interior, last) = r.split_at_mut((b - a - 2) * len);
                let (edge, r) = std::mem::take(&mut edge_rest).split_at_mut(2 * len);
                edge_rest = r;
                let (first_new, last_new) = edge.split_at_mut(len);
                tasks.push(((a, b), (&*first, &*last), interior, (first_new, last_new)));
            }
            let olds: Vec<(&[f32], &[f32])> = tasks.iter().map(|t| t.1).collect();
            let olds = &olds;
            tasks.into_par_iter().enumerate().for_each(
                |(k, ((a, b), (first, last), interior, (first_new, last_new)))| {
                    first_new.copy_from_slice(first);
                    last_new.copy_from_slice(last);
                    let mut s = RowScratch::new(m);
                    let interior_rows = b - a - 2;
                    for y in a..b {
                        // Pass 1 of row y: rows a − 1 and b are the neighbouring bands' (old) edge rows.
                        {
                            let outside_above = (y == a && a > 0).then(|| olds[k - 1].1);
                            let outside_below = (y + 1 == b && b < h).then(|| olds[k + 1].0);
                            band_step(
                                self,
                                Pass::Even,
                                y,
                                (a, b),
                                interior,
                                first_new,
                                last_new,
                                outside_above,
                                outside_below,
                                vals,
                                &mut s,
                            );
                        }
                        // Pass 2 of the interior row y − 1 (rows a + 1 ..= b − 2), now that pass 1 of y is done.
                        if y >= a + 2 && interior_rows > 0 {
                            band_step(
                                self,
                                Pass::Odd,
                                y - 1,
                                (a, b),
                                interior,
                                first_new,
                                last_new,
                                None,
                                None,
                                vals,
                                &mut s,
                            );
                        }
                    }
                },
            );
        }
        // Pass 1 of the edge rows back into Q, then their pass 2 (reading only the even pixels of the rows
        // around, all final now).
        for (&(a, b), edge) in bands.iter().zip(edges.chunks_exact(2 * len)) {
            q[a * len..][..len].copy_from_slice(&edge[..len]);
            q[(b - 1) * len..][..len].copy_from_slice(&edge[len..]);
        }
        for &(a, b) in bands {
            for y in [a, b - 1] {
                let (nbrs, row) = split_rows(q, y, len);
                update_row(self, y, Pass::Odd, nbrs, None, vals, row, &mut s);
            }
        }
    }

    /// Pixel i's message factors: Q̃_i(l) = out_scale · (raw_i(l) − self_w · Q_i(l)), where raw is the lattice
    /// output for the (possibly pre-scaled) marginals.
    #[inline]
    fn message_factors(&self, i: usize) -> (f32, f32) {
        let out_s = self.out_scale.get(i).copied().unwrap_or(1.0);
        let in_s = self.in_scale.get(i).copied().unwrap_or(1.0);
        let self_w = self.self_weight.get(i).copied().unwrap_or(0.0) * in_s;
        (out_s, self_w)
    }

    /// The fully connected message Q̃ (normalised, self term excluded as configured) for the current marginals,
    /// `N × M`; empty when ω = 0. For tests and diagnostics: [`MeanField::step`] computes the same values inline.
    pub fn fcm_message(&mut self) -> Vec<f32> {
        let m = self.cost.ndisp;
        let Some(lat) = &self.lattice else { return Vec::new() };
        let mut scratch = std::mem::take(&mut self.scratch);
        let scale = (!self.in_scale.is_empty()).then_some(self.in_scale.as_slice());
        let vals = lat.splat_blur(&self.q, scale, m, &mut scratch);
        let mut out = vec![0.0; self.q.len()];
        for (i, msg) in out.chunks_exact_mut(m).enumerate() {
            lat.slice(vals, i, msg);
            let (out_s, self_w) = self.message_factors(i);
            for (g, qv) in msg.iter_mut().zip(&self.q[i * m..][..m]) {
                *g = out_s * (*g - self_w * qv).max(0.0);
            }
        }
        self.scratch = scratch;
        out
    }

    /// The current marginals.
    pub fn marginals(&self) -> &[f32] {
        &self.q
    }

    /// Consumes the state, returning the marginals as a volume.
    pub fn into_marginals(self) -> Marginals {
        self.into_marginals_and_buffers().0
    }

    /// Consumes the state, returning the marginals and the buffers for reuse by another [`MeanField`].
    pub fn into_marginals_and_buffers(self) -> (Marginals, Buffers) {
        let (w, h, m) = (self.cost.width, self.cost.height, self.cost.ndisp);
        let buffers = Buffers { q: Vec::new(), next: self.next, scratch: self.scratch };
        (CostVolume { width: w, height: h, ndisp: m, data: self.q }, buffers)
    }
}

/// Computes the new Q for row `y` into `out_row`: neighbours' marginals come from `nbrs` (rows y − 1, y, y + 1;
/// row y from `out_row` itself when `nbrs.same` is `None`), the pixel's own previous marginal (for the self
/// term) from `own_row`, or from `out_row` itself when `None`. `pass` picks the pixels to compute; with
/// [`Pass::Odd`] and a separate `nbrs.same`, the even pixels are copied from it.
/// Compiled for AVX2 + FMA as well, picked at run time (same results: no contraction of a·b + c).
#[allow(clippy::too_many_arguments)]
#[multiversion(targets("x86_64+avx2+fma"))]
fn update_row<'c, 'r>(
    mf: &MeanField<'c>,
    y: usize,
    pass: Pass,
    nbrs: NeighbourRows<'r>,
    own_row: Option<&[f32]>,
    vals: &[f32],
    out_row: &mut [f32],
    s: &mut RowScratch,
) {
    let (w, m) = (mf.cost.width, mf.cost.ndisp);
    let PairwiseWeights { fcm, lcm } = mf.weights;
    let lattice = mf.lattice.as_ref().filter(|_| fcm > 0.0);
    for x in 0..w {
        let i = y * w + x;
        let odd = (x + y) % 2 == 1;
        match pass {
            Pass::All => {}
            Pass::Even if odd => continue,
            Pass::Even => {}
            Pass::Odd if !odd => {
                if let Some(same) = nbrs.same {
                    out_row[x * m..][..m].copy_from_slice(&same[x * m..][..m]);
                }
                continue;
            }
            Pass::Odd => {}
        }
        // The pixel's own slot, and the row's other pixels (its left and right neighbours when updating in
        // place: they are of the other colour, so not written by this pass).
        let (before, rest) = out_row.split_at_mut(x * m);
        let (e, after) = rest.split_at_mut(m);
        let (before, after): (&[f32], &[f32]) = (before, after);
        let own: &[f32] = match own_row {
            Some(r) => &r[x * m..][..m],
            None => e,
        };
        let full = lattice.map(|lat| {
            lat.slice(vals, i, &mut s.msg);
            let (out_scale, self_weight) = mf.message_factors(i);
            FullTerm { msg: &s.msg, own, omega: fcm, out_scale, self_weight }
        });
        let local = (lcm > 0.0).then(|| {
            // Missing neighbours (image border) read a row of zeros with weight 0.
            let zeros = &s.zeros[..];
            let (l, r) = ((x > 0).then(|| x - 1), (x + 1 < w).then_some(x + 1));
            let wts = [
                l.map_or(0.0, |_| mf.local.right.data[i - 1]),
                r.map_or(0.0, |_| mf.local.right.data[i]),
                nbrs.above.map_or(0.0, |_| mf.local.down.data[i - w]),
                nbrs.below.map_or(0.0, |_| mf.local.down.data[i]),
            ];
            let ql = l.map_or(zeros, |l| match nbrs.same {
                Some(same) => &same[l * m..][..m],
                None => &before[l * m..][..m],
            });
            let qr = r.map_or(zeros, |r| match nbrs.same {
                Some(same) => &same[r * m..][..m],
                None => &after[..m],
            });
            let qu = nbrs.above.map_or(zeros, |row| &row[x * m..][..m]);
            let qd = nbrs.below.map_or(zeros, |row| &row[x * m..][..m]);
            // Accumulated in the order left, right, up, down (the sequential reference's order).
            for (k, p) in s.p_padded[1..=m].iter_mut().enumerate() {
                *p = wts[0] * ql[k] + wts[1] * qr[k] + wts[2] * qu[k] + wts[3] * qd[k];
            }
            LocalTerm { p_padded: &s.p_padded, omega: lcm, beta: mf.beta }
        });
        pixel_energies(mf.cost.pixel(i), mf.unary_scale, full, local, &mut s.energy[..m]);
        softmax_neg_padded(&s.energy, &mut s.exps, e);
    }
}

/// One pass over row y of a band `[a, b)` in [`MeanField::checkerboard_in_place`]: the band's interior rows
/// a + 1 … b − 2 are `interior` (updated in place), its first and last rows `first` and `last` (the edge
/// buffers); rows a − 1 and b, outside the band, are `outside_above` and `outside_below` when needed.
#[allow(clippy::too_many_arguments)]
fn band_step(
    mf: &MeanField<'_>,
    pass: Pass,
    y: usize,
    (a, b): (usize, usize),
    interior: &mut [f32],
    first: &mut [f32],
    last: &mut [f32],
    outside_above: Option<&[f32]>,
    outside_below: Option<&[f32]>,
    vals: &[f32],
    s: &mut RowScratch,
) {
    let len = first.len();
    if y == a {
        let below = if b - a > 2 { &interior[..len] } else { &*last };
        let nbrs = NeighbourRows { above: outside_above, same: None, below: Some(below) };
        update_row(mf, y, pass, nbrs, None, vals, first, s);
    } else if y + 1 == b {
        let above = if b - a > 2 { &interior[interior.len() - len..] } else { &*first };
        let nbrs = NeighbourRows { above: Some(above), same: None, below: outside_below };
        update_row(mf, y, pass, nbrs, None, vals, last, s);
    } else {
        let r = y - a - 1;
        let (before, rest) = interior.split_at_mut(r * len);
        let (row, after) = rest.split_at_mut(len);
        let above: &[f32] = if r == 0 { first } else { &before[(r - 1) * len..] };
        let below: &[f32] = if after.is_empty() { last } else { &after[..len] };
        let nbrs = NeighbourRows { above: Some(above), same: None, below: Some(below) };
        update_row(mf, y, pass, nbrs, None, vals, row, s);
    }
}

/// Bands of rows for [`MeanField::checkerboard_in_place`]: about two per thread, each at least 3 rows
/// (`[a, b)` ranges covering `0..height`); empty if the image has fewer than 3 rows. The banding changes the
/// order of work only, never the results.
fn checkerboard_bands(height: usize, threads: usize) -> Vec<(usize, usize)> {
    if height < 3 {
        return Vec::new();
    }
    let count = (2 * threads.max(1)).min(height / 3).max(1);
    (0..count).map(|k| (k * height / count, (k + 1) * height / count)).collect()
}

/// The marginals of the rows around the row being updated (each `width × M`; `None` outside the image, and
/// `same` is `None` when the row is updated in place).
#[derive(Clone, Copy)]
struct NeighbourRows<'s> {
    above: Option<&'s [f32]>,
    same: Option<&'s [f32]>,
    below: Option<&'s [f32]>,
}

impl<'s> NeighbourRows<'s> {
    /// Rows y − 1, y, y + 1 of a whole volume with rows of `len` values.
    fn of(volume: &'s [f32], y: usize, len: usize) -> Self {
        let h = volume.len() / len;
        NeighbourRows {
            above: (y > 0).then(|| &volume[(y - 1) * len..][..len]),
            same: Some(&volume[y * len..][..len]),
            below: (y + 1 < h).then(|| &volume[(y + 1) * len..][..len]),
        }
    }
}

/// Splits rows y − 1, y, y + 1 out of a volume with rows of `len` values: row y mutable, its neighbours as
/// [`NeighbourRows`] with `same` = `None` (for an update in place).
fn split_rows(volume: &mut [f32], y: usize, len: usize) -> (NeighbourRows<'_>, &mut [f32]) {
    let (before, rest) = volume.split_at_mut(y * len);
    let (row, after) = rest.split_at_mut(len);
    let above = (y > 0).then(|| &before[(y - 1) * len..]);
    let below = (!after.is_empty()).then(|| &after[..len]);
    (NeighbourRows { above, same: None, below }, row)
}

/// Fills `q` (`w × h` pixels of `m` labels) from the marginals of the level reduced 2 times: every pixel takes
/// its 2 × 2 block's.
///
/// # Panics
/// If `coarse` is not `w × h` reduced 2 times, or has another number of labels.
fn copy_from_coarse(q: &mut [f32], w: usize, h: usize, m: usize, coarse: &Marginals) {
    let cw = coarse.width;
    assert_eq!(
        (cw, coarse.height, coarse.ndisp),
        (crate::scale::reduced_len(w, 2), crate::scale::reduced_len(h, 2), m),
        "coarse marginals of the wrong size"
    );
    q.par_chunks_mut(w * m).enumerate().for_each(|(y, row)| {
        let crow = &coarse.data[(y / 2) * cw * m..][..cw * m];
        for (x, qx) in row.chunks_exact_mut(m).enumerate() {
            qx.copy_from_slice(&crow[(x / 2) * m..][..m]);
        }
    });
}

/// The block means of a cost volume over `factor × factor` pixels (partial blocks at the right and bottom edges
/// average the pixels they have); the labels are unchanged.
pub fn downsample_volume(vol: &CostVolume, factor: usize) -> CostVolume {
    let (w, h, m) = (vol.width, vol.height, vol.ndisp);
    let (sw, sh) = (crate::scale::reduced_len(w, factor), crate::scale::reduced_len(h, factor));
    let mut out = CostVolume::new(sw, sh, m, 0.0);
    out.data.par_chunks_mut((sw * m).max(1)).enumerate().for_each(|(by, out_row)| {
        let (y0, y1) = (by * factor, ((by + 1) * factor).min(h));
        for (bx, o) in out_row.chunks_exact_mut(m).enumerate() {
            let (x0, x1) = (bx * factor, ((bx + 1) * factor).min(w));
            for y in y0..y1 {
                for x in x0..x1 {
                    o.iter_mut().zip(vol.pixel(y * w + x)).for_each(|(a, c)| *a += c);
                }
            }
            let inv = 1.0 / ((y1 - y0) * (x1 - x0)) as f32;
            o.iter_mut().for_each(|a| *a *= inv);
        }
    });
    out
}

/// Coarse-to-fine mean field (`p.pyramid_levels` = L > 1).
///
/// Level k (0 = the input) is the image and the cost volume reduced 2^k times by block means, with the same
/// labels and σx / 2^k (the same kernel in input pixels). The coarsest level starts from the unary and runs
/// `p.iterations` with the configured annealing; each finer level starts from its parent's marginals (every pixel
/// takes its 2 × 2 block's, [`MeanField::from_coarse`]) and runs `p.pyramid_iterations` at `unary_scale`.
/// The model is the same at every level; what changes is how far evidence travels per iteration: the local
/// message crosses one pixel per iteration, so on the full grid a textureless region W pixels wide needs ~W / 2
/// red-black iterations before its marginals see its textured borders, and 2^(L−1) times fewer at the coarsest
/// level. Levels stop early when the next one would be narrower or shorter than 2 pixels. With L = 1 this is
/// `p.iterations` steps of [`MeanField`] from `buffers`, as in [`infer_mean_field`].
///
/// Memory: besides the input volume and the final Q (in `buffers` when it holds an `N × M` allocation), the
/// coarse levels' volumes and marginals, at most 2/3 of a volume more (Σ 2 · 4^−k).
pub fn infer_coarse_to_fine(
    cost: &CostVolume,
    image: &RgbImage,
    p: &MeanFieldParams,
    weights: PairwiseWeights,
    buffers: Buffers,
) -> (Marginals, Buffers) {
    // pyramid[k − 1] = the image and the volume reduced 2^k times.
    let mut pyramid: Vec<(RgbImage, CostVolume)> = Vec::new();
    for _ in 1..p.pyramid_levels.max(1) {
        let (img, vol) = pyramid.last().map_or((image, cost), |(i, v)| (i, v));
        if img.width < 4 || img.height < 4 {
            break;
        }
        let next = (crate::scale::downsample_rgb(img, 2), downsample_volume(vol, 2));
        pyramid.push(next);
    }
    // Finer levels start from their parent, at the final temperature.
    let refine = MeanFieldParams { unary_scale_start: 0.0, ..p.clone() };
    // One level (σx in its own pixels): from the parent's marginals if there is a parent, else from the unary.
    let run_level = |vol: &CostVolume, img: &RgbImage, level: u32, parent: Option<Marginals>, buffers: Buffers| {
        let base = if parent.is_some() { &refine } else { p };
        let lp = MeanFieldParams { sigma_xy: p.sigma_xy / (1u32 << level) as f32, ..base.clone() };
        let (mut mf, iterations) = match parent {
            Some(q) => (MeanField::from_coarse(vol, img, &lp, weights, buffers, &q), p.pyramid_iterations),
            None => (MeanField::with_buffers(vol, img, &lp, weights, buffers), p.iterations),
        };
        (0..iterations).for_each(|_| mf.step());
        mf.into_marginals_and_buffers()
    };
    let mut parent = None;
    while let Some((img, vol)) = pyramid.pop() {
        let level = pyramid.len() as u32 + 1;
        parent = Some(run_level(&vol, &img, level, parent, Buffers::default()).0);
    }
    run_level(cost, image, 0, parent, buffers)
}

/// Runs mean-field inference and returns the marginals: `p.iterations` iterations, coarse to fine when
/// `p.pyramid_levels` > 1 ([`infer_coarse_to_fine`]).
pub fn infer_mean_field(
    cost: &CostVolume,
    image: &RgbImage,
    p: &MeanFieldParams,
    weights: PairwiseWeights,
) -> Marginals {
    infer_coarse_to_fine(cost, image, p, weights, Buffers::default()).0
}

/// Disparity (argmax Q, ties to the smaller label, with an optional sub-pixel parabola through ln Q) and
/// confidence (max Q) from marginals.
pub fn decode_marginals(q: &Marginals, subpixel: bool) -> (DisparityMap, Plane<f32>) {
    let (w, h, m) = (q.width, q.height, q.ndisp);
    let mut disp = Plane::new(w, h, 0.0f32);
    let mut conf = Plane::new(w, h, 0.0f32);
    disp.data.par_iter_mut().zip(conf.data.par_iter_mut()).enumerate().with_min_len(1024).for_each(|(i, (d, c))| {
        let qi = q.pixel(i);
        // The first label holding the maximum (two vectorisable passes instead of a serial compare chain).
        let max = lane_max(qi);
        let best = qi.iter().position(|&v| v == max).unwrap_or(0);
        *c = qi[best];
        *d = best as f32;
        if subpixel && best > 0 && best + 1 < m {
            *d += parabola_offset(qi[best - 1], qi[best], qi[best + 1]);
        }
    });
    (disp, conf)
}

/// Vertex offset in [−0.5, 0.5] of the parabola through (−1, ln a), (0, ln b), (1, ln c), where b is the largest.
#[inline]
pub fn parabola_offset(a: f32, b: f32, c: f32) -> f32 {
    const FLOOR: f32 = 1e-30;
    let (la, lb, lc) = (a.max(FLOOR).ln(), b.max(FLOOR).ln(), c.max(FLOOR).ln());
    let curvature = la - 2.0 * lb + lc;
    if curvature < -1e-6 { (0.5 * (la - lc) / curvature).clamp(-0.5, 0.5) } else { 0.0 }
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)] // index loops read best in reference implementations
mod tests {
    use super::*;
    use crate::params::{CostParams, Params, Schedule};
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

    fn tiny_image(w: usize, h: usize) -> RgbImage {
        let noise = rand_vec(w * h, 5);
        let mut img = RgbImage::new(w, h);
        for i in 0..w * h {
            let x = i % w;
            let base = if x < w / 2 { [180.0, 60.0, 50.0] } else { [40.0, 90.0, 200.0] };
            for c in 0..3 {
                img.channels[c][i] = base[c] + 25.0 * noise[i];
            }
        }
        img
    }

    /// The lattice message against Σ_{j≠i} k(i, j) Q_j(l) computed densely, for each normalisation.
    /// Tolerance as for the lattice itself (its kernel is an approximation of the Gaussian; see
    /// `lattice_matches_brute_force_gaussian`): relative L2 error below 12%.
    #[test]
    fn meanfield_fcm_message_matches_brute_force() {
        let (w, h, m) = (16, 12, 4);
        let img = tiny_image(w, h);
        let n = w * h;
        let cost =
            CostVolume { width: w, height: h, ndisp: m, data: rand_vec(n * m, 11).iter().map(|v| v * 10.0).collect() };
        for norm in [Normalization::None, Normalization::Pixel, Normalization::Symmetric] {
            let p = MeanFieldParams { normalization: norm, exclude_self: true, ..MeanFieldParams::default() };
            let mut mf = MeanField::new(&cost, &img, &p, PairwiseWeights { fcm: 1.0, lcm: 0.0 });
            let fast = mf.fcm_message();
            let q = mf.marginals().to_vec();
            let k = |i: usize, j: usize| {
                let (xi, yi, xj, yj) = ((i % w) as f32, (i / w) as f32, (j % w) as f32, (j / w) as f32);
                let (fi, fj) = (img.rgb(i), img.rgb(j));
                let dp = ((xi - xj).powi(2) + (yi - yj).powi(2)) / (2.0 * p.sigma_xy.powi(2));
                let df = fi.iter().zip(&fj).map(|(a, b)| (a - b).powi(2)).sum::<f32>() / (2.0 * p.sigma_rgb.powi(2));
                (-dp - df).exp()
            };
            let deg: Vec<f32> = (0..n).map(|i| (0..n).filter(|&j| j != i).map(|j| k(i, j)).sum()).collect();
            let (mut err2, mut ref2) = (0.0f64, 0.0f64);
            for i in 0..n {
                for l in 0..m {
                    let reference: f32 = (0..n)
                        .filter(|&j| j != i)
                        .map(|j| {
                            let kij = k(i, j);
                            match norm {
                                Normalization::None => kij * q[j * m + l],
                                Normalization::Pixel => kij * q[j * m + l] / deg[i],
                                Normalization::Symmetric => kij * q[j * m + l] / (deg[i] * deg[j]).sqrt(),
                            }
                        })
                        .sum();
                    err2 += f64::from(fast[i * m + l] - reference).powi(2);
                    ref2 += f64::from(reference).powi(2);
                }
            }
            let rel = (err2 / ref2).sqrt();
            assert!(rel < 0.12, "{norm:?}: relative L2 error {rel}");
        }
    }

    /// Random texture, right view shifted by a three-band disparity field.
    fn banded_pair(w: usize, h: usize) -> (RgbImage, RgbImage, impl Fn(usize) -> usize) {
        let field = move |x: usize| {
            if x < w / 3 {
                4
            } else if x < 2 * w / 3 {
                9
            } else {
                14
            }
        };
        let tex_l = rand_vec(w * h * 3, 21);
        let tex_r = rand_vec(w * h * 3, 77);
        let mut left = RgbImage::new(w, h);
        let mut right = RgbImage::new(w, h);
        for c in 0..3 {
            for i in 0..w * h {
                left.channels[c][i] = 255.0 * tex_l[i * 3 + c];
                right.channels[c][i] = 255.0 * tex_r[i * 3 + c];
            }
        }
        for y in 0..h {
            for x in 0..w {
                let d = field(x);
                if x >= d {
                    for c in 0..3 {
                        right.channels[c][y * w + x - d] = left.channels[c][y * w + x];
                    }
                }
            }
        }
        (left, right, field)
    }

    /// Every model recovers a piecewise-constant disparity field on a textured pair: at least 97% of the pixels
    /// away from the image border and from the band edges (where occlusions make the answer ambiguous) get the
    /// exact label.
    #[test]
    fn meanfield_models_recover_synthetic_disparity() {
        let (w, h, nd) = (90, 40, 18);
        let (left, right, field) = banded_pair(w, h);
        let cost = crate::cost::build_cost_volume(&left, &right, nd, &CostParams::default());
        for (name, weights, schedule) in [
            ("lcm", PairwiseWeights { fcm: 0.0, lcm: 1.0 }, Schedule::Jacobi),
            ("fcm", PairwiseWeights { fcm: 30.0, lcm: 0.0 }, Schedule::Jacobi),
            ("jem", PairwiseWeights { fcm: 30.0, lcm: 1.0 }, Schedule::Jacobi),
            ("lcm checkerboard", PairwiseWeights { fcm: 0.0, lcm: 1.0 }, Schedule::Checkerboard),
            ("jem checkerboard", PairwiseWeights { fcm: 30.0, lcm: 1.0 }, Schedule::Checkerboard),
            ("lcm pyramid", PairwiseWeights { fcm: 0.0, lcm: 1.0 }, Schedule::Checkerboard),
            ("jem pyramid", PairwiseWeights { fcm: 30.0, lcm: 1.0 }, Schedule::Checkerboard),
        ] {
            let pyramid_levels = if name.ends_with("pyramid") { 2 } else { 1 };
            let p = MeanFieldParams { iterations: 5, schedule, pyramid_levels, ..MeanFieldParams::default() };
            let q = infer_mean_field(&cost, &left, &p, weights);
            let (disp, conf) = decode_marginals(&q, false);
            let (mut good, mut total) = (0, 0);
            for y in 4..h - 4 {
                for x in 20..w - 4 {
                    if [w / 3, 2 * w / 3].iter().any(|&e| x + 16 > e && x < e + 4) {
                        continue;
                    }
                    total += 1;
                    good += usize::from(disp.at(x, y) == field(x) as f32);
                }
            }
            let frac = good as f64 / total as f64;
            assert!(frac >= 0.97, "{name}: {good}/{total} exact");
            assert!(conf.data.iter().all(|c| (0.0..=1.0 + 1e-6).contains(c)));
        }
    }

    /// The red-black schedule against a slow reference: update every even pixel from the old marginals, then
    /// every odd pixel from the new even ones, one pixel at a time, with the local term only.
    #[test]
    fn meanfield_checkerboard_matches_sequential_reference() {
        let (w, h, nd) = (13, 7, 6);
        let (left, right, _) = banded_pair(w, h);
        let cost = crate::cost::build_cost_volume(&left, &right, nd, &CostParams::default());
        let p = MeanFieldParams { iterations: 2, schedule: Schedule::Checkerboard, ..MeanFieldParams::default() };
        let weights = PairwiseWeights { fcm: 0.0, lcm: 1.5 };
        let fast = infer_mean_field(&cost, &left, &p, weights);
        let local = local_weights(&left, &p);
        let mut q: Vec<f32> = cost.data.iter().map(|c| c * p.unary_scale).collect();
        q.chunks_exact_mut(nd).for_each(softmax_neg_in_place);
        for _ in 0..p.iterations {
            for parity in [0, 1] {
                let old = q.clone();
                for y in 0..h {
                    for x in (0..w).filter(|x| (x + y) % 2 == parity) {
                        let i = y * w + x;
                        let mut nbrs = Vec::new();
                        if x > 0 {
                            nbrs.push((i - 1, local.right.data[i - 1]));
                        }
                        if x + 1 < w {
                            nbrs.push((i + 1, local.right.data[i]));
                        }
                        if y > 0 {
                            nbrs.push((i - w, local.down.data[i - w]));
                        }
                        if y + 1 < h {
                            nbrs.push((i + w, local.down.data[i]));
                        }
                        let mut e: Vec<f32> = (0..nd).map(|d| p.unary_scale * cost.data[i * nd + d]).collect();
                        for d in 0..nd {
                            // Naive O(M²) local energy, without the label-independent constant.
                            let mut s = 0.0;
                            for l in 0..nd {
                                let phi = match d.abs_diff(l) {
                                    0 => 0.0,
                                    1 => p.beta,
                                    _ => 1.0,
                                };
                                let pt: f32 = nbrs.iter().map(|&(j, wt)| wt * old[j * nd + l]).sum();
                                s += (phi - 1.0) * pt;
                            }
                            e[d] += weights.lcm * s;
                        }
                        softmax_neg_in_place(&mut e);
                        q[i * nd..][..nd].copy_from_slice(&e);
                    }
                }
            }
        }
        for (a, b) in fast.data.iter().zip(&q) {
            assert!((a - b).abs() < 1e-5, "{a} vs {b}");
        }
    }

    /// The in-place red-black update (one sweep per band, and two plain sweeps without bands) against the
    /// two-buffer, two-sweep one, bit for bit, for several heights and bandings, with both pairwise terms.
    #[test]
    fn meanfield_in_place_checkerboard_matches_two_sweeps() {
        for (w, h) in [(9, 3), (8, 4), (11, 7), (10, 13)] {
            let (left, right, _) = banded_pair(w, h);
            let nd = 5;
            let cost = crate::cost::build_cost_volume(&left, &right, nd, &CostParams::default());
            let p = MeanFieldParams { schedule: Schedule::Checkerboard, ..MeanFieldParams::default() };
            let weights = PairwiseWeights { fcm: 8.0, lcm: 1.5 };
            let reference = {
                let mut mf = MeanField::new(&cost, &left, &p, weights);
                mf.next = vec![0.0; mf.q.len()];
                for _ in 0..3 {
                    let (mut q, mut next) = (std::mem::take(&mut mf.q), std::mem::take(&mut mf.next));
                    let mut scratch = std::mem::take(&mut mf.scratch);
                    let vals = mf.lattice.as_ref().unwrap().splat_blur(&q, Some(&mf.in_scale), nd, &mut scratch);
                    mf.checkerboard_two_pass(&mut q, &mut next, vals);
                    (mf.q, mf.next, mf.scratch) = (q, next, scratch);
                }
                mf.q
            };
            for count in 0..=h / 3 {
                let bands: Vec<(usize, usize)> = (0..count).map(|k| (k * h / count, (k + 1) * h / count)).collect();
                let mut mf = MeanField::new(&cost, &left, &p, weights);
                let mut edges = vec![0.0; 2 * count * w * nd];
                for _ in 0..3 {
                    let mut q = std::mem::take(&mut mf.q);
                    let mut scratch = std::mem::take(&mut mf.scratch);
                    let vals = mf.lattice.as_ref().unwrap().splat_blur(&q, Some(&mf.in_scale), nd, &mut scratch);
                    mf.checkerboard_in_place(&mut q, vals, &bands, &mut edges);
                    (mf.q, mf.scratch) = (q, scratch);
                }
                assert!(
                    mf.q.iter().zip(&reference).all(|(a, b)| a.to_bits() == b.to_bits()),
                    "{w}x{h}, bands {bands:?}"
                );
            }
        }
        assert!(checkerboard_bands(2, 4).is_empty());
        assert_eq!(checkerboard_bands(7, 4), vec![(0, 3), (3, 7)]);
    }

    #[test]
    fn meanfield_marginals_are_distributions() {
        let (w, h, nd) = (30, 10, 8);
        let (left, right, _) = banded_pair(w, h);
        let cost = crate::cost::build_cost_volume(&left, &right, nd, &CostParams::default());
        let q = infer_mean_field(&cost, &left, &MeanFieldParams::default(), PairwiseWeights { fcm: 30.0, lcm: 1.0 });
        for i in 0..w * h {
            let s: f32 = q.pixel(i).iter().sum();
            assert!((s - 1.0).abs() < 1e-4 && q.pixel(i).iter().all(|v| v.is_finite() && *v >= 0.0));
        }
    }

    #[test]
    fn meanfield_zero_iterations_is_softmax_of_the_unary() {
        let (w, h, nd) = (20, 6, 5);
        let (left, right, _) = banded_pair(w, h);
        let cost = crate::cost::build_cost_volume(&left, &right, nd, &CostParams::default());
        let p = MeanFieldParams { iterations: 0, ..MeanFieldParams::default() };
        let q = infer_mean_field(&cost, &left, &p, PairwiseWeights { fcm: 30.0, lcm: 1.0 });
        let (disp, _) = decode_marginals(&q, false);
        assert_eq!(disp, crate::cost::winner_take_all(&cost));
    }

    #[test]
    fn meanfield_run_is_identical_with_1_and_2_threads() {
        let (w, h) = (64, 30);
        let (left, right, _) = banded_pair(w, h);
        let pair = crate::StereoPair::new(left, right, 16).unwrap();
        let run = |threads| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            pool.install(|| crate::run(&Params::default(), &pair).unwrap().disparity)
        };
        let (a, b) = (run(1), run(2));
        assert!(a.data.iter().zip(&b.data).all(|(x, y)| x.to_bits() == y.to_bits()));
    }

    /// The annealing schedule: off gives `unary_scale` at every step; on, it starts at `unary_scale_start`, ends at
    /// `unary_scale` after T iterations (and stays there), and consecutive scales have a constant ratio.
    #[test]
    fn meanfield_unary_schedule_is_geometric_from_start_to_end() {
        let off = MeanFieldParams { iterations: 4, unary_scale: 0.1, ..MeanFieldParams::default() };
        assert!((0..8).all(|t| UnarySchedule::new(&off).at(t) == 0.1));
        let p = MeanFieldParams { iterations: 4, unary_scale: 0.16, unary_scale_start: 0.01, ..off };
        let s = UnarySchedule::new(&p);
        let expected = [0.01, 0.02, 0.04, 0.08, 0.16, 0.16, 0.16];
        for (t, e) in expected.iter().enumerate() {
            assert!((s.at(t) - e).abs() < 1e-7, "step {t}: {} vs {e}", s.at(t));
        }
        assert_eq!(s.at(4), 0.16, "the last iteration uses unary_scale exactly");
        // Cooling as well as heating, and T = 0 (nothing to anneal).
        let down = UnarySchedule::new(&MeanFieldParams { unary_scale_start: 0.4, ..p });
        assert!((down.at(2) - 0.4 * (0.16f32 / 0.4).sqrt()).abs() < 1e-6);
        assert_eq!(UnarySchedule::new(&MeanFieldParams { iterations: 0, ..p }).at(0), 0.16);
    }

    /// `unary_anneal_iterations` = K: the schedule reaches `unary_scale` at step K and stays there.
    #[test]
    fn meanfield_unary_schedule_holds_after_k_iterations() {
        let p = MeanFieldParams {
            iterations: 6,
            unary_scale: 0.16,
            unary_scale_start: 0.04,
            unary_anneal_iterations: 2,
            ..MeanFieldParams::default()
        };
        let s = UnarySchedule::new(&p);
        let expected = [0.04, 0.08, 0.16, 0.16, 0.16, 0.16, 0.16];
        for (t, e) in expected.iter().enumerate() {
            assert!((s.at(t) - e).abs() < 1e-7, "step {t}: {} vs {e}", s.at(t));
        }
        let all = UnarySchedule::new(&MeanFieldParams { unary_anneal_iterations: 6, ..p.clone() });
        assert_eq!(all, UnarySchedule::new(&MeanFieldParams { unary_anneal_iterations: 0, ..p }));
    }

    /// Block means with partial blocks at the right and bottom edges: a 3 × 3 volume of 2 labels reduced 2 times.
    #[test]
    fn meanfield_downsample_volume_takes_block_means() {
        // Label 0 holds the pixel index, label 1 ten times it.
        let data: Vec<f32> = (0..9).flat_map(|i| [i as f32, 10.0 * i as f32]).collect();
        let vol = CostVolume { width: 3, height: 3, ndisp: 2, data };
        let small = downsample_volume(&vol, 2);
        assert_eq!((small.width, small.height, small.ndisp), (2, 2, 2));
        // Blocks: {0, 1, 3, 4} | {2, 5} over {6, 7} | {8}.
        assert_eq!(small.data, vec![2.0, 20.0, 3.5, 35.0, 6.5, 65.0, 8.0, 80.0]);
    }

    /// Every pixel of a 5 × 3 level takes the marginal of its 2 × 2 block in the 3 × 2 coarse level.
    #[test]
    fn meanfield_from_coarse_copies_each_block() {
        let (w, h, m) = (5, 3, 4);
        let cost = random_cost(w, h, m, 3, 10.0);
        let coarse = random_cost(3, 2, m, 9, 1.0);
        let p = MeanFieldParams::default();
        let mf = MeanField::from_coarse(&cost, &RgbImage::new(w, h), &p, LCM_ONLY, Buffers::default(), &coarse);
        for y in 0..h {
            for x in 0..w {
                let (i, parent) = (y * w + x, (y / 2) * 3 + x / 2);
                assert_eq!(&mf.marginals()[i * m..][..m], coarse.pixel(parent), "pixel ({x}, {y})");
            }
        }
    }

    /// One level is the plain inference, bit for bit (the pyramid only adds levels in front of it).
    #[test]
    fn meanfield_one_level_pyramid_is_plain_inference() {
        let (w, h, m) = (23, 17, 9);
        let cost = random_cost(w, h, m, 5, 20.0);
        let (image, _, _) = banded_pair(w, h);
        let p = MeanFieldParams { iterations: 4, unary_scale_start: 0.1, ..MeanFieldParams::default() };
        let weights = PairwiseWeights { fcm: 5.0, lcm: 1.0 };
        let mut mf = MeanField::new(&cost, &image, &p, weights);
        (0..p.iterations).for_each(|_| mf.step());
        let plain = mf.into_marginals();
        let (pyr, _) = infer_coarse_to_fine(&cost, &image, &p, weights, Buffers::default());
        assert!(plain.data.iter().zip(&pyr.data).all(|(a, b)| a.to_bits() == b.to_bits()));
    }

    /// What the pyramid is for: weak evidence under strong noise. Every pixel's cost is uniform noise in 0..6 plus
    /// 1 for every label but the true one (5 of 8), so the true label wins the winner-take-all at few pixels;
    /// the local term has to pool evidence over a large neighbourhood. The same number of iterations pools more
    /// when it starts on a grid reduced 4 times (a 4 × 4 block mean already averages 16 pixels' noise).
    #[test]
    fn meanfield_pyramid_pools_weak_evidence() {
        let (w, h, m) = (64, 32, 8);
        let noise = rand_vec(w * h * m, 41);
        let data = noise.iter().enumerate().map(|(k, v)| 6.0 * v + if k % m == 5 { 0.0 } else { 1.0 }).collect();
        let cost = CostVolume { width: w, height: h, ndisp: m, data };
        let image = RgbImage::new(w, h);
        let exact = |disp: &Plane<f32>| disp.data.iter().filter(|&&d| d == 5.0).count() as f64 / (w * h) as f64;
        let wta = exact(&crate::cost::winner_take_all(&cost));
        let exact_after = |levels| {
            let p = MeanFieldParams {
                iterations: 4,
                pyramid_levels: levels,
                pyramid_iterations: 4,
                ..MeanFieldParams::default()
            };
            let q = infer_mean_field(&cost, &image, &p, PairwiseWeights { fcm: 0.0, lcm: 0.5 });
            exact(&decode_marginals(&q, false).0)
        };
        let (plain, pyramid) = (exact_after(1), exact_after(3));
        // Measured: WTA 0.29, plain 0.70, three levels 0.88.
        assert!(wta < 0.4, "the evidence is not weak: WTA already gets {wta:.2}");
        assert!(plain < 0.8 && pyramid > 0.85, "plain {plain:.3}, coarse to fine {pyramid:.3}");
    }

    /// Cold marginals (costs spread over 0..400 at unary scale 1) keep no subnormal float, neither in Q nor in the
    /// fully connected message built from it (the lattice multiplies Q by weights below 1 many times), and the
    /// floor costs nothing that matters: every probability removed was below 1e−20 of its pixel's maximum.
    #[test]
    fn meanfield_cold_marginals_hold_no_subnormal_floats() {
        let (w, h, m) = (40, 24, 30);
        let cost = random_cost(w, h, m, 17, 400.0);
        let (image, _, _) = banded_pair(w, h);
        let p = MeanFieldParams { unary_scale: 1.0, ..MeanFieldParams::default() };
        let mut mf = MeanField::new(&cost, &image, &p, PairwiseWeights { fcm: 30.0, lcm: 1.0 });
        let zeros_at_start = mf.marginals().iter().filter(|&&v| v == 0.0).count();
        assert!(zeros_at_start > 0, "the test needs labels below the floor");
        for q in mf.marginals().chunks_exact(m) {
            let max = q.iter().copied().fold(0.0f32, f32::max);
            assert!(q.iter().all(|&v| v == 0.0 || v >= max * MIN_RELATIVE_PROBABILITY * 0.99));
        }
        for _ in 0..3 {
            mf.step();
            assert!(mf.marginals().iter().all(|v| *v == 0.0 || v.is_normal()), "subnormal marginal");
        }
        assert!(mf.fcm_message().iter().all(|v| *v == 0.0 || v.is_normal()), "subnormal message");
    }

    const LCM_ONLY: PairwiseWeights = PairwiseWeights { fcm: 0.0, lcm: 1.0 };

    /// A `w × h × m` cost volume of uniform random costs in `[0, scale)`.
    fn random_cost(w: usize, h: usize, m: usize, seed: u64, scale: f32) -> CostVolume {
        CostVolume {
            width: w,
            height: h,
            ndisp: m,
            data: rand_vec(w * h * m, seed).iter().map(|v| v * scale).collect(),
        }
    }

    /// The label-aware local coupling: ω̃ × M / reference, ω untouched; off = unchanged.
    #[test]
    fn meanfield_label_aware_weights_scale_with_the_labels() {
        let w = PairwiseWeights { fcm: 7.0, lcm: 1.5 };
        assert_eq!(label_aware_weights(w, &MeanFieldParams::default(), 190), w);
        let p = MeanFieldParams { lcm_weight_ref_labels: 60, ..MeanFieldParams::default() };
        assert_eq!(label_aware_weights(w, &p, 60), w);
        assert_eq!(label_aware_weights(w, &p, 180), PairwiseWeights { fcm: 7.0, lcm: 4.5 });
    }

    /// With annealing the initial marginals are the softmax of the starting scale, each iteration uses the next
    /// scale of the schedule (checked against a Jacobi run built from scratch with that scale), and without it
    /// the output is bit for bit the plain run's.
    #[test]
    fn meanfield_annealing_applies_the_schedule_per_iteration() {
        let (w, h, nd) = (24, 9, 7);
        let (left, right, _) = banded_pair(w, h);
        let cost = crate::cost::build_cost_volume(&left, &right, nd, &CostParams::default());
        let weights = PairwiseWeights { fcm: 0.0, lcm: 1.5 };
        let plain =
            MeanFieldParams { iterations: 3, unary_scale: 0.2, schedule: Schedule::Jacobi, ..Default::default() };
        let annealed = MeanFieldParams { unary_scale_start: 0.05, ..plain.clone() };
        let schedule = UnarySchedule::new(&annealed);
        // Reference: one Jacobi step from the given marginals with a fixed scale.
        let jacobi_step = |q: &[f32], scale: f32| -> Vec<f32> {
            let p = MeanFieldParams { iterations: 1, unary_scale: scale, ..plain.clone() };
            let mut mf = MeanField::new(&cost, &left, &p, weights);
            mf.q.copy_from_slice(q);
            mf.step();
            mf.q
        };
        let mut mf = MeanField::new(&cost, &left, &annealed, weights);
        let mut reference: Vec<f32> = cost.data.iter().map(|c| c * 0.05).collect();
        reference.chunks_exact_mut(nd).for_each(softmax_neg_in_place);
        assert!(mf.marginals().iter().zip(&reference).all(|(a, b)| a.to_bits() == b.to_bits()));
        for t in 1..=3 {
            mf.step();
            reference = jacobi_step(&reference, schedule.at(t));
            assert!(mf.marginals().iter().zip(&reference).all(|(a, b)| a.to_bits() == b.to_bits()), "step {t}");
        }
        let off = MeanFieldParams { unary_scale_start: 0.0, ..annealed };
        let a = infer_mean_field(&cost, &left, &off, weights);
        let b = infer_mean_field(&cost, &left, &plain, weights);
        assert!(a.data.iter().zip(&b.data).all(|(x, y)| x.to_bits() == y.to_bits()));
    }

    #[test]
    fn parabola_offset_finds_the_vertex() {
        // ln Q = −(x − 0.3)² sampled at −1, 0, 1.
        let f = |x: f32| (-(x - 0.3f32).powi(2)).exp();
        assert!((parabola_offset(f(-1.0), f(0.0), f(1.0)) - 0.3).abs() < 1e-4);
        assert_eq!(parabola_offset(0.2, 0.2, 0.2), 0.0, "flat: no offset");
        assert_eq!(parabola_offset(0.0, 1.0, 0.0), 0.0, "symmetric");
    }
}
