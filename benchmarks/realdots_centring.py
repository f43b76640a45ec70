"""Centring of real white dots: our refiner against plain centroids and library fits.

``python benchmarks/realdots_centring.py [--cameras cam1 cam2] [--seeds 0 1 2] [--every 6]
[--no-stills] [--no-seqs] [--csv FILE]``

Measurement only (DEV seeds of :mod:`wingphoto.synth.realdots`; never the TEST seeds).
On the still photographs ``cal1.tif`` / ``cal2.tif`` (``../shared/data/real-dots``) each
reference dot (MyPTV's centroid, ``camN_cal_points``) is centred from a click at its
nearest pixel by

* ``ours_pick``: the tracker's refined pick (``track_markers`` on the photograph given
  twice, frame 0: the pick refinement, as the tracker does it);
* ``ours_track``: frame 1 of that run (the per-frame refinement, with its ``sigma`` and
  status: ``ok%`` is the share ok, ``sig`` the median sigma);
* ``shape``: threshold at half the dot's contrast (background: a plane on the window's
  border), the connected pixels at the click, unweighted mean of their coordinates;
* ``wcent``: intensity-weighted centroid of the background-subtracted values over the
  pixels above a fifth of the contrast (connected to the click), no clip;
* ``ellipse``: ``cv2.fitEllipse`` on the outer contour of the half-contrast mask;
* ``rprops``: ``skimage.measure.regionprops(...).centroid_weighted`` of the
  half-contrast mask, intensity the background-subtracted image;
* ``gauss``: a 2-D elliptical Gaussian plus a plane fitted by ``scipy.optimize.least_squares``
  to the 13 x 13 window;
* ``ours_seq`` (sequences only): the whole sequence tracked from its frame-0 picks by
  ``track_markers``, as ``benchmarks/track_sweep.py`` does (every point with a position);
* ``myptv``: MyPTV's own segmentation as in its example configuration (Gaussian blur 0.4,
  local filter 20, threshold 14, the blob's brightness-weighted mean of the processed
  image) - the estimator the reference came from.

Then the same on frames (every ``--every``-th) of the rendered DEV sequences against
their exact truth (the reference mapped through the warp), clicking at the truth's
nearest pixel. Prints, per data set and method, the median, 90th percentile and worst
radial error (px), and writes every dot's errors to ``--csv``.
"""
from __future__ import annotations

import argparse
import logging
import os
import warnings

import numpy as np
import pandas as pd

HALF = 8  # half width of the analysis window (px): dots ~5 px across, ~33 px apart


def versions():
    """One line with the library versions the figures depend on."""
    import cv2
    import scipy
    import skimage

    return (f"numpy {np.__version__}; OpenCV {cv2.__version__}; scipy {scipy.__version__}; "
            f"scikit-image {skimage.__version__}")


def _window(img, ix, iy, half=HALF):
    """(patch, background-subtracted patch, noise, x0, y0) around the integer pixel (ix, iy)."""
    H, W = img.shape
    x0, x1 = max(ix - half, 0), min(ix + half + 1, W)
    y0, y1 = max(iy - half, 0), min(iy + half + 1, H)
    p = img[y0:y1, x0:x1].astype(np.float64)
    yy, xx = np.mgrid[y0:y1, x0:x1]
    b = np.zeros(p.shape, bool)
    b[:2], b[-2:], b[:, :2], b[:, -2:] = True, True, True, True
    A = np.column_stack([np.ones(b.sum()), xx[b] - ix, yy[b] - iy])
    coef = np.linalg.lstsq(A, p[b], rcond=None)[0]
    sig = p - (coef[0] + coef[1] * (xx - ix) + coef[2] * (yy - iy))
    dif = np.diff(p, axis=1).ravel()
    noise = 1.4826 * float(np.median(np.abs(dif - np.median(dif)))) / np.sqrt(2)
    return p, sig, noise, x0, y0


def _contrast(sig, noise):
    """The dot's contrast: the median of its 9 brightest pixels (a 1-3 px specular
    highlight, up to saturation on cam1, does not set it; a ~5 px dot has ~20 px)."""
    return float(np.median(np.sort(sig.ravel())[-9:]))


def _component(mask, lx, ly):
    """The connected part of ``mask`` at (lx, ly) (or at its nearest mask pixel)."""
    from scipy import ndimage

    lab, n = ndimage.label(mask)
    if n == 0:
        return None
    k = lab[ly, lx]
    if k == 0:
        yy, xx = np.nonzero(lab)
        j = np.argmin((xx - lx) ** 2 + (yy - ly) ** 2)
        if (xx[j] - lx) ** 2 + (yy[j] - ly) ** 2 > 4:
            return None
        k = lab[yy[j], xx[j]]
    return lab == k


def alternatives(img, starts):
    """Centres (n, 2) by each non-tracker method from integer starts (n, 2): a dict."""
    import cv2
    from scipy.optimize import least_squares
    from skimage.measure import regionprops

    n = len(starts)
    out = {k: np.full((n, 2), np.nan) for k in ("shape", "wcent", "ellipse", "rprops", "gauss")}
    for i, (sx, sy) in enumerate(np.rint(starts).astype(int)):
        p, sig, noise, x0, y0 = _window(img, sx, sy)
        lx, ly = sx - x0, sy - y0
        con = _contrast(sig, noise)
        half = _component(sig > 0.5 * con, lx, ly)
        if half is None:
            continue
        yy, xx = np.nonzero(half)
        out["shape"][i] = x0 + xx.mean(), y0 + yy.mean()
        fifth = _component(sig > 0.2 * con, lx, ly)
        w = np.where(fifth, sig, 0.0)
        gy, gx = np.mgrid[: sig.shape[0], : sig.shape[1]]
        out["wcent"][i] = x0 + (w * gx).sum() / w.sum(), y0 + (w * gy).sum() / w.sum()
        cs, _ = cv2.findContours(half.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        if cs and len(max(cs, key=len)) >= 5:
            (ex, ey), _, _ = cv2.fitEllipse(max(cs, key=len))
            out["ellipse"][i] = x0 + ex, y0 + ey
        rp = regionprops(half.astype(np.int32), intensity_image=np.maximum(sig, 0.0))
        if rp:
            cy, cx = rp[0].centroid_weighted
            out["rprops"][i] = x0 + cx, y0 + cy
        c = 6
        sub = p[max(ly - c, 0): ly + c + 1, max(lx - c, 0): lx + c + 1]
        oy, ox = max(ly - c, 0), max(lx - c, 0)
        qy, qx = np.mgrid[: sub.shape[0], : sub.shape[1]]
        bx, by = out["shape"][i] - (x0 + ox, y0 + oy)

        def res(q):
            a, mx, my, sx2, sy2, b0, b1, b2 = q
            g = a * np.exp(-0.5 * ((qx - mx) ** 2 / sx2 ** 2 + (qy - my) ** 2 / sy2 ** 2))
            return (g + b0 + b1 * qx + b2 * qy - sub).ravel()

        q0 = [con, bx, by, 1.5, 1.5, float(np.median(sub)), 0.0, 0.0]
        try:
            r = least_squares(res, q0, bounds=([0, -1, -1, 0.3, 0.3, -np.inf, -np.inf, -np.inf],
                                              [np.inf, sub.shape[1], sub.shape[0], 6, 6, np.inf, np.inf, np.inf]))
            out["gauss"][i] = x0 + ox + r.x[1], y0 + oy + r.x[2]
        except ValueError:
            pass
    return out


def myptv_centres(img, starts, threshold=14.0, blur=0.4, local=20.0):
    """MyPTV's 'labeling' segmentation (its example's settings); the blob at each start."""
    from scipy import ndimage

    f = img.astype(np.float32)
    b = ndimage.gaussian_filter(f, blur)
    num = b - ndimage.gaussian_filter(b, local)
    den = np.sqrt(ndimage.gaussian_filter(num * num, local))
    normed = np.divide(num, den, out=np.zeros_like(num), where=den != 0)
    proc = b * (normed > 1)
    lab, _ = ndimage.label(proc > threshold)
    out = np.full((len(starts), 2), np.nan)
    H, W = img.shape
    for i, (sx, sy) in enumerate(np.rint(starts).astype(int)):
        y0, y1, x0, x1 = max(sy - 3, 0), min(sy + 4, H), max(sx - 3, 0), min(sx + 4, W)
        ks = lab[y0:y1, x0:x1]
        ks = ks[ks > 0]
        if ks.size == 0:
            continue
        k = np.bincount(ks).argmax()
        yy, xx = np.nonzero(lab[max(sy - HALF, 0): sy + HALF + 1, max(sx - HALF, 0): sx + HALF + 1] == k)
        yy, xx = yy + max(sy - HALF, 0), xx + max(sx - HALF, 0)
        w = proc[yy, xx].astype(np.float64)
        out[i] = (w * xx).sum() / w.sum(), (w * yy).sum() / w.sum()
    return out


def ours(img, starts):
    """The tracker's centring from clicks at ``starts``: (pick xy, frame-1 xy, sigma, ok).

    ``track_markers`` on the image given twice; clicks it rejects (not on a marker, too
    near the edge) are dropped (NaN)."""
    from wingphoto import track_markers

    n = len(starts)
    keep = np.ones(n, bool)
    frames = np.stack([img, img]).astype(np.uint8 if img.max() <= 255 else np.uint16)
    while True:
        idx = np.flatnonzero(keep)
        try:
            tr = track_markers(frames, np.rint(starts[idx]), progress=False)
            break
        except ValueError as e:
            import re

            m = re.search(r"point (\d+)", str(e))
            if not m:
                raise
            keep[idx[int(m.group(1))]] = False
    pick = np.full((n, 2), np.nan)
    trk = np.full((n, 2), np.nan)
    sig = np.full(n, np.nan)
    ok = np.zeros(n, bool)
    t0 = tr[tr.frame == 0].sort_values("point")
    t1 = tr[tr.frame == 1].sort_values("point")
    pick[idx] = t0[["x", "y"]].to_numpy()
    moved = (t0["reason"] == "pick_moved").to_numpy()
    pick[idx[moved]] = np.nan
    trk[idx] = t1[["x", "y"]].to_numpy()
    sig[idx] = t1["sigma"].to_numpy()
    ok[idx] = (t1["status"] == "ok").to_numpy()
    return pick, trk, sig, ok


def measure(img, truth, label):
    """Errors of every method on one image against ``truth`` (n, 2): a DataFrame."""
    pick, trk, sig, ok = ours(img, truth)
    cent = alternatives(img, truth)
    cent["myptv"] = myptv_centres(img, truth)
    cent["ours_pick"] = pick
    cent["ours_track"] = trk
    rows = []
    for name, xy in cent.items():
        e = xy - truth
        rows.append(pd.DataFrame(dict(set=label, method=name, dot=np.arange(len(truth)), ex=e[:, 0], ey=e[:, 1],
                                      err=np.hypot(e[:, 0], e[:, 1]), sigma=sig if name == "ours_track" else np.nan,
                                      ok=ok if name == "ours_track" else False)))
    return pd.concat(rows)


def stills(cameras):
    """The per-dot errors on the still photographs (DataFrame)."""
    from wingphoto.synth import realdots

    out = []
    for cam in cameras:
        img, ref = realdots._load(None, cam)  # (float32 photograph, reference centroids)
        H, W = img.shape
        ref = ref[np.all((ref > 14) & (ref < np.array([W, H]) - 15), axis=1)]
        out.append(measure(img, ref, f"still_{cam}"))
    return pd.concat(out)


def sequences(cameras, seeds, every):
    """The per-dot errors on frames of rendered DEV sequences (DataFrame)."""
    from wingphoto import track_markers
    from wingphoto.synth import realdots
    from wingphoto.validation import point_errors

    out = []
    for cam in cameras:
        for seed in seeds:
            if seed not in realdots.DEV_SEEDS:
                raise SystemExit(f"seed {seed} is not a DEV seed {realdots.DEV_SEEDS}")
            seq = realdots.render_realdots(cam, seed=seed)
            tr = track_markers(seq.frames(cam), seq.picks(cam), camera=cam, progress=False)
            a = point_errors(tr, seq, cam)
            st = np.full(a["ok"].shape, "", object)
            st[tr["frame"].to_numpy(), tr["point"].to_numpy()] = tr["reason"].to_numpy()
            for k in range(0, len(seq), every):
                v = np.flatnonzero(seq.visible[k])
                d = measure(seq.images[k], seq.points[k, v], f"seq_{cam}")
                d["dot"] = v[d["dot"].to_numpy()]
                has = np.isfinite(a["error"][k, v])
                # the whole sequence tracked from its frame-0 picks (as the sweep does)
                d2 = pd.DataFrame(dict(set=f"seq_{cam}", method="ours_seq", dot=v[has], err=a["error"][k, v][has],
                                       sigma=a["sigma"][k, v][has], ok=a["ok"][k, v][has], reason=st[k, v][has]))
                d = pd.concat([d, d2])
                d["seed"], d["frame"] = seed, k
                out.append(d)
    return pd.concat(out)


def table(df):
    """Median, p90, worst error (px) per data set and method, and ours_track's ok share and sigma."""
    g = df.groupby(["set", "method"], sort=False)
    t = g["err"].agg(n="count", median="median", p90=lambda e: np.nanpercentile(e, 90), worst="max")
    t["ok%"] = g["ok"].mean() * 100
    t["sig"] = g["sigma"].median()
    return t


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cameras", nargs="+", default=["cam1", "cam2"])
    ap.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    ap.add_argument("--every", type=int, default=6, help="use every k-th frame of the sequences")
    ap.add_argument("--no-stills", action="store_true")
    ap.add_argument("--no-seqs", action="store_true")
    ap.add_argument("--csv", default=None)
    a = ap.parse_args(argv)
    logging.disable(logging.WARNING)
    warnings.filterwarnings("ignore")
    import wingphoto

    print(versions(), "; wingphoto from", os.path.dirname(wingphoto.__file__))
    parts = []
    if not a.no_stills:
        parts.append(stills(a.cameras))
    if not a.no_seqs:
        parts.append(sequences(a.cameras, a.seeds, a.every))
    df = pd.concat(parts)
    with pd.option_context("display.width", 200, "display.precision", 3):
        print(table(df).to_string(float_format=lambda v: f"{v:.3f}"))
    if a.csv:
        df.to_csv(a.csv, index=False)
        print("per-dot errors written to", a.csv)


if __name__ == "__main__":
    main()
