"""Motion model: prediction from the reliable history, and its update (both engines)."""
from __future__ import annotations

import numpy as np

from . import engine
from .engine import jit
from .geometry import _nearest_kernel, _nearest_two

__all__ = ["predict_positions", "shift_history", "start_frame", "update_model"]


#: A marker slower than this (px/frame) by its motion model is still (the mount, the
#: reference dots): it measures and confirms a camera shift
#: (:meth:`~.glitch.GlitchStage._still_found`), and does not anchor the wide search's
#: consensus for moving markers (:meth:`~.identity.IdentityStage._consensus`).
STILL_SPEED = 0.3
#: The fast frame takes a marker (``F``) whose motion model's residual RMS is below
#: FAST_RMS px and whose last score was at least FAST_SCORE (with three points of history,
#: seen on the frame before, nothing near: see :func:`start_frame`).
FAST_RMS, FAST_SCORE = 0.35, 0.9
#: A fast-path marker is verified after its refinement (``Tracker._verify_fast`` and the
#: fast frame): its NCC at the refined pixel at least FAST_VERIFY_SCORE, its distance from
#: the prediction below the larger of FAST_VERIFY_PX and 4 residual RMS.
FAST_VERIFY_SCORE, FAST_VERIFY_PX = 0.85, 1.0
#: Running values, (weight of the old value, weight of the new one): an ok point's mass and
#: score references (the status rules' drops), and the motion model's residual RMS (on squares).
MASS_BLEND, SCORE_BLEND, RMS_BLEND = (0.9, 0.1), (0.7, 0.3), (0.8, 0.2)


def model_speed(hist_x, hist_t):
    """Each marker's speed (px a frame) over the last two points of its motion model's
    history (NaN without two)."""
    dt = np.abs(hist_t[:, 0] - hist_t[:, 1])
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.hypot(*(hist_x[:, 0] - hist_x[:, 1]).T) / dt


def predict_positions(hx, ht, nh, t):
    """Extrapolate each marker's reliable history to frame ``t``.

    Parameters
    ----------
    hx : (N, 3, 2) ndarray
        The last three reliable refined positions (x, y), newest first (NaN where absent).
    ht : (N, 3) ndarray of int
        Their frames.
    nh : (N,) ndarray of int
        How many of them are known (1-3).
    t : int
        Frame to predict.

    Returns
    -------
    (N, 2) ndarray
        Quadratic (Lagrange weights through three points, so gaps are handled), linear with
        two, constant with one; after a gap of more than 3 frames at most linear, of more
        than 8 constant (a quadratic explodes over long gaps).
    """
    t0, t1, t2 = ht[:, 0], ht[:, 1], ht[:, 2]
    d = np.abs(t - t0)
    if np.all((nh == 3) & (d == 1) & (np.abs(t0 - t1) == 1) & (np.abs(t1 - t2) == 1)):
        return 3.0 * hx[:, 0] - 3.0 * hx[:, 1] + hx[:, 2]
    order = np.where(d > 3, np.minimum(nh, 2), nh)
    order = np.where(d > 8, 1, order)
    return _lagrange(hx, ht.astype(float), order, float(t))


def _lagrange(hx, a, order, tq):
    """Each marker's history polynomial at frame(s) ``tq``: Lagrange weights through its
    ``order`` (1-3) newest points ``hx`` (N, 3, 2) at frames ``a`` (N, 3, float)."""
    a0, a1, a2 = a[:, 0], a[:, 1], a[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        q0 = (tq - a1) * (tq - a2) / ((a0 - a1) * (a0 - a2))
        q1 = (tq - a0) * (tq - a2) / ((a1 - a0) * (a1 - a2))
        q2 = (tq - a0) * (tq - a1) / ((a2 - a0) * (a2 - a1))
        l0 = (tq - a1) / (a0 - a1)
        l1 = (tq - a0) / (a1 - a0)
    c0 = np.where(order == 3, q0, np.where(order == 2, l0, 1.0))
    c1 = np.where(order == 3, q1, np.where(order == 2, l1, 0.0))
    c2 = np.where(order == 3, q2, 0.0)
    h1 = np.where(order[:, None] >= 2, hx[:, 1], 0.0)
    h2 = np.where(order[:, None] >= 3, hx[:, 2], 0.0)
    return c0[:, None] * hx[:, 0] + c1[:, None] * h1 + c2[:, None] * h2


def shift_history(hx, ht, nh, dt):
    """Move each marker's reliable history ``dt`` frames along its own motion.

    Parameters
    ----------
    hx : (N, 3, 2) ndarray
        The last three reliable positions (x, y) px, newest first (NaN where absent).
    ht : (N, 3) ndarray of int
        Their frames.
    nh : (N,) ndarray of int
        How many of them are known (1-3).
    dt : int
        Frames to move by (frame numbers: negative for a backward pass).

    Returns
    -------
    (N, 3, 2) ndarray
        Position ``k`` replaced by the history's own polynomial (quadratic through three
        points, linear through two, constant) at frame ``ht[:, k] + dt``; the frames
        ``ht`` are kept.

    Notes
    -----
    Used when frames were dropped (or one repeated): predicting frame ``t`` from the
    shifted history is the full-order extrapolation of the original history to frame
    ``t + dt``, the gaps stay as they were (the search windows and the motion model's
    limits do not widen for the frames that never reached the tracker), and the
    following frames continue from it.
    """
    out = hx.copy()
    if dt == 0:
        return out
    a = ht.astype(float)
    with np.errstate(invalid="ignore"):  # (NaN history rows of absent points)
        for k in range(3):
            v = _lagrange(hx, a, nh, a[:, k] + dt)
            known = (k < nh)
            out[known, k] = v[known]
    return out


def _pre_numpy(t, hx, ht, nh, resid_rms, lostflag, last_ok, last_score, stagger, h, rb, W, H, max_coast, every,
               search_radius, pred, gap, steady, inside, fits, r, F, wide, j2, d2, merged, crowded):
    """numpy twin of :func:`_pre_kernel` (same arguments, same in-place outputs)."""
    pred[:] = predict_positions(hx, ht, nh, t)
    gap[:] = np.abs(t - ht[:, 0])
    steady[:] = (gap == 1) & (nh == 3) & (np.abs(t - last_ok) == 1)
    lostflag |= gap > max_coast
    prx, pry = pred[:, 0], pred[:, 1]
    inside[:] = ~lostflag & (prx >= -0.5) & (prx <= W - 0.5) & (pry >= -0.5) & (pry <= H - 0.5)
    px = np.rint(np.where(inside, prx, 0.0))
    py = np.rint(np.where(inside, pry, 0.0))
    fits[:] = inside & (px - h >= 0) & (py - h >= 0) & (px + h <= W - 1) & (py + h <= H - 1)
    n = len(h)
    if n < 2:
        j2[:], d2[:] = -1, np.inf
    else:
        j, d, _ = _nearest_two(prx, pry, inside)
        j2[:], d2[:] = j, d
    jn0 = np.maximum(j2[:, 0], 0)
    merged[:] = inside & (d2[:, 0] < rb + rb[jn0] + 1.0)
    crowded[:] = d2[:, 0] < rb + rb[jn0] + 4.0
    F[:] = (fits & (nh == 3) & (gap == 1) & (resid_rms < FAST_RMS) & (last_score >= FAST_SCORE) & ~crowded
            & (stagger != t % every))
    wide[:] = fits & (nh == 1)
    r[:] = np.where(wide, search_radius,
                    np.clip(np.ceil(2.0 + 3.0 * resid_rms + (gap - 1)), 2, search_radius)).astype(np.int64)


def start_frame(t, hx, ht, nh, resid_rms, lostflag, last_ok, last_score, stagger, h, rb, W, H, max_coast, every,
                search_radius):
    """Predictions and search plan of frame ``t`` (the engine's :func:`_pre_kernel` or
    :func:`_pre_numpy`); returns a dict of pred, gap, steady, inside, fits, r, F, wide,
    j2, d2, merged, crowded. Marks markers that coasted beyond ``max_coast`` in
    ``lostflag``."""
    n = h.shape[0]
    o = dict(pred=np.empty((n, 2)), gap=np.empty(n, np.int64), steady=np.empty(n, np.bool_),
             inside=np.empty(n, np.bool_), fits=np.empty(n, np.bool_), r=np.empty(n, np.int64),
             F=np.empty(n, np.bool_), wide=np.empty(n, np.bool_), j2=np.empty((n, 2), np.int64),
             d2=np.empty((n, 2)), merged=np.empty(n, np.bool_), crowded=np.empty(n, np.bool_))
    fn = _pre_kernel if engine.use_numba() else _pre_numpy
    fn(t, hx, ht, nh, resid_rms, lostflag, last_ok, last_score, stagger, h, rb, W, H, max_coast, every,
       search_radius, o["pred"], o["gap"], o["steady"], o["inside"], o["fits"], o["r"], o["F"], o["wide"],
       o["j2"], o["d2"], o["merged"], o["crowded"])
    return o


def _history_numpy(t, X, Y, S, ST, rel, resid, mass, hx, ht, nh, resid_rms, last_score, last_ok, mass_ref,
                   score_ref, last_upd, par, upd):
    """numpy twin of :func:`_history_kernel` (same arguments, same in-place outputs)."""
    ri = np.flatnonzero(rel)
    if ri.size:
        us = ri[nh[ri] >= 2]
        if us.size:
            e = resid[us]
            resid_rms[us] = np.sqrt(RMS_BLEND[0] * resid_rms[us] ** 2 + RMS_BLEND[1] * e * e)
        hx[ri, 2] = hx[ri, 1]
        hx[ri, 1] = hx[ri, 0]
        hx[ri, 0, 0] = X[ri]
        hx[ri, 0, 1] = Y[ri]
        ht[ri, 2] = ht[ri, 1]
        ht[ri, 1] = ht[ri, 0]
        ht[ri, 0] = t
        np.minimum(nh + rel, 3, out=nh)
    ok = ST == 0
    last_score[:] = np.where(ok & np.isfinite(S), S, 0.0)
    last_ok[ok] = t
    mass_ref[ok] = MASS_BLEND[0] * mass_ref[ok] + MASS_BLEND[1] * mass[ok]
    score_ref[ok] = SCORE_BLEND[0] * score_ref[ok] + SCORE_BLEND[1] * S[ok]
    upd[:] = ok & (S >= par[0]) & (S < par[1]) & (np.abs(t - last_upd) >= par[2])


def update_model(t, X, Y, S, ST, rel, resid, mass, hx, ht, nh, resid_rms, last_score, last_ok, mass_ref, score_ref,
                 last_upd, par):
    """Feed the motion model with the points ``rel`` and update the running values of
    the ok points (the engine's :func:`_history_kernel` or :func:`_history_numpy`);
    returns which templates to update."""
    upd = np.empty(X.shape[0], np.bool_)
    fn = _history_kernel if engine.use_numba() else _history_numpy
    fn(t, X, Y, S, ST, rel, resid, mass, hx, ht, nh, resid_rms, last_score, last_ok, mass_ref, score_ref, last_upd,
       par, upd)
    return upd


@jit
def _pre_kernel(t, hx, ht, nh, resid_rms, lostflag, last_ok, last_score, stagger, h, rb, W, H, max_coast, every,
                search_radius, pred, gap, steady, inside, fits, r, F, wide, j2, d2, merged, crowded):
    """Compiled start of :meth:`_Tracker.step`: predictions (as :meth:`_Tracker.predict`),
    gaps, newly lost markers, window fits, nearest neighbours of the predictions, merged
    and crowded markers, the fast path and the search radii (in-place outputs)."""
    n = h.shape[0]
    tf = np.float64(t)
    for i in range(n):
        t0 = ht[i, 0]
        t1 = ht[i, 1]
        t2 = ht[i, 2]
        d = abs(t - t0)
        gap[i] = d
        order = nh[i]
        if d > 3:
            order = min(order, 2)
        if d > 8:
            order = 1
        a0 = np.float64(t0)
        a1 = np.float64(t1)
        a2 = np.float64(t2)
        if order == 3:
            c0 = (tf - a1) * (tf - a2) / ((a0 - a1) * (a0 - a2))
            c1 = (tf - a0) * (tf - a2) / ((a1 - a0) * (a1 - a2))
            c2 = (tf - a0) * (tf - a1) / ((a2 - a0) * (a2 - a1))
            pred[i, 0] = c0 * hx[i, 0, 0] + c1 * hx[i, 1, 0] + c2 * hx[i, 2, 0]
            pred[i, 1] = c0 * hx[i, 0, 1] + c1 * hx[i, 1, 1] + c2 * hx[i, 2, 1]
        elif order == 2:
            c0 = (tf - a1) / (a0 - a1)
            c1 = (tf - a0) / (a1 - a0)
            pred[i, 0] = c0 * hx[i, 0, 0] + c1 * hx[i, 1, 0]
            pred[i, 1] = c0 * hx[i, 0, 1] + c1 * hx[i, 1, 1]
        else:
            pred[i, 0] = hx[i, 0, 0]
            pred[i, 1] = hx[i, 0, 1]
        steady[i] = d == 1 and nh[i] == 3 and abs(t - last_ok[i]) == 1
        if not lostflag[i] and d > max_coast:
            lostflag[i] = True
        x = pred[i, 0]
        y = pred[i, 1]
        ins = (not lostflag[i]) and x >= -0.5 and x <= W - 0.5 and y >= -0.5 and y <= H - 0.5
        inside[i] = ins
        px = np.rint(x) if ins else 0.0
        py = np.rint(y) if ins else 0.0
        fits[i] = ins and px - h[i] >= 0 and py - h[i] >= 0 and px + h[i] <= W - 1 and py + h[i] <= H - 1
    _nearest_kernel(pred[:, 0], pred[:, 1], inside, j2, d2)
    for i in range(n):
        j = j2[i, 0]
        lim = rb[i] + rb[max(j, 0)]
        merged[i] = inside[i] and d2[i, 0] < lim + 1.0
        crowded[i] = d2[i, 0] < lim + 4.0
        F[i] = (fits[i] and nh[i] == 3 and gap[i] == 1 and resid_rms[i] < FAST_RMS and last_score[i] >= FAST_SCORE
                and not crowded[i] and stagger[i] != t % every)
        ri = np.ceil(2.0 + 3.0 * resid_rms[i] + (gap[i] - 1))
        ri = min(max(ri, 2.0), np.float64(search_radius))
        wide[i] = fits[i] and nh[i] == 1
        r[i] = search_radius if wide[i] else int(ri)




@jit
def _history_kernel(t, X, Y, S, ST, rel, resid, mass, hx, ht, nh, resid_rms, last_score, last_ok, mass_ref,
                    score_ref, last_upd, par, upd):
    """Compiled end of :meth:`_Tracker.step`: the motion model fed with the points ``rel``
    (history shift, count, residual RMS), the running values of the ok points, and which
    templates to update (``par``: update_score, refresh_below, update_every)."""
    for i in range(X.shape[0]):
        ok = ST[i] == 0
        if rel[i]:
            if nh[i] >= 2:
                e = resid[i]
                resid_rms[i] = np.sqrt(RMS_BLEND[0] * resid_rms[i] * resid_rms[i] + RMS_BLEND[1] * e * e)
            hx[i, 2, 0] = hx[i, 1, 0]
            hx[i, 2, 1] = hx[i, 1, 1]
            hx[i, 1, 0] = hx[i, 0, 0]
            hx[i, 1, 1] = hx[i, 0, 1]
            hx[i, 0, 0] = X[i]
            hx[i, 0, 1] = Y[i]
            ht[i, 2] = ht[i, 1]
            ht[i, 1] = ht[i, 0]
            ht[i, 0] = t
            nh[i] = min(nh[i] + 1, 3)
        last_score[i] = S[i] if ok and not np.isnan(S[i]) else 0.0
        upd[i] = False
        if ok:
            last_ok[i] = t
            mass_ref[i] = MASS_BLEND[0] * mass_ref[i] + MASS_BLEND[1] * mass[i]
            score_ref[i] = SCORE_BLEND[0] * score_ref[i] + SCORE_BLEND[1] * S[i]
            upd[i] = S[i] >= par[0] and S[i] < par[1] and abs(t - last_upd[i]) >= par[2]


