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
/// [`Error::SizeMismatch`] or [`Error::Input`] for unequal or empty images (checked before the range is
/// measured), [`Error::InvalidParam`] for an impossible range, [`Error::OutOfMemory`] when the run fits
/// `limit_bytes` neither in one piece nor in tiles.
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
    let w = left.width;
    let stated = match source {
        NdispSource::Given(n) => Some(n),
        NdispSource::Stated(n) => Some(n),
        NdispSource::Unknown => None,
    };
    let search = !matches!(source, NdispSource::Given(_)) && crate::range::needs_search(stated, w);
    let ndisp = match stated {
        Some(n) if !search => n,
        _ => crate::range::find_ndisp(&left, &right, crate::range::search_limit(stated, w), &params.cost),
    };
    let pair = StereoPair::new(left, right, ndisp)?;
    let strategy = Strategy::choose(pair.left.width, pair.left.height, pair.ndisp, params, limit_bytes)?;
    Ok(Plan { pair, strategy, ndisp_measured: search })
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
