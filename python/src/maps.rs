//! Disparity maps in and out of Python: `jem.depth`, `jem.cloud`, `jem.colorize`, `jem.read_pfm` and
//! `jem.write_pfm`. Each checks the memory it will hold for the call against its `max_memory` (default: the command
//! line's limit) from the array's shape or the file's header, before anything is allocated, and copies the array
//! into a fallible allocation: a map too large is a `MemoryError`, never an abort.

use std::path::PathBuf;

use jem::Plane;
use numpy::{PyArray2, PyArrayDescrMethods, PyArrayMethods, PyUntypedArray, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use super::{ImageArray, check_memory, memory_limit, reserve, to_array, to_numpy, to_py};

/// Bytes per pixel `depth` holds: the map copied in (4) and the depth map (4).
const DEPTH_BYTES_PER_PX: u64 = 8;
/// Bytes per pixel `cloud` holds at the most: the map (4), the image's planes (12), the cloud (15, its vectors
/// reserved to their size) and the arrays it becomes (15).
const CLOUD_BYTES_PER_PX: u64 = 4 + 12 + 15 + 15;
/// Bytes per pixel `colorize` holds: the map (4) and the colours (3).
const COLORIZE_BYTES_PER_PX: u64 = 7;
/// Bytes per pixel `read_pfm` and `write_pfm` hold: the map (4) and the file's bytes (4).
const PFM_BYTES_PER_PX: u64 = 8;

/// Metric depth Z = f·baseline / (disp + doffs), float32 H×W, in the baseline's unit; ``inf`` where the
/// disparity is invalid or d + doffs ≤ 0 (as ``jem --depth``). ``f``: focal length in pixels; ``doffs``: the
/// x-difference of the principal points (Middlebury calib.txt). ``max_depth``: depths beyond it are ``inf`` too
/// (default f·baseline, the depth of a one-pixel disparity, as ``jem --depth``; ``float("inf")`` keeps all).
/// ``max_memory``: bytes the call may hold (default: as ``match``); a map too large for it raises MemoryError.
#[pyfunction]
#[pyo3(signature = (disp, f, baseline, doffs=0.0, max_depth=None, max_memory=None))]
pub(crate) fn depth<'py>(
    py: Python<'py>,
    disp: &Bound<'py, PyAny>,
    f: f64,
    baseline: f64,
    doffs: f64,
    max_depth: Option<f64>,
    max_memory: Option<i64>,
) -> PyResult<Bound<'py, PyArray2<f32>>> {
    let camera = checked_camera(f, baseline, 0.0, 0.0, doffs, max_depth)?;
    let map = to_plane(disp, "disp", ("depth", DEPTH_BYTES_PER_PX, memory_limit(max_memory)?))?;
    Ok(to_numpy(py, py.detach(|| jem::geometry::depth_map(&map, &camera))))
}

/// The point cloud of a disparity map, as ``jem LEFT RIGHT --cloud C.ply`` writes it: ``(points, colours)``, the
/// points float32 N×3 (X, Y, Z in the left camera's frame: x right, y down, z forward, in the baseline's unit;
/// X = (x − cx)·Z/f, Y = (y − cy)·Z/f, Z = f·baseline / (d + doffs)), the colours uint8 N×3 (RGB, the pixel of
/// ``left``), one row per pixel with a depth, in row order (the PLY's vertices, in order). ``left``: the image,
/// as ``match`` takes it (H×W, H×W×3 or H×W×4; uint8 or uint16), the size of ``disp``. ``f``, ``cx``, ``cy``:
/// ``cam0`` of a calib.txt, in pixels; ``doffs``: its x-difference of the principal points; ``max_depth``: no
/// point beyond it (default f·baseline, as ``--cloud``; ``float("inf")`` keeps all). ``max_memory``: as ``depth``.
#[pyfunction]
#[pyo3(signature = (disp, left, f, baseline, cx, cy, doffs=0.0, max_depth=None, max_memory=None))]
pub(crate) fn cloud<'py>(
    py: Python<'py>,
    disp: &Bound<'py, PyAny>,
    left: &Bound<'py, PyAny>,
    f: f64,
    baseline: f64,
    cx: f64,
    cy: f64,
    doffs: f64,
    max_depth: Option<f64>,
    max_memory: Option<i64>,
) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
    let camera = checked_camera(f, baseline, cx, cy, doffs, max_depth)?;
    let map = to_plane(disp, "disp", ("cloud", CLOUD_BYTES_PER_PX, memory_limit(max_memory)?))?;
    let image = ImageArray::inspect(left, "left")?;
    if (image.width, image.height) != map.dims() {
        return Err(PyValueError::new_err(format!(
            "left is {}×{} but disp is {}×{} (width × height)",
            image.width,
            image.height,
            map.dims().0,
            map.dims().1
        )));
    }
    let image = image.to_rgb()?;
    let cloud = py.detach(|| jem::geometry::point_cloud(&map, &image, &camera));
    let n = cloud.points.len();
    let mut points = reserve::<f32>("cloud", 3 * n)?;
    points.extend(cloud.points.iter().flatten());
    let mut colours = reserve::<u8>("cloud", 3 * n)?;
    colours.extend(cloud.colours.iter().flatten());
    drop(cloud);
    Ok((to_array(py, &[n, 3], points)?, to_array(py, &[n, 3], colours)?))
}

/// A camera from Python's numbers: ``f`` and ``baseline`` positive, all finite, and their product within 32-bit
/// floats (what a depth map holds); ``max_depth`` positive (infinite keeps every depth), by default f·baseline (a
/// one-pixel disparity's depth).
fn checked_camera(
    f: f64,
    baseline: f64,
    cx: f64,
    cy: f64,
    doffs: f64,
    max_depth: Option<f64>,
) -> PyResult<jem::geometry::Camera> {
    let finite = [f, baseline, cx, cy, doffs].iter().all(|v| v.is_finite()) && jem::geometry::fits_f32(f * baseline);
    if !(finite && f > 0.0 && baseline > 0.0) {
        return Err(PyValueError::new_err(format!(
            "f {f} and baseline {baseline} must be positive and finite (and their product within 32-bit floats), \
             cx {cx}, cy {cy} and doffs {doffs} finite"
        )));
    }
    let max_depth = max_depth.unwrap_or(f * baseline);
    if max_depth.is_nan() || max_depth <= 0.0 {
        return Err(PyValueError::new_err(format!("max_depth {max_depth} must be positive")));
    }
    Ok(jem::geometry::Camera { focal: f, cx, cy, baseline, doffs, max_depth })
}

/// A disparity map in colour, as ``jem viz`` draws it: uint8 H×W×3 (RGB), dark indigo (low) through blue,
/// green, yellow to dark red (high), invalid (``inf``, NaN) pixels black; the same bytes as the PNG ``jem viz
/// DISP -o OUT.png --vmin A --vmax B`` writes. ``vmin``, ``vmax``: the range the colours span (default: the map's
/// finite range, as ``jem viz`` without a calib.txt beside DISP). ``max_memory``: as ``depth``. Raises ValueError
/// for a bound that is not finite or a range that is empty or reversed.
#[pyfunction]
#[pyo3(signature = (disp, vmin=None, vmax=None, max_memory=None))]
pub(crate) fn colorize<'py>(
    py: Python<'py>,
    disp: &Bound<'py, PyAny>,
    vmin: Option<f64>,
    vmax: Option<f64>,
    max_memory: Option<i64>,
) -> PyResult<Bound<'py, PyAny>> {
    let map = to_plane(disp, "disp", ("colorize", COLORIZE_BYTES_PER_PX, memory_limit(max_memory)?))?;
    let given = (vmin.map(|v| v as f32), vmax.map(|v| v as f32));
    let (lo, hi) = jem::viz::colour_range(&map, given, None, ("vmin", "vmax")).map_err(|e| to_py(&e))?;
    let canvas = py.detach(|| jem::viz::colorize(&map, lo, hi));
    to_array(py, &[canvas.height, canvas.width, 3], canvas.data)
}

/// A 2-D floating-point array (any strides) as a plane of f32: float32 as it is, float64 rounded, and the other
/// floating types (float16, longdouble) through numpy's conversion to float32. `(what, bytes_per_px, limit)`: the
/// call's memory per pixel, checked against its limit from the shape before anything is copied
/// ([`check_memory`]); the copy is a fallible allocation.
fn to_plane(
    array: &Bound<'_, PyAny>,
    name: &str,
    (what, bytes_per_px, limit): (&str, u64, u64),
) -> PyResult<Plane<f32>> {
    let bad = || PyValueError::new_err(format!("{name}: expected a 2-D floating-point numpy array (e.g. float32)"));
    let untyped = array.cast::<PyUntypedArray>().map_err(|_| bad())?;
    let shape = untyped.shape();
    if shape.len() != 2 || untyped.dtype().kind() != b'f' {
        return Err(bad());
    }
    check_memory(what, (shape[1], shape[0]), bytes_per_px, limit)?;
    let copy = |w: usize, h: usize, values: &mut dyn Iterator<Item = f32>| -> PyResult<Plane<f32>> {
        let mut data = reserve::<f32>(what, w.saturating_mul(h))?;
        data.extend(values);
        Plane::from_vec(w, h, data).map_err(|e| to_py(&e))
    };
    if let Ok(a) = array.cast::<PyArray2<f32>>() {
        let view = a.readonly();
        let (h, w) = view.as_array().dim();
        return copy(w, h, &mut view.as_array().iter().copied());
    }
    if let Ok(a) = array.cast::<PyArray2<f64>>() {
        let view = a.readonly();
        let (h, w) = view.as_array().dim();
        return copy(w, h, &mut view.as_array().iter().map(|&v| v as f32));
    }
    // Another floating type: numpy's own conversion (its failed allocation is a MemoryError).
    to_plane(&array.call_method1("astype", ("float32",))?, name, (what, bytes_per_px, limit))
}

/// A PFM file as float32 H×W, top row first (PFM stores rows bottom-up; this undoes it), ``inf`` kept. A 3-channel
/// PFM gives its first channel. ``max_memory``: as ``depth``; the header's size is checked against it before the
/// body is read. Raises ValueError for a malformed file or one that is not a regular file (a FIFO, a device),
/// MemoryError for a map too large, OSError if it cannot be read.
#[pyfunction]
#[pyo3(signature = (path, max_memory=None))]
pub(crate) fn read_pfm(py: Python<'_>, path: PathBuf, max_memory: Option<i64>) -> PyResult<Bound<'_, PyArray2<f32>>> {
    let limit = memory_limit(max_memory)?;
    let map = py.detach(|| jem::io::pfm::read_pfm_within(&path, limit)).map_err(|e| to_py(&e))?;
    Ok(to_numpy(py, map))
}

/// Writes a 2-D float array (float32; any other floating type, float16 or float64, converted to float32) as a
/// greyscale little-endian PFM, rows bottom-up as Middlebury's files, atomically (a temporary file renamed into
/// place): the bytes ``jem`` writes. An existing ``path`` that is not a regular file (a device, a FIFO) is refused
/// with ValueError, never replaced. ``max_memory``: as ``depth``.
#[pyfunction]
#[pyo3(signature = (path, array, max_memory=None))]
pub(crate) fn write_pfm(
    py: Python<'_>,
    path: PathBuf,
    array: &Bound<'_, PyAny>,
    max_memory: Option<i64>,
) -> PyResult<()> {
    let map = to_plane(array, "array", ("write_pfm", PFM_BYTES_PER_PX, memory_limit(max_memory)?))?;
    if map.data().is_empty() {
        return Err(PyValueError::new_err("array: a PFM cannot hold an empty image"));
    }
    py.detach(|| jem::io::pfm::write_pfm(&path, &map)).map_err(|e| to_py(&e))
}
