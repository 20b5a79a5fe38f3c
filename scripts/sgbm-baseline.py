#!/usr/bin/env python3
"""OpenCV's StereoSGBM as a baseline beside jem, on every MiddEval3 scene folder under TREE.

Usage: scripts/sgbm-baseline.py TREE [NAME]    (NAME default: SGBM)
Writes into each scene folder disp0NAME.pfm (holes filled with the row's background: the smaller of the nearest
valid disparities to the left and right) and disp0NAMEraw.pfm (holes = inf), with timeNAME.txt / timeNAMEraw.txt
(seconds of compute(), one thread); then `jem eval TREE --alg NAME --alg NAMEraw` scores them. Settings: mode
3WAY, block 5, P1 = 8·3·5², P2 = 32·3·5², uniqueness 10, speckle window 100 / range 2, disp12MaxDiff 1,
numDisparities = ndisp of calib.txt rounded up to 16. Needs numpy and OpenCV (pip install numpy
opencv-python-headless). A tree that already holds results of that NAME is refused before anything is written;
each scene's four files appear together.
"""
import glob
import math
import os
import re
import sys
import time

import cv2
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from pfm import write_pfm  # noqa: E402 (the scripts' own module, beside them)

cv2.setNumThreads(1)


def fill_background(d):
    """Each row's holes take the smaller of the nearest valid disparities to their left and right."""
    out = d.copy()
    w = d.shape[1]
    idx = np.arange(w)
    for y, row in enumerate(d):
        valid = np.isfinite(row)
        if not valid.any():
            out[y] = 0.0
            continue
        left = np.maximum.accumulate(np.where(valid, idx, -1))
        right = np.minimum.accumulate(np.where(valid, idx, w)[::-1])[::-1]
        from_left = np.where(left >= 0, row[np.clip(left, 0, w - 1)], np.inf)
        from_right = np.where(right < w, row[np.clip(right, 0, w - 1)], np.inf)
        out[y] = np.where(valid, row, np.minimum(from_left, from_right))
    return out


def ndisp_of(calib):
    with open(calib) as f:
        for line in f:
            m = re.match(r'\s*ndisp\s*=\s*(\S+)', line)
            if m:
                return int(float(m.group(1)))
    sys.exit(f'error: {calib}: no ndisp')


def run(scene, name):
    labels = int(math.ceil(ndisp_of(os.path.join(scene, 'calib.txt')) / 16.0) * 16)
    left = cv2.imread(os.path.join(scene, 'im0.png'), cv2.IMREAD_COLOR)
    right = cv2.imread(os.path.join(scene, 'im1.png'), cv2.IMREAD_COLOR)
    if left is None or right is None:
        sys.exit(f'error: {scene}: im0.png / im1.png missing or unreadable')
    block = 5
    sgbm = cv2.StereoSGBM_create(minDisparity=0, numDisparities=labels, blockSize=block,
                                 P1=8 * 3 * block * block, P2=32 * 3 * block * block, disp12MaxDiff=1,
                                 uniquenessRatio=10, speckleWindowSize=100, speckleRange=2,
                                 mode=cv2.STEREO_SGBM_MODE_SGBM_3WAY)
    start = time.perf_counter()
    fixed = sgbm.compute(left, right)
    seconds = time.perf_counter() - start
    d = fixed.astype(np.float32) / 16.0
    d[fixed < 0] = np.inf
    # Each file written beside its place and renamed into it once all four are complete.
    done = []
    try:
        for n, disparity in ((name + 'raw', d), (name, fill_background(d))):
            write_pfm(os.path.join(scene, f'.disp0{n}.pfm.partial'), disparity)
            done.append(f'disp0{n}.pfm')
            with open(os.path.join(scene, f'.time{n}.txt.partial'), 'w') as f:
                f.write(f'{seconds:.4f}\n')
            done.append(f'time{n}.txt')
        for f in done:
            os.replace(os.path.join(scene, f'.{f}.partial'), os.path.join(scene, f))
    finally:
        for f in done:
            if os.path.exists(os.path.join(scene, f'.{f}.partial')):
                os.remove(os.path.join(scene, f'.{f}.partial'))
    print(f'{os.path.basename(scene):<28} numDisparities {labels:3d}  {seconds:.3f} s  '
          f'valid {100 * np.isfinite(d).mean():.1f} %')


def main():
    if len(sys.argv) > 1 and sys.argv[1] in ('-h', '--help'):
        print(__doc__)
        sys.exit(0)
    if len(sys.argv) not in (2, 3):
        sys.exit(__doc__.split('\n\n')[1].strip())
    name = sys.argv[2] if len(sys.argv) == 3 else 'SGBM'
    if not re.fullmatch(r'[A-Za-z0-9_-]+', name) or name.upper() == 'GT':
        sys.exit(f'error: {name}: not a usable algorithm name')
    scenes = sorted(os.path.dirname(p) for p in glob.glob(os.path.join(sys.argv[1], '**', 'calib.txt'),
                                                           recursive=True))
    if not scenes:
        sys.exit(f'error: {sys.argv[1]}: no scene folders (calib.txt) found')
    # Never over another run's results (jem's, say, under the same name): refused before anything is written.
    for scene in scenes:
        for f in (f'disp0{name}.pfm', f'disp0{name}raw.pfm', f'time{name}.txt', f'time{name}raw.txt'):
            if os.path.lexists(os.path.join(scene, f)):
                sys.exit(f'error: {os.path.join(scene, f)}: exists (remove it or give another NAME)')
    for scene in scenes:
        run(scene, name)


if __name__ == '__main__':
    main()
