//! The coarse prior (our addition, not in the paper; see [`crate::condition`], "Coarse prior"): the pipeline run
//! on the pair reduced F×, its answer brought back to full size, and a penalty on the fine cost for labels far
//! from it ([`Prior`]).
//!
//! The coarse level is set up here once ([`CoarseLevel`]), for the whole image's chain and for the tiles
//! ([`super::tile`]); what differs between the two is a named option of it.

use rayon::prelude::*;

use crate::error::Result;
use crate::image::{CostVolume, DisparityMap, Plane, StereoPair};
use crate::imgproc::filter::window_extreme;
use crate::params::{self, Params};
use crate::{condition, cost, meanfield, scale};

use super::output::{PipelineOutput, Timings};
use super::prepared::Prepared;
use crate::setup::strategy::kernel_reach_px;

/// The coarse level's downscale factor in the whole image's chain: each level is the one above it reduced 2×
/// (`condition.prior.levels` levels in all).
pub(crate) const CHAIN_FACTOR: usize = 2;

/// How a coarse level is set up and made into a prior. The whole image's chain ([`CoarseLevel::chain`]) and the
/// tiles ([`CoarseLevel::tiles`]) run the same steps — the pipeline at 1/`factor` with the finer level's noise,
/// reduced, as its ceiling; the right views aligned vertically against its answer; the prior made of it, weakened
/// where the full resolution has detail the coarse level cannot hold — and differ in these options.
#[derive(Clone, Copy, Debug)]
pub(crate) struct CoarseLevel {
    /// The downscale factor F.
    pub factor: usize,
    /// The stage its run is timed and reported under.
    pub stage: &'static str,
    /// The coarse run takes the pair as conditioned at this level, with the conditioning that is done already
    /// (histogram matching, stretch, JPEG) off, this level's block band kept, and a coarse prior of its own one level
    /// fewer (`prior.levels`). Off (tiles), the
    /// coarse level is an ordinary run on the input pair at its size, conditioned by itself.
    pub on_conditioned_pair: bool,
    /// The coarse run's plane segment count is scaled down with its area: the same segment size in the scene. Off
    /// (tiles), it keeps the count: it is the base answer, as good as a run at that resolution can be.
    pub same_segment_size: bool,
    /// The prior leaves a coarse depth edge's whole step free (`condition.prior.spread`). Off (tiles), it is a point
    /// prior: the coarse level is the base answer there, and freeing its depth edges lets the fine level move them
    /// away from where they are (docs/tuning-log.md, "The prior at coarse depth edges"). The coarse level's own
    /// chain has the spread.
    pub spread_at_edges: bool,
    /// The prior's weight has a floor where the full resolution adds little detail to the coarse level
    /// ([`tiled_prior_floor`]; tiles, where the coarse answer is the base of the run).
    pub detail_floor: bool,
}

impl CoarseLevel {
    /// The whole image's coarse prior: the pair reduced [`CHAIN_FACTOR`]×.
    pub(crate) fn chain() -> CoarseLevel {
        CoarseLevel {
            factor: CHAIN_FACTOR,
            stage: "coarse prior",
            on_conditioned_pair: true,
            same_segment_size: true,
            spread_at_edges: true,
            detail_floor: false,
        }
    }

    /// The coarse level of a tiled run, at 1/`factor`.
    pub(crate) fn tiles(factor: usize) -> CoarseLevel {
        CoarseLevel {
            factor,
            stage: "coarse level",
            on_conditioned_pair: false,
            same_segment_size: false,
            spread_at_edges: false,
            detail_floor: true,
        }
    }

    /// Whether the chain's coarse level runs on `pair` (as prepared in `input`): when the prior has a weight, and
    /// the reduced pair is at least 8 × 8 with its reduced range below its width.
    pub(crate) fn applies(&self, pair: &StereoPair, input: &Prepared) -> bool {
        let f = self.factor;
        let fits = pair.left.width >= 8 * f
            && pair.left.height >= 8 * f
            && pair.ndisp.div_ceil(f) < pair.left.width.div_ceil(f);
        (input.prior_weight > 0.0 || input.prior_flat > 0.0) && fits
    }

    /// The coarse run's parameters (its noise ceiling is not one of them: [`CoarseLevel::run`]).
    pub(crate) fn params(&self, params: &Params, input: &Prepared) -> Params {
        let mut coarse = params.clone();
        coarse.downscale = self.factor;
        // The prior is made of the plain bilinear upsampling: an edge-aware one fixes a coarse edge where the coarse
        // level put it, which the fine level should be free to correct (docs/tuning-log.md, "Edge-aware
        // upsampling").
        coarse.upsample.edge_px = 0.0;
        // For the same reason, no median at its depth edges; and no sub-pixel refinement, which a prior of whole
        // coarse pixels has no use for.
        coarse.post.wmedian.edge_px = 0.0;
        coarse.post.subpixel.enabled = false;
        // A coarse level gives the finer one its scene-wide context: both terms of the model, grouped labels or not.
        coarse.meanfield = params.meanfield.for_coarse_level();
        if self.same_segment_size {
            // A 1/F² of the pixels gets a 1/F² of the segments.
            coarse.post.sps.segments = params.post.sps.segments.div_ceil(self.factor * self.factor);
        }
        if self.on_conditioned_pair {
            let c = &params.condition;
            let deeper = c.prior.levels > 1;
            coarse.condition = params::ConditionParams {
                stretch: params::StretchParams { enabled: false, ..c.stretch },
                noise: params::NoiseParams { jpeg: false, block_band: input.block_band(c), ..c.noise },
                prior: params::PriorParams {
                    per_sigma: if deeper { c.prior.per_sigma } else { 0.0 },
                    flat: if deeper { c.prior.flat } else { 0.0 },
                    levels: if deeper { c.prior.levels - 1 } else { 1 },
                    ..c.prior
                },
                ..*c
            };
        }
        coarse
    }

    /// Runs the coarse level on `pair` (or, [`CoarseLevel::on_conditioned_pair`], on the pair as conditioned in
    /// `input`). Its noise is at most this level's, reduced by the F × F box average (σ / F: the `noise_ceiling` of
    /// [`condition::condition_pair`]): its own one-image estimate reads texture as noise, and the gradient term's ε
    /// that follows it hides faint shading (docs/tuning-log.md, "The tiled coarse level's noise").
    ///
    /// # Errors
    /// As [`super::run`].
    pub(crate) fn run(&self, params: &Params, pair: &StereoPair, input: &Prepared) -> Result<PipelineOutput> {
        let coarse_params = self.params(params, input);
        let source = if self.on_conditioned_pair { input.pairs(pair).0 } else { pair };
        super::run_level(&coarse_params, source, &super::RunOptions::quiet(), input.noise_ceiling(self.factor))
    }

    /// Runs the coarse level (stage [`CoarseLevel::stage`]) and makes its answer the prior of this level. On the
    /// way, the right views of `input` are moved onto the left view's rows where the coarse answer shows them off
    /// ([`Prepared::align_vertically`]).
    ///
    /// # Errors
    /// As [`super::run`].
    pub(crate) fn prior(
        &self,
        params: &Params,
        pair: &StereoPair,
        input: &mut Prepared,
        on_stage: &dyn Fn(&str),
        t: &mut Timings,
    ) -> Result<Prior> {
        let c = &params.condition;
        on_stage(self.stage);
        let coarse = t.time(self.stage, || self.run(params, pair, input))?;
        let grey_left = input.pairs(pair).1.left.to_grey();
        input.align_vertically(c, &grey_left, &coarse, t);
        let mut weight = input.prior_weight;
        if self.detail_floor {
            let coarse_grey = scale::downsample_rgb(&input.pairs(pair).1.left, self.factor).to_grey();
            weight = weight.max(tiled_prior_floor(&grey_left, &coarse_grey));
        }
        let mut prior = Prior::from_coarse(coarse, weight, input.prior_flat, c.prior.untrusted);
        prior.weaken_at_detail(&grey_left, self.factor, c.prior.detail);
        if self.spread_at_edges {
            prior.spread_at_edges(self.factor, c.prior.spread, c.prior.trunc_px);
        }
        Ok(prior)
    }
}

/// What the full-resolution cost is pulled towards: a coarse run's disparities, in the labels of the pair it
/// is added to (see [`condition`], "Coarse prior").
pub(crate) struct Prior {
    /// The coarse disparities (`inf`: no prior at that pixel).
    pub disparity: DisparityMap,
    /// The labels the prior leaves free (up to its margin), `(low, high)`: beside a coarse depth edge the whole
    /// step, elsewhere the coarse disparity itself ([`Prior::spread_at_edges`]; `None`: the coarse disparity
    /// everywhere).
    pub free: Option<(DisparityMap, DisparityMap)>,
    /// Per-pixel factor of the weight (the coarse confidence, lowered where its left-right check failed).
    pub confidence: Plane<f32>,
    /// λ before the per-pixel factor.
    pub weight: f32,
    /// Where the fine cost is flat, λ is at least this × its flatness ([`cost::flatness`]; `condition.prior.flat`).
    pub flat: f32,
    /// Whether inference keeps each pixel to a band of labels around the prior ([`Prior::label_bands`]; tiles).
    pub in_bands: bool,
}

/// The labels either side of a pixel's own best label that its band holds ([`Prior::label_bands`]): the sub-pixel
/// parabola's neighbours and one more. Measured in tiles (docs/tuning-log.md, "Label bands in tiles").
const OWN_BEST_BAND: usize = 2;

impl Prior {
    /// The prior of a coarse run's output (brought to the fine size) with weight λ = `weight`: a pixel the coarse
    /// left-right check rejected was filled by a guess, so its factor is its max-marginal × `untrusted`.
    pub(crate) fn from_coarse(coarse: PipelineOutput, weight: f32, flat: f32, untrusted: f32) -> Prior {
        let mut confidence = coarse.max_marginal;
        confidence.data.iter_mut().zip(&coarse.consistent.data).filter(|(_, ok)| !**ok).for_each(|(c, _)| {
            *c *= untrusted;
        });
        Prior { disparity: coarse.disparity, free: None, confidence, weight, flat, in_bands: false }
    }

    /// Each pixel's band of labels for inference at the fine level ([`meanfield::bands`]): the labels the prior
    /// leaves free within the fully connected kernel's reach (3σx), widened by the labels over which its
    /// penalty still changes (margin + truncation + 1), joined with the pixel's own best label by its cost alone,
    /// `own_best`, ± [`OWN_BEST_BAND`]. For the `right_view`, the prior is carried over to it first
    /// ([`meanfield::bands::warp_to_right_view`]).
    pub(crate) fn label_bands(
        &self,
        own_best: &DisparityMap,
        ndisp: usize,
        right_view: bool,
        params: &Params,
    ) -> meanfield::LabelBands {
        let c = &params.condition;
        let reach = kernel_reach_px(params);
        let half_width = c.prior.margin_px + c.prior.trunc_px + 1.0;
        let (low, high) = self.free.as_ref().map_or((&self.disparity, &self.disparity), |(l, h)| (l, h));
        let bands =
            |low, high| meanfield::LabelBands::around((low, high), own_best, ndisp, reach, half_width, OWN_BEST_BAND);
        if right_view {
            let (low, high) = meanfield::bands::warp_to_right_view(low, high);
            bands(&low, &high)
        } else {
            bands(low, high)
        }
    }

    /// Beside a depth edge of the coarse answer (a level `factor` times coarser), leaves the whole step free: the
    /// range of the coarse disparities within `spread` coarse pixels where they differ by more than `min_jump`
    /// ([`edge_range`]; nothing when `spread` is 0).
    pub(crate) fn spread_at_edges(&mut self, factor: usize, spread: usize, min_jump: f32) {
        if spread > 0 {
            self.free = Some(edge_range(&self.disparity, spread * factor, min_jump));
        }
    }

    /// Adds the prior's penalty to `cost` (the fine level's left volume, before inference): at pixel i, label d
    /// gets λᵢ·min(max(dist(d) − margin, 0), trunc), dist the distance from the labels the prior leaves free, and
    /// λᵢ = max(`weight`, `flat` × the flatness of the pixel's cost, [`cost::flatness`]) × its confidence factor
    /// (the confidence only with `prior.confidence`). Stage `flatness` when the floor can matter.
    pub(crate) fn add_to(&self, cost: &mut CostVolume, c: &params::ConditionParams, t: &mut Timings) {
        let m = cost.ndisp;
        let flatness = self.needs_flatness().then(|| t.time("flatness", || cost::flatness(cost)));
        cost.data.par_chunks_mut(m).enumerate().for_each(|(i, costs)| {
            let floor = flatness.as_ref().map_or(0.0, |f| self.flat * f.data[i]);
            self.add_at(i, floor, costs, c);
        });
    }

    /// Whether [`Prior::add_to`] needs the cost's flatness, a pass over the whole volume first: not where the
    /// noise-scaled weight is at least `flat`, since the floor never exceeds it.
    pub(crate) fn needs_flatness(&self) -> bool {
        self.flat > self.weight
    }

    /// [`Prior::add_to`] for row `y` of a volume `width` pixels wide, `row` its costs (for a prior that does not
    /// need the flatness: [`Prior::needs_flatness`]).
    pub(crate) fn add_to_row(&self, y: usize, width: usize, row: &mut [f32], c: &params::ConditionParams) {
        debug_assert!(!self.needs_flatness());
        let m = row.len() / width.max(1);
        for (x, costs) in row.chunks_exact_mut(m.max(1)).enumerate() {
            self.add_at(y * width + x, 0.0, costs, c);
        }
    }

    /// The penalty of pixel `i` added to its `costs`, its weight at least `floor`.
    #[inline(always)]
    fn add_at(&self, i: usize, floor: f32, costs: &mut [f32], c: &params::ConditionParams) {
        let (margin, trunc) = (c.prior.margin_px, c.prior.trunc_px);
        let (low, high) = self.free.as_ref().map_or((&self.disparity, &self.disparity), |(l, h)| (l, h));
        let (low, high) = (low.data[i], high.data[i]);
        if !low.is_finite() {
            return;
        }
        let weight = self.weight.max(floor);
        let lambda = if c.prior.confidence { weight * self.confidence.data[i] } else { weight };
        for (d, v) in costs.iter_mut().enumerate() {
            // The distance from [low, high]: |d − d_coarse| where the two are one. Compares and selects, the same
            // values as `f32::max` and `clamp` for these (never NaN) operands, without their NaN fix-ups.
            let d = d as f32;
            let above = d - high;
            let off = if d < low {
                low - d
            } else if above > 0.0 {
                above
            } else {
                0.0
            };
            let over = off - margin;
            let penalty = if over > 0.0 { over } else { 0.0 };
            *v += lambda * if penalty < trunc { penalty } else { trunc };
        }
    }

    /// Weakens the prior where `grey` (the full-resolution cost image) has detail a level `factor` times coarser
    /// cannot hold ([`detail_factor`] with `k`; nothing when `k` is 0).
    pub(crate) fn weaken_at_detail(&mut self, grey: &Plane<f32>, factor: usize, k: f32) {
        if k > 0.0 {
            let f = detail_factor(grey, factor, k);
            self.confidence.data.iter_mut().zip(&f.data).for_each(|(c, f)| *c *= f);
        }
    }
}

/// The least weight of the coarse prior in a tile whose full resolution holds no more detail than its coarse
/// level (see [`tiled_prior_floor`]). The untiled default weighs the prior by the measured noise (0.5·σn) and the
/// cost's flatness, relative to the image's own; on an image upscaled ×4 every pixel's cost is about as flat, and
/// the fine cost alone drifts inside its label window: the floor holds it to the coarse answer (docs/tuning-log.md,
/// "Label bands in tiles").
pub(crate) const TILED_PRIOR_FLOOR: f32 = 2.0;

/// The prior's floor in the tiles: [`TILED_PRIOR_FLOOR`] × min(1, 2·(1 − k)), k the share of the coarse level's
/// sharpness ([`crate::condition::sharpness`], the cost pair's left view) that the full resolution keeps. A photo
/// has detail at every scale and keeps most of it (trainingQ run in tiles over a coarse level at 1/2: k 0.85–0.96,
/// a floor of 0.2–0.6); an image enlarged from a smaller one has none to add (the ×4 scenes: k 0.35–0.45, the
/// full floor). A constant floor of 2 cost the photos: tiled trainingQ (`jem batch --max-memory 300M`) 3.83 with
/// it, 3.67 with this one, 3.68 with none; the ×4 scenes are unchanged.
pub(crate) fn tiled_prior_floor(full_grey: &Plane<f32>, coarse_grey: &Plane<f32>) -> f32 {
    let coarse = condition::sharpness(coarse_grey);
    let kept = if coarse > 0.0 { condition::sharpness(full_grey) / coarse } else { 1.0 };
    TILED_PRIOR_FLOOR * (2.0 * (1.0 - kept)).clamp(0.0, 1.0)
}

/// How much of each pixel's neighbourhood a coarse level `factor` times smaller cannot hold, as a factor for the
/// coarse prior's weight: `1 / (1 + D / (k·D̄))`, where D is the 3 × 3 mean of |G − the mean of G over the
/// `factor` × `factor` block holding the pixel| and D̄ its mean over the image (so the factor does not depend on the
/// image's contrast). Thin structures and edges, where the coarse answer is least reliable, get a weaker prior; flat
/// regions keep it. All ones when `k` ≤ 0 or the image has no detail at all.
pub(crate) fn detail_factor(grey: &Plane<f32>, factor: usize, k: f32) -> Plane<f32> {
    let (w, h) = grey.dims();
    let f = factor.max(1);
    // The mean of each F × F block (clipped at the borders), once per block.
    let bw = w.div_ceil(f);
    let mut block_means = vec![0.0f32; bw * h.div_ceil(f)];
    block_means.par_chunks_mut(bw.max(1)).enumerate().for_each(|(by, means)| {
        let (y0, y1) = (by * f, (by * f + f).min(h));
        for (bx, m) in means.iter_mut().enumerate() {
            let (x0, x1) = (bx * f, (bx * f + f).min(w));
            let mut sum = 0.0f32;
            for yy in y0..y1 {
                sum += grey.row(yy)[x0..x1].iter().fold(0.0f32, |a, &g| a + g);
            }
            *m = sum / ((y1 - y0) * (x1 - x0)) as f32;
        }
    });
    let mut lost = Plane::new(w, h, 0.0f32);
    lost.data.par_chunks_mut(w.max(1)).enumerate().for_each(|(y, row)| {
        let (g, means) = (grey.row(y), &block_means[y / f * bw..]);
        for (x, v) in row.iter_mut().enumerate() {
            *v = g[x] - means[x / f];
        }
    });
    let mut out = crate::imgproc::filter::local_mean_abs(&lost, 1);
    let scale = k * crate::imgproc::stats::plane_mean(&out);
    if scale > 0.0 && scale.is_finite() {
        out.data.iter_mut().for_each(|d| *d = 1.0 / (1.0 + *d / scale));
    } else {
        out.data.fill(1.0);
    }
    out
}

/// The range of disparities a coarse prior accepts at each pixel: `(low, high)`, both the pixel's own value
/// except beside a depth edge, where the values within `radius` pixels (a square window) differ by more than
/// `min_jump`; there they are the window's smallest and largest. Non-finite values (no prior) are skipped, and
/// stay non-finite. `radius` 0 returns two copies.
pub(crate) fn edge_range(coarse: &Plane<f32>, radius: usize, min_jump: f32) -> (Plane<f32>, Plane<f32>) {
    let (w, h) = coarse.dims();
    if radius == 0 || w == 0 || h == 0 {
        return (coarse.clone(), coarse.clone());
    }
    let (lo, hi) = (
        window_extreme(coarse, radius, f32::INFINITY, f32::min),
        window_extreme(coarse, radius, f32::NEG_INFINITY, f32::max),
    );
    let mut low = coarse.clone();
    let mut high = coarse.clone();
    low.data.par_iter_mut().zip(&mut high.data).enumerate().for_each(|(i, (l, h))| {
        if l.is_finite() && hi.data[i] - lo.data[i] > min_jump {
            (*l, *h) = (lo.data[i], hi.data[i]);
        }
    });
    (low, high)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::RgbImage;
    use crate::synth;

    /// The coarse levels keep both terms of the model whatever their size; the full resolution's setting is its own.
    #[test]
    fn a_coarse_level_infers_with_both_terms() {
        let scene = synth::render_scene(&synth::SynthParams { width: 64, height: 48, ndisp: 16, seed: 2 }).unwrap();
        let pair = StereoPair::borrowed(&scene.left, &scene.right, scene.ndisp).unwrap();
        let params = Params::default();
        assert!(params.meanfield.grouped_local);
        let input = Prepared::of(&params, &pair, None, &mut Timings::default());
        for level in [CoarseLevel::chain(), CoarseLevel::tiles(4)] {
            let coarse = level.params(&params, &input);
            assert!(!coarse.meanfield.grouped_local, "{level:?}");
            assert_eq!(coarse.meanfield.fcm_weight, params.meanfield.fcm_weight);
        }
    }

    #[test]
    fn the_prior_holds_where_the_cost_is_flat_even_at_zero_noise() {
        // Two pixels, five labels: a flat cost and one with a clear winner at label 4; the coarse answer says 1.
        let data = vec![3.0, 3.0, 3.0, 3.0, 3.0, 6.0, 6.0, 6.0, 6.0, 0.0];
        let prior = |flat| Prior {
            disparity: Plane::from_parts(2, 1, vec![1.0, 1.0]),
            free: None,
            confidence: Plane::new(2, 1, 1.0),
            weight: 0.0, // a noiseless pair: no noise-scaled weight
            flat,
            in_bands: false,
        };
        let c = {
            let prior = params::PriorParams { margin_px: 0.0, trunc_px: 8.0, ..Default::default() };
            params::ConditionParams { prior, ..Default::default() }
        };
        let with = |flat| {
            let mut cost = CostVolume { width: 2, height: 1, ndisp: 5, data: data.clone() };
            prior(flat).add_to(&mut cost, &c, &mut Timings::default());
            cost
        };
        assert_eq!(with(0.0).data, data, "no floor, no weight: the cost is unchanged");
        let held = with(1.0);
        // The flat pixel has flatness 1 (λ = 1): label 1 now wins, by 1 per label of distance.
        assert_eq!(cost::argmin(held.pixel(0)), 1);
        assert_eq!(held.pixel(0), &[4.0, 3.0, 4.0, 5.0, 6.0]);
        // The distinct pixel: spread 4.8, median spread 4.8 (the upper of two), flatness ½: the winner stays.
        assert_eq!(cost::argmin(held.pixel(1)), 4);
        assert!((held.pixel(1)[4] - 1.5).abs() < 1e-6, "{:?}", held.pixel(1));
    }

    /// The prior added row by row as the volume is built, and the own best labels taken there, are what the
    /// separate passes give (the fused path of `fine_pass`), bit for bit.
    #[test]
    fn the_prior_added_row_by_row_is_the_prior_added_after() {
        let scene = synth::render_scene(&synth::SynthParams { width: 96, height: 64, ndisp: 24, seed: 3 }).unwrap();
        let (w, h, m) = (96, 64, scene.ndisp);
        let coarse: Vec<f32> = crate::test_util::rand_vec(w * h, 5).iter().map(|v| v * m as f32).collect();
        let mut disparity = Plane::from_parts(w, h, coarse);
        disparity.data[7] = f32::INFINITY; // no prior at that pixel
        let confidence = Plane::from_parts(w, h, crate::test_util::rand_vec(w * h, 6));
        let prior = Prior { disparity, free: None, confidence, weight: 1.5, flat: 1.0, in_bands: true };
        assert!(!prior.needs_flatness());
        let (c, p) = (params::ConditionParams::default(), params::CostParams::default());
        let mut after = cost::build_cost_volume(&scene.left, &scene.right, m, &p);
        let own = cost::winner_take_all(&after);
        prior.add_to(&mut after, &c, &mut Timings::default());
        let (fused, rows) =
            cost::build_cost_volume_then(&scene.left, &scene.right, m, &p, None, Vec::new(), |y, row| {
                let own = cost::row_argmins(row, m);
                prior.add_to_row(y, w, row, &c);
                own
            });
        assert_eq!(fused.data, after.data);
        assert_eq!(rows.concat(), own.data);
        let (right, right_rows) =
            cost::derive_right_volume_then(&after, 30.0, Vec::new(), |_, row| cost::row_argmins(row, m));
        assert_eq!(right.data, cost::derive_right_volume(&after, 30.0).data);
        assert_eq!(right_rows.concat(), cost::winner_take_all(&right).data);
    }

    /// The prior's floor follows the detail the full resolution adds: seeded white noise has detail at every scale
    /// and keeps its sharpness over its half-resolution copy (no floor); the same noise enlarged ×4 (bilinear)
    /// keeps little of it over its quarter (the whole floor). A flat image measures nothing and gets none.
    #[test]
    fn the_prior_floor_is_for_images_without_fine_detail() {
        let (w, h) = (160, 120);
        let mut noise = RgbImage::new(w, h);
        for (c, ch) in noise.channels.iter_mut().enumerate() {
            *ch = crate::test_util::rand_vec(w * h, 10 + c as u64).iter().map(|v| 255.0 * v).collect();
        }
        let reduced = |img: &RgbImage, f| crate::scale::downsample_rgb(img, f).to_grey();
        let detailed = tiled_prior_floor(&noise.to_grey(), &reduced(&noise, 2));
        assert!(detailed < 0.1 * TILED_PRIOR_FLOOR, "floor {detailed} on white noise");
        let mut enlarged = RgbImage::new(4 * w, 4 * h);
        for (dst, src) in enlarged.channels.iter_mut().zip(&noise.channels) {
            *dst = crate::scale::upsample_plane(&Plane::from_parts(w, h, src.clone()), 4, 4 * w, 4 * h).data;
        }
        assert_eq!(tiled_prior_floor(&enlarged.to_grey(), &reduced(&enlarged, 4)), TILED_PRIOR_FLOOR);
        let flat = Plane::new(64, 64, 100.0);
        assert_eq!(tiled_prior_floor(&flat, &flat), 0.0, "no detail at either level: no measurement, no floor");
    }

    /// A one-pixel line on a flat background: the 2 × 2 block average cannot hold it, so the prior is weakest on
    /// and beside it and untouched far from it; the factor ignores the image's contrast, and a flat image keeps
    /// the whole prior.
    #[test]
    fn detail_factor_weakens_the_prior_at_thin_structures_only() {
        let (w, h) = (24, 12);
        let line = |contrast: f32| Plane {
            width: w,
            height: h,
            data: (0..w * h).map(|i| if i % w == 11 { 100.0 + contrast } else { 100.0 }).collect(),
        };
        let f = detail_factor(&line(60.0), 2, 3.0);
        let at = |x: usize| f.data[6 * w + x];
        assert!(at(11) < 0.5 && at(10) < 0.8, "on the line {} beside it {}", at(11), at(10));
        assert_eq!(at(2), 1.0);
        assert_eq!(at(20), 1.0);
        let weaker = detail_factor(&line(6.0), 2, 3.0);
        assert!(f.data.iter().zip(&weaker.data).all(|(a, b)| (a - b).abs() < 1e-6), "contrast changed the factor");
        let flat = detail_factor(&line(0.0), 2, 3.0);
        assert!(flat.data.iter().all(|&v| v == 1.0));
        assert!(detail_factor(&line(60.0), 2, 0.0).data.iter().all(|&v| v == 1.0));
    }

    /// The prior's free range: widened to the whole step within `radius` of a coarse depth edge, on both sides;
    /// a slope whose window spans less than `min_jump` keeps the point; a pixel without a prior keeps none.
    #[test]
    fn edge_range_frees_the_step_only_beside_depth_edges() {
        let (w, h) = (20, 5);
        // A step from 10 to 30 at x = 10, a gentle slope (0.1 px per px) on top, and one pixel without a prior.
        let mut coarse = Plane::from_parts(
            w,
            h,
            (0..w * h).map(|i| 0.1 * (i % w) as f32 + if i % w >= 10 { 20.0 } else { 10.0 }).collect(),
        );
        coarse.data[2 * w + 3] = f32::INFINITY;
        let (low, high) = edge_range(&coarse, 2, 8.0);
        for y in 0..h {
            for x in 0..w {
                let (c, lo, hi) = (coarse.row(y)[x], low.row(y)[x], high.row(y)[x]);
                if !c.is_finite() {
                    assert!(!lo.is_finite() && !hi.is_finite(), "no prior at ({x}, {y})");
                } else if (8..12).contains(&x) {
                    assert_eq!(
                        (lo, hi),
                        (0.1 * (x.saturating_sub(2)) as f32 + 10.0, 0.1 * (x + 2) as f32 + 20.0),
                        "({x}, {y})"
                    );
                } else {
                    assert_eq!((lo, hi), (c, c), "away from the step, ({x}, {y})");
                }
            }
        }
        // Radius 0: two copies.
        let (low, high) = edge_range(&coarse, 0, 8.0);
        assert!(low.data.iter().zip(&coarse.data).all(|(a, b)| a == b || (!a.is_finite() && !b.is_finite())));
        assert!(high.data.iter().zip(&coarse.data).all(|(a, b)| a == b || (!a.is_finite() && !b.is_finite())));
    }
}
