//! The temporal model (our addition, not the paper's): a [`crate::Matcher`] that remembers the frames of a stereo
//! sequence uses what it saw before for the frame it matches now.
//!
//! Each frame is first compared with the previous one, on their left views in grey ([`motion`]): the global
//! integer shift that best aligns them, and what that shift leaves unexplained beyond the two frames' noise,
//! relative to the image's contrast. A change of exposure between them (a gain and an offset on every grey value,
//! [`exposure`]) is fitted first and compensated in the previous view, then the shift searched again: what the
//! frames' exposure explains is neither motion nor a cut. Then it is one of:
//!
//! - **a cut** (the first frame, a new size, or more than half the contrast unexplained: another scene). Every
//!   memory is dropped and the frame is matched as a first frame, exactly as without the model.
//! - **still** (no shift). The views are folded into their running means ([`average::ViewMeans`]: a pixel starts
//!   again where the frame differs from the mean by more than its noise allows — something moved there) and the
//!   pipeline matches the means: n frames of a still camera hold the scene with 1/√n of one frame's noise. The
//!   answers are folded into a running mean too, weighted by the frames each was matched on
//!   ([`average::AnswerMean`]), which starts again where either view's mean did (the right one at the pixel's match: a
//!   moving object uncovers background in the right view where the left view holds still): a static pixel's answer
//!   settles instead of flickering with each frame's noise. A frame that leaves the means exactly as they were (a clean
//!   camera's repeated frame) keeps the previous answer. Each view's exposure change against its running mean is fitted
//!   and the mean carried to the new exposure (clipped at 0 and 255) before the frame is folded in: the means follow
//!   the camera's exposure and do not start again.
//! - **moving** (a shift). The previous answer, moved by the shift, is the prior of the frame in place of the
//!   coarse chain, which is not run: with the coarse prior's weight rule (λ by the measured noise, at least the
//!   cost's flatness, times the previous confidence, lowered where its left-right check failed), released where
//!   the shifted frames disagree (disocclusions, moving objects, the parallax a shift cannot follow; the previous
//!   view compared under the new exposure). The vertical
//!   offset removed from the previous frame's right view is reused instead of measured again, and the frame runs
//!   one mean-field iteration fewer (the prior has placed each pixel), its right view, which serves the left-right
//!   check only, one with the local term alone. The slanted planes start from the previous frame's segments and
//!   planes, moved by the shift (new cells where the frames disagree), and stop once they have settled
//!   ([`crate::post::planes`]). The running means start again.
//! - **travelling** (a motion in depth or a turn: a car driving forward, a camera moving sideways with parallax).
//!   Points are tracked from the previous left view into the current one ([`track`]) and the camera's 3D motion
//!   fitted to them through the previous answer's disparities ([`egomotion`]; no calibration needed). Where it
//!   explains clearly more of the points than the global shift does, the previous answer is carried by it
//!   (each pixel to where the motion puts it, with the disparity it has there) instead of by the shift, released
//!   where the previous view seen through the motion disagrees with the current one, with twice the prior's weight,
//!   both terms of the model in both views (the left one iteration fewer, the right one iteration) and each
//!   pixel's labels kept to a band around the carried answer.
//!
//! A moving or travelling frame's answer then moves half-way to the carried one wherever the two agree within 1 px
//! and the frames agree ([`average::carry_answer`]): each surface keeps a running mean of its disparity.
//!
//! Frames run this way only when the pipeline runs whole and at full resolution (no tiles, `downscale` 1);
//! otherwise each frame is matched alone. The search range is held from the first frame (a measured range is
//! measured once). Measurements: docs/tuning-log.md, "Stereo video".

mod average;
mod egomotion;
pub(crate) mod exposure;
pub(crate) mod motion;
mod track;

use crate::error::Result;
use crate::image::{Plane, StereoPair};
use crate::params::Params;
use crate::pipeline::{self, FramePrior, FrameViews, PipelineOutput, RunOptions};
use average::{AnswerMean, ViewMeans, carry_answer};
use egomotion::Motion;
pub use exposure::Exposure;
use motion::Shift;
use track::{Reach, Tracker};

/// Beyond this share of the image's contrast left unexplained by the shift, the frame shows another scene.
const CUT_UNEXPLAINED: f64 = 0.5;

/// Frames with no shift are of a still camera only where the noise explains their difference: beyond this share of
/// the image's contrast something in the scene or the camera's view changed (a zoom, a forward motion, light).
const STILL_UNEXPLAINED: f64 = 0.05;

/// The prior is released where the shifted frames' 5 × 5 mean grey difference exceeds this many times what two
/// frames' noise gives (plus half a grey level of quantisation).
const RELEASE_NOISE_MULTIPLE: f32 = 2.0;

/// Mean-field iterations of a moving frame's right view, which runs with the local term alone: it serves the
/// left-right check only, and one iteration of its own cost (the prior carried over) with its 4-neighbour term finds
/// the pixels whose left answer it contradicts nearly as well as the configured inference (pans and moving objects
/// within 0.6 % of the accuracy, without building the right view's lattice; the tuning log's "Stereo video: the
/// temporal model").
const RIGHT_ITERATIONS: usize = 1;

/// A pan's left view: after its first iteration, the pixels at least this sure of their label settle and the
/// second iteration updates only the others (a fifth to a quarter of a pan's pixels). The prior carried from the
/// previous frame has placed the settled ones, so a second update would barely move them: the answers are as good
/// for less time, and 0.9 or 0.99 do the same. Not on a travelling frame: there the carried prior weighs twice and
/// makes pixels sure early, and the later iterations are what moves them toward the camera's motion (figures: the
/// tuning log, "Settled pixels on a pan").
const SETTLED_CONFIDENCE: f32 = 0.95;

/// How a frame was matched.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameKind {
    /// As a first frame: the first of a sequence, or after a scene cut or a change of size.
    First,
    /// After a scene cut: the previous frames were forgotten and it ran as a first frame.
    Cut,
    /// A still camera: on the running means of the views, its answer folded into theirs.
    Still {
        /// The frames the views' means hold at most (the pixel that has held still longest).
        frames: u16,
    },
    /// A moving camera: with the previous answer, moved by the shift, as its prior.
    Moving {
        /// The shift, in pixels: this frame's (x, y) shows what the previous one showed at (x + dx, y + dy).
        dx: i32,
        /// See `dx`.
        dy: i32,
    },
    /// A camera moving in depth or turning, whose view no global shift explains (a car driving forward): with the
    /// previous answer carried by the camera's 3D motion, fitted to points tracked between the frames, as its prior.
    Travelling {
        /// The tracked points the motion explains.
        tracks: u32,
    },
}

/// What the model keeps from one frame to the next.
#[derive(Clone, Debug, Default)]
pub(crate) struct State {
    /// The previous frame: its left view in grey, the answer given for it, its range.
    previous: Option<Previous>,
    /// The running means of a still camera's views and answers.
    still: Option<(ViewMeans, AnswerMean)>,
    /// What the last moving frame's inference left for the next one's.
    spare: Spare,
}

/// The large allocations (cost volumes, marginals) one moving frame hands to the next, which takes its volumes in
/// them instead of allocating, page-faulting and zeroing them again (a few per cent of a KITTI frame's time). At
/// most 1.5 volumes' worth, so that the frame's peak does not rise: more would sit idle beside the volumes the frame
/// allocates (two volumes kept raised a KITTI frame's peak by 12 %, the lattice's buffers kept a pan's by 18 %).
/// Kept only from one moving frame to the next: any other frame frees them before it runs. Scratch, not state: a
/// copy of the state starts without them.
#[derive(Debug, Default)]
struct Spare(crate::meanfield::Buffers);

impl Clone for Spare {
    fn clone(&self) -> Self {
        Spare::default()
    }
}

#[derive(Clone, Debug)]
struct Previous {
    grey: Plane<f32>,
    answer: PipelineOutput,
    ndisp: usize,
}

impl State {
    /// Forgets every frame.
    pub(crate) fn reset(&mut self) {
        *self = State::default();
    }

    /// The range the sequence holds (the first frame's), if a frame has been matched.
    pub(crate) fn held_range(&self) -> Option<usize> {
        self.previous.as_ref().map(|p| p.ndisp)
    }
}

/// Matches `pair` as the next frame of the sequence `state` remembers (see the module doc), and remembers it.
/// Returns the answer, how the frame was matched and the exposure change compensated in it (`None`: none).
///
/// # Errors
/// As [`crate::pipeline::run`].
pub(crate) fn match_frame(
    state: &mut State,
    params: &Params,
    pair: &StereoPair,
    options: &RunOptions<'_>,
) -> Result<(PipelineOutput, FrameKind, Option<Exposure>)> {
    (options.on_stage)("motion");
    let start = std::time::Instant::now();
    let grey = pair.left.to_grey();
    let noise = crate::condition::channel_noise(&pair.left);
    let previous = state.previous.take().filter(|p| p.grey.dims() == grey.dims() && p.ndisp == pair.ndisp);
    let seen = previous.is_some();
    let compared = previous.as_ref().map(|p| compare(&p.grey, &grey));
    let unexplained = compared.as_ref().map_or(0.0, |c| motion::unexplained(c.shift, &grey, noise));
    let cut = unexplained > CUT_UNEXPLAINED;
    // The comparison with the previous frame (and for a moving camera, the previous answer carried into this one),
    // timed as a stage of the frames that have one.
    let mut motion_time = seen.then(|| start.elapsed());
    let mut spare = std::mem::take(&mut state.spare);
    let (mut out, kind, exposure) = match (previous, compared) {
        (Some(prev), Some(c)) if !cut && (c.shift.dx, c.shift.dy) == (0, 0) && unexplained < STILL_UNEXPLAINED => {
            drop(spare);
            let (out, frames, exposure) = still_frame(state, params, pair, noise, prev, options)?;
            (out, FrameKind::Still { frames }, exposure)
        }
        (Some(prev), Some(c)) if !cut => {
            state.still = None;
            let (carried, released, motion) = carry_previous(&prev, &c, &grey, noise, unexplained);
            motion_time = Some(start.elapsed());
            let (before, held) = (carried.disparity.clone(), released.clone());
            let mut out = moving_frame(params, pair, (carried, released), motion.is_some(), options, &mut spare.0)?;
            spare.0.trim(3 * pair.left.len() * pair.ndisp / 2);
            state.spare = spare;
            carry_answer(&mut out.disparity, &before, &held);
            let kind = match motion {
                Some(m) => FrameKind::Travelling { tracks: m.inliers as u32 },
                None => FrameKind::Moving { dx: c.shift.dx as i32, dy: c.shift.dy as i32 },
            };
            (out, kind, c.exposure)
        }
        _ => {
            drop(spare);
            state.still = None;
            let out = pipeline::run_with(params, pair, options)?;
            state.still = Some((ViewMeans::start(&pair.left, &pair.right), AnswerMean::start(&out.disparity)));
            (out, if seen { FrameKind::Cut } else { FrameKind::First }, None)
        }
    };
    if let Some(t) = motion_time {
        out.timings.stages.insert(0, ("motion", t));
    }
    state.previous = Some(Previous { grey, answer: out.clone(), ndisp: pair.ndisp });
    Ok((out, kind, exposure))
}

/// The previous left view (grey) compared with the current one.
struct Compared {
    /// The shift between them, under the exposure change.
    shift: Shift,
    /// The exposure change from the previous view to the current one.
    exposure: Option<Exposure>,
    /// The previous view under that change (`None`: the view as it is).
    reference: Option<Plane<f32>>,
}

/// Compares two frames' left views: the shift, the exposure change fitted under it, and with a change the shift
/// searched again between the compensated previous view and the current one.
fn compare(prev: &Plane<f32>, cur: &Plane<f32>) -> Compared {
    let shift = motion::global_shift(prev, cur);
    match exposure::fit(prev, cur, shift) {
        None => Compared { shift, exposure: None, reference: None },
        Some(e) => {
            let reference = e.apply_plane(prev);
            Compared { shift: motion::global_shift(&reference, cur), exposure: Some(e), reference: Some(reference) }
        }
    }
}

/// A still camera's frame: the pipeline on the views' running means, the answer folded into the answers' mean,
/// which starts again where the scene changed ([`average::Folded::changed_for`], at the previous answer's matches).
/// A frame that leaves the means exactly as they were (a clean camera's repeated frame) keeps the previous answer.
/// Returns the answer, the frames the means hold at most and the left view's exposure change against its mean.
fn still_frame(
    state: &mut State,
    params: &Params,
    pair: &StereoPair,
    noise: f32,
    prev: Previous,
    options: &RunOptions<'_>,
) -> Result<(PipelineOutput, u16, Option<Exposure>)> {
    let (views, answers, out, exposure) = match state.still.take() {
        Some((mut views, mut answers)) => {
            let exposure = views.follow_exposure(&pair.left, &pair.right);
            let folded = views.fold(&pair.left, &pair.right, noise);
            let out = if folded.moved || exposure.is_some() {
                let changed = folded.changed_for(&prev.answer.disparity);
                let mut frames = views.left_counts().clone();
                frames.data.iter_mut().zip(&changed.data).filter(|(_, c)| **c).for_each(|(n, _)| *n = 1);
                let means = StereoPair::borrowed(&views.left, &views.right, pair.ndisp)?;
                let mut out = pipeline::run_with(params, &means, options)?;
                answers.fold(&out.disparity, &frames);
                out.disparity = answers.mean.clone();
                out
            } else {
                PipelineOutput { timings: Default::default(), ..prev.answer }
            };
            (views, answers, out, exposure)
        }
        // The camera has just stopped: this frame starts the means.
        None => {
            let out = pipeline::run_with(params, pair, options)?;
            (ViewMeans::start(&pair.left, &pair.right), AnswerMean::start(&out.disparity), out, None)
        }
    };
    let frames = views.left_counts().data.iter().copied().max().unwrap_or(1);
    state.still = Some((views, answers));
    Ok((out, frames, exposure))
}

/// The previous answer carried into the current frame, and where it is released (the frames disagree there):
/// moved by the camera's 3D motion where a global shift does not explain the tracked points
/// ([`beyond_shift`]; the motion returned; not tried where the shift leaves no more unexplained than noise does),
/// else by the shift.
fn carry_previous(
    prev: &Previous,
    compared: &Compared,
    grey: &Plane<f32>,
    noise: f32,
    unexplained: f64,
) -> (PipelineOutput, Plane<bool>, Option<Motion>) {
    let limit = RELEASE_NOISE_MULTIPLE * (crate::imgproc::noise::GREY_DIFFERENCE_PER_SIGMA as f32 * noise + 0.5);
    let reference = compared.reference.as_ref().unwrap_or(&prev.grey);
    // Where the shift leaves no more unexplained than a still camera's noise does (a pan without parallax), no
    // motion can explain clearly more: the points are not tracked.
    let beyond = (unexplained >= STILL_UNEXPLAINED)
        .then(|| beyond_shift(reference, grey, &prev.answer.disparity, compared.shift, noise))
        .flatten();
    match beyond {
        Some(m) => {
            let (answer, moved) = egomotion::carry(&prev.answer, reference, &m);
            (answer, egomotion::disagreement(&moved, grey, limit, m.tolerance), Some(m))
        }
        None => (
            motion::shift_answer(&prev.answer, compared.shift),
            motion::disagreement(reference, grey, compared.shift, limit),
            None,
        ),
    }
}

/// A prior carried by a 3D motion weighs this many times the coarse prior's rule: it is the whole answer of a
/// frame a fraction of a second before, not a coarse run's (on KITTI frames weight 1 left the answers about as
/// inconsistent from frame to frame as without a prior, 2 brought them level with the independent run's).
/// Its frame also runs both terms in both views: the right view's local term alone, which serves a pan, cost a
/// driving camera 1.3 % of photometric error and 5 % of consistency.
const TRAVELLING_PRIOR_SCALE: f32 = 2.0;

/// Mean-field iterations of a travelling frame's right view, with both terms, in label bands around the carried
/// answer warped across: it serves the left-right check only, and one iteration of the fully connected term reaches
/// across the image (on KITTI frames the left answer's photometric error was no worse than with the configured
/// three, for about 15 % less time; figures: the tuning log, "A travelling frame's right view with one iteration").
const TRAVELLING_RIGHT_ITERATIONS: usize = 1;

/// Mean-field iterations of a travelling frame's left view: one fewer than configured, as on a pan. The carried
/// prior, weighing twice and with the labels kept to bands around it, has placed the pixels: on the 51 KITTI frames
/// the third iteration moved the photometric error by 0.05 % and the consistency by 0.6 %, for 6 % of the frame's
/// time, and on the synthetic dolly with exact truth the frames are better with two (tuning log, "A travelling
/// frame's left view one iteration fewer"). Not where the inference runs on grouped labels with the local term alone
/// (`local_alone`, a large image): there an iteration carries the answer one pixel further, not across the image,
/// and the configured count stays (KITTI enlarged 1.5× lost 2 % of its consistency with one fewer).
fn travelling_left_iterations(params: &Params, local_alone: bool) -> usize {
    let configured = params.meanfield.iterations;
    if local_alone { configured } else { configured.saturating_sub(1).max(1) }
}

/// The fewest tracked points a motion must explain, and the share of all tracked points.
const MIN_TRACKS: usize = 24;
const MIN_TRACK_SHARE: f64 = 0.5;

/// The camera's 3D motion between the frames, where it explains clearly more of the tracked points than the global
/// shift does (by a quarter more, and 5 % of all points): a pan keeps its shift. The points are tracked from where
/// the shift puts them, the motion fitted, then tracked again from where the motion puts them (the near scene moves
/// further than a search from the shift reaches) and the motion fitted again.
fn beyond_shift(
    reference: &Plane<f32>,
    grey: &Plane<f32>,
    disparity: &Plane<f32>,
    shift: Shift,
    noise: f32,
) -> Option<Motion> {
    let tracker = Tracker::new(reference, grey, disparity, crate::imgproc::noise::GREY_NOISE_PER_SIGMA * noise);
    let (dx, dy) = (shift.dx as f64, shift.dy as f64);
    let tracks = tracker.follow(|x, y, _| Some((x - dx, y - dy)), Reach::Wide);
    let n = tracks.len() as f64;
    let first = egomotion::fit(&tracks, egomotion::INLIER_PX)?;
    let again = tracker.follow(|x, y, d| first.apply(x, y, d).map(|(x, y, _)| (x, y)), Reach::Near);
    let m = egomotion::fit(&again, egomotion::INLIER_PX).filter(|m| m.inliers >= first.inliers).unwrap_or(first);
    // Judged within what the tracks' precision allows, the shift as well as the motion.
    let tolerance = egomotion::tolerance(&m, &again);
    let m = if tolerance > m.tolerance {
        egomotion::fit(&again, tolerance).filter(|t| t.inliers >= m.inliers).unwrap_or(m)
    } else {
        m
    };
    let by_shift = tracks.iter().filter(|t| (t.tx - (t.x - dx)).hypot(t.ty - (t.y - dy)) <= m.tolerance).count() as f64;
    let explained = m.inliers as f64;
    (m.inliers >= MIN_TRACKS && explained >= MIN_TRACK_SHARE * n && explained > 1.25 * by_shift + 0.05 * n).then_some(m)
}

/// A moving camera's frame: the previous answer, carried into it, as the prior (see the module doc). Carried by
/// a 3D motion (`travelling`), the prior weighs [`TRAVELLING_PRIOR_SCALE`] times more, the left view runs both terms
/// for [`travelling_left_iterations`] and the right view [`TRAVELLING_RIGHT_ITERATIONS`], and each pixel's inference is
/// kept to a band of labels around the carried answer (the tiles' label bands: the answers within the fully
/// connected kernel's reach, ± the prior's margin and truncation, and the pixel's own best label), which makes the
/// answers more consistent from frame to frame. Only the bands are stored (about a third of a KITTI frame's
/// labels; `meanfield::packed`), so the update reads a third of the memory. On a larger image, whose inference groups
/// its labels, the bands are grouped with them: the frame takes the grouped run's time and memory, not every label's.
/// The frame's large allocations come from `buffers` (what the moving frame before it left) and go back there.
fn moving_frame(
    params: &Params,
    pair: &StereoPair,
    (mut carried, released): (PipelineOutput, Plane<bool>),
    travelling: bool,
    options: &RunOptions<'_>,
    buffers: &mut crate::meanfield::Buffers,
) -> Result<PipelineOutput> {
    // Where the frames disagree the carried segments do not hold either: those pixels start on the grid's cells.
    if let Some(s) = &mut carried.segmentation {
        s.release(&released.data);
    }
    // On grouped labels with the local term alone (a large image) the answer stays close to the carried prior, so
    // agreeing with it says little: such a frame keeps the check's verdict (KITTI enlarged 1.5×: consistency 3.78 →
    // 5.18 with the carried answers kept) and the configured iterations.
    let local_alone = travelling && params.for_image(pair.left.width * pair.left.height).grouped_local_alone();
    let from = FramePrior {
        vertical_offset: carried.vertical_offset,
        answer: carried,
        released: Some(released),
        weight_scale: if travelling { TRAVELLING_PRIOR_SCALE } else { 1.0 },
        views: Some(match travelling {
            true => FrameViews {
                iterations: [travelling_left_iterations(params, local_alone), TRAVELLING_RIGHT_ITERATIONS],
                right_local_only: false,
                settle_at: None,
                keep_carried: !local_alone,
            },
            false => FrameViews {
                iterations: [params.meanfield.iterations.saturating_sub(1).max(1), RIGHT_ITERATIONS],
                right_local_only: true,
                settle_at: Some(SETTLED_CONFIDENCE),
                keep_carried: false,
            },
        }),
        in_bands: travelling,
    };
    pipeline::run_with_prior(params, pair, from, options, buffers)
}
