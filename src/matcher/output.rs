//! What a match gives: the map and its companions ([`Output`]), how the run was set up ([`RunPlan`], [`Tiles`]),
//! the rectified view ([`Rectified`]).

use std::path::PathBuf;

use crate::error::Result;
use crate::image::{DisparityMap, Plane, RgbImage};
use crate::pipeline::{Measured, Timings};
use crate::temporal::{Exposure, FrameKind};

#[cfg(doc)]
use super::Matcher;

/// How a match was set up: its range, whether it went in tiles, the memory it planned for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RunPlan {
    /// The number of disparities searched: `min_disp..min_disp + ndisp − 1`.
    pub ndisp: usize,
    /// The smallest disparity searched ([`Matcher::with_min_disp`]; 0 by default).
    pub min_disp: usize,
    /// Whether the range was measured on the pair (none given, or the stated one no real bound).
    pub ndisp_measured: bool,
    /// `Some` when the pair did not fit the memory limit in one piece and ran in tiles.
    pub tiles: Option<Tiles>,
    /// The memory the run planned for, in bytes (what the limit was checked against).
    pub memory_bytes: u64,
    /// The reduction of the working resolution chosen for the pair: 1 = its own resolution; 2ᵏ when its k finest
    /// octaves hold no detail of their own (`[working]`; `downscale` is apart from it).
    pub working_factor: usize,
}

/// How a tiled run was cut.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Tiles {
    /// The side of a tile's core in pixels (before any split).
    pub core_px: usize,
    /// The downscale factor of the coarse level the tiles start from.
    pub coarse_factor: usize,
}

/// What a match produces.
#[derive(Clone, Debug)]
pub struct Output {
    /// The left view's disparity map in pixels, `inf` where invalid (when post-processing leaves holes).
    pub disparity: DisparityMap,
    /// Per-pixel confidence of the disparity map, 0..1: the probability that it is within 1 px of the truth, made to
    /// rank the errors (`post::confidence`; 0 where the map is invalid). `None` when the matcher was told not to
    /// compute it ([`Matcher::with_confidence`]).
    pub confidence: Option<Plane<f32>>,
    /// The pixels that passed the left-right check (all of them when it is off).
    pub consistent: Plane<bool>,
    /// Time per stage.
    pub timings: Timings,
    /// What the adaptive front end measured on the pair; `None` when `[condition]` is off.
    pub measured: Option<Measured>,
    /// How the match was set up.
    pub plan: RunPlan,
    /// Seconds in the pipeline: the run itself, without loading, the range measurement or writing (what
    /// MiddEval3's `time*.txt` holds).
    pub seconds: f64,
    /// How the frame was matched, for a matcher that remembers frames ([`Matcher::with_temporal`]); `None` for a
    /// pair matched alone.
    pub frame: Option<FrameKind>,
    /// The exposure change the temporal model compensated in this frame (against the previous frame or the
    /// still camera's running mean); `None` when there was none, or for a pair matched alone.
    pub exposure: Option<Exposure>,
    /// What the pair check found ([`Matcher::with_checks`]; `None` when not asked for). Its warnings as a front
    /// end says them: [`Output::warnings`].
    pub checks: Option<crate::PairCheck>,
    /// The rectified view the map belongs to, when the matcher rectified the pair ([`Matcher::with_rectification`]).
    pub rectified: Option<Rectified>,
}

/// The pair as a matcher rectified it before matching ([`Matcher::with_rectification`]).
#[derive(Clone, Debug)]
pub struct Rectified {
    /// The rectified left view: the view the disparity map is of (the colours of a point cloud, say).
    pub left: RgbImage,
    /// The calibration file the pair was rectified with.
    pub calibration: PathBuf,
}

impl Output {
    /// The pair check's warnings, one line per problem (none when the pair looks right or was not checked). For a
    /// pair the matcher rectified, a warning that the pair is not rectified doubts the calibration instead of
    /// advising to rectify it ([`crate::PairCheck::after_rectify`]).
    pub fn warnings(&self) -> Vec<String> {
        let warnings = self.checks.as_ref().map(crate::PairCheck::warnings).unwrap_or_default();
        match &self.rectified {
            Some(r) => warnings.into_iter().map(|w| crate::PairCheck::after_rectify(w, &r.calibration)).collect(),
            None => warnings,
        }
    }

    /// The confidence map.
    ///
    /// # Errors
    /// [`crate::error::Error::Argument`] when the matcher was told not to compute it ([`Matcher::with_confidence`]).
    pub fn confidence_map(&self) -> Result<&Plane<f32>> {
        let missing = || crate::error::Error::argument("no confidence map was computed for this run");
        self.confidence.as_ref().ok_or_else(missing)
    }

    /// Refuses a `min_confidence` that is not a confidence from 0 to 1 (NaN included), naming it `name` (the
    /// front ends check theirs with it before anything runs).
    ///
    /// # Errors
    /// [`crate::Error::InvalidParam`] naming `name`.
    pub fn check_min_confidence(name: &str, min_confidence: f32) -> Result<()> {
        if (0.0..=1.0).contains(&min_confidence) {
            Ok(())
        } else {
            Err(crate::Error::param(name, min_confidence, "a confidence from 0 to 1"))
        }
    }

    /// The disparity map with every pixel whose confidence is below `min_confidence` made invalid (`inf`): the
    /// reliable pixels only (`jem --min-confidence`).
    ///
    /// # Errors
    /// [`crate::Error::InvalidParam`] naming `min_confidence` when it is not a confidence from 0 to 1 (NaN included);
    /// as [`Output::confidence_map`].
    pub fn reliable_disparity(&self, min_confidence: f32) -> Result<DisparityMap> {
        Output::check_min_confidence("min_confidence", min_confidence)?;
        let confidence = self.confidence_map()?;
        let mut out = self.disparity.clone();
        out.data.iter_mut().zip(&confidence.data).filter(|&(_, &c)| c < min_confidence).for_each(|(d, _)| {
            *d = f32::INFINITY;
        });
        Ok(out)
    }
}
