#!/usr/bin/env python3
"""Degradations outside `jem degrade`'s recipes, for the "Other degradations" table of docs/RESULTS.md.

Usage: scripts/other-degradations.py SRC VARIANT OUT
Copies every scene folder of SRC (a MiddEval3 tree such as trainingQ: folders with im0.png and im1.png) to OUT,
the images degraded as VARIANT says, calib.txt, disp0GT.pfm and mask0nocc.png copied unchanged (when present).
OUT must not exist; it is built in a hidden sibling folder of its own and renamed at the end, so a failed run
leaves nothing. Seeded: numpy's default_rng streams spawned from SeedSequence(1), one for every left view and one for
every right view, the scenes in sorted order; a rerun writes the same bytes. Needs numpy, OpenCV and Pillow
(pip install numpy opencv-python-headless pillow). Colours are in OpenCV's BGR order inside this script.

Variants (grey levels of the 8-bit images, pixels of the image as it is):
  clean        unchanged (for the SGBM baseline on the same tree layout)
  vshift05     right view 0.5 px lower (bilinear)           vshift1    right view 1 px lower
  rot02        right view rotated 0.2 deg about its centre (bilinear, borders replicated)
  wb           white-balance mismatch: right view R x 1.15, B x 0.85
  vignette     both views x (1 - 0.5 (r / rmax)^2), the centre 10 % of the width left (left view) or right
  blurR        right view only blurred, Gaussian sigma 1.5 px
  motion       both views: horizontal box blur of 5 px
  chroma       colour noise: Gaussian sigma 6 per channel drawn on a half-resolution grid (2 x 2 blotches)
  sp           salt and pepper: 0.5 % of the pixels set to 0 or 255, each view independently
  clip         overexposure: both views x 1.8, clipped at 255
  resamp       both views reduced to 0.6 x (area) and enlarged back (bicubic)
  dark_jpeg    x 0.2, Gaussian noise sigma 2, JPEG quality 60 (Pillow), both views
  dark_nojpeg  dark_jpeg without the JPEG step
  noise_uneq   Gaussian noise sigma 2 on the left view, 10 on the right
"""
import io
import os
import shutil
import sys

import cv2
import numpy as np
from PIL import Image

VARIANTS = ['clean', 'vshift05', 'vshift1', 'rot02', 'wb', 'vignette', 'blurR', 'motion', 'chroma',
            'sp', 'clip', 'resamp', 'dark_jpeg', 'dark_nojpeg', 'noise_uneq']
COPIED = ('calib.txt', 'disp0GT.pfm', 'mask0nocc.png')


def warp(img, M):
    h, w = img.shape[:2]
    return cv2.warpAffine(img, M, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


def vshift(img, dy):
    # content moves down by dy px: out(x, y) = in(x, y - dy), bilinear
    return warp(img, np.float32([[1, 0, 0], [0, 1, dy]]))


def rotate(img, deg):
    h, w = img.shape[:2]
    M = cv2.getRotationMatrix2D(((w - 1) / 2.0, (h - 1) / 2.0), deg, 1.0)
    return warp(img, M)


def vignette(img, dx_frac):
    # factor 1 - 0.5 (r/rmax)^2, centre = image centre shifted by dx_frac*w horizontally,
    # rmax = distance from that centre to its farthest corner (so the factor is 0.5 there)
    h, w = img.shape[:2]
    cx, cy = (w - 1) / 2.0 + dx_frac * w, (h - 1) / 2.0
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    r2 = (xx - cx) ** 2 + (yy - cy) ** 2
    rmax2 = max((x - cx) ** 2 + (y - cy) ** 2 for x in (0, w - 1) for y in (0, h - 1))
    f = 1.0 - 0.5 * r2 / rmax2
    return img * f[:, :, None]


def gauss_noise(img, sigma, rng):
    return img + rng.normal(0.0, sigma, img.shape)


def chroma(img, sigma, rng):
    # independent N(0, sigma) per channel on a grid of half resolution, nearest-neighbour upsampled
    # (2x2 blocks, so the per-pixel sigma stays 6)
    h, w, c = img.shape
    n = rng.normal(0.0, sigma, ((h + 1) // 2, (w + 1) // 2, c))
    n = np.repeat(np.repeat(n, 2, axis=0), 2, axis=1)[:h, :w]
    return img + n


def salt_pepper(img, frac, rng):
    h, w = img.shape[:2]
    out = img.copy()
    hit = rng.random((h, w)) < frac
    val = np.where(rng.random((h, w)) < 0.5, 0.0, 255.0)
    out[hit] = val[hit][:, None]
    return out


def jpeg(img, q):
    u8 = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    buf = io.BytesIO()
    Image.fromarray(u8[:, :, ::-1]).save(buf, format='JPEG', quality=q)
    buf.seek(0)
    return np.asarray(Image.open(buf).convert('RGB'))[:, :, ::-1].astype(np.float64)


def degrade(variant, img, view, rng):
    """img: float64 HxWx3 BGR in 0..255; view 0 = left, 1 = right."""
    if variant == 'clean':
        return img
    if variant == 'vshift05':
        return vshift(img, 0.5) if view == 1 else img
    if variant == 'vshift1':
        return vshift(img, 1.0) if view == 1 else img
    if variant == 'rot02':
        return rotate(img, 0.2) if view == 1 else img
    if variant == 'wb':
        if view == 0:
            return img
        out = img.copy()
        out[:, :, 2] *= 1.15
        out[:, :, 0] *= 0.85
        return out
    if variant == 'vignette':
        return vignette(img, 0.10 if view == 0 else -0.10)
    if variant == 'blurR':
        return cv2.GaussianBlur(img, (0, 0), 1.5) if view == 1 else img
    if variant == 'motion':
        return cv2.blur(img, (5, 1))  # 5 px horizontal box
    if variant == 'chroma':
        return chroma(img, 6.0, rng)
    if variant == 'sp':
        return salt_pepper(img, 0.005, rng)
    if variant == 'clip':
        return img * 1.8
    if variant == 'resamp':
        h, w = img.shape[:2]
        small = cv2.resize(img, (int(round(w * 0.6)), int(round(h * 0.6))), interpolation=cv2.INTER_AREA)
        return cv2.resize(small, (w, h), interpolation=cv2.INTER_CUBIC)
    if variant == 'dark_jpeg':
        return jpeg(gauss_noise(img * 0.2, 2.0, rng), 60)
    if variant == 'dark_nojpeg':  # extra: dark_jpeg without the JPEG step (decomposition)
        return gauss_noise(img * 0.2, 2.0, rng)
    if variant == 'noise_uneq':
        return gauss_noise(img, 2.0 if view == 0 else 10.0, rng)
    raise SystemExit(f'unknown variant {variant}')


def main():
    if len(sys.argv) != 4 or sys.argv[2] not in VARIANTS:
        sys.exit('usage: other-degradations.py SRC VARIANT OUT   (VARIANT: ' + ' '.join(VARIANTS) + ')')
    src, variant, out = sys.argv[1], sys.argv[2], os.path.abspath(sys.argv[3])
    if os.path.exists(out):
        sys.exit(f'error: {out} exists; refusing to write over it')
    scenes = sorted(d for d in os.listdir(src) if os.path.isfile(os.path.join(src, d, 'im0.png')))
    if not scenes:
        sys.exit(f'error: {src} holds no scene folder (im0.png, im1.png)')
    # Built in a hidden folder of our own beside OUT (created here, so never someone else's) and renamed at the end.
    tmp = os.path.join(os.path.dirname(out), f'.{os.path.basename(out)}.partial-{os.getpid()}')
    os.mkdir(tmp)
    rngs = [np.random.default_rng(s) for s in np.random.SeedSequence(1).spawn(2)]
    try:
        for s in scenes:
            os.mkdir(os.path.join(tmp, s))
            for f in COPIED:
                if os.path.isfile(os.path.join(src, s, f)):
                    shutil.copy2(os.path.join(src, s, f), os.path.join(tmp, s, f))
            for view in (0, 1):
                name = f'im{view}.png'
                img = cv2.imread(os.path.join(src, s, name), cv2.IMREAD_COLOR)
                if img is None:
                    raise SystemExit(f'error: {os.path.join(src, s, name)}: not a readable image')
                res = degrade(variant, img.astype(np.float64), view, rngs[view])
                if not cv2.imwrite(os.path.join(tmp, s, name), np.clip(np.rint(res), 0, 255).astype(np.uint8)):
                    raise SystemExit(f'error: {os.path.join(tmp, s, name)}: could not be written')
        os.rename(tmp, out)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    print(f'{variant}: {len(scenes)} scenes -> {out}')


if __name__ == '__main__':
    main()
