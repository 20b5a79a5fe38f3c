//! `jem.rectify_maps` and `jem.rectify`: a raw pair rectified from its stereo calibration, as `jem rectify` and
//! OpenCV's `stereoRectify` + `initUndistortRectifyMap` + `remap` do.

use std::path::PathBuf;

use jem::{Error, RgbImage};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use super::matcher::warn_all;
use super::{ImageArray, check_memory, guarded, memory_limit, reserve, to_array, to_numpy, to_py};

/// Bytes per pixel `rectify_maps` holds: both views' maps, two `f32` each.
const MAPS_BYTES_PER_PX: u64 = 16;
/// Bytes per pixel `rectify` holds at the most: the views as planes (24), what rectifying holds beyond them
/// ([`jem::rectify::RECTIFY_BYTES_PER_PX`]) and the 8-bit views returned (6).
const RECTIFY_CALL_BYTES_PER_PX: u64 = 24 + jem::rectify::RECTIFY_BYTES_PER_PX + 6;

/// The rectification a stereo calibration file gives views of ``size`` (width, height; default: the size the
/// file states), as OpenCV's ``stereoRectify`` and ``initUndistortRectifyMap`` give it: a dict with
/// ``map1x``, ``map1y`` (left) and ``map2x``, ``map2y`` (right), float32 H×W (for each rectified pixel, where in the
/// original image it comes from: ``cv2.remap``'s maps), ``R1``, ``R2`` (3×3), ``P1``, ``P2`` (3×4), ``Q`` (4×4),
/// ``roi1``, ``roi2`` (each view's rectangle of valid pixels, ``(x, y, w, h)``: ``validPixROI1``/``2``), ``focal``,
/// ``baseline`` (the calibration's unit), ``doffs`` and ``size``. ``calib``: OpenCV FileStorage YAML/XML or KITTI
/// calib_cam_to_cam.txt. ``max_memory``: bytes the maps may take (default: as ``match``). ``alpha``:
/// ``stereoRectify``'s free scaling, 0..1 (0, the default: valid pixels only; 1: every raw pixel kept; not for a
/// file that holds its own R1/R2/P1/P2). Raises ValueError for a malformed or unusable calibration or a bad
/// ``alpha``, MemoryError for maps beyond ``max_memory``, OSError if it cannot be read; warns (UserWarning) for a
/// rectified view that comes out mostly black.
#[pyfunction]
#[pyo3(signature = (calib, size=None, max_memory=None, alpha=None))]
pub(crate) fn rectify_maps<'py>(
    py: Python<'py>,
    calib: PathBuf,
    size: Option<(usize, usize)>,
    max_memory: Option<i64>,
    alpha: Option<f64>,
) -> PyResult<Bound<'py, PyDict>> {
    let limit = memory_limit(max_memory)?;
    let calibration = jem::rectify::StereoCalibration::load(&calib).map_err(|e| to_py(&e))?;
    let size = size.or(calibration.image_size).ok_or_else(|| {
        PyValueError::new_err(format!("{}: states no image size; give size=(width, height)", calib.display()))
    })?;
    if size.0 == 0 || size.1 == 0 || size.0.saturating_mul(size.1) > 1 << 30 {
        return Err(PyValueError::new_err(format!("size {size:?}: expected 1..2^30 pixels")));
    }
    check_memory("rectify_maps", size, MAPS_BYTES_PER_PX, limit)?;
    let rect = calibration.rectification_with_alpha(size, alpha).map_err(|e| to_py(&e))?;
    warn_all(py, &rect.warnings())?;
    let ((m1x, m1y), (m2x, m2y)) =
        py.detach(|| (rect.maps(jem::rectify::View::Left), rect.maps(jem::rectify::View::Right)));
    let out = PyDict::new(py);
    for (name, plane) in [("map1x", m1x), ("map1y", m1y), ("map2x", m2x), ("map2y", m2y)] {
        out.set_item(name, to_numpy(py, plane))?;
    }
    let t = rect.transforms();
    let rows = |m: &[[f64; 3]; 3]| m.iter().map(|r| r.to_vec()).collect::<Vec<_>>();
    let rows4 = |m: &[[f64; 4]]| m.iter().map(|r| r.to_vec()).collect::<Vec<_>>();
    out.set_item("R1", rows(&t.r1))?;
    out.set_item("R2", rows(&t.r2))?;
    out.set_item("P1", rows4(&t.p1))?;
    out.set_item("P2", rows4(&t.p2))?;
    out.set_item("Q", rows4(&rect.q()))?;
    let [roi1, roi2] = rect.valid_rois();
    out.set_item("roi1", roi1)?;
    out.set_item("roi2", roi2)?;
    out.set_item("focal", rect.focal_px())?;
    out.set_item("baseline", rect.baseline())?;
    out.set_item("doffs", rect.doffs())?;
    out.set_item("size", size)?;
    Ok(out)
}

/// Rectifies a raw pair with its stereo calibration (as ``jem rectify``): the rectified views as uint8 arrays (the
/// images ``jem rectify`` writes: H×W when both views are grey H×W arrays, else H×W×3), and the Middlebury
/// calib.txt of the rectified pair as text. ``left``, ``right`` as for ``match``, checked against ``max_memory``
/// (bytes; default: as ``match``) from their shapes before they are copied. ``alpha`` as for ``rectify_maps``.
/// Raises ValueError for a bad array, calibration or ``alpha``, MemoryError for views beyond ``max_memory``, OSError
/// if the file cannot be read; warns (UserWarning) for a view that comes out mostly black.
#[pyfunction]
#[pyo3(signature = (calib, left, right, max_memory=None, alpha=None))]
pub(crate) fn rectify<'py>(
    py: Python<'py>,
    calib: PathBuf,
    left: &Bound<'py, PyAny>,
    right: &Bound<'py, PyAny>,
    max_memory: Option<i64>,
    alpha: Option<f64>,
) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>, String)> {
    let limit = memory_limit(max_memory)?;
    let (left, right) = (ImageArray::inspect(left, "left")?, ImageArray::inspect(right, "right")?);
    if (left.width, left.height) != (right.width, right.height) {
        let e = Error::SizeMismatch { left: (left.width, left.height), right: (right.width, right.height) };
        return Err(to_py(&e));
    }
    check_memory("rectify", (left.width, left.height), RECTIFY_CALL_BYTES_PER_PX, limit)?;
    let calibration = jem::rectify::StereoCalibration::load(&calib).map_err(|e| to_py(&e))?;
    let rect = calibration.rectification_with_alpha((left.width, left.height), alpha).map_err(|e| to_py(&e))?;
    warn_all(py, &rect.warnings())?;
    // Grey views stay grey: their three channels are equal, and so are those of the rectified views.
    let channels = if left.samples == 1 && right.samples == 1 { 1 } else { 3 };
    let (l, r) = (left.to_rgb()?, right.to_rgb()?);
    let (l, r) = py.detach(|| guarded(None, || rect.rectify_pair(&l, &r)))?;
    let bytes = |img: &RgbImage| -> PyResult<Vec<u8>> {
        let mut out = reserve::<u8>("rectify", channels * img.len())?;
        let sample = |v: f32| v.round().clamp(0.0, 255.0) as u8;
        out.extend((0..img.len()).flat_map(|i| img.rgb(i).into_iter().take(channels).map(sample)));
        Ok(out)
    };
    let (w, h) = l.dims();
    let shape: &[usize] = if channels == 1 { &[h, w] } else { &[h, w, 3] };
    Ok((to_array(py, shape, bytes(&l)?)?, to_array(py, shape, bytes(&r)?)?, rect.calib_txt()))
}
