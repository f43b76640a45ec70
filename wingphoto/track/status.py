"""Statuses, reasons and the status rules of a point-frame.

The rules are ONE ordered table, :data:`RULES`: each engine computes the same condition
matrix (:func:`_conditions_kernel`, compiled, or its numpy twin :func:`_conditions_numpy`),
and :func:`apply_rules` gives every point the status and reason of the *last* rule that
applies (so a later rule overrides an earlier one: a point whose score fell below
``lost_score`` is lost, whatever else was wrong with it).
"""
from __future__ import annotations

import numpy as np

from . import engine
from .engine import jit

STATUS = ("ok", "flagged", "lost", "manual", "interpolated")
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
    "imprecise",
    "blank",
    "constellation",
    "misplaced",
)
_R = {name: i for i, name in enumerate(REASONS)}

#: How much further (px) from its prediction a marker may be found for each frame it went
#: unseen (``gap - 1``): the motion model's error grows while it coasts (the jump rule, the
#: constellation check of :class:`~.tracker.Tracker` and of the fast frame).
COAST_PX = 2.0
#: Two markers whose refined centres are closer than this many blob radii (the larger of
#: the two) sit on one blob: neither is ok (``Tracker._coincident``; the fast frame hands
#: such a frame to it).
COINCIDENT = 1.0
#: A marker found within STAY_PX of its prediction and of its last reliable position, with
#: a score of at least STAY_SCORE, stayed on its own blob: its identity is not in doubt
#: (``Tracker._judge`` and the fast frame).
STAY_PX, STAY_SCORE = 0.5, 0.95

#: The status rules, in order (the last that applies wins): (reason, status, condition).
RULES = (
    ("imprecise", FLAGGED, "sigma > max_sigma, or a faded blob on a rough background (a precision flag: any "
                           "identity rule below overrides it)"),
    ("low_score", FLAGGED, "score < min_score"),
    ("no_signal", FLAGGED, "mass < min_mass_ratio * frame-0 mass"),
    ("merged", FLAGGED, "mass > max_mass_ratio * running mass (off by default)"),
    ("appearance", FLAGGED, "score < running score - max_score_drop (off by default)"),
    ("ambiguous", FLAGGED, "an unexplained second correlation peak within ambiguity_margin"),
    ("jump", FLAGGED, "refined point further from the prediction than the motion model allows"),
    ("foreign", FLAGGED, "something bright no known marker explains touches the disk"),
    ("merged", FLAGGED, "the blob touches a neighbour's without a dark gap, or a bright bridge joins them"),
    ("conflict", FLAGGED, "another marker took this marker's blob"),
    ("low_score", LOST, "score < lost_score, or no positive mass"),
)
_RULE_STATUS = np.array([r[1] for r in RULES], np.int8)
_RULE_REASON = np.array([_R[r[0]] for r in RULES], np.int8)
N_RULES = len(RULES)
#: Flags about a point's precision, not its identity.
_SOFT = np.array([_R[k] for k in ("merged", "foreign", "background", "imprecise")], np.int8)
_IS_SOFT = np.isin(np.arange(len(REASONS)), _SOFT)


@jit
def _conditions_kernel(fits, S, SEC, mass, mass0, mass_ref, score_ref, resid, resid_rms, gap, nh, foreign, imprecise,
                       XP, YP, prx, pry, inside, j2, rb, valley, lose, par, cond):
    """Compiled condition matrix ``cond`` (n, N_RULES) of :data:`RULES` (rows of markers
    whose window fits; the others stay False). ``par``: min_score, lost_score,
    min_mass_ratio, max_mass_ratio, max_score_drop, ambiguity_margin, jump_px, merge
    valley, bridge."""
    n = fits.shape[0]
    for i in range(n):
        for k in range(cond.shape[1]):
            cond[i, k] = False
        if not fits[i]:
            continue
        sc = S[i]
        ms = mass[i]
        cond[i, 0] = imprecise[i]
        cond[i, 1] = sc < par[0]
        cond[i, 2] = ms < par[2] * mass0[i]
        cond[i, 3] = np.isfinite(par[3]) and ms > par[3] * mass_ref[i]
        cond[i, 4] = np.isfinite(par[4]) and sc < score_ref[i] - par[4]
        cond[i, 5] = SEC[i] >= sc - par[5]
        lim = max(par[6], 4.0 * resid_rms[i] + COAST_PX * (gap[i] - 1))
        cond[i, 6] = nh[i] >= 3 and resid[i] > lim
        cond[i, 7] = foreign[i]
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
        cond[i, 8] = (touch and not (vl < par[7])) or vl > par[8]
        cond[i, 9] = lose[i]
        cond[i, 10] = ((sc < par[1]) or not (ms > 0)) and not lose[i]


def _conditions_numpy(fits, S, SEC, mass, mass0, mass_ref, score_ref, resid, resid_rms, gap, nh, foreign, imprecise,
                      XP, YP, prx, pry, inside, j2, rb, valley, lose, par, cond):
    """numpy twin of :func:`_conditions_kernel` (same arguments, same output)."""
    with np.errstate(invalid="ignore"):
        lim = np.maximum(par[6], 4.0 * resid_rms + COAST_PX * (gap - 1))
        px = np.where(np.isfinite(XP), XP, np.where(inside & (gap == 1), prx, np.nan))
        py = np.where(np.isfinite(YP), YP, np.where(inside & (gap == 1), pry, np.nan))
        j = np.maximum(j2, 0)
        d = np.hypot(px[j] - px[:, None], py[j] - py[:, None])
        d[j2 < 0] = np.inf
        touch = (d < rb[:, None] + rb[j] + 1.0).any(1)
        c = np.column_stack([
            imprecise,
            S < par[0],
            mass < par[2] * mass0,
            np.isfinite(par[3]) & (mass > par[3] * mass_ref),
            np.isfinite(par[4]) & (S < score_ref - par[4]),
            SEC >= S - par[5],
            (nh >= 3) & (resid > lim),
            foreign,
            (touch & ~(valley < par[7])) | (valley > par[8]),
            lose,
            ((S < par[1]) | ~(mass > 0)) & ~lose,
        ])
    cond[:] = c & fits[:, None]


def rule_conditions(*args):
    """Condition matrix of :data:`RULES` by the engine in use (see :func:`_conditions_kernel`)."""
    fits = args[0]
    cond = np.empty((fits.shape[0], N_RULES), np.bool_)
    (_conditions_kernel if engine.use_numba() else _conditions_numpy)(*args, cond)
    return cond


def apply_rules(cond, ST, RS):
    """Give each point with a rule that applies the status and reason of the last one.

    Parameters
    ----------
    cond : (n, N_RULES) ndarray of bool
    ST, RS : (n,) ndarray of int8
        Status and reason codes, changed in place where a rule applies; left as they are
        where none does (the caller sets the matched points ok first).
    """
    any_ = cond.any(1)
    last = N_RULES - 1 - np.argmax(cond[:, ::-1], axis=1)
    ST[any_] = _RULE_STATUS[last[any_]]
    RS[any_] = _RULE_REASON[last[any_]]
