"""Memory the module allocates for a caller: checked against ``max_memory`` from the shapes (or a file's header)
before anything is allocated, or allocated fallibly, so that a call too large raises MemoryError instead of aborting
the interpreter. Each call runs in a child process under an address-space limit (``RLIMIT_AS``), where a failed
allocation that aborts shows up as exit code 134 (SIGABRT) instead of killing pytest."""

import os
import stat
import subprocess
import sys
import struct
import textwrap
import zlib

import pytest

import jem

# The address space the children get: room for Python, numpy and the module, far less than the arrays asked for.
LIMIT = 3_000_000_000


def run_limited(code, tmp_path, timeout=300):
    """Runs ``code`` (after ``import numpy as np, jem``) in a child under ``LIMIT`` bytes of address space; returns
    (exit code, stdout + stderr)."""
    script = "import resource\n" f"resource.setrlimit(resource.RLIMIT_AS, ({LIMIT}, {LIMIT}))\n" "import numpy as np, jem\n"
    script += textwrap.dedent(code)
    path = tmp_path / "child.py"
    path.write_text(script)
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    proc = subprocess.run([sys.executable, str(path)], capture_output=True, text=True, env=env, cwd=tmp_path, timeout=timeout)
    return proc.returncode, proc.stdout + proc.stderr


def expect_memory_error(call, tmp_path, setup=""):
    """``call`` raises MemoryError in the child (and the child ends normally)."""
    code = setup + textwrap.dedent(
        f"""
        try:
            {call}
        except MemoryError as e:
            print("MemoryError:", e)
        else:
            print("no error")
        """
    )
    rc, out = run_limited(code, tmp_path)
    assert rc == 0 and "MemoryError:" in out, f"{call}: exit {rc}: {out[-2000:]}"
    return out


HUGE = "big = np.broadcast_to(np.float32(1), (40000, 40000))\n"


@pytest.mark.parametrize(
    "call",
    [
        "jem.depth(big, 100.0, 1.0)",
        "jem.colorize(big)",
        "jem.cloud(big, np.broadcast_to(np.uint8(1), (40000, 40000)), 100.0, 1.0, 0.0, 0.0)",
        "jem.write_pfm('big.pfm', big)",
    ],
)
def test_a_map_too_large_raises_memory_error_not_an_abort(tmp_path, call):
    out = expect_memory_error(call, tmp_path, HUGE)
    assert "40000" in out, out
    assert not (tmp_path / "big.pfm").exists()


def save_calibration(path, size):
    """A pinhole rig's OpenCV calibration for views of ``size``."""
    w, h = size
    m = lambda name, rows, cols, data: f"{name}: !!opencv-matrix\n   rows: {rows}\n   cols: {cols}\n   dt: d\n   data: {data}\n"
    k = f"[ 80., 0., {(w - 1) / 2}, 0., 80., {(h - 1) / 2}, 0., 0., 1. ]"
    d = "[ 0., 0., 0., 0., 0. ]"
    text = "%YAML:1.0\n---\n" + m("K1", 3, 3, k) + m("D1", 1, 5, d) + m("K2", 3, 3, k) + m("D2", 1, 5, d)
    text += m("R", 3, 3, "[ 1., 0., 0., 0., 1., 0., 0., 0., 1. ]") + m("T", 3, 1, "[ -0.25, 0., 0. ]")
    path.write_text(text)
    return path


def test_rectification_too_large_raises_memory_error(tmp_path):
    save_calibration(tmp_path / "cal.yml", (64, 48))
    expect_memory_error("jem.rectify_maps('cal.yml', size=(30000, 30000))", tmp_path)
    # 20000² views: checked from the shapes before anything is copied or rectified.
    views = "v = np.broadcast_to(np.uint8(1), (20000, 20000, 3))\n"
    expect_memory_error("jem.rectify('cal.yml', v, v)", tmp_path, views)
    # A limit the caller gives is held too, without any address-space limit.
    v = __import__("numpy").zeros((600, 800, 3), "uint8")
    with pytest.raises(MemoryError, match="memory limit"):
        jem.rectify(save_calibration(tmp_path / "small.yml", (800, 600)), v, v, max_memory=10_000_000)
    with pytest.raises(MemoryError, match="memory limit"):
        jem.rectify_maps(tmp_path / "small.yml", size=(800, 600), max_memory=1_000_000)


def test_max_memory_bounds_the_helpers():
    import numpy as np

    disp = np.ones((1000, 1000), np.float32)
    for call in (
        lambda: jem.depth(disp, 100.0, 1.0, max_memory=1_000_000),
        lambda: jem.colorize(disp, max_memory=1_000_000),
        lambda: jem.cloud(disp, np.zeros((1000, 1000), np.uint8), 100.0, 1.0, 0.0, 0.0, max_memory=1_000_000),
    ):
        with pytest.raises(MemoryError, match="1000x1000"):
            call()
    assert jem.depth(disp, 100.0, 1.0, max_memory=100_000_000).shape == (1000, 1000)


def png_declaring(width, height, path, rows=None):
    """A small grey PNG whose header declares ``width`` × ``height``: its rows all zero, compressed; only the first
    ``rows`` of them when given (a file cut short)."""
    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    row = b"\x00" * (width + 1)
    body = zlib.compressobj(9)
    data = b"".join(body.compress(row) for _ in range(height if rows is None else rows)) + body.flush()
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", data) + chunk(b"IEND", b""))
    return path


def test_read_image_checks_the_header_against_the_memory_limit(tmp_path):
    png = png_declaring(20000, 20000, tmp_path / "bomb.png")
    assert png.stat().st_size < 1_000_000, "a small file"
    with pytest.raises(MemoryError, match="bomb.png"):
        jem.read_image(png, max_memory=300_000_000)
    # The default limit is the command line's: 80 % of what an address-space limit leaves; a header declaring
    # 60000 × 60000 (3.6 GB of samples) is refused from the header, before the decoder sees the data.
    png_declaring(60000, 60000, tmp_path / "huge.png", rows=4)
    out = expect_memory_error("jem.read_image('huge.png')", tmp_path)
    assert "huge.png" in out and "60000x60000" in out
    small = png_declaring(64, 48, tmp_path / "small.png")
    assert jem.read_image(small, max_memory=1_000_000).shape == (48, 64)


@pytest.mark.parametrize("target", ["/dev/zero", "/dev/urandom", "link", "fifo"])
def test_read_image_refuses_what_is_not_a_regular_file(tmp_path, target):
    path = tmp_path / "img.png"
    if target == "link":
        path.symlink_to("/dev/zero")
    elif target == "fifo":
        os.mkfifo(path)
    else:
        path = target
    code = f"""
    try:
        jem.read_image({str(path)!r})
    except ValueError as e:
        print("ValueError:", e)
    """
    try:
        rc, out = run_limited(code, tmp_path, timeout=60)
    except subprocess.TimeoutExpired:
        pytest.fail(f"read_image({target}) did not return")
    assert rc == 0 and "not a regular file" in out, f"exit {rc}: {out[-2000:]}"
    if target == "fifo":
        assert stat.S_ISFIFO(os.stat(path).st_mode)
