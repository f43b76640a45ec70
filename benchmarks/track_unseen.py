"""Glitches and variations our renderers do not make, applied to their sequences after the fact.

Each run takes a sequence with exact truth - the independent renderer's (``wingphoto.synth.
independent``) or a real-dot one (``wingphoto.synth.realdots``) - changes it the way a
recording or a set-up might that no renderer of ours does, adjusts the truth where the change
moves the image, tracks it from frame-0 picks and prints the share of visible point-frames ok
and the confident errors (ok points more than 1 px from the truth). Seeds are not tuned on:
take fresh ones (the DEV seeds of session 26 were 360-364 and real-dot 5-12).

Variants of an independent render (``--kind hard`` or ``clean``; a frame ``k`` in the middle
third is chosen by the seed):

``bump DX,DY[,DEG]``  the camera shifted (and rolled) from frame k on
``black N``           N black frames from k;  ``dark N``: N near-black frames with noise
``dim G``, ``flash G``  frame k at gain G (with noise when dimmed)
``drop N``            N consecutive frames removed at k
``trunc``             the lower 40 % of frame k zero (a truncated transfer)
``tear``              the lower half of frame k copied byte for byte from frame k-1
``vib A,P``           a sinusoidal vibration of amplitude A px, period P frames, from k
``shake A``           a random shift of up to A px on every frame from k (not physical)
``nup S``             frames upsampled S times (bigger markers), then fresh noise
``soften S``          every frame blurred by a Gaussian of S px after its noise (correlated noise)

Variants of a real-dot sequence (``--realdots``): ``invert`` (dark dots), ``u16``, ``u12``,
``float``, ``gain`` (a quarter of the contrast), ``nup S``, ``soften S``.

Run::

    python benchmarks/track_unseen.py --seeds 360 361 --variants "tear" "bump 12,-9" "vib 1.5,12"
    python benchmarks/track_unseen.py --realdots --seeds 5 6 --variants invert "nup 2"
"""
from __future__ import annotations

import argparse
import logging
import sys

import cv2
import numpy as np


def _warp(img, M):
    H, W = img.shape
    return cv2.warpAffine(img, M, (W, H), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


def _upsample(F, s, rng, noise):
    F2 = np.stack([cv2.resize(f, None, fx=s, fy=s, interpolation=cv2.INTER_CUBIC) for f in F])
    top = np.iinfo(F.dtype).max if F.dtype.kind in "ui" else 1.0
    return np.clip(F2 + rng.normal(0, noise, F2.shape), 0, top).astype(F.dtype)


def apply_variant(F, T, V, name, arg, rng, k):
    """Return (frames, truth, visible) changed by variant ``name`` (argument string ``arg``)
    at frame ``k``; the inputs are not modified."""
    F, T, V = F.copy(), T.astype(float).copy(), V.copy()
    H, W = F.shape[1:]
    a = [float(v) for v in arg.split(",")] if arg else []
    if name == "bump":
        M = cv2.getRotationMatrix2D((W / 2 - 0.5, H / 2 - 0.5), a[2] if len(a) > 2 else 0.0, 1.0)
        M[:, 2] += a[:2]
        for t in range(k, len(F)):
            F[t] = _warp(F[t], M)
            T[t] = T[t] @ M[:, :2].T + M[:, 2]
    elif name in ("black", "dark"):
        n = int(a[0])
        F[k:k + n] = 0 if name == "black" else np.clip(rng.normal(3, 2, F[k:k + n].shape), 0, 255)
        V[k:k + n] = False
    elif name == "dim":
        F[k] = np.clip(F[k] * a[0] + rng.normal(0, 2, F[k].shape), 0, np.iinfo(F.dtype).max)
    elif name == "flash":
        F[k] = np.clip(F[k].astype(float) * a[0], 0, np.iinfo(F.dtype).max)
    elif name == "drop":
        keep = np.r_[0:k, k + int(a[0]):len(F)]
        F, T, V = F[keep], T[keep], V[keep]
    elif name == "trunc":
        F[k, int(0.6 * H):] = 0
        V[k] &= T[k, :, 1] < int(0.6 * H) - 0.5
    elif name == "tear":
        F[k, H // 2:] = F[k - 1, H // 2:]  # (truth: the instant of frame k)
    elif name in ("vib", "shake"):
        ph = rng.uniform(0, 2 * np.pi, 2)
        for t in range(k, len(F)):
            if name == "vib":
                d = a[0] * np.sin(2 * np.pi * (t - k) / a[1] + ph) - a[0] * np.sin(ph)
            else:
                d = rng.uniform(-a[0], a[0], 2)
            F[t] = _warp(F[t], np.float32([[1, 0, d[0]], [0, 1, d[1]]]))
            T[t] = T[t] + d
    elif name == "soften":  # every frame blurred after its noise (a colour camera's demosaicing, JPEG)
        F = np.stack([cv2.GaussianBlur(f, (0, 0), a[0]) for f in F])
    elif name == "nup":
        F = _upsample(F, a[0], rng, 2.0)
        T = (T + 0.5) * a[0] - 0.5
    elif name == "invert":
        F = (np.iinfo(F.dtype).max - F).astype(F.dtype)
    elif name == "u16":
        F = (F.astype(np.uint16) * 257 + rng.integers(0, 200, F.shape)).astype(np.uint16)
    elif name == "u12":
        F = F.astype(np.uint16) << 4
    elif name == "float":
        F = F.astype(np.float32) / 255.0
    elif name == "gain":
        F = (40 + F.astype(np.float32) * 0.25).astype(np.uint8)
    elif name != "none":
        raise SystemExit(f"unknown variant {name!r}; see python benchmarks/track_unseen.py --help")
    H, W = F.shape[1:]
    V &= (T[..., 0] >= -0.5) & (T[..., 0] <= W - 0.5) & (T[..., 1] >= -0.5) & (T[..., 1] <= H - 0.5)
    return F, T, V


def run_one(args, seed, camera, variant):
    from wingphoto import track_markers
    from wingphoto.synth import independent, realdots

    name, _, arg = variant.partition(" ")
    rng = np.random.default_rng(seed)
    if args.realdots:
        base = realdots.render_realdots(camera, seed=seed, n_frames=60 + realdots.GLITCH_SPARE)
        q = base.head(60)
        F, T, V = np.asarray(q.frames()), np.asarray(q.points, float), np.asarray(q.visible)
        picked = np.all(np.isfinite(base.picks()), axis=1)
        n_out = len(F)
    else:
        q = independent.render_independent(args.kind, seed=seed, camera=camera, n_frames=110)
        F, T, V = q.images, q.points, q.visible
        picked = V[0]
        n_out = 100
    k = int(rng.integers(len(F) // 3, 2 * len(F) // 3))
    F, T, V = apply_variant(F, T, V, name, arg, rng, k)
    F, T, V = F[:n_out], T[:n_out], V[:n_out]
    picks = np.round(T[0])
    picks[~(picked & V[0])] = np.nan
    tr = track_markers(F, picks, camera=camera, progress=False)
    tr = tr[tr.point.isin(np.flatnonzero(picked & V[0]))]
    fr, pt = tr.frame.to_numpy(), tr.point.to_numpy()
    err = np.hypot(tr.x.to_numpy() - T[fr, pt, 0], tr.y.to_numpy() - T[fr, pt, 1])
    ok = (tr.status == "ok").to_numpy()
    vis = V[fr, pt]
    return dict(seed=seed, camera=camera, variant=variant, frame=k, n_visible=int(vis.sum()),
                n_ok_visible=int((ok & vis).sum()), confident_errors=int((ok & (err > 1)).sum()),
                worst_px=float(np.nanmax(err[ok])) if ok.any() else np.nan)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, nargs="+", required=True, help="seeds (fresh ones: not tuned on)")
    ap.add_argument("--variants", nargs="+", default=["none", "tear", "bump 12,-9", "black 2", "vib 1.5,12"],
                    help='variants, e.g. "bump 12,-9" (see the module docstring)')
    ap.add_argument("--kind", default="hard", help="independent renderer kind (default hard)")
    ap.add_argument("--realdots", action="store_true", help="real-dot sequences (cameras cam1, cam2)")
    ap.add_argument("--csv", default=None, help="write the table here")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.ERROR)
    import pandas as pd

    cams = ("cam1", "cam2") if args.realdots else ("left", "right")
    rows = []
    for seed in args.seeds:
        for cam in cams:
            for v in args.variants:
                r = run_one(args, seed, cam, v)
                rows.append(r)
                print(f"{v:14s} {cam:5s} seed {seed:4d} (frame {r['frame']:2d}): ok {r['n_ok_visible']:5d} of "
                      f"{r['n_visible']:5d}, confident errors {r['confident_errors']}, worst {r['worst_px']:.2f} px",
                      flush=True)
    d = pd.DataFrame(rows)
    if args.csv:
        d.to_csv(args.csv, index=False)
    bad = d[d.confident_errors > 0]
    print(f"confident errors (ok > 1 px): {int(d.confident_errors.sum())} in {len(bad)} of {len(d)} sequences")
    return 0


if __name__ == "__main__":
    sys.exit(main())
