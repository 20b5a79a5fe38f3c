#!/usr/bin/env python3
"""Brings answers on MiddEval3 trainingH views to the trainingQ grid, to score them against trainingQ's truth where
the H truth is not at hand: each 2 × 2 block's median (invalid pixels left out), the disparities halved.

Usage: scripts/h-on-q.py HTREE QTREE NAME
For every scene folder under HTREE with disp0NAME.pfm, writes QTREE/<scene>/disp0NAME.pfm (QTREE's scene folders
must exist and hold disp0GT.pfm, whose size is the grid; scripts/native-set.sh makes them as links to trainingQ).
Then `jem eval QTREE --alg NAME` scores them in full-resolution pixels as for any Q answer. Needs numpy.
"""
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from pfm import read_pfm, write_pfm  # noqa: E402 (the scripts' own module, beside them)


def to_q(d, shape):
    """The H map `d` on a Q grid of `shape`: 2 × 2 medians of the valid values, halved; inf where none is valid."""
    qh, qw = shape
    d = np.where(np.isfinite(d), d, np.nan)[:2 * qh, :2 * qw]
    blocks = np.stack([d[0::2, 0::2], d[1::2, 0::2], d[0::2, 1::2], d[1::2, 1::2]])
    with np.errstate(all='ignore'):
        m = np.nanmedian(blocks, axis=0) / 2
    return np.where(np.isfinite(m), m, np.inf).astype(np.float32)


def main():
    if len(sys.argv) != 4:
        sys.exit(__doc__)
    htree, qtree, name = sys.argv[1:]
    done = 0
    for scene in sorted(os.listdir(htree)):
        src = os.path.join(htree, scene, f'disp0{name}.pfm')
        if not os.path.isfile(src):
            continue
        gt = os.path.join(qtree, scene, 'disp0GT.pfm')
        if not os.path.isfile(gt):
            sys.exit(f'error: {gt}: missing (the Q scene folder of {scene})')
        dst = os.path.join(qtree, scene, f'disp0{name}.pfm')
        write_pfm(dst, to_q(read_pfm(src), read_pfm(gt).shape))
        done += 1
    print(f'{done} scene(s) brought to the Q grid under {qtree}')


if __name__ == '__main__':
    main()
