//! The memory model: what a run will need, estimated before anything large is allocated, and the guard that
//! refuses a run that would not fit ([`check_memory`]; [`crate::pipeline::tile`] runs such a pair in tiles instead).

use std::sync::{Condvar, Mutex};

use crate::error::{self, Error, Result};
use crate::params::{LrcMode, Model, Params, Schedule};
use crate::scale;

/// Estimated peak memory of [`crate::pipeline::run`] in bytes for a `width × height` pair with `ndisp` labels and
/// `params` (including [`Params::downscale`]).
///
/// The model, at the resolution the pipeline runs at (the input reduced by `params.downscale`: N pixels,
/// M labels, one N × M `f32` volume = 4NM bytes):
/// - JEM and FCM: two volumes alive at the peak — the cost volume and the marginals Q (the right view reuses
///   the left view's spent buffers, so it adds none), three with the Jacobi schedule (the next Q; the
///   checkerboard updates Q in place) — plus the lattice's two vertex buffers, V × M `f32` each with V ≤ N
///   vertices (~0.4 N on natural images; the bound is used): 4 volumes (5 with Jacobi);
/// - LCM: the two (three) volumes;
/// - coarse-to-fine (`meanfield.pyramid_levels` = L > 1): each coarse level k < L adds its volume and marginals
///   (and next Q with Jacobi) at 4^−k of the size, at most 2/3 (1) of a volume more;
/// - WTA: one volume, two with the left-right check (both views' cost volumes);
/// - on labels grouped k at a time (an image above `meanfield.reference_px`, run whole: [`Params::for_image`]):
///   the full cost volume beside the above at 1/k of the labels (1 + 4/k volumes for FCM; 1 + 2/k for JEM, whose
///   local term runs alone there with `meanfield.grouped_local`);
/// - plus ~300 bytes per pixel: the images, the lattice's per-pixel tables, the maps of the post-processing; and
///   [`COST_MINIMA_BYTES_PER_PX`], the cost's lowest minima kept for the confidence while the volume is built;
/// - plus the process itself, [`PROCESS_BYTES`].
///
/// With a downscale factor > 1, what is held at the input's own size is added ([`DOWNSCALED_FULL_SIZE_BYTES_PER_PX`]
/// per input pixel): at `--downscale 16` it is most of the run.
pub(crate) fn estimate_memory_bytes(width: usize, height: usize, ndisp: usize, params: &Params) -> u64 {
    estimate_at_factor(width, height, ndisp, params, params.downscale.max(1))
}

/// [`estimate_memory_bytes`] with the downscale factor given explicitly.
fn estimate_at_factor(width: usize, height: usize, ndisp: usize, params: &Params, factor: usize) -> u64 {
    let full_size = if factor > 1 { DOWNSCALED_FULL_SIZE_BYTES_PER_PX * width as u64 * height as u64 } else { 0 };
    reduced_run_bytes(width, height, ndisp, params, factor) + full_size
}

/// The memory of the coarse level of a tiled run (`params.downscale` its factor, > 1): its run at the reduced size
/// and its own full-size copies (the reduced pair's source and the maps it brings back, 32 bytes per input pixel).
/// The pair and the stitched maps are counted beside it (`FULL_SIZE_BYTES_PER_PX` of the tile plan), not here.
pub(crate) fn coarse_level_bytes(width: usize, height: usize, ndisp: usize, params: &Params) -> u64 {
    let factor = params.downscale.max(1);
    reduced_run_bytes(width, height, ndisp, params, factor)
        + COARSE_FULL_SIZE_BYTES_PER_PX * width as u64 * height as u64
}

/// Bytes per pixel of the cost's three lowest minima (value and label, `f32` each) that the confidence reads.
pub(crate) const COST_MINIMA_BYTES_PER_PX: u64 = 24;

/// Bytes per input pixel the coarse level of a tiled run holds at the full size ([`coarse_level_bytes`]).
const COARSE_FULL_SIZE_BYTES_PER_PX: u64 = 32;

/// The run at 1/`factor` of the size (see [`estimate_memory_bytes`]), without what is held at the input's size.
fn reduced_run_bytes(width: usize, height: usize, ndisp: usize, params: &Params, factor: usize) -> u64 {
    let (w, h, m) =
        (scale::reduced_len(width, factor), scale::reduced_len(height, factor), scale::reduced_ndisp(ndisp, factor));
    let n = w as u64 * h as u64;
    let volume = 4 * n * m as u64;
    let next_q = u64::from(params.meanfield.schedule == Schedule::Jacobi);
    // Labels grouped k at a time: the full volume stays beside the inference's (see `crate::pipeline`'s label step).
    let groups = match params.model {
        Model::Wta => 1,
        _ => params.meanfield.for_image(w * h).label_step.max(1) as u64,
    };
    // On grouped labels the `jem` model may run its local term alone: no lattice.
    let local = groups > 1 && params.meanfield.grouped_local;
    let volumes = match params.model {
        Model::Wta if params.post.lrc.mode == LrcMode::Off => 1,
        Model::Wta => 2,
        Model::Lcm => 2 + next_q,
        Model::Jem if local => 2 + next_q,
        Model::Fcm | Model::Jem => 4 + next_q,
    };
    // Coarse-to-fine: each coarse level's volume and marginals (and next Q with Jacobi), at 4^−k of the size.
    let pyramid = match params.model {
        Model::Wta => 0,
        _ => (1..params.meanfield.pyramid_levels as u32).map(|k| (2 + next_q) * volume.div_ceil(4u64.pow(k))).sum(),
    };
    let inference = (volumes * volume + pyramid).div_ceil(groups);
    let full = if groups > 1 { volume } else { 0 };
    full + inference + (300 + COST_MINIMA_BYTES_PER_PX) * n + PROCESS_BYTES
}

/// [`estimate_memory_bytes`] for a tile's crop: a tile searches its label window in bands, on every label.
pub(crate) fn estimate_tile_bytes(width: usize, height: usize, ndisp: usize, params: &Params) -> u64 {
    let mut every_label = params.clone();
    every_label.meanfield.reference_px = 0.0;
    estimate_memory_bytes(width, height, ndisp, &every_label)
}

/// Bytes per input pixel a downscaled run holds at the input's size, at the most: the pair (24), the maps brought
/// back to full size (disparity, confidence, max-marginal, consistent: 13); after the run, beside the pair, the maps
/// kept (9) and the reliable pixels' copy (`--min-confidence`: 4), either the pair's check (its grey views and a
/// blur: 12; `Matcher::check_pair`) or the files `jem match` encodes before writing them all or none (disparity and
/// confidence 8, depth and its file 8, a PLY cloud 15, the left-right mask 2: 33). Counted as the pair and the maps
/// alone, a run at `--downscale 16` peaked at 1.4 times its plan.
pub(crate) const DOWNSCALED_FULL_SIZE_BYTES_PER_PX: u64 = 24 + 9 + 4 + 33;

/// The memory of the process before it holds any image: code, libraries, thread stacks (a 64 × 32 pair peaks at
/// 8.9 MiB with 2 threads), counted with room to spare in [`estimate_memory_bytes`].
pub(crate) const PROCESS_BYTES: u64 = 16 << 20;

/// Fails fast, before anything large is allocated, when a run would need more than `limit_bytes`.
///
/// # Errors
/// [`Error::OutOfMemory`] with the estimate, the limit and what to do about it: the smallest `--downscale`
/// factor (above the current one) whose estimate fits, or, if none does, smaller images or a smaller ndisp; and
/// `--max-memory` for a machine that has the memory.
pub(crate) fn check_memory(width: usize, height: usize, ndisp: usize, params: &Params, limit_bytes: u64) -> Result<()> {
    let needed = estimate_memory_bytes(width, height, ndisp, params);
    if needed <= limit_bytes {
        return Ok(());
    }
    let current = params.downscale.max(1);
    let fitting = (current + 1..)
        .take_while(|&f| scale::factor_fits(width, ndisp, f))
        .map(|f| (f, estimate_at_factor(width, height, ndisp, params, f)))
        .find(|&(_, bytes)| bytes <= limit_bytes);
    let what = format!("{width}x{height} with ndisp {ndisp}");
    let hint = match fitting {
        Some((f, bytes)) => format!(
            "{what} is too large; --downscale {f} (run at 1/{f} resolution) would need about {}; or raise \
             --max-memory if the machine has the memory",
            error::human_bytes(bytes)
        ),
        None => format!(
            "{what} is too large even downscaled; use smaller images or a smaller ndisp, or raise --max-memory if \
             the machine has the memory"
        ),
    };
    Err(Error::OutOfMemory { needed, limit: limit_bytes, hint })
}

/// A default memory limit: 80% of the machine's physical memory (from `/proc/meminfo`), or 8 GiB where that
/// cannot be read; and under an address-space limit (`ulimit -v`), at most 80% of the room this process has left
/// in it, since an allocation beyond it fails (and a failed allocation aborts the process).
pub(crate) fn default_memory_limit() -> u64 {
    let ram = crate::process::physical_memory_bytes().map(|b| b / 1024 * 1024 / 5 * 4).unwrap_or(8 << 30);
    crate::process::address_space_room().map_or(ram, |room| ram.min(room / 5 * 4))
}

/// Memory that concurrent runs share (the scenes of `jem batch`, matchers in threads): a run reserves its estimate
/// before it loads its images and waits while the runs going on hold so much that its share would not fit. A run
/// alone always gets what it asks for (its estimate was checked against the total before).
#[derive(Debug)]
pub struct MemoryBudget {
    total: u64,
    used: Mutex<u64>,
    freed: Condvar,
}

/// Memory held from a [`MemoryBudget`] until dropped.
pub struct Reservation<'a> {
    budget: &'a MemoryBudget,
    bytes: u64,
}

impl MemoryBudget {
    /// A budget of `total` bytes.
    pub fn new(total: u64) -> Self {
        MemoryBudget { total, used: Mutex::new(0), freed: Condvar::new() }
    }

    /// Takes `bytes`, waiting until they fit beside what is held (at once when nothing is).
    pub fn reserve(&self, bytes: u64) -> Reservation<'_> {
        let mut used = self.used.lock().unwrap_or_else(|p| p.into_inner());
        while *used > 0 && used.saturating_add(bytes) > self.total {
            used = self.freed.wait(used).unwrap_or_else(|p| p.into_inner());
        }
        *used = used.saturating_add(bytes);
        Reservation { budget: self, bytes }
    }

    /// The total.
    pub fn total(&self) -> u64 {
        self.total
    }

    /// Bytes held now.
    pub fn in_use(&self) -> u64 {
        *self.used.lock().unwrap_or_else(|p| p.into_inner())
    }
}

impl Drop for Reservation<'_> {
    fn drop(&mut self) {
        let mut used = self.budget.used.lock().unwrap_or_else(|p| p.into_inner());
        *used = used.saturating_sub(self.bytes);
        self.budget.freed.notify_all();
    }
}

#[cfg(test)]
mod tests {
    use std::sync::atomic::{AtomicUsize, Ordering};

    use super::*;

    /// Six concurrent holders of 40 of 100 bytes never hold more than 100 together; a request
    /// larger than the total still runs alone.
    #[test]
    fn memory_budget_bounds_concurrent_scenes() {
        let budget = MemoryBudget::new(100);
        let peak = AtomicUsize::new(0);
        std::thread::scope(|scope| {
            for _ in 0..6 {
                scope.spawn(|| {
                    let _r = budget.reserve(40);
                    peak.fetch_max(budget.in_use() as usize, Ordering::SeqCst);
                    std::thread::sleep(std::time::Duration::from_millis(20));
                });
            }
        });
        assert!(peak.load(Ordering::SeqCst) <= 100 && peak.load(Ordering::SeqCst) >= 40);
        assert_eq!(budget.in_use(), 0);
        let alone = budget.reserve(150);
        assert_eq!(budget.in_use(), 150);
        drop(alone);
    }

    #[test]
    fn memory_estimate_scales_with_pixels_and_labels() {
        let p = Params::default();
        // Vintage at quarter resolution: 720x480 (about), ndisp 190: 4 volumes of 263 MB plus 324 B/px = 1.16 GB.
        let vintage = estimate_memory_bytes(720, 480, 190, &p);
        assert_eq!(vintage, 4 * 4 * 720 * 480 * 190 + 324 * 720 * 480 + PROCESS_BYTES);
        assert!(vintage > 1 << 30 && vintage < 2 << 30, "{vintage}");
        let data = |w, h| estimate_memory_bytes(w, h, 10, &p) - PROCESS_BYTES;
        assert_eq!(data(200, 100) * 4, data(400, 200));
        let volume = 4 * 720 * 480 * 190;
        let wta = Params { model: Model::Wta, ..Params::default() };
        assert_eq!(vintage - estimate_memory_bytes(720, 480, 190, &wta), 2 * volume);
        let mut one = wta.clone();
        one.post.lrc.mode = LrcMode::Off;
        assert_eq!(estimate_memory_bytes(720, 480, 190, &wta) - estimate_memory_bytes(720, 480, 190, &one), volume);
        let lcm = Params { model: Model::Lcm, ..Params::default() };
        assert_eq!(vintage - estimate_memory_bytes(720, 480, 190, &lcm), 2 * volume);
        // The Jacobi schedule keeps a second Q.
        let mut jacobi = Params::default();
        jacobi.meanfield.schedule = Schedule::Jacobi;
        assert_eq!(estimate_memory_bytes(720, 480, 190, &jacobi) - vintage, volume);
        // Two pyramid levels: a coarse volume and its marginals, a quarter of the size each.
        let mut pyramid = lcm.clone();
        pyramid.meanfield.pyramid_levels = 2;
        let extra = estimate_memory_bytes(720, 480, 190, &pyramid) - estimate_memory_bytes(720, 480, 190, &lcm);
        assert_eq!(extra, 2 * volume / 4);
    }

    #[test]
    fn memory_estimate_follows_grouped_labels() {
        let p = Params::default();
        let mut every = p.clone();
        every.meanfield.reference_px = 0.0;
        // Motorcycle H: 1482x994, 140 labels, grouped 2 at a time: the full volume plus 2 volumes of half the
        // labels with the local term alone (measured: 1870 MiB peak against this 2045 MiB), 4 with both terms
        // (2127 MiB against 2831 MiB).
        let (n, volume) = (1482 * 994, 4 * 1482 * 994 * 140);
        let grouped = estimate_memory_bytes(1482, 994, 140, &p);
        assert_eq!(grouped, volume + 2 * volume / 2 + 324 * n + PROCESS_BYTES);
        let mut both_terms = p.clone();
        both_terms.meanfield.grouped_local = false;
        let grouped = estimate_memory_bytes(1482, 994, 140, &both_terms);
        assert_eq!(grouped, volume + 4 * volume / 2 + 324 * n + PROCESS_BYTES);
        assert_eq!(estimate_memory_bytes(1482, 994, 140, &every), 4 * volume + 324 * n + PROCESS_BYTES);
        // A tile searches every label of its window: its crop is counted as such, whatever its size.
        assert_eq!(estimate_tile_bytes(1482, 994, 140, &p), estimate_memory_bytes(1482, 994, 140, &every));
        // WTA and the sizes below the reference are not grouped.
        let wta = Params { model: Model::Wta, ..p.clone() };
        assert_eq!(estimate_memory_bytes(1482, 994, 140, &wta), 2 * volume + 324 * n + PROCESS_BYTES);
        assert_eq!(estimate_memory_bytes(741, 497, 70, &p), estimate_memory_bytes(741, 497, 70, &every));
    }

    #[test]
    fn memory_estimate_uses_the_reduced_size() {
        let p = Params { downscale: 2, ..Params::default() };
        // 722x480 at 1/2: 361x240 with 95 labels, plus what is held at the input's size (70 B per input pixel).
        let n = 361 * 240;
        let at_full_size = DOWNSCALED_FULL_SIZE_BYTES_PER_PX * 722 * 480;
        assert_eq!(estimate_memory_bytes(722, 480, 190, &p), 4 * 4 * n * 95 + 324 * n + at_full_size + PROCESS_BYTES);
        let full = estimate_memory_bytes(722, 480, 190, &Params::default());
        assert!(estimate_memory_bytes(722, 480, 190, &p) * 5 < full, "about 1/6 of the memory");
    }

    #[test]
    fn memory_guard_refuses_before_allocating() {
        let p = Params::default();
        // Full resolution 2880x1988 at ndisp 760 would need ~70 GB: refused at once with the numbers and the
        // smallest downscale that fits (1/2: ~9 GB).
        let e = check_memory(2880, 1988, 760, &p, 24 << 30).unwrap_err();
        let msg = e.to_string();
        assert!(msg.contains("needs about") && msg.contains("GiB") && msg.contains("2880x1988"), "{msg}");
        assert!(msg.contains("--downscale 2 ") && msg.contains("--max-memory"), "{msg}");
        check_memory(450, 375, 64, &p, 24 << 30).unwrap();
        // With 2 GiB the same input needs 1/4 (~1.2 GB); downscale 2 in the config already is taken into account.
        let msg = check_memory(2880, 1988, 760, &p, 2 << 30).unwrap_err().to_string();
        assert!(msg.contains("--downscale 4 "), "{msg}");
        let msg = check_memory(2880, 1988, 760, &Params { downscale: 2, ..p.clone() }, 2 << 30).unwrap_err();
        assert!(msg.to_string().contains("--downscale 4 "), "{msg}");
        check_memory(2880, 1988, 760, &Params { downscale: 4, ..p.clone() }, 2 << 30).unwrap();
        // Nothing fits in 1 MiB: no downscale is suggested.
        let msg = check_memory(2880, 1988, 760, &p, 1 << 20).unwrap_err().to_string();
        assert!(msg.contains("even downscaled") && !msg.contains("--downscale"), "{msg}");
    }
}
