//! The `jem` Python module: numpy arrays in, numpy arrays out, over the `jem` library.
//!
//! Nothing here decides how a pair is matched: the range, the whole-or-tiles choice and the run are
//! [`jem::Matcher`]'s (what `jem match` calls), the config is [`jem::Params::load`], and the memory check before the
//! arrays are copied is [`jem::Matcher::check_size`] (what `jem match` checks from the image headers), so an array
//! gives the map the command line writes for the same file, byte for byte. This file converts arrays (as
//! [`jem::io::read_image`] converts a decoded image: 8-bit values as they are, 16-bit ones divided by 257) and
//! errors, releases the GIL around the work and keeps panics and failed allocations from crossing into Python:
//! what a call holds for its caller is checked against its memory limit (`max_memory`) from the arrays' shapes or
//! the files' headers first, and the arrays are copied into fallible allocations (`MemoryError`, never an abort).

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::PathBuf;

mod maps;
mod matcher;
mod rectify;

use jem::{Error, Params, Plane, RgbImage};
use matcher::{MatchOptions, PyMatcher};
use numpy::ndarray::Array2;
use numpy::{PyArray2, PyArrayDescrMethods, PyArrayDyn, PyArrayMethods, PyUntypedArray, PyUntypedArrayMethods};
use pyo3::exceptions::{PyMemoryError, PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyInt, PyList, PyMapping, PyString};

/// A `jem::Error` as the Python exception a caller expects: `MemoryError` for a run that fits the memory limit
/// neither whole nor in tiles, the matching `OSError` subclass (`FileNotFoundError`, ...) for a file the
/// system refused, `ValueError` for everything else (bad shapes, ranges, config keys, malformed files). The
/// message is the command line's: the error and each of its causes.
fn to_py(err: &Error) -> PyErr {
    let msg = err.chain();
    match err {
        Error::OutOfMemory { .. } => PyMemoryError::new_err(msg),
        Error::Io { source, .. } => std::io::Error::new(source.kind(), msg).into(),
        _ => PyValueError::new_err(msg),
    }
}

/// A pool of `n` worker threads.
fn thread_pool(n: usize) -> PyResult<rayon::ThreadPool> {
    let pool = rayon::ThreadPoolBuilder::new().num_threads(n).build();
    pool.map_err(|e| PyRuntimeError::new_err(format!("cannot start {n} threads: {e}")))
}

/// Runs `work` in `pool` (`None`: the global pool, one worker per core), catching a panic: a bug in jem becomes a
/// `RuntimeError` instead of tearing down the interpreter's thread.
fn guarded<T: Send>(pool: Option<&rayon::ThreadPool>, work: impl FnOnce() -> jem::Result<T> + Send) -> PyResult<T> {
    let run = AssertUnwindSafe(|| match pool {
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

/// An image array as its shape and dtype tell it, before any of its data is read.
struct ImageArray<'a, 'py> {
    array: &'a Bound<'py, PyAny>,
    name: &'static str,
    width: usize,
    height: usize,
    /// Samples per pixel: 1 (grey), 3 (RGB) or 4 (RGBA, alpha dropped).
    samples: usize,
    /// 16-bit samples (else 8-bit).
    sixteen: bool,
    /// 16-bit samples in the other byte order (`>u2` on a little-endian machine): converted by numpy first.
    swapped: bool,
}

impl<'a, 'py> ImageArray<'a, 'py> {
    /// H×W grey, H×W×3 RGB or H×W×4 RGBA, uint8 or uint16 in either byte order, any strides.
    fn inspect(array: &'a Bound<'py, PyAny>, name: &'static str) -> PyResult<Self> {
        let untyped = array.cast::<PyUntypedArray>().map_err(|_| {
            let kind = array.get_type().name().map_or("?".to_string(), |n| n.to_string());
            PyValueError::new_err(format!("{name}: expected a numpy array, got {kind}"))
        })?;
        let shape = untyped.shape().to_vec();
        let (height, width, samples) = match shape[..] {
            [h, w] => (h, w, 1),
            [h, w, c @ (3 | 4)] => (h, w, c),
            _ => {
                return Err(PyValueError::new_err(format!(
                    "{name}: shape {shape:?} is neither H×W (grey), H×W×3 (RGB) nor H×W×4 (RGBA)"
                )));
            }
        };
        let dtype = untyped.dtype();
        let (sixteen, swapped) = match (dtype.kind(), dtype.itemsize()) {
            (b'u', 1) => (false, false),
            (b'u', 2) => (true, dtype.is_native_byteorder() == Some(false)),
            _ => {
                return Err(PyValueError::new_err(format!(
                    "{name}: dtype {dtype} is not supported (expected uint8 or uint16)"
                )));
            }
        };
        Ok(ImageArray { array, name, width, height, samples, sixteen, swapped })
    }

    /// The memory its conversion holds at its peak: the three `f32` planes, and numpy's native-order copy of
    /// swapped samples.
    fn load_bytes(&self) -> u64 {
        let px = self.width as u64 * self.height as u64;
        let samples = px * self.samples as u64;
        12 * px + if self.swapped { 2 * samples } else { 0 }
    }

    /// The pixels as planes of `f32` (as [`jem::io::read_image`] gives a decoded image: alpha dropped), read in
    /// logical order.
    /// Every large buffer is allocated fallibly: a failure is a `MemoryError`, never an abort.
    fn to_rgb(&self) -> PyResult<RgbImage> {
        let n = self.width.checked_mul(self.height).ok_or_else(|| self.too_large())?;
        let mut channels: [Vec<f32>; 3] = Default::default();
        for c in &mut channels {
            c.try_reserve_exact(n).map_err(|_| {
                PyMemoryError::new_err(format!(
                    "{}: cannot allocate {} for a {}x{} image",
                    self.name,
                    mib(12 * n as u64),
                    self.width,
                    self.height
                ))
            })?;
        }
        let mut put = |k: usize, v: f32| match self.samples {
            1 => channels.iter_mut().for_each(|c| c.push(v)),
            n => {
                if let Some(c) = channels.get_mut(k % n) {
                    c.push(v);
                }
            }
        };
        if self.sixteen {
            // Another byte order: numpy makes the native copy (its allocation failure is a MemoryError).
            let native;
            let array = if self.swapped {
                native = self.array.call_method1("astype", ("=u2",))?;
                &native
            } else {
                self.array
            };
            let a = array.cast::<PyArrayDyn<u16>>().map_err(|e| PyValueError::new_err(e.to_string()))?;
            let view = a.readonly();
            view.as_array().iter().enumerate().for_each(|(k, &v)| put(k, f32::from(v) / 257.0));
        } else {
            let a = self.array.cast::<PyArrayDyn<u8>>().map_err(|e| PyValueError::new_err(e.to_string()))?;
            let view = a.readonly();
            view.as_array().iter().enumerate().for_each(|(k, &v)| put(k, f32::from(v)));
        }
        RgbImage::from_channels(self.width, self.height, channels).map_err(|e| to_py(&e))
    }

    fn too_large(&self) -> PyErr {
        PyValueError::new_err(format!("{}: {}×{} is too large", self.name, self.width, self.height))
    }
}

/// Bytes as MiB with one decimal.
fn mib(bytes: u64) -> String {
    format!("{:.1} MiB", bytes as f64 / f64::from(1u32 << 20))
}

/// The memory limit of a call: `max_memory` (bytes, at least 1) or the command line's default (80 % of RAM, and of
/// the address space left under `ulimit -v`).
fn memory_limit(max_memory: Option<i64>) -> PyResult<u64> {
    Ok(positive("max_memory", max_memory)?.unwrap_or_else(jem::default_memory_limit))
}

/// Refuses, before anything is allocated, a call `what` on a `width` × `height` image that holds `bytes_per_px` a
/// pixel beyond `limit` bytes: a MemoryError with the size, the need and the limit.
fn check_memory(what: &str, (width, height): (usize, usize), bytes_per_px: u64, limit: u64) -> PyResult<()> {
    let need = (width as u64).saturating_mul(height as u64).saturating_mul(bytes_per_px);
    if need <= limit {
        return Ok(());
    }
    Err(PyMemoryError::new_err(format!(
        "{what}: a {width}x{height} image needs about {} but the memory limit is {} (max_memory)",
        mib(need),
        mib(limit)
    )))
}

/// An empty vector with room for `n` values, allocated fallibly: a failure is a MemoryError naming `what`.
fn reserve<T>(what: &str, n: usize) -> PyResult<Vec<T>> {
    let mut v = Vec::new();
    v.try_reserve_exact(n).map_err(|_| {
        PyMemoryError::new_err(format!("{what}: cannot allocate {}", mib((n * std::mem::size_of::<T>()) as u64)))
    })?;
    Ok(v)
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
    if value.is_instance_of::<PyInt>() {
        return Err(PyValueError::new_err(format!(
            "config key {key}: {value} is too large (a config's whole numbers are 64-bit)"
        )));
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

/// The items of a mapping (a dict, a `types.MappingProxyType`, any `collections.abc.Mapping`).
fn mapping_items<'py>(mapping: &Bound<'py, PyMapping>) -> PyResult<Vec<(Bound<'py, PyAny>, Bound<'py, PyAny>)>> {
    mapping.items()?.iter().map(|item| item.extract()).collect()
}

/// A config mapping in the TOML's shape, flattened to `section.key=value` items (`--set` form).
fn flatten(mapping: &Bound<'_, PyMapping>, prefix: &str, out: &mut Vec<String>) -> PyResult<()> {
    for (k, v) in mapping_items(mapping)? {
        let key = format!(
            "{prefix}{}",
            k.extract::<String>()
                .map_err(|_| { PyValueError::new_err(format!("config keys are strings; {prefix}{k} is not")) })?
        );
        match v.cast::<PyMapping>() {
            Ok(section) => flatten(section, &format!("{key}."), out)?,
            Err(_) => out.push(format!("{key}={}", toml_value(&v, &key)?)),
        }
    }
    Ok(())
}

/// The configuration ``jem batch`` records beside each result (configNAME.toml): every parameter that ``config``
/// and ``overrides`` give (as for ``match``), defaults included, as TOML that ``jem --config`` reads back, after
/// comment lines naming jem's version and ``command`` (what ran it). Raises ValueError for a bad config or override.
#[pyfunction]
#[pyo3(signature = (command, config=None, overrides=None))]
fn config_record(
    command: &str,
    config: Option<&Bound<'_, PyAny>>,
    overrides: Option<&Bound<'_, PyAny>>,
) -> PyResult<String> {
    Ok(jem::batch::config_record(&load_params(config, overrides)?, command))
}

/// The parameters of a call: the defaults, then `config` (a preset's name, a TOML file, or a mapping applied key by
/// key as `--set` items), then `overrides` (a mapping, as `--set`: a string value is taken as the command line
/// would, `"fcm"` or `"3"`).
fn load_params(config: Option<&Bound<'_, PyAny>>, overrides: Option<&Bound<'_, PyAny>>) -> PyResult<Params> {
    let mut items = Vec::new();
    let mut file = None;
    let mut preset = None;
    match config {
        None => {}
        Some(c) => match c.cast::<PyMapping>() {
            Ok(mapping) => flatten(mapping, "", &mut items)?,
            Err(_) => match preset_name(c) {
                Some(name) => preset = Some(name),
                None => {
                    file = Some(c.extract::<PathBuf>().map_err(|_| {
                        PyValueError::new_err(format!("config: expected a TOML file's path or a mapping, got {c}"))
                    })?);
                }
            },
        },
    }
    let overrides = match overrides {
        None => Vec::new(),
        Some(o) => {
            let mapping = o.cast::<PyMapping>().map_err(|_| {
                let kind = o.get_type().name().map_or("?".to_string(), |n| n.to_string());
                PyValueError::new_err(format!(
                    "overrides: expected a mapping of \"section.key\" to a value, got {kind}"
                ))
            })?;
            mapping_items(mapping)?
        }
    };
    for (k, v) in overrides {
        let key: String =
            k.extract().map_err(|_| PyValueError::new_err(format!("override key {k} is not a string")))?;
        let value = match (v.cast::<PyString>(), toml_value(&v, &key)?) {
            (Ok(s), _) => s.to_string(),
            // As Python spells it (`1e+30`, which TOML reads too), so that a message quotes what was given.
            (Err(_), toml::Value::Float(_)) => v.repr()?.to_string(),
            (Err(_), other) => other.to_string(),
        };
        items.push(format!("{key}={value}"));
    }
    match preset {
        Some(name) => Params::preset_with(&name, &items),
        None => Params::load(file.as_deref(), &items),
    }
    .map_err(|e| to_py(&e))
}

/// The preset `config` names: a string that is a preset's name (``"fast"``) and names nothing on disk, so that a
/// file of that name in the working directory is read as it always was.
fn preset_name(config: &Bound<'_, PyAny>) -> Option<String> {
    let name: String = config.cast::<PyString>().ok()?.extract().ok()?;
    let known = Params::preset_names().contains(&name.as_str()) && !std::path::Path::new(&name).exists();
    known.then_some(name)
}

/// The names ``config=`` takes as presets, the shipped configs built in (``"fast"``, ``"balanced"``, ...): each
/// gives exactly what its TOML file in the checkout's ``configs/`` gives. A file of that name in the working
/// directory is read instead.
#[pyfunction]
fn preset_names() -> Vec<&'static str> {
    Params::preset_names()
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
/// ``left``, ``right``: numpy arrays H×W (grey), H×W×3 (RGB order; OpenCV loads BGR: ``img[..., ::-1]``) or
/// H×W×4 (RGBA; alpha is dropped, as ``jem`` drops it from an RGBA file), uint8 or uint16 in either byte order (16-bit values are divided by 257, as a 16-bit PNG is), any strides; grey
/// and colour may be mixed; they are checked against ``max_memory`` from their shapes before they are copied.
/// ``ndisp``: the search range 0..ndisp-1; ``None`` measures it on the pair as ``jem`` does without a calib.txt (up
/// to the width). ``calib_ndisp``: a range a calib.txt states, used as ``jem`` uses one
/// (measured instead, up to it, when it is half the width or more); ``ndisp`` wins. ``min_disp``: the smallest
/// disparity searched (OpenCV SGBM's ``minDisparity``; default 0): the range is min_disp..min_disp+ndisp-1, and the
/// left view's first ``min_disp`` columns are ``inf``, as ``jem --min-disp``. ``config``: a preset's name
/// (``"fast"``; ``preset_names()``), a TOML file's path, or a mapping in the TOML's shape (``{"meanfield":
/// {"iterations": 5}}``; any ``Mapping``). ``overrides``: a mapping ``{"section.key": value}``, applied last, as
/// ``--set``. ``threads``: worker threads for this call (default: one per core; at most 4 per core, at least 16,
/// as ``--threads``); the result is the same for any count. ``max_memory``: bytes (default 80 % of RAM, and of the
/// address space left under ``ulimit -v``); a pair too large for it runs in tiles, as ``--max-memory`` does.
///
/// ``rectify``: a stereo calibration file (OpenCV FileStorage YAML/XML, KITTI calib_cam_to_cam.txt): the raw views
/// are rectified first, as ``jem match --rectify`` does, and the map is of the rectified left view.
/// ``min_confidence``: pixels whose confidence is below it are ``inf`` (as ``jem --min-confidence``).
///
/// Returns the map; with ``confidence=True`` also the per-pixel confidence (0..1, the probability that the
/// disparity is within 1 px, ranking the errors; float32 H×W), and with ``return_info=True`` also a dict: ``ndisp``, ``ndisp_measured``, ``tiled``, ``noise``
/// (σ of each view, or None with ``condition.enabled = false``), ``timings`` (seconds per stage), ``seconds``
/// (the run, as jem batch counts it), ``memory_planned`` and ``peak_rss`` (bytes; the whole process's peak),
/// ``checks`` (the numbers of the pair's checks: ``negative_share``, ``vertical_px``, ``vertical_limit_px``,
/// ``range_share``, ``textured_share``, ``clipped``, ``sharpness_ratio``, ``focus_beyond``, ``identical_share``,
/// ``top_share``, ``measured_ndisp``, ``offsets_by_third``)
/// and ``warnings`` (the lines ``jem`` prints for a pair that looks wrong, each also a UserWarning).
///
/// The GIL is released while matching, so pairs can run in Python threads. Ctrl-C (KeyboardInterrupt) is
/// honoured only when the call returns.
///
/// Raises ValueError (bad shape, dtype, range, config key or value, thread count), MemoryError (the run fits
/// ``max_memory`` neither whole nor in tiles, or its memory cannot be allocated), OSError (an unreadable config
/// file). Warns (UserWarning) for a value the image
/// cannot use, held to a bound as ``jem`` does (``post.sps.segments`` above pixels / ``post.sps.min_support``).
#[pyfunction]
#[pyo3(
    name = "match",
    signature = (left, right, ndisp=None, config=None, overrides=None, threads=None, max_memory=None,
                 confidence=false, return_info=false, calib_ndisp=None, rectify=None, min_confidence=None,
                 min_disp=None)
)]
fn match_pair<'py>(
    py: Python<'py>,
    left: &Bound<'py, PyAny>,
    right: &Bound<'py, PyAny>,
    ndisp: Option<i64>,
    config: Option<&Bound<'py, PyAny>>,
    overrides: Option<&Bound<'py, PyAny>>,
    threads: Option<i64>,
    max_memory: Option<i64>,
    confidence: bool,
    return_info: bool,
    calib_ndisp: Option<i64>,
    rectify: Option<PathBuf>,
    min_confidence: Option<f32>,
    min_disp: Option<i64>,
) -> PyResult<Bound<'py, PyAny>> {
    let options = MatchOptions::new(false, rectify, min_confidence)?.with_min_disp(min_disp)?;
    let matcher = PyMatcher::build(ndisp, calib_ndisp, config, overrides, threads, max_memory, options)?;
    matcher.run(py, left, right, confidence, return_info)
}

/// A PNG, PPM/PGM, JPEG, BMP, TIFF or WebP file as a numpy array, as ``jem`` reads it: uint8 or uint16 (the file's
/// bit depth), H×W for grey, H×W×3 (RGB) for colour; alpha is dropped. The header is read first: a file whose
/// decoding needs more than ``max_memory`` bytes (default: as ``match``) raises MemoryError before anything is
/// decoded (a small file may declare a huge image), and one that is not a regular file (a FIFO, ``/dev/zero``)
/// raises ValueError before it is read, as ``jem`` refuses them. Raises ValueError for an undecodable file, OSError
/// if it cannot be read.
#[pyfunction]
#[pyo3(signature = (path, max_memory=None))]
fn read_image(py: Python<'_>, path: PathBuf, max_memory: Option<i64>) -> PyResult<Bound<'_, PyAny>> {
    let limit = memory_limit(max_memory)?;
    let img = py.detach(|| jem::io::decode_image_within(&path, limit)).map_err(|e| to_py(&e))?;
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
/// ``match`` computes a disparity map (the same bytes as the ``jem`` command line), ``Matcher`` matches many pairs
/// with one configuration and can remember a sequence's frames, ``sequence_frames`` lists a sequence folder's
/// frames, ``depth`` turns a map into metric depth and ``cloud`` into the points ``--cloud`` writes,
/// ``colorize`` draws it as ``jem viz`` does, ``read_pfm``/``write_pfm`` read and write Middlebury's PFM files,
/// ``read_image`` loads an image file (PNG, PNM, JPEG, BMP, TIFF, WebP).
#[pymodule]
#[pyo3(name = "jem")]
fn jem_module(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_function(wrap_pyfunction!(match_pair, m)?)?;
    m.add_function(wrap_pyfunction!(maps::depth, m)?)?;
    m.add_function(wrap_pyfunction!(maps::cloud, m)?)?;
    m.add_function(wrap_pyfunction!(maps::colorize, m)?)?;
    m.add_function(wrap_pyfunction!(maps::read_pfm, m)?)?;
    m.add_function(wrap_pyfunction!(maps::write_pfm, m)?)?;
    m.add_function(wrap_pyfunction!(read_image, m)?)?;
    m.add_function(wrap_pyfunction!(rectify::rectify_maps, m)?)?;
    m.add_function(wrap_pyfunction!(rectify::rectify, m)?)?;
    m.add_function(wrap_pyfunction!(matcher::sequence_frames, m)?)?;
    m.add_function(wrap_pyfunction!(config_record, m)?)?;
    m.add_function(wrap_pyfunction!(preset_names, m)?)?;
    m.add_class::<PyMatcher>()?;
    // maturin's package __init__ re-exports `*` of the native module: `__all__` makes that include __version__.
    let all = [
        "__version__",
        "match",
        "Matcher",
        "sequence_frames",
        "depth",
        "cloud",
        "colorize",
        "read_pfm",
        "write_pfm",
        "read_image",
        "rectify_maps",
        "rectify",
        "config_record",
        "preset_names",
    ];
    m.add("__all__", all)?;
    Ok(())
}
