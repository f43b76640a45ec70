"""Nearest neighbours and robust affine maps between marker constellations."""
from __future__ import annotations

import math

import numpy as np

from . import engine
from .engine import jit


@jit
def _nearest_kernel(px, py, valid, j, d):
    """Compiled twin of :func:`_nearest_two` (indices and distances of the two nearest)."""
    n = px.shape[0]
    for i in range(n):
        b0 = b1 = np.inf
        k0 = k1 = -1
        if valid[i] and not (np.isnan(px[i]) or np.isnan(py[i])):
            for q in range(n):
                if q == i or not valid[q] or np.isnan(px[q]) or np.isnan(py[q]):
                    continue
                dx = px[i] - px[q]
                dy = py[i] - py[q]
                e = dx * dx + dy * dy
                if e < b0:
                    b1, k1 = b0, k0
                    b0, k0 = e, q
                elif e < b1:
                    b1, k1 = e, q
        j[i, 0] = k0
        j[i, 1] = k1
        d[i, 0] = np.sqrt(b0)
        d[i, 1] = np.sqrt(b1)




def _nearest_two(px, py, valid):
    """Indices of the two nearest other valid points (-1 for none) and their distances."""
    n = len(px)
    if n < 2:
        return np.full((n, 2), -1), np.full((n, 2), np.inf), None
    if engine.use_numba():
        j = np.empty((n, 2), np.int64)
        d = np.empty((n, 2))
        _nearest_kernel(np.asarray(px, np.float64), np.asarray(py, np.float64), np.asarray(valid, np.bool_), j, d)
        return j, d, None
    ok = valid & np.isfinite(px) & np.isfinite(py)
    x = np.where(ok, px, 0.0)
    y = np.where(ok, py, 0.0)
    dx = x[:, None] - x
    dy = y[:, None] - y
    d2 = dx * dx + dy * dy
    bad = ~(ok[:, None] & ok)
    bad.flat[:: n + 1] = True
    d2[bad] = np.inf
    ar = np.arange(n)
    j0 = d2.argmin(1)
    d0 = d2[ar, j0]
    saved = d0.copy()
    d2[ar, j0] = np.inf
    j1 = d2.argmin(1)
    d1 = d2[ar, j1]
    d2[ar, j0] = saved
    j = np.column_stack([np.where(np.isfinite(d0), j0, -1), np.where(np.isfinite(d1), j1, -1)])
    return j, np.sqrt(np.column_stack([d0, d1])), d2


def _fit_affine(src, dst):
    """Least-squares 2D affine (or translation with < 3 points) mapping src -> dst."""
    n = len(src)
    if n == 0:
        return None
    if n < 3:
        t = np.mean(dst - src, axis=0)
        return np.array([[1.0, 0.0, t[0]], [0.0, 1.0, t[1]]])
    A = np.column_stack([src, np.ones(n)])
    M, _, rank, _ = np.linalg.lstsq(A, dst, rcond=None)
    if rank < 3:
        t = np.mean(dst - src, axis=0)
        return np.array([[1.0, 0.0, t[0]], [0.0, 1.0, t[1]]])
    return M.T


def _apply_affine(M, p):
    return p @ M[:, :2].T + M[:, 2]


#: :func:`_one_out` leaves a point out only when each of the others is checked by the
#: rest: a point whose leverage in their fit (its hat-matrix diagonal, 1 for a point that
#: alone fixes a direction, e.g. off the line the others lie on) is above this is fitted
#: whatever its error (:func:`_max_leverage`). (Five points spread at random have a
#: largest leverage of 0.90 in the median, 0.99 at the 95th percentile; a dot alone on its
#: row of a grid, 1.000.)
MAX_POINT_LEVERAGE = 0.99


def _max_leverage(src):
    """Largest leverage (hat-matrix diagonal, 0-1) of the points ``src`` (n, 2) in an affine
    fit: how much of a point's own error its fitted value follows. Near 1 for a point that
    no other point checks: on a grid of dots the neighbours often lie on two rows, one of
    them a single dot, and any displacement of that dot - a wrong match on the next dot of
    its row - fits exactly (real dots, dropped, DEV seed 610 cam1, frame 1: of six
    neighbours on two rows, a dot leaving the view had matched its row neighbour's blob;
    :func:`_one_out` left out the right dot of that row, the other five fitted at 0.19 px,
    and the map sent two wide-searched dots along their row, ok 25-50 px off).
    Written by hand: a three-column SVD; no library gives the hat matrix of a fit."""
    n = len(src)
    if n <= 3:
        return 1.0
    A = np.column_stack([src - src.mean(0), np.ones(n)])
    U, sv, _ = np.linalg.svd(A, full_matrices=False)
    keep = sv > 1e-9 * sv[0]
    return float(np.max(np.sum(U[:, keep] ** 2, axis=1)))


def _one_out(src, dst, tol):
    """The point whose removal makes the least-squares affine fit of the others good, or -1.

    One gross outlier among few points pulls the whole fit (its leverage), so that every
    residual is large and a threshold on their median rejects none. With five or more
    points and an RMS residual above ``tol``, each point is left out in turn; the one
    whose removal brings the others' RMS within ``tol`` and below half the full fit's is
    returned. Independent renderer, black DEV seed 18 left: one runaway anchor 98 px off
    among six neighbours gave an RMS of 26 px (the map put a lost marker 33 px off); the
    other five fit to 0.12 px."""
    n = len(src)
    if n < 5:
        return -1
    full = np.linalg.norm(_apply_affine(_fit_affine(src, dst), src) - dst, axis=1)
    rms_all = math.sqrt(float(np.mean(full**2)))
    if rms_all <= tol:
        return -1
    best, best_rms = -1, np.inf
    for k in range(n):
        o = np.arange(n) != k
        if _max_leverage(src[o]) > MAX_POINT_LEVERAGE:
            continue  # (the others fit whatever one of them does: no evidence)
        r = np.linalg.norm(_apply_affine(_fit_affine(src[o], dst[o]), src[o]) - dst[o], axis=1)
        rk = math.sqrt(float(np.mean(r**2)))
        if rk < best_rms:
            best, best_rms = k, rk
    return best if best_rms <= tol and best_rms < 0.5 * rms_all else -1


def _robust_affine(src, dst, iters=3, tol=2.0, quality=False, one_out=False):
    """Affine src -> dst with outlier rejection; optionally also the inliers' RMS residual.

    With ``one_out``, the iterations start without the one point :func:`_one_out` finds
    (if any): for neighbours of one kind only (:func:`_neighbour_prediction`). Among a
    static dot and five wing markers (a reference-frame map, :mod:`.reacquire` case 2,
    for a marker without a velocity) it left out the dot and mapped a still marker with
    the wing (independent hard extra DEV seeds 4 and 6 left: re-acquisitions delayed, ok
    0.7135 -> 0.7081)."""
    keep = np.ones(len(src), bool)
    k = _one_out(src, dst, tol) if one_out else -1
    if k >= 0:
        keep[k] = False
    M = None
    for _ in range(iters):
        if keep.sum() == 0:
            break
        M = _fit_affine(src[keep], dst[keep])
        res = np.linalg.norm(_apply_affine(M, src) - dst, axis=1)
        new = res < max(tol, 3.0 * np.median(res[keep]) if keep.any() else tol)
        if new.sum() < min(3, len(src)) or np.array_equal(new, keep):
            break
        keep = new
    if not quality:
        return M
    if M is None:
        return None, np.inf, 0
    res = np.linalg.norm(_apply_affine(M, src[keep]) - dst[keep], axis=1)
    rms = float(np.sqrt(np.mean(res**2))) if keep.sum() > 3 else (0.0 if keep.sum() == 3 else np.inf)
    return M, rms, int(keep.sum())


def _neighbour_prediction(p0, prev, now, min_m=2, reach=False, max_reach=math.inf):
    """Where a marker at ``p0`` moved to, from neighbours that moved from ``prev`` to ``now``.

    ``prev``, ``now`` : (m, 2) positions of up to six nearest neighbours, nearest first.
    A robust affine map when four or more of them agree with one (RMS <= 1.5 px; a single
    gross outlier is left out first, :func:`_one_out`), else
    the mean displacement of the largest group that moved alike (within 2 px + 10 %: all
    of them when there are two or three, at least three otherwise; a single neighbour's
    displacement when ``min_m`` is 1). Returns the predicted position and its tolerance
    (px), or None when the neighbours do not move together. With ``reach``, the mean
    displacement's tolerance also grows with how far the marker is from the group times
    how differently the group moved (:func:`_reach`), and a third value is the tolerance
    for vouching for the marker: twice that growth when the group lies along a line the
    marker is off (:data:`REACH_ACROSS`; a miss beyond the first tolerance still
    condemns). A mean displacement that may miss the marker by more than ``max_reach`` px
    (:func:`_reach`) predicts nothing.
    """
    m = len(prev)
    if m >= 4:
        M, rms, nin = _robust_affine(prev, now, quality=True, one_out=True)
        if M is not None and nin >= 4 and rms <= 1.5:
            q = _apply_affine(M, p0[None, :])[0]
            return (q, 2.5, 2.5) if reach else (q, 2.5)
    if m < max(min_m, 1):
        return None
    D = now - prev
    tol = 2.0 + 0.1 * np.hypot(D[:, 0], D[:, 1])
    dd = np.hypot(D[:, None, 0] - D[None, :, 0], D[:, None, 1] - D[None, :, 1])
    alike = dd <= tol[:, None]
    j = int(np.argmax(alike.sum(1)))
    if alike[j].sum() < min(3, m):
        return None
    dm = D[alike[j]].mean(0)
    lim = 2.0 + 0.1 * math.hypot(*dm)
    if reach or max_reach < math.inf:
        miss = _reach(p0, prev[alike[j]], D[alike[j]])
        if miss > max_reach:
            return None
        if reach:
            grp = prev[alike[j]]
            across = miss if len(grp) >= 2 and _off_the_line(p0, grp) else 0.0
            return p0 + dm, lim + miss, lim + miss + across
    return p0 + dm, lim


#: A group whose members lie along a line measures how the displacement changes along
#: that line only: a marker further off the line than the group's own width plus
#: REACH_ACROSS times the group's length can move in ways the group does not see (a wing
#: pitching about the line they mark), so the group's mean move may miss it by more
#: than :func:`_reach` says: to vouch for such a marker, that miss counts twice
#: (:func:`_neighbour_prediction` with ``reach``).
REACH_ACROSS = 0.5


def _reach(p0, prev, D):
    """How far a group's mean displacement ``D`` (rows) may miss a marker at ``p0`` (px):
    the group's largest difference of displacement per px between two of its members
    (a turning or stretching wing moves them unlike, a rigid shift alike) times the
    distance from the marker to its nearest member. 0 for a group of one.

    Two neighbours 47-49 px from a marker, 17 px apart, moved 4 px unlike over a
    four-frame gap at a turn: their mean move put the marker 11 px from where it was,
    3.5 px from a neighbour's blob it had slipped onto, and vouched for it there (the
    tolerance, 2 px + 10 % of the move, was 3.9): independent renderer, dropped, DEV seed
    85 left, two markers ok 12-15 px off until the audit's trimming caught them."""
    if len(prev) < 2:
        return 0.0
    dP = np.hypot(prev[:, None, 0] - prev[None, :, 0], prev[:, None, 1] - prev[None, :, 1])
    dD = np.hypot(D[:, None, 0] - D[None, :, 0], D[:, None, 1] - D[None, :, 1])
    pair = dP > 0
    grad = float((dD[pair] / dP[pair]).max()) if pair.any() else 0.0
    return grad * float(np.hypot(prev[:, 0] - p0[0], prev[:, 1] - p0[1]).min())


def _off_the_line(p0, prev):
    """Whether ``p0`` lies off the principal line of the points ``prev`` by more than their
    width across it plus :data:`REACH_ACROSS` times their length along it."""
    c = prev.mean(axis=0)
    U = prev - c
    _, _, vt = np.linalg.svd(U, full_matrices=False)
    normal = np.array([-vt[0, 1], vt[0, 0]])
    along, across = U @ vt[0], U @ normal
    h = abs(float((p0 - c) @ normal))
    return h > float(np.abs(across).max()) + REACH_ACROSS * float(along.max() - along.min())


