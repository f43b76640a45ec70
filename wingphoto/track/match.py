"""Windowed normalised cross-correlation and peak analysis (both engines)."""
from __future__ import annotations

import cv2
import numpy as np

from . import engine
from .engine import jit


@jit(fastmath=True)
def _ncc_kernel(frame, tz, tid, th, cx, cy, rr, maps, origin, shape):
    """Compiled windowed TM_CCOEFF_NORMED (as :func:`match_windows`) with zero-mean,
    unit-norm templates ``tz[tid]`` (S, S), each (2 th + 1)^2 at the centre of its array."""
    H, W = frame.shape
    n = cx.shape[0]
    c0 = tz.shape[1] // 2
    for i in range(n):
        h = th[i]
        r = rr[i]
        x0 = max(cx[i] - h - r, 0)
        y0 = max(cy[i] - h - r, 0)
        x1 = min(cx[i] + h + r + 1, W)
        y1 = min(cy[i] + h + r + 1, H)
        origin[i, 0] = x0 + h
        origin[i, 1] = y0 + h
        s = 2 * h + 1
        rows = y1 - y0 - 2 * h
        cols = x1 - x0 - 2 * h
        if rows <= 0 or cols <= 0:
            shape[i, 0] = 0
            shape[i, 1] = 0
            continue
        shape[i, 0] = rows
        shape[i, 1] = cols
        wh = y1 - y0
        ww = x1 - x0
        win = np.empty((wh, ww), np.float32)
        ii = np.zeros((wh + 1, ww + 1))
        i2 = np.zeros((wh + 1, ww + 1))
        for a in range(wh):
            run = 0.0
            run2 = 0.0
            for b in range(ww):
                val = np.float64(frame[y0 + a, x0 + b])
                win[a, b] = val
                run += val
                run2 += val * val
                ii[a + 1, b + 1] = ii[a, b + 1] + run
                i2[a + 1, b + 1] = i2[a, b + 1] + run2
        ti = tid[i]
        t0 = c0 - h
        tp = np.empty((s, s), np.float32)
        for p in range(s):
            for q in range(s):
                tp[p, q] = tz[ti, t0 + p, t0 + q]
        N = float(s * s)
        for a in range(rows):
            for b in range(cols):
                acc = np.float32(0.0)
                for p in range(s):
                    for q in range(s):
                        acc += win[a + p, b + q] * tp[p, q]
                s1 = ii[a + s, b + s] - ii[a, b + s] - ii[a + s, b] + ii[a, b]
                s2 = i2[a + s, b + s] - i2[a, b + s] - i2[a + s, b] + i2[a, b]
                var = s2 - s1 * s1 / N
                if var > 1e-6 * (s2 + 1.0):
                    maps[i, a, b] = acc / np.sqrt(var)
                else:
                    maps[i, a, b] = 0.0


@jit
def _score1(frame, tz, ti, h, x, y):
    """TM_CCOEFF_NORMED of template ``tz[ti]`` centred at pixel (x, y); -2 off the image."""
    H, W = frame.shape
    c0 = tz.shape[1] // 2
    x0 = x - h
    y0 = y - h
    s = 2 * h + 1
    if x0 < 0 or y0 < 0 or x0 + s > W or y0 + s > H:
        return -2.0
    t0 = c0 - h
    s1 = s2 = num = 0.0
    for p in range(s):
        for q in range(s):
            val = np.float64(frame[y0 + p, x0 + q])
            s1 += val
            s2 += val * val
            num += val * tz[ti, t0 + p, t0 + q]
    var = s2 - s1 * s1 / (s * s)
    return num / np.sqrt(var) if var > 1e-6 * (s2 + 1.0) else 0.0


@jit
def _score_kernel(frame, tz, tid, th, cx, cy, out):
    """TM_CCOEFF_NORMED of template ``tz[tid[i]]`` centred at pixel (cx, cy) (0 where it
    does not fit in the image or the window is flat)."""
    for i in range(cx.shape[0]):
        s = _score1(frame, tz, tid[i], th[i], cx[i], cy[i])
        out[i] = 0.0 if s == -2.0 else s


@jit
def _climb_kernel(frame, tz, tid, th, cx, cy, rr, out):
    """Hill-climb the correlation from the predicted pixel (cx, cy) within +/- rr px:
    the local maximum nearest the prediction, at a fraction of a full window's cost.
    ``out`` (n, 4): x, y, score, rim (1 where the climb reached the window's edge)."""
    for i in range(cx.shape[0]):
        h = th[i]
        ti = tid[i]
        x = cx[i]
        y = cy[i]
        best = _score1(frame, tz, ti, h, x, y)
        for _ in range(4 * rr[i] + 4):
            bx = x
            by = y
            bs = best
            for a in range(-1, 2):
                for b in range(-1, 2):
                    if a == 0 and b == 0:
                        continue
                    nx = x + b
                    ny = y + a
                    if abs(nx - cx[i]) > rr[i] or abs(ny - cy[i]) > rr[i]:
                        continue
                    sc = _score1(frame, tz, ti, h, nx, ny)
                    if sc > bs:
                        bs = sc
                        bx = nx
                        by = ny
            if bx == x and by == y:
                break
            x = bx
            y = by
            best = bs
        out[i, 0] = x
        out[i, 1] = y
        out[i, 2] = best
        out[i, 3] = 1.0 if (abs(x - cx[i]) == rr[i] or abs(y - cy[i]) == rr[i]) else 0.0




@jit
def _analyse_kernel(maps, shape, excl, oth, out):
    """Compiled twin of :func:`_analyse_maps`; ``oth`` (n, K, 2) cells to exclude (NaN
    none); ``out`` (n, 5) receives u, v, score, second, border."""
    n, m, _ = maps.shape
    for i in range(n):
        rows = shape[i, 0]
        cols = shape[i, 1]
        best = -np.inf
        bu = 0
        bv = 0
        for v in range(m):
            for u in range(m):
                if maps[i, v, u] > best:
                    best = maps[i, v, u]
                    bu = u
                    bv = v
        border = bu == 0 or bv == 0 or bu == cols - 1 or bv == rows - 1
        second = -2.0
        if m >= 3:
            ex2 = excl[i] * excl[i]
            lim = excl[i] + m
            for v in range(1, rows - 1):
                for u in range(1, cols - 1):
                    val = maps[i, v, u]
                    if val < second:
                        continue
                    if (u - bu) * (u - bu) + (v - bv) * (v - bv) <= ex2:
                        continue
                    is_max = True
                    for a in range(-1, 2):
                        for b in range(-1, 2):
                            if maps[i, v + a, u + b] > val:
                                is_max = False
                    if not is_max:
                        continue
                    skip = False
                    for k in range(oth.shape[1]):
                        ou = oth[i, k, 0]
                        ov = oth[i, k, 1]
                        if np.isnan(ou) or not (abs(ou - m / 2) < lim and abs(ov - m / 2) < lim):
                            continue
                        if (u - ou) * (u - ou) + (v - ov) * (v - ov) <= ex2:
                            skip = True
                    if not skip:
                        second = val
        out[i, 0] = bu
        out[i, 1] = bv
        out[i, 2] = best
        out[i, 3] = second
        out[i, 4] = 1.0 if border else 0.0




# --------------------------------------------------------------------------- matcher
def match_windows(frame, templates, centres, radii):
    """Correlate each template in a small window around its predicted centre.

    The fast windowed matcher: one ``cv2.matchTemplate`` (``TM_CCOEFF_NORMED``) per
    marker on a ``(2 h + 2 r + 1)``-pixel window; maps are returned padded in one array
    so that peak finding is vectorised across markers.

    Parameters
    ----------
    frame : (H, W) ndarray of uint8 or float32
        Image (other dtypes are converted to float32 window by window).
    templates : list of (2h+1, 2h+1) ndarrays
        One odd-sized template per marker, its centre pixel on the marker centre; uint8
        for uint8 frames, float32 otherwise.
    centres : (N, 2) array_like of int
        Predicted centre pixel (x, y) of each marker.
    radii : (N,) array_like of int
        Search radius in px (the window holds the centre +/- radius).

    Returns
    -------
    maps : (N, M, M) ndarray of float32
        Correlation maps, ``M = 2 max(radii) + 1``, padded with -2; ``maps[i, v, u]`` is
        the score of centring marker i at pixel ``(origin[i, 0] + u, origin[i, 1] + v)``.
    origin : (N, 2) ndarray of int64
        Pixel (x, y) of each map's cell (0, 0).
    shape : (N, 2) ndarray of int64
        Valid (rows, cols) of each map (smaller where the window is clipped by the image
        edge; 0 where the template does not fit).
    """
    centres = np.asarray(centres, dtype=np.int64).reshape(-1, 2)
    radii = np.asarray(radii, dtype=np.int64).reshape(-1)
    n = len(centres)
    m = 2 * int(radii.max()) + 1 if n else 1
    maps = np.full((n, m, m), -2.0, np.float32)
    origin = np.zeros((n, 2), np.int64)
    shape = np.zeros((n, 2), np.int64)
    H, W = frame.shape
    conv = frame.dtype != np.uint8 and frame.dtype != np.float32
    method = cv2.TM_CCOEFF_NORMED
    mt = cv2.matchTemplate
    cx_l = centres[:, 0].tolist()
    cy_l = centres[:, 1].tolist()
    r_l = radii.tolist()
    for i in range(n):
        tpl = templates[i]
        h = tpl.shape[0] // 2
        r = r_l[i]
        cx, cy = cx_l[i], cy_l[i]
        x0 = cx - h - r
        y0 = cy - h - r
        x1 = cx + h + r + 1
        y1 = cy + h + r + 1
        if x0 < 0:
            x0 = 0
        if y0 < 0:
            y0 = 0
        if x1 > W:
            x1 = W
        if y1 > H:
            y1 = H
        origin[i, 0] = x0 + h
        origin[i, 1] = y0 + h
        if x1 - x0 <= 2 * h or y1 - y0 <= 2 * h:
            continue
        win = frame[y0:y1, x0:x1]
        if conv:
            win = win.astype(np.float32)
        res = mt(win, tpl, method)
        rh, rw = res.shape
        maps[i, :rh, :rw] = res
        shape[i, 0] = rh
        shape[i, 1] = rw
    return maps, origin, shape


# --------------------------------------------------------------------------- peaks
_K3 = np.ones((3, 3), np.uint8)


def _analyse_maps(maps, shape, excl, others=()):
    """Best peak, runner-up local maximum and border test for padded correlation maps.

    others : sequence of (n, 2) float arrays of map cells (u, v) to exclude from the
        runner-up search (other markers' expected positions), NaN for none.
    """
    n, m, _ = maps.shape
    if n == 0:  # (the numpy twin's reshapes and cv2.dilate cannot take 0 maps)
        e = np.empty(0)
        return e.astype(np.int64), e.astype(np.int64), e, e, e.astype(bool)
    if engine.use_numba():
        oth = np.full((n, max(len(others), 1), 2), np.nan)
        for q, o in enumerate(others):
            oth[:, q] = o
        out = np.empty((n, 5))
        _analyse_kernel(maps, shape, np.asarray(excl, np.float64), oth, out)
        return out[:, 0].astype(np.int64), out[:, 1].astype(np.int64), out[:, 2], out[:, 3], out[:, 4] > 0
    flat = maps.reshape(n, -1)
    k = flat.argmax(1)
    score = flat[np.arange(n), k].astype(np.float64)
    v = k // m
    u = k - v * m
    rows = shape[:, 0]
    cols = shape[:, 1]
    border = (u == 0) | (v == 0) | (u == cols - 1) | (v == rows - 1)
    if m < 3:
        return u, v, score, np.full(n, -2.0), border
    pad = np.full((n, m + 1, m), -2.0, np.float32)
    pad[:, :m] = maps
    dil = cv2.dilate(pad.reshape(-1, m), _K3).reshape(n, m + 1, m)[:, :m]
    g = _GRID[:m]
    GU = g[None, None, :]
    GV = g[None, :, None]
    ex2 = (excl * excl)[:, None, None]
    # interior local maxima away from the best peak
    cand = maps >= dil
    cand[:, 0, :] = False
    cand[:, :, 0] = False
    if (rows < m).any() or (cols < m).any():
        cand &= (GU <= (cols - 2)[:, None, None]) & (GV <= (rows - 2)[:, None, None])
    else:
        cand[:, m - 1, :] = False
        cand[:, :, m - 1] = False
    du = GU - u[:, None, None]
    dv = GV - v[:, None, None]
    cand &= (du * du + dv * dv) > ex2
    for o in others:
        lim = excl + m
        use = np.isfinite(o[:, 0]) & (np.abs(o[:, 0] - m / 2) < lim) & (np.abs(o[:, 1] - m / 2) < lim)
        if not use.any():
            continue
        ui = np.flatnonzero(use)
        ou = o[ui, 0][:, None, None]
        ov = o[ui, 1][:, None, None]
        near = ((GU - ou) ** 2 + (GV - ov) ** 2) <= ex2[ui]
        cand[ui] &= ~near
    second = np.where(cand, maps, -2.0).reshape(n, -1).max(1).astype(np.float64)
    return u, v, score, second, border


_GRID = np.arange(256)


