//! Whether a run fits in one piece or goes in tiles, and how the tiles are cut: the strategy is chosen from the
//! memory model ([`super::memory`]) before anything large is allocated. The tiled run itself is the pipeline's
//! (`pipeline/tile.rs`, whose module doc explains the cut and the memory of a tile).

use super::memory::{check_memory, coarse_level_bytes, estimate_memory_bytes, estimate_tile_bytes};
use crate::error::Result;
use crate::params::Params;

/// The fully connected kernel's reach in pixels, 3σx (`meanfield.sigma_xy`): beyond it a pixel's Gaussian weight
/// is below about 1 % of its peak (e^−4.5).
pub(crate) fn kernel_reach_px(params: &Params) -> usize {
    (3.0 * params.meanfield.sigma_xy).ceil() as usize
}

/// Pixels added on every side of a core of an image of `pixels` pixels: the fully connected kernel's reach, 3σx,
/// plus the weighted median's radius at that image's size (15 + 9 by default up to 0.375 M pixels;
/// [`crate::params::WmedianParams::for_image`]): beyond it no pixel of the core sees the crop's border
/// (docs/tuning-log.md, "Label bands in tiles").
pub(crate) fn halo_px(params: &Params, pixels: usize) -> usize {
    let wm = &params.post.wmedian;
    kernel_reach_px(params) + if wm.enabled { wm.for_image(pixels).radius } else { 0 }
}

/// The smallest core a tile is split down to.
pub(crate) const MIN_CORE_PX: usize = 64;

/// Memory per full-resolution pixel beside the tiles: the pair, its conditioned copies and the vertically
/// aligned right views ([`crate::condition::vertical`]; up to 6 RGB `f32` images), the coarse result at full size, the prior
/// made of it and the stitched maps.
pub(crate) const FULL_SIZE_BYTES_PER_PX: u64 = 6 * 12 + 6 * 4 + 2;

/// How a tiled run cuts the problem.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TilePlan {
    /// The coarse level's downscale factor (≥ 2).
    pub coarse_factor: usize,
    /// Core size in pixels (≥ `MIN_CORE_PX`); a core whose tile exceeds `tile_budget_bytes` is split.
    pub core_px: usize,
    /// Memory one tile may use.
    pub tile_budget_bytes: u64,
    /// Split a core further where its four quarters are less work than it (crop pixels × labels; see
    /// `TileJob::splitting_saves_work`). Off, a core is split only to fit the budget.
    pub split_for_work: bool,
}

/// The memory a tiled run plans for (at most): it stays near this whatever the image size.
pub(crate) const TILED_BUDGET_BYTES: u64 = 2 << 30;

/// Chooses a plan for a `width × height` pair with `ndisp` labels within `limit_bytes`: after the full-size
/// maps, the smallest coarse factor (a power of two) whose untiled run fits what is left, and cores of 1024
/// pixels, split while a tile would not fit either. `None` when even the coarsest level does not fit.
pub(crate) fn plan_tiles(
    width: usize,
    height: usize,
    ndisp: usize,
    params: &Params,
    limit_bytes: u64,
) -> Option<TilePlan> {
    let beside = FULL_SIZE_BYTES_PER_PX * (width * height) as u64;
    let budget = limit_bytes.checked_sub(beside)?;
    // The smallest tile must fit even with the whole range as its window.
    let side = MIN_CORE_PX + 2 * halo_px(params, width * height);
    if estimate_tile_bytes((side + ndisp).min(width), side.min(height), ndisp, params) > tile_share(budget) {
        return None;
    }
    let factor = (1..8).map(|k| 1usize << k).find(|&f| {
        let coarse = coarse_level_params(params, f);
        crate::scale::factor_fits(width, ndisp, f) && coarse_level_bytes(width, height, ndisp, &coarse) <= budget
    })?;
    Some(TilePlan { coarse_factor: factor, core_px: 1024, tile_budget_bytes: budget, split_for_work: true })
}

/// The parameters a tiled run's coarse level at 1/`factor` is planned with: its mean field as every coarse level runs
/// it ([`crate::params::MeanFieldParams::for_coarse_level`]).
fn coarse_level_params(params: &Params, factor: usize) -> Params {
    Params { downscale: factor, meanfield: params.meanfield.for_coarse_level(), ..params.clone() }
}

/// The part of the budget one tile may plan for. The allocator keeps some of each tile's freed memory, so the
/// heap grows over a run of tiles of different sizes even when every tile's estimate stays within the budget; a
/// tenth is left for that.
pub(crate) fn tile_share(budget: u64) -> u64 {
    budget / 10 * 9
}

/// How a run is carried out within a memory limit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Strategy {
    /// In one piece.
    Whole,
    /// In tiles over a coarse level (the pipeline's `tile.rs`).
    Tiled(TilePlan),
}

impl Strategy {
    /// Chooses: in one piece when the estimate fits `limit_bytes` (or the run is downscaled: `--downscale` is the
    /// user's own way to fit), else in tiles within the smaller of `limit_bytes` and [`TILED_BUDGET_BYTES`].
    ///
    /// # Errors
    /// [`crate::Error::OutOfMemory`] (as [`super::memory::check_memory`]) when neither fits.
    pub(crate) fn choose(
        width: usize,
        height: usize,
        ndisp: usize,
        params: &Params,
        limit_bytes: u64,
    ) -> Result<Strategy> {
        let whole = estimate_memory_bytes(width, height, ndisp, params);
        if whole <= limit_bytes || params.downscale > 1 {
            check_memory(width, height, ndisp, params, limit_bytes)?;
            return Ok(Strategy::Whole);
        }
        match plan_tiles(width, height, ndisp, params, limit_bytes.min(TILED_BUDGET_BYTES)) {
            Some(p) => Ok(Strategy::Tiled(p)),
            None => check_memory(width, height, ndisp, params, limit_bytes).map(|()| Strategy::Whole),
        }
    }

    /// The memory the run may use (the estimate in one piece; the tiled budget plus the full-size maps).
    pub(crate) fn memory_bytes(&self, width: usize, height: usize, ndisp: usize, params: &Params) -> u64 {
        match self {
            Strategy::Whole => estimate_memory_bytes(width, height, ndisp, params),
            Strategy::Tiled(p) => p.tile_budget_bytes + FULL_SIZE_BYTES_PER_PX * (width * height) as u64,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A coarse level large enough for grouped labels runs both terms, and is planned with their memory.
    #[test]
    fn a_tiled_coarse_level_is_planned_with_both_terms() {
        let p = Params::default();
        assert!(p.meanfield.grouped_local);
        let coarse = coarse_level_params(&p, 2);
        assert_eq!(coarse.downscale, 2);
        assert!(!coarse.meanfield.grouped_local);
        // 4000 x 3000 at 1/2: 3 M pixels, grouped; both terms need more than the local term alone.
        let as_configured = Params { downscale: 2, ..p.clone() };
        assert!(coarse_level_bytes(4000, 3000, 256, &coarse) > coarse_level_bytes(4000, 3000, 256, &as_configured));
    }
}
