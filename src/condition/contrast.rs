//! Contrast (module doc of [`crate::condition`], items 1 and 2): the right view's histogram matched onto the
//! left view's (`experimental.match_histograms`), and a low-contrast view stretched to [`TARGET_RANGE`] grey levels
//! (`condition.stretch`).

use std::borrow::Cow;

use crate::image::{RgbImage, StereoPair};

use super::stats::{histogram, percentiles};

/// The grey-level span the left view's 0.5–99.5 % range is stretched to (when it is smaller).
pub const TARGET_RANGE: f32 = 230.0;

/// Maps each channel of `src` onto the distribution of the same channel of `reference` (histogram
/// specification on 256 bins: each source level goes to the reference level of the same cumulative frequency,
/// taken at the middle of the source level's mass).
pub(super) fn match_histograms(src: &RgbImage, reference: &RgbImage) -> RgbImage {
    let mut out = src.clone();
    for c in 0..3 {
        let hs = histogram(&src.channels[c]);
        let hr = histogram(&reference.channels[c]);
        let (ns, nr) = (src.len() as f64, reference.len() as f64);
        let mut cum_r = Vec::with_capacity(256);
        let mut acc = 0.0;
        for v in hr {
            acc += v as f64 / nr;
            cum_r.push(acc);
        }
        let mut lut = [0.0f32; 256];
        let mut acc = 0.0;
        for (level, &count) in hs.iter().enumerate() {
            let mid = acc + 0.5 * count as f64 / ns;
            acc += count as f64 / ns;
            // The reference level where the cumulative frequency reaches `mid`, interpolated within the bin.
            let k = cum_r.partition_point(|&c| c < mid).min(255);
            let below = if k == 0 { 0.0 } else { cum_r[k - 1] };
            let width = (cum_r[k] - below).max(1e-12);
            lut[level] = (k as f64 - 0.5 + ((mid - below) / width).clamp(0.0, 1.0)).clamp(0.0, 255.0) as f32;
        }
        out.channels[c].iter_mut().for_each(|v| *v = lut[v.round().clamp(0.0, 255.0) as usize]);
    }
    out
}

/// Stretches each view of `guide` whose robust range (the 0.5th to the 99.5th percentile of grey) is below
/// [`TARGET_RANGE`] / `min_gain` to span [`TARGET_RANGE`] grey levels (an affine map about the range's centre; see
/// the module doc, "Contrast"), copying the pair only then. Returns the two views' gains (1 = none).
pub(super) fn stretch(guide: &mut Cow<'_, StereoPair>, min_gain: f32) -> [f32; 2] {
    let mut gain = [1.0f32; 2];
    for (view, g) in gain.iter_mut().enumerate() {
        let img = if view == 0 { &guide.left } else { &guide.right };
        let (lo, hi) = percentiles(&img.to_grey().data, 0.005, 0.995);
        let range = (hi - lo).max(1.0);
        if TARGET_RANGE / range >= min_gain.max(1.0 + 1e-6) {
            *g = TARGET_RANGE / range;
            let (centre, gv) = (0.5 * (lo + hi), *g);
            let owned = guide.to_mut();
            let img = if view == 0 { &mut owned.left } else { &mut owned.right };
            for ch in &mut img.channels {
                ch.iter_mut().for_each(|v| *v = ((*v - centre) * gv + 127.5).clamp(0.0, 255.0));
            }
        }
    }
    gain
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::condition::condition_pair;
    use crate::condition::test_images::textured;
    use crate::params::{ConditionParams, StretchParams};

    /// A right view with another gain and gamma is mapped back onto the left view's levels.
    #[test]
    fn histogram_matching_undoes_a_tone_curve() {
        let left = textured(120, 80, 2.0, 5);
        let mut right = left.clone();
        for ch in &mut right.channels {
            ch.iter_mut().for_each(|v| *v = (255.0 * (0.6 * *v / 255.0).powf(1.4)).round());
        }
        let matched = match_histograms(&right, &left);
        let mean_abs = |a: &RgbImage| {
            a.channels[1].iter().zip(&left.channels[1]).map(|(p, q)| (p - q).abs()).sum::<f32>() / a.len() as f32
        };
        assert!(mean_abs(&right) > 30.0, "the tone curve changes the image");
        assert!(mean_abs(&matched) < 2.0, "matched: {}", mean_abs(&matched));
    }

    /// A dark pair is stretched (each view by its own range); a full-contrast pair is left alone; off is off.
    #[test]
    fn stretch_only_for_low_contrast() {
        // Full contrast: a ramp over the whole 8-bit range.
        let mut bright = RgbImage::new(64, 48);
        bright
            .channels
            .iter_mut()
            .for_each(|c| c.iter_mut().enumerate().for_each(|(i, v)| *v = (255 * (i % 64) / 63) as f32));
        let mut dark = textured(64, 48, 1.0, 7);
        dark.channels.iter_mut().for_each(|c| c.iter_mut().for_each(|v| *v = (*v * 0.2).round()));
        let p = ConditionParams {
            stretch: StretchParams { enabled: true, ..Default::default() },
            ..ConditionParams::off()
        };
        let pair = |img: &RgbImage| StereoPair { left: img.clone(), right: img.clone(), ndisp: 4 };
        let dark_pair = pair(&dark);
        let out = condition_pair(&dark_pair, &p, None);
        assert!(out.stats.gain[0] > 3.0 && out.stats.gain[0] == out.stats.gain[1], "gain {:?}", out.stats.gain);
        assert!(matches!(out.guide, Cow::Owned(_)));
        assert_eq!(out.guide.left, out.guide.right);
        assert!(out.cost.is_none(), "nothing denoised");
        let bright_pair = pair(&bright);
        let out = condition_pair(&bright_pair, &p, None);
        assert_eq!(out.stats.gain, [1.0, 1.0]);
        assert!(matches!(out.guide, Cow::Borrowed(_)), "a full-contrast pair is not copied");
        let out = condition_pair(&dark_pair, &ConditionParams::off(), None);
        assert_eq!(out.guide.left, dark);
    }
}
