//! Running the pipeline at reduced resolution (the `downscale` key, `--downscale N`).
//!
//! With a factor N > 1, [`crate::pipeline::run`] reduces both images by N×N box averaging ([`downsample_rgb`]),
//! searches `ceil(ndisp / N)` labels, runs the normal pipeline on the small pair, and brings the disparity map back
//! to the input size ([`upsample_disparity_guided`]: bilinear, then × N). Memory and time of inference scale with
//! pixels × labels, so a factor of 2 needs about 1/8 of the memory and time.
//!
//! - **Downsampling**: output pixel (i, j) is the mean of input block `[i·N, (i+1)·N) × [j·N, (j+1)·N)` clipped
//!   to the image, so a partial block at the right or bottom border is the mean of the pixels it has. The
//!   output is `ceil(w / N) × ceil(h / N)`.
//! - **Upsampling**: each low-resolution pixel stands at the centre of its block (for a partial block, the centre
//!   of the pixels it has). A full-resolution pixel interpolates bilinearly between the (up to) four block
//!   centres around it, and is clamped to the nearest centre beyond the outermost ones.
//! - **Invalid pixels** (`inf`/NaN) are never blended into valid ones: a full-resolution pixel is invalid exactly
//!   when the low-resolution pixel of its own block is invalid (so holes keep their extent, N× larger); otherwise
//!   it interpolates only the valid pixels among the four, their bilinear weights renormalised. (The own block's
//!   pixel always has a positive weight, so there is always something to interpolate.)
//!
//! - **Edge-aware upsampling** (our addition, `[upsample]`; [`upsample_disparity_guided`]): where the four
//!   disparities a pixel interpolates differ by more than `edge_px` (full-resolution px), it lies at a depth edge,
//!   and blending them puts it on neither surface. It takes instead the one of the four whose reduced pixel's
//!   colour is nearest its own, weighted by its bilinear weight (a joint-bilateral choice, not a blend):
//!   the edge follows the full-resolution image (docs/tuning-log.md, "Edge-aware upsampling").
//!
//! Every parameter measured in pixels (σx of the bilateral kernel, the LRC threshold, the weighted-median
//! window, the superpixel count, …) applies at the reduced resolution, unchanged.
//!
//! Both resamplers are O(w·h) (the box filter O(w·h) whatever N), row-parallel, and deterministic whatever the
//! thread count (every output value is computed in a fixed order by one thread).

use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::image::{DisparityMap, Plane, RgbImage, StereoPair};

/// Length of an axis of `len` pixels reduced by `factor`: `ceil(len / factor)`.
///
/// # Panics
/// If `factor` is 0.
pub(crate) fn reduced_len(len: usize, factor: usize) -> usize {
    assert!(factor > 0, "downscale factor must be at least 1");
    len.div_ceil(factor)
}

/// The search range at reduced resolution: `ceil(ndisp / factor)`, at least 1.
///
/// # Panics
/// If `factor` is 0.
pub(crate) fn reduced_ndisp(ndisp: usize, factor: usize) -> usize {
    reduced_len(ndisp, factor).max(1)
}

/// Whether `factor` leaves a valid problem for a `width`-pixel-wide pair with `ndisp` labels: the reduced
/// search range must stay below the reduced width (as [`StereoPair::new`] requires at any resolution).
pub(crate) fn factor_fits(width: usize, ndisp: usize, factor: usize) -> bool {
    factor > 0 && reduced_ndisp(ndisp, factor) < reduced_len(width, factor)
}

/// Reduces an image by `factor` × `factor` box averaging (see the module doc). `factor` 1 returns a copy.
///
/// # Panics
/// If `factor` is 0.
pub(crate) fn downsample_rgb(image: &RgbImage, factor: usize) -> RgbImage {
    let (w, h) = image.dims();
    let mut out = RgbImage::new(reduced_len(w, factor), reduced_len(h, factor));
    for (dst, src) in out.channels.iter_mut().zip(&image.channels) {
        downsample_channel(src, w, h, factor, dst);
    }
    out
}

/// Reduces a plane by `factor` × `factor` box averaging, as [`downsample_rgb`] each channel: the sum of each of a
/// block's columns, then the sum of those (the temporal pyramids' [`crate::imgproc::filter::box_reduce`] sums rows
/// first, and rounds differently; see `imgproc::filter`'s module doc).
///
/// # Panics
/// If `factor` is 0.
pub(crate) fn downsample_plane(plane: &Plane<f32>, factor: usize) -> Plane<f32> {
    let (w, h) = plane.dims();
    let mut out = Plane::new(reduced_len(w, factor), reduced_len(h, factor), 0.0f32);
    downsample_channel(&plane.data, w, h, factor, &mut out.data);
    out
}

/// One row-major `w` × `h` channel reduced by `factor` into `dst` (the reduced size, written in full).
fn downsample_channel(src: &[f32], w: usize, h: usize, factor: usize, dst: &mut [f32]) {
    let sw = reduced_len(w, factor);
    if sw == 0 || reduced_len(h, factor) == 0 {
        return;
    }
    dst.par_chunks_mut(sw).enumerate().for_each_init(
        || vec![0.0f32; w],
        |column_sums, (by, out_row)| {
            let (y0, y1) = (by * factor, ((by + 1) * factor).min(h));
            // Column sums over the block's rows, then block sums along the row, in a fixed order.
            column_sums.copy_from_slice(&src[y0 * w..][..w]);
            for y in y0 + 1..y1 {
                column_sums.iter_mut().zip(&src[y * w..][..w]).for_each(|(s, v)| *s += v);
            }
            for ((bx, o), block) in out_row.iter_mut().enumerate().zip(column_sums.chunks(factor)) {
                let count = (block.len() * (y1 - y0)) as f32;
                debug_assert_eq!(block.len(), ((bx + 1) * factor).min(w) - bx * factor);
                *o = block.iter().sum::<f32>() / count;
            }
        },
    );
}

/// Reduces both views by `factor` and the search range to `ceil(ndisp / factor)`.
///
/// # Errors
/// [`Error::InvalidParam`] naming `downscale` if the reduced search range would not stay below the reduced
/// width (the factor is too large for this pair), with the largest factor that works.
///
/// # Panics
/// If `factor` is 0.
pub(crate) fn downsample_pair(pair: &StereoPair, factor: usize) -> Result<StereoPair<'static>> {
    let (w, h) = pair.left.dims();
    if !factor_fits(w, pair.ndisp, factor) {
        let largest = (1..).take_while(|&f| factor_fits(w, pair.ndisp, f)).last().unwrap_or(1);
        return Err(Error::param(
            "downscale",
            factor,
            format!(
                "at most {largest} for a {w}x{h} pair with ndisp {}: at 1/{factor} the search range {} would not \
                 stay below the width {}",
                pair.ndisp,
                reduced_ndisp(pair.ndisp, factor),
                reduced_len(w, factor)
            ),
        ));
    }
    let (left, right) = rayon::join(|| downsample_rgb(&pair.left, factor), || downsample_rgb(&pair.right, factor));
    StereoPair::new(left, right, reduced_ndisp(pair.ndisp, factor))
}

/// Per output coordinate along one axis: the two low-resolution indices to interpolate between and the weight of
/// the second (the first gets 1 − weight).
fn axis_table(len: usize, factor: usize) -> Vec<(usize, usize, f32)> {
    let low = reduced_len(len, factor);
    // Centre of block k in full-resolution pixel coordinates (partial blocks: the centre of the pixels they have).
    let centre = |k: usize| (k * factor + ((k + 1) * factor).min(len) - 1) as f32 * 0.5;
    (0..len)
        .map(|x| {
            let k = x / factor;
            let (c, xf) = (centre(k), x as f32);
            if xf < c && k > 0 {
                let c0 = centre(k - 1);
                (k - 1, k, (xf - c0) / (c - c0))
            } else if xf > c && k + 1 < low {
                let c1 = centre(k + 1);
                (k, k + 1, (xf - c) / (c1 - c))
            } else {
                (k, k, 0.0)
            }
        })
        .collect()
}

/// Brings a low-resolution map back to `width × height` by bilinear interpolation, keeping invalid (non-finite)
/// pixels invalid as the module doc says; values are not rescaled.
///
/// # Panics
/// If `factor` is 0 or `low` is not `ceil(width / factor) × ceil(height / factor)`.
pub(crate) fn upsample_plane(low: &Plane<f32>, factor: usize, width: usize, height: usize) -> Plane<f32> {
    resample_up(low, factor, width, height, 1.0, None)
}

/// Brings a low-resolution disparity map back to `width × height` (see [`upsample_plane`]) and multiplies it by
/// `factor`, so that the disparities are in full-resolution pixels. Invalid pixels stay `inf`.
///
/// # Panics
/// If `factor` is 0 or `low` is not `ceil(width / factor) × ceil(height / factor)`.
#[cfg(test)]
pub(crate) fn upsample_disparity(low: &DisparityMap, factor: usize, width: usize, height: usize) -> DisparityMap {
    resample_up(low, factor, width, height, factor as f32, None)
}

/// Brings a low-resolution mask back to `width × height`: each pixel takes the flag of the reduced pixel it
/// falls in (nearest; a flag has nothing to interpolate).
///
/// # Panics
/// If `factor` is 0 or `low` is empty.
pub(crate) fn upsample_mask(low: &Plane<bool>, factor: usize, width: usize, height: usize) -> Plane<bool> {
    let (lw, lh) = low.dims();
    let data = (0..width * height)
        .map(|i| low.at(((i % width) / factor).min(lw - 1), ((i / width) / factor).min(lh - 1)))
        .collect();
    Plane::from_parts(width, height, data)
}

/// Brings a low-resolution disparity map back to `guide`'s size as [`upsample_plane`] and multiplies it by `factor`
/// (disparities in full-resolution pixels), edge-aware (see the module doc): where the (up to) four disparities a
/// pixel interpolates span more than `edge_px` full-resolution pixels, it takes the one of them that maximises
/// −|I − Ī_k|² / 2σ² + ln(w_k + 0.05), with I its colour in `guide`, Ī_k the reduced pixel's colour in
/// `low_guide` (the reduced guide), σ = `sigma_rgb` and w_k the bilinear weight (floored, so that a far corner of the
/// right colour still wins). `edge_px` = 0 is the plain bilinear upsampling everywhere.
///
/// # Panics
/// If `low` and `low_guide` differ in size, or as [`upsample_plane`] for `guide`'s size.
pub(crate) fn upsample_disparity_guided(
    low: &DisparityMap,
    low_guide: &RgbImage,
    guide: &RgbImage,
    factor: usize,
    edge_px: f32,
    sigma_rgb: f32,
) -> DisparityMap {
    assert_eq!(low.dims(), low_guide.dims(), "low-resolution map and guide differ in size");
    let (width, height) = guide.dims();
    let edges = EdgeGuide { low: low_guide, full: guide, edge_px, inv: 1.0 / (2.0 * sigma_rgb * sigma_rgb) };
    resample_up(low, factor, width, height, factor as f32, (edge_px > 0.0).then_some(&edges))
}

/// The colours [`upsample_disparity_guided`] chooses by at depth edges.
struct EdgeGuide<'a> {
    /// The reduced guide (one colour per low-resolution pixel).
    low: &'a RgbImage,
    /// The full-resolution guide.
    full: &'a RgbImage,
    /// The span of the four (scaled) values above which a pixel chooses instead of blending.
    edge_px: f32,
    /// 1 / 2σ².
    inv: f32,
}

impl EdgeGuide<'_> {
    /// The value full-resolution pixel `i` takes from its four `corners` (low-resolution index, value, bilinear
    /// weight), `blend` their bilinear result, values scaled by `value_scale`.
    fn choose(&self, i: usize, corners: &[(usize, f32, f32); 4], blend: f32, value_scale: f32) -> f32 {
        let finite = corners.iter().map(|&(_, v, _)| v).filter(|v| v.is_finite());
        let (lo, hi) = finite.fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), v| (lo.min(v), hi.max(v)));
        if (hi - lo) * value_scale <= self.edge_px {
            return blend;
        }
        let c = self.full.rgb(i);
        let mut best = (f32::NEG_INFINITY, blend);
        for &(k, v, w) in corners {
            if v.is_finite() {
                let g = self.low.rgb(k);
                let dist = (c[0] - g[0]).powi(2) + (c[1] - g[1]).powi(2) + (c[2] - g[2]).powi(2);
                let score = (w + 0.05).ln() - dist * self.inv;
                if score > best.0 {
                    best = (score, v * value_scale);
                }
            }
        }
        best.1
    }
}

/// Bilinear upsampling with invalid pixels kept (the module doc), values × `value_scale`; at depth edges the
/// choice of `edges` instead of the blend.
fn resample_up(
    low: &Plane<f32>,
    factor: usize,
    width: usize,
    height: usize,
    value_scale: f32,
    edges: Option<&EdgeGuide<'_>>,
) -> Plane<f32> {
    let (lw, lh) = (reduced_len(width, factor), reduced_len(height, factor));
    assert_eq!(low.dims(), (lw, lh), "low-resolution map is not the {width}x{height} size reduced by {factor}");
    let mut out = Plane::new(width, height, f32::INFINITY);
    if width == 0 || height == 0 {
        return out;
    }
    let (xs, ys) = (axis_table(width, factor), axis_table(height, factor));
    out.data.par_chunks_mut(width).zip(ys.par_iter()).enumerate().for_each(|(y, (row, &(j0, j1, wy)))| {
        let own_row = low.row(y / factor);
        for (x, (o, &(i0, i1, wx))) in row.iter_mut().zip(&xs).enumerate() {
            if !own_row[x / factor].is_finite() {
                continue; // stays inf
            }
            let corners = [
                (j0 * lw + i0, (1.0 - wy) * (1.0 - wx)),
                (j0 * lw + i1, (1.0 - wy) * wx),
                (j1 * lw + i0, wy * (1.0 - wx)),
                (j1 * lw + i1, wy * wx),
            ]
            .map(|(k, w)| (k, low.data[k], w));
            let (mut sum, mut weight) = (0.0f32, 0.0f32);
            for &(_, v, wgt) in &corners {
                if v.is_finite() {
                    sum += wgt * v;
                    weight += wgt;
                }
            }
            let blend = sum / weight * value_scale;
            *o = edges.map_or(blend, |e| e.choose(y * width + x, &corners, blend, value_scale));
        }
    });
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn example_of_downsample_rgb() {
        use crate::image::RgbImage;
        let mut img = RgbImage::new(3, 1);
        img.channels[0] = vec![10.0, 20.0, 60.0];
        let small = crate::scale::downsample_rgb(&img, 2);
        assert_eq!(small.dims(), (2, 1));
        assert_eq!(small.channels[0], vec![15.0, 60.0]); // the partial block is the mean of the one pixel it has
    }

    #[test]
    fn example_of_upsample_disparity() {
        use crate::image::Plane;
        let low = Plane::from_parts(2, 1, vec![1.0, f32::INFINITY]);
        let full = crate::scale::upsample_disparity(&low, 2, 4, 1);
        assert_eq!(full.data, vec![2.0, 2.0, f32::INFINITY, f32::INFINITY]);
    }

    fn grey(w: usize, h: usize, v: &[f32]) -> RgbImage {
        let mut img = RgbImage::new(w, h);
        for (c, ch) in img.channels.iter_mut().enumerate() {
            *ch = v.iter().map(|x| x + 100.0 * c as f32).collect();
        }
        img
    }

    fn assert_close(got: &[f32], want: &[f32]) {
        assert_eq!(got.len(), want.len());
        for (i, (g, w)) in got.iter().zip(want).enumerate() {
            let ok = if w.is_finite() { (g - w).abs() <= 1e-5 } else { !g.is_finite() };
            assert!(ok, "pixel {i}: got {g}, want {w}\n got {got:?}\nwant {want:?}");
        }
    }

    #[test]
    fn guided_upsampling_puts_an_edge_pixel_on_the_surface_of_its_colour() {
        // A step edge inside block 1 (pixels 2, 3 at factor 2): pixel 2 is dark like the near surface (blocks 0 and
        // 1's mean is taken as dark), pixel 3 bright like the far one. Reduced: colour and disparity per block.
        let full = grey(8, 1, &[0.0, 0.0, 0.0, 200.0, 200.0, 200.0, 200.0, 200.0]);
        let low_guide = grey(4, 1, &[0.0, 40.0, 200.0, 200.0]);
        let low = Plane::from_parts(4, 1, vec![10.0, 10.0, 2.0, 2.0]);
        let plain = upsample_disparity(&low, 2, 8, 1);
        let guided = upsample_disparity_guided(&low, &low_guide, &full, 2, 1.0, 10.0);
        // Bilinear blends pixel 3 (between block centres 2.5 and 4.5) to 16; guided it takes the far surface's 4.
        assert!((plain.data[3] - 16.0).abs() < 1e-4, "{:?}", plain.data);
        assert_eq!(guided.data[3], 4.0);
        // Pixel 2 is as dark as block 0 and 1: the near surface, 20.
        assert_eq!(guided.data[2], 20.0);
        // Away from the edge (all four within edge_px), nothing changes.
        for i in [0, 1, 6, 7] {
            assert_eq!(guided.data[i], plain.data[i], "pixel {i}");
        }
        // A ramp whose neighbours differ by less than edge_px is the plain bilinear result everywhere.
        let ramp = Plane::from_parts(4, 1, vec![1.0, 1.2, 1.4, 1.6]);
        assert_eq!(
            upsample_disparity_guided(&ramp, &low_guide, &full, 2, 1.0, 10.0).data,
            upsample_disparity(&ramp, 2, 8, 1).data
        );
        // edge_px 0 is plain bilinear.
        assert_eq!(upsample_disparity_guided(&low, &low_guide, &full, 2, 0.0, 10.0).data, plain.data);
        // Invalid pixels stay invalid and are never chosen.
        let holes = Plane::from_parts(4, 1, vec![10.0, f32::INFINITY, 2.0, 2.0]);
        let out = upsample_disparity_guided(&holes, &low_guide, &full, 2, 1.0, 10.0);
        assert!(!out.data[2].is_finite() && !out.data[3].is_finite());
        assert!(out.data.iter().all(|d| !d.is_finite() || *d == 20.0 || *d == 4.0 || (4.0..=20.0).contains(d)));
    }

    #[test]
    fn sizes_and_ranges() {
        assert_eq!(reduced_len(722, 2), 361);
        assert_eq!(reduced_len(5, 2), 3);
        assert_eq!(reduced_ndisp(190, 2), 95);
        assert_eq!(reduced_ndisp(191, 2), 96);
        assert_eq!(reduced_ndisp(1, 4), 1);
        assert!(factor_fits(10, 6, 1) && factor_fits(10, 6, 2));
        // 10 px, ndisp 6 at 1/3: 2 labels but 4 px (fits); at 1/5: 2 labels, 2 px (does not).
        assert!(factor_fits(10, 6, 3) && !factor_fits(10, 6, 5));
        assert!(!factor_fits(10, 6, 0));
    }

    #[test]
    fn downsample_even_size() {
        #[rustfmt::skip]
        let img = grey(4, 2, &[
            0.0, 2.0,  4.0, 8.0,
            4.0, 6.0, 10.0, 10.0,
        ]);
        let small = downsample_rgb(&img, 2);
        assert_eq!(small.dims(), (2, 1));
        assert_eq!(small.channels[0], vec![3.0, 8.0]);
        assert_eq!(small.channels[2], vec![203.0, 208.0]);
        assert_eq!(downsample_rgb(&img, 1), img);
    }

    #[test]
    fn downsample_odd_size_averages_partial_blocks() {
        #[rustfmt::skip]
        let img = grey(5, 3, &[
            1.0,  3.0,  5.0,  7.0, 20.0,
            5.0,  7.0,  9.0, 11.0, 40.0,
            2.0,  4.0, 12.0, 13.0, 50.0,
        ]);
        let small = downsample_rgb(&img, 2);
        assert_eq!(small.dims(), (3, 2));
        // Full blocks of 4, the right column's blocks of 2, the bottom row's blocks of 2, the corner of 1.
        assert_eq!(small.channels[0], vec![4.0, 8.0, 30.0, 3.0, 12.5, 50.0]);
        assert_eq!(small.channels[1], vec![104.0, 108.0, 130.0, 103.0, 112.5, 150.0]);
        // Factor 3 on 5×3: blocks 3×3 and 2×3.
        let s3 = downsample_rgb(&img, 3);
        assert_eq!(s3.dims(), (2, 1));
        assert_eq!(s3.channels[0], vec![48.0 / 9.0, 141.0 / 6.0]);
    }

    #[test]
    fn upsample_interpolates_between_block_centres() {
        // 5 px at factor 2: block centres at 0.5, 2.5 and 4 (the partial block's single pixel).
        let low = Plane::from_parts(3, 1, vec![0.0, 2.0, 6.0]);
        let d = upsample_disparity(&low, 2, 5, 1);
        // x = 0 clamps to the first centre; x = 1: 0 + 0.25·2; x = 2: 0.75·2; x = 3: 2 + (1/3)·4; x = 4: 6. All ×2.
        assert_close(&d.data, &[0.0, 1.0, 3.0, 2.0 * (2.0 + 4.0 / 3.0), 12.0]);
        let c = upsample_plane(&low, 2, 5, 1);
        assert_close(&c.data, &[0.0, 0.5, 1.5, 2.0 + 4.0 / 3.0, 6.0]);
    }

    #[test]
    fn upsample_two_dimensions() {
        // 2×2 low-res map of a 4×4 image: centres at 0.5 and 2.5 on both axes.
        let low = Plane::from_parts(2, 2, vec![0.0, 4.0, 8.0, 12.0]);
        let full = upsample_plane(&low, 2, 4, 4);
        #[rustfmt::skip]
        let want = [
            0.0, 1.0, 3.0, 4.0,
            2.0, 3.0, 5.0, 6.0,
            6.0, 7.0, 9.0, 10.0,
            8.0, 9.0, 11.0, 12.0,
        ];
        assert_close(&full.data, &want);
    }

    #[test]
    fn upsample_keeps_invalid_pixels_out_of_valid_ones() {
        let inf = f32::INFINITY;
        // A 6×3 image at factor 2: 3×2 low-res with one invalid pixel. Column centres 0.5, 2.5, 4.5; row centres
        // 0.5 and 2 (the bottom blocks are one row high).
        let low = Plane::from_parts(3, 2, vec![1.0, inf, 3.0, 5.0, 7.0, 9.0]);
        let full = upsample_disparity(&low, 2, 6, 3);
        // The invalid block (x 2..4, y 0..2) stays invalid, and no valid pixel takes anything from it. At y = 1
        // (1/3 of the way to the bottom row), x = 1 (wx = 1/4): weights 1/2 on 1, 1/4 on 5, 1/12 on 7 (the 1/6 on
        // inf is dropped) → (7/3) / (5/6) = 2.8; x = 4 (wx = 3/4 from column 1): 1/2 on 3, 1/12 on 7, 1/4 on 9
        // → (13/3) / (5/6) = 5.2. Then ×2.
        #[rustfmt::skip]
        let want = [
            2.0,             2.0,       inf,       inf,       6.0,       6.0,
            2.0 * 7.0 / 3.0, 2.0 * 2.8, inf,       inf,       2.0 * 5.2, 10.0,
            10.0,            11.0,      2.0 * 6.5, 2.0 * 7.5, 2.0 * 8.5, 18.0,
        ];
        assert_close(&full.data, &want);
        // An all-invalid map stays all invalid.
        let none = upsample_disparity(&Plane::new(3, 2, inf), 2, 6, 3);
        assert!(none.data.iter().all(|v| !v.is_finite()));
        // NaN counts as invalid too.
        let nan = upsample_plane(&Plane::from_parts(2, 1, vec![f32::NAN, 4.0]), 2, 4, 1);
        assert_close(&nan.data, &[inf, inf, 4.0, 4.0]);
    }

    #[test]
    fn pair_too_small_for_the_factor_is_an_error() {
        let img = RgbImage::new(40, 8);
        let pair = StereoPair::new(img.clone(), img, 36).unwrap();
        let small = downsample_pair(&pair, 2).unwrap();
        assert_eq!((small.left.dims(), small.ndisp), ((20, 4), 18));
        // Factors 1 to 4 work (at 4: 9 labels, 10 px); at 5: 8 labels, 8 px.
        let e = downsample_pair(&pair, 5).unwrap_err().to_string();
        assert!(e.contains("downscale = 5") && e.contains("at most 4") && e.contains("40x8"), "{e}");
    }
}
