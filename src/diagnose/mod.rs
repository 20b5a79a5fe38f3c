//! Checks of a pair that no disparity map could make right: views given the wrong way round, rows further apart
//! than the alignment corrects, a range of more than half the width, almost no texture, one view far darker,
//! brighter or blurrier than the front end allows for. Each is a number ([`PairCheck`]) and, past its bound, a
//! one-line warning ([`PairCheck::warnings`]); the map is still made.
//!
//! - **Swapped views**: the reliable matches (left-right consistent, distinct, coherent: the range measurement's,
//!   `crate::setup::range`) at 1/4 resolution, searched at positive disparities on the pair and on the pair
//!   mirrored left to right (whose positive disparities are the pair's negative ones). Clearly most of them at
//!   negative disparity ([`SWAPPED_SHARE`]): the views look swapped.
//! - **Vertical offset**: the views' row profiles (each row's mean grey level, less its local mean over
//!   [`PROFILE_DETREND`] rows) are correlated over vertical shifts; a horizontal disparity moves content along a
//!   row and leaves the profile nearly as it is, a vertical offset shifts it. Beyond what the alignment
//!   corrects ([`VerticalParams::MAX_OFFSET_PX`]) and clearly better correlated than no shift, it is a warning;
//!   rows that repeat down the image (a rival correlation peak) leave it unmeasured.
//! - **Texture**: the share of pixels whose gradient stands above the noise.
//! - **Exposure**: the share of pixels clipped to black or white in one view and not the other (detail lost
//!   there cannot be matched; a gain or an offset the front end stretches away).
//! - **Focus**: the views' sharpness ratio beyond the largest blur the front end gives the sharper view.
//! - **The same image twice**: nearly every pixel equal in both views (the same file given twice, say): a
//!   disparity of 0 everywhere, "100 % valid", says nothing about the scene.
//! - **Repetitive texture matched a period off** (with the answer's confidence): [`repetitive`].

mod answer;
mod repetitive;

pub use repetitive::Repetition;

use crate::condition::MAX_MATCHING_BLUR;
use crate::image::{Plane, RgbImage};
use crate::imgproc::filter::{central_differences, gaussian_blur_plane};
use crate::params::{CostParams, VerticalParams};
use crate::scale::downsample_rgb;

/// Rows over which the row profile's slow trend (lighting, vignetting) is taken out.
const PROFILE_DETREND: usize = 15;

/// A vertical offset is reported only when its profile correlation beats no shift's by at least this much: on a
/// pair without horizontal structure both are noise.
const PROFILE_MARGIN: f64 = 0.2;

/// Another correlation peak within this of the best one makes a vertical offset ambiguous ([`has_rival_peak`]).
/// Half of [`PROFILE_MARGIN`]: a repetitive pattern's rival peaks come within a few hundredths of the best.
const RIVAL_PEAK_MARGIN: f64 = 0.1;

/// More of the reliable matches than this share at negative disparity: the views look swapped. Swapped trainingQ
/// pairs put 70–87 % there; a share near one half says the matches go both ways, as on a texture that repeats
/// along the row (a chessboard over the whole frame: 52 %), and tells nothing of the order.
const SWAPPED_SHARE: f32 = 0.6;

/// A pixel is textured when its gradient magnitude exceeds this many times the noise σ (and 2 grey levels).
const TEXTURE_SIGMAS: f32 = 3.0;

/// The reduction the texture is measured at (as the range measurement and the swap check see the pair).
const TEXTURE_FACTOR: usize = 4;

/// Fewer textured pixels than this share: almost no texture (matching then rests on propagation alone).
const MIN_TEXTURED_SHARE: f32 = 0.05;

/// A difference in the clipped share of the views beyond this (a fraction of the pixels) is reported.
const MAX_CLIPPED_DIFFERENCE: f32 = 0.10;

/// More pixels than this share equal in both views (within half a grey level): the same image twice. Two cameras
/// never see that (their noise alone differs), even of a scene all at infinity.
const MAX_IDENTICAL_SHARE: f32 = 0.99;

/// What was checked on a pair (see the module doc); `None` where it could not be measured.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PairCheck {
    /// The share of the reliable matches at negative disparity (0..1; over 0.6: swapped, see the module doc).
    pub negative_share: Option<f32>,
    /// The right view's vertical offset measured from the row profiles (px; + = the right view's content lower).
    pub vertical_px: Option<f32>,
    /// The largest offset the alignment corrects (px).
    pub vertical_limit_px: f32,
    /// The measured range as a share of the width, when it was measured.
    pub range_share: Option<f32>,
    /// The share of the left view's pixels with texture above the noise.
    pub textured_share: f32,
    /// The share of each view's pixels clipped to black or white.
    pub clipped: [f32; 2],
    /// The sharper view's sharpness over the blurrier one's, and whether the largest blur the front end applies
    /// still leaves the sharper one sharper than the other by more than the front end tolerates.
    pub sharpness_ratio: f32,
    /// Whether the focus difference is beyond what the front end matches.
    pub focus_beyond: bool,
    /// The share of pixels whose colour is the same in both views, within half a grey level.
    pub identical_share: f32,
    /// A given range (not measured): its smallest disparity and its number of disparities.
    pub given_range: Option<[usize; 2]>,
    /// With a given range: the share of the valid answers within 4 px of its top (the answer checks).
    pub top_share: Option<f32>,
    /// The range measured on the pair (0..N−1) when the answers pile up at the top of a given range.
    pub measured_ndisp: Option<usize>,
    /// The right view's vertical offset in the image's left and right third, then in its top and bottom third
    /// (px; `None` where not measured), and how far apart the thirds' centres are across and down (px).
    pub offsets_by_third: [Option<f32>; 4],
    /// How far apart the centres of the left and right thirds, and of the top and bottom ones, are (px).
    pub thirds_apart_px: [f32; 2],
    /// The largest region of texture that repeats itself within the search range and whose answer is doubtful or a
    /// period off a neighbouring part's (the answer checks, with a confidence map).
    pub repetition: Option<Repetition>,
}

impl PairCheck {
    /// A warning about a pair that is not rectified, for a pair already rectified with `calib` (`jem match
    /// --rectify`, Python `rectify=`): the advice to rectify it would be given to one who did; the calibration, or the
    /// order of the views, is in doubt. Other warnings are returned as they are.
    pub fn after_rectify(warning: String, calib: &std::path::Path) -> String {
        let advice = format!(
            "after --rectify {}: is it this rig's calibration, and LEFT the left camera's view?",
            calib.display()
        );
        warning
            .replace(
                "the pair is not rectified (rectify it with --rectify CALIB)",
                &format!("the pair is not rectified {advice}"),
            )
            .replace("(the pair is not rectified)", &format!("(the pair is not rectified {advice})"))
    }

    /// One line per problem found (no line for a pair that looks right).
    pub fn warnings(&self) -> Vec<String> {
        let mut out = Vec::new();
        if self.identical_share > MAX_IDENTICAL_SHARE {
            out.push(format!(
                "the two views are the same image ({:.1} % of the pixels equal): there is nothing to match; give the \
                 left and the right camera's views",
                100.0 * self.identical_share
            ));
        }
        if let Some(share) = self.negative_share
            && share > SWAPPED_SHARE
        {
            out.push(format!(
                "the views look swapped: {:.0} % of the reliable matches are at negative disparity (give the left \
                 view first)",
                100.0 * share
            ));
        }
        if let Some(v) = self.vertical_px
            && v.abs() > self.vertical_limit_px
        {
            out.push(format!(
                "the right view is {:.1} px {} than the left, more than the {} px the alignment corrects: the pair is \
                 not rectified (rectify it with --rectify CALIB)",
                v.abs(),
                if v > 0.0 { "lower" } else { "higher" },
                self.vertical_limit_px
            ));
        }
        if let Some(r) = self.range_share
            && r > 0.5
        {
            out.push(format!(
                "the measured disparity range is {:.0} % of the width: objects that close, or views that do not \
                 overlap (a pair this wide apart is rarely matched right)",
                100.0 * r
            ));
        }
        out.extend(self.range_warning());
        out.extend(self.rotation_warnings());
        out.extend(self.repetition_warning());
        if self.textured_share < MIN_TEXTURED_SHARE {
            out.push(format!(
                "almost no texture: {:.1} % of the pixels stand above the noise; the disparities are guesses \
                 propagated from the few that do",
                100.0 * self.textured_share
            ));
        }
        let [cl, cr] = self.clipped;
        if (cl - cr).abs() > MAX_CLIPPED_DIFFERENCE {
            out.push(format!(
                "the views are exposed differently: {:.0} % of the left view's pixels and {:.0} % of the right's are \
                 clipped to black or white; detail lost in one view cannot be matched",
                100.0 * cl,
                100.0 * cr
            ));
        }
        if self.focus_beyond {
            out.push(format!(
                "one view is {:.1} times sharper than the other, more than a blur of {MAX_MATCHING_BLUR} px \
                 evens out (focus or motion blur)",
                self.sharpness_ratio
            ));
        }
        out
    }
}

impl PairCheck {
    /// The warning for a given range the scene reaches beyond: the answers pile up at its top and the pair
    /// measures a larger one.
    fn range_warning(&self) -> Option<String> {
        let ([d0, n], share) = (self.given_range?, self.top_share?);
        let beyond = |m: usize| m >= d0 + n + answer::MEASURE_MARGIN_PX;
        let fits = self.measured_ndisp.filter(|&m| share > answer::MAX_TOP_SHARE && beyond(m))?;
        let flag = if d0 > 0 { format!("--min-disp {d0} --ndisp {}", fits - d0) } else { format!("--ndisp {fits}") };
        Some(format!(
            "the scene reaches beyond the search range {d0}..{}: {:.0} % of the answers are within 4 px of its top, \
             and the pair measures a range of 0..{} ({flag} would fit)",
            d0 + n - 1,
            100.0 * share,
            fits - 1
        ))
    }

    /// The warning for a large region of repetitive texture whose answer is doubtful: likely a period off.
    fn repetition_warning(&self) -> Option<String> {
        let r = self.repetition.filter(|r| r.share > repetitive::MIN_SHARE)?;
        let [x0, y0, x1, y1] = r.bounds;
        Some(format!(
            "{:.0} % of the image (x {x0}..{x1}, y {y0}..{y1}) is texture that repeats every {:.0} px along the row, \
             within the search range, and its answers are doubtful or a period off their neighbours': they may \
             be matched one period off; a range that holds less than one period there (--min-disp, --ndisp) \
             avoids it",
            100.0 * r.share,
            r.period_px
        ))
    }

    /// The warnings for a vertical offset that changes across the image (rotation) or down it (scale).
    fn rotation_warnings(&self) -> Vec<String> {
        let spread = |a: Option<f32>, b: Option<f32>| Some(b? - a?).filter(|s| s.abs() > answer::MAX_OFFSET_SPREAD_PX);
        // A third not measured: its offset from the whole image's, which is that of the middle.
        let other = |x: Option<f32>, y: Option<f32>| x.or_else(|| Some(2.0 * self.vertical_px? - y?));
        let [l, r, t, b] = self.offsets_by_third;
        let (l, r, t, b) = (other(l, r), other(r, l), other(t, b), other(b, t));
        let [across, down] = self.thirds_apart_px;
        let mut out = Vec::new();
        if let Some(s) = spread(l, r) {
            out.push(format!(
                "the vertical offset between the views goes from {:+.1} px at the left to {:+.1} px at the right: the \
                 right view is rotated by about {:.1}° against the left (the pair is not rectified)",
                l.unwrap_or(0.0),
                r.unwrap_or(0.0),
                (s / across.max(1.0)).atan().to_degrees()
            ));
        }
        if let Some(s) = spread(t, b) {
            out.push(format!(
                "the vertical offset between the views goes from {:+.1} px at the top to {:+.1} px at the bottom: the \
                 right view is scaled by about {:+.1} % against the left (the pair is not rectified)",
                t.unwrap_or(0.0),
                b.unwrap_or(0.0),
                100.0 * s / down.max(1.0)
            ));
        }
        out
    }
}

impl std::fmt::Display for PairCheck {
    /// One line of the numbers (what `jem -v` prints).
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let opt =
            |v: Option<f32>, scale: f32, unit: &str| v.map_or("-".to_string(), |v| format!("{:.2}{unit}", v * scale));
        write!(
            f,
            "checked: negative-disparity share {}, vertical offset {} (alignment up to {} px), range {} of the width, \
             textured {:.1} %, clipped {:.1} / {:.1} %, sharpness ratio {:.2}, identical {:.1} %, at the range's top \
             {}, measured range {}, vertical offset by third (left right top bottom) {}, repetitive and suspect {}",
            opt(self.negative_share, 100.0, " %"),
            opt(self.vertical_px, 1.0, " px"),
            self.vertical_limit_px,
            opt(self.range_share, 100.0, " %"),
            100.0 * self.textured_share,
            100.0 * self.clipped[0],
            100.0 * self.clipped[1],
            self.sharpness_ratio,
            100.0 * self.identical_share,
            opt(self.top_share, 100.0, " %"),
            self.measured_ndisp.map_or("-".to_string(), |n| n.to_string()),
            self.offsets_by_third.map(|v| opt(v, 1.0, "")).join(" "),
            self.repetition.map_or("-".to_string(), |r| format!(
                "{:.1} % (period {} px)",
                100.0 * r.share,
                r.period_px
            ))
        )
    }
}

/// Checks a pair (see the module doc). `noise` is the noise σ the front end measured and the left view's contrast
/// gain it was measured after (σ is in stretched grey levels); `range_share`
/// the measured range over the width, when it was measured. The swap check runs at a resolution whose cost volume
/// fits `limit_bytes` (none when none does).
pub fn check_pair(
    left: &RgbImage,
    right: &RgbImage,
    p: &CostParams,
    noise: Option<(f32, f32)>,
    range_share: Option<f32>,
    limit_bytes: u64,
) -> PairCheck {
    let (w, h) = left.dims();
    let negative_share = crate::setup::range::measure_factor(w, h, w, limit_bytes).and_then(|factor| {
        let (l, r) = (downsample_rgb(left, factor), downsample_rgb(right, factor));
        // Half the width: the largest range a pair is matched over with any sense.
        let labels = (l.width / 2).max(2);
        // One after the other: each is sized to fit the memory limit on its own (and runs in parallel inside).
        let direct = crate::setup::range::reliable_matches(&l, &r, labels, p);
        let mirrored = crate::setup::range::reliable_matches(&l.mirrored(), &r.mirrored(), labels, p);
        // Disparity 0 (the far distance) matches the same either way round.
        let count = |m: &[f32]| m.iter().filter(|&&d| d >= 1.0).count();
        let (pos, neg) = (count(&direct), count(&mirrored));
        (100 * (pos + neg) >= l.len()).then(|| neg as f32 / (pos + neg) as f32)
    });
    let (gl, gr) = (left.to_grey(), right.to_grey());
    let (sigma, gain) = noise.unwrap_or((0.0, 1.0));
    let (sharpness_ratio, focus_beyond) = sharpness_ratio(&gl, &gr);
    PairCheck {
        negative_share,
        vertical_px: vertical_offset(&gl, &gr),
        vertical_limit_px: VerticalParams::MAX_OFFSET_PX,
        range_share,
        textured_share: textured_share(left, sigma, gain),
        clipped: [clipped_share(left), clipped_share(right)],
        sharpness_ratio,
        focus_beyond,
        identical_share: identical_share(left, right),
        given_range: None,
        top_share: None,
        measured_ndisp: None,
        offsets_by_third: [None; 4],
        thirds_apart_px: [2.0 * (w / 3) as f32, 2.0 * (h / 3) as f32],
        repetition: None,
    }
}

/// Adds to `check` what the answer tells of the pair (the answer checks): `given_range` ([smallest disparity, number])
/// when the range was given rather than measured, and `measure` to measure the range on the pair, called only when
/// the answers pile up at the top of the given one.
pub fn check_answer(
    check: &mut PairCheck,
    left: &RgbImage,
    right: &RgbImage,
    disparity: &crate::image::DisparityMap,
    given_range: Option<[usize; 2]>,
    measure: impl FnOnce() -> Option<usize>,
) {
    check.given_range = given_range;
    check.top_share = given_range.map(|[d0, n]| answer::top_share(disparity, d0 + n - 1));
    if check.top_share.is_some_and(|s| s > answer::MAX_TOP_SHARE) {
        check.measured_ndisp = measure();
    }
    check.offsets_by_third = answer::offsets_by_third(&left.to_grey(), &right.to_grey(), disparity);
}

/// Adds to `check` the largest region of the left view whose texture repeats itself within `range_px` (the search
/// range's width) and whose answer `disparity` its `confidence` doubts or is a period off a neighbouring part's
/// ([`Repetition`]).
///
/// # Panics
/// If the view, the answer and the confidence differ in size.
pub fn check_repetition(
    check: &mut PairCheck,
    left: &RgbImage,
    disparity: &crate::image::DisparityMap,
    confidence: &Plane<f32>,
    range_px: usize,
) {
    check.repetition = repetitive::repetitive_region(left, disparity, confidence, range_px);
}

/// The share of pixels whose three channels differ by at most half a grey level between the views.
fn identical_share(left: &RgbImage, right: &RgbImage) -> f32 {
    let same = |i: usize| left.rgb(i).iter().zip(right.rgb(i)).all(|(a, b)| (a - b).abs() <= 0.5);
    (0..left.len()).filter(|&i| same(i)).count() as f32 / left.len().max(1) as f32
}

/// Each row's mean grey level less its mean over the [`PROFILE_DETREND`] rows around it.
fn row_profile(grey: &Plane<f32>) -> Vec<f64> {
    let (w, h) = grey.dims();
    let means: Vec<f64> = (0..h).map(|y| grey.row(y).iter().map(|&v| f64::from(v)).sum::<f64>() / w as f64).collect();
    let half = PROFILE_DETREND / 2;
    (0..h)
        .map(|y| {
            let (a, b) = (y.saturating_sub(half), (y + half + 1).min(h));
            means[y] - means[a..b].iter().sum::<f64>() / (b - a) as f64
        })
        .collect()
}

/// The vertical shift (px, sub-pixel) of the right view's row profile against the left's, within ±⅛ of the height;
/// `None` when its correlation does not beat no shift's by [`PROFILE_MARGIN`] or the image is too small.
fn vertical_offset(left: &Plane<f32>, right: &Plane<f32>) -> Option<f32> {
    vertical_offset_within(left, right, 0..left.height(), OffsetTest::BeatsNoShift)
}

/// When a measured vertical offset counts.
#[derive(Clone, Copy, PartialEq)]
enum OffsetTest {
    /// Its correlation beats no shift's by [`PROFILE_MARGIN`] (or it is 0): an offset is there at all.
    BeatsNoShift,
    /// Its correlation is at least this: the profiles match well enough to say where (an offset may be small).
    Correlation(f64),
}

/// [`vertical_offset`] of the left view's rows `rows` (the right view's rows they are compared with may lie
/// outside them), counted as `test` says.
fn vertical_offset_within(
    left: &Plane<f32>,
    right: &Plane<f32>,
    rows: std::ops::Range<usize>,
    test: OffsetTest,
) -> Option<f32> {
    let h = left.height();
    let reach = (h / 8) as i64;
    if reach < 2 {
        return None;
    }
    let (pl, pr) = (row_profile(left), row_profile(right));
    let ncc = |dy: i64| -> f64 {
        let pairs = (rows.start as i64..rows.end as i64).filter_map(|y| {
            let yr = y + dy;
            (yr >= 0 && yr < h as i64).then(|| (pl[y as usize], pr[yr as usize]))
        });
        let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
        for (a, b) in pairs {
            sab += a * b;
            saa += a * a;
            sbb += b * b;
        }
        if saa > 0.0 && sbb > 0.0 { sab / (saa * sbb).sqrt() } else { f64::NEG_INFINITY }
    };
    let scores: Vec<(i64, f64)> = (-reach..=reach).map(|dy| (dy, ncc(dy))).collect();
    let &(best, score) = scores.iter().max_by(|a, b| a.1.total_cmp(&b.1).then(b.0.abs().cmp(&a.0.abs())))?;
    let counts = match test {
        OffsetTest::BeatsNoShift => score - ncc(0) >= PROFILE_MARGIN || best == 0,
        OffsetTest::Correlation(min) => score >= min,
    };
    if !counts || !score.is_finite() || has_rival_peak(&scores, best, score) {
        return None;
    }
    // A parabola through the peak and its neighbours.
    let at = |dy: i64| scores.iter().find(|s| s.0 == dy).map(|s| s.1);
    let sub = match (at(best - 1), at(best + 1)) {
        (Some(a), Some(c)) if (a - 2.0 * score + c) < 0.0 => 0.5 * (a - c) / (a - 2.0 * score + c),
        _ => 0.0,
    };
    Some((best as f64 + sub) as f32)
}

/// Whether the correlation over vertical shifts `scores` ((shift, correlation) by shift) has another peak, away
/// from the best shift `best` (beyond its own flanks), within [`RIVAL_PEAK_MARGIN`] of its `score`: rows that
/// repeat themselves down the image (a chessboard, blinds, shelving) match a period off as well as at the true
/// offset, and which of the two is the offset the profiles cannot tell.
fn has_rival_peak(scores: &[(i64, f64)], best: i64, score: f64) -> bool {
    scores.windows(3).any(|w| {
        let (dy, v) = w[1];
        (dy - best).abs() > 2 && v >= w[0].1 && v >= w[2].1 && v >= score - RIVAL_PEAK_MARGIN
    })
}

/// The share of the view's pixels with texture above the noise, at [`TEXTURE_FACTOR`] × reduced resolution (where
/// the averaging has taken the noise down by that factor, as the matching's windows do): the gradient magnitude
/// over [`TEXTURE_SIGMAS`] × the reduced noise σ and 2 grey levels, both in the grey levels of the view stretched
/// by `gain` (as the front end matches it: a dark view is not textureless).
fn textured_share(view: &RgbImage, sigma: f32, gain: f32) -> f32 {
    let grey = downsample_rgb(view, TEXTURE_FACTOR).to_grey();
    let (gx, gy) = central_differences(&grey);
    let threshold = (TEXTURE_SIGMAS * sigma / TEXTURE_FACTOR as f32).max(2.0) / gain.max(1.0);
    let n = gx.data().iter().zip(gy.data()).filter(|&(&a, &b)| a.hypot(b) > threshold).count();
    n as f32 / grey.data().len().max(1) as f32
}

/// The share of pixels whose channels are all at most 1 or all at least 254.
fn clipped_share(img: &RgbImage) -> f32 {
    let n = (0..img.len()).filter(|&i| {
        let c = img.rgb(i);
        c.iter().all(|&v| v <= 1.0) || c.iter().all(|&v| v >= 254.0)
    });
    n.count() as f32 / img.len().max(1) as f32
}

/// The sharper view's sharpness over the other's, and whether the largest blur the front end gives the sharper
/// view still leaves it more than the front end's tolerance (`condition.sharpness_ratio`, 1.25) sharper.
fn sharpness_ratio(left: &Plane<f32>, right: &Plane<f32>) -> (f32, bool) {
    let (sl, sr) = (crate::condition::sharpness(left), crate::condition::sharpness(right));
    let (sharp, blurry, sharper) = if sl >= sr { (sl, sr, left) } else { (sr, sl, right) };
    if blurry.is_nan() || blurry <= 0.0 {
        return (1.0, false);
    }
    let ratio = sharp / blurry;
    // Cheap first: a blur of 3 px lowers the sharpness far more than 2 times, so below that nothing is beyond.
    if ratio < 2.0 {
        return (ratio, false);
    }
    let (w, h) = sharper.dims();
    let blurred = Plane::from_parts(w, h, gaussian_blur_plane(sharper.data(), w, h, MAX_MATCHING_BLUR));
    (ratio, crate::condition::sharpness(&blurred) > 1.25 * blurry)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::{SynthParams, render_scene};

    fn scene() -> (RgbImage, RgbImage) {
        let s = render_scene(&SynthParams { width: 240, height: 180, ndisp: 32, seed: 5 }).unwrap();
        (s.left, s.right)
    }

    fn check(l: &RgbImage, r: &RgbImage) -> PairCheck {
        check_pair(l, r, &CostParams::default(), None, None, u64::MAX)
    }

    /// The image with every channel mapped through `f`.
    fn mapped(img: &RgbImage, f: impl Fn(usize, usize, &[f32]) -> f32) -> RgbImage {
        let (w, h) = img.dims();
        let channels = [0, 1, 2].map(|c| (0..w * h).map(|i| f(i % w, i / w, img.channel(c))).collect());
        RgbImage::from_channels(w, h, channels).unwrap()
    }

    #[test]
    fn a_good_pair_gives_no_warning() {
        let (l, r) = scene();
        let c = check(&l, &r);
        assert!(c.warnings().is_empty(), "{c}: {:?}", c.warnings());
        assert!(c.negative_share.unwrap() < 0.5 && c.vertical_px.unwrap().abs() < 0.5, "{c}");
    }

    /// The same image as both views matches at 0 everywhere, "100 % valid": said to be the same image. A good
    /// pair, and one view made a little brighter (still almost the same image to the eye), are not.
    #[test]
    fn the_same_image_twice_is_said_to_be() {
        let (l, r) = scene();
        let c = check(&l, &l);
        assert!(c.identical_share == 1.0, "{c}");
        assert!(c.warnings().iter().any(|w| w.starts_with("the two views are the same image (100.0 %")), "{c}");
        assert!(check(&l, &r).identical_share < 0.5, "{}", check(&l, &r));
        let brighter = mapped(&l, |x, y, c| (c[y * l.width() + x] + 2.0).min(255.0));
        assert!(!check(&l, &brighter).warnings().iter().any(|w| w.contains("same image")));
    }

    #[test]
    fn swapped_views_are_said_to_be() {
        let (l, r) = scene();
        let c = check(&r, &l);
        assert!(c.warnings().iter().any(|w| w.starts_with("the views look swapped")), "{c}");
    }

    #[test]
    fn a_right_view_lower_than_the_alignment_corrects_is_reported_with_its_offset() {
        let (l, r) = scene();
        let w = r.width();
        let lower = mapped(&r, |x, y, ch| if y >= 7 { ch[(y - 7) * w + x] } else { ch[x] });
        let c = check(&l, &lower);
        assert!((c.vertical_px.unwrap() - 7.0).abs() < 0.5, "{c}");
        let warnings = c.warnings();
        assert!(
            warnings.iter().any(|w| w.contains(" px lower than the left") && w.contains("--rectify")),
            "{warnings:?}"
        );
    }

    /// The image resampled at `(x, y) → at(x, y)` (bilinear, clamped at the borders).
    fn warped(img: &RgbImage, at: impl Fn(f64, f64) -> (f64, f64)) -> RgbImage {
        let (w, h) = img.dims();
        let channel = |c: usize| {
            let src = img.channel(c);
            let sample = |i: usize| {
                let (x, y) = at((i % w) as f64, (i / w) as f64);
                crate::imgproc::sample::sample_bilinear(src, w, h, x, y) as f32
            };
            (0..w * h).map(sample).collect()
        };
        RgbImage::from_channels(w, h, [0, 1, 2].map(channel)).unwrap()
    }

    /// The checks of a scene's pair with its true disparities as the answer and `given` as the range.
    fn checked_with_answer(right: impl Fn(&RgbImage) -> RgbImage, given: Option<[usize; 2]>, fits: usize) -> PairCheck {
        let s = crate::synth::render_scene(&SynthParams { width: 240, height: 180, ndisp: 32, seed: 5 }).unwrap();
        let right = right(&s.right);
        let mut c = check(&s.left, &right);
        check_answer(&mut c, &s.left, &right, &s.gt, given, || Some(fits));
        c
    }

    /// A right view rotated by 1.5° or scaled by 3 % is said to be, with about its angle and scale; the pair as
    /// rendered is not (the vertical offset is the same in every third).
    #[test]
    fn a_rotated_or_scaled_right_view_is_said_to_be() {
        let (cx, cy) = (119.5, 89.5);
        let (sin, cos) = 1.5f64.to_radians().sin_cos();
        let rotate = |r: &RgbImage| {
            warped(r, |x, y| (cx + cos * (x - cx) + sin * (y - cy), cy - sin * (x - cx) + cos * (y - cy)))
        };
        let c = checked_with_answer(rotate, None, 0);
        let rotated = c.warnings().into_iter().find(|w| w.contains("rotated by about")).expect("rotation");
        assert!(rotated.contains("1.") || rotated.contains("2."), "{rotated}: {c}");
        let scale = |r: &RgbImage| warped(r, |x, y| (cx + (x - cx) / 1.03, cy + (y - cy) / 1.03));
        let c = checked_with_answer(scale, None, 0);
        assert!(c.warnings().iter().any(|w| w.contains("scaled by about +")), "{c}: {:?}", c.warnings());
        let c = checked_with_answer(RgbImage::clone, None, 0);
        assert!(c.warnings().is_empty(), "{c}: {:?}", c.warnings());
        let [l, r, t, b] = c.offsets_by_third.map(Option::unwrap);
        assert!((l - r).abs() < 0.5 && (t - b).abs() < 0.5, "{c}");
    }

    /// A chessboard over the whole frame repeats its rows every period: the right view a period lower matches as
    /// well as one in line, so no offset is measured and nothing is said of rotation or scale.
    #[test]
    fn rows_that_repeat_give_no_vertical_offset() {
        let (w, h, period) = (240usize, 180usize, 12usize);
        let board = |dx: f64, dy: f64| {
            let cell = |x: f64, y: f64| ((x / 6.0).floor() + (y / 6.0).floor()).rem_euclid(2.0) as f32;
            let grey: Vec<f32> =
                (0..w * h).map(|i| 40.0 + 170.0 * cell((i % w) as f64 + dx, (i / w) as f64 - dy)).collect();
            RgbImage::from_channels(w, h, [grey.clone(), grey.clone(), grey]).unwrap()
        };
        let (l, r) = (board(0.0, 0.0), board(8.0, period as f64 * 2.0));
        let c = check(&l, &r);
        assert_eq!(c.vertical_px, None, "{c}");
        let gt = Plane::new(w, h, 8.0);
        let mut c = check(&l, &r);
        check_answer(&mut c, &l, &r, &gt, None, || None);
        assert!(c.offsets_by_third.iter().all(Option::is_none), "{c}");
        assert!(c.warnings().iter().all(|w| !w.contains("vertical offset")), "{:?}", c.warnings());
        let scores: Vec<(i64, f64)> = (-20..=20).map(|dy| (dy, (dy as f64 * 0.5).cos())).collect();
        assert!(has_rival_peak(&scores, 0, 1.0), "a cosine peaks every 4π px");
        let single: Vec<(i64, f64)> = (-20..=20).map(|dy| (dy, -(dy as f64).abs() / 20.0)).collect();
        assert!(!has_rival_peak(&single, 0, 0.0));
    }

    /// A given range the scene reaches beyond (answers piled up at its top, a larger range measured) is said to
    /// be, with the range that fits; the same answers under a range that holds them, or a measurement that finds
    /// nothing beyond the margin, are not.
    #[test]
    fn a_range_that_clips_the_scene_is_said_to_be_with_one_that_fits() {
        let clipped = |r: &RgbImage| r.clone();
        // The scene's disparities reach 31 or so: a range of 16 leaves many beyond it (the true map is the answer,
        // so "piled up" is read as "at or beyond the top").
        let c = checked_with_answer(clipped, Some([0, 16]), 48);
        let w = c.warnings().into_iter().find(|w| w.starts_with("the scene reaches beyond")).expect("clipping");
        assert!(w.contains("range 0..15") && w.contains("--ndisp 48 would fit"), "{w}");
        let c = checked_with_answer(clipped, Some([4, 12]), 48);
        assert!(c.warnings().iter().any(|w| w.contains("--min-disp 4 --ndisp 44 would fit")), "{:?}", c.warnings());
        assert!(checked_with_answer(clipped, Some([0, 16]), 31).warnings().is_empty());
        let c = checked_with_answer(clipped, Some([0, 64]), 80);
        assert!(c.top_share == Some(0.0) && c.measured_ndisp.is_none() && c.warnings().is_empty(), "{c}");
    }

    #[test]
    fn a_flat_pair_has_almost_no_texture() {
        let flat = mapped(&scene().0, |x, y, _| 120.0 + ((x * 7 + y * 13) % 3) as f32 * 0.3);
        let c = check(&flat, &flat);
        assert!(c.warnings().iter().any(|w| w.starts_with("almost no texture")), "{c}");
    }

    #[test]
    fn a_clipped_view_and_a_blurred_view_are_reported() {
        let (l, r) = scene();
        let bright = mapped(&r, |x, y, ch| (ch[y * r.width() + x] * 3.0).min(255.0));
        assert!(check(&l, &bright).warnings().iter().any(|w| w.contains("exposed differently")));
        let (w, h) = r.dims();
        let blurred =
            RgbImage::from_channels(w, h, [0, 1, 2].map(|c| gaussian_blur_plane(r.channel(c), w, h, 6.0))).unwrap();
        let c = check(&l, &blurred);
        assert!(c.focus_beyond && c.warnings().iter().any(|w| w.contains("sharper than the other")), "{c}");
        // A blur the front end evens out is no warning.
        let slight =
            RgbImage::from_channels(w, h, [0, 1, 2].map(|c| gaussian_blur_plane(r.channel(c), w, h, 1.0))).unwrap();
        assert!(!check(&l, &slight).focus_beyond);
    }
}
