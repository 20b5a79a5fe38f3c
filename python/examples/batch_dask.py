#!/usr/bin/env python3
"""`jem batch` for MiddEval3-style folders, scaled out on a Dask cluster (here a local one).

    python batch_dask.py DIR... --alg NAME [--config FILE] [--set KEY=VALUE]... [--workers N] [--threads T]

Every folder under DIR... holding im0.png, im1.png and calib.txt is a scene; each runs as one Dask task that calls
jem.match and writes what `jem batch DIR --alg NAME` writes for it, in the scene folder: disp0NAME.pfm (the same
bytes), timeNAME.txt (the seconds spent matching, "%.6f") and configNAME.toml (every parameter, jem's version and
this command: jem.config_record). The files are written to hidden temporary names first and renamed into place,
so a killed worker leaves no truncated result. As with `jem batch`, a failing scene
is reported and the others still run; the exit code is 2 if any failed.

Each worker is a process running one scene at a time on T threads (jem releases the GIL; the result does not
depend on T). For a remote cluster, replace LocalCluster with the address of its scheduler: the workers need jem
installed and the data at the same paths.
"""

import argparse
import os
import re
import socket
import sys
import time
from pathlib import Path

import jem

SCENE_FILES = ("im0.png", "im1.png", "calib.txt")


def find_scenes(roots):
    """Scene folders under the roots (the roots included), sorted, hidden folders skipped, a scene not searched
    further, a folder reached twice through links visited once: the folders `jem batch` finds in a MiddEval3
    tree."""
    found, seen = set(), set()
    for root in roots:
        if not Path(root).is_dir():
            raise SystemExit(f"error: {root} is not a folder")
        for folder, subdirs, _ in os.walk(root, followlinks=True):
            if os.path.realpath(folder) in seen:
                subdirs.clear()
                continue
            seen.add(os.path.realpath(folder))
            if all(Path(folder, f).is_file() for f in SCENE_FILES):
                found.add(os.path.normpath(folder))
                subdirs.clear()
            else:
                subdirs[:] = [d for d in subdirs if not d.startswith(".")]
    return sorted(found)


def calib_ndisp(path):
    """The `ndisp` a calib.txt states."""
    for line in Path(path).read_text().splitlines():
        key, _, value = line.partition("=")
        if key.strip() == "ndisp":
            return int(value.strip())
    raise ValueError(f"{path}: no ndisp")


def check_replaceable(path):
    """Refuses a destination that exists and is not a regular file (a device, a FIFO, also through a symbolic
    link): a rename would put a plain file in its place, as jem refuses to."""
    if path.exists() and not path.is_file():
        raise ValueError(f"{path}: not a regular file; jem writes only regular files and will not replace it")


def write_all_or_none(files):
    """Writes each (path, writer) to a hidden temporary file beside it, then renames them all into place; on any
    failure the temporary files are removed and no destination is touched. A destination that is not a regular
    file is refused before anything is written."""
    for path, _ in files:
        check_replaceable(path)
    staged = []
    try:
        for path, write in files:
            tmp = path.with_name(f".{path.name}.{socket.gethostname()}.{os.getpid()}.tmp")
            staged.append((tmp, path))
            write(tmp)
        for tmp, path in staged:
            check_replaceable(path)
            os.replace(tmp, path)
    finally:
        for tmp, _ in staged:
            if tmp.exists():
                tmp.unlink()


def run_scene(scene, alg, ndisp, config, overrides, threads, max_memory, record):
    """Matches one scene and writes its result files; returns (scene, seconds, ndisp). Runs on a worker."""
    scene = Path(scene)
    left, right = jem.read_image(scene / "im0.png"), jem.read_image(scene / "im1.png")
    disp, info = jem.match(
        left,
        right,
        ndisp=ndisp,
        calib_ndisp=None if ndisp is not None else calib_ndisp(scene / "calib.txt"),
        config=config,
        overrides=overrides,
        threads=threads,
        max_memory=max_memory,
        return_info=True,
    )
    seconds = info["seconds"]
    write_all_or_none(
        [
            (scene / f"disp0{alg}.pfm", lambda p: jem.write_pfm(p, disp)),
            (scene / f"time{alg}.txt", lambda p: p.write_text(f"{seconds:.6f}\n")),
            (scene / f"config{alg}.toml", lambda p: p.write_text(record)),
        ]
    )
    return str(scene), seconds, info["ndisp"]


def parse_args(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("dirs", nargs="+", metavar="DIR")
    p.add_argument("--alg", required=True, help="algorithm name in the result files (as jem batch --alg)")
    p.add_argument("--config", "-c", help="TOML config file")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override one key")
    p.add_argument("--ndisp", type=int, help="search range for every scene (default: calib.txt's)")
    p.add_argument("--workers", type=int, default=1, help="worker processes (default 1)")
    p.add_argument("--threads", type=int, default=os.cpu_count(), help="threads per worker (default: all cores)")
    p.add_argument("--max-memory", type=int, help="bytes per run, as jem --max-memory (default: 80%% of RAM)")
    args = p.parse_args(argv)
    # The names jem batch accepts: they become file names, and disp0GT.pfm is the ground truth.
    if not re.fullmatch(r"[A-Za-z0-9_-]{1,64}", args.alg) or args.alg.upper() == "GT":
        p.error(f"--alg {args.alg!r}: 1 to 64 letters, digits, _ or -, and not GT")
    bad = [s for s in args.set if "=" not in s]
    if bad:
        p.error(f"--set {bad[0]!r}: expected KEY=VALUE")
    return args


def main(argv=None):
    args = parse_args(argv)
    from dask.distributed import Client, LocalCluster, as_completed

    scenes = find_scenes(args.dirs)
    overrides = dict(s.split("=", 1) for s in args.set)
    command = " ".join(["batch_dask.py", *(argv if argv is not None else sys.argv[1:])])
    try:
        record = jem.config_record(command, config=args.config, overrides=overrides)
    except (ValueError, OSError) as e:  # a bad config or override fails every scene alike: said once
        print(f"error: {e}", file=sys.stderr)
        return 2
    failed = 0
    start = time.perf_counter()
    cluster = LocalCluster(n_workers=args.workers, threads_per_worker=1, processes=True)
    with cluster, Client(cluster) as client:
        futures = client.map(
            run_scene,
            scenes,
            alg=args.alg,
            ndisp=args.ndisp,
            config=args.config,
            overrides=overrides,
            threads=args.threads,
            max_memory=args.max_memory,
            record=record,
            pure=False,
        )
        scene_of = {f.key: scene for f, scene in zip(futures, scenes)}
        for future in as_completed(futures):
            try:
                _, seconds, ndisp = future.result()
                print(f"{scene_of[future.key]}  ndisp {ndisp}  {seconds:.2f} s", flush=True)
            except Exception as e:  # a bad scene is reported; the others go on, as in jem batch
                failed += 1
                print(f"error: {scene_of[future.key]}: {e}", file=sys.stderr, flush=True)
    print(f"{len(scenes) - failed} of {len(scenes)} scenes in {time.perf_counter() - start:.1f} s")
    return 2 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
