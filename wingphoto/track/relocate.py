"""Re-acquisition of a whole group of markers lost at once, by their reference constellation.

At a stroke reversal a wing can turn nearly edge-on: its markers become thin ellipses and
are lost, all of them. When the wing is face-on again, :mod:`.reacquire` cannot bring any
back, as it predicts a lost marker from ok neighbours of its kind and none is left. This
stage finds the group again as a whole: the candidate blobs of the frame (the peaks of the
group's mean template's correlation, away from the markers still tracked), then the
identities by fitting the group's *reference* constellation (its positions on the picks'
frame, ``Tracker.ref_pos``) to the candidates - affine hypotheses from triangles of near
neighbours, refined to a homography - accepted only when the fit is unambiguous (enough
inliers, a clear margin over the best different fit) and each marker's own template
correlates well at its candidate. The markers found are handed back ``flagged``
(``reacquired``) with their motion model restarted from their velocity against the previous
frame (a patch around each marker, with its neighbours and the membrane's texture, found
again there), so that the usual rules make them ok on the following frames.

A wrong re-acquisition is worse than none: every test errs on the side of waiting.
"""
from __future__ import annotations

import logging

import cv2
import numpy as np
from scipy.spatial import cKDTree

from .geometry import _apply_affine, _robust_affine
from .predict import STILL_SPEED, model_speed
from .sigma import sigma_of
from .status import _R, FLAGGED, OK

__all__ = ["find_candidates", "fit_constellation", "relocate_group"]

logger = logging.getLogger("wingphoto.track")

#: At least this many markers lost together make a group worth searching for as a whole.
MIN_GROUP = 6
#: The group is searched for only while fewer than this many moving markers are ok (with
#: four, :mod:`.reacquire` maps the lost ones from them) and fewer moving markers have a
#: position on the frame (ok or flagged) than are lost (a sheet of faint dots, flagged
#: but followed, is not a lost group).
MAX_OK_MOVING = 4
#: A candidate blob: a peak of the group template's correlation of at least this.
CANDIDATE_SCORE = 0.6
#: At most this many candidates (the strongest) enter the fit.
MAX_CANDIDATES = 80
#: Accepted fit: at least this many inliers, and this share of the group.
MIN_INLIERS, MIN_SHARE = 6, 0.6
#: Inlier tolerance (px) of the final homography, and of the affine hypotheses as a share
#: of the group's reference spacing (at least ``FIT_TOL``).
FIT_TOL, HYP_TOL = 2.0, 0.25
#: The best different fit (its mapped positions a third of a spacing or more away from the
#: best's) may have at most this share of the best fit's inliers.
MARGIN = 0.6
#: Each marker's own template must correlate at least this well at its candidate.
MARKER_SCORE = 0.8
#: A hypothesis's linear part: singular values within these bounds (scale from the picks'
#: frame), and at most this ratio between them (foreshortening).
SCALE_RANGE, MAX_ANISOTROPY = (0.4, 2.5), 4.0
#: Hypotheses from at most MAX_ANCHORS reference triangles, scored on at most MAX_PROBE
#: reference points (both spread over the group).
MAX_ANCHORS, MAX_PROBE = 6, 20
#: A group that is not found is searched for again on every RETRY-th frame only, and
#: less often the longer it has been lost (:func:`_due`): RETRY frames apart during the
#: first RETRY_SPAN frames, then twice, four and at most MAX_BACKOFF times as far apart
#: (a search costs ~40 ms; real dots that left the view were searched for 20 times in 60
#: frames, 5x the tracking time).
RETRY, RETRY_SPAN, MAX_BACKOFF = 2, 16, 8
#: Velocity of the markers found: a patch of 2 PATCH_HALF + 1 px around each is found in
#: the previous frame (correlation at least VEL_SCORE); an affine map of the patches'
#: motion must hold for VEL_SHARE of them within VEL_RMS px.
PATCH_HALF, VEL_SCORE, VEL_SHARE, VEL_RMS = 15, 0.7, 0.8, 1.5
#: A marker within this distance (px) of its reference position is still: the static
#: mount and dots (or a wing at rest), told apart from the moving wing.
STILL_PX = 1.5
#: A marker ever written this far (px) from its reference position is a wing marker, even
#: when lost at rest where it was on the reference frame (a camera's bump moves the static
#: dots by a few px only): the static dots must not place it. Independent renderer,
#: repeated, extra DEV seed 5 left: marker 17, lost at a stroke reversal within 1.5 px of
#: its frame-0 position, was placed there by five static dots 10 frames later (one wing
#: neighbour, an outlier of their map) and re-acquired on marker 19's blob, 33 px off.
ROAM_PX = 15.0


def find_candidates(frame, template, *, min_score=CANDIDATE_SCORE, radius=2, exclude=None, max_n=MAX_CANDIDATES):
    """Candidate marker blobs: peaks of a template's correlation over the whole frame.

    Parameters
    ----------
    frame : (H, W) ndarray
        The image.
    template : (s, s) ndarray of float, s odd
        The marker template (the group's mean one).
    min_score : float
        Least TM_CCOEFF_NORMED of a peak.
    radius : int
        A peak is the maximum within this many px.
    exclude : (K, 3) ndarray of float, optional
        (x, y, r) discs (px) where no candidate may lie (markers still tracked).
    max_n : int
        At most this many candidates, the strongest.

    Returns
    -------
    xy : (M, 2) ndarray of float
        Pixel (x, y) of each candidate, origin at the centre of the top-left pixel.
    score : (M,) ndarray of float
        Its correlation.
    """
    s = template.shape[0]
    h = s // 2
    img = np.ascontiguousarray(frame, dtype=np.float32)
    if img.shape[0] < s or img.shape[1] < s:
        return np.zeros((0, 2)), np.zeros(0)
    cmap = cv2.matchTemplate(img, np.ascontiguousarray(template, dtype=np.float32), cv2.TM_CCOEFF_NORMED)
    cmap = np.nan_to_num(cmap, nan=-1.0, posinf=-1.0, neginf=-1.0)
    k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))
    peak = (cmap >= cv2.dilate(cmap, k)) & (cmap >= min_score)
    yy, xx = np.nonzero(peak)
    sc = cmap[yy, xx].astype(np.float64)
    xy = np.column_stack([xx + h, yy + h]).astype(np.float64)
    if exclude is not None and len(exclude) and len(xy):
        d = np.hypot(xy[:, None, 0] - exclude[None, :, 0], xy[:, None, 1] - exclude[None, :, 1])
        keep = ~(d < exclude[None, :, 2]).any(1)
        xy, sc = xy[keep], sc[keep]
    o = np.argsort(-sc, kind="stable")[:max_n]
    return xy[o], sc[o]


def _spread(pts, k):
    """Indices of at most ``k`` of the points ``pts`` (n, 2), spread over them (farthest
    point sampling from the first)."""
    n = len(pts)
    if n <= k:
        return np.arange(n)
    pick = [0]
    d = np.hypot(*(pts - pts[0]).T)
    for _ in range(k - 1):
        j = int(np.argmax(d))
        pick.append(j)
        d = np.minimum(d, np.hypot(*(pts - pts[j]).T))
    return np.array(sorted(pick), np.int64)


def _triangles(ref):
    """For each reference point, its two nearest others: (n, 3) index triangles that are
    not degenerate (area at least a tenth of the square of their longest side)."""
    n = len(ref)
    tree = cKDTree(ref)
    _, nn = tree.query(ref, k=min(3, n))
    tri = []
    for a in range(n):
        b, c = int(nn[a, 1]), int(nn[a, 2])
        p, q, r = ref[a], ref[b], ref[c]
        area = abs((q[0] - p[0]) * (r[1] - p[1]) - (q[1] - p[1]) * (r[0] - p[0])) / 2
        longest = max(np.sum((q - p) ** 2), np.sum((r - p) ** 2), np.sum((r - q) ** 2))
        if area >= 0.1 * longest:
            tri.append((a, b, c))
    return np.array(tri, np.int64).reshape(-1, 3)


def _affines(src, dst):
    """(K, 2, 3) affine maps of K triangles ``src`` (K, 3, 2) onto ``dst`` (K, 3, 2)."""
    A = np.concatenate([src, np.ones(src.shape[:2] + (1,))], axis=2)  # (K, 3, 3)
    with np.errstate(all="ignore"):
        M = np.linalg.solve(A, dst)  # (K, 3, 2): [x y 1] @ M = dst
    return np.transpose(M, (0, 2, 1))


def _plausible(M):
    """Hypotheses whose linear part keeps the orientation, within the scale bounds."""
    L = M[:, :, :2]
    ok = np.isfinite(L).all((1, 2)) & (np.linalg.det(np.nan_to_num(L)) > 0)
    sv = np.linalg.svd(np.nan_to_num(L), compute_uv=False)
    with np.errstate(divide="ignore", invalid="ignore"):
        ok &= (sv[:, 1] >= SCALE_RANGE[0]) & (sv[:, 0] <= SCALE_RANGE[1]) & (sv[:, 0] <= MAX_ANISOTROPY * sv[:, 1])
    return ok


def _associate(mapped, cand, tree, tol):
    """One-to-one nearest candidate of each mapped point within ``tol`` px (-1: none)."""
    d, j = tree.query(mapped, k=1)
    d = np.where(np.isfinite(d), d, np.inf)
    j = np.where(d <= tol, j, -1)
    # a candidate claimed twice goes to the nearer point
    order = np.argsort(d, kind="stable")
    used = set()
    out = np.full(len(mapped), -1)
    for i in order.tolist():
        if j[i] >= 0 and j[i] not in used:
            used.add(int(j[i]))
            out[i] = j[i]
    return out


def _affine_lstsq(src, dst):
    """(3, 2) least-squares affine map: ``[x y 1] @ X`` approximates ``dst``."""
    X, *_ = np.linalg.lstsq(np.column_stack([src, np.ones(len(src))]), dst, rcond=None)
    return X


def _refine_fit(ref, cand, tree, M, tol):
    """Iterate association and fit from affine ``M``: a few affine rounds at ``tol``, then a
    homography at :data:`FIT_TOL`. Returns (assignment (n,), mapped (n, 2), rms)."""
    mapped = ref @ M[:, :2].T + M[:, 2]
    a = _associate(mapped, cand, tree, tol)
    for _ in range(3):
        m = a >= 0
        if m.sum() < 3:
            return a, mapped, np.inf
        X = _affine_lstsq(ref[m], cand[a[m]])
        mapped = np.column_stack([ref, np.ones(len(ref))]) @ X
        a2 = _associate(mapped, cand, tree, max(FIT_TOL, 0.5 * tol))
        if np.array_equal(a2, a):
            break
        a = a2
    m = a >= 0
    if m.sum() >= 5:
        Hm, _ = cv2.findHomography(ref[m].astype(np.float64), cand[a[m]].astype(np.float64), 0)
        if Hm is not None and np.isfinite(Hm).all():
            mh = cv2.perspectiveTransform(ref[None].astype(np.float64), Hm)[0]
            ah = _associate(mh, cand, tree, FIT_TOL)
            if (ah >= 0).sum() >= m.sum():
                mapped, a = mh, ah
    m = a >= 0
    if not m.any():
        return a, mapped, np.inf
    r = np.hypot(*(mapped[m] - cand[a[m]]).T)
    a = np.where(np.isin(np.arange(len(a)), np.flatnonzero(m)[r > FIT_TOL]), -1, a)
    m = a >= 0
    rms = float(np.sqrt(np.mean(np.sum((mapped[m] - cand[a[m]]) ** 2, 1)))) if m.any() else np.inf
    return a, mapped, rms


def fit_constellation(ref, cand, *, n_keep=8):
    """Fit a reference constellation to candidate blobs whose identities are unknown.

    Parameters
    ----------
    ref : (n, 2) ndarray of float
        The group's positions (x, y) px on the reference frame.
    cand : (M, 2) ndarray of float
        Candidate blob positions (x, y) px on this frame.
    n_keep : int
        Hypotheses (the most inliers) refined.

    Returns
    -------
    dict or None
        ``assign`` (n,) index into ``cand`` (-1: no candidate), ``mapped`` (n, 2) the
        reference positions mapped by the refined fit, ``inliers``, ``rms`` (px) and
        ``second``: the inliers of the best fit that differs from it (mapped positions a
        third of a spacing or more apart); None when no hypothesis can be made.

    Notes
    -----
    Hypotheses: the affine map of each reference triangle (a point and its two nearest
    others) onto each triangle of candidates (a candidate and two of its four nearest),
    kept when it preserves orientation, with a scale in :data:`SCALE_RANGE` and at most
    :data:`MAX_ANISOTROPY` of foreshortening (at most :data:`MAX_ANCHORS` reference
    triangles, spread over the group); scored by the reference points (at most
    :data:`MAX_PROBE`, spread) mapped within ``HYP_TOL`` spacings of a candidate; the
    best ``n_keep`` distinct ones refined by iterated association (affine, then a
    homography at :data:`FIT_TOL` px).
    """
    ref = np.asarray(ref, np.float64)
    cand = np.asarray(cand, np.float64)
    n, m = len(ref), len(cand)
    if n < 3 or m < 3:
        return None
    rtree = cKDTree(ref)
    dref, _ = rtree.query(ref, k=2)
    spacing = float(np.median(dref[:, 1]))
    tol = max(FIT_TOL, HYP_TOL * spacing)
    tri = _triangles(ref)
    if not len(tri):
        return None
    # a few anchor triangles spread over the group, and at most MAX_PROBE points to score
    # the hypotheses with (the cost of a large group, a sheet of dots, stays bounded)
    tri = tri[_spread(ref[tri[:, 0]], MAX_ANCHORS)]
    probe = _spread(ref, MAX_PROBE)
    ctree = cKDTree(cand)
    kk = min(5, m)
    _, cnn = ctree.query(cand, k=kk)
    # candidate triangles: a candidate and an ordered pair of its nearest others
    pairs = np.array([(b, c) for b in range(1, kk) for c in range(1, kk) if b != c], np.int64)
    ctri = np.column_stack([np.repeat(np.arange(m), len(pairs)), cnn[:, pairs[:, 0]].ravel(),
                            cnn[:, pairs[:, 1]].ravel()])
    src = ref[tri]  # (T, 3, 2)
    dst = cand[ctri]  # (C, 3, 2)
    T, C = len(tri), len(ctri)
    M = _affines(np.repeat(src, C, axis=0), np.tile(dst, (T, 1, 1)))
    good = _plausible(M)
    M = M[good]
    if not len(M):
        return None
    mapped = np.einsum("kij,nj->kni", M[:, :, :2], ref[probe]) + M[:, None, :, 2]
    d, _ = ctree.query(mapped.reshape(-1, 2), k=1)
    score = (d.reshape(len(M), len(probe)) <= tol).sum(1)
    top = np.argsort(-score, kind="stable")
    fits = []
    for k in top.tolist():
        if len(fits) >= n_keep or score[k] < 3:
            break
        # one refinement per distinct outcome
        if any(np.median(np.hypot(*(mapped[k] - f[1][probe]).T)) < 0.33 * spacing for f in fits):
            continue
        a, mp, rms = _refine_fit(ref, cand, ctree, M[k], tol)
        fits.append((a, mp, rms))
    if not fits:
        return None
    key = [(int((f[0] >= 0).sum()), -f[2]) for f in fits]
    b = max(range(len(fits)), key=lambda i: key[i])
    a, mp, rms = fits[b]
    second = 0
    for i, f in enumerate(fits):
        if i != b and np.median(np.hypot(*(f[1] - mp).T)) >= 0.33 * spacing:
            second = max(second, key[i][0])
    second = max(second, _alias_inliers(ref, cand, rtree, ctree, a, tol))
    return {"assign": a, "mapped": mp, "inliers": int((a >= 0).sum()), "rms": rms, "second": second,
            "spacing": spacing}


def _alias_inliers(ref, cand, rtree, tree, a, tol):
    """The most inliers of the best fit's aliases: the group moved by one step to a
    reference neighbour (each of the six nearest to its central point), refined.

    A regular constellation - a grid of dots - fits its own blobs shifted by a grid step
    nearly as well, and the triangle hypotheses need not propose that shift: real dots,
    dropped, fresh DEV seed 147 cam2, frame 40 (15 frames lost): a fit of 33 inliers one
    grid spacing off was taken with "second 19", while the true placement had 31 (385 ok
    points 29-36 px off). Counting the aliases makes such a fit ambiguous; on a wing,
    whose markers are no lattice, an alias finds few."""
    m = a >= 0
    if m.sum() < 3:
        return 0
    X = _affine_lstsq(ref[m], cand[a[m]])  # the best fit's affine
    centre = int(np.argmin(np.hypot(*(ref - np.median(ref, axis=0)).T)))
    _, nn = rtree.query(ref[centre], k=min(7, len(ref)))
    best = 0
    for j in np.atleast_1d(nn)[1:].tolist():
        step = ref[j] - ref[centre]
        M = np.column_stack([X[:2].T, X[2] + step @ X[:2]])  # x -> affine(x + step)
        aa, _, _ = _refine_fit(ref, cand, tree, M, tol)
        best = max(best, int((aa >= 0).sum()))
    return best


def _velocity(prev, frame, pts, radius, half=PATCH_HALF):
    """Motion (px per frame, (k, 2)) of points ``pts`` of ``frame`` since ``prev``, or None.

    The patch of ``2 half + 1`` px around each point (its marker, its neighbours and the
    membrane's texture: unambiguous where the marker alone is not) is found in ``prev``
    within ``radius`` px; a robust affine map of the points onto their positions in
    ``prev`` must hold for at least :data:`VEL_SHARE` of them within :data:`VEL_RMS` px,
    and gives every point's previous position.
    """
    if prev is None or prev.shape != frame.shape:
        return None
    H, W = frame.shape[:2]
    f = np.ascontiguousarray(frame, dtype=np.float32)
    g = np.ascontiguousarray(prev, dtype=np.float32)
    src, dst = [], []
    for x, y in np.rint(pts).astype(np.int64):
        if x - half - radius < 0 or y - half - radius < 0 or x + half + radius > W - 1 or y + half + radius > H - 1:
            continue
        patch = f[y - half: y + half + 1, x - half: x + half + 1]
        win = g[y - half - radius: y + half + radius + 1, x - half - radius: x + half + radius + 1]
        c = cv2.matchTemplate(win, patch, cv2.TM_CCOEFF_NORMED)
        _, mx, _, loc = cv2.minMaxLoc(c)
        if not mx >= VEL_SCORE:
            continue
        src.append((x, y))
        dst.append((x + loc[0] - radius, y + loc[1] - radius))
    k = len(pts)
    if len(src) < max(4, VEL_SHARE * k):
        return None
    M, rms, nin = _robust_affine(np.array(src, float), np.array(dst, float), tol=VEL_RMS, quality=True)
    if M is None or nin < max(4, VEL_SHARE * k) or rms > VEL_RMS:
        return None
    return pts - _apply_affine(M, np.asarray(pts, float))


def _was_moving(tr, res=None):
    """Markers that were moving when last seen - away from their reference position, or
    faster than ``STILL_SPEED`` - as :mod:`.reacquire` tells the wing from the static dots
    (a static dot hidden by the wing is not fitted with the wing's constellation); with
    the results ``res``, also those written :data:`ROAM_PX` or more from their reference
    position on any frame (a wing marker lost at rest where it was on the reference frame)."""
    p0 = tr.hist_x[:, 0]
    away = np.hypot(p0[:, 0] - tr.ref_pos[:, 0], p0[:, 1] - tr.ref_pos[:, 1]) >= STILL_PX
    dt = np.abs(tr.hist_t[:, 0] - tr.hist_t[:, 1])
    with np.errstate(invalid="ignore"):
        fast = (tr.nh >= 2) & (dt > 0) & (model_speed(tr.hist_x, tr.hist_t) >= STILL_SPEED)
    return away | fast | (False if res is None else _roamed(tr, res))


def _roamed(tr, res):
    """Markers written :data:`ROAM_PX` or more from their reference position on any frame
    of ``res``: wing markers, never the static mount and dots (a camera's bump moves those
    a few px)."""
    with np.errstate(invalid="ignore"):
        return (np.hypot(res.x - tr.ref_pos[:, 0], res.y - tr.ref_pos[:, 1]) >= ROAM_PX).any(0)


def _moving(tr, X, Y, sel):
    """Markers ``sel`` (bool) that moved from their reference position (the wing, not the
    static dots)."""
    return sel & (np.hypot(X - tr.ref_pos[:, 0], Y - tr.ref_pos[:, 1]) >= STILL_PX)


def _due(t, lost_for):
    """Whether a group lost for ``lost_for`` frames is searched for on frame ``t``.

    Stateless (a function of the frame and of the motion model's history, which a
    checkpoint saves), so a resumed run searches on the same frames as an uninterrupted one.
    """
    backoff = 1
    while backoff < MAX_BACKOFF and lost_for >= RETRY_SPAN * (2 * backoff - 1):
        backoff *= 2
    return t % (RETRY * backoff) == 0


def relocate_group(tr, frame, t, res, direction, ctx):
    """Find a group of markers lost together again by its reference constellation.

    Parameters
    ----------
    tr : Tracker
        The tracker (its state is updated for the markers found).
    frame : (H, W) ndarray
    t : int
        Frame index (row of ``res``).
    res : _Results
        The pass's result arrays (read only).
    direction : int
        +1 forward, -1 backward.
    ctx : FrameContext
        This frame's context; ``X, Y, S, XP, YP, ST, RS`` are written for the markers found.

    Returns
    -------
    (k,) ndarray of int
        The markers re-acquired (flagged ``reacquired``).

    Notes
    -----
    Runs only on a steady frame (no glitch, no hypothesis of dropped or repeated frames;
    every :data:`RETRY`-th frame and less often the longer the group has been lost,
    :func:`_due`, to bound its cost) when at least :data:`MIN_GROUP`
    markers that were moving when last seen (the wing, not the static dots) are lost,
    fewer than :data:`MAX_OK_MOVING` moving markers are ok and fewer moving markers have
    a position on this frame than are lost. The candidates exclude the blobs of every
    marker with a position on this frame; the fit (:func:`fit_constellation`) must place at least
    :data:`MIN_INLIERS` and :data:`MIN_SHARE` of the group, with the best different fit
    at most :data:`MARGIN` of its inliers. Each marker then needs its own template's
    correlation of at least :data:`MARKER_SCORE` at its candidate, a refined blob of its
    mass with no foreign blob, within :data:`FIT_TOL` + 1 px of the fit.
    """
    none = np.zeros(0, np.int64)
    if ctx.glitch or ctx.aged != 0 or t % RETRY:
        return none
    X, Y, S, ST, RS = ctx.X, ctx.Y, ctx.S, ctx.ST, ctx.RS
    group = np.flatnonzero(tr.lostflag & np.isfinite(tr.ref_pos[:, 0]) & _was_moving(tr))
    if group.size and not _due(t, int(np.min(np.abs(t - tr.hist_t[group, 0])))):
        return none
    if (group.size < MIN_GROUP or _moving(tr, X, Y, ST == OK).sum() >= MAX_OK_MOVING
            or _moving(tr, X, Y, np.isfinite(X)).sum() >= group.size):
        return none
    tmpl = tr.tz[group].mean(0)
    if not np.any(tmpl):
        return none
    have = np.flatnonzero(np.isfinite(X))
    excl = np.column_stack([X[have], Y[have], tr.rb[have] + 2.0 + float(np.median(tr.rb[group]))])
    cand, _ = find_candidates(frame, tmpl, radius=max(2, int(np.min(tr.rb[group]))), exclude=excl)
    if len(cand) < MIN_INLIERS:
        logger.debug("frame %d: group of %d lost markers: %d candidate blobs", t, group.size, len(cand))
        return none
    fit = fit_constellation(tr.ref_pos[group], cand)
    if fit is None:
        logger.debug("frame %d: group of %d lost markers: no fit to %d candidates", t, group.size, len(cand))
        return none
    n_in, second = fit["inliers"], fit["second"]
    if n_in < max(MIN_INLIERS, MIN_SHARE * group.size) or second > MARGIN * n_in:
        logger.debug("frame %d: group of %d lost markers: fit of %d inliers (second %d) refused",
                     t, group.size, n_in, second)
        return none
    a = fit["assign"]
    sel = group[a >= 0]
    cxy = cand[a[a >= 0]]
    fx = fit["mapped"][a >= 0]
    # each marker's own template, at its candidate (best within 2 px)
    ci = np.rint(cxy).astype(np.int64)
    h = tr.h[sel]
    W, H = tr.W, tr.H
    inside = ((ci[:, 0] - h - 2 >= 0) & (ci[:, 1] - h - 2 >= 0) & (ci[:, 0] + h + 2 <= W - 1)
              & (ci[:, 1] + h + 2 <= H - 1))
    sel, cxy, fx, ci = sel[inside], cxy[inside], fx[inside], ci[inside]
    if not sel.size:
        return none
    maps, origin, shp = tr._match(frame, sel, ci, [2] * sel.size)
    found = []
    for k, i in enumerate(sel.tolist()):
        mk = maps[k, : shp[k, 1], : shp[k, 0]]
        if not mk.size:
            continue
        v, u = np.unravel_index(int(np.argmax(mk)), mk.shape)
        sc = float(mk[v, u])
        if sc < MARKER_SCORE:
            continue
        found.append((i, float(origin[k, 0] + u), float(origin[k, 1] + v), sc, fx[k]))
    if len(found) < max(MIN_INLIERS, MIN_SHARE * group.size):
        logger.debug("frame %d: group of %d lost markers: %d of %d fitted pass their own template",
                     t, group.size, len(found), sel.size)
        return none
    out = []
    ox, oy = X.copy(), Y.copy()  # every marker's blob: tracked, or found here
    for i, mx, my, _, _ in found:
        ox[i], oy[i] = mx, my
    for i, mx, my, sc, fxi in found:
        one = np.array([i])
        rx, ry, mass, inf = tr._refine_candidate(frame, i, mx, my, ox, oy)
        if not (mass[0] > tr.p.min_mass_ratio * tr.mass0[i]) or inf["foreign"][0]:
            continue
        if not np.hypot(rx[0] - fxi[0], ry[0] - fxi[1]) <= FIT_TOL + 1.0:
            continue
        out.append((i, rx[0], ry[0], sc, mx, my, float(sigma_of(tr.noise[one], inf, sc, tr.rb[one])[0])))
    if len(out) < MIN_INLIERS:
        logger.debug("frame %d: group of %d lost markers: %d of %d refined near the fit", t, group.size, len(out),
                     len(found))
        return none
    prev = tr._prev
    cur = np.array([(o[1], o[2]) for o in out])
    vel = _velocity(prev, frame, cur, tr.p.search_radius)
    if vel is None:
        logger.debug("frame %d: %d markers of a lost group found, but not their motion: not re-acquired", t, len(out))
        return none
    # (the image's motion since the previous one holds the camera's bump, and spans the
    # frames dropped in between)
    vel = ctx.step_velocity(vel)
    tp = t - direction
    for k, (i, x, y, sc, mx, my, sg) in enumerate(out):
        X[i], Y[i], S[i], ctx.XP[i], ctx.YP[i] = x, y, sc, mx, my
        ST[i] = FLAGGED
        RS[i] = _R["reacquired"]
        ctx.sigma[i] = sg
        # the motion model restarts with the velocity measured against the previous frame
        tr.hist_x[i] = np.nan
        tr.hist_x[i, 0] = (x, y)
        tr.hist_x[i, 1] = (x - vel[k, 0], y - vel[k, 1])
        tr.hist_t[i] = (t, tp, tp - direction)
        tr.nh[i] = 2
        tr.resid_rms[i] = 1.0
        tr.lostflag[i] = False
        tr.restarted[i] = True
        tr.last_ok[i] = t
    out = [o[0] for o in out]
    if out:
        logger.info("frame %d: %d of %d lost markers re-acquired by their constellation (%d inliers, second %d, "
                    "rms %.2f px)", t, len(out), group.size, n_in, second, fit["rms"])
    return np.array(out, np.int64)
