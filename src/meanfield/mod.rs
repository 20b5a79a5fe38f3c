//! Joint mean-field inference on the FCM + LCM energy (paper §3, Algorithm 1).
//!
//! Q_i(d) ∝ exp(−ψ_u(d) − Q̂_i(d) − P̂_i(d)), where
//! - ψ_u = `unary_scale` × cost (the cost volume as a log-likelihood up to a temperature);
//! - the fully connected Potts message Q̂_i(d) = ω·(Σ_l Q̃_i(l) − Q̃_i(d)), Q̃_i(l) = Σ_{j≠i} k(i, j) Q_j(l), with
//!   Q̃ from the permutohedral lattice for all labels at once ([`full`]);
//! - the local message P̂_i(d) = ω̃·Σ_l φ̃(d, l) P̃_i(l), P̃_i(l) = Σ_{j∈N4(i)} w̃(i, j) Q_j(l), in its O(M) form
//!   P̂_i(d) = ω̃·(S_i − P̃_i(d) − (1 − β)(P̃_i(d−1) + P̃_i(d+1))), S_i = Σ_l P̃_i(l) ([`energy`]).
//!
//! The terms ω·Σ_l Q̃_i(l) and ω̃·S_i do not depend on d, so they cancel in the normalisation of Q_i and are not
//! computed; the update uses E_i(d) = ψ_u(d) − ω·Q̃_i(d) − ω̃·(P̃_i(d) + (1 − β)(P̃_i(d−1) + P̃_i(d+1))), and
//! Q_i = softmax(−E_i) with the minimum energy subtracted first (no overflow, never NaN for finite costs).
//!
//! [`MeanField`] is Algorithm 1: build it once per view (Q initialised to softmax(−ψ_u)), then
//! [`MeanField::step`] T times — message passing (splat and blur on the lattice), then one update pass per pixel
//! that slices its message, adds the compatibility transform and the local term, and normalises. After T
//! iterations the disparity is argmax Q (the paper's WTA) and the confidence max Q ([`decode`]). Models: `lcm`
//! sets ω = 0, `fcm` sets ω̃ = 0 (same code path).
//!
//! The files follow the algorithm; the paper's parts:
//! - [`energy`]: the unary, the local edge weights w̃ (eq. 8) and message, one pixel's energies and softmax;
//! - [`full`]: the fully connected kernel (lattice, normalisation, the pixel's own term);
//! - [`update`]: the per-pixel update of one row (Algorithm 1's compatibility transform and local update);
//! - [`decode`]: argmax and confidence.
//!
//! and what we added to it, each measured on trainingQ (docs/tuning-log.md) and switchable by configuration:
//! - [`schedule`]: red-black (checkerboard) updates in place instead of the paper's all-at-once (Jacobi) update
//!   (evidence crosses the local term twice as fast per iteration);
//! - [`anneal`]: deterministic annealing of the unary temperature and the label-aware local coupling;
//! - [`pyramid`]: coarse-to-fine inference (the same model on a 2× reduced grid first);
//! - [`bands`]: label bands, each pixel's marginal kept to a run of labels (the tiles of [`crate::pipeline::tile`],
//!   a travelling frame), stored packed, one pixel's band after another ([`packed`]);
//! - in [`full`]: the normalisation of the message (the paper leaves it unnormalised);
//! - in [`energy`]: the floor under tiny probabilities ([`energy::MIN_RELATIVE_PROBABILITY`]) and the sub-pixel
//!   parabola.
//!
//! Memory: Q, `N × M` f32 (the bands' labels only with label bands; and the next Q with the Jacobi schedule; the
//! checkerboard updates Q in place), plus the lattice's two `vertices × M` buffers (the fully connected message is
//! sliced per pixel inside the update, never stored); each iteration is O(N·M) and allocation-free apart from a few
//! `M`-long scratch vectors per thread.

pub(crate) mod anneal;
pub(crate) mod bands;
pub(crate) mod decode;
pub(crate) mod energy;
pub(crate) mod full;
mod packed;
pub(crate) mod pyramid;
pub(crate) mod schedule;
pub(crate) mod update;

use rayon::prelude::*;

use crate::image::{CostVolume, Plane, RgbImage};
use crate::lattice::{Bands, LatticeScratch};
use crate::params::{MeanFieldParams, Schedule};

pub(crate) use anneal::{UnarySchedule, label_aware_weights};
pub(crate) use bands::LabelBands;
pub use decode::decode_marginals;
pub(crate) use energy::{LocalWeights, local_weights};
pub(crate) use pyramid::infer_coarse_to_fine;

use energy::unary_marginals;
use full::FullKernel;
use packed::Packed;
use pyramid::copy_from_coarse;
use schedule::checkerboard_bands;
use update::Pass;

/// Per-pixel label distributions, laid out like a [`CostVolume`]: `data[(y·w + x)·M + d]`.
pub(crate) type Marginals = CostVolume;

/// The weights of the two pairwise terms for one run (0 switches a term off).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PairwiseWeights {
    /// ω, fully connected.
    pub fcm: f32,
    /// ω̃, locally connected.
    pub lcm: f32,
}

/// Large buffers a [`MeanField`] can take over from a previous one (the other view, the previous tile), so that
/// they are not allocated and page-faulted again.
#[derive(Debug, Default)]
pub struct Buffers {
    /// Spare `N × M` allocations: spent marginals, dropped cost volumes (at most [`MAX_SPARE`]).
    spare: Vec<Vec<f32>>,
    next: Vec<f32>,
    scratch: LatticeScratch,
}

/// The most spare allocations [`Buffers`] keeps: a view's inference needs its cost volume and its marginals, and
/// the next volume is built while they are alive.
pub(crate) const MAX_SPARE: usize = 3;

impl Buffers {
    /// Gives back an allocation that is no longer needed (old marginals, a dropped cost volume): the next
    /// [`MeanField`] keeps its marginals in one, and [`Buffers::take`] hands them out. Beyond [`MAX_SPARE`] the
    /// smallest is freed.
    pub fn recycle(&mut self, storage: Vec<f32>) {
        if storage.capacity() == 0 {
            return;
        }
        self.spare.push(storage);
        if self.spare.len() > MAX_SPARE {
            let smallest = (0..self.spare.len()).min_by_key(|&i| self.spare[i].capacity()).unwrap_or(0);
            self.spare.swap_remove(smallest);
        }
    }

    /// Keeps the spare allocations up to `values` in all, the largest first, and frees the rest, the lattice's
    /// buffers and `next`.
    pub fn trim(&mut self, values: usize) {
        self.spare.sort_by_key(|v| std::cmp::Reverse(v.capacity()));
        let mut total = 0;
        self.spare.retain(|v| {
            total += v.capacity();
            total <= values
        });
        self.next = Vec::new();
        self.scratch = LatticeScratch::default();
    }

    /// A spare allocation of `len` values (what it held before, or zeros; for a buffer that is written in full
    /// before it is read): the smallest that holds `len`, else the largest, grown; a fresh one if there is none.
    pub fn take(&mut self, len: usize) -> Vec<f32> {
        let cap = |i: &usize| self.spare[*i].capacity();
        let all = 0..self.spare.len();
        let pick = all.clone().filter(|i| cap(i) >= len).min_by_key(cap).or_else(|| all.max_by_key(cap));
        crate::image::reuse_storage(pick.map_or_else(Vec::new, |i| self.spare.swap_remove(i)), len)
    }
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
    /// The fully connected kernel (`None` when ω = 0).
    full: Option<FullKernel>,
    local: LocalWeights,
    q: Vec<f32>,
    /// The next Q (Jacobi schedule only; the checkerboard updates Q in place).
    next: Vec<f32>,
    /// Two rows per band of rows for the in-place checkerboard.
    edges: Vec<f32>,
    scratch: LatticeScratch,
    /// The spare allocations this run did not take, handed on with the buffers.
    spare: Vec<Vec<f32>>,
    /// Each pixel's labels (its marginal is 0 outside them); `None`: all labels.
    label_bands: Option<LabelBands>,
    /// With label bands: only the bands are stored, Q (and `next`) packed ([`packed`]); `None`: `N × M`.
    packed: Option<Packed>,
    /// Where each row of pixels starts in Q: `height + 1` entries (`y · width · M` unless packed).
    row_starts: Vec<usize>,
    /// The pixels that have settled ([`MeanField::settle`]): later steps keep their marginals (empty: none).
    settled: Vec<bool>,
}

impl<'a> MeanField<'a> {
    /// Marks as settled every pixel whose largest marginal is at least `confidence`, and returns how many are:
    /// the steps after this keep their marginals as they are and update only the others (a frame whose prior,
    /// carried from the previous frame, has already placed most pixels). The settled pixels still send their
    /// messages to the others. `confidence` above 1 settles none: the steps are then the usual ones, bit for bit.
    pub fn settle(&mut self, confidence: f32) -> usize {
        let n = self.cost.width * self.cost.height;
        let settled = (0..n)
            .into_par_iter()
            .with_min_len(1024)
            .map(|i| self.stored(i).0.iter().fold(0.0f32, |top, &v| top.max(v)) >= confidence)
            .collect();
        self.settled = settled;
        self.settled.iter().filter(|&&s| s).count()
    }

    /// Pixel i's marginal as Q stores it, and the label of its first value: its band (packed or not) with label
    /// bands, else all labels from 0. Outside it the marginal is 0.
    #[inline]
    fn stored(&self, i: usize) -> (&[f32], usize) {
        let m = self.cost.ndisp;
        match (&self.packed, &self.label_bands) {
            (Some(p), Some(bands)) => (&self.q[p.offsets[i]..p.offsets[i + 1]], bands.of(i).0),
            (_, Some(bands)) => {
                let (a, b) = bands.of(i);
                (&self.q[i * m + a..i * m + b], a)
            }
            (_, None) => (&self.q[i * m..][..m], 0),
        }
    }

    /// Whether pixel `i` has settled ([`MeanField::settle`]).
    #[inline]
    pub(super) fn is_settled(&self, i: usize) -> bool {
        self.settled.get(i).copied().unwrap_or(false)
    }

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
        Self::build(cost, image, p, weights, buffers, None, None)
    }

    /// Like [`MeanField::with_buffers`], with each pixel's marginal kept to its band of labels (0 outside it):
    /// an iteration's update, splat and slice cost the bands, not all labels (`bands`), and only the bands are
    /// stored (`packed`).
    ///
    /// # Panics
    /// If the image, the cost volume and the bands differ in size or labels.
    pub fn in_label_bands(
        cost: &'a CostVolume,
        image: &RgbImage,
        p: &MeanFieldParams,
        weights: PairwiseWeights,
        buffers: Buffers,
        label_bands: LabelBands,
    ) -> Self {
        Self::build(cost, image, p, weights, buffers, None, Some((label_bands, true)))
    }

    /// [`MeanField::in_label_bands`] with Q kept `N × M` (0 outside the bands): the reference for the packed run.
    #[cfg(test)]
    pub(super) fn in_dense_label_bands(
        cost: &'a CostVolume,
        image: &RgbImage,
        p: &MeanFieldParams,
        weights: PairwiseWeights,
        buffers: Buffers,
        label_bands: LabelBands,
    ) -> Self {
        Self::build(cost, image, p, weights, buffers, None, Some((label_bands, false)))
    }

    /// Like [`MeanField::with_buffers`], but Q starts from the marginals of a level reduced 2 times instead of
    /// the unary: every pixel takes its 2 × 2 block's (coarse-to-fine inference, `infer_coarse_to_fine`).
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
        Self::build(cost, image, p, weights, buffers, Some(coarse), None)
    }

    /// The constructors' common body: Q from `coarse` if given, else softmax(−ψ_u) (within the label bands, if
    /// given, packed if asked).
    fn build(
        cost: &'a CostVolume,
        image: &RgbImage,
        p: &MeanFieldParams,
        weights: PairwiseWeights,
        buffers: Buffers,
        coarse: Option<&Marginals>,
        label_bands: Option<(LabelBands, bool)>,
    ) -> Self {
        assert_eq!((cost.width, cost.height), image.dims(), "cost volume and image differ in size");
        if let Some((b, _)) = &label_bands {
            assert_eq!((b.width, b.height, b.ndisp), (cost.width, cost.height, cost.ndisp), "label bands differ");
        }
        let (n, m) = (image.len(), cost.ndisp);
        let weights = label_aware_weights(weights, p, m);
        let full = (weights.fcm > 0.0).then(|| FullKernel::new(image, p));
        let mut buffers = buffers;
        let packed = match &label_bands {
            Some((bands, true)) => Some(Packed::new(bands, cost, p.iterations > 1, &mut |len| buffers.take(len))),
            _ => None,
        };
        let label_bands = label_bands.map(|(bands, _)| bands);
        let values = packed.as_ref().map_or(n * m, Packed::len);
        // Q is written in full below, in parallel, and `next` (needed by the Jacobi schedule only) by each iteration
        // before it is read: what a reused buffer held does not matter.
        let mut q = buffers.take(values);
        let Buffers { spare, mut next, scratch } = buffers;
        let next_len = if p.schedule == Schedule::Jacobi { values } else { 0 };
        if next.len() != next_len {
            next = vec![0.0; next_len];
        } else if label_bands.is_some() && packed.is_none() {
            // Each iteration writes only the bands of `next`: the rest must be 0.
            next.fill(0.0);
        }
        let row_starts = match &packed {
            Some(packed) => packed.row_starts(cost.width, cost.height),
            None => (0..=cost.height).map(|y| y * cost.width * m).collect(),
        };
        let edges = match p.schedule {
            Schedule::Jacobi => Vec::new(),
            Schedule::Checkerboard => {
                vec![0.0; 2 * checkerboard_bands(cost.height, rayon::current_num_threads()).len() * cost.width * m]
            }
        };
        let unary_schedule = UnarySchedule::new(p);
        let scale = unary_schedule.at(0);
        match (coarse, &label_bands, &packed) {
            (Some(coarse), _, _) => copy_from_coarse(&mut q, cost.width, cost.height, m, coarse),
            (None, Some(bands), Some(packed)) => {
                packed.fill_unary(&mut q, bands, cost, scale);
            }
            (None, Some(bands), None) => {
                const CHUNK: usize = 256;
                q.par_chunks_mut(m * CHUNK).zip(cost.data.par_chunks(m * CHUNK)).enumerate().for_each(|(k, (q, c))| {
                    for (j, (q, c)) in q.chunks_exact_mut(m).zip(c.chunks_exact(m)).enumerate() {
                        let (lo, hi) = bands.of(k * CHUNK + j);
                        q.fill(0.0);
                        unary_marginals(&c[lo..hi], scale, hi - lo, &mut q[lo..hi]);
                    }
                });
            }
            (None, None, _) => {
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
            full,
            local: local_weights(image, p),
            q,
            next,
            edges,
            scratch,
            spare,
            label_bands,
            packed,
            row_starts,
            settled: Vec::new(),
        }
    }

    /// One mean-field iteration over all pixels, with the configured [`Schedule`] and the next unary scale of the
    /// `UnarySchedule`.
    pub fn step(&mut self) {
        self.done += 1;
        self.unary_scale = self.unary_schedule.at(self.done);
        let m = self.cost.ndisp;
        let mut next = std::mem::take(&mut self.next);
        let mut q = std::mem::take(&mut self.q);
        let mut scratch = std::mem::take(&mut self.scratch);
        let mut edges = std::mem::take(&mut self.edges);
        let vals: &[f32] = match &self.full {
            Some(full) => {
                let bands = self.label_bands.as_ref().map(|b| Bands {
                    ranges: b.as_slice(),
                    packed: self.packed.as_ref().map(|p| p.offsets.as_slice()),
                });
                full.splat_blur(&q, bands, m, &mut scratch)
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

    /// The fully connected message Q̃ (normalised, self term excluded as configured) for the current marginals,
    /// `N × M`; empty when ω = 0. For tests and diagnostics: [`MeanField::step`] computes the same values inline.
    pub fn fcm_message(&mut self) -> Vec<f32> {
        let q = self.marginals().into_owned();
        let Some(full) = &self.full else { return Vec::new() };
        full.message(&q, self.cost.ndisp, &mut self.scratch)
    }

    /// The current marginals, `N × M` (unpacked if packed).
    pub fn marginals(&self) -> std::borrow::Cow<'_, [f32]> {
        match (&self.packed, &self.label_bands) {
            (Some(packed), Some(bands)) => {
                let mut dense = vec![0.0; self.cost.data.len()];
                packed.unpack(&self.q, bands, self.cost.ndisp, &mut dense);
                std::borrow::Cow::Owned(dense)
            }
            _ => std::borrow::Cow::Borrowed(&self.q),
        }
    }

    /// Consumes the state, returning the marginals as a volume.
    pub fn into_marginals(self) -> Marginals {
        self.into_marginals_and_buffers().0
    }

    /// The disparity and confidence of the current marginals ([`decode_marginals`]), without unpacking packed ones.
    pub fn decode(&self, subpixel: bool) -> (crate::image::DisparityMap, crate::image::Plane<f32>) {
        let m = self.cost.ndisp;
        decode::decode_with(self.cost.width, self.cost.height, subpixel, |i| {
            let (q, first) = self.stored(i);
            (q, first, m)
        })
    }

    /// Consumes the state: frees what only the iterations need (the lattice, the local weights, the checkerboard's
    /// edge rows, a packed cost), then decodes the marginals ([`MeanField::decode`]) and returns the answer and the
    /// buffers, as [`MeanField::into_buffers`]. The answer's maps never sit beside the lattice.
    pub fn decode_into_buffers(
        mut self,
        subpixel: bool,
    ) -> ((crate::image::DisparityMap, crate::image::Plane<f32>), Buffers) {
        self.full = None;
        self.local = LocalWeights { right: Plane::new(0, 0, 0.0), down: Plane::new(0, 0, 0.0) };
        self.settled = Vec::new();
        self.edges = Vec::new();
        if let Some(packed) = &mut self.packed {
            packed.cost = Vec::new();
        }
        let decoded = self.decode(subpixel);
        (decoded, self.into_buffers())
    }

    /// Consumes the state, returning its buffers for reuse by another [`MeanField`] (the marginals among them). A
    /// packed cost is freed: kept as a spare beside the marginals it would only raise the peak of the next view.
    pub fn into_buffers(self) -> Buffers {
        let mut buffers = Buffers { spare: self.spare, next: self.next, scratch: self.scratch };
        buffers.recycle(self.q);
        buffers
    }

    /// Consumes the state, returning the marginals (`N × M`, unpacked if packed) and the buffers for reuse by another
    /// [`MeanField`] (a packed cost freed, as by [`MeanField::into_buffers`]).
    pub fn into_marginals_and_buffers(self) -> (Marginals, Buffers) {
        let (w, h, m) = (self.cost.width, self.cost.height, self.cost.ndisp);
        let mut buffers = Buffers { spare: self.spare, next: self.next, scratch: self.scratch };
        let data = match (&self.packed, &self.label_bands) {
            (Some(packed), Some(bands)) => {
                // Written in full by the unpacking.
                let mut dense = buffers.take(w * h * m);
                packed.unpack(&self.q, bands, m, &mut dense);
                buffers.recycle(self.q);
                dense
            }
            _ => self.q,
        };
        (CostVolume { width: w, height: h, ndisp: m, data }, buffers)
    }
}

/// Runs mean-field inference and returns the marginals: `p.iterations` iterations, coarse to fine when
/// `p.pyramid_levels` > 1 (`infer_coarse_to_fine`).
pub fn infer_mean_field(
    cost: &CostVolume,
    image: &RgbImage,
    p: &MeanFieldParams,
    weights: PairwiseWeights,
) -> Marginals {
    infer_coarse_to_fine(cost, image, p, weights, Buffers::default()).0
}

#[cfg(test)]
mod tests;
