"""Motion model: prediction from the reliable history, and its update (both engines)."""
from __future__ import annotations

import numpy as np

from .engine import jit
from .geometry import _nearest_kernel


@jit
def _pre_kernel(t, hx, ht, nh, sigma, lostflag, last_ok, last_score, stagger, h, rb, W, H, max_coast, every,
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
        F[i] = (fits[i] and nh[i] == 3 and gap[i] == 1 and sigma[i] < 0.35 and last_score[i] >= 0.9
                and not crowded[i] and stagger[i] != t % every)
        ri = np.ceil(2.0 + 3.0 * sigma[i] + (gap[i] - 1))
        ri = min(max(ri, 2.0), np.float64(search_radius))
        wide[i] = fits[i] and nh[i] == 1
        r[i] = search_radius if wide[i] else int(ri)




@jit
def _history_kernel(t, X, Y, S, ST, rel, resid, mass, hx, ht, nh, sigma, last_score, last_ok, mass_ref,
                    score_ref, last_upd, par, upd):
    """Compiled end of :meth:`_Tracker.step`: the motion model fed with the points ``rel``
    (history shift, count, residual RMS), the running values of the ok points, and which
    templates to update (``par``: update_score, refresh_below, update_every)."""
    for i in range(X.shape[0]):
        ok = ST[i] == 0
        if rel[i]:
            if nh[i] >= 2:
                e = resid[i]
                sigma[i] = np.sqrt(0.8 * sigma[i] * sigma[i] + 0.2 * e * e)
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
            mass_ref[i] = 0.9 * mass_ref[i] + 0.1 * mass[i]
            score_ref[i] = 0.7 * score_ref[i] + 0.3 * S[i]
            upd[i] = S[i] >= par[0] and S[i] < par[1] and abs(t - last_upd[i]) >= par[2]


