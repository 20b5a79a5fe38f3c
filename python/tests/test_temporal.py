"""jem.Matcher: one configuration for many pairs, and the frames of a sequence remembered (the temporal model)."""

import numpy as np
import pytest

import jem


@pytest.fixture(scope="module")
def noisy_sequence(cli, tmp_path_factory):
    """A small synthetic still-camera sequence with fresh noise per frame, rendered by `jem synth --frames`."""
    seq = tmp_path_factory.mktemp("seq") / "still"
    cli("synth", seq, "--frames", "4", "--motion", "static", "--noise", "6", "--width", "128", "--height", "96")
    return seq


def test_a_temporal_matcher_gives_the_maps_jem_sequence_writes(cli, noisy_sequence, tmp_path):
    out = tmp_path / "out"
    cli("sequence", noisy_sequence, "-o", out)
    frames = jem.sequence_frames(noisy_sequence)
    assert [f[0] for f in frames] == ["000000", "000001", "000002", "000003"]
    matcher = jem.Matcher(temporal=True, calib_ndisp=48)
    kinds = []
    for stem, left, right in frames:
        disp, info = matcher.match(jem.read_image(left), jem.read_image(right), return_info=True)
        kinds.append(info["frame"])
        np.testing.assert_array_equal(disp, jem.read_pfm(out / f"{stem}.pfm"), err_msg=stem)
    assert kinds == ["first", "still", "still", "still"]
    assert info["frames_averaged"] == 4


def test_an_exposure_step_is_compensated_and_reported(cli, tmp_path):
    seq = tmp_path / "step"
    cli("synth", seq, "--frames", "3", "--noise", "4", "--width", "128", "--height", "96", "--exposure-step", "2:10")
    matcher = jem.Matcher(temporal=True, calib_ndisp=48)
    infos = [matcher.match(jem.read_image(l), jem.read_image(r), return_info=True)[1]
             for _, l, r in jem.sequence_frames(seq)]
    assert [i["frame"] for i in infos] == ["first", "still", "still"]
    assert infos[1]["exposure"] is None
    gain, offset = infos[2]["exposure"]
    assert abs(gain - 1.1) < 0.05 and abs(offset) < 3


def test_reset_starts_again_and_a_plain_matcher_forgets(noisy_sequence):
    (_, l0, r0), (_, l1, r1) = jem.sequence_frames(noisy_sequence)[:2]
    pairs = [(jem.read_image(l0), jem.read_image(r0)), (jem.read_image(l1), jem.read_image(r1))]
    temporal = jem.Matcher(ndisp=48, temporal=True)
    first = temporal.match(*pairs[0])
    temporal.match(*pairs[1])
    temporal.reset()
    again, info = temporal.match(*pairs[0], return_info=True)
    assert info["frame"] == "first"
    np.testing.assert_array_equal(again, first)
    plain = jem.Matcher(ndisp=48)
    _, info = plain.match(*pairs[1], return_info=True)
    assert info["frame"] is None
    np.testing.assert_array_equal(plain.match(*pairs[1]), jem.match(*pairs[1], ndisp=48))


def test_a_folder_that_is_no_sequence_is_named(tmp_path):
    (tmp_path / "left").mkdir()
    with pytest.raises(ValueError, match="right"):
        jem.sequence_frames(tmp_path)
