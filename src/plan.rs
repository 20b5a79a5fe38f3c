//! How `jem match` sets up a run once the images are decoded: the search range (given, stated by the data, or
//! measured on the pair: [`crate::range`]), then in one piece or in tiles under a memory limit
//! ([`crate::tile::Strategy`]). The command line and the Python module (`python/`) both call [`plan_match`], so
//! the same pair and settings give the same disparity map, byte for byte, whichever way it is run.

use crate::error::{Error, Result};
use crate::image::{RgbImage, StereoPair};
use crate::params::Params;
use crate::tile::Strategy;

/// Where a pair's disparity range comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NdispSource {
    /// Given by the user (`--ndisp`): used as it is.
    Given(usize),
    /// Stated by the data (`calib.txt`): used unless it is no real bound ([`crate::range::needs_search`]), in which
    /// case the range is measured, up to it.
    Stated(usize),
    /// None: the range is measured, up to the width ([`crate::range::search_limit`], as `jem batch` does).
    Unknown,
}

impl NdispSource {
    /// The range stated or given, and whether it is measured on a `width`-pixel-wide pair.
    pub fn rule(self, width: usize) -> (Option<usize>, bool) {
        match self {
            NdispSource::Given(n) => (Some(n), false),
            NdispSource::Stated(n) => (Some(n), crate::range::needs_search(Some(n), width)),
            NdispSource::Unknown => (None, true),
        }
    }
}

/// The memory of a decoded `width × height` pair: two [`RgbImage`]s, 12 bytes a pixel each.
pub fn pair_bytes(width: usize, height: usize) -> u64 {
    24 * width as u64 * height as u64
}

/// Checks a pair against `limit_bytes` from its headers ([`crate::io::png::read_pair_header`]), before either image
/// is decoded: the loading itself, the range measurement when the range is measured (beside the decoded pair:
/// [`crate::range::find_ndisp`] then runs within the rest), and the run with the range given, or with the smallest
/// range a measurement can give. [`plan_match`] checks the rest once the range is known.
///
/// # Errors
/// [`Error::OutOfMemory`] when one of them does not fit, [`Error::InvalidParam`] for an impossible range.
pub fn check_before_decode(
    header: &crate::io::png::ImageHeader,
    source: NdispSource,
    params: &Params,
    limit_bytes: u64,
) -> Result<()> {
    let (w, h) = (header.width, header.height);
    let (stated, search) = source.rule(w);
    match stated {
        Some(n) if !search => {
            Strategy::choose(w, h, n, params, limit_bytes)?;
        }
        _ => {
            let max = crate::range::search_limit(stated, w);
            Strategy::choose(w, h, crate::range::min_ndisp(max), params, limit_bytes)?;
            let within = measure_budget(w, h, limit_bytes);
            if crate::range::measure_factor(w, h, max, within).is_none() {
                return Err(crate::range::too_large(w, h, max, within));
            }
        }
    }
    if header.load_bytes > limit_bytes {
        return Err(Error::OutOfMemory {
            needed: header.load_bytes,
            limit: limit_bytes,
            hint: format!(
                "loading the {w}x{h} pair does not fit; use smaller images, or raise --max-memory if the machine \
                 has the memory"
            ),
        });
    }
    Ok(())
}

/// A pair ready to run, and how.
#[derive(Clone, Debug)]
pub struct Plan {
    /// The pair with its search range.
    pub pair: StereoPair,
    /// In one piece or in tiles.
    pub strategy: Strategy,
    /// Whether the range was measured on the pair (rather than given or stated).
    pub ndisp_measured: bool,
}

/// Settles the range of `left`/`right` (see [`NdispSource`]) and how to run the pair within `limit_bytes`.
/// Run it with `plan.strategy.run(params, &plan.pair, on_stage)`.
///
/// # Errors
/// [`Error::SizeMismatch`] or [`Error::Input`] for unequal or empty images, or images narrower than 2 pixels
/// (checked before the range is measured), [`Error::InvalidParam`] for an impossible range, [`Error::OutOfMemory`] when the run fits
/// `limit_bytes` neither in one piece nor in tiles, or the range measurement does not fit beside the pair.
pub fn plan_match(
    left: RgbImage,
    right: RgbImage,
    source: NdispSource,
    params: &Params,
    limit_bytes: u64,
) -> Result<Plan> {
    if left.dims() != right.dims() {
        return Err(Error::SizeMismatch { left: left.dims(), right: right.dims() });
    }
    if left.is_empty() {
        return Err(Error::Input("the images are empty (0 pixels)".into()));
    }
    if left.width < 2 {
        let (w, h) = left.dims();
        return Err(Error::Input(format!("the images are {w}x{h}; a stereo pair must be at least 2 pixels wide")));
    }
    let (ndisp, ndisp_measured) = search_range(&left, &right, source, params, limit_bytes)?;
    let pair = StereoPair::new(left, right, ndisp)?;
    let strategy = Strategy::choose(pair.left.width, pair.left.height, pair.ndisp, params, limit_bytes)?;
    Ok(Plan { pair, strategy, ndisp_measured })
}

/// The search range of a decoded pair: `source`'s when it is a real bound ([`NdispSource::rule`]), else measured
/// on the pair ([`crate::range::find_ndisp`]) within `limit_bytes` less the decoded pair's own bytes
/// ([`measure_budget`]). Returns it and whether it was measured. `jem`, the Python module and `jem batch` all take
/// their range from here.
///
/// # Errors
/// As [`crate::range::find_ndisp`].
pub fn search_range(
    left: &RgbImage,
    right: &RgbImage,
    source: NdispSource,
    params: &Params,
    limit_bytes: u64,
) -> Result<(usize, bool)> {
    let (w, h) = left.dims();
    match source.rule(w) {
        (Some(n), false) => Ok((n, false)),
        (stated, _) => {
            let max = crate::range::search_limit(stated, w);
            let ndisp = crate::range::find_ndisp(left, right, max, &params.cost, measure_budget(w, h, limit_bytes))?;
            Ok((ndisp, true))
        }
    }
}

/// What the range measurement of a `width` × `height` pair may use of `limit_bytes`: the rest beside the decoded
/// pair ([`pair_bytes`]).
pub fn measure_budget(width: usize, height: usize, limit_bytes: u64) -> u64 {
    limit_bytes.saturating_sub(pair_bytes(width, height))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Plans a black 40 × 20 left view against a black right view `right_width` wide.
    fn plan(right_width: usize, source: NdispSource) -> Result<Plan> {
        plan_match(RgbImage::new(40, 20), RgbImage::new(right_width, 20), source, &Params::default(), u64::MAX)
    }

    #[test]
    fn unequal_sizes_fail_before_the_range_is_measured() {
        let err = plan(41, NdispSource::Unknown).unwrap_err();
        assert!(matches!(err, Error::SizeMismatch { left: (40, 20), right: (41, 20) }), "{err}");
    }

    #[test]
    fn a_given_range_is_used_even_when_wide() {
        let plan = plan(40, NdispSource::Given(30)).unwrap();
        assert_eq!((plan.pair.ndisp, plan.ndisp_measured), (30, false));
    }

    #[test]
    fn a_stated_range_is_used_unless_it_is_no_bound() {
        let narrow = plan(40, NdispSource::Stated(12)).unwrap();
        assert_eq!((narrow.pair.ndisp, narrow.ndisp_measured), (12, false));
        let wide = plan(40, NdispSource::Stated(30)).unwrap();
        assert!(wide.ndisp_measured && wide.pair.ndisp <= 30, "{}", wide.pair.ndisp);
    }
}
