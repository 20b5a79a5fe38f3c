"""jem.match gives the command line's disparity map, byte for byte, for every kind of input and setting."""

import sys
import warnings

import numpy as np
import pytest
from conftest import REPO, SCENES, SYNTH, calib_ndisp, pfm_bytes

import jem


def write_pnm(path, array):
    """A binary PGM (H×W) or PPM (H×W×3), 8 or 16 bit (big-endian, as the format says)."""
    magic = b"P5" if array.ndim == 2 else b"P6"
    maxval = 255 if array.dtype == np.uint8 else 65535
    h, w = array.shape[:2]
    path.write_bytes(b"%s\n%d %d\n%d\n" % (magic, w, h, maxval) + array.astype(array.dtype.newbyteorder(">")).tobytes())
    return path


def test_example_with_its_calib_matches_the_cli(tmp_path, cli, synth_pair):
    cli(SYNTH / "im0.png", SYNTH / "im1.png", "-o", tmp_path / "cli.pfm")
    disp, info = jem.match(*synth_pair, calib_ndisp=calib_ndisp(SYNTH / "calib.txt"), return_info=True)
    assert disp.dtype == np.float32 and disp.shape == synth_pair[0].shape[:2]
    assert (info["ndisp"], info["ndisp_measured"], info["tiled"]) == (48, False, False)
    assert pfm_bytes(tmp_path, disp) == (tmp_path / "cli.pfm").read_bytes()
    np.testing.assert_array_equal(disp, jem.read_pfm(tmp_path / "cli.pfm"))


def test_measured_range_matches_the_cli(tmp_path, cli, synth_pair):
    # Without a calib.txt beside the images, jem measures the range on the pair; so does ndisp=None.
    for name in ("im0.png", "im1.png"):
        (tmp_path / name).symlink_to(SYNTH / name)
    cli(tmp_path / "im0.png", tmp_path / "im1.png", "-o", tmp_path / "cli.pfm")
    disp, info = jem.match(*synth_pair, return_info=True)
    assert info["ndisp_measured"]
    assert pfm_bytes(tmp_path, disp) == (tmp_path / "cli.pfm").read_bytes()


def test_tiles_config_file_and_overrides_match_the_cli(tmp_path, cli, synth_pair):
    config = REPO / "configs" / "jem-lrc.toml"
    cli(SYNTH / "im0.png", SYNTH / "im1.png", "-o", tmp_path / "cli.pfm", "--max-memory", "50M",
        "--config", config, "--set", "meanfield.iterations=2", "--set", "model=jem")
    disp, info = jem.match(*synth_pair, ndisp=48, config=config, overrides={"meanfield.iterations": 2, "model": "jem"},
                           max_memory=50 << 20, return_info=True)
    assert info["tiled"]
    assert pfm_bytes(tmp_path, disp) == (tmp_path / "cli.pfm").read_bytes()


@pytest.mark.skipif(sys.version_info < (3, 11), reason="tomllib is Python 3.11+")
def test_config_dict_is_the_toml_file(tmp_path, synth_pair):
    import tomllib

    path = REPO / "configs" / "jem-lrc.toml"
    settings = tomllib.loads(path.read_text())
    from_file = jem.match(*synth_pair, ndisp=48, config=path, overrides={"meanfield.iterations": 1})
    from_dict = jem.match(*synth_pair, ndisp=48, config=settings, overrides={"meanfield.iterations": "1"})
    assert pfm_bytes(tmp_path, from_file) == pfm_bytes(tmp_path, from_dict, "dict.pfm")
    # And the settings matter: the defaults give another map.
    assert not np.array_equal(from_file, jem.match(*synth_pair, ndisp=48, overrides={"meanfield.iterations": 1}))


@pytest.mark.parametrize("scene", SCENES)
def test_training_q_scene_matches_the_cli(tmp_path, cli, training_q, scene):
    # The data is read in place; only the outputs go to the temporary folder.
    folder = training_q / scene
    cli(folder / "im0.png", folder / "im1.png", "-o", tmp_path / "cli.pfm", "--threads", "2")
    left, right = jem.read_image(folder / "im0.png"), jem.read_image(folder / "im1.png")
    disp = jem.match(left, right, calib_ndisp=calib_ndisp(folder / "calib.txt"), threads=2)
    assert pfm_bytes(tmp_path, disp) == (tmp_path / "cli.pfm").read_bytes()


def test_grey_and_16_bit_inputs_match_the_cli(tmp_path, cli, synth_pair):
    left, right = synth_pair
    grey = [write_pnm(tmp_path / f"g{i}.pgm", v[..., 1].copy()) for i, v in enumerate((left, right))]
    cli(*grey, "--ndisp", 48, "-o", tmp_path / "grey.pfm")
    disp = jem.match(left[..., 1], right[..., 1], ndisp=48)
    assert pfm_bytes(tmp_path, disp) == (tmp_path / "grey.pfm").read_bytes()
    # A grey view is used as RGB with equal channels.
    same = jem.match(np.repeat(left[..., 1:2], 3, axis=2), right[..., 1], ndisp=48)
    np.testing.assert_array_equal(disp, same)

    # 16 bit, with low bits that do not survive the division by 257: the same conversion as the PNG loader.
    rng = np.random.default_rng(0)
    deep = [(v.astype(np.uint16) * 257 + rng.integers(0, 200, v.shape)).astype(np.uint16) for v in (left, right)]
    ppm = [write_pnm(tmp_path / f"c{i}.ppm", v) for i, v in enumerate(deep)]
    cli(*ppm, "--ndisp", 48, "-o", tmp_path / "deep.pfm")
    assert jem.read_image(ppm[0]).dtype == np.uint16
    assert pfm_bytes(tmp_path, jem.match(*deep, ndisp=48)) == (tmp_path / "deep.pfm").read_bytes()


def test_non_contiguous_inputs_give_the_same_map(synth_pair):
    left, right = synth_pair
    expected = jem.match(left, right, ndisp=48)
    bgr = [np.ascontiguousarray(v[..., ::-1]) for v in (left, right)]
    flipped = jem.match(bgr[0][..., ::-1], bgr[1][..., ::-1], ndisp=48)  # negative channel stride (OpenCV's BGR)
    fortran = jem.match(np.asfortranarray(left), np.asfortranarray(right), ndisp=48)
    wide = [np.repeat(v, 2, axis=1) for v in (left, right)]
    strided = jem.match(wide[0][:, ::2], wide[1][:, ::2], ndisp=48)  # every other column of a wider buffer
    assert not bgr[0][..., ::-1].flags.c_contiguous and not wide[0][:, ::2].flags.c_contiguous
    for got in (flipped, fortran, strided):
        np.testing.assert_array_equal(got, expected)


def test_confidence_and_info(synth_pair):
    disp, conf, info = jem.match(*synth_pair, ndisp=48, confidence=True, return_info=True)
    assert conf.dtype == np.float32 and conf.shape == disp.shape
    assert np.all((conf >= 0) & (conf <= 1))
    assert np.isfinite(disp).mean() > 0.9 and np.nanmax(disp[np.isfinite(disp)]) < 48
    assert set(info) == {"ndisp", "ndisp_measured", "tiled", "noise", "timings", "seconds", "memory_planned",
                         "peak_rss", "frame", "frames_averaged", "shift", "exposure", "checks", "warnings"}
    # jem.match remembers nothing: no frame kind; a good pair raises no warning.
    assert info["frame"] is None and info["frames_averaged"] is None and info["shift"] is None
    assert info["exposure"] is None
    assert info["warnings"] == [] and set(info["checks"]) >= {"negative_share", "vertical_px", "textured_share"}
    assert len(info["noise"]) == 2 and info["timings"] and all(t >= 0 for t in info["timings"].values())
    assert 0 < info["seconds"] and info["memory_planned"] > 0 and info["peak_rss"] > 0
    off = jem.match(*synth_pair, ndisp=48, overrides={"condition.enabled": False}, return_info=True)[1]
    assert off["noise"] is None


def test_a_segment_count_the_image_cannot_hold_warns(synth_pair):
    # Held to pixels / post.sps.min_support, as jem does (which says so on stderr).
    small = tuple(view[:48, :64] for view in synth_pair)
    with pytest.warns(UserWarning, match=r"post\.sps\.segments = 100000 .*using 307"):
        held = jem.match(*small, ndisp=16, overrides={"post.sps.segments": 100000})
    assert np.isfinite(held).all() and held.max() < 16
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the bound itself: no warning
        jem.match(*small, ndisp=16, overrides={"post.sps.segments": 307})


def test_version_is_the_core_crate_version():
    text = (REPO / "Cargo.toml").read_text()
    assert f'version = "{jem.__version__}"' in text.split("[dependencies]")[0]


def test_min_confidence_matches_the_cli(tmp_path, cli, synth_pair):
    cli(SYNTH / "im0.png", SYNTH / "im1.png", "-o", tmp_path / "cli.pfm", "--min-confidence", "0.8")
    disp = jem.match(*synth_pair, calib_ndisp=calib_ndisp(SYNTH / "calib.txt"), min_confidence=0.8)
    assert pfm_bytes(tmp_path, disp) == (tmp_path / "cli.pfm").read_bytes()
    assert 0 < np.isinf(disp).sum() < disp.size
    with pytest.raises(ValueError, match="min_confidence"):
        jem.match(*synth_pair, ndisp=48, min_confidence=2.0)


def test_min_disp_matches_the_cli(tmp_path, cli, synth_pair):
    cli(SYNTH / "im0.png", SYNTH / "im1.png", "-o", tmp_path / "cli.pfm", "--ndisp", "40", "--min-disp", "8")
    disp = jem.match(*synth_pair, ndisp=40, min_disp=8)
    assert pfm_bytes(tmp_path, disp) == (tmp_path / "cli.pfm").read_bytes()
    assert np.isinf(disp[:, :8]).all() and np.nanmin(np.where(np.isinf(disp), np.nan, disp)) >= 7.5
    with pytest.raises(ValueError, match="min_disp"):
        jem.match(*synth_pair, ndisp=40, min_disp=-1)
