"""Special files as outputs, arrays too large for the memory limit, thread counts, byte orders, the mappings and
float types the stub promises, and override values of the wrong type."""

import os
import stat
import subprocess
import sys
import types
from pathlib import Path

import numpy as np
import pytest

import jem

SMALL = np.zeros((16, 40, 3), np.uint8)


def test_write_pfm_refuses_a_device_node_or_a_fifo(tmp_path):
    """A rename would replace a device or a FIFO with a plain file (as root, `jem.write_pfm('/dev/null', a)` the
    system's /dev/null): refused, and the file is left as it is."""
    fifo = tmp_path / "fifo.pfm"
    os.mkfifo(fifo)
    link = tmp_path / "null.pfm"
    link.symlink_to("/dev/null")
    specials = [(fifo, stat.S_ISFIFO), (link, stat.S_ISCHR)]
    if os.geteuid() == 0:
        node = tmp_path / "mynull"
        os.mknod(node, 0o644 | stat.S_IFCHR, os.makedev(1, 3))
        specials.append((node, stat.S_ISCHR))
    for path, kind in specials:
        with pytest.raises(ValueError, match=f"{path}: is a .*, not a regular file"):
            jem.write_pfm(path, np.zeros((2, 2), np.float32))
        assert kind(os.stat(path).st_mode), f"{path} was replaced"
    assert link.is_symlink()
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(p.name for p, _ in specials), "no temporary file"


def run_python(code, limit_address_space=None):
    """Runs `code` in a new interpreter (its peak memory its own), optionally under an address-space limit."""
    prelude = "import resource, numpy as np, jem\n"
    if limit_address_space:
        prelude += f"resource.setrlimit(resource.RLIMIT_AS, ({limit_address_space}, {limit_address_space}))\n"
    return subprocess.run([sys.executable, "-c", prelude + code], capture_output=True, text=True, timeout=300)


def test_memory_is_checked_before_the_arrays_are_copied():
    """An 8000×8000×3 input with max_memory=64 MiB is refused from its shape, before a copy (which takes ~2 GB)."""
    proc = run_python(
        "a = np.broadcast_to(np.uint8(7), (8000, 8000, 3))\n"
        "before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss\n"
        "try:\n"
        "    jem.match(a, a, ndisp=64, max_memory=64 << 20)\n"
        "except MemoryError as e:\n"
        "    print('MemoryError', e)\n"
        "print('grew', (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before) // 1024, 'MiB')\n"
    )
    assert proc.returncode == 0, proc.stderr
    assert "MemoryError" in proc.stdout, proc.stdout
    grew = int(proc.stdout.split("grew ")[1].split()[0])
    assert grew < 50, proc.stdout


@pytest.mark.parametrize("max_memory", [None, 1 << 40])
def test_an_allocation_failure_is_a_memory_error_not_an_abort(max_memory):
    """A 25000×25000×3 (broadcast) pair under a 2.5 GB address-space limit: a MemoryError and the interpreter alive,
    never an abort ("memory allocation of 1875000000 bytes failed", SIGABRT). The default limit stays within the
    address space; with a larger one given, the copy itself fails, as a MemoryError."""
    proc = run_python(
        "a = np.broadcast_to(np.uint8(7), (25000, 25000, 3))\n"
        "try:\n"
        f"    jem.match(a, a, ndisp=64, max_memory={max_memory})\n"
        "except MemoryError as e:\n"
        "    print('MemoryError', e)\n"
        "print('alive')\n",
        limit_address_space=2500 * 10**6,
    )
    assert proc.returncode == 0, (proc.returncode, proc.stderr)
    assert "MemoryError" in proc.stdout and "alive" in proc.stdout, proc.stdout


@pytest.mark.parametrize("threads", [1000, 5000])
def test_threads_are_capped_as_on_the_command_line(threads, cli, tmp_path):
    """Thousands of threads only add switching (or fail to start): refused with the bound `--threads` has."""
    with pytest.raises(ValueError, match=rf"invalid threads = {threads} \(expected 1 to \d+ \(4 per core"):
        jem.match(SMALL, SMALL, ndisp=8, threads=threads)
    proc = cli("eval", tmp_path, "--alg", "A", "--threads", threads, check=False)
    assert proc.returncode == 2 and f"invalid --threads = {threads} (expected 1 to " in proc.stderr


def test_big_endian_uint16_is_read_as_its_values(synth_pair):
    """`>u2` arrays (FITS, network data) give the same map as `<u2` ones."""
    native = [v.astype("<u2") * 257 for v in synth_pair]
    swapped = [v.astype(">u2") for v in native]
    assert swapped[0].dtype.byteorder in "><" and not swapped[0].dtype.isnative
    np.testing.assert_array_equal(jem.match(*swapped, ndisp=48), jem.match(*native, ndisp=48))
    np.testing.assert_array_equal(jem.match(swapped[0][..., 0], swapped[1][..., 0], ndisp=48),
                                  jem.match(native[0][..., 0], native[1][..., 0], ndisp=48))


def test_any_mapping_is_a_config_or_overrides(synth_pair):
    """The stub promises Mapping: a `types.MappingProxyType` (also nested in a config) is one."""
    left, right = synth_pair
    want = jem.match(left, right, ndisp=48, config={"meanfield": {"iterations": 1}}, overrides={"model": "wta"})
    proxy = types.MappingProxyType
    got = jem.match(left, right, ndisp=48, config=proxy({"meanfield": proxy({"iterations": 1})}),
                    overrides=proxy({"model": "wta"}))
    np.testing.assert_array_equal(got, want)
    with pytest.raises(ValueError, match="overrides: expected a mapping"):
        jem.match(left, right, ndisp=48, overrides=[("model", "wta")])


def test_float16_and_other_floats_are_written_and_converted(tmp_path):
    """The stub promises np.floating: float16 (and longdouble, big-endian float32) are converted to float32."""
    values = np.array([[0.5, 1.25], [np.inf, 65504.0]], np.float16)
    for dtype in (np.float16, np.longdouble, ">f4"):
        jem.write_pfm(tmp_path / "x.pfm", values.astype(dtype))
        np.testing.assert_array_equal(jem.read_pfm(tmp_path / "x.pfm"), values.astype(np.float32))
        np.testing.assert_array_equal(jem.depth(values.astype(dtype), 2.0, 3.0),
                                      jem.depth(values.astype(np.float32), 2.0, 3.0))


def test_an_absurd_override_says_what_is_wrong(tmp_path, cli):
    """An override of 1e30 says what the key takes (not "invalid type: floating point …, expected usize")."""
    for value, message in [
        (1e30, r"`meanfield.iterations` takes a whole number >= 0 \(like 5\), not 1e\+30"),
        (10**30, r"meanfield.iterations: 1000000000000000000000000000000 is too large"),
    ]:
        with pytest.raises(ValueError, match=message):
            jem.match(SMALL, SMALL, ndisp=8, overrides={"meanfield.iterations": value})
    proc = cli("config", "--set", "meanfield.iterations=1e30", check=False)
    assert proc.stderr == "error: --set: `meanfield.iterations` takes a whole number >= 0 (like 5), not 1e30\n"


def test_the_dask_example_refuses_a_fifo_for_a_result(tmp_path, cli):
    """examples/batch_dask.py renames its files into place itself: a FIFO where disp0NAME.pfm goes is refused (that
    scene fails, the other runs) and left as it is."""
    for seed in (1, 2):
        cli("synth", tmp_path / f"s{seed}", "--width", 64, "--height", 48, "--ndisp", 16, "--seed", seed)
    fifo = tmp_path / "s1" / "disp0PY.pfm"
    os.mkfifo(fifo)
    example = Path(__file__).resolve().parents[1] / "examples" / "batch_dask.py"
    proc = subprocess.run(
        [sys.executable, str(example), str(tmp_path), "--alg", "PY", "--workers", "1", "--threads", "1",
         "--set", "model=wta"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert f"{fifo}: not a regular file" in proc.stderr, proc.stderr
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)
    assert not (tmp_path / "s1" / "timePY.txt").exists() and (tmp_path / "s2" / "disp0PY.pfm").is_file()
