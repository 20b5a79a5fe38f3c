//! The `jem` Python module: numpy arrays in, numpy arrays out, over the `jem` library.
//!
//! Nothing here decides how a pair is matched: the range, the whole-or-tiles choice and the run are
//! [`jem::Matcher`]'s (what `jem match` calls), the config is [`jem::Params::load`], the pixel conversion is
//! [`jem::io::image_from_dynamic`] (what the image loader calls), so an array gives the map the command line
//! writes for the same file, byte for byte. This file converts arrays and
//! errors, releases the GIL around the work and keeps panics from crossing into Python.

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::PathBuf;

use image::{DynamicImage, ImageBuffer, Luma, Rgb};
use jem::{Error, Matcher, NdispSource, Params, Plane};
use numpy::ndarray::Array2;
use numpy::{PyArray2, PyArrayDyn, PyArrayMethods, PyUntypedArray, PyUntypedArrayMethods};
use pyo3::exceptions::{PyMemoryError, PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyString};

/// A `jem::Error` as the Python exception a caller expects: `MemoryError` for a run that fits the memory limit
/// neither whole nor in tiles, the matching `OSError` subclass (`FileNotFoundError`, ...) for a file the
/// system refused, `ValueError` for everything else (bad shapes, ranges, config keys, malformed files). The
/// message is the command line's: the error and each of its causes.
fn to_py(err: &Error) -> PyErr {
    let mut msg = err.to_string();
    let mut source = std::error::Error::source(err);
    while let Some(s) = source {
        msg.push_str(": ");
        msg.push_str(&s.to_string());
        source = s.source();
    }
    match err {
        Error::OutOfMemory { .. } => PyMemoryError::new_err(msg),
        Error::Io { source, .. } => std::io::Error::new(source.kind(), msg).into(),
        _ => PyValueError::new_err(msg),
    }
}

/// Runs `work` with a pool of `threads` workers (`None`: the global pool, one per core), catching a panic: a
/// bug in jem becomes a `RuntimeError` instead of tearing down the interpreter's thread.
fn guarded<T: Send>(threads: Option<usize>, work: impl FnOnce() -> jem::Result<T> + Send) -> PyResult<T> {
    let pool = match threads {
        None => None,
        Some(n) => Some(
            rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .build()
                .map_err(|e| PyRuntimeError::new_err(format!("cannot start {n} threads: {e}")))?,
        ),
    };
    let run = AssertUnwindSafe(|| match &pool {
        Some(pool) => pool.install(work),
        None => work(),
    });
    match catch_unwind(run) {
        Ok(result) => result.map_err(|e| to_py(&e)),
        Err(payload) => {
            let what = payload
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| payload.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "a panic without a message".into());
            Err(PyRuntimeError::new_err(format!("internal error in jem (please report it): {what}")))
        }
    }
}

/// A view as a decoded image: H×W grey or H×W×3 RGB, 8 or 16 bit, any strides (copied in logical order).
fn to_image(array: &Bound<'_, PyAny>, name: &str) -> PyResult<DynamicImage> {
    let untyped = array.cast::<PyUntypedArray>().map_err(|_| {
        let kind = array.get_type().name().map_or("?".to_string(), |n| n.to_string());
        PyValueError::new_err(format!("{name}: expected a numpy array, got {kind}"))
    })?;
    let shape = untyped.shape().to_vec();
    let (h, w, colour) = match shape[..] {
        [h, w] => (h, w, false),
        [h, w, 3] => (h, w, true),
        _ => {
            return Err(PyValueError::new_err(format!(
                "{name}: shape {shape:?} is neither H×W (grey) nor H×W×3 (RGB)"
            )));
        }
    };
    let too_large = || PyValueError::new_err(format!("{name}: {w}×{h} is too large"));
    let (w, h) = (u32::try_from(w).map_err(|_| too_large())?, u32::try_from(h).map_err(|_| too_large())?);
    if let Ok(a) = array.cast::<PyArrayDyn<u8>>() {
        let data: Vec<u8> = a.readonly().as_array().iter().copied().collect();
        return Ok(if colour {
            DynamicImage::ImageRgb8(ImageBuffer::<Rgb<u8>, _>::from_raw(w, h, data).ok_or_else(too_large)?)
        } else {
            DynamicImage::ImageLuma8(ImageBuffer::<Luma<u8>, _>::from_raw(w, h, data).ok_or_else(too_large)?)
        });
    }
    if let Ok(a) = array.cast::<PyArrayDyn<u16>>() {
        let data: Vec<u16> = a.readonly().as_array().iter().copied().collect();
        return Ok(if colour {
            DynamicImage::ImageRgb16(ImageBuffer::<Rgb<u16>, _>::from_raw(w, h, data).ok_or_else(too_large)?)
        } else {
            DynamicImage::ImageLuma16(ImageBuffer::<Luma<u16>, _>::from_raw(w, h, data).ok_or_else(too_large)?)
        });
    }
    let dtype = untyped.dtype().to_string();
    Err(PyValueError::new_err(format!("{name}: dtype {dtype} is not supported (expected uint8 or uint16)")))
}

/// A Python value as a TOML value (what `--set key=value` would parse it to).
fn toml_value(value: &Bound<'_, PyAny>, key: &str) -> PyResult<toml::Value> {
    // bool before int: True is an int in Python.
    if let Ok(b) = value.extract::<bool>() {
        return Ok(toml::Value::Boolean(b));
    }
    if let Ok(i) = value.extract::<i64>() {
        return Ok(toml::Value::Integer(i));
    }
    if let Ok(f) = value.extract::<f64>() {
        return Ok(toml::Value::Float(f));
    }
    if let Ok(s) = value.extract::<String>() {
        return Ok(toml::Value::String(s));
    }
    if let Ok(list) = value.cast::<PyList>() {
        let items = list.iter().map(|v| toml_value(&v, key)).collect::<PyResult<_>>()?;
        return Ok(toml::Value::Array(items));
    }
    Err(PyValueError::new_err(format!("config key {key}: {value} is not a bool, number, string or list")))
}

/// A config dict in the TOML's shape, flattened to `section.key=value` items (`--set` form).
fn flatten(dict: &Bound<'_, PyDict>, prefix: &str, out: &mut Vec<String>) -> PyResult<()> {
    for (k, v) in dict.iter() {
        let key = format!(
            "{prefix}{}",
            k.extract::<String>()
                .map_err(|_| { PyValueError::new_err(format!("config keys are strings; {prefix}{k} is not")) })?
        );
        match v.cast::<PyDict>() {
            Ok(section) => flatten(section, &format!("{key}."), out)?,
            Err(_) => out.push(format!("{key}={}", toml_value(&v, &key)?)),
        }
    }
    Ok(())
}

/// The parameters of a call: the defaults, then `config` (a TOML file, or a dict applied key by key as `--set`
/// items), then `overrides` (as `--set`: a string value is taken as the command line would, `"fcm"` or `"3"`).
fn load_params(config: Option<&Bound<'_, PyAny>>, overrides: Option<&Bound<'_, PyDict>>) -> PyResult<Params> {
    let mut items = Vec::new();
    let mut path = None;
    match config {
        None => {}
        Some(c) if c.is_instance_of::<PyDict>() => flatten(c.cast::<PyDict>()?, "", &mut items)?,
        Some(c) => {
            path = Some(c.extract::<PathBuf>().map_err(|_| {
                PyValueError::new_err(format!("config: expected a TOML file's path or a dict, got {c}"))
            })?);
        }
    }
    for (k, v) in overrides.into_iter().flat_map(|d| d.iter()) {
        let key: String =
            k.extract().map_err(|_| PyValueError::new_err(format!("override key {k} is not a string")))?;
        let value = match v.cast::<PyString>() {
            Ok(s) => s.to_string(),
            Err(_) => toml_value(&v, &key)?.to_string(),
        };
        items.push(format!("{key}={value}"));
    }
    Params::load(path.as_deref(), &items).map_err(|e| to_py(&e))
}

/// A positive integer argument, or `ValueError` naming it.
fn positive(name: &str, value: Option<i64>) -> PyResult<Option<u64>> {
    value
        .map(|v| {
            u64::try_from(v).ok().filter(|&v| v > 0).ok_or_else(|| to_py(&Error::param(name, v, "an integer >= 1")))
        })
        .transpose()
}

/// A float plane as a numpy H×W float32 array, without copying.
fn to_numpy<'py>(py: Python<'py>, plane: Plane<f32>) -> Bound<'py, PyArray2<f32>> {
    let (w, h) = plane.dims();
    let array = Array2::from_shape_vec((h, w), plane.into_data()).expect("a plane's data is width × height values");
    PyArray2::from_owned_array(py, array)
}

/// The left view's disparity map of a rectified pair: float32 H×W, ``inf`` where invalid, exactly the map
/// ``jem LEFT RIGHT -o OUT.pfm`` writes for the same images and settings (``read_pfm`` gives the same array).
///
/// ``left``, ``right``: numpy arrays H×W (grey) or H×W×3 (RGB order; OpenCV loads BGR: ``img[..., ::-1]``),
/// uint8 or uint16 (16-bit values are divided by 257, as a 16-bit PNG is), any strides; grey and colour may be
/// mixed. ``ndisp``: the search range 0..ndisp-1; ``None`` measures it on the pair as ``jem`` does without a
/// calib.txt (up to the width). ``calib_ndisp``: a range a calib.txt states, used as ``jem`` uses one
/// (measured instead, up to it, when it is half the width or more); ``ndisp`` wins. ``config``: a TOML file's
/// path, or a dict in the TOML's shape (``{"meanfield": {"iterations": 5}}``). ``overrides``: a dict
/// ``{"section.key": value}``, applied last, as ``--set``. ``threads``: worker threads for this call (default: one
/// per core); the result is the same for any count. ``max_memory``: bytes (default 80 % of RAM); a pair too
/// large for it runs in tiles, as ``--max-memory`` does.
///
/// Returns the map; with ``confidence=True`` also the per-pixel confidence (max-marginal of the left view,
/// float32 H×W), and with ``return_info=True`` also a dict: ``ndisp``, ``ndisp_measured``, ``tiled``, ``noise``
/// (σ of each view, or None with ``condition.enabled = false``), ``timings`` (seconds per stage), ``seconds``
/// (the run, as jem batch counts it), ``memory_planned`` and ``peak_rss`` (bytes; the whole process's peak).
///
/// The GIL is released while matching, so pairs can run in Python threads. Ctrl-C (KeyboardInterrupt) is
/// honoured only when the call returns.
///
/// Raises ValueError (bad shape, dtype, range, config key or value), MemoryError (the run fits ``max_memory``
/// neither whole nor in tiles), OSError (an unreadable config file). Warns (UserWarning) for a value the image
/// cannot use, held to a bound as ``jem`` does (``post.sps.segments`` above pixels / ``post.sps.min_support``).
#[pyfunction]
#[pyo3(
    name = "match",
    signature = (left, right, ndisp=None, config=None, overrides=None, threads=None, max_memory=None,
                 confidence=false, return_info=false, calib_ndisp=None)
)]
#[allow(clippy::too_many_arguments)] // the Python signature the issue asks for
fn match_pair<'py>(
    py: Python<'py>,
    left: &Bound<'py, PyAny>,
    right: &Bound<'py, PyAny>,
    ndisp: Option<i64>,
    config: Option<&Bound<'py, PyAny>>,
    overrides: Option<&Bound<'py, PyDict>>,
    threads: Option<i64>,
    max_memory: Option<i64>,
    confidence: bool,
    return_info: bool,
    calib_ndisp: Option<i64>,
) -> PyResult<Bound<'py, PyAny>> {
    let (l, r) = (to_image(left, "left")?, to_image(right, "right")?);
    let params = load_params(config, overrides)?;
    let given = positive("ndisp", ndisp)?.map(|n| n as usize);
    let source = NdispSource::resolve(given, positive("calib_ndisp", calib_ndisp)?.map(|n| n as usize));
    let threads = positive("threads", threads)?.map(|n| n as usize);
    let limit = positive("max_memory", max_memory)?.unwrap_or_else(jem::default_memory_limit);
    let mut matcher = Matcher::new(params.clone()).map_err(|e| to_py(&e))?.with_ndisp(source).with_max_memory(limit);
    let out = py.detach(|| {
        guarded(threads, || {
            let (l, r) = (jem::io::image_from_dynamic(&l), jem::io::image_from_dynamic(&r));
            matcher.match_pair(&l, &r)
        })
    })?;
    // Values too large for this image (held to a bound, as `jem` warns on stderr): a UserWarning each.
    let (w, h) = out.disparity.dims();
    for warning in params.image_warnings(w, h) {
        let message = std::ffi::CString::new(warning).unwrap_or_default();
        PyErr::warn(py, &py.get_type::<pyo3::exceptions::PyUserWarning>(), &message, 1)?;
    }
    let mut result = vec![to_numpy(py, out.disparity).into_any()];
    if confidence {
        result.push(to_numpy(py, out.confidence).into_any());
    }
    if return_info {
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
        result.push(info.into_any());
    }
    if result.len() == 1 {
        return Ok(result.remove(0));
    }
    Ok(pyo3::types::PyTuple::new(py, result)?.into_any())
}

/// Metric depth Z = f·baseline / (disp + doffs), float32 H×W, in the baseline's unit; ``inf`` where the
/// disparity is invalid or d + doffs ≤ 0 (as ``jem --depth``). ``f``: focal length in pixels; ``doffs``: the
/// x-difference of the principal points (Middlebury calib.txt).
#[pyfunction]
#[pyo3(signature = (disp, f, baseline, doffs=0.0))]
fn depth<'py>(
    py: Python<'py>,
    disp: &Bound<'py, PyAny>,
    f: f64,
    baseline: f64,
    doffs: f64,
) -> PyResult<Bound<'py, PyArray2<f32>>> {
    if !(f.is_finite() && f > 0.0 && baseline.is_finite() && baseline > 0.0 && doffs.is_finite()) {
        return Err(PyValueError::new_err(format!(
            "f {f} and baseline {baseline} must be positive and finite, doffs {doffs} finite"
        )));
    }
    let map = to_plane(disp, "disp")?;
    let camera = jem::geometry::Camera { focal: f, cx: 0.0, cy: 0.0, baseline, doffs };
    Ok(to_numpy(py, py.detach(|| jem::geometry::depth_map(&map, &camera))))
}

/// A 2-D float32 or float64 array (any strides) as a plane of f32.
fn to_plane(array: &Bound<'_, PyAny>, name: &str) -> PyResult<Plane<f32>> {
    let bad = || PyValueError::new_err(format!("{name}: expected a 2-D float32 or float64 numpy array"));
    if let Ok(a) = array.cast::<PyArray2<f32>>() {
        let view = a.readonly();
        let (h, w) = view.as_array().dim();
        return Plane::from_vec(w, h, view.as_array().iter().copied().collect()).map_err(|e| to_py(&e));
    }
    if let Ok(a) = array.cast::<PyArray2<f64>>() {
        let view = a.readonly();
        let (h, w) = view.as_array().dim();
        return Plane::from_vec(w, h, view.as_array().iter().map(|&v| v as f32).collect()).map_err(|e| to_py(&e));
    }
    Err(bad())
}

/// A PFM file as float32 H×W, top row first (PFM stores rows bottom-up; this undoes it), ``inf`` kept. A 3-channel
/// PFM gives its first channel. Raises ValueError for a malformed file, OSError if it cannot be read.
#[pyfunction]
fn read_pfm(py: Python<'_>, path: PathBuf) -> PyResult<Bound<'_, PyArray2<f32>>> {
    let map = py.detach(|| jem::io::pfm::read_pfm(&path)).map_err(|e| to_py(&e))?;
    Ok(to_numpy(py, map))
}

/// Writes a 2-D float array (float32, or float64 rounded to float32) as a greyscale little-endian PFM, rows
/// bottom-up as Middlebury's files, atomically (a temporary file renamed into place): the bytes ``jem`` writes.
#[pyfunction]
fn write_pfm(py: Python<'_>, path: PathBuf, array: &Bound<'_, PyAny>) -> PyResult<()> {
    let map = to_plane(array, "array")?;
    if map.data().is_empty() {
        return Err(PyValueError::new_err("array: a PFM cannot hold an empty image"));
    }
    py.detach(|| jem::io::pfm::write_pfm(&path, &map)).map_err(|e| to_py(&e))
}

/// A PNG, PPM/PGM or JPEG file as a numpy array, as ``jem`` reads it: uint8 or uint16 (the file's bit depth),
/// H×W for grey, H×W×3 (RGB) for colour; alpha is dropped. Raises ValueError for an undecodable file, OSError
/// if it cannot be read.
#[pyfunction]
fn read_image(py: Python<'_>, path: PathBuf) -> PyResult<Bound<'_, PyAny>> {
    let img = py
        .detach(|| {
            let reader = image::ImageReader::open(&path).and_then(|r| r.with_guessed_format());
            let reader = reader.map_err(|e| Error::io(&path, e))?;
            reader.decode().map_err(|source| Error::Image { path: path.clone(), source })
        })
        .map_err(|e| to_py(&e))?;
    let (w, h) = (img.width() as usize, img.height() as usize);
    let grey = !img.color().has_color();
    let sixteen = img.color().bytes_per_pixel() / img.color().channel_count() > 1;
    Ok(match (grey, sixteen) {
        (true, false) => to_array(py, &[h, w], img.into_luma8().into_raw())?,
        (false, false) => to_array(py, &[h, w, 3], img.into_rgb8().into_raw())?,
        (true, true) => to_array(py, &[h, w], img.into_luma16().into_raw())?,
        (false, true) => to_array(py, &[h, w, 3], img.into_rgb16().into_raw())?,
    })
}

/// Pixels in row-major order as a numpy array of `shape` (H×W or H×W×3).
fn to_array<'py, T: numpy::Element>(py: Python<'py>, shape: &[usize], data: Vec<T>) -> PyResult<Bound<'py, PyAny>> {
    Ok(numpy::PyArray1::from_vec(py, data).reshape(shape.to_vec())?.into_any())
}

/// Stereo matching by joint energy minimization (Xue & Cai), on numpy arrays.
///
/// ``match`` computes a disparity map (the same bytes as the ``jem`` command line), ``depth`` turns it into metric
/// depth, ``read_pfm``/``write_pfm`` read and write Middlebury's PFM files, ``read_image`` loads a PNG/PNM/JPEG.
#[pymodule]
#[pyo3(name = "jem")]
fn jem_module(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_function(wrap_pyfunction!(match_pair, m)?)?;
    m.add_function(wrap_pyfunction!(depth, m)?)?;
    m.add_function(wrap_pyfunction!(read_pfm, m)?)?;
    m.add_function(wrap_pyfunction!(write_pfm, m)?)?;
    m.add_function(wrap_pyfunction!(read_image, m)?)?;
    // maturin's package __init__ re-exports `*` of the native module: `__all__` makes that include __version__.
    m.add("__all__", ["__version__", "match", "depth", "read_pfm", "write_pfm", "read_image"])?;
    Ok(())
}
