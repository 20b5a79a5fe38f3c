#!/usr/bin/env python3
"""Builds "Middlebury 2005 full size": the 2005 scenes Art, Books, Dolls and Reindeer at full resolution (1390 or
1342 x 1110, true disparities up to 225 px), view1 / view5 as left / right, converted to the MiddEval3 scene folders
of scripts/ood-set.py: OUT/trainingX/midd2005F_<scene>/{im0.png, im1.png, calib.txt, disp0GT.pfm, mask0nocc.png,
SOURCE.txt}, ground truth at the images' resolution (score with `jem eval OUT/trainingX --alg NAME --scale 1`).

Usage: scripts/midd2005-full.py SRC OUT
SRC holds clones of the two repositories, each checked out at the commit below, under these folder names:

    git clone https://github.com/omkarbhoite25/3D-Sensing-Sensor-Fusion SRC/3D-Sensing-Sensor-Fusion
    git -C SRC/3D-Sensing-Sensor-Fusion checkout 3e8594838eb99fe5537bff579b0860f9c2433908
    git clone https://github.com/jli262/Disparity-Map-Generator SRC/Disparity-Map-Generator
    git -C SRC/Disparity-Map-Generator checkout d621b5ea89cba1acc8f8c5441604f1f770f8ee1d

Read: Input_Images/{Art/Art,Books/Books}/{view1,view5,disp1,disp5}.png from the first, and
StereoMatchingTestings/{Dolls,Reindeer}/{view1,view5,disp1}.png from the second (its Art, not used, is
byte-identical to the first's). Full-size 2005 disparity PNGs hold the disparity itself (value / 1), 0 = unknown.

Needs numpy and OpenCV, and scripts/ood-set.py beside this script (its Builder, grey() and occluded() are reused).
OUT must not exist; it is written whole or not at all. The data stay outside this repository: the images are the
repositories' (and Middlebury's) own, under their terms.

Per pair: ndisp = 1.1 x the largest true disparity, rounded up to a multiple of 16; mask0nocc.png is 255 where the
ground truth is visible in both views, 128 where it is occluded (a 1-px consistency check of the left ground truth
against the right one, as in ood-set.py), 0 where there is none. Dolls and Reindeer come without disp5.png: their
right ground truth is the left one forward-warped (where several pixels land, the nearest surface wins); on Art and
Books that labels 99.0 % and 99.8 % of the ground-truth pixels as the shipped disp5.png does.
"""
import importlib.util
import os

import numpy as np

_spec = importlib.util.spec_from_file_location(
    'ood_set', os.path.join(os.path.dirname(os.path.abspath(__file__)), 'ood-set.py'))
ood = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(ood)

# Pair name, repository (owner/name, short commit), scene folder, whether it ships disp5.png.
SCENES = [
    ('Art', 'omkarbhoite25/3D-Sensing-Sensor-Fusion', '3e85948', 'Input_Images/Art/Art', True),
    ('Books', 'omkarbhoite25/3D-Sensing-Sensor-Fusion', '3e85948', 'Input_Images/Books/Books', True),
    ('Dolls', 'jli262/Disparity-Map-Generator', 'd621b5e', 'StereoMatchingTestings/Dolls', False),
    ('Reindeer', 'jli262/Disparity-Map-Generator', 'd621b5e', 'StereoMatchingTestings/Reindeer', False),
]


def forward_warp(dl):
    """The right view's disparities from the left ones: each left pixel moved to x - round(d), the largest disparity
    (the nearest surface) kept where several land; 0 where none does (unknown to occluded())."""
    h, w = dl.shape
    dr = np.zeros((h, w), np.float32)
    ys, xs = np.nonzero(dl > 0)
    xr = xs - np.round(dl[ys, xs]).astype(int)
    keep = xr >= 0
    np.maximum.at(dr, (ys[keep], xr[keep]), dl[ys[keep], xs[keep]])
    return dr


def build(b):
    for name, repo, commit, d, has5 in SCENES:
        folder = repo.split('/')[1]
        g1 = ood.grey(b.path(folder, f'{d}/disp1.png'))
        dl = np.where(g1 > 0, g1, 0.0)
        if has5:
            g5 = ood.grey(b.path(folder, f'{d}/disp5.png'))
            dr = np.where(g5 > 0, g5, np.inf)
        else:
            dr = forward_warp(dl)
        mask = np.where(g1 > 0, np.where(ood.occluded(dl, dr), 128, 255), 0)
        files = 'view1,view5,disp1,disp5' if has5 else 'view1,view5,disp1'
        note = '' if has5 else '; right ground truth: disp1 forward-warped'
        b.scene(f'midd2005F_{name}', b.path(folder, f'{d}/view1.png'), b.path(folder, f'{d}/view5.png'), dl, mask,
                f'{repo} {commit} {d}/{{{files}}}.png (full size, disparity = value / 1{note})')


def main():
    ood.run(__doc__, 'trainingX', build)


if __name__ == '__main__':
    main()
