//! The fine pass: the pipeline from the cost volume on, at the resolution the pair is matched at (the whole
//! image, a label window of it, or one tile): Census + gradient cost ([`crate::cost`]), the coarse prior added to
//! it, mean-field inference (or WTA) for both views ([`crate::meanfield`]), then the post-processing
//! ([`crate::post`]): left-right check, occlusion fill, weighted median, slanted planes.

use std::borrow::Cow;

use crate::error::Result;
use crate::image::{CostVolume, DisparityMap, Plane, RgbImage, StereoPair};
use crate::params::{self, LrcMode, MeanFieldParams, Model, Params};
use crate::{cost, meanfield, post};

use super::label_step;
use super::output::{PipelineOutput, Timings};
use super::prior::Prior;

/// Disparity and confidence of one view.
struct ViewEstimate {
    disparity: DisparityMap,
    confidence: Plane<f32>,
}

/// What the fine pass works on: the guidance pair (colour weights, post-processing), the pair the matching cost
/// sees, its cost parameters and an optional coarse prior.
#[derive(Clone, Copy)]
pub(crate) struct FineInput<'a> {
    /// The guidance pair.
    pub guide: &'a StereoPair<'a>,
    /// The pair the matching cost sees (the guidance itself when conditioning is off).
    pub cost_pair: &'a StereoPair<'a>,
    /// The cost parameters for this pair ([`super::prepared::Prepared::cost_params`]).
    pub cost_params: &'a params::CostParams,
    /// ḡ of the gradient normalisation measured on the whole pair ([`super::prepared::Prepared::grad_norm_mean`];
    /// `None`: measured on this pair's left view).
    pub grad_norm_mean: Option<f32>,
    /// The coarse prior, if any.
    pub prior: Option<&'a Prior>,
    /// The left view's first `left_from` columns are there only for the right view's matches (a tile's extension,
    /// [`super::tile`]): the left view's inference and post-processing skip them, and the output maps start after
    /// them (0 outside tiles).
    pub left_from: usize,
    /// How the views run when not as configured (a frame of a sequence, [`FrameViews`]).
    pub views: Option<FrameViews>,
    /// Whether to compute the confidence map ([`PipelineOutput::confidence`]).
    pub confidence: bool,
    /// The guidance pair's measured noise σn (the noisier view's, grey levels; 0 when conditioning is off): the
    /// second median's colour weight widens with it.
    pub noise: f32,
    /// The planes' segmentation to start from (a panning camera's previous frame, moved; `None`: a grid).
    pub segmentation: Option<&'a post::planes::Segmentation>,
    /// Whether a large image's inference on grouped labels (`meanfield.label_step` > 1) keeps the prior's label
    /// bands, grouped with the labels (a travelling frame of a sequence: it runs in the grouped run's time and
    /// memory); otherwise a pass with bands infers on every label (a tile).
    pub grouped_bands: bool,
}

/// How a frame of a sequence runs its two views: its prior has placed each pixel, so fewer mean-field iterations
/// serve, and its right view only serves the left-right check.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct FrameViews {
    /// Mean-field iterations of the left and the right view.
    pub iterations: [usize; 2],
    /// The right view with the local term alone (no fully connected term: no lattice is built for it).
    pub right_local_only: bool,
    /// After each iteration but the last, the pixels at least this sure of their label settle: the later
    /// iterations update only the others ([`meanfield::MeanField::settle`]; `None`: every pixel, every iteration).
    pub settle_at: Option<f32>,
    /// Where the right view contradicts the left answer but the left pixel sees its match (no nearer surface of the
    /// left answer covers it) and its answer agrees with the prior (the answer carried from the previous frame, not
    /// released) within the check's tolerance, the pixel keeps its answer ([`keep_where_carried_agrees`]).
    pub keep_carried: bool,
}

/// The pipeline from the cost volume on, for `input` ([`FineInput`]): cost volume (stage `cost volume`), inference
/// for the left and the right view, left-right check, fill, weighted median and planes. `buffers` carries the
/// large allocations from one call to the next (the tiles).
pub(crate) fn fine_pass(
    params: &Params,
    input: &FineInput<'_>,
    buffers: &mut meanfield::Buffers,
    on_stage: &dyn Fn(&str),
    mut t: Timings,
) -> Result<PipelineOutput> {
    let pass = Pass { params, input: *input, prior_bands: input.prior.filter(|p| p.in_bands) };
    on_stage("cost volume");
    let mut volume = pass.left_volume(buffers, &mut t);
    on_stage("inference (left)");
    let guide = pass.input.guide;
    let guide_left = match pass.input.left_from {
        0 => Cow::Borrowed(guide.left.as_ref()),
        from => Cow::Owned(guide.left.columns_from(from)),
    };
    let minima = volume.minima.take();
    let (left, right) = pass.infer_views(volume, &guide_left, buffers, on_stage, &mut t);
    on_stage("post-processing");
    // The decoded map before post-processing, for the confidence only.
    let decoded = input.confidence.then(|| left.disparity.clone());
    let (disparity, trusted, segmentation) = pass.post_process(left.disparity, right.as_ref(), &guide_left, &mut t);
    let confidence = decoded.map(|decoded| {
        t.time("confidence", || {
            post::confidence::confidence_map(&post::confidence::ConfidenceInputs {
                max_marginal: &left.confidence,
                decoded: &decoded,
                right: right.as_ref().map(|r| (&r.disparity, pass.input.left_from)),
                final_map: &disparity,
                consistent: &trusted,
                coarse: pass.input.prior.map(|p| (&p.disparity, pass.input.left_from)),
                guide: &guide_left,
                minima: minima.as_ref(),
            })
        })
    });
    Ok(PipelineOutput {
        disparity,
        confidence,
        max_marginal: left.confidence,
        consistent: trusted,
        timings: t,
        measured: None,
        vertical_offset: None,
        segmentation: segmentation.filter(|_| pass.input.left_from == 0),
    })
}

/// One fine pass: its parameters, its input, and the prior when it comes with label bands (tiles).
struct Pass<'a> {
    params: &'a Params,
    input: FineInput<'a>,
    prior_bands: Option<&'a Prior>,
}

/// The left view's cost volume, the prior added, and its label bands (tiles).
struct LeftVolume {
    cost: CostVolume,
    bands: Option<meanfield::LabelBands>,
    /// The lowest minima of each pixel's cost before the prior, for the confidence.
    minima: Option<Plane<post::confidence::CostMinima>>,
}

impl Pass<'_> {
    /// The rows' own best labels as one map (with label bands only).
    fn best_of_rows(&self, rows: Vec<Option<Vec<f32>>>) -> Option<Plane<f32>> {
        let (w, h) = self.input.guide.left.dims();
        self.prior_bands.map(|_| Plane::from_parts(w, h, rows.into_iter().flatten().flatten().collect()))
    }

    /// The left view's cost volume with the coarse prior added, and (tiles) each pixel's label band. Each pixel's
    /// own best label is taken before the prior is added; both are done row by row as the volume is written,
    /// unless the prior needs the cost's flatness (a median over the whole volume) first.
    fn left_volume(&self, buffers: &mut meanfield::Buffers, t: &mut Timings) -> LeftVolume {
        let FineInput { guide: pair, cost_pair, cost_params, grad_norm_mean, prior, left_from, .. } = self.input;
        let c = &self.params.condition;
        let (w, h) = pair.left.dims();
        let storage = buffers.take(w * h * pair.ndisp);
        let prior_bands = self.prior_bands;
        let row_prior = prior.filter(|p| !p.needs_flatness());
        let minima = self.input.confidence;
        let (mut cost, rows) = t.time("cost", || {
            let (left, right) = (&cost_pair.left, &cost_pair.right);
            cost::build_cost_volume_then(left, right, pair.ndisp, cost_params, grad_norm_mean, storage, |y, row| {
                let own = prior_bands.map(|_| cost::row_argmins(row, pair.ndisp));
                let minima = minima.then(|| post::confidence::cost_minima_row(row, pair.ndisp));
                if let Some(prior) = row_prior {
                    prior.add_to_row(y, w, row, c);
                }
                (own, minima)
            })
        });
        let (own_rows, minima_rows): (Vec<_>, Vec<_>) = rows.into_iter().unzip();
        let minima = minima.then(|| {
            let all = Plane::from_parts(w, h, minima_rows.into_iter().flatten().flatten().collect());
            if left_from > 0 { all.columns_from(left_from) } else { all }
        });
        let own_best = self.best_of_rows(own_rows);
        if let Some(prior) = prior.filter(|p| p.needs_flatness()) {
            prior.add_to(&mut cost, c, t);
        }
        let bands = own_best.zip(prior_bands).map(|(best, prior)| {
            t.time("bands", || {
                let bands = prior.label_bands(&best, pair.ndisp, false, self.params);
                if left_from > 0 { bands.columns_from(left_from) } else { bands }
            })
        });
        LeftVolume { cost, bands, minima }
    }

    /// The right view's cost volume derived from the left one, with (tiles) its pixels' own best labels taken row by
    /// row.
    fn right_volume(
        &self,
        cost_left: &CostVolume,
        buffers: &mut meanfield::Buffers,
        t: &mut Timings,
    ) -> (CostVolume, Option<Plane<f32>>) {
        let storage = buffers.take(cost_left.data.len());
        let out_of_view = cost::truncation_cost(&self.params.cost);
        let ndisp = self.input.guide.ndisp;
        let (cost_right, best_rows) = t.time("cost right", || {
            cost::derive_right_volume_then(cost_left, out_of_view, storage, |_, row| {
                self.prior_bands.map(|_| cost::row_argmins(row, ndisp))
            })
        });
        (cost_right, self.best_of_rows(best_rows))
    }

    /// Inference for the left view, then (with the left-right check) the right one.
    ///
    /// Left inference first, then the right volume from the left one; the left volume is spent before the right
    /// inference: at most one volume plus one view's inference buffers are alive at a time (three N × M buffers in
    /// all, plus the lattice's). Spent buffers go back to `buffers` for the next volume, view or call. With the
    /// extension (a tile) the right volume comes first, while the left volume still has every column; the columns
    /// the left view keeps then move to the front of the left volume's own storage. The left inference has the same
    /// three buffers alive (the two volumes and its marginals), and no copy of the kept columns is allocated,
    /// page-faulted and freed per tile.
    fn infer_views(
        &self,
        volume: LeftVolume,
        guide_left: &RgbImage,
        buffers: &mut meanfield::Buffers,
        on_stage: &dyn Fn(&str),
        t: &mut Timings,
    ) -> (ViewEstimate, Option<ViewEstimate>) {
        let (params, left_from) = (self.params, self.input.left_from);
        let need_right = params.post.lrc.mode != LrcMode::Off;
        let iterations = self.input.views.map_or([params.meanfield.iterations; 2], |v| v.iterations);
        let settle_at = self.input.views.and_then(|v| v.settle_at);
        let LeftVolume { cost: cost_left, bands: left_bands, .. } = volume;
        let step = params.meanfield.label_step;
        let bands_allow = left_bands.is_none() || self.input.grouped_bands;
        if step > 1 && left_from == 0 && bands_allow && params.model != Model::Wta {
            return self.infer_grouped(cost_left, left_bands, guide_left, iterations, buffers, on_stage, t);
        }
        let (left, cost_right) = if left_from > 0 {
            let cost_right = need_right.then(|| self.right_volume(&cost_left, buffers, t));
            let kept = t.time("cost", || cost_left.into_columns_from(left_from));
            let left = estimate_view(
                params,
                View { image: guide_left, cost: &kept, iterations: iterations[0], local_only: false, settle_at },
                left_bands,
                t,
                buffers,
            );
            buffers.recycle(kept.data);
            (left, cost_right)
        } else {
            let view =
                View { image: guide_left, cost: &cost_left, iterations: iterations[0], local_only: false, settle_at };
            let left = estimate_view(params, view, left_bands, t, buffers);
            // The right volume goes into the left view's spent marginals, and the left volume's storage becomes the
            // right view's marginals: no new allocation for the right view.
            let cost_right = need_right.then(|| self.right_volume(&cost_left, buffers, t));
            buffers.recycle(cost_left.data);
            (left, cost_right)
        };
        let right = cost_right.map(|(cost_right, best)| {
            let ndisp = self.input.guide.ndisp;
            let right_bands = self
                .prior_bands
                .zip(best)
                .map(|(prior, best)| t.time("bands", || prior.label_bands(&best, ndisp, true, params)));
            on_stage("inference (right)");
            // Only a model with both terms has a local term to keep.
            let local_only = self.input.views.is_some_and(|v| v.right_local_only) && params.model == Model::Jem;
            let view = View {
                image: &self.input.guide.right,
                cost: &cost_right,
                iterations: iterations[1],
                local_only,
                settle_at,
            };
            let right = estimate_view(params, view, right_bands, t, buffers);
            buffers.recycle(cost_right.data);
            right
        });
        (left, right)
    }

    /// [`Pass::infer_views`] on labels grouped `label_step` at a time (a large image; [`label_step`]): each view's
    /// grouped volume from the full left one, its inference (the local term alone with `meanfield.grouped_local`),
    /// and its decoded map brought back to the full labels by the full volume. Alive at most: the full volume, one
    /// grouped volume and a view's marginals (the full volume and two halves at step 2, against three full volumes
    /// on every label). With a prior in bands, each view keeps its bands, grouped: the left view's `left_bands`, the
    /// right view's around its own best groups.
    #[allow(clippy::too_many_arguments)]
    fn infer_grouped(
        &self,
        full: CostVolume,
        left_bands: Option<meanfield::LabelBands>,
        guide_left: &RgbImage,
        iterations: [usize; 2],
        buffers: &mut meanfield::Buffers,
        on_stage: &dyn Fn(&str),
        t: &mut Timings,
    ) -> (ViewEstimate, Option<ViewEstimate>) {
        let params = self.params;
        let step = params.meanfield.label_step;
        let out_of_view = cost::truncation_cost(&params.cost);
        let ndisp = self.input.guide.ndisp;
        let settle_at = self.input.views.and_then(|v| v.settle_at);
        let mut infer = |side: label_step::View,
                         image: &RgbImage,
                         iterations: usize,
                         local_only: bool,
                         bands: Option<meanfield::LabelBands>| {
            let storage = buffers.take(full.data.len().div_ceil(step));
            let grouped =
                t.time("group labels", || label_step::grouped_volume(&full, side, step, out_of_view, storage));
            // The right view's bands around its own best groups (the left view's come with its volume).
            let bands = match (side, self.prior_bands) {
                (label_step::View::Left, _) => bands,
                (label_step::View::Right, Some(prior)) => Some(t.time("bands", || {
                    let best = cost::winner_take_all(&grouped);
                    let best =
                        Plane::from_parts(best.width, best.height, best.data.iter().map(|g| g * step as f32).collect());
                    prior.label_bands(&best, ndisp, true, params)
                })),
                (label_step::View::Right, None) => None,
            }
            .map(|b| b.grouped(step));
            let mut estimate = estimate_view(
                params,
                View { image, cost: &grouped, iterations, local_only, settle_at },
                bands,
                t,
                buffers,
            );
            buffers.recycle(grouped.data);
            t.time("refine labels", || {
                label_step::refine_from_full(&mut estimate.disparity, &full, side, step, out_of_view);
            });
            estimate
        };
        // Only a model with both terms has a local term to keep.
        let jem = params.model == Model::Jem;
        let local = params.grouped_local_alone();
        let left = infer(label_step::View::Left, guide_left, iterations[0], local, left_bands);
        let right = (params.post.lrc.mode != LrcMode::Off).then(|| {
            on_stage("inference (right)");
            let frame_local = self.input.views.is_some_and(|v| v.right_local_only);
            let local_only = local || (frame_local && jem);
            // A frame's fewer right-view iterations presume the fully connected term, whose one iteration reaches
            // across the image; where the grouping leaves the local term alone (one pixel per iteration), the
            // right view keeps the configured iterations unless the frame asked for the local term itself.
            let right_iterations = if local && self.input.views.is_some() && !frame_local {
                params.meanfield.iterations
            } else {
                iterations[1]
            };
            infer(label_step::View::Right, &self.input.guide.right, right_iterations, local_only, None)
        });
        buffers.recycle(full.data);
        (left, right)
    }

    /// Left-right check (with `right`), fill, weighted median, planes, the median at depth edges and the sub-pixel
    /// refinement (on the cost pair) on the left view's `disparity`; returns the map, the pixels that passed the
    /// check and the planes' segmentation.
    fn post_process(
        &self,
        mut disparity: DisparityMap,
        right: Option<&ViewEstimate>,
        guide_left: &RgbImage,
        t: &mut Timings,
    ) -> (DisparityMap, Plane<bool>, Option<post::planes::Segmentation>) {
        let (post, left_from) = (&self.params.post, self.input.left_from);
        let mut segmentation = None;
        let mut trusted = Plane::new(disparity.width, disparity.height, true);
        if let Some(right) = right {
            let (checked, mask) = t.time("lrc", || {
                let check = |left: &DisparityMap| {
                    post::lr_check::left_right_check(left, &right.disparity, post.lrc.mode, post.lrc.thresh_px)
                };
                let carried = self.input.prior.filter(|_| self.input.views.is_some_and(|v| v.keep_carried));
                if left_from == 0 {
                    let (mut checked, mut mask) = check(&disparity);
                    if let Some(prior) = carried {
                        keep_where_carried_agrees(&disparity, prior, post.lrc.thresh_px, &mut checked, &mut mask);
                    }
                    return (checked, mask);
                }
                // The left map at the right view's width (unknown in the extension), checked, and cut again.
                let mut full = Plane::new(right.disparity.width, right.disparity.height, f32::INFINITY);
                for y in 0..full.height {
                    full.row_mut(y)[left_from..].copy_from_slice(disparity.row(y));
                }
                let (checked, mask) = check(&full);
                (checked.columns_from(left_from), mask.columns_from(left_from))
            });
            disparity = checked;
            trusted = mask;
        }
        if post.fill {
            t.time("fill", || post::fill::fill_occlusions_in_place(&mut disparity));
        }
        if post.wmedian.enabled {
            let targets = Plane::from_parts(trusted.width, trusted.height, trusted.data.iter().map(|ok| !ok).collect());
            disparity =
                t.time("wmedian", || post::wmedian::weighted_median(&disparity, guide_left, &targets, &post.wmedian));
        }
        if post.sps.enabled {
            let start = self.input.segmentation;
            let (planes, segments) =
                t.time("sps", || post::planes::fit_planes_from(guide_left, &disparity, &trusted, &post.sps, start));
            disparity = planes;
            segmentation = Some(segments);
            // A plane extrapolated to a segment's far corner can leave the search range.
            self.clamp_to_searched(&mut disparity);
        }
        if post.wmedian.enabled && post.wmedian.edge_px > 0.0 {
            disparity = t.time("edges", || {
                let wm = &post.wmedian;
                let targets = post::wmedian::edge_targets(&disparity, wm.edge_px, wm.edge_band, &trusted);
                post::wmedian::weighted_median(&disparity, guide_left, &targets, &wm.second_run(self.input.noise))
            });
        }
        if post.subpixel.enabled {
            // On the pair the cost saw: under noise its views are the denoised ones, the better evidence (trainingQ
            // noise σ 8 6.913 -> 6.897, clean the same).
            let cost = self.input.cost_pair;
            disparity = t.time("subpixel", || {
                let left = match left_from {
                    0 => Cow::Borrowed(cost.left.as_ref()),
                    from => Cow::Owned(cost.left.columns_from(from)),
                };
                post::subpixel::refine_subpixel(&left, &cost.right, &disparity, left_from, &post.subpixel)
            });
            // Half a pixel past either end of the range, from a surface at its edge.
            self.clamp_to_searched(&mut disparity);
        }
        (disparity, trusted, segmentation)
    }

    /// Clamps every finite disparity to the range that was searched, 0..=ndisp − 1: the answer is never outside it.
    fn clamp_to_searched(&self, disparity: &mut DisparityMap) {
        let top = (self.input.guide.ndisp - 1) as f32;
        disparity.data.iter_mut().filter(|d| d.is_finite()).for_each(|d| *d = d.clamp(0.0, top));
    }
}

/// [`FrameViews::keep_carried`]: the pixels of `left` (the answer before the check) that the check rejected
/// (`trusted` false, `checked` invalid there) but that see their match ([`post::lr_check::visible_in_right`]) and agree
/// within `thresh_px` with `prior`'s disparity where it holds (a positive weight: carried and not released) take
/// their answer back and count as trusted. The right view of a frame with a carried prior runs a single iteration;
/// where it disagrees with an answer the previous frame's inference gave and the release test confirmed against
/// the current view, the two outweigh it. A smeared foreground is not kept unless it was carried.
fn keep_where_carried_agrees(
    left: &DisparityMap,
    prior: &Prior,
    thresh_px: f32,
    checked: &mut DisparityMap,
    trusted: &mut Plane<bool>,
) {
    let visible = post::lr_check::visible_in_right(left, thresh_px);
    let agrees = |i: usize| {
        let (d, c) = (left.data[i], prior.disparity.data[i]);
        prior.confidence.data[i] > 0.0 && (d - c).abs() <= thresh_px
    };
    for (i, ok) in trusted.data.iter_mut().enumerate() {
        if !*ok && visible.data[i] && agrees(i) {
            *ok = true;
            checked.data[i] = left.data[i];
        }
    }
}

/// One view for [`estimate_view`]: its image, its cost volume, its mean-field iterations, and whether its mean field
/// runs with the local term alone (no fully connected term, so no lattice; [`FrameViews::right_local_only`]).
struct View<'a> {
    image: &'a RgbImage,
    cost: &'a CostVolume,
    iterations: usize,
    local_only: bool,
    /// [`FrameViews::settle_at`].
    settle_at: Option<f32>,
}

/// Inference for one view: WTA on the cost, or mean field with the view's own image (the configuration's mean field
/// with the view's iterations), within `bands` if given (not with the mean field's pyramid, nor for WTA). `buffers`
/// carries the large allocations from one view to the next.
fn estimate_view(
    params: &Params,
    View { image, cost, iterations, local_only, settle_at }: View<'_>,
    bands: Option<meanfield::LabelBands>,
    t: &mut Timings,
    buffers: &mut meanfield::Buffers,
) -> ViewEstimate {
    match params.model {
        Model::Wta => {
            let disparity = t.time("wta", || cost::winner_take_all(cost));
            let confidence = Plane::new(cost.width, cost.height, 1.0);
            ViewEstimate { disparity, confidence }
        }
        Model::Lcm | Model::Fcm | Model::Jem => {
            let fcm = if local_only { 0.0 } else { params.effective_fcm_weight() };
            let weights = meanfield::PairwiseWeights { fcm, lcm: params.effective_lcm_weight() };
            let reuse = std::mem::take(buffers);
            let mf_params = MeanFieldParams { iterations, ..params.meanfield.clone() };
            let ((disparity, confidence), rest) = if mf_params.pyramid_levels > 1 {
                let (q, mut rest) =
                    t.time("mf pyramid", || meanfield::infer_coarse_to_fine(cost, image, &mf_params, weights, reuse));
                let decoded = t.time("decode", || meanfield::decode_marginals(&q, params.meanfield.subpixel));
                rest.recycle(q.data);
                (decoded, rest)
            } else {
                let mut mf = t.time("mf setup", || match bands {
                    Some(bands) => meanfield::MeanField::in_label_bands(cost, image, &mf_params, weights, reuse, bands),
                    None => meanfield::MeanField::with_buffers(cost, image, &mf_params, weights, reuse),
                });
                t.time("mf iterations", || {
                    for k in 0..iterations {
                        mf.step();
                        if let Some(confidence) = settle_at.filter(|_| k + 1 < iterations) {
                            mf.settle(confidence);
                        }
                    }
                });
                t.time("decode", || mf.decode_into_buffers(params.meanfield.subpixel))
            };
            *buffers = rest;
            ViewEstimate { disparity, confidence }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A rejected pixel takes its answer back only where it sees its match, the carried answer holds there and the
    /// two agree within the tolerance; trusted pixels and the others stay as the check left them.
    #[test]
    fn a_rejected_pixel_keeps_its_answer_only_where_the_carried_one_confirms_it() {
        let row = |v: &[f32]| Plane::from_parts(v.len(), 1, v.to_vec());
        // x = 5 (d 4) covers x = 2's match (1); x = 4 leaves the view.
        let left = row(&[0.0, 1.0, 1.0, 1.0, 9.0, 4.0, 2.0, 2.0]);
        let carried = row(&[0.0, 1.5, 1.0, 3.0, 9.0, 4.0, 2.0, f32::INFINITY]);
        let weight = row(&[1.0, 1.0, 1.0, 1.0, 1.0, 0.0, 1.0, 1.0]);
        let prior =
            Prior { disparity: carried, free: None, confidence: weight, weight: 1.0, flat: 0.0, in_bands: true };
        let mut trusted = Plane::from_parts(8, 1, vec![true, false, false, false, false, false, false, false]);
        let mut checked =
            row(&[0.0, f32::INFINITY, f32::INFINITY, f32::INFINITY, f32::INFINITY, f32::INFINITY, 7.0, f32::INFINITY]);
        keep_where_carried_agrees(&left, &prior, 1.0, &mut checked, &mut trusted);
        // x = 1 agrees (0.5 px) and sees its match; x = 2 is hidden; x = 3 disagrees (2 px); x = 4 has no match;
        // x = 5's carried answer was released; x = 6 agrees and takes its own answer back; x = 7 has none carried.
        assert_eq!(trusted.data, vec![true, true, false, false, false, false, true, false]);
        let inf = f32::INFINITY;
        assert_eq!(checked.data, vec![0.0, 1.0, inf, inf, inf, inf, 2.0, inf]);
    }
}
