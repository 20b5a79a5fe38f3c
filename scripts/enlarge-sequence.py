#!/usr/bin/env python3
"""Enlarge a stereo sequence by a factor: the same footage as a higher-resolution camera would give it, to see what
the temporal model does at a size its thresholds were not chosen at (KITTI frames enlarged 1.5 times: 1839 x 555).

Usage: scripts/enlarge-sequence.py SEQ OUT FACTOR

SEQ holds left/, right/ (PNG frames), calib.txt (Middlebury keys) and optionally poses.txt; OUT must not exist.
Each view is resized bicubically (pixel centres kept: x' = (x + 0.5) * FACTOR - 0.5; the kernel's overshoot at edges
is held to the views' integer range, as any resampled 8/16-bit image is); calib.txt's cam0/cam1 focal
length and principal point, width, height and ndisp are scaled to match (the baseline stays: poses are in metres),
poses.txt is copied as it is. Needs numpy and cv2 (opencv-python-headless).
"""
import os
import re
import shutil
import sys

import cv2


def scaled_calib(text, k, width, height):
    def camera(m):
        v = [float(t) for t in re.split(r"[\s;]+", m.group(2).strip()) if t]
        f, cx, cy = v[0] * k, (v[2] + 0.5) * k - 0.5, (v[5] + 0.5) * k - 0.5
        return f"{m.group(1)}=[{f:.6f} 0 {cx:.6f}; 0 {f:.6f} {cy:.6f}; 0 0 1]"

    text = re.sub(r"(cam[01])=\[([^\]]*)\]", camera, text)
    text = re.sub(r"width=\s*\d+", f"width={width}", text)
    text = re.sub(r"height=\s*\d+", f"height={height}", text)
    text = re.sub(r"ndisp=\s*(\d+)", lambda m: f"ndisp={round(int(m.group(1)) * k)}", text)
    return text


def main():
    if len(sys.argv) != 4:
        sys.exit(__doc__.split("\n\n")[1])
    seq, out, k = sys.argv[1], sys.argv[2], float(sys.argv[3])
    if os.path.exists(out):
        sys.exit(f"error: {out} exists; give a new folder")
    tmp = out + ".partial"
    shutil.rmtree(tmp, ignore_errors=True)
    size = None
    for side in ("left", "right"):
        os.makedirs(os.path.join(tmp, side))
        for name in sorted(os.listdir(os.path.join(seq, side))):
            img = cv2.imread(os.path.join(seq, side, name), cv2.IMREAD_UNCHANGED)
            if img is None:
                sys.exit(f"error: {os.path.join(seq, side, name)}: not an image cv2 reads")
            h, w = img.shape[:2]
            size = (round(w * k), round(h * k))
            cv2.imwrite(os.path.join(tmp, side, os.path.splitext(name)[0] + ".png"),
                        cv2.resize(img, size, interpolation=cv2.INTER_CUBIC))
    with open(os.path.join(seq, "calib.txt")) as f:
        calib = scaled_calib(f.read(), k, *size)
    with open(os.path.join(tmp, "calib.txt"), "w") as f:
        f.write(calib)
    if os.path.exists(os.path.join(seq, "poses.txt")):
        shutil.copy(os.path.join(seq, "poses.txt"), os.path.join(tmp, "poses.txt"))
    os.rename(tmp, out)
    print(f"wrote {out}: {size[0]}x{size[1]}")


if __name__ == "__main__":
    main()
