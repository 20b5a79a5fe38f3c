//! `jem.Matcher`: a matcher built once and called per pair, which can remember the frames of a sequence (the
//! temporal model of `jem::Matcher::with_temporal`), and `jem.sequence_frames`, the frames of a sequence folder.
//! `jem.match` is a `Matcher` that is used once.

use std::path::PathBuf;

use jem::{FrameKind, NdispSource, Output, Params};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use super::{ImageArray, guarded, load_params, positive, to_numpy, to_py};

/// Matches rectified pairs with one configuration; with ``temporal=True`` the pairs are the frames of one stereo
/// sequence, in order, and each is matched with what the frames before it showed (a still camera's frames are
/// averaged and its answers settle; a moving camera's previous answer, moved by the camera's shift, is the prior;
/// a scene cut is detected and forgets the past). ``reset()`` starts a new sequence.
///
/// The arguments are those of ``jem.match``: ``ndisp``, ``calib_ndisp``, ``config``, ``overrides``, ``threads``,
/// ``max_memory``; with ``temporal=True`` the range of the first frame is held for the sequence.
/// ``match(left, right, confidence=False, return_info=False)`` returns what ``jem.match`` returns (the info dict
/// also has ``frame``: how the frame was matched, e.g. ``"still"``, ``"moving"``, ``"cut"``).
#[pyclass(name = "Matcher", module = "jem")]
pub(crate) struct PyMatcher {
    matcher: jem::Matcher,
    params: Params,
    threads: Option<usize>,
}

impl PyMatcher {
    /// A matcher from `jem.match`'s arguments.
    pub(crate) fn build(
        ndisp: Option<i64>,
        calib_ndisp: Option<i64>,
        config: Option<&Bound<'_, PyAny>>,
        overrides: Option<&Bound<'_, PyAny>>,
        threads: Option<i64>,
        max_memory: Option<i64>,
        temporal: bool,
    ) -> PyResult<PyMatcher> {
        let params = load_params(config, overrides)?;
        let given = positive("ndisp", ndisp)?.map(|n| n as usize);
        let source = NdispSource::resolve(given, positive("calib_ndisp", calib_ndisp)?.map(|n| n as usize));
        // The command line's bound (jem::threads), checked before any thread starts.
        let threads = positive("threads", threads)?.map(|n| jem::threads::check_threads("threads", n)).transpose();
        let threads = threads.map_err(|e| to_py(&e))?;
        let limit = positive("max_memory", max_memory)?.unwrap_or_else(jem::default_memory_limit);
        let matcher = jem::Matcher::new(params.clone()).map_err(|e| to_py(&e))?;
        let matcher = matcher.with_ndisp(source).with_max_memory(limit).with_temporal(temporal);
        Ok(PyMatcher { matcher, params, threads })
    }

    /// Matches one pair of arrays and builds what `match` returns.
    pub(crate) fn run<'py>(
        &mut self,
        py: Python<'py>,
        left: &Bound<'py, PyAny>,
        right: &Bound<'py, PyAny>,
        confidence: bool,
        return_info: bool,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (left, right) = (ImageArray::inspect(left, "left")?, ImageArray::inspect(right, "right")?);
        // From the shapes, before anything is copied: a pair too large for the limit costs no memory.
        let input_bytes = left.load_bytes().saturating_add(right.load_bytes());
        let sizes = ((left.width, left.height), (right.width, right.height));
        self.matcher.check_size(sizes.0, sizes.1, input_bytes).map_err(|e| to_py(&e))?;
        let (l, r) = (left.to_rgb()?, right.to_rgb()?);
        let (matcher, threads) = (&mut self.matcher, self.threads);
        let out = py.detach(|| guarded(threads, || matcher.match_pair(&l, &r)))?;
        results(py, out, &self.params, confidence, return_info)
    }
}

#[pymethods]
impl PyMatcher {
    #[new]
    #[pyo3(signature = (ndisp=None, config=None, overrides=None, threads=None, max_memory=None, temporal=false,
                        calib_ndisp=None))]
    fn new(
        ndisp: Option<i64>,
        config: Option<&Bound<'_, PyAny>>,
        overrides: Option<&Bound<'_, PyAny>>,
        threads: Option<i64>,
        max_memory: Option<i64>,
        temporal: bool,
        calib_ndisp: Option<i64>,
    ) -> PyResult<PyMatcher> {
        PyMatcher::build(ndisp, calib_ndisp, config, overrides, threads, max_memory, temporal)
    }

    /// The left view's disparity map of the pair (and with the flags, its confidence and an info dict), as
    /// ``jem.match``; a temporal matcher remembers the pair as the next frame.
    #[pyo3(name = "match", signature = (left, right, confidence=false, return_info=false))]
    fn match_pair<'py>(
        &mut self,
        py: Python<'py>,
        left: &Bound<'py, PyAny>,
        right: &Bound<'py, PyAny>,
        confidence: bool,
        return_info: bool,
    ) -> PyResult<Bound<'py, PyAny>> {
        self.run(py, left, right, confidence, return_info)
    }

    /// Forgets the frames matched so far: the next pair starts a new sequence.
    fn reset(&mut self) {
        self.matcher.reset();
    }
}

/// What `match` returns for `out`: the map, then the confidence and the info dict when asked for. Values too
/// large for this image (held to a bound, as `jem` warns on stderr) give a UserWarning each.
fn results<'py>(
    py: Python<'py>,
    out: Output,
    params: &Params,
    confidence: bool,
    return_info: bool,
) -> PyResult<Bound<'py, PyAny>> {
    let (w, h) = out.disparity.dims();
    for warning in params.image_warnings(w, h) {
        let message = std::ffi::CString::new(warning).unwrap_or_default();
        PyErr::warn(py, &py.get_type::<pyo3::exceptions::PyUserWarning>(), &message, 1)?;
    }
    let info = if return_info { Some(info(py, &out)?) } else { None };
    let mut result = vec![to_numpy(py, out.disparity).into_any()];
    if confidence {
        result.push(to_numpy(py, out.confidence).into_any());
    }
    result.extend(info);
    if result.len() == 1 {
        return Ok(result.remove(0));
    }
    Ok(pyo3::types::PyTuple::new(py, result)?.into_any())
}

/// The info dict of a match (see `jem.match`).
fn info<'py>(py: Python<'py>, out: &Output) -> PyResult<Bound<'py, PyAny>> {
    let info = PyDict::new(py);
    info.set_item("ndisp", out.plan.ndisp)?;
    info.set_item("ndisp_measured", out.plan.ndisp_measured)?;
    info.set_item("tiled", out.plan.tiles.is_some())?;
    info.set_item("noise", out.measured.map(|m| (m.stats.noise[0], m.stats.noise[1])))?;
    let timings = PyDict::new(py);
    for (name, d) in &out.timings.stages {
        let sum = timings.get_item(name)?.map_or(Ok(0.0), |v| v.extract::<f64>())?;
        timings.set_item(name, sum + d.as_secs_f64())?;
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
    });
    info.set_item("frame", frame.map(|f| f.0))?;
    info.set_item("frames_averaged", frame.and_then(|f| f.1))?;
    info.set_item("shift", frame.and_then(|f| f.2))?;
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
