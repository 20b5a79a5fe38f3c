//! The fully connected term's kernel (paper §3.1 and Algorithm 1, "message passing"): for every pixel i and
//! label l, Q̃_i(l) = Σ_{j≠i} k(i, j) Q_j(l) with the bilateral kernel
//! k(i, j) = exp(−|p_i − p_j|² / 2σx² − |I_i − I_j|² / 2σf²), for all labels at once through the permutohedral
//! lattice ([`crate::lattice`]), in O(N·M) instead of O(N²·M).
//!
//! Two choices the paper leaves open, made here (the tuning started from them; docs/tuning-log.md):
//! - normalisation ([`Normalization`]): the paper's unnormalised sum grows with the number of similar pixels
//!   around i (≈ 2πσx² = 157 in a uniform region, a few near thin structures), so no single ω suits both; the
//!   default `symmetric` filters D^{-1/2} Q and scales the result by D^{-1/2} (D = the kernel's row sums, as in
//!   Krähenbühl's dense-CRF code); `pixel` divides by D; `none` is the paper's form;
//! - the pixel's own term (`exclude_self`, the paper's j ≠ i): the lattice includes it, so its weight is
//!   subtracted per pixel after slicing.
//!
//! `FullKernel` holds the lattice and the per-pixel factors; the update ([`super::update`]) slices the blurred
//! vertex values per pixel inside its own loop, so the N × M message is never stored.

use crate::image::RgbImage;
use crate::lattice::{Bands, Lattice, LatticeScratch};
use crate::params::{MeanFieldParams, Normalization};

/// The fully connected kernel of one view: the lattice over (x/σx, y/σx, rgb/σf) and the normalisation and
/// self-exclusion factors of every pixel.
pub(super) struct FullKernel {
    lattice: Lattice,
    /// Per-pixel factor applied to Q before filtering (symmetric normalisation) — empty if 1.
    in_scale: Vec<f32>,
    /// Per-pixel factor applied to the filtered message — empty if 1.
    out_scale: Vec<f32>,
    /// Per-pixel self-weight to subtract (scaled like the input) — empty if the self term is kept.
    self_weight: Vec<f32>,
}

impl FullKernel {
    /// Builds the lattice for `image` with σx = `p.sigma_xy`, σf = `p.sigma_rgb`, and the factors of
    /// `p.normalization` and `p.exclude_self` (one filtering of a constant image gives the row sums D).
    pub(super) fn new(image: &RgbImage, p: &MeanFieldParams) -> Self {
        let n = image.len();
        let lattice = Lattice::build(image, p.sigma_xy, p.sigma_rgb);
        let (mut in_scale, mut out_scale, mut self_weight) = (Vec::new(), Vec::new(), Vec::new());
        let mut norm = vec![0.0f32; n];
        lattice.filter(&vec![1.0f32; n], &mut norm, 1, &mut LatticeScratch::default());
        let sw = lattice.self_weight();
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
        FullKernel { lattice, in_scale, out_scale, self_weight }
    }

    /// Splats the marginals `q` (`N × m`, pre-scaled for the symmetric normalisation) onto the lattice and blurs
    /// them: the vertex values that [`FullKernel::slice`] reads per pixel.
    /// With `bands`, pixel i's marginals are 0 outside its band and only its band is splatted (the same result); packed
    /// bands hold only the bands.
    pub(super) fn splat_blur<'s>(
        &self,
        q: &[f32],
        bands: Option<Bands<'_>>,
        m: usize,
        scratch: &'s mut LatticeScratch,
    ) -> &'s [f32] {
        let scale = (!self.in_scale.is_empty()).then_some(self.in_scale.as_slice());
        self.lattice.splat_blur(q, scale, bands, m, scratch)
    }

    /// The raw filtered values of pixel `i` (before [`FullKernel::message_factors`]) into `out`, one per label.
    #[inline(always)]
    pub(super) fn slice(&self, vals: &[f32], i: usize, out: &mut [f32]) {
        self.lattice.slice(vals, i, out);
    }

    /// [`FullKernel::slice`] for the labels `first..first + out.len()` of `m`.
    #[inline(always)]
    pub(super) fn slice_labels(&self, vals: &[f32], i: usize, m: usize, first: usize, out: &mut [f32]) {
        self.lattice.slice_channels(vals, i, m, first, out);
    }

    /// Pixel i's message factors: Q̃_i(l) = out_scale · (raw_i(l) − self_w · Q_i(l)), where raw is the lattice
    /// output for the (possibly pre-scaled) marginals.
    #[inline]
    pub(super) fn message_factors(&self, i: usize) -> (f32, f32) {
        let out_s = self.out_scale.get(i).copied().unwrap_or(1.0);
        let in_s = self.in_scale.get(i).copied().unwrap_or(1.0);
        let self_w = self.self_weight.get(i).copied().unwrap_or(0.0) * in_s;
        (out_s, self_w)
    }

    /// The message Q̃ (normalised, self term excluded as configured) of every pixel for the marginals `q`
    /// (`N × m`), as one `N × m` buffer: the update computes the same values inline.
    pub(super) fn message(&self, q: &[f32], m: usize, scratch: &mut LatticeScratch) -> Vec<f32> {
        let vals = self.splat_blur(q, None, m, scratch);
        let mut out = vec![0.0; q.len()];
        for (i, msg) in out.chunks_exact_mut(m).enumerate() {
            self.slice(vals, i, msg);
            let (out_s, self_w) = self.message_factors(i);
            for (g, qv) in msg.iter_mut().zip(&q[i * m..][..m]) {
                *g = out_s * (*g - self_w * qv).max(0.0);
            }
        }
        out
    }
}
