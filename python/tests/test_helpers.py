"""The helpers around matching give what the command line writes: RGBA arrays read as RGBA files are, jem.cloud
the points and colours of --cloud's PLY, jem.colorize the PNG of jem viz."""

import struct
import zlib

import numpy as np
import pytest
from conftest import SYNTH

import jem


def write_png(path, array):
    """An 8-bit PNG of an H×W×3 or H×W×4 uint8 array (no filter, one IDAT): enough for these tests."""
    h, w, c = array.shape
    colour_type = {3: 2, 4: 6}[c]

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    rows = b"".join(b"\0" + array[y].tobytes() for y in range(h))
    header = struct.pack(">IIBBBBB", w, h, 8, colour_type, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(rows))
                     + chunk(b"IEND", b""))
    return path


def calib(path):
    """A calib.txt's cam0 (f, cx, cy), baseline and doffs."""
    values = dict(line.split("=", 1) for line in path.read_text().splitlines() if "=" in line)
    cam0 = [float(v) for v in values["cam0"].strip("[]").replace(";", " ").split()]
    return {"f": cam0[0], "cx": cam0[2], "cy": cam0[5], "baseline": float(values["baseline"]),
            "doffs": float(values.get("doffs", 0))}


def read_ply(path):
    """The vertices of a binary little-endian PLY with x y z float and red green blue uchar."""
    data = path.read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode()
    assert "property float x\nproperty float y\nproperty float z\nproperty uchar red" in header
    vertex = np.dtype([("xyz", "<f4", 3), ("rgb", "u1", 3)])
    return np.frombuffer(data[end:], vertex)


def test_rgba_arrays_match_the_cli_on_rgba_files(tmp_path, cli, synth_pair):
    rng = np.random.default_rng(1)
    rgba = [np.concatenate([v, rng.integers(0, 256, v.shape[:2] + (1,), np.uint8)], axis=2) for v in synth_pair]
    files = [write_png(tmp_path / f"im{i}.png", v) for i, v in enumerate(rgba)]
    cli(*files, "--ndisp", 48, "-o", tmp_path / "cli.pfm")
    disp = jem.match(*rgba, ndisp=48)
    np.testing.assert_array_equal(disp, jem.read_pfm(tmp_path / "cli.pfm"))
    # The alpha channel is dropped: the RGB arrays give the same map.
    np.testing.assert_array_equal(disp, jem.match(*synth_pair, ndisp=48))


def test_cloud_is_the_ply_the_cli_writes(tmp_path, cli, synth_pair):
    cli(SYNTH / "im0.png", SYNTH / "im1.png", "-o", tmp_path / "d.pfm", "--cloud", tmp_path / "c.ply")
    disp = jem.read_pfm(tmp_path / "d.pfm")
    points, colours = jem.cloud(disp, synth_pair[0], **calib(SYNTH / "calib.txt"))
    assert points.dtype == np.float32 and colours.dtype == np.uint8
    ply = read_ply(tmp_path / "c.ply")
    assert points.shape == colours.shape == (len(ply), 3) and len(ply) == np.isfinite(disp).sum()
    np.testing.assert_array_equal(points, ply["xyz"])
    np.testing.assert_array_equal(colours, ply["rgb"])
    # Z = f·B / (d + doffs) and the colours of the valid pixels, in row order.
    y, x = np.nonzero(np.isfinite(disp))
    np.testing.assert_array_equal(colours, synth_pair[0][y, x])
    c = calib(SYNTH / "calib.txt")
    np.testing.assert_allclose(points[:, 2], c["f"] * c["baseline"] / (disp[y, x] + c["doffs"]), rtol=1e-6)


def test_cloud_refuses_a_bad_camera_or_another_size(synth_pair):
    disp = np.ones(synth_pair[0].shape[:2], np.float32)
    with pytest.raises(ValueError, match="must be positive and finite"):
        jem.cloud(disp, synth_pair[0], f=0, baseline=1, cx=0, cy=0)
    with pytest.raises(ValueError, match=r"left is 320×240 but disp is 319×240"):
        jem.cloud(disp[:, 1:], synth_pair[0], f=1, baseline=1, cx=0, cy=0)


@pytest.mark.parametrize("bounds", [(), ("--vmin", 5, "--vmax", 30)])
def test_colorize_is_the_png_jem_viz_writes(tmp_path, cli, bounds):
    # A map with invalid pixels, in a folder without a calib.txt (whose vmin/vmax jem viz would use).
    rng = np.random.default_rng(2)
    disp = rng.uniform(0, 40, (30, 50)).astype(np.float32)
    disp[3, :7] = np.inf
    jem.write_pfm(tmp_path / "d.pfm", disp)
    cli("viz", tmp_path / "d.pfm", "-o", tmp_path / "v.png", *bounds)
    kwargs = dict(zip(("vmin", "vmax"), bounds[1::2]))
    picture = jem.colorize(disp, **kwargs)
    assert picture.dtype == np.uint8 and picture.shape == (30, 50, 3)
    np.testing.assert_array_equal(picture, jem.read_image(tmp_path / "v.png"))
    assert (picture[3, :7] == 0).all()


def test_colorize_refuses_a_bad_range():
    disp = np.zeros((2, 2), np.float32)
    for kwargs in ({"vmin": 3, "vmax": 3}, {"vmin": 4, "vmax": 1}, {"vmin": float("nan")}):
        with pytest.raises(ValueError, match="vmin"):
            jem.colorize(disp, **kwargs)
