//! `jem.Matcher`: a matcher built once and called per pair, which can remember the frames of a sequence (the
//! temporal model of `jem::Matcher::with_temporal`), and `jem.sequence_frames`, the frames of a sequence folder.
//! `jem.match` is a `Matcher` that is used once.

use std::path::PathBuf;
use std::sync::{Mutex, MutexGuard, TryLockError};

use jem::rectify::StereoCalibration;
use jem::{Error, FrameKind, NdispSource, Output, PairCheck, Params};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use super::{ImageArray, check_memory, guarded, load_params, positive, thread_pool, to_numpy, to_py};

/// Matches rectified pairs with one configuration; with ``temporal=True`` the pairs are the frames of one stereo
/// sequence, in order, and each is matched with what the frames before it showed (a still camera's frames are
/// averaged and its answers settle; a moving camera's previous answer, moved by the camera's shift, is the prior;
/// a scene cut is detected and forgets the past). ``reset()`` starts a new sequence.
///
/// The arguments are those of ``jem.match``: ``ndisp``, ``calib_ndisp``, ``min_disp``, ``config``, ``overrides``,
/// ``threads``, ``max_memory``; with ``temporal=True`` the range of the first frame is held for the sequence.
/// ``match(left, right, confidence=False, return_info=False)`` returns what ``jem.match`` returns (the info dict
/// also has ``frame``: how the frame was matched, e.g. ``"still"``, ``"moving"``, ``"cut"``).
///
/// One matcher may be called from several threads: its calls take turns (``match`` and ``reset`` wait, with the GIL
/// released, for the call in progress to end), so each gets the result it would get alone at that point of the
/// sequence. Pairs match in parallel on matchers of their own.
#[pyclass(name = "Matcher", module = "jem", frozen)]
pub(crate) struct PyMatcher {
    /// Everything a call changes, held by one call at a time ([`PyMatcher::turn`]).
    state: Mutex<State>,
}

/// A matcher's state.
pub(crate) struct State {
    matcher: jem::Matcher,
    params: Params,
    threads: Option<usize>,
    /// The pool of `threads` workers, built at the first call and kept for the next: starting the threads anew
    /// for every pair would cost each call their start-up.
    pool: Option<rayon::ThreadPool>,
    options: MatchOptions,
}

/// What a matcher does besides the match: remember the frames, rectify the raw views first, keep the reliable
/// pixels only.
pub(crate) struct MatchOptions {
    temporal: bool,
    /// The stereo calibration the raw views are rectified with (for each size, the matcher is given its
    /// rectification).
    calibration: Option<StereoCalibration>,
    min_confidence: Option<f32>,
    /// The smallest disparity searched (``min_disp``).
    min_disp: usize,
}

impl MatchOptions {
    /// From the ``temporal``, ``rectify`` and ``min_confidence`` arguments, checked (``min_disp``: 0 until
    /// [`MatchOptions::with_min_disp`]).
    pub(crate) fn new(temporal: bool, rectify: Option<PathBuf>, min_confidence: Option<f32>) -> PyResult<MatchOptions> {
        if let Some(c) = min_confidence {
            jem::Output::check_min_confidence("min_confidence", c).map_err(|e| to_py(&e))?;
        }
        let calibration = match &rectify {
            Some(path) => Some(StereoCalibration::load(path).map_err(|e| to_py(&e))?),
            None => None,
        };
        Ok(MatchOptions { temporal, calibration, min_confidence, min_disp: 0 })
    }

    /// With the ``min_disp`` argument: a disparity of 0 or more (``None``: 0).
    pub(crate) fn with_min_disp(mut self, min_disp: Option<i64>) -> PyResult<MatchOptions> {
        let d = min_disp.unwrap_or(0);
        let d = usize::try_from(d).map_err(|_| to_py(&Error::param("min_disp", d, "a disparity of 0 or more")))?;
        self.min_disp = d;
        Ok(self)
    }
}

impl PyMatcher {
    /// The state, once the call in progress (from another thread) has ended: waited for with the GIL released, so
    /// that the call in progress, which needs the GIL to return, can end. A panic is caught inside a call (a
    /// RuntimeError) and never poisons the lock; a poisoned one would be taken as it is.
    fn turn(&self, py: Python<'_>) -> MutexGuard<'_, State> {
        loop {
            match self.state.try_lock() {
                Ok(state) => return state,
                Err(TryLockError::Poisoned(p)) => return p.into_inner(),
                Err(TryLockError::WouldBlock) => {
                    py.detach(|| drop(self.state.lock()));
                }
            }
        }
    }

    /// A matcher from `jem.match`'s arguments.
    pub(crate) fn build(
        ndisp: Option<i64>,
        calib_ndisp: Option<i64>,
        config: Option<&Bound<'_, PyAny>>,
        overrides: Option<&Bound<'_, PyAny>>,
        threads: Option<i64>,
        max_memory: Option<i64>,
        options: MatchOptions,
    ) -> PyResult<PyMatcher> {
        let params = load_params(config, overrides)?;
        let given = positive("ndisp", ndisp)?.map(|n| n as usize);
        let source = NdispSource::resolve(given, positive("calib_ndisp", calib_ndisp)?.map(|n| n as usize));
        // The command line's bound (jem::threads), checked before any thread starts.
        let threads = positive("threads", threads)?.map(|n| jem::threads::check_threads("threads", n)).transpose();
        let threads = threads.map_err(|e| to_py(&e))?;
        let limit = positive("max_memory", max_memory)?.unwrap_or_else(jem::default_memory_limit);
        let matcher = jem::Matcher::new(params.clone()).map_err(|e| to_py(&e))?;
        let matcher = matcher.with_ndisp(source).with_max_memory(limit).with_temporal(options.temporal);
        let matcher = matcher.with_min_disp(options.min_disp).with_checks(true);
        let matcher = match options.min_confidence {
            Some(c) => matcher.with_min_confidence(c).map_err(|e| to_py(&e))?,
            None => matcher,
        };
        Ok(PyMatcher { state: Mutex::new(State { matcher, params, threads, pool: None, options }) })
    }

    /// Matches one pair of arrays and builds what `match` returns, in its turn ([`PyMatcher::turn`]).
    pub(crate) fn run<'py>(
        &self,
        py: Python<'py>,
        left: &Bound<'py, PyAny>,
        right: &Bound<'py, PyAny>,
        confidence: bool,
        return_info: bool,
    ) -> PyResult<Bound<'py, PyAny>> {
        self.turn(py).run(py, left, right, confidence, return_info)
    }
}

impl State {
    /// [`PyMatcher::run`], with the state held.
    fn run<'py>(
        &mut self,
        py: Python<'py>,
        left: &Bound<'py, PyAny>,
        right: &Bound<'py, PyAny>,
        confidence: bool,
        return_info: bool,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (left, right) = (ImageArray::inspect(left, "left")?, ImageArray::inspect(right, "right")?);
        // The confidence map costs a few per cent of a run: computed only when shown or used (a bound on it).
        self.matcher.set_confidence(confidence);
        // From the shapes, before anything is copied: a pair too large for the limit costs no memory.
        let input_bytes = left.load_bytes().saturating_add(right.load_bytes());
        let sizes = ((left.width, left.height), (right.width, right.height));
        self.matcher.check_size(sizes.0, sizes.1, input_bytes).map_err(|e| to_py(&e))?;
        if self.options.calibration.is_some() {
            // The rectified pair and a view's maps beside the arrays, as `jem match --rectify` checks them.
            let per_px = jem::rectify::RECTIFY_BYTES_PER_PX.saturating_add(24);
            check_memory("rectify", sizes.0, per_px, self.matcher.max_memory())?;
        }
        let size = (left.width, left.height);
        if let Some(calibration) = &self.options.calibration
            && self.matcher.rectification().is_none_or(|r| r.size() != size)
        {
            // Computed once per size.
            let rectification = calibration.rectification(size).map_err(|e| to_py(&e))?;
            self.matcher.set_rectification(Some(rectification));
        }
        if let Some(rect) = self.matcher.rectification() {
            warn_all(py, &rect.warnings())?;
        }
        let (l, r) = (left.to_rgb()?, right.to_rgb()?);
        if let (Some(n), None) = (self.threads, &self.pool) {
            self.pool = Some(thread_pool(n)?);
        }
        let (matcher, pool) = (&mut self.matcher, self.pool.as_ref());
        let out = py.detach(|| guarded(pool, || matcher.match_pair(&l, &r)))?;
        results(py, out, &self.params, Shown { confidence, return_info })
    }
}

#[pymethods]
impl PyMatcher {
    #[new]
    #[pyo3(signature = (ndisp=None, config=None, overrides=None, threads=None, max_memory=None, temporal=false,
                        calib_ndisp=None, rectify=None, min_confidence=None, min_disp=None))]
    fn new(
        ndisp: Option<i64>,
        config: Option<&Bound<'_, PyAny>>,
        overrides: Option<&Bound<'_, PyAny>>,
        threads: Option<i64>,
        max_memory: Option<i64>,
        temporal: bool,
        calib_ndisp: Option<i64>,
        rectify: Option<PathBuf>,
        min_confidence: Option<f32>,
        min_disp: Option<i64>,
    ) -> PyResult<PyMatcher> {
        let options = MatchOptions::new(temporal, rectify, min_confidence)?.with_min_disp(min_disp)?;
        PyMatcher::build(ndisp, calib_ndisp, config, overrides, threads, max_memory, options)
    }

    /// The left view's disparity map of the pair (and with the flags, its confidence and an info dict), as
    /// ``jem.match``; a temporal matcher remembers the pair as the next frame.
    #[pyo3(name = "match", signature = (left, right, confidence=false, return_info=false))]
    fn match_pair<'py>(
        &self,
        py: Python<'py>,
        left: &Bound<'py, PyAny>,
        right: &Bound<'py, PyAny>,
        confidence: bool,
        return_info: bool,
    ) -> PyResult<Bound<'py, PyAny>> {
        self.run(py, left, right, confidence, return_info)
    }

    /// Forgets the frames matched so far: the next pair starts a new sequence (after the call in progress from
    /// another thread, if any).
    fn reset(&self, py: Python<'_>) {
        self.turn(py).matcher.reset();
    }
}

/// What a call asked to see.
struct Shown {
    confidence: bool,
    return_info: bool,
}

/// What `match` returns for `out`: the map (the reliable pixels only with ``min_confidence``), then the confidence
/// and the info dict when asked for. Values too large for this image (held to a bound, as `jem` warns on stderr)
/// and a pair that looks wrong (swapped, unrectified, ...; the lines `jem` prints) give a UserWarning each.
fn results<'py>(py: Python<'py>, out: Output, params: &Params, shown: Shown) -> PyResult<Bound<'py, PyAny>> {
    let (w, h) = out.disparity.dims();
    let said = out.warnings();
    let warnings: Vec<String> = params.image_warnings(w, h).into_iter().chain(said.iter().cloned()).collect();
    warn_all(py, &warnings)?;
    let info = match (&out.checks, shown.return_info) {
        (Some(check), true) => Some(info(py, &out, check, said)?),
        _ => None,
    };
    if shown.confidence {
        out.confidence_map().map_err(|e| to_py(&e))?;
    }
    let Output { disparity, confidence, .. } = out;
    let mut result = vec![to_numpy(py, disparity).into_any()];
    if let Some(confidence) = confidence.filter(|_| shown.confidence) {
        result.push(to_numpy(py, confidence).into_any());
    }
    result.extend(info);
    if result.len() == 1 {
        return Ok(result.remove(0));
    }
    Ok(pyo3::types::PyTuple::new(py, result)?.into_any())
}

/// Each line a UserWarning.
pub(crate) fn warn_all(py: Python<'_>, lines: &[String]) -> PyResult<()> {
    for line in lines {
        let message = std::ffi::CString::new(line.as_str()).unwrap_or_default();
        PyErr::warn(py, &py.get_type::<pyo3::exceptions::PyUserWarning>(), &message, 1)?;
    }
    Ok(())
}

/// The info dict of a match (see `jem.match`).
fn info<'py>(py: Python<'py>, out: &Output, check: &PairCheck, warnings: Vec<String>) -> PyResult<Bound<'py, PyAny>> {
    let info = PyDict::new(py);
    info.set_item("ndisp", out.plan.ndisp)?;
    info.set_item("ndisp_measured", out.plan.ndisp_measured)?;
    info.set_item("tiled", out.plan.tiles.is_some())?;
    info.set_item("noise", out.measured.map(|m| (m.stats.noise[0], m.stats.noise[1])))?;
    let timings = PyDict::new(py);
    for (name, d) in &out.timings.per_stage().stages {
        timings.set_item(name, d.as_secs_f64())?;
    }
    info.set_item("timings", timings)?;
    info.set_item("seconds", out.seconds)?;
    info.set_item("memory_planned", out.plan.memory_bytes)?;
    info.set_item("peak_rss", jem::peak_rss_bytes())?;
    let frame = out.frame.map(|k| match k {
        FrameKind::First => ("first", None, None),
        FrameKind::Cut => ("cut", None, None),
        FrameKind::Still { frames } => ("still", Some(i64::from(frames)), None),
        FrameKind::Moving { dx, dy } => ("moving", None, Some((dx, dy))),
        FrameKind::Travelling { .. } => ("moving", None, None),
    });
    info.set_item("frame", frame.map(|f| f.0))?;
    info.set_item("frames_averaged", frame.and_then(|f| f.1))?;
    info.set_item("shift", frame.and_then(|f| f.2))?;
    info.set_item("exposure", out.exposure.map(|e| (e.gain, e.offset)))?;
    let checks = PyDict::new(py);
    checks.set_item("negative_share", check.negative_share)?;
    checks.set_item("vertical_px", check.vertical_px)?;
    checks.set_item("vertical_limit_px", check.vertical_limit_px)?;
    checks.set_item("range_share", check.range_share)?;
    checks.set_item("textured_share", check.textured_share)?;
    checks.set_item("clipped", (check.clipped[0], check.clipped[1]))?;
    checks.set_item("sharpness_ratio", check.sharpness_ratio)?;
    checks.set_item("focus_beyond", check.focus_beyond)?;
    checks.set_item("identical_share", check.identical_share)?;
    checks.set_item("top_share", check.top_share)?;
    checks.set_item("measured_ndisp", check.measured_ndisp)?;
    checks.set_item("offsets_by_third", check.offsets_by_third.to_vec())?;
    info.set_item("checks", checks)?;
    info.set_item("warnings", warnings)?;
    Ok(info.into_any())
}

/// The frames of a stereo sequence folder (``left/`` and ``right/`` paired by file name, or a KITTI raw drive
/// folder), in order: a list of ``(stem, left_path, right_path)``; read them with ``read_image``. Raises
/// ValueError for a folder that is no sequence (unequal counts, unpaired names), naming it.
#[pyfunction]
pub(crate) fn sequence_frames(dir: PathBuf) -> PyResult<Vec<(String, PathBuf, PathBuf)>> {
    let seq = jem::sequence::Sequence::open(&dir).map_err(|e| to_py(&e))?;
    Ok(seq.frames.into_iter().map(|f| (f.stem, f.left, f.right)).collect())
}
