"""PFM reading and writing for the Python helper scripts (scripts/ood-set.py, scripts/sgbm-baseline.py): one grey
channel, little-endian on writing, rows bottom to top as the format stores them (returned and taken top to bottom)."""
import sys

import numpy as np


def read_pfm(path):
    """A PFM file as a float32 array (the first channel of a colour PFM)."""
    with open(path, 'rb') as f:
        kind = f.readline().strip()
        if kind not in (b'Pf', b'PF'):
            sys.exit(f'error: {path}: not a PFM file')
        w, h = map(int, f.readline().split())
        scale = float(f.readline())
        channels = 3 if kind == b'PF' else 1
        data = np.frombuffer(f.read(w * h * channels * 4), dtype='<f4' if scale < 0 else '>f4')
    a = data.reshape(h, w, channels)[..., 0] if channels == 3 else data.reshape(h, w)
    return np.flipud(a).astype(np.float32)


def write_pfm(path, a):
    """A 2-D array as a one-channel little-endian PFM."""
    a = np.asarray(a, dtype='<f4')
    h, w = a.shape
    with open(path, 'wb') as f:
        f.write(b'Pf\n%d %d\n-1\n' % (w, h))
        f.write(np.flipud(a).tobytes())
