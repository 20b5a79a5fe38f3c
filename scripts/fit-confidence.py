#!/usr/bin/env python3
"""Fits the confidence's logistic model (src/post/confidence.rs) and reports its sparsification AUC, held out by
scene folds.

    cargo build --release --features confidence-dump
    mkdir DUMP && JEM_CONFIDENCE_DUMP=DUMP target/release/jem batch MIRROR --alg FIT --confidence --threads 1 --jobs 1
    python scripts/fit-confidence.py DUMP MIRROR [--features NAME,...]

MIRROR is a MiddEval3 trainingQ tree (scenes in path order, as batch runs them: dump k is scene k). The dump holds
the per-pixel inputs of each confidence map (`confidence-dump` feature); this script computes the pooled measures
from them as src/post/confidence.rs does, fits P(error > 1 px) on 20 000 nonocc pixels a scene by Newton's method
(a small ridge), and scores the sparsification AUC per scene on every nonocc pixel, as `jem eval` does: fitted on
all scenes, and held out (fitted on two folds, scored on the third; twins together). It prints the weights in
the order of the features, to paste into WEIGHTS.
"""
import argparse
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from pfm import read_pfm  # noqa: E402

FOLDS = [['Adirondack', 'ArtL', 'Jadeplant', 'Motorcycle', 'MotorcycleE'],
         ['Piano', 'PianoL', 'Pipes', 'Playroom', 'Recycle'],
         ['Playtable', 'PlaytableP', 'Shelves', 'Teddy', 'Vintage']]
AGREEMENT_SCALE_PX = 0.5
CAP_PX = 8.0
LN_FLOOR = 1e-3
PER_SCENE = 20000


def read_dump(path):
    with open(path, 'rb') as f:
        head = f.readline().split()
        w, h, names = int(head[0]), int(head[1]), [n.decode() for n in head[2:]]
        data = np.frombuffer(f.read(), dtype='<f4').reshape(len(names), h, w)
    return dict(zip(names, data))


def box_mean(p, r):
    """The mean over (2r + 1)² windows, borders replicated (filter::box_mean_separable)."""
    if r == 0:
        return p.astype(np.float64)
    q = np.pad(p.astype(np.float64), r, mode='edge')
    c = np.cumsum(np.cumsum(np.pad(q, ((1, 0), (1, 0))), 0), 1)
    k = 2 * r + 1
    s = c[k:, k:] - c[:-k, k:] - c[k:, :-k] + c[:-k, :-k]
    return s / (k * k)


def window_range(f, r):
    """max − min of the finite values over (2r + 1)² windows (0 where there is none)."""
    lo = np.where(np.isfinite(f), f, np.inf)
    hi = np.where(np.isfinite(f), f, -np.inf)
    lo = np.pad(lo, r, mode='constant', constant_values=np.inf)
    hi = np.pad(hi, r, mode='constant', constant_values=-np.inf)
    h, w = f.shape
    mn = np.full(f.shape, np.inf)
    mx = np.full(f.shape, -np.inf)
    for dy in range(2 * r + 1):
        for dx in range(2 * r + 1):
            mn = np.minimum(mn, lo[dy:dy + h, dx:dx + w])
            mx = np.maximum(mx, hi[dy:dy + h, dx:dx + w])
    return np.where(mn <= mx, mx - mn, 0.0)


def window_min(v, r):
    """The minimum over (2r + 1)² windows (inf padding)."""
    h, w = v.shape
    q = np.pad(v, r, mode='constant', constant_values=np.inf)
    rows = np.min([q[:, dx:dx + w] for dx in range(2 * r + 1)], 0)
    return np.min([rows[dy:dy + h] for dy in range(2 * r + 1)], 0)


def diff(a, b):
    ok = np.isfinite(a) & np.isfinite(b)
    return np.where(ok, np.minimum(np.abs(np.where(ok, a - b, 0)), CAP_PX), CAP_PX)


def measures(m):
    """Every candidate pooled measure of one dump, by name."""
    d, f, mm = m['decoded'], m['final'], np.clip(m['max_marginal'], 0, 1)
    e_lr = np.zeros_like(d) if np.isnan(m['right']).all() else diff(d, m['right'])
    e_co = np.zeros_like(d) if np.isnan(m['coarse']).all() else diff(f, m['coarse'])
    e_post = diff(f, d)
    s = mm * np.exp(-(e_lr + e_post + e_co) / AGREEMENT_SCALE_PX)
    gy, gx = np.gradient(m['grey'].astype(np.float64))
    tex = np.log1p(box_mean(np.hypot(gx, gy), 2))
    failed = 1.0 - m['consistent']
    rej = box_mean(failed, 3)
    out = {}
    for r in (1, 3, 6, 12, 25, 40):
        out[f'agree{r}'] = np.log(box_mean(s, r) + LN_FLOOR)
    for r in (0, 7, 15):
        out[f'tex{r}'] = box_mean(tex, r)
    out['tex_rel7'] = out['tex7'] - np.median(out['tex7'])
    out['edge'] = np.log1p(np.minimum(window_range(f, 1), 16))
    out['edge2'] = np.log1p(np.minimum(window_range(f, 2), 16))
    out['rej'] = rej
    out['rej7'] = box_mean(rej, 7)
    out['rej25'] = box_mean(rej, 25)
    out['dist_rej'] = np.log1p(m['dist_rejected'])
    ff = np.where(np.isfinite(f), f, 0)
    for r in (2, 7):
        var = np.maximum(box_mean(ff * ff, r) - box_mean(ff, r) ** 2, 0)
        out[f'fvar{r}'] = np.log1p(var)
    c0, c1, c2 = m['c0'], m['c1'], m['c2']
    d0, d1, d2 = m['d0'], m['d1'], m['d2']
    if not np.isnan(c0).all():
        pk = (c1 - c0) / (c1 + c0 + 1e-3)
        out['pkrn'] = pk
        for r in (2, 7, 15):
            out[f'pkrn{r}'] = box_mean(pk, r)
        near = np.minimum(np.minimum(diff(f, d0), diff(f, d1)), diff(f, d2))
        off0 = diff(f, d0)
        out['off_best'] = np.log1p(off0)
        for r in (2, 7, 15):
            out[f'off_best{r}'] = box_mean(np.log1p(off0), r)
        out['off_any'] = np.log1p(near)
        # The cost margin of the best minimum not at the answer, over the cost of the one at it.
        at = np.where(diff(f, d0) <= 1, c0, np.where(diff(f, d1) <= 1, c1, np.where(diff(f, d2) <= 1, c2, np.nan)))
        other = np.where(diff(f, d0) > 1, c0, np.where(diff(f, d1) > 1, c1, c2))
        margin = np.where(np.isnan(at), -0.5, (other - np.nan_to_num(at)) / (other + np.nan_to_num(at) + 1e-3))
        out['margin'] = margin
        for r in (2, 7, 15):
            out[f'margin{r}'] = box_mean(margin, r)
        at_best = diff(f, d0) <= 1
        for r in (3, 7, 15):
            out[f'against{r}'] = box_mean(np.where(at_best, 0, pk), r)
            out[f'offbest{r}'] = box_mean(1.0 - at_best, r)
        out['c0'] = c0
        out['c0_7'] = box_mean(c0, 7)
        out['c0_rel7'] = out['c0_7'] - np.median(c0)
        far = (np.abs(d1 - d0) > 2) & ((c1 - c0) / (c1 + c0 + 1e-3) < 0.1)
        out['amb15'] = box_mean(far.astype(float), 7)
    for r in (1, 7):
        out[f'mm{r}'] = np.log(box_mean(mm, r) + LN_FLOOR)
    for name, e in (('elr', e_lr), ('epost', e_post), ('eco', e_co)):
        for r in (2, 7, 15):
            out[f'{name}{r}'] = box_mean(np.log1p(e), r)
    dd = np.where(np.isfinite(d), d, 0)
    for r in (2, 7):
        out[f'dvar{r}'] = np.log1p(np.maximum(box_mean(dd * dd, r) - box_mean(dd, r) ** 2, 0))
    for r in (3, 7):
        out[f'edge_{r}'] = box_mean(out['edge'], r)
    gy, gx = np.gradient(ff)
    out['slant3'] = box_mean(np.log1p(np.minimum(np.hypot(gx, gy), 4)), 3)
    for r in (3, 7):
        fin = np.isfinite(f)
        hi = -window_min(np.where(fin, -f, np.inf), r)
        lo = window_min(np.where(fin, f, np.inf), r)
        out[f'above{r}'] = np.log1p(np.clip(np.where(fin & np.isfinite(hi), hi - f, 0), 0, 16))
        out[f'below{r}'] = np.log1p(np.clip(np.where(fin & np.isfinite(lo), f - lo, 0), 0, 16))
    gyg, gxg = np.gradient(m['grey'].astype(np.float64))
    out['texx7'] = box_mean(np.log1p(box_mean(np.abs(gxg), 2)), 7)
    out['texy7'] = box_mean(np.log1p(box_mean(np.abs(gyg), 2)), 7)
    out['texx0'] = np.log1p(box_mean(np.abs(gxg), 2))
    w = f.shape[1]
    out['fx'] = np.where(np.isfinite(f), f, 0) / max(np.nanmax(np.where(np.isfinite(f), f, np.nan)), 1)
    out['xrel'] = np.broadcast_to(np.arange(w)[None, :] / w, f.shape)
    return out


def auc(conf, bad):
    """Sparsification AUC as src/eval/sparsification.rs computes it (stable sort, most confident first)."""
    order = np.argsort(-conf, kind='stable')
    b = np.cumsum(bad[order])
    n = len(bad)
    kept = [max(n * k // 20, 1) for k in range(1, 21)]
    a = np.mean([b[m - 1] / m for m in kept])
    nbad = bad.sum()
    opt = np.mean([max(0, m - (n - nbad)) / m for m in kept])
    return a, opt


def fit(x, y, ridge=1e-3, iters=30):
    """Logistic regression by Newton's method on standardised features; weights in the features' own units."""
    mu, sd = x.mean(0), x.std(0) + 1e-9
    z = np.hstack([(x - mu) / sd, np.ones((len(x), 1))])
    beta = np.zeros(z.shape[1])
    for _ in range(iters):
        p = 1 / (1 + np.exp(-z @ beta))
        g = z.T @ (p - y) + ridge * len(x) * np.r_[beta[:-1], 0]
        hmat = (z * (p * (1 - p))[:, None]).T @ z + ridge * len(x) * np.diag(np.r_[np.ones(len(beta) - 1), 0])
        step = np.linalg.solve(hmat, g)
        beta -= step
        if np.abs(step).max() < 1e-8:
            break
    wts = beta[:-1] / sd
    return wts, beta[-1] - (wts * mu).sum(), beta[:-1]


def fit_mlp(x, y, hidden=8, steps=4000, batch=4096, lr=3e-3, seed=0):
    """A one-hidden-layer tanh network for P(error) (Adam, minibatches), on standardised features; returns a
    function of raw features giving the log-odds."""
    rng = np.random.default_rng(seed)
    mu, sd = x.mean(0), x.std(0) + 1e-9
    z = (x - mu) / sd
    n, k = z.shape
    params = [rng.normal(0, 1 / np.sqrt(k), (k, hidden)), np.zeros(hidden), rng.normal(0, 1 / np.sqrt(hidden), hidden),
              np.zeros(1)]
    m = [np.zeros_like(p) for p in params]
    v = [np.zeros_like(p) for p in params]
    for t in range(1, steps + 1):
        idx = rng.integers(0, n, batch)
        xb, yb = z[idx], y[idx]
        w1, b1, w2, b2 = params
        a = np.tanh(xb @ w1 + b1)
        logit = a @ w2 + b2[0]
        p = 1 / (1 + np.exp(-logit))
        g = (p - yb) / batch
        gw2 = a.T @ g
        gb2 = np.array([g.sum()])
        ga = np.outer(g, w2) * (1 - a * a)
        gw1 = xb.T @ ga + 1e-4 * w1
        gb1 = ga.sum(0)
        for i, gr in enumerate([gw1, gb1, gw2, gb2]):
            m[i] = 0.9 * m[i] + 0.1 * gr
            v[i] = 0.999 * v[i] + 0.001 * gr * gr
            params[i] = params[i] - lr * (m[i] / (1 - 0.9 ** t)) / (np.sqrt(v[i] / (1 - 0.999 ** t)) + 1e-8)
    w1, b1, w2, b2 = params
    return lambda xr: np.tanh(((xr - mu) / sd) @ w1 + b1) @ w2 + b2[0]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('dump')
    ap.add_argument('mirror')
    ap.add_argument('--features', default='agree1,agree12,agree25,tex7,edge,rej,rej7')
    ap.add_argument('--interactions', default='', help='pairs a*b, comma separated')
    ap.add_argument('--scale', type=float, default=1.0, help='bad threshold in matched px')
    ap.add_argument('--mlp', type=int, default=0, help='hidden units: a small network instead of the logistic')
    ap.add_argument('--test', nargs=2, action='append', default=[], metavar=('DUMP', 'MIRROR'),
                    help='also score the model fitted on all scenes on these (degraded copies; never fitted on)')
    ap.add_argument('--within', action='store_true', help='one intercept per scene while fitting (weights from the '
                    'variation within scenes; the mean intercept kept)')
    ap.add_argument('--stage2', default='', help='radii: a second logistic over the first one\'s log-odds pooled')
    args = ap.parse_args()
    scenes = sorted(s for s in os.listdir(args.mirror) if os.path.exists(os.path.join(args.mirror, s, 'im0.png')))
    names = args.features.split(',')
    inter = [p.split('*') for p in args.interactions.split(',') if p]
    rng = np.random.default_rng(0)
    data = {}
    radii = [int(r) for r in args.stage2.split(',') if r]
    load(args, args.dump, args.mirror, scenes, names, inter, rng, data, '')
    tests = []
    for i, (dump, mirror) in enumerate(args.test):
        load(args, dump, mirror, scenes, names, inter, rng, data, f'#{i}')
        tests.append((dump, [s + f'#{i}' for s in scenes]))
    run(args, scenes, names, inter, data, radii, tests)


def load(args, dump, mirror, scenes, names, inter, rng, data, tag):
    import cv2
    for k, scene in enumerate(scenes):
        m = read_dump(os.path.join(dump, f'{k:03d}.bin'))
        gt = read_pfm(os.path.join(mirror, scene, 'disp0GT.pfm'))
        mask = cv2.imread(os.path.join(mirror, scene, 'mask0nocc.png'), cv2.IMREAD_GRAYSCALE)
        assert gt.shape == m['final'].shape, (scene, gt.shape, m['final'].shape)
        meas = measures(m)
        cols = [meas[n] for n in names] + [meas[a] * meas[b] for a, b in inter]
        sel = np.isfinite(gt) & (mask == 255)
        f = m['final']
        bad = ~np.isfinite(f) | (np.abs(np.where(np.isfinite(f), f, 0) - gt) > args.scale)
        planes = np.stack(cols).astype(np.float32)
        x = planes[:, sel].T.astype(np.float64)
        invalid = ~np.isfinite(f[sel])
        sub = rng.choice(len(x), min(PER_SCENE, len(x)), replace=False)
        data[scene + tag] = (x, bad[sel].astype(float), invalid, sub, planes if args.stage2 else None, sel)


def run(args, scenes, names, inter, data, radii, tests):

    def score(model, scene):
        x, bad, invalid = data[scene][:3]
        conf = 1 / (1 + np.exp(model(x, scene)))
        conf[invalid] = 0
        return auc(conf.astype(np.float32), bad)

    def fit_on(group):
        x = np.vstack([data[s][0][data[s][3]] for s in group])
        y = np.concatenate([data[s][1][data[s][3]] for s in group])
        if args.mlp:
            net = fit_mlp(x, y, args.mlp)
            return (lambda xr, s: net(xr)), None
        if args.within:
            counts = [len(data[s][3]) for s in group]
            onehot = np.zeros((len(x), len(group) - 1))
            start = counts[0]
            for j, c in enumerate(counts[1:]):
                onehot[start:start + c, j] = 1
                start += c
            wts, b0, std = fit(np.hstack([x, onehot]), y)
            k = x.shape[1]
            b0 = b0 + wts[k:].sum() / len(group)
            wts, std = wts[:k], std[:k]
        else:
            wts, b0, std = fit(x, y)
        if not radii:
            return (lambda xr, s: xr @ wts + b0), (wts, b0, std)

        def second(s):
            planes, sel = data[s][4], data[s][5]
            logit = np.tensordot(wts, planes, 1) + b0
            return np.stack([logit[sel]] + [box_mean(logit, r)[sel] for r in radii], 1)
        x2 = np.vstack([second(s)[data[s][3]] for s in group])
        w2, b2, std2 = fit(x2, y)
        return (lambda xr, s: second(s) @ w2 + b2), (w2, b2, std2)

    model, linear = fit_on(scenes)
    held = {}
    for i, fold in enumerate(FOLDS):
        m2, _ = fit_on([s for s in scenes if s not in fold])
        for s in fold:
            held[s] = (score(m2, s)[0], i)
    rows = []
    for s in scenes:
        a, opt = score(model, s)
        rows.append((s, a, held[s][0], opt))
        print(f'{s:12s} fitted {a:.4f} held {held[s][0]:.4f} optimum {opt:.4f}')
    arr = np.array([r[1:] for r in rows])
    print(f'mean         fitted {arr[:, 0].mean():.4f} held {arr[:, 1].mean():.4f} optimum {arr[:, 2].mean():.4f}')
    for i, fold in enumerate(FOLDS):
        print(f'fold {"ABC"[i]} held {np.mean([held[s][0] for s in fold]):.4f}')
    for dump, group in tests:
        print(f'{dump}: fitted on all {np.mean([score(model, s)[0] for s in group]):.4f} optimum '
              f'{np.mean([score(model, s)[1] for s in group]):.4f}')
    labels = names + [f'{a}*{b}' for a, b in inter]
    if linear is None:
        return
    wts, b0, std = linear
    print('weights', ', '.join(f'{l}={v:.4f}' for l, v in zip(labels, wts)), f'bias={b0:.4f}')
    print('standardised', ', '.join(f'{l}={v:.3f}' for l, v in zip(labels, std)))


if __name__ == '__main__':
    main()
