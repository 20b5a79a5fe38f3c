//! Tiled inference with label windows: pairs too large for one cost volume, in bounded memory.
//!
//! Memory and time of the pipeline grow with pixels × labels, but at any pixel only a narrow band of labels
//! around the answer carries probability. [`run_tiled`] therefore:
//!
//! 1. runs the whole pipeline (the default one, with its own coarse prior) at 1/F resolution over the full
//!    range (`coarse_factor` F; the result is brought back to full size as `--downscale F` does);
//! 2. conditions the full-resolution pair once (noise, contrast: [`crate::condition`]), so every tile sees the
//!    same images and the same measured noise;
//! 3. cuts the image into square *cores* of at most `core_px` pixels and runs the pipeline from the cost volume on
//!    (`fine_pass` in fine.rs: mean field for both views, left-right check, fill, weighted median, planes) on each core
//!    plus a halo, over a *label window* `[lo, hi]`: the coarse disparities in and around the core, widened by F + 2
//!    labels (the coarse answer is good to about one coarse label) — the full range where the coarse run left no
//!    disparity. The right crop is shifted by `lo` columns, so label d' of the tile is disparity `lo + d'` and the tile
//!    is an ordinary problem of `hi − lo + 1` labels. The coarse answer is also the tile's prior (a point prior: no
//!    spread at its depth edges), with the weight of the untiled run, or more where the full resolution adds little
//!    detail to the coarse level ([`super::prior::tiled_prior_floor`]). Inside the window, each pixel's inference keeps
//!    to its own *label band* (`crate::meanfield::bands`): the coarse answers within the kernel's reach, ± the prior's
//!    margin and truncation, and the pixel's own best label. On the ×4 scenes a band is about 44 labels where the
//!    tile's window is about 104: the iterations are about a tenth faster (their time is mostly per pixel, not per
//!    label) and a little more accurate;
//! 4. keeps each tile's core (`lo` added back) and stitches the cores.
//!
//! **Halo.** A core pixel must see what it would see untiled: the fully connected kernel reaches 3σx, and the
//! weighted median reads the pixels within its radius, whose own kernels reach 3σx further; so every side gets
//! [`halo_px`] pixels (24 by default; the plane segments near a crop border are cut by it, and fitted on what is
//! left of them). The left side also gets the window width, so that every core pixel's candidate matches lie
//! inside the right crop. That *extension* is for the right view only: the left view's inference and
//! post-processing start at the halo (`left_from` of `fine_pass`; on Adirondack ×4 it was a quarter of the tiles'
//! pixels).
//! Inside the halo the tile differs from the untiled run (its borders are the crop's), so the tiled result
//! agrees with the untiled one up to the coarse-window truncation and the far reach of the kernel and the planes
//! (tests: `tiled_matches_untiled`).
//!
//! **Work.** A tile costs about its crop's pixels × its labels. A core whose disparities span a wide range (a
//! depth edge, a steep slant) is cheaper in quarters, each with a narrower window, even with their own halos; so
//! a core is split while its four quarters are less work in all than it is by a fifth (docs/tuning-log.md,
//! "Serial work in the tiles").
//!
//! **Memory.** Each tile needs [`crate::setup::memory::estimate_tile_bytes`] for its crop and window, plus one volume
//! for what the allocator keeps of freed volumes and one for the right view's volume, derived before the left view's
//! inference (`tile_need`); a core whose tile would exceed nine tenths of the budget (the rest is left for what the
//! allocator keeps between tiles) is split in four until it fits (or reaches [`MIN_CORE_PX`]). One tile at a time is
//! alive (its pipeline is parallel inside; `run_tiled` says why tiles do not run side by side). The coarse run needs
//! the untiled estimate at 1/F. On top: the full-size pair, its conditioned and aligned copies, the prior and the
//! full-size maps, [`crate::setup::strategy::FULL_SIZE_BYTES_PER_PX`] per pixel. A tile's spent volumes and marginals
//! are the next tile's (`meanfield::Buffers`): a volume freed to the OS and allocated again is page-faulted and zeroed
//! again, which was a tenth of a ×4 run's time.
//!
//! Parameters measured in pixels keep their meaning; the plane segments keep their size (a tile gets the share
//! of `post.sps.segments` that its area is of the image).

use crate::error::Result;
use crate::image::{Plane, StereoPair};
use crate::params::Params;

use super::fine::{FineInput, fine_pass};
use super::output::{PipelineOutput, Timings};
use super::prepared::Prepared;
use super::prior::{CoarseLevel, Prior};
use super::window::{Rect, cut_pairs, cut_plane, window_in};
use crate::setup::memory::estimate_tile_bytes;
use crate::setup::strategy::{MIN_CORE_PX, TilePlan, halo_px, tile_share};

/// Runs the pipeline on `pair` in tiles (see the module doc).
///
/// # Errors
/// As `crate::run`; [`crate::Error::InvalidParam`] if the coarse factor is too large for the pair.
pub fn run_tiled(
    params: &Params,
    pair: &StereoPair,
    plan: &TilePlan,
    options: &super::RunOptions<'_>,
) -> Result<PipelineOutput> {
    let on_stage = options.on_stage;
    params.validate()?;
    let mut t = Timings::default();
    let (w, h) = pair.left.dims();
    let f = plan.coarse_factor.max(2);

    let mut input = Prepared::of(params, pair, None, &mut t);
    // The coarse answer is the base of a tiled run: a point prior, with a floor on its weight where the full
    // resolution adds little detail to it (see `CoarseLevel::tiles`).
    let prior = CoarseLevel::tiles(f).prior(params, pair, &mut input, on_stage, &mut t)?;
    let (guide, cost_pair) = input.pairs(pair);

    on_stage("tiles");
    let mut out = PipelineOutput {
        disparity: Plane::new(w, h, f32::INFINITY),
        confidence: options.confidence.then(|| Plane::new(w, h, 0.0)),
        max_marginal: Plane::new(w, h, 0.0),
        consistent: Plane::new(w, h, false),
        timings: Timings::default(),
        measured: input.measured(),
        vertical_offset: None,
        segmentation: None,
    };
    let margin = f + 2;
    let step = plan.core_px.max(MIN_CORE_PX);
    let mut cores: Vec<Rect> = Vec::new();
    for y0 in (0..h).step_by(step) {
        for x0 in (0..w).step_by(step) {
            cores.push(Rect { x0, y0, x1: (x0 + step).min(w), y1: (y0 + step).min(h) });
        }
    }
    // The median's windows follow the whole image's size, not a tile's.
    let sized = params.for_image(w * h);
    let job = TileJob {
        params: &sized,
        guide,
        cost_pair,
        cost_params: &input.cost_params,
        grad_norm_mean: input.grad_norm_mean,
        noise: input.noise(),
        prior: &prior,
        margin,
        halo: halo_px(params, w * h),
        confidence: options.confidence,
    };
    let share = tile_share(plan.tile_budget_bytes);
    // Each stage of the tiles is reported summed over them, and the cutting and stitching as "tiles (rest)".
    let start = std::time::Instant::now();
    let mut in_tiles = Timings::default();
    // The tiles, depth first, in a fixed order: the output does not depend on the thread count. Where a core is
    // split depends on the coarse answer only, so the list is known before any tile runs.
    let mut tiles = Vec::new();
    while let Some(core) = cores.pop() {
        let tile = job.tile(core);
        let need = tile_need(&tile, params);
        let side = (core.x1 - core.x0).max(core.y1 - core.y0);
        if side > MIN_CORE_PX && (need > share || (plan.split_for_work && job.splitting_saves_work(&tile))) {
            cores.extend(split(core).into_iter().rev());
            continue;
        }
        tiles.push(tile);
    }
    // The volumes and marginals of one tile are the next one's. They are allocated once, at the size of the largest
    // tile's volume (which that tile needs anyway), so that no tile grows them: a grown buffer is copied and its new
    // pages are faulted in and zeroed, a cost paid again for every tile.
    let mut buffers = crate::meanfield::Buffers::default();
    let largest = tiles.iter().map(Tile::work).max().unwrap_or(0) as usize;
    for _ in 0..crate::meanfield::MAX_SPARE {
        buffers.recycle(vec![0.0; largest]);
    }
    // One tile at a time: with tiles side by side (each on its own thread) the allocator's per-thread arenas each
    // keep their tile's freed memory, and the peak passes the limit the tiles were planned for.
    for tile in &tiles {
        let result = job.run(tile, &mut buffers)?;
        in_tiles.add_summed(&result.timings);
        job.keep(tile, &result, &mut out);
    }
    let rest = start.elapsed().saturating_sub(in_tiles.total());
    t.stages.extend(in_tiles.stages);
    t.stages.push(("tiles (rest)", rest));
    out.timings = t;
    Ok(out)
}

/// The memory a tile plans for: [`crate::setup::memory::estimate_tile_bytes`] of its crop and window, plus one volume
/// (crop pixels × labels × 4 bytes): inside a tile the allocator keeps some of what is freed (a volume freed on
/// the heap leaves a hole the next, larger one does not fit). Measured on a 1280×960 scene of 160 labels under
/// `--max-memory 300M` (tests/cli.rs): one tile used 182 MiB against an estimate of 148. Plus the right view's
/// volume, which a tile derives before the left view's inference (`fine_pass`): three volumes are alive then.
fn tile_need(tile: &Tile, params: &Params) -> u64 {
    let (w, h) = (tile.crop.x1 - tile.crop.x0, tile.crop.y1 - tile.crop.y0);
    estimate_tile_bytes(w, h, tile.labels, params) + 2 * 4 * tile.work()
}

/// The four quarters of a core (fewer for a thin one), in row-major order.
fn split(r: Rect) -> Vec<Rect> {
    let (xm, ym) = ((r.x0 + r.x1).div_ceil(2), (r.y0 + r.y1).div_ceil(2));
    let mut parts = Vec::with_capacity(4);
    for (y0, y1) in [(r.y0, ym), (ym, r.y1)] {
        for (x0, x1) in [(r.x0, xm), (xm, r.x1)] {
            if x1 > x0 && y1 > y0 {
                parts.push(Rect { x0, y0, x1, y1 });
            }
        }
    }
    parts
}

/// What every tile shares.
struct TileJob<'a> {
    params: &'a Params,
    guide: &'a StereoPair<'a>,
    cost_pair: &'a StereoPair<'a>,
    cost_params: &'a crate::params::CostParams,
    grad_norm_mean: Option<f32>,
    /// [`FineInput::noise`].
    noise: f32,
    prior: &'a Prior,
    margin: usize,
    /// [`halo_px`].
    halo: usize,
    /// Whether the tiles compute their confidence maps.
    confidence: bool,
}

/// One tile: its core, its halo, its crop, its label window.
struct Tile {
    core: Rect,
    halo: usize,
    crop: Rect,
    lo: usize,
    labels: usize,
}

impl Tile {
    /// The crop's first columns that are there only for the right view's matches: the left view's inference and
    /// output start after them, at the core's halo.
    fn left_from(&self) -> usize {
        self.core.x0.saturating_sub(self.halo) - self.crop.x0
    }

    /// Its work: crop pixels × labels (also the entries of one of its volumes).
    fn work(&self) -> u64 {
        ((self.crop.x1 - self.crop.x0) * (self.crop.y1 - self.crop.y0) * self.labels) as u64
    }
}

impl TileJob<'_> {
    /// The crop and label window of a core.
    fn tile(&self, core: Rect) -> Tile {
        let (w, h) = self.guide.left.dims();
        let ndisp = self.guide.ndisp;
        // The window: the coarse disparities in the core and its halo.
        let around = Rect {
            x0: core.x0.saturating_sub(self.halo),
            y0: core.y0.saturating_sub(self.halo),
            x1: (core.x1 + self.halo).min(w),
            y1: (core.y1 + self.halo).min(h),
        };
        // The full range where the coarse run left no disparity.
        let (lo, labels) = window_in(&self.prior.disparity, around, ndisp, self.margin).unwrap_or((0, ndisp));
        let mut crop = Rect {
            x0: core.x0.saturating_sub(self.halo + labels),
            y0: core.y0.saturating_sub(self.halo),
            x1: (core.x1 + self.halo).min(w),
            y1: (core.y1 + self.halo).min(h),
        };
        // The tile's range must stay below its width.
        if crop.x1 - crop.x0 <= labels {
            crop.x1 = (crop.x0 + labels + 1).min(w);
            crop.x0 = crop.x1.saturating_sub(labels + 1);
        }
        Tile { core, halo: self.halo, crop, lo, labels }
    }

    /// Whether the four quarters of a tile's core, each with its own halo and label window, are clearly less work
    /// in all (crop pixels × labels) than the tile, by a fifth: a core spanning a wide range of disparities is
    /// cheaper in pieces whose windows are narrower, despite their halos. Not for any saving: each split adds
    /// seams, which cost accuracy when the saving is small.
    fn splitting_saves_work(&self, tile: &Tile) -> bool {
        let parts: u64 = split(tile.core).into_iter().map(|c| self.tile(c).work()).sum();
        5 * parts < 4 * tile.work()
    }

    /// Runs the pipeline on one tile.
    fn run(&self, tile: &Tile, buffers: &mut crate::meanfield::Buffers) -> Result<PipelineOutput> {
        let (crop, lo) = (tile.crop, tile.lo);
        let (guide, cost_pair) = cut_pairs(self.guide, self.cost_pair, crop, lo, tile.labels)?;
        let prior = Prior {
            disparity: cut_plane(&self.prior.disparity, crop, |d| d - lo as f32),
            free: None,
            confidence: cut_plane(&self.prior.confidence, crop, |v| v),
            weight: self.prior.weight,
            flat: self.prior.flat,
            in_bands: true,
        };
        let (w, h) = self.guide.left.dims();
        let mut params = self.params.clone();
        let area = ((crop.x1 - crop.x0 - tile.left_from()) * (crop.y1 - crop.y0)) as f64 / (w * h) as f64;
        params.post.sps.segments = ((self.params.post.sps.segments as f64 * area).ceil() as usize).max(1);
        let input = FineInput {
            guide: &guide,
            cost_pair: cost_pair.as_ref().unwrap_or(&guide),
            cost_params: self.cost_params,
            grad_norm_mean: self.grad_norm_mean,
            noise: self.noise,
            prior: Some(&prior),
            left_from: tile.left_from(),
            views: None,
            confidence: self.confidence,
            segmentation: None,
            grouped_bands: false,
        };
        fine_pass(&params, &input, buffers, &|_| {}, Timings::default())
    }

    /// Writes the core of a tile's `result` into `out` (with the window's `lo` added back).
    fn keep(&self, tile: &Tile, result: &PipelineOutput, out: &mut PipelineOutput) {
        let (crop, lo) = (tile.crop, tile.lo);
        let w = self.guide.left.width;
        let x0 = crop.x0 + tile.left_from();
        let cw = crop.x1 - x0;
        for y in tile.core.y0..tile.core.y1 {
            let src = (y - crop.y0) * cw;
            for x in tile.core.x0..tile.core.x1 {
                let i = src + x - x0;
                let o = y * w + x;
                out.disparity.data[o] = result.disparity.data[i] + lo as f32;
                if let (Some(out), Some(tile)) = (&mut out.confidence, &result.confidence) {
                    out.data[o] = tile.data[i];
                }
                out.max_marginal.data[o] = result.max_marginal.data[i];
                out.consistent.data[o] = result.consistent.data[i];
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::image::{DisparityMap, RgbImage};
    use crate::synth::{MASK_VISIBLE, SynthParams, render_scene};

    /// Mean absolute errors of `a` and `b` over the visible pixels, and the share of those where `a` and `b`
    /// differ by more than 1 (occluded pixels are filled guesses in both).
    fn compare(a: &DisparityMap, b: &DisparityMap, gt: &DisparityMap, mask: &Plane<u8>) -> (f64, f64, f64) {
        let (mut ea, mut eb, mut n, mut apart) = (0.0, 0.0, 0usize, 0usize);
        for i in (0..gt.data.len()).filter(|&i| mask.data[i] == MASK_VISIBLE) {
            // A NaN or an invalid pixel on one side only counts as apart.
            let close = (a.data[i] - b.data[i]).abs() <= 1.0 || a.data[i] == b.data[i];
            apart += usize::from(!close);
            ea += f64::from((a.data[i] - gt.data[i]).abs());
            eb += f64::from((b.data[i] - gt.data[i]).abs());
            n += 1;
        }
        (ea / n as f64, eb / n as f64, apart as f64 / n as f64)
    }

    /// The coarse level of a tiled run keeps the full resolution's noise reduced as its ceiling: a noisy synthetic
    /// pair whose random texture, reduced 4×, reads as noise to the one-image estimate (well above σ / 4 without
    /// the ceiling), and at most σ / 4 with it.
    #[test]
    fn the_coarse_level_keeps_the_full_resolutions_noise_as_a_ceiling() {
        use crate::degrade::{Degradation, Recipe, View, degrade};
        let scene = render_scene(&SynthParams { width: 320, height: 240, ndisp: 32, seed: 9 }).unwrap();
        let recipe = Recipe(vec![Degradation::Noise { sigma: 4.0 }]);
        let (left, right) = (
            degrade(&scene.left, &recipe, View::Left, 1).unwrap(),
            degrade(&scene.right, &recipe, View::Right, 1).unwrap(),
        );
        let pair = StereoPair::new(left, right, scene.ndisp).unwrap();
        let params = Params::default();
        let f = 4;
        let input = Prepared::of(&params, &pair, None, &mut Timings::default());
        let ceiling = input.noise_ceiling(f).expect("conditioning is on by default");
        let noise = |out: PipelineOutput| out.measured.expect("a conditioned run reports what it measured").stats.noise;
        let level = CoarseLevel::tiles(f);
        assert_eq!(level.params(&params, &input).downscale, f);
        let own = noise(crate::pipeline::run(&Params { downscale: f, ..params.clone() }, &pair).unwrap());
        let kept = noise(level.run(&params, &pair, &input).unwrap());
        eprintln!("full σn / {f} {ceiling:?}, coarse level's own estimate {own:?}, with the ceiling {kept:?}");
        for v in 0..2 {
            assert!(own[v] > 2.0 * ceiling[v], "view {v}: the texture reads as noise at 1/{f} ({own:?})");
            assert!(kept[v] <= ceiling[v], "view {v}: {kept:?} above the ceiling {ceiling:?}");
        }
    }

    /// Tiles agree with one tile over the whole image: cores of 96 px (12 tiles on 360 × 240) against a single
    /// core. Tolerance: at most 2 % of the visible pixels more than 1 px apart (0.4 % measured), and the tiled error within 10 % (+0.05
    /// px) of the untiled one — tiles see their own crop borders in the halo, their own label windows and plane
    /// segments, so they are not bit-identical; what must not happen is seams or lost surfaces.
    #[test]
    fn tiled_matches_untiled() {
        let scene = render_scene(&SynthParams { width: 360, height: 240, ndisp: 64, seed: 5 }).unwrap();
        let pair = StereoPair::new(scene.left.clone(), scene.right.clone(), scene.ndisp).unwrap();
        let params = Params::default();
        let whole = TilePlan { coarse_factor: 2, core_px: 1024, tile_budget_bytes: u64::MAX, split_for_work: false };
        let tiles = TilePlan { core_px: 96, ..whole };
        let one = run_tiled(&params, &pair, &whole, &crate::pipeline::RunOptions::quiet()).unwrap();
        let many = run_tiled(&params, &pair, &tiles, &crate::pipeline::RunOptions::quiet()).unwrap();
        let (e_many, e_one, apart) = compare(&many.disparity, &one.disparity, &scene.gt, &scene.mask);
        eprintln!("tiled {e_many:.3} px, untiled {e_one:.3} px, {:.2} % apart", 100.0 * apart);
        assert!(apart <= 0.02, "{:.1} % of the pixels more than 1 px apart", 100.0 * apart);
        assert!(e_many <= 1.1 * e_one + 0.05, "tiled {e_many:.3} px vs untiled {e_one:.3} px");
        assert!(e_one < 1.0, "the scene is matched: {e_one:.3} px");
        // A tight memory budget splits the cores further; the result is still the same problem.
        let halo = halo_px(&params, pair.left.width * pair.left.height);
        let need = estimate_tile_bytes(96 + 2 * halo + 40, 96 + 2 * halo, 40, &params);
        let split_plan = TilePlan { tile_budget_bytes: need / 2, ..tiles };
        let small = run_tiled(&params, &pair, &split_plan, &crate::pipeline::RunOptions::quiet()).unwrap();
        let (e_small, _, apart) = compare(&small.disparity, &one.disparity, &scene.gt, &scene.mask);
        assert!(apart <= 0.05 && e_small <= 1.1 * e_one + 0.05, "{apart} {e_small}");
    }

    /// A tile's extension (the columns only the right view's matches need) is left out of the left view: the map
    /// over the kept columns is the one computed with them (up to 1 px on ≥ 98 % of the visible pixels; the
    /// plane segments of a narrower image differ, and the kernel's reach from the left border), and the
    /// buffers carried into a second call give the same bytes as fresh ones.
    #[test]
    fn the_left_extension_is_skipped() {
        let scene = render_scene(&SynthParams { width: 240, height: 160, ndisp: 32, seed: 7 }).unwrap();
        let pair = StereoPair::new(scene.left.clone(), scene.right.clone(), scene.ndisp).unwrap();
        let params = Params::default();
        let pass = |left_from, buffers: &mut crate::meanfield::Buffers| {
            let input = FineInput {
                guide: &pair,
                cost_pair: &pair,
                cost_params: &params.cost,
                grad_norm_mean: None,
                noise: 0.0,
                prior: None,
                left_from,
                views: None,
                confidence: true,
                segmentation: None,
                grouped_bands: false,
            };
            fine_pass(&params, &input, buffers, &|_| {}, Timings::default()).unwrap()
        };
        let mut buffers = crate::meanfield::Buffers::default();
        let all = pass(0, &mut buffers);
        let k = 40;
        let kept = pass(k, &mut buffers);
        assert_eq!(kept.disparity.dims(), (240 - k, 160));
        assert_eq!(kept.confidence.map(|c| c.dims()), Some((240 - k, 160)));
        let cut = |m: &DisparityMap| m.columns_from(k);
        let gt = cut(&scene.gt);
        let mask = scene.mask.columns_from(k);
        let (e_kept, e_all, apart) = compare(&kept.disparity, &cut(&all.disparity), &gt, &mask);
        assert!(apart <= 0.02, "{:.1} % apart", 100.0 * apart);
        assert!(e_kept <= e_all + 0.05, "{e_kept} vs {e_all}");
        // The buffers now hold spent volumes and marginals of both sizes: reused, they give the same bytes.
        let again = pass(0, &mut buffers);
        assert_eq!(again.disparity.data, all.disparity.data);
        let again = pass(k, &mut Default::default());
        assert_eq!(again.disparity.data, kept.disparity.data);
    }

    /// Same input, same plan: byte-identical output whatever the thread count.
    #[test]
    fn tiled_output_does_not_depend_on_threads() {
        let scene = render_scene(&SynthParams { width: 200, height: 120, ndisp: 32, seed: 9 }).unwrap();
        let pair = StereoPair::new(scene.left, scene.right, scene.ndisp).unwrap();
        let plan = TilePlan { coarse_factor: 2, core_px: 64, tile_budget_bytes: u64::MAX, split_for_work: false };
        let run = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            pool.install(|| {
                run_tiled(&Params::default(), &pair, &plan, &crate::pipeline::RunOptions::quiet()).unwrap().disparity
            })
        };
        let one = run(1);
        assert!(one.data.iter().all(|d| d.is_finite()));
        assert_eq!(
            one.data.iter().map(|d| d.to_bits()).collect::<Vec<_>>(),
            run(3).data.iter().map(|d| d.to_bits()).collect::<Vec<_>>()
        );
    }

    /// A core with a near object in one corner is split for work (three of its quarters get a narrow window); a
    /// core over one surface is not (its quarters' windows are as wide, plus their halos).
    #[test]
    fn cores_split_where_the_window_is_wide() {
        let (w, h) = (512, 256);
        let pair = StereoPair::new(RgbImage::new(w, h), RgbImage::new(w, h), 160).unwrap();
        let params = Params::default();
        let job_for = |prior: &Prior, check: &dyn Fn(&TileJob<'_>)| {
            let job = TileJob {
                params: &params,
                guide: &pair,
                cost_pair: &pair,
                cost_params: &params.cost,
                grad_norm_mean: None,
                noise: 0.0,
                prior,
                margin: 4,
                halo: halo_px(&params, pair.left.width * pair.left.height),
                confidence: false,
            };
            check(&job);
        };
        let prior_of = |f: &dyn Fn(usize, usize) -> f32| {
            let disparity = Plane::from_parts(w, h, (0..w * h).map(|i| f(i % w, i / w)).collect());
            Prior { disparity, free: None, confidence: Plane::new(w, h, 1.0), weight: 1.0, flat: 0.0, in_bands: false }
        };
        let core = Rect { x0: 0, y0: 0, x1: w, y1: h };
        job_for(&prior_of(&|x, y| if x < 200 && y < 80 { 150.0 } else { 10.0 }), &|job| {
            assert!(job.splitting_saves_work(&job.tile(core)));
        });
        job_for(&prior_of(&|_, _| 40.0), &|job| assert!(!job.splitting_saves_work(&job.tile(core))));
    }

    #[test]
    fn split_covers_the_core() {
        let r = Rect { x0: 10, y0: 0, x1: 15, y1: 1 };
        let parts = split(r);
        let area: usize = parts.iter().map(|p| (p.x1 - p.x0) * (p.y1 - p.y0)).sum();
        assert_eq!(area, 5);
        assert_eq!(parts.len(), 2);
    }
}
