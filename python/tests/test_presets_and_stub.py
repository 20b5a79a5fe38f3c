"""The shipped configs by name (`config="fast"`), the stub's info dict against the module's, and a matcher's
workers kept from call to call."""

import ast
import os
import time

import numpy as np
import pytest
from conftest import REPO, SYNTH

import jem

CONFIGS = REPO / "configs"


def test_the_presets_are_the_shipped_configs():
    assert jem.preset_names() == sorted(p.stem for p in CONFIGS.glob("*.toml"))
    for name in jem.preset_names():
        # Every parameter, defaults included: the preset is exactly its file.
        assert jem.config_record("c", config=name) == jem.config_record("c", config=CONFIGS / f"{name}.toml"), name
    with_set = {"meanfield.iterations": 1}
    assert (jem.config_record("c", config="fast", overrides=with_set)
            == jem.config_record("c", config=str(CONFIGS / "fast.toml"), overrides=with_set))


def test_a_preset_matches_as_its_file_does(tmp_path, cli, synth_pair):
    cli(SYNTH / "im0.png", SYNTH / "im1.png", "-o", tmp_path / "cli.pfm", "--ndisp", "48",
        "--config", CONFIGS / "fast.toml")
    by_name = jem.Matcher(ndisp=48, config="fast").match(*synth_pair)
    np.testing.assert_array_equal(by_name, jem.read_pfm(tmp_path / "cli.pfm"))
    np.testing.assert_array_equal(by_name, jem.match(*synth_pair, ndisp=48, config=CONFIGS / "fast.toml"))


def test_a_file_of_a_preset_s_name_is_read_and_other_names_are_paths(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(FileNotFoundError, match="fastest"):
        jem.config_record("c", config="fastest")
    (tmp_path / "fast").write_text('model = "wta"\n')
    assert 'model = "wta"' in jem.config_record("c", config="fast")


def stub_keys(name):
    """The keys the stub's TypedDict `name` declares."""
    tree = ast.parse((REPO / "python" / "jem.pyi").read_text())
    cls = next(n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == name)
    return {s.target.id for s in cls.body if isinstance(s, ast.AnnAssign)}


def test_the_stub_declares_every_info_key(synth_pair):
    _, info = jem.Matcher(ndisp=48, temporal=True).match(*synth_pair, return_info=True)
    assert set(info) == stub_keys("MatchInfo")
    assert set(info["checks"]) == stub_keys("PairChecks")


def threads_of_this_process():
    return len(os.listdir("/proc/self/task"))


@pytest.mark.skipif(not os.path.isdir("/proc/self/task"), reason="counts threads in /proc")
def test_a_matcher_keeps_its_workers(synth_pair):
    matcher = jem.Matcher(ndisp=48, threads=3, overrides={"meanfield.iterations": 1})
    before = threads_of_this_process()
    first = matcher.match(*synth_pair)
    time.sleep(0.2)  # a pool dropped at the call's end would have let its threads go by now
    started = threads_of_this_process()
    assert started >= before + 3
    for _ in range(3):
        np.testing.assert_array_equal(matcher.match(*synth_pair), first)
    assert threads_of_this_process() == started
    np.testing.assert_array_equal(first, jem.match(*synth_pair, ndisp=48, overrides={"meanfield.iterations": 1}))
