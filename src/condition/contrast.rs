//! Contrast (module doc of [`crate::condition`], item 1): a low-contrast view stretched to [`TARGET_RANGE`] grey
//! levels (`condition.stretch`).

use std::borrow::Cow;

use crate::image::StereoPair;

use crate::imgproc::stats::percentiles;

/// The grey-level span the left view's 0.5–99.5 % range is stretched to (when it is smaller).
pub(crate) const TARGET_RANGE: f32 = 230.0;

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
            for ch in &mut img.to_mut().channels {
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
    use crate::image::RgbImage;
    use crate::params::{ConditionParams, StretchParams};

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
        let pair = |img: &RgbImage| StereoPair::new(img.clone(), img.clone(), 4).unwrap();
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
        assert_eq!(*out.guide.left, dark);
    }
}
