"""examples/batch_dask.py writes what `jem batch` writes, on two trainingQ scenes."""

import re
import subprocess
import sys
from pathlib import Path

from conftest import SCENES

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "batch_dask.py"


def mirror(data, dest):
    """Real scene folders holding symbolic links to the data's input files: results land in `dest`, never in
    the data set."""
    for scene in SCENES:
        (dest / scene).mkdir(parents=True)
        for name in ("im0.png", "im1.png", "calib.txt"):
            (dest / scene / name).symlink_to(data / scene / name)
    return dest


def test_dask_example_writes_jem_batch_s_files(tmp_path, cli, training_q):
    before = {s: sorted(p.name for p in (training_q / s).iterdir()) for s in SCENES}
    by_cli = mirror(training_q, tmp_path / "cli")
    by_dask = mirror(training_q, tmp_path / "dask")
    cli("batch", by_cli, "--alg", "PY", "--threads", "2")
    proc = subprocess.run(
        [sys.executable, str(EXAMPLE), str(by_dask), "--alg", "PY", "--workers", "1", "--threads", "2"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    assert "2 of 2 scenes" in proc.stdout
    for scene in SCENES:
        written = sorted(p.name for p in (by_dask / scene).iterdir())
        assert written == sorted(p.name for p in (by_cli / scene).iterdir())
        assert written == ["calib.txt", "configPY.toml", "disp0PY.pfm", "im0.png", "im1.png", "timePY.txt"]
        assert (by_dask / scene / "disp0PY.pfm").read_bytes() == (by_cli / scene / "disp0PY.pfm").read_bytes()
        assert re.fullmatch(r"\d+\.\d{6}\n", (by_dask / scene / "timePY.txt").read_text())
        # The same configuration, recorded under each command's own line.
        drop_command = lambda p: re.sub(r"(?m)^# command: .*\n", "", p.read_text())  # noqa: E731
        assert drop_command(by_dask / scene / "configPY.toml") == drop_command(by_cli / scene / "configPY.toml")
        assert "# command: batch_dask.py " in (by_dask / scene / "configPY.toml").read_text()
    after = {s: sorted(p.name for p in (training_q / s).iterdir()) for s in SCENES}
    assert after == before, "nothing is written into the data set"


def test_dask_example_reports_a_bad_scene_and_goes_on(tmp_path, training_q):
    data = mirror(training_q, tmp_path / "data")
    (data / SCENES[0] / "calib.txt").unlink()
    (data / SCENES[0] / "calib.txt").write_text("ndisp=oops\n")
    proc = subprocess.run(
        [sys.executable, str(EXAMPLE), str(data / SCENES[0]), str(data / SCENES[1]), "--alg", "PY", "--threads", "2",
         "--set", "downscale=2"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert "1 of 2 scenes" in proc.stdout
    assert re.search(rf"error: .*{SCENES[0]}: invalid literal for int", proc.stderr), proc.stderr
    assert not (data / SCENES[0] / "disp0PY.pfm").exists() and (data / SCENES[1] / "disp0PY.pfm").exists()
