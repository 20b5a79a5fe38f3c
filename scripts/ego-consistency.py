#!/usr/bin/env python3
"""Judge a stereo sequence's answers without disparity truth, given the camera's poses (KITTI odometry).

Usage: scripts/ego-consistency.py SEQ OUTDIR [--max-depth 40]

SEQ holds left/, right/, calib.txt (Middlebury keys: cam0's f, baseline) and poses.txt (one camera-to-world 3x4
matrix per frame, row-major, as KITTI odometry's); OUTDIR the maps `jem sequence` wrote (<stem>.pfm).

Prints, per frame pair and as means:
- ego-motion consistency: each valid pixel of frame t nearer than --max-depth metres is back-projected (Z = f·B/d),
  moved by T_{t+1}^-1 · T_t, projected into frame t+1 (rounded to a pixel) and its disparity f·B/Z' compared with
  frame t+1's answer there; mean and median |difference| in px over the pixels valid in both;
- photometric error: the right view (grey) sampled at x − d (linear) against the left view, mean |difference| over
  valid pixels whose match falls inside the image.
Needs numpy and an image reader (cv2 or imageio).
"""
import argparse
import os
import re
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from pfm import read_pfm  # noqa: E402


def read_grey(path):
    import cv2
    img = cv2.imread(path, cv2.IMREAD_UNCHANGED).astype(np.float64)
    if img.ndim == 3:
        img = img[..., 2] * 0.299 + img[..., 1] * 0.587 + img[..., 0] * 0.114
    return img


def calib(path):
    text = open(path).read()
    f = float(re.search(r"cam0=\[\s*([0-9.eE+-]+)", text).group(1))
    m = re.search(r"cam0=\[\s*[0-9.eE+-]+\s+[0-9.eE+-]+\s+([0-9.eE+-]+);\s*[0-9.eE+-]+\s+[0-9.eE+-]+\s+([0-9.eE+-]+)", text)
    cx, cy = float(m.group(1)), float(m.group(2))
    baseline = float(re.search(r"baseline=\s*([0-9.eE+-]+)", text).group(1)) / 1000.0
    return f, cx, cy, baseline


def poses(path):
    out = []
    for line in open(path):
        v = [float(t) for t in line.split()]
        if len(v) == 12:
            m = np.eye(4)
            m[:3, :] = np.array(v).reshape(3, 4)
            out.append(m)
    return out


def consistency(d0, d1, f, cx, cy, b, motion, max_depth):
    h, w = d0.shape
    ys, xs = np.nonzero(np.isfinite(d0) & (d0 > 0))
    d = d0[ys, xs]
    z = f * b / d
    keep = z < max_depth
    xs, ys, d, z = xs[keep], ys[keep], d[keep], z[keep]
    pts = np.stack([(xs - cx) * z / f, (ys - cy) * z / f, z, np.ones_like(z)])
    moved = motion @ pts
    z1 = moved[2]
    front = z1 > 0.1
    u = np.rint(moved[0][front] / z1[front] * f + cx).astype(int)
    v = np.rint(moved[1][front] / z1[front] * f + cy).astype(int)
    expect = f * b / z1[front]
    inside = (u >= 0) & (u < w) & (v >= 0) & (v < h)
    u, v, expect = u[inside], v[inside], expect[inside]
    got = d1[v, u]
    valid = np.isfinite(got) & (got > 0)
    diff = np.abs(got[valid] - expect[valid])
    return (float(diff.mean()), float(np.median(diff))) if diff.size else (float("nan"), float("nan"))


def photometric(left, right, d):
    h, w = d.shape
    ys, xs = np.nonzero(np.isfinite(d))
    xr = xs - d[ys, xs]
    inside = (xr >= 0) & (xr <= w - 1)
    ys, xs, xr = ys[inside], xs[inside], xr[inside]
    x0 = np.floor(xr).astype(int)
    x1 = np.minimum(x0 + 1, w - 1)
    a = xr - x0
    sample = right[ys, x0] * (1 - a) + right[ys, x1] * a
    return float(np.abs(sample - left[ys, xs]).mean())


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("seq")
    ap.add_argument("out")
    ap.add_argument("--max-depth", type=float, default=40.0)
    args = ap.parse_args()
    f, cx, cy, b = calib(os.path.join(args.seq, "calib.txt"))
    ts = poses(os.path.join(args.seq, "poses.txt"))
    stems = sorted(os.path.splitext(n)[0] for n in os.listdir(os.path.join(args.seq, "left")))
    stems = [s for s in stems if os.path.exists(os.path.join(args.out, s + ".pfm"))]
    ext = {s: n for n in os.listdir(os.path.join(args.seq, "left")) for s in [os.path.splitext(n)[0]]}
    means, medians, photo = [], [], []
    for i, s in enumerate(stems):
        d = read_pfm(os.path.join(args.out, s + ".pfm"))
        left = read_grey(os.path.join(args.seq, "left", ext[s]))
        right = read_grey(os.path.join(args.seq, "right", ext[s]))
        photo.append(photometric(left, right, d))
        line = f"{s} photometric {photo[-1]:.3f}"
        if i + 1 < len(stems):
            k = int(s)
            d1 = read_pfm(os.path.join(args.out, stems[i + 1] + ".pfm"))
            motion = np.linalg.inv(ts[int(stems[i + 1])]) @ ts[k]
            mean, med = consistency(d, d1, f, cx, cy, b, motion, args.max_depth)
            means.append(mean)
            medians.append(med)
            line += f" consistency mean {mean:.3f} median {med:.3f}"
        print(line)
    print(f"mean photometric {np.mean(photo):.4f} consistency mean {np.mean(means):.4f} median {np.mean(medians):.4f}")


if __name__ == "__main__":
    main()
