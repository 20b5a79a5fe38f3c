"""Every error path raises a Python exception with jem's message; nothing panics across the boundary."""

import numpy as np
import pytest
from test_match import write_pnm

import jem

SMALL = np.zeros((16, 40, 3), np.uint8)


@pytest.mark.parametrize(
    "left, message",
    [
        (np.zeros((16, 40, 2), np.uint8), r"shape \[16, 40, 2\] is neither H×W \(grey\), H×W×3 \(RGB\) nor H×W×4"),
        (np.zeros(40, np.uint8), r"shape \[40\] is neither"),
        (np.zeros((16, 40, 3), np.float32), "dtype float32 is not supported"),
        (np.zeros((16, 40), np.int16), "dtype int16 is not supported"),
        ([[0] * 40] * 16, "expected a numpy array, got list"),
        (np.zeros((16, 41, 3), np.uint8), "left image is 41x16 but right image is 40x16"),
        (np.zeros((0, 0, 3), np.uint8), "empty"),
    ],
)
def test_bad_images(left, message):
    right = np.zeros((0, 0, 3), np.uint8) if np.shape(left)[:2] == (0, 0) else SMALL
    with pytest.raises(ValueError, match=message):
        jem.match(left, right, ndisp=8)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"ndisp": 40}, r"invalid ndisp = 40 \(expected at least 1 and less than the image width 40\)"),
        ({"ndisp": 0}, r"invalid ndisp = 0 \(expected an integer >= 1\)"),
        ({"ndisp": -3}, "invalid ndisp = -3"),
        ({"calib_ndisp": 0}, "invalid calib_ndisp = 0"),
        ({"threads": 0}, "invalid threads = 0"),
        ({"max_memory": -1}, "invalid max_memory = -1"),
        ({"overrides": {"meanfield.iteratons": 3}}, "unknown field `iteratons`"),
        ({"overrides": {"meanfield.sigma_xy": -1.5}}, r"invalid meanfield.sigma_xy = -1.5 \(expected a finite"),
        ({"overrides": {"meanfield.iterations": "many"}}, r"`meanfield.iterations` takes a whole number .* not many"),
        ({"overrides": {"model": object()}}, "not a bool, number, string or list"),
        ({"config": {"cost": {"census_window": [9, 7], "bogus": True}}}, "unknown field `bogus`"),
        ({"config": {"meanfield": {"iterations": None}}}, "config key meanfield.iterations"),
        ({"config": 12}, "expected a TOML file's path or a mapping"),
    ],
)
def test_bad_settings(kwargs, message):
    kwargs = {"ndisp": 8, **kwargs}
    with pytest.raises(ValueError, match=message):
        jem.match(SMALL, SMALL, **kwargs)


def test_config_files(tmp_path):
    with pytest.raises(FileNotFoundError, match="missing.toml"):
        jem.match(SMALL, SMALL, ndisp=8, config=tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[meanfield\niterations = 3\n")
    with pytest.raises(ValueError, match="bad.toml"):
        jem.match(SMALL, SMALL, ndisp=8, config=bad)


def test_messages_are_the_cli_s(tmp_path, cli):
    """The exception's text is what the command line prints after `error: `."""
    left = write_pnm(tmp_path / "l.ppm", np.zeros((16, 40, 3), np.uint8))
    right = write_pnm(tmp_path / "r.ppm", np.zeros((16, 41, 3), np.uint8))
    for args, call in [
        ((left, right), lambda: jem.match(SMALL, np.zeros((16, 41, 3), np.uint8))),
        ((left, left, "--ndisp", 8, "--set", "post.lrc.mode=sideways"),
         lambda: jem.match(SMALL, SMALL, ndisp=8, overrides={"post.lrc.mode": "sideways"})),
        ((left, left, "--ndisp", 8, "--max-memory", "1M"),
         lambda: jem.match(SMALL, SMALL, ndisp=8, max_memory=1 << 20)),
    ]:
        proc = cli(*args, "-o", tmp_path / "out.pfm", check=False)
        assert proc.returncode == 2
        with pytest.raises((ValueError, MemoryError)) as caught:
            call()
        assert proc.stderr == f"error: {caught.value}\n"


def test_too_large_even_in_tiles_is_a_memory_error():
    with pytest.raises(MemoryError, match=r"this run needs about .* but the memory limit is"):
        jem.match(SMALL, SMALL, ndisp=8, max_memory=1000)


def test_file_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="nothing.pfm"):
        jem.read_pfm(tmp_path / "nothing.pfm")
    with pytest.raises(FileNotFoundError, match="nothing.png"):
        jem.read_image(tmp_path / "nothing.png")
    (tmp_path / "bad.pfm").write_bytes(b"Pf\n2 2\n-1\n" + b"\0" * 12)
    with pytest.raises(ValueError, match=r"invalid PFM: 2x2x1 needs 16 data bytes but the file has 12"):
        jem.read_pfm(tmp_path / "bad.pfm")
    (tmp_path / "bad.png").write_bytes(b"\x89PNG\r\n\x1a\n" + b"\0" * 20)
    with pytest.raises(ValueError, match="bad.png: image codec error"):
        jem.read_image(tmp_path / "bad.png")
    with pytest.raises(FileNotFoundError):
        jem.write_pfm(tmp_path / "no" / "such" / "folder.pfm", np.zeros((2, 2), np.float32))


@pytest.mark.parametrize(
    "array, message",
    [
        (np.zeros((2, 2, 3), np.float32), "expected a 2-D floating-point numpy array"),
        (np.zeros((2, 2), np.int32), "expected a 2-D floating-point numpy array"),
        (np.zeros((0, 3), np.float32), "cannot hold an empty image"),
    ],
)
def test_write_pfm_refuses(tmp_path, array, message):
    with pytest.raises(ValueError, match=message):
        jem.write_pfm(tmp_path / "x.pfm", array)
    assert not (tmp_path / "x.pfm").exists()


@pytest.mark.parametrize("f, baseline, doffs", [(0, 1, 0), (1, -1, 0), (float("nan"), 1, 0), (1, 1, float("inf"))])
def test_depth_refuses_a_bad_camera(f, baseline, doffs):
    with pytest.raises(ValueError, match="must be positive and finite"):
        jem.depth(np.zeros((2, 2), np.float32), f, baseline, doffs)
