//! The disparity range of a pair when none is given, or when the given one is not a real bound.
//!
//! Some data sets state no range, and some state one that is not a bound at all: ETH3D's calib.txt says
//! ndisp = the image width, where the real disparities stay below a few dozen. Inference costs time and memory
//! in proportion to the number of labels, so a range that is 20 times too wide makes a run 20 times slower for
//! nothing. [`find_ndisp`] measures the range instead: the matching cost at 1/4 resolution over the whole
//! candidate range, winner-take-all in both views, the matches that are left-right consistent, distinct and
//! spatially coherent (at least [`MIN_COHERENT_NEIGHBOURS`] of the 8 neighbours' winners within one label), and
//! the largest disparity a dense group of them holds, plus a margin. The policy ([`needs_search`]): search when
//! no range is given, or when the given one is at least half the image width; up to [`search_limit`], the one
//! rule of `jem` and `jem batch`.

use crate::cost;
use crate::error::{Error, Result};
use crate::image::RgbImage;
use crate::params::CostParams;
use crate::scale::downsample_rgb;

/// A match counts when its cost is below this fraction of the best cost more than one label away.
const DISTINCT_RATIO: f32 = 0.8;

/// A match counts only when at least this many of its 8 neighbours' winner-take-all labels are within one label of
/// it. A surface is connected and its disparity varies smoothly; the chance matches of blank, repetitive or
/// unmatched areas scatter, and where real matches are few they would otherwise stretch the range (MiddEval3 ArtL
/// with ndisp = width: 244 instead of 80; RESULTS.md, "A stated range that is no bound").
pub(crate) const MIN_COHERENT_NEIGHBOURS: usize = 2;

/// A stated range at least this fraction of the width is treated as "not a real bound".
pub(crate) const SUSPECT_FRACTION: f64 = 0.5;

/// Whether the range of a `width`-pixel-wide pair should be measured: none given, or `stated` ≥ half the width.
pub(crate) fn needs_search(stated: Option<usize>, width: usize) -> bool {
    stated.is_none_or(|n| n as f64 >= SUSPECT_FRACTION * width as f64)
}

/// The largest range [`find_ndisp`] considers for a `width`-pixel-wide pair whose stated range is `stated`: the
/// stated range, or the whole width when none is stated (no range is no bound, as ETH3D's ndisp = width is not:
/// docs/cli.md, "The search range"), never more than the largest range a pair of that width takes (width − 1: a
/// disparity of width − 2 at most, as [`crate::image::StereoPair::new`] requires), nor below 1. `jem` and
/// `jem batch` both ask this.
pub(crate) fn search_limit(stated: Option<usize>, width: usize) -> usize {
    stated.unwrap_or(width).min(width.saturating_sub(1)).max(1)
}

/// The smallest range [`find_ndisp`] returns for a search up to `max_ndisp`.
pub(crate) fn min_ndisp(max_ndisp: usize) -> usize {
    16.min(max_ndisp)
}

/// The memory [`find_ndisp`] allocates for a `width × height` pair searched up to `max_ndisp` at 1/`factor`
/// resolution: the two reduced images (12 bytes a pixel each), the cost volume and the right view's volume derived
/// from it (both alive at once, 4 bytes a label), and the two winner-take-all maps and the list of consistent
/// matches (4 bytes a pixel each).
pub(crate) fn measure_bytes(width: usize, height: usize, max_ndisp: usize, factor: usize) -> u64 {
    let n = crate::scale::reduced_len(width, factor) as u64 * crate::scale::reduced_len(height, factor) as u64;
    let labels = max_ndisp.div_ceil(factor).clamp(2, crate::scale::reduced_len(width, factor).max(2)) as u64;
    24 * n + 8 * n * labels + 12 * n
}

/// The resolution factor [`find_ndisp`] measures at within `limit_bytes`: 1/4 (but at least 32 × 16 pixels left to
/// match), or, when that does not fit, the smallest coarser factor that does and leaves at least 8 × 4 pixels;
/// `None` when none does.
pub(crate) fn measure_factor(width: usize, height: usize, max_ndisp: usize, limit_bytes: u64) -> Option<usize> {
    let first = first_factor(width, height);
    std::iter::once(first)
        .chain((first + 1..).take_while(|f| width / f >= 8 && height / f >= 4))
        .find(|&f| measure_bytes(width, height, max_ndisp, f) <= limit_bytes)
}

/// 1/4 resolution, but at least 32 × 16 pixels left to match.
fn first_factor(width: usize, height: usize) -> usize {
    (1..=4).rev().find(|f| width / f >= 32 && height / f >= 16).unwrap_or(1)
}

/// The search range 0..N−1 for the pair, at most `max_ndisp` (and at least 16): see the module doc. Falls back
/// to `max_ndisp` when fewer than 1 % of the pixels are consistent (no reliable measurement). What it allocates
/// stays within `limit_bytes` ([`measure_bytes`]): a pair too large to measure at 1/4 resolution within it is
/// measured coarser ([`measure_factor`]).
///
/// # Errors
/// [`Error::OutOfMemory`] when the measurement fits `limit_bytes` at no resolution.
pub(crate) fn find_ndisp(
    left: &RgbImage,
    right: &RgbImage,
    max_ndisp: usize,
    p: &CostParams,
    limit_bytes: u64,
) -> Result<usize> {
    let (w, h) = left.dims();
    let factor = measure_factor(w, h, max_ndisp, limit_bytes).ok_or_else(|| too_large(w, h, max_ndisp, limit_bytes))?;
    let (l, r) = (downsample_rgb(left, factor), downsample_rgb(right, factor));
    let labels = max_ndisp.div_ceil(factor).clamp(2, l.width.max(2));
    let consistent = reliable_matches(&l, &r, labels, p);
    let dl_len = l.len();
    if consistent.len() * 100 < dl_len {
        return Ok(max_ndisp);
    }
    // The largest disparity still held by a real surface: chance matches that pass both tests scatter thinly
    // over the whole range (a few pixels per label), a surface fills neighbouring labels densely. `top` is the
    // largest label whose three-label neighbourhood holds at least 0.5 % of the consistent pixels (and 8): a
    // surface smaller than that at the far end of the range is lost (the price of not trusting the range).
    let mut hist = vec![0usize; labels + 2];
    for &d in &consistent {
        hist[(d.round() as usize).min(labels - 1) + 1] += 1;
    }
    let need = (consistent.len() / 200).max(8);
    let top = (0..labels).rev().find(|&d| hist[d] + hist[d + 1] + hist[d + 2] >= need).unwrap_or(labels - 1) as f32;
    // Two coarse labels and 8 px of margin, in full-resolution pixels.
    let n = ((f64::from(top) + 2.0) * factor as f64).ceil() as usize + 8;
    Ok(n.clamp(min_ndisp(max_ndisp), max_ndisp))
}

/// The disparities (in `left`'s pixels, 0..`labels`) of the matches of a pair that are left-right consistent,
/// distinct and spatially coherent (see the module doc): the ones a measurement can rest on.
pub(crate) fn reliable_matches(left: &RgbImage, right: &RgbImage, labels: usize, p: &CostParams) -> Vec<f32> {
    let vol = cost::build_cost_volume(left, right, labels, p);
    let dl = cost::winner_take_all(&vol);
    let dr = cost::winner_take_all(&cost::derive_right_volume(&vol, cost::truncation_cost(p)));
    // Distinct: the best cost clearly below the best one away from it (a flat or repetitive region matches
    // anywhere, and such chance matches would stretch the range).
    let distinct = |i: usize, d: usize| {
        let c = vol.pixel(i);
        let second = c.iter().enumerate().filter(|(k, _)| k.abs_diff(d) > 1).map(|(_, v)| *v).fold(f32::MAX, f32::min);
        c[d] < DISTINCT_RATIO * second
    };
    let (lw, lh) = left.dims();
    let coherent = |x: usize, y: usize, d: f32| {
        let rows = y.saturating_sub(1)..=(y + 1).min(lh - 1);
        let cols = x.saturating_sub(1)..=(x + 1).min(lw - 1);
        let agree = rows
            .flat_map(|yy| cols.clone().map(move |xx| (xx, yy)))
            .filter(|&(xx, yy)| (xx, yy) != (x, y) && (dl.data[yy * lw + xx] - d).abs() <= 1.0)
            .count();
        agree >= MIN_COHERENT_NEIGHBOURS
    };
    dl.data
        .iter()
        .enumerate()
        .filter_map(|(i, &d)| {
            let (x, y) = (i % lw, i / lw);
            let xr = x.checked_sub(d.round() as usize)?;
            let ok = (dr.data[y * lw + xr] - d).abs() <= 1.0 && distinct(i, d.round() as usize) && coherent(x, y, d);
            ok.then_some(d)
        })
        .collect()
}

/// The error of a range measurement that fits `limit_bytes` at no resolution.
pub(crate) fn too_large(width: usize, height: usize, max_ndisp: usize, limit_bytes: u64) -> Error {
    Error::OutOfMemory {
        needed: measure_bytes(width, height, max_ndisp, first_factor(width, height)),
        limit: limit_bytes,
        hint: format!(
            "measuring the search range of {width}x{height} (up to {max_ndisp}) does not fit; give it with --ndisp N, \
             or raise --max-memory if the machine has the memory"
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One rule for every caller: no range searches the whole width, a stated one up to itself, never past the
    /// width, whichever front end asks.
    #[test]
    fn search_limit_is_the_stated_range_or_the_width() {
        assert_eq!(search_limit(None, 640), 639);
        assert_eq!(search_limit(Some(640), 640), 639);
        assert_eq!(search_limit(Some(900), 640), 639);
        assert_eq!(search_limit(Some(320), 640), 320);
        assert_eq!(search_limit(None, 3), 2);
        assert_eq!(search_limit(None, 2), 1);
    }

    /// The limit is a range the pair takes, so a measurement that falls back to it (too few
    /// consistent matches) or reaches it runs: a 3 × 2 pair with no range gave "invalid ndisp = 3".
    #[test]
    fn the_search_limit_is_a_valid_range() {
        for w in [2, 3, 5, 40] {
            let img = RgbImage::new(w, 2);
            let n = find_ndisp(&img, &img, search_limit(None, w), &CostParams::default(), u64::MAX).unwrap();
            assert!(crate::image::StereoPair::new(img.clone(), img, n).is_ok(), "width {w}: ndisp {n}");
        }
    }
    use crate::synth::{SynthParams, render_scene};

    #[test]
    fn policy() {
        assert!(needs_search(None, 100));
        assert!(needs_search(Some(50), 100));
        assert!(!needs_search(Some(49), 100));
    }

    /// The measurement stays within the memory limit. A limit just below what 1/4 resolution
    /// needs measures coarser (and still covers the scene); a limit nothing fits is refused before allocating.
    #[test]
    fn the_measurement_stays_within_the_limit() {
        let s = render_scene(&SynthParams { width: 320, height: 240, ndisp: 64, seed: 1 }).unwrap();
        let at_4 = measure_bytes(320, 240, 320, 4);
        assert_eq!(measure_factor(320, 240, 320, at_4), Some(4));
        let coarser = measure_factor(320, 240, 320, at_4 - 1).unwrap();
        assert!(coarser > 4 && measure_bytes(320, 240, 320, coarser) < at_4, "{coarser}");
        let n = find_ndisp(&s.left, &s.right, 320, &CostParams::default(), at_4 - 1).unwrap();
        let true_max = s.gt.data.iter().copied().fold(0.0f32, f32::max);
        assert!(n as f32 > true_max + 1.0 && n <= 320, "found {n}, true max {true_max}");
        let err = find_ndisp(&s.left, &s.right, 320, &CostParams::default(), 1000).unwrap_err();
        assert!(matches!(err, Error::OutOfMemory { limit: 1000, .. }), "{err}");
    }

    /// A rendered scene with a range stated as the whole width: the measured range covers every true disparity
    /// and is far smaller than the stated one.
    #[test]
    fn finds_a_range_that_covers_the_scene() {
        for seed in [1, 2, 3] {
            let s = render_scene(&SynthParams { width: 320, height: 240, ndisp: 64, seed }).unwrap();
            let n = find_ndisp(&s.left, &s.right, 320, &CostParams::default(), u64::MAX).unwrap();
            let true_max = s.gt.data.iter().copied().fold(0.0f32, f32::max);
            assert!(n as f32 > true_max + 1.0 && n <= 100, "seed {seed}: found {n}, true max {true_max}");
        }
    }

    /// A third of the scene shows unrelated random texture in the two views (a screen, an occluded area): its
    /// winner-take-all matches are chance, and some pass the consistency and distinctness tests at any label.
    /// They scatter, so the coherence test drops them and the range stays near the scene's.
    #[test]
    fn chance_matches_do_not_stretch_the_range() {
        let (w, h) = (320, 240);
        let mut rng = crate::rng::SplitMix64::new(7);
        for seed in [4, 5] {
            let mut s = render_scene(&SynthParams { width: w, height: h, ndisp: 40, seed }).unwrap();
            for img in [&mut s.left, &mut s.right] {
                for i in (0..w * h).filter(|i| i % w >= 2 * w / 3) {
                    let v = 255.0 * rng.next_f64() as f32;
                    img.channels.iter_mut().for_each(|c| c[i] = v);
                }
            }
            let n = find_ndisp(&s.left, &s.right, w, &CostParams::default(), u64::MAX).unwrap();
            let true_max = s.gt.data.iter().copied().fold(0.0f32, f32::max);
            assert!(n as f32 > true_max + 1.0 && n <= 72, "seed {seed}: found {n}, true max {true_max}");
        }
    }
}
