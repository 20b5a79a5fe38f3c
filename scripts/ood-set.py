#!/usr/bin/env python3
"""Builds the out-of-distribution test set of docs/RESULTS.md ("Other benchmarks"): 15 stereo pairs with ground
truth that public GitHub repositories ship as sample data (KITTI 2012 and 2015, Middlebury 2003, 2005 and 2006,
SCARED, FlyingThings3D, and one Middlebury 2014 scene as a control), converted to MiddEval3 scene folders:
OUT/trainingQ/<pair>/{im0.png, im1.png, calib.txt, disp0GT.pfm, mask0nocc.png, SOURCE.txt}, ground truth at the
images' resolution (score with `jem eval OUT/trainingQ --alg NAME --scale 1`).

Usage: scripts/ood-set.py SRC OUT
SRC holds clones of the five repositories, each checked out at the commit below, under these folder names:

    git clone https://github.com/mli0603/stereo-transformer SRC/stereo-transformer
    git -C SRC/stereo-transformer checkout 44703b01d59c8accff1d396ec842c3d1b9a8fb9a
    git clone https://github.com/mli0603/stereo-transformer SRC/stereo-transformer-b5d5e94
    git -C SRC/stereo-transformer-b5d5e94 checkout b5d5e9436012cd03b9a6b41fb688907a81e7165b
    git clone https://github.com/youtudou/ROB501_2020 SRC/ROB501_2020
    git -C SRC/ROB501_2020 checkout e5e5c327db3949099c97adb331e02ce2005604b0
    git clone https://github.com/omkarbhoite25/3D-Sensing-Sensor-Fusion SRC/3D-Sensing-Sensor-Fusion
    git -C SRC/3D-Sensing-Sensor-Fusion checkout 3e8594838eb99fe5537bff579b0860f9c2433908
    git clone https://github.com/DeepMotionAIResearch/DenseMatchingBenchmark SRC/DenseMatchingBenchmark
    git -C SRC/DenseMatchingBenchmark checkout 010aeb66e3ceaf3d866036b0ca751861df39432d

Needs numpy and OpenCV (pip install numpy opencv-python-headless). OUT must not exist; it is written whole or not
at all. The data stay outside this
repository: the samples are the repositories' (and their benchmarks') own, under their terms.

Per pair: ndisp = 1.1 × the largest true disparity, rounded up to a multiple of 16; mask0nocc.png is 255 where the
ground truth is visible in both views, 128 where it is occluded (from the source's occlusion map, or else a 1-px
consistency check of its left and right ground truths), 0 where there is none (teddy and the KITTI 2015 frame ship
no occlusion information: every pixel with ground truth is 255).
"""
import math
import os
import shutil
import sys

import cv2
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from pfm import read_pfm, write_pfm  # noqa: E402 (the scripts' own module, beside them)


def image8(path):
    """An 8-bit BGR image (16-bit images scaled, alpha dropped)."""
    im = cv2.imread(path, cv2.IMREAD_UNCHANGED)
    if im is None:
        sys.exit(f'error: {path}: missing or not an image')
    if im.dtype != np.uint8:
        im = (im / 257).round().astype(np.uint8)
    if im.ndim == 3 and im.shape[2] == 4:
        im = im[:, :, :3]
    return im


def grey(path):
    im = cv2.imread(path, cv2.IMREAD_GRAYSCALE)
    if im is None:
        sys.exit(f'error: {path}: missing or not an image')
    return im.astype(np.float32)


def kitti_disparity(path):
    """A KITTI disparity PNG: (disparity, valid); 16 bit, value / 256, 0 = no ground truth."""
    a = cv2.imread(path, cv2.IMREAD_UNCHANGED)
    if a is None or a.dtype != np.uint16:
        sys.exit(f'error: {path}: not a 16-bit KITTI disparity PNG')
    return a.astype(np.float32) / 256.0, a > 0


def occluded(dl, dr, tol=1.0):
    """Occluded in the left view: x − dl(x) leaves the image, or the right ground truth there is nearer by more than
    `tol` (another surface covers the point). Unknown values: 0 or inf."""
    h, w = dl.shape
    dl = np.nan_to_num(dl, posinf=0.0)
    xs = np.arange(w)[None, :] - np.round(dl).astype(int)
    dr_at = dr[np.arange(h)[:, None], np.clip(xs, 0, w - 1)]
    known = np.isfinite(dr_at) & (dr_at > 0)
    return (xs < 0) | (known & (dr_at > dl + tol))


class Builder:
    def __init__(self, src, out):
        self.src, self.out = src, out

    def path(self, repo, rel):
        return os.path.join(self.src, repo, rel)

    def scene(self, name, left, right, gt, mask, source):
        d = os.path.join(self.out, name)
        os.makedirs(d)
        L, R = image8(left), image8(right)
        h, w = L.shape[:2]
        if R.shape[:2] != (h, w) or gt.shape != (h, w) or mask.shape != (h, w):
            sys.exit(f'error: {name}: images {L.shape} / {R.shape}, ground truth {gt.shape}, mask {mask.shape}')
        gt = np.where(mask > 0, gt, np.inf).astype(np.float32)
        valid = np.isfinite(gt)
        top = float(gt[valid].max())
        ndisp = int(math.ceil(top * 1.1 / 16.0) * 16)
        cv2.imwrite(os.path.join(d, 'im0.png'), L)
        cv2.imwrite(os.path.join(d, 'im1.png'), R)
        write_pfm(os.path.join(d, 'disp0GT.pfm'), gt)
        cv2.imwrite(os.path.join(d, 'mask0nocc.png'), mask.astype(np.uint8))
        with open(os.path.join(d, 'calib.txt'), 'w') as f:
            f.write(f'width={w}\nheight={h}\nndisp={ndisp}\nisint=0\n'
                    f'vmin={int(math.floor(gt[valid].min()))}\nvmax={int(math.ceil(top))}\n')
        with open(os.path.join(d, 'SOURCE.txt'), 'w') as f:
            f.write(source + '\n')
        print(f'{name:<28} {w:4d} x {h:<4d} ndisp {ndisp:3d}  visible {100 * (mask == 255).mean():5.1f} %')

    def build(self):
        st = 'stereo-transformer'
        # KITTI 2015, frame 000046: only the all-pixel ground truth is shipped.
        k = 'sample_data/KITTI_2015/training'
        gt, valid = kitti_disparity(self.path(st, f'{k}/disp_occ_0/000046_10.png'))
        self.scene('kitti15_000046', self.path(st, f'{k}/image_2/000046_10.png'),
                   self.path(st, f'{k}/image_3/000046_10.png'), gt, np.where(valid, 255, 0),
                   f'mli0603/stereo-transformer 44703b0 {k}/{{image_2,image_3,disp_occ_0}}/000046_10.png')
        # KITTI 2012, frame 000070: non-occluded and all-pixel ground truth.
        rob = 'ROB501_2020'
        k = 'Assignment_3/stereo/kitti'
        gt, all_valid = kitti_disparity(self.path(rob, f'{k}/disp_occ/000070_10.png'))
        _, noc_valid = kitti_disparity(self.path(rob, f'{k}/disp_noc/000070_10.png'))
        self.scene('kitti12_000070', self.path(rob, f'{k}/colored_0/000070_10.png'),
                   self.path(rob, f'{k}/colored_1/000070_10.png'), gt,
                   np.where(noc_valid, 255, np.where(all_valid, 128, 0)),
                   f'youtudou/ROB501_2020 e5e5c32 {k}/{{colored_0,colored_1,disp_noc,disp_occ}}/000070_10.png')
        # Middlebury 2003 at quarter size (disparity = value / 4); cones' occlusions from its disp6.
        for nm in ('cones', 'teddy'):
            s = f'Assignment_3/stereo/{nm}'
            g = grey(self.path(rob, f'{s}/{nm}_disp_02.png'))
            mask = np.where(g > 0, 255, 0)
            if nm == 'cones':
                g6 = grey(self.path('3D-Sensing-Sensor-Fusion', 'Input_Images/cones/cones/disp6.pgm')) / 4.0
                mask = np.where(g > 0, np.where(occluded(g / 4.0, np.where(g6 > 0, g6, np.inf)), 128, 255), 0)
            self.scene(f'midd2003_{nm}', self.path(rob, f'{s}/{nm}_image_02.png'),
                       self.path(rob, f'{s}/{nm}_image_06.png'), g / 4.0, mask,
                       f'youtudou/ROB501_2020 e5e5c32 {s}/{nm}_{{image_02,image_06,disp_02}}.png')
        # Middlebury 2005 (full size) and 2006 (half size): view1 / view5, disp1 / disp5 (0 = unknown).
        osf = '3D-Sensing-Sensor-Fusion'
        for name, left_dir, right_dir, factor, year in [
                ('Aloe', 'Aloe/Aloe', 'Aloe/Aloe', 2, 2006), ('Baby1', 'Baby/Baby', 'Baby/Baby1', 2, 2006),
                ('Bowling1', 'Bowling/Bowling', 'Bowling/Bowling1', 2, 2006),
                ('Cloth1', 'Cloth/Cloth', 'Cloth/Cloth1', 2, 2006),
                ('Flowerpots', 'Flowerpots/Flowerpots', 'Flowerpots/Flowerpots', 2, 2006),
                ('Art', 'Art/Art', 'Art/Art', 1, 2005)]:
            g1 = grey(self.path(osf, f'Input_Images/{left_dir}/disp1.png'))
            g5 = grey(self.path(osf, f'Input_Images/{right_dir}/disp5.png'))
            dl = np.where(g1 > 0, g1 / factor, 0.0)
            dr = np.where(g5 > 0, g5 / factor, np.inf)
            mask = np.where(g1 > 0, np.where(occluded(dl, dr), 128, 255), 0)
            self.scene(f'midd{year}_{name}', self.path(osf, f'Input_Images/{left_dir}/view1.png'),
                       self.path(osf, f'Input_Images/{right_dir}/view5.png'), dl, mask,
                       f'omkarbhoite25/3D-Sensing-Sensor-Fusion 3e85948 Input_Images/{{{left_dir},{right_dir}}}/'
                       f'{{view1,view5,disp1,disp5}}.png (disparity = value / {factor})')
        # SCARED (endoscopy): 0 = no ground truth, occlusion map 128 = occluded.
        s = 'sample_data/SCARED/train'
        f = 'dataset_1_keyframe_2_frame_data000000'
        b5 = 'stereo-transformer-b5d5e94'
        gt = cv2.imread(self.path(b5, f'{s}/disparity/{f}.tiff'), cv2.IMREAD_UNCHANGED)
        if gt is None:
            sys.exit(f'error: {self.path(b5, f"{s}/disparity/{f}.tiff")}: missing or unreadable')
        gt = gt.astype(np.float32)
        occ = grey(self.path(b5, f'{s}/occlusion/{f}.png'))
        self.scene('scared_d1k2', self.path(b5, f'{s}/left/{f}.png'), self.path(b5, f'{s}/right/{f}.png'), gt,
                   np.where(gt > 0, np.where(occ == 128, 128, 255), 0),
                   f'mli0603/stereo-transformer b5d5e94 {s}/{{left,right,disparity,occlusion}}/{f}.*')
        # FlyingThings3D (rendered): one frame with its occlusion map, two with left and right ground truth.
        s = 'sample_data/SCENE_FLOW'
        gt = read_pfm(self.path(st, f'{s}/disparity/left/A-0032-0006.pfm'))
        occ = grey(self.path(st, f'{s}/occlusion/left/A-0032-0006.png')) > 0
        self.scene('sceneflow_ft3d_A0032_0006', self.path(st, f'{s}/RGB_cleanpass/left/A-0032-0006.png'),
                   self.path(st, f'{s}/RGB_cleanpass/right/A-0032-0006.png'), gt, np.where(occ, 128, 255),
                   f'mli0603/stereo-transformer 44703b0 {s}/{{RGB_cleanpass,disparity,occlusion}}/{{left,right}}/'
                   'A-0032-0006.*')
        dmb = 'DenseMatchingBenchmark'
        s = 'tools/demo_data'
        for i in ('0', '4'):
            dl = read_pfm(self.path(dmb, f'{s}/disparity/left/{i}.pfm'))
            dr = read_pfm(self.path(dmb, f'{s}/disparity/right/{i}.pfm'))
            self.scene(f'sceneflow_ft3d_dmb{i}', self.path(dmb, f'{s}/images/left/{i}.png'),
                       self.path(dmb, f'{s}/images/right/{i}.png'), dl, np.where(occluded(dl, dr), 128, 255),
                       f'DeepMotionAIResearch/DenseMatchingBenchmark 010aeb6 {s}/{{images,disparity}}/{{left,right}}/'
                       f'{i}.*')
        # Control: Middlebury 2014 Motorcycle at quarter size, in distribution.
        s = 'sample_data/MIDDLEBURY_2014/trainingQ/Motorcycle'
        self.scene('zz_ctrl_midd2014_MotorcycleQ', self.path(st, f'{s}/im0.png'), self.path(st, f'{s}/im1.png'),
                   read_pfm(self.path(st, f'{s}/disp0GT.pfm')), grey(self.path(st, f'{s}/mask0nocc.png')),
                   f'mli0603/stereo-transformer 44703b0 {s}/*')


def run(doc, split, build):
    """The command line `SCRIPT SRC OUT` of a set builder whose usage is `doc`: `build(builder)` fills OUT/split
    through a Builder reading SRC; OUT must not exist and appears whole or not at all."""
    if len(sys.argv) > 1 and sys.argv[1] in ('-h', '--help'):
        print(doc)
        sys.exit(0)
    if len(sys.argv) != 3:
        sys.exit(doc.split('\n\n')[1].strip())
    src, out = sys.argv[1], os.path.normpath(sys.argv[2])
    if os.path.lexists(out):
        sys.exit(f'error: {out}: exists (give a new folder)')
    # Built in a hidden folder beside OUT and renamed at the end: OUT appears whole or not at all.
    partial = os.path.join(os.path.dirname(out) or '.', f'.{os.path.basename(out)}.partial-{os.getpid()}')
    # Created here (an existing folder of that name is an error), so the clean-up below only removes our own.
    os.mkdir(partial)
    try:
        build(Builder(src, os.path.join(partial, split)))
        os.rename(partial, out)
    finally:
        shutil.rmtree(partial, ignore_errors=True)


def main():
    run(__doc__, 'trainingQ', Builder.build)


if __name__ == '__main__':
    main()
