"""Hops: whether a marker's path, followed while it was not ok, changed blob.

The rule (:meth:`~.identity.IdentityStage._hopped` documents why) is applied to every
``imprecise`` marker on every frame, over its whole path since its last ok frame, and such
runs last hundreds of frames on real dots. The numpy twin walks one marker at a time with
some twenty array calls each (~70 us); the compiled kernel walks all of them in one call.
Written by hand: no library follows a path for hops.
"""
from __future__ import annotations

import math

import numpy as np

from . import engine
from .engine import jit


def _frames_since(t0, t, T):
    """The frames strictly between a marker's last ok frame ``t0`` and frame ``t``, in the
    order of the pass (none when ``t0`` is not a frame of the ``T`` rows)."""
    if not 0 <= t0 < T:
        return np.zeros(0, np.int64)
    return np.arange(t0, t, 1 if t > t0 else -1)[1:]


#: A step of a marker's path while not ok that differs from the step before by more than
#: this fraction of its spacing is a hop onto another blob.
HOP_FRACTION = 0.4
#: A step shorter than this (px) between two longer ones is a one-frame stall (a repeated
#: frame), not part of a hop.
STALL_PX = 0.5
#: ... and the path resumes within this fraction of the hop limit (on schedule, or one
#: frame late). With the whole hop limit, a marker slowing at a reversal (0.4 px/frame)
#: before a 9 px hop onto a neighbour's blob was a 'stall' that hid the hop: it resumed
#: ok there, 10 px off (independent renderer, black, fresh DEV seed 57 right).
STALL_RESUME = 0.5
#: Steps over at most this many frames without a position count at their mean velocity.
_GAP_FRAMES = 3


def path_hopped(fr, P, lim):
    """Whether a path hopped (numpy twin of the compiled kernel).

    Parameters
    ----------
    fr : (M,) int array
        Frames of the positions, in the order of the pass (no frame without a position).
    P : (M, 2) float array
        Positions (x, y).
    lim : float
        Largest change of velocity between two steps (px/frame) that is not a hop.

    Returns
    -------
    bool
    """
    if fr.size < 3:
        return False
    cons = np.abs(np.diff(fr)) == 1
    V = np.diff(P, axis=0)
    keep = np.ones(fr.size, bool)
    # a one-frame stall (a repeated frame): a short step between two consecutive ones,
    # after which the path comes back on schedule or resumes one frame late
    j = np.arange(2, fr.size - 1)
    j = j[cons[j - 2] & cons[j - 1] & cons[j] & (np.hypot(*V[j - 1].T) < STALL_PX)]
    back = P[j + 1] - (P[j - 1] + 2.0 * V[j - 2])
    keep[j] = np.minimum(np.hypot(*back.T), np.hypot(*(V[j] - V[j - 2]).T)) > STALL_RESUME * lim
    stalls = fr[~keep]
    fr, P = fr[keep], P[keep]
    dt = np.abs(np.diff(fr))
    V = np.diff(P, axis=0) / dt[:, None]
    # a step over one or two frames without a position (lost, out of frame) counts at
    # its mean velocity; one over a dropped stall does not (it moved a frame less)
    lo, hi = np.minimum(fr[:-1], fr[1:]), np.maximum(fr[:-1], fr[1:])
    over_stall = ((stalls > lo[:, None]) & (stalls < hi[:, None])).any(1)
    usable = (dt == 1) | ((dt <= _GAP_FRAMES) & ~over_stall)
    both = usable[1:] & usable[:-1]
    acc = np.hypot(*(V[1:] - V[:-1]).T)[both]
    return bool(acc.size > 0 and acc.max() > lim)


def from_last_reacquisition(fr, reason, reacquired, i):
    """Frames ``fr`` of marker ``i`` from its last re-acquisition among them on (all if
    none; ``reason`` holds the reason codes, ``reacquired`` is that one's): a
    re-acquisition moved it on purpose, its path is followed from there."""
    rq = np.flatnonzero(reason[fr, i] == reacquired)
    return fr[rq[-1]:] if rq.size else fr


def _path(x, y, reason, reacquired, i, t0, t, now):
    """Frames and positions of marker ``i`` from frame ``t0`` (or its last re-acquisition
    after it) up to frame ``t`` (excluded), then ``now`` at ``t`` if given; frames
    without a position are left out."""
    fr = from_last_reacquisition(np.arange(t0, t, 1 if t > t0 else -1), reason, reacquired, i)
    P = np.column_stack([x[fr, i], y[fr, i]])
    if now is not None:
        fr = np.append(fr, t)
        P = np.vstack([P, [now]])
    fin = np.isfinite(P).all(axis=1)
    return fr[fin], P[fin]


@jit
def _hopped_kernel(x, y, reason, reacquired, idx, t0s, t, nowx, nowy, use_now, lims, out):
    """Compiled twin of :func:`path_hopped` over :func:`_path` for markers ``idx``."""
    for k in range(idx.size):
        i = idx[k]
        t0 = t0s[k]
        n = abs(t - t0)
        step = 1 if t > t0 else -1
        start = 0
        for q in range(n):
            if reason[t0 + q * step, i] == reacquired:
                start = q
        fr = np.empty(n - start + 1, np.int64)
        px = np.empty(n - start + 1)
        py = np.empty(n - start + 1)
        m = 0
        for q in range(start, n):
            f = t0 + q * step
            if not (np.isnan(x[f, i]) or np.isnan(y[f, i])):
                fr[m], px[m], py[m] = f, x[f, i], y[f, i]
                m += 1
        if use_now and not (np.isnan(nowx[i]) or np.isnan(nowy[i])):
            fr[m], px[m], py[m] = t, nowx[i], nowy[i]
            m += 1
        if m < 3:
            continue
        lim = lims[k]
        keep = np.ones(m, np.bool_)
        for j in range(2, m - 1):
            if (abs(fr[j - 1] - fr[j - 2]) == 1 and abs(fr[j] - fr[j - 1]) == 1 and abs(fr[j + 1] - fr[j]) == 1
                    and math.hypot(px[j] - px[j - 1], py[j] - py[j - 1]) < STALL_PX):
                v2x, v2y = px[j - 1] - px[j - 2], py[j - 1] - py[j - 2]
                bx = px[j + 1] - (px[j - 1] + 2.0 * v2x)
                by = py[j + 1] - (py[j - 1] + 2.0 * v2y)
                ax = (px[j + 1] - px[j]) - v2x
                ay = (py[j + 1] - py[j]) - v2y
                keep[j] = min(math.hypot(bx, by), math.hypot(ax, ay)) > STALL_RESUME * lim
        # walk the kept positions: velocity of each step, usable or not, against the last
        prev = -1  # index of the previous kept position
        have = False  # a usable step before this one
        lvx = lvy = 0.0
        skipped = False  # a stall left out since the previous kept position
        for j in range(m):
            if not keep[j]:
                skipped = True
                continue
            if prev >= 0:
                dt = abs(fr[j] - fr[prev])
                vx, vy = (px[j] - px[prev]) / dt, (py[j] - py[prev]) / dt
                usable = dt == 1 or (dt <= _GAP_FRAMES and not skipped)
                if usable and have and math.hypot(vx - lvx, vy - lvy) > lim:
                    out[k] = True
                    break
                have = usable
                lvx, lvy = vx, vy
            prev = j
            skipped = False
    return out


def hopped(x, y, reason, reacquired, idx, t0s, t, now, lims):
    """Whether the path of each marker of ``idx`` hopped (boolean array).

    Parameters
    ----------
    x, y : (T, N) float arrays
        Positions written so far (NaN: none).
    reason : (T, N) int array
        Reason codes; ``reacquired`` is the one that restarts a path.
    reacquired : int
    idx : (K,) int array
        Markers to judge.
    t0s : (K,) int array
        Each marker's last ok frame, where its path starts (a frame of the ``T`` rows).
    t : int
        This frame (excluded unless ``now`` is given).
    now : tuple of two (N,) float arrays or None
        Positions on frame ``t``.
    lims : (K,) float array
        Each marker's hop limit (px/frame).

    Returns
    -------
    (K,) bool array
    """
    out = np.zeros(idx.size, bool)
    if engine.use_numba():
        nowx, nowy = (now[0], now[1]) if now is not None else (x[0], y[0])
        return _hopped_kernel(x, y, reason, np.int64(reacquired), np.asarray(idx, np.int64),
                              np.asarray(t0s, np.int64), int(t), np.asarray(nowx, np.float64),
                              np.asarray(nowy, np.float64), now is not None, np.asarray(lims, np.float64), out)
    for k, i in enumerate(idx.tolist()):
        pos = (now[0][i], now[1][i]) if now is not None else None
        fr, P = _path(x, y, reason, reacquired, i, int(t0s[k]), t, pos)
        out[k] = path_hopped(fr, P, float(lims[k]))
    return out
