"""Stereo matching by joint energy minimization (Xue & Cai), on numpy arrays.

``match`` computes a disparity map (the same bytes as the ``jem`` command line), ``Matcher`` matches many pairs
with one configuration and can remember a sequence's frames (``sequence_frames`` lists a sequence folder's),
``depth`` turns a map into metric depth and ``cloud`` into the points ``--cloud`` writes, ``colorize`` draws it
as ``jem viz`` does, ``read_pfm``/``write_pfm`` read and write Middlebury's PFM files, ``read_image`` loads an
image file (PNG, PNM, JPEG, BMP, TIFF, WebP), ``rectify``/``rectify_maps`` rectify a raw pair from its stereo
calibration as OpenCV does.
"""

import os
from pathlib import Path
from typing import Any, Literal, Mapping, Optional, Tuple, TypedDict, Union, final, overload, type_check_only

import numpy as np
import numpy.typing as npt

__version__: str
__all__ = [
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
]

_Image = Union[npt.NDArray[np.uint8], npt.NDArray[np.uint16]]
_Map = npt.NDArray[np.float32]
_Path = Union[str, "os.PathLike[str]"]
# A preset's name (``preset_names()``) is a str, as a path is.
_Config = Union[_Path, Mapping[str, Any], None]

@type_check_only
class PairChecks(TypedDict):
    """The numbers of a pair's checks (``MatchInfo["checks"]``), those behind ``warnings``; None where a check
    could not be made on the pair."""

    negative_share: Optional[float]
    vertical_px: Optional[float]
    vertical_limit_px: float
    range_share: Optional[float]
    textured_share: float
    clipped: Tuple[float, float]
    sharpness_ratio: float
    focus_beyond: bool
    identical_share: float
    top_share: Optional[float]
    measured_ndisp: Optional[int]
    offsets_by_third: list[Optional[float]]

@type_check_only
class MatchInfo(TypedDict):
    """The info dict ``match(..., return_info=True)`` returns (a plain dict at run time; this type exists for type
    checkers only: import it under ``typing.TYPE_CHECKING``). Every key is always present."""

    ndisp: int
    ndisp_measured: bool
    tiled: bool
    # Each view's noise σ; None with ``condition.enabled = false``.
    noise: Optional[Tuple[float, float]]
    # Seconds per stage.
    timings: dict[str, float]
    seconds: float
    memory_planned: int
    # The whole process's peak resident memory in bytes; None where the system does not tell it.
    peak_rss: Optional[int]
    # How a temporal matcher matched the frame; None for ``jem.match`` and a matcher without ``temporal=True``.
    frame: Optional[Literal["first", "still", "moving", "cut"]]
    frames_averaged: Optional[int]
    # The camera's shift (dx, dy) in pixels, for a moving frame it could measure.
    shift: Optional[Tuple[int, int]]
    # The (gain, offset) compensated in the frame.
    exposure: Optional[Tuple[float, float]]
    checks: PairChecks
    warnings: list[str]

# What ``match`` returns for flags that are not literals.
_MatchResult = Union[_Map, Tuple[_Map, _Map], Tuple[_Map, MatchInfo], Tuple[_Map, _Map, MatchInfo]]

@overload
def match(
    left: _Image,
    right: _Image,
    ndisp: Optional[int] = None,
    config: _Config = None,
    overrides: Optional[Mapping[str, Any]] = None,
    threads: Optional[int] = None,
    max_memory: Optional[int] = None,
    confidence: Literal[False] = False,
    return_info: Literal[False] = False,
    calib_ndisp: Optional[int] = None,
    rectify: Optional[_Path] = None,
    min_confidence: Optional[float] = None,
    min_disp: Optional[int] = None,
) -> _Map: ...
@overload
def match(
    left: _Image,
    right: _Image,
    ndisp: Optional[int] = None,
    config: _Config = None,
    overrides: Optional[Mapping[str, Any]] = None,
    threads: Optional[int] = None,
    max_memory: Optional[int] = None,
    *,
    confidence: Literal[True],
    return_info: Literal[False] = False,
    calib_ndisp: Optional[int] = None,
    rectify: Optional[_Path] = None,
    min_confidence: Optional[float] = None,
    min_disp: Optional[int] = None,
) -> Tuple[_Map, _Map]: ...
@overload
def match(
    left: _Image,
    right: _Image,
    ndisp: Optional[int] = None,
    config: _Config = None,
    overrides: Optional[Mapping[str, Any]] = None,
    threads: Optional[int] = None,
    max_memory: Optional[int] = None,
    confidence: Literal[False] = False,
    *,
    return_info: Literal[True],
    calib_ndisp: Optional[int] = None,
    rectify: Optional[_Path] = None,
    min_confidence: Optional[float] = None,
    min_disp: Optional[int] = None,
) -> Tuple[_Map, MatchInfo]: ...
@overload
def match(
    left: _Image,
    right: _Image,
    ndisp: Optional[int] = None,
    config: _Config = None,
    overrides: Optional[Mapping[str, Any]] = None,
    threads: Optional[int] = None,
    max_memory: Optional[int] = None,
    *,
    confidence: Literal[True],
    return_info: Literal[True],
    calib_ndisp: Optional[int] = None,
    rectify: Optional[_Path] = None,
    min_confidence: Optional[float] = None,
    min_disp: Optional[int] = None,
) -> Tuple[_Map, _Map, MatchInfo]: ...
@overload
def match(
    left: _Image,
    right: _Image,
    ndisp: Optional[int] = None,
    config: _Config = None,
    overrides: Optional[Mapping[str, Any]] = None,
    threads: Optional[int] = None,
    max_memory: Optional[int] = None,
    confidence: bool = False,
    return_info: bool = False,
    calib_ndisp: Optional[int] = None,
    rectify: Optional[_Path] = None,
    min_confidence: Optional[float] = None,
    min_disp: Optional[int] = None,
) -> _MatchResult:
    """The left view's disparity map of a rectified pair: float32 H×W, ``inf`` where invalid, exactly the map
    ``jem LEFT RIGHT -o OUT.pfm`` writes for the same images and settings.

    ``left``, ``right``: H×W (grey), H×W×3 (RGB order; OpenCV loads BGR) or H×W×4 (RGBA, alpha dropped), uint8 or
    uint16 (either byte order), any strides; checked against ``max_memory`` from their shapes before they are
    copied. ``ndisp``: the search range 0..ndisp-1; ``None`` measures it on the pair, as ``jem`` does without
    calib.txt. ``calib_ndisp``: a range a calib.txt states, used as ``jem`` uses one. ``config``: a preset's name
    (``"fast"``; ``preset_names()``), a TOML path or a mapping in the TOML's shape. ``overrides``:
    ``{"section.key": value}`` as ``--set``. ``threads``: workers for this call (at most 4 per core, at least 16).
    ``max_memory``: bytes; larger runs go in tiles. With ``confidence=True`` also the confidence map, with
    ``return_info=True`` also a dict (``MatchInfo``: ndisp, ndisp_measured, tiled, noise, timings, seconds,
    memory_planned, peak_rss, frame, frames_averaged, shift, exposure, checks, warnings). ``rectify``: a stereo
    calibration (OpenCV FileStorage YAML/XML, KITTI calib_cam_to_cam.txt); the raw views are rectified first, as
    ``jem match --rectify``, and the map is of the rectified left view. ``min_confidence``: pixels whose confidence
    is below it are ``inf``. ``min_disp``: the smallest disparity searched (SGBM's ``minDisparity``):
    min_disp..min_disp+ndisp-1, the first ``min_disp`` columns ``inf``. The GIL is released while matching;
    KeyboardInterrupt is honoured only when the call returns.

    Raises ValueError (shape, dtype, range, config, threads), MemoryError (fits neither whole nor in tiles, or
    cannot be allocated), OSError.
    Warns (UserWarning) for a value the image cannot use, held to a bound (post.sps.segments).
    """

def depth(
    disp: npt.NDArray[np.floating[Any]],
    f: float,
    baseline: float,
    doffs: float = 0.0,
    max_depth: Optional[float] = None,
    max_memory: Optional[int] = None,
) -> _Map:
    """Metric depth Z = f·baseline / (disp + doffs), float32, ``inf`` where there is none or beyond ``max_depth``
    (default f·baseline, the depth of a one-pixel disparity). ``max_memory``: bytes the call may hold (default:
    as ``match``); a map too large raises MemoryError before anything is allocated."""

def cloud(
    disp: npt.NDArray[np.floating[Any]], left: _Image, f: float, baseline: float, cx: float, cy: float,
    doffs: float = 0.0, max_depth: Optional[float] = None, max_memory: Optional[int] = None,
) -> Tuple[npt.NDArray[np.float32], npt.NDArray[np.uint8]]:
    """The point cloud ``--cloud`` writes: (points float32 N×3, colours uint8 N×3), one row per pixel with a depth,
    in row order; X = (x − cx)·Z/f, Y = (y − cy)·Z/f, Z = f·baseline / (d + doffs), in the baseline's unit.
    ``max_memory`` as ``depth``."""

def colorize(
    disp: npt.NDArray[np.floating[Any]],
    vmin: Optional[float] = None,
    vmax: Optional[float] = None,
    max_memory: Optional[int] = None,
) -> npt.NDArray[np.uint8]:
    """The disparity map in colour as ``jem viz`` draws it: uint8 H×W×3, invalid pixels black; the range defaults to
    the map's finite range. ``max_memory`` as ``depth``."""

def read_pfm(path: _Path, max_memory: Optional[int] = None) -> _Map:
    """A PFM file as float32 H×W, top row first, ``inf`` kept; the header's size is checked against ``max_memory``
    (as ``depth``) before the body is read."""

def write_pfm(path: _Path, array: npt.NDArray[np.floating[Any]], max_memory: Optional[int] = None) -> None:
    """Writes a 2-D float array (any floating type, as float32) as a little-endian greyscale PFM (Middlebury rows
    bottom-up), atomically; an existing path that is not a regular file (a device, a FIFO) raises ValueError.
    ``max_memory`` as ``depth``."""

def read_image(path: _Path, max_memory: Optional[int] = None) -> _Image:
    """A PNG, PPM/PGM, JPEG, BMP, TIFF or WebP as uint8 or uint16, H×W (grey) or H×W×3 (RGB), as ``jem`` reads it.
    The header is checked first: a decoding beyond ``max_memory`` (as ``depth``) raises MemoryError, a path that is
    not a regular file (a FIFO, ``/dev/zero``) ValueError, before anything is read."""

@final
class Matcher:
    """Matches pairs with one configuration; with ``temporal=True`` the pairs are the frames of one stereo
    sequence, in order, each matched with what the frames before it showed (a still camera's frames averaged and
    its answers settled; a moving camera's previous answer, moved by its shift, as the prior; scene cuts detected).
    Arguments as ``match``. OpenCV users: like ``cv2.StereoSGBM_create(...)`` then ``.compute(L, R)``. Calls on one
    matcher from several threads take turns (each waits, the GIL released, for the one in progress)."""

    def __new__(
        cls,
        ndisp: Optional[int] = None,
        config: _Config = None,
        overrides: Optional[Mapping[str, Any]] = None,
        threads: Optional[int] = None,
        max_memory: Optional[int] = None,
        temporal: bool = False,
        calib_ndisp: Optional[int] = None,
        rectify: Optional[_Path] = None,
        min_confidence: Optional[float] = None,
        min_disp: Optional[int] = None,
    ) -> "Matcher": ...
    @overload
    def match(
        self,
        left: _Image,
        right: _Image,
        confidence: Literal[False] = False,
        return_info: Literal[False] = False,
    ) -> _Map: ...
    @overload
    def match(
        self,
        left: _Image,
        right: _Image,
        confidence: Literal[True],
        return_info: Literal[False] = False,
    ) -> Tuple[_Map, _Map]: ...
    @overload
    def match(
        self,
        left: _Image,
        right: _Image,
        *,
        confidence: Literal[False] = False,
        return_info: Literal[True],
    ) -> Tuple[_Map, MatchInfo]: ...
    @overload
    def match(
        self,
        left: _Image,
        right: _Image,
        confidence: Literal[True],
        return_info: Literal[True],
    ) -> Tuple[_Map, _Map, MatchInfo]: ...
    @overload
    def match(
        self,
        left: _Image,
        right: _Image,
        confidence: bool = False,
        return_info: bool = False,
    ) -> _MatchResult:
        """As ``jem.match``; a temporal matcher remembers the pair as the next frame (the info dict's ``frame``:
        ``"first"``, ``"still"``, ``"moving"`` or ``"cut"``; ``frames_averaged``; ``shift``; ``exposure``: the
        (gain, offset) compensated in the frame, or None)."""
    def reset(self) -> None:
        """Forgets the frames matched so far: the next pair starts a new sequence."""

def sequence_frames(dir: _Path) -> list[Tuple[str, Path, Path]]:
    """The frames of a sequence folder (``left/`` + ``right/`` paired by name, or a KITTI raw drive), in order:
    ``(stem, left_path, right_path)``."""

def rectify_maps(
    calib: _Path,
    size: Optional[Tuple[int, int]] = None,
    max_memory: Optional[int] = None,
    alpha: Optional[float] = None,
) -> dict[str, Any]:
    """The rectification of a stereo calibration (OpenCV FileStorage YAML/XML, KITTI calib_cam_to_cam.txt) for views
    of ``size`` (width, height; default: the size the file states), as ``cv2.stereoRectify`` and
    ``cv2.initUndistortRectifyMap`` give it: ``map1x``, ``map1y``, ``map2x``, ``map2y`` (float32 H×W, cv2.remap's
    maps), ``R1``, ``R2``, ``P1``, ``P2``, ``Q`` (nested lists), ``roi1``, ``roi2`` (each view's valid pixels,
    ``(x, y, w, h)``: validPixROI1/2), ``focal``, ``baseline``, ``doffs``, ``size``. ``alpha``: stereoRectify's free
    scaling, 0..1 (0, the default: valid pixels only; 1: every raw pixel kept). ``max_memory`` as ``depth``; a view
    that would come out mostly black is a UserWarning."""

def rectify(
    calib: _Path,
    left: _Image,
    right: _Image,
    max_memory: Optional[int] = None,
    alpha: Optional[float] = None,
) -> Tuple[npt.NDArray[np.uint8], npt.NDArray[np.uint8], str]:
    """The rectified views (uint8, what ``jem rectify`` writes: H×W when both views are grey H×W arrays, else
    H×W×3) and the rectified pair's Middlebury calib.txt text. ``alpha`` as ``rectify_maps``; ``max_memory`` as
    ``depth``, checked from the shapes."""

def config_record(
    command: str,
    config: _Config = None,
    overrides: Optional[Mapping[str, Any]] = None,
) -> str:
    """The configuration `jem batch` records beside each result (configNAME.toml): every parameter, as TOML that
    `jem --config` reads back, after comment lines naming jem's version and ``command``."""

def preset_names() -> list[str]:
    """The names ``config=`` takes as presets (``"fast"``, ``"balanced"``, ...): the shipped ``configs/*.toml`` built
    in, each giving exactly what its file gives. A file of that name in the working directory is read instead."""
