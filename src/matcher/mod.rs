//! [`Matcher`]: the library's front door. Built once from a configuration, it matches pairs: decoded images
//! ([`Matcher::match_pair`]) or image files ([`Matcher::match_files`], whose size is checked against the memory
//! limit from the headers, before decoding). What a front end asks besides the match is done inside it too: raw
//! views rectified first ([`Matcher::with_rectification`]), the pair checked ([`Matcher::with_checks`]), the
//! unreliable pixels dropped ([`Matcher::with_min_confidence`]). Every front end (`jem`, `jem sequence`,
//! `jem batch`, the Python module) matches through it.

use std::borrow::Cow;
use std::path::Path;
use std::sync::Arc;
use std::time::Instant;

use crate::error::Result;
use crate::image::RgbImage;
use crate::params::Params;
use crate::pipeline::{self, PipelineOutput};
use crate::rectify::Rectification;
use crate::setup::memory::MemoryBudget;
use crate::setup::strategy::Strategy;
use crate::setup::{self, NdispSource, Plan};
pub use crate::temporal::{Exposure, FrameKind};

mod output;
pub use output::{Output, Rectified, RunPlan, Tiles};

/// Matches rectified stereo pairs with one configuration.
///
/// ```
/// use jem::{Matcher, NdispSource, Params, RgbImage};
/// let (left, right) = (RgbImage::new(64, 32), RgbImage::new(64, 32));
/// let mut matcher = Matcher::new(Params::default())?.with_ndisp(NdispSource::Given(16));
/// let out = matcher.match_pair(&left, &right)?;
/// assert_eq!(out.disparity.dims(), (64, 32));
/// assert_eq!(out.plan.ndisp, 16);
/// # Ok::<(), jem::Error>(())
/// ```
#[derive(Clone, Debug)]
pub struct Matcher {
    params: Params,
    ndisp: NdispSource,
    max_memory_bytes: u64,
    budget: Option<Arc<MemoryBudget>>,
    /// The frames of a sequence, remembered (`with_temporal`); `None`: each pair alone.
    temporal: Option<crate::temporal::State>,
    /// Whether each match computes its confidence map (`with_confidence`).
    confidence: bool,
    /// The smallest disparity searched (`with_min_disp`).
    min_disp: usize,
    /// Raw views are rectified with this before matching (`with_rectification`).
    rectification: Option<Rectification>,
    /// Whether each match checks the pair (`with_checks`).
    checks: bool,
    /// Pixels of a lower confidence are dropped from the map (`with_min_confidence`).
    min_confidence: Option<f32>,
}

/// What a match reports while it runs (see [`Matcher::match_pair_with`]).
#[derive(Clone, Copy, Debug)]
pub enum Progress<'a> {
    /// The range is known and the run set up; the pipeline starts.
    Planned(&'a RunPlan),
    /// A stage of the pipeline starts (its name, as [`crate::Timings`] reports it).
    Stage(&'a str),
}

impl Matcher {
    /// A matcher with these parameters, the range measured on each pair and 80 % of the machine's memory as the
    /// limit.
    ///
    /// # Errors
    /// [`crate::error::Error::InvalidParam`] if `params` do not validate.
    pub fn new(params: Params) -> Result<Matcher> {
        params.validate()?;
        Ok(Matcher {
            params,
            ndisp: NdispSource::Unknown,
            max_memory_bytes: default_memory_limit(),
            budget: None,
            temporal: None,
            confidence: true,
            min_disp: 0,
            rectification: None,
            checks: false,
            min_confidence: None,
        })
    }

    /// Where the search range comes from ([`NdispSource`]; default: measured on each pair).
    pub fn with_ndisp(mut self, ndisp: NdispSource) -> Matcher {
        self.ndisp = ndisp;
        self
    }

    /// Searches the disparities `min_disp..min_disp + ndisp − 1` instead of `0..ndisp − 1` (OpenCV SGBM's
    /// `minDisparity`; for a scene that starts far from infinity, say a close-range rig): the left view's first
    /// `min_disp` columns, which match nothing at such disparities, come out invalid; the range source
    /// ([`Matcher::with_ndisp`]) gives the number of disparities, and a measured range is measured from `min_disp`
    /// up. 0 (the default) is the ordinary search. A pair narrower than `min_disp + 2` pixels is refused when
    /// matched. How: `src/min_disp.rs`.
    pub fn with_min_disp(mut self, min_disp: usize) -> Matcher {
        self.min_disp = min_disp;
        self
    }

    /// The smallest disparity searched.
    pub fn min_disp(&self) -> usize {
        self.min_disp
    }

    /// The confidence below which pixels are dropped from the map ([`Matcher::with_min_confidence`]), if any.
    pub fn min_confidence(&self) -> Option<f32> {
        self.min_confidence
    }

    /// Rectifies each pair with `rectification` before matching it, as `jem rectify` does: the pairs given are the
    /// raw views (of the rectification's size; another size is an error), the outputs are of the rectified left view
    /// ([`Output::rectified`]), and the search range, the pair check and the temporal model all see the rectified
    /// pair. Its warnings ([`Rectification::warnings`]) are the caller's to show.
    pub fn with_rectification(mut self, rectification: Rectification) -> Matcher {
        self.rectification = Some(rectification);
        self
    }

    /// [`Matcher::with_rectification`] for a matcher in use, say for views of another size (`None`: no more).
    pub fn set_rectification(&mut self, rectification: Option<Rectification>) {
        self.rectification = rectification;
    }

    /// The rectification applied before matching, if any.
    pub fn rectification(&self) -> Option<&Rectification> {
        self.rectification.as_ref()
    }

    /// Whether each match also checks the pair for what would make any disparity map of it wrong
    /// ([`Output::checks`], [`Output::warnings`]; default: no). The check reads the confidence map when there is
    /// one (a region of repetitive texture matched doubtfully).
    pub fn with_checks(mut self, on: bool) -> Matcher {
        self.checks = on;
        self
    }

    /// Keeps in the map only the pixels whose confidence is `min_confidence` or more (the others invalid, `inf`;
    /// [`Output::reliable_disparity`]); the confidence is then computed whatever [`Matcher::with_confidence`]
    /// says, and the pair check ([`Matcher::with_checks`]) reads the map before the bound.
    ///
    /// # Errors
    /// [`crate::Error::InvalidParam`] naming `min_confidence` when it is not a confidence from 0 to 1.
    pub fn with_min_confidence(mut self, min_confidence: f32) -> Result<Matcher> {
        Output::check_min_confidence("min_confidence", min_confidence)?;
        self.min_confidence = Some(min_confidence);
        Ok(self)
    }

    /// The memory limit in bytes: a pair whose run would need more runs in tiles, and one that fits neither way is
    /// refused before anything large is allocated ([`crate::error::Error::OutOfMemory`]).
    pub fn with_max_memory(mut self, bytes: u64) -> Matcher {
        self.max_memory_bytes = bytes;
        self
    }

    /// Shares a memory budget with other matchers running at the same time ([`Matcher::match_files`] waits while
    /// the others hold so much that its share would not fit). The limit becomes the budget's total.
    pub fn with_budget(mut self, budget: Arc<MemoryBudget>) -> Matcher {
        self.max_memory_bytes = budget.total();
        self.budget = Some(budget);
        self
    }

    /// Remembers the pairs it matches as the frames of one stereo sequence, in order (see the temporal model in
    /// the crate's docs, and docs/video.md): a still camera's frames are matched on the running means of the views
    /// and their answers settle; a moving camera's frame takes the previous answer, moved by the camera's shift, as
    /// its prior instead of the coarse chain; a scene cut is detected and forgets the past. The search range of
    /// the first frame is held for the sequence. `false` matches each pair alone (the default).
    pub fn with_temporal(mut self, on: bool) -> Matcher {
        self.temporal = on.then(Default::default);
        self
    }

    /// Whether each match computes its confidence map ([`Output::confidence`]; default: yes). It costs a few per
    /// cent of a run; `false` saves that when only the disparity map is wanted (a bound on it,
    /// [`Matcher::with_min_confidence`], computes it all the same).
    pub fn with_confidence(mut self, on: bool) -> Matcher {
        self.confidence = on;
        self
    }

    /// [`Matcher::with_confidence`] for a matcher in use (one that remembers frames keeps them).
    pub fn set_confidence(&mut self, on: bool) {
        self.confidence = on;
    }

    /// Forgets the frames matched so far (a new sequence starts with the next pair).
    pub fn reset(&mut self) {
        if let Some(state) = &mut self.temporal {
            state.reset();
        }
    }

    /// The parameters.
    pub fn params(&self) -> &Params {
        &self.params
    }

    /// Where the search range comes from.
    pub fn ndisp(&self) -> NdispSource {
        self.ndisp
    }

    /// The memory limit in bytes.
    pub fn max_memory(&self) -> u64 {
        self.max_memory_bytes
    }

    /// Whether the matcher remembers the pairs as the frames of a sequence ([`Matcher::with_temporal`]).
    pub fn is_temporal(&self) -> bool {
        self.temporal.is_some()
    }

    /// The left view's disparity map of a rectified pair, or of a raw one with [`Matcher::with_rectification`]
    /// (and the rest of [`Output`]).
    ///
    /// # Errors
    /// [`crate::error::Error::SizeMismatch`] or [`crate::error::Error::InputImage`] for unequal, empty or 1-pixel-wide
    /// images (or views not of the rectification's size),
    /// [`crate::error::Error::InvalidParam`] for an impossible range or parameters the image cannot hold,
    /// [`crate::error::Error::OutOfMemory`] when the run fits the limit neither in one piece nor in tiles.
    pub fn match_pair(&mut self, left: &RgbImage, right: &RgbImage) -> Result<Output> {
        self.match_pair_with(left, right, &|_| {})
    }

    /// [`Matcher::match_pair`], reporting its progress to `on_progress`.
    ///
    /// # Errors
    /// As [`Matcher::match_pair`].
    pub fn match_pair_with(
        &mut self,
        left: &RgbImage,
        right: &RgbImage,
        on_progress: &dyn Fn(Progress<'_>),
    ) -> Result<Output> {
        let (left, right) = self.rectify(left, right)?;
        let (l, r) = self.cut(&left, &right)?;
        let plan = setup::plan_match(&l, &r, self.source(), &self.params, self.max_memory_bytes)?;
        let out = self.run(&plan, on_progress)?;
        let out = self.finish(out, &left, &right)?;
        Ok(self.with_views(out, left))
    }

    /// The pair as the matcher matches it: rectified when it rectifies ([`Matcher::with_rectification`]), else as
    /// given.
    fn rectify<'p>(&self, left: &'p RgbImage, right: &'p RgbImage) -> Result<(Cow<'p, RgbImage>, Cow<'p, RgbImage>)> {
        match &self.rectification {
            Some(rect) => {
                let (l, r) = rect.rectify_pair(left, right)?;
                Ok((Cow::Owned(l), Cow::Owned(r)))
            }
            None => Ok((Cow::Borrowed(left), Cow::Borrowed(right))),
        }
    }

    /// What a match does after the run on the pair it matched: the pair check, then the confidence bound.
    fn finish(&self, mut out: Output, left: &RgbImage, right: &RgbImage) -> Result<Output> {
        if self.checks {
            out.checks = Some(self.check_pair(left, right, &out));
        }
        if let Some(c) = self.min_confidence {
            out.disparity = out.reliable_disparity(c)?;
        }
        Ok(out)
    }

    /// `out` with the left view it matched when the matcher rectified it ([`Matcher::rectify`]; nothing for a pair
    /// matched as given).
    fn with_views(&self, mut out: Output, left: Cow<'_, RgbImage>) -> Output {
        if let (Cow::Owned(left), Some(rect)) = (left, &self.rectification) {
            out.rectified = Some(Rectified { left, calibration: rect.calibration_path().to_path_buf() });
        }
        out
    }

    /// The pair as the pipeline matches it: as it is, or cut for a search from `min_disp` (`src/min_disp.rs`).
    fn cut<'p>(&self, left: &'p RgbImage, right: &'p RgbImage) -> Result<(Cow<'p, RgbImage>, Cow<'p, RgbImage>)> {
        if self.min_disp == 0 {
            return Ok((Cow::Borrowed(left), Cow::Borrowed(right)));
        }
        if left.dims() != right.dims() {
            return Err(crate::error::Error::SizeMismatch { left: left.dims(), right: right.dims() });
        }
        let (l, r) = crate::min_disp::cut_pair(left, right, self.min_disp)?;
        Ok((Cow::Owned(l), Cow::Owned(r)))
    }

    /// The range source of the next pair: a remembered sequence holds its first frame's range.
    fn source(&self) -> NdispSource {
        match (self.temporal.as_ref().and_then(|t| t.held_range()), self.ndisp) {
            (Some(held), NdispSource::Stated(_) | NdispSource::Unknown) => NdispSource::Given(held),
            _ => self.ndisp,
        }
    }

    /// Checks, before anything is allocated, that a pair of views of these sizes (width, height) can be matched:
    /// equal sizes, at least 2 pixels wide, and within the memory limit with `input_bytes` for holding the input
    /// (the range measurement and the run included, as [`Matcher::read_pair`] checks from the files' headers). For
    /// callers that convert their own pixels ([`RgbImage::from_channels`]): check first, then convert.
    ///
    /// # Errors
    /// [`crate::error::Error::SizeMismatch`], [`crate::error::Error::InputImage`] for empty or 1-pixel-wide views,
    /// [`crate::error::Error::OutOfMemory`] when the pair cannot fit.
    pub fn check_size(&self, left: (usize, usize), right: (usize, usize), input_bytes: u64) -> Result<()> {
        let (w, h) = left;
        if left != right {
            return Err(crate::error::Error::SizeMismatch { left, right });
        }
        if w == 0 || h == 0 {
            return Err(crate::error::Error::bad_image("the images are empty (0 pixels)"));
        }
        if w < 2 {
            return Err(crate::error::Error::bad_image(format!(
                "the images are {w}x{h}; a stereo pair must be at least 2 pixels wide"
            )));
        }
        crate::min_disp::check(w, self.min_disp)?;
        let header = crate::io::ImageHeader { width: w, height: h, load_bytes: input_bytes };
        setup::check_before_decode(&header, self.ndisp, &self.params, self.max_memory_bytes).map(|_| ())
    }

    /// The search range this matcher would match `left`/`right` with, and whether it is measured on them (see
    /// [`NdispSource`]).
    ///
    /// # Errors
    /// As [`Matcher::match_pair`], for the range.
    pub fn search_range(&self, left: &RgbImage, right: &RgbImage) -> Result<(usize, bool)> {
        let (left, right) = self.rectify(left, right)?;
        let (left, right) = self.cut(&left, &right)?;
        let plan = setup::plan_match(&left, &right, self.ndisp, &self.params, self.max_memory_bytes)?;
        Ok((plan.pair.ndisp, plan.ndisp_measured))
    }

    /// Reads a pair of image files (PNG, PPM/PGM, JPEG, BMP, TIFF or WebP; 8 or 16 bit) as the matcher would
    /// match them: both
    /// headers are checked against the memory limit first (the loading, the range measurement and the run), and
    /// neither image is decoded when the pair cannot fit.
    ///
    /// # Errors
    /// [`crate::error::Error::Io`] or [`crate::error::Error::Image`] naming the file,
    /// [`crate::error::Error::SizeMismatch`] from the headers, [`crate::error::Error::OutOfMemory`] as above.
    pub fn read_pair(&self, left: &Path, right: &Path) -> Result<(RgbImage, RgbImage)> {
        let header = crate::io::png::read_pair_header(left, right)?;
        setup::check_before_decode(&header, self.ndisp, &self.params, self.max_memory_bytes)?;
        crate::io::png::load_rgb_pair_within(left, right, self.max_memory_bytes)
    }

    /// Reads and matches a pair of image files ([`Matcher::read_pair`], then [`Matcher::match_pair_with`]). With
    /// a shared budget ([`Matcher::with_budget`]) it holds what the loading and the range measurement need before
    /// decoding, and what the run needs before it starts, waiting while other matchers hold too much.
    ///
    /// # Errors
    /// As [`Matcher::read_pair`] and [`Matcher::match_pair`].
    pub fn match_files(&mut self, left: &Path, right: &Path, on_progress: &dyn Fn(Progress<'_>)) -> Result<Output> {
        let header = crate::io::png::read_pair_header(left, right)?;
        let need = setup::check_before_decode(&header, self.ndisp, &self.params, self.max_memory_bytes)?;
        let budget = self.budget.clone();
        let mut held = budget.as_deref().map(|b| wait_for(b, need, on_progress));
        on_progress(Progress::Stage("loading"));
        let raw = crate::io::png::load_rgb_pair_within(left, right, self.max_memory_bytes)?;
        let (left, right) = self.rectify(&raw.0, &raw.1)?;
        let (l, r) = self.cut(&left, &right)?;
        let plan = setup::plan_match(&l, &r, self.source(), &self.params, self.max_memory_bytes)?;
        if let Some(budget) = budget.as_deref() {
            let (w, h) = l.dims();
            let run = plan.strategy.memory_bytes(w, h, plan.pair.ndisp, &self.params).max(header.load_bytes);
            if run != need {
                drop(held.take());
                held = Some(wait_for(budget, run, on_progress));
            }
        }
        let out = self.run(&plan, on_progress);
        drop(held);
        let out = self.finish(out?, &left, &right)?;
        Ok(self.with_views(out, left))
    }

    /// Checks a matched pair for what would make any disparity map of it wrong ([`crate::PairCheck`]: swapped
    /// views, a vertical offset beyond the alignment, a range over half the width, no texture, an exposure or focus
    /// difference beyond the front end; with its confidence map, a large region of repetitive texture whose answer
    /// is doubtful); `out` is the match's output (its measured range and noise), `left`, `right` the pair matched
    /// (rectified, when the matcher rectified it).
    ///
    /// The swap check runs within what the memory limit leaves beside what the caller holds by then (the pair, the
    /// output maps and the check's grey views: 41 bytes a pixel): given the whole limit, it took a downscaled run
    /// past it.
    fn check_pair(&self, left: &RgbImage, right: &RgbImage, out: &Output) -> crate::PairCheck {
        let width = left.width().max(1) as f32;
        let range_share = out.plan.ndisp_measured.then(|| (out.plan.min_disp + out.plan.ndisp) as f32 / width);
        let noise = out.measured.map(|m| (m.stats.sigma(), m.stats.gain[0]));
        let held = CHECK_HELD_BYTES_PER_PX.saturating_mul(left.len() as u64);
        let budget = self.max_memory_bytes.saturating_sub(held);
        let mut check = crate::diagnose::check_pair(left, right, &self.params.cost, noise, range_share, budget);
        let given = (!out.plan.ndisp_measured).then_some([out.plan.min_disp, out.plan.ndisp]);
        let limit = crate::setup::range::search_limit(None, left.width());
        let measure = || crate::setup::range::find_ndisp(left, right, limit, &self.params.cost, budget).ok();
        crate::diagnose::check_answer(&mut check, left, right, &out.disparity, given, measure);
        if let Some(confidence) = &out.confidence {
            crate::diagnose::check_repetition(&mut check, left, &out.disparity, confidence, out.plan.ndisp);
        }
        check
    }

    /// Runs a planned pair.
    fn run(&mut self, plan: &Plan<'_>, on_progress: &dyn Fn(Progress<'_>)) -> Result<Output> {
        let (w, h) = plan.pair.left.dims();
        // Owned: the temporal state below borrows `self` mutably.
        let params = plan.params(&self.params).into_owned();
        let run_plan = RunPlan {
            ndisp: plan.pair.ndisp,
            min_disp: self.min_disp,
            ndisp_measured: plan.ndisp_measured,
            tiles: match plan.strategy {
                Strategy::Whole => None,
                Strategy::Tiled(t) => Some(Tiles { core_px: t.core_px, coarse_factor: t.coarse_factor }),
            },
            memory_bytes: plan.strategy.memory_bytes(w, h, plan.pair.ndisp, &params),
            working_factor: plan.working_factor,
        };
        on_progress(Progress::Planned(&run_plan));
        let on_stage = |stage: &str| on_progress(Progress::Stage(stage));
        let confidence = self.confidence || self.min_confidence.is_some();
        let options = pipeline::RunOptions { on_stage: &on_stage, confidence };
        let start = Instant::now();
        // A remembered sequence runs its frames through the temporal model where the pipeline runs whole and at
        // full resolution; any other frame runs alone and starts the sequence again.
        let temporal = self.temporal.as_mut();
        let (out, frame, exposure) = match (plan.strategy, temporal) {
            (Strategy::Whole, Some(state)) if params.downscale == 1 => {
                let (out, kind, exposure) = crate::temporal::match_frame(state, &params, &plan.pair, &options)?;
                (out, Some(kind), exposure)
            }
            (strategy, temporal) => {
                let alone = temporal.is_some().then_some(FrameKind::First);
                if let Some(state) = temporal {
                    state.reset();
                }
                let out = match strategy {
                    Strategy::Whole => pipeline::run_with(&params, &plan.pair, &options)?,
                    Strategy::Tiled(tiles) => pipeline::tile::run_tiled(&params, &plan.pair, &tiles, &options)?,
                };
                (out, alone, None)
            }
        };
        let seconds = start.elapsed().as_secs_f64();
        let PipelineOutput { disparity, confidence, consistent, timings, measured, .. } = out;
        let (disparity, confidence, consistent) = match self.min_disp {
            0 => (disparity, confidence, consistent),
            d => crate::min_disp::widen_output(&disparity, confidence.as_ref(), &consistent, d),
        };
        Ok(Output {
            disparity,
            confidence,
            consistent,
            timings,
            measured,
            plan: run_plan,
            seconds,
            frame,
            exposure,
            checks: None,
            rectified: None,
        })
    }
}

/// Bytes per pixel of the pair a caller holds while it is checked ([`Matcher::check_pair`]): both views (24), the
/// output maps (disparity, confidence, consistent: 9) and the check's own grey views (8).
pub(crate) const CHECK_HELD_BYTES_PER_PX: u64 = 24 + 9 + 8;

/// Holds `bytes` of `budget`, reporting the wait as a stage.
fn wait_for<'b>(
    budget: &'b MemoryBudget,
    bytes: u64,
    on_progress: &dyn Fn(Progress<'_>),
) -> crate::setup::memory::Reservation<'b> {
    on_progress(Progress::Stage("waiting for memory"));
    budget.reserve(bytes)
}

/// A default memory limit: 80 % of the machine's physical memory, or 8 GiB where that cannot be read.
pub fn default_memory_limit() -> u64 {
    crate::setup::memory::default_memory_limit()
}

#[cfg(test)]
mod tests;
