"""PFM and image files, depth, and matching from several Python threads."""

import threading
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest
from conftest import SYNTH, pfm_bytes

import jem


def test_pfm_round_trip_keeps_every_bit_in_middlebury_orientation(tmp_path):
    rng = np.random.default_rng(1)
    disp = rng.normal(20, 10, (5, 7)).astype(np.float32)
    disp[1, 2] = np.inf
    disp[3, 4] = -0.0
    data = pfm_bytes(tmp_path, disp)
    header = b"Pf\n7 5\n-1\n"
    assert data[: len(header)] == header and len(data) == len(header) + disp.size * 4
    # Rows bottom-up, little-endian: the file's first row is the array's last.
    np.testing.assert_array_equal(np.frombuffer(data[len(header) :], "<f4").reshape(5, 7)[::-1], disp)
    back = jem.read_pfm(tmp_path / "module.pfm")
    assert back.dtype == np.float32 and back.view(np.uint32).tolist() == disp.view(np.uint32).tolist()
    # float64 and non-contiguous input: rounded to float32, written in logical order.
    wide = np.repeat(disp.astype(np.float64), 2, axis=1)[:, ::2]
    assert pfm_bytes(tmp_path, wide, "wide.pfm") == data
    assert not list(tmp_path.glob(".*")), "no temporary file is left behind"


def test_read_pfm_reads_big_endian_and_colour_files(tmp_path):
    values = np.arange(6, dtype=np.float32).reshape(2, 3)
    (tmp_path / "be.pfm").write_bytes(b"Pf\n3 2\n1.0\n" + values[::-1].astype(">f4").tobytes())
    np.testing.assert_array_equal(jem.read_pfm(tmp_path / "be.pfm"), values)
    rgb = np.stack([values, values + 10, values + 20], axis=-1)
    (tmp_path / "rgb.pfm").write_bytes(b"PF\r\n3 2\r\n-1\r\n" + rgb[::-1].astype("<f4").tobytes())
    np.testing.assert_array_equal(jem.read_pfm(tmp_path / "rgb.pfm"), values)


def test_read_image_gives_the_file_s_pixels():
    left = jem.read_image(SYNTH / "im0.png")
    assert left.dtype == np.uint8 and left.shape == (240, 320, 3)
    # The PNG's own bytes: a 320×240 RGB image whose channels are not all equal.
    assert left.std() > 10 and not np.array_equal(left[..., 0], left[..., 2])


def test_depth_is_f_b_over_d_plus_doffs():
    disp = np.array([[10.0, np.inf], [-5.0, 0.5]], np.float32)
    z = jem.depth(disp, 1000.0, 100.0, doffs=5.0)
    assert z.dtype == np.float32
    np.testing.assert_array_equal(z, np.array([[1e5 / 15, np.inf], [np.inf, 1e5 / 5.5]], np.float32))
    # float64 input and the default doffs of 0: d = 0 is at infinity.
    np.testing.assert_array_equal(jem.depth(np.array([[0.0, 4.0]]), 2.0, 3.0), np.array([[np.inf, 1.5]], np.float32))


def test_thread_counts_and_python_threads_give_identical_maps(tmp_path, synth_pair):
    reference = pfm_bytes(tmp_path, jem.match(*synth_pair, ndisp=48, threads=1))
    assert pfm_bytes(tmp_path, jem.match(*synth_pair, ndisp=48, threads=2)) == reference
    assert pfm_bytes(tmp_path, jem.match(*synth_pair, ndisp=48, threads=3)) == reference
    with ThreadPoolExecutor(3) as pool:
        maps = list(pool.map(lambda t: jem.match(*synth_pair, ndisp=48, threads=t), [1, 2, None]))
    for i, disp in enumerate(maps):
        assert pfm_bytes(tmp_path, disp, f"{i}.pfm") == reference


def test_the_gil_is_released_while_matching(synth_pair):
    # A Python thread counts while the main thread is inside jem.match. Holding the GIL through the call would
    # stop it for the whole call (a switch needs the holder to run Python code); released, it keeps counting.
    ticks, done = [0], threading.Event()

    def count():
        while not done.is_set():
            ticks[0] += 1
            time.sleep(0.001)

    counter = threading.Thread(target=count)
    counter.start()
    try:
        time.sleep(0.05)
        before = ticks[0]
        _, info = jem.match(*synth_pair, ndisp=48, threads=1, return_info=True)
        during = ticks[0] - before
    finally:
        done.set()
        counter.join()
    # At 1 ms a tick, the call's seconds would allow ~1000/s; ask for a tenth of that.
    assert during >= 100 * info["seconds"], (during, info["seconds"])


def test_depth_stops_at_one_pixel_of_disparity_unless_told():
    disp = np.array([[0.001, 0.5, 1.0, 10.0]], np.float32)
    # f·B = 100: the depth of a one-pixel disparity is the default range, as jem --depth.
    np.testing.assert_array_equal(jem.depth(disp, 500.0, 0.2), np.array([[np.inf, np.inf, 100.0, 10.0]], np.float32))
    np.testing.assert_array_equal(jem.depth(disp, 500.0, 0.2, max_depth=float("inf"))[0, 1], np.float32(200.0))
    with pytest.raises(ValueError, match="max_depth"):
        jem.depth(disp, 500.0, 0.2, max_depth=-1.0)


def test_one_matcher_called_from_several_threads_serialises_the_calls(synth_pair):
    """Four threads matching through one Matcher each get the map (three of four got "Already borrowed"); the
    calls take turns, each waiting with the GIL released."""
    reference = jem.match(*synth_pair, ndisp=48)
    matcher = jem.Matcher(ndisp=48)
    with ThreadPoolExecutor(4) as pool:
        maps = list(pool.map(lambda _: matcher.match(*synth_pair), range(4)))
    assert len(maps) == 4
    for disp in maps:
        assert disp.view(np.uint32).tolist() == reference.view(np.uint32).tolist()


def test_reset_during_a_match_waits_for_it(synth_pair):
    """``reset()`` from another thread while a temporal matcher matches waits for the match in progress (it raised
    "Already borrowed"); every match still gives a map, each frame matched as a first frame or after the ones
    since the last reset."""
    matcher = jem.Matcher(ndisp=48, temporal=True)
    results, errors = [], []

    def frames():
        try:
            results.extend(matcher.match(*synth_pair, return_info=True) for _ in range(3))
        except Exception as e:  # noqa: BLE001 - the test reports whatever was raised
            errors.append(e)

    worker = threading.Thread(target=frames)
    worker.start()
    resets = 0
    while worker.is_alive():
        matcher.reset()
        resets += 1
        time.sleep(0.01)
    worker.join()
    assert not errors and resets > 0, errors
    assert len(results) == 3
    for disp, info in results:
        assert disp.shape == (240, 320) and info["frame"] in ("first", "still")
