"""Shared fixtures: the `jem` binary the module is compared with, the shipped example, the Middlebury data."""

import os
import subprocess
from pathlib import Path

import pytest

import jem

REPO = Path(__file__).resolve().parents[2]
SYNTH = REPO / "examples" / "synth"
# As the Rust tests: $JEM_DATA holds MiddEval3/, default ../shared/middlebury beside the checkout.
DATA = Path(os.environ.get("JEM_DATA", REPO.parent / "shared" / "middlebury"))
TRAINING_Q = DATA / "MiddEval3" / "trainingQ"
# Two small trainingQ scenes (450×375 and 347×277): about 3 s a run on 2 cores.
SCENES = ("Teddy", "ArtL")


@pytest.fixture(scope="session")
def jem_bin():
    """The command-line binary built from the same checkout (`cargo build --release`; $JEM_BIN overrides)."""
    path = Path(os.environ.get("JEM_BIN", REPO / "target" / "release" / "jem"))
    if not path.is_file():
        pytest.fail(f"{path} not found: build it with `cargo build --release` (or point JEM_BIN at it)")
    return path


@pytest.fixture(scope="session")
def cli(jem_bin):
    """Runs `jem ARGS...` quietly; returns the completed process (check=False: error tests read stderr)."""

    def run(*args, check=True):
        proc = subprocess.run([str(jem_bin), *map(str, args), "--quiet"], capture_output=True, text=True)
        if check and proc.returncode != 0:
            raise AssertionError(f"jem {' '.join(map(str, args))} failed: {proc.stderr}")
        return proc

    return run


@pytest.fixture(scope="session")
def training_q():
    """The trainingQ folder; skipped with a notice when absent, unless JEM_REQUIRE_DATA=1 (CI) makes that fail."""
    if not all((TRAINING_Q / s / "im0.png").is_file() for s in SCENES):
        msg = f"Middlebury trainingQ not found at {TRAINING_Q} (set JEM_DATA)"
        if os.environ.get("JEM_REQUIRE_DATA") == "1":
            pytest.fail(msg)
        pytest.skip(msg)
    return TRAINING_Q


@pytest.fixture(scope="session")
def synth_pair():
    """The shipped example as the module reads it: uint8 H×W×3."""
    return jem.read_image(SYNTH / "im0.png"), jem.read_image(SYNTH / "im1.png")


def calib_ndisp(path):
    """The ndisp a calib.txt states."""
    for line in Path(path).read_text().splitlines():
        if line.startswith("ndisp="):
            return int(line.split("=", 1)[1])
    raise ValueError(f"{path}: no ndisp")


def pfm_bytes(tmp_path, disp, name="module.pfm"):
    """The bytes jem.write_pfm writes for `disp`."""
    path = tmp_path / name
    jem.write_pfm(path, disp)
    return path.read_bytes()
