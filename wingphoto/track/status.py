"""Statuses, reasons and the status rules of a point-frame (both engines)."""
from __future__ import annotations

import numpy as np

from .engine import jit

STATUS = ("ok", "flagged", "lost", "manual")
OK, FLAGGED, LOST, MANUAL = 0, 1, 2, 3
#: Reasons a point is flagged or lost (the ``reason`` column; "" when ok).
REASONS = (
    "",
    "low_score",
    "ambiguous",
    "merged",
    "conflict",
    "edge",
    "out_of_frame",
    "jump",
    "lost_track",
    "reacquired",
    "fb_disagree",
    "stereo",
    "no_signal",
    "appearance",
    "no_pick",
    "pick_moved",
    "foreign",
    "background",
)
_R = {name: i for i, name in enumerate(REASONS)}
_RULE_CODES = np.array([_R[k] for k in ("low_score", "no_signal", "merged", "appearance", "ambiguous", "jump",
                                        "foreign", "background", "conflict")], np.int8)
#: Flags about a point's precision, not its identity.
_SOFT = np.array([_R[k] for k in ("merged", "foreign", "background")], np.int8)
_IS_SOFT = np.isin(np.arange(len(REASONS)), _SOFT)


@jit
def _rules_kernel(fits, S, SEC, mass, mass0, mass_ref, score_ref, resid, sigma, gap, nh, foreign, bgres, peak,
                  peak0, XP, YP, prx, pry, inside, j2, rb, valley, lose, par, ST, RS, X, Y, codes):
    """Compiled status rules of :meth:`_Tracker.step` (the last rule that applies wins),
    then a conflict loser is put at its prediction and a lost point's position cleared.
    ``par``: min_score, lost_score, min_mass_ratio, max_mass_ratio, max_score_drop,
    ambiguity_margin, jump_px, bg residual, faded bg residual, faded, weak, merge valley,
    bridge; ``codes``: the reason codes of low_score, no_signal, merged, appearance,
    ambiguous, jump, foreign, background, conflict."""
    n = fits.shape[0]
    for i in range(n):
        if not fits[i]:
            continue
        sc = S[i]
        ms = mass[i]
        st = 0
        rs = 0
        if sc < par[0]:
            st, rs = 1, codes[0]
        if ms < par[2] * mass0[i]:
            st, rs = 1, codes[1]
        if np.isfinite(par[3]) and ms > par[3] * mass_ref[i]:
            st, rs = 1, codes[2]
        if np.isfinite(par[4]) and sc < score_ref[i] - par[4]:
            st, rs = 1, codes[3]
        if SEC[i] >= sc - par[5]:
            st, rs = 1, codes[4]
        lim = max(par[6], 4.0 * sigma[i] + 2.0 * (gap[i] - 1))
        if nh[i] >= 3 and resid[i] > lim:
            st, rs = 1, codes[5]
        if foreign[i]:
            st, rs = 1, codes[6]
        bg = bgres[i]
        faded = peak[i] < par[9] * peak0[i] or sc < par[10]
        if bg > par[7] or (faded and bg > par[8]):
            st, rs = 1, codes[7]
        # blobs touching a neighbour's (matched, or predicted if tracked last frame)
        touch = False
        xi = XP[i] if not np.isnan(XP[i]) else (prx[i] if inside[i] and gap[i] == 1 else np.nan)
        yi = YP[i] if not np.isnan(YP[i]) else (pry[i] if inside[i] and gap[i] == 1 else np.nan)
        for k in range(2):
            j = j2[i, k]
            if j < 0:
                continue
            xj = XP[j] if not np.isnan(XP[j]) else (prx[j] if inside[j] and gap[j] == 1 else np.nan)
            yj = YP[j] if not np.isnan(YP[j]) else (pry[j] if inside[j] and gap[j] == 1 else np.nan)
            if np.hypot(xj - xi, yj - yi) < rb[i] + rb[j] + 1.0:
                touch = True
        vl = valley[i]
        if (touch and not (vl < par[11])) or vl > par[12]:
            st, rs = 1, codes[2]
        if lose[i]:
            st, rs = 1, codes[8]
        if ((sc < par[1]) or not (ms > 0)) and not lose[i]:
            st, rs = 2, codes[0]
        ST[i] = st
        RS[i] = rs
        if lose[i]:
            X[i] = prx[i]
            Y[i] = pry[i]
        if st == 2:
            X[i] = np.nan
            Y[i] = np.nan


