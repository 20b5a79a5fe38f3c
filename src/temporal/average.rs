//! Running means over the frames of a still camera: of the views, so that the matcher sees the scene with the
//! noise of one frame divided by √n, and of the answers, so that what the matcher says about a static pixel
//! settles instead of flickering. Each pixel keeps its own count and starts again where the scene changed.

use super::exposure::Exposure;
use super::motion::Shift;
use crate::image::{DisparityMap, Plane, RgbImage};
use crate::imgproc::filter::box_mean;
use crate::imgproc::noise::GREY_NOISE_PER_SIGMA;

/// The most frames a running mean holds: beyond √16 = 4 times less noise, the mean follows slow changes (light,
/// exposure) too slowly for the little it still gains.
pub(crate) const MAX_FRAMES: u16 = 16;

/// A change larger than this many standard deviations of the noise is the scene's, not the noise's.
const CHANGE_SIGMAS: f32 = 4.0;

/// The least per-channel noise σ the change test assumes (quantisation and the clean camera's own noise).
const MIN_SIGMA: f32 = 0.5;

/// The running mean of both views, each pixel with its count of frames.
#[derive(Clone, Debug)]
pub(crate) struct ViewMeans {
    pub(crate) left: RgbImage,
    pub(crate) right: RgbImage,
    counts: [Plane<u16>; 2],
}

impl ViewMeans {
    /// The means of one frame.
    pub(crate) fn start(left: &RgbImage, right: &RgbImage) -> ViewMeans {
        let (w, h) = left.dims();
        ViewMeans { left: left.clone(), right: right.clone(), counts: [Plane::new(w, h, 1), Plane::new(w, h, 1)] }
    }

    /// Folds a new frame into the means and returns where each view started again and whether any mean moved. A
    /// pixel starts again where the 3 × 3 mean of its grey difference from the mean exceeds [`CHANGE_SIGMAS`]
    /// standard deviations of that mean under noise of per-channel σ `noise_sigma` (something moved or changed
    /// there); elsewhere the mean takes the frame with weight 1/n, n its count (at most [`MAX_FRAMES`]).
    pub(crate) fn fold(&mut self, left: &RgbImage, right: &RgbImage, noise_sigma: f32) -> Folded {
        let (left, left_moved) = fold_view(&mut self.left, &mut self.counts[0], left, noise_sigma);
        let (right, right_moved) = fold_view(&mut self.right, &mut self.counts[1], right, noise_sigma);
        Folded { left, right, moved: left_moved || right_moved }
    }

    /// Carries the means to the exposure of a new frame: each view's change against its mean is fitted
    /// ([`super::exposure::fit`]) and applied to the mean (clipped to 0–255, as the frame is). Returns the left
    /// view's change (`None`: none to compensate).
    pub(crate) fn follow_exposure(&mut self, left: &RgbImage, right: &RgbImage) -> Option<Exposure> {
        let mut changes = [None; 2];
        for ((mean, frame), change) in [(&mut self.left, left), (&mut self.right, right)].into_iter().zip(&mut changes)
        {
            *change = super::exposure::fit(&mean.to_grey(), &frame.to_grey(), Shift { dx: 0, dy: 0, residual: 0.0 });
            if let Some(e) = *change {
                e.apply_image(mean);
            }
        }
        changes[0]
    }

    /// The frames the left view's mean holds at each pixel.
    pub(crate) fn left_counts(&self) -> &Plane<u16> {
        &self.counts[0]
    }
}

/// What folding a frame into the means did ([`ViewMeans::fold`]).
pub(crate) struct Folded {
    /// Where the left view started again.
    pub(crate) left: Plane<bool>,
    /// Where the right view started again.
    pub(crate) right: Plane<bool>,
    /// Whether any value of either mean changed (not, when the frame repeats the means exactly).
    pub(crate) moved: bool,
}

impl Folded {
    /// The left pixels whose scene changed, in either view: where the left view started again, or where the right
    /// view did at the match `answer` gives the pixel (x − d, within a pixel either side for the answer's own
    /// error). An object that moves changes what a left pixel's match sees even where the left view itself holds
    /// still (the background it uncovers in the right view).
    pub(crate) fn changed_for(&self, answer: &DisparityMap) -> Plane<bool> {
        let mut changed = self.left.clone();
        let w = answer.width as i64;
        for y in 0..answer.height {
            let (right, row) = (self.right.row(y), answer.row(y));
            for (x, c) in changed.row_mut(y).iter_mut().enumerate() {
                let d = row[x];
                if *c || !d.is_finite() {
                    continue;
                }
                let at = (x as f32 - d).round() as i64;
                *c = (at - 1..=at + 1).any(|k| (0..w).contains(&k) && right[k as usize]);
            }
        }
        changed
    }
}

/// [`ViewMeans::fold`] for one view: where it started again, and whether any value of the mean changed.
fn fold_view(mean: &mut RgbImage, count: &mut Plane<u16>, frame: &RgbImage, noise_sigma: f32) -> (Plane<bool>, bool) {
    let (w, h) = frame.dims();
    let (grey_frame, grey_mean) = (frame.to_grey(), mean.to_grey());
    let diff = Plane::from_parts(w, h, grey_frame.data.iter().zip(&grey_mean.data).map(|(f, m)| f - m).collect());
    let local = box_mean(&diff, 1);
    let sigma_grey = GREY_NOISE_PER_SIGMA * noise_sigma.max(MIN_SIGMA);
    let mut restarted = Plane::new(w, h, false);
    let moved = frame.channels.iter().zip(&mean.channels).any(|(f, m)| f != m);
    for i in 0..w * h {
        let n = f32::from(count.data[i]);
        // The difference of a frame and an n-frame mean has σ·√(1 + 1/n); a 3 × 3 mean of it a third of that.
        let limit = CHANGE_SIGMAS * sigma_grey * (1.0 + 1.0 / n).sqrt() / 3.0;
        if local.data[i].abs() > limit {
            count.data[i] = 1;
            restarted.data[i] = true;
            for c in 0..3 {
                mean.channels[c][i] = frame.channels[c][i];
            }
        } else {
            count.data[i] = (count.data[i] + 1).min(MAX_FRAMES);
            let k = 1.0 / f32::from(count.data[i]);
            for c in 0..3 {
                mean.channels[c][i] += (frame.channels[c][i] - mean.channels[c][i]) * k;
            }
        }
    }
    (restarted, moved)
}

/// The running mean of a still camera's answers, each weighted by the frames in the view means it was matched on
/// (an answer from n frames' mean has about 1/n of the noise variance of one frame's: inverse-variance weights). A
/// static pixel's value settles, and later answers, from less noisy means, count more.
#[derive(Clone, Debug)]
pub(crate) struct AnswerMean {
    pub(crate) mean: DisparityMap,
    weight: Plane<f32>,
}

impl AnswerMean {
    /// The mean of one answer.
    pub(crate) fn start(answer: &DisparityMap) -> AnswerMean {
        let (w, h) = answer.dims();
        AnswerMean { mean: answer.clone(), weight: Plane::new(w, h, 1.0) }
    }

    /// Folds a new answer in, matched on view means of `frames` frames at each pixel: where the views started
    /// again or the mean has no value, the mean is the answer; elsewhere the weighted mean of the answers (the
    /// weight held is at most that of [`MAX_FRAMES`] frames of [`MAX_FRAMES`] each, so the mean still follows a
    /// slow change). An invalid answer leaves the mean as it is.
    pub(crate) fn fold(&mut self, answer: &DisparityMap, frames: &Plane<u16>) {
        let cap = f32::from(MAX_FRAMES) * f32::from(MAX_FRAMES);
        for i in 0..answer.data.len() {
            let d = answer.data[i];
            let m = &mut self.mean.data[i];
            let n = f32::from(frames.data[i]);
            if !d.is_finite() {
                continue;
            }
            if frames.data[i] == 1 || !m.is_finite() {
                *m = d;
                self.weight.data[i] = 1.0;
                continue;
            }
            let held = self.weight.data[i].min(cap);
            self.weight.data[i] = held + n;
            *m += (d - *m) * n / (held + n);
        }
    }
}

/// Where a moving frame's answer agrees with the previous answer carried into it (within [`AGREE_PX`], at a pixel
/// the frames agree on), the answer moves [`CARRIED_SHARE`] of the way to the carried one: a surface seen in both
/// frames keeps its disparity from frame to frame instead of taking each frame's own error, and since the carried
/// answer is the previous frame's answer so carried, each is a running mean over the frames that saw the surface
/// (older frames weigh less by half each frame). Where they disagree (a depth edge moved, something moved, one of
/// them wrong) the frame's own answer stands.
pub(crate) fn carry_answer(answer: &mut DisparityMap, carried: &DisparityMap, released: &Plane<bool>) {
    for ((d, &c), &r) in answer.data.iter_mut().zip(&carried.data).zip(&released.data) {
        if !r && d.is_finite() && c.is_finite() && (c - *d).abs() <= AGREE_PX {
            *d += CARRIED_SHARE * (c - *d);
        }
    }
}

/// The share of the carried answer in a moving frame's answer where the two agree ([`carry_answer`]).
const CARRIED_SHARE: f32 = 0.5;
/// How close (px) a moving frame's answer and the carried one must be to be the same surface ([`carry_answer`]):
/// as close as the left-right check's default asks of the two views' answers.
const AGREE_PX: f32 = 1.0;

#[cfg(test)]
mod tests {
    use super::*;

    fn grey_image(values: &[f32], w: usize) -> RgbImage {
        let v = values.to_vec();
        RgbImage::from_channels(w, values.len() / w, [v.clone(), v.clone(), v]).unwrap()
    }

    #[test]
    fn a_left_pixel_changes_where_its_match_in_the_right_view_restarted() {
        let row = |v: &[bool]| Plane::from_parts(v.len(), 1, v.to_vec());
        let (f, t) = (false, true);
        // The right view restarted at x = 2 only; the left view at x = 7.
        let folded =
            Folded { left: row(&[f, f, f, f, f, f, f, t]), right: row(&[f, f, t, f, f, f, f, f]), moved: true };
        let answer = Plane::from_parts(8, 1, vec![0.0, 0.0, 0.0, 1.0, 2.0, 4.0, f32::INFINITY, 0.0]);
        // x − d: 0, 1, 2, 2, 2, 1, -, 7; within a pixel of 2: x = 1..=5; x = 7 by the left view itself.
        let changed = folded.changed_for(&answer);
        assert_eq!(changed.data, vec![f, t, t, t, t, t, f, t]);
    }

    #[test]
    fn a_repeated_frame_leaves_the_means_unmoved() {
        let a = grey_image(&[100.0, 50.0, 20.0, 7.0], 2);
        let mut means = ViewMeans::start(&a, &a);
        assert!(!means.fold(&a, &a, 1.0).moved);
        let mut b = a.clone();
        b.channel_mut(1)[3] = 7.5;
        assert!(means.fold(&a, &b, 1.0).moved, "the right view's mean moved");
    }

    #[test]
    fn the_mean_of_a_still_scene_averages_and_restarts_where_it_changes() {
        let a = grey_image(&[100.0; 16], 4);
        let mut means = ViewMeans::start(&a, &a);
        let mut b = grey_image(&[102.0; 16], 4);
        let restarted = means.fold(&b, &b, 2.0).left;
        assert!(restarted.data.iter().all(|r| !r), "a change within the noise");
        assert_eq!(means.left.channel(0)[5], 101.0);
        // A bright object enters the right half: those pixels (and their 3 × 3 neighbours) start again.
        for y in 0..4 {
            for x in 2..4 {
                for c in 0..3 {
                    b.channel_mut(c)[y * 4 + x] = 200.0;
                }
            }
        }
        let restarted = means.fold(&b, &b, 2.0).left;
        assert!(restarted.data[3] && restarted.data[2] && !restarted.data[0]);
        assert_eq!(means.left.channel(1)[3], 200.0);
        assert_eq!(means.left_counts().data[3], 1);
        assert_eq!(means.left_counts().data[0], 3);
    }

    #[test]
    fn identical_frames_leave_the_mean_exactly_as_it_was() {
        let a = grey_image(&[10.0, 37.5, 200.25, 99.0], 2);
        let mut means = ViewMeans::start(&a, &a);
        for _ in 0..20 {
            means.fold(&a, &a, 0.0);
        }
        assert_eq!(means.left, a);
        assert_eq!(means.left_counts().data[0], MAX_FRAMES);
    }

    /// A textured grey image, `w` × `h`, values in 40..200.
    fn textured(w: usize, h: usize) -> Vec<f32> {
        (0..w * h).map(|i| 120.0 + 50.0 * ((i % w) as f32 * 0.3).sin() + 30.0 * ((i / w) as f32 * 0.2).cos()).collect()
    }

    #[test]
    fn the_means_follow_an_exposure_change_and_do_not_start_again() {
        let a = grey_image(&textured(64, 48), 64);
        let mut means = ViewMeans::start(&a, &a);
        let mut brighter = a.clone();
        brighter.channels.iter_mut().flatten().for_each(|v| *v = (*v * 1.1).min(255.0));
        let e = means.follow_exposure(&brighter, &brighter).expect("a 10 % gain");
        assert!((e.gain - 1.1).abs() < 1e-3 && e.offset.abs() < 0.1, "{e:?}");
        let restarted = means.fold(&brighter, &brighter, 2.0).left;
        assert!(restarted.data.iter().all(|r| !r), "the mean was carried to the new exposure");
        assert_eq!(means.left_counts().data[0], 2);
        assert!(means.left.channels[0].iter().zip(&brighter.channels[0]).all(|(m, f)| (m - f).abs() < 0.2));
        // The same exposure again: nothing to compensate.
        assert_eq!(means.follow_exposure(&brighter, &brighter), None);
    }

    #[test]
    fn an_answer_mean_weighs_later_answers_more() {
        let frames = |n: u16| Plane::new(2, 1, n);
        let mut m = AnswerMean::start(&Plane::from_parts(2, 1, vec![10.0, f32::INFINITY]));
        // The second answer, from a two-frame mean, weighs twice the first.
        m.fold(&Plane::from_parts(2, 1, vec![11.0, 5.0]), &frames(2));
        assert!((m.mean.data[0] - (10.0 + 2.0 / 3.0)).abs() < 1e-6, "{}", m.mean.data[0]);
        assert_eq!(m.mean.data[1], 5.0);
        // The third, from three frames, weighs 3 of 6.
        m.fold(&Plane::from_parts(2, 1, vec![16.0, f32::INFINITY]), &frames(3));
        assert!((m.mean.data[0] - (10.0 + 22.0 + 48.0) / 6.0).abs() < 1e-5, "{}", m.mean.data[0]);
        assert_eq!(m.mean.data[1], 5.0, "an invalid answer leaves the mean");
        // Where the views started again (one frame in their mean), the new answer.
        m.fold(&Plane::from_parts(2, 1, vec![40.0, 6.0]), &Plane::from_parts(2, 1, vec![1, 4]));
        assert_eq!(m.mean.data[0], 40.0);
    }

    #[test]
    fn a_moving_frame_keeps_half_of_the_carried_answer_where_they_agree() {
        let inf = f32::INFINITY;
        let carried = Plane::from_parts(6, 1, vec![10.0, 10.0, 10.0, 10.0, inf, 10.0]);
        let mut answer = Plane::from_parts(6, 1, vec![10.8, 12.0, 9.2, 10.6, 7.0, inf]);
        let released = Plane::from_parts(6, 1, vec![false, false, false, true, false, false]);
        carry_answer(&mut answer, &carried, &released);
        // Within 1 px: half-way; 2 px apart, released, or either one missing: the frame's own answer.
        for (i, want) in [10.4, 12.0, 9.6, 10.6, 7.0].into_iter().enumerate() {
            assert!((answer.data[i] - want).abs() < 1e-5, "pixel {i}: {} against {want}", answer.data[i]);
        }
        assert!(!answer.data[5].is_finite());
    }
}
