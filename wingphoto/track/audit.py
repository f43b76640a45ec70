"""The last check of a tracking run: every ok point against its neighbours' map from the picks.

A post-pass over the finished result arrays (:meth:`~.driver._Run.merged`). For each
marker, its ``AUDIT_NEIGHBOURS`` nearest markers in the picks (the reference
constellation) that are ok on a frame give, by least squares, the affine map from their
picked positions to where they are on that frame; a planar wing seen by a camera moves, over
a few neighbour spacings, by such a map however far it turned since the picks. An ok point
further from where the map puts it than ``AUDIT_FRACTION`` of its spacing is flagged
``misplaced``.

Why a post-pass: the tracker's identity checks (:mod:`.identity`) judge a marker when it
moves or resumes, against its neighbours' motion since a recent frame, and each of them
changes what the motion models and re-acquisition see next; each new check moved identity
slips from one independent render to another (session 6). A marker that slipped onto
another blob and then moved steadily with it passed every later frame's checks (a slip
on an independent render's DEV sequence: ok 33 px off). This check looks at the picks,
not at recent frames, and only turns ok points into flagged ones after tracking, so it
cannot send the tracker anywhere: it can cost ok points, never add a wrong one.

A verdict needs a map that can be trusted at the marker: at least ``AUDIT_MIN`` ok
neighbours (three fit any map exactly: nothing would check it), their residual RMS at most
``AUDIT_RMS_PX`` (neighbours that do not move as one plane - static dots among wing
markers, a slipped neighbour - give no verdict), and the marker inside their spread
(its leverage at most ``AUDIT_LEVERAGE``: no far extrapolation). Written by
hand: it is a weighted least squares per point and frame over a masked set of neighbours,
26,000 tiny systems per 1000 frames, which no library batches cheaply (the numpy twin,
batched over frames, costs ~0.2 s per 1000 frames; the compiled kernel a few ms).
"""
from __future__ import annotations

import numpy as np

from . import engine
from .engine import jit
from .status import _R, FLAGGED, OK

__all__ = ["audit_against_picks"]

#: Neighbours of a marker in the picks that may judge it (ten: near a stroke reversal
#: most of a marker's six nearest are flagged or lost with it).
AUDIT_NEIGHBOURS = 10
#: Fewest of them, ok on the frame, for a verdict.
AUDIT_MIN = 4
#: Largest RMS residual (px) of the neighbours' affine map for a verdict.
AUDIT_RMS_PX = 2.0
#: Largest leverage of the marker in its neighbours' fit for a verdict (the factor by which
#: their position errors grow in its prediction, ``sqrt(a0' (A'A)^-1 a0)``; 1/sqrt(n) at
#: their centre, ~2 for a marker at the wing's edge with its ok neighbours on one side).
AUDIT_LEVERAGE = 2.5
#: An ok point further from where its neighbours' map puts it than this fraction of its
#: spacing (its nearest marker in the picks), and than ``AUDIT_SLACK_PX`` plus three
#: times the map's error there (its RMS, at least ``AUDIT_RMS_FLOOR``, times the
#: leverage), is flagged ``misplaced``.
AUDIT_FRACTION = 0.4
AUDIT_SLACK_PX = 2.0
AUDIT_RMS_FLOOR = 0.5
#: A point whose ok positions all stay within this distance (px) of its pick is still (the
#: mount, reference dots: a camera bump moves them by a few px): it is neither judged nor a
#: judge - the wing's map, extrapolated to the hinge, put the mount 8 px from where it sat.
AUDIT_STILL_PX = 10.0
#: Where the neighbours' map gives no verdict and one of them is further from it than
#: ``AUDIT_FRACTION`` of the marker's spacing (a neighbour on another marker's blob, not
#: a wing that bends a little: trimming those flagged 9 correct points of our hard_stroke
#: DEV), that neighbour is left out and the map refitted, up to AUDIT_TRIM times (more
#: than ``AUDIT_MIN`` neighbours before each). Two markers of a row that slipped together
#: by one spacing each spoiled the other's map, so neither was judged: both ok 12-15 px
#: off for 7 frames (fresh DEV dropped seed 85 left, after a change of re-acquisition).
AUDIT_TRIM = 2


def _neighbours(ref, k):
    """Indices (N, k) of each point's ``k`` nearest other points in ``ref`` (-1: fewer)."""
    d = np.hypot(ref[:, None, 0] - ref[None, :, 0], ref[:, None, 1] - ref[None, :, 1])
    np.fill_diagonal(d, np.inf)
    order = np.argsort(d, axis=1)[:, :k]
    near = np.take_along_axis(d, order, axis=1)
    return np.where(np.isfinite(near), order, -1), near[:, 0]


def _map_of_one(p0, src, dst, use):
    """Per frame: where the least-squares affine map of the neighbours ``src`` (k, 2) ->
    ``dst`` (T, k, 2), over those ``use`` (T, k), puts ``p0`` (2,); the map's error there
    (px: its RMS residual, at least ``AUDIT_RMS_FLOOR``, times ``p0``'s leverage); and
    whether the frame may judge (enough neighbours, a trusted map, a bounded leverage)."""
    T, k = use.shape
    A = np.column_stack([src, np.ones(k)])  # (k, 3)
    w = use.astype(float)
    n = w.sum(1)
    # (matrix products, not einsum: ~10x faster for these shapes)
    G = (w @ (A[:, :, None] * A[:, None, :]).reshape(k, 9)).reshape(T, 3, 3)
    H = A.T @ np.where(use[..., None], dst, 0.0)  # (T, 3, 2)
    out = np.full((T, 2), np.nan)
    err = np.full(T, np.nan)
    judge = n >= AUDIT_MIN
    # (neighbours on a line fix no map: their spread across it, relative to along it)
    m = G[:, :2, 2] / np.maximum(n, 1)[:, None]
    spread = G[:, :2, :2] / np.maximum(n, 1)[:, None, None] - m[:, :, None] * m[:, None, :]
    tr = spread[:, 0, 0] + spread[:, 1, 1]
    judge &= np.linalg.det(spread) > 1e-4 * tr * tr
    t = judge.nonzero()[0]
    if not t.size:
        return out, err, judge
    a0 = np.append(p0, 1.0)
    Ginv = np.linalg.inv(G[t])
    beta = Ginv @ H[t]  # (t, 3, 2)
    fit = A @ beta
    r2 = np.where(use[t], np.sum((fit - dst[t]) ** 2, axis=2), 0.0)
    rms = np.sqrt(r2.sum(1) / n[t])
    lev = np.sqrt((Ginv @ a0) @ a0)
    out[t] = a0 @ beta
    err[t] = np.maximum(rms, AUDIT_RMS_FLOOR) * lev
    judge[t] = (rms <= AUDIT_RMS_PX) & (lev <= AUDIT_LEVERAGE)
    return out, err, judge


def _trim_worst(src, dst, use, judge, far):
    """The neighbours ``use`` (T, k) without, on each frame whose map gave no verdict but
    has more than ``AUDIT_MIN`` neighbours, the one furthest from their map if it is
    further than ``far`` px; and those frames (T,) bool."""
    n = use.sum(1)
    again = ~judge & (n > AUDIT_MIN)
    if not again.any():
        return use, again
    t = again.nonzero()[0]
    A = np.column_stack([src, np.ones(len(src))])
    w = use[t].astype(float)
    G = (w @ (A[:, :, None] * A[:, None, :]).reshape(len(src), 9)).reshape(t.size, 3, 3)
    H = A.T @ np.where(use[t][..., None], dst[t], 0.0)
    ok = np.abs(np.linalg.det(G)) > 0
    beta = np.zeros((t.size, 3, 2))
    beta[ok] = np.linalg.solve(G[ok], H[ok])
    r2 = np.where(use[t], np.sum((A @ beta - dst[t]) ** 2, axis=2), -1.0)
    use = use.copy()
    worst = np.argmax(r2, axis=1)
    ok &= r2[np.arange(t.size), worst] > far * far
    use[t[ok], worst[ok]] = False
    again[t[~ok]] = False
    return use, again


def _misplaced_numpy(X, Y, ok, ref, nbr, spacing):
    """(T, M) whether each ok point is away from its neighbours' map (numpy twin of
    :func:`_misplaced_kernel`). ``X, Y, ok``: (T, M) positions and ok-ness of the audited
    points; ``ref``: their picks (M, 2); ``nbr``: (M, K) their neighbours (-1: none);
    ``spacing``: (M,) the distance to their nearest."""
    bad = np.zeros(ok.shape, bool)
    for a in range(ok.shape[1]):
        js = nbr[a][nbr[a] >= 0]
        if js.size < AUDIT_MIN or not ok[:, a].any():
            continue
        use = ok[:, js] & np.isfinite(X[:, js])
        dst = np.stack([X[:, js], Y[:, js]], axis=2)
        pred, err, judge = _map_of_one(ref[a], ref[js], dst, use)
        for _ in range(AUDIT_TRIM):  # (leave out a wrong neighbour where the map misfits)
            use, again = _trim_worst(ref[js], dst, use, judge, AUDIT_FRACTION * spacing[a])
            if not again.any():
                break
            p2, e2, j2 = _map_of_one(ref[a], ref[js], dst[again], use[again])
            pred[again], err[again], judge[again] = p2, e2, j2
        judge &= ok[:, a]
        off = np.hypot(X[:, a] - pred[:, 0], Y[:, a] - pred[:, 1])
        lim = np.maximum(AUDIT_FRACTION * spacing[a], AUDIT_SLACK_PX + 3.0 * err)
        bad[:, a] = judge & (off > lim)
    return bad


@jit
def _fit_one(X, Y, ok, ref, nbr, t, a, skip):
    """The affine map of marker ``a``'s neighbours on frame ``t`` (those ok, not marked in
    ``skip``), from their normal equations summed in place, the 3 x 3 system inverted by
    its adjugate. Returns n, whether the system is solvable, whether the neighbours span
    the plane (not a line), where the map puts ``a`` (px, py), the RMS residual, ``a``'s
    leverage, the neighbour (its slot in ``nbr[a]``) furthest from the map and its
    squared distance."""
    K = nbr.shape[1]
    n = su = sv = suu = suv = svv = 0.0
    hx0 = hx1 = hx2 = hy0 = hy1 = hy2 = sbb = 0.0
    for q in range(K):
        j = nbr[a, q]
        if j < 0 or skip[q] or not ok[t, j] or np.isnan(X[t, j]):
            continue
        u, v, x, y = ref[j, 0], ref[j, 1], X[t, j], Y[t, j]
        n += 1.0
        su += u
        sv += v
        suu += u * u
        suv += u * v
        svv += v * v
        hx0 += u * x
        hx1 += v * x
        hx2 += x
        hy0 += u * y
        hy1 += v * y
        hy2 += y
        sbb += x * x + y * y
    if n < 3:
        return n, False, False, np.nan, np.nan, np.nan, np.nan, -1, 0.0
    mu, mv = su / n, sv / n
    cuu, cuv, cvv = suu / n - mu * mu, suv / n - mu * mv, svv / n - mv * mv
    tr = cuu + cvv
    spans = cuu * cvv - cuv * cuv > 1e-4 * tr * tr
    # G = [[suu, suv, su], [suv, svv, sv], [su, sv, n]]: its inverse by the adjugate
    c00 = svv * n - sv * sv
    c01 = -(suv * n - sv * su)
    c02 = suv * sv - svv * su
    c11 = suu * n - su * su
    c12 = -(suu * sv - suv * su)
    c22 = suu * svv - suv * suv
    det = suu * c00 + suv * c01 + su * c02
    if det == 0.0:
        return n, False, spans, np.nan, np.nan, np.nan, np.nan, -1, 0.0
    i00, i01, i02, i11, i12, i22 = c00 / det, c01 / det, c02 / det, c11 / det, c12 / det, c22 / det
    bx0 = i00 * hx0 + i01 * hx1 + i02 * hx2
    bx1 = i01 * hx0 + i11 * hx1 + i12 * hx2
    bx2 = i02 * hx0 + i12 * hx1 + i22 * hx2
    by0 = i00 * hy0 + i01 * hy1 + i02 * hy2
    by1 = i01 * hy0 + i11 * hy1 + i12 * hy2
    by2 = i02 * hy0 + i12 * hy1 + i22 * hy2
    # sum of squared residuals: b'b - beta' A'b (the normal equations hold)
    r2 = sbb - (bx0 * hx0 + bx1 * hx1 + bx2 * hx2) - (by0 * hy0 + by1 * hy1 + by2 * hy2)
    rms = np.sqrt(max(r2, 0.0) / n)
    p0, p1 = ref[a, 0], ref[a, 1]
    lev2 = (p0 * (i00 * p0 + i01 * p1 + i02) + p1 * (i01 * p0 + i11 * p1 + i12)
            + (i02 * p0 + i12 * p1 + i22))
    worst = -1
    wr = -1.0
    for q in range(K):
        j = nbr[a, q]
        if j < 0 or skip[q] or not ok[t, j] or np.isnan(X[t, j]):
            continue
        u, v = ref[j, 0], ref[j, 1]
        ex = bx0 * u + bx1 * v + bx2 - X[t, j]
        ey = by0 * u + by1 * v + by2 - Y[t, j]
        if ex * ex + ey * ey > wr:
            wr = ex * ex + ey * ey
            worst = q
    return (n, True, spans, bx0 * p0 + bx1 * p1 + bx2, by0 * p0 + by1 * p1 + by2, rms,
            np.sqrt(max(lev2, 0.0)), worst, wr)


@jit
def _misplaced_kernel(X, Y, ok, ref, nbr, spacing, bad):
    """Compiled :func:`_misplaced_numpy` (writes ``bad``): per point and frame the map of
    :func:`_fit_one`, refitted without its worst neighbour up to ``AUDIT_TRIM`` times
    (~50x faster than the batched numpy)."""
    T, M = ok.shape
    K = nbr.shape[1]
    skip = np.zeros(K, np.bool_)
    for t in range(T):
        for a in range(M):
            bad[t, a] = False
            if not ok[t, a]:
                continue
            skip[:] = False
            for it in range(AUDIT_TRIM + 1):
                n, solved, spans, px, py, rms, lev, worst, wr = _fit_one(X, Y, ok, ref, nbr, t, a, skip)
                if n >= AUDIT_MIN and solved and spans and rms <= AUDIT_RMS_PX and lev <= AUDIT_LEVERAGE:
                    lim = max(AUDIT_FRACTION * spacing[a], AUDIT_SLACK_PX + 3.0 * max(rms, AUDIT_RMS_FLOOR) * lev)
                    bad[t, a] = np.hypot(X[t, a] - px, Y[t, a] - py) > lim
                    break
                far = AUDIT_FRACTION * spacing[a]
                if not (solved and n > AUDIT_MIN and wr > far * far):
                    break
                skip[worst] = True


def audit_against_picks(res, ref, audited, judged=None):
    """Flag ``misplaced`` the ok points of ``res`` that their neighbours' map from the picks
    puts elsewhere (in place).

    Parameters
    ----------
    res : _Results or namespace
        The run's merged (T, N) result arrays (``x``, ``y``, ``status``, ``reason``).
    ref : (N, 2) ndarray of float
        The reference constellation: the picked positions, or every point's position on
        one frame where it was ok (a pick frame of other points, a corrected frame).
    audited : (N,) ndarray of bool
        The points whose ``ref`` is on that one frame (the others are neither judged nor
        judges; nor are the still ones, ``AUDIT_STILL_PX``).
    judged : (N,) ndarray of bool, optional
        Of those, the points that may be flagged (default: all of them); the others only
        judge (markers already audited from their own picks, or not re-tracked).

    Returns
    -------
    int
        How many ok point-frames were flagged.
    """
    audited = audited & np.all(np.isfinite(ref), axis=1)
    with np.errstate(invalid="ignore"):
        moved = np.hypot(res.x - ref[:, 0], res.y - ref[:, 1])
        moved = np.where(res.status == OK, moved, 0.0).max(axis=0) if len(moved) else np.zeros(len(ref))
    idx = np.flatnonzero(audited & (moved >= AUDIT_STILL_PX))
    if idx.size < AUDIT_MIN + 1:
        return 0
    nbr, spacing = _neighbours(ref[idx], AUDIT_NEIGHBOURS)
    ok = res.status[:, idx] == OK
    X, Y = np.ascontiguousarray(res.x[:, idx]), np.ascontiguousarray(res.y[:, idx])
    if engine.use_numba():
        bad = np.empty(ok.shape, np.bool_)
        _misplaced_kernel(X, Y, ok, np.ascontiguousarray(ref[idx]), nbr, spacing, bad)
    else:
        bad = _misplaced_numpy(X, Y, ok, ref[idx], nbr, spacing)
    if judged is not None:
        bad &= np.asarray(judged, bool)[idx][None, :]
    rows, cols = bad.nonzero()
    res.status[rows, idx[cols]] = FLAGGED
    res.reason[rows, idx[cols]] = _R["misplaced"]
    return int(bad.sum())
