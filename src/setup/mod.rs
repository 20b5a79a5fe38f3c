//! Setting up a run, before anything large is allocated: the search range ([`NdispSource`]: given, stated by
//! the data, or measured on the pair, [`range`]), the memory model ([`memory`]) and whether the run goes in one
//! piece or in tiles ([`strategy`]). The `Matcher` is the one caller: `jem`, `jem batch` and the Python module
//! all match through it, so the same pair and settings give the same disparity map, byte for byte, whichever way
//! it is run.
//!
//! From files the order is: both headers ([`check_before_decode`]: the loading, the range measurement when the
//! range is measured, and the run with the range given, or the smallest a measurement can give, against the
//! limit), the decoding within the limit, then [`plan_match`] on the decoded pair: the range, then the strategy.

pub(crate) mod memory;
pub(crate) mod range;
pub(crate) mod strategy;
pub(crate) mod working;

use std::borrow::Cow;

use crate::error::{Error, Result};
use crate::image::{RgbImage, StereoPair};
use crate::io::png::ImageHeader;
use crate::params::Params;
use strategy::Strategy;

/// Where a pair's disparity range comes from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum NdispSource {
    /// Given by the user (`--ndisp`): used as it is.
    Given(usize),
    /// Stated by the data (`calib.txt`, or a layout's known range such as KITTI's 192): used unless it is no real
    /// bound (`range::needs_search`: half the width or more), in which case the range is measured, up to it.
    Stated(usize),
    /// None: the range is measured, up to the width.
    #[default]
    Unknown,
}

impl NdispSource {
    /// The rule of every front end: a range the user gives wins; else the one the data states; else none.
    pub fn resolve(given: Option<usize>, stated: Option<usize>) -> NdispSource {
        match (given, stated) {
            (Some(n), _) => NdispSource::Given(n),
            (None, Some(n)) => NdispSource::Stated(n),
            (None, None) => NdispSource::Unknown,
        }
    }

    /// The range stated or given, and whether it is measured on a `width`-pixel-wide pair.
    pub(crate) fn rule(self, width: usize) -> (Option<usize>, bool) {
        match self {
            NdispSource::Given(n) => (Some(n), false),
            NdispSource::Stated(n) => (Some(n), range::needs_search(Some(n), width)),
            NdispSource::Unknown => (None, true),
        }
    }

    /// The range stated or given, whether measured or not (`None` for [`NdispSource::Unknown`]).
    pub fn stated(self) -> Option<usize> {
        match self {
            NdispSource::Given(n) | NdispSource::Stated(n) => Some(n),
            NdispSource::Unknown => None,
        }
    }
}

/// The memory of a decoded `width × height` pair: two [`RgbImage`]s, 12 bytes a pixel each.
pub(crate) fn pair_bytes(width: usize, height: usize) -> u64 {
    24 * width as u64 * height as u64
}

/// Checks a pair against `limit_bytes` from its headers ([`crate::io::png::read_pair_header`]), before either image
/// is decoded: the loading itself, the range measurement when the range is measured (beside the decoded pair:
/// [`range::find_ndisp`] then runs within the rest), and the run with the range given, or with the smallest
/// range a measurement can give. [`plan_match`] checks the rest once the range is known. Returns the memory to
/// hold until the range is known: the loading, or the decoded pair and the measurement, whichever is larger.
///
/// # Errors
/// [`Error::OutOfMemory`] when one of them does not fit, [`Error::InvalidParam`] for an impossible range.
pub(crate) fn check_before_decode(
    header: &ImageHeader,
    source: NdispSource,
    params: &Params,
    limit_bytes: u64,
) -> Result<u64> {
    let (w, h) = (header.width, header.height);
    let (stated, search) = source.rule(w);
    let mut need = header.load_bytes;
    match stated {
        Some(n) if !search => {
            let strategy = Strategy::choose(w, h, n, params, limit_bytes)?;
            need = need.max(strategy.memory_bytes(w, h, n, params));
        }
        _ => {
            let max = range::search_limit(stated, w);
            Strategy::choose(w, h, range::min_ndisp(max), params, limit_bytes)?;
            let within = measure_budget(w, h, limit_bytes);
            let factor = range::measure_factor(w, h, max, within).ok_or_else(|| range::too_large(w, h, max, within))?;
            need = need.max(pair_bytes(w, h) + range::measure_bytes(w, h, max, factor));
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
    Ok(need)
}

/// A pair ready to run, and how.
#[derive(Clone, Debug)]
pub(crate) struct Plan<'a> {
    /// The pair with its search range.
    pub pair: StereoPair<'a>,
    /// In one piece or in tiles.
    pub strategy: Strategy,
    /// Whether the range was measured on the pair (rather than given or stated).
    pub ndisp_measured: bool,
    /// The working resolution's reduction ([`working::working_factor`]; 1 = the input's own resolution).
    pub working_factor: usize,
}

impl Plan<'_> {
    /// The parameters the pair runs with: `params`, at the working resolution when it is below the input's.
    pub(crate) fn params<'p>(&self, params: &'p Params) -> Cow<'p, Params> {
        match self.working_factor {
            1 => Cow::Borrowed(params),
            f => Cow::Owned(Params { downscale: f, ..params.clone() }),
        }
    }
}

/// Settles the range of `left`/`right` (see [`NdispSource`]) and how to run the pair within `limit_bytes`.
///
/// # Errors
/// [`Error::SizeMismatch`] or [`Error::InputImage`] for unequal or empty images, or images narrower than 2 pixels
/// (checked before the range is measured), [`Error::InvalidParam`] for an impossible range, [`Error::OutOfMemory`]
/// when the run fits `limit_bytes` neither in one piece nor in tiles, or the range measurement does not fit beside
/// the pair.
pub(crate) fn plan_match<'a>(
    left: &'a RgbImage,
    right: &'a RgbImage,
    source: NdispSource,
    params: &Params,
    limit_bytes: u64,
) -> Result<Plan<'a>> {
    if left.dims() != right.dims() {
        return Err(Error::SizeMismatch { left: left.dims(), right: right.dims() });
    }
    if left.is_empty() {
        return Err(Error::bad_image("the images are empty (0 pixels)"));
    }
    if left.width < 2 {
        let (w, h) = left.dims();
        return Err(Error::bad_image(format!("the images are {w}x{h}; a stereo pair must be at least 2 pixels wide")));
    }
    let (ndisp, ndisp_measured) = search_range(left, right, source, params, limit_bytes)?;
    let pair = StereoPair::borrowed(left, right, ndisp)?;
    let working_factor = working::working_factor(left, ndisp, params);
    let run = Params { downscale: params.downscale * working_factor, ..params.clone() };
    let strategy = Strategy::choose(pair.left.width, pair.left.height, pair.ndisp, &run, limit_bytes)?;
    Ok(Plan { pair, strategy, ndisp_measured, working_factor })
}

/// The search range of a decoded pair: `source`'s when it is a real bound ([`NdispSource::rule`]), else measured
/// on the pair ([`range::find_ndisp`]) within `limit_bytes` less the decoded pair's own bytes ([`measure_budget`]).
/// Returns it and whether it was measured.
///
/// # Errors
/// As [`range::find_ndisp`].
fn search_range(
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
            let max = range::search_limit(stated, w);
            let ndisp = range::find_ndisp(left, right, max, &params.cost, measure_budget(w, h, limit_bytes))?;
            Ok((ndisp, true))
        }
    }
}

/// What the range measurement of a `width` × `height` pair may use of `limit_bytes`: the rest beside the decoded
/// pair ([`pair_bytes`]).
fn measure_budget(width: usize, height: usize, limit_bytes: u64) -> u64 {
    limit_bytes.saturating_sub(pair_bytes(width, height))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Plans a black 40 × 20 left view against a black right view `right_width` wide.
    fn plan(right_width: usize, source: NdispSource) -> Result<(usize, bool)> {
        let (left, right) = (RgbImage::new(40, 20), RgbImage::new(right_width, 20));
        plan_match(&left, &right, source, &Params::default(), u64::MAX).map(|p| (p.pair.ndisp, p.ndisp_measured))
    }

    #[test]
    fn unequal_sizes_fail_before_the_range_is_measured() {
        let err = plan(41, NdispSource::Unknown).unwrap_err();
        assert!(matches!(err, Error::SizeMismatch { left: (40, 20), right: (41, 20) }), "{err}");
    }

    #[test]
    fn a_given_range_is_used_even_when_wide() {
        assert_eq!(plan(40, NdispSource::Given(30)).unwrap(), (30, false));
    }

    #[test]
    fn a_stated_range_is_used_unless_it_is_no_bound() {
        assert_eq!(plan(40, NdispSource::Stated(12)).unwrap(), (12, false));
        let (ndisp, measured) = plan(40, NdispSource::Stated(30)).unwrap();
        assert!(measured && ndisp <= 30, "{ndisp}");
    }

    #[test]
    fn a_given_range_wins_over_a_stated_one() {
        assert_eq!(NdispSource::resolve(Some(8), Some(64)), NdispSource::Given(8));
        assert_eq!(NdispSource::resolve(None, Some(64)), NdispSource::Stated(64));
        assert_eq!(NdispSource::resolve(None, None), NdispSource::Unknown);
    }
}
