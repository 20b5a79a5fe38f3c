//! Coarse-to-fine inference (our addition, not in the paper; `pyramid_levels` > 1): the same model first on the
//! image and cost volume reduced 2× (block means, same labels, σx / 2), then on the full grid started from those
//! marginals. The local message crosses one pixel per iteration, so a textureless region far from texture needs
//! many iterations on the full grid and 2^(L−1) times fewer at the coarsest level. Measured on trainingQ in
//! docs/tuning-log.md ("Sweep log: LCM — coarse to fine").

use rayon::prelude::*;

use super::Marginals;
use super::{Buffers, MeanField, PairwiseWeights};
use crate::image::{CostVolume, RgbImage};
use crate::params::MeanFieldParams;

/// Fills `q` (`w × h` pixels of `m` labels) from the marginals of the level reduced 2 times: every pixel takes
/// its 2 × 2 block's.
///
/// # Panics
/// If `coarse` is not `w × h` reduced 2 times, or has another number of labels.
pub(super) fn copy_from_coarse(q: &mut [f32], w: usize, h: usize, m: usize, coarse: &Marginals) {
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
pub(crate) fn downsample_volume(vol: &CostVolume, factor: usize) -> CostVolume {
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
/// `p.iterations` steps of [`MeanField`] from `buffers`, as in [`super::infer_mean_field`].
///
/// Memory: besides the input volume and the final Q (in `buffers` when it holds an `N × M` allocation), the
/// coarse levels' volumes and marginals, at most 2/3 of a volume more (Σ 2 · 4^−k).
pub(crate) fn infer_coarse_to_fine(
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

#[cfg(test)]
mod tests {
    use super::*;

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
}
