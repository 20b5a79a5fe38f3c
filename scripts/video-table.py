#!/usr/bin/env python3
"""The table of the stereo-video measurements: one row per sequence scored by scripts/video-run.sh.

Usage: scripts/video-table.py RESULTS [BASE]
  RESULTS  a folder of NAME.json files (`jem eval --format json` of each sequence's results)
  BASE     another such folder (the independent baseline): adds the ratios RESULTS / BASE

Columns: avgErr over all frames and over frames 5-10 (the issue's target window), bad2, the frame-to-frame change
on static pixels (flicker), the error of the change elsewhere, and the mean seconds per frame over frames 2..N
(the first frame pays for what later frames may reuse). Errors in full-resolution px for q-* (x4).
Standard library only.
"""
import json
import os
import sys


def load(folder):
    out = {}
    for name in sorted(os.listdir(folder)):
        if name.endswith(".json"):
            with open(os.path.join(folder, name)) as f:
                out[name[:-5]] = json.load(f)
    return out


def figures(report):
    frames = list(report["frames"].items())
    avg = [f["avgerr"] for _, f in frames]
    window = avg[4:10]
    times = [f.get("seconds") for _, f in frames[1:] if f.get("seconds") is not None]
    return {
        "avgerr": sum(avg) / len(avg),
        "avgerr5_10": sum(window) / len(window) if window else float("nan"),
        "bad2": sum(f["bad2"] for _, f in frames) / len(frames),
        "flicker": report["flicker"],
        "change_err": report["change_err"],
        "s_per_frame": sum(times) / len(times) if times else float("nan"),
        "frames": len(frames),
    }


def fmt(v, digits=2):
    return "-" if v is None or v != v else f"{v:.{digits}f}"


def main():
    results = load(sys.argv[1])
    base = load(sys.argv[2]) if len(sys.argv) > 2 else None
    keys = ["avgerr", "avgerr5_10", "bad2", "flicker", "change_err", "s_per_frame"]
    head = ["sequence", "frames", "avgErr", "avgErr 5-10", "bad2", "flicker", "change err", "s/frame 2..N"]
    if base:
        head += ["avgErr x", "5-10 x", "flicker x", "time x"]
    print("| " + " | ".join(head) + " |")
    print("|" + "|".join(["---"] + ["---:"] * (len(head) - 1)) + "|")
    for name, report in results.items():
        f = figures(report)
        row = [name, str(f["frames"])] + [fmt(f[k]) for k in keys]
        if base and name in base:
            b = figures(base[name])
            ratio = lambda k: fmt(f[k] / b[k], 3) if b[k] and f[k] is not None and b[k] == b[k] else "-"
            row += [ratio("avgerr"), ratio("avgerr5_10"), ratio("flicker"), ratio("s_per_frame")]
        print("| " + " | ".join(row) + " |")


if __name__ == "__main__":
    main()
